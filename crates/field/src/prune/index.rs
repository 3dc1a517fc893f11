//! The child trees the pruner reads ([`PruneIndex`]): which children of a large composite
//! can matter near a ball, found without reading the others.

use glam::DVec3;
use marchmesh_scene::SmoothOp;

use crate::leaf::Leaf;
use crate::program::{Instr, Op, Program};

/// Composite nodes with at least this many children get a child tree in a [`PruneIndex`]
/// (below it one pass over the children costs about what the tree does).
const INDEX_MIN_CHILDREN: usize = 16;

/// Most children in a leaf of a child tree.
const TREE_LEAF_CHILDREN: usize = 4;

/// What the pruner reads besides the program: which subtrees hold a mesh grid (never
/// pruned), and for every union, subtraction and smooth union with at least
/// 16 children (`INDEX_MIN_CHILDREN`) a binary tree over its children *in their stored order*,
/// each tree node holding the union of its run's bounding boxes.
///
/// A bounded child's value is at least the distance to its box outside it (the bound logic
/// of [`crate::program`]: `g = max(L, ...)`), so a run whose box is farther than some
/// threshold from the ball is skipped without evaluating a child: the pruner then reads
/// only the children near a ball (plus `log n` tree nodes) instead of all of them. Runs
/// keep the fold order of a smooth union, which its pruning rules need; a random walk's
/// consecutive children are near each other, so its runs make tight boxes. Built in one
/// pass over the program ([`PruneIndex::build`]); valid only for that program.
#[derive(Debug, Clone, Default)]
pub struct PruneIndex {
    /// Mesh leaves among nodes `0..i` (so a subtree `[i, end)` holds one when the counts
    /// at `i` and `end` differ); empty means "scan the subtree".
    mesh_before: Vec<u32>,
    pub(super) trees: super::FastMap<u32, ChildTree>,
}

#[derive(Debug, Clone)]
pub(super) struct ChildTree {
    /// Node index of each child, in stored order.
    pub(super) kids: Vec<u32>,
    /// Tree nodes; 0 is the root.
    pub(super) nodes: Vec<TreeNode>,
}

#[derive(Debug, Clone)]
pub(super) struct TreeNode {
    /// Union of the run's boxes (parent frame of the children: the composite's frame).
    pub(super) lo: [f64; 3],
    pub(super) hi: [f64; 3],
    /// Every child of the run is bounded (has a box and no mesh grid).
    pub(super) bounded: bool,
    /// The run: positions `start..end` in `kids`.
    pub(super) start: u32,
    pub(super) end: u32,
    /// The two halves, `None` for a leaf.
    pub(super) sub: Option<[u32; 2]>,
}

impl PruneIndex {
    /// The index of `prog` (one pass over it, plus `O(n log n)` per tree of `n` children).
    pub fn build(prog: &Program<f64>) -> PruneIndex {
        let mut index = PruneIndex::meshes_only(prog);
        for (i, ins) in prog.instrs.iter().enumerate() {
            let indexed = matches!(
                ins.op,
                Op::Union
                    | Op::Subtraction
                    | Op::Smooth {
                        op: SmoothOp::Union | SmoothOp::Blend,
                        ..
                    }
            );
            if !indexed {
                continue;
            }
            let mut kids = Vec::new();
            let mut j = i + 1;
            while j < ins.end as usize {
                kids.push(j as u32);
                j = prog.instrs[j].end as usize;
            }
            if kids.len() < INDEX_MIN_CHILDREN {
                continue;
            }
            let mut tree = ChildTree {
                kids,
                nodes: Vec::new(),
            };
            let n = tree.kids.len() as u32;
            index.grow(prog, &mut tree, 0, n);
            index.trees.insert(i as u32, tree);
        }
        index
    }

