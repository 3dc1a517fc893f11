//! Bakes a mesh and measures time, memory and grid error against brute force.
//!
//! `cargo run --release -p marchmesh-bake --example bake_mesh -- scenes/meshes/bunny.obj 64 [samples]`
//!
//! Error is measured at `samples` pseudo-random points inside the grid box (default 2000):
//! grid `sample` minus the brute-force signed distance, in cells and in mesh units; sign
//! disagreements are counted separately (brute force uses the exact winding number).

use std::path::Path;

use glam::Vec3;
use marchmesh_bake::{BakeOptions, bake_with_stats, brute_force_signed_distance};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .map_or("scenes/meshes/bunny.obj", |s| s.as_str());
    let res: u32 = args.get(2).map_or(Ok(64), |s| s.parse())?;
    let samples: usize = args.get(3).map_or(Ok(2000), |s| s.parse())?;
    let mesh = marchmesh_meshio::load_mesh(Path::new(path))?;
    let opts = BakeOptions {
        resolution: res,
        cache_dir: None,
    };
    let (baked, stats) = bake_with_stats(&mesh, &opts)?;
    let g = &baked.grid;
    println!(
        "{path}: {} triangles, closed {}, res {res}: dims {:?}, bake {:.1} ms, grid {} bytes, bvh {} bytes, winding evals {}/{} ({:.1}%)",
        mesh.triangles.len(),
        mesh.is_closed(),
        g.dims,
        baked.bake_ms,
        g.memory_bytes(),
        stats.bvh_bytes,
        stats.winding_evaluations,
        stats.samples,
        100.0 * stats.winding_evaluations as f64 / stats.samples.max(1) as f64
    );
    println!(
        "  phases: bvh {:.1} ms, distance {:.1} ms, sign {:.1} ms",
        stats.bvh_ms, stats.distance_ms, stats.sign_ms
    );
    for n in &baked.notes {
        println!("  note: {n}");
    }
    let (lo, hi) = g.bounds();
    let mut state = 0x1234_5678_9abc_def0u64;
    let mut rnd = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let (mut max_err, mut sum_err, mut sign_bad, mut n) = (0.0f32, 0.0f64, 0usize, 0usize);
    for _ in 0..samples {
        let p = lo + (hi - lo) * Vec3::new(rnd(), rnd(), rnd());
        let exact = brute_force_signed_distance(&mesh, p);
        let s = g.sample(p);
        if (s < 0.0) != (exact < 0.0) && exact.abs() > g.cell_size {
            sign_bad += 1;
            continue;
        }
        let e = (s - exact).abs();
        max_err = max_err.max(e);
        sum_err += e as f64;
        n += 1;
    }
    println!(
        "  error vs brute force at {samples} points: mean {:.4} cells, max {:.4} cells (cell {:.3e}); sign disagreements farther than a cell: {sign_bad}",
        sum_err / n.max(1) as f64 / g.cell_size as f64,
        max_err / g.cell_size,
        g.cell_size
    );
    Ok(())
}
