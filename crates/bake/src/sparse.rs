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

use glam::{DVec3, Vec3};

use crate::grid::{clamp_to_lattice, extend_outside};

/// Cells along each edge of a brick.
pub const BRICK: u32 = 8;

/// Tag bit of an empty brick cell's word (the rest is its distance bound and side).
pub(crate) const EMPTY: u32 = 1 << 31;
/// Side bit of an empty brick cell's word: set when the brick cell is inside the solid.
pub(crate) const INSIDE: u32 = 1 << 30;
/// Largest distance bound an empty word can hold, in 1/[`BOUND_STEPS`] cells.
pub(crate) const BOUND_MAX: u32 = INSIDE - 1;
/// Subdivisions of a cell in an empty word's distance bound (rounded down).
pub(crate) const BOUND_STEPS: f64 = 16.0;

/// How brick samples are stored (`f32`, `u16`, `u8` as data).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Hash,
    Default,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Quantization {
    /// 32-bit floats: exact distances (clamped to the band, see [`SparseGrid::clamp`]).
    #[default]
    F32,
    /// 16 bits per sample over `[-clamp, clamp]`: error at most `clamp / 65535`.
    U16,
    /// 8 bits per sample over `[-clamp, clamp]`: error at most `clamp / 255` (2% of a cell
    /// at the default band).
    U8,
}

impl Quantization {
    /// Bytes per stored sample.
    pub fn bytes(self) -> usize {
        match self {
            Quantization::F32 => 4,
            Quantization::U16 => 2,
            Quantization::U8 => 1,
        }
    }

    /// Largest code (`0` for f32, which is not quantized).
    pub fn max_code(self) -> u32 {
        match self {
            Quantization::F32 => 0,
            Quantization::U16 => u16::MAX as u32,
            Quantization::U8 => u8::MAX as u32,
        }
    }

    /// Worst-case quantization error for samples clamped to `[-clamp, clamp]` (round to
    /// nearest: half a step), mesh units.
    pub fn max_error(self, clamp: f32) -> f32 {
        match self.max_code() {
            0 => 0.0,
            m => clamp / m as f32,
        }
    }

    /// Lower-case name (`f32`, `u16`, `u8`).
    pub fn name(self) -> &'static str {
        match self {
            Quantization::F32 => "f32",
            Quantization::U16 => "u16",
            Quantization::U8 => "u8",
        }
    }

    pub(crate) fn code(self) -> u8 {
        match self {
            Quantization::F32 => 0,
            Quantization::U16 => 1,
            Quantization::U8 => 2,
        }
    }

    pub(crate) fn from_code(c: u8) -> Option<Self> {
        match c {
            0 => Some(Quantization::F32),
            1 => Some(Quantization::U16),
            2 => Some(Quantization::U8),
            _ => None,
        }
    }
}

/// How a brick is interpolated between its samples (`trilinear`, `tricubic`, `normals` as
/// data).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Hash,
    Default,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Reconstruction {
    /// Trilinear over the 8 surrounding samples: exact for linear fields (flat facets), C0,
    /// its gradient jumps across cell faces. Error at most half a cell diagonal.
    #[default]
    Trilinear,
    /// Tricubic Catmull-Rom (Catmull & Rom 1974; Keys 1981, `a = -1/2`) over the 4^3
    /// surrounding samples, within [`TRICUBIC_ZONE_CELLS`] of the surface (trilinear
    /// elsewhere): interpolating, exact for quadratic fields, C1, so normals are continuous
    /// across cells. Stores the same 9^3 samples per brick as trilinear: a stencil that
    /// crosses a brick face reads the neighbouring brick's samples (the ring of cells along
    /// a brick's faces costs up to 8 brick-word lookups instead of none), and falls back to
    /// the trilinear value where a neighbouring brick cell is empty or off the lattice (a
    /// seam, rare within the zone: empty brick cells lie beyond the band). 8x the sample
    /// reads near the surface. Not a strict bound: the kernel overshoots by a few percent of
    /// the sample differences.
    Tricubic,
    /// Gradient-corrected: every brick sample also stores the unit normal of its closest
    /// triangle (octahedral, 2 x 8 bits, [`encode_octahedral`]), and within
    /// [`TRICUBIC_ZONE_CELLS`] of the surface the value is the blend of the 8 cell corners'
    /// tangent planes `e_c(p) = d_c + n_c . (p - x_c)` ("Hermite" data as in dual
    /// contouring, Ju et al. 2002), weighted by `t_c / (sigma^2 + e_c^2)^2` (`t_c` the
    /// trilinear weights, `sigma` = [`PLANE_SOFTNESS_CELLS`]): the planes that pass through
    /// `p` dominate, so a flat facet seen by one corner is reproduced with its own normal
    /// instead of the cell's average, and the normal no longer carries the distances'
    /// quantization noise. The result stays within [`PLANE_CORRECTION_CELLS`] of the
    /// trilinear value (smoothly clamped), so planes extended past their facet cannot move
    /// silhouettes. C0 (the weights are continuous), exact for one plane; 3 bytes per
    /// sample with u8 distances instead of 1. Trilinear farther out.
    Normals,
}

