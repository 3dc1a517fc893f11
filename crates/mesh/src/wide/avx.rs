//! The x86_64 node and triangle tests: 256-bit AVX slab tests of a node's 8 boxes (with a
//! form for rays starting at the origin, and forms specialised per octant of the ray's
//! direction) and the SSE triangle-block test. The AVX-512
//! level runs this same source compiled with AVX-512 enabled ([`super::avx_twins`]).

use obvhs::ray::Ray;

use super::isa::NodeTest;
use super::layout::{BLOCK, TriBlock, WIDTH, WideNode};

/// 256-bit AVX node test; only called from `#[target_feature(enable = "avx,popcnt")]` functions
/// after runtime detection.
#[cfg(target_arch = "x86_64")]
pub(super) struct Avx;

#[cfg(target_arch = "x86_64")]
impl NodeTest for Avx {
    #[inline(always)]
    fn test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        avx_node_test::<false>(node, ray)
    }
}

/// [`Avx`] for rays starting at the origin of render space (every camera ray: render space
/// is centred on the camera): `lo - 0` is `lo`, so each plane distance is one product,
/// bit for bit the same as [`Avx`]'s but for the sign of a zero.
#[cfg(target_arch = "x86_64")]
pub(super) struct AvxAtOrigin;

#[cfg(target_arch = "x86_64")]
impl NodeTest for AvxAtOrigin {
    #[inline(always)]
    fn test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        avx_node_test::<true>(node, ray)
    }
}

/// [`Avx`] specialised to one octant of ray directions: `NX`, `NY`, `NZ` say which axes the
/// direction is negative along (the sign bit of the inverse direction, which
/// `ray.inv_direction` shares with the direction, a zero's sign included). The near plane
/// of each axis is then known without testing, so each plane distance is computed once as
/// the entry or the exit distance of its axis instead of both being computed and ordered
/// by `min` and `max` (Embree's and tinybvh's sign-selected near and far planes). With the
/// boxes' `lo <= hi`, `(lo - o) * inv <= (hi - o) * inv` for a positive `inv` and the
/// reverse for a negative one (rounding is monotone), so the masks and the entry distances
/// are [`Avx`]'s bit for bit but for the sign of a zero. `AT_ORIGIN` as in [`AvxAtOrigin`].
#[cfg(target_arch = "x86_64")]
pub(super) struct AvxOctant<const NX: bool, const NY: bool, const NZ: bool, const AT_ORIGIN: bool>;

#[cfg(target_arch = "x86_64")]
impl<const NX: bool, const NY: bool, const NZ: bool, const AT_ORIGIN: bool> NodeTest
    for AvxOctant<NX, NY, NZ, AT_ORIGIN>
{
    #[inline(always)]
    fn test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        use std::arch::x86_64::*;
        // SAFETY: inlined only into AVX-enabled callers (see `closest_avx`); loads are from
        // 32-byte aligned arrays of 8 f32.
        unsafe {
            let plane = |axis: usize, negative: bool| {
                let (near, far) = match negative {
                    false => (&node.lo[axis], &node.hi[axis]),
                    true => (&node.hi[axis], &node.lo[axis]),
                };
                let inv = _mm256_set1_ps(ray.inv_direction[axis]);
                let (near, far) = (_mm256_load_ps(near.as_ptr()), _mm256_load_ps(far.as_ptr()));
                let (near, far) = match AT_ORIGIN {
                    true => (near, far),
                    false => {
                        let o = _mm256_set1_ps(ray.origin[axis]);
                        (_mm256_sub_ps(near, o), _mm256_sub_ps(far, o))
                    }
                };
                (_mm256_mul_ps(near, inv), _mm256_mul_ps(far, inv))
            };
            let (nx, fx) = plane(0, NX);
            let (ny, fy) = plane(1, NY);
            let (nz, fz) = plane(2, NZ);
            let t_in = _mm256_max_ps(_mm256_max_ps(nx, ny), nz);
            let t_out = _mm256_min_ps(_mm256_min_ps(fx, fy), fz);
            let ok = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(t_out, t_in),
                _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GE_OQ>(t_out, _mm256_setzero_ps()),
                    _mm256_cmp_ps::<_CMP_LT_OQ>(t_in, _mm256_set1_ps(ray.tmax)),
                ),
            );
            let mut entry = [0.0f32; WIDTH];
            _mm256_storeu_ps(entry.as_mut_ptr(), t_in);
            (_mm256_movemask_ps(ok) as u32, entry)
        }
    }
}

