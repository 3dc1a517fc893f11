//! Renders stability cases and judges them against their ground truth.

use std::path::Path;
use std::time::Instant;

use marchmesh_core::{
    Accuracy, BackgroundSampler, Framebuffer, Measured, RenderOptions, RenderOutput, Tolerance,
    compare, render,
};
use marchmesh_registry::{self as backend, BackendId, BackendSpec};
use marchmesh_scene::{Scene, parse_scene};
use serde::Serialize;

use crate::cases::{StabilityCase, Variant};

/// How the cases are run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunOptions {
    /// Image side in pixels (square renders). Default 96.
    pub side: u32,
    /// Render threads (0 = all cores).
    pub threads: usize,
    /// Each build and render is refused before allocating more than this many bytes.
    pub memory_limit_bytes: u64,
}

impl Default for RunOptions {
    fn default() -> Self {
        Self {
            side: 96,
            threads: 0,
            memory_limit_bytes: marchmesh_core::DEFAULT_MEMORY_LIMIT_BYTES,
        }
    }
}

/// Whether a configuration's result can be trusted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Indistinguishable from the truth at this resolution: no NaN/inf, silhouette mismatch
    /// <= 0.5% of pixels, relative depth error p95 <= 1e-3, mean normal error <= 1 degree,
    /// step exhaustion <= 0.1% of rays (image-judged cases: PSNR >= 40 dB).
    Exact,
    /// Usable with visible error: no NaN/inf, silhouette <= 5%, relative depth p95 <= 1e-2,
    /// mean normal error <= 5 degrees, step exhaustion <= 5% (image-judged: PSNR >= 25 dB).
    Degraded,
    /// Anything worse, or NaN/inf in the output.
    Broken,
    /// The backend refused to build the scene (the error is in the row's `error`).
    Refused,
}

impl Verdict {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Exact => "exact",
            Verdict::Degraded => "degraded",
            Verdict::Broken => "broken",
            Verdict::Refused => "refused",
        }
    }
}

/// What was measured for one configuration.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Metrics {
    /// Non-finite values in the output (pixels, hits, AOVs); must be zero.
    pub non_finite: u64,
    /// Pixels hit by exactly one of the configuration and the truth, % of all pixels.
    pub silhouette_mismatch_pct: f64,
    /// Pixels the truth hits with all four neighbours hit, that the configuration misses:
    /// rays slipping through a surface (cracks between triangles, tunnelling).
    pub interior_holes: u64,
    /// 95th percentile of |depth - true depth| / true depth over pixels both hit.
    pub depth_rel_p95: f64,
    /// Largest |depth - true depth| over pixels both hit, relative to the scene size.
    pub depth_max_over_scene: f64,
    /// Largest |depth - true depth| / true depth over pixels both hit (reported, not judged).
    pub depth_rel_max: f64,
    /// Pixels both hit with relative depth error above 1e-3 (reported, not judged).
    pub depth_rel_tail_px: u64,
    /// Pixels both hit with normal error above 5 degrees (reported, not judged).
    pub normal_deg_tail_px: u64,
    /// Mean normal angle error, degrees.
    pub normal_deg_mean: f64,
    /// 95th percentile normal angle error, degrees.
    pub normal_deg_p95: f64,
    /// 8-bit PSNR of the image against the truth's, dB (infinite when identical).
    pub psnr_db: f64,
    /// Rays (all kinds) that ended by step exhaustion, %.
    pub step_exhaustion_pct: f64,
    /// Mean sphere-tracing steps (or root-finding iterations) per ray.
    pub mean_steps: f64,
}

impl Metrics {
    /// Metrics of `test` against `truth` (same size).
    pub fn measure(test: &RenderOutput, truth: &RenderOutput, scene_size: f64) -> Self {
        let acc: Accuracy = compare(&test.framebuffer, &truth.framebuffer)
            .unwrap_or_else(|_| unreachable!("both renders use the case's image size"));
        let s = &test.stats;
        Self {
            non_finite: acc.non_finite as u64 + s.non_finite_hits + s.non_finite_pixels,
            silhouette_mismatch_pct: acc.silhouette_mismatch_pct,
            interior_holes: interior_holes(&test.framebuffer, &truth.framebuffer),
            depth_rel_p95: acc.depth_rel_p95,
            depth_max_over_scene: acc.depth_abs_max / scene_size.max(f64::MIN_POSITIVE),
            depth_rel_max: acc.depth_rel_max,
            depth_rel_tail_px: acc.depth_rel_tail_px as u64,
            normal_deg_tail_px: acc.normal_deg_tail_px as u64,
            normal_deg_mean: acc.normal_deg_mean,
            normal_deg_p95: acc.normal_deg_p95,
            psnr_db: acc.psnr_db,
            step_exhaustion_pct: 100.0 * s.step_exhaustion_rate(),
            mean_steps: s.mean_steps(),
        }
    }

