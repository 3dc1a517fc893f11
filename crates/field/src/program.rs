//! The flat SDF program: nodes stored in pre-order in one `Vec`, each carrying its subtree's
//! end index, its frame transform, its distance scale and its bounding box, and the
//! interpreter that evaluates it for any [`Lane`] type.
//!
//! # Bounds and skipping
//! A node with `has_bound` stores an axis-aligned box (in its parent's frame) containing its
//! solid, and `tau` (half the box diagonal for subtrees and meshes, infinite for analytic
//! leaves, which thus stay exact everywhere). With `L` the distance to that box (`L > 0`
//! only outside it) and `c` the node's evaluated value, the parent uses
//! `g = max(L, min(c, tau))` (`min(c, tau)` inside the box), and skips evaluating `c` when
//! `L >= tau` (then `g = L`) or when `L` already proves the node cannot change the parent's
//! result (union: `L >= best so far`; smooth union: `L >= best + k`; subtracted child:
//! `L >= -first`). `g` is 1-Lipschitz, never above the true distance, and equal to `c`
//! wherever `c <= tau`; so a point far from a subtree pays only its box test and the
//! field stays continuous across the skip boundary.
//!
//! # Repetition
//! A repeat node evaluates, per repeated axis, every copy whose box (child box shifted by
//! the copy's offset) overlaps the window `[x - R, x + R]` around the point, and returns
//! `min(evaluated copies, R)`. Any copy outside the window is farther than `R` along that
//! axis, so the result is exactly `min(true distance, R)`: a 1-Lipschitz bound, exact near
//! surfaces, continuous across cell borders. `R` is half the smallest period, reduced so at
//! most [`MAX_WINDOW`] copies per axis are evaluated; a child that fits its cell needs at
//! most 3 per axis (usually 2). A child wider than `MAX_WINDOW - 1` periods (or unbounded
//! along a repeated axis) cannot get a valid window: it is evaluated over the nearest
//! `MAX_WINDOW` copies only, the result may over-estimate, and the compiler records a note.

use crate::lane::{Lane, Scalar, V3};
use marchmesh_scene::SmoothOp;

use crate::leaf::{GridList, Leaf};
use crate::shapes::{self, TriData};

pub(crate) mod blend;
pub mod segment;

/// Most copies evaluated per repeated axis: the scene's
/// [`marchmesh_scene::validate::REPEAT_WINDOW`], which its limit on nested repetitions counts.
pub const MAX_WINDOW: usize = marchmesh_scene::validate::REPEAT_WINDOW as usize;

/// An affine map `p -> lin * p + trans` (`lin` row-major, `None` = identity).
#[derive(Debug, Clone, PartialEq)]
pub struct Affine<S> {
    /// Row-major 3x3 linear part, `None` for the identity.
    pub lin: Option<[S; 9]>,
    /// Translation.
    pub trans: [S; 3],
}

impl<S: Scalar> Affine<S> {
    /// `lin * p + trans` in lane type `T`.
    #[inline(always)]
    pub(crate) fn apply<T: Lane<S = S>>(&self, p: V3<T>) -> V3<T> {
        let t = V3::<T>::splat3(self.trans);
        match &self.lin {
            None => p + t,
            Some(m) => {
                let s = |i: usize| T::splat(m[i]);
                V3::new(
                    s(0) * p.x + s(1) * p.y + s(2) * p.z,
                    s(3) * p.x + s(4) * p.y + s(5) * p.z,
                    s(6) * p.x + s(7) * p.y + s(8) * p.z,
                ) + t
            }
        }
    }

    /// The linear part alone (directions: `lin * d`).
    #[inline(always)]
    pub(crate) fn apply_linear<T: Lane<S = S>>(&self, d: V3<T>) -> V3<T> {
        match &self.lin {
            None => d,
            Some(m) => {
                let s = |i: usize| T::splat(m[i]);
                V3::new(
                    s(0) * d.x + s(1) * d.y + s(2) * d.z,
                    s(3) * d.x + s(4) * d.y + s(5) * d.z,
                    s(6) * d.x + s(7) * d.y + s(8) * d.z,
                )
            }
        }
    }
}

/// What a node computes: a leaf ([`Leaf`], its distance in `Leaf::distance`) or a
/// combinator of the nodes of its subtree.
#[derive(Debug, Clone, PartialEq)]
pub enum Op<S> {
    /// A primitive: an analytic shape or a mesh grid.
    Leaf(Leaf<S>),
    /// Minimum of the children.
    Union,
    /// Maximum of the children.
    Intersection,
    /// `max(first, -others...)`.
    Subtraction,
    /// The children folded left to right by a smooth operator ([`shapes::smin`] for a
    /// union; see [`SmoothOp`]).
    Smooth {
        /// The blended operation.
        op: SmoothOp,
        /// Blend radius.
        k: S,
        /// 1 / k.
        inv_k: S,
    },
    /// Domain repetition of the single child.
    Repeat {
        /// Period per axis (0 = not repeated).
        period: [S; 3],
        /// Copies per axis (0 = infinite).
        count: [S; 3],
        /// Offset of copy 0 per axis (`-(n-1)/2 * period`, 0 for infinite).
        first: [S; 3],
        /// Window half-width `R`.
        r: S,
    },
}

/// One node of the program.
#[derive(Debug, Clone, PartialEq)]
pub struct Instr<S> {
    /// Index one past this node's subtree.
    pub end: u32,
    /// Material of the node (for leaves, the surface material).
    pub material: u32,
    /// Whether `lo`/`hi`/`tau` are used to skip this node.
    pub has_bound: bool,
    /// Bounding box in the parent's frame (may hold infinities).
    pub lo: [S; 3],
    /// Bounding box upper corner.
    pub hi: [S; 3],
    /// Skip distance (half the box diagonal).
    pub tau: S,
    /// Parent frame -> node frame.
    pub to_local: Affine<S>,
    /// Node-frame distances times this = parent-frame bound (smallest singular value of the
    /// node-to-parent linear map; 1 for rigid transforms).
    pub dscale: S,
    /// What it computes.
    pub op: Op<S>,
}

