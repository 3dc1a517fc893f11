//! Flat geometry: the triangles of everything placed once, transformed into render space
//! and appended to one BLAS input, from either a loaded mesh or a shape's own triangles.

use glam::{Affine3A, DAffine3, DVec3, Vec3};
use marchmesh_meshio::TriangleMesh;
use marchmesh_scene::MaterialId;

use crate::blas::BlasInput;
use crate::build;
use crate::tessellate::LocalMesh;

/// f64 affine to f32 (render-space magnitudes are bounded by max_distance).
pub(crate) trait AsAffine3A {
    fn as_affine3a_checked(&self) -> Affine3A;
}

impl AsAffine3A for DAffine3 {
    fn as_affine3a_checked(&self) -> Affine3A {
        Affine3A::from_mat3_translation(self.matrix3.as_mat3(), self.translation.as_vec3())
    }
}

/// Bounds of f32 positions, in f64.
pub(crate) fn positions_bounds(positions: &[Vec3]) -> (DVec3, DVec3) {
    let mut lo = Vec3::INFINITY;
    let mut hi = Vec3::NEG_INFINITY;
    for p in positions {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    (lo.as_dvec3(), hi.as_dvec3())
}

/// Render-space box of a placed local box, widened by a relative epsilon so that f32
/// rounding never cuts a copy.
pub(crate) fn render_box(to_render: &DAffine3, local: (DVec3, DVec3)) -> obvhs::aabb::Aabb {
    let (lo, hi) = build::transform_bounds(to_render, local);
    let pad = (hi - lo).max_element() * 1e-5 + lo.abs().max(hi.abs()).max_element() * 1e-6;
    obvhs::aabb::Aabb::new((lo - pad).as_vec3().into(), (hi + pad).as_vec3().into())
}

/// A shape's triangles before placement.
pub(crate) enum SourceMesh<'a> {
    File(&'a TriangleMesh),
    Local(&'a LocalMesh),
}

impl SourceMesh<'_> {
    fn vertex_count(&self) -> usize {
        match self {
            SourceMesh::File(m) => m.positions.len(),
            SourceMesh::Local(m) => m.positions.len(),
        }
    }
    fn triangles(&self) -> &[[u32; 3]] {
        match self {
            SourceMesh::File(m) => &m.triangles,
            SourceMesh::Local(m) => &m.triangles,
        }
    }
    fn position(&self, i: usize) -> DVec3 {
        match self {
            SourceMesh::File(m) => m.positions[i].as_dvec3(),
            SourceMesh::Local(m) => m.positions[i],
        }
    }
    fn normal(&self, i: usize) -> Option<DVec3> {
        match self {
            SourceMesh::File(m) => m.normals.as_ref().map(|n| n[i].as_dvec3()),
            SourceMesh::Local(m) => m.normals.as_ref().map(|n| n[i]),
        }
    }
    fn has_normals(&self) -> bool {
        match self {
            SourceMesh::File(m) => m.normals.is_some(),
            SourceMesh::Local(m) => m.normals.is_some(),
        }
    }
    fn materials(&self) -> Option<&[MaterialId]> {
        match self {
            SourceMesh::File(_) => None,
            SourceMesh::Local(m) => m.materials.as_deref(),
        }
    }
    /// The mesh in its own frame, as a BLAS input.
    pub(crate) fn blas_input(&self) -> BlasInput {
        let n = self.vertex_count();
        BlasInput {
            positions: (0..n).map(|i| self.position(i).as_vec3()).collect(),
            normals: self.has_normals().then(|| {
                (0..n)
                    .map(|i| self.normal(i).unwrap_or(DVec3::ZERO).as_vec3())
                    .collect()
            }),
            triangles: self.triangles().to_vec(),
            materials: self.materials().map(<[u32]>::to_vec).unwrap_or_default(),
        }
    }
}

/// Accumulates render-space triangles of everything placed once.
#[derive(Default)]
pub(crate) struct FlatBuilder {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    any_normals: bool,
    pub(crate) triangles: Vec<[u32; 3]>,
    materials: Vec<MaterialId>,
}

impl FlatBuilder {
    pub(crate) fn append(
        &mut self,
        source: &SourceMesh,
        to_render: &DAffine3,
        material: MaterialId,
    ) {
        let base = self.positions.len() as u32;
        let normal_matrix = to_render.matrix3.inverse().transpose();
        let mirrored = to_render.matrix3.determinant() < 0.0;
        for i in 0..source.vertex_count() {
            self.positions
                .push(to_render.transform_point3(source.position(i)).as_vec3());
            let n = source.normal(i).map_or(Vec3::ZERO, |n| {
                (normal_matrix * n).normalize_or_zero().as_vec3()
            });
            self.normals.push(n);
        }
        self.any_normals |= source.has_normals();
        let per_triangle = source.materials();
        for (k, t) in source.triangles().iter().enumerate() {
            let [a, b, c] = t.map(|i| base + i);
            self.triangles
                .push(if mirrored { [a, c, b] } else { [a, b, c] });
            self.materials.push(
                per_triangle
                    .and_then(|m| m.get(k).copied())
                    .unwrap_or(material),
            );
        }
    }

    /// Appends the plane `dot(normal, p) = offset` (in the frame `m`) as a grid of quads
    /// around the camera's foot point covering every point within `max_distance` of the
    /// camera, cells growing geometrically away from the foot so that triangles near the
    /// camera stay small (f32 precision). Returns the number of cells.
    pub(crate) fn append_plane(
        &mut self,
        normal: DVec3,
        offset: f64,
        m: &DAffine3,
        max_distance: f64,
        material: MaterialId,
    ) -> usize {
        let n_local = normal.normalize();
        let point = m.transform_point3(n_local * offset);
        let n = (m.matrix3.inverse().transpose() * n_local).normalize();
        let height = point.dot(n);
        let foot = n * height;
        let u = n.any_orthonormal_vector();
        let v = n.cross(u);
        // Coordinates 0, +-D 2^-k for k = K..0.
        let d = max_distance;
        let smallest = height.abs().max(d * 1e-4);
        let levels = ((d / smallest).log2().ceil().clamp(0.0, 12.0)) as i32;
        let mut coords: Vec<f64> = vec![0.0];
        for k in 0..=levels {
            let c = d * 0.5f64.powi(k);
            coords.push(c);
            coords.push(-c);
        }
        coords.sort_by(f64::total_cmp);
        let base = self.positions.len() as u32;
        let side = coords.len() as u32;
        for &y in &coords {
            for &x in &coords {
                self.positions.push((foot + u * x + v * y).as_vec3());
                self.normals.push(Vec3::ZERO);
            }
        }
        for j in 0..side - 1 {
            for i in 0..side - 1 {
                let a = base + j * side + i;
                let b = a + 1;
                let c = a + side + 1;
                let dd = a + side;
                // u x v = n: (a, b, c) runs counter-clockwise around n.
                self.triangles.push([a, b, c]);
                self.triangles.push([a, c, dd]);
                self.materials.push(material);
                self.materials.push(material);
            }
        }
        ((side - 1) * (side - 1)) as usize
    }

    /// The BLAS input and the material every triangle shares (0 when they differ). A
    /// uniform material is returned instead of stored per triangle, so shading a hit reads
    /// no per-triangle array (on a large mesh that lookup is one more cache miss per hit).
    pub(crate) fn into_input(self) -> (BlasInput, MaterialId) {
        let uniform = match self.materials.split_first() {
            Some((&first, rest)) if rest.iter().all(|&m| m == first) => Some(first),
            Some(_) => None,
            None => Some(0),
        };
        let input = BlasInput {
            positions: self.positions,
            normals: self.any_normals.then_some(self.normals),
            triangles: self.triangles,
            materials: if uniform.is_some() {
                Vec::new()
            } else {
                self.materials
            },
        };
        (input, uniform.unwrap_or(0))
    }
}
