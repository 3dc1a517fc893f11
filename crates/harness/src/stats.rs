//! Timing statistics: median, min, max, MAD and a distribution-free confidence interval of
//! the median from order statistics; and the repeat loop that collects the samples.

use serde::{Deserialize, Serialize};

/// Summary of a set of samples (any unit; the harness uses milliseconds).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Number of samples.
    pub n: usize,
    /// Median (mean of the two middle samples for even `n`).
    pub median: f64,
    /// Smallest sample.
    pub min: f64,
    /// Largest sample.
    pub max: f64,
    /// Median absolute deviation from the median (unscaled).
    pub mad: f64,
    /// Lower end of the confidence interval of the median: order statistic `x_(j)`.
    pub ci_low: f64,
    /// Upper end: order statistic `x_(n+1-j)`.
    pub ci_high: f64,
    /// Actual coverage of `[ci_low, ci_high]` (>= 0.95 from 6 samples on; fewer samples
    /// give `[min, max]` with coverage `1 - 2^(1-n)`).
    pub ci_coverage: f64,
}

fn median_sorted(s: &[f64]) -> f64 {
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// The 1-based rank `j` of the order-statistic interval `[x_(j), x_(n+1-j)]` for the median
/// with coverage at least `confidence`, and its exact coverage under the binomial(n, 1/2)
/// law. The largest such `j` (narrowest interval); `j = 1` with lower coverage when even
/// `[min, max]` does not reach `confidence`. `n` must be >= 1.
pub fn median_ci_rank(n: usize, confidence: f64) -> (usize, f64) {
    let tail = (1.0 - confidence) / 2.0;
    // log pmf(0) = -n ln 2; pmf(k) = pmf(k-1) * (n-k+1)/k.
    let mut log_pmf = -(n as f64) * std::f64::consts::LN_2;
    let mut cdf = log_pmf.exp(); // P(X <= 0)
    if cdf > tail {
        return (1, 1.0 - 2.0 * cdf);
    }
    // Invariant: cdf = P(X <= j - 1) <= tail.
    let mut j = 1;
    while j < n.div_ceil(2) {
        log_pmf += ((n - j + 1) as f64 / j as f64).ln();
        let next = cdf + log_pmf.exp(); // P(X <= j)
        if next > tail {
            break;
        }
        cdf = next;
        j += 1;
    }
    (j, 1.0 - 2.0 * cdf)
}

impl Summary {
    /// Summarises `samples` (NaN samples are an error of the caller: they sort last).
    /// `None` for an empty slice.
    pub fn of(samples: &[f64]) -> Option<Self> {
        if samples.is_empty() {
            return None;
        }
        let mut s = samples.to_vec();
        s.sort_by(|a, b| a.total_cmp(b));
        let n = s.len();
        let median = median_sorted(&s);
        let mut dev: Vec<f64> = s.iter().map(|x| (x - median).abs()).collect();
        dev.sort_by(|a, b| a.total_cmp(b));
        let (j, coverage) = median_ci_rank(n, 0.95);
        Some(Self {
            n,
            median,
            min: s[0],
            max: s[n - 1],
            mad: median_sorted(&dev),
            ci_low: s[j - 1],
            ci_high: s[n - j],
            ci_coverage: coverage,
        })
    }
}

/// The paired ratio `b / a` of two configurations measured in the same rotation rounds: the
/// per-round ratios `b_r / a_r` over the rounds both took part in, summarised like any sample
/// (median with its order-statistic confidence interval). A slow drift of the machine's load
/// scales both renders of a round alike and cancels in the ratio, which a ratio of two medians
/// taken at different times does not.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PairedRatio {
    /// Rounds in which both were measured.
    pub rounds: usize,
    /// Median of the per-round ratios.
    pub median: f64,
    /// Lower end of its confidence interval.
    pub ci_low: f64,
    /// Upper end.
    pub ci_high: f64,
    /// Coverage of `[ci_low, ci_high]`.
    pub ci_coverage: f64,
}

impl PairedRatio {
    /// Pairs the samples of `a` and `b` by round (`(round, value)` pairs; a round missing in
    /// either is skipped; non-positive or non-finite values are skipped). `None` when no round
    /// pairs up.
    pub fn of(a: &[(u32, f64)], b: &[(u32, f64)]) -> Option<Self> {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        // The first usable sample of each round of `a`, looked up by round: linear in the
        // samples (a results.json may hold millions of them).
        let mut by_round = std::collections::HashMap::with_capacity(a.len());
        for &(r, x) in a.iter().filter(|(_, x)| ok(*x)) {
            by_round.entry(r).or_insert(x);
        }
        let ratios: Vec<f64> = b
            .iter()
            .filter(|(_, y)| ok(*y))
            .filter_map(|(r, y)| by_round.get(r).map(|x| y / x))
            .collect();
        let s = Summary::of(&ratios)?;
        Some(Self {
            rounds: s.n,
            median: s.median,
            ci_low: s.ci_low,
            ci_high: s.ci_high,
            ci_coverage: s.ci_coverage,
        })
    }

