//! Wavefront OBJ loading through `tobj`.

use std::io::BufReader;
use std::path::Path;

use glam::Vec3;

use crate::{LoadBound, LoadCheck, LoadReport, MeshFormat, MeshLoadError, RawMesh};

/// Most vertices one OBJ face may have. A polygon becomes a fan of `n - 2` triangles sharing
/// one vertex; a fan of 100,000 slivers makes every backend's build crawl, and real meshes'
/// polygons have a handful of vertices (a cylinder cap a few hundred).
pub const MAX_OBJ_FACE_VERTICES: usize = 4096;

/// Refuses a face (`f` line, with `\` continuations) of more than [`MAX_OBJ_FACE_VERTICES`]
/// vertices, and counts what parsing will allocate ([`LoadBound`]: records, face corners,
/// fan triangles), in one linear pass before parsing.
fn scan(path: &Path, bytes: &[u8]) -> Result<LoadBound, MeshLoadError> {
    let mut bound = LoadBound {
        file_bytes: bytes.len() as u64,
        ..LoadBound::default()
    };
    let mut line_no = 0usize;
    let mut in_face = false;
    let mut vertices = 0usize;
    let end_face = |bound: &mut LoadBound, vertices: usize| {
        bound.vertices += vertices as u64;
        bound.triangles += vertices.saturating_sub(2) as u64;
    };
    for line in bytes.split(|&b| b == b'\n') {
        line_no += 1;
        let mut tokens = line
            .split(|b| b.is_ascii_whitespace())
            .filter(|t| !t.is_empty());
        if !in_face {
            match tokens.next() {
                Some(b"f") => {}
                Some(b"v" | b"vn" | b"vt") => {
                    bound.records += 1;
                    continue;
                }
                _ => continue,
            }
            vertices = 0;
        }
        let mut continued = false;
        for t in tokens {
            if t == b"\\" {
                continued = true;
            } else {
                vertices += 1;
            }
        }
        in_face = continued;
        if !in_face {
            end_face(&mut bound, vertices);
        }
        if vertices > MAX_OBJ_FACE_VERTICES {
            return Err(MeshLoadError::Malformed {
                path: path.to_path_buf(),
                format: "OBJ",
                reason: format!(
                    "line {line_no}: a face of more than {MAX_OBJ_FACE_VERTICES} vertices"
                ),
            });
        }
    }
    if in_face {
        end_face(&mut bound, vertices);
    }
    Ok(bound)
}

/// Reads every model of an OBJ file (materials ignored) into one raw mesh, asking `check`
/// with the counts of [`scan`] before parsing.
pub(crate) fn load(path: &Path, check: &mut LoadCheck<'_>) -> Result<RawMesh, MeshLoadError> {
    let bytes = crate::read_file(path)?;
    let bound = scan(path, &bytes)?;
    crate::run_check(path, check, &bound)?;
    let mut reader = BufReader::new(&bytes[..]);
    let options = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    // Materials do not matter to geometry: never open .mtl files.
    let (models, _materials) = tobj::load_obj_buf(&mut reader, &options, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .map_err(|e| MeshLoadError::Malformed {
        path: path.to_path_buf(),
        format: "OBJ",
        reason: e.to_string(),
    })?;

    let mut report = LoadReport {
        source: path.to_path_buf(),
        format: MeshFormat::Obj,
        ..LoadReport::default()
    };
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut all_have_normals = true;
    let mut triangles = Vec::new();
    for model in &models {
        let m = &model.mesh;
        let base = u32::try_from(positions.len()).map_err(|_| too_large(path))?;
        let count = m.positions.len() / 3;
        positions.extend(
            m.positions
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2])),
        );
        if m.normals.len() == m.positions.len() && !m.normals.is_empty() {
            normals.extend(
                m.normals
                    .chunks_exact(3)
                    .map(|c| Vec3::new(c[0], c[1], c[2])),
            );
        } else if count > 0 {
            if all_have_normals && !m.normals.is_empty() {
                report.notes.push(format!(
                    "normals dropped: model {:?} has {} normal components for {} vertices",
                    model.name,
                    m.normals.len(),
                    count
                ));
            } else if all_have_normals && !normals.is_empty() {
                report
                    .notes
                    .push(format!("normals dropped: model {:?} has none", model.name));
            }
            all_have_normals = false;
        }
        if !m.indices.len().is_multiple_of(3) {
            return Err(MeshLoadError::Malformed {
                path: path.to_path_buf(),
                format: "OBJ",
                reason: format!(
                    "model {:?}: {} face indices is not a multiple of 3 after triangulation",
                    model.name,
                    m.indices.len()
                ),
            });
        }
        for t in m.indices.chunks_exact(3) {
            let mut tri = [0u32; 3];
            for (k, &i) in t.iter().enumerate() {
                tri[k] = base.checked_add(i).ok_or_else(|| too_large(path))?;
            }
            triangles.push(tri);
        }
    }
    u32::try_from(positions.len()).map_err(|_| too_large(path))?;
    let normals = (all_have_normals && !positions.is_empty()).then_some(normals);
    Ok(RawMesh {
        report,
        positions,
        normals,
        triangles,
    })
}

fn too_large(path: &Path) -> MeshLoadError {
    MeshLoadError::TooLarge {
        path: path.to_path_buf(),
        reason: "more than 2^32 vertices".into(),
    }
}
