//! Bounds every backend agrees on: the f64 box type, each shape's bounds in its own frame and
//! how composites combine their children's boxes, plus the singular values that turn a
//! transform's stretch into distance bounds.
//!
//! Shapes carry their own bounds (as in pbrt-v4's `Shape::Bounds`): [`NodeKind::local_bounds`]
//! answers for every variant, so a new shape fails to compile here until its box is written,
//! and the field compiler, the reference and the mesh backend read the same numbers.

use std::path::Path;

use glam::{DAffine3, DMat3, DVec3};

use crate::resolved::{Node, NodeKind, Shape};

/// An axis-aligned box in f64 that may be infinite along some axes (`lo = -inf`, `hi = +inf`
/// on an axis nothing bounds, e.g. a plane or an infinite repetition).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub lo: DVec3,
    /// Largest corner.
    pub hi: DVec3,
}

impl Aabb {
    /// All of space.
    pub const INFINITE: Aabb = Aabb {
        lo: DVec3::splat(f64::NEG_INFINITY),
        hi: DVec3::splat(f64::INFINITY),
    };

    /// The box from `lo` to `hi`.
    pub const fn new(lo: DVec3, hi: DVec3) -> Aabb {
        Aabb { lo, hi }
    }

    /// The box `[-half, half]`.
    pub fn symmetric(half: DVec3) -> Aabb {
        Aabb {
            lo: -half,
            hi: half,
        }
    }

    /// The smallest box holding `points`; `None` for no points.
    pub fn from_points(points: impl IntoIterator<Item = DVec3>) -> Option<Aabb> {
        points.into_iter().fold(None, |acc, p| {
            Some(match acc {
                None => Aabb { lo: p, hi: p },
                Some(b) => Aabb {
                    lo: b.lo.min(p),
                    hi: b.hi.max(p),
                },
            })
        })
    }

    /// Finite along every axis.
    pub fn is_finite(&self) -> bool {
        self.lo.is_finite() && self.hi.is_finite()
    }

    /// Finite along at least one side of one axis (bounds something).
    pub fn any_finite(&self) -> bool {
        (0..3).any(|a| self.lo[a].is_finite() || self.hi[a].is_finite())
    }

    /// `Some((lo, hi))` when finite, `None` otherwise.
    pub fn finite(&self) -> Option<(DVec3, DVec3)> {
        self.is_finite().then_some((self.lo, self.hi))
    }

    /// The smallest box holding both.
    pub fn hull(&self, o: &Aabb) -> Aabb {
        Aabb {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
        }
    }

    /// The common part (may be empty: `lo > hi` on some axis).
    pub fn intersect(&self, o: &Aabb) -> Aabb {
        Aabb {
            lo: self.lo.max(o.lo),
            hi: self.hi.min(o.hi),
        }
    }

    /// Grown by `margin` on every side.
    pub fn grown(&self, margin: f64) -> Aabb {
        Aabb {
            lo: self.lo - DVec3::splat(margin),
            hi: self.hi + DVec3::splat(margin),
        }
    }

    /// The box holding this box mapped by `xf` (its eight corners). An infinite box stays
    /// exact under a pure translation and becomes [`Aabb::INFINITE`] under anything else.
    pub fn transformed(&self, xf: &DAffine3) -> Aabb {
        if self.is_finite() {
            let corners = (0..8).map(|i| {
                xf.transform_point3(DVec3::new(
                    if i & 1 == 0 { self.lo.x } else { self.hi.x },
                    if i & 2 == 0 { self.lo.y } else { self.hi.y },
                    if i & 4 == 0 { self.lo.z } else { self.hi.z },
                ))
            });
            Aabb::from_points(corners).unwrap_or(*self)
        } else if xf.matrix3 == DMat3::IDENTITY {
            Aabb {
                lo: self.lo + xf.translation,
                hi: self.hi + xf.translation,
            }
        } else {
            Aabb::INFINITE
        }
    }

