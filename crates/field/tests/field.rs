//! Field tests: primitives against independent closed forms or brute force, bounds never
//! over-estimating, Lipschitz property of every operator, repetition at cell borders,
//! f32/f64/8-lane agreement, materials.

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_field::{Field, FieldOptions, MeshGrid};
use marchmesh_scene::{Node, NodeKind, Shape, SmoothOp, compose_transform};
use proptest::prelude::*;

fn node(kind: NodeKind, transform: DAffine3, material: u32) -> Node {
    Node {
        transform,
        material,
        name: None,
        json_path: "test".into(),
        kind,
    }
}

fn leaf(kind: NodeKind) -> Node {
    node(kind, DAffine3::IDENTITY, 0)
}

fn at(kind: NodeKind, t: DVec3) -> Node {
    node(kind, DAffine3::from_translation(t), 0)
}

/// A deterministic uniform sequence in [0, 1) (a 64-bit LCG, Knuth's MMIX constants) for
/// test points.
fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut rng = seed;
    move || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn field(n: &Node) -> Field {
    Field::compile_node(n, DAffine3::IDENTITY, &FieldOptions::default()).expect("compiles")
}

fn sphere(r: f64) -> NodeKind {
    NodeKind::Leaf(Shape::Sphere { radius: r })
}

/// Independent exact box distance: clamp for the outside, nearest face inside.
fn box_exact(p: DVec3, b: DVec3) -> f64 {
    let c = p.clamp(-b, b);
    if c != p {
        (p - c).length()
    } else {
        -(b - p.abs()).min_element()
    }
}

/// Independent exact cylinder distance in the (radial, y) half plane.
fn cyl_exact(p: DVec3, r: f64, h: f64) -> f64 {
    let q = glam::DVec2::new(DVec3::new(p.x, 0.0, p.z).length(), p.y.abs());
    let c = q.clamp(glam::DVec2::ZERO, glam::DVec2::new(r, h));
    if c != q {
        (q - c).length()
    } else {
        -(r - q.x).min(h - q.y)
    }
}

/// Independent exact torus distance: closest point on the core circle.
fn torus_exact(p: DVec3, big: f64, small: f64) -> f64 {
    let radial = DVec3::new(p.x, 0.0, p.z);
    let core = if radial.length() > 0.0 {
        radial.normalize() * big
    } else {
        DVec3::new(big, 0.0, 0.0)
    };
    (p - core).length() - small
}

/// Exact distance to an ellipsoid surface (Eberly: bisection on the 1D root), f64.
fn ellipsoid_exact(p: DVec3, r: DVec3) -> f64 {
    let q = p.abs();
    let inside = (q / r).length_squared() < 1.0;
    // Closest point x_i = r_i^2 q_i / (t + r_i^2), with F(t) = sum (r_i q_i / (t + r_i^2))^2 = 1.
    let f = |t: f64| -> f64 {
        (0..3)
            .map(|i| {
                let v = r[i] * q[i] / (t + r[i] * r[i]);
                v * v
            })
            .sum::<f64>()
            - 1.0
    };
    let rmin2 = r.min_element().powi(2);
    let (mut lo, mut hi) = if inside {
        (-rmin2, 0.0)
    } else {
        (0.0, q.length() * r.max_element() + 1.0)
    };
    if !inside {
        while f(hi) > 0.0 {
            hi *= 2.0;
        }
    }
    // F is decreasing on (-rmin^2, inf).
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let t = 0.5 * (lo + hi);
    let x = DVec3::new(
        r.x * r.x * q.x / (t + r.x * r.x),
        r.y * r.y * q.y / (t + r.y * r.y),
        r.z * r.z * q.z / (t + r.z * r.z),
    );
    let d = (q - x).length();
    // Degenerate inside cases (point on an axis) may pick a worse stationary point; also
    // compare with the axis-aligned candidates, which are always on the surface.
    if inside {
        let mut best = d;
        for i in 0..3 {
            let mut c = q;
            let others: f64 = (0..3)
                .filter(|&j| j != i)
                .map(|j| (q[j] / r[j]).powi(2))
                .sum();
            if others < 1.0 {
                c[i] = r[i] * (1.0 - others).sqrt();
                best = best.min((q - c).length());
            }
        }
        -best
    } else {
        d
    }
}

