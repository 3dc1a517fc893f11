//! Per-pixel accuracy of one render against a reference render of the same camera.
//!
//! Both framebuffers record AOVs of the primary ray through each pixel centre, so the same
//! pixel is the same ray in both, and geometric errors are measured along identical rays.

use crate::framebuffer::Framebuffer;

/// How a test render differs from the reference.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Accuracy {
    /// Pixels compared.
    pub pixels: usize,
    /// Pixels hit in both renders (where depth and normal errors are measured).
    pub both_hit: usize,
    /// Pixels hit in exactly one of the two renders.
    pub silhouette_mismatch: usize,
    /// `silhouette_mismatch` as a percentage of all pixels.
    pub silhouette_mismatch_pct: f64,
    /// Pixels hit in both whose material differs (a different surface was hit).
    pub material_mismatch: usize,
    /// Mean absolute depth error over `both_hit` pixels, world units.
    pub depth_abs_mean: f64,
    /// 95th percentile of the absolute depth error, world units.
    pub depth_abs_p95: f64,
    /// Largest absolute depth error, world units.
    pub depth_abs_max: f64,
    /// Mean of |depth error| / reference depth (dimensionless).
    pub depth_rel_mean: f64,
    /// 95th percentile of |depth error| / reference depth.
    pub depth_rel_p95: f64,
    /// Largest |depth error| / reference depth: a few wrong pixels hide below the p95.
    pub depth_rel_max: f64,
    /// Pixels hit by both whose relative depth error exceeds [`DEPTH_REL_TAIL`].
    pub depth_rel_tail_px: usize,
    /// Mean angle between normals in degrees.
    pub normal_deg_mean: f64,
    /// 95th percentile of the normal angle error in degrees.
    pub normal_deg_p95: f64,
    /// Largest normal angle error in degrees.
    pub normal_deg_max: f64,
    /// Pixels hit by both whose normals differ by more than [`NORMAL_DEG_TAIL`] degrees.
    pub normal_deg_tail_px: usize,
    /// Peak signal-to-noise ratio of the 8-bit colour images in dB (infinite if identical).
    pub psnr_db: f64,
    /// NaN or infinite values in the test render's colour, or in its depth where it hit.
    pub non_finite: usize,
}

/// Relative depth error beyond which a pixel counts in [`Accuracy::depth_rel_tail_px`]: 1e-3,
/// the stability study's "exact" bound on the p95.
pub const DEPTH_REL_TAIL: f64 = 1e-3;

/// Normal angle error in degrees beyond which a pixel counts in
/// [`Accuracy::normal_deg_tail_px`]: 5, the stability study's "degraded" bound on the mean.
pub const NORMAL_DEG_TAIL: f64 = 5.0;

/// Why two framebuffers cannot be compared.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("cannot compare a {test_w}x{test_h} render with a {ref_w}x{ref_h} reference")]
pub struct SizeMismatch {
    /// Test width.
    pub test_w: u32,
    /// Test height.
    pub test_h: u32,
    /// Reference width.
    pub ref_w: u32,
    /// Reference height.
    pub ref_h: u32,
}

/// The `q`-quantile (0..=1) of `v` by nearest rank; 0 for an empty slice. Sorts `v`.
pub fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let idx = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
    v[idx]
}

