//! glTF 2.0 loading through `gltf`, and a minimal binary glTF writer.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use glam::{DMat3, DMat4, Mat4, Vec3};
use gltf::mesh::Mode;

use crate::{LoadReport, MeshFormat, MeshLoadError, RawMesh, TriangleMesh};

/// Deepest node hierarchy followed (guards against cyclic node graphs in corrupt files).
const MAX_NODE_DEPTH: usize = 256;

fn malformed(path: &Path, reason: impl Into<String>) -> MeshLoadError {
    MeshLoadError::Malformed {
        path: path.to_path_buf(),
        format: "glTF",
        reason: reason.into(),
    }
}

/// Reads every triangle primitive instanced by the default scene (or the first scene; or every
/// mesh untransformed if the file has no scene), node transforms applied.
pub(crate) fn load(path: &Path) -> Result<RawMesh, MeshLoadError> {
    let bytes = std::fs::read(path).map_err(|source| MeshLoadError::Io {
        path: path.to_path_buf(),
        action: "cannot read",
        source,
    })?;
    if bytes.starts_with(b"glTF") {
        check_glb_header(path, &bytes)?;
    }
    // The gltf crate is not hardened against every corrupt input: turn a panic into an error.
    let parsed = catch_unwind(AssertUnwindSafe(|| -> Result<_, gltf::Error> {
        let gltf::Gltf { document, blob } = gltf::Gltf::from_slice(&bytes)?;
        let buffers = gltf::import_buffers(&document, path.parent(), blob)?;
        Ok((document, buffers))
    }))
    .map_err(|_| malformed(path, "the glTF parser failed on this file"))?;
    let (document, buffers) = parsed.map_err(|e| malformed(path, e.to_string()))?;

    let mut out = RawMesh {
        report: LoadReport {
            source: path.to_path_buf(),
            format: MeshFormat::Gltf,
            ..LoadReport::default()
        },
        positions: Vec::new(),
        normals: Some(Vec::new()),
        triangles: Vec::new(),
    };
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next());
    let read = catch_unwind(AssertUnwindSafe(|| -> Result<(), MeshLoadError> {
        match scene {
            Some(scene) => {
                let mut stack: Vec<(gltf::Node, DMat4, usize)> =
                    scene.nodes().map(|n| (n, DMat4::IDENTITY, 0)).collect();
                while let Some((node, parent, depth)) = stack.pop() {
                    if depth > MAX_NODE_DEPTH {
                        return Err(malformed(
                            path,
                            format!("node hierarchy deeper than {MAX_NODE_DEPTH} (cyclic?)"),
                        ));
                    }
                    let local = Mat4::from_cols_array_2d(&node.transform().matrix()).as_dmat4();
                    let world = parent * local;
                    if let Some(mesh) = node.mesh() {
                        for primitive in mesh.primitives() {
                            append_primitive(path, &primitive, &buffers, world, &mut out)?;
                        }
                    }
                    stack.extend(node.children().map(|c| (c, world, depth + 1)));
                }
            }
            None => {
                out.report
                    .notes
                    .push("the file has no scene: every mesh is loaded untransformed".into());
                for mesh in document.meshes() {
                    for primitive in mesh.primitives() {
                        append_primitive(path, &primitive, &buffers, DMat4::IDENTITY, &mut out)?;
                    }
                }
            }
        }
        Ok(())
    }))
    .map_err(|_| {
        malformed(
            path,
            "reading the mesh data failed (inconsistent accessors?)",
        )
    })?;
    read?;
    Ok(out)
}

/// Checks the 12-byte GLB header before handing the bytes to the parser.
fn check_glb_header(path: &Path, bytes: &[u8]) -> Result<(), MeshLoadError> {
    if bytes.len() < 20 {
        return Err(malformed(
            path,
            format!("GLB file of only {} bytes", bytes.len()),
        ));
    }
    let word = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    let version = word(4);
    if version != 2 {
        return Err(malformed(
            path,
            format!("GLB version {version}, expected 2"),
        ));
    }
    let length = word(8) as usize;
    if length < 20 || length > bytes.len() {
        return Err(malformed(
            path,
            format!(
                "GLB header declares {length} bytes but the file has {}",
                bytes.len()
            ),
        ));
    }
    let json_length = word(12) as usize;
    if json_length > length - 20 {
        return Err(malformed(
            path,
            format!("GLB JSON chunk of {json_length} bytes exceeds the file"),
        ));
    }
    Ok(())
}

