//! Closed-form ray/primitive intersection in f64, in each primitive's local frame.
//!
//! Rays are `o + t d` with `d` of any non-zero length (a non-uniform scale above the
//! primitive stretches it); `t` is the caller's parameter, so hits need no conversion.
//! Solids return their spans along the whole line; normals point outward (unnormalised).

use glam::DVec3;
use marchmesh_scene::Shape;

use crate::poly;
use crate::spans::{Boundary, Span};

/// The spans of `shape` (local frame) along the whole line `o + t d`: the reference's one
/// dispatch over shapes, exhaustive so a new shape fails to compile here until it has an
/// exact intersection. A triangle (no inside) has none: its hits come from [`triangle`];
/// a mesh file has its own BVH and is never compiled to a shape.
pub(crate) fn spans(shape: &Shape, o: DVec3, d: DVec3) -> Vec<Span> {
    let one = |s: Option<Span>| s.into_iter().collect::<Vec<_>>();
    match shape {
        Shape::Sphere { radius } => one(sphere(o, d, *radius)),
        Shape::Ellipsoid { radii } => one(ellipsoid(o, d, *radii)),
        Shape::Box { half_extents } => one(aabox(o, d, *half_extents)),
        Shape::Cylinder {
            radius,
            half_height,
        } => one(cylinder(o, d, *radius, *half_height)),
        Shape::Torus {
            major_radius,
            minor_radius,
        } => torus(o, d, *major_radius, *minor_radius),
        Shape::RoundedBox {
            half_extents,
            rounding_radius,
        } => one(rounded_box(o, d, *half_extents, *rounding_radius)),
        Shape::Capsule {
            radius,
            half_height,
        } => one(capsule(o, d, *radius, *half_height)),
        Shape::CappedCone {
            half_height,
            bottom_radius,
            top_radius,
        } => one(capped_cone(o, d, *half_height, *bottom_radius, *top_radius)),
        Shape::Plane { normal, offset } => one(half_space(o, d, *normal, *offset)),
        Shape::Triangle { .. } | Shape::Mesh { .. } => Vec::new(),
    }
}

fn b(t: f64, normal: DVec3) -> Boundary {
    Boundary {
        t,
        normal,
        material: 0,
    }
}

/// The sphere of radius `r` at the origin. Uses the perpendicular-distance form (Haines et
/// al., Ray Tracing Gems ch. 7) so far-away origins keep their precision.
pub fn sphere(o: DVec3, d: DVec3, r: f64) -> Option<Span> {
    let len = d.length();
    let du = d / len;
    let tc = -o.dot(du);
    let perp = o + tc * du;
    let h = r * r - perp.length_squared();
    if h < 0.0 {
        return None;
    }
    let s = h.sqrt();
    let (t0, t1) = ((tc - s) / len, (tc + s) / len);
    Some(Span {
        enter: b(t0, o + t0 * d),
        exit: b(t1, o + t1 * d),
    })
}

/// The ellipsoid with semi-axes `radii` at the origin: a unit sphere after scaling.
pub fn ellipsoid(o: DVec3, d: DVec3, radii: DVec3) -> Option<Span> {
    let s = sphere(o / radii, d / radii, 1.0)?;
    let n = |t: f64| (o + t * d) / (radii * radii);
    Some(Span {
        enter: b(s.enter.t, n(s.enter.t)),
        exit: b(s.exit.t, n(s.exit.t)),
    })
}

/// The axis-aligned box `|p_i| <= h_i` (slab method with explicit parallel-ray handling).
pub fn aabox(o: DVec3, d: DVec3, h: DVec3) -> Option<Span> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    let (mut n0, mut n1) = (DVec3::ZERO, DVec3::ZERO);
    for axis in 0..3 {
        let (oa, da, ha) = (o[axis], d[axis], h[axis]);
        if da == 0.0 {
            if oa.abs() > ha {
                return None;
            }
            continue;
        }
        let inv = 1.0 / da;
        let (mut near, mut far) = ((-ha - oa) * inv, (ha - oa) * inv);
        let mut sign = -1.0;
        if near > far {
            std::mem::swap(&mut near, &mut far);
            sign = 1.0;
        }
        let mut axis_n = DVec3::ZERO;
        axis_n[axis] = 1.0;
        if near > t0 {
            t0 = near;
            n0 = axis_n * sign;
        }
        if far < t1 {
            t1 = far;
            n1 = -axis_n * sign;
        }
        if t0 > t1 {
            return None;
        }
    }
    Some(Span {
        enter: b(t0, n0),
        exit: b(t1, n1),
    })
}

