//! BVH build and 500x500 primary + shadow rays through the mesh backend, against the same
//! triangles and rays traced by obvhs directly (no marchmesh code in the loop), so the
//! backend's throughput can be quoted as a ratio of raw obvhs measured in the same run.
//!
//! Meshes: bunny (3.7k triangles), dragon_res3 (48k), and a sphere tessellated at a fixed
//! level to ~1M triangles. BVHs: Bvh2 and CwBvh (medium preset). Threads: 1 and 2 (local
//! rayon pools). Run: `cargo bench -p marchmesh-mesh --bench bvh` (add `-- --quick` for a
//! short run).

mod support;

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3A;
use marchmesh_core::Geometry;
use marchmesh_mesh::{BvhKind, MeshOptions, build};
use support::*;

fn bench(c: &mut Criterion) {
    let mut cases = vec![
        mesh_case("bunny", "bunny.obj"),
        mesh_case("dragon_res3", "dragon_res3.obj"),
    ];
    if std::env::var_os("MARCHMESH_BENCH_SKIP_1M").is_none() {
        cases.push(sphere_case());
    }
    for case in &cases {
        let mut group = c.benchmark_group(format!("build/{}", case.name));
        group.sample_size(10);
        group.throughput(Throughput::Elements(case.tris.len() as u64));
        for kind in [BvhKind::Bvh2, BvhKind::CwBvh, BvhKind::Wide] {
            let options = MeshOptions {
                bvh: Some(kind),
                ..case.options
            };
            group.bench_function(BenchmarkId::new("marchmesh", format!("{kind:?}")), |b| {
                b.iter(|| black_box(build(&case.scene, &options).expect("build")))
            });
            group.bench_function(BenchmarkId::new("obvhs_raw", format!("{kind:?}")), |b| {
                b.iter(|| black_box(raw_build(kind, &case.tris)))
            });
        }
        group.finish();

        let primary = primary_rays(&case.scene);
        for kind in [BvhKind::Bvh2, BvhKind::CwBvh, BvhKind::Wide] {
            let options = MeshOptions {
                bvh: Some(kind),
                ..case.options
            };
            let g = build(&case.scene, &options).expect("build");
            let (lo, hi) =
                case.tris
                    .iter()
                    .fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(lo, hi), t| {
                        (
                            lo.min(t.v0).min(t.v1).min(t.v2),
                            hi.max(t.v0).max(t.v1).max(t.v2),
                        )
                    });
            let shadow = shadow_rays(&g, &primary, (hi - lo).max_element());
            let raw = raw_build(kind, &case.tris);
            // Both must see the same scene.
            let agree = primary
                .iter()
                .step_by(97)
                .filter(|r| {
                    let a = g.closest_hit(r).hit().map_or(f32::INFINITY, |h| h.t);
                    let b = raw_closest(&raw, r);
                    a == b || (a - b).abs() <= 1e-5 * b
                })
                .count();
            assert_eq!(
                agree,
                primary.iter().step_by(97).count(),
                "{}: backend and raw obvhs disagree",
                case.name
            );
            eprintln!(
                "{} {kind:?}: {} primary + {} shadow rays per iteration; build phases {:?}; memory {} bytes",
                case.name,
                primary.len(),
                shadow.len(),
                g.report().build_phases_ms,
                g.report().memory_bytes
            );
            let mut group = c.benchmark_group(format!("trace/{}/{kind:?}", case.name));
            group.sample_size(10);
            group.throughput(Throughput::Elements((primary.len() + shadow.len()) as u64));
            for threads in [1usize, 2] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .expect("pool");
                group.bench_function(BenchmarkId::new("marchmesh", format!("{threads}t")), |b| {
                    b.iter(|| pool.install(|| black_box(trace_backend(&g, &primary, &shadow))))
                });
                group.bench_function(BenchmarkId::new("obvhs_raw", format!("{threads}t")), |b| {
                    b.iter(|| pool.install(|| black_box(trace_raw(&raw, &primary, &shadow))))
                });
            }
            group.finish();
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
