//! Which backend is faster, said once: the clock verdicts read ([`Clock`]), speed ratios of
//! two rows with their uncertainty ([`Contest`], paired by rotation round when the rows were
//! timed together), the per-setting headline ([`Headline`]), the "faster at matched accuracy"
//! claims ([`matched_accuracy`]), and how two runs' verdicts agree ([`compare_runs`]). The
//! summary and `marchmesh compare` both read these, so a verdict is computed in one place.

use std::collections::BTreeMap;
use std::fmt;

use crate::results::{Results, Row, TimingSample};
use crate::stats::{PairedRatio, Summary};

/// PSNR against the reference (dB) a configuration must reach to count in a headline, the
/// findings' memory budget and `compare`'s verdict view: [`marchmesh_core::INVISIBLE_PSNR_DB`],
/// beyond which the remaining differences are hard to see (the stability study's "exact" for
/// image-judged cases too).
pub const HEADLINE_MIN_PSNR_DB: f64 = marchmesh_core::INVISIBLE_PSNR_DB;

/// The time a verdict compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clock {
    /// Wall-clock time of a render: what a user waits, but inflated unevenly by other
    /// processes when the machine is oversubscribed.
    Wall,
    /// Process CPU time (user + system, all threads): hardly changed by competing processes,
    /// blind to idle waiting (none in a CPU-bound render).
    Cpu,
}

impl Clock {
    /// The clock for `res`: CPU time when the 1-minute load average at the start or the end of
    /// the run exceeded the logical core count (other processes then took cores from the
    /// renders, so wall time measured the machine's load as much as the renders) and every row
    /// has CPU time; wall time otherwise.
    pub fn for_run(res: &Results) -> Self {
        let p = &res.provenance;
        let load = p
            .load_average_1m
            .into_iter()
            .chain(p.load_average_1m_end)
            .fold(f64::NEG_INFINITY, f64::max);
        let busy = load > p.logical_cores as f64;
        let merged_busy = res.merged_from.iter().any(|m| {
            m.provenance
                .load_average_1m
                .into_iter()
                .chain(m.provenance.load_average_1m_end)
                .any(|l| l > m.provenance.logical_cores as f64)
        });
        let all_cpu = res.rows.iter().all(|r| r.render_cpu_ms_median.is_some());
        if (busy || merged_busy) && all_cpu {
            Self::Cpu
        } else {
            Self::Wall
        }
    }

    /// `wall` or `CPU`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Wall => "wall",
            Self::Cpu => "CPU",
        }
    }

    /// The row's median render time on this clock, ms (wall time if the row has no CPU time).
    pub fn median_ms(self, r: &Row) -> f64 {
        match self {
            Self::Cpu => r.render_cpu_ms_median.unwrap_or(r.render_ms_median),
            Self::Wall => r.render_ms_median,
        }
    }

    /// The 95% confidence interval of that median, ms.
    pub(crate) fn ci_ms(self, r: &Row) -> (f64, f64) {
        match (self, r.render_cpu_ms_ci_low, r.render_cpu_ms_ci_high) {
            (Self::Cpu, Some(lo), Some(hi)) => (lo, hi),
            _ => (r.render_ms_ci_low, r.render_ms_ci_high),
        }
    }

    fn sample(self, s: &TimingSample) -> Option<f64> {
        match self {
            Self::Wall => Some(s.wall_ms),
            Self::Cpu => s.cpu_ms,
        }
    }
}

/// What verdicts read from a run: the clock and the per-round samples.
#[derive(Debug, Clone, Copy)]
pub struct Timing<'a> {
    /// The clock.
    pub clock: Clock,
    /// Per configuration id, every timed render.
    pub samples: Option<&'a BTreeMap<String, Vec<TimingSample>>>,
}

impl<'a> Timing<'a> {
    /// The clock of [`Clock::for_run`] and the run's samples.
    pub fn of(res: &'a Results) -> Self {
        Self {
            clock: Clock::for_run(res),
            samples: Some(&res.timings),
        }
    }

    /// Wall time and no samples (ratios of medians): for rows without a run.
    pub fn medians_only() -> Self {
        Self {
            clock: Clock::Wall,
            samples: None,
        }
    }

