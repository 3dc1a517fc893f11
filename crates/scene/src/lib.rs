//! The marchmesh scene model.
//!
//! A scene is a JSON file ([`format`](mod@format)) that states only what it needs; [`load`] parses it,
//! checks every value ([`validate`]) and returns the resolved [`Scene`] that backends build
//! from. Errors name the file, the line and column (for syntax and type errors) and the JSON
//! path of the offending value. The format is described for users in `scenes/README.md`;
//! [`json_schema`] gives its machine-readable schema.

pub mod bounds;
pub mod deep;
pub mod format;
pub mod resolved;
mod strict;
pub mod validate;

use std::path::{Path, PathBuf};

pub use format::*;
pub use resolved::*;
pub use validate::Problem;

/// Why a scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{}: cannot read scene file: {source}", path.display())]
    Io {
        /// The scene file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The file is missing, not a regular file (a folder, device or FIFO) or larger than the
    /// read cap (`MARCHMESH_MAX_READ_MIB`).
    #[error("{}: cannot read scene file: {reason}", path.display())]
    Unreadable {
        /// The scene file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// The file is not UTF-8 text (UTF-16, NUL bytes, invalid sequences).
    #[error("{source_name}: {reason}")]
    Encoding {
        /// The scene file.
        source_name: String,
        /// What encoding problem was found.
        reason: String,
    },
    /// The JSON is malformed or a value has the wrong type or an unknown field.
    #[error(
        "{source_name}:{line}:{column}: at `{}`: {message}",
        validate::shown_path(json_path)
    )]
    Parse {
        /// The scene file (or `<string>`).
        source_name: String,
        /// 1-based line of the error.
        line: usize,
        /// 1-based column of the error.
        column: usize,
        /// JSON path of the value being read (`.` for the top level).
        json_path: String,
        /// serde's description.
        message: String,
    },
    /// The JSON is well formed but values are out of range or inconsistent.
    #[error("{source_name}: invalid scene:\n{}", problems.iter().map(|p| format!("  {p}")).collect::<Vec<_>>().join("\n"))]
    Invalid {
        /// The scene file (or `<string>`).
        source_name: String,
        /// Every problem found.
        problems: Vec<Problem>,
    },
}

/// Parses JSON text into the serde model, reporting the JSON path of any error.
pub fn parse_file_format(text: &str, source_name: &str) -> Result<SceneFile, SceneError> {
    if let Some((line, column)) = deep::too_deep(text, validate::MAX_JSON_DEPTH) {
        return Err(SceneError::Parse {
            source_name: source_name.to_string(),
            line,
            column,
            json_path: ".".into(),
            message: format!(
                "JSON nests deeper than {} levels (objects nest at most {} levels)",
                validate::MAX_JSON_DEPTH,
                validate::MAX_NESTING_DEPTH
            ),
        });
    }
    let mut de = serde_json::Deserializer::from_str(text);
    // The depth was checked above; each level of the recursive descent runs on a stack
    // that `deep::guard` grows, whatever the thread.
    de.disable_recursion_limit();
    let stacked = serde_stacker::Deserializer {
        de: &mut de,
        red_zone: deep::RED_ZONE,
        stack_size: deep::STACK_SEGMENT,
    };
    let parsed: Result<SceneFile, _> = serde_path_to_error::deserialize(strict::Strict(stacked));
    let file = parsed.map_err(|e| {
        let json_path = e.path().to_string();
        let inner = e.into_inner();
        SceneError::Parse {
            source_name: source_name.to_string(),
            line: inner.line(),
            column: inner.column(),
            json_path,
            message: strip_position(&inner.to_string()),
        }
    })?;
    // Trailing characters after the document.
    de.end().map_err(|e| SceneError::Parse {
        source_name: source_name.to_string(),
        line: e.line(),
        column: e.column(),
        json_path: ".".into(),
        message: strip_position(&e.to_string()),
    })?;
    Ok(file)
}

fn strip_position(msg: &str) -> String {
    match msg.rfind(" at line ") {
        Some(i) => msg[..i].to_string(),
        None => msg.to_string(),
    }
}

/// Parses and validates scene JSON. Relative mesh and image paths resolve against `base_dir`.
pub fn parse_scene(text: &str, source_name: &str, base_dir: &Path) -> Result<Scene, SceneError> {
    let file = parse_file_format(text, source_name)?;
    validate::resolve(&file, base_dir, source_name).map_err(|problems| SceneError::Invalid {
        source_name: source_name.to_string(),
        problems,
    })
}

/// Largest scene file [`load`] reads: 64 MiB, room for [`validate::MAX_NODES`] objects of
/// several hundred bytes each; a larger file is refused before it is parsed.
pub const MAX_SCENE_FILE_BYTES: u64 = 64 << 20;

/// Reads, parses and validates a scene file (a regular file of at most
/// [`MAX_SCENE_FILE_BYTES`] and the `MARCHMESH_MAX_READ_MIB` cap).
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let bytes = marchmesh_safeio::read_regular_within(path, MAX_SCENE_FILE_BYTES).map_err(|e| {
        SceneError::Unreadable {
            path: path.to_path_buf(),
            reason: match e {
                marchmesh_safeio::SafeIoError::Io { source, .. } => source.to_string(),
                other => {
                    let text = other.to_string();
                    let prefix = format!("{}: ", path.display());
                    text.strip_prefix(&prefix).unwrap_or(&text).to_string()
                }
            },
        }
    })?;
    let source_name = path.display().to_string();
    let text = decode_text(&bytes, &source_name)?;
    let base = path.parent().unwrap_or(Path::new("."));
    parse_scene(text, &source_name, base)
}

/// The scene text of `bytes`: UTF-8, with a leading UTF-8 byte-order mark skipped. UTF-16
/// (either byte order, detected by its BOM or by NUL bytes) and other non-UTF-8 text is an
/// error saying so, instead of a JSON syntax error.
pub fn decode_text<'a>(bytes: &'a [u8], source_name: &str) -> Result<&'a str, SceneError> {
    let encoding = |what: &str| SceneError::Encoding {
        source_name: source_name.to_string(),
        reason: what.to_string(),
    };
    if bytes.starts_with(&[0xFF, 0xFE]) || bytes.starts_with(&[0xFE, 0xFF]) || bytes.contains(&0) {
        return Err(encoding(
            "the file is UTF-16 (or contains NUL bytes); save it as UTF-8",
        ));
    }
    let bytes = bytes.strip_prefix(&[0xEF, 0xBB, 0xBF]).unwrap_or(bytes);
    std::str::from_utf8(bytes).map_err(|e| {
        encoding(&format!(
            "not valid UTF-8 (byte offset {}); save it as UTF-8",
            e.valid_up_to()
        ))
    })
}

/// The JSON Schema of the scene format, pretty-printed.
pub fn json_schema() -> String {
    let schema = schemars::schema_for!(SceneFile);
    serde_json::to_string_pretty(&schema).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
}
