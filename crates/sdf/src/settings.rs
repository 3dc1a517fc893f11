//! The sdf backend's options as `key=value` data ([`SdfSettings`]) and its
//! [`marchmesh_core::Backend`] implementation ([`SdfBackend`]).
//!
//! The doc comment of each field is its `--opt help` line and its JSON Schema description;
//! the defaults come from [`SdfOptions::DEFAULT`], whose fields document why they are what
//! they are.

use std::path::PathBuf;

use marchmesh_scene::Scene;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::{HitEpsilon, SdfError, SdfGeometry, SdfOptions};

/// `key=value` options of the sdf backend. Unknown keys are refused.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SdfSettings {
    /// Hit epsilon as a fraction of the pixel footprint at the point (scale invariant).
    pub eps_px: f64,
    /// Absolute hit epsilon, world units; replaces eps_px when given.
    pub eps_abs: Option<f64>,
    /// Most field evaluations per ray; rays that run out count as misses.
    pub max_steps: u32,
    /// Longest ray, world units; none = the scene's render.max_distance.
    pub max_distance: Option<f64>,
    /// Over-relaxation factor in [1, 2) with overlap fallback (1 = off).
    pub relaxation: f64,
    /// Regula-falsi iterations pinning a hit onto the surface.
    pub refine_steps: u32,
    /// Central-difference normal step, fraction of the pixel footprint.
    pub normal_step: f64,
    /// Trace batches 8 rays in lockstep (same results).
    pub lockstep: bool,
    /// In lockstep batches, trace bundles of primary rays through only the objects their
    /// cone can reach (false: the whole field for every ray).
    pub cull: bool,
    /// Skip subtrees by their bounding boxes and clip rays to the scene box (false: every
    /// node at every step, the naive cost).
    pub bounds: bool,
    /// Cells on the longest side of baked mesh distance grids.
    pub grid_res: u32,
    /// Folder caching baked grids (none = no disk cache).
    pub cache_dir: Option<PathBuf>,
    /// Area-light soft shadows from one cone march per light (approximate) instead of
    /// sampled rays.
    pub cone_shadows: bool,
    /// Ambient occlusion from this many field taps along the normal (approximate); 0 =
    /// sampled rays.
    pub ao_taps: u32,
}

impl Default for SdfSettings {
    fn default() -> Self {
        SdfSettings::of(&SdfOptions::DEFAULT)
    }
}

impl SdfSettings {
    /// The settings that give `o`.
    pub fn of(o: &SdfOptions) -> SdfSettings {
        let (eps_px, eps_abs) = match o.hit_epsilon {
            HitEpsilon::PixelCone(k) => (k, None),
            HitEpsilon::Absolute(e) => (0.25, Some(e)),
        };
        SdfSettings {
            eps_px,
            eps_abs,
            max_steps: o.max_steps,
            max_distance: o.max_distance,
            relaxation: o.relaxation,
            refine_steps: o.refine_steps,
            normal_step: o.normal_step,
            lockstep: o.lockstep,
            cull: o.cull,
            bounds: o.bounds,
            grid_res: o.mesh_grid_resolution,
            cache_dir: o.cache_dir.clone(),
            cone_shadows: o.cone_shadows,
            ao_taps: o.ao_taps,
        }
    }

    /// The typed options these settings stand for (range checks happen in [`crate::build`]).
    pub fn options(&self) -> SdfOptions {
        SdfOptions {
            hit_epsilon: match self.eps_abs {
                Some(e) => HitEpsilon::Absolute(e),
                None => HitEpsilon::PixelCone(self.eps_px),
            },
            max_steps: self.max_steps,
            max_distance: self.max_distance,
            relaxation: self.relaxation,
            refine_steps: self.refine_steps,
            normal_step: self.normal_step,
            lockstep: self.lockstep,
            cull: self.cull,
            bounds: self.bounds,
            mesh_grid_resolution: self.grid_res,
            cache_dir: self.cache_dir.clone(),
            cone_shadows: self.cone_shadows,
            ao_taps: self.ao_taps,
            ..SdfOptions::DEFAULT
        }
    }
}

/// The sdf backend: sphere tracing a compiled signed distance field.
#[derive(Debug, Clone, Copy, Default)]
pub struct SdfBackend;

impl marchmesh_core::Backend for SdfBackend {
    const NAME: &'static str = "sdf";
    type Settings = SdfSettings;
    type Error = SdfError;
    type Geometry = SdfGeometry;

    fn build(
        scene: &Scene,
        settings: &SdfSettings,
        memory_limit_bytes: u64,
    ) -> Result<SdfGeometry, SdfError> {
        let options = SdfOptions {
            memory_limit_bytes,
            ..settings.options()
        };
        crate::build(scene, &options)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_and_options_round_trip() {
        assert_eq!(SdfSettings::default().options(), SdfOptions::DEFAULT);
        let o = SdfOptions {
            hit_epsilon: HitEpsilon::Absolute(1e-3),
            max_distance: Some(7.0),
            cache_dir: Some("grids".into()),
            ..SdfOptions::DEFAULT
        };
        assert_eq!(SdfSettings::of(&o).options(), o);
    }
}