    /// Whether the confidence interval excludes 1 (one side is faster beyond the noise).
    pub fn decisive(&self) -> bool {
        self.ci_low > 1.0 || self.ci_high < 1.0
    }
}

/// How many timed repeats to run after the untimed warm-up.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RepeatPolicy {
    /// At least this many timed repeats (>= 1).
    pub min_count: u32,
    /// Keep repeating until the timed repeats add up to this many seconds...
    pub min_time_s: f64,
    /// ...but never more than this many repeats.
    pub max_count: u32,
}

impl Default for RepeatPolicy {
    fn default() -> Self {
        Self {
            min_count: 3,
            min_time_s: 1.0,
            max_count: 50,
        }
    }
}

impl RepeatPolicy {
    /// The `--quick` version: one repeat, no minimum time.
    pub fn quick(self) -> Self {
        Self {
            min_count: 1,
            min_time_s: 0.0,
            max_count: self.max_count.min(1),
        }
    }

    /// How far (0 to 1) `count` repeats taking `total_s` seconds are towards meeting the
    /// policy: the lesser of the count's share of `min_count` and the greater of the time's
    /// share of `min_time_s` and the count's share of `max_count`; 1 once no repeat is due.
    pub fn progress(&self, count: u32, total_s: f64) -> f64 {
        if !self.wants_more(count, total_s) {
            return 1.0;
        }
        let share = |a: f64, b: f64| if b > 0.0 { (a / b).min(1.0) } else { 1.0 };
        let by_count = share(f64::from(count), f64::from(self.min_count.max(1)));
        let by_time = share(total_s, self.min_time_s)
            .max(share(f64::from(count), f64::from(self.max_count.max(1))));
        by_count.min(by_time).clamp(0.0, 1.0)
    }

