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
//!   the nearer one) applied along the fold, which is what keeps the fold order.
//!
//! Intervals carry a slack for f32 rounding, so the f32 program pruned from the f64 one
//! drops only children that are exact no-ops in f32 as well.
//!
//! [`Cells`] applies this over an octree of the field's box: each cell prunes its parent
//! cell's program further (fidget prunes its tapes per image region the same way with
//! interval arithmetic, Keeter 2020), and a cell where the whole field is provably positive
//! by a margin holds no program at all but answers a safe bound.

use glam::{DVec3, Vec3};

use crate::lane::{F32x8, V3};
use marchmesh_scene::SmoothOp;

use crate::leaf::Leaf;
use crate::program::{Affine, GridSampler, Instr, Op, Program};
use crate::shapes;

/// Deepest composite nesting the pruner descends into; deeper subtrees are kept whole (so a
/// deep tree costs bounded recursion and time per cell).
const MAX_PRUNE_DEPTH: usize = 24;

/// Relative slack of every interval (f32 rounding of the values and of the coordinates).
const SLACK_REL: f64 = 2e-5;

/// A program restricted to a ball, and the interval of its value there.
#[derive(Debug, Clone, PartialEq)]
pub struct Pruned {
    /// The restricted program: within the `max_error` given to [`prune`] of the whole
    /// program at every point of the ball (equal to it for `0`).
    pub program: Program<f64>,
    /// Lower bound of the value over the ball (`-inf` when unknown).
    pub lo: f64,
    /// Upper bound of the value over the ball (`+inf` when unknown).
    pub hi: f64,
    /// Index in the whole program of each node of [`Pruned::program`]: equal lists mean
    /// equal programs (cells share them).
    pub source: Vec<u32>,
}

/// `prog` restricted to the ball of radius `radius` around `centre` (in the frame the program
/// is evaluated in), within `max_error` inside the ball: `0` keeps the whole program's value
/// bit for bit, a positive `max_error` lets smooth unions drop the start of their fold where
/// it changes the value by less than that (see `Pruner::smooth_union_keep`). Never fails
/// (an empty program stays empty).
pub fn prune(
    prog: &Program<f64>,
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
        };
    }
    let mut p = Pruner {
        prog,
        grids,
        out: Vec::with_capacity(prog.instrs.len().min(1024)),
        source: Vec::with_capacity(prog.instrs.len().min(1024)),
        // Errors of nested cuts add along a path of at most MAX_PRUNE_DEPTH + 1 nodes.
        cut_error: if max_error.is_finite() && max_error > 0.0 {
            max_error / (MAX_PRUNE_DEPTH + 1) as f64
        } else {
            0.0
        },
    };
    let c = V3::new(centre.x, centre.y, centre.z);
    let (lo, hi) = p.interval(0, c, radius);
    p.emit(0, c, radius, 0);
    Pruned {
        program: Program { instrs: p.out },
        lo,
        hi,
        source: p.source,
    }
}

struct Pruner<'a> {
    prog: &'a Program<f64>,
    grids: &'a [Box<dyn GridSampler>],
    out: Vec<Instr<f64>>,
    /// Index in `prog` of each node of `out`.
    source: Vec<u32>,
    /// Largest change of one smooth union's value its prefix cut may make (0: exact).
    cut_error: f64,
}

/// An upper bound of the stretch of `a`'s linear part (its Frobenius norm; 1 for none).
fn stretch(a: &Affine<f64>) -> f64 {
    a.lin
        .map_or(1.0, |m| m.iter().map(|v| v * v).sum::<f64>().sqrt())
}

