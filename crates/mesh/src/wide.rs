//! An 8-wide CPU BVH converted from an obvhs [`Bvh2`], traversed with SIMD box tests (8
//! child boxes per node in one AVX test, runtime-detected, with a portable fallback) and
//! SIMD triangle tests (blocks of 4 triangles, SSE on x86_64, portable elsewhere); on a CPU
//! with AVX-512 the same code is compiled with it enabled ([`Isa::Avx512`]).
//!
//! Layout (after Wald et al. 2008 "Getting rid of packets" and Embree's BVH8 with
//! triangle4 blocks, Wald et al. 2014): each node holds its 8 child boxes as structure of
//! arrays plus 8 child references; leaves are runs of [`TriBlock`]s holding 4 triangles each
//! as structure of arrays, in BVH slot order, so slots, normals and materials of the
//! [`crate::blas::Blas`] stay valid. Conversion collapses the Bvh2 by the SAH-optimal
//! dynamic programme of Ylitie et al. 2017 (see [`Collapse`]), which fills nodes (5.8 of 8
//! children on average on the dragons against 4.4 for opening the largest child greedily)
//! and may merge small Bvh2 leaves into one block.
//!
//! Exactness: the triangle test is obvhs' `RtTriangle::intersect` (Möller-Trumbore) computed
//! lane-wise in the same operation order without fused multiply-add, so every `t` is
//! bit-identical to the Bvh2 path; the box test is obvhs' `Aabb::intersect_ray` slab test.
//! Closest hits therefore equal the Bvh2 path's except for exact ties between triangles at
//! the same `t` (shared edges), where the visiting order picks the winner.

// Lane loops index several structure-of-arrays fields by the same lane, mirroring SIMD lanes.
#![allow(clippy::needless_range_loop)]

use std::mem::MaybeUninit;

use glam::Vec3A;
use marchmesh_core::RayWork;
use obvhs::{bvh2::Bvh2, ray::Ray, rt_triangle::RtTriangle};

