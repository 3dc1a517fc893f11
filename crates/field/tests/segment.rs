//! Segment tracing's safe steps (`Field::segment_step`): the field never changes sign within
//! a step (checked by dense sampling along random rays against planes, boxes, spheres, CSG
//! and transformed nodes), the value is the interpreter's, a step is never below the plain
//! sphere-tracing step, and grazing rays over a plane or a box top get steps reaching the
//! surface.

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_field::{Field, FieldOptions};
use marchmesh_scene::{Node, NodeKind, Shape, SmoothOp, compose_transform};
use proptest::prelude::*;

fn node(kind: NodeKind, transform: DAffine3) -> Node {
    Node {
        transform,
        material: 0,
        name: None,
        json_path: "test".into(),
        kind,
    }
}

fn at(kind: NodeKind, t: DVec3) -> Node {
    node(kind, DAffine3::from_translation(t))
}

fn field(n: &Node) -> Field {
    Field::compile_node(n, DAffine3::IDENTITY, &FieldOptions::default()).expect("compiles")
}

fn plane(normal: DVec3, offset: f64) -> NodeKind {
    NodeKind::Leaf(Shape::Plane {
        normal: normal.normalize(),
        offset,
    })
}

fn cube(b: DVec3) -> NodeKind {
    NodeKind::Leaf(Shape::Box { half_extents: b })
}

fn cases() -> Vec<(&'static str, Node)> {
    let a = at(cube(DVec3::new(1.0, 0.6, 0.8)), DVec3::new(0.3, 0.0, 0.0));
    let b = at(
        NodeKind::Leaf(Shape::Sphere { radius: 0.9 }),
        DVec3::new(-0.4, 0.5, 0.2),
    );
    let far = at(
        NodeKind::Leaf(Shape::Sphere { radius: 0.5 }),
        DVec3::new(2.5, 1.0, -2.0),
    );
    let ground = node(plane(DVec3::new(0.1, 1.0, -0.2), -1.0), DAffine3::IDENTITY);
    let tilted = node(
        cube(DVec3::new(1.5, 0.2, 1.0)),
        compose_transform(
            DVec3::new(0.0, -0.5, 0.5),
            DVec3::new(20.0, 35.0, 5.0),
            DVec3::new(1.0, 1.0, 1.0),
        ),
    );
    let stretched = node(
        NodeKind::Leaf(Shape::Sphere { radius: 1.0 }),
        compose_transform(
            DVec3::ZERO,
            DVec3::new(15.0, 25.0, 0.0),
            DVec3::new(2.0, 0.3, 1.0),
        ),
    );
    let cylinder = NodeKind::Leaf(Shape::Cylinder {
        radius: 0.7,
        half_height: 0.9,
    });
    let tilted_cylinder = node(
        cylinder.clone(),
        compose_transform(
            DVec3::new(0.4, -0.3, 0.6),
            DVec3::new(30.0, 10.0, 45.0),
            DVec3::new(1.0, 1.0, 1.0),
        ),
    );
    let op = |k: NodeKind| node(k, DAffine3::IDENTITY);
    vec![
        ("cylinder", at(cylinder, DVec3::new(-0.2, 0.1, 0.3))),
        ("tilted_cylinder", tilted_cylinder),
        ("plane", ground.clone()),
        ("box", a.clone()),
        ("sphere", b.clone()),
        ("tilted_box", tilted.clone()),
        ("stretched_sphere", stretched.clone()),
        (
            "union",
            op(NodeKind::Union(vec![
                ground.clone(),
                a.clone(),
                b.clone(),
                far.clone(),
            ])),
        ),
        (
            "intersection",
            op(NodeKind::Intersection(vec![a.clone(), b.clone()])),
        ),
        (
            "subtraction",
            op(NodeKind::Subtraction(vec![
                a.clone(),
                b.clone(),
                far.clone(),
            ])),
        ),
        (
            "csg_on_ground",
            op(NodeKind::Union(vec![
                ground,
                op(NodeKind::Subtraction(vec![tilted, b.clone()])),
                stretched,
            ])),
        ),
        (
            "smooth_union",
            op(NodeKind::Smooth {
                op: SmoothOp::Union,
                children: vec![a, b],
                blend_radius: 0.5,
            }),
        ),
    ]
}

/// The first sign change of `f` along `p + s d` for `s` in `[0, s_max]`, by dense sampling
/// (`None`: none seen).
fn first_sign_change(f: &Field, p: DVec3, d: DVec3, s_max: f64, v: f64) -> Option<f64> {
    let n = 4000;
    (1..=n).map(|i| s_max * i as f64 / n as f64).find(|&s| {
        let w = f.distance_f64(p + d * s);
        // A value within rounding of zero is on the surface, not past it.
        w * v.signum() < -1e-9
    })
}