    /// Distance from `p` to the box; 0 inside.
    pub fn distance_to(&self, p: DVec3) -> f64 {
        (self.lo - p).max(p - self.hi).max(DVec3::ZERO).length()
    }
}

/// What bounds a node in its own frame, per [`NodeKind`] variant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LocalBounds<'a> {
    /// A leaf shape with a finite box.
    Finite(Aabb),
    /// A shape that bounds nothing (a plane).
    Unbounded,
    /// A mesh file: its box is known once the file is loaded.
    MeshFile(&'a Path),
    /// A composite: its box follows from its children's ([`combine`]).
    Composite,
}

impl Shape {
    /// The shape's bounds in its own frame. Exhaustive over the shapes: a new shape must
    /// say its box here.
    pub fn local_bounds(&self) -> LocalBounds<'_> {
        match self {
            Shape::Sphere { radius } => LocalBounds::Finite(Aabb::symmetric(DVec3::splat(*radius))),
            Shape::Ellipsoid { radii } => LocalBounds::Finite(Aabb::symmetric(*radii)),
            Shape::Box { half_extents } => LocalBounds::Finite(Aabb::symmetric(*half_extents)),
            Shape::Cylinder {
                radius,
                half_height,
            } => LocalBounds::Finite(Aabb::symmetric(DVec3::new(*radius, *half_height, *radius))),
            Shape::Torus {
                major_radius,
                minor_radius,
            } => {
                let outer = major_radius + minor_radius;
                LocalBounds::Finite(Aabb::symmetric(DVec3::new(outer, *minor_radius, outer)))
            }
            Shape::Triangle { vertices } => LocalBounds::Finite(Aabb {
                lo: vertices[0].min(vertices[1]).min(vertices[2]),
                hi: vertices[0].max(vertices[1]).max(vertices[2]),
            }),
            Shape::RoundedBox { half_extents, .. } => {
                LocalBounds::Finite(Aabb::symmetric(*half_extents))
            }
            Shape::Capsule {
                radius,
                half_height,
            } => LocalBounds::Finite(Aabb::symmetric(DVec3::new(
                *radius,
                half_height + radius,
                *radius,
            ))),
            Shape::CappedCone {
                half_height,
                bottom_radius,
                top_radius,
            } => {
                let r = bottom_radius.max(*top_radius);
                LocalBounds::Finite(Aabb::symmetric(DVec3::new(r, *half_height, r)))
            }
            Shape::Plane { .. } => LocalBounds::Unbounded,
            Shape::Mesh { path } => LocalBounds::MeshFile(path),
        }
    }
}

impl NodeKind {
    /// The node's bounds in its own frame (before its transform), as far as the node alone
    /// decides them: a leaf's [`Shape::local_bounds`], or [`LocalBounds::Composite`].
    pub fn local_bounds(&self) -> LocalBounds<'_> {
        match self {
            NodeKind::Leaf(shape) => shape.local_bounds(),
            NodeKind::Union(_)
            | NodeKind::Smooth { .. }
            | NodeKind::Intersection(_)
            | NodeKind::Subtraction(_)
            | NodeKind::Repeat { .. } => LocalBounds::Composite,
        }
    }
}

