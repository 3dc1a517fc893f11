//! Issue 11 item 3: a backend's build is estimated and refused over the memory limit before
//! it allocates, with the object, the estimate, the limit and the option named.

use marchmesh_mesh::MeshBackend;
use marchmesh_registry::{self as backend, BackendId, BackendSpec};
use marchmesh_sdf::SdfBackend;

const MESH: BackendId = BackendId::of::<MeshBackend>();
const SDF: BackendId = BackendId::of::<SdfBackend>();

const MIB: u64 = 1 << 20;

fn scene(text: &str) -> marchmesh_scene::Scene {
    let base = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    marchmesh_scene::parse_scene(text, "limit.json", &base).expect("valid scene")
}

fn spec(kind: BackendId, options: &[&str]) -> BackendSpec {
    BackendSpec {
        kind,
        options: options
            .iter()
            .map(|o| backend::parse_option(o).expect("option"))
            .collect(),
    }
}

fn build_error(scene: &marchmesh_scene::Scene, spec: &BackendSpec, limit: u64) -> String {
    match backend::build_within(scene, spec, limit) {
        Ok(_) => panic!("built within {limit} bytes"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_sphere_seen_through_a_tiny_field_of_view_is_refused_not_tessellated() {
    // 16M triangles (about 5 GB) for a 32x32 image before the limit existed.
    let s = scene(
        r#"{ "camera": { "position": [0, 0, -4], "look_at": [0, 0, 0], "width": 32, "height": 32,
                         "vfov_deg": 1e-3 },
             "objects": [ { "shape": { "sphere": { "radius": 1 } } } ] }"#,
    );
    let msg = build_error(&s, &spec(MESH, &[]), 100 * MIB);
    for part in [
        "objects[0]",
        "triangles",
        "100 MiB",
        "--memory-limit-mib",
        "tess_px",
    ] {
        assert!(msg.contains(part), "{part}: {msg}");
    }
    // The same scene at a coarse budget fits.
    backend::build_within(&s, &spec(MESH, &["tess_level=3"]), 100 * MIB)
        .expect("a fixed level-3 sphere is small");
}

#[test]
fn segment_caps_beyond_the_documented_maximum_are_refused() {
    let s = scene(r#"{ "objects": [ { "shape": { "sphere": { "radius": 1 } } } ] }"#);
    let msg = build_error(
        &s,
        &spec(MESH, &["max_segments=4000000000", "tess_px=1e-9"]),
        4096 * MIB,
    );
    assert!(
        msg.contains("max_segments_per_turn must be in 8..=65536"),
        "{msg}"
    );
}

#[test]
fn extraction_grids_count_against_the_limit() {
    let s = scene(
        r#"{ "objects": [ { "shape": { "smooth_union": { "blend_radius": 0.2, "children": [
               { "shape": { "sphere": { "radius": 1 } } },
               { "shape": { "box": { "half_extents": [0.5, 0.5, 0.5] } },
                 "transform": { "translate": [1, 0, 0] } } ] } } } ] }"#,
    );
    let msg = build_error(&s, &spec(MESH, &["surface_res=512"]), 200 * MIB);
    assert!(
        msg.contains("surface-extraction grid of 512^3") && msg.contains("surface_res"),
        "{msg}"
    );
}

#[test]
fn mesh_grids_of_the_sdf_backend_count_against_the_limit() {
    let s = scene(r#"{ "objects": [ { "shape": { "mesh": { "path": "meshes/bunny.obj" } } } ] }"#);
    let msg = build_error(&s, &spec(SDF, &["grid_res=512"]), 1000 * MIB);
    for part in [
        "resolution 512",
        "1000 MiB",
        "grid_res",
        "--memory-limit-mib",
    ] {
        assert!(msg.contains(part), "{part}: {msg}");
    }
    let msg = build_error(&s, &spec(MESH, &[]), MIB / 2);
    assert!(
        msg.contains("bunny.obj") && msg.contains("triangles"),
        "{msg}"
    );
}

const REFERENCE: BackendId = BackendId::REFERENCE;

#[test]
fn mesh_loads_of_the_reference_and_the_sdf_backend_count_against_the_limit() {
    // The bunny's load bound with the reference's f64 copy and BVH, or the sdf backend's bake,
    // is a few MiB: refused at 1 MiB (a tiny grid fits) naming the object, the file and the
    // limit, before the mesh is decoded.
    let s = scene(r#"{ "objects": [ { "shape": { "mesh": { "path": "meshes/bunny.obj" } } } ] }"#);
    for (kind, options) in [(REFERENCE, &[][..]), (SDF, &["grid_res=8"][..])] {
        let msg = build_error(&s, &spec(kind, options), MIB);
        for part in [
            "objects[0]",
            "bunny.obj",
            "triangles",
            "memory limit of 1 MiB",
            "--memory-limit-mib",
        ] {
            assert!(msg.contains(part), "{part}: {msg}");
        }
        backend::build_within(&s, &spec(kind, options), 64 * MIB).expect("fits in 64 MiB");
    }
}

#[test]
fn mesh_files_larger_than_the_limit_are_refused_before_they_are_read() {
    // 12 MiB of vertex records: over a 10 MiB limit on its size alone.
    let dir = std::env::temp_dir().join(format!("marchmesh-limit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let obj = dir.join("huge.obj");
    std::fs::write(&obj, "v 0.50 0.50 0.5\n".repeat(12 << 20 >> 4)).unwrap();
    let text = format!(
        r#"{{ "objects": [ {{ "shape": {{ "mesh": {{ "path": {:?} }} }} }} ] }}"#,
        obj.display()
    );
    let s = scene(&text);
    for (kind, options) in [(REFERENCE, &[][..]), (SDF, &["grid_res=8"][..])] {
        let msg = build_error(&s, &spec(kind, options), 10 * MIB);
        for part in [
            "huge.obj",
            "12 MiB of file, 0 records",
            "memory limit of 10 MiB",
        ] {
            assert!(msg.contains(part), "{part}: {msg}");
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}