/// The 8-lane slab test of [`Avx`] (`AT_ORIGIN = false`) and [`AvxAtOrigin`] (`true`: the
/// ray's origin is 0 and not subtracted).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn avx_node_test<const AT_ORIGIN: bool>(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
    use std::arch::x86_64::*;
    // SAFETY: inlined only into AVX-enabled callers (see `closest_avx`); loads are from
    // 32-byte aligned arrays of 8 f32.
    unsafe {
        let mut t_in = _mm256_set1_ps(f32::NEG_INFINITY);
        let mut t_out = _mm256_set1_ps(f32::INFINITY);
        for axis in 0..3 {
            let inv = _mm256_set1_ps(ray.inv_direction[axis]);
            let lo = _mm256_load_ps(node.lo[axis].as_ptr());
            let hi = _mm256_load_ps(node.hi[axis].as_ptr());
            let (lo, hi) = match AT_ORIGIN {
                true => (lo, hi),
                false => {
                    let o = _mm256_set1_ps(ray.origin[axis]);
                    (_mm256_sub_ps(lo, o), _mm256_sub_ps(hi, o))
                }
            };
            let t1 = _mm256_mul_ps(lo, inv);
            let t2 = _mm256_mul_ps(hi, inv);
            t_in = _mm256_max_ps(t_in, _mm256_min_ps(t1, t2));
            t_out = _mm256_min_ps(t_out, _mm256_max_ps(t1, t2));
        }
        let ok = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GE_OQ>(t_out, t_in),
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(t_out, _mm256_setzero_ps()),
                _mm256_cmp_ps::<_CMP_LT_OQ>(t_in, _mm256_set1_ps(ray.tmax)),
            ),
        );
        let mut entry = [0.0f32; WIDTH];
        _mm256_storeu_ps(entry.as_mut_ptr(), t_in);
        (_mm256_movemask_ps(ok) as u32, entry)
    }
}

/// SSE form of [`block_hits`] (SSE2 is part of x86_64: no detection needed). Same
/// operations in the same order as the portable form, no fused multiply-add.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) fn block_hits_sse(b: &TriBlock, ray: &Ray) -> [f32; BLOCK] {
    use std::arch::x86_64::*;
    let (t, valid) = block_test_sse::<false>(b, ray);
    // SAFETY: SSE2 is baseline on x86_64.
    unsafe {
        let hit_t = select_ps(_mm_set1_ps(f32::INFINITY), t, valid);
        let mut out = [0.0f32; BLOCK];
        _mm_storeu_ps(out.as_mut_ptr(), hit_t);
        out
    }
}

/// SSE form of [`block_hit_mask`](super::isa::block_hit_mask): the lanes of
/// [`block_hits_sse`] below `ray.tmax` as a mask, straight from the test's own
/// comparisons (no select of `+inf`, no second comparison against `ray.tmax`), and each
/// lane's `t`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) fn block_hit_mask_sse(b: &TriBlock, ray: &Ray) -> (u32, [f32; BLOCK]) {
    use std::arch::x86_64::*;
    let (t, valid) = block_test_sse::<true>(b, ray);
    // SAFETY: SSE2 is baseline on x86_64.
    unsafe {
        let mut out = [0.0f32; BLOCK];
        _mm_storeu_ps(out.as_mut_ptr(), t);
        (_mm_movemask_ps(valid) as u32, out)
    }
}

