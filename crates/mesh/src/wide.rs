//! An 8-wide CPU BVH converted from an obvhs [`Bvh2`], traversed with SIMD box tests (8
//! child boxes per node in one AVX test, runtime-detected, with a portable fallback) and
//! SIMD triangle tests (blocks of 4 triangles, SSE on x86_64, portable elsewhere).
//!
//! Layout (after Wald et al. 2008 "Getting rid of packets" and Embree's BVH8 with
//! triangle4 blocks, Wald et al. 2014): each node holds its 8 child boxes as structure of
//! arrays plus 8 child references; leaves are runs of [`TriBlock`]s holding 4 triangles each
//! as structure of arrays, in BVH slot order, so slots, normals and materials of the
//! [`crate::blas::Blas`] stay valid. Conversion keeps every Bvh2 leaf as a leaf and collapses
//! inner nodes greedily (open the child with the largest surface area until 8 children).
//!
//! Exactness: the triangle test is obvhs' `RtTriangle::intersect` (Möller-Trumbore) computed
//! lane-wise in the same operation order without fused multiply-add, so every `t` is
//! bit-identical to the Bvh2 path; the box test is obvhs' `Aabb::intersect_ray` slab test.
//! Closest hits therefore equal the Bvh2 path's except for exact ties between triangles at
//! the same `t` (shared edges), where the visiting order picks the winner.

// Lane loops index several structure-of-arrays fields by the same lane, mirroring SIMD lanes.
#![allow(clippy::needless_range_loop)]

use std::mem::MaybeUninit;

use marchmesh_core::RayWork;
use obvhs::{bvh2::Bvh2, ray::Ray, rt_triangle::RtTriangle};

/// Children per node.
pub(crate) const WIDTH: usize = 8;
/// Triangles per block.
pub(crate) const BLOCK: usize = 4;
/// An empty child lane (also marks padding lanes of a triangle block).
pub(crate) const EMPTY: u32 = u32::MAX;
/// Child reference flag: the low 24 bits are the first block, bits 24..31 the block count.
pub(crate) const LEAF: u32 = 1 << 31;
pub(crate) const LEAF_FIRST_BITS: u32 = 24;
const LEAF_MAX_BLOCKS: u32 = 127;
/// Traversal stack entries held on the call stack. Each node pushes at most `WIDTH - 1`
/// entries, so trees deeper than `(STACK - 1) / (WIDTH - 1)` nodes are not converted.
pub(crate) const STACK: usize = 512;
const MAX_DEPTH: u32 = ((STACK - 1) / (WIDTH - 1)) as u32;

/// One node: 8 child boxes (structure of arrays) and child references (an inner node
/// index, a leaf `LEAF | count << 24 | first block`, or `EMPTY`). Empty lanes hold the box
/// `[+inf, +inf]`, which no finite ray enters. 224 bytes.
#[derive(Clone, Copy)]
#[repr(C, align(32))]
pub(crate) struct WideNode {
    pub(crate) lo: [[f32; WIDTH]; 3],
    pub(crate) hi: [[f32; WIDTH]; 3],
    pub(crate) child: [u32; WIDTH],
}

const EMPTY_NODE: WideNode = WideNode {
    lo: [[f32::INFINITY; WIDTH]; 3],
    hi: [[f32::INFINITY; WIDTH]; 3],
    child: [EMPTY; WIDTH],
};

/// Four triangles as structure of arrays in obvhs' `RtTriangle` form (`e1 = v0 - v1`,
/// `e2 = v2 - v0`, `ng = e1 x e2`). Padding lanes hold zero geometry, whose test computes
/// `t = 0 * inf = NaN` and so never reports a hit. 192 bytes, cache-line aligned: a block
/// is exactly 3 lines (the BVH slots live apart in [`WideBvh::slots`], read only on a hit).
#[derive(Clone, Copy)]
#[repr(C, align(64))]
pub(crate) struct TriBlock {
    v0: [[f32; BLOCK]; 3],
    e1: [[f32; BLOCK]; 3],
    e2: [[f32; BLOCK]; 3],
    ng: [[f32; BLOCK]; 3],
}

