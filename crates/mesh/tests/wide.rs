//! The 8-wide SIMD layout (`bvh=wide`) against the Bvh2 path it is converted from: the same
//! closest-hit distance bit for bit and the same occlusion on every conformance case and the
//! bunny, and no ray slipping between the triangles of closed meshes.

use glam::{DVec3, Vec3};
use marchmesh_core::{Geometry, Ray};
use marchmesh_mesh::{BvhKind, MeshOptions, build};
use marchmesh_scene::Scene;
use marchmesh_testkit::*;

fn both(scene: &Scene, options: MeshOptions) -> (impl Geometry, impl Geometry) {
    let bvh2 = build(
        scene,
        &MeshOptions {
            bvh: Some(BvhKind::Bvh2),
            ..options
        },
    )
    .expect("bvh2 build");
    let wide = build(
        scene,
        &MeshOptions {
            bvh: Some(BvhKind::Wide),
            ..options
        },
    )
    .expect("wide build");
    (bvh2, wide)
}

/// Asserts identical hit distances (bits), materials and occlusion; returns the hit count.
fn assert_identical(a: &dyn Geometry, b: &dyn Geometry, rays: &[Ray], label: &str) -> usize {
    let mut hits = 0;
    for (k, ray) in rays.iter().enumerate() {
        let (x, y) = (a.closest_hit(ray).hit(), b.closest_hit(ray).hit());
        match (x, y) {
            (Some(x), Some(y)) => {
                hits += 1;
                assert_eq!(
                    x.t.to_bits(),
                    y.t.to_bits(),
                    "{label} ray {k}: t {} vs {}",
                    x.t,
                    y.t
                );
                // Ties between triangles at the same t (shared edges) may pick another
                // triangle of the same surface: same material, close normal.
                assert_eq!(x.material, y.material, "{label} ray {k}: material");
                assert!(
                    x.normal.dot(y.normal) > 0.9,
                    "{label} ray {k}: normals {:?} vs {:?}",
                    x.normal,
                    y.normal
                );
            }
            (None, None) => {}
            (x, y) => panic!("{label} ray {k}: bvh2 {x:?} vs wide {y:?}"),
        }
        for t_max in [0.5, 3.0, 8.0] {
            let shadow = Ray { t_max, ..*ray };
            assert_eq!(
                a.occluded(&shadow).occluded,
                b.occluded(&shadow).occluded,
                "{label} ray {k}: occlusion before {t_max}"
            );
        }
    }
    hits
}

#[test]
fn wide_matches_bvh2_on_every_conformance_case() {
    let mut total = 0;
    for case in marchmesh_conformance::CASES {
        let scene = marchmesh_conformance::case_scene(case.id);
        let (bvh2, wide) = both(&scene, MeshOptions::fast());
        total += assert_identical(&bvh2, &wide, &camera_rays(&scene, 48), case.name);
    }
    assert!(total > 1000, "the suite should hit something: {total} hits");
}

#[test]
fn wide_matches_bvh2_on_the_bunny_at_every_build_preset() {
    let s = scene(
        r#"{"camera": {"position": [0.02, 0.12, 0.35], "look_at": [-0.02, 0.1, 0], "vfov_deg": 40},
            "objects": [{"shape": {"mesh": {"path": "meshes/bunny.obj"}}}]}"#,
    );
    for quality in [
        marchmesh_mesh::BuildQuality::Fastest,
        marchmesh_mesh::BuildQuality::Medium,
        marchmesh_mesh::BuildQuality::Tuned,
        marchmesh_mesh::BuildQuality::Slow,
    ] {
        let (bvh2, wide) = both(
            &s,
            MeshOptions {
                build: Some(quality),
                ..MeshOptions::default()
            },
        );
        let hits = assert_identical(&bvh2, &wide, &camera_rays(&s, 80), &format!("{quality:?}"));
        assert!(
            hits > 1000,
            "{quality:?}: bunny should fill the view: {hits} hits"
        );
    }
}

