//! `summary.md`, `plots/*.svg` and `report.html` from [`Results`]; `marchmesh report`
//! regenerates them from `results.json` alone, so the tables only depend on what the JSON
//! holds.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use plotters::prelude::*;

use crate::backend::BackendKind;
use crate::results::{Results, Row};
use crate::verdicts::{
    Clock, HEADLINE_MIN_PSNR_DB, Timing, backends, headlines, matched_accuracy, setting, settings,
};

/// A column of the summary table: its header and the cell text of a row.
pub type SummaryColumn = (&'static str, fn(&Row) -> String);

/// The per-configuration table of the summary: each column once, its header beside the
/// value it shows, so the two cannot drift apart.
pub const SUMMARY_COLUMNS: &[SummaryColumn] = &[
    ("backend", |r| r.backend.clone()),
    ("quality", |r| r.quality.clone()),
    ("size", |r| format!("{}x{}", r.width, r.height)),
    ("threads", |r| r.threads.to_string()),
    ("build ms", |r| format!("{:.2}", r.build_ms_total)),
    ("render ms median [95% CI]", |r| {
        format!(
            "{:.2} [{:.2}, {:.2}]",
            r.render_ms_median, r.render_ms_ci_low, r.render_ms_ci_high
        )
    }),
    ("CPU ms median [95% CI]", |r| {
        match (
            r.render_cpu_ms_median,
            r.render_cpu_ms_ci_low,
            r.render_cpu_ms_ci_high,
        ) {
            (Some(m), Some(lo), Some(hi)) => format!("{m:.2} [{lo:.2}, {hi:.2}]"),
            _ => "n/a".into(),
        }
    }),
    ("Mrays/s", |r| format!("{:.2}", r.mrays_per_s)),
    ("Mrays/CPU-s", |r| opt(r.mrays_per_cpu_s, 2)),
    ("memory", |r| bytes(r.memory_bytes)),
    ("heap build", |r| opt_bytes(r.peak_heap_bytes_build)),
    ("heap render", |r| opt_bytes(r.peak_heap_bytes_render)),
    ("silhouette %", |r| opt(r.silhouette_mismatch_pct, 3)),
    ("depth p95 / scene", |r| opt(r.depth_err_p95_rel_scene, 5)),
    ("normal mean deg", |r| opt(r.normal_err_deg_mean, 2)),
    ("depth rel max", |r| opt(r.depth_err_rel_max, 4)),
    ("tail px depth / normal", tail_px),
    ("PSNR dB", |r| opt(r.psnr_db, 1)),
    ("SSIM", |r| opt(r.ssim, 4)),
    ("steps mean", |r| format!("{:.1}", r.steps_mean)),
    ("exhausted %", |r| format!("{:.3}", r.step_exhaustion_pct)),
    ("nodes/ray", |r| format!("{:.1}", r.node_visits_per_ray)),
];

/// Bytes with a binary unit (B, KiB, MiB, GiB), 3 significant digits.
pub fn bytes(b: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < units.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} B")
    } else if v >= 100.0 {
        format!("{v:.0} {}", units[u])
    } else if v >= 10.0 {
        format!("{v:.1} {}", units[u])
    } else {
        format!("{v:.2} {}", units[u])
    }
}

/// `depth / normal` tail pixel counts of a row, `n/a` without a reference.
fn tail_px(r: &Row) -> String {
    match (r.depth_err_rel_tail_px, r.normal_err_deg_tail_px) {
        (Some(d), Some(n)) => format!("{d} / {n}"),
        _ => "n/a".into(),
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("n/a".into(), |x| {
        if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e6) {
            format!("{x:.2e}")
        } else {
            format!("{x:.digits$}")
        }
    })
}

fn opt_bytes(v: Option<u64>) -> String {
    v.map_or("n/a".into(), bytes)
}

