//! One place that knows every backend: build any of them for a scene from a name and
//! `key=value` options, as given on the command line or in a suite file.
//!
//! Each backend implements [`marchmesh_core::Backend`]: its options are a serde type in its
//! own crate whose field doc comments are the `--opt help` text ([`option_docs`], read from
//! the type's JSON Schema) and whose defaults are the backend's. `key=value` pairs become a
//! JSON object deserialized into that type ([`settings`]); unknown keys and unparsable values
//! are errors that name the backend, the key and the valid keys or the value. Range checks are
//! left to the backend's own build, whose errors name the field. The registry is generic over
//! the trait: a new backend is a [`BackendKind`] variant and one arm in each match below.

use std::fmt;
use std::str::FromStr;

use marchmesh_core::{Backend, DEFAULT_MEMORY_LIMIT_BYTES, Geometry};
use marchmesh_mesh::MeshBackend;
use marchmesh_reference::ReferenceBackend;
use marchmesh_scene::Scene;
use marchmesh_sdf::SdfBackend;

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
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BackendSpec {
    /// Which backend.
    pub kind: BackendKind,
    /// `key=value` options in the order given; later keys override earlier ones.
    pub options: Vec<(String, String)>,
}

/// Why a backend could not be built.
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    /// The name is not a backend.
    #[error("unknown backend `{0}` (expected one of: reference, sdf, mesh)")]
    UnknownBackend(String),
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

/// Parses `key=value`.
pub fn parse_option(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.trim().is_empty() => Ok((k.trim().to_string(), v.trim().to_string())),
        _ => Err(format!("`{s}` is not of the form key=value")),
    }
}

/// One option key of a backend, read from its settings type's JSON Schema.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OptionDoc {
    /// The key as written in `key=value`.
    pub key: String,
    /// The value type (`float`, `int`, `bool`, `text`, the accepted words, `|none` when it
    /// may be unset).
    pub ty: String,
    /// What it controls, with units (the field's doc comment).
    pub doc: String,
    /// The documented default, written as it would be parsed (`none` when unset).
    pub default: String,
}

/// The options of backend `B`, from its settings type: keys in alphabetical order.
pub fn option_docs<B: Backend>() -> Vec<OptionDoc> {
    let schema = serde_json::to_value(schemars::schema_for!(B::Settings)).unwrap_or_default();
    let defaults = serde_json::to_value(B::documented_defaults()).unwrap_or_default();
    let Some(props) = schema.get("properties").and_then(|p| p.as_object()) else {
        return Vec::new();
    };
    props
        .iter()
        .map(|(key, prop)| (key, prop, defaults.get(key)))
        .map(|(key, prop, default)| OptionDoc {
            key: key.clone(),
            // `none` is worth saying only where it is the default (elsewhere leaving the key
            // out keeps the default).
            ty: match default {
                None | Some(serde_json::Value::Null) => type_text(prop, &schema),
                Some(_) => type_text(prop, &schema).replace("|none", ""),
            },
            doc: prop
                .get("description")
                .and_then(|d| d.as_str())
                .unwrap_or_default()
                .replace('\n', " "),
            default: match default {
                None | Some(serde_json::Value::Null) => "none".into(),
                Some(serde_json::Value::String(s)) => s.clone(),
                Some(v) => v.to_string(),
            },
        })
        .collect()
}

