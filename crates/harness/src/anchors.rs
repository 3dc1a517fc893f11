//! External anchors: each backend measured against the best known implementations of its
//! representation on the same rays, by the scripts outside the default build
//! (`scripts/anchor.sh` runs them all; `scripts/anchor_embree.sh`: the mesh backend against
//! Embree 4 on camera and incoherent rays; `scripts/anchor_tinybvh.sh`: the mesh backend
//! against tinybvh and Embree in the same rounds; `scripts/anchor_fidget.sh`: the sdf backend
//! against fidget). Their JSON files are read here into one [`Anchor`] form, which a run
//! records (`marchmesh bench --anchor`) and the findings show, so a verdict between the
//! backends stands beside how far each is from its field's best. See `docs/anchors.md`.

use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;

use marchmesh_core::Backend;
use marchmesh_mesh::MeshBackend;
use marchmesh_sdf::SdfBackend;
use serde::{Deserialize, Serialize};

/// Largest anchor file read (an anchor run writes a few hundred KB at most).
pub const MAX_ANCHOR_FILE_BYTES: u64 = 16 << 20;

/// Largest rate, ratio or cost accepted from an anchor file (the bound the results file
/// applies to every figure): a larger one is a broken file, not a measurement.
pub const MAX_ANCHOR_VALUE: f64 = crate::results::MAX_RESULT_VALUE;

/// Largest ray, hit or triangle count accepted from an anchor file (2^40): the anchors trace
/// at most a few million rays.
pub const MAX_ANCHOR_COUNT: u64 = 1 << 40;

/// One anchor run, normalised from any anchor script's JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Anchor {
    /// `embree`, `tinybvh` or `fidget`.
    pub tool: String,
    /// The anchor's version as its script reported it.
    pub version: String,
    /// The marchmesh backend measured against it (`mesh` or `sdf`).
    pub backend: String,
    /// The file it was read from, as given.
    pub file: String,
    /// When the anchor ran (UTC).
    pub date_utc: String,
    /// Load averages (1, 5, 15 minutes) when it started and ended: the figures are ratios
    /// of interleaved rounds, but a busy machine widens their spread.
    pub load_average_start: String,
    /// See `load_average_start`.
    pub load_average_end: String,
    /// One row per mesh or scene, ray kind, marchmesh tracer and peer.
    pub entries: Vec<AnchorEntry>,
}

fn camera() -> String {
    "camera".into()
}

fn closest_hit() -> String {
    "closest hit".into()
}

/// marchmesh against one of the anchor's calls on one mesh or scene and one kind of ray.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnchorEntry {
    /// The mesh file or scene whose rays both traced (with its triangle count or depth
    /// resolution in parentheses when the file gives it).
    pub subject: String,
    /// The kind of ray: `camera` (coherent), or the incoherent `ao` (ambient-occlusion rays),
    /// `bounce` (diffuse bounce rays) and `shadow` (area-light shadow rays). Records made
    /// before incoherent rays were anchored hold camera rays only, hence the default.
    #[serde(default = "camera")]
    pub rays: String,
    /// `closest hit` or `occlusion` (any hit within the ray's extent).
    #[serde(default = "closest_hit")]
    pub query: String,
    /// marchmesh's tracer (`wide1`: single rays, `wide4x2`: 8-ray packets on 4x2 tiles,
    /// `wide`: incoherent batches, `sdf`: the sdf backend).
    pub tracer: String,
    /// The anchor's side compared with: one call (`embree1`: `rtcIntersect1`/`rtcOccluded1`,
    /// `embree8`: the 8-wide calls, `tinybvh-LAYOUT`), or per round the best of several
    /// (`fastest tinybvh`, `faster single-ray peer`: Embree's single-ray call or tinybvh,
    /// `fastest peer`: every call of both). Empty: the anchor's only call (records made
    /// before anchors had several).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub peer: String,
    /// Unit of both rates (`Mrays/s` or `Mpix/s`), 1 thread.
    pub unit: String,
    /// marchmesh's rate (median over rounds).
    pub ours: f64,
    /// The peer's rate (median over rounds; for a best-of peer, the best of their medians).
    pub anchor: f64,
    /// marchmesh / peer: the median of per-round ratios (above 1: marchmesh is faster).
    pub ratio: f64,
    /// The sdf backend only: its time per ray-step in nanoseconds, the anchor's render time
    /// over its pixels times their mean marching steps (one field evaluation of one ray,
    /// with the marching and hit work around it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ours_ns_per_step: Option<f64>,
}

/// Why an anchor file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum AnchorError {
    /// Reading failed (missing, not a regular file, over [`MAX_ANCHOR_FILE_BYTES`]).
    #[error("{file}: {reason}")]
    Read {
        /// The file.
        file: String,
        /// The I/O error.
        reason: String,
    },
    /// Not JSON of any anchor's form, or inconsistent within itself.
    #[error("{file}: at {path}: {reason}")]
    Json {
        /// The file.
        file: String,
        /// Where in the document.
        path: String,
        /// What was wrong.
        reason: String,
    },
    /// A rate, ratio or cost is not a finite positive number of at most [`MAX_ANCHOR_VALUE`].
    #[error(
        "{file}: {entry}: {field} is {shown}, not a finite positive number of at most {max:e}",
        shown = short_number(*value),
        max = MAX_ANCHOR_VALUE
    )]
    Value {
        /// The file.
        file: String,
        /// Which entry: its mesh or scene, kind of ray, tracer and peer.
        entry: String,
        /// The field.
        field: &'static str,
        /// The value read.
        value: f64,
    },
}

/// `scripts/anchor_embree.py --json`.
#[derive(Deserialize)]
struct EmbreeFile {
    embree_version: String,
    date_utc: String,
    load_average_start: String,
    load_average_end: String,
    meshes: Vec<EmbreeMesh>,
}

#[derive(Deserialize)]
struct EmbreeMesh {
    mesh: String,
    #[serde(default)]
    triangles: Option<u64>,
    embree: EmbreeRate,
    tracers: BTreeMap<String, EmbreeTracer>,
    /// Since incoherent rays were anchored.
    #[serde(default)]
    incoherent: Option<EmbreeIncoherent>,
}

#[derive(Deserialize)]
struct EmbreeRate {
    mrays_per_s_median: f64,
}

#[derive(Deserialize)]
struct EmbreeTracer {
    mrays_per_s_median: f64,
    ratio_over_embree_per_round_median: f64,
}

#[derive(Deserialize)]
struct EmbreeIncoherent {
    kinds: BTreeMap<String, EmbreeKind>,
}

#[derive(Deserialize)]
struct EmbreeKind {
    query: String,
    rays: u64,
    embree: EmbreeCall,
    tracers: BTreeMap<String, EmbreeKindTracer>,
}

#[derive(Deserialize)]
struct EmbreeCall {
    mrays_per_s_median: f64,
    hits: u64,
}

