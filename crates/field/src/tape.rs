//! Straight-line evaluation of small programs: a union of leaves (analytic shapes and mesh
//! grids; or one leaf),
//! the shape of every scene of a few objects and of most bundles after [`crate::cull`].
//!
//! The interpreter ([`Program::eval`]) walks the pre-order node list recursively, passing
//! the point and returning a (distance, material) pair through every level, and tests each
//! node's bound flag, context and operator; for a 5-object scene that bookkeeping cost about
//! 1100 instructions per 8-lane evaluation (callgrind, `seed-slab`), several times the
//! arithmetic. A [`Tape`] is the same program flattened once into a list of leaves under
//! one root: evaluation is one loop over the leaves with a running minimum, and it runs
//! exactly the interpreter's arithmetic in the interpreter's order (the root's bound, the
//! nearer-first order of a two-member union, each bounded leaf's skip against the running
//! minimum), so its values are bit for bit [`Program::eval`]'s: the unit tests below compare
//! them on random points.

use glam::Vec3;

use crate::dual::{Dual1, Dual8};
use crate::lane::{F32x8, Lane, V3};
use crate::leaf::{GridList, GridSource, Leaf, NoGrids};
use crate::program::segment::{bounded_step, fallback, leaf_lambda, leaf_step};
use crate::program::{Affine, GridSampler, Instr, Op, Program};
use crate::recede;
use crate::shapes;

/// A node's bound as the interpreter uses it (`Instr::has_bound`): its box and skip
/// distance.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Bound {
    pub(crate) lo: [f32; 3],
    pub(crate) hi: [f32; 3],
    pub(crate) tau: f32,
}

impl Bound {
    fn of(ins: &Instr<f32>) -> Option<Bound> {
        ins.has_bound.then_some(Bound {
            lo: ins.lo,
            hi: ins.hi,
            tau: ins.tau,
        })
    }
}

/// One leaf (an analytic shape or a mesh grid) with its frame, distance scale and
/// (optional) bound.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TapeLeaf {
    pub(crate) to_local: Affine<f32>,
    pub(crate) dscale: f32,
    pub(crate) bound: Option<Bound>,
    /// The node's box in its parent's frame (every node carries one, also where `bound`
    /// is off because testing it costs more than the leaf): [`Tape::recedes`] uses it.
    bbox: ([f32; 3], [f32; 3]),
    material: u32,
    pub(crate) shape: Leaf<f32>,
}

/// The root union's own frame and bound.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Root {
    pub(crate) to_local: Affine<f32>,
    pub(crate) dscale: f32,
    pub(crate) bound: Option<Bound>,
    material: u32,
    /// Two members, both bounded: the interpreter visits the nearer one first
    /// (`Program::nearer_second`), which decides the second one's skip.
    pub(crate) pair: bool,
}

/// A program flattened to a union of leaves, see the [module docs](self).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Tape {
    /// `None`: the program is the single leaf `leaves[0]`.
    pub(crate) root: Option<Root>,
    pub(crate) leaves: Vec<TapeLeaf>,
    /// Whether a leaf is a mesh grid (evaluations then take the grid list).
    pub(crate) has_mesh: bool,
}

/// Whether `op` is a leaf the tape evaluates: every analytic primitive and mesh grids
/// (sampled through the grid list the tape's evaluations are given).
pub(crate) fn tape_leaf(op: &Op<f32>) -> bool {
    matches!(op, Op::Leaf(_))
}

/// The tape's copy of leaf node `ins` (an [`Op::Leaf`]); `None` for another node.
fn leaf(ins: &Instr<f32>) -> Option<TapeLeaf> {
    let Op::Leaf(shape) = &ins.op else {
        return None;
    };
    Some(TapeLeaf {
        to_local: ins.to_local.clone(),
        dscale: ins.dscale,
        bound: Bound::of(ins),
        bbox: (ins.lo, ins.hi),
        material: ins.material,
        shape: shape.clone(),
    })
}

impl Tape {
    /// Most leaves a tape holds. Compiled fields never have a flat union of more than
    /// [`crate::compile::GROUP`] members below a root (larger unions get a hierarchy), so
    /// this bounds the restrictions of [`crate::cull`], whose kept leaves are flattened: on
    /// 10000 separate spheres (`primary_rays` example, 256x256, row bundles of 32 rays, up
    /// to 47 leaves kept) a flat loop over them took 2.3x fewer instructions per image than
    /// the interpreter on the kept hierarchy (callgrind: 4057M -> 1790M, 1000 spheres 1318M
    /// -> 853M); 16 recovered only 5% at 10000 spheres and 128 changed nothing.
    pub const MAX_LEAVES: usize = 64;

