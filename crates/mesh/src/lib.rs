//! The mesh backend of marchmesh: every object becomes triangles in obvhs BVHs.
//!
//! * Analytic shapes are tessellated to an error budget ([`Tessellation`]): by default the
//!   chord error, seen from the shape's nearest distance to the camera, stays under a quarter
//!   of a pixel. Planes become a finite quad grid covering `render.max_distance` around the
//!   camera's foot point.
//! * Meshes load through `marchmesh-meshio` (OBJ, glTF/.glb).
//! * CSG intersections, subtractions and smooth unions have no exact triangle form: their
//!   surface is extracted from the shared distance field (`marchmesh-field`) with surface
//!   nets, restricted to the object's bounds. Plain unions need no extraction: their
//!   children are traced directly (same first hit for rays starting outside the solid).
//! * Shapes placed more than once (repetition, a mesh used twice) are built once as a
//!   bottom-level BVH and instanced under a top-level BVH with object-to-render transforms;
//!   everything placed once is flattened into one render-space BVH. Infinite repetition is
//!   bounded to the cells within `max_distance` of the camera (reported in the notes).
//! * Shading normals interpolate vertex normals with barycentrics where the surface has
//!   them (tessellations, meshes with normals), geometric normals otherwise.
//!
//! All data is in render space (world minus camera position, in f64 before converting to
//! f32), as the [`marchmesh_core::Geometry`] contract requires.

mod blas;
mod build;
pub mod extract;
mod options;
// SIMD traversal: std::arch intrinsics behind runtime feature detection (each unsafe call
// states why the CPU feature is present); the only unsafe code besides the counting allocator.
#[allow(unsafe_code)]
mod packet;
mod settings;
pub mod tessellate;
#[allow(unsafe_code)]
mod wide;

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use glam::{Affine3A, DAffine3, DVec3, Vec3, Vec3A};
use marchmesh_core::{
    Geometry, GeometryReport, Hit, NoHit, OcclusionResult, Ray, RayWork, RenderSpace, Termination,
    TraceResult,
};
use marchmesh_meshio::{MeshLoadError, TriangleMesh, load_mesh};
use marchmesh_scene::{MaterialId, Node, NodeKind, Scene, Shape};
use obvhs::ray::Ray as ObRay;

use blas::{Blas, BlasHit, BlasInput, Tree};
use build::{Placement, ShapeKey};

pub use extract::MAX_SURFACE_RESOLUTION;
pub use options::{
    BUILD_BYTES_PER_TRIANGLE, BuildQuality, BvhKind, Extraction, MAX_SEGMENTS_PER_TURN,
    MAX_TESS_LEVEL, MeshOptions, MeshPreset, Tessellation,
};
pub use settings::MeshBackend;
use tessellate::{Detail, LocalMesh, ScreenBudget};

/// Why the mesh backend could not build a scene.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// A mesh file could not be loaded (the message names the file and the reason).
    #[error("{json_path}: {source}")]
    Load {
        /// The scene object that uses the mesh.
        json_path: String,
        /// What went wrong.
        source: MeshLoadError,
    },
    /// The scene uses something this backend cannot turn into triangles.
    #[error("{json_path}: not supported by the mesh backend: {reason}")]
    Unsupported {
        /// The offending object.
        json_path: String,
        /// Why.
        reason: String,
    },
    /// A repetition places more copies than `MeshOptions::max_instances`: a finite one by its
    /// counts, an infinite one by the cells within `max_distance` of the camera.
    #[error(
        "{json_path}: {} would need {cells} cells{} (limit {limit}); {} or raise max_instances",
        if *infinite { "infinite repetition" } else { "finite repetition" },
        if *infinite { " within max_distance" } else { " by its counts" },
        if *infinite { "lower render.max_distance" } else { "lower its counts" }
    )]
    TooManyInstances {
        /// The repeat node.
        json_path: String,
        /// Cells needed.
        cells: u64,
        /// The limit.
        limit: u64,
        /// Whether some repeated axis has no count (cells counted within `max_distance`).
        infinite: bool,
    },
    /// The build would need more memory than [`MeshOptions::memory_limit_bytes`]; refused
    /// before allocating it.
    #[error(
        "{json_path}: {what} would bring the mesh backend's build to about {needed_mib} MiB, over the memory limit of {limit_mib} MiB; raise --memory-limit-mib or coarsen {knob}"
    )]
    OverMemoryLimit {
        /// The object whose geometry crossed the limit.
        json_path: String,
        /// What was about to be built (e.g. "16433316 triangles of tessellation").
        what: String,
        /// Estimated build memory including this object, MiB (rounded up).
        needed_mib: u64,
        /// The limit, MiB.
        limit_mib: u64,
        /// The option that controls this object's size.
        knob: &'static str,
    },
    /// An option is out of range.
    #[error("invalid mesh backend option: {0}")]
    InvalidOption(String),
}

/// Bytes per placement (the walk's placement, the instance and its box), for the estimate.
const INSTANCE_BYTES: u64 = 160;

/// Bytes per cell of a surface-extraction grid (f32 samples plus surface nets' per-cell
/// vertex map), for the estimate.
const EXTRACTION_BYTES_PER_CELL: u64 = 12;

/// The build's running memory estimate against [`MeshOptions::memory_limit_bytes`].
struct BuildBudget {
    limit_bytes: u64,
    planned_bytes: u64,
}

impl BuildBudget {
    /// Triangles that still fit, `copies` times each.
    fn triangles_left(&self, copies: u64) -> u64 {
        self.limit_bytes.saturating_sub(self.planned_bytes)
            / BUILD_BYTES_PER_TRIANGLE
            / copies.max(1)
    }

    /// Adds `bytes` (kept for the rest of the build when `keep`), or refuses.
    fn take(
        &mut self,
        bytes: u64,
        keep: bool,
        json_path: &str,
        what: impl FnOnce() -> String,
        knob: &'static str,
    ) -> Result<(), MeshError> {
        let needed = self.planned_bytes.saturating_add(bytes);
        if needed > self.limit_bytes {
            return Err(self.refusal(bytes, json_path, what(), knob));
        }
        if keep {
            self.planned_bytes = needed;
        }
        Ok(())
    }

    /// The error refusing `bytes` more.
    fn refusal(&self, bytes: u64, json_path: &str, what: String, knob: &'static str) -> MeshError {
        MeshError::OverMemoryLimit {
            json_path: json_path.to_string(),
            what,
            needed_mib: self.planned_bytes.saturating_add(bytes).div_ceil(1 << 20),
            limit_mib: self.limit_bytes >> 20,
            knob,
        }
    }
}

/// One placement of a BLAS: the render-to-local transform and the fallback material.
#[derive(Debug, Clone, Copy)]
struct Instance {
    to_local: Affine3A,
    blas: u32,
    material: MaterialId,
}

/// Where a closest hit was found.
#[derive(Debug, Clone, Copy)]
enum HitSource {
    Flat,
    Instance(u32),
}

