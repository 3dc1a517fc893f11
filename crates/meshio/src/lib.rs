//! Triangle mesh loading for marchmesh.
//!
//! [`load_mesh`] reads Wavefront OBJ (via `tobj`; polygons are triangulated, normals optional,
//! all models merged) and glTF 2.0 (`.gltf` with its buffers, or binary `.glb`, via `gltf`;
//! every triangle primitive of every mesh instanced by the default scene, with node transforms
//! applied) into one indexed [`TriangleMesh`]. Zero-area and repeated triangles are skipped and
//! counted in the [`LoadReport`], never fatal; non-finite vertices, out-of-range indices,
//! missing or corrupt files and unknown extensions are [`MeshLoadError`]s naming the file.
//!
//! [`write_glb`] writes a mesh as a minimal binary glTF, so the project can produce its own
//! glTF test assets (a round trip reproduces the mesh bit for bit).

mod gltf_io;
mod obj;

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};

pub use gltf_io::write_glb;

/// An indexed triangle mesh in the file's own coordinates and units.
#[derive(Debug, Clone, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions (all finite).
    pub positions: Vec<Vec3>,
    /// Per-vertex unit normals, same length as `positions`; `None` when the file has none
    /// (or some were unusable, see [`LoadReport::notes`]).
    pub normals: Option<Vec<Vec3>>,
    /// Triangles as indices into `positions`, counter-clockwise seen from the front.
    pub triangles: Vec<[u32; 3]>,
    /// What loading found and changed.
    pub report: LoadReport,
}

/// The file format a mesh came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MeshFormat {
    /// Wavefront OBJ.
    #[default]
    Obj,
    /// glTF 2.0, JSON (`.gltf`) or binary (`.glb`).
    Gltf,
}

/// What loading a mesh read, skipped and changed.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LoadReport {
    /// The file loaded.
    pub source: PathBuf,
    /// Its format.
    pub format: MeshFormat,
    /// Vertices read (after OBJ face-vertex splitting; before nothing is removed).
    pub vertices_read: usize,
    /// Triangles read, after triangulating polygons, before skipping any.
    pub triangles_read: usize,
    /// Triangles skipped because their area is exactly zero (repeated or collinear corners).
    pub degenerate_skipped: usize,
    /// Triangles skipped because the same triangle (same corners, same orientation) was
    /// already present.
    pub duplicate_skipped: usize,
    /// glTF primitives skipped because they are points or lines.
    pub non_triangle_primitives_skipped: usize,
    /// Human-readable notes (e.g. why normals were dropped).
    pub notes: Vec<String>,
}

/// Why a mesh could not be loaded or written. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum MeshLoadError {
    /// The file could not be opened, read or written.
    #[error("{path}: {action}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What was attempted (`"cannot read"`, `"cannot write"`).
        action: &'static str,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file is missing, unreadable, not a regular file (a folder, device or FIFO) or
    /// larger than the read cap.
    #[error("{path}: cannot read mesh file: {reason}")]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// Why (the OS error, "not a regular file (folder)", or the cap and how to raise it).
        reason: String,
    },
    /// The extension is not `.obj`, `.gltf` or `.glb`.
    #[error("{path}: unsupported mesh file extension {extension:?} (expected .obj, .gltf or .glb)")]
    UnsupportedExtension {
        /// The file.
        path: PathBuf,
        /// Its extension (empty if none).
        extension: String,
    },
    /// The file's contents are not a valid mesh of its format.
    #[error("{path}: corrupt or unsupported {format} file: {reason}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// `"OBJ"` or `"glTF"`.
        format: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A vertex position has a NaN or infinite coordinate.
    #[error("{path}: vertex {index} has a non-finite position {position:?}")]
    NonFiniteVertex {
        /// The file.
        path: PathBuf,
        /// 0-based index of the vertex in the loaded (merged) vertex list.
        index: usize,
        /// The offending position.
        position: [f32; 3],
    },
    /// A triangle refers to a vertex that does not exist.
    #[error(
        "{path}: triangle {triangle} refers to vertex {index} but there are only {vertex_count} vertices"
    )]
    IndexOutOfRange {
        /// The file.
        path: PathBuf,
        /// 0-based triangle index.
        triangle: usize,
        /// The bad vertex index.
        index: u32,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// Nothing renderable is left.
    #[error("{path}: no usable triangles ({triangles_read} read, {degenerate_skipped} degenerate)")]
    Empty {
        /// The file.
        path: PathBuf,
        /// Triangles read.
        triangles_read: usize,
        /// Of which degenerate.
        degenerate_skipped: usize,
    },
    /// Loading the file would take more memory than the caller allows
    /// ([`load_mesh_checked`]); refused before the allocation.
    #[error("{path}: {reason}")]
    OverBudget {
        /// The file.
        path: PathBuf,
        /// The caller's reason (the estimate and the limit).
        reason: String,
    },
    /// The mesh is too large for the format (u32 indices / glb sizes).
    #[error("{path}: mesh too large: {reason}")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// What overflowed.
        reason: String,
    },
}

