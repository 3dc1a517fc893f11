//! The answer at a glance: per scene setting and accuracy target
//! ([`ACCURACY_TARGETS_DB`]), which backend is fastest among the configurations reaching the
//! target, by how much, or that one backend alone reaches it. One [`DecisionChart`] feeds the
//! chart and table that open `summary.md`, `report.html` and the findings, and the lines
//! `bench` prints when it ends, so they cannot disagree.

use std::fmt::Write as _;

use crate::results::{Results, Row};
use crate::verdicts::{
    ACCURACY_TARGETS_DB, TargetVerdict, Timing, at_target, by_setting, setting_name,
};

/// One scene setting's verdicts, one per target.
#[derive(Debug, Clone, PartialEq)]
pub struct DecisionRow {
    /// The setting (`group/scene WxH tN`).
    pub name: String,
    /// The clock its times were read on (`wall` or `CPU`).
    pub clock: &'static str,
    /// One verdict per [`DecisionChart::targets`] entry.
    pub cells: Vec<TargetVerdict>,
}

/// Scene setting x accuracy target -> winner and ratio.
#[derive(Debug, Clone, PartialEq)]
pub struct DecisionChart {
    /// The accuracy targets, dB (the columns).
    pub targets: Vec<f64>,
    /// The settings with accuracy measured (the rows), in first-appearance order.
    pub rows: Vec<DecisionRow>,
}

impl DecisionChart {
    /// The chart of one run: every setting with accuracy, on the run's verdict clock.
    pub fn of_run(res: &Results) -> Self {
        let machines: std::collections::BTreeSet<&str> =
            res.rows.iter().map(|r| r.machine.as_str()).collect();
        let timing = Timing::of(res);
        Self::of_settings(
            by_setting(&res.rows)
                .into_iter()
                .map(|(k, rows)| (setting_name(&k, machines.len() > 1), rows, timing)),
        )
    }

