//! Meshes for the reference: f64 vertices, a simple median-split BVH used only to prune
//! candidates, and the exact f64 ray/triangle test deciding every hit.

use glam::DVec3;
use marchmesh_meshio::TriangleMesh;

use crate::primitives;

#[derive(Debug, Clone, Copy)]
struct BNode {
    min: DVec3,
    max: DVec3,
    /// Leaf: first triangle in `order`; inner: index of the left child (right = left + 1).
    start: u32,
    /// Triangles in a leaf; 0 for inner nodes.
    count: u32,
}

/// A triangle mesh in its local frame, ready for exact ray queries.
#[derive(Debug, Clone)]
pub struct MeshData {
    positions: Vec<DVec3>,
    normals: Option<Vec<DVec3>>,
    triangles: Vec<[u32; 3]>,
    order: Vec<u32>,
    nodes: Vec<BNode>,
    /// Every edge shared by exactly two triangles: the mesh bounds a solid.
    pub closed: bool,
}

/// A hit on a mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshHit {
    /// Ray parameter.
    pub t: f64,
    /// Shading normal (interpolated vertex normal, or geometric), local frame, unnormalised.
    pub normal: DVec3,
    /// Geometric normal `(b-a) x (c-a)` (outward for closed counter-clockwise meshes).
    pub geometric: DVec3,
}

const LEAF_SIZE: usize = 4;

impl MeshData {
    /// Converts a loaded mesh and builds its BVH.
    pub fn new(mesh: &TriangleMesh) -> Self {
        let positions: Vec<DVec3> = mesh.positions.iter().map(|p| p.as_dvec3()).collect();
        let normals = mesh
            .normals
            .as_ref()
            .map(|n| n.iter().map(|n| n.as_dvec3()).collect());
        let mut m = Self {
            positions,
            normals,
            triangles: mesh.triangles.clone(),
            order: (0..mesh.triangles.len() as u32).collect(),
            nodes: Vec::new(),
            closed: mesh.is_closed(),
        };
        let centroids: Vec<DVec3> = m
            .triangles
            .iter()
            .map(|t| t.iter().map(|&i| m.positions[i as usize]).sum::<DVec3>() / 3.0)
            .collect();
        m.nodes.push(BNode {
            min: DVec3::ZERO,
            max: DVec3::ZERO,
            start: 0,
            count: 0,
        });
        let n = m.order.len();
        m.build(0, 0, n, &centroids);
        m
    }

    fn tri(&self, i: u32) -> [DVec3; 3] {
        self.triangles[i as usize].map(|v| self.positions[v as usize])
    }

    fn build(&mut self, node: usize, lo: usize, hi: usize, centroids: &[DVec3]) {
        let (mut min, mut max) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        let (mut cmin, mut cmax) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for &t in &self.order[lo..hi] {
            for v in self.tri(t) {
                min = min.min(v);
                max = max.max(v);
            }
            cmin = cmin.min(centroids[t as usize]);
            cmax = cmax.max(centroids[t as usize]);
        }
        self.nodes[node].min = min;
        self.nodes[node].max = max;
        if hi - lo <= LEAF_SIZE {
            self.nodes[node].start = lo as u32;
            self.nodes[node].count = (hi - lo) as u32;
            return;
        }
        let axis = (cmax - cmin).max_position();
        let mid = (lo + hi) / 2;
        self.order[lo..hi].select_nth_unstable_by(mid - lo, |a, b| {
            centroids[*a as usize][axis].total_cmp(&centroids[*b as usize][axis])
        });
        let left = self.nodes.len();
        let empty = BNode {
            min: DVec3::ZERO,
            max: DVec3::ZERO,
            start: 0,
            count: 0,
        };
        self.nodes.push(empty);
        self.nodes.push(empty);
        self.nodes[node].start = left as u32;
        self.build(left, lo, mid, centroids);
        self.build(left + 1, mid, hi, centroids);
    }