/// How far below its children's minimum a left-to-right fold of `children` polynomial smooth
/// minima with blend radius `blend_radius` (`k`) can lie: `D(children)`, never above `k`
/// whatever the count, and exact (reached when all children are equal).
///
/// The kernel (Quilez 2013) is `smin(x, a) = min(x, a) - max(k - |x - a|, 0)^2 / (4k)`; it
/// is non-decreasing in both arguments. Folding `f_1 = a_1`, `f_{i+1} = smin(f_i, a_{i+1})`
/// with `m_i = min(a_1..a_i)` and the deficit `D_i = m_i - f_i >= 0`, and writing
/// `g(D) = D + max(k - D, 0)^2 / (4k)` (increasing, `g(D) < k` for `D < k`, fixed point `k`):
/// - `a >= m_i`: `|f_i - a| >= D_i`, so `D_{i+1} = D_i + max(k - |f_i - a|, 0)^2 / (4k) <= g(D_i)`;
/// - `f_i <= a < m_i`: with `t = a - f_i` in `[0, D_i)`, `D_{i+1} = g(t) <= g(D_i)`;
/// - `a < f_i`: `D_{i+1} = max(k - (f_i - a), 0)^2 / (4k) <= k / 4 = g(0)`.
///
/// So `D_n <= g^(n-1)(0)`, with equality for equal children: `0, k/4, 25k/64, ...`, rising to
/// `k` as `1 - D_n / k ~ 4 / n`. The old rule of `k/4` per fold (unbounded in `n`) is the first
/// step only. Returns `k` itself beyond 65,536 children (the limit, always safe).
pub fn smooth_fold_deficit(blend_radius: f64, children: usize) -> f64 {
    let k = blend_radius;
    if children > 1 << 16 {
        return k;
    }
    let mut d = 0.0f64;
    for _ in 1..children {
        let h = (k - d).max(0.0);
        d += h * h / (4.0 * k);
    }
    // One part in 1e12 for the rounding of the iteration; never above the limit k.
    (d * (1.0 + 1e-12)).min(k)
}

/// How far below its children's minimum `m` a blend ([`crate::SmoothOp::Blend`]) of
/// `children` values with blend radius `blend_radius` (`k`) can lie: `k (1 - 1/sqrt(n))`,
/// below `k` whatever the count, and exact when all `n` children are equal.
///
/// The blend is the `f` with `sum_i max(0, 1 - (a_i - f) / k)^2 = 1`. The nearest child's
/// term is 1 at `f = m` and the sum falls as `f` falls, so `f <= m`; a child `k` or more
/// above `f` adds nothing. Each of the at most `n` terms is at most `((m - f + k) / k)^2`,
/// so `n ((m - f + k) / k)^2 >= 1`, i.e. `m - f <= k (1 - 1/sqrt(n))`. Beyond `2^32`
/// children the bound returned is `k` (always safe).
pub fn blend_deficit(blend_radius: f64, children: usize) -> f64 {
    let k = blend_radius;
    if children == 0 || children as u64 > 1 << 32 {
        return k;
    }
    let d = k * (1.0 - 1.0 / (children as f64).sqrt());
    // One part in 1e12 for rounding; never above the limit k.
    (d + 1e-12 * k).min(k)
}

/// A composite's box in its own frame from its children's boxes in that frame (each child's
/// own transform applied; [`Aabb::INFINITE`] for an unbounded child). Leaves give `None`.
///
/// Union: the hull. Smooth union: the hull grown by [`smooth_fold_deficit`] (blend:
/// [`blend_deficit`]; at most the blend radius, whatever the child count): every child is at least its box's distance away from
/// a point outside the hull grown by that much, so the fold is positive there (children
/// whose values are bounds of this kind, as every composite's box makes them). Intersection
/// (hard or smooth): the common part. Subtraction (hard or smooth): the first child. Repetition: the child's box spread over the
/// copies, infinite along an axis repeated without end.
pub fn combine(kind: &NodeKind, children: &[Aabb]) -> Option<Aabb> {
    let hull = || {
        let first = *children.first()?;
        Some(children.iter().skip(1).fold(first, |a, b| a.hull(b)))
    };
    match kind {
        NodeKind::Union(_) => hull(),
        NodeKind::Smooth {
            op, blend_radius, ..
        } => match op {
            crate::SmoothOp::Union => {
                let deficit = smooth_fold_deficit(*blend_radius, children.len());
                hull().map(|h| h.grown(deficit))
            }
            crate::SmoothOp::Blend => {
                let deficit = blend_deficit(*blend_radius, children.len());
                hull().map(|h| h.grown(deficit))
            }
            // A smooth maximum never lies below either argument, so the fold is at least
            // every child (intersection) or at least the first child (subtraction): no growth.
            crate::SmoothOp::Intersection => children.iter().fold(None, |acc: Option<Aabb>, b| {
                Some(acc.map_or(*b, |a| a.intersect(b)))
            }),
            crate::SmoothOp::Subtraction => children.first().copied(),
        },
        NodeKind::Intersection(_) => children.iter().fold(None, |acc: Option<Aabb>, b| {
            Some(acc.map_or(*b, |a| a.intersect(b)))
        }),
        NodeKind::Subtraction(_) => children.first().copied(),
        NodeKind::Repeat { period, count, .. } => {
            let mut b = *children.first()?;
            for axis in 0..3 {
                if period[axis] > 0.0 {
                    match count[axis] {
                        Some(n) => {
                            let half_span = f64::from(n.saturating_sub(1)) * 0.5 * period[axis];
                            b.lo[axis] -= half_span;
                            b.hi[axis] += half_span;
                        }
                        None => {
                            b.lo[axis] = f64::NEG_INFINITY;
                            b.hi[axis] = f64::INFINITY;
                        }
                    }
                }
            }
            Some(b)
        }
        NodeKind::Leaf(_) => None,
    }
}

