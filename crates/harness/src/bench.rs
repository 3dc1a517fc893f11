//! Runs a suite: every configuration is built, rendered once untimed (heap, RSS, accuracy,
//! work and images come from this render), then the configurations of one scene and resolution
//! are timed together in shuffled rotation rounds (see [`run`]).

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use marchmesh_core::{
    BackgroundSampler, DEFAULT_MEMORY_LIMIT_BYTES, Framebuffer, Geometry, RenderOptions, compare,
    image_io, render,
};
use marchmesh_scene::{RenderOverrides, Scene};

use crate::alloc::HeapPhase;
use crate::backend::{self, BackendId, BackendSpec};
use crate::images;
use crate::results::{Failure, ReferenceInfo, Row, TimingSample};
use crate::rss::RssPhase;
use crate::schedule;
use crate::stats::{RepeatPolicy, Summary};
use crate::suite::BackendConfig;
use crate::suite::{Resolution, Suite, glob_match};

/// One configuration to measure.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// `group/scene/backend:label/WxH/tN`, matched by `--filter`.
    pub id: String,
    /// Group name.
    pub group: String,
    /// Scene name.
    pub scene: String,
    /// Scene file.
    pub scene_path: PathBuf,
    /// Quality label.
    pub label: String,
    /// Backend and options.
    pub spec: BackendSpec,
    /// Requested resolution.
    pub resolution: Resolution,
    /// Render settings replacing the scene's (the group's `spp` folded in).
    pub render: RenderOverrides,
    /// Render settings of the reference render this configuration is measured against.
    pub truth_render: RenderOverrides,
    /// Render threads (resolved: never 0).
    pub threads: usize,
    /// Compare with the reference.
    pub reference: bool,
    /// Repeat policy.
    pub repeats: RepeatPolicy,
}

/// How to run a suite.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Use the suite's quick repeats.
    pub quick: bool,
    /// Replace every group's thread counts with this one.
    pub threads: Option<usize>,
    /// Only configurations whose id matches this glob (a glob without `*` matches as a
    /// substring).
    pub filter: Option<String>,
    /// Folder for PNGs and heatmaps (`None` = no images).
    pub images_dir: Option<PathBuf>,
    /// Seed of the shuffled rotation orders (recorded in the results).
    pub seed: u64,
    /// The built representations of one rotation block held at once stay within this many
    /// bytes (by their reported memory); a block over it is timed in parts.
    pub hold_memory_bytes: u64,
    /// Host name written into every row.
    pub machine: String,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            quick: false,
            threads: None,
            filter: None,
            images_dir: None,
            seed: 0,
            hold_memory_bytes: DEFAULT_MEMORY_LIMIT_BYTES,
            machine: String::new(),
        }
    }
}

/// Progress callbacks.
pub trait Progress {
    /// The run starts with `total` configurations.
    fn start(&mut self, total: usize);
    /// Configuration `index` starts.
    fn config(&mut self, index: usize, id: &str);
    /// A phase of the current configuration (`build`, `warm-up`, `repeat 3`, ...).
    fn phase(&mut self, what: &str);
    /// The current configuration finished (measured or failed).
    fn done(&mut self, index: usize);
    /// A message for the user.
    fn note(&mut self, message: &str);
    /// Configuration `index` is this far (0 to 1) through its work: half when it is built and
    /// warmed up, the other half over its timed rounds as its repeat policy is met
    /// ([`RepeatPolicy::progress`]); [`Progress::done`] means 1. The CLI's ETA ([`Eta`])
    /// counts these, so it moves with every round rather than once per rotation block.
    fn advanced(&mut self, _index: usize, _fraction: f64) {}
    /// Everything measured so far, after each rotation block: the CLI writes it to disk so a
    /// crash or kill loses at most one block.
    fn checkpoint(&mut self, _so_far: &Outcome) {}
}

/// A scene path as results record it, the same on every machine: from the nearest folder
/// named `scenes` on (`scenes/csg.json`, wherever the checkout or the extracted built-in copy
/// is), else relative to the current folder when below it, else as given; `..` and `.`
/// resolved lexically, `/`-separated.
pub fn portable_scene_path(path: &Path) -> String {
    use std::path::Component;
    let mut parts: Vec<String> = Vec::new();
    let mut absolute = false;
    for c in path.components() {
        match c {
            Component::ParentDir => {
                if parts.pop().is_none() && !absolute {
                    parts.push("..".into());
                }
            }
            Component::CurDir => {}
            Component::RootDir | Component::Prefix(_) => absolute = true,
            Component::Normal(n) => parts.push(n.to_string_lossy().into_owned()),
        }
    }
    if let Some(i) = parts.iter().rposition(|p| p == "scenes") {
        return parts[i..].join("/");
    }
    if absolute
        && let Ok(cwd) = std::env::current_dir()
        && let Ok(rel) = Path::new(&format!("/{}", parts.join("/"))).strip_prefix(&cwd)
    {
        return rel.to_string_lossy().replace('\\', "/");
    }
    let joined = parts.join("/");
    if absolute {
        format!("/{joined}")
    } else {
        joined
    }
}

/// The share of a configuration's work [`Progress::advanced`] reports once it is built and
/// warmed up (the rest is its timed rounds).
pub const PREPARED_FRACTION: f64 = 0.5;

/// The remaining time of a run from how far its configurations are ([`Progress::advanced`]).
/// Preparing a configuration (builds, reference renders, the warm-up: the first
/// [`PREPARED_FRACTION`] of its work) and timing it (the rest) cost differently, so the
/// elapsed times seen at each query are fitted as `a * prepared + b * timed` work (least
/// squares, `a, b >= 0`) and the work left is priced at those rates; with too few queries to
/// tell them apart, at the mean rate so far. Meaningful from the first prepared
/// configuration on.
#[derive(Debug, Clone)]
pub struct Eta {
    fractions: Vec<f64>,
    /// `(elapsed s, prepared work, timed work)` at each query.
    samples: std::cell::RefCell<Vec<(f64, f64, f64)>>,
}

