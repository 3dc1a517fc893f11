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
use crate::lane::{Lane, Scalar, V3};
use crate::leaf::Leaf;
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
    pub fn segment(&self, p: V3<S>, d: V3<S>, len: S, grids: &[Box<dyn GridSampler>]) -> (S, S) {
        if self.instrs.is_empty() {
            return (S::c(super::BIG), S::c(f64::INFINITY));
        }
        let (v, s) = self.seg_child(0, p, d, len, Ctx::Plain, grids);
        (v, s.max(fallback(v, d)))
    }

    /// [`Program::segment`] of the program whose root keeps only its children `kids` (see
    /// [`Program::eval_root_subset`]): the same value and step as that restricted program's.
    pub fn segment_root_subset(
        &self,
        kids: &[u32],
        p: V3<S>,
        d: V3<S>,
        len: S,
        grids: &[Box<dyn GridSampler>],
    ) -> (S, S) {
        if self.instrs.is_empty() || kids.is_empty() || !self.root_is_smooth_union_or_blend() {
            return self.segment(p, d, len, grids);
        }
        // A blend has the global bound (`seg_node`'s last arm), under the root's box.
        let ins = &self.instrs[0];
        let node = || {
            let (v, _) = self.root_subset_node::<S, false>(kids, &[], &[], p, grids);
            (v, fallback(v, d))
        };
        let (v, s) = if ins.has_bound {
            bounded_step((ins.lo, ins.hi, ins.tau), None, p, d, node)
        } else {
            node()
        };
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
        grids: &[Box<dyn GridSampler>],
    ) -> (S, S) {
        let ins = &self.instrs[i];
        let above = ctx.inherited_by(ins);
        if !ins.has_bound {
            return self.seg_node(i, p, d, len, above, grids);
        }
        let below = match ctx {
            Ctx::Below(thr) => Some(thr),
            _ => None,
        };
        bounded_step((ins.lo, ins.hi, ins.tau), below, p, d, || {
            self.seg_node(i, p, d, len, above, grids)
        })
    }

    /// [`Program::node`] with a safe step (in the ray parameter, which every frame shares).
    fn seg_node(
        &self,
        i: usize,
        p: V3<S>,
        d: V3<S>,
        len: S,
        above: Option<S>,
        grids: &[Box<dyn GridSampler>],
    ) -> (S, S) {
        let ins = &self.instrs[i];
        let zero = S::c(0.0);
        let end = ins.end as usize;
        let q = || ins.to_local.apply(p);
        let dl = || ins.to_local.apply_linear(d);
        let dl = dl();
        if let Op::Leaf(leaf) = &ins.op
            && let Some(lambda) = leaf_lambda(leaf, q, dl, len)
        {
            let (v, _) = self.node::<S, false>(i, p, above, grids);
            return (v, leaf_step(v, lambda, dl.len(), len, d));
        }
        match &ins.op {
            Op::Union => {
                let q = q();
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
                let q = q();
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
                let q = q();
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
#[inline(always)]
pub(crate) fn fallback<T: Lane>(v: T, d: V3<T>) -> T {
    let s = v.abs() / d.len();
    let zero = T::c(0.0);
    T::select(T::le(zero, s), s, zero)
}

/// Per lane `(a < 0) != (b < 0)`.
#[inline(always)]
fn signs_differ<T: Lane>(a: T, b: T) -> T::Mask {
    let zero = T::c(0.0);
    let (na, nb) = (T::lt(a, zero), T::lt(b, zero));
    T::or(T::and(na, T::not(nb)), T::and(T::not(na), nb))
}

/// The ray parameter `s >= 0` where `p + s d` first enters the box `[lo, hi]` (infinite
/// bounds allowed), or infinity when it never does. `p` is outside the box.
#[inline(always)]
pub(crate) fn ray_box_enter<T: Lane>(p: V3<T>, d: V3<T>, lo: [T::S; 3], hi: [T::S; 3]) -> T {
    let zero = T::c(0.0);
    let inf = T::c(f64::INFINITY);
    let mut enter = zero;
    let mut exit = inf;
    let mut miss = T::lt(zero, zero);
    for (pa, da, l, h) in [
        (p.x, d.x, lo[0], hi[0]),
        (p.y, d.y, lo[1], hi[1]),
        (p.z, d.z, lo[2], hi[2]),
    ] {
        let (l, h) = (T::splat(l), T::splat(h));
        // Parallel to the slab: inside it or never in the box.
        let flat = T::and(T::le(da, zero), T::le(zero, da));
        miss = T::or(miss, T::and(flat, T::or(T::lt(pa, l), T::lt(h, pa))));
        let a = (l - pa) / da;
        let b = (h - pa) / da;
        let ordered = T::lt(a, b);
        let (n, f) = (T::select(ordered, a, b), T::select(ordered, b, a));
        // NaN (an infinite bound at an infinite position) leaves the interval as it is.
        let live = T::not(flat);
        enter = T::select(T::and(live, T::lt(enter, n)), n, enter);
        exit = T::select(T::and(live, T::lt(f, exit)), f, exit);
    }
    T::select(T::or(miss, T::lt(exit, enter)), inf, enter)
}

/// A bounded node's value and safe step (`Program::child` with a safe step): `lo`, `hi`
/// its box and `tau` its skip distance in the parent's frame, `below` the running minimum
/// of an enclosing union it is skipped against, `node` the unbounded node's value and step.
/// Outside the box the node's value is at least the box distance, positive until the ray
/// enters the box (an exact slab test).
#[inline(always)]
pub(crate) fn bounded_step<T: Lane>(
    (lo, hi, tau): ([T::S; 3], [T::S; 3], T::S),
    below: Option<T>,
    p: V3<T>,
    d: V3<T>,
    node: impl FnOnce() -> (T, T),
) -> (T, T) {
    let zero = T::c(0.0);
    let l = shapes::box_distance(p, V3::splat3(lo), V3::splat3(hi));
    let outside = T::lt(zero, l);
    let tau = T::splat(tau);
    let mut skip = T::and(outside, T::le(tau, l));
    if let Some(thr) = below {
        skip = T::or(skip, T::and(outside, T::le(thr, l)));
    }
    let enter = if T::any(outside) {
        T::select(outside, ray_box_enter(p, d, lo, hi), zero)
    } else {
        zero
    };
    if T::all(skip) {
        return (l, enter);
    }
    let (c, sc) = node();
    let cc = c.min(tau);
    let g = T::select(outside, l.max(cc), cc);
    // `max(l, min(c, tau))` stays positive while either term does.
    let positive = enter.max(T::select(T::lt(zero, c), sc, zero));
    let step = T::select(T::lt(zero, g), positive, fallback(g, d));
    (T::select(skip, l, g), T::select(skip, enter, step))
}

/// The directional bound `lambda` of `leaf` over the segment `[q, q + len d]` (local
/// frame, `q` computed only for leaves that need it) and whether it holds only on the
/// segment; `None` for leaves without a local bound (the global bound serves them).
/// inner nodes.
#[inline(always)]
pub(crate) fn leaf_lambda<T: Lane>(
    leaf: &Leaf<T::S>,
    q: impl FnOnce() -> V3<T>,
    d: V3<T>,
    len: T,
) -> Option<(T, bool)> {
    Some(match leaf {
        Leaf::Plane { n, .. } => (V3::splat3(*n).dot(d).abs(), false),
        Leaf::Box { b } => (box_lambda(q(), d, len, *b), true),
        Leaf::Cylinder { r, h } => (cylinder_lambda(q(), d, len, *r, *h), true),
        Leaf::Sphere { .. } => (sphere_lambda(q(), d, len), true),
        Leaf::SphereAt { c, .. } => (sphere_lambda(q() - V3::splat3(*c), d, len), true),
        // Optional per shape: the others take the global bound.
        _ => return None,
    })
}

/// A leaf's safe step from its value `v` and directional bound `lambda` (local frame,
/// `dn` the local direction's length; clamped to `len` when the bound holds only on the
/// segment), never below the global bound along `d` (the parent frame's direction).
#[inline(always)]
pub(crate) fn leaf_step<T: Lane>(
    v: T,
    (lambda, on_segment): (T, bool),
    dn: T,
    len: T,
    d: V3<T>,
) -> T {
    let m = T::c(LAMBDA_MARGIN);
    let lam = lambda + lambda * m + dn * m;
    let mut s = v.abs() / lam;
    if on_segment {
        s = s.min(len);
    }
    s.max(fallback(v, d))
}

/// Bound on `|d . grad f|` for the box of half extents `b` at the origin over the segment
/// `[q, q + len d]`: outside the box the gradient lies on the axes with `|x_i| > b_i`, inside
/// on the axis of the largest `|x_i| - b_i`; axes that can be neither on the segment drop
/// out of `|d|`.
#[inline(always)]
fn box_lambda<T: Lane>(q: V3<T>, d: V3<T>, len: T, b: [T::S; 3]) -> T {
    let zero = T::c(0.0);
    let q1 = q + d.scale(len);
    let range = |a0: T, a1: T, b: T::S| -> (T, T) {
        let (x0, x1) = (a0.abs(), a1.abs());
        let hi = x0.max(x1);
        let lo = T::select(signs_differ(a0, a1), zero, x0.min(x1));
        (lo - T::splat(b), hi - T::splat(b))
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
        let active = T::or(T::lt(zero, hi), T::not(T::lt(hi, floor)));
        l2 = T::select(active, l2 + da[a] * da[a], l2);
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
#[inline(always)]
fn cylinder_lambda<T: Lane>(q: V3<T>, d: V3<T>, len: T, r: T::S, h: T::S) -> T {
    let zero = T::c(0.0);
    let q1 = q + d.scale(len);
    let rho = |x: T, z: T| (x * x + z * z).sqrt();
    let (r0, r1) = (rho(q.x, q.z), rho(q1.x, q1.z));
    let dxz2 = d.x * d.x + d.z * d.z;
    // The radial distance is convex along the segment: largest at an end, smallest at the
    // point closest to the axis (clamped to the segment).
    let s = (-(q.x * d.x + q.z * d.z) / dxz2).max(zero).min(len);
    let closest = T::select(T::lt(zero, dxz2), rho(q.x + d.x * s, q.z + d.z * s), r0);
    let (r, h) = (T::splat(r), T::splat(h));
    let radial = (closest.min(r0).min(r1) - r, r0.max(r1) - r);
    let (y0, y1) = (q.y.abs(), q1.y.abs());
    let ylo = T::select(signs_differ(q.y, q1.y), zero, y0.min(y1));
    let cap = (ylo - h, y0.max(y1) - h);
    let floor = radial.0.max(cap.0);
    // Active when it may be positive or the largest; NaN counts as active (safe).
    let active = |hi: T| T::or(T::lt(zero, hi), T::not(T::lt(hi, floor)));
    let mut l2 = zero;
    l2 = T::select(active(radial.1), l2 + dxz2, l2);
    l2 = T::select(active(cap.1), l2 + d.y * d.y, l2);
    l2.sqrt()
}

/// Bound on `|d . grad |x - c||` over the segment `[a, a + len d]` with `a = q - c`: with
/// `e = d / |d|`, `u = (a + s d) . e` and `w = |a x e|` (the ray's distance from the centre),
/// the derivative is `|d| |u| / sqrt(u^2 + w^2)`, increasing in `|u|`, so largest at an end.
#[inline(always)]
fn sphere_lambda<T: Lane>(a: V3<T>, d: V3<T>, len: T) -> T {
    let zero = T::c(0.0);
    let dn = d.len();
    let e = d.scale(T::c(1.0) / dn);
    let u0 = a.dot(e);
    let u1 = u0 + len * dn;
    let u = u0.abs().max(u1.abs());
    let w = a.cross(e).len();
    let r = (u * u + w * w).sqrt();
    let lambda = T::select(T::lt(zero, r), dn * (u / r), dn);
    T::select(T::lt(zero, dn), lambda, zero)
}
