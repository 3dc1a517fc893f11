//! Hostile input to the commands that read finished runs (`report`, `compare`, `merge`,
//! `findings`): nothing is written through a link or into a folder given as a file, absurd
//! numbers and oversized or special files are refused naming the file, incomplete runs make
//! the commands fail instead of passing silently, names cannot inject Markdown or spreadsheet
//! formulas, and a closed stdout ends them quietly.

use std::process::{Command, Stdio};

use marchmesh_harness::results::{Failure, Results};

mod support;
use support::{marchmesh, results, row, run_dir, stderr, tmp};

fn small_run() -> Results {
    results(vec![
        row("s", "sdf", "a", 2.0, Some(40.0)),
        row("s", "mesh", "b", 3.0, Some(45.0)),
    ])
}

#[test]
fn report_refuses_a_symlink_at_a_plot_and_leaves_its_target_alone() {
    let dir = tmp("report-plot-link");
    let run = run_dir(&dir, "run", &small_run());
    // The plot report writes for the scene, planted as a link to a file of the user's.
    std::fs::create_dir_all(run.join("plots")).unwrap();
    let victim = dir.join("victim.txt");
    std::fs::write(&victim, b"precious").unwrap();
    let plot = run.join("plots/time_vs_error_g_s.svg");
    std::os::unix::fs::symlink(&victim, &plot).unwrap();
    let o = marchmesh(&["report", run.to_str().unwrap()], &dir);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("time_vs_error_g_s.svg") && stderr(&o).contains("symbolic link"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
    assert!(
        std::fs::symlink_metadata(&plot)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    std::fs::remove_file(&plot).unwrap();
    let o = marchmesh(&["report", run.to_str().unwrap()], &dir);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read_to_string(&plot).unwrap().contains("<svg"));
}

#[test]
fn absurd_numbers_in_results_are_refused_naming_the_row() {
    let dir = tmp("report-absurd");
    let good = run_dir(&dir, "good", &small_run());
    for (name, value) in [("huge", 1e308), ("negative", -5.0)] {
        let mut res = small_run();
        res.rows[1].render_ms_median = value;
        let run = run_dir(&dir, name, &res);
        for args in [
            vec!["report", run.to_str().unwrap()],
            vec!["compare", good.to_str().unwrap(), run.to_str().unwrap()],
        ] {
            let o = marchmesh(&args, &dir);
            assert!(!o.status.success(), "{args:?}");
            let e = stderr(&o);
            assert!(
                e.contains("g/s/mesh:b/x1/t1") && e.contains("render_ms_median"),
                "{args:?}: {e}"
            );
        }
    }
    // A zero time has no ratio: compare says n/a instead of NaN or inf.
    let mut zero = small_run();
    zero.rows[0].render_ms_median = 0.0;
    let zero = run_dir(&dir, "zero", &zero);
    let o = marchmesh(
        &["compare", good.to_str().unwrap(), zero.to_str().unwrap()],
        &dir,
    );
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.contains("NaN") && !out.contains("inf"), "{out}");
    assert!(out.contains("n/a"), "{out}");
}