const EMPTY_BLOCK: TriBlock = TriBlock {
    v0: [[0.0; BLOCK]; 3],
    e1: [[0.0; BLOCK]; 3],
    e2: [[0.0; BLOCK]; 3],
    ng: [[0.0; BLOCK]; 3],
};

/// The 8-wide BVH with its triangle blocks.
#[derive(Clone)]
pub(crate) struct WideBvh {
    pub(crate) nodes: Vec<WideNode>,
    pub(crate) blocks: Vec<TriBlock>,
    /// BVH slots of each block's lanes (`EMPTY` on padding lanes), parallel to `blocks`.
    pub(crate) slots: Vec<[u32; BLOCK]>,
    /// Reference of the root (node 0, or a leaf when the whole tree is one leaf).
    pub(crate) root: u32,
    /// Whether this CPU runs the 256-bit AVX node test (detected at build).
    pub(crate) avx: bool,
}

impl WideBvh {
    /// Converts a Bvh2 whose leaves index `tris` (slot order). `None` when the tree is too
    /// deep for the fixed traversal stack or too large for the 24-bit block references
    /// (more than 16M blocks): the caller keeps the Bvh2, which has no such limits.
    pub(crate) fn from_bvh2(bvh: &Bvh2, tris: &[RtTriangle]) -> Option<Self> {
        let mut out = Self {
            nodes: Vec::new(),
            blocks: Vec::new(),
            slots: Vec::new(),
            root: EMPTY,
            avx: detect_avx(),
        };
        let Some(root) = bvh.nodes.first() else {
            return Some(out);
        };
        if root.is_leaf() {
            out.root = out.leaf(root.first_index, root.prim_count, tris)?;
            return Some(out);
        }
        out.root = 0;
        out.nodes.push(EMPTY_NODE);
        // (wide node index, Bvh2 node index, depth)
        let mut queue: Vec<(usize, usize, u32)> = vec![(0, 0, 1)];
        while let Some((w, b, depth)) = queue.pop() {
            if depth > MAX_DEPTH {
                return None;
            }
            let first = bvh.nodes.get(b)?.first_index as usize;
            let mut children: Vec<usize> = vec![first, first + 1];
            while children.len() < WIDTH {
                // Open the inner child with the largest surface area.
                let widest = children
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| bvh.nodes.get(**c).is_some_and(|n| !n.is_leaf()))
                    .max_by(|a, b| {
                        let area = |i: usize| bvh.nodes[i].aabb().half_area();
                        area(*a.1).total_cmp(&area(*b.1))
                    })
                    .map(|(k, _)| k);
                let Some(k) = widest else { break };
                let opened = children.swap_remove(k);
                let f = bvh.nodes[opened].first_index as usize;
                children.extend([f, f + 1]);
            }
            let mut node = EMPTY_NODE;
            for (lane, &c) in children.iter().enumerate() {
                let n = bvh.nodes.get(c)?;
                let aabb = n.aabb();
                for axis in 0..3 {
                    node.lo[axis][lane] = aabb.min[axis];
                    node.hi[axis][lane] = aabb.max[axis];
                }
                node.child[lane] = if n.is_leaf() {
                    out.leaf(n.first_index, n.prim_count, tris)?
                } else {
                    let index = out.nodes.len();
                    out.nodes.push(EMPTY_NODE);
                    queue.push((index, c, depth + 1));
                    u32::try_from(index).ok().filter(|&i| i & LEAF == 0)?
                };
            }
            out.nodes[w] = node;
        }
        out.nodes.shrink_to_fit();
        out.blocks.shrink_to_fit();
        out.slots.shrink_to_fit();
        Some(out)
    }

    /// Appends the blocks of the Bvh2 leaf `slots first..first + count`; its reference.
    fn leaf(&mut self, first: u32, count: u32, tris: &[RtTriangle]) -> Option<u32> {
        let first_block = u32::try_from(self.blocks.len()).ok()?;
        let n_blocks = count.div_ceil(BLOCK as u32);
        if first_block >= 1 << LEAF_FIRST_BITS || n_blocks > LEAF_MAX_BLOCKS {
            return None;
        }
        for chunk in (first..first + count).collect::<Vec<u32>>().chunks(BLOCK) {
            let mut block = EMPTY_BLOCK;
            let mut slots = [EMPTY; BLOCK];
            for (lane, &slot) in chunk.iter().enumerate() {
                let t = tris.get(slot as usize)?;
                for axis in 0..3 {
                    block.v0[axis][lane] = t.v0[axis];
                    block.e1[axis][lane] = t.e1[axis];
                    block.e2[axis][lane] = t.e2[axis];
                    block.ng[axis][lane] = t.ng[axis];
                }
                slots[lane] = slot;
            }
            self.blocks.push(block);
            self.slots.push(slots);
        }
        Some(LEAF | n_blocks << LEAF_FIRST_BITS | first_block)
    }

    /// The triangle (obvhs form, bit-identical to the `RtTriangle` it was converted from)
    /// behind a hit reference `prim = block * 4 + lane`; `None` for a reference outside the
    /// blocks. Read from the block the hit test just loaded, so shading a hit costs no
    /// extra cache miss and no per-slot copy of the triangles is kept.
    #[inline]
    pub(crate) fn triangle(&self, prim: u32) -> Option<RtTriangle> {
        let b = self.blocks.get((prim / BLOCK as u32) as usize)?;
        let lane = (prim % BLOCK as u32) as usize;
        let v = |a: &[[f32; BLOCK]; 3]| glam::Vec3A::new(a[0][lane], a[1][lane], a[2][lane]);
        Some(RtTriangle {
            v0: v(&b.v0),
            e1: v(&b.e1),
            e2: v(&b.e2),
            ng: v(&b.ng),
        })
    }

    /// The BVH slot behind a hit reference; `None` outside the blocks or on a padding lane.
    #[inline]
    pub(crate) fn slot(&self, prim: u32) -> Option<u32> {
        let slot = self.slots.get((prim / BLOCK as u32) as usize)?[(prim % BLOCK as u32) as usize];
        (slot != EMPTY).then_some(slot)
    }

    /// Node count.
    pub(crate) fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Bytes of nodes and triangle blocks (lengths).
    pub(crate) fn memory_bytes(&self) -> u64 {
        (self.nodes.len() * size_of::<WideNode>()
            + self.blocks.len() * (size_of::<TriBlock>() + size_of::<[u32; BLOCK]>()))
            as u64
    }

    /// Closest triangle along `ray` before `ray.tmax` as `(prim, t)`, `prim` a
    /// [`WideBvh::triangle`] reference (`block * 4 + lane`); shrinks `ray.tmax`. Counts one
    /// node visit per wide node and 4 primitive tests per block.
    #[inline]
    pub(crate) fn closest(&self, ray: &mut Ray, work: &mut RayWork) -> Option<(u32, f32)> {
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is set only when the CPU reports AVX and POPCNT.
            return unsafe { closest_avx(self, ray, work) };
        }
        self.closest_with::<Portable>(ray, work)
    }

    /// Whether any triangle lies along `ray` before `ray.tmax`.
    #[inline]
    pub(crate) fn any(&self, ray: &mut Ray, work: &mut RayWork) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is set only when the CPU reports AVX and POPCNT.
            return unsafe { any_avx(self, ray, work) };
        }
        self.any_with::<Portable>(ray, work)
    }

    /// Visits the triangle slots of the leaves `ray` reaches (nearest child first);
    /// `leaf(ray, slot)` may shrink `ray.tmax` and returns `false` to stop. Scalar
    /// per-slot form for callers that test their own primitives.
    #[inline(always)]
    pub(crate) fn traverse_slots(
        &self,
        ray: &mut Ray,
        work: &mut RayWork,
        mut leaf: impl FnMut(&mut Ray, u32) -> bool,
    ) {
        self.traverse::<Portable, false>(ray, work, |ray, first, blocks| {
            let slots = self
                .slots
                .get(first..first + blocks.len())
                .unwrap_or_default();
            for s in slots {
                for &slot in s {
                    if slot != EMPTY && !leaf(ray, slot) {
                        return false;
                    }
                }
            }
            true
        });
    }

    #[inline(always)]
    fn closest_with<N: NodeTest>(&self, ray: &mut Ray, work: &mut RayWork) -> Option<(u32, f32)> {
        let mut best = None;
        let mut tests = 0u32;
        self.traverse::<N, false>(ray, work, |ray, first, blocks| {
            for (i, b) in blocks.iter().enumerate() {
                tests += BLOCK as u32;
                let t = block_hits(b, ray);
                for lane in 0..BLOCK {
                    if t[lane] < ray.tmax {
                        ray.tmax = t[lane];
                        best = Some((((first + i) * BLOCK + lane) as u32, t[lane]));
                    }
                }
            }
            true
        });
        work.primitive_tests += tests;
        best
    }

    #[inline(always)]
    fn any_with<N: NodeTest>(&self, ray: &mut Ray, work: &mut RayWork) -> bool {
        let mut hit = false;
        let mut tests = 0u32;
        self.traverse::<N, true>(ray, work, |ray, _, blocks| {
            for b in blocks {
                tests += BLOCK as u32;
                if block_hits(b, ray).iter().any(|&t| t < ray.tmax) {
                    hit = true;
                    return false;
                }
            }
            true
        });
        work.primitive_tests += tests;
        hit
    }

    /// Stack traversal. Closest-hit mode (`ANY = false`) descends into the nearest hit
    /// child and pushes the others far-to-near with their entry distances, skipping popped
    /// entries beyond `ray.tmax`; any-hit mode skips the sorting.
    #[inline(always)]
    fn traverse<N: NodeTest, const ANY: bool>(
        &self,
        ray: &mut Ray,
        work: &mut RayWork,
        mut leaf: impl FnMut(&mut Ray, usize, &[TriBlock]) -> bool,
    ) {
        if self.root == EMPTY {
            return;
        }
        let mut stack: [MaybeUninit<(u32, f32)>; STACK] = [const { MaybeUninit::uninit() }; STACK];
        let mut sp = 0usize;
        let mut cur = self.root;
        let mut visits = 0u32;
        'walk: loop {
            if cur & LEAF != 0 {
                let first = (cur & ((1 << LEAF_FIRST_BITS) - 1)) as usize;
                let count = ((cur & !LEAF) >> LEAF_FIRST_BITS) as usize;
                if let Some(blocks) = self.blocks.get(first..first + count)
                    && !leaf(ray, first, blocks)
                {
                    break 'walk;
                }
            } else if let Some(node) = self.nodes.get(cur as usize) {
                visits += 1;
                let (mut mask, dist) = N::test(node, ray);
                if PREFETCH {
                    let mut m = mask;
                    while m != 0 {
                        self.prefetch(node.child[m.trailing_zeros() as usize]);
                        m &= m - 1;
                    }
                }
                match mask.count_ones() {
                    0 => {}
                    1 => {
                        cur = node.child[mask.trailing_zeros() as usize];
                        continue 'walk;
                    }
                    hits => {
                        let mut near = [(EMPTY, 0.0f32); WIDTH];
                        let mut k = 0;
                        while mask != 0 {
                            let lane = mask.trailing_zeros() as usize;
                            mask &= mask - 1;
                            let e = (node.child[lane], dist[lane]);
                            if ANY {
                                near[k] = e;
                            } else {
                                // Insertion sort, nearest first.
                                let mut j = k;
                                while j > 0 && near[j - 1].1 > e.1 {
                                    near[j] = near[j - 1];
                                    j -= 1;
                                }
                                near[j] = e;
                            }
                            k += 1;
                        }
                        for e in near[1..hits as usize].iter().rev() {
                            // The depth limit of the conversion keeps sp < STACK.
                            if let Some(s) = stack.get_mut(sp) {
                                s.write(*e);
                                sp += 1;
                            }
                        }
                        cur = near[0].0;
                        continue 'walk;
                    }
                }
            }
            // Pop the next entry still in front of the closest hit.
            loop {
                if sp == 0 {
                    break 'walk;
                }
                sp -= 1;
                // SAFETY: entries below `sp` were written by the push above.
                let (child, d) = unsafe { stack[sp].assume_init() };
                if ANY || d < ray.tmax {
                    cur = child;
                    continue 'walk;
                }
            }
        }
        work.node_visits += visits;
    }
}