    /// Whether another repeat is due after `count` repeats taking `total_s` seconds.
    pub fn wants_more(&self, count: u32, total_s: f64) -> bool {
        count < self.min_count.max(1) || (total_s < self.min_time_s && count < self.max_count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repeat_progress_follows_the_policy() {
        let p = RepeatPolicy::default(); // 3 repeats, 1 s, at most 50
        assert_eq!(p.progress(0, 0.0), 0.0);
        // Slow renders: the count decides.
        assert!((p.progress(1, 2.0) - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(p.progress(3, 6.0), 1.0);
        // Fast renders: the time decides.
        assert!((p.progress(10, 0.25) - 0.25).abs() < 1e-12);
        assert_eq!(p.progress(50, 0.5), 1.0);
        assert_eq!(p.quick().progress(1, 0.0), 1.0);
    }

    #[test]
    fn odd_and_even_medians_min_max_mad() {
        let s = Summary::of(&[5.0, 1.0, 3.0, 2.0, 100.0]).unwrap();
        assert_eq!((s.n, s.median, s.min, s.max), (5, 3.0, 1.0, 100.0));
        // |x - 3| = 2, 2, 0, 1, 97 -> sorted 0, 1, 2, 2, 97 -> 2.
        assert_eq!(s.mad, 2.0);
        let e = Summary::of(&[4.0, 1.0, 3.0, 2.0]).unwrap();
        assert_eq!(e.median, 2.5);
        // |x - 2.5| = 1.5, 0.5, 0.5, 1.5 -> 1.0.
        assert_eq!(e.mad, 1.0);
        assert!(Summary::of(&[]).is_none());
        let one = Summary::of(&[7.0]).unwrap();
        assert_eq!(
            (one.median, one.mad, one.ci_low, one.ci_high),
            (7.0, 0.0, 7.0, 7.0)
        );
    }

    #[test]
    fn ci_ranks_match_binomial_tables() {
        // Known order-statistic ranks for a 95% median CI (e.g. Conover, Practical
        // Nonparametric Statistics, table A3): n=6 -> (1,6) 96.9%, n=10 -> (2,9) 97.9%,
        // n=20 -> (6,15) 95.9%, n=100 -> (40,61) 96.5%.
        let (j, c) = median_ci_rank(6, 0.95);
        assert_eq!(j, 1);
        assert!((c - 0.96875).abs() < 1e-12);
        let (j, c) = median_ci_rank(10, 0.95);
        assert_eq!(j, 2);
        assert!((c - 0.978515625).abs() < 1e-9);
        assert_eq!(median_ci_rank(20, 0.95).0, 6);
        assert_eq!(median_ci_rank(100, 0.95).0, 40);
        // Too few samples: [min, max] with its real coverage.
        let (j, c) = median_ci_rank(5, 0.95);
        assert_eq!(j, 1);
        assert!((c - 0.9375).abs() < 1e-12);
        // Large n does not underflow into nonsense: about n/2 - 0.98 sqrt(n).
        let (j, c) = median_ci_rank(10_000, 0.95);
        assert!((4900..=4903).contains(&j), "{j}");
        assert!((0.95..0.96).contains(&c), "{c}");
    }

    #[test]
    fn ci_brackets_the_median_of_synthetic_samples() {
        // 1..=21 shuffled deterministically: median 11, CI ranks (6, 16) for n = 21.
        let samples: Vec<f64> = (0..21).map(|i| ((i * 8) % 21 + 1) as f64).collect();
        let s = Summary::of(&samples).unwrap();
        assert_eq!(s.median, 11.0);
        let (j, _) = median_ci_rank(21, 0.95);
        assert_eq!(j, 6);
        assert_eq!((s.ci_low, s.ci_high), (6.0, 16.0));
        assert!(s.ci_coverage >= 0.95);
    }

    #[test]
    fn paired_ratios_cancel_a_drift_that_unpaired_medians_do_not() {
        // The machine slows down 4x over 11 rounds; b is always exactly 2.5x slower than a
        // within a round, with +-1% jitter alternating in sign.
        let drift = |r: u32| 1.0 + 0.3 * f64::from(r);
        let jitter = |r: u32| if r.is_multiple_of(2) { 1.01 } else { 0.99 };
        let a: Vec<(u32, f64)> = (0..11).map(|r| (r, 10.0 * drift(r))).collect();
        let b: Vec<(u32, f64)> = (0..11).map(|r| (r, 25.0 * drift(r) * jitter(r))).collect();
        let p = PairedRatio::of(&a, &b).unwrap();
        assert_eq!(p.rounds, 11);
        // Per-round ratios are 2.525 (6 rounds) and 2.475 (5 rounds): median 2.525.
        assert!((p.median - 2.525).abs() < 1e-12, "{}", p.median);
        assert!(p.ci_low >= 2.475 - 1e-12 && p.ci_high <= 2.525 + 1e-12);
        assert!(p.decisive());
        // If b's rounds were taken later (the last 6 rounds) and a's earlier (first 5), the
        // unpaired ratio of medians would be far off.
        let ma = Summary::of(&a[..5].iter().map(|x| x.1).collect::<Vec<_>>()).unwrap();
        let mb = Summary::of(&b[5..].iter().map(|x| x.1).collect::<Vec<_>>()).unwrap();
        assert!(mb.median / ma.median > 3.5);
    }

    #[test]
    fn paired_ratio_skips_unpaired_rounds_and_spans_one_when_undecided() {
        let a = [(0, 10.0), (1, 10.0), (2, 10.0), (3, 10.0), (5, 1.0)];
        let b = [(0, 9.0), (1, 11.0), (2, 9.5), (3, 10.5), (4, 3.0)];
        let p = PairedRatio::of(&a, &b).unwrap();
        assert_eq!(p.rounds, 4);
        assert!((p.median - 1.0).abs() < 1e-12);
        assert_eq!((p.ci_low, p.ci_high), (0.9, 1.1));
        assert!(!p.decisive());
        assert!(PairedRatio::of(&a, &[(9, 1.0)]).is_none());
        assert!(PairedRatio::of(&[(0, 0.0)], &[(0, 1.0)]).is_none());
        // A round's first usable sample of `a` is the one paired.
        let p = PairedRatio::of(&[(0, 0.0), (0, 2.0), (0, 4.0)], &[(0, 1.0)]).unwrap();
        assert_eq!((p.rounds, p.median), (1, 0.5));
    }

    #[test]
    fn pairing_a_million_rounds_takes_linear_time() {
        let n = 1_000_000u32;
        let a: Vec<(u32, f64)> = (0..n).map(|r| (r, 1.0)).collect();
        let b: Vec<(u32, f64)> = (0..n).rev().map(|r| (r, 2.0)).collect();
        let start = std::time::Instant::now();
        let p = PairedRatio::of(&a, &b).unwrap();
        assert_eq!((p.rounds, p.median), (n as usize, 2.0));
        // Searching `a` for each sample of `b` took hours here.
        assert!(start.elapsed() < std::time::Duration::from_secs(30));
    }

    #[test]
    fn repeat_policy_honours_count_and_time() {
        let p = RepeatPolicy {
            min_count: 3,
            min_time_s: 1.0,
            max_count: 10,
        };
        // Fast samples (10 ms): keep going to the max count (time never reached).
        assert!(p.wants_more(9, 0.09));
        assert!(!p.wants_more(10, 0.1));
        // Slow samples (600 ms): the min count suffices once time is reached.
        assert!(p.wants_more(2, 1.2));
        assert!(!p.wants_more(3, 1.8));
        // Quick: one sample.
        assert!(p.quick().wants_more(0, 0.0));
        assert!(!p.quick().wants_more(1, 0.01));
    }
}
