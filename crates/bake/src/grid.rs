//! The baked signed distance grid and its trilinear sampler.

use glam::{DVec3, Vec3};

/// Signed distances sampled on a regular lattice, in the mesh's local frame and units.
///
/// Sample `(i, j, k)` sits at `min + cell_size * (i, j, k)` and is stored at
/// `values[i + dims[0] * (j + dims[1] * k)]` (x fastest). Negative inside, positive outside.
///
/// **Accuracy.** Each stored value is the exact distance to the closest triangle (f32) with
/// the sign of the generalized winding number. Trilinear interpolation of samples of any
/// 1-Lipschitz function `f` (the true signed distance, where the sign is right) differs from
/// `f` by at most the weighted distance to the cell corners, `sqrt(3)/2 * cell_size` (half a
/// cell diagonal): it never over-estimates by more than that. Flat regions are reproduced
/// exactly; edges, corners and features thinner than a cell are rounded off.
///
/// **Lipschitz behaviour.** Each partial derivative of the trilinear interpolant is a convex
/// blend of sample differences along one axis divided by `cell_size`, hence at most 1 in
/// magnitude: the gradient norm is at most `sqrt(3)` in the worst case (three axes at slope
/// 1 at once, which a distance function cannot do at a sample but the interpolant can
/// between samples near creases), and close to 1 elsewhere. A sphere tracer that needs a
/// strict bound divides by `sqrt(3)`; in practice overshoot is limited by the half-diagonal
/// error bound above.
///
/// **Outside the grid box** [`DistanceGrid::sample`] returns `sqrt(a^2 + b^2)` where `a` is
/// the distance to the box and `b` the (positive) sample at the clamped point `q`: since the
/// mesh lies inside the box and `q` is the projection of `p` onto it, every mesh point `m`
/// has `|p - m|^2 >= a^2 + |q - m|^2`, so this never over-estimates beyond the sample error
/// at `q`, unlike `a + b`, which can over-estimate by up to `b`. It is continuous (equals `b`
/// on the box) and 1-Lipschitz in `a`. A non-positive `b` (a box face inside the solid,
/// which the padding makes impossible for meshes whose winding number is 0 there) gives
/// `b + a`. Never NaN for finite input; a non-finite coordinate gives a non-finite result.
#[derive(Debug, Clone, PartialEq)]
pub struct DistanceGrid {
    /// Position of sample `(0, 0, 0)` (the box's minimum corner), mesh local frame.
    pub min: Vec3,
    /// Edge length of the cubic cells, mesh units (> 0).
    pub cell_size: f32,
    /// Samples per axis (each >= 2).
    pub dims: [u32; 3],
    /// Signed distances, `dims[0] * dims[1] * dims[2]` of them, x fastest.
    pub values: Vec<f32>,
}

