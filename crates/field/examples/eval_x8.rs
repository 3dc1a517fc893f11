//! Per-evaluation cost of a scene's field on eight lanes: the field of each scene given is
//! evaluated at points along its camera rays (pixel centres of a 256 x 256 image, every
//! seventh, at distance 3: the `field_*/x8` points of the sdf backend's `trace` bench) by
//! the function compiled per program ([`marchmesh_field::jit`]), the specialised kernel
//! ([`marchmesh_field::kernel`]) and the tape, in rounds that rotate which runs first, and
//! the nanoseconds of thread CPU time (Linux schedstat) per 8-lane evaluation printed
//! (medians) with the medians of the per-round ratios. `--only jit|kernel|tape` runs one
//! variant alone (for callgrind: the difference of two pass counts).
//!
//! `cargo run --release -p marchmesh-field --features jit --example eval_x8 -- SCENE.json...
//! [--passes N] [--rounds R] [--only VARIANT]` (without the feature `jit` the "jit" variant
//! is the kernel). The thread CPU time advances in steps of a few milliseconds on some
//! machines: use enough passes that one timing is a few hundred milliseconds.

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

/// The variants timed: name and how the field evaluates.
const VARIANTS: [&str; 3] = ["jit", "kernel", "tape"];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut scenes = Vec::new();
    let mut passes = 50;
    let mut rounds = 11;
    let mut only: Option<String> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--passes" => passes = args.next().ok_or("--passes needs a value")?.parse()?,
            "--rounds" => rounds = args.next().ok_or("--rounds needs a value")?.parse()?,
            "--only" => only = Some(args.next().ok_or("--only needs jit, kernel or tape")?),
            _ => scenes.push(PathBuf::from(a)),
        }
    }
    for path in scenes {
        let scene = marchmesh_scene::load(&path)?.with_image_size(256, 256)?;
        let mut fields = Vec::new();
        let mut compile_us = 0.0;
        for v in VARIANTS {
            let mut f = Field::compile_scene(&scene, &FieldOptions::DEFAULT)?;
            f.set_kernels(v != "tape");
            let t = Instant::now();
            f.set_jit(v == "jit");
            if v == "jit" {
                compile_us = t.elapsed().as_secs_f64() * 1e6;
            }
            fields.push(f);
        }
        let pts = points(&scene);
        if let Some(o) = &only {
            // One variant alone (for callgrind: difference two pass counts).
            let k = VARIANTS
                .iter()
                .position(|v| v == o)
                .ok_or("unknown --only")?;
            let f = &fields[k];
            for _ in 0..rounds {
                let (ns, _) = time(|p| f.distance_lanes(p), &pts, passes);
                println!("{}: {o} {ns:.2} ns per 8-lane evaluation", path.display());
            }
            continue;
        }
        // Rounds rotate which variant runs first; medians of the times and of the
        // per-round ratios.
        let mut ns: [Vec<f64>; 3] = Default::default();
        let (mut kj, mut tj) = (Vec::new(), Vec::new());
        for round in 0..rounds {
            let mut t = [(0.0, 0.0f32); 3];
            for k in 0..3 {
                let v = (k + round) % 3;
                let f = &fields[v];
                t[v] = time(|p| f.distance_lanes(p), &pts, passes);
            }
            assert_eq!(t[0].1.to_bits(), t[2].1.to_bits(), "the same values (jit)");
            assert_eq!(
                t[1].1.to_bits(),
                t[2].1.to_bits(),
                "the same values (kernel)"
            );
            for v in 0..3 {
                ns[v].push(t[v].0);
            }
            kj.push(t[1].0 / t[0].0);
            tj.push(t[2].0 / t[0].0);
        }
        let (jit, kernel) = (&fields[0], &fields[1]);
        println!(
            "{}: jit {} ({} operations, compiled in {compile_us:.0} us), kernel {} ({} runs, {} leaves on the tape's path); ns per 8-lane evaluation: jit {:.2}, kernel {:.2}, tape {:.2} (medians of {rounds} rounds x {} evaluations); per-round medians kernel / jit {:.3}, tape / jit {:.3}",
            path.display(),
            jit.jit().is_some(),
            jit.jit().map_or(0, |j| j.ops()),
            kernel.kernel().is_some(),
            kernel.kernel().map_or(0, |k| k.runs()),
            kernel.kernel().map_or(0, |k| k.fallback_leaves()),
            median(&mut ns[0]),
            median(&mut ns[1]),
            median(&mut ns[2]),
            passes * pts.len(),
            median(&mut kj),
            median(&mut tj)
        );
    }
    Ok(())
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
