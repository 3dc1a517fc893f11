//! Primary rays of `seed-spheres` (and `csg`) at 256x256: 8-ray lockstep batches against one
//! ray at a time (same results), and field evaluation per point; full renders at 500x500
//! with 1 and 2 threads against the naive baseline ([`naive`]: recursive tree evaluator,
//! fixed epsilon, no bounds, no relaxation), Mrays/s as criterion throughput (elements =
//! rays of one render) and mean steps per ray printed.

mod naive;

use std::hint::black_box;
use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use marchmesh_core::{
    BackgroundSampler, Geometry, Ray, RenderOptions, RenderSpace, TraceResult, compare, render,
};
use marchmesh_scene::Scene;
use marchmesh_sdf::{SdfOptions, build};

const SIDE: u32 = 256;

fn load(name: &str) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes")
        .join(name);
    marchmesh_scene::load(&path)
        .expect("committed scene")
        .with_image_size(SIDE, SIDE)
        .expect("size")
}

/// One primary ray per pixel centre, render space.
fn primary_rays(scene: &Scene) -> Vec<Ray> {
    let _ = RenderSpace::of(scene);
    let c = &scene.camera;
    let mut rays = Vec::with_capacity((c.width * c.height) as usize);
    for y in 0..c.height {
        for x in 0..c.width {
            // The integrator's camera rays (pixel centres), bit for bit.
            rays.push(marchmesh_core::camera::primary_ray(
                c,
                x,
                y,
                glam::DVec2::splat(0.5),
                scene.render.max_distance,
            ));
        }
    }
    rays
}

fn bench(c: &mut Criterion) {
    for name in ["seed-spheres.json", "csg.json"] {
        let scene = load(name);
        let rays = primary_rays(&scene);
        let mut group = c.benchmark_group(format!("primary_{}", name.trim_end_matches(".json")));
        group.throughput(Throughput::Elements(rays.len() as u64));
        group.sample_size(10);
        for lockstep in [true, false] {
            let g = build(
                &scene,
                &SdfOptions {
                    lockstep,
                    ..SdfOptions::DEFAULT
                },
            )
            .expect("builds");
            let mut out = vec![TraceResult::default(); rays.len()];
            // Rows of rays, as the core integrator hands them over.
            group.bench_function(if lockstep { "lockstep8" } else { "single" }, |b| {
                b.iter(|| {
                    for (r, o) in rays
                        .chunks(SIDE as usize)
                        .zip(out.chunks_mut(SIDE as usize))
                    {
                        g.closest_hits(black_box(r), o);
                    }
                })
            });
            let steps: u64 = out.iter().map(|r| r.work.steps as u64).sum();
            eprintln!(
                "{name} lockstep={lockstep}: mean steps per primary ray {:.2}",
                steps as f64 / rays.len() as f64
            );
        }
        group.finish();
        // Field evaluation per point along the rays (scalar vs 8 lanes).
        let g = build(&scene, &SdfOptions::DEFAULT).expect("builds");
        let pts: Vec<Vec3> = rays.iter().step_by(7).map(|r| r.dir * 3.0).collect();
        let mut group = c.benchmark_group(format!("field_{}", name.trim_end_matches(".json")));
        group.throughput(Throughput::Elements(pts.len() as u64));
        group.bench_function("scalar", |b| {
            b.iter(|| pts.iter().map(|p| g.field().distance(*p)).sum::<f32>())
        });
        group.bench_function("x8", |b| {
            b.iter(|| {
                pts.chunks_exact(8)
                    .map(|c| {
                        g.field()
                            .distance_x8(std::array::from_fn(|i| c[i]))
                            .iter()
                            .sum::<f32>()
                    })
                    .sum::<f32>()
            })
        });
        group.finish();
    }
}

fn renders(c: &mut Criterion) {
    for name in ["seed-spheres.json", "csg.json"] {
        let scene = load(name).with_image_size(500, 500).expect("size");
        let bg = BackgroundSampler::load(&scene.background).expect("background");
        let sdf = build(&scene, &SdfOptions::DEFAULT).expect("builds");
        let baseline = naive::NaiveGeometry::new(&scene);
        let mut group = c.benchmark_group(format!("render500_{}", name.trim_end_matches(".json")));
        group.sample_size(10);
        let runs: [(&str, &dyn Geometry, usize); 4] = [
            ("sdf_1t", &sdf, 1),
            ("sdf_2t", &sdf, 2),
            ("naive_1t", &baseline, 1),
            ("naive_2t", &baseline, 2),
        ];
        let mut fbs = Vec::new();
        for (label, g, threads) in runs {
            let opts = RenderOptions {
                threads,
                ..Default::default()
            };
            let out = render(&scene, g, &bg, &opts, &|| {}).expect("render");
            let rays = out.stats.total_rays();
            eprintln!(
                "{name} {label}: {} rays, mean steps per ray {:.2}, exhaustion {:.4}%, {:.2} Mrays/s (single run)",
                rays,
                out.stats.mean_steps(),
                100.0 * out.stats.step_exhaustion_rate(),
                rays as f64 / out.elapsed.as_secs_f64() / 1e6
            );
            if threads == 1 {
                fbs.push(out.framebuffer);
            }
            group.throughput(Throughput::Elements(rays));
            group.bench_function(label, |b| {
                b.iter(|| render(&scene, g, &bg, &opts, &|| {}).expect("render"))
            });
        }
        if let [a, b] = &fbs[..]
            && let Ok(acc) = compare(a, b)
        {
            eprintln!(
                "{name}: sdf vs naive: silhouette {:.3}%, depth rel p95 {:.2e}, normal mean {:.3} deg",
                acc.silhouette_mismatch_pct, acc.depth_rel_p95, acc.normal_deg_mean
            );
        }
        group.finish();
    }
}

criterion_group!(benches, bench, renders);
criterion_main!(benches);