const PREFETCH: bool = true;

impl WideBvh {
    /// Starts loading child `c` (a node's 4 cache lines, or a leaf's first two blocks) so
    /// the misses of all children a ray enters overlap (memory-level parallelism).
    #[inline(always)]
    fn prefetch(&self, c: u32) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
            let (base, lines): (*const i8, usize) = if c & LEAF != 0 {
                let first = (c & ((1 << LEAF_FIRST_BITS) - 1)) as usize;
                let count = ((c & !LEAF) >> LEAF_FIRST_BITS) as usize;
                (
                    self.blocks.as_ptr().wrapping_add(first).cast(),
                    count.min(2) * size_of::<TriBlock>() / 64,
                )
            } else {
                (
                    self.nodes.as_ptr().wrapping_add(c as usize).cast(),
                    size_of::<WideNode>().div_ceil(64),
                )
            };
            for k in 0..lines {
                // SAFETY: a prefetch is a hint and never faults, whatever the address.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(base.wrapping_add(k * 64)) };
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = c;
    }
}

/// Whether the 256-bit node test can run (AVX with POPCNT, which every AVX CPU has).
fn detect_avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx") && std::arch::is_x86_feature_detected!("popcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,popcnt")]
unsafe fn closest_avx(bvh: &WideBvh, ray: &mut Ray, work: &mut RayWork) -> Option<(u32, f32)> {
    bvh.closest_with::<Avx>(ray, work)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,popcnt")]
unsafe fn any_avx(bvh: &WideBvh, ray: &mut Ray, work: &mut RayWork) -> bool {
    bvh.any_with::<Avx>(ray, work)
}

/// The 8-box slab test of a node: bit `i` of the mask is set when the ray enters child
/// box `i` (exit >= entry, exit >= 0) at an entry distance below `ray.tmax`; entry
/// distances per lane. Same arithmetic as obvhs `Aabb::intersect_ray`.
pub(crate) trait NodeTest {
    fn test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]);
}

