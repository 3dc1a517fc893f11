//! External anchors: each backend measured against the best known implementation of its
//! representation on the same rays, by the scripts outside the default build
//! (`scripts/anchor_embree.sh`: the mesh backend against Embree 4's `rtcIntersect1`;
//! `scripts/anchor_fidget.sh`: the sdf backend against fidget). Their JSON files are read
//! here into one [`Anchor`] form, which a run records (`marchmesh bench --anchor`) and the
//! findings show, so a verdict between the backends stands beside how far each is from its
//! field's best.

use std::fmt::Write;
use std::path::Path;

use marchmesh_core::Backend;
use marchmesh_mesh::MeshBackend;
use marchmesh_sdf::SdfBackend;
use serde::{Deserialize, Serialize};

/// Largest anchor file read (an anchor run writes a few tens of KB).
pub const MAX_ANCHOR_FILE_BYTES: u64 = 16 << 20;

/// One anchor run, normalised from either script's JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Anchor {
    /// `embree` or `fidget`.
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
    /// One row per mesh or scene and marchmesh tracer.
    pub entries: Vec<AnchorEntry>,
}

/// marchmesh against the anchor on one mesh or scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnchorEntry {
    /// The mesh file or scene whose camera rays both traced.
    pub subject: String,
    /// marchmesh's tracer (`wide1`: single rays, `wide4x2`: packets, `sdf`: the sdf backend).
    pub tracer: String,
    /// Unit of both rates (`Mrays/s` or `Mpix/s`), 1 thread.
    pub unit: String,
    /// marchmesh's rate (median over rounds).
    pub ours: f64,
    /// The anchor's rate (median over rounds).
    pub anchor: f64,
    /// marchmesh / anchor: the median of per-round ratios (above 1: marchmesh is faster).
    pub ratio: f64,
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
    /// Not JSON of either anchor's form.
    #[error("{file}: at {path}: {reason}")]
    Json {
        /// The file.
        file: String,
        /// Where in the document.
        path: String,
        /// What was wrong.
        reason: String,
    },
    /// A rate or ratio is not a finite positive number.
    #[error("{file}: {subject} ({tracer}): {field} is {value}, not a finite positive number")]
    Value {
        /// The file.
        file: String,
        /// Its mesh or scene.
        subject: String,
        /// Its tracer.
        tracer: String,
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
    embree: EmbreeRate,
    tracers: std::collections::BTreeMap<String, EmbreeTracer>,
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
    fidget: FidgetRate,
    sdf: FidgetRate,
    ratio_sdf_over_fidget_per_round_median: f64,
}

#[derive(Deserialize)]
struct FidgetRate {
    mpix_per_s_median: f64,
}

/// The `tool` field both forms start with.
#[derive(Deserialize)]
struct Tool {
    tool: String,
}

fn parse<T: serde::de::DeserializeOwned>(file: &str, text: &str) -> Result<T, AnchorError> {
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| AnchorError::Json {
        file: file.to_string(),
        path: e.path().to_string(),
        reason: e.into_inner().to_string(),
    })
}

/// Reads an anchor file written by `scripts/anchor_embree.py --json` (`"tool":
/// "anchor-embree"`) or by `crates/anchor-fidget --json` (`"tool": "anchor-fidget"`).
/// Fails naming the file (and the place in it) on anything else, and on a rate or ratio
/// that is not finite and positive.
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
            let entries = f
                .meshes
                .iter()
                .flat_map(|m| {
                    m.tracers.iter().map(|(name, t)| AnchorEntry {
                        subject: m.mesh.clone(),
                        tracer: name.clone(),
                        unit: "Mrays/s".into(),
                        ours: t.mrays_per_s_median,
                        anchor: m.embree.mrays_per_s_median,
                        ratio: t.ratio_over_embree_per_round_median,
                    })
                })
                .collect();
            Anchor {
                tool: "embree".into(),
                version: f.embree_version,
                backend: MeshBackend::NAME.into(),
                file,
                date_utc: f.date_utc,
                load_average_start: f.load_average_start,
                load_average_end: f.load_average_end,
                entries,
            }
        }
        "anchor-fidget" => {
            let f: FidgetFile = parse(&file, &text)?;
            let entries = f
                .scenes
                .iter()
                .map(|s| AnchorEntry {
                    subject: format!("{} ({} voxels)", s.scene, s.fidget_depth_voxels),
                    tracer: SdfBackend::NAME.into(),
                    unit: "Mpix/s".into(),
                    ours: s.sdf.mpix_per_s_median,
                    anchor: s.fidget.mpix_per_s_median,
                    ratio: s.ratio_sdf_over_fidget_per_round_median,
                })
                .collect();
            Anchor {
                tool: "fidget".into(),
                version: format!("fidget {}", f.fidget_version),
                backend: SdfBackend::NAME.into(),
                file,
                date_utc: f.date_utc,
                load_average_start: f.load_average_start,
                load_average_end: f.load_average_end,
                entries,
            }
        }
        other => {
            return Err(AnchorError::Json {
                file,
                path: "tool".into(),
                reason: format!(
                    "{other:?} is not an anchor this version reads (anchor-embree, anchor-fidget)"
                ),
            });
        }
    };
    for e in &anchor.entries {
        for (field, value) in [("ours", e.ours), ("anchor", e.anchor), ("ratio", e.ratio)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(AnchorError::Value {
                    file: anchor.file.clone(),
                    subject: e.subject.clone(),
                    tracer: e.tracer.clone(),
                    field,
                    value,
                });
            }
        }
    }
    Ok(anchor)
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
            "\0{:?}\0{:?}\0{:?}\0{:x}\0{:x}\0{:x}",
            e.subject,
            e.tracer,
            e.unit,
            e.ours.to_bits(),
            e.anchor.to_bits(),
            e.ratio.to_bits()
        );
    }
    key
}

