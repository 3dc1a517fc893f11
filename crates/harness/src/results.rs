//! What a run produces: one [`Row`] per configuration (the CSV columns, units in the names),
//! plus provenance, failures and per-configuration step histograms in `results.json`.

use std::collections::BTreeMap;
use std::path::Path;

use marchmesh_core::compare::Accuracy;
use serde::{Deserialize, Serialize};

/// One measured configuration. Field order is the CSV column order. `Option` fields are
/// empty in the CSV (null in JSON) only where they do not apply; see [`Row::why_empty`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// `group/scene/backend:label/WxH/tN`.
    pub config_id: String,
    /// Suite group.
    pub group: String,
    /// Scene name.
    pub scene: String,
    /// Scene file as given.
    pub scene_file: String,
    /// Backend name.
    pub backend: String,
    /// Quality label.
    pub quality: String,
    /// Options as `k=v;k=v` (empty = defaults).
    pub options: String,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Render threads.
    pub threads: usize,
    /// Host name of the machine that measured it (see [`Provenance::machine`]); speed is only
    /// compared between rows of the same machine.
    #[serde(default)]
    pub machine: String,
    /// Wall time of the backend build, ms.
    pub build_ms_total: f64,
    /// The backend's build phases as `name=ms;...`.
    pub build_phases_ms: String,
    /// Timed render repeats.
    pub render_repeats: usize,
    /// Median render time, ms.
    pub render_ms_median: f64,
    /// Fastest render, ms.
    pub render_ms_min: f64,
    /// Slowest render, ms.
    pub render_ms_max: f64,
    /// Median absolute deviation of render times, ms.
    pub render_ms_mad: f64,
    /// Lower end of the confidence interval of the median, ms.
    pub render_ms_ci_low: f64,
    /// Upper end of the confidence interval of the median, ms.
    pub render_ms_ci_high: f64,
    /// Coverage of that interval (0.95 or more from 6 repeats on).
    pub render_ci_coverage: f64,
    /// Median process CPU time (user + system, all threads) of one timed render, ms: unlike
    /// wall time it hardly grows when other processes compete for the cores.
    #[serde(default)]
    pub render_cpu_ms_median: Option<f64>,
    /// Lower end of the 95% confidence interval of the CPU-time median, ms.
    #[serde(default)]
    pub render_cpu_ms_ci_low: Option<f64>,
    /// Upper end of the 95% confidence interval of the CPU-time median, ms.
    #[serde(default)]
    pub render_cpu_ms_ci_high: Option<f64>,
    /// Camera rays per render.
    pub rays_primary: u64,
    /// Shadow, ambient-occlusion, reflection and bounce rays per render.
    pub rays_secondary: u64,
    /// (primary + secondary) rays / median render time, millions per second.
    pub mrays_per_s: f64,
    /// (primary + secondary) rays / median CPU time of a render, millions per CPU-second.
    #[serde(default)]
    pub mrays_per_cpu_s: Option<f64>,
    /// Camera rays per thread-second spent in the geometry, millions (timed per batch).
    #[serde(default)]
    pub mrays_camera_per_thread_s: Option<f64>,
    /// Shadow rays (or cone queries) per thread-second spent in the geometry, millions.
    #[serde(default)]
    pub mrays_shadow_per_thread_s: Option<f64>,
    /// Ambient-occlusion rays (or tap queries) per thread-second in the geometry, millions.
    #[serde(default)]
    pub mrays_ao_per_thread_s: Option<f64>,
    /// Reflection and path-tracer bounce rays per thread-second in the geometry, millions.
    #[serde(default)]
    pub mrays_bounce_per_thread_s: Option<f64>,
    /// Representation bytes reported by the backend.
    pub memory_bytes: u64,
    /// Triangles stored (mesh backend; flat + instanced BLAS triangles).
    pub triangles: Option<u64>,
    /// Peak heap above the phase's starting level during the build, bytes.
    pub peak_heap_bytes_build: Option<u64>,
    /// Peak heap above the phase's starting level during one render, bytes.
    pub peak_heap_bytes_render: Option<u64>,
    /// Process peak RSS during the build, bytes.
    pub peak_rss_bytes_build: Option<u64>,
    /// Process peak RSS during one render, bytes.
    pub peak_rss_bytes_render: Option<u64>,
    /// Pixels hit by exactly one of this render and the reference, %.
    pub silhouette_mismatch_pct: Option<f64>,
    /// Mean |depth - reference depth| where both hit, world units.
    pub depth_err_mean: Option<f64>,
    /// 95th percentile depth error, world units.
    pub depth_err_p95: Option<f64>,
    /// Largest depth error, world units.
    pub depth_err_max: Option<f64>,
    /// `depth_err_p95 / scene_size_world`.
    pub depth_err_p95_rel_scene: Option<f64>,
    /// `depth_err_max / scene_size_world`.
    pub depth_err_max_rel_scene: Option<f64>,
    /// Diagonal of the box around the points the reference sees, world units.
    pub scene_size_world: Option<f64>,
    /// Mean normal angle error, degrees.
    pub normal_err_deg_mean: Option<f64>,
    /// 95th percentile normal angle error, degrees.
    pub normal_err_deg_p95: Option<f64>,
    /// Largest |depth - reference depth| / reference depth where both hit (the tail a p95
    /// hides). Empty in results written before the column existed.
    #[serde(default)]
    pub depth_err_rel_max: Option<f64>,
    /// Pixels hit by both with relative depth error above 1e-3 (`core::compare::DEPTH_REL_TAIL`).
    #[serde(default)]
    pub depth_err_rel_tail_px: Option<u64>,
    /// Largest normal angle error, degrees.
    #[serde(default)]
    pub normal_err_deg_max: Option<f64>,
    /// Pixels hit by both with normal error above 5 degrees (`core::compare::NORMAL_DEG_TAIL`).
    #[serde(default)]
    pub normal_err_deg_tail_px: Option<u64>,
    /// 8-bit PSNR against the reference image, dB (capped at 100 = identical).
    pub psnr_db: Option<f64>,
    /// Mean SSIM of the luma (8x8 windows, stride 4) against the reference image.
    pub ssim: Option<f64>,
    /// Mean SDF steps per ray (all rays; 0 for backends that do not march).
    pub steps_mean: f64,
    /// Most SDF steps of any ray.
    pub steps_max: u32,
    /// Rays ending by step exhaustion, %.
    pub step_exhaustion_pct: f64,
    /// Mean BVH nodes visited per ray (0 for backends without a BVH).
    pub node_visits_per_ray: f64,
    /// Most nodes visited by any ray.
    pub node_visits_max: u32,
    /// NaN/inf values in the output (colour, depth, hits); should be 0.
    pub non_finite_count: u64,
    /// Why accuracy columns are empty, or other remarks (`;`-separated).
    pub notes: String,
}

