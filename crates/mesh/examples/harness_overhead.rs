//! Share of a 1-thread render of the benchmark's bunny (500x500, scene defaults) spent
//! outside ray traversal: the same render with the geometry stubbed to a constant miss,
//! interleaved with the real one, medians of ROUNDS.
//!
//! `cargo run --release -p marchmesh-mesh --example harness_overhead [-- ROUNDS [BVH]]`

#[path = "../benches/support/mod.rs"]
mod support;

use std::time::Instant;

use marchmesh_core::{
    BackgroundSampler, Geometry, GeometryReport, NoHit, OcclusionResult, Ray, RenderOptions,
    Termination, TraceResult, render,
};
use marchmesh_mesh::{BvhKind, MeshOptions, build};
use support::*;

/// Misses everything at no cost.
struct Miss;

impl Geometry for Miss {
    fn closest_hit(&self, _: &Ray) -> TraceResult {
        TraceResult::not_found(NoHit::Miss, Default::default())
    }
    fn occluded(&self, _: &Ray) -> OcclusionResult {
        OcclusionResult {
            occluded: false,
            termination: Termination::Miss,
            work: Default::default(),
        }
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
            bvh,
            ..case.options
        },
    )?;
    let bg = BackgroundSampler::load(&case.scene.background)?;
    let opts = RenderOptions {
        threads: 1,
        ..Default::default()
    };
    let time = |geometry: &dyn Geometry| -> Result<f64, Box<dyn std::error::Error>> {
        let t = Instant::now();
        render(&case.scene, geometry, &bg, &opts, &|| {})?;
        Ok(t.elapsed().as_secs_f64())
    };
    time(&g)?;
    let (mut real, mut stub) = (Vec::new(), Vec::new());
    for _ in 0..rounds {
        real.push(time(&g)?);
        stub.push(time(&Miss)?);
    }
    let (r, s) = (median(real), median(stub));
    println!(
        "bunny {bvh:?}: render {:.1} ms, geometry stubbed to a miss {:.1} ms: overhead {:.1}% of render time",
        r * 1e3,
        s * 1e3,
        100.0 * s / r
    );
    Ok(())
}
