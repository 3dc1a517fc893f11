//! The build pipeline's phases behind [`crate::build`]: mesh files loaded once, placements
//! grouped by shape, each shape's triangles made within the memory budget (tessellation,
//! surface extraction on a grid sized from the screen), flat and instanced geometry
//! assembled into BVHs, and the report describing the result.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use glam::{DAffine3, DVec3};
use marchmesh_core::{FarFrame, GeometryReport};
use marchmesh_meshio::{TriangleMesh, load_mesh};
use marchmesh_scene::{MaterialId, Node, NodeKind, Scene, Shape};

use crate::blas::{self, Blas, Tree};
use crate::budget::{
    BuildBudget, EXTRACTION_BYTES_PER_CELL, EXTRACTION_KNOB, INSTANCE_BYTES,
    extracted_triangles_estimate, triangle_bytes,
};
use crate::build::{self, Placement, ShapeKey};
use crate::flat::{AsAffine3A, FlatBuilder, SourceMesh, positions_bounds, render_box};
use crate::tessellate::{self, Detail, LocalMesh, ScreenBudget};
use crate::{
    Extraction, FarInstance, Instance, MAX_SURFACE_RESOLUTION, MeshError, MeshOptions, NEAR,
    Tessellation, extract,
};

/// Phase 1: every mesh file of the scene loaded once, with notes on skipped triangles.
pub(crate) fn load_meshes(
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
pub(crate) fn group_by_shape<'p, 'a>(
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
pub(crate) struct ShapeInputs<'a> {
    pub(crate) scene: &'a Scene,
    pub(crate) options: &'a MeshOptions,
    pub(crate) meshes: &'a HashMap<PathBuf, TriangleMesh>,
    pub(crate) mesh_bounds: &'a HashMap<PathBuf, (DVec3, DVec3)>,
}

/// Phase 3's result: the flat BVH, the instanced BLASes, their instances and the TLAS.
pub(crate) struct Assembled {
    pub(crate) flat_blas: Option<Blas>,
    /// Material of every flat triangle when they all share one (the flat BLAS then keeps no
    /// per-triangle materials and a hit needs no lookup); 0 otherwise.
    pub(crate) flat_material: MaterialId,
    pub(crate) flat_triangles: usize,
    pub(crate) blases: Vec<Blas>,
    pub(crate) instances: Vec<Instance>,
    /// The frames of the instances far from the camera ([`Instance::far`] indexes them).
    pub(crate) far_instances: Vec<FarInstance>,
    pub(crate) tlas: Option<Tree>,
}

impl ShapeInputs<'_> {
    /// Phase 2: the local triangles of every group (analytic shapes tessellated at the finest
    /// detail any placement needs, CSG surfaces extracted; `None` for mesh files, used as
    /// loaded), refusing before allocating when the build would exceed the memory limit.
    /// Returns the meshes and the time spent extracting.
    pub(crate) fn triangulate(
        &self,
        groups: &[(ShapeKey, Vec<&Placement>)],
        placement_count: usize,
        report: &mut GeometryReport,
    ) -> Result<(Vec<Option<LocalMesh>>, Duration), MeshError> {
        let options = self.options;
        let mut local_meshes: Vec<Option<LocalMesh>> = Vec::with_capacity(groups.len());
        let mut extract_time = Duration::ZERO;
        let mut budget = BuildBudget {
            limit_bytes: options.memory_limit_bytes(),
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
                // A camera near or inside the bounds: the box says little (nothing inside
                // it), the field at the camera bounds the nearest surface point's distance
                // from below. On the surface (or holding a mesh) a thousandth of the size,
                // as the tessellation's screen budget assumes.
                let mut distance = build::distance_to_box(world);
                if distance < size
                    && let Some(d) = build::camera_surface_distance(p.node, p.to_render)
                {
                    distance = distance.max(d);
                }
                let distance = distance.max(1e-3 * size);
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
    pub(crate) fn assemble(
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
        let mut far_instances: Vec<FarInstance> = Vec::new();
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
            // A placement far from the camera is an instance with a frame of its own (its
            // rays enter it through f64), whatever the instancing option: flattened into
            // render space its vertices would be rounded to the f32 grid out there.
            // Equal keys are equal shapes: one local box serves the group.
            let local_bounds = placements
                .first()
                .and_then(|p| build::local_bounds(p.node, self.mesh_bounds));
            let frames: Vec<Option<FarFrame>> = placements
                .iter()
                .map(|p| {
                    let (lo, hi) = build::transform_bounds(&p.to_render, local_bounds?);
                    FarFrame::of_box(lo, hi)
                })
                .collect();
            let any_far = frames.iter().any(Option::is_some);
            if (options.instancing() && placements.len() > 1) || any_far {
                let input = source.blas_input();
                if input.triangles.is_empty() {
                    continue;
                }
                let local_box = positions_bounds(&input.positions);
                let blas_index = blases.len() as u32;
                blases.push(Blas::build(input, options.bvh(), params));
                for (p, frame) in placements.iter().zip(&frames) {
                    instance_boxes.push(render_box(&p.to_render, local_box));
                    let to_local = p.to_render.inverse();
                    let far = match frame {
                        Some(frame) => {
                            far_instances.push(FarInstance {
                                frame: *frame,
                                to_local,
                            });
                            far_instances.len() as u32 - 1
                        }
                        None => NEAR,
                    };
                    instances.push(Instance {
                        to_local: to_local.as_affine3a_checked(),
                        blas: blas_index,
                        material: p.material,
                        far,
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
            far_instances,
            tlas,
        }
    }
}

/// [`Extraction::ScreenCell`] grids have at least this many cells a side divided by the
/// cell's pixels.
const SCREEN_CELL_FLOOR: f64 = 128.0;

/// The report's memory, triangle counts, counters and notes on the built geometry.
pub(crate) fn describe(
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
        far_instances,
        tlas,
        ..
    } = built;
    let flat_triangles = *flat_triangles;
    let blas_triangles: usize = blases.iter().map(|b| b.triangle_count).sum();
    let instance_bytes = (instances.len() * size_of::<Instance>()
        + far_instances.len() * size_of::<FarInstance>()) as u64;
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
        ("far_instances".into(), far_instances.len() as f64),
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
    if !far_instances.is_empty() {
        report.notes.push(format!(
            "{} placement(s) farther than {} radii from the camera traced as instances in frames of their own (rays enter them in f64)",
            far_instances.len(),
            marchmesh_core::FAR_RATIO
        ));
    }
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
