//! The one list of geometry backends, and everything built on it: any backend from a name
//! and `key=value` options, as given on the command line or in a suite file.
//!
//! Each backend implements [`marchmesh_core::Backend`]: its options are a serde type in its
//! own crate whose field doc comments are the `--opt help` text ([`option_docs`], read from
//! the type's JSON Schema) and whose defaults are the backend's. `key=value` pairs become a
//! JSON object deserialized into that type ([`settings`]); unknown keys and unparsable values
//! are errors that name the backend, the key and the valid keys or the value. Range checks are
//! left to the backend's own build, whose errors name the field.
//!
//! The registry is [`ENTRIES`]: one line per backend type. Everything else (names, help,
//! schema, building, the viewer's quality knob, which backend is the ground truth) is read
//! from the trait through a [`BackendId`], so a new backend is its crate, a dependency here
//! and one line in [`ENTRIES`]. A crate of its own (not a module of `marchmesh-harness`) so
//! the viewer and the stability study get the backends without the harness's runner,
//! results and reports.

use std::fmt;
use std::str::FromStr;

use marchmesh_core::{Backend, DEFAULT_MEMORY_LIMIT_BYTES, Geometry, QualityKnob};
use marchmesh_scene::Scene;

/// Every backend, in report order (the ground truth first; plots colour a backend by its
/// place here). Adding a backend: its crate as a dependency of this one and one line here.
pub const ENTRIES: &[Entry] = &[
    Entry::of::<marchmesh_reference::ReferenceBackend>(),
    Entry::of::<marchmesh_sdf::SdfBackend>(),
    Entry::of::<marchmesh_mesh::MeshBackend>(),
];

/// How many backends there are.
pub const COUNT: usize = ENTRIES.len();

/// One registered backend: its trait's items as data, so the rest of the product can hold
/// "a backend" without naming its type.
#[derive(Clone, Copy)]
pub struct Entry {
    /// [`Backend::NAME`].
    pub name: &'static str,
    /// [`Backend::GROUND_TRUTH`].
    pub ground_truth: bool,
    option_docs: fn() -> Vec<OptionDoc>,
    schema: fn() -> serde_json::Value,
    check: fn(BackendId, &[Pair]) -> Result<(), BackendError>,
    quality_knob: fn(BackendId, &[Pair]) -> Result<Option<QualityKnob>, BackendError>,
    build: BuildFn,
}

/// One `key=value` option.
type Pair = (String, String);

/// Builds a backend's geometry from `key=value` options within a memory limit in bytes.
type BuildFn = fn(BackendId, &Scene, &[Pair], u64) -> Result<Box<dyn Geometry>, BackendError>;

impl Entry {
    /// The entry of backend `B`.
    pub const fn of<B: Backend>() -> Entry {
        Entry {
            name: B::NAME,
            ground_truth: B::GROUND_TRUTH,
            option_docs: option_docs::<B>,
            schema: schema::<B>,
            check: check_as::<B>,
            quality_knob: quality_knob_as::<B>,
            build: build_as::<B>,
        }
    }
}

/// A registered backend: an index into [`ENTRIES`], ordered as they are.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BackendId(u8);

const fn same(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

impl BackendId {
    /// Every backend, in [`ENTRIES`] order.
    pub const ALL: [BackendId; COUNT] = {
        let mut all = [BackendId(0); COUNT];
        let mut i = 0;
        while i < COUNT {
            all[i] = BackendId(i as u8);
            i += 1;
        }
        all
    };

    /// The ground truth ([`Backend::GROUND_TRUTH`]); a compile error unless exactly one
    /// registered backend is.
    pub const REFERENCE: BackendId = {
        let mut found = None;
        let mut i = 0;
        while i < COUNT {
            if ENTRIES[i].ground_truth {
                assert!(found.is_none(), "two backends claim to be the ground truth");
                found = Some(BackendId(i as u8));
            }
            i += 1;
        }
        match found {
            Some(id) => id,
            None => panic!("no backend is the ground truth"),
        }
    };

    /// Backend `B`'s id. Panics (a compile error in a `const`) when `B` is not registered.
    pub const fn of<B: Backend>() -> BackendId {
        let mut i = 0;
        while i < COUNT {
            if same(ENTRIES[i].name, B::NAME) {
                return BackendId(i as u8);
            }
            i += 1;
        }
        panic!("backend not registered in marchmesh_registry::ENTRIES")
    }

    /// Its entry.
    pub const fn entry(self) -> &'static Entry {
        &ENTRIES[self.0 as usize]
    }

    /// Its place in [`ENTRIES`] (and [`BackendId::ALL`]).
    pub const fn index(self) -> usize {
        self.0 as usize
    }

    /// The lower-case name used on the command line and in reports.
    pub const fn name(self) -> &'static str {
        self.entry().name
    }

    /// Whether it is the ground truth.
    pub const fn is_ground_truth(self) -> bool {
        self.entry().ground_truth
    }

    /// Its options as `--opt help` rows ([`option_docs`]).
    pub fn option_docs(self) -> Vec<OptionDoc> {
        (self.entry().option_docs)()
    }

    /// The JSON Schema of its settings type (what suite files and `--opt` accept).
    pub fn schema(self) -> serde_json::Value {
        (self.entry().schema)()
    }

    /// Its quality knob given the user's `key=value` options ([`Backend::quality_knob`]);
    /// `None`: it has none. Errors: the options do not parse or are inconsistent.
    pub fn quality_knob(
        self,
        pairs: &[(String, String)],
    ) -> Result<Option<QualityKnob>, BackendError> {
        (self.entry().quality_knob)(self, pairs)
    }

    /// Whether it has a quality knob at its default settings.
    pub fn has_quality_knob(self) -> bool {
        self.quality_knob(&[]).is_ok_and(|k| k.is_some())
    }
}

