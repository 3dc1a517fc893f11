//! One place that knows every backend: build any of them for a scene from a name and
//! `key=value` options, as given on the command line or in a suite file.
//!
//! Each backend has an option table ([`option_table`]): key, value type, default and meaning.
//! Options are applied in order onto the backend's documented defaults (later keys override
//! earlier ones); unknown keys and unparsable values are errors that name the backend, the
//! key and the valid keys. Range checks are left to the backend's own `build`, whose errors
//! name the field.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

use marchmesh_core::{DEFAULT_MEMORY_LIMIT_BYTES, Geometry};
use marchmesh_mesh::{BuildQuality, BvhKind, MeshOptions, Tessellation};
use marchmesh_scene::Scene;
use marchmesh_sdf::{HitEpsilon, SdfOptions};

/// The geometry backends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum BackendKind {
    /// Exact analytic f64 ray casting: the ground truth.
    Reference,
    /// Sphere tracing a compiled signed distance field.
    Sdf,
    /// Triangles in an obvhs BVH.
    Mesh,
}

impl BackendKind {
    /// Every backend, reference first.
    pub const ALL: [BackendKind; 3] = [BackendKind::Reference, BackendKind::Sdf, BackendKind::Mesh];

    /// The lower-case name used on the command line and in reports.
    pub const fn name(self) -> &'static str {
        match self {
            BackendKind::Reference => "reference",
            BackendKind::Sdf => "sdf",
            BackendKind::Mesh => "mesh",
        }
    }
}

impl fmt::Display for BackendKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for BackendKind {
    type Err = BackendError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        BackendKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| BackendError::UnknownBackend(s.to_string()))
    }
}

/// A backend and its options.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct BackendSpec {
    /// Which backend.
    pub kind: Option<BackendKind>,
    /// `key=value` options in the order given; later keys override earlier ones.
    pub options: Vec<(String, String)>,
}

/// Why a backend could not be built.
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    /// The name is not a backend.
    #[error("unknown backend `{0}` (expected one of: reference, sdf, mesh)")]
    UnknownBackend(String),
    /// No backend was named.
    #[error("no backend given")]
    Missing,
    /// An option key the backend does not have, or a value it cannot parse.
    #[error("backend `{backend}`: option `{key}`: {reason}")]
    BadOption {
        /// The backend.
        backend: BackendKind,
        /// The option key.
        key: String,
        /// Why it was rejected (lists the valid keys for unknown ones).
        reason: String,
    },
    /// The backend failed to build (bad mesh file, scene it cannot represent, ...).
    #[error("backend `{backend}` failed to build the scene: {reason}")]
    Build {
        /// The backend.
        backend: BackendKind,
        /// The backend's error message.
        reason: String,
    },
}

/// Message of the reference backend's build error while it is not linked in.
pub const NOT_BUILT: &str = "not built into this binary yet";

/// Parses `key=value`.
pub fn parse_option(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.trim().is_empty() => Ok((k.trim().to_string(), v.trim().to_string())),
        _ => Err(format!("`{s}` is not of the form key=value")),
    }
}

/// One documented option key of a backend.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OptionDoc {
    /// The key as written in `key=value`.
    pub key: &'static str,
    /// The value type (`float`, `int`, `bool`, `path|none`, or the accepted words).
    pub ty: &'static str,
    /// What it controls, with units.
    pub doc: &'static str,
}