impl Row {
    /// Fills the accuracy columns from the comparison with the reference: `accuracy` of the
    /// render, the scene's size in world units (`None` when unbounded; the `_rel_scene`
    /// columns stay empty then) and the SSIM (`None` when the image is too small). A new
    /// accuracy column is its field here and its line below; [`accuracy_columns`] follows.
    pub fn set_accuracy(
        &mut self,
        accuracy: &Accuracy,
        scene_size: Option<f64>,
        ssim: Option<f64>,
    ) {
        let a = accuracy;
        let rel = |v: f64| scene_size.filter(|s| *s > 0.0).map(|s| v / s);
        self.silhouette_mismatch_pct = Some(a.silhouette_mismatch_pct);
        self.depth_err_mean = Some(a.depth_abs_mean);
        self.depth_err_p95 = Some(a.depth_abs_p95);
        self.depth_err_max = Some(a.depth_abs_max);
        self.depth_err_p95_rel_scene = rel(a.depth_abs_p95);
        self.depth_err_max_rel_scene = rel(a.depth_abs_max);
        self.scene_size_world = scene_size;
        self.normal_err_deg_mean = Some(a.normal_deg_mean);
        self.normal_err_deg_p95 = Some(a.normal_deg_p95);
        self.depth_err_rel_max = Some(a.depth_rel_max);
        self.depth_err_rel_tail_px = Some(a.depth_rel_tail_px as u64);
        self.normal_err_deg_max = Some(a.normal_deg_max);
        self.normal_err_deg_tail_px = Some(a.normal_deg_tail_px as u64);
        self.psnr_db = Some(a.psnr_db.min(100.0));
        self.ssim = ssim;
    }

    /// Why `column` may be empty in this row, `None` if it must be filled.
    pub fn why_empty(&self, column: &str) -> Option<&'static str> {
        match column {
            "triangles" => Some("the backend does not store triangles"),
            "peak_heap_bytes_build" | "peak_heap_bytes_render" => {
                Some("counting allocator not installed in this binary")
            }
            "peak_rss_bytes_build" | "peak_rss_bytes_render" => {
                Some("peak RSS reset not available on this system")
            }
            c if !self.notes.is_empty() && accuracy_columns().iter().any(|a| a == c) => {
                Some("no reference (see notes)")
            }
            "notes" => Some("no remarks"),
            "render_cpu_ms_median"
            | "render_cpu_ms_ci_low"
            | "render_cpu_ms_ci_high"
            | "mrays_per_cpu_s" => Some("process CPU time unavailable on this system"),
            "mrays_shadow_per_thread_s"
            | "mrays_ao_per_thread_s"
            | "mrays_bounce_per_thread_s"
            | "mrays_camera_per_thread_s" => Some("no rays of this type were traced"),
            _ => None,
        }
    }
}

