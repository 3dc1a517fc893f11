//! Per-ray-step cost of the sdf backend on primary rays: traces the camera rays of a scene
//! (rows of rays, as the integrator hands them over, one thread) with `closest_hits` and
//! prints Mrays/s, mean field evaluations per ray and ns per ray-step (median of the
//! repeats). `spheres=N` replaces the scene's objects by a union of N separate unit-radius
//! spheres on a jittered grid filling the view, which is how the object-count scaling of
//! issue 14 is measured (the image stays the same size and similar in coverage).
//!
//! `cargo run --release -p marchmesh-sdf --example primary_rays -- SCENE [side=512]
//! [repeats=9] [spheres=N] [lockstep=true|false] [cull=true|false] [segment=true|false]
//! [beams=true|false] [recede=true|false] [relaxation=OMEGA] [prune_cells=auto|octree|root]
//! [versus=KEY=VALUE]`
//!
//! `versus=cull=false` (or `lockstep=false`, `segment=false`, `beams=false`, `recede=false`,
//! `kernels=false`, `jit=true` (built with `--features jit`), `relaxation=1.5`) builds a second geometry with that option
//! changed and times the two in alternating rounds (order swapped every round), printing
//! the median of the per-round time ratios: the number to quote on a shared machine, with
//! the load average (`uptime`); absolute times drift.

use std::path::Path;
use std::time::Instant;

use glam::DVec2;
use marchmesh_core::camera::primary_ray_on;
use marchmesh_core::{Geometry, Termination, TraceResult};
use marchmesh_scene::{Node, NodeKind, Scene, Shape};
use marchmesh_sdf::{PruneCells, SdfOptions, build};

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
    let flag = |v: Option<&str>| v.is_none_or(|v| v != "false");
    let lockstep = flag(kv("lockstep"));
    let cull = flag(kv("cull"));
    let segment = flag(kv("segment"));
    let beams = flag(kv("beams"));
    let recede = flag(kv("recede"));
    let relaxation = match kv("relaxation") {
        None => SdfOptions::DEFAULT.relaxation,
        Some(v) => v.parse().map_err(|e| format!("relaxation: {e}"))?,
    };
    let prune_cells = match kv("prune_cells") {
        None | Some("auto") => PruneCells::Auto,
        Some("octree") => PruneCells::Octree,
        Some("root") => PruneCells::Root,
        Some(v) => return Err(format!("prune_cells: {v}: expected auto, octree or root")),
    };
    let mut scene = marchmesh_scene::load(Path::new(path))
        .map_err(|e| e.to_string())?
        .with_image_size(side, side)
        .map_err(|e| e.to_string())?;
    if spheres > 0 {
        scene = with_spheres(scene, spheres);
    }
    let options = SdfOptions {
        lockstep,
        cull,
        segment,
        beams,
        recede,
        relaxation,
        prune_cells,
        ..SdfOptions::DEFAULT
    };
    let g = build(&scene, &options).map_err(|e| e.to_string())?;
    let versus = match kv("versus") {
        None => None,
        Some(spec) => {
            let mut other = options.clone();
            match spec {
                "cull=false" => other.cull = false,
                "cull=true" => other.cull = true,
                "lockstep=false" => other.lockstep = false,
                "lockstep=true" => other.lockstep = true,
                "segment=false" => other.segment = false,
                "segment=true" => other.segment = true,
                "beams=false" => other.beams = false,
                "beams=true" => other.beams = true,
                "recede=false" => other.recede = false,
                "recede=true" => other.recede = true,
                "kernels=false" => other.kernels = false,
                "kernels=true" => other.kernels = true,
                "jit=false" => other.jit = false,
                "jit=true" => other.jit = true,
                _ if spec.starts_with("relaxation=") => {
                    other.relaxation = spec["relaxation=".len()..]
                        .parse()
                        .map_err(|e| format!("versus: {spec}: {e}"))?;
                }
                _ => {
                    return Err(format!(
                        "versus: {spec}: expected cull=, lockstep=, segment=, beams=, recede=, kernels= or jit=BOOL, or relaxation=OMEGA"
                    ));
                }
            }
            Some((spec, build(&scene, &other).map_err(|e| e.to_string())?))
        }
    };
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
    // One render: (seconds, field evaluations, hits).
    let mut trace = |g: &dyn Geometry| {
        let (mut s, mut h) = (0u64, 0u64);
        let start = Instant::now();
        for row in &rows {
            g.closest_hits(row, &mut out);
            for r in &out {
                s += u64::from(r.work.steps);
                h += u64::from(r.termination() == Termination::Hit);
            }
        }
        (start.elapsed().as_secs_f64(), s, h)
    };
    let rays = f64::from(side) * f64::from(side);
    let label = if spheres > 0 {
        format!("{path} spheres={spheres}")
    } else {
        path.clone()
    };
    let (mut times, mut other_times, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
    let (mut steps, mut hits, mut other_steps) = (0, 0, 0);
    for rep in 0..=repeats {
        let a_first = rep % 2 == 0;
        let mut a = (0.0, 0, 0);
        let mut b = None;
        for turn in 0..2 {
            match (&versus, (turn == 0) == a_first) {
                (_, true) => a = trace(&g),
                (Some((_, other)), false) => b = Some(trace(other)),
                (None, false) => {}
            }
        }
        if rep == 0 {
            continue; // warm-up
        }
        (steps, hits) = (a.1, a.2);
        times.push(a.0);
        if let Some(b) = b {
            other_steps = b.1;
            other_times.push(b.0);
            ratios.push(b.0 / a.0);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let t = median(&mut times);
    println!(
        "{label} {side}x{side} lockstep={lockstep} cull={cull}: {:.3} Mrays/s (median of {repeats}), mean steps {:.2}, {:.1} ns per ray-step, hits {hits}",
        rays / t / 1e6,
        steps as f64 / rays,
        t * 1e9 / steps as f64,
    );
    if let Some((spec, _)) = &versus {
        let tb = median(&mut other_times);
        println!(
            "  versus {spec}: {:.3} Mrays/s, mean steps {:.2}, {:.1} ns per ray-step; time ratio (versus / this, median of {} alternating rounds) {:.3}",
            rays / tb / 1e6,
            other_steps as f64 / rays,
            tb * 1e9 / other_steps as f64,
            ratios.len(),
            median(&mut ratios),
        );
    }
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
            node.kind = NodeKind::Leaf(Shape::Sphere { radius });
            node.transform.matrix3 = glam::DMat3::IDENTITY;
            node.transform.translation = cam.position + right * x + up * y + fwd * z;
            node
        })
        .collect();
    scene
}