/// Wide BVH size (nodes and triangle blocks, bytes) above which [`Geometry::closest_hits`]
/// traces its batches as interleaved single rays ([`wide::WideBvh::closest_interleaved`])
/// instead of packets or one ray after another. Interleaving hides the cache misses of a
/// tree far larger than the caches but costs bookkeeping on a cached one. Measured: `docs/decisions/0013`.
const INTERLEAVE_MIN_BYTES: u64 = 16 << 20;

/// The built mesh backend: a render-space BVH of everything placed once, plus instanced
/// BLASes under a TLAS. Implements [`Geometry`].
#[derive(Clone)]
pub struct MeshGeometry {
    flat: Option<Blas>,
    flat_materials_default: MaterialId,
    packets: bool,
    /// Whether batches are traced as interleaved single rays (a flat wide BVH larger than
    /// [`INTERLEAVE_MIN_BYTES`], no instances).
    interleave: bool,
    blases: Vec<Blas>,
    instances: Vec<Instance>,
    tlas: Option<Tree>,
    max_distance: f32,
    report: GeometryReport,
}

/// Builds the mesh representation of `scene`.
///
/// Errors: an unreadable or invalid mesh file, an infinite repetition of an unbounded
/// child or with more cells than `options.max_instances`, a CSG object when the distance
/// field cannot be evaluated, or an out-of-range option.
pub fn build(scene: &Scene, options: &MeshOptions) -> Result<MeshGeometry, MeshError> {
    check_options(options)?;
    let mut report = GeometryReport {
        backend: <MeshBackend as marchmesh_core::Backend>::NAME.into(),
        ..GeometryReport::default()
    };
    let space = RenderSpace::of(scene);

    // Phase 1: load every mesh file once.
    let t0 = Instant::now();
    let meshes = load_meshes(scene, &mut report)?;
    let mesh_bounds: HashMap<PathBuf, (DVec3, DVec3)> = meshes
        .iter()
        .map(|(p, m)| {
            let (lo, hi) = m.bounds();
            (p.clone(), (lo.as_dvec3(), hi.as_dvec3()))
        })
        .collect();
    let load_ms = ms(t0.elapsed());

    // Phase 2: walk the scene, group placements by shape, make each shape's triangles.
    let t1 = Instant::now();
    let walk = build::walk(scene, options, space.from_world(), &mesh_bounds)?;
    report.notes.extend(walk.notes.iter().cloned());
    let groups = group_by_shape(&walk.placements);
    let shapes = ShapeInputs {
        scene,
        options,
        meshes: &meshes,
        mesh_bounds: &mesh_bounds,
    };
    let (local_meshes, extract_time) =
        shapes.triangulate(&groups, walk.placements.len(), &mut report)?;
    let tessellate_ms = ms(t1.elapsed().saturating_sub(extract_time));
    let extract_ms = ms(extract_time);

    // Phase 3: assemble flat and instanced geometry and build the BVHs.
    let t2 = Instant::now();
    let built = shapes.assemble(&groups, &local_meshes, &walk, &mut report);
    let bvh_ms = ms(t2.elapsed());
    report.build_phases_ms = vec![
        ("load".into(), load_ms),
        ("tessellate".into(), tessellate_ms),
        ("extract".into(), extract_ms),
        ("bvh".into(), bvh_ms),
    ];
    describe(&built, &walk, options, &mut report);
    let Assembled {
        flat_blas,
        flat_material,
        blases,
        instances,
        tlas,
        ..
    } = built;
    let interleave = tlas.is_none()
        && flat_blas
            .as_ref()
            .and_then(Blas::wide)
            .is_some_and(|w| w.memory_bytes() > INTERLEAVE_MIN_BYTES);
    if interleave {
        report.notes.push(format!(
            "the wide BVH exceeds {} MiB: batches are traced as {} interleaved single rays",
            INTERLEAVE_MIN_BYTES >> 20,
            wide::INTERLEAVE
        ));
    }
    Ok(MeshGeometry {
        flat: flat_blas,
        flat_materials_default: flat_material,
        packets: options.packets(),
        interleave,
        blases,
        instances,
        tlas,
        max_distance: scene.render.max_distance as f32,
        report,
    })
}

/// Phase 1: every mesh file of the scene loaded once, with notes on skipped triangles.
fn load_meshes(
    scene: &Scene,
    report: &mut GeometryReport,
) -> Result<HashMap<PathBuf, TriangleMesh>, MeshError> {
    let mut meshes: HashMap<PathBuf, TriangleMesh> = HashMap::new();
    let mut load_error = None;
    scene.visit_nodes(|n| {
        if let NodeKind::Leaf(Shape::Mesh { path }) = &n.kind
            && !meshes.contains_key(path)
            && load_error.is_none()
        {
            match load_mesh(path) {
                Ok(m) => {
                    let r = &m.report;
                    if r.degenerate_skipped + r.duplicate_skipped > 0 {
                        report.notes.push(format!(
                            "{}: skipped {} degenerate and {} duplicate triangles of {}",
                            path.display(),
                            r.degenerate_skipped,
                            r.duplicate_skipped,
                            r.triangles_read
                        ));
                    }
                    report
                        .notes
                        .extend(r.notes.iter().map(|s| format!("{}: {s}", path.display())));
                    meshes.insert(path.clone(), m);
                }
                Err(source) => {
                    load_error = Some(MeshError::Load {
                        json_path: n.json_path.clone(),
                        source,
                    })
                }
            }
        }
    });
    match load_error {
        Some(e) => Err(e),
        None => Ok(meshes),
    }
}

/// Placements grouped by shape, in first-appearance order.
fn group_by_shape<'p, 'a>(
    placements: &'p [Placement<'a>],
) -> Vec<(ShapeKey, Vec<&'p Placement<'a>>)> {
    let mut groups: Vec<(ShapeKey, Vec<&'p Placement<'a>>)> = Vec::new();
    let mut group_of: HashMap<ShapeKey, usize> = HashMap::new();
    for p in placements {
        let g = *group_of.entry(p.key.clone()).or_insert_with(|| {
            groups.push((p.key.clone(), Vec::new()));
            groups.len() - 1
        });
        groups[g].1.push(p);
    }
    groups
}

/// What phases 2 and 3 read: the scene, the options and the loaded meshes.
struct ShapeInputs<'a> {
    scene: &'a Scene,
    options: &'a MeshOptions,
    meshes: &'a HashMap<PathBuf, TriangleMesh>,
    mesh_bounds: &'a HashMap<PathBuf, (DVec3, DVec3)>,
}

/// Phase 3's result: the flat BVH, the instanced BLASes, their instances and the TLAS.
struct Assembled {
    flat_blas: Option<Blas>,
    /// Material of every flat triangle when they all share one (the flat BLAS then keeps no
    /// per-triangle materials and a hit needs no lookup); 0 otherwise.
    flat_material: MaterialId,
    flat_triangles: usize,
    blases: Vec<Blas>,
    instances: Vec<Instance>,
    tlas: Option<Tree>,
}

