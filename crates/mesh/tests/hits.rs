//! Hits of the mesh backend against independent answers: analytic spheres, a brute-force
//! f64 ray caster over the bunny, flattened versus instanced geometry, Bvh2 versus CwBvh.

use glam::DVec3;
use marchmesh_core::Geometry;
use marchmesh_mesh::{BvhKind, MeshOptions, build};
use marchmesh_testkit::*;

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
            tess_chord: Some(budget),
            ..MeshOptions::default()
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
        match (r.hit(), exact) {
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

const BUNNY: &str = r#"{"camera": {"position": [0, 2, -5.5], "look_at": [0, 1.2, 0], "vfov_deg": 40, "width": 64, "height": 64},
    "objects": [{"shape": {"mesh": {"path": "meshes/bunny.obj"}}, "transform": {"scale": 0.25, "rotate_deg": [0, 30, 0]}}]}"#;

#[test]
fn bunny_hits_match_a_brute_force_f64_ray_caster() {
    let s = scene(BUNNY);
    let mesh = marchmesh_meshio::load_mesh(&scenes_dir().join("meshes/bunny.obj")).expect("bunny");
    let to_render = marchmesh_core::RenderSpace::of(&s).from_world() * s.objects[0].transform;
    let positions: Vec<DVec3> = mesh
        .positions
        .iter()
        .map(|p| to_render.transform_point3(p.as_dvec3()))
        .collect();
    for kind in [BvhKind::Bvh2, BvhKind::CwBvh, BvhKind::Wide] {
        let g = build(
            &s,
            &MeshOptions {
                bvh: Some(kind),
                ..MeshOptions::default()
            },
        )
        .expect("build");
        let (mut hits, mut mismatches) = (0, 0);
        for ray in camera_rays(&s, 64) {
            let r = g.closest_hit(&ray);
            let truth =
                brute_force_hit(&positions, &mesh.triangles, DVec3::ZERO, ray.dir.as_dvec3());
            match (r.hit(), truth) {
                (Some(h), Some(t)) => {
                    hits += 1;
                    assert!(
                        (f64::from(h.t) - t).abs() < 1e-5 * t,
                        "{kind:?}: t {} vs {t}",
                        h.t
                    );
                    assert!(r.work.node_visits > 0 && r.work.primitive_tests > 0);
                }
                (None, None) => {}
                _ => mismatches += 1,
            }
        }
        assert!(hits > 500, "{kind:?}: only {hits} hits");
        // f32 versus f64 may disagree on rays grazing an edge; no more than a handful.
        assert!(
            mismatches <= 2,
            "{kind:?}: {mismatches} hit/miss disagreements"
        );
    }
}

/// Compares two geometries ray by ray (hit, t, normal, material).
fn assert_same_hits(
    a: &dyn Geometry,
    b: &dyn Geometry,
    rays: &[marchmesh_core::Ray],
    label: &str,
) -> usize {
    let mut hits = 0;
    for ray in rays {
        let (ra, rb) = (a.closest_hit(ray), b.closest_hit(ray));
        match (ra.hit(), rb.hit()) {
            (Some(x), Some(y)) => {
                hits += 1;
                assert!(
                    (x.t - y.t).abs() <= 1e-4 * x.t.max(1.0),
                    "{label}: t {} vs {}",
                    x.t,
                    y.t
                );
                assert!(
                    x.normal.dot(y.normal) > 0.999,
                    "{label}: normals {:?} vs {:?}",
                    x.normal,
                    y.normal
                );
                assert_eq!(x.material, y.material, "{label}: material");
            }
            (None, None) => {}
            (x, y) => panic!("{label}: hit {x:?} vs {y:?}"),
        }
        let shadow = marchmesh_core::Ray { t_max: 3.0, ..*ray };
        assert_eq!(
            a.occluded(&shadow).occluded,
            b.occluded(&shadow).occluded,
            "{label}: occlusion"
        );
    }
    hits
}