/// The rows of one setting on the Pareto front of median render time (lower better) against
/// PSNR (higher better): no other row is at least as fast and at least as accurate while
/// strictly better in one. Sorted by time. Rows without PSNR are left out.
pub fn pareto_front(rows: &[&Row]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..rows.len())
        .filter(|&i| rows[i].psnr_db.is_some())
        .collect();
    idx.sort_by(|&a, &b| {
        rows[a]
            .render_ms_median
            .total_cmp(&rows[b].render_ms_median)
            .then(
                rows[b]
                    .psnr_db
                    .unwrap_or(0.0)
                    .total_cmp(&rows[a].psnr_db.unwrap_or(0.0)),
            )
    });
    let mut front = Vec::new();
    let mut best = f64::NEG_INFINITY;
    for i in idx {
        let p = rows[i].psnr_db.unwrap_or(f64::NEG_INFINITY);
        if p > best {
            front.push(i);
            best = p;
        }
    }
    front
}

fn label(r: &Row) -> String {
    format!("{}:{}", r.backend, r.quality)
}

/// Plain-language verdict of one setting, each claim with its numbers; times on `timing`'s
/// clock, speed ratios from [`Timing::contest`].
pub fn verdict(rows: &[&Row], timing: Timing<'_>) -> Vec<String> {
    let mut out = Vec::new();
    let clock = timing.clock;
    let names = backends(rows.iter().copied());
    let of = |b: &str| {
        rows.iter()
            .copied()
            .filter(|r| r.backend == b)
            .collect::<Vec<_>>()
    };
    let fastest = rows
        .iter()
        .min_by(|a, b| clock.median_ms(a).total_cmp(&clock.median_ms(b)));
    if let Some(f) = fastest {
        out.push(format!(
            "Fastest configuration: {} at {:.2} ms {} time ({:.2} Mrays/s, PSNR {} dB).",
            label(f),
            clock.median_ms(f),
            clock.name(),
            f.mrays_per_s,
            opt(f.psnr_db, 1)
        ));
    }
    if names.len() >= 2 {
        // Speed at matched accuracy: for each PSNR target reached by some row, which backend
        // reaches it fastest; runs of the same winner are merged into ranges.
        let mut runs: Vec<(String, f64, f64, Option<String>)> = Vec::new(); // winner, from, to, contest at `to`
        for (q, contest) in matched_accuracy(rows, timing) {
            let (winner, said) = match contest {
                Ok(c) if c.decisive => (c.faster.clone(), Some(c.to_string())),
                Ok(c) => ("no clear winner".to_string(), Some(c.to_string())),
                Err(only) => (format!("{only} (only {only} reaches it)"), None),
            };
            match runs.last_mut() {
                Some(last) if last.0 == winner => {
                    last.2 = q;
                    last.3 = said;
                }
                _ => runs.push((winner, q, q, said)),
            }
        }
        if !runs.is_empty() {
            let parts: Vec<String> = runs
                .iter()
                .map(|(w, from, to, said)| {
                    let range = if from == to {
                        format!("PSNR target {from:.1} dB")
                    } else {
                        format!("PSNR targets {from:.1}-{to:.1} dB")
                    };
                    match said {
                        Some(c) if w == "no clear winner" => {
                            format!("{range}: {c}")
                        }
                        Some(c) => format!("{w} is faster for {range} ({c} at {to:.1} dB)"),
                        None => format!("{range}: {w}"),
                    }
                })
                .collect();
            out.push(format!("At matched accuracy: {}.", parts.join("; ")));
        }
        let best_psnr: Vec<String> = names
            .iter()
            .filter_map(|b| {
                let p = of(b)
                    .iter()
                    .filter_map(|r| r.psnr_db)
                    .fold(f64::NEG_INFINITY, f64::max);
                p.is_finite().then(|| format!("{b} {p:.1} dB"))
            })
            .collect();
        if best_psnr.len() == names.len() {
            out.push(format!(
                "Best accuracy reached: {} PSNR.",
                best_psnr.join(", ")
            ));
        }
        // Median memory over each backend's quality levels, least first.
        let mut mem: Vec<(&str, u64)> = names
            .iter()
            .map(|b| {
                let mut v: Vec<u64> = of(b).iter().map(|r| r.memory_bytes).collect();
                v.sort_unstable();
                (b.as_str(), v[v.len() / 2])
            })
            .collect();
        mem.sort_by_key(|m| m.1);
        if let [(less, lo), (more, hi), ..] = mem.as_slice()
            && *lo > 0
        {
            let listed: Vec<String> = names
                .iter()
                .filter_map(|b| mem.iter().find(|m| m.0 == b))
                .map(|(b, m)| format!("{b} {}", bytes(*m)))
                .collect();
            out.push(format!(
                "Memory: {less} uses {:.1}x less than {more} (median over quality levels: {}).",
                *hi as f64 / *lo as f64,
                listed.join(", ")
            ));
        }
    }
    let exhausted: Vec<&&Row> = rows
        .iter()
        .filter(|r| r.step_exhaustion_pct > 0.1)
        .collect();
    for r in exhausted {
        out.push(format!(
            "{} ends {:.2}% of its rays by step exhaustion (drawn as misses).",
            label(r),
            r.step_exhaustion_pct
        ));
    }
    for r in rows.iter().filter(|r| r.non_finite_count > 0) {
        out.push(format!(
            "{} produced {} NaN/inf values.",
            label(r),
            r.non_finite_count
        ));
    }
    out
}

