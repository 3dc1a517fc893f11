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
    EMPTY, LEAF, STACK, WIDTH, WideBvh, WideNode, closest_in_blocks, entered_children, leaf_range,
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
    if bvh.avx {
        // SAFETY: `avx` is set only when the CPU reports AVX and POPCNT.
        return Some(unsafe { closest8_avx(bvh, &bounds, rays, visits, tests) });
    }
    Some(closest8_with(bvh, &bounds, rays, visits, tests))
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,popcnt")]
unsafe fn closest8_avx(
    bvh: &WideBvh,
    bounds: &Bounds,
    rays: &mut [Ray; PACKET],
    visits: &mut u32,
    tests: &mut [u32; PACKET],
) -> [Option<(u32, f32)>; PACKET] {
    closest8_with(bvh, bounds, rays, visits, tests)
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
