//! `summary.md`: provenance, the verdict clock, headlines, the per-configuration table
//! ([`SUMMARY_COLUMNS`]) and each setting's Pareto front and verdict.

use super::{bytes, label, opt, opt_bytes, pareto_front_on, tail_px, verdict};
use crate::results::{Results, Row};
use crate::verdicts::{Clock, HEADLINE_MIN_PSNR_DB, Timing, by_setting, headlines};
use std::collections::BTreeMap;
use std::fmt::Write as _;

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

pub(crate) fn timing_clock(res: &Results) -> Clock {
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
    let chart = crate::decision::DecisionChart::of_run(res);
    if !chart.is_empty() {
        let _ = writeln!(
            s,
            "## Answer\n\nPer scene and accuracy target, the fastest backend among the configurations reaching the target (PSNR against the exact reference), with the runner-up's time over the winner's and its 95% confidence interval (*medians*: the two were not timed together, the ratio is of medians). *No clear winner*: the interval includes 1. *Alone*: no other backend reaches the target. Each backend's fastest configuration reaching a target is named under *Headlines* and per scene below.\n\n{}",
            chart.markdown()
        );
    }
    let _ = writeln!(s, "## Method\n");
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
    let references: std::collections::HashMap<(&str, u32, u32), &crate::results::ReferenceInfo> =
        res.references
            .iter()
            .rev()
            .map(|r| ((r.scene.as_str(), r.width, r.height), r))
            .collect();
    for ((group, scene), rows) in &order {
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
        for r in rows {
            let cells: Vec<String> = SUMMARY_COLUMNS.iter().map(|c| (c.1)(r)).collect();
            let _ = writeln!(s, "| {} |", cells.join(" | "));
        }
        s.push('\n');
        for (k, set) in by_setting(rows.iter().copied()) {
            let _ = writeln!(s, "### {}x{}, {} threads\n", k.2, k.3, k.4);
            if res.merged_from.len() > 1 && !k.5.is_empty() {
                let _ = writeln!(s, "Measured on {}.\n", k.5);
            }
            if let Some(r) = references.get(&(k.1.as_str(), k.2, k.3))
                && let (Some(b), Some(t)) = (r.build_ms, r.render_ms)
            {
                let _ = writeln!(
                    s,
                    "Ground truth: the exact reference backend, build {b:.2} ms, one render {t:.2} ms (all cores).\n"
                );
            }
            let front = pareto_front_on(&set, timing.clock);
            if front.is_empty() {
                let _ = writeln!(s, "No accuracy measured: no Pareto front.\n");
            } else {
                let parts: Vec<String> = front
                    .iter()
                    .map(|&i| {
                        format!(
                            "{} ({:.2} ms, {:.1} dB)",
                            label(set[i]),
                            timing.clock.median_ms(set[i]),
                            set[i].psnr_db.unwrap_or(f64::NAN)
                        )
                    })
                    .collect();
                let _ = writeln!(
                    s,
                    "Pareto front ({} time vs PSNR, fastest first): {}.\n",
                    timing.clock.name(),
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
    s.push_str(&crate::anchors::anchors_markdown(&res.anchors));
    s
}

/// The rows of each distinct `(group, scene)` pair of a run, pairs in first-appearance order
/// and rows in their order (linear time: one hash lookup per row).
pub(crate) fn group_scenes(res: &Results) -> Vec<((String, String), Vec<&Row>)> {
    let mut index: std::collections::HashMap<(&str, &str), usize> = Default::default();
    let mut out: Vec<((String, String), Vec<&Row>)> = Vec::new();
    for r in &res.rows {
        match index.get(&(r.group.as_str(), r.scene.as_str())) {
            Some(&i) => out[i].1.push(r),
            None => {
                index.insert((r.group.as_str(), r.scene.as_str()), out.len());
                out.push(((r.group.clone(), r.scene.clone()), vec![r]));
            }
        }
    }
    out
}
