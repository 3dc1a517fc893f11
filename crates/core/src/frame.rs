//! Local frames of objects far from the camera.
//!
//! Render space is centred on the camera, so f32 keeps its precision near the camera, but an
//! object `D` units away sits where an f32 step is `D * 2^-24` (0.06 units at 1e6): its
//! vertices, its distance field's translation and every sample point of a ray reaching it are
//! rounded to that grid, which breaks silhouettes and normals once the step nears a pixel.
//! A backend gives such an object a frame of its own, centred on it, and a ray enters that
//! frame through f64: the ray is advanced in f64 to the object's bounding sphere
//! ([`FarFrame::enter`]), the start point is expressed relative to the frame's origin in f64
//! and only then rounded to f32 (small, near the object), the backend traces from there in
//! f32, and the hit's ray parameter is reassembled in f64 ([`FrameEntry::render_t`]). The
//! two f32 backends share this logic; each decides which of its objects are far with
//! [`FarFrame::of_box`].

use glam::{DVec3, Vec3};

use crate::geometry::Ray;

/// An object whose bounding sphere's centre lies more than this many radii from the camera
/// is far: in render space its f32 rounding would exceed `FAR_RATIO * 2^-24` (6e-5) of its
/// size. Nearer objects stay in render space.
pub const FAR_RATIO: f64 = 1024.0;

/// The bounding sphere (render space, f64) of an object far from the camera, traced in a
/// frame of its own.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FarFrame {
    centre: DVec3,
    radius: f64,
}

/// Where a ray enters a [`FarFrame`]: the f64 start point and the ray's interval measured
/// from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameEntry {
    /// Ray parameter (render space) of the start: the entry into the bounding sphere, or 0
    /// when the ray starts inside it.
    pub t0: f64,
    /// The start point, render space, f64.
    pub start: DVec3,
    /// The ray's `t_min`, measured from the start (>= 0).
    pub t_min: f32,
    /// The ray's `t_max`, measured from the start.
    pub t_max: f32,
}

impl FarFrame {
    /// The frame of an object whose render-space bounds are `(lo, hi)`, or `None` when the
    /// object is not far (its sphere's centre within [`FAR_RATIO`] radii of the camera), the
    /// box is empty or not finite. The sphere is the box's circumscribed sphere, padded by a
    /// relative 1e-6 so that f32 rounding of the object never leaves it.
    pub fn of_box(lo: DVec3, hi: DVec3) -> Option<Self> {
        if !(lo.is_finite() && hi.is_finite() && lo.cmple(hi).all()) {
            return None;
        }
        let centre = (lo + hi) * 0.5;
        let half = (hi - lo).length() * 0.5;
        let radius = half * (1.0 + 1e-6) + centre.length() * 1e-12 + f64::MIN_POSITIVE;
        (centre.length() > FAR_RATIO * radius).then_some(Self { centre, radius })
    }

    /// The sphere's centre, render space.
    pub fn centre(&self) -> DVec3 {
        self.centre
    }

    /// The sphere's radius.
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// Distance from the camera (the render-space origin) to the sphere's centre.
    pub fn distance(&self) -> f64 {
        self.centre.length()
    }

    /// Where the ray from `origin` along `dir` (render space; `dir` need not be unit: the ray
    /// parameter is along `dir` as given) with interval `[t_min, t_max]` enters the sphere,
    /// computed in f64; `None` when it misses the sphere within its interval (or any input
    /// is NaN). A primary ray should pass its exact f64 direction
    /// ([`crate::PrimarySamples::direction`]): over the lever arm to a far object the f32
    /// rounding of a direction moves the start by `D * 2^-24`.
    pub fn enter(&self, origin: Vec3, dir: DVec3, t_min: f32, t_max: f32) -> Option<FrameEntry> {
        let o = origin.as_dvec3();
        let dd = dir.length_squared();
        if dd.is_nan() || dd <= 0.0 {
            return None;
        }
        let tc = (self.centre - o).dot(dir) / dd;
        let off = o + dir * tc - self.centre;
        let h2 = self.radius * self.radius - off.length_squared();
        if h2.is_nan() || h2 < 0.0 {
            return None;
        }
        let h = (h2 / dd).sqrt();
        let (t_in, t_out) = (tc - h, tc + h);
        let (lo, hi) = (f64::from(t_min.max(0.0)), f64::from(t_max));
        if !(t_out >= lo && t_in <= hi) {
            return None;
        }
        let t0 = t_in.max(0.0);
        Some(FrameEntry {
            t0,
            start: o + dir * t0,
            t_min: (lo - t0).max(0.0) as f32,
            t_max: (hi - t0) as f32,
        })
    }
}

impl FrameEntry {
    /// The render-space ray parameter of `t_local`, a parameter measured from the start,
    /// added in f64 and rounded once.
    #[inline]
    pub fn render_t(&self, t_local: f32) -> f32 {
        (self.t0 + f64::from(t_local)) as f32
    }