impl Pruner<'_> {
    fn end(&self, i: usize) -> usize {
        self.prog.instrs[i].end as usize
    }

    fn has_mesh(&self, i: usize) -> bool {
        self.prog.instrs[i..self.end(i)]
            .iter()
            .any(|n| matches!(n.op, Op::Leaf(Leaf::Mesh { .. })))
    }

    /// Node `i`'s value over the ball `(q, r)` in its parent's frame.
    fn interval(&self, i: usize, q: V3<f64>, r: f64) -> (f64, f64) {
        if self.has_mesh(i) {
            return (f64::NEG_INFINITY, f64::INFINITY);
        }
        let v = self.prog.node_value(i, q, self.grids);
        if !v.is_finite() {
            return (f64::NEG_INFINITY, f64::INFINITY);
        }
        let scale = q.x.abs().max(q.y.abs()).max(q.z.abs()) + r;
        let slack = SLACK_REL * (1.0 + v.abs() + scale);
        (v - r - slack, v + r + slack)
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

    /// The children of a smooth union (a left fold `f_j = smin(f_{j-1}, a_j)`) to keep, from
    /// each child's interval `(index, lo, hi)` over the ball.
    ///
    /// Exact rules: a child with `a_j >= P.hi + k` (`P` the prefix's interval, folded by
    /// interval arithmetic: `smin` is non-decreasing in both arguments) leaves the fold
    /// unchanged and is dropped; a child with `a_j <= P.lo - k` replaces it (`smin = a_j`), so
    /// every child before it is dropped.
    ///
    /// Cut within `self.cut_error`: starting the fold at child `c` instead (dropping the
    /// children before it) changes `f_c` by at most `k h^2 / 4` where the child lies below the
    /// prefix over the whole ball (`h = max(k - (P.lo - a.hi), 0) / k`), and a change of the
    /// prefix reaches the result through `d smin(x, a) / dx`, which is `h / 2 <= 1/2` where
    /// the child is below `x` and at most 1 anywhere (so later steps never amplify it, and
    /// a dropped no-op child passes it unchanged). The latest `c` whose change, times the
    /// product of the later steps' derivative bounds, is within the budget is taken: in an
    /// approach chain (each child nearer than the running blend) the prefix's influence
    /// halves at least with every step, so a few dozen children remain instead of the whole
    /// chain.
    fn smooth_union_keep(&self, kids: &[(usize, f64, f64)], k: f64, inv_k: f64) -> Vec<usize> {
        // Kept children with the prefix interval before each.
        let mut chain: Vec<(usize, f64, f64, f64, f64)> = Vec::new();
        let mut fold: Option<(f64, f64)> = None;
        for &(j, lo, hi) in kids {
            match fold {
                None => {
                    chain.push((j, lo, hi, f64::INFINITY, f64::INFINITY));
                    fold = Some((lo, hi));
                }
                Some((plo, phi)) => {
                    if lo >= phi + k {
                        // smin(f, a_j) = f exactly: a no-op.
                        continue;
                    }
                    if plo >= hi + k {
                        // smin(f, a_j) = a_j exactly: the prefix no longer matters.
                        chain.clear();
                        chain.push((j, lo, hi, f64::INFINITY, f64::INFINITY));
                        fold = Some((lo, hi));
                        continue;
                    }
                    chain.push((j, lo, hi, plo, phi));
                    fold = Some((
                        shapes::smin(plo, lo, k, inv_k),
                        shapes::smin(phi, hi, k, inv_k),
                    ));
                }
            }
        }
        let mut start = 0;
        if self.cut_error > 0.0 && chain.len() > 1 {
            // `after`: the product of the derivative bounds of the steps after `c`.
            let mut after = 1.0f64;
            for c in (1..chain.len()).rev() {
                let (_, _, hi, plo, _) = chain[c];
                let below = plo >= hi;
                let h = ((k - (plo - hi)) * inv_k).clamp(0.0, 1.0);
                if below && 0.25 * k * h * h * after <= self.cut_error {
                    start = c;
                    break;
                }
                after *= if below { 0.5 * h } else { 1.0 };
            }
        }
        chain[start..].iter().map(|c| c.0).collect()
    }

    /// Emits node `i` (kept) restricted to the ball `(c, r)` in its parent's frame.
    fn emit(&mut self, i: usize, c: V3<f64>, r: f64, depth: usize) {
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
        let mut kids = Vec::new();
        let mut j = i + 1;
        while j < end {
            let (lo, hi) = self.interval(j, q, rq);
            kids.push((j, lo, hi));
            j = self.end(j);
        }
        let keep: Vec<usize> = match &ins.op {
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
            } => self.smooth_union_keep(&kids, *k, *inv_k),
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
            _ => unreachable!("composite checked above"),
        };
        let start = self.out.len();
        self.out.push(ins.clone());
        self.source.push(i as u32);
        for j in keep {
            self.emit(j, q, rq, depth + 1);
        }
        self.out[start].end = self.out.len() as u32;
    }
}