    fn rounds(&self, r: &Row) -> Option<Vec<(u32, f64)>> {
        let s = self.samples?.get(&r.config_id)?;
        s.iter()
            .map(|x| self.clock.sample(x).map(|v| (x.round, v)))
            .collect()
    }

    /// The speed contest of `a` against `b`: which is faster and by how much, with the
    /// uncertainty of the ratio. Paired (median of per-round ratios with its CI) when both
    /// rows were timed in the same rotation, else the ratio of the medians, called decisive
    /// when the two medians' confidence intervals do not overlap.
    pub fn contest(&self, a: &Row, b: &Row) -> Contest {
        let (ta, tb) = (self.clock.median_ms(a), self.clock.median_ms(b));
        let a_faster = ta <= tb;
        let (fast, slow) = if a_faster { (a, b) } else { (b, a) };
        let paired = match (self.rounds(fast), self.rounds(slow)) {
            (Some(f), Some(s)) => PairedRatio::of(&f, &s),
            _ => None,
        };
        match paired {
            Some(p) => Contest {
                faster: fast.backend.clone(),
                slower: slow.backend.clone(),
                faster_label: format!("{}:{}", fast.backend, fast.quality),
                ratio: p.median,
                ci: Some((p.ci_low, p.ci_high, p.ci_coverage)),
                rounds: p.rounds,
                // The paired median can fall below 1 although the medians say otherwise
                // (skewed samples): then the direction itself is uncertain.
                decisive: p.ci_low > 1.0,
            },
            None => {
                let (f, s) = (self.clock.ci_ms(fast), self.clock.ci_ms(slow));
                Contest {
                    faster: fast.backend.clone(),
                    slower: slow.backend.clone(),
                    faster_label: format!("{}:{}", fast.backend, fast.quality),
                    ratio: self.clock.median_ms(slow) / self.clock.median_ms(fast).max(1e-12),
                    ci: None,
                    rounds: 0,
                    decisive: f.1 < s.0,
                }
            }
        }
    }
}

/// Which of two rows is faster, by how much, and how sure.
#[derive(Debug, Clone, PartialEq)]
pub struct Contest {
    /// Backend of the faster row.
    pub faster: String,
    /// Backend of the slower row.
    pub slower: String,
    /// `backend:quality` of the faster row.
    pub faster_label: String,
    /// Slower time / faster time (>= 1 by the medians; the paired median may dip below 1).
    pub ratio: f64,
    /// Confidence interval of the paired ratio and its coverage, when paired.
    pub ci: Option<(f64, f64, f64)>,
    /// Rotation rounds the paired ratio is over (0 when not paired).
    pub rounds: usize,
    /// The faster row is faster beyond the noise (paired: CI above 1; unpaired: the two
    /// medians' intervals do not overlap).
    pub decisive: bool,
}

impl Contest {
    /// The ratio oriented as `backend`'s time over the other's (< 1: `backend` is faster);
    /// `None` if `backend` is not one of the two.
    pub fn time_ratio_of(&self, backend: &str) -> Option<f64> {
        if self.faster == backend {
            Some(1.0 / self.ratio)
        } else if self.slower == backend {
            Some(self.ratio)
        } else {
            None
        }
    }
}

impl fmt::Display for Contest {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ci = match self.ci {
            Some((lo, hi, cov)) => format!(
                ", paired over {} rounds, {:.0}% CI {lo:.2}-{hi:.2}",
                self.rounds,
                cov * 100.0
            ),
            None => ", ratio of medians".into(),
        };
        if self.decisive {
            write!(
                f,
                "{} {:.2}x faster than {}{ci}",
                self.faster, self.ratio, self.slower
            )
        } else {
            write!(
                f,
                "no clear winner ({} {:.2}x faster than {} by the medians{ci}: within the noise)",
                self.faster, self.ratio, self.slower
            )
        }
    }
}

/// Rows that differ only in backend and quality: speed is compared within one setting
/// (group, scene, image size, threads, machine).
pub type SettingKey = (String, String, u32, u32, usize, String);

/// The setting of a row.
pub fn setting(r: &Row) -> SettingKey {
    (
        r.group.clone(),
        r.scene.clone(),
        r.width,
        r.height,
        r.threads,
        r.machine.clone(),
    )
}

