//! A full render's ray rate as a fraction of the bare traversal rate: the benchmark's bunny
//! (500x500, as `benches/bvh.rs` frames it) rendered on 1 thread, against the mesh backend's
//! traversal alone of the exact batches that render hands it (camera rays tile by tile through
//! `closest_hits_primary` with the tile's samples, and shadow rays through `occluded_many`),
//! recorded from one untimed render. Rounds interleave the two (bare, render, bare, render ...),
//! each timed on the calling thread's CPU time; prints the median of the per-round ratios
//! `bare time / render time` (= render rays/s over bare rays/s, the same rays on both sides)
//! with their range, and the integrator's own share of the render as `trace_time` sees it.
//!
//! `cargo run --release -p marchmesh-mesh --example render_ratio [-- ROUNDS [LIGHTS [MESH [MODE]]]]`
//!
//! `LIGHTS`: `primary` (default; the scene's default lights with the directional light's
//! shadows off, so the render traces camera rays only: a full primary-ray render), `shadows`
//! (the default lights: camera rays and one shadow ray per lit hit). `MESH`: a file under
//! `scenes/meshes` (default `bunny.obj`). `MODE`: `both` (default), or `bare` or `render` to
//! time only that side (for a profiler).

#[path = "../benches/support/mod.rs"]
mod support;

use std::sync::Mutex;
use std::time::Instant;

use marchmesh_core::{
    BackgroundSampler, BatchPolicy, Cone, Geometry, GeometryReport, OcclusionResult,
    PrimarySamples, Ray, RenderOptions, RenderOutput, Shortcuts, SurfacePoint, Tile, TraceResult,
    Visibility, render_into,
};
use marchmesh_mesh::{MeshOptions, build};
use marchmesh_scene::Light;
use support::*;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// One batch query a render made: its rays, and for camera rays the tile they sample.
enum Batch {
    Primary(Vec<Ray>, Tile),
    Closest(Vec<Ray>),
    Occluded(Vec<Ray>),
}

/// Passes every query through to `inner`, recording the batches.
struct Recorder<'g> {
    inner: &'g dyn Geometry,
    batches: Mutex<Vec<Batch>>,
}

impl Recorder<'_> {
    fn record(&self, b: Batch) {
        self.batches.lock().expect("recorder lock").push(b);
    }
}

impl Geometry for Recorder<'_> {
    fn closest_hit(&self, ray: &Ray) -> TraceResult {
        self.inner.closest_hit(ray)
    }
    fn occluded(&self, ray: &Ray) -> OcclusionResult {
        self.inner.occluded(ray)
    }
    fn closest_hits(&self, rays: &[Ray], out: &mut [TraceResult]) {
        self.record(Batch::Closest(rays.to_vec()));
        self.inner.closest_hits(rays, out);
    }
    fn closest_hits_primary(
        &self,
        rays: &[Ray],
        samples: PrimarySamples<'_>,
        out: &mut [TraceResult],
    ) {
        self.record(Batch::Primary(rays.to_vec(), samples.tile_bounds()));
        self.inner.closest_hits_primary(rays, samples, out);
    }
    fn occluded_many(&self, rays: &[Ray], out: &mut [OcclusionResult]) {
        self.record(Batch::Occluded(rays.to_vec()));
        self.inner.occluded_many(rays, out);
    }
    fn report(&self) -> GeometryReport {
        self.inner.report()
    }
    fn tile_width(&self) -> u32 {
        self.inner.tile_width()
    }
    fn batch_policy(&self) -> BatchPolicy {
        self.inner.batch_policy()
    }
    fn shortcuts(&self) -> Shortcuts {
        self.inner.shortcuts()
    }
    fn cone_visibility(&self, cones: &[Cone], out: &mut [Visibility]) {
        self.inner.cone_visibility(cones, out);
    }
    fn ambient_openness(&self, points: &[SurfacePoint], distance: f32, out: &mut [Visibility]) {
        self.inner.ambient_openness(points, distance, out);
    }
}