/// The columns [`Row::set_accuracy`] fills: those empty in a default row and filled once an
/// accuracy is set (every column of a comparison with the reference).
pub fn accuracy_columns() -> &'static [String] {
    static COLUMNS: std::sync::OnceLock<Vec<String>> = std::sync::OnceLock::new();
    COLUMNS.get_or_init(|| {
        let cells = |row: &Row| row_csv_lines(row).1;
        let empty = Row::default();
        let mut filled = Row::default();
        filled.set_accuracy(&Accuracy::default(), Some(1.0), Some(1.0));
        csv_header()
            .into_iter()
            .zip(cells(&empty).into_iter().zip(cells(&filled)))
            .filter(|(_, (before, after))| before != after)
            .map(|(name, _)| name)
            .collect()
    })
}

/// Where and how a run was made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// UTC start time, ISO 8601.
    pub date_utc: String,
    /// CPU model name.
    pub cpu_model: String,
    /// Logical cores available.
    pub logical_cores: usize,
    /// `rustc -V` of the compiler that built the binary.
    pub rustc: String,
    /// Target triple.
    pub target: String,
    /// `release` or `debug`.
    pub profile: String,
    /// `git rev-parse HEAD` at run time (`unknown` outside a repository).
    pub git_commit: String,
    /// Whether the work tree had uncommitted changes.
    pub git_dirty: bool,
    /// marchmesh version.
    pub version: String,
    /// The command line.
    pub command: String,
    /// 1-minute load average when the run started (`/proc/loadavg`; other processes competing
    /// for the cores make times noisier). `None` where unavailable.
    #[serde(default)]
    pub load_average_1m: Option<f64>,
    /// 1-minute load average when the run ended. With the start value it decides which clock
    /// verdicts use (see `report::Clock`).
    #[serde(default)]
    pub load_average_1m_end: Option<f64>,
    /// Host name of the machine (`/etc/hostname`, `HOSTNAME`), so merged shards keep apart
    /// the rows of different machines: speed is only compared within one machine.
    #[serde(default)]
    pub machine: String,
}

/// One timed render of a configuration.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimingSample {
    /// Rotation round it was taken in: samples of configurations of one scene and resolution
    /// with the same round were taken back to back and form the pairs of a paired ratio.
    pub round: u32,
    /// Wall-clock time of the render, ms.
    pub wall_ms: f64,
    /// Process CPU time (user + system, all threads) of the render, ms; `None` where the
    /// system cannot tell.
    pub cpu_ms: Option<f64>,
}

/// A reference render made for accuracy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceInfo {
    /// Scene name.
    pub scene: String,
    /// Image size.
    pub width: u32,
    /// Image size.
    pub height: u32,
    /// Build time, ms (`None` if it failed).
    pub build_ms: Option<f64>,
    /// One untimed render, ms.
    pub render_ms: Option<f64>,
    /// Why it is missing, if it is.
    pub error: Option<String>,
}

/// A configuration that could not be measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Failure {
    /// Its id.
    pub config_id: String,
    /// The error chain.
    pub error: String,
}

/// Everything `results.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Results {
    /// Folder name of the run.
    pub run_id: String,
    /// Suite name.
    pub suite: String,
    /// Suite file.
    pub suite_file: String,
    /// Suite description.
    pub description: String,
    /// Provenance.
    pub provenance: Provenance,
    /// Whether the run was stopped early (Ctrl-C): the rows are the finished ones.
    pub interrupted: bool,
    /// Measured configurations.
    pub rows: Vec<Row>,
    /// Configurations that failed.
    pub failures: Vec<Failure>,
    /// Scenes skipped, with the reason.
    pub skipped: Vec<String>,
    /// Reference renders.
    pub references: Vec<ReferenceInfo>,
    /// Per configuration: primary-ray SDF step counts in power-of-two bins
    /// (bin 0: 0 steps, bin k: 2^(k-1) ..= 2^k - 1).
    pub steps_histograms: BTreeMap<String, Vec<u64>>,
    /// Per configuration id: every timed render in order, with its rotation round.
    #[serde(default)]
    pub timings: BTreeMap<String, Vec<TimingSample>>,
    /// Seed of the shuffled round orders (`marchmesh bench --seed` reproduces the order).
    #[serde(default)]
    pub rotation_seed: Option<u64>,
    /// Configurations of the run that have no row and no failure: the run was interrupted
    /// (or crashed after a checkpoint) before measuring them.
    #[serde(default)]
    pub missing: Vec<String>,
    /// `K/N` when this is shard K of N of a suite (`bench --shard`); merged runs list their
    /// shards' provenance in `merged_from`.
    #[serde(default)]
    pub shard: Option<String>,
    /// For a run made by `marchmesh merge`: the run id, shard and provenance of each input.
    #[serde(default)]
    pub merged_from: Vec<MergedShard>,
    /// Files of the run (images) that could not be written, with the reason.
    #[serde(default)]
    pub write_errors: Vec<String>,
    /// External anchor runs recorded with this run (`marchmesh bench --anchor`): each
    /// backend against the best known implementation of its representation.
    #[serde(default)]
    pub anchors: Vec<crate::anchors::Anchor>,
}