#[test]
fn no_ray_slips_between_the_triangles_of_a_closed_sphere() {
    // Rays from all around aimed at points inside a finely tessellated closed sphere must all
    // hit it, including those through vertices and along edges.
    let s = scene(
        r#"{"camera": {"position": [0, 0, -4], "look_at": [0, 0, 0], "vfov_deg": 40},
            "objects": [{"shape": {"sphere": {"radius": 1}}}]}"#,
    );
    let g = build(
        &s,
        &MeshOptions {
            bvh: Some(BvhKind::Wide),
            tess_level: Some(3),
            ..MeshOptions::default()
        },
    )
    .expect("build");
    let eye = DVec3::new(0.0, 0.0, -4.0); // render space origin is the camera
    let mut missed = 0;
    let n = 60;
    for i in 0..n {
        for j in 0..n {
            // Targets on a grid inside the sphere's silhouette (radius 0.95 around centre).
            let x = (f64::from(i) / f64::from(n - 1) - 0.5) * 1.3;
            let y = (f64::from(j) / f64::from(n - 1) - 0.5) * 1.3;
            let target = DVec3::new(x, y, 0.0) - eye;
            let ray = Ray {
                origin: Vec3::ZERO,
                dir: target.normalize().as_vec3(),
                t_min: 0.0,
                t_max: f32::INFINITY,
            };
            if g.closest_hit(&ray).hit().is_none() {
                missed += 1;
            }
        }
    }
    assert_eq!(missed, 0, "{missed} rays slipped through the closed sphere");
}

#[test]
fn packets_match_single_rays_on_every_conformance_case_and_the_bunny() {
    let mut scenes: Vec<Scene> = marchmesh_conformance::CASES
        .iter()
        .map(|c| marchmesh_conformance::case_scene(c.id))
        .collect();
    scenes.push(scene(
        r#"{"camera": {"position": [0.02, 0.12, 0.35], "look_at": [-0.02, 0.1, 0], "vfov_deg": 40},
            "objects": [{"shape": {"mesh": {"path": "meshes/bunny.obj"}}}]}"#,
    ));
    let mut hits = 0;
    for (i, s) in scenes.iter().enumerate() {
        let options = MeshOptions {
            bvh: Some(BvhKind::Wide),
            packets: Some(false),
            ..MeshOptions::fast()
        };
        let single = build(s, &options).expect("build");
        let packets = build(
            s,
            &MeshOptions {
                packets: Some(true),
                ..options
            },
        )
        .expect("build");
        // Row batches of 61 rays: 7 packets and a remainder of 5 traced one by one.
        let rays = camera_rays(s, 61);
        let mut out = vec![marchmesh_core::TraceResult::default(); rays.len()];
        for (r, o) in rays.chunks(61).zip(out.chunks_mut(61)) {
            packets.closest_hits(r, o);
        }
        for (k, (ray, p)) in rays.iter().zip(&out).enumerate() {
            let one = single.closest_hit(ray).hit();
            match (one, p.hit()) {
                (Some(a), Some(b)) => {
                    hits += 1;
                    assert_eq!(a.t.to_bits(), b.t.to_bits(), "scene {i} ray {k}");
                    assert_eq!(a.material, b.material, "scene {i} ray {k}");
                }
                (None, None) => {}
                (a, b) => panic!("scene {i} ray {k}: single {a:?} vs packet {b:?}"),
            }
        }
    }
    assert!(hits > 1000, "the scenes should hit something: {hits} hits");
}

