//! Cost of a sphere-tracing step over the whole field against the field pruned per region
//! (`Field::build_cells`), on the scenes given: every camera ray (the scene's camera, a
//! `SIDE x SIDE` image) sphere-traced with plain steps to a hit (`d < 1e-4 t`), a miss past
//! the field's box or 1000 steps, per variant per round for at least 0.3 s, the variants
//! alternating in every round. Prints per scene and variant the median over rounds of thread CPU time per
//! step (Linux `/proc/thread-self/schedstat`; wall time elsewhere), the steps, the hits, and
//! whether both variants agree on every ray's hit or miss.
//!
//! `cargo run --release -p marchmesh-field --example prune_cost -- SCENE.json... [--side N]
//! [--rounds R] [--depth D] [--exact] [--error-rel E] [--probe] [--pruned-only]`
//! (`--pruned-only`: time only the pruned field, for profiling; `--exact`: prune without
//! cutting smooth folds; `--error-rel`: the cut's error relative to the field's box, default
//! 2^-24; `--probe`: also print how many nodes a ball around hit points keeps, by radius and
//! error: what finer cells could reach)

use std::path::PathBuf;
use std::time::Instant;

use glam::Vec3;
use marchmesh_field::{Field, FieldOptions};

/// Nanoseconds this thread has run (schedstat), or wall-clock nanoseconds since `start`.
fn thread_ns(start: Instant) -> u128 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or_else(|| start.elapsed().as_nanos())
}

struct Trace {
    /// Steps of all traces run.
    steps: u64,
    /// Steps of one trace of every ray.
    steps_once: u64,
    hits: Vec<bool>,
    ns: u128,
}

/// [`trace_once`] repeated until it has run 0.3 s (the thread clock's resolution is coarse).
fn trace(field: &Field, rays: &[Vec3], t_max: f32) -> Trace {
    let start = Instant::now();
    let mut total = trace_once(field, rays, t_max);
    total.steps_once = total.steps;
    while start.elapsed().as_secs_f64() < 0.3 {
        let more = trace_once(field, rays, t_max);
        total.steps += more.steps;
        total.ns += more.ns;
    }
    total
}

