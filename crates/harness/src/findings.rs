//! The answer in one place: `marchmesh findings RUN... --out FILE` reads any number of runs and
//! writes one Markdown document that, for every axis a situation varies along in the data
//! (object copies, mesh size, image size, threads, accuracy target, memory budget), states who
//! is faster where, where the winner changes (the crossover, interpolated, with the interval
//! the confidence intervals allow), a plot along the axis, and the run and configuration ids
//! every claim rests on. Claims the data cannot carry (intervals including a ratio of 1, a
//! single point, rows from different machines) are stated as such.
//!
//! Axes are found from the rows alone, so the document regenerates byte-identically from the
//! same `results.json` files on any machine: within one suite group and scene, varying thread
//! counts give a threads axis and varying image sizes an image-size axis; a group whose scenes
//! carry their size in the name (`repeat_100`, `repeat_inf`) or whose triangle backends report
//! different triangle counts per scene gives a scene-size axis; quality levels within one
//! scene give the accuracy-target and memory-budget axes.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use crate::report::bytes;
use crate::results::{Results, Row};
use crate::verdicts::{Clock, HEADLINE_MIN_PSNR_DB, Timing, headlines, matched_accuracy};

/// The decision chart's file in the plots folder.
const DECISION_SVG: &str = "decision.svg";

/// One run given to `findings`: its folder name (links are `NAME/summary.md`, relative to the
/// folder holding the runs, where `FINDINGS.md` belongs) and its results.
#[derive(Debug, Clone)]
pub struct Run {
    /// The run folder's name.
    pub name: String,
    /// Its `results.json`.
    pub results: Results,
}

/// A row with the run it came from.
#[derive(Clone, Copy)]
struct Point<'a> {
    run: usize,
    row: &'a Row,
    clock: Clock,
}

impl Point<'_> {
    fn ms(&self) -> f64 {
        self.clock.median_ms(self.row)
    }
    /// The 95% CI of the median on the run's clock.
    fn ci(&self) -> (f64, f64) {
        self.clock.ci_ms(self.row)
    }
    fn label(&self) -> String {
        format!("{}:{}", self.row.backend, self.row.quality)
    }
}

/// Which of two points is faster, with the ratio's interval from the medians' CIs.
struct Duel {
    faster: String,
    slower: String,
    /// slower / faster by the medians.
    ratio: f64,
    /// Interval of slower / faster allowed by the two CIs (low may be below 1).
    range: (f64, f64),
}

