//! Share of a 1-thread render of the benchmark's bunny (500x500, scene defaults) spent
//! outside ray traversal: the same render with the geometry stubbed to a constant miss,
//! interleaved with the real one, medians of ROUNDS. Both render into one reused output
//! (`render_into`, as benchmarks repeating a render do); `fresh` renders with `render`,
//! allocating the framebuffer each time; `stub` or `real` times only that one (for profiling).
//! The renders record no AOVs, as the harness's timed repeats (`RenderOptions::aovs`); a
//! fourth argument `aovs` records them (the default of `render`).
//!
//! `cargo run --release -p marchmesh-mesh --example harness_overhead [-- ROUNDS [BVH [MODE [aovs]]]]`
//! (MODE: `both`, `fresh`, `stub` or `real`)

#[path = "../benches/support/mod.rs"]
mod support;

use std::time::Instant;

use marchmesh_core::{
    BackgroundSampler, Geometry, GeometryReport, NoHit, OcclusionResult, Ray, RenderOptions,
    RenderOutput, Termination, TraceResult, render, render_into,
};
use marchmesh_mesh::{BvhKind, MeshOptions, build};
use support::*;

/// Misses everything at no cost, in the screen tiles the mesh backend asks for (its
/// `tile_width`), so the stub render does the integrator's work of the real one.
struct Miss {
    tile_width: u32,
}

fn miss() -> TraceResult {
    TraceResult::not_found(NoHit::Miss, Default::default())
}

fn clear() -> OcclusionResult {
    OcclusionResult {
        occluded: false,
        termination: Termination::Miss,
        work: Default::default(),
    }
}

impl Geometry for Miss {
    fn tile_width(&self) -> u32 {
        self.tile_width
    }

    fn closest_hit(&self, _: &Ray) -> TraceResult {
        miss()
    }
    fn occluded(&self, _: &Ray) -> OcclusionResult {
        clear()
    }
    fn closest_hits(&self, _: &[Ray], out: &mut [TraceResult]) {
        out.fill(miss());
    }
    fn occluded_many(&self, _: &[Ray], out: &mut [OcclusionResult]) {
        out.fill(clear());
    }
    fn report(&self) -> GeometryReport {
        GeometryReport::default()
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let rounds: usize = args.get(1).map_or(Ok(7), |s| s.parse())?;
    let bvh = match args.get(2).map_or("wide", String::as_str) {
        "bvh2" => BvhKind::Bvh2,
        "cwbvh" => BvhKind::CwBvh,
        _ => BvhKind::Wide,
    };
    let case = mesh_case("bunny", "bunny.obj");
    let g = build(
        &case.scene,
        &MeshOptions {
            bvh: Some(bvh),
            ..case.options
        },
    )?;
    let stub_geometry = Miss {
        tile_width: g.tile_width(),
    };
    let bg = BackgroundSampler::load(&case.scene.background)?;
    let aovs = args.get(4).is_some_and(|a| a == "aovs");
    let opts = RenderOptions {
        threads: 1,
        aovs,
        ..Default::default()
    };
    let mode = args.get(3).map_or("", String::as_str);
    let fresh = mode == "fresh";
    let mut out = RenderOutput::default();
    let mut time = |geometry: &dyn Geometry| -> Result<f64, Box<dyn std::error::Error>> {
        let t = Instant::now();
        if fresh {
            render(&case.scene, geometry, &bg, &opts, &|| {})?;
        } else {
            render_into(&case.scene, geometry, &bg, &opts, &|| {}, &mut out)?;
        }
        Ok(t.elapsed().as_secs_f64())
    };
    // Warm-up; a profiled run (`stub` or `real`) runs only its own render.
    if mode != "stub" {
        time(&g)?;
    }
    if mode != "real" {
        time(&stub_geometry)?;
    }
    let (mut real, mut stub) = (Vec::new(), Vec::new());
    for _ in 0..rounds {
        if mode != "stub" {
            real.push(time(&g)?);
        }
        if mode != "real" {
            stub.push(time(&stub_geometry)?);
        }
    }
    if mode == "stub" || mode == "real" {
        let t = median(if mode == "stub" { stub } else { real });
        println!(
            "bunny {bvh:?} (AOVs {aovs}): {mode} only: {:.2} ms",
            t * 1e3
        );
        return Ok(());
    }
    let (r, s) = (median(real), median(stub));
    println!(
        "bunny {bvh:?}{}{}: render {:.1} ms, geometry stubbed to a miss {:.1} ms: overhead {:.1}% of render time",
        if fresh { " (fresh framebuffers)" } else { "" },
        if aovs { " with AOVs" } else { "" },
        r * 1e3,
        s * 1e3,
        100.0 * s / r
    );
    Ok(())
}