/// Softness of [`Reconstruction::Normals`]' plane weights, in cells: planes within about
/// this distance of the point count about equally. Chosen on dragon_res3 at 128 effective
/// (mean normal error 5.29 degrees at 0.1 against 5.32 at 0.05 and 5.53 at 0.2).
pub const PLANE_SOFTNESS_CELLS: f64 = 0.1;

/// Largest change, in cells, [`Reconstruction::Normals`] makes to the trilinear value (a
/// smooth clamp, `c tanh(x / c)`). Unlimited, a corner's tangent plane extended past the
/// edge of its facet adds false surface at silhouettes (dragon_res3 at 128: 0.59% silhouette
/// pixels wrong, 8.2 degrees, against 0.05% and 6.6 degrees trilinear); at 0.1 cells the
/// silhouettes are the trilinear ones (0.04%) and the normal error 5.29 degrees (0.05:
/// 5.36, 0.3: 5.90).
pub const PLANE_CORRECTION_CELLS: f64 = 0.1;

/// Least agreement `|sum wn n| / sum wn` of the corners' weighted normals for
/// [`SparseGrid::stored_normal`] to answer.
pub const STORED_NORMAL_AGREEMENT: f64 = 0.99;

/// Softness of [`SparseGrid::stored_normal`]'s weights `t_c / (sigma^2 + e_c^2)^2`, in
/// cells: much sharper than [`PLANE_SOFTNESS_CELLS`], so the normal is the facet whose plane
/// passes through the point rather than a mix. Chosen on the stability study's sparse u8
/// bakes (mean normal error at 128 / 256 / 512 effective, sigma 0.1 -> 0.03 -> 0.02 ->
/// 0.01: dragon_res3 5.43 / 3.37 / 2.00 -> 5.00 / 2.91 / 1.68 -> 4.84 / 2.78 / 1.59 ->
/// 4.74 / 2.66 / 1.52; bunny 1.52 / 0.94 / 0.64 -> 1.30 / 0.80 / 0.53 -> 1.23 / 0.76 /
/// 0.50 -> 1.14 / 0.70 / 0.47), the data it is judged on: a choice to recheck on other
/// meshes.
pub const NORMAL_SOFTNESS_CELLS: f64 = 0.01;

/// Octahedral code of a unit vector (Meyer et al. 2010, "On floating-point normal vectors";
/// Cigolle et al. 2014): the vector projected onto the octahedron `|x| + |y| + |z| = 1`,
/// the lower half folded over, `x` and `y` in 8 bits each (low byte `x`). About 0.3 degrees
/// mean error. A zero or non-finite vector encodes `+z`.
pub fn encode_octahedral(n: Vec3) -> u16 {
    let l1 = n.x.abs() + n.y.abs() + n.z.abs();
    if !(l1.is_finite() && l1 > 0.0) {
        return encode_octahedral(Vec3::Z);
    }
    let (mut x, mut y) = (n.x / l1, n.y / l1);
    if n.z < 0.0 {
        (x, y) = ((1.0 - y.abs()) * x.signum(), (1.0 - x.abs()) * y.signum());
    }
    let q = |v: f32| (((v.clamp(-1.0, 1.0) + 1.0) * 0.5 * 255.0).round()) as u16;
    q(x) | (q(y) << 8)
}

/// The unit vector of an octahedral code ([`encode_octahedral`]); every code decodes to a
/// unit vector.
#[inline(always)]
pub fn decode_octahedral(c: u16) -> DVec3 {
    let x = (c & 0xff) as f64 * (2.0 / 255.0) - 1.0;
    let y = (c >> 8) as f64 * (2.0 / 255.0) - 1.0;
    let z = 1.0 - x.abs() - y.abs();
    let (x, y) = if z < 0.0 {
        ((1.0 - y.abs()) * x.signum(), (1.0 - x.abs()) * y.signum())
    } else {
        (x, y)
    };
    DVec3::new(x, y, z).normalize()
}