/// An upper bound of what loading a mesh file allocates, known before its contents are
/// decoded: from the file's size alone (before it is read: no vertices or triangles yet), then
/// from its counts (an OBJ's records and face corners in one pass over its bytes; a glTF's
/// declared buffers and the accessor counts of every primitive its node tree places).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LoadBound {
    /// Bytes read and held while loading (the file, a GLB's copied binary chunk, a glTF's
    /// buffers as declared).
    pub file_bytes: u64,
    /// OBJ `v`, `vn` and `vt` records (parsed into temporary arrays).
    pub records: u64,
    /// Most vertices of the loaded mesh (an OBJ's face corners, a glTF's placed `POSITION`
    /// counts).
    pub vertices: u64,
    /// Most triangles of the loaded mesh.
    pub triangles: u64,
}

impl LoadBound {
    /// Bytes per OBJ record while parsing (three f32 and the parser's bookkeeping).
    pub const BYTES_PER_RECORD: u64 = 16;
    /// Bytes per vertex at the peak of a load: the parser's arrays and index map, the raw
    /// and the final positions and normals.
    pub const BYTES_PER_VERTEX: u64 = 128;
    /// Bytes per triangle at the peak of a load: the parser's faces and indices, the raw and
    /// the kept triangles and the duplicate set.
    pub const BYTES_PER_TRIANGLE: u64 = 128;

    /// The message refusing a load over `limit_bytes`: `doing` (e.g. "loading it") would
    /// take `needed_bytes`, the load's own counts, then `extra` (what the caller builds from
    /// the mesh and holds already, starting with its separator).
    pub fn over_limit(
        &self,
        doing: &str,
        needed_bytes: u64,
        extra: &str,
        limit_bytes: u64,
    ) -> String {
        format!(
            "{doing} would take about {} MiB ({} MiB of file, {} records, up to {} vertices and {} triangles{extra}), over the memory limit of {} MiB; raise --memory-limit-mib or use a smaller mesh",
            needed_bytes.div_ceil(1 << 20),
            self.file_bytes.div_ceil(1 << 20),
            self.records,
            self.vertices,
            self.triangles,
            limit_bytes >> 20
        )
    }

    /// The bound in bytes (saturating).
    pub fn load_bytes(&self) -> u64 {
        self.file_bytes
            .saturating_add(self.records.saturating_mul(Self::BYTES_PER_RECORD))
            .saturating_add(self.vertices.saturating_mul(Self::BYTES_PER_VERTEX))
            .saturating_add(self.triangles.saturating_mul(Self::BYTES_PER_TRIANGLE))
    }
}

/// The check a caller of [`load_mesh_checked`] runs on each [`LoadBound`]: `Err(reason)`
/// refuses the load.
pub type LoadCheck<'a> = dyn FnMut(&LoadBound) -> Result<(), String> + 'a;

/// Loads an `.obj`, `.gltf` or `.glb` file (extension matched case-insensitively).
///
/// Errors: missing/unreadable file, unsupported extension, corrupt contents, a non-finite
/// vertex (naming its index), an out-of-range index, or no non-degenerate triangle at all.
pub fn load_mesh(path: &Path) -> Result<TriangleMesh, MeshLoadError> {
    load_mesh_checked(path, &mut |_| Ok(()))
}

/// [`load_mesh`], asking `check` before each allocation that grows with the file: with the
/// file's size before it is read, and with the counts before the mesh is decoded (see
/// [`LoadBound`]). A caller adds what it will build from the mesh (a BVH, a bake) and
/// compares with its memory limit; `Err(reason)` becomes [`MeshLoadError::OverBudget`].
pub fn load_mesh_checked(
    path: &Path,
    check: &mut LoadCheck<'_>,
) -> Result<TriangleMesh, MeshLoadError> {
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    // The size on the path; the read itself type-checks and caps the file.
    if let Ok(meta) = std::fs::metadata(path) {
        let before_reading = LoadBound {
            file_bytes: meta.len(),
            ..LoadBound::default()
        };
        run_check(path, check, &before_reading)?;
    }
    let raw = match extension.as_str() {
        "obj" => obj::load(path, check)?,
        "gltf" | "glb" => gltf_io::load(path, check)?,
        _ => {
            return Err(MeshLoadError::UnsupportedExtension {
                path: path.to_path_buf(),
                extension,
            });
        }
    };
    assemble(raw)
}

