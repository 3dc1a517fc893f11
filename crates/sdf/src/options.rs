//! Knobs of the SDF backend: one flat serde type, [`SdfOptions`], whose fields are the
//! `key=value` options. The first paragraph of each field's doc comment is its `--opt help`
//! line, the whole comment its JSON Schema description; the rest says why the default is what
//! it is. Structured views ([`SdfOptions::hit_epsilon`], [`SdfOptions::mesh_grid`]) are
//! methods. A new option is a field here, its default in [`SdfOptions::DEFAULT`] and its use.

use std::path::PathBuf;

use marchmesh_field::MeshGrid;
use marchmesh_field::bake::{Quantization, Reconstruction};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// When a sphere-tracing step counts as a hit: the field value at the current point is below
/// this epsilon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HitEpsilon {
    /// A fixed distance in world units (> 0), whatever the distance from the camera. Fails
    /// at both ends of scale (merged features on tiny scenes, many steps on huge ones). Both
    /// kinds are floored at about 1e-6 times the distance from the camera (8 f32 ulps of the
    /// position), below which no surface could be resolved.
    Absolute(f64),
    /// A fraction `k` (> 0) of the pixel footprint at the point:
    /// `eps = k * camera.pixel_angle() * (|ray origin| + t)` (`|ray origin|` is the distance
    /// already travelled from the camera, render space being camera-centred). Scale
    /// invariant: behaves the same at every scene scale.
    PixelCone(f64),
}

/// The default hit shell in pixel footprints ([`SdfOptions::eps_px`]).
pub(crate) const DEFAULT_EPS_PX: f64 = 0.05;

/// `grid=` values: how mesh distance fields are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum GridKind {
    /// Dense trilinear grid.
    Dense,
    /// Sparse narrow-band brick grid.
    Sparse,
}

/// `prune_cells=` values: how a field pruned per region is divided into cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum PruneCells {
    /// The octree where it pays for one image, else one cell (see
    /// [`SdfOptions::prune_cells`]).
    Auto,
    /// The octree, refined while its work budget lasts (best per ray; up to about 0.7 s of
    /// build).
    Octree,
    /// One cell over the field's box (no octree build; a root smooth union's folds still
    /// skip far children eight at a time).
    Root,
}

