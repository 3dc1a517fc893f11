//! `marchmesh bench`, `report`, `merge`, `findings` and `compare`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use marchmesh_harness::bench::{self, BenchOptions, Progress};
use marchmesh_harness::report;
use marchmesh_harness::results::{Provenance, Results};
use marchmesh_harness::suite;

use crate::BenchArgs;

pub(crate) fn command_line() -> String {
    std::env::args().collect::<Vec<_>>().join(" ")
}

/// Installs a Ctrl-C handler that sets the returned flag (second Ctrl-C exits at once).
fn stop_flag() -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let _ = ctrlc::set_handler(move || {
        if s.swap(true, Ordering::SeqCst) {
            eprintln!("\nsecond Ctrl-C: exiting without writing");
            std::process::exit(130);
        }
        eprintln!("\nCtrl-C: stopping after the current round (Ctrl-C again to abort)");
    });
    stop
}

struct Bars {
    /// Stderr is not a terminal (a log file, a pipe, a Slurm job): the bars are hidden there,
    /// so each configuration's start and every note are written as plain lines instead.
    plain: bool,
    multi: MultiProgress,
    overall: ProgressBar,
    current: Option<ProgressBar>,
    started: Instant,
    eta: bench::Eta,
}

/// The overall bar counts hundredths of a configuration, so it moves with every timed round.
const BAR_STEPS: f64 = 100.0;

impl Bars {
    fn new() -> Self {
        let multi = MultiProgress::new();
        let overall = multi.add(ProgressBar::new(0));
        overall.set_style(
            ProgressStyle::with_template("{prefix} [{bar:30}] {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        overall.set_prefix("bench");
        Self {
            plain: !std::io::IsTerminal::is_terminal(&std::io::stderr()),
            multi,
            overall,
            current: None,
            started: Instant::now(),
            eta: bench::Eta::new(0),
        }
    }

    /// Moves the overall bar to the work done and says it with the elapsed time and the ETA.
    fn show(&self) {
        self.overall
            .set_position((self.eta.done() * BAR_STEPS).round() as u64);
        let elapsed = self.started.elapsed().as_secs_f64();
        let eta = self
            .eta
            .remaining_s(elapsed)
            .map_or_else(|| "estimating".to_string(), duration);
        self.overall.set_message(format!(
            "{:.1}/{} configurations, {} elapsed, eta {eta}",
            self.eta.done(),
            self.eta.total(),
            duration(elapsed)
        ));
    }
}

/// Seconds as `42s`, `3m05s` or `1h02m`.
fn duration(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    match s {
        0..60 => format!("{s}s"),
        60..3600 => format!("{}m{:02}s", s / 60, s % 60),
        _ => format!("{}h{:02}m", s / 3600, s / 60 % 60),
    }
}

/// Writes `results.json` of the run so far after every rotation block, atomically: a crash or
/// kill loses at most the block being measured, and the folder says what is missing.
struct Checkpointing<'a> {
    bars: Bars,
    template: &'a Results,
    dir: &'a Path,
}

impl Progress for Checkpointing<'_> {
    fn start(&mut self, total: usize) {
        self.bars.start(total);
    }
    fn config(&mut self, index: usize, id: &str) {
        self.bars.config(index, id);
    }
    fn phase(&mut self, what: &str) {
        self.bars.phase(what);
    }
    fn done(&mut self, index: usize) {
        self.bars.done(index);
    }
    fn note(&mut self, message: &str) {
        self.bars.note(message);
    }
    fn advanced(&mut self, index: usize, fraction: f64) {
        self.bars.advanced(index, fraction);
    }
    fn checkpoint(&mut self, so_far: &bench::Outcome) {
        let mut results = results_of(self.template.clone(), so_far.clone());
        // A checkpoint is a run that has not finished: if the process is killed now, the
        // file must say so.
        results.interrupted = true;
        if let Err(e) = results.write_json(&self.dir.join("results.json")) {
            self.bars.note(&format!("checkpoint not written: {e}"));
        }
    }
}

/// `template` (suite, provenance, ...) with what `outcome` measured appended to what it
/// holds (nothing for a new run; the measured part of a resumed one); `missing` is the
/// outcome's.
fn results_of(template: Results, outcome: bench::Outcome) -> Results {
    let mut r = Results {
        interrupted: outcome.interrupted,
        rotation_seed: template.rotation_seed.or(Some(outcome.rotation_seed)),
        missing: outcome.missing,
        ..template
    };
    r.rows.extend(outcome.rows);
    r.failures.extend(outcome.failures);
    r.references.extend(outcome.references);
    r.steps_histograms.extend(outcome.steps_histograms);
    r.timings.extend(outcome.timings);
    r.write_errors.extend(outcome.write_errors);
    r
}