impl fmt::Display for BackendId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl fmt::Debug for BackendId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for BackendId {
    type Err = BackendError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        BackendId::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| BackendError::UnknownBackend(s.to_string()))
    }
}

/// The names of every backend, comma-separated (for error messages).
fn names() -> String {
    BackendId::ALL.map(BackendId::name).join(", ")
}

/// A backend and its options.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BackendSpec {
    /// Which backend.
    pub kind: BackendId,
    /// `key=value` options in the order given; later keys override earlier ones.
    pub options: Vec<(String, String)>,
}

/// Why a backend could not be built.
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    /// The name is not a backend.
    #[error("unknown backend `{0}` (expected one of: {names})", names = names())]
    UnknownBackend(String),
    /// An option key the backend does not have, or a value it cannot parse.
    #[error("backend `{backend}`: option `{key}`: {reason}")]
    BadOption {
        /// The backend.
        backend: BackendId,
        /// The option key.
        key: String,
        /// Why it was rejected (lists the valid keys for unknown ones).
        reason: String,
    },
    /// The backend failed to build (bad mesh file, scene it cannot represent, ...).
    #[error("backend `{backend}` failed to build the scene: {reason}")]
    Build {
        /// The backend.
        backend: BackendId,
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
    /// What it controls, with units (the first paragraph of the field's doc comment).
    pub doc: String,
    /// The documented default, written as it would be parsed (`none` when unset).
    pub default: String,
}

