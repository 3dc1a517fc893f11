//! How fast could camera rays go with this field evaluator and nothing else? Issue 14's
//! ceiling measurement.
//!
//! Times, in alternating rounds in one process (order swapped every round, 1 thread), the
//! sdf backend's `closest_hits` on the image's rows of camera rays against a *lean* 8-lane
//! sphere tracer over the same compiled field ([`Field::distance_lanes`]): rays clipped to the
//! field's bounds, relaxed steps (omega 1.2) with Keinert's overlap undo, a hit where the
//! distance falls below the backend's own hit shell (`PixelCone(0.05)`), no refinement of the
//! hit, no shell decisions, segment tracing, culling or receding checks, and normals from four
//! 8-lane evaluations per eight hits (the tetrahedron stencil). So the lean tracer does less
//! than the backend: its time is an upper bound on what removing the backend's control logic
//! could give, and its depth error against the backend (printed) says what that logic buys.
//!
//! `cargo run --release -p marchmesh-sdf --example lean_ceiling -- SCENE [side=512] [repeats=9]`
//!
//! Prints both pixel rates (median of the repeats), the median of the per-round time ratios
//! (the number to quote, with the load average: `uptime`), mean field evaluations per ray, and
//! the lean depths' error against the backend's (mean / p95 / max over pixels both hit).

use std::path::Path;
use std::time::Instant;

use glam::{DVec2, Vec3};
use marchmesh_core::camera::primary_ray_on;
use marchmesh_core::{Geometry, Ray, TraceResult};
use marchmesh_field::{F32x8, Field, FieldOptions, Lane, V3};
use marchmesh_sdf::{SdfOptions, build};

