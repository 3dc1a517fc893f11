//! The sdf backend's options as `key=value` data ([`SdfSettings`]) and its
//! [`marchmesh_core::Backend`] implementation ([`SdfBackend`]).
//!
//! The doc comment of each field is its `--opt help` line and its JSON Schema description;
//! the defaults come from [`SdfOptions::DEFAULT`], whose fields document why they are what
//! they are.

use std::path::PathBuf;

use marchmesh_field::MeshGrid;
use marchmesh_field::bake::{Quantization, Reconstruction};
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
    /// Prune the field per region: octree of 2^prune_depth finest cells per axis, each cell
    /// holding only the nodes that matter in it (0 = off; pruned fields are not culled).
    pub prune_depth: u32,
    /// In lockstep batches, march one cone per run of four camera rays and start the rays
    /// where it stops (false: every ray from its origin).
    pub beams: bool,
    /// End rays that recede from every surface (convex leaves growing, other leaves' boxes
    /// behind) instead of marching them to the end of their range.
    pub recede: bool,
    /// Switch slowly progressing (grazing) rays to segment tracing with local directional
    /// Lipschitz bounds (false: plain sphere tracing throughout).
    pub segment: bool,
    /// Skip subtrees by their bounding boxes and clip rays to the scene box (false: every
    /// node at every step, the naive cost).
    pub bounds: bool,
    /// Cells on the longest side of baked mesh distance grids (effective resolution for
    /// sparse grids), 4..=512.
    pub grid_res: u32,
    /// Mesh distance grid: dense (n^3 f32 samples) or sparse (8^3-cell bricks only within
    /// `band` cells of the surface, memory ~ n^2).
    pub grid: GridKind,
    /// Sparse grids: band half-width in cells, 1..=16 (bricks where the surface comes this
    /// close; the field is at least this far elsewhere).
    pub band: u32,
    /// Sparse grids: sample storage, f32, u16 or u8 (error clamp/65535 or clamp/255, clamp
    /// = band + 1 cells).
    pub quantize: QuantizeKind,
    /// Sparse grids: interpolation, trilinear, tricubic (Catmull-Rom near the surface,
    /// C1 normals, the same 9^3 samples per brick, stencils read across brick faces) or
    /// normals (a stored normal per sample, 2 bytes more, blended tangent planes near the
    /// surface: follows flat facets).
    pub recon: ReconKind,
    /// Folder caching baked grids (none = no disk cache).
    pub cache_dir: Option<PathBuf>,
    /// Area-light soft shadows from one cone march per light (approximate) instead of
    /// sampled rays.
    pub cone_shadows: bool,
    /// Ambient occlusion from this many field taps along the normal (approximate); 0 =
    /// sampled rays.
    pub ao_taps: u32,
}

/// `grid=` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum GridKind {
    /// Dense trilinear grid.
    Dense,
    /// Sparse narrow-band brick grid.
    Sparse,
}

/// `quantize=` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum QuantizeKind {
    /// 32-bit floats.
    F32,
    /// 16 bits per sample.
    U16,
    /// 8 bits per sample.
    U8,
}

/// `recon=` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ReconKind {
    /// Trilinear.
    Trilinear,
    /// Tricubic Catmull-Rom near the surface.
    Tricubic,
    /// Gradient-corrected: stored per-sample normals (2 more bytes per sample), blended
    /// tangent planes near the surface.
    Normals,
}

impl Default for SdfSettings {
    fn default() -> Self {
        SdfSettings::of(&SdfOptions::DEFAULT)
    }
}

impl SdfSettings {
    /// The settings that give `o`.
    pub fn of(o: &SdfOptions) -> SdfSettings {
        let sparse = match (o.mesh_grid, MeshGrid::SPARSE_DEFAULT) {
            (
                MeshGrid::Sparse {
                    band_voxels,
                    quantization,
                    reconstruction,
                },
                _,
            )
            | (
                MeshGrid::Dense,
                MeshGrid::Sparse {
                    band_voxels,
                    quantization,
                    reconstruction,
                },
            ) => (band_voxels, quantization, reconstruction),
            (MeshGrid::Dense, MeshGrid::Dense) => (2, Quantization::F32, Reconstruction::Trilinear),
        };
        let (eps_px, eps_abs) = match o.hit_epsilon {
            HitEpsilon::PixelCone(k) => (k, None),
            HitEpsilon::Absolute(e) => (crate::options::DEFAULT_EPS_PX, Some(e)),
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
            prune_depth: o.prune_depth,
            beams: o.beams,
            recede: o.recede,
            segment: o.segment,
            bounds: o.bounds,
            grid_res: o.mesh_grid_resolution,
            grid: match o.mesh_grid {
                MeshGrid::Dense => GridKind::Dense,
                MeshGrid::Sparse { .. } => GridKind::Sparse,
            },
            band: sparse.0,
            quantize: match sparse.1 {
                Quantization::F32 => QuantizeKind::F32,
                Quantization::U16 => QuantizeKind::U16,
                Quantization::U8 => QuantizeKind::U8,
            },
            recon: match sparse.2 {
                Reconstruction::Trilinear => ReconKind::Trilinear,
                Reconstruction::Tricubic => ReconKind::Tricubic,
                Reconstruction::Normals => ReconKind::Normals,
            },
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
            prune_depth: self.prune_depth,
            beams: self.beams,
            recede: self.recede,
            segment: self.segment,
            bounds: self.bounds,
            mesh_grid_resolution: self.grid_res,
            mesh_grid: match self.grid {
                GridKind::Dense => MeshGrid::Dense,
                GridKind::Sparse => MeshGrid::Sparse {
                    band_voxels: self.band,
                    quantization: match self.quantize {
                        QuantizeKind::F32 => Quantization::F32,
                        QuantizeKind::U16 => Quantization::U16,
                        QuantizeKind::U8 => Quantization::U8,
                    },
                    reconstruction: match self.recon {
                        ReconKind::Trilinear => Reconstruction::Trilinear,
                        ReconKind::Tricubic => Reconstruction::Tricubic,
                        ReconKind::Normals => Reconstruction::Normals,
                    },
                },
            },
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
        let o = SdfOptions {
            mesh_grid: MeshGrid::Sparse {
                band_voxels: 3,
                quantization: Quantization::U8,
                reconstruction: Reconstruction::Tricubic,
            },
            mesh_grid_resolution: 200,
            ..SdfOptions::DEFAULT
        };
        assert_eq!(SdfSettings::of(&o).options(), o);
    }
}