impl Eta {
    /// A run of `total` configurations, none started.
    pub fn new(total: usize) -> Self {
        Self {
            fractions: vec![0.0; total],
            samples: std::cell::RefCell::new(Vec::new()),
        }
    }

    /// Configuration `index` is `fraction` (clamped to 0..=1; never moving back) through its
    /// work.
    pub fn advance(&mut self, index: usize, fraction: f64) {
        if let Some(f) = self.fractions.get_mut(index) {
            *f = f.max(fraction.clamp(0.0, 1.0));
        }
    }

    /// The work done, in configurations (fractional).
    pub fn done(&self) -> f64 {
        self.fractions.iter().sum()
    }

    /// The number of configurations.
    pub fn total(&self) -> usize {
        self.fractions.len()
    }

    /// Prepared and timed work done, in configurations.
    fn split(&self) -> (f64, f64) {
        self.fractions.iter().fold((0.0, 0.0), |(p, t), f| {
            (
                p + f.min(PREPARED_FRACTION),
                t + (f - PREPARED_FRACTION).max(0.0),
            )
        })
    }

    /// Seconds left after `elapsed_s` seconds; `None` before any work is done.
    pub fn remaining_s(&self, elapsed_s: f64) -> Option<f64> {
        let done = self.done();
        if done <= 1e-9 {
            return None;
        }
        let (prepared, timed) = self.split();
        let total = self.total() as f64;
        let (left_p, left_t) = (
            (total * PREPARED_FRACTION - prepared).max(0.0),
            (total * (1.0 - PREPARED_FRACTION) - timed).max(0.0),
        );
        let mean = elapsed_s * (total - done).max(0.0) / done;
        let mut samples = self.samples.borrow_mut();
        // One sample per state of the work: the first query after it moved.
        let moved = samples
            .last()
            .is_none_or(|&(_, p, q)| (p, q) != (prepared, timed));
        if moved && elapsed_s.is_finite() && samples.len() < MAX_ETA_SAMPLES {
            samples.push((elapsed_s, prepared, timed));
        }
        // Normal equations of t = a p + b q.
        let (mut spp, mut spq, mut sqq, mut stp, mut stq) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(t, p, q) in samples.iter() {
            spp += p * p;
            spq += p * q;
            sqq += q * q;
            stp += t * p;
            stq += t * q;
        }
        let det = spp * sqq - spq * spq;
        if samples.len() < 4 || det <= 1e-9 * spp * sqq {
            return Some(mean);
        }
        let a = (stp * sqq - stq * spq) / det;
        let b = (stq * spp - stp * spq) / det;
        if !(a.is_finite() && b.is_finite()) || a < 0.0 || b < 0.0 {
            return Some(mean);
        }
        Some(a * left_p + b * left_t)
    }
}

/// Queries [`Eta`] keeps for its fit (a run's progress bar asks a few times a second).
const MAX_ETA_SAMPLES: usize = 100_000;

/// A progress sink that ignores everything.
#[derive(Debug, Default)]
pub struct Silent;

impl Progress for Silent {
    fn start(&mut self, _: usize) {}
    fn config(&mut self, _: usize, _: &str) {}
    fn phase(&mut self, _: &str) {}
    fn done(&mut self, _: usize) {}
    fn note(&mut self, _: &str) {}
}

/// What a run measured.
#[derive(Debug, Clone, Default)]
pub struct Outcome {
    /// Measured configurations.
    pub rows: Vec<Row>,
    /// Configurations that failed.
    pub failures: Vec<Failure>,
    /// Reference renders.
    pub references: Vec<ReferenceInfo>,
    /// Step histograms by configuration id.
    pub steps_histograms: BTreeMap<String, Vec<u64>>,
    /// Stopped early.
    pub interrupted: bool,
    /// Every timed render by configuration id.
    pub timings: BTreeMap<String, Vec<TimingSample>>,
    /// Seed of the rotation orders.
    pub rotation_seed: u64,
    /// Configurations neither measured nor failed (the run stopped before them).
    pub missing: Vec<String>,
    /// Files (images) that could not be written, with the reason.
    pub write_errors: Vec<String>,
}

fn resolve_threads(t: usize) -> usize {
    if t == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        t
    }
}

fn resolution_tag(r: Resolution) -> String {
    match r {
        Resolution::Size { width, height } => format!("{width}x{height}"),
        Resolution::MaxSide { max_side } => format!("max{max_side}"),
        Resolution::Scale { scale } => format!("x{scale}"),
    }
}

/// Whether `id` passes `filter`.
pub fn filter_matches(filter: &str, id: &str) -> bool {
    if filter.contains(['*', '?']) {
        glob_match(filter, id)
    } else {
        id.contains(filter)
    }
}