fn main() {
    if let Err(e) = run() {
        eprintln!("lean_ceiling: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args
        .first()
        .ok_or("usage: lean_ceiling SCENE [side=512] [repeats=9]")?;
    let num = |key: &str, d: u32| -> Result<u32, String> {
        args.iter()
            .skip(1)
            .find_map(|a| a.strip_prefix(key)?.strip_prefix('='))
            .map_or(Ok(d), |v| v.parse().map_err(|e| format!("{key}: {e}")))
    };
    let side = num("side", 512)?.max(1);
    let repeats = num("repeats", 9)?.max(1);
    let scene = marchmesh_scene::load(Path::new(path))
        .map_err(|e| e.to_string())?
        .with_image_size(side, side)
        .map_err(|e| e.to_string())?;
    let backend = build(&scene, &SdfOptions::DEFAULT).map_err(|e| e.to_string())?;
    let field =
        Field::compile_scene(&scene, &FieldOptions::default()).map_err(|e| e.to_string())?;
    let (lo, hi) = field
        .bounds()
        .ok_or("the lean tracer needs a bounded field (no plane)")?;
    let lean = Lean {
        field: &field,
        lo: lo.as_vec3(),
        hi: hi.as_vec3(),
        eps_cone: (0.05 * scene.camera.pixel_angle()) as f32,
    };
    let plane = scene.camera.image_plane();
    let t_max = scene.render.max_distance;
    let rows: Vec<Vec<Ray>> = (0..side)
        .map(|y| {
            (0..side)
                .map(|x| primary_ray_on(&plane, x, y, DVec2::splat(0.5), t_max))
                .collect()
        })
        .collect();
    let rays: Vec<Ray> = rows.iter().flatten().copied().collect();
    let n = rays.len();
    let mut row_out = vec![TraceResult::default(); side as usize];
    let mut depth_backend = vec![f32::NAN; n];
    let mut depth_lean = vec![f32::NAN; n];
    let (mut t_backend, mut t_lean, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
    let mut steps = (0u64, 0u64);
    for rep in 0..=repeats {
        let mut round = [0.0f64; 2];
        for turn in 0..2 {
            if (turn == 0) == (rep % 2 == 0) {
                let start = Instant::now();
                let mut s = 0u64;
                for (y, row) in rows.iter().enumerate() {
                    backend.closest_hits(row, &mut row_out);
                    for (x, r) in row_out.iter().enumerate() {
                        s += u64::from(r.work.steps);
                        depth_backend[y * side as usize + x] = r.hit().map_or(f32::NAN, |h| h.t);
                    }
                }
                round[0] = start.elapsed().as_secs_f64();
                steps.0 = s;
            } else {
                let start = Instant::now();
                steps.1 = lean.trace(&rays, &mut depth_lean);
                round[1] = start.elapsed().as_secs_f64();
            }
        }
        if rep > 0 {
            t_backend.push(round[0]);
            t_lean.push(round[1]);
            ratios.push(round[0] / round[1]);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let rate = |t: f64| n as f64 / t / 1e6;
    let per_ray = |s: u64| s as f64 / n as f64;
    println!(
        "{path} {side}x{side}, 1 thread, {repeats} rounds: backend {:.2} Mrays/s ({:.2} evaluations a ray), lean {:.2} Mrays/s ({:.2}); backend time / lean time {:.3} (median of per-round ratios)",
        rate(median(&mut t_backend)),
        per_ray(steps.0),
        rate(median(&mut t_lean)),
        per_ray(steps.1),
        median(&mut ratios),
    );
    let mut err: Vec<f64> = depth_backend
        .iter()
        .zip(&depth_lean)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| f64::from((a - b).abs()))
        .collect();
    let disagree = depth_backend
        .iter()
        .zip(&depth_lean)
        .filter(|(a, b)| a.is_finite() != b.is_finite())
        .count();
    if err.is_empty() {
        println!("no pixel hit by both");
        return Ok(());
    }
    err.sort_by(f64::total_cmp);
    println!(
        "lean depth against the backend's: mean {:.1e} / p95 {:.1e} / max {:.1e} over {} pixels; {} pixels hit by one only",
        err.iter().sum::<f64>() / err.len() as f64,
        err[err.len() * 95 / 100],
        err[err.len() - 1],
        err.len(),
        disagree,
    );
    Ok(())
}

/// The lean tracer: the field, its bounds in render space and the hit shell's slope.
struct Lean<'a> {
    field: &'a Field,
    lo: Vec3,
    hi: Vec3,
    eps_cone: f32,
}

impl Lean<'_> {
    /// Traces `rays` eight at a time, writes each hit distance (NaN for a miss) to `depth`
    /// and returns the field evaluations made (normals excluded).
    fn trace(&self, rays: &[Ray], depth: &mut [f32]) -> u64 {
        let c = F32x8::splat;
        // Rays that enter the bounds, with their range inside them.
        let mut queue = Vec::with_capacity(rays.len());
        for (i, r) in rays.iter().enumerate() {
            depth[i] = f32::NAN;
            let inv = r.dir.recip();
            let (a, b) = ((self.lo - r.origin) * inv, (self.hi - r.origin) * inv);
            let t0 = a.min(b).max_element().max(r.t_min);
            let t1 = a.max(b).min_element().min(r.t_max);
            if t0 <= t1 {
                queue.push((i, t0, t1));
            }
        }
        let mut next = queue.iter();
        let zero = V3::<F32x8>::splat3([0.0; 3]);
        let (mut o, mut dir) = (zero, zero);
        let (mut t, mut t_end) = (c(0.0), c(-1.0));
        let (mut t_prev, mut r_prev, mut omega) = (c(0.0), c(0.0), c(1.2));
        let mut ray_of: [Option<usize>; 8] = [None; 8];
        let mut hits: Vec<(usize, Vec3)> = Vec::with_capacity(8);
        let mut evals = 0u64;
        loop {
            for (k, slot) in ray_of.iter_mut().enumerate() {
                if slot.is_some() {
                    continue;
                }
                let Some(&(i, t0, t1)) = next.next() else {
                    continue;
                };
                let r = &rays[i];
                (o.x.0[k], o.y.0[k], o.z.0[k]) = (r.origin.x, r.origin.y, r.origin.z);
                (dir.x.0[k], dir.y.0[k], dir.z.0[k]) = (r.dir.x, r.dir.y, r.dir.z);
                (t.0[k], t_end.0[k], t_prev.0[k], r_prev.0[k], omega.0[k]) = (t0, t1, t0, 0.0, 1.2);
                *slot = Some(i);
            }
            if ray_of.iter().all(Option::is_none) {
                break;
            }
            let p = V3::new(o.x + dir.x * t, o.y + dir.y * t, o.z + dir.z * t);
            let r = self.field.distance_lanes(p).abs();
            let hit = F32x8::lt(r, c(self.eps_cone) * t);
            // Keinert et al. 2014: a relaxed step whose sphere leaves a gap is undone.
            let undo = F32x8::and(F32x8::lt(c(1.0), omega), F32x8::lt(r + r_prev, t - t_prev));
            let stepped = F32x8::select(undo, t_prev + r_prev, t + r * omega);
            omega = F32x8::select(undo, c(1.0), omega);
            t_prev = F32x8::select(undo, t_prev, t);
            r_prev = F32x8::select(undo, r_prev, r);
            t = F32x8::select(F32x8::and(hit, F32x8::not(undo)), t, stepped);
            for (k, slot) in ray_of.iter_mut().enumerate() {
                let Some(i) = *slot else { continue };
                evals += 1;
                if hit.0[k] != 0 && undo.0[k] == 0 {
                    depth[i] = t.0[k];
                    hits.push((i, Vec3::new(p.x.0[k], p.y.0[k], p.z.0[k])));
                    if hits.len() == 8 {
                        self.normals(&mut hits);
                    }
                    *slot = None;
                } else if t.0[k] > t_end.0[k] {
                    *slot = None;
                }
            }
        }
        self.normals(&mut hits);
        evals
    }

    /// Normals of up to eight hits from the tetrahedron stencil (four 8-lane evaluations),
    /// as a lean tracer would shade them; the result only has to be computed.
    fn normals(&self, hits: &mut Vec<(usize, Vec3)>) {
        const H: f32 = 1e-4;
        let corners = [
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(-1.0, -1.0, 1.0),
            Vec3::new(-1.0, 1.0, -1.0),
            Vec3::new(1.0, 1.0, 1.0),
        ];
        let mut g = [Vec3::ZERO; 8];
        for k in corners {
            let mut p = V3::<F32x8>::splat3([0.0; 3]);
            for (j, (_, at)) in hits.iter().enumerate() {
                let q = *at + k * H;
                (p.x.0[j], p.y.0[j], p.z.0[j]) = (q.x, q.y, q.z);
            }
            let d = self.field.distance_lanes(p);
            for (j, gj) in g.iter_mut().enumerate().take(hits.len()) {
                *gj += k * d.0[j];
            }
        }
        std::hint::black_box(g.map(Vec3::normalize_or_zero));
        hits.clear();
    }
}
