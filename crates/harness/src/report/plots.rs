//! `plots/*.svg`: scatter and line plots drawn with plotters' SVG backend (no fonts needed, so
//! the files are the same on every machine).

use std::collections::BTreeMap;
use std::path::Path;

use plotters::prelude::*;

use super::{group_scenes, short_num};
use crate::backend::BackendId;
use crate::results::Results;
use marchmesh_core::Backend;

pub(crate) fn plot_err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

pub(crate) const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// A backend's plot colour: by its place in [`BackendId::ALL`], so a backend keeps its
/// colour in every plot (sdf blue, mesh red as before); unknown names share one other colour.
pub(crate) fn color_of(backend: &str) -> RGBColor {
    let i = BackendId::ALL
        .iter()
        .position(|k| k.name() == backend)
        .map_or(COLORS.len() - 2, |i| (i + COLORS.len() - 1) % COLORS.len());
    COLORS[i]
}

pub(crate) fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
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

pub(crate) fn lin_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
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

/// Writes a drawn plot to `path` through [`marchmesh_safeio::replace_regular`], so a symlink,
/// folder or device at the plot's name is refused instead of written through.
fn publish_svg(path: &Path, svg: &str) -> Result<(), String> {
    marchmesh_safeio::replace_regular(path, svg.as_bytes()).map_err(|e| e.to_string())
}

pub(crate) fn scatter_by_backend(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    points: &[(String, f64, f64)],
    y_log: bool,
) -> Result<(), String> {
    let mut svg = String::new();
    let root = SVGBackend::with_string(&mut svg, (720, 480)).into_drawing_area();
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
    root.present().map_err(plot_err)?;
    drop(root);
    publish_svg(path, &svg)
}

pub(crate) fn lines(
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
    let mut svg = String::new();
    let root = SVGBackend::with_string(&mut svg, (720, 480)).into_drawing_area();
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
    root.present().map_err(plot_err)?;
    drop(root);
    publish_svg(path, &svg)
}

/// Writes the plots into `dir` (created), returning the file names. A plot without data is
/// not written.
pub fn write_plots(res: &Results, dir: &Path) -> Result<Vec<String>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut written = Vec::new();
    let slug = crate::bench::slug;
    // Time vs error per (group, scene).
    let scenes = group_scenes(res);
    for ((g, sc), rows) in &scenes {
        let pts: Vec<(String, f64, f64)> = rows
            .iter()
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
        let series: Vec<(String, Vec<(f64, f64)>)> = rows
            .iter()
            .filter(|r| r.backend == marchmesh_sdf::SdfBackend::NAME)
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