impl ShapeInputs<'_> {
    /// Phase 2: the local triangles of every group (analytic shapes tessellated at the finest
    /// detail any placement needs, CSG surfaces extracted; `None` for mesh files, used as
    /// loaded), refusing before allocating when the build would exceed the memory limit.
    /// Returns the meshes and the time spent extracting.
    fn triangulate(
        &self,
        groups: &[(ShapeKey, Vec<&Placement>)],
        placement_count: usize,
        report: &mut GeometryReport,
    ) -> Result<(Vec<Option<LocalMesh>>, Duration), MeshError> {
        let options = self.options;
        let mut local_meshes: Vec<Option<LocalMesh>> = Vec::with_capacity(groups.len());
        let mut extract_time = Duration::ZERO;
        let mut budget = BuildBudget {
            limit_bytes: options.memory_limit_bytes,
            planned_bytes: 0,
        };
        budget.take(
            (placement_count as u64).saturating_mul(INSTANCE_BYTES),
            true,
            "objects",
            || format!("{placement_count} placements"),
            "max_instances",
        )?;
        // Every extraction's output estimated before the first one runs (each can take
        // seconds): a build over the limit is refused before any work.
        // Triangles are stored once per placement unless instanced.
        let copies_of = |placements: &[&Placement]| {
            if options.instancing() && placements.len() > 1 {
                1
            } else {
                placements.len() as u64
            }
        };
        // Each composite group's extraction grid, computed once (`None` for other groups).
        let resolutions: Vec<Option<u32>> = groups
            .iter()
            .map(|(key, placements)| {
                matches!(key, ShapeKey::Composite(_))
                    .then(|| self.extraction_resolution(placements))
                    .transpose()
            })
            .collect::<Result<_, _>>()?;
        let extractions: Vec<(&str, u64, u32)> = groups
            .iter()
            .zip(&resolutions)
            .filter_map(|((_, placements), res)| {
                Some((
                    placements[0].node.json_path.as_str(),
                    copies_of(placements),
                    (*res)?,
                ))
            })
            .collect();
        if let Some((first, ..)) = extractions.first() {
            let bytes = extractions
                .iter()
                .map(|&(_, copies, res)| triangle_bytes(extracted_triangles_estimate(res), copies))
                .fold(0u64, u64::saturating_add);
            if budget.planned_bytes.saturating_add(bytes) > budget.limit_bytes {
                let copies: u64 = extractions.iter().map(|e| e.1).sum();
                let finest = extractions.iter().map(|e| e.2).max().unwrap_or(0);
                return Err(budget.refusal(
                    bytes,
                    first,
                    format!(
                        "{} surface extractions ({copies} copies in all) on grids of up to {finest} cells a side",
                        extractions.len()
                    ),
                    EXTRACTION_KNOB,
                ));
            }
        }
        for ((key, placements), resolution) in groups.iter().zip(resolutions) {
            let node = placements[0].node;
            let copies = copies_of(placements);
            let mesh = match key {
                ShapeKey::Analytic(..) => {
                    Some(self.tessellate(node, placements, copies, &mut budget, report)?)
                }
                ShapeKey::Composite(_) => {
                    let resolution = resolution.unwrap_or(MAX_SURFACE_RESOLUTION);
                    Some(self.extract(
                        node,
                        resolution,
                        copies,
                        &mut budget,
                        &mut extract_time,
                        report,
                    )?)
                }
                ShapeKey::Mesh(path) => {
                    let triangles = self
                        .meshes
                        .get(path)
                        .map_or(0, |m| m.triangles.len() as u64);
                    budget.take(
                        triangle_bytes(triangles, copies),
                        true,
                        &node.json_path,
                        || format!("{triangles} triangles of {} x {copies}", path.display()),
                        "the mesh (a smaller file, or instancing=true)",
                    )?;
                    None
                }
            };
            local_meshes.push(mesh);
        }
        Ok((local_meshes, extract_time))
    }

    /// An analytic shape tessellated at the finest detail any of its placements needs.
    fn tessellate(
        &self,
        node: &Node,
        placements: &[&Placement],
        copies: u64,
        budget: &mut BuildBudget,
        report: &mut GeometryReport,
    ) -> Result<LocalMesh, MeshError> {
        let (options, mesh_bounds) = (self.options, self.mesh_bounds);
        let pixel_angle = self.scene.camera.pixel_angle();
        let local = build::local_bounds(node, mesh_bounds).unwrap_or((DVec3::ZERO, DVec3::ZERO));
        let screen_budget;
        let detail = match options.tessellation()? {
            Tessellation::ScreenError { pixels } => {
                screen_budget = screen_budget_for(placements, local, pixels * pixel_angle);
                Detail::Screen(&screen_budget)
            }
            other => placements
                .iter()
                .map(|p| build::placement_detail(p, other))
                .reduce(build::finer)
                .unwrap_or(Detail::Level(0)),
        };
        let tessellated = tessellate::tessellate_within(
            &node.kind,
            detail,
            options.max_segments_per_turn(),
            budget.triangles_left(copies),
        );
        let mesh = match tessellated {
            Ok(Some(mesh)) => mesh,
            Ok(None) => {
                return Err(MeshError::Unsupported {
                    json_path: node.json_path.clone(),
                    reason: "shape has no tessellation".into(),
                });
            }
            Err(too_many) => {
                return Err(budget.refusal(
                        triangle_bytes(too_many.triangles, copies),
                        &node.json_path,
                        format!(
                            "tessellating into {} triangles (segments per turn {:?}) x {copies} placement(s)",
                            too_many.triangles, too_many.segments
                        ),
                        "the tessellation (--opt tess_px / tess_chord / tess_level / max_segments)",
                    ));
            }
        };
        budget.take(
            triangle_bytes(mesh.triangles.len() as u64, copies),
            true,
            &node.json_path,
            || format!("{} triangles of tessellation", mesh.triangles.len()),
            "the tessellation (--opt tess_px / tess_chord / tess_level / max_segments)",
        )?;
        if !mesh.segments.is_empty() {
            let capped = mesh
                .segments
                .iter()
                .any(|&s| s >= options.max_segments_per_turn());
            report.notes.push(format!(
                "{}: {} triangles, segments per turn {:?}{}{}",
                node.json_path,
                mesh.triangles.len(),
                mesh.segments,
                match detail {
                    Detail::ChordError(e) => format!(", local chord budget {e:.3e}"),
                    Detail::Level(l) => format!(", level {l}"),
                    Detail::Screen(_) => match options.tessellation()? {
                        Tessellation::ScreenError { pixels } =>
                            format!(", screen budget {pixels} px per band"),
                        _ => String::new(),
                    },
                },
                if capped {
                    " (capped by max_segments_per_turn)"
                } else {
                    ""
                }
            ));
        }
        Ok(mesh)
    }

    /// The extraction grid's cells along the longest side of a composite's bounds: by
    /// [`MeshOptions::extraction`], on screen from the nearest placement (one mesh serves
    /// every placement, so the finest need wins), clamped to `8..=MAX_SURFACE_RESOLUTION`.
    fn extraction_resolution(&self, placements: &[&Placement]) -> Result<u32, MeshError> {
        let pixels = match self.options.extraction()? {
            Extraction::Cells(cells) => return Ok(cells),
            Extraction::ScreenCell { pixels } => pixels,
        };
        let Some(local) = build::local_bounds(placements[0].node, self.mesh_bounds) else {
            // Unbounded: the extraction refuses it, naming the node.
            return Ok(8);
        };
        let cell_per_distance = pixels * self.scene.camera.pixel_angle();
        let finest = placements
            .iter()
            .map(|p| {
                let world = build::transform_bounds(&p.to_render, local);
                let size = (world.1 - world.0).max_element();
                // A camera on or inside the bounds sees it at most a thousandth of its size
                // away (as the tessellation's screen budget assumes).
                let distance = build::distance_to_box(world).max(1e-3 * size);
                size / (cell_per_distance * distance)
            })
            .fold(0.0f64, f64::max);
        // Never coarser than 128 / pixels cells a side: a cell small on screen can still be
        // large against the surface's curvature, which the normals show (decision 0015).
        let floor =
            (SCREEN_CELL_FLOOR / pixels).clamp(8.0, f64::from(extract::MAX_SURFACE_RESOLUTION));
        let max = f64::from(extract::MAX_SURFACE_RESOLUTION);
        Ok(if finest.is_nan() {
            extract::MAX_SURFACE_RESOLUTION
        } else {
            finest.max(floor).ceil().clamp(8.0, max) as u32
        })
    }

    /// A CSG node's surface extracted from its distance field on a grid of `resolution`
    /// cells along its longest side.
    fn extract(
        &self,
        node: &Node,
        resolution: u32,
        copies: u64,
        budget: &mut BuildBudget,
        extract_time: &mut Duration,
        report: &mut GeometryReport,
    ) -> Result<LocalMesh, MeshError> {
        let te = Instant::now();
        let local = build::local_bounds(node, self.mesh_bounds);
        // Meshes inside a CSG node are baked to distance grids as fine as the
        // extraction grid: a finer bake would not show, a coarser one would.
        let field_options = marchmesh_field::FieldOptions {
            mesh_grid_resolution: resolution,
            cache_dir: None,
            ..marchmesh_field::FieldOptions::DEFAULT
        };
        let cells = u64::from(resolution + 1).pow(3);
        budget.take(
            cells.saturating_mul(EXTRACTION_BYTES_PER_CELL),
            false,
            &node.json_path,
            || format!("a surface-extraction grid of {}^3 cells", resolution),
            EXTRACTION_KNOB,
        )?;
        let mesh = extract::extract(node, local, resolution, &field_options)?;
        budget.take(
            triangle_bytes(mesh.triangles.len() as u64, copies),
            true,
            &node.json_path,
            || format!("{} extracted triangles", mesh.triangles.len()),
            EXTRACTION_KNOB,
        )?;
        report.notes.push(format!(
            "{}: surface extracted from the distance field, {} triangles at resolution {}",
            node.json_path,
            mesh.triangles.len(),
            resolution
        ));

        *extract_time += te.elapsed();
        Ok(mesh)
    }

    /// Phase 3: flat and instanced geometry assembled and their BVHs built.
    fn assemble(
        &self,
        groups: &[(ShapeKey, Vec<&Placement>)],
        local_meshes: &[Option<LocalMesh>],
        walk: &build::Walk<'_>,
        report: &mut GeometryReport,
    ) -> Assembled {
        let (scene, options, meshes) = (self.scene, self.options, self.meshes);
        let params = options.build_quality().params();
        let mut flat = FlatBuilder::default();
        let mut blases: Vec<Blas> = Vec::new();
        let mut instances: Vec<Instance> = Vec::new();
        let mut instance_boxes: Vec<obvhs::aabb::Aabb> = Vec::new();
        for ((key, placements), local) in groups.iter().zip(local_meshes) {
            let source: SourceMesh = match (key, local) {
                (ShapeKey::Mesh(path), _) => match meshes.get(path) {
                    Some(m) => SourceMesh::File(m),
                    None => continue,
                },
                (_, Some(l)) => SourceMesh::Local(l),
                _ => continue,
            };
            if options.instancing() && placements.len() > 1 {
                let input = source.blas_input();
                if input.triangles.is_empty() {
                    continue;
                }
                let local_box = positions_bounds(&input.positions);
                let blas_index = blases.len() as u32;
                blases.push(Blas::build(input, options.bvh(), params));
                for p in placements {
                    instance_boxes.push(render_box(&p.to_render, local_box));
                    instances.push(Instance {
                        to_local: p.to_render.inverse().as_affine3a_checked(),
                        blas: blas_index,
                        material: p.material,
                    });
                }
            } else {
                for p in placements {
                    flat.append(&source, &p.to_render, p.material);
                }
            }
        }
        for (node, m) in &walk.planes {
            if let NodeKind::Leaf(Shape::Plane { normal, offset }) = node.kind {
                let quads =
                    flat.append_plane(normal, offset, m, scene.render.max_distance, node.material);
                report.notes.push(format!(
                    "{}: plane clipped to a {:.6}-unit square around the camera's foot point ({quads} cells)",
                    node.json_path,
                    2.0 * scene.render.max_distance
                ));
            }
        }
        let flat_triangles = flat.triangles.len();
        let (input, flat_material) = flat.into_input();
        let flat_blas =
            (!input.triangles.is_empty()).then(|| Blas::build(input, options.bvh(), params));
        let tlas = if instances.is_empty() {
            None
        } else {
            let boxes = instance_boxes;
            let mut t = Duration::default();
            let mut tlas = obvhs::bvh2::builder::build_bvh2(&boxes, params, &mut t);
            tlas.primitives_to_nodes = Vec::new();
            tlas.parents = Vec::new();
            tlas.primitive_indices_freelist = Vec::new();
            tlas.nodes.shrink_to_fit();
            Some(Tree::Bvh2(tlas))
        };

        Assembled {
            flat_blas,
            flat_material,
            flat_triangles,
            blases,
            instances,
            tlas,
        }
    }
}

