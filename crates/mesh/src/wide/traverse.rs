//! Single-ray traversal of the wide BVH (closest hit, any hit, and a per-slot walk), the
//! prefetching of entered children, and the child ordering and leaf tests that single-ray,
//! interleaved and packet traversal share.

use std::mem::MaybeUninit;

use glam::Vec3A;
use marchmesh_core::RayWork;
use obvhs::ray::Ray;

#[cfg(target_arch = "x86_64")]
use super::avx::AvxOctant;
use super::isa::{Isa, NodeTest, block_hit_mask};
use super::layout::{BLOCK, EMPTY, LEAF, STACK, TriBlock, WIDTH, WideBvh, WideNode, leaf_range};
use super::portable::Portable;

impl WideBvh {
    /// Closest triangle along `ray` before `ray.tmax` as `(prim, t)`, `prim` a
    /// [`WideBvh::triangle`] reference (`block * 4 + lane`); shrinks `ray.tmax`. Counts one
    /// node visit per wide node and 4 primitive tests per block.
    #[inline]
    pub(crate) fn closest(&self, ray: &mut Ray, work: &mut RayWork) -> Option<(u32, f32)> {
        #[cfg(target_arch = "x86_64")]
        if self.isa != Isa::Portable {
            // SAFETY: `isa` is above `Portable` only when the CPU reports its features.
            return unsafe {
                match octant(ray) {
                    0 => self.closest_octant::<false, false, false>(ray, work),
                    1 => self.closest_octant::<true, false, false>(ray, work),
                    2 => self.closest_octant::<false, true, false>(ray, work),
                    3 => self.closest_octant::<true, true, false>(ray, work),
                    4 => self.closest_octant::<false, false, true>(ray, work),
                    5 => self.closest_octant::<true, false, true>(ray, work),
                    6 => self.closest_octant::<false, true, true>(ray, work),
                    _ => self.closest_octant::<true, true, true>(ray, work),
                }
            };
        }
        self.closest_portable(ray, work)
    }

    /// [`WideBvh::closest`] without SIMD node tests. Not inlined: its traversal stack
    /// would otherwise sit in the frame of the dispatch above, which every ray enters (a
    /// stack probe, six saved registers and their restores on the way to the AVX code).
    #[inline(never)]
    fn closest_portable(&self, ray: &mut Ray, work: &mut RayWork) -> Option<(u32, f32)> {
        match self.prefetch {
            true => self.closest_with::<Portable, true>(ray, work),
            false => self.closest_with::<Portable, false>(ray, work),
        }
    }

    /// [`WideBvh::closest`] at an AVX level for rays in one octant (see [`AvxOctant`]).
    ///
    /// # Safety
    /// `self.isa` must not be [`Isa::Portable`].
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn closest_octant<const NX: bool, const NY: bool, const NZ: bool>(
        &self,
        ray: &mut Ray,
        work: &mut RayWork,
    ) -> Option<(u32, f32)> {
        use {closest_avx as c, closest_avx512 as c512};
        type Off<const X: bool, const Y: bool, const Z: bool> = AvxOctant<X, Y, Z, false>;
        type At<const X: bool, const Y: bool, const Z: bool> = AvxOctant<X, Y, Z, true>;
        // SAFETY: the caller checked the level.
        unsafe {
            match (self.prefetch, ray.origin == Vec3A::ZERO) {
                (true, false) => {
                    by_isa!(self.isa, c, c512, ::<Off<NX, NY, NZ>, true>(self, ray, work))
                }
                (false, false) => {
                    by_isa!(self.isa, c, c512, ::<Off<NX, NY, NZ>, false>(self, ray, work))
                }
                (true, true) => {
                    by_isa!(self.isa, c, c512, ::<At<NX, NY, NZ>, true>(self, ray, work))
                }
                (false, true) => {
                    by_isa!(self.isa, c, c512, ::<At<NX, NY, NZ>, false>(self, ray, work))
                }
            }
        }
    }

