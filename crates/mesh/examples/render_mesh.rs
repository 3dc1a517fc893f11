//! Renders a scene file with the mesh backend to a PNG (for eyeballing; the CLI is the real
//! entry point): `cargo run --release -p marchmesh-mesh --example render_mesh -- SCENE OUT.png [SIDE]`.

use std::path::PathBuf;

use marchmesh_core::{BackgroundSampler, RenderOptions, image_io::write_png, render};
use marchmesh_mesh::{MeshOptions, build};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(scene_path), Some(out)) = (args.get(1), args.get(2)) else {
        return Err("usage: render_mesh SCENE OUT.png [SIDE]".into());
    };
    let mut scene = marchmesh_scene::load(&PathBuf::from(scene_path))?;
    if let Some(side) = args.get(3) {
        let side: u32 = side.parse()?;
        let height = side * scene.camera.height / scene.camera.width.max(1);
        scene = scene.with_image_size(side, height.max(1))?;
    }
    let g = build(&scene, &MeshOptions::DEFAULT)?;
    let bg = BackgroundSampler::load(&scene.background)?;
    let out_img = render(&scene, &g, &bg, &RenderOptions::default(), &|| {})?;
    write_png(&out_img.framebuffer, &PathBuf::from(out))?;
    let r = marchmesh_core::Geometry::report(&g);
    eprintln!(
        "memory {} bytes, phases {:?}, counters {:?}",
        r.memory_bytes, r.build_phases_ms, r.counters
    );
    for n in r.notes {
        eprintln!("note: {n}");
    }
    eprintln!(
        "render {:?}, mean node visits {:.1}",
        out_img.elapsed,
        out_img.stats.mean_node_visits()
    );
    Ok(())
}
