//! Converts any mesh the loader reads (OBJ, glTF, GLB) to a minimal binary glTF:
//! `cargo run -p marchmesh-meshio --example to_glb -- scenes/meshes/bunny.obj /tmp/bunny.glb`.
//! Loading the output gives the same positions, normals and triangles bit for bit.

use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(input), Some(output)) = (args.get(1), args.get(2)) else {
        return Err("usage: to_glb INPUT OUTPUT.glb".into());
    };
    let mesh = marchmesh_meshio::load_mesh(&PathBuf::from(input))?;
    marchmesh_meshio::write_glb(&mesh, &PathBuf::from(output))?;
    let back = marchmesh_meshio::load_mesh(&PathBuf::from(output))?;
    if back.content_hash() != mesh.content_hash() {
        return Err(format!("{output}: reloaded mesh differs from {input}").into());
    }
    eprintln!(
        "{input} -> {output}: {} vertices, {} triangles ({} degenerate skipped), hash {:016x}",
        mesh.positions.len(),
        mesh.triangles.len(),
        mesh.report.degenerate_skipped,
        mesh.content_hash()
    );
    Ok(())
}