impl Node {
    /// The node's box in its parent's frame (its transform applied), recursively;
    /// `mesh_bounds` gives a mesh file's box in its own frame (`None`: unknown, which makes
    /// the result unknown too). [`Aabb::INFINITE`] along axes nothing bounds.
    pub fn bounds_in_parent(&self, mesh_bounds: &dyn Fn(&Path) -> Option<Aabb>) -> Option<Aabb> {
        Some(
            self.bounds_in_own_frame(mesh_bounds)?
                .transformed(&self.transform),
        )
    }

    /// [`Node::bounds_in_parent`] before the node's own transform.
    pub fn bounds_in_own_frame(&self, mesh_bounds: &dyn Fn(&Path) -> Option<Aabb>) -> Option<Aabb> {
        match self.kind.local_bounds() {
            LocalBounds::Finite(b) => Some(b),
            LocalBounds::Unbounded => Some(Aabb::INFINITE),
            LocalBounds::MeshFile(path) => mesh_bounds(path),
            LocalBounds::Composite => {
                let boxes = self
                    .children()
                    .iter()
                    .map(|c| c.bounds_in_parent(mesh_bounds))
                    .collect::<Option<Vec<Aabb>>>()?;
                combine(&self.kind, &boxes)
            }
        }
    }
}

/// The three singular values of `m`, smallest first: square roots of the eigenvalues of
/// `m^T m` by cyclic Jacobi rotations (Golub & Van Loan, Matrix Computations, 8.5). The
/// smallest scales distances into a bound under non-uniform scale; the largest is the
/// transform's greatest stretch.
pub fn singular_values(m: &DMat3) -> [f64; 3] {
    let s = m.transpose() * *m;
    let mut a = [
        [s.x_axis.x, s.y_axis.x, s.z_axis.x],
        [s.x_axis.y, s.y_axis.y, s.z_axis.y],
        [s.x_axis.z, s.y_axis.z, s.z_axis.z],
    ];
    for _ in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-30 * (a[0][0].abs() + a[1][1].abs() + a[2][2].abs()) {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * c;
            // a <- J^T a J with the rotation in the (p, q) plane.
            for row in &mut a {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - sn * akq;
                row[q] = sn * akp + c * akq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * row_p[k] - sn * row_q[k]);
            a[q] = std::array::from_fn(|k| sn * row_p[k] + c * row_q[k]);
        }
    }
    let mut values = [a[0][0], a[1][1], a[2][2]].map(|l| l.max(0.0).sqrt());
    values.sort_by(f64::total_cmp);
    values
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn singular_values_of_a_rotated_scale_are_the_scales() {
        let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0);
        let m = rot * DMat3::from_diagonal(DVec3::new(3.0, 0.5, 2.0)) * rot.transpose();
        let s = singular_values(&m);
        for (got, want) in s.iter().zip([0.5, 2.0, 3.0]) {
            assert!((got - want).abs() < 1e-12, "{s:?}");
        }
        assert_eq!(singular_values(&DMat3::ZERO), [0.0; 3]);
    }

    #[test]
    fn transformed_boxes_hold_every_corner_and_infinite_boxes_stay_honest() {
        let b = Aabb::symmetric(DVec3::new(1.0, 2.0, 3.0));
        let xf = DAffine3::from_rotation_y(0.7) * DAffine3::from_translation(DVec3::X);
        let t = b.transformed(&xf);
        for i in 0..8 {
            let c = DVec3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -2.0 } else { 2.0 },
                if i & 4 == 0 { -3.0 } else { 3.0 },
            );
            let p = xf.transform_point3(c);
            assert!(p.cmpge(t.lo - 1e-12).all() && p.cmple(t.hi + 1e-12).all());
        }
        let slab = Aabb::new(
            DVec3::new(f64::NEG_INFINITY, -1.0, f64::NEG_INFINITY),
            DVec3::new(f64::INFINITY, 1.0, f64::INFINITY),
        );
        let moved = slab.transformed(&DAffine3::from_translation(DVec3::Y));
        assert_eq!((moved.lo.y, moved.hi.y), (0.0, 2.0));
        assert_eq!(slab.transformed(&xf), Aabb::INFINITE);
        assert_eq!(b.distance_to(DVec3::new(4.0, 0.0, 0.0)), 3.0);
    }

    #[test]
    fn the_fold_deficit_starts_at_a_quarter_and_never_reaches_the_blend_radius() {
        let k = 0.026;
        assert_eq!(smooth_fold_deficit(k, 0), 0.0);
        assert_eq!(smooth_fold_deficit(k, 1), 0.0);
        assert!((smooth_fold_deficit(k, 2) - k / 4.0).abs() < 1e-12 * k);
        assert!((smooth_fold_deficit(k, 3) - 25.0 * k / 64.0).abs() < 1e-12 * k);
        let mut last = 0.0;
        for n in [4, 10, 100, 1000, 10_000, 65_536] {
            let d = smooth_fold_deficit(k, n);
            assert!(d > last && d < k, "n = {n}: {d}");
            // 1 - D/k behaves like 4/n: within a factor 2 of it for large n.
            let rest = 1.0 - d / k;
            assert!(
                rest < 8.0 / n as f64 && rest > 2.0 / n as f64,
                "n = {n}: {rest}"
            );
            last = d;
        }
        assert_eq!(smooth_fold_deficit(k, 1 << 20), k);
    }

    fn leaf(kind: NodeKind) -> Node {
        Node {
            transform: DAffine3::IDENTITY,
            material: 0,
            name: None,
            json_path: "test".into(),
            kind,
        }
    }

    #[test]
    fn smooth_unions_grow_by_the_fold_deficit_and_repeats_spread_over_their_copies() {
        let sphere = || leaf(NodeKind::Leaf(Shape::Sphere { radius: 1.0 }));
        let smooth = leaf(NodeKind::Smooth {
            op: crate::SmoothOp::Union,
            children: vec![sphere(), sphere(), sphere()],
            blend_radius: 0.4,
        });
        let three = smooth.bounds_in_own_frame(&|_| None).expect("bounded");
        assert!(
            (three.hi.x - (1.0 + 0.4 * 25.0 / 64.0)).abs() < 1e-9,
            "{three:?}"
        );
        let repeat = leaf(NodeKind::Repeat {
            child: Box::new(sphere()),
            period: DVec3::new(4.0, 0.0, 3.0),
            count: [Some(3), None, None],
        });
        let b = repeat.bounds_in_own_frame(&|_| None).expect("bounded");
        assert_eq!((b.lo.x, b.hi.x), (-5.0, 5.0));
        assert_eq!((b.lo.y, b.hi.y), (-1.0, 1.0));
        assert!(b.lo.z.is_infinite() && b.hi.z.is_infinite());
        let mesh = leaf(NodeKind::Leaf(Shape::Mesh {
            path: "m.obj".into(),
        }));
        assert_eq!(mesh.bounds_in_parent(&|_| None), None, "unknown mesh box");
    }
}
