//! Build cost of the mesh backend on scene files: builds each scene with the default options
//! and prints the build phases (load, tessellate, extract, bvh) in ms and the triangle count.
//! `cargo run --release -p marchmesh-mesh --example extract_cost -- SCENE.json...`

use marchmesh_core::Geometry;
use marchmesh_mesh::{MeshOptions, build};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    for path in std::env::args().skip(1) {
        let text = std::fs::read_to_string(&path)?;
        let dir = std::path::Path::new(&path)
            .parent()
            .unwrap_or(std::path::Path::new("."))
            .to_path_buf();
        let scene = marchmesh_scene::parse_scene(&text, &path, &dir)?;
        let t0 = std::time::Instant::now();
        let geometry = build(&scene, &MeshOptions::default())?;
        let report = geometry.report();
        println!(
            "{path}: build {:.0} ms, phases {:?}, triangles {:?}",
            t0.elapsed().as_secs_f64() * 1e3,
            report.build_phases_ms,
            report.triangles
        );
    }
    Ok(())
}
