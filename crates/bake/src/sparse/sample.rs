//! Distance lookups in a sparse grid: lattice values, trilinear and tricubic interpolation
//! (the tricubic stencil reading across brick faces), the lower bound in empty brick cells,
//! and the extension outside the lattice box.

use glam::{DVec3, Vec3};

use super::SparseGrid;
use super::format::{
    BOUND_MAX, BOUND_STEPS, BRICK, Code, EMPTY, INSIDE, Reconstruction, Samples,
    TRICUBIC_ZONE_CELLS,
};
use crate::grid::{clamp_to_lattice, extend_outside};

/// A lattice cell inside a brick: local cell `[i, j, k]` (`0..BRICK` per axis), the fraction
/// within it, and the sample index of its `(0, 0, 0)` corner (apron included).
pub(super) type BrickCell = ([usize; 3], DVec3, usize);

impl SparseGrid {
    /// The stored value of lattice sample `(i, j, k)` (decoded) from a brick holding it (a
    /// sample on a brick cell face belongs to the bricks on both sides, which hold the same
    /// value); `None` out of range or when no brick holds it.
    pub fn value(&self, i: u32, j: u32, k: u32) -> Option<f32> {
        let c = self.lattice_cells();
        if i > c[0] || j > c[1] || k > c[2] {
            return None;
        }
        let opts = |v: u32, a: usize| {
            let hi = (v / BRICK).min(self.bricks[a] - 1);
            let lo = if v.is_multiple_of(BRICK) && v > 0 {
                (v - 1) / BRICK
            } else {
                hi
            };
            [hi, lo]
        };
        let a = self.reconstruction.apron();
        let s = self.brick_edge();
        let (scale, off) = self.decode();
        for bz in opts(k, 2) {
            for by in opts(j, 1) {
                for bx in opts(i, 0) {
                    let w = self.cells[(bx + self.bricks[0] * (by + self.bricks[1] * bz)) as usize];
                    if w & EMPTY != 0 {
                        continue;
                    }
                    let l = [i - BRICK * bx + a, j - BRICK * by + a, k - BRICK * bz + a];
                    let at = w as usize * s * s * s
                        + l[0] as usize
                        + s * (l[1] as usize + s * l[2] as usize);
                    let v = match &self.samples {
                        Samples::F32(v) => v.get(at)?.get(),
                        Samples::U16(v) => v.get(at)?.get(),
                        Samples::U8(v) => v.get(at)?.get(),
                    };
                    return Some((v * scale + off) as f32);
                }
            }
        }
        None
    }

