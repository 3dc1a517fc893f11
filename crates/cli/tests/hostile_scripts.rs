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
