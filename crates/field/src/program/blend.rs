//! The blend ([`SmoothOp::Blend`](marchmesh_scene::SmoothOp::Blend)): a smooth union of all
//! children at once, the same value whatever their order, so a point's value needs only the
//! children near it (`docs/decisions/0031-an-order-free-blend.md`).
//!
//! # The value
//! With the children's values `a_i`, their minimum `m` and the blend radius `k`, the blend is
//! the `f` with `sum_i max(0, 1 - (a_i - f) / k)^2 = 1`. Writing `b_i = a_i - m >= 0` and
//! `x = f - m + k`, that is `g(x) = sum_i max(0, x - b_i)^2 = k^2`:
//! - `g` is 0 below the least `b` (which is 0), then continuous, convex and increasing, so the
//!   root `x*` is unique and lies in `(0, k]`: `f` is at most `m` and a child `k` or more
//!   above `f` adds nothing (it can be dropped exactly);
//! - over the active children `A = {b_i < x*}`, `|A| x^2 - 2 S1 x + S2 = k^2` (`S1`, `S2` the
//!   sums of `b` and `b^2` over `A`): `x*` is its larger root;
//! - by the implicit function theorem `df/da_i = w_i / sum_j w_j` with
//!   `w_i = max(0, x* - b_i) >= 0`: the gradient is a convex combination of the children's,
//!   so the blend is 1-Lipschitz and non-decreasing in every child (interval arithmetic on it
//!   is exact at the interval's ends), and C1 (`g` is C1);
//! - `f >= m - k (1 - 1/sqrt(n))` ([`marchmesh_scene::bounds::blend_deficit`]); one child gives
//!   `f = a`, two equal children `f = a - 0.29 k` (the left fold's `smin`: `a - k/4`).
//!
//! # The solve
//! Start from `x = k` (at or above the root) with `A = {b < x}`; compute `|A|`, `S1`, `S2`
//! and the largest `b` in `A`, and the larger root `r` of `A`'s quadratic. If no `b` in `A`
//! exceeds `r`, every child of `A` is active at `r` and none outside is (they are at or above
//! `x >= r`), so `r = x*`. Otherwise `x` moves to the lower of the largest `b` (whose child is
//! then inactive: were `x* > b_max`, `A` would be exactly the active set and `r = x*`) and
//! Newton's step on `g` from `x` (never below `x*`: `g` is convex and `g(x) >= k^2`), and the
//! pass repeats with the smaller `A`. Each pass drops at least one child; near a surface of
//! the sculpted molecules a point needs 1-2 passes. After [`BLEND_PASSES`] a lane not yet
//! settled gets the lower bound `m + k / sqrt(|A|) - k` (from `|A| x*^2 >= k^2`): a safe
//! step, never above the blend.
//!
//! # Bit for bit in every evaluator
//! The sums add, in the children's stored order, `b` for the children with `b < x` and an
//! exact `+0` for the others. A child skipped (its box, or its sphere's squared distance,
//! proves it at least the threshold above `m`) or pruned away (at least `k` above the least
//! upper bound over a region) would have added `+0`: the whole program, a pruned one, a
//! region's subset of the children and the merged subsets of 8-lane queries all give the
//! same bits.

use crate::lane::{Lane, Scalar, V3};

use super::{BIG, FOLD_BLOCK, GridSampler, KidBlock, Program, msel};

/// Most values of children within `k` of the running minimum at some lane a blend keeps
/// between its passes; a blend with more evaluates its children again in each pass (the
/// same values, more slowly).
pub(crate) const BLEND_BUFFER: usize = 32;

/// Most passes of a blend's solve; each drops at least one child, so a blend of at most
/// this many children within `k` of their minimum always settles.
pub(crate) const BLEND_PASSES: usize = 24;

/// The children of node `i`: `(index, None)` in stored order.
#[derive(Clone)]
pub(crate) struct Children<'a, S> {
    prog: &'a Program<S>,
    next: usize,
    end: usize,
}

impl<'a, S: Scalar> Children<'a, S> {
    pub(crate) fn of(prog: &'a Program<S>, i: usize) -> Self {
        Children {
            prog,
            next: i + 1,
            end: prog.instrs[i].end as usize,
        }
    }
}

impl<S: Scalar> Iterator for Children<'_, S> {
    type Item = (usize, Option<[S; 4]>);
    #[inline(always)]
    fn next(&mut self) -> Option<Self::Item> {
        if self.next >= self.end {
            return None;
        }
        let j = self.next;
        self.next = self.prog.instrs[j].end as usize;
        Some((j, None))
    }
}

/// Running sums of one pass over the children with `b = a - m < x`, added in the
/// children's stored order (every evaluator adds the same values in the same order).
pub(crate) struct Sums<T> {
    m: T,
    x: T,
    count: T,
    s1: T,
    s2: T,
    most: T,
}

