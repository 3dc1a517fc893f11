//! Suite files: which scenes, backends, quality levels, resolutions and thread counts a
//! benchmark run measures. The format is documented in `scenes/suites/README.md`.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use marchmesh_scene::RenderOverrides;

use crate::backend::{self, BackendId, BackendSpec};
use crate::stats::RepeatPolicy;

/// A suite file as written (paths still relative to the file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SuiteFile {
    /// Suite name (default: the file stem).
    #[serde(default)]
    pub name: Option<String>,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// Timed repeats after the warm-up (default: 3 repeats and 1 s, at most 50).
    #[serde(default)]
    pub repeats: RepeatPolicy,
    /// Repeats under `--quick` (default: one repeat).
    #[serde(default)]
    pub quick_repeats: Option<RepeatPolicy>,
    /// Write each configuration's PNG and difference heatmap into `images/` (default true).
    #[serde(default = "yes")]
    pub images: bool,
    /// Groups of configurations (each a cross product).
    pub groups: Vec<Group>,
}

fn yes() -> bool {
    true
}

/// A cross product: scenes x resolutions x backends x threads.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Group {
    /// Group name, the first part of every configuration id.
    pub name: String,
    /// Scene files or globs (`*`, `?` in the file name), relative to the suite file.
    pub scenes: Vec<SceneEntry>,
    /// Image sizes (default: the scene's own).
    #[serde(default = "default_resolutions")]
    pub resolutions: Vec<Resolution>,
    /// Samples per pixel override (default: the scene's own).
    #[serde(default)]
    pub spp: Option<u32>,
    /// Render settings of the reference render every configuration is measured against
    /// (default: the scene's own), e.g. `{"area_light_samples": 1024}` so noisy lighting is
    /// compared with a converged truth.
    #[serde(default)]
    pub truth: RenderOverrides,
    /// Render thread counts (0 = one per logical core). Default `[0]`.
    #[serde(default = "default_threads")]
    pub threads: Vec<usize>,
    /// Backend configurations.
    pub backends: Vec<BackendEntry>,
    /// Measure accuracy against the reference backend (default true).
    #[serde(default = "yes")]
    pub reference: bool,
    /// Repeat policy override for this group.
    #[serde(default)]
    pub repeats: Option<RepeatPolicy>,
}

fn default_resolutions() -> Vec<Resolution> {
    vec![Resolution::Scale { scale: 1.0 }]
}

fn default_threads() -> Vec<usize> {
    vec![0]
}

/// A scene file, a glob, or either with options.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum SceneEntry {
    /// A path or glob relative to the suite file.
    Path(String),
    /// A path or glob with a display name and an optional flag.
    Detailed {
        /// Path or glob relative to the suite file.
        path: String,
        /// Display name (default: file stem). Only for single files.
        #[serde(default)]
        name: Option<String>,
        /// Skip with a message (instead of failing) when the file or a mesh it uses is
        /// absent (e.g. the full dragon, fetched by `scripts/fetch_dragon.sh`).
        #[serde(default)]
        optional: bool,
    },
}

/// An image size.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Resolution {
    /// Exact size in pixels.
    Size {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// The longer side in pixels, the scene's aspect ratio kept.
    MaxSide {
        /// Longer side in pixels.
        max_side: u32,
    },
    /// The scene's size times `scale` (at least 1 pixel per side).
    Scale {
        /// Factor applied to both sides.
        scale: f64,
    },
}

impl Resolution {
    /// The pixel size for a scene whose own size is `w` x `h`.
    pub fn apply(self, w: u32, h: u32) -> (u32, u32) {
        let scaled = |f: f64| {
            (
                ((w as f64 * f).round() as u32).max(1),
                ((h as f64 * f).round() as u32).max(1),
            )
        };
        match self {
            Resolution::Size { width, height } => (width, height),
            Resolution::MaxSide { max_side } => scaled(max_side as f64 / w.max(h).max(1) as f64),
            Resolution::Scale { scale } => scaled(scale),
        }
    }
}