    /// The tape of `prog` when it is one leaf (an analytic shape or a mesh grid) or a union
    /// (not a nested one) of at most [`Tape::MAX_LEAVES`] such leaves; `None` otherwise (the
    /// interpreter serves it).
    pub fn of(prog: &Program<f32>) -> Option<Tape> {
        let mut t = Tape::default();
        t.rebuild(prog).then_some(t)
    }

    /// [`Tape::of`] into `self`, reusing its buffer; false (and `self` unusable) when the
    /// program has another shape.
    pub fn rebuild(&mut self, prog: &Program<f32>) -> bool {
        self.leaves.clear();
        self.root = None;
        let Some(first) = prog.instrs.first() else {
            return false;
        };
        if let Some(only) = leaf(first) {
            if prog.instrs.len() != 1 {
                return false;
            }
            self.has_mesh = matches!(only.shape, Leaf::Mesh { .. });
            self.leaves.push(only);
            return true;
        }
        if !matches!(first.op, Op::Union) || first.end as usize != prog.instrs.len() {
            return false;
        }
        let n = prog.instrs.len() - 1;
        if n == 0 || n > Self::MAX_LEAVES {
            return false;
        }
        // Every node after the root must be a leaf of it (its subtree is itself).
        for (k, ins) in prog.instrs[1..].iter().enumerate() {
            match leaf(ins) {
                Some(l) if ins.end as usize == k + 2 => self.leaves.push(l),
                _ => return false,
            }
        }
        self.root = Some(Root {
            to_local: first.to_local.clone(),
            dscale: first.dscale,
            bound: Bound::of(first),
            material: first.material,
            pair: n == 2 && self.leaves.iter().all(|l| l.bound.is_some()),
        });
        self.has_mesh = self
            .leaves
            .iter()
            .any(|l| matches!(l.shape, Leaf::Mesh { .. }));
        true
    }

    /// Leaves on the tape.
    pub fn len(&self) -> usize {
        self.leaves.len()
    }

    /// Whether the tape holds no leaf (never true for a tape [`Tape::of`] returned).
    pub fn is_empty(&self) -> bool {
        self.leaves.is_empty()
    }

