//! Batches of single rays traced in turns through the wide BVH, so the cache misses of
//! independent rays overlap.

use std::mem::MaybeUninit;

#[cfg(target_arch = "x86_64")]
use glam::Vec3A;
use marchmesh_core::RayWork;
use obvhs::ray::Ray;

#[cfg(target_arch = "x86_64")]
use super::avx::{Avx, AvxAtOrigin};
use super::isa::{Isa, NodeTest};
use super::layout::{EMPTY, LEAF, STACK, WIDTH, WideBvh, leaf_range};
use super::portable::Portable;
use super::traverse::{closest_in_blocks, entered_children, push_ranked, two_entered};

/// Rays traced together by [`WideBvh::closest_interleaved`].
pub(crate) const INTERLEAVE: usize = 8;

impl WideBvh {
    /// Closest hits of `INTERLEAVE` independent rays, each exactly as [`WideBvh::closest`]
    /// would find it (same visiting order, so the same hit even on ties), traced in turns:
    /// each ray takes one step (a node or a leaf), prefetches what it will read next, and
    /// hands over to the next ray, so the cache misses of different rays overlap instead
    /// of each ray waiting out its own (software pipelining of independent traversals; on
    /// a mesh far larger than the caches a ray is bound by the latency of its dependent
    /// node and block loads). Adds each ray's work to `work[k]`.
    pub(crate) fn closest_interleaved(
        &self,
        rays: &mut [Ray; INTERLEAVE],
        work: &mut [RayWork; INTERLEAVE],
    ) -> [Option<(u32, f32)>; INTERLEAVE] {
        #[cfg(target_arch = "x86_64")]
        if self.isa != Isa::Portable {
            // SAFETY: `isa` is above `Portable` only when the CPU reports its features.
            return unsafe {
                use {interleaved_avx as i, interleaved_avx512 as i512};
                match rays.iter().all(|r| r.origin == Vec3A::ZERO) {
                    true => by_isa!(self.isa, i, i512, ::<AvxAtOrigin>(self, rays, work)),
                    false => by_isa!(self.isa, i, i512, ::<Avx>(self, rays, work)),
                }
            };
        }
        self.interleaved_with::<Portable>(rays, work)
    }

    #[inline(always)]
    fn interleaved_with<N: NodeTest>(
        &self,
        rays: &mut [Ray; INTERLEAVE],
        work: &mut [RayWork; INTERLEAVE],
    ) -> [Option<(u32, f32)>; INTERLEAVE] {
        let mut best = [None; INTERLEAVE];
        if self.root == EMPTY {
            return best;
        }
        // `WIDTH` spare entries per stack, as in single-ray traversal (`push_ranked`).
        let mut stacks: [[MaybeUninit<(u32, f32)>; STACK + WIDTH]; INTERLEAVE] =
            [const { [const { MaybeUninit::uninit() }; STACK + WIDTH] }; INTERLEAVE];
        let mut sps = [0usize; INTERLEAVE];
        let mut curs = [self.root; INTERLEAVE];
        let mut visits = [0u32; INTERLEAVE];
        let mut tests = [0u32; INTERLEAVE];
        let mut active: u32 = (1 << INTERLEAVE) - 1;
        while active != 0 {
            let mut pending = active;
            while pending != 0 {
                let k = pending.trailing_zeros() as usize;
                pending &= pending - 1;
                let ray = &mut rays[k];
                let stack = &mut stacks[k];
                let sp = &mut sps[k];
                let cur = curs[k];
                // One step of `traverse` (closest-hit mode) for ray k.
                if cur & LEAF != 0 {
                    let (first, count) = leaf_range(cur);
                    if let Some(blocks) = self.blocks.get(first..first + count) {
                        tests[k] += closest_in_blocks(first, blocks, ray, &mut best[k]);
                    }
                } else if let Some(node) = self.nodes.get(cur as usize) {
                    visits[k] += 1;
                    let (mask, dist) = N::test(node, ray);
                    self.prefetch_children(node, mask);
                    match mask.count_ones() {
                        0 => {}
                        1 => {
                            curs[k] = node.child[mask.trailing_zeros() as usize];
                            continue;
                        }
                        2 => {
                            let (near, far) = two_entered(node, &dist, mask);
                            if let Some(s) = stack.get_mut(*sp) {
                                s.write(far);
                                *sp += 1;
                            }
                            curs[k] = near.0;
                            continue;
                        }
                        hits @ 3..=4 => {
                            curs[k] = push_ranked(node, &dist, mask, hits as usize, stack, sp);
                            continue;
                        }
                        hits => {
                            let near = entered_children::<false>(node, &dist, mask);
                            for e in near[1..hits as usize].iter().rev() {
                                // The depth limit of the conversion keeps sp < STACK.
                                if let Some(s) = stack.get_mut(*sp) {
                                    s.write(*e);
                                    *sp += 1;
                                }
                            }
                            curs[k] = near[0].0;
                            continue;
                        }
                    }
                }
                // Pop the next entry still in front of the closest hit.
                loop {
                    if *sp == 0 {
                        active &= !(1 << k);
                        break;
                    }
                    *sp -= 1;
                    // SAFETY: entries below `sp` were written by the push above.
                    let (child, d) = unsafe { stack[*sp].assume_init() };
                    if d < ray.tmax {
                        curs[k] = child;
                        self.prefetch(child);
                        break;
                    }
                }
            }
        }
        for k in 0..INTERLEAVE {
            work[k].node_visits += visits[k];
            work[k].primitive_tests += tests[k];
        }
        best
    }
}

avx_twins! {
    /// [`WideBvh::interleaved_with`] compiled for AVX / AVX-512.
    unsafe fn [interleaved_avx, interleaved_avx512]<N: NodeTest>(
        bvh: &WideBvh,
        rays: &mut [Ray; INTERLEAVE],
        work: &mut [RayWork; INTERLEAVE],
    ) -> [Option<(u32, f32)>; INTERLEAVE] {
        bvh.interleaved_with::<N>(rays, work)
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3A;
    use marchmesh_core::RayWork;
    use obvhs::ray::Ray;

    use super::INTERLEAVE;
    use crate::wide::Isa;
    use crate::wide::test_util::{lcg, wide_of_random};

    #[test]
    fn interleaved_rays_find_exactly_the_single_ray_hits() {
        let (mut w, _) = wide_of_random(4000, 31, obvhs::BvhBuildParams::medium_build());
        let mut s = 41u64;
        let mut hits = 0;
        for isa in Isa::available() {
            w.isa = isa;
            for _ in 0..64 {
                let rays: [Ray; INTERLEAVE] = std::array::from_fn(|_| {
                    let o = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 8.0 - 4.0;
                    let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                    Ray::new(o, (target - o).normalize(), 0.0, 100.0)
                });
                let mut together = rays;
                let mut work = [RayWork::default(); INTERLEAVE];
                let got = w.closest_interleaved(&mut together, &mut work);
                for k in 0..INTERLEAVE {
                    let mut alone = rays[k];
                    let mut single_work = RayWork::default();
                    let want = w.closest(&mut alone, &mut single_work);
                    assert_eq!(
                        got[k].map(|(p, t)| (p, t.to_bits())),
                        want.map(|(p, t)| (p, t.to_bits()))
                    );
                    assert_eq!(work[k], single_work);
                    hits += usize::from(want.is_some());
                }
            }
        }
        assert!(hits > 100, "{hits} hits: the rays must mostly hit");
    }
}