/// Plain per-lane code (auto-vectorised where the compiler can).
pub(crate) struct Portable;

impl NodeTest for Portable {
    #[inline(always)]
    fn test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        let mut entry = [0.0f32; WIDTH];
        let mut mask = 0u32;
        for lane in 0..WIDTH {
            let mut t_in = f32::NEG_INFINITY;
            let mut t_out = f32::INFINITY;
            for axis in 0..3 {
                let t1 = (node.lo[axis][lane] - ray.origin[axis]) * ray.inv_direction[axis];
                let t2 = (node.hi[axis][lane] - ray.origin[axis]) * ray.inv_direction[axis];
                t_in = t_in.max(t1.min(t2));
                t_out = t_out.min(t1.max(t2));
            }
            entry[lane] = t_in;
            if t_out >= t_in && t_out >= 0.0 && t_in < ray.tmax {
                mask |= 1 << lane;
            }
        }
        (mask, entry)
    }
}

/// 256-bit AVX node test; only called from `#[target_feature(enable = "avx,popcnt")]` functions
/// after runtime detection.
#[cfg(target_arch = "x86_64")]
struct Avx;

#[cfg(target_arch = "x86_64")]
impl NodeTest for Avx {
    #[inline(always)]
    fn test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        use std::arch::x86_64::*;
        // SAFETY: inlined only into AVX-enabled callers (see `closest_avx`); loads are from
        // 32-byte aligned arrays of 8 f32.
        unsafe {
            let mut t_in = _mm256_set1_ps(f32::NEG_INFINITY);
            let mut t_out = _mm256_set1_ps(f32::INFINITY);
            for axis in 0..3 {
                let o = _mm256_set1_ps(ray.origin[axis]);
                let inv = _mm256_set1_ps(ray.inv_direction[axis]);
                let lo = _mm256_load_ps(node.lo[axis].as_ptr());
                let hi = _mm256_load_ps(node.hi[axis].as_ptr());
                let t1 = _mm256_mul_ps(_mm256_sub_ps(lo, o), inv);
                let t2 = _mm256_mul_ps(_mm256_sub_ps(hi, o), inv);
                t_in = _mm256_max_ps(t_in, _mm256_min_ps(t1, t2));
                t_out = _mm256_min_ps(t_out, _mm256_max_ps(t1, t2));
            }
            let ok = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(t_out, t_in),
                _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GE_OQ>(t_out, _mm256_setzero_ps()),
                    _mm256_cmp_ps::<_CMP_LT_OQ>(t_in, _mm256_set1_ps(ray.tmax)),
                ),
            );
            let mut entry = [0.0f32; WIDTH];
            _mm256_storeu_ps(entry.as_mut_ptr(), t_in);
            (_mm256_movemask_ps(ok) as u32, entry)
        }
    }
}

