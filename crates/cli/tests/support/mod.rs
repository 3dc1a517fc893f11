//! What the hostile tests (`tests/hostile_*.rs`) share: scratch folders, running the binary
//! and reading what it printed. Each test file uses a part of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use marchmesh_harness::results::{Provenance, Results, Row};

/// A fresh, empty scratch folder for one test: `name` starts with the test file's surface
/// (`bench-...`, `render-...`), so tests of different files never share one.
pub fn tmp(name: &str) -> PathBuf {
    marchmesh_testkit::temp_dir(&format!("hostile-{name}"))
}

/// The `marchmesh` binary run in `cwd`, not told where the repository is
/// (`MARCHMESH_ROOT` removed), so it finds its suites as an installed binary would.
pub fn command(cwd: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_marchmesh"));
    c.current_dir(cwd).env_remove("MARCHMESH_ROOT");
    c
}

/// Runs `marchmesh args...` in `cwd` ([`command`]) to completion.
pub fn marchmesh(args: &[&str], cwd: &Path) -> Output {
    command(cwd).args(args).output().expect("run marchmesh")
}

/// Bytes a command printed, as text.
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// What a command printed on stderr.
pub fn stderr(o: &Output) -> String {
    text(&o.stderr)
}

/// A measured row of configuration `g/{scene}/{backend}:{quality}/x1/t1`.
pub fn row(scene: &str, backend: &str, quality: &str, ms: f64, psnr: Option<f64>) -> Row {
    Row {
        config_id: format!("g/{scene}/{backend}:{quality}/x1/t1"),
        group: "g".into(),
        scene: scene.into(),
        backend: backend.into(),
        quality: quality.into(),
        width: 8,
        height: 8,
        threads: 1,
        render_repeats: 1,
        render_ms_median: ms,
        render_ms_min: ms,
        render_ms_max: ms,
        render_ms_ci_low: ms,
        render_ms_ci_high: ms,
        build_ms_total: 1.0,
        psnr_db: psnr,
        memory_bytes: 1024,
        ..Row::default()
    }
}

/// A finished run of `rows` (suite "suite", nothing missing).
pub fn results(rows: Vec<Row>) -> Results {
    let mut provenance = Provenance::collect("test".into());
    provenance.load_average_1m = Some(0.0);
    provenance.git_commit = "c0ffee".into();
    provenance.git_dirty = false;
    Results {
        run_id: "run".into(),
        suite: "suite".into(),
        suite_file: String::new(),
        description: String::new(),
        provenance,
        interrupted: false,
        rows,
        failures: Vec::new(),
        skipped: Vec::new(),
        references: Vec::new(),
        steps_histograms: Default::default(),
        timings: Default::default(),
        rotation_seed: Some(1),
        missing: Vec::new(),
        shard: None,
        merged_from: Vec::new(),
        write_errors: Vec::new(),
        anchors: Vec::new(),
    }
}

/// A run folder `dir/name` holding `res` as results.json.
pub fn run_dir(dir: &Path, name: &str, res: &Results) -> PathBuf {
    let run = dir.join(name);
    std::fs::create_dir_all(&run).unwrap();
    res.write_json(&run.join("results.json")).unwrap();
    run
}