impl Progress for Bars {
    fn start(&mut self, total: usize) {
        self.eta = bench::Eta::new(total);
        self.overall.set_length(total as u64 * BAR_STEPS as u64);
        self.show();
        if self.plain {
            eprintln!("bench: {total} configurations");
        }
    }
    fn config(&mut self, index: usize, id: &str) {
        if self.plain {
            eprintln!("bench: [{}/{}] {id}", index + 1, self.eta.total());
        }
        if let Some(b) = self.current.take() {
            b.finish_and_clear();
            self.multi.remove(&b);
        }
        let bar = self.multi.add(ProgressBar::new_spinner());
        bar.set_style(
            ProgressStyle::with_template("  {spinner} {prefix}: {msg} ({elapsed})")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        bar.set_prefix(format!("[{}] {id}", index + 1));
        bar.enable_steady_tick(std::time::Duration::from_millis(200));
        self.current = Some(bar);
    }
    fn phase(&mut self, what: &str) {
        if let Some(b) = &self.current {
            b.set_message(what.to_string());
        }
    }
    fn done(&mut self, index: usize) {
        self.eta.advance(index, 1.0);
        self.show();
    }
    fn note(&mut self, message: &str) {
        if self.plain {
            eprintln!("note: {message}");
        } else {
            let _ = self.multi.println(format!("note: {message}"));
        }
    }
    fn advanced(&mut self, index: usize, fraction: f64) {
        self.eta.advance(index, fraction);
        self.show();
    }
}

/// Appends a formatted line to a `String`.
macro_rules! outln {
    ($out:expr, $($arg:tt)*) => {{
        use std::fmt::Write as _;
        let _ = writeln!($out, $($arg)*);
    }};
}

/// Writes `text` to stdout; a closed pipe (`marchmesh compare A B | head`) is not an error.
fn print_ignoring_broken_pipe(text: &str) -> Result<()> {
    use std::io::Write as _;
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e).context("writing to stdout"),
        _ => Ok(()),
    }
}

pub fn bench(args: BenchArgs) -> Result<()> {
    // Installed before the run folder exists, so an interrupt at any moment after the folder
    // appears stops the run cleanly and writes what was measured.
    let stop = stop_flag();
    if let Some(run) = &args.resume {
        return resume(&args, run, stop);
    }
    // The built-in scenes are needed only for a suite given by name.
    let suite_path = crate::assets::suite_file(&args.suite)?;
    let suite = suite::load(&suite_path)?;
    if let Some(t) = args.threads.filter(|&t| t > marchmesh_core::MAX_THREADS) {
        bail!(
            "--threads {t} is over the limit of {} (0 = all cores)",
            marchmesh_core::MAX_THREADS
        );
    }
    let seed = args
        .seed
        .unwrap_or_else(marchmesh_harness::schedule::clock_seed);
    let options = BenchOptions {
        quick: args.quick,
        threads: args.threads,
        filter: args.filter.clone(),
        images_dir: None,
        seed,
        hold_memory_bytes: args.memory_limit_mib.saturating_mul(1 << 20),
        machine: marchmesh_harness::results::hostname(),
    };
    let mut configs = bench::configurations(&suite, &options);
    for s in &suite.skipped {
        eprintln!("skipped: {s}");
    }
    // Checked for --list as for a run: a listing that is empty is the same mistake.
    if configs.is_empty() {
        bail!(
            "no configuration of suite {} matches{}",
            suite_path.display(),
            args.filter
                .as_deref()
                .map(|f| format!(" the filter {f:?}"))
                .unwrap_or_default(),
        );
    }
    if let Some(shard) = args.shard {
        configs = bench::shard(&configs, shard).map_err(anyhow::Error::msg)?;
    }
    if args.list {
        let mut text = String::new();
        for c in &configs {
            outln!(text, "{}", c.id);
        }
        return print_ignoring_broken_pipe(&text);
    }
    // Read before the run, so a bad anchor file fails in a second, not after the suite.
    let anchors = args
        .anchor
        .iter()
        .map(|p| marchmesh_harness::anchors::read_anchor(p))
        .collect::<Result<Vec<_>, _>>()
        .context("--anchor")?;
    crate::refuse_file_as_folder(&args.results_dir, "--out")?;
    let (run_id, dir) = report::create_run_dir(&args.results_dir, &suite.name)
        .with_context(|| format!("creating a run folder in {}", args.results_dir.display()))?;
    eprintln!(
        "suite {} ({}){}: {} configurations, rotation seed {seed} -> {}",
        suite.name,
        suite_path.display(),
        args.shard
            .map(|s| format!(" shard {s}"))
            .unwrap_or_default(),
        configs.len(),
        dir.display()
    );
    let template = Results {
        run_id: run_id.clone(),
        suite: suite.name.clone(),
        suite_file: suite_path.display().to_string(),
        description: suite.description.clone(),
        provenance: Provenance::collect(command_line()),
        interrupted: false,
        rows: Vec::new(),
        failures: Vec::new(),
        skipped: suite.skipped.clone(),
        references: Vec::new(),
        steps_histograms: Default::default(),
        timings: Default::default(),
        rotation_seed: Some(seed),
        missing: configs.iter().map(|c| c.id.clone()).collect(),
        shard: args.shard.map(|s| s.to_string()),
        merged_from: Vec::new(),
        write_errors: Vec::new(),
        anchors,
    };
    // The folder says from the start what is still missing, and that the run has not
    // finished (a killed run keeps this file).
    Results {
        interrupted: true,
        ..template.clone()
    }
    .write_json(&dir.join("results.json"))
    .with_context(|| format!("writing results into {}", dir.display()))?;
    let options = BenchOptions {
        images_dir: suite.images.then(|| dir.join("images")),
        ..options
    };
    measure(
        &configs,
        &options,
        &template,
        &dir,
        &Default::default(),
        stop,
    )
}