/// One input of a merged run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MergedShard {
    /// Its run id.
    pub run_id: String,
    /// Its `K/N`, if it was a shard.
    pub shard: Option<String>,
    /// Where and how it was made.
    pub provenance: Provenance,
    /// How many rows it contributed.
    pub rows: usize,
}

/// Largest magnitude of a number [`Results::check_values`] accepts (1e15: a millisecond
/// count of 30,000 years, a PSNR, error or ray rate far beyond any measurement).
pub const MAX_RESULT_VALUE: f64 = 1e15;

/// Most bins of a steps histogram [`Results::check_values`] accepts: bin `k` counts rays of
/// `2^(k-1)..2^k - 1` steps, so a 64-bit step count fills at most 65.
pub const MAX_HISTOGRAM_BINS: usize = 65;

/// `x` as an error message shows it: in scientific notation when it is huge (1e308 in full
/// is 309 digits) or tiny.
fn short_number(x: f64) -> String {
    if x != 0.0 && x.is_finite() && !(1e-6..1e15).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// Why results could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ResultsError {
    /// The file is not a regular file within the read cap, or cannot be read.
    #[error(transparent)]
    Read(#[from] marchmesh_safeio::SafeIoError),
    /// File I/O.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: String,
        /// The error.
        source: std::io::Error,
    },
    /// JSON syntax or shape.
    #[error("{file}: at {path}: {reason}")]
    Json {
        /// The file.
        file: String,
        /// JSON path.
        path: String,
        /// The error.
        reason: String,
    },
    /// Writing a file failed (the OS error, or the target is not a regular file).
    #[error("{file}: {reason}")]
    Write {
        /// The file.
        file: String,
        /// Why.
        reason: String,
    },
    /// CSV writing or reading.
    #[error("{file}: {reason}")]
    Csv {
        /// The file.
        file: String,
        /// The error.
        reason: String,
    },
}