/// The configurations of `suite` under `options` (filter applied), in run order.
pub fn configurations(suite: &Suite, options: &BenchOptions) -> Vec<Config> {
    let mut out = Vec::new();
    for g in &suite.groups {
        let threads: Vec<usize> = match options.threads {
            Some(t) => vec![resolve_threads(t)],
            None => g.threads.iter().map(|&t| resolve_threads(t)).collect(),
        };
        let base = g.repeats.unwrap_or(suite.repeats);
        let repeats = if options.quick {
            suite.quick_repeats.min_repeats_of(base)
        } else {
            base
        };
        for (scene, path) in &g.scenes {
            for &resolution in &g.resolutions {
                for BackendConfig {
                    label,
                    spec,
                    render,
                } in &g.backends
                {
                    for &t in &threads {
                        let kind = spec.kind.name();
                        let id = format!(
                            "{}/{scene}/{kind}:{label}/{}/t{t}",
                            g.name,
                            resolution_tag(resolution)
                        );
                        if options
                            .filter
                            .as_deref()
                            .is_some_and(|f| !filter_matches(f, &id))
                        {
                            continue;
                        }
                        out.push(Config {
                            id,
                            group: g.name.clone(),
                            scene: scene.clone(),
                            scene_path: path.clone(),
                            label: label.clone(),
                            spec: spec.clone(),
                            resolution,
                            render: RenderOverrides {
                                samples_per_pixel: render.samples_per_pixel.or(g.spp),
                                ..render.clone()
                            },
                            truth_render: RenderOverrides {
                                samples_per_pixel: g.truth.samples_per_pixel.or(g.spp),
                                ..g.truth.clone()
                            },
                            threads: t,
                            reference: g.reference,
                            repeats,
                        });
                    }
                }
            }
        }
    }
    out
}

impl RepeatPolicy {
    /// The quick policy, but never more repeats than `base` asks for.
    fn min_repeats_of(self, base: RepeatPolicy) -> RepeatPolicy {
        RepeatPolicy {
            min_count: self.min_count.min(base.min_count).max(1),
            min_time_s: self.min_time_s.min(base.min_time_s),
            max_count: self.max_count.min(base.max_count).max(1),
        }
    }
}

type SceneKey = String;

struct Loaded {
    scene: Scene,
    background: BackgroundSampler,
}

struct Truth {
    fb: Framebuffer,
    size: Option<f64>,
}

/// A configuration's render overrides as `render.key=value` pairs for the options column.
fn render_override_pairs(o: &RenderOverrides) -> Vec<String> {
    match serde_json::to_value(o) {
        Ok(serde_json::Value::Object(map)) => map
            .into_iter()
            .map(|(k, v)| format!("render.{k}={v}"))
            .collect(),
        _ => Vec::new(),
    }
}

/// The longest [`slug`] in bytes: two of them plus the longest prefix and suffix the tools
/// add (`steps_histogram_`, `_`, `_accuracy.svg`) stay well under the 255-byte file-name
/// limit of common file systems.
pub const SLUG_MAX_BYTES: usize = 96;

/// File-name-safe version of a configuration id (or a group, scene or suite name): ASCII
/// letters, digits and `-_.=` kept, anything else `_`. At most [`SLUG_MAX_BYTES`] bytes: a
/// longer one keeps a readable prefix and ends in `-` and 16 hex digits of a stable hash
/// (FNV-1a) of the whole `id`, so distinct long ids keep distinct names.
pub fn slug(id: &str) -> String {
    let full: String = id
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.=".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if full.len() <= SLUG_MAX_BYTES {
        return full;
    }
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in id.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01B3);
    }
    // `full` is ASCII, so any byte index is a character boundary.
    format!("{}-{h:016x}", &full[..SLUG_MAX_BYTES - 17])
}

fn load_scene(path: &Path, res: Resolution, render: &RenderOverrides) -> Result<Loaded, String> {
    let scene = marchmesh_scene::load(path).map_err(|e| e.to_string())?;
    let (w, h) = res.apply(scene.camera.width, scene.camera.height);
    let scene = scene
        .with_image_size(w, h)
        .map_err(|e| format!("{}: image size {w}x{h}: {e}", path.display()))?
        .with_render_overrides(render)
        .map_err(|e| format!("{}: render settings: {e}", path.display()))?;
    let background = BackgroundSampler::load(&scene.background)
        .map_err(|e| format!("{}: background: {e}", path.display()))?;
    Ok(Loaded { scene, background })
}

/// Consecutive runs of `configs` measured in one rotation: same suite group, scene file,
/// resolution and render settings (they differ in backend, quality and threads).
pub fn rotation_blocks(configs: &[Config]) -> Vec<std::ops::Range<usize>> {
    let key = |c: &Config| {
        (
            c.group.clone(),
            c.scene_path.clone(),
            resolution_tag(c.resolution),
        )
    };
    let mut blocks: Vec<std::ops::Range<usize>> = Vec::new();
    for (i, c) in configs.iter().enumerate() {
        match blocks.last_mut() {
            Some(b) if key(&configs[b.start]) == key(c) => b.end = i + 1,
            _ => blocks.push(i..i + 1),
        }
    }
    blocks
}

/// A configuration built, warmed up and compared with the reference, holding its geometry
/// while it waits for its timed repeats.
struct Prepared {
    index: usize,
    loaded: Rc<Loaded>,
    geometry: Box<dyn Geometry>,
    /// Every column but the timing ones.
    row: Row,
    histogram: Vec<u64>,
    samples: Vec<TimingSample>,
    /// A timed render failed: the configuration becomes a failure.
    error: Option<String>,
    /// Images that could not be written.
    write_errors: Vec<String>,
}