/// Möller-Trumbore (1997) on the 4 lanes of a block, exactly obvhs'
/// `RtTriangle::intersect`: each lane's `t` if it hits within `[ray.tmin, ray.tmax]`, else
/// `+inf` (padding lanes, all zero, compute `t = NaN` and never hit).
#[inline(always)]
pub(crate) fn block_hits(b: &TriBlock, ray: &Ray) -> [f32; BLOCK] {
    #[cfg(target_arch = "x86_64")]
    {
        block_hits_sse(b, ray)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        block_hits_portable(b, ray)
    }
}

/// The per-lane reference form of [`block_hits`].
#[inline(always)]
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
fn block_hits_portable(b: &TriBlock, ray: &Ray) -> [f32; BLOCK] {
    let (o, d) = (ray.origin, ray.direction);
    let mut out = [f32::INFINITY; BLOCK];
    for lane in 0..BLOCK {
        let c = [
            b.v0[0][lane] - o.x,
            b.v0[1][lane] - o.y,
            b.v0[2][lane] - o.z,
        ];
        let r = [
            d.y * c[2] - d.z * c[1],
            d.z * c[0] - d.x * c[2],
            d.x * c[1] - d.y * c[0],
        ];
        let ng = [b.ng[0][lane], b.ng[1][lane], b.ng[2][lane]];
        let inv_det = 1.0 / (ng[0] * d.x + ng[1] * d.y + ng[2] * d.z);
        let u = (r[0] * b.e2[0][lane] + r[1] * b.e2[1][lane] + r[2] * b.e2[2][lane]) * inv_det;
        let v = (r[0] * b.e1[0][lane] + r[1] * b.e1[1][lane] + r[2] * b.e1[2][lane]) * inv_det;
        let w = 1.0 - u - v;
        let signs = u.to_bits() | v.to_bits() | w.to_bits();
        if inv_det != 0.0 && signs & 0x8000_0000 == 0 {
            let t = (ng[0] * c[0] + ng[1] * c[1] + ng[2] * c[2]) * inv_det;
            if t >= ray.tmin && t <= ray.tmax {
                out[lane] = t;
            }
        }
    }
    out
}