    /// Whether any triangle lies along `ray` before `ray.tmax`.
    #[inline]
    pub(crate) fn any(&self, ray: &mut Ray, work: &mut RayWork) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.isa != Isa::Portable {
            // SAFETY: `isa` is above `Portable` only when the CPU reports its features.
            return unsafe {
                match octant(ray) {
                    0 => self.any_octant::<false, false, false>(ray, work),
                    1 => self.any_octant::<true, false, false>(ray, work),
                    2 => self.any_octant::<false, true, false>(ray, work),
                    3 => self.any_octant::<true, true, false>(ray, work),
                    4 => self.any_octant::<false, false, true>(ray, work),
                    5 => self.any_octant::<true, false, true>(ray, work),
                    6 => self.any_octant::<false, true, true>(ray, work),
                    _ => self.any_octant::<true, true, true>(ray, work),
                }
            };
        }
        self.any_portable(ray, work)
    }

    /// [`WideBvh::any`] without SIMD node tests, not inlined (see
    /// [`WideBvh::closest_portable`]).
    #[inline(never)]
    fn any_portable(&self, ray: &mut Ray, work: &mut RayWork) -> bool {
        match self.prefetch {
            true => self.any_with::<Portable, true>(ray, work),
            false => self.any_with::<Portable, false>(ray, work),
        }
    }

    /// [`WideBvh::any`] at an AVX level for rays in one octant (see [`AvxOctant`]).
    ///
    /// # Safety
    /// `self.isa` must not be [`Isa::Portable`].
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn any_octant<const NX: bool, const NY: bool, const NZ: bool>(
        &self,
        ray: &mut Ray,
        work: &mut RayWork,
    ) -> bool {
        use {any_avx as a, any_avx512 as a512};
        type Off<const X: bool, const Y: bool, const Z: bool> = AvxOctant<X, Y, Z, false>;
        // SAFETY: the caller checked the level.
        unsafe {
            match self.prefetch {
                true => by_isa!(self.isa, a, a512, ::<Off<NX, NY, NZ>, true>(self, ray, work)),
                false => by_isa!(self.isa, a, a512, ::<Off<NX, NY, NZ>, false>(self, ray, work)),
            }
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
    pub(super) fn closest_with<N: NodeTest, const PREFETCH: bool>(
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
    pub(super) fn any_with<N: NodeTest, const PREFETCH: bool>(
        &self,
        ray: &mut Ray,
        work: &mut RayWork,
    ) -> bool {
        let mut hit = false;
        let mut tests = 0u32;
        self.traverse::<N, true, PREFETCH>(ray, work, |ray, _, blocks| {
            for b in blocks {
                tests += BLOCK as u32;
                if block_hit_mask(b, ray).0 != 0 {
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
        // `WIDTH` spare entries: the branch-free pushes below write all 8 lanes.
        let mut stack: [MaybeUninit<(u32, f32)>; STACK + WIDTH] =
            [const { MaybeUninit::uninit() }; STACK + WIDTH];
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
                // A tree of comparisons rather than a `match`, which compiles to a jump
                // table: one indirect branch per node that the predictor often misses.
                let hits = mask.count_ones();
                if hits == 1 {
                    cur = node.child[mask.trailing_zeros() as usize];
                    continue 'walk;
                }
                if hits > 1 {
                    if ANY {
                        // The lowest entered lane is next, read from the node rather than
                        // back from the stack (no store and reload on the way to the next
                        // node). The others are pushed highest lane first, one
                        // unconditional write each, so the lowest of them is popped first:
                        // the order of `entered_children::<true>` without a branch per lane.
                        cur = node.child[mask.trailing_zeros() as usize];
                        let rest = mask & (mask - 1);
                        let mut top = sp;
                        for lane in (0..WIDTH).rev() {
                            if let Some(s) = stack.get_mut(top) {
                                s.write((node.child[lane], 0.0));
                            }
                            top += ((rest >> lane) & 1) as usize;
                        }
                        sp += hits as usize - 1;
                    } else if hits == 2 {
                        let (near, far) = two_entered(node, &dist, mask);
                        if let Some(s) = stack.get_mut(sp) {
                            s.write(far);
                            sp += 1;
                        }
                        cur = near.0;
                    } else if hits <= 4 {
                        cur = push_ranked(node, &dist, mask, hits as usize, &mut stack, &mut sp);
                    } else {
                        let near = entered_children::<ANY>(node, &dist, mask);
                        for e in near[1..hits as usize].iter().rev() {
                            // The depth limit of the conversion keeps sp < STACK.
                            if let Some(s) = stack.get_mut(sp) {
                                s.write(*e);
                                sp += 1;
                            }
                        }
                        cur = near[0].0;
                    }
                    continue 'walk;
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

/// The octant of `ray`'s direction: bit `axis` set when the direction is negative along
/// `axis` (the sign bit of the inverse direction, which is the direction's).
#[inline(always)]
fn octant(ray: &Ray) -> u32 {
    ray.inv_direction.is_negative_bitmask()
}

/// Node and block bytes from which single-ray traversal prefetches each entered child.
/// Below this size the prefetch instructions cost more than the latency they hide (measured: `docs/decisions/0013`).
pub(super) const PREFETCH_MIN_BYTES: usize = 16 << 20;

impl WideBvh {
    /// [`WideBvh::prefetch`] of every child of `node` whose lane is set in `mask`.
    #[inline(always)]
    pub(super) fn prefetch_children(&self, node: &WideNode, mut mask: u32) {
        while mask != 0 {
            self.prefetch(node.child[mask.trailing_zeros() as usize]);
            mask &= mask - 1;
        }
    }

    /// Starts loading child `c` (a node's 4 cache lines, or a leaf's first two blocks) so
    /// the misses of all children a ray enters overlap (memory-level parallelism).
    #[inline(always)]
    pub(super) fn prefetch(&self, c: u32) {
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
    unsafe fn [any_avx, any_avx512]<N: NodeTest, const PREFETCH: bool>(
        bvh: &WideBvh,
        ray: &mut Ray,
        work: &mut RayWork,
    ) -> bool {
        bvh.any_with::<N, PREFETCH>(ray, work)
    }
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
        // Most blocks hold no hit: the test's mask decides, and the lanes below `tmax`
        // then update in lane order (a later lane must be strictly nearer).
        let (mut below, t) = block_hit_mask(b, ray);
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

/// Pushes the `n` children (3 or 4) of `node` whose lanes are set in `mask` as
/// [`entered_children`] orders them (by entry distance `dist`, the lower lane first on a
/// tie), the nearest left out: returns it, and `*sp` grows by `n - 1`. Without a branch on
/// the distances or on `n`: the first four entered lanes are taken (a missing fourth as
/// distance `+inf`, so it ranks last), each one's rank is counted from the six comparisons
/// of pairs, and each is stored straight into its stack slot: the nearest (rank 0) into the
/// slot above the pushed ones, read back as the return value, a missing one above that.
#[inline(always)]
pub(super) fn push_ranked(
    node: &WideNode,
    dist: &[f32; WIDTH],
    mask: u32,
    n: usize,
    stack: &mut [MaybeUninit<(u32, f32)>],
    sp: &mut usize,
) -> u32 {
    const MAX: usize = 4;
    let mut entries = [(EMPTY, f32::INFINITY); MAX];
    let mut m = mask;
    for e in &mut entries {
        let lane = (m.trailing_zeros() as usize) & (WIDTH - 1);
        let d = if m != 0 { dist[lane] } else { f32::INFINITY };
        m &= m.wrapping_sub(1);
        *e = (node.child[lane], d);
    }
    let rank = ranks4(entries.map(|e| e.1));
    let top = *sp + n - 1;
    for i in 0..MAX {
        let r = rank[i];
        let slot = if r < n { top - r } else { top + 1 + r };
        if let Some(s) = stack.get_mut(slot) {
            s.write(entries[i]);
        }
    }
    *sp = top;
    // SAFETY: the entered lanes take ranks 0..n, so slot `top` (rank 0) was written.
    stack
        .get(top)
        .map_or(EMPTY, |s| unsafe { s.assume_init() }.0)
}

/// Each of four distances' place in their stable ascending order: `d[i]` goes after
/// `d[j]` when `d[j] < d[i]`, or on a tie when `j < i` (no NaN among them). The six pairs'
/// comparisons on SSE2 lanes: lane `i` against lane `(i + r) % 4` for `r` in 1..4, a
/// later lane counted when strictly nearer, an earlier one unless strictly further
/// (scalar comparisons compile to `setcc` and spills; measured: `docs/decisions/0027`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn ranks4(d: [f32; 4]) -> [usize; 4] {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is baseline on x86_64.
    unsafe {
        let v = _mm_loadu_ps(d.as_ptr());
        let mut rank = _mm_setzero_si128();
        // One rotation: lanes below `later` compare with a later lane (`<`), the others
        // with an earlier one (`<=`); each counted comparison is a -1 lane subtracted.
        macro_rules! rotation {
            ($imm:literal, $later:expr) => {{
                let other = _mm_shuffle_ps::<$imm>(v, v);
                let later = _mm_castsi128_ps($later);
                let before = _mm_or_ps(
                    _mm_and_ps(later, _mm_cmplt_ps(other, v)),
                    _mm_andnot_ps(later, _mm_cmple_ps(other, v)),
                );
                rank = _mm_sub_epi32(rank, _mm_castps_si128(before));
            }};
        }
        rotation!(0x39, _mm_setr_epi32(-1, -1, -1, 0)); // lane i against i + 1
        rotation!(0x4E, _mm_setr_epi32(-1, -1, 0, 0)); // i + 2
        rotation!(0x93, _mm_setr_epi32(-1, 0, 0, 0)); // i + 3
        let mut out = [0u32; 4];
        _mm_storeu_si128(out.as_mut_ptr().cast(), rank);
        out.map(|r| r as usize)
    }
}

/// [`ranks4`] off x86_64: the six comparisons one by one.
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn ranks4(d: [f32; 4]) -> [usize; 4] {
    let mut rank = [0usize; 4];
    for i in 0..4 {
        for j in i + 1..4 {
            // The later lane goes first only when strictly nearer.
            let later_first = usize::from(d[j] < d[i]);
            rank[i] += later_first;
            rank[j] += 1 - later_first;
        }
    }
    rank
}

/// The two children a ray enters (`mask` has exactly two lanes set) as `(near, far)`
/// `(child, entry distance)` pairs, in [`entered_children`]' order (the lower lane first on
/// a tie) without its loop: the most common split in closest-hit traversal (single rays
/// 1.020x on dragon_res3, interleaved rays 1.044x on the full dragon).
#[inline(always)]
pub(super) fn two_entered(
    node: &WideNode,
    dist: &[f32; WIDTH],
    mask: u32,
) -> ((u32, f32), (u32, f32)) {
    let a = mask.trailing_zeros() as usize;
    let b = (mask & (mask - 1)).trailing_zeros() as usize;
    let (near, far) = if dist[b] < dist[a] { (b, a) } else { (a, b) };
    ((node.child[near], dist[near]), (node.child[far], dist[far]))
}

#[cfg(test)]
mod tests {
    use glam::Vec3A;
    use marchmesh_core::RayWork;
    use obvhs::ray::Ray;

    use crate::wide::Isa;
    use crate::wide::test_util::{lcg, wide_of_random};

    #[test]
    fn ranked_pushes_keep_the_insertion_sort_order() {
        // Every mask of 3 or 4 entered lanes, with distances drawn from a few values
        // (ties, and a zero of either sign) and from random ones: the pushed children,
        // popped, come in `entered_children`' order, the nearest returned first.
        use std::mem::MaybeUninit;

        use super::{entered_children, push_ranked};
        use crate::wide::layout::{EMPTY_NODE, STACK, WIDTH};
        let mut node = EMPTY_NODE;
        for lane in 0..WIDTH {
            node.child[lane] = 100 + lane as u32;
        }
        let few = [0.5f32, -0.0, 0.0, 0.5, 2.0, -1.0];
        let mut s = 71u64;
        let mut checked = 0;
        for mask in 0u32..256 {
            let n = mask.count_ones() as usize;
            if !(3..=4).contains(&n) {
                continue;
            }
            for round in 0..64 {
                let dist: [f32; WIDTH] = std::array::from_fn(|_| match round % 2 {
                    0 => few[(lcg(&mut s) * few.len() as f32) as usize % few.len()],
                    _ => lcg(&mut s) * 4.0 - 1.0,
                });
                let expected = entered_children::<false>(&node, &dist, mask);
                let mut stack = [const { MaybeUninit::uninit() }; STACK + WIDTH];
                let mut sp = 3;
                let first = push_ranked(&node, &dist, mask, n, &mut stack, &mut sp);
                assert_eq!(sp, 3 + n - 1);
                let mut order = vec![first];
                while sp > 3 {
                    sp -= 1;
                    // SAFETY: the entries from 3 to `sp` were written by the push.
                    order.push(unsafe { stack[sp].assume_init() }.0);
                }
                let want: Vec<u32> = expected[..n].iter().map(|e| e.0).collect();
                assert_eq!(order, want, "mask {mask:08b}, distances {dist:?}");
                checked += 1;
            }
        }
        assert_eq!(checked, (56 + 70) * 64);
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
}
