//! The anchor scripts' shared helpers (`scripts/anchor_common.sh`): no interpreter planted in
//! a shared folder is run, temporary files live in a private folder, and two runs in the same
//! second never write to one output name.

use std::process::{Command, Output};

mod support;
use support::{text, tmp};

/// Runs `body` in bash after sourcing the helpers, with `env` set and HOME/XDG cleared.
fn helpers(body: &str, env: &[(&str, &str)]) -> Output {
    let common = marchmesh_testkit::repo_root().join("scripts/anchor_common.sh");
    let mut c = Command::new("bash");
    c.arg("-c")
        .arg(format!(
            "set -euo pipefail; . '{}'; {body}",
            common.display()
        ))
        .env_remove("EMBREE_VENV")
        .env_remove("XDG_CACHE_HOME")
        .env_remove("HOME");
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().unwrap()
}

#[test]
fn the_python_environment_lives_in_the_users_cache_and_planted_ones_are_refused() {
    let dir = tmp("scripts-venv");
    let home = dir.join("home");
    let o = helpers(
        "anchor_venv embree-venv",
        &[("HOME", home.to_str().unwrap())],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let venv = text(&o.stdout);
    assert_eq!(
        venv.trim(),
        home.join(".cache/marchmesh/embree-venv")
            .display()
            .to_string()
    );
    assert!(!venv.contains("/tmp/embree-venv"));
    // A folder anyone can write into (a planted interpreter) is refused.
    let planted = home.join(".cache/marchmesh/embree-venv");
    std::fs::create_dir_all(planted.join("bin")).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&planted, std::fs::Permissions::from_mode(0o777)).unwrap();
    let o = helpers(
        "anchor_venv embree-venv",
        &[("HOME", home.to_str().unwrap())],
    );
    assert!(!o.status.success());
    assert!(text(&o.stderr).contains("not used"), "{}", text(&o.stderr));
    // Without HOME or XDG_CACHE_HOME there is no default: nothing under /tmp is guessed.
    let o = helpers("anchor_venv embree-venv", &[]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("EMBREE_VENV"),
        "{}",
        text(&o.stderr)
    );
}

