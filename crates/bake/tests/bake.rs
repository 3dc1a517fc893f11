//! Baked grids against brute-force distances, signs of closed and open meshes, the cache,
//! and input errors.

use std::path::{Path, PathBuf};

use glam::Vec3;
use marchmesh_bake::{
    BakeError, BakeOptions, DistanceGrid, bake, bake_with_stats, brute_force_signed_distance, cache,
};
use marchmesh_meshio::load_mesh;

mod common;
use common::cube;

fn mesh_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes/meshes")
        .join(name)
}

fn opts(resolution: u32) -> BakeOptions {
    BakeOptions {
        resolution,
        cache_dir: None,
    }
}

/// Deterministic points in the box `(lo, hi)`.
fn points(lo: Vec3, hi: Vec3, n: usize, seed: u64) -> Vec<Vec3> {
    let mut s = seed | 1;
    let mut r = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    (0..n)
        .map(|_| lo + (hi - lo) * Vec3::new(r(), r(), r()))
        .collect()
}

/// Half a cell diagonal: the trilinear error bound for a 1-Lipschitz field.
fn bound(g: &DistanceGrid) -> f32 {
    0.5 * 3f32.sqrt() * g.cell_size * 1.001 + 1e-5
}

fn unique_dir(tag: &str) -> PathBuf {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    std::env::temp_dir().join(format!(
        "marchmesh-bake-{tag}-{}-{nanos}",
        std::process::id()
    ))
}

#[test]
fn cube_grid_within_half_a_cell_diagonal_of_exact() {
    let mesh = cube(true);
    let g = bake(&mesh, &opts(16)).unwrap().grid;
    assert_eq!(g.values.len(), g.dims.iter().product::<u32>() as usize);
    let (lo, hi) = g.bounds();
    assert!(
        lo.cmple(Vec3::splat(-1.0 - 2.9 * g.cell_size)).all(),
        "{lo}"
    );
    assert!(hi.cmpge(Vec3::splat(1.0 + 2.9 * g.cell_size)).all(), "{hi}");
    for p in points(lo, hi, 2000, 7) {
        // Exact signed distance of the cube, closed form.
        let q = p.abs() - Vec3::ONE;
        let exact = q.max(Vec3::ZERO).length() + q.max_element().min(0.0);
        let s = g.sample(p);
        assert!(
            (s - exact).abs() <= bound(&g),
            "{p}: grid {s}, exact {exact}"
        );
        assert!((brute_force_signed_distance(&mesh, p) - exact).abs() < 1e-5);
        assert!((g.sample_f64(p.as_dvec3()) as f32 - s).abs() < 1e-5);
    }
}

#[test]
fn outside_the_box_never_over_estimates_beyond_the_bound() {
    let mesh = cube(true);
    let g = bake(&mesh, &opts(8)).unwrap().grid;
    let (lo, hi) = g.bounds();
    let c = 0.5 * (lo + hi);
    for p in points(c - 4.0 * (hi - lo), c + 4.0 * (hi - lo), 2000, 11) {
        let q = p.abs() - Vec3::ONE;
        let exact = q.max(Vec3::ZERO).length() + q.max_element().min(0.0);
        let s = g.sample(p);
        assert!(s.is_finite() && s > 0.0 || p.cmpge(lo).all() && p.cmple(hi).all());
        assert!(s <= exact + bound(&g), "{p}: grid {s}, exact {exact}");
    }
    // Continuity across a face.
    let on = Vec3::new(hi.x, 0.3, 0.2);
    assert!((g.sample(on) - g.sample(on + Vec3::X * 1e-4)).abs() < 2e-4);
}

#[test]
fn bunny_low_res_matches_brute_force_and_signs() {
    let mesh = load_mesh(&mesh_path("bunny.obj")).unwrap();
    assert!(mesh.is_closed());
    let g = bake(&mesh, &opts(12)).unwrap().grid;
    let (lo, hi) = g.bounds();
    let mut inside = 0;
    for p in points(lo, hi, 150, 3) {
        let exact = brute_force_signed_distance(&mesh, p);
        let s = g.sample(p);
        assert!(
            (s - exact).abs() <= bound(&g),
            "{p}: grid {s}, exact {exact}"
        );
        inside += (exact < 0.0) as usize;
    }
    assert!(inside > 0, "the sample set must reach inside the bunny");
    // Stored samples: exact distance magnitudes, sign right wherever it matters.
    for k in (0..g.dims[2]).step_by(3) {
        for j in (0..g.dims[1]).step_by(3) {
            for i in (0..g.dims[0]).step_by(3) {
                let p = g.min + g.cell_size * Vec3::new(i as f32, j as f32, k as f32);
                let v = g.value(i, j, k).unwrap();
                let exact = brute_force_signed_distance(&mesh, p);
                assert!((v.abs() - exact.abs()).abs() < 1e-4 * g.cell_size.max(1.0));
                if exact.abs() > 1e-3 * g.cell_size {
                    assert_eq!(v < 0.0, exact < 0.0, "sign at {p}: {v} vs {exact}");
                }
            }
        }
    }
}

