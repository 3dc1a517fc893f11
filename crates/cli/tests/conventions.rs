//! The command-line conventions: built-in scenes and suites by name from any folder, `-o` for
//! what a command writes and `-O` for backend options, unknown names listing the known ones,
//! `validate` listing every problem it can find, the AOVs as one OpenEXR file beside the PFMs,
//! and `compare` stating each run's clock and load.

use std::path::{Path, PathBuf};

fn marchmesh(args: &[&str], cwd: &Path) -> (bool, String, String) {
    marchmesh_testkit::run_program(env!("CARGO_BIN_EXE_marchmesh"), args, cwd)
}

/// `marchmesh` run outside any checkout, with its own cache folder for the built-in scenes.
fn marchmesh_outside(args: &[&str], cwd: &Path) -> (bool, String, String) {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(args)
        .current_dir(cwd)
        .env_remove("MARCHMESH_ROOT")
        .env("XDG_CACHE_HOME", cwd.join("cache"))
        .output()
        .expect("marchmesh runs");
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn tmp(name: &str) -> PathBuf {
    marchmesh_testkit::temp_dir(&format!("cli-conventions-{name}"))
}

#[test]
fn built_in_scenes_are_listed_extracted_and_rendered_by_name_anywhere() {
    let dir = tmp("scenes");
    let (ok, stdout, stderr) = marchmesh_outside(&["scenes"], &dir);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("  seed-spheres\n") && stdout.contains("  default\n"),
        "{stdout}"
    );
    // Extracted as the repository lays them out, into a new folder only.
    let (ok, stdout, stderr) = marchmesh_outside(&["scenes", "-o", "mine"], &dir);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("scenes"), "{stdout}");
    assert!(dir.join("mine/seed-spheres.json").is_file());
    assert!(dir.join("mine/suites/default.json").is_file());
    let (ok, _, stderr) = marchmesh_outside(&["scenes", "-o", "mine"], &dir);
    assert!(!ok && stderr.contains("not empty"), "{stderr}");
    // A built-in scene by name, from a folder that is no checkout; -o is the image, -O a
    // backend option; the AOVs come as PFMs and one EXR.
    let (ok, stdout, stderr) = marchmesh_outside(
        &[
            "render",
            "seed-spheres",
            "-b",
            "sdf",
            "-O",
            "eps_px=0.1",
            "--width",
            "24",
            "--height",
            "16",
            "--threads",
            "1",
            "-o",
            "seed.png",
            "--aov",
            "aov",
        ],
        &dir,
    );
    assert!(ok, "{stdout}{stderr}");
    assert!(dir.join("seed.png").is_file());
    assert!(dir.join("aov/depth.pfm").is_file());
    let exr = std::fs::read(dir.join("aov/aovs.exr")).unwrap();
    assert_eq!(&exr[..4], &[0x76, 0x2f, 0x31, 0x01], "OpenEXR magic number");
    for channel in ["color.R", "depth.Z", "normal.X", "work.steps"] {
        assert!(
            exr.windows(channel.len()).any(|w| w == channel.as_bytes()),
            "no {channel} channel"
        );
    }
    // An unknown name lists the built-in scenes.
    let (ok, _, stderr) = marchmesh_outside(&["render", "seed-spherez"], &dir);
    assert!(!ok, "{stderr}");
    assert!(
        stderr.contains("seed-spherez") && stderr.contains("built-in scenes: "),
        "{stderr}"
    );
    let (ok, stdout, stderr) = marchmesh_outside(&["validate", "csg"], &dir);
    assert!(ok && stdout.contains(": ok: "), "{stdout}{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn validate_lists_every_problem_it_can_find() {
    let dir = tmp("validate");
    let scene = dir.join("bad.json");
    std::fs::write(
        &scene,
        r#"{
  "camera": { "position": [0, 0, -4], "look_at": [0, 0, 0], "width": "wide", "hieght": 9 },
  "objects": [
    { "shape": { "sphere": { "radius": 1, "colour": 3 } } },
    { "shape": { "sphere": { "radius": -1 } } }
  ]
}"#,
    )
    .unwrap();
    let (ok, _, stderr) = marchmesh(&["validate", scene.to_str().unwrap()], &dir);
    assert!(!ok);
    // The first problem with its line, the others by JSON path, then the value checks.
    for expected in ["camera.width", "hieght", "colour", "radius"] {
        assert!(stderr.contains(expected), "{expected} missing:\n{stderr}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn compare_states_each_runs_clock_and_load() {
    let results = marchmesh_testkit::repo_root().join("bench-results");
    let (ok, stdout, stderr) = marchmesh(
        &[
            "compare",
            "20261126T234337Z-default",
            "20261127T012132Z-default",
        ],
        &results,
    );
    assert!(ok, "{stderr}");
    let clocks = stdout
        .lines()
        .find(|l| l.starts_with("clocks: "))
        .unwrap_or_else(|| panic!("no clocks line:\n{stdout}"));
    assert!(
        clocks.contains("A on ") && clocks.contains("B on ") && clocks.contains("load "),
        "{clocks}"
    );
    // The clocks line comes before the per-configuration ratios.
    let at = stdout.find("clocks: ").unwrap();
    assert!(at < stdout.find("configuration").unwrap(), "{stdout}");
}
