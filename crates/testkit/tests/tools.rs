//! The skip rule of `testkit::tools`: a test whose tool is missing passes and names the skip,
//! unless `MARCHMESH_REQUIRE_TOOLS=1`, where the same test fails. Checked by running this test
//! binary again as a child with an empty `PATH`, so no tool can be found.

use std::process::Command;

use marchmesh_testkit::tools::{REQUIRE_ENV, SKIP_LOG_ENV, Tool, require, summary};

/// The child's body: needs GNU parallel (not on the child's empty `PATH`).
#[test]
#[ignore = "run only as the child of skipping_fails_only_when_tools_are_required"]
fn child_needing_a_missing_tool() {
    if require(Tool::GnuParallel, "child_needing_a_missing_tool").is_none() {
        return;
    }
    panic!("GNU parallel was found on an empty PATH");
}

/// Runs the child test with `PATH` empty and the skip log in `log`; `required` sets
/// `MARCHMESH_REQUIRE_TOOLS=1`. Returns (success, stderr and stdout).
fn run_child(log: &std::path::Path, required: bool) -> (bool, String) {
    let exe = std::env::current_exe().expect("test executable");
    let mut cmd = Command::new(exe);
    cmd.args([
        "--exact",
        "child_needing_a_missing_tool",
        "--ignored",
        "--test-threads=1",
    ])
    .env("PATH", "")
    .env(SKIP_LOG_ENV, log)
    .env_remove(REQUIRE_ENV);
    if required {
        cmd.env(REQUIRE_ENV, "1");
    }
    let out = cmd.output().expect("run the child test");
    // The harness reports a failed test's panic on stdout, a skip goes to stderr: both.
    (
        out.status.success(),
        format!(
            "{}{}",
            String::from_utf8_lossy(&out.stderr),
            String::from_utf8_lossy(&out.stdout)
        ),
    )
}

#[test]
fn skipping_fails_only_when_tools_are_required() {
    let log = marchmesh_testkit::temp_dir("tools-skip-log");

    let (ok, stderr) = run_child(&log, false);
    assert!(ok, "a missing tool must skip, not fail:\n{stderr}");
    assert!(
        stderr.contains("skipped: child_needing_a_missing_tool (needs GNU parallel): GNU parallel is not installed"),
        "the skip is named on stderr:\n{stderr}"
    );
    let listed = summary(&log);
    assert_eq!(listed.len(), 1, "{listed:?}");
    assert!(listed[0].contains("apt-get install parallel"), "{listed:?}");

    let (ok, stderr) = run_child(&log, true);
    assert!(
        !ok,
        "with {REQUIRE_ENV}=1 a missing tool must fail the test"
    );
    assert!(stderr.contains("forbids skipping"), "{stderr}");

    std::fs::remove_dir_all(&log).ok();
}