fn trace_once(field: &Field, rays: &[Vec3], t_max: f32) -> Trace {
    let start = Instant::now();
    let t0 = thread_ns(start);
    let mut steps = 0u64;
    let mut hits = Vec::with_capacity(rays.len());
    for &d in rays {
        let mut t = 0.0f32;
        let mut hit = false;
        for _ in 0..1000 {
            let v = field.distance(d * t);
            steps += 1;
            if v < 1e-4 * t.max(1.0) {
                hit = true;
                break;
            }
            t += v;
            if t > t_max {
                break;
            }
        }
        hits.push(hit);
    }
    Trace {
        steps,
        steps_once: steps,
        hits,
        ns: thread_ns(start) - t0,
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (mut scenes, mut side, mut rounds, mut depth) = (Vec::new(), 128u32, 3usize, 6u32);
    // The sdf backend's default (`marchmesh_sdf::PRUNE_MAX_ERROR_REL`); `--exact` for 0.
    let mut max_error_rel = 1.0 / 16_777_216.0;
    let mut probe = false;
    let mut pruned_only = false;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut num = || -> Result<u32, Box<dyn std::error::Error>> {
            Ok(args.next().ok_or("missing value")?.parse()?)
        };
        match a.as_str() {
            "--side" => side = num()?,
            "--rounds" => rounds = num()? as usize,
            "--depth" => depth = num()?,
            "--exact" => max_error_rel = 0.0,
            "--probe" => probe = true,
            "--pruned-only" => pruned_only = true,
            "--error-rel" => {
                max_error_rel = args.next().ok_or("missing value")?.parse()?;
            }
            _ => scenes.push(PathBuf::from(a)),
        }
    }
    for path in &scenes {
        let scene = marchmesh_scene::load(path)?;
        let whole = Field::compile_scene(&scene, &FieldOptions::default())?;
        let mut pruned = Field::compile_scene(&scene, &FieldOptions::default())?;
        let t0 = Instant::now();
        let stats = pruned.build_cells(depth, max_error_rel);
        let build_ms = t0.elapsed().as_secs_f64() * 1e3;
        let cam = &scene.camera;
        let half = (0.5 * cam.vfov_rad).tan();
        let rays: Vec<Vec3> = (0..side * side)
            .map(|i| {
                let (x, y) = (i % side, i / side);
                let sx = (2.0 * (f64::from(x) + 0.5) / f64::from(side) - 1.0) * half;
                let sy = (1.0 - 2.0 * (f64::from(y) + 0.5) / f64::from(side)) * half;
                (cam.forward + cam.right * sx + cam.up * sy)
                    .normalize()
                    .as_vec3()
            })
            .collect();
        let t_max = whole
            .bounds()
            .map_or(100.0, |(lo, hi)| lo.length().max(hi.length()) as f32 + 1.0);
        let (mut cw, mut cp) = (Vec::new(), Vec::new());
        let (mut last_w, mut last_p) = (None, None);
        for _ in 0..rounds {
            let p = trace(&pruned, &rays, t_max);
            let w = if pruned_only {
                trace_once(&pruned, &rays, t_max)
            } else {
                trace(&whole, &rays, t_max)
            };
            cw.push(w.ns as f64 / w.steps.max(1) as f64);
            cp.push(p.ns as f64 / p.steps.max(1) as f64);
            last_w = Some(w);
            last_p = Some(p);
        }
        let (w, p) = (last_w.ok_or("no rounds")?, last_p.ok_or("no rounds")?);
        if probe {
            // Kept nodes of balls around hit points, by radius and error.
            let prog = whole.program_f64();
            let index = marchmesh_field::prune::PruneIndex::build(prog);
            let hits: Vec<glam::DVec3> = rays
                .iter()
                .filter_map(|&d| {
                    let mut t = 0.0f32;
                    for _ in 0..1000 {
                        let v = whole.distance(d * t);
                        if v < 1e-4 * t.max(1.0) {
                            return Some((d * t).as_dvec3());
                        }
                        t += v;
                        if t > t_max {
                            return None;
                        }
                    }
                    None
                })
                .step_by(4)
                .take(200)
                .collect();
            for r in [0.04, 0.02, 0.01, 0.005, 0.001, 0.0] {
                for err in [0.0, 1e-7, 1e-5, 1e-3] {
                    let (mut sum, mut max, mut work) = (0usize, 0usize, 0usize);
                    for &h in &hits {
                        let pr =
                            marchmesh_field::prune::prune_indexed(prog, &index, &[], h, r, err);
                        sum += pr.program.instrs.len();
                        max = max.max(pr.program.instrs.len());
                        work += pr.work;
                    }
                    println!(
                        "  r {r}: err {err}: mean kept {:.1}, max {max}, mean work {:.0} over {} hit points",
                        sum as f64 / hits.len().max(1) as f64,
                        work as f64 / hits.len().max(1) as f64,
                        hits.len()
                    );
                }
            }
        }
        let agree = w.hits.iter().zip(&p.hits).filter(|(a, b)| a == b).count();
        println!(
            "{}: nodes {}, cells (program, far, largest program, whole, subset, subset children, fine lists, fine children) {:?} built in {:.0} ms; whole {:.1} ns/step ({} steps a trace, {} hits); pruned {:.1} ns/step ({} steps a trace, {} hits); hit/miss agree on {}/{} rays",
            path.display(),
            whole.node_count(),
            stats.map(|s| (
                s.program_cells,
                s.far_cells,
                s.max_program_nodes,
                s.whole_cells,
                s.subset_cells,
                s.subset_children,
                s.fine_lists,
                s.fine_children
            )),
            build_ms,
            median(cw),
            w.steps_once,
            w.hits.iter().filter(|h| **h).count(),
            median(cp),
            p.steps_once,
            p.hits.iter().filter(|h| **h).count(),
            agree,
            rays.len()
        );
    }
    Ok(())
}
