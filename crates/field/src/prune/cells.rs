//! The octree of restricted programs ([`Cells`]) a field's point queries read.

use glam::{DVec3, Vec3};

use super::{PruneIndex, prune_indexed, root_subset, survey_root};
use crate::lane::{F32x8, V3};
use crate::leaf::Leaf;
use crate::program::{GridSampler, KidBlock, Op, Program};

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
        /// The field's value at the box's centre bounded on `bound`'s side (a lower bound
        /// when positive, an upper bound when negative; at least `|bound|` from zero), so
        /// by the Lipschitz bound the distance from `p` is also at least
        /// `|centre_bound| - |p - centre|`.
        centre_bound: f32,
    },
    /// No program of its own: the whole program is evaluated (the node budget was spent).
    Whole,
    /// The program restricted to the cell when that keeps the root (a smooth union or a
    /// blend) and some of its children whole: those children's node indices, in stored
    /// order, read through [`Program::eval_root_subset`] on the whole program (4 bytes a
    /// child instead of a copied node; the same values).
    Subset {
        /// Node indices of the kept children (at least one).
        kids: Box<[u32]>,
        /// [`KidBlock::table`] of `kids` over the whole program's sphere table (empty
        /// while building): a fold scans eight children at a time.
        blocks: Box<[KidBlock]>,
    },
    /// The program restricted to the cell (exact there).
    Program {
        /// f32 program (the tracer's).
        p32: Program<f32>,
        /// f64 program.
        p64: Program<f64>,
    },
}

impl Cell {
    /// Whether the cell answers by evaluating a program (not a far bound).
    fn evaluates(&self) -> bool {
        !matches!(self, Cell::Far { .. })
    }
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
    by_source: super::FastMap<Vec<u32>, u32>,
    /// While building: how many more program nodes the pruner may read
    /// ([`Cells::max_work`]).
    work_left: usize,
    /// The whole program's [`Program::sphere_table`] in f32 when some cell is a
    /// [`Cell::Subset`] (empty otherwise): subset folds rule far spheres out from it.
    spheres32: Vec<[f32; 4]>,
    /// A blend root's children per finest cell ([`FineLists`]; empty otherwise).
    fine: FineLists,
}

/// For a root blend ([`marchmesh_scene::SmoothOp::Blend`]): per finest cell of the octree
/// inside a subset cell listing more than [`FINE_MIN_KIDS`] children, the ones that can
/// come within `k` of the blend's minimum in that finest cell (the others add an exact `+0`
/// to the blend's sums there, `program::blend`), deduplicated. A blend's value at a point
/// needs only the children near it, so lists over finest cells, not over the cells the
/// octree's work budget stops at, set a step's cost. A fold has no such lists: its value
/// depends on the children before the near ones.
#[derive(Debug, Clone, Default)]
struct FineLists {
    /// Per finest cell (as [`Cells`]' index): where its list starts in `kids`, `u32::MAX` for
    /// none (the cell's own list applies). Empty when there are no lists.
    entry: Vec<u32>,
    /// The lists, each its length and then its children in stored order: a step reads its
    /// entry and then one run of memory, not a table of spans between them.
    kids: Vec<u32>,
    /// Distinct lists in `kids`.
    lists: usize,
}

/// Subset cells of a root blend listing more children than this get [`FineLists`].
const FINE_MIN_KIDS: usize = 16;

/// The descent [`Cells::list_blend_children`] makes.
struct Lists<'a> {
    prog: &'a Program<f64>,
    /// The program's [`Program::sphere_table`].
    spheres: Vec<[f64; 4]>,
    /// Stretch of the root's frame (a ball's radius in it).
    stretch: f64,
    k: f64,
    lo: DVec3,
    /// A finest cell's size.
    size: DVec3,
    /// Finest cells per axis.
    res: usize,
    /// Per finest cell: whether its cell gets a list.
    wants: &'a [bool],
    /// Each distinct list's span.
    seen: super::FastMap<Vec<u32>, u32>,
}