/// Runs the caller's check on `bound`, naming the file in a refusal.
pub(crate) fn run_check(
    path: &Path,
    check: &mut LoadCheck<'_>,
    bound: &LoadBound,
) -> Result<(), MeshLoadError> {
    check(bound).map_err(|reason| MeshLoadError::OverBudget {
        path: path.to_path_buf(),
        reason,
    })
}

/// Reads a mesh file with the [`marchmesh_safeio`] cap (1 GiB unless `MARCHMESH_MAX_READ_MIB`
/// says otherwise), refusing folders, devices and FIFOs.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, MeshLoadError> {
    marchmesh_safeio::read_regular(path).map_err(|e| MeshLoadError::Unreadable {
        path: path.to_path_buf(),
        reason: match e {
            marchmesh_safeio::SafeIoError::Io { source, .. } => source.to_string(),
            other => strip_path(&other.to_string(), path),
        },
    })
}

/// `message` without a leading `"{path}: "`, so the path is not printed twice.
fn strip_path(message: &str, path: &Path) -> String {
    let prefix = format!("{}: ", path.display());
    message.strip_prefix(&prefix).unwrap_or(message).to_string()
}

/// A mesh as read from a file, before validation.
pub(crate) struct RawMesh {
    pub report: LoadReport,
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    pub triangles: Vec<[u32; 3]>,
}

/// Validates a raw mesh: rejects non-finite vertices and bad indices, drops unusable normals,
/// skips degenerate and duplicate triangles.
pub(crate) fn assemble(raw: RawMesh) -> Result<TriangleMesh, MeshLoadError> {
    let RawMesh {
        mut report,
        positions,
        mut normals,
        triangles,
    } = raw;
    let path = report.source.clone();
    if let Some(index) = positions.iter().position(|p| !p.is_finite()) {
        return Err(MeshLoadError::NonFiniteVertex {
            path,
            index,
            position: positions[index].to_array(),
        });
    }
    if let Some(n) = &normals {
        if n.len() != positions.len() {
            report.notes.push(format!(
                "normals dropped: {} normals for {} vertices",
                n.len(),
                positions.len()
            ));
            normals = None;
        } else if let Some(i) = n
            .iter()
            .position(|v| !v.is_finite() || v.length_squared() == 0.0)
        {
            report.notes.push(format!(
                "normals dropped: vertex {i} has an unusable normal {:?}; geometric normals are used",
                n[i].to_array()
            ));
            normals = None;
        }
    }
    if let Some(n) = &mut normals {
        // Renormalise only normals that are not unit already, so a written-and-reloaded mesh
        // keeps its normals bit for bit.
        for v in n.iter_mut() {
            if (v.length_squared() - 1.0).abs() > 1e-5 {
                *v = v.normalize();
            }
        }
    }
    report.vertices_read = positions.len();
    report.triangles_read = triangles.len();
    let vertex_count = positions.len();
    let mut kept = Vec::with_capacity(triangles.len());
    let mut seen: HashSet<[u32; 3]> = HashSet::with_capacity(triangles.len());
    for (t, tri) in triangles.iter().enumerate() {
        if let Some(&index) = tri.iter().find(|&&i| i as usize >= vertex_count) {
            return Err(MeshLoadError::IndexOutOfRange {
                path,
                triangle: t,
                index,
                vertex_count,
            });
        }
        let [a, b, c] = tri.map(|i| positions[i as usize].as_dvec3());
        if (b - a).cross(c - a) == DVec3::ZERO {
            report.degenerate_skipped += 1;
            continue;
        }
        if !seen.insert(canonical_rotation(*tri)) {
            report.duplicate_skipped += 1;
            continue;
        }
        kept.push(*tri);
    }
    if kept.is_empty() {
        return Err(MeshLoadError::Empty {
            path,
            triangles_read: report.triangles_read,
            degenerate_skipped: report.degenerate_skipped,
        });
    }
    Ok(TriangleMesh {
        positions,
        normals,
        triangles: kept,
        report,
    })
}