    /// The value of the program at `p` (and the material when `M`), bit for bit
    /// [`Program::eval`]'s with the same `grids` (the field's mesh grids, indexed by the
    /// program's [`Leaf::Mesh`] leaves; panics on an index past them, as the interpreter).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn eval<T: Lane<S = f32>, const M: bool>(
        &self,
        p: V3<T>,
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T::Mat) {
        if self.has_mesh {
            self.eval_in::<T, M, _>(p, GridList(grids))
        } else {
            self.eval_in::<T, M, _>(p, NoGrids)
        }
    }

    /// [`Tape::eval`] with mesh leaves sampled from `grids`.
    #[inline(always)]
    fn eval_in<T: Lane<S = f32>, const M: bool, G: GridSource>(
        &self,
        p: V3<T>,
        grids: G,
    ) -> (T, T::Mat) {
        match &self.root {
            None => bounded::<T, M, G>(&self.leaves[0], p, None, grids),
            Some(root) => match &root.bound {
                None => self.union::<T, M, G>(root, p, grids),
                Some(b) => {
                    let zero = T::c(0.0);
                    let l = shapes::box_distance(p, V3::splat3(b.lo), V3::splat3(b.hi));
                    let tau = T::splat(b.tau);
                    let outside = T::lt(zero, l);
                    let skip = T::and(outside, T::le(tau, l));
                    let mat = T::mat_splat(root.material);
                    if T::all(skip) {
                        return (l, mat);
                    }
                    let (c, m) = self.union::<T, M, G>(root, p, grids);
                    let cc = c.min(tau);
                    let g = T::select(outside, l.max(cc), cc);
                    (T::select(skip, l, g), msel::<T, M>(skip, mat, m))
                }
            },
        }
    }

    /// Per lane the value and a segment-tracing safe step along `d` over `len`, bit for bit
    /// [`Program::segment`]'s on the program the tape was built from (the same formulas in
    /// the same order; the union's members in the program's order, where [`Tape::eval`]
    /// visits a pair nearer first: a member's skip decides its step). What lockstep bundles
    /// use for their segment-tracing lanes instead of one interpreter call per lane.
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn segment<T: Lane<S = f32>>(
        &self,
        p: V3<T>,
        d: V3<T>,
        len: T,
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T) {
        if self.has_mesh {
            self.segment_in(p, d, len, GridList(grids))
        } else {
            self.segment_in(p, d, len, NoGrids)
        }
    }

    /// [`Tape::segment`] with mesh leaves sampled from `grids`.
    #[inline(always)]
    fn segment_in<T: Lane<S = f32>, G: GridSource>(
        &self,
        p: V3<T>,
        d: V3<T>,
        len: T,
        grids: G,
    ) -> (T, T) {
        let (v, s) = match &self.root {
            None => seg_bounded(&self.leaves[0], p, d, len, None, grids),
            Some(root) => {
                let union = || self.seg_union(root, p, d, len, grids);
                match &root.bound {
                    None => union(),
                    Some(b) => bounded_step((b.lo, b.hi, b.tau), None, p, d, union),
                }
            }
        };
        (v, s.max(fallback(v, d)))
    }

    /// The root union's value and safe step (without its own bound), `p` and `d` in the
    /// root's parent frame: every member must stay positive, so the smallest member step.
    #[inline(always)]
    fn seg_union<T: Lane<S = f32>, G: GridSource>(
        &self,
        root: &Root,
        p: V3<T>,
        d: V3<T>,
        len: T,
        grids: G,
    ) -> (T, T) {
        let q = root.to_local.apply(p);
        let dl = root.to_local.apply_linear(d);
        let (mut best, mut step) = seg_bounded(&self.leaves[0], q, dl, len, None, grids);
        for l in &self.leaves[1..] {
            let (v, s) = seg_bounded(l, q, dl, len, Some(best), grids);
            best = best.min(v);
            step = step.min(s);
        }
        let v = best * T::splat(root.dscale);
        (v, T::select(T::lt(T::c(0.0), v), step, fallback(v, d)))
    }

    /// Whether the ray from `p` along `d` (no unit length needed) can meet no leaf of the
    /// tape any more. A leaf is left behind when
    /// - it is convex (sphere, plane, box, ellipsoid bound, capped cylinder) and its value
    ///   grows along `d` at `p`: the distance to a convex set is a convex function along a
    ///   line, so from a point where it grows it never shrinks again, and a value that is
    ///   positive there never reaches 0; or
    /// - the ray misses the leaf's bounding box from `p` on.
    ///
    /// Conservative: a torus, triangle or mesh grid whose box the ray still meets (an
    /// unbounded mesh grid always), a point on or in a convex leaf, or a ray within about
    /// 0.006 degree of tangency answers false. Used to end
    /// rays receding from everything (shadow rays climbing away from a ground, rays that
    /// passed every object) instead of marching them to the end of their range.
    pub fn recedes(&self, p: Vec3, d: Vec3) -> bool {
        let (p, d) = (V3::new(p.x, p.y, p.z), V3::new(d.x, d.y, d.z));
        let (q, dq) = match &self.root {
            None => (p, d),
            Some(root) => (root.to_local.apply(p), root.to_local.apply_linear(d)),
        };
        let inv = recede::recip(dq);
        self.leaves.iter().all(|l| leaf_recedes(l, q, dq, inv))
    }

    /// Per lane, the analytic gradient of the leaf nearest to the point: the leaf whose value
    /// the union's running minimum takes last (as [`Tape::eval`] picks materials), then
    /// that leaf's distance alone differentiated through the root's frame ([`Dual8`] once
    /// for all lanes nearest one leaf when they are two or more, [`Dual1`] otherwise: the
    /// same bits either way).
    /// This is the gradient of the surface a hit lies on, at the cost of one 8-lane
    /// evaluation and one leaf per lane, where a [`crate::dual::Dual8`] evaluation of a
    /// long tape differentiates every leaf. It ignores the bounds (a point outside the
    /// root's box, or past a bounded leaf's skip distance, gets the leaf's own gradient
    /// rather than the box distance's), so it is for points on or near a surface. A mesh
    /// grid has no derivative: the lanes nearest one get NaN.
    pub fn nearest_gradients(&self, p: V3<F32x8>, grids: &[Box<dyn GridSampler>]) -> [Vec3; 8] {
        let nearest = if self.has_mesh {
            self.nearest::<F32x8, _>(p, GridList(grids))
        } else {
            self.nearest::<F32x8, _>(p, NoGrids)
        };
        // Each leaf nearest to two lanes or more is differentiated once in all eight
        // lanes ([`Dual8`]: per lane [`Dual1`]'s operations, so the same bits as
        // [`Tape::leaf_gradient`]); the 8 hits of a batch mostly lie on one or two
        // surfaces. A leaf nearest to one lane alone takes the scalar [`Dual1`].
        let mut out = [Vec3::ZERO; 8];
        let mut todo: u32 = 0xff;
        while todo != 0 {
            let first = todo.trailing_zeros() as usize;
            let k = nearest[first];
            let mut lanes = 0u32;
            for (i, &n) in nearest.iter().enumerate() {
                if n == k {
                    lanes |= 1 << i;
                }
            }
            let lanes = lanes & todo;
            todo &= !lanes;
            if lanes.count_ones() < 2 {
                out[first] = self.leaf_gradient(k, lane_point(p, first));
                continue;
            }
            let g = self.leaf_gradients(k, p);
            for (i, o) in out.iter_mut().enumerate() {
                if lanes & (1 << i) != 0 {
                    *o = g[i];
                }
            }
        }
        out
    }

    /// [`Tape::nearest_gradients`] at one point (bit for bit a lane's result: the same
    /// operations per lane).
    pub fn nearest_gradient(&self, p: Vec3, grids: &[Box<dyn GridSampler>]) -> Vec3 {
        let q = V3::new(p.x, p.y, p.z);
        let nearest = if self.has_mesh {
            self.nearest::<f32, _>(q, GridList(grids))
        } else {
            self.nearest::<f32, _>(q, NoGrids)
        };
        self.leaf_gradient(nearest, p)
    }

    /// Per lane the index of the leaf the union's running minimum takes last.
    #[inline(always)]
    fn nearest<T: Lane<S = f32>, G: GridSource>(&self, p: V3<T>, grids: G) -> T::Mat {
        match &self.root {
            None => T::mat_splat(0),
            Some(root) => {
                let q = root.to_local.apply(p);
                let (mut best, _) = bounded::<T, false, G>(&self.leaves[0], q, None, grids);
                let mut at = T::mat_splat(0);
                for (k, l) in self.leaves.iter().enumerate().skip(1) {
                    let (d, _) = bounded::<T, false, G>(l, q, Some(best), grids);
                    let take = T::lt(d, best);
                    best = best.min(d);
                    at = T::mat_select(take, T::mat_splat(k as u32), at);
                }
                at
            }
        }
    }

    /// The analytic gradient of leaf `k`'s distance alone at `p` (through the root's frame).
    fn leaf_gradient(&self, k: u32, p: Vec3) -> Vec3 {
        let leaf = &self.leaves[k as usize];
        if matches!(leaf.shape, Leaf::Mesh { .. }) {
            // Sampled without a derivative: no need to sample it.
            return Vec3::NAN;
        }
        let x = Dual1::seed(V3::new(p.x, p.y, p.z));
        let d = match &self.root {
            None => value(leaf, x, NoGrids),
            Some(root) => value(leaf, root.to_local.apply(x), NoGrids) * Dual1::splat(root.dscale),
        };
        Vec3::new(d.d.x, d.d.y, d.d.z)
    }

    /// [`Tape::leaf_gradient`] of leaf `k` at eight points at once, bit for bit.
    fn leaf_gradients(&self, k: u32, p: V3<F32x8>) -> [Vec3; 8] {
        let leaf = &self.leaves[k as usize];
        if matches!(leaf.shape, Leaf::Mesh { .. }) {
            return [Vec3::NAN; 8];
        }
        let x = Dual8::seed(p);
        let d = match &self.root {
            None => value(leaf, x, NoGrids),
            Some(root) => value(leaf, root.to_local.apply(x), NoGrids) * Dual8::splat(root.dscale),
        };
        std::array::from_fn(|i| Vec3::new(d.d.x.0[i], d.d.y.0[i], d.d.z.0[i]))
    }

    /// The root union's value (without its own bound), `p` in the root's parent frame.
    #[inline(always)]
    fn union<T: Lane<S = f32>, const M: bool, G: GridSource>(
        &self,
        root: &Root,
        p: V3<T>,
        grids: G,
    ) -> (T, T::Mat) {
        let q = root.to_local.apply(p);
        let ds = T::splat(root.dscale);
        if root.pair {
            let (a, b) = (&self.leaves[0], &self.leaves[1]);
            let (ba, bb) = (bound_of(a), bound_of(b));
            let la = shapes::box_distance(q, V3::splat3(ba.lo), V3::splat3(ba.hi));
            let lb = shapes::box_distance(q, V3::splat3(bb.lo), V3::splat3(bb.hi));
            let (first, second) = if lb.hsum() < la.hsum() {
                (b, a)
            } else {
                (a, b)
            };
            let (best, bm) = bounded::<T, M, G>(first, q, None, grids);
            let (d, m) = bounded::<T, M, G>(second, q, Some(best), grids);
            let take = T::lt(d, best);
            return (best.min(d) * ds, msel::<T, M>(take, m, bm));
        }
        let (mut best, mut bm) = bounded::<T, M, G>(&self.leaves[0], q, None, grids);
        for l in &self.leaves[1..] {
            let (d, m) = bounded::<T, M, G>(l, q, Some(best), grids);
            let take = T::lt(d, best);
            best = best.min(d);
            bm = msel::<T, M>(take, m, bm);
        }
        (best * ds, bm)
    }
}

