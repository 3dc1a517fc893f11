//! The number types the evaluator is generic over: `f32`, `f64` and [`F32x8`] (eight f32
//! lanes evaluated in lockstep). The distance functions are written once against [`Lane`], so
//! the f64 reference, the f32 tracer and the 8-lane tracer compute the same formulas.

use std::ops::{Add, Div, Mul, Neg, Sub};

use crate::program::GridSampler;

/// A number type the field can be evaluated in: one value (`f32`, `f64`) or several lanes.
///
/// Comparisons return a [`Lane::Mask`]; data-dependent choices go through [`Lane::select`], so
/// lane types evaluate every branch some lane needs and blend.
pub trait Lane:
    Copy
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// The scalar type program constants are stored in.
    type S: Scalar;
    /// Per-lane booleans.
    type Mask: Copy;
    /// Per-lane material ids.
    type Mat: Copy;
    /// Every lane equal to `s`.
    fn splat(s: Self::S) -> Self;
    /// A constant (converted from f64).
    #[inline]
    fn c(v: f64) -> Self {
        Self::splat(Self::S::from_f64(v))
    }
    /// Square root.
    fn sqrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// Lane-wise minimum.
    fn min(self, o: Self) -> Self;
    /// Lane-wise maximum.
    fn max(self, o: Self) -> Self;
    /// Round down.
    fn floor(self) -> Self;
    /// Round up.
    fn ceil(self) -> Self;
    /// `self < o`.
    fn lt(self, o: Self) -> Self::Mask;
    /// `self <= o`.
    fn le(self, o: Self) -> Self::Mask;
    /// Lane-wise and.
    fn and(a: Self::Mask, b: Self::Mask) -> Self::Mask;
    /// Lane-wise or.
    fn or(a: Self::Mask, b: Self::Mask) -> Self::Mask;
    /// Lane-wise negation (`!m`: a comparison involving NaN is false, its negation true).
    fn not(m: Self::Mask) -> Self::Mask;
    /// True if any lane is set.
    fn any(m: Self::Mask) -> bool;
    /// True if every lane is set.
    fn all(m: Self::Mask) -> bool;
    /// `m ? a : b` per lane.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// Every lane's material `id`.
    fn mat_splat(id: u32) -> Self::Mat;
    /// `m ? a : b` per lane for materials.
    fn mat_select(m: Self::Mask, a: Self::Mat, b: Self::Mat) -> Self::Mat;
    /// Largest lane, as f64.
    fn hmax(self) -> f64;
    /// Sum of the lanes (traversal-order heuristics only).
    fn hsum(self) -> f64;
    /// The mesh grid `grid`'s signed distance at the point `(x, y, z)` of each lane (the
    /// grid's local frame), at this lane type's precision: [`GridSampler::sample`] for f64,
    /// [`GridSampler::sample_f32`] for f32 lanes (eight at a time through
    /// [`GridSampler::sample_f32x8`]), so the f32 tracer never widens to f64 per lookup.
    fn sample_grid(grid: &dyn GridSampler, x: Self, y: Self, z: Self) -> Self;
    /// Clamp to `[lo, hi]`.
    #[inline]
    fn clamp(self, lo: Self, hi: Self) -> Self {
        self.max(lo).min(hi)
    }
}

/// A scalar lane type program constants are stored in (`f32` or `f64`).
pub trait Scalar: Lane<S = Self> + PartialOrd + std::fmt::Debug {
    /// Conversion from f64 (rounding to nearest for f32).
    fn from_f64(v: f64) -> Self;
    /// Conversion to f64 (exact).
    fn to_f64(self) -> f64;
}

