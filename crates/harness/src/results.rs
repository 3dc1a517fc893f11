//! What a run produces: one [`Row`] per configuration (the CSV columns, units in the names),
//! plus provenance, failures and per-configuration step histograms in `results.json`.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

/// One measured configuration. Field order is the CSV column order. `Option` fields are
/// empty in the CSV (null in JSON) only where they do not apply; see [`Row::why_empty`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
    /// Camera rays per render.
    pub rays_primary: u64,
    /// Shadow, ambient-occlusion, reflection and bounce rays per render.
    pub rays_secondary: u64,
    /// (primary + secondary) rays / median render time, millions per second.
    pub mrays_per_s: f64,
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
    /// Why `column` may be empty in this row, `None` if it must be filled.
    pub fn why_empty(&self, column: &str) -> Option<&'static str> {
        match column {
            "triangles" if self.backend != "mesh" => Some("not a triangle backend"),
            "peak_heap_bytes_build" | "peak_heap_bytes_render" => {
                Some("counting allocator not installed in this binary")
            }
            "peak_rss_bytes_build" | "peak_rss_bytes_render" => {
                Some("peak RSS reset not available on this system")
            }
            c if ACCURACY_COLUMNS.contains(&c) && !self.notes.is_empty() => {
                Some("no reference (see notes)")
            }
            "notes" => Some("no remarks"),
            "mrays_shadow_per_thread_s"
            | "mrays_ao_per_thread_s"
            | "mrays_bounce_per_thread_s"
            | "mrays_camera_per_thread_s" => Some("no rays of this type were traced"),
            _ => None,
        }
    }
}

/// Columns filled from the comparison with the reference.
pub const ACCURACY_COLUMNS: &[&str] = &[
    "silhouette_mismatch_pct",
    "depth_err_mean",
    "depth_err_p95",
    "depth_err_max",
    "depth_err_p95_rel_scene",
    "depth_err_max_rel_scene",
    "scene_size_world",
    "normal_err_deg_mean",
    "normal_err_deg_p95",
    "depth_err_rel_max",
    "depth_err_rel_tail_px",
    "normal_err_deg_max",
    "normal_err_deg_tail_px",
    "psnr_db",
    "ssim",
];

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
}

/// Why results could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ResultsError {
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
    /// CSV writing or reading.
    #[error("{file}: {reason}")]
    Csv {
        /// The file.
        file: String,
        /// The error.
        reason: String,
    },
}

fn io_err(p: &Path) -> impl Fn(std::io::Error) -> ResultsError + '_ {
    move |source| ResultsError::Io {
        file: p.display().to_string(),
        source,
    }
}

impl Results {
    /// Writes `results.json` (pretty) to `path`.
    pub fn write_json(&self, path: &Path) -> Result<(), ResultsError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| ResultsError::Json {
            file: path.display().to_string(),
            path: String::new(),
            reason: e.to_string(),
        })?;
        std::fs::write(path, text + "\n").map_err(io_err(path))
    }

    /// Reads a `results.json`; errors name the file and the JSON path.
    pub fn read_json(path: &Path) -> Result<Self, ResultsError> {
        let text = std::fs::read_to_string(path).map_err(io_err(path))?;
        let de = &mut serde_json::Deserializer::from_str(&text);
        serde_path_to_error::deserialize(de).map_err(|e| ResultsError::Json {
            file: path.display().to_string(),
            path: e.path().to_string(),
            reason: e.into_inner().to_string(),
        })
    }

    /// Writes the rows as `results.csv` (header = [`Row`] field names).
    pub fn write_csv(&self, path: &Path) -> Result<(), ResultsError> {
        let err = |e: csv::Error| ResultsError::Csv {
            file: path.display().to_string(),
            reason: e.to_string(),
        };
        let mut w = csv::Writer::from_path(path).map_err(err)?;
        if self.rows.is_empty() {
            w.write_record(csv_header()).map_err(err)?;
        }
        for r in &self.rows {
            w.serialize(r).map_err(err)?;
        }
        w.flush().map_err(io_err(path))
    }
}

