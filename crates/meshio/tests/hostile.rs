//! Hostile mesh files (issue 11): URIs reaching outside the glTF's folder, unbounded reads,
//! non-regular files, and inconsistent accessors. Each case is a clear error naming the file,
//! never a panic and never a read of a file it should not touch.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

use marchmesh_meshio::load_mesh;

/// A fresh, unique folder in the system temp dir.
fn scratch() -> PathBuf {
    static COUNTER: AtomicU32 = AtomicU32::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("marchmesh-hostile-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// 36 bytes: one triangle of three f32 VEC3 positions.
fn triangle_bytes() -> Vec<u8> {
    [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|c| c.to_le_bytes())
        .collect()
}

/// A one-triangle glTF whose buffer is `uri` declaring `byte_length` bytes, with the
/// POSITION accessor of `position_type` / `component` and an optional index accessor.
fn gltf_json(uri: &str, byte_length: u64, position_type: &str, component: u32) -> String {
    format!(
        r#"{{
      "asset": {{"version": "2.0"}},
      "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
      "accessors": [{{"bufferView": 0, "componentType": {component}, "count": 3,
                     "type": "{position_type}", "min": [0, 0, 0], "max": [1, 1, 0]}}],
      "bufferViews": [{{"buffer": 0, "byteLength": 36}}],
      "buffers": [{{"byteLength": {byte_length}, "uri": {uri:?}}}]
    }}"#
    )
}

fn write_gltf(dir: &Path, json: &str) -> PathBuf {
    let p = dir.join("model.gltf");
    std::fs::write(&p, json).expect("write gltf");
    p
}

fn data_uri(bytes: &[u8]) -> String {
    format!(
        "data:application/octet-stream;base64,{}",
        base64::encode(bytes)
    )
}

#[test]
fn item1_gltf_buffer_uris_outside_the_folder_are_refused_naming_file_and_uri() {
    // A "secret" file beside (not inside) the glTF's folder, shaped like valid vertex data, so
    // the old loader would happily turn it into a triangle.
    let outer = scratch();
    let secret = outer.join("secret.bin");
    std::fs::write(&secret, triangle_bytes()).expect("secret");
    let dir = outer.join("model");
    std::fs::create_dir_all(&dir).expect("model dir");
    std::os::unix::fs::symlink(&secret, dir.join("link.bin")).expect("symlink");
    let absolute = secret.display().to_string();
    let file_url = format!("file://{absolute}");
    for uri in [
        "../secret.bin",
        "%2e%2e/secret.bin",
        "sub/../../secret.bin",
        absolute.as_str(),
        file_url.as_str(),
        "link.bin",
        "../../../../../../../../etc/passwd",
    ] {
        let p = write_gltf(&dir, &gltf_json(uri, 36, "VEC3", 5126));
        let msg = load_mesh(&p).expect_err(uri).to_string();
        assert!(
            msg.contains("model.gltf") && msg.contains(uri) && msg.contains("refused"),
            "{uri}: {msg}"
        );
    }
}

#[test]
fn item1_data_uris_and_files_inside_the_folder_still_load() {
    let dir = scratch();
    let p = write_gltf(
        &dir,
        &gltf_json(&data_uri(&triangle_bytes()), 36, "VEC3", 5126),
    );
    assert_eq!(load_mesh(&p).expect("data: URI").triangles.len(), 1);
    std::fs::create_dir_all(dir.join("bin")).expect("sub");
    std::fs::write(dir.join("bin/tri 1.bin"), triangle_bytes()).expect("bin");
    let p = write_gltf(&dir, &gltf_json("bin/tri%201.bin", 36, "VEC3", 5126));
    assert_eq!(load_mesh(&p).expect("relative URI").triangles.len(), 1);
}

#[test]
fn item2_dev_zero_and_folders_are_refused_not_read() {
    let dir = scratch();
    let zero_obj = dir.join("zero.obj");
    std::os::unix::fs::symlink("/dev/zero", &zero_obj).expect("symlink");
    let msg = load_mesh(&zero_obj).expect_err("/dev/zero").to_string();
    assert!(
        msg.contains("zero.obj") && msg.contains("not a regular file"),
        "{msg}"
    );

    let folder = dir.join("x.obj");
    std::fs::create_dir_all(&folder).expect("folder");
    let msg = load_mesh(&folder).expect_err("folder").to_string();
    assert!(msg.contains("x.obj") && msg.contains("folder"), "{msg}");
    assert!(!msg.contains("read error"), "{msg}");
}

#[test]
fn item2_declared_buffer_length_is_checked_against_the_cap_and_the_data() {
    let dir = scratch();
    std::fs::write(dir.join("tri.bin"), triangle_bytes()).expect("bin");
    // Declares a terabyte: refused before anything is read or allocated.
    let p = write_gltf(&dir, &gltf_json("tri.bin", 1 << 40, "VEC3", 5126));
    let msg = load_mesh(&p).expect_err("huge").to_string();
    assert!(msg.contains("MARCHMESH_MAX_READ_MIB"), "{msg}");
    // Declares more than the file holds.
    let p = write_gltf(&dir, &gltf_json("tri.bin", 48, "VEC3", 5126));
    let msg = load_mesh(&p).expect_err("short").to_string();
    assert!(msg.contains("declares 48 bytes but holds only 36"), "{msg}");
}

