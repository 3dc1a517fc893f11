//! Every 8-lane evaluator of the field against the interpreter, as fidget tests its
//! evaluators: one suite of checks ([`Suite`]), instantiated once per evaluator by
//! [`evaluator_tests!`]. The evaluators are the specialised kernel
//! ([`marchmesh_field::kernel`]), the tape it specialises (kernels off), the function
//! compiled per program ([`marchmesh_field::jit`]), and the interpreter, the kernel or the
//! compiled function on the restricted programs of a bundle of rays; the reference is the f32
//! interpreter one point at a time ([`Field::distance`]), compared bit for bit, on random
//! unions of random leaves of every analytic kind in random frames, with and without bounds,
//! at random points. Plus: which programs get a kernel, and that the leaves it does not
//! specialise take the tape's path (and are still bit for bit the interpreter's).

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_field::{Field, FieldOptions, RayCone, Restricted};
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

/// The field of `n`, kernels on.
fn compile(n: &Node) -> Field {
    let mut f =
        Field::compile_node(n, DAffine3::IDENTITY, &FieldOptions::default()).expect("compiles");
    f.set_kernels(true);
    f
}

fn union(children: Vec<Node>) -> Node {
    node(NodeKind::Union(children), DAffine3::IDENTITY, 0)
}

/// Every analytic shape kind; `k` picks one, `a` and `b` (in `[0, 1)`) size it.
fn shape(k: usize, a: f64, b: f64) -> Shape {
    let s = 0.2 + a;
    let t = 0.1 + 0.5 * b;
    match k % 11 {
        0 => Shape::Sphere { radius: s },
        1 => Shape::Box {
            half_extents: DVec3::new(s, t, 0.5 * (s + t)),
        },
        2 => Shape::Plane {
            normal: DVec3::new(a - 0.5, 1.0, b - 0.5).normalize(),
            offset: -1.5 - a,
        },
        3 => Shape::Ellipsoid {
            radii: DVec3::new(s, t, 0.5 * (s + t)),
        },
        4 => Shape::Cylinder {
            radius: t,
            half_height: s,
        },
        5 => Shape::Torus {
            major_radius: s + t,
            minor_radius: t,
        },
        6 => Shape::RoundedBox {
            half_extents: DVec3::new(s, t, s),
            rounding_radius: 0.4 * t.min(s),
        },
        7 => Shape::Capsule {
            half_height: s,
            radius: t,
        },
        8 => Shape::CappedCone {
            half_height: s,
            bottom_radius: t,
            top_radius: 0.5 * t,
        },
        9 => Shape::Triangle {
            vertices: [
                DVec3::new(-s, 0.0, 0.0),
                DVec3::new(s, t, 0.0),
                DVec3::new(0.0, s, t),
            ],
        },
        // A sphere far out (the compiler keeps huge spheres in the parent frame).
        _ => Shape::Sphere {
            radius: 500.0 + 100.0 * a,
        },
    }
}

/// A random leaf: shape kind, sizes, translation, rotation (none for `rot` < 0.3, so
/// frames without a linear part occur), uniform scale.
fn leaf() -> impl Strategy<Value = Node> {
    (
        0usize..11,
        0.0f64..1.0,
        0.0f64..1.0,
        (-3.0f64..3.0, -2.0f64..2.0, 1.0f64..7.0),
        (0.0f64..1.0, -90.0f64..90.0, -90.0f64..90.0),
        prop_oneof![Just(1.0f64), 0.5f64..2.0],
        1u32..9,
    )
        .prop_map(|(k, a, b, (x, y, z), (rot, ry, rz), scale, material)| {
            let mut t = DVec3::new(x, y, z);
            if k % 11 == 10 {
                // The huge sphere's top near the others.
                t.y -= 500.0 + 100.0 * a + 2.0;
            }
            let r = if rot < 0.3 {
                DVec3::ZERO
            } else {
                DVec3::new(rot * 40.0, ry, rz)
            };
            node(
                NodeKind::Leaf(shape(k, a, b)),
                compose_transform(t, r, DVec3::splat(scale)),
                material,
            )
        })
}

/// A random program: a union of 1 to 9 random leaves (one leaf alone when 1), with its
/// bounds or without them.
fn program() -> impl Strategy<Value = (Node, bool)> {
    (proptest::collection::vec(leaf(), 1..10), any::<bool>()).prop_map(|(mut l, bounds)| {
        let n = if l.len() == 1 { l.remove(0) } else { union(l) };
        (n, bounds)
    })
}