#[test]
fn temporary_files_go_to_a_private_folder_removed_at_exit() {
    let o = helpers(
        "anchor_private_tmp; stat -c '%a' \"$anchor_tmp\"; echo \"$anchor_tmp\"",
        &[],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    let mut lines = out.lines();
    assert_eq!(lines.next(), Some("700"));
    let folder = lines.next().unwrap();
    assert!(!folder.ends_with("/tmp"), "{folder}");
    assert!(
        !std::path::Path::new(folder).exists(),
        "not removed at exit"
    );
}

#[test]
fn runs_in_the_same_second_get_distinct_output_names() {
    let dir = tmp("scripts-names");
    let d = dir.to_str().unwrap();
    let o = helpers(
        &format!(
            "anchor_reserve '{d}' embree; anchor_reserve '{d}' embree; anchor_reserve '{d}' embree"
        ),
        &[],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    let names: std::collections::BTreeSet<&str> = out.lines().collect();
    assert_eq!(names.len(), 3, "{out}");
    for n in &names {
        assert!(std::path::Path::new(&format!("{n}.md")).exists(), "{n}");
    }
    // Every anchor script uses the helpers and no fixed name in a shared folder.
    for script in ["anchor_embree.sh", "anchor_fidget.sh", "anchor_tinybvh.sh"] {
        let text =
            std::fs::read_to_string(marchmesh_testkit::repo_root().join("scripts").join(script))
                .unwrap();
        assert!(text.contains("anchor_common.sh") && text.contains("anchor_reserve"));
        assert!(!text.contains("/tmp/"), "{script} names a fixed /tmp path");
    }
}

/// The Mitsuba cross-check's plane geometry, which needs neither numpy nor Mitsuba: a plane's
/// square is centred on the camera's foot point in render space, also with the camera far
/// from the world origin (where a world-space foot point left the visible ground uncovered).
#[test]
fn the_mitsuba_crosscheck_places_planes_in_render_space() {
    let Some(python) = marchmesh_testkit::tools::require(
        marchmesh_testkit::tools::Tool::Python,
        "the_mitsuba_crosscheck_places_planes_in_render_space",
    ) else {
        return;
    };
    let o = Command::new(python)
        .args([
            "-m",
            "unittest",
            "-v",
            "test_crosscheck_mitsuba.PlaneSquare",
        ])
        .current_dir(marchmesh_testkit::repo_root().join("scripts"))
        .output()
        .unwrap();
    let out = text(&o.stderr);
    assert!(o.status.success(), "{out}");
    // unittest -v prints `name ... ok` or, from Python 3.11, `name (module.Class.name) ... ok`.
    assert!(
        out.lines().any(|l| l
            .starts_with("test_the_square_is_centred_below_a_camera_far_from_the_origin")
            && l.ends_with("... ok")),
        "{out}"
    );
    assert!(out.contains("Ran 2 tests"), "{out}");
}

/// The Mitsuba path-tracing cross-check's decision rule, on synthetic images without numpy
/// or Mitsuba: unbiased renders pass at any noise level (where a fixed PSNR threshold failed
/// them), a bias hidden in the mean or concentrated in a few pixels fails the noise check,
/// one beyond the mean tolerance fails the mean check.
#[test]
fn the_mitsuba_path_tracing_crosscheck_decides_by_bias_against_noise() {
    let Some(python) = marchmesh_testkit::tools::require(
        marchmesh_testkit::tools::Tool::Python,
        "the_mitsuba_path_tracing_crosscheck_decides_by_bias_against_noise",
    ) else {
        return;
    };
    let o = Command::new(python)
        .args(["-m", "unittest", "-v", "test_crosscheck_mitsuba_pt.Verdict"])
        .current_dir(marchmesh_testkit::repo_root().join("scripts"))
        .output()
        .unwrap();
    let out = text(&o.stderr);
    assert!(o.status.success(), "{out}");
    for name in [
        "test_unbiased_renders_pass_whatever_their_noise",
        "test_a_bias_hidden_in_the_mean_fails_the_noise_check",
        "test_a_large_bias_in_a_few_pixels_fails_the_noise_check",
        "test_a_uniform_bias_beyond_the_mean_tolerance_fails",
    ] {
        // unittest -v prints `name ... ok` or, from Python 3.11, `name (module.Class.name) ... ok`.
        assert!(
            out.lines()
                .any(|l| l.starts_with(name) && l.ends_with("... ok")),
            "{name}: {out}"
        );
    }
    assert!(out.contains("Ran 7 tests"), "{out}");
}

/// The tinybvh anchor's own logic, which needs neither numpy, Embree nor tinybvh: its
/// program's output is parsed or refused, ratios are medians of per-round ratios against the
/// round's fastest peer, and tinybvh's header is looked up where the script documents it.
#[test]
fn the_tinybvh_anchor_parses_its_programs_output_and_finds_its_header() {
    let Some(python) = marchmesh_testkit::tools::require(
        marchmesh_testkit::tools::Tool::Python,
        "the_tinybvh_anchor_parses_its_programs_output_and_finds_its_header",
    ) else {
        return;
    };
    let o = Command::new(python)
        .args(["-m", "unittest", "-v", "test_anchor_tinybvh"])
        .current_dir(marchmesh_testkit::repo_root().join("scripts"))
        .output()
        .unwrap();
    let out = text(&o.stderr);
    assert!(o.status.success(), "{out}");
    for name in [
        "test_a_build_line_then_one_rate_per_pass",
        "test_malformed_output_is_refused",
        "test_the_fastest_peer_is_taken_round_by_round",
        "test_tinybvh_dir_must_hold_the_header",
        "test_without_either_place_the_message_names_both",
    ] {
        // unittest -v prints `name ... ok` or, from Python 3.11, `name (module.Class.name) ... ok`.
        assert!(
            out.lines()
                .any(|l| l.starts_with(name) && l.ends_with("... ok")),
            "{name}: {out}"
        );
    }
    assert!(out.contains("Ran 11 tests"), "{out}");
}

/// Writes an executable shell script.
fn script(path: &std::path::Path, body: &str) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, format!("#!/usr/bin/env bash\n{body}\n")).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755)).unwrap();
}

/// `scripts/anchor.sh` run with `args`, `env` set and the tools' variables cleared.
fn anchor_sh(path: &std::path::Path, args: &[&str], env: &[(&str, &str)]) -> Output {
    // bash by its path: a test may give the command a PATH without it.
    let bash = Command::new("bash")
        .args(["-c", "command -v bash"])
        .output()
        .unwrap();
    let mut c = Command::new(text(&bash.stdout).trim());
    c.arg(path).args(args);
    for k in [
        "CC",
        "CXX",
        "TINYBVH_DIR",
        "TINYBVH_GIT_DIR",
        "EMBREE_VENV",
        "ANCHOR_OUT_DIR",
    ] {
        c.env_remove(k);
    }
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().unwrap()
}