/// The distinct settings of `rows` in first-appearance order (linear time).
pub fn settings<'a>(rows: impl IntoIterator<Item = &'a Row>) -> Vec<SettingKey> {
    by_setting(rows).into_iter().map(|(k, _)| k).collect()
}

/// The rows of each distinct setting, settings in first-appearance order and rows in their
/// order (linear time: one hash lookup per row).
pub fn by_setting<'a>(rows: impl IntoIterator<Item = &'a Row>) -> Vec<(SettingKey, Vec<&'a Row>)> {
    let mut index: std::collections::HashMap<SettingKey, usize> = Default::default();
    let mut out: Vec<(SettingKey, Vec<&'a Row>)> = Vec::new();
    for r in rows {
        let k = setting(r);
        match index.get(&k) {
            Some(&i) => out[i].1.push(r),
            None => {
                index.insert(k.clone(), out.len());
                out.push((k, vec![r]));
            }
        }
    }
    out
}

/// `group/scene WxH tN` (with ` on machine` when `with_machine`).
pub fn setting_name(k: &SettingKey, with_machine: bool) -> String {
    let machine = if with_machine && !k.5.is_empty() {
        format!(" on {}", k.5)
    } else {
        String::new()
    };
    format!("{}/{} {}x{} t{}{machine}", k.0, k.1, k.2, k.3, k.4)
}

/// The backends of `rows` in first-appearance order.
pub fn backends<'a>(rows: impl IntoIterator<Item = &'a Row>) -> Vec<String> {
    let mut seen: std::collections::HashSet<&'a str> = Default::default();
    let mut out: Vec<String> = Vec::new();
    for r in rows {
        if seen.insert(r.backend.as_str()) {
            out.push(r.backend.clone());
        }
    }
    out
}

/// Per backend of `rows` (first-appearance order), its fastest row on `timing`'s clock among
/// those reaching `min_psnr` dB (`None` when none does).
fn fastest_per_backend<'a>(
    rows: &[&'a Row],
    min_psnr: f64,
    timing: Timing<'_>,
) -> Vec<(String, Option<&'a Row>)> {
    backends(rows.iter().copied())
        .into_iter()
        .map(|b| {
            let best = rows
                .iter()
                .filter(|r| r.backend == b && r.psnr_db.is_some_and(|p| p >= min_psnr))
                .min_by(|x, y| {
                    timing
                        .clock
                        .median_ms(x)
                        .total_cmp(&timing.clock.median_ms(y))
                })
                .copied();
            (b, best)
        })
        .collect()
}

/// The contest of the fastest backend's row against the runner-up backend's, when at least
/// two backends have a row.
fn winner_and_runner_up(best: &[(String, Option<&Row>)], timing: Timing<'_>) -> Option<Contest> {
    let mut ranked: Vec<&Row> = best.iter().filter_map(|(_, r)| *r).collect();
    ranked.sort_by(|x, y| {
        timing
            .clock
            .median_ms(x)
            .total_cmp(&timing.clock.median_ms(y))
    });
    match ranked.as_slice() {
        [first, second, ..] => Some(timing.contest(first, second)),
        _ => None,
    }
}

/// The headline of one setting: per backend its fastest row reaching a PSNR threshold, and
/// the contest of the fastest backend with the runner-up.
#[derive(Debug, Clone, PartialEq)]
pub struct Headline {
    /// The setting.
    pub setting: SettingKey,
    /// `group/scene WxH tN`.
    pub name: String,
    /// Per backend of the setting (first-appearance order): its fastest row reaching the
    /// threshold, described as `sdf:quality 12.3 ms (45.0 dB, 1.2 MiB)`, or `None`.
    pub best: Vec<(String, Option<String>)>,
    /// Fastest backend against the runner-up, when two backends reach the threshold.
    pub contest: Option<Contest>,
    /// The PSNR threshold, dB.
    pub min_psnr: f64,
}

impl fmt::Display for Headline {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sides: Vec<String> = self
            .best
            .iter()
            .map(|(b, d)| {
                d.clone()
                    .unwrap_or_else(|| format!("{b}: none reaches {:.0} dB", self.min_psnr))
            })
            .collect();
        write!(f, "{}: {}", self.name, sides.join(" vs "))?;
        if let Some(c) = &self.contest {
            write!(f, ": {c}")?;
        }
        Ok(())
    }
}

