//! Issue 11: `render` never loses the user's data. Existing files (including every AOV file,
//! dangling symlinks and files created during a render) are never overwritten without
//! `--force`; special files are never replaced even with it; concurrent renders to one `--out`
//! have exactly one winner; thread counts are capped; `--out x.jpg` writes JPEG.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod support;
use support::{stderr, tmp};

/// A tiny scene (8x8 sphere) in `dir`.
fn scene(dir: &Path) -> PathBuf {
    let p = dir.join("s.json");
    std::fs::write(
        &p,
        r#"{"camera": {"width": 8, "height": 8}, "objects": [{"shape": {"sphere": {}}}]}"#,
    )
    .unwrap();
    p
}

fn render(dir: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .arg("render")
        .arg(scene(dir))
        .args(["--threads", "1"])
        .args(extra)
        .current_dir(dir)
        .output()
        .expect("run marchmesh")
}

#[test]
fn item6_aov_files_are_never_overwritten_without_force() {
    let dir = tmp("aov");
    let aov = dir.join("aov");
    std::fs::create_dir_all(&aov).unwrap();
    for name in ["normal.pfm", "mask.pfm", "work.pfm", "termination.pfm"] {
        std::fs::write(aov.join(name), b"mine").unwrap();
        let o = render(&dir, &["--out", "a.png", "--aov", "aov"]);
        assert!(!o.status.success(), "{name}");
        assert!(
            stderr(&o).contains(name) && stderr(&o).contains("--force"),
            "{}",
            stderr(&o)
        );
        assert_eq!(std::fs::read(aov.join(name)).unwrap(), b"mine");
        assert!(
            !dir.join("a.png").exists(),
            "nothing is published when one file is refused"
        );
        std::fs::remove_file(aov.join(name)).unwrap();
    }
    let o = render(&dir, &["--out", "a.png", "--aov", "aov"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(aov.join("termination.pfm").exists() && dir.join("a.png").exists());
}

#[test]
fn item8_concurrent_renders_to_one_out_have_exactly_one_winner() {
    let dir = tmp("race");
    let exe = env!("CARGO_BIN_EXE_marchmesh");
    let s = scene(&dir);
    let children: Vec<_> = (0..8)
        .map(|_| {
            Command::new(exe)
                .arg("render")
                .arg(&s)
                .args(["--threads", "1", "--out", "race.png"])
                .current_dir(&dir)
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    let winners = children
        .into_iter()
        .map(|c| c.wait_with_output().unwrap())
        .filter(|o| o.status.success())
        .count();
    assert_eq!(winners, 1);
    let png = std::fs::read(dir.join("race.png")).unwrap();
    image_is_valid_png(&png);
    // No temporary files are left behind.
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.contains("tmp")), "{names:?}");
}

fn image_is_valid_png(bytes: &[u8]) {
    assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"));
    assert!(bytes.ends_with(b"IEND\xaeB`\x82"), "PNG is complete");
}

#[test]
fn item9_dangling_symlinks_and_special_files_are_never_replaced() {
    let dir = tmp("symlink");
    std::os::unix::fs::symlink(dir.join("missing.png"), dir.join("link.png")).unwrap();
    let o = render(&dir, &["--out", "link.png"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("already exists"), "{}", stderr(&o));
    assert!(!dir.join("missing.png").exists());
    let o = render(&dir, &["--out", "link.png", "--force"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("not a regular file"), "{}", stderr(&o));
    assert!(
        std::fs::symlink_metadata(dir.join("link.png"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
    std::os::unix::fs::symlink("/dev/null", dir.join("null.png")).unwrap();
    let o = render(&dir, &["--out", "null.png", "--force"]);
    assert!(!o.status.success(), "{}", stderr(&o));
}

#[test]
fn item5_thread_counts_are_capped() {
    let dir = tmp("threads");
    let o = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .arg("render")
        .arg(scene(&dir))
        .args(["--threads", "1000000", "--out", "t.png"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("over the limit of 1024"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.join("t.png").exists());
}

#[test]
fn item16_out_jpg_writes_jpeg_and_unknown_extensions_are_refused() {
    let dir = tmp("jpeg");
    let o = render(&dir, &["--out", "x.jpg"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let bytes = std::fs::read(dir.join("x.jpg")).unwrap();
    assert!(bytes.starts_with(&[0xFF, 0xD8, 0xFF]), "JPEG magic");
    let o = render(&dir, &["--out", "x.bmp"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("unsupported image extension"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn item14_schema_validate_and_bench_list_on_a_closed_stdout_do_not_panic() {
    let dir = tmp("pipe");
    let s = scene(&dir);
    for args in [
        vec!["schema".to_string()],
        vec!["validate".into(), s.display().to_string()],
        vec![
            "bench".into(),
            "--suite".into(),
            "default".into(),
            "--list".into(),
        ],
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
            .args(&args)
            .env(
                "MARCHMESH_ROOT",
                concat!(env!("CARGO_MANIFEST_DIR"), "/../.."),
            )
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take()); // the reader goes away before anything is written
        let o = child.wait_with_output().unwrap();
        assert!(!stderr(&o).contains("panicked"), "{args:?}: {}", stderr(&o));
    }
}

#[test]
fn item16_validate_fails_on_missing_environment_maps_and_meshes() {
    let dir = tmp("validate");
    let p = dir.join("env.json");
    std::fs::write(
        &p,
        r#"{"background": {"environment": {"path": "nope.hdr"}},
            "objects": [{"shape": {"mesh": {"path": "nope.obj"}}}]}"#,
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(["validate"])
        .arg(&p)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("environment map") && stderr(&o).contains("nope.hdr"),
        "{}",
        stderr(&o)
    );
    assert!(stderr(&o).contains("nope.obj"), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        !out.contains(": ok"),
        "ok printed beside the problems: {out}"
    );
}

#[test]
fn item7_stability_never_writes_into_a_non_empty_folder() {
    let dir = tmp("stability");
    let run = dir.join("run");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::write(run.join("summary.md"), b"mine").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(["stability", "--out"])
        .arg(&run)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("not empty"), "{}", stderr(&o));
    assert_eq!(std::fs::read(run.join("summary.md")).unwrap(), b"mine");
    let scenes = dir.join("scenes");
    std::fs::create_dir_all(&scenes).unwrap();
    std::fs::write(scenes.join("x.json"), b"mine").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(["stability", "--out"])
        .arg(dir.join("run2"))
        .arg("--write-scenes")
        .arg(&scenes)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--write-scenes"), "{}", stderr(&o));
}

#[test]
fn item11_stability_fails_when_the_filter_matches_nothing() {
    let dir = tmp("stability-filter");
    let o = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(["stability", "--filter", "no-such-case-xyz", "--out"])
        .arg(dir.join("run"))
        .output()
        .unwrap();
    assert!(!o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("no stability case matches"),
        "{}",
        stderr(&o)
    );
    assert!(
        !dir.join("run").exists(),
        "a run that measured nothing leaves no folder"
    );
    // Nor the folders it made above its own, while the user's folder stays.
    std::fs::create_dir(dir.join("mine")).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(["stability", "--filter", "no-such-case-xyz", "--out"])
        .arg(dir.join("mine/new/run"))
        .output()
        .unwrap();
    assert!(!o.status.success(), "{}", stderr(&o));
    assert!(dir.join("mine").is_dir() && !dir.join("mine/new").exists());
}

#[test]
fn item5_bench_thread_counts_are_capped_on_the_command_line_and_in_suites() {
    let dir = tmp("bench-threads");
    let o = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(["bench", "--suite", "smoke", "--threads", "5000", "--list"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env(
            "MARCHMESH_ROOT",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../.."),
        )
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--threads 5000 is over the limit of 1024"),
        "{}",
        stderr(&o)
    );
    std::fs::copy(
        concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/csg.json"),
        dir.join("csg.json"),
    )
    .unwrap();
    std::fs::write(
        dir.join("suite.json"),
        r#"{"groups": [{"name": "g", "scenes": ["csg.json"], "threads": [1, 100000], "backends": [{"backend": "sdf"}]}]}"#,
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(["bench", "--suite", "suite.json", "--out", "out"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("groups[0].threads[1]") && stderr(&o).contains("over the limit"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.join("out").exists());
}

#[test]
fn item12_an_installed_binary_finds_its_suites_and_writes_under_the_current_folder() {
    // An empty folder, no checkout, a private cache: the embedded suites and scenes are used.
    let dir = tmp("installed");
    let cache = dir.join("cache");
    let work = dir.join("work");
    std::fs::create_dir_all(&work).unwrap();
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_marchmesh"))
            .args(args)
            .current_dir(&work)
            .env("XDG_CACHE_HOME", &cache)
            .env_remove("MARCHMESH_ROOT")
            .output()
            .unwrap()
    };
    let o = run(&["bench", "--suite", "smoke", "--list"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("smoke/csg/sdf"));
    let o = run(&[
        "bench", "--suite", "smoke", "--filter", "*/csg/*", "--quick",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let runs: Vec<_> = std::fs::read_dir(work.join("bench-results"))
        .unwrap()
        .collect();
    assert_eq!(runs.len(), 1, "results go under the current folder");
    // The scenes came from the extracted copy in the cache, not from the build tree.
    let extracted: Vec<_> = std::fs::read_dir(cache.join("marchmesh"))
        .unwrap()
        .flatten()
        .collect();
    assert_eq!(extracted.len(), 1);
    assert!(
        extracted[0]
            .path()
            .join("scenes/suites/default.json")
            .is_file()
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn output_folders_given_as_files_are_named_as_files() {
    let dir = tmp("folder-is-file");
    std::fs::write(dir.join("afile"), b"mine").unwrap();
    std::fs::write(dir.join("f.png"), b"mine").unwrap();
    let o = support::marchmesh(&["scenes", "-o", "afile"], &dir);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("afile is a file, not a folder"),
        "{}",
        stderr(&o)
    );
    let o = render(&dir, &["--out", "a.png", "--aov", "f.png"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("f.png is a file, not a folder"),
        "{}",
        stderr(&o)
    );
    let o = support::marchmesh(
        &["stability", "--out", "afile", "--filter", "nothing"],
        &dir,
    );
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("afile is a file, not a folder"),
        "{}",
        stderr(&o)
    );
    for f in ["afile", "f.png"] {
        assert_eq!(std::fs::read(dir.join(f)).unwrap(), b"mine");
    }
    assert!(!dir.join("a.png").exists());
}

#[test]
fn paths_through_a_file_or_a_dangling_link_name_the_component_and_the_reason() {
    let dir = tmp("folder-path-deeper");
    std::fs::write(dir.join("afile"), b"mine").unwrap();
    std::os::unix::fs::symlink(dir.join("nowhere"), dir.join("dangling")).unwrap();
    let run = support::run_dir(
        &dir,
        "run",
        &support::results(vec![support::row("s", "sdf", "a", 2.0, Some(40.0))]),
    );
    let run = run.to_str().unwrap();
    for (parent, reason) in [
        ("afile", "afile is a file, not a folder"),
        ("dangling", "which does not exist"),
    ] {
        let deep = format!("{parent}/x/y");
        let png = format!("{parent}/x.png");
        let md = format!("{parent}/F.md");
        let cases: Vec<Vec<&str>> = vec![
            vec!["render", "s.json", "-o", &png],
            vec!["render", "s.json", "-o", "a.png", "--aov", &deep],
            vec!["render", "s.json", "-o", "a.png", "--aov", parent],
            vec!["scenes", "-o", &deep],
            vec!["merge", "-o", &deep, run],
            vec!["findings", run, "-o", &md],
            vec!["stability", "--out", &deep, "--filter", "nothing"],
            vec!["bench", "--suite", "smoke", "--out", &deep],
        ];
        for args in cases {
            scene(&dir);
            let o = support::marchmesh(&args, &dir);
            let e = stderr(&o);
            assert!(!o.status.success(), "{args:?}");
            assert!(
                e.contains(reason) && !e.contains("os error"),
                "{args:?}: {e}"
            );
        }
    }
    assert_eq!(std::fs::read(dir.join("afile")).unwrap(), b"mine");
    assert!(!dir.join("nowhere").exists() && !dir.join("a.png").exists());
}
