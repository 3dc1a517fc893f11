//! Tessellation of every analytic shape: vertices on the surface, chord error within the
//! budget in both directions (triangle points to the surface, surface points to the
//! triangles), watertight and outward-oriented closed shapes, and error falling with the
//! budget.

use glam::{DVec2, DVec3};
use marchmesh_mesh::tessellate::{Detail, LocalMesh, tessellate};
use marchmesh_meshio::{LoadReport, TriangleMesh};
use marchmesh_scene::{NodeKind, Shape};

fn shapes() -> Vec<(&'static str, NodeKind)> {
    vec![
        ("sphere", NodeKind::Leaf(Shape::Sphere { radius: 1.3 })),
        (
            "ellipsoid",
            NodeKind::Leaf(Shape::Ellipsoid {
                radii: DVec3::new(1.3, 0.6, 0.8),
            }),
        ),
        (
            "box",
            NodeKind::Leaf(Shape::Box {
                half_extents: DVec3::new(0.8, 0.5, 0.6),
            }),
        ),
        (
            "cylinder",
            NodeKind::Leaf(Shape::Cylinder {
                radius: 0.7,
                half_height: 0.8,
            }),
        ),
        (
            "torus",
            NodeKind::Leaf(Shape::Torus {
                major_radius: 1.1,
                minor_radius: 0.35,
            }),
        ),
    ]
}

/// Exact distance to an ellipsoid (closest point by bisection on the Lagrange parameter).
fn ellipsoid_distance(radii: DVec3, p: DVec3) -> f64 {
    let q = p.abs().max(DVec3::splat(1e-12));
    let a2 = radii * radii;
    let f = |t: f64| {
        let x = radii * q / (DVec3::splat(t) + a2);
        x.length_squared() - 1.0
    };
    let mut lo = -a2.min_element() + 1e-15;
    let mut hi = q.length() * radii.max_element() + 1.0;
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 { lo = mid } else { hi = mid }
    }
    let t = 0.5 * (lo + hi);
    let closest = a2 * q / (DVec3::splat(t) + a2);
    (closest - q).length()
}

fn distance(kind: &NodeKind, p: DVec3) -> f64 {
    match kind {
        NodeKind::Leaf(Shape::Ellipsoid { radii }) => ellipsoid_distance(*radii, p),
        k => exact_surface_distance(k, p).expect("exact distance"),
    }
}

/// Points sampled on the exact surface of each shape (deterministic).
fn surface_samples(kind: &NodeKind, n: usize) -> Vec<DVec3> {
    let mut out = Vec::new();
    let golden = 0.618_033_988_749_895;
    for i in 0..n {
        let u = (i as f64 + 0.5) / n as f64;
        let v = (i as f64 * golden).fract();
        let phi = v * std::f64::consts::TAU;
        match *kind {
            NodeKind::Leaf(Shape::Sphere { radius }) => {
                let y = 1.0 - 2.0 * u;
                let r = (1.0 - y * y).sqrt();
                out.push(DVec3::new(r * phi.cos(), y, r * phi.sin()) * radius);
            }
            NodeKind::Leaf(Shape::Ellipsoid { radii }) => {
                let y = 1.0 - 2.0 * u;
                let r = (1.0 - y * y).sqrt();
                out.push(DVec3::new(r * phi.cos(), y, r * phi.sin()) * radii);
            }
            NodeKind::Leaf(Shape::Box { half_extents }) => {
                let face = i % 6;
                let axis = face / 2;
                let sign = if face % 2 == 0 { 1.0 } else { -1.0 };
                let mut p = DVec3::new(2.0 * u - 1.0, 2.0 * v - 1.0, 0.0);
                p = match axis {
                    0 => DVec3::new(sign, p.x, p.y),
                    1 => DVec3::new(p.x, sign, p.y),
                    _ => DVec3::new(p.x, p.y, sign),
                };
                out.push(p * half_extents);
            }
            NodeKind::Leaf(Shape::Cylinder {
                radius,
                half_height,
            }) => {
                if i % 3 == 0 {
                    let r = radius * u.sqrt();
                    let y = if i % 2 == 0 {
                        half_height
                    } else {
                        -half_height
                    };
                    out.push(DVec3::new(r * phi.cos(), y, r * phi.sin()));
                } else {
                    out.push(DVec3::new(
                        radius * phi.cos(),
                        (2.0 * u - 1.0) * half_height,
                        radius * phi.sin(),
                    ));
                }
            }
            NodeKind::Leaf(Shape::Torus {
                major_radius,
                minor_radius,
            }) => {
                let theta = u * std::f64::consts::TAU * 7.0;
                let ring = major_radius + minor_radius * theta.cos();
                out.push(DVec3::new(
                    ring * phi.cos(),
                    minor_radius * theta.sin(),
                    ring * phi.sin(),
                ));
            }
            _ => {}
        }
    }
    out
}

