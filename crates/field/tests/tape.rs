//! The flattened tape ([`marchmesh_field::tape`]) against the interpreter: bit for bit the
//! same distances and materials on unions of analytic leaves (bounded and unbounded, the
//! nearer-first pair, a single leaf); and the forward-mode gradient
//! ([`Field::distance_gradient_x8`]) against f64 central differences; the 8-lane segment
//! step ([`Field::segment_lanes`]) bit for bit the interpreter's ([`Field::segment_step`]);
//! rays [`Field::recedes`] calls receding meet no surface.

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_field::lane::{F32x8, V3};
use marchmesh_field::{Field, FieldOptions};
use marchmesh_scene::{Node, NodeKind, Shape, compose_transform};
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

fn field(n: &Node) -> Field {
    Field::compile_node(n, DAffine3::IDENTITY, &FieldOptions::default()).expect("compiles")
}

fn union(children: Vec<Node>) -> Node {
    node(NodeKind::Union(children), DAffine3::IDENTITY, 0)
}

/// Leaves of every analytic kind, rotated, translated and scaled, materials 1..
fn leaves() -> Vec<Node> {
    let xf = |t: [f64; 3], r: [f64; 3], s: f64| {
        compose_transform(DVec3::from(t), DVec3::from(r), DVec3::splat(s))
    };
    vec![
        node(
            NodeKind::Leaf(Shape::Sphere { radius: 0.7 }),
            xf([0.5, 0.2, 3.0], [0.0; 3], 1.0),
            1,
        ),
        node(
            NodeKind::Leaf(Shape::Box {
                half_extents: DVec3::new(0.4, 0.3, 0.5),
            }),
            xf([1.1, -0.6, 2.2], [10.0, 35.0, 0.0], 1.0),
            2,
        ),
        node(
            NodeKind::Leaf(Shape::Ellipsoid {
                radii: DVec3::new(0.9, 0.3, 0.5),
            }),
            xf([-1.0, 0.4, 2.5], [0.0, 20.0, 40.0], 1.0),
            3,
        ),
        node(
            NodeKind::Leaf(Shape::Torus {
                major_radius: 0.6,
                minor_radius: 0.2,
            }),
            xf([0.0, -1.0, 4.0], [60.0, 0.0, 20.0], 1.3),
            4,
        ),
        node(
            NodeKind::Leaf(Shape::Cylinder {
                radius: 0.3,
                half_height: 1.0,
            }),
            xf([-1.5, -0.5, 3.5], [0.0, 0.0, 15.0], 1.0),
            5,
        ),
        node(
            NodeKind::Leaf(Shape::Triangle {
                vertices: [
                    DVec3::new(-1.0, 0.0, 5.0),
                    DVec3::new(1.0, 0.3, 5.0),
                    DVec3::new(0.0, 1.5, 5.5),
                ],
            }),
            DAffine3::IDENTITY,
            6,
        ),
        node(
            NodeKind::Leaf(Shape::Plane {
                normal: DVec3::Y,
                offset: -2.0,
            }),
            DAffine3::IDENTITY,
            7,
        ),
    ]
}

fn cases() -> Vec<(&'static str, Field)> {
    let l = leaves();
    vec![
        ("all leaves", field(&union(l.clone()))),
        ("bounded leaves", field(&union(l[2..6].to_vec()))),
        // Two bounded members: visited nearer first.
        ("pair", field(&union(vec![l[2].clone(), l[3].clone()]))),
        ("single sphere", field(&l[0])),
        ("single ellipsoid", field(&l[2])),
        (
            "all leaves without bounds",
            field(&union(l.clone())).without_bounds(),
        ),
    ]
}

#[test]
fn small_unions_of_leaves_get_a_tape_and_others_do_not() {
    for (name, f) in cases() {
        assert!(f.has_tape(), "{name}");
    }
    let l = leaves();
    let nested = union(vec![union(l[..2].to_vec()), l[2].clone()]);
    assert!(!field(&nested).has_tape());
    let csg = node(
        NodeKind::Subtraction(l[..2].to_vec()),
        DAffine3::IDENTITY,
        0,
    );
    assert!(!field(&csg).has_tape());
}