/// What a cell of [`Cells`] answers.
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    /// No surface in the cell: the whole field is at least `bound > 0` (or at most
    /// `bound < 0`) in the box `[lo, hi]`, so the distance to any surface from a point `p` of
    /// the box is at least `|bound|` plus `p`'s distance to the box's boundary (a path to a
    /// surface leaves the box through a point where `|field| >= |bound|`); the cell answers
    /// that, with the field's sign.
    Far {
        /// Bound of the field over the box nearest to zero (its sign is the field's there).
        bound: f32,
        /// Box lower corner.
        lo: [f32; 3],
        /// Box upper corner.
        hi: [f32; 3],
    },
    /// The program restricted to the cell (exact there).
    Program {
        /// f32 program (the tracer's).
        p32: Program<f32>,
        /// f64 program.
        p64: Program<f64>,
    },
}

/// An octree of cells over a box, each holding the field's program pruned to it or a far
/// bound, looked up through a dense index at the finest level.
#[derive(Debug, Clone)]
pub struct Cells {
    lo: [f32; 3],
    hi: [f32; 3],
    /// Finest cells per axis.
    res: u32,
    inv_size: [f32; 3],
    /// Cell id per finest cell, x fastest.
    index: Vec<u32>,
    cells: Vec<Cell>,
    /// Lower bound of the field on the box's boundary (and thus of the distance to any
    /// surface from outside the box, added to the distance to the box).
    pad: f32,
    stats: CellStats,
    /// While building: the cell holding each distinct program, by its nodes' indices in the
    /// whole program (neighbouring cells often keep the same children; they share one).
    by_source: std::collections::HashMap<Vec<u32>, u32>,
    /// While building: how many more program nodes the pruner may read
    /// ([`Cells::max_work`]).
    work_left: usize,
}

/// Counts of a [`Cells`] build, for reports.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CellStats {
    /// Cells holding a program.
    pub program_cells: usize,
    /// Cells answering a far bound.
    pub far_cells: usize,
    /// Program nodes over all program cells.
    pub program_nodes: usize,
    /// Largest program of any cell (nodes).
    pub max_program_nodes: usize,
    /// Program cells that share the program of an earlier cell (counted in
    /// `program_cells`, not in `program_nodes`).
    pub shared_cells: usize,
    /// Program nodes the pruner read over the build (its work: each octree node prunes its
    /// parent's program).
    pub pruned_nodes: usize,
}

/// Cells with at most this many nodes are not subdivided further.
const LEAF_NODES: usize = 12;

/// The far test: a cell is far when the field's bound nearest to zero over it is at least
/// this fraction of its bounding radius away from zero (so far values stay well above any
/// hit epsilon; the paper's empty cells are those where `|d| > 2R` at the centre).
const FAR_FRACTION: f64 = 0.5;