/// Runs `configs`. Configurations of one scene and resolution ([`rotation_blocks`]) are first
/// built, warmed up and compared with the reference one by one, their geometries held (while
/// the representations together stay within `options.hold_memory_bytes`; otherwise the block
/// is measured in smaller parts and a note says so), then timed in rounds: every round renders
/// each configuration still wanting repeats once, in an order shuffled by
/// [`schedule::round_order`] with `options.seed`. Slow drifts of the machine's load then fall
/// on all of them alike, and per-round ratios ([`crate::stats::PairedRatio`]) cancel them.
///
/// `stop` is checked between configurations and between rounds: once set, the run ends with
/// the configurations finished so far (at least one repeat each) and `interrupted = true`.
/// `progress.checkpoint` sees the outcome after every block.
pub fn run(
    configs: &[Config],
    options: &BenchOptions,
    progress: &mut dyn Progress,
    stop: &AtomicBool,
) -> Outcome {
    let mut out = Outcome {
        rotation_seed: options.seed,
        missing: configs.iter().map(|c| c.id.clone()).collect(),
        ..Outcome::default()
    };
    let mut scenes: HashMap<SceneKey, Result<Rc<Loaded>, String>> = HashMap::new();
    let mut truths: HashMap<SceneKey, Result<Truth, String>> = HashMap::new();
    progress.start(configs.len());
    for block in rotation_blocks(configs) {
        let mut held: Vec<Prepared> = Vec::new();
        let mut held_bytes = 0u64;
        for index in block.clone() {
            if stop.load(Ordering::Relaxed) {
                out.interrupted = true;
                break;
            }
            let c = &configs[index];
            progress.config(index, &c.id);
            let key = |render: &RenderOverrides| -> SceneKey {
                format!(
                    "{}|{}|{render:?}",
                    c.scene_path.display(),
                    resolution_tag(c.resolution)
                )
            };
            let (loaded_key, truth_key) = (key(&c.render), key(&c.truth_render));
            if c.reference && !truths.contains_key(&truth_key) {
                let truth_scene = scenes.entry(truth_key.clone()).or_insert_with(|| {
                    load_scene(&c.scene_path, c.resolution, &c.truth_render).map(Rc::new)
                });
                let truth = match truth_scene {
                    Ok(truth_scene) => {
                        progress.phase("reference");
                        let (truth, info) =
                            reference_render(c, truth_scene, options, &mut out.write_errors);
                        out.references.push(info);
                        truth
                    }
                    Err(e) => Err(format!("reference scene: {e}")),
                };
                if let Err(e) = &truth {
                    progress.note(&format!("{} reference: {e}", c.scene));
                }
                truths.insert(truth_key.clone(), truth);
            }
            let loaded = scenes
                .entry(loaded_key)
                .or_insert_with(|| load_scene(&c.scene_path, c.resolution, &c.render).map(Rc::new));
            let truth = if c.reference {
                truths.get(&truth_key)
            } else {
                None
            };
            let prepared = match loaded {
                Ok(l) => prepare(index, c, l.clone(), truth, options, progress),
                Err(e) => Err(e.clone()),
            };
            match prepared {
                Ok(p) => {
                    progress.advanced(index, PREPARED_FRACTION);
                    let bytes = p.row.memory_bytes;
                    if !held.is_empty()
                        && held_bytes.saturating_add(bytes) > options.hold_memory_bytes
                    {
                        progress.note(&format!(
                            "{}: the block's geometries would hold {} (limit {}): timing the {} configurations held so far in their own rotation",
                            c.id,
                            crate::report::bytes(held_bytes.saturating_add(bytes)),
                            crate::report::bytes(options.hold_memory_bytes),
                            held.len()
                        ));
                        let done = std::mem::take(&mut held);
                        rotate_and_finish(done, configs, options, progress, stop, &mut out);
                        held_bytes = 0;
                    }
                    held_bytes = held_bytes.saturating_add(bytes);
                    held.push(p);
                }
                Err(e) => {
                    progress.note(&format!("{}: {e}", c.id));
                    out.failures.push(Failure {
                        config_id: c.id.clone(),
                        error: e,
                    });
                    progress.done(index);
                }
            }
        }
        rotate_and_finish(held, configs, options, progress, stop, &mut out);
        out.missing = missing(configs, &out);
        progress.checkpoint(&out);
        if out.interrupted {
            break;
        }
    }
    if stop.load(Ordering::Relaxed) {
        out.interrupted = true;
    }
    if out.interrupted {
        progress.note("stopped: writing the finished configurations");
    }
    out.missing = missing(configs, &out);
    out
}

/// The ids of `configs` with neither a row nor a failure in `out`.
fn missing(configs: &[Config], out: &Outcome) -> Vec<String> {
    configs
        .iter()
        .filter(|c| {
            !out.rows.iter().any(|r| r.config_id == c.id)
                && !out.failures.iter().any(|f| f.config_id == c.id)
        })
        .map(|c| c.id.clone())
        .collect()
}

/// Times the held configurations of one block in shuffled rounds, then turns each into a row
/// (or a failure) in `out` and drops its geometry.
fn rotate_and_finish(
    mut held: Vec<Prepared>,
    configs: &[Config],
    options: &BenchOptions,
    progress: &mut dyn Progress,
    stop: &AtomicBool,
    out: &mut Outcome,
) {
    let Some(first) = held.first() else {
        return;
    };
    let block_key = {
        let c = &configs[first.index];
        format!("{}/{}/{}", c.group, c.scene, resolution_tag(c.resolution))
    };
    let mut round = 0u32;
    loop {
        let active: Vec<usize> = (0..held.len())
            .filter(|&i| {
                let p = &held[i];
                let total_s: f64 = p.samples.iter().map(|s| s.wall_ms).sum::<f64>() * 1e-3;
                p.error.is_none()
                    && configs[p.index]
                        .repeats
                        .wants_more(p.samples.len() as u32, total_s)
            })
            .collect();
        if active.is_empty() {
            break;
        }
        // Every configuration has one repeat after round 0: a stop ends the run after it.
        if round > 0 && stop.load(Ordering::Relaxed) {
            out.interrupted = true;
            break;
        }
        for i in schedule::round_order(&active, options.seed, &block_key, round) {
            let p = &mut held[i];
            let c = &configs[p.index];
            progress.phase(&format!("round {}: {}", round + 1, c.id));
            match timed_render(p, c.threads) {
                Ok((wall_ms, cpu_ms)) => p.samples.push(TimingSample {
                    round,
                    wall_ms,
                    cpu_ms,
                }),
                Err(e) => p.error = Some(e),
            }
            let total_s: f64 = p.samples.iter().map(|s| s.wall_ms).sum::<f64>() * 1e-3;
            let timed = c.repeats.progress(p.samples.len() as u32, total_s);
            progress.advanced(
                p.index,
                PREPARED_FRACTION + (1.0 - PREPARED_FRACTION) * timed,
            );
        }
        round += 1;
    }
    for p in held.drain(..) {
        let c = &configs[p.index];
        out.write_errors.extend(p.write_errors);
        match finish_row(p.row, &p.samples, p.error) {
            Ok(row) => {
                out.steps_histograms.insert(c.id.clone(), p.histogram);
                out.timings.insert(c.id.clone(), p.samples);
                out.rows.push(row);
            }
            Err(e) => {
                progress.note(&format!("{}: {e}", c.id));
                out.failures.push(Failure {
                    config_id: c.id.clone(),
                    error: e,
                });
            }
        }
        progress.done(p.index);
    }
}