impl Program<f32> {
    /// The normal a baked mesh stores at the surface point `p` (root's parent frame), when
    /// the surface there is a mesh grid's: the nearest child is followed down through plain
    /// unions to a mesh-grid leaf ([`Leaf::Mesh`]), whose [`GridSampler::stored_normal`] is carried back
    /// up through the nodes' frames (a gradient maps by the transpose of `to_local`'s
    /// linear part). `None` when the path meets any other operation (CSG, smooth blends,
    /// repetition, an analytic leaf) or the grid has no normal there: the caller then
    /// differentiates the field. Unit length.
    pub fn stored_normal(&self, p: [f32; 3], grids: &[Box<dyn GridSampler>]) -> Option<[f32; 3]> {
        if self.instrs.is_empty() {
            return None;
        }
        let n = self.stored_normal_at(0, V3::new(p[0], p[1], p[2]), grids)?;
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        (len > 0.0 && len.is_finite()).then(|| n.map(|c| c / len))
    }

    /// [`Program::stored_normal`] below node `i`, `p` in its parent's frame.
    fn stored_normal_at(
        &self,
        i: usize,
        p: V3<f32>,
        grids: &[Box<dyn GridSampler>],
    ) -> Option<[f32; 3]> {
        let ins = self.instrs.get(i)?;
        let q = ins.to_local.apply(p);
        let local = match &ins.op {
            Op::Leaf(Leaf::Mesh { grid }) => {
                grids.get(*grid as usize)?.stored_normal(q.x, q.y, q.z)?
            }
            Op::Union => {
                let (mut best, mut best_d) = (None, f32::INFINITY);
                let mut j = i + 1;
                while j < ins.end as usize {
                    let d = self.child::<f32, false>(j, q, Ctx::Plain, grids).0;
                    if d < best_d {
                        (best, best_d) = (Some(j), d);
                    }
                    j = self.instrs.get(j)?.end as usize;
                }
                self.stored_normal_at(best?, q, grids)?
            }
            _ => return None,
        };
        Some(match &ins.to_local.lin {
            None => local,
            // The gradient in the parent frame is lin^T times the local one (row-major).
            Some(m) => {
                [0, 1, 2].map(|c| m[c] * local[0] + m[3 + c] * local[1] + m[6 + c] * local[2])
            }
        })
    }
}

impl Instr<f64> {
    /// Makes the node read points in its parent's frame unchanged (identity transform,
    /// distance scale 1): for leaves whose parameters were already expressed in the parent
    /// frame in f64 (spheres near the camera, planes), which avoids f32 cancellation.
    pub fn evaluate_in_parent_frame(&mut self) {
        self.to_local = Affine {
            lin: None,
            trans: [0.0; 3],
        };
        self.dscale = 1.0;
    }
}

/// A mesh distance grid sampler, in the mesh's local frame.
pub trait GridSampler: Send + Sync {
    /// Signed distance at a local point (f64).
    fn sample(&self, x: f64, y: f64, z: f64) -> f64;
    /// Signed distance at a local point (f32): the f32 tracer's lookup, within the grid's
    /// own error of [`GridSampler::sample`] (it may round differently).
    fn sample_f32(&self, x: f32, y: f32, z: f32) -> f32;
    /// [`GridSampler::sample_f32`] at eight points (the lanes of an 8-wide evaluation),
    /// lane by lane the same values. Grids override it to dispatch once per eight lookups.
    fn sample_f32x8(&self, x: [f32; 8], y: [f32; 8], z: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| self.sample_f32(x[i], y[i], z[i]))
    }
    /// Exact bytes held.
    fn memory_bytes(&self) -> u64;
    /// Whether the grid stores surface normals ([`GridSampler::stored_normal`] can answer);
    /// `false` by default.
    fn stores_normals(&self) -> bool {
        false
    }
    /// The unit surface normal the grid stores near a local point (pointing to increasing
    /// distance), if it stores normals and the point is near its surface; `None` otherwise
    /// (the default).
    fn stored_normal(&self, _x: f32, _y: f32, _z: f32) -> Option<[f32; 3]> {
        None
    }
}

/// A compiled program in scalar type `S`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Program<S> {
    /// Nodes in pre-order. Node 0 is the root.
    pub instrs: Vec<Instr<S>>,
}

/// How a parent combines a child, for skipping.
#[derive(Clone, Copy)]
enum Ctx<T> {
    /// Skip only by `tau`.
    Plain,
    /// Skip also when `L >= thr` (the child cannot lower the running minimum).
    Below(T),
}

impl<T: Copy> Ctx<T> {
    /// The running threshold node `ins` inherits: a union that is combined by `min` (or a
    /// smooth minimum) one level up only has to be exact below the parent's running
    /// threshold, so it starts its own minimum there and skips its children against it too.
    /// Its result then is `min(thr, value)`, which leaves the parent's combination unchanged.
    /// Only without a distance scale, so the threshold needs no conversion.
    #[inline(always)]
    fn inherited_by<S: Scalar>(self, ins: &Instr<S>) -> Option<T> {
        match self {
            Ctx::Below(thr) if matches!(ins.op, Op::Union) && ins.dscale.to_f64() == 1.0 => {
                Some(thr)
            }
            _ => None,
        }
    }
}

const BIG: f64 = 1e30;

/// Material select, compiled away when materials are not tracked (`M = false`).
#[inline(always)]
fn msel<T: Lane, const M: bool>(m: T::Mask, a: T::Mat, b: T::Mat) -> T::Mat {
    if M { T::mat_select(m, a, b) } else { b }
}

impl<S: Scalar> Program<S> {
    /// Exact bytes of the instruction list (length times element size; boxed triangle data
    /// counted too).
    pub fn memory_bytes(&self) -> u64 {
        let tri = self
            .instrs
            .iter()
            .filter(|i| matches!(i.op, Op::Leaf(Leaf::Triangle(_))))
            .count();
        (self.instrs.len() * std::mem::size_of::<Instr<S>>()
            + tri * std::mem::size_of::<TriData<S>>()) as u64
    }

