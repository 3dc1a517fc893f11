//! Packets of 8 coherent rays through the [`WideBvh`]: one conservative interval-arithmetic
//! node test per packet (Wald, Boulos, Shirley 2007, "Ray tracing deformable scenes using
//! dynamic bounding volume hierarchies", interval culling), exact per-ray triangle tests at
//! the leaves.
//!
//! The packet's rays share one origin and `tmin` (primary rays, shadow rays towards a point
//! light after swapping ends); each axis's inverse direction is bounded by the interval of
//! its 8 values. Because `(plane - origin) * inv` is monotone in `inv` (and so is its
//! rounding), the products at the interval ends bound every ray's slab distances: a node is
//! skipped only when no ray of the packet can enter it before the packet's largest `tmax`.
//! Leaves run the same block test as single rays, so each ray's closest `t` equals its
//! single-ray result (ties between triangles at one `t` aside).

// Lane loops index several structure-of-arrays fields by the same lane, mirroring SIMD lanes.
#![allow(clippy::needless_range_loop)]

use obvhs::ray::Ray;

use crate::wide::{
    EMPTY, Isa, LEAF, STACK, WIDTH, WideBvh, WideNode, by_isa, closest_in_blocks, entered_children,
    leaf_range,
};

/// Rays per packet.
pub(crate) const PACKET: usize = 8;

/// A packet's interval bounds: shared origin and per-axis inverse-direction intervals.
struct Bounds {
    origin: [f32; 3],
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
}

impl Bounds {
    /// `None` unless all rays share origin (bitwise) and `tmin`.
    fn of(rays: &[Ray; PACKET]) -> Option<Self> {
        let o = rays[0].origin;
        let mut inv_lo = rays[0].inv_direction;
        let mut inv_hi = inv_lo;
        for r in rays {
            if r.origin.to_array().map(f32::to_bits) != o.to_array().map(f32::to_bits)
                || r.tmin.to_bits() != rays[0].tmin.to_bits()
                || !r.inv_direction.is_finite()
            {
                return None;
            }
            inv_lo = inv_lo.min(r.inv_direction);
            inv_hi = inv_hi.max(r.inv_direction);
        }
        Some(Self {
            origin: o.to_array(),
            inv_lo: inv_lo.to_array(),
            inv_hi: inv_hi.to_array(),
        })
    }

    /// Mask of children some ray of the packet may enter before `tmax`, and lower bounds
    /// of the entry distances.
    #[inline(always)]
    fn test(&self, node: &WideNode, tmax: f32) -> (u32, [f32; WIDTH]) {
        let mut entry = [0.0f32; WIDTH];
        let mut mask = 0u32;
        for lane in 0..WIDTH {
            let mut t_in = f32::NEG_INFINITY;
            let mut t_out = f32::INFINITY;
            for axis in 0..3 {
                let a = node.lo[axis][lane] - self.origin[axis];
                let b = node.hi[axis][lane] - self.origin[axis];
                let (p, q) = (a * self.inv_lo[axis], a * self.inv_hi[axis]);
                let (r, s) = (b * self.inv_lo[axis], b * self.inv_hi[axis]);
                t_in = t_in.max(p.min(q).min(r.min(s)));
                t_out = t_out.min(p.max(q).max(r.max(s)));
            }
            entry[lane] = t_in;
            if t_out >= t_in && t_out >= 0.0 && t_in < tmax {
                mask |= 1 << lane;
            }
        }
        (mask, entry)
    }
}

/// Lanes of `node` whose child is a leaf (empty lanes excluded).
#[inline(always)]
fn leaf_lanes(node: &WideNode) -> u32 {
    let mut m = 0;
    for (lane, &c) in node.child.iter().enumerate() {
        if c & LEAF != 0 && c != EMPTY {
            m |= 1 << lane;
        }
    }
    m
}