/// Runs `f` and returns its result with the process CPU time it took (user + system, all
/// threads of the process), ms; `None` where the system cannot tell. Other threads of this
/// process running meanwhile are counted too: the harness runs nothing else while timing.
pub fn with_process_cpu_ms<T>(f: impl FnOnce() -> T) -> (T, Option<f64>) {
    let start = cpu_time::ProcessTime::try_now().ok();
    let out = f();
    let cpu_ms = start
        .and_then(|t| t.try_elapsed().ok())
        .map(|d| d.as_secs_f64() * 1e3);
    (out, cpu_ms)
}

/// One timed render: (wall ms, process CPU ms if the system can tell). Only its time is
/// read (image, accuracy and counters come from the untimed render of [`prepare`]), so it
/// records no AOVs.
fn timed_render(p: &Prepared, threads: usize) -> Result<(f64, Option<f64>), String> {
    let ropts = RenderOptions {
        threads,
        aovs: false,
        ..Default::default()
    };
    let (o, cpu_ms) = with_process_cpu_ms(|| {
        render(
            &p.loaded.scene,
            p.geometry.as_ref(),
            &p.loaded.background,
            &ropts,
            &|| {},
        )
    });
    let o = o.map_err(|e| format!("render: {e}"))?;
    Ok((o.elapsed.as_secs_f64() * 1e3, cpu_ms))
}

/// Fills the timing columns of `row` from its samples.
fn finish_row(
    mut row: Row,
    samples: &[TimingSample],
    error: Option<String>,
) -> Result<Row, String> {
    if let Some(e) = error {
        return Err(e);
    }
    let wall: Vec<f64> = samples.iter().map(|s| s.wall_ms).collect();
    let t = Summary::of(&wall).ok_or("no timed repeat")?;
    let cpu: Option<Vec<f64>> = samples.iter().map(|s| s.cpu_ms).collect();
    let cpu = cpu.as_deref().and_then(Summary::of);
    let rays = (row.rays_primary + row.rays_secondary) as f64;
    row.render_repeats = t.n;
    row.render_ms_median = t.median;
    row.render_ms_min = t.min;
    row.render_ms_max = t.max;
    row.render_ms_mad = t.mad;
    row.render_ms_ci_low = t.ci_low;
    row.render_ms_ci_high = t.ci_high;
    row.render_ci_coverage = t.ci_coverage;
    row.mrays_per_s = rays / (t.median * 1e-3).max(1e-12) / 1e6;
    row.render_cpu_ms_median = cpu.map(|c| c.median);
    row.render_cpu_ms_ci_low = cpu.map(|c| c.ci_low);
    row.render_cpu_ms_ci_high = cpu.map(|c| c.ci_high);
    row.mrays_per_cpu_s = cpu.map(|c| rays / (c.median * 1e-3).max(1e-12) / 1e6);
    Ok(row)
}

/// Notes a failed image write in `errors` (the run goes on; the CLI reports them and exits
/// nonzero).
fn image_written(
    result: Result<(), impl std::fmt::Display>,
    path: &Path,
    errors: &mut Vec<String>,
) {
    if let Err(e) = result {
        let e = e.to_string();
        // Errors of safeio name the file already.
        if e.contains(&*path.to_string_lossy()) {
            errors.push(e);
        } else {
            errors.push(format!("{}: {e}", path.display()));
        }
    }
}

fn reference_render(
    c: &Config,
    l: &Loaded,
    options: &BenchOptions,
    write_errors: &mut Vec<String>,
) -> (Result<Truth, String>, ReferenceInfo) {
    let (w, h) = (l.scene.camera.width, l.scene.camera.height);
    let mut info = ReferenceInfo {
        scene: c.scene.clone(),
        width: w,
        height: h,
        build_ms: None,
        render_ms: None,
        error: None,
    };
    let spec = BackendSpec {
        kind: BackendId::REFERENCE,
        options: Vec::new(),
    };
    let t0 = Instant::now();
    let geometry = match backend::build(&l.scene, &spec) {
        Ok(g) => g,
        Err(e) => {
            let msg = format!("reference unavailable ({e}): accuracy columns left empty");
            info.error = Some(msg.clone());
            return (Err(msg), info);
        }
    };
    info.build_ms = Some(t0.elapsed().as_secs_f64() * 1e3);
    let ropts = RenderOptions {
        threads: 0,
        ..Default::default()
    };
    match render(&l.scene, geometry.as_ref(), &l.background, &ropts, &|| {}) {
        Ok(o) => {
            info.render_ms = Some(o.elapsed.as_secs_f64() * 1e3);
            if let Some(dir) = &options.images_dir {
                let p = dir.join(format!("{}_{w}x{h}_reference.png", slug(&c.scene)));
                image_written(
                    images::publish_png(image_io::encode_color(&o.framebuffer, false, &p), &p),
                    &p,
                    write_errors,
                );
            }
            let size = images::visible_scene_size(&l.scene, &o.framebuffer);
            (
                Ok(Truth {
                    fb: o.framebuffer,
                    size,
                }),
                info,
            )
        }
        Err(e) => {
            let msg = format!("reference render failed ({e}): accuracy columns left empty");
            info.error = Some(msg.clone());
            (Err(msg), info)
        }
    }
}

