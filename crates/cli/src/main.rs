//! `marchmesh`: render a scene with any backend, validate scenes, print the scene schema, run
//! benchmarks, and fly through a scene (`view`).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use marchmesh_core::{BackgroundSampler, RenderOptions, image_io};
use marchmesh_harness::backend::{self, BackendId, BackendSpec};

/// Prints a line to stdout like `println!`, but a closed stdout ends the process quietly
/// (see [`say`]) instead of panicking.
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::say(format_args!($($arg)*))
    };
}

mod assets;
mod bench;
mod exr_aov;
mod stability;
mod view;

#[derive(Parser)]
#[command(
    name = "marchmesh",
    version,
    about = "Sphere tracing vs BVH ray tracing, measured."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene to a PNG (and optional float AOVs).
    Render(RenderArgs),
    /// Check a scene file and print a summary, or every problem found.
    Validate {
        /// Scene files (or built-in scene names) to check.
        #[arg(required = true)]
        scenes: Vec<PathBuf>,
    },
    /// List the built-in scenes and suites (usable by name from any folder), or extract
    /// them with -o.
    Scenes {
        /// Write every built-in scene, mesh and suite into this folder (new or empty), laid
        /// out as the repository's scenes/ folder.
        #[arg(long, short = 'o', value_name = "DIR")]
        out: Option<PathBuf>,
    },
    /// Print the JSON Schema of the scene format.
    Schema,
    /// Run a benchmark suite and write bench-results/RUN_ID/ (CSV, JSON, summary, plots, images).
    Bench(BenchArgs),
    /// Write the findings across runs: per axis (scene size, image size, threads, accuracy
    /// target, memory) who is faster where and where the winner changes, with plots.
    Findings {
        /// Run folders (or their results.json); the newest run counts for a configuration
        /// measured twice.
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        /// The Markdown file to write; plots go to `<FILE stem>-plots/` beside it. Links to
        /// each run's summary.md are relative to FILE's folder (any folder on the same file
        /// system tree works).
        #[arg(long, short = 'o', value_name = "FILE")]
        out: PathBuf,
        /// Replace an existing FILE and its plots.
        #[arg(long)]
        force: bool,
        /// An external anchor run to show besides those the runs recorded (repeatable; see
        /// `bench --anchor`).
        #[arg(long, value_name = "FILE")]
        anchor: Vec<PathBuf>,
    },
    /// Regenerate summary.md, plots/ and report.html of a run folder from its results.json.
    Report {
        /// The run folder (holding results.json).
        dir: PathBuf,
    },
    /// Combine shard runs (`bench --shard K/N`) of one suite and commit into one run folder.
    Merge {
        /// Shard run folders (or their results.json).
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        /// The merged run folder (created; must be new or empty: nothing is overwritten).
        #[arg(long, short = 'o', value_name = "DIR")]
        out: PathBuf,
    },
    /// Print the ratios of two runs, configuration by configuration (B / A), then whether
    /// every headline and matched-accuracy verdict of A holds in B and how far its ratio moved.
    Compare {
        /// Baseline run folder (or its results.json).
        a: PathBuf,
        /// Run folder to compare (or its results.json).
        b: PathBuf,
    },
    /// Run the numerical-stability cases on every backend against the reference.
    Stability(StabilityArgs),
    /// Fly through a scene in a window (or replay a script headless): sdf, mesh and reference
    /// side by side, coarse while moving and refined when still, with time, Mrays/s, memory
    /// and accuracy on screen.
    #[command(after_help = view::AFTER_HELP)]
    View(view::ViewArgs),
}