/// Peak build bytes of `triangles` stored `copies` times.
/// Triangles expected from extracting a surface on a grid of `resolution` cells along its
/// longest side, for the estimate made before any extraction: a sphere filling the grid
/// (surface nets emit two triangles per grid face the surface crosses: `2 pi res^2`). A
/// surface with more area in the same box (many small parts) gives more; the exact count is
/// charged after each extraction.
/// [`Extraction::ScreenCell`] grids have at least this many cells a side divided by the
/// cell's pixels.
const SCREEN_CELL_FLOOR: f64 = 128.0;

/// What to change when extraction is over the memory limit.
const EXTRACTION_KNOB: &str = "the extraction grid (--opt surface_px or surface_res)";

fn extracted_triangles_estimate(resolution: u32) -> u64 {
    let r = u64::from(resolution);
    (r * r).saturating_mul(2 * 314) / 100
}

fn triangle_bytes(triangles: u64, copies: u64) -> u64 {
    triangles
        .saturating_mul(copies)
        .saturating_mul(BUILD_BYTES_PER_TRIANGLE)
}

/// The report's memory, triangle counts, counters and notes on the built geometry.
fn describe(
    built: &Assembled,
    walk: &build::Walk<'_>,
    options: &MeshOptions,
    report: &mut GeometryReport,
) {
    let Assembled {
        flat_blas,
        flat_triangles,
        blases,
        instances,
        tlas,
        ..
    } = built;
    let flat_triangles = *flat_triangles;
    let blas_triangles: usize = blases.iter().map(|b| b.triangle_count).sum();
    let instance_bytes = (instances.len() * size_of::<Instance>()) as u64;
    let memory = flat_blas.as_ref().map_or(0, Blas::memory_bytes)
        + blases.iter().map(Blas::memory_bytes).sum::<u64>()
        + instance_bytes
        + tlas.as_ref().map_or(0, Tree::memory_bytes);
    report.memory_bytes = memory;
    report.triangles = Some((flat_triangles + blas_triangles) as u64);
    let rendered_triangles: u64 = flat_triangles as u64
        + instances
            .iter()
            .map(|i| blases[i.blas as usize].triangle_count as u64)
            .sum::<u64>();
    report.counters = vec![
        ("flat_triangles".into(), flat_triangles as f64),
        ("blas_count".into(), blases.len() as f64),
        ("blas_triangles".into(), blas_triangles as f64),
        ("instances".into(), instances.len() as f64),
        ("repeat_cells".into(), walk.repeat_cells as f64),
        ("instanced_triangles".into(), rendered_triangles as f64),
        (
            "bvh_nodes".into(),
            (flat_blas.as_ref().map_or(0, |b| b.tree.node_count())
                + blases.iter().map(|b| b.tree.node_count()).sum::<usize>()) as f64,
        ),
        (
            "tlas_nodes".into(),
            tlas.as_ref().map_or(0, Tree::node_count) as f64,
        ),
        ("instance_bytes".into(), instance_bytes as f64),
    ];
    report.notes.push(format!(
        "bvh: {:?} with {:?} preset; instancing {}",
        options.bvh(),
        options.build_quality(),
        if options.instancing() { "on" } else { "off" }
    ));
    let fell_back = flat_blas
        .iter()
        .chain(blases.iter())
        .filter(|b| b.tree.kind() != options.bvh())
        .count();
    if fell_back > 0 {
        report.notes.push(format!(
            "{fell_back} BVH(s) smaller than {} units built as Bvh2: obvhs CwBvh loses rays on tiny trees",
            blas::CWBVH_MIN_EXTENT
        ));
    }
}