    /// The verdict (see [`Verdict`] for the thresholds).
    pub fn verdict(&self, judge_by_image: bool) -> Verdict {
        if self.non_finite > 0 {
            return Verdict::Broken;
        }
        if judge_by_image {
            return if self.psnr_db >= marchmesh_core::INVISIBLE_PSNR_DB {
                Verdict::Exact
            } else if self.psnr_db >= 25.0 {
                Verdict::Degraded
            } else {
                Verdict::Broken
            };
        }
        // The same bounds type as the conformance suite (materials are not judged here).
        let m = Measured {
            silhouette_mismatch_pct: self.silhouette_mismatch_pct,
            depth_rel_p95: self.depth_rel_p95,
            normal_deg_mean: self.normal_deg_mean,
            material_mismatch_pct: 0.0,
            step_exhaustion_pct: self.step_exhaustion_pct,
        };
        if Tolerance::STABILITY_EXACT.admits(&m) {
            Verdict::Exact
        } else if Tolerance::STABILITY_DEGRADED.admits(&m) {
            Verdict::Degraded
        } else {
            Verdict::Broken
        }
    }
}

/// Pixels the truth hits, with its four neighbours hit too, where `test` misses.
pub fn interior_holes(test: &Framebuffer, truth: &Framebuffer) -> u64 {
    let (w, h) = (truth.width as usize, truth.height as usize);
    let mut n = 0;
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let i = y * w + x;
            let solid = [i, i - 1, i + 1, i - w, i + w]
                .iter()
                .all(|&j| truth.is_hit(j));
            if solid && !test.is_hit(i) {
                n += 1;
            }
        }
    }
    n
}

/// One row of the stability report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    /// `family/parameter=value`.
    pub case: String,
    /// Family name.
    pub family: String,
    /// Swept parameter.
    pub parameter: String,
    /// Swept value.
    pub value: f64,
    /// Backend name.
    pub backend: String,
    /// `backend[k=v,...]`.
    pub configuration: String,
    /// The verdict.
    pub verdict: Verdict,
    /// Measurements (`None` when the backend refused the scene).
    pub metrics: Option<Metrics>,
    /// Build time of the configuration, ms.
    pub build_ms: f64,
    /// Render time of the configuration, ms.
    pub render_ms: f64,
    /// Representation bytes reported by the backend.
    pub memory_bytes: u64,
    /// The build or render error, when refused.
    pub error: Option<String>,
    /// The backend's notes (conversions, clamps).
    pub notes: Vec<String>,
}

/// Why a case could not run at all (its scene or its truth failed).
#[derive(Debug, thiserror::Error)]
pub enum CaseError {
    /// The generated scene does not parse or validate.
    #[error("{case}: scene rejected: {reason}")]
    Scene {
        /// Case id.
        case: String,
        /// The scene error.
        reason: String,
    },
    /// The reference could not produce the truth.
    #[error("{case}: ground truth failed: {reason}")]
    Truth {
        /// Case id.
        case: String,
        /// The reason.
        reason: String,
    },
}

fn load(case: &StabilityCase, json: &str, side: u32) -> Result<Scene, CaseError> {
    let err = |e: &dyn std::fmt::Display| CaseError::Scene {
        case: case.id(),
        reason: e.to_string(),
    };
    let scene = parse_scene(json, &format!("<stability {}>", case.id()), &case.base_dir)
        .map_err(|e| err(&e))?;
    scene.with_image_size(side, side).map_err(|e| err(&e))
}

struct Rendered {
    output: RenderOutput,
    build_ms: f64,
    memory_bytes: u64,
    notes: Vec<String>,
}

fn build_and_render(
    scene: &Scene,
    variant: &Variant,
    options: &RunOptions,
) -> Result<Rendered, String> {
    let spec = BackendSpec {
        kind: variant.backend,
        options: variant.options.clone(),
    };
    let t0 = Instant::now();
    let geometry = backend::build_within(scene, &spec, options.memory_limit_bytes)
        .map_err(|e| e.to_string())?;
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let background = BackgroundSampler::load_within(&scene.background, options.memory_limit_bytes)
        .map_err(|e| e.to_string())?;
    let render_options = RenderOptions {
        threads: options.threads,
        memory_limit_bytes: options.memory_limit_bytes,
        ..Default::default()
    };
    let output = render(
        scene,
        geometry.as_ref(),
        &background,
        &render_options,
        &|| {},
    )
    .map_err(|e| e.to_string())?;
    let report = geometry.report();
    Ok(Rendered {
        output,
        build_ms,
        memory_bytes: report.memory_bytes,
        notes: report.notes,
    })
}