/// obvhs' slab test (`Aabb::intersect_ray`) of one ray against child box `lane`.
#[inline(always)]
fn enters(node: &WideNode, lane: usize, ray: &Ray) -> bool {
    let mut t_in = f32::NEG_INFINITY;
    let mut t_out = f32::INFINITY;
    for axis in 0..3 {
        let t1 = (node.lo[axis][lane] - ray.origin[axis]) * ray.inv_direction[axis];
        let t2 = (node.hi[axis][lane] - ray.origin[axis]) * ray.inv_direction[axis];
        t_in = t_in.max(t1.min(t2));
        t_out = t_out.min(t1.max(t2));
    }
    t_out >= t_in && t_out >= 0.0 && t_in < ray.tmax
}

/// Closest hits of 8 rays as `(prim, t)` each (`prim` a [`WideBvh::triangle`] reference), shrinking each `tmax`; `None` (nothing
/// done) when the rays do not share an origin and `tmin`: trace them one by one then.
/// Adds the packet's node visits to `visits` and block tests per ray to `tests`.
pub(crate) fn closest8(
    bvh: &WideBvh,
    rays: &mut [Ray; PACKET],
    visits: &mut u32,
    tests: &mut [u32; PACKET],
) -> Option<[Option<(u32, f32)>; PACKET]> {
    let bounds = Bounds::of(rays)?;
    #[cfg(target_arch = "x86_64")]
    if bvh.isa != Isa::Portable {
        use avx::{closest8_avx as c, closest8_avx512 as c512};
        // SAFETY: `isa` is above `Portable` only when the CPU reports its features.
        return Some(unsafe {
            // Camera rays start at the origin of render space: no origin to subtract.
            match bounds.origin == [0.0; 3] {
                true => by_isa!(bvh.isa, c, c512, ::<true>(bvh, &bounds, rays, visits, tests)),
                false => by_isa!(bvh.isa, c, c512, ::<false>(bvh, &bounds, rays, visits, tests)),
            }
        });
    }
    Some(closest8_with(bvh, &bounds, rays, visits, tests))
}

#[inline(always)]
fn closest8_with(
    bvh: &WideBvh,
    bounds: &Bounds,
    rays: &mut [Ray; PACKET],
    visits: &mut u32,
    tests: &mut [u32; PACKET],
) -> [Option<(u32, f32)>; PACKET] {
    let mut best = [None; PACKET];
    if bvh.root == EMPTY {
        return best;
    }
    let packet_tmax =
        |rays: &[Ray; PACKET]| rays.iter().fold(f32::NEG_INFINITY, |m, r| m.max(r.tmax));
    let mut tmax = packet_tmax(rays);
    let mut stack = [(EMPTY, 0.0f32); STACK];
    let mut sp = 0usize;
    let mut cur = bvh.root;
    'walk: loop {
        if cur & LEAF != 0 {
            // Only the root can be a leaf here (leaf children are handled in their parent).
            let (first, count) = leaf_range(cur);
            if let Some(blocks) = bvh.blocks.get(first..first + count) {
                for (k, ray) in rays.iter_mut().enumerate() {
                    tests[k] += closest_in_blocks(first, blocks, ray, &mut best[k]);
                }
                tmax = packet_tmax(rays);
            }
        } else if let Some(node) = bvh.nodes.get(cur as usize) {
            *visits += 1;
            let (mut mask, dist) = bounds.test(node, tmax);
            // Leaf children now, each ray first checking the leaf's box alone: a packet's
            // interval reaches many leaves that only some of its rays enter.
            let mut leaves = mask & leaf_lanes(node);
            mask &= !leaves;
            while leaves != 0 {
                let lane = leaves.trailing_zeros() as usize;
                leaves &= leaves - 1;
                let c = node.child[lane];
                let (first, count) = leaf_range(c);
                let Some(blocks) = bvh.blocks.get(first..first + count) else {
                    continue;
                };
                for (k, ray) in rays.iter_mut().enumerate() {
                    if !enters(node, lane, ray) {
                        continue;
                    }
                    tests[k] += closest_in_blocks(first, blocks, ray, &mut best[k]);
                }
                tmax = packet_tmax(rays);
            }
            let hits = mask.count_ones() as usize;
            if hits > 0 {
                let near = entered_children::<false>(node, &dist, mask);
                for e in near[1..hits].iter().rev() {
                    // The depth limit of the conversion keeps sp < STACK.
                    if let Some(s) = stack.get_mut(sp) {
                        *s = *e;
                        sp += 1;
                    }
                }
                cur = near[0].0;
                continue 'walk;
            }
        }
        loop {
            if sp == 0 {
                break 'walk;
            }
            sp -= 1;
            let (child, d) = stack[sp];
            if d < tmax {
                cur = child;
                continue 'walk;
            }
        }
    }
    best
}