/// Distance (in cells, by the trilinear value) below which [`Reconstruction::Tricubic`]
/// evaluates the cubic; farther out the trilinear value (a step size) is enough.
pub const TRICUBIC_ZONE_CELLS: f64 = 1.5;

impl Reconstruction {
    /// Samples of apron on each side of a brick beyond its `BRICK + 1` own samples: none for
    /// either reconstruction (tricubic stencils that cross a brick face read the neighbour
    /// brick), kept as the layout parameter of the cache and the bake.
    pub fn apron(self) -> u32 {
        match self {
            Reconstruction::Trilinear | Reconstruction::Tricubic | Reconstruction::Normals => 0,
        }
    }

    /// Lower-case name (`trilinear`, `tricubic`).
    pub fn name(self) -> &'static str {
        match self {
            Reconstruction::Trilinear => "trilinear",
            Reconstruction::Tricubic => "tricubic",
            Reconstruction::Normals => "normals",
        }
    }

    pub(crate) fn code(self) -> u8 {
        match self {
            Reconstruction::Trilinear => 0,
            Reconstruction::Tricubic => 1,
            Reconstruction::Normals => 2,
        }
    }

    pub(crate) fn from_code(c: u8) -> Option<Self> {
        match c {
            0 => Some(Reconstruction::Trilinear),
            1 => Some(Reconstruction::Tricubic),
            2 => Some(Reconstruction::Normals),
            _ => None,
        }
    }
}

/// The samples of every brick, brick after brick (`samples_per_brick` each, x fastest).
#[derive(Debug, Clone, PartialEq)]
pub enum Samples {
    /// Distances, mesh units.
    F32(Vec<f32>),
    /// Codes: distance `= -clamp + code * (2 clamp / 65535)`.
    U16(Vec<u16>),
    /// Codes: distance `= -clamp + code * (2 clamp / 255)`.
    U8(Vec<u8>),
}

impl Samples {
    /// Number of stored samples.
    pub fn len(&self) -> usize {
        match self {
            Samples::F32(v) => v.len(),
            Samples::U16(v) => v.len(),
            Samples::U8(v) => v.len(),
        }
    }

    /// True when no sample is stored.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The quantization these samples use.
    pub fn quantization(&self) -> Quantization {
        match self {
            Samples::F32(_) => Quantization::F32,
            Samples::U16(_) => Quantization::U16,
            Samples::U8(_) => Quantization::U8,
        }
    }

    /// Bytes of the samples.
    pub fn bytes(&self) -> usize {
        self.len() * self.quantization().bytes()
    }
}

