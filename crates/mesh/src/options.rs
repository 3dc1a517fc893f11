//! Build options of the mesh backend: BVH kind and build preset, tessellation budget,
//! surface-extraction resolution, instancing.

use obvhs::BvhBuildParams;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Which obvhs BVH layout the triangles are traversed in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum BvhKind {
    /// Binary BVH (`obvhs::bvh2::Bvh2`), 48-byte nodes, up to 8 triangles per leaf (per preset).
    Bvh2,
    /// Compressed 8-wide BVH (`obvhs::cwbvh::CwBvh`, Ylitie et al. 2017), 80-byte nodes,
    /// SIMD node tests, up to 3 triangles per leaf.
    CwBvh,
    /// 8-wide BVH converted from the Bvh2 build (`crate::wide`): 224-byte nodes with SoA
    /// child boxes tested 8 at a time (AVX, runtime-detected, portable fallback), triangles
    /// in SoA blocks of 4 tested with SSE; same hits as [`BvhKind::Bvh2`]. Its Bvh2 build
    /// caps leaves at 4 triangles (one block), whatever the preset says.
    Wide,
}

/// obvhs build presets (`BvhBuildParams::*_build()`, and one of our own), from fastest build
/// to best traversal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum BuildQuality {
    /// `fastest_build`: PLOC with minimal search, no reinsertion, one triangle per leaf.
    Fastest,
    /// `very_fast_build`.
    VeryFast,
    /// `fast_build`.
    Fast,
    /// `medium_build`: about Embree's build time with faster traversal.
    Medium,
    /// `medium_build` with a better tree for more build time (the default): the first PLOC
    /// pass pairs nearest neighbours only (`search_depth_threshold: 1`) and reinsertion
    /// (Meister and Bittner 2018, "Parallel Reinsertion for Bounding Volume Hierarchy
    /// Optimization") visits half the nodes instead of 5% (`reinsertion_batch_ratio: 0.5`).
    /// The wide BVH had 11% fewer bytes per triangle and its single rays ran 1.14-1.15x
    /// (dragon_res3), 1.05x (bunny) and 1.02-1.06x (871k dragon) as fast as with `Medium`
    /// (`anchor_rays`, 5-7 interleaved rounds, load 1.2-1.9), for 2.3-2.8x the build time
    /// (871k dragon, 1 thread: 2.7 s against 1.0-1.2 s).
    Tuned,
    /// `slow_build`: spatial pre-splits, wider PLOC search.
    Slow,
    /// `very_slow_build`: full reinsertion pass.
    VerySlow,
}

impl BuildQuality {
    /// The obvhs parameters of this preset.
    pub const fn params(self) -> BvhBuildParams {
        match self {
            Self::Fastest => BvhBuildParams::fastest_build(),
            Self::VeryFast => BvhBuildParams::very_fast_build(),
            Self::Fast => BvhBuildParams::fast_build(),
            Self::Medium => BvhBuildParams::medium_build(),
            Self::Tuned => BvhBuildParams {
                search_depth_threshold: 1,
                reinsertion_batch_ratio: 0.5,
                ..BvhBuildParams::medium_build()
            },
            Self::Slow => BvhBuildParams::slow_build(),
            Self::VerySlow => BvhBuildParams::very_slow_build(),
        }
    }
}

/// How finely analytic shapes are tessellated.
///
/// The chord error is the largest distance between the exact surface and its triangles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tessellation {
    /// Chord error, projected on screen from the shape's nearest distance to the camera,
    /// stays below `pixels` pixels: world error `pixels * camera.pixel_angle() * distance`.
    /// Shapes far away get few triangles, near ones many. `pixels` must be > 0.
    ScreenError {
        /// Screen-space budget in pixels (e.g. 0.25).
        pixels: f64,
    },
    /// A fixed chord error in world units (> 0), whatever the distance.
    ChordError {
        /// World-space budget.
        world: f64,
    },
    /// A fixed subdivision: `8 * 2^level` segments per full turn (half that per half turn,
    /// e.g. sphere latitudes), independent of size and camera. `level <= 12`.
    FixedLevel(u32),
}