/// Runs one case: the truth, then every variant against it.
pub fn run_case(case: &StabilityCase, options: &RunOptions) -> Result<Vec<Row>, CaseError> {
    let scene = load(case, &case.scene_json, options.side)?;
    let truth_scene = match &case.truth_json {
        Some(json) => load(case, json, options.side)?,
        None => scene.clone(),
    };
    let truth_of = |variant: &Variant| {
        build_and_render(&truth_scene, variant, options).map_err(|reason| CaseError::Truth {
            case: case.id(),
            reason,
        })
    };
    let reference = Variant::default_of(BackendId::REFERENCE);
    let shared_truth = if case.self_truth {
        None
    } else {
        Some(truth_of(&reference)?)
    };
    let mut rows = Vec::new();
    for variant in &case.variants {
        let row = |verdict, metrics, r: Option<&Rendered>, error| Row {
            case: case.id(),
            family: case.family.to_string(),
            parameter: case.parameter.to_string(),
            value: case.value,
            backend: variant.backend.name().to_string(),
            configuration: variant.label(),
            verdict,
            metrics,
            build_ms: r.map_or(0.0, |r| r.build_ms),
            render_ms: r.map_or(0.0, |r| r.output.elapsed.as_secs_f64() * 1e3),
            memory_bytes: r.map_or(0, |r| r.memory_bytes),
            error,
            notes: r.map_or_else(Vec::new, |r| r.notes.clone()),
        };
        let own_truth;
        let truth = match &shared_truth {
            Some(t) => t,
            None => {
                own_truth = truth_of(variant)?;
                &own_truth
            }
        };
        match build_and_render(&scene, variant, options) {
            Ok(r) => {
                let m = Metrics::measure(&r.output, &truth.output, case.scene_size);
                rows.push(row(m.verdict(case.judge_by_image), Some(m), Some(&r), None));
            }
            Err(e) => rows.push(row(Verdict::Refused, None, None, Some(e))),
        }
    }
    Ok(rows)
}

/// Runs every case whose id contains `filter` (all when `None`), calling `progress` with
/// each case id before it starts. Cases that cannot run are returned as errors beside the
/// rows of those that did.
pub fn run_cases(
    cases: &[StabilityCase],
    filter: Option<&str>,
    options: &RunOptions,
    progress: &mut dyn FnMut(usize, usize, &str),
) -> (Vec<Row>, Vec<CaseError>) {
    let selected: Vec<&StabilityCase> = cases
        .iter()
        .filter(|c| filter.is_none_or(|f| c.id().contains(f)))
        .collect();
    let mut rows = Vec::new();
    let mut errors = Vec::new();
    for (i, case) in selected.iter().enumerate() {
        progress(i, selected.len(), &case.id());
        match run_case(case, options) {
            Ok(r) => rows.extend(r),
            Err(e) => errors.push(e),
        }
    }
    (rows, errors)
}

/// Writes each case's scene (and truth scene) as pretty JSON into `dir`, named after the
/// case id, so any case can be re-rendered with `marchmesh render`. Mesh paths are rewritten
/// relative to `dir` (the meshes themselves are not copied). Returns the file names written.
pub fn write_scenes(cases: &[&StabilityCase], dir: &Path) -> std::io::Result<Vec<String>> {
    marchmesh_safeio::create_folder(dir).map_err(std::io::Error::other)?;
    let dir_abs = std::path::absolute(dir)?;
    let mut written = Vec::new();
    for c in cases {
        let stem = c.id().replace(['/', '='], "_");
        let base = std::path::absolute(&c.base_dir)?;
        let texts = std::iter::once(("", &c.scene_json))
            .chain(c.truth_json.as_ref().map(|t| (".truth", t)));
        for (suffix, json) in texts {
            let mut v: serde_json::Value =
                serde_json::from_str(json).map_err(std::io::Error::other)?;
            rewrite_mesh_paths(&mut v, &base, &dir_abs);
            let name = format!("{stem}{suffix}.json");
            let text = serde_json::to_string_pretty(&v).map_err(std::io::Error::other)?;
            marchmesh_safeio::publish_new(&dir.join(&name), (text + "\n").as_bytes())
                .map_err(std::io::Error::other)?;
            written.push(name);
        }
    }
    Ok(written)
}

/// Rewrites every `"mesh": {"path": ...}` from relative-to-`from` to relative-to-`to`.
fn rewrite_mesh_paths(v: &mut serde_json::Value, from: &Path, to: &Path) {
    match v {
        serde_json::Value::Object(map) => {
            if let Some(serde_json::Value::Object(mesh)) = map.get_mut("mesh")
                && let Some(serde_json::Value::String(p)) = mesh.get_mut("path")
            {
                let abs = from.join(&*p);
                *p = relative_path(&abs, to).to_string_lossy().replace('\\', "/");
            }
            for (_, child) in map.iter_mut() {
                rewrite_mesh_paths(child, from, to);
            }
        }
        serde_json::Value::Array(items) => {
            for child in items {
                rewrite_mesh_paths(child, from, to);
            }
        }
        _ => {}
    }
}

/// `target` expressed relative to the folder `base` (both absolute, lexically normalised).
pub fn relative_path(target: &Path, base: &Path) -> std::path::PathBuf {
    use std::path::Component;
    let norm = |p: &Path| -> Vec<std::ffi::OsString> {
        let mut out: Vec<std::ffi::OsString> = Vec::new();
        for c in p.components() {
            match c {
                Component::ParentDir => {
                    out.pop();
                }
                Component::CurDir => {}
                other => out.push(other.as_os_str().to_owned()),
            }
        }
        out
    };
    let (t, b) = (norm(target), norm(base));
    let common = t.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut out = std::path::PathBuf::new();
    for _ in common..b.len() {
        out.push("..");
    }
    for part in &t[common..] {
        out.push(part);
    }
    out
}