/// The capped cylinder along y: `x^2 + z^2 <= r^2`, `|y| <= hh`.
pub fn cylinder(o: DVec3, d: DVec3, r: f64, hh: f64) -> Option<Span> {
    // Infinite cylinder in xz.
    let (o2, d2) = (glam::DVec2::new(o.x, o.z), glam::DVec2::new(d.x, d.z));
    let (mut t0, mut t1, mut n0, mut n1);
    let dd = d2.length_squared();
    if dd == 0.0 {
        if o2.length_squared() > r * r {
            return None;
        }
        t0 = f64::NEG_INFINITY;
        t1 = f64::INFINITY;
        n0 = DVec3::ZERO;
        n1 = DVec3::ZERO;
    } else {
        let len = dd.sqrt();
        let du = d2 / len;
        let tc = -o2.dot(du);
        let perp = o2 + tc * du;
        let h = r * r - perp.length_squared();
        if h < 0.0 {
            return None;
        }
        let s = h.sqrt();
        t0 = (tc - s) / len;
        t1 = (tc + s) / len;
        let side = |t: f64| {
            let p = o + t * d;
            DVec3::new(p.x, 0.0, p.z)
        };
        n0 = side(t0);
        n1 = side(t1);
    }
    // Slab in y.
    if d.y == 0.0 {
        if o.y.abs() > hh {
            return None;
        }
    } else {
        let (mut near, mut far) = ((-hh - o.y) / d.y, (hh - o.y) / d.y);
        let mut ny = -1.0;
        if near > far {
            std::mem::swap(&mut near, &mut far);
            ny = 1.0;
        }
        if near > t0 {
            t0 = near;
            n0 = DVec3::new(0.0, ny, 0.0);
        }
        if far < t1 {
            t1 = far;
            n1 = DVec3::new(0.0, -ny, 0.0);
        }
    }
    (t0 <= t1).then(|| Span {
        enter: b(t0, n0),
        exit: b(t1, n1),
    })
}

/// The convex hull of spans of convex pieces: a convex solid that is the union of convex
/// pieces meets a line in one interval, from the earliest entry to the latest exit of any
/// piece (each piece's interval lies in it, and together they cover it).
fn convex_union(pieces: impl IntoIterator<Item = Option<Span>>) -> Option<Span> {
    pieces.into_iter().flatten().reduce(|a, s| Span {
        enter: if s.enter.t < a.enter.t {
            s.enter
        } else {
            a.enter
        },
        exit: if s.exit.t > a.exit.t { s.exit } else { a.exit },
    })
}

/// The capsule of radius `r` around the y-axis segment `|y| <= hh`: the union of the
/// capped cylinder over the segment and the spheres at its ends (convex: `convex_union`).
pub fn capsule(o: DVec3, d: DVec3, r: f64, hh: f64) -> Option<Span> {
    let end = |y: f64| {
        let c = DVec3::new(0.0, y, 0.0);
        sphere(o - c, d, r)
    };
    let middle = (hh > 0.0).then(|| cylinder(o, d, r, hh)).flatten();
    convex_union([middle, end(hh), end(-hh)])
}

