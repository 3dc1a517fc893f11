//! The sparse narrow-band brick grid and its sampler.
//!
//! A lattice of cubic cells (edge [`SparseGrid::cell_size`]) is cut into *brick cells* of
//! [`BRICK`]^3 cells. Only brick cells the surface passes near (within
//! [`SparseGrid::band_voxels`] cells of the brick's box) hold a *brick*: the signed distance
//! at its `(BRICK + 1)^3` lattice samples (the samples on a brick face are stored by both
//! bricks), so a trilinear lookup never reads another brick; a tricubic stencil that
//! crosses a brick face reads the neighbour's samples. Every other
//! brick cell stores one 32-bit word: a conservative lower bound of the distance at its
//! centre and the side (inside/outside). This is the layout of Unreal Engine's mesh distance
//! fields (8^3 bricks of 8-bit distances in a narrow band) and of OpenVDB narrow-band level
//! sets (Museth 2013, "VDB: High-resolution sparse volumes with dynamic topology"), reduced
//! to one level: a brick-presence map whose empty entries carry distances to the band.
//!
//! Memory is proportional to the surface area, not the volume: the bunny at 256 cells on its
//! longest side holds about as many bytes in 8-bit bricks as a dense 64^3 grid of f32.
//!
//! One concept per file: `format` (the stored words, sample encodings and reconstruction
//! kinds), `sample` (distance lookups: trilinear, tricubic across brick faces, the bound in
//! empty brick cells), `normals` (octahedral normal codes and the blend of the corners'
//! tangent planes); the grid itself and its invariants are here.

use glam::Vec3;

mod format;
mod normals;
mod sample;

pub(crate) use format::{BOUND_MAX, BOUND_STEPS, EMPTY, INSIDE};
pub use format::{BRICK, Quantization, Reconstruction, Samples, TRICUBIC_ZONE_CELLS};
pub use normals::{
    NORMAL_SOFTNESS_CELLS, PLANE_CORRECTION_CELLS, PLANE_SOFTNESS_CELLS, STORED_NORMAL_AGREEMENT,
    decode_octahedral, encode_octahedral,
};

/// A sparse narrow-band signed distance grid (mesh local frame and units).
///
/// **Lattice.** Sample `(i, j, k)` sits at `min + cell_size * (i, j, k)`; the lattice has
/// `BRICK * bricks[a]` cells along axis `a`. Brick cell `(bx, by, bz)` covers lattice cells
/// `BRICK * b .. BRICK * (b + 1)`; its word in [`SparseGrid::cells`] (x fastest) is either the
/// index of its brick (`< 2^31`) or an empty word (bit 31 set; bit 30 = inside; bits 0..30 a
/// lower bound of `|distance|` at the brick cell's centre in 1/16 cells, rounded down).
///
/// **Bricks.** Brick `n` holds `s^3` samples, `s = BRICK + 1 + 2 * apron`, at
/// [`SparseGrid::samples`]`[n * s^3 ..]`, local `(a, b, c)` (x fastest) being lattice sample
/// `BRICK * brick + (a, b, c) - apron`. Every sample is the exact distance to the closest
/// triangle, signed by the closest face's side or the generalized winding number (see
/// [`crate::bake_sparse`]), clamped to `[-clamp, clamp]` and then quantized.
///
/// **Values and accuracy.** In a brick: the trilinear (or tricubic) interpolant, within half
/// a cell diagonal of the true distance where the sign is right, plus the quantization
/// error ([`Quantization::max_error`]). In an empty brick cell: `side * max(band_voxels *
/// cell_size, b - |p - c|)` with `b` the stored bound at the centre `c`: a lower bound of the
/// true distance everywhere in it (the bake keeps every brick cell the surface comes within
/// `band_voxels` cells of), so sphere tracing never steps through a surface there, and far
/// from the surface it is within a brick's half diagonal of the true distance. Outside the
/// lattice box, as [`crate::DistanceGrid`]: `sqrt(a^2 + b^2)` from the value `b` at the
/// projection onto the box, `a` the distance to it.
#[derive(Debug, Clone, PartialEq)]
pub struct SparseGrid {
    /// Position of lattice sample `(0, 0, 0)`, mesh local frame.
    min: Vec3,
    /// Edge of the cubic cells, mesh units (> 0).
    cell_size: f32,
    /// Brick cells per axis (each >= 1).
    bricks: [u32; 3],
    /// Band half-width in cells: every brick cell the surface comes within this many cells
    /// of holds a brick.
    band_voxels: u32,
    /// Stored distances are clamped to `[-clamp, clamp]`, mesh units
    /// (`(band_voxels + 1) * cell_size`, see [`crate::CLAMP_BEYOND_BAND`]).
    clamp: f32,
    /// How bricks are interpolated (sets the apron).
    reconstruction: Reconstruction,
    /// One word per brick cell (x fastest): brick index or empty word.
    cells: Vec<u32>,
    /// Brick samples.
    samples: Samples,
    /// Octahedral normal codes, one per brick sample ([`Reconstruction::Normals`] only,
    /// empty otherwise).
    normals: Vec<u16>,
}