#[derive(clap::Args)]
struct BenchArgs {
    /// Suite name (built-in, `marchmesh scenes` lists them) or path to a suite file.
    #[arg(long, default_value = "default")]
    suite: String,
    /// Folder the run folder (`<UTC time>-<suite>`) is created in. (`--out` is an older
    /// spelling, kept for scripts.)
    #[arg(
        long = "results-dir",
        alias = "out",
        value_name = "DIR",
        default_value = "bench-results"
    )]
    results_dir: PathBuf,
    /// Only configurations whose id (group/scene/backend:quality/size/tN) matches this glob
    /// (without * or ?: substring match).
    #[arg(long)]
    filter: Option<String>,
    /// Render threads for every configuration (overrides the suite's thread counts; 0 = all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Fewer timed repeats (the suite's quick policy, default one repeat).
    #[arg(long)]
    quick: bool,
    /// Only list the configurations.
    #[arg(long)]
    list: bool,
    /// Run only shard K of N (1 <= K <= N): a deterministic partition of the configurations
    /// keeping each scene's in one shard. Combine the shard folders with `marchmesh merge`.
    #[arg(long, value_name = "K/N")]
    shard: Option<marchmesh_harness::bench::Shard>,
    /// Seed of the shuffled rotation order (default: from the clock; recorded in the results).
    #[arg(long)]
    seed: Option<u64>,
    /// The built geometries held at once while one scene's configurations are timed in
    /// rotation stay within this many MiB (by their reported memory); also each build's limit.
    #[arg(long, default_value_t = marchmesh_core::DEFAULT_MEMORY_LIMIT_BYTES >> 20)]
    memory_limit_mib: u64,
    /// Resume the interrupted or killed run in this run folder: measure the configurations
    /// its results.json lists as missing (with the same --filter, --threads and --quick as
    /// the original run) into the same folder, keeping what it measured. The suite, folder,
    /// seed and anchors are the run's: giving them too is an error, not silently ignored.
    #[arg(
        long,
        value_name = "RUN",
        conflicts_with_all = ["list", "shard", "suite", "results_dir", "seed", "anchor"]
    )]
    resume: Option<PathBuf>,
    /// Record an external anchor run with this run (repeatable): the JSON of
    /// scripts/anchor_embree.sh (mesh backend vs Embree 4), scripts/anchor_tinybvh.sh (mesh
    /// backend vs tinybvh and Embree) or scripts/anchor_fidget.sh (sdf backend vs fidget), as
    /// scripts/anchor.sh writes them, shown in summary.md and the findings beside the verdicts.
    #[arg(long, value_name = "FILE")]
    anchor: Vec<PathBuf>,
}

#[derive(clap::Args)]
struct StabilityArgs {
    /// Output folder, new or empty (default bench-results/stability-TIMESTAMP/ in UTC).
    #[arg(long, short = 'o', value_name = "DIR")]
    out: Option<PathBuf>,
    /// Only cases whose id contains this.
    #[arg(long)]
    filter: Option<String>,
    /// Image side in pixels.
    #[arg(long, default_value_t = 96)]
    side: u32,
    /// Render threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Refuse before allocating when a case's images (the truth, the render and their
    /// comparison: three framebuffers) or one build would exceed this many MiB.
    #[arg(long, default_value_t = marchmesh_core::DEFAULT_MEMORY_LIMIT_BYTES >> 20)]
    memory_limit_mib: u64,
    /// Include the slow cases (1M+ triangle meshes, 10^5 steps).
    #[arg(long)]
    large: bool,
    /// Also write every case's scene JSON into this folder.
    #[arg(long, value_name = "DIR")]
    write_scenes: Option<PathBuf>,
}

#[derive(clap::Args)]
struct RenderArgs {
    /// Scene file (JSON), or the name of a built-in scene (`marchmesh scenes` lists them).
    scene: PathBuf,
    /// Geometry backend: reference (exact, f64), sdf (sphere tracing) or mesh (BVH).
    #[arg(long, short, default_value = "reference")]
    backend: String,
    /// Backend option as key=value (repeatable); `--opt help` lists them.
    #[arg(long = "opt", short = 'O', value_name = "KEY=VALUE")]
    options: Vec<String>,
    /// Output image: .png, .jpg or .jpeg.
    #[arg(long, short = 'o', value_name = "FILE", default_value = "out.png")]
    out: PathBuf,
    /// Override the scene's image width in pixels.
    #[arg(long)]
    width: Option<u32>,
    /// Override the scene's image height in pixels.
    #[arg(long)]
    height: Option<u32>,
    /// Override the scene's samples per pixel (1..=1024; 1..=65536 with the path tracer).
    #[arg(long)]
    spp: Option<u32>,
    /// Worker threads (0 = one per logical core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Also write float AOVs (depth, normal, mask, work, termination) into this folder: one
    /// PFM per AOV and all of them as layers of one OpenEXR file, aovs.exr.
    #[arg(long, value_name = "DIR")]
    aov: Option<PathBuf>,
    /// Overwrite existing output files.
    #[arg(long)]
    force: bool,
    /// Refuse renders whose estimated memory (the backend's build: triangles, grids,
    /// instances; then the image buffers) would exceed this many MiB.
    #[arg(long, default_value_t = 4096)]
    memory_limit_mib: u64,
    /// Stop (writing nothing) as soon as the build and the render together take, or the
    /// render is projected from the rows done so far to take, more than this many seconds.
    #[arg(long, value_name = "SECONDS")]
    max_seconds: Option<f64>,
}

