//! What every geometry backend is to the rest of the product: a name, its options as data and
//! a build from a scene.
//!
//! The options are one serde type per backend (`deny_unknown_fields`, every field defaulted):
//! its field doc comments become `--opt help` and the JSON Schema, `key=value` pairs on the
//! command line and in suite files deserialize into it, and it converts into the backend's own
//! typed options. So a key, its meaning and its default are written once, next to the code
//! that uses them, in the backend's crate. The registry (`marchmesh-registry`) holds one list of
//! the types implementing this trait; everything it says about a backend (its name, `--opt
//! help`, the schema, whether it is the ground truth, the viewer's quality knob) comes from
//! here.

use std::fmt::Debug;

use marchmesh_scene::Scene;
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::Geometry;

/// A geometry backend.
pub trait Backend {
    /// The lower-case name used on the command line and in reports (`sdf`, `mesh`, ...).
    /// Written once: the backend's own report and errors read it from here.
    const NAME: &'static str;

    /// Whether this is the exact reference every accuracy is measured against (the viewer's
    /// accuracy overlay, the benchmarks' and the stability study's ground truth). Exactly one
    /// registered backend says yes; the registry's tests check it.
    const GROUND_TRUTH: bool = false;

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

    /// Checks `settings` for inconsistencies that need no scene (e.g. two keys that exclude
    /// each other), so suite files fail before anything is built. The default accepts
    /// everything serde accepted; range checks may wait for [`Backend::build`].
    fn check(settings: &Self::Settings) -> Result<(), Self::Error> {
        let _ = settings;
        Ok(())
    }

    /// The one option the viewer's `+`/`-` keys scale, given the user's `settings` (e.g. the
    /// hit epsilon the user chose: absolute if they gave one, else the pixel one). `None`
    /// (the default): no knob, e.g. an exact backend. Errors: as [`Backend::check`].
    fn quality_knob(settings: &Self::Settings) -> Result<Option<QualityKnob>, Self::Error> {
        let _ = settings;
        Ok(None)
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

/// A backend's quality knob: one `key=value` option that quality level `q` sets (level 0 is
/// the value the user's settings give).
#[derive(Debug, Clone, PartialEq)]
pub enum QualityKnob {
    /// An option whose value is divided by `2^q` (an error budget: higher quality, smaller).
    Halving {
        /// The option key (its unit is the key's: `_px` pixels, otherwise world units).
        key: &'static str,
        /// Its value at level 0.
        base: f64,
    },
    /// An integer option that gains `q`, clamped to `min..=max` (a subdivision level).
    Counting {
        /// The option key.
        key: &'static str,
        /// Its value at level 0.
        base: i64,
        /// Smallest value set.
        min: i64,
        /// Largest value set.
        max: i64,
    },
}

impl QualityKnob {
    /// The `key=value` option that sets the knob to `level`.
    pub fn option(&self, level: i32) -> (String, String) {
        match *self {
            QualityKnob::Halving { key, base } => {
                (key.to_string(), format!("{}", base * 2f64.powi(-level)))
            }
            QualityKnob::Counting {
                key,
                base,
                min,
                max,
            } => (
                key.to_string(),
                (base + i64::from(level)).clamp(min, max).to_string(),
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knobs_halve_or_count_within_their_range() {
        let k = QualityKnob::Halving {
            key: "eps_px",
            base: 0.05,
        };
        assert_eq!(k.option(1), ("eps_px".into(), "0.025".into()));
        assert_eq!(k.option(-2), ("eps_px".into(), "0.2".into()));
        let k = QualityKnob::Counting {
            key: "tess_level",
            base: 3,
            min: 0,
            max: 12,
        };
        assert_eq!(k.option(2), ("tess_level".into(), "5".into()));
        assert_eq!(k.option(-9), ("tess_level".into(), "0".into()));
        assert_eq!(k.option(20), ("tess_level".into(), "12".into()));
    }
}