/// Brute force distance to a triangle by dense barycentric sampling (upper bound, within
/// the sampling spacing of the true value).
fn triangle_brute(p: DVec3, v: [DVec3; 3], n: usize) -> f64 {
    let mut best = f64::INFINITY;
    for i in 0..=n {
        for j in 0..=(n - i) {
            let a = i as f64 / n as f64;
            let b = j as f64 / n as f64;
            let q = v[0] + (v[1] - v[0]) * a + (v[2] - v[0]) * b;
            best = best.min((p - q).length());
        }
    }
    best
}

fn pt() -> impl Strategy<Value = DVec3> {
    (-4.0f64..4.0, -4.0f64..4.0, -4.0f64..4.0).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn exact_primitives(p in pt()) {
        let s = field(&leaf(sphere(1.3)));
        prop_assert!((s.distance_f64(p) - (p.length() - 1.3)).abs() < 1e-12);
        let b = DVec3::new(1.0, 0.5, 2.0);
        let bx = field(&leaf(NodeKind::Leaf(Shape::Box { half_extents: b })));
        prop_assert!((bx.distance_f64(p) - box_exact(p, b)).abs() < 1e-12);
        let c = field(&leaf(NodeKind::Leaf(Shape::Cylinder { radius: 0.8, half_height: 1.5 })));
        prop_assert!((c.distance_f64(p) - cyl_exact(p, 0.8, 1.5)).abs() < 1e-12);
        let t = field(&leaf(NodeKind::Leaf(Shape::Torus { major_radius: 2.0, minor_radius: 0.5 })));
        prop_assert!((t.distance_f64(p) - torus_exact(p, 2.0, 0.5)).abs() < 1e-12);
        let n = DVec3::new(1.0, 2.0, -0.5).normalize();
        let pl = field(&leaf(NodeKind::Leaf(Shape::Plane { normal: n, offset: 0.7 })));
        prop_assert!((pl.distance_f64(p) - (n.dot(p) - 0.7)).abs() < 1e-12);
    }

    #[test]
    fn triangle_matches_brute_force(p in pt()) {
        let v = [DVec3::new(-1.0, 0.2, 0.1), DVec3::new(2.0, -0.5, 0.3), DVec3::new(0.3, 1.7, -0.8)];
        let f = field(&leaf(NodeKind::Leaf(Shape::Triangle { vertices: v })));
        let d = f.distance_f64(p);
        let brute = triangle_brute(p, v, 200);
        // Sampling spacing: the longest edge / 200.
        let h = 3.2 / 200.0;
        prop_assert!(d >= 0.0);
        prop_assert!(d <= brute + 1e-12, "d {d} brute {brute}");
        prop_assert!(d >= brute - h, "d {d} brute {brute}");
    }

    #[test]
    fn ellipsoid_bound_never_over_estimates(p in pt()) {
        let r = DVec3::new(2.0, 0.5, 1.0);
        let f = field(&leaf(NodeKind::Leaf(Shape::Ellipsoid { radii: r })));
        let d = f.distance_f64(p);
        let exact = ellipsoid_exact(p, r);
        prop_assert_eq!(d < 0.0, exact < 0.0);
        prop_assert!(d.abs() <= exact.abs() + 1e-9, "bound {d} exact {exact}");
        // Stretched sphere (non-uniform scale) is corrected by the smallest singular value.
        let s = node(sphere(1.0), compose_transform(DVec3::ZERO, DVec3::new(10.0, 20.0, 30.0), r), 0);
        let fs = field(&s);
        let rot = compose_transform(DVec3::ZERO, DVec3::new(10.0, 20.0, 30.0), DVec3::ONE);
        let local = rot.inverse().transform_point3(p);
        let exact = ellipsoid_exact(local, r);
        let ds = fs.distance_f64(p);
        prop_assert_eq!(ds < 0.0, exact < 0.0);
        prop_assert!(ds.abs() <= exact.abs() + 1e-9, "scaled {ds} exact {exact}");
    }

    #[test]
    fn rigid_and_uniform_transforms_exact(p in pt(), s in 0.2f64..3.0) {
        let b = DVec3::new(0.7, 0.4, 1.1);
        let xf = compose_transform(DVec3::new(0.5, -1.0, 2.0), DVec3::new(30.0, -40.0, 75.0), DVec3::splat(s));
        let f = field(&node(NodeKind::Leaf(Shape::Box { half_extents: b }), xf, 0));
        let local = xf.inverse().transform_point3(p);
        prop_assert!((f.distance_f64(p) - s * box_exact(local, b)).abs() < 1e-9);
    }

    #[test]
    fn union_is_exact_outside_and_a_bound_inside(p in pt()) {
        let u = node(NodeKind::Union(vec![
            at(sphere(1.0), DVec3::new(-1.0, 0.0, 0.0)),
            at(NodeKind::Leaf(Shape::Torus { major_radius: 1.0, minor_radius: 0.3 }), DVec3::new(1.5, 0.0, 0.0)),
            at(NodeKind::Leaf(Shape::Cylinder { radius: 0.5, half_height: 1.0 }), DVec3::new(0.0, 2.0, 0.0)),
        ]), DAffine3::IDENTITY, 0);
        let f = field(&u);
        let e = ((p - DVec3::new(-1.0, 0.0, 0.0)).length() - 1.0)
            .min(torus_exact(p - DVec3::new(1.5, 0.0, 0.0), 1.0, 0.3))
            .min(cyl_exact(p - DVec3::new(0.0, 2.0, 0.0), 0.5, 1.0));
        let d = f.distance_f64(p);
        // The union's own box takes over beyond its tau (half its diagonal, > 2 here):
        // exact below, a lower bound above.
        prop_assert!(d <= e + 1e-12);
        if e < 1.0 {
            prop_assert!((d - e).abs() < 1e-12, "d {d} e {e}");
        }
    }
}

