//! `plots/*.svg`: scatter and line plots drawn with plotters' SVG backend (no fonts needed, so
//! the files are the same on every machine).

use std::collections::BTreeMap;
use std::path::Path;

use plotters::prelude::*;

use super::{group_scenes, pareto_front_on, short_num};
use crate::backend::BackendId;
use crate::results::Results;
use crate::verdicts::Clock;
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

/// A log axis range covering `values`: widened to whole powers of ten, so the axis has a tick
/// at each power and its 1-2-5 steps (plotters puts log ticks only from the first power of ten
/// inside the range on).
pub(crate) fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| *v > 0.0 && v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.1, 10.0);
    }
    let lo = 10f64.powf(lo.log10().floor());
    let hi = 10f64.powf(hi.log10().ceil()).max(lo * 10.0);
    (lo, hi)
}

/// The label of log-axis tick `v` on an axis from `lo` to `hi`: only the ticks at mantissas
/// 1, 2, 3 and 5 (up to two decades), 1, 2 and 5 (up to four) or powers of ten (more) carry a
/// label, so labels never run into each other; the other ticks stay
/// as unlabelled grid lines.
pub(crate) fn log_tick_label(v: f64, lo: f64, hi: f64) -> String {
    if v <= 0.0 || !v.is_finite() {
        return String::new();
    }
    let decades = (hi / lo).log10();
    let mantissa = v / 10f64.powf(v.log10().floor());
    let m = mantissa.round();
    let near = (mantissa - m).abs() < 1e-6 * m.max(1.0) || (mantissa - 10.0).abs() < 1e-6;
    let m = if (mantissa - 10.0).abs() < 1e-6 {
        1.0
    } else {
        m
    };
    let allowed: &[f64] = if decades <= 2.01 {
        &[1.0, 2.0, 3.0, 5.0]
    } else if decades <= 4.01 {
        &[1.0, 2.0, 5.0]
    } else {
        &[1.0]
    };
    if near && allowed.contains(&m) {
        short_num(v)
    } else {
        String::new()
    }
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
    let (ly0, ly1) = log_range(points.iter().map(|p| p.2));
    macro_rules! draw {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                // No minor lines between the ticks: on a log axis they crowd into grey bands.
                .light_line_style(TRANSPARENT)
                .x_desc(x_desc)
                .y_desc(y_desc)
                .x_labels(100)
                .y_labels(if y_log { 100 } else { 10 })
                .x_label_formatter(&|v| log_tick_label(*v, x0, x1))
                .y_label_formatter(&|v| {
                    if y_log {
                        log_tick_label(*v, ly0, ly1)
                    } else {
                        short_num(*v)
                    }
                })
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
        draw!(
            builder
                .build_cartesian_2d((x0..x1).log_scale(), (ly0..ly1).log_scale())
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
    let xs = || series.iter().flat_map(|s| s.1.iter().map(|p| p.0));
    let (lx0, lx1) = log_range(xs());
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
                // No minor lines between the ticks: on a log axis they crowd into grey bands.
                .light_line_style(TRANSPARENT)
                .x_desc(x_desc)
                .y_desc(y_desc)
                .x_labels(if log_x { 100 } else { 10 })
                .x_label_formatter(&|v| {
                    if log_x {
                        log_tick_label(*v, lx0, lx1)
                    } else {
                        short_num(*v)
                    }
                })
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
    if log_x {
        draw!(
            builder
                .build_cartesian_2d((lx0..lx1).log_scale(), 0.0..y1)
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

/// Font size of a point's quality label, pixels.
const LABEL_FONT_PX: i32 = 11;

/// Radius of the region around a point that labels keep clear of, pixels (the circle is 4).
const POINT_CLEAR_PX: i32 = 5;

/// One configuration's point on a time-vs-accuracy plot.
struct Mark {
    /// (time ms, PSNR dB) in chart coordinates.
    at: (f64, f64),
    /// The point in the drawing's pixels.
    pixel: (i32, i32),
    color: RGBColor,
    on_front: bool,
    label: String,
}

/// An estimate of `label`'s width in pixels at [`LABEL_FONT_PX`] (sans-serif averages a bit
/// over half the font size per character; erring wide keeps labels apart).
fn label_width_px(label: &str) -> i32 {
    let chars = i32::try_from(label.chars().count()).unwrap_or(i32::MAX / 8);
    chars.saturating_mul(LABEL_FONT_PX * 6 / 10) + 2
}

/// Offsets (from its point, pixels, to the label's top-left corner) for the labels of
/// `points` (each a pixel position and its label's width), chosen greedily in order: the
/// first of a ring of candidate positions around the point whose box overlaps no label
/// placed before it and no point. Where every candidate overlaps, the one overlapping least
/// is used, so a crowded plot still labels every point.
fn place_labels(points: &[((i32, i32), i32)]) -> Vec<(i32, i32)> {
    type Rect = (i32, i32, i32, i32); // x0, y0, x1, y1
    fn overlap(a: Rect, b: Rect) -> i64 {
        let w = i64::from(a.2.min(b.2)) - i64::from(a.0.max(b.0));
        let h = i64::from(a.3.min(b.3)) - i64::from(a.1.max(b.1));
        if w > 0 && h > 0 { w * h } else { 0 }
    }
    let h = LABEL_FONT_PX + 1;
    let point_boxes: Vec<Rect> = points
        .iter()
        .map(|&((x, y), _)| {
            (
                x - POINT_CLEAR_PX,
                y - POINT_CLEAR_PX,
                x + POINT_CLEAR_PX,
                y + POINT_CLEAR_PX,
            )
        })
        .collect();
    let mut placed: Vec<Rect> = Vec::with_capacity(points.len());
    let mut offsets = Vec::with_capacity(points.len());
    for &((x, y), w) in points {
        let candidates = [
            (6, -h),
            (6, 1),
            (-6 - w, -h),
            (-6 - w, 1),
            (-w / 2, -h - 6),
            (-w / 2, 7),
            (6, -2 * h),
            (6, h + 1),
            (-6 - w, -2 * h),
            (-6 - w, h + 1),
            (-w / 2, -2 * h - 6),
            (-w / 2, h + 7),
        ];
        let cost = |&(dx, dy): &(i32, i32)| -> i64 {
            let r = (x + dx, y + dy, x + dx + w, y + dy + h);
            placed.iter().map(|&p| overlap(r, p)).sum::<i64>()
                + point_boxes.iter().map(|&p| overlap(r, p)).sum::<i64>()
        };
        let best = candidates
            .iter()
            .find(|c| cost(c) == 0)
            .or_else(|| candidates.iter().min_by_key(|c| cost(c)))
            .copied()
            .unwrap_or((6, -h));
        placed.push((x + best.0, y + best.1, x + best.0 + w, y + best.1 + h));
        offsets.push(best);
    }
    offsets
}

/// Render time (on the run's verdict `clock`, log axis, with each median's 95% CI as a bar)
/// against PSNR for the rows of one scene: each backend's Pareto front (no faster row of the
/// backend is at least as accurate) as a line through its points, dominated configurations as
/// faint hollow points, every point labelled with its quality level. Rows without PSNR are
/// left out.
///
/// Errors: the SVG cannot be written.
pub(crate) fn time_vs_accuracy(
    path: &Path,
    title: &str,
    clock: Clock,
    rows: &[&crate::results::Row],
) -> Result<(), String> {
    let rows: Vec<&crate::results::Row> = rows
        .iter()
        .copied()
        .filter(|r| r.psnr_db.is_some())
        .collect();
    let mut svg = String::new();
    let root = SVGBackend::with_string(&mut svg, (720, 480)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let (x0, x1) = log_range(rows.iter().flat_map(|r| {
        let (lo, hi) = clock.ci_ms(r);
        [clock.median_ms(r), lo, hi]
    }));
    let (y0, y1) = lin_range(rows.iter().filter_map(|r| r.psnr_db));
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        // No minor lines between the ticks: on a log axis they crowd into grey bands.
        .light_line_style(TRANSPARENT)
        .x_desc(format!(
            "median render time, ms, {} clock (log); bars: 95% CI",
            clock.name()
        ))
        .y_desc("PSNR vs reference, dB")
        .x_labels(100)
        .x_label_formatter(&|v| log_tick_label(*v, x0, x1))
        .y_label_formatter(&|v| short_num(*v))
        .draw()
        .map_err(plot_err)?;
    let backends = crate::verdicts::backends(rows.iter().copied());
    let mut marks: Vec<Mark> = Vec::new();
    for b in &backends {
        let c = color_of(b);
        let own: Vec<&crate::results::Row> =
            rows.iter().copied().filter(|r| &r.backend == b).collect();
        let front = pareto_front_on(&own, clock);
        let at = |r: &crate::results::Row| (clock.median_ms(r), r.psnr_db.unwrap_or(0.0));
        // The CI of each median as a horizontal bar (faint for dominated rows).
        chart
            .draw_series(own.iter().enumerate().map(|(i, r)| {
                let (lo, hi) = clock.ci_ms(r);
                let (x, y) = at(r);
                let alpha = if front.contains(&i) { 0.8 } else { 0.25 };
                PathElement::new(
                    vec![(lo.min(x), y), (hi.max(x), y)],
                    c.mix(alpha).stroke_width(1),
                )
            }))
            .map_err(plot_err)?;
        chart
            .draw_series(LineSeries::new(
                front.iter().map(|&i| at(own[i])),
                ShapeStyle::from(&c).stroke_width(2),
            ))
            .map_err(plot_err)?
            .label(format!("{b}: Pareto front (hollow: dominated)"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c.stroke_width(2)));
        for (i, r) in own.iter().enumerate() {
            marks.push(Mark {
                at: at(r),
                pixel: chart.backend_coord(&at(r)),
                color: c,
                on_front: front.contains(&i),
                label: r.quality.clone(),
            });
        }
    }
    // Labels placed after every point is known, front points first, so no label covers
    // another label or a point where the plot has room for it.
    marks.sort_by_key(|m| !m.on_front);
    let offsets = place_labels(
        &marks
            .iter()
            .map(|m| (m.pixel, label_width_px(&m.label)))
            .collect::<Vec<_>>(),
    );
    for (m, offset) in marks.iter().zip(offsets) {
        let (style, text_color) = if m.on_front {
            (m.color.filled(), BLACK.mix(0.9))
        } else {
            (m.color.mix(0.35).stroke_width(1), BLACK.mix(0.45))
        };
        chart
            .draw_series(std::iter::once(
                EmptyElement::at(m.at)
                    + Circle::new((0, 0), 4, style)
                    + Text::new(
                        m.label.clone(),
                        offset,
                        ("sans-serif", LABEL_FONT_PX).into_font().color(&text_color),
                    ),
            ))
            .map_err(plot_err)?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(plot_err)?;
    root.present().map_err(plot_err)?;
    drop(chart);
    drop(root);
    publish_svg(path, &svg)
}

/// Writes the plots into `dir` (created, or reused only if it is a real folder, never a
/// symbolic link), returning the file names. A plot without data is not written.
pub fn write_plots(res: &Results, dir: &Path) -> Result<Vec<String>, String> {
    marchmesh_safeio::own_folder(dir).map_err(|e| e.to_string())?;
    let mut written = Vec::new();
    let slug = crate::bench::slug;
    // Time vs error per (group, scene).
    let scenes = group_scenes(res);
    let clock = Clock::for_run(res);
    for ((g, sc), rows) in &scenes {
        if rows.iter().any(|r| r.psnr_db.is_some()) {
            let name = format!("time_vs_error_{}_{}.svg", slug(g), slug(sc));
            time_vs_accuracy(
                &dir.join(&name),
                &format!("{g}/{sc}: render time vs accuracy"),
                clock,
                rows,
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

#[cfg(test)]
mod tests {
    use super::*;

    type Rect = (i32, i32, i32, i32);

    fn rects(points: &[((i32, i32), i32)], offsets: &[(i32, i32)]) -> Vec<Rect> {
        let h = LABEL_FONT_PX + 1;
        points
            .iter()
            .zip(offsets)
            .map(|(&((x, y), w), &(dx, dy))| (x + dx, y + dy, x + dx + w, y + dy + h))
            .collect()
    }

    fn overlaps(a: Rect, b: Rect) -> bool {
        a.0 < b.2 && b.0 < a.2 && a.1 < b.3 && b.1 < a.3
    }

    #[test]
    fn a_lone_point_is_labelled_above_right() {
        let points = [((100, 100), label_width_px("default"))];
        assert_eq!(place_labels(&points), vec![(6, -(LABEL_FONT_PX + 1))]);
    }

    #[test]
    fn clustered_points_get_labels_that_cover_no_label_and_no_point() {
        // Three configurations a few pixels apart, as sdf's default/fast/relax sit on one
        // plot: with the same offset their labels would overprint.
        let points: Vec<((i32, i32), i32)> = [
            ("default", (300, 70)),
            ("fast", (306, 70)),
            ("relax", (312, 71)),
        ]
        .iter()
        .map(|&(label, p)| (p, label_width_px(label)))
        .collect();
        let placed = rects(&points, &place_labels(&points));
        for (i, a) in placed.iter().enumerate() {
            for b in &placed[i + 1..] {
                assert!(!overlaps(*a, *b), "labels {a:?} and {b:?} overlap");
            }
            for &((x, y), _) in &points {
                let point = (
                    x - POINT_CLEAR_PX,
                    y - POINT_CLEAR_PX,
                    x + POINT_CLEAR_PX,
                    y + POINT_CLEAR_PX,
                );
                assert!(
                    !overlaps(*a, point),
                    "label {a:?} covers the point at ({x}, {y})"
                );
            }
        }
    }

    #[test]
    fn a_crowd_larger_than_the_ring_still_labels_every_point() {
        let points: Vec<((i32, i32), i32)> =
            (0..40).map(|i| ((200 + i % 3, 200 + i % 2), 30)).collect();
        assert_eq!(place_labels(&points).len(), points.len());
    }
}