impl DistanceGrid {
    /// Box covered by the samples: `(min, min + cell_size * (dims - 1))`.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let n = Vec3::new(
            (self.dims[0].max(1) - 1) as f32,
            (self.dims[1].max(1) - 1) as f32,
            (self.dims[2].max(1) - 1) as f32,
        );
        (self.min, self.min + n * self.cell_size)
    }

    /// Exact bytes held: the samples (`values.len() * 4`) plus this struct itself.
    pub fn memory_bytes(&self) -> u64 {
        (self.values.len() * std::mem::size_of::<f32>() + std::mem::size_of::<Self>()) as u64
    }

    /// The stored sample `(i, j, k)`; `None` out of range.
    pub fn value(&self, i: u32, j: u32, k: u32) -> Option<f32> {
        let [nx, ny, nz] = self.dims;
        if i >= nx || j >= ny || k >= nz {
            return None;
        }
        self.values
            .get(i as usize + nx as usize * (j as usize + ny as usize * k as usize))
            .copied()
    }

    /// Signed distance at `p` (mesh local frame), f32: trilinear inside the grid box,
    /// `sqrt(a^2 + b^2)` outside (see the type's docs for accuracy and Lipschitz bounds).
    /// An empty or malformed grid (values shorter than dims) gives `f32::INFINITY`.
    #[inline]
    pub fn sample(&self, p: Vec3) -> f32 {
        let [nx, ny, nz] = self.dims;
        let n = nx as usize * ny as usize * nz as usize;
        if nx < 2 || ny < 2 || nz < 2 || self.values.len() < n {
            return f32::INFINITY;
        }
        let inv = 1.0 / self.cell_size;
        let g = (p - self.min) * inv;
        let maxc = Vec3::new((nx - 1) as f32, (ny - 1) as f32, (nz - 1) as f32);
        let gc = g.clamp(Vec3::ZERO, maxc);
        // NaN coordinates: clamp keeps NaN; map them to the corner so indexing stays safe.
        let gc = Vec3::select(gc.cmpeq(gc), gc, Vec3::ZERO);
        let off = g - gc;
        let i = (gc.x as u32).min(nx - 2);
        let j = (gc.y as u32).min(ny - 2);
        let k = (gc.z as u32).min(nz - 2);
        let f = gc - Vec3::new(i as f32, j as f32, k as f32);
        let sx = 1usize;
        let sy = nx as usize;
        let sz = nx as usize * ny as usize;
        let base = i as usize + sy * j as usize + sz * k as usize;
        let v = &self.values;
        let c000 = v[base];
        let c100 = v[base + sx];
        let c010 = v[base + sy];
        let c110 = v[base + sy + sx];
        let c001 = v[base + sz];
        let c101 = v[base + sz + sx];
        let c011 = v[base + sz + sy];
        let c111 = v[base + sz + sy + sx];
        let x00 = c000 + (c100 - c000) * f.x;
        let x10 = c010 + (c110 - c010) * f.x;
        let x01 = c001 + (c101 - c001) * f.x;
        let x11 = c011 + (c111 - c011) * f.x;
        let y0 = x00 + (x10 - x00) * f.y;
        let y1 = x01 + (x11 - x01) * f.y;
        let b = y0 + (y1 - y0) * f.z;
        if off == Vec3::ZERO {
            b
        } else {
            // Outside the box (or NaN): f64 so far points neither overflow nor lose `b`.
            let a = off.as_dvec3().length() * self.cell_size as f64;
            extend_outside(b as f64, a) as f32
        }
    }

    /// [`DistanceGrid::sample`] in f64 (interpolation in f64 over the f32 samples, so
    /// points far outside keep their precision). Same contract.
    #[inline]
    pub fn sample_f64(&self, p: DVec3) -> f64 {
        let [nx, ny, nz] = self.dims;
        let n = nx as usize * ny as usize * nz as usize;
        if nx < 2 || ny < 2 || nz < 2 || self.values.len() < n {
            return f64::INFINITY;
        }
        let maxc = DVec3::new((nx - 1) as f64, (ny - 1) as f64, (nz - 1) as f64);
        let (gc, outside) = clamp_to_lattice(p, self.min, self.cell_size as f64, maxc);
        let i = (gc.x as u32).min(nx - 2);
        let j = (gc.y as u32).min(ny - 2);
        let k = (gc.z as u32).min(nz - 2);
        let f = gc - DVec3::new(i as f64, j as f64, k as f64);
        let sy = nx as usize;
        let sz = nx as usize * ny as usize;
        let base = i as usize + sy * j as usize + sz * k as usize;
        let v = |o: usize| self.values[base + o] as f64;
        let x00 = v(0) + (v(1) - v(0)) * f.x;
        let x10 = v(sy) + (v(sy + 1) - v(sy)) * f.x;
        let x01 = v(sz) + (v(sz + 1) - v(sz)) * f.x;
        let x11 = v(sz + sy) + (v(sz + sy + 1) - v(sz + sy)) * f.x;
        let y0 = x00 + (x10 - x00) * f.y;
        let y1 = x01 + (x11 - x01) * f.y;
        let b = y0 + (y1 - y0) * f.z;
        extend_outside(b, outside)
    }
}

