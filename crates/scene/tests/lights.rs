//! Area lights, ambient occlusion and path-tracer settings: defaults, and every bad value
//! reported with its JSON path.

use std::path::Path;

use marchmesh_scene::{Integrator, Light, SceneError, parse_scene};

fn problems(json: &str) -> Vec<(String, String)> {
    match parse_scene(json, "t.json", Path::new(".")) {
        Ok(_) => Vec::new(),
        Err(SceneError::Invalid { problems, .. }) => problems
            .into_iter()
            .map(|p| (p.json_path, p.reason))
            .collect(),
        Err(e) => vec![(String::new(), e.to_string())],
    }
}

fn has(problems: &[(String, String)], path: &str, reason_part: &str) -> bool {
    problems
        .iter()
        .any(|(p, r)| p == path && r.contains(reason_part))
}

#[test]
fn area_lights_and_lighting_settings_take_their_documented_defaults() {
    let s = parse_scene(
        r#"{ "lights": [ { "rectangle_light": { "corner": [0, 2, 0], "edge_u": [1, 0, 0],
              "edge_v": [0, 0, 1], "intensity": 2 } },
              { "sphere_light": { "position": [0, 3, 0], "radius": 0.5, "intensity": 1,
                "color": [1, 0.5, 0.25] } } ] }"#,
        "t.json",
        Path::new("."),
    )
    .unwrap();
    let r = &s.render;
    assert_eq!(r.integrator, Integrator::Whitted);
    assert_eq!(r.area_light_samples, 16);
    assert_eq!(r.ambient_occlusion, None);
    assert_eq!((r.max_bounces, r.seed), (8, 0));
    match s.lights[0] {
        Light::Rectangle {
            emission,
            casts_shadows,
            ..
        } => {
            assert_eq!(emission.to_array(), [2.0, 2.0, 2.0]);
            assert!(casts_shadows);
        }
        ref other => panic!("{other:?}"),
    }
    match s.lights[1] {
        Light::Sphere { emission, .. } => assert_eq!(emission.to_array(), [1.0, 0.5, 0.25]),
        ref other => panic!("{other:?}"),
    }
}

#[test]
fn bad_area_lights_are_reported_with_their_paths() {
    let p = problems(
        r#"{ "lights": [
              { "sphere_light": { "position": [0, 3, 0], "radius": 0, "intensity": -1 } },
              { "rectangle_light": { "corner": [0, 2, 0], "edge_u": [1, 0, 0],
                "edge_v": [2, 0, 0], "intensity": 1, "color": [2, 0, 0] } },
              { "rectangle_light": { "corner": [0, 2, 0], "edge_u": [0, 0, 0],
                "edge_v": [0, 0, 1], "intensity": 1 } } ] }"#,
    );
    assert!(has(&p, "lights[0].sphere_light.radius", "> 0"), "{p:?}");
    assert!(
        has(&p, "lights[0].sphere_light.intensity", "[0, 1000000]"),
        "{p:?}"
    );
    assert!(
        has(&p, "lights[1].rectangle_light.edge_v", "no area"),
        "{p:?}"
    );
    assert!(
        has(&p, "lights[1].rectangle_light.color[0]", "[0, 1]"),
        "{p:?}"
    );
    assert!(
        has(&p, "lights[2].rectangle_light.edge_v", "no area"),
        "{p:?}"
    );
}

#[test]
fn sample_and_bounce_caps_are_enforced_per_integrator() {
    let p = problems(
        r#"{ "render": { "samples_per_pixel": 2048, "area_light_samples": 0,
             "max_bounces": 65, "ambient_occlusion": { "samples": 5000, "distance": 0 } } }"#,
    );
    assert!(
        has(&p, "render.samples_per_pixel", "1..=1024 for the whitted"),
        "{p:?}"
    );
    assert!(has(&p, "render.area_light_samples", "1..=4096"), "{p:?}");
    assert!(has(&p, "render.max_bounces", "0..=64"), "{p:?}");
    assert!(
        has(&p, "render.ambient_occlusion.samples", "1..=4096"),
        "{p:?}"
    );
    assert!(has(&p, "render.ambient_occlusion.distance", "> 0"), "{p:?}");
    // The path tracer accepts converged-truth sample counts, up to its own cap.
    assert!(
        problems(r#"{ "render": { "integrator": "path", "samples_per_pixel": 65536 } }"#)
            .is_empty()
    );
    let p = problems(r#"{ "render": { "integrator": "path", "samples_per_pixel": 65537 } }"#);
    assert!(
        has(&p, "render.samples_per_pixel", "1..=65536 for the path"),
        "{p:?}"
    );
}

#[test]
fn unknown_integrators_and_light_fields_are_parse_errors() {
    let p = problems(r#"{ "render": { "integrator": "photon" } }"#);
    assert!(p[0].1.contains("render.integrator"), "{p:?}");
    let p = problems(
        r#"{ "lights": [ { "sphere_light": { "position": [0, 0, 0], "radius": 1,
             "intensity": 1, "power": 3 } } ] }"#,
    );
    assert!(p[0].1.contains("power"), "{p:?}");
}

#[test]
fn render_overrides_are_checked_like_scene_values() {
    use marchmesh_scene::RenderOverrides;
    let base = || {
        parse_scene(
            r#"{ "render": { "ambient_occlusion": { "samples": 8 } } }"#,
            "t.json",
            Path::new("."),
        )
        .unwrap()
    };
    let s = base()
        .with_render_overrides(&RenderOverrides {
            area_light_samples: Some(64),
            ambient_occlusion_samples: Some(32),
            seed: Some(9),
            ..RenderOverrides::default()
        })
        .unwrap();
    assert_eq!(s.render.area_light_samples, 64);
    assert_eq!(s.render.ambient_occlusion.unwrap().samples, 32);
    assert_eq!(s.render.seed, 9);
    let err = |o: RenderOverrides| base().with_render_overrides(&o).unwrap_err();
    assert!(
        err(RenderOverrides {
            area_light_samples: Some(0),
            ..RenderOverrides::default()
        })
        .contains("area_light_samples must be in 1..=4096")
    );
    assert!(
        err(RenderOverrides {
            samples_per_pixel: Some(5000),
            ..RenderOverrides::default()
        })
        .contains("1..=1024 for the whitted")
    );
    let no_ao = parse_scene("{}", "t.json", Path::new(".")).unwrap();
    let e = no_ao
        .with_render_overrides(&RenderOverrides {
            ambient_occlusion_samples: Some(4),
            ..RenderOverrides::default()
        })
        .unwrap_err();
    assert!(e.contains("no render.ambient_occlusion"), "{e}");
}