#[derive(Deserialize)]
struct EmbreeKindTracer {
    mrays_per_s_median: f64,
    ratio_over_embree_per_round_median: f64,
    hits: u64,
    #[serde(default)]
    disagreements: Option<u64>,
}

/// `scripts/anchor_tinybvh.py --json`.
#[derive(Deserialize)]
struct TinybvhFile {
    tinybvh_version: String,
    embree_version: String,
    date_utc: String,
    load_average_start: String,
    load_average_end: String,
    meshes: Vec<TinybvhMesh>,
}

#[derive(Deserialize)]
struct TinybvhMesh {
    mesh: String,
    triangles: u64,
    kinds: BTreeMap<String, TinybvhKind>,
}

#[derive(Deserialize)]
struct TinybvhKind {
    query: String,
    rays: u64,
    sides: BTreeMap<String, TinybvhSide>,
    marchmesh: BTreeMap<String, TinybvhOurs>,
}

#[derive(Deserialize)]
struct TinybvhSide {
    mrays_per_s_median: f64,
    hits: u64,
    #[serde(default)]
    disagreements: Option<u64>,
}

#[derive(Deserialize)]
struct TinybvhOurs {
    over: BTreeMap<String, f64>,
    /// Not in the first files.
    #[serde(default)]
    over_fastest_tinybvh: Option<f64>,
    over_faster_single_ray_peer: f64,
    over_fastest_peer: f64,
}

/// `crates/anchor-fidget --json`.
#[derive(Deserialize)]
struct FidgetFile {
    fidget_version: String,
    date_utc: String,
    load_average_start: String,
    load_average_end: String,
    scenes: Vec<FidgetScene>,
}

#[derive(Deserialize)]
struct FidgetScene {
    scene: String,
    fidget_depth_voxels: u32,
    #[serde(default)]
    width: Option<u64>,
    #[serde(default)]
    height: Option<u64>,
    fidget: FidgetRate,
    sdf: FidgetRate,
    ratio_sdf_over_fidget_per_round_median: f64,
    #[serde(default)]
    sdf_mean_steps_per_ray: Option<f64>,
}

#[derive(Deserialize)]
struct FidgetRate {
    mpix_per_s_median: f64,
    #[serde(default)]
    median_s: Option<f64>,
}

/// The `tool` field every form starts with.
#[derive(Deserialize)]
struct Tool {
    tool: String,
}

fn parse<T: serde::de::DeserializeOwned>(file: &str, text: &str) -> Result<T, AnchorError> {
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let mut reason = inner.to_string();
        // A syntax error's path stops at the enclosing list: quote the text before it, which
        // names the field, and say why NaN or Infinity (Python's json writes them) is refused.
        if inner.is_syntax() && inner.line() > 0 {
            let line = text.lines().nth(inner.line() - 1).unwrap_or("");
            let at = line
                .char_indices()
                .nth(inner.column().saturating_sub(1))
                .map_or(line.len(), |(i, _)| i);
            let before: String = {
                let head = &line[..at];
                let skip = head.chars().count().saturating_sub(60);
                head.chars().skip(skip).collect()
            };
            let rest = &line[at..];
            let _ = write!(reason, ", after `{}`", before.trim_start());
            if ["NaN", "Infinity", "-Infinity"]
                .iter()
                .any(|w| rest.starts_with(w) || before.ends_with(&w[..1]))
            {
                reason.push_str(
                    ": NaN and Infinity are not JSON numbers (the anchor measured no finite value)",
                );
            }
        }
        AnchorError::Json {
            file: file.to_string(),
            path,
            reason,
        }
    })
}