impl Duel {
    fn of(a: &Point<'_>, b: &Point<'_>) -> Self {
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
    fn decisive(&self) -> bool {
        self.range.0 > 1.0
    }
    fn winner(&self) -> &str {
        if self.decisive() {
            &self.faster
        } else {
            "no clear winner"
        }
    }
    fn describe(&self) -> String {
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
    fn log_ratio(a: &Point<'_>, b: &Point<'_>) -> (f64, f64, f64) {
        let (al, ah) = a.ci();
        let (bl, bh) = b.ci();
        ((a.ms() / b.ms()).ln(), (al / bh).ln(), (ah / bl).ln())
    }
}

/// The value of a scene-size axis: finite, or the infinite repetition.
#[derive(Debug, Clone, Copy, PartialEq)]
enum AxisValue {
    Finite(f64),
    Infinite,
}

impl AxisValue {
    fn show(self) -> String {
        match self {
            Self::Finite(v) => sig(v),
            Self::Infinite => "infinite".into(),
        }
    }
}

/// `v` with about three significant digits, integers below 10^7 in full.
fn sig(v: f64) -> String {
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
fn size_in_name(scene: &str) -> Option<AxisValue> {
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
fn newest_points(runs: &[Run]) -> Vec<Point<'_>> {
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
fn distinct<T, K: PartialEq>(items: &[T], f: impl Fn(&T) -> K) -> Vec<K> {
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
struct Section {
    title: String,
    brief: String,
    body: String,
}

/// A link to the run's `summary.md`; a run that did not finish (interrupted, killed or with
/// configurations missing) has none, so it is named and marked incomplete instead.
fn link(runs: &[Run], run: usize) -> String {
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

fn run_links(runs: &[Run], points: &[Point<'_>]) -> String {
    distinct(points, |p| p.run)
        .into_iter()
        .map(|r| link(runs, r))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Rows of more than one machine cannot carry a speed claim: different CPU models, or
/// different host names where the runs recorded them (older runs did not).
fn machines_differ(runs: &[Run], points: &[Point<'_>]) -> bool {
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
fn fastest_per_backend<'a>(points: &[Point<'a>]) -> Vec<Point<'a>> {
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
fn duel(points: &[Point<'_>]) -> Option<Duel> {
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
fn crossover(x0: f64, x1: f64, r0: (f64, f64, f64), r1: (f64, f64, f64)) -> (f64, f64, f64) {
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

fn slug(s: &str) -> String {
    crate::bench::slug(s).replace(['/', ':'], "_")
}

/// One point of a scene-size axis: its value, the winner there, ln(time ratio) of the two
/// leading backends with its interval, and which two backends (`a/b`) that ratio is of.
type Step = (AxisValue, String, Option<(f64, f64, f64)>, String);

/// A scene-size axis over the scenes of one suite group.
fn scene_axis(
    runs: &[Run],
    group: &str,
    points: &[Point<'_>],
    plots: &mut Vec<Plot>,
) -> Option<Section> {
    let scenes = distinct(points, |p| p.row.scene.clone());
    if scenes.len() < 2 {
        return None;
    }
    // x from the scene names, else from the triangle counts the triangle backends report.
    let by_name: Option<Vec<AxisValue>> = scenes.iter().map(|s| size_in_name(s)).collect();
    let (axis, xs): (&str, Vec<AxisValue>) = if let Some(v) = by_name {
        ("copies (the number in the scene name)", v)
    } else {
        // One triangle configuration per scene: its triangle count is the scene's size (with
        // several, as in a quality sweep, the scenes are not a series).
        let tri: Option<Vec<AxisValue>> = scenes
            .iter()
            .map(|s| {
                let t: Vec<u64> = points
                    .iter()
                    .filter(|p| &p.row.scene == s)
                    .filter_map(|p| p.row.triangles)
                    .collect();
                match t.as_slice() {
                    [one] => Some(AxisValue::Finite(*one as f64)),
                    _ => None,
                }
            })
            .collect();
        ("triangles of the mesh", tri?)
    };
    let mut order: Vec<usize> = (0..scenes.len()).collect();
    order.sort_by(|&a, &b| match (xs[a], xs[b]) {
        (AxisValue::Finite(x), AxisValue::Finite(y)) => x.total_cmp(&y),
        (AxisValue::Finite(_), AxisValue::Infinite) => std::cmp::Ordering::Less,
        (AxisValue::Infinite, AxisValue::Finite(_)) => std::cmp::Ordering::Greater,
        _ => std::cmp::Ordering::Equal,
    });
    let labels = distinct(points, Point::label);
    let mut body = String::new();
    // Speed is compared only between configurations reaching the same accuracy target.
    let target = HEADLINE_MIN_PSNR_DB;
    let reaches = |p: &Point<'_>| {
        p.row.psnr_db.is_some_and(|q| {
            crate::verdicts::psnr_target_level(q)
                >= target - crate::verdicts::PSNR_TARGET_STEP_DB / 2.0
        })
    };
    let _ = writeln!(
        body,
        "| {axis} | {} | at >= {target:.0} dB: fastest vs runner-up among the configurations reaching it |",
        labels.join(" | ")
    );
    let _ = writeln!(body, "|---|{}---|", "---|".repeat(labels.len()));
    let mut winners: Vec<Step> = Vec::new();
    let mut series: Vec<(String, Vec<(f64, f64)>)> =
        labels.iter().map(|l| (l.clone(), Vec::new())).collect();
    for &i in &order {
        let at: Vec<Point<'_>> = points
            .iter()
            .filter(|p| p.row.scene == scenes[i])
            .copied()
            .collect();
        let cells: Vec<String> = labels
            .iter()
            .map(|l| {
                at.iter()
                    .find(|p| &p.label() == l)
                    .map_or("n/a".into(), |p| {
                        format!(
                            "{:.1} ms, {} dB, {}",
                            p.ms(),
                            p.row.psnr_db.map_or("n/a".into(), |q| format!("{q:.1}")),
                            bytes(p.row.memory_bytes)
                        )
                    })
            })
            .collect();
        if let AxisValue::Finite(x) = xs[i] {
            for (s, l) in series.iter_mut().zip(&labels) {
                if let Some(p) = at.iter().find(|p| &p.label() == l) {
                    s.1.push((x, p.ms()));
                }
            }
        }
        let matched: Vec<Point<'_>> = at.iter().filter(|p| reaches(p)).copied().collect();
        // Speed is compared only within one machine.
        let d = if machines_differ(runs, points) {
            None
        } else {
            duel(&matched)
        };
        let best = fastest_per_backend(&matched);
        let alone = match best.as_slice() {
            [one] => Some(format!("{} alone reaches {target:.0} dB", one.row.backend)),
            [] => Some(format!("none reaches {target:.0} dB")),
            _ => None,
        };
        let others_best: Vec<String> = distinct(&at, |p| p.row.backend.clone())
            .into_iter()
            .filter(|b| !best.iter().any(|p| &p.row.backend == b))
            .map(|b| {
                let top = at
                    .iter()
                    .filter(|p| p.row.backend == b)
                    .filter_map(|p| p.row.psnr_db)
                    .fold(f64::NEG_INFINITY, f64::max);
                if top.is_finite() {
                    format!("{b} at most {top:.1} dB")
                } else {
                    format!("{b} without accuracy")
                }
            })
            .collect();
        let log_ratio = match best.as_slice() {
            [a, b, ..] => Some(Duel::log_ratio(a, b)),
            _ => None,
        };
        let pair = best
            .iter()
            .take(2)
            .map(|p| p.row.backend.clone())
            .collect::<Vec<_>>()
            .join("/");
        let verdict = match (&d, &alone) {
            (Some(d), _) => d.describe(),
            (None, Some(a)) if !others_best.is_empty() => {
                format!("{a} ({})", others_best.join(", "))
            }
            (None, Some(a)) => a.clone(),
            (None, None) => "n/a".into(),
        };
        let _ = writeln!(
            body,
            "| {} | {} | {verdict} |",
            xs[i].show(),
            cells.join(" | "),
        );
        winners.push((
            xs[i],
            match (&d, alone) {
                (Some(d), _) => d.winner().to_string(),
                (None, Some(a)) => a,
                (None, None) => "n/a".into(),
            },
            log_ratio,
            pair,
        ));
    }
    let _ = writeln!(body);
    let mut crossings = Vec::new();
    for w in winners.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if a.1 == b.1 || a.3 != b.3 {
            continue;
        }
        match (a.0, b.0, a.2, b.2) {
            (AxisValue::Finite(x0), AxisValue::Finite(x1), Some(r0), Some(r1)) => {
                let (mid, lo, hi) = crossover(x0, x1, r0, r1);
                crossings.push(format!(
                    "from {} to {} between {} and {} {axis} (interpolated {}, interval {}-{} from the CIs)",
                    a.1,
                    b.1,
                    a.0.show(),
                    b.0.show(),
                    sig(mid),
                    sig(lo),
                    sig(hi),
                ));
            }
            _ => crossings.push(format!(
                "from {} to {} between {} and {} {axis}",
                a.1,
                b.1,
                a.0.show(),
                b.0.show()
            )),
        }
    }
    // Runs of the same verdict along the axis, in order.
    let mut stretches: Vec<(String, AxisValue, AxisValue)> = Vec::new();
    for w in &winners {
        match stretches.last_mut() {
            Some(last) if last.0 == w.1 => last.2 = w.0,
            _ => stretches.push((w.1.clone(), w.0, w.0)),
        }
    }
    let said: Vec<String> = stretches
        .iter()
        .map(|(w, from, to)| {
            if from == to {
                format!("{w} at {}", from.show())
            } else {
                format!("{w} from {} to {}", from.show(), to.show())
            }
        })
        .collect();
    let brief = if machines_differ(runs, points) {
        format!("{group}: rows from different machines; no speed claim along {axis}.")
    } else if stretches.len() == 1 {
        format!(
            "{group}: at >= {target:.0} dB, {} at every measured {axis} ({} to {}; each backend's fastest configuration reaching {target:.0} dB, PSNR in the table).",
            stretches[0].0,
            stretches[0].1.show(),
            stretches[0].2.show()
        )
    } else if crossings.is_empty() {
        format!(
            "{group}: at >= {target:.0} dB, {} {axis} (each backend's fastest configuration reaching {target:.0} dB, PSNR in the table).",
            said.join("; ")
        )
    } else {
        format!(
            "{group}: at >= {target:.0} dB, {} {axis}; the winner changes {} (each backend's fastest configuration reaching {target:.0} dB, PSNR in the table).",
            said.join("; "),
            crossings.join("; ")
        )
    };
    let _ = writeln!(body, "{brief}\n");
    let name = format!("{}.svg", slug(group));
    plots.push(Plot {
        file: name.clone(),
        title: format!("{group}: render time along {axis}"),
        x: axis.to_string(),
        series,
        log_x: true,
        ideal: None,
    });
    let _ = writeln!(body, "![{group}](PLOTS/{name})\n");
    Some(Section {
        title: format!("{group}: scene size ({})", run_links(runs, points)),
        brief,
        body,
    })
}

/// Image size (pixels) or thread count along one scene.
fn setting_axis(
    runs: &[Run],
    group: &str,
    scene: &str,
    points: &[Point<'_>],
    threads: bool,
    plots: &mut Vec<Plot>,
) -> Option<Section> {
    let key = |p: &Point<'_>| {
        if threads {
            p.row.threads as f64
        } else {
            f64::from(p.row.width) * f64::from(p.row.height)
        }
    };
    let mut xs = distinct(points, |p| key(p).to_bits());
    if xs.len() < 2 {
        return None;
    }
    xs.sort_by(|a, b| f64::from_bits(*a).total_cmp(&f64::from_bits(*b)));
    let axis = if threads { "threads" } else { "pixels" };
    let labels = distinct(points, Point::label);
    let mut body = String::new();
    let _ = writeln!(body, "| {axis} | {} | winner |", labels.join(" | "));
    let _ = writeln!(body, "|---|{}---|", "---|".repeat(labels.len()));
    let mut series: Vec<(String, Vec<(f64, f64)>)> =
        labels.iter().map(|l| (l.clone(), Vec::new())).collect();
    let mut winners = Vec::new();
    let base: BTreeMap<String, f64> = labels
        .iter()
        .filter_map(|l| {
            points
                .iter()
                .filter(|p| &p.label() == l && key(p).to_bits() == xs[0])
                .map(|p| (l.clone(), p.ms()))
                .next()
        })
        .collect();
    for &xb in &xs {
        let x = f64::from_bits(xb);
        let at: Vec<Point<'_>> = points
            .iter()
            .filter(|p| key(p).to_bits() == xb)
            .copied()
            .collect();
        let cells: Vec<String> = labels
            .iter()
            .map(|l| {
                at.iter()
                    .find(|p| &p.label() == l)
                    .map_or("n/a".into(), |p| {
                        if threads {
                            let speedup = base.get(l).map_or(f64::NAN, |b| b / p.ms());
                            format!(
                                "{:.1} ms, speedup {speedup:.2}x (ideal {:.0}x)",
                                p.ms(),
                                x / f64::from_bits(xs[0])
                            )
                        } else {
                            format!("{:.1} ms ({}x{})", p.ms(), p.row.width, p.row.height)
                        }
                    })
            })
            .collect();
        for (s, l) in series.iter_mut().zip(&labels) {
            if let Some(p) = at.iter().find(|p| &p.label() == l) {
                let y = if threads {
                    base.get(l).map_or(f64::NAN, |b| b / p.ms())
                } else {
                    p.ms()
                };
                s.1.push((x, y));
            }
        }
        // Speed is compared only within one machine.
        let d = if machines_differ(runs, points) {
            None
        } else {
            duel(&at)
        };
        let _ = writeln!(
            body,
            "| {x} | {} | {} |",
            cells.join(" | "),
            d.as_ref().map_or("n/a".into(), Duel::describe)
        );
        winners.push((x, d.map(|d| d.winner().to_string()).unwrap_or_default()));
    }
    let _ = writeln!(body);
    let changes: Vec<String> = winners
        .windows(2)
        .filter(|w| w[0].1 != w[1].1)
        .map(|w| {
            format!(
                "from {} to {} between {} and {} {axis}",
                w[0].1,
                w[1].1,
                sig(w[0].0),
                sig(w[1].0)
            )
        })
        .collect();
    let brief = if machines_differ(runs, points) {
        format!("{group}/{scene}: rows from different machines; no speed claim along {axis}.")
    } else if changes.is_empty() {
        format!(
            "{group}/{scene}: {} at every measured {axis} ({} to {}).",
            winners.first().map_or("", |w| w.1.as_str()),
            winners.first().map_or(0.0, |w| w.0),
            winners.last().map_or(0.0, |w| w.0)
        )
    } else {
        format!(
            "{group}/{scene}: the winner changes {}.",
            changes.join("; ")
        )
    };
    let _ = writeln!(body, "{brief}\n");
    let name = format!("{}_{}_{axis}.svg", slug(group), slug(scene));
    plots.push(Plot {
        file: name.clone(),
        title: if threads {
            format!(
                "{group}/{scene}: speedup over {} thread(s)",
                f64::from_bits(xs[0])
            )
        } else {
            format!("{group}/{scene}: render time along image size")
        },
        x: axis.to_string(),
        series,
        log_x: !threads,
        ideal: threads.then_some(f64::from_bits(xs[0])),
    });
    let _ = writeln!(body, "![{group}/{scene}](PLOTS/{name})\n");
    Some(Section {
        title: format!(
            "{group}/{scene}: {} ({})",
            if threads { "threads" } else { "image size" },
            run_links(runs, points)
        ),
        brief,
        body,
    })
}

/// Accuracy target and memory budget along the quality levels of one scene and setting.
fn quality_axes(
    runs: &[Run],
    group: &str,
    scene: &str,
    points: &[Point<'_>],
    plots: &mut Vec<Plot>,
) -> Option<Section> {
    if distinct(points, |p| p.row.backend.clone()).len() < 2
        || points.iter().all(|p| p.row.psnr_db.is_none())
    {
        return None;
    }
    let rows: Vec<&Row> = points.iter().map(|p| p.row).collect();
    let clock = points[0].clock;
    let run = &runs[points[0].run].results;
    let timing = Timing::of(run);
    // Speed is compared only within one machine: rows of several make no claim at all.
    let claims = if machines_differ(runs, points) {
        Vec::new()
    } else {
        matched_accuracy(&rows, timing)
    };
    let mut body = String::new();
    if !claims.is_empty() {
        let _ = writeln!(
            body,
            "| PSNR target (dB) | fastest backend reaching it vs runner-up ({} time) |\n|---|---|",
            clock.name()
        );
    }
    let mut runs_of_winner: Vec<(String, f64, f64)> = Vec::new();
    for (q, c) in &claims {
        let (w, text) = match c {
            Ok(c) if c.decisive => (c.faster.clone(), format!("{c} (`{}`)", c.faster_label)),
            Ok(c) => ("no clear winner".to_string(), c.to_string()),
            Err(only) => (format!("{only} alone"), format!("only {only} reaches it")),
        };
        let _ = writeln!(body, "| {q:.1} | {text} |");
        match runs_of_winner.last_mut() {
            Some(last) if last.0 == w => last.2 = *q,
            _ => runs_of_winner.push((w, *q, *q)),
        }
    }
    let _ = writeln!(body);
    let last = runs_of_winner.len().saturating_sub(1);
    let ranges: Vec<String> = runs_of_winner
        .iter()
        .enumerate()
        .map(|(i, (w, a, b))| {
            // A backend alone at the top reaches every target from `a` up: no other row
            // of the setting reaches any of them (targets are per 0.1 dB, see
            // `verdicts::PSNR_TARGET_STEP_DB`).
            if i == last && w.ends_with(" alone") {
                format!("{w} reaches {a:.1} dB and above")
            } else if a == b {
                format!("{w} at {a:.1} dB")
            } else {
                format!("{w} from {a:.1} to {b:.1} dB")
            }
        })
        .collect();
    let crossings: Vec<String> = runs_of_winner
        .windows(2)
        .map(|w| {
            format!(
                "between {:.1} and {:.1} dB ({} -> {})",
                w[0].2, w[1].1, w[0].0, w[1].0
            )
        })
        .collect();
    // Memory budget: the least memory with which each backend reaches the headline PSNR.
    let min_psnr = HEADLINE_MIN_PSNR_DB;
    let backends = distinct(points, |p| p.row.backend.clone());
    let least: Vec<(String, Option<&Point<'_>>)> = backends
        .iter()
        .map(|b| {
            (
                b.clone(),
                points
                    .iter()
                    .filter(|p| &p.row.backend == b && p.row.psnr_db.is_some_and(|q| q >= min_psnr))
                    .min_by_key(|p| p.row.memory_bytes),
            )
        })
        .collect();
    let mem: Vec<String> = least
        .iter()
        .map(|(b, p)| {
            p.map_or(format!("{b} never reaches {min_psnr:.0} dB"), |p| {
                format!(
                    "{b} needs {} (`{}`)",
                    bytes(p.row.memory_bytes),
                    p.row.config_id
                )
            })
        })
        .collect();
    let _ = writeln!(
        body,
        "Memory budget for {min_psnr:.0} dB: {}.\n",
        mem.join("; ")
    );
    let brief = if machines_differ(runs, points) {
        format!("{group}/{scene}: rows from different machines; no speed claim.")
    } else {
        format!(
            "{group}/{scene}: at matched accuracy {}{}.",
            ranges.join(", "),
            if crossings.is_empty() {
                String::new()
            } else {
                format!("; the winner changes {}", crossings.join(", "))
            }
        )
    };
    let _ = writeln!(body, "{brief}\n");
    // Plot: time against PSNR per backend (each backend's fastest time reaching a target).
    let series: Vec<(String, Vec<(f64, f64)>)> = backends
        .iter()
        .map(|b| {
            let mut pts: Vec<(f64, f64)> = points
                .iter()
                .filter(|p| &p.row.backend == b)
                .filter_map(|p| p.row.psnr_db.map(|q| (q.min(100.0), p.ms())))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            (b.clone(), pts)
        })
        .collect();
    let name = format!("{}_{}_accuracy.svg", slug(group), slug(scene));
    plots.push(Plot {
        file: name.clone(),
        title: format!("{group}/{scene}: render time against PSNR"),
        x: "PSNR (dB)".into(),
        series,
        log_x: false,
        ideal: None,
    });
    let _ = writeln!(body, "![{group}/{scene}](PLOTS/{name})\n");
    Some(Section {
        title: format!(
            "{group}/{scene}: accuracy target and memory ({})",
            run_links(runs, points)
        ),
        brief,
        body,
    })
}

/// A plot to draw.
struct Plot {
    file: String,
    title: String,
    x: String,
    series: Vec<(String, Vec<(f64, f64)>)>,
    log_x: bool,
    /// Thread-axis speedup plots: the ideal line y = x / base.
    ideal: Option<f64>,
}

/// The findings document for `runs` and the number of plots written into `plots_dir` (linked
/// as `plots_link/NAME.svg`; created, or reused only if it is a real folder, never a symbolic
/// link). Its anchor section lists the anchors the runs recorded, then `more_anchors`.
/// Deterministic: the same inputs give the same bytes.
///
/// Errors: `plots_dir` is a symbolic link, file or special file, or a plot cannot be written.
pub fn write_findings(
    runs: &[Run],
    more_anchors: &[crate::anchors::Anchor],
    plots_dir: &Path,
    plots_link: &str,
) -> Result<(String, usize), String> {
    let points = newest_points(runs);
    let mut plots = Vec::new();
    let mut sections = Vec::new();
    let groups = distinct(&points, |p| {
        (runs[p.run].results.suite.clone(), p.row.group.clone())
    });
    for (suite, group) in &groups {
        let in_group: Vec<Point<'_>> = points
            .iter()
            .filter(|p| &runs[p.run].results.suite == suite && &p.row.group == group)
            .copied()
            .collect();
        let name = format!("{suite}/{group}");
        let scenes = distinct(&in_group, |p| p.row.scene.clone());
        let one_setting_per_scene = scenes.iter().all(|s| {
            let at: Vec<&Point<'_>> = in_group.iter().filter(|p| &p.row.scene == s).collect();
            distinct(&at, |p| (p.row.threads, p.row.width, p.row.height)).len() == 1
        });
        if scenes.len() > 1
            && one_setting_per_scene
            && let Some(s) = scene_axis(runs, &name, &in_group, &mut plots)
        {
            sections.push(s);
            continue;
        }
        for scene in &scenes {
            let at: Vec<Point<'_>> = in_group
                .iter()
                .filter(|p| &p.row.scene == scene)
                .copied()
                .collect();
            if let Some(s) = setting_axis(runs, &name, scene, &at, true, &mut plots) {
                sections.push(s);
            } else if let Some(s) = setting_axis(runs, &name, scene, &at, false, &mut plots) {
                sections.push(s);
            } else if let Some(s) = quality_axes(runs, &name, scene, &at, &mut plots) {
                sections.push(s);
            }
        }
    }
    marchmesh_safeio::own_folder(plots_dir).map_err(|e| e.to_string())?;
    // The folder belongs to this document: plots of an earlier version that this one no
    // longer draws are removed (only `.svg` files; anything else is left alone).
    if let Ok(entries) = std::fs::read_dir(plots_dir) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let stale = name.ends_with(".svg")
                && name != DECISION_SVG
                && !plots.iter().any(|p| p.file == name);
            if stale && e.file_type().is_ok_and(|t| t.is_file()) {
                std::fs::remove_file(e.path())
                    .map_err(|err| format!("{}: {err}", e.path().display()))?;
            }
        }
    }
    for p in &plots {
        let path = plots_dir.join(&p.file);
        let mut series = p.series.clone();
        if let Some(base) = p.ideal {
            let xs: Vec<f64> = series
                .iter()
                .flat_map(|s| s.1.iter().map(|q| q.0))
                .collect();
            let mut ideal: Vec<(f64, f64)> = xs.iter().map(|&x| (x, x / base)).collect();
            ideal.sort_by(|a, b| a.0.total_cmp(&b.0));
            ideal.dedup();
            series.push(("ideal".into(), ideal));
        }
        crate::report::line_plot(
            &path,
            &p.title,
            &p.x,
            if p.ideal.is_some() {
                "speedup"
            } else {
                "render time (ms)"
            },
            &series,
            p.log_x,
        )?;
    }
    // The answer first: per scene setting and accuracy target, the winner among the
    // configurations reaching it (each run's rows on its own clock).
    let used_runs = distinct(&points, |p| p.run);
    let per_run: Vec<(usize, Vec<&Row>)> = used_runs
        .iter()
        .map(|&i| {
            (
                i,
                points
                    .iter()
                    .filter(|p| p.run == i)
                    .map(|p| p.row)
                    .collect(),
            )
        })
        .collect();
    let chart =
        crate::decision::DecisionChart::of_settings(per_run.iter().flat_map(|(i, rows)| {
            let timing = Timing::of(&runs[*i].results);
            let machines: std::collections::BTreeSet<&str> =
                rows.iter().map(|r| r.machine.as_str()).collect();
            crate::verdicts::by_setting(rows.iter().copied())
                .into_iter()
                .map(move |(k, set)| {
                    (
                        crate::verdicts::setting_name(&k, machines.len() > 1),
                        set,
                        timing,
                    )
                })
        }));
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Findings: when is sphere tracing a distance field faster than ray tracing triangles in a BVH?\n"
    );
    if !chart.is_empty() {
        marchmesh_safeio::replace_regular(&plots_dir.join(DECISION_SVG), chart.svg().as_bytes())
            .map_err(|e| e.to_string())?;
        let _ = writeln!(
            s,
            "## Answer\n\n![decision chart]({plots_link}/{DECISION_SVG})\n\nPer scene setting and accuracy target (PSNR against the exact reference), the fastest backend among the configurations reaching the target, with the runner-up's time over the winner's and its 95% confidence interval (*medians*: a ratio of medians, the two not timed together). *No clear winner*: the interval includes 1; *alone*: no other backend reaches the target. The sections below give every axis with its numbers; the method follows this table.\n\n{}",
            chart.markdown()
        );
        let _ = writeln!(s, "## Method and runs\n");
    }
    let _ = writeln!(
        s,
        "Generated by `marchmesh findings` from the runs below; regenerate with `marchmesh findings {}{} --out FINDINGS.md` in this folder. Each section is one axis a situation varies along; its first sentence is the claim, the table the numbers (render times are medians on each run's verdict clock, wall or CPU, see its summary), the plot the picture. A winner is named only when the ratio's range from the two medians' 95% confidence intervals stays above 1; otherwise the section says *no clear winner*. Where the same configuration was measured by several runs, the newest run counts. Links go to each run's summary, where every configuration id below has its full row.\n",
        runs.iter()
            .map(|r| r.name.as_str())
            .collect::<Vec<_>>()
            .join(" "),
        more_anchors
            .iter()
            .map(|a| format!(" --anchor {}", a.file))
            .collect::<String>()
    );
    let _ = writeln!(
        s,
        "| run | suite | commit | date (UTC) | CPU, cores | load average | clock |\n|---|---|---|---|---|---|---|"
    );
    let used = distinct(&points, |p| p.run);
    for (i, r) in runs.iter().enumerate() {
        let p = &r.results.provenance;
        let _ = writeln!(
            s,
            "| {}{} | {} | {}{} | {} | {}, {} | {} | {} |",
            link(runs, i),
            if used.contains(&i) {
                ""
            } else {
                " (superseded)"
            },
            r.results.suite,
            &p.git_commit[..p.git_commit.len().min(8)],
            if p.git_dirty { "+dirty" } else { "" },
            p.date_utc,
            p.cpu_model,
            p.logical_cores,
            match (p.load_average_1m, p.load_average_1m_end) {
                (Some(a), Some(b)) => format!("{a:.2} -> {b:.2}"),
                (Some(a), None) => format!("{a:.2}"),
                _ => "n/a".into(),
            },
            Clock::for_run(&r.results).name()
        );
    }
    // How far each backend is from its field's best, as the runs recorded it.
    let mut anchors: Vec<crate::anchors::Anchor> = Vec::new();
    for a in runs
        .iter()
        .flat_map(|r| &r.results.anchors)
        .chain(more_anchors)
    {
        if !anchors.contains(a) {
            anchors.push(a.clone());
        }
    }
    if !anchors.is_empty() {
        let _ = write!(s, "\n{}", crate::anchors::anchors_markdown(&anchors));
    }
    // Categorical axes (scene kind: primitives vs CSG and smooth blends; workload: camera and
    // shadow rays vs soft shadows, ambient occlusion, path tracing): each scene's headline.
    let mut heads = String::new();
    for &i in &used {
        let rows: Vec<Row> = points
            .iter()
            .filter(|p| p.run == i)
            .map(|p| p.row.clone())
            .collect();
        for h in headlines(&rows, HEADLINE_MIN_PSNR_DB, Timing::of(&runs[i].results)) {
            let winner = h.contest.as_ref().map_or_else(
                || {
                    let reaching: Vec<&str> = h
                        .best
                        .iter()
                        .filter(|b| b.1.is_some())
                        .map(|b| b.0.as_str())
                        .collect();
                    match reaching.as_slice() {
                        [] => "none reaches it".to_string(),
                        [one] => format!("only {one} reaches it"),
                        _ => "n/a".to_string(),
                    }
                },
                ToString::to_string,
            );
            let _ = writeln!(
                heads,
                "| {} | {} | {} | {} |",
                h.name,
                h.best
                    .iter()
                    .map(|(b, d)| d.clone().unwrap_or_else(|| format!("{b}: none")))
                    .collect::<Vec<_>>()
                    .join("; "),
                winner,
                link(runs, i)
            );
        }
    }
    if !heads.is_empty() {
        sections.push(Section {
            title: format!(
                "Scene kind and workload: each scene at >= {HEADLINE_MIN_PSNR_DB:.0} dB"
            ),
            brief: format!(
                "Scene kind and workload (primitives, CSG and blends, repetition, meshes; camera and hard-shadow rays, soft shadows, ambient occlusion, path tracing): the headline of every scene at >= {HEADLINE_MIN_PSNR_DB:.0} dB is tabled below."
            ),
            body: format!(
                "Each backend's fastest configuration reaching {HEADLINE_MIN_PSNR_DB:.0} dB per scene and setting, on each run's clock, with the paired or median-ratio contest of the two fastest backends. The default suite's `csg` scene holds the CSG operations and smooth blends, `primitives` the plain shapes; the lighting suite's groups are the workloads (ray types).\n\n| setting | fastest per backend | contest | run |\n|---|---|---|---|\n{heads}\n"
            ),
        });
    }
    let _ = writeln!(s, "\n## In brief\n");
    for sec in &sections {
        let _ = writeln!(s, "- {}", sec.brief);
    }
    let _ = writeln!(s);
    for sec in &sections {
        let _ = writeln!(s, "## {}\n", sec.title);
        s.push_str(&sec.body.replace("PLOTS/", &format!("{plots_link}/")));
    }
    Ok((s, plots.len() + usize::from(!chart.is_empty())))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::results::tests_support::{results, row};

    fn at(scene: &str, backend: &str, ms: f64, tri: Option<u64>) -> Row {
        let mut r = row(backend, "q", ms, Some(45.0), 100);
        r.scene = scene.into();
        r.group = "repeat".into();
        r.config_id = format!("repeat/{scene}/{backend}:q/x1/t2");
        r.triangles = tri;
        r
    }

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

    #[test]
    fn a_scene_axis_finds_the_crossover_and_says_so() {
        let rows = vec![
            at("repeat_1", "sdf", 30.0, None),
            at("repeat_1", "mesh", 10.0, Some(100)),
            at("repeat_100", "sdf", 30.0, None),
            at("repeat_100", "mesh", 20.0, Some(100)),
            at("repeat_10000", "sdf", 30.0, None),
            at("repeat_10000", "mesh", 90.0, Some(100)),
            at("repeat_inf", "sdf", 30.0, None),
            at("repeat_inf", "mesh", 200.0, Some(100)),
        ];
        let runs = vec![Run {
            name: "run1".into(),
            results: results(rows),
        }];
        let dir = std::env::temp_dir().join(format!("marchmesh-findings-{}", std::process::id()));
        let doc = write_findings(&runs, &[], &dir, "plots").unwrap().0;
        assert!(
            doc.contains("from mesh to sdf between 100 and 10000 copies (the number in the scene name) (interpolated 346,"),
            "{doc}"
        );
        assert!(doc.contains("[run1](run1/summary.md)"), "{doc}");
        assert!(doc.contains("| infinite |"), "{doc}");
        assert!(dir.join("suite_repeat.svg").is_file());
        // A plot the document no longer draws is removed; other files stay.
        std::fs::write(dir.join("old_axis.svg"), "<svg/>").unwrap();
        std::fs::write(dir.join("notes.txt"), "mine").unwrap();
        // Same input, same bytes.
        assert_eq!(write_findings(&runs, &[], &dir, "plots").unwrap().0, doc);
        assert!(!dir.join("old_axis.svg").exists());
        assert!(dir.join("notes.txt").is_file());
        std::fs::remove_dir_all(&dir).ok();
    }

    /// One quality level of one backend on a scene `q` (quality axis only).
    fn level(backend: &str, quality: &str, ms: f64, psnr: f64) -> Row {
        let mut r = row(backend, quality, ms, Some(psnr), 100);
        r.scene = "box".into();
        r.group = "quality".into();
        r.config_id = format!("quality/box/{backend}:{quality}/x1/t2");
        r
    }

    fn findings_of(rows: Vec<Row>, name: &str) -> String {
        let runs = vec![Run {
            name: "run1".into(),
            results: results(rows),
        }];
        let dir =
            std::env::temp_dir().join(format!("marchmesh-findings-{name}-{}", std::process::id()));
        let doc = write_findings(&runs, &[], &dir, "plots").unwrap().0;
        std::fs::remove_dir_all(&dir).ok();
        doc
    }

    #[test]
    fn targets_that_print_alike_are_one_row() {
        // mesh tops out at 48.17 dB, sdf at 48.24 dB: both print as 48.2, so at 48.2 dB both
        // reach the target and mesh (faster) wins; nobody is "alone" there.
        let doc = findings_of(
            vec![
                level("mesh", "lo", 1.0, 28.4),
                level("mesh", "hi", 2.0, 48.17),
                level("sdf", "lo", 9.0, 30.0),
                level("sdf", "hi", 10.0, 48.24),
            ],
            "tie",
        );
        let rows_at = |t: &str| doc.lines().filter(|l| l.starts_with(t)).count();
        assert_eq!(rows_at("| 48.2 |"), 1, "{doc}");
        assert!(!doc.contains("only sdf reaches it"), "{doc}");
        assert!(!doc.contains("between 48.2 and 48.2"), "{doc}");
        assert!(doc.contains("mesh from 28.4 to 48.2 dB."), "{doc}");
    }

    #[test]
    fn a_backend_alone_is_checked_against_every_row() {
        // sdf alone reaches 48.3 dB: no mesh row prints at 48.3 or above.
        let rows = vec![
            level("mesh", "lo", 1.0, 28.4),
            level("mesh", "hi", 2.0, 48.24),
            level("sdf", "lo", 9.0, 30.0),
            level("sdf", "hi", 10.0, 48.26),
        ];
        let doc = findings_of(rows.clone(), "alone");
        assert!(
            doc.contains("mesh from 28.4 to 48.2 dB, sdf alone reaches 48.3 dB and above; the winner changes between 48.2 and 48.3 dB (mesh -> sdf alone)."),
            "{doc}"
        );
        for line in doc.lines().filter(|l| l.contains("only sdf reaches it")) {
            let target: f64 = line.split('|').nth(1).unwrap().trim().parse().unwrap();
            for r in rows.iter().filter(|r| r.backend != "sdf") {
                let printed: f64 = format!("{:.1}", r.psnr_db.unwrap()).parse().unwrap();
                assert!(
                    printed < target,
                    "{line} but {} prints {printed}",
                    r.config_id
                );
            }
        }
    }

    #[test]
    fn rows_from_two_nodes_make_no_speed_claim() {
        let mut rows = vec![
            level("mesh", "lo", 1.0, 30.0),
            level("sdf", "lo", 9.0, 30.0),
        ];
        rows[0].machine = "node-a".into();
        rows[1].machine = "node-b".into();
        let doc = findings_of(rows, "nodes");
        assert!(
            doc.contains("quality/box: rows from different machines; no speed claim."),
            "{doc}"
        );
        assert!(!doc.contains("x faster than"), "{doc}");
    }

    #[test]
    fn overlapping_intervals_are_no_winner() {
        let mut a = at("s_1", "sdf", 10.0, None);
        (a.render_ms_ci_low, a.render_ms_ci_high) = (8.0, 12.0);
        let mut b = at("s_1", "mesh", 11.0, Some(1));
        (b.render_ms_ci_low, b.render_ms_ci_high) = (9.0, 13.0);
        let pa = Point {
            run: 0,
            row: &a,
            clock: Clock::Wall,
        };
        let pb = Point {
            run: 0,
            row: &b,
            clock: Clock::Wall,
        };
        let d = Duel::of(&pa, &pb);
        assert!(!d.decisive());
        assert!(
            d.describe().starts_with("no clear winner"),
            "{}",
            d.describe()
        );
    }
}
