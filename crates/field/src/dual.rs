//! Forward-mode differentiation of the field: [`Dual8`], eight lanes of a value and its
//! gradient with respect to the evaluation point (dual numbers, e.g. Griewank and Walther,
//! "Evaluating Derivatives", 2nd ed. 2008, ch. 3). Evaluating the field program in `Dual8`
//! gives the exact gradient of the evaluated expression at eight points in one pass, where
//! central differences need six evaluations per point and lose about `ulp(|p|) / h` of
//! precision to cancellation.
//!
//! Branches go through [`Lane::select`] and `min`/`max` pick a whole dual, so the gradient
//! is the one of the branch taken (one-sided at a crease; at a tie, the first argument's). `floor`/`ceil` have derivative 0.
//! Mesh grids ([`Lane::sample_grid`]) are sampled without a derivative: their gradient lanes are
//! NaN, so a caller sees a non-finite gradient and falls back to differences.

use std::ops::{Add, Div, Mul, Neg, Sub};

use crate::lane::{F32x8, Lane, M8, V3};
use crate::program::GridSampler;

macro_rules! dual {
    ($(#[$doc:meta])* $name:ident, $t:ty, $mask:ty, $mat:ty) => {
$(#[$doc])*
        #[derive(Debug, Clone, Copy, Default)]
        pub struct $name {
    /// The value.
    pub v: $t,
    /// The gradient.
    pub d: V3<$t>,
}

impl $name {
    /// A value with gradient zero.
    #[inline]
    fn constant(v: $t) -> Self {
        let z = <$t as Lane>::splat(0.0);
        $name {
            v,
            d: V3::new(z, z, z),
        }
    }

    /// Points as the independent variables: `x` has gradient `(1, 0, 0)`, and so on.
    #[inline]
    pub fn seed(p: V3<$t>) -> V3<$name> {
        let (o, z) = (<$t as Lane>::splat(1.0), <$t as Lane>::splat(0.0));
        V3::new(
            $name {
                v: p.x,
                d: V3::new(o, z, z),
            },
            $name {
                v: p.y,
                d: V3::new(z, o, z),
            },
            $name {
                v: p.z,
                d: V3::new(z, z, o),
            },
        )
    }

    /// `self.d * s`.
    #[inline]
    fn dscale(self, s: $t) -> V3<$t> {
        V3::new(self.d.x * s, self.d.y * s, self.d.z * s)
    }
}

impl Add for $name {
    type Output = $name;
    #[inline]
    fn add(self, o: $name) -> $name {
        $name {
            v: self.v + o.v,
            d: self.d + o.d,
        }
    }
}

impl Sub for $name {
    type Output = $name;
    #[inline]
    fn sub(self, o: $name) -> $name {
        $name {
            v: self.v - o.v,
            d: self.d - o.d,
        }
    }
}

impl Mul for $name {
    type Output = $name;
    #[inline]
    fn mul(self, o: $name) -> $name {
        $name {
            v: self.v * o.v,
            d: self.dscale(o.v) + o.dscale(self.v),
        }
    }
}

impl Div for $name {
    type Output = $name;
    #[inline]
    fn div(self, o: $name) -> $name {
        let v = self.v / o.v;
        // (a / b)' = (a' - v b') / b
        let inv = <$t as Lane>::splat(1.0) / o.v;
        $name {
            v,
            d: (self.d - o.dscale(v)).scale(inv),
        }
    }
}

impl Neg for $name {
    type Output = $name;
    #[inline]
    fn neg(self) -> $name {
        $name {
            v: -self.v,
            d: V3::new(-self.d.x, -self.d.y, -self.d.z),
        }
    }
}

impl Lane for $name {
    type S = f32;
    type Mask = $mask;
    type Mat = $mat;
    #[inline]
    fn splat(s: f32) -> Self {
        $name::constant(<$t as Lane>::splat(s))
    }
    #[inline]
    fn sqrt(self) -> Self {
        let v = Lane::sqrt(self.v);
        // d sqrt(a) = a' / (2 sqrt(a)); 0 where the value is 0 (the derivative is infinite
        // there, e.g. a box distance inside its box: such lanes are never selected, and a
        // surface point of an unsigned field gets a zero gradient, which callers reject).
        let k = <$t as Lane>::select(
            <$t as Lane>::lt(<$t as Lane>::splat(0.0), v),
            <$t as Lane>::splat(0.5) / v,
            <$t as Lane>::splat(0.0),
        );
        $name {
            v,
            d: self.dscale(k),
        }
    }
    #[inline]
    fn abs(self) -> Self {
        Self::select(<$t as Lane>::lt(self.v, <$t as Lane>::splat(0.0)), -self, self)
    }
    #[inline]
    fn min(self, o: Self) -> Self {
        // At a tie `self` (the same value either way): in the distance functions the first
        // argument is the shape's term and the second a constant (`q.max(0)`, `.min(0)` in
        // a box), so a point exactly on a face keeps the face's gradient instead of 0.
        Self::select(<$t as Lane>::le(self.v, o.v), self, o)
    }
    #[inline]
    fn max(self, o: Self) -> Self {
        Self::select(<$t as Lane>::le(o.v, self.v), self, o)
    }
    #[inline]
    fn floor(self) -> Self {
        $name::constant(Lane::floor(self.v))
    }
    #[inline]
    fn ceil(self) -> Self {
        $name::constant(Lane::ceil(self.v))
    }
    #[inline]
    fn lt(self, o: Self) -> $mask {
        <$t as Lane>::lt(self.v, o.v)
    }
    #[inline]
    fn le(self, o: Self) -> $mask {
        <$t as Lane>::le(self.v, o.v)
    }
    #[inline]
    fn and(a: $mask, b: $mask) -> $mask {
        <$t as Lane>::and(a, b)
    }
    #[inline]
    fn or(a: $mask, b: $mask) -> $mask {
        <$t as Lane>::or(a, b)
    }
    #[inline]
    fn not(m: $mask) -> $mask {
        <$t as Lane>::not(m)
    }
    #[inline]
    fn any(m: $mask) -> bool {
        <$t as Lane>::any(m)
    }
    #[inline]
    fn all(m: $mask) -> bool {
        <$t as Lane>::all(m)
    }
    #[inline]
    fn select(m: $mask, a: Self, b: Self) -> Self {
        let s = |x: $t, y: $t| <$t as Lane>::select(m, x, y);
        $name {
            v: s(a.v, b.v),
            d: V3::new(s(a.d.x, b.d.x), s(a.d.y, b.d.y), s(a.d.z, b.d.z)),
        }
    }
    #[inline]
    fn mat_splat(id: u32) -> $mat {
        <$t as Lane>::mat_splat(id)
    }
    #[inline]
    fn mat_select(m: $mask, a: $mat, b: $mat) -> $mat {
        <$t as Lane>::mat_select(m, a, b)
    }
    #[inline]
    fn hmax(self) -> f64 {
        Lane::hmax(self.v)
    }
    #[inline]
    fn hsum(self) -> f64 {
        Lane::hsum(self.v)
    }
    #[inline]
    fn sample_grid(grid: &dyn GridSampler, x: Self, y: Self, z: Self) -> Self {
        let nan = <$t as Lane>::splat(f32::NAN);
        $name {
            v: <$t as Lane>::sample_grid(grid, x.v, y.v, z.v),
            d: V3::new(nan, nan, nan),
        }
    }
}

    };
}

dual!(
    /// Eight lanes of a value `v` and its partial derivatives `d = (dv/dx, dv/dy, dv/dz)`.
    Dual8, F32x8, M8, [u32; 8]
);
dual!(
    /// One value `v` and its partial derivatives `d = (dv/dx, dv/dy, dv/dz)`: per lane the
    /// same operations as [`Dual8`], so the same bits.
    Dual1, f32, bool, u32
);

#[cfg(test)]
mod tests {
    use super::*;

    fn lanes(f: impl Fn(usize) -> f32) -> F32x8 {
        F32x8(std::array::from_fn(f))
    }

    /// The dual gradient of an expression against central differences in f64 of the same
    /// expression.
    #[test]
    fn gradients_match_differences() {
        let p = V3::new(
            lanes(|k| 0.31 + 0.1 * k as f32),
            lanes(|k| -0.7 + 0.05 * k as f32),
            lanes(|k| 1.1 - 0.2 * k as f32),
        );
        let f = |x: Dual8, y: Dual8, z: Dual8| -> Dual8 {
            let r = (x * x + y * y + z * z).sqrt();
            let a = (x - Dual8::splat(0.5)).abs().max(y * z) / (r + Dual8::splat(1.0));
            a.min(-z + x * Dual8::splat(3.0))
        };
        let fd = |x: f64, y: f64, z: f64| -> f64 {
            let r = (x * x + y * y + z * z).sqrt();
            let a = (x - 0.5).abs().max(y * z) / (r + 1.0);
            a.min(-z + x * 3.0)
        };
        let s = Dual8::seed(p);
        let d = f(s.x, s.y, s.z);
        for k in 0..8 {
            let (x, y, z) = (p.x.0[k] as f64, p.y.0[k] as f64, p.z.0[k] as f64);
            let h = 1e-6;
            let g = [
                (fd(x + h, y, z) - fd(x - h, y, z)) / (2.0 * h),
                (fd(x, y + h, z) - fd(x, y - h, z)) / (2.0 * h),
                (fd(x, y, z + h) - fd(x, y, z - h)) / (2.0 * h),
            ];
            let got = [d.d.x.0[k], d.d.y.0[k], d.d.z.0[k]];
            for a in 0..3 {
                assert!(
                    (got[a] as f64 - g[a]).abs() < 1e-4,
                    "lane {k} axis {a}: {} vs {}",
                    got[a],
                    g[a]
                );
            }
            assert!((d.v.0[k] as f64 - fd(x, y, z)).abs() < 1e-5);
        }
    }

    #[test]
    fn sqrt_of_zero_has_a_zero_gradient_and_grids_a_nan_one() {
        let s = Dual8::seed(V3::new(
            F32x8::splat(0.0),
            F32x8::splat(0.0),
            F32x8::splat(0.0),
        ));
        let r = (s.x * s.x + s.y * s.y).sqrt();
        assert_eq!(r.d.x.0, [0.0; 8]);
        /// A "grid" whose f32 distance is the point's x (its f64 one is off by 1000, so the
        /// test sees which sampler the f32 lanes take).
        struct PlaneX;
        impl GridSampler for PlaneX {
            fn sample(&self, x: f64, _: f64, _: f64) -> f64 {
                x + 1000.0
            }
            fn sample_f32(&self, x: f32, _: f32, _: f32) -> f32 {
                x
            }
            fn memory_bytes(&self) -> u64 {
                0
            }
        }
        let x = Dual8::seed(V3::new(
            F32x8(std::array::from_fn(|i| i as f32 - 2.5)),
            F32x8::splat(1.0),
            F32x8::splat(2.0),
        ));
        let g = Dual8::sample_grid(&PlaneX, x.x, x.y, x.z);
        assert_eq!(g.v.0, x.x.v.0, "each lane's own point");
        assert!(g.d.x.0.iter().all(|v| v.is_nan()));
    }
}