/// The value type of a schema property as help text.
fn type_text(prop: &serde_json::Value, root: &serde_json::Value) -> String {
    let resolve = |v: &serde_json::Value| -> serde_json::Value {
        match v.get("$ref").and_then(|r| r.as_str()) {
            Some(r) => r
                .strip_prefix("#/")
                .map(|path| {
                    path.split('/')
                        .fold(root, |node, part| {
                            node.get(part).unwrap_or(&serde_json::Value::Null)
                        })
                        .clone()
                })
                .unwrap_or_default(),
            None => v.clone(),
        }
    };
    let mut words: Vec<String> = Vec::new();
    let mut add = |v: &serde_json::Value| {
        let v = resolve(v);
        if let Some(values) = v.get("enum").and_then(|e| e.as_array()) {
            words.extend(values.iter().filter_map(|x| x.as_str().map(str::to_string)));
        }
        if let Some(options) = v.get("oneOf").and_then(|e| e.as_array()) {
            words.extend(
                options
                    .iter()
                    .filter_map(|o| o.get("const").and_then(|c| c.as_str()).map(str::to_string)),
            );
        }
        let types = match v.get("type") {
            Some(serde_json::Value::String(t)) => vec![t.clone()],
            Some(serde_json::Value::Array(ts)) => ts
                .iter()
                .filter_map(|t| t.as_str().map(str::to_string))
                .collect(),
            _ => Vec::new(),
        };
        for t in types {
            words.push(
                match t.as_str() {
                    "number" => "float",
                    "integer" => "int",
                    "boolean" => "bool",
                    "string" => "text",
                    "null" => "none",
                    other => other,
                }
                .to_string(),
            );
        }
    };
    match prop.get("anyOf").and_then(|a| a.as_array()) {
        Some(alternatives) => alternatives.iter().for_each(&mut add),
        None => add(prop),
    }
    // "none" last: the value may be left unset.
    words.sort_by_key(|w| w == "none");
    words.dedup();
    words.join("|")
}

/// The options of `kind` as aligned text (for `--opt help`).
pub fn option_help(kind: BackendKind) -> String {
    let table = match kind {
        BackendKind::Reference => option_docs::<ReferenceBackend>(),
        BackendKind::Sdf => option_docs::<SdfBackend>(),
        BackendKind::Mesh => option_docs::<MeshBackend>(),
    };
    if table.is_empty() {
        return format!("backend `{kind}` has no options\n");
    }
    let kw = table.iter().map(|o| o.key.len()).max().unwrap_or(0);
    let tw = table.iter().map(|o| o.ty.len()).max().unwrap_or(0);
    let mut s = format!("options of backend `{kind}` (key=value):\n");
    for o in &table {
        s += &format!(
            "  {:kw$}  {:tw$}  default {:8}  {}\n",
            o.key, o.ty, o.default, o.doc
        );
    }
    s
}

/// A `key=value` value as JSON: `none`/`null` is null, `true`/`false` (and yes/no, on/off)
/// booleans, finite numbers numbers; anything else, and every value of a `text` key, a
/// string. The settings type then accepts or refuses it.
fn json_value(value: &str, text_key: bool) -> serde_json::Value {
    use serde_json::Value;
    if value.eq_ignore_ascii_case("none") || value == "null" {
        return Value::Null;
    }
    if text_key {
        return Value::String(value.to_string());
    }
    match value {
        "true" | "yes" | "on" => return Value::Bool(true),
        "false" | "no" | "off" => return Value::Bool(false),
        _ => {}
    }
    if let Ok(u) = value.parse::<u64>() {
        return Value::from(u);
    }
    if let Ok(i) = value.parse::<i64>() {
        return Value::from(i);
    }
    match value
        .parse::<f64>()
        .ok()
        .and_then(serde_json::Number::from_f64)
    {
        Some(n) => Value::Number(n),
        None => Value::String(value.to_string()),
    }
}

/// The settings of backend `B` from `key=value` pairs (a key given twice: the later wins).
///
/// Errors: [`BackendError::BadOption`] naming the backend and the key: an unknown key (with
/// the valid keys) or a value its field refuses (with the value).
pub fn settings<B: Backend>(
    kind: BackendKind,
    pairs: &[(String, String)],
) -> Result<B::Settings, BackendError> {
    let docs = option_docs::<B>();
    let mut map = serde_json::Map::new();
    for (key, value) in pairs {
        let Some(doc) = docs.iter().find(|d| &d.key == key) else {
            let keys: Vec<&str> = docs.iter().map(|d| d.key.as_str()).collect();
            return Err(bad(
                kind,
                key,
                if keys.is_empty() {
                    "unknown option; it has no options".into()
                } else {
                    format!("unknown option; valid keys: {}", keys.join(", "))
                },
            ));
        };
        let text_key = doc.ty.split('|').any(|t| t == "text");
        map.insert(key.clone(), json_value(value, text_key));
    }
    let value = serde_json::Value::Object(map);
    serde_path_to_error::deserialize::<_, B::Settings>(&value).map_err(|e| {
        let key = e.path().to_string();
        let given = pairs
            .iter()
            .rev()
            .find(|(k, _)| *k == key)
            .map_or(String::new(), |(_, v)| format!(" (given `{v}`)"));
        bad(kind, &key, format!("{}{given}", e.into_inner()))
    })
}