impl Lists<'_> {
    /// Whether a finest cell of the block at `at` (finest cells) of side `span` wants a list.
    fn wanted(&self, at: [usize; 3], span: usize) -> bool {
        (at[2]..at[2] + span).any(|z| {
            (at[1]..at[1] + span).any(|y| {
                let row = (z * self.res + y) * self.res;
                self.wants[row + at[0]..row + at[0] + span].contains(&true)
            })
        })
    }

    /// Of `parent` (stored order), the children that can come within `k` of the blend's
    /// minimum in the ball around the block at `at` of side `span`.
    fn keep(&self, at: [usize; 3], span: usize, parent: &[u32]) -> Vec<u32> {
        let corner = |o: usize| {
            self.lo
                + self.size * DVec3::new((at[0] + o) as f64, (at[1] + o) as f64, (at[2] + o) as f64)
        };
        let (a, b) = (corner(0), corner(span));
        let c = 0.5 * (a + b);
        let root = &self.prog.instrs[0];
        let q = root.to_local.apply(V3::new(c.x, c.y, c.z));
        let rq = 0.5 * (b - a).length() * self.stretch;
        // Each child's value at the centre (`-inf` for a child that is not a sphere).
        let values: Vec<f64> = parent
            .iter()
            .map(|&j| {
                let s = self.spheres[j as usize];
                if s[3].is_nan() {
                    return f64::NEG_INFINITY;
                }
                let (x, y, z) = (q.x + s[0], q.y + s[1], q.z + s[2]);
                (x * x + y * y + z * z).sqrt() - s[3]
            })
            .collect();
        let least_upper = values
            .iter()
            .filter(|d| d.is_finite())
            .fold(f64::INFINITY, |m, d| m.min(d + rq));
        let scale = q.x.abs().max(q.y.abs()).max(q.z.abs()) + rq + self.k;
        let reach =
            least_upper + self.k + super::SLACK_REL * (1.0 + least_upper.abs().min(1e300) + scale);
        parent
            .iter()
            .zip(&values)
            .filter(|(_, d)| **d - rq < reach)
            .map(|(&j, _)| j)
            .collect()
    }

    fn descend(
        &mut self,
        index: &[u32],
        cells: &[Cell],
        at: [usize; 3],
        span: usize,
        parent: &[u32],
        fine: &mut FineLists,
    ) {
        if !self.wanted(at, span) {
            return;
        }
        let list = self.keep(at, span, parent);
        if span > 1 {
            let half = span / 2;
            for o in 0..8 {
                let sub = [0, 1, 2].map(|a| at[a] + ((o >> a) & 1) * half);
                self.descend(index, cells, sub, half, &list, fine);
            }
            return;
        }
        let e = (at[2] * self.res + at[1]) * self.res + at[0];
        let Some(Cell::Subset { kids, .. }) = cells.get(index[e] as usize) else {
            return;
        };
        // Both lists are in stored order: their intersection, in it.
        let mut both = Vec::with_capacity(list.len().min(kids.len()));
        let (mut i, mut j) = (0, 0);
        while i < list.len() && j < kids.len() {
            match list[i].cmp(&kids[j]) {
                std::cmp::Ordering::Less => i += 1,
                std::cmp::Ordering::Greater => j += 1,
                std::cmp::Ordering::Equal => {
                    both.push(list[i]);
                    i += 1;
                    j += 1;
                }
            }
        }
        if both.len() >= kids.len() || both.is_empty() {
            return;
        }
        let start = match self.seen.get(&both) {
            Some(&start) => start,
            None => {
                let start = fine.kids.len() as u32;
                fine.kids.push(both.len() as u32);
                fine.kids.extend_from_slice(&both);
                fine.lists += 1;
                self.seen.insert(both, start);
                start
            }
        };
        fine.entry[e] = start;
    }
}

