//! The sdf backend's [`marchmesh_core::Backend`] implementation ([`SdfBackend`]); its
//! settings are [`SdfOptions`].

use marchmesh_core::QualityKnob;
use marchmesh_scene::Scene;

use crate::{HitEpsilon, SdfError, SdfGeometry, SdfOptions};

/// The sdf backend: sphere tracing a compiled signed distance field.
#[derive(Debug, Clone, Copy, Default)]
pub struct SdfBackend;

impl marchmesh_core::Backend for SdfBackend {
    const NAME: &'static str = "sdf";
    type Settings = SdfOptions;
    type Error = SdfError;
    type Geometry = SdfGeometry;

    fn build(
        scene: &Scene,
        settings: &SdfOptions,
        memory_limit_bytes: u64,
    ) -> Result<SdfGeometry, SdfError> {
        let options = SdfOptions {
            memory_limit_bytes,
            ..settings.clone()
        };
        crate::build(scene, &options)
    }

    /// Every range that needs no scene ([`crate::check_options`]), so a suite with an
    /// out-of-range option fails when loaded.
    fn check(settings: &SdfOptions) -> Result<(), SdfError> {
        crate::check_options(settings)
    }

    /// The hit epsilon: `eps_abs` when given, else `eps_px`.
    fn quality_knob(settings: &SdfOptions) -> Result<Option<QualityKnob>, SdfError> {
        Ok(Some(match settings.hit_epsilon() {
            HitEpsilon::PixelCone(k) => QualityKnob::Halving {
                key: "eps_px",
                base: k,
            },
            HitEpsilon::Absolute(e) => QualityKnob::Halving {
                key: "eps_abs",
                base: e,
            },
        }))
    }
}