fn timing_clock(res: &Results) -> Clock {
    Clock::for_run(res)
}

/// The Markdown summary of a run.
pub fn summary_markdown(res: &Results) -> String {
    let mut s = String::new();
    let p = &res.provenance;
    let _ = writeln!(s, "# Benchmark `{}`: run {}\n", res.suite, res.run_id);
    if !res.description.is_empty() {
        let _ = writeln!(s, "{}\n", res.description);
    }
    let _ = writeln!(
        s,
        "| date (UTC) | CPU | logical cores | rustc | target | profile | commit | version |\n|---|---|---|---|---|---|---|---|\n| {} | {} | {} | {} | {} | {} | {}{} | {} |\n",
        p.date_utc,
        p.cpu_model,
        p.logical_cores,
        p.rustc,
        p.target,
        p.profile,
        &p.git_commit[..p.git_commit.len().min(12)],
        if p.git_dirty { " (dirty)" } else { "" },
        p.version
    );
    let _ = writeln!(s, "Command: `{}`\n", p.command);
    if let Some(l) = p.load_average_1m {
        let _ = writeln!(
            s,
            "Load average at the start: {l:.2} on {} logical cores{}.\n",
            p.logical_cores,
            if l > 0.5 * p.logical_cores as f64 {
                " (shared machine: other processes competed for the cores, so times are noisier than the confidence intervals of a quiet machine)"
            } else {
                ""
            }
        );
    }
    if let Some(l) = p.load_average_1m_end {
        let _ = writeln!(s, "Load average at the end: {l:.2}.\n");
    }
    let _ = writeln!(
        s,
        "{}\n",
        match timing_clock(res) {
            Clock::Cpu => format!(
                "Verdicts use **CPU time** (user + system of all threads): the load average exceeded the {} logical cores, so other processes took cores from the renders and wall time would measure the machine's load as much as the representations. Both clocks are in the tables.",
                p.logical_cores
            ),
            Clock::Wall => format!(
                "Verdicts use **wall time**: the load average stayed within the {} logical cores, so wall time is what a user waits and is not inflated by competition (CPU time would switch on above it). Both clocks are in the tables.",
                p.logical_cores
            ),
        }
    );
    if let Some(seed) = res.rotation_seed {
        let _ = writeln!(
            s,
            "The configurations of one scene and resolution were timed in rotation: each round renders every configuration still wanting repeats once, in an order shuffled with seed {seed} (`marchmesh bench --seed {seed}` reproduces it).\n"
        );
    }
    let _ = writeln!(
        s,
        "{} configurations measured, {} failed, {} scenes skipped{}.\n",
        res.rows.len(),
        res.failures.len(),
        res.skipped.len(),
        if res.interrupted {
            "; **interrupted**: only finished configurations are listed"
        } else {
            ""
        }
    );
    let _ = writeln!(
        s,
        "Times are medians of the timed repeats after one untimed warm-up, with the order-statistic 95% confidence interval of the median. Accuracy is against the exact reference render at the same camera: silhouette = % of pixels hit by only one of the two, depth error p95 relative to the diagonal of the visible scene, normal error in degrees, PSNR of the 8-bit images (100 = identical); rare large errors a p95 hides show as the largest depth error relative to the reference depth and the tail counts: pixels beyond 1e-3 relative depth / beyond 5 degrees normal. Memory is the representation's bytes as reported by the backend; heap columns are the peak heap above the phase's start (counting allocator), the render's including its framebuffers.\n"
    );
    for f in &res.failures {
        let _ = writeln!(s, "- failed: `{}`: {}", f.config_id, f.error);
    }
    for m in &res.missing {
        let _ = writeln!(s, "- missing (not measured before the run stopped): `{m}`");
    }
    for e in &res.write_errors {
        let _ = writeln!(s, "- not written: {e}");
    }
    for k in &res.skipped {
        let _ = writeln!(s, "- skipped: {k}");
    }
    for r in res
        .references
        .iter()
        .filter_map(|r| r.error.as_ref().map(|e| (r, e)))
    {
        let _ = writeln!(
            s,
            "- reference for {} {}x{}: {}",
            r.0.scene, r.0.width, r.0.height, r.1
        );
    }
    if !res.failures.is_empty()
        || !res.skipped.is_empty()
        || !res.missing.is_empty()
        || !res.write_errors.is_empty()
    {
        s.push('\n');
    }
    let timing = Timing::of(res);
    let heads = headlines(&res.rows, HEADLINE_MIN_PSNR_DB, timing);
    if !heads.is_empty() {
        let _ = writeln!(
            s,
            "## Headlines\n\nFastest configuration of each backend reaching PSNR >= {:.0} dB against the reference, per scene and setting, on {} time (memory is that configuration's representation). A ratio is \"paired\" when both were timed in the same rotation: it is the median of the per-round ratios with its confidence interval, which cancels slow drifts of the machine's load; a claim whose interval includes 1 is reported as no clear winner.\n",
            HEADLINE_MIN_PSNR_DB,
            timing.clock.name()
        );
        for h in heads {
            let _ = writeln!(s, "- {h}");
        }
        s.push('\n');
    }
    // Tables per group and scene, in first-appearance order.
    let order = group_scenes(res);
    for (group, scene) in &order {
        let rows: Vec<&Row> = res
            .rows
            .iter()
            .filter(|r| &r.group == group && &r.scene == scene)
            .collect();
        let _ = writeln!(s, "## {group} / {scene}\n");
        let _ = writeln!(
            s,
            "| {} |\n|{}",
            SUMMARY_COLUMNS
                .iter()
                .map(|c| c.0)
                .collect::<Vec<_>>()
                .join(" | "),
            "---|".repeat(SUMMARY_COLUMNS.len())
        );
        for r in &rows {
            let cells: Vec<String> = SUMMARY_COLUMNS.iter().map(|c| (c.1)(r)).collect();
            let _ = writeln!(s, "| {} |", cells.join(" | "));
        }
        s.push('\n');
        for k in settings(rows.iter().copied()) {
            let set: Vec<&Row> = rows.iter().copied().filter(|r| setting(r) == k).collect();
            let _ = writeln!(s, "### {}x{}, {} threads\n", k.2, k.3, k.4);
            if res.merged_from.len() > 1 && !k.5.is_empty() {
                let _ = writeln!(s, "Measured on {}.\n", k.5);
            }
            if let Some(r) = res
                .references
                .iter()
                .find(|r| r.scene == k.1 && (r.width, r.height) == (k.2, k.3))
                && let (Some(b), Some(t)) = (r.build_ms, r.render_ms)
            {
                let _ = writeln!(
                    s,
                    "Ground truth: the exact reference backend, build {b:.2} ms, one render {t:.2} ms (all cores).\n"
                );
            }
            let front = pareto_front(&set);
            if front.is_empty() {
                let _ = writeln!(s, "No accuracy measured: no Pareto front.\n");
            } else {
                let parts: Vec<String> = front
                    .iter()
                    .map(|&i| {
                        format!(
                            "{} ({:.2} ms, {:.1} dB)",
                            label(set[i]),
                            set[i].render_ms_median,
                            set[i].psnr_db.unwrap_or(f64::NAN)
                        )
                    })
                    .collect();
                let _ = writeln!(
                    s,
                    "Pareto front (render time vs PSNR, fastest first): {}.\n",
                    parts.join(" -> ")
                );
            }
            let mut mem: BTreeMap<&str, (u64, u64)> = BTreeMap::new();
            for r in &set {
                let e = mem.entry(r.backend.as_str()).or_insert((u64::MAX, 0));
                e.0 = e.0.min(r.memory_bytes);
                e.1 = e.1.max(r.memory_bytes);
            }
            let mem_parts: Vec<String> = mem
                .iter()
                .map(|(b, (lo, hi))| format!("{b} {} to {}", bytes(*lo), bytes(*hi)))
                .collect();
            let _ = writeln!(s, "Memory: {}.\n", mem_parts.join(", "));
            for v in verdict(&set, timing) {
                let _ = writeln!(s, "- {v}");
            }
            s.push('\n');
        }
    }
    s
}