/// The rotation of a triangle's indices that starts at the smallest (orientation kept).
fn canonical_rotation(t: [u32; 3]) -> [u32; 3] {
    if t[0] <= t[1] && t[0] <= t[2] {
        t
    } else if t[1] <= t[2] {
        [t[1], t[2], t[0]]
    } else {
        [t[2], t[0], t[1]]
    }
}

impl TriangleMesh {
    /// Axis-aligned bounds `(min, max)` of the vertices referenced by triangles; an empty mesh
    /// gives the inverted box `(+inf, -inf)`.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::INFINITY;
        let mut hi = Vec3::NEG_INFINITY;
        for t in &self.triangles {
            for &i in t {
                if let Some(&p) = self.positions.get(i as usize) {
                    lo = lo.min(p);
                    hi = hi.max(p);
                }
            }
        }
        (lo, hi)
    }

    /// A 64-bit FNV-1a hash of positions, normals and triangles (not the report), stable
    /// across runs, platforms and builds: a cache key for derived data.
    pub fn content_hash(&self) -> u64 {
        let mut h = Fnv1a::new();
        h.write_u64(self.positions.len() as u64);
        for p in &self.positions {
            for c in p.to_array() {
                h.write_u32(c.to_bits());
            }
        }
        match &self.normals {
            Some(n) => {
                h.write_u64(1 + n.len() as u64);
                for v in n {
                    for c in v.to_array() {
                        h.write_u32(c.to_bits());
                    }
                }
            }
            None => h.write_u64(0),
        }
        h.write_u64(self.triangles.len() as u64);
        for t in &self.triangles {
            for &i in t {
                h.write_u32(i);
            }
        }
        h.finish()
    }

    /// True when every edge is shared by exactly two triangles, vertices being identified by
    /// position (so meshes split at normal seams still count as closed). An empty mesh is not
    /// closed.
    pub fn is_closed(&self) -> bool {
        !self.triangles.is_empty()
            && self
                .edge_uses()
                .is_some_and(|edges| edges.values().all(|e| e.uses == 2))
    }

    /// Every undirected edge of the mesh, vertices welded by position (bitwise equal
    /// coordinates share an index), keyed `(low, high)` welded index, with how its triangles
    /// walk it. `None` when a triangle indexes past the positions.
    pub fn edge_uses(&self) -> Option<HashMap<(u32, u32), EdgeUses>> {
        let mut weld: HashMap<[u32; 3], u32> = HashMap::with_capacity(self.positions.len());
        let welded: Vec<u32> = self
            .positions
            .iter()
            .map(|p| {
                let key = p.to_array().map(f32::to_bits);
                let next = weld.len() as u32;
                *weld.entry(key).or_insert(next)
            })
            .collect();
        let mut edges: HashMap<(u32, u32), EdgeUses> =
            HashMap::with_capacity(self.triangles.len() * 2);
        for t in &self.triangles {
            for k in 0..3 {
                let a = *welded.get(t[k] as usize)?;
                let b = *welded.get(t[(k + 1) % 3] as usize)?;
                let e = edges.entry((a.min(b), a.max(b))).or_default();
                e.net += (a < b) as i32 - (a > b) as i32;
                e.uses += 1;
            }
        }
        Some(edges)
    }

    /// Exact bytes of positions, normals and indices (lengths, not capacities).
    pub fn memory_bytes(&self) -> u64 {
        let v = std::mem::size_of::<Vec3>() as u64;
        self.positions.len() as u64 * v
            + self.normals.as_ref().map_or(0, |n| n.len() as u64 * v)
            + self.triangles.len() as u64 * std::mem::size_of::<[u32; 3]>() as u64
    }
}

/// How the triangles of a mesh walk one undirected edge `(low, high)` (see
/// [`TriangleMesh::edge_uses`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EdgeUses {
    /// Walks from low to high minus walks from high to low: 0 when the faces around the edge
    /// agree on their orientation; always 0 for a degenerate edge (`low == high`).
    pub net: i32,
    /// Triangles walking the edge (2 on a closed manifold).
    pub uses: u32,
}

/// 64-bit FNV-1a (stable, unlike `std`'s `DefaultHasher`).
struct Fnv1a(u64);

impl Fnv1a {
    fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    fn write_u32(&mut self, v: u32) {
        self.write(&v.to_le_bytes());
    }
    fn write_u64(&mut self, v: u64) {
        self.write(&v.to_le_bytes());
    }
    fn finish(&self) -> u64 {
        self.0
    }
}

#[cfg(test)]
mod tests;