/// One headline per setting with accuracy: each backend's fastest row reaching `min_psnr`
/// dB, the fastest backend compared with the runner-up on `timing`'s clock.
pub fn headlines(rows: &[Row], min_psnr: f64, timing: Timing<'_>) -> Vec<Headline> {
    let machines: std::collections::BTreeSet<&str> =
        rows.iter().map(|r| r.machine.as_str()).collect();
    let mut out = Vec::new();
    for (k, set) in by_setting(rows) {
        if set.iter().all(|r| r.psnr_db.is_none()) {
            continue;
        }
        let best = fastest_per_backend(&set, min_psnr, timing);
        let describe = |r: &Row| {
            format!(
                "{}:{} {:.1} ms ({:.1} dB, {})",
                r.backend,
                r.quality,
                timing.clock.median_ms(r),
                r.psnr_db.unwrap_or(f64::NAN),
                crate::report::bytes(r.memory_bytes)
            )
        };
        out.push(Headline {
            name: setting_name(&k, machines.len() > 1),
            setting: k,
            best: best
                .iter()
                .map(|(b, r)| (b.clone(), r.map(describe)))
                .collect(),
            contest: winner_and_runner_up(&best, timing),
            min_psnr,
        });
    }
    out
}

/// The resolution of accuracy targets in dB: the precision every report prints a PSNR with.
/// Two rows whose PSNRs print the same reach the same targets, so a table never shows two
/// targets that read alike with different winners.
pub const PSNR_TARGET_STEP_DB: f64 = 0.1;

/// `psnr_db` rounded to the nearest [`PSNR_TARGET_STEP_DB`]: the highest target a row with
/// that PSNR reaches.
pub fn psnr_target_level(psnr_db: f64) -> f64 {
    (psnr_db / PSNR_TARGET_STEP_DB).round() * PSNR_TARGET_STEP_DB
}

/// For every PSNR target reached in `rows` (one setting; targets are the rows' PSNRs at
/// [`PSNR_TARGET_STEP_DB`] resolution, a row reaching every target up to its own level): the
/// fastest backend reaching it against the runner-up, or `Err(backend)` when only one backend
/// reaches it.
pub fn matched_accuracy(rows: &[&Row], timing: Timing<'_>) -> Vec<(f64, Result<Contest, String>)> {
    let mut targets: Vec<f64> = rows
        .iter()
        .filter_map(|r| r.psnr_db)
        .map(psnr_target_level)
        .collect();
    targets.sort_by(f64::total_cmp);
    targets.dedup_by(|a, b| (*a - *b).abs() < PSNR_TARGET_STEP_DB / 2.0);
    // Per backend, its rows by PSNR from the highest down with the fastest row so far: the
    // fastest row reaching a target is the entry of the last row still reaching it, found
    // by binary search (n log n over all targets instead of n per target).
    let time = |r: &Row| timing.clock.median_ms(r);
    let ladders: Vec<(String, Vec<(f64, &Row)>)> = backends(rows.iter().copied())
        .into_iter()
        .map(|b| {
            let mut own: Vec<(usize, &Row)> = rows
                .iter()
                .copied()
                .enumerate()
                .filter(|(_, r)| r.backend == b && r.psnr_db.is_some())
                .collect();
            own.sort_by(|x, y| {
                let p = |r: &Row| r.psnr_db.unwrap_or(0.0);
                p(y.1).total_cmp(&p(x.1))
            });
            // Ties in time go to the earlier row, as `fastest_per_backend` does.
            let mut ladder: Vec<(f64, &Row)> = Vec::with_capacity(own.len());
            let mut fastest: Option<(usize, &Row)> = None;
            for (i, r) in own {
                fastest = match fastest {
                    Some((j, f)) if time(f).total_cmp(&time(r)).then(j.cmp(&i)).is_le() => {
                        Some((j, f))
                    }
                    _ => Some((i, r)),
                };
                if let Some((_, f)) = fastest {
                    ladder.push((r.psnr_db.unwrap_or(0.0), f));
                }
            }
            (b, ladder)
        })
        .collect();
    targets
        .into_iter()
        .filter_map(|q| {
            let best: Vec<(String, Option<&Row>)> = ladders
                .iter()
                .map(|(b, ladder)| {
                    // A row reaches `q` when its PSNR rounds to `q` or above.
                    let reaching =
                        ladder.partition_point(|(p, _)| *p >= q - PSNR_TARGET_STEP_DB / 2.0);
                    (b.clone(), reaching.checked_sub(1).map(|i| ladder[i].1))
                })
                .collect();
            match winner_and_runner_up(&best, timing) {
                Some(c) => Some((q, Ok(c))),
                None => best
                    .into_iter()
                    .find(|(_, r)| r.is_some())
                    .map(|(b, _)| (q, Err(b))),
            }
        })
        .collect()
}

