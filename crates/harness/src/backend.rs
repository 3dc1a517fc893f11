//! One place that knows every backend: build any of them for a scene from a name and
//! `key=value` options, as given on the command line or in a suite file.

use std::fmt;
use std::str::FromStr;

use marchmesh_core::Geometry;
use marchmesh_scene::Scene;

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

/// Parses `key=value`.
pub fn parse_option(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.trim().is_empty() => Ok((k.trim().to_string(), v.trim().to_string())),
        _ => Err(format!("`{s}` is not of the form key=value")),
    }
}

/// Builds the backend named in `spec` for `scene`.
pub fn build(scene: &Scene, spec: &BackendSpec) -> Result<Box<dyn Geometry>, BackendError> {
    let kind = spec.kind.ok_or(BackendError::Missing)?;
    let build_err = |e: &dyn fmt::Display| BackendError::Build {
        backend: kind,
        reason: e.to_string(),
    };
    match kind {
        BackendKind::Reference | BackendKind::Sdf | BackendKind::Mesh => Err(BackendError::Build {
            backend: kind,
            reason: "not built into this binary yet".into(),
        }),
    }
}
