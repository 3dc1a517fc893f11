//! The distance field's one-query approximations (cone soft shadows, few-tap ambient
//! occlusion) against the exact answer from sampled rays through the reference backend.

use marchmesh_core::{BackgroundSampler, Geometry, RenderOptions, RenderOutput, render};
use marchmesh_scene::{Scene, parse_scene};
use marchmesh_sdf::{SdfOptions, build};

/// A sphere of radius 1 on the ground under `light`, with `render` settings appended.
fn sphere_on_ground(light: &str, render_extra: &str) -> Scene {
    let json = format!(
        r#"{{ "camera": {{ "position": [0, 6, -6], "look_at": [0, 0, 0], "vfov_deg": 50,
              "width": 64, "height": 64 }},
            "lights": [ {light} ],
            "objects": [
              {{ "shape": {{ "plane": {{ "normal": [0, 1, 0] }} }} }},
              {{ "shape": {{ "sphere": {{ "radius": 1 }} }}, "transform": {{ "translate": [0, 1, 0] }},
                 "material": {{ "color": [0.8, 0.3, 0.3] }} }} ],
            "render": {{ "max_reflection_depth": 0 {render_extra} }} }}"#
    );
    parse_scene(&json, "test", std::path::Path::new(".")).expect("valid test scene")
}

fn run(scene: &Scene, g: &dyn Geometry) -> RenderOutput {
    let bg = BackgroundSampler::load(&scene.background).unwrap();
    render(
        scene,
        g,
        &bg,
        &RenderOptions {
            threads: 1,
            ..Default::default()
        },
        &|| {},
    )
    .unwrap()
}

fn mean_abs_difference(a: &RenderOutput, b: &RenderOutput) -> f32 {
    let n = a.framebuffer.color.len() as f32;
    a.framebuffer
        .color
        .iter()
        .zip(&b.framebuffer.color)
        .map(|(x, y)| (*x - *y).abs().max_element())
        .sum::<f32>()
        / n
}

const AREA_LIGHT: &str = r#"{ "rectangle_light": { "corner": [-1.5, 4, -1.5],
    "edge_u": [3, 0, 0], "edge_v": [0, 0, 3], "intensity": 1 } }"#;

#[test]
fn cone_shadows_approximate_sampled_soft_shadows_with_a_few_queries_per_light() {
    let s = sphere_on_ground(AREA_LIGHT, r#", "area_light_samples": 64"#);
    let truth = run(
        &s,
        &marchmesh_reference::build(&s, &Default::default()).unwrap(),
    );
    let sampled = run(&s, &build(&s, &SdfOptions::DEFAULT).unwrap());
    let cone_opts = SdfOptions {
        cone_shadows: true,
        ..SdfOptions::DEFAULT
    };
    let cone_geometry = build(&s, &cone_opts).unwrap();
    assert!(cone_geometry.shortcuts().cone_shadows);
    let cone = run(&s, &cone_geometry);
    // One to four cone queries per lit shading point (four where the light is wider than
    // `CONE_SPLIT_TAN`: its quarters) instead of up to 64 shadow rays (samples of the light
    // below a point's horizon need no ray).
    let (rays, cones) = (sampled.stats.shadow_rays, cone.stats.shadow_rays);
    assert!(
        rays > 15 * cones && rays <= 64 * cones,
        "{rays} rays, {cones} cones"
    );
    let (e_sampled, e_cone) = (
        mean_abs_difference(&sampled, &truth),
        mean_abs_difference(&cone, &truth),
    );
    // Sampled rays through the field agree with the exact reference; the cone estimate is an
    // approximation with a visible but bounded error, and it is soft, not a hard shadow.
    assert!(e_sampled < 2e-3, "sampled {e_sampled}");
    assert!(e_cone < 0.03, "cone {e_cone}");
    let hard = sphere_on_ground(
        r#"{ "point": { "position": [0, 4, 0], "intensity": 1 } }"#,
        "",
    );
    let hard = run(&hard, &build(&hard, &SdfOptions::DEFAULT).unwrap());
    assert!(
        mean_abs_difference(&cone, &hard) > e_cone,
        "softer than a point light"
    );
}

#[test]
fn tap_ambient_occlusion_is_exact_on_open_ground_and_darkens_the_contact() {
    let light = r#"{ "ambient": { "intensity": 1 } }"#;
    let s = sphere_on_ground(
        light,
        r#", "ambient_occlusion": { "samples": 64, "distance": 1.5 }"#,
    );
    let taps = build(
        &s,
        &SdfOptions {
            ao_taps: 5,
            ..SdfOptions::DEFAULT
        },
    )
    .unwrap();
    let truth = run(
        &s,
        &marchmesh_reference::build(&s, &Default::default()).unwrap(),
    );
    let est = run(&s, &taps);
    let px = |o: &RenderOutput, col: u32, row: u32| o.framebuffer.color[(row * 64 + col) as usize];
    // Far from the sphere both see an open hemisphere.
    assert!((px(&est, 2, 62) - px(&truth, 2, 62)).abs().max_element() < 1e-5);
    // Just below the sphere's silhouette the ground is occluded in both, to a similar degree.
    let col = 32;
    let row = (32..64)
        .find(|&r| est.framebuffer.material[(r * 64 + col) as usize] == 0)
        .unwrap();
    let (t, e) = (px(&truth, col, row).x, px(&est, col, row).x);
    let open = px(&truth, 2, 62).x;
    assert!(
        t < 0.8 * open && e < 0.9 * open,
        "truth {t}, taps {e}, open {open}"
    );
    assert_eq!(est.stats.ao_rays * 64, truth.stats.ao_rays);
    assert!(mean_abs_difference(&est, &truth) < 0.05);
}