/// Builds configuration `index`, renders it once untimed (memory, work, accuracy and images
/// come from this render) and returns it with every column but the timing ones.
fn prepare(
    index: usize,
    c: &Config,
    l: Rc<Loaded>,
    truth: Option<&Result<Truth, String>>,
    options: &BenchOptions,
    progress: &mut dyn Progress,
) -> Result<Prepared, String> {
    let scene = &l.scene;
    progress.phase("build");
    let heap = HeapPhase::start();
    let rss = RssPhase::start();
    let t0 = Instant::now();
    let geometry = backend::build_within(scene, &c.spec, options.hold_memory_bytes)
        .map_err(|e| e.to_string())?;
    let build_ms_total = t0.elapsed().as_secs_f64() * 1e3;
    let peak_heap_bytes_build = heap.finish();
    let peak_rss_bytes_build = rss.finish();
    let report = geometry.report();

    let ropts = RenderOptions {
        threads: c.threads,
        ..Default::default()
    };
    progress.phase("warm-up");
    let heap = HeapPhase::start();
    let rss = RssPhase::start();
    let warm = render(scene, geometry.as_ref(), &l.background, &ropts, &|| {})
        .map_err(|e| format!("render: {e}"))?;
    let peak_heap_bytes_render = heap.finish();
    let peak_rss_bytes_render = rss.finish();

    let s = &warm.stats;
    let fb = &warm.framebuffer;
    let mut notes = Vec::new();
    let slug_id = slug(&c.id);
    let mut write_errors = Vec::new();
    if let Some(dir) = &options.images_dir {
        let p = dir.join(format!("{slug_id}.png"));
        image_written(
            images::publish_png(image_io::encode_color(fb, false, &p), &p),
            &p,
            &mut write_errors,
        );
    }
    let acc = match truth {
        Some(Ok(truth)) => {
            let a = compare(fb, &truth.fb).map_err(|e| e.to_string())?;
            if let Some(dir) = &options.images_dir {
                let p = dir.join(format!("{slug_id}.diff.png"));
                image_written(
                    images::publish_png(images::diff_png(fb, &truth.fb), &p),
                    &p,
                    &mut write_errors,
                );
            }
            Some((a, truth.size, images::ssim(fb, &truth.fb)))
        }
        Some(Err(e)) => {
            notes.push(e.clone());
            None
        }
        None => {
            notes.push("accuracy not requested by the suite".into());
            None
        }
    };
    let rel = |v: f64, size: Option<f64>| size.filter(|s| *s > 0.0).map(|s| v / s);
    let kind = c.spec.kind.name();
    let total_rays = s.total_rays();
    let rates = s.mrays_per_thread_second();
    let row = Row {
        config_id: c.id.clone(),
        group: c.group.clone(),
        scene: c.scene.clone(),
        scene_file: portable_scene_path(&c.scene_path),
        backend: kind.to_string(),
        quality: c.label.clone(),
        options: c
            .spec
            .options
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .chain(render_override_pairs(&c.render))
            .collect::<Vec<_>>()
            .join(";"),
        width: scene.camera.width,
        height: scene.camera.height,
        spp: scene.render.samples_per_pixel,
        threads: c.threads,
        machine: options.machine.clone(),
        build_ms_total,
        build_phases_ms: report
            .build_phases_ms
            .iter()
            .map(|(k, v)| format!("{k}={v:.3}"))
            .collect::<Vec<_>>()
            .join(";"),
        rays_primary: s.primary_rays,
        rays_secondary: total_rays - s.primary_rays,
        mrays_camera_per_thread_s: rates.camera,
        mrays_shadow_per_thread_s: rates.shadow,
        mrays_ao_per_thread_s: rates.ambient_occlusion,
        mrays_bounce_per_thread_s: rates.bounce,
        memory_bytes: report.memory_bytes,
        triangles: report.triangles,
        peak_heap_bytes_build,
        peak_heap_bytes_render,
        peak_rss_bytes_build,
        peak_rss_bytes_render,
        silhouette_mismatch_pct: acc.as_ref().map(|a| a.0.silhouette_mismatch_pct),
        depth_err_mean: acc.as_ref().map(|a| a.0.depth_abs_mean),
        depth_err_p95: acc.as_ref().map(|a| a.0.depth_abs_p95),
        depth_err_max: acc.as_ref().map(|a| a.0.depth_abs_max),
        depth_err_p95_rel_scene: acc.as_ref().and_then(|a| rel(a.0.depth_abs_p95, a.1)),
        depth_err_max_rel_scene: acc.as_ref().and_then(|a| rel(a.0.depth_abs_max, a.1)),
        scene_size_world: acc.as_ref().and_then(|a| a.1),
        normal_err_deg_mean: acc.as_ref().map(|a| a.0.normal_deg_mean),
        normal_err_deg_p95: acc.as_ref().map(|a| a.0.normal_deg_p95),
        depth_err_rel_max: acc.as_ref().map(|a| a.0.depth_rel_max),
        depth_err_rel_tail_px: acc.as_ref().map(|a| a.0.depth_rel_tail_px as u64),
        normal_err_deg_max: acc.as_ref().map(|a| a.0.normal_deg_max),
        normal_err_deg_tail_px: acc.as_ref().map(|a| a.0.normal_deg_tail_px as u64),
        psnr_db: acc.as_ref().map(|a| a.0.psnr_db.min(100.0)),
        ssim: acc.as_ref().and_then(|a| a.2),
        steps_mean: s.mean_steps(),
        steps_max: s.max_steps_seen,
        step_exhaustion_pct: 100.0 * s.step_exhaustion_rate(),
        node_visits_per_ray: s.mean_node_visits(),
        node_visits_max: s.max_node_visits_seen,
        non_finite_count: images::non_finite(fb) + s.non_finite_hits + s.non_finite_pixels,
        notes: notes.join("; "),
        ..Row::default()
    };
    let histogram = images::steps_histogram(fb);
    drop(warm);
    Ok(Prepared {
        index,
        loaded: l.clone(),
        geometry,
        row,
        histogram,
        samples: Vec::new(),
        error: None,
        write_errors,
    })
}