/// Nodes exercising every operator (and transforms, repetition) for the Lipschitz test.
fn operator_cases() -> Vec<(&'static str, Node)> {
    let a = at(
        NodeKind::Leaf(Shape::Box {
            half_extents: DVec3::new(1.0, 0.6, 0.8),
        }),
        DVec3::new(0.3, 0.0, 0.0),
    );
    let b = at(sphere(0.9), DVec3::new(-0.4, 0.5, 0.2));
    let c = node(
        NodeKind::Leaf(Shape::Torus {
            major_radius: 0.8,
            minor_radius: 0.25,
        }),
        compose_transform(
            DVec3::new(0.0, -0.3, 0.0),
            DVec3::new(60.0, 0.0, 20.0),
            DVec3::ONE,
        ),
        0,
    );
    let stretched = node(
        sphere(1.0),
        compose_transform(
            DVec3::ZERO,
            DVec3::new(15.0, 25.0, 0.0),
            DVec3::new(2.0, 0.3, 1.0),
        ),
        0,
    );
    let ell = leaf(NodeKind::Leaf(Shape::Ellipsoid {
        radii: DVec3::new(1.5, 0.4, 0.9),
    }));
    let tri = leaf(NodeKind::Leaf(Shape::Triangle {
        vertices: [
            DVec3::new(-1.0, 0.0, 0.0),
            DVec3::new(1.0, 0.3, 0.0),
            DVec3::new(0.0, 1.5, 0.5),
        ],
    }));
    let op = |k: NodeKind| node(k, DAffine3::IDENTITY, 0);
    vec![
        (
            "union",
            op(NodeKind::Union(vec![a.clone(), b.clone(), c.clone()])),
        ),
        (
            "intersection",
            op(NodeKind::Intersection(vec![a.clone(), b.clone()])),
        ),
        (
            "subtraction",
            op(NodeKind::Subtraction(vec![a.clone(), b.clone(), c.clone()])),
        ),
        (
            "smooth_union",
            op(NodeKind::Smooth {
                op: SmoothOp::Union,
                children: vec![a.clone(), b.clone(), c.clone()],
                blend_radius: 0.5,
            }),
        ),
        ("non_uniform_scale", stretched),
        ("ellipsoid", ell),
        ("triangle", tri),
        (
            "repeat_infinite",
            op(NodeKind::Repeat {
                child: Box::new(b.clone()),
                period: DVec3::new(2.5, 0.0, 3.0),
                count: [None; 3],
            }),
        ),
        (
            "repeat_limited",
            op(NodeKind::Repeat {
                child: Box::new(c.clone()),
                period: DVec3::new(2.0, 2.0, 0.0),
                count: [Some(3), Some(2), None],
            }),
        ),
        (
            "repeat_wide_child",
            // The child is wider than its cell: more neighbours are evaluated.
            op(NodeKind::Repeat {
                child: Box::new(a.clone()),
                period: DVec3::new(1.5, 0.0, 0.0),
                count: [Some(4), None, None],
            }),
        ),
        (
            "scaled_csg",
            node(
                NodeKind::Subtraction(vec![a, b]),
                compose_transform(
                    DVec3::new(1.0, 2.0, 0.0),
                    DVec3::new(0.0, 45.0, 0.0),
                    DVec3::new(1.5, 0.5, 1.0),
                ),
                0,
            ),
        ),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn every_operator_is_lipschitz(p in pt(), dir in pt(), len in 0.0f64..0.5) {
        let q = p + dir.normalize_or_zero() * len;
        for (name, n) in operator_cases() {
            let f = field(&n);
            let (a, b) = (f.distance_f64(p), f.distance_f64(q));
            prop_assert!((a - b).abs() <= (p - q).length() * (1.0 + 1e-9) + 1e-12,
                "{name}: |{a} - {b}| > {}", (p - q).length());
        }
    }

    #[test]
    fn f32_f64_and_8_lanes_agree(p in pt()) {
        for (name, n) in operator_cases() {
            let f = field(&n);
            let d64 = f.distance_f64(p);
            let d32 = f.distance(p.as_vec3());
            prop_assert!((d64 - d32 as f64).abs() < 1e-5, "{name}: {d64} vs {d32}");
            let pts: [Vec3; 8] = std::array::from_fn(|i| (p + DVec3::new(i as f64 * 0.37, -(i as f64) * 0.21, 0.1)).as_vec3());
            let lanes = f.distance_x8(pts);
            let (dm, mm) = f.distance_material_x8(pts);
            for i in 0..8 {
                prop_assert_eq!(lanes[i], f.distance(pts[i]), "{} lane {}", name, i);
                prop_assert_eq!((dm[i], mm[i]), f.distance_material(pts[i]), "{} lane {}", name, i);
            }
        }
    }
}

/// min over all copies of a repeated child computed directly (brute force over copies).
fn repeat_brute(child: &Field, p: DVec3, period: DVec3, count: [Option<u32>; 3]) -> f64 {
    let range = |a: usize| -> Vec<f64> {
        if period[a] == 0.0 {
            return vec![0.0];
        }
        match count[a] {
            Some(n) => (0..n)
                .map(|i| (i as f64 - (n as f64 - 1.0) * 0.5) * period[a])
                .collect(),
            None => (-20..=20).map(|i| i as f64 * period[a]).collect(),
        }
    };
    let mut best = f64::INFINITY;
    for x in range(0) {
        for y in range(1) {
            for z in range(2) {
                best = best.min(child.distance_f64(p - DVec3::new(x, y, z)));
            }
        }
    }
    best
}

#[test]
fn repetition_is_exact_below_the_window_and_continuous_at_borders() {
    let child = node(
        NodeKind::Leaf(Shape::Torus {
            major_radius: 0.9,
            minor_radius: 0.3,
        }),
        compose_transform(
            DVec3::new(0.1, 0.0, -0.05),
            DVec3::new(80.0, 10.0, 0.0),
            DVec3::ONE,
        ),
        0,
    );
    let cf = field(&child);
    for (period, count) in [
        (DVec3::new(2.5, 0.0, 2.5), [None, None, None]),
        (DVec3::new(2.5, 3.0, 0.0), [Some(3), Some(4), None]),
        (DVec3::new(1.2, 0.0, 0.0), [Some(5), None, None]), // child wider than its cell
    ] {
        let rep = node(
            NodeKind::Repeat {
                child: Box::new(child.clone()),
                period,
                count,
            },
            DAffine3::IDENTITY,
            0,
        );
        let f = field(&rep);
        let r = period.max_element().min(
            [period.x, period.y, period.z]
                .into_iter()
                .filter(|v| *v > 0.0)
                .fold(f64::INFINITY, f64::min),
        ) * 0.5;
        let mut unit = uniform(12345);
        let mut next = || unit() * 12.0 - 6.0;
        for _ in 0..2000 {
            let p = DVec3::new(next(), next() * 0.5, next());
            let d = f.distance_f64(p);
            let brute = repeat_brute(&cf, p, period, count);
            assert!(d <= brute + 1e-9, "{period} {p}: field {d} > brute {brute}");
            // Exact below the window half-width (R is at most half the smallest period).
            if brute < 0.25 * r {
                assert!(
                    (d - brute).abs() < 1e-9,
                    "{period} {p}: field {d} brute {brute}"
                );
            }
        }
        // Crossing every cell border along x: continuous (jump below 2 * eps).
        let eps = 1e-7;
        for i in -4..=4 {
            if period.x == 0.0 {
                continue;
            }
            let x = (i as f64 + 0.5) * period.x;
            for y in [-0.3, 0.0, 0.2] {
                for z in [-1.1, 0.0, 0.4] {
                    let a = f.distance_f64(DVec3::new(x - eps, y, z));
                    let b = f.distance_f64(DVec3::new(x + eps, y, z));
                    assert!(
                        (a - b).abs() <= 2.0 * eps * (1.0 + 1e-6),
                        "border x={x}: {a} vs {b}"
                    );
                }
            }
        }
    }
}

#[test]
fn materials_follow_the_surface() {
    let a = node(
        NodeKind::Leaf(Shape::Box {
            half_extents: DVec3::ONE,
        }),
        DAffine3::IDENTITY,
        1,
    );
    let b = node(
        sphere(0.8),
        DAffine3::from_translation(DVec3::new(1.0, 0.0, 0.0)),
        2,
    );
    let u = field(&node(
        NodeKind::Union(vec![a.clone(), b.clone()]),
        DAffine3::IDENTITY,
        0,
    ));
    assert_eq!(u.distance_material(Vec3::new(-2.0, 0.0, 0.0)).1, 1);
    assert_eq!(u.distance_material(Vec3::new(2.5, 0.0, 0.0)).1, 2);
    let s = field(&node(
        NodeKind::Subtraction(vec![a, b]),
        DAffine3::IDENTITY,
        0,
    ));
    // Inside the cut (near the sphere's surface inside the box): the sphere defines it.
    assert_eq!(s.distance_material(Vec3::new(0.15, 0.0, 0.0)).1, 2);
    // On the box's far face: the box.
    assert_eq!(s.distance_material(Vec3::new(-1.05, 0.0, 0.0)).1, 1);
}

#[test]
fn bounds_and_errors() {
    let f = field(&at(sphere(1.0), DVec3::new(2.0, 0.0, 0.0)));
    let (lo, hi) = f.bounds().expect("bounded");
    assert_eq!(
        (lo, hi),
        (DVec3::new(1.0, -1.0, -1.0), DVec3::new(3.0, 1.0, 1.0))
    );
    let pl = field(&leaf(NodeKind::Leaf(Shape::Plane {
        normal: DVec3::Y,
        offset: 0.0,
    })));
    assert!(pl.bounds().is_none());
    let singular = node(
        sphere(1.0),
        DAffine3::from_scale(DVec3::new(1.0, 0.0, 1.0)),
        0,
    );
    let e =
        Field::compile_node(&singular, DAffine3::IDENTITY, &FieldOptions::default()).unwrap_err();
    assert!(e.to_string().contains("test"), "{e}");
    assert!(f.memory_bytes() > 0);
}

#[test]
fn far_subtrees_pay_only_their_bound_and_stay_lower_bounds() {
    // Far away, the value of a complex subtree is the distance to its box.
    let t = at(
        NodeKind::Leaf(Shape::Torus {
            major_radius: 1.0,
            minor_radius: 0.2,
        }),
        DVec3::ZERO,
    );
    let f = field(&t);
    let p = DVec3::new(100.0, 0.0, 0.0);
    assert!((f.distance_f64(p) - 98.8).abs() < 1e-9);
    assert!(
        f.distance_f64(DVec3::new(100.0, 100.0, 0.0))
            <= torus_exact(DVec3::new(100.0, 100.0, 0.0), 1.0, 0.2)
    );
}

#[test]
fn scene_compiles_in_render_space() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/csg.json");
    let scene = marchmesh_scene::load(&path).unwrap();
    let f = Field::compile_scene(&scene, &FieldOptions::default()).unwrap();
    // The camera is outside every solid.
    assert!(f.distance(Vec3::ZERO) > 0.0);
}