    /// Evaluates the whole program at `p` (root's parent frame): (distance, material); the
    /// material is only tracked when `M` is true (otherwise it is the root's).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn eval<T: Lane<S = S>, const M: bool>(
        &self,
        p: V3<T>,
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T::Mat) {
        if self.instrs.is_empty() {
            return (T::c(BIG), T::mat_splat(0));
        }
        self.child::<T, M>(0, p, Ctx::Plain, grids)
    }

    /// Whether the root is a smooth union or a blend, so [`Program::eval_root_subset`]
    /// applies.
    pub fn root_is_smooth_union_or_blend(&self) -> bool {
        self.instrs.first().is_some_and(|n| {
            matches!(
                n.op,
                Op::Smooth {
                    op: SmoothOp::Union | SmoothOp::Blend,
                    ..
                }
            )
        })
    }

    /// Whether the root is a blend ([`SmoothOp::Blend`]).
    pub fn root_is_blend(&self) -> bool {
        self.instrs.first().is_some_and(|n| {
            matches!(
                n.op,
                Op::Smooth {
                    op: SmoothOp::Blend,
                    ..
                }
            )
        })
    }

    /// [`Program::eval`] of the program whose root (a smooth union or a blend: see
    /// [`Program::root_is_smooth_union_or_blend`]) keeps only its children `kids` (their node
    /// indices, in fold order, at least one), each whole: bit for bit what that restricted
    /// program evaluates to, without copying it (a region's pruned cell stores 4 bytes a
    /// child). Another root is evaluated whole. `spheres` is this program's
    /// [`Program::sphere_table`] (or empty: the nodes are read instead; same values) and
    /// `blocks` is [`KidBlock::table`] of `kids` (or empty: every child is tested on its
    /// own; same values). `blocks` is read only by an f32 smooth union and only when it holds
    /// `kids` (one block per eight); otherwise the children are tested one by one.
    #[inline]
    pub fn eval_root_subset<T: Lane<S = S>, const M: bool>(
        &self,
        kids: &[u32],
        spheres: &[[S; 4]],
        blocks: &[KidBlock],
        p: V3<T>,
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T::Mat) {
        let Some(ins) = self.instrs.first() else {
            return (T::c(BIG), T::mat_splat(0));
        };
        if kids.is_empty() || !self.root_is_smooth_union_or_blend() {
            return self.eval::<T, M>(p, grids);
        }
        if !ins.has_bound {
            return self.root_subset_node::<T, M>(kids, spheres, blocks, p, grids);
        }
        // As `child` reads a bounded node.
        let zero = T::c(0.0);
        let l = shapes::box_distance(p, V3::splat3(ins.lo), V3::splat3(ins.hi));
        let tau = T::splat(ins.tau);
        let outside = T::lt(zero, l);
        let skip = T::and(outside, T::le(tau, l));
        let mat = T::mat_splat(ins.material);
        if T::all(skip) {
            return (l, mat);
        }
        let (c, m) = self.root_subset_node::<T, M>(kids, spheres, blocks, p, grids);
        let cc = c.min(tau);
        let g = T::select(outside, l.max(cc), cc);
        (T::select(skip, l, g), msel::<T, M>(skip, mat, m))
    }

    /// The root smooth union over `kids` without its bound (as `node` folds it).
    #[inline(always)]
    pub(crate) fn root_subset_node<T: Lane<S = S>, const M: bool>(
        &self,
        kids: &[u32],
        spheres: &[[S; 4]],
        blocks: &[KidBlock],
        p: V3<T>,
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T::Mat) {
        let ins = &self.instrs[0];
        let Op::Smooth { k, inv_k, op } = &ins.op else {
            return self.node::<T, M>(0, p, None, grids);
        };
        let q = ins.to_local.apply(p);
        if *op == SmoothOp::Blend {
            // One f32 point over spheres of the table: eight children at a time.
            if std::mem::size_of::<T>() == 4
                && std::mem::size_of::<S>() == 4
                && spheres.len() == self.instrs.len()
                && let Some((v, j)) = self.blend_spheres_f32(
                    kids,
                    spheres,
                    [q.x, q.y, q.z].map(|c| c.hmax() as f32),
                    k.to_f64() as f32,
                )
            {
                let v = T::splat(S::from_f64(f64::from(v)));
                let mat = if M { self.instrs[j].material } else { 0 };
                return (v * T::splat(ins.dscale), T::mat_splat(mat));
            }
            let kids = kids
                .iter()
                .map(|&j| (j as usize, spheres.get(j as usize).copied()));
            let blocks = if std::mem::size_of::<S>() == 4
                && blocks.len() == kids.len().div_ceil(FOLD_BLOCK)
            {
                blocks
            } else {
                &[]
            };
            let (v, m) = self.blend::<T, M, _>(kids, blocks, q, *k, grids);
            return (v * T::splat(ins.dscale), m);
        }
        let k = T::splat(*k);
        let inv_k = T::splat(*inv_k);
        let (mut best, mut bm) = self.child::<T, M>(kids[0] as usize, q, Ctx::Plain, grids);
        // Blocks hold f32 constants: only an f32 program reads them, and only when they
        // hold exactly `kids`.
        if std::mem::size_of::<S>() != 4 || blocks.len() != kids.len().div_ceil(FOLD_BLOCK) {
            for &j in &kids[1..] {
                let sphere = spheres.get(j as usize).copied();
                (best, bm) = self.fold_child::<T, M>(j, sphere, q, best, bm, (k, inv_k), grids);
            }
            return (best * T::splat(ins.dscale), bm);
        }
        // The lanes' bounding ball (centre `c`, radius `rho`): a block of eight kept
        // children is scanned at once against it with the lanes' largest running value,
        // and only the children it cannot rule out are tested one by one and folded.
        let (c, rho) = lanes_ball(q);
        let k32 = k.hmax() as f32;
        for (b, block) in blocks.iter().enumerate() {
            // The largest running value, NaN when a lane's is not finite (`hmax` passes
            // over NaN; `hsum` does not).
            let most = if best.hsum().is_finite() {
                best.hmax() as f32
            } else {
                f32::NAN
            };
            let mut near = block.near(c, rho, most, k32);
            if b == 0 {
                // The first child started the fold.
                near &= !1;
            }
            while near != 0 {
                let i = near.trailing_zeros() as usize;
                near &= near - 1;
                let Some(&j) = kids.get(b * FOLD_BLOCK + i) else {
                    break;
                };
                let sphere = [block.x[i], block.y[i], block.z[i], block.r[i]]
                    .map(|v| S::from_f64(f64::from(v)));
                (best, bm) =
                    self.fold_child::<T, M>(j, Some(sphere), q, best, bm, (k, inv_k), grids);
            }
        }
        (best * T::splat(ins.dscale), bm)
    }

    /// Folds child `j` of a smooth union (blend radius and its inverse `kk`) into the
    /// running value and material `(best, bm)` at `q` (the union's frame). `sphere` is the
    /// child's [`Program::sphere_table`] entry, if known (`NaN` when it is not a sphere): a
    /// sphere at least `k` above `best` at every lane is skipped, and without the material
    /// its value is computed from the entry (`shapes::sphere(q + t, r)`, as `node` computes
    /// it) instead of reading its node. The same value and material as folding the node.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn fold_child<T: Lane<S = S>, const M: bool>(
        &self,
        j: u32,
        sphere: Option<[S; 4]>,
        q: V3<T>,
        best: T,
        bm: T::Mat,
        (k, inv_k): (T, T),
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T::Mat) {
        if self.sphere_no_op(j as usize, sphere.as_ref(), q, best, k) {
            return (best, bm);
        }
        // A child at least k above the running value leaves it unchanged.
        let (d, m) = self.child_or_sphere::<T, M>(j as usize, sphere, q, best + k, grids);
        let take = T::lt(d, best);
        (shapes::smin(best, d, k, inv_k), msel::<T, M>(take, m, bm))
    }

    /// Child `j`'s value at `q` (its parent's frame) when it is below `thr` at a lane, else
    /// some value at or above `thr` there; the material when `M`. `sphere` is its
    /// [`Program::sphere_table`] entry when known (read instead of the node when the material
    /// is not needed; the same value).
    #[inline(always)]
    fn child_or_sphere<T: Lane<S = S>, const M: bool>(
        &self,
        j: usize,
        sphere: Option<[S; 4]>,
        q: V3<T>,
        thr: T,
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T::Mat) {
        match sphere {
            Some(e) if !M && !e[3].to_f64().is_nan() => (
                shapes::sphere(q + V3::<T>::splat3([e[0], e[1], e[2]]), T::splat(e[3])),
                T::mat_splat(0),
            ),
            _ => self.child::<T, M>(j, q, Ctx::Below(thr), grids),
        }
    }

    /// Per node, `[tx, ty, tz, r]` when the node is a sphere placed by a translation alone
    /// (no bound, no distance scale), whose value in its parent's frame is then
    /// `|p + t| - r` ([`shapes::sphere`]); `[NaN; 4]` for any other node. Constants are
    /// converted as [`Program::cast`] converts them, so a table of `U` matches the program
    /// cast to `U` bit for bit. Compact (16 bytes a node in f32): a fold over many children
    /// rules far spheres out from it without reading their nodes
    /// ([`Program::eval_root_subset`]).
    pub fn sphere_table<U: Scalar>(&self) -> Vec<[U; 4]> {
        let c = |v: S| U::from_f64(v.to_f64());
        self.instrs
            .iter()
            .map(|ins| match Self::sphere_entry(ins) {
                Some(e) => e.map(c),
                None => [U::from_f64(f64::NAN); 4],
            })
            .collect()
    }

    /// `[tx, ty, tz, r]` of node `ins` when it is a sphere placed by a translation alone
    /// (see [`Program::sphere_table`]).
    #[inline(always)]
    fn sphere_entry(ins: &Instr<S>) -> Option<[S; 4]> {
        match &ins.op {
            Op::Leaf(Leaf::Sphere { r })
                if !ins.has_bound && ins.to_local.lin.is_none() && ins.dscale.to_f64() == 1.0 =>
            {
                let [x, y, z] = ins.to_local.trans;
                Some([x, y, z, *r])
            }
            _ => None,
        }
    }

    /// Whether child `i` of a smooth union is a sphere ([`Program::sphere_table`]'s entry
    /// `sphere`, or the node itself when `sphere` is `None`) at least `k` above the running
    /// value `best` at every lane of `p` (the union's frame), so folding it would leave
    /// `best` and the material unchanged bit for bit (`smin` with `h = 0` returns `best`;
    /// the child is not nearer). Decided on the squared distance, without the square root
    /// the sphere's value needs, with a margin of `1e-5 (|best| + k + r)`, far above the
    /// rounding of the value's operations (about `9 eps` of the same sum), so it never skips
    /// a child the fold would read. `false` for any other child and where `best` is not
    /// finite.
    #[inline(always)]
    fn sphere_no_op<T: Lane<S = S>>(
        &self,
        i: usize,
        sphere: Option<&[S; 4]>,
        p: V3<T>,
        best: T,
        k: T,
    ) -> bool {
        match sphere {
            Some(e) => ball_far(e, p, best, k),
            None => Self::sphere_entry(&self.instrs[i]).is_some_and(|e| ball_far(&e, p, best, k)),
        }
    }

    /// The value node `i` contributes to its parent at `p` (its parent's frame), bound logic
    /// included: what the pruner ([`crate::prune`]) brackets over a region.
    pub(crate) fn node_value(&self, i: usize, p: V3<S>, grids: &[Box<dyn GridSampler>]) -> S
    where
        S: Lane<S = S>,
    {
        self.child::<S, false>(i, p, Ctx::Plain, grids).0
    }

    /// Node `i` including its bound logic, `p` in its parent's frame.
    #[inline(always)]
    fn child<T: Lane<S = S>, const M: bool>(
        &self,
        i: usize,
        p: V3<T>,
        ctx: Ctx<T>,
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T::Mat) {
        let ins = &self.instrs[i];
        let above = ctx.inherited_by(ins);
        if !ins.has_bound {
            return self.node::<T, M>(i, p, above, grids);
        }
        let zero = T::c(0.0);
        let l = shapes::box_distance(p, V3::splat3(ins.lo), V3::splat3(ins.hi));
        let tau = T::splat(ins.tau);
        let outside = T::lt(zero, l);
        let mut skip = T::and(outside, T::le(tau, l));
        if let Ctx::Below(thr) = ctx {
            skip = T::or(skip, T::and(outside, T::le(thr, l)));
        }
        let mat = T::mat_splat(ins.material);
        if T::all(skip) {
            return (l, mat);
        }
        let (c, m) = self.node::<T, M>(i, p, above, grids);
        let cc = c.min(tau);
        let g = T::select(outside, l.max(cc), cc);
        (T::select(skip, l, g), msel::<T, M>(skip, mat, m))
    }

    /// Node `i` without its bound, `p` in its parent's frame.
    fn node<T: Lane<S = S>, const M: bool>(
        &self,
        i: usize,
        p: V3<T>,
        above: Option<T>,
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T::Mat) {
        let ins = &self.instrs[i];
        let q = ins.to_local.apply(p);
        let mat = T::mat_splat(ins.material);
        let end = ins.end as usize;
        let (d, m) = match &ins.op {
            Op::Leaf(leaf) => (leaf.distance(q, GridList(grids)), mat),
            Op::Union => {
                let mut j = i + 1;
                if let Some(second) = self.nearer_second::<T>(j, end, q) {
                    // Two bounded children, the second nearer: visit it first, so the running
                    // minimum is small early and the farther child is more likely skipped
                    // (front-to-back order, as a BVH traversal visits the nearer child
                    // first). Union is order-independent: the value is the same.
                    let (mut best, mut bm) = match above {
                        Some(thr) => (thr, mat),
                        None => self.child::<T, M>(second, q, Ctx::Plain, grids),
                    };
                    for k in [second, j] {
                        if k == second && above.is_none() {
                            continue;
                        }
                        let (d, m) = self.child::<T, M>(k, q, Ctx::Below(best), grids);
                        let take = T::lt(d, best);
                        best = best.min(d);
                        bm = msel::<T, M>(take, m, bm);
                    }
                    return (best * T::splat(ins.dscale), bm);
                }
                let (mut best, mut bm) = match above {
                    Some(thr) => (thr, mat),
                    None => {
                        let first = self.child::<T, M>(j, q, Ctx::Plain, grids);
                        j = self.instrs[j].end as usize;
                        first
                    }
                };
                while j < end {
                    let (d, m) = self.child::<T, M>(j, q, Ctx::Below(best), grids);
                    let take = T::lt(d, best);
                    best = best.min(d);
                    bm = msel::<T, M>(take, m, bm);
                    j = self.instrs[j].end as usize;
                }
                (best, bm)
            }
            Op::Intersection => {
                let mut j = i + 1;
                let (mut best, mut bm) = self.child::<T, M>(j, q, Ctx::Plain, grids);
                j = self.instrs[j].end as usize;
                while j < end {
                    let (d, m) = self.child::<T, M>(j, q, Ctx::Plain, grids);
                    let take = T::lt(best, d);
                    best = best.max(d);
                    bm = msel::<T, M>(take, m, bm);
                    j = self.instrs[j].end as usize;
                }
                (best, bm)
            }
            Op::Subtraction => {
                let mut j = i + 1;
                let (mut best, mut bm) = self.child::<T, M>(j, q, Ctx::Plain, grids);
                j = self.instrs[j].end as usize;
                while j < end {
                    let (d, m) = self.subtrahend::<T, M>(j, q, best, grids);
                    let nd = -d;
                    let take = T::lt(best, nd);
                    best = best.max(nd);
                    bm = msel::<T, M>(take, m, bm);
                    j = self.instrs[j].end as usize;
                }
                (best, bm)
            }
            Op::Smooth {
                op: SmoothOp::Blend,
                k,
                ..
            } => self.blend::<T, M, _>(blend::Children::of(self, i), &[], q, *k, grids),
            Op::Smooth { op, k, inv_k } => {
                let k = T::splat(*k);
                let inv_k = T::splat(*inv_k);
                let mut j = i + 1;
                let (mut best, mut bm) = self.child::<T, M>(j, q, Ctx::Plain, grids);
                j = self.instrs[j].end as usize;
                while j < end {
                    let (m, take) = match op {
                        SmoothOp::Union => {
                            if self.sphere_no_op(j, None, q, best, k) {
                                j = self.instrs[j].end as usize;
                                continue;
                            }
                            // A child at least k above the running value leaves it unchanged.
                            let (d, m) = self.child::<T, M>(j, q, Ctx::Below(best + k), grids);
                            let take = T::lt(d, best);
                            best = shapes::smin(best, d, k, inv_k);
                            (m, take)
                        }
                        SmoothOp::Intersection => {
                            let (d, m) = self.child::<T, M>(j, q, Ctx::Plain, grids);
                            let take = T::lt(best, d);
                            best = shapes::smax(best, d, k, inv_k);
                            (m, take)
                        }
                        SmoothOp::Subtraction => {
                            // Skipped exactly when it cannot come within k of cutting.
                            let (d, m) = self.subtrahend::<T, M>(j, q, best - k, grids);
                            let nd = -d;
                            let take = T::lt(best, nd);
                            best = shapes::smax(best, nd, k, inv_k);
                            (m, take)
                        }
                        SmoothOp::Blend => unreachable!("a blend is not a fold: matched above"),
                    };
                    bm = msel::<T, M>(take, m, bm);
                    j = self.instrs[j].end as usize;
                }
                (best, bm)
            }
            Op::Repeat {
                period,
                count,
                first,
                r,
            } => self.repeat::<T, M>(i + 1, q, period, count, first, *r, grids),
        };
        (d * T::splat(ins.dscale), m)
    }

    /// For a union whose children start at `first` and end at `end`: when it has exactly two
    /// children, both bounded, and the second's box is nearer to `q` (summed over lanes),
    /// the second's index; otherwise `None` (visit in stored order). The compiler's union
    /// hierarchy ([`crate::compile`]'s median splits) is made of such pairs, so this turns its
    /// traversal front-to-back: a union of N separate objects then costs about `log N` box
    /// tests per evaluation near a surface instead of opening every box nearer than the
    /// first leaf found.
    #[inline(always)]
    fn nearer_second<T: Lane<S = S>>(&self, first: usize, end: usize, q: V3<T>) -> Option<usize> {
        let a = &self.instrs[first];
        let second = a.end as usize;
        if second >= end {
            return None;
        }
        let b = &self.instrs[second];
        if b.end as usize != end || !a.has_bound || !b.has_bound {
            return None;
        }
        let la = shapes::box_distance(q, V3::splat3(a.lo), V3::splat3(a.hi));
        let lb = shapes::box_distance(q, V3::splat3(b.lo), V3::splat3(b.hi));
        (lb.hsum() < la.hsum()).then_some(second)
    }

    /// A subtracted child: exact skip when it cannot cut into `first`.
    #[inline]
    fn subtrahend<T: Lane<S = S>, const M: bool>(
        &self,
        j: usize,
        q: V3<T>,
        first: T,
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T::Mat) {
        let ins = &self.instrs[j];
        if !ins.has_bound {
            return self.node::<T, M>(j, q, None, grids);
        }
        let zero = T::c(0.0);
        let l = shapes::box_distance(q, V3::splat3(ins.lo), V3::splat3(ins.hi));
        // Outside its box the child is >= l > 0, so -child <= -l; when -l <= first the
        // subtraction's max is `first` whatever the child's value.
        let skip = T::and(T::lt(zero, l), T::le(-first, l));
        let mat = T::mat_splat(ins.material);
        if T::all(skip) {
            return (T::c(BIG), mat);
        }
        let (c, m) = self.node::<T, M>(j, q, None, grids);
        (T::select(skip, T::c(BIG), c), m)
    }

    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn repeat<T: Lane<S = S>, const M: bool>(
        &self,
        c: usize,
        q: V3<T>,
        period: &[S; 3],
        count: &[S; 3],
        first: &[S; 3],
        r: S,
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T::Mat) {
        let ch = &self.instrs[c];
        let rr = T::splat(r);
        let qa = [q.x, q.y, q.z];
        // Per axis: first cell, last cell, number of cells to loop over.
        let mut lo_j = [T::c(0.0); 3];
        let mut hi_j = [T::c(0.0); 3];
        let mut n = [1usize; 3];
        for a in 0..3 {
            let p = period[a];
            if p.to_f64() == 0.0 {
                continue;
            }
            let pp = T::splat(p);
            let x = qa[a] - T::splat(first[a]);
            let mut jl = ((x - rr - T::splat(ch.hi[a])) / pp).ceil();
            let mut jh = ((x + rr - T::splat(ch.lo[a])) / pp).floor();
            let cnt = count[a].to_f64();
            let nearest = (x / pp + T::c(0.5)).floor();
            if cnt > 0.0 {
                let last = T::c(cnt - 1.0);
                let zero = T::c(0.0);
                let nearest = nearest.clamp(zero, last);
                jl = jl.max(zero).min(nearest);
                jh = jh.min(last).max(nearest);
            } else {
                // Non-finite windows (unbounded child) fall back to the nearest copies.
                jl = jl.max(nearest - T::c(2.0)).min(nearest);
                jh = jh.min(nearest + T::c(2.0)).max(nearest);
            }
            jh = jh.min(jl + T::c((MAX_WINDOW - 1) as f64));
            let span = (jh - jl).hmax();
            n[a] = if span.is_finite() && span >= 0.0 {
                (span as usize + 1).min(MAX_WINDOW)
            } else {
                1
            };
            lo_j[a] = jl;
            hi_j[a] = jh;
        }
        let offset = |a: usize, k: usize| -> T {
            if period[a].to_f64() == 0.0 {
                T::c(0.0)
            } else {
                let j = (lo_j[a] + T::c(k as f64)).min(hi_j[a]);
                T::splat(first[a]) + j * T::splat(period[a])
            }
        };
        let mut best = rr;
        let mut bm = T::mat_splat(ch.material);
        for kx in 0..n[0] {
            let ox = offset(0, kx);
            for ky in 0..n[1] {
                let oy = offset(1, ky);
                for kz in 0..n[2] {
                    let oz = offset(2, kz);
                    let p = V3::new(q.x - ox, q.y - oy, q.z - oz);
                    let (d, m) = self.child::<T, M>(c, p, Ctx::Below(best), grids);
                    let take = T::lt(d, best);
                    best = best.min(d);
                    bm = msel::<T, M>(take, m, bm);
                }
            }
        }
        (best, bm)
    }

    /// The same program with constants converted to another scalar type.
    pub fn cast<U: Scalar>(&self) -> Program<U> {
        let c = |v: S| U::from_f64(v.to_f64());
        let c3 = |v: [S; 3]| v.map(c);
        Program {
            instrs: self
                .instrs
                .iter()
                .map(|i| Instr {
                    end: i.end,
                    material: i.material,
                    has_bound: i.has_bound,
                    lo: c3(i.lo),
                    hi: c3(i.hi),
                    tau: c(i.tau),
                    to_local: Affine {
                        lin: i.to_local.lin.map(|m| m.map(c)),
                        trans: c3(i.to_local.trans),
                    },
                    dscale: c(i.dscale),
                    op: match &i.op {
                        Op::Leaf(leaf) => Op::Leaf(leaf.cast()),
                        Op::Union => Op::Union,
                        Op::Intersection => Op::Intersection,
                        Op::Subtraction => Op::Subtraction,
                        Op::Smooth { op, k, inv_k } => Op::Smooth {
                            op: *op,
                            k: c(*k),
                            inv_k: c(*inv_k),
                        },
                        Op::Repeat {
                            period,
                            count,
                            first,
                            r,
                        } => Op::Repeat {
                            period: c3(*period),
                            count: c3(*count),
                            first: c3(*first),
                            r: c(*r),
                        },
                    },
                })
                .collect(),
        }
    }
}

