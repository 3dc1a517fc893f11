//! Fuzzes glTF buffer URIs: the input (lossy UTF-8) is the `uri` of the only buffer of an
//! otherwise valid one-triangle glTF in a folder that also holds a valid `in.bin`. Beside that
//! folder lies `secret.bin`, a valid triangle whose coordinates are all 4242. Any URI must give
//! an error or a mesh, never a panic, and never a mesh built from the secret file (URIs are
//! confined to the glTF's folder; issue 11 item 1).
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

const SECRET: f32 = 4242.0;

fn triangle(v: f32) -> Vec<u8> {
    [v, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0, v]
        .iter()
        .flat_map(|c| c.to_le_bytes())
        .collect()
}

/// The jail folder (`<tmp>/marchmesh-fuzz-uris-<pid>/model`), created once.
fn model_dir() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let outer =
            std::env::temp_dir().join(format!("marchmesh-fuzz-uris-{}", std::process::id()));
        let model = outer.join("model");
        std::fs::create_dir_all(&model).expect("fuzz folder");
        std::fs::write(outer.join("secret.bin"), triangle(SECRET)).expect("secret");
        std::fs::write(model.join("in.bin"), triangle(1.0)).expect("in.bin");
        model
    })
}

fuzz_target!(|data: &[u8]| {
    let uri = String::from_utf8_lossy(data);
    let json = serde_json::json!({
        "asset": {"version": "2.0"},
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [SECRET, SECRET, SECRET]}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "buffers": [{"byteLength": 36, "uri": uri}]
    });
    let path = model_dir().join("model.gltf");
    if std::fs::write(&path, json.to_string()).is_err() {
        return;
    }
    if let Ok(mesh) = marchmesh_meshio::load_mesh(&path) {
        assert!(
            mesh.positions.iter().all(|p| p.max_element() != SECRET),
            "URI {uri:?} read the file outside the glTF's folder"
        );
    }
});