/// A stored sample type and its decoding to a distance (`code * scale + offset`).
trait Code: Copy {
    fn get(self) -> f64;
    fn get_f32(self) -> f32;
}
impl Code for f32 {
    #[inline(always)]
    fn get(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn get_f32(self) -> f32 {
        self
    }
}
impl Code for u16 {
    #[inline(always)]
    fn get(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn get_f32(self) -> f32 {
        self as f32
    }
}
impl Code for u8 {
    #[inline(always)]
    fn get(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn get_f32(self) -> f32 {
        self as f32
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

/// [`SparseGrid::corner_planes`]' sums over a cell's 8 corners.
#[derive(Default)]
struct CornerPlanes {
    /// `sum w e`: tangent-plane values (cells) weighted by [`PLANE_SOFTNESS_CELLS`].
    value: f64,
    /// `sum w`.
    weight: f64,
    /// `sum wn n`: normals weighted by [`NORMAL_SOFTNESS_CELLS`].
    normal: DVec3,
    /// `sum wn`.
    normal_weight: f64,
}

/// A lattice cell inside a brick: local cell `[i, j, k]` (`0..BRICK` per axis), the fraction
/// within it, and the sample index of its `(0, 0, 0)` corner (apron included).
type BrickCell = ([usize; 3], DVec3, usize);

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

    /// [`Reconstruction::Normals`]' value, in cells, at `f` in the cell whose `(0, 0, 0)`
    /// sample is at `base` (row stride `s`), given the trilinear value `tri` (cells): the
    /// blend `P` of the corners' tangent planes, kept within [`PLANE_CORRECTION_CELLS`] of
    /// `tri` as `tri + c tanh((P - tri) / c)`. `None` when the weights vanish or a sample or
    /// normal code is missing (then the caller keeps `tri`).
    #[inline]
    fn planes(&self, base: usize, s: usize, f: DVec3, tri: f64) -> Option<f64> {
        let p = self.corner_planes(base, s, f)?;
        let c = PLANE_CORRECTION_CELLS;
        Some(tri + c * ((p.value / p.weight - tri) / c).tanh())
    }

    /// The weighted sums of [`SparseGrid::planes`]' blend at `f` in the cell whose
    /// `(0, 0, 0)` sample is at `base` over the 8 corners, and of the corners' normals with
    /// the sharper weights of [`NORMAL_SOFTNESS_CELLS`]. `None` when the weights vanish or a
    /// sample or normal code is missing.
    #[inline]
    fn corner_planes(&self, base: usize, s: usize, f: DVec3) -> Option<CornerPlanes> {
        let (scale, off) = self.decode();
        let inv_h = 1.0 / self.cell_size as f64;
        let sig2 = PLANE_SOFTNESS_CELLS * PLANE_SOFTNESS_CELLS;
        let nsig2 = NORMAL_SOFTNESS_CELLS * NORMAL_SOFTNESS_CELLS;
        let mut sums = CornerPlanes::default();
        for c in 0..8usize {
            let o = [c & 1, (c >> 1) & 1, c >> 2];
            let at = base + o[0] + s * (o[1] + s * o[2]);
            let code = match &self.samples {
                Samples::F32(v) => v.get(at)?.get(),
                Samples::U16(v) => v.get(at)?.get(),
                Samples::U8(v) => v.get(at)?.get(),
            };
            let n = decode_octahedral(*self.normals.get(at)?);
            let r = f - DVec3::new(o[0] as f64, o[1] as f64, o[2] as f64);
            // The corner's tangent plane at p, cells (first-order Taylor expansion).
            let e = (code * scale + off) * inv_h + n.dot(r);
            let t: f64 = [0, 1, 2]
                .map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] })
                .iter()
                .product();
            let q = sig2 + e * e;
            let w = t / (q * q);
            sums.value += w * e;
            sums.weight += w;
            let qn = nsig2 + e * e;
            let wn = t / (qn * qn);
            sums.normal += wn * n;
            sums.normal_weight += wn;
        }
        let ok = |w: f64| w > 0.0 && w.is_finite();
        (ok(sums.weight) && ok(sums.normal_weight)).then_some(sums)
    }

    /// The surface normal the grid stores near `p` (mesh local frame), for
    /// [`Reconstruction::Normals`] grids within [`TRICUBIC_ZONE_CELLS`] of the surface: the
    /// corners' closest-triangle normals blended with the weights of their tangent planes
    /// at `p` (the planes through `p` dominate, so a point on a facet gets that facet's
    /// normal rather than the smooth field's gradient), unit length, pointing to increasing
    /// distance. `None` for other reconstructions, outside the lattice box, in an empty
    /// brick, farther from the surface, or where the blend vanishes (the caller then
    /// differentiates the field).
    pub fn stored_normal(&self, p: Vec3) -> Option<Vec3> {
        if self.reconstruction != Reconstruction::Normals {
            return None;
        }
        let c = self.lattice_cells();
        let maxc = DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
        let g = (p.as_dvec3() - self.min.as_dvec3()) * (1.0 / self.cell_size as f64);
        if !(g.cmpge(DVec3::ZERO).all() && g.cmple(maxc).all()) {
            return None;
        }
        let (_, _, Some((_, f, base))) = self.cell_at(g) else {
            return None;
        };
        if self.trilinear_at(base, f).abs() >= TRICUBIC_ZONE_CELLS * self.cell_size as f64 {
            return None;
        }
        let p = self.corner_planes(base, self.brick_edge(), f)?;
        // Corners that disagree (a crease or a fold of the scan within the cell): no
        // stored answer, the field's gradient averages them better.
        if p.normal.length() < STORED_NORMAL_AGREEMENT * p.normal_weight {
            return None;
        }
        p.normal.try_normalize().map(|n| n.as_vec3())
    }