fn the_anchor_command() -> std::path::PathBuf {
    marchmesh_testkit::repo_root().join("scripts/anchor.sh")
}

#[test]
fn the_anchor_command_refuses_bad_arguments_with_its_usage() {
    let out = tmp("anchor-usage");
    let o_dir = out.join("anchors");
    for (args, expect) in [
        (vec!["--bogus"], "unknown argument '--bogus'"),
        (vec!["--only", "embree,optix"], "'optix' is not an anchor"),
        (vec!["--only"], "usage: scripts/anchor.sh"),
        (vec!["--out"], "usage: scripts/anchor.sh"),
        (vec!["--only", ","], "is not an anchor"),
    ] {
        let mut a = vec!["--out", o_dir.to_str().unwrap()];
        a.extend(args.iter().copied());
        // A bad argument before --out too.
        let o = anchor_sh(&the_anchor_command(), &a, &[]);
        let e = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(expect), "{args:?}: {e}");
        assert!(!o_dir.exists(), "{args:?} wrote something");
    }
    let o = anchor_sh(&the_anchor_command(), &["--help"], &[]);
    assert!(o.status.success());
    assert!(text(&o.stdout).contains("--quick"), "{}", text(&o.stdout));
}

#[test]
fn the_anchor_command_names_every_missing_tool_and_what_to_install() {
    let dir = tmp("anchor-missing");
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    // An Embree environment whose Python lacks embreex.
    let venv = dir.join("venv");
    script(&venv.join("bin/python"), "exit 1");
    let o = anchor_sh(
        &the_anchor_command(),
        &["--check"],
        &[
            ("CC", "/nonexistent/cc"),
            ("CXX", "/nonexistent/c++"),
            ("TINYBVH_DIR", empty.to_str().unwrap()),
            ("EMBREE_VENV", venv.to_str().unwrap()),
        ],
    );
    let e = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    for what in [
        "a C compiler '/nonexistent/cc'",
        "apt-get install build-essential",
        "a C++17 compiler '/nonexistent/c++'",
        "has no tiny_bvh.h",
        "git clone https://github.com/jbikker/tinybvh",
        "Embree 4 (the embreex package)",
        "pip install embreex numpy",
    ] {
        assert!(e.contains(what), "{what}: {e}");
    }
    // Without TINYBVH_DIR, a git directory without the header is named.
    let o = anchor_sh(
        &the_anchor_command(),
        &["--check", "--only", "tinybvh"],
        &[
            ("TINYBVH_GIT_DIR", empty.to_str().unwrap()),
            ("CXX", "/nonexistent/c++"),
            ("CC", "/nonexistent/cc"),
            ("EMBREE_VENV", venv.to_str().unwrap()),
        ],
    );
    let e = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains(&format!("the git directory {}", empty.display()))
            && e.contains("TINYBVH_GIT_DIR"),
        "{e}"
    );
    // Without cargo on the PATH, the fidget anchor cannot build: named with rustup.
    let bin = dir.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    std::os::unix::fs::symlink(
        String::from_utf8(
            Command::new("bash")
                .args(["-c", "command -v dirname"])
                .output()
                .unwrap()
                .stdout,
        )
        .unwrap()
        .trim(),
        bin.join("dirname"),
    )
    .unwrap();
    let o = anchor_sh(
        &the_anchor_command(),
        &["--check", "--only", "fidget"],
        &[("PATH", bin.to_str().unwrap())],
    );
    let e = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("cargo (Rust): install it with rustup"), "{e}");
}

