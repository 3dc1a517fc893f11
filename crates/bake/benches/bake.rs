//! Bake times: bunny (3,674 triangles) at 32/64/128 cells and dragon_res3 (47,794
//! triangles, open scan) at 64, no cache, on rayon pools of 1 and 2 threads; plus one grid
//! sample (f32) for the sampling cost.
//!
//! `cargo bench -p marchmesh-bake`

use std::hint::black_box;
use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use marchmesh_bake::{BakeOptions, bake};

fn load(name: &str) -> marchmesh_meshio::TriangleMesh {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes/meshes")
        .join(name);
    marchmesh_meshio::load_mesh(&p).expect("committed mesh loads")
}

fn benches(c: &mut Criterion) {
    let bunny = load("bunny.obj");
    let dragon = load("dragon_res3.obj");
    let mut g = c.benchmark_group("bake");
    g.sample_size(10);
    for threads in [1usize, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("rayon pool");
        for (name, mesh, res) in [
            ("bunny", &bunny, 32u32),
            ("bunny", &bunny, 64),
            ("bunny", &bunny, 128),
            ("dragon_res3", &dragon, 64),
        ] {
            let opts = BakeOptions {
                resolution: res,
                cache_dir: None,
            };
            g.bench_function(format!("{name}/{res}/{threads}t"), |b| {
                b.iter(|| pool.install(|| bake(black_box(mesh), &opts).expect("bake")))
            });
        }
    }
    g.finish();
    let grid = bake(
        &bunny,
        &BakeOptions {
            resolution: 64,
            cache_dir: None,
        },
    )
    .expect("bake")
    .grid;
    let (lo, hi) = grid.bounds();
    let pts: Vec<Vec3> = (0..1024)
        .map(|i| {
            let f = i as f32;
            lo + (hi - lo)
                * Vec3::new(
                    (f * 0.618).fract(),
                    (f * 0.414).fract(),
                    (f * 0.732).fract(),
                )
        })
        .collect();
    c.bench_function("sample/bunny64/1024pts", |b| {
        b.iter(|| pts.iter().map(|&p| grid.sample(black_box(p))).sum::<f32>())
    });
}

criterion_group!(bench, benches);
criterion_main!(bench);