/// Refuses to resume a run whose `results.json` no interrupted run writes (a configuration
/// with two rows, listed twice as missing, or both measured and missing: resuming it would
/// leave duplicate rows), or whose `images/` or `plots/` is not a folder of its own (a
/// symbolic link would send the resumed images or plots elsewhere).
fn check_resumable(previous: &Results, json: &Path, run: &Path) -> Result<()> {
    let mut rows = std::collections::HashSet::new();
    if let Some(id) = previous
        .rows
        .iter()
        .map(|r| r.config_id.as_str())
        .find(|id| !rows.insert(*id))
    {
        bail!(
            "{}: configuration {id} has more than one row: not a file an interrupted run writes, nothing was measured",
            json.display()
        );
    }
    let mut missing = std::collections::HashSet::new();
    if let Some(id) = previous
        .missing
        .iter()
        .map(String::as_str)
        .find(|id| rows.contains(id) || !missing.insert(*id))
    {
        bail!(
            "{}: configuration {id} is listed as missing twice or also has a row: not a file an interrupted run writes, nothing was measured",
            json.display()
        );
    }
    for folder in ["images", "plots"] {
        marchmesh_safeio::check_own_folder(&run.join(folder)).map_err(|e| {
            anyhow::anyhow!(
                "{e}: a resumed run writes its {folder} only into its own folder, nothing was measured"
            )
        })?;
    }
    Ok(())
}

/// `bench --resume RUN`: the configurations RUN's results.json lists as missing, measured
/// into RUN on top of what it holds.
fn resume(args: &BenchArgs, run: &Path, stop: Arc<AtomicBool>) -> Result<()> {
    let json = run.join("results.json");
    let previous = Results::read_json(&json)
        .with_context(|| format!("{} not resumed, nothing was measured", run.display()))?;
    if !previous.is_incomplete() {
        bail!(
            "{}: the run finished (nothing missing, not interrupted): nothing to resume",
            run.display()
        );
    }
    check_resumable(&previous, &json, run)?;
    let suite_path = PathBuf::from(&previous.suite_file);
    let suite =
        suite::load(&suite_path).with_context(|| format!("the suite of {}", json.display()))?;
    if suite.name != previous.suite {
        bail!(
            "{}: the run is of suite {:?} but {} is now suite {:?}",
            run.display(),
            previous.suite,
            suite_path.display(),
            suite.name
        );
    }
    if let Some(t) = args.threads.filter(|&t| t > marchmesh_core::MAX_THREADS) {
        bail!(
            "--threads {t} is over the limit of {} (0 = all cores)",
            marchmesh_core::MAX_THREADS
        );
    }
    let options = BenchOptions {
        quick: args.quick,
        threads: args.threads,
        filter: args.filter.clone(),
        images_dir: suite.images.then(|| run.join("images")),
        seed: previous.rotation_seed.unwrap_or_default(),
        hold_memory_bytes: args.memory_limit_mib.saturating_mul(1 << 20),
        machine: marchmesh_harness::results::hostname(),
    };
    let wanted: std::collections::HashSet<&str> =
        previous.missing.iter().map(String::as_str).collect();
    let configs: Vec<bench::Config> = bench::configurations(&suite, &options)
        .into_iter()
        .filter(|c| wanted.contains(c.id.as_str()))
        .collect();
    let found: std::collections::HashSet<&str> = configs.iter().map(|c| c.id.as_str()).collect();
    let unknown: Vec<&str> = previous
        .missing
        .iter()
        .map(String::as_str)
        .filter(|id| !found.contains(id))
        .collect();
    if !unknown.is_empty() {
        bail!(
            "{} missing configurations of {} are not in {} as expanded now (first: {}): pass the run's --filter, --threads and --quick",
            unknown.len(),
            run.display(),
            suite_path.display(),
            unknown[0]
        );
    }
    // A run folder copied without its images (or whose images/ was removed) gets the folder
    // back: the images of the resumed configurations are written into it, not lost.
    if let Some(images) = &options.images_dir {
        marchmesh_safeio::own_folder(images)
            .map_err(|e| anyhow::anyhow!("{e}: nothing was measured"))?;
    }
    // Reference images the interrupted run already wrote stay; a second copy is not an error.
    let existing_images: std::collections::HashSet<PathBuf> = std::fs::read_dir(run.join("images"))
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    let mut template = Results {
        interrupted: true,
        missing: configs.iter().map(|c| c.id.clone()).collect(),
        ..previous
    };
    template.provenance.command = format!(
        "{} (resumed: {})",
        template.provenance.command,
        command_line()
    );
    template
        .write_json(&json)
        .with_context(|| format!("writing {}", json.display()))?;
    eprintln!(
        "resuming {}: {} configurations missing, rotation seed {}",
        run.display(),
        configs.len(),
        options.seed
    );
    let template = Results {
        interrupted: false,
        ..template
    };
    measure(&configs, &options, &template, run, &existing_images, stop)
}