/// Lane `k` of `p`.
fn lane_point(p: V3<F32x8>, k: usize) -> Vec3 {
    Vec3::new(p.x.0[k], p.y.0[k], p.z.0[k])
}

fn bound_of(l: &TapeLeaf) -> &Bound {
    l.bound
        .as_ref()
        .expect("a pair union's members are bounded (checked when built)")
}

/// Material select, compiled away when materials are not tracked (as the interpreter's).
#[inline(always)]
fn msel<T: Lane, const M: bool>(m: T::Mask, a: T::Mat, b: T::Mat) -> T::Mat {
    if M { T::mat_select(m, a, b) } else { b }
}

/// A leaf with its bound logic (`Program::child`), `below` the running minimum it is
/// skipped against (`Ctx::Below`), `p` in its parent's frame.
#[inline(always)]
pub(crate) fn bounded<T: Lane<S = f32>, const M: bool, G: GridSource>(
    leaf: &TapeLeaf,
    p: V3<T>,
    below: Option<T>,
    grids: G,
) -> (T, T::Mat) {
    let mat = T::mat_splat(leaf.material);
    let Some(b) = &leaf.bound else {
        return (value(leaf, p, grids), mat);
    };
    let zero = T::c(0.0);
    let l = shapes::box_distance(p, V3::splat3(b.lo), V3::splat3(b.hi));
    let tau = T::splat(b.tau);
    let outside = T::lt(zero, l);
    let mut skip = T::and(outside, T::le(tau, l));
    if let Some(thr) = below {
        skip = T::or(skip, T::and(outside, T::le(thr, l)));
    }
    if T::all(skip) {
        return (l, mat);
    }
    let c = value(leaf, p, grids);
    let cc = c.min(tau);
    let g = T::select(outside, l.max(cc), cc);
    (T::select(skip, l, g), mat)
}