/// Lattice coordinates of `p` for a lattice with sample 0 at `min` and cell `h`, clamped into
/// `[0, max_cell]` (NaN coordinates to 0), and the distance from `p` to that box in world
/// units (NaN for a NaN point).
#[inline]
pub(crate) fn clamp_to_lattice(p: DVec3, min: Vec3, h: f64, max_cell: DVec3) -> (DVec3, f64) {
    let g = (p - min.as_dvec3()) / h;
    let gc = g.clamp(DVec3::ZERO, max_cell);
    let gc = DVec3::select(gc.cmpeq(gc), gc, DVec3::ZERO);
    (gc, (g - gc).length() * h)
}

/// The grid value at a point `outside` away from the box, given the value `b` at the nearest
/// point of the box: `hypot(outside, b)` outside a positive surface distance, `b + outside`
/// otherwise; `b` itself inside the box. Never above the true distance where `b` is not.
#[inline]
pub(crate) fn extend_outside(b: f64, outside: f64) -> f64 {
    if outside > 0.0 || outside.is_nan() {
        if b > 0.0 {
            // `hypot` (a libm call, 3% of a sparse-grid render's instructions) only where
            // the squares could overflow.
            if outside < 1e150 && b < 1e150 {
                (outside * outside + b * b).sqrt()
            } else {
                outside.hypot(b)
            }
        } else {
            b + outside
        }
    } else {
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn linear_grid() -> DistanceGrid {
        // f(p) = p.x - 1 on [0,2]^3 with cell 0.5.
        let dims = [5u32, 5, 5];
        let mut values = Vec::new();
        for _k in 0..5 {
            for _j in 0..5 {
                for i in 0..5 {
                    values.push(i as f32 * 0.5 - 1.0);
                }
            }
        }
        DistanceGrid {
            min: Vec3::ZERO,
            cell_size: 0.5,
            dims,
            values,
        }
    }

    #[test]
    fn trilinear_reproduces_linear_fields() {
        let g = linear_grid();
        for p in [
            Vec3::new(0.3, 1.7, 0.2),
            Vec3::new(1.99, 0.0, 2.0),
            Vec3::new(2.0, 2.0, 2.0),
        ] {
            assert!((g.sample(p) - (p.x - 1.0)).abs() < 1e-6);
            assert!((g.sample_f64(p.as_dvec3()) - (p.x as f64 - 1.0)).abs() < 1e-6);
        }
        assert_eq!(g.bounds(), (Vec3::ZERO, Vec3::splat(2.0)));
        assert_eq!(
            g.memory_bytes(),
            125 * 4 + std::mem::size_of::<DistanceGrid>() as u64
        );
    }

    #[test]
    fn outside_is_continuous_and_finite() {
        let g = linear_grid();
        // Across the +x face: b = 1 at the face.
        let a = g.sample(Vec3::new(2.0, 1.0, 1.0));
        let b = g.sample(Vec3::new(2.0001, 1.0, 1.0));
        assert!((a - b).abs() < 1e-3);
        let far = g.sample(Vec3::new(5.0, 1.0, 1.0));
        assert!((far - (9.0f32 + 1.0).sqrt()).abs() < 1e-5);
        // Across the -x face: b = -1 there, so b + a.
        assert!((g.sample(Vec3::new(-1.0, 1.0, 1.0)) - 0.0).abs() < 1e-6);
        assert!(g.sample(Vec3::splat(f32::NAN)).is_nan());
        assert!(g.sample(Vec3::splat(1e30)).is_finite());
    }

    #[test]
    fn malformed_grids_do_not_panic() {
        let mut g = linear_grid();
        g.values.truncate(10);
        assert_eq!(g.sample(Vec3::ONE), f32::INFINITY);
        g.dims = [1, 1, 1];
        assert_eq!(g.sample_f64(DVec3::ONE), f64::INFINITY);
        assert_eq!(g.value(9, 0, 0), None);
    }
}
