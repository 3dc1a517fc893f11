//! Compiled signed distance fields of marchmesh scenes.
//!
//! [`Field::compile_scene`] turns a scene (or [`Field::compile_node`] one subtree) into a flat
//! program (see [`program`]) evaluated by one generic interpreter in f32 ([`Field::distance`]),
//! f64 ([`Field::distance_f64`]) or eight f32 lanes in lockstep ([`Field::distance_x8`]).
//!
//! # What the value means
//! - Sphere, plane, box, capped cylinder, torus: exact Euclidean signed distance.
//! - Triangle: exact *unsigned* distance (a two-sided surface, never negative).
//! - Ellipsoid: the scaled-sphere bound `min(r) * (|p / r| - 1)` ([`shapes::ellipsoid`]):
//!   right sign, zero on the surface, never above the true distance.
//! - Transforms: rigid and uniform scale exact; non-uniform scale multiplies the local
//!   distance by the smallest singular value of the linear map (a bound).
//! - Union/intersection/subtraction: `min`/`max`/`max(a, -b)` (exact outside for union,
//!   bounds otherwise); smooth union: Quilez's polynomial smooth minimum ([`shapes::smin`]),
//!   a 1-Lipschitz bound of its own blended surface.
//! - Repetition: `min(true distance of the repeated set, R)`, see [`program`].
//! - Mesh: a baked signed distance grid (`marchmesh-bake`, mesh local frame, cached on disk
//!   when [`FieldOptions::cache_dir`] is set), dense or sparse ([`MeshGrid`]) sampled
//!   trilinearly (or, sparse only, tricubically or by stored normals): within half a cell diagonal of the true
//!   distance where the sign is right, features thinner than a cell lost; the interpolant's
//!   gradient can reach `sqrt(3)` between samples near creases, so this is the one leaf that
//!   is not a strict bound. Sparse grids hold bricks only near the surface and a lower bound
//!   of the distance (at least the band width) elsewhere, plus the quantization error of
//!   8/16-bit samples. Open meshes take their sign from the generalized winding number.
//! - Far from a subtree's bounding box the subtree's value is replaced by the distance to its
//!   box (see [`program`]).
//!
//! Every value except mesh grids is 1-Lipschitz (up to rounding), so `|d|` never exceeds the
//! distance to the zero set: sphere tracing with step `d` cannot step through a surface.
//!
//! Material: the closest leaf's material for unions; for intersection and subtraction the
//! material of the child whose value defines the result (the surface there).
//!
//! Build cost: the public evaluation entry points ([`Field::distance_lanes`],
//! [`tape::Tape::eval`], [`program::Program::eval`], ...) are `#[inline]` only in builds
//! without debug assertions. Inlined, each calling crate (and each of its codegen units)
//! compiles its own copy of the evaluators, which are `#[inline(always)]` inside; in the
//! test profile that took minutes of LLVM time per crate. Optimized builds keep the
//! cross-crate inlining (`docs/decisions/0016-evaluators-compiled-once-in-test-builds.md`).

// Index loops over fixed lanes/axes are the clearest form here and auto-vectorise.
#![allow(clippy::needless_range_loop)]

pub mod compile;
pub mod cull;
pub mod dual;
pub mod jit;
pub mod kernel;
pub mod lane;
pub mod leaf;
pub mod program;
pub mod prune;
mod recede;
pub mod shapes;
pub mod tape;

use std::path::PathBuf;
use std::time::Instant;

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_scene::{MaterialId, Node, NodeKind, Scene, Shape};

use compile::{Aabb, MeshResolver, compile_roots};
pub use cull::{RayCone, Restricted};
pub use dual::{Dual1, Dual8};
use kernel::Kernel;
pub use lane::{F32x8, Lane, M8, Scalar, V3};
/// The bake crate (grid types, quantization and reconstruction options), re-exported so
/// backends name the same types.
pub use marchmesh_bake as bake;
use program::{GridSampler, Program};
use tape::Tape;

/// Which representation a mesh's distance field is baked into.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshGrid {
    /// A dense trilinear grid ([`marchmesh_bake::DistanceGrid`]): `n^3` f32 samples.
    Dense,
    /// A sparse narrow-band brick grid ([`marchmesh_bake::SparseGrid`]): bricks of
    /// `8^3` cells only where the surface passes, memory proportional to the surface.
    Sparse {
        /// Band half-width in cells (bricks within it of the surface).
        band_voxels: u32,
        /// Sample storage.
        quantization: marchmesh_bake::Quantization,
        /// Interpolation.
        reconstruction: marchmesh_bake::Reconstruction,
    },
}

impl MeshGrid {
    /// The sparse grid at its defaults: band 2 cells, f32, trilinear.
    pub const SPARSE_DEFAULT: MeshGrid = MeshGrid::Sparse {
        band_voxels: 2,
        quantization: marchmesh_bake::Quantization::F32,
        reconstruction: marchmesh_bake::Reconstruction::Trilinear,
    };
}

