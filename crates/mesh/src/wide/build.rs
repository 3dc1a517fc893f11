//! Conversion of an obvhs Bvh2 into the wide layout: the SAH-optimal collapse into 8-wide
//! nodes and the builder that packs leaves into triangle blocks.

use obvhs::{bvh2::Bvh2, rt_triangle::RtTriangle};

use super::huge::HugeBuf;
use super::isa::Isa;
use super::layout::{
    BLOCK, EMPTY, EMPTY_BLOCK, EMPTY_NODE, LEAF, LEAF_FIRST_BITS, LEAF_MAX_BLOCKS, MAX_DEPTH,
    TriBlock, WIDTH, WideBvh, WideNode,
};
use super::traverse::PREFETCH_MIN_BYTES;

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
pub(super) struct Collapse {
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

/// The wide BVH under construction, in growable arrays.
#[derive(Default)]
pub(super) struct Builder {
    pub(super) nodes: Vec<WideNode>,
    pub(super) blocks: Vec<TriBlock>,
    pub(super) slots: Vec<[u32; BLOCK]>,
}

impl Builder {
    /// Appends the blocks of a leaf holding the triangle slots `slots`; its reference.
    pub(super) fn leaf(&mut self, slots: &[u32], tris: &[RtTriangle]) -> Option<u32> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wide::test_util::wide_of_random;

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
}
