//! glTF 2.0 loading through `gltf`, and a minimal binary glTF writer.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use glam::{DMat3, DMat4, Mat4, Vec3};
use gltf::mesh::Mode;

use crate::{LoadBound, LoadCheck, LoadReport, MeshFormat, MeshLoadError, RawMesh, TriangleMesh};

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
/// mesh untransformed if the file has no scene), node transforms applied, asking `check` with
/// [`load_bound`] before any buffer is read.
pub(crate) fn load(path: &Path, check: &mut LoadCheck<'_>) -> Result<RawMesh, MeshLoadError> {
    let bytes = crate::read_file(path)?;
    if bytes.starts_with(b"glTF") {
        check_glb_header(path, &bytes)?;
    }
    // The gltf crate is not hardened against every corrupt input: turn a panic into an error.
    let parsed = catch_unwind(AssertUnwindSafe(|| -> Result<_, gltf::Error> {
        let gltf::Gltf { document, blob } = gltf::Gltf::from_slice(&bytes)?;
        Ok((document, blob))
    }))
    .map_err(|_| malformed(path, "the glTF parser failed on this file"))?;
    let (document, blob) = parsed.map_err(|e| malformed(path, e.to_string()))?;
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next());
    check_node_tree(path, &document, scene.as_ref())?;
    crate::run_check(
        path,
        check,
        &load_bound(&document, scene.as_ref(), bytes.len() as u64),
    )?;
    let buffers = load_buffers(path, &document, blob)?;
    check_accessors(path, &document, &buffers)?;

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

/// Loads every buffer of `document`: the GLB blob, a `data:` URI (base64), or a file named by
/// a relative URI that, percent-decoded and canonicalised (symlinks resolved), lies inside the
/// glTF's own folder. Absolute paths, other schemes (`file:`, `http:`) and paths escaping the
/// folder are refused naming the glTF and the URI; files are read with the [`crate::read_file`]
/// cap and must hold at least the buffer's declared `byteLength`, which is checked before reading.
fn load_buffers(
    path: &Path,
    document: &gltf::Document,
    mut blob: Option<Vec<u8>>,
) -> Result<Vec<Vec<u8>>, MeshLoadError> {
    let cap = marchmesh_safeio::read_cap_bytes().map_err(|e| MeshLoadError::Unreadable {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let folder = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for buffer in document.buffers() {
        let declared = buffer.length() as u64;
        if declared > cap {
            return Err(malformed(
                path,
                format!(
                    "buffer {} declares {declared} bytes, over the read limit of {cap} bytes (set {} in MiB to raise it)",
                    buffer.index(),
                    marchmesh_safeio::READ_CAP_ENV
                ),
            ));
        }
        let mut data = match buffer.source() {
            gltf::buffer::Source::Bin => blob
                .take()
                .ok_or_else(|| malformed(path, "a buffer refers to a missing GLB binary chunk"))?,
            gltf::buffer::Source::Uri(uri) => load_uri(path, folder, uri, cap)?,
        };
        if (data.len() as u64) < declared {
            return Err(malformed(
                path,
                format!(
                    "buffer {} declares {declared} bytes but holds only {}",
                    buffer.index(),
                    data.len()
                ),
            ));
        }
        data.truncate(declared as usize);
        out.push(data);
    }
    Ok(out)
}

/// The bytes of one buffer URI, confined as [`load_buffers`] describes.
fn load_uri(path: &Path, folder: &Path, uri: &str, cap: u64) -> Result<Vec<u8>, MeshLoadError> {
    let refuse = |why: &str| malformed(path, format!("buffer URI {uri:?} refused: {why}"));
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, payload) = rest
            .split_once(";base64,")
            .ok_or_else(|| refuse("only base64 data: URIs are supported"))?;
        if payload.len() as u64 / 4 * 3 > cap {
            return Err(refuse("larger than the read limit"));
        }
        return base64::decode(payload).map_err(|e| refuse(&format!("bad base64: {e}")));
    }
    let decoded = percent_decode(uri).ok_or_else(|| refuse("bad percent-encoding"))?;
    if decoded.contains(':') || decoded.starts_with('/') || decoded.starts_with('\\') {
        return Err(refuse(
            "only data: URIs and relative paths inside the glTF's folder are allowed",
        ));
    }
    let folder = folder.canonicalize().map_err(|source| MeshLoadError::Io {
        path: folder.to_path_buf(),
        action: "cannot resolve the glTF's folder",
        source,
    })?;
    let target = folder
        .join(&decoded)
        .canonicalize()
        .map_err(|e| refuse(&format!("cannot resolve: {e}")))?;
    if !target.starts_with(&folder) {
        return Err(refuse("it resolves outside the glTF's folder"));
    }
    marchmesh_safeio::read_capped(&target, cap).map_err(|e| refuse(&e.to_string()))
}