/// One backend configuration of a group.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BackendEntry {
    /// `sdf`, `mesh` or `reference`.
    pub backend: String,
    /// Quality label in reports (default: the options joined, or `default`).
    #[serde(default)]
    pub label: Option<String>,
    /// `key=value` options, applied in order (see `marchmesh render --opt help`).
    #[serde(default)]
    pub options: Vec<String>,
    /// Render settings of this configuration (default: the scene's own), e.g.
    /// `{"area_light_samples": 16}`: a quality level of the light transport.
    #[serde(default)]
    pub render: RenderOverrides,
}

/// One resolved backend configuration of a group.
#[derive(Debug, Clone, PartialEq)]
pub struct BackendConfig {
    /// Quality label.
    pub label: String,
    /// Backend and options.
    pub spec: BackendSpec,
    /// Render settings replacing the scene's.
    pub render: RenderOverrides,
}

/// A validated suite: scene paths resolved, backends parsed.
#[derive(Debug, Clone, PartialEq)]
pub struct Suite {
    /// Suite name.
    pub name: String,
    /// The file it came from.
    pub path: PathBuf,
    /// Description.
    pub description: String,
    /// Repeats.
    pub repeats: RepeatPolicy,
    /// Repeats under `--quick`.
    pub quick_repeats: RepeatPolicy,
    /// Whether to write images.
    pub images: bool,
    /// Groups with resolved scenes.
    pub groups: Vec<ResolvedGroup>,
    /// Scenes skipped (optional and absent), with the reason.
    pub skipped: Vec<String>,
}

/// A group with its scenes found and backends checked.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedGroup {
    /// Group name.
    pub name: String,
    /// (display name, path) of each scene.
    pub scenes: Vec<(String, PathBuf)>,
    /// Resolutions.
    pub resolutions: Vec<Resolution>,
    /// Samples per pixel override.
    pub spp: Option<u32>,
    /// Render settings of the reference render.
    pub truth: RenderOverrides,
    /// Thread counts.
    pub threads: Vec<usize>,
    /// The backend configurations.
    pub backends: Vec<BackendConfig>,
    /// Accuracy against the reference.
    pub reference: bool,
    /// Repeat override.
    pub repeats: Option<RepeatPolicy>,
}

