//! The stored form of a sparse grid: brick size, the empty brick-cell words, how samples
//! are encoded (f32, u16, u8) and how bricks are reconstructed between samples.

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
    /// 32-bit floats: exact distances (clamped to the band, see
    /// [`SparseGrid::clamp`](super::SparseGrid::clamp)).
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
    /// Gradient-corrected: every brick sample also stores the unit normal of its closest triangle
    /// (octahedral, 2 x 8 bits, [`encode_octahedral`](super::encode_octahedral)), and within
    /// [`TRICUBIC_ZONE_CELLS`] of the surface the value is the blend of the 8 cell corners' tangent
    /// planes `e_c(p) = d_c + n_c . (p - x_c)` ("Hermite" data as in dual contouring, Ju et al.
    /// 2002), weighted by `t_c / (sigma^2 + e_c^2)^2` (`t_c` the trilinear weights, `sigma` =
    /// [`PLANE_SOFTNESS_CELLS`](super::PLANE_SOFTNESS_CELLS)): the planes that pass through `p`
    /// dominate, so a flat facet seen by one corner is reproduced with its own normal instead of
    /// the cell's average, and the normal no longer carries the distances' quantization noise. The
    /// result stays within [`PLANE_CORRECTION_CELLS`](super::PLANE_CORRECTION_CELLS) of the
    /// trilinear value (smoothly clamped), so planes extended past their facet cannot move
    /// silhouettes. C0 (the weights are continuous), exact for one plane; 3 bytes per sample with
    /// u8 distances instead of 1. Trilinear farther out.
    Normals,
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
pub(super) trait Code: Copy {
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