fn bad(kind: BackendKind, key: &str, reason: String) -> BackendError {
    BackendError::BadOption {
        backend: kind,
        key: key.to_string(),
        reason,
    }
}

/// Checks `spec`'s options without building anything (for validating suite files early):
/// unknown keys, unparsable values and inconsistent settings are errors.
pub fn check_options(spec: &BackendSpec) -> Result<(), BackendError> {
    let kind = spec.kind;
    let build_err = |e: &dyn fmt::Display| BackendError::BadOption {
        backend: kind,
        key: "options".into(),
        reason: e.to_string(),
    };
    match kind {
        BackendKind::Reference => settings::<ReferenceBackend>(kind, &spec.options).map(drop),
        BackendKind::Sdf => settings::<SdfBackend>(kind, &spec.options).map(drop),
        BackendKind::Mesh => settings::<MeshBackend>(kind, &spec.options)?
            .options()
            .map(drop)
            .map_err(|e| build_err(&e)),
    }
}

/// Builds `kind`'s geometry for `scene` from `key=value` options (default memory limit).
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
    let kind = spec.kind;
    match kind {
        BackendKind::Reference => {
            build_as::<ReferenceBackend>(kind, scene, &spec.options, memory_limit_bytes)
        }
        BackendKind::Sdf => build_as::<SdfBackend>(kind, scene, &spec.options, memory_limit_bytes),
        BackendKind::Mesh => {
            build_as::<MeshBackend>(kind, scene, &spec.options, memory_limit_bytes)
        }
    }
}

/// Parses `B`'s settings and builds it.
fn build_as<B: Backend>(
    kind: BackendKind,
    scene: &Scene,
    pairs: &[(String, String)],
    memory_limit_bytes: u64,
) -> Result<Box<dyn Geometry>, BackendError> {
    let settings = settings::<B>(kind, pairs)?;
    let geometry =
        B::build(scene, &settings, memory_limit_bytes).map_err(|e| BackendError::Build {
            backend: kind,
            reason: e.to_string(),
        })?;
    Ok(Box::new(geometry))
}

#[cfg(test)]
mod tests {
    use super::*;
    use marchmesh_mesh::{BuildQuality, BvhKind, MeshOptions, Tessellation};
    use marchmesh_sdf::{HitEpsilon, SdfOptions};

