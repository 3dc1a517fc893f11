//! The reference's compiled object tree and its two queries: the closest surface along a
//! ray, and the spans of a solid along a ray (for CSG).

use std::collections::{HashMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;

use glam::{DAffine3, DMat3, DVec3};
use marchmesh_field::{Field, FieldOptions};
use marchmesh_meshio::load_mesh;
use marchmesh_scene::bounds::{Aabb, LocalBounds, combine};
use marchmesh_scene::{MaterialId, Node, NodeKind};

use crate::meshbvh::MeshData;
use crate::primitives;
use crate::spans::{Boundary, Op, Span, combine_all, first_boundary};
use crate::{ReferenceError, ReferenceOptions};

/// Work counters of one query.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Work {
    /// Repetition cells walked and smooth-union field evaluations.
    pub steps: u32,
    /// BVH nodes visited.
    pub nodes: u32,
    /// Primitive and triangle tests.
    pub tests: u32,
    /// A bounded search gave up before deciding.
    pub exhausted: bool,
}

/// A smooth union: its f64 field in the node's local frame and the search settings.
#[derive(Debug)]
pub(crate) struct Smooth {
    field: Field,
    bounds: Option<(DVec3, DVec3)>,
    /// Absolute root tolerance and minimum march step, local units.
    eps: f64,
    /// Central-difference step for normals, local units.
    h: f64,
    max_steps: u32,
}

/// Domain repetition of one child.
#[derive(Debug)]
pub(crate) struct Repeat {
    child: RNode,
    period: DVec3,
    /// Per axis: `Some((j_min, j_max, offset))` copies at `(j + offset) * period`; `None` for
    /// an axis that is not repeated.
    range: [Option<(i64, i64, f64)>; 3],
    /// Child bounds in the repetition frame (before the copy offset).
    child_bounds: (DVec3, DVec3),
    /// Neighbour offsets whose copies can reach into a cell, per axis.
    reach: [(i64, i64); 3],
    /// Some copy reaches beyond its cell (`reach` is not all zero), so copies may overlap.
    copies_overlap: bool,
    max_cells: u32,
}

#[derive(Debug)]
pub(crate) enum RKind {
    Sphere(f64),
    Ellipsoid(DVec3),
    Box(DVec3),
    Cylinder(f64, f64),
    Torus(f64, f64),
    Plane(DVec3, f64),
    Triangle([DVec3; 3]),
    Mesh(Arc<MeshData>),
    Union(Vec<RNode>),
    Intersection(Vec<RNode>),
    Subtraction(Vec<RNode>),
    Smooth(Box<Smooth>),
    Repeat(Box<Repeat>),
}

/// A node in its parent's frame.
#[derive(Debug)]
pub(crate) struct RNode {
    to_local: DAffine3,
    normal_to_parent: DMat3,
    material: MaterialId,
    /// Bounds in the parent frame, `None` when unbounded.
    pub bounds: Option<(DVec3, DVec3)>,
    /// Whether the node bounds a solid (has an inside), needed under intersection and
    /// subtraction.
    solid: bool,
    kind: RKind,
}

/// Most iterative work (repetition cells walked plus smooth-union field evaluations) one
/// query may spend before it gives up with `MaxSteps`: bounds the time of pathological but
/// valid scenes (an infinite repetition of a squashed smooth union) to about a second per
/// ray instead of hours.
pub(crate) const MAX_WORK_PER_QUERY: u32 = 4_000_000;

/// Most copies of a repeated child that may overlap one cell (see [`Repeat`]).
pub(crate) const MAX_COPIES_PER_CELL: u32 = 4096;

/// Loads each mesh file once.
pub(crate) struct Compiler<'a> {
    pub options: &'a ReferenceOptions,
    pub meshes: HashMap<PathBuf, Arc<MeshData>>,
    pub mesh_bytes: u64,
    pub notes: Vec<String>,
}

fn transform_bounds(m: &DAffine3, (lo, hi): (DVec3, DVec3)) -> (DVec3, DVec3) {
    let b = Aabb::new(lo, hi).transformed(m);
    (b.lo, b.hi)
}