/// Defines the functions `$avx` and `$avx512` with one signature and body, compiled for
/// [`Isa::Avx`] (AVX and POPCNT enabled) and for [`Isa::Avx512`] (AVX-512 F, VL, BW and DQ
/// as well). Both are `unsafe`: call them only at the level [`Isa::detect`] found.
macro_rules! avx_twins {
    ($(#[$m:meta])* $vis:vis unsafe fn [$avx:ident, $avx512:ident] $($signature_and_body:tt)*) => {
        $(#[$m])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx,popcnt")]
        $vis unsafe fn $avx $($signature_and_body)*

        $(#[$m])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx,popcnt,avx512f,avx512vl,avx512bw,avx512dq")]
        $vis unsafe fn $avx512 $($signature_and_body)*
    };
}
pub(crate) use avx_twins;

/// `$avx512 $call` at [`Isa::Avx512`], else `$avx $call` (`$call`: turbofish and
/// arguments); an `unsafe` call of [`avx_twins`] functions, so `$isa` must not be
/// [`Isa::Portable`].
macro_rules! by_isa {
    ($isa:expr, $avx:ident, $avx512:ident, $($call:tt)*) => {
        match $isa {
            Isa::Avx512 => $avx512 $($call)*,
            _ => $avx $($call)*,
        }
    };
}
pub(crate) use by_isa;

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
    pub(crate) v0: [[f32; BLOCK]; 3],
    pub(crate) e1: [[f32; BLOCK]; 3],
    pub(crate) e2: [[f32; BLOCK]; 3],
    pub(crate) ng: [[f32; BLOCK]; 3],
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
    /// Nodes, each node's inner children contiguous, in depth-first order of their parents.
    pub(crate) nodes: HugeBuf<WideNode>,
    /// Triangle blocks, each node's leaf children contiguous.
    pub(crate) blocks: HugeBuf<TriBlock>,
    /// BVH slots of each block's lanes (`EMPTY` on padding lanes), parallel to `blocks`.
    pub(crate) slots: Vec<[u32; BLOCK]>,
    /// Reference of the root (node 0, or a leaf when the whole tree is one leaf).
    pub(crate) root: u32,
    /// The SIMD level traversal runs at on this CPU (detected at build).
    pub(crate) isa: Isa,
    /// Whether single-ray traversal prefetches the children a ray enters: only for trees
    /// of at least [`PREFETCH_MIN_BYTES`], whose nodes come from memory rather than cache.
    pub(crate) prefetch: bool,
}

impl WideBvh {
    /// Converts a Bvh2 whose leaves index `tris` (slot order). `None` when the tree is too
    /// deep for the fixed traversal stack or too large for the 24-bit block references
    /// (more than 16M blocks): the caller keeps the Bvh2, which has no such limits.
    pub(crate) fn from_bvh2(bvh: &Bvh2, tris: &[RtTriangle]) -> Option<Self> {
        let mut out = Builder::default();
        if bvh.nodes.is_empty() {
            return Some(out.finish(EMPTY));
        }
        let plan = Collapse::plan(bvh)?;
        if plan.leaf_at_root() {
            let slots = plan.slots_under(bvh, 0)?;
            let root = out.leaf(&slots, tris)?;
            return Some(out.finish(root));
        }
        out.nodes.push(EMPTY_NODE);
        // (wide node index, Bvh2 node index, depth)
        let mut queue: Vec<(usize, usize, u32)> = vec![(0, 0, 1)];
        let mut children = Vec::with_capacity(WIDTH);
        while let Some((w, b, depth)) = queue.pop() {
            if depth > MAX_DEPTH {
                return None;
            }
            children.clear();
            plan.children(bvh, b, &mut children)?;
            let mut node = EMPTY_NODE;
            for (lane, &(c, is_leaf)) in children.iter().enumerate() {
                let aabb = bvh.nodes.get(c)?.aabb();
                for axis in 0..3 {
                    node.lo[axis][lane] = aabb.min[axis];
                    node.hi[axis][lane] = aabb.max[axis];
                }
                node.child[lane] = if is_leaf {
                    let slots = plan.slots_under(bvh, c)?;
                    out.leaf(&slots, tris)?
                } else {
                    let index = out.nodes.len();
                    out.nodes.push(EMPTY_NODE);
                    queue.push((index, c, depth + 1));
                    u32::try_from(index).ok().filter(|&i| i & LEAF == 0)?
                };
            }
            out.nodes[w] = node;
        }
        Some(out.finish(0))
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
        if self.isa != Isa::Portable {
            // SAFETY: `isa` is above `Portable` only when the CPU reports its features.
            return unsafe {
                use {closest_avx as c, closest_avx512 as c512};
                match (self.prefetch, ray.origin == Vec3A::ZERO) {
                    (true, false) => by_isa!(self.isa, c, c512, ::<Avx, true>(self, ray, work)),
                    (false, false) => by_isa!(self.isa, c, c512, ::<Avx, false>(self, ray, work)),
                    (true, true) => {
                        by_isa!(self.isa, c, c512, ::<AvxAtOrigin, true>(self, ray, work))
                    }
                    (false, true) => {
                        by_isa!(self.isa, c, c512, ::<AvxAtOrigin, false>(self, ray, work))
                    }
                }
            };
        }
        match self.prefetch {
            true => self.closest_with::<Portable, true>(ray, work),
            false => self.closest_with::<Portable, false>(ray, work),
        }
    }

    /// Whether any triangle lies along `ray` before `ray.tmax`.
    #[inline]
    pub(crate) fn any(&self, ray: &mut Ray, work: &mut RayWork) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.isa != Isa::Portable {
            // SAFETY: `isa` is above `Portable` only when the CPU reports its features.
            return unsafe {
                match self.prefetch {
                    true => by_isa!(self.isa, any_avx, any_avx512, ::<true>(self, ray, work)),
                    false => by_isa!(self.isa, any_avx, any_avx512, ::<false>(self, ray, work)),
                }
            };
        }
        match self.prefetch {
            true => self.any_with::<Portable, true>(ray, work),
            false => self.any_with::<Portable, false>(ray, work),
        }
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
        let mut blocks_leaf = |ray: &mut Ray, first: usize, blocks: &[TriBlock]| {
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
        };
        match self.prefetch {
            true => self.traverse::<Portable, false, true>(ray, work, &mut blocks_leaf),
            false => self.traverse::<Portable, false, false>(ray, work, &mut blocks_leaf),
        }
    }

    #[inline(always)]
    fn closest_with<N: NodeTest, const PREFETCH: bool>(
        &self,
        ray: &mut Ray,
        work: &mut RayWork,
    ) -> Option<(u32, f32)> {
        let mut best = None;
        let mut tests = 0u32;
        self.traverse::<N, false, PREFETCH>(ray, work, |ray, first, blocks| {
            tests += closest_in_blocks(first, blocks, ray, &mut best);
            true
        });
        work.primitive_tests += tests;
        best
    }

    #[inline(always)]
    fn any_with<N: NodeTest, const PREFETCH: bool>(
        &self,
        ray: &mut Ray,
        work: &mut RayWork,
    ) -> bool {
        let mut hit = false;
        let mut tests = 0u32;
        self.traverse::<N, true, PREFETCH>(ray, work, |ray, _, blocks| {
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
    fn traverse<N: NodeTest, const ANY: bool, const PREFETCH: bool>(
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
                let (first, count) = leaf_range(cur);
                if let Some(blocks) = self.blocks.get(first..first + count)
                    && !leaf(ray, first, blocks)
                {
                    break 'walk;
                }
            } else if let Some(node) = self.nodes.get(cur as usize) {
                visits += 1;
                let (mask, dist) = N::test(node, ray);
                if PREFETCH {
                    self.prefetch_children(node, mask);
                }
                match mask.count_ones() {
                    0 => {}
                    1 => {
                        cur = node.child[mask.trailing_zeros() as usize];
                        continue 'walk;
                    }
                    2 if !ANY => {
                        let (near, far) = two_entered(node, &dist, mask);
                        if let Some(s) = stack.get_mut(sp) {
                            s.write(far);
                            sp += 1;
                        }
                        cur = near.0;
                        continue 'walk;
                    }
                    hits => {
                        let near = entered_children::<ANY>(node, &dist, mask);
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

/// Cost of testing one node's 8 child boxes, per unit of the node's surface area.
const COST_NODE: f32 = 1.0;
/// Cost of testing one triangle block, per unit of the leaf's surface area: half a node
/// test. Measured: `docs/decisions/0013`.
const COST_BLOCK: f32 = 0.5;
/// Most triangles a collapsed leaf may hold: two blocks (see [`COST_BLOCK`]).
const MAX_LEAF_TRIS: u32 = 8;

/// How one Bvh2 subtree is represented with `k + 1` wide subtrees (`k` in `0..WIDTH`).
#[derive(Clone, Copy)]
enum Choice {
    /// One leaf holding every triangle below (only for `k = 0`).
    Leaf,
    /// One wide node whose children distribute the two Bvh2 children: the left gets `j + 1`
    /// subtrees, the right the rest of `WIDTH` (only for `k = 0`).
    Node(u8),
    /// Fewer subtrees than allowed are cheaper: as for `k - 1`.
    Fewer,
    /// The left Bvh2 child as `j + 1` subtrees, the right as `k - j`.
    Split(u8),
}

/// SAH-optimal collapse of a Bvh2 into 8-wide nodes and leaves of at most
/// [`MAX_LEAF_TRIS`] triangles, by the dynamic programme of Ylitie, Karras, Laine 2017
/// ("Efficient incoherent ray traversal on GPUs through compressed wide BVHs", sec. 4.1):
/// `C(n, k)` is the least SAH cost of representing the subtree `n` with at most `k`
/// subtrees; a leaf costs `area * blocks * COST_BLOCK`, a node `area * COST_NODE` plus
/// the best distribution of its two children over `WIDTH` subtrees.
struct Collapse {
    /// Per Bvh2 node, the choice for each `k + 1` subtrees.
    choice: Vec<[Choice; WIDTH]>,
}

impl Collapse {
    /// `None` when the Bvh2 is malformed (a child index out of range).
    fn plan(bvh: &Bvh2) -> Option<Self> {
        let n = bvh.nodes.len();
        let mut cost = vec![[f32::INFINITY; WIDTH]; n];
        let mut prims = vec![0u32; n];
        let mut choice = vec![[Choice::Fewer; WIDTH]; n];
        // Post-order walk without recursion (degenerate trees can be deep).
        let mut stack: Vec<(usize, bool)> = vec![(0, false)];
        while let Some((i, expanded)) = stack.pop() {
            let node = bvh.nodes.get(i)?;
            let area = node.aabb().half_area();
            if node.is_leaf() {
                prims[i] = node.prim_count;
                let blocks = node.prim_count.div_ceil(BLOCK as u32).max(1) as f32;
                cost[i] = [area * blocks * COST_BLOCK; WIDTH];
                choice[i] = [Choice::Leaf; WIDTH];
                continue;
            }
            let (l, r) = (node.first_index as usize, node.first_index as usize + 1);
            if r >= n {
                return None;
            }
            if !expanded {
                stack.extend([(i, true), (l, false), (r, false)]);
                continue;
            }
            prims[i] = prims[l].saturating_add(prims[r]);
            // distribute(k): least cost of the two children as k + 2 subtrees in all.
            let (cl, cr) = (cost[l], cost[r]);
            let distribute = |k: usize| {
                (0..=k)
                    .map(|j| (cl[j] + cr[k - j], j as u8))
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .unwrap_or((f32::INFINITY, 0))
            };
            let (inner, j) = distribute(WIDTH - 2);
            let mut c0 = (area * COST_NODE + inner, Choice::Node(j));
            if prims[i] <= MAX_LEAF_TRIS {
                let leaf = area * prims[i].div_ceil(BLOCK as u32) as f32 * COST_BLOCK;
                if leaf <= c0.0 {
                    c0 = (leaf, Choice::Leaf);
                }
            }
            cost[i][0] = c0.0;
            choice[i][0] = c0.1;
            for k in 1..WIDTH {
                let (d, j) = distribute(k - 1);
                if d < cost[i][k - 1] {
                    cost[i][k] = d;
                    choice[i][k] = Choice::Split(j);
                } else {
                    cost[i][k] = cost[i][k - 1];
                    choice[i][k] = Choice::Fewer;
                }
            }
        }
        Some(Self { choice })
    }

    /// Whether the whole tree collapses into one leaf.
    fn leaf_at_root(&self) -> bool {
        matches!(self.choice.first().map(|c| c[0]), Some(Choice::Leaf) | None)
    }

    /// Children of the wide node made from Bvh2 node `b` (whose choice is `Node`), as
    /// `(Bvh2 node, is a leaf)`, at most `WIDTH`.
    fn children(&self, bvh: &Bvh2, b: usize, out: &mut Vec<(usize, bool)>) -> Option<()> {
        let Choice::Node(j) = self.choice.get(b)?[0] else {
            return None;
        };
        let l = bvh.nodes.get(b)?.first_index as usize;
        self.expand(bvh, l, j as usize, out)?;
        self.expand(bvh, l + 1, WIDTH - 2 - j as usize, out)
    }

    /// Appends the subtrees representing Bvh2 node `n` with at most `k + 1` subtrees.
    fn expand(&self, bvh: &Bvh2, n: usize, k: usize, out: &mut Vec<(usize, bool)>) -> Option<()> {
        // Depth of this recursion is at most WIDTH: each Split hands out fewer subtrees.
        match *self.choice.get(n)?.get(k)? {
            Choice::Leaf => out.push((n, true)),
            Choice::Node(_) => out.push((n, false)),
            Choice::Fewer => self.expand(bvh, n, k.checked_sub(1)?, out)?,
            Choice::Split(j) => {
                // A Split is only recorded for inner nodes, whose children are
                // `first_index` and `first_index + 1`.
                let l = bvh.nodes.get(n)?.first_index as usize;
                self.expand(bvh, l, j as usize, out)?;
                self.expand(bvh, l + 1, k.checked_sub(1 + j as usize)?, out)?;
            }
        }
        Some(())
    }

    /// The triangle slots of every Bvh2 leaf below node `n`, left to right.
    fn slots_under(&self, bvh: &Bvh2, n: usize) -> Option<Vec<u32>> {
        let mut slots = Vec::new();
        let mut stack = vec![n];
        while let Some(i) = stack.pop() {
            let node = bvh.nodes.get(i)?;
            if node.is_leaf() {
                slots.extend(node.first_index..node.first_index.checked_add(node.prim_count)?);
            } else {
                let l = node.first_index as usize;
                stack.extend([l + 1, l]);
            }
        }
        Some(slots)
    }
}

/// Node and block bytes from which single-ray traversal prefetches each entered child.
/// Below this size the prefetch instructions cost more than the latency they hide (measured: `docs/decisions/0013`).
const PREFETCH_MIN_BYTES: usize = 16 << 20;

impl WideBvh {
    /// [`WideBvh::prefetch`] of every child of `node` whose lane is set in `mask`.
    #[inline(always)]
    fn prefetch_children(&self, node: &WideNode, mut mask: u32) {
        while mask != 0 {
            self.prefetch(node.child[mask.trailing_zeros() as usize]);
            mask &= mask - 1;
        }
    }

    /// Starts loading child `c` (a node's 4 cache lines, or a leaf's first two blocks) so
    /// the misses of all children a ray enters overlap (memory-level parallelism).
    #[inline(always)]
    fn prefetch(&self, c: u32) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
            const NODE_LINES: usize = size_of::<WideNode>().div_ceil(64);
            const BLOCK_LINES: usize = size_of::<TriBlock>() / 64;
            // Constant trip counts, so the loops unroll (a runtime line count kept a loop
            // per entered child: single-ray traversal on dragon_res3 took 15% more
            // instructions, callgrind).
            let line = |p: *const i8, k: usize| {
                // SAFETY: a prefetch is a hint and never faults, whatever the address.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(k * 64)) }
            };
            if c & LEAF != 0 {
                let (first, count) = leaf_range(c);
                let base: *const i8 = self.blocks.as_ptr().wrapping_add(first).cast();
                for k in 0..BLOCK_LINES {
                    line(base, k);
                }
                if count > 1 {
                    for k in BLOCK_LINES..2 * BLOCK_LINES {
                        line(base, k);
                    }
                }
            } else {
                let base: *const i8 = self.nodes.as_ptr().wrapping_add(c as usize).cast();
                for k in 0..NODE_LINES {
                    line(base, k);
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = c;
    }
}

/// The wide BVH under construction, in growable arrays.
#[derive(Default)]
struct Builder {
    nodes: Vec<WideNode>,
    blocks: Vec<TriBlock>,
    slots: Vec<[u32; BLOCK]>,
}

impl Builder {
    /// Appends the blocks of a leaf holding the triangle slots `slots`; its reference.
    fn leaf(&mut self, slots: &[u32], tris: &[RtTriangle]) -> Option<u32> {
        let first_block = u32::try_from(self.blocks.len()).ok()?;
        let n_blocks = u32::try_from(slots.len().div_ceil(BLOCK)).ok()?;
        if first_block >= 1 << LEAF_FIRST_BITS || n_blocks > LEAF_MAX_BLOCKS {
            return None;
        }
        for chunk in slots.chunks(BLOCK) {
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

    /// The finished BVH with root reference `root`.
    fn finish(mut self, root: u32) -> WideBvh {
        self.slots.shrink_to_fit();
        let bytes = size_of_val(&self.nodes[..]) + size_of_val(&self.blocks[..]);
        WideBvh {
            nodes: HugeBuf::from_slice(&self.nodes),
            blocks: HugeBuf::from_slice(&self.blocks),
            slots: self.slots,
            root,
            isa: Isa::detect(),
            prefetch: bytes >= PREFETCH_MIN_BYTES,
        }
    }
}

/// Arrays at least this large go to transparent huge pages ([`HugeBuf`]).
const HUGE_MIN_BYTES: usize = 1 << 20;
/// The x86_64 / aarch64-4k transparent huge page size.
const HUGE_PAGE: usize = 2 << 20;

/// A fixed-length array of `Copy` elements (nodes, triangle blocks). At least
/// [`HUGE_MIN_BYTES`] long it is allocated 2 MiB-aligned, rounded up to whole 2 MiB pages,
/// and on Linux advised `MADV_HUGEPAGE` before it is written, so the kernel backs it with
/// transparent huge pages (when `/sys/kernel/mm/transparent_hugepage/enabled` is `always`
/// or `madvise`; with `never`, or if the advice fails, it is plain memory and works the same).
/// A random walk over the full dragon's ~80 MB of nodes and blocks misses the TLB on most
/// node visits with 4 KiB pages; Embree allocates its BVH on huge pages for the same reason.
pub(crate) struct HugeBuf<T: Copy> {
    ptr: std::ptr::NonNull<T>,
    len: usize,
    /// `None` for an empty buffer (dangling pointer, nothing allocated).
    layout: Option<std::alloc::Layout>,
}

// SAFETY: `HugeBuf` owns its elements like a `Box<[T]>`.
unsafe impl<T: Copy + Send> Send for HugeBuf<T> {}
// SAFETY: shared access only reads, like `&[T]`.
unsafe impl<T: Copy + Sync> Sync for HugeBuf<T> {}

impl<T: Copy> HugeBuf<T> {
    /// A copy of `items`. Aborts through [`std::alloc::handle_alloc_error`] when the memory
    /// cannot be allocated, as `Vec` does.
    pub(crate) fn from_slice(items: &[T]) -> Self {
        let bytes = size_of_val(items);
        if bytes == 0 {
            return Self {
                ptr: std::ptr::NonNull::dangling(),
                len: items.len(),
                layout: None,
            };
        }
        let huge = bytes >= HUGE_MIN_BYTES;
        let layout = if huge {
            std::alloc::Layout::from_size_align(
                bytes.next_multiple_of(HUGE_PAGE),
                HUGE_PAGE.max(align_of::<T>()),
            )
        } else {
            std::alloc::Layout::array::<T>(items.len())
        };
        // A slice's size always fits a layout, short of an address-space-sized slice.
        let layout = layout.unwrap_or_else(|_| panic!("{bytes} bytes do not fit a layout"));
        // SAFETY: `layout` has a non-zero size.
        let raw = unsafe { std::alloc::alloc(layout) };
        let Some(ptr) = std::ptr::NonNull::new(raw.cast::<T>()) else {
            std::alloc::handle_alloc_error(layout)
        };
        #[cfg(target_os = "linux")]
        if huge {
            // SAFETY: the range is the allocation just made, page-aligned (2 MiB) and a whole
            // number of pages long; the advice changes no contents. Failure is harmless.
            unsafe {
                libc::madvise(raw.cast(), layout.size(), libc::MADV_HUGEPAGE);
            }
        }
        // SAFETY: the allocation holds `items.len()` elements of `T`, suitably aligned, and
        // does not overlap `items`.
        unsafe { std::ptr::copy_nonoverlapping(items.as_ptr(), ptr.as_ptr(), items.len()) };
        Self {
            ptr,
            len: items.len(),
            layout: Some(layout),
        }
    }
}

impl<T: Copy> std::ops::Deref for HugeBuf<T> {
    type Target = [T];
    #[inline(always)]
    fn deref(&self) -> &[T] {
        // SAFETY: `ptr` holds `len` initialised elements (or is dangling with `len` zero-sized
        // elements / `len == 0`).
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> Clone for HugeBuf<T> {
    fn clone(&self) -> Self {
        Self::from_slice(self)
    }
}

impl<T: Copy> Drop for HugeBuf<T> {
    fn drop(&mut self) {
        if let Some(layout) = self.layout {
            // SAFETY: allocated in `from_slice` with exactly this layout.
            unsafe { std::alloc::dealloc(self.ptr.as_ptr().cast(), layout) };
        }
    }
}

/// Rays traced together by [`WideBvh::closest_interleaved`].
pub(crate) const INTERLEAVE: usize = 8;

impl WideBvh {
    /// Closest hits of `INTERLEAVE` independent rays, each exactly as [`WideBvh::closest`]
    /// would find it (same visiting order, so the same hit even on ties), traced in turns:
    /// each ray takes one step (a node or a leaf), prefetches what it will read next, and
    /// hands over to the next ray, so the cache misses of different rays overlap instead
    /// of each ray waiting out its own (software pipelining of independent traversals; on
    /// a mesh far larger than the caches a ray is bound by the latency of its dependent
    /// node and block loads). Adds each ray's work to `work[k]`.
    pub(crate) fn closest_interleaved(
        &self,
        rays: &mut [Ray; INTERLEAVE],
        work: &mut [RayWork; INTERLEAVE],
    ) -> [Option<(u32, f32)>; INTERLEAVE] {
        #[cfg(target_arch = "x86_64")]
        if self.isa != Isa::Portable {
            // SAFETY: `isa` is above `Portable` only when the CPU reports its features.
            return unsafe {
                use {interleaved_avx as i, interleaved_avx512 as i512};
                match rays.iter().all(|r| r.origin == Vec3A::ZERO) {
                    true => by_isa!(self.isa, i, i512, ::<AvxAtOrigin>(self, rays, work)),
                    false => by_isa!(self.isa, i, i512, ::<Avx>(self, rays, work)),
                }
            };
        }
        self.interleaved_with::<Portable>(rays, work)
    }

    #[inline(always)]
    fn interleaved_with<N: NodeTest>(
        &self,
        rays: &mut [Ray; INTERLEAVE],
        work: &mut [RayWork; INTERLEAVE],
    ) -> [Option<(u32, f32)>; INTERLEAVE] {
        let mut best = [None; INTERLEAVE];
        if self.root == EMPTY {
            return best;
        }
        let mut stacks: [[MaybeUninit<(u32, f32)>; STACK]; INTERLEAVE] =
            [const { [const { MaybeUninit::uninit() }; STACK] }; INTERLEAVE];
        let mut sps = [0usize; INTERLEAVE];
        let mut curs = [self.root; INTERLEAVE];
        let mut visits = [0u32; INTERLEAVE];
        let mut tests = [0u32; INTERLEAVE];
        let mut active: u32 = (1 << INTERLEAVE) - 1;
        while active != 0 {
            let mut pending = active;
            while pending != 0 {
                let k = pending.trailing_zeros() as usize;
                pending &= pending - 1;
                let ray = &mut rays[k];
                let stack = &mut stacks[k];
                let sp = &mut sps[k];
                let cur = curs[k];
                // One step of `traverse` (closest-hit mode) for ray k.
                if cur & LEAF != 0 {
                    let (first, count) = leaf_range(cur);
                    if let Some(blocks) = self.blocks.get(first..first + count) {
                        tests[k] += closest_in_blocks(first, blocks, ray, &mut best[k]);
                    }
                } else if let Some(node) = self.nodes.get(cur as usize) {
                    visits[k] += 1;
                    let (mask, dist) = N::test(node, ray);
                    self.prefetch_children(node, mask);
                    match mask.count_ones() {
                        0 => {}
                        1 => {
                            curs[k] = node.child[mask.trailing_zeros() as usize];
                            continue;
                        }
                        2 => {
                            let (near, far) = two_entered(node, &dist, mask);
                            if let Some(s) = stack.get_mut(*sp) {
                                s.write(far);
                                *sp += 1;
                            }
                            curs[k] = near.0;
                            continue;
                        }
                        hits => {
                            let near = entered_children::<false>(node, &dist, mask);
                            for e in near[1..hits as usize].iter().rev() {
                                // The depth limit of the conversion keeps sp < STACK.
                                if let Some(s) = stack.get_mut(*sp) {
                                    s.write(*e);
                                    *sp += 1;
                                }
                            }
                            curs[k] = near[0].0;
                            continue;
                        }
                    }
                }
                // Pop the next entry still in front of the closest hit.
                loop {
                    if *sp == 0 {
                        active &= !(1 << k);
                        break;
                    }
                    *sp -= 1;
                    // SAFETY: entries below `sp` were written by the push above.
                    let (child, d) = unsafe { stack[*sp].assume_init() };
                    if d < ray.tmax {
                        curs[k] = child;
                        self.prefetch(child);
                        break;
                    }
                }
            }
        }
        for k in 0..INTERLEAVE {
            work[k].node_visits += visits[k];
            work[k].primitive_tests += tests[k];
        }
        best
    }
}

avx_twins! {
    /// [`WideBvh::interleaved_with`] compiled for AVX / AVX-512.
    unsafe fn [interleaved_avx, interleaved_avx512]<N: NodeTest>(
        bvh: &WideBvh,
        rays: &mut [Ray; INTERLEAVE],
        work: &mut [RayWork; INTERLEAVE],
    ) -> [Option<(u32, f32)>; INTERLEAVE] {
        bvh.interleaved_with::<N>(rays, work)
    }
}

avx_twins! {
    /// [`WideBvh::closest_with`] compiled for AVX / AVX-512.
    unsafe fn [closest_avx, closest_avx512]<N: NodeTest, const PREFETCH: bool>(
        bvh: &WideBvh,
        ray: &mut Ray,
        work: &mut RayWork,
    ) -> Option<(u32, f32)> {
        bvh.closest_with::<N, PREFETCH>(ray, work)
    }
}

avx_twins! {
    /// [`WideBvh::any_with`] compiled for AVX / AVX-512.
    unsafe fn [any_avx, any_avx512]<const PREFETCH: bool>(
        bvh: &WideBvh,
        ray: &mut Ray,
        work: &mut RayWork,
    ) -> bool {
        bvh.any_with::<Avx, PREFETCH>(ray, work)
    }
}

/// The SIMD level traversal runs at, detected once per BVH build ([`Isa::detect`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
// Off x86_64 only `Portable` is ever detected.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(crate) enum Isa {
    /// Plain per-lane code: any CPU.
    Portable,
    /// The 256-bit AVX node tests and SSE triangle tests (AVX and POPCNT).
    Avx,
    /// The same code compiled with AVX-512 F, VL, BW and DQ enabled as well: the compiler
    /// then keeps comparison results in mask registers instead of vector masks and
    /// `movemask`s (the source, and so every rounded operation, stays the same: no fused
    /// multiply-add). Measured against [`Isa::Avx`]: `docs/decisions/0013`.
    Avx512,
}

impl Isa {
    /// The highest level this CPU supports.
    pub(crate) fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx") && has!("popcnt") {
                if has!("avx512f") && has!("avx512vl") && has!("avx512bw") && has!("avx512dq") {
                    return Self::Avx512;
                }
                return Self::Avx;
            }
        }
        Self::Portable
    }

    /// Every level this CPU can run, lowest first (tests compare them).
    #[cfg(test)]
    pub(crate) fn available() -> Vec<Self> {
        [Self::Portable, Self::Avx, Self::Avx512]
            .into_iter()
            .filter(|&l| l <= Self::detect())
            .collect()
    }
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
        avx_node_test::<false>(node, ray)
    }
}

/// [`Avx`] for rays starting at the origin of render space (every camera ray: render space
/// is centred on the camera): `lo - 0` is `lo`, so each plane distance is one product,
/// bit for bit the same as [`Avx`]'s but for the sign of a zero.
#[cfg(target_arch = "x86_64")]
struct AvxAtOrigin;

#[cfg(target_arch = "x86_64")]
impl NodeTest for AvxAtOrigin {
    #[inline(always)]
    fn test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        avx_node_test::<true>(node, ray)
    }
}

/// The 8-lane slab test of [`Avx`] (`AT_ORIGIN = false`) and [`AvxAtOrigin`] (`true`: the
/// ray's origin is 0 and not subtracted).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn avx_node_test<const AT_ORIGIN: bool>(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
    use std::arch::x86_64::*;
    // SAFETY: inlined only into AVX-enabled callers (see `closest_avx`); loads are from
    // 32-byte aligned arrays of 8 f32.
    unsafe {
        let mut t_in = _mm256_set1_ps(f32::NEG_INFINITY);
        let mut t_out = _mm256_set1_ps(f32::INFINITY);
        for axis in 0..3 {
            let inv = _mm256_set1_ps(ray.inv_direction[axis]);
            let lo = _mm256_load_ps(node.lo[axis].as_ptr());
            let hi = _mm256_load_ps(node.hi[axis].as_ptr());
            let (lo, hi) = match AT_ORIGIN {
                true => (lo, hi),
                false => {
                    let o = _mm256_set1_ps(ray.origin[axis]);
                    (_mm256_sub_ps(lo, o), _mm256_sub_ps(hi, o))
                }
            };
            let t1 = _mm256_mul_ps(lo, inv);
            let t2 = _mm256_mul_ps(hi, inv);
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

/// `(index of the first block, block count)` of leaf child `c` (`c & LEAF != 0`).
#[inline(always)]
pub(crate) fn leaf_range(c: u32) -> (usize, usize) {
    (
        (c & ((1 << LEAF_FIRST_BITS) - 1)) as usize,
        ((c & !LEAF) >> LEAF_FIRST_BITS) as usize,
    )
}

/// Tests `ray` against a leaf's `blocks` (the first at block index `first`): each hit nearer
/// than `ray.tmax` shortens the ray and becomes `best` (primitive, t). Returns the triangle
/// tests done.
#[inline(always)]
pub(crate) fn closest_in_blocks(
    first: usize,
    blocks: &[TriBlock],
    ray: &mut Ray,
    best: &mut Option<(u32, f32)>,
) -> u32 {
    for (i, b) in blocks.iter().enumerate() {
        let t = block_hits(b, ray);
        // Most blocks hold no hit: one vector compare decides, and the lanes below `tmax`
        // then update in lane order (a later lane must be strictly nearer), as before.
        let mut below = 0u32;
        for lane in 0..BLOCK {
            below |= u32::from(t[lane] < ray.tmax) << lane;
        }
        while below != 0 {
            let lane = below.trailing_zeros() as usize;
            below &= below - 1;
            if t[lane] < ray.tmax {
                ray.tmax = t[lane];
                *best = Some((((first + i) * BLOCK + lane) as u32, t[lane]));
            }
        }
    }
    (blocks.len() * BLOCK) as u32
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

/// The children of `node` whose lanes are set in `mask`, with their entry distances `dist`:
/// the first `mask.count_ones()` entries, nearest first unless `ANY` (an occlusion query
/// takes any order and skips the sort), the rest `EMPTY`. Shared by single-ray, interleaved
/// and packet traversal so all three visit children in the same order.
#[inline(always)]
pub(crate) fn entered_children<const ANY: bool>(
    node: &WideNode,
    dist: &[f32; WIDTH],
    mut mask: u32,
) -> [(u32, f32); WIDTH] {
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
    near
}

/// The two children a ray enters (`mask` has exactly two lanes set) as `(near, far)`
/// `(child, entry distance)` pairs, in [`entered_children`]' order (the lower lane first on
/// a tie) without its loop: the most common split in closest-hit traversal (single rays
/// 1.020x on dragon_res3, interleaved rays 1.044x on the full dragon).
#[inline(always)]
fn two_entered(node: &WideNode, dist: &[f32; WIDTH], mask: u32) -> ((u32, f32), (u32, f32)) {
    let a = mask.trailing_zeros() as usize;
    let b = (mask & (mask - 1)).trailing_zeros() as usize;
    let (near, far) = if dist[b] < dist[a] { (b, a) } else { (a, b) };
    ((node.child[near], dist[near]), (node.child[far], dist[far]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::triangle::Triangle;

    #[test]
    fn huge_buffers_hold_their_copy_on_both_paths() {
        // Below and above `HUGE_MIN_BYTES` (the second goes to 2 MiB-aligned huge pages),
        // and empty; clones are independent copies.
        for n in [0usize, 1, 1000, HUGE_MIN_BYTES / 4 + 17] {
            let items: Vec<u32> = (0..n as u32).map(|i| i.wrapping_mul(2654435761)).collect();
            let buf = HugeBuf::from_slice(&items);
            assert_eq!(&buf[..], &items[..], "{n} items");
            if size_of_val(&items[..]) >= HUGE_MIN_BYTES {
                assert_eq!(
                    buf.as_ptr() as usize % HUGE_PAGE,
                    0,
                    "huge buffer alignment"
                );
            }
            let copy = buf.clone();
            drop(buf);
            assert_eq!(&copy[..], &items[..], "{n} items, clone");
        }
        let blocks = HugeBuf::from_slice(&[EMPTY_BLOCK; 3]);
        assert_eq!(blocks.len(), 3);
        assert_eq!(blocks.as_ptr() as usize % align_of::<TriBlock>(), 0);
    }

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

    /// `n` random triangles (seed `seed`) built by obvhs with `params` and converted: the
    /// wide BVH and the Bvh2-ordered slot triangles it was converted from.
    fn wide_of_random(
        n: usize,
        seed: u64,
        params: obvhs::BvhBuildParams,
    ) -> (WideBvh, Vec<RtTriangle>) {
        let plain: Vec<Triangle> = random_tris(n, seed)
            .iter()
            .map(|t| Triangle {
                v0: t.v0,
                v1: t.v0 - t.e1,
                v2: t.v0 + t.e2,
            })
            .collect();
        let mut time = std::time::Duration::default();
        let bvh = obvhs::bvh2::builder::build_bvh2_from_tris(&plain, params, &mut time);
        let slot_tris: Vec<RtTriangle> = bvh
            .primitive_indices
            .iter()
            .map(|&i| RtTriangle::from(&plain[i as usize]))
            .collect();
        let w = WideBvh::from_bvh2(&bvh, &slot_tris).expect("converts");
        (w, slot_tris)
    }

    #[test]
    fn block_test_is_bit_identical_to_obvhs_intersect() {
        // 399: the last block has a padding lane, which must never hit.
        let tris = random_tris(399, 7);
        let mut s = 99u64;
        for chunk in tris.chunks(BLOCK) {
            let mut w = Builder::default();
            let slots: Vec<u32> = (0..chunk.len() as u32).collect();
            assert!(w.leaf(&slots, chunk).is_some());
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
        let (w, slot_tris) = wide_of_random(2000, 11, obvhs::BvhBuildParams::medium_build());
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
    fn collapse_fills_nodes_and_keeps_leaves_within_the_leaf_size() {
        let (w, _) = wide_of_random(
            3000,
            23,
            obvhs::BvhBuildParams {
                max_prims_per_leaf: BLOCK as u32,
                ..obvhs::BvhBuildParams::medium_build()
            },
        );
        let mut children = 0;
        for node in w.nodes.iter() {
            let used = node.child.iter().filter(|&&c| c != EMPTY).count();
            assert!((2..=WIDTH).contains(&used), "{used} children");
            // Used lanes first, empty lanes after.
            assert!(node.child[..used].iter().all(|&c| c != EMPTY));
            for &c in &node.child[..used] {
                if c & LEAF != 0 {
                    let blocks = (c & !LEAF) >> LEAF_FIRST_BITS;
                    assert!(
                        blocks as usize * BLOCK
                            <= MAX_LEAF_TRIS.next_multiple_of(BLOCK as u32) as usize
                    );
                }
            }
            children += used;
        }
        // A Bvh2 node has 2 children; the collapse must do much better than pairs (the
        // greedy collapse it replaced averaged 4.4 on the dragons).
        let mean = children as f64 / w.nodes.len() as f64;
        assert!(mean > 5.0, "{mean} children per node");
    }

    #[test]
    fn interleaved_rays_find_exactly_the_single_ray_hits() {
        let (mut w, _) = wide_of_random(4000, 31, obvhs::BvhBuildParams::medium_build());
        let mut s = 41u64;
        let mut hits = 0;
        for isa in Isa::available() {
            w.isa = isa;
            for _ in 0..64 {
                let rays: [Ray; INTERLEAVE] = std::array::from_fn(|_| {
                    let o = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 8.0 - 4.0;
                    let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                    Ray::new(o, (target - o).normalize(), 0.0, 100.0)
                });
                let mut together = rays;
                let mut work = [RayWork::default(); INTERLEAVE];
                let got = w.closest_interleaved(&mut together, &mut work);
                for k in 0..INTERLEAVE {
                    let mut alone = rays[k];
                    let mut single_work = RayWork::default();
                    let want = w.closest(&mut alone, &mut single_work);
                    assert_eq!(
                        got[k].map(|(p, t)| (p, t.to_bits())),
                        want.map(|(p, t)| (p, t.to_bits()))
                    );
                    assert_eq!(work[k], single_work);
                    hits += usize::from(want.is_some());
                }
            }
        }
        assert!(hits > 100, "{hits} hits: the rays must mostly hit");
    }

    #[test]
    fn every_isa_level_gives_the_portable_answers() {
        // Each level (`Isa::available`: portable, AVX, AVX-512 where the CPU has them)
        // compiles the same source; closest and any-hit queries, interleaved batches and
        // packets must return what the portable code returns, bit for bit, with the same
        // work counts, for rays from the origin (the camera's) and from elsewhere.
        let (mut w, _) = wide_of_random(4000, 53, obvhs::BvhBuildParams::medium_build());
        let mut s = 59u64;
        let mut batches: Vec<[Ray; INTERLEAVE]> = Vec::new();
        for b in 0..48 {
            let shared = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 8.0 - 4.0;
            batches.push(std::array::from_fn(|_| {
                let o = if b % 2 == 0 { Vec3A::ZERO } else { shared };
                let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                Ray::new(o, (target - o).normalize(), 0.0, 100.0)
            }));
        }
        type Hit = Option<(u32, u32)>;
        // Per ray (closest, work, any), per batch ray (interleaved, then packet), counts.
        type Answers = (Vec<(Hit, RayWork, bool)>, Vec<Hit>, Vec<u32>);
        let answers = |w: &WideBvh| -> Answers {
            let bits = |h: Option<(u32, f32)>| h.map(|(p, t)| (p, t.to_bits()));
            let (mut single, mut batched, mut counts) = (Vec::new(), Vec::new(), Vec::new());
            for rays in &batches {
                for ray in rays {
                    let (mut r, mut work) = (*ray, RayWork::default());
                    let closest = bits(w.closest(&mut r, &mut work));
                    let mut r = *ray;
                    single.push((closest, work, w.any(&mut r, &mut RayWork::default())));
                }
                let (mut r, mut work) = (*rays, [RayWork::default(); INTERLEAVE]);
                batched.extend(w.closest_interleaved(&mut r, &mut work).map(bits));
                counts.extend(work.iter().map(|k| k.node_visits));
                let (mut r, mut visits, mut tests) = (*rays, 0, [0; crate::packet::PACKET]);
                let packet = crate::packet::closest8(w, &mut r, &mut visits, &mut tests)
                    .expect("the rays of a batch share their origin");
                batched.extend(packet.map(bits));
                counts.push(visits);
                counts.extend(tests);
            }
            (single, batched, counts)
        };
        w.isa = Isa::Portable;
        let portable = answers(&w);
        let hits = portable.0.iter().filter(|a| a.0.is_some()).count();
        assert!(hits > 100, "{hits} hits: the rays must mostly hit");
        for isa in Isa::available() {
            w.isa = isa;
            assert!(
                answers(&w) == portable,
                "{isa:?} differs from the portable code"
            );
        }
    }

    #[test]
    fn prefetching_changes_no_hit_and_no_count() {
        // Small trees do not prefetch (`PREFETCH_MIN_BYTES`); forced on, every closest and
        // any-hit answer and every work counter must stay the same, with both node tests.
        let (mut w, _) = wide_of_random(4000, 37, obvhs::BvhBuildParams::medium_build());
        assert!(
            !w.prefetch,
            "a 4000-triangle tree is below the prefetch size"
        );
        let mut s = 43u64;
        let mut hits = 0;
        for isa in Isa::available() {
            w.isa = isa;
            for _ in 0..512 {
                let o = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 8.0 - 4.0;
                let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                let ray = Ray::new(o, (target - o).normalize(), 0.0, 100.0);
                let mut answers = Vec::new();
                for prefetch in [false, true] {
                    w.prefetch = prefetch;
                    let (mut r, mut work) = (ray, RayWork::default());
                    let closest = w.closest(&mut r, &mut work).map(|(p, t)| (p, t.to_bits()));
                    let (mut r, mut any_work) = (ray, RayWork::default());
                    let any = w.any(&mut r, &mut any_work);
                    answers.push((closest, work, any, any_work));
                }
                assert_eq!(answers[0], answers[1]);
                hits += usize::from(answers[0].0.is_some());
            }
        }
        assert!(hits > 500, "{hits} hits: the rays must mostly hit");
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
                if Isa::detect() >= Isa::Avx {
                    // SAFETY: AVX detected above.
                    let avx = unsafe { avx_test(&node, &ray) };
                    assert_eq!(avx.0, expected);
                }
            }
        }
    }

    #[test]
    fn rays_from_the_origin_get_the_same_node_tests() {
        // Camera rays start at the origin of render space and take `AvxAtOrigin`: same
        // masks as obvhs and the same entry distances as `Avx` (as numbers), including
        // axis-aligned directions, whose inverse obvhs clamps to +-1/EPSILON.
        #[cfg(target_arch = "x86_64")]
        if Isa::detect() >= Isa::Avx {
            let tris = random_tris(300, 7);
            let boxes: Vec<_> = tris.iter().map(|t| t.aabb()).collect();
            let mut s = 9u64;
            let mut entered = 0;
            for chunk in boxes.chunks(WIDTH) {
                let mut node = EMPTY_NODE;
                for (lane, b) in chunk.iter().enumerate() {
                    for axis in 0..3 {
                        node.lo[axis][lane] = b.min[axis];
                        node.hi[axis][lane] = b.max[axis];
                    }
                }
                let mut dirs: Vec<Vec3A> = (0..100)
                    .map(|_| {
                        let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                        target.normalize()
                    })
                    .collect();
                dirs.extend([Vec3A::X, Vec3A::NEG_Y, Vec3A::Z, Vec3A::new(-0.0, 0.0, 1.0)]);
                for d in dirs {
                    let ray = Ray::new(Vec3A::ZERO, d, 0.0, 3.0);
                    let mut expected = 0u32;
                    for (lane, b) in chunk.iter().enumerate() {
                        if b.intersect_ray(&ray) < ray.tmax {
                            expected |= 1 << lane;
                        }
                    }
                    // SAFETY: AVX detected above.
                    let (general, at_origin) =
                        unsafe { (avx_test(&node, &ray), avx_at_origin_test(&node, &ray)) };
                    assert_eq!(general.0, expected);
                    assert_eq!(at_origin.0, expected);
                    for lane in 0..WIDTH {
                        let (a, b) = (at_origin.1[lane], general.1[lane]);
                        assert!(a == b || (a.is_nan() && b.is_nan()), "{a} vs {b}");
                    }
                    entered += expected.count_ones();
                }
            }
            assert!(
                entered > 100,
                "{entered} boxes entered: the rays must reach the boxes"
            );
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,popcnt")]
    unsafe fn avx_test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        Avx::test(node, ray)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,popcnt")]
    unsafe fn avx_at_origin_test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        AvxAtOrigin::test(node, ray)
    }
}