/// Options of field compilation.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldOptions {
    /// Cells on the longest side of a baked mesh distance grid (default 64); for sparse
    /// grids the effective resolution. Higher is more accurate (error about one cell near
    /// thin features) and costs `n^3` memory and bake time for dense grids, about `n^2`
    /// for sparse ones.
    pub mesh_grid_resolution: u32,
    /// Where baked grids are cached (keyed by mesh content and resolution); `None` = no cache.
    pub cache_dir: Option<PathBuf>,
    /// The representation of mesh distance fields (default [`MeshGrid::Dense`]).
    pub mesh_grid: MeshGrid,
    /// What baking mesh grids may take (default unlimited): before a mesh file is read, and
    /// again before it is decoded, the grids already baked, the load's bound
    /// ([`marchmesh_meshio::LoadBound`]), the bake's working set
    /// ([`BAKE_BYTES_PER_TRIANGLE`] per triangle) and the grid's bound
    /// ([`FieldOptions::mesh_grid_bytes_bound`]) must fit, else [`FieldError::MeshBake`]
    /// refuses the mesh. A grid found in the cache is counted as if baked.
    pub memory_limit_bytes: u64,
}

/// Bytes per cell of a baked dense mesh grid for the memory estimate: the f32 sample plus
/// the bake's per-cell working data (nearest-triangle search and sign).
pub const BAKE_BYTES_PER_CELL: u64 = 12;

/// Bytes per triangle of a bake's working set for the memory estimate: the triangles copied
/// by value twice (input and leaf order), centroids, order, nodes and winding moments of the
/// bake's BVH, and the closedness test's edge map.
pub const BAKE_BYTES_PER_TRIANGLE: u64 = 192;

impl FieldOptions {
    /// The defaults: dense, resolution 64, no cache, no memory limit.
    pub const DEFAULT: FieldOptions = FieldOptions {
        mesh_grid_resolution: 64,
        cache_dir: None,
        mesh_grid: MeshGrid::Dense,
        memory_limit_bytes: u64::MAX,
    };

    /// Estimated peak bytes of baking one mesh grid, before any mesh is read: dense,
    /// [`BAKE_BYTES_PER_CELL`] per cell of the (at most cubic) lattice; sparse, the upper
    /// bound of [`marchmesh_bake::SparseOptions::max_bake_bytes`] (every brick cell holding
    /// a brick, which a surface cannot reach: the real grid is proportional to its area).
    pub fn mesh_grid_bytes_bound(&self) -> u64 {
        match self.mesh_grid {
            MeshGrid::Dense => {
                // Cells on the longest side, plus the apron of one sample each side.
                u64::from(self.mesh_grid_resolution.saturating_add(3))
                    .pow(3)
                    .saturating_mul(BAKE_BYTES_PER_CELL)
            }
            MeshGrid::Sparse {
                band_voxels,
                quantization,
                reconstruction,
            } => marchmesh_bake::SparseOptions {
                resolution: self.mesh_grid_resolution,
                band_voxels,
                quantization,
                reconstruction,
                cache_dir: None,
            }
            .max_bake_bytes(),
        }
    }
}

impl Default for FieldOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why a field could not be compiled.
#[derive(Debug, thiserror::Error)]
pub enum FieldError {
    /// A mesh could not be loaded or baked into a distance grid.
    #[error("{json_path}: mesh {path}: {reason}")]
    MeshBake {
        /// JSON path of the mesh node.
        json_path: String,
        /// Mesh file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// A node cannot be compiled (singular transform, degenerate triangle).
    #[error("{json_path}: {reason}")]
    Degenerate {
        /// JSON path of the node.
        json_path: String,
        /// What is wrong.
        reason: String,
    },
}

/// What compiling cost and produced, for backend reports.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FieldReport {
    /// Phases with wall time in milliseconds (`compile`, `mesh_bake`).
    pub phases_ms: Vec<(String, f64)>,
    /// Named counts (`program_nodes`, `mesh_grids`, `grid_cells`).
    pub counters: Vec<(String, f64)>,
    /// Approximations made (ellipsoid bound, non-uniform scales, mesh grids, repetition).
    pub notes: Vec<String>,
}

/// A field's program restricted to a ball ([`Field::restricted_to_ball`]).
#[derive(Debug, Clone)]
pub struct BallProgram {
    p32: Program<f32>,
}

impl BallProgram {
    /// Nodes of the restricted program.
    pub fn node_count(&self) -> usize {
        self.p32.instrs.len()
    }
}

/// A compiled distance field (render space for [`Field::compile_scene`], the caller's frame
/// for [`Field::compile_node`]).
pub struct Field {
    p32: Program<f32>,
    p64: Program<f64>,
    /// `p32` flattened when it is a small union of analytic or mesh-grid leaves ([`tape`]): what the
    /// 8-lane evaluations run (same values).
    tape: Option<Tape>,
    /// `tape` specialised ([`kernel`]) when it has a kernel and kernels are on
    /// ([`Field::set_kernels`]): what [`Field::distance_lanes`] runs (same values).
    kernel: Option<Kernel>,
    /// Whether [`Field::set_kernels`] turned kernels on (off by default).
    kernels: bool,
    /// `tape` compiled to machine code ([`jit`]) when JIT compilation is on
    /// ([`Field::set_jit`]) and the tape compiles: what [`Field::distance_lanes`] runs
    /// first (same values).
    jit: Option<std::sync::Arc<jit::Jit>>,
    /// Whether [`Field::set_jit`] turned JIT compilation on (off by default).
    jits: bool,
    /// The restrictions' compiled functions ([`Field::restrict_to`]), keyed by the nodes
    /// each kept.
    jit_cache: jit::Cache,
    grids: Vec<Box<dyn GridSampler>>,
    bounds: Option<(DVec3, DVec3)>,
    /// The program pruned per octree cell ([`prune`]), when built: what the point queries
    /// evaluate.
    cells: Option<prune::Cells>,
    /// Child trees of the program's large composites, built on first use by
    /// [`Field::build_cells`] or [`Field::restricted_to_ball`].
    prune_index: std::sync::OnceLock<prune::PruneIndex>,
    report: FieldReport,
}