fn append_primitive(
    path: &Path,
    primitive: &gltf::Primitive,
    buffers: &[gltf::buffer::Data],
    world: DMat4,
    out: &mut RawMesh,
) -> Result<(), MeshLoadError> {
    let mode = primitive.mode();
    if !matches!(
        mode,
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    ) {
        out.report.non_triangle_primitives_skipped += 1;
        return Ok(());
    }
    let reader = primitive.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let positions: Vec<Vec3> = reader
        .read_positions()
        .ok_or_else(|| malformed(path, "a primitive has no POSITION attribute"))?
        .map(Vec3::from_array)
        .collect();
    let normals: Option<Vec<Vec3>> = reader
        .read_normals()
        .map(|n| n.map(Vec3::from_array).collect());
    let indices: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..u32::try_from(positions.len()).map_err(|_| too_large(path))?).collect(),
    };
    let base = u32::try_from(out.positions.len()).map_err(|_| too_large(path))?;
    let count = positions.len();
    u32::try_from(out.positions.len() + count).map_err(|_| too_large(path))?;

    let identity = world == DMat4::IDENTITY;
    let linear = DMat3::from_mat4(world);
    let normal_matrix = linear.inverse().transpose();
    let mirrored = linear.determinant() < 0.0;
    if identity {
        out.positions.extend_from_slice(&positions);
    } else {
        out.positions.extend(
            positions
                .iter()
                .map(|p| world.transform_point3(p.as_dvec3()).as_vec3()),
        );
    }
    match (normals, out.normals.as_mut()) {
        (Some(n), Some(all)) if n.len() == count => {
            if identity {
                all.extend_from_slice(&n);
            } else {
                all.extend(
                    n.iter()
                        .map(|v| (normal_matrix * v.as_dvec3()).normalize_or_zero().as_vec3()),
                );
            }
        }
        (_, Some(_)) => {
            out.report
                .notes
                .push("normals dropped: a primitive has no usable NORMAL attribute".into());
            out.normals = None;
        }
        (_, None) => {}
    }

    let mut push = |a: u32, b: u32, c: u32| -> Result<(), MeshLoadError> {
        let t = [a, b, c].map(|i| base.checked_add(i));
        let [Some(a), Some(b), Some(c)] = t else {
            return Err(too_large(path));
        };
        out.triangles
            .push(if mirrored { [a, c, b] } else { [a, b, c] });
        Ok(())
    };
    match mode {
        Mode::Triangles => {
            for t in indices.chunks_exact(3) {
                push(t[0], t[1], t[2])?;
            }
        }
        Mode::TriangleStrip => {
            for k in 2..indices.len() {
                if k % 2 == 0 {
                    push(indices[k - 2], indices[k - 1], indices[k])?;
                } else {
                    push(indices[k - 1], indices[k - 2], indices[k])?;
                }
            }
        }
        Mode::TriangleFan => {
            for k in 2..indices.len() {
                push(indices[0], indices[k - 1], indices[k])?;
            }
        }
        _ => {}
    }
    Ok(())
}

fn too_large(path: &Path) -> MeshLoadError {
    MeshLoadError::TooLarge {
        path: path.to_path_buf(),
        reason: "more than 2^32 vertices or bytes".into(),
    }
}

/// Writes `mesh` as a minimal binary glTF 2.0 file: one scene, one node, one mesh, one
/// triangle primitive with `POSITION`, `NORMAL` (if the mesh has normals) and `u32` indices.
/// Loading the file back with [`crate::load_mesh`] gives the same positions, normals and
/// triangles bit for bit.
///
/// Errors: an empty mesh, more data than a GLB can hold, or an I/O failure.
pub fn write_glb(mesh: &TriangleMesh, path: &Path) -> Result<(), MeshLoadError> {
    if mesh.positions.is_empty() || mesh.triangles.is_empty() {
        return Err(MeshLoadError::Empty {
            path: path.to_path_buf(),
            triangles_read: mesh.triangles.len(),
            degenerate_skipped: 0,
        });
    }
    let n = mesh.positions.len();
    let normals = mesh.normals.as_ref().filter(|v| v.len() == n);
    let mut bin: Vec<u8> = Vec::with_capacity(n * 24 + mesh.triangles.len() * 12);
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &mesh.positions {
        for (k, c) in p.to_array().into_iter().enumerate() {
            lo[k] = lo[k].min(c);
            hi[k] = hi[k].max(c);
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    let positions_len = bin.len();
    if let Some(normals) = normals {
        for v in normals {
            for c in v.to_array() {
                bin.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    let normals_len = bin.len() - positions_len;
    let indices_offset = bin.len();
    for t in &mesh.triangles {
        for &i in t {
            bin.extend_from_slice(&i.to_le_bytes());
        }
    }
    let indices_len = bin.len() - indices_offset;

    let mut attributes = serde_json::json!({ "POSITION": 0 });
    let mut views = vec![serde_json::json!({
        "buffer": 0, "byteOffset": 0, "byteLength": positions_len, "target": 34962
    })];
    let mut accessors = vec![serde_json::json!({
        "bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3",
        "min": lo, "max": hi
    })];
    if normals.is_some() {
        attributes["NORMAL"] = serde_json::json!(1);
        views.push(serde_json::json!({
            "buffer": 0, "byteOffset": positions_len, "byteLength": normals_len, "target": 34962
        }));
        accessors.push(serde_json::json!({
            "bufferView": 1, "componentType": 5126, "count": n, "type": "VEC3"
        }));
    }
    let index_view = views.len();
    views.push(serde_json::json!({
        "buffer": 0, "byteOffset": indices_offset, "byteLength": indices_len, "target": 34963
    }));
    accessors.push(serde_json::json!({
        "bufferView": index_view, "componentType": 5125,
        "count": mesh.triangles.len() * 3, "type": "SCALAR"
    }));
    let json = serde_json::json!({
        "asset": { "version": "2.0", "generator": "marchmesh-meshio" },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [{
            "attributes": attributes,
            "indices": accessors.len() - 1,
            "mode": 4
        }]}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{ "byteLength": bin.len() }]
    });
    let mut json_bytes = json.to_string().into_bytes();
    while !json_bytes.len().is_multiple_of(4) {
        json_bytes.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json_bytes.len() + 8 + bin.len();
    let total32 = u32::try_from(total).map_err(|_| MeshLoadError::TooLarge {
        path: path.to_path_buf(),
        reason: format!("{total} bytes exceed the 4 GiB GLB limit"),
    })?;
    let mut file = Vec::with_capacity(total);
    file.extend_from_slice(b"glTF");
    file.extend_from_slice(&2u32.to_le_bytes());
    file.extend_from_slice(&total32.to_le_bytes());
    file.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    file.extend_from_slice(b"JSON");
    file.extend_from_slice(&json_bytes);
    file.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    file.extend_from_slice(b"BIN\0");
    file.extend_from_slice(&bin);
    std::fs::write(path, file).map_err(|source| MeshLoadError::Io {
        path: path.to_path_buf(),
        action: "cannot write",
        source,
    })
}