/// Runs `configs` into the run folder `dir` (checkpointing `results.json` after every
/// rotation block on top of `template`), writes the report and fails when anything is
/// missing, failed or not written. Images in `kept` (written by the run being resumed) are
/// not written again, and that is not an error. `stop` (set by Ctrl-C) ends the run after the
/// current round.
fn measure(
    configs: &[bench::Config],
    options: &BenchOptions,
    template: &Results,
    dir: &Path,
    kept: &std::collections::HashSet<PathBuf>,
    stop: Arc<AtomicBool>,
) -> Result<()> {
    let mut progress = Checkpointing {
        bars: Bars::new(),
        template,
        dir,
    };
    let outcome = bench::run(configs, options, &mut progress, &stop);
    if let Some(b) = progress.bars.current.take() {
        b.finish_and_clear();
    }
    progress.bars.overall.finish_and_clear();
    let elapsed = progress.bars.started.elapsed();
    let mut results = results_of(template.clone(), outcome);
    results.write_errors.retain(|e| {
        !kept
            .iter()
            .any(|p| e.starts_with(&format!("{}: already exists", p.display())))
    });
    results.provenance.load_average_1m_end = marchmesh_harness::results::load_average_1m();
    // A report file that cannot be written (a full disk) is one more write error: the
    // summary below still names every failure and the run still exits nonzero.
    let report_written = report::write_run(&results, dir);
    let written = match report_written.as_ref() {
        Ok(plots) => format!("{} plots and report.html", plots.len()),
        Err(e) => {
            results
                .write_errors
                .push(format!("writing results into {}: {e}", dir.display()));
            "the report was not written (see below)".to_string()
        }
    };
    out!(
        "{}: {} configurations measured, {} failed, {} missing{} in {:.1} s; {written}",
        dir.display(),
        results.rows.len(),
        results.failures.len(),
        results.missing.len(),
        if results.interrupted {
            " (interrupted)"
        } else {
            ""
        },
        elapsed.as_secs_f64(),
    );
    print_answer(&results, dir, report_written.is_ok());
    // Where the lists below can also be read: only files this run has written in full (a
    // summary.md written before a later report file failed lacks that failure).
    let (json_written, summary_written) = match &report_written {
        Ok(_) => (true, true),
        Err(e) => (e.results_json, false),
    };
    let listed_in = |file: &str, written: bool| {
        if written {
            format!("listed above and in {}", dir.join(file).display())
        } else {
            format!("listed above; {file} was not written")
        }
    };
    for f in &results.failures {
        eprintln!("failed: {}: {}", f.config_id, f.error);
    }
    for m in &results.missing {
        eprintln!("missing: {m}");
    }
    for e in &results.write_errors {
        eprintln!("not written: {e}");
    }
    if results.interrupted {
        bail!(
            "interrupted: {} of {} configurations missing ({})",
            results.missing.len(),
            configs.len(),
            listed_in("results.json", json_written)
        );
    }
    if !results.write_errors.is_empty() {
        bail!(
            "{} files of the run could not be written ({})",
            results.write_errors.len(),
            listed_in("summary.md", summary_written)
        );
    }
    if !results.failures.is_empty() {
        bail!(
            "{} of {} configurations failed ({})",
            results.failures.len(),
            configs.len(),
            listed_in("summary.md", summary_written)
        );
    }
    Ok(())
}