thread_local! {
    /// The merged kept children of an 8-lane query over several subset cells, and a bit
    /// per child marking them (all clear between queries).
    static MERGED: std::cell::RefCell<(Vec<u32>, Vec<u64>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

/// A cell of the octree being built: its box and its block of finest cells.
#[derive(Debug, Clone, Copy)]
struct Region {
    lo: DVec3,
    hi: DVec3,
    /// Lowest finest cell of the block.
    at: [u32; 3],
    /// Finest cells per axis of the block.
    span: u32,
}

impl Region {
    /// The eight cells below.
    fn split(&self) -> [Region; 8] {
        let half = self.span / 2;
        let mid = 0.5 * (self.lo + self.hi);
        std::array::from_fn(|o| {
            let o = o as u32;
            let pick = |axis: u32, l: f64, m: f64, h: f64| {
                if (o >> axis) & 1 == 0 { (l, m) } else { (m, h) }
            };
            let (x0, x1) = pick(0, self.lo.x, mid.x, self.hi.x);
            let (y0, y1) = pick(1, self.lo.y, mid.y, self.hi.y);
            let (z0, z1) = pick(2, self.lo.z, mid.z, self.hi.z);
            Region {
                lo: DVec3::new(x0, y0, z0),
                hi: DVec3::new(x1, y1, z1),
                at: [0, 1, 2].map(|a| self.at[a] + ((o >> a) & 1) * half),
                span: half,
            }
        })
    }
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
    /// Work of the build ([`super::Pruned::work`] summed, plus the surveys of crowded cells).
    pub pruned_nodes: usize,
    /// Program cells that read the whole program: the node budget ([`Cells::max_nodes`])
    /// was spent (counted in `program_cells`).
    pub whole_cells: usize,
    /// Program cells listing the root's kept children ([`Cell::Subset`]; counted in
    /// `program_cells`, not in `program_nodes`).
    pub subset_cells: usize,
    /// Children listed by all subset cells.
    pub subset_children: usize,
    /// The work budget stopped the refinement: some cells settled where they would have
    /// been split further (at a coarser level than `depth`).
    pub budget_cut: bool,
    /// Distinct lists of a root blend's children per finest cell (`FineLists`).
    pub fine_lists: usize,
    /// Children listed by those lists.
    pub fine_children: usize,
}

/// Cells with at most this many nodes are not subdivided further.
const LEAF_NODES: usize = 12;

/// Restricted programs of at most this many nodes are copied into their cell (contiguous
/// nodes evaluate faster than a list of indices into the whole program) while the node
/// budget lasts; larger ones are stored as subsets when they can be.
const COPY_NODES: usize = 32;

/// The far test: a cell is far when the field's bound nearest to zero over it is at least
/// this fraction of its bounding radius away from zero (so far values stay well above any
/// hit epsilon; the paper's empty cells are those where `|d| > 2R` at the centre).
const FAR_FRACTION: f64 = 0.5;

impl Cells {
    /// Builds the octree over `bounds` (a box holding every surface of the field; the octree
    /// covers it grown by `pad`, which must be positive) down to `2^depth` finest cells per
    /// axis (`depth` at most 8), refined level by level while the next level's predicted
    /// work fits in [`Cells::max_work`] (so a large program gets a coarser octree, and a
    /// deep chain whose cells keep most of it is not read once per octree node); cells
    /// past [`Cells::max_nodes`] program nodes read the whole program. Memory and time stay
    /// bounded: the work spent is at most about twice the budget (the last level settles
    /// its cells whatever they cost). `None` when the box is not finite or the program
    /// holds a mesh grid (grids are not Lipschitz bounds, see the module docs). Every cell
    /// restricts the whole program through `index` (built
    /// from `prog` by [`PruneIndex::build`]) within `max_error` of its value in the cell, and
    /// far bounds hold for the whole program: `0` keeps values bit for bit.
    pub fn build(
        prog: &Program<f64>,
        index: &PruneIndex,
        grids: &[Box<dyn GridSampler>],
        bounds: (DVec3, DVec3),
        pad: f64,
        depth: u32,
        max_error: f64,
    ) -> Option<Cells> {
        let work = Self::max_work(prog.instrs.len());
        Self::build_within(prog, index, grids, bounds, pad, depth, max_error, work)
    }

    /// [`Cells::build`] with a work budget of `work` instead of [`Cells::max_work`].
    #[allow(clippy::too_many_arguments)]
    pub fn build_within(
        prog: &Program<f64>,
        index: &PruneIndex,
        grids: &[Box<dyn GridSampler>],
        bounds: (DVec3, DVec3),
        pad: f64,
        depth: u32,
        max_error: f64,
        work: usize,
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
            by_source: super::FastMap::default(),
            work_left: work,
            spheres32: Vec::new(),
            fine: FineLists::default(),
        };
        let budget = Self::max_nodes(prog.instrs.len());
        let mut level = vec![Region {
            lo,
            hi,
            at: [0; 3],
            span: res,
        }];
        while !level.is_empty() {
            let work_before = cells.work_left;
            let mut crowded = Vec::new();
            for &region in &level {
                // Once the work budget is spent, the rest of the level settles.
                let refine = cells.work_left > 0;
                if !cells.settle(prog, index, grids, region, refine, budget, max_error) {
                    crowded.push(region);
                }
            }
            // The next level has eight cells per crowded one, each costing at most about
            // what a cell of this level did (finer cells keep fewer children).
            let per_cell = (work_before - cells.work_left) / level.len().max(1);
            let next = crowded.len() * 8;
            if next.saturating_mul(per_cell.max(1)) > cells.work_left {
                cells.stats.budget_cut = true;
                for &region in &crowded {
                    cells.settle(prog, index, grids, region, false, budget, max_error);
                }
                break;
            }
            level = crowded.iter().flat_map(Region::split).collect();
        }
        cells.by_source = super::FastMap::default();
        if cells.stats.subset_cells > 0 {
            cells.spheres32 = prog.sphere_table();
            for cell in &mut cells.cells {
                if let Cell::Subset { kids, blocks } = cell {
                    *blocks = KidBlock::table(&cells.spheres32, kids).into();
                }
            }
        }
        Some(cells)
    }

    /// Lists a root blend's children per finest cell for its subset cells listing more than
    /// 16 children (read by the queries in place of the cell's list): call it once the
    /// octree is final (a trial build does not need them). `prog` is the program the cells
    /// were built from.
    /// Does nothing for any other root. The lists come from a descent of the octree's
    /// blocks from the whole box down to the finest cells, each block keeping of its
    /// parent's list the children that can come within `k` of the blend's minimum in its
    /// bounding ball: a sphere whose least value there is at least `k` (and a slack for the
    /// f32 evaluation's rounding) above the least upper bound of the listed spheres is
    /// dropped (it adds an exact `+0` there and in every block below); any other child is
    /// kept. A finest cell's list is then intersected with its cell's own.
    pub fn list_blend_children(&mut self, prog: &Program<f64>) {
        self.fine = FineLists::default();
        let Some(root) = prog.instrs.first() else {
            return;
        };
        let Op::Smooth {
            op: marchmesh_scene::SmoothOp::Blend,
            k,
            ..
        } = root.op
        else {
            return;
        };
        let res = self.res as usize;
        let wants: Vec<bool> = self
            .index
            .iter()
            .map(|&id| {
                matches!(self.cells.get(id as usize),
                    Some(Cell::Subset { kids, .. }) if kids.len() > FINE_MIN_KIDS)
            })
            .collect();
        if !wants.contains(&true) {
            return;
        }
        let lo = DVec3::from_array(self.lo.map(f64::from));
        let size = DVec3::from_array(self.inv_size.map(|v| 1.0 / f64::from(v)));
        let all: Vec<u32> = crate::program::blend::Children::of(prog, 0)
            .map(|(j, _)| j as u32)
            .collect();
        let mut fine = FineLists {
            entry: vec![u32::MAX; self.index.len()],
            ..FineLists::default()
        };
        let mut lists = Lists {
            prog,
            spheres: prog.sphere_table::<f64>(),
            stretch: super::stretch(&root.to_local),
            k,
            lo,
            size,
            res,
            wants: &wants,
            seen: super::FastMap::default(),
        };
        lists.descend(
            &self.index,
            &self.cells,
            [0; 3],
            self.res as usize,
            &all,
            &mut fine,
        );
        if fine.lists > 0 {
            self.stats.fine_lists = fine.lists;
            self.stats.fine_children = fine.kids.len() - fine.lists;
            self.fine = fine;
        }
    }

    /// The children to read at the finest cell `e` of a subset cell listing `kids`: its
    /// [`FineLists`] entry when it has one, else `kids`.
    #[inline(always)]
    fn kids_at<'a>(&'a self, e: usize, kids: &'a [u32]) -> &'a [u32] {
        self.fine_list(e).unwrap_or(kids)
    }

    /// The [`FineLists`] list of the finest cell `e`, `None` when it has none.
    #[inline(always)]
    fn fine_list(&self, e: usize) -> Option<&[u32]> {
        let start = *self.fine.entry.get(e)? as usize;
        let len = *self.fine.kids.get(start)? as usize;
        self.fine.kids.get(start + 1..start + 1 + len)
    }

    /// The most program nodes all cells of a program of `nodes` nodes may hold together:
    /// eight times the program, at least 2^18 (about 100 MB); cells past it read the whole
    /// program ([`Cell::Whole`]).
    pub fn max_nodes(nodes: usize) -> usize {
        nodes.saturating_mul(8).max(1 << 18)
    }

    /// The work ([`super::Pruned::work`]) the octree's build may spend: 2^24 (a few tenths of a
    /// second), or 64 times the program when that is more. The octree is refined level by
    /// level while the next level's predicted work fits in what is left; past it the
    /// cells of the last level keep their programs (coarser cells, never a failed build).
    pub fn max_work(nodes: usize) -> usize {
        nodes.saturating_mul(64).max(1 << 24)
    }

    /// Settles the cell `region` as a far bound or a program cell, or (when `refine`, it
    /// keeps more than [`LEAF_NODES`] and is not a finest cell) leaves it to be split:
    /// returns whether it was settled. The whole program is restricted to the cell's
    /// bounding ball through `index` (so a cell's cost follows the children near it, at any
    /// depth); a crowded cell (by the root's child tree) is split without restricting.
    #[allow(clippy::too_many_arguments)]
    fn settle(
        &mut self,
        prog: &Program<f64>,
        index: &PruneIndex,
        grids: &[Box<dyn GridSampler>],
        region: Region,
        refine: bool,
        budget: usize,
        max_error: f64,
    ) -> bool {
        let Region { lo, hi, at, span } = region;
        // Unrefined for want of work (not for depth): a crowded cell settling marks the cut.
        let starved = !refine && span > 1;
        let refine = refine && span > 1;
        let radius = 0.5 * (hi - lo).length();
        let centre = 0.5 * (lo + hi);
        if let Some((lower, crowded, work)) =
            survey_root(prog, index, grids, centre, radius, LEAF_NODES)
        {
            self.spend(work);
            if lower >= FAR_FRACTION * radius {
                self.push_far(lower, lower, region);
                return true;
            }
            if crowded && refine {
                return false;
            }
            self.stats.budget_cut |= crowded && starved;
        }
        let pruned = prune_indexed(prog, index, grids, centre, radius, max_error);
        self.spend(pruned.work);
        let nodes = pruned.program.instrs.len();
        // `lo`/`hi` bound the whole program's value over the cell.
        // The interval is the centre's value widened by the radius.
        if pruned.lo >= FAR_FRACTION * radius {
            self.push_far(pruned.lo, pruned.lo + radius, region);
            return true;
        }
        if pruned.hi <= -FAR_FRACTION * radius {
            self.push_far(pruned.hi, pruned.hi - radius, region);
            return true;
        }
        if refine && nodes > LEAF_NODES {
            return false;
        }
        self.stats.budget_cut |= starved && nodes > LEAF_NODES;
        let id = if let Some(&id) = self.by_source.get(&pruned.source) {
            self.stats.shared_cells += 1;
            id
        } else if let Some(kids) = (nodes > COPY_NODES || self.stats.program_nodes + nodes > budget)
            .then(|| root_subset(prog, &pruned.source))
            .flatten()
            && self.stats.subset_children + kids.len() <= Self::max_subset_children()
        {
            let id = self.cells.len() as u32;
            self.stats.subset_cells += 1;
            self.stats.subset_children += kids.len();
            self.stats.max_program_nodes = self.stats.max_program_nodes.max(nodes);
            self.by_source.insert(pruned.source, id);
            self.cells.push(Cell::Subset {
                kids,
                blocks: Box::new([]),
            });
            id
        } else if self.stats.program_nodes + nodes > budget {
            self.stats.whole_cells += 1;
            let id = self.cells.len() as u32;
            self.cells.push(Cell::Whole);
            id
        } else {
            let id = self.cells.len() as u32;
            self.by_source.insert(pruned.source, id);
            self.stats.program_nodes += nodes;
            self.stats.max_program_nodes = self.stats.max_program_nodes.max(nodes);
            self.cells.push(Cell::Program {
                p32: pruned.program.cast::<f32>(),
                p64: pruned.program,
            });
            id
        };
        self.stats.program_cells += 1;
        self.fill_index(at, span, id);
        true
    }

    /// The most kept children all subset cells ([`Cell::Subset`]) may list together: 2^22,
    /// 20 bytes each with their blocks ([`KidBlock`]), about 84 MB; past it cells copy their
    /// programs (within [`Cells::max_nodes`]).
    pub fn max_subset_children() -> usize {
        1 << 22
    }

    fn spend(&mut self, work: usize) {
        self.work_left = self.work_left.saturating_sub(work);
        self.stats.pruned_nodes += work;
    }

    /// A far cell of `region` whose field is at least `bound > 0` (at most `bound < 0`)
    /// over it and at least (at most) `centre_bound` at its centre.
    fn push_far(&mut self, bound: f64, centre_bound: f64, region: Region) {
        self.stats.far_cells += 1;
        let id = self.cells.len() as u32;
        let centre_bound = if bound > 0.0 {
            centre_bound.max(bound)
        } else {
            centre_bound.min(bound)
        };
        self.cells.push(Cell::Far {
            bound: bound as f32,
            lo: region.lo.as_vec3().to_array(),
            hi: region.hi.as_vec3().to_array(),
            centre_bound: centre_bound as f32,
        });
        self.fill_index(region.at, region.span, id);
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
                Cell::Far { .. } | Cell::Whole => 0,
                Cell::Subset { kids, blocks } => {
                    kids.len() as u64 * 4 + std::mem::size_of_val(&**blocks) as u64
                }
                Cell::Program { p32, p64 } => p32.memory_bytes() + p64.memory_bytes(),
            })
            .sum();
        (self.index.len() * 4
            + self.cells.len() * std::mem::size_of::<Cell>()
            + self.spheres32.len() * 16
            + self.fine.entry.len() * 4
            + self.fine.kids.len() * 4) as u64
            + programs
    }

    /// The cell holding `p`, `None` outside the octree's box.
    #[inline(always)]
    pub fn locate(&self, p: [f32; 3]) -> Option<&Cell> {
        self.locate_finest(p).map(|(_, c)| c)
    }

    /// The finest cell holding `p` (its index) and the cell it belongs to, `None` outside the
    /// octree's box.
    #[inline(always)]
    fn locate_finest(&self, p: [f32; 3]) -> Option<(usize, &Cell)> {
        let e = self.finest(p)?;
        let id = self.index[e];
        self.cells.get(id as usize).map(|c| (e, c))
    }

    /// The finest cell holding `p` (its index), `None` outside the octree's box.
    #[inline(always)]
    fn finest(&self, p: [f32; 3]) -> Option<usize> {
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
        Some((at[2] * res + at[1]) * res + at[0])
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

    /// A far cell's value at `p` inside its box (with the field's sign): the larger of
    /// `|bound|` plus `p`'s distance to the box's boundary and `|centre_bound|` less `p`'s
    /// distance to the box's centre (each a lower bound of the distance to any surface).
    #[inline(always)]
    pub fn far_value(
        bound: f32,
        centre_bound: f32,
        lo: &[f32; 3],
        hi: &[f32; 3],
        p: [f32; 3],
    ) -> f32 {
        let mut inner = f32::INFINITY;
        let mut r2 = 0.0f32;
        for a in 0..3 {
            inner = inner.min(p[a] - lo[a]).min(hi[a] - p[a]);
            let c = p[a] - 0.5 * (lo[a] + hi[a]);
            r2 += c * c;
        }
        // The relative slack covers the f32 rounding of the distance to the centre.
        let from_centre = centre_bound.abs() - r2.sqrt() * (1.0 + 1e-6);
        (bound.abs() + inner.max(0.0))
            .max(from_centre)
            .copysign(bound)
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
        let found: [Option<(usize, &Cell)>; 8] =
            std::array::from_fn(|i| self.locate_finest(pts[i]));
        let cells: [Option<&Cell>; 8] = std::array::from_fn(|i| found[i].map(|f| f.1));
        // Per subset lane, the children it reads (a blend's finest-cell list or its cell's).
        let lists: [Option<&[u32]>; 8] = std::array::from_fn(|i| match found[i] {
            Some((e, Cell::Subset { kids, .. })) => Some(self.kids_at(e, kids)),
            _ => None,
        });
        let mut done = 0u8;
        if M && cells.iter().any(|c| !c.is_some_and(Cell::evaluates)) {
            let (d, m) = whole.eval::<F32x8, true>(p, grids);
            for i in 0..8 {
                if !cells[i].is_some_and(Cell::evaluates) {
                    out.0[i] = d.0[i];
                    mat[i] = m[i];
                    done |= 1 << i;
                }
            }
        }
        // Lanes in two or more subset cells: one evaluation over the union of their kept
        // children (in fold order), exact for every one of them: a child one cell drops is a
        // no-op or a replaced prefix there, and folding more children only lowers the prefix
        // (the replacement and no-op tests hold a fortiori), while a cut prefix's influence
        // only shrinks.
        let mut subsets = [&[][..]; 8];
        let mut n_subsets = 0;
        for i in 0..8 {
            if (done >> i) & 1 == 0
                && let Some(kids) = lists[i]
                && !subsets[..n_subsets].iter().any(|k| std::ptr::eq(*k, kids))
            {
                subsets[n_subsets] = kids;
                n_subsets += 1;
            }
        }
        if n_subsets > 1 {
            MERGED.with_borrow_mut(|(merged, bits)| {
                // The union in fold order (ascending node index): every list's children set
                // as bits, then the words between the least and the greatest read back in
                // order (and cleared). No comparison per pair of children, whose branches a
                // pairwise merge mispredicts about every other time.
                let mut separate = 0;
                let (mut lo, mut hi) = (usize::MAX, 0);
                for kids in &subsets[..n_subsets] {
                    separate += kids.len();
                    // A word's bits gather in a register while the list stays in it (lists
                    // run in order), so the set is not read and written back per child.
                    let (mut at, mut word) = (usize::MAX, 0u64);
                    for &j in *kids {
                        let w = j as usize / 64;
                        if w != at {
                            if let Some(b) = bits.get_mut(at) {
                                *b |= word;
                            }
                            if w >= bits.len() {
                                bits.resize(w + 1, 0);
                            }
                            lo = lo.min(w);
                            hi = hi.max(w);
                            (at, word) = (w, 0);
                        }
                        word |= 1 << (j % 64);
                    }
                    if let Some(b) = bits.get_mut(at) {
                        *b |= word;
                    }
                }
                merged.clear();
                if let Some(words) = bits.get_mut(lo..=hi) {
                    for (w, word) in (lo..).zip(words) {
                        let mut set = std::mem::take(word);
                        while set != 0 {
                            merged.push((w * 64) as u32 + set.trailing_zeros());
                            set &= set - 1;
                        }
                    }
                }
                // One evaluation over the union only when it reads fewer children than one
                // per cell would.
                if merged.len() < separate {
                    let (d, m) =
                        whole.eval_root_subset::<F32x8, M>(merged, &self.spheres32, &[], p, grids);
                    for l in 0..8 {
                        if (done >> l) & 1 == 0 && matches!(cells[l], Some(Cell::Subset { .. })) {
                            out.0[l] = d.0[l];
                            mat[l] = m[l];
                            done |= 1 << l;
                        }
                    }
                }
            });
        }
        for i in 0..8 {
            if (done >> i) & 1 == 1 {
                continue;
            }
            let c = match cells[i] {
                None => {
                    out.0[i] = self.outside(pts[i]);
                    continue;
                }
                Some(Cell::Far {
                    bound,
                    lo,
                    hi,
                    centre_bound,
                }) => {
                    out.0[i] = Self::far_value(*bound, *centre_bound, lo, hi, pts[i]);
                    continue;
                }
                Some(c) => c,
            };
            let (d, m) = match (c, lists[i]) {
                (Cell::Program { p32, .. }, _) => p32.eval::<F32x8, M>(p, grids),
                (Cell::Subset { kids, blocks }, Some(list)) => {
                    // The cell's blocks hold its own list only.
                    let blocks = if std::ptr::eq(list, &**kids) {
                        &**blocks
                    } else {
                        &[]
                    };
                    whole.eval_root_subset::<F32x8, M>(list, &self.spheres32, blocks, p, grids)
                }
                _ => whole.eval::<F32x8, M>(p, grids),
            };
            // Every lane in the same cell reading the same children (every lane of a whole
            // cell) takes this answer.
            for l in i..8 {
                let same = cells[l].is_some_and(|o| {
                    (std::ptr::eq(o, c)
                        && lists[l].map(<[u32]>::as_ptr) == lists[i].map(<[u32]>::as_ptr))
                        || matches!((o, c), (Cell::Whole, Cell::Whole))
                });
                if same {
                    out.0[l] = d.0[l];
                    mat[l] = m[l];
                    done |= 1 << l;
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
        let e = self.finest(a);
        // A blend's finest-cell list first: one entry and one run of memory, without the
        // cell between them.
        if let Some(list) = e.and_then(|e| self.fine_list(e)) {
            return whole.eval_root_subset::<f32, M>(list, &self.spheres32, &[], v, grids);
        }
        let found = e.and_then(|e| self.cells.get(self.index[e] as usize).map(|c| (e, c)));
        match found.map(|f| f.1) {
            Some(Cell::Program { p32, .. }) => p32.eval::<f32, M>(v, grids),
            Some(Cell::Subset { kids, blocks }) => {
                let list = found.map_or(&**kids, |(e, _)| self.kids_at(e, kids));
                let blocks = if std::ptr::eq(list, &**kids) {
                    &**blocks
                } else {
                    &[]
                };
                whole.eval_root_subset::<f32, M>(list, &self.spheres32, blocks, v, grids)
            }
            Some(Cell::Whole) => whole.eval::<f32, M>(v, grids),
            _ if M => whole.eval::<f32, true>(v, grids),
            None => (self.outside(a), 0),
            Some(Cell::Far {
                bound,
                lo,
                hi,
                centre_bound,
            }) => (Self::far_value(*bound, *centre_bound, lo, hi, a), 0),
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
            Some(Cell::Program { .. } | Cell::Whole | Cell::Subset { .. }) => None,
            None => {
                let (blo, bhi) = (lo(&self.lo), lo(&self.hi));
                let d = (blo - p).max(p - bhi).max(DVec3::ZERO).length();
                Some(d + f64::from(self.pad) - slack)
            }
            Some(Cell::Far {
                bound,
                lo: l,
                hi: h,
                centre_bound,
            }) => {
                let inner = (p - lo(l)).min(lo(h) - p).min_element().max(0.0);
                let from_centre =
                    f64::from(centre_bound.abs()) - (p - 0.5 * (lo(l) + lo(h))).length();
                let b = f64::from(*bound);
                Some(
                    ((b.abs() + inner).max(from_centre) - slack)
                        .max(0.0)
                        .copysign(b),
                )
            }
        }
    }

    /// Value and material at `p` in f64 (`M`: track the material): the cell's program in
    /// program and subset cells, else `whole` (the unpruned program, so far cells answer
    /// the exact value here; [`Cells::far_bound_f64`] is their bound).
    #[inline]
    pub fn eval_f64<const M: bool>(
        &self,
        p: DVec3,
        whole: &Program<f64>,
        grids: &[Box<dyn GridSampler>],
    ) -> (f64, u32) {
        let v = V3::new(p.x, p.y, p.z);
        match self.locate(p.as_vec3().to_array()) {
            Some(Cell::Program { p64, .. }) => p64.eval::<f64, M>(v, grids),
            Some(Cell::Subset { kids, .. }) => {
                whole.eval_root_subset::<f64, M>(kids, &[], &[], v, grids)
            }
            _ => whole.eval::<f64, M>(v, grids),
        }
    }

    /// [`Program::segment`] over `[a, a + len dir]`: the cell's program when one program or
    /// subset cell holds both ends (the same values along it), else `whole`.
    #[inline]
    pub fn segment_f32(
        &self,
        a: Vec3,
        dir: Vec3,
        len: f32,
        whole: &Program<f32>,
        grids: &[Box<dyn GridSampler>],
    ) -> (f32, f32) {
        let v = |x: Vec3| V3::new(x.x, x.y, x.z);
        let (ca, cb) = (
            self.locate(a.to_array()),
            self.locate((a + dir * len).to_array()),
        );
        match (ca, cb) {
            (Some(c @ Cell::Program { p32, .. }), Some(o)) if std::ptr::eq(c, o) => {
                p32.segment(v(a), v(dir), len, grids)
            }
            (Some(c @ Cell::Subset { kids, .. }), Some(o)) if std::ptr::eq(c, o) => {
                whole.segment_root_subset(kids, v(a), v(dir), len, grids)
            }
            _ => whole.segment(v(a), v(dir), len, grids),
        }
    }
}
