//! Golden renders: the three foundation scenes at 64x64 with the reference, compared with
//! the committed PNGs (PSNR >= 40 dB; an exact backend on the same machine gives identical
//! images, the margin absorbs float differences between platforms). Rewrite them with
//! `MARCHMESH_BLESS=1 cargo test -p marchmesh-reference --test golden` after an intended
//! change, and look at them before committing.

use std::path::{Path, PathBuf};

use marchmesh_core::{BackgroundSampler, RenderOptions, render};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn psnr(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let mse: f64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (f64::from(*x) - f64::from(*y)).powi(2))
        .sum::<f64>()
        / a.as_raw().len() as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}

fn golden(name: &str) {
    let scene_path = root().join("../../scenes").join(format!("{name}.json"));
    let scene = marchmesh_scene::load(&scene_path)
        .and_then(|s| s.with_image_size(64, 64).map_err(|e| panic!("{e}")))
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let g = marchmesh_reference::build(&scene, &Default::default()).unwrap();
    let bg = BackgroundSampler::load(&scene.background).unwrap();
    let out = render(
        &scene,
        &g,
        &bg,
        &RenderOptions {
            threads: 1,
            ..Default::default()
        },
        &|| {},
    )
    .unwrap();
    assert_eq!(out.stats.non_finite_pixels, 0);
    let img = out.framebuffer.to_rgb8();
    let path = root().join("tests/golden").join(format!("{name}.png"));
    if std::env::var_os("MARCHMESH_BLESS").is_some() {
        img.save(&path).unwrap();
        return;
    }
    let stored = image::open(Path::new(&path))
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (run with MARCHMESH_BLESS=1 to create it)",
                path.display()
            )
        })
        .to_rgb8();
    let p = psnr(&img, &stored);
    assert!(
        p >= 40.0,
        "{name}: PSNR {p:.1} dB against {}",
        path.display()
    );
}

#[test]
fn primitives() {
    golden("primitives");
}

#[test]
fn csg() {
    golden("csg");
}

#[test]
fn seed_spheres() {
    golden("seed-spheres");
}