/// Decodes `%XX` escapes; `None` for a malformed escape or non-UTF-8 result.
fn percent_decode(uri: &str) -> Option<String> {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// What loading `document` allocates at most ([`LoadBound`]), from its declared sizes: the
/// file (`file_bytes`, twice: a GLB's binary chunk is copied) and every buffer as declared;
/// the vertices and triangles of every triangle primitive once per node that places it
/// (the node graph is a tree, checked first), or once per mesh without a scene.
fn load_bound(
    document: &gltf::Document,
    scene: Option<&gltf::Scene>,
    file_bytes: u64,
) -> LoadBound {
    let mut bound = LoadBound {
        file_bytes: document
            .buffers()
            .map(|b| b.length() as u64)
            .fold(file_bytes.saturating_mul(2), u64::saturating_add),
        ..LoadBound::default()
    };
    let mut add_mesh = |mesh: gltf::Mesh| {
        for primitive in mesh.primitives() {
            let vertices = primitive
                .get(&gltf::Semantic::Positions)
                .map_or(0, |a| a.count() as u64);
            let corners = primitive.indices().map_or(vertices, |a| a.count() as u64);
            let triangles = match primitive.mode() {
                Mode::Triangles => corners / 3,
                Mode::TriangleStrip | Mode::TriangleFan => corners.saturating_sub(2),
                _ => continue,
            };
            bound.vertices = bound.vertices.saturating_add(vertices);
            bound.triangles = bound.triangles.saturating_add(triangles);
        }
    };
    match scene {
        Some(scene) => {
            let mut stack: Vec<gltf::Node> = scene.nodes().collect();
            while let Some(node) = stack.pop() {
                if let Some(mesh) = node.mesh() {
                    add_mesh(mesh);
                }
                stack.extend(node.children());
            }
        }
        None => document.meshes().for_each(add_mesh),
    }
    bound
}

/// Checks, before any accessor is read, that every buffer view lies inside its buffer, every
/// accessor inside its view (or buffer), index accessors are unsigned-integer `SCALAR`s and
/// `POSITION` accessors are `VEC3` of `FLOAT`: the `gltf` reader would panic or silently
/// misread otherwise.
fn check_accessors(
    path: &Path,
    document: &gltf::Document,
    buffers: &[Vec<u8>],
) -> Result<(), MeshLoadError> {
    use gltf::accessor::{DataType, Dimensions};
    for view in document.views() {
        let have = buffers.get(view.buffer().index()).map_or(0, Vec::len);
        let end = view.offset().checked_add(view.length());
        if end.is_none_or(|end| end > have) {
            return Err(malformed(
                path,
                format!(
                    "buffer view {} ends at byte {} but buffer {} has {have} bytes",
                    view.index(),
                    view.offset().saturating_add(view.length()),
                    view.buffer().index()
                ),
            ));
        }
    }
    for accessor in document.accessors() {
        if accessor.sparse().is_some() {
            return Err(malformed(
                path,
                format!(
                    "accessor {} is sparse ({} elements): sparse accessors are not supported",
                    accessor.index(),
                    accessor.count()
                ),
            ));
        }
        let Some(view) = accessor.view() else {
            return Err(malformed(
                path,
                format!(
                    "accessor {} has no buffer view ({} elements): not supported",
                    accessor.index(),
                    accessor.count()
                ),
            ));
        };
        let element = accessor.size();
        if let Some(stride) = view.stride()
            && stride < element
        {
            return Err(malformed(
                path,
                format!(
                    "buffer view {} has byteStride {stride}, smaller than the {element}-byte elements of accessor {}",
                    view.index(),
                    accessor.index()
                ),
            ));
        }
        let stride = view.stride().unwrap_or(element);
        let span = accessor
            .count()
            .checked_sub(1)
            .map_or(Some(0), |n| n.checked_mul(stride)?.checked_add(element));
        let end = span.and_then(|s| s.checked_add(accessor.offset()));
        if end.is_none_or(|end| end > view.length()) {
            return Err(malformed(
                path,
                format!(
                    "accessor {} ({} elements) does not fit in buffer view {} of {} bytes",
                    accessor.index(),
                    accessor.count(),
                    view.index(),
                    view.length()
                ),
            ));
        }
    }
    for mesh in document.meshes() {
        for primitive in mesh.primitives() {
            if let Some(indices) = primitive.indices() {
                let ok_type = matches!(
                    indices.data_type(),
                    DataType::U8 | DataType::U16 | DataType::U32
                );
                if !ok_type || indices.dimensions() != Dimensions::Scalar {
                    return Err(malformed(
                        path,
                        format!(
                            "index accessor {} is {:?} {:?}; indices must be SCALAR unsigned integers",
                            indices.index(),
                            indices.dimensions(),
                            indices.data_type()
                        ),
                    ));
                }
            }
            for (semantic, accessor) in primitive.attributes() {
                if semantic == gltf::Semantic::Positions
                    && (accessor.dimensions() != Dimensions::Vec3
                        || accessor.data_type() != DataType::F32)
                {
                    return Err(malformed(
                        path,
                        format!(
                            "POSITION accessor {} is {:?} {:?}; it must be VEC3 FLOAT",
                            accessor.index(),
                            accessor.dimensions(),
                            accessor.data_type()
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// Checks that the node graph is a tree (glTF 2.0, section 3.5.3): no node is the child of two
/// parents or twice of one, and the scene lists each root once and no child as a root. Each
/// node is then visited at most once, so a 1 KB file cannot expand to 2^N instances.
fn check_node_tree(
    path: &Path,
    document: &gltf::Document,
    scene: Option<&gltf::Scene>,
) -> Result<(), MeshLoadError> {
    let mut has_parent = vec![false; document.nodes().len()];
    for node in document.nodes() {
        for child in node.children() {
            let seen = has_parent.get_mut(child.index()).ok_or_else(|| {
                malformed(path, format!("node {} has a missing child", node.index()))
            })?;
            if *seen {
                return Err(malformed(
                    path,
                    format!(
                        "node {} is listed as a child more than once (node {} lists it): glTF node graphs must be trees",
                        child.index(),
                        node.index()
                    ),
                ));
            }
            *seen = true;
        }
    }
    if let Some(scene) = scene {
        let mut is_root = vec![false; has_parent.len()];
        for root in scene.nodes() {
            let i = root.index();
            if has_parent.get(i).copied().unwrap_or(true) || is_root[i] {
                return Err(malformed(
                    path,
                    format!(
                        "scene {} lists node {i} more than once or also as a child: glTF node graphs must be trees",
                        scene.index()
                    ),
                ));
            }
            is_root[i] = true;
        }
    }
    Ok(())
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
    buffers: &[Vec<u8>],
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
    let reader = primitive.reader(|b| buffers.get(b.index()).map(|d| &d[..]));
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