/// SSE form of [`block_hits`] (SSE2 is part of x86_64: no detection needed). Same
/// operations in the same order as the portable form, no fused multiply-add.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn block_hits_sse(b: &TriBlock, ray: &Ray) -> [f32; BLOCK] {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is baseline on x86_64; loads are from 16-byte aligned arrays of 4 f32.
    unsafe {
        let ld = |a: &[f32; BLOCK]| _mm_load_ps(a.as_ptr());
        let (ox, oy, oz) = (
            _mm_set1_ps(ray.origin.x),
            _mm_set1_ps(ray.origin.y),
            _mm_set1_ps(ray.origin.z),
        );
        let (dx, dy, dz) = (
            _mm_set1_ps(ray.direction.x),
            _mm_set1_ps(ray.direction.y),
            _mm_set1_ps(ray.direction.z),
        );
        let cx = _mm_sub_ps(ld(&b.v0[0]), ox);
        let cy = _mm_sub_ps(ld(&b.v0[1]), oy);
        let cz = _mm_sub_ps(ld(&b.v0[2]), oz);
        let rx = _mm_sub_ps(_mm_mul_ps(dy, cz), _mm_mul_ps(dz, cy));
        let ry = _mm_sub_ps(_mm_mul_ps(dz, cx), _mm_mul_ps(dx, cz));
        let rz = _mm_sub_ps(_mm_mul_ps(dx, cy), _mm_mul_ps(dy, cx));
        let dot = |ax: __m128, ay: __m128, az: __m128, bx: __m128, by: __m128, bz: __m128| {
            _mm_add_ps(
                _mm_add_ps(_mm_mul_ps(ax, bx), _mm_mul_ps(ay, by)),
                _mm_mul_ps(az, bz),
            )
        };
        let (ngx, ngy, ngz) = (ld(&b.ng[0]), ld(&b.ng[1]), ld(&b.ng[2]));
        let inv_det = _mm_div_ps(_mm_set1_ps(1.0), dot(ngx, ngy, ngz, dx, dy, dz));
        let u = _mm_mul_ps(
            dot(rx, ry, rz, ld(&b.e2[0]), ld(&b.e2[1]), ld(&b.e2[2])),
            inv_det,
        );
        let v = _mm_mul_ps(
            dot(rx, ry, rz, ld(&b.e1[0]), ld(&b.e1[1]), ld(&b.e1[2])),
            inv_det,
        );
        let w = _mm_sub_ps(_mm_sub_ps(_mm_set1_ps(1.0), u), v);
        let t = _mm_mul_ps(dot(ngx, ngy, ngz, cx, cy, cz), inv_det);
        // All sign bits clear (u, v, w >= +0, no NaN with the sign set).
        let signs = _mm_or_ps(_mm_or_ps(u, v), w);
        let positive =
            _mm_castsi128_ps(_mm_cmpgt_epi32(_mm_castps_si128(signs), _mm_set1_epi32(-1)));
        let valid = _mm_and_ps(
            _mm_and_ps(positive, _mm_cmpneq_ps(inv_det, _mm_setzero_ps())),
            _mm_and_ps(
                _mm_cmpge_ps(t, _mm_set1_ps(ray.tmin)),
                _mm_cmple_ps(t, _mm_set1_ps(ray.tmax)),
            ),
        );
        let hit_t = select_ps(_mm_set1_ps(f32::INFINITY), t, valid);
        let mut out = [0.0f32; BLOCK];
        _mm_storeu_ps(out.as_mut_ptr(), hit_t);
        out
    }
}

