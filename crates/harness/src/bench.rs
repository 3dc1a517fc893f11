//! Runs a suite: every configuration is built, rendered once untimed (heap, RSS, accuracy,
//! work and images come from this render), then rendered repeatedly for timing.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use marchmesh_core::{BackgroundSampler, Framebuffer, RenderOptions, compare, image_io, render};
use marchmesh_scene::{RenderOverrides, Scene};

use crate::alloc::HeapPhase;
use crate::backend::{self, BackendKind, BackendSpec};
use crate::images;
use crate::results::{Failure, ReferenceInfo, Row};
use crate::rss::RssPhase;
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
#[derive(Debug, Clone, Default)]
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
}

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
                        let kind = spec.kind.map_or("?", BackendKind::name);
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

/// File-name-safe version of a configuration id.
pub fn slug(id: &str) -> String {
    id.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.=".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
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

/// Runs `configs`. `stop` is checked between configurations (and between repeats): once set,
/// the run ends with the rows finished so far and `interrupted = true`.
pub fn run(
    configs: &[Config],
    options: &BenchOptions,
    progress: &mut dyn Progress,
    stop: &AtomicBool,
) -> Outcome {
    let mut out = Outcome::default();
    let mut scenes: HashMap<SceneKey, Result<Loaded, String>> = HashMap::new();
    let mut truths: HashMap<SceneKey, Result<Truth, String>> = HashMap::new();
    progress.start(configs.len());
    for (index, c) in configs.iter().enumerate() {
        if stop.load(Ordering::Relaxed) {
            out.interrupted = true;
            progress.note("stopped: writing the finished configurations");
            break;
        }
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
            let truth_scene = scenes
                .entry(truth_key.clone())
                .or_insert_with(|| load_scene(&c.scene_path, c.resolution, &c.truth_render));
            let truth = match truth_scene {
                Ok(truth_scene) => {
                    progress.phase("reference");
                    let (truth, info) = reference_render(c, truth_scene, options);
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
            .entry(loaded_key.clone())
            .or_insert_with(|| load_scene(&c.scene_path, c.resolution, &c.render));
        let loaded = match loaded {
            Ok(l) => l,
            Err(e) => {
                out.failures.push(Failure {
                    config_id: c.id.clone(),
                    error: e.clone(),
                });
                progress.note(&format!("{}: {e}", c.id));
                progress.done(index);
                continue;
            }
        };
        let truth = if c.reference {
            truths.get(&truth_key)
        } else {
            None
        };
        match measure(c, loaded, truth, options, progress, stop) {
            Ok((row, hist)) => {
                out.steps_histograms.insert(c.id.clone(), hist);
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
        progress.done(index);
    }
    out
}

fn reference_render(
    c: &Config,
    l: &Loaded,
    options: &BenchOptions,
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
        kind: Some(BackendKind::Reference),
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
                let _ = image_io::write_png(&o.framebuffer, &p);
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

fn measure(
    c: &Config,
    l: &Loaded,
    truth: Option<&Result<Truth, String>>,
    options: &BenchOptions,
    progress: &mut dyn Progress,
    stop: &AtomicBool,
) -> Result<(Row, Vec<u64>), String> {
    let scene = &l.scene;
    progress.phase("build");
    let heap = HeapPhase::start();
    let rss = RssPhase::start();
    let t0 = Instant::now();
    let geometry = backend::build(scene, &c.spec).map_err(|e| e.to_string())?;
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

    let mut n = 0;
    let samples = c.repeats.run(
        || {
            n += 1;
            progress.phase(&format!("repeat {n}"));
            render(scene, geometry.as_ref(), &l.background, &ropts, &|| {})
                .map(|o| o.elapsed.as_secs_f64())
                .map_err(|e| format!("render: {e}"))
        },
        || stop.load(Ordering::Relaxed),
    )?;
    let samples_ms: Vec<f64> = samples.iter().map(|s| s * 1e3).collect();
    let t = Summary::of(&samples_ms).ok_or("no timed repeat")?;

    let s = &warm.stats;
    let fb = &warm.framebuffer;
    let mut notes = Vec::new();
    let slug_id = slug(&c.id);
    if let Some(dir) = &options.images_dir {
        let _ = image_io::write_png(fb, &dir.join(format!("{slug_id}.png")));
    }
    let acc = match truth {
        Some(Ok(truth)) => {
            let a = compare(fb, &truth.fb).map_err(|e| e.to_string())?;
            if let Some(dir) = &options.images_dir {
                let _ =
                    images::write_diff_png(fb, &truth.fb, &dir.join(format!("{slug_id}.diff.png")));
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
    let kind = c.spec.kind.map_or("?", BackendKind::name);
    let counter = |name: &str| {
        report
            .counters
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| *v as u64)
    };
    let triangles = (kind == "mesh")
        .then(|| counter("flat_triangles").unwrap_or(0) + counter("blas_triangles").unwrap_or(0));
    let total_rays = s.total_rays();
    let rates = s.mrays_per_thread_second();
    let row = Row {
        config_id: c.id.clone(),
        group: c.group.clone(),
        scene: c.scene.clone(),
        scene_file: c.scene_path.display().to_string(),
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
        build_ms_total,
        build_phases_ms: report
            .build_phases_ms
            .iter()
            .map(|(k, v)| format!("{k}={v:.3}"))
            .collect::<Vec<_>>()
            .join(";"),
        render_repeats: t.n,
        render_ms_median: t.median,
        render_ms_min: t.min,
        render_ms_max: t.max,
        render_ms_mad: t.mad,
        render_ms_ci_low: t.ci_low,
        render_ms_ci_high: t.ci_high,
        render_ci_coverage: t.ci_coverage,
        rays_primary: s.primary_rays,
        rays_secondary: total_rays - s.primary_rays,
        mrays_per_s: total_rays as f64 / (t.median * 1e-3).max(1e-12) / 1e6,
        mrays_camera_per_thread_s: rates.camera,
        mrays_shadow_per_thread_s: rates.shadow,
        mrays_ao_per_thread_s: rates.ambient_occlusion,
        mrays_bounce_per_thread_s: rates.bounce,
        memory_bytes: report.memory_bytes,
        triangles,
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
    };
    Ok((row, images::steps_histogram(fb)))
}
