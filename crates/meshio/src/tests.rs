use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};

use super::*;

/// A fresh, unique file path in the system temp dir.
fn temp_path(name: &str) -> PathBuf {
    static COUNTER: AtomicU32 = AtomicU32::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("marchmesh-meshio-{}-{n}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

fn write(name: &str, contents: &[u8]) -> PathBuf {
    let p = temp_path(name);
    std::fs::write(&p, contents).expect("write temp file");
    p
}

const TETRA: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

#[test]
fn obj_quad_without_normals_is_triangulated() {
    let p = write(
        "quad.obj",
        b"v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nf 1 2 3 4\n",
    );
    let m = load_mesh(&p).expect("load");
    assert_eq!(m.triangles.len(), 2);
    assert_eq!(m.report.triangles_read, 2);
    assert!(m.normals.is_none());
    assert!(!m.is_closed());
    assert_eq!(m.bounds(), (Vec3::ZERO, Vec3::new(2.0, 1.0, 0.0)));
    assert_eq!(m.memory_bytes(), 4 * 12 + 2 * 12);
}

#[test]
fn obj_tetrahedron_is_closed_and_keeps_normals() {
    let mut src = String::from(TETRA.split("f ").next().unwrap_or(""));
    src.push_str("vn 0 0 2\n");
    src.push_str("f 1//1 3//1 2//1\nf 1//1 2//1 4//1\nf 1//1 4//1 3//1\nf 2//1 3//1 4//1\n");
    let m = load_mesh(&write("tetra_n.obj", src.as_bytes())).expect("load");
    assert_eq!(m.triangles.len(), 4);
    let n = m.normals.as_ref().expect("normals");
    assert_eq!(n.len(), m.positions.len());
    assert!(
        n.iter().all(|v| (*v - Vec3::Z).length() < 1e-6),
        "normals are renormalised"
    );
    assert!(m.is_closed());
}

#[test]
fn open_mesh_and_doubly_used_edge_are_not_closed() {
    let open = load_mesh(&write(
        "open.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\n",
    ))
    .expect("load");
    assert!(!open.is_closed());
    let closed = load_mesh(&write("tetra.obj", TETRA.as_bytes())).expect("load");
    assert!(closed.is_closed());
}

#[test]
fn degenerate_and_duplicate_triangles_are_skipped_and_counted() {
    let src = format!("{TETRA}f 1 1 2\nf 1 2 2\nv 2 0 0\nf 1 2 5\nf 3 2 1\nf 2 1 3\n");
    let m = load_mesh(&write("degen.obj", src.as_bytes())).expect("load");
    // f 1 1 2, f 1 2 2 (repeated corner) and f 1 2 5 (collinear) are degenerate;
    // f 3 2 1 is a rotation of f 1 3 2: duplicate; f 2 1 3 is also a rotation of 1 3 2.
    assert_eq!(m.report.degenerate_skipped, 3);
    assert_eq!(m.report.duplicate_skipped, 2);
    assert_eq!(m.report.triangles_read, 9);
    assert_eq!(m.triangles.len(), 4);
    assert!(m.is_closed());
}

#[test]
fn nan_vertex_is_an_error_naming_file_and_vertex() {
    let p = write("nan.obj", b"v 0 0 0\nv NaN 0 0\nv 0 1 0\nf 1 2 3\n");
    let e = load_mesh(&p).expect_err("NaN must be rejected");
    assert!(
        matches!(e, MeshLoadError::NonFiniteVertex { index: 1, .. }),
        "{e:?}"
    );
    let msg = e.to_string();
    assert!(msg.contains("nan.obj") && msg.contains("vertex 1"), "{msg}");
    let p = write("inf.obj", b"v 0 0 0\nv 1 0 0\nv 0 inf 0\nf 1 2 3\n");
    let msg = load_mesh(&p).expect_err("inf").to_string();
    assert!(msg.contains("inf.obj") && msg.contains("vertex 2"), "{msg}");
}

#[test]
fn missing_file_unknown_extension_and_corrupt_obj_are_clear_errors() {
    let missing = temp_path("does_not_exist.obj");
    let msg = load_mesh(&missing).expect_err("missing").to_string();
    assert!(
        msg.contains("does_not_exist.obj") && msg.contains("cannot read"),
        "{msg}"
    );

    let msg = load_mesh(&write("mesh.stl", b"solid x"))
        .expect_err("stl")
        .to_string();
    assert!(
        msg.contains("mesh.stl") && msg.contains("unsupported"),
        "{msg}"
    );

    let e = load_mesh(&write(
        "bad_index.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
    ))
    .expect_err("bad index");
    assert!(matches!(e, MeshLoadError::Malformed { .. }), "{e:?}");
    assert!(e.to_string().contains("bad_index.obj"));

    let e = load_mesh(&write("garbage.obj", b"v 0 zero 0\nf 1 2 3\n")).expect_err("garbage");
    assert!(matches!(e, MeshLoadError::Malformed { .. }), "{e:?}");
}

#[test]
fn mesh_of_only_degenerate_triangles_is_empty_error() {
    let e =
        load_mesh(&write("flat.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")).expect_err("empty");
    assert!(
        matches!(
            e,
            MeshLoadError::Empty {
                triangles_read: 1,
                degenerate_skipped: 1,
                ..
            }
        ),
        "{e:?}"
    );
    let e = load_mesh(&write("nothing.obj", b"# empty\n")).expect_err("empty");
    assert!(e.to_string().contains("nothing.obj"), "{e}");
}

#[test]
fn glb_round_trip_is_bit_exact_with_and_without_normals() {
    let plain = load_mesh(&write("rt.obj", TETRA.as_bytes())).expect("load");
    let glb = temp_path("rt.glb");
    write_glb(&plain, &glb).expect("write");
    let back = load_mesh(&glb).expect("reload");
    assert_eq!(back.positions, plain.positions);
    assert_eq!(back.normals, plain.normals);
    assert_eq!(back.triangles, plain.triangles);
    assert_eq!(back.content_hash(), plain.content_hash());
    assert_eq!(back.report.format, MeshFormat::Gltf);

    let mut with_normals = plain.clone();
    with_normals.normals = Some(
        plain
            .positions
            .iter()
            .map(|p| (*p - Vec3::splat(0.25)).normalize())
            .collect(),
    );
    write_glb(&with_normals, &glb).expect("write");
    let back = load_mesh(&glb).expect("reload");
    assert_eq!(back.normals, with_normals.normals);
    assert_eq!(back.content_hash(), with_normals.content_hash());
    assert_ne!(with_normals.content_hash(), plain.content_hash());
}

#[test]
fn truncated_or_garbage_glb_is_an_error_not_a_panic() {
    let plain = load_mesh(&write("t.obj", TETRA.as_bytes())).expect("load");
    let glb = temp_path("t.glb");
    write_glb(&plain, &glb).expect("write");
    let bytes = std::fs::read(&glb).expect("read");
    for cut in [0, 4, 12, 19, 40, bytes.len() / 2, bytes.len() - 4] {
        let p = write("cut.glb", &bytes[..cut]);
        let e = load_mesh(&p).expect_err("truncated glb");
        assert!(e.to_string().contains("cut.glb"), "{e}");
    }
    let mut flipped = bytes.clone();
    let json_start = 20;
    flipped[json_start + 1] = b'#';
    assert!(load_mesh(&write("bad_json.glb", &flipped)).is_err());
    assert!(load_mesh(&write("text.gltf", b"{ not json")).is_err());
}

#[test]
fn gltf_node_transforms_are_applied_and_mirroring_keeps_orientation() {
    // One triangle in an external .bin, instanced by a child node whose parent translates by
    // (10, 0, 0) and which itself scales x by -1 (a mirror).
    let bin_path = temp_path("tri.bin");
    let mut bin = Vec::new();
    for c in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend_from_slice(&c.to_le_bytes());
    }
    std::fs::write(&bin_path, &bin).expect("bin");
    let json = r#"{
      "asset": {"version": "2.0"},
      "scene": 0,
      "scenes": [{"nodes": [0]}],
      "nodes": [
        {"translation": [10, 0, 0], "children": [1]},
        {"scale": [-1, 1, 1], "mesh": 0}
      ],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                     "min": [0, 0, 0], "max": [1, 1, 0]}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}],
      "buffers": [{"byteLength": 36, "uri": "tri.bin"}]
    }"#;
    let gltf_path = bin_path.with_file_name("tri.gltf");
    std::fs::write(&gltf_path, json).expect("gltf");
    let m = load_mesh(&gltf_path).expect("load gltf");
    assert_eq!(
        m.positions,
        vec![
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(9.0, 0.0, 0.0),
            Vec3::new(10.0, 1.0, 0.0)
        ]
    );
    // Source winding (0,1,2) faces +z; mirrored positions reverse it, so the loader swaps two
    // corners to keep the face towards +z.
    let [a, b, c] = m.triangles[0].map(|i| m.positions[i as usize]);
    assert!((b - a).cross(c - a).z > 0.0);
}

#[test]
fn content_hash_matches_an_independent_fnv1a_and_changes_with_any_bit() {
    let m = TriangleMesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        normals: None,
        triangles: vec![[0, 1, 2]],
        report: LoadReport::default(),
    };
    // Independent byte stream: count, coordinates, normals tag, count, indices.
    let mut bytes = Vec::new();
    bytes.extend_from_slice(&3u64.to_le_bytes());
    for c in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bytes.extend_from_slice(&c.to_bits().to_le_bytes());
    }
    bytes.extend_from_slice(&0u64.to_le_bytes());
    bytes.extend_from_slice(&1u64.to_le_bytes());
    for i in [0u32, 1, 2] {
        bytes.extend_from_slice(&i.to_le_bytes());
    }
    let expected = bytes.iter().fold(0xcbf29ce484222325u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x100000001b3)
    });
    assert_eq!(m.content_hash(), expected);
    let mut other = m.clone();
    other.positions[2].y = f32::from_bits(1.0f32.to_bits() + 1);
    assert_ne!(other.content_hash(), m.content_hash());
    let mut other = m.clone();
    other.triangles[0] = [0, 2, 1];
    assert_ne!(other.content_hash(), m.content_hash());
}
