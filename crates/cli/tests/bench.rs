//! `marchmesh bench --suite smoke` end to end: CSV and JSON parse back with every column
//! filled, `report` regenerates identical tables, `compare` matches every configuration.

use std::path::{Path, PathBuf};
use std::process::Command;

use marchmesh_harness::results::{self, Results};

fn marchmesh(args: &[&str], cwd: &Path) -> (bool, String, String) {
    marchmesh_testkit::run_program(env!("CARGO_BIN_EXE_marchmesh"), args, cwd)
}

fn repo() -> PathBuf {
    marchmesh_testkit::repo_root()
}

fn tmp(name: &str) -> PathBuf {
    marchmesh_testkit::temp_dir(&format!("cli-{name}"))
}

fn only_run(out: &Path) -> PathBuf {
    let runs: Vec<PathBuf> = std::fs::read_dir(out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(runs.len(), 1, "{runs:?}");
    runs[0].clone()
}

#[test]
fn smoke_suite_writes_complete_results_and_report_reproduces_them() {
    let out = tmp("smoke");
    let out_s = out.to_str().unwrap();
    let anchor = "bench-results/anchors/fidget-20261123T231703Z.json";
    let (ok, stdout, stderr) = marchmesh(
        &[
            "bench",
            "--suite",
            "smoke",
            "--results-dir",
            out_s,
            "--anchor",
            anchor,
        ],
        &repo(),
    );
    assert!(ok, "bench failed:\n{stdout}\n{stderr}");
    let run = only_run(&out);
    // The terminal gives the answer: a verdict per scene at each accuracy target, then
    // where the report is.
    assert!(stdout.contains("answer: the fastest backend"), "{stdout}");
    assert!(
        stdout.contains(">=30 dB: ") && stdout.contains(">=50 dB: "),
        "{stdout}"
    );
    assert!(
        stdout.contains(&format!("report: {}", run.join("report.html").display())),
        "{stdout}"
    );
    let name = run.file_name().unwrap().to_string_lossy().into_owned();
    assert!(name.ends_with("-smoke"), "{name}");

    // JSON: every configuration measured, provenance filled.
    let res = Results::read_json(&run.join("results.json")).unwrap();
    assert!(res.failures.is_empty(), "{:?}", res.failures);
    assert!(!res.interrupted);
    let scenes = std::fs::read_dir(repo().join("scenes"))
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "json")
        })
        .count();
    assert_eq!(
        res.rows.len(),
        2 * scenes,
        "sdf and mesh for every committed scene"
    );
    let p = &res.provenance;
    for (what, v) in [
        ("date", &p.date_utc),
        ("cpu", &p.cpu_model),
        ("rustc", &p.rustc),
        ("target", &p.target),
        ("commit", &p.git_commit),
        ("command", &p.command),
    ] {
        assert!(!v.is_empty() && v != "unknown", "{what} = {v:?}");
    }
    assert!(p.logical_cores >= 1);

    // The anchor is recorded and shown.
    assert_eq!(res.anchors.len(), 1);
    assert_eq!(res.anchors[0].backend, "sdf");
    let summary = std::fs::read_to_string(run.join("summary.md")).unwrap();
    assert!(
        summary.contains("## Each backend against its anchor") && summary.contains(anchor),
        "{summary}"
    );

    // Scene paths are recorded from the scenes folder on, not as this machine's path.
    for r in &res.rows {
        assert!(r.scene_file.starts_with("scenes/"), "{}", r.scene_file);
    }
    // The summary opens with the answer, the method after it.
    let answer = summary.find("## Answer").expect("an answer section");
    assert!(answer < summary.find("## Method").unwrap(), "{summary}");

    // CSV: same rows, every column filled unless the row says why it may be empty.
    let csv_rows = results::read_csv(&run.join("results.csv")).unwrap();
    assert_eq!(csv_rows.len(), res.rows.len());
    let text = std::fs::read_to_string(run.join("results.csv")).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    assert_eq!(header, results::csv_header());
    for (row, line) in csv_rows.iter().zip(text.lines().skip(1)) {
        assert_eq!(
            row.config_id,
            res.rows
                .iter()
                .find(|r| r.config_id == row.config_id)
                .unwrap()
                .config_id
        );
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells.len(), header.len(), "{line}");
        for (col, cell) in header.iter().zip(&cells) {
            if cell.is_empty() {
                assert!(
                    row.why_empty(col).is_some(),
                    "{}: column {col} is empty",
                    row.config_id
                );
            }
        }
        // The reference exists, so accuracy is always measured.
        assert!(
            row.psnr_db.is_some() && row.silhouette_mismatch_pct.is_some(),
            "{}",
            row.config_id
        );
        assert!(row.render_ms_median > 0.0 && row.mrays_per_s > 0.0);
        assert!(row.peak_heap_bytes_build.is_some() && row.peak_heap_bytes_render.is_some());
        assert_eq!(row.non_finite_count, 0, "{}", row.config_id);
        if row.backend == "mesh" {
            assert!(row.triangles.unwrap() > 0 && row.node_visits_per_ray > 0.0);
        } else {
            assert!(row.steps_mean > 0.0);
        }
    }
    assert!(run.join("images").read_dir().unwrap().count() >= 3 * res.rows.len() / 2);
    assert!(run.join("plots").read_dir().unwrap().count() >= scenes);

    // report regenerates identical tables, plots and report.html.
    let summary = std::fs::read_to_string(run.join("summary.md")).unwrap();
    assert!(summary.contains("Pareto front") && summary.contains("render ms median"));
    let plot = std::fs::read_dir(run.join("plots"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let plot_before = std::fs::read(&plot).unwrap();
    let html = std::fs::read_to_string(run.join("report.html")).unwrap();
    assert!(html.contains("render ms median") && html.contains("<svg"));
    std::fs::remove_file(run.join("report.html")).unwrap();
    std::fs::remove_file(run.join("summary.md")).unwrap();
    std::fs::remove_dir_all(run.join("plots")).unwrap();
    let (ok, stdout, stderr) = marchmesh(&["report", run.to_str().unwrap()], &repo());
    assert!(ok, "report failed:\n{stdout}\n{stderr}");
    assert_eq!(
        std::fs::read_to_string(run.join("summary.md")).unwrap(),
        summary
    );
    assert_eq!(std::fs::read(&plot).unwrap(), plot_before);
    assert_eq!(
        std::fs::read_to_string(run.join("report.html")).unwrap(),
        html
    );

    // compare a run with itself: every configuration matched at ratio 1.
    let (ok, stdout, stderr) = marchmesh(
        &["compare", run.to_str().unwrap(), run.to_str().unwrap()],
        &repo(),
    );
    assert!(ok, "compare failed:\n{stdout}\n{stderr}");
    assert!(
        stdout.contains(&format!(
            "{} configurations matched (geometric mean render ratio 1.000x)",
            res.rows.len()
        )),
        "{stdout}"
    );
    assert!(!stdout.contains("compare machines"), "{stdout}");
    // A run from another CPU: compare says its ratios compare machines too.
    let mut elsewhere = res.clone();
    elsewhere.provenance.cpu_model = "Another CPU".into();
    elsewhere.provenance.machine = "node-b".into();
    let other = out.join("elsewhere");
    std::fs::create_dir_all(&other).unwrap();
    elsewhere.write_json(&other.join("results.json")).unwrap();
    let (ok, stdout, stderr) = marchmesh(
        &["compare", run.to_str().unwrap(), other.to_str().unwrap()],
        &repo(),
    );
    assert!(ok, "compare failed:\n{stdout}\n{stderr}");
    assert!(
        stdout.contains("B on node-b (Another CPU): the ratios compare machines as well as builds"),
        "{stdout}"
    );
    std::fs::remove_dir_all(&other).ok();

    // A second run never overwrites the first.
    let (ok, _, stderr) = marchmesh(
        &[
            "bench",
            "--suite",
            "smoke",
            "--out",
            out_s,
            "--filter",
            "*/csg/sdf*",
            "--quick",
        ],
        &repo(),
    );
    assert!(ok, "{stderr}");
    let runs = std::fs::read_dir(&out).unwrap().count();
    assert_eq!(runs, 2);
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn bad_suites_and_filters_are_clear_errors() {
    let dir = tmp("bad");
    let suite = dir.join("bad.json");
    std::fs::write(
        &suite,
        r#"{"groups": [{"name": "g", "scenes": ["x.json"], "backends": [{"backend": "sdf"}]}]}"#,
    )
    .unwrap();
    let (ok, _, stderr) = marchmesh(&["bench", "--suite", suite.to_str().unwrap()], &dir);
    assert!(!ok);
    assert!(
        stderr.contains("bad.json") && stderr.contains("groups[0].scenes[0]"),
        "{stderr}"
    );
    let (ok, _, stderr) = marchmesh(
        &[
            "bench",
            "--suite",
            "smoke",
            "--filter",
            "nothing-matches-this",
            "--out",
            dir.to_str().unwrap(),
        ],
        &repo(),
    );
    assert!(!ok);
    assert!(stderr.contains("no configuration"), "{stderr}");
    // An unknown suite name lists the built-in suites, and says it once.
    let (ok, _, stderr) = marchmesh(&["bench", "--suite", "nosuch"], &dir);
    assert!(!ok);
    assert!(
        stderr.contains("no suite named \"nosuch\"") && stderr.contains("default, "),
        "{stderr}"
    );
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    let (ok, _, stderr) = marchmesh(&["report", dir.to_str().unwrap()], &dir);
    assert!(!ok && stderr.contains("results.json"), "{stderr}");
    // A bad anchor file fails before any run folder is made.
    let not_anchor = dir.join("not-an-anchor.json");
    std::fs::write(&not_anchor, r#"{"tool": "nothing"}"#).unwrap();
    let runs = dir.join("runs");
    let (ok, _, stderr) = marchmesh(
        &[
            "bench",
            "--suite",
            "smoke",
            "--out",
            runs.to_str().unwrap(),
            "--anchor",
            not_anchor.to_str().unwrap(),
        ],
        &repo(),
    );
    assert!(!ok && stderr.contains("not-an-anchor.json"), "{stderr}");
    assert!(
        !runs.exists(),
        "no run folder for a run that could not start"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn render_works_with_every_backend_and_rejects_unknown_options() {
    let dir = tmp("render");
    for b in ["sdf", "mesh", "reference"] {
        let out = dir.join(format!("{b}.png"));
        let (ok, stdout, stderr) = marchmesh(
            &[
                "render",
                "scenes/seed-spheres.json",
                "--backend",
                b,
                "--width",
                "24",
                "--height",
                "16",
                "--out",
                out.to_str().unwrap(),
            ],
            &repo(),
        );
        assert!(ok, "{b}: {stdout}{stderr}");
        assert!(out.is_file());
    }
    let (ok, _, stderr) = marchmesh(
        &[
            "render",
            "scenes/seed-spheres.json",
            "-b",
            "mesh",
            "-O",
            "tess=3",
            "--out",
            dir.join("x.png").to_str().unwrap(),
        ],
        &repo(),
    );
    assert!(
        !ok && stderr.contains("`mesh`")
            && stderr.contains("`tess`")
            && stderr.contains("tess_level"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[cfg(unix)]
#[test]
fn ctrl_c_keeps_the_finished_configurations() {
    let dir = tmp("ctrlc");
    let scene = repo().join("scenes/seed-spheres.json");
    let second = repo().join("scenes/csg.json");
    let suite = dir.join("slow.json");
    // Every configuration repeats for at least 30 s: only an interrupt ends the run early.
    // Two scenes: two rotation blocks, the second never starts.
    std::fs::write(
        &suite,
        format!(
            r#"{{"repeats": {{"min_count": 1, "min_time_s": 30, "max_count": 100000}}, "images": false,
                "groups": [{{"name": "g", "scenes": ["{}", "{}"], "resolutions": [{{"max_side": 16}}], "spp": 1,
                "threads": [1], "reference": false,
                "backends": [{{"backend": "sdf"}}, {{"backend": "mesh"}}, {{"backend": "sdf", "label": "b"}}]}}]}}"#,
            scene.display(),
            second.display()
        ),
    )
    .unwrap();
    let out = dir.join("out");
    let mut child = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args([
            "bench",
            "--suite",
            suite.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Stderr is a pipe, so progress comes as plain lines: wait for the first configuration to
    // start (the stop is checked before each configuration, so that one is measured).
    let stderr_pipe = child.stderr.take().unwrap();
    let (lines_tx, lines_rx) = std::sync::mpsc::channel::<String>();
    let reader = std::thread::spawn(move || {
        use std::io::BufRead as _;
        for line in std::io::BufReader::new(stderr_pipe).lines() {
            let Ok(line) = line else { break };
            if lines_tx.send(line).is_err() {
                break;
            }
        }
    });
    let mut seen = Vec::new();
    loop {
        let line = lines_rx
            .recv_timeout(std::time::Duration::from_secs(120))
            .unwrap_or_else(|_| panic!("the first configuration never started: {seen:?}"));
        let first = line.starts_with("bench: [1/6] ");
        seen.push(line);
        if first {
            break;
        }
    }
    assert!(
        out.is_dir(),
        "the run folder appears before measuring starts"
    );
    std::thread::sleep(std::time::Duration::from_millis(200));
    let interrupted_at = std::time::Instant::now();
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let output = child.wait_with_output().unwrap();
    reader.join().unwrap();
    seen.extend(lines_rx.try_iter());
    let stderr = seen.join("\n");
    // An interrupted run is not a success: scripts must not take it for a full run.
    assert!(!output.status.success(), "{stderr}");
    assert!(stderr.contains("interrupted: "), "{stderr}");
    assert!(
        interrupted_at.elapsed().as_secs() < 30,
        "the interrupt did not stop the repeats"
    );
    let run = only_run(&out);
    let res = Results::read_json(&run.join("results.json")).unwrap();
    assert!(res.interrupted);
    // The configurations of the first block built before the interrupt finish their round
    // in progress (one repeat each); the second block never starts and is listed as missing.
    assert!(!res.rows.is_empty());
    assert_eq!(res.rows.len() + res.missing.len(), 6, "{:?}", res.missing);
    assert!(
        res.rows
            .iter()
            .all(|r| r.render_repeats >= 1 && r.scene == "seed-spheres")
    );
    assert!(
        res.missing.iter().filter(|m| m.contains("/csg/")).count() == 3,
        "{:?}",
        res.missing
    );
    assert_eq!(
        results::read_csv(&run.join("results.csv")).unwrap().len(),
        res.rows.len()
    );
    let summary = std::fs::read_to_string(run.join("summary.md")).unwrap();
    assert!(summary.contains("interrupted") && summary.contains("missing (not measured"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn stability_runs_a_filtered_family_and_writes_its_report() {
    let dir = tmp("stability");
    let out = dir.join("run");
    let scenes = dir.join("scenes");
    let (ok, stdout, stderr) = marchmesh(
        &[
            "stability",
            "--filter",
            "scale/",
            "--side",
            "12",
            "--out",
            out.to_str().unwrap(),
            "--write-scenes",
            scenes.to_str().unwrap(),
        ],
        &repo(),
    );
    assert!(ok, "{stdout}{stderr}");
    for f in ["stability.csv", "stability.json", "summary.md"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    assert!(scenes.read_dir().unwrap().count() > 0);
    assert!(stdout.contains("rows"), "{stdout}");
    // A second run into the same folder is refused rather than overwriting it.
    let (ok, _, stderr) = marchmesh(
        &[
            "stability",
            "--filter",
            "scale/",
            "--side",
            "12",
            "--out",
            out.to_str().unwrap(),
        ],
        &repo(),
    );
    assert!(!ok && stderr.contains("not empty"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}