/// [`bounded`] with a safe step (`Program::seg_child` of a leaf).
#[inline(always)]
fn seg_bounded<T: Lane<S = f32>, G: GridSource>(
    leaf: &TapeLeaf,
    p: V3<T>,
    d: V3<T>,
    len: T,
    below: Option<T>,
    grids: G,
) -> (T, T) {
    let node = || {
        let v = value(leaf, p, grids);
        let dl = leaf.to_local.apply_linear(d);
        match leaf_lambda(&leaf.shape, || leaf.to_local.apply(p), dl, len) {
            Some(lambda) => (v, leaf_step(v, lambda, dl.len(), len, d)),
            None => (v, fallback(v, d)),
        }
    };
    match &leaf.bound {
        None => node(),
        Some(b) => bounded_step((b.lo, b.hi, b.tau), below, p, d, node),
    }
}

/// A leaf's value (`Program::node` for a leaf), `p` in its parent's frame.
#[inline(always)]
fn value<T: Lane<S = f32>, G: GridSource>(leaf: &TapeLeaf, p: V3<T>, grids: G) -> T {
    let q = leaf.to_local.apply(p);
    let d = leaf.shape.distance(q, grids);
    d * T::splat(leaf.dscale)
}

/// [`Tape::recedes`] for one leaf, `q` and `dq` in the leaf's parent frame (`inv` the
/// reciprocals of `dq`'s components).
fn leaf_recedes(l: &TapeLeaf, q: V3<f32>, dq: V3<f32>, inv: V3<f32>) -> bool {
    // A mesh grid's zero set keeps to its mesh's box only while the leaf's bound keeps the
    // value outside the box at least the box distance; unbounded (`Field::without_bounds`),
    // quantisation or an open mesh's sign can put it a little outside.
    if matches!(l.shape, Leaf::Mesh { .. }) && l.bound.is_none() {
        return false;
    }
    let (lq, ld) = (l.to_local.apply(q), l.to_local.apply_linear(dq));
    // The gradient direction of a convex leaf's value at `lq` (`None`: not convex, or the
    // point is inside where the direction is not the outward one).
    let outward = l.shape.outward(lq);
    if let Some(g) = outward {
        // Growing, by more than rounding can fake: cos(angle to the surface) > 1e-4.
        let along = g.dot(ld);
        if along > 0.0 && along * along > 1e-8 * g.len2() * ld.len2() {
            return true;
        }
    }
    recede::misses_box(q, dq, inv, l.bbox)
}