#[test]
fn huge_sphere_near_the_frame_origin_keeps_f32_precision() {
    // The seed scene's ground: radius 5000, centre 5001 below the camera.
    let g = at(sphere(5000.0), DVec3::new(0.0, -5001.0, 0.0));
    let f = field(&g);
    for p in [
        DVec3::new(0.3, -1.0 + 5e-4, 2.0),
        DVec3::new(-2.0, -0.999, 5.0),
        DVec3::new(1.0, -1.0 - 2e-4, 3.0),
    ] {
        let exact = (p - DVec3::new(0.0, -5001.0, 0.0)).length() - 5000.0;
        let d32 = f.distance(p.as_vec3()) as f64;
        // Plain |p - c| - r in f32 would be quantised to ulp(5000) = 4.9e-4.
        assert!((d32 - exact).abs() < 2e-6, "{p}: {d32} vs {exact}");
    }
}

#[test]
fn mesh_node_matches_brute_force_distance_within_half_a_cell() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/meshes/bunny.obj");
    let mesh = marchmesh_meshio::load_mesh(&path).expect("committed bunny");
    let xf = compose_transform(
        DVec3::new(0.3, -0.2, 1.0),
        DVec3::new(0.0, 30.0, 0.0),
        DVec3::splat(0.25),
    );
    let n = node(NodeKind::Leaf(Shape::Mesh { path: path.clone() }), xf, 3);
    let f = field(&n);
    let (lo, hi) = mesh.bounds();
    let cell = (hi - lo).max_element() as f64 / 64.0;
    let tol = 0.87 * cell * 0.25 + 1e-5;
    let tris: Vec<[DVec3; 3]> = mesh
        .triangles
        .iter()
        .map(|t| t.map(|i| xf.transform_point3(mesh.positions[i as usize].as_dvec3())))
        .collect();
    let (wlo, whi) = f.bounds().expect("a mesh is bounded");
    let mut next = uniform(7);
    for _ in 0..150 {
        // Points inside the mesh's own box (inside the grid), mapped to the frame.
        let local = lo.as_dvec3() + (hi - lo).as_dvec3() * DVec3::new(next(), next(), next());
        let p = xf.transform_point3(local);
        let exact = tris
            .iter()
            .map(|t| {
                (p - marchmesh_bake::closest_point_on_triangle_f64(p, t[0], t[1], t[2])).length()
            })
            .fold(f64::INFINITY, f64::min);
        let d = f.distance_f64(p);
        // Beyond tau (half the box diagonal) the node's value is capped/boxed: a lower bound.
        let tau = 0.5 * (whi - wlo).length();
        if exact < 0.9 * tau {
            assert!(
                (d.abs() - exact).abs() <= tol,
                "{p}: grid {d} brute {exact} tol {tol}"
            );
        } else {
            assert!(
                d.abs() <= exact + tol,
                "{p}: grid {d} brute {exact} tol {tol}"
            );
        }
        assert_eq!(f.distance_material(p.as_vec3()).1, 3);
    }
    assert!(f.memory_bytes() > 64 * 64 * 4, "the grid is counted");
    assert!(f.report().notes.iter().any(|n| n.contains("distance grid")));
}