/// The CSV column names, in order.
pub fn csv_header() -> Vec<String> {
    // Serialize an example row into a CSV header through the same path as the data.
    let mut w = csv::Writer::from_writer(Vec::new());
    let _ = w.serialize(example_row());
    let bytes = w.into_inner().unwrap_or_default();
    let text = String::from_utf8_lossy(&bytes);
    text.lines()
        .next()
        .unwrap_or("")
        .split(',')
        .map(str::to_string)
        .collect()
}

fn example_row() -> Row {
    Row {
        config_id: String::new(),
        group: String::new(),
        scene: String::new(),
        scene_file: String::new(),
        backend: String::new(),
        quality: String::new(),
        options: String::new(),
        width: 0,
        height: 0,
        spp: 0,
        threads: 0,
        build_ms_total: 0.0,
        build_phases_ms: String::new(),
        render_repeats: 0,
        render_ms_median: 0.0,
        render_ms_min: 0.0,
        render_ms_max: 0.0,
        render_ms_mad: 0.0,
        render_ms_ci_low: 0.0,
        render_ms_ci_high: 0.0,
        render_ci_coverage: 0.0,
        rays_primary: 0,
        rays_secondary: 0,
        mrays_per_s: 0.0,
        mrays_camera_per_thread_s: None,
        mrays_shadow_per_thread_s: None,
        mrays_ao_per_thread_s: None,
        mrays_bounce_per_thread_s: None,
        memory_bytes: 0,
        triangles: None,
        peak_heap_bytes_build: None,
        peak_heap_bytes_render: None,
        peak_rss_bytes_build: None,
        peak_rss_bytes_render: None,
        silhouette_mismatch_pct: None,
        depth_err_mean: None,
        depth_err_p95: None,
        depth_err_max: None,
        depth_err_p95_rel_scene: None,
        depth_err_max_rel_scene: None,
        scene_size_world: None,
        normal_err_deg_mean: None,
        normal_err_deg_p95: None,
        depth_err_rel_max: None,
        depth_err_rel_tail_px: None,
        normal_err_deg_max: None,
        normal_err_deg_tail_px: None,
        psnr_db: None,
        ssim: None,
        steps_mean: 0.0,
        steps_max: 0,
        step_exhaustion_pct: 0.0,
        node_visits_per_ray: 0.0,
        node_visits_max: 0,
        non_finite_count: 0,
        notes: String::new(),
    }
}

/// Reads the rows of a `results.csv` back.
pub fn read_csv(path: &Path) -> Result<Vec<Row>, ResultsError> {
    let err = |e: csv::Error| ResultsError::Csv {
        file: path.display().to_string(),
        reason: e.to_string(),
    };
    let mut r = csv::Reader::from_path(path).map_err(err)?;
    r.deserialize().map(|row| row.map_err(err)).collect()
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
            load_average_1m: std::fs::read_to_string("/proc/loadavg")
                .ok()
                .and_then(|t| t.split_whitespace().next()?.parse().ok()),
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
            psnr_db: psnr,
            memory_bytes: memory,
            ..example_row()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates() {
        assert_eq!(utc_strings(0).0, "1970-01-01T00:00:00Z");
        assert_eq!(utc_strings(951_782_400).0, "2000-02-29T00:00:00Z");
        assert_eq!(utc_strings(1_700_000_000).1, "20231114T221320Z");
    }

    #[test]
    fn header_has_units_and_every_field() {
        let h = csv_header();
        assert_eq!(h.len(), 56);
        for c in [
            "render_ms_median",
            "peak_heap_bytes_render",
            "depth_err_p95",
            "mrays_per_s",
        ] {
            assert!(h.iter().any(|x| x == c), "{c}");
        }
    }
}