/// Most placements a screen budget considers (the nearest ones; farther copies of a shape
/// almost never need a finer band than the nearest).
const MAX_BUDGET_PLACEMENTS: usize = 512;

/// The screen-space budget of a shape from its placements (the nearest
/// [`MAX_BUDGET_PLACEMENTS`]), distances floored at 1/1000 of the shape's size.
fn screen_budget_for(
    placements: &[&Placement],
    local: (DVec3, DVec3),
    error_per_distance: f64,
) -> ScreenBudget {
    let mut by_distance: Vec<(f64, f64, DAffine3)> = placements
        .iter()
        .map(|p| {
            let world = build::transform_bounds(&p.to_render, local);
            (
                build::distance_to_box(world),
                (world.1 - world.0).length(),
                p.to_render,
            )
        })
        .collect();
    by_distance.sort_by(|a, b| a.0.total_cmp(&b.0));
    by_distance.truncate(MAX_BUDGET_PLACEMENTS);
    let min_distance = by_distance
        .iter()
        .map(|(_, size, _)| size * 1e-3)
        .fold(f64::INFINITY, f64::min)
        .max(f64::MIN_POSITIVE);
    let transforms: Vec<DAffine3> = by_distance.iter().map(|(_, _, m)| *m).collect();
    ScreenBudget::new(&transforms, error_per_distance, min_distance)
}

