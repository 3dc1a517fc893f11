//! The SIMD level traversal runs at (detected once per build) and the entry points of the
//! per-level node and triangle tests: the [`NodeTest`] trait and [`block_hits`].

use obvhs::ray::Ray;

use super::layout::{BLOCK, TriBlock, WIDTH, WideNode};

/// The SIMD level traversal runs at, detected once per BVH build ([`Isa::detect`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
// Off x86_64 only `Portable` is ever detected.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(crate) enum Isa {
    /// Plain per-lane code: any CPU.
    Portable,
    /// The 256-bit AVX node tests and SSE triangle tests (AVX and POPCNT).
    Avx,
    /// The same code compiled with AVX-512 F, VL, BW and DQ enabled as well: the compiler
    /// then keeps comparison results in mask registers instead of vector masks and
    /// `movemask`s (the source, and so every rounded operation, stays the same: no fused
    /// multiply-add). Measured against [`Isa::Avx`]: `docs/decisions/0013`.
    Avx512,
}

impl Isa {
    /// The highest level this CPU supports.
    pub(crate) fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx") && has!("popcnt") {
                if has!("avx512f") && has!("avx512vl") && has!("avx512bw") && has!("avx512dq") {
                    return Self::Avx512;
                }
                return Self::Avx;
            }
        }
        Self::Portable
    }

    /// Every level this CPU can run, lowest first (tests compare them).
    #[cfg(test)]
    pub(crate) fn available() -> Vec<Self> {
        [Self::Portable, Self::Avx, Self::Avx512]
            .into_iter()
            .filter(|&l| l <= Self::detect())
            .collect()
    }
}

/// The 8-box slab test of a node: bit `i` of the mask is set when the ray enters child
/// box `i` (exit >= entry, exit >= 0) at an entry distance below `ray.tmax`; entry
/// distances per lane. Same arithmetic as obvhs `Aabb::intersect_ray`.
pub(crate) trait NodeTest {
    fn test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]);
}

/// Möller-Trumbore (1997) on the 4 lanes of a block, exactly obvhs'
/// `RtTriangle::intersect`: each lane's `t` if it hits within `[ray.tmin, ray.tmax]`, else
/// `+inf` (padding lanes, all zero, compute `t = NaN` and never hit).
#[inline(always)]
// Traversal asks for the mask form ([`block_hit_mask`]); this one is the reference the
// tests compare it with.
#[cfg_attr(not(test), allow(dead_code))]
pub(crate) fn block_hits(b: &TriBlock, ray: &Ray) -> [f32; BLOCK] {
    #[cfg(target_arch = "x86_64")]
    {
        super::avx::block_hits_sse(b, ray)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        super::portable::block_hits_portable(b, ray)
    }
}