    /// Only the mesh counts: the pruner then reads every child (what [`prune`] does).
    pub(super) fn meshes_only(prog: &Program<f64>) -> PruneIndex {
        let mut mesh_before = Vec::with_capacity(prog.instrs.len() + 1);
        let mut n = 0u32;
        mesh_before.push(0);
        for ins in &prog.instrs {
            n += u32::from(matches!(ins.op, Op::Leaf(Leaf::Mesh { .. })));
            mesh_before.push(n);
        }
        PruneIndex {
            mesh_before,
            trees: super::FastMap::default(),
        }
    }

    pub(super) fn has_mesh(&self, prog: &Program<f64>, i: usize) -> bool {
        let end = prog.instrs[i].end as usize;
        match (self.mesh_before.get(i), self.mesh_before.get(end)) {
            (Some(a), Some(b)) => a != b,
            _ => prog.instrs[i..end]
                .iter()
                .any(|n| matches!(n.op, Op::Leaf(Leaf::Mesh { .. }))),
        }
    }

    /// Adds the tree node of run `start..end` (and below it), returning its index.
    fn grow(&self, prog: &Program<f64>, tree: &mut ChildTree, start: u32, end: u32) -> u32 {
        let at = tree.nodes.len() as u32;
        tree.nodes.push(TreeNode {
            lo: [f64::INFINITY; 3],
            hi: [f64::NEG_INFINITY; 3],
            bounded: true,
            start,
            end,
            sub: None,
        });
        let (lo, hi, bounded) = if (end - start) as usize <= TREE_LEAF_CHILDREN {
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            let mut bounded = true;
            for &j in &tree.kids[start as usize..end as usize] {
                let ins = &prog.instrs[j as usize];
                if !box_bounds_value(ins) || self.has_mesh(prog, j as usize) {
                    bounded = false;
                }
                for a in 0..3 {
                    lo[a] = lo[a].min(ins.lo[a]);
                    hi[a] = hi[a].max(ins.hi[a]);
                }
            }
            (lo, hi, bounded)
        } else {
            let mid = start + (end - start) / 2;
            let l = self.grow(prog, tree, start, mid);
            let r = self.grow(prog, tree, mid, end);
            tree.nodes[at as usize].sub = Some([l, r]);
            let (a, b) = (&tree.nodes[l as usize], &tree.nodes[r as usize]);
            (
                std::array::from_fn(|k| a.lo[k].min(b.lo[k])),
                std::array::from_fn(|k| a.hi[k].max(b.hi[k])),
                a.bounded && b.bounded,
            )
        };
        let n = &mut tree.nodes[at as usize];
        n.lo = lo;
        n.hi = hi;
        n.bounded = bounded && lo.iter().chain(&hi).all(|v| !v.is_nan());
        at
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> u64 {
        let trees: usize = self
            .trees
            .values()
            .map(|t| t.kids.len() * 4 + t.nodes.len() * std::mem::size_of::<TreeNode>())
            .sum();
        (self.mesh_before.len() * 4 + trees) as u64
    }
}

/// Whether node `ins`'s value (as its parent reads it) is at least the distance to its box
/// outside the box: a bounded node's is (the bound logic takes `max(L, ...)`), and so is an
/// unbounded sphere's or box's under a rigid or uniformly scaled frame (an exact distance
/// to a solid inside the box; a non-uniform scale makes it a smaller bound).
fn box_bounds_value(ins: &Instr<f64>) -> bool {
    if ins.has_bound {
        return true;
    }
    let exact_leaf = matches!(
        ins.op,
        Op::Leaf(Leaf::Sphere { .. } | Leaf::SphereAt { .. } | Leaf::Box { .. })
    );
    exact_leaf
        && ins.to_local.lin.is_none_or(|m| {
            // A similarity: orthogonal rows of equal length.
            let row = |i: usize| DVec3::new(m[3 * i], m[3 * i + 1], m[3 * i + 2]);
            let (a, b, c) = (row(0), row(1), row(2));
            let n = a.length_squared();
            let tol = 1e-12 * n;
            (b.length_squared() - n).abs() <= tol
                && (c.length_squared() - n).abs() <= tol
                && a.dot(b).abs() <= tol
                && a.dot(c).abs() <= tol
                && b.dot(c).abs() <= tol
        })
}