const SDF_OPTIONS: &[OptionDoc] = &[
    OptionDoc {
        key: "eps_px",
        ty: "float",
        doc: "hit epsilon as a fraction of the pixel footprint at the point (scale invariant)",
    },
    OptionDoc {
        key: "eps_abs",
        ty: "float",
        doc: "absolute hit epsilon, world units (replaces eps_px)",
    },
    OptionDoc {
        key: "max_steps",
        ty: "int",
        doc: "most field evaluations per ray; rays that run out count as misses",
    },
    OptionDoc {
        key: "max_distance",
        ty: "float|none",
        doc: "longest ray, world units; none = the scene's render.max_distance",
    },
    OptionDoc {
        key: "relaxation",
        ty: "float",
        doc: "over-relaxation factor in [1, 2) with overlap fallback (1 = off)",
    },
    OptionDoc {
        key: "refine_steps",
        ty: "int",
        doc: "plain steps after a hit to move it onto the surface",
    },
    OptionDoc {
        key: "normal_step",
        ty: "float",
        doc: "central-difference normal step, fraction of the pixel footprint",
    },
    OptionDoc {
        key: "lockstep",
        ty: "bool",
        doc: "trace batches 8 rays in lockstep (same results)",
    },
    OptionDoc {
        key: "grid_res",
        ty: "int",
        doc: "cells on the longest side of baked mesh distance grids",
    },
    OptionDoc {
        key: "cache_dir",
        ty: "path|none",
        doc: "folder caching baked grids (none = no disk cache)",
    },
    OptionDoc {
        key: "cone_shadows",
        ty: "bool",
        doc: "area-light soft shadows from one cone march per light (approximate) instead of sampled rays",
    },
    OptionDoc {
        key: "ao_taps",
        ty: "int",
        doc: "ambient occlusion from this many field taps along the normal (approximate); 0 = sampled rays",
    },
];

const MESH_OPTIONS: &[OptionDoc] = &[
    OptionDoc {
        key: "preset",
        ty: "fast|default|quality",
        doc: "start from MeshOptions::fast()/DEFAULT/quality() (give it first)",
    },
    OptionDoc {
        key: "bvh",
        ty: "bvh2|cwbvh|wide",
        doc: "BVH layout: binary, compressed 8-wide, or SIMD 8-wide converted from bvh2",
    },
    OptionDoc {
        key: "build",
        ty: "fastest|very_fast|fast|medium|slow|very_slow",
        doc: "obvhs build preset",
    },
    OptionDoc {
        key: "tess_px",
        ty: "float",
        doc: "tessellation chord error on screen, pixels",
    },
    OptionDoc {
        key: "tess_chord",
        ty: "float",
        doc: "tessellation chord error, world units (replaces tess_px)",
    },
    OptionDoc {
        key: "tess_level",
        ty: "int",
        doc: "fixed tessellation: 8*2^level segments per turn, <= 12 (replaces tess_px)",
    },
    OptionDoc {
        key: "surface_res",
        ty: "int",
        doc: "surface-nets cells on the longest side of CSG / smooth-union objects (8..=512)",
    },
    OptionDoc {
        key: "packets",
        ty: "bool",
        doc: "trace 8 rays of a batch as one packet (bvh=wide, no instances)",
    },
    OptionDoc {
        key: "instancing",
        ty: "bool",
        doc: "instance repeated shapes under a TLAS (false = flatten into one BVH)",
    },
    OptionDoc {
        key: "max_instances",
        ty: "int",
        doc: "largest instance count an infinite repetition may expand to",
    },
    OptionDoc {
        key: "max_segments",
        ty: "int",
        doc: "cap on segments per full turn of any parametric direction",
    },
];

const REFERENCE_OPTIONS: &[OptionDoc] = &[];

/// The documented options of `kind`.
pub fn option_table(kind: BackendKind) -> &'static [OptionDoc] {
    match kind {
        BackendKind::Reference => REFERENCE_OPTIONS,
        BackendKind::Sdf => SDF_OPTIONS,
        BackendKind::Mesh => MESH_OPTIONS,
    }
}

