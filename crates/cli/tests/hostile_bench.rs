//! Hostile input to `bench` and `stability`: suite files that collide ids, expand without
//! bound, are special files or the wrong JSON shape are refused at load naming the file and
//! field; shard counts are checked before use; a full disk leaves no partial image or
//! generated folder; the built-in scenes come from a private, verified cache.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

mod support;
use support::{marchmesh, results, row, run_dir, stderr, tmp};

fn repo() -> PathBuf {
    marchmesh_testkit::repo_root()
        .canonicalize()
        .expect("repository root")
}

/// A suite file `dir/name` with one group made of `group_body` (JSON members).
fn suite(dir: &Path, name: &str, group_body: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(
        &p,
        format!(
            r#"{{"repeats": {{"min_count": 1, "min_time_s": 0, "max_count": 1}},
                "groups": [{{"name": "g", {group_body}}}]}}"#
        ),
    )
    .unwrap();
    p
}

fn csg() -> String {
    repo().join("scenes/csg.json").display().to_string()
}

#[test]
fn labels_whose_file_names_collide_are_refused_at_load() {
    let dir = tmp("bench-labels");
    let s = suite(
        &dir,
        "s.json",
        &format!(
            r#""scenes": ["{}"], "threads": [1], "backends": [
                {{"backend": "sdf", "label": "q a"}}, {{"backend": "sdf", "label": "q_a"}}]"#,
            csg()
        ),
    );
    let o = marchmesh(&["bench", "--suite", s.to_str().unwrap(), "--list"], &dir);
    assert!(
        !o.status.success(),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let e = stderr(&o);
    assert!(
        e.contains("s.json") && e.contains("q a") && e.contains("q_a") && e.contains("groups[0]"),
        "{e}"
    );
    // The same label twice is a collision too.
    let s = suite(
        &dir,
        "t.json",
        &format!(
            r#""scenes": ["{}"], "threads": [1], "backends": [
                {{"backend": "sdf", "label": "q"}}, {{"backend": "sdf", "label": "q", "options": ["eps_px=2"]}}]"#,
            csg()
        ),
    );
    let o = marchmesh(&["bench", "--suite", s.to_str().unwrap(), "--list"], &dir);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("distinct `label`"), "{}", stderr(&o));
}

#[test]
fn two_scenes_of_one_file_name_in_different_folders_are_refused_at_load() {
    let dir = tmp("bench-scenes");
    for sub in ["a", "b"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
        std::fs::copy(repo().join("scenes/csg.json"), dir.join(sub).join("x.json")).unwrap();
    }
    let s = suite(
        &dir,
        "s.json",
        r#""scenes": ["a/x.json", "b/x.json"], "threads": [1], "backends": [{"backend": "sdf"}]"#,
    );
    let o = marchmesh(&["bench", "--suite", s.to_str().unwrap(), "--list"], &dir);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("stands for both") && e.contains("`name`"), "{e}");
}