/// Children per [`KidBlock`].
pub const FOLD_BLOCK: usize = 8;

/// Eight consecutive kept children of a smooth fold as spheres, structure of arrays: the
/// `[tx, ty, tz, r]` of [`Program::sphere_table`] (the child's value in the fold's frame is
/// `|p + t| - r`), `NaN` for a child that is not a sphere (never ruled out) and an infinite
/// translation past the end of the list (always ruled out). A fold scans a block in one
/// vector operation ([`KidBlock::near`]). 128 bytes.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(32))]
pub struct KidBlock {
    /// `tx` per child.
    pub x: [f32; FOLD_BLOCK],
    /// `ty` per child.
    pub y: [f32; FOLD_BLOCK],
    /// `tz` per child.
    pub z: [f32; FOLD_BLOCK],
    /// Radius per child.
    pub r: [f32; FOLD_BLOCK],
}

impl KidBlock {
    /// The blocks of `kids` (node indices into `spheres`, an f32
    /// [`Program::sphere_table`]), eight children each in order; an index outside `spheres`
    /// counts as a child that is not a sphere.
    pub fn table(spheres: &[[f32; 4]], kids: &[u32]) -> Vec<KidBlock> {
        kids.chunks(FOLD_BLOCK)
            .map(|run| {
                let mut b = KidBlock {
                    x: [f32::INFINITY; FOLD_BLOCK],
                    y: [f32::INFINITY; FOLD_BLOCK],
                    z: [f32::INFINITY; FOLD_BLOCK],
                    r: [0.0; FOLD_BLOCK],
                };
                for (i, &j) in run.iter().enumerate() {
                    let e = spheres.get(j as usize).copied().unwrap_or([f32::NAN; 4]);
                    (b.x[i], b.y[i], b.z[i], b.r[i]) = (e[0], e[1], e[2], e[3]);
                }
                b
            })
            .collect()
    }