/// The default value of option `key` of `kind`, written as it would be parsed, read from
/// the backend's `DEFAULT` options (so it cannot drift from the backend). `none` when the
/// key is unset by default; `None` for an unknown key.
pub fn default_value(kind: BackendKind, key: &str) -> Option<String> {
    let f = |x: f64| format!("{x}");
    Some(match kind {
        BackendKind::Reference => return None,
        BackendKind::Sdf => {
            let o = SdfOptions::DEFAULT;
            match key {
                "eps_px" => match o.hit_epsilon {
                    HitEpsilon::PixelCone(k) => f(k),
                    HitEpsilon::Absolute(_) => "none".into(),
                },
                "eps_abs" => match o.hit_epsilon {
                    HitEpsilon::Absolute(e) => f(e),
                    HitEpsilon::PixelCone(_) => "none".into(),
                },
                "max_steps" => o.max_steps.to_string(),
                "max_distance" => o.max_distance.map_or("none".into(), f),
                "relaxation" => f(o.relaxation),
                "refine_steps" => o.refine_steps.to_string(),
                "normal_step" => f(o.normal_step),
                "lockstep" => o.lockstep.to_string(),
                "grid_res" => o.mesh_grid_resolution.to_string(),
                "cache_dir" => o
                    .cache_dir
                    .map_or("none".into(), |p| p.display().to_string()),
                "cone_shadows" => o.cone_shadows.to_string(),
                "ao_taps" => o.ao_taps.to_string(),
                _ => return None,
            }
        }
        BackendKind::Mesh => {
            let o = MeshOptions::DEFAULT;
            match key {
                "preset" => "default".into(),
                "bvh" => match o.bvh {
                    BvhKind::Bvh2 => "bvh2",
                    BvhKind::CwBvh => "cwbvh",
                    BvhKind::Wide => "wide",
                }
                .into(),
                "build" => match o.build_quality {
                    BuildQuality::Fastest => "fastest",
                    BuildQuality::VeryFast => "very_fast",
                    BuildQuality::Fast => "fast",
                    BuildQuality::Medium => "medium",
                    BuildQuality::Slow => "slow",
                    BuildQuality::VerySlow => "very_slow",
                }
                .into(),
                "tess_px" | "tess_chord" | "tess_level" => match (key, o.tessellation) {
                    ("tess_px", Tessellation::ScreenError { pixels }) => f(pixels),
                    ("tess_chord", Tessellation::ChordError { world }) => f(world),
                    ("tess_level", Tessellation::FixedLevel(l)) => l.to_string(),
                    _ => "none".into(),
                },
                "surface_res" => o.surface_resolution.to_string(),
                "packets" => o.packets.to_string(),
                "instancing" => o.instancing.to_string(),
                "max_instances" => o.max_instances.to_string(),
                "max_segments" => o.max_segments_per_turn.to_string(),
                _ => return None,
            }
        }
    })
}

/// The option table of `kind` as aligned text (for `--opt help`).
pub fn option_help(kind: BackendKind) -> String {
    let table = option_table(kind);
    if table.is_empty() {
        return format!("backend `{kind}` has no options\n");
    }
    let kw = table.iter().map(|o| o.key.len()).max().unwrap_or(0);
    let tw = table.iter().map(|o| o.ty.len()).max().unwrap_or(0);
    let mut s = format!("options of backend `{kind}` (key=value):\n");
    for o in table {
        let d = default_value(kind, o.key).unwrap_or_default();
        s += &format!(
            "  {:kw$}  {:tw$}  default {:8}  {}\n",
            o.key, o.ty, d, o.doc
        );
    }
    s
}

fn valid_keys(kind: BackendKind) -> String {
    let keys: Vec<&str> = option_table(kind).iter().map(|o| o.key).collect();
    if keys.is_empty() {
        "it has no options".into()
    } else {
        format!("valid keys: {}", keys.join(", "))
    }
}

fn bad(kind: BackendKind, key: &str, reason: String) -> BackendError {
    BackendError::BadOption {
        backend: kind,
        key: key.to_string(),
        reason,
    }
}

fn parse_f64(v: &str) -> Result<f64, String> {
    match v.parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        Ok(_) => Err(format!("`{v}` is not a finite number")),
        Err(_) => Err(format!("`{v}` is not a number")),
    }
}

fn parse_int<T: FromStr>(v: &str) -> Result<T, String> {
    v.parse::<T>()
        .map_err(|_| format!("`{v}` is not a non-negative integer in range"))
}

fn parse_bool(v: &str) -> Result<bool, String> {
    match v {
        "true" | "1" | "yes" | "on" => Ok(true),
        "false" | "0" | "no" | "off" => Ok(false),
        _ => Err(format!("`{v}` is not a boolean (true/false)")),
    }
}

fn is_none(v: &str) -> bool {
    v.eq_ignore_ascii_case("none")
}

