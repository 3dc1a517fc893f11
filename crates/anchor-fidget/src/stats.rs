//! Timing summaries and depth errors against the exact reference.

use serde::Serialize;

/// Wall times of one renderer's timed repeats on one scene.
#[derive(Debug, Clone, Serialize)]
pub struct Timing {
    /// Every timed repeat, seconds, in round order.
    pub times_s: Vec<f64>,
    /// Median of `times_s`.
    pub median_s: f64,
    /// Smallest of `times_s`.
    pub min_s: f64,
    /// Megapixels per second at the median time.
    pub mpix_per_s_median: f64,
    /// Megapixels per second at the smallest time.
    pub mpix_per_s_best: f64,
}

impl Timing {
    /// Summarises `times_s` for an image of `pixels` pixels. `times_s` must not be empty.
    pub fn new(times_s: Vec<f64>, pixels: u64) -> Self {
        let median_s = median(&times_s);
        let min_s = times_s.iter().copied().fold(f64::INFINITY, f64::min);
        let mp = pixels as f64 / 1e6;
        Self {
            median_s,
            min_s,
            mpix_per_s_median: mp / median_s,
            mpix_per_s_best: mp / min_s,
            times_s,
        }
    }
}

/// Median of `v` (mean of the middle two for even lengths); NaN for an empty slice.
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// One renderer's depth (distance along the unit camera ray) against the reference's, per
/// pixel.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct DepthErrors {
    /// Pixels both hit (the errors below are over these).
    pub compared: u64,
    /// Mean absolute depth error, world units.
    pub mean: f64,
    /// 95th percentile of the absolute error (nearest rank).
    pub p95: f64,
    /// Largest absolute error.
    pub max: f64,
    /// Pixel index (`row * width + column`) of the largest error, with the renderer's and
    /// the reference's depths there.
    pub max_at: Option<(u64, f64, f64)>,
    /// Mean of `|error| / reference depth`.
    pub mean_relative: f64,
    /// Pixels whose relative error exceeds 1e-2: a different surface (a sliver or a
    /// silhouette stepped over, with something behind it hit instead).
    pub over_1e2_relative: u64,
    /// Pixels where exactly one of the two hit: `only_renderer + only_reference`.
    pub silhouette_mismatch: u64,
    /// Pixels the renderer hit and the reference did not.
    pub only_renderer: u64,
    /// Pixels the reference hit and the renderer did not.
    pub only_reference: u64,
}

impl DepthErrors {
    /// Compares per-pixel depths (`None` = no hit). Both slices have one entry per pixel.
    pub fn new(renderer: &[Option<f64>], reference: &[Option<f64>]) -> Self {
        assert_eq!(renderer.len(), reference.len(), "one depth per pixel");
        let mut errs = Vec::new();
        let mut rel = 0.0;
        let mut out = Self::default();
        for (i, (r, g)) in renderer.iter().zip(reference).enumerate() {
            match (r, g) {
                (Some(r), Some(g)) => {
                    let e = (r - g).abs();
                    if out.max_at.is_none() || e > out.max {
                        out.max = e;
                        out.max_at = Some((i as u64, *r, *g));
                    }
                    errs.push(e);
                    let re = e / g.abs().max(f64::MIN_POSITIVE);
                    rel += re;
                    if re > 1e-2 {
                        out.over_1e2_relative += 1;
                    }
                }
                (Some(_), None) => out.only_renderer += 1,
                (None, Some(_)) => out.only_reference += 1,
                (None, None) => {}
            }
        }
        out.silhouette_mismatch = out.only_renderer + out.only_reference;
        out.compared = errs.len() as u64;
        if !errs.is_empty() {
            out.mean = errs.iter().sum::<f64>() / errs.len() as f64;
            out.mean_relative = rel / errs.len() as f64;
            errs.sort_by(f64::total_cmp);
            let rank = ((0.95 * errs.len() as f64).ceil() as usize).clamp(1, errs.len());
            out.p95 = errs[rank - 1];
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_and_silhouettes_are_counted() {
        let r = [Some(1.0), Some(2.5), None, Some(4.0), None];
        let g = [Some(1.5), Some(2.0), Some(3.0), None, None];
        let e = DepthErrors::new(&r, &g);
        assert_eq!(e.compared, 2);
        assert_eq!(
            (e.only_renderer, e.only_reference, e.silhouette_mismatch),
            (1, 1, 2)
        );
        assert!((e.mean - 0.5).abs() < 1e-15 && e.max == 0.5 && e.p95 == 0.5);
        assert_eq!(e.max_at, Some((0, 1.0, 1.5)));
        assert_eq!(e.over_1e2_relative, 2);
        assert!((e.mean_relative - 0.5 * (0.5 / 1.5 + 0.25)).abs() < 1e-15);
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        let t = Timing::new(vec![0.5, 0.25, 1.0], 1_000_000);
        assert_eq!((t.median_s, t.min_s, t.mpix_per_s_median), (0.5, 0.25, 2.0));
    }
}