impl<T: Lane> Sums<T> {
    /// Adds a child's value `a` (an exact `+0` where `a - m >= x`).
    #[inline(always)]
    pub(crate) fn add(&mut self, a: T) {
        let zero = T::c(0.0);
        let b = a - self.m;
        let inside = T::lt(b, self.x);
        let bz = T::select(inside, b, zero);
        self.count = self.count + T::select(inside, T::c(1.0), zero);
        self.s1 = self.s1 + bz;
        self.s2 = self.s2 + bz * bz;
        self.most = self.most.max(bz);
    }
}

/// The blend of blend radius `k` of children whose minimum is `m`, by the solve of the
/// [module docs](self): `pass(x, sums)` adds (through [`Sums::add`]) the value of every
/// child that may lie below `m + x` at some lane, in stored order (values at or above it
/// add `+0`, so any superset gives the same bits).
#[inline(always)]
pub(crate) fn settle<T: Lane>(m: T, k: T, mut pass: impl FnMut(T, &mut Sums<T>)) -> T {
    let zero = T::c(0.0);
    let kk = k * k;
    let mut x = k;
    let mut value = m;
    let mut settled = T::lt(zero, zero);
    let mut count = T::c(1.0);
    for _ in 0..BLEND_PASSES {
        let mut s = Sums {
            m,
            x,
            count: zero,
            s1: zero,
            s2: zero,
            most: zero,
        };
        pass(x, &mut s);
        count = s.count.max(T::c(1.0));
        let disc = (s.s1 * s.s1 - s.count * (s.s2 - kk)).max(zero);
        let r = (s.s1 + disc.sqrt()) / count;
        let done = T::and(T::le(s.most, r), T::not(settled));
        value = T::select(done, m - (k - r), value);
        settled = T::or(settled, done);
        if T::all(settled) {
            return value;
        }
        // Newton's step on g from x, or the largest b (its child is inactive).
        let g = (s.count * x - s.s1 - s.s1) * x + s.s2 - kk;
        let slope = (s.count * x - s.s1) * T::c(2.0);
        let newton = x - g / slope;
        x = T::select(settled, x, newton.min(s.most));
    }
    T::select(settled, value, m - (k - k / count.sqrt()))
}

/// Most children [`Program::blend_spheres_f32`] computes once and keeps; a longer list is
/// computed again in its second pass.
const SPHERE_VALUES: usize = 64;

impl<S: Scalar> Program<S> {
    /// The blend of blend radius `k` of the children `kids` (`(node, sphere table entry)`,
    /// in stored order) at `q`, their parent's frame, and the nearest child's material when
    /// `M` (see the [module docs](self)). `kids` is read again when more than
    /// [`BLEND_BUFFER`] children come within `k` of the minimum. `blocks` is empty or
    /// [`KidBlock::table`] of exactly `kids` (f32 programs only): the same values.
    #[inline(always)]
    pub(crate) fn blend<T: Lane<S = S>, const M: bool, I>(
        &self,
        kids: I,
        blocks: &[KidBlock],
        q: V3<T>,
        k: S,
        grids: &[Box<dyn GridSampler>],
    ) -> (T, T::Mat)
    where
        I: Iterator<Item = (usize, Option<[S; 4]>)> + Clone,
    {
        let zero = T::c(0.0);
        let k = T::splat(k);
        // Pass 1: the minimum, its material, and the values that may come within `k` of it.
        let mut best = T::c(BIG);
        let mut bm = T::mat_splat(0);
        let mut kept = [zero; BLEND_BUFFER];
        let mut n = 0;
        let mut spilled = false;
        // With `blocks` (the kids' spheres eight at a time, in the same order), one vector
        // test per eight children rules out those at least `k` above every lane's running
        // value over the lanes' ball, as `sphere_no_op` rules out one.
        let ball = (!blocks.is_empty()).then(|| super::lanes_ball(q));
        let k32 = k.hmax() as f32;
        let mut near = u8::MAX;
        for (i, (j, sphere)) in kids.clone().enumerate() {
            if let Some((c, rho)) = ball {
                if i % FOLD_BLOCK == 0 {
                    // NaN when a lane's running value is not finite: nothing is ruled out.
                    let most = if best.hsum().is_finite() {
                        best.hmax() as f32
                    } else {
                        f32::NAN
                    };
                    near = blocks
                        .get(i / FOLD_BLOCK)
                        .map_or(u8::MAX, |b| b.near(c, rho, most, k32));
                }
                if (near >> (i % FOLD_BLOCK)) & 1 == 0 {
                    continue;
                }
            }
            if self.sphere_no_op(j, sphere.as_ref(), q, best, k) {
                continue;
            }
            let (d, m) = self.child_or_sphere::<T, M>(j, sphere, q, best + k, grids);
            if T::any(T::lt(d, best + k)) {
                if n < BLEND_BUFFER {
                    kept[n] = d;
                    n += 1;
                } else {
                    spilled = true;
                }
            }
            let take = T::lt(d, best);
            best = best.min(d);
            bm = msel::<T, M>(take, m, bm);
        }
        let m = best;
        let value = settle(m, k, |x, s| {
            if spilled {
                for (j, sphere) in kids.clone() {
                    if self.sphere_no_op(j, sphere.as_ref(), q, m, x) {
                        continue;
                    }
                    s.add(
                        self.child_or_sphere::<T, false>(j, sphere, q, m + x, grids)
                            .0,
                    );
                }
            } else {
                for &a in &kept[..n] {
                    s.add(a);
                }
            }
        });
        (value, bm)
    }

