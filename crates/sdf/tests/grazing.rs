//! Grazing rays (issue 14 item 3): segment tracing makes rays at 5 ... 0.001 degree over a
//! plane or a box top hit exactly within 64 evaluations (plain sphere tracing
//! exhausts 512 steps below 0.1 degree), and random rays at small angles over planes,
//! boxes, spheres and CSG find the exact reference's hits (no surface skipped that plain
//! sphere tracing finds).

use glam::Vec3;
use marchmesh_core::{Geometry, Ray, Termination};
use marchmesh_scene::{Scene, parse_scene};
use marchmesh_sdf::{SdfGeometry, SdfOptions, build};
use proptest::prelude::*;

fn scene(objects: &str) -> Scene {
    let json = format!(
        r#"{{"camera": {{"position": [0, 0, -5], "look_at": [0, 0, 0], "vfov_deg": 40, "width": 64, "height": 64}},
            "objects": [{objects}], "render": {{"max_distance": 1e7}}}}"#
    );
    parse_scene(&json, "test", std::path::Path::new(".")).expect("valid test scene")
}

fn ray(dir: Vec3) -> Ray {
    Ray {
        origin: Vec3::ZERO,
        dir: dir.normalize(),
        t_min: 0.0,
        t_max: f32::INFINITY,
    }
}

/// The scene's sdf geometry without segment tracing: plain (relaxed) sphere tracing.
fn plain_tracer(s: &Scene) -> SdfGeometry {
    build(
        s,
        &SdfOptions {
            segment: false,
            ..SdfOptions::DEFAULT
        },
    )
    .unwrap()
}

const PLANE: &str = r#"{"shape": {"plane": {}}, "transform": {"translate": [0, -1, 0]}}"#;
const SLAB: &str = r#"{"shape": {"box": {"half_extents": [1e6, 0.5, 1e6]}}, "transform": {"translate": [0, -1.5, 0]}}"#;

#[test]
fn grazing_rays_over_a_plane_and_a_box_top_hit_exactly() {
    for objects in [PLANE, SLAB] {
        let s = scene(objects);
        let g = build(&s, &SdfOptions::DEFAULT).unwrap();
        let plain = plain_tracer(&s);
        for deg in [5.0f64, 1.0, 0.1, 0.01, 0.001] {
            let (sn, cs) = deg.to_radians().sin_cos();
            // Also off to the side: the ray is not in a symmetry plane of the box.
            for side in [0.0, 0.3] {
                let r = ray(Vec3::new(side, -sn as f32, cs as f32));
                let exact = 1.0 / f64::from(r.dir.y).abs();
                let out = g.closest_hit(&r);
                assert_eq!(out.termination(), Termination::Hit, "{objects} at {deg}");
                let t = f64::from(out.hit().unwrap().t);
                assert!(
                    ((t - exact) / exact).abs() < 1e-4,
                    "{objects} at {deg}: t {t} exact {exact}"
                );
                assert!(
                    out.work.steps <= 64,
                    "{objects} at {deg}: {} steps",
                    out.work.steps
                );
                let n = out.hit().unwrap().normal;
                assert!(n.dot(Vec3::Y) > 0.9999, "{objects} at {deg}: normal {n:?}");
                // The 8-lane path takes the same decisions.
                let mut batch = vec![Default::default(); 3];
                g.closest_hits(&[r, r, r], &mut batch);
                assert_eq!(batch[1], out, "{objects} at {deg}: lockstep");
                if deg <= 0.1 {
                    // What plain sphere tracing did: hundreds of steps, or none left.
                    let before = plain.closest_hit(&r);
                    assert!(
                        before.work.steps > 4 * out.work.steps,
                        "{objects} at {deg}: {} plain steps, {} segment steps",
                        before.work.steps,
                        out.work.steps
                    );
                }
            }
        }
    }
}