impl Cells {
    /// Builds the octree over `bounds` (a box holding every surface of the field; the octree
    /// covers it grown by `pad`, which must be positive) down to `2^depth` finest cells per
    /// axis (`depth` at most 8). `None` when the box is not finite, the program holds a
    /// mesh grid (grids are not Lipschitz bounds, see the module docs), the cells'
    /// programs would hold more than [`Cells::max_nodes`] nodes in all, or the pruner would
    /// read more than [`Cells::max_work`] program nodes (the build stops there: memory and
    /// time stay bounded; a deep chain whose cells keep most of it reads the whole program
    /// once per octree node). Every cell's program is within `max_error` of the
    /// whole program in the cell (each level of the octree prunes within its share), and far
    /// bounds are lowered by it: `0` keeps values bit for bit.
    pub fn build(
        prog: &Program<f64>,
        grids: &[Box<dyn GridSampler>],
        bounds: (DVec3, DVec3),
        pad: f64,
        depth: u32,
        max_error: f64,
    ) -> Option<Cells> {
        let depth = depth.min(8);
        let max_error = if max_error.is_finite() {
            max_error.max(0.0)
        } else {
            0.0
        };
        if !(bounds.0.is_finite() && bounds.1.is_finite() && pad > 0.0)
            || prog
                .instrs
                .iter()
                .any(|n| matches!(n.op, Op::Leaf(Leaf::Mesh { .. })))
        {
            return None;
        }
        let lo = bounds.0 - DVec3::splat(pad);
        let hi = bounds.1 + DVec3::splat(pad);
        let res = 1u32 << depth;
        let size = (hi - lo) / f64::from(res);
        let mut cells = Cells {
            lo: lo.as_vec3().to_array(),
            hi: hi.as_vec3().to_array(),
            res,
            inv_size: (1.0 / size).as_vec3().to_array(),
            index: vec![0; (res as usize).pow(3)],
            cells: Vec::new(),
            pad: pad as f32,
            stats: CellStats::default(),
            by_source: std::collections::HashMap::new(),
            work_left: Self::max_work(prog.instrs.len()),
        };
        let budget = Self::max_nodes(prog.instrs.len());
        let whole: Vec<u32> = (0..prog.instrs.len() as u32).collect();
        let level_error = max_error / f64::from(depth + 1);
        let built = cells.build_cell(
            prog,
            &whole,
            grids,
            (lo, hi),
            [0; 3],
            res,
            budget,
            (level_error, max_error),
        );
        cells.by_source = std::collections::HashMap::new();
        built.then_some(cells)
    }

    /// The most program nodes all cells of a program of `nodes` nodes may hold together:
    /// eight times the program, at least 2^18.
    pub fn max_nodes(nodes: usize) -> usize {
        nodes.saturating_mul(8).max(1 << 18)
    }

    /// The most program nodes the pruner may read building the octree of a program of
    /// `nodes` nodes: 2^22 (about a second of pruning), or 16 times the program when that is
    /// more. A build over it stops ([`Cells::build`] returns `None`).
    pub fn max_work(nodes: usize) -> usize {
        nodes.saturating_mul(16).max(1 << 22)
    }

    #[allow(clippy::too_many_arguments)]
    fn build_cell(
        &mut self,
        prog: &Program<f64>,
        prog_source: &[u32],
        grids: &[Box<dyn GridSampler>],
        (lo, hi): (DVec3, DVec3),
        at: [u32; 3],
        span: u32,
        budget: usize,
        (level_error, max_error): (f64, f64),
    ) -> bool {
        let work = prog.instrs.len();
        if work > self.work_left {
            return false;
        }
        self.work_left -= work;
        self.stats.pruned_nodes += work;
        let radius = 0.5 * (hi - lo).length();
        let mut pruned = prune(prog, grids, 0.5 * (lo + hi), radius, level_error);
        for s in &mut pruned.source {
            *s = prog_source[*s as usize];
        }
        let nodes = pruned.program.instrs.len();
        // The parent's program may be up to `max_error` off the whole field's value.
        let far = if pruned.lo >= FAR_FRACTION * radius + max_error {
            Some(pruned.lo - max_error)
        } else if pruned.hi <= -FAR_FRACTION * radius - max_error {
            Some(pruned.hi + max_error)
        } else {
            None
        };
        let cell = if let Some(bound) = far {
            self.stats.far_cells += 1;
            Cell::Far {
                bound: bound as f32,
                lo: lo.as_vec3().to_array(),
                hi: hi.as_vec3().to_array(),
            }
        } else if span == 1 || nodes <= LEAF_NODES {
            if let Some(&id) = self.by_source.get(&pruned.source) {
                self.stats.program_cells += 1;
                self.stats.shared_cells += 1;
                self.fill_index(at, span, id);
                return true;
            }
            if self.stats.program_nodes + nodes > budget {
                return false;
            }
            self.by_source
                .insert(pruned.source.clone(), self.cells.len() as u32);
            self.stats.program_cells += 1;
            self.stats.program_nodes += nodes;
            self.stats.max_program_nodes = self.stats.max_program_nodes.max(nodes);
            Cell::Program {
                p32: pruned.program.cast::<f32>(),
                p64: pruned.program,
            }
        } else {
            let half = span / 2;
            let mid = 0.5 * (lo + hi);
            for o in 0..8u32 {
                let pick = |axis: u32, l: f64, m: f64, h: f64| {
                    if (o >> axis) & 1 == 0 { (l, m) } else { (m, h) }
                };
                let (x0, x1) = pick(0, lo.x, mid.x, hi.x);
                let (y0, y1) = pick(1, lo.y, mid.y, hi.y);
                let (z0, z1) = pick(2, lo.z, mid.z, hi.z);
                let sub = [0, 1, 2].map(|a| at[a] + ((o >> a) & 1) * half);
                if !self.build_cell(
                    &pruned.program,
                    &pruned.source,
                    grids,
                    (DVec3::new(x0, y0, z0), DVec3::new(x1, y1, z1)),
                    sub,
                    half,
                    budget,
                    (level_error, max_error),
                ) {
                    return false;
                }
            }
            return true;
        };
        let id = self.cells.len() as u32;
        self.cells.push(cell);
        self.fill_index(at, span, id);
        true
    }