/// The options of backend `B`, from its settings type: keys in alphabetical order.
pub fn option_docs<B: Backend>() -> Vec<OptionDoc> {
    let schema = schema::<B>();
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
            // The first paragraph: the rest of a field's doc comment says why the default is
            // what it is, for the schema and the API docs.
            doc: prop
                .get("description")
                .and_then(|d| d.as_str())
                .unwrap_or_default()
                .split("\n\n")
                .next()
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

/// The JSON Schema of `B`'s settings type.
fn schema<B: Backend>() -> serde_json::Value {
    serde_json::to_value(schemars::schema_for!(B::Settings)).unwrap_or_default()
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
pub fn option_help(kind: BackendId) -> String {
    let table = kind.option_docs();
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
    kind: BackendId,
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

fn bad(kind: BackendId, key: &str, reason: String) -> BackendError {
    BackendError::BadOption {
        backend: kind,
        key: key.to_string(),
        reason,
    }
}

/// Checks `spec`'s options without building anything (for validating suite files early):
/// unknown keys, unparsable values and inconsistent settings ([`Backend::check`]) are errors.
pub fn check_options(spec: &BackendSpec) -> Result<(), BackendError> {
    (spec.kind.entry().check)(spec.kind, &spec.options)
}

/// `B`'s settings from `pairs`, checked ([`Backend::check`]).
fn check_as<B: Backend>(kind: BackendId, pairs: &[(String, String)]) -> Result<(), BackendError> {
    let settings = settings::<B>(kind, pairs)?;
    B::check(&settings).map_err(|e| inconsistent(kind, &e))
}

/// `B`'s quality knob at the settings `pairs` give.
fn quality_knob_as<B: Backend>(
    kind: BackendId,
    pairs: &[(String, String)],
) -> Result<Option<QualityKnob>, BackendError> {
    let settings = settings::<B>(kind, pairs)?;
    B::quality_knob(&settings).map_err(|e| inconsistent(kind, &e))
}

/// Settings that parsed but contradict each other.
fn inconsistent(kind: BackendId, e: &dyn fmt::Display) -> BackendError {
    BackendError::BadOption {
        backend: kind,
        key: "options".into(),
        reason: e.to_string(),
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
    (spec.kind.entry().build)(spec.kind, scene, &spec.options, memory_limit_bytes)
}

/// Parses `B`'s settings and builds it.
fn build_as<B: Backend>(
    kind: BackendId,
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
    use marchmesh_mesh::{
        BuildQuality, BvhKind, Extraction, MeshBackend, MeshOptions, Tessellation,
    };
    use marchmesh_reference::ReferenceBackend;
    use marchmesh_sdf::{HitEpsilon, SdfBackend, SdfOptions};

    const SDF: BackendId = BackendId::of::<SdfBackend>();
    const MESH: BackendId = BackendId::of::<MeshBackend>();

    fn opts(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    fn sdf(pairs: &[(&str, &str)]) -> Result<SdfOptions, BackendError> {
        settings::<SdfBackend>(SDF, &opts(pairs))
    }

    fn mesh(pairs: &[(&str, &str)]) -> Result<MeshOptions, String> {
        let o = settings::<MeshBackend>(MESH, &opts(pairs)).map_err(|e| e.to_string())?;
        o.tessellation().map_err(|e| e.to_string())?;
        Ok(o)
    }

    /// Every value the mesh build reads from `o`.
    fn resolved(o: &MeshOptions) -> impl PartialEq + std::fmt::Debug {
        (
            (
                o.bvh(),
                o.build_quality(),
                o.tessellation().expect("consistent"),
            ),
            (
                o.extraction().expect("consistent"),
                o.packets(),
                o.instancing(),
            ),
            (
                o.max_instances(),
                o.max_segments_per_turn(),
                o.memory_limit_bytes,
            ),
        )
    }

    /// Every key with its documented default, as `key=value` pairs.
    fn documented(kind: BackendId, docs: Vec<OptionDoc>) -> Vec<(String, String)> {
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
        let s = documented(SDF, option_docs::<SdfBackend>());
        let got = settings::<SdfBackend>(SDF, &s).expect("defaults parse");
        assert_eq!(got, SdfOptions::DEFAULT);
        let m = documented(MESH, option_docs::<MeshBackend>());
        let got = settings::<MeshBackend>(MESH, &m).expect("defaults parse");
        let defaults = MeshOptions::default();
        assert_eq!(resolved(&got), resolved(&defaults));
    }

    #[test]
    fn every_key_has_a_type_a_doc_and_accepts_an_example() {
        for (kind, docs) in [
            (SDF, option_docs::<SdfBackend>()),
            (MESH, option_docs::<MeshBackend>()),
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
        assert_eq!(s.hit_epsilon(), HitEpsilon::Absolute(1e-4));
        assert_eq!(s.max_steps, 64);
        assert_eq!(s.relaxation, 1.5);
        assert_eq!(s.grid_res, 32);
        assert_eq!(s.max_distance, Some(100.0));
        assert!(!s.lockstep);
        assert_eq!(
            s.cache_dir,
            Some("123".into()),
            "a path key keeps digits as text"
        );
        // A preset given after an option no longer drops that option.
        let late = mesh(&[("bvh", "cwbvh"), ("preset", "fast")]).unwrap();
        assert_eq!(late.bvh(), BvhKind::CwBvh);
        let m = mesh(&[
            ("preset", "fast"),
            ("bvh", "cwbvh"),
            ("build", "very_slow"),
            ("tess_level", "5"),
            ("surface_res", "48"),
            ("instancing", "false"),
        ])
        .unwrap();
        assert_eq!(m.bvh(), BvhKind::CwBvh);
        assert_eq!(m.build_quality(), BuildQuality::VerySlow);
        assert_eq!(m.tessellation().ok(), Some(Tessellation::FixedLevel(5)));
        assert_eq!(m.extraction().ok(), Some(Extraction::Cells(48)));
        assert!(!m.instancing());
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
            kind: BackendId::REFERENCE,
            options: opts(&[("x", "1")]),
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains("`reference`") && e.contains("`x`"), "{e}");
    }

    #[test]
    fn bad_values_name_backend_key_and_value() {
        for (kind, k, v) in [
            (SDF, "max_steps", "-3"),
            (SDF, "eps_px", "nan"),
            (SDF, "relaxation", "fast"),
            (SDF, "lockstep", "maybe"),
            (MESH, "bvh", "bvh4"),
            (MESH, "build", "quick"),
            (MESH, "tess_level", "1.5"),
            (MESH, "preset", "best"),
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
    fn ids_name_their_types_in_list_order_with_one_ground_truth() {
        assert_eq!(BackendId::REFERENCE, BackendId::of::<ReferenceBackend>());
        assert_eq!(
            BackendId::ALL.map(BackendId::name),
            [ReferenceBackend::NAME, SdfBackend::NAME, MeshBackend::NAME]
        );
        for id in BackendId::ALL {
            assert_eq!(id.name().parse::<BackendId>().expect("parses"), id);
            assert_eq!(id.is_ground_truth(), id == BackendId::REFERENCE, "{id}");
            assert_eq!(id.has_quality_knob(), !id.is_ground_truth(), "{id}");
            assert!(id.schema().get("properties").is_some() || id.option_docs().is_empty());
        }
        let e = "voxels".parse::<BackendId>().unwrap_err().to_string();
        assert!(
            e.contains("`voxels`") && e.contains("reference, sdf, mesh"),
            "{e}"
        );
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
        let h = option_help(MESH);
        for d in option_docs::<MeshBackend>() {
            assert!(h.contains(&d.key), "{h}");
        }
        assert!(h.contains("bvh2|cwbvh|wide"), "{h}");
        assert!(h.contains("default wide"), "{h}");
        let h = option_help(SDF);
        assert!(h.contains("eps_abs") && h.contains("float|none"), "{h}");
        assert!(
            h.contains("eps_px        float  "),
            "no |none where a default exists: {h}"
        );
        assert!(option_help(BackendId::REFERENCE).contains("has no options"));
    }
}