/// Most rays `scene` can trace: camera samples times, per hit, the shadow rays of every
/// light (area lights: their samples) and the AO rays, times the reflection depth; for the
/// path tracer, a bounce ray and a shadow ray per bounce. An upper bound for the estimate
/// printed before long renders.
fn ray_bound(scene: &marchmesh_scene::Scene) -> f64 {
    use marchmesh_scene::{Integrator, Light};
    let r = &scene.render;
    let camera = f64::from(scene.camera.width)
        * f64::from(scene.camera.height)
        * f64::from(r.samples_per_pixel);
    match r.integrator {
        Integrator::Path => camera * (2.0 * f64::from(r.max_bounces) + 1.0),
        Integrator::Whitted => {
            let per_hit: f64 = scene
                .lights
                .iter()
                .map(|l| match l {
                    Light::Ambient { .. } => 0.0,
                    Light::Point { .. } | Light::Directional { .. } => 1.0,
                    Light::Sphere { .. } | Light::Rectangle { .. } => {
                        f64::from(r.area_light_samples)
                    }
                })
                .sum::<f64>()
                + r.ambient_occlusion.map_or(0.0, |a| f64::from(a.samples));
            camera * (1.0 + per_hit) * (f64::from(r.max_reflection_depth) + 1.0)
        }
    }
}

/// Renders with at most this many rays go without an up-front estimate.
const QUIET_RAY_BOUND: f64 = 1e9;

#[global_allocator]
static ALLOC: marchmesh_harness::alloc::CountingAlloc = marchmesh_harness::alloc::CountingAlloc;

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render(args),
        Command::Validate { scenes } => validate(&scenes),
        Command::Scenes { out } => scenes(out.as_deref()),
        Command::Schema => {
            say(format_args!("{}", marchmesh_scene::json_schema()));
            Ok(())
        }
        Command::Bench(args) => bench::bench(args),
        Command::Report { dir } => bench::report(&dir),
        Command::Merge { runs, out } => bench::merge(&runs, &out),
        Command::Findings {
            runs,
            out,
            force,
            anchor,
        } => bench::findings(&runs, &anchor, &out, force),
        Command::Compare { a, b } => bench::compare(&a, &b),
        Command::Stability(args) => stability::stability(args),
        Command::View(args) => view::view(args),
    };
    if let Err(e) = result {
        eprintln!("error: {}", error_chain(&e));
        std::process::exit(1);
    }
}

/// The error and its causes joined with `: `, leaving out a cause whose text the message
/// already holds (library errors name their OS error in their own text too).
fn error_chain(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let cause = cause.to_string();
        if text.contains(&cause) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&cause);
    }
    text
}

/// Prints one line to stdout. A closed stdout (`marchmesh schema | head -c1`) ends the process
/// quietly with status 141 (128 + SIGPIPE, what a shell reports for a killed writer) instead
/// of panicking like `println!`; other write errors end it with status 1 and a message.
pub(crate) fn say(line: std::fmt::Arguments) {
    use std::io::Write;
    if let Err(e) = writeln!(std::io::stdout().lock(), "{line}") {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(141);
        }
        eprintln!("error: cannot write to stdout: {e}");
        std::process::exit(1);
    }
}