/// A number as an error shows it: in full when short, else in scientific notation.
fn short_number(x: f64) -> String {
    if x == 0.0 || (1e-4..1e6).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// The order ray kinds are listed in: camera (coherent) first.
fn kind_rank(kind: &str) -> (u8, &str) {
    let rank = match kind {
        "camera" => 0,
        "ao" => 1,
        "bounce" => 2,
        "shadow" => 3,
        _ => 4,
    };
    (rank, kind)
}

/// `closest hit` or `occlusion`, as the scripts write them.
fn check_query(file: &str, path: String, query: &str) -> Result<String, AnchorError> {
    match query {
        "closest hit" | "occlusion" => Ok(query.to_string()),
        other => Err(AnchorError::Json {
            file: file.to_string(),
            path,
            reason: format!("{other:?} is not a query (\"closest hit\" or \"occlusion\")"),
        }),
    }
}

/// A count is at most [`MAX_ANCHOR_COUNT`] and at most `rays` (a hit or disagreement count).
fn check_count(file: &str, path: String, n: u64, rays: Option<u64>) -> Result<(), AnchorError> {
    let reason = if n > MAX_ANCHOR_COUNT {
        format!("{n} is more than the {MAX_ANCHOR_COUNT} rays an anchor can trace")
    } else if let Some(r) = rays.filter(|&r| n > r) {
        format!("{n} is more than the kind's {r} rays")
    } else {
        return Ok(());
    };
    Err(AnchorError::Json {
        file: file.to_string(),
        path,
        reason,
    })
}

fn mesh_subject(mesh: &str, triangles: Option<u64>) -> String {
    match triangles {
        Some(n) => format!("{mesh} ({n} triangles)"),
        None => mesh.to_string(),
    }
}

fn embree_entries(file: &str, f: &EmbreeFile) -> Result<Vec<AnchorEntry>, AnchorError> {
    let mut entries = Vec::new();
    for (i, m) in f.meshes.iter().enumerate() {
        if let Some(n) = m.triangles {
            check_count(file, format!("meshes[{i}].triangles"), n, None)?;
        }
        let subject = mesh_subject(&m.mesh, m.triangles);
        for (name, t) in &m.tracers {
            entries.push(AnchorEntry {
                subject: subject.clone(),
                rays: camera(),
                query: closest_hit(),
                tracer: name.clone(),
                peer: "embree1".into(),
                unit: "Mrays/s".into(),
                ours: t.mrays_per_s_median,
                anchor: m.embree.mrays_per_s_median,
                ratio: t.ratio_over_embree_per_round_median,
                ours_ns_per_step: None,
            });
        }
        let Some(inc) = &m.incoherent else { continue };
        let mut kinds: Vec<_> = inc.kinds.iter().collect();
        kinds.sort_by(|a, b| kind_rank(a.0).cmp(&kind_rank(b.0)));
        for (kind, k) in kinds {
            let at = format!("meshes[{i}].incoherent.kinds.{kind}");
            let query = check_query(file, format!("{at}.query"), &k.query)?;
            check_count(file, format!("{at}.rays"), k.rays, None)?;
            check_count(
                file,
                format!("{at}.embree.hits"),
                k.embree.hits,
                Some(k.rays),
            )?;
            for (name, t) in &k.tracers {
                let tat = format!("{at}.tracers.{name}");
                check_count(file, format!("{tat}.hits"), t.hits, Some(k.rays))?;
                if let Some(d) = t.disagreements {
                    check_count(file, format!("{tat}.disagreements"), d, Some(k.rays))?;
                }
                entries.push(AnchorEntry {
                    subject: subject.clone(),
                    rays: kind.clone(),
                    query: query.clone(),
                    tracer: name.clone(),
                    peer: "embree1".into(),
                    unit: "Mrays/s".into(),
                    ours: t.mrays_per_s_median,
                    anchor: k.embree.mrays_per_s_median,
                    ratio: t.ratio_over_embree_per_round_median,
                    ours_ns_per_step: None,
                });
            }
        }
    }
    Ok(entries)
}

/// The best-of peers of a tinybvh file, and which sides each takes the best of.
fn best_of(peer: &str, side: &str) -> bool {
    match peer {
        "fastest tinybvh" => side.starts_with("tinybvh-"),
        "faster single-ray peer" => side == "embree1" || side.starts_with("tinybvh-"),
        _ => true,
    }
}

fn tinybvh_entries(file: &str, f: &TinybvhFile) -> Result<Vec<AnchorEntry>, AnchorError> {
    let mut entries = Vec::new();
    for (i, m) in f.meshes.iter().enumerate() {
        check_count(file, format!("meshes[{i}].triangles"), m.triangles, None)?;
        let subject = mesh_subject(&m.mesh, Some(m.triangles));
        let mut kinds: Vec<_> = m.kinds.iter().collect();
        kinds.sort_by(|a, b| kind_rank(a.0).cmp(&kind_rank(b.0)));
        for (kind, k) in kinds {
            let at = format!("meshes[{i}].kinds.{kind}");
            let query = check_query(file, format!("{at}.query"), &k.query)?;
            check_count(file, format!("{at}.rays"), k.rays, None)?;
            for (name, side) in &k.sides {
                let sat = format!("{at}.sides.{name}");
                check_count(file, format!("{sat}.hits"), side.hits, Some(k.rays))?;
                if let Some(d) = side.disagreements {
                    check_count(file, format!("{sat}.disagreements"), d, Some(k.rays))?;
                }
            }
            let rate = |side: &str, path: String| {
                k.sides
                    .get(side)
                    .map(|s| s.mrays_per_s_median)
                    .ok_or_else(|| AnchorError::Json {
                        file: file.to_string(),
                        path,
                        reason: format!("names side {side:?}, which {at}.sides does not have"),
                    })
            };
            if k.marchmesh.is_empty() {
                return Err(AnchorError::Json {
                    file: file.to_string(),
                    path: format!("{at}.marchmesh"),
                    reason: "no marchmesh tracer was timed".into(),
                });
            }
            let peers: Vec<&String> = k
                .sides
                .keys()
                .filter(|s| !k.marchmesh.contains_key(*s))
                .collect();
            for (tracer, o) in &k.marchmesh {
                let oat = format!("{at}.marchmesh.{tracer}");
                let ours = rate(tracer, oat.clone())?;
                let mut push = |peer: &str, anchor: f64, ratio: f64| {
                    entries.push(AnchorEntry {
                        subject: subject.clone(),
                        rays: kind.clone(),
                        query: query.clone(),
                        tracer: tracer.clone(),
                        peer: peer.to_string(),
                        unit: "Mrays/s".into(),
                        ours,
                        anchor,
                        ratio,
                        ours_ns_per_step: None,
                    });
                };
                for (peer, &ratio) in &o.over {
                    push(peer, rate(peer, format!("{oat}.over.{peer}"))?, ratio);
                }
                for (peer, ratio) in [
                    ("fastest tinybvh", o.over_fastest_tinybvh),
                    (
                        "faster single-ray peer",
                        Some(o.over_faster_single_ray_peer),
                    ),
                    ("fastest peer", Some(o.over_fastest_peer)),
                ] {
                    let Some(ratio) = ratio else { continue };
                    let best = peers
                        .iter()
                        .filter(|s| best_of(peer, s))
                        .map(|s| k.sides[*s].mrays_per_s_median)
                        .fold(None, |b: Option<f64>, r| Some(b.map_or(r, |b| b.max(r))));
                    let Some(best) = best else {
                        return Err(AnchorError::Json {
                            file: file.to_string(),
                            path: format!("{at}.sides"),
                            reason: format!("no side to take the {peer} from"),
                        });
                    };
                    push(peer, best, ratio);
                }
            }
        }
    }
    Ok(entries)
}

fn fidget_entries(file: &str, f: &FidgetFile) -> Result<Vec<AnchorEntry>, AnchorError> {
    let mut entries = Vec::new();
    for (i, s) in f.scenes.iter().enumerate() {
        for (field, n) in [("width", s.width), ("height", s.height)] {
            if let Some(n) = n {
                check_count(file, format!("scenes[{i}].{field}"), n, None)?;
            }
        }
        // Time per ray-step: the render's median time over its pixels' marching steps.
        let ns_per_step = match (s.width, s.height, s.sdf.median_s, s.sdf_mean_steps_per_ray) {
            (Some(w), Some(h), Some(t), Some(steps)) => {
                Some(t * 1e9 / (w as f64 * h as f64 * steps))
            }
            _ => None,
        };
        entries.push(AnchorEntry {
            subject: format!("{} ({} voxels)", s.scene, s.fidget_depth_voxels),
            rays: camera(),
            query: closest_hit(),
            tracer: SdfBackend::NAME.into(),
            peer: String::new(),
            unit: "Mpix/s".into(),
            ours: s.sdf.mpix_per_s_median,
            anchor: s.fidget.mpix_per_s_median,
            ratio: s.ratio_sdf_over_fidget_per_round_median,
            ours_ns_per_step: ns_per_step,
        });
    }
    Ok(entries)
}

/// Reads an anchor file written by `scripts/anchor_embree.py --json` (`"tool":
/// "anchor-embree"`: camera rays, and since incoherent rays were anchored their AO, bounce
/// and shadow rays), by `scripts/anchor_tinybvh.py --json` (`"tool": "anchor-tinybvh"`:
/// every ray kind against Embree's and tinybvh's calls) or by `crates/anchor-fidget --json`
/// (`"tool": "anchor-fidget"`).
///
/// Errors name the file and the place in it: a file that cannot be read, that is not JSON
/// of one of those forms (truncated, another tool, a field missing or of the wrong type), a
/// query that is neither closest hit nor occlusion, a count over [`MAX_ANCHOR_COUNT`] or a
/// hit count over its rays, a side named but not timed, and a rate, ratio or cost that is
/// not finite, positive and at most [`MAX_ANCHOR_VALUE`].
pub fn read_anchor(path: &Path) -> Result<Anchor, AnchorError> {
    let file = path.display().to_string();
    let bytes =
        marchmesh_safeio::read_regular_within(path, MAX_ANCHOR_FILE_BYTES).map_err(|e| {
            AnchorError::Read {
                file: file.clone(),
                reason: e.to_string(),
            }
        })?;
    let text = String::from_utf8_lossy(&bytes);
    let anchor = match parse::<Tool>(&file, &text)?.tool.as_str() {
        "anchor-embree" => {
            let f: EmbreeFile = parse(&file, &text)?;
            Anchor {
                tool: "embree".into(),
                entries: embree_entries(&file, &f)?,
                version: f.embree_version,
                backend: MeshBackend::NAME.into(),
                file,
                date_utc: f.date_utc,
                load_average_start: f.load_average_start,
                load_average_end: f.load_average_end,
            }
        }
        "anchor-tinybvh" => {
            let f: TinybvhFile = parse(&file, &text)?;
            Anchor {
                tool: "tinybvh".into(),
                entries: tinybvh_entries(&file, &f)?,
                version: format!("{} and {}", f.tinybvh_version, f.embree_version),
                backend: MeshBackend::NAME.into(),
                file,
                date_utc: f.date_utc,
                load_average_start: f.load_average_start,
                load_average_end: f.load_average_end,
            }
        }
        "anchor-fidget" => {
            let f: FidgetFile = parse(&file, &text)?;
            Anchor {
                tool: "fidget".into(),
                entries: fidget_entries(&file, &f)?,
                version: format!("fidget {}", f.fidget_version),
                backend: SdfBackend::NAME.into(),
                file,
                date_utc: f.date_utc,
                load_average_start: f.load_average_start,
                load_average_end: f.load_average_end,
            }
        }
        other => {
            return Err(AnchorError::Json {
                file,
                path: "tool".into(),
                reason: format!(
                    "{other:?} is not an anchor this version reads (anchor-embree, anchor-tinybvh, anchor-fidget)"
                ),
            });
        }
    };
    for e in &anchor.entries {
        let values = [("ours", e.ours), ("anchor", e.anchor), ("ratio", e.ratio)];
        let cost = e.ours_ns_per_step.map(|v| ("ours_ns_per_step", v));
        for (field, value) in values.into_iter().chain(cost) {
            if !(value.is_finite() && value > 0.0 && value <= MAX_ANCHOR_VALUE) {
                return Err(AnchorError::Value {
                    file: anchor.file.clone(),
                    entry: format!(
                        "{} ({} rays, {} over {})",
                        e.subject,
                        e.rays,
                        e.tracer,
                        peer_name(&anchor, e)
                    ),
                    field,
                    value,
                });
            }
        }
    }
    Ok(anchor)
}

/// The entry's peer, or the anchor's tool when the entry names none.
fn peer_name<'a>(a: &'a Anchor, e: &'a AnchorEntry) -> &'a str {
    if e.peer.is_empty() { &a.tool } else { &e.peer }
}

/// What makes two anchors the same (every field, the numbers by their bits), as a key for a
/// set: runs of one session share their anchors, and merging or summarising thousands of them
/// must not compare each with every other.
pub fn identity(a: &Anchor) -> String {
    let mut key = format!(
        "{:?}\0{:?}\0{:?}\0{:?}\0{:?}\0{:?}\0{:?}",
        a.tool, a.version, a.backend, a.file, a.date_utc, a.load_average_start, a.load_average_end
    );
    for e in &a.entries {
        let _ = write!(
            key,
            "\0{:?}\0{:?}\0{:?}\0{:?}\0{:?}\0{:?}\0{:x}\0{:x}\0{:x}\0{:?}",
            e.subject,
            e.rays,
            e.query,
            e.tracer,
            e.peer,
            e.unit,
            e.ours.to_bits(),
            e.anchor.to_bits(),
            e.ratio.to_bits(),
            e.ours_ns_per_step.map(f64::to_bits)
        );
    }
    key
}

/// The subject as shown: the file name (the JSON keeps the whole path).
fn short_subject(subject: &str) -> String {
    Path::new(subject)
        .file_name()
        .map_or_else(|| subject.to_string(), |n| n.to_string_lossy().into_owned())
}

/// The newest anchor (by date) of `tool` with an entry `has`, if any.
fn newest<'a>(
    anchors: &'a [Anchor],
    tool: &str,
    has: impl Fn(&AnchorEntry) -> bool,
) -> Option<&'a Anchor> {
    anchors
        .iter()
        .filter(|a| a.tool == tool && a.entries.iter().any(&has))
        .max_by(|a, b| a.date_utc.cmp(&b.date_utc))
}

