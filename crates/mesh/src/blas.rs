//! One bottom-level acceleration structure: triangles in an obvhs BVH, with optional vertex
//! normals and per-triangle materials, and traversal that counts its work.

use std::time::Duration;

use glam::{UVec2, Vec2, Vec3, Vec3A};
use marchmesh_core::RayWork;
use marchmesh_scene::MaterialId;
use obvhs::{
    BvhBuildParams,
    bvh2::{Bvh2, builder::build_bvh2_from_tris, node::Bvh2Node},
    cwbvh::{CwBvh, builder::build_cwbvh_from_tris, node::CwBvhNode},
    faststack::FastStack,
    ray::Ray,
    rt_triangle::RtTriangle,
    triangle::Triangle,
};

use crate::options::BvhKind;
use crate::wide::WideBvh;

/// The BVH of one BLAS or of the TLAS.
#[derive(Clone)]
pub(crate) enum Tree {
    Bvh2(Bvh2),
    CwBvh(CwBvh),
    Wide(WideTree),
}

/// An 8-wide BVH converted from a Bvh2 build, with the Bvh2's slot-to-primitive map.
#[derive(Clone)]
pub(crate) struct WideTree {
    pub wide: WideBvh,
    pub primitive_indices: Vec<u32>,
}

/// Smallest extent (world units, largest side of the triangles' bounding box) for which a
/// CwBvh is built. obvhs 0.4's compressed nodes quantise child boxes against the parent and
/// miss every ray when the whole tree is smaller than about 1e-5 units (measured with the
/// stability study: a sphere of radius 1e-5 gets no hits, 3e-5 does); below this margin the
/// builder falls back to a Bvh2, which is exact at any scale.
pub(crate) const CWBVH_MIN_EXTENT: f32 = 1e-3;