/// Prints the answer of a run: per scene setting, the verdict at each accuracy target (the
/// decision chart of its summary), then where the report is if it was written.
fn print_answer(results: &Results, dir: &Path, report_written: bool) {
    let chart = marchmesh_harness::decision::DecisionChart::of_run(results);
    if chart.is_empty() {
        out!("answer: no configuration measured accuracy, so no verdict at matched accuracy");
    } else {
        out!(
            "answer: the fastest backend among the configurations reaching each accuracy target (PSNR vs the reference), runner-up time / winner time with its 95% CI:"
        );
        let text = chart.terminal();
        out!("{}", text.trim_end_matches('\n'));
    }
    if report_written {
        out!("report: {}", dir.join("report.html").display());
    }
}

/// `marchmesh findings RUN... --out FILE [--force]`.
pub fn findings(runs: &[PathBuf], anchors: &[PathBuf], out: &Path, force: bool) -> Result<()> {
    let anchors = anchors
        .iter()
        .map(|p| marchmesh_harness::anchors::read_anchor(p))
        .collect::<Result<Vec<_>, _>>()
        .context("--anchor")?;
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty())
        .with_context(|| format!("--out {}: needs a file name", out.display()))?;
    let plots_link = format!("{stem}-plots");
    let plots_dir = out
        .parent()
        .map_or_else(|| PathBuf::from(&plots_link), |p| p.join(&plots_link));
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        marchmesh_safeio::check_folder_path(parent)
            .with_context(|| format!("--out {}", out.display()))?;
    }
    // Checked before anything is written: with --force only a regular file is replaced.
    if let Ok(meta) = std::fs::symlink_metadata(out)
        && !meta.file_type().is_file()
    {
        bail!(
            "--out {}: not a regular file (a folder, device or symbolic link): not replaced, even with --force (nothing was written)",
            out.display()
        );
    }
    if !force {
        if out.exists() || std::fs::symlink_metadata(out).is_ok() {
            bail!(
                "--out {}: exists; pass --force to replace it and {} (nothing was overwritten)",
                out.display(),
                plots_dir.display()
            );
        }
        refuse_non_empty(&plots_dir, "plots folder")?;
    }
    // The plots folder belongs to the document (its stale plots are removed): a symbolic link
    // there would send the writes and removals into a folder of the user's.
    marchmesh_safeio::check_own_folder(&plots_dir).with_context(|| {
        format!(
            "--out {}: its plots folder is not replaced, even with --force",
            out.display()
        )
    })?;
    let doc_dir = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
        .to_path_buf();
    let inputs = runs
        .iter()
        .map(|r| {
            let json = results_path(r);
            let results = Results::read_json(&json)?;
            // The run as the document links it: its folder relative to the document's.
            let folder = json
                .parent()
                .filter(|p| !p.as_os_str().is_empty())
                .unwrap_or(Path::new("."));
            let name = run_link(&doc_dir, folder).with_context(|| {
                format!(
                    "--out {}: cannot link run {} from there (nothing was written)",
                    out.display(),
                    r.display()
                )
            })?;
            Ok(marchmesh_harness::findings::Run {
                name,
                results: results.markdown_safe(),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let (text, plot_count) =
        marchmesh_harness::findings::write_findings(&inputs, &anchors, &plots_dir, &plots_link)
            .map_err(anyhow::Error::msg)
            .context("writing the findings plots")?;
    let write = if force {
        marchmesh_safeio::replace_regular(out, text.as_bytes())
    } else {
        marchmesh_safeio::publish_new(out, text.as_bytes())
    };
    write.with_context(|| format!("writing {}", out.display()))?;
    out!(
        "{}: findings from {} runs ({} plots in {})",
        out.display(),
        inputs.len(),
        plot_count,
        plots_dir.display()
    );
    let unfinished: Vec<String> = inputs
        .iter()
        .filter(|r| r.results.is_incomplete() || !r.results.failures.is_empty())
        .map(|r| {
            format!(
                "{} ({} missing, {} failed{})",
                r.name,
                r.results.missing.len(),
                r.results.failures.len(),
                if r.results.interrupted {
                    ", interrupted"
                } else {
                    ""
                }
            )
        })
        .collect();
    if !unfinished.is_empty() {
        bail!(
            "{} of {} runs are incomplete or have failures (marked in {}): {}",
            unfinished.len(),
            inputs.len(),
            out.display(),
            unfinished.join(", ")
        );
    }
    Ok(())
}

/// The path of run folder `run` as seen from folder `doc_dir` (both resolved: symlinks,
/// `..`), `/`-separated, for the findings' links to `RUN/summary.md`.
///
/// Errors: a folder cannot be resolved (it does not exist), or the path is not valid UTF-8.
fn run_link(doc_dir: &Path, run: &Path) -> Result<String> {
    let from = std::fs::canonicalize(doc_dir)
        .with_context(|| format!("resolving the folder {}", doc_dir.display()))?;
    let to = std::fs::canonicalize(run)
        .with_context(|| format!("resolving the run folder {}", run.display()))?;
    let rel = relative_path(&from, &to);
    let parts: Vec<&str> = rel
        .components()
        .map(|c| c.as_os_str().to_str())
        .collect::<Option<_>>()
        .with_context(|| format!("{} is not valid UTF-8", rel.display()))?;
    Ok(if parts.is_empty() {
        ".".to_string()
    } else {
        parts.join("/")
    })
}

/// `to` relative to `from` (both absolute and resolved): `..` up to their common ancestor,
/// then down.
fn relative_path(from: &Path, to: &Path) -> PathBuf {
    let (f, t): (Vec<_>, Vec<_>) = (from.components().collect(), to.components().collect());
    let common = f.iter().zip(&t).take_while(|(a, b)| a == b).count();
    let mut rel = PathBuf::new();
    for _ in common..f.len() {
        rel.push("..");
    }
    for c in &t[common..] {
        rel.push(c.as_os_str());
    }
    rel
}

/// `marchmesh merge RUN... --out DIR`.
pub fn merge(runs: &[PathBuf], out: &Path) -> Result<()> {
    refuse_non_empty(out, "--out")?;
    let inputs = runs
        .iter()
        .map(|r| {
            let res = Results::read_json(&results_path(r))?;
            Ok((r.display().to_string(), res))
        })
        .collect::<Result<Vec<_>>>()?;
    let run_id = out
        .file_name()
        .map_or_else(|| "merged".into(), |n| n.to_string_lossy().into_owned());
    let merged = Results::merge(inputs, run_id, command_line())?;
    marchmesh_safeio::create_folder(out).with_context(|| format!("creating {}", out.display()))?;
    let plots = report::write_run(&merged, out)
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("writing the merged run into {}", out.display()))?;
    let machines: std::collections::BTreeSet<&str> =
        merged.rows.iter().map(|r| r.machine.as_str()).collect();
    // Configurations of shards not given are in no input: the count then is a lower bound.
    let missing = if shard_problems(&merged).is_empty() {
        format!("{} missing", merged.missing.len())
    } else {
        format!(
            "{} missing listed (more in the shards not given)",
            merged.missing.len()
        )
    };
    out!(
        "{}: {} runs merged, {} configurations measured on {} machine(s), {} failed, {missing}; {} plots and report.html",
        out.display(),
        merged.merged_from.len(),
        merged.rows.len(),
        machines.len(),
        merged.failures.len(),
        plots.len()
    );
    incomplete_merge(&merged)
}

/// What is wrong with the shards a merged run holds: shards of different counts, or shards
/// of the suite not given (empty for unsharded runs and complete sets).
fn shard_problems(merged: &Results) -> Vec<String> {
    let mut problems = Vec::new();
    let mut shard_counts = std::collections::BTreeMap::<u64, Vec<u64>>::new();
    for m in &merged.merged_from {
        if let Some((k, n)) = m.shard.as_deref().and_then(|s| s.split_once('/'))
            && let (Ok(k), Ok(n)) = (k.parse::<u64>(), n.parse::<u64>())
        {
            shard_counts.entry(n).or_default().push(k);
        }
    }
    for (n, given) in &shard_counts {
        if shard_counts.len() > 1 {
            problems.push(format!(
                "shards of different counts ({:?}) were merged",
                shard_counts.keys().collect::<Vec<_>>()
            ));
            break;
        }
        let absent: Vec<String> = (1..=*n)
            .filter(|k| !given.contains(k))
            .take(20)
            .map(|k| format!("{k}/{n}"))
            .collect();
        if !absent.is_empty() {
            problems.push(format!(
                "shard(s) {} not given: their configurations are missing",
                absent.join(", ")
            ));
        }
    }
    problems
}

/// The error of a merged run that is not the whole suite: an input was interrupted or
/// killed, configurations failed or are missing, or shards of the suite were not given.
fn incomplete_merge(merged: &Results) -> Result<()> {
    let mut problems = shard_problems(merged);
    if merged.interrupted {
        problems.push("an input run was interrupted or killed".into());
    }
    for m in merged.missing.iter().take(20) {
        eprintln!("missing: {m}");
    }
    if !merged.missing.is_empty() {
        problems.push(format!("{} configurations missing", merged.missing.len()));
    }
    for f in &merged.failures {
        eprintln!("failed: {}: {}", f.config_id, f.error);
    }
    if !merged.failures.is_empty() {
        problems.push(format!("{} configurations failed", merged.failures.len()));
    }
    if !problems.is_empty() {
        bail!("the merged run is incomplete: {}", problems.join("; "));
    }
    Ok(())
}

fn results_path(p: &Path) -> PathBuf {
    if p.is_dir() {
        p.join("results.json")
    } else {
        p.to_path_buf()
    }
}

pub fn report(dir: &Path) -> Result<()> {
    let res = Results::read_json(&results_path(dir))?;
    let out = if dir.is_dir() {
        dir.to_path_buf()
    } else {
        dir.parent()
            .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
    };
    let plots = report::write_report(&res, &out)
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("writing the report into {}", out.display()))?;
    out!(
        "{}: summary.md, report.html and {} plots regenerated from {} rows",
        out.display(),
        plots.len(),
        res.rows.len()
    );
    Ok(())
}

pub fn compare(a: &Path, b: &Path) -> Result<()> {
    let ra = Results::read_json(&results_path(a))?;
    let rb = Results::read_json(&results_path(b))?;
    let mut out = String::new();
    outln!(
        out,
        "A = {} ({}), B = {} ({}); ratios are B / A",
        ra.run_id,
        ra.provenance.git_commit,
        rb.run_id,
        rb.provenance.git_commit
    );
    let (pa, pb) = (&ra.provenance, &rb.provenance);
    outln!(out, "{}", clocks_and_loads(&ra, &rb));
    let clock = ratio_clock(&ra, &rb);
    if pa.cpu_model != pb.cpu_model || pa.machine != pb.machine {
        outln!(
            out,
            "note: A ran on {} ({}), B on {} ({}): the ratios compare machines as well as builds",
            pa.machine,
            pa.cpu_model,
            pb.machine,
            pb.cpu_model
        );
    }
    outln!(
        out,
        "{:<60} {:>10} {:>10} {:>9} {:>9} {:>9} {:>10}",
        "configuration",
        "render A",
        "render B",
        "render",
        "build",
        "memory",
        "PSNR B-A"
    );
    let rows_b: std::collections::HashMap<&str, &marchmesh_harness::results::Row> =
        rb.rows.iter().map(|y| (y.config_id.as_str(), y)).collect();
    let ids_a: std::collections::HashSet<&str> =
        ra.rows.iter().map(|x| x.config_id.as_str()).collect();
    // A ratio of two measured values; `n/a` where a side is zero (no meaningful ratio).
    let ratio = |b: f64, a: f64| (a > 0.0 && b > 0.0).then(|| b / a);
    let show = |r: Option<f64>| r.map_or_else(|| "n/a".to_string(), |r| format!("{r:.3}x"));
    let mut matched = 0;
    let mut ratios = 0;
    let mut log_sum = 0.0;
    for x in &ra.rows {
        let Some(y) = rows_b.get(x.config_id.as_str()) else {
            continue;
        };
        matched += 1;
        let render = ratio(clock.median_ms(y), clock.median_ms(x));
        if let Some(r) = render {
            ratios += 1;
            log_sum += r.ln();
        }
        let psnr = match (x.psnr_db, y.psnr_db) {
            (Some(p), Some(q)) => format!("{:+.2}", q - p),
            _ => "n/a".into(),
        };
        outln!(
            out,
            "{:<60} {:>8.2}ms {:>8.2}ms {:>9} {:>9} {:>9} {:>10}",
            x.config_id,
            clock.median_ms(x),
            clock.median_ms(y),
            show(render),
            show(ratio(y.build_ms_total, x.build_ms_total)),
            show(ratio(y.memory_bytes as f64, x.memory_bytes as f64)),
            psnr
        );
    }
    let only_a = ra.rows.len() - matched;
    let only_b = rb
        .rows
        .iter()
        .filter(|y| !ids_a.contains(y.config_id.as_str()))
        .count();
    if matched == 0 {
        bail!("the runs share no configuration ({only_a} only in A, {only_b} only in B)");
    }
    outln!(
        out,
        "{matched} configurations matched (geometric mean render ratio {}); {only_a} only in A, {only_b} only in B",
        show((ratios > 0).then(|| (log_sum / ratios as f64).exp()))
    );
    verdict_view(&mut out, &ra, &rb);
    print_ignoring_broken_pipe(&out)
}

/// The line `compare` prints before its ratios: each run's verdict clock and the load average
/// it ran under (start -> end, on how many logical cores), so a ratio read between a quiet
/// and a busy run is read as such.
fn clocks_and_loads(a: &Results, b: &Results) -> String {
    use marchmesh_harness::verdicts::Clock;
    let one = |name: &str, r: &Results| {
        let p = &r.provenance;
        let load = match (p.load_average_1m, p.load_average_1m_end) {
            (Some(s), Some(e)) => format!("load {s:.2} -> {e:.2}"),
            (Some(s), None) => format!("load {s:.2} at the start"),
            _ => "load not recorded".to_string(),
        };
        format!(
            "{name} on {} time ({load} on {} logical cores)",
            Clock::for_run(r).name(),
            p.logical_cores
        )
    };
    format!(
        "clocks: {}, {}; per-configuration render times below on {} time (CPU only when both runs are judged on it)",
        one("A", a),
        one("B", b),
        ratio_clock(a, b).name()
    )
}

/// The clock of `compare`'s per-configuration ratios: CPU time when both runs' verdicts use
/// it, else wall time.
fn ratio_clock(a: &Results, b: &Results) -> marchmesh_harness::verdicts::Clock {
    use marchmesh_harness::verdicts::Clock;
    if Clock::for_run(a) == Clock::Cpu && Clock::for_run(b) == Clock::Cpu {
        Clock::Cpu
    } else {
        Clock::Wall
    }
}

/// Whether every verdict of A (headlines at `HEADLINE_MIN_PSNR_DB` and matched-accuracy claims) holds
/// in B, each run read on its own clock, and how far each speed ratio moved.
fn verdict_view(out: &mut String, ra: &Results, rb: &Results) {
    use marchmesh_harness::verdicts::{
        Clock, HEADLINE_MIN_PSNR_DB, compare_runs, movement_summary,
    };
    let claims = compare_runs(ra, rb, HEADLINE_MIN_PSNR_DB);
    outln!(
        out,
        "\nverdicts (A on {} time, B on {} time; moved = change of A's winner / runner-up time ratio):",
        Clock::for_run(ra).name(),
        Clock::for_run(rb).name()
    );
    if claims.is_empty() {
        outln!(
            out,
            "no verdict is in both runs (no setting has sdf and mesh rows with accuracy)"
        );
        return;
    }
    outln!(
        out,
        "{:<64} {:>10} {:>10} {:>6} {:>8}",
        "claim",
        "winner A",
        "winner B",
        "agree",
        "moved"
    );
    for c in &claims {
        outln!(
            out,
            "{:<64} {:>10} {:>10} {:>6} {:>8}",
            c.claim,
            c.winners.0,
            c.winners.1,
            if c.agree { "yes" } else { "NO" },
            c.moved_pct.map_or("n/a".into(), |m| format!("{m:.1}%"))
        );
    }
    if let Some((moved, disagree)) = movement_summary(&claims) {
        let headlines: Vec<_> = claims
            .iter()
            .filter(|c| c.claim.starts_with("headline"))
            .collect();
        let headline_max = headlines
            .iter()
            .filter_map(|c| c.moved_pct)
            .fold(0.0_f64, f64::max);
        outln!(
            out,
            "{} claims: {disagree} disagree; ratios moved by median {:.1}%, at most {:.1}%; headlines: {} of {} agree, at most {headline_max:.1}% moved",
            claims.len(),
            moved.median,
            moved.max,
            headlines.iter().filter(|c| c.agree).count(),
            headlines.len()
        );
    }
}

/// Refuses `dir` (named by `flag` in the message) if it exists and is not an empty folder.
pub(crate) fn refuse_non_empty(dir: &std::path::Path, flag: &str) -> Result<()> {
    crate::refuse_file_as_folder(dir, flag)?;
    match std::fs::read_dir(dir) {
        Ok(mut entries) => {
            if entries.next().is_some() {
                bail!(
                    "{flag} {}: folder is not empty; choose a new or empty folder (nothing was overwritten)",
                    dir.display()
                );
            }
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e).with_context(|| format!("{flag} {}", dir.display())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths_climb_to_the_common_folder() {
        let p = |s: &str| PathBuf::from(s);
        assert_eq!(relative_path(&p("/a/b"), &p("/a/b/run")), p("run"));
        assert_eq!(relative_path(&p("/a/docs"), &p("/a/b/run")), p("../b/run"));
        assert_eq!(relative_path(&p("/a/b/run"), &p("/a/b/run")), p(""));
    }

    #[test]
    fn the_bar_reads_durations_compactly() {
        assert_eq!(duration(42.4), "42s");
        assert_eq!(duration(185.0), "3m05s");
        assert_eq!(duration(3720.0), "1h02m");
    }
}
