//! Segment tracing: how far a ray may step before the field can change sign, from local
//! directional Lipschitz bounds (Galin, Guérin, Paris, Peytavie 2020, "Segment Tracing Using
//! Local Lipschitz Bounds", Computer Graphics Forum 39(2)).
//!
//! Sphere tracing steps by the field value `f`, the distance a 1-Lipschitz field needs in
//! the worst direction. Along a ray `p(s) = p + s d` the field only changes as fast as its
//! directional derivative: where `|df/ds| <= lambda` on `[0, len]`, `f` keeps its sign on
//! `[0, min(|f| / lambda, len))` (the paper's step `f / lambda`, section 4). A ray passing at
//! angle `theta` over a plane has `lambda = sin(theta)`: one step instead of
//! `~ln(f / eps) / theta`.
//!
//! Each node reports its value (the interpreter's, same formulas and skips) and a *safe step*
//! `s`: for a value `v != 0`, `v` keeps its sign on the ray parameter interval `[0, s)`.
//! * Plane: `lambda = |n . d|`, valid everywhere.
//! * Box: only the axes whose `|x_i| - b_i` can be positive on the segment (outside) or the
//!   largest (inside) carry the gradient, so `lambda = |d restricted to those axes|`.
//! * Cylinder: as the box, with a radial and an axial term.
//! * Sphere: `|df/ds| = |u| / sqrt(u^2 + w^2)` with `u` the position along the ray relative
//!   to the centre's projection and `w` the ray's distance from the centre; largest at an end.
//! * Other leaves (and smooth union, repetition, mesh grids): the global bound `|v| / |d|`,
//!   which is plain sphere tracing.
//! * Union (`min`), positive: every child must stay positive, the minimum of their steps;
//!   intersection and subtraction (`max`), positive: one positive term staying positive
//!   suffices, the maximum. Negative values fall back to the global bound.
//! * A bounded subtree seen from outside its box is positive until the ray enters the box
//!   (an exact slab test), whatever its contents.
//!
//! Every step is also at least the global bound `|v| / |d|`, so it never falls below a plain
//! sphere-tracing step; bounds get a relative margin for rounding ([`LAMBDA_MARGIN`]).

use super::{Ctx, GridSampler, Op, Program};
use crate::lane::{Scalar, V3};
use crate::shapes;

/// Relative and absolute (times `|d|`) margin added to every directional bound, so rounding
/// of the bound itself (a dot product of unit vectors nearly perpendicular has an absolute
/// error of a few f32 ulps) never lets a step reach past the sign change.
pub const LAMBDA_MARGIN: f64 = 1e-6;

impl<S: Scalar> Program<S> {
    /// The field value at `p` and a safe step along `d` (see the [module docs](self)): for a
    /// value `v != 0`, the field keeps the sign of `v` at `p + s d` for every `s` in
    /// `[0, step)`. `len > 0` is the segment the local bounds are computed over (a longer one
    /// gives looser bounds); the step may exceed it where a bound holds everywhere (planes,
    /// boxes not yet entered). The step is never below `|v| / |d|` (plain sphere tracing),
    /// and 0 for `v = 0` or a NaN value. Same value as [`Program::eval`] (up to the order of
    /// a union's minimum, which does not change it).
    pub fn segment(&self, p: V3<S>, d: V3<S>, len: S, grids: &[&dyn GridSampler]) -> (S, S) {
        if self.instrs.is_empty() {
            return (S::c(super::BIG), S::c(f64::INFINITY));
        }
        let (v, s) = self.seg_child(0, p, d, len, Ctx::Plain, grids);
        (v, s.max(fallback(v, d)))
    }

    /// [`Program::child`] with a safe step.
    fn seg_child(
        &self,
        i: usize,
        p: V3<S>,
        d: V3<S>,
        len: S,
        ctx: Ctx<S>,
        grids: &[&dyn GridSampler],
    ) -> (S, S) {
        let ins = &self.instrs[i];
        let above = ctx.inherited_by(ins);
        if !ins.has_bound {
            return self.seg_node(i, p, d, len, above, grids);
        }
        let zero = S::c(0.0);
        let l = shapes::box_distance(p, V3::splat3(ins.lo), V3::splat3(ins.hi));
        let outside = zero < l;
        let tau = ins.tau;
        let mut skip = outside && tau <= l;
        if let Ctx::Below(thr) = ctx {
            skip |= outside && thr <= l;
        }
        // Outside the box the subtree's value is >= l > 0 until the ray enters the box.
        let enter = if outside {
            ray_box_enter(p, d, ins.lo, ins.hi)
        } else {
            zero
        };
        if skip {
            return (l, enter);
        }
        let (c, sc) = self.seg_node(i, p, d, len, above, grids);
        let cc = c.min(tau);
        let g = if outside { l.max(cc) } else { cc };
        let step = if zero < g {
            // `max(l, min(c, tau))` stays positive while either term does.
            enter.max(if zero < c { sc } else { zero })
        } else {
            fallback(g, d)
        };
        (g, step)
    }