fn pt() -> impl Strategy<Value = DVec3> {
    (-4.0f64..4.0, -4.0f64..4.0, -4.0f64..4.0).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn a_safe_step_never_crosses_a_surface(p in pt(), dir in pt(), len in 0.01f64..20.0) {
        prop_assume!(dir.length() > 1e-3);
        let d = dir.normalize();
        for (name, n) in cases() {
            let f = field(&n);
            let (v, step) = f.segment_step_f64(p, d, len);
            prop_assert_eq!(v, f.distance_f64(p), "{}: value", name);
            prop_assert!(step >= v.abs() * (1.0 - 1e-12), "{name}: step {step} below |v| {v}");
            if v.abs() < 1e-9 {
                continue;
            }
            let reach = step.min(50.0);
            if let Some(s) = first_sign_change(&f, p, d, reach, v) {
                prop_assert!(s >= step, "{name}: sign changes at {s} within the step {step} (v {v}, len {len})");
            }
            // The f32 step agrees with the f64 one up to rounding, and is as safe.
            let (v32, step32) = f.segment_step(p.as_vec3(), d.as_vec3(), len as f32);
            prop_assert!((f64::from(v32) - v).abs() < 1e-5, "{name}: f32 value {v32} vs {v}");
            if let Some(s) = first_sign_change(&f, p, d, f64::from(step32).min(50.0), v) {
                prop_assert!(s >= f64::from(step32) - 1e-4 * s.max(1.0),
                    "{name}: f32 step {step32} passes the sign change at {s}");
            }
        }
    }
}

/// The exact distance along a ray from `p` (direction `d`) to the plane `y = 0`.
fn to_ground(p: DVec3, d: DVec3) -> f64 {
    -p.y / d.y
}

#[test]
fn grazing_rays_over_a_plane_and_a_box_top_step_to_the_surface() {
    let ground = field(&node(plane(DVec3::Y, 0.0), DAffine3::IDENTITY));
    let slab = field(&at(
        cube(DVec3::new(1e5, 0.5, 1e5)),
        DVec3::new(0.0, -0.5, 0.0),
    ));
    for deg in [1.0f64, 0.1, 0.01] {
        let (s, c) = deg.to_radians().sin_cos();
        let d = DVec3::new(0.0, -s, c);
        let p = DVec3::new(0.0, 1.0, 0.0);
        let exact = to_ground(p, d);
        // The plane's bound holds everywhere: one step reaches the surface.
        let (_, step) = ground.segment_step_f64(p, d, 1.0);
        assert!(
            step <= exact && step > exact * 0.99,
            "plane at {deg}: {step} vs {exact}"
        );
        // The box top's bound holds along the top: the step is the segment when it is
        // shorter than the way down, the way down otherwise.
        let (_, step) = slab.segment_step_f64(p, d, 10.0);
        assert!((step - 10.0).abs() < 1e-9, "box at {deg}: {step}");
        let (_, step) = slab.segment_step_f64(p, d, 2.0 * exact);
        assert!(
            step <= exact && step > exact * 0.99,
            "box at {deg}: {step} vs {exact}"
        );
        // f32 as well (the tracer's precision).
        let (_, step) = ground.segment_step(p.as_vec3(), d.as_vec3(), 1.0);
        assert!(f64::from(step) < exact * 1.0001 && f64::from(step) > exact * 0.99);
    }
}

#[test]
fn rays_skimming_a_cylinder_cap_step_to_the_cap_or_past_it() {
    // Cap at local y = 1 (radius 10, half height 1), the cylinder turned 30 degrees about z
    // so that the region just above the cap lies inside its world bounding box: the step
    // must come from the cylinder's own bound, not from clipping rays to the box. Rays start
    // 1e-3 above the cap and descend at small angles along local z, meeting the cap's plane
    // within its radius (at 0.01 degrees 5.7 units on).
    let turn = DAffine3::from_rotation_z(30f64.to_radians());
    let f = field(&node(
        NodeKind::Leaf(Shape::Cylinder {
            radius: 10.0,
            half_height: 1.0,
        }),
        turn,
    ));
    for deg in [1.0f64, 0.1, 0.01] {
        let (s, c) = deg.to_radians().sin_cos();
        let d = turn.transform_vector3(DVec3::new(0.0, -s, c));
        let p = turn.transform_point3(DVec3::new(0.0, 1.0 + 1e-3, -1.5));
        // Where the ray meets the cap plane.
        let down = 1e-3 / s;
        let len = 1.0;
        let (v, step) = f.segment_step_f64(p, d, len);
        assert!((v - 1e-3).abs() < 1e-9, "value {v}");
        // Never past the cap, and at least the segment (or the way down when shorter): the
        // plain sphere-tracing step would be 1e-3.
        assert!(
            step <= down * (1.0 + 1e-6) && step >= len.min(down) * 0.99,
            "{deg} deg: step {step}, cap at {down}"
        );
    }
}

#[test]
fn a_ray_passing_a_sphere_steps_past_it_and_a_ray_towards_it_stops_before_it() {
    let f = field(&at(
        NodeKind::Leaf(Shape::Sphere { radius: 1.0 }),
        DVec3::new(0.0, 0.0, 5.0),
    ));
    // Passing 1.01 from the centre: the bound along the ray is small near closest approach
    // (|u| <= 0.1 on this segment: lambda ~ 0.1).
    let p = Vec3::new(1.01, 0.0, 4.9);
    let (v, step) = f.segment_step(p, Vec3::Z, 0.2);
    assert!(step > 5.0 * v, "step {step}, distance {v}");
    // Straight at it: the plain step.
    let (v, step) = f.segment_step(Vec3::ZERO, Vec3::Z, 8.0);
    assert!((step - v).abs() < 1e-5 * v, "step {step}, distance {v}");
}