    /// Points the finest cells of the `span`^3 block at `at` to cell `id`.
    fn fill_index(&mut self, at: [u32; 3], span: u32, id: u32) {
        let res = self.res as usize;
        for z in at[2]..at[2] + span {
            for y in at[1]..at[1] + span {
                let row = (z as usize * res + y as usize) * res;
                self.index[row + at[0] as usize..row + (at[0] + span) as usize].fill(id);
            }
        }
    }

    /// Counts of the build.
    pub fn stats(&self) -> CellStats {
        self.stats
    }

    /// Exact bytes held (index, cells and their programs).
    pub fn memory_bytes(&self) -> u64 {
        let programs: u64 = self
            .cells
            .iter()
            .map(|c| match c {
                Cell::Far { .. } => 0,
                Cell::Program { p32, p64 } => p32.memory_bytes() + p64.memory_bytes(),
            })
            .sum();
        (self.index.len() * 4 + self.cells.len() * std::mem::size_of::<Cell>()) as u64 + programs
    }

    /// The cell holding `p`, `None` outside the octree's box.
    #[inline(always)]
    pub fn locate(&self, p: [f32; 3]) -> Option<&Cell> {
        let mut at = [0usize; 3];
        for a in 0..3 {
            let f = (p[a] - self.lo[a]) * self.inv_size[a];
            // Also false for NaN.
            if !(f >= 0.0 && p[a] <= self.hi[a]) {
                return None;
            }
            at[a] = (f as usize).min(self.res as usize - 1);
        }
        let res = self.res as usize;
        let id = self.index[(at[2] * res + at[1]) * res + at[0]];
        self.cells.get(id as usize)
    }

    /// The safe value outside the box: the distance to the box plus the pad.
    #[inline(always)]
    pub fn outside(&self, p: [f32; 3]) -> f32 {
        let mut s = 0.0f32;
        for a in 0..3 {
            let d = (self.lo[a] - p[a]).max(p[a] - self.hi[a]).max(0.0);
            s += d * d;
        }
        s.sqrt() + self.pad
    }

    /// A far cell's value at `p` inside its box: `bound` moved away from zero by `p`'s
    /// distance to the box's boundary.
    #[inline(always)]
    pub fn far_value(bound: f32, lo: &[f32; 3], hi: &[f32; 3], p: [f32; 3]) -> f32 {
        let mut inner = f32::INFINITY;
        for a in 0..3 {
            inner = inner.min(p[a] - lo[a]).min(hi[a] - p[a]);
        }
        bound + inner.max(0.0).copysign(bound)
    }