fn validate(paths: &[PathBuf]) -> Result<()> {
    let mut failed = 0;
    for arg in paths {
        let p = match assets::scene_file(arg) {
            Ok(p) => p,
            Err(e) => {
                failed += 1;
                eprintln!("{}", error_chain(&e));
                continue;
            }
        };
        match marchmesh_scene::load(&p) {
            Ok(s) => {
                let mut problems: Vec<String> = s
                    .mesh_paths()
                    .iter()
                    .filter(|m| !m.exists())
                    .map(|m| format!("mesh file {} does not exist", m.display()))
                    .collect();
                if let marchmesh_scene::Background::Environment { path, .. } = &s.background
                    && !path.exists()
                {
                    problems.push(format!("environment map {} does not exist", path.display()));
                } else if let Err(e) = marchmesh_core::check_background(
                    &s.background,
                    marchmesh_core::DEFAULT_MEMORY_LIMIT_BYTES,
                ) {
                    problems.push(e.to_string());
                }
                if problems.is_empty() {
                    let mut nodes = 0;
                    s.visit_nodes(|_| nodes += 1);
                    say(format_args!(
                        "{}: ok: {}x{} camera, {} lights, {} objects ({} nodes), {} meshes",
                        p.display(),
                        s.camera.width,
                        s.camera.height,
                        s.lights.len(),
                        s.objects.len(),
                        nodes,
                        s.mesh_paths().len()
                    ));
                } else {
                    // Never "ok" beside a problem: a scene that cannot render is invalid.
                    failed += 1;
                    for m in problems {
                        eprintln!("{}: {m}", p.display());
                    }
                }
            }
            Err(e) => {
                failed += 1;
                eprintln!("{e}");
                if let marchmesh_scene::SceneError::Parse { json_path, .. } = &e {
                    for more in further_problems(&p, json_path) {
                        eprintln!("{more}");
                    }
                }
            }
        }
    }
    if failed > 0 {
        bail!("{failed} of {} scene(s) are invalid", paths.len());
    }
    Ok(())
}

/// Most problems [`further_problems`] looks for after a parse error.
const MAX_PROBLEMS: usize = 64;

/// The problems of a scene file beyond its first parse error: serde stops at the first wrong
/// value, so each is taken out of the JSON (by its JSON path) and the rest parsed again, until
/// the file parses (then its validation problems follow) or a problem cannot be taken out (a
/// missing field of the user's, malformed JSON). Line numbers are those of the first error
/// only: the later ones are found in the edited document, so they are given by JSON path,
/// mapped back to the indices of the user's file (an array element taken out shifts the
/// later ones). A missing field is reported unless a value taken out caused it, and the array
/// element holding it is taken out so the search goes on. `first_path` is
/// the first error's JSON path, not repeated (the edited document's keys are in sorted order,
/// so it need not come first there).
fn further_problems(path: &Path, first_path: &str) -> Vec<String> {
    let Ok(bytes) =
        marchmesh_safeio::read_regular_within(path, marchmesh_scene::MAX_SCENE_FILE_BYTES)
    else {
        return Vec::new();
    };
    let Ok(mut doc) = serde_json::from_slice::<serde_json::Value>(&bytes) else {
        return Vec::new();
    };
    let name = path.display().to_string();
    let base = path.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    let mut first_seen = false;
    let mut taken = TakenOut::default();
    while out.len() < MAX_PROBLEMS {
        let text = doc.to_string();
        match marchmesh_scene::parse_scene(&text, &name, base) {
            Ok(_) => break,
            Err(marchmesh_scene::SceneError::Parse {
                json_path, message, ..
            }) => {
                let Some(segments) = json_segments(&json_path) else {
                    out.push(format!("{name}: at `{json_path}`: {message}"));
                    break;
                };
                let original = taken.original(&segments);
                if let Some(field) = missing_field(&message) {
                    let shown = render_path(&original);
                    // The user's own missing field is reported (once: the first error is
                    // printed by the caller); one missing only because a value was taken out
                    // is not. Either way the value cannot be completed: the array element
                    // holding it is taken out and the search goes on.
                    if !taken.keys.contains(&(shown.clone(), field.to_string())) {
                        if first_seen || shown != first_path {
                            out.push(format!("{name}: at `{shown}`: {message}"));
                        } else {
                            first_seen = true;
                        }
                    }
                    let Some(at) = segments
                        .iter()
                        .rposition(|s| matches!(s, Segment::Index(_)))
                    else {
                        break;
                    };
                    if !taken.remove(&mut doc, &segments[..=at]) {
                        break;
                    }
                    continue;
                }
                let shown = render_path(&original);
                if first_seen || shown != first_path {
                    out.push(format!("{name}: at `{shown}`: {message}"));
                } else {
                    first_seen = true;
                }
                if !taken.remove(&mut doc, &segments) {
                    break;
                }
            }
            Err(e @ marchmesh_scene::SceneError::Invalid { .. }) => {
                out.push(e.to_string());
                break;
            }
            Err(_) => break,
        }
    }
    out
}

