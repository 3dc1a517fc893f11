//! Receding tests: whether a ray can still meet a surface of a leaf or a subtree, the
//! question behind ending rays that move away from everything ([`crate::Field::recedes`]).
//!
//! Two facts answer it without marching:
//! - the distance to a convex set is a convex function along a line, so where the value of
//!   a convex leaf (sphere, plane, box, capped cylinder; the ellipsoid's scaled-sphere
//!   bound is convex too) is positive and grows along the ray, it never shrinks again and
//!   never reaches 0;
//! - a ray that misses a node's bounding box from its current point on never meets
//!   anything inside it.
//!
//! The tape ([`crate::tape::Tape::recedes`]) asks them of each leaf of its union. (The
//! same tests compose through CSG, an intersection being left behind when any member is; a
//! version over the interpreter's programs answered on `csg` but cost more than it saved
//! there, 1.1x slower, and was dropped.)

use crate::lane::V3;
use crate::program::Op;

/// Whether the ray `q + t dq`, `t >= 0` (leaf frame), can no longer meet the surface of the
/// convex leaf `op`: the point is outside (value > 0) and the value grows along `dq`, by
/// more than rounding can fake (cosine of the angle to the surface above 1e-4). False for
/// leaves that are not convex (torus, triangle kept apart: a flat triangle's distance is
/// convex but its value is never negative, so "outside" says nothing), mesh grids and
/// operators.
pub(crate) fn convex_leaf_recedes(op: &Op<f32>, q: V3<f32>, dq: V3<f32>) -> bool {
    // The outward gradient direction where the point is outside, else `None`.
    let outward: Option<V3<f32>> = match op {
        Op::Sphere { r } => (q.len2() > r * r).then_some(q),
        Op::SphereAt { c, r, .. } => {
            let e = q - V3::splat3(*c);
            (e.len2() > r * r).then_some(e)
        }
        Op::Plane { n, offset } => {
            let n = V3::splat3(*n);
            (q.dot(n) > *offset).then_some(n)
        }
        Op::Box { b } => {
            let e = V3::new(
                q.x - q.x.clamp(-b[0], b[0]),
                q.y - q.y.clamp(-b[1], b[1]),
                q.z - q.z.clamp(-b[2], b[2]),
            );
            (e.len2() > 0.0).then_some(e)
        }
        Op::Ellipsoid { inv_r, .. } => {
            let w = V3::splat3(*inv_r);
            let s = q.mul_elem(w);
            (s.len2() > 1.0).then(|| s.mul_elem(w))
        }
        Op::Cylinder { r, h } => {
            let rad = (q.x * q.x + q.z * q.z).sqrt();
            let k = if rad > *r { 1.0 - *r / rad } else { 0.0 };
            let e = V3::new(q.x * k, q.y - q.y.clamp(-*h, *h), q.z * k);
            (e.len2() > 0.0).then_some(e)
        }
        Op::Torus { .. }
        | Op::Triangle(_)
        | Op::Mesh { .. }
        | Op::Union
        | Op::Intersection
        | Op::Subtraction
        | Op::SmoothUnion { .. }
        | Op::Repeat { .. } => None,
    };
    outward.is_some_and(|g| {
        let along = g.dot(dq);
        along > 0.0 && along * along > 1e-8 * g.len2() * dq.len2()
    })
}

/// The reciprocals of `d`'s components, for [`misses_box`].
pub(crate) fn recip(d: V3<f32>) -> V3<f32> {
    V3::new(d.x.recip(), d.y.recip(), d.z.recip())
}

/// Whether the ray `q + t dq`, `t >= 0`, misses the box `[lo, hi]` (slab test, `inv` from
/// [`recip`]; a zero direction component outside its slab misses, inside it never bounds
/// `t`; non-finite values never prove a miss).
pub(crate) fn misses_box(
    q: V3<f32>,
    dq: V3<f32>,
    inv: V3<f32>,
    (lo, hi): ([f32; 3], [f32; 3]),
) -> bool {
    let (mut enter, mut exit) = (0.0f32, f32::INFINITY);
    for (o, v, w, lo, hi) in [
        (q.x, dq.x, inv.x, lo[0], hi[0]),
        (q.y, dq.y, inv.y, lo[1], hi[1]),
        (q.z, dq.z, inv.z, lo[2], hi[2]),
    ] {
        if v == 0.0 {
            if o < lo || o > hi {
                return true;
            }
            continue;
        }
        let (a, c) = ((lo - o) * w, (hi - o) * w);
        enter = enter.max(a.min(c));
        exit = exit.min(a.max(c));
    }
    exit < enter
}
