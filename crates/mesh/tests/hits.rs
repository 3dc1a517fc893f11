//! Hits of the mesh backend against independent answers: analytic spheres, a brute-force
//! f64 ray caster over the bunny, flattened versus instanced geometry, Bvh2 versus CwBvh.

mod common;

use common::*;
use glam::DVec3;
use marchmesh_core::Geometry;
use marchmesh_mesh::{BvhKind, MeshOptions, Tessellation, build};

#[test]
fn sphere_hits_match_the_analytic_sphere_within_the_chord_budget() {
    let s = scene(
        r#"{"camera": {"position": [0, 1.5, -5], "look_at": [0, 0, 0], "vfov_deg": 40, "width": 64, "height": 64},
            "objects": [{"shape": {"sphere": {"radius": 1}}, "transform": {"translate": [0.2, 0, 0]}}]}"#,
    );
    let budget = 1e-3;
    let g = build(
        &s,
        &MeshOptions {
            tessellation: Tessellation::ChordError { world: budget },
            ..MeshOptions::DEFAULT
        },
    )
    .expect("build");
    let cam = s.camera.position;
    let mut hits = 0;
    for ray in camera_rays(&s, 48) {
        let r = g.closest_hit(&ray);
        let exact = ray_sphere(
            DVec3::ZERO,
            ray.dir.as_dvec3(),
            DVec3::new(0.2, 0.0, 0.0) - cam,
            1.0,
        );
        match (r.hit, exact) {
            (Some(h), Some(t)) => {
                hits += 1;
                // The mesh lies inside the sphere, within the chord budget of it.
                let err = f64::from(h.t) - t;
                let cos = (ray
                    .dir
                    .as_dvec3()
                    .dot(-(h.position.as_dvec3() - (DVec3::new(0.2, 0.0, 0.0) - cam)).normalize()))
                .abs();
                assert!(
                    err > -1e-4 && err * cos < budget * 1.01 + 1e-4,
                    "t error {err} (cos {cos})"
                );
                let exact_n =
                    (h.position.as_dvec3() - (DVec3::new(0.2, 0.0, 0.0) - cam)).normalize();
                assert!(
                    h.normal.as_dvec3().dot(exact_n) > 0.999,
                    "normal {:?} vs {exact_n:?}",
                    h.normal
                );
            }
            (None, None) => {}
            // Silhouette pixels may differ by the chord error.
            (a, b) => {
                let d = ray.dir.as_dvec3();
                let oc = -(DVec3::new(0.2, 0.0, 0.0) - cam);
                let miss_distance = (oc - d * oc.dot(d)).length();
                assert!(
                    (miss_distance - 1.0).abs() < 2.0 * budget,
                    "hit mismatch {a:?} {b:?} at {miss_distance}"
                );
            }
        }
    }
    assert!(hits > 300, "{hits}");
}