/// The f32 tracer samples mesh grids in f32, eight lanes at a time: each lane must equal the
/// single-point f32 lookup bit for bit and stay within f32 rounding of the f64 lookup, for
/// dense and sparse (f32 and u8) grids, at points inside the grid's box and beyond it.
#[test]
fn mesh_grids_in_f32_lanes_match_single_points_and_f64() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/meshes/bunny.obj");
    let xf = compose_transform(
        DVec3::new(0.3, -0.2, 1.0),
        DVec3::new(0.0, 30.0, 0.0),
        DVec3::splat(0.25),
    );
    let n = node(NodeKind::Leaf(Shape::Mesh { path }), xf, 3);
    let sparse_u8 = MeshGrid::Sparse {
        band_voxels: 2,
        quantization: marchmesh_bake::Quantization::U8,
        reconstruction: marchmesh_bake::Reconstruction::Trilinear,
    };
    for grid in [MeshGrid::Dense, MeshGrid::SPARSE_DEFAULT, sparse_u8] {
        let opts = FieldOptions {
            mesh_grid_resolution: 32,
            mesh_grid: grid,
            ..FieldOptions::default()
        };
        // The mesh alone runs on a tape; carved by a sphere (CSG) on the interpreter.
        let carved = node(
            NodeKind::Subtraction(vec![
                n.clone(),
                node(
                    NodeKind::Leaf(Shape::Sphere { radius: 0.2 }),
                    DAffine3::from_translation(DVec3::new(0.3, 0.0, 1.0)),
                    1,
                ),
            ]),
            DAffine3::IDENTITY,
            0,
        );
        for (which, tree) in [("mesh", &n), ("carved mesh", &carved)] {
            let f = Field::compile_node(tree, DAffine3::IDENTITY, &opts).expect("compiles");
            assert_eq!(f.has_tape(), which == "mesh");
            let (lo, hi) = f.bounds().expect("a mesh is bounded");
            let mut next = uniform(11);
            for _ in 0..40 {
                // Points from half a box beyond each side to half a box beyond the other.
                let pts: [Vec3; 8] = std::array::from_fn(|_| {
                    let u = DVec3::new(next(), next(), next()) * 2.0 - 0.5;
                    (lo + (hi - lo) * u).as_vec3()
                });
                let lanes = f.distance_x8(pts);
                for (i, p) in pts.iter().enumerate() {
                    let d32 = f.distance(*p);
                    assert_eq!(
                        lanes[i].to_bits(),
                        d32.to_bits(),
                        "{grid:?} lane {i} at {p}"
                    );
                    let d64 = f.distance_f64(p.as_dvec3());
                    assert!(
                        (d64 - d32 as f64).abs() <= 1e-5 * d64.abs().max(1.0),
                        "{which} {grid:?} at {p}: f32 {d32} vs f64 {d64}"
                    );
                }
            }
        }
    }
}

