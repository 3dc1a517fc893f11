//! The reference's compiled object tree ([`CompiledNode`]) and its two queries: the closest
//! surface along a ray, and the spans of a solid along a ray (for CSG).

use std::sync::Arc;

use glam::{DAffine3, DMat3, DVec3};
use marchmesh_scene::{MaterialId, Shape};

use crate::meshbvh::MeshData;
use crate::primitives;
use crate::repeat::Repeat;
use crate::smooth::Smooth;
use crate::spans::{Boundary, Op, Span, combine_all, first_boundary};

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

#[derive(Debug)]
pub(crate) enum CompiledKind {
    /// A shape intersected in closed form ([`primitives::spans`]; never a mesh file).
    Shape(Shape),
    Mesh(Arc<MeshData>),
    Union(Vec<CompiledNode>),
    Intersection(Vec<CompiledNode>),
    Subtraction(Vec<CompiledNode>),
    Smooth(Box<Smooth>),
    Repeat(Box<Repeat>),
}

/// A node in its parent's frame.
#[derive(Debug)]
pub(crate) struct CompiledNode {
    pub(crate) to_local: DAffine3,
    pub(crate) normal_to_parent: DMat3,
    pub(crate) material: MaterialId,
    /// Bounds in the parent frame, `None` when unbounded.
    pub bounds: Option<(DVec3, DVec3)>,
    /// Whether the node bounds a solid (has an inside), needed under intersection and
    /// subtraction.
    pub(crate) solid: bool,
    pub(crate) kind: CompiledKind,
}

/// Most iterative work (repetition cells walked plus smooth-union field evaluations) one
/// query may spend before it gives up with `MaxSteps`: bounds the time of pathological but
/// valid scenes (an infinite repetition of a squashed smooth union) to about a second per
/// ray instead of hours.
pub(crate) const MAX_WORK_PER_QUERY: u32 = 4_000_000;

/// Most copies of a repeated child that may overlap one cell (see [`Repeat`]).
pub(crate) const MAX_COPIES_PER_CELL: u32 = 4096;

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

pub(crate) fn map(b: Boundary, m: &DMat3, material: Option<MaterialId>) -> Boundary {
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

pub(crate) fn map_span(s: Span, m: &DMat3, material: Option<MaterialId>) -> Span {
    Span {
        enter: map(s.enter, m, material),
        exit: map(s.exit, m, material),
    }
}

/// Union of any number of spans (sorted merge).
pub(crate) fn union_many(mut spans: Vec<Span>) -> Vec<Span> {
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

impl CompiledNode {
    pub(crate) fn leaf_material(&self) -> Option<MaterialId> {
        match self.kind {
            CompiledKind::Union(_)
            | CompiledKind::Intersection(_)
            | CompiledKind::Subtraction(_)
            | CompiledKind::Smooth(_)
            | CompiledKind::Repeat(_) => None,
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
            CompiledKind::Shape(Shape::Triangle { vertices: v }) => {
                work.tests += 1;
                primitives::triangle(ol, dl, v)
                    .filter(|h| h.0 >= t_min && h.0 <= t_max)
                    .map(|(t, _, _, n)| Boundary {
                        t,
                        normal: n,
                        material: self.material,
                    })
            }
            CompiledKind::Mesh(m) => {
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
            CompiledKind::Union(children) if !self.solid => {
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
            CompiledKind::Repeat(r) => r.closest(ol, dl, t_min, t_max, work),
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

    pub(crate) fn local_spans(
        &self,
        o: DVec3,
        d: DVec3,
        t_min: f64,
        t_max: f64,
        work: &mut Work,
    ) -> Vec<Span> {
        work.tests += 1;
        match &self.kind {
            CompiledKind::Shape(shape) => primitives::spans(shape, o, d),
            CompiledKind::Mesh(mesh) => {
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
            CompiledKind::Union(c) => union_many(
                c.iter()
                    .flat_map(|c| c.spans(o, d, t_min, t_max, work))
                    .collect(),
            ),
            CompiledKind::Intersection(c) => combine_all(
                c.iter()
                    .map(|c| c.spans(o, d, t_min, t_max, work))
                    .collect(),
                Op::Intersection,
            ),
            CompiledKind::Subtraction(c) => combine_all(
                c.iter()
                    .map(|c| c.spans(o, d, t_min, t_max, work))
                    .collect(),
                Op::Subtraction,
            ),
            CompiledKind::Smooth(s) => s.spans(o, d, t_min, t_max, work),
            CompiledKind::Repeat(r) => r.spans(o, d, t_min, t_max, work),
        }
    }
}
