//! The cluster path for real: `scripts/slurm_bench.sh` on a one-node Slurm
//! (`scripts/slurm_local.sh start`; CI starts it). The smoke suite as three shards, merged,
//! holds exactly the configurations of an unsharded run; a cancelled shard makes the merge
//! fail with the shard named, and `--rerun-failed` runs only it and completes the merge; a node
//! whose binary is not the submitted build refuses its shard before any work; a missing build
//! and a missing `sbatch` are clear errors. Paths carry spaces throughout.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use marchmesh_harness::results::Results;
use marchmesh_testkit::tools::{Tool, require, skip};

const BIN: &str = env!("CARGO_BIN_EXE_marchmesh");

fn script() -> PathBuf {
    marchmesh_testkit::repo_root().join("scripts/slurm_bench.sh")
}

fn text(o: &Output) -> String {
    format!(
        "status {}\nstdout:\n{}\nstderr:\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Runs `scripts/slurm_bench.sh args` with `bin` as the build.
fn submit(bin: &Path, args: &[&str]) -> Output {
    Command::new("bash")
        .arg(script())
        .args(args)
        .env("MARCHMESH_BIN", bin)
        .current_dir(marchmesh_testkit::repo_root())
        .output()
        .expect("run slurm_bench.sh")
}

/// The sorted configuration ids of a run folder.
fn configs(run: &Path) -> Vec<String> {
    let r = Results::read_json(&run.join("results.json"))
        .unwrap_or_else(|e| panic!("{}: {e}", run.display()));
    let mut v: Vec<String> = r.rows.iter().map(|r| r.config_id.clone()).collect();
    v.sort();
    v
}

/// The job id in a line `PREFIX <id>:` or `PREFIX <id> ` of the script's output.
fn job_id(out: &Output, prefix: &str) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout);
    stdout
        .lines()
        .find_map(|l| l.strip_prefix(prefix))
        .and_then(|rest| rest.split([':', ' ']).next())
        .map(str::to_owned)
        .unwrap_or_else(|| panic!("no '{prefix}' line:\n{}", text(out)))
}

/// Waits (at most 10 minutes) until Slurm no longer lists `job` as pending or running.
fn wait_gone(job: &str) {
    let start = Instant::now();
    loop {
        let out = Command::new("squeue")
            .args(["-h", "-j", job, "-o", "%T"])
            .output()
            .expect("squeue");
        let states = String::from_utf8_lossy(&out.stdout);
        if states.trim().is_empty() || !out.status.success() {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(600),
            "job {job} still {states} after 10 minutes"
        );
        std::thread::sleep(Duration::from_millis(500));
    }
}

/// Whether a Slurm controller answers with a usable node.
fn slurm_up() -> bool {
    Command::new("sinfo")
        .args(["-h", "-o", "%T"])
        .output()
        .is_ok_and(|o| {
            o.status.success()
                && String::from_utf8_lossy(&o.stdout)
                    .lines()
                    .any(|s| matches!(s.trim(), "idle" | "mixed" | "allocated" | "completing"))
        })
}

