//! Sparse brick grids against brute force and the dense grid: lattice values, trilinear
//! equality, the conservative bound outside the band, quantization error, open meshes, the
//! cache, and hostile options.

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use marchmesh_bake::{
    BakeError, DistanceGrid, Quantization, Reconstruction, SparseGrid, SparseOptions, bake_sparse,
    brute_force_signed_distance, cache,
};
use marchmesh_meshio::{TriangleMesh, load_mesh};

mod common;
use common::cube;
use proptest::prelude::*;

fn bunny() -> TriangleMesh {
    load_mesh(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/meshes/bunny.obj")).unwrap()
}

fn opts(resolution: u32, q: Quantization, r: Reconstruction) -> SparseOptions {
    SparseOptions {
        resolution,
        band_voxels: 2,
        quantization: q,
        reconstruction: r,
        cache_dir: None,
    }
}

fn lattice_point(g: &SparseGrid, i: u32, j: u32, k: u32) -> Vec3 {
    g.min() + g.cell_size() * Vec3::new(i as f32, j as f32, k as f32)
}

/// The brick cell of lattice cell `(i, j, k)` holds a brick.
fn in_brick(g: &SparseGrid, i: u32, j: u32, k: u32) -> bool {
    let b = g.bricks();
    let c = [i / 8, j / 8, k / 8];
    c.iter().zip(b).all(|(c, b)| *c < b)
        && g.cells()[(c[0] + b[0] * (c[1] + b[1] * c[2])) as usize] < (1 << 31)
}

fn unique_dir(tag: &str) -> PathBuf {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    std::env::temp_dir().join(format!(
        "marchmesh-sparse-{tag}-{}-{nanos}",
        std::process::id()
    ))
}

#[test]
fn brick_samples_are_exact_signed_distances_and_trilinear_matches_the_dense_lattice() {
    let mesh = cube(true);
    let (baked, stats) = bake_sparse(
        &mesh,
        &opts(16, Quantization::F32, Reconstruction::Trilinear),
    )
    .unwrap();
    let g = &baked.grid;
    assert!(stats.bricks > 0 && stats.bricks < stats.brick_cells);
    assert_eq!(stats.winding_bricks, 0, "a closed cube has no caps");
    // A dense grid on the same lattice from brute force, clamped like the bricks.
    let dims = g.dims();
    let mut values = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let d = brute_force_signed_distance(&mesh, lattice_point(g, i, j, k));
                values.push(d.clamp(-g.clamp(), g.clamp()));
            }
        }
    }
    let dense = DistanceGrid {
        min: g.min(),
        cell_size: g.cell_size(),
        dims,
        values,
    };
    let mut checked = 0;
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                if let Some(v) = g.value(i, j, k) {
                    let want = dense.value(i, j, k).unwrap();
                    assert!((v - want).abs() < 1e-5, "({i},{j},{k}): {v} vs {want}");
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 1000);
    // Inside bricks the trilinear value is the dense grid's.
    let mut state = 7u64;
    let mut rnd = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let (lo, hi) = g.bounds();
    let mut inside = 0;
    for _ in 0..5000 {
        let p = lo + (hi - lo) * Vec3::new(rnd(), rnd(), rnd());
        let c = ((p - g.min()) / g.cell_size()).as_uvec3();
        if !in_brick(g, c.x, c.y, c.z) {
            continue;
        }
        inside += 1;
        assert!((g.sample(p) - dense.sample(p)).abs() < 1e-5, "{p}");
    }
    assert!(inside > 100);
}

#[test]
fn quantization_error_is_within_its_bound() {
    let mesh = bunny();
    let f = bake_sparse(
        &mesh,
        &opts(48, Quantization::F32, Reconstruction::Trilinear),
    )
    .unwrap()
    .0
    .grid;
    for q in [Quantization::U16, Quantization::U8] {
        let g = bake_sparse(&mesh, &opts(48, q, Reconstruction::Trilinear))
            .unwrap()
            .0
            .grid;
        assert_eq!(g.cells(), f.cells());
        // Half a step, plus f32 rounding of the encode (a few percent of a u16 step).
        let bound = q.max_error(g.clamp()) * 1.05;
        let d = g.dims();
        let mut worst = 0.0f32;
        for k in 0..d[2] {
            for j in 0..d[1] {
                for i in 0..d[0] {
                    if let (Some(a), Some(b)) = (g.value(i, j, k), f.value(i, j, k)) {
                        worst = worst.max((a - b).abs());
                    }
                }
            }
        }
        assert!(worst <= bound, "{q:?}: {worst} > {bound}");
        assert!(worst > 0.0);
        // Bytes: the samples shrink by 2x and 4x.
        assert_eq!(g.samples().bytes() * 4 / q.bytes(), f.samples().bytes());
    }
}