fn point_triangle_distance(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    // Ericson, Real-Time Collision Detection, 5.1.5.
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (p - a).length();
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (p - b).length();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (p - (a + ab * (d1 / (d1 - d3)))).length();
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (p - c).length();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (p - (a + ac * (d2 / (d2 - d6)))).length();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return (p - (b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))))).length();
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    (p - (a + ab * v + ac * w)).length()
}

fn corners(m: &LocalMesh, t: &[u32; 3]) -> [DVec3; 3] {
    t.map(|i| m.positions[i as usize])
}

/// Largest distance from points on the triangles to the exact surface.
fn mesh_to_surface_error(kind: &NodeKind, m: &LocalMesh) -> f64 {
    let bary = [
        (1.0 / 3.0, 1.0 / 3.0),
        (0.5, 0.5),
        (0.0, 0.5),
        (0.5, 0.0),
        (0.25, 0.25),
        (0.5, 0.25),
        (0.25, 0.5),
        (2.0 / 3.0, 1.0 / 6.0),
        (1.0 / 6.0, 2.0 / 3.0),
        (1.0 / 6.0, 1.0 / 6.0),
    ];
    let mut worst: f64 = 0.0;
    for t in &m.triangles {
        let [a, b, c] = corners(m, t);
        for &(u, v) in &bary {
            let p = a + (b - a) * u + (c - a) * v;
            worst = worst.max(distance(kind, p));
        }
    }
    worst
}

/// Largest distance from sampled exact-surface points to the tessellation.
fn surface_to_mesh_error(kind: &NodeKind, m: &LocalMesh, samples: usize) -> f64 {
    surface_samples(kind, samples)
        .into_iter()
        .map(|p| {
            m.triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = corners(m, t);
                    point_triangle_distance(p, a, b, c)
                })
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max)
}

#[test]
fn every_vertex_lies_on_the_exact_surface() {
    for (name, kind) in shapes() {
        let m = tessellate(&kind, Detail::ChordError(1e-2), 4096).expect(name);
        for p in &m.positions {
            let d = distance(&kind, *p);
            assert!(d < 1e-9, "{name}: vertex {p:?} is {d} off the surface");
        }
    }
}

#[test]
fn chord_error_stays_within_the_budget_both_ways() {
    for budget in [5e-2, 1e-2, 2e-3] {
        for (name, kind) in shapes() {
            let m = tessellate(&kind, Detail::ChordError(budget), 4096).expect(name);
            let out = mesh_to_surface_error(&kind, &m);
            assert!(
                out <= budget,
                "{name} at {budget}: triangles reach {out} from the surface"
            );
            let back = surface_to_mesh_error(&kind, &m, 300);
            assert!(
                back <= budget,
                "{name} at {budget}: surface points are {back} from the triangles"
            );
        }
    }
}