    /// Signed distance at `p` (mesh local frame), f32: the value of
    /// [`SparseGrid::sample_f64`] (same contract), with lattice coordinates and the
    /// trilinear interpolation in f32 (the tracer's hot path, as the dense grid's f32
    /// sampler). Beyond the lattice box the value at the nearest point of the box is
    /// extended as the f64 sampler does; tricubic evaluations go through f64. A NaN
    /// coordinate gives NaN; never panics.
    #[inline]
    pub fn sample(&self, p: Vec3) -> f32 {
        let c = self.lattice_cells();
        let maxc = Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32);
        let g = (p - self.min) * (1.0 / self.cell_size);
        if g.cmpge(Vec3::ZERO).all() && g.cmple(maxc).all() {
            return self.value_in_box_f32(g);
        }
        if g.is_nan() {
            return f32::NAN;
        }
        let gc = g.clamp(Vec3::ZERO, maxc);
        let outside = (g - gc).as_dvec3().length() * self.cell_size as f64;
        extend_outside(self.value_in_box_f32(gc) as f64, outside) as f32
    }

    /// [`SparseGrid::value_in_box`] in f32 at lattice coordinates `g` (cells, inside the
    /// box), trilinear in f32; the tricubic zone through the f64 path.
    #[inline]
    fn value_in_box_f32(&self, g: Vec3) -> f32 {
        let bs = BRICK as f32;
        let gb = g * (1.0 / bs);
        let bi = [
            (gb.x as u32).min(self.bricks[0] - 1),
            (gb.y as u32).min(self.bricks[1] - 1),
            (gb.z as u32).min(self.bricks[2] - 1),
        ];
        let w = self.cells[(bi[0] + self.bricks[0] * (bi[1] + self.bricks[1] * bi[2])) as usize];
        let corner = Vec3::new(bi[0] as f32, bi[1] as f32, bi[2] as f32) * bs;
        if w & EMPTY != 0 {
            let bound = (w & BOUND_MAX) as f32 * (1.0 / BOUND_STEPS as f32);
            let centre = corner + Vec3::splat(0.5 * bs);
            let d = (bound - (g - centre).length()).max(self.band_voxels as f32) * self.cell_size;
            return if w & INSIDE != 0 { -d } else { d };
        }
        let local = g - corner;
        let i = (local.x as usize).min(BRICK as usize - 1);
        let j = (local.y as usize).min(BRICK as usize - 1);
        let k = (local.z as usize).min(BRICK as usize - 1);
        let f = local - Vec3::new(i as f32, j as f32, k as f32);
        let s = self.brick_edge();
        let base = w as usize * s * s * s + i + s * (j + s * k);
        let (scale, off) = self.decode();
        let tri = match &self.samples {
            Samples::F32(v) => trilinear_f32(v, base, s, f),
            Samples::U16(v) => trilinear_f32(v, base, s, f),
            Samples::U8(v) => trilinear_f32(v, base, s, f),
        } * scale as f32
            + off as f32;
        if self.reconstruction == Reconstruction::Trilinear
            || tri.abs() >= (TRICUBIC_ZONE_CELLS as f32) * self.cell_size
        {
            return tri;
        }
        self.value_in_box(g.as_dvec3()) as f32
    }

    /// Signed distance at `p` (mesh local frame) in f64; see the type's docs for the value
    /// and its accuracy. A NaN coordinate gives NaN; never panics ([`SparseGrid::from_parts`]
    /// checked the layout).
    #[inline]
    pub fn sample_f64(&self, p: DVec3) -> f64 {
        let c = self.lattice_cells();
        let maxc = DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
        let h = self.cell_size as f64;
        // Inside the box (the common case): no clamping, no distance to the box. NaN fails
        // the comparisons and takes the general path, which maps it to NaN.
        let g = (p - self.min.as_dvec3()) * (1.0 / h);
        if g.cmpge(DVec3::ZERO).all() && g.cmple(maxc).all() {
            return self.value_in_box(g);
        }
        let (gc, outside) = clamp_to_lattice(p, self.min, h, maxc);
        extend_outside(self.value_in_box(gc), outside)
    }

    /// The value at lattice coordinates `g` (cells, inside the box).
    #[inline]
    fn value_in_box(&self, g: DVec3) -> f64 {
        let bs = BRICK as f64;
        let h = self.cell_size as f64;
        let (bi, w, cell) = self.cell_at(g);
        let Some(([i, j, k], f, base)) = cell else {
            let bound = (w & BOUND_MAX) as f64 / BOUND_STEPS;
            let centre = DVec3::new(
                bi[0] as f64 * bs + 0.5 * bs,
                bi[1] as f64 * bs + 0.5 * bs,
                bi[2] as f64 * bs + 0.5 * bs,
            );
            let d = (bound - (g - centre).length()).max(self.band_voxels as f64) * h;
            return if w & INSIDE != 0 { -d } else { d };
        };
        let s = self.brick_edge();
        let (scale, off) = self.decode();
        let tri = self.trilinear_at(base, f);
        if self.reconstruction == Reconstruction::Trilinear || tri.abs() >= TRICUBIC_ZONE_CELLS * h
        {
            return tri;
        }
        if self.reconstruction == Reconstruction::Normals {
            return self.planes(base, s, f, tri / h).map_or(tri, |d| d * h);
        }
        let inner = 1..=BRICK as usize - 2;
        if inner.contains(&i) && inner.contains(&j) && inner.contains(&k) {
            // The whole 4^3 stencil lies in this brick: it starts one sample below the cell.
            let o = base - 1 - s - s * s;
            let cubic = match &self.samples {
                Samples::F32(v) => tricubic_strided(v, o, s, f),
                Samples::U16(v) => tricubic_strided(v, o, s, f),
                Samples::U8(v) => tricubic_strided(v, o, s, f),
            };
            return cubic * scale + off;
        }
        let Some(stencil) = self.stencil_across_bricks(bi, [i, j, k]) else {
            return tri;
        };
        let cubic = match &self.samples {
            Samples::F32(v) => tricubic(v, &stencil, f),
            Samples::U16(v) => tricubic(v, &stencil, f),
            Samples::U8(v) => tricubic(v, &stencil, f),
        };
        cubic * scale + off
    }

    /// Where lattice point `g` (cells, inside the box) falls: its brick cell `bi`, that
    /// cell's word, and unless the brick cell is empty the [`BrickCell`].
    #[inline(always)]
    pub(super) fn cell_at(&self, g: DVec3) -> ([u32; 3], u32, Option<BrickCell>) {
        let [bx, by, _] = self.bricks;
        let bs = BRICK as f64;
        let gb = g * (1.0 / bs); // exact: BRICK is a power of two
        let bi = [
            (gb.x as u32).min(self.bricks[0] - 1),
            (gb.y as u32).min(self.bricks[1] - 1),
            (gb.z as u32).min(self.bricks[2] - 1),
        ];
        let w = self.cells[(bi[0] + bx * (bi[1] + by * bi[2])) as usize];
        if w & EMPTY != 0 {
            return (bi, w, None);
        }
        let local = g - DVec3::new(bi[0] as f64, bi[1] as f64, bi[2] as f64) * bs;
        let i = (local.x as usize).min(BRICK as usize - 1);
        let j = (local.y as usize).min(BRICK as usize - 1);
        let k = (local.z as usize).min(BRICK as usize - 1);
        let f = local - DVec3::new(i as f64, j as f64, k as f64);
        let s = self.brick_edge();
        let a = self.reconstruction.apron() as usize;
        let base = w as usize * s * s * s + (i + a) + s * ((j + a) + s * (k + a));
        (bi, w, Some(([i, j, k], f, base)))
    }

    /// The trilinear value (world units) of the cell whose `(0, 0, 0)` sample is at `base`,
    /// at fraction `f`.
    #[inline(always)]
    pub(super) fn trilinear_at(&self, base: usize, f: DVec3) -> f64 {
        let s = self.brick_edge();
        let (scale, off) = self.decode();
        (match &self.samples {
            Samples::F32(v) => trilinear(v, base, s, f),
            Samples::U16(v) => trilinear(v, base, s, f),
            Samples::U8(v) => trilinear(v, base, s, f),
        }) * scale
            + off
    }

    /// Sample indices of the 4^3 tricubic stencil of local cell `cell` (`0..BRICK` per axis)
    /// of brick cell `bi` (x fastest, see [`tricubic`]) when the stencil crosses a brick face.
    /// A stencil coordinate is local `-1..=BRICK + 1` of this brick: local `BRICK - 1` of the
    /// brick below for `-1`, this brick for `0..=BRICK`, local 1 of the brick above for
    /// `BRICK + 1` (shared face samples are equal in both bricks). `None` when a needed brick
    /// cell is off the lattice or empty.
    #[cold]
    #[inline(never)]
    fn stencil_across_bricks(&self, bi: [u32; 3], cell: [usize; 3]) -> Option<[usize; 64]> {
        // Per axis and stencil position: (brick offset + 1, local sample index).
        let per_axis = |a: usize| -> Option<[(usize, usize); 4]> {
            let mut out = [(1usize, 0usize); 4];
            for (t, o) in out.iter_mut().enumerate() {
                let l = cell[a] as i64 + t as i64 - 1;
                *o = if l < 0 {
                    if bi[a] == 0 {
                        return None;
                    }
                    (0, (l + BRICK as i64) as usize)
                } else if l > BRICK as i64 {
                    if bi[a] + 1 >= self.bricks[a] {
                        return None;
                    }
                    (2, (l - BRICK as i64) as usize)
                } else {
                    (1, l as usize)
                };
            }
            Some(out)
        };
        let axes = [per_axis(0)?, per_axis(1)?, per_axis(2)?];
        let s = self.brick_edge();
        let per = s * s * s;
        // Sample base of each neighbouring brick (offset + 1 per axis), looked up once.
        let mut bases: [Option<Option<usize>>; 27] = [None; 27];
        let mut idx = [0usize; 64];
        for (n, x) in idx.iter_mut().enumerate() {
            let (ex, ey, ez) = (axes[0][n & 3], axes[1][(n >> 2) & 3], axes[2][n >> 4]);
            let slot = ex.0 + 3 * (ey.0 + 3 * ez.0);
            let base = *bases[slot].get_or_insert_with(|| {
                let b = [
                    bi[0] + ex.0 as u32 - 1,
                    bi[1] + ey.0 as u32 - 1,
                    bi[2] + ez.0 as u32 - 1,
                ];
                let w =
                    self.cells[(b[0] + self.bricks[0] * (b[1] + self.bricks[1] * b[2])) as usize];
                (w & EMPTY == 0).then_some(w as usize * per)
            });
            *x = base? + ex.1 + s * (ey.1 + s * ez.1);
        }
        Some(idx)
    }
}

