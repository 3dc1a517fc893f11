//! Fuzzes the mesh loaders (OBJ via tobj, glTF/.glb via gltf) through the public entry point:
//! the first byte picks the extension, the rest is the file. Any input must give a mesh or an
//! error, never a panic, and a loaded mesh must hold only finite vertices and valid indices.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&kind, body)) = data.split_first() else {
        return;
    };
    let ext = match kind % 3 {
        0 => "obj",
        1 => "glb",
        _ => "gltf",
    };
    let path = std::env::temp_dir().join(format!("marchmesh-fuzz-{}.{ext}", std::process::id()));
    if std::fs::write(&path, body).is_err() {
        return;
    }
    if let Ok(mesh) = marchmesh_meshio::load_mesh(&path) {
        assert!(mesh.positions.iter().all(|p| p.is_finite()));
        let n = mesh.positions.len() as u32;
        assert!(mesh.triangles.iter().all(|t| t.iter().all(|&i| i < n)));
    }
});