impl std::fmt::Debug for Field {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Field")
            .field("nodes", &self.p64.instrs.len())
            .field("grids", &self.grids.len())
            .field("bounds", &self.bounds)
            .finish()
    }
}

struct Meshes<'a> {
    opts: &'a FieldOptions,
    seen: Vec<(PathBuf, u32, Aabb)>,
    grids: Vec<Box<dyn GridSampler>>,
    notes: Vec<String>,
    bake_ms: f64,
}

/// A baked grid as the evaluator sees it.
enum Grid {
    Dense(marchmesh_bake::DistanceGrid),
    Sparse(marchmesh_bake::SparseGrid),
}

impl GridSampler for Grid {
    fn sample(&self, x: f64, y: f64, z: f64) -> f64 {
        match self {
            Grid::Dense(g) => g.sample_f64(DVec3::new(x, y, z)),
            Grid::Sparse(g) => g.sample_f64(DVec3::new(x, y, z)),
        }
    }
    fn sample_f32(&self, x: f32, y: f32, z: f32) -> f32 {
        match self {
            Grid::Dense(g) => g.sample(Vec3::new(x, y, z)),
            Grid::Sparse(g) => g.sample(Vec3::new(x, y, z)),
        }
    }
    fn sample_f32x8(&self, x: [f32; 8], y: [f32; 8], z: [f32; 8]) -> [f32; 8] {
        // One dispatch for the eight lookups, each inlined.
        match self {
            Grid::Dense(g) => std::array::from_fn(|i| g.sample(Vec3::new(x[i], y[i], z[i]))),
            Grid::Sparse(g) => std::array::from_fn(|i| g.sample(Vec3::new(x[i], y[i], z[i]))),
        }
    }
    fn memory_bytes(&self) -> u64 {
        match self {
            Grid::Dense(g) => g.memory_bytes(),
            Grid::Sparse(g) => g.memory_bytes(),
        }
    }
    fn stores_normals(&self) -> bool {
        matches!(self, Grid::Sparse(g) if g.reconstruction() == marchmesh_bake::Reconstruction::Normals)
    }
    fn stored_normal(&self, x: f32, y: f32, z: f32) -> Option<[f32; 3]> {
        match self {
            Grid::Dense(_) => None,
            Grid::Sparse(g) => g.stored_normal(Vec3::new(x, y, z)).map(|n| n.to_array()),
        }
    }
}

