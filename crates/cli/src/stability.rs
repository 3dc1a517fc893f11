//! `marchmesh stability`: the numerical-stability cases on every backend against the
//! reference, written as `stability.csv`, `stability.json` and `summary.md`.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use marchmesh_harness::results::utc_strings;

use crate::StabilityArgs;
use crate::bench::{command_line, refuse_non_empty};

pub fn stability(args: StabilityArgs) -> Result<()> {
    let memory_limit_bytes = args.memory_limit_mib.saturating_mul(1 << 20);
    // The truth, the render and their comparison are held at once.
    let images_bytes =
        marchmesh_core::Framebuffer::bytes_for(args.side, args.side).saturating_mul(3);
    if args.side == 0 || images_bytes > memory_limit_bytes {
        bail!(
            "--side {}: a case holds three {0}x{0} images ({images_bytes} bytes), over --memory-limit-mib {} (or the side is 0)",
            args.side,
            args.memory_limit_mib
        );
    }
    let root = crate::assets::root()?;
    let out = match args.out {
        Some(o) => o,
        None => PathBuf::from("bench-results").join(format!(
            "stability-{}",
            utc_strings(marchmesh_harness::results::now_secs()).1
        )),
    };
    // --out is the run folder itself: it must be new or empty, so no file is ever replaced.
    refuse_non_empty(&out, "--out")?;
    if let Some(dir) = &args.write_scenes {
        refuse_non_empty(dir, "--write-scenes")?;
    }
    // The folders made here (the run folder and any missing above it) go again if the run
    // measures nothing.
    let created = marchmesh_safeio::create_folder_tracked(&out)
        .with_context(|| format!("creating {}", out.display()))?;
    let ctx = marchmesh_stability::CaseContext {
        generated_dir: out.join("generated"),
        scenes_dir: root.join("scenes"),
        include_large: args.large,
    };
    let cases = match marchmesh_stability::all_cases(&ctx) {
        Ok(cases) => cases,
        Err(e) => {
            // Leave no partial generated/ behind: the folder was new or empty.
            let _ = std::fs::remove_dir_all(&ctx.generated_dir);
            marchmesh_safeio::remove_created_folders(&created);
            return Err(e).with_context(|| {
                format!(
                    "generating the cases under {} (removed again)",
                    ctx.generated_dir.display()
                )
            });
        }
    };
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
        memory_limit_bytes,
    };
    let (rows, errors) =
        marchmesh_stability::run_cases(&cases, args.filter.as_deref(), &opts, &mut |i, n, id| {
            bar.set_length(n as u64);
            bar.set_position(i as u64);
            bar.set_message(id.to_string());
        });
    bar.finish_and_clear();
    if rows.is_empty() && errors.is_empty() {
        // Leave nothing behind for a run that measured nothing: the folder was new or empty,
        // so what is in it is this run's; then the folders this run made.
        if let Ok(entries) = std::fs::read_dir(&out) {
            for e in entries.flatten() {
                let _ =
                    std::fs::remove_dir_all(e.path()).or_else(|_| std::fs::remove_file(e.path()));
            }
        }
        marchmesh_safeio::remove_created_folders(&created);
        bail!(
            "no stability case matches the filter {:?}",
            args.filter.as_deref().unwrap_or("")
        );
    }
    marchmesh_stability::report::write(&out, &rows, &errors, args.side, &command_line())
        .with_context(|| format!("writing the report into {}", out.display()))?;
    let counts = marchmesh_stability::report::verdict_counts(&rows);
    out!(
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
    if rows.is_empty() {
        bail!(
            "every one of the {} selected cases failed to run",
            errors.len()
        );
    }
    Ok(())
}