impl Tree {
    /// Builds over triangles with the given preset (inside the current rayon pool). A CwBvh
    /// request over triangles smaller than [`CWBVH_MIN_EXTENT`] builds a Bvh2 instead.
    pub(crate) fn build(kind: BvhKind, tris: &[Triangle], params: BvhBuildParams) -> Self {
        let mut t = Duration::default();
        let (mut lo, mut hi) = (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY));
        for tri in tris {
            for v in [tri.v0, tri.v1, tri.v2] {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        let kind = if kind == BvhKind::CwBvh && (hi - lo).max_element() < CWBVH_MIN_EXTENT {
            BvhKind::Bvh2
        } else {
            kind
        };
        match kind {
            BvhKind::Bvh2 => {
                let mut b = build_bvh2_from_tris(tris, params, &mut t);
                // Drop what traversal does not use and the builders' over-reservation.
                b.primitives_to_nodes = Vec::new();
                b.parents = Vec::new();
                b.primitive_indices_freelist = Vec::new();
                b.nodes.shrink_to_fit();
                b.primitive_indices.shrink_to_fit();
                Tree::Bvh2(b)
            }
            BvhKind::CwBvh => {
                let mut b = build_cwbvh_from_tris(tris, params, &mut t);
                b.exact_node_aabbs = None;
                b.nodes.shrink_to_fit();
                b.primitive_indices.shrink_to_fit();
                Tree::CwBvh(b)
            }
            BvhKind::Wide => {
                // Leaves of at most one triangle block: a Bvh2 leaf of 5-8 triangles costs
                // two block tests and padding (measured: 1.2-1.5x faster on the bunny and the
                // 871k dragon, neutral on dragon_res3).
                let params = BvhBuildParams {
                    max_prims_per_leaf: params.max_prims_per_leaf.min(crate::wide::BLOCK as u32),
                    ..params
                };
                let b = build_bvh2_from_tris(tris, params, &mut t);
                let slot_tris: Vec<RtTriangle> = b
                    .primitive_indices
                    .iter()
                    .map(|&i| RtTriangle::from(&tris[i as usize]))
                    .collect();
                // A tree too deep or too large for the wide layout stays a Bvh2.
                match WideBvh::from_bvh2(&b, &slot_tris) {
                    Some(wide) => {
                        let mut primitive_indices = b.primitive_indices;
                        primitive_indices.shrink_to_fit();
                        Tree::Wide(WideTree {
                            wide,
                            primitive_indices,
                        })
                    }
                    None => Self::build(BvhKind::Bvh2, tris, params),
                }
            }
        }
    }

    /// Slot-to-primitive map (`primitive_indices`).
    pub(crate) fn primitive_indices(&self) -> &[u32] {
        match self {
            Tree::Bvh2(b) => &b.primitive_indices,
            Tree::CwBvh(b) => &b.primitive_indices,
            Tree::Wide(w) => &w.primitive_indices,
        }
    }

    /// Which layout was built (a CwBvh request may have fallen back to Bvh2).
    pub(crate) fn kind(&self) -> BvhKind {
        match self {
            Tree::Bvh2(_) => BvhKind::Bvh2,
            Tree::CwBvh(_) => BvhKind::CwBvh,
            Tree::Wide(_) => BvhKind::Wide,
        }
    }

    /// Node count.
    pub(crate) fn node_count(&self) -> usize {
        match self {
            Tree::Bvh2(b) => b.nodes.len(),
            Tree::CwBvh(b) => b.nodes.len(),
            Tree::Wide(w) => w.wide.node_count(),
        }
    }

    /// Exact bytes of nodes and index arrays (lengths, not capacities).
    pub(crate) fn memory_bytes(&self) -> u64 {
        match self {
            Tree::Bvh2(b) => {
                (b.nodes.len() * size_of::<Bvh2Node>()
                    + (b.primitive_indices.len()
                        + b.primitive_indices_freelist.len()
                        + b.primitives_to_nodes.len()
                        + b.parents.len())
                        * 4) as u64
            }
            Tree::CwBvh(b) => {
                (b.nodes.len() * size_of::<CwBvhNode>()
                    + b.primitive_indices.len() * 4
                    + b.exact_node_aabbs.as_ref().map_or(0, |a| a.len() * 24))
                    as u64
            }
            Tree::Wide(w) => w.wide.memory_bytes() + w.primitive_indices.len() as u64 * 4,
        }
    }

    /// Visits the leaves a ray reaches, nearest-first where cheap; `leaf(ray, slot)` tests
    /// primitive slot `slot`, may shrink `ray.tmax`, and returns `false` to stop.
    #[inline(always)]
    pub(crate) fn traverse(
        &self,
        ray: &mut Ray,
        work: &mut RayWork,
        mut leaf: impl FnMut(&mut Ray, u32) -> bool,
    ) {
        match self {
            Tree::Bvh2(b) => {
                obvhs::fast_stack!(u32, (96, 192), b.max_depth, stack, {
                    traverse_bvh2(b, &mut stack, ray, work, &mut leaf)
                })
            }
            Tree::CwBvh(b) => traverse_cwbvh(b, ray, work, &mut leaf),
            Tree::Wide(w) => w.wide.traverse_slots(ray, work, leaf),
        }
    }
}

/// Stack traversal of a Bvh2 (the loop of `Bvh2::ray_traverse_dynamic`, with counters).
/// Counts every child box tested as a node visit.
#[inline(always)]
fn traverse_bvh2<S: FastStack<u32>>(
    bvh: &Bvh2,
    stack: &mut S,
    ray: &mut Ray,
    work: &mut RayWork,
    leaf: &mut impl FnMut(&mut Ray, u32) -> bool,
) {
    let Some(root) = bvh.nodes.first() else {
        return;
    };
    work.node_visits += 1;
    if root.aabb().intersect_ray(ray) >= ray.tmax {
        return;
    }
    if root.is_leaf() {
        visit_leaf(root, ray, leaf);
        return;
    }
    let mut current = root.first_index;
    loop {
        let (Some(mut near), Some(mut far)) = (
            bvh.nodes.get(current as usize),
            bvh.nodes.get(current as usize + 1),
        ) else {
            return;
        };
        work.node_visits += 2;
        let mut t_near = near.aabb().intersect_ray(ray);
        let mut t_far = far.aabb().intersect_ray(ray);
        if t_near > t_far {
            std::mem::swap(&mut t_near, &mut t_far);
            std::mem::swap(&mut near, &mut far);
        }
        let mut go_near = t_near < ray.tmax;
        if go_near && near.is_leaf() {
            if !visit_leaf(near, ray, leaf) {
                return;
            }
            go_near = false;
        }
        let mut go_far = t_far < ray.tmax;
        if go_far && far.is_leaf() {
            if !visit_leaf(far, ray, leaf) {
                return;
            }
            go_far = false;
        }
        current = match (go_near, go_far) {
            (true, true) => {
                stack.push(far.first_index);
                near.first_index
            }
            (true, false) => near.first_index,
            (false, true) => far.first_index,
            (false, false) => match stack.pop() {
                Some(next) => next,
                None => return,
            },
        };
    }
}

/// Tests every primitive slot of a Bvh2 leaf; `false` when `leaf` asked to stop.
#[inline(always)]
fn visit_leaf(
    node: &Bvh2Node,
    ray: &mut Ray,
    leaf: &mut impl FnMut(&mut Ray, u32) -> bool,
) -> bool {
    for slot in node.first_index..node.first_index + node.prim_count {
        if !leaf(ray, slot) {
            return false;
        }
    }
    true
}

/// CwBvh traversal through obvhs' `traverse!` macro, counting node tests.
#[inline(always)]
fn traverse_cwbvh(
    bvh: &CwBvh,
    ray: &mut Ray,
    work: &mut RayWork,
    leaf: &mut impl FnMut(&mut Ray, u32) -> bool,
) {
    if bvh.nodes.is_empty() {
        return;
    }
    let mut state = bvh.new_traversal(ray.direction);
    let mut node;
    let mut visits = 0u32;
    // The primitive block runs inside an inner loop of the macro: stopping needs a label.
    'traversal: {
        obvhs::traverse!(
            bvh,
            node,
            state,
            {
                visits += 1;
                node.intersect_ray(ray, state.oct_inv4)
            },
            {
                if !leaf(ray, state.primitive_id) {
                    break 'traversal;
                }
            }
        );
    }
    work.node_visits += visits;
    // The macro names UVec2 unqualified; keep the import used.
    let _ = UVec2::ZERO;
}

