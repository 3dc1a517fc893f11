//! A built geometry seen from a camera that has moved since it was built.
//!
//! Backends build in *render space*, centred on the camera of the scene they were built for
//! (`ARCHITECTURE.md`, "Coordinate spaces"). While the camera flies, rebuilding every frame
//! would cost a BVH build per frame on large meshes, so coarse frames trace the geometry
//! built at an earlier camera position (its *anchor*) through [`Offset`]: rays in the current
//! render space are moved by `current - anchor` into the geometry's, hits are moved back. It
//! is an approximation for moving frames only: the shift is rounded to f32, the sdf's
//! pixel-relative epsilon and the mesh's on-screen tessellation budget were set for the
//! anchor, and the reference's exact camera rays are not used. Still frames rebuild at the
//! camera and trace without it, exactly as `marchmesh render` does.

use glam::Vec3;
use marchmesh_core::{
    Cone, Geometry, GeometryReport, OcclusionResult, PrimarySamples, Ray, Shortcuts, SurfacePoint,
    TraceResult, Visibility,
};

/// `inner` (built in the render space of a camera at the anchor) traced from the current
/// render space, `shift = current camera - anchor` (world units, f32).
pub struct Offset<'a> {
    /// The geometry built at the anchor.
    pub inner: &'a dyn Geometry,
    /// Current camera position minus the anchor, world units.
    pub shift: Vec3,
}

impl Offset<'_> {
    fn ray(&self, r: &Ray) -> Ray {
        Ray {
            origin: r.origin + self.shift,
            ..*r
        }
    }

    fn back(&self, t: TraceResult) -> TraceResult {
        match t.hit() {
            Some(mut hit) => {
                hit.position -= self.shift;
                TraceResult::found(hit, t.work)
            }
            None => t,
        }
    }
}

impl Geometry for Offset<'_> {
    fn closest_hit(&self, ray: &Ray) -> TraceResult {
        self.back(self.inner.closest_hit(&self.ray(ray)))
    }

    fn occluded(&self, ray: &Ray) -> OcclusionResult {
        self.inner.occluded(&self.ray(ray))
    }

    fn closest_hits(&self, rays: &[Ray], out: &mut [TraceResult]) {
        let moved: Vec<Ray> = rays.iter().map(|r| self.ray(r)).collect();
        self.inner.closest_hits(&moved, out);
        for t in out.iter_mut() {
            *t = self.back(*t);
        }
    }

    /// The camera samples start at the current camera, not at the geometry's origin, so
    /// they are dropped: the moved f32 rays are traced (see the module docs).
    fn closest_hits_primary(
        &self,
        rays: &[Ray],
        _samples: PrimarySamples<'_>,
        out: &mut [TraceResult],
    ) {
        self.closest_hits(rays, out);
    }

    fn occluded_many(&self, rays: &[Ray], out: &mut [OcclusionResult]) {
        let moved: Vec<Ray> = rays.iter().map(|r| self.ray(r)).collect();
        self.inner.occluded_many(&moved, out);
    }

    fn report(&self) -> GeometryReport {
        self.inner.report()
    }

    fn shortcuts(&self) -> Shortcuts {
        self.inner.shortcuts()
    }

    fn cone_visibility(&self, cones: &[Cone], out: &mut [Visibility]) {
        let moved: Vec<Cone> = cones
            .iter()
            .map(|c| Cone {
                origin: c.origin + self.shift,
                ..*c
            })
            .collect();
        self.inner.cone_visibility(&moved, out);
    }

    fn ambient_openness(&self, points: &[SurfacePoint], distance: f32, out: &mut [Visibility]) {
        let moved: Vec<SurfacePoint> = points
            .iter()
            .map(|p| SurfacePoint {
                position: p.position + self.shift,
                ..*p
            })
            .collect();
        self.inner.ambient_openness(&moved, distance, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use marchmesh_registry::{self as backend, BackendId, BackendSpec};

    #[test]
    fn a_shifted_geometry_hits_what_a_rebuilt_one_hits() {
        let at = |z: f64| {
            marchmesh_testkit::scene(&format!(
                r#"{{"camera": {{"position": [0, 0, {z}], "look_at": [0, 0, 10], "width": 16, "height": 16}},
                    "objects": [{{"shape": {{"sphere": {{"radius": 1}}}}, "transform": {{"translate": [0, 0, 5]}}}}]}}"#
            ))
        };
        let spec = BackendSpec {
            kind: BackendId::REFERENCE,
            options: vec![],
        };
        let anchor = backend::build(&at(0.0), &spec).expect("build");
        let rebuilt = backend::build(&at(1.0), &spec).expect("build");
        let shifted = Offset {
            inner: anchor.as_ref(),
            shift: Vec3::new(0.0, 0.0, 1.0),
        };
        let ray = Ray {
            origin: Vec3::ZERO,
            dir: Vec3::new(0.1, 0.05, 1.0).normalize(),
            t_min: 0.0,
            t_max: 100.0,
        };
        let (a, b) = (shifted.closest_hit(&ray), rebuilt.closest_hit(&ray));
        let (a, b) = (a.hit().expect("hit"), b.hit().expect("hit"));
        assert!((a.t - b.t).abs() < 1e-5, "{a:?} {b:?}");
        assert!((a.position - b.position).length() < 1e-5, "{a:?} {b:?}");
        let mut many = [TraceResult::default(); 1];
        shifted.closest_hits(&[ray], &mut many);
        assert_eq!(many[0].hit().map(|h| h.t), Some(a.t));
        let occ = shifted.occluded(&Ray { t_max: 3.0, ..ray });
        assert!(!occ.occluded, "the sphere starts ~3 units away");
    }
}