    /// [`Program::node`] with a safe step (in the ray parameter, which every frame shares).
    fn seg_node(
        &self,
        i: usize,
        p: V3<S>,
        d: V3<S>,
        len: S,
        above: Option<S>,
        grids: &[&dyn GridSampler],
    ) -> (S, S) {
        let ins = &self.instrs[i];
        let zero = S::c(0.0);
        let end = ins.end as usize;
        let q = || ins.to_local.apply(p);
        let dl = || ins.to_local.apply_linear(d);
        // A leaf: the interpreter's value, the step from its directional bound `lambda`
        // (local frame; valid on `[0, len]` when `on_segment`).
        let leaf = |lambda: S, on_segment: bool| -> (S, S) {
            let (v, _) = self.node::<S, false>(i, p, above, grids);
            let dn = dl().len();
            let m = S::c(LAMBDA_MARGIN);
            let lam = lambda + lambda * m + dn * m;
            let mut s = v.abs() / lam;
            if on_segment {
                s = s.min(len);
            }
            (v, s.max(fallback(v, d)))
        };
        match &ins.op {
            Op::Plane { n, .. } => leaf(V3::splat3(*n).dot(dl()).abs(), false),
            Op::Box { b } => leaf(box_lambda(q(), dl(), len, *b), true),
            Op::Cylinder { r, h } => leaf(cylinder_lambda(q(), dl(), len, *r, *h), true),
            Op::Sphere { .. } => leaf(sphere_lambda(q(), dl(), len), true),
            Op::SphereAt { c, .. } => leaf(sphere_lambda(q() - V3::splat3(*c), dl(), len), true),
            Op::Union => {
                let (q, dl) = (q(), dl());
                let inf = S::c(f64::INFINITY);
                let mut j = i + 1;
                let (mut best, mut step) = match above {
                    // The parent's running minimum, a constant here.
                    Some(thr) => (thr, inf),
                    None => {
                        let first = self.seg_child(j, q, dl, len, Ctx::Plain, grids);
                        j = self.instrs[j].end as usize;
                        first
                    }
                };
                while j < end {
                    let (v, s) = self.seg_child(j, q, dl, len, Ctx::Below(best), grids);
                    best = best.min(v);
                    step = step.min(s);
                    j = self.instrs[j].end as usize;
                }
                let v = best * ins.dscale;
                // Positive: every child stays positive for the smallest child step.
                let s = if zero < v { step } else { fallback(v, d) };
                (v, s)
            }
            Op::Intersection => {
                let (q, dl) = (q(), dl());
                let mut j = i + 1;
                let mut best = S::c(f64::NEG_INFINITY);
                let mut step = zero;
                while j < end {
                    let (v, s) = self.seg_child(j, q, dl, len, Ctx::Plain, grids);
                    best = best.max(v);
                    // Positive: one positive child staying positive keeps the maximum so.
                    if zero < v {
                        step = step.max(s);
                    }
                    j = self.instrs[j].end as usize;
                }
                let v = best * ins.dscale;
                (v, if zero < v { step } else { fallback(v, d) })
            }
            Op::Subtraction => {
                let (q, dl) = (q(), dl());
                let mut j = i + 1;
                let (mut best, first_step) = self.seg_child(j, q, dl, len, Ctx::Plain, grids);
                let mut step = if zero < best { first_step } else { zero };
                j = self.instrs[j].end as usize;
                while j < end {
                    let (b, _) = self.subtrahend::<S, false>(j, q, best, grids);
                    let nb = -b;
                    best = best.max(nb);
                    if zero < nb {
                        // Inside the subtracted solid: it stays so for the global bound.
                        step = step.max(fallback(b, dl));
                    }
                    j = self.instrs[j].end as usize;
                }
                let v = best * ins.dscale;
                (v, if zero < v { step } else { fallback(v, d) })
            }
            // Leaves without a local bound here, blends, repetition and mesh grids: the
            // global bound.
            _ => {
                let (v, _) = self.node::<S, false>(i, p, above, grids);
                (v, fallback(v, d))
            }
        }
    }
}

/// The global (1-Lipschitz) safe step `|v| / |d|`; 0 for NaN.
#[inline]
fn fallback<S: Scalar>(v: S, d: V3<S>) -> S {
    let s = v.abs() / d.len();
    if s >= S::c(0.0) { s } else { S::c(0.0) }
}

/// The ray parameter `s >= 0` where `p + s d` first enters the box `[lo, hi]` (infinite
/// bounds allowed), or infinity when it never does. `p` is outside the box.
fn ray_box_enter<S: Scalar>(p: V3<S>, d: V3<S>, lo: [S; 3], hi: [S; 3]) -> S {
    let zero = S::c(0.0);
    let inf = S::c(f64::INFINITY);
    let mut enter = zero;
    let mut exit = inf;
    for (pa, da, l, h) in [
        (p.x, d.x, lo[0], hi[0]),
        (p.y, d.y, lo[1], hi[1]),
        (p.z, d.z, lo[2], hi[2]),
    ] {
        if da == zero {
            if pa < l || pa > h {
                return inf;
            }
            continue;
        }
        let a = (l - pa) / da;
        let b = (h - pa) / da;
        let (n, f) = if a < b { (a, b) } else { (b, a) };
        // NaN (an infinite bound at an infinite position) leaves the interval as it is.
        if n > enter {
            enter = n;
        }
        if f < exit {
            exit = f;
        }
    }
    if exit < enter { inf } else { enter }
}

