//! The program pruned per region of space: hierarchical Lipschitz pruning (Barbier, Sanchez
//! et al. 2025, "Lipschitz Pruning: Hierarchical Simplification of Primitive-Based SDFs"), on
//! the flat program of [`crate::program`].
//!
//! Every node's value is 1-Lipschitz (see the crate docs; subtrees holding a baked mesh grid
//! are the exception and are never pruned nor used to prune), so over a ball of radius `r`
//! around `c` a node's value lies in `[v(c) - r, v(c) + r]`. With these intervals a node
//! keeps only the children that can change its value inside the ball, and the result equals
//! the whole program's value there bit for bit (dropped children are exact no-ops):
//! - union (`min`): a child whose lower bound exceeds another child's upper bound is never
//!   the minimum;
//! - intersection (`max`): a child whose upper bound is below another's lower bound is never
//!   the maximum;
//! - subtraction: a subtracted child whose lower bound exceeds minus the first child's lower
//!   bound never cuts into it;
//! - smooth union, a left-to-right fold `f_j = smin(f_{j-1}, a_j)`: with the prefix interval
//!   `P` (folded by interval arithmetic: the polynomial `smin` is non-decreasing in both
//!   arguments), a child with `a_j >= P.hi + k` leaves the fold unchanged (the kernel's `h` is
//!   exactly 0) and is dropped; a child with `a_j <= P.lo - k` replaces the fold exactly
//!   (`smin = a_j`), so every child before it is dropped. This is the paper's rule for
//!   binary smooth nodes (children differing by more than `k` across the cell collapse to
//!   the nearer one) applied along the fold, which is what keeps the fold order;
//! - blend (`program::blend`, order-free): a child whose lower bound is at least the least
//!   upper bound plus `k` adds an exact `+0` and is dropped, wherever it stands.
//!
//! Intervals carry a slack for f32 rounding, so the f32 program pruned from the f64 one
//! drops only children that are exact no-ops in f32 as well.
//!
//! [`Cells`] applies this over an octree of the field's box: each cell restricts the whole
//! program to itself (fidget prunes its tapes per image region the same way with interval
//! arithmetic, Keeter 2020), reading the children of large composites through a
//! [`PruneIndex`] so that a cell's cost follows the children near it rather than their
//! count, and a cell where the whole field is provably positive by a margin holds no program
//! at all but answers a safe bound.

use glam::DVec3;

use crate::lane::V3;
use marchmesh_scene::SmoothOp;

use crate::program::{Affine, GridSampler, Instr, Op, Program};
use crate::shapes;

mod cells;
mod index;

/// A hash map with a cheap multiplicative hasher (rustc's "Fx"): the pruner's maps are keyed
/// by node indices and index lists, hashed millions of times in a build, where the
/// standard hasher's DoS resistance buys nothing.
type FastMap<K, V> = std::collections::HashMap<K, V, std::hash::BuildHasherDefault<FxHasher>>;

/// The hasher of [`FastMap`].
#[derive(Default, Clone, Copy)]
struct FxHasher(u64);

