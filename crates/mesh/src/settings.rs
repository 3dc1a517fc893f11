//! The mesh backend's options as `key=value` data ([`MeshSettings`]) and its
//! [`marchmesh_core::Backend`] implementation ([`MeshBackend`]).
//!
//! The doc comment of each field is its `--opt help` line and its JSON Schema description;
//! the defaults come from the preset ([`MeshOptions::DEFAULT`] unless `preset` says
//! otherwise), whose fields document why they are what they are.

use marchmesh_scene::Scene;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::{BuildQuality, BvhKind, MeshError, MeshGeometry, MeshOptions, Tessellation};

/// A starting point for the other mesh options.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum MeshPreset {
    /// [`MeshOptions::fast`]: Bvh2, fast build, 1-pixel tessellation, 64-cell extraction.
    Fast,
    /// [`MeshOptions::DEFAULT`].
    #[default]
    Default,
    /// [`MeshOptions::quality`]: CwBvh, slow build, 0.1-pixel tessellation, 256 cells.
    Quality,
}

/// `key=value` options of the mesh backend; a key left out keeps the preset's value.
/// Unknown keys are refused.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct MeshSettings {
    /// Start from MeshOptions::fast()/DEFAULT/quality(); the other keys override it.
    pub preset: Option<MeshPreset>,
    /// BVH layout: binary, compressed 8-wide, or SIMD 8-wide converted from bvh2.
    pub bvh: Option<BvhKind>,
    /// BVH build preset: an obvhs preset, or tuned (medium, more reinsertion; the default).
    pub build: Option<BuildQuality>,
    /// Tessellation chord error on screen, pixels.
    pub tess_px: Option<f64>,
    /// Tessellation chord error, world units (instead of tess_px).
    pub tess_chord: Option<f64>,
    /// Fixed tessellation: 8*2^level segments per turn, <= 12 (instead of tess_px).
    pub tess_level: Option<u32>,
    /// Surface-nets cells on the longest side of CSG / smooth-union objects (8..=512).
    pub surface_res: Option<u32>,
    /// Trace 8 rays of a batch as one packet (bvh=wide, no instances).
    pub packets: Option<bool>,
    /// Instance repeated shapes under a TLAS (false = flatten into one BVH).
    pub instancing: Option<bool>,
    /// Largest instance count an infinite repetition may expand to.
    pub max_instances: Option<u64>,
    /// Cap on segments per full turn of any parametric direction (8..=65536).
    pub max_segments: Option<u32>,
}

impl MeshSettings {
    /// Every key set to what `o` uses (the tessellation key that `o` uses, the others none).
    pub fn of(o: &MeshOptions) -> MeshSettings {
        let (tess_px, tess_chord, tess_level) = match o.tessellation {
            Tessellation::ScreenError { pixels } => (Some(pixels), None, None),
            Tessellation::ChordError { world } => (None, Some(world), None),
            Tessellation::FixedLevel(l) => (None, None, Some(l)),
        };
        MeshSettings {
            preset: None,
            bvh: Some(o.bvh),
            build: Some(o.build_quality),
            tess_px,
            tess_chord,
            tess_level,
            surface_res: Some(o.surface_resolution),
            packets: Some(o.packets),
            instancing: Some(o.instancing),
            max_instances: Some(o.max_instances),
            max_segments: Some(o.max_segments_per_turn),
        }
    }

    /// The typed options: the preset with every given key applied (range checks happen in
    /// [`crate::build`]). Errors: more than one of tess_px, tess_chord, tess_level.
    pub fn options(&self) -> Result<MeshOptions, MeshError> {
        let mut o = match self.preset.unwrap_or_default() {
            MeshPreset::Fast => MeshOptions::fast(),
            MeshPreset::Default => MeshOptions::DEFAULT,
            MeshPreset::Quality => MeshOptions::quality(),
        };
        o.tessellation = match (self.tess_px, self.tess_chord, self.tess_level) {
            (None, None, None) => o.tessellation,
            (Some(pixels), None, None) => Tessellation::ScreenError { pixels },
            (None, Some(world), None) => Tessellation::ChordError { world },
            (None, None, Some(level)) => Tessellation::FixedLevel(level),
            _ => {
                return Err(MeshError::InvalidOption(
                    "give one of tess_px, tess_chord, tess_level".into(),
                ));
            }
        };
        o.bvh = self.bvh.unwrap_or(o.bvh);
        o.build_quality = self.build.unwrap_or(o.build_quality);
        o.surface_resolution = self.surface_res.unwrap_or(o.surface_resolution);
        o.packets = self.packets.unwrap_or(o.packets);
        o.instancing = self.instancing.unwrap_or(o.instancing);
        o.max_instances = self.max_instances.unwrap_or(o.max_instances);
        o.max_segments_per_turn = self.max_segments.unwrap_or(o.max_segments_per_turn);
        Ok(o)
    }
}

/// The mesh backend: triangles in obvhs BVHs.
#[derive(Debug, Clone, Copy, Default)]
pub struct MeshBackend;

impl marchmesh_core::Backend for MeshBackend {
    const NAME: &'static str = "mesh";
    type Settings = MeshSettings;
    type Error = MeshError;
    type Geometry = MeshGeometry;

    fn documented_defaults() -> MeshSettings {
        MeshSettings {
            preset: Some(MeshPreset::Default),
            ..MeshSettings::of(&MeshOptions::DEFAULT)
        }
    }

    fn build(
        scene: &Scene,
        settings: &MeshSettings,
        memory_limit_bytes: u64,
    ) -> Result<MeshGeometry, MeshError> {
        let options = MeshOptions {
            memory_limit_bytes,
            ..settings.options()?
        };
        crate::build(scene, &options)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_apply_first_and_keys_override_them() {
        assert_eq!(
            MeshSettings::default().options().expect("valid"),
            MeshOptions::DEFAULT
        );
        let s = MeshSettings {
            preset: Some(MeshPreset::Fast),
            bvh: Some(BvhKind::CwBvh),
            ..MeshSettings::default()
        };
        let o = s.options().expect("valid");
        assert_eq!(o.bvh, BvhKind::CwBvh);
        assert_eq!(o.surface_resolution, MeshOptions::fast().surface_resolution);
        assert_eq!(
            MeshSettings::of(&MeshOptions::quality())
                .options()
                .expect("valid"),
            MeshOptions::quality()
        );
        let both = MeshSettings {
            tess_px: Some(1.0),
            tess_level: Some(2),
            ..MeshSettings::default()
        };
        assert!(both.options().is_err());
    }
}