/// Möller-Trumbore on a block's 4 lanes: each lane's `t` and whether it hits within
/// `[ray.tmin, ray.tmax]`, or with `BELOW_TMAX` within `[ray.tmin, ray.tmax)`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn block_test_sse<const BELOW_TMAX: bool>(
    b: &TriBlock,
    ray: &Ray,
) -> (std::arch::x86_64::__m128, std::arch::x86_64::__m128) {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is baseline on x86_64; loads are from 16-byte aligned arrays of 4 f32.
    unsafe {
        let ld = |a: &[f32; BLOCK]| _mm_load_ps(a.as_ptr());
        let (ox, oy, oz) = (
            _mm_set1_ps(ray.origin.x),
            _mm_set1_ps(ray.origin.y),
            _mm_set1_ps(ray.origin.z),
        );
        let (dx, dy, dz) = (
            _mm_set1_ps(ray.direction.x),
            _mm_set1_ps(ray.direction.y),
            _mm_set1_ps(ray.direction.z),
        );
        let cx = _mm_sub_ps(ld(&b.v0[0]), ox);
        let cy = _mm_sub_ps(ld(&b.v0[1]), oy);
        let cz = _mm_sub_ps(ld(&b.v0[2]), oz);
        let rx = _mm_sub_ps(_mm_mul_ps(dy, cz), _mm_mul_ps(dz, cy));
        let ry = _mm_sub_ps(_mm_mul_ps(dz, cx), _mm_mul_ps(dx, cz));
        let rz = _mm_sub_ps(_mm_mul_ps(dx, cy), _mm_mul_ps(dy, cx));
        let dot = |ax: __m128, ay: __m128, az: __m128, bx: __m128, by: __m128, bz: __m128| {
            _mm_add_ps(
                _mm_add_ps(_mm_mul_ps(ax, bx), _mm_mul_ps(ay, by)),
                _mm_mul_ps(az, bz),
            )
        };
        let (ngx, ngy, ngz) = (ld(&b.ng[0]), ld(&b.ng[1]), ld(&b.ng[2]));
        let inv_det = _mm_div_ps(_mm_set1_ps(1.0), dot(ngx, ngy, ngz, dx, dy, dz));
        let u = _mm_mul_ps(
            dot(rx, ry, rz, ld(&b.e2[0]), ld(&b.e2[1]), ld(&b.e2[2])),
            inv_det,
        );
        let v = _mm_mul_ps(
            dot(rx, ry, rz, ld(&b.e1[0]), ld(&b.e1[1]), ld(&b.e1[2])),
            inv_det,
        );
        let w = _mm_sub_ps(_mm_sub_ps(_mm_set1_ps(1.0), u), v);
        let t = _mm_mul_ps(dot(ngx, ngy, ngz, cx, cy, cz), inv_det);
        // All sign bits clear (u, v, w >= +0, no NaN with the sign set).
        let signs = _mm_or_ps(_mm_or_ps(u, v), w);
        let positive =
            _mm_castsi128_ps(_mm_cmpgt_epi32(_mm_castps_si128(signs), _mm_set1_epi32(-1)));
        let tmax = _mm_set1_ps(ray.tmax);
        let valid = _mm_and_ps(
            _mm_and_ps(positive, _mm_cmpneq_ps(inv_det, _mm_setzero_ps())),
            _mm_and_ps(
                _mm_cmpge_ps(t, _mm_set1_ps(ray.tmin)),
                match BELOW_TMAX {
                    true => _mm_cmplt_ps(t, tmax),
                    false => _mm_cmple_ps(t, tmax),
                },
            ),
        );
        (t, valid)
    }
}

/// `mask ? a_true : a_false` per lane with SSE2 bit operations.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn select_ps(
    a_false: std::arch::x86_64::__m128,
    a_true: std::arch::x86_64::__m128,
    mask: std::arch::x86_64::__m128,
) -> std::arch::x86_64::__m128 {
    use std::arch::x86_64::*;
    // SAFETY: SSE is baseline on x86_64.
    unsafe { _mm_or_ps(_mm_and_ps(mask, a_true), _mm_andnot_ps(mask, a_false)) }
}

#[cfg(test)]
mod tests {
    use glam::Vec3A;
    use obvhs::ray::Ray;

    use super::AvxOctant;
    use crate::wide::isa::NodeTest;
    use crate::wide::layout::WideNode;

    /// [`AvxOctant`]'s test for `ray`'s octant, from the origin or not.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,popcnt")]
    unsafe fn octant_test(node: &WideNode, ray: &Ray, at_origin: bool) -> (u32, [f32; WIDTH]) {
        macro_rules! by_octant {
            ($o:literal) => {
                match ray.inv_direction.is_negative_bitmask() {
                    0 => AvxOctant::<false, false, false, $o>::test(node, ray),
                    1 => AvxOctant::<true, false, false, $o>::test(node, ray),
                    2 => AvxOctant::<false, true, false, $o>::test(node, ray),
                    3 => AvxOctant::<true, true, false, $o>::test(node, ray),
                    4 => AvxOctant::<false, false, true, $o>::test(node, ray),
                    5 => AvxOctant::<true, false, true, $o>::test(node, ray),
                    6 => AvxOctant::<false, true, true, $o>::test(node, ray),
                    _ => AvxOctant::<true, true, true, $o>::test(node, ray),
                }
            };
        }
        match at_origin {
            true => by_octant!(true),
            false => by_octant!(false),
        }
    }

