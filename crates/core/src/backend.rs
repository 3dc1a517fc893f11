//! What every geometry backend is to the rest of the product: a name, its options as data and
//! a build from a scene.
//!
//! The options are one serde type per backend (`deny_unknown_fields`, every field defaulted):
//! its field doc comments become `--opt help` and the JSON Schema, `key=value` pairs on the
//! command line and in suite files deserialize into it, and it converts into the backend's own
//! typed options. So a key, its meaning and its default are written once, next to the code
//! that uses them, in the backend's crate. The registry in `marchmesh-harness` is generic over
//! this trait.

use std::fmt::Debug;

use marchmesh_scene::Scene;
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::Geometry;

/// A geometry backend.
pub trait Backend {
    /// The lower-case name used on the command line and in reports (`sdf`, `mesh`, ...).
    const NAME: &'static str;

    /// The backend's options as `key=value` data. `Default` is the documented default;
    /// unknown keys must be refused (`#[serde(deny_unknown_fields)]`).
    type Settings: Serialize + DeserializeOwned + schemars::JsonSchema + Default + Clone + Debug;

    /// Why a build failed (the message names the object, the file or the option).
    type Error: std::error::Error + Send + Sync + 'static;

    /// The built geometry.
    type Geometry: Geometry + 'static;

    /// Every key with its effective default value, for `--opt help` (e.g. keys that stand
    /// for a choice among alternatives show the one the defaults make).
    fn documented_defaults() -> Self::Settings {
        Self::Settings::default()
    }

    /// Builds `scene`. Errors: the settings are inconsistent or out of range, a file cannot
    /// be loaded, the scene uses something the backend cannot represent, or the estimated
    /// build memory exceeds `memory_limit_bytes` (refused before allocating).
    fn build(
        scene: &Scene,
        settings: &Self::Settings,
        memory_limit_bytes: u64,
    ) -> Result<Self::Geometry, Self::Error>;
}