/// Options of [`crate::build`]. Build one with [`MeshOptions::DEFAULT`] or a preset and
/// change fields.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshOptions {
    /// BVH layout. Default [`BvhKind::Wide`]: measured with `scripts/anchor_embree.py` (1
    /// thread, 500x500 primary rays, interleaved rounds, thread CPU time, load ~12) it traced
    /// 1.8x (bunny), 1.55x (dragon_res3) and 1.9x (871k-triangle dragon) as many rays per
    /// second as Bvh2, for about 1.1x its memory then; its single rays now run 1.28x, 1.09x
    /// and 1.07-1.09x Embree 4's `rtcIntersect1` called from C
    /// (`bench-results/anchors/embree-20261127T010637Z`). Earlier, Bvh2 rendered
    /// seed-spheres 1.84x and the bunny 1.24x faster than CwBvh
    /// (bench-results/20261122T222119Z-default).
    pub bvh: BvhKind,
    /// Build preset. Default [`BuildQuality::Tuned`].
    pub build_quality: BuildQuality,
    /// Tessellation of analytic shapes. Default `ScreenError { pixels: 0.25 }`.
    pub tessellation: Tessellation,
    /// Surface-nets grid cells along the longest side of a CSG / smooth-union object's
    /// bounds (8..=512). Default 128.
    pub surface_resolution: u32,
    /// Trace the rays of a `closest_hits` batch 8 at a time as packets (interval culling,
    /// `crate::packet`) when the BVH is [`BvhKind::Wide`], nothing is instanced and the
    /// tree is below the interleaving size (above it batches are interleaved single rays
    /// either way); same hits as single rays. Default `true`: renders with packets took
    /// 0.75x (bunny), 0.77x (dragon_res3), 0.79x (seed-spheres), 0.72x (csg) and 0.87x
    /// (bunny with soft shadows) of the time without (CLI, 1 thread, 6-8 alternating
    /// rounds, load 2.4-2.9, images byte-identical). It was `false` until the packets were
    /// vectorised (they measured 1.03x on the bunny then).
    pub packets: bool,
    /// Instance shapes used more than once (repetition, a mesh placed twice) from one BLAS
    /// under a TLAS. `false` flattens everything into one BVH (same image, more memory).
    /// Default `true`.
    pub instancing: bool,
    /// Largest number of instances an infinite repetition may expand to (cells within
    /// `render.max_distance` of the camera). Exceeding it is an error. Default 4,194,304.
    pub max_instances: u64,
    /// Cap on segments per full turn of any parametric direction (bounds triangle counts
    /// when the camera touches a shape), `8..=`[`MAX_SEGMENTS_PER_TURN`]. Default 4096.
    pub max_segments_per_turn: u32,
    /// The build refuses, before allocating, to plan more than this many bytes
    /// ([`crate::MeshError::OverMemoryLimit`]); estimated at [`BUILD_BYTES_PER_TRIANGLE`] per
    /// triangle plus extraction grids and instances. Not a `key=value` option: the harness
    /// sets it from `--memory-limit-mib`. Default 4 GiB.
    pub memory_limit_bytes: u64,
}

/// Largest accepted [`MeshOptions::max_segments_per_turn`] (the angle lists alone would
/// otherwise take gigabytes before any triangle exists).
pub const MAX_SEGMENTS_PER_TURN: u32 = 1 << 16;

/// Peak bytes a build takes per triangle, for the memory estimate: measured as peak RSS over
/// triangles for one sphere tessellated to 16.4M triangles (5.2 GB, about 317 bytes each: the
/// f64 local mesh, its f32 render-space copy, the Bvh2 build and the wide layout) and for a
/// 10M-triangle OBJ (2.9 GB).
pub const BUILD_BYTES_PER_TRIANGLE: u64 = 320;

impl MeshOptions {
    /// The documented defaults.
    pub const DEFAULT: Self = Self {
        bvh: BvhKind::Wide,
        build_quality: BuildQuality::Tuned,
        tessellation: Tessellation::ScreenError { pixels: 0.25 },
        surface_resolution: 128,
        packets: true,
        instancing: true,
        max_instances: 1 << 22,
        max_segments_per_turn: 4096,
        memory_limit_bytes: 4 << 30,
    };

    /// Defaults with a fast build: Bvh2, `fast_build`, 1-pixel tessellation error, 64-cell
    /// surface extraction. For previews and tests.
    pub const fn fast() -> Self {
        Self {
            bvh: BvhKind::Bvh2,
            build_quality: BuildQuality::Fast,
            tessellation: Tessellation::ScreenError { pixels: 1.0 },
            surface_resolution: 64,
            ..Self::DEFAULT
        }
    }

    /// Defaults with a high-quality build: CwBvh, `slow_build`, 0.1-pixel tessellation error,
    /// 256-cell surface extraction.
    pub const fn quality() -> Self {
        Self {
            bvh: BvhKind::CwBvh,
            build_quality: BuildQuality::Slow,
            tessellation: Tessellation::ScreenError { pixels: 0.1 },
            surface_resolution: 256,
            ..Self::DEFAULT
        }
    }
}

impl Default for MeshOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}