fn plot_err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// A backend's plot colour: by its place in [`BackendKind::ALL`], so a backend keeps its
/// colour in every plot (sdf blue, mesh red as before); unknown names share one other colour.
fn color_of(backend: &str) -> RGBColor {
    let i = BackendKind::ALL
        .iter()
        .position(|k| k.name() == backend)
        .map_or(COLORS.len() - 2, |i| (i + COLORS.len() - 1) % COLORS.len());
    COLORS[i]
}

/// Axis numbers: at most 3 significant digits, k/M/G suffixes for large values.
fn short_num(v: f64) -> String {
    let a = v.abs();
    let (x, suffix) = if a >= 1e9 {
        (v / 1e9, "G")
    } else if a >= 1e6 {
        (v / 1e6, "M")
    } else if a >= 1e4 {
        (v / 1e3, "k")
    } else {
        (v, "")
    };
    let t = format!("{x:.3}");
    let t = if t.contains('.') {
        t.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        t
    };
    format!("{t}{suffix}")
}

fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| *v > 0.0 && v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.1, 10.0);
    }
    (lo / 1.5, hi * 1.5)
}

fn lin_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.1).max(1.0);
    (lo - pad, hi + pad)
}

fn scatter_by_backend(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    points: &[(String, f64, f64)],
    y_log: bool,
) -> Result<(), String> {
    let root = SVGBackend::new(path, (720, 480)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let (x0, x1) = log_range(points.iter().map(|p| p.1));
    let mut backends: Vec<&str> = points.iter().map(|p| p.0.as_str()).collect();
    backends.sort_unstable();
    backends.dedup();
    let mut builder = ChartBuilder::on(&root);
    builder
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70);
    macro_rules! draw {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_desc(y_desc)
                .x_label_formatter(&|v| short_num(*v))
                .y_label_formatter(&|v| short_num(*v))
                .draw()
                .map_err(plot_err)?;
            for b in &backends {
                let c = color_of(b);
                chart
                    .draw_series(
                        points
                            .iter()
                            .filter(|p| p.0 == *b)
                            .map(|p| Circle::new((p.1, p.2), 5, c.filled())),
                    )
                    .map_err(plot_err)?
                    .label(b.to_string())
                    .legend(move |(x, y)| Circle::new((x, y), 5, c.filled()));
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(plot_err)?;
        }};
    }
    if y_log {
        let (y0, y1) = log_range(points.iter().map(|p| p.2));
        draw!(
            builder
                .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
                .map_err(plot_err)?
        );
    } else {
        let (y0, y1) = lin_range(points.iter().map(|p| p.2));
        draw!(
            builder
                .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
                .map_err(plot_err)?
        );
    }
    root.present().map_err(plot_err)
}

