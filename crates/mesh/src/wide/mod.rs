//! An 8-wide CPU BVH converted from an obvhs [`Bvh2`](obvhs::bvh2::Bvh2), traversed with SIMD box
//! tests (8 child boxes per node in one AVX test, runtime-detected, with a portable fallback) and
//! SIMD triangle tests (blocks of 4 triangles, SSE on x86_64, portable elsewhere); on a CPU with
//! AVX-512 the same code is compiled with it enabled ([`Isa::Avx512`]).
//!
//! Layout (after Wald et al. 2008 "Getting rid of packets" and Embree's BVH8 with triangle4 blocks,
//! Wald et al. 2014): each node holds its 8 child boxes as structure of arrays plus 8 child
//! references; leaves are runs of [`TriBlock`]s holding 4 triangles each as structure of arrays, in
//! BVH slot order, so slots, normals and materials of the [`crate::blas::Blas`] stay valid.
//! Conversion collapses the Bvh2 by the SAH-optimal dynamic programme of Ylitie et al. 2017 (see
//! [`Collapse`](build::Collapse)), which fills nodes (5.8 of 8 children on average on the dragons
//! against 4.4 for opening the largest child greedily) and may merge small Bvh2 leaves into one
//! block.
//!
//! Exactness: the triangle test is obvhs' `RtTriangle::intersect` (Möller-Trumbore) computed
//! lane-wise in the same operation order without fused multiply-add, so every `t` is
//! bit-identical to the Bvh2 path; the box test is obvhs' `Aabb::intersect_ray` slab test.
//! Closest hits therefore equal the Bvh2 path's except for exact ties between triangles at
//! the same `t` (shared edges), where the visiting order picks the winner.
//!
//! One concept per file: `layout` (nodes, triangle blocks and the [`WideBvh`] they form),
//! `build` (the collapse from the Bvh2), `huge` (the huge-page arrays holding them),
//! `traverse` (single-ray closest and any-hit traversal, shared child ordering, pushes and
//! leaf tests), `interleave` (batches of single rays traced in turns), `isa` (the SIMD level and
//! the node and triangle tests' entry points), and one file per instruction set of those
//! tests: `portable` and `avx` (x86_64; the AVX-512 twins are the same source compiled
//! with more features enabled, by [`avx_twins`]). Ray packets live in [`crate::packet`].

// Lane loops index several structure-of-arrays fields by the same lane, mirroring SIMD lanes.
#![allow(clippy::needless_range_loop)]

/// Defines the functions `$avx` and `$avx512` with one signature and body, compiled for
/// [`Isa::Avx`] (AVX and POPCNT enabled) and for [`Isa::Avx512`] (AVX-512 F, VL, BW and DQ
/// as well). Both are `unsafe`: call them only at the level [`Isa::detect`] found.
macro_rules! avx_twins {
    ($(#[$m:meta])* $vis:vis unsafe fn [$avx:ident, $avx512:ident] $($signature_and_body:tt)*) => {
        $(#[$m])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx,popcnt")]
        $vis unsafe fn $avx $($signature_and_body)*

        $(#[$m])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx,popcnt,avx512f,avx512vl,avx512bw,avx512dq")]
        $vis unsafe fn $avx512 $($signature_and_body)*
    };
}
pub(crate) use avx_twins;

/// `$avx512 $call` at [`Isa::Avx512`], else `$avx $call` (`$call`: turbofish and
/// arguments); an `unsafe` call of [`avx_twins`] functions, so `$isa` must not be
/// [`Isa::Portable`].
macro_rules! by_isa {
    ($isa:expr, $avx:ident, $avx512:ident, $($call:tt)*) => {
        match $isa {
            Isa::Avx512 => $avx512 $($call)*,
            _ => $avx $($call)*,
        }
    };
}
pub(crate) use by_isa;

#[cfg(target_arch = "x86_64")]
mod avx;
mod build;
mod huge;
mod interleave;
mod isa;
mod layout;
mod portable;
mod traverse;

pub(crate) use interleave::INTERLEAVE;
pub(crate) use isa::Isa;
pub(crate) use layout::{
    BLOCK, EMPTY, LEAF, STACK, TriBlock, WIDTH, WideBvh, WideNode, leaf_range,
};
pub(crate) use traverse::{closest_in_blocks, entered_children};

/// Random triangles and trees the tests of every concept share.
#[cfg(test)]
mod test_util {
    use glam::Vec3A;
    use obvhs::{ray::Ray, rt_triangle::RtTriangle, triangle::Triangle};

    use super::{WIDTH, WideBvh, WideNode};
    #[cfg(target_arch = "x86_64")]
    use super::{
        avx::{Avx, AvxAtOrigin},
        isa::NodeTest,
    };

    /// A small deterministic pseudo-random sequence in [0, 1).
    pub(super) fn lcg(state: &mut u64) -> f32 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*state >> 40) as f32) / (1u64 << 24) as f32
    }

    pub(super) fn random_tris(n: usize, seed: u64) -> Vec<RtTriangle> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                let c = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                let mut v = || c + Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 0.6 - 0.3;
                RtTriangle::from(&Triangle {
                    v0: v(),
                    v1: v(),
                    v2: v(),
                })
            })
            .collect()
    }

    /// `n` random triangles (seed `seed`) built by obvhs with `params` and converted: the
    /// wide BVH and the Bvh2-ordered slot triangles it was converted from.
    pub(super) fn wide_of_random(
        n: usize,
        seed: u64,
        params: obvhs::BvhBuildParams,
    ) -> (WideBvh, Vec<RtTriangle>) {
        let plain: Vec<Triangle> = random_tris(n, seed)
            .iter()
            .map(|t| Triangle {
                v0: t.v0,
                v1: t.v0 - t.e1,
                v2: t.v0 + t.e2,
            })
            .collect();
        let mut time = std::time::Duration::default();
        let bvh = obvhs::bvh2::builder::build_bvh2_from_tris(&plain, params, &mut time);
        let slot_tris: Vec<RtTriangle> = bvh
            .primitive_indices
            .iter()
            .map(|&i| RtTriangle::from(&plain[i as usize]))
            .collect();
        let w = WideBvh::from_bvh2(&bvh, &slot_tris).expect("converts");
        (w, slot_tris)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,popcnt")]
    pub(super) unsafe fn avx_test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        Avx::test(node, ray)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,popcnt")]
    pub(super) unsafe fn avx_at_origin_test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        AvxAtOrigin::test(node, ray)
    }
}