/// The lanes of [`block_hits`] nearer than `ray.tmax` as a mask (bit `lane`), and each
/// lane's `t`, which is [`block_hits`]' on the mask's lanes (and meaningless on the
/// others). The form traversal asks for: one mask decides whether a block holds a hit.
#[inline(always)]
pub(crate) fn block_hit_mask(b: &TriBlock, ray: &Ray) -> (u32, [f32; BLOCK]) {
    #[cfg(target_arch = "x86_64")]
    {
        super::avx::block_hit_mask_sse(b, ray)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let t = super::portable::block_hits_portable(b, ray);
        let mut mask = 0u32;
        for lane in 0..BLOCK {
            mask |= u32::from(t[lane] < ray.tmax) << lane;
        }
        (mask, t)
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3A;
    use marchmesh_core::RayWork;
    use obvhs::ray::Ray;

    use super::*;
    use crate::wide::INTERLEAVE;
    use crate::wide::build::Builder;
    use crate::wide::layout::{EMPTY_NODE, WideBvh};
    use crate::wide::portable::{Portable, block_hits_portable};
    #[cfg(target_arch = "x86_64")]
    use crate::wide::test_util::avx_test;
    use crate::wide::test_util::{lcg, random_tris, wide_of_random};

    #[test]
    fn block_test_is_bit_identical_to_obvhs_intersect() {
        // 399: the last block has a padding lane, which must never hit.
        let tris = random_tris(399, 7);
        let mut s = 99u64;
        let mut masked = 0;
        for chunk in tris.chunks(BLOCK) {
            let mut w = Builder::default();
            let slots: Vec<u32> = (0..chunk.len() as u32).collect();
            assert!(w.leaf(&slots, chunk).is_some());
            let block = w.blocks[0];
            for _ in 0..200 {
                let o = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 6.0 - 3.0;
                let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                let ray = Ray::new(o, (target - o).normalize(), 0.0, 100.0);
                let simd = block_hits(&block, &ray);
                let portable = block_hits_portable(&block, &ray);
                for lane in 0..BLOCK {
                    let scalar = chunk.get(lane).map_or(f32::INFINITY, |t| t.intersect(&ray));
                    assert_eq!(simd[lane].to_bits(), scalar.to_bits(), "lane {lane}");
                    assert_eq!(portable[lane].to_bits(), scalar.to_bits(), "lane {lane}");
                }
                // The mask form: the lanes below `tmax`, with the same `t` there, also
                // when `tmax` is a lane's own `t` (then that lane is not below it).
                let firsts = simd.iter().copied().filter(|t| t.is_finite());
                for tmax in [ray.tmax, 1.0, f32::INFINITY].into_iter().chain(firsts) {
                    let ray = Ray { tmax, ..ray };
                    let expected = block_hits(&block, &ray);
                    let (mask, t) = block_hit_mask(&block, &ray);
                    for lane in 0..BLOCK {
                        let below = expected[lane] < tmax;
                        assert_eq!(mask >> lane & 1 == 1, below, "lane {lane}, tmax {tmax}");
                        if below {
                            assert_eq!(t[lane].to_bits(), expected[lane].to_bits());
                        }
                    }
                    masked += mask.count_ones();
                }
            }
        }
        assert!(masked > 100, "{masked} masked lanes: the rays must hit");
    }

    #[test]
    fn every_isa_level_gives_the_portable_answers() {
        // Each level (`Isa::available`: portable, AVX, AVX-512 where the CPU has them)
        // compiles the same source; closest and any-hit queries, interleaved batches and
        // packets must return what the portable code returns, bit for bit, with the same
        // work counts, for rays from the origin (the camera's) and from elsewhere.
        let (mut w, _) = wide_of_random(4000, 53, obvhs::BvhBuildParams::medium_build());
        let mut s = 59u64;
        let mut batches: Vec<[Ray; INTERLEAVE]> = Vec::new();
        for b in 0..48 {
            let shared = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 8.0 - 4.0;
            batches.push(std::array::from_fn(|_| {
                let o = if b % 2 == 0 { Vec3A::ZERO } else { shared };
                let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                Ray::new(o, (target - o).normalize(), 0.0, 100.0)
            }));
        }
        type Hit = Option<(u32, u32)>;
        // Per ray (closest, work, any), per batch ray (interleaved, then packet), counts.
        type Answers = (Vec<(Hit, RayWork, bool)>, Vec<Hit>, Vec<u32>);
        let answers = |w: &WideBvh| -> Answers {
            let bits = |h: Option<(u32, f32)>| h.map(|(p, t)| (p, t.to_bits()));
            let (mut single, mut batched, mut counts) = (Vec::new(), Vec::new(), Vec::new());
            for rays in &batches {
                for ray in rays {
                    let (mut r, mut work) = (*ray, RayWork::default());
                    let closest = bits(w.closest(&mut r, &mut work));
                    let mut r = *ray;
                    single.push((closest, work, w.any(&mut r, &mut RayWork::default())));
                }
                let (mut r, mut work) = (*rays, [RayWork::default(); INTERLEAVE]);
                batched.extend(w.closest_interleaved(&mut r, &mut work).map(bits));
                counts.extend(work.iter().map(|k| k.node_visits));
                let (mut r, mut visits, mut tests) = (*rays, 0, [0; crate::packet::PACKET]);
                let packet = crate::packet::closest8(w, &mut r, &mut visits, &mut tests)
                    .expect("the rays of a batch share their origin");
                batched.extend(packet.map(bits));
                counts.push(visits);
                counts.extend(tests);
            }
            (single, batched, counts)
        };
        w.isa = Isa::Portable;
        let portable = answers(&w);
        let hits = portable.0.iter().filter(|a| a.0.is_some()).count();
        assert!(hits > 100, "{hits} hits: the rays must mostly hit");
        for isa in Isa::available() {
            w.isa = isa;
            assert!(
                answers(&w) == portable,
                "{isa:?} differs from the portable code"
            );
        }
    }

    #[test]
    fn node_tests_agree_with_obvhs_slab_test() {
        let tris = random_tris(300, 3);
        let boxes: Vec<_> = tris.iter().map(|t| t.aabb()).collect();
        let mut s = 5u64;
        for chunk in boxes.chunks(WIDTH) {
            let mut node = EMPTY_NODE;
            for (lane, b) in chunk.iter().enumerate() {
                for axis in 0..3 {
                    node.lo[axis][lane] = b.min[axis];
                    node.hi[axis][lane] = b.max[axis];
                }
                node.child[lane] = lane as u32;
            }
            for _ in 0..100 {
                let o = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 6.0 - 3.0;
                let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                let ray = Ray::new(o, (target - o).normalize(), 0.0, 3.0);
                let mut expected = 0u32;
                for (lane, b) in chunk.iter().enumerate() {
                    if b.intersect_ray(&ray) < ray.tmax {
                        expected |= 1 << lane;
                    }
                }
                assert_eq!(Portable::test(&node, &ray).0, expected);
                #[cfg(target_arch = "x86_64")]
                if Isa::detect() >= Isa::Avx {
                    // SAFETY: AVX detected above.
                    let avx = unsafe { avx_test(&node, &ray) };
                    assert_eq!(avx.0, expected);
                }
            }
        }
    }
}