fn lines(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<(), String> {
    line_plot(path, title, x_desc, y_desc, series, false)
}

/// A line plot of named series (points and lines, one colour each) from zero up on the y axis;
/// a log x axis when `log_x` (non-positive x values are left out there).
///
/// Errors: the SVG cannot be written.
pub(crate) fn line_plot(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    series: &[(String, Vec<(f64, f64)>)],
    log_x: bool,
) -> Result<(), String> {
    let root = SVGBackend::new(path, (720, 480)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let y1 = series
        .iter()
        .flat_map(|s| s.1.iter().map(|p| p.1))
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .max(1e-9)
        * 1.1;
    let mut builder = ChartBuilder::on(&root);
    builder
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70);
    macro_rules! draw {
        ($chart:expr, $keep:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_desc(y_desc)
                .x_label_formatter(&|v| short_num(*v))
                .draw()
                .map_err(plot_err)?;
            for (i, (name, pts)) in series.iter().enumerate() {
                let c = COLORS[i % COLORS.len()];
                let pts: Vec<(f64, f64)> = pts
                    .iter()
                    .copied()
                    .filter(|p| p.1.is_finite() && $keep(p.0))
                    .collect();
                let style = ShapeStyle::from(&c).stroke_width(2);
                chart
                    .draw_series(LineSeries::new(pts.iter().copied(), style))
                    .map_err(plot_err)?
                    .label(name.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c));
                chart
                    .draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))
                    .map_err(plot_err)?;
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(plot_err)?;
        }};
    }
    let xs = || series.iter().flat_map(|s| s.1.iter().map(|p| p.0));
    if log_x {
        let (x0, x1) = log_range(xs());
        draw!(
            builder
                .build_cartesian_2d((x0..x1).log_scale(), 0.0..y1)
                .map_err(plot_err)?,
            |x: f64| x > 0.0
        );
    } else {
        let (x0, x1) = lin_range(xs());
        draw!(
            builder
                .build_cartesian_2d(x0.max(0.0)..x1, 0.0..y1)
                .map_err(plot_err)?,
            |_: f64| true
        );
    }
    root.present().map_err(plot_err)
}