/// The command's own filing, with stand-ins for the three anchor scripts (which need Embree,
/// tinybvh and fidget): every anchor's files are listed in a note with the load before and
/// after it, a second run in the same second takes new names, nothing present is overwritten,
/// and a failing anchor fails the command without losing the others' files.
#[test]
fn the_anchor_command_files_every_anchor_without_overwriting_anything() {
    let dir = tmp("anchor-filing");
    let root = dir.join("repo");
    let real = marchmesh_testkit::repo_root().join("scripts");
    for f in ["anchor.sh", "anchor_common.sh"] {
        std::fs::create_dir_all(root.join("scripts")).unwrap();
        std::fs::copy(real.join(f), root.join("scripts").join(f)).unwrap();
    }
    std::fs::create_dir_all(root.join("crates/anchor-fidget")).unwrap();
    std::fs::write(root.join("crates/anchor-fidget/Cargo.toml"), "").unwrap();
    // Stand-ins: each reserves its name as the real scripts do and reports its flags.
    for tool in ["embree", "tinybvh", "fidget"] {
        script(
            &root.join(format!("scripts/anchor_{tool}.sh")),
            &format!(
                r#"set -euo pipefail
root="$(cd "$(dirname "${{BASH_SOURCE[0]}}")/.." && pwd)"
. "$root/scripts/anchor_common.sh"
[ "{tool}" != "${{FAIL:-}}" ] || {{ echo "{tool} broke" >&2; exit 1; }}
base="$(anchor_reserve "$ANCHOR_OUT_DIR" {tool})"
echo "{{\"flags\": \"$*\"}}" >"$base.json"
echo "wrote $base.json and .md""#
            ),
        );
    }
    let bin = dir.join("bin");
    for tool in ["cargo", "cc", "c++"] {
        script(&bin.join(tool), "exit 0");
    }
    let venv = dir.join("venv");
    script(&venv.join("bin/python"), "exit 0");
    let tinybvh = dir.join("tinybvh");
    std::fs::create_dir_all(&tinybvh).unwrap();
    std::fs::write(tinybvh.join("tiny_bvh.h"), "").unwrap();
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("keep.json"), "mine").unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let env = [
        ("PATH", path.as_str()),
        ("EMBREE_VENV", venv.to_str().unwrap()),
        ("TINYBVH_DIR", tinybvh.to_str().unwrap()),
    ];
    let cmd = root.join("scripts/anchor.sh");
    let args = ["--quick", "--out", out.to_str().unwrap()];
    let first = anchor_sh(&cmd, &args, &env);
    assert!(first.status.success(), "{}", text(&first.stderr));
    let second = anchor_sh(&cmd, &args, &env);
    assert!(second.status.success(), "{}", text(&second.stderr));
    let files = |o: &Output| -> Vec<String> {
        text(&o.stdout)
            .lines()
            .filter_map(|l| l.strip_prefix("anchor file: ").map(str::to_string))
            .collect()
    };
    let (a, b) = (files(&first), files(&second));
    assert_eq!((a.len(), b.len()), (3, 3), "{a:?} {b:?}");
    for f in a.iter().chain(&b) {
        assert!(std::path::Path::new(f).is_file(), "{f}");
    }
    let all: std::collections::BTreeSet<&String> = a.iter().chain(&b).collect();
    assert_eq!(all.len(), 6, "a name was reused: {a:?} {b:?}");
    assert_eq!(
        std::fs::read_to_string(out.join("keep.json")).unwrap(),
        "mine"
    );
    // The quick flags reach each anchor.
    let flags = |f: &str| std::fs::read_to_string(f).unwrap();
    assert!(
        flags(&a[0]).contains("--rounds 2 --repeats 3"),
        "{}",
        flags(&a[0])
    );
    assert!(flags(&a[1]).contains("--layouts bvh8"), "{}", flags(&a[1]));
    assert!(flags(&a[2]).contains("--repeats 3"), "{}", flags(&a[2]));
    // The note lists each anchor with the load before and after it.
    let note = text(&first.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("anchor note: ").map(str::to_string))
        .expect("note");
    let note = std::fs::read_to_string(note).unwrap();
    assert!(
        note.contains("Command: scripts/anchor.sh --quick"),
        "{note}"
    );
    for tool in ["embree", "tinybvh", "fidget"] {
        assert!(
            note.lines()
                .any(|l| l.starts_with(&format!("| {tool} | ")) && l.contains(".json")),
            "{tool}: {note}"
        );
    }
    // A failing anchor fails the command; the others still file theirs.
    let failing: Vec<(&str, &str)> = env.iter().copied().chain([("FAIL", "tinybvh")]).collect();
    let o = anchor_sh(&cmd, &args, &failing);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stderr));
    assert!(
        text(&o.stderr).contains("the tinybvh anchor failed"),
        "{}",
        text(&o.stderr)
    );
    assert_eq!(files(&o).len(), 2, "{}", text(&o.stdout));
}

/// Every anchor script files into the folder `scripts/anchor.sh` gives it.
#[test]
fn every_anchor_script_honours_the_output_folder_of_the_one_command() {
    for s in ["anchor_embree.sh", "anchor_tinybvh.sh", "anchor_fidget.sh"] {
        let text = std::fs::read_to_string(marchmesh_testkit::repo_root().join("scripts").join(s))
            .unwrap();
        assert!(text.contains("out=\"${ANCHOR_OUT_DIR:-"), "{s}");
    }
    let one = std::fs::read_to_string(the_anchor_command()).unwrap();
    for s in ["anchor_embree.sh", "anchor_tinybvh.sh", "anchor_fidget.sh"] {
        assert!(one.contains(s), "{s}");
    }
}