/// The accuracy targets (PSNR against the reference, dB) the answer is given at: the decision
/// chart of the summary, report.html and the findings, and the verdicts `bench` prints when it
/// ends. 30 dB: a preview whose errors show; [`HEADLINE_MIN_PSNR_DB`] (40 dB): differences hard
/// to see; 50 dB: close to exact.
pub const ACCURACY_TARGETS_DB: [f64; 3] = [30.0, HEADLINE_MIN_PSNR_DB, 50.0];

/// Who is fastest at one accuracy target: only rows whose PSNR reaches the target (at
/// [`PSNR_TARGET_STEP_DB`] resolution) take part, so a winner is only ever named between
/// configurations of matched accuracy.
#[derive(Debug, Clone, PartialEq)]
pub enum TargetVerdict {
    /// Two or more backends reach the target: the fastest against the runner-up (decisive or
    /// not: see [`Contest::decisive`]).
    Contest(Contest),
    /// Only this backend reaches the target (`backend:quality` of its fastest row reaching it).
    Alone {
        /// The backend.
        backend: String,
        /// Its fastest configuration reaching the target.
        label: String,
    },
    /// No row reaches the target.
    Nobody,
}

impl TargetVerdict {
    /// The backend named as the answer: the decisive winner or the one backend reaching the
    /// target; `None` for no clear winner or no row reaching it.
    pub fn winner(&self) -> Option<&str> {
        match self {
            Self::Contest(c) if c.decisive => Some(&c.faster),
            Self::Alone { backend, .. } => Some(backend),
            _ => None,
        }
    }

    /// A short cell text: `mesh 2.71x (CI 2.33-2.90)`, `no clear winner (sdf 1.02x)`, `sdf
    /// alone`, `none reaches it`.
    pub fn short(&self) -> String {
        match self {
            Self::Contest(c) => {
                let ci = match c.ci {
                    Some((lo, hi, _)) => format!("CI {lo:.2}-{hi:.2}"),
                    None => "medians".to_string(),
                };
                if c.decisive {
                    format!("{} {:.2}x ({ci})", c.faster, c.ratio)
                } else {
                    format!("no clear winner ({} {:.2}x, {ci})", c.faster, c.ratio)
                }
            }
            Self::Alone { backend, .. } => format!("{backend} alone"),
            Self::Nobody => "none reaches it".to_string(),
        }
    }
}

impl fmt::Display for TargetVerdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Contest(c) => write!(f, "{c} (`{}`)", c.faster_label),
            Self::Alone { backend, label } => {
                write!(f, "only {backend} reaches it (`{label}`)")
            }
            Self::Nobody => write!(f, "no configuration reaches it"),
        }
    }
}

/// The verdict of `rows` (one setting) at accuracy target `target_db`: each backend's fastest
/// row whose PSNR reaches the target, the fastest backend against the runner-up on `timing`'s
/// clock.
pub fn at_target(rows: &[&Row], target_db: f64, timing: Timing<'_>) -> TargetVerdict {
    let reaching: Vec<&Row> = rows
        .iter()
        .copied()
        .filter(|r| {
            r.psnr_db
                .is_some_and(|p| psnr_target_level(p) >= target_db - PSNR_TARGET_STEP_DB / 2.0)
        })
        .collect();
    let best = fastest_per_backend(&reaching, f64::NEG_INFINITY, timing);
    if let Some(c) = winner_and_runner_up(&best, timing) {
        return TargetVerdict::Contest(c);
    }
    match best.iter().find_map(|(b, r)| r.map(|r| (b, r))) {
        Some((b, r)) => TargetVerdict::Alone {
            backend: b.clone(),
            label: format!("{}:{}", r.backend, r.quality),
        },
        None => TargetVerdict::Nobody,
    }
}