#[test]
fn instancing_gives_the_same_hits_as_flattened_geometry() {
    let scenes = [
        r#"{"camera": {"position": [0, 1.5, -5], "look_at": [0, 0, 0], "vfov_deg": 40, "width": 64, "height": 64},
            "objects": [{"shape": {"repeat": {"period": [1, 0, 1], "count": [3, null, 2],
                "child": {"shape": {"union": {"children": [
                    {"shape": {"sphere": {"radius": 0.35}}},
                    {"shape": {"box": {"half_extents": [0.1, 0.45, 0.1]}}, "material": {"color": [1, 0, 0]}}]}}}}},
                "transform": {"rotate_deg": [0, 20, 0], "scale": [1, 1.2, 0.9]}}]}"#,
        r#"{"camera": {"position": [0, 2, -6], "look_at": [0, 0, 0], "vfov_deg": 50, "width": 64, "height": 64},
            "objects": [{"shape": {"repeat": {"period": [2, 0, 2],
                "child": {"shape": {"box": {"half_extents": [0.4, 0.4, 0.4]}}}}}}],
            "render": {"max_distance": 40}}"#,
        r#"{"camera": {"position": [0, 2, -5.5], "look_at": [0, 1.2, 0], "vfov_deg": 50, "width": 64, "height": 64},
            "objects": [{"shape": {"mesh": {"path": "meshes/bunny.obj"}}, "transform": {"scale": 0.25, "translate": [-1, 0, 0]}},
                        {"shape": {"mesh": {"path": "meshes/bunny.obj"}}, "transform": {"scale": [0.2, 0.3, 0.25], "translate": [1.2, 0, 0], "rotate_deg": [0, 90, 0]}, "material": {"color": [0, 1, 0]}},
                        {"shape": {"plane": {}}}]}"#,
    ];
    for (k, json) in scenes.iter().enumerate() {
        let s = scene(json);
        let inst = build(&s, &MeshOptions::default()).expect("instanced");
        let flat = build(
            &s,
            &MeshOptions {
                instancing: Some(false),
                ..MeshOptions::default()
            },
        )
        .expect("flat");
        assert!(inst.instance_count() >= 2, "scene {k}: nothing instanced");
        assert_eq!(flat.instance_count(), 0);
        assert!(
            inst.report().memory_bytes < flat.report().memory_bytes,
            "scene {k}: instancing {} bytes vs flat {}",
            inst.report().memory_bytes,
            flat.report().memory_bytes
        );
        let hits = assert_same_hits(&inst, &flat, &camera_rays(&s, 64), &format!("scene {k}"));
        assert!(hits > 200, "scene {k}: {hits} hits");
    }
}

#[test]
fn bvh2_and_cwbvh_and_every_preset_agree() {
    let s = scene(BUNNY);
    let reference = build(
        &s,
        &MeshOptions {
            bvh: Some(BvhKind::Bvh2),
            ..MeshOptions::default()
        },
    )
    .expect("bvh2");
    for quality in [
        marchmesh_mesh::BuildQuality::Fastest,
        marchmesh_mesh::BuildQuality::Slow,
    ] {
        for bvh in [BvhKind::Bvh2, BvhKind::CwBvh, BvhKind::Wide] {
            let g = build(
                &s,
                &MeshOptions {
                    bvh: Some(bvh),
                    build: Some(quality),
                    ..MeshOptions::default()
                },
            )
            .expect("build");
            assert_same_hits(
                &g,
                &reference,
                &camera_rays(&s, 32),
                &format!("{bvh:?} {quality:?}"),
            );
        }
    }
}

