//! Per-evaluation cost of a scene's field on eight lanes: the field of each scene given is
//! evaluated at points along its camera rays (pixel centres of a 256 x 256 image, every
//! seventh, at distance 3: the `field_*/x8` points of the sdf backend's `trace` bench) by
//! the specialised kernel ([`marchmesh_field::kernel`]) and by the tape, in rounds that
//! alternate which runs first, and the nanoseconds of thread CPU time (Linux schedstat) per
//! 8-lane evaluation printed (medians) with the median of the per-round ratios.
//!
//! `cargo run --release -p marchmesh-field --example eval_x8 -- SCENE.json... [--passes N]
//! [--rounds R]`

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;

use glam::Vec3;
use marchmesh_field::{F32x8, Field, FieldOptions, V3};

/// Nanoseconds this thread has run (schedstat), or wall-clock nanoseconds since `start`.
fn thread_ns(start: Instant) -> u128 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or_else(|| start.elapsed().as_nanos())
}

/// The scene's points as 8-lane batches.
fn points(scene: &marchmesh_scene::Scene) -> Vec<V3<F32x8>> {
    let c = &scene.camera;
    let mut pts = Vec::new();
    for y in 0..c.height {
        for x in 0..c.width {
            let r = camera_dir(c, x, y);
            pts.push(r * 3.0);
        }
    }
    let pts: Vec<Vec3> = pts.into_iter().step_by(7).collect();
    pts.chunks_exact(8)
        .map(|c| V3::from_points(std::array::from_fn(|i| c[i])))
        .collect()
}

/// The direction of the camera ray through pixel `(x, y)`'s centre (render space: the
/// camera at the origin).
fn camera_dir(c: &marchmesh_scene::Camera, x: u32, y: u32) -> Vec3 {
    let (fwd, right, up) = (c.forward, c.right, c.up);
    let h = (c.vfov_rad * 0.5).tan();
    let w = h * f64::from(c.width) / f64::from(c.height);
    let sx = (2.0 * (f64::from(x) + 0.5) / f64::from(c.width) - 1.0) * w;
    let sy = (1.0 - 2.0 * (f64::from(y) + 0.5) / f64::from(c.height)) * h;
    (fwd + right * sx + up * sy).normalize().as_vec3()
}

fn time(f: impl Fn(V3<F32x8>) -> F32x8, pts: &[V3<F32x8>], passes: usize) -> (f64, f32) {
    let start = Instant::now();
    let t0 = thread_ns(start);
    let mut s = 0.0f32;
    for _ in 0..passes {
        for p in pts {
            s += f(black_box(*p)).0.iter().sum::<f32>();
        }
    }
    let dt = (thread_ns(start) - t0) as f64;
    (dt / (passes * pts.len()) as f64, s)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut scenes = Vec::new();
    let mut passes = 50;
    let mut rounds = 11;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--passes" => passes = args.next().ok_or("--passes needs a value")?.parse()?,
            "--rounds" => rounds = args.next().ok_or("--rounds needs a value")?.parse()?,
            _ => scenes.push(PathBuf::from(a)),
        }
    }
    for path in scenes {
        let scene = marchmesh_scene::load(&path)?.with_image_size(256, 256)?;
        let mut kernel = Field::compile_scene(&scene, &FieldOptions::DEFAULT)?;
        kernel.set_kernels(true);
        let mut tape = Field::compile_scene(&scene, &FieldOptions::DEFAULT)?;
        tape.set_kernels(false);
        let pts = points(&scene);
        // Rounds alternate which variant runs first; the median of per-round ratios.
        let (mut tk, mut tt, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
        for round in 0..rounds {
            let (k, t) = if round % 2 == 0 {
                let k = time(|p| kernel.distance_lanes(p), &pts, passes);
                (k, time(|p| tape.distance_lanes(p), &pts, passes))
            } else {
                let t = time(|p| tape.distance_lanes(p), &pts, passes);
                (time(|p| kernel.distance_lanes(p), &pts, passes), t)
            };
            assert_eq!(k.1.to_bits(), t.1.to_bits(), "the same values");
            tk.push(k.0);
            tt.push(t.0);
            ratios.push(t.0 / k.0);
        }
        println!(
            "{}: kernel {} ({} runs, {} leaves on the tape's path), ns per 8-lane evaluation: kernel {:.2}, tape {:.2} (medians of {rounds} rounds x {} evaluations); tape / kernel per round median {:.3}",
            path.display(),
            kernel.kernel().is_some(),
            kernel.kernel().map_or(0, |k| k.runs()),
            kernel.kernel().map_or(0, |k| k.fallback_leaves()),
            median(&mut tk),
            median(&mut tt),
            passes * pts.len(),
            median(&mut ratios)
        );
    }
    Ok(())
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