/// Applies `key=value` options in order onto the SDF defaults.
pub fn sdf_options(options: &[(String, String)]) -> Result<SdfOptions, BackendError> {
    let kind = BackendKind::Sdf;
    let mut o = SdfOptions::DEFAULT;
    for (k, v) in options {
        let r: Result<(), String> = (|| {
            match k.as_str() {
                "eps_px" => o.hit_epsilon = HitEpsilon::PixelCone(parse_f64(v)?),
                "eps_abs" => o.hit_epsilon = HitEpsilon::Absolute(parse_f64(v)?),
                "max_steps" => o.max_steps = parse_int(v)?,
                "max_distance" => {
                    o.max_distance = if is_none(v) {
                        None
                    } else {
                        Some(parse_f64(v)?)
                    }
                }
                "relaxation" => o.relaxation = parse_f64(v)?,
                "refine_steps" => o.refine_steps = parse_int(v)?,
                "normal_step" => o.normal_step = parse_f64(v)?,
                "lockstep" => o.lockstep = parse_bool(v)?,
                "grid_res" => o.mesh_grid_resolution = parse_int(v)?,
                "cache_dir" => {
                    o.cache_dir = if is_none(v) {
                        None
                    } else {
                        Some(PathBuf::from(v))
                    }
                }
                "cone_shadows" => o.cone_shadows = parse_bool(v)?,
                "ao_taps" => o.ao_taps = parse_int(v)?,
                _ => return Err(format!("unknown option; {}", valid_keys(kind))),
            }
            Ok(())
        })();
        r.map_err(|reason| bad(kind, k, reason))?;
    }
    Ok(o)
}

/// Applies `key=value` options in order onto the mesh defaults.
pub fn mesh_options(options: &[(String, String)]) -> Result<MeshOptions, BackendError> {
    let kind = BackendKind::Mesh;
    let mut o = MeshOptions::DEFAULT;
    // A preset sets every field: apply it first so `--opt x=1 --opt preset=fast` keeps x.
    let presets_first = options
        .iter()
        .filter(|(k, _)| k == "preset")
        .chain(options.iter().filter(|(k, _)| k != "preset"));
    for (k, v) in presets_first {
        let r: Result<(), String> = (|| {
            match k.as_str() {
                "preset" => {
                    o = match v.as_str() {
                        "fast" => MeshOptions::fast(),
                        "default" => MeshOptions::DEFAULT,
                        "quality" => MeshOptions::quality(),
                        _ => return Err(format!("`{v}` is not one of fast, default, quality")),
                    }
                }
                "bvh" => {
                    o.bvh = match v.to_ascii_lowercase().as_str() {
                        "bvh2" => BvhKind::Bvh2,
                        "cwbvh" => BvhKind::CwBvh,
                        "wide" => BvhKind::Wide,
                        _ => return Err(format!("`{v}` is not one of bvh2, cwbvh, wide")),
                    }
                }
                "build" => {
                    o.build_quality = match v.as_str() {
                        "fastest" => BuildQuality::Fastest,
                        "very_fast" => BuildQuality::VeryFast,
                        "fast" => BuildQuality::Fast,
                        "medium" => BuildQuality::Medium,
                        "slow" => BuildQuality::Slow,
                        "very_slow" => BuildQuality::VerySlow,
                        _ => {
                            return Err(format!(
                                "`{v}` is not one of fastest, very_fast, fast, medium, slow, very_slow"
                            ));
                        }
                    }
                }
                "tess_px" => {
                    o.tessellation = Tessellation::ScreenError {
                        pixels: parse_f64(v)?,
                    }
                }
                "tess_chord" => {
                    o.tessellation = Tessellation::ChordError {
                        world: parse_f64(v)?,
                    }
                }
                "tess_level" => o.tessellation = Tessellation::FixedLevel(parse_int(v)?),
                "surface_res" => o.surface_resolution = parse_int(v)?,
                "packets" => o.packets = parse_bool(v)?,
                "instancing" => o.instancing = parse_bool(v)?,
                "max_instances" => o.max_instances = parse_int(v)?,
                "max_segments" => o.max_segments_per_turn = parse_int(v)?,
                _ => return Err(format!("unknown option; {}", valid_keys(kind))),
            }
            Ok(())
        })();
        r.map_err(|reason| bad(kind, k, reason))?;
    }
    Ok(o)
}

