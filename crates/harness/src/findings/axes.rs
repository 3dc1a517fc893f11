//! The axes a situation varies along, each turned into a section with its plot: scene size
//! (copies or triangles), a setting (threads, image size), and quality levels (accuracy target
//! and memory budget).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::Run;
use super::model::{
    AxisValue, Duel, Plot, Point, Section, Step, crossover, distinct, duel, fastest_per_backend,
    machines_differ, run_links, sig, size_in_name, slug,
};
use crate::report::bytes;
use crate::results::Row;
use crate::verdicts::{HEADLINE_MIN_PSNR_DB, Timing, matched_accuracy};

/// A scene-size axis over the scenes of one suite group.
pub(super) fn scene_axis(
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
pub(super) fn setting_axis(
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
pub(super) fn quality_axes(
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
