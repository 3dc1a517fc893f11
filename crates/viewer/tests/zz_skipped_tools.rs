//! The end of `cargo test --workspace`: lists every test that skipped for want of an outside
//! tool (see `marchmesh_testkit::tools`), with how to install it.
//!
//! Cargo runs test binaries in package-name then target-name order, and `marchmesh-viewer` is
//! the workspace's last package, so this binary (`zz_` to sort last within it) runs after every
//! test that can skip. Run alone, it lists the skips of the last run of each such test.

use std::io::Write;

use marchmesh_testkit::tools::{Tool, skip_log_dir, summary};

#[test]
fn list_the_tests_skipped_for_want_of_a_tool() {
    let Some(log) = skip_log_dir() else {
        return;
    };
    let skips = summary(&log);
    // Straight to the process's standard error: the harness would hide captured output.
    let mut err = std::io::stderr().lock();
    if skips.is_empty() {
        let _ = writeln!(err, "\nno test skipped for want of a tool");
        return;
    }
    let _ = writeln!(
        err,
        "\n{} test(s) skipped for want of a tool (the README lists what each adds):",
        skips.len()
    );
    for s in &skips {
        let _ = writeln!(err, "  {s}");
    }
    let hints: Vec<String> = Tool::ALL
        .iter()
        .filter(|t| skips.iter().any(|s| s.contains(t.name())))
        .map(|t| format!("  {}: {}", t.name(), t.install_hint()))
        .collect();
    let _ = writeln!(err, "install:\n{}", hints.join("\n"));
}
