//! The wide BVH's memory layout: 8-wide nodes (child boxes as structure of arrays and child
//! references), blocks of 4 triangles, and the [`WideBvh`] holding both with the slots
//! behind each hit reference.

use obvhs::rt_triangle::RtTriangle;

use super::huge::HugeBuf;
use super::isa::Isa;

/// Children per node.
pub(crate) const WIDTH: usize = 8;
/// Triangles per block.
pub(crate) const BLOCK: usize = 4;
/// An empty child lane (also marks padding lanes of a triangle block).
pub(crate) const EMPTY: u32 = u32::MAX;
/// Child reference flag: the low 24 bits are the first block, bits 24..31 the block count.
pub(crate) const LEAF: u32 = 1 << 31;
pub(crate) const LEAF_FIRST_BITS: u32 = 24;
pub(super) const LEAF_MAX_BLOCKS: u32 = 127;
/// Traversal stack entries held on the call stack. Each node pushes at most `WIDTH - 1`
/// entries, so trees deeper than `(STACK - 1) / (WIDTH - 1)` nodes are not converted.
pub(crate) const STACK: usize = 512;
pub(super) const MAX_DEPTH: u32 = ((STACK - 1) / (WIDTH - 1)) as u32;

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

pub(super) const EMPTY_NODE: WideNode = WideNode {
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

pub(super) const EMPTY_BLOCK: TriBlock = TriBlock {
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
    /// of at least [`PREFETCH_MIN_BYTES`](super::traverse::PREFETCH_MIN_BYTES), whose nodes
    /// come from memory rather than cache.
    pub(crate) prefetch: bool,
}

impl WideBvh {
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
}

/// `(index of the first block, block count)` of leaf child `c` (`c & LEAF != 0`).
#[inline(always)]
pub(crate) fn leaf_range(c: u32) -> (usize, usize) {
    (
        (c & ((1 << LEAF_FIRST_BITS) - 1)) as usize,
        ((c & !LEAF) >> LEAF_FIRST_BITS) as usize,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wide::test_util::wide_of_random;

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
}