impl MeshResolver for Meshes<'_> {
    fn resolve(&mut self, node: &Node) -> Result<(u32, Aabb), FieldError> {
        let NodeKind::Leaf(Shape::Mesh { path }) = &node.kind else {
            unreachable!("resolve is called on mesh nodes only")
        };
        if let Some((_, idx, bb)) = self.seen.iter().find(|(p, _, _)| p == path) {
            return Ok((*idx, *bb));
        }
        let err = |reason: String| FieldError::MeshBake {
            json_path: node.json_path.clone(),
            path: path.clone(),
            reason,
        };
        let t0 = Instant::now();
        let limit = self.opts.memory_limit_bytes;
        let held: u64 = self.grids.iter().map(|g| g.memory_bytes()).sum();
        let grid = self.opts.mesh_grid_bytes_bound();
        let mut check = |b: &marchmesh_meshio::LoadBound| {
            let bake = b.triangles.saturating_mul(BAKE_BYTES_PER_TRIANGLE);
            let needed = held
                .saturating_add(grid)
                .saturating_add(b.load_bytes())
                .saturating_add(bake);
            if needed <= limit {
                return Ok(());
            }
            Err(b.over_limit(
                "loading and baking it",
                needed,
                &format!(
                    ", {} MiB for its grid, {} MiB of grids already baked",
                    grid.div_ceil(1 << 20),
                    held.div_ceil(1 << 20)
                ),
                limit,
            ))
        };
        let mesh = marchmesh_meshio::load_mesh_checked(path, &mut check).map_err(|e| match e {
            marchmesh_meshio::MeshLoadError::OverBudget { reason, .. } => err(reason),
            other => err(other.to_string()),
        })?;
        let open_note = if mesh.is_closed() {
            ""
        } else {
            "; open mesh: sign from the generalized winding number, holes may close or leak by about a cell"
        };
        let (grid, notes) = match self.opts.mesh_grid {
            MeshGrid::Dense => {
                let baked = marchmesh_bake::bake(
                    &mesh,
                    &marchmesh_bake::BakeOptions {
                        resolution: self.opts.mesh_grid_resolution,
                        cache_dir: self.opts.cache_dir.clone(),
                    },
                )
                .map_err(|e| err(e.to_string()))?;
                let g = &baked.grid;
                self.notes.push(format!(
                    "{}: mesh {} baked to a {}x{}x{} distance grid ({} B{}), trilinear; distances within half a cell diagonal ({:.3e} mesh units), features thinner than a cell lost{}",
                    node.json_path,
                    path.display(),
                    g.dims[0],
                    g.dims[1],
                    g.dims[2],
                    g.memory_bytes(),
                    if baked.from_cache { ", from cache" } else { "" },
                    g.cell_size * 0.866,
                    open_note
                ));
                (Grid::Dense(baked.grid), baked.notes)
            }
            MeshGrid::Sparse {
                band_voxels,
                quantization,
                reconstruction,
            } => {
                let (baked, _) = marchmesh_bake::bake_sparse(
                    &mesh,
                    &marchmesh_bake::SparseOptions {
                        resolution: self.opts.mesh_grid_resolution,
                        band_voxels,
                        quantization,
                        reconstruction,
                        cache_dir: self.opts.cache_dir.clone(),
                    },
                )
                .map_err(|e| err(e.to_string()))?;
                let g = &baked.grid;
                let d = g.dims();
                self.notes.push(format!(
                    "{}: mesh {} baked to a sparse grid, effective {}x{}x{}, {} bricks of 8^3 cells ({} B{}), {} {}, band {} cells; distances within half a cell diagonal ({:.3e} mesh units) plus quantization ({:.3e}) in the band, a lower bound (at least the band) elsewhere{}",
                    node.json_path,
                    path.display(),
                    d[0],
                    d[1],
                    d[2],
                    g.brick_count(),
                    g.memory_bytes(),
                    if baked.from_cache { ", from cache" } else { "" },
                    quantization.name(),
                    reconstruction.name(),
                    band_voxels,
                    g.cell_size() * 0.866,
                    quantization.max_error(g.clamp()),
                    if mesh.is_closed() {
                        ""
                    } else {
                        "; open mesh: signs from face sides, bricks whose sides contradict their distances from the winding number (caps across large holes possible)"
                    }
                ));
                (Grid::Sparse(baked.grid), baked.notes)
            }
        };
        self.bake_ms += t0.elapsed().as_secs_f64() * 1e3;
        let (lo, hi) = mesh.bounds();
        let bb = Aabb {
            lo: lo.as_dvec3(),
            hi: hi.as_dvec3(),
        };
        self.notes
            .extend(notes.iter().map(|n| format!("{}: {n}", node.json_path)));
        let idx = self.grids.len() as u32;
        self.grids.push(Box::new(grid));
        self.seen.push((path.clone(), idx, bb));
        Ok((idx, bb))
    }
}

impl Field {
    /// Compiles every object of `scene` (their union) in render space (world minus the
    /// camera position). Errors name the node's JSON path (and mesh file).
    pub fn compile_scene(scene: &Scene, opts: &FieldOptions) -> Result<Field, FieldError> {
        let from_world = DAffine3::from_translation(-scene.camera.position);
        let nodes: Vec<(&Node, DAffine3)> = scene
            .objects
            .iter()
            .map(|n| (n, from_world * n.transform))
            .collect();
        Self::compile(&nodes, opts)
    }

    /// Compiles one subtree: a frame point is `parent_to_frame * node.transform * local`.
    /// Pass `node.transform.inverse()` to evaluate in the node's local frame.
    pub fn compile_node(
        node: &Node,
        parent_to_frame: DAffine3,
        opts: &FieldOptions,
    ) -> Result<Field, FieldError> {
        Self::compile(&[(node, parent_to_frame * node.transform)], opts)
    }

    fn compile(nodes: &[(&Node, DAffine3)], opts: &FieldOptions) -> Result<Field, FieldError> {
        let t0 = Instant::now();
        let mut meshes = Meshes {
            opts,
            seen: Vec::new(),
            grids: Vec::new(),
            notes: Vec::new(),
            bake_ms: 0.0,
        };
        let (p64, bb, mut notes) = compile_roots(nodes, &mut meshes)?;
        let p32 = p64.cast::<f32>();
        let total = t0.elapsed().as_secs_f64() * 1e3;
        let mut has_ellipsoid = false;
        let mut has_smooth = false;
        for (n, _) in nodes {
            n.visit(&mut |n| match n.kind {
                NodeKind::Leaf(Shape::Ellipsoid { .. }) => has_ellipsoid = true,
                NodeKind::Smooth { .. } => has_smooth = true,
                _ => {}
            });
        }
        if has_ellipsoid {
            notes.push(
                "ellipsoid: scaled-sphere distance bound min(r)*(|p/r|-1), never over-estimates"
                    .into(),
            );
        }
        if has_smooth {
            notes.push(
                "smooth union: polynomial smin (Quilez), a bound of the blended surface".into(),
            );
        }
        notes.extend(meshes.notes);
        let mut phases = vec![("field_compile".to_string(), total - meshes.bake_ms)];
        if !meshes.grids.is_empty() {
            phases.push(("mesh_bake".to_string(), meshes.bake_ms));
        }
        let bounds = bb
            .filter(|b| b.lo.is_finite() && b.hi.is_finite())
            .map(|b| (b.lo, b.hi));
        let counters = vec![
            ("program_nodes".to_string(), p64.instrs.len() as f64),
            ("mesh_grids".to_string(), meshes.grids.len() as f64),
        ];
        Ok(Field {
            tape: Tape::of(&p32),
            kernel: None,
            kernels: false,
            jit: None,
            jits: false,
            jit_cache: jit::Cache::default(),
            p32,
            p64,
            grids: meshes.grids,
            bounds,
            cells: None,
            prune_index: std::sync::OnceLock::new(),
            report: FieldReport {
                phases_ms: phases,
                counters,
                notes,
            },
        })
    }