/// The packet traversal of [`closest8_with`] with the rays as structure of arrays in AVX
/// registers: the interval node test runs on 8 child boxes at once, and at a leaf the 8
/// rays are tested against one box and then against one triangle at a time (8 rays per
/// Möller-Trumbore test, the layout of Wald et al. 2001 "Interactive rendering with
/// coherent ray tracing"), instead of one ray against a block of 4 triangles. Every lane
/// runs obvhs' operations in the same order without fused multiply-add, so each ray's
/// `t` and winner are those of [`closest_in_blocks`] (triangles are visited in the same
/// block and lane order, and a hit is taken only when strictly nearer).
#[cfg(target_arch = "x86_64")]
mod avx {
    use std::arch::x86_64::*;

    use obvhs::ray::Ray;

    use super::{Bounds, PACKET, leaf_lanes};
    use crate::wide::{
        BLOCK, EMPTY, LEAF, STACK, TriBlock, WIDTH, WideBvh, WideNode, entered_children, leaf_range,
    };

    /// The packet's rays as structure of arrays, with each ray's current `tmax` and best
    /// hit reference.
    struct Soa {
        origin: [f32; 3],
        dir: [__m256; 3],
        inv: [__m256; 3],
        tmin: __m256,
        tmax: __m256,
        prim: __m256i,
        /// Rays that found a hit.
        found: u32,
    }

    crate::wide::avx_twins! {
        /// [`closest8`] compiled for AVX / AVX-512 ([`crate::wide::Isa`]).
        pub(super) unsafe fn [closest8_avx, closest8_avx512]<const AT_ORIGIN: bool>(
            bvh: &WideBvh,
            bounds: &Bounds,
            rays: &mut [Ray; PACKET],
            visits: &mut u32,
            tests: &mut [u32; PACKET],
        ) -> [Option<(u32, f32)>; PACKET] {
            // SAFETY: the caller checked the CPU's level (see `super::closest8`).
            unsafe { closest8::<AT_ORIGIN>(bvh, bounds, rays, visits, tests) }
        }
    }