#[test]
fn slurm_shards_merge_into_the_unsharded_run_and_failures_rerun() {
    const TEST: &str = "slurm_shards_merge_into_the_unsharded_run_and_failures_rerun";
    if require(Tool::Slurm, TEST).is_none() {
        return;
    }
    if !slurm_up() {
        skip(
            Tool::Slurm,
            TEST,
            "no Slurm controller answers with a usable node (scripts/slurm_local.sh start)",
        );
        return;
    }
    let dir = marchmesh_testkit::temp_dir("slurm").join("with spaces");
    std::fs::create_dir_all(&dir).unwrap();

    // The unsharded run, for comparison.
    let whole = dir.join("whole run");
    let (ok, stdout, stderr) = marchmesh_testkit::run_program(
        BIN,
        &[
            "bench",
            "--suite",
            "smoke",
            "--out",
            whole.to_str().unwrap(),
        ],
        &marchmesh_testkit::repo_root(),
    );
    assert!(ok, "{stdout}\n{stderr}");
    let whole_run = std::fs::read_dir(&whole)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let expected = configs(&whole_run);
    assert!(expected.len() >= 3, "{expected:?}");

    // Three shards through Slurm, waited for: the merge holds exactly the same configurations.
    let out = dir.join("cluster out");
    let o = submit(
        Path::new(BIN),
        &["--wait", "smoke", "3", out.to_str().unwrap()],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(configs(&out.join("merged")), expected);
    for k in 1..=3 {
        assert!(out.join(format!("shards/{k}.ok")).is_file(), "shard {k}");
    }
    // A second submission into the same folder is refused (it would mix runs).
    let o = submit(Path::new(BIN), &["smoke", "3", out.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(text(&o).contains("--rerun-failed"), "{}", text(&o));

    // A cancelled shard: the merge fails naming it; --rerun-failed runs it alone and completes.
    // A blocker job holds the node so the shards are still pending when one is cancelled.
    let blocker = Command::new("sbatch")
        .args(["--parsable", "--exclusive", "--wrap", "sleep 300"])
        .args(["--output", "/dev/null"])
        .output()
        .expect("sbatch blocker");
    assert!(blocker.status.success(), "{}", text(&blocker));
    let blocker = String::from_utf8_lossy(&blocker.stdout).trim().to_owned();
    let out2 = dir.join("cancelled out");
    let o = submit(Path::new(BIN), &["smoke", "3", out2.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let array = job_id(&o, "array job ");
    let merge = job_id(&o, "merge job ");
    let cancel = Command::new("scancel")
        .arg(format!("{array}_2"))
        .status()
        .expect("scancel");
    assert!(cancel.success());
    Command::new("scancel").arg(&blocker).status().ok();
    wait_gone(&array);
    wait_gone(&merge);
    let log =
        std::fs::read_to_string(out2.join(format!("logs/merge-{merge}.log"))).expect("merge log");
    assert!(
        log.contains("shard(s) 2 of 3 did not finish") && log.contains("--rerun-failed"),
        "{log}"
    );
    assert!(!out2.join("shards/2.ok").exists());
    let o = submit(
        Path::new(BIN),
        &[
            "--wait",
            "--rerun-failed",
            "smoke",
            "3",
            out2.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("shards 2 of 3"), "{}", text(&o));
    assert_eq!(configs(&out2.join("merged")), expected);
    // The failed merge's folder, if it wrote one, was moved aside, not deleted.
    assert!(out2.join("attempts").is_dir());

    // A node whose binary is not the submitted build refuses the shard before any work.
    let copy = dir.join("copied build");
    std::fs::copy(BIN, &copy).unwrap();
    let blocker = Command::new("sbatch")
        .args(["--parsable", "--exclusive", "--wrap", "sleep 300"])
        .args(["--output", "/dev/null"])
        .output()
        .expect("sbatch blocker");
    let blocker = String::from_utf8_lossy(&blocker.stdout).trim().to_owned();
    let out3 = dir.join("mismatch out");
    let o = submit(&copy, &["smoke", "3", out3.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let (array, merge) = (job_id(&o, "array job "), job_id(&o, "merge job "));
    // Another build replaces the binary after submission.
    std::fs::write(&copy, b"#!/bin/sh\nexit 0\n").unwrap();
    Command::new("scancel").arg(&blocker).status().ok();
    wait_gone(&array);
    wait_gone(&merge);
    for k in 1..=3 {
        let failed = std::fs::read_to_string(out3.join(format!("shards/{k}.failed")))
            .unwrap_or_else(|e| panic!("shard {k} has no .failed: {e}"));
        assert!(
            failed.contains("not the build that was submitted"),
            "{failed}"
        );
        assert!(
            !out3.join(format!("shards/{k}")).exists(),
            "shard {k} did work"
        );
    }

    std::fs::remove_dir_all(dir.parent().unwrap()).ok();
}

/// Needs no Slurm: the script's refusals before it submits anything.
#[test]
fn slurm_script_refuses_a_missing_build_or_sbatch() {
    let dir = marchmesh_testkit::temp_dir("slurm-refusals");
    let out = dir.join("out");
    // No sbatch on PATH (nothing at all: the script must say so before it needs anything).
    // `bash` by its full path: a child's PATH also decides where its program is looked up.
    let bash = std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default())
        .map(|d| d.join("bash"))
        .find(|p| p.is_file())
        .expect("bash on PATH");
    let o = Command::new(&bash)
        .arg(script())
        .args(["smoke", "2", out.to_str().unwrap()])
        .env("PATH", "/usr/bin/nonexistent-only")
        .env("MARCHMESH_BIN", BIN)
        .output()
        .expect("run slurm_bench.sh");
    assert!(!o.status.success());
    assert!(text(&o).contains("sbatch is not on PATH"), "{}", text(&o));

    // A build that does not exist (checked before sbatch, so a fake sbatch that records calls
    // must never be called).
    let fake = dir.join("bin");
    std::fs::create_dir_all(&fake).unwrap();
    let called = dir.join("sbatch-called");
    std::fs::write(
        fake.join("sbatch"),
        format!("#!/bin/sh\ntouch '{}'\necho 1\n", called.display()),
    )
    .unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(fake.join("sbatch"), std::fs::Permissions::from_mode(0o755))
            .unwrap();
    }
    let path = format!(
        "{}:{}",
        fake.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let o = Command::new("bash")
        .arg(script())
        .args(["smoke", "2", out.to_str().unwrap()])
        .env("PATH", &path)
        .env("MARCHMESH_BIN", dir.join("no such build"))
        .output()
        .expect("run slurm_bench.sh");
    assert!(!o.status.success());
    assert!(text(&o).contains("is not built"), "{}", text(&o));
    assert!(!called.exists(), "sbatch was called for a missing build");

    // Bad shard counts.
    for bad in ["0", "-1", "x", "1000000"] {
        let o = Command::new("bash")
            .arg(script())
            .args(["smoke", bad, out.to_str().unwrap()])
            .env("PATH", &path)
            .env("MARCHMESH_BIN", BIN)
            .output()
            .expect("run slurm_bench.sh");
        assert!(!o.status.success(), "{bad}");
        assert!(text(&o).contains("SHARDS must be"), "{bad}: {}", text(&o));
    }
    assert!(!called.exists());
    std::fs::remove_dir_all(&dir).ok();
}
