//! `marchmesh view`: the interactive viewer (crate `marchmesh-viewer`) and its headless
//! script mode.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use marchmesh_harness::backend::{self, BackendId};
use marchmesh_viewer::{Script, Session, SessionOptions, headless, window};

/// The `--help` text after the options: keys and the script format.
pub const AFTER_HELP: &str = r#"Keys: W/S forward/back, A/D left/right, Q/E down/up (one step per frame while held; --step),
mouse drag (left button) to look, 1 sdf, 2 mesh, 3 reference (each built once and kept),
Tab split (left: the shown backend, right: the one shown before, same camera),
+/- quality of the shown backend (sdf: hit epsilon eps_px, mesh: tessellation budget tess_px;
each level halves or doubles it, -3..=3), R reset camera and quality, P save shot-NNN.png
and shot-NNN.json (the camera as a scene file) into --shots, Escape quit.

Frames: coarse (1/4 of each side, scaled up) while anything changes, then 1/2 and full
resolution on the next still frames. Moving frames trace the backend built at the last still
camera, shifted; still frames rebuild at the camera and are exactly `marchmesh render`'s.
Refined frames are measured against the reference at the same camera and full resolution.

Script (--headless --script FILE --frames DIR), a JSON array of entries:
  {"key": "W", "frames": 10}  movement key (W A S D Q E) held for 10 frames (default 1)
  {"key": "2"}                1 2 3 Tab + - R: pressed on the first of `frames` frames
  {"mouse_drag": [dx, dy]}    drag by dx, dy window pixels on each of `frames` frames
  {"wait": 3}                 3 still frames (refines one level per frame)
  {"key": "P"}                no frame: save the last frame and its camera into DIR
DIR gets frame-00000.png ... (window size, no overlay unless --overlay) and frames.json
(per frame: camera position, yaw, pitch, backend, refinement level, times, accuracy).
Nothing is overwritten: existing frame files are an error before anything is rendered."#;

/// Arguments of `marchmesh view`.
#[derive(clap::Args)]
pub struct ViewArgs {
    /// Scene file (JSON), or the name of a built-in scene (`marchmesh scenes` lists them).
    scene: PathBuf,
    /// Backend shown first: sdf, mesh or reference.
    #[arg(long, short, default_value = "sdf")]
    backend: String,
    /// Backend option as `[BACKEND:]key=value` (repeatable), e.g. `mesh:bvh=bvh2`; without
    /// BACKEND: for the --backend one. `--opt sdf:help` lists a backend's options. The
    /// quality knob's key applies on top.
    #[arg(long = "opt", short = 'O', value_name = "[BACKEND:]KEY=VALUE")]
    options: Vec<String>,
    /// Window width in pixels (default: the scene's image width).
    #[arg(long)]
    width: Option<u32>,
    /// Window height in pixels (default: the scene's image height).
    #[arg(long)]
    height: Option<u32>,
    /// Render threads (0 = one per logical core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// World units per movement step (default: 1/20 of the median distance to the surfaces
    /// the start camera sees).
    #[arg(long)]
    step: Option<f64>,
    /// Do not measure refined frames against the reference.
    #[arg(long)]
    no_accuracy: bool,
    /// Each backend build and render stays within this many MiB.
    #[arg(long, default_value_t = marchmesh_core::DEFAULT_MEMORY_LIMIT_BYTES >> 20)]
    memory_limit_mib: u64,
    /// No window: replay --script and write the frames into --frames.
    #[arg(long, requires_all = ["script", "frames"])]
    headless: bool,
    /// The script of input events (JSON; format below).
    #[arg(long, value_name = "FILE", requires = "headless")]
    script: Option<PathBuf>,
    /// Folder for the frames and frames.json (created if missing).
    #[arg(long, value_name = "DIR", requires = "headless")]
    frames: Option<PathBuf>,
    /// Headless: draw the overlay text into the frames too.
    #[arg(long, requires = "headless")]
    overlay: bool,
    /// Folder P saves screenshots and camera scenes into in the window.
    #[arg(long, value_name = "DIR", default_value = ".")]
    shots: PathBuf,
    /// End the window session after this many window updates (for tests).
    #[arg(long, hide = true)]
    exit_after_frames: Option<u64>,
}

/// `[BACKEND:]key=value` options grouped by backend; without a backend name before a colon
/// an option belongs to the backend shown first.
fn parse_options(
    raw: &[String],
    first: BackendId,
) -> Result<BTreeMap<BackendId, Vec<(String, String)>>> {
    let mut out: BTreeMap<BackendId, Vec<(String, String)>> = BTreeMap::new();
    for o in raw {
        let (kind, pair) = match o.split_once(':') {
            Some((name, pair)) => match name.trim().parse::<BackendId>() {
                Ok(kind) => (kind, pair),
                Err(_) => (first, o.as_str()),
            },
            None => (first, o.as_str()),
        };
        if pair.trim() == "help" {
            out!("{}", backend::option_help(kind).trim_end_matches('\n'));
            std::process::exit(0);
        }
        let kv = backend::parse_option(pair)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--opt {o}"))?;
        out.entry(kind).or_default().push(kv);
    }
    Ok(out)
}

/// Largest `--step`: beyond it a camera position leaves the range f32 render space can hold.
const MAX_STEP: f64 = 1e12;

/// Runs `marchmesh view`.
pub fn view(args: ViewArgs) -> Result<()> {
    let kind: BackendId = args.backend.parse()?;
    if let Some(step) = args.step
        && !(step.is_finite() && step > 0.0 && step <= MAX_STEP)
    {
        bail!("--step {step:e}: must be a positive number of world units, at most {MAX_STEP:e}");
    }
    let options = parse_options(&args.options, kind)?;
    // Read the script first: a malformed script fails before anything is built.
    let script = match &args.script {
        Some(path) => Some(Script::load(path)?),
        None => None,
    };
    let opts = SessionOptions {
        scene: crate::assets::scene_file(&args.scene)?,
        backend: kind,
        options,
        width: args.width,
        height: args.height,
        threads: args.threads,
        step: args.step,
        memory_limit_bytes: args.memory_limit_mib.saturating_mul(1 << 20),
        accuracy: !args.no_accuracy,
    };
    let mut session =
        Session::open(&opts).with_context(|| format!("opening {}", args.scene.display()))?;
    if args.headless {
        let (Some(script), Some(dir)) = (script, &args.frames) else {
            bail!("--headless needs --script FILE and --frames DIR");
        };
        let out = headless::run(&mut session, &script, dir, args.overlay)
            .with_context(|| format!("replaying the script into {}", dir.display()))?;
        let total: f64 = out.frames.iter().map(|f| f.ms).sum();
        out!(
            "{}: {} frames ({:.1} ms rendering), {} shots, {}",
            dir.display(),
            out.frames.len(),
            total,
            out.shots.len(),
            headless::FRAMES_JSON
        );
        return Ok(());
    }
    let run = window::WindowRun {
        shots_dir: args.shots.clone(),
        exit_after_frames: args.exit_after_frames,
    };
    let summary = window::run(&mut session, &run)?;
    out!(
        "window closed after {} frames ({} updates), {} shots",
        summary.frames,
        summary.updates,
        summary.shots.len()
    );
    Ok(())
}