fn pt() -> impl Strategy<Value = DVec3> {
    (-3.0f64..3.0, -3.0f64..3.0, -1.0f64..7.0).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn tapes_are_bit_for_bit_the_interpreter(p in pt(), spread in 0.0f64..2.0) {
        for (name, f) in cases() {
            // Lanes near and far apart (the root's and the leaves' skips decide per lane).
            let pts: [Vec3; 8] = std::array::from_fn(|i| {
                (p + DVec3::new(i as f64 * 0.37, -(i as f64) * 0.21, 0.1) * spread).as_vec3()
            });
            let lanes = f.distance_x8(pts);
            let (dm, mm) = f.distance_material_x8(pts);
            for i in 0..8 {
                prop_assert_eq!(lanes[i].to_bits(), f.distance(pts[i]).to_bits(), "{} lane {}", name, i);
                let (d, m) = f.distance_material(pts[i]);
                prop_assert_eq!((dm[i].to_bits(), mm[i]), (d.to_bits(), m), "{} lane {}", name, i);
            }
        }
    }

    /// Lanes near different leaves in any pattern (several lanes on one leaf, which
    /// `nearest_gradients_x8` differentiates once in eight lanes, and lanes alone on theirs,
    /// which take the scalar path): each lane bit for bit the one-point gradient.
    #[test]
    fn mixed_lanes_get_each_points_nearest_gradient(
        pick in proptest::array::uniform8(0usize..7),
        off in proptest::array::uniform8((-0.6f64..0.6, -0.6f64..0.6, -0.6f64..0.6)),
    ) {
        // Near each leaf of `leaves()` (the plane's point below the others).
        let near = [
            [0.5, 0.2, 3.0], [1.1, -0.6, 2.2], [-1.0, 0.4, 2.5], [0.0, -1.0, 4.0],
            [-1.5, -0.5, 3.5], [0.0, 0.6, 5.2], [2.5, -2.1, 6.0],
        ];
        for (name, f) in cases() {
            let pts: [Vec3; 8] = std::array::from_fn(|i| {
                let (x, y, z) = off[i];
                (DVec3::from(near[pick[i]]) + DVec3::new(x, y, z)).as_vec3()
            });
            let lanes = f.nearest_gradients_x8(pts).expect("a tape");
            for i in 0..8 {
                let one = f.nearest_gradient(pts[i]).expect("a tape");
                prop_assert_eq!(one.to_array().map(f32::to_bits), lanes[i].to_array().map(f32::to_bits),
                    "{} lane {} at {}", name, i, pts[i]);
            }
        }
    }

    #[test]
    fn gradients_are_the_fields_derivative(p in pt()) {
        for (name, f) in cases() {
            let pts: [Vec3; 8] = std::array::from_fn(|i| (p + DVec3::new(0.0, 0.0, i as f64 * 0.05)).as_vec3());
            let (d, g) = f.distance_gradient_x8(pts).expect("no mesh grids");
            prop_assert_eq!(d, f.distance_x8(pts), "{}", name);
            // The nearest leaf's gradient: one point at a time bit for bit the lanes'.
            let near = f.nearest_gradients_x8(pts).expect("a tape");
            for i in 0..8 {
                let one = f.nearest_gradient(pts[i]).expect("a tape");
                prop_assert_eq!(one.to_array().map(f32::to_bits), near[i].to_array().map(f32::to_bits),
                    "{} lane {}", name, i);
            }
            for i in 0..8 {
                let q = pts[i].as_dvec3();
                let h = 1e-5;
                let c = |e: DVec3| (f.distance_f64(q + e * h) - f.distance_f64(q - e * h)) / (2.0 * h);
                let want = DVec3::new(c(DVec3::X), c(DVec3::Y), c(DVec3::Z));
                // Away from creases (where the two one-sided derivatives differ) the
                // analytic gradient is the difference quotient's limit.
                let one_sided = |e: DVec3| (f.distance_f64(q + e * h) - f.distance_f64(q)) / h;
                let smooth = [DVec3::X, DVec3::Y, DVec3::Z]
                    .iter()
                    .all(|&e| (one_sided(e) + one_sided(-e)).abs() < 1e-3);
                if smooth {
                    prop_assert!((g[i].as_dvec3() - want).length() < 2e-3,
                        "{} lane {}: {} vs {}", name, i, g[i], want);
                }
            }
        }
    }

    #[test]
    fn lane_segment_steps_are_bit_for_bit_the_interpreter(
        p in pt(),
        dir in pt(),
        axis in 0usize..4,
        spread in 0.0f64..2.0,
        len in 0.001f64..20.0,
    ) {
        // Some rays parallel to the boxes' slabs (`axis` < 3 zeroes one component).
        let mut dir = dir - DVec3::new(0.0, 0.0, 3.0);
        if axis < 3 {
            dir[axis] = 0.0;
        }
        for (name, f) in cases() {
            let pts: [Vec3; 8] = std::array::from_fn(|i| {
                (p + DVec3::new(i as f64 * 0.37, -(i as f64) * 0.21, 0.1) * spread).as_vec3()
            });
            let dirs: [Vec3; 8] = std::array::from_fn(|i| {
                (dir + DVec3::new(0.0, i as f64 * 0.1, 0.0) * spread).as_vec3()
            });
            let lens: [f32; 8] = std::array::from_fn(|i| (len * (1.0 + i as f64 * 0.5)) as f32);
            let (v, s) = f
                .segment_lanes(V3::from_points(pts), V3::from_points(dirs), F32x8(lens))
                .expect("a tape");
            for i in 0..8 {
                let (sv, ss) = f.segment_step(pts[i], dirs[i], lens[i]);
                prop_assert_eq!((v.0[i].to_bits(), s.0[i].to_bits()), (sv.to_bits(), ss.to_bits()),
                    "{} lane {}: ({}, {}) vs ({}, {})", name, i, v.0[i], s.0[i], sv, ss);
                // The value is the distance (lockstep bundles use it as such).
                prop_assert_eq!(v.0[i].to_bits(), f.distance(pts[i]).to_bits(), "{} lane {}", name, i);
            }
        }
    }

    #[test]
    fn receding_rays_meet_no_surface(p in pt(), dir in pt(), axis in 0usize..4) {
        let mut dir = dir - DVec3::new(0.0, 0.0, 3.0);
        if axis < 3 {
            dir[axis] = 0.0;
        }
        prop_assume!(dir.length() > 1e-3);
        let unit = dir.normalize();
        for (name, f) in cases() {
            if !(f.distance_f64(p) > 1e-3 && f.recedes(p.as_vec3(), dir.as_vec3())) {
                continue;
            }
            // Every sample out to 200 units (finer near the start) stays outside.
            for k in 1..=4000 {
                let t = 0.05 * f64::from(k) * (1.0 + f64::from(k) / 2000.0);
                let d = f.distance_f64(p + unit * t);
                prop_assert!(d > 0.0, "{}: {} at t = {} from {:?} along {:?}", name, d, t, p, dir);
            }
        }
    }
}