    /// Local bounds of the vertices.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        (self.nodes[0].min, self.nodes[0].max)
    }

    /// Bytes held, from lengths.
    pub fn memory_bytes(&self) -> u64 {
        (self.positions.len() * 24
            + self.normals.as_ref().map_or(0, |n| n.len() * 24)
            + self.triangles.len() * 12
            + self.order.len() * 4
            + self.nodes.len() * std::mem::size_of::<BNode>()) as u64
    }

    /// Triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Calls `visit(t, triangle)` for every triangle whose exact test hits within
    /// `[t_lo, t_hi]`; `visit` returns the new upper bound (shrink it for closest-hit).
    /// Returns (nodes visited, triangles tested).
    fn traverse(
        &self,
        o: DVec3,
        d: DVec3,
        t_lo: f64,
        mut t_hi: f64,
        visit: &mut dyn FnMut(f64, f64, f64, u32, DVec3) -> f64,
    ) -> (u32, u32) {
        let inv = d.recip();
        let mut stack = vec![0usize];
        let (mut nodes, mut tests) = (0u32, 0u32);
        while let Some(i) = stack.pop() {
            let n = self.nodes[i];
            nodes += 1;
            // Slab test; NaN from 0 * inf is handled by treating it as "inside".
            let t0 = (n.min - o) * inv;
            let t1 = (n.max - o) * inv;
            let near = t0.min(t1);
            let far = t0.max(t1);
            let enter = [near.x, near.y, near.z]
                .into_iter()
                .filter(|v| !v.is_nan())
                .fold(t_lo, f64::max);
            let exit = [far.x, far.y, far.z]
                .into_iter()
                .filter(|v| !v.is_nan())
                .fold(t_hi, f64::min);
            // A relative tolerance keeps triangles lying exactly in a box face.
            if enter - exit > 1e-9 * (1.0 + exit.abs().min(enter.abs())) {
                continue;
            }
            if n.count == 0 {
                stack.push(n.start as usize);
                stack.push(n.start as usize + 1);
                continue;
            }
            for k in n.start..n.start + n.count {
                let tri = self.order[k as usize];
                tests += 1;
                if let Some((t, u, v, g)) = primitives::triangle(o, d, &self.tri(tri))
                    && t >= t_lo
                    && t <= t_hi
                {
                    t_hi = visit(t, u, v, tri, g);
                }
            }
        }
        (nodes, tests)
    }

    fn shading_normal(&self, tri: u32, u: f64, v: f64, geometric: DVec3) -> DVec3 {
        match &self.normals {
            Some(n) => {
                let [a, b, c] = self.triangles[tri as usize].map(|i| n[i as usize]);
                let s = a * (1.0 - u - v) + b * u + c * v;
                if s.length_squared() > 0.0 {
                    s
                } else {
                    geometric
                }
            }
            None => geometric,
        }
    }

    /// The closest hit in `[t_lo, t_hi]`, with (nodes visited, triangles tested).
    pub fn closest(&self, o: DVec3, d: DVec3, t_lo: f64, t_hi: f64) -> (Option<MeshHit>, u32, u32) {
        let mut best: Option<(f64, f64, f64, u32, DVec3)> = None;
        let (n, k) = self.traverse(o, d, t_lo, t_hi, &mut |t, u, v, tri, g| {
            if best.is_none_or(|b| t < b.0) {
                best = Some((t, u, v, tri, g));
            }
            t
        });
        let hit = best.map(|(t, u, v, tri, g)| MeshHit {
            t,
            normal: self.shading_normal(tri, u, v, g),
            geometric: g,
        });
        (hit, n, k)
    }

    /// Every hit in `[t_lo, t_hi]`, sorted by `t`, with (nodes visited, triangles tested).
    /// Hits at the same `t` on a shared edge or vertex are reported once per triangle.
    pub fn all_hits(&self, o: DVec3, d: DVec3, t_lo: f64, t_hi: f64) -> (Vec<MeshHit>, u32, u32) {
        let mut hits = Vec::new();
        let (n, k) = self.traverse(o, d, t_lo, t_hi, &mut |t, u, v, tri, g| {
            hits.push(MeshHit {
                t,
                normal: self.shading_normal(tri, u, v, g),
                geometric: g,
            });
            t_hi
        });
        hits.sort_by(|a, b| a.t.total_cmp(&b.t));
        (hits, n, k)
    }
}