/// The entry of `a` for (subject, rays, tracer, peer), if it has one.
fn find<'a>(
    a: &'a Anchor,
    subject: &str,
    rays: &str,
    tracer: &str,
    peer: &str,
) -> Option<&'a AnchorEntry> {
    a.entries
        .iter()
        .find(|e| e.subject == subject && e.rays == rays && e.tracer == tracer && e.peer == peer)
}

/// Rows of (subject, rays, query, tracer, ours) in the order the entries give them.
fn rows(a: &Anchor) -> Vec<(&str, &str, &str, &str, f64)> {
    let mut out: Vec<(&str, &str, &str, &str, f64)> = Vec::new();
    for e in &a.entries {
        let row = (
            e.subject.as_str(),
            e.rays.as_str(),
            e.query.as_str(),
            e.tracer.as_str(),
            e.ours,
        );
        if !out.iter().any(|r| (r.0, r.1, r.3) == (row.0, row.1, row.3)) {
            out.push(row);
        }
    }
    out
}

fn ratio_cell(e: Option<&AnchorEntry>) -> String {
    e.map_or_else(|| "-".into(), |e| format!("**{:.2}**", e.ratio))
}

/// The summary of the newest tinybvh anchor: the mesh backend's ratio against Embree, tinybvh
/// and the faster of them, per mesh and kind of ray.
fn mesh_peers_markdown(s: &mut String, a: &Anchor) {
    let _ = writeln!(
        s,
        "### The mesh backend against Embree and tinybvh, coherent and incoherent rays\n\nFrom the newest tinybvh anchor (`{}`, {} UTC, load {} -> {}; {}), which times the mesh backend, Embree and tinybvh on the same rays in the same interleaved rounds. Camera rays are coherent (`wide1` traces them one by one, `wide4x2` in 8-ray packets on 4x2 tiles); AO, bounce and shadow rays are incoherent (`wide`: batches through the mesh backend's many-ray calls). Each column is marchmesh's rate over the peer's, the median of per-round ratios: Embree's single-ray call (`rtcIntersect1`, `rtcOccluded1`), its 8-wide call, tinybvh's fastest layout, and per round the faster of Embree's single-ray call and tinybvh, and the fastest of every call. Above 1 marchmesh is faster.\n",
        a.file, a.date_utc, a.load_average_start, a.load_average_end, a.version
    );
    let _ = writeln!(
        s,
        "| mesh | rays | query | marchmesh tracer | marchmesh | vs Embree 1-ray | vs Embree 8-wide | vs tinybvh (fastest layout) | vs faster of Embree 1-ray and tinybvh | vs fastest call |\n|---|---|---|---|---|---|---|---|---|---|"
    );
    for (subject, rays, query, tracer, ours) in rows(a) {
        let cell = |peer: &str| ratio_cell(find(a, subject, rays, tracer, peer));
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.2} Mrays/s | {} | {} | {} | {} | {} |",
            short_subject(subject),
            rays,
            query,
            tracer,
            ours,
            cell("embree1"),
            cell("embree8"),
            cell("fastest tinybvh"),
            cell("faster single-ray peer"),
            cell("fastest peer"),
        );
    }
    let _ = writeln!(s);
}

