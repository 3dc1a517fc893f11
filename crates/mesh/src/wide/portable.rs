//! The portable node and triangle tests: plain per-lane code, the reference form every
//! SIMD level reproduces bit for bit.

use obvhs::ray::Ray;

use super::isa::NodeTest;
use super::layout::{BLOCK, TriBlock, WIDTH, WideNode};

/// Plain per-lane code (auto-vectorised where the compiler can).
pub(crate) struct Portable;

impl NodeTest for Portable {
    #[inline(always)]
    fn test(node: &WideNode, ray: &Ray) -> (u32, [f32; WIDTH]) {
        let mut entry = [0.0f32; WIDTH];
        let mut mask = 0u32;
        for lane in 0..WIDTH {
            let mut t_in = f32::NEG_INFINITY;
            let mut t_out = f32::INFINITY;
            for axis in 0..3 {
                let t1 = (node.lo[axis][lane] - ray.origin[axis]) * ray.inv_direction[axis];
                let t2 = (node.hi[axis][lane] - ray.origin[axis]) * ray.inv_direction[axis];
                t_in = t_in.max(t1.min(t2));
                t_out = t_out.min(t1.max(t2));
            }
            entry[lane] = t_in;
            if t_out >= t_in && t_out >= 0.0 && t_in < ray.tmax {
                mask |= 1 << lane;
            }
        }
        (mask, entry)
    }
}

/// The per-lane reference form of [`block_hits`].
#[inline(always)]
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
pub(super) fn block_hits_portable(b: &TriBlock, ray: &Ray) -> [f32; BLOCK] {
    let (o, d) = (ray.origin, ray.direction);
    let mut out = [f32::INFINITY; BLOCK];
    for lane in 0..BLOCK {
        let c = [
            b.v0[0][lane] - o.x,
            b.v0[1][lane] - o.y,
            b.v0[2][lane] - o.z,
        ];
        let r = [
            d.y * c[2] - d.z * c[1],
            d.z * c[0] - d.x * c[2],
            d.x * c[1] - d.y * c[0],
        ];
        let ng = [b.ng[0][lane], b.ng[1][lane], b.ng[2][lane]];
        let inv_det = 1.0 / (ng[0] * d.x + ng[1] * d.y + ng[2] * d.z);
        let u = (r[0] * b.e2[0][lane] + r[1] * b.e2[1][lane] + r[2] * b.e2[2][lane]) * inv_det;
        let v = (r[0] * b.e1[0][lane] + r[1] * b.e1[1][lane] + r[2] * b.e1[2][lane]) * inv_det;
        let w = 1.0 - u - v;
        let signs = u.to_bits() | v.to_bits() | w.to_bits();
        if inv_det != 0.0 && signs & 0x8000_0000 == 0 {
            let t = (ng[0] * c[0] + ng[1] * c[1] + ng[2] * c[2]) * inv_det;
            if t >= ray.tmin && t <= ray.tmax {
                out[lane] = t;
            }
        }
    }
    out
}