impl std::hash::Hasher for FxHasher {
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            let mut w = [0u8; 8];
            w.copy_from_slice(c);
            self.write_u64(u64::from_le_bytes(w));
        }
        for &b in chunks.remainder() {
            self.write_u64(u64::from(b));
        }
    }

    #[inline]
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }

    #[inline]
    fn write_u32(&mut self, v: u32) {
        self.write_u64(u64::from(v));
    }

    #[inline]
    fn write_usize(&mut self, v: usize) {
        self.write_u64(v as u64);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

pub use cells::{Cell, CellStats, Cells};
pub use index::PruneIndex;
use index::{ChildTree, TreeNode};

/// Deepest composite nesting the pruner descends into; deeper subtrees are kept whole (so a
/// deep tree costs bounded recursion and time per cell).
const MAX_PRUNE_DEPTH: usize = 24;

/// Relative slack of every interval (f32 rounding of the values and of the coordinates).
const SLACK_REL: f64 = 2e-5;

/// Rounds of the fold walk that read the unread runs its kept fold would start before,
/// before every run is read.
const OPEN_ROUNDS: usize = 3;

/// A program restricted to a ball, and the interval of its value there.
#[derive(Debug, Clone, PartialEq)]
pub struct Pruned {
    /// The restricted program: within the `max_error` given to [`prune`] of the whole
    /// program at every point of the ball (equal to it for `0`).
    pub program: Program<f64>,
    /// Lower bound of the whole program's value over the ball (`-inf` when unknown).
    pub lo: f64,
    /// Upper bound of the whole program's value over the ball (`+inf` when unknown).
    pub hi: f64,
    /// Index in the whole program of each node of [`Pruned::program`]: equal lists mean
    /// equal programs (cells share them).
    pub source: Vec<u32>,
    /// Work of the restriction: child intervals evaluated plus child-tree nodes visited.
    pub work: usize,
}

/// `prog` restricted to the ball of radius `radius` around `centre` (in the frame the program
/// is evaluated in), within `max_error` inside the ball: `0` keeps the whole program's value
/// bit for bit, a positive `max_error` lets smooth unions drop the start of their fold where
/// it changes the value by less than that (see `FoldChain::cut_start`). Reads every child
/// of every node it keeps; [`prune_indexed`] reads only the children near the ball. Never
/// fails (an empty program stays empty).
pub fn prune(
    prog: &Program<f64>,
    grids: &[Box<dyn GridSampler>],
    centre: DVec3,
    radius: f64,
    max_error: f64,
) -> Pruned {
    prune_indexed(
        prog,
        &PruneIndex::meshes_only(prog),
        grids,
        centre,
        radius,
        max_error,
    )
}

/// [`prune`] reading the children of large composites through `index` (built by
/// [`PruneIndex::build`] from `prog`): the same rules, applied to the children a child tree
/// cannot rule out, so its cost follows the children near the ball rather than their
/// count. The result may keep a few more nodes than [`prune`]'s (a run skipped at the start
/// of a smooth fold is bounded more loosely than its children would be), never fewer
/// than its rules need: values are as [`prune`] states.
pub fn prune_indexed(
    prog: &Program<f64>,
    index: &PruneIndex,
    grids: &[Box<dyn GridSampler>],
    centre: DVec3,
    radius: f64,
    max_error: f64,
) -> Pruned {
    if prog.instrs.is_empty() {
        return Pruned {
            program: Program::default(),
            lo: f64::INFINITY,
            hi: f64::INFINITY,
            source: Vec::new(),
            work: 0,
        };
    }
    // Errors of nested cuts add along a path of at most MAX_PRUNE_DEPTH + 1 nodes.
    let (cut_error, max_error) = if max_error.is_finite() && max_error > 0.0 {
        (max_error / (MAX_PRUNE_DEPTH + 1) as f64, max_error)
    } else {
        (0.0, 0.0)
    };
    let mut p = Pruner::new(prog, index, grids, (cut_error, max_error));
    let c = V3::new(centre.x, centre.y, centre.z);
    // The root's interval from the restricted program (within `max_error` of the whole's,
    // bit for bit at 0), so a large program is not evaluated whole.
    p.emit(0, c, radius, 0);
    let program = Program { instrs: p.out };
    let (lo, hi) = if index.has_mesh(prog, 0) {
        (f64::NEG_INFINITY, f64::INFINITY)
    } else {
        bracket(program.node_value(0, c, grids), c, radius, max_error)
    };
    Pruned {
        program,
        lo,
        hi,
        source: p.source,
        work: p.work,
    }
}

/// The children a restricted program keeps when it is `prog`'s root, a smooth union or a
/// blend, with some of its children each copied whole (`source`: the restricted nodes'
/// indices in `prog`), else `None`.
fn root_subset(prog: &Program<f64>, source: &[u32]) -> Option<Box<[u32]>> {
    if source.len() < 2 || source[0] != 0 || !prog.root_is_smooth_union_or_blend() {
        return None;
    }
    let root_end = prog.instrs[0].end;
    let mut kids = Vec::new();
    let mut at = 1;
    while at < source.len() {
        let j = source[at];
        let end = prog.instrs.get(j as usize)?.end;
        let len = (end - j) as usize;
        if j == 0 || end > root_end || !source.get(at..at + len)?.iter().copied().eq(j..end) {
            return None;
        }
        kids.push(j);
        at += len;
    }
    Some(kids.into_boxed_slice())
}

/// What the child tree of `prog`'s root (an indexed union or smooth union) says of the ball
/// without restricting the program to it, for an octree cell: a lower bound of the whole
/// program's value over the ball (from the children's boxes: `-inf` when unknown), whether
/// restricting would plainly keep more than `cap` children (the ball meets a child's box
/// and more than `cap` boxes come near), and the work spent. `None` when the root has no
/// child tree.
fn survey_root(
    prog: &Program<f64>,
    index: &PruneIndex,
    grids: &[Box<dyn GridSampler>],
    centre: DVec3,
    radius: f64,
    cap: usize,
) -> Option<(f64, bool, usize)> {
    let root = prog.instrs.first()?;
    let tree = index.trees.get(&0)?;
    let slack = match root.op {
        Op::Union => 0.0,
        Op::Smooth {
            op: SmoothOp::Union | SmoothOp::Blend,
            k,
            ..
        } => k,
        _ => return None,
    };
    let mut p = Pruner::new(prog, index, grids, (0.0, 0.0));
    let c = V3::new(centre.x, centre.y, centre.z);
    let q = root.to_local.apply(c);
    let rq = radius * stretch(&root.to_local);
    // Every child is at least the nearest run's box bound; a fold of values lies less than
    // `k` below their minimum (`marchmesh_scene::bounds::smooth_fold_deficit`).
    let nearest = p.least_lower(tree, q, rq);
    let mut lower = root.dscale * (nearest - slack);
    if root.has_bound {
        // The parent reads `max(L, min(c, tau))` (`min(c, tau)` inside the box).
        lower = lower.min(root.tau);
        let d = shapes::box_distance(c, V3::splat3(root.lo), V3::splat3(root.hi)) - radius;
        if d > 0.0 {
            lower = lower.max(d);
        }
    }
    if !lower.is_finite() {
        lower = f64::NEG_INFINITY;
    }
    let scale = c.x.abs().max(c.y.abs()).max(c.z.abs()) + radius;
    lower -= SLACK_REL * (1.0 + lower.abs().min(1e300) + scale);
    // Only a cell that meets a child's box may be crowded: one that does not could be far,
    // which restricting it finds exactly.
    let crowded = nearest == f64::NEG_INFINITY && p.crowded(tree, q, rq, slack + 2.0 * rq, cap);
    Some((lower, crowded, p.work))
}

/// The interval `v +- (r + slack + err)` of a 1-Lipschitz value `v` at the centre `q` of a
/// ball of radius `r` (unknown when `v` is not finite).
fn bracket(v: f64, q: V3<f64>, r: f64, err: f64) -> (f64, f64) {
    if !v.is_finite() {
        return (f64::NEG_INFINITY, f64::INFINITY);
    }
    let scale = q.x.abs().max(q.y.abs()).max(q.z.abs()) + r;
    let slack = SLACK_REL * (1.0 + v.abs() + scale) + err;
    (v - r - slack, v + r + slack)
}

struct Pruner<'a> {
    prog: &'a Program<f64>,
    index: &'a PruneIndex,
    grids: &'a [Box<dyn GridSampler>],
    out: Vec<Instr<f64>>,
    /// Index in `prog` of each node of `out`.
    source: Vec<u32>,
    /// Largest change of one smooth union's value its prefix cut may make (0: exact).
    cut_error: f64,
    /// Largest change of any node's value by the restriction (0: exact).
    max_error: f64,
    /// Child intervals evaluated and tree nodes visited.
    work: usize,
    /// Indexed composites already restricted to find their interval (node, its restricted
    /// nodes with `end` relative to 0, their sources), emitted from here when kept.
    scratch: FastMap<usize, (Vec<Instr<f64>>, Vec<u32>)>,
    /// Intervals already read (a node is read under one ball per restriction).
    known: FastMap<usize, (f64, f64)>,
}