impl SparseGrid {
    /// Assembles a grid from its parts, checking every invariant the sampler relies on
    /// (positive finite cell and clamp, finite min, `cells` sized for `bricks`, samples a
    /// whole number of bricks, every brick word a valid brick index, no NaN sample), so
    /// sampling a grid never panics. `Err` names the first problem.
    #[allow(clippy::too_many_arguments)]
    pub fn from_parts(
        min: Vec3,
        cell_size: f32,
        bricks: [u32; 3],
        band_voxels: u32,
        clamp: f32,
        reconstruction: Reconstruction,
        cells: Vec<u32>,
        samples: Samples,
        normals: Vec<u16>,
    ) -> Result<SparseGrid, String> {
        if !(min.is_finite() && cell_size.is_finite() && cell_size > 0.0) {
            return Err("non-finite min or non-positive cell size".into());
        }
        if !(clamp.is_finite() && clamp > 0.0) {
            return Err(format!("clamp {clamp} is not a positive distance"));
        }
        if bricks.iter().any(|&b| b == 0 || b > 1 << 12) {
            return Err(format!("bad brick cell counts {bricks:?}"));
        }
        let n: usize = bricks.iter().map(|&b| b as usize).product();
        if cells.len() != n {
            return Err(format!(
                "{} brick-cell words, {bricks:?} need {n}",
                cells.len()
            ));
        }
        let per = (BRICK + 1 + 2 * reconstruction.apron()).pow(3) as usize;
        if !samples.len().is_multiple_of(per) {
            return Err(format!(
                "{} samples are not a whole number of {per}-sample bricks",
                samples.len()
            ));
        }
        let count = samples.len() / per;
        let mut used = vec![false; count];
        for &w in &cells {
            if w & EMPTY == 0 {
                match used.get_mut(w as usize) {
                    Some(u) if !*u => *u = true,
                    Some(_) => return Err(format!("brick {w} is referenced twice")),
                    None => return Err(format!("brick word {w} >= brick count {count}")),
                }
            }
        }
        if used.iter().any(|u| !u) {
            return Err("a stored brick is referenced by no brick cell".into());
        }
        if let Samples::F32(v) = &samples
            && v.iter().any(|x| !x.is_finite())
        {
            return Err("non-finite sample".into());
        }
        let want = match reconstruction {
            Reconstruction::Normals => samples.len(),
            _ => 0,
        };
        if normals.len() != want {
            return Err(format!(
                "{} normal codes, a {} grid of {} samples needs {want}",
                normals.len(),
                reconstruction.name(),
                samples.len()
            ));
        }
        Ok(SparseGrid {
            min,
            cell_size,
            bricks,
            band_voxels,
            clamp,
            reconstruction,
            cells,
            samples,
            normals,
        })
    }

    /// Position of lattice sample `(0, 0, 0)`, mesh local frame.
    pub fn min(&self) -> Vec3 {
        self.min
    }

    /// Edge of the cubic cells, mesh units.
    pub fn cell_size(&self) -> f32 {
        self.cell_size
    }