macro_rules! scalar_lane {
    ($t:ty, $sample:ident) => {
        impl Lane for $t {
            type S = $t;
            type Mask = bool;
            type Mat = u32;
            #[inline(always)]
            fn splat(s: $t) -> Self {
                s
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline(always)]
            fn min(self, o: Self) -> Self {
                if self < o { self } else { o }
            }
            #[inline(always)]
            fn max(self, o: Self) -> Self {
                if self > o { self } else { o }
            }
            #[inline(always)]
            fn floor(self) -> Self {
                <$t>::floor(self)
            }
            #[inline(always)]
            fn ceil(self) -> Self {
                <$t>::ceil(self)
            }
            #[inline(always)]
            fn lt(self, o: Self) -> bool {
                self < o
            }
            #[inline(always)]
            fn le(self, o: Self) -> bool {
                self <= o
            }
            #[inline(always)]
            fn and(a: bool, b: bool) -> bool {
                a & b
            }
            #[inline(always)]
            fn or(a: bool, b: bool) -> bool {
                a | b
            }
            #[inline(always)]
            fn not(m: bool) -> bool {
                !m
            }
            #[inline(always)]
            fn any(m: bool) -> bool {
                m
            }
            #[inline(always)]
            fn all(m: bool) -> bool {
                m
            }
            #[inline(always)]
            fn select(m: bool, a: Self, b: Self) -> Self {
                if m { a } else { b }
            }
            #[inline(always)]
            fn mat_splat(id: u32) -> u32 {
                id
            }
            #[inline(always)]
            fn mat_select(m: bool, a: u32, b: u32) -> u32 {
                if m { a } else { b }
            }
            #[inline(always)]
            fn hmax(self) -> f64 {
                self as f64
            }
            #[inline(always)]
            fn hsum(self) -> f64 {
                self as f64
            }
            #[inline]
            fn sample_grid(grid: &dyn GridSampler, x: Self, y: Self, z: Self) -> Self {
                grid.$sample(x, y, z)
            }
        }
        impl Scalar for $t {
            #[inline(always)]
            fn from_f64(v: f64) -> Self {
                v as $t
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                self as f64
            }
        }
    };
}
scalar_lane!(f32, sample_f32);
scalar_lane!(f64, sample);

/// Eight f32 lanes, operated on element-wise (the loops auto-vectorise to SIMD).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(align(32))]
pub struct F32x8(pub [f32; 8]);

macro_rules! binop8 {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for F32x8 {
            type Output = F32x8;
            #[inline(always)]
            fn $f(self, o: F32x8) -> F32x8 {
                let mut r = [0.0f32; 8];
                for i in 0..8 {
                    r[i] = self.0[i] $op o.0[i];
                }
                F32x8(r)
            }
        }
    };
}
binop8!(Add, add, +);
binop8!(Sub, sub, -);
binop8!(Mul, mul, *);
binop8!(Div, div, /);

impl Neg for F32x8 {
    type Output = F32x8;
    #[inline(always)]
    fn neg(self) -> F32x8 {
        F32x8(self.0.map(|v| -v))
    }
}

impl F32x8 {
    #[inline(always)]
    fn zip(self, o: F32x8, f: impl Fn(f32, f32) -> f32) -> F32x8 {
        let mut r = [0.0f32; 8];
        for i in 0..8 {
            r[i] = f(self.0[i], o.0[i]);
        }
        F32x8(r)
    }
}

impl F32x8 {
    #[inline(always)]
    fn mask(self, o: F32x8, f: impl Fn(f32, f32) -> bool) -> M8 {
        let mut r = [0u32; 8];
        for i in 0..8 {
            r[i] = if f(self.0[i], o.0[i]) { !0 } else { 0 };
        }
        M8(r)
    }
}

/// Eight lane masks, each all ones (true) or all zeros (false), so selects are bitwise
/// blends that vectorise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(align(32))]
pub struct M8(pub [u32; 8]);