/// A bottom-level structure.
#[derive(Clone)]
pub(crate) struct Blas {
    /// Triangles in BVH slot order (`tris[slot]` is triangle `primitive_indices[slot]`);
    /// empty for a wide tree, whose triangle blocks hold the same data.
    pub tris: Vec<RtTriangle>,
    /// The BVH.
    pub tree: Tree,
    /// Unit vertex normals, if the source had them.
    pub normals: Option<Vec<Vec3>>,
    /// Vertex indices per slot (kept only with `normals`).
    pub indices: Vec<[u32; 3]>,
    /// Material per slot (empty: the instance's material).
    pub materials: Vec<MaterialId>,
    /// Triangle count (distinct, before any spatial splits).
    pub triangle_count: usize,
}

/// Input of [`Blas::build`]: f32 positions in the BLAS's frame.
pub(crate) struct BlasInput {
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    pub triangles: Vec<[u32; 3]>,
    pub materials: Vec<MaterialId>,
}

/// A closest-hit candidate inside one BLAS.
#[derive(Debug, Clone, Copy)]
pub(crate) struct BlasHit {
    pub t: f32,
    /// Where the triangle is stored: its BVH slot for Bvh2/CwBvh, the block reference of a
    /// wide tree ([`WideBvh::triangle`]); [`Blas::slot`] resolves it, only when shading
    /// needs per-slot data (one cache miss less per hit otherwise).
    pub prim: u32,
}

impl Blas {
    /// Builds the BVH; `input.triangles` must be non-empty with valid indices.
    pub(crate) fn build(input: BlasInput, kind: BvhKind, params: BvhBuildParams) -> Self {
        let pos = &input.positions;
        let vertex = |i: u32| Vec3A::from(pos.get(i as usize).copied().unwrap_or(Vec3::ZERO));
        let tris: Vec<Triangle> = input
            .triangles
            .iter()
            .map(|t| Triangle {
                v0: vertex(t[0]),
                v1: vertex(t[1]),
                v2: vertex(t[2]),
            })
            .collect();
        let tree = Tree::build(kind, &tris, params);
        // A wide tree keeps its triangles in its blocks (shading reads them there).
        let rt: Vec<RtTriangle> = if matches!(tree, Tree::Wide(_)) {
            Vec::new()
        } else {
            tree.primitive_indices()
                .iter()
                .map(|&i| RtTriangle::from(&tris[i as usize]))
                .collect()
        };
        // Per-triangle shading data in slot order too: one indirection less per hit.
        let slots = tree.primitive_indices();
        let indices = if input.normals.is_some() {
            slots.iter().map(|&i| input.triangles[i as usize]).collect()
        } else {
            Vec::new()
        };
        let materials = if input.materials.is_empty() {
            Vec::new()
        } else {
            slots
                .iter()
                .map(|&i| input.materials.get(i as usize).copied().unwrap_or(0))
                .collect()
        };
        Self {
            tris: rt,
            tree,
            normals: input.normals,
            indices,
            materials,
            triangle_count: input.triangles.len(),
        }
    }

