//! Renders a scene with the reference backend: `render_reference SCENE OUT.png [SIDE]`.

use std::path::Path;

use marchmesh_core::{BackgroundSampler, RenderOptions, image_io, render};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(scene_path), Some(out)) = (args.get(1), args.get(2)) else {
        return Err("usage: render_reference SCENE OUT.png [SIDE]".into());
    };
    let mut scene = marchmesh_scene::load(Path::new(scene_path))?;
    if let Some(side) = args.get(3) {
        let side: u32 = side.parse()?;
        scene = scene.with_image_size(side, side)?;
    }
    let geometry = marchmesh_reference::build(&scene, &Default::default())?;
    let background = BackgroundSampler::load(&scene.background)?;
    let output = render(
        &scene,
        &geometry,
        &background,
        &RenderOptions::default(),
        &|| {},
    )?;
    image_io::write_png(&output.framebuffer, Path::new(out))?;
    println!(
        "render {:?}, hits {}, max-steps rays {}",
        output.elapsed,
        output.stats.hits,
        output.stats.closest_max_steps + output.stats.occlusion_max_steps
    );
    Ok(())
}
