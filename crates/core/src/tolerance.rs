//! Accuracy bounds a render must meet against the reference: one type for the conformance
//! suite's per-case tolerances and the stability study's exact/degraded verdicts, so both read
//! the same metrics the same way.

use crate::{Accuracy, RenderStats};

/// PSNR (dB, 8-bit images against the reference) above which the remaining differences are
/// hard to see at the default image sizes: the benchmark headlines' threshold and the
/// stability study's "exact" bound for cases judged by the image.
pub const INVISIBLE_PSNR_DB: f64 = 40.0;

/// What a render measured against the reference, in the units of [`Tolerance`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    /// Pixels hit by exactly one of the two, % of all pixels.
    pub silhouette_mismatch_pct: f64,
    /// 95th percentile of |depth - true depth| / true depth over pixels both hit (NaN when no
    /// pixel is hit by both).
    pub depth_rel_p95: f64,
    /// Mean normal angle error over pixels both hit, degrees (NaN when none).
    pub normal_deg_mean: f64,
    /// Pixels both hit showing another material, % of those pixels.
    pub material_mismatch_pct: f64,
    /// Rays that ended by step exhaustion, %.
    pub step_exhaustion_pct: f64,
}

impl Measured {
    /// The measurements of a render compared with the reference (`accuracy`) and its
    /// counters (`stats`).
    pub fn of(accuracy: &Accuracy, stats: &RenderStats) -> Self {
        Self {
            silhouette_mismatch_pct: accuracy.silhouette_mismatch_pct,
            depth_rel_p95: accuracy.depth_rel_p95,
            normal_deg_mean: accuracy.normal_deg_mean,
            material_mismatch_pct: 100.0 * accuracy.material_mismatch as f64
                / accuracy.both_hit.max(1) as f64,
            step_exhaustion_pct: 100.0 * stats.step_exhaustion_rate(),
        }
    }
}

/// Largest errors a render may show against the reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerance {
    /// Largest share of pixels hit by exactly one of the backend and the reference, %.
    pub silhouette_mismatch_pct: f64,
    /// Largest 95th-percentile depth error relative to the reference depth.
    pub depth_rel_p95: f64,
    /// Largest mean normal angle error, degrees.
    pub normal_deg_mean: f64,
    /// Largest share of pixels (hit by both) showing a different material, %.
    pub material_mismatch_pct: f64,
    /// Largest share of rays that may end by step exhaustion, %.
    pub step_exhaustion_pct: f64,
}

impl Default for Tolerance {
    /// Tight defaults meant for an accurate backend (the conformance suite's): 1.5%
    /// silhouette pixels, 0.2% relative depth, 1 degree mean normal error, 1% material, no
    /// step exhaustion.
    fn default() -> Self {
        Self {
            silhouette_mismatch_pct: 1.5,
            depth_rel_p95: 2e-3,
            normal_deg_mean: 1.0,
            material_mismatch_pct: 1.0,
            step_exhaustion_pct: 0.0,
        }
    }
}

impl Tolerance {
    /// The stability study's "exact": 0.5% silhouette pixels, 1e-3 relative depth (p95),
    /// 1 degree mean normal error, 0.1% of rays exhausted (materials not judged).
    pub const STABILITY_EXACT: Self = Self {
        silhouette_mismatch_pct: 0.5,
        depth_rel_p95: 1e-3,
        normal_deg_mean: 1.0,
        material_mismatch_pct: f64::INFINITY,
        step_exhaustion_pct: 0.1,
    };

    /// The stability study's "degraded" (beyond it: broken): 5% silhouette pixels, 1e-2
    /// relative depth, 5 degrees, 5% of rays exhausted.
    pub const STABILITY_DEGRADED: Self = Self {
        silhouette_mismatch_pct: 5.0,
        depth_rel_p95: 1e-2,
        normal_deg_mean: 5.0,
        material_mismatch_pct: f64::INFINITY,
        step_exhaustion_pct: 5.0,
    };

    /// Every bound `m` exceeds, one sentence each; empty when `m` is within all of them.
    /// Depth and normal errors that are NaN (no pixel hit by both) pass: the silhouette bound
    /// decides those renders alone.
    pub fn violations(&self, m: &Measured) -> Vec<String> {
        let mut out = Vec::new();
        if m.silhouette_mismatch_pct > self.silhouette_mismatch_pct {
            out.push(format!(
                "silhouette mismatch {:.2}% > {:.2}%",
                m.silhouette_mismatch_pct, self.silhouette_mismatch_pct
            ));
        }
        if m.depth_rel_p95 > self.depth_rel_p95 {
            out.push(format!(
                "relative depth error p95 {:.2e} > {:.2e}",
                m.depth_rel_p95, self.depth_rel_p95
            ));
        }
        if m.normal_deg_mean > self.normal_deg_mean {
            out.push(format!(
                "mean normal error {:.3} deg > {:.3} deg",
                m.normal_deg_mean, self.normal_deg_mean
            ));
        }
        if m.material_mismatch_pct > self.material_mismatch_pct {
            out.push(format!(
                "material mismatch {:.2}% > {:.2}%",
                m.material_mismatch_pct, self.material_mismatch_pct
            ));
        }
        if m.step_exhaustion_pct > self.step_exhaustion_pct {
            out.push(format!(
                "step exhaustion {:.3}% > {:.3}%",
                m.step_exhaustion_pct, self.step_exhaustion_pct
            ));
        }
        out
    }

    /// Whether `m` is within every bound ([`Tolerance::violations`] is empty).
    pub fn admits(&self, m: &Measured) -> bool {
        self.violations(m).is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(sil: f64, depth: f64, normal: f64, exhaust: f64) -> Measured {
        Measured {
            silhouette_mismatch_pct: sil,
            depth_rel_p95: depth,
            normal_deg_mean: normal,
            material_mismatch_pct: 0.0,
            step_exhaustion_pct: exhaust,
        }
    }

    #[test]
    fn bounds_are_inclusive_and_nan_errors_pass() {
        let t = Tolerance::STABILITY_EXACT;
        assert!(t.admits(&m(0.5, 1e-3, 1.0, 0.1)));
        assert!(t.admits(&m(0.0, f64::NAN, f64::NAN, 0.0)));
        let v = t.violations(&m(0.6, 2e-3, 1.5, 0.2));
        assert_eq!(v.len(), 4, "{v:?}");
        assert!(v[0].starts_with("silhouette mismatch 0.60% > 0.50%"));
        assert!(Tolerance::STABILITY_DEGRADED.admits(&m(0.6, 2e-3, 1.5, 0.2)));
        assert!(!Tolerance::default().admits(&Measured {
            material_mismatch_pct: 2.0,
            ..m(0.0, 0.0, 0.0, 0.0)
        }));
    }
}
