//! `summary.md`, `plots/*.svg` and `report.html` from [`Results`]; `marchmesh report`
//! regenerates them from `results.json` alone, so the tables only depend on what the JSON
//! holds.

mod analysis;
mod format;
mod plots;
mod summary;

pub(crate) use analysis::label;
pub use analysis::{pareto_front, pareto_front_on, verdict};
pub use format::{bytes, md_escape};
pub(crate) use format::{opt, opt_bytes, short_num, tail_px};
pub use plots::write_plots;
pub(crate) use plots::{color_of, line_plot};
pub(crate) use summary::group_scenes;
pub use summary::{SUMMARY_COLUMNS, SummaryColumn, summary_markdown};

use std::path::Path;

use crate::results::Results;

/// Writes `summary.md`, `plots/` and `report.html` (which inlines the plots and shows the
/// images of `images/`, see [`crate::html`]) into `dir` from `res`. Returns the plot file
/// names. A `plots/` that is a symbolic link, file or special file is refused before
/// anything is written.
pub fn write_report(res: &Results, dir: &Path) -> Result<Vec<String>, String> {
    write_report_noting_summary(res, dir, &mut false)
}

/// [`write_report`], setting `summary_written` once `summary.md` is written (so a caller
/// whose later step failed knows whether the summary it names exists).
fn write_report_noting_summary(
    res: &Results,
    dir: &Path,
    summary_written: &mut bool,
) -> Result<Vec<String>, String> {
    marchmesh_safeio::check_own_folder(&dir.join("plots")).map_err(|e| e.to_string())?;
    let summary = dir.join("summary.md");
    let html = dir.join("report.html");
    check_regenerable(&summary, SUMMARY_MARK)?;
    check_regenerable(&html, HTML_MARK)?;
    marchmesh_safeio::replace_regular(&summary, summary_markdown(&res.markdown_safe()).as_bytes())
        .map_err(|e| e.to_string())?;
    *summary_written = true;
    let plots = write_plots(res, &dir.join("plots"))?;
    marchmesh_safeio::replace_regular(&html, crate::html::report_html(res, dir).as_bytes())
        .map_err(|e| e.to_string())?;
    Ok(plots)
}

/// How every `summary.md` a run's report writes starts.
const SUMMARY_MARK: &str = "# Benchmark `";

/// What the head of every `report.html` holds.
const HTML_MARK: &str = "<title>marchmesh ";

/// Bytes at the start of a report file searched for its mark.
const MARK_WINDOW: u64 = 4096;

/// Refuses to replace `path` when it is a regular file that a run's report did not write
/// (its first [`MARK_WINDOW`] bytes lack `mark`): `report FILE.json` writes beside the file,
/// and a `summary.md` or `report.html` of the user's there is not ours to overwrite. An
/// absent file, or one that is not regular (refused when replaced), passes.
fn check_regenerable(path: &Path, mark: &str) -> Result<(), String> {
    use std::io::Read;
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        return Ok(());
    };
    if !meta.file_type().is_file() {
        return Ok(());
    }
    let mut head = Vec::new();
    marchmesh_safeio::open_regular(path, u64::MAX)
        .and_then(|(file, _)| {
            file.take(MARK_WINDOW)
                .read_to_end(&mut head)
                .map_err(|source| marchmesh_safeio::SafeIoError::Io {
                    path: path.to_path_buf(),
                    action: "cannot read",
                    source,
                })
        })
        .map_err(|e| e.to_string())?;
    let ours = head.windows(mark.len()).any(|w| w == mark.as_bytes());
    if ours {
        Ok(())
    } else {
        Err(format!(
            "{}: exists and was not written by a marchmesh report (no {mark:?} in its head): not replaced (move it away to regenerate the report)",
            path.display()
        ))
    }
}

