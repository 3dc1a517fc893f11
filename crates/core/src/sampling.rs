//! Deterministic sampling for the lighting integrators: counter-based random numbers keyed by
//! (seed, pixel, sample), randomized low-discrepancy points, and warps to the hemisphere and
//! to cones.
//!
//! Every random choice is a pure function of the scene's seed and the pixel, sample and
//! dimension it is made for, so an image does not depend on the thread count or on the order
//! rows are traced in.

use glam::Vec3;

use crate::camera::radical_inverse;

/// The SplitMix64 finaliser: a bijective 64-bit mix whose outputs pass BigCrush when fed a
/// counter (Steele, Lea and Flood, "Fast splittable pseudorandom number generators", 2014).
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A uniform number in `[0, 1)` from a 64-bit key (24 random bits, exactly representable).
#[inline]
pub fn unit_from_key(key: u64) -> f32 {
    (mix64(key) >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

/// The key of one pixel sample: mixes the scene seed with the pixel and the sample index.
#[inline]
pub fn sample_key(seed: u64, column: u32, row: u32, sample: u32) -> u64 {
    mix64(seed ^ mix64(((row as u64) << 32 | column as u64) ^ mix64(sample as u64 + 1)))
}

/// A counter-based random stream (SplitMix64): `next` returns uniform numbers in `[0, 1)`.
#[derive(Debug, Clone)]
pub struct Rng {
    state: u64,
}

impl Rng {
    /// The stream of `key` (see [`sample_key`]).
    pub fn new(key: u64) -> Self {
        Self { state: key }
    }

    /// The next uniform number in `[0, 1)`.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        unit_from_key(self.state)
    }
}

/// Point `k` of the `n`-point two-dimensional Hammersley set `((k + 0.5) / n, phi_2(k))`,
/// shifted by `rotation` modulo 1 (a Cranley-Patterson rotation, so neighbouring pixels do not
/// share one pattern while each pixel's `n` points stay stratified).
#[inline]
pub fn hammersley(k: u32, n: u32, rotation: (f32, f32)) -> (f32, f32) {
    let u = (k as f32 + 0.5) / n as f32;
    let v = radical_inverse(k, 2) as f32;
    (wrap01(u + rotation.0), wrap01(v + rotation.1))
}

/// The first prime bases of the randomized Halton sequence used by the path tracer.
const HALTON_PRIMES: [u32; 32] = [
    2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61, 67, 71, 73, 79, 83, 89, 97,
    101, 103, 107, 109, 113, 127, 131,
];

/// Dimension `dim` of sample `sample` of a randomized Halton sequence: the radical inverse in
/// the `dim`-th prime base, rotated by a per-pixel offset drawn from `pixel_key`. Beyond the
/// 32 tabulated dimensions it returns a plain random number from the same key.
#[inline]
pub fn halton_dim(sample: u32, dim: u32, pixel_key: u64) -> f32 {
    let rotation = unit_from_key(pixel_key ^ mix64(dim as u64 + 0x51ed));
    match HALTON_PRIMES.get(dim as usize) {
        Some(&base) => wrap01(radical_inverse(sample, base) as f32 + rotation),
        None => unit_from_key(pixel_key ^ mix64((sample as u64) << 32 | dim as u64)),
    }
}

#[inline]
fn wrap01(x: f32) -> f32 {
    let f = x - x.floor();
    // x.floor() can round so that f == 1.0 for x just below an integer.
    if f >= 1.0 { 0.0 } else { f }
}

/// An orthonormal basis `(t, b)` completing the unit vector `n` to a right-handed frame
/// `(t, b, n)` (Duff et al., "Building an Orthonormal Basis, Revisited", JCGT 2017).
#[inline]
pub fn orthonormal_basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// A cosine-distributed direction in the hemisphere around the unit vector `n` (density
/// `cos(theta) / pi`), from two uniform numbers: Malley's method over Shirley and Chiu's
/// concentric disk mapping ("A Low Distortion Map Between Disk and Square", 1997).
#[inline]
pub fn cosine_hemisphere(n: Vec3, u: f32, v: f32) -> Vec3 {
    let (dx, dy) = concentric_disk(u, v);
    let z = (1.0 - dx * dx - dy * dy).max(0.0).sqrt();
    let (t, b) = orthonormal_basis(n);
    (t * dx + b * dy + n * z).normalize()
}

fn concentric_disk(u: f32, v: f32) -> (f32, f32) {
    let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
    if a == 0.0 && b == 0.0 {
        return (0.0, 0.0);
    }
    let (r, phi) = if a.abs() > b.abs() {
        (a, std::f32::consts::FRAC_PI_4 * (b / a))
    } else {
        (
            b,
            std::f32::consts::FRAC_PI_2 - std::f32::consts::FRAC_PI_4 * (a / b),
        )
    };
    (r * phi.cos(), r * phi.sin())
}

/// A direction uniformly distributed over the solid angle of the cone around the unit vector
/// `axis` whose half angle has `1 - cos(half angle) = one_minus_cos_max` (density
/// `1 / (2 pi one_minus_cos_max)`; pbrt-v3 `UniformSampleCone`). Taking `1 - cos` rather than
/// `cos` keeps cones narrower than f32's resolution of `cos` near 1 (tiny or far lights) exact.
#[inline]
pub fn uniform_cone(axis: Vec3, one_minus_cos_max: f32, u: f32, v: f32) -> Vec3 {
    let one_minus_cos = u * one_minus_cos_max;
    let cos_theta = 1.0 - one_minus_cos;
    let sin_theta = (one_minus_cos * (2.0 - one_minus_cos)).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * v;
    let (t, b) = orthonormal_basis(axis);
    (t * (sin_theta * phi.cos()) + b * (sin_theta * phi.sin()) + axis * cos_theta).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_is_orthonormal_for_every_octant() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.5, 0.8).normalize(),
            Vec3::new(-0.7, 0.1, -0.7).normalize(),
        ] {
            let (t, b) = orthonormal_basis(n);
            assert!((t.length() - 1.0).abs() < 1e-5 && (b.length() - 1.0).abs() < 1e-5);
            assert!(t.dot(b).abs() < 1e-5 && t.dot(n).abs() < 1e-5 && b.dot(n).abs() < 1e-5);
            assert!((t.cross(b) - n).length() < 1e-5, "right-handed");
        }
    }

    #[test]
    fn cosine_hemisphere_has_mean_cosine_two_thirds() {
        // E[cos theta] under density cos/pi is 2/3; the directions stay above the surface.
        let n = Vec3::new(0.2, 0.9, -0.1).normalize();
        let count = 64 * 64;
        let mut sum = 0.0;
        for k in 0..count {
            let (u, v) = hammersley(k, count, (0.0, 0.0));
            let d = cosine_hemisphere(n, u, v);
            assert!(d.dot(n) >= -1e-6);
            sum += d.dot(n) as f64;
        }
        assert!(
            (sum / count as f64 - 2.0 / 3.0).abs() < 2e-3,
            "{}",
            sum / count as f64
        );
    }

    #[test]
    fn cone_directions_stay_in_the_cone_and_cover_it_evenly() {
        let axis = Vec3::new(1.0, 1.0, 0.0).normalize();
        let cos_max = 0.9f32;
        let count = 4096;
        let mut sum = 0.0;
        for k in 0..count {
            let (u, v) = hammersley(k, count, (0.3, 0.7));
            let c = uniform_cone(axis, 1.0 - cos_max, u, v).dot(axis);
            assert!(c >= cos_max - 1e-5);
            sum += c as f64;
        }
        // Uniform over solid angle: cos theta is uniform in [cos_max, 1].
        assert!((sum / count as f64 - 0.95).abs() < 1e-3);
    }

    #[test]
    fn random_numbers_are_deterministic_in_range_and_keyed() {
        let mut a = Rng::new(sample_key(7, 3, 4, 5));
        let mut b = Rng::new(sample_key(7, 3, 4, 5));
        let mut c = Rng::new(sample_key(8, 3, 4, 5));
        let (mut same, mut mean) = (0, 0.0);
        for _ in 0..10_000 {
            let (x, y, z) = (a.next_f32(), b.next_f32(), c.next_f32());
            assert_eq!(x, y);
            assert!((0.0..1.0).contains(&x));
            same += (x == z) as u32;
            mean += x as f64;
        }
        assert!(same < 10, "a different seed gives a different stream");
        assert!((mean / 10_000.0 - 0.5).abs() < 0.02);
        for dim in 0..40 {
            let h = halton_dim(17, dim, 99);
            assert!((0.0..1.0).contains(&h));
        }
    }
}