/// An upper bound of the stretch of `a`'s linear part (its Frobenius norm; 1 for none).
fn stretch(a: &Affine<f64>) -> f64 {
    a.lin
        .map_or(1.0, |m| m.iter().map(|v| v * v).sum::<f64>().sqrt())
}

/// One step of a smooth union's fold as the pruner keeps it: a child (`node` its index in
/// the program) or a skipped run of a child tree (`run` its tree node), with its value's
/// interval and the prefix's interval before it.
#[derive(Debug, Clone, Copy)]
struct Link {
    node: usize,
    run: Option<u32>,
    hi: f64,
    plo: f64,
}

/// The kept steps of a smooth union's fold `f_j = smin(f_{j-1}, a_j)`, built child by child
/// (and run by run) in fold order.
///
/// Exact rules: a child with `a_j >= P.hi + k` (`P` the prefix's interval, folded by
/// interval arithmetic: `smin` is non-decreasing in both arguments) leaves the fold
/// unchanged and is dropped; a child with `a_j <= P.lo - k` replaces it (`smin = a_j`), so
/// every step before it is dropped. A run of children each at least `lb` is folded as
/// `P -> [min(P.lo, lb) - k, P.hi]`: a fold of any values lies less than `k` below their
/// minimum (`marchmesh_scene::bounds::smooth_fold_deficit`) and `smin` never exceeds its
/// first argument.
struct FoldChain {
    k: f64,
    inv_k: f64,
    links: Vec<Link>,
    fold: Option<(f64, f64)>,
}