/// Shard `index` of `count` of a suite (`bench --shard K/N`, 1-based `K`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// Which shard, 1 ..= `count`.
    pub index: usize,
    /// How many shards.
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// Parses `K/N` with 1 <= K <= N.
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("--shard {s:?}: expected K/N with 1 <= K <= N, e.g. 2/8");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count): (usize, usize) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if index == 0 || index > count {
            return Err(bad());
        }
        Ok(Self { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// The configurations of shard `shard`: a deterministic partition of `configs` (every
/// configuration in exactly one shard) in which all configurations of one scene file stay
/// together, so each scene's reference renders and rotation blocks are made once. Scenes go
/// to shards greedily, most configurations first, each to the shard with the fewest so far
/// (ties: lowest shard, then suite order). Suite order is kept within a shard.
///
/// Errors: more shards than scene files, the units a suite is split into (checked before
/// anything is allocated per shard): some shard would be empty, so its run would fail and
/// the shards could never be merged. The message gives the largest possible N.
pub fn shard(configs: &[Config], shard: Shard) -> Result<Vec<Config>, String> {
    let mut scene_index: HashMap<&Path, usize> = HashMap::new();
    let mut scenes: Vec<(&Path, usize)> = Vec::new();
    for c in configs {
        let i = *scene_index
            .entry(c.scene_path.as_path())
            .or_insert_with(|| {
                scenes.push((c.scene_path.as_path(), 0));
                scenes.len() - 1
            });
        scenes[i].1 += 1;
    }
    if shard.count > scenes.len() {
        return Err(format!(
            "--shard {shard}: {} shards but the {} configurations come from only {} scene files (all configurations of a scene run in one shard): N must be at most {}",
            shard.count,
            configs.len(),
            scenes.len(),
            scenes.len()
        ));
    }
    let mut order: Vec<usize> = (0..scenes.len()).collect();
    order.sort_by(|&a, &b| scenes[b].1.cmp(&scenes[a].1).then(a.cmp(&b)));
    let mut load = vec![0usize; shard.count];
    let mut owner = vec![0usize; scenes.len()];
    for i in order {
        let (s, _) = load
            .iter()
            .enumerate()
            .min_by_key(|&(k, l)| (*l, k))
            .unwrap_or((0, &0));
        owner[i] = s;
        load[s] += scenes[i].1;
    }
    Ok(configs
        .iter()
        .filter(|c| {
            scene_index
                .get(c.scene_path.as_path())
                .is_some_and(|&i| owner[i] == shard.index - 1)
        })
        .cloned()
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A simulated run of `blocks` rotation blocks of `per_block` configurations: each built
    /// in 2 s (the block's first also renders its reference, 10 s), then 3 rounds of 1 s per
    /// configuration. Returns (elapsed, estimated remaining, true remaining) at every event.
    fn simulate_eta(blocks: usize, per_block: usize) -> Vec<(f64, f64, f64)> {
        let policy = RepeatPolicy::default();
        let total = blocks * per_block;
        let mut eta = Eta::new(total);
        let mut t = 0.0;
        let mut events = Vec::new();
        for b in 0..blocks {
            for k in 0..per_block {
                t += if k == 0 { 12.0 } else { 2.0 };
                eta.advance(b * per_block + k, PREPARED_FRACTION);
                events.push((t, eta.remaining_s(t)));
            }
            for round in 1..=3u32 {
                for k in 0..per_block {
                    t += 1.0;
                    let timed = policy.progress(round, f64::from(round));
                    eta.advance(
                        b * per_block + k,
                        PREPARED_FRACTION + (1.0 - PREPARED_FRACTION) * timed,
                    );
                    events.push((t, eta.remaining_s(t)));
                }
            }
        }
        events
            .into_iter()
            .map(|(at, est)| (at, est.unwrap_or(f64::NAN), t - at))
            .collect()
    }

    #[test]
    fn results_record_scene_paths_from_the_scenes_folder() {
        assert_eq!(
            portable_scene_path(Path::new("/work/main/scenes/suites/../csg.json")),
            "scenes/csg.json"
        );
        assert_eq!(
            portable_scene_path(Path::new(
                "/home/u/.cache/marchmesh/0.1-ab/scenes/meshes/../seed-spheres.json"
            )),
            "scenes/seed-spheres.json"
        );
        assert_eq!(
            portable_scene_path(Path::new("mine/./x.json")),
            "mine/x.json"
        );
        assert_eq!(
            portable_scene_path(Path::new("/elsewhere/x.json")),
            "/elsewhere/x.json"
        );
    }

    #[test]
    fn the_eta_is_within_30_percent_after_the_first_block() {
        let per_block = 6;
        let events = simulate_eta(8, per_block);
        // The first block's events: its builds, then three rounds.
        let first_block = per_block + 3 * per_block;
        for (at, est, truth) in &events[first_block - 1..events.len() - 1] {
            let err = (est - truth).abs() / truth.max(1.0);
            // Within 30%, or 10 s near the end of the run (where the last block's reference
            // render, priced at the mean preparation rate, is a large share of what is left).
            assert!(
                err <= 0.3 || (est - truth).abs() < 10.0,
                "at {at} s: estimated {est:.0} s left, truly {truth:.0} s"
            );
        }
        // Before any configuration is built there is no estimate (not "eta 0s").
        assert!(Eta::new(3).remaining_s(40.0).is_none());
    }

    fn config(scene: &str, backend: &str) -> Config {
        Config {
            id: format!("g/{scene}/{backend}/64x64/t1"),
            group: "g".into(),
            scene: scene.into(),
            scene_path: PathBuf::from(format!("{scene}.json")),
            label: "q".into(),
            spec: BackendSpec {
                kind: BackendId::of::<marchmesh_sdf::SdfBackend>(),
                options: vec![],
            },
            resolution: Resolution::Size {
                width: 64,
                height: 64,
            },
            render: RenderOverrides::default(),
            truth_render: RenderOverrides::default(),
            threads: 1,
            reference: true,
            repeats: RepeatPolicy::default(),
        }
    }

    #[test]
    fn shards_partition_every_configuration_once_keeping_scenes_together() {
        let mut configs = Vec::new();
        for (scene, n) in [("a", 5), ("b", 1), ("c", 3), ("d", 3), ("e", 2), ("f", 7)] {
            for i in 0..n {
                configs.push(config(scene, &format!("sdf:{i}")));
            }
        }
        for count in 1..=6 {
            let shards: Vec<Vec<Config>> = (1..=count)
                .map(|index| shard(&configs, Shard { index, count }).unwrap())
                .collect();
            let mut seen: Vec<&str> = shards.iter().flatten().map(|c| c.id.as_str()).collect();
            seen.sort_unstable();
            let mut all: Vec<&str> = configs.iter().map(|c| c.id.as_str()).collect();
            all.sort_unstable();
            assert_eq!(seen, all, "{count} shards");
            for s in &shards {
                for c in s {
                    // A scene lives in exactly one shard.
                    assert_eq!(
                        shards
                            .iter()
                            .filter(|t| t.iter().any(|d| d.scene == c.scene))
                            .count(),
                        1
                    );
                }
                // Suite order kept.
                let pos: Vec<usize> = s
                    .iter()
                    .map(|c| configs.iter().position(|d| d.id == c.id).unwrap_or(0))
                    .collect();
                assert!(pos.windows(2).all(|w| w[0] < w[1]));
            }
            // Deterministic.
            assert_eq!(
                shard(&configs, Shard { index: 1, count }).unwrap(),
                shards[0]
            );
        }
        // Two shards balance 21 configurations as 11 / 10 (f+b+e... greedily).
        let two: Vec<usize> = (1..=2)
            .map(|index| shard(&configs, Shard { index, count: 2 }).unwrap().len())
            .collect();
        assert_eq!(two.iter().sum::<usize>(), 21);
        assert!(two.iter().all(|&n| (10..=11).contains(&n)), "{two:?}");
        // Six scenes: a seventh shard would be empty.
        let e = shard(&configs, Shard { index: 7, count: 7 }).unwrap_err();
        assert!(e.contains("at most 6"), "{e}");
    }

    #[test]
    fn more_shards_than_scenes_are_refused_before_allocating() {
        let configs = vec![config("a", "sdf"), config("b", "sdf")];
        for count in [3, 1_000_000_000_000, usize::MAX] {
            let e = shard(&configs, Shard { index: 1, count }).unwrap_err();
            assert!(e.contains("at most 2"), "{e}");
        }
        assert_eq!(
            shard(&configs, Shard { index: 2, count: 2 }).unwrap().len(),
            1
        );
    }

    #[test]
    fn long_slugs_are_capped_with_a_stable_hash() {
        assert_eq!(slug("g/s/sdf:a b/x1/t1"), "g_s_sdf_a_b_x1_t1");
        let long = |c: char| format!("{}/s/sdf:a/x1/t1", c.to_string().repeat(300));
        let (a, b) = (slug(&long('a')), slug(&long('b')));
        assert_eq!(a.len(), SLUG_MAX_BYTES);
        assert!(a.starts_with("aaaa") && a != b, "{a} {b}");
        assert_eq!(a, slug(&long('a')));
        // Ids differing only past the prefix still differ.
        let (x, y) = (
            format!("{}x", "g".repeat(200)),
            format!("{}y", "g".repeat(200)),
        );
        assert_ne!(slug(&x), slug(&y));
    }

    #[test]
    fn shard_specs_parse_and_refuse_nonsense() {
        assert_eq!("2/8".parse::<Shard>(), Ok(Shard { index: 2, count: 8 }));
        for bad in ["0/3", "4/3", "3", "a/b", "1/0", ""] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
    }

    #[test]
    fn rotation_blocks_group_one_scene_and_resolution() {
        let mut c = vec![config("a", "sdf"), config("a", "mesh"), config("b", "sdf")];
        c[1].resolution = Resolution::Size {
            width: 64,
            height: 64,
        };
        let mut d = config("a", "mesh:2");
        d.resolution = Resolution::MaxSide { max_side: 32 };
        c.push(d);
        assert_eq!(rotation_blocks(&c), vec![0..2, 2..3, 3..4]);
    }
}