fn check_options(o: &MeshOptions) -> Result<(), MeshError> {
    match o.tessellation()? {
        Tessellation::ScreenError { pixels } if !(pixels.is_finite() && pixels > 0.0) => {
            return Err(MeshError::InvalidOption(format!(
                "tess_px must be a finite number of pixels > 0, got {pixels}"
            )));
        }
        Tessellation::ChordError { world } if !(world > 0.0 && world.is_finite()) => {
            return Err(MeshError::InvalidOption(format!(
                "tess_chord must be a finite length in world units > 0, got {world}"
            )));
        }
        Tessellation::FixedLevel(l) if l > MAX_TESS_LEVEL => {
            return Err(MeshError::InvalidOption(format!(
                "tess_level must be in 0..={MAX_TESS_LEVEL}, got {l}"
            )));
        }
        _ => {}
    }
    match o.extraction()? {
        Extraction::Cells(cells) if !(8..=extract::MAX_SURFACE_RESOLUTION).contains(&cells) => {
            return Err(MeshError::InvalidOption(format!(
                "surface_res must be in 8..={}, got {cells}",
                extract::MAX_SURFACE_RESOLUTION,
            )));
        }
        Extraction::ScreenCell { pixels } if !(pixels.is_finite() && pixels > 0.0) => {
            return Err(MeshError::InvalidOption(format!(
                "surface_px must be > 0, got {pixels}"
            )));
        }
        _ => {}
    }
    if !(8..=MAX_SEGMENTS_PER_TURN).contains(&o.max_segments_per_turn()) {
        return Err(MeshError::InvalidOption(format!(
            "max_segments_per_turn must be in 8..={MAX_SEGMENTS_PER_TURN}, got {}",
            o.max_segments_per_turn()
        )));
    }
    Ok(())
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// f64 affine to f32 (render-space magnitudes are bounded by max_distance).
trait AsAffine3A {
    fn as_affine3a_checked(&self) -> Affine3A;
}

impl AsAffine3A for DAffine3 {
    fn as_affine3a_checked(&self) -> Affine3A {
        Affine3A::from_mat3_translation(self.matrix3.as_mat3(), self.translation.as_vec3())
    }
}

/// Bounds of f32 positions, in f64.
fn positions_bounds(positions: &[Vec3]) -> (DVec3, DVec3) {
    let mut lo = Vec3::INFINITY;
    let mut hi = Vec3::NEG_INFINITY;
    for p in positions {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    (lo.as_dvec3(), hi.as_dvec3())
}

/// Render-space box of a placed local box, widened by a relative epsilon so that f32
/// rounding never cuts a copy.
fn render_box(to_render: &DAffine3, local: (DVec3, DVec3)) -> obvhs::aabb::Aabb {
    let (lo, hi) = build::transform_bounds(to_render, local);
    let pad = (hi - lo).max_element() * 1e-5 + lo.abs().max(hi.abs()).max_element() * 1e-6;
    obvhs::aabb::Aabb::new((lo - pad).as_vec3().into(), (hi + pad).as_vec3().into())
}

/// A shape's triangles before placement.
enum SourceMesh<'a> {
    File(&'a TriangleMesh),
    Local(&'a LocalMesh),
}

impl SourceMesh<'_> {
    fn vertex_count(&self) -> usize {
        match self {
            SourceMesh::File(m) => m.positions.len(),
            SourceMesh::Local(m) => m.positions.len(),
        }
    }
    fn triangles(&self) -> &[[u32; 3]] {
        match self {
            SourceMesh::File(m) => &m.triangles,
            SourceMesh::Local(m) => &m.triangles,
        }
    }
    fn position(&self, i: usize) -> DVec3 {
        match self {
            SourceMesh::File(m) => m.positions[i].as_dvec3(),
            SourceMesh::Local(m) => m.positions[i],
        }
    }
    fn normal(&self, i: usize) -> Option<DVec3> {
        match self {
            SourceMesh::File(m) => m.normals.as_ref().map(|n| n[i].as_dvec3()),
            SourceMesh::Local(m) => m.normals.as_ref().map(|n| n[i]),
        }
    }
    fn has_normals(&self) -> bool {
        match self {
            SourceMesh::File(m) => m.normals.is_some(),
            SourceMesh::Local(m) => m.normals.is_some(),
        }
    }
    fn materials(&self) -> Option<&[MaterialId]> {
        match self {
            SourceMesh::File(_) => None,
            SourceMesh::Local(m) => m.materials.as_deref(),
        }
    }
    /// The mesh in its own frame, as a BLAS input.
    fn blas_input(&self) -> BlasInput {
        let n = self.vertex_count();
        BlasInput {
            positions: (0..n).map(|i| self.position(i).as_vec3()).collect(),
            normals: self.has_normals().then(|| {
                (0..n)
                    .map(|i| self.normal(i).unwrap_or(DVec3::ZERO).as_vec3())
                    .collect()
            }),
            triangles: self.triangles().to_vec(),
            materials: self.materials().map(<[u32]>::to_vec).unwrap_or_default(),
        }
    }
}

/// Accumulates render-space triangles of everything placed once.
#[derive(Default)]
struct FlatBuilder {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    any_normals: bool,
    triangles: Vec<[u32; 3]>,
    materials: Vec<MaterialId>,
}

impl FlatBuilder {
    fn append(&mut self, source: &SourceMesh, to_render: &DAffine3, material: MaterialId) {
        let base = self.positions.len() as u32;
        let normal_matrix = to_render.matrix3.inverse().transpose();
        let mirrored = to_render.matrix3.determinant() < 0.0;
        for i in 0..source.vertex_count() {
            self.positions
                .push(to_render.transform_point3(source.position(i)).as_vec3());
            let n = source.normal(i).map_or(Vec3::ZERO, |n| {
                (normal_matrix * n).normalize_or_zero().as_vec3()
            });
            self.normals.push(n);
        }
        self.any_normals |= source.has_normals();
        let per_triangle = source.materials();
        for (k, t) in source.triangles().iter().enumerate() {
            let [a, b, c] = t.map(|i| base + i);
            self.triangles
                .push(if mirrored { [a, c, b] } else { [a, b, c] });
            self.materials.push(
                per_triangle
                    .and_then(|m| m.get(k).copied())
                    .unwrap_or(material),
            );
        }
    }

    /// Appends the plane `dot(normal, p) = offset` (in the frame `m`) as a grid of quads
    /// around the camera's foot point covering every point within `max_distance` of the
    /// camera, cells growing geometrically away from the foot so that triangles near the
    /// camera stay small (f32 precision). Returns the number of cells.
    fn append_plane(
        &mut self,
        normal: DVec3,
        offset: f64,
        m: &DAffine3,
        max_distance: f64,
        material: MaterialId,
    ) -> usize {
        let n_local = normal.normalize();
        let point = m.transform_point3(n_local * offset);
        let n = (m.matrix3.inverse().transpose() * n_local).normalize();
        let height = point.dot(n);
        let foot = n * height;
        let u = n.any_orthonormal_vector();
        let v = n.cross(u);
        // Coordinates 0, +-D 2^-k for k = K..0.
        let d = max_distance;
        let smallest = height.abs().max(d * 1e-4);
        let levels = ((d / smallest).log2().ceil().clamp(0.0, 12.0)) as i32;
        let mut coords: Vec<f64> = vec![0.0];
        for k in 0..=levels {
            let c = d * 0.5f64.powi(k);
            coords.push(c);
            coords.push(-c);
        }
        coords.sort_by(f64::total_cmp);
        let base = self.positions.len() as u32;
        let side = coords.len() as u32;
        for &y in &coords {
            for &x in &coords {
                self.positions.push((foot + u * x + v * y).as_vec3());
                self.normals.push(Vec3::ZERO);
            }
        }
        for j in 0..side - 1 {
            for i in 0..side - 1 {
                let a = base + j * side + i;
                let b = a + 1;
                let c = a + side + 1;
                let dd = a + side;
                // u x v = n: (a, b, c) runs counter-clockwise around n.
                self.triangles.push([a, b, c]);
                self.triangles.push([a, c, dd]);
                self.materials.push(material);
                self.materials.push(material);
            }
        }
        ((side - 1) * (side - 1)) as usize
    }

    /// The BLAS input and the material every triangle shares (0 when they differ). A
    /// uniform material is returned instead of stored per triangle, so shading a hit reads
    /// no per-triangle array (on a large mesh that lookup is one more cache miss per hit).
    fn into_input(self) -> (BlasInput, MaterialId) {
        let uniform = match self.materials.split_first() {
            Some((&first, rest)) if rest.iter().all(|&m| m == first) => Some(first),
            Some(_) => None,
            None => Some(0),
        };
        let input = BlasInput {
            positions: self.positions,
            normals: self.any_normals.then_some(self.normals),
            triangles: self.triangles,
            materials: if uniform.is_some() {
                Vec::new()
            } else {
                self.materials
            },
        };
        (input, uniform.unwrap_or(0))
    }
}

impl std::fmt::Debug for MeshGeometry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MeshGeometry")
            .field("triangles", &self.triangle_count())
            .field("blases", &self.blases.len())
            .field("instances", &self.instances.len())
            .field("memory_bytes", &self.report.memory_bytes)
            .finish()
    }
}

impl MeshGeometry {
    /// Distinct triangles held (flat plus one copy per BLAS).
    pub fn triangle_count(&self) -> u64 {
        (self.flat.as_ref().map_or(0, |b| b.triangle_count)
            + self.blases.iter().map(|b| b.triangle_count).sum::<usize>()) as u64
    }