#[test]
fn rays_leaving_every_leaf_recede_and_others_do_not() {
    let l = leaves();
    let f = field(&union(l.clone()));
    // Straight up from above the scene, past the plane (y = -2): away from everything.
    let above = Vec3::new(0.0, 3.0, 3.0);
    assert!(f.recedes(above, Vec3::Y));
    // Up from just above the plane between the objects, tilted back towards the camera.
    assert!(f.recedes(Vec3::new(0.0, -1.9, -2.0), Vec3::new(0.0, 1.0, -1.0)));
    // Towards the sphere, and down towards the plane: not receding.
    assert!(!f.recedes(Vec3::new(0.5, 0.2, 0.0), Vec3::Z));
    assert!(!f.recedes(above, -Vec3::Y));
    // A ray that still meets the torus's box: not provably receding.
    assert!(!f.recedes(Vec3::new(0.0, -1.0, 0.0), Vec3::Z));
    // Without a tape the question is not answered.
    let csg = node(
        NodeKind::Subtraction(l[..2].to_vec()),
        DAffine3::IDENTITY,
        0,
    );
    assert!(!field(&csg).recedes(above, Vec3::Y));
}

/// Mesh grids are tape leaves too: a union of a baked mesh (dense and sparse), a sphere and
/// a plane gets a tape whose lanes are bit for bit the interpreter's (distances, materials,
/// segment steps); rays it calls receding meet no surface; the nearest leaf's gradient is
/// analytic for the sphere and the plane and NaN for the grid (sampled without a
/// derivative: the tracer then differentiates the field); the whole-field dual gradient
/// is not offered.
#[test]
fn unions_with_mesh_grids_get_a_tape_bit_for_bit_the_interpreter() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/meshes/bunny.obj");
    let bunny = node(
        NodeKind::Leaf(Shape::Mesh { path }),
        compose_transform(
            DVec3::new(0.3, -0.2, 3.0),
            DVec3::new(0.0, 30.0, 0.0),
            DVec3::splat(0.15),
        ),
        4,
    );
    let scene = union(vec![
        bunny,
        leaves()[0].clone(),
        node(
            NodeKind::Leaf(Shape::Plane {
                normal: DVec3::Y,
                offset: -1.0,
            }),
            DAffine3::IDENTITY,
            5,
        ),
    ]);
    let mut rng = 5u64;
    let mut next = move || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    for grid in [
        marchmesh_field::MeshGrid::Dense,
        marchmesh_field::MeshGrid::SPARSE_DEFAULT,
    ] {
        let opts = FieldOptions {
            mesh_grid_resolution: 32,
            mesh_grid: grid,
            ..FieldOptions::default()
        };
        let f = Field::compile_node(&scene, DAffine3::IDENTITY, &opts).expect("compiles");
        assert!(f.has_tape(), "{grid:?}");
        assert!(f.distance_gradient_x8([Vec3::ZERO; 8]).is_none());
        let (mut receding, mut mesh_nearest, mut analytic_nearest) = (0, 0, 0);
        for _ in 0..300 {
            let p = DVec3::new(next() * 6.0 - 3.0, next() * 4.0 - 1.5, next() * 6.0);
            let spread = next() * 2.0;
            let pts: [Vec3; 8] = std::array::from_fn(|i| {
                (p + DVec3::new(i as f64 * 0.37, -(i as f64) * 0.21, 0.1) * spread).as_vec3()
            });
            let dir = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
            let dirs: [Vec3; 8] = std::array::from_fn(|i| {
                (dir + DVec3::new(0.0, i as f64 * 0.1, 0.0) * spread).as_vec3()
            });
            let lens: [f32; 8] = std::array::from_fn(|i| (0.05 + next() * 3.0 * i as f64) as f32);
            let lanes = f.distance_x8(pts);
            let (dm, mm) = f.distance_material_x8(pts);
            let (v, s) = f
                .segment_lanes(V3::from_points(pts), V3::from_points(dirs), F32x8(lens))
                .expect("a tape");
            for i in 0..8 {
                let at = format!("{grid:?} lane {i} at {}", pts[i]);
                assert_eq!(lanes[i].to_bits(), f.distance(pts[i]).to_bits(), "{at}");
                let (d, m) = f.distance_material(pts[i]);
                assert_eq!((dm[i].to_bits(), mm[i]), (d.to_bits(), m), "{at}");
                let (sv, ss) = f.segment_step(pts[i], dirs[i], lens[i]);
                assert_eq!(
                    (v.0[i].to_bits(), s.0[i].to_bits()),
                    (sv.to_bits(), ss.to_bits()),
                    "{at}"
                );
            }
            // Points on the surfaces: the nearest leaf's gradient.
            let on: [Vec3; 8] = std::array::from_fn(|i| {
                let q = pts[i];
                q - Vec3::Y * f.distance(q).max(0.0) * if i % 2 == 0 { 1.0 } else { 0.0 }
            });
            // `None` only when every lane is nearest the grid.
            let g = f.nearest_gradients_x8(on).unwrap_or([Vec3::NAN; 8]);
            for i in 0..8 {
                let one = f.nearest_gradient(on[i]).expect("a tape");
                assert_eq!(
                    g[i].to_array().map(f32::to_bits),
                    one.to_array().map(f32::to_bits)
                );
                let (_, m) = f.distance_material(on[i]);
                if m == 4 {
                    mesh_nearest += 1;
                    assert!(
                        g[i].is_nan(),
                        "{grid:?}: the grid's lanes have no derivative"
                    );
                } else {
                    analytic_nearest += 1;
                    assert!((g[i].length() - 1.0).abs() < 1e-3, "{grid:?}: {}", g[i]);
                }
            }
            // Receding rays stay outside every surface out to 200 units (rays climbing
            // away from the plane, which no ray going down leaves behind).
            let (q, u) = (p, (dir.with_y(dir.y.abs() + 0.2)).normalize());
            if f.distance_f64(q) > 1e-3 && f.recedes(q.as_vec3(), u.as_vec3()) {
                receding += 1;
                for k in 1..=2000 {
                    let t = 0.1 * f64::from(k) * (1.0 + f64::from(k) / 1000.0);
                    assert!(
                        f.distance_f64(q + u * t) > 0.0,
                        "{grid:?}: {q} along {u}, t {t}"
                    );
                }
            }
        }
        assert!(
            receding > 10 && mesh_nearest > 10 && analytic_nearest > 10,
            "{grid:?}: the cases are exercised ({receding}, {mesh_nearest}, {analytic_nearest})"
        );
    }
}