/// Checks the options of the reference backend (it has none yet).
fn reference_options(options: &[(String, String)]) -> Result<(), BackendError> {
    let kind = BackendKind::Reference;
    if let Some((k, _)) = options.first() {
        return Err(bad(
            kind,
            k,
            format!("unknown option; {}", valid_keys(kind)),
        ));
    }
    Ok(())
}

/// Checks `spec`'s options without building anything (suite validation).
pub fn check_options(spec: &BackendSpec) -> Result<(), BackendError> {
    match spec.kind.ok_or(BackendError::Missing)? {
        BackendKind::Reference => reference_options(&spec.options),
        BackendKind::Sdf => sdf_options(&spec.options).map(drop),
        BackendKind::Mesh => mesh_options(&spec.options).map(drop),
    }
}

/// Whether `kind` is linked into this binary.
pub fn is_available(_kind: BackendKind) -> bool {
    true
}

/// Builds the backend named in `spec` for `scene`.
pub fn build(scene: &Scene, spec: &BackendSpec) -> Result<Box<dyn Geometry>, BackendError> {
    build_within(scene, spec, DEFAULT_MEMORY_LIMIT_BYTES)
}

/// [`build`] refusing, before allocating, builds whose estimated memory (tessellated and
/// loaded triangles, extraction and bake grids, instances) exceeds `memory_limit_bytes`; the
/// error names the object, the estimate, the limit and the option to change. The reference
/// backend keeps only the scene's meshes (their reads are capped) and is not estimated.
pub fn build_within(
    scene: &Scene,
    spec: &BackendSpec,
    memory_limit_bytes: u64,
) -> Result<Box<dyn Geometry>, BackendError> {
    let kind = spec.kind.ok_or(BackendError::Missing)?;
    let build_err = |e: &dyn fmt::Display| BackendError::Build {
        backend: kind,
        reason: e.to_string(),
    };
    match kind {
        BackendKind::Reference => {
            reference_options(&spec.options)?;
            let g =
                marchmesh_reference::build(scene, &marchmesh_reference::ReferenceOptions::DEFAULT)
                    .map_err(|e| build_err(&e))?;
            Ok(Box::new(g))
        }
        BackendKind::Sdf => {
            let o = SdfOptions {
                memory_limit_bytes,
                ..sdf_options(&spec.options)?
            };
            let g = marchmesh_sdf::build(scene, &o).map_err(|e| build_err(&e))?;
            Ok(Box::new(g))
        }
        BackendKind::Mesh => {
            let o = MeshOptions {
                memory_limit_bytes,
                ..mesh_options(&spec.options)?
            };
            let g = marchmesh_mesh::build(scene, &o).map_err(|e| build_err(&e))?;
            Ok(Box::new(g))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    #[test]
    fn every_documented_key_parses_its_default_or_an_example() {
        for kind in [BackendKind::Sdf, BackendKind::Mesh] {
            for o in option_table(kind) {
                let d = default_value(kind, o.key).expect("every key has a default");
                let value = match (d.as_str(), o.ty) {
                    ("none", "float") => "0.01".to_string(),
                    ("none", "int") => "3".to_string(),
                    _ => d,
                };
                let spec = BackendSpec {
                    kind: Some(kind),
                    options: opts(&[(o.key, &value)]),
                };
                check_options(&spec).unwrap_or_else(|e| panic!("{kind} {}: {e}", o.key));
            }
        }
    }

    #[test]
    fn defaults_in_the_table_match_the_structs() {
        let all_defaults = |kind| -> Vec<(String, String)> {
            option_table(kind)
                .iter()
                .filter_map(|o| {
                    let d = default_value(kind, o.key)?;
                    (d != "none" || o.ty.contains("none")).then(|| (o.key.to_string(), d))
                })
                .collect()
        };
        assert_eq!(
            sdf_options(&all_defaults(BackendKind::Sdf)).unwrap(),
            SdfOptions::DEFAULT
        );
        assert_eq!(
            mesh_options(&all_defaults(BackendKind::Mesh)).unwrap(),
            MeshOptions::DEFAULT
        );
    }

    #[test]
    fn values_land_in_the_right_fields() {
        let s = sdf_options(&opts(&[
            ("eps_abs", "1e-4"),
            ("max_steps", "64"),
            ("relaxation", "1.5"),
            ("grid_res", "32"),
            ("max_distance", "100"),
            ("lockstep", "false"),
        ]))
        .unwrap();
        assert_eq!(s.hit_epsilon, HitEpsilon::Absolute(1e-4));
        assert_eq!(s.max_steps, 64);
        assert_eq!(s.relaxation, 1.5);
        assert_eq!(s.mesh_grid_resolution, 32);
        assert_eq!(s.max_distance, Some(100.0));
        assert!(!s.lockstep);
        // Issue 11 item 16: a preset given after an option no longer drops that option.
        let late = mesh_options(&opts(&[("bvh", "cwbvh"), ("preset", "fast")])).unwrap();
        assert_eq!(late.bvh, BvhKind::CwBvh);
        let m = mesh_options(&opts(&[
            ("preset", "fast"),
            ("bvh", "cwbvh"),
            ("build", "very_slow"),
            ("tess_level", "5"),
            ("surface_res", "48"),
            ("instancing", "false"),
        ]))
        .unwrap();
        assert_eq!(m.bvh, BvhKind::CwBvh);
        assert_eq!(m.build_quality, BuildQuality::VerySlow);
        assert_eq!(m.tessellation, Tessellation::FixedLevel(5));
        assert_eq!(m.surface_resolution, 48);
        assert!(!m.instancing);
        let later_wins = mesh_options(&opts(&[("tess_level", "5"), ("tess_px", "2")])).unwrap();
        assert_eq!(
            later_wins.tessellation,
            Tessellation::ScreenError { pixels: 2.0 }
        );
    }

    #[test]
    fn unknown_keys_name_backend_key_and_valid_keys() {
        let e = sdf_options(&opts(&[("epsilon", "0.1")]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("`sdf`") && e.contains("`epsilon`"), "{e}");
        assert!(e.contains("eps_abs") && e.contains("max_steps") && e.contains("grid_res"));
        let e = mesh_options(&opts(&[("tess", "1")]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("`mesh`") && e.contains("`tess`") && e.contains("tess_level"));
        let e = check_options(&BackendSpec {
            kind: Some(BackendKind::Reference),
            options: opts(&[("x", "1")]),
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains("`reference`") && e.contains("`x`"), "{e}");
    }

    #[test]
    fn bad_values_name_backend_key_and_value() {
        for (kind, k, v) in [
            (BackendKind::Sdf, "max_steps", "-3"),
            (BackendKind::Sdf, "eps_px", "nan"),
            (BackendKind::Sdf, "relaxation", "fast"),
            (BackendKind::Sdf, "lockstep", "maybe"),
            (BackendKind::Mesh, "bvh", "bvh4"),
            (BackendKind::Mesh, "build", "quick"),
            (BackendKind::Mesh, "tess_level", "1.5"),
            (BackendKind::Mesh, "preset", "best"),
        ] {
            let e = check_options(&BackendSpec {
                kind: Some(kind),
                options: opts(&[(k, v)]),
            })
            .unwrap_err()
            .to_string();
            assert!(
                e.contains(&format!("`{kind}`")) && e.contains(&format!("`{k}`")) && e.contains(v),
                "{e}"
            );
        }
    }

    #[test]
    fn parse_option_splits_on_the_first_equals() {
        assert_eq!(
            parse_option("cache_dir=a=b").unwrap(),
            ("cache_dir".to_string(), "a=b".to_string())
        );
        assert!(parse_option("=3").is_err());
        assert!(parse_option("novalue").is_err());
    }

    #[test]
    fn help_lists_every_key() {
        let h = option_help(BackendKind::Mesh);
        for o in option_table(BackendKind::Mesh) {
            assert!(h.contains(o.key));
        }
    }
}
