//! Compiling the resolved scene into the reference's object tree: closed-form leaves in their
//! own frames, CSG and repetition nodes with their boxes, smooth unions with their f64 fields,
//! mesh files loaded once.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{DAffine3, DVec3};
use marchmesh_field::{Field, FieldOptions};
use marchmesh_meshio::{MeshLoadError, TriangleMesh, load_mesh_checked};
use marchmesh_scene::bounds::{Aabb, LocalBounds, combine};
use marchmesh_scene::{Node, NodeKind, Shape};

use crate::meshbvh::MeshData;
use crate::node::{CompiledKind, CompiledNode, MAX_COPIES_PER_CELL};
use crate::repeat::Repeat;
use crate::smooth::Smooth;
use crate::{MESH_BYTES_PER_TRIANGLE, MESH_BYTES_PER_VERTEX, ReferenceError, ReferenceOptions};

/// Smooth unions of at least this many field nodes get their field pruned per region.
const SMOOTH_PRUNE_MIN_NODES: usize = 16;

/// Octree depth of a smooth union's pruned field (`2^6` finest cells per axis).
const SMOOTH_PRUNE_DEPTH: u32 = 6;

/// Largest change the pruning may make to a smooth union's f64 field, as a fraction of its
/// box's longest side: near f64's resolution, so the roots found are the whole field's to
/// within far less than the root finder's tolerance (`smooth_union_tolerance`).
const SMOOTH_PRUNE_MAX_ERROR_REL: f64 = 1e-13;

/// Loads each mesh file once.
pub(crate) struct Compiler<'a> {
    pub options: &'a ReferenceOptions,
    pub meshes: HashMap<PathBuf, Arc<MeshData>>,
    pub mesh_bytes: u64,
    pub notes: Vec<String>,
}

pub(crate) fn transform_bounds(m: &DAffine3, (lo, hi): (DVec3, DVec3)) -> (DVec3, DVec3) {
    let b = Aabb::new(lo, hi).transformed(m);
    (b.lo, b.hi)
}

/// A leaf shape's box in its own frame (the scene's one definition); `None` when unbounded.
pub(crate) fn leaf_bounds(shape: &Shape) -> Option<(DVec3, DVec3)> {
    match shape.local_bounds() {
        LocalBounds::Finite(b) => Some((b.lo, b.hi)),
        LocalBounds::Unbounded | LocalBounds::MeshFile(_) | LocalBounds::Composite => None,
    }
}

/// A CSG node's box from its compiled children's (the scene's rules); `None` when unbounded.
pub(crate) fn combined_bounds(
    kind: &NodeKind,
    children: &[CompiledNode],
) -> Option<(DVec3, DVec3)> {
    let boxes: Vec<Aabb> = children
        .iter()
        .map(|c| {
            c.bounds
                .map_or(Aabb::INFINITE, |(lo, hi)| Aabb::new(lo, hi))
        })
        .collect();
    combine(kind, &boxes)?.finite()
}