/// Seconds the calling thread has run on a CPU (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`):
/// on a loaded machine it leaves out the time spent descheduled. Wall seconds since `start`
/// off Linux or if the clock fails.
#[allow(unsafe_code)] // one libc call, no std equivalent
fn thread_seconds(start: Instant) -> f64 {
    #[cfg(target_os = "linux")]
    {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: `ts` is a valid, writable timespec.
        if unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) } == 0 {
            return ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9;
        }
    }
    start.elapsed().as_secs_f64()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().collect();
    let rounds: usize = args.get(1).map_or(Ok(15), |s| s.parse())?;
    let shadows = match args.get(2).map_or("primary", String::as_str) {
        "primary" => false,
        "shadows" => true,
        other => return Err(format!("LIGHTS must be primary or shadows, not {other:?}").into()),
    };
    let file = args.get(3).map_or("bunny.obj", String::as_str).to_owned();
    let name: &'static str = Box::leak(file.clone().into_boxed_str());
    let mut case = mesh_case(name, &file);
    if !shadows {
        for l in &mut case.scene.lights {
            if let Light::Directional { casts_shadows, .. } | Light::Point { casts_shadows, .. } = l
            {
                *casts_shadows = false;
            }
        }
    }
    let scene = &case.scene;
    let g = build(scene, &MeshOptions { ..case.options })?;
    let bg = BackgroundSampler::load(&scene.background)?;
    let opts = RenderOptions {
        threads: 1,
        aovs: false,
        ..Default::default()
    };
    let mut out = RenderOutput::default();

    // The batches of one render, in its order.
    let recorder = Recorder {
        inner: &g,
        batches: Mutex::new(Vec::new()),
    };
    render_into(scene, &recorder, &bg, &opts, &|| {}, &mut out)?;
    let batches = recorder.batches.into_inner().expect("recorder lock");
    let rays: usize = batches
        .iter()
        .map(|b| match b {
            Batch::Primary(r, _) | Batch::Closest(r) | Batch::Occluded(r) => r.len(),
        })
        .sum();
    let widest = batches
        .iter()
        .map(|b| match b {
            Batch::Primary(r, _) | Batch::Closest(r) | Batch::Occluded(r) => r.len(),
        })
        .max()
        .unwrap_or(0);
    let mut hits = vec![TraceResult::default(); widest];
    let mut occl = vec![OcclusionResult::default(); widest];

    let clock = Instant::now();
    let mut bare = || {
        let t = thread_seconds(clock);
        for b in &batches {
            match b {
                Batch::Primary(r, tile) => g.closest_hits_primary(
                    r,
                    PrimarySamples::tile(&scene.camera, *tile),
                    &mut hits[..r.len()],
                ),
                Batch::Closest(r) => g.closest_hits(r, &mut hits[..r.len()]),
                Batch::Occluded(r) => g.occluded_many(r, &mut occl[..r.len()]),
            }
        }
        std::hint::black_box((&hits, &occl));
        thread_seconds(clock) - t
    };
    let full = |out: &mut RenderOutput| -> Res<f64> {
        let t = thread_seconds(clock);
        render_into(scene, &g, &bg, &opts, &|| {}, out)?;
        Ok(thread_seconds(clock) - t)
    };
    // Warm-up.
    bare();
    full(&mut out)?;
    // One side only, for a profiler.
    match args.get(4).map_or("both", String::as_str) {
        "both" => {}
        "bare" => {
            let t: f64 = (0..rounds).map(|_| bare()).sum();
            println!("bare only: {:.2} ms per pass", t / rounds as f64 * 1e3);
            return Ok(());
        }
        "render" => {
            let mut t = 0.0;
            for _ in 0..rounds {
                t += full(&mut out)?;
            }
            println!("render only: {:.2} ms per render", t / rounds as f64 * 1e3);
            return Ok(());
        }
        other => return Err(format!("MODE must be both, bare or render, not {other:?}").into()),
    }
    let (mut ratios, mut bares, mut fulls, mut traced) = (vec![], vec![], vec![], vec![]);
    for _ in 0..rounds {
        let b = bare();
        let f = full(&mut out)?;
        ratios.push(b / f);
        bares.push(b);
        fulls.push(f);
        let t = &out.stats.trace_time;
        let ns = t.camera_ns + t.shadow_ns + t.ambient_occlusion_ns + t.bounce_ns;
        traced.push(ns as f64 * 1e-9 / out.elapsed.as_secs_f64());
    }
    let (lo, hi) = ratios
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, h), &r| (l.min(r), h.max(r)));
    println!(
        "{name} 500x500, 1 thread, {} ({} batches, {rays} rays), {rounds} rounds:",
        if shadows {
            "camera and shadow rays"
        } else {
            "camera rays only"
        },
        batches.len()
    );
    println!(
        "  bare traversal {:.2} ms ({:.2} Mrays/s), full render {:.2} ms ({:.2} Mrays/s)",
        median(bares.clone()) * 1e3,
        rays as f64 / median(bares) * 1e-6,
        median(fulls.clone()) * 1e3,
        rays as f64 / median(fulls) * 1e-6,
    );
    println!(
        "  render rate / bare rate: median {:.3} (range {lo:.3}-{hi:.3}); the render's own trace_time: {:.3} of its wall time",
        median(ratios),
        median(traced)
    );
    Ok(())
}