    /// Brick cells per axis.
    pub fn bricks(&self) -> [u32; 3] {
        self.bricks
    }

    /// Band half-width in cells.
    pub fn band_voxels(&self) -> u32 {
        self.band_voxels
    }

    /// Stored distances are clamped to `[-clamp, clamp]`, mesh units.
    pub fn clamp(&self) -> f32 {
        self.clamp
    }

    /// How bricks are interpolated.
    pub fn reconstruction(&self) -> Reconstruction {
        self.reconstruction
    }

    /// The brick-cell words (x fastest).
    pub fn cells(&self) -> &[u32] {
        &self.cells
    }

    /// The brick samples.
    pub fn samples(&self) -> &Samples {
        &self.samples
    }

    /// Octahedral normal codes, one per brick sample ([`Reconstruction::Normals`]; empty
    /// for the other reconstructions).
    pub fn normals(&self) -> &[u16] {
        &self.normals
    }

    /// Samples per brick edge, `BRICK + 1 + 2 * apron`.
    pub fn brick_edge(&self) -> usize {
        (BRICK + 1 + 2 * self.reconstruction.apron()) as usize
    }

    /// Samples per brick.
    pub fn samples_per_brick(&self) -> usize {
        self.brick_edge().pow(3)
    }

    /// Number of bricks stored.
    pub fn brick_count(&self) -> usize {
        self.samples.len() / self.samples_per_brick().max(1)
    }

    /// Lattice cells per axis (`BRICK * bricks`).
    pub fn lattice_cells(&self) -> [u32; 3] {
        self.bricks.map(|b| b * BRICK)
    }

    /// Effective dense resolution: lattice samples per axis.
    pub fn dims(&self) -> [u32; 3] {
        self.lattice_cells().map(|c| c + 1)
    }

    /// Box covered by the lattice: `(min, min + cell_size * cells)`.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let c = self.lattice_cells();
        (
            self.min,
            self.min + self.cell_size * Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32),
        )
    }

    /// Exact bytes held: brick samples, normal codes, brick-cell words and this struct.
    pub fn memory_bytes(&self) -> u64 {
        (self.samples.bytes()
            + self.normals.len() * 2
            + self.cells.len() * 4
            + std::mem::size_of::<Self>()) as u64
    }

    /// `(scale, offset)` decoding a stored code to a distance.
    fn decode(&self) -> (f64, f64) {
        match self.samples.quantization().max_code() {
            0 => (1.0, 0.0),
            m => {
                let c = self.clamp as f64;
                (2.0 * c / m as f64, -c)
            }
        }
    }
}

/// Grids the tests of every concept share.
#[cfg(test)]
mod test_util {
    use glam::Vec3;

    use super::*;

    /// A grid of `f(p) = p.x - 2.3` on 2x1x1 brick cells, brick 0 present, brick 1 empty.
    pub(super) fn linear(recon: Reconstruction, q: Quantization) -> SparseGrid {
        let a = recon.apron() as i32;
        let s = (BRICK as i32 + 1 + 2 * a) as usize;
        let h = 0.5f32;
        let clamp = 8.0;
        let mut vals = Vec::new();
        for _c in 0..s {
            for _b in 0..s {
                for i in 0..s {
                    let x = (i as i32 - a) as f32 * h;
                    vals.push((x - 2.3f32).clamp(-clamp, clamp));
                }
            }
        }
        let m = q.max_code() as f32;
        let samples = match q {
            Quantization::F32 => Samples::F32(vals),
            Quantization::U16 => Samples::U16(
                vals.iter()
                    .map(|v| ((v + clamp) / (2.0 * clamp) * m).round() as u16)
                    .collect(),
            ),
            Quantization::U8 => Samples::U8(
                vals.iter()
                    .map(|v| ((v + clamp) / (2.0 * clamp) * m).round() as u8)
                    .collect(),
            ),
        };
        // Brick cell 1 spans x in [4, 8]: its centre is 3.7 units (7.4 cells) from x = 2.3.
        let empty = EMPTY | ((7.4 * BOUND_STEPS) as u32 - 1);
        SparseGrid::from_parts(
            Vec3::ZERO,
            h,
            [2, 1, 1],
            2,
            clamp,
            recon,
            vec![0, empty],
            samples,
            vec![],
        )
        .unwrap()
    }

