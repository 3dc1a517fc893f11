//! The committed meshes load with the counts their credits state, and the bunny survives a
//! round trip through the project's own .glb writer bit for bit.

use std::path::{Path, PathBuf};

use marchmesh_meshio::{load_mesh, write_glb};

fn mesh_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes/meshes")
        .join(name)
}

#[test]
fn bunny_loads_closed_with_its_stated_counts() {
    let m = load_mesh(&mesh_path("bunny.obj")).expect("bunny");
    assert_eq!(m.triangles.len(), 3674);
    assert_eq!(m.report.degenerate_skipped, 0);
    assert!(m.normals.is_none());
    assert!(m.is_closed());
    let (lo, hi) = m.bounds();
    assert!((hi - lo).max_element() > 5.0 && (hi - lo).max_element() < 20.0);
}

#[test]
fn teapot_and_dragon_load_open() {
    let t = load_mesh(&mesh_path("teapot.obj")).expect("teapot");
    assert_eq!(t.report.triangles_read, 992);
    assert!(!t.is_closed());
    let d = load_mesh(&mesh_path("dragon_res3.obj")).expect("dragon");
    assert_eq!(d.report.triangles_read, 47794);
    assert!(!d.is_closed());
}

#[test]
fn bunny_round_trips_through_glb() {
    let m = load_mesh(&mesh_path("bunny.obj")).expect("bunny");
    let out = std::env::temp_dir().join(format!("marchmesh-bunny-{}.glb", std::process::id()));
    write_glb(&m, &out).expect("write glb");
    let g = load_mesh(&out).expect("load glb");
    std::fs::remove_file(&out).ok();
    assert_eq!(g.positions, m.positions);
    assert_eq!(g.normals, m.normals);
    assert_eq!(g.triangles, m.triangles);
    assert_eq!(g.content_hash(), m.content_hash());
}