impl Compiler<'_> {
    /// Loads a mesh file, refused before it is read, and again before it is decoded, when
    /// the meshes already loaded, the load and the f64 copy with its BVH would exceed
    /// [`ReferenceOptions::memory_limit_bytes`].
    fn load_within_limit(&self, path: &Path) -> Result<TriangleMesh, MeshLoadError> {
        let (held, limit) = (self.mesh_bytes, self.options.memory_limit_bytes);
        load_mesh_checked(path, &mut |b| {
            let kept = b
                .triangles
                .saturating_mul(MESH_BYTES_PER_TRIANGLE)
                .saturating_add(b.vertices.saturating_mul(MESH_BYTES_PER_VERTEX));
            let needed = held.saturating_add(b.load_bytes()).saturating_add(kept);
            if needed <= limit {
                return Ok(());
            }
            Err(b.over_limit(
                "loading it",
                needed,
                &format!(
                    " and their f64 copy with its BVH, {} MiB of meshes already loaded",
                    held.div_ceil(1 << 20)
                ),
                limit,
            ))
        })
    }

    /// Compiles `node`; `parent_to_frame` maps the node's parent frame to the frame the
    /// result is queried in (render space for top-level objects, identity below).
    pub fn compile(
        &mut self,
        node: &Node,
        parent_to_frame: DAffine3,
    ) -> Result<CompiledNode, ReferenceError> {
        let to_frame = parent_to_frame * node.transform;
        let to_local = to_frame.inverse();
        let unsupported = |reason: &str| ReferenceError::Unsupported {
            json_path: node.json_path.clone(),
            reason: reason.to_string(),
        };
        let (kind, local_bounds, solid): (CompiledKind, Option<(DVec3, DVec3)>, bool) = match &node
            .kind
        {
            NodeKind::Leaf(Shape::Mesh { path }) => {
                let mesh = match self.meshes.get(path) {
                    Some(m) => m.clone(),
                    None => {
                        let loaded =
                            self.load_within_limit(path)
                                .map_err(|e| ReferenceError::Mesh {
                                    json_path: node.json_path.clone(),
                                    reason: e.to_string(),
                                })?;
                        let m = Arc::new(MeshData::new(&loaded));
                        self.mesh_bytes += m.memory_bytes();
                        self.notes.push(format!(
                            "{}: {} triangles, {}",
                            path.display(),
                            m.triangle_count(),
                            if m.closed {
                                "closed (a solid)"
                            } else {
                                "open (a surface only)"
                            }
                        ));
                        self.meshes.insert(path.clone(), m.clone());
                        m
                    }
                };
                let b = mesh.bounds();
                let closed = mesh.closed;
                (CompiledKind::Mesh(mesh), Some(b), closed)
            }
            // A triangle has no inside; every other shape bounds a solid (a plane: its
            // half-space).
            NodeKind::Leaf(shape) => (
                CompiledKind::Shape(shape.clone()),
                leaf_bounds(shape),
                !matches!(shape, Shape::Triangle { .. }),
            ),
            NodeKind::Union(children) => {
                let c = self.children(children)?;
                let b = combined_bounds(&node.kind, &c);
                let solid = c.iter().all(|c| c.solid);
                (CompiledKind::Union(c), b, solid)
            }
            NodeKind::Intersection(children) | NodeKind::Subtraction(children) => {
                let c = self.children(children)?;
                if let Some(bad) = children.iter().zip(&c).find(|(_, r)| !r.solid) {
                    return Err(ReferenceError::Unsupported {
                        json_path: bad.0.json_path.clone(),
                        reason: "intersection and subtraction need solids; triangles and open meshes have no inside".into(),
                    });
                }
                let is_intersection = matches!(node.kind, NodeKind::Intersection(_));
                let b = combined_bounds(&node.kind, &c);
                let kind = if is_intersection {
                    CompiledKind::Intersection(c)
                } else {
                    CompiledKind::Subtraction(c)
                };
                (kind, b, true)
            }
            NodeKind::Smooth { .. } => {
                let mut field = Field::compile_node(
                    node,
                    node.transform.inverse(),
                    &FieldOptions {
                        memory_limit_bytes: self
                            .options
                            .memory_limit_bytes
                            .saturating_sub(self.mesh_bytes),
                        ..FieldOptions::default()
                    },
                )
                .map_err(|e| unsupported(&format!("its distance field could not be built: {e}")))?;
                // Pruned per region: the root finding then reads, at each point, only the
                // children that can change the blend there (values within
                // SMOOTH_PRUNE_MAX_ERROR_REL of the whole field's) and crosses empty cells in
                // one step each.
                if field.node_count() >= SMOOTH_PRUNE_MIN_NODES {
                    field.build_cells(SMOOTH_PRUNE_DEPTH, SMOOTH_PRUNE_MAX_ERROR_REL);
                }
                let bounds = field.bounds();
                let size = bounds.map_or(1.0, |(lo, hi)| (hi - lo).length().max(1e-300));
                let smooth = Smooth {
                    field,
                    bounds,
                    eps: self.options.smooth_union_tolerance * size,
                    h: 1e-6 * size,
                    max_steps: self.options.smooth_union_max_steps,
                };
                (CompiledKind::Smooth(Box::new(smooth)), bounds, true)
            }
            NodeKind::Repeat {
                child,
                period,
                count,
            } => {
                let c = self.compile(child, DAffine3::IDENTITY)?;
                let Some(cb) = c.bounds else {
                    return Err(unsupported(
                        "repetition of an unbounded child (a plane or an infinite repetition) is not supported by the reference",
                    ));
                };
                let mut range = [None; 3];
                let mut reach = [(0, 0); 3];
                let (mut lo, mut hi) = cb;
                let mut bounded = true;
                for a in 0..3 {
                    if period[a] <= 0.0 {
                        continue;
                    }
                    let p = period[a];
                    reach[a] = (
                        (-0.5 - cb.1[a] / p).ceil() as i64,
                        (0.5 - cb.0[a] / p).floor() as i64,
                    );
                    match count[a] {
                        Some(n) => {
                            let off = if n % 2 == 0 { 0.5 } else { 0.0 };
                            let half = (i64::from(n) - 1) / 2;
                            let (j0, j1) = if n % 2 == 0 {
                                (-half - 1, half)
                            } else {
                                (-half, half)
                            };
                            range[a] = Some((j0, j1, off));
                            lo[a] = cb.0[a] + (j0 as f64 + off) * p;
                            hi[a] = cb.1[a] + (j1 as f64 + off) * p;
                        }
                        None => {
                            range[a] = Some((i64::MIN / 4, i64::MAX / 4, 0.0));
                            bounded = false;
                        }
                    }
                }
                // Copies a cell can see: bounded so a child far larger than its period
                // cannot make every ray test millions of copies.
                let per_cell: f64 = (0..3)
                    .map(|a| {
                        let width = (reach[a].1 - reach[a].0 + 1) as f64;
                        match range[a] {
                            Some((j0, j1, _)) => width.min((j1 - j0 + 1) as f64),
                            None => 1.0,
                        }
                    })
                    .product();
                if per_cell > f64::from(MAX_COPIES_PER_CELL) {
                    return Err(unsupported(&format!(
                        "the repeated child is so much larger than its period that each cell overlaps {per_cell:.0} copies (limit {MAX_COPIES_PER_CELL}); increase the period or shrink the child"
                    )));
                }
                let rep = Repeat {
                    child: c,
                    period: *period,
                    range,
                    child_bounds: cb,
                    reach,
                    copies_overlap: reach.iter().any(|r| *r != (0, 0)),
                    max_cells: self.options.max_repeat_cells,
                };
                let solid = rep.child.solid;
                (
                    CompiledKind::Repeat(Box::new(rep)),
                    bounded.then_some((lo, hi)),
                    solid,
                )
            }
        };
        Ok(CompiledNode {
            to_local,
            normal_to_parent: to_local.matrix3.transpose(),
            material: node.material,
            bounds: local_bounds.map(|b| transform_bounds(&to_frame, b)),
            solid,
            kind,
        })
    }

    pub(crate) fn children(
        &mut self,
        children: &[Node],
    ) -> Result<Vec<CompiledNode>, ReferenceError> {
        children
            .iter()
            .map(|c| self.compile(c, DAffine3::IDENTITY))
            .collect()
    }
}