/// Options of [`crate::build`], and the sdf backend's `key=value` options (unknown keys are
/// refused).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SdfOptions {
    /// Hit epsilon as a fraction of the pixel footprint at the point (scale invariant).
    ///
    /// The shell in which the tracer stops trusting plain steps and decides hit or near
    /// miss (see the crate docs and [`HitEpsilon`]); default 0.05. Hits are then refined to
    /// 1e-3 of it; it sets what is merged: features thinner than half of it may be stepped
    /// over, and near misses closer than it are decided by the (scalar) shell logic. Larger:
    /// fewer steps near surfaces; smaller: more steps for grazing rays. The default was measured against 0.25, 0.1 and 0.02 px: `docs/decisions/0013`.
    pub eps_px: f64,
    /// Absolute hit epsilon, world units; replaces eps_px when given.
    ///
    /// Default none ([`HitEpsilon::Absolute`] when given).
    pub eps_abs: Option<f64>,
    /// Most field evaluations per ray; rays that run out count as misses.
    ///
    /// Deciding included (default 512). A ray that runs out ends with
    /// `Termination::MaxSteps` (counted as no hit, never drawn as a surface). At the defaults
    /// it happens to none of the conformance cases' rays (0.02 px shells too), to none in
    /// `csg` or `seed-spheres` and to 0.002% of the rays of `primitives` in the default suite.
    /// (At 0.05 px it used to happen to rays skimming the cap of the conformance `cylinder`
    /// within the shell: receding from a surface they crawled at steps of their height; they
    /// now switch to segment tracing, which has a local bound for cylinders.)
    pub max_steps: u32,
    /// Longest ray, world units; none = the scene's render.max_distance.
    ///
    /// Default none. Rays reaching it end with `Termination::MaxDistance`.
    pub max_distance: Option<f64>,
    /// Over-relaxation factor in [1, 2) with overlap fallback (1 = off).
    ///
    /// Omega (Keinert et al. 2014, "Enhanced Sphere Tracing"): steps are `omega * d`; when
    /// the unbounding spheres of two consecutive points do not overlap the step is undone,
    /// replaced by the plain step, and relaxation is switched off for the rest of the ray, so
    /// it never steps through a surface plain tracing hits (tested on a 1e-3 thick slab).
    /// Default 1.2, measured at 256x256 (mean field evaluations per ray, all rays, omega 1.0 /
    /// 1.2 / 1.5): seed-spheres 23.7 / 21.5 / 20.8, csg 26.9 / 23.3 / 23.9, primitives 32.7 /
    /// 29.2 / 26.7; 1.2 is the best on csg and within 4% elsewhere, with the same images
    /// (conformance unchanged).
    pub relaxation: f64,
    /// Regula-falsi iterations pinning a hit onto the surface.
    ///
    /// Illinois iterations allowed to pin down a crossing once the ray is found inside a
    /// surface (default 16; each stops early at 1e-3 of the epsilon). 0 keeps the last
    /// outside sample as the hit.
    pub refine_steps: u32,
    /// Central-difference normal step, fraction of the pixel footprint.
    ///
    /// Default 0.02, where there is no analytic gradient. Measured on `seed-spheres` at
    /// 256x256 against analytic sphere normals (mean / p95 / max angle error over 39k primary
    /// hits, `examples/render_sdf.rs`): 0.002: 0.086 / 0.194 / 0.40 deg (f32 cancellation),
    /// 0.005: 0.033 / 0.076 / 0.15, 0.01: 0.014 / 0.036 / 8.8, 0.02: 0.009 / 0.018 / 23.5,
    /// 0.05: 0.014 / 0.012 / 35.6, 0.1: 0.023 / 0.011 / 40.2, 1.0: 0.171 / 0.011 / 44.8 deg
    /// (the max is a silhouette or contact pixel whose stencil reaches another surface).
    /// Larger steps also straddle edges: hits within a step of a box edge get a blend of both
    /// faces' normals, which at 0.1 put the conformance case `repeat_infinite` (far, small
    /// boxes) at 1.4 deg mean against the reference (0.035 deg at 0.02).
    pub normal_step: f64,
    /// Trace batches 8 rays in lockstep (same results).
    ///
    /// `closest_hits` batches as SoA lanes (default true); false traces them one at a time.
    pub lockstep: bool,
    /// In lockstep batches, trace bundles of primary rays through only the objects their
    /// cone can reach (false: the whole field for every ray).
    ///
    /// Each bundle of up to [`crate::CULL_BUNDLE`] rays sharing an origin (primary rays) is
    /// traced through the field restricted to the objects the bundle's cone can reach
    /// ([`marchmesh_field::RayCone`]; default true): a step then costs what the objects near
    /// the bundle cost, not what the scene's object count costs. Hits agree with the
    /// unrestricted field to the refinement threshold (the steps differ, so not bit for bit).
    pub cull: bool,
    /// Prune the field per region of space: an octree of `2^prune_depth` finest cells per
    /// axis, each cell holding only the nodes that matter in it (0 = off).
    ///
    /// `marchmesh_field::prune`, after Barbier, Sanchez et al. 2025 ("Lipschitz Pruning"):
    /// each cell over the scene's box keeps only the nodes that can matter in it, smooth
    /// unions included, or answers a far bound where no surface is (default 6; at most
    /// [`crate::MAX_PRUNE_DEPTH`]). Built for fields holding a smooth union, of at least
    /// [`crate::PRUNE_MIN_NODES`] nodes, with a finite box and no mesh grid; when built, point
    /// queries read their cell's program (the whole program's value bit for bit) and bundles
    /// are not culled ([`SdfOptions::cull`]).
    pub prune_depth: u32,
    /// Cells of the pruning per region: auto (default), octree or root.
    ///
    /// `auto` gives the octree its whole work budget when the camera's samples times the
    /// field's nodes reach [`crate::PRUNE_OCTREE_MIN_SAMPLE_NODES`] (a quarter of it,
    /// [`crate::PRUNE_OCTREE_MIN_SAMPLE_NODES_BLEND`], for a root `blend`); below, a small budget
    /// ([`crate::PRUNE_TRIAL_WORK`]), and one cell over the whole box where that does not
    /// finish the octree: the whole budget's build (up to about 0.7 s) would cost more
    /// than it saves on one image that small. `octree` is the fastest per ray, for renders
    /// that reuse one build (benchmark repeats, the viewer); `root` never refines. Measured:
    /// `docs/decisions/0030` and `0031`.
    pub prune_cells: PruneCells,
    /// In lockstep batches, march one cone per run of four camera rays and start the rays
    /// where it stops (false: every ray from its origin).
    ///
    /// The rays start at least two hit shells from every surface (`beam.rs`; default true):
    /// the empty space in front of the first surface is crossed once per four rays instead of
    /// once per ray. Hits agree with unbeamed tracing to the refinement threshold (the steps
    /// differ, so not bit for bit). Needs `bounds` (the naive level has neither). Only for cameras inside the scene's box (measured: `docs/decisions/0013`).
    pub beams: bool,
    /// End rays that recede from every surface (convex leaves growing, other leaves' boxes
    /// behind) instead of marching them to the end of their range.
    ///
    /// Default true: every eighth evaluation a ray in plain marching whose distance grew asks
    /// the field's tape whether each leaf is convex and receding (the distance to a convex
    /// set is convex along a line: once it grows it never shrinks) or has its box behind the
    /// ray ([`marchmesh_field::Field::recedes`]), and ends as it would at the end of its
    /// range when all are. Shadow rays climbing away from a ground and rays that passed every
    /// object stop marching to the end of their range. Fields without a tape (CSG,
    /// repetition) never answer yes; a mesh grid is left behind only with its box. Needs
    /// `bounds` (the naive level has none).
    pub recede: bool,
    /// Evaluate the field's 8-lane distances through kernels specialised per program (and
    /// per restriction of it to a bundle of rays) instead of the generic tape (false: the
    /// tape).
    ///
    /// Default true: the same values bit for bit ([`marchmesh_field::kernel`]), with the
    /// per-leaf dispatch decided once when the field is built; measured faster per 8-lane
    /// evaluation and, by a little, on primary-ray traces with the per-bundle rebuild paid
    /// (`docs/decisions/0023-field-kernels-specialised-per-program.md`). Fields the kernel
    /// does not cover (mesh grids, CSG) keep the tape or the interpreter.
    pub kernels: bool,
    /// Evaluate the field's 8-lane distances through a function compiled to machine code
    /// per program with cranelift (and per restriction of it to a bundle of rays, compiled
    /// once per set of kept objects and cached) instead of the kernel (false: `kernels`
    /// decides).
    ///
    /// The same values bit for bit ([`marchmesh_field::jit`]). Default false: slower than
    /// the kernel on x64 (`docs/decisions/0026-field-programs-compiled-with-cranelift.md`).
    /// Needs the crate's cargo feature `jit`; without it (the default build) the option
    /// changes nothing. Fields it does not compile (mesh grids, CSG, a union of two bounded
    /// members) keep the kernel, the tape or the interpreter.
    pub jit: bool,
    /// Switch slowly progressing (grazing) rays to segment tracing with local directional
    /// Lipschitz bounds (false: plain sphere tracing throughout).
    ///
    /// Galin et al. 2020; default true: at 0.1 and 0.01 degree over a plane or a box top
    /// every ray used to exhaust 512 steps. False is the A/B baseline.
    pub segment: bool,
    /// Skip subtrees by their bounding boxes and clip rays to the scene box (false: every
    /// node at every step, the naive cost).
    ///
    /// Default true; false is [`marchmesh_field::Field::without_bounds`]: the cost of sphere
    /// tracing without bounding volumes, for the naive baseline level.
    pub bounds: bool,
    /// Cells on the longest side of baked mesh distance grids (effective resolution for
    /// sparse grids), 4..=512.
    ///
    /// Default 64.
    pub grid_res: u32,
    /// Mesh distance grid: dense (n^3 f32 samples) or sparse (8^3-cell bricks only within
    /// `band` cells of the surface, memory ~ n^2).
    ///
    /// See [`SdfOptions::mesh_grid`]. Sparse u8 at 128 cells holds the bunny in 0.90 MB
    /// where the dense 64^3 grid takes 1.11 MB, with PSNR 34.8 dB (36.4 dB tricubic) / mean
    /// normal error 0.60 deg against 32.1 dB / 0.98 deg on
    /// `scenes/generated/mesh_bunny.json` at 320x240 (dragon_res3: 0.60 MB, 32.6 dB, 1.18
    /// deg, tricubic 34.0 dB, 1.04 deg), and bakes faster than the dense 128^3 grid; it
    /// renders at about the dense grid's speed (1.08x its time at 128, tricubic 1.43x). The
    /// `normals` reconstruction stores a normal per sample (3x the u8 bytes) and lowers the
    /// bunny's mean normal error at 128 from 2.17 to 1.67 deg in the stability study. The
    /// default stays the dense grid every committed run was measured with.
    pub grid: GridKind,
    /// Sparse grids: band half-width in cells, 1..=16 (bricks where the surface comes this
    /// close; the field is at least this far elsewhere).
    ///
    /// Default [`MeshGrid::SPARSE_DEFAULT`]'s.
    pub band: u32,
    /// Sparse grids: sample storage, f32, u16 or u8 (error clamp/65535 or clamp/255, clamp
    /// = band + 1 cells).
    ///
    /// Default [`MeshGrid::SPARSE_DEFAULT`]'s.
    pub quantize: Quantization,
    /// Sparse grids: interpolation, trilinear, tricubic (Catmull-Rom near the surface,
    /// C1 normals, the same 9^3 samples per brick, stencils read across brick faces) or
    /// normals (a stored normal per sample, 2 bytes more, blended tangent planes near the
    /// surface: follows flat facets).
    ///
    /// Default [`MeshGrid::SPARSE_DEFAULT`]'s.
    pub recon: Reconstruction,
    /// Folder caching baked grids (none = no disk cache).
    ///
    /// Default none.
    pub cache_dir: Option<PathBuf>,
    /// Area-light soft shadows from one cone march per light (approximate) instead of
    /// sampled rays.
    ///
    /// Quilez's penumbra estimate, an approximation, instead of the integrator's sampled
    /// shadow rays (exact as the sample count grows); a long rectangle light takes one cone
    /// per squarish part (`marchmesh_core::emitter::Emitter::cones_from`). Its error per
    /// light size, aspect and occluder distance is the stability study's `shadow_*`
    /// families. Default false.
    pub cone_shadows: bool,
    /// Ambient occlusion from this many field taps along the normal (approximate); 0 =
    /// sampled rays.
    ///
    /// Evans 2006, an approximation, instead of the integrator's sampled rays; default 0.
    pub ao_taps: u32,
    /// The build refuses, before baking, grids whose estimated memory
    /// ([`crate::BAKE_BYTES_PER_CELL`] per cell of every distinct mesh's grid) exceeds this
    /// ([`crate::SdfError::OverMemoryLimit`]), and each mesh file whose load and bake would
    /// exceed it with the grids (checked before the file is read and again before it is
    /// decoded: `marchmesh_field::FieldOptions::memory_limit_bytes`). Not a `key=value`
    /// option: the registry sets it from `--memory-limit-mib`. Default 4 GiB.
    #[serde(skip)]
    #[schemars(skip)]
    pub memory_limit_bytes: u64,
}

