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
//!
//! `model` holds the points, duels and sections the claims are made from, `axes` finds each
//! axis and writes its section; this file assembles the document.

use std::fmt::Write as _;
use std::path::Path;

use crate::results::{Results, Row};
use crate::verdicts::{Clock, HEADLINE_MIN_PSNR_DB, Timing, headlines};

mod axes;
mod model;

use axes::{quality_axes, scene_axis, setting_axis};
use model::{Point, Section, distinct, link, newest_points};

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

/// The findings document for `runs` and the number of plots written into `plots_dir` (linked
/// as `plots_link/NAME.svg`; created, or reused only if it is a real folder, never a symbolic
/// link). Its anchor section lists the anchors the runs recorded and `more_anchors` (which
/// replace a run's copy of the same anchor run), by tool and date.
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
    // How far each backend is from its field's best. An anchor file given here is read as this
    // version reads it (a run may have recorded the same file before the reader gave every
    // figure, such as the sdf backend's cost per step), so it stands for the run's copy of the
    // same run of the anchor (same tool, file name and date: the run may have been given
    // another path to it); listed by tool, then date.
    let mut anchors: Vec<crate::anchors::Anchor> = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for a in more_anchors
        .iter()
        .chain(runs.iter().flat_map(|r| &r.results.anchors))
    {
        let name = Path::new(&a.file)
            .file_name()
            .map_or_else(|| a.file.clone(), |n| n.to_string_lossy().into_owned());
        if seen.insert((a.tool.clone(), name, a.date_utc.clone())) {
            anchors.push(a.clone());
        }
    }
    anchors.sort_by(|a, b| (&a.tool, &a.date_utc).cmp(&(&b.tool, &b.date_utc)));
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
    use super::model::Duel;
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