    /// `f(p) = 0.1 |p - (4, 4, 4)|^2 - 0.3` on 2x2x2 brick cells of cell 0.5 (all eight
    /// bricks meet at the paraboloid's centre), tricubic, f32; `drop` empties one brick.
    pub(super) fn paraboloid(drop: Option<usize>) -> SparseGrid {
        let h = 0.5f32;
        let s = (BRICK + 1) as usize;
        let f = |p: Vec3| 0.1 * (p - Vec3::splat(4.0)).length_squared() - 0.3;
        let mut cells = Vec::new();
        let mut vals = Vec::new();
        for n in 0..8usize {
            let b = [n & 1, (n >> 1) & 1, n >> 2];
            if drop == Some(n) {
                cells.push(EMPTY | INSIDE);
                continue;
            }
            cells.push((vals.len() / s.pow(3)) as u32);
            for c in 0..s {
                for bb in 0..s {
                    for a in 0..s {
                        let l = [a, bb, c];
                        let p = Vec3::from_array(
                            [0, 1, 2].map(|x| (BRICK as usize * b[x] + l[x]) as f32 * h),
                        );
                        vals.push(f(p));
                    }
                }
            }
        }
        SparseGrid::from_parts(
            Vec3::ZERO,
            h,
            [2, 2, 2],
            2,
            16.0,
            Reconstruction::Tricubic,
            cells,
            Samples::F32(vals),
            vec![],
        )
        .unwrap()
    }

    /// [`linear`] with [`Reconstruction::Normals`] and every normal `+x` (exact for the plane).
    pub(super) fn linear_normals(q: Quantization) -> SparseGrid {
        let g = linear(Reconstruction::Trilinear, q);
        let n = g.samples.len();
        SparseGrid::from_parts(
            g.min,
            g.cell_size,
            g.bricks,
            g.band_voxels,
            g.clamp,
            Reconstruction::Normals,
            g.cells.clone(),
            g.samples.clone(),
            vec![encode_octahedral(Vec3::X); n],
        )
        .unwrap()
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::test_util::*;
    use super::*;

    #[test]
    fn malformed_parts_are_refused() {
        let g = linear(Reconstruction::Trilinear, Quantization::U8);
        let parts = |cells: Vec<u32>, samples: Samples, recon: Reconstruction| {
            SparseGrid::from_parts(
                g.min,
                g.cell_size,
                g.bricks,
                2,
                g.clamp,
                recon,
                cells,
                samples,
                vec![],
            )
        };
        let t = Reconstruction::Trilinear;
        assert!(parts(g.cells.clone(), g.samples.clone(), t).is_ok());
        assert!(parts(vec![0], g.samples.clone(), t).is_err());
        assert!(parts(vec![5, EMPTY], g.samples.clone(), t).is_err());
        assert!(parts(vec![0, 0], g.samples.clone(), t).is_err());
        assert!(parts(vec![EMPTY, EMPTY], g.samples.clone(), t).is_err());
        assert!(parts(g.cells.clone(), Samples::U8(vec![0; 700]), t).is_err());
        // Both reconstructions share the layout.
        assert!(parts(g.cells.clone(), g.samples.clone(), Reconstruction::Tricubic).is_ok());
        assert!(parts(vec![0, EMPTY], Samples::F32(vec![f32::NAN; 729]), t).is_err());
        assert!(
            SparseGrid::from_parts(
                Vec3::NAN,
                1.0,
                [1, 1, 1],
                2,
                1.0,
                t,
                vec![EMPTY],
                Samples::U8(vec![]),
                vec![],
            )
            .is_err()
        );
        assert!(
            SparseGrid::from_parts(
                Vec3::ZERO,
                1.0,
                [1, 1, 1],
                2,
                0.0,
                t,
                vec![EMPTY],
                Samples::U8(vec![]),
                vec![],
            )
            .is_err()
        );
    }
}