/// The box of half extents `half` with edges and corners rounded by radius `r`
/// (`0 <= r <= min(half)`): the inner box `half - r` grown by `r`, i.e. the union of the
/// inner box grown along each axis alone, a cylinder along each of its 12 edges and a sphere
/// at each of its 8 corners (convex: `convex_union`). `r = 0` is the plain box.
pub fn rounded_box(o: DVec3, d: DVec3, half: DVec3, r: f64) -> Option<Span> {
    if r <= 0.0 {
        return aabox(o, d, half);
    }
    let inner = (half - DVec3::splat(r)).max(DVec3::ZERO);
    let mut pieces: Vec<Option<Span>> = Vec::with_capacity(23);
    for axis in 0..3 {
        let mut h = inner;
        h[axis] += r;
        pieces.push(aabox(o, d, h));
    }
    // Edges along `axis`: cylinders in a frame whose y is that axis (a permutation of the
    // coordinates: orthogonal, so `t` is unchanged and normals map back by the inverse).
    for axis in 0..3 {
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        let to_frame = |v: DVec3| DVec3::new(v[a], v[axis], v[b]);
        let from_frame = |v: DVec3| {
            let mut w = DVec3::ZERO;
            w[a] = v.x;
            w[axis] = v.y;
            w[b] = v.z;
            w
        };
        for (sa, sb) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
            let mut c = DVec3::ZERO;
            c[a] = sa * inner[a];
            c[b] = sb * inner[b];
            pieces.push(
                cylinder(to_frame(o - c), to_frame(d), r, inner[axis]).map(|s| Span {
                    enter: Boundary {
                        normal: from_frame(s.enter.normal),
                        ..s.enter
                    },
                    exit: Boundary {
                        normal: from_frame(s.exit.normal),
                        ..s.exit
                    },
                }),
            );
        }
    }
    for i in 0..8 {
        let c = DVec3::new(
            if i & 1 == 0 { -inner.x } else { inner.x },
            if i & 2 == 0 { -inner.y } else { inner.y },
            if i & 4 == 0 { -inner.z } else { inner.z },
        );
        pieces.push(sphere(o - c, d, r));
    }
    convex_union(pieces)
}