/// The grids the bound is checked on: every quantization and reconstruction of the bunny at
/// 40 cells.
fn bound_grids() -> &'static [(SparseGrid, f32)] {
    static GRIDS: std::sync::OnceLock<Vec<(SparseGrid, f32)>> = std::sync::OnceLock::new();
    GRIDS.get_or_init(|| {
        let mesh = bunny();
        let mut v = Vec::new();
        for q in [Quantization::F32, Quantization::U8] {
            for r in [Reconstruction::Trilinear, Reconstruction::Tricubic] {
                let g = bake_sparse(&mesh, &opts(40, q, r)).unwrap().0.grid;
                // Half a cell diagonal (trilinear), the quantization, and for tricubic the
                // Catmull-Rom overshoot (a tenth of a cell here).
                let extra = if r == Reconstruction::Tricubic {
                    0.1
                } else {
                    0.0
                };
                let allow = (0.5 * 3f32.sqrt() + extra) * g.cell_size()
                    + q.max_error(g.clamp())
                    + 1e-4 * g.cell_size();
                v.push((g, allow));
            }
        }
        v
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// `|field(p)| <= |exact distance| + documented error` at random points in and around
    /// the box: sphere tracing never steps through the surface beyond the error.
    #[test]
    fn field_never_exceeds_the_exact_distance_plus_its_error(
        u in 0.0f32..1.0, v in 0.0f32..1.0, w in 0.0f32..1.0, grow in 0.8f32..1.6
    ) {
        let mesh = bunny();
        for (g, allow) in bound_grids() {
            let (lo, hi) = g.bounds();
            let c = 0.5 * (lo + hi);
            let p = c + (Vec3::new(u, v, w) - 0.5) * (hi - lo) * grow;
            let exact = brute_force_signed_distance(&mesh, p);
            let s = g.sample_f64(p.as_dvec3());
            prop_assert!(s.abs() <= exact.abs() as f64 + *allow as f64,
                "{:?} {:?} at {p}: field {s}, exact {exact}, allowed {allow}",
                g.samples().quantization(), g.reconstruction());
        }
    }
}

#[test]
fn tricubic_is_closer_to_the_surface_than_trilinear_on_a_sphere_like_mesh() {
    // Near the bunny's surface, the cubic reconstruction's mean error is below trilinear's.
    let mesh = bunny();
    let t = bake_sparse(
        &mesh,
        &opts(40, Quantization::F32, Reconstruction::Trilinear),
    )
    .unwrap()
    .0
    .grid;
    let c = bake_sparse(
        &mesh,
        &opts(40, Quantization::F32, Reconstruction::Tricubic),
    )
    .unwrap()
    .0
    .grid;
    let (lo, hi) = t.bounds();
    let mut state = 11u64;
    let mut rnd = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let (mut et, mut ec, mut n) = (0.0f64, 0.0f64, 0);
    while n < 300 {
        let p = lo + (hi - lo) * Vec3::new(rnd(), rnd(), rnd());
        let exact = brute_force_signed_distance(&mesh, p);
        if exact.abs() > 0.5 * t.cell_size() {
            continue;
        }
        et += (t.sample(p) - exact).abs() as f64;
        ec += (c.sample(p) - exact).abs() as f64;
        n += 1;
    }
    assert!(ec < et, "tricubic {ec} vs trilinear {et}");
}

#[test]
fn open_meshes_resign_contradicting_bricks_by_winding_number() {
    // The cube without its top: face sides and the winding number disagree near the
    // opening's rim. Bricks whose neighbouring samples change sign with no room for a
    // surface between them take the winding number's sides; the walls are still found
    // from outside, at the right distance and sign.
    let mesh = cube(false);
    let (b, s) = bake_sparse(
        &mesh,
        &opts(16, Quantization::F32, Reconstruction::Trilinear),
    )
    .unwrap();
    assert!(s.winding_bricks > 0, "{s:?}");
    assert!(b.notes.iter().any(|n| n.contains("not closed")));
    let d = b.grid.sample_f64(DVec3::new(1.05, 0.0, 0.0));
    assert!(d > 0.0 && d < 0.2, "{d}");
    // The closed cube has none.
    let (_, s) = bake_sparse(
        &cube(true),
        &opts(16, Quantization::F32, Reconstruction::Trilinear),
    )
    .unwrap();
    assert_eq!(s.winding_bricks, 0);
}

#[test]
fn cache_round_trip_and_corruption() {
    let dir = unique_dir("cache");
    let mesh = cube(true);
    let o = SparseOptions {
        cache_dir: Some(dir.clone()),
        ..opts(16, Quantization::U8, Reconstruction::Tricubic)
    };
    let (first, _) = bake_sparse(&mesh, &o).unwrap();
    assert!(!first.from_cache);
    let file = cache::sparse_cache_path(&dir, mesh.content_hash(), &o);
    assert!(file.is_file());
    let (second, stats) = bake_sparse(&mesh, &o).unwrap();
    assert!(second.from_cache, "{:?}", second.notes);
    assert_eq!(stats.bricks, 0);
    assert_eq!(first.grid, second.grid);
    // Other options are other keys; decoding against the wrong key is refused.
    let good = std::fs::read(&file).unwrap();
    let other = SparseOptions {
        band_voxels: 3,
        ..o.clone()
    };
    assert!(cache::decode_sparse(&good, mesh.content_hash(), &other).is_err());
    assert!(cache::decode_sparse(&good, mesh.content_hash() ^ 1, &o).is_err());
    assert_ne!(cache::sparse_cache_path(&dir, 1, &other), file);
    // Every single-byte corruption is caught.
    for i in (0..good.len()).step_by(7) {
        let mut c = good.clone();
        c[i] ^= 0x10;
        assert!(
            cache::decode_sparse(&c, mesh.content_hash(), &o).is_err(),
            "byte {i}"
        );
    }
    for (what, bytes) in [
        ("truncated", good[..good.len() - 3].to_vec()),
        ("empty", Vec::new()),
        ("garbage", b"MMSDFBRK not a grid".to_vec()),
    ] {
        std::fs::write(&file, &bytes).unwrap();
        let (b, _) = bake_sparse(&mesh, &o).unwrap();
        assert!(!b.from_cache, "{what}");
        assert!(b.notes.iter().any(|n| n.contains("rejected")), "{what}");
        assert_eq!(b.grid, first.grid, "{what}");
        assert_eq!(std::fs::read(&file).unwrap(), good, "{what}: repaired");
    }
    // A checksum-valid file whose brick words are inconsistent is refused by validation.
    let mut forged = cache::encode_sparse(&first.grid, mesh.content_hash(), &o);
    let words_at = 8 + 4 + 8 + 4 + 4 + 2 + 12 + 12 + 4 + 4 + 8;
    forged[words_at..words_at + 4].copy_from_slice(&123_456u32.to_le_bytes());
    let n = forged.len() - 8;
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &b in &forged[..n] {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    forged[n..].copy_from_slice(&h.to_le_bytes());
    let e = cache::decode_sparse(&forged, mesh.content_hash(), &o).unwrap_err();
    assert!(e.contains("brick"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn normals_cache_round_trip_and_corruption() {
    let dir = unique_dir("cache-normals");
    let mesh = cube(true);
    let o = SparseOptions {
        cache_dir: Some(dir.clone()),
        ..opts(16, Quantization::U8, Reconstruction::Normals)
    };
    let (first, _) = bake_sparse(&mesh, &o).unwrap();
    assert_eq!(first.grid.normals().len(), first.grid.samples().len());
    let (second, _) = bake_sparse(&mesh, &o).unwrap();
    assert!(second.from_cache, "{:?}", second.notes);
    assert_eq!(first.grid, second.grid);
    let file = cache::sparse_cache_path(&dir, mesh.content_hash(), &o);
    let good = std::fs::read(&file).unwrap();
    // The normal codes are the file's tail before the checksum: a corrupted or missing
    // code is caught, and a grid of another reconstruction is another key.
    let tail = good.len() - 8 - 2 * first.grid.normals().len();
    for i in (tail..good.len()).step_by(5) {
        let mut c = good.clone();
        c[i] ^= 0x01;
        assert!(
            cache::decode_sparse(&c, mesh.content_hash(), &o).is_err(),
            "byte {i}"
        );
    }
    let mut short = good[..good.len() - 10].to_vec();
    short.extend_from_slice(&good[good.len() - 8..]);
    assert!(cache::decode_sparse(&short, mesh.content_hash(), &o).is_err());
    let tri = SparseOptions {
        reconstruction: Reconstruction::Trilinear,
        ..o.clone()
    };
    assert!(cache::decode_sparse(&good, mesh.content_hash(), &tri).is_err());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn hostile_options_and_meshes_are_errors() {
    let mesh = cube(true);
    for (res, band) in [(3, 2), (513, 2), (0, 2), (u32::MAX, 2), (16, 0), (16, 17)] {
        let o = SparseOptions {
            resolution: res,
            band_voxels: band,
            ..SparseOptions::DEFAULT
        };
        let e = bake_sparse(&mesh, &o).unwrap_err();
        assert!(
            matches!(e, BakeError::Resolution { .. } | BakeError::Band { .. }),
            "{e}"
        );
        assert!(o.validate().is_err());
    }
    let empty = TriangleMesh {
        triangles: Vec::new(),
        ..cube(true)
    };
    assert!(matches!(
        bake_sparse(&empty, &SparseOptions::DEFAULT),
        Err(BakeError::Empty { .. })
    ));
    let mut nan = cube(true);
    nan.positions[3] = Vec3::NAN;
    assert!(matches!(
        bake_sparse(&nan, &SparseOptions::DEFAULT),
        Err(BakeError::InvalidMesh { .. })
    ));
    let mut flat = cube(true);
    flat.positions.iter_mut().for_each(|p| *p = Vec3::ONE);
    assert!(bake_sparse(&flat, &SparseOptions::DEFAULT).is_err());
    // The memory bounds grow with the options and cover what a bake holds.
    let small = opts(64, Quantization::U8, Reconstruction::Trilinear);
    let (b, s) = bake_sparse(&bunny(), &small).unwrap();
    assert!(b.grid.memory_bytes() <= small.max_grid_bytes());
    assert!(s.band_bytes + s.grid_bytes <= small.max_bake_bytes());
    assert!(
        opts(512, Quantization::F32, Reconstruction::Tricubic).max_bake_bytes()
            > opts(512, Quantization::U8, Reconstruction::Trilinear).max_bake_bytes()
    );
}