#[test]
fn closed_cube_sign_every_sample() {
    let g = bake(&cube(true), &opts(10)).unwrap().grid;
    for k in 0..g.dims[2] {
        for j in 0..g.dims[1] {
            for i in 0..g.dims[0] {
                let p = g.min + g.cell_size * Vec3::new(i as f32, j as f32, k as f32);
                let v = g.value(i, j, k).unwrap();
                let inside = p.abs().max_element() < 1.0 - 1e-4;
                let outside = p.abs().max_element() > 1.0 + 1e-4;
                assert!(!inside || v < 0.0, "{p} {v}");
                assert!(!outside || v > 0.0, "{p} {v}");
            }
        }
    }
}

#[test]
fn open_cube_keeps_its_inside() {
    let mesh = cube(false);
    assert!(!mesh.is_closed());
    let baked = bake(&mesh, &opts(16)).unwrap();
    assert!(baked.notes.iter().any(|n| n.contains("not closed")));
    let g = &baked.grid;
    // Far inside (winding 5/6 at the centre) and well below the hole.
    for p in [
        Vec3::ZERO,
        Vec3::new(0.3, -0.5, -0.2),
        Vec3::new(-0.6, -0.7, 0.6),
    ] {
        assert!(g.sample(p) < 0.0, "{p}: {}", g.sample(p));
    }
    // Far outside, including beside and below; above the hole the cap is expected.
    for p in [
        Vec3::new(1.2, 0.0, 0.0),
        Vec3::new(0.0, -1.2, 0.0),
        Vec3::new(1.15, 1.15, 1.15),
        Vec3::new(6.0, 2.0, -3.0),
    ] {
        assert!(g.sample(p) > 0.0, "{p}: {}", g.sample(p));
    }
}

#[test]
fn teapot_sign_far_inside_and_outside() {
    let mesh = load_mesh(&mesh_path("teapot.obj")).unwrap();
    assert!(!mesh.is_closed());
    let g = bake(&mesh, &opts(24)).unwrap().grid;
    let (lo, hi) = mesh.bounds();
    // Body centre: well inside (checked against the brute-force winding number too).
    let body = Vec3::new(0.0, 0.5 * (lo.y + hi.y), 0.0);
    assert!(brute_force_signed_distance(&mesh, body) < -1.0);
    assert!(g.sample(body) < 0.0);
    for p in [
        Vec3::new(0.0, hi.y + 2.0, 0.0),
        Vec3::new(0.0, lo.y - 2.0, 0.0),
        Vec3::new(hi.x + 1.0, hi.y, hi.z),
        Vec3::new(0.0, 0.0, hi.z + 1.5),
        Vec3::new(40.0, -3.0, 7.0),
    ] {
        assert!(g.sample(p) > 0.0, "{p}: {}", g.sample(p));
    }
}

