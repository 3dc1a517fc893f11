//! Outside tools some tests need (GNU parallel, Chromium, Xvfb, Slurm), found on `PATH`, and
//! the one way a test skips for want of one.
//!
//! Contract: a test that needs a tool calls [`require`] (or [`skip`] when the tool is there but
//! cannot be used, e.g. a display that will not open). Without the tool the test returns early
//! after one line on the real standard error (not captured by the test harness, so a passing
//! run shows it) and a record in the skip log; [`summary`] lists what the log holds, and the
//! workspace's last test binary prints it. With the environment variable [`REQUIRE_ENV`] set
//! to `1` a skip is a test failure instead, so a run that is meant to have every tool (CI)
//! cannot pass by skipping.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Setting this environment variable to `1` turns every skip into a panic (CI sets it).
pub const REQUIRE_ENV: &str = "MARCHMESH_REQUIRE_TOOLS";

/// An outside program that some tests need and the README lists as optional.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tool {
    /// GNU parallel: the README's one-machine sharding one-liner.
    GnuParallel,
    /// Chromium (headless): the report.html browser test.
    Chromium,
    /// Xvfb, a virtual X server: the viewer's window test.
    Xvfb,
    /// Slurm (`sbatch`, `squeue`; a running controller): the cluster script's test.
    Slurm,
    /// Python 3: the tests of the Python scripts (the Mitsuba cross-check's geometry).
    Python,
}

impl Tool {
    /// Every tool, in the order the README lists them.
    pub const ALL: [Tool; 5] = [
        Tool::GnuParallel,
        Tool::Chromium,
        Tool::Xvfb,
        Tool::Slurm,
        Tool::Python,
    ];

    /// A short name for messages.
    pub const fn name(self) -> &'static str {
        match self {
            Tool::GnuParallel => "GNU parallel",
            Tool::Chromium => "Chromium",
            Tool::Xvfb => "Xvfb",
            Tool::Slurm => "Slurm",
            Tool::Python => "Python 3",
        }
    }

    /// Program names looked up on `PATH`; the first found is the tool.
    const fn programs(self) -> &'static [&'static str] {
        match self {
            Tool::GnuParallel => &["parallel"],
            Tool::Chromium => &["chromium", "chromium-browser"],
            Tool::Xvfb => &["Xvfb"],
            Tool::Slurm => &["sbatch"],
            Tool::Python => &["python3"],
        }
    }

    /// How to install it on Debian (one line).
    pub const fn install_hint(self) -> &'static str {
        match self {
            Tool::GnuParallel => "apt-get install parallel",
            Tool::Chromium => "bash scripts/install_chromium.sh",
            Tool::Xvfb => "apt-get install xvfb",
            Tool::Slurm => "bash scripts/slurm_local.sh start (installs and starts slurm-wlm)",
            Tool::Python => "apt-get install python3",
        }
    }

    /// The program's path on `PATH`, if it is there. GNU parallel must also be GNU's (the
    /// `moreutils` program of the same name takes other arguments).
    pub fn find(self) -> Option<PathBuf> {
        let found = self.programs().iter().find_map(|name| on_path(name))?;
        if self == Tool::GnuParallel {
            let out = std::process::Command::new(&found)
                .arg("--version")
                .output()
                .ok()?;
            if !out.status.success() || !String::from_utf8_lossy(&out.stdout).contains("GNU") {
                return None;
            }
        }
        Some(found)
    }
}

/// The file `name` in a folder of `PATH`, if any.
fn on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

/// The tool's path, or `None` after recording a skip of `test` (see the module doc; panics
/// instead when [`REQUIRE_ENV`] is `1`).
pub fn require(tool: Tool, test: &str) -> Option<PathBuf> {
    match tool.find() {
        Some(p) => {
            clear_skip(test);
            Some(p)
        }
        None => {
            skip(
                tool,
                test,
                &format!("{} is not installed ({})", tool.name(), tool.install_hint()),
            );
            None
        }
    }
}

/// Records that `test` did not run because of `tool` for `reason`: one line on the real
/// standard error and a record in the skip log. Panics instead when [`REQUIRE_ENV`] is `1`.
pub fn skip(tool: Tool, test: &str, reason: &str) {
    if required() {
        panic!(
            "{test} needs {}: {reason} ({REQUIRE_ENV}=1 forbids skipping)",
            tool.name()
        );
    }
    let line = format!("skipped: {test} (needs {}): {reason}", tool.name());
    // Straight to the process's standard error: `eprintln!` would be captured and hidden.
    let _ = writeln!(std::io::stderr(), "{line}");
    if let Some(dir) = skip_log_dir() {
        let _ = std::fs::create_dir_all(&dir);
        let _ = std::fs::write(dir.join(format!("{}.txt", sanitise(test))), line);
    }
}

/// Whether skipping is forbidden ([`REQUIRE_ENV`] is `1`).
pub fn required() -> bool {
    std::env::var(REQUIRE_ENV).is_ok_and(|v| v == "1")
}

/// Overrides the skip log's folder (the self-test of this module uses it).
pub const SKIP_LOG_ENV: &str = "MARCHMESH_SKIP_LOG_DIR";

/// The skip log: the folder [`SKIP_LOG_ENV`] names, else `target/test-skips/` of the build the
/// running test belongs to (found from the test executable's path,
/// `target/<profile>/deps/<test>`), or `None` when that is not where it runs from.
pub fn skip_log_dir() -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os(SKIP_LOG_ENV) {
        return Some(PathBuf::from(dir));
    }
    let exe = std::env::current_exe().ok()?;
    let deps = exe.parent()?;
    let target = deps.parent()?.parent()?;
    (deps.file_name()? == "deps").then(|| target.join("test-skips"))
}

/// The skips recorded in the log folder `log`, sorted, one line each. A test clears its own
/// record whenever it finds its tool, so the log holds the tests whose last run skipped.
pub fn summary(log: &Path) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(log) else {
        return Vec::new();
    };
    let mut lines: Vec<String> = entries
        .filter_map(Result::ok)
        .filter_map(|e| std::fs::read_to_string(e.path()).ok())
        .map(|s| s.trim().to_owned())
        .collect();
    lines.sort();
    lines
}

/// Removes the record of `test` from the skip log (a test that ran clears its old skip).
pub fn clear_skip(test: &str) {
    if let Some(dir) = skip_log_dir() {
        let _ = std::fs::remove_file(dir.join(format!("{}.txt", sanitise(test))));
    }
}

fn sanitise(test: &str) -> String {
    test.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '-'
            }
        })
        .collect()
}