    /// Values (and materials when `M`) at eight points: each lane answered by its cell, one
    /// 8-lane evaluation per distinct program cell among the lanes.
    /// With `M`, lanes outside program cells take their value and material from `whole`
    /// (the unpruned program: far bounds carry no material).
    pub fn eval_x8<const M: bool>(
        &self,
        p: V3<F32x8>,
        whole: &Program<f32>,
        grids: &[Box<dyn GridSampler>],
    ) -> (F32x8, [u32; 8]) {
        let mut out = F32x8([0.0; 8]);
        let mut mat = [0u32; 8];
        let pts: [[f32; 3]; 8] = std::array::from_fn(|i| [p.x.0[i], p.y.0[i], p.z.0[i]]);
        let cells: [Option<&Cell>; 8] = std::array::from_fn(|i| self.locate(pts[i]));
        let mut done = 0u8;
        if M && cells
            .iter()
            .any(|c| !matches!(c, Some(Cell::Program { .. })))
        {
            let (d, m) = whole.eval::<F32x8, true>(p, grids);
            for i in 0..8 {
                if !matches!(cells[i], Some(Cell::Program { .. })) {
                    out.0[i] = d.0[i];
                    mat[i] = m[i];
                    done |= 1 << i;
                }
            }
        }
        for i in 0..8 {
            if (done >> i) & 1 == 1 {
                continue;
            }
            match cells[i] {
                None => {
                    out.0[i] = self.outside(pts[i]);
                    done |= 1 << i;
                }
                Some(Cell::Far { bound, lo, hi }) => {
                    out.0[i] = Self::far_value(*bound, lo, hi, pts[i]);
                    done |= 1 << i;
                }
                Some(c @ Cell::Program { p32, .. }) => {
                    let (d, m) = p32.eval::<F32x8, M>(p, grids);
                    for l in i..8 {
                        if cells[l].is_some_and(|o| std::ptr::eq(o, c)) {
                            out.0[l] = d.0[l];
                            mat[l] = m[l];
                            done |= 1 << l;
                        }
                    }
                }
            }
        }
        (out, mat)
    }

    /// Value and material at one point in f32 (`M`: track the material, taken from `whole`
    /// outside program cells).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn eval<const M: bool>(
        &self,
        p: Vec3,
        whole: &Program<f32>,
        grids: &[Box<dyn GridSampler>],
    ) -> (f32, u32) {
        let a = p.to_array();
        let v = V3::new(p.x, p.y, p.z);
        match self.locate(a) {
            Some(Cell::Program { p32, .. }) => p32.eval::<f32, M>(v, grids),
            _ if M => whole.eval::<f32, true>(v, grids),
            None => (self.outside(a), 0),
            Some(Cell::Far { bound, lo, hi }) => (Self::far_value(*bound, lo, hi, a), 0),
        }
    }

    /// A bound of the distance to any surface at `p` in f64, with the field's sign, where `p`
    /// is outside the box or in a far cell (with a slack for the f32 corners), `None` in
    /// program cells.
    #[inline]
    pub fn far_bound_f64(&self, p: DVec3) -> Option<f64> {
        let a = p.as_vec3().to_array();
        let slack = 1e-6 * (1.0 + p.abs().max_element());
        let lo = |b: &[f32; 3]| DVec3::from_array(b.map(f64::from));
        match self.locate(a) {
            Some(Cell::Program { .. }) => None,
            None => {
                let (blo, bhi) = (lo(&self.lo), lo(&self.hi));
                let d = (blo - p).max(p - bhi).max(DVec3::ZERO).length();
                Some(d + f64::from(self.pad) - slack)
            }
            Some(Cell::Far {
                bound,
                lo: l,
                hi: h,
            }) => {
                let inner = (p - lo(l)).min(lo(h) - p).min_element().max(0.0);
                let b = f64::from(*bound);
                Some((b.abs() + inner - slack).max(0.0).copysign(b))
            }
        }
    }

    /// The f64 program of the cell holding `p` when it is a program cell (`None` outside
    /// the box and in far cells, where the caller evaluates the whole program).
    #[inline]
    pub fn program_f64(&self, p: DVec3) -> Option<&Program<f64>> {
        match self.locate(p.as_vec3().to_array())? {
            Cell::Program { p64, .. } => Some(p64),
            Cell::Far { .. } => None,
        }
    }

    /// The f32 program of the program cell holding both `a` and `b`, if one does.
    #[inline]
    pub fn program_f32_holding(&self, a: Vec3, b: Vec3) -> Option<&Program<f32>> {
        let ca = self.locate(a.to_array())?;
        let cb = self.locate(b.to_array())?;
        match ca {
            Cell::Program { p32, .. } if std::ptr::eq(ca, cb) => Some(p32),
            _ => None,
        }
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
