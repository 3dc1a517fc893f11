//! `stability.csv`, `stability.json` and `summary.md` of a stability run.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use crate::cases::fmt_value;
use crate::runner::{CaseError, Metrics, Row, Verdict};

/// One column of `stability.csv`: its header name (units in the name) and its cell for a row.
/// A new metric is a field of [`crate::runner::Metrics`], its value in `Metrics::measure`, and
/// one entry in [`COLUMNS`].
pub struct Column {
    /// Header name.
    pub name: &'static str,
    /// The row's cell, CSV-quoted where needed; empty when the row has no metrics.
    pub cell: fn(&Row) -> String,
}

/// The metric `f` reads, or an empty cell when the row has none (a refused configuration).
fn metric(r: &Row, f: impl Fn(&Metrics) -> String) -> String {
    r.metrics.as_ref().map(f).unwrap_or_default()
}

/// The columns of `stability.csv`, in order: one row per case x configuration.
pub const COLUMNS: &[Column] = &[
    Column {
        name: "case",
        cell: |r| csv_field(&r.case),
    },
    Column {
        name: "family",
        cell: |r| csv_field(&r.family),
    },
    Column {
        name: "parameter",
        cell: |r| csv_field(&r.parameter),
    },
    Column {
        name: "value",
        cell: |r| format!("{}", r.value),
    },
    Column {
        name: "backend",
        cell: |r| csv_field(&r.backend),
    },
    Column {
        name: "configuration",
        cell: |r| csv_field(&r.configuration),
    },
    Column {
        name: "verdict",
        cell: |r| r.verdict.name().to_string(),
    },
    Column {
        name: "non_finite",
        cell: |r| metric(r, |m| m.non_finite.to_string()),
    },
    Column {
        name: "silhouette_mismatch_pct",
        cell: |r| metric(r, |m| format!("{:.4}", m.silhouette_mismatch_pct)),
    },
    Column {
        name: "interior_holes_px",
        cell: |r| metric(r, |m| m.interior_holes.to_string()),
    },
    Column {
        name: "depth_rel_p95",
        cell: |r| metric(r, |m| format!("{:.3e}", m.depth_rel_p95)),
    },
    Column {
        name: "depth_max_over_scene",
        cell: |r| metric(r, |m| format!("{:.3e}", m.depth_max_over_scene)),
    },
    Column {
        name: "depth_rel_max",
        cell: |r| metric(r, |m| format!("{:.3e}", m.depth_rel_max)),
    },
    Column {
        name: "depth_rel_tail_px",
        cell: |r| metric(r, |m| m.depth_rel_tail_px.to_string()),
    },
    Column {
        name: "normal_deg_mean",
        cell: |r| metric(r, |m| format!("{:.4}", m.normal_deg_mean)),
    },
    Column {
        name: "normal_deg_tail_px",
        cell: |r| metric(r, |m| m.normal_deg_tail_px.to_string()),
    },
    Column {
        name: "normal_deg_p95",
        cell: |r| metric(r, |m| format!("{:.4}", m.normal_deg_p95)),
    },
    Column {
        name: "psnr_db",
        cell: |r| metric(r, |m| format!("{:.2}", m.psnr_db)),
    },
    Column {
        name: "step_exhaustion_pct",
        cell: |r| metric(r, |m| format!("{:.4}", m.step_exhaustion_pct)),
    },
    Column {
        name: "mean_steps",
        cell: |r| metric(r, |m| format!("{:.2}", m.mean_steps)),
    },
    Column {
        name: "build_ms",
        cell: |r| format!("{:.2}", r.build_ms),
    },
    Column {
        name: "render_ms",
        cell: |r| format!("{:.2}", r.render_ms),
    },
    Column {
        name: "memory_bytes",
        cell: |r| r.memory_bytes.to_string(),
    },
    Column {
        name: "error",
        cell: |r| csv_field(r.error.as_deref().unwrap_or("")),
    },
];

