//! Per-ray-step cost of the sdf backend on primary rays: traces the camera rays of a scene
//! (rows of rays, as the integrator hands them over, one thread) with `closest_hits` and
//! prints Mrays/s, mean field evaluations per ray and ns per ray-step (median of the
//! repeats). `spheres=N` replaces the scene's objects by a union of N separate unit-radius
//! spheres on a jittered grid filling the view, which is how the object-count scaling of
//! issue 14 is measured (the image stays the same size and similar in coverage).
//!
//! `cargo run --release -p marchmesh-sdf --example primary_rays -- SCENE [side=512]
//! [repeats=9] [spheres=N] [lockstep=true|false]`
//!
//! Compare builds or options by alternating runs and quoting ratios with the load average
//! (`uptime`): this prints absolute times, which drift on a shared machine.

use std::path::Path;
use std::time::Instant;

use glam::DVec2;
use marchmesh_core::camera::primary_ray_on;
use marchmesh_core::{Geometry, Termination, TraceResult};
use marchmesh_scene::{Node, NodeKind, Scene};
use marchmesh_sdf::{SdfOptions, build};

fn main() {
    if let Err(e) = run() {
        eprintln!("primary_rays: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args
        .first()
        .ok_or("usage: primary_rays SCENE [side=512] [repeats=9] [spheres=N] [lockstep=true]")?;
    let kv = |key: &str| {
        args.iter()
            .skip(1)
            .find_map(|a| a.strip_prefix(key)?.strip_prefix('='))
    };
    let num = |key: &str, d: u32| -> Result<u32, String> {
        kv(key).map_or(Ok(d), |v| v.parse().map_err(|e| format!("{key}: {e}")))
    };
    let side = num("side", 512)?;
    let repeats = num("repeats", 9)?.max(1);
    let spheres = num("spheres", 0)?;
    let lockstep = kv("lockstep").is_none_or(|v| v != "false");
    let mut scene = marchmesh_scene::load(Path::new(path))
        .map_err(|e| e.to_string())?
        .with_image_size(side, side)
        .map_err(|e| e.to_string())?;
    if spheres > 0 {
        scene = with_spheres(scene, spheres);
    }
    let g = build(
        &scene,
        &SdfOptions {
            lockstep,
            ..SdfOptions::DEFAULT
        },
    )
    .map_err(|e| e.to_string())?;
    let plane = scene.camera.image_plane();
    let t_max = scene.render.max_distance;
    let rows: Vec<Vec<_>> = (0..side)
        .map(|y| {
            (0..side)
                .map(|x| primary_ray_on(&plane, x, y, DVec2::splat(0.5), t_max))
                .collect()
        })
        .collect();
    let mut out = vec![TraceResult::default(); side as usize];
    let mut times = Vec::new();
    let (mut steps, mut hits) = (0u64, 0u64);
    for rep in 0..=repeats {
        let (mut s, mut h) = (0u64, 0u64);
        let start = Instant::now();
        for row in &rows {
            g.closest_hits(row, &mut out);
            for r in &out {
                s += u64::from(r.work.steps);
                h += u64::from(r.termination() == Termination::Hit);
            }
        }
        let dt = start.elapsed().as_secs_f64();
        if rep > 0 {
            times.push(dt);
        }
        (steps, hits) = (s, h);
    }
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    let rays = f64::from(side) * f64::from(side);
    println!(
        "{path}{} {side}x{side} lockstep={lockstep}: {:.3} Mrays/s (median of {repeats}, min {:.1} ms), mean steps {:.2}, {:.1} ns per ray-step, hits {hits}",
        if spheres > 0 {
            format!(" spheres={spheres}")
        } else {
            String::new()
        },
        rays / median / 1e6,
        times[0] * 1e3,
        steps as f64 / rays,
        median * 1e9 / steps as f64,
    );
    Ok(())
}

/// The scene with its objects replaced by `n` unit spheres on a jittered grid in front of
/// the camera (a slab 6 units deep starting 4 units away, as wide as the view there).
fn with_spheres(mut scene: Scene, n: u32) -> Scene {
    let Some(template) = scene.objects.first().cloned() else {
        return scene;
    };
    let cols = (f64::from(n)).sqrt().ceil() as u32;
    let cam = &scene.camera;
    let half = (cam.vfov_rad * 0.5).tan() * 7.0;
    let pitch = 2.0 * half / f64::from(cols);
    let radius = (0.35 * pitch).min(1.0);
    let (right, up, fwd) = (cam.right, cam.up, cam.forward);
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut jitter = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    scene.objects = (0..n)
        .map(|i| {
            let (cx, cy) = (i % cols, i / cols);
            let x = -half + pitch * (f64::from(cx) + 0.5);
            let y = -half + pitch * (f64::from(cy) + 0.5);
            let z = 7.0 + 3.0 * jitter();
            let mut node: Node = template.clone();
            node.kind = NodeKind::Sphere { radius };
            node.transform.matrix3 = glam::DMat3::IDENTITY;
            node.transform.translation = cam.position + right * x + up * y + fwd * z;
            node
        })
        .collect();
    scene
}