    fn opts(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    fn sdf(pairs: &[(&str, &str)]) -> Result<SdfOptions, BackendError> {
        settings::<SdfBackend>(BackendKind::Sdf, &opts(pairs)).map(|s| s.options())
    }

    fn mesh(pairs: &[(&str, &str)]) -> Result<MeshOptions, String> {
        settings::<MeshBackend>(BackendKind::Mesh, &opts(pairs))
            .map_err(|e| e.to_string())?
            .options()
            .map_err(|e| e.to_string())
    }

    /// Every key with its documented default, as `key=value` pairs.
    fn documented(kind: BackendKind, docs: Vec<OptionDoc>) -> Vec<(String, String)> {
        let pairs: Vec<(String, String)> = docs
            .into_iter()
            .filter(|d| d.default != "none")
            .map(|d| (d.key, d.default))
            .collect();
        assert!(!pairs.is_empty(), "{kind}");
        pairs
    }

    #[test]
    fn the_documented_defaults_parse_back_to_the_backends_defaults() {
        let s = documented(BackendKind::Sdf, option_docs::<SdfBackend>());
        let got = settings::<SdfBackend>(BackendKind::Sdf, &s).expect("defaults parse");
        assert_eq!(got.options(), SdfOptions::DEFAULT);
        let m = documented(BackendKind::Mesh, option_docs::<MeshBackend>());
        let got = settings::<MeshBackend>(BackendKind::Mesh, &m).expect("defaults parse");
        assert_eq!(got.options().expect("consistent"), MeshOptions::DEFAULT);
    }

    #[test]
    fn every_key_has_a_type_a_doc_and_accepts_an_example() {
        for (kind, docs) in [
            (BackendKind::Sdf, option_docs::<SdfBackend>()),
            (BackendKind::Mesh, option_docs::<MeshBackend>()),
        ] {
            for d in docs {
                assert!(!d.ty.is_empty() && !d.doc.is_empty(), "{kind} {d:?}");
                let example = match (d.default.as_str(), d.ty.split('|').next()) {
                    ("none", Some("float")) => "0.01".to_string(),
                    ("none", Some("int")) => "3".to_string(),
                    ("none", Some("text")) => "somewhere".to_string(),
                    (default, _) => default.to_string(),
                };
                let spec = BackendSpec {
                    kind,
                    options: opts(&[(&d.key, &example)]),
                };
                check_options(&spec).unwrap_or_else(|e| panic!("{kind} {}: {e}", d.key));
            }
        }
    }

    #[test]
    fn values_land_in_the_right_fields() {
        let s = sdf(&[
            ("eps_abs", "1e-4"),
            ("max_steps", "64"),
            ("relaxation", "1.5"),
            ("grid_res", "32"),
            ("max_distance", "100"),
            ("lockstep", "false"),
            ("cache_dir", "123"),
        ])
        .unwrap();
        assert_eq!(s.hit_epsilon, HitEpsilon::Absolute(1e-4));
        assert_eq!(s.max_steps, 64);
        assert_eq!(s.relaxation, 1.5);
        assert_eq!(s.mesh_grid_resolution, 32);
        assert_eq!(s.max_distance, Some(100.0));
        assert!(!s.lockstep);
        assert_eq!(
            s.cache_dir,
            Some("123".into()),
            "a path key keeps digits as text"
        );
        // Issue 11 item 16: a preset given after an option no longer drops that option.
        let late = mesh(&[("bvh", "cwbvh"), ("preset", "fast")]).unwrap();
        assert_eq!(late.bvh, BvhKind::CwBvh);
        let m = mesh(&[
            ("preset", "fast"),
            ("bvh", "cwbvh"),
            ("build", "very_slow"),
            ("tess_level", "5"),
            ("surface_res", "48"),
            ("instancing", "false"),
        ])
        .unwrap();
        assert_eq!(m.bvh, BvhKind::CwBvh);
        assert_eq!(m.build_quality, BuildQuality::VerySlow);
        assert_eq!(m.tessellation, Tessellation::FixedLevel(5));
        assert_eq!(m.surface_resolution, 48);
        assert!(!m.instancing);
        let e = mesh(&[("tess_level", "5"), ("tess_px", "2")]).unwrap_err();
        assert!(e.contains("one of tess_px, tess_chord, tess_level"), "{e}");
    }

    #[test]
    fn unknown_keys_name_backend_key_and_valid_keys() {
        let e = sdf(&[("epsilon", "0.1")]).unwrap_err().to_string();
        assert!(e.contains("`sdf`") && e.contains("`epsilon`"), "{e}");
        assert!(e.contains("eps_abs") && e.contains("max_steps") && e.contains("grid_res"));
        let e = mesh(&[("tess", "1")]).unwrap_err();
        assert!(e.contains("`mesh`") && e.contains("`tess`") && e.contains("tess_level"));
        let e = check_options(&BackendSpec {
            kind: BackendKind::Reference,
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
                kind,
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
    fn help_lists_every_key_with_its_type_and_default() {
        let h = option_help(BackendKind::Mesh);
        for d in option_docs::<MeshBackend>() {
            assert!(h.contains(&d.key), "{h}");
        }
        assert!(h.contains("bvh2|cwbvh|wide"), "{h}");
        assert!(h.contains("default wide"), "{h}");
        let h = option_help(BackendKind::Sdf);
        assert!(h.contains("eps_abs") && h.contains("float|none"), "{h}");
        assert!(
            h.contains("eps_px        float  "),
            "no |none where a default exists: {h}"
        );
        assert!(option_help(BackendKind::Reference).contains("has no options"));
    }
}