impl FoldChain {
    fn new(k: f64, inv_k: f64) -> FoldChain {
        FoldChain {
            k,
            inv_k,
            links: Vec::new(),
            fold: None,
        }
    }

    /// Whether every child whose value is at least `lo` is a no-op here.
    fn skips(&self, lo: f64) -> bool {
        self.fold.is_some_and(|(_, phi)| lo >= phi + self.k)
    }

    fn child(&mut self, node: usize, lo: f64, hi: f64) {
        let (k, inv_k) = (self.k, self.inv_k);
        match self.fold {
            None => {
                self.links.push(Link {
                    node,
                    run: None,
                    hi,
                    plo: f64::INFINITY,
                });
                self.fold = Some((lo, hi));
            }
            Some((plo, phi)) => {
                if lo >= phi + k {
                    // smin(f, a_j) = f exactly: a no-op.
                    return;
                }
                if plo >= hi + k {
                    // smin(f, a_j) = a_j exactly: the prefix no longer matters.
                    self.links.clear();
                    self.links.push(Link {
                        node,
                        run: None,
                        hi,
                        plo: f64::INFINITY,
                    });
                    self.fold = Some((lo, hi));
                    return;
                }
                self.links.push(Link {
                    node,
                    run: None,
                    hi,
                    plo,
                });
                self.fold = Some((
                    shapes::smin(plo, lo, k, inv_k),
                    shapes::smin(phi, hi, k, inv_k),
                ));
            }
        }
    }

    /// A run of children each at least `lb` over the ball, not read.
    fn run(&mut self, run: u32, lb: f64) {
        let (plo, phi) = self.fold.unwrap_or((f64::INFINITY, f64::INFINITY));
        self.links.push(Link {
            node: 0,
            run: Some(run),
            hi: f64::INFINITY,
            plo,
        });
        self.fold = Some((plo.min(lb) - self.k, phi));
    }

    /// Where the kept fold may start within `cut_error` (0: exact).
    ///
    /// Starting the fold at child `c` instead (dropping the steps before it) changes `f_c`
    /// by at most `k h^2 / 4` where the child lies below the prefix over the whole ball
    /// (`h = max(k - (P.lo - a.hi), 0) / k`), and a change of the prefix reaches the result
    /// through `d smin(x, a) / dx`, which is `h / 2 <= 1/2` where the child is below `x` and
    /// at most 1 anywhere (so later steps never amplify it, and a dropped no-op child
    /// passes it unchanged). The latest `c` whose change, times the product of the later
    /// steps' derivative bounds, is within the budget is taken: in an approach chain (each
    /// child nearer than the running blend) the prefix's influence halves at least with
    /// every step, so a few dozen children remain instead of the whole chain. A run is
    /// never a start (its children are not known).
    fn cut_start(&self, cut_error: f64) -> usize {
        let (k, inv_k) = (self.k, self.inv_k);
        if cut_error > 0.0 && self.links.len() > 1 {
            // `after`: the product of the derivative bounds of the steps after `c`.
            let mut after = 1.0f64;
            for c in (1..self.links.len()).rev() {
                let Link { hi, plo, run, .. } = self.links[c];
                let below = run.is_none() && plo >= hi;
                let h = ((k - (plo - hi)) * inv_k).clamp(0.0, 1.0);
                if below && 0.25 * k * h * h * after <= cut_error {
                    return c;
                }
                after *= if below { 0.5 * h } else { 1.0 };
            }
        }
        0
    }
}