impl Lane for F32x8 {
    type S = f32;
    type Mask = M8;
    type Mat = [u32; 8];
    #[inline(always)]
    fn splat(s: f32) -> Self {
        F32x8([s; 8])
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        F32x8(self.0.map(f32::sqrt))
    }
    #[inline(always)]
    fn abs(self) -> Self {
        F32x8(self.0.map(f32::abs))
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        self.zip(o, |a, b| if a < b { a } else { b })
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        self.zip(o, |a, b| if a > b { a } else { b })
    }
    #[inline(always)]
    fn floor(self) -> Self {
        F32x8(self.0.map(f32::floor))
    }
    #[inline(always)]
    fn ceil(self) -> Self {
        F32x8(self.0.map(f32::ceil))
    }
    #[inline(always)]
    fn lt(self, o: Self) -> M8 {
        self.mask(o, |a, b| a < b)
    }
    #[inline(always)]
    fn le(self, o: Self) -> M8 {
        self.mask(o, |a, b| a <= b)
    }
    #[inline(always)]
    fn and(a: M8, b: M8) -> M8 {
        let mut r = [0u32; 8];
        for i in 0..8 {
            r[i] = a.0[i] & b.0[i];
        }
        M8(r)
    }
    #[inline(always)]
    fn or(a: M8, b: M8) -> M8 {
        let mut r = [0u32; 8];
        for i in 0..8 {
            r[i] = a.0[i] | b.0[i];
        }
        M8(r)
    }
    #[inline(always)]
    fn not(m: M8) -> M8 {
        M8(m.0.map(|b| !b))
    }
    #[inline(always)]
    fn any(m: M8) -> bool {
        m.0.iter().fold(0, |a, &b| a | b) != 0
    }
    #[inline(always)]
    fn all(m: M8) -> bool {
        m.0.iter().fold(!0, |a, &b| a & b) != 0
    }
    #[inline(always)]
    fn select(m: M8, a: Self, b: Self) -> Self {
        let mut r = [0.0f32; 8];
        for i in 0..8 {
            r[i] = f32::from_bits((a.0[i].to_bits() & m.0[i]) | (b.0[i].to_bits() & !m.0[i]));
        }
        F32x8(r)
    }
    #[inline(always)]
    fn mat_splat(id: u32) -> [u32; 8] {
        [id; 8]
    }
    #[inline(always)]
    fn mat_select(m: M8, a: [u32; 8], b: [u32; 8]) -> [u32; 8] {
        let mut r = [0u32; 8];
        for i in 0..8 {
            r[i] = (a[i] & m.0[i]) | (b[i] & !m.0[i]);
        }
        r
    }
    #[inline(always)]
    fn hmax(self) -> f64 {
        self.0.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b)) as f64
    }
    #[inline(always)]
    fn hsum(self) -> f64 {
        self.0.iter().map(|&v| f64::from(v)).sum()
    }
    #[inline]
    fn sample_grid(grid: &dyn GridSampler, x: Self, y: Self, z: Self) -> Self {
        F32x8(grid.sample_f32x8(x.0, y.0, z.0))
    }
}

/// A 3-vector of lanes (no glam type is generic over the number type).
#[derive(Debug, Clone, Copy, Default)]
pub struct V3<T> {
    /// x.
    pub x: T,
    /// y.
    pub y: T,
    /// z.
    pub z: T,
}

impl V3<F32x8> {
    /// Eight points as lanes (structure of arrays), lane `k` = `p[k]`.
    #[inline(always)]
    pub fn from_points(p: [glam::Vec3; 8]) -> Self {
        V3::new(
            F32x8(p.map(|v| v.x)),
            F32x8(p.map(|v| v.y)),
            F32x8(p.map(|v| v.z)),
        )
    }
}

impl<T: Lane> V3<T> {
    /// From components.
    #[inline(always)]
    pub fn new(x: T, y: T, z: T) -> Self {
        V3 { x, y, z }
    }
    /// From a stored constant.
    #[inline(always)]
    pub fn splat3(v: [T::S; 3]) -> Self {
        V3::new(T::splat(v[0]), T::splat(v[1]), T::splat(v[2]))
    }
    /// Dot product.
    #[inline(always)]
    pub fn dot(self, o: Self) -> T {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Squared length.
    #[inline(always)]
    pub fn len2(self) -> T {
        self.dot(self)
    }
    /// Length.
    #[inline(always)]
    pub fn len(self) -> T {
        self.len2().sqrt()
    }
    /// Component-wise absolute value.
    #[inline(always)]
    pub fn abs(self) -> Self {
        V3::new(self.x.abs(), self.y.abs(), self.z.abs())
    }
    /// Component-wise max with a scalar lane.
    #[inline(always)]
    pub fn max_s(self, s: T) -> Self {
        V3::new(self.x.max(s), self.y.max(s), self.z.max(s))
    }
    /// Largest component.
    #[inline(always)]
    pub fn max_elem(self) -> T {
        self.x.max(self.y).max(self.z)
    }
    /// Cross product.
    #[inline(always)]
    pub fn cross(self, o: Self) -> Self {
        V3::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    /// Scaled by a lane.
    #[inline(always)]
    pub fn scale(self, s: T) -> Self {
        V3::new(self.x * s, self.y * s, self.z * s)
    }
    /// Component-wise product.
    #[inline(always)]
    pub fn mul_elem(self, o: Self) -> Self {
        V3::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
}

impl<T: Lane> Add for V3<T> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        V3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl<T: Lane> Sub for V3<T> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        V3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