    /// [`super::closest8`] with AVX intrinsics; inlined into [`closest8_avx`] and
    /// [`closest8_avx512`].
    ///
    /// # Safety
    /// The CPU must support AVX and POPCNT.
    #[inline(always)]
    unsafe fn closest8<const AT_ORIGIN: bool>(
        bvh: &WideBvh,
        bounds: &Bounds,
        rays: &mut [Ray; PACKET],
        visits: &mut u32,
        tests: &mut [u32; PACKET],
    ) -> [Option<(u32, f32)>; PACKET] {
        // SAFETY: AVX is enabled in every caller (see `closest8`); loads are in bounds.
        unsafe {
            let mut best = [None; PACKET];
            if bvh.root == EMPTY {
                return best;
            }
            let lanes =
                |f: fn(&Ray) -> f32| -> [f32; PACKET] { std::array::from_fn(|k| f(&rays[k])) };
            let ld = |a: [f32; PACKET]| _mm256_loadu_ps(a.as_ptr());
            let mut soa = Soa {
                origin: bounds.origin,
                dir: [
                    ld(lanes(|r| r.direction.x)),
                    ld(lanes(|r| r.direction.y)),
                    ld(lanes(|r| r.direction.z)),
                ],
                inv: [
                    ld(lanes(|r| r.inv_direction.x)),
                    ld(lanes(|r| r.inv_direction.y)),
                    ld(lanes(|r| r.inv_direction.z)),
                ],
                tmin: ld(lanes(|r| r.tmin)),
                tmax: ld(lanes(|r| r.tmax)),
                prim: _mm256_set1_epi32(-1),
                found: 0,
            };
            let mut tmax = hmax(soa.tmax);
            let mut stack = [(EMPTY, 0.0f32); STACK];
            let mut sp = 0usize;
            let mut cur = bvh.root;
            'walk: loop {
                if cur & LEAF != 0 {
                    // Only the root can be a leaf here: every ray tests it.
                    let (first, count) = leaf_range(cur);
                    if let Some(blocks) = bvh.blocks.get(first..first + count) {
                        leaf(&mut soa, 0xff, first, blocks, tests);
                        tmax = hmax(soa.tmax);
                    }
                } else if let Some(node) = bvh.nodes.get(cur as usize) {
                    *visits += 1;
                    let (mut mask, dist) = interval_test::<AT_ORIGIN>(bounds, node, tmax);
                    let mut leaves = mask & leaf_lanes(node);
                    mask &= !leaves;
                    while leaves != 0 {
                        let lane = leaves.trailing_zeros() as usize;
                        leaves &= leaves - 1;
                        let (first, count) = leaf_range(node.child[lane]);
                        let Some(blocks) = bvh.blocks.get(first..first + count) else {
                            continue;
                        };
                        let enter = box_test::<AT_ORIGIN>(&soa, node, lane);
                        if enter != 0 {
                            leaf(&mut soa, enter, first, blocks, tests);
                            tmax = hmax(soa.tmax);
                        }
                    }
                    let hits = mask.count_ones() as usize;
                    if hits > 0 {
                        let near = entered_children::<false>(node, &dist, mask);
                        for e in near[1..hits].iter().rev() {
                            // The depth limit of the conversion keeps sp < STACK.
                            if let Some(s) = stack.get_mut(sp) {
                                *s = *e;
                                sp += 1;
                            }
                        }
                        cur = near[0].0;
                        continue 'walk;
                    }
                }
                loop {
                    if sp == 0 {
                        break 'walk;
                    }
                    sp -= 1;
                    let (child, d) = stack[sp];
                    if d < tmax {
                        cur = child;
                        continue 'walk;
                    }
                }
            }
            let mut t = [0.0f32; PACKET];
            let mut p = [0u32; PACKET];
            _mm256_storeu_ps(t.as_mut_ptr(), soa.tmax);
            _mm256_storeu_si256(p.as_mut_ptr().cast(), soa.prim);
            for k in 0..PACKET {
                rays[k].tmax = t[k];
                if soa.found & (1 << k) != 0 {
                    best[k] = Some((p[k], t[k]));
                }
            }
            best
        }
    }

    /// Largest lane.
    #[inline(always)]
    unsafe fn hmax(v: __m256) -> f32 {
        // SAFETY: AVX is enabled in every caller (see `closest8`); loads are in bounds.
        unsafe {
            let m = _mm_max_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
            let m = _mm_max_ps(m, _mm_movehl_ps(m, m));
            let m = _mm_max_ss(m, _mm_shuffle_ps::<1>(m, m));
            _mm_cvtss_f32(m)
        }
    }

    /// [`Bounds::test`] on the 8 lanes at once; empty lanes are never set. `AT_ORIGIN`:
    /// the origin is 0 and not subtracted (`plane - 0` is `plane`, but for a zero's sign).
    #[inline(always)]
    unsafe fn interval_test<const AT_ORIGIN: bool>(
        b: &Bounds,
        node: &WideNode,
        tmax: f32,
    ) -> (u32, [f32; WIDTH]) {
        // SAFETY: AVX is enabled in every caller (see `closest8`); loads are in bounds.
        unsafe {
            let mut t_in = _mm256_set1_ps(f32::NEG_INFINITY);
            let mut t_out = _mm256_set1_ps(f32::INFINITY);
            for axis in 0..3 {
                let o = _mm256_set1_ps(b.origin[axis]);
                let (il, ih) = (
                    _mm256_set1_ps(b.inv_lo[axis]),
                    _mm256_set1_ps(b.inv_hi[axis]),
                );
                let (lo, hi) = (
                    _mm256_load_ps(node.lo[axis].as_ptr()),
                    _mm256_load_ps(node.hi[axis].as_ptr()),
                );
                let (lo, hi) = match AT_ORIGIN {
                    true => (lo, hi),
                    false => (_mm256_sub_ps(lo, o), _mm256_sub_ps(hi, o)),
                };
                let (p, q) = (_mm256_mul_ps(lo, il), _mm256_mul_ps(lo, ih));
                let (r, s) = (_mm256_mul_ps(hi, il), _mm256_mul_ps(hi, ih));
                t_in = _mm256_max_ps(
                    t_in,
                    _mm256_min_ps(_mm256_min_ps(p, q), _mm256_min_ps(r, s)),
                );
                t_out = _mm256_min_ps(
                    t_out,
                    _mm256_max_ps(_mm256_max_ps(p, q), _mm256_max_ps(r, s)),
                );
            }
            let ok = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(t_out, t_in),
                _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GE_OQ>(t_out, _mm256_setzero_ps()),
                    _mm256_cmp_ps::<_CMP_LT_OQ>(t_in, _mm256_set1_ps(tmax)),
                ),
            );
            let mut entry = [0.0f32; WIDTH];
            _mm256_storeu_ps(entry.as_mut_ptr(), t_in);
            let mut mask = _mm256_movemask_ps(ok) as u32;
            for lane in 0..WIDTH {
                if node.child[lane] == EMPTY {
                    mask &= !(1 << lane);
                }
            }
            (mask, entry)
        }
    }

    /// Rays of the packet entering child box `lane` before their own `tmax`: obvhs' slab
    /// test (`Aabb::intersect_ray`, as [`super::enters`]) per lane; `AT_ORIGIN` as for
    /// [`interval_test`].
    #[inline(always)]
    unsafe fn box_test<const AT_ORIGIN: bool>(soa: &Soa, node: &WideNode, lane: usize) -> u32 {
        // SAFETY: AVX is enabled in every caller (see `closest8`); loads are in bounds.
        unsafe {
            let mut t_in = _mm256_set1_ps(f32::NEG_INFINITY);
            let mut t_out = _mm256_set1_ps(f32::INFINITY);
            for axis in 0..3 {
                let (a, b) = match AT_ORIGIN {
                    true => (node.lo[axis][lane], node.hi[axis][lane]),
                    false => (
                        node.lo[axis][lane] - soa.origin[axis],
                        node.hi[axis][lane] - soa.origin[axis],
                    ),
                };
                let (a, b) = (_mm256_set1_ps(a), _mm256_set1_ps(b));
                let t1 = _mm256_mul_ps(a, soa.inv[axis]);
                let t2 = _mm256_mul_ps(b, soa.inv[axis]);
                t_in = _mm256_max_ps(t_in, _mm256_min_ps(t1, t2));
                t_out = _mm256_min_ps(t_out, _mm256_max_ps(t1, t2));
            }
            let ok = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(t_out, t_in),
                _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GE_OQ>(t_out, _mm256_setzero_ps()),
                    _mm256_cmp_ps::<_CMP_LT_OQ>(t_in, soa.tmax),
                ),
            );
            _mm256_movemask_ps(ok) as u32
        }
    }

    /// Tests the rays in `enter` against a leaf's `blocks` (the first at block index
    /// `first`), one triangle (8 rays) at a time, in block then lane order; counts 4 tests
    /// per block for each entering ray, as single rays do.
    #[inline(always)]
    unsafe fn leaf(
        soa: &mut Soa,
        enter: u32,
        first: usize,
        blocks: &[TriBlock],
        tests: &mut [u32; PACKET],
    ) {
        // SAFETY: AVX is enabled in every caller (see `closest8`); loads are in bounds.
        unsafe {
            let per_ray = (blocks.len() * BLOCK) as u32;
            for k in 0..PACKET {
                if enter & (1 << k) != 0 {
                    tests[k] += per_ray;
                }
            }
            let active = mask_of(enter);
            let [dx, dy, dz] = soa.dir;
            let [ox, oy, oz] = soa.origin;
            for (i, b) in blocks.iter().enumerate() {
                for lane in 0..BLOCK {
                    let ng = [b.ng[0][lane], b.ng[1][lane], b.ng[2][lane]];
                    // A zero normal (padding lanes) gives t = 0 * inf = NaN: never a hit.
                    if ng == [0.0; 3] {
                        continue;
                    }
                    let c = [b.v0[0][lane] - ox, b.v0[1][lane] - oy, b.v0[2][lane] - oz];
                    let (cx, cy, cz) = (
                        _mm256_set1_ps(c[0]),
                        _mm256_set1_ps(c[1]),
                        _mm256_set1_ps(c[2]),
                    );
                    let rx = _mm256_sub_ps(_mm256_mul_ps(dy, cz), _mm256_mul_ps(dz, cy));
                    let ry = _mm256_sub_ps(_mm256_mul_ps(dz, cx), _mm256_mul_ps(dx, cz));
                    let rz = _mm256_sub_ps(_mm256_mul_ps(dx, cy), _mm256_mul_ps(dy, cx));
                    let e1 = [b.e1[0][lane], b.e1[1][lane], b.e1[2][lane]];
                    let e2 = [b.e2[0][lane], b.e2[1][lane], b.e2[2][lane]];
                    let inv_det = _mm256_div_ps(_mm256_set1_ps(1.0), dot(dx, dy, dz, ng));
                    let u = _mm256_mul_ps(dot(rx, ry, rz, e2), inv_det);
                    let v = _mm256_mul_ps(dot(rx, ry, rz, e1), inv_det);
                    let w = _mm256_sub_ps(_mm256_sub_ps(_mm256_set1_ps(1.0), u), v);
                    let nc = ng[0] * c[0] + ng[1] * c[1] + ng[2] * c[2];
                    let t = _mm256_mul_ps(_mm256_set1_ps(nc), inv_det);
                    // u, v, w >= +0: no sign bit set (NaNs included, as in the SSE test).
                    let signs = _mm256_or_ps(_mm256_or_ps(u, v), w);
                    let valid = _mm256_and_ps(
                        _mm256_and_ps(
                            active,
                            _mm256_cmp_ps::<_CMP_NEQ_UQ>(inv_det, _mm256_setzero_ps()),
                        ),
                        _mm256_and_ps(
                            _mm256_cmp_ps::<_CMP_GE_OQ>(t, soa.tmin),
                            _mm256_cmp_ps::<_CMP_LT_OQ>(t, soa.tmax),
                        ),
                    );
                    let sign_mask = _mm256_movemask_ps(signs) as u32;
                    let hit = _mm256_movemask_ps(valid) as u32 & !sign_mask;
                    if hit == 0 {
                        continue;
                    }
                    let hitv = mask_of(hit);
                    soa.tmax = _mm256_blendv_ps(soa.tmax, t, hitv);
                    let id = (((first + i) * BLOCK + lane) as u32) as i32;
                    soa.prim = _mm256_castps_si256(_mm256_blendv_ps(
                        _mm256_castsi256_ps(soa.prim),
                        _mm256_castsi256_ps(_mm256_set1_epi32(id)),
                        hitv,
                    ));
                    soa.found |= hit;
                }
            }
        }
    }

    /// All-ones lanes where `bits` is set.
    #[inline(always)]
    unsafe fn mask_of(bits: u32) -> __m256 {
        // SAFETY: AVX is enabled in every caller (see `closest8`); loads are in bounds.
        unsafe {
            let lanes: [i32; PACKET] = std::array::from_fn(|k| -((bits >> k & 1) as i32));
            _mm256_castsi256_ps(_mm256_loadu_si256(lanes.as_ptr().cast()))
        }
    }

    /// `(x * v[0] + y * v[1]) + z * v[2]`, obvhs' dot product order.
    #[inline(always)]
    unsafe fn dot(x: __m256, y: __m256, z: __m256, v: [f32; 3]) -> __m256 {
        // SAFETY: AVX is enabled in every caller (see `closest8`); loads are in bounds.
        unsafe {
            _mm256_add_ps(
                _mm256_add_ps(
                    _mm256_mul_ps(x, _mm256_set1_ps(v[0])),
                    _mm256_mul_ps(y, _mm256_set1_ps(v[1])),
                ),
                _mm256_mul_ps(z, _mm256_set1_ps(v[2])),
            )
        }
    }
}