#[test]
fn large_unions_are_grouped_without_changing_values() {
    let mut next = uniform(99);
    let mut spheres = Vec::new();
    let mut children = vec![node(
        NodeKind::Leaf(Shape::Plane {
            normal: DVec3::Y,
            offset: -3.0,
        }),
        DAffine3::IDENTITY,
        1,
    )];
    for i in 0..200 {
        let c = DVec3::new(
            next() * 20.0 - 10.0,
            next() * 4.0 - 2.0,
            next() * 20.0 - 10.0,
        );
        let r = 0.1 + next() * 0.4;
        spheres.push((c, r, i as u32 + 2));
        children.push(node(sphere(r), DAffine3::from_translation(c), i as u32 + 2));
    }
    let f = field(&node(NodeKind::Union(children), DAffine3::IDENTITY, 0));
    // The hierarchy adds synthetic nodes.
    assert!(f.node_count() > 201, "{}", f.node_count());
    for _ in 0..2000 {
        let p = DVec3::new(
            next() * 22.0 - 11.0,
            next() * 6.0 - 3.5,
            next() * 22.0 - 11.0,
        );
        let (mut e, mut m) = (p.y + 3.0, 1);
        for (c, r, id) in &spheres {
            let d = (p - *c).length() - r;
            if d < e {
                e = d;
                m = *id;
            }
        }
        let (d, mat) = f.distance_material_f64(p);
        // Exact below the union's own tau (half its box diagonal, > 10 here).
        assert!((d - e).abs() < 1e-9, "{p}: {d} vs {e}");
        assert_eq!(mat, m, "{p}");
        let d32 = f.distance(p.as_vec3()) as f64;
        assert!((d32 - e).abs() < 1e-5, "{p}: f32 {d32} vs {e}");
    }
}