/// How one verdict of run A fares in run B.
#[derive(Debug, Clone, PartialEq)]
pub struct VerdictAgreement {
    /// `headline group/scene WxH tN` or `matched group/scene WxH tN @ 40.0 dB`.
    pub claim: String,
    /// Winner in A and B (`undecided` when within the noise).
    pub winners: (String, String),
    /// Both runs name the same winner, or both are undecided.
    pub agree: bool,
    /// |ratio B / ratio A - 1| in percent, the ratio taken as A's winner's time over A's
    /// runner-up's; `None` when B's contest is between other backends.
    pub moved_pct: Option<f64>,
}

fn winner(c: &Contest) -> String {
    if c.decisive {
        c.faster.clone()
    } else {
        "undecided".into()
    }
}

fn agreement(claim: String, a: &Contest, b: &Contest) -> VerdictAgreement {
    let ra = 1.0 / a.ratio;
    let rb = b
        .time_ratio_of(&a.faster)
        .filter(|_| b.time_ratio_of(&a.slower).is_some());
    let (wa, wb) = (winner(a), winner(b));
    VerdictAgreement {
        claim,
        agree: wa == wb,
        winners: (wa, wb),
        moved_pct: rb.map(|rb| (rb / ra - 1.0).abs() * 100.0),
    }
}

/// Every headline and every matched-accuracy claim present in both runs (same setting,
/// machine ignored: the point is to compare machines and moments), each run read on its own
/// clock ([`Clock::for_run`]).
pub fn compare_runs(a: &Results, b: &Results, min_psnr: f64) -> Vec<VerdictAgreement> {
    let (ta, tb) = (Timing::of(a), Timing::of(b));
    let strip = |k: &SettingKey| (k.0.clone(), k.1.clone(), k.2, k.3, k.4);
    let mut out = Vec::new();
    let hb = headlines(&b.rows, min_psnr, tb);
    let mut hb_index: std::collections::HashMap<_, usize> = Default::default();
    for (i, y) in hb.iter().enumerate() {
        hb_index.entry(strip(&y.setting)).or_insert(i);
    }
    for x in headlines(&a.rows, min_psnr, ta) {
        let Some(y) = hb_index.get(&strip(&x.setting)).map(|&i| &hb[i]) else {
            continue;
        };
        if let (Some(ca), Some(cb)) = (&x.contest, &y.contest) {
            out.push(agreement(
                format!("headline {}", setting_name(&x.setting, false)),
                ca,
                cb,
            ));
        }
    }
    let sets_b = by_setting(&b.rows);
    let mut first_b: std::collections::HashMap<_, usize> = Default::default();
    for (i, (k, _)) in sets_b.iter().enumerate() {
        first_b.entry(strip(k)).or_insert(i);
    }
    for (ka, sa) in by_setting(&a.rows) {
        let Some(&ib) = first_b.get(&strip(&ka)) else {
            continue;
        };
        let ma = matched_accuracy(&sa, ta);
        let mb = matched_accuracy(&sets_b[ib].1, tb);
        for (q, ca) in &ma {
            // mb is sorted by target: the nearest target by binary search.
            let at = mb.partition_point(|(p, _)| *p < q - 1e-9);
            let Some((_, cb)) = mb.get(at).filter(|(p, _)| (p - q).abs() < 1e-9) else {
                continue;
            };
            if let (Ok(ca), Ok(cb)) = (ca, cb) {
                out.push(agreement(
                    format!("matched {} @ {q:.1} dB", setting_name(&ka, false)),
                    ca,
                    cb,
                ));
            }
        }
    }
    out
}

