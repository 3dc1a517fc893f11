//! Prints the SDF backend's accuracy against the reference on every conformance case (the
//! numbers behind the tolerances in `tests/conformance.rs`).
//!
//! `cargo run --release -p marchmesh-sdf --example conformance_report`

use marchmesh_conformance::{CASES, run_case};
use marchmesh_core::Geometry;
use marchmesh_scene::Scene;
use marchmesh_sdf::SdfOptions;

fn main() {
    // MESH_RES overrides the mesh grid resolution (default 64), to measure its effect.
    let res = std::env::var("MESH_RES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(SdfOptions::DEFAULT.grid_res);
    // EPS_PX and MAX_STEPS override the hit shell and the step budget (candidate defaults).
    let mut opts = SdfOptions {
        grid_res: res,
        ..SdfOptions::DEFAULT
    };
    if let Some(k) = std::env::var("EPS_PX").ok().and_then(|v| v.parse().ok()) {
        opts.eps_px = k;
    }
    if let Some(n) = std::env::var("MAX_STEPS").ok().and_then(|v| v.parse().ok()) {
        opts.max_steps = n;
    }
    let backend =
        |s: &Scene| marchmesh_sdf::build(s, &opts).map(|g| Box::new(g) as Box<dyn Geometry>);
    let reference = |s: &Scene| {
        marchmesh_reference::build(s, &Default::default()).map(|g| Box::new(g) as Box<dyn Geometry>)
    };
    println!(
        "case | silhouette % | depth rel p95 | normal mean deg | normal p95 deg | material mismatch | exhaustion % | mean steps"
    );
    for c in CASES {
        let scene = marchmesh_conformance::case_scene(c.id);
        match backend(&scene) {
            Err(e) => {
                println!("{} | backend cannot build: {e}", c.name);
                continue;
            }
            Ok(g) => {
                if std::env::var_os("NOTES").is_some() {
                    let r = g.report();
                    println!(
                        "  {}: memory {} B, phases {:?}, counters {:?}",
                        c.name, r.memory_bytes, r.build_phases_ms, r.counters
                    );
                    for n in r.notes {
                        println!("  note: {n}");
                    }
                }
            }
        }
        let r = run_case(c.id, &backend, &reference);
        let a = &r.accuracy;
        println!(
            "{} | {:.2} | {:.2e} | {:.3} | {:.3} | {} | {:.3} | {:.1}",
            c.name,
            a.silhouette_mismatch_pct,
            a.depth_rel_p95,
            a.normal_deg_mean,
            a.normal_deg_p95,
            a.material_mismatch,
            100.0 * r.stats.step_exhaustion_rate(),
            r.stats.mean_steps()
        );
    }
}