    #[inline]
    fn eval<T: Lane, const M: bool>(&self, prog: &Program<T::S>, p: V3<T>) -> (T, T::Mat) {
        prog.eval::<T, M>(p, &self.grids)
    }

    /// Whether a baked mesh stores surface normals (sparse grids with `recon=normals`), so
    /// [`Field::stored_normal`] can answer.
    pub fn stores_normals(&self) -> bool {
        self.grids.iter().any(|g| g.stores_normals())
    }

    /// The unit normal a baked mesh stores at the surface point `p`
    /// ([`program::Program::stored_normal`]): a facet's own normal where the field's
    /// gradient would be the smooth grid's. `None` where the surface is not a mesh grid
    /// storing normals or the path to it is not plain unions.
    pub fn stored_normal(&self, p: Vec3) -> Option<Vec3> {
        if !self.stores_normals() {
            return None;
        }
        self.p32
            .stored_normal(p.to_array(), &self.grids)
            .map(Vec3::from_array)
    }

    /// Prunes the program per region ([`prune::Cells`]): an octree of `2^depth` finest cells
    /// per axis over the field's box, each cell holding the program restricted to the nodes
    /// that can matter in it, or a far bound where no surface is. Point queries then evaluate
    /// the cell's program (within `max_error_rel` times the box's longest side of the whole
    /// program's value; bit for bit with `0`: see [`prune::prune`]) or the far
    /// bound (a safe bound of the distance to any surface with the field's sign, at least half
    /// the cell's radius: never mistaken for a hit). The octree is refined while its work
    /// budget lasts ([`prune::Cells::build`]). Does nothing and returns
    /// `None` when the field is unbounded, has mesh grids or was built
    /// [`Field::without_bounds`].
    pub fn build_cells(&mut self, depth: u32, max_error_rel: f64) -> Option<prune::CellStats> {
        let work = prune::Cells::max_work(self.p64.instrs.len());
        self.build_cells_within(depth, max_error_rel, work, false)
    }

    /// [`Field::build_cells`] with a work budget of `work` ([`prune::Cells::build_within`])
    /// instead of [`prune::Cells::max_work`]. `0` settles the octree's root: one cell over
    /// the whole box (for a root smooth union, its children as one [`prune::Cell::Subset`]
    /// whose folds skip far children eight at a time), built in about one pass over the
    /// program. With `root_if_cut`, an octree whose refinement the budget cut short
    /// ([`prune::CellStats::budget_cut`]) is replaced by that one cell (so at most `work`
    /// is spent on an octree that is kept only when complete). Returns `None` as
    /// [`Field::build_cells`] does.
    pub fn build_cells_within(
        &mut self,
        depth: u32,
        max_error_rel: f64,
        work: usize,
        root_if_cut: bool,
    ) -> Option<prune::CellStats> {
        let (lo, hi) = self.bounds?;
        let max_error = max_error_rel * (hi - lo).max_element();
        let t0 = Instant::now();
        let index = self.prune_index();
        if depth == 0 {
            return None;
        }
        let depth = depth.min(8);
        // Half a finest cell of margin around the surfaces' box.
        let pad = 0.5 * (hi - lo).max_element() / f64::from(1u32 << depth) + 1e-9;
        let build = |work: usize| {
            prune::Cells::build_within(
                &self.p64,
                index,
                &self.grids,
                (lo, hi),
                pad,
                // A lone root cell needs no index of finest cells.
                if work == 0 { 0 } else { depth },
                max_error,
                work,
            )
        };
        let mut cells = build(work)?;
        let fell_back = root_if_cut && work > 0 && cells.stats().budget_cut;
        if fell_back {
            cells = build(0)?;
        }
        cells.list_blend_children(&self.p64);
        let stats = cells.stats();
        self.report
            .phases_ms
            .push(("field_prune".into(), t0.elapsed().as_secs_f64() * 1e3));
        self.report.counters.extend([
            ("prune_program_cells".into(), stats.program_cells as f64),
            ("prune_far_cells".into(), stats.far_cells as f64),
            (
                "prune_mean_cell_nodes".into(),
                stats.program_nodes as f64 / stats.program_cells.max(1) as f64,
            ),
            (
                "prune_max_cell_nodes".into(),
                stats.max_program_nodes as f64,
            ),
            ("prune_whole_cells".into(), stats.whole_cells as f64),
            ("prune_subset_cells".into(), stats.subset_cells as f64),
            ("prune_root_fallback".into(), f64::from(u8::from(fell_back))),
        ]);
        self.cells = Some(cells);
        Some(stats)
    }