#[test]
fn item15_position_must_be_vec3_float() {
    let dir = scratch();
    for (ty, component) in [("VEC2", 5126), ("VEC3", 5120)] {
        let p = write_gltf(
            &dir,
            &gltf_json(&data_uri(&triangle_bytes()), 36, ty, component),
        );
        let msg = load_mesh(&p).expect_err(ty).to_string();
        assert!(
            msg.contains("it must be VEC3 FLOAT"),
            "{ty} {component}: {msg}"
        );
    }
}

#[test]
fn item15_float_index_accessor_is_an_error_not_a_caught_panic() {
    let dir = scratch();
    let mut bytes = triangle_bytes();
    for i in [0.0f32, 1.0, 2.0] {
        bytes.extend_from_slice(&i.to_le_bytes());
    }
    let json = format!(
        r#"{{
      "asset": {{"version": "2.0"}},
      "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
      "accessors": [
        {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
          "min": [0, 0, 0], "max": [1, 1, 0]}},
        {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "SCALAR"}}],
      "bufferViews": [{{"buffer": 0, "byteLength": 36}},
                      {{"buffer": 0, "byteOffset": 36, "byteLength": 12}}],
      "buffers": [{{"byteLength": 48, "uri": {:?}}}]
    }}"#,
        data_uri(&bytes)
    );
    let msg = load_mesh(&write_gltf(&dir, &json))
        .expect_err("float indices")
        .to_string();
    assert!(
        msg.contains("model.gltf") && msg.contains("indices must be SCALAR unsigned integers"),
        "{msg}"
    );
}

#[test]
fn item15_buffers_shorter_than_their_views_are_refused() {
    let dir = scratch();
    // The buffer holds (and declares) 24 bytes; the view and accessor claim 36.
    let json = gltf_json(&data_uri(&triangle_bytes()[..24]), 24, "VEC3", 5126);
    let msg = load_mesh(&write_gltf(&dir, &json))
        .expect_err("short buffer")
        .to_string();
    assert!(msg.contains("buffer view 0 ends at byte 36"), "{msg}");
}

/// A glTF of `n` nodes where every node lists the next one as a child twice (before the fix
/// this expanded to 2^n instances).
fn doubled_children_gltf(n: usize) -> String {
    let nodes: Vec<String> = (0..n)
        .map(|i| {
            if i + 1 < n {
                format!(r#"{{"children": [{0}, {0}]}}"#, i + 1)
            } else {
                r#"{"mesh": 0}"#.to_string()
            }
        })
        .collect();
    format!(
        r#"{{
      "asset": {{"version": "2.0"}},
      "scene": 0,
      "scenes": [{{"nodes": [0]}}],
      "nodes": [{}],
      "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
      "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                     "min": [0, 0, 0], "max": [1, 1, 0]}}],
      "bufferViews": [{{"buffer": 0, "byteLength": 36}}],
      "buffers": [{{"byteLength": 36, "uri": {:?}}}]
    }}"#,
        nodes.join(","),
        data_uri(&triangle_bytes())
    )
}

#[test]
fn gltf_node_graphs_must_be_trees() {
    let dir = scratch();
    let msg = load_mesh(&write_gltf(&dir, &doubled_children_gltf(40)))
        .expect_err("a node listed twice as a child")
        .to_string();
    assert!(
        msg.contains("model.gltf") && msg.contains("more than once") && msg.contains("trees"),
        "{msg}"
    );
    // A root listed many times in the scene is refused the same way.
    let json = doubled_children_gltf(1).replace(
        r#""scenes": [{"nodes": [0]}]"#,
        &format!(
            r#""scenes": [{{"nodes": [{}]}}]"#,
            vec!["0"; 100_000].join(",")
        ),
    );
    let msg = load_mesh(&write_gltf(&dir, &json))
        .expect_err("a root listed 100000 times")
        .to_string();
    assert!(msg.contains("more than once"), "{msg}");
    // The plain tree still loads.
    let mesh = load_mesh(&write_gltf(&dir, &doubled_children_gltf(1))).expect("one node");
    assert_eq!(mesh.triangles.len(), 1);
}

