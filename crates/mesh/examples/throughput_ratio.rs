//! Backend throughput as a ratio of raw obvhs, measured by interleaving the two (A B A B ...)
//! so that load from other processes hits both alike; prints medians. Same cases, rays and
//! baseline as `benches/bvh.rs`.
//!
//! `cargo run --release -p marchmesh-mesh --example throughput_ratio [-- ROUNDS [1m]]`

#[path = "../benches/support/mod.rs"]
mod support;

use std::time::Instant;

use glam::Vec3A;
use marchmesh_mesh::{BvhKind, MeshOptions, build};
use support::*;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let rounds: usize = args.get(1).map_or(Ok(7), |s| s.parse())?;
    let mut cases = vec![
        mesh_case("bunny", "bunny.obj"),
        mesh_case("dragon_res3", "dragon_res3.obj"),
    ];
    if args.iter().any(|a| a == "1m") {
        cases.push(sphere_case());
    }
    println!("case           bvh    threads  backend Mrays/s  obvhs Mrays/s  ratio");
    for case in &cases {
        let primary = primary_rays(&case.scene);
        for kind in [BvhKind::Bvh2, BvhKind::CwBvh, BvhKind::Wide] {
            let g = build(
                &case.scene,
                &MeshOptions {
                    bvh: Some(kind),
                    ..case.options
                },
            )?;
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
            let rays = (primary.len() + shadow.len()) as f64;
            for threads in [1usize, 2] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()?;
                let (mut a, mut b) = (Vec::new(), Vec::new());
                let mut sink = 0.0;
                for _ in 0..rounds {
                    let t = Instant::now();
                    sink += pool.install(|| trace_backend(&g, &primary, &shadow));
                    a.push(rays / t.elapsed().as_secs_f64() / 1e6);
                    let t = Instant::now();
                    sink += pool.install(|| trace_raw(&raw, &primary, &shadow));
                    b.push(rays / t.elapsed().as_secs_f64() / 1e6);
                }
                let (ma, mb) = (median(a), median(b));
                println!(
                    "{:<14} {:<6} {threads:>7}  {ma:>15.2}  {mb:>13.2}  {:.3}{}",
                    case.name,
                    format!("{kind:?}"),
                    ma / mb,
                    if sink.is_nan() { "?" } else { "" }
                );
            }
        }
    }
    Ok(())
}