#[test]
fn glb_export_of_the_bunny_renders_identically_to_the_obj() {
    let mesh = marchmesh_meshio::load_mesh(&scenes_dir().join("meshes/bunny.obj")).expect("bunny");
    let dir = std::env::temp_dir().join(format!("marchmesh-mesh-glb-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let glb = dir.join("bunny.glb");
    marchmesh_meshio::write_glb(&mesh, &glb).expect("write glb");
    let obj_scene = scene(BUNNY);
    let glb_json = BUNNY.replace(
        "meshes/bunny.obj",
        &glb.display().to_string().replace('\\', "/"),
    );
    let glb_scene = scene(&glb_json);
    let a = build(&obj_scene, &MeshOptions::default()).expect("obj");
    let b = build(&glb_scene, &MeshOptions::default()).expect("glb");
    for ray in camera_rays(&obj_scene, 64) {
        assert_eq!(a.closest_hit(&ray), b.closest_hit(&ray));
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn nan_and_degenerate_meshes_are_handled_with_clear_messages() {
    let dir = std::env::temp_dir().join(format!("marchmesh-mesh-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let nan = dir.join("nan.obj");
    std::fs::write(&nan, "v 0 0 0\nv 1 0 0\nv 0 NaN 0\nf 1 2 3\n").expect("write");
    let json = |p: &std::path::Path| {
        format!(
            r#"{{"camera": {{"position": [0, 0, -3], "width": 16, "height": 16}}, "objects": [{{"name": "bad", "shape": {{"mesh": {{"path": "{}"}}}}}}]}}"#,
            p.display().to_string().replace('\\', "/")
        )
    };
    let err = build(&scene(&json(&nan)), &MeshOptions::default()).expect_err("NaN vertex");
    let msg = err.to_string();
    assert!(
        msg.contains("nan.obj") && msg.contains("vertex 2") && msg.contains("objects[0]"),
        "{msg}"
    );

    let degenerate = dir.join("degenerate.obj");
    std::fs::write(
        &degenerate,
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 1 1 3\n",
    )
    .expect("write");
    let g = build(&scene(&json(&degenerate)), &MeshOptions::default())
        .expect("degenerate triangles are skipped");
    assert_eq!(g.triangle_count(), 1);
    let notes = g.report().notes.join("\n");
    assert!(notes.contains("skipped 2 degenerate"), "{notes}");

    let missing = dir.join("missing.obj");
    let msg = build(&scene(&json(&missing)), &MeshOptions::default())
        .expect_err("missing")
        .to_string();
    assert!(msg.contains("missing.obj"), "{msg}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn planes_cover_max_distance_and_are_exact() {
    let s = scene(
        r#"{"camera": {"position": [3, 2, -4], "look_at": [0, 0, 0], "width": 16, "height": 16},
            "objects": [{"shape": {"plane": {"normal": [0, 1, 0.2], "offset": -0.5}}}],
            "render": {"max_distance": 500}}"#,
    );
    let g = build(&s, &MeshOptions::default()).expect("plane");
    let n = DVec3::new(0.0, 1.0, 0.2).normalize();
    let cam = s.camera.position;
    let height = cam.dot(n) + 0.5;
    let mut checked = 0;
    for k in 0..200 {
        let a = k as f64 * 0.37;
        // Directions towards the plane, some nearly grazing.
        let d = (DVec3::new(a.cos(), 0.0, a.sin()) * (1.0 + (k % 7) as f64 * 3.0) - n).normalize();
        let denom = d.dot(n);
        let t = -height / denom;
        let ray = marchmesh_core::Ray {
            origin: glam::Vec3::ZERO,
            dir: d.as_vec3(),
            t_min: 0.0,
            t_max: f32::INFINITY,
        };
        let r = g.closest_hit(&ray);
        if t > 0.0 && t < 499.0 {
            let h = r.hit().expect("plane hit within max_distance");
            assert!(
                (f64::from(h.t) - t).abs() < 1e-5 * t.max(1.0),
                "t {} vs {t}",
                h.t
            );
            assert!(h.normal.as_dvec3().dot(n) > 0.99999);
            checked += 1;
        } else if !(0.0..=501.0).contains(&t) {
            assert!(
                r.hit().is_none(),
                "hit behind the camera or beyond max_distance at {t}"
            );
        }
    }
    assert!(checked > 50);
}

#[test]
fn infinite_repetition_is_bounded_and_reported() {
    let s = scene(
        r#"{"camera": {"position": [0, 2, -6], "look_at": [0, 0, 0], "vfov_deg": 50, "width": 32, "height": 32},
            "objects": [{"shape": {"repeat": {"period": [2, 0, 2],
                "child": {"shape": {"box": {"half_extents": [0.4, 0.4, 0.4]}}}}}}],
            "render": {"max_distance": 40}}"#,
    );
    let g = build(&s, &MeshOptions::default()).expect("build");
    let report = g.report();
    let cells = report
        .counters
        .iter()
        .find(|(k, _)| k == "repeat_cells")
        .expect("counter")
        .1;
    // Cells within 40 of the camera on a 2-unit grid: about pi 20^2, less the near-plane rows.
    assert!(cells > 1000.0 && cells < 1400.0, "{cells}");
    assert!(
        report
            .notes
            .iter()
            .any(|n| n.contains("infinite repetition bounded")),
        "{:?}",
        report.notes
    );
    assert_eq!(g.instance_count() as f64, cells);
    let err = build(
        &s,
        &MeshOptions {
            max_instances: Some(100),
            ..MeshOptions::default()
        },
    )
    .expect_err("limit");
    assert!(err.to_string().contains("max_instances"), "{err}");
    assert!(err.to_string().contains("infinite repetition"), "{err}");
}

#[test]
fn a_finite_repetition_over_the_instance_limit_is_not_called_infinite() {
    let s = scene(
        r#"{"camera": {"position": [0, 2, -6], "look_at": [0, 0, 0], "vfov_deg": 50, "width": 32, "height": 32},
            "objects": [{"shape": {"repeat": {"period": [2, 2, 2], "count": [200, 200, 200],
                "child": {"shape": {"box": {"half_extents": [0.4, 0.4, 0.4]}}}}}}]}"#,
    );
    let err = build(&s, &MeshOptions::default()).expect_err("8M cells are over the default limit");
    let msg = err.to_string();
    assert!(msg.starts_with("objects[0]: "), "{msg}");
    assert!(msg.contains("finite repetition"), "{msg}");
    assert!(msg.contains("8000000 cells by its counts"), "{msg}");
    assert!(!msg.contains("infinite"), "{msg}");
    assert!(!msg.contains("max_distance"), "{msg}");
}

#[test]
fn depth_error_against_the_analytic_sphere_falls_as_the_screen_budget_shrinks() {
    let s = scene(
        r#"{"camera": {"position": [0, 1.5, -5], "look_at": [0, 0, 0], "vfov_deg": 40, "width": 128, "height": 128},
            "objects": [{"shape": {"sphere": {"radius": 1}}}]}"#,
    );
    let centre = -s.camera.position;
    let mut previous = f64::INFINITY;
    let mut triangles_before = 0;
    for pixels in [4.0, 1.0, 0.25, 0.0625] {
        let g = build(
            &s,
            &MeshOptions {
                tess_px: Some(pixels),
                ..MeshOptions::default()
            },
        )
        .expect("build");
        let mut worst: f64 = 0.0;
        for ray in camera_rays(&s, 64) {
            if let (Some(h), Some(_)) = (
                g.closest_hit(&ray).hit(),
                ray_sphere(DVec3::ZERO, ray.dir.as_dvec3(), centre, 1.0),
            ) {
                // The hit point's distance from the exact sphere (the chord error; depth
                // differences along grazing rays are larger and not what the budget bounds).
                worst = worst.max(((h.position.as_dvec3() - centre).length() - 1.0).abs());
            }
        }
        // The budget: pixels x pixel angle x nearest distance (4 units here).
        let budget = pixels * s.camera.pixel_angle() * (s.camera.position.length() - 1.0);
        assert!(
            worst <= budget * 1.05 + 1e-6,
            "{pixels} px: error {worst} over budget {budget}"
        );
        assert!(
            worst < previous,
            "{pixels} px: error {worst} did not fall below {previous}"
        );
        assert!(g.triangle_count() > triangles_before);
        triangles_before = g.triangle_count();
        previous = worst;
    }
}

/// A sphere 1e6 units from the camera (and 1e7 off-axis) is a far instance traced in its own
/// frame: no cracks inside its silhouette, its silhouette and depth within the chord budget,
/// its normals the tessellation's (in render space its vertices sat on a 0.06-unit grid).
#[test]
fn far_spheres_are_hit_like_the_analytic_sphere() {
    for (distance, off_axis) in [(1e6, false), (1e6, true), (1e7, true)] {
        let s = far_sphere_scene(distance, off_axis);
        let g = build(
            &s,
            &MeshOptions {
                tess_chord: Some(1e-3),
                ..MeshOptions::default()
            },
        )
        .expect("build");
        assert_eq!(g.instance_count(), 1, "the far sphere is an instance");
        let checked = check_far_sphere(&s, &g, 0.01, 2.0);
        assert!(checked > 500, "{distance}: only {checked} hits checked");
    }
}