/// Catmull-Rom weights of the samples at `-1, 0, 1, 2` for a point at `t` in `[0, 1]`
/// (Keys 1981, cubic convolution with `a = -1/2`).
#[inline(always)]
fn catmull_rom(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

/// The trilinear interpolant (in stored codes) at `f` in the cell whose `(0, 0, 0)` sample
/// is `v[base]` (row stride `s`, plane stride `s^2`).
#[inline(always)]
fn trilinear<T: Code>(v: &[T], base: usize, s: usize, f: DVec3) -> f64 {
    let (sy, sz) = (s, s * s);
    let g = |o: usize| v[base + o].get();
    let x00 = g(0) + (g(1) - g(0)) * f.x;
    let x10 = g(sy) + (g(sy + 1) - g(sy)) * f.x;
    let x01 = g(sz) + (g(sz + 1) - g(sz)) * f.x;
    let x11 = g(sz + sy) + (g(sz + sy + 1) - g(sz + sy)) * f.x;
    let y0 = x00 + (x10 - x00) * f.y;
    let y1 = x01 + (x11 - x01) * f.y;
    y0 + (y1 - y0) * f.z
}

/// [`trilinear`] in f32.
#[inline(always)]
fn trilinear_f32<T: Code>(v: &[T], base: usize, s: usize, f: Vec3) -> f32 {
    let (sy, sz) = (s, s * s);
    let g = |o: usize| v[base + o].get_f32();
    let x00 = g(0) + (g(1) - g(0)) * f.x;
    let x10 = g(sy) + (g(sy + 1) - g(sy)) * f.x;
    let x01 = g(sz) + (g(sz + 1) - g(sz)) * f.x;
    let x11 = g(sz + sy) + (g(sz + sy + 1) - g(sz + sy)) * f.x;
    let y0 = x00 + (x10 - x00) * f.y;
    let y1 = x01 + (x11 - x01) * f.y;
    y0 + (y1 - y0) * f.z
}

/// [`tricubic`] over the 4^3 samples of one brick starting at `v[o]` (row stride `s`).
#[inline(always)]
fn tricubic_strided<T: Code>(v: &[T], o: usize, s: usize, f: DVec3) -> f64 {
    let (wx, wy, wz) = (catmull_rom(f.x), catmull_rom(f.y), catmull_rom(f.z));
    let mut acc = 0.0;
    for (c, wzc) in wz.iter().enumerate() {
        let mut plane = 0.0;
        for (b, wyb) in wy.iter().enumerate() {
            let r = &v[o + b * s + c * s * s..o + b * s + c * s * s + 4];
            let row =
                wx[0] * r[0].get() + wx[1] * r[1].get() + wx[2] * r[2].get() + wx[3] * r[3].get();
            plane += wyb * row;
        }
        acc += wzc * plane;
    }
    acc
}

/// The Catmull-Rom tricubic (in stored codes) at `f` over the 4^3 samples `v[stencil[n]]`,
/// `n = a + 4 b + 16 c` for the samples at offsets `(a - 1, b - 1, c - 1)` from the cell's
/// `(0, 0, 0)` sample.
#[inline(always)]
fn tricubic<T: Code>(v: &[T], stencil: &[usize; 64], f: DVec3) -> f64 {
    let (wx, wy, wz) = (catmull_rom(f.x), catmull_rom(f.y), catmull_rom(f.z));
    let mut acc = 0.0;
    for (c, wzc) in wz.iter().enumerate() {
        let mut plane = 0.0;
        for (b, wyb) in wy.iter().enumerate() {
            let r = &stencil[16 * c + 4 * b..16 * c + 4 * b + 4];
            let row = wx[0] * v[r[0]].get()
                + wx[1] * v[r[1]].get()
                + wx[2] * v[r[2]].get()
                + wx[3] * v[r[3]].get();
            plane += wyb * row;
        }
        acc += wzc * plane;
    }
    acc
}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};

    use super::*;
    use crate::sparse::test_util::*;
    use crate::sparse::*;

    #[test]
    fn reconstructions_reproduce_linear_fields_in_bricks() {
        for recon in [Reconstruction::Trilinear, Reconstruction::Tricubic] {
            for q in [Quantization::F32, Quantization::U16, Quantization::U8] {
                let g = linear(recon, q);
                let tol = q.max_error(g.clamp) as f64 + 1e-5;
                for p in [
                    DVec3::new(0.3, 1.7, 0.2),
                    DVec3::new(2.31, 0.0, 3.9),
                    DVec3::new(3.99, 4.0, 4.0),
                    DVec3::new(2.2, 2.2, 2.2),
                ] {
                    let d = g.sample_f64(p);
                    assert!((d - (p.x - 2.3)).abs() < tol, "{recon:?} {q:?} {p}: {d}");
                }
            }
        }
    }

    #[test]
    fn empty_cells_are_lower_bounds_with_the_band_floor() {
        let g = linear(Reconstruction::Trilinear, Quantization::F32);
        for x in [4.0, 4.5, 6.0, 7.9, 8.0] {
            for y in [0.0, 2.0, 4.0] {
                let p = DVec3::new(x, y, 1.0);
                let d = g.sample_f64(p);
                assert!(d <= p.x - 2.3 + 1e-9, "{p}: {d}");
                assert!(d >= 2.0 * 0.5 - 1e-9, "{p}: {d}");
            }
        }
        // Outside the box: never above the true distance to the plane x = 2.3.
        let p = DVec3::new(10.0, 1.0, 1.0);
        assert!(g.sample_f64(p) <= 7.7 + 1e-9);
        assert!(g.sample_f64(DVec3::splat(f64::NAN)).is_nan());
        assert!(g.sample(Vec3::splat(1e30)).is_finite());
    }

    #[test]
    fn tricubic_reads_across_brick_faces_and_falls_back_at_empty_ones() {
        let exact = |p: DVec3| 0.1 * (p - DVec3::splat(4.0)).length_squared() - 0.3;
        let g = paraboloid(None);
        let tri = linear(Reconstruction::Trilinear, Quantization::F32);
        assert_eq!(g.brick_edge(), tri.brick_edge());
        // Points in cells along brick faces, edges and the shared corner, all in the zone:
        // Catmull-Rom reproduces quadratics, so the stencil read across the bricks is exact
        // (the trilinear value is off by up to 0.1 * 3 * h^2 / 4 here).
        let pts = [
            DVec3::new(3.8, 4.1, 4.3),
            DVec3::new(4.2, 3.6, 3.9),
            DVec3::new(3.7, 3.9, 4.45),
            DVec3::new(4.05, 4.4, 3.55),
            DVec3::new(3.6, 3.6, 3.6),
        ];
        for p in pts {
            let d = g.sample_f64(p);
            assert!((d - exact(p)).abs() < 1e-5, "{p}: {d} vs {}", exact(p));
        }
        // With one brick empty, stencils reaching into it fall back to trilinear: finite,
        // within the trilinear error, and no longer exact.
        let g = paraboloid(Some(0));
        let p = DVec3::new(4.2, 4.1, 4.3); // in brick 7, its stencil reaches brick 0
        let d = g.sample_f64(p);
        assert!((d - exact(p)).abs() < 0.1 * 3.0 * 0.25 / 4.0 + 1e-6, "{d}");
        assert!((d - exact(p)).abs() > 1e-4, "{d}");
    }

    #[test]
    fn f32_sampling_agrees_with_f64_everywhere() {
        let mut grids = vec![paraboloid(None), paraboloid(Some(3))];
        for q in [Quantization::F32, Quantization::U16, Quantization::U8] {
            grids.push(linear(Reconstruction::Trilinear, q));
            grids.push(linear(Reconstruction::Tricubic, q));
        }
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for g in &grids {
            let (lo, hi) = g.bounds();
            let span = hi - lo;
            for _ in 0..4000 {
                // A margin around the box, so the outside branch is exercised too.
                let p = lo - 0.2 * span + 1.4 * span * Vec3::new(rnd(), rnd(), rnd());
                let (a, b) = (g.sample(p) as f64, g.sample_f64(p.as_dvec3()));
                assert!(
                    (a - b).abs() <= 1e-4 * (1.0 + b.abs()),
                    "{p}: f32 {a} vs f64 {b}"
                );
            }
            for p in [lo, hi, 0.5 * (lo + hi)] {
                let (a, b) = (g.sample(p) as f64, g.sample_f64(p.as_dvec3()));
                assert!(
                    (a - b).abs() <= 1e-4 * (1.0 + b.abs()),
                    "{p}: f32 {a} vs f64 {b}"
                );
            }
            assert!(g.sample(Vec3::new(f32::NAN, 1.0, 1.0)).is_nan());
        }
    }

    #[test]
    fn lattice_values_and_addressing() {
        let g = linear(Reconstruction::Tricubic, Quantization::F32);
        assert_eq!(g.brick_edge(), 9);
        assert_eq!(g.brick_count(), 1);
        assert_eq!(g.dims(), [17, 9, 9]);
        for i in 0..=8 {
            let v = g.value(i, 3, 5).unwrap();
            assert!((v - (i as f32 * 0.5 - 2.3)).abs() < 1e-6);
        }
        assert_eq!(g.value(9, 0, 0), None); // brick cell 1 is empty
        assert!(g.value(8, 0, 0).is_some()); // on the face: brick 0 holds it
        assert_eq!(g.value(17, 0, 0), None);
        assert_eq!(
            g.memory_bytes(),
            (9usize.pow(3) * 4 + 8 + std::mem::size_of::<SparseGrid>()) as u64
        );
    }

    #[test]
    fn catmull_rom_weights_sum_to_one_and_interpolate() {
        for t in [0.0, 0.25, 0.5, 0.9, 1.0] {
            let w = catmull_rom(t);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            // Reproduces linear data: sum w_i * (i - 1) = t.
            let lin: f64 = w
                .iter()
                .enumerate()
                .map(|(i, w)| w * (i as f64 - 1.0))
                .sum();
            assert!((lin - t).abs() < 1e-12);
        }
        assert_eq!(catmull_rom(0.0), [0.0, 1.0, 0.0, 0.0]);
    }
}