    /// Closest hit along `ray` (in this BLAS's frame) before `ray.tmax`; shrinks `ray.tmax`.
    #[inline(always)]
    pub(crate) fn closest(&self, ray: &mut Ray, work: &mut RayWork) -> Option<BlasHit> {
        if let Tree::Wide(w) = &self.tree {
            let (prim, t) = w.wide.closest(ray, work)?;
            return Some(BlasHit { t, prim });
        }
        let mut best: Option<BlasHit> = None;
        let tris = &self.tris;
        let mut tests = 0u32;
        self.tree.traverse(ray, work, |ray, slot| {
            tests += 1;
            if let Some(tri) = tris.get(slot as usize) {
                let t = tri.intersect(ray);
                if t < ray.tmax {
                    ray.tmax = t;
                    best = Some(BlasHit { t, prim: slot });
                }
            }
            true
        });
        work.primitive_tests += tests;
        best
    }

    /// Whether anything lies along `ray` before `ray.tmax`.
    #[inline(always)]
    pub(crate) fn any(&self, ray: &mut Ray, work: &mut RayWork) -> bool {
        if let Tree::Wide(w) = &self.tree {
            return w.wide.any(ray, work);
        }
        let tris = &self.tris;
        let mut hit = false;
        let mut tests = 0u32;
        self.tree.traverse(ray, work, |ray, slot| {
            tests += 1;
            if let Some(tri) = tris.get(slot as usize)
                && tri.intersect(ray) < ray.tmax
            {
                hit = true;
                return false;
            }
            true
        });
        work.primitive_tests += tests;
        hit
    }

    /// The triangle of a hit: from the wide tree's blocks, else `tris[slot]`.
    #[inline]
    fn hit_triangle(&self, hit: &BlasHit) -> Option<RtTriangle> {
        match &self.tree {
            Tree::Wide(w) => w.wide.triangle(hit.prim),
            Tree::Bvh2(_) | Tree::CwBvh(_) => self.tris.get(hit.prim as usize).copied(),
        }
    }

    /// The BVH slot of a hit (index into the per-slot shading data); `None` if the hit names
    /// no triangle of this BLAS.
    #[inline]
    pub(crate) fn slot(&self, hit: &BlasHit) -> Option<u32> {
        match &self.tree {
            Tree::Wide(w) => w.wide.slot(hit.prim),
            Tree::Bvh2(_) | Tree::CwBvh(_) => Some(hit.prim),
        }
    }

    /// Shading normal (this BLAS's frame, unit) at a hit: interpolated vertex normals if
    /// present (barycentrics from `RtTriangle::compute_barycentric`), else geometric.
    /// `+Z` for a hit that names no triangle of this BLAS.
    pub(crate) fn normal(&self, ray: &Ray, hit: &BlasHit) -> Vec3 {
        let Some(tri) = self.hit_triangle(hit) else {
            return Vec3::Z;
        };
        let geometric = Vec3::from(tri.compute_normal());
        if let Some(normals) = &self.normals
            && let Some(idx) = self.slot(hit).and_then(|s| self.indices.get(s as usize))
        {
            let b: Vec2 = tri.compute_barycentric(ray);
            let n = |k: usize| normals.get(idx[k] as usize).copied().unwrap_or(geometric);
            let interpolated = n(0) * (1.0 - b.x - b.y) + n(1) * b.x + n(2) * b.y;
            if let Some(unit) = interpolated.try_normalize() {
                return unit;
            }
        }
        geometric
    }

    /// The wide layout, when this BLAS was built as one (for packet traversal).
    pub(crate) fn wide(&self) -> Option<&WideBvh> {
        match &self.tree {
            Tree::Wide(w) => Some(&w.wide),
            Tree::Bvh2(_) | Tree::CwBvh(_) => None,
        }
    }

    /// Material of the triangle of a hit, if this BLAS carries materials.
    #[inline]
    pub(crate) fn material(&self, hit: &BlasHit) -> Option<MaterialId> {
        if self.materials.is_empty() {
            return None;
        }
        self.materials.get(self.slot(hit)? as usize).copied()
    }

    /// Exact bytes held (lengths).
    pub(crate) fn memory_bytes(&self) -> u64 {
        (self.tris.len() * size_of::<RtTriangle>()
            + self
                .normals
                .as_ref()
                .map_or(0, |n| n.len() * size_of::<Vec3>())
            + self.indices.len() * 12
            + self.materials.len() * 4) as u64
            + self.tree.memory_bytes()
    }
}