impl Results {
    /// Writes `results.json` (pretty) to `path`.
    pub fn write_json(&self, path: &Path) -> Result<(), ResultsError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| ResultsError::Json {
            file: path.display().to_string(),
            path: String::new(),
            reason: e.to_string(),
        })?;
        // Atomic (temporary file renamed over it): a checkpoint interrupted mid-write leaves
        // the previous checkpoint, never half a file.
        marchmesh_safeio::replace_regular(path, (text + "\n").as_bytes()).map_err(|e| {
            ResultsError::Write {
                file: path.display().to_string(),
                reason: e.to_string(),
            }
        })
    }

    /// Reads a `results.json` (a regular file within the `MARCHMESH_MAX_READ_MIB` read cap)
    /// and checks its numbers ([`Self::check_values`]); errors name the file and the JSON path (the
    /// row's configuration id for a bad value).
    pub fn read_json(path: &Path) -> Result<Self, ResultsError> {
        let bytes = marchmesh_safeio::read_regular(path)?;
        let de = &mut serde_json::Deserializer::from_slice(&bytes);
        let results: Self =
            serde_path_to_error::deserialize(de).map_err(|e| ResultsError::Json {
                file: path.display().to_string(),
                path: e.path().to_string(),
                reason: e.into_inner().to_string(),
            })?;
        results
            .check_values()
            .and_then(|()| results.check_unique_rows())
            .map_err(|(at, reason)| ResultsError::Json {
                file: path.display().to_string(),
                path: at,
                reason,
            })?;
        Ok(results)
    }

    /// Refuses a configuration id with more than one row, a failure listed twice or beside a
    /// row, or an id listed as missing twice or beside a row or failure (no run writes any of
    /// these; reports would count it twice and `merge` would take the file for two
    /// overlapping shards). Returns the JSON path of the first such entry and the reason
    /// naming the id and where it first appeared.
    pub fn check_unique_rows(&self) -> Result<(), (String, String)> {
        let mut first = std::collections::HashMap::with_capacity(self.rows.len());
        for (i, r) in self.rows.iter().enumerate() {
            if let Some(j) = first.insert(r.config_id.as_str(), i) {
                return Err((
                    format!("rows[{i}].config_id"),
                    format!(
                        "configuration {} has more than one row (also rows[{j}]): each configuration has one row",
                        r.config_id
                    ),
                ));
            }
        }
        let mut failed = std::collections::HashMap::with_capacity(self.failures.len());
        for (i, f) in self.failures.iter().enumerate() {
            let id = &f.config_id;
            if let Some(&j) = first.get(id.as_str()) {
                return Err((
                    format!("failures[{i}].config_id"),
                    format!("configuration {id} is listed as failed but has a row (rows[{j}])"),
                ));
            }
            if let Some(j) = failed.insert(id.as_str(), i) {
                return Err((
                    format!("failures[{i}].config_id"),
                    format!("configuration {id} is listed as failed twice (also failures[{j}])"),
                ));
            }
        }
        let mut listed = std::collections::HashMap::with_capacity(self.missing.len());
        for (i, id) in self.missing.iter().enumerate() {
            if let Some(&j) = first.get(id.as_str()) {
                return Err((
                    format!("missing[{i}]"),
                    format!("configuration {id} is listed as missing but has a row (rows[{j}])"),
                ));
            }
            if let Some(&j) = failed.get(id.as_str()) {
                return Err((
                    format!("missing[{i}]"),
                    format!("configuration {id} is listed as missing but failed (failures[{j}])"),
                ));
            }
            if let Some(j) = listed.insert(id.as_str(), i) {
                return Err((
                    format!("missing[{i}]"),
                    format!("configuration {id} is listed as missing twice (also missing[{j}])"),
                ));
            }
        }
        Ok(())
    }

    /// A copy whose free text (names, ids, options, notes, errors, provenance, anchors) is
    /// escaped for Markdown ([`crate::report::md_escape`]), timings re-keyed to the escaped
    /// ids: what `summary.md` and the findings are written from, so a name cannot add a
    /// table column, a heading or HTML. Plain names are unchanged.
    pub fn markdown_safe(&self) -> Results {
        use crate::report::md_escape;
        let esc = |s: &mut String| *s = md_escape(s);
        let mut r = self.clone();
        for x in [
            &mut r.run_id,
            &mut r.suite,
            &mut r.suite_file,
            &mut r.description,
        ] {
            esc(x);
        }
        let p = &mut r.provenance;
        for x in [
            &mut p.date_utc,
            &mut p.cpu_model,
            &mut p.rustc,
            &mut p.target,
            &mut p.profile,
            &mut p.git_commit,
            &mut p.version,
            &mut p.command,
            &mut p.machine,
        ] {
            esc(x);
        }
        for row in &mut r.rows {
            row.map_text_cells(esc);
        }
        for f in &mut r.failures {
            esc(&mut f.config_id);
            esc(&mut f.error);
        }
        for x in r
            .skipped
            .iter_mut()
            .chain(r.missing.iter_mut())
            .chain(r.write_errors.iter_mut())
        {
            esc(x);
        }
        for x in &mut r.references {
            esc(&mut x.scene);
            if let Some(e) = &mut x.error {
                esc(e);
            }
        }
        r.timings = std::mem::take(&mut r.timings)
            .into_iter()
            .map(|(k, v)| (md_escape(&k), v))
            .collect();
        r.steps_histograms = std::mem::take(&mut r.steps_histograms)
            .into_iter()
            .map(|(k, v)| (md_escape(&k), v))
            .collect();
        for a in &mut r.anchors {
            for x in [
                &mut a.tool,
                &mut a.version,
                &mut a.backend,
                &mut a.file,
                &mut a.date_utc,
                &mut a.load_average_start,
                &mut a.load_average_end,
            ] {
                esc(x);
            }
            for e in &mut a.entries {
                esc(&mut e.subject);
                esc(&mut e.rays);
                esc(&mut e.query);
                esc(&mut e.tracer);
                esc(&mut e.peer);
                esc(&mut e.unit);
            }
        }
        r
    }

    /// Whether the run did not finish: interrupted, killed (its last checkpoint says
    /// interrupted) or with configurations missing.
    pub fn is_incomplete(&self) -> bool {
        self.interrupted || !self.missing.is_empty()
    }

    /// Refuses numbers no measurement produces, which would otherwise make reports hang on a
    /// plot axis of 300 decades or print `NaNx`: every float must be finite with a magnitude of
    /// at most [`MAX_RESULT_VALUE`], and times (ms) must not be negative. Returns the JSON
    /// path (naming the row's configuration id) and the reason.
    pub fn check_values(&self) -> Result<(), (String, String)> {
        let bad =
            |x: f64, time: bool| !x.is_finite() || x.abs() > MAX_RESULT_VALUE || (time && x < 0.0);
        let reason = |what: &str, x: f64| {
            format!(
                "{what} = {} is not a measurement (finite, at most {MAX_RESULT_VALUE:e} in magnitude, times not negative)",
                short_number(x)
            )
        };
        for (i, r) in self.rows.iter().enumerate() {
            let at = |field: &str| format!("rows[{i}] ({}).{field}", r.config_id);
            let value = serde_json::to_value(r).map_err(|e| (at(""), e.to_string()))?;
            if let serde_json::Value::Object(map) = value {
                for (k, v) in &map {
                    if let Some(x) = v.as_f64() {
                        let time = k.contains("_ms");
                        if bad(x, time) {
                            return Err((at(k), reason(k, x)));
                        }
                    }
                }
            }
        }
        for (id, samples) in &self.timings {
            for (j, t) in samples.iter().enumerate() {
                for (name, x) in [("wall_ms", Some(t.wall_ms)), ("cpu_ms", t.cpu_ms)] {
                    if let Some(x) = x.filter(|&x| bad(x, true)) {
                        return Err((format!("timings.{id}[{j}].{name}"), reason(name, x)));
                    }
                }
            }
        }
        for (i, r) in self.references.iter().enumerate() {
            for (name, x) in [("build_ms", r.build_ms), ("render_ms", r.render_ms)] {
                if let Some(x) = x.filter(|&x| bad(x, true)) {
                    return Err((format!("references[{i}].{name}"), reason(name, x)));
                }
            }
        }
        // Anchor rates and ratios are positive like the anchor files they were read from
        // (a 300-digit rate would be printed in full in every table).
        for (i, a) in self.anchors.iter().enumerate() {
            for (j, e) in a.entries.iter().enumerate() {
                let values = [("ours", e.ours), ("anchor", e.anchor), ("ratio", e.ratio)];
                let cost = e.ours_ns_per_step.map(|x| ("ours_ns_per_step", x));
                for (name, x) in values.into_iter().chain(cost) {
                    if bad(x, true) || x <= 0.0 {
                        return Err((
                            format!("anchors[{i}].entries[{j}].{name}"),
                            format!(
                                "{name} = {} is not a rate or ratio (finite, positive, at most {MAX_RESULT_VALUE:e})",
                                short_number(x)
                            ),
                        ));
                    }
                }
            }
        }
        for (id, bins) in &self.steps_histograms {
            let at = format!("steps_histograms.{id}");
            if bins.len() > MAX_HISTOGRAM_BINS {
                return Err((
                    at,
                    format!(
                        "{} bins, more than the {MAX_HISTOGRAM_BINS} log2 bins of a step count",
                        bins.len()
                    ),
                ));
            }
            let total: u128 = bins.iter().map(|&n| u128::from(n)).sum();
            if total as f64 > MAX_RESULT_VALUE {
                return Err((
                    at,
                    format!(
                        "{total} rays in all is not a measurement (at most {MAX_RESULT_VALUE:e})"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Writes the rows as `results.csv` (header = [`Row`] field names).
    pub fn write_csv(&self, path: &Path) -> Result<(), ResultsError> {
        let err = |e: csv::Error| ResultsError::Csv {
            file: path.display().to_string(),
            reason: e.to_string(),
        };
        let mut w = csv::Writer::from_writer(Vec::new());
        if self.rows.is_empty() {
            w.write_record(csv_header()).map_err(err)?;
        }
        for r in &self.rows {
            let mut r = r.clone();
            r.map_text_cells(|cell| {
                if cell.starts_with(CSV_FORMULA_STARTS) {
                    cell.insert(0, '\'');
                }
            });
            w.serialize(&r).map_err(err)?;
        }
        let bytes = w.into_inner().map_err(|e| ResultsError::Csv {
            file: path.display().to_string(),
            reason: e.to_string(),
        })?;
        // Atomic, like results.json: a failed write leaves the previous file, never half of it.
        marchmesh_safeio::replace_regular(path, &bytes).map_err(|e| ResultsError::Write {
            file: path.display().to_string(),
            reason: e.to_string(),
        })
    }
}

/// The CSV column names, in order.
pub fn csv_header() -> Vec<String> {
    // Serialize an example row into a CSV header through the same path as the data.
    row_csv_lines(&Row::default()).0
}

/// `row` serialized as CSV the way [`Results::write_csv`] writes it (without the formula
/// escaping): its header's cells and its data line's cells. The cells of a line are split on
/// commas, so only rows whose text cells hold no comma split correctly (the default and
/// accuracy-only rows these helpers serialize do).
fn row_csv_lines(row: &Row) -> (Vec<String>, Vec<String>) {
    let mut w = csv::Writer::from_writer(Vec::new());
    let _ = w.serialize(row);
    let bytes = w.into_inner().unwrap_or_default();
    let text = String::from_utf8_lossy(&bytes);
    let mut lines = text
        .lines()
        .map(|l| l.split(',').map(str::to_string).collect::<Vec<_>>());
    let header = lines.next().unwrap_or_default();
    (header, lines.next().unwrap_or_default())
}

/// First characters that make a spreadsheet read a cell as a formula (`=`, `+`, `-`, `@`,
/// tab, carriage return): [`Results::write_csv`] writes such text cells with a leading `'`,
/// which [`read_csv`] removes again.
pub const CSV_FORMULA_STARTS: [char; 6] = ['=', '+', '-', '@', '\t', '\r'];

impl Row {
    /// Applies `f` to every text cell (ids, names, options, notes).
    fn map_text_cells(&mut self, mut f: impl FnMut(&mut String)) {
        for cell in [
            &mut self.config_id,
            &mut self.group,
            &mut self.scene,
            &mut self.scene_file,
            &mut self.backend,
            &mut self.quality,
            &mut self.options,
            &mut self.machine,
            &mut self.build_phases_ms,
            &mut self.notes,
        ] {
            f(cell);
        }
    }
}

/// Reads the rows of a `results.csv` back (a regular file within the read cap; text cells
/// neutralised by [`Results::write_csv`] come back as they were).
pub fn read_csv(path: &Path) -> Result<Vec<Row>, ResultsError> {
    let err = |e: csv::Error| ResultsError::Csv {
        file: path.display().to_string(),
        reason: e.to_string(),
    };
    let bytes = marchmesh_safeio::read_regular(path)?;
    let mut r = csv::Reader::from_reader(&bytes[..]);
    r.deserialize::<Row>()
        .map(|row| {
            let mut row = row.map_err(err)?;
            row.map_text_cells(|cell| {
                if cell.starts_with('\'') && cell[1..].starts_with(CSV_FORMULA_STARTS) {
                    cell.remove(0);
                }
            });
            Ok(row)
        })
        .collect()
}

/// Date `days` after 1970-01-01 as (year, month, day) (Howard Hinnant's civil_from_days).
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

/// UTC time `secs` after the epoch as (`YYYY-MM-DDTHH:MM:SSZ`, `YYYYMMDDTHHMMSSZ`).
pub fn utc_strings(secs: u64) -> (String, String) {
    let (y, mo, d) = civil_from_days((secs / 86_400) as i64);
    let s = secs % 86_400;
    let (h, mi, se) = (s / 3600, s % 3600 / 60, s % 60);
    (
        format!("{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{se:02}Z"),
        format!("{y:04}{mo:02}{d:02}T{h:02}{mi:02}{se:02}Z"),
    )
}

/// Seconds since the epoch now.
pub fn now_secs() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

fn git(args: &[&str]) -> Option<String> {
    let out = std::process::Command::new("git").args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// Why shard runs cannot be merged.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MergeError {
    /// Nothing to merge.
    #[error("merge needs at least one run")]
    Empty,
    /// Two inputs ran different suites.
    #[error(
        "{first} ran suite {first_suite:?} but {other} ran {other_suite:?}: only shards of one suite merge"
    )]
    SuiteMismatch {
        /// First input.
        first: String,
        /// Its suite.
        first_suite: String,
        /// The mismatching input.
        other: String,
        /// Its suite.
        other_suite: String,
    },
    /// Two inputs were built from different commits (or one from a dirty tree).
    #[error(
        "{first} was measured at commit {first_commit} but {other} at {other_commit}: only runs of one commit merge (rebuild the shards from the same commit)"
    )]
    CommitMismatch {
        /// First input.
        first: String,
        /// Its commit (`+dirty` when the work tree had changes).
        first_commit: String,
        /// The mismatching input.
        other: String,
        /// Its commit.
        other_commit: String,
    },
    /// A configuration was measured, failed or listed as missing in two inputs.
    #[error("configuration {config_id} is in both {first} and {other}: shards must not overlap")]
    Overlap {
        /// The configuration.
        config_id: String,
        /// One input.
        first: String,
        /// The other.
        other: String,
    },
}

impl Results {
    /// Combines shard runs (`(name, results)`, name used in errors) into one run called
    /// `run_id`: rows, failures, references, histograms and timings concatenated; each row
    /// keeps its machine in [`Row::machine`] and each input's provenance is listed in
    /// [`Results::merged_from`]; the merged provenance is the first input's with `command`.
    ///
    /// Errors: no input, inputs of different suites or commits (a dirty tree counts as a
    /// different commit), or a configuration present in two inputs (as a row, a failure or
    /// missing: the merged file would list it twice, which no reader accepts).
    pub fn merge(
        inputs: Vec<(String, Results)>,
        run_id: String,
        command: String,
    ) -> Result<Results, MergeError> {
        let commit = |r: &Results| {
            format!(
                "{}{}",
                r.provenance.git_commit,
                if r.provenance.git_dirty { "+dirty" } else { "" }
            )
        };
        let Some((first_name, first)) = inputs.first() else {
            return Err(MergeError::Empty);
        };
        for (name, r) in &inputs[1..] {
            if r.suite != first.suite {
                return Err(MergeError::SuiteMismatch {
                    first: first_name.clone(),
                    first_suite: first.suite.clone(),
                    other: name.clone(),
                    other_suite: r.suite.clone(),
                });
            }
            if commit(r) != commit(first) {
                return Err(MergeError::CommitMismatch {
                    first: first_name.clone(),
                    first_commit: commit(first),
                    other: name.clone(),
                    other_commit: commit(r),
                });
            }
        }
        let mut owner: BTreeMap<String, String> = BTreeMap::new();
        for (name, r) in &inputs {
            let ids = r
                .rows
                .iter()
                .map(|x| &x.config_id)
                .chain(r.failures.iter().map(|f| &f.config_id))
                .chain(r.missing.iter());
            for id in ids {
                if let Some(prev) = owner.insert(id.clone(), name.clone()) {
                    return Err(MergeError::Overlap {
                        config_id: id.clone(),
                        first: prev,
                        other: name.clone(),
                    });
                }
            }
        }
        let mut out = Results {
            run_id,
            suite: first.suite.clone(),
            suite_file: first.suite_file.clone(),
            description: first.description.clone(),
            provenance: Provenance {
                command,
                ..first.provenance.clone()
            },
            interrupted: false,
            rows: Vec::new(),
            failures: Vec::new(),
            skipped: Vec::new(),
            references: Vec::new(),
            steps_histograms: BTreeMap::new(),
            timings: BTreeMap::new(),
            rotation_seed: first.rotation_seed,
            missing: Vec::new(),
            shard: None,
            merged_from: Vec::new(),
            write_errors: Vec::new(),
            anchors: Vec::new(),
        };
        // Anchors seen so far, by content: a set, so thousands of them merge in linear time.
        let mut seen_anchors = std::collections::HashSet::new();
        let mut seen_skipped = std::collections::HashSet::new();
        for (_, r) in inputs {
            out.merged_from.push(MergedShard {
                run_id: r.run_id.clone(),
                shard: r.shard.clone(),
                provenance: r.provenance.clone(),
                rows: r.rows.len(),
            });
            out.interrupted |= r.interrupted;
            let machine = r.provenance.machine.clone();
            out.rows.extend(r.rows.into_iter().map(|mut x| {
                if x.machine.is_empty() {
                    x.machine = machine.clone();
                }
                x
            }));
            out.failures.extend(r.failures);
            for s in r.skipped {
                if seen_skipped.insert(s.clone()) {
                    out.skipped.push(s);
                }
            }
            out.references.extend(r.references);
            out.steps_histograms.extend(r.steps_histograms);
            out.timings.extend(r.timings);
            out.missing.extend(r.missing);
            out.write_errors.extend(r.write_errors);
            for a in r.anchors {
                if seen_anchors.insert(crate::anchors::identity(&a)) {
                    out.anchors.push(a);
                }
            }
        }
        Ok(out)
    }
}

/// The 1-minute load average (`/proc/loadavg`), `None` where unavailable.
pub fn load_average_1m() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|t| t.split_whitespace().next()?.parse().ok())
}