/// Eight lanes around `p`, `spread` apart (near one another or not: the bounds' skips
/// decide per lane).
fn lanes(p: DVec3, spread: f64) -> [Vec3; 8] {
    std::array::from_fn(|i| {
        (p + DVec3::new(
            i as f64 * 0.37,
            -(i as f64) * 0.21,
            0.1 + 0.3 * (i % 3) as f64,
        ) * spread)
            .as_vec3()
    })
}

fn pt() -> impl Strategy<Value = DVec3> {
    (-4.0f64..4.0, -3.0f64..3.0, -1.0f64..8.0).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

/// An 8-lane evaluator of a compiled field.
trait Evaluator {
    /// Prepares `field` (kernels on or off).
    fn prepare(field: Field) -> Field;
    /// The distances at `pts`.
    fn eval(field: &Field, pts: [Vec3; 8]) -> [f32; 8];
}

/// The specialised kernel.
struct KernelEval;
impl Evaluator for KernelEval {
    fn prepare(mut field: Field) -> Field {
        field.set_kernels(true);
        field
    }
    fn eval(field: &Field, pts: [Vec3; 8]) -> [f32; 8] {
        field.distance_x8(pts)
    }
}

/// The tape (kernels off).
struct TapeEval;
impl Evaluator for TapeEval {
    fn prepare(mut field: Field) -> Field {
        field.set_kernels(false);
        field
    }
    fn eval(field: &Field, pts: [Vec3; 8]) -> [f32; 8] {
        field.distance_x8(pts)
    }
}

/// The function compiled per program ([`marchmesh_field::jit`]; the kernel where it does
/// not compile). Needs the crate's `jit` feature.
#[cfg(feature = "jit")]
struct JitEval;
#[cfg(feature = "jit")]
impl Evaluator for JitEval {
    fn prepare(mut field: Field) -> Field {
        field.set_kernels(true);
        field.set_jit(true);
        field
    }
    fn eval(field: &Field, pts: [Vec3; 8]) -> [f32; 8] {
        field.distance_x8(pts)
    }
}

/// [`RestrictedEval`] with JIT compilation on (the restrictions' compiled functions).
#[cfg(feature = "jit")]
struct RestrictedJitEval;
#[cfg(feature = "jit")]
impl Evaluator for RestrictedJitEval {
    fn prepare(field: Field) -> Field {
        JitEval::prepare(field)
    }
    fn eval(field: &Field, pts: [Vec3; 8]) -> [f32; 8] {
        RestrictedEval::eval(field, pts)
    }
}

/// The field restricted to a cone around the lanes from the origin (kernels on): on the
/// lanes' own rays it is the whole field's value wherever no dropped object is nearer, so
/// it is compared with the interpreter on the restricted program.
struct RestrictedEval;
impl Evaluator for RestrictedEval {
    fn prepare(mut field: Field) -> Field {
        field.set_kernels(true);
        field
    }
    fn eval(field: &Field, pts: [Vec3; 8]) -> [f32; 8] {
        match cone(&pts) {
            Some(c) => {
                let mut r = Restricted::default();
                field.restrict_to(&c, &mut r);
                let lanes = field.restricted_distance_x8(&r, pts);
                // The reference for a restriction is its own interpreter.
                for (i, p) in pts.iter().enumerate() {
                    assert_eq!(
                        lanes[i].to_bits(),
                        field.restricted_distance(&r, *p).to_bits(),
                        "restricted lane {i} at {p} (kernel {}, jit {})",
                        r.is_kerneled(),
                        r.is_jitted()
                    );
                }
                field.distance_x8(pts)
            }
            None => field.distance_x8(pts),
        }
    }
}

/// The cone of rays from the origin through `pts`, if they are in front of it.
fn cone(pts: &[Vec3; 8]) -> Option<RayCone> {
    RayCone::around(Vec3::ZERO, pts.iter().copied(), 20.0, 1e-4, 1e-4)
}

/// The checks every evaluator passes.
struct Suite<E>(std::marker::PhantomData<E>);

impl<E: Evaluator> Suite<E> {
    /// Random programs at random points: bit for bit the interpreter.
    fn random_programs() {
        let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig {
            cases: 300,
            ..ProptestConfig::default()
        });
        runner
            .run(
                &(program(), pt(), 0.0f64..2.5),
                |((n, bounds), p, spread)| {
                    let f = compile(&n);
                    let f = E::prepare(if bounds { f } else { f.without_bounds() });
                    let pts = lanes(p, spread);
                    let got = E::eval(&f, pts);
                    for i in 0..8 {
                        prop_assert_eq!(
                            got[i].to_bits(),
                            f.distance(pts[i]).to_bits(),
                            "lane {} at {}: {} vs {}",
                            i,
                            pts[i],
                            got[i],
                            f.distance(pts[i])
                        );
                    }
                    Ok(())
                },
            )
            .expect("bit for bit the interpreter");
    }

    /// Each leaf kind alone and in a union with the others, in frames with and without a
    /// linear part, on a grid of points through and around it.
    fn every_leaf_kind() {
        for k in 0..11 {
            for rot in [DVec3::ZERO, DVec3::new(20.0, 35.0, -10.0)] {
                let n = node(
                    NodeKind::Leaf(shape(k, 0.4, 0.6)),
                    compose_transform(DVec3::new(0.3, -0.2, 3.0), rot, DVec3::splat(1.3)),
                    1,
                );
                let others = node(
                    NodeKind::Leaf(shape(k + 1, 0.2, 0.3)),
                    compose_transform(DVec3::new(-1.0, 0.5, 4.0), rot, DVec3::ONE),
                    2,
                );
                for (name, prog) in [("alone", n.clone()), ("union", union(vec![n, others]))] {
                    let f = E::prepare(compile(&prog));
                    for x in -6..=6 {
                        for y in -6..=6 {
                            let p = DVec3::new(0.3 + 0.31 * x as f64, -0.2 + 0.29 * y as f64, 3.0);
                            let pts = lanes(p, 0.2);
                            let got = E::eval(&f, pts);
                            for i in 0..8 {
                                assert_eq!(
                                    got[i].to_bits(),
                                    f.distance(pts[i]).to_bits(),
                                    "kind {k} {name} rotated {} lane {i} at {}",
                                    rot != DVec3::ZERO,
                                    pts[i]
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// NaN, infinite and signed-zero coordinates: the same bits as the interpreter.
    fn odd_points() {
        let l: Vec<Node> = (0..11)
            .map(|k| {
                node(
                    NodeKind::Leaf(shape(k, 0.5, 0.5)),
                    compose_transform(
                        DVec3::new(k as f64 * 0.4 - 2.0, 0.0, 3.0),
                        DVec3::ZERO,
                        DVec3::ONE,
                    ),
                    1,
                )
            })
            .collect();
        let f = E::prepare(compile(&union(l)));
        let odd = [
            0.0,
            -0.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e30,
            -1e-30,
        ];
        for (j, &v) in odd.iter().enumerate() {
            let pts: [Vec3; 8] = std::array::from_fn(|i| match i % 3 {
                0 => Vec3::new(v, 0.0, 3.0),
                1 => Vec3::new(-0.0, v, -0.0),
                _ => Vec3::new(odd[(j + i) % odd.len()], v, 3.0),
            });
            let got = E::eval(&f, pts);
            for i in 0..8 {
                assert_eq!(
                    got[i].to_bits(),
                    f.distance(pts[i]).to_bits(),
                    "lane {i} at {}",
                    pts[i]
                );
            }
        }
    }
}

/// One test per check for evaluator `$e`, in module `$m`.
macro_rules! evaluator_tests {
    ($m:ident, $e:ty) => {
        mod $m {
            use super::*;
            #[test]
            fn random_programs() {
                Suite::<$e>::random_programs();
            }
            #[test]
            fn every_leaf_kind() {
                Suite::<$e>::every_leaf_kind();
            }
            #[test]
            fn odd_points() {
                Suite::<$e>::odd_points();
            }
        }
    };
}

evaluator_tests!(kernel, KernelEval);
evaluator_tests!(tape, TapeEval);
evaluator_tests!(restricted, RestrictedEval);
#[cfg(feature = "jit")]
evaluator_tests!(jit, JitEval);
#[cfg(feature = "jit")]
evaluator_tests!(restricted_jit, RestrictedJitEval);

/// Which programs compile: every analytic leaf kind (with the kernel's fallback leaves),
/// bounded or not; not mesh grids (below) nor a root union of two bounded members; a
/// bundle's restriction compiles once and is then found in the field's cache.
#[cfg(feature = "jit")]
#[test]
fn which_programs_compile() {
    let at = |k: usize, x: f64| {
        node(
            NodeKind::Leaf(shape(k, 0.3, 0.3)),
            compose_transform(
                DVec3::new(x, 0.0, 3.0),
                DVec3::new(0.0, 20.0, 0.0),
                DVec3::ONE,
            ),
            1,
        )
    };
    // Unions of at most eight members (larger ones get a hierarchy, and no tape).
    for kinds in [0..6, 6..11] {
        let every: Vec<Node> = kinds.map(|k| at(k, k as f64 * 0.5 - 2.5)).collect();
        let f = JitEval::prepare(compile(&union(every.clone())));
        assert!(f.jit().is_some_and(|j| j.ops() > 100));
        let f = JitEval::prepare(compile(&union(every)).without_bounds());
        assert!(f.jit().is_some());
    }
    let pair = JitEval::prepare(compile(&union(vec![at(3, 0.0), at(5, 2.0)])));
    assert!(pair.has_tape() && pair.jit().is_none());
    let mut off = compile(&union(vec![at(0, 0.0), at(1, 1.0)]));
    off.set_jit(false);
    assert!(off.jit().is_none());
    let f = JitEval::prepare(compile(&union(vec![at(0, -1.0), at(1, 0.0), at(2, 1.0)])));
    let pts = lanes(DVec3::new(0.0, 0.0, 3.0), 0.05);
    let mut r = Restricted::default();
    for _ in 0..3 {
        f.restrict_to(&cone(&pts).expect("a cone"), &mut r);
        assert!(r.is_jitted() && !r.is_kerneled());
    }
    assert_eq!(f.jit_cached(), 1);
}

/// Spheres, planes and boxes are specialised (no leaf on the tape's path); the other
/// shapes are not, and take the tape's leaf evaluation; fields with mesh grids, with a
/// root union of two bounded members or without a tape get no kernel; kernels off: none.
#[test]
fn which_programs_get_a_kernel_and_which_leaves_fall_back() {
    let at = |k: usize, x: f64, rot: f64| {
        node(
            NodeKind::Leaf(shape(k, 0.3, 0.3)),
            compose_transform(
                DVec3::new(x, 0.0, 3.0),
                DVec3::new(0.0, rot, 0.0),
                DVec3::ONE,
            ),
            1,
        )
    };
    // Sphere, box (translated and rotated), plane, huge sphere.
    let common = union(vec![
        at(0, -1.0, 0.0),
        at(1, 0.0, 0.0),
        at(1, 1.0, 30.0),
        at(2, 0.0, 0.0),
        at(10, 0.0, 0.0),
    ]);
    let f = compile(&common);
    let k = f.kernel().expect("a kernel");
    assert_eq!(k.fallback_leaves(), 0);
    // Ellipsoid, torus, triangle between two spheres: three leaves on the tape's path.
    let mixed = union(vec![
        at(0, -1.0, 0.0),
        at(3, 0.0, 0.0),
        at(5, 1.0, 0.0),
        at(9, 2.0, 0.0),
        at(0, 3.0, 0.0),
    ]);
    let f = compile(&mixed);
    let k = f.kernel().expect("a kernel");
    assert_eq!(k.fallback_leaves(), 3);
    assert!(k.runs() >= 3);
    for x in -10..=10 {
        let pts = lanes(DVec3::new(0.4 * x as f64, 0.1, 3.0), 0.3);
        let got = f.distance_x8(pts);
        for i in 0..8 {
            assert_eq!(got[i].to_bits(), f.distance(pts[i]).to_bits());
        }
    }
    // Two bounded members (visited nearer first by the tape): no kernel, still a tape.
    let pair = compile(&union(vec![at(3, 0.0, 0.0), at(5, 2.0, 0.0)]));
    assert!(pair.has_tape() && pair.kernel().is_none());
    // CSG: no tape, no kernel.
    let csg = compile(&node(
        NodeKind::Subtraction(vec![at(1, 0.0, 0.0), at(0, 0.2, 0.0)]),
        DAffine3::IDENTITY,
        0,
    ));
    assert!(!csg.has_tape() && csg.kernel().is_none());
    // Off.
    let mut off = compile(&common);
    off.set_kernels(false);
    assert!(off.kernel().is_none() && off.has_tape());
    // A bundle's restriction of the common union gets a kernel of its own.
    let f = compile(&common);
    let pts = lanes(DVec3::new(0.0, 0.0, 3.0), 0.05);
    let mut r = Restricted::default();
    f.restrict_to(&cone(&pts).expect("a cone"), &mut r);
    assert!(r.is_kerneled());
}

/// A mesh grid leaf: no kernel (the tape samples the grid), the same values.
#[test]
fn mesh_grids_keep_the_tape() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/meshes/bunny.obj");
    let scene = union(vec![
        node(
            NodeKind::Leaf(Shape::Mesh { path }),
            compose_transform(DVec3::new(0.3, -0.2, 3.0), DVec3::ZERO, DVec3::splat(0.15)),
            4,
        ),
        node(
            NodeKind::Leaf(Shape::Sphere { radius: 0.5 }),
            compose_transform(DVec3::new(-1.0, 0.0, 3.0), DVec3::ZERO, DVec3::ONE),
            1,
        ),
    ]);
    let opts = FieldOptions {
        mesh_grid_resolution: 16,
        ..FieldOptions::default()
    };
    let mut f = Field::compile_node(&scene, DAffine3::IDENTITY, &opts).expect("compiles");
    f.set_kernels(true);
    assert!(f.has_tape() && f.kernel().is_none());
    f.set_jit(true);
    assert!(f.jit().is_none());
}
