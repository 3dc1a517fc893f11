//! Surface-nets extraction of distance fields (the path CSG objects take): closed, outward,
//! near the zero set, converging with resolution, materials per triangle.

use glam::DVec3;
use marchmesh_mesh::extract::extract_surface;
use marchmesh_mesh::tessellate::LocalMesh;
use marchmesh_meshio::{LoadReport, TriangleMesh};

fn sphere(p: DVec3) -> f64 {
    p.length() - 1.0
}

fn cube(p: DVec3) -> f64 {
    let q = p.abs() - DVec3::splat(0.8);
    q.max(DVec3::ZERO).length() + q.max_element().min(0.0)
}

/// Intersection of the cube and the sphere (exact inside/outside, a bound elsewhere).
fn rounded_cube(p: DVec3) -> f64 {
    cube(p).max(sphere(p))
}

fn closed(m: &LocalMesh) -> bool {
    TriangleMesh {
        positions: m.positions.iter().map(|p| p.as_vec3()).collect(),
        normals: None,
        triangles: m.triangles.clone(),
        report: LoadReport::default(),
    }
    .is_closed()
}

fn volume(m: &LocalMesh) -> f64 {
    m.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            a.dot(b.cross(c)) / 6.0
        })
        .sum()
}

#[test]
fn extracted_sphere_is_closed_outward_and_converges() {
    let bounds = (DVec3::splat(-1.0), DVec3::splat(1.0));
    let mut previous = f64::INFINITY;
    for resolution in [16, 32, 64] {
        let m = extract_surface(|p| sphere(p) as f32, |_| 7, bounds, resolution);
        let cell = 2.0 / f64::from(resolution);
        assert!(closed(&m), "{resolution}: not closed");
        let v = volume(&m);
        let exact = 4.0 / 3.0 * std::f64::consts::PI;
        assert!(
            (v - exact).abs() < 0.05 * exact,
            "{resolution}: volume {v} vs {exact}"
        );
        let worst = m
            .positions
            .iter()
            .map(|p| sphere(*p).abs())
            .fold(0.0, f64::max);
        assert!(
            worst < 0.5 * cell,
            "{resolution}: vertex {worst} off the surface (cell {cell})"
        );
        assert!(worst < previous, "{resolution}: error did not fall");
        previous = worst;
        let normals = m.normals.as_ref().expect("normals");
        for (p, n) in m.positions.iter().zip(normals) {
            assert!(n.dot(p.normalize()) > 0.99, "normal {n:?} at {p:?}");
        }
        assert!(
            m.materials
                .as_ref()
                .expect("materials")
                .iter()
                .all(|&id| id == 7)
        );
    }
}

#[test]
fn csg_like_field_gives_a_closed_mesh_with_per_triangle_materials() {
    let bounds = (DVec3::splat(-0.8), DVec3::splat(0.8));
    let m = extract_surface(
        |p| rounded_cube(p) as f32,
        |p| if cube(p) > sphere(p) { 1 } else { 2 },
        bounds,
        48,
    );
    assert!(closed(&m));
    assert!(volume(&m) > 0.0);
    let materials = m.materials.as_ref().expect("materials");
    assert!(
        materials.contains(&1) && materials.contains(&2),
        "both surfaces present"
    );
    // Flat faces of the cube: points near x = 0.8 and small y, z are cube material.
    for (t, &id) in m.triangles.iter().zip(materials) {
        let c = t.map(|i| m.positions[i as usize]).iter().sum::<DVec3>() / 3.0;
        if c.x > 0.79 && c.y.abs() < 0.2 && c.z.abs() < 0.2 {
            assert_eq!(id, 1, "at {c:?}");
        }
    }
}

#[test]
fn non_finite_samples_do_not_poison_the_mesh() {
    let m = extract_surface(
        |p| {
            if p.x > 0.9 {
                f32::NAN
            } else {
                sphere(p) as f32
            }
        },
        |_| 0,
        (DVec3::splat(-1.0), DVec3::splat(1.0)),
        16,
    );
    assert!(!m.triangles.is_empty());
    assert!(m.positions.iter().all(|p| p.is_finite()));
}