/// Writes the plots into `dir` (created), returning the file names. A plot without data is
/// not written.
pub fn write_plots(res: &Results, dir: &Path) -> Result<Vec<String>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut written = Vec::new();
    let slug = crate::bench::slug;
    // Time vs error per (group, scene).
    let scenes = group_scenes(res);
    for (g, sc) in &scenes {
        let pts: Vec<(String, f64, f64)> = res
            .rows
            .iter()
            .filter(|r| &r.group == g && &r.scene == sc)
            .filter_map(|r| {
                r.psnr_db
                    .map(|p| (r.backend.clone(), r.render_ms_median, p))
            })
            .collect();
        if !pts.is_empty() {
            let name = format!("time_vs_error_{}_{}.svg", slug(g), slug(sc));
            scatter_by_backend(
                &dir.join(&name),
                &format!("{g}/{sc}: render time vs accuracy"),
                "median render time, ms (log)",
                "PSNR vs reference, dB",
                &pts,
                false,
            )?;
            written.push(name);
        }
        // Steps histogram of every sdf configuration of the scene.
        let series: Vec<(String, Vec<(f64, f64)>)> = res
            .rows
            .iter()
            .filter(|r| &r.group == g && &r.scene == sc && r.backend == "sdf")
            .filter_map(|r| {
                let h = res.steps_histograms.get(&r.config_id)?;
                let total: u64 = h.iter().sum();
                (total > 0).then(|| {
                    (
                        r.quality.clone(),
                        h.iter()
                            .enumerate()
                            .map(|(i, &n)| (i as f64, n as f64 / total as f64))
                            .collect(),
                    )
                })
            })
            .take(8)
            .collect();
        if !series.is_empty() {
            let name = format!("steps_histogram_{}_{}.svg", slug(g), slug(sc));
            lines(
                &dir.join(&name),
                &format!("{g}/{sc}: SDF steps per primary ray"),
                "log2 bin (k: 2^(k-1)..2^k-1 steps)",
                "fraction of primary rays",
                &series,
            )?;
            written.push(name);
        }
    }
    // Memory vs scene size: x = triangles stored (mesh rows: their own; other rows: the
    // largest mesh configuration of the same scene).
    let mut tri: BTreeMap<(String, String), u64> = BTreeMap::new();
    for r in &res.rows {
        if let Some(t) = r.triangles {
            let e = tri.entry((r.group.clone(), r.scene.clone())).or_insert(0);
            *e = (*e).max(t);
        }
    }
    let pts: Vec<(String, f64, f64)> = res
        .rows
        .iter()
        .filter_map(|r| {
            let t = r
                .triangles
                .or_else(|| tri.get(&(r.group.clone(), r.scene.clone())).copied())?;
            Some((
                r.backend.clone(),
                t.max(1) as f64,
                r.memory_bytes.max(1) as f64,
            ))
        })
        .collect();
    if !pts.is_empty() {
        let name = "memory_vs_scene_size.svg".to_string();
        scatter_by_backend(
            &dir.join(&name),
            "representation memory vs scene size",
            "triangles stored (sdf: the scene's largest mesh configuration) (log)",
            "representation memory, bytes (log)",
            &pts,
            true,
        )?;
        written.push(name);
    }
    // Mrays/s vs threads for configurations measured at several thread counts.
    let mut by_cfg: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    for r in &res.rows {
        let key = format!(
            "{}/{}/{}:{} {}x{}",
            r.group, r.scene, r.backend, r.quality, r.width, r.height
        );
        by_cfg
            .entry(key)
            .or_default()
            .push((r.threads as f64, r.mrays_per_s));
    }
    let series: Vec<(String, Vec<(f64, f64)>)> = by_cfg
        .into_iter()
        .filter(|(_, v)| v.len() > 1)
        .map(|(k, mut v)| {
            v.sort_by(|a, b| a.0.total_cmp(&b.0));
            (k, v)
        })
        .take(12)
        .collect();
    if !series.is_empty() {
        let name = "mrays_vs_threads.svg".to_string();
        lines(
            &dir.join(&name),
            "throughput vs render threads",
            "threads",
            "Mrays/s (primary + secondary)",
            &series,
        )?;
        written.push(name);
    }
    Ok(written)
}