#[test]
fn cache_round_trip_identical() {
    let dir = unique_dir("roundtrip");
    let mesh = cube(true);
    let o = BakeOptions {
        resolution: 9,
        cache_dir: Some(dir.clone()),
    };
    let first = bake(&mesh, &o).unwrap();
    assert!(!first.from_cache);
    let file = cache::cache_path(&dir, mesh.content_hash(), 9);
    assert!(file.is_file(), "{}", file.display());
    let (second, stats) = bake_with_stats(&mesh, &o).unwrap();
    assert!(second.from_cache, "{:?}", second.notes);
    assert_eq!(stats.samples, 0);
    assert_eq!(first.grid, second.grid);
    // Another resolution is another key.
    let other = bake(
        &mesh,
        &BakeOptions {
            resolution: 10,
            ..o.clone()
        },
    )
    .unwrap();
    assert!(!other.from_cache);
    // No temporary files left behind.
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 2, "{names:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn corrupted_cache_is_rebaked() {
    let dir = unique_dir("corrupt");
    let mesh = cube(true);
    let o = BakeOptions {
        resolution: 8,
        cache_dir: Some(dir.clone()),
    };
    let fresh = bake(&mesh, &o).unwrap();
    let file = cache::cache_path(&dir, mesh.content_hash(), 8);
    let good = std::fs::read(&file).unwrap();
    let mut flipped = good.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x40;
    for (what, bytes) in [
        ("flipped", flipped),
        ("truncated", good[..good.len() - 5].to_vec()),
        ("empty", Vec::new()),
        ("garbage", b"not a grid at all".to_vec()),
    ] {
        std::fs::write(&file, &bytes).unwrap();
        let b = bake(&mesh, &o).unwrap();
        assert!(!b.from_cache, "{what}");
        assert!(
            b.notes.iter().any(|n| n.contains("rejected")),
            "{what}: {:?}",
            b.notes
        );
        assert_eq!(b.grid, fresh.grid, "{what}");
        // The re-bake repaired the file.
        assert_eq!(std::fs::read(&file).unwrap(), good, "{what}");
    }
    // A cache directory that cannot be created is a note, not an error.
    let blocker = dir.join("a-file");
    std::fs::write(&blocker, b"x").unwrap();
    let b = bake(
        &mesh,
        &BakeOptions {
            resolution: 8,
            cache_dir: Some(blocker.join("sub")),
        },
    )
    .unwrap();
    assert!(b.notes.iter().any(|n| n.contains("could not cache")));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_input_errors() {
    let mesh = cube(true);
    for r in [0, 3, 513, u32::MAX] {
        let e = bake(&mesh, &opts(r)).unwrap_err();
        assert_eq!(e, BakeError::Resolution { resolution: r });
        assert!(e.to_string().contains("4..=512"), "{e}");
    }
    assert!(bake(&mesh, &opts(4)).is_ok());
    let mut empty = cube(true);
    empty.triangles.clear();
    empty.report.source = PathBuf::from("empty.obj");
    let e = bake(&empty, &opts(16)).unwrap_err();
    assert!(matches!(e, BakeError::Empty { .. }));
    assert!(e.to_string().contains("empty.obj"), "{e}");
    let mut bad = cube(true);
    bad.triangles[3][1] = 99;
    assert!(matches!(
        bake(&bad, &opts(16)),
        Err(BakeError::InvalidMesh { .. })
    ));
    let mut nan = cube(true);
    nan.positions[2].y = f32::NAN;
    assert!(matches!(
        bake(&nan, &opts(16)),
        Err(BakeError::InvalidMesh { .. })
    ));
    let mut point = cube(true);
    point.positions.iter_mut().for_each(|p| *p = Vec3::ONE);
    let e = bake(&point, &opts(16)).unwrap_err();
    assert!(e.to_string().contains("no extent"), "{e}");
}

#[test]
fn flat_mesh_gets_a_padded_grid() {
    // A single square in the z = 0 plane: zero extent along z still gets padding cells.
    let mut m = cube(true);
    m.positions = vec![
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    ];
    m.triangles = vec![[0, 1, 2], [0, 2, 3]];
    let g = bake(&m, &opts(8)).unwrap().grid;
    assert!(g.dims[2] >= 7, "{:?}", g.dims);
    // An open sheet has no inside: both sides are outside, |distance| as usual.
    for z in [0.25f32, -0.25] {
        let d = g.sample(Vec3::new(0.5, 0.5, z));
        assert!(d > 0.0 && (d - 0.25).abs() <= bound(&g), "{z}: {d}");
    }
}

#[test]
fn trilinear_gradient_bounded_by_sqrt3() {
    let mesh = load_mesh(&mesh_path("bunny.obj")).unwrap();
    let g = bake(&mesh, &opts(10)).unwrap().grid;
    let (lo, hi) = g.bounds();
    let step = 1e-3 * g.cell_size;
    let mut worst = 0.0f32;
    for p in points(lo, hi, 500, 5) {
        for dir in [Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE.normalize()] {
            let slope = (g.sample_f64((p + dir * step).as_dvec3()) - g.sample_f64(p.as_dvec3()))
                .abs()
                / step as f64;
            worst = worst.max(slope as f32);
        }
    }
    assert!(worst <= 3f32.sqrt() * 1.01, "slope {worst}");
}