impl<'a> Pruner<'a> {
    /// A pruner of `prog` with `(cut_error, max_error)` (see the fields).
    fn new(
        prog: &'a Program<f64>,
        index: &'a PruneIndex,
        grids: &'a [Box<dyn GridSampler>],
        (cut_error, max_error): (f64, f64),
    ) -> Pruner<'a> {
        Pruner {
            prog,
            index,
            grids,
            out: Vec::new(),
            source: Vec::new(),
            cut_error,
            max_error,
            work: 0,
            scratch: FastMap::default(),
            known: FastMap::default(),
        }
    }
    fn end(&self, i: usize) -> usize {
        self.prog.instrs[i].end as usize
    }

    fn has_mesh(&self, i: usize) -> bool {
        self.index.has_mesh(self.prog, i)
    }

    /// Node `i`'s value over the ball `(q, r)` in its parent's frame. An indexed composite
    /// is restricted to the ball first (kept for [`Pruner::emit`]) and its restriction
    /// evaluated, so a large subtree is not evaluated whole.
    fn interval(&mut self, i: usize, q: V3<f64>, r: f64, depth: usize) -> (f64, f64) {
        if let Some(&known) = self.known.get(&i) {
            return known;
        }
        let v = self.interval_uncached(i, q, r, depth);
        self.known.insert(i, v);
        v
    }

    fn interval_uncached(&mut self, i: usize, q: V3<f64>, r: f64, depth: usize) -> (f64, f64) {
        self.work += 1;
        if self.has_mesh(i) {
            return (f64::NEG_INFINITY, f64::INFINITY);
        }
        if depth < MAX_PRUNE_DEPTH && self.index.trees.contains_key(&(i as u32)) {
            let base = self.out.len();
            self.emit(i, q, r, depth);
            let mut instrs: Vec<Instr<f64>> = self.out.drain(base..).collect();
            let source: Vec<u32> = self.source.drain(base..).collect();
            for n in &mut instrs {
                n.end -= base as u32;
            }
            let sub = Program { instrs };
            let v = sub.node_value(0, q, self.grids);
            self.scratch.insert(i, (sub.instrs, source));
            return bracket(v, q, r, self.max_error);
        }
        bracket(self.prog.node_value(i, q, self.grids), q, r, 0.0)
    }

    /// Copies node `i`'s whole subtree.
    fn copy(&mut self, i: usize) {
        let end = self.end(i);
        let base = self.out.len();
        for n in &self.prog.instrs[i..end] {
            let mut n = n.clone();
            n.end = (n.end as usize - i + base) as u32;
            self.out.push(n);
        }
        self.source.extend(i as u32..end as u32);
    }

    /// Lower bound of every child of `run` over the ball `(q, r)` (the composite's frame),
    /// from the run's box: `-inf` when a child is unbounded or the ball meets the box.
    fn run_lower(&mut self, run: &TreeNode, q: V3<f64>, r: f64) -> f64 {
        self.work += 1;
        if !run.bounded {
            return f64::NEG_INFINITY;
        }
        let d = shapes::box_distance(q, V3::splat3(run.lo), V3::splat3(run.hi));
        let scale = q.x.abs().max(q.y.abs()).max(q.z.abs()) + r;
        let lb = d - r - SLACK_REL * (1.0 + d + scale);
        if lb > 0.0 { lb } else { f64::NEG_INFINITY }
    }

    /// The least upper bound over the ball of any child of `tree`, reading only the runs
    /// that could hold a smaller one (nearer run first).
    fn least_upper(
        &mut self,
        tree: &ChildTree,
        at: u32,
        q: V3<f64>,
        r: f64,
        depth: usize,
        best: &mut f64,
    ) {
        let run = &tree.nodes[at as usize];
        if self.run_lower(run, q, r) >= *best {
            return;
        }
        match run.sub {
            None => {
                for &j in &tree.kids[run.start as usize..run.end as usize] {
                    let (_, hi) = self.interval(j as usize, q, r, depth);
                    *best = best.min(hi);
                }
            }
            Some([a, b]) => {
                let la = self.run_lower(&tree.nodes[a as usize], q, r);
                let lb = self.run_lower(&tree.nodes[b as usize], q, r);
                let order = if lb < la { [b, a] } else { [a, b] };
                for s in order {
                    self.least_upper(tree, s, q, r, depth, best);
                }
            }
        }
    }

    /// The children of `tree` (positions `from..`) whose lower bound is at most `thr`, with
    /// their intervals, in stored order.
    #[allow(clippy::too_many_arguments)]
    fn children_below(
        &mut self,
        tree: &ChildTree,
        at: u32,
        from: u32,
        q: V3<f64>,
        r: f64,
        depth: usize,
        thr: f64,
        out: &mut Vec<(usize, f64, f64)>,
    ) {
        let run = &tree.nodes[at as usize];
        if run.end <= from || self.run_lower(run, q, r) > thr {
            return;
        }
        match run.sub {
            None => {
                for &j in &tree.kids[run.start.max(from) as usize..run.end as usize] {
                    let (lo, hi) = self.interval(j as usize, q, r, depth);
                    if lo <= thr {
                        out.push((j as usize, lo, hi));
                    }
                }
            }
            Some([a, b]) => {
                self.children_below(tree, a, from, q, r, depth, thr, out);
                self.children_below(tree, b, from, q, r, depth, thr, out);
            }
        }
    }

    /// The least box lower bound over the ball of any run of `tree` down to its leaves
    /// (`-inf` when a run is unbounded or the ball meets a leaf run's box).
    fn least_lower(&mut self, tree: &ChildTree, q: V3<f64>, r: f64) -> f64 {
        // Best first: a heap of runs by their bound.
        let mut heap = std::collections::BinaryHeap::new();
        let key =
            |v: f64| std::cmp::Reverse(v.to_bits() ^ if v < 0.0 { u64::MAX } else { 1 << 63 });
        let root = self.run_lower(&tree.nodes[0], q, r);
        heap.push((key(root), root.to_bits(), 0u32));
        while let Some((_, bits, at)) = heap.pop() {
            let lb = f64::from_bits(bits);
            match tree.nodes[at as usize].sub {
                None => return lb,
                Some(sub) => {
                    for s in sub {
                        let l = self.run_lower(&tree.nodes[s as usize], q, r);
                        heap.push((key(l), l.to_bits(), s));
                    }
                }
            }
        }
        f64::NEG_INFINITY
    }

    /// Whether more than `cap` children of `tree` have a box lower bound below the least
    /// child upper bound plus `slack` over the ball (reading at most about `cap` children
    /// past the nearest).
    fn crowded(&mut self, tree: &ChildTree, q: V3<f64>, r: f64, slack: f64, cap: usize) -> bool {
        // Children whose boxes the ball meets first: a large cell is crowded by them alone,
        // found without evaluating a child.
        if self.count_below(tree, q, r, f64::NEG_INFINITY, cap) > cap {
            return true;
        }
        let mut least = f64::INFINITY;
        self.least_upper(tree, 0, q, r, 1, &mut least);
        self.count_below(tree, q, r, least + slack, cap) > cap
    }

    /// How many children of `tree` lie in runs whose box lower bound is at most `thr`
    /// (counted up to just past `cap`).
    fn count_below(&mut self, tree: &ChildTree, q: V3<f64>, r: f64, thr: f64, cap: usize) -> usize {
        let mut count = 0usize;
        let mut stack = vec![0u32];
        while let Some(at) = stack.pop() {
            let run = &tree.nodes[at as usize];
            if self.run_lower(run, q, r) > thr {
                continue;
            }
            match run.sub {
                None => {
                    count += (run.end - run.start) as usize;
                    if count > cap {
                        return count;
                    }
                }
                Some([a, b]) => stack.extend([a, b]),
            }
        }
        count
    }

    /// Walks `tree` in fold order into `chain`: runs the fold proves no-ops are skipped,
    /// runs at least `far` away are folded unread unless `open` says to read them whole (an
    /// empty `open`: everything below is read).
    #[allow(clippy::too_many_arguments)]
    fn fold_walk(
        &mut self,
        tree: &ChildTree,
        at: u32,
        q: V3<f64>,
        r: f64,
        depth: usize,
        far: f64,
        open: &[bool],
        chain: &mut FoldChain,
    ) {
        let run = &tree.nodes[at as usize];
        let lb = self.run_lower(run, q, r);
        if chain.skips(lb) {
            return;
        }
        // An empty `open` below a run read whole.
        let whole = open.get(at as usize).copied().unwrap_or(true);
        if !whole && lb >= far {
            chain.run(at, lb);
            return;
        }
        match run.sub {
            None => {
                for &j in &tree.kids[run.start as usize..run.end as usize] {
                    let j = j as usize;
                    let (lo, hi) = self.interval(j, q, r, depth);
                    chain.child(j, lo, hi);
                }
            }
            Some([a, b]) => {
                let below = if whole { &[][..] } else { open };
                self.fold_walk(tree, a, q, r, depth, far, below, chain);
                self.fold_walk(tree, b, q, r, depth, far, below, chain);
            }
        }
    }

    /// The children of the indexed smooth union `tree` to keep over the ball: the fold walk
    /// with runs farther than the nearest child's upper bound plus `4k + 2r` left unread,
    /// repeated while the kept fold would start before an unread run, which is then read
    /// whole (a level at a time costs more rounds than it saves on sculpted molecules).
    /// Child intervals are read once (kept across rounds).
    #[allow(clippy::too_many_arguments)]
    fn smooth_union_keep_indexed(
        &mut self,
        tree: &ChildTree,
        q: V3<f64>,
        r: f64,
        depth: usize,
        k: f64,
        inv_k: f64,
    ) -> Vec<usize> {
        let mut nearest = f64::INFINITY;
        self.least_upper(tree, 0, q, r, depth, &mut nearest);
        let far = nearest + 4.0 * k + 2.0 * r;
        let mut open = vec![false; tree.nodes.len()];
        for round in 0..=OPEN_ROUNDS {
            if round == OPEN_ROUNDS {
                open.fill(true);
            }
            let mut chain = FoldChain::new(k, inv_k);
            self.fold_walk(tree, 0, q, r, depth, far, &open, &mut chain);
            let kept = &chain.links[chain.cut_start(self.cut_error)..];
            let mut unread = false;
            for l in kept {
                if let Some(run) = l.run {
                    open[run as usize] = true;
                    unread = true;
                }
            }
            if !unread {
                return kept.iter().map(|l| l.node).collect();
            }
        }
        unreachable!("the round with every run open reads every child")
    }

    /// The children of node `i` (composite, `ins`) to keep over the ball `(q, rq)` in its
    /// frame: through its child tree when it has one, else from every child's interval.
    fn keep(&mut self, i: usize, q: V3<f64>, rq: f64, depth: usize) -> Vec<usize> {
        let index = self.index;
        let prog = self.prog;
        let ins = &prog.instrs[i];
        if let Some(tree) = index.trees.get(&(i as u32)) {
            match &ins.op {
                Op::Union => {
                    let mut least = f64::INFINITY;
                    self.least_upper(tree, 0, q, rq, depth, &mut least);
                    let mut kids = Vec::new();
                    self.children_below(tree, 0, 0, q, rq, depth, least, &mut kids);
                    return kids.into_iter().map(|c| c.0).collect();
                }
                Op::Subtraction => {
                    let first = tree.kids[0] as usize;
                    let (first_lo, _) = self.interval(first, q, rq, depth);
                    let mut kids = Vec::new();
                    self.children_below(tree, 0, 1, q, rq, depth, -first_lo, &mut kids);
                    return std::iter::once(first)
                        .chain(kids.into_iter().map(|c| c.0))
                        .collect();
                }
                Op::Smooth {
                    op: SmoothOp::Union,
                    k,
                    inv_k,
                } => return self.smooth_union_keep_indexed(tree, q, rq, depth, *k, *inv_k),
                Op::Smooth {
                    op: SmoothOp::Blend,
                    k,
                    ..
                } => {
                    let mut least = f64::INFINITY;
                    self.least_upper(tree, 0, q, rq, depth, &mut least);
                    let mut kids = Vec::new();
                    self.children_below(tree, 0, 0, q, rq, depth, least + k, &mut kids);
                    // The blend's sums add in stored order (`program::blend`).
                    let mut kids: Vec<usize> = kids.into_iter().map(|c| c.0).collect();
                    kids.sort_unstable();
                    return kids;
                }
                _ => {}
            }
        }
        let end = ins.end as usize;
        let mut kids = Vec::new();
        let mut j = i + 1;
        while j < end {
            let (lo, hi) = self.interval(j, q, rq, depth);
            kids.push((j, lo, hi));
            j = self.end(j);
        }
        match &ins.op {
            Op::Union => {
                let min_hi = kids.iter().map(|k| k.2).fold(f64::INFINITY, f64::min);
                kids.iter().filter(|k| k.1 <= min_hi).map(|k| k.0).collect()
            }
            Op::Intersection => {
                let max_lo = kids.iter().map(|k| k.1).fold(f64::NEG_INFINITY, f64::max);
                kids.iter().filter(|k| k.2 >= max_lo).map(|k| k.0).collect()
            }
            Op::Subtraction => {
                let first_lo = kids[0].1;
                std::iter::once(kids[0].0)
                    .chain(kids[1..].iter().filter(|k| k.1 <= -first_lo).map(|k| k.0))
                    .collect()
            }
            Op::Smooth {
                op: SmoothOp::Union,
                k,
                inv_k,
            } => {
                let mut chain = FoldChain::new(*k, *inv_k);
                for &(j, lo, hi) in &kids {
                    chain.child(j, lo, hi);
                }
                chain.links[chain.cut_start(self.cut_error)..]
                    .iter()
                    .map(|l| l.node)
                    .collect()
            }
            // A blend: a child at least `k` above the least upper bound is at least `k` above
            // the blend everywhere in the ball and adds an exact `+0` (`program::blend`).
            Op::Smooth {
                op: SmoothOp::Blend,
                k,
                ..
            } => {
                let min_hi = kids.iter().map(|k| k.2).fold(f64::INFINITY, f64::min);
                kids.iter()
                    .filter(|c| c.1 < min_hi + k)
                    .map(|c| c.0)
                    .collect()
            }
            // A smooth maximum fold `f_j = smax(f_{j-1}, b_j)` (`b_j` the child, negated for a
            // subtraction): a child at least `k` below the prefix's lower bound leaves it
            // unchanged (`h` is exactly 0) and is dropped; nothing else is (the prefix interval
            // is folded by interval arithmetic: `smax` is non-decreasing in both arguments).
            Op::Smooth {
                op: op @ (SmoothOp::Intersection | SmoothOp::Subtraction),
                k,
                inv_k,
            } => {
                let (k, inv_k) = (*k, *inv_k);
                let subtract = matches!(op, SmoothOp::Subtraction);
                let mut kept = vec![kids[0].0];
                let (mut plo, mut phi) = (kids[0].1, kids[0].2);
                for &(j, lo, hi) in &kids[1..] {
                    let (blo, bhi) = if subtract { (-hi, -lo) } else { (lo, hi) };
                    if bhi <= plo - k {
                        continue;
                    }
                    kept.push(j);
                    plo = shapes::smax(plo, blo, k, inv_k);
                    phi = shapes::smax(phi, bhi, k, inv_k);
                }
                kept
            }
            _ => unreachable!("keep is called on composites"),
        }
    }

    /// Emits node `i` (kept) restricted to the ball `(c, r)` in its parent's frame.
    fn emit(&mut self, i: usize, c: V3<f64>, r: f64, depth: usize) {
        if !self.scratch.is_empty()
            && let Some((instrs, source)) = self.scratch.remove(&i)
        {
            let base = self.out.len() as u32;
            self.out.extend(instrs.into_iter().map(|mut n| {
                n.end += base;
                n
            }));
            self.source.extend(source);
            return;
        }
        let ins = &self.prog.instrs[i];
        let composite = matches!(
            ins.op,
            Op::Union | Op::Intersection | Op::Subtraction | Op::Smooth { .. }
        );
        if !composite || depth >= MAX_PRUNE_DEPTH || self.has_mesh(i) {
            self.copy(i);
            return;
        }
        let q = ins.to_local.apply(c);
        let rq = r * stretch(&ins.to_local);
        let end = ins.end as usize;
        if end == i + 1 {
            self.copy(i);
            return;
        }
        let keep = self.keep(i, q, rq, depth + 1);
        let start = self.out.len();
        self.out.push(self.prog.instrs[i].clone());
        self.source.push(i as u32);
        for j in keep {
            self.emit(j, q, rq, depth + 1);
        }
        self.out[start].end = self.out.len() as u32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stretch_bounds_the_largest_singular_value() {
        let a = Affine {
            lin: Some([2.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0]),
            trans: [0.0; 3],
        };
        assert!(stretch(&a) >= 2.0);
        let id = Affine {
            lin: None,
            trans: [1.0; 3],
        };
        assert_eq!(stretch(&id), 1.0);
    }
}