    /// A bit per child (bit `i` for child `i`) that may change a fold whose running value
    /// is at most `best` at every point within `rho` of `c` (the fold's frame), with blend
    /// radius `k`: a child's bit is clear only when its sphere is at least `k` above `best`
    /// over the whole ball, decided as a fold decides one child far
    /// (`|c + t|^2 > (best + k + r + rho + 1e-5 (|best| + k + r + rho))^2`, no square root),
    /// so folding it would leave the value and material bit for bit. Every bit is set when
    /// `best`, `c` or `rho` is not finite.
    #[inline(always)]
    pub fn near(&self, c: [f32; 3], rho: f32, best: f32, k: f32) -> u8 {
        if !(best.is_finite() && rho.is_finite() && c.iter().all(|v| v.is_finite())) {
            return u8::MAX;
        }
        let mut far = [false; FOLD_BLOCK];
        for i in 0..FOLD_BLOCK {
            let r = self.r[i] + rho;
            let reach = best + k + r;
            let reach = reach + 1e-5 * (best.abs() + k + r);
            let (dx, dy, dz) = (c[0] + self.x[i], c[1] + self.y[i], c[2] + self.z[i]);
            let d2 = dx * dx + dy * dy + dz * dz;
            far[i] = (0.0 < reach) & (reach * reach < d2);
        }
        let mut near = 0u8;
        for (i, f) in far.iter().enumerate() {
            near |= u8::from(!f) << i;
        }
        near
    }
}

