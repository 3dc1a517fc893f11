//! Area lights, ambient occlusion and the path tracer, rendered through the exact reference
//! backend and checked against closed forms (furnace, form factor) and against the point-light
//! and no-occlusion limits.

use glam::Vec3;
use marchmesh_core::RenderOutput;
use marchmesh_scene::Scene;

use marchmesh_testkit::scene;

fn render_with(scene: &Scene, threads: usize) -> RenderOutput {
    let g = marchmesh_reference::build(scene, &Default::default()).unwrap();
    let out = marchmesh_testkit::render_with(scene, &g, threads);
    assert_eq!(out.stats.non_finite_pixels, 0);
    out
}

fn pixel(out: &RenderOutput, col: u32, row: u32) -> Vec3 {
    let fb = &out.framebuffer;
    fb.color[(row * fb.width + col) as usize]
}

#[test]
fn path_tracer_passes_the_white_furnace() {
    // A convex Lambertian sphere of albedo 0.5 under a uniform environment of radiance 0.8
    // reflects exactly 0.5 * 0.8 at every point: one bounce, and every bounce ray escapes.
    let s = scene(
        r#"{ "camera": { "position": [0, 0, -4], "look_at": [0, 0, 0], "vfov_deg": 40,
             "width": 24, "height": 24 },
           "background": { "color": [0.8, 0.8, 0.8] }, "lights": [],
           "objects": [ { "shape": { "sphere": { "radius": 1 } },
                          "material": { "color": [0.5, 0.5, 0.5] } } ],
           "render": { "integrator": "path", "samples_per_pixel": 8, "max_bounces": 4 } }"#,
    );
    let out = render_with(&s, 1);
    let (mut on, mut off) = (0, 0);
    for row in 0..24 {
        for col in 0..24 {
            let c = pixel(&out, col, row);
            let hit = out.framebuffer.depth[(row * 24 + col) as usize].is_finite();
            // Edge pixels mix sphere and background samples; the centre sample decides `hit`.
            if hit && (c - Vec3::splat(0.4)).abs().max_element() < 1e-3 {
                on += 1;
            } else if !hit && (c - Vec3::splat(0.8)).abs().max_element() < 1e-3 {
                off += 1;
            }
        }
    }
    // Everything but the silhouette's anti-aliased ring is exact.
    assert!(on > 150 && off > 150, "on {on}, off {off}");
    assert!(out.stats.bounce_rays > 0);
}

/// The fraction of a Lambertian point's hemisphere-weighted view that a parallel rectangle
/// `a x b` at height `c` covers when the point lies under one of its corners (the point-to-
/// rectangle form factor, e.g. Howell's catalogue, configuration B-3).
fn corner_form_factor(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * std::f64::consts::PI)
}

#[test]
fn path_tracer_direct_light_matches_the_rectangle_form_factor() {
    // A 2x2 light of radiance 1 at height 1 over a plane of albedo 0.5; the camera looks down
    // through the light's back side (invisible) at the point under its centre. Outgoing
    // radiance = albedo * radiance * form factor.
    let s = scene(
        r#"{ "camera": { "position": [0, 5, 0], "look_at": [0, 0, 0], "up": [0, 0, 1],
             "vfov_deg": 1, "width": 3, "height": 3 },
           "lights": [ { "rectangle_light": { "corner": [-1, 1, -1], "edge_u": [2, 0, 0],
                          "edge_v": [0, 0, 2], "intensity": 1 } } ],
           "objects": [ { "shape": { "plane": { "normal": [0, 1, 0] } },
                          "material": { "color": [0.5, 0.5, 0.5] } } ],
           "render": { "integrator": "path", "samples_per_pixel": 1024, "max_bounces": 0 } }"#,
    );
    let expect = 0.5 * 4.0 * corner_form_factor(1.0, 1.0, 1.0);
    let got = pixel(&render_with(&s, 1), 1, 1);
    for ch in got.to_array() {
        assert!(
            (ch as f64 - expect).abs() < 0.005 * expect,
            "{got:?} vs {expect}"
        );
    }
}

#[test]
fn path_tracer_gives_the_same_image_at_any_thread_count() {
    let json = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../scenes/lighting/cornell-box.json"),
    )
    .unwrap();
    let s = scene(&json).with_image_size(24, 24).unwrap();
    let a = render_with(&s, 1);
    let b = render_with(&s, 2);
    assert_eq!(a.framebuffer.color, b.framebuffer.color);
    // The box is lit: the mean radiance is well above zero and finite.
    let mean: Vec3 = a.framebuffer.color.iter().sum::<Vec3>() / a.framebuffer.color.len() as f32;
    assert!(mean.min_element() > 0.01 && mean.x > 0.1, "{mean:?}");
    assert!(a.stats.shadow_rays > 0 && a.stats.bounce_rays > 0);
}