/// This machine's host name, `unknown` if it cannot be found.
pub fn hostname() -> String {
    std::fs::read_to_string("/etc/hostname")
        .ok()
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .or_else(|| std::env::var("HOSTNAME").ok())
        .unwrap_or_else(|| "unknown".into())
}

impl Provenance {
    /// Collects provenance now; `command` is the command line.
    pub fn collect(command: String) -> Self {
        let cpu_model = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|t| {
                t.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.trim().to_string())
            })
            .unwrap_or_else(|| "unknown".into());
        let commit = git(&["rev-parse", "HEAD"]);
        let dirty = commit.is_some()
            && git(&["status", "--porcelain", "--untracked-files=no"])
                .is_some_and(|s| !s.is_empty());
        Self {
            date_utc: utc_strings(now_secs()).0,
            cpu_model,
            logical_cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            rustc: env!("MARCHMESH_RUSTC_VERSION").to_string(),
            target: env!("MARCHMESH_TARGET").to_string(),
            profile: if cfg!(debug_assertions) {
                "debug"
            } else {
                "release"
            }
            .to_string(),
            git_commit: commit.unwrap_or_else(|| "unknown".into()),
            git_dirty: dirty,
            version: env!("CARGO_PKG_VERSION").to_string(),
            command,
            load_average_1m: load_average_1m(),
            load_average_1m_end: None,
            machine: hostname(),
        }
    }
}

