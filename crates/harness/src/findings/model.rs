//! What the findings are made from: rows as points of a run, duels between the fastest
//! backends with the interval of their ratio, crossovers, axis values, links to the runs, and
//! the finished sections and plots.

use std::collections::BTreeMap;

use super::Run;
use crate::results::Row;
use crate::verdicts::Clock;

/// A row with the run it came from.
#[derive(Clone, Copy)]
pub(super) struct Point<'a> {
    pub(super) run: usize,
    pub(super) row: &'a Row,
    pub(super) clock: Clock,
}

impl Point<'_> {
    pub(super) fn ms(&self) -> f64 {
        self.clock.median_ms(self.row)
    }
    /// The 95% CI of the median on the run's clock.
    pub(super) fn ci(&self) -> (f64, f64) {
        self.clock.ci_ms(self.row)
    }
    pub(super) fn label(&self) -> String {
        format!("{}:{}", self.row.backend, self.row.quality)
    }
}

/// Which of two points is faster, with the ratio's interval from the medians' CIs.
pub(super) struct Duel {
    pub(super) faster: String,
    pub(super) slower: String,
    /// slower / faster by the medians.
    pub(super) ratio: f64,
    /// Interval of slower / faster allowed by the two CIs (low may be below 1).
    pub(super) range: (f64, f64),
}

impl Duel {
    pub(super) fn of(a: &Point<'_>, b: &Point<'_>) -> Self {
        let (f, s) = if a.ms() <= b.ms() { (a, b) } else { (b, a) };
        let (fl, fh) = f.ci();
        let (sl, sh) = s.ci();
        Self {
            faster: f.row.backend.clone(),
            slower: s.row.backend.clone(),
            ratio: s.ms() / f.ms().max(1e-12),
            range: (sl / fh.max(1e-12), sh / fl.max(1e-12)),
        }
    }
    pub(super) fn decisive(&self) -> bool {
        self.range.0 > 1.0
    }
    pub(super) fn winner(&self) -> &str {
        if self.decisive() {
            &self.faster
        } else {
            "no clear winner"
        }
    }
    pub(super) fn describe(&self) -> String {
        if self.decisive() {
            format!(
                "{} {:.2}x faster than {} (CI range {:.2}-{:.2})",
                self.faster, self.ratio, self.slower, self.range.0, self.range.1
            )
        } else {
            format!(
                "no clear winner ({} {:.2}x faster than {} by the medians, CI range {:.2}-{:.2} includes 1)",
                self.faster, self.ratio, self.slower, self.range.0, self.range.1
            )
        }
    }
    /// ln(time of `a` / time of `b`) by medians and its interval.
    pub(super) fn log_ratio(a: &Point<'_>, b: &Point<'_>) -> (f64, f64, f64) {
        let (al, ah) = a.ci();
        let (bl, bh) = b.ci();
        ((a.ms() / b.ms()).ln(), (al / bh).ln(), (ah / bl).ln())
    }
}

/// The value of a scene-size axis: finite, or the infinite repetition.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum AxisValue {
    Finite(f64),
    Infinite,
}

impl AxisValue {
    pub(super) fn show(self) -> String {
        match self {
            Self::Finite(v) => sig(v),
            Self::Infinite => "infinite".into(),
        }
    }
}

/// `v` with about three significant digits, integers below 10^7 in full.
pub(super) fn sig(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e7 {
        format!("{v:.0}")
    } else if v.abs() >= 1e7 {
        format!("{v:.2e}")
    } else if v.abs() >= 100.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.3}")
    }
}

/// The number a generated scene's name ends with (`repeat_100` -> 100, `repeat_inf` ->
/// infinite), if any.
pub(super) fn size_in_name(scene: &str) -> Option<AxisValue> {
    let tail = scene.rsplit(['_', '-']).next()?;
    if tail == "inf" {
        return Some(AxisValue::Infinite);
    }
    tail.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .map(AxisValue::Finite)
        .filter(|_| scene.len() > tail.len())
}

/// `runs` reduced to one point per (suite, configuration id): the newest run measuring it
/// (by start date, then command-line order), listed in the order the runs were given.
pub(super) fn newest_points(runs: &[Run]) -> Vec<Point<'_>> {
    let mut by_date: Vec<usize> = (0..runs.len()).collect();
    by_date.sort_by(|&a, &b| {
        runs[a]
            .results
            .provenance
            .date_utc
            .cmp(&runs[b].results.provenance.date_utc)
            .then(a.cmp(&b))
    });
    let mut by_id: BTreeMap<(String, String), Point<'_>> = BTreeMap::new();
    for &i in &by_date {
        let clock = Clock::for_run(&runs[i].results);
        for row in &runs[i].results.rows {
            let key = (runs[i].results.suite.clone(), row.config_id.clone());
            by_id.insert(key, Point { run: i, row, clock });
        }
    }
    let mut out = Vec::new();
    for r in runs {
        for row in &r.results.rows {
            if let Some(p) = by_id.remove(&(r.results.suite.clone(), row.config_id.clone())) {
                out.push(p);
            }
        }
    }
    out
}

/// The distinct values of `f` over `items`, in first-appearance order.
pub(super) fn distinct<T, K: PartialEq>(items: &[T], f: impl Fn(&T) -> K) -> Vec<K> {
    let mut out: Vec<K> = Vec::new();
    for x in items {
        let k = f(x);
        if !out.contains(&k) {
            out.push(k);
        }
    }
    out
}

