//! Renders scene files with the mesh backend and the reference at a given size on 2 threads
//! (AOVs on, as `marchmesh render --aov` does) and writes each render's colour and AOV planes
//! as the CLI's PFM files into `OUT/<scene>_<backend>.aov/`, named as `marchmesh render` names
//! them, so two builds' renders can be compared byte for byte (`cmp`).
//!
//! `cargo run --release -p marchmesh-mesh --example render_aovs -- OUT WIDTH HEIGHT SCENE...`
//! (a scene's name in `OUT` is its path under `scenes/` with `/` as `_`, without `.json`)

use std::path::Path;

use marchmesh_core::{BackgroundSampler, Geometry, RenderOptions, image_io, render};

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().collect();
    let [_, out, w, h, scenes @ ..] = &args[..] else {
        return Err("usage: render_aovs OUT WIDTH HEIGHT SCENE...".into());
    };
    let (w, h): (u32, u32) = (w.parse()?, h.parse()?);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    for name in scenes {
        let scene =
            marchmesh_scene::load(&root.join(format!("{name}.json")))?.with_image_size(w, h)?;
        let bg = BackgroundSampler::load(&scene.background)?;
        let mesh: Box<dyn Geometry> = Box::new(marchmesh_mesh::build(&scene, &Default::default())?);
        let reference: Box<dyn Geometry> =
            Box::new(marchmesh_reference::build(&scene, &Default::default())?);
        for (backend, g) in [("mesh", mesh), ("reference", reference)] {
            let opts = RenderOptions {
                threads: 2,
                ..Default::default()
            };
            let r = render(&scene, g.as_ref(), &bg, &opts, &|| {})?;
            let dir = Path::new(out).join(format!("{}_{backend}.aov", name.replace('/', "_")));
            std::fs::create_dir_all(&dir)?;
            for (file, bytes) in image_io::aov_files(&r.framebuffer) {
                std::fs::write(dir.join(file), bytes)?;
            }
            println!("{name} {backend}: {:?}", r.stats.hits);
        }
    }
    Ok(())
}
