//! Sharded runs: the smoke suite run as three shards by GNU parallel, merged, holds the same
//! configurations and the same accuracy columns as an unsharded run; `merge` refuses runs of
//! other suites or commits; a failing configuration makes `bench` exit nonzero.

use std::path::{Path, PathBuf};
use std::process::Command;

use marchmesh_harness::results::Results;

fn repo() -> PathBuf {
    marchmesh_testkit::repo_root()
}

fn tmp(name: &str) -> PathBuf {
    marchmesh_testkit::temp_dir(&format!("shard-{name}"))
}

fn marchmesh(args: &[&str]) -> (bool, String, String) {
    marchmesh_testkit::run_program(env!("CARGO_BIN_EXE_marchmesh"), args, &repo())
}

fn runs_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    v.sort();
    v
}

/// (config id, PSNR, silhouette %, depth p95, normal mean) of every row, sorted.
type AccuracyRow = (String, Option<f64>, Option<f64>, Option<f64>, Option<f64>);

fn accuracy(res: &Results) -> Vec<AccuracyRow> {
    let mut v: Vec<_> = res
        .rows
        .iter()
        .map(|r| {
            (
                r.config_id.clone(),
                r.psnr_db,
                r.silhouette_mismatch_pct,
                r.depth_err_p95,
                r.normal_err_deg_mean,
            )
        })
        .collect();
    v.sort_by(|a, b| a.0.cmp(&b.0));
    v
}

#[test]
fn gnu_parallel_shards_merge_into_the_unsharded_run() {
    use marchmesh_testkit::tools::{Tool, require};
    let Some(parallel) = require(
        Tool::GnuParallel,
        "gnu_parallel_shards_merge_into_the_unsharded_run",
    ) else {
        return;
    };
    let dir = tmp("parallel");
    let (whole, shards, merged) = (dir.join("whole"), dir.join("shards"), dir.join("merged"));
    let (ok, stdout, stderr) = marchmesh(&[
        "bench",
        "--suite",
        "smoke",
        "--out",
        whole.to_str().unwrap(),
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    // The documented one-liner (README "Beyond one machine").
    let status = Command::new(&parallel)
        .args([
            "--will-cite",
            "--halt",
            "now,fail=1",
            env!("CARGO_BIN_EXE_marchmesh"),
            "bench",
            "--suite",
            "smoke",
            "--shard",
            "{}/3",
            "--out",
            shards.to_str().unwrap(),
            ":::",
            "1",
            "2",
            "3",
        ])
        .current_dir(repo())
        .output()
        .expect("run parallel");
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let shard_runs = runs_in(&shards);
    assert_eq!(shard_runs.len(), 3, "{shard_runs:?}");
    let mut args = vec!["merge".to_string()];
    args.extend(shard_runs.iter().map(|p| p.display().to_string()));
    args.extend(["--out".into(), merged.display().to_string()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let (ok, stdout, stderr) = marchmesh(&args);
    assert!(ok, "{stdout}\n{stderr}");

    let whole = Results::read_json(&runs_in(&whole)[0].join("results.json")).unwrap();
    let merged = Results::read_json(&merged.join("results.json")).unwrap();
    assert!(!whole.rows.is_empty());
    assert_eq!(accuracy(&merged), accuracy(&whole));
    assert_eq!(merged.merged_from.len(), 3);
    let mut shard_names: Vec<_> = merged
        .merged_from
        .iter()
        .filter_map(|m| m.shard.clone())
        .collect();
    shard_names.sort();
    assert_eq!(shard_names, ["1/3", "2/3", "3/3"]);
    assert!(merged.missing.is_empty() && merged.failures.is_empty());
    // Each scene's reference was rendered once, in its shard.
    assert_eq!(merged.references.len(), whole.references.len());

    // Merging into a non-empty folder, or runs of different suites, is refused.
    let mut other = Results::read_json(&shard_runs[1].join("results.json")).unwrap();
    other.suite = "scaling".into();
    let other_dir = dir.join("other");
    std::fs::create_dir_all(&other_dir).unwrap();
    other.write_json(&other_dir.join("results.json")).unwrap();
    let fresh = dir.join("fresh");
    let (ok, _, stderr) = marchmesh(&[
        "merge",
        shard_runs[0].to_str().unwrap(),
        other_dir.to_str().unwrap(),
        "--out",
        fresh.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("ran suite \"smoke\"") && stderr.contains("\"scaling\""),
        "{stderr}"
    );
    assert!(!fresh.exists(), "a refused merge creates nothing");
    other.suite = "smoke".into();
    other.provenance.git_commit = "0000000000000000000000000000000000000000".into();
    other.write_json(&other_dir.join("results.json")).unwrap();
    let (ok, _, stderr) = marchmesh(&[
        "merge",
        shard_runs[0].to_str().unwrap(),
        other_dir.to_str().unwrap(),
        "--out",
        fresh.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(stderr.contains("only runs of one commit merge"), "{stderr}");
    let (ok, _, stderr) = marchmesh(&[
        "merge",
        shard_runs[0].to_str().unwrap(),
        "--out",
        shards.to_str().unwrap(),
    ]);
    assert!(!ok && stderr.contains("not empty"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_failing_configuration_makes_bench_exit_nonzero_and_is_listed() {
    let dir = tmp("failing");
    std::fs::copy(repo().join("scenes/csg.json"), dir.join("csg.json")).unwrap();
    // The second backend asks for more memory than the suite's build limit allows.
    std::fs::write(
        dir.join("suite.json"),
        r#"{"repeats": {"min_count": 1, "min_time_s": 0, "max_count": 1},
            "groups": [{"name": "g", "scenes": ["csg.json"], "resolutions": [{"max_side": 16}],
              "threads": [1],
              "backends": [{"backend": "sdf", "label": "ok"},
                           {"backend": "mesh", "label": "huge", "options": ["tess_px=1e-6"]}]}]}"#,
    )
    .unwrap();
    let out = dir.join("out");
    let (ok, stdout, stderr) = marchmesh(&[
        "bench",
        "--suite",
        dir.join("suite.json").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--memory-limit-mib",
        "64",
    ]);
    assert!(!ok, "{stdout}\n{stderr}");
    assert!(stderr.contains("1 of 2 configurations failed"), "{stderr}");
    let res = Results::read_json(&runs_in(&out)[0].join("results.json")).unwrap();
    assert_eq!(res.rows.len(), 1);
    assert_eq!(res.failures.len(), 1);
    assert!(res.failures[0].config_id.contains("mesh:huge"));
    assert!(res.missing.is_empty());
    std::fs::remove_dir_all(&dir).ok();
}