/// `mask ? a_true : a_false` per lane with SSE2 bit operations.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn select_ps(
    a_false: std::arch::x86_64::__m128,
    a_true: std::arch::x86_64::__m128,
    mask: std::arch::x86_64::__m128,
) -> std::arch::x86_64::__m128 {
    use std::arch::x86_64::*;
    // SAFETY: SSE is baseline on x86_64.
    unsafe { _mm_or_ps(_mm_and_ps(mask, a_true), _mm_andnot_ps(mask, a_false)) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;
    use obvhs::triangle::Triangle;

    /// A small deterministic pseudo-random sequence in [0, 1).
    fn lcg(state: &mut u64) -> f32 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*state >> 40) as f32) / (1u64 << 24) as f32
    }

    fn random_tris(n: usize, seed: u64) -> Vec<RtTriangle> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                let c = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                let mut v = || c + Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 0.6 - 0.3;
                RtTriangle::from(&Triangle {
                    v0: v(),
                    v1: v(),
                    v2: v(),
                })
            })
            .collect()
    }

    #[test]
    fn block_test_is_bit_identical_to_obvhs_intersect() {
        // 399: the last block has a padding lane, which must never hit.
        let tris = random_tris(399, 7);
        let mut s = 99u64;
        for chunk in tris.chunks(BLOCK) {
            let mut w = WideBvh {
                nodes: Vec::new(),
                blocks: Vec::new(),
                slots: Vec::new(),
                root: EMPTY,
                avx: false,
            };
            assert!(w.leaf(0, chunk.len() as u32, chunk).is_some());
            let block = w.blocks[0];
            for _ in 0..200 {
                let o = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 6.0 - 3.0;
                let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                let ray = Ray::new(o, (target - o).normalize(), 0.0, 100.0);
                let simd = block_hits(&block, &ray);
                let portable = block_hits_portable(&block, &ray);
                for lane in 0..BLOCK {
                    let scalar = chunk.get(lane).map_or(f32::INFINITY, |t| t.intersect(&ray));
                    assert_eq!(simd[lane].to_bits(), scalar.to_bits(), "lane {lane}");
                    assert_eq!(portable[lane].to_bits(), scalar.to_bits(), "lane {lane}");
                }
            }
        }
    }

    #[test]
    fn hit_references_give_back_the_converted_triangle_and_slot() {
        let tris = random_tris(2000, 11);
        let plain: Vec<Triangle> = tris
            .iter()
            .map(|t| {
                let (v0, e1, e2) = (t.v0, t.e1, t.e2);
                Triangle {
                    v0,
                    v1: v0 - e1,
                    v2: v0 + e2,
                }
            })
            .collect();
        let mut time = std::time::Duration::default();
        let bvh = obvhs::bvh2::builder::build_bvh2_from_tris(
            &plain,
            obvhs::BvhBuildParams::medium_build(),
            &mut time,
        );
        let slot_tris: Vec<RtTriangle> = bvh
            .primitive_indices
            .iter()
            .map(|&i| RtTriangle::from(&plain[i as usize]))
            .collect();
        let w = WideBvh::from_bvh2(&bvh, &slot_tris).expect("converts");
        assert_eq!(w.blocks.len(), w.slots.len());
        let mut seen = vec![false; slot_tris.len()];
        for prim in 0..(w.blocks.len() * BLOCK) as u32 {
            let Some(slot) = w.slot(prim) else { continue };
            assert!(
                !std::mem::replace(&mut seen[slot as usize], true),
                "slot twice"
            );
            let (got, want) = (
                w.triangle(prim).expect("in range"),
                slot_tris[slot as usize],
            );
            for (a, b) in [
                (got.v0, want.v0),
                (got.e1, want.e1),
                (got.e2, want.e2),
                (got.ng, want.ng),
            ] {
                assert_eq!(
                    a.to_array().map(f32::to_bits),
                    b.to_array().map(f32::to_bits)
                );
            }
        }
        assert!(seen.iter().all(|&s| s), "every slot in some block");
        assert!(w.triangle((w.blocks.len() * BLOCK) as u32).is_none());
    }

    #[test]
    fn node_tests_agree_with_obvhs_slab_test() {
        let tris = random_tris(300, 3);
        let boxes: Vec<_> = tris.iter().map(|t| t.aabb()).collect();
        let mut s = 5u64;
        for chunk in boxes.chunks(WIDTH) {
            let mut node = EMPTY_NODE;
            for (lane, b) in chunk.iter().enumerate() {
                for axis in 0..3 {
                    node.lo[axis][lane] = b.min[axis];
                    node.hi[axis][lane] = b.max[axis];
                }
                node.child[lane] = lane as u32;
            }
            for _ in 0..100 {
                let o = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 6.0 - 3.0;
                let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                let ray = Ray::new(o, (target - o).normalize(), 0.0, 3.0);
                let mut expected = 0u32;
                for (lane, b) in chunk.iter().enumerate() {
                    if b.intersect_ray(&ray) < ray.tmax {
                        expected |= 1 << lane;
                    }
                }
                assert_eq!(Portable::test(&node, &ray).0, expected);
                #[cfg(target_arch = "x86_64")]
                if detect_avx() {
                    // SAFETY: AVX detected above.
                    let avx = unsafe { avx_test(&node, &ray) };
                    assert_eq!(avx.0, expected);
                }
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,popcnt")]
    unsafe fn avx_test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        Avx::test(node, ray)
    }
}
