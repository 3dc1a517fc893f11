//! Distance functions of the analytic primitives in their local frames, written once for
//! every [`Lane`] type. Formulas follow Inigo Quilez's catalogue of distance functions.
//! All are exact Euclidean signed distances except [`ellipsoid`] (a bound, see there) and
//! [`triangle`] (exact but unsigned: a triangle has no inside).

use crate::lane::{Lane, V3};

/// Sphere of radius `r` at the origin: `|p| - r`. Exact.
#[inline(always)]
pub fn sphere<T: Lane>(p: V3<T>, r: T) -> T {
    p.len() - r
}

/// Sphere with centre `c`, radius `r` and `k = |c|^2 - r^2`, as
/// `(|p|^2 - 2 p.c + k) / (|p - c| + r)` (equal to `|p - c| - r`). Exact, and accurate in f32
/// for points near the origin of the frame even when `|c|` and `r` are huge.
#[inline(always)]
pub fn sphere_at<T: Lane>(p: V3<T>, c: V3<T>, r: T, k: T) -> T {
    (p.len2() - p.dot(c) * T::c(2.0) + k) / ((p - c).len() + r)
}

/// Half-space `dot(n, p) <= offset` with unit `n`: `dot(n, p) - offset`. Exact.
#[inline(always)]
pub fn plane<T: Lane>(p: V3<T>, n: V3<T>, offset: T) -> T {
    p.dot(n) - offset
}

/// Box with half extents `b` at the origin. Exact (outside and inside).
#[inline(always)]
pub fn box3<T: Lane>(p: V3<T>, b: V3<T>) -> T {
    let q = p.abs() - b;
    let zero = T::c(0.0);
    q.max_s(zero).len() + q.max_elem().min(zero)
}

/// Torus around the y axis, major radius `big`, minor radius `small`. Exact.
#[inline(always)]
pub fn torus<T: Lane>(p: V3<T>, big: T, small: T) -> T {
    let qx = (p.x * p.x + p.z * p.z).sqrt() - big;
    (qx * qx + p.y * p.y).sqrt() - small
}

/// Capped cylinder along y with radius `r` and half height `h`. Exact.
#[inline(always)]
pub fn cylinder<T: Lane>(p: V3<T>, r: T, h: T) -> T {
    let zero = T::c(0.0);
    let dx = (p.x * p.x + p.z * p.z).sqrt() - r;
    let dy = p.y.abs() - h;
    let ox = dx.max(zero);
    let oy = dy.max(zero);
    dx.max(dy).min(zero) + (ox * ox + oy * oy).sqrt()
}

/// Box with half extents `inner + r` whose edges and corners are rounded by radius `r`:
/// the box of half extents `inner` grown by `r`, so `box3(p, inner) - r`. Exact.
#[inline(always)]
pub fn rounded_box<T: Lane>(p: V3<T>, inner: V3<T>, r: T) -> T {
    box3(p, inner) - r
}

/// Capsule: the points within `r` of the y-axis segment `|y| <= h`. Exact.
#[inline(always)]
pub fn capsule<T: Lane>(p: V3<T>, h: T, r: T) -> T {
    let y = p.y - p.y.clamp(-h, h);
    (p.x * p.x + y * y + p.z * p.z).sqrt() - r
}

/// Capped cone along y from radius `r1` at `y = -h` to `r2` at `y = h` (Quilez's
/// `sdCappedCone`), `inv_k2 = 1 / ((r2 - r1)^2 + 4 h^2)`. Exact.
#[inline(always)]
pub fn capped_cone<T: Lane>(p: V3<T>, h: T, r1: T, r2: T, inv_k2: T) -> T {
    let zero = T::c(0.0);
    let qx = (p.x * p.x + p.z * p.z).sqrt();
    let qy = p.y;
    // Nearest cap: the bottom one below the middle.
    let cap_r = T::select(T::lt(qy, zero), r1, r2);
    let ca_x = qx - qx.min(cap_r);
    let ca_y = qy.abs() - h;
    // Nearest point of the slanted side, from (r2, h) along (r2 - r1, 2h).
    let (k2x, k2y) = (r2 - r1, h + h);
    let t = (((r2 - qx) * k2x + (h - qy) * k2y) * inv_k2).clamp(zero, T::c(1.0));
    let cb_x = qx - r2 + k2x * t;
    let cb_y = qy - h + k2y * t;
    let inside = T::and(T::lt(cb_x, zero), T::lt(ca_y, zero));
    let d = (ca_x * ca_x + ca_y * ca_y)
        .min(cb_x * cb_x + cb_y * cb_y)
        .sqrt();
    T::select(inside, -d, d)
}