/// The sdf evaluator's cost per ray-step from the newest fidget anchor that gives it.
fn sdf_cost_markdown(s: &mut String, a: &Anchor) {
    let _ = writeln!(
        s,
        "### The sdf evaluator's cost per evaluation\n\nFrom the newest fidget anchor that gives it (`{}`, {} UTC, load {} -> {}): the sdf backend's camera-ray render time over its pixels times their mean marching steps, so one field evaluation of one ray with the marching and hit work around it (evaluations run 8 rays a lane-group), beside both renderers' time per pixel. Ratio: sdf over fidget, above 1 the sdf backend is faster.\n",
        a.file, a.date_utc, a.load_average_start, a.load_average_end
    );
    let _ = writeln!(
        s,
        "| scene | sdf ns per ray-step | sdf ns per pixel | fidget ns per pixel | ratio |\n|---|---|---|---|---|"
    );
    for e in a.entries.iter().filter(|e| e.ours_ns_per_step.is_some()) {
        let _ = writeln!(
            s,
            "| {} | {:.1} | {:.1} | {:.1} | **{:.2}** |",
            short_subject(&e.subject),
            e.ours_ns_per_step.unwrap_or(f64::NAN),
            1e3 / e.ours,
            1e3 / e.anchor,
            e.ratio
        );
    }
    let _ = writeln!(s);
}

/// One anchor's table: with one peer, marchmesh's rate, the anchor's and the ratio; with
/// several, the ratio over each (the peer's rate in parentheses).
fn anchor_table(s: &mut String, a: &Anchor) {
    let _ = writeln!(
        s,
        "**{} backend vs {}** (`{}`, {} UTC, load {} -> {})\n",
        a.backend, a.version, a.file, a.date_utc, a.load_average_start, a.load_average_end
    );
    let mut peers: Vec<&str> = Vec::new();
    for e in &a.entries {
        if !peers.contains(&e.peer.as_str()) {
            peers.push(&e.peer);
        }
    }
    let rays = a.entries.iter().any(|e| e.rays != "camera");
    let rays_head = if rays { " rays |" } else { "" };
    let rays_rule = if rays { "---|" } else { "" };
    if peers.len() <= 1 {
        let cost = a.entries.iter().any(|e| e.ours_ns_per_step.is_some());
        let _ = writeln!(
            s,
            "| mesh or scene |{rays_head} marchmesh tracer | marchmesh | {} | ratio |{}\n|---|{rays_rule}---|---|---|---|{}",
            peers
                .first()
                .filter(|p| !p.is_empty())
                .unwrap_or(&a.tool.as_str()),
            if cost { " sdf ns per ray-step |" } else { "" },
            if cost { "---|" } else { "" },
        );
        for e in &a.entries {
            let rays_cell = if rays {
                format!(" {} |", e.rays)
            } else {
                String::new()
            };
            let cost_cell = if cost {
                e.ours_ns_per_step
                    .map_or_else(|| " - |".into(), |c| format!(" {c:.1} |"))
            } else {
                String::new()
            };
            let _ = writeln!(
                s,
                "| {} |{} {} | {:.2} {} | {:.2} {} | **{:.2}** |{}",
                short_subject(&e.subject),
                rays_cell,
                e.tracer,
                e.ours,
                e.unit,
                e.anchor,
                e.unit,
                e.ratio,
                cost_cell
            );
        }
    } else {
        let _ = write!(
            s,
            "| mesh or scene |{rays_head} marchmesh tracer | marchmesh |"
        );
        for p in &peers {
            let _ = write!(s, " vs {p} |");
        }
        let _ = writeln!(
            s,
            "\n|---|{rays_rule}---|---|{}",
            "---|".repeat(peers.len())
        );
        for (subject, r, _, tracer, ours) in rows(a) {
            let unit = a.entries.first().map_or("", |e| e.unit.as_str());
            let rays_cell = if rays {
                format!(" {r} |")
            } else {
                String::new()
            };
            let _ = write!(
                s,
                "| {} |{} {} | {:.2} {} |",
                short_subject(subject),
                rays_cell,
                tracer,
                ours,
                unit
            );
            for p in &peers {
                let cell = find(a, subject, r, tracer, p).map_or_else(
                    || "-".into(),
                    |e| format!("**{:.2}** ({:.2})", e.ratio, e.anchor),
                );
                let _ = write!(s, " {cell} |");
            }
            let _ = writeln!(s);
        }
    }
    let _ = writeln!(s);
}