/// A finished section of the document.
pub(super) struct Section {
    pub(super) title: String,
    pub(super) brief: String,
    pub(super) body: String,
}

/// A link to the run's `summary.md`; a run that did not finish (interrupted, killed or with
/// configurations missing) has none, so it is named and marked incomplete instead.
pub(super) fn link(runs: &[Run], run: usize) -> String {
    let r = &runs[run];
    if r.results.is_incomplete() {
        format!(
            "{} (incomplete run: {} configurations missing)",
            crate::report::md_escape(&r.name),
            r.results.missing.len()
        )
    } else {
        let url: String = r
            .name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || "-._~/=,+:".contains(c) {
                    c.to_string()
                } else {
                    let mut b = [0u8; 4];
                    c.encode_utf8(&mut b)
                        .bytes()
                        .map(|x| format!("%{x:02X}"))
                        .collect()
                }
            })
            .collect();
        format!("[{}]({url}/summary.md)", crate::report::md_escape(&r.name))
    }
}

pub(super) fn run_links(runs: &[Run], points: &[Point<'_>]) -> String {
    distinct(points, |p| p.run)
        .into_iter()
        .map(|r| link(runs, r))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Rows of more than one machine cannot carry a speed claim: different CPU models, or
/// different host names where the runs recorded them (older runs did not).
pub(super) fn machines_differ(runs: &[Run], points: &[Point<'_>]) -> bool {
    let cpus = distinct(points, |p| runs[p.run].results.provenance.cpu_model.clone());
    let hosts: Vec<String> = distinct(points, |p| {
        if p.row.machine.is_empty() {
            runs[p.run].results.provenance.machine.clone()
        } else {
            p.row.machine.clone()
        }
    })
    .into_iter()
    .filter(|m| !m.is_empty())
    .collect();
    cpus.len() > 1 || hosts.len() > 1
}

/// The fastest point of each backend among `points`.
pub(super) fn fastest_per_backend<'a>(points: &[Point<'a>]) -> Vec<Point<'a>> {
    distinct(points, |p| p.row.backend.clone())
        .into_iter()
        .filter_map(|b| {
            points
                .iter()
                .filter(|p| p.row.backend == b)
                .min_by(|x, y| x.ms().total_cmp(&y.ms()))
                .copied()
        })
        .collect()
}

/// Fastest and runner-up backend among `points`.
pub(super) fn duel(points: &[Point<'_>]) -> Option<Duel> {
    let mut best = fastest_per_backend(points);
    best.sort_by(|x, y| x.ms().total_cmp(&y.ms()));
    match best.as_slice() {
        [a, b, ..] => Some(Duel::of(a, b)),
        _ => None,
    }
}

/// Where along a log axis the two backends' times cross between `x0` and `x1`: the
/// interpolated point (linear in log x and log time ratio) and the interval given by the CI
/// bounds of the ratio at both ends.
pub(super) fn crossover(
    x0: f64,
    x1: f64,
    r0: (f64, f64, f64),
    r1: (f64, f64, f64),
) -> (f64, f64, f64) {
    let (l0, l1) = (x0.ln(), x1.ln());
    let at = |a: f64, b: f64| {
        if (a - b).abs() < 1e-12 || a.signum() == b.signum() && a != 0.0 {
            None
        } else {
            Some((l0 + (l1 - l0) * a / (a - b)).exp())
        }
    };
    let mid = at(r0.0, r1.0).unwrap_or((x0 * x1).sqrt());
    let ends: Vec<f64> = [at(r0.1, r1.1), at(r0.2, r1.2)]
        .into_iter()
        .map(|v| v.unwrap_or(mid))
        .collect();
    let lo = ends.iter().copied().fold(mid, f64::min).max(x0.min(x1));
    let hi = ends.iter().copied().fold(mid, f64::max).min(x0.max(x1));
    (mid, lo, hi)
}

pub(super) fn slug(s: &str) -> String {
    crate::bench::slug(s).replace(['/', ':'], "_")
}

/// One point of a scene-size axis: its value, the winner there, ln(time ratio) of the two
/// leading backends with its interval, and which two backends (`a/b`) that ratio is of.
pub(super) type Step = (AxisValue, String, Option<(f64, f64, f64)>, String);

/// A plot to draw.
pub(super) struct Plot {
    pub(super) file: String,
    pub(super) title: String,
    pub(super) x: String,
    pub(super) series: Vec<(String, Vec<(f64, f64)>)>,
    pub(super) log_x: bool,
    /// Thread-axis speedup plots: the ideal line y = x / base.
    pub(super) ideal: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_names_carry_sizes() {
        assert_eq!(size_in_name("repeat_100"), Some(AxisValue::Finite(100.0)));
        assert_eq!(size_in_name("repeat_inf"), Some(AxisValue::Infinite));
        assert_eq!(size_in_name("csg"), None);
        assert_eq!(size_in_name("100"), None);
    }

    #[test]
    fn crossovers_interpolate_in_log_space_with_an_interval() {
        // log ratio goes from +ln 2 at x=10 to -ln 2 at x=1000: crossing at 100.
        let (mid, lo, hi) = crossover(
            10.0,
            1000.0,
            (2f64.ln(), 1.5f64.ln(), 2.5f64.ln()),
            (0.5f64.ln(), 0.4f64.ln(), 0.6f64.ln()),
        );
        assert!((mid - 100.0).abs() < 1e-9, "{mid}");
        assert!(
            lo < mid && mid < hi && lo >= 10.0 && hi <= 1000.0,
            "{lo} {hi}"
        );
    }
}
