//! Point-triangle geometry: closest point (Ericson, *Real-Time Collision Detection*, 5.1.5)
//! and the signed solid angle of a triangle (Van Oosterom & Strackee 1983).

use glam::{DVec3, Vec3};

macro_rules! closest_point_impl {
    ($name:ident, $seg:ident, $edges:ident, $v:ty, $s:ty) => {
        /// The point of triangle `(a, b, c)` closest to `p` (Ericson's Voronoi-region
        /// routine; the face case projects onto the plane, which stays accurate for thin
        /// triangles). Triangles thinner than `sin(angle at a) < 1e-3` (including
        /// zero-area ones) use the closest point on their three edges, at most their
        /// inradius (`<= 1e-3` of the shorter side at `a`) from the exact answer. Always
        /// finite for finite input.
        #[inline]
        pub fn $name(p: $v, a: $v, b: $v, c: $v) -> $v {
            let ab = b - a;
            let ac = c - a;
            let ap = p - a;
            let n = ab.cross(ac);
            let n2 = n.length_squared();
            if n2.is_nan() || n2 <= 1e-6 * ab.length_squared() * ac.length_squared() {
                return $edges(p, a, b, c);
            }
            let d1 = ab.dot(ap);
            let d2 = ac.dot(ap);
            if d1 <= 0.0 && d2 <= 0.0 {
                return a;
            }
            let bp = p - b;
            let d3 = ab.dot(bp);
            let d4 = ac.dot(bp);
            if d3 >= 0.0 && d4 <= d3 {
                return b;
            }
            let vc = d1 * d4 - d3 * d2;
            if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
                let den = d1 - d3;
                if den > 0.0 {
                    return a + ab * (d1 / den);
                }
            }
            let cp = p - c;
            let d5 = ab.dot(cp);
            let d6 = ac.dot(cp);
            if d6 >= 0.0 && d5 <= d6 {
                return c;
            }
            let vb = d5 * d2 - d1 * d6;
            if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
                let den = d2 - d6;
                if den > 0.0 {
                    return a + ac * (d2 / den);
                }
            }
            let va = d3 * d6 - d5 * d4;
            if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
                let den = (d4 - d3) + (d5 - d6);
                if den > 0.0 {
                    return b + (c - b) * ((d4 - d3) / den);
                }
            }
            // Face region: project onto the plane.
            let q = p - n * (n.dot(ap) / n2);
            if q.is_finite() {
                return q;
            }
            $edges(p, a, b, c)
        }

        /// Nearest of the three edges' closest points.
        #[inline]
        fn $edges(p: $v, a: $v, b: $v, c: $v) -> $v {
            let e0 = $seg(p, a, b);
            let e1 = $seg(p, b, c);
            let e2 = $seg(p, c, a);
            let (d0, d1, d2) = (
                (p - e0).length_squared(),
                (p - e1).length_squared(),
                (p - e2).length_squared(),
            );
            if d0 <= d1 && d0 <= d2 {
                e0
            } else if d1 <= d2 {
                e1
            } else {
                e2
            }
        }

        #[inline]
        fn $seg(p: $v, a: $v, b: $v) -> $v {
            let ab = b - a;
            let l2 = ab.length_squared();
            if l2 <= 0.0 {
                return a;
            }
            let t: $s = (ab.dot(p - a) / l2).clamp(0.0, 1.0);
            a + ab * t
        }
    };
}

closest_point_impl!(
    closest_point_on_triangle,
    closest_on_segment,
    closest_on_edges,
    Vec3,
    f32
);
closest_point_impl!(
    closest_point_on_triangle_f64,
    closest_on_segment_f64,
    closest_on_edges_f64,
    DVec3,
    f64
);

/// Squared distance from `p` to triangle `(a, b, c)` (f32).
#[inline]
pub fn point_triangle_distance_squared(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f32 {
    (p - closest_point_on_triangle(p, a, b, c)).length_squared()
}

/// Signed solid angle (steradians, in `[-2pi, 2pi]`) subtended at `p` by triangle
/// `(a, b, c)`: positive when `p` is behind the triangle (on the side its counter-clockwise
/// normal points away from). Summed over a closed outward-oriented mesh it is `4pi` inside
/// and `0` outside. 0 for `p` in the triangle's plane outside it; finite for all finite input.
#[inline]
pub fn solid_angle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f32 {
    let (a, b, c) = (a - p, b - p, c - p);
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let num = a.dot(b.cross(c));
    let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    2.0 * num.atan2(den)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_of_a_right_triangle() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        // Face interior.
        let q = closest_point_on_triangle(Vec3::new(0.25, 0.25, 2.0), a, b, c);
        assert!((q - Vec3::new(0.25, 0.25, 0.0)).length() < 1e-6);
        // Vertex regions.
        assert_eq!(
            closest_point_on_triangle(Vec3::new(-1.0, -1.0, 0.3), a, b, c),
            a
        );
        assert_eq!(
            closest_point_on_triangle(Vec3::new(2.0, -0.1, 0.0), a, b, c),
            b
        );
        assert_eq!(
            closest_point_on_triangle(Vec3::new(-0.1, 2.0, 0.0), a, b, c),
            c
        );
        // Edge regions.
        let q = closest_point_on_triangle(Vec3::new(0.5, -1.0, 0.0), a, b, c);
        assert!((q - Vec3::new(0.5, 0.0, 0.0)).length() < 1e-6);
        let q = closest_point_on_triangle(Vec3::new(1.0, 1.0, 0.0), a, b, c);
        assert!((q - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-6);
        let q = closest_point_on_triangle(Vec3::new(-1.0, 0.5, 0.0), a, b, c);
        assert!((q - Vec3::new(0.0, 0.5, 0.0)).length() < 1e-6);
    }

    #[test]
    fn degenerate_triangles_are_finite() {
        let a = Vec3::ZERO;
        let b = Vec3::new(1.0, 1.0, 1.0);
        let c = Vec3::new(2.0, 2.0, 2.0);
        let p = Vec3::new(3.0, 0.0, 0.0);
        let q = closest_point_on_triangle(p, a, b, c);
        assert!(q.is_finite());
        // Closest point on the segment a..c.
        let t = (p.dot(c) / c.length_squared()).clamp(0.0, 1.0);
        assert!((q - c * t).length() < 1e-5, "{q}");
        let q = closest_point_on_triangle(p, a, a, a);
        assert_eq!(q, a);
    }

    #[test]
    fn solid_angle_of_a_closed_tetrahedron() {
        // Outward CCW tetrahedron.
        let v = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        ];
        let f = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let total = |p: Vec3| -> f32 {
            f.iter()
                .map(|t| solid_angle(p, v[t[0]], v[t[1]], v[t[2]]))
                .sum()
        };
        let inside = total(Vec3::splat(0.1));
        assert!(
            (inside - 4.0 * std::f32::consts::PI).abs() < 1e-4,
            "{inside}"
        );
        let outside = total(Vec3::new(2.0, 1.0, -0.5));
        assert!(outside.abs() < 1e-4, "{outside}");
    }
}