    /// Number of instances under the TLAS.
    pub fn instance_count(&self) -> usize {
        self.instances.len()
    }

    #[inline(always)]
    fn ob_ray(&self, ray: &Ray) -> ObRay {
        ob_ray_new(
            Vec3A::from(ray.origin),
            Vec3A::from(ray.dir),
            ray.t_min,
            ray.t_max.min(self.max_distance),
        )
    }

    fn local_ray(inst: &Instance, r: &ObRay) -> ObRay {
        ObRay::new(
            inst.to_local.transform_point3a(r.origin),
            inst.to_local.transform_vector3a(r.direction),
            r.tmin,
            r.tmax,
        )
    }
}

/// `obvhs::ray::Ray::new(origin, direction, tmin, tmax)`, bit for bit, with the inverse
/// direction computed on the 3 lanes at once (one vector division and a select) instead of
/// obvhs' `safe_inverse` branch per axis: `|x| <= EPSILON` gives `signum(x) / EPSILON`,
/// which is `copysign(2^23, x)` exactly; every other `x` gives `1 / x`.
#[inline(always)]
fn ob_ray_new(origin: Vec3A, direction: Vec3A, tmin: f32, tmax: f32) -> ObRay {
    let small = direction.abs().cmple(Vec3A::splat(f32::EPSILON));
    let clamped = Vec3A::splat(1.0 / f32::EPSILON).copysign(direction);
    ObRay {
        origin,
        direction,
        inv_direction: Vec3A::select(small, clamped, Vec3A::ONE / direction),
        tmin,
        tmax,
    }
}

impl MeshGeometry {
    /// Closest hits of 8 rays of a batch as one packet through the flat wide BVH; `false`
    /// (nothing written) when packets are off, the scene has instances, the flat BVH is not
    /// wide, or the rays do not share an origin.
    fn closest_packet(&self, rays: &[Ray], out: &mut [TraceResult]) -> bool {
        let (true, Some(flat), None) = (self.packets, &self.flat, &self.tlas) else {
            return false;
        };
        let (Some(wide), Ok(rays8), true) = (
            flat.wide(),
            <&[Ray; packet::PACKET]>::try_from(rays),
            out.len() == packet::PACKET,
        ) else {
            return false;
        };
        let mut r: [ObRay; packet::PACKET] = std::array::from_fn(|k| self.ob_ray(&rays8[k]));
        if r.iter().any(|r| r.tmax.is_nan() || r.tmax < r.tmin) {
            return false;
        }
        let mut visits = 0;
        let mut tests = [0; packet::PACKET];
        let Some(best) = packet::closest8(wide, &mut r, &mut visits, &mut tests) else {
            return false;
        };
        for k in 0..packet::PACKET {
            let work = RayWork {
                node_visits: visits.div_ceil(packet::PACKET as u32),
                primitive_tests: tests[k],
                ..RayWork::default()
            };
            out[k] = match best[k] {
                Some((prim, t)) => {
                    let hit = BlasHit { t, prim };
                    TraceResult::found(
                        Hit {
                            t,
                            position: rays8[k].origin + rays8[k].dir * t,
                            normal: flat.normal(&r[k], &hit),
                            material: flat.material(&hit).unwrap_or(self.flat_materials_default),
                        },
                        work,
                    )
                }
                None => TraceResult::not_found(NoHit::Miss, work),
            };
        }
        true
    }
}

impl MeshGeometry {
    /// Closest hits of a batch (a multiple of [`wide::INTERLEAVE`] rays) traced in turns
    /// through the flat wide BVH ([`wide::WideBvh::closest_interleaved`]), each hit exactly
    /// the single-ray hit; `false` (nothing written) unless interleaving is on for this
    /// geometry (see [`INTERLEAVE_MIN_BYTES`]) and the batch fits.
    fn closest_interleaved(&self, rays: &[Ray], out: &mut [TraceResult]) -> bool {
        let (true, Some(flat), None) = (self.interleave, &self.flat, &self.tlas) else {
            return false;
        };
        let Some(wide) = flat.wide() else {
            return false;
        };
        if rays.len() != out.len() || !rays.len().is_multiple_of(wide::INTERLEAVE) {
            return false;
        }
        for (rays, out) in rays
            .chunks_exact(wide::INTERLEAVE)
            .zip(out.chunks_exact_mut(wide::INTERLEAVE))
        {
            let Ok(rays) = <&[Ray; wide::INTERLEAVE]>::try_from(rays) else {
                return false;
            };
            let mut r: [ObRay; wide::INTERLEAVE] = std::array::from_fn(|k| self.ob_ray(&rays[k]));
            // A ray with an empty interval is not traced (as in `closest_hit`): tmax = -inf
            // enters no box and passes no triangle test.
            let empty = r.map(|r| r.tmax.is_nan() || r.tmax < r.tmin);
            for (ray, &e) in r.iter_mut().zip(&empty) {
                if e {
                    ray.tmax = f32::NEG_INFINITY;
                }
            }
            let mut work = [RayWork::default(); wide::INTERLEAVE];
            let best = wide.closest_interleaved(&mut r, &mut work);
            for k in 0..wide::INTERLEAVE {
                out[k] = match (best[k], empty[k]) {
                    (_, true) => TraceResult::not_found(NoHit::Miss, RayWork::default()),
                    (None, false) => TraceResult::not_found(NoHit::Miss, work[k]),
                    (Some((prim, t)), false) => {
                        let hit = BlasHit { t, prim };
                        TraceResult::found(
                            Hit {
                                t,
                                position: rays[k].origin + rays[k].dir * t,
                                normal: flat.normal(&r[k], &hit),
                                material: flat
                                    .material(&hit)
                                    .unwrap_or(self.flat_materials_default),
                            },
                            work[k],
                        )
                    }
                };
            }
        }
        true
    }
}

impl Geometry for MeshGeometry {
    /// 64 columns: the same packets (8 consecutive pixels of a tile row start at multiples
    /// of 8 either way) with an eighth of the integrator's fixed cost per tile. Measured: `docs/decisions/0013`.
    fn tile_width(&self) -> u32 {
        64
    }

    /// Traces 8 consecutive rays at a time: interleaved single rays on a large flat wide
    /// BVH (above 16 MiB), else as a packet where packets are on and the
    /// scene allows it (flat wide BVH, shared origin), else one by one; same hits either
    /// way (a packet may break an exact tie between two triangles differently).
    fn closest_hits(&self, rays: &[Ray], out: &mut [TraceResult]) {
        assert_eq!(
            rays.len(),
            out.len(),
            "closest_hits: rays and out differ in length"
        );
        for (rs, os) in rays
            .chunks(packet::PACKET)
            .zip(out.chunks_mut(packet::PACKET))
        {
            if !self.closest_interleaved(rs, os) && !self.closest_packet(rs, os) {
                for (r, o) in rs.iter().zip(os.iter_mut()) {
                    *o = self.closest_hit(r);
                }
            }
        }
    }