/// The sparse grid settings [`SdfOptions::DEFAULT`] keeps for `grid=sparse`.
const SPARSE_DEFAULT: (u32, Quantization, Reconstruction) = match MeshGrid::SPARSE_DEFAULT {
    MeshGrid::Sparse {
        band_voxels,
        quantization,
        reconstruction,
    } => (band_voxels, quantization, reconstruction),
    MeshGrid::Dense => (2, Quantization::F32, Reconstruction::Trilinear),
};

impl SdfOptions {
    /// The defaults documented on each field.
    pub const DEFAULT: SdfOptions = SdfOptions {
        eps_px: DEFAULT_EPS_PX,
        eps_abs: None,
        max_steps: 512,
        max_distance: None,
        relaxation: 1.2,
        refine_steps: 16,
        normal_step: 0.02,
        lockstep: true,
        cull: true,
        prune_depth: 6,
        prune_cells: PruneCells::Auto,
        beams: true,
        recede: true,
        kernels: true,
        jit: false,
        segment: true,
        bounds: true,
        grid_res: 64,
        grid: GridKind::Dense,
        band: SPARSE_DEFAULT.0,
        quantize: SPARSE_DEFAULT.1,
        recon: SPARSE_DEFAULT.2,
        cache_dir: None,
        cone_shadows: false,
        ao_taps: 0,
        memory_limit_bytes: 4 << 30,
    };