#[test]
fn steps_histograms_whose_counts_overflow_are_refused_not_summed() {
    // Counts near 2^64 made `report` panic adding them up (the sum overflowed).
    let dir = tmp("report-histogram");
    let good = run_dir(&dir, "good", &small_run());
    let id = small_run().rows[0].config_id.clone();
    for (name, bins) in [
        ("overflow", vec![u64::MAX; 3]),
        ("too-many-bins", vec![1; 1000]),
    ] {
        let mut res = small_run();
        res.steps_histograms.insert(id.clone(), bins);
        let run = run_dir(&dir, name, &res);
        std::fs::write(run.join("summary.md"), b"the user's summary").unwrap();
        let findings = dir.join(format!("{name}.md"));
        for args in [
            vec!["report", run.to_str().unwrap()],
            vec!["compare", good.to_str().unwrap(), run.to_str().unwrap()],
            vec![
                "findings",
                run.to_str().unwrap(),
                "--out",
                findings.to_str().unwrap(),
            ],
        ] {
            let o = marchmesh(&args, &dir);
            let e = stderr(&o);
            assert_eq!(o.status.code(), Some(1), "{args:?}: {e}");
            assert!(
                e.contains("results.json") && e.contains(&format!("steps_histograms.{id}")),
                "{args:?}: {e}"
            );
            assert!(!e.contains("panicked"), "{e}");
        }
        assert_eq!(
            std::fs::read(run.join("summary.md")).unwrap(),
            b"the user's summary"
        );
        assert!(!findings.exists());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn results_files_are_capped_and_special_files_refused_without_blocking() {
    let dir = tmp("report-special");
    let good = run_dir(&dir, "good", &small_run());
    // A FIFO as results.json: refused at once (opening it for reading would block).
    let fifo_run = dir.join("fifo");
    std::fs::create_dir_all(&fifo_run).unwrap();
    let fifo = fifo_run.join("results.json");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let o = marchmesh(&["report", fifo_run.to_str().unwrap()], &dir);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("not a regular file"), "{}", stderr(&o));
    // /dev/zero through a symlink: refused, not read.
    let zero_run = dir.join("zero");
    std::fs::create_dir_all(&zero_run).unwrap();
    std::os::unix::fs::symlink("/dev/zero", zero_run.join("results.json")).unwrap();
    let o = marchmesh(
        &[
            "compare",
            good.to_str().unwrap(),
            zero_run.to_str().unwrap(),
        ],
        &dir,
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("not a regular file"), "{}", stderr(&o));
    // The read cap applies to results.json, and a mistyped cap is an error.
    let o = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(["report", good.to_str().unwrap()])
        .env("MARCHMESH_MAX_READ_MIB", "abc")
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("MARCHMESH_MAX_READ_MIB"),
        "{}",
        stderr(&o)
    );
    let big = results(
        (0..3000)
            .map(|i| row(&format!("s{i}"), "sdf", "a", 1.0, None))
            .collect(),
    );
    let big = run_dir(&dir, "big", &big);
    assert!(std::fs::metadata(big.join("results.json")).unwrap().len() > 1 << 20);
    let o = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(["compare", good.to_str().unwrap(), big.to_str().unwrap()])
        .env("MARCHMESH_MAX_READ_MIB", "1")
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("larger than the read limit"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn merge_fails_on_missing_shards_and_incomplete_runs() {
    let dir = tmp("report-merge");
    let mut one = small_run();
    one.shard = Some("1/2".into());
    let one = run_dir(&dir, "one", &one);
    let out = dir.join("merged");
    let o = marchmesh(
        &[
            "merge",
            one.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &dir,
    );
    assert!(!o.status.success(), "merging shard 1 of 2 alone succeeded");
    assert!(stderr(&o).contains("2/2 not given"), "{}", stderr(&o));
    // The count of missing configurations cannot include the absent shard's: said so.
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("missing listed (more in the shards not given)"),
        "{stdout}"
    );
    // The merged folder is still written, and says what is missing.
    assert!(out.join("summary.md").exists());

    let mut killed = small_run();
    killed.interrupted = true;
    killed.missing = vec!["g/t/sdf:a/x1/t1".into()];
    killed.rows.truncate(1);
    killed.failures = vec![Failure {
        config_id: "g/s/mesh:b/x1/t1".into(),
        error: "boom".into(),
    }];
    let killed = run_dir(&dir, "killed", &killed);
    let out = dir.join("merged2");
    let o = marchmesh(
        &[
            "merge",
            killed.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &dir,
    );
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("missing: g/t/sdf:a/x1/t1"), "{e}");
    assert!(
        e.contains("interrupted") && e.contains("1 configurations failed"),
        "{e}"
    );
}

#[test]
fn findings_fail_on_incomplete_runs_and_mark_them_instead_of_linking() {
    let dir = tmp("report-findings");
    let good = run_dir(&dir, "good", &small_run());
    let mut killed = small_run();
    killed.interrupted = true;
    killed.missing = vec!["g/t/sdf:a/x1/t1".into()];
    let killed = run_dir(&dir, "killed", &killed);
    let out = dir.join("F.md");
    let o = marchmesh(
        &[
            "findings",
            good.to_str().unwrap(),
            killed.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &dir,
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("killed (1 missing"), "{}", stderr(&o));
    let doc = std::fs::read_to_string(&out).unwrap();
    assert!(!doc.contains("(killed/summary.md)"), "{doc}");
}

#[test]
fn findings_force_onto_a_folder_writes_nothing() {
    let dir = tmp("report-findings-folder");
    let good = run_dir(&dir, "good", &small_run());
    let out = dir.join("F.md");
    std::fs::create_dir_all(&out).unwrap();
    let o = marchmesh(
        &[
            "findings",
            good.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--force",
        ],
        &dir,
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("not a regular file"), "{}", stderr(&o));
    assert!(
        !dir.join("F-plots").exists(),
        "plots written before refusing"
    );
}

#[test]
fn names_cannot_inject_markdown_or_spreadsheet_formulas() {
    let dir = tmp("report-inject");
    let mut res = small_run();
    res.rows[0].quality = "=HYPERLINK(\"http://x\")|<img src=x onerror=alert(1)>\n# Owned".into();
    res.rows[0].config_id = format!("g/s/sdf:{}/x1/t1", res.rows[0].quality);
    res.rows[1].notes = "@SUM(A1)".into();
    let run = run_dir(&dir, "run", &res);
    let o = marchmesh(&["report", run.to_str().unwrap()], &dir);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary = std::fs::read_to_string(run.join("summary.md")).unwrap();
    assert!(!summary.contains("<img"), "{summary}");
    assert!(!summary.contains("\n# Owned"), "{summary}");
    assert!(summary.contains("\\|&lt;img"), "{summary}");
    // results.csv (written by bench and merge): formula cells are neutralised and read back.
    res.write_csv(&run.join("results.csv")).unwrap();
    let csv = std::fs::read_to_string(run.join("results.csv")).unwrap();
    assert!(
        !csv.contains(",=HYPERLINK") && !csv.contains("\"=HYPERLINK"),
        "{csv}"
    );
    assert!(csv.contains("'@SUM(A1)"), "{csv}");
    let back = marchmesh_harness::results::read_csv(&run.join("results.csv")).unwrap();
    assert_eq!(back[0].quality, res.rows[0].quality);
    assert_eq!(back[1].notes, "@SUM(A1)");
}

#[test]
fn a_closed_stdout_ends_report_compare_merge_and_findings_quietly() {
    let dir = tmp("report-pipe");
    let good = run_dir(&dir, "good", &small_run());
    let merged = dir.join("merged");
    let findings = dir.join("F.md");
    let cases: Vec<Vec<&str>> = vec![
        vec!["report", good.to_str().unwrap()],
        vec!["compare", good.to_str().unwrap(), good.to_str().unwrap()],
        vec![
            "merge",
            good.to_str().unwrap(),
            "--out",
            merged.to_str().unwrap(),
        ],
        vec![
            "findings",
            good.to_str().unwrap(),
            "--out",
            findings.to_str().unwrap(),
        ],
    ];
    for args in cases {
        let mut child = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
            .args(&args)
            .current_dir(&dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let o = child.wait_with_output().unwrap();
        let e = stderr(&o);
        assert!(!e.contains("panicked"), "{args:?}: {e}");
        assert_ne!(o.status.code(), Some(101), "{args:?}: {e}");
    }
}

#[test]
fn findings_refuse_a_symlinked_plots_folder_and_count_only_the_plots_written() {
    let dir = tmp("report-findings-plots-link");
    let good = run_dir(&dir, "good", &small_run());
    let precious = dir.join("precious");
    std::fs::create_dir_all(&precious).unwrap();
    std::fs::write(precious.join("logo.svg"), b"art").unwrap();
    std::os::unix::fs::symlink(&precious, dir.join("findings-plots")).unwrap();
    let out = dir.join("findings.md");
    let args = [
        "findings",
        "-o",
        out.to_str().unwrap(),
        good.to_str().unwrap(),
        "--force",
    ];
    let o = marchmesh(&args, &dir);
    let e = stderr(&o);
    assert!(!o.status.success(), "{e}");
    assert!(
        e.contains("findings-plots") && e.contains("symbolic link"),
        "{e}"
    );
    assert_eq!(std::fs::read(precious.join("logo.svg")).unwrap(), b"art");
    assert_eq!(std::fs::read_dir(&precious).unwrap().count(), 1);
    assert!(!out.exists(), "the document was written");
    // A real plots folder holding other files of the user's: they stay and are not counted.
    std::fs::remove_file(dir.join("findings-plots")).unwrap();
    let plots = dir.join("findings-plots");
    std::fs::create_dir_all(&plots).unwrap();
    std::fs::write(plots.join("notes.txt"), b"mine").unwrap();
    std::fs::write(plots.join("README.md"), b"mine").unwrap();
    let o = marchmesh(&args, &dir);
    assert!(o.status.success(), "{}", stderr(&o));
    let svgs = std::fs::read_dir(&plots)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".svg"))
        .count();
    let said = support::text(&o.stdout);
    assert!(said.contains(&format!("({svgs} plots in")), "{said}");
    assert_eq!(std::fs::read(plots.join("notes.txt")).unwrap(), b"mine");
}

#[test]
fn report_refuses_a_symlinked_or_file_plots_folder_and_writes_nothing() {
    let dir = tmp("report-plots-folder-link");
    let run = run_dir(&dir, "run", &small_run());
    let victim = dir.join("victim");
    std::fs::create_dir_all(&victim).unwrap();
    // A file of the user's with the name of a plot report writes for the run.
    std::fs::write(victim.join("time_vs_error_g_s.svg"), b"precious").unwrap();
    std::os::unix::fs::symlink(&victim, run.join("plots")).unwrap();
    let o = marchmesh(&["report", run.to_str().unwrap()], &dir);
    let e = stderr(&o);
    assert!(!o.status.success(), "{e}");
    assert!(e.contains("plots") && e.contains("symbolic link"), "{e}");
    assert_eq!(
        std::fs::read(victim.join("time_vs_error_g_s.svg")).unwrap(),
        b"precious"
    );
    assert_eq!(std::fs::read_dir(&victim).unwrap().count(), 1);
    assert!(!run.join("summary.md").exists() && !run.join("report.html").exists());
    // plots/ as a file: refused the same way, the file kept.
    std::fs::remove_file(run.join("plots")).unwrap();
    std::fs::write(run.join("plots"), b"a file").unwrap();
    let o = marchmesh(&["report", run.to_str().unwrap()], &dir);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("is a file"), "{}", stderr(&o));
    assert_eq!(std::fs::read(run.join("plots")).unwrap(), b"a file");
}

#[test]
fn results_with_a_repeated_configuration_are_refused_naming_the_file_and_id() {
    let dir = tmp("report-duplicate-rows");
    let good = run_dir(&dir, "good", &small_run());
    let mut res = small_run();
    let twin = res.rows[1].clone();
    res.rows.extend(std::iter::repeat_n(twin, 1000));
    let run = run_dir(&dir, "dup", &res);
    let findings = dir.join("F.md");
    let merged = dir.join("m");
    for args in [
        vec!["report", run.to_str().unwrap()],
        vec!["compare", good.to_str().unwrap(), run.to_str().unwrap()],
        vec![
            "findings",
            run.to_str().unwrap(),
            "-o",
            findings.to_str().unwrap(),
        ],
        vec![
            "merge",
            "-o",
            merged.to_str().unwrap(),
            run.to_str().unwrap(),
        ],
    ] {
        let o = marchmesh(&args, &dir);
        let e = stderr(&o);
        assert!(!o.status.success(), "{args:?}");
        assert!(
            e.contains("dup/results.json")
                && e.contains("g/s/mesh:b/x1/t1")
                && e.contains("more than one row")
                && !e.contains("shards must not overlap"),
            "{args:?}: {e}"
        );
    }
    assert!(!findings.exists() && !merged.exists());
    assert!(!run.join("summary.md").exists());
}

fn anchor(file: &str, ours: f64) -> marchmesh_harness::anchors::Anchor {
    marchmesh_harness::anchors::Anchor {
        tool: "embree".into(),
        version: "4".into(),
        backend: "mesh".into(),
        file: file.into(),
        date_utc: "2026-01-01T00:00:00Z".into(),
        load_average_start: "0".into(),
        load_average_end: "0".into(),
        entries: vec![marchmesh_harness::anchors::AnchorEntry {
            subject: "bunny.obj".into(),
            rays: "camera".into(),
            query: "closest hit".into(),
            tracer: "wide1".into(),
            peer: String::new(),
            unit: "Mrays/s".into(),
            ours,
            anchor: 2.0,
            ratio: ours / 2.0,
            ours_ns_per_step: None,
        }],
    }
}

#[test]
fn absurd_anchor_rates_in_results_are_refused_naming_the_entry() {
    let dir = tmp("report-anchor-values");
    let good = run_dir(&dir, "good", &small_run());
    for (name, ours) in [("huge", 1e308), ("negative", -1.0), ("zero", 0.0)] {
        let mut res = small_run();
        res.anchors = vec![anchor("a.json", ours)];
        let run = run_dir(&dir, name, &res);
        let findings = dir.join("F.md");
        for args in [
            vec!["report", run.to_str().unwrap()],
            vec!["compare", good.to_str().unwrap(), run.to_str().unwrap()],
            vec![
                "findings",
                run.to_str().unwrap(),
                "-o",
                findings.to_str().unwrap(),
            ],
        ] {
            let o = marchmesh(&args, &dir);
            let e = stderr(&o);
            assert_eq!(o.status.code(), Some(1), "{args:?}: {e}");
            assert!(
                e.contains("results.json") && e.contains("anchors[0].entries[0].ours"),
                "{args:?}: {e}"
            );
            // Shown short, not as its 309 digits.
            assert!(ours != 1e308 || e.contains("ours = 1e308"), "{e}");
        }
        assert!(!findings.exists() && !run.join("summary.md").exists());
    }
}

#[test]
fn thousands_of_anchors_and_skipped_scenes_are_merged_and_summarised_in_linear_time() {
    let dir = tmp("report-many-anchors");
    let mut a = small_run();
    a.rows.truncate(1);
    a.anchors = (0..20_000)
        .map(|i| anchor(&format!("{i}.json"), 1.0))
        .collect();
    a.skipped = (0..100_000)
        .map(|i| format!("scene {i}: skipped"))
        .collect();
    let mut b = small_run();
    b.rows.drain(..1);
    b.anchors = a.anchors.clone();
    b.skipped = a.skipped.clone();
    let a = run_dir(&dir, "a", &a);
    let b = run_dir(&dir, "b", &b);
    let merged = dir.join("m");
    let findings = dir.join("F.md");
    let start = std::time::Instant::now();
    for args in [
        vec![
            "merge",
            "-o",
            merged.to_str().unwrap(),
            a.to_str().unwrap(),
            b.to_str().unwrap(),
        ],
        vec![
            "findings",
            a.to_str().unwrap(),
            b.to_str().unwrap(),
            "-o",
            findings.to_str().unwrap(),
        ],
    ] {
        let o = marchmesh(&args, &dir);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    }
    // Comparing every anchor (and skipped scene) with every other took minutes at this count.
    assert!(
        start.elapsed() < std::time::Duration::from_secs(60),
        "{:?}",
        start.elapsed()
    );
    let m = Results::read_json(&merged.join("results.json")).unwrap();
    assert_eq!((m.anchors.len(), m.skipped.len()), (20_000, 100_000));
}

#[test]
fn report_beside_a_results_file_keeps_a_summary_and_page_it_did_not_write() {
    let dir = tmp("report-users-files");
    let folder = run_dir(&dir, "downloads", &small_run());
    for (file, mine) in [
        ("summary.md", &b"my own notes"[..]),
        ("report.html", &b"<html>my page</html>"[..]),
    ] {
        std::fs::write(folder.join(file), mine).unwrap();
        let o = marchmesh(
            &["report", folder.join("results.json").to_str().unwrap()],
            &dir,
        );
        let e = stderr(&o);
        assert!(!o.status.success(), "{e}");
        assert!(
            e.contains(file) && e.contains("not written by a marchmesh report"),
            "{e}"
        );
        assert_eq!(std::fs::read(folder.join(file)).unwrap(), mine);
        std::fs::remove_file(folder.join(file)).unwrap();
    }
    // The report's own files are regenerated, again and again.
    for _ in 0..2 {
        let o = marchmesh(&["report", folder.to_str().unwrap()], &dir);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    assert!(
        std::fs::read_to_string(folder.join("summary.md"))
            .unwrap()
            .starts_with("# Benchmark `")
    );
}

#[test]
fn results_whose_failures_repeat_a_row_or_each_other_are_refused_by_every_reader() {
    let dir = tmp("report-duplicate-failures");
    let good = run_dir(&dir, "good", &small_run());
    let failure = |id: &str| Failure {
        config_id: id.into(),
        error: "boom".into(),
    };
    let mut beside = small_run();
    beside.failures = vec![failure(&beside.rows[1].config_id.clone())];
    let beside = run_dir(&dir, "beside", &beside);
    let mut twice = small_run();
    twice.failures = vec![failure("g/s/sdf:z/x1/t1"), failure("g/s/sdf:z/x1/t1")];
    let twice = run_dir(&dir, "twice", &twice);
    for (run, id, reason) in [
        (
            &beside,
            "g/s/mesh:b/x1/t1",
            "listed as failed but has a row",
        ),
        (&twice, "g/s/sdf:z/x1/t1", "listed as failed twice"),
    ] {
        let findings = dir.join("F.md");
        let merged = dir.join("m");
        for args in [
            vec!["report", run.to_str().unwrap()],
            vec!["compare", good.to_str().unwrap(), run.to_str().unwrap()],
            vec![
                "findings",
                run.to_str().unwrap(),
                "-o",
                findings.to_str().unwrap(),
            ],
            vec![
                "merge",
                "-o",
                merged.to_str().unwrap(),
                run.to_str().unwrap(),
            ],
        ] {
            let o = marchmesh(&args, &dir);
            let e = stderr(&o);
            assert!(!o.status.success(), "{args:?}");
            assert!(
                e.contains("results.json")
                    && e.contains("failures[")
                    && e.contains(id)
                    && e.contains(reason)
                    && !e.contains("shards must not overlap"),
                "{args:?}: {e}"
            );
        }
        assert!(!findings.exists() && !merged.exists());
        assert!(!run.join("summary.md").exists());
    }
}

#[test]
fn results_listing_a_configuration_as_missing_twice_or_beside_its_row_are_refused() {
    let dir = tmp("report-duplicate-missing");
    let mut twice = small_run();
    twice.interrupted = true;
    twice.missing = vec!["zz".into(), "zz".into()];
    let twice = run_dir(&dir, "twice", &twice);
    let mut beside = small_run();
    beside.interrupted = true;
    beside.missing = vec![beside.rows[0].config_id.clone()];
    let beside = run_dir(&dir, "beside", &beside);
    for (run, reason) in [
        (&twice, "listed as missing twice"),
        (&beside, "listed as missing but has a row"),
    ] {
        let merged = dir.join("m");
        let o = marchmesh(
            &[
                "merge",
                "-o",
                merged.to_str().unwrap(),
                run.to_str().unwrap(),
            ],
            &dir,
        );
        let e = stderr(&o);
        assert!(!o.status.success(), "{e}");
        assert!(
            e.contains("results.json")
                && e.contains(reason)
                && e.contains("missing[")
                && !e.contains("configurations missing"),
            "{e}"
        );
        assert!(!merged.exists());
        let o = marchmesh(&["report", run.to_str().unwrap()], &dir);
        assert!(!o.status.success() && stderr(&o).contains(reason));
    }
}