    /// Where lattice point `g` (cells, inside the box) falls: its brick cell `bi`, that
    /// cell's word, and unless the brick cell is empty the [`BrickCell`].
    #[inline(always)]
    fn cell_at(&self, g: DVec3) -> ([u32; 3], u32, Option<BrickCell>) {
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
    fn trilinear_at(&self, base: usize, f: DVec3) -> f64 {
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
    use super::*;

    /// A grid of `f(p) = p.x - 2.3` on 2x1x1 brick cells, brick 0 present, brick 1 empty.
    fn linear(recon: Reconstruction, q: Quantization) -> SparseGrid {
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

    /// `f(p) = 0.1 |p - (4, 4, 4)|^2 - 0.3` on 2x2x2 brick cells of cell 0.5 (all eight
    /// bricks meet at the paraboloid's centre), tricubic, f32; `drop` empties one brick.
    fn paraboloid(drop: Option<usize>) -> SparseGrid {
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

    #[test]
    fn octahedral_codes_round_trip_within_a_degree() {
        let mut worst = 0.0f64;
        for i in 0..2000 {
            let (a, b) = (i as f32 * 0.7548777, i as f32 * 0.5698403);
            let z = 2.0 * b.fract() - 1.0;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = std::f32::consts::TAU * a.fract();
            let n = Vec3::new(r * phi.cos(), r * phi.sin(), z);
            let d = decode_octahedral(encode_octahedral(n));
            assert!((d.length() - 1.0).abs() < 1e-12);
            worst = worst.max(d.dot(n.as_dvec3()).clamp(-1.0, 1.0).acos().to_degrees());
        }
        assert!(worst < 1.0, "{worst}");
        for n in [Vec3::X, -Vec3::Y, Vec3::Z, -Vec3::Z] {
            assert!(decode_octahedral(encode_octahedral(n)).dot(n.as_dvec3()) > 0.9999);
        }
        assert_eq!(encode_octahedral(Vec3::ZERO), encode_octahedral(Vec3::Z));
        assert_eq!(encode_octahedral(Vec3::NAN), encode_octahedral(Vec3::Z));
    }

    /// [`linear`] with [`Reconstruction::Normals`] and every normal `+x` (exact for the plane).
    fn linear_normals(q: Quantization) -> SparseGrid {
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

    #[test]
    fn stored_normals_answer_near_the_surface_of_normals_grids_only() {
        // The plane x = 2.3 with every normal +x: the blend is +x near it; nothing far from
        // it (4.4 cells), outside the lattice, or from a grid without normals.
        for q in [Quantization::F32, Quantization::U8] {
            let g = linear_normals(q);
            for y in [0.3, 1.0, 3.1] {
                let n = g.stored_normal(Vec3::new(2.3, y, 1.7)).expect("a normal");
                // Octahedral codes of 2 x 8 bits hold a direction to about 0.3 degrees.
                assert!((n.length() - 1.0).abs() < 1e-5, "{n:?}");
                assert!(n.angle_between(Vec3::X).to_degrees() < 0.5, "{n:?}");
            }
            assert_eq!(g.stored_normal(Vec3::new(0.1, 1.0, 1.0)), None);
            assert_eq!(g.stored_normal(Vec3::new(2.3, -1.0, 1.0)), None);
            assert_eq!(g.stored_normal(Vec3::new(f32::NAN, 1.0, 1.0)), None);
            let plain = linear(Reconstruction::Trilinear, q);
            assert_eq!(plain.stored_normal(Vec3::new(2.3, 1.0, 1.0)), None);
        }
    }

    #[test]
    fn planes_reproduce_a_plane_and_need_their_normals() {
        for q in [Quantization::F32, Quantization::U16, Quantization::U8] {
            let g = linear_normals(q);
            // Plus the octahedral code's error (+x decodes 0.2 degrees off) over a cell.
            let tol = q.max_error(g.clamp) as f64 + 0.01 * g.cell_size as f64;
            for p in [
                DVec3::new(2.31, 0.0, 3.9),
                DVec3::new(2.2, 2.2, 2.2),
                DVec3::new(2.6, 1.3, 0.4),
            ] {
                let d = g.sample_f64(p);
                assert!((d - (p.x - 2.3)).abs() < tol, "{q:?} {p}: {d}");
                assert!((g.sample(p.as_vec3()) as f64 - d).abs() < 1e-4);
            }
        }
        let g = linear(Reconstruction::Trilinear, Quantization::U8);
        let parts = |recon, normals| {
            SparseGrid::from_parts(
                g.min,
                g.cell_size,
                g.bricks,
                2,
                g.clamp,
                recon,
                g.cells.clone(),
                g.samples.clone(),
                normals,
            )
        };
        assert!(parts(Reconstruction::Normals, vec![]).is_err());
        assert!(parts(Reconstruction::Normals, vec![0; 728]).is_err());
        assert!(parts(Reconstruction::Normals, vec![0; 729]).is_ok());
        assert!(parts(Reconstruction::Trilinear, vec![0; 729]).is_err());
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