#[test]
fn gltf_strides_smaller_than_an_element_and_sparse_accessors_are_clear_errors() {
    let dir = scratch();
    let stride = gltf_json(&data_uri(&triangle_bytes()), 36, "VEC3", 5126).replace(
        r#""byteLength": 36}],"#,
        r#""byteLength": 36, "byteStride": 4}],"#,
    );
    assert!(stride.contains("byteStride"));
    let msg = load_mesh(&write_gltf(&dir, &stride))
        .expect_err("stride 4")
        .to_string();
    assert!(msg.contains("byteStride 4"), "{msg}");
    let sparse = gltf_json(&data_uri(&triangle_bytes()), 36, "VEC3", 5126).replace(
        r#""count": 3,"#,
        r#""count": 1000000000, "sparse": {"count": 1, "indices": {"bufferView": 0, "componentType": 5125}, "values": {"bufferView": 0}},"#,
    );
    let sparse = sparse.replace(
        r#""bufferView": 0, "componentType": 5126"#,
        r#""componentType": 5126"#,
    );
    let msg = load_mesh(&write_gltf(&dir, &sparse))
        .expect_err("sparse")
        .to_string();
    assert!(msg.contains("sparse"), "{msg}");
    assert!(!msg.contains("no POSITION"), "{msg}");
}

#[test]
fn obj_faces_beyond_the_vertex_cap_are_refused_in_linear_time() {
    let dir = scratch();
    let n = 100_000;
    let mut obj = String::new();
    for i in 0..n {
        let a = i as f64 / n as f64 * std::f64::consts::TAU;
        obj.push_str(&format!("v {} {} 0\n", a.cos(), a.sin()));
    }
    obj.push('f');
    for i in 1..=n {
        obj.push_str(&format!(" {i}"));
    }
    obj.push('\n');
    let p = dir.join("big.obj");
    std::fs::write(&p, obj).expect("write obj");
    let msg = load_mesh(&p).expect_err("huge face").to_string();
    assert!(
        msg.contains("big.obj") && msg.contains("line 100001") && msg.contains("4096"),
        "{msg}"
    );
}

/// Every bound a checked load passes to its check, in order.
fn bounds_seen(path: &Path) -> (Vec<marchmesh_meshio::LoadBound>, bool) {
    let mut seen = Vec::new();
    let ok = marchmesh_meshio::load_mesh_checked(path, &mut |b| {
        seen.push(*b);
        Ok(())
    })
    .is_ok();
    (seen, ok)
}

#[test]
fn checked_loads_ask_before_reading_and_before_decoding_with_the_counts() {
    let dir = scratch();
    // A quad (two fan triangles) and a triangle; four positions, one normal.
    let obj = dir.join("quad.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\nf 1//1 2//1 4//1\n",
    )
    .unwrap();
    let size = std::fs::metadata(&obj).unwrap().len();
    let (seen, ok) = bounds_seen(&obj);
    assert!(ok);
    assert_eq!(seen.len(), 2, "{seen:?}");
    // Before reading: the file's size alone.
    assert_eq!(
        seen[0],
        marchmesh_meshio::LoadBound {
            file_bytes: size,
            ..Default::default()
        }
    );
    // Before decoding: 5 records, 7 corners, 3 triangles.
    assert_eq!(
        seen[1],
        marchmesh_meshio::LoadBound {
            file_bytes: size,
            records: 5,
            vertices: 7,
            triangles: 3,
        }
    );
    // glTF: the placed primitives' counts and the buffers as declared, before any is read.
    let mesh = marchmesh_meshio::load_mesh(&obj).unwrap();
    let glb = dir.join("quad.glb");
    marchmesh_meshio::write_glb(&mesh, &glb).unwrap();
    let size = std::fs::metadata(&glb).unwrap().len();
    let (seen, ok) = bounds_seen(&glb);
    assert!(ok);
    assert_eq!(seen.len(), 2, "{seen:?}");
    assert_eq!(seen[1].vertices, mesh.positions.len() as u64);
    assert_eq!(seen[1].triangles, mesh.triangles.len() as u64);
    assert!(seen[1].file_bytes > 2 * size, "{seen:?}");
    assert!(seen[1].load_bytes() > seen[0].load_bytes());
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_refused_checked_load_names_the_file_and_reads_nothing_more() {
    let dir = scratch();
    let obj = dir.join("big.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let mut calls = 0;
    let e = marchmesh_meshio::load_mesh_checked(&obj, &mut |b| {
        calls += 1;
        if b.triangles > 0 {
            Err("too many triangles for this test".into())
        } else {
            Ok(())
        }
    })
    .expect_err("refused before decoding");
    assert_eq!(calls, 2);
    let msg = e.to_string();
    assert!(
        msg.contains("big.obj") && msg.ends_with("too many triangles for this test"),
        "{msg}"
    );
    // Refused on its size: the first check runs before the file is read.
    let mut calls = 0;
    let e = marchmesh_meshio::load_mesh_checked(&obj, &mut |b| {
        calls += 1;
        assert_eq!((b.records, b.vertices, b.triangles), (0, 0, 0));
        Err("too large a file".into())
    });
    assert!(e.is_err_and(|e| e.to_string().ends_with("too large a file")));
    assert_eq!(calls, 1);
    let _ = std::fs::remove_dir_all(dir);
}