/// A [`Summary`] of the claims' movements (median and max moved percent) and how many claims
/// disagree.
pub fn movement_summary(v: &[VerdictAgreement]) -> Option<(Summary, usize)> {
    let moved: Vec<f64> = v.iter().filter_map(|x| x.moved_pct).collect();
    Summary::of(&moved).map(|s| (s, v.iter().filter(|x| !x.agree).count()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::results::tests_support::{results, row};

    fn samples(values: &[f64]) -> Vec<TimingSample> {
        values
            .iter()
            .enumerate()
            .map(|(i, &v)| TimingSample {
                round: i as u32,
                wall_ms: v,
                cpu_ms: Some(v * 2.0),
            })
            .collect()
    }

    #[test]
    fn contests_pair_by_round_and_say_when_they_cannot_tell() {
        let a = row("sdf", "a", 10.0, Some(45.0), 100);
        let b = row("mesh", "b", 20.0, Some(45.0), 100);
        let mut t = BTreeMap::new();
        // The machine slows down over the rounds; mesh is always 2x sdf.
        t.insert(
            a.config_id.clone(),
            samples(&[10.0, 20.0, 40.0, 80.0, 160.0]),
        );
        t.insert(
            b.config_id.clone(),
            samples(&[20.0, 40.0, 80.0, 160.0, 320.0]),
        );
        let timing = Timing {
            clock: Clock::Wall,
            samples: Some(&t),
        };
        let c = timing.contest(&a, &b);
        assert_eq!((c.faster.as_str(), c.ratio, c.rounds), ("sdf", 2.0, 5));
        assert!(c.decisive);
        assert!(
            c.to_string()
                .starts_with("sdf 2.00x faster than mesh, paired over 5 rounds")
        );
        assert_eq!(c.time_ratio_of("sdf"), Some(0.5));
        assert_eq!(c.time_ratio_of("mesh"), Some(2.0));
        assert_eq!(c.time_ratio_of("voxels"), None);
        // Per-round ratios straddling 1: no winner.
        t.insert(
            b.config_id.clone(),
            samples(&[9.0, 21.0, 39.0, 82.0, 150.0]),
        );
        let timing = Timing {
            clock: Clock::Wall,
            samples: Some(&t),
        };
        let c = timing.contest(&a, &b);
        assert!(!c.decisive, "{c}");
        assert!(c.to_string().starts_with("no clear winner"), "{c}");
        // Without samples: ratio of medians, decisive only when the CIs are apart.
        let c = Timing::medians_only().contest(&a, &b);
        assert_eq!((c.ratio, c.ci), (2.0, None));
        assert!(c.decisive);
    }

    #[test]
    fn a_busy_run_is_judged_on_cpu_time() {
        let mut r = row("sdf", "a", 10.0, Some(45.0), 100);
        r.render_cpu_ms_median = Some(7.0);
        let mut res = results(vec![r.clone()]);
        res.provenance.logical_cores = 2;
        res.provenance.load_average_1m = Some(0.3);
        res.provenance.load_average_1m_end = Some(1.9);
        assert_eq!(Clock::for_run(&res), Clock::Wall);
        res.provenance.load_average_1m_end = Some(4.5);
        assert_eq!(Clock::for_run(&res), Clock::Cpu);
        assert_eq!(Clock::Cpu.median_ms(&r), 7.0);
        // A row without CPU time keeps the run on wall time.
        res.rows.push(row("mesh", "b", 1.0, None, 1));
        assert_eq!(Clock::for_run(&res), Clock::Wall);
    }

    #[test]
    fn verdicts_of_two_runs_agree_or_say_how_they_moved() {
        let rows = |mesh_ms: f64| {
            vec![
                row("sdf", "a", 10.0, Some(45.0), 100),
                row("mesh", "b", mesh_ms, Some(45.0), 100),
            ]
        };
        let mut a = results(rows(20.0));
        let b = results(rows(22.0));
        let v = compare_runs(&a, &b, 40.0);
        // One headline and one matched-accuracy claim (45 dB).
        assert_eq!(v.len(), 2, "{v:?}");
        assert!(v.iter().all(|x| x.agree));
        let moved = v[0].moved_pct.unwrap();
        assert!(
            (moved - (1.0 - 20.0 / 22.0) * 100.0).abs() < 1e-9,
            "{moved}"
        );
        let faster = row("mesh", "b", 5.0, Some(45.0), 100);
        a.rows[1] = faster;
        let v = compare_runs(&a, &b, 40.0);
        assert!(!v[0].agree);
        assert_eq!(v[0].winners, ("mesh".to_string(), "sdf".to_string()));
    }

    #[test]
    fn speed_is_compared_only_within_one_node() {
        // A merged cluster run: sdf measured on node-a, mesh on node-b (mesh's times would
        // win). No headline or matched claim may set one node's time against the other's.
        let on = |backend: &str, ms: f64, node: &str| {
            let mut r = row(backend, "q", ms, Some(45.0), 100);
            r.machine = node.into();
            r
        };
        let rows = vec![
            on("sdf", 10.0, "node-a"),
            on("mesh", 1.0, "node-b"),
            on("sdf", 12.0, "node-b"),
        ];
        let h = headlines(&rows, 40.0, Timing::medians_only());
        assert_eq!(h.len(), 2, "one setting per node");
        let a = h.iter().find(|h| h.name.contains("node-a")).unwrap();
        assert!(a.contest.is_none(), "node-a has one backend: no contest");
        let b = h.iter().find(|h| h.name.contains("node-b")).unwrap();
        let c = b.contest.as_ref().unwrap();
        assert_eq!((c.faster.as_str(), c.slower.as_str()), ("mesh", "sdf"));
        assert!(
            (c.ratio - 12.0).abs() < 1e-9,
            "node-b's own sdf row: {}",
            c.ratio
        );
    }

    #[test]
    fn a_target_is_won_only_among_rows_reaching_it() {
        let rows = [
            row("sdf", "a", 10.0, Some(52.0), 100),
            row("mesh", "b", 2.0, Some(24.0), 100),
            row("mesh", "c", 5.0, Some(39.96), 100),
        ];
        let rows: Vec<&Row> = rows.iter().collect();
        let t = Timing::medians_only();
        // 30 dB: mesh:c (39.96 prints as 40.0) against sdf; the faster mesh:b is too coarse.
        match at_target(&rows, 30.0, t) {
            TargetVerdict::Contest(c) => {
                assert_eq!((c.faster_label.as_str(), c.ratio), ("mesh:c", 2.0));
            }
            v => panic!("{v:?}"),
        }
        // 40 dB: 39.96 dB rounds to the 40.0 dB it is printed with.
        assert_eq!(at_target(&rows, 40.0, t).winner(), Some("mesh"));
        let alone = at_target(&rows, 50.0, t);
        assert_eq!(alone.winner(), Some("sdf"));
        assert_eq!(alone.short(), "sdf alone");
        assert_eq!(alone.to_string(), "only sdf reaches it (`sdf:a`)");
        assert_eq!(at_target(&rows, 60.0, t), TargetVerdict::Nobody);
        assert_eq!(at_target(&rows, 60.0, t).winner(), None);
    }

    #[test]
    fn headlines_rank_any_number_of_backends() {
        let rows = vec![
            row("sdf", "a", 10.0, Some(45.0), 100),
            row("mesh", "b", 20.0, Some(45.0), 100),
            row("voxels", "c", 4.0, Some(41.0), 100),
            row("voxels", "d", 1.0, Some(20.0), 100),
        ];
        let h = headlines(&rows, 40.0, Timing::medians_only());
        assert_eq!(h.len(), 1);
        let c = h[0].contest.as_ref().unwrap();
        assert_eq!(
            (c.faster.as_str(), c.slower.as_str(), c.ratio),
            ("voxels", "sdf", 2.5)
        );
        assert_eq!(h[0].best.len(), 3);
        let m = matched_accuracy(&rows.iter().collect::<Vec<_>>(), Timing::medians_only());
        // 20 dB: voxels:d vs sdf; 41: voxels:c vs sdf; 45: sdf vs mesh.
        let winners: Vec<(f64, &str, &str)> = m
            .iter()
            .map(|(q, c)| {
                let c = c.as_ref().unwrap();
                (*q, c.faster.as_str(), c.slower.as_str())
            })
            .collect();
        assert_eq!(
            winners,
            [
                (20.0, "voxels", "sdf"),
                (41.0, "voxels", "sdf"),
                (45.0, "sdf", "mesh")
            ]
        );
    }
}