#[test]
fn error_falls_as_the_budget_shrinks_and_uses_it_reasonably() {
    for (name, kind) in shapes() {
        if name == "box" {
            continue; // exact at any budget
        }
        let mut previous = f64::INFINITY;
        for budget in [1e-1, 1e-2, 1e-3] {
            let m = tessellate(&kind, Detail::ChordError(budget), 4096).expect(name);
            let err = mesh_to_surface_error(&kind, &m);
            assert!(
                err < previous,
                "{name}: error {err} did not fall at budget {budget}"
            );
            // Not wastefully fine: the realised error uses at least a tenth of the budget.
            assert!(
                err > budget * 0.1,
                "{name}: error {err} far below budget {budget}"
            );
            previous = err;
        }
    }
}

#[test]
fn closed_shapes_are_watertight_and_outward() {
    for (name, kind) in shapes() {
        for detail in [Detail::Level(0), Detail::Level(3), Detail::ChordError(1e-3)] {
            let m = tessellate(&kind, detail, 4096).expect(name);
            assert!(m.closed, "{name}");
            let tm = TriangleMesh {
                positions: m.positions.iter().map(|p| p.as_vec3()).collect(),
                normals: None,
                triangles: m.triangles.clone(),
                report: LoadReport::default(),
            };
            assert!(tm.is_closed(), "{name} at {detail:?} is not watertight");
            // Positive signed volume close to the exact one means consistent outward winding.
            let volume: f64 = m
                .triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = corners(&m, t);
                    a.dot(b.cross(c)) / 6.0
                })
                .sum();
            assert!(volume > 0.0, "{name}: inward winding (volume {volume})");
            for t in &m.triangles {
                let [a, b, c] = corners(&m, t);
                assert!(
                    (b - a).cross(c - a).length() > 0.0,
                    "{name}: degenerate triangle"
                );
            }
            // Vertex normals, where present, agree with the faces around them.
            if let Some(normals) = &m.normals {
                for t in &m.triangles {
                    let [a, b, c] = corners(&m, t);
                    let face = (b - a).cross(c - a).normalize();
                    for &i in t {
                        assert!(
                            normals[i as usize].dot(face) > 0.0,
                            "{name}: normal against its face"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn fixed_levels_double_the_segments() {
    let kind = NodeKind::Leaf(Shape::Torus {
        major_radius: 1.0,
        minor_radius: 0.25,
    });
    let a = tessellate(&kind, Detail::Level(1), 4096).expect("torus");
    let b = tessellate(&kind, Detail::Level(2), 4096).expect("torus");
    assert_eq!(a.segments, vec![16, 16]);
    assert_eq!(b.segments, vec![32, 32]);
    assert_eq!(b.triangles.len(), 4 * a.triangles.len());
    let capped = tessellate(&kind, Detail::ChordError(1e-12), 64).expect("torus");
    assert_eq!(capped.segments, vec![64, 64]);
}

#[test]
fn ellipsoid_reference_distance_is_exact_on_a_sphere() {
    // The bisection used above agrees with the sphere's closed form.
    let r = DVec3::splat(2.0);
    for p in [DVec3::new(3.0, 0.5, -1.0), DVec3::new(0.1, 0.2, 0.3)] {
        assert!((ellipsoid_distance(r, p) - (p.length() - 2.0).abs()).abs() < 1e-9);
    }
    let _ = DVec2::ZERO;
}

#[test]
fn screen_budgets_hold_where_each_part_is_and_coarsen_far_away() {
    use glam::{DAffine3, DQuat};
    use marchmesh_mesh::tessellate::ScreenBudget;
    // The camera sits at the render-space origin, 0.5-0.7 units off each shape's side.
    let placement = DAffine3::from_rotation_translation(
        DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 0.2),
        DVec3::new(-2.0, 0.2, 0.1),
    );
    let k = 2e-3; // world error per unit distance
    let budget = ScreenBudget::new(&[placement], k, 1e-3);
    for (name, kind) in shapes() {
        let m = tessellate(&kind, Detail::Screen(&budget), 4096).expect(name);
        let tm = TriangleMesh {
            positions: m.positions.iter().map(|p| p.as_vec3()).collect(),
            normals: None,
            triangles: m.triangles.clone(),
            report: LoadReport::default(),
        };
        assert!(
            tm.is_closed(),
            "{name}: adaptive tessellation is not watertight"
        );
        for t in &m.triangles {
            let [a, b, c] = corners(&m, t);
            for (u, v) in [(1.0 / 3.0, 1.0 / 3.0), (0.5, 0.0), (0.0, 0.5), (0.5, 0.5)] {
                let p = a + (b - a) * u + (c - a) * v;
                let allowed = k * placement.transform_point3(p).length().max(1e-3);
                let err = distance(&kind, p);
                assert!(
                    err <= allowed * 1.01 + 1e-12,
                    "{name}: error {err} over {allowed} at {p:?}"
                );
            }
        }
        if name != "box" {
            // Uniform at the nearest distance would be finer everywhere.
            let nearest = m
                .positions
                .iter()
                .map(|p| placement.transform_point3(*p).length())
                .fold(f64::INFINITY, f64::min);
            let uniform = tessellate(&kind, Detail::ChordError(k * nearest), 4096).expect(name);
            assert!(
                m.triangles.len() < uniform.triangles.len(),
                "{name}: adaptive {} vs uniform {}",
                m.triangles.len(),
                uniform.triangles.len()
            );
        }
    }
}

/// Issue 11 item 3: the triangle count is known, and refused, before the triangles exist.
#[test]
fn tessellate_within_refuses_exactly_above_the_cap() {
    use marchmesh_mesh::tessellate::tessellate_within;
    for kind in [
        NodeKind::Leaf(Shape::Sphere { radius: 1.0 }),
        NodeKind::Leaf(Shape::Torus {
            major_radius: 1.0,
            minor_radius: 0.25,
        }),
        NodeKind::Leaf(Shape::Cylinder {
            radius: 0.5,
            half_height: 1.0,
        }),
    ] {
        let full = tessellate(&kind, Detail::Level(3), 4096).expect("analytic");
        let count = full.triangles.len() as u64;
        // The planned count is an upper bound that is exact for rows without poles.
        let refused = tessellate_within(&kind, Detail::Level(3), 4096, count / 2)
            .expect_err("half the triangles");
        assert!(
            refused.triangles >= count,
            "{kind:?}: {refused:?} vs {count}"
        );
        let fits = tessellate_within(&kind, Detail::Level(3), 4096, refused.triangles)
            .expect("fits")
            .expect("analytic");
        assert_eq!(fits.triangles.len() as u64, count, "{kind:?}");
    }
}

/// Exact distance from `p` to the surface of an analytic shape (local frame), for measuring
/// tessellation error; `None` for shapes without one here (ellipsoid, plane, composites).
fn exact_surface_distance(kind: &NodeKind, p: DVec3) -> Option<f64> {
    Some(match *kind {
        NodeKind::Leaf(Shape::Sphere { radius }) => (p.length() - radius).abs(),
        NodeKind::Leaf(Shape::Box { half_extents }) => {
            let q = p.abs() - half_extents;
            (q.max(DVec3::ZERO).length() + q.max_element().min(0.0)).abs()
        }
        NodeKind::Leaf(Shape::Cylinder {
            radius,
            half_height,
        }) => {
            let d = DVec2::new(DVec2::new(p.x, p.z).length(), p.y).abs()
                - DVec2::new(radius, half_height);
            (d.x.max(d.y).min(0.0) + d.max(DVec2::ZERO).length()).abs()
        }
        NodeKind::Leaf(Shape::Torus {
            major_radius,
            minor_radius,
        }) => {
            let q = DVec2::new(DVec2::new(p.x, p.z).length() - major_radius, p.y);
            (q.length() - minor_radius).abs()
        }
        _ => return None,
    })
}