/// Bound on `|d . grad f|` for the box of half extents `b` at the origin over the segment
/// `[q, q + len d]`: outside the box the gradient lies on the axes with `|x_i| > b_i`, inside
/// on the axis of the largest `|x_i| - b_i`; axes that can be neither on the segment drop
/// out of `|d|`.
fn box_lambda<S: Scalar>(q: V3<S>, d: V3<S>, len: S, b: [S; 3]) -> S {
    let zero = S::c(0.0);
    let q1 = q + d.scale(len);
    let range = |a0: S, a1: S, b: S| -> (S, S) {
        let (x0, x1) = (a0.abs(), a1.abs());
        let hi = x0.max(x1);
        let lo = if (a0 < zero) != (a1 < zero) {
            zero
        } else {
            x0.min(x1)
        };
        (lo - b, hi - b)
    };
    let r = [
        range(q.x, q1.x, b[0]),
        range(q.y, q1.y, b[1]),
        range(q.z, q1.z, b[2]),
    ];
    let floor = r[0].0.max(r[1].0).max(r[2].0);
    let da = [d.x, d.y, d.z];
    let mut l2 = zero;
    for a in 0..3 {
        let (_, hi) = r[a];
        // Active when it may be positive or the largest; NaN counts as active (safe).
        let never_largest = hi < floor;
        if zero < hi || !never_largest {
            l2 = l2 + da[a] * da[a];
        }
    }
    l2.sqrt()
}

/// Bound on `|d . grad f|` for the capped cylinder of radius `r` and half height `h` along
/// `y` (`shapes::cylinder`) over the segment `[q, q + len d]`, as [`box_lambda`] with two
/// "axes": the radial term `|x_xz| - r` (gradient along the radial unit vector, so at most
/// `|d_xz|`) and the cap term `|y| - h` (gradient along `y`). A term that can be neither
/// positive nor the largest on the segment drops out. Over a cap the radial term is negative
/// throughout, so a ray grazing the cap plane gets `lambda = |d_y|`: without this every ray
/// skimming a cap within a few pixel footprints crawled at steps of its height (the
/// conformance case `cylinder` exhausted 512 steps at a hit shell of 0.05 px).
fn cylinder_lambda<S: Scalar>(q: V3<S>, d: V3<S>, len: S, r: S, h: S) -> S {
    let zero = S::c(0.0);
    let q1 = q + d.scale(len);
    let rho = |x: S, z: S| (x * x + z * z).sqrt();
    let (r0, r1) = (rho(q.x, q.z), rho(q1.x, q1.z));
    let dxz2 = d.x * d.x + d.z * d.z;
    // The radial distance is convex along the segment: largest at an end, smallest at the
    // point closest to the axis (clamped to the segment).
    let closest = if zero < dxz2 {
        let s = (-(q.x * d.x + q.z * d.z) / dxz2).max(zero).min(len);
        rho(q.x + d.x * s, q.z + d.z * s)
    } else {
        r0
    };
    let radial = (closest.min(r0).min(r1) - r, r0.max(r1) - r);
    let (y0, y1) = (q.y.abs(), q1.y.abs());
    let ylo = if (q.y < zero) != (q1.y < zero) {
        zero
    } else {
        y0.min(y1)
    };
    let cap = (ylo - h, y0.max(y1) - h);
    let floor = radial.0.max(cap.0);
    let mut l2 = zero;
    // Active when it may be positive or the largest; NaN counts as active (safe).
    let (radial_never_largest, cap_never_largest) = (radial.1 < floor, cap.1 < floor);
    if zero < radial.1 || !radial_never_largest {
        l2 = l2 + dxz2;
    }
    if zero < cap.1 || !cap_never_largest {
        l2 = l2 + d.y * d.y;
    }
    l2.sqrt()
}

/// Bound on `|d . grad |x - c||` over the segment `[a, a + len d]` with `a = q - c`: with
/// `e = d / |d|`, `u = (a + s d) . e` and `w = |a x e|` (the ray's distance from the centre),
/// the derivative is `|d| |u| / sqrt(u^2 + w^2)`, increasing in `|u|`, so largest at an end.
fn sphere_lambda<S: Scalar>(a: V3<S>, d: V3<S>, len: S) -> S {
    let dn = d.len();
    let positive = dn > S::c(0.0);
    if !positive {
        return S::c(0.0);
    }
    let e = d.scale(S::c(1.0) / dn);
    let u0 = a.dot(e);
    let u1 = u0 + len * dn;
    let u = u0.abs().max(u1.abs());
    let w = a.cross(e).len();
    let r = (u * u + w * w).sqrt();
    if r > S::c(0.0) { dn * (u / r) } else { dn }
}