/// The CSV header line: the names of [`COLUMNS`], comma-separated.
pub fn csv_header() -> String {
    COLUMNS.iter().map(|c| c.name).collect::<Vec<_>>().join(",")
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The rows as CSV text (header included). Missing metrics are empty fields.
pub fn to_csv(rows: &[Row]) -> String {
    let mut out = csv_header();
    out.push('\n');
    for r in rows {
        let cells: Vec<String> = COLUMNS.iter().map(|c| (c.cell)(r)).collect();
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    out
}

/// Everything `stability.json` holds.
#[derive(Debug, Serialize)]
pub struct StabilityReport<'a> {
    /// The command line that produced the run.
    pub command: &'a str,
    /// Image side of every render, pixels.
    pub side: u32,
    /// One entry per case x configuration.
    pub rows: &'a [Row],
    /// Cases that could not run at all.
    pub case_errors: Vec<String>,
}

/// The safe ranges per family and configuration: for each verdict, the swept values that got it.
/// A backend run in one configuration in a family is named by the backend alone (`mesh`
/// for `mesh[tess_px=0.05]`); one run in several (`sdf` and `sdf[segment=false]`) keeps the
/// configurations apart, so each line's values are one configuration's.
pub fn ranges(rows: &[Row]) -> BTreeMap<(String, String), BTreeMap<&'static str, Vec<f64>>> {
    let mut configurations: BTreeMap<(&str, &str), std::collections::BTreeSet<&str>> =
        BTreeMap::new();
    for r in rows {
        configurations
            .entry((&r.family, &r.backend))
            .or_default()
            .insert(&r.configuration);
    }
    let mut out: BTreeMap<(String, String), BTreeMap<&'static str, Vec<f64>>> = BTreeMap::new();
    for r in rows {
        let several = configurations
            .get(&(r.family.as_str(), r.backend.as_str()))
            .is_some_and(|c| c.len() > 1);
        let label = if several {
            r.configuration.clone()
        } else {
            r.backend.clone()
        };
        out.entry((r.family.clone(), label))
            .or_default()
            .entry(r.verdict.name())
            .or_default()
            .push(r.value);
    }
    out
}

/// The image error over each family's sweep, per configuration: `(lowest PSNR dB, the swept
/// value where it occurs, highest PSNR dB)` over the rows with metrics (identical images, an
/// infinite PSNR, count as the highest). Families judged by image (the shadow methods, acne)
/// read their error bound here.
pub fn psnr_bounds(rows: &[Row]) -> BTreeMap<(String, String), (f64, f64, f64)> {
    let mut out: BTreeMap<(String, String), (f64, f64, f64)> = BTreeMap::new();
    for r in rows {
        let Some(m) = &r.metrics else { continue };
        if m.psnr_db.is_nan() {
            continue;
        }
        let e = out
            .entry((r.family.clone(), r.configuration.clone()))
            .or_insert((f64::INFINITY, r.value, f64::NEG_INFINITY));
        if m.psnr_db < e.0 {
            e.0 = m.psnr_db;
            e.1 = r.value;
        }
        e.2 = e.2.max(m.psnr_db);
    }
    out
}