/// Ellipsoid with semi-axes `r` (`rmin` = smallest of them): the *scaled-sphere bound*
/// `rmin * (|p / r| - 1)`.
///
/// Not the exact distance (no closed form exists) but a bound that never over-estimates:
/// `g(p) = |p / r| - 1` is `1/rmin`-Lipschitz and zero exactly on the surface, so
/// `rmin * g` is 1-Lipschitz and zero on the surface, hence `|rmin * g(p)| <= dist(p, surface)`
/// with the right sign. Exact for spheres; far from a strongly stretched ellipsoid it
/// under-estimates by up to the ratio `rmin / rmax` (sphere tracing then takes more steps;
/// the enclosing box bound of the node limits that loss far away).
#[inline(always)]
pub fn ellipsoid<T: Lane>(p: V3<T>, inv_r: V3<T>, rmin: T) -> T {
    rmin * (p.mul_elem(inv_r).len() - T::c(1.0))
}

/// Precomputed data of a triangle, see [`triangle`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriData<S> {
    /// Corner a.
    pub a: [S; 3],
    /// Corner b.
    pub b: [S; 3],
    /// Corner c.
    pub c: [S; 3],
    /// b - a.
    pub ba: [S; 3],
    /// c - b.
    pub cb: [S; 3],
    /// a - c.
    pub ac: [S; 3],
    /// cross(ba, n), cross(cb, n), cross(ac, n) with n = cross(ba, ac): edge-plane normals.
    pub en: [[S; 3]; 3],
    /// Unit normal.
    pub n: [S; 3],
    /// 1 / |ba|^2, 1 / |cb|^2, 1 / |ac|^2.
    pub inv2: [S; 3],
}

/// Unsigned distance to a triangle (a two-sided surface of zero thickness). Exact.
#[inline(always)]
pub fn triangle<T: Lane>(p: V3<T>, t: &TriData<T::S>) -> T {
    let zero = T::c(0.0);
    let one = T::c(1.0);
    let pa = p - V3::splat3(t.a);
    let pb = p - V3::splat3(t.b);
    let pc = p - V3::splat3(t.c);
    let s0 = V3::splat3(t.en[0]).dot(pa);
    let s1 = V3::splat3(t.en[1]).dot(pb);
    let s2 = V3::splat3(t.en[2]).dot(pc);
    // Inside the prism over the triangle iff all three edge-plane tests agree (>= 0).
    let inside = T::and(T::and(T::le(zero, s0), T::le(zero, s1)), T::le(zero, s2));
    let np = V3::splat3(t.n).dot(pa);
    let face = np * np;
    let edge = |e: [T::S; 3], inv: T::S, pv: V3<T>| -> T {
        let e = V3::splat3(e);
        let h = (e.dot(pv) * T::splat(inv)).clamp(zero, one);
        (e.scale(h) - pv).len2()
    };
    let d2 = if T::all(inside) {
        face
    } else {
        let ed = edge(t.ba, t.inv2[0], pa)
            .min(edge(t.cb, t.inv2[1], pb))
            .min(edge(t.ac, t.inv2[2], pc));
        T::select(inside, face, ed)
    };
    d2.sqrt()
}

/// Distance from `p` to the box `[lo, hi]` (0 inside); infinite bounds allowed.
#[inline(always)]
pub fn box_distance<T: Lane>(p: V3<T>, lo: V3<T>, hi: V3<T>) -> T {
    let zero = T::c(0.0);
    let dx = (lo.x - p.x).max(p.x - hi.x).max(zero);
    let dy = (lo.y - p.y).max(p.y - hi.y).max(zero);
    let dz = (lo.z - p.z).max(p.z - hi.z).max(zero);
    (dx * dx + dy * dy + dz * dz).sqrt()
}

/// Quilez's polynomial smooth minimum with blend radius `k > 0`:
/// `min(a, b) - h^2 k / 4` with `h = max(k - |a - b|, 0) / k`.
///
/// Its gradient with respect to `(a, b)` has non-negative weights summing to 1, so it is
/// 1-Lipschitz when `a` and `b` are: a *bound* on the distance to its own zero set (the
/// blended surface), not the exact distance. It never exceeds `min(a, b)` and differs from
/// it by at most `k / 4`, only where `|a - b| < k`.
#[inline(always)]
pub fn smin<T: Lane>(a: T, b: T, k: T, inv_k: T) -> T {
    let h = (k - (a - b).abs()).max(T::c(0.0)) * inv_k;
    a.min(b) - h * h * k * T::c(0.25)
}

/// The polynomial smooth maximum `-smin(-a, -b)` = `max(a, b) + h^2 k / 4` with the same
/// `h`: never below `max(a, b)`, at most `k / 4` above it, 1-Lipschitz when `a` and `b` are.
/// Smooth intersection folds it; smooth subtraction folds `smax(a, -b)`.
#[inline(always)]
pub fn smax<T: Lane>(a: T, b: T, k: T, inv_k: T) -> T {
    let h = (k - (a - b).abs()).max(T::c(0.0)) * inv_k;
    a.max(b) + h * h * k * T::c(0.25)
}