/// Rows for tests of the report.
#[cfg(test)]
pub(crate) mod tests_support {
    use super::*;

    /// A row of `backend:quality` with a median time, PSNR and memory; the rest zero.
    pub fn row(backend: &str, quality: &str, ms: f64, psnr: Option<f64>, memory: u64) -> Row {
        Row {
            config_id: format!("g/s/{backend}:{quality}/x1/t1"),
            group: "g".into(),
            scene: "s".into(),
            backend: backend.into(),
            quality: quality.into(),
            render_ms_median: ms,
            render_ms_ci_low: ms,
            render_ms_ci_high: ms,
            psnr_db: psnr,
            memory_bytes: memory,
            ..Row::default()
        }
    }

    /// A quiet-machine run holding `rows`.
    pub fn results(rows: Vec<Row>) -> Results {
        let mut provenance = Provenance::collect(String::new());
        provenance.load_average_1m = Some(0.0);
        provenance.load_average_1m_end = Some(0.0);
        Results {
            run_id: "run".into(),
            suite: "suite".into(),
            suite_file: String::new(),
            description: String::new(),
            provenance,
            interrupted: false,
            rows,
            failures: vec![],
            skipped: vec![],
            references: vec![],
            steps_histograms: BTreeMap::new(),
            timings: BTreeMap::new(),
            rotation_seed: None,
            missing: vec![],
            shard: None,
            merged_from: vec![],
            write_errors: vec![],
            anchors: vec![],
        }
    }
}

#[cfg(test)]
mod tests;