#[test]
fn interleaved_batches_match_single_rays_on_a_large_mesh() {
    // 262k triangles: a wide BVH above the interleaving threshold.
    let s = scene(
        r#"{"camera": {"position": [0, 0, -3], "look_at": [0, 0, 0], "vfov_deg": 50},
            "objects": [{"shape": {"sphere": {"radius": 1}}},
                        {"shape": {"box": {"half_extents": [0.3, 0.3, 0.3]}}, "transform": {"translate": [0.9, 0.6, -0.8]}}]}"#,
    );
    let g = build(
        &s,
        &MeshOptions {
            bvh: Some(BvhKind::Wide),
            tess_level: Some(6),
            ..MeshOptions::default()
        },
    )
    .expect("build");
    assert!(
        g.report().notes.iter().any(|n| n.contains("interleaved")),
        "interleaving should be on: {:?}",
        g.report().notes
    );
    let mut rays = camera_rays(&s, 48);
    // An empty interval and a short one among them.
    rays[5].t_max = -1.0;
    rays[9].t_max = 2.5;
    let mut out = vec![marchmesh_core::TraceResult::default(); rays.len()];
    for (r, o) in rays.chunks(48).zip(out.chunks_mut(48)) {
        g.closest_hits(r, o);
    }
    let mut hits = 0;
    for (k, (ray, batch)) in rays.iter().zip(&out).enumerate() {
        let one = g.closest_hit(ray);
        assert_eq!(one.work, batch.work, "ray {k}: work");
        match (one.hit(), batch.hit()) {
            (Some(a), Some(b)) => {
                hits += 1;
                assert_eq!(a.t.to_bits(), b.t.to_bits(), "ray {k}");
                assert_eq!(a.normal, b.normal, "ray {k}");
                assert_eq!(a.material, b.material, "ray {k}");
            }
            (None, None) => {}
            (a, b) => panic!("ray {k}: single {a:?} vs batch {b:?}"),
        }
    }
    assert!(
        hits > 1000,
        "the sphere should fill much of the view: {hits} hits"
    );
}

#[test]
fn batches_answer_each_incoherent_ray_as_if_alone() {
    // Rays around the bunny in every direction octant, in one batch longer than a run the
    // batch queries reorder by octant (and not a multiple of a packet): each answer and its
    // work equal the single-ray query's.
    let s = scene(
        r#"{"camera": {"position": [0.02, 0.12, 0.35], "look_at": [-0.02, 0.1, 0], "vfov_deg": 40},
            "objects": [{"shape": {"mesh": {"path": "meshes/bunny.obj"}}}]}"#,
    );
    let g = build(
        &s,
        &MeshOptions {
            bvh: Some(BvhKind::Wide),
            ..MeshOptions::default()
        },
    )
    .expect("build");
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut unit = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 40) as f32) / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    // The bunny's centre in render space (world minus the camera position).
    let centre = Vec3::new(-0.037, -0.02, -0.35);
    let rays: Vec<Ray> = (0..601)
        .map(|k| {
            let origin = centre + Vec3::new(unit(), unit(), unit()) * 0.1;
            let dir = Vec3::new(unit(), unit(), unit()).normalize_or(Vec3::X);
            let t_max = if k % 3 == 0 { 0.05 } else { f32::INFINITY };
            Ray {
                origin,
                dir,
                t_min: 0.0,
                t_max,
            }
        })
        .collect();
    let mut closest = vec![marchmesh_core::TraceResult::default(); rays.len()];
    let mut occluded = vec![marchmesh_core::OcclusionResult::default(); rays.len()];
    g.closest_hits(&rays, &mut closest);
    g.occluded_many(&rays, &mut occluded);
    let (mut hits, mut blocked) = (0, 0);
    for (k, ray) in rays.iter().enumerate() {
        let one = g.closest_hit(ray);
        assert_eq!(one.work, closest[k].work, "ray {k}: work");
        match (one.hit(), closest[k].hit()) {
            (Some(a), Some(b)) => {
                hits += 1;
                assert_eq!(a.t.to_bits(), b.t.to_bits(), "ray {k}");
                assert_eq!(a.normal, b.normal, "ray {k}");
                assert_eq!(a.material, b.material, "ray {k}");
            }
            (None, None) => {}
            (a, b) => panic!("ray {k}: single {a:?} vs batch {b:?}"),
        }
        let alone = g.occluded(ray);
        assert_eq!(alone.occluded, occluded[k].occluded, "ray {k}: occlusion");
        assert_eq!(alone.work, occluded[k].work, "ray {k}: occlusion work");
        blocked += usize::from(alone.occluded);
    }
    assert!(
        hits > 100 && blocked > 50,
        "{hits} hits, {blocked} occluded: the rays must reach the bunny"
    );
}
