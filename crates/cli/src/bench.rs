//! `marchmesh bench`, `report`, `compare` and `stability`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use marchmesh_harness::bench::{self, BenchOptions, Progress};
use marchmesh_harness::report;
use marchmesh_harness::results::{Provenance, Results, utc_strings};
use marchmesh_harness::suite;

use crate::{BenchArgs, StabilityArgs};

fn command_line() -> String {
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
        eprintln!("\nCtrl-C: stopping after the current configuration (Ctrl-C again to abort)");
    });
    stop
}

struct Bars {
    multi: MultiProgress,
    overall: ProgressBar,
    current: Option<ProgressBar>,
    started: Instant,
}

impl Bars {
    fn new() -> Self {
        let multi = MultiProgress::new();
        let overall = multi.add(ProgressBar::new(0));
        overall.set_style(
            ProgressStyle::with_template(
                "{prefix} [{bar:30}] {pos}/{len} configurations, {elapsed} elapsed, eta {eta}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        overall.set_prefix("bench");
        Self {
            multi,
            overall,
            current: None,
            started: Instant::now(),
        }
    }
}

impl Progress for Bars {
    fn start(&mut self, total: usize) {
        self.overall.set_length(total as u64);
    }
    fn config(&mut self, index: usize, id: &str) {
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
    fn done(&mut self, _index: usize) {
        if let Some(b) = self.current.take() {
            b.finish_and_clear();
            self.multi.remove(&b);
        }
        self.overall.inc(1);
    }
    fn note(&mut self, message: &str) {
        let _ = self.multi.println(format!("note: {message}"));
    }
}

fn repo_root() -> PathBuf {
    // Suites are looked up under the current folder, then next to the executable's repo.
    let cwd = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."));
    if cwd.join("scenes/suites").is_dir() {
        return cwd;
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

pub fn bench(args: BenchArgs) -> Result<()> {
    let suite_path = suite::locate(&args.suite, &repo_root());
    let suite = suite::load(&suite_path)?;
    let options = BenchOptions {
        quick: args.quick,
        threads: args.threads,
        filter: args.filter.clone(),
        images_dir: None,
    };
    let configs = bench::configurations(&suite, &options);
    for s in &suite.skipped {
        eprintln!("skipped: {s}");
    }
    if args.list {
        for c in &configs {
            println!("{}", c.id);
        }
        return Ok(());
    }
    if configs.is_empty() {
        bail!(
            "no configuration of suite {} matches the filter {:?}",
            suite_path.display(),
            args.filter
        );
    }
    let (run_id, dir) = report::create_run_dir(&args.out, &suite.name)
        .with_context(|| format!("creating a run folder in {}", args.out.display()))?;
    eprintln!(
        "suite {} ({}): {} configurations -> {}",
        suite.name,
        suite_path.display(),
        configs.len(),
        dir.display()
    );
    let provenance = Provenance::collect(command_line());
    let options = BenchOptions {
        images_dir: suite.images.then(|| dir.join("images")),
        ..options
    };
    let stop = stop_flag();
    let mut bars = Bars::new();
    let outcome = bench::run(&configs, &options, &mut bars, &stop);
    bars.overall.finish_and_clear();
    let elapsed = bars.started.elapsed();
    let results = Results {
        run_id: run_id.clone(),
        suite: suite.name.clone(),
        suite_file: suite_path.display().to_string(),
        description: suite.description.clone(),
        provenance,
        interrupted: outcome.interrupted,
        rows: outcome.rows,
        failures: outcome.failures,
        skipped: suite.skipped.clone(),
        references: outcome.references,
        steps_histograms: outcome.steps_histograms,
    };
    let plots = report::write_run(&results, &dir)
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("writing results into {}", dir.display()))?;
    println!(
        "{}: {} configurations measured, {} failed{} in {:.1} s; {} plots",
        dir.display(),
        results.rows.len(),
        results.failures.len(),
        if results.interrupted {
            " (interrupted)"
        } else {
            ""
        },
        elapsed.as_secs_f64(),
        plots.len()
    );
    for f in &results.failures {
        eprintln!("failed: {}: {}", f.config_id, f.error);
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
    println!(
        "{}: summary.md and {} plots regenerated from {} rows",
        out.display(),
        plots.len(),
        res.rows.len()
    );
    Ok(())
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
    let mut matched = 0;
    let mut log_sum = 0.0;
    for x in &ra.rows {
        let Some(y) = rb.rows.iter().find(|y| y.config_id == x.config_id) else {
            continue;
        };
        matched += 1;
        let ratio = y.render_ms_median / x.render_ms_median.max(1e-12);
        log_sum += ratio.ln();
        let psnr = match (x.psnr_db, y.psnr_db) {
            (Some(p), Some(q)) => format!("{:+.2}", q - p),
            _ => "n/a".into(),
        };
        outln!(
            out,
            "{:<60} {:>8.2}ms {:>8.2}ms {:>8.3}x {:>8.3}x {:>8.3}x {:>10}",
            x.config_id,
            x.render_ms_median,
            y.render_ms_median,
            ratio,
            y.build_ms_total / x.build_ms_total.max(1e-12),
            y.memory_bytes as f64 / (x.memory_bytes as f64).max(1.0),
            psnr
        );
    }
    let only_a = ra
        .rows
        .iter()
        .filter(|x| !rb.rows.iter().any(|y| y.config_id == x.config_id))
        .count();
    let only_b = rb
        .rows
        .iter()
        .filter(|y| !ra.rows.iter().any(|x| x.config_id == y.config_id))
        .count();
    if matched == 0 {
        bail!("the runs share no configuration ({only_a} only in A, {only_b} only in B)");
    }
    outln!(
        out,
        "{matched} configurations matched (geometric mean render ratio {:.3}x); {only_a} only in A, {only_b} only in B",
        (log_sum / matched as f64).exp()
    );
    print_ignoring_broken_pipe(&out)
}

pub fn stability(args: StabilityArgs) -> Result<()> {
    let root = repo_root();
    let out = match args.out {
        Some(o) => o,
        None => root.join("bench-results").join(format!(
            "stability-{}",
            utc_strings(marchmesh_harness::results::now_secs()).1
        )),
    };
    // --out is the run folder itself: it must be new or empty, so no file is ever replaced.
    refuse_non_empty(&out, "--out")?;
    if let Some(dir) = &args.write_scenes {
        refuse_non_empty(dir, "--write-scenes")?;
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let ctx = marchmesh_stability::CaseContext {
        generated_dir: out.join("generated"),
        scenes_dir: root.join("scenes"),
        include_large: args.large,
    };
    let cases = marchmesh_stability::all_cases(&ctx)
        .with_context(|| format!("generating the cases under {}", ctx.generated_dir.display()))?;
    if let Some(dir) = &args.write_scenes {
        let selected: Vec<_> = cases
            .iter()
            .filter(|c| args.filter.as_deref().is_none_or(|f| c.id().contains(f)))
            .collect();
        let written = marchmesh_stability::runner::write_scenes(&selected, dir)
            .with_context(|| format!("writing scenes into {}", dir.display()))?;
        eprintln!("wrote {} scenes into {}", written.len(), dir.display());
    }
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("stability [{bar:30}] {pos}/{len} cases, eta {eta}: {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let opts = marchmesh_stability::RunOptions {
        side: args.side,
        threads: args.threads,
    };
    let (rows, errors) =
        marchmesh_stability::run_cases(&cases, args.filter.as_deref(), &opts, &mut |i, n, id| {
            bar.set_length(n as u64);
            bar.set_position(i as u64);
            bar.set_message(id.to_string());
        });
    bar.finish_and_clear();
    marchmesh_stability::report::write(&out, &rows, &errors, args.side, &command_line())
        .with_context(|| format!("writing the report into {}", out.display()))?;
    let counts = marchmesh_stability::report::verdict_counts(&rows);
    println!(
        "{}: {} rows ({}), {} cases could not run",
        out.display(),
        rows.len(),
        counts
            .iter()
            .map(|(k, v)| format!("{v} {k}"))
            .collect::<Vec<_>>()
            .join(", "),
        errors.len()
    );
    for e in &errors {
        eprintln!("case error: {e}");
    }
    if rows.is_empty() && errors.is_empty() {
        bail!(
            "no stability case matches the filter {:?}",
            args.filter.as_deref().unwrap_or("")
        );
    }
    if rows.is_empty() {
        bail!(
            "every one of the {} selected cases failed to run",
            errors.len()
        );
    }
    Ok(())
}

/// Refuses `dir` (named by `flag` in the message) if it exists and is not an empty folder.
fn refuse_non_empty(dir: &std::path::Path, flag: &str) -> Result<()> {
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
