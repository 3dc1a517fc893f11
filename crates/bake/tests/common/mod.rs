//! Meshes the bake integration tests share.

use glam::Vec3;
use marchmesh_meshio::TriangleMesh;

/// Axis-aligned cube `[-1, 1]^3`, outward counter-clockwise triangles, optionally without
/// its top (+y) face.
pub fn cube(with_top: bool) -> TriangleMesh {
    let positions: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            )
        })
        .collect();
    // Quads (outward CCW), top = +y is the last.
    let quads = [
        [0, 4, 6, 2], // -x
        [1, 3, 7, 5], // +x
        [0, 1, 5, 4], // -y
        [0, 2, 3, 1], // -z
        [4, 5, 7, 6], // +z
        [2, 6, 7, 3], // +y
    ];
    let n = if with_top { 6 } else { 5 };
    let triangles = quads[..n]
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    TriangleMesh {
        positions,
        normals: None,
        triangles,
        report: Default::default(),
    }
}