/// Why a suite file is unusable. Every variant names the file; parse and validation errors
/// name the JSON path too.
#[derive(Debug, thiserror::Error)]
pub enum SuiteError {
    /// The file cannot be read.
    #[error("{file}: {source}")]
    Io {
        /// The suite file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a regular file within the read cap.
    #[error(transparent)]
    Read(#[from] marchmesh_safeio::SafeIoError),
    /// The JSON does not match the format.
    #[error("{file}: at {path}: {reason}")]
    Format {
        /// The suite file.
        file: PathBuf,
        /// JSON path of the offending value.
        path: String,
        /// What is wrong.
        reason: String,
    },
}

/// Largest suite file [`load`] reads: 16 MiB (the shipped suites are a few KiB).
pub const MAX_SUITE_FILE_BYTES: u64 = 16 << 20;

/// Most configurations a suite may expand to (scenes x resolutions x backends x threads over
/// all groups): 100,000, a month of benchmarking at the shipped suites' pace. A suite over it
/// is refused at load, before anything is expanded.
pub const MAX_CONFIGURATIONS: u64 = 100_000;

/// Most timed repeats a repeat policy may ask for (`max_count`, and so `min_count`):
/// 1,000,000 per configuration. Every repeat's time is kept in results.json, and a policy of
/// billions would run (and grow) for ever.
pub const MAX_REPEATS: u32 = 1_000_000;

/// Longest `min_time_s` a repeat policy may ask for: an hour of repeats per configuration.
pub const MAX_REPEAT_SECONDS: f64 = 3600.0;

/// The JSON paths of values the suite format reads as objects that are arrays instead
/// (serde would read an array as the object's fields in order): the top level, each group,
/// its backends, resolutions, scene entries, repeat policies and render settings.
fn arrays_for_objects(v: &serde_json::Value) -> Option<String> {
    use serde_json::Value;
    let is_array = |v: Option<&Value>| matches!(v, Some(Value::Array(_)));
    let Value::Object(top) = v else {
        return Some(".".into());
    };
    for key in ["repeats", "quick_repeats"] {
        if is_array(top.get(key)) {
            return Some(key.into());
        }
    }
    let Some(Value::Array(groups)) = top.get("groups") else {
        return None;
    };
    for (gi, g) in groups.iter().enumerate() {
        let Value::Object(g) = g else {
            return Some(format!("groups[{gi}]"));
        };
        for key in ["repeats", "truth"] {
            if is_array(g.get(key)) {
                return Some(format!("groups[{gi}].{key}"));
            }
        }
        for list in ["backends", "resolutions"] {
            if let Some(Value::Array(items)) = g.get(list) {
                for (i, item) in items.iter().enumerate() {
                    if !item.is_object() {
                        return Some(format!("groups[{gi}].{list}[{i}]"));
                    }
                    if is_array(item.get("render")) {
                        return Some(format!("groups[{gi}].{list}[{i}].render"));
                    }
                }
            }
        }
        if let Some(Value::Array(items)) = g.get("scenes") {
            for (i, item) in items.iter().enumerate() {
                if item.is_array() {
                    return Some(format!("groups[{gi}].scenes[{i}]"));
                }
            }
        }
    }
    None
}

/// Refuses what would make two configurations, plots or images share a name: a scene name
/// standing for two files, two backends of a group with one `backend:label`, and distinct
/// ids, plot names or reference image names whose file-name forms
/// ([`crate::bench::slug`]) are equal (labels `q a` and `q_a`). Returns the JSON path and
/// the reason.
fn check_unique_names(groups: &[ResolvedGroup]) -> Result<(), (String, String)> {
    use crate::bench::slug;
    use std::collections::HashMap;
    let mut scene_files: HashMap<&str, &Path> = HashMap::new();
    let mut scene_slugs: HashMap<String, &str> = HashMap::new();
    let mut plot_slugs: HashMap<String, (&str, &str)> = HashMap::new();
    let mut id_slugs: HashMap<String, String> = HashMap::new();
    for (gi, g) in groups.iter().enumerate() {
        let gp = format!("groups[{gi}]");
        for (name, path) in &g.scenes {
            if let Some(other) = scene_files.insert(name, path)
                && other != path
            {
                return Err((
                    format!("{gp}.scenes"),
                    format!(
                        "the scene name `{name}` stands for both {} and {}: give one a distinct `name`",
                        other.display(),
                        path.display()
                    ),
                ));
            }
            if let Some(other) = scene_slugs.insert(slug(name), name)
                && other != name
            {
                return Err((
                    format!("{gp}.scenes"),
                    format!(
                        "the scene names `{other}` and `{name}` share the image file name `{}`: rename one",
                        slug(name)
                    ),
                ));
            }
            if let Some(&(og, os)) = plot_slugs.get(&format!("{}_{}", slug(&g.name), slug(name)))
                && (og, os) != (g.name.as_str(), name.as_str())
            {
                return Err((
                    format!("{gp}.scenes"),
                    format!(
                        "`{og}/{os}` and `{}/{name}` share a plot file name: rename a group or scene",
                        g.name
                    ),
                ));
            }
            plot_slugs.insert(format!("{}_{}", slug(&g.name), slug(name)), (&g.name, name));
        }
        let mut labels: HashMap<String, usize> = HashMap::new();
        for (bi, b) in g.backends.iter().enumerate() {
            let id = format!("{}:{}", b.spec.kind.name(), b.label);
            if let Some(first) = labels.insert(id.clone(), bi) {
                return Err((
                    format!("{gp}.backends[{bi}].label"),
                    format!("`{id}` is also backends[{first}]: give each a distinct `label`"),
                ));
            }
        }
        for (name, _) in &g.scenes {
            for b in &g.backends {
                // Thread counts are numbers and resolution tags are made of safe characters:
                // the ids without them decide whether two file names collide.
                let id = format!("{}/{name}/{}:{}", g.name, b.spec.kind.name(), b.label);
                if let Some(other) = id_slugs.insert(slug(&id), id.clone())
                    && other != id
                {
                    return Err((
                        format!("{gp}.backends"),
                        format!(
                            "configurations `{other}` and `{id}` share the image file name `{}`: rename a label, scene or group",
                            slug(&id)
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The label of a backend entry: its own, else its options joined with `,`, else `default`.
pub fn default_label(options: &[String]) -> String {
    if options.is_empty() {
        "default".into()
    } else {
        options.join(",")
    }
}

/// Matches `text` against a glob with `*` (any run, also across `/`) and `?` (one char).
pub fn glob_match(pattern: &str, text: &str) -> bool {
    let (p, t): (Vec<char>, Vec<char>) = (pattern.chars().collect(), text.chars().collect());
    let (mut pi, mut ti) = (0, 0);
    let mut star: Option<(usize, usize)> = None;
    while ti < t.len() {
        if pi < p.len() && (p[pi] == '?' || p[pi] == t[ti]) {
            pi += 1;
            ti += 1;
        } else if pi < p.len() && p[pi] == '*' {
            star = Some((pi, ti));
            pi += 1;
        } else if let Some((sp, st)) = star {
            pi = sp + 1;
            ti = st + 1;
            star = Some((sp, st + 1));
        } else {
            return false;
        }
    }
    p[pi..].iter().all(|&c| c == '*')
}

fn expand_glob(base: &Path, pattern: &str) -> std::io::Result<Vec<PathBuf>> {
    let full = base.join(pattern);
    let name = full
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    if !name.contains(['*', '?']) {
        return Ok(vec![full]);
    }
    let dir = full.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir)? {
        let p = e?.path();
        let n = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if p.is_file() && glob_match(&name, &n) {
            out.push(p);
        }
    }
    out.sort();
    Ok(out)
}

/// Parses suite text; `file` names it in errors and `base` resolves its relative paths.
pub fn parse(text: &str, file: &Path) -> Result<Suite, SuiteError> {
    let fmt_err = |path: String, reason: String| SuiteError::Format {
        file: file.to_path_buf(),
        path,
        reason,
    };
    if let Ok(value) = serde_json::from_str::<serde_json::Value>(text)
        && let Some(at) = arrays_for_objects(&value)
    {
        return Err(fmt_err(at, "expected a JSON object, found an array".into()));
    }
    let de = &mut serde_json::Deserializer::from_str(text);
    let raw: SuiteFile = serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        fmt_err(path, e.into_inner().to_string())
    })?;
    let base = file.parent().unwrap_or(Path::new("."));
    let name = raw.name.clone().unwrap_or_else(|| {
        file.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "suite".into())
    });
    let check_policy = |p: &RepeatPolicy, path: String| {
        if p.min_count == 0
            || p.max_count < p.min_count
            || p.max_count > MAX_REPEATS
            || !(0.0..=MAX_REPEAT_SECONDS).contains(&p.min_time_s)
        {
            return Err(fmt_err(
                path,
                format!(
                    "need 1 <= min_count <= max_count <= {MAX_REPEATS} and 0 <= min_time_s <= {MAX_REPEAT_SECONDS}, got min_count {}, max_count {}, min_time_s {}",
                    p.min_count, p.max_count, p.min_time_s
                ),
            ));
        }
        Ok(())
    };
    check_policy(&raw.repeats, "repeats".into())?;
    if let Some(q) = &raw.quick_repeats {
        check_policy(q, "quick_repeats".into())?;
    }
    if raw.groups.is_empty() {
        return Err(fmt_err("groups".into(), "no groups".into()));
    }
    let mut groups = Vec::new();
    let mut skipped = Vec::new();
    for (gi, g) in raw.groups.iter().enumerate() {
        let gp = format!("groups[{gi}]");
        if g.name.is_empty() || g.name.contains(['/', '\\']) {
            return Err(fmt_err(
                format!("{gp}.name"),
                "group names must be non-empty without slashes".into(),
            ));
        }
        if let Some(p) = &g.repeats {
            check_policy(p, format!("{gp}.repeats"))?;
        }
        let mut scenes = Vec::new();
        for (si, s) in g.scenes.iter().enumerate() {
            let sp = format!("{gp}.scenes[{si}]");
            let (pattern, name, optional) = match s {
                SceneEntry::Path(p) => (p.as_str(), None, false),
                SceneEntry::Detailed {
                    path,
                    name,
                    optional,
                } => (path.as_str(), name.clone(), *optional),
            };
            let found = expand_glob(base, pattern)
                .map_err(|e| fmt_err(sp.clone(), format!("cannot list `{pattern}`: {e}")))?;
            if found.is_empty() {
                return Err(fmt_err(sp, format!("`{pattern}` matches no file")));
            }
            if name.is_some() && found.len() > 1 {
                return Err(fmt_err(
                    sp,
                    format!("a name is given but `{pattern}` matches several files"),
                ));
            }
            for path in found {
                let stem = path
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let display = name.clone().unwrap_or(stem);
                if !path.is_file() {
                    if path.is_dir() {
                        return Err(fmt_err(
                            sp.clone(),
                            format!("{} is a folder, not a scene file", path.display()),
                        ));
                    }
                    if path.exists() {
                        return Err(fmt_err(
                            sp.clone(),
                            format!(
                                "{} is not a regular file (a device, FIFO or socket)",
                                path.display()
                            ),
                        ));
                    }
                    if optional {
                        skipped.push(format!(
                            "{}/{display}: {} is absent (optional scene; skipped)",
                            g.name,
                            path.display()
                        ));
                        continue;
                    }
                    return Err(fmt_err(
                        sp.clone(),
                        format!("scene file {} does not exist", path.display()),
                    ));
                }
                if optional
                    && let Ok(bytes) = marchmesh_safeio::read_regular(&path)
                    && let Some(missing) = missing_mesh(&String::from_utf8_lossy(&bytes), &path)
                {
                    skipped.push(format!(
                        "{}/{display}: mesh {} is absent (optional scene; skipped; scripts/fetch_dragon.sh fetches the full dragon)",
                        g.name,
                        missing.display()
                    ));
                    continue;
                }
                scenes.push((display, path));
            }
        }
        if g.resolutions.is_empty() || g.threads.is_empty() || g.backends.is_empty() {
            return Err(fmt_err(
                gp,
                "resolutions, threads and backends must not be empty".into(),
            ));
        }
        if let Some((ti, t)) = g
            .threads
            .iter()
            .enumerate()
            .find(|(_, t)| **t > marchmesh_core::MAX_THREADS)
        {
            return Err(fmt_err(
                format!("{gp}.threads[{ti}]"),
                format!(
                    "{t} threads is over the limit of {} (0 = all cores)",
                    marchmesh_core::MAX_THREADS
                ),
            ));
        }
        for (ri, r) in g.resolutions.iter().enumerate() {
            let ok = match *r {
                Resolution::Size { width, height } => width > 0 && height > 0,
                Resolution::MaxSide { max_side } => max_side > 0,
                Resolution::Scale { scale } => scale > 0.0 && scale.is_finite(),
            };
            if !ok {
                return Err(fmt_err(
                    format!("{gp}.resolutions[{ri}]"),
                    "sizes must be > 0".into(),
                ));
            }
        }
        // The upper bound depends on the scene's integrator: checked when each scene loads.
        if g.spp == Some(0) {
            return Err(fmt_err(format!("{gp}.spp"), "must be >= 1".into()));
        }
        let mut backends = Vec::new();
        for (bi, b) in g.backends.iter().enumerate() {
            let bp = format!("{gp}.backends[{bi}]");
            let kind: BackendId = b.backend.parse().map_err(|e: backend::BackendError| {
                fmt_err(format!("{bp}.backend"), e.to_string())
            })?;
            let mut options = Vec::new();
            for (oi, o) in b.options.iter().enumerate() {
                options.push(
                    backend::parse_option(o)
                        .map_err(|e| fmt_err(format!("{bp}.options[{oi}]"), e))?,
                );
            }
            let spec = BackendSpec { kind, options };
            backend::check_options(&spec)
                .map_err(|e| fmt_err(format!("{bp}.options"), e.to_string()))?;
            let label = b.label.clone().unwrap_or_else(|| default_label(&b.options));
            if label.contains('/') {
                return Err(fmt_err(
                    format!("{bp}.label"),
                    "labels must not contain `/`".into(),
                ));
            }
            backends.push(BackendConfig {
                label,
                spec,
                render: b.render.clone(),
            });
        }
        groups.push(ResolvedGroup {
            name: g.name.clone(),
            scenes,
            resolutions: g.resolutions.clone(),
            spp: g.spp,
            truth: g.truth.clone(),
            threads: g.threads.clone(),
            backends,
            reference: g.reference,
            repeats: g.repeats,
        });
    }
    let mut total: u64 = 0;
    for (gi, g) in groups.iter().enumerate() {
        let n = [
            g.scenes.len(),
            g.resolutions.len(),
            g.backends.len(),
            g.threads.len(),
        ]
        .iter()
        .try_fold(1u64, |acc, &k| acc.checked_mul(k as u64));
        total = n.and_then(|n| total.checked_add(n)).unwrap_or(u64::MAX);
        if total > MAX_CONFIGURATIONS {
            return Err(fmt_err(
                format!("groups[{gi}]"),
                format!(
                    "the suite expands to more than {MAX_CONFIGURATIONS} configurations (scenes x resolutions x backends x threads); split it"
                ),
            ));
        }
    }
    check_unique_names(&groups).map_err(|(at, reason)| fmt_err(at, reason))?;
    Ok(Suite {
        name,
        path: file.to_path_buf(),
        description: raw.description,
        repeats: raw.repeats,
        quick_repeats: raw.quick_repeats.unwrap_or_else(|| raw.repeats.quick()),
        images: raw.images,
        groups,
        skipped,
    })
}

/// The first mesh file a scene text refers to that does not exist (lexical scan of
/// `"path"` values under `"mesh"` objects; the scene loader reports anything subtler).
fn missing_mesh(text: &str, scene_path: &Path) -> Option<PathBuf> {
    let v: serde_json::Value = serde_json::from_str(text).ok()?;
    let base = scene_path.parent().unwrap_or(Path::new("."));
    fn walk(v: &serde_json::Value, base: &Path) -> Option<PathBuf> {
        match v {
            serde_json::Value::Object(m) => {
                if let Some(serde_json::Value::Object(mesh)) = m.get("mesh")
                    && let Some(serde_json::Value::String(p)) = mesh.get("path")
                {
                    let full = base.join(p);
                    if !full.is_file() {
                        return Some(full);
                    }
                }
                m.values().find_map(|c| walk(c, base))
            }
            serde_json::Value::Array(a) => a.iter().find_map(|c| walk(c, base)),
            _ => None,
        }
    }
    walk(&v, base)
}

/// Loads and validates a suite file: a regular file within the `MARCHMESH_MAX_READ_MIB` read
/// cap (a FIFO or device is refused without blocking), at most [`MAX_SUITE_FILE_BYTES`].
pub fn load(path: &Path) -> Result<Suite, SuiteError> {
    let bytes = marchmesh_safeio::read_regular_within(path, MAX_SUITE_FILE_BYTES)?;
    let text = String::from_utf8(bytes).map_err(|e| SuiteError::Format {
        file: path.to_path_buf(),
        path: ".".into(),
        reason: format!("not UTF-8 text: {e}"),
    })?;
    parse(&text, path)
}

/// Finds a suite by name (`scenes/suites/NAME.json` under the folder `root` returns, called
/// only for a name) or takes it as a path (it has an extension or a folder part).
///
/// Errors: those of `root`.
pub fn locate<E>(
    name_or_path: &str,
    root: impl FnOnce() -> Result<PathBuf, E>,
) -> Result<PathBuf, E> {
    let p = PathBuf::from(name_or_path);
    if p.extension().is_some() || p.components().count() > 1 {
        Ok(p)
    } else {
        Ok(root()?
            .join("scenes/suites")
            .join(format!("{name_or_path}.json")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn globs() {
        assert!(glob_match("*.json", "a.json"));
        assert!(!glob_match("*.json", "a.jsonx"));
        assert!(glob_match("smoke/*/sdf:*", "smoke/primitives/sdf:eps_px=1"));
        assert!(glob_match("a?c", "abc"));
        assert!(!glob_match("a?c", "ac"));
        assert!(glob_match("*", ""));
        assert!(glob_match("*mesh*", "default/csg/mesh:bvh2/500x300/t2"));
    }

    fn write_tmp(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("marchmesh-suite-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("scene.json"), r#"{"objects": []}"#).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn errors_name_file_and_json_path() {
        let p = write_tmp(
            "bad1.json",
            r#"{"groups": [{"name": "g", "scenes": ["scene.json"], "backends": [{"backend": "sdf", "options": ["eps=1"]}]}]}"#,
        );
        let e = load(&p).unwrap_err().to_string();
        assert!(
            e.contains("bad1.json") && e.contains("groups[0].backends[0].options"),
            "{e}"
        );
        assert!(e.contains("eps_px"), "lists valid keys: {e}");
        let p = write_tmp(
            "bad2.json",
            r#"{"groups": [{"name": "g", "scenes": ["scene.json"], "threads": ["x"], "backends": []}]}"#,
        );
        let e = load(&p).unwrap_err().to_string();
        assert!(
            e.contains("bad2.json") && e.contains("groups[0].threads[0]"),
            "{e}"
        );
        let p = write_tmp(
            "bad3.json",
            r#"{"groups": [{"name": "g", "scenes": ["nope*.json"], "backends": [{"backend": "mesh"}]}]}"#,
        );
        let e = load(&p).unwrap_err().to_string();
        assert!(
            e.contains("groups[0].scenes[0]") && e.contains("matches no file"),
            "{e}"
        );
        let p = write_tmp("bad4.json", r#"{"groups": [], "colour": 1}"#);
        let e = load(&p).unwrap_err().to_string();
        assert!(e.contains("colour"), "{e}");
    }

    #[test]
    fn optional_absent_scenes_are_skipped_with_a_message() {
        let p = write_tmp(
            "opt.json",
            r#"{"groups": [{"name": "g", "scenes": ["scene.json", {"path": "absent.json", "optional": true}],
                 "resolutions": [{"max_side": 32}, {"width": 8, "height": 4}],
                 "backends": [{"backend": "mesh", "options": ["bvh=bvh2"]}, {"backend": "sdf", "label": "q"}]}]}"#,
        );
        let s = load(&p).unwrap();
        assert_eq!(s.name, "opt");
        assert_eq!(s.groups[0].scenes.len(), 1);
        assert_eq!(s.skipped.len(), 1);
        assert!(s.skipped[0].contains("absent.json"));
        assert_eq!(s.groups[0].backends[0].label, "bvh=bvh2");
        assert_eq!(s.groups[0].backends[1].label, "q");
        assert_eq!(s.groups[0].resolutions[0].apply(500, 400), (32, 26));
        assert_eq!(s.groups[0].resolutions[1].apply(500, 400), (8, 4));
    }

    #[test]
    fn render_overrides_and_truth_are_read_and_unknown_keys_named() {
        let p = write_tmp(
            "light.json",
            r#"{"groups": [{"name": "g", "scenes": ["scene.json"],
                 "truth": {"area_light_samples": 1024},
                 "backends": [{"backend": "mesh", "label": "r4", "render": {"area_light_samples": 4}}]}]}"#,
        );
        let s = load(&p).unwrap();
        assert_eq!(s.groups[0].truth.area_light_samples, Some(1024));
        assert_eq!(s.groups[0].backends[0].render.area_light_samples, Some(4));
        let p = write_tmp(
            "badlight.json",
            r#"{"groups": [{"name": "g", "scenes": ["scene.json"],
                 "backends": [{"backend": "mesh", "render": {"shadow_rays": 4}}]}]}"#,
        );
        let e = load(&p).unwrap_err().to_string();
        assert!(
            e.contains("groups[0].backends[0].render") && e.contains("shadow_rays"),
            "{e}"
        );
    }
}
