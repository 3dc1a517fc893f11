//! Runs a suite: every configuration is built, rendered once untimed (heap, RSS, accuracy,
//! work and images come from this render), then the configurations of one scene and resolution
//! are timed together in shuffled rotation rounds (see [`run`]).
//!
//! `configs` lists a suite's configurations, `shard` cuts them between machines,
//! `prepare` loads scenes and builds what a configuration renders, `progress` reports the
//! run with its time estimate; this file runs the rotation rounds and records the rows.

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::rc::Rc;
use std::sync::atomic::{AtomicBool, Ordering};

use marchmesh_core::{DEFAULT_MEMORY_LIMIT_BYTES, RenderOptions, render};
use marchmesh_scene::RenderOverrides;

use crate::backend::BackendSpec;
use crate::results::{Failure, ReferenceInfo, Row, TimingSample};
use crate::schedule;
use crate::stats::{RepeatPolicy, Summary};
use crate::suite::Resolution;

mod configs;
mod prepare;
mod progress;
mod shard;

use configs::resolution_tag;
pub use configs::{
    SLUG_MAX_BYTES, configurations, filter_matches, portable_scene_path, rotation_blocks, slug,
};
use prepare::{Loaded, Prepared, SceneKey, Truth, load_scene, prepare, reference_render};
pub use progress::{Eta, PREPARED_FRACTION, Progress, Silent};
pub use shard::{Shard, shard};

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

/// Configurations the tests of every concept share.
#[cfg(test)]
mod test_util {
    use super::*;
    use crate::backend::BackendId;

    pub(super) fn config(scene: &str, backend: &str) -> Config {
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
}