/// Scenes for the random-ray test: every object's surface reachable at small angles from
/// the origin (looking along +z, slightly down).
fn scenes() -> Vec<(&'static str, String)> {
    vec![
        ("plane", PLANE.to_string()),
        ("slab", SLAB.to_string()),
        (
            "tilted_plane",
            r#"{"shape": {"plane": {"normal": [0.2, 1, -0.1]}}, "transform": {"translate": [0, -1, 0]}}"#.into(),
        ),
        (
            "ground_and_spheres",
            format!(
                r#"{PLANE}, {{"shape": {{"sphere": {{"radius": 1}}}}, "transform": {{"translate": [0.5, 0, 20]}}}},
                   {{"shape": {{"sphere": {{"radius": 0.3}}}}, "transform": {{"translate": [-0.4, -0.75, 60]}}}}"#
            ),
        ),
        (
            "csg_on_ground",
            format!(
                r#"{PLANE}, {{"shape": {{"subtraction": {{"children": [
                      {{"shape": {{"box": {{"half_extents": [2, 0.6, 2]}}}}}},
                      {{"shape": {{"sphere": {{"radius": 0.9}}}}, "transform": {{"translate": [0, 0.6, 0]}}}}]}}}},
                   "transform": {{"translate": [0, -0.9, 40], "rotate_deg": [0, 30, 0]}}}},
                   {{"shape": {{"intersection": {{"children": [
                      {{"shape": {{"box": {{"half_extents": [0.5, 0.05, 0.5]}}}}}},
                      {{"shape": {{"sphere": {{"radius": 0.6}}}}}}]}}}},
                   "transform": {{"translate": [1, -0.5, 15]}}}}"#
            ),
        ),
        (
            "thin_plate_above_box",
            format!(
                r#"{SLAB}, {{"shape": {{"box": {{"half_extents": [3, 0.001, 3]}}}}, "transform": {{"translate": [0, -0.99, 80]}}}}"#
            ),
        ),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn random_grazing_rays_find_the_reference_hits(
        x in -0.05f32..0.05,
        deg in prop::sample::select(vec![0.001f32, 0.01, 0.05, 0.2, 0.7, 1.5, 3.0, 8.0]),
        frac in 0.5f32..1.5,
    ) {
        let a = (deg * frac).to_radians();
        let r = ray(Vec3::new(x, -a.sin(), a.cos()));
        for (name, objects) in scenes() {
            let s = scene(&objects);
            let g = build(&s, &SdfOptions::DEFAULT).unwrap();
            let truth = marchmesh_reference::build(&s, &Default::default()).unwrap();
            let want = truth.closest_hit(&r);
            let got = g.closest_hit(&r);
            prop_assert!(got.termination() != Termination::MaxSteps,
                "{name} at {deg}: {} steps", got.work.steps);
            let inf = f64::INFINITY;
            let tw = want.hit().map_or(inf, |h| f64::from(h.t));
            let th = got.hit().map_or(inf, |h| f64::from(h.t));
            let at = |t: f64| g.field().distance_f64((r.origin + r.dir * t as f32).as_dvec3());
            let cone = s.camera.pixel_angle();
            if th > tw * (1.0 + 1e-3) {
                // Past the reference's surface: only a ray skimming it (never deeper inside
                // than a pixel's cone) may do that; a skipped surface fails here.
                let end = th.min(2.0 * tw);
                let deepest = (0..=400)
                    .map(|i| at(tw + (end - tw) * f64::from(i) / 400.0))
                    .fold(inf, f64::min);
                if deepest <= -cone * tw {
                    // Allowed only where plain sphere tracing passes this surface too
                    // (this test once found such a case, csg_on_ground at ~1.2 degree, x =
                    // -0.0209, fixed since: `plain_tracing_does_not_pass_the_box_on_the_ground`):
                    // segment tracing must do no worse.
                    let plain = plain_tracer(&s).closest_hit(&r);
                    let tp = plain.hit().map_or(inf, |h| f64::from(h.t));
                    prop_assert!(tp > tw * (1.0 + 1e-3) && th <= tp * (1.0 + 1e-3),
                        "{name} at {deg}: sdf {th} passed the reference hit {tw} (depth {deepest}), plain tracing {tp}");
                }
            } else if th < tw * (1.0 - 1e-3) {
                // Before it: a near miss called a hit must be within a pixel's cone.
                prop_assert!(at(th).abs() < cone * th,
                    "{name} at {deg}: sdf {th} before the reference {tw}, field {}", at(th));
            }
        }
    }
}

/// Plain sphere tracing (`segment=false`) used to pass the CSG box standing on the ground in
/// `csg_on_ground`: a ray skimming the ground inside the hit shell took a secant prediction
/// from the ground's shallow slope that landed past the box, and the crossing was bracketed
/// without sweeping the gap (found by the property test above at about 1.2 degrees; 6532 of
/// 300,000 rays at 0.3-3.3 degrees hit behind the reference on 8d2a5f7, none on 6f9be06,
/// after the shell's sweeps were reworked). Every plain-traced ray of a grid over that
/// neighbourhood hits no further than the exact reference; on 8d2a5f7 this test fails.
#[test]
fn plain_tracing_does_not_pass_the_box_on_the_ground() {
    let (_, objects) = scenes()
        .into_iter()
        .find(|(name, _)| *name == "csg_on_ground")
        .expect("scene listed");
    let s = scene(&objects);
    let plain = plain_tracer(&s);
    let truth = marchmesh_reference::build(&s, &Default::default()).unwrap();
    let mut hits = 0;
    for i in 0..=20 {
        let x = -0.05 + 0.0025 * i as f32;
        for j in 0..=60 {
            let deg = 0.9f32 + 0.01 * j as f32;
            let a = deg.to_radians();
            let r = ray(Vec3::new(x, -a.sin(), a.cos()));
            let want = truth
                .closest_hit(&r)
                .hit()
                .expect("the ground is below every ray")
                .t;
            let got = plain.closest_hit(&r);
            assert_eq!(got.termination(), Termination::Hit, "x {x}, {deg} degrees");
            let got = got.hit().unwrap().t;
            assert!(
                got <= want * (1.0 + 1e-3),
                "x {x}, {deg} degrees: plain tracing hit at {got}, the reference at {want}"
            );
            hits += usize::from((got - want).abs() <= want * 1e-3);
        }
    }
    // Nearly every ray agrees with the reference (1281 rays), so the bound above is not
    // passed by rays that hit something nearer than the reference does.
    assert!(hits > 1000, "{hits} hits agree");
}