/// The ball around a query's lanes: the centre of their box and the largest distance from
/// it (grown by a relative 1e-6 for its rounding), in f32; a lone point is its own centre
/// with radius 0. Not finite when a lane is not.
#[inline(always)]
fn lanes_ball<T: Lane>(q: V3<T>) -> ([f32; 3], f32) {
    if !(q.x.hsum() + q.y.hsum() + q.z.hsum()).is_finite() {
        return ([f32::NAN; 3], f32::NAN);
    }
    let mid = |v: T| {
        let (hi, lo) = (v.hmax(), -(-v).hmax());
        (0.5 * (hi + lo)) as f32
    };
    let c = [mid(q.x), mid(q.y), mid(q.z)];
    let d = q - V3::<T>::splat3(c.map(|v| T::S::from_f64(f64::from(v))));
    let rho = d.len2().hmax().sqrt() as f32;
    (c, rho * (1.0 + 1e-6))
}

/// Whether every point within the ball `[tx, ty, tz, r]` (centre `-t`, radius `r`: an
/// entry of [`Program::sphere_table`]) is at least `k` above the running value `best` at
/// every lane of `p`, decided on the squared distance
/// `|p + t|^2 > (best + k + r + 1e-5 (|best| + k + r))^2`. The margin is far above the
/// rounding of a sphere child's value near the threshold (about `9 eps` of the same sum), so
/// folding the sphere would leave `best` and the material bit for bit (`smin` with
/// `h = 0`). `false` where `best` is not finite or the entry is NaN.
#[inline(always)]
fn ball_far<S: Scalar, T: Lane<S = S>>(e: &[S; 4], p: V3<T>, best: T, k: T) -> bool {
    let [x, y, z, r] = *e;
    let r = T::splat(r);
    let reach = best + k + r;
    let reach = reach + T::c(1e-5) * (best.abs() + k + r);
    let q = p + V3::<T>::splat3([x, y, z]);
    T::all(T::and(
        T::lt(T::c(0.0), reach),
        T::lt(reach * reach, q.len2()),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lane::F32x8;

    /// A sphere child's value at `p` as [`Program::node`] computes it (translation, then
    /// [`shapes::sphere`]).
    fn sphere_value(e: [f32; 4], p: V3<f32>) -> f32 {
        shapes::sphere(p + V3::splat3([e[0], e[1], e[2]]), e[3])
    }

    /// Where `sphere_no_op` skips a child, folding it would have left the running value bit
    /// for bit and the material unchanged: 200,000 random spheres, running values (inside and
    /// outside) and blend radii over scales from 1e-3 to 1e3, the point placed at the skip
    /// threshold within a relative 1e-4 (about the margin). At least a quarter of them must
    /// be skipped, so the check is not vacuous.
    #[test]
    fn a_skipped_sphere_leaves_the_fold_unchanged() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let prog = Program::<f32>::default();
        let (mut skipped, cases) = (0, 200_000);
        for i in 0..cases {
            let scale = [1e-3f32, 1.0, 1e3][i % 3];
            let t = [next(), next(), next()].map(|v| (2.0 * v - 1.0) * scale);
            let r = next() * scale;
            let k = (1e-4 + 0.5 * next()) * scale;
            let best = (2.0 * next() - 1.0) * 0.5 * (r + k);
            let dir = [next(), next(), next()].map(|v| 2.0 * v - 1.0);
            let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2])
                .sqrt()
                .max(1e-6);
            let at = (best + k + r).abs() * (1.0 + (2.0 * next() - 1.0) * 1e-4);
            // The sphere's centre is `-t`; `p` lies `at` from it.
            let p = V3::new(
                -t[0] + dir[0] / n * at,
                -t[1] + dir[1] / n * at,
                -t[2] + dir[2] / n * at,
            );
            let e = [t[0], t[1], t[2], r];
            if prog.sphere_no_op::<f32>(0, Some(&e), p, best, k) {
                skipped += 1;
                let d = sphere_value(e, p);
                assert!(d >= best, "case {i}: skipped a nearer child, {d} < {best}");
                assert_eq!(
                    shapes::smin(best, d, k, 1.0 / k).to_bits(),
                    best.to_bits(),
                    "case {i}: the fold would have changed"
                );
            }
        }
        assert!(skipped > cases / 4, "only {skipped} of {cases} skipped");
    }

    /// Where [`KidBlock::near`] rules a child out, folding it would have left the running
    /// value bit for bit at every point of the ball: 20,000 random blocks of eight spheres
    /// over scales from 1e-3 to 1e3, balls of random radius, points on the ball's surface
    /// toward each sphere, the ball placed at the first sphere's threshold within a relative
    /// 1e-4. At least a quarter of the children must be ruled out (not vacuous).
    #[test]
    fn a_child_a_block_rules_out_leaves_the_fold_unchanged() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let (mut out, cases) = (0, 20_000);
        for i in 0..cases {
            let scale = [1e-3f32, 1.0, 1e3][i % 3];
            let centre = [next(), next(), next()].map(|v| (2.0 * v - 1.0) * scale);
            let spheres: Vec<[f32; 4]> = (0..FOLD_BLOCK)
                .map(|_| {
                    let mut e = [0.0; 4];
                    for a in 0..3 {
                        e[a] = -(centre[a] + (2.0 * next() - 1.0) * 0.1 * scale);
                    }
                    e[3] = next() * 0.05 * scale;
                    e
                })
                .collect();
            let kids: Vec<u32> = (0..FOLD_BLOCK as u32).collect();
            let block = KidBlock::table(&spheres, &kids)[0];
            let k = (1e-4 + 0.5 * next()) * scale;
            let rho = [0.0, next() * 0.05 * scale][i % 2];
            let best = (2.0 * next() - 1.0) * 0.5 * (spheres[0][3] + k);
            let dir = [next(), next(), next()].map(|v| 2.0 * v - 1.0);
            let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2])
                .sqrt()
                .max(1e-6);
            let e0 = spheres[0];
            let at = (best + k + e0[3] + rho).abs() * (1.0 + (2.0 * next() - 1.0) * 1e-4);
            let c: [f32; 3] = std::array::from_fn(|a| -e0[a] + dir[a] / n * at);
            let near = block.near(c, rho, best, k);
            for (j, &e) in spheres.iter().enumerate() {
                if (near >> j) & 1 == 1 {
                    continue;
                }
                out += 1;
                // The ball's point nearest the sphere, and a few others.
                let to: [f32; 3] = std::array::from_fn(|a| -e[a] - c[a]);
                let len = (to[0] * to[0] + to[1] * to[1] + to[2] * to[2]).sqrt();
                for f in [1.0f32, 0.5, 0.0, -1.0] {
                    let p = V3::new(
                        c[0] + to[0] / len * rho * f,
                        c[1] + to[1] / len * rho * f,
                        c[2] + to[2] / len * rho * f,
                    );
                    let d = sphere_value(e, p);
                    assert!(d >= best, "case {i}, sphere {j}: {d} < {best}");
                    assert_eq!(
                        shapes::smin(best, d, k, 1.0 / k).to_bits(),
                        best.to_bits(),
                        "case {i}, sphere {j}: the fold would have changed"
                    );
                }
            }
        }
        assert!(out > cases * FOLD_BLOCK / 4, "only {out} ruled out");
    }

    /// Padding past the list is always ruled out, a child that is not a sphere (or an index
    /// outside the table) never, and nothing is ruled out for a non-finite running value or
    /// ball; a lone point is its own ball.
    #[test]
    fn blocks_pad_and_keep_what_they_cannot_bound() {
        let spheres = [[0.0f32, 0.0, 0.0, 0.1], [f32::NAN; 4]];
        let blocks = KidBlock::table(&spheres, &[0, 1, 0, 7, 0, 0, 0, 0, 0]);
        assert_eq!(blocks.len(), 2);
        let far = [10.0f32, 0.0, 0.0];
        assert_eq!(blocks[0].near(far, 0.0, 0.0, 0.1), 0b0000_1010);
        assert_eq!(blocks[1].near(far, 0.0, 0.0, 0.1), 0);
        assert_eq!(blocks[1].near([0.2, 0.0, 0.0], 0.0, 0.0, 0.1), 1);
        assert_eq!(blocks[1].near(far, 9.9, 0.0, 0.1), 1);
        for bad in [f32::NAN, f32::INFINITY] {
            assert_eq!(blocks[1].near(far, 0.0, bad, 0.1), u8::MAX);
            assert_eq!(blocks[1].near(far, bad, 0.0, 0.1), u8::MAX);
            assert_eq!(blocks[1].near([bad, 0.0, 0.0], 0.0, 0.0, 0.1), u8::MAX);
        }
        assert_eq!(
            lanes_ball(V3::new(1.0f32, 2.0, 3.0)),
            ([1.0, 2.0, 3.0], 0.0)
        );
        let mut x = [0.0f32; 8];
        x[3] = 2.0;
        let (c, rho) = lanes_ball(V3::new(F32x8(x), F32x8([0.0; 8]), F32x8([0.0; 8])));
        assert_eq!(c, [1.0, 0.0, 0.0]);
        assert!((1.0..1.0001).contains(&rho));
        x[5] = f32::NAN;
        assert!(
            lanes_ball(V3::new(F32x8(x), F32x8([0.0; 8]), F32x8([0.0; 8])))
                .1
                .is_nan()
        );
    }

    /// The test above can fail: far spheres are skipped, near ones and non-finite running
    /// values are not, on every lane of an 8-lane query.
    #[test]
    fn far_spheres_are_skipped_and_near_ones_read() {
        let prog = Program::<f32>::default();
        let e = [0.0, 0.0, 0.0, 0.1];
        let (best, k) = (0.05, 0.02);
        let far = V3::new(0.2f32, 0.0, 0.0);
        let near = V3::new(0.16f32, 0.0, 0.0);
        assert!(prog.sphere_no_op::<f32>(0, Some(&e), far, best, k));
        assert!(!prog.sphere_no_op::<f32>(0, Some(&e), near, best, k));
        assert!(!prog.sphere_no_op::<f32>(0, Some(&e), far, f32::INFINITY, k));
        assert!(!prog.sphere_no_op::<f32>(0, Some(&e), far, f32::NAN, k));
        let lanes = |v: f32| {
            let mut x = [0.2f32; 8];
            x[7] = v;
            V3::new(F32x8(x), F32x8([0.0; 8]), F32x8([0.0; 8]))
        };
        let (b8, k8) = (F32x8::splat(best), F32x8::splat(k));
        assert!(prog.sphere_no_op::<F32x8>(0, Some(&e), lanes(0.3), b8, k8));
        assert!(!prog.sphere_no_op::<F32x8>(0, Some(&e), lanes(0.16), b8, k8));
        // A non-sphere entry is never skipped.
        let nan = [f32::NAN; 4];
        assert!(!prog.sphere_no_op::<f32>(0, Some(&nan), far, best, k));
    }
}