/// Creates a fresh run folder `<out>/<UTC timestamp>-<suite>` (suffix `-2`, `-3`, ... if the
/// name is taken: runs never overwrite each other) with `images/` inside. Returns the run id
/// and the folder.
pub fn create_run_dir(out: &Path, suite: &str) -> std::io::Result<(String, std::path::PathBuf)> {
    std::fs::create_dir_all(out)?;
    let stamp = crate::results::utc_strings(crate::results::now_secs()).1;
    let base = format!("{stamp}-{}", crate::bench::slug(suite));
    for n in 1..1000 {
        let id = if n == 1 {
            base.clone()
        } else {
            format!("{base}-{n}")
        };
        let dir = out.join(&id);
        match std::fs::create_dir(&dir) {
            Ok(()) => {
                std::fs::create_dir(dir.join("images"))?;
                return Ok((id, dir));
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::other(format!("too many runs named {base}")))
}

/// Why [`write_run`] stopped, and which of the files a message may point to it had written
/// by then.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{reason}")]
pub struct RunWriteError {
    /// `results.json` holds `res` (it was written and read back).
    pub results_json: bool,
    /// `summary.md` was written from `res`.
    pub summary_md: bool,
    /// What failed, naming the file.
    pub reason: String,
}

/// Writes `results.json`, then reads it back and writes `results.csv`, `summary.md`,
/// `plots/` and `report.html` from what was read, so `marchmesh report` on the folder reproduces them exactly.
/// Returns the plot file names.
///
/// Errors: the first write that failed, with which of `results.json` and `summary.md` were
/// written before it.
pub fn write_run(res: &Results, dir: &Path) -> Result<Vec<String>, RunWriteError> {
    let mut failed = RunWriteError {
        results_json: false,
        summary_md: false,
        reason: String::new(),
    };
    let json = dir.join("results.json");
    let back = res
        .write_json(&json)
        .and_then(|()| Results::read_json(&json))
        .map_err(|e| RunWriteError {
            reason: e.to_string(),
            ..failed.clone()
        })?;
    failed.results_json = true;
    back.write_csv(&dir.join("results.csv"))
        .map_err(|e| RunWriteError {
            reason: e.to_string(),
            ..failed.clone()
        })?;
    let mut summary_md = false;
    write_report_noting_summary(&back, dir, &mut summary_md).map_err(|reason| RunWriteError {
        summary_md,
        reason,
        ..failed
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::results::tests_support::row;
    use crate::verdicts::{Timing, headlines};

    #[test]
    fn axis_numbers_are_short() {
        assert_eq!(short_num(10_000_000.0), "10M");
        assert_eq!(short_num(250.0), "250");
        assert_eq!(short_num(0.125), "0.125");
        assert_eq!(short_num(45_000.0), "45k");
    }

    #[test]
    fn log_ticks_are_labelled_sparsely_enough_not_to_overlap() {
        use super::plots::{log_range, log_tick_label};
        // Two decades: 1, 2, 3, 5 of each; 6, 7, 8, 9 stay unlabelled grid lines.
        let (lo, hi) = log_range([150.0, 900.0].into_iter());
        assert_eq!((lo, hi), (100.0, 1000.0));
        let labels: Vec<String> = [
            100.0, 200.0, 300.0, 500.0, 600.0, 700.0, 800.0, 900.0, 1000.0,
        ]
        .iter()
        .map(|&v| log_tick_label(v, lo, hi))
        .collect();
        assert_eq!(labels, ["100", "200", "300", "500", "", "", "", "", "1000"]);
        // Four decades: 1, 2, 5; more: powers of ten only.
        assert_eq!(log_tick_label(3.0, 1.0, 1e4), "");
        assert_eq!(log_tick_label(5000.0, 1.0, 1e4), "5000");
        assert_eq!(log_tick_label(5e5, 1.0, 1e7), "");
        assert_eq!(log_tick_label(1e6, 1.0, 1e7), "1M");
        // Floating-point key points near a mantissa still count.
        assert_eq!(log_tick_label(199.99999999, lo, hi), "200");
    }

    #[test]
    fn bytes_are_human_readable() {
        assert_eq!(bytes(512), "512 B");
        assert_eq!(bytes(2048), "2.00 KiB");
        assert_eq!(bytes(45 << 20), "45.0 MiB");
        assert_eq!(bytes(300 << 30), "300 GiB");
    }

    #[test]
    fn headlines_compare_the_fastest_rows_above_the_threshold() {
        let a = row("sdf", "a", 10.0, Some(45.0), 100);
        let b = row("sdf", "b", 5.0, Some(30.0), 100);
        let c = row("mesh", "c", 30.0, Some(41.0), 2048);
        let h = headlines(&[a.clone(), b, c], 40.0, Timing::medians_only());
        assert_eq!(h.len(), 1);
        let h0 = h[0].to_string();
        assert!(h0.contains("sdf:a 10.0 ms (45.0 dB, 100 B) vs mesh:c 30.0 ms (41.0 dB, 2.00 KiB): sdf 3.00x faster than mesh, ratio of medians"), "{h0}");
        let low = row("mesh", "d", 1.0, Some(30.0), 2048);
        let h = headlines(&[a, low], 40.0, Timing::medians_only());
        assert!(h[0].contest.is_none());
        assert!(
            h[0].to_string().contains("mesh: none reaches 40 dB"),
            "{}",
            h[0]
        );
    }

    #[test]
    fn pareto_front_keeps_only_undominated_rows() {
        let a = row("sdf", "a", 10.0, Some(30.0), 100);
        let b = row("sdf", "b", 20.0, Some(25.0), 100); // slower and worse than a
        let c = row("mesh", "c", 5.0, Some(20.0), 1000);
        let d = row("mesh", "d", 30.0, Some(40.0), 1000);
        let e = row("mesh", "e", 1.0, None, 1000); // no accuracy: not on the front
        let rows = vec![&a, &b, &c, &d, &e];
        let front: Vec<&str> = pareto_front(&rows)
            .iter()
            .map(|&i| rows[i].quality.as_str())
            .collect();
        assert_eq!(front, ["c", "a", "d"]);
    }

    #[test]
    fn verdict_states_the_winner_per_accuracy_range_and_memory() {
        let a = row("sdf", "a", 10.0, Some(30.0), 100);
        let c = row("mesh", "c", 5.0, Some(20.0), 1000);
        let d = row("mesh", "d", 30.0, Some(40.0), 1000);
        let v = verdict(&[&a, &c, &d], Timing::medians_only()).join("\n");
        assert!(
            v.contains("Fastest configuration: mesh:c at 5.00 ms"),
            "{v}"
        );
        assert!(
            v.contains("mesh is faster for PSNR target 20.0 dB (mesh 2.00x faster than sdf, ratio of medians at 20.0 dB)"),
            "{v}"
        );
        assert!(
            v.contains("sdf is faster for PSNR target 30.0 dB (sdf 3.00x faster than mesh, ratio of medians at 30.0 dB)"),
            "{v}"
        );
        assert!(
            v.contains("PSNR target 40.0 dB: mesh (only mesh reaches it)"),
            "{v}"
        );
        assert!(v.contains("sdf uses 10.0x less than mesh"), "{v}");
    }
}