/// A Markdown section: one table per anchor, marchmesh's rate, the anchor's and the ratio.
/// Empty for no anchors.
pub fn anchors_markdown(anchors: &[Anchor]) -> String {
    let mut s = String::new();
    if anchors.is_empty() {
        return s;
    }
    let _ = writeln!(
        s,
        "## Each backend against its anchor\n\nThe best known implementation of each representation on the same camera rays, 1 thread, interleaved rounds (ratio: median of per-round ratios; above 1 marchmesh is faster). Measured by the anchor scripts, not by this run: their date and load are given.\n"
    );
    for a in anchors {
        let _ = writeln!(
            s,
            "**{} backend vs {}** (`{}`, {} UTC, load {} -> {})\n",
            a.backend, a.version, a.file, a.date_utc, a.load_average_start, a.load_average_end
        );
        let _ = writeln!(
            s,
            "| mesh or scene | marchmesh tracer | marchmesh | {} | ratio |\n|---|---|---|---|---|",
            a.tool
        );
        for e in &a.entries {
            // The file name says which mesh or scene; the JSON keeps the whole path.
            let subject = std::path::Path::new(&e.subject)
                .file_name()
                .map_or_else(|| e.subject.clone(), |n| n.to_string_lossy().into_owned());
            let _ = writeln!(
                s,
                "| {} | {} | {:.2} {} | {:.2} {} | **{:.2}** |",
                subject, e.tracer, e.ours, e.unit, e.anchor, e.unit, e.ratio
            );
        }
        let _ = writeln!(s);
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

    #[test]
    fn reads_an_embree_anchor() {
        let a = read_anchor(&write("embree.json", EMBREE)).expect("reads");
        assert_eq!((a.tool.as_str(), a.backend.as_str()), ("embree", "mesh"));
        assert_eq!(a.entries.len(), 2);
        let wide4x2 = &a.entries[1];
        assert_eq!(wide4x2.tracer, "wide4x2");
        assert_eq!(
            (wide4x2.ours, wide4x2.anchor, wide4x2.ratio),
            (18.7, 11.0, 1.7)
        );
        let md = anchors_markdown(&[a]);
        assert!(
            md.contains("| bunny.obj | wide4x2 | 18.70 Mrays/s | 11.00 Mrays/s | **1.70** |"),
            "{md}"
        );
    }

    #[test]
    fn reads_a_fidget_anchor() {
        let text = r#"{"tool": "anchor-fidget", "fidget_version": "0.4.3",
            "date_utc": "2026-11-23 23:19:23", "load_average_start": "1.79 1.57 1.79",
            "load_average_end": "1.19 1.42 1.72",
            "scenes": [{"scene": "seed-slab.json", "fidget_depth_voxels": 512,
              "fidget": {"mpix_per_s_median": 4.47}, "sdf": {"mpix_per_s_median": 2.17},
              "ratio_sdf_over_fidget_per_round_median": 0.55}]}"#;
        let a = read_anchor(&write("fidget.json", text)).expect("reads");
        assert_eq!((a.tool.as_str(), a.backend.as_str()), ("fidget", "sdf"));
        assert_eq!(a.entries[0].subject, "seed-slab.json (512 voxels)");
        assert_eq!(a.entries[0].ratio, 0.55);
    }

    #[test]
    fn refuses_other_files_naming_the_file_and_the_place() {
        let e = read_anchor(&write("other.json", r#"{"tool": "something"}"#)).unwrap_err();
        assert!(
            e.to_string().contains("other.json") && e.to_string().contains("tool"),
            "{e}"
        );
        let e = read_anchor(&write(
            "broken.json",
            r#"{"tool": "anchor-embree", "meshes": 3}"#,
        ))
        .unwrap_err();
        assert!(matches!(e, AnchorError::Json { .. }), "{e}");
        let e = read_anchor(&write("notjson.json", "<html>")).unwrap_err();
        assert!(e.to_string().contains("notjson.json"), "{e}");
        let e = read_anchor(Path::new("/nonexistent/anchor.json")).unwrap_err();
        assert!(matches!(e, AnchorError::Read { .. }), "{e}");
    }

    #[test]
    fn refuses_rates_that_are_not_finite_and_positive() {
        let bad = EMBREE.replace(
            "\"ratio_over_embree_per_round_median\": 1.7",
            "\"ratio_over_embree_per_round_median\": -1.7",
        );
        let e = read_anchor(&write("negative.json", &bad)).unwrap_err();
        assert!(
            matches!(e, AnchorError::Value { field: "ratio", .. }),
            "{e}"
        );
        let zero = EMBREE.replace(
            "\"mrays_per_s_median\": 11.0",
            "\"mrays_per_s_median\": 0.0",
        );
        let e = read_anchor(&write("zero.json", &zero)).unwrap_err();
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
    }
}
