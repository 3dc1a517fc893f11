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
//! The tape ([`crate::tape::Tape::recedes`]) asks them of each leaf of its union, the
//! convex test inline in its loop: its union is positive where a ray asks, so no leaf's
//! sign needs checking (as a shared function with that check, seed-spheres rendered 1.08x
//! slower). The same tests compose through CSG (an intersection is left behind when any
//! member is); a version over the interpreter's programs answered on `csg` but cost more
//! than it saved there, 1.1x slower, and was dropped.

use crate::lane::V3;

/// The reciprocals of `d`'s components, for [`misses_box`].
#[inline]
pub(crate) fn recip(d: V3<f32>) -> V3<f32> {
    V3::new(d.x.recip(), d.y.recip(), d.z.recip())
}

/// Whether the ray `q + t dq`, `t >= 0`, misses the box `[lo, hi]` (slab test, `inv` from
/// [`recip`]; a zero direction component outside its slab misses, inside it never bounds
/// `t`; non-finite values never prove a miss).
#[inline]
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
