//! Bakes a mesh into a sparse brick grid and a dense grid and reports bytes, time per phase
//! and error against brute force, near the surface and everywhere.
//!
//! `cargo run --release -p marchmesh-bake --example bake_sparse -- scenes/meshes/bunny.obj 256 [band] [f32|u16|u8] [trilinear|tricubic|normals] [dense-res]`
//!
//! Error at pseudo-random points of the grid box: grid value minus the brute-force signed
//! distance (exact winding number), in cells; "near" = within 1 cell of the surface. Also
//! checks the conservative bound `value <= |exact| + half a cell diagonal + quantization`
//! outside the surface and counts violations.

use std::path::Path;

use glam::Vec3;
use marchmesh_bake::{
    BakeOptions, Quantization, Reconstruction, SparseOptions, bake_sparse, bake_with_stats,
    brute_force_signed_distance,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .map_or("scenes/meshes/bunny.obj", |s| s.as_str());
    let res: u32 = args.get(2).map_or(Ok(256), |s| s.parse())?;
    let band: u32 = args.get(3).map_or(Ok(2), |s| s.parse())?;
    let quantization = match args.get(4).map_or("f32", |s| s.as_str()) {
        "u16" => Quantization::U16,
        "u8" => Quantization::U8,
        _ => Quantization::F32,
    };
    let reconstruction = match args.get(5).map_or("trilinear", |s| s.as_str()) {
        "tricubic" => Reconstruction::Tricubic,
        "normals" => Reconstruction::Normals,
        _ => Reconstruction::Trilinear,
    };
    let dense_res: u32 = args.get(6).map_or(Ok(0), |s| s.parse())?;
    let mesh = marchmesh_meshio::load_mesh(Path::new(path))?;
    let opts = SparseOptions {
        resolution: res,
        band_voxels: band,
        quantization,
        reconstruction,
        cache_dir: None,
    };
    let (baked, s) = bake_sparse(&mesh, &opts)?;
    let g = &baked.grid;
    println!(
        "{path}: {} triangles, closed {}, sparse res {res} band {band} {} {}: {} bytes, {} bricks of {} brick cells ({} candidates, {} signed by winding numbers), bake {:.1} ms",
        mesh.triangles.len(),
        mesh.is_closed(),
        quantization.name(),
        reconstruction.name(),
        g.memory_bytes(),
        s.bricks,
        s.brick_cells,
        s.candidates,
        s.winding_bricks,
        baked.bake_ms
    );
    println!(
        "  phases ms: bvh {:.1}, coarse {:.1}, distance {:.1}, sign {:.1}, encode {:.1}; bytes: bvh {}, coarse {}, band {}, grid {}; distances {}, windings {}",
        s.bvh_ms,
        s.coarse_ms,
        s.distance_ms,
        s.sign_ms,
        s.encode_ms,
        s.bvh_bytes,
        s.coarse_bytes,
        s.band_bytes,
        s.grid_bytes,
        s.distance_evaluations,
        s.winding_evaluations
    );
    if dense_res > 0 {
        let (d, ds) = bake_with_stats(
            &mesh,
            &BakeOptions {
                resolution: dense_res,
                cache_dir: None,
            },
        )?;
        println!(
            "  dense {dense_res}: {} bytes, bake {:.1} ms (bvh {:.1}, distance {:.1}, sign {:.1})",
            d.grid.memory_bytes(),
            d.bake_ms,
            ds.bvh_ms,
            ds.distance_ms,
            ds.sign_ms
        );
    }
    memory_breakdown(g);
    let h = g.cell_size();
    let (lo, hi) = g.bounds();
    let mut state = 0x1234_5678_9abc_def0u64;
    let mut rnd = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let allow = 0.5 * 3f32.sqrt() * h + quantization.max_error(g.clamp()) + 1e-5 * h;
    let (mut n_near, mut sum_near, mut max_near, mut violations, mut n) = (0, 0.0, 0.0f32, 0, 0);
    for _ in 0..20000 {
        let p = lo + (hi - lo) * Vec3::new(rnd(), rnd(), rnd());
        let exact = brute_force_signed_distance(&mesh, p);
        let v = g.sample(p);
        n += 1;
        if v.abs() > exact.abs() + allow {
            violations += 1;
        }
        if exact.abs() < h {
            let e = (v - exact).abs() / h;
            n_near += 1;
            sum_near += e as f64;
            max_near = max_near.max(e);
        }
    }
    println!(
        "  {n} points: {violations} exceed |exact| + {:.3} cells; {n_near} near the surface: mean |error| {:.4} cells, max {:.3} cells",
        allow / h,
        sum_near / n_near.max(1) as f64,
        max_near
    );
    Ok(())
}

/// Where the grid's bytes go: brick samples against brick-cell words, the samples' distances
/// (within one cell of the surface, within the band, clamped), and what 4^3-cell bricks
/// (5^3 samples, kept under the same rule) would hold instead.
fn memory_breakdown(g: &marchmesh_bake::SparseGrid) {
    let h = g.cell_size();
    let [bx, by, bz] = g.bricks();
    let b = marchmesh_bake::sparse::BRICK;
    let (mut n, mut near1, mut in_band, mut clamped) = (0u64, 0u64, 0u64, 0u64);
    let keep = (g.band_voxels() as f32 + 0.5 * 3f32.sqrt()) * h * (1.0 + 1e-4);
    let mut sub_kept = 0u64;
    let mut sub_total = 0u64;
    for k in 0..bz {
        for j in 0..by {
            for i in 0..bx {
                let w = g.cells()[(i + bx * (j + by * k)) as usize];
                if w & (1 << 31) != 0 {
                    continue;
                }
                let mut sub = [false; 8];
                for c in 0..=b {
                    for bb in 0..=b {
                        for a in 0..=b {
                            let Some(v) = g.value(b * i + a, b * j + bb, b * k + c) else {
                                continue;
                            };
                            n += 1;
                            let d = v.abs();
                            near1 += u64::from(d <= h);
                            in_band += u64::from(d <= g.band_voxels() as f32 * h);
                            clamped += u64::from(d >= g.clamp() * 0.999);
                            if d <= keep {
                                for (s, kept) in sub.iter_mut().enumerate() {
                                    let lo =
                                        [s & 1, (s >> 1) & 1, s >> 2].map(|x| x as u32 * b / 2);
                                    if [a, bb, c]
                                        .iter()
                                        .zip(lo)
                                        .all(|(&x, l)| x >= l && x <= l + b / 2)
                                    {
                                        *kept = true;
                                    }
                                }
                            }
                        }
                    }
                }
                sub_total += 8;
                sub_kept += sub.iter().filter(|x| **x).count() as u64;
            }
        }
    }
    let q = g.samples().quantization().bytes() as u64;
    let words = g.cells().len() as u64 * 4;
    let words4 = words * 8;
    println!(
        "  memory: samples {} B, brick-cell words {} B; of {n} samples: {:.1}% within 1 cell, {:.1}% within the band, {:.1}% clamped; 4^3 bricks: {sub_kept} of {sub_total} sub-bricks kept -> samples {} B + words {} B (one level) = {} B",
        g.samples().bytes(),
        words,
        100.0 * near1 as f64 / n.max(1) as f64,
        100.0 * in_band as f64 / n.max(1) as f64,
        100.0 * clamped as f64 / n.max(1) as f64,
        sub_kept * 125 * q,
        words4,
        sub_kept * 125 * q + words4
    );
}