/// Compares `test` against `reference` pixel by pixel.
///
/// # Panics
/// If either framebuffer has no AOVs ([`Framebuffer::has_aovs`]): the comparison reads them.
pub fn compare(test: &Framebuffer, reference: &Framebuffer) -> Result<Accuracy, SizeMismatch> {
    if (test.width, test.height) != (reference.width, reference.height) {
        return Err(SizeMismatch {
            test_w: test.width,
            test_h: test.height,
            ref_w: reference.width,
            ref_h: reference.height,
        });
    }
    assert!(
        test.has_aovs() && reference.has_aovs(),
        "compare: a framebuffer rendered without AOVs"
    );
    let n = test.len();
    let mut a = Accuracy {
        pixels: n,
        ..Default::default()
    };
    let mut depth_abs = Vec::new();
    let mut depth_rel = Vec::new();
    let mut normal_deg = Vec::new();
    for i in 0..n {
        let (th, rh) = (test.is_hit(i), reference.is_hit(i));
        if !test.color[i].is_finite() || test.depth[i].is_nan() {
            a.non_finite += 1;
        }
        if th != rh {
            a.silhouette_mismatch += 1;
            continue;
        }
        if !th {
            continue;
        }
        a.both_hit += 1;
        if test.material[i] != reference.material[i] {
            a.material_mismatch += 1;
        }
        let d = (test.depth[i] as f64 - reference.depth[i] as f64).abs();
        depth_abs.push(d);
        depth_rel.push(d / (reference.depth[i] as f64).max(f64::MIN_POSITIVE));
        let c = test.normal[i]
            .as_dvec3()
            .normalize_or_zero()
            .dot(reference.normal[i].as_dvec3().normalize_or_zero())
            .clamp(-1.0, 1.0);
        normal_deg.push(c.acos().to_degrees());
    }
    a.silhouette_mismatch_pct = 100.0 * a.silhouette_mismatch as f64 / n.max(1) as f64;
    let mean = |v: &[f64]| {
        if v.is_empty() {
            0.0
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    a.depth_abs_mean = mean(&depth_abs);
    a.depth_rel_mean = mean(&depth_rel);
    a.normal_deg_mean = mean(&normal_deg);
    a.depth_abs_max = depth_abs.iter().copied().fold(0.0, f64::max);
    a.normal_deg_max = normal_deg.iter().copied().fold(0.0, f64::max);
    a.depth_rel_max = depth_rel.iter().copied().fold(0.0, f64::max);
    a.depth_rel_tail_px = depth_rel.iter().filter(|e| **e > DEPTH_REL_TAIL).count();
    a.normal_deg_tail_px = normal_deg.iter().filter(|e| **e > NORMAL_DEG_TAIL).count();
    a.depth_abs_p95 = quantile(&mut depth_abs, 0.95);
    a.depth_rel_p95 = quantile(&mut depth_rel, 0.95);
    a.normal_deg_p95 = quantile(&mut normal_deg, 0.95);
    a.psnr_db = psnr_8bit(test, reference);
    Ok(a)
}

/// PSNR in dB of the two colour buffers after the 8-bit conversion used for PNG output.
pub fn psnr_8bit(test: &Framebuffer, reference: &Framebuffer) -> f64 {
    let (a, b) = (test.to_rgb8(), reference.to_rgb8());
    let mut se = 0.0f64;
    for (x, y) in a.as_raw().iter().zip(b.as_raw()) {
        let d = *x as f64 - *y as f64;
        se += d * d;
    }
    let mse = se / a.as_raw().len().max(1) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0 * 255.0 / mse).log10()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn fb_with(depths: &[f32], normals: &[Vec3]) -> Framebuffer {
        let mut fb = Framebuffer::new(depths.len() as u32, 1);
        fb.depth.copy_from_slice(depths);
        fb.normal.copy_from_slice(normals);
        for (i, d) in depths.iter().enumerate() {
            if d.is_finite() {
                fb.material[i] = 0;
                fb.color[i] = Vec3::ONE;
            }
        }
        fb
    }

    #[test]
    fn identical_renders_have_zero_error_and_infinite_psnr() {
        let a = fb_with(&[1.0, 2.0, f32::INFINITY], &[Vec3::Z, Vec3::Y, Vec3::ZERO]);
        let acc = compare(&a, &a).unwrap();
        assert_eq!(acc.silhouette_mismatch, 0);
        assert_eq!(acc.both_hit, 2);
        assert_eq!(acc.depth_abs_max, 0.0);
        assert_eq!(acc.normal_deg_max, 0.0);
        assert!(acc.psnr_db.is_infinite());
    }

    #[test]
    fn errors_are_measured_where_both_hit_and_silhouettes_counted() {
        let r = fb_with(&[1.0, 2.0, f32::INFINITY, 4.0], &[Vec3::Z; 4]);
        let n45 = Vec3::new(0.0, 1.0, 1.0).normalize();
        let t = fb_with(&[1.5, 2.0, 3.0, 4.0], &[Vec3::Z, n45, Vec3::Z, Vec3::Z]);
        let acc = compare(&t, &r).unwrap();
        assert_eq!(acc.silhouette_mismatch, 1);
        assert_eq!(acc.silhouette_mismatch_pct, 25.0);
        assert_eq!(acc.both_hit, 3);
        assert!((acc.depth_abs_max - 0.5).abs() < 1e-9);
        assert!((acc.depth_abs_mean - 0.5 / 3.0).abs() < 1e-9);
        assert!((acc.depth_rel_p95 - 0.5).abs() < 1e-9);
        assert!((acc.normal_deg_max - 45.0).abs() < 1e-4);
        assert!((acc.normal_deg_mean - 15.0).abs() < 1e-4);
        assert!((acc.depth_rel_max - 0.5).abs() < 1e-9);
        assert_eq!(acc.depth_rel_tail_px, 1);
        assert_eq!(acc.normal_deg_tail_px, 1);
        assert!(acc.psnr_db.is_finite());
    }

    #[test]
    fn tail_counts_see_the_few_large_errors_a_p95_hides() {
        // 100 pixels: 97 exact, 3 with a 20% depth error and a 90-degree normal.
        let r = fb_with(&[10.0; 100], &[Vec3::Z; 100]);
        let mut depths = [10.0f32; 100];
        let mut normals = [Vec3::Z; 100];
        for i in [3, 50, 97] {
            depths[i] = 12.0;
            normals[i] = Vec3::X;
        }
        // Just inside both bounds: not counted.
        depths[10] = 10.0 + 0.9e-2;
        normals[10] = Vec3::new(0.0, 4.9f32.to_radians().sin(), 4.9f32.to_radians().cos());
        let acc = compare(&fb_with(&depths, &normals), &r).unwrap();
        assert!(acc.depth_rel_p95 < 1e-3, "the p95 hides them: {acc:?}");
        assert!((acc.depth_rel_max - 0.2).abs() < 1e-6);
        assert_eq!(acc.depth_rel_tail_px, 3);
        assert_eq!(acc.normal_deg_tail_px, 3);
    }

    #[test]
    fn size_mismatch_is_an_error() {
        let a = Framebuffer::new(2, 2);
        let b = Framebuffer::new(2, 3);
        assert!(compare(&a, &b).is_err());
    }

    #[test]
    fn quantile_uses_nearest_rank() {
        let mut v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(quantile(&mut v, 0.95), 95.0);
        assert_eq!(quantile(&mut v, 0.0), 1.0);
        assert_eq!(quantile(&mut v, 1.0), 100.0);
        assert_eq!(quantile(&mut [], 0.5), 0.0);
    }
}