    /// The ray from the start in a frame whose origin is `frame_origin` (render space): the
    /// start minus `frame_origin` in f64, then rounded to f32; `dir` as given.
    pub fn local_ray(&self, frame_origin: DVec3, dir: Vec3) -> Ray {
        Ray {
            origin: (self.start - frame_origin).as_vec3(),
            dir,
            t_min: self.t_min,
            t_max: self.t_max,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_sphere_at(d: DVec3) -> FarFrame {
        FarFrame::of_box(d - DVec3::ONE, d + DVec3::ONE).expect("far")
    }

    #[test]
    fn near_and_degenerate_boxes_get_no_frame() {
        assert!(FarFrame::of_box(DVec3::splat(-1.0), DVec3::ONE).is_none());
        let d = DVec3::new(0.0, 0.0, 1000.0);
        assert!(FarFrame::of_box(d - DVec3::ONE, d + DVec3::ONE).is_none());
        assert!(FarFrame::of_box(DVec3::ONE, DVec3::ZERO).is_none());
        assert!(FarFrame::of_box(DVec3::ZERO, DVec3::splat(f64::INFINITY)).is_none());
        assert!(FarFrame::of_box(DVec3::splat(f64::NAN), DVec3::ONE).is_none());
        let far = DVec3::new(0.0, 0.0, 1e4);
        assert!(FarFrame::of_box(far - DVec3::ONE, far + DVec3::ONE).is_some());
    }

    #[test]
    fn a_ray_missing_the_sphere_or_outside_its_interval_does_not_enter() {
        let f = unit_sphere_at(DVec3::new(0.0, 0.0, 1e6));
        assert!(f.enter(Vec3::ZERO, DVec3::X, 0.0, f32::INFINITY).is_none());
        assert!(f.enter(Vec3::ZERO, DVec3::Z, 0.0, 1e5).is_none());
        assert!(f.enter(Vec3::ZERO, -DVec3::Z, 0.0, f32::INFINITY).is_none());
        assert!(f.enter(Vec3::ZERO, DVec3::ZERO, 0.0, 1.0).is_none());
        assert!(f.enter(Vec3::ZERO, DVec3::Z, 0.0, f32::NAN).is_none());
    }

    /// A hit 1e6 (and 1e7) units away, found in the frame in f32 and reassembled, lands
    /// within an f32 ulp of the f64 truth, where the same hit computed in render space f32
    /// is off by up to half an f32 step there (0.03 units).
    #[test]
    fn a_far_hit_reassembled_from_the_frame_is_within_an_f32_ulp_of_the_truth() {
        for d in [1e6, 1e7] {
            let c = DVec3::new(0.3, -0.2, d);
            let f = unit_sphere_at(c);
            let mut seed = 7u64;
            let mut checked = 0;
            for _ in 0..2000 {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let u = ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0;
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let v = ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0;
                // Exact f64 direction to a point near the sphere's silhouette.
                let target = c + DVec3::new(u, v, 0.0) * 1.2;
                let dir = target.normalize();
                // Truth: ray-sphere (radius 1 about c) in f64.
                let tc = c.dot(dir);
                let off = dir * tc - c;
                let h2 = 1.0 - off.length_squared();
                let Some(e) = f.enter(Vec3::ZERO, dir, 0.0, f32::INFINITY) else {
                    assert!(h2 < 0.0, "a ray hitting the sphere enters its frame");
                    continue;
                };
                if h2 < 1e-6 {
                    continue;
                }
                let t_true = tc - h2.sqrt();
                // The same intersection in the frame, in f32.
                let r = e.local_ray(c, dir.as_vec3());
                let (o, dl) = (r.origin, r.dir);
                let b = o.dot(dl);
                let cc = o.length_squared() - 1.0;
                let disc = b * b - cc;
                assert!(disc > 0.0);
                let t_local = -b - disc.sqrt();
                let t = e.render_t(t_local);
                let ulp = f64::from(f32::EPSILON) * t_true;
                assert!(
                    (f64::from(t) - t_true).abs() <= 2.0 * ulp,
                    "d {d}: t {t} vs {t_true}"
                );
                let p_local = o + dl * t_local;
                let p_true = dir * t_true - c;
                assert!(
                    (p_local.as_dvec3() - p_true).length() <= 1e-5,
                    "d {d}: hit point in the frame {p_local} vs {p_true}"
                );
                checked += 1;
            }
            assert!(checked > 500, "{checked}");
        }
    }

    #[test]
    fn an_interval_is_measured_from_the_start() {
        let f = unit_sphere_at(DVec3::new(0.0, 0.0, 5e6));
        let e = f.enter(Vec3::ZERO, DVec3::Z, 1.0, 6e6).expect("enters");
        assert!(
            (e.t0 - (5e6 - 3f64.sqrt() * (1.0 + 1e-6))).abs() < 1e-3,
            "{}",
            e.t0
        );
        assert_eq!(e.t_min, 0.0);
        assert!((f64::from(e.t_max) - (6e6 - e.t0)).abs() < 0.1);
        // A ray starting inside the sphere starts where it is.
        let inside = f.enter(Vec3::new(0.0, 0.0, 5e6), DVec3::Y, 0.0, 10.0);
        let inside = inside.expect("enters");
        assert_eq!(inside.t0, 0.0);
        assert_eq!(inside.start, DVec3::new(0.0, 0.0, 5e6));
        assert_eq!(inside.local_ray(f.centre(), Vec3::Y).origin, Vec3::ZERO);
    }
}