/// A sphere of radius 1 resting on the ground, lit by `light` (a JSON light object).
fn sphere_on_ground(light: &str, extra_render: &str) -> Scene {
    scene(&format!(
        r#"{{ "camera": {{ "position": [0, 6, -6], "look_at": [0, 0, 0], "vfov_deg": 50,
              "width": 48, "height": 48 }},
            "lights": [ {light} ],
            "objects": [
              {{ "shape": {{ "plane": {{ "normal": [0, 1, 0] }} }} }},
              {{ "shape": {{ "sphere": {{ "radius": 1 }} }}, "transform": {{ "translate": [0, 1, 0] }},
                 "material": {{ "color": [0.8, 0.3, 0.3] }} }} ],
            "render": {{ "max_reflection_depth": 0 {extra_render} }} }}"#
    ))
}

#[test]
fn a_tiny_area_light_shades_like_a_point_light() {
    let point = render_with(
        &sphere_on_ground(
            r#"{ "point": { "position": [2, 5, -1], "intensity": 0.9 } }"#,
            "",
        ),
        1,
    );
    let area = render_with(
        &sphere_on_ground(
            r#"{ "sphere_light": { "position": [2, 5, -1], "radius": 1e-4, "intensity": 0.9 } }"#,
            r#", "area_light_samples": 4"#,
        ),
        1,
    );
    let worst = point
        .framebuffer
        .color
        .iter()
        .zip(&area.framebuffer.color)
        .map(|(a, b)| (*a - *b).abs().max_element())
        .fold(0.0f32, f32::max);
    assert!(worst < 2e-3, "largest difference {worst}");
    assert_eq!(area.stats.shadow_rays, 4 * point.stats.shadow_rays);
}

/// Ground pixels whose shadowed brightness is strictly between 5% and 95% of the same
/// render's brightness without shadows: the penumbra.
fn penumbra_pixels(shadowed: &RenderOutput, unshadowed: &RenderOutput) -> usize {
    shadowed
        .framebuffer
        .color
        .iter()
        .zip(&unshadowed.framebuffer.color)
        .zip(&shadowed.framebuffer.material)
        .filter(|((s, u), m)| **m == 0 && u.x > 0.0 && (0.05..0.95).contains(&(s.x / u.x)))
        .count()
}

#[test]
fn an_area_light_casts_a_penumbra_a_point_light_does_not() {
    let point = |shadows: bool| {
        render_with(
            &sphere_on_ground(
                &format!(
                    r#"{{ "point": {{ "position": [0, 4, 0], "intensity": 1, "casts_shadows": {shadows} }} }}"#
                ),
                "",
            ),
            1,
        )
    };
    let rectangle = |shadows: bool| {
        render_with(
            &sphere_on_ground(
                &format!(
                    r#"{{ "rectangle_light": {{ "corner": [-1.5, 4, -1.5], "edge_u": [3, 0, 0],
                         "edge_v": [0, 0, 3], "intensity": 1, "casts_shadows": {shadows} }} }}"#
                ),
                r#", "area_light_samples": 64"#,
            ),
            1,
        )
    };
    let (hard, hard_open) = (point(true), point(false));
    let (soft, soft_open) = (rectangle(true), rectangle(false));
    assert_eq!(penumbra_pixels(&hard, &hard_open), 0);
    let n = penumbra_pixels(&soft, &soft_open);
    assert!(n > 40, "{n} penumbra pixels");
}

#[test]
fn ambient_occlusion_darkens_the_contact_and_leaves_open_ground_alone() {
    let light = r#"{ "ambient": { "intensity": 1 } }"#;
    let plain = render_with(&sphere_on_ground(light, ""), 1);
    let ao = render_with(
        &sphere_on_ground(
            light,
            r#", "ambient_occlusion": { "samples": 64, "distance": 1.5 }"#,
        ),
        1,
    );
    // A ground point far from the sphere (bottom-left corner of the image) sees an open sky.
    let (c0, c1) = (pixel(&plain, 2, 45), pixel(&ao, 2, 45));
    assert!((c0 - c1).abs().max_element() < 1e-6, "{c0:?} vs {c1:?}");
    // Just below the sphere's silhouette, in front of the contact point, the ground is
    // occluded by the sphere.
    let col = 24;
    let below = (24..48)
        .find(|&row| ao.framebuffer.material[(row * 48 + col) as usize] == 0)
        .unwrap();
    let (p, a) = (pixel(&plain, col, below), pixel(&ao, col, below));
    assert!(a.x < 0.8 * p.x, "occluded {a:?} vs open {p:?}");
    assert!(ao.stats.ao_rays > 0 && plain.stats.ao_rays == 0);
    assert!(
        ao.stats
            .mrays_per_thread_second()
            .ambient_occlusion
            .is_some()
    );
}