fn list(values: &[f64]) -> String {
    values
        .iter()
        .map(|v| fmt_value(*v))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `summary.md`: verdict ranges per family and backend, then every row's key numbers.
pub fn to_markdown(rows: &[Row], errors: &[CaseError], side: u32) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Stability run\n");
    let truth_samples = crate::cases::SHADOW_TRUTH_SAMPLES;
    let _ = writeln!(
        s,
        "Each case renders {side}x{side} pixels with the exact reference (ground truth) and each \
         configuration. Verdicts: **exact** = no NaN, silhouette <= 0.5%, relative depth p95 <= 1e-3, \
         mean normal error <= 1 deg, step exhaustion <= 0.1%; **degraded** = silhouette <= 5%, depth \
         p95 <= 1e-2, normal <= 5 deg, exhaustion <= 5%; **broken** = worse or any NaN/inf; \
         **refused** = the backend declined to build (clear error). Image-judged families use \
         PSNR >= 40 dB / >= 25 dB: acne against each backend's own render at the default offset, \
         the shadow families against the reference's converged direct light ({truth_samples} \
         samples a light). \
         Rare large errors a p95 hides are reported beside the verdict (not judged): the largest \
         relative depth error and the tail pixels beyond 1e-3 relative depth / 5 deg normal. \
         The mesh backend runs at a 0.05 px chord budget (its accuracy setting) so that its \
         tessellation error does not hide the numerical effects.\n"
    );
    let _ = writeln!(s, "## Ranges per family and configuration\n");
    let _ = writeln!(
        s,
        "| family | configuration | exact | degraded | broken | refused |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for ((family, backend), by) in ranges(rows) {
        let get = |v: &str| by.get(v).map(|x| list(x)).unwrap_or_default();
        let _ = writeln!(
            s,
            "| {family} | {backend} | {} | {} | {} | {} |",
            get("exact"),
            get("degraded"),
            get("broken"),
            get("refused")
        );
    }
    let _ = writeln!(s, "\n## Image error per family and configuration\n");
    let _ = writeln!(
        s,
        "PSNR of each configuration's image against its truth over the family's sweep: the \
         lowest is the family's error bound for that configuration.\n"
    );
    let _ = writeln!(
        s,
        "| family | configuration | lowest PSNR dB | at | highest PSNR dB |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|");
    for ((family, configuration), (lo, at, hi)) in psnr_bounds(rows) {
        let _ = writeln!(
            s,
            "| {family} | {configuration} | {lo:.1} | {} | {hi:.1} |",
            fmt_value(at)
        );
    }
    let _ = writeln!(s, "\n## All rows\n");
    let _ = writeln!(
        s,
        "| case | configuration | verdict | NaN | silhouette % | holes px | depth rel p95 | depth rel max | tail px depth / normal | normal deg mean | PSNR dB | exhaustion % | mean steps | render ms |"
    );
    let _ = writeln!(
        s,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in rows {
        match &r.metrics {
            Some(m) => {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {} | {:.2} | {} | {:.2e} | {:.2e} | {} / {} | {:.3} | {:.1} | {:.2} | {:.1} | {:.1} |",
                    r.case,
                    r.configuration,
                    r.verdict.name(),
                    m.non_finite,
                    m.silhouette_mismatch_pct,
                    m.interior_holes,
                    m.depth_rel_p95,
                    m.depth_rel_max,
                    m.depth_rel_tail_px,
                    m.normal_deg_tail_px,
                    m.normal_deg_mean,
                    m.psnr_db,
                    m.step_exhaustion_pct,
                    m.mean_steps,
                    r.render_ms
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | | | | | | | | | | | | {} |",
                    r.case,
                    r.configuration,
                    r.verdict.name(),
                    r.error.as_deref().unwrap_or("").replace('|', "/")
                );
            }
        }
    }
    if !errors.is_empty() {
        let _ = writeln!(s, "\n## Cases that could not run\n");
        for e in errors {
            let _ = writeln!(s, "- {e}");
        }
    }
    s
}

/// Publishes `bytes` as a new file `dir/name` (never overwriting, never through a symlink; a
/// failed write leaves no partial file).
fn publish(dir: &Path, name: &str, bytes: &[u8]) -> std::io::Result<()> {
    marchmesh_safeio::publish_new(&dir.join(name), bytes).map_err(std::io::Error::other)
}

/// Writes `stability.csv`, `stability.json` and `summary.md` into `dir` (which must exist),
/// each as a new file: an existing file of those names is an error, not overwritten.
pub fn write(
    dir: &Path,
    rows: &[Row],
    errors: &[CaseError],
    side: u32,
    command: &str,
) -> std::io::Result<()> {
    publish(dir, "stability.csv", to_csv(rows).as_bytes())?;
    let report = StabilityReport {
        command,
        side,
        rows,
        case_errors: errors.iter().map(|e| e.to_string()).collect(),
    };
    let json = serde_json::to_string_pretty(&report).map_err(std::io::Error::other)?;
    publish(dir, "stability.json", json.as_bytes())?;
    publish(
        dir,
        "summary.md",
        to_markdown(rows, errors, side).as_bytes(),
    )?;
    Ok(())
}

/// Counts rows per verdict.
pub fn verdict_counts(rows: &[Row]) -> BTreeMap<&'static str, usize> {
    let mut m = BTreeMap::new();
    for v in [
        Verdict::Exact,
        Verdict::Degraded,
        Verdict::Broken,
        Verdict::Refused,
    ] {
        m.insert(v.name(), rows.iter().filter(|r| r.verdict == v).count());
    }
    m
}