#[test]
fn shard_counts_beyond_the_configurations_are_refused_not_allocated() {
    let dir = tmp("bench-shard");
    for shard in ["1/1000000000000", "1/18446744073709551615", "1/3"] {
        let o = marchmesh(
            &[
                "bench", "--suite", "smoke", "--filter", "csg/sdf", "--shard", shard, "--list",
            ],
            &repo(),
        );
        assert!(!o.status.success(), "{shard}");
        let e = stderr(&o);
        assert!(
            e.contains("configurations") && !e.contains("panicked"),
            "{shard}: {e}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn shard_counts_beyond_the_scenes_and_empty_listings_are_refused() {
    let dir = tmp("bench-shard-scenes");
    // The csg scene's two configurations are one unit: a second shard would be empty.
    for extra in [&["--list"][..], &["--out", dir.to_str().unwrap()][..]] {
        let mut args = vec![
            "bench", "--suite", "smoke", "--filter", "/csg/", "--shard", "2/2",
        ];
        args.extend_from_slice(extra);
        let o = marchmesh(&args, &repo());
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{extra:?}: {e}");
        assert!(e.contains("at most 1"), "{extra:?}: {e}");
        assert!(o.stdout.is_empty(), "{extra:?}");
    }
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "a run folder");
    // A filter that matches nothing fails the listing as it fails the run.
    let o = marchmesh(
        &[
            "bench", "--suite", "smoke", "--filter", "nothing*", "--list",
        ],
        &repo(),
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("nothing*"), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn long_group_and_scene_names_still_give_file_names_that_fit() {
    let dir = tmp("bench-long-names");
    let (group, scene) = ("g".repeat(130), "s".repeat(130));
    let s = dir.join("long.json");
    std::fs::write(
        &s,
        format!(
            r#"{{"repeats": {{"min_count": 1, "min_time_s": 0, "max_count": 1}},
                "groups": [{{"name": "{group}", "scenes": [{{"path": "{}", "name": "{scene}"}}],
                    "resolutions": [{{"max_side": 16}}], "spp": 1, "threads": [1],
                    "backends": [{{"backend": "sdf", "label": "q", "options": ["max_steps=64"]}}]}}]}}"#,
            csg()
        ),
    )
    .unwrap();
    let runs = dir.join("runs");
    let o = marchmesh(
        &[
            "bench",
            "--suite",
            s.to_str().unwrap(),
            "--out",
            runs.to_str().unwrap(),
        ],
        &dir,
    );
    let said = support::text(&o.stdout);
    assert!(o.status.success(), "{said}{}", stderr(&o));
    let run = std::fs::read_dir(&runs)
        .unwrap()
        .flatten()
        .next()
        .unwrap()
        .path();
    assert!(run.join("report.html").exists(), "{said}");
    let names: Vec<String> = ["images", "plots"]
        .iter()
        .flat_map(|f| std::fs::read_dir(run.join(f)).unwrap().flatten())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().any(|n| n.ends_with(".diff.png")), "{names:?}");
    assert!(names.iter().any(|n| n.ends_with(".svg")), "{names:?}");
    assert!(names.iter().all(|n| n.len() <= 255), "{names:?}");
    let o = marchmesh(&["report", run.to_str().unwrap()], &dir);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn suites_expanding_beyond_the_maximum_are_refused_at_load() {
    let dir = tmp("bench-expand");
    let resolutions: Vec<String> = (1..=400)
        .map(|k| format!(r#"{{"width": {k}, "height": {k}}}"#))
        .collect();
    let backends: Vec<String> = (0..300)
        .map(|k| format!(r#"{{"backend": "sdf", "label": "l{k}"}}"#))
        .collect();
    let s = suite(
        &dir,
        "big.json",
        &format!(
            r#""scenes": ["{}"], "threads": [1], "resolutions": [{}], "backends": [{}]"#,
            csg(),
            resolutions.join(","),
            backends.join(",")
        ),
    );
    let o = marchmesh(&["bench", "--suite", s.to_str().unwrap(), "--list"], &dir);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("more than 100000 configurations"),
        "{}",
        stderr(&o)
    );
    assert!(o.stdout.is_empty());
}

/// Runs marchmesh with `args` and fails the test if it has not exited within 20 s (a read
/// that blocks on a FIFO would hang forever).
fn within_seconds(args: &[&str], cwd: &Path) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(args)
        .current_dir(cwd)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(20) {
            child.kill().ok();
            panic!("marchmesh {args:?} blocked");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

#[test]
fn fifos_and_devices_as_suites_scenes_and_anchors_are_refused_without_blocking() {
    let dir = tmp("bench-fifo");
    let fifo = dir.join("f.json");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let f = fifo.to_str().unwrap();
    for args in [
        vec!["bench", "--suite", f, "--list"],
        vec!["bench", "--suite", "/dev/zero", "--list"],
        vec!["validate", f],
        vec!["render", f, "--out", "x.png"],
        vec![
            "bench",
            "--suite",
            "smoke",
            "--filter",
            "csg/sdf",
            "--anchor",
            f,
            "--out",
            dir.to_str().unwrap(),
        ],
    ] {
        let cwd = if args.contains(&"smoke") {
            repo()
        } else {
            dir.clone()
        };
        let o = within_seconds(&args, &cwd);
        assert!(!o.status.success(), "{args:?}");
        assert!(
            stderr(&o).contains("not a regular file"),
            "{args:?}: {}",
            stderr(&o)
        );
    }
    // A suite whose scene is a folder says so.
    std::fs::create_dir_all(dir.join("folder.json")).unwrap();
    let s = suite(
        &dir,
        "s.json",
        r#""scenes": ["folder.json"], "backends": [{"backend": "sdf"}]"#,
    );
    let o = marchmesh(&["bench", "--suite", s.to_str().unwrap(), "--list"], &dir);
    assert!(stderr(&o).contains("is a folder"), "{}", stderr(&o));
}

#[test]
fn suite_files_must_use_objects_where_the_format_has_objects() {
    let dir = tmp("bench-arrays");
    let s = dir.join("a.json");
    std::fs::write(&s, r#"["x", "", {}, false, [{"name": "g"}]]"#).unwrap();
    let o = marchmesh(&["bench", "--suite", s.to_str().unwrap(), "--list"], &dir);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("expected a JSON object, found an array"),
        "{}",
        stderr(&o)
    );
    let s = suite(
        &dir,
        "b.json",
        &format!(
            r#""scenes": ["{}"], "resolutions": [[8, 8]], "backends": [{{"backend": "sdf"}}]"#,
            csg()
        ),
    );
    let o = marchmesh(&["bench", "--suite", s.to_str().unwrap(), "--list"], &dir);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("groups[0].resolutions[0]"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_full_disk_leaves_no_partial_image_and_lists_the_failed_writes() {
    let dir = tmp("bench-full");
    let s = suite(
        &dir,
        "s.json",
        &format!(
            r#""scenes": ["{}"], "threads": [1], "resolutions": [{{"width": 256, "height": 256}}],
               "backends": [{{"backend": "sdf"}}]"#,
            repo().join("scenes/seed-spheres.json").display()
        ),
    );
    // Files over 24 KiB cannot be written (as on a full disk): results.json fits, the
    // 256x256 images do not.
    let o = Command::new("bash")
        .arg("-c")
        .arg(format!(
            "trap '' XFSZ; ulimit -f 24; exec '{}' bench --suite '{}' --out '{}'",
            env!("CARGO_BIN_EXE_marchmesh"),
            s.display(),
            dir.join("out").display()
        ))
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(!o.status.success(), "{}", stderr(&o));
    let run = std::fs::read_dir(dir.join("out"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let mut leftovers = Vec::new();
    for e in std::fs::read_dir(run.join("images")).unwrap() {
        let p = e.unwrap().path();
        let bytes = std::fs::read(&p).unwrap();
        // Every image present is complete (a PNG ends with its IEND chunk).
        if !bytes.ends_with(&[0xAE, 0x42, 0x60, 0x82]) {
            leftovers.push(p);
        }
    }
    assert!(leftovers.is_empty(), "partial files: {leftovers:?}");
    let res = marchmesh_harness::results::Results::read_json(&run.join("results.json")).unwrap();
    assert!(
        res.write_errors.iter().any(|e| e.contains(".png")),
        "{:?}",
        res.write_errors
    );
    assert!(
        stderr(&o).contains("could not be written"),
        "{}",
        stderr(&o)
    );
    // The plots do not fit either, so there is no report, and stdout does not claim one.
    assert!(!run.join("report.html").exists());
    let said = support::text(&o.stdout);
    assert!(
        said.contains("the report was not written") && !said.contains("report.html"),
        "{said}"
    );
}

#[test]
fn stability_leaves_no_partial_generated_folder_and_bounds_its_images() {
    let dir = tmp("bench-stability");
    let out = dir.join("st");
    let o = Command::new("bash")
        .arg("-c")
        .arg(format!(
            "trap '' XFSZ; ulimit -f 4; exec '{}' stability --out '{}' --filter none",
            env!("CARGO_BIN_EXE_marchmesh"),
            out.display()
        ))
        .current_dir(repo())
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(!out.join("generated").exists(), "{}", stderr(&o));
    let o = marchmesh(
        &[
            "stability",
            "--side",
            "8192",
            "--memory-limit-mib",
            "1024",
            "--out",
            out.to_str().unwrap(),
        ],
        &repo(),
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--memory-limit-mib"), "{}", stderr(&o));
}

/// `bench --suite NAME --list` from `cwd` (no checkout there) with the cache environment
/// `env`, HOME removed.
fn list_builtin(cwd: &Path, env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_marchmesh"));
    c.args(["bench", "--suite", "smoke", "--list"])
        .current_dir(cwd)
        .env_remove("MARCHMESH_ROOT")
        .env_remove("HOME")
        .env_remove("XDG_CACHE_HOME");
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().unwrap()
}

#[test]
fn the_built_in_scene_cache_is_private_and_verified() {
    let dir = tmp("bench-cache");
    let cache = dir.join("cache");
    let env = [("XDG_CACHE_HOME", cache.to_str().unwrap())];
    let o = list_builtin(&dir, &env);
    assert!(o.status.success(), "{}", stderr(&o));
    let listed = o.stdout.clone();
    let base = cache.join("marchmesh");
    use std::os::unix::fs::PermissionsExt;
    assert_eq!(
        std::fs::metadata(&base).unwrap().permissions().mode() & 0o777,
        0o700
    );
    // Replace the extracted smoke suite by one listing other files: it is detected and
    // extracted afresh.
    let copy = std::fs::read_dir(&base)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.join("scenes/suites/smoke.json").exists())
        .unwrap();
    std::fs::write(
        copy.join("scenes/suites/smoke.json"),
        r#"{"groups": [{"name": "etc", "scenes": ["/etc/*"], "backends": [{"backend": "sdf"}]}]}"#,
    )
    .unwrap();
    let o = list_builtin(&dir, &env);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(o.stdout, listed, "the altered copy was trusted");
    // A cache folder others can write into is not used; the private fallback is.
    std::fs::set_permissions(&base, std::fs::Permissions::from_mode(0o777)).unwrap();
    let o = list_builtin(&dir, &env);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(o.stdout, listed);
    // With no usable cache at all, a suite given as a path still works.
    let own = suite(
        &dir,
        "own.json",
        &format!(
            r#""scenes": ["{}"], "backends": [{{"backend": "sdf"}}]"#,
            csg()
        ),
    );
    let o = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(["bench", "--suite", own.to_str().unwrap(), "--list"])
        .current_dir(&dir)
        .env_remove("MARCHMESH_ROOT")
        .env_remove("HOME")
        .env("XDG_CACHE_HOME", "/proc/no-such-cache")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn a_killed_run_says_so_and_resumes_into_the_same_folder() {
    let dir = tmp("bench-resume");
    let out = dir.join("runs");
    let args = [
        "bench",
        "--suite",
        "smoke",
        "--filter",
        "smoke/csg/",
        "--out",
        out.to_str().unwrap(),
    ];
    let mut child = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(args)
        .current_dir(repo())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Kill it as soon as the run folder holds its first results.json.
    let start = Instant::now();
    let json = loop {
        let found = std::fs::read_dir(&out).ok().and_then(|d| {
            d.flatten()
                .map(|e| e.path().join("results.json"))
                .find(|p| p.exists())
        });
        if let Some(p) = found {
            break p;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "no results.json");
        std::thread::sleep(Duration::from_millis(5));
    };
    child.kill().unwrap();
    child.wait().unwrap();
    let res = marchmesh_harness::results::Results::read_json(&json).unwrap();
    assert!(
        res.interrupted || res.missing.is_empty(),
        "a killed run with {} missing says interrupted: false",
        res.missing.len()
    );
    let run = json.parent().unwrap();
    // The run's --filter again; the suite is the run's own.
    let resume_args = [
        "bench",
        "--filter",
        "smoke/csg/",
        "--resume",
        run.to_str().unwrap(),
    ];
    let o = marchmesh(&resume_args, &repo());
    if res.missing.is_empty() {
        // The run finished before the kill: nothing to resume, said so.
        assert!(stderr(&o).contains("nothing to resume"), "{}", stderr(&o));
        return;
    }
    assert!(o.status.success(), "{}", stderr(&o));
    let done = marchmesh_harness::results::Results::read_json(&json).unwrap();
    assert!(!done.interrupted && done.missing.is_empty());
    assert_eq!(done.rows.len(), 2, "{:?}", done.rows.len());
    assert!(run.join("summary.md").exists());
}

/// An interrupted run of the smoke suite in `dir/name` (results.json only, no images/),
/// with `missing` left to measure.
fn interrupted_smoke_run(dir: &Path, name: &str, missing: &[&str]) -> PathBuf {
    let mut res = results(vec![]);
    res.suite = "smoke".into();
    res.suite_file = repo()
        .join("scenes/suites/smoke.json")
        .display()
        .to_string();
    res.interrupted = true;
    res.missing = missing.iter().map(|m| m.to_string()).collect();
    run_dir(dir, name, &res)
}

#[test]
fn resuming_a_run_without_its_images_folder_writes_the_images_into_a_new_one() {
    let dir = tmp("bench-resume-no-images");
    let run = interrupted_smoke_run(&dir, "run", &["smoke/csg/sdf:eps_px=1/max32/t1"]);
    let o = marchmesh(&["bench", "--resume", run.to_str().unwrap()], &dir);
    assert!(o.status.success(), "{}", stderr(&o));
    let images: Vec<_> = std::fs::read_dir(run.join("images"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        images.iter().any(|n| n.starts_with("smoke_csg_sdf")),
        "{images:?}"
    );
}

#[test]
fn options_a_resumed_run_cannot_honour_are_refused_not_ignored() {
    let dir = tmp("bench-resume-conflicts");
    let run = interrupted_smoke_run(&dir, "run", &["smoke/csg/sdf:eps_px=1/max32/t1"]);
    let before = std::fs::read(run.join("results.json")).unwrap();
    for extra in [
        &["--suite", "default"][..],
        &["--out", "elsewhere"][..],
        &["--results-dir", "elsewhere"][..],
        &["--seed", "7"][..],
        &["--anchor", "a.json"][..],
    ] {
        let mut args = vec!["bench", "--resume", run.to_str().unwrap()];
        args.extend(extra);
        let o = marchmesh(&args, &dir);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {e}");
        assert!(e.contains("cannot be used with"), "{extra:?}: {e}");
    }
    assert_eq!(std::fs::read(run.join("results.json")).unwrap(), before);
    assert!(!dir.join("elsewhere").exists());
}

#[test]
fn a_summary_that_could_not_be_written_is_not_named_as_listing_anything() {
    let dir = tmp("bench-summary-unwritten");
    let run = interrupted_smoke_run(&dir, "run", &["smoke/csg/sdf:eps_px=1/max32/t1"]);
    // A folder where summary.md goes: the report cannot be written (and is not replaced).
    std::fs::create_dir(run.join("summary.md")).unwrap();
    std::fs::write(run.join("summary.md/keep.txt"), b"mine").unwrap();
    let o = marchmesh(&["bench", "--resume", run.to_str().unwrap()], &dir);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("could not be written")
            && e.contains("summary.md was not written")
            && !e.contains("and in"),
        "{e}"
    );
    assert_eq!(
        std::fs::read(run.join("summary.md/keep.txt")).unwrap(),
        b"mine"
    );
    // results.json, written before the summary, holds the measured row.
    let done = marchmesh_harness::results::Results::read_json(&run.join("results.json")).unwrap();
    assert_eq!(done.rows.len(), 1);
}

#[test]
fn resuming_a_run_that_would_duplicate_rows_or_write_through_a_link_is_refused() {
    let dir = tmp("bench-resume-hostile");
    let suite = repo().join("scenes/suites/smoke.json");
    let interrupted = |rows: Vec<marchmesh_harness::results::Row>, missing: &[&str]| {
        let mut res = results(rows);
        res.suite = "smoke".into();
        res.suite_file = suite.display().to_string();
        res.interrupted = true;
        res.missing = missing.iter().map(|m| m.to_string()).collect();
        res
    };
    let a = row("s", "sdf", "a", 2.0, None);
    let id = a.config_id.clone();
    let cases = [
        (
            "twice",
            interrupted(vec![a.clone(), a.clone()], &["g/t/sdf:a/x1/t1"]),
        ),
        ("measured-and-missing", interrupted(vec![a.clone()], &[&id])),
        ("missing-twice", interrupted(vec![], &[&id, &id])),
    ];
    for (name, res) in cases {
        let run = run_dir(&dir, name, &res);
        let before = std::fs::read(run.join("results.json")).unwrap();
        let o = marchmesh(&["bench", "--resume", run.to_str().unwrap()], &dir);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{name}: {e}");
        assert!(
            e.contains("results.json") && e.contains(&id) && e.contains("nothing was measured"),
            "{name}: {e}"
        );
        // The run is left as it was: its results.json unchanged, no image written.
        assert_eq!(std::fs::read(run.join("results.json")).unwrap(), before);
        assert!(!run.join("images").exists());
    }
    // images/ linked to a folder of the user's: refused before anything is written there.
    let victim = dir.join("victim");
    std::fs::create_dir_all(&victim).unwrap();
    std::fs::write(victim.join("keep.txt"), b"precious").unwrap();
    let run = run_dir(&dir, "linked", &interrupted(vec![], &[&id]));
    std::os::unix::fs::symlink(&victim, run.join("images")).unwrap();
    let o = marchmesh(&["bench", "--resume", run.to_str().unwrap()], &dir);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("images") && e.contains("symbolic link") && e.contains("nothing was measured"),
        "{e}"
    );
    let kept: Vec<_> = std::fs::read_dir(&victim).unwrap().flatten().collect();
    assert_eq!(kept.len(), 1);
    assert_eq!(std::fs::read(victim.join("keep.txt")).unwrap(), b"precious");
    // plots/ linked to a folder of the user's: refused the same way.
    let run = run_dir(&dir, "plots-linked", &interrupted(vec![], &[&id]));
    std::os::unix::fs::symlink(&victim, run.join("plots")).unwrap();
    let before = std::fs::read(run.join("results.json")).unwrap();
    let o = marchmesh(&["bench", "--resume", run.to_str().unwrap()], &dir);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("plots") && e.contains("symbolic link") && e.contains("nothing was measured"),
        "{e}"
    );
    assert_eq!(std::fs::read(run.join("results.json")).unwrap(), before);
    assert_eq!(std::fs::read_dir(&victim).unwrap().count(), 1);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn repeat_policies_beyond_the_documented_maxima_are_refused_at_load() {
    // Four billion repeats of at least 1e308 s each ran for ever.
    let dir = tmp("bench-repeats");
    for (policy, shown) in [
        (
            r#"{"min_count": 4294967295, "min_time_s": 0, "max_count": 4294967295}"#,
            "max_count 4294967295",
        ),
        (
            r#"{"min_count": 1, "min_time_s": 1e308, "max_count": 10}"#,
            "min_time_s 1e308",
        ),
    ] {
        let p = dir.join("s.json");
        std::fs::write(
            &p,
            format!(
                r#"{{"repeats": {policy}, "groups": [{{"name": "g", "scenes": [{:?}],
                    "resolutions": [{{"max_side": 8}}], "threads": [1],
                    "backends": [{{"backend": "sdf", "label": "a", "options": []}}]}}]}}"#,
                csg()
            ),
        )
        .unwrap();
        let o = marchmesh(&["bench", "--suite", p.to_str().unwrap(), "--list"], &dir);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{e}");
        assert!(
            e.contains("s.json")
                && e.contains("repeats")
                && e.contains("10000")
                && e.contains(shown),
            "{e}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