    fn closest_hit(&self, ray: &Ray) -> TraceResult {
        let mut work = RayWork::default();
        let mut r = self.ob_ray(ray);
        if r.tmax.is_nan() || r.tmax < r.tmin {
            return TraceResult::not_found(NoHit::Miss, work);
        }
        let mut best: Option<(HitSource, BlasHit)> = None;
        if let Some(flat) = &self.flat
            && let Some(h) = flat.closest(&mut r, &mut work)
        {
            best = Some((HitSource::Flat, h));
        }
        if let Some(tlas) = &self.tlas {
            let mut inner = RayWork::default();
            let prims = tlas.primitive_indices();
            tlas.traverse(&mut r, &mut work, |r, slot| {
                let Some(&i) = prims.get(slot as usize) else {
                    return true;
                };
                let inst = &self.instances[i as usize];
                let mut local = Self::local_ray(inst, r);
                if let Some(h) = self.blases[inst.blas as usize].closest(&mut local, &mut inner) {
                    r.tmax = h.t;
                    best = Some((HitSource::Instance(i), h));
                }
                true
            });
            work.node_visits += inner.node_visits;
            work.primitive_tests += inner.primitive_tests;
        }
        let Some((source, hit)) = best else {
            return TraceResult::not_found(NoHit::Miss, work);
        };
        let t = r.tmax;
        let (normal, material) = match source {
            HitSource::Flat => match &self.flat {
                Some(flat) => (
                    flat.normal(&r, &hit),
                    flat.material(&hit).unwrap_or(self.flat_materials_default),
                ),
                None => (Vec3::Z, 0),
            },
            HitSource::Instance(i) => {
                let inst = &self.instances[i as usize];
                let blas = &self.blases[inst.blas as usize];
                let local = Self::local_ray(inst, &r);
                let n_local = Vec3A::from(blas.normal(&local, &hit));
                let n = inst.to_local.matrix3.transpose() * n_local;
                (
                    Vec3::from(n).try_normalize().unwrap_or(Vec3::Z),
                    blas.material(&hit).unwrap_or(inst.material),
                )
            }
        };
        TraceResult::found(
            Hit {
                t,
                position: ray.origin + ray.dir * t,
                normal,
                material,
            },
            work,
        )
    }

    fn occluded(&self, ray: &Ray) -> OcclusionResult {
        let mut work = RayWork::default();
        let mut r = self.ob_ray(ray);
        let mut occluded = false;
        if r.tmax >= r.tmin {
            if let Some(flat) = &self.flat {
                occluded = flat.any(&mut r, &mut work);
            }
            if !occluded && let Some(tlas) = &self.tlas {
                let mut inner = RayWork::default();
                let prims = tlas.primitive_indices();
                tlas.traverse(&mut r, &mut work, |r, slot| {
                    let Some(&i) = prims.get(slot as usize) else {
                        return true;
                    };
                    let inst = &self.instances[i as usize];
                    let mut local = Self::local_ray(inst, r);
                    if self.blases[inst.blas as usize].any(&mut local, &mut inner) {
                        occluded = true;
                        return false;
                    }
                    true
                });
                work.node_visits += inner.node_visits;
                work.primitive_tests += inner.primitive_tests;
            }
        }
        OcclusionResult {
            occluded,
            termination: if occluded {
                Termination::Hit
            } else {
                Termination::Miss
            },
            work,
        }
    }

    fn report(&self) -> GeometryReport {
        self.report.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_extraction_options_are_refused_naming_the_key() {
        for (options, key) in [
            (
                MeshOptions {
                    surface_px: Some(0.0),
                    ..MeshOptions::DEFAULT
                },
                "surface_px",
            ),
            (
                MeshOptions {
                    surface_px: Some(-1.0),
                    ..MeshOptions::DEFAULT
                },
                "surface_px",
            ),
            (
                MeshOptions {
                    surface_px: Some(f64::NAN),
                    ..MeshOptions::DEFAULT
                },
                "surface_px",
            ),
            (
                MeshOptions {
                    surface_px: Some(f64::INFINITY),
                    ..MeshOptions::DEFAULT
                },
                "surface_px",
            ),
            (
                MeshOptions {
                    surface_res: Some(4),
                    ..MeshOptions::DEFAULT
                },
                "surface_res",
            ),
            (
                MeshOptions {
                    surface_res: Some(MAX_SURFACE_RESOLUTION + 1),
                    ..MeshOptions::DEFAULT
                },
                "surface_res",
            ),
            (
                MeshOptions {
                    surface_px: Some(1.0),
                    surface_res: Some(64),
                    ..MeshOptions::DEFAULT
                },
                "surface_px, surface_res",
            ),
        ] {
            let e = check_options(&options).expect_err(key).to_string();
            assert!(e.contains(key), "{options:?}: {e}");
        }
        // Tessellation keys too, with the accepted range, never the internal variant names.
        for (options, expected) in [
            (
                MeshOptions {
                    tess_level: Some(MAX_TESS_LEVEL + 1),
                    ..MeshOptions::DEFAULT
                },
                "tess_level must be in 0..=12",
            ),
            (
                MeshOptions {
                    tess_chord: Some(0.0),
                    ..MeshOptions::DEFAULT
                },
                "tess_chord must be",
            ),
            (
                MeshOptions {
                    tess_px: Some(0.0),
                    ..MeshOptions::DEFAULT
                },
                "tess_px must be",
            ),
        ] {
            let e = check_options(&options).expect_err(expected).to_string();
            assert!(e.contains(expected), "{options:?}: {e}");
        }
        check_options(&MeshOptions {
            surface_px: Some(0.5),
            ..MeshOptions::DEFAULT
        })
        .expect("valid");
    }

    #[test]
    fn ob_ray_new_is_bit_identical_to_obvhs_ray_new() {
        let eps = f32::EPSILON;
        let mut values = vec![
            0.0,
            -0.0,
            eps,
            -eps,
            eps * 0.5,
            -eps * 0.5,
            f32::from_bits(eps.to_bits() + 1),
            f32::MIN_POSITIVE,
            1e-30,
            1.0,
            -1.0,
            0.3,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ];
        let mut s = 12345u32;
        for _ in 0..2000 {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let v = f32::from_bits(s);
            if v.is_finite() {
                values.push(v);
            }
        }
        for w in values.windows(3) {
            let (o, d) = (Vec3A::new(1.0, -2.0, 3.0), Vec3A::new(w[0], w[1], w[2]));
            let (a, b) = (ob_ray_new(o, d, 0.5, 7.0), ObRay::new(o, d, 0.5, 7.0));
            let bits = |v: Vec3A| v.to_array().map(f32::to_bits);
            assert_eq!(bits(a.inv_direction), bits(b.inv_direction), "{d}");
            assert_eq!(bits(a.direction), bits(b.direction));
            assert_eq!(bits(a.origin), bits(b.origin));
            assert_eq!((a.tmin, a.tmax), (b.tmin, b.tmax));
        }
    }
}