#[test]
fn without_bounds_the_field_has_the_same_sign_and_the_same_values_near_surfaces() {
    // Away from a subtree's box its value is replaced by a bound (the box distance, or the
    // value capped at tau); evaluating every node gives the operators' own values. Both are
    // distance bounds of the same surfaces: the sign agrees everywhere and the values agree
    // near the surfaces, where nothing is skipped. Every operator case, near to far.
    for (name, n) in operator_cases() {
        let bounded = field(&n);
        let exact = field(&n).without_bounds();
        assert!(exact.bounds().is_none(), "{name}");
        for i in 0..9 {
            for j in 0..9 {
                for k in 0..9 {
                    let p = DVec3::new(i as f64, j as f64, k as f64) * 1.5 - DVec3::splat(6.0);
                    let (b, e) = (bounded.distance_f64(p), exact.distance_f64(p));
                    assert_eq!(e > 0.0, b > 0.0, "{name} at {p}: sign {e} vs {b}");
                    if e.abs() < 0.05 {
                        assert!((e - b).abs() < 1e-9, "{name} at {p}: {e} vs {b}");
                    }
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    /// `scene::bounds::smooth_fold_deficit` against the field's own kernel: a left-to-right
    /// fold of `n` smooth minima is never more than the deficit below the children's minimum
    /// (random values, clustered within a few blend radii so the kernel is active).
    #[test]
    fn smooth_folds_stay_within_the_fold_deficit(
        k in 0.001f64..2.0,
        values in proptest::collection::vec(-3.0f64..3.0, 1..200),
    ) {
        let vals: Vec<f64> = values.iter().map(|v| v * k).collect();
        let fold = vals[1..].iter().fold(vals[0], |acc, &v| {
            marchmesh_field::shapes::smin(acc, v, k, 1.0 / k)
        });
        let min = vals.iter().copied().fold(f64::INFINITY, f64::min);
        let deficit = marchmesh_scene::bounds::smooth_fold_deficit(k, vals.len());
        prop_assert!(fold <= min + 1e-12 * k);
        prop_assert!(fold >= min - deficit - 1e-12 * k,
            "n = {}: {} below the minimum, bound {}", vals.len(), min - fold, deficit);
    }

    /// The box `combine` gives a smooth union holds its blended surface: random chains of
    /// spheres, the compiled field positive at random points outside the box.
    #[test]
    fn smooth_union_boxes_hold_the_blended_surface(
        k in 0.01f64..0.5,
        steps in proptest::collection::vec((-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0), 1..60),
        probe in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
    ) {
        let mut c = DVec3::ZERO;
        let children: Vec<Node> = steps.iter().map(|&(x, y, z)| {
            c += DVec3::new(x, y, z) * 0.1;
            at(sphere(0.05), c)
        }).collect();
        let n = leaf(NodeKind::Smooth {
            op: SmoothOp::Union, children, blend_radius: k });
        let b = n.bounds_in_own_frame(&|_| None).expect("bounded");
        let f = field(&n);
        // Points on the box's surface and beyond it.
        let dir = DVec3::new(probe.0, probe.1, probe.2);
        let centre = (b.lo + b.hi) * 0.5;
        let half = (b.hi - b.lo) * 0.5;
        let scale = (dir.abs() / half).max_element().max(1e-12);
        for grow in [1.0, 1.01, 1.5] {
            let p = centre + dir / scale * grow;
            prop_assert!(f.distance_f64(p) >= -1e-12, "{p} outside {b:?}: {}", f.distance_f64(p));
        }
        // Equal children reach the deficit, so the growth is needed: the fold at a point
        // equidistant from n coincident spheres is the deficit below their distance.
        let same = leaf(NodeKind::Smooth {
            op: SmoothOp::Union,
            children: vec![leaf(sphere(0.05)); steps.len()],
            blend_radius: k,
        });
        let d = field(&same).distance_f64(DVec3::new(1.0, 0.0, 0.0));
        let want = 0.95 - marchmesh_scene::bounds::smooth_fold_deficit(k, steps.len());
        prop_assert!((d - want).abs() < 1e-9, "{d} vs {want}");
    }
}