/// The capped cone along y from radius `r1` at `y = -hh` to `r2` at `y = hh` (both >= 0,
/// not both 0): the slab `|y| <= hh` clipped by the lateral quadric
/// `x^2 + z^2 <= R(y)^2`, `R(y) = (r1 + r2) / 2 + (r2 - r1) / (2 hh) y`. In the slab `R >= 0`,
/// so the quadric's other nappe (beyond the apex) never enters and the part of the slab
/// interval where the quadratic is <= 0 is the one interval a convex solid gives.
pub fn capped_cone(o: DVec3, d: DVec3, hh: f64, r1: f64, r2: f64) -> Option<Span> {
    // Slab in y.
    let (mut t0, mut t1, mut n0, mut n1);
    if d.y == 0.0 {
        if o.y.abs() > hh {
            return None;
        }
        (t0, t1) = (f64::NEG_INFINITY, f64::INFINITY);
        (n0, n1) = (DVec3::ZERO, DVec3::ZERO);
    } else {
        let (mut near, mut far) = ((-hh - o.y) / d.y, (hh - o.y) / d.y);
        let mut ny = -1.0;
        if near > far {
            std::mem::swap(&mut near, &mut far);
            ny = 1.0;
        }
        (t0, t1) = (near, far);
        (n0, n1) = (DVec3::new(0.0, ny, 0.0), DVec3::new(0.0, -ny, 0.0));
    }
    let slope = (r2 - r1) / (2.0 * hh);
    let mid = 0.5 * (r1 + r2);
    // g(t) = |xz(o + t d)|^2 - R(y(t))^2 = qa t^2 + qb t + qc.
    let ro = mid + slope * o.y;
    let qa = d.x * d.x + d.z * d.z - slope * slope * d.y * d.y;
    let qb = 2.0 * (o.x * d.x + o.z * d.z - slope * d.y * ro);
    let qc = o.x * o.x + o.z * o.z - ro * ro;
    let side = |t: f64| {
        let p = o + t * d;
        let rho = (p.x * p.x + p.z * p.z).sqrt();
        if rho > 0.0 {
            DVec3::new(p.x / rho, -slope, p.z / rho)
        } else {
            DVec3::new(0.0, -slope.signum(), 0.0)
        }
    };
    // The parameter interval (possibly unbounded) where g <= 0 inside the slab.
    let (lo, hi): (f64, f64) = if qa == 0.0 {
        if qb == 0.0 {
            if qc > 0.0 {
                return None;
            }
            (f64::NEG_INFINITY, f64::INFINITY)
        } else if qb > 0.0 {
            (f64::NEG_INFINITY, -qc / qb)
        } else {
            (-qc / qb, f64::INFINITY)
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc < 0.0 {
            if qa > 0.0 {
                return None;
            }
            (f64::NEG_INFINITY, f64::INFINITY)
        } else {
            // Stable roots (no cancellation between -qb and the root).
            let root = if qb >= 0.0 { disc.sqrt() } else { -disc.sqrt() };
            let q = -0.5 * (qb + root);
            let (mut ra, mut rb) = (q / qa, qc / q);
            if q == 0.0 {
                (ra, rb) = (0.0, 0.0);
            }
            if ra > rb {
                std::mem::swap(&mut ra, &mut rb);
            }
            if qa > 0.0 {
                (ra, rb)
            } else {
                // g <= 0 outside the roots: keep the side that meets the slab.
                let left = t1.min(ra) - t0;
                let right = t1 - t0.max(rb);
                if left >= right {
                    (f64::NEG_INFINITY, ra)
                } else {
                    (rb, f64::INFINITY)
                }
            }
        }
    };
    if lo > t0 {
        t0 = lo;
        n0 = side(lo);
    }
    if hi < t1 {
        t1 = hi;
        n1 = side(hi);
    }
    (t0 <= t1).then(|| Span {
        enter: b(t0, n0),
        exit: b(t1, n1),
    })
}

/// The half-space `dot(n, p) <= offset` (`n` unit).
pub fn half_space(o: DVec3, d: DVec3, n: DVec3, offset: f64) -> Option<Span> {
    let s = n.dot(o) - offset;
    let dn = n.dot(d);
    if dn == 0.0 {
        return (s <= 0.0).then(|| Span {
            enter: Boundary::infinite(f64::NEG_INFINITY),
            exit: Boundary::infinite(f64::INFINITY),
        });
    }
    let t = -s / dn;
    Some(if dn < 0.0 {
        Span {
            enter: b(t, n),
            exit: Boundary::infinite(f64::INFINITY),
        }
    } else {
        Span {
            enter: Boundary::infinite(f64::NEG_INFINITY),
            exit: b(t, n),
        }
    })
}

/// The torus around y (major radius `big`, tube radius `small`): the quartic in the ray
/// parameter, taken about the point of the ray nearest the centre so its coefficients are
/// well conditioned, solved by derivative recursion and bisection ([`poly::real_roots`]).
/// Spans come from the sign of the implicit function between consecutive roots.
pub fn torus(o: DVec3, d: DVec3, big: f64, small: f64) -> Vec<Span> {
    let len = d.length();
    let du = d / len;
    let tc = -o.dot(du);
    let oc = o + tc * du;
    let reach = big + small;
    let c0 = oc.length_squared();
    if c0 > reach * reach {
        return Vec::new();
    }
    let half = (reach * reach - c0).sqrt();
    let k = c0 + big * big - small * small;
    let r2 = 4.0 * big * big;
    let a2 = du.x * du.x + du.z * du.z;
    let a1 = oc.x * du.x + oc.z * du.z;
    let a0 = oc.x * oc.x + oc.z * oc.z;
    let coeffs = [k * k - r2 * a0, -2.0 * r2 * a1, 2.0 * k - r2 * a2, 0.0, 1.0];
    let f = |s: f64| {
        let p = oc + s * du;
        let q = p.length_squared() + big * big - small * small;
        q * q - r2 * (p.x * p.x + p.z * p.z)
    };
    let roots = poly::real_roots(&coeffs, -half * 1.0001, half * 1.0001, 0.0);
    let mut spans = Vec::new();
    let normal = |s: f64| {
        let p = oc + s * du;
        let q = p.length_squared() + big * big - small * small;
        4.0 * q * p - 2.0 * r2 * DVec3::new(p.x, 0.0, p.z)
    };
    for w in roots.windows(2) {
        if f(0.5 * (w[0] + w[1])) < 0.0 {
            let (s0, s1) = (w[0], w[1]);
            spans.push(Span {
                enter: b((tc + s0) / len, normal(s0)),
                exit: b((tc + s1) / len, normal(s1)),
            });
        }
    }
    spans
}

/// Ray/triangle intersection in f64 (Möller-Trumbore): `t` over the whole line, the
/// barycentrics `(u, v)` of vertices 1 and 2, and the geometric normal `(b-a) x (c-a)`.
/// Edges are inclusive, so rays through a shared edge hit both neighbours.
pub fn triangle(o: DVec3, d: DVec3, v: &[DVec3; 3]) -> Option<(f64, f64, f64, DVec3)> {
    let e1 = v[1] - v[0];
    let e2 = v[2] - v[0];
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - v[0];
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let w = d.dot(q) * inv;
    if w < 0.0 || u + w > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    Some((t, u, w, e1.cross(e2)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_from_outside_and_inside() {
        let s = sphere(DVec3::new(0.0, 0.0, -5.0), DVec3::Z, 1.0).unwrap();
        assert_eq!((s.enter.t, s.exit.t), (4.0, 6.0));
        let s = sphere(DVec3::ZERO, DVec3::new(0.0, 0.0, 2.0), 1.0).unwrap();
        assert_eq!((s.enter.t, s.exit.t), (-0.5, 0.5));
        assert!(sphere(DVec3::new(0.0, 1.5, -5.0), DVec3::Z, 1.0).is_none());
    }

    #[test]
    fn box_parallel_to_a_face() {
        let s = aabox(DVec3::new(-5.0, 0.5, 0.2), DVec3::X, DVec3::splat(1.0)).unwrap();
        assert_eq!((s.enter.t, s.exit.t), (4.0, 6.0));
        assert_eq!(s.enter.normal, DVec3::NEG_X);
        assert_eq!(s.exit.normal, DVec3::X);
        assert!(aabox(DVec3::new(-5.0, 1.5, 0.0), DVec3::X, DVec3::splat(1.0)).is_none());
    }

    #[test]
    fn cylinder_side_and_caps() {
        let s = cylinder(DVec3::new(-5.0, 0.0, 0.0), DVec3::X, 1.0, 2.0).unwrap();
        assert_eq!((s.enter.t, s.exit.t), (4.0, 6.0));
        let s = cylinder(DVec3::new(0.0, 5.0, 0.0), DVec3::NEG_Y, 1.0, 2.0).unwrap();
        assert_eq!((s.enter.t, s.exit.t), (3.0, 7.0));
        assert_eq!(s.enter.normal, DVec3::Y);
    }

    #[test]
    fn torus_through_the_hole_and_the_tube() {
        // Along x through the centre: tube from 1.5..2.5 on both sides (R = 2, r = 0.5).
        let s = torus(DVec3::new(-5.0, 0.0, 0.0), DVec3::X, 2.0, 0.5);
        let ts: Vec<(f64, f64)> = s.iter().map(|s| (s.enter.t, s.exit.t)).collect();
        assert_eq!(ts.len(), 2);
        for ((a, b), (ea, eb)) in ts.iter().zip([(2.5, 3.5), (6.5, 7.5)]) {
            assert!((a - ea).abs() < 1e-12 && (b - eb).abs() < 1e-12, "{ts:?}");
        }
        // Down the axis: nothing.
        assert!(torus(DVec3::new(0.0, 5.0, 0.0), DVec3::NEG_Y, 2.0, 0.5).is_empty());
    }

    #[test]
    fn half_space_both_directions() {
        let s = half_space(DVec3::new(0.0, 2.0, 0.0), DVec3::NEG_Y, DVec3::Y, 0.0).unwrap();
        assert_eq!(s.enter.t, 2.0);
        assert!(s.exit.t.is_infinite());
        let s = half_space(DVec3::new(0.0, -2.0, 0.0), DVec3::Y, DVec3::Y, 0.0).unwrap();
        assert_eq!(s.exit.t, 2.0);
    }

    #[test]
    fn triangle_hit_and_miss() {
        let v = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let (t, u, w, n) = triangle(DVec3::new(0.25, 0.25, -1.0), DVec3::Z, &v).unwrap();
        assert_eq!((t, u, w), (1.0, 0.25, 0.25));
        assert_eq!(n, DVec3::Z);
        assert!(triangle(DVec3::new(0.75, 0.75, -1.0), DVec3::Z, &v).is_none());
    }
}
