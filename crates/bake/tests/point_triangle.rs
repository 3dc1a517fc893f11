//! Property tests of the point-triangle distance (Ericson) against brute-force sampling of
//! the triangle, and of the solid angle's sign.

use glam::{DVec3, Vec3};
use marchmesh_bake::{
    closest_point_on_triangle, closest_point_on_triangle_f64, point_triangle_distance_squared,
    solid_angle,
};
use proptest::prelude::*;

fn v3() -> impl Strategy<Value = Vec3> {
    (-2.0f32..2.0, -2.0f32..2.0, -2.0f32..2.0).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// Minimum distance from `p` to `n(n+1)/2`-ish barycentric samples of the triangle, and the
/// sample spacing (every triangle point is within `spacing` of a sample).
fn sampled(p: DVec3, a: DVec3, b: DVec3, c: DVec3, n: usize) -> (f64, f64) {
    let mut best = f64::INFINITY;
    for i in 0..=n {
        for j in 0..=n - i {
            let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
            let q = a + (b - a) * u + (c - a) * v;
            best = best.min((p - q).length());
        }
    }
    let spacing = ((b - a).length() + (c - a).length()) / n as f64;
    (best, spacing)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn distance_matches_sampling(p in v3(), a in v3(), b in v3(), c in v3()) {
        let d = point_triangle_distance_squared(p, a, b, c).sqrt() as f64;
        let (pd, ad, bd, cd) = (p.as_dvec3(), a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
        let (best, spacing) = sampled(pd, ad, bd, cd, 60);
        // Never farther than any point of the triangle, never much nearer than the samples.
        prop_assert!(d <= best + 1e-4, "d {d} > sampled {best}");
        prop_assert!(d >= best - spacing - 1e-4, "d {d} << sampled {best} (spacing {spacing})");
        // The closest point lies on the triangle and realises the distance.
        let q = closest_point_on_triangle(p, a, b, c);
        prop_assert!(q.is_finite());
        prop_assert!(point_triangle_distance_squared(q, a, b, c).sqrt() < 1e-4);
        prop_assert!(((p - q).length() as f64 - d).abs() < 1e-5);
        // f64 routine agrees.
        let q64 = closest_point_on_triangle_f64(pd, ad, bd, cd);
        prop_assert!(((pd - q64).length() - d).abs() < 1e-4 * (1.0 + d));
    }

    #[test]
    fn degenerate_triangles_stay_finite(p in v3(), a in v3(), b in v3(), t in -1.0f32..2.0) {
        // c on the line through a and b: zero area.
        let c = a + (b - a) * t;
        let q = closest_point_on_triangle(p, a, b, c);
        prop_assert!(q.is_finite());
        let d = (p - q).length() as f64;
        let (best, spacing) = sampled(p.as_dvec3(), a.as_dvec3(), b.as_dvec3(), c.as_dvec3(), 60);
        prop_assert!(d <= best + 1e-4 && d >= best - spacing - 1e-4, "{d} vs {best}");
    }

    #[test]
    fn thin_triangles_accurate(
        p in v3(), a in v3(), b in v3(), t in -1.0f32..2.0, e in 1e-4f32..1e-1, side in v3()
    ) {
        let ab = b - a;
        prop_assume!(ab.length() > 0.1);
        let perp = side.cross(ab);
        prop_assume!(perp.length() > 1e-2);
        let c = a + ab * t + perp.normalize() * e * ab.length();
        let q = closest_point_on_triangle(p, a, b, c);
        let d = (p - q).length() as f64;
        let (best, spacing) = sampled(p.as_dvec3(), a.as_dvec3(), b.as_dvec3(), c.as_dvec3(), 60);
        // Exact up to the documented sliver allowance (1e-3 of the shorter side at a).
        let allow = 1e-3 * (ab.length().min((c - a).length())) as f64 + 1e-4;
        prop_assert!(d <= best + allow && d >= best - spacing - 1e-4, "{d} vs {best}");
    }

    #[test]
    fn solid_angle_sign_follows_the_side(a in v3(), b in v3(), c in v3(), h in 0.01f32..1.0) {
        let n = (b - a).cross(c - a);
        prop_assume!(n.length() > 1e-2);
        let centroid = (a + b + c) / 3.0;
        let nn = n.normalize();
        let behind = solid_angle(centroid - nn * h, a, b, c);
        let front = solid_angle(centroid + nn * h, a, b, c);
        prop_assert!(behind > 0.0 && front < 0.0, "{behind} {front}");
        prop_assert!((behind + front).abs() < 1e-3, "{behind} {front}");
        prop_assert!(behind <= 2.0 * std::f32::consts::PI + 1e-4);
    }
}