    #[test]
    fn octant_node_tests_are_the_min_max_tests() {
        // Sign-selected near and far planes: the same masks as obvhs' slab test and the
        // same entry distances as `Avx` (as numbers: a zero's sign may differ), in every
        // octant, from the origin and from elsewhere, axis-aligned directions and
        // negative zeros included, with rays whose `tmax` cuts some boxes.
        #[cfg(target_arch = "x86_64")]
        if Isa::detect() >= Isa::Avx {
            let tris = random_tris(400, 17);
            let boxes: Vec<_> = tris.iter().map(|t| t.aabb()).collect();
            let mut s = 23u64;
            let mut entered = 0;
            for chunk in boxes.chunks(WIDTH) {
                let mut node = EMPTY_NODE;
                for (lane, b) in chunk.iter().enumerate() {
                    for axis in 0..3 {
                        node.lo[axis][lane] = b.min[axis];
                        node.hi[axis][lane] = b.max[axis];
                    }
                }
                let mut rays = Vec::new();
                for k in 0..160 {
                    let o = match k % 2 {
                        0 => Vec3A::ZERO,
                        _ => Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 6.0 - 3.0,
                    };
                    let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                    let tmax = if k % 3 == 0 { 2.0 } else { 100.0 };
                    rays.push(Ray::new(o, (target - o).normalize(), 0.0, tmax));
                }
                for d in [
                    Vec3A::X,
                    Vec3A::NEG_X,
                    Vec3A::NEG_Y,
                    Vec3A::Z,
                    Vec3A::new(-0.0, 0.0, 1.0),
                    Vec3A::new(0.0, -0.0, -1.0),
                    Vec3A::new(-0.0, -1.0, -0.0),
                ] {
                    rays.push(Ray::new(Vec3A::ZERO, d, 0.0, 3.0));
                    rays.push(Ray::new(Vec3A::new(0.3, -0.2, 0.1), d, 0.0, 3.0));
                }
                for ray in rays {
                    let mut expected = 0u32;
                    for (lane, b) in chunk.iter().enumerate() {
                        if b.intersect_ray(&ray) < ray.tmax {
                            expected |= 1 << lane;
                        }
                    }
                    // SAFETY: AVX detected above.
                    let (general, octant) = unsafe {
                        (
                            avx_test(&node, &ray),
                            octant_test(&node, &ray, ray.origin == Vec3A::ZERO),
                        )
                    };
                    assert_eq!(general.0, expected);
                    assert_eq!(octant.0, expected, "{ray:?}");
                    for lane in 0..WIDTH {
                        let (a, b) = (octant.1[lane], general.1[lane]);
                        assert!(a == b || (a.is_nan() && b.is_nan()), "{a} vs {b}");
                    }
                    entered += expected.count_ones();
                }
            }
            assert!(
                entered > 200,
                "{entered} boxes entered: the rays must reach the boxes"
            );
        }
    }

    use crate::wide::isa::Isa;
    use crate::wide::layout::{EMPTY_NODE, WIDTH};
    use crate::wide::test_util::{avx_at_origin_test, avx_test, lcg, random_tris};

    #[test]
    fn rays_from_the_origin_get_the_same_node_tests() {
        // Camera rays start at the origin of render space and take `AvxAtOrigin`: same
        // masks as obvhs and the same entry distances as `Avx` (as numbers), including
        // axis-aligned directions, whose inverse obvhs clamps to +-1/EPSILON.
        #[cfg(target_arch = "x86_64")]
        if Isa::detect() >= Isa::Avx {
            let tris = random_tris(300, 7);
            let boxes: Vec<_> = tris.iter().map(|t| t.aabb()).collect();
            let mut s = 9u64;
            let mut entered = 0;
            for chunk in boxes.chunks(WIDTH) {
                let mut node = EMPTY_NODE;
                for (lane, b) in chunk.iter().enumerate() {
                    for axis in 0..3 {
                        node.lo[axis][lane] = b.min[axis];
                        node.hi[axis][lane] = b.max[axis];
                    }
                }
                let mut dirs: Vec<Vec3A> = (0..100)
                    .map(|_| {
                        let target = Vec3A::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
                        target.normalize()
                    })
                    .collect();
                dirs.extend([Vec3A::X, Vec3A::NEG_Y, Vec3A::Z, Vec3A::new(-0.0, 0.0, 1.0)]);
                for d in dirs {
                    let ray = Ray::new(Vec3A::ZERO, d, 0.0, 3.0);
                    let mut expected = 0u32;
                    for (lane, b) in chunk.iter().enumerate() {
                        if b.intersect_ray(&ray) < ray.tmax {
                            expected |= 1 << lane;
                        }
                    }
                    // SAFETY: AVX detected above.
                    let (general, at_origin) =
                        unsafe { (avx_test(&node, &ray), avx_at_origin_test(&node, &ray)) };
                    assert_eq!(general.0, expected);
                    assert_eq!(at_origin.0, expected);
                    for lane in 0..WIDTH {
                        let (a, b) = (at_origin.1[lane], general.1[lane]);
                        assert!(a == b || (a.is_nan() && b.is_nan()), "{a} vs {b}");
                    }
                    entered += expected.count_ones();
                }
            }
            assert!(
                entered > 100,
                "{entered} boxes entered: the rays must reach the boxes"
            );
        }
    }
}
