//! The mesh backend's [`marchmesh_core::Backend`] implementation ([`MeshBackend`]); its
//! settings are [`MeshOptions`].

use marchmesh_core::QualityKnob;
use marchmesh_scene::Scene;

use crate::{MAX_TESS_LEVEL, MeshError, MeshGeometry, MeshOptions, MeshPreset, Tessellation};

/// The mesh backend: triangles in obvhs BVHs.
#[derive(Debug, Clone, Copy, Default)]
pub struct MeshBackend;

impl marchmesh_core::Backend for MeshBackend {
    const NAME: &'static str = "mesh";
    type Settings = MeshOptions;
    type Error = MeshError;
    type Geometry = MeshGeometry;

    /// The default preset with every key it sets.
    fn documented_defaults() -> MeshOptions {
        MeshOptions {
            preset: Some(MeshPreset::Default),
            ..MeshPreset::Default.values()
        }
    }

    fn build(
        scene: &Scene,
        settings: &MeshOptions,
        memory_limit_bytes: u64,
    ) -> Result<MeshGeometry, MeshError> {
        let options = MeshOptions {
            memory_limit_bytes: Some(memory_limit_bytes),
            ..*settings
        };
        crate::build(scene, &options)
    }

    /// Refuses more than one of tess_px, tess_chord, tess_level.
    fn check(settings: &MeshOptions) -> Result<(), MeshError> {
        settings.tessellation().map(drop)
    }

    /// The tessellation budget the user chose: `tess_px` (pixels) or `tess_chord` (world
    /// units) halved per level, or `tess_level` raised by one per level within
    /// 0..=[`MAX_TESS_LEVEL`].
    fn quality_knob(settings: &MeshOptions) -> Result<Option<QualityKnob>, MeshError> {
        Ok(Some(match settings.tessellation()? {
            Tessellation::ScreenError { pixels } => QualityKnob::Halving {
                key: "tess_px",
                base: pixels,
            },
            Tessellation::ChordError { world } => QualityKnob::Halving {
                key: "tess_chord",
                base: world,
            },
            Tessellation::FixedLevel(level) => QualityKnob::Counting {
                key: "tess_level",
                base: i64::from(level),
                min: 0,
                max: i64::from(MAX_TESS_LEVEL),
            },
        }))
    }
}