    /// The hit epsilon: `eps_abs` when given, else `eps_px` of the pixel footprint.
    pub fn hit_epsilon(&self) -> HitEpsilon {
        match self.eps_abs {
            Some(e) => HitEpsilon::Absolute(e),
            None => HitEpsilon::PixelCone(self.eps_px),
        }
    }

    /// The representation of mesh distance fields: `grid`, and for sparse grids `band`,
    /// `quantize` and `recon`.
    pub fn mesh_grid(&self) -> MeshGrid {
        match self.grid {
            GridKind::Dense => MeshGrid::Dense,
            GridKind::Sparse => MeshGrid::Sparse {
                band_voxels: self.band,
                quantization: self.quantize,
                reconstruction: self.recon,
            },
        }
    }

    /// These options with mesh grids represented as `grid` (sets `grid`, `band`, `quantize`
    /// and `recon`).
    pub fn with_mesh_grid(self, grid: MeshGrid) -> SdfOptions {
        match grid {
            MeshGrid::Dense => SdfOptions {
                grid: GridKind::Dense,
                ..self
            },
            MeshGrid::Sparse {
                band_voxels,
                quantization,
                reconstruction,
            } => SdfOptions {
                grid: GridKind::Sparse,
                band: band_voxels,
                quantize: quantization,
                recon: reconstruction,
                ..self
            },
        }
    }
}

impl Default for SdfOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}