/// A leaf shape's box in its own frame (the scene's one definition); `None` when unbounded.
fn leaf_bounds(kind: &NodeKind) -> Option<(DVec3, DVec3)> {
    match kind.local_bounds() {
        LocalBounds::Finite(b) => Some((b.lo, b.hi)),
        LocalBounds::Unbounded | LocalBounds::MeshFile(_) | LocalBounds::Composite => None,
    }
}

/// A CSG node's box from its compiled children's (the scene's rules); `None` when unbounded.
fn combined_bounds(kind: &NodeKind, children: &[RNode]) -> Option<(DVec3, DVec3)> {
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
    /// Compiles `node`; `parent_to_frame` maps the node's parent frame to the frame the
    /// result is queried in (render space for top-level objects, identity below).
    pub fn compile(
        &mut self,
        node: &Node,
        parent_to_frame: DAffine3,
    ) -> Result<RNode, ReferenceError> {
        let to_frame = parent_to_frame * node.transform;
        let to_local = to_frame.inverse();
        let unsupported = |reason: &str| ReferenceError::Unsupported {
            json_path: node.json_path.clone(),
            reason: reason.to_string(),
        };
        let (kind, local_bounds, solid): (RKind, Option<(DVec3, DVec3)>, bool) = match &node.kind {
            NodeKind::Sphere { radius } => (RKind::Sphere(*radius), leaf_bounds(&node.kind), true),
            NodeKind::Ellipsoid { radii } => {
                (RKind::Ellipsoid(*radii), leaf_bounds(&node.kind), true)
            }
            NodeKind::Box { half_extents } => {
                (RKind::Box(*half_extents), leaf_bounds(&node.kind), true)
            }
            NodeKind::Cylinder {
                radius,
                half_height,
            } => (
                RKind::Cylinder(*radius, *half_height),
                leaf_bounds(&node.kind),
                true,
            ),
            NodeKind::Torus {
                major_radius,
                minor_radius,
            } => (
                RKind::Torus(*major_radius, *minor_radius),
                leaf_bounds(&node.kind),
                true,
            ),
            NodeKind::Plane { normal, offset } => (
                RKind::Plane(*normal, *offset),
                leaf_bounds(&node.kind),
                true,
            ),
            NodeKind::Triangle { vertices } => {
                (RKind::Triangle(*vertices), leaf_bounds(&node.kind), false)
            }
            NodeKind::Mesh { path } => {
                let mesh = match self.meshes.get(path) {
                    Some(m) => m.clone(),
                    None => {
                        let loaded = load_mesh(path).map_err(|e| ReferenceError::Mesh {
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
                (RKind::Mesh(mesh), Some(b), closed)
            }
            NodeKind::Union(children) => {
                let c = self.children(children)?;
                let b = combined_bounds(&node.kind, &c);
                let solid = c.iter().all(|c| c.solid);
                (RKind::Union(c), b, solid)
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
                    RKind::Intersection(c)
                } else {
                    RKind::Subtraction(c)
                };
                (kind, b, true)
            }
            NodeKind::SmoothUnion { .. } => {
                let field =
                    Field::compile_node(node, node.transform.inverse(), &FieldOptions::default())
                        .map_err(|e| {
                        unsupported(&format!("its distance field could not be built: {e}"))
                    })?;
                let bounds = field.bounds();
                let size = bounds.map_or(1.0, |(lo, hi)| (hi - lo).length().max(1e-300));
                let smooth = Smooth {
                    field,
                    bounds,
                    eps: self.options.smooth_union_tolerance * size,
                    h: 1e-6 * size,
                    max_steps: self.options.smooth_union_max_steps,
                };
                (RKind::Smooth(Box::new(smooth)), bounds, true)
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
                    RKind::Repeat(Box::new(rep)),
                    bounded.then_some((lo, hi)),
                    solid,
                )
            }
        };
        Ok(RNode {
            to_local,
            normal_to_parent: to_local.matrix3.transpose(),
            material: node.material,
            bounds: local_bounds.map(|b| transform_bounds(&to_frame, b)),
            solid,
            kind,
        })
    }

    fn children(&mut self, children: &[Node]) -> Result<Vec<RNode>, ReferenceError> {
        children
            .iter()
            .map(|c| self.compile(c, DAffine3::IDENTITY))
            .collect()
    }
}

/// Parameter range of the ray inside a box (with `t` limits), `None` when it misses.
pub(crate) fn ray_box(
    o: DVec3,
    d: DVec3,
    (lo, hi): (DVec3, DVec3),
    t0: f64,
    t1: f64,
) -> Option<(f64, f64)> {
    let (mut a, mut b) = (t0, t1);
    for k in 0..3 {
        if d[k] == 0.0 {
            if o[k] < lo[k] || o[k] > hi[k] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d[k];
        let (n, f) = ((lo[k] - o[k]) * inv, (hi[k] - o[k]) * inv);
        a = a.max(n.min(f));
        b = b.min(n.max(f));
    }
    // A relative tolerance keeps surfaces lying in a bounds face.
    (a <= b + 1e-9 * (1.0 + b.abs())).then_some((a, b))
}

fn map(b: Boundary, m: &DMat3, material: Option<MaterialId>) -> Boundary {
    Boundary {
        t: b.t,
        normal: if b.t.is_finite() {
            *m * b.normal
        } else {
            b.normal
        },
        material: material.unwrap_or(b.material),
    }
}

fn map_span(s: Span, m: &DMat3, material: Option<MaterialId>) -> Span {
    Span {
        enter: map(s.enter, m, material),
        exit: map(s.exit, m, material),
    }
}

/// Union of any number of spans (sorted merge).
fn union_many(mut spans: Vec<Span>) -> Vec<Span> {
    spans.sort_by(|a, b| a.enter.t.total_cmp(&b.enter.t));
    let mut out: Vec<Span> = Vec::with_capacity(spans.len());
    for s in spans {
        match out.last_mut() {
            Some(last) if s.enter.t <= last.exit.t => {
                if s.exit.t > last.exit.t {
                    last.exit = s.exit;
                }
            }
            _ => out.push(s),
        }
    }
    out
}

impl RNode {
    fn leaf_material(&self) -> Option<MaterialId> {
        match self.kind {
            RKind::Union(_)
            | RKind::Intersection(_)
            | RKind::Subtraction(_)
            | RKind::Smooth(_)
            | RKind::Repeat(_) => None,
            _ => Some(self.material),
        }
    }

    /// The first surface in `[t_min, t_max]` along `o + t d` (parent frame), if any.
    pub fn closest(
        &self,
        o: DVec3,
        d: DVec3,
        t_min: f64,
        t_max: f64,
        work: &mut Work,
    ) -> Option<Boundary> {
        if let Some(b) = self.bounds {
            ray_box(o, d, b, t_min, t_max)?;
        }
        let ol = self.to_local.transform_point3(o);
        let dl = self.to_local.transform_vector3(d);
        let local = match &self.kind {
            RKind::Triangle(v) => {
                work.tests += 1;
                primitives::triangle(ol, dl, v)
                    .filter(|h| h.0 >= t_min && h.0 <= t_max)
                    .map(|(t, _, _, n)| Boundary {
                        t,
                        normal: n,
                        material: self.material,
                    })
            }
            RKind::Mesh(m) => {
                let (hit, n, k) = m.closest(ol, dl, t_min, t_max);
                work.nodes += n;
                work.tests += k;
                hit.map(|h| Boundary {
                    t: h.t,
                    normal: h.normal,
                    material: self.material,
                })
            }
            // A union of solids is one solid (a ray starting inside sees its boundary, not
            // the inner faces): the spans arm below. A union holding a surface (triangle,
            // open mesh) has no inside: the first surface of any child.
            RKind::Union(children) if !self.solid => {
                let mut best: Option<Boundary> = None;
                for c in children {
                    let hi = best.map_or(t_max, |b| b.t);
                    if let Some(h) = c.closest(ol, dl, t_min, hi, work)
                        && best.is_none_or(|b| h.t < b.t)
                    {
                        best = Some(h);
                    }
                }
                best
            }
            RKind::Repeat(r) => r.closest(ol, dl, t_min, t_max, work),
            _ => {
                let spans = self.local_spans(ol, dl, t_min, t_max, work);
                first_boundary(&spans, t_min, t_max)
            }
        };
        local.map(|b| map(b, &self.normal_to_parent, self.leaf_material()))
    }

    /// The spans of this solid along `o + t d` (parent frame), complete over `[t_min, t_max]`
    /// and correct about whether `t_min` is inside; boundaries outside may be omitted.
    pub fn spans(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64, work: &mut Work) -> Vec<Span> {
        if let Some(b) = self.bounds
            && ray_box(o, d, b, f64::NEG_INFINITY, f64::INFINITY).is_none()
        {
            return Vec::new();
        }
        let ol = self.to_local.transform_point3(o);
        let dl = self.to_local.transform_vector3(d);
        let m = self.leaf_material();
        self.local_spans(ol, dl, t_min, t_max, work)
            .into_iter()
            .map(|s| map_span(s, &self.normal_to_parent, m))
            .collect()
    }

    fn local_spans(
        &self,
        o: DVec3,
        d: DVec3,
        t_min: f64,
        t_max: f64,
        work: &mut Work,
    ) -> Vec<Span> {
        work.tests += 1;
        let one = |s: Option<Span>| s.into_iter().collect::<Vec<_>>();
        match &self.kind {
            RKind::Sphere(r) => one(primitives::sphere(o, d, *r)),
            RKind::Ellipsoid(r) => one(primitives::ellipsoid(o, d, *r)),
            RKind::Box(h) => one(primitives::aabox(o, d, *h)),
            RKind::Cylinder(r, hh) => one(primitives::cylinder(o, d, *r, *hh)),
            RKind::Torus(a, b) => primitives::torus(o, d, *a, *b),
            RKind::Plane(n, off) => one(primitives::half_space(o, d, *n, *off)),
            RKind::Triangle(_) => Vec::new(),
            RKind::Mesh(mesh) => {
                let (hits, n, k) = mesh.all_hits(o, d, f64::NEG_INFINITY, f64::INFINITY);
                work.nodes += n;
                work.tests += k;
                // Parity with entering/leaving from the geometric normal; hits on shared
                // edges (same t, same direction) count once.
                let mut spans = Vec::new();
                let mut open: Option<Boundary> = None;
                let mut last: Option<(f64, bool)> = None;
                for h in hits {
                    let entering = h.geometric.dot(d) < 0.0;
                    if last.is_some_and(|(t, e)| {
                        e == entering && (h.t - t).abs() <= 1e-12 * (1.0 + t.abs())
                    }) {
                        continue;
                    }
                    last = Some((h.t, entering));
                    let b = Boundary {
                        t: h.t,
                        normal: h.normal,
                        material: self.material,
                    };
                    match (entering, open) {
                        (true, None) => open = Some(b),
                        (false, Some(e)) => {
                            spans.push(Span { enter: e, exit: b });
                            open = None;
                        }
                        (false, None) => spans.push(Span {
                            enter: Boundary::infinite(f64::NEG_INFINITY),
                            exit: b,
                        }),
                        (true, Some(_)) => {}
                    }
                }
                if let Some(e) = open {
                    spans.push(Span {
                        enter: e,
                        exit: Boundary::infinite(f64::INFINITY),
                    });
                }
                spans
            }
            RKind::Union(c) => union_many(
                c.iter()
                    .flat_map(|c| c.spans(o, d, t_min, t_max, work))
                    .collect(),
            ),
            RKind::Intersection(c) => combine_all(
                c.iter()
                    .map(|c| c.spans(o, d, t_min, t_max, work))
                    .collect(),
                Op::Intersection,
            ),
            RKind::Subtraction(c) => combine_all(
                c.iter()
                    .map(|c| c.spans(o, d, t_min, t_max, work))
                    .collect(),
                Op::Subtraction,
            ),
            RKind::Smooth(s) => s.spans(o, d, t_min, t_max, work),
            RKind::Repeat(r) => r.spans(o, d, t_min, t_max, work),
        }
    }
}

impl Smooth {
    fn boundary(&self, o: DVec3, d: DVec3, t: f64) -> Boundary {
        let p = o + t * d;
        let h = self.h;
        let g = |q: DVec3| self.field.distance_f64(q);
        let normal = DVec3::new(
            g(p + DVec3::X * h) - g(p - DVec3::X * h),
            g(p + DVec3::Y * h) - g(p - DVec3::Y * h),
            g(p + DVec3::Z * h) - g(p - DVec3::Z * h),
        );
        Boundary {
            t,
            normal,
            material: self.field.distance_material_f64(p).1,
        }
    }

    /// Sign changes of the field along the ray by sphere tracing in f64 (steps never pass
    /// the zero set) and bisection of each bracketed change to the last bit.
    fn spans(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64, work: &mut Work) -> Vec<Span> {
        let (mut t, t_end) = match self.bounds {
            Some(b) => match ray_box(o, d, b, t_min, t_max) {
                Some(r) => r,
                None => return Vec::new(),
            },
            None => (t_min, t_max),
        };
        let len = d.length();
        let f = |t: f64| self.field.distance_f64(o + t * d);
        let mut g = f(t);
        let mut inside = g < 0.0;
        let mut open = inside.then(|| Boundary::infinite(f64::NEG_INFINITY));
        let mut spans = Vec::new();
        let mut steps = 0u32;
        while t < t_end {
            steps += 1;
            if steps > self.max_steps || work.steps.saturating_add(steps) > MAX_WORK_PER_QUERY {
                work.exhausted = true;
                break;
            }
            let step = (g.abs() / len).max(self.eps / len);
            let t_next = (t + step).min(t_end);
            let g_next = f(t_next);
            if (g_next < 0.0) != inside {
                // Bisect [t, t_next] on the sign.
                let (mut a, mut b) = (t, t_next);
                for _ in 0..80 {
                    let m = 0.5 * (a + b);
                    if m <= a || m >= b {
                        break;
                    }
                    if (f(m) < 0.0) == inside {
                        a = m;
                    } else {
                        b = m;
                    }
                    steps += 1;
                }
                let root = 0.5 * (a + b);
                let bd = self.boundary(o, d, root);
                if inside {
                    spans.push(Span {
                        enter: open.take().unwrap_or(Boundary::infinite(f64::NEG_INFINITY)),
                        exit: bd,
                    });
                } else {
                    open = Some(bd);
                }
                inside = !inside;
            }
            t = t_next;
            g = g_next;
        }
        if let Some(e) = open {
            spans.push(Span {
                enter: e,
                exit: Boundary::infinite(f64::INFINITY),
            });
        }
        work.steps = work.steps.saturating_add(steps);
        spans
    }
}

impl Repeat {
    fn offset(&self, j: [i64; 3]) -> DVec3 {
        let mut off = DVec3::ZERO;
        for a in 0..3 {
            if let Some((_, _, c)) = self.range[a] {
                off[a] = (j[a] as f64 + c) * self.period[a];
            }
        }
        off
    }

    fn in_range(&self, j: [i64; 3]) -> bool {
        (0..3).all(|a| match self.range[a] {
            Some((lo, hi, _)) => j[a] >= lo && j[a] <= hi,
            None => j[a] == 0,
        })
    }

    /// Walks the cells the ray crosses within `[t0, t1]` (Amanatides-Woo over the repeated
    /// axes) and calls `visit(copy)` for every copy that can reach into each cell, once per
    /// copy. `visit` returns false to stop; the walk also stops after `max_cells` cells
    /// (flagged as exhausted) or when `stop_after(t_cell_exit)` says so.
    #[allow(clippy::too_many_arguments)] // A walk's ray, range, counters and two callbacks.
    fn walk(
        &self,
        o: DVec3,
        d: DVec3,
        t0: f64,
        t1: f64,
        work: &mut Work,
        visit: &mut dyn FnMut([i64; 3], &mut Work) -> bool,
        stop_after: &dyn Fn(f64) -> bool,
    ) {
        let p0 = o + t0 * d;
        let mut cell = [0i64; 3];
        let mut t_next = [f64::INFINITY; 3];
        let mut t_delta = [f64::INFINITY; 3];
        let mut step = [0i64; 3];
        for a in 0..3 {
            let Some((_, _, c)) = self.range[a] else {
                continue;
            };
            let p = self.period[a];
            let x = p0[a] / p - c;
            cell[a] = x.round() as i64;
            if d[a] != 0.0 {
                step[a] = if d[a] > 0.0 { 1 } else { -1 };
                let boundary = (cell[a] as f64 + c + 0.5 * step[a] as f64) * p;
                t_next[a] = t0 + ((boundary - p0[a]) / d[a]).max(0.0);
                t_delta[a] = p / d[a].abs();
            }
        }
        let mut seen: HashSet<[i64; 3]> = HashSet::new();
        let mut cells = 0u32;
        loop {
            cells += 1;
            if cells > self.max_cells || work.steps.saturating_add(cells) > MAX_WORK_PER_QUERY {
                work.exhausted = true;
                break;
            }
            // Copies that reach into this cell, clipped to the copies that exist.
            let span = |a: usize| {
                let (lo, hi) = (cell[a] + self.reach[a].0, cell[a] + self.reach[a].1);
                match self.range[a] {
                    Some((j0, j1, _)) => (lo.max(j0), hi.min(j1)),
                    None => (0, 0),
                }
            };
            let (sx, sy, sz) = (span(0), span(1), span(2));
            for jx in sx.0..=sx.1 {
                for jy in sy.0..=sy.1 {
                    for jz in sz.0..=sz.1 {
                        let j = [jx, jy, jz];
                        if self.in_range(j) && seen.insert(j) && !visit(j, work) {
                            work.steps = work.steps.saturating_add(cells);
                            return;
                        }
                    }
                }
            }
            let (axis, t_exit) = (0..3)
                .map(|a| (a, t_next[a]))
                .min_by(|x, y| x.1.total_cmp(&y.1))
                .unwrap_or((0, f64::INFINITY));
            if t_exit > t1 || stop_after(t_exit) || !t_exit.is_finite() {
                break;
            }
            cell[axis] += step[axis];
            t_next[axis] += t_delta[axis];
        }
        work.steps = work.steps.saturating_add(cells);
    }

    /// Where the walk starts and ends: the query range clipped to the copies' extent.
    fn range_t(&self, o: DVec3, d: DVec3, t0: f64, t1: f64) -> Option<(f64, f64)> {
        let (mut lo, mut hi) = (DVec3::splat(f64::NEG_INFINITY), DVec3::splat(f64::INFINITY));
        for a in 0..3 {
            match self.range[a] {
                None => {
                    lo[a] = self.child_bounds.0[a];
                    hi[a] = self.child_bounds.1[a];
                }
                Some((j0, j1, c)) if j0 > i64::MIN / 8 => {
                    let p = self.period[a];
                    lo[a] = (self.child_bounds.0[a] + (j0 as f64 + c) * p)
                        .min((j0 as f64 + c - 0.5) * p);
                    hi[a] = (self.child_bounds.1[a] + (j1 as f64 + c) * p)
                        .max((j1 as f64 + c + 0.5) * p);
                }
                Some(_) => {}
            }
        }
        ray_box(o, d, (lo, hi), t0, t1)
    }

    fn closest(
        &self,
        o: DVec3,
        d: DVec3,
        t_min: f64,
        t_max: f64,
        work: &mut Work,
    ) -> Option<Boundary> {
        // The repetition is the union of whole copies. Copies that fit their cells are
        // disjoint, so the first surface of any copy is the union's; overlapping solid
        // copies seen from inside one need the union's spans (inner faces are not seen).
        if self.copies_overlap && self.child.solid {
            let starts_inside = self
                .spans(o, d, t_min, t_min, work)
                .iter()
                .any(|s| s.enter.t <= t_min && t_min < s.exit.t);
            if starts_inside {
                return first_boundary(&self.spans(o, d, t_min, t_max, work), t_min, t_max);
            }
        }
        let (a, b) = self.range_t(o, d, t_min, t_max)?;
        let best = std::cell::Cell::new(None::<Boundary>);
        self.walk(
            o,
            d,
            a,
            b,
            work,
            &mut |j, work| {
                let hi = best.get().map_or(t_max, |h| h.t);
                if let Some(h) = self.child.closest(o - self.offset(j), d, t_min, hi, work)
                    && best.get().is_none_or(|b| h.t < b.t)
                {
                    best.set(Some(h));
                }
                true
            },
            &|t_exit| best.get().is_some_and(|h| h.t <= t_exit),
        );
        best.get()
    }

    fn spans(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64, work: &mut Work) -> Vec<Span> {
        // Start early enough to meet every copy that contains the point at t_min.
        let size = (self.child_bounds.1 - self.child_bounds.0).length() + self.period.length();
        let back = size / d.length();
        let Some((a, b)) = self.range_t(o, d, t_min - back, t_max) else {
            return Vec::new();
        };
        let mut all = Vec::new();
        self.walk(
            o,
            d,
            a,
            b,
            work,
            &mut |j, work| {
                all.extend(self.child.spans(o - self.offset(j), d, t_min, t_max, work));
                true
            },
            &|_| false,
        );
        union_many(all)
    }
}