/// The field name of serde's "missing field `NAME`" message.
fn missing_field(message: &str) -> Option<&str> {
    message.strip_prefix("missing field `")?.split('`').next()
}

/// One step of a JSON path: an object key or an array index.
#[derive(Clone, Debug, PartialEq)]
enum Segment {
    Key(String),
    Index(usize),
}

/// The steps of a serde_path_to_error path (`a.b[2].c`; `.` for the document itself), or
/// `None` when it is not of that form.
fn json_segments(json_path: &str) -> Option<Vec<Segment>> {
    let mut segments = Vec::new();
    if json_path == "." {
        return Some(segments);
    }
    for part in json_path.split('.') {
        let (key, rest) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        if !key.is_empty() {
            segments.push(Segment::Key(key.to_string()));
        }
        for index in rest.split('[').filter(|x| !x.is_empty()) {
            segments.push(Segment::Index(
                index.strip_suffix(']')?.parse::<usize>().ok()?,
            ));
        }
    }
    Some(segments)
}

/// `segments` written as a JSON path (`a.b[2].c`; `.` for none).
fn render_path(segments: &[Segment]) -> String {
    let mut s = String::new();
    for seg in segments {
        match seg {
            Segment::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Segment::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    if s.is_empty() { ".".into() } else { s }
}

/// What [`further_problems`] took out of the document, in the user's file's terms: the
/// original indices taken out of each array (by the array's original path) and the keys
/// taken out of each object (original path, key).
#[derive(Default)]
struct TakenOut {
    indices: std::collections::HashMap<String, Vec<usize>>,
    keys: std::collections::HashSet<(String, String)>,
}

impl TakenOut {
    /// `current` (a path in the edited document) as the path of the same value in the
    /// user's file.
    fn original(&self, current: &[Segment]) -> Vec<Segment> {
        let mut out: Vec<Segment> = Vec::with_capacity(current.len());
        for seg in current {
            match seg {
                Segment::Key(_) => out.push(seg.clone()),
                Segment::Index(c) => {
                    let gone = self
                        .indices
                        .get(&render_path(&out))
                        .map_or(&[][..], Vec::as_slice);
                    // The c-th original index not taken out.
                    let mut o = 0;
                    let mut left = *c;
                    loop {
                        if !gone.contains(&o) {
                            if left == 0 {
                                break;
                            }
                            left -= 1;
                        }
                        o += 1;
                    }
                    out.push(Segment::Index(o));
                }
            }
        }
        out
    }

    /// Takes the value at `current` out of `doc` and records it; false when the path does
    /// not lead to a removable value.
    fn remove(&mut self, doc: &mut serde_json::Value, current: &[Segment]) -> bool {
        let original = self.original(current);
        if !remove_at(doc, current) {
            return false;
        }
        if let Some((last, parent)) = original.split_last() {
            match last {
                Segment::Index(o) => self
                    .indices
                    .entry(render_path(parent))
                    .or_default()
                    .push(*o),
                Segment::Key(k) => {
                    self.keys.insert((render_path(parent), k.clone()));
                }
            }
        }
        true
    }
}

/// Removes the value at `segments` from `doc`; false when the path does not lead to a
/// removable value.
fn remove_at(doc: &mut serde_json::Value, segments: &[Segment]) -> bool {
    let Some((last, parents)) = segments.split_last() else {
        return false;
    };
    let mut at = doc;
    for seg in parents {
        let next = match (seg, at) {
            (Segment::Index(i), serde_json::Value::Array(a)) => a.get_mut(*i),
            (Segment::Key(k), serde_json::Value::Object(o)) => o.get_mut(k),
            _ => None,
        };
        match next {
            Some(n) => at = n,
            None => return false,
        }
    }
    match (last, at) {
        (Segment::Index(i), serde_json::Value::Array(a)) if *i < a.len() => {
            a.remove(*i);
            true
        }
        (Segment::Key(k), serde_json::Value::Object(o)) => o.remove(k).is_some(),
        _ => false,
    }
}

/// `marchmesh scenes [-o DIR]`: lists the built-in scenes and suites, or writes them all into
/// DIR (new or empty) as the repository's `scenes/` folder is laid out.
fn scenes(out: Option<&Path>) -> Result<()> {
    let Some(dir) = out else {
        say(format_args!(
            "built-in scenes (marchmesh render NAME, validate NAME, view NAME):"
        ));
        for n in assets::scene_names() {
            say(format_args!("  {n}"));
        }
        say(format_args!(
            "built-in suites (marchmesh bench --suite NAME):"
        ));
        for n in assets::suite_names() {
            say(format_args!("  {n}"));
        }
        say(format_args!(
            "marchmesh scenes -o DIR writes them (with their meshes) into DIR"
        ));
        return Ok(());
    };
    refuse_file_as_folder(dir, "-o")?;
    if let Ok(mut entries) = std::fs::read_dir(dir)
        && entries.next().is_some()
    {
        bail!(
            "-o {}: folder is not empty; choose a new or empty folder (nothing was written)",
            dir.display()
        );
    }
    let files = assets::embedded_files();
    for (name, bytes) in files {
        let path = dir.join(name);
        if let Some(parent) = path.parent() {
            marchmesh_safeio::create_folder(parent)
                .with_context(|| format!("creating {}", parent.display()))?;
        }
        marchmesh_safeio::publish_new(&path, bytes)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    out!(
        "{}: {} files ({} scenes, {} suites)",
        dir.display(),
        files.len(),
        assets::scene_names().len(),
        assets::suite_names().len()
    );
    Ok(())
}

/// Refuses an output folder `dir` (given as `flag`) that, or a folder above which, exists but
/// is not a folder: a file, a special file or a dangling symbolic link (a link to a folder is
/// the user's choice), naming it plainly instead of the OS error ("Not a directory", "File
/// exists") creating inside it would give.
pub(crate) fn refuse_file_as_folder(dir: &Path, flag: &str) -> Result<()> {
    marchmesh_safeio::check_folder_path(dir).map_err(|e| anyhow::anyhow!("{flag} {e}"))
}

/// Refuses to replace an existing file unless `force`.
fn check_writable(path: &Path, force: bool) -> Result<()> {
    // symlink_metadata: a dangling symlink exists too and is never replaced.
    if let Ok(meta) = std::fs::symlink_metadata(path) {
        if !force {
            bail!(
                "{} already exists (use --force to overwrite)",
                path.display()
            );
        }
        if !meta.file_type().is_file() {
            bail!(
                "{} is not a regular file (a folder, device or symbolic link): not replaced, even with --force",
                path.display()
            );
        }
    }
    if path.exists() && !force {
        bail!(
            "{} already exists (use --force to overwrite)",
            path.display()
        );
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.is_dir()
    {
        marchmesh_safeio::check_folder_path(dir)
            .with_context(|| format!("cannot write {}", path.display()))?;
        bail!(
            "cannot write {}: folder {} does not exist",
            path.display(),
            dir.display()
        );
    }
    Ok(())
}

fn render(args: RenderArgs) -> Result<()> {
    let kind: BackendId = args.backend.parse()?;
    if args.options.iter().any(|o| o == "help") {
        out!("{}", backend::option_help(kind).trim_end_matches('\n'));
        return Ok(());
    }
    let options = args
        .options
        .iter()
        .map(|s| backend::parse_option(s).map_err(anyhow::Error::msg))
        .collect::<Result<Vec<_>>>()?;
    if args.threads > MAX_THREADS {
        bail!(
            "--threads {} is over the limit of {MAX_THREADS}",
            args.threads
        );
    }
    let jpeg = output_is_jpeg(&args.out)?;
    // The AOV folder is created only when there is something to put in it (after the
    // render): a render stopped early or failing leaves no empty folder behind.
    if let Some(dir) = &args.aov {
        refuse_file_as_folder(dir, "--aov")?;
    }
    let targets = render_targets(&args.out, args.aov.as_deref());
    for t in &targets {
        // A file in a folder the AOV folder's creation will make (the AOV folder or one above
        // it, e.g. `-o new/a.png --aov new/aov`) cannot exist yet: nothing to check.
        let in_folder_to_make = t
            .parent()
            .filter(|p| !p.as_os_str().is_empty() && !p.exists())
            .is_some_and(|p| args.aov.as_deref().is_some_and(|a| a.starts_with(p)));
        if !in_folder_to_make {
            check_writable(t, args.force)?;
        }
    }
    let memory_limit_bytes = args.memory_limit_mib.saturating_mul(1 << 20);
    let scene_path = assets::scene_file(&args.scene)?;
    let mut scene = marchmesh_scene::load(&scene_path)?;
    let (w, h) = (
        args.width.unwrap_or(scene.camera.width),
        args.height.unwrap_or(scene.camera.height),
    );
    scene = scene
        .with_image_size(w, h)
        .map_err(anyhow::Error::msg)
        .context("--width/--height")?;
    if let Some(spp) = args.spp {
        scene = scene
            .with_samples_per_pixel(spp)
            .map_err(anyhow::Error::msg)
            .context("--spp")?;
    }
    let background = BackgroundSampler::load_within(&scene.background, memory_limit_bytes)
        .with_context(|| format!("scene {}", scene_path.display()))?;

    if let Some(limit) = args.max_seconds
        && !(limit.is_finite() && limit > 0.0)
    {
        bail!("--max-seconds {limit}: must be a positive number");
    }
    let t0 = Instant::now();
    // The deadline holds from the build on (a deep field can take minutes to build) and
    // while no row has finished yet (a band of a render at the caps can take minutes).
    let finished = std::sync::Arc::new(AtomicBool::new(false));
    if let Some(limit) = args.max_seconds {
        let finished = finished.clone();
        std::thread::spawn(move || {
            let deadline = t0 + Duration::from_secs_f64(limit);
            while Instant::now() < deadline {
                if finished.load(Ordering::Relaxed) {
                    return;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            if !finished.load(Ordering::Relaxed) {
                eprintln!(
                    "\nerror: the build and render did not finish within --max-seconds {limit}; nothing was written"
                );
                std::process::exit(1);
            }
        });
    }
    let spec = BackendSpec { kind, options };
    let geometry = backend::build_within(&scene, &spec, memory_limit_bytes)
        .with_context(|| format!("building scene {}", scene_path.display()))?;
    let build_time = t0.elapsed();
    let bound = ray_bound(&scene);
    if bound > QUIET_RAY_BOUND {
        eprintln!(
            "note: up to {bound:.2e} rays ({}x{}, {} spp); progress follows after a second, --max-seconds stops a render projected to take longer",
            w, h, scene.render.samples_per_pixel
        );
    }
    let bar = ProgressBar::with_draw_target(Some(h as u64), ProgressDrawTarget::hidden());
    bar.set_style(
        ProgressStyle::with_template("{spinner} rendering [{bar:40}] {pos}/{len} rows, eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let shown = AtomicBool::new(false);
    let start = Instant::now();
    let on_row = || {
        bar.inc(1);
        if !shown.load(Ordering::Relaxed) && start.elapsed() > Duration::from_secs(1) {
            shown.store(true, Ordering::Relaxed);
            bar.set_draw_target(ProgressDrawTarget::stderr());
        }
        if let Some(limit) = args.max_seconds {
            let elapsed = start.elapsed().as_secs_f64();
            let projected = elapsed * f64::from(h) / bar.position().max(1) as f64;
            if build_time.as_secs_f64() + projected > limit {
                bar.finish_and_clear();
                eprintln!(
                    "error: the render is projected to take {projected:.0} s ({} of {h} rows in {elapsed:.1} s) after a build of {:.1} s, over --max-seconds {limit}; nothing was written",
                    bar.position(),
                    build_time.as_secs_f64()
                );
                std::process::exit(1);
            }
        }
    };
    let opts = RenderOptions {
        threads: args.threads,
        memory_limit_bytes,
        ..Default::default()
    };
    let out = marchmesh_core::render(&scene, geometry.as_ref(), &background, &opts, &on_row)?;
    finished.store(true, Ordering::Relaxed);
    bar.finish_and_clear();

    // Encode everything first, then publish all-or-nothing.
    let mut files = vec![(
        args.out.clone(),
        image_io::encode_color(&out.framebuffer, jpeg, &args.out)?,
    )];
    if let Some(dir) = &args.aov {
        for (name, bytes) in image_io::aov_files(&out.framebuffer) {
            files.push((dir.join(name), bytes));
        }
        files.push((
            dir.join(exr_aov::AOV_EXR_NAME),
            exr_aov::encode(&out.framebuffer)?,
        ));
    }
    let created = match &args.aov {
        Some(dir) => marchmesh_safeio::create_folder_tracked(dir)
            .with_context(|| format!("creating AOV folder {}", dir.display()))?,
        None => Vec::new(),
    };
    if let Err(e) = publish_all(&files, args.force) {
        // publish_all removed what it wrote; the folders made for it go too.
        marchmesh_safeio::remove_created_folders(&created);
        return Err(e);
    }
    let report = geometry.report();
    let s = &out.stats;
    let secs = out.elapsed.as_secs_f64();
    out!(
        "{}: {}x{} {} spp, backend {}: build {:.1} ms, render {:.1} ms, {:.2} Mrays/s ({} rays), {} bytes of geometry",
        args.out.display(),
        w,
        h,
        scene.render.samples_per_pixel,
        kind,
        build_time.as_secs_f64() * 1e3,
        secs * 1e3,
        s.total_rays() as f64 / secs.max(1e-9) / 1e6,
        s.total_rays(),
        report.memory_bytes
    );
    if s.shadow_rays + s.ao_rays + s.reflection_rays + s.bounce_rays > 0 {
        let r = s.mrays_per_thread_second();
        let rate = |rays: u64, mrays: Option<f64>| match mrays {
            Some(m) => format!("{rays} ({m:.2} Mrays per thread-second)"),
            None => rays.to_string(),
        };
        out!(
            "  rays: camera {}, shadow {}, ambient occlusion {}, reflection/bounce {}",
            rate(s.primary_rays, r.camera),
            rate(s.shadow_rays, r.shadow),
            rate(s.ao_rays, r.ambient_occlusion),
            rate(s.reflection_rays + s.bounce_rays, r.bounce),
        );
    }
    if s.steps > 0 {
        out!(
            "  sdf steps: mean {:.1}, max {}",
            s.mean_steps(),
            s.max_steps_seen
        );
    }
    if s.node_visits > 0 {
        out!(
            "  bvh node visits: mean {:.1}, max {}",
            s.mean_node_visits(),
            s.max_node_visits_seen
        );
    }
    for note in &report.notes {
        out!("  note: {note}");
    }
    let exhausted = s.closest_max_steps + s.occlusion_max_steps;
    if exhausted > 0 {
        eprintln!(
            "warning: {exhausted} rays ({:.3}%) ran out of steps (drawn as misses); raise max_steps",
            100.0 * s.step_exhaustion_rate()
        );
    }
    if s.non_finite_hits + s.non_finite_pixels > 0 {
        eprintln!(
            "warning: {} non-finite hits and {} non-finite pixels",
            s.non_finite_hits, s.non_finite_pixels
        );
    }
    Ok(())
}

use marchmesh_core::MAX_THREADS;

/// Whether `--out` asks for JPEG (`.jpg`/`.jpeg`) rather than PNG (`.png`); other extensions
/// are refused rather than written as PNG bytes under a misleading name.
fn output_is_jpeg(out: &Path) -> Result<bool> {
    let ext = out
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "png" => Ok(false),
        "jpg" | "jpeg" => Ok(true),
        _ => bail!(
            "--out {}: unsupported image extension {ext:?} (use .png, .jpg or .jpeg)",
            out.display()
        ),
    }
}

/// Every file a render writes: the image, then each AOV file.
fn render_targets(out: &Path, aov: Option<&Path>) -> Vec<PathBuf> {
    let mut v = vec![out.to_path_buf()];
    if let Some(dir) = aov {
        v.extend(image_io::AOV_FILE_NAMES.iter().map(|n| dir.join(n)));
        v.push(dir.join(exr_aov::AOV_EXR_NAME));
    }
    v
}

/// Publishes every `(path, bytes)` atomically. Without `force` each file is created new
/// (a file created meanwhile by anyone makes this fail, never overwritten) and on any failure
/// the files this call already published are removed again, so a render leaves all its files
/// or none. With `force` existing regular files are replaced (never a folder, device or
/// symlink); files replaced before a failure stay replaced.
fn publish_all(files: &[(PathBuf, Vec<u8>)], force: bool) -> Result<()> {
    let mut published: Vec<&Path> = Vec::new();
    for (path, bytes) in files {
        let result = if force {
            marchmesh_safeio::replace_regular(path, bytes)
        } else {
            marchmesh_safeio::publish_new(path, bytes)
        };
        if let Err(e) = result {
            if !force {
                for p in &published {
                    std::fs::remove_file(p).ok();
                }
            }
            let hint = if matches!(e, marchmesh_safeio::SafeIoError::Exists { .. }) {
                " (use --force to overwrite)"
            } else {
                ""
            };
            bail!("{e}{hint}");
        }
        published.push(path);
    }
    Ok(())
}