    /// [`Program::blend`] at one f32 point `q` of the children `kids`, when every one is a
    /// sphere of this program's [`Program::sphere_table`] `spheres` (cast to f32): their
    /// values eight at a time, the same operations as the node's (`|q + t| - r`), then the
    /// same solve over the ones within `k` of the minimum in stored order: the same bits
    /// and the nearest child's node. `None` (nothing computed that matters) when a child is
    /// not such a sphere, `q` is not finite, or more than [`BLEND_BUFFER`] children come
    /// within `k` of the minimum.
    pub(crate) fn blend_spheres_f32(
        &self,
        kids: &[u32],
        spheres: &[[S; 4]],
        q: [f32; 3],
        k: f32,
    ) -> Option<(f32, usize)> {
        const W: usize = 8;
        if !q.iter().all(|v| v.is_finite()) {
            return None;
        }
        let f = |v: S| v.to_f64() as f32;
        // A lane past the list's end: `|q| + inf`, so `+inf`, never near the minimum.
        const PAD: [f32; 4] = [0.0, 0.0, 0.0, f32::NEG_INFINITY];
        // The values of a chunk of at most eight children; `None` for a child missing from
        // the table. Every lane is read at a constant index (the chunk's length only picks
        // the padding), so the lanes are assembled in registers, not stored one by one and
        // read back as a vector (a store-forwarding stall per vector).
        let values = |chunk: &[u32]| -> Option<[f32; W]> {
            let mut e = [PAD; W];
            for (l, lane) in e.iter_mut().enumerate() {
                if let Some(&j) = chunk.get(l) {
                    *lane = spheres.get(j as usize)?.map(f);
                }
            }
            Some(std::array::from_fn(|l| {
                let (x, y, z) = (q[0] + e[l][0], q[1] + e[l][1], q[2] + e[l][2]);
                (x * x + y * y + z * z).sqrt() - e[l][3]
            }))
        };
        let mut kept = [[0.0f32; W]; SPHERE_VALUES / W];
        let mut best = [f32::INFINITY; W];
        let mut at = [0u32; W];
        let mut nan = [false; W];
        for (c, chunk) in kids.chunks(W).enumerate() {
            let d = values(chunk)?;
            for l in 0..W {
                nan[l] |= d[l].is_nan();
                let nearer = d[l] < best[l];
                best[l] = if nearer { d[l] } else { best[l] };
                at[l] = if nearer { (c * W + l) as u32 } else { at[l] };
            }
            if let Some(out) = kept.get_mut(c) {
                *out = d;
            }
        }
        // A child that is not a sphere has NaN in the table: the node computes it instead.
        if nan.contains(&true) {
            return None;
        }
        // The first child at the least value (as a fold of `d < best` takes it).
        let m = best.iter().copied().fold(f32::INFINITY, f32::min);
        let first = (0..W)
            .filter(|&l| best[l] == m)
            .map(|l| at[l] as usize)
            .min()?;
        let mut near = [0.0f32; BLEND_BUFFER];
        let mut n = 0;
        let mut note = |a: f32| {
            if a - m < k {
                if n == BLEND_BUFFER {
                    return false;
                }
                near[n] = a;
                n += 1;
            }
            true
        };
        if kids.len() <= SPHERE_VALUES {
            // The near lanes of each chunk as bits (compared eight at a time; padding lanes
            // are `+inf`), then only those read, in stored order.
            for d in &kept[..kids.len().div_ceil(W)] {
                let mut bits = 0u32;
                for (l, &a) in d.iter().enumerate() {
                    bits |= u32::from(a - m < k) << l;
                }
                while bits != 0 {
                    let l = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    if !note(d[l & (W - 1)]) {
                        return None;
                    }
                }
            }
        } else {
            for chunk in kids.chunks(W) {
                let d = values(chunk)?;
                if !d[..chunk.len()].iter().all(|&a| note(a)) {
                    return None;
                }
            }
        }
        let value = settle(m, k, |_, s| {
            for &a in &near[..n] {
                s.add(a);
            }
        });
        Some((value, *kids.get(first)? as usize))
    }
}