/// A Markdown section: first the mesh backend against Embree and tinybvh per mesh and kind of
/// ray (from the newest tinybvh anchor) and the sdf evaluator's cost per evaluation (from the
/// newest fidget anchor giving it), when such anchors are given; then one table per anchor.
/// Empty for no anchors. Deterministic: the same anchors in the same order give the same
/// bytes.
pub fn anchors_markdown(anchors: &[Anchor]) -> String {
    let mut s = String::new();
    if anchors.is_empty() {
        return s;
    }
    let _ = writeln!(
        s,
        "## Each backend against its anchor\n\nThe best known implementations of each representation on the same rays, 1 thread, interleaved rounds (ratio: median of per-round ratios; above 1 marchmesh is faster). Measured by the anchor scripts (`scripts/anchor.sh`, see docs/anchors.md), not by this run: their date and load are given.\n"
    );
    let mut summarised = false;
    if let Some(a) = newest(anchors, "tinybvh", |e| !e.peer.is_empty()) {
        mesh_peers_markdown(&mut s, a);
        summarised = true;
    }
    if let Some(a) = newest(anchors, "fidget", |e| e.ours_ns_per_step.is_some()) {
        sdf_cost_markdown(&mut s, a);
        summarised = true;
    }
    if summarised {
        let _ = writeln!(s, "### Every anchor run\n");
    }
    for a in anchors {
        anchor_table(&mut s, a);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("marchmesh-anchors-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let p = dir.join(name);
        std::fs::write(&p, text).expect("write");
        p
    }

    const EMBREE: &str = r#"{"tool": "anchor-embree", "embree_version": "embreex 4.4.0",
        "date_utc": "2026-11-24 01:00:00", "load_average_start": "0.5 0.5 0.5",
        "load_average_end": "0.6 0.5 0.5", "threads": 1,
        "meshes": [{"mesh": "scenes/meshes/bunny.obj", "triangles": 3,
          "embree": {"mrays_per_s_rounds": [10.0, 12.0], "mrays_per_s_median": 11.0},
          "tracers": {
            "wide1": {"mrays_per_s_median": 12.1, "ratio_over_embree_per_round_median": 1.1},
            "wide4x2": {"mrays_per_s_median": 18.7, "ratio_over_embree_per_round_median": 1.7}}}]}"#;

    /// An Embree anchor with incoherent rays (AO and shadow: occlusion; bounce: closest hit).
    const EMBREE_INCOHERENT: &str = r#"{"tool": "anchor-embree", "embree_version": "Embree 4",
        "date_utc": "2026-11-27 23:34:50", "load_average_start": "4.23 4.92 5.75",
        "load_average_end": "5.80 5.31 5.41",
        "meshes": [{"mesh": "scenes/meshes/bunny.obj", "triangles": 3674,
          "embree": {"mrays_per_s_median": 19.4},
          "tracers": {"wide1": {"mrays_per_s_median": 15.3, "ratio_over_embree_per_round_median": 0.77}},
          "incoherent": {"seed": 42, "kinds": {
            "shadow": {"query": "occlusion", "rays": 36288,
              "embree": {"call": "rtcOccluded1", "mrays_per_s_median": 9.1, "hits": 11372},
              "embree8": {"call": "rtcOccluded8", "mrays_per_s_median": 11.0,
                "ratio_over_embree_per_round_median": 1.2, "hits": 11372, "disagreements": 0},
              "tracers": {"wide": {"mrays_per_s_median": 8.2,
                "ratio_over_embree_per_round_median": 0.89, "hits": 11372, "disagreements": 0}}},
            "ao": {"query": "occlusion", "rays": 70031,
              "embree": {"call": "rtcOccluded1", "mrays_per_s_median": 10.3, "hits": 1961},
              "tracers": {"wide": {"mrays_per_s_median": 9.2,
                "ratio_over_embree_per_round_median": 0.89, "hits": 1961, "disagreements": 0}}},
            "bounce": {"query": "closest hit", "rays": 70031, "tmax": "inf",
              "embree": {"call": "rtcIntersect1", "mrays_per_s_median": 9.3, "hits": 4352},
              "tracers": {"wide": {"mrays_per_s_median": 7.1,
                "ratio_over_embree_per_round_median": 0.78, "hits": 4352}}}}}}]}"#;

    /// A tinybvh anchor: camera rays (single rays and packets) and AO rays (occlusion).
    const TINYBVH: &str = r#"{"tool": "anchor-tinybvh", "tinybvh_version": "tinybvh 1.6.7",
        "embree_version": "Embree 4", "date_utc": "2026-11-28 02:05:34",
        "load_average_start": "5.61 4.68 4.64", "load_average_end": "9.42 8.74 6.62",
        "meshes": [{"mesh": "/tmp/x/dragon.obj", "triangles": 871306, "kinds": {
          "ao": {"query": "occlusion", "rays": 100,
            "sides": {
              "embree1": {"mrays_per_s_median": 10.0, "hits": 7, "disagreements": null},
              "embree8": {"mrays_per_s_median": 14.0, "hits": 7, "disagreements": 0},
              "tinybvh-bvh8": {"mrays_per_s_median": 11.0, "hits": 7, "disagreements": 0},
              "wide": {"mrays_per_s_median": 9.0, "hits": 7, "disagreements": 0}},
            "marchmesh": {"wide": {"over": {"embree1": 0.9, "embree8": 0.64, "tinybvh-bvh8": 0.82},
              "over_fastest_tinybvh": 0.82, "over_faster_single_ray_peer": 0.81,
              "over_fastest_peer": 0.64}}},
          "camera": {"query": "closest hit", "rays": 250,
            "sides": {
              "embree1": {"mrays_per_s_median": 20.0, "hits": 70},
              "embree8": {"mrays_per_s_median": 30.0, "hits": 70, "disagreements": 0},
              "tinybvh-bvh8": {"mrays_per_s_median": 27.0, "hits": 70, "disagreements": 0},
              "tinybvh-bvh4": {"mrays_per_s_median": 23.0, "hits": 70, "disagreements": 0},
              "wide1": {"mrays_per_s_median": 17.0, "hits": 70},
              "wide4x2": {"mrays_per_s_median": 37.0, "hits": 70}},
            "marchmesh": {
              "wide1": {"over": {"embree1": 0.85, "embree8": 0.57, "tinybvh-bvh8": 0.63,
                "tinybvh-bvh4": 0.74}, "over_fastest_tinybvh": 0.63,
                "over_faster_single_ray_peer": 0.62, "over_fastest_peer": 0.56},
              "wide4x2": {"over": {"embree1": 1.85, "embree8": 1.23, "tinybvh-bvh8": 1.37,
                "tinybvh-bvh4": 1.6}, "over_fastest_tinybvh": 1.37,
                "over_faster_single_ray_peer": 1.36, "over_fastest_peer": 1.22}}}}}]}"#;

    const FIDGET: &str = r#"{"tool": "anchor-fidget", "fidget_version": "0.4.3",
            "date_utc": "2026-11-23 23:19:23", "load_average_start": "1.79 1.57 1.79",
            "load_average_end": "1.19 1.42 1.72",
            "scenes": [{"scene": "seed-slab.json", "fidget_depth_voxels": 512,
              "width": 512, "height": 256,
              "fidget": {"mpix_per_s_median": 4.47, "median_s": 0.029},
              "sdf": {"mpix_per_s_median": 2.17, "median_s": 0.0604},
              "ratio_sdf_over_fidget_per_round_median": 0.55,
              "sdf_mean_steps_per_ray": 10.0}]}"#;

    fn entry<'a>(a: &'a Anchor, rays: &str, tracer: &str, peer: &str) -> &'a AnchorEntry {
        a.entries
            .iter()
            .find(|e| e.rays == rays && e.tracer == tracer && e.peer == peer)
            .unwrap_or_else(|| panic!("no {rays} {tracer} over {peer} in {:#?}", a.entries))
    }

    #[test]
    fn reads_an_embree_anchor() {
        let a = read_anchor(&write("embree.json", EMBREE)).expect("reads");
        assert_eq!((a.tool.as_str(), a.backend.as_str()), ("embree", "mesh"));
        assert_eq!(a.entries.len(), 2);
        let wide4x2 = &a.entries[1];
        assert_eq!(wide4x2.tracer, "wide4x2");
        assert_eq!(wide4x2.subject, "scenes/meshes/bunny.obj (3 triangles)");
        assert_eq!(
            (
                wide4x2.rays.as_str(),
                wide4x2.query.as_str(),
                wide4x2.peer.as_str()
            ),
            ("camera", "closest hit", "embree1")
        );
        assert_eq!(
            (wide4x2.ours, wide4x2.anchor, wide4x2.ratio),
            (18.7, 11.0, 1.7)
        );
        let md = anchors_markdown(&[a]);
        assert!(
            md.contains(
                "| bunny.obj (3 triangles) | wide4x2 | 18.70 Mrays/s | 11.00 Mrays/s | **1.70** |"
            ),
            "{md}"
        );
    }

    #[test]
    fn reads_embree_ao_rays_as_occlusion_queries() {
        let a = read_anchor(&write("embree-ao.json", EMBREE_INCOHERENT)).expect("reads");
        let ao = entry(&a, "ao", "wide", "embree1");
        assert_eq!(ao.query, "occlusion");
        assert_eq!((ao.ours, ao.anchor, ao.ratio), (9.2, 10.3, 0.89));
    }

    #[test]
    fn reads_embree_bounce_rays_as_closest_hit_queries() {
        let a = read_anchor(&write("embree-bounce.json", EMBREE_INCOHERENT)).expect("reads");
        let bounce = entry(&a, "bounce", "wide", "embree1");
        assert_eq!(bounce.query, "closest hit");
        assert_eq!((bounce.ours, bounce.anchor, bounce.ratio), (7.1, 9.3, 0.78));
    }

    #[test]
    fn reads_embree_shadow_rays_and_lists_kinds_camera_first() {
        let a = read_anchor(&write("embree-shadow.json", EMBREE_INCOHERENT)).expect("reads");
        let shadow = entry(&a, "shadow", "wide", "embree1");
        assert_eq!(shadow.query, "occlusion");
        assert_eq!(shadow.ratio, 0.89);
        let kinds: Vec<&str> = a.entries.iter().map(|e| e.rays.as_str()).collect();
        assert_eq!(kinds, ["camera", "ao", "bounce", "shadow"]);
        let md = anchors_markdown(&[a]);
        assert!(
            md.contains("| bunny.obj (3674 triangles) | shadow | wide | 8.20 Mrays/s | 9.10 Mrays/s | **0.89** |"),
            "{md}"
        );
    }

    #[test]
    fn reads_tinybvh_camera_rays_against_every_peer() {
        let a = read_anchor(&write("tinybvh-camera.json", TINYBVH)).expect("reads");
        assert_eq!((a.tool.as_str(), a.backend.as_str()), ("tinybvh", "mesh"));
        assert_eq!(a.version, "tinybvh 1.6.7 and Embree 4");
        let e = entry(&a, "camera", "wide1", "embree1");
        assert_eq!((e.ours, e.anchor, e.ratio), (17.0, 20.0, 0.85));
        assert_eq!(e.subject, "/tmp/x/dragon.obj (871306 triangles)");
        let e = entry(&a, "camera", "wide4x2", "tinybvh-bvh4");
        assert_eq!((e.ours, e.anchor, e.ratio), (37.0, 23.0, 1.6));
        // Best-of peers: the best of the medians they choose from.
        let e = entry(&a, "camera", "wide4x2", "fastest tinybvh");
        assert_eq!((e.anchor, e.ratio), (27.0, 1.37));
        let e = entry(&a, "camera", "wide4x2", "faster single-ray peer");
        assert_eq!((e.anchor, e.ratio), (27.0, 1.36));
        let e = entry(&a, "camera", "wide1", "fastest peer");
        assert_eq!((e.anchor, e.ratio), (30.0, 0.56));
        // Camera rays first.
        assert_eq!(a.entries[0].rays, "camera");
    }

    #[test]
    fn reads_tinybvh_occlusion_rays_and_shows_every_mesh_and_kind() {
        let a = read_anchor(&write("tinybvh-ao.json", TINYBVH)).expect("reads");
        let e = entry(&a, "ao", "wide", "faster single-ray peer");
        assert_eq!(e.query, "occlusion");
        assert_eq!((e.ours, e.anchor, e.ratio), (9.0, 11.0, 0.81));
        let e = entry(&a, "ao", "wide", "fastest peer");
        assert_eq!(e.anchor, 14.0);
        let md = anchors_markdown(&[a]);
        assert!(
            md.contains("### The mesh backend against Embree and tinybvh"),
            "{md}"
        );
        assert!(
            md.contains("| dragon.obj (871306 triangles) | camera | closest hit | wide4x2 | 37.00 Mrays/s | **1.85** | **1.23** | **1.37** | **1.36** | **1.22** |"),
            "{md}"
        );
        assert!(
            md.contains("| dragon.obj (871306 triangles) | ao | occlusion | wide | 9.00 Mrays/s | **0.90** | **0.64** | **0.82** | **0.81** | **0.64** |"),
            "{md}"
        );
        // The per-run table names each peer with its rate.
        assert!(md.contains("**0.82** (11.00)"), "{md}");
    }

    #[test]
    fn a_tinybvh_file_before_the_fastest_tinybvh_ratio_reads_without_it() {
        let old = TINYBVH.replace("\"over_fastest_tinybvh\": 0.82,", "");
        let a = read_anchor(&write("tinybvh-old.json", &old)).expect("reads");
        assert!(
            !a.entries
                .iter()
                .any(|e| e.rays == "ao" && e.peer == "fastest tinybvh")
        );
        assert!(
            a.entries
                .iter()
                .any(|e| e.rays == "camera" && e.peer == "fastest tinybvh")
        );
    }

    #[test]
    fn reads_a_fidget_anchor_and_the_sdf_cost_per_step() {
        let a = read_anchor(&write("fidget.json", FIDGET)).expect("reads");
        assert_eq!((a.tool.as_str(), a.backend.as_str()), ("fidget", "sdf"));
        assert_eq!(a.entries[0].subject, "seed-slab.json (512 voxels)");
        assert_eq!(a.entries[0].ratio, 0.55);
        // 0.0604 s over 512 x 256 pixels x 10 steps.
        let ns = a.entries[0].ours_ns_per_step.expect("cost");
        assert!(
            (ns - 0.0604e9 / (512.0 * 256.0 * 10.0)).abs() < 1e-9,
            "{ns}"
        );
        let md = anchors_markdown(&[a]);
        assert!(
            md.contains("### The sdf evaluator's cost per evaluation")
                && md.contains("| seed-slab.json (512 voxels) | 46.1 | 460.8 | 223.7 | **0.55** |"),
            "{md}"
        );
        // Files without the step counts (the first fidget anchors) read without a cost.
        let old = FIDGET.replace("\"sdf_mean_steps_per_ray\": 10.0", "\"leaves\": 5");
        let a = read_anchor(&write("fidget-old.json", &old)).expect("reads");
        assert_eq!(a.entries[0].ours_ns_per_step, None);
        assert!(!anchors_markdown(&[a]).contains("cost per evaluation"));
    }

    /// Every committed anchor file reads, each tool and each kind of ray among them.
    #[test]
    fn every_committed_anchor_file_reads() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../bench-results/anchors");
        let mut tools = std::collections::BTreeSet::new();
        let mut kinds = std::collections::BTreeSet::new();
        for e in std::fs::read_dir(&dir).expect("anchors folder") {
            let p = e.expect("entry").path();
            if p.extension().is_some_and(|x| x == "json") {
                let a = read_anchor(&p).unwrap_or_else(|e| panic!("{e}"));
                assert!(!a.entries.is_empty(), "{}", p.display());
                tools.insert(a.tool.clone());
                kinds.extend(a.entries.iter().map(|e| (e.rays.clone(), e.query.clone())));
            }
        }
        assert_eq!(
            tools.into_iter().collect::<Vec<_>>(),
            ["embree", "fidget", "tinybvh"]
        );
        for k in [
            ("camera", "closest hit"),
            ("ao", "occlusion"),
            ("bounce", "closest hit"),
            ("shadow", "occlusion"),
        ] {
            assert!(kinds.contains(&(k.0.to_string(), k.1.to_string())), "{k:?}");
        }
    }

    /// The error names the file and what it says names the field.
    fn refused(name: &str, text: &str, field: &str) -> AnchorError {
        let e = read_anchor(&write(name, text)).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains(name), "no file name: {msg}");
        assert!(msg.contains(field), "no field {field}: {msg}");
        assert!(!msg.contains("panicked"), "{msg}");
        e
    }

    #[test]
    fn refuses_other_files_naming_the_file_and_the_place() {
        refused("other.json", r#"{"tool": "something"}"#, "tool");
        let e = refused(
            "broken.json",
            r#"{"tool": "anchor-embree", "meshes": 3}"#,
            "at meshes: invalid type",
        );
        assert!(matches!(e, AnchorError::Json { .. }), "{e}");
        refused("notjson.json", "<html>", "expected value");
        let e = read_anchor(Path::new("/nonexistent/anchor.json")).unwrap_err();
        assert!(matches!(e, AnchorError::Read { .. }), "{e}");
    }

    #[test]
    fn refuses_truncated_files() {
        for (name, text) in [
            ("cut-tinybvh.json", TINYBVH),
            ("cut-embree.json", EMBREE_INCOHERENT),
            ("cut-fidget.json", FIDGET),
        ] {
            let e = refused(name, &text[..text.len() * 2 / 3], "EOF");
            assert!(matches!(e, AnchorError::Json { .. }), "{e}");
        }
    }

    #[test]
    fn refuses_one_tools_figures_under_another_tools_name() {
        // A tinybvh file labelled as Embree's: Embree's fields are missing.
        let e = refused(
            "wrong-kind.json",
            &TINYBVH.replace("anchor-tinybvh", "anchor-embree"),
            "embree",
        );
        assert!(matches!(e, AnchorError::Json { .. }), "{e}");
        // A ray kind whose query is neither closest hit nor occlusion.
        refused(
            "wrong-query.json",
            &TINYBVH.replace("\"query\": \"occlusion\"", "\"query\": \"any\""),
            "meshes[0].kinds.ao.query",
        );
        // A ratio over a peer that was not timed.
        refused(
            "untimed-peer.json",
            &TINYBVH.replace("\"tinybvh-bvh4\": 1.6", "\"tinybvh-soa\": 1.6"),
            "camera.marchmesh.wide4x2.over.tinybvh-soa",
        );
        // A tracer's ratios without its rate.
        refused(
            "untimed-tracer.json",
            &TINYBVH.replace(
                "\"wide\": {\"mrays_per_s_median\": 9.0",
                "\"w\": {\"mrays_per_s_median\": 9.0",
            ),
            "meshes[0].kinds.ao.marchmesh.wide",
        );
    }

    #[test]
    fn refuses_nan_and_infinite_timings() {
        // Python's json writes NaN and Infinity, which are not JSON.
        for (name, bad) in [("nan.json", "NaN"), ("inf.json", "Infinity")] {
            let e = refused(
                name,
                &TINYBVH.replace(
                    "\"mrays_per_s_median\": 23.0",
                    &format!("\"mrays_per_s_median\": {bad}"),
                ),
                "\"tinybvh-bvh4\": {\"mrays_per_s_median\":",
            );
            assert!(e.to_string().contains("not JSON numbers"), "{e}");
            assert!(matches!(e, AnchorError::Json { .. }), "{e}");
        }
    }

    #[test]
    fn refuses_rates_that_are_not_finite_and_positive() {
        let bad = EMBREE.replace(
            "\"ratio_over_embree_per_round_median\": 1.7",
            "\"ratio_over_embree_per_round_median\": -1.7",
        );
        let e = refused("negative.json", &bad, "ratio is -1.7");
        assert!(
            matches!(e, AnchorError::Value { field: "ratio", .. }),
            "{e}"
        );
        let zero = EMBREE.replace(
            "\"mrays_per_s_median\": 11.0",
            "\"mrays_per_s_median\": 0.0",
        );
        let e = refused("zero.json", &zero, "anchor is 0");
        assert!(
            matches!(
                e,
                AnchorError::Value {
                    field: "anchor",
                    ..
                }
            ),
            "{e}"
        );
        // A negative timing of an incoherent kind names its kind, tracer and peer.
        let e = refused(
            "negative-ao.json",
            &TINYBVH.replace("\"embree8\": 0.64", "\"embree8\": -0.64"),
            "ao rays, wide over embree8",
        );
        assert!(
            matches!(e, AnchorError::Value { field: "ratio", .. }),
            "{e}"
        );
        // A negative time of the fidget anchor gives a negative cost.
        refused(
            "negative-time.json",
            &FIDGET.replace("\"median_s\": 0.0604", "\"median_s\": -0.0604"),
            "ours_ns_per_step",
        );
        // Absurdly large.
        refused(
            "huge-rate.json",
            &TINYBVH.replace(
                "\"mrays_per_s_median\": 37.0",
                "\"mrays_per_s_median\": 1e300",
            ),
            "ours is 1e300",
        );
    }

    #[test]
    fn refuses_huge_and_inconsistent_counts() {
        refused(
            "huge-rays.json",
            &TINYBVH.replace("\"rays\": 250", "\"rays\": 1125899906842624"),
            "meshes[0].kinds.camera.rays",
        );
        refused(
            "overflow.json",
            &TINYBVH.replace("\"rays\": 250", "\"rays\": 99999999999999999999999"),
            "meshes[0].kinds.camera.rays",
        );
        refused(
            "float-count.json",
            &TINYBVH.replace("\"triangles\": 871306", "\"triangles\": 8.5e5"),
            "meshes[0].triangles",
        );
        refused(
            "more-hits.json",
            &EMBREE_INCOHERENT.replace("\"hits\": 4352}}}", "\"hits\": 99999}}}"),
            "meshes[0].incoherent.kinds.bounce.tracers.wide.hits",
        );
        refused(
            "huge-image.json",
            &FIDGET.replace("\"width\": 512", "\"width\": 1099511627777"),
            "scenes[0].width",
        );
    }
}