    /// The chart of named settings, each with its rows and the timing of the run they come
    /// from. Settings without any accuracy are left out.
    pub fn of_settings<'a>(
        settings: impl IntoIterator<Item = (String, Vec<&'a Row>, Timing<'a>)>,
    ) -> Self {
        let targets = ACCURACY_TARGETS_DB.to_vec();
        let rows = settings
            .into_iter()
            .filter(|(_, rows, _)| rows.iter().any(|r| r.psnr_db.is_some()))
            .map(|(name, rows, timing)| DecisionRow {
                name,
                clock: timing.clock.name(),
                cells: targets
                    .iter()
                    .map(|&t| at_target(&rows, t, timing))
                    .collect(),
            })
            .collect();
        Self { targets, rows }
    }

    /// Whether there is nothing to show.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// The Markdown table: one row per setting, one column per target; a cell names the
    /// winner with its speed ratio and the ratio's 95% CI (or *medians* when the two rows were
    /// not timed together), *no clear winner*, the one backend reaching the target, or that
    /// none does.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "| scene, image size, threads | {} |\n|---|{}",
            self.targets
                .iter()
                .map(|t| format!(">= {t:.0} dB"))
                .collect::<Vec<_>>()
                .join(" | "),
            "---|".repeat(self.targets.len())
        );
        for r in &self.rows {
            let cells: Vec<String> = r
                .cells
                .iter()
                .map(|c| match c.winner() {
                    Some(w) => {
                        let rest = c.short();
                        let rest = rest.strip_prefix(w).unwrap_or(&rest);
                        format!("**{w}**{rest}")
                    }
                    None => c.short(),
                })
                .collect();
            let _ = writeln!(
                s,
                "| {} ({} time) | {} |",
                crate::report::md_escape(&r.name),
                r.clock,
                cells.join(" | ")
            );
        }
        s
    }

    /// The lines `bench` prints when it ends: per setting, the verdict at each target.
    pub fn terminal(&self) -> String {
        let mut s = String::new();
        let width = self.rows.iter().map(|r| r.name.len()).max().unwrap_or(0);
        for r in &self.rows {
            let cells: Vec<String> = self
                .targets
                .iter()
                .zip(&r.cells)
                .map(|(t, c)| format!(">={t:.0} dB: {}", c.short()))
                .collect();
            let _ = writeln!(
                s,
                "  {:<width$}  {}  [{} time]",
                r.name,
                cells.join("  |  "),
                r.clock
            );
        }
        s
    }

    /// The chart as plain SVG (rectangles and text only, so `report.html` inlines it): one
    /// row per setting, one column per target, each cell coloured by its winner's plot
    /// colour (faint when one backend alone reaches the target, grey for no clear winner,
    /// white when none reaches it) and labelled with the winner and ratio.
    pub fn svg(&self) -> String {
        const LABEL_W: usize = 300;
        const CELL_W: usize = 200;
        const ROW_H: usize = 28;
        const HEAD_H: usize = 54;
        let width = LABEL_W + CELL_W * self.targets.len() + 10;
        let height = HEAD_H + ROW_H * self.rows.len() + 40;
        let mut s = String::new();
        let _ = write!(
            s,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{height}\" viewBox=\"0 0 {width} {height}\" font-family=\"sans-serif\">"
        );
        let _ = write!(
            s,
            "<rect x=\"0\" y=\"0\" width=\"{width}\" height=\"{height}\" fill=\"#ffffff\"/>"
        );
        let _ = write!(
            s,
            "<text x=\"8\" y=\"20\" font-size=\"15\" font-weight=\"bold\">Fastest backend at matched accuracy</text>"
        );
        let _ = write!(
            s,
            "<text x=\"8\" y=\"{}\" font-size=\"12\" fill=\"rgb(68,68,68)\">scene, image size, threads</text>",
            HEAD_H - 8
        );
        for (j, t) in self.targets.iter().enumerate() {
            let _ = write!(
                s,
                "<text x=\"{}\" y=\"{}\" font-size=\"12\" fill=\"rgb(68,68,68)\" text-anchor=\"middle\">PSNR &gt;= {t:.0} dB</text>",
                LABEL_W + CELL_W * j + CELL_W / 2,
                HEAD_H - 8
            );
        }
        for (i, r) in self.rows.iter().enumerate() {
            let y = HEAD_H + ROW_H * i;
            let _ = write!(
                s,
                "<text x=\"8\" y=\"{}\" font-size=\"12\">{}</text>",
                y + ROW_H / 2 + 4,
                crate::html::escape(&clip(&r.name, 44))
            );
            for (j, c) in r.cells.iter().enumerate() {
                let x = LABEL_W + CELL_W * j;
                let (fill, opacity) = match c {
                    TargetVerdict::Contest(k) if k.decisive => (hex(&k.faster), "0.85"),
                    TargetVerdict::Contest(_) => ("#cccccc".to_string(), "1"),
                    TargetVerdict::Alone { backend, .. } => (hex(backend), "0.3"),
                    TargetVerdict::Nobody => ("#ffffff".to_string(), "1"),
                };
                let _ = write!(
                    s,
                    "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"{fill}\" fill-opacity=\"{opacity}\" stroke=\"#ffffff\" stroke-width=\"2\"/>",
                    x, y, CELL_W, ROW_H
                );
                let (text, color) = match c {
                    TargetVerdict::Contest(k) if k.decisive => {
                        (format!("{} {:.2}x", k.faster, k.ratio), "#ffffff")
                    }
                    TargetVerdict::Contest(k) => (
                        format!("no clear winner ({:.2}x)", k.ratio),
                        "rgb(34,34,34)",
                    ),
                    TargetVerdict::Alone { backend, .. } => {
                        (format!("{backend} alone"), "rgb(34,34,34)")
                    }
                    TargetVerdict::Nobody => ("none reaches it".to_string(), "rgb(136,136,136)"),
                };
                let _ = write!(
                    s,
                    "<text x=\"{}\" y=\"{}\" font-size=\"12\" text-anchor=\"middle\" fill=\"{color}\">{}</text>",
                    x + CELL_W / 2,
                    y + ROW_H / 2 + 4,
                    crate::html::escape(&text)
                );
            }
        }
        let _ = write!(
            s,
            "<text x=\"8\" y=\"{}\" font-size=\"11\" fill=\"rgb(68,68,68)\">ratio: runner-up's time / winner's, each backend's fastest configuration reaching the target; faint: one backend alone reaches it</text>",
            HEAD_H + ROW_H * self.rows.len() + 22
        );
        s.push_str("</svg>\n");
        s
    }
}

/// `text` cut to `max` characters with an ellipsis.
fn clip(text: &str, max: usize) -> String {
    if text.chars().count() <= max {
        text.to_string()
    } else {
        let mut t: String = text.chars().take(max.saturating_sub(1)).collect();
        t.push('…');
        t
    }
}

/// A backend's plot colour as `#rrggbb`.
fn hex(backend: &str) -> String {
    let c = crate::report::color_of(backend);
    format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::results::tests_support::{results, row};

    #[test]
    fn the_chart_names_a_winner_only_at_matched_accuracy() {
        let res = results(vec![
            row("sdf", "a", 10.0, Some(52.0), 100),
            row("mesh", "b", 2.0, Some(24.0), 100),
            row("mesh", "c", 5.0, Some(41.0), 100),
        ]);
        let chart = DecisionChart::of_run(&res);
        assert_eq!(chart.rows.len(), 1);
        let md = chart.markdown();
        assert!(md.contains("| >= 30 dB | >= 40 dB | >= 50 dB |"), "{md}");
        assert!(md.contains("**mesh** 2.00x (medians)"), "{md}");
        assert!(md.contains("| **sdf** alone |"), "{md}");
        let term = chart.terminal();
        assert!(term.contains(">=50 dB: sdf alone"), "{term}");
        assert!(term.contains("[wall time]"), "{term}");
        let svg = chart.svg();
        assert!(
            svg.contains("mesh 2.00x") && svg.contains("sdf alone"),
            "{svg}"
        );
        assert!(crate::html::svg_is_plain(&svg), "{svg}");
    }

    #[test]
    fn settings_without_accuracy_are_left_out() {
        let res = results(vec![row("sdf", "a", 10.0, None, 100)]);
        assert!(DecisionChart::of_run(&res).is_empty());
    }
}