    /// Whether the program holds a smooth union or a blend (which the per-bundle culling
    /// keeps whole).
    pub fn has_smooth_unions_or_blends(&self) -> bool {
        self.p64.instrs.iter().any(|i| {
            matches!(
                i.op,
                program::Op::Smooth {
                    op: marchmesh_scene::SmoothOp::Union | marchmesh_scene::SmoothOp::Blend,
                    ..
                }
            )
        })
    }

    /// Whether point queries run on pruned cells ([`Field::build_cells`]).
    pub fn has_cells(&self) -> bool {
        self.cells.is_some()
    }

    /// Signed distance bound at `p` (f32). 1e30 for an empty field.
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn distance(&self, p: Vec3) -> f32 {
        match &self.cells {
            Some(c) => c.eval::<false>(p, &self.p32, &self.grids).0,
            None => self.eval::<f32, false>(&self.p32, V3::new(p.x, p.y, p.z)).0,
        }
    }

    /// Signed distance bound at `p` in f64 (same formulas as [`Field::distance`]; the whole
    /// program's value in far cells).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn distance_f64(&self, p: DVec3) -> f64 {
        match &self.cells {
            Some(c) => c.eval_f64::<false>(p, &self.p64, &self.grids).0,
            None => self.eval::<f64, false>(&self.p64, V3::new(p.x, p.y, p.z)).0,
        }
    }

    /// A bound of the distance to the surfaces at `p` in f64 for marching: in the far cells of
    /// a pruned field ([`Field::build_cells`]) and outside its box their bound, elsewhere
    /// [`Field::distance_f64`]. Its sign is the field's everywhere, so sign changes along a
    /// ray are the field's.
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn distance_bound_f64(&self, p: DVec3) -> f64 {
        match self.cells.as_ref().and_then(|c| c.far_bound_f64(p)) {
            Some(b) => b,
            None => self.distance_f64(p),
        }
    }

    /// Distance and the material of the surface defining it (f32; the whole program's
    /// value in far cells, which carry no material).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn distance_material(&self, p: Vec3) -> (f32, MaterialId) {
        match &self.cells {
            Some(c) => c.eval::<true>(p, &self.p32, &self.grids),
            None => self.eval::<f32, true>(&self.p32, V3::new(p.x, p.y, p.z)),
        }
    }

    /// Distance and material in f64.
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn distance_material_f64(&self, p: DVec3) -> (f64, MaterialId) {
        match &self.cells {
            Some(c) => c.eval_f64::<true>(p, &self.p64, &self.grids),
            None => self.eval::<f64, true>(&self.p64, V3::new(p.x, p.y, p.z)),
        }
    }

    /// The distance at `p` (as [`Field::distance`]) and a safe step along `dir` from local
    /// directional Lipschitz bounds over the segment `[p, p + len dir]` (segment tracing,
    /// see [`program::segment`]): for a distance `d != 0` the field keeps the sign of `d` at
    /// `p + s dir` for every `s` in `[0, step)`. Never below `|d| / |dir|`; 0 when `d` is 0 or
    /// NaN. `len` must be positive (a longer segment gives looser bounds).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn segment_step(&self, p: Vec3, dir: Vec3, len: f32) -> (f32, f32) {
        // A segment inside one program cell reads the cell's program (the same values
        // along it); any other the whole program.
        match &self.cells {
            Some(c) => c.segment_f32(p, dir, len, &self.p32, &self.grids),
            None => self.segment_in(&self.p32, p, dir, len),
        }
    }

    /// [`Field::segment_step`] in f64 (same formulas).
    pub fn segment_step_f64(&self, p: DVec3, dir: DVec3, len: f64) -> (f64, f64) {
        let v = |a: DVec3| V3::new(a.x, a.y, a.z);
        self.p64.segment(v(p), v(dir), len, &self.grids)
    }

    #[inline]
    fn segment_in(&self, prog: &Program<f32>, p: Vec3, dir: Vec3, len: f32) -> (f32, f32) {
        let v = |a: Vec3| V3::new(a.x, a.y, a.z);
        prog.segment(v(p), v(dir), len, &self.grids)
    }

    /// Distances at eight points evaluated in lockstep (same values as [`Field::distance`]
    /// per lane).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn distance_x8(&self, p: [Vec3; 8]) -> [f32; 8] {
        self.distance_lanes(V3::from_points(p)).0
    }

    /// Distances and materials at eight points evaluated in lockstep (per lane the same as
    /// [`Field::distance_material`]).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn distance_material_x8(&self, p: [Vec3; 8]) -> ([f32; 8], [MaterialId; 8]) {
        let p = V3::from_points(p);
        if let Some(c) = &self.cells {
            let (d, m) = c.eval_x8::<true>(p, &self.p32, &self.grids);
            return (d.0, m);
        }
        let (d, m) = match &self.tape {
            Some(t) => t.eval::<F32x8, true>(p, &self.grids),
            None => self.eval::<F32x8, true>(&self.p32, p),
        };
        (d.0, m)
    }

    /// Distances of eight points given as SoA lanes (per lane the same as
    /// [`Field::distance`]).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn distance_lanes(&self, p: V3<F32x8>) -> F32x8 {
        if let Some(c) = &self.cells {
            return c.eval_x8::<false>(p, &self.p32, &self.grids).0;
        }
        if let Some(j) = &self.jit {
            return j.eval(p);
        }
        if let Some(k) = &self.kernel {
            return k.eval(p);
        }
        match &self.tape {
            Some(t) => t.eval::<F32x8, false>(p, &self.grids).0,
            None => self.eval::<F32x8, false>(&self.p32, p).0,
        }
    }

    /// Whether the ray from `p` along `dir` can meet no surface any more ([`Tape::recedes`]:
    /// every leaf convex and receding, or its box left behind); false when the field has no
    /// [`tape`] (the question is then not answered, never wrongly answered yes).
    pub fn recedes(&self, p: Vec3, dir: Vec3) -> bool {
        self.tape.as_ref().is_some_and(|t| t.recedes(p, dir))
    }

    /// [`Field::segment_step`] on eight lanes (points `p`, directions `d`, segment lengths
    /// `len`), per lane the same value and step bit for bit; `None` when the field has no
    /// [`tape`] (the scalar query serves it).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn segment_lanes(&self, p: V3<F32x8>, d: V3<F32x8>, len: F32x8) -> Option<(F32x8, F32x8)> {
        self.tape
            .as_ref()
            .map(|t| t.segment(p, d, len, &self.grids))
    }

    /// Distances and their gradients at eight points, by forward-mode differentiation of
    /// the f32 program ([`Dual8`]): the exact gradient of the evaluated expression (at a
    /// crease, of the branch the evaluation took; 0 where the distance is 0 on an unsigned
    /// surface). `None` when the field has mesh grids, which are sampled without a
    /// derivative, and when the field has no [`tape`] (the interpreter is not instantiated
    /// for dual numbers: its recursion made that instance too costly to compile). Distances
    /// are the same as [`Field::distance_x8`]'s.
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn distance_gradient_x8(&self, p: [Vec3; 8]) -> Option<([f32; 8], [Vec3; 8])> {
        if !self.grids.is_empty() {
            return None;
        }
        let t = self.tape.as_ref()?;
        let d = t
            .eval::<Dual8, false>(Dual8::seed(V3::from_points(p)), &self.grids)
            .0;
        let g = std::array::from_fn(|k| Vec3::new(d.d.x.0[k], d.d.y.0[k], d.d.z.0[k]));
        Some((d.v.0, g))
    }

    /// Normals' gradients at eight points on surfaces: per lane the analytic gradient of
    /// the leaf nearest to the point ([`Tape::nearest_gradients`]: at a hit, the surface
    /// hit), far cheaper than [`Field::distance_gradient_x8`] on a tape of several leaves
    /// and the same away from ties and bounds. A lane nearest a mesh grid gets NaN (a grid
    /// has no derivative). `None` when the field has no [`tape`] or no lane has a gradient.
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn nearest_gradients_x8(&self, p: [Vec3; 8]) -> Option<[Vec3; 8]> {
        let t = self.tape.as_ref()?;
        let g = t.nearest_gradients(V3::from_points(p), &self.grids);
        g.iter().any(|v| v.is_finite()).then_some(g)
    }

    /// [`Field::nearest_gradients_x8`] at one point (bit for bit a lane's result).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn nearest_gradient(&self, p: Vec3) -> Option<Vec3> {
        Some(self.tape.as_ref()?.nearest_gradient(p, &self.grids))
    }

    /// Turns the specialised 8-lane evaluation ([`kernel`]) on or off (off by default, see
    /// the module docs): with it on, [`Field::distance_lanes`] (and [`Field::distance_x8`]) and the restricted
    /// evaluations run the field's (or the restriction's) [`Kernel`] when its [`tape`] has
    /// one; the values are the same either way. Off: the tape and the interpreter.
    pub fn set_kernels(&mut self, on: bool) {
        self.kernels = on;
        self.kernel = self.kernel_of_tape();
    }

    /// The specialised [`Kernel`] [`Field::distance_lanes`] runs, if any (`None`: kernels
    /// are off, or the field has no tape or a tape without a kernel).
    pub fn kernel(&self) -> Option<&Kernel> {
        self.kernel.as_ref()
    }

    /// Turns the 8-lane evaluation compiled to machine code ([`jit`]) on or off (off by
    /// default): with it on, [`Field::distance_lanes`] and the restricted evaluations run
    /// a function compiled from the field's (or the restriction's) [`tape`] when it
    /// compiles (restrictions compiled once per set of kept nodes and cached), and the
    /// kernel or the tape otherwise; the values are the same either way.
    pub fn set_jit(&mut self, on: bool) {
        self.jits = on;
        self.jit_cache.clear();
        self.jit = self.jit_of_tape();
    }

    /// The compiled function [`Field::distance_lanes`] runs, if any (`None`: JIT
    /// compilation is off, or the field has no tape or one that does not compile).
    pub fn jit(&self) -> Option<&jit::Jit> {
        self.jit.as_deref()
    }

    /// Restrictions compiled so far (and cached) since JIT compilation was turned on.
    pub fn jit_cached(&self) -> usize {
        self.jit_cache.len()
    }

    /// The field's tape compiled, when JIT compilation is on and it compiles.
    fn jit_of_tape(&self) -> Option<std::sync::Arc<jit::Jit>> {
        if !self.jits {
            return None;
        }
        let t = self.tape.as_ref()?;
        jit::Jit::of(t).ok().map(std::sync::Arc::new)
    }

    /// The kernel of the field's tape, when kernels are on.
    fn kernel_of_tape(&self) -> Option<Kernel> {
        if !self.kernels {
            return None;
        }
        self.tape.as_ref().and_then(Kernel::of)
    }

    /// Whether the 8-lane evaluations run a flattened [`tape`] (a union of at most
    /// [`Tape::MAX_LEAVES`] analytic or mesh-grid leaves) rather than the interpreter.
    pub fn has_tape(&self) -> bool {
        self.tape.is_some()
    }

    /// The same field without its skipping bounds: every node is evaluated at every query
    /// (otherwise a subtree far outside its box contributes a bound instead of its value;
    /// the sign and the values near surfaces are the same either way) and [`Field::bounds`]
    /// is `None`, so a tracer has no scene box to clip rays to. What the sdf backend's `bounds=false` measures: the cost of
    /// a field evaluated without bounding volumes.
    pub fn without_bounds(mut self) -> Self {
        for i in &mut self.p32.instrs {
            i.has_bound = false;
        }
        for i in &mut self.p64.instrs {
            i.has_bound = false;
        }
        self.tape = Tape::of(&self.p32);
        self.kernel = self.kernel_of_tape();
        self.jit_cache.clear();
        self.jit = self.jit_of_tape();
        self.bounds = None;
        self.cells = None;
        self
    }

    /// Box containing every surface, `None` when unbounded (planes, infinite repetition),
    /// empty, or after [`Field::without_bounds`].
    pub fn bounds(&self) -> Option<(DVec3, DVec3)> {
        self.bounds
    }

    /// Exact bytes held: both programs (f32 and f64) and the mesh grids, from lengths.
    pub fn memory_bytes(&self) -> u64 {
        self.p32.memory_bytes()
            + self.p64.memory_bytes()
            + self.cells.as_ref().map_or(0, prune::Cells::memory_bytes)
            + self.grids.iter().map(|g| g.memory_bytes()).sum::<u64>()
    }

    /// Bytes of the f32 program and grids only (what the f32 tracer reads).
    pub fn memory_bytes_f32(&self) -> u64 {
        self.p32.memory_bytes() + self.grids.iter().map(|g| g.memory_bytes()).sum::<u64>()
    }

    /// Compile phases, counters and notes.
    pub fn report(&self) -> &FieldReport {
        &self.report
    }

    /// The program restricted to the ball of `radius` around `centre` ([`prune::prune`]),
    /// for reading many points inside the ball through [`Field::ball_distance_x8`]: at every
    /// point of the ball its value is within `max_error_rel` times the longest side of the
    /// field's box of the whole program's (`0` without finite bounds: exact). Points outside
    /// the ball get values that may be wrong. Costs a pass over the children near the ball
    /// ([`prune::prune_indexed`]).
    pub fn restricted_to_ball(
        &self,
        centre: DVec3,
        radius: f64,
        max_error_rel: f64,
    ) -> BallProgram {
        let extent = self
            .bounds
            .map(|(lo, hi)| (hi - lo).max_element())
            .filter(|e| e.is_finite())
            .unwrap_or(0.0);
        let max_error = (max_error_rel * extent).max(0.0);
        let pruned = prune::prune_indexed(
            &self.p64,
            self.prune_index(),
            &self.grids,
            centre,
            radius,
            max_error,
        );
        BallProgram {
            p32: pruned.program.cast::<f32>(),
        }
    }

    /// Distances at eight points inside the ball `ball` was restricted to (per lane the
    /// whole field's [`Field::distance`] within the error given to
    /// [`Field::restricted_to_ball`]).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn ball_distance_x8(&self, ball: &BallProgram, p: [Vec3; 8]) -> [f32; 8] {
        ball.p32
            .eval::<F32x8, false>(V3::from_points(p), &self.grids)
            .0
            .0
    }

    /// The material every point of the field has when all its nodes carry one material (so
    /// no evaluation is needed to know it), else `None`.
    pub fn single_material(&self) -> Option<MaterialId> {
        let first = self.p64.instrs.first()?.material;
        self.p64
            .instrs
            .iter()
            .all(|i| i.material == first)
            .then_some(first)
    }

    /// The child trees the pruner reads ([`prune::PruneIndex`]), built on first use.
    fn prune_index(&self) -> &prune::PruneIndex {
        self.prune_index
            .get_or_init(|| prune::PruneIndex::build(&self.p64))
    }

    /// The compiled f64 program (the whole one, never a pruned cell's).
    pub fn program_f64(&self) -> &Program<f64> {
        &self.p64
    }

    /// Number of program nodes.
    pub fn node_count(&self) -> usize {
        self.p64.instrs.len()
    }
}