/// Writes `summary.md`, `plots/` and `report.html` (which inlines the plots and shows the
/// images of `images/`, see [`crate::html`]) into `dir` from `res`. Returns the plot file
/// names.
pub fn write_report(res: &Results, dir: &Path) -> Result<Vec<String>, String> {
    let summary = dir.join("summary.md");
    marchmesh_safeio::replace_regular(&summary, summary_markdown(res).as_bytes())
        .map_err(|e| e.to_string())?;
    let plots = write_plots(res, &dir.join("plots"))?;
    let html = dir.join("report.html");
    marchmesh_safeio::replace_regular(&html, crate::html::report_html(res, dir).as_bytes())
        .map_err(|e| e.to_string())?;
    Ok(plots)
}

/// Creates a fresh run folder `<out>/<UTC timestamp>-<suite>` (suffix `-2`, `-3`, ... if the
/// name is taken: runs never overwrite each other) with `images/` inside. Returns the run id
/// and the folder.
pub fn create_run_dir(out: &Path, suite: &str) -> std::io::Result<(String, std::path::PathBuf)> {
    std::fs::create_dir_all(out)?;
    let stamp = crate::results::utc_strings(crate::results::now_secs()).1;
    let base = format!("{stamp}-{}", crate::bench::slug(suite));
    for n in 1..1000 {
        let id = if n == 1 {
            base.clone()
        } else {
            format!("{base}-{n}")
        };
        let dir = out.join(&id);
        match std::fs::create_dir(&dir) {
            Ok(()) => {
                std::fs::create_dir(dir.join("images"))?;
                return Ok((id, dir));
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::other(format!("too many runs named {base}")))
}

/// Writes `results.json`, then reads it back and writes `results.csv`, `summary.md`,
/// `plots/` and `report.html` from what was read, so `marchmesh report` on the folder reproduces them exactly.
/// Returns the plot file names.
pub fn write_run(res: &Results, dir: &Path) -> Result<Vec<String>, String> {
    let json = dir.join("results.json");
    res.write_json(&json).map_err(|e| e.to_string())?;
    let back = Results::read_json(&json).map_err(|e| e.to_string())?;
    back.write_csv(&dir.join("results.csv"))
        .map_err(|e| e.to_string())?;
    write_report(&back, dir)
}

/// The distinct `(group, scene)` pairs of a run, in first-appearance order.
fn group_scenes(res: &Results) -> Vec<(String, String)> {
    let mut order: Vec<(String, String)> = Vec::new();
    for r in &res.rows {
        let k = (r.group.clone(), r.scene.clone());
        if !order.contains(&k) {
            order.push(k);
        }
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::results::tests_support::row;

    #[test]
    fn axis_numbers_are_short() {
        assert_eq!(short_num(10_000_000.0), "10M");
        assert_eq!(short_num(250.0), "250");
        assert_eq!(short_num(0.125), "0.125");
        assert_eq!(short_num(45_000.0), "45k");
    }

    #[test]
    fn bytes_are_human_readable() {
        assert_eq!(bytes(512), "512 B");
        assert_eq!(bytes(2048), "2.00 KiB");
        assert_eq!(bytes(45 << 20), "45.0 MiB");
        assert_eq!(bytes(300 << 30), "300 GiB");
    }

    #[test]
    fn headlines_compare_the_fastest_rows_above_the_threshold() {
        let a = row("sdf", "a", 10.0, Some(45.0), 100);
        let b = row("sdf", "b", 5.0, Some(30.0), 100);
        let c = row("mesh", "c", 30.0, Some(41.0), 2048);
        let h = headlines(&[a.clone(), b, c], 40.0, Timing::medians_only());
        assert_eq!(h.len(), 1);
        let h0 = h[0].to_string();
        assert!(h0.contains("sdf:a 10.0 ms (45.0 dB, 100 B) vs mesh:c 30.0 ms (41.0 dB, 2.00 KiB): sdf 3.00x faster than mesh, ratio of medians"), "{h0}");
        let low = row("mesh", "d", 1.0, Some(30.0), 2048);
        let h = headlines(&[a, low], 40.0, Timing::medians_only());
        assert!(h[0].contest.is_none());
        assert!(
            h[0].to_string().contains("mesh: none reaches 40 dB"),
            "{}",
            h[0]
        );
    }

    #[test]
    fn pareto_front_keeps_only_undominated_rows() {
        let a = row("sdf", "a", 10.0, Some(30.0), 100);
        let b = row("sdf", "b", 20.0, Some(25.0), 100); // slower and worse than a
        let c = row("mesh", "c", 5.0, Some(20.0), 1000);
        let d = row("mesh", "d", 30.0, Some(40.0), 1000);
        let e = row("mesh", "e", 1.0, None, 1000); // no accuracy: not on the front
        let rows = vec![&a, &b, &c, &d, &e];
        let front: Vec<&str> = pareto_front(&rows)
            .iter()
            .map(|&i| rows[i].quality.as_str())
            .collect();
        assert_eq!(front, ["c", "a", "d"]);
    }

    #[test]
    fn verdict_states_the_winner_per_accuracy_range_and_memory() {
        let a = row("sdf", "a", 10.0, Some(30.0), 100);
        let c = row("mesh", "c", 5.0, Some(20.0), 1000);
        let d = row("mesh", "d", 30.0, Some(40.0), 1000);
        let v = verdict(&[&a, &c, &d], Timing::medians_only()).join("\n");
        assert!(
            v.contains("Fastest configuration: mesh:c at 5.00 ms"),
            "{v}"
        );
        assert!(
            v.contains("mesh is faster for PSNR target 20.0 dB (mesh 2.00x faster than sdf, ratio of medians at 20.0 dB)"),
            "{v}"
        );
        assert!(
            v.contains("sdf is faster for PSNR target 30.0 dB (sdf 3.00x faster than mesh, ratio of medians at 30.0 dB)"),
            "{v}"
        );
        assert!(
            v.contains("PSNR target 40.0 dB: mesh (only mesh reaches it)"),
            "{v}"
        );
        assert!(v.contains("sdf uses 10.0x less than mesh"), "{v}");
    }
}
