//! Surface extraction for CSG intersections, subtractions and smooth unions: the zero set of
//! a distance field sampled on a regular grid over the object's bounds, meshed with surface
//! nets (`fast-surface-nets`).

use fast_surface_nets::ndshape::RuntimeShape;
use fast_surface_nets::{SurfaceNetsBuffer, surface_nets};
use glam::DVec3;
use marchmesh_field::{Field, FieldOptions};
use marchmesh_scene::{MaterialId, Node};
use rayon::prelude::*;

use crate::MeshError;
use crate::tessellate::LocalMesh;

/// Largest grid resolution accepted (cells along the longest side): 512^3 samples hold
/// about 0.5 GB of f32.
pub const MAX_SURFACE_RESOLUTION: u32 = 512;

/// Composites whose field has fewer nodes are sampled without pruning per region.
const PRUNE_MIN_NODES: usize = 16;

/// Largest change the pruning per region may make to the sampled field, as a fraction of the
/// field's box: 2^-24, below the f32 rounding of the samples.
const PRUNE_MAX_ERROR_REL: f64 = 1.0 / 16_777_216.0;

/// Extracts the surface of a composite node in its local frame (the frame before
/// `node.transform`) from the shared distance field (`marchmesh-field`).
///
/// `bounds` are the node's local bounds when the backend knows them; otherwise the field's
/// own bounds are used. A composite without finite bounds (a subtraction from a plane, an
/// intersection of infinite repetitions) has no finite surface to extract: that is
/// [`MeshError::Unsupported`], naming the node.
pub(crate) fn extract(
    node: &Node,
    bounds: Option<(DVec3, DVec3)>,
    resolution: u32,
    field_options: &FieldOptions,
) -> Result<LocalMesh, MeshError> {
    let field =
        Field::compile_node(node, node.transform.inverse(), field_options).map_err(|e| {
            MeshError::Unsupported {
                json_path: node.json_path.clone(),
                reason: format!("its distance field could not be built: {e}"),
            }
        })?;
    let bounds = bounds
        .or_else(|| field.bounds())
        .filter(|(lo, hi)| lo.is_finite() && hi.is_finite() && (*hi - *lo).min_element() >= 0.0)
        .ok_or_else(|| MeshError::Unsupported {
            json_path: node.json_path.clone(),
            reason: "the CSG result is unbounded (e.g. a plane or an infinite repetition survives), so it has no finite surface to extract".into(),
        })?;
    // Pruned per block: each block of samples near the surface reads the program restricted
    // to the block's ball (one pass over the program per block), so a sample reads only the
    // children that matter near it, however many the field holds and however little an
    // octree of cells over the whole box could prune (smooth folds prune only in regions
    // about the blend radius across). Block centres, which decide which blocks are near,
    // read the whole field.
    let field = &field;
    let prune = field.node_count() >= PRUNE_MIN_NODES;
    let single_material = field.single_material();
    let sdf = |p: [DVec3; 8]| field.distance_x8(p.map(DVec3::as_vec3));
    Ok(extract_surface_blocks(
        &sdf,
        |centre, radius| {
            let ball = prune.then(|| field.restricted_to_ball(centre, radius, PRUNE_MAX_ERROR_REL));
            move |p: [DVec3; 8]| match &ball {
                Some(b) => field.ball_distance_x8(b, p.map(DVec3::as_vec3)),
                None => field.distance_x8(p.map(DVec3::as_vec3)),
            }
        },
        |p| single_material.unwrap_or_else(|| field.distance_material_f64(p).1),
        bounds,
        resolution,
    ))
}

/// Meshes the zero set of `distance` (negative inside, in the frame of `bounds`) inside
/// `bounds` with surface nets on a grid of `resolution` cells along the longest side
/// (clamped to `8..=MAX_SURFACE_RESOLUTION`), padded by two cells so that a surface touching
/// the bounds closes. `material_at` gives each triangle's material at its centroid.
///
/// Vertices lie within about one cell of the surface (surface nets place them at the mean
/// of the cell's edge crossings); normals are the normalised field gradient estimated by
/// the mesher. Triangles come out counter-clockwise seen from outside (positive distance).
/// A closed zero set inside the bounds gives a closed mesh.
///
/// Only the samples near the surface read `distance` (see `sample_narrow_band`), so the
/// cost grows with the surface's area in cells, not the grid's volume.
pub fn extract_surface(
    distance: impl Fn(DVec3) -> f32 + Sync,
    material_at: impl Fn(DVec3) -> MaterialId + Sync,
    bounds: (DVec3, DVec3),
    resolution: u32,
) -> LocalMesh {
    extract_surface_x8(|p| p.map(&distance), material_at, bounds, resolution)
}

/// [`extract_surface`] with the field read eight points at a time: `distance_x8` returns
/// the distances at its eight points (the sampler passes runs of up to eight samples of a
/// grid row, repeating the last point to fill the lanes).
pub fn extract_surface_x8(
    distance_x8: impl Fn([DVec3; 8]) -> [f32; 8] + Sync,
    material_at: impl Fn(DVec3) -> MaterialId + Sync,
    bounds: (DVec3, DVec3),
    resolution: u32,
) -> LocalMesh {
    extract_surface_blocks(
        &distance_x8,
        |_, _| &distance_x8,
        material_at,
        bounds,
        resolution,
    )
}

/// [`extract_surface_x8`] where the samples of each block near the surface are read through
/// `block(centre, radius)`, an evaluator that must agree with `distance_x8` (within the
/// field's f32 rounding) at every point within `radius` of `centre`: a field restricted to
/// the block. `distance_x8` reads the blocks' centres.
fn extract_surface_blocks<B: Fn([DVec3; 8]) -> [f32; 8]>(
    distance_x8: &(impl Fn([DVec3; 8]) -> [f32; 8] + Sync),
    block: impl Fn(DVec3, f64) -> B + Sync,
    material_at: impl Fn(DVec3) -> MaterialId + Sync,
    bounds: (DVec3, DVec3),
    resolution: u32,
) -> LocalMesh {
    let resolution = resolution.clamp(8, MAX_SURFACE_RESOLUTION);
    let (lo, hi) = bounds;
    let extent = (hi - lo).max(DVec3::splat(1e-300));
    let cell = extent.max_element() / f64::from(resolution);
    let origin = lo - DVec3::splat(2.0 * cell);
    let dims = ((extent / cell).ceil().as_uvec3() + glam::UVec3::splat(5)).to_array();
    let shape = RuntimeShape::<u32, 3>::new(dims);
    let sdf = sample_narrow_band(distance_x8, &block, origin, cell, dims);
    let mut buffer = SurfaceNetsBuffer::default();
    surface_nets(&sdf, &shape, [0; 3], dims.map(|d| d - 1), &mut buffer);

    let positions: Vec<DVec3> = buffer
        .positions
        .iter()
        .map(|p| origin + DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])) * cell)
        .collect();
    let normals: Vec<DVec3> = buffer
        .normals
        .iter()
        .map(|n| DVec3::new(f64::from(n[0]), f64::from(n[1]), f64::from(n[2])).normalize_or_zero())
        .collect();
    let mut triangles: Vec<[u32; 3]> = buffer
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .filter(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            (b - a).cross(c - a) != DVec3::ZERO
        })
        .collect();
    // Orient counter-clockwise from outside: compare the winding with the field gradient.
    let agreement: f64 = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            let g = normals[t[0] as usize] + normals[t[1] as usize] + normals[t[2] as usize];
            (b - a).cross(c - a).dot(g)
        })
        .sum();
    if agreement < 0.0 {
        for t in &mut triangles {
            t.swap(1, 2);
        }
    }
    // In parallel: one field evaluation per triangle, in the triangles' order.
    let materials = triangles
        .par_iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            material_at((a + b + c) / 3.0)
        })
        .collect();
    LocalMesh {
        positions,
        normals: Some(normals),
        triangles,
        closed: true,
        segments: Vec::new(),
        materials: Some(materials),
    }
}

/// Samples per axis of a block of [`sample_narrow_band`].
const BAND_BLOCK: usize = 8;
const _: () = assert!(BAND_BLOCK == 8, "a block row is one 8-point query");

/// The grid of `dims` samples at `origin + i * cell`, read from `distance` only near the
/// surface: each block of [`BAND_BLOCK`]^3 samples first reads the field at its centre, and
/// when that value `d` is farther from zero than the block's half diagonal plus two cell
/// diagonals (the field is 1-Lipschitz, or a bound of a 1-Lipschitz field that is never
/// nearer zero than the field), every sample `p` of the block takes `d` moved towards zero
/// by `|p - centre|`, which keeps the field's sign and stays at least two cell diagonals
/// from zero. Surface nets read values only at the corners of cells the surface crosses,
/// whose values lie within a cell diagonal of zero, so no such corner is in a skipped
/// block: the mesh is the one the fully sampled grid gives.
fn sample_narrow_band<B: Fn([DVec3; 8]) -> [f32; 8]>(
    distance_x8: &(impl Fn([DVec3; 8]) -> [f32; 8] + Sync),
    block: &(impl Fn(DVec3, f64) -> B + Sync),
    origin: DVec3,
    cell: f64,
    dims: [u32; 3],
) -> Vec<f32> {
    let [nx, ny, nz] = dims.map(|d| d as usize);
    let slice = nx * ny;
    let blocks = [nx, ny, nz].map(|n| n.div_ceil(BAND_BLOCK));
    let point =
        |x: usize, y: usize, z: usize| origin + DVec3::new(x as f64, y as f64, z as f64) * cell;
    // Non-finite samples would poison the mesher: treat them as outside.
    let finite = |d: f32| if d.is_finite() { d } else { f32::MAX };
    // One slab of blocks (BAND_BLOCK planes of z) per task.
    let slabs: Vec<Vec<f32>> = (0..blocks[2])
        .into_par_iter()
        .map(|bz| {
            let z0 = bz * BAND_BLOCK;
            let z1 = (z0 + BAND_BLOCK).min(nz);
            let mut out = vec![0f32; slice * (z1 - z0)];
            for by in 0..blocks[1] {
                let (y0, y1) = (by * BAND_BLOCK, ((by + 1) * BAND_BLOCK).min(ny));
                let x_range = |bx: usize| (bx * BAND_BLOCK, ((bx + 1) * BAND_BLOCK).min(nx));
                let centre_index = |bx: usize| {
                    let (x0, x1) = x_range(bx);
                    DVec3::new(
                        0.5 * (x0 + x1 - 1) as f64,
                        0.5 * (y0 + y1 - 1) as f64,
                        0.5 * (z0 + z1 - 1) as f64,
                    )
                };
                // The centres of eight blocks of the row per query.
                let mut centre_values = Vec::with_capacity(blocks[0].next_multiple_of(8));
                for first in (0..blocks[0]).step_by(8) {
                    centre_values.extend(distance_x8(std::array::from_fn(|i| {
                        origin + centre_index((first + i).min(blocks[0] - 1)) * cell
                    })));
                }
                for (bx, &centre_value) in centre_values.iter().enumerate().take(blocks[0]) {
                    let (x0, x1) = x_range(bx);
                    let centre_index = centre_index(bx);
                    let half_diagonal = DVec3::new(
                        (x1 - x0 - 1) as f64,
                        (y1 - y0 - 1) as f64,
                        (z1 - z0 - 1) as f64,
                    )
                    .length()
                        * 0.5
                        * cell;
                    let d = f64::from(centre_value);
                    let far = d.is_finite() && d.abs() > half_diagonal + 2.0 * 3f64.sqrt() * cell;
                    // Every sample of the block lies within its half diagonal of the centre.
                    let near_field = (!far).then(|| {
                        block(
                            origin + centre_index * cell,
                            half_diagonal * (1.0 + 1e-9) + 1e-300,
                        )
                    });
                    for z in z0..z1 {
                        for y in y0..y1 {
                            let row = (z - z0) * slice + y * nx;
                            if let Some(near_field) = &near_field {
                                // BAND_BLOCK is 8: one row of a block is one call.
                                let values = near_field(std::array::from_fn(|i| {
                                    point((x0 + i).min(x1 - 1), y, z)
                                }));
                                for x in x0..x1 {
                                    out[row + x] = finite(values[x - x0]);
                                }
                            } else {
                                for x in x0..x1 {
                                    let offset = (DVec3::new(x as f64, y as f64, z as f64)
                                        - centre_index)
                                        .length()
                                        * cell;
                                    out[row + x] = ((d.abs() - offset) as f32).copysign(d as f32);
                                }
                            }
                        }
                    }
                }
            }
            out
        })
        .collect();
    slabs.concat()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The narrow band gives the surface-nets mesh of the fully sampled grid: same
    /// triangles, same positions, for spheres of several sizes against the grid.
    #[test]
    fn narrow_band_meshes_like_the_full_grid() {
        for (radius, resolution) in [(0.9, 16u32), (0.3, 64), (0.05, 128), (0.013, 200)] {
            let distance = |p: DVec3| (p.length() - radius) as f32;
            let bounds = (DVec3::splat(-1.0), DVec3::splat(1.0));
            let band = extract_surface(distance, |_| MaterialId::default(), bounds, resolution);
            // The full grid: every sample read.
            let cell = 2.0 / f64::from(resolution);
            let origin = bounds.0 - DVec3::splat(2.0 * cell);
            let dims =
                ((DVec3::splat(2.0) / cell).ceil().as_uvec3() + glam::UVec3::splat(5)).to_array();
            let mut full = Vec::new();
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        full.push(distance(
                            origin + DVec3::new(f64::from(x), f64::from(y), f64::from(z)) * cell,
                        ));
                    }
                }
            }
            let shape = RuntimeShape::<u32, 3>::new(dims);
            let mut buffer = SurfaceNetsBuffer::default();
            surface_nets(&full, &shape, [0; 3], dims.map(|d| d - 1), &mut buffer);
            assert!(!band.triangles.is_empty(), "radius {radius}: no surface");
            assert_eq!(
                band.positions.len(),
                buffer.positions.len(),
                "radius {radius}"
            );
            for (a, b) in band.positions.iter().zip(&buffer.positions) {
                let b =
                    origin + DVec3::new(f64::from(b[0]), f64::from(b[1]), f64::from(b[2])) * cell;
                assert!((*a - b).length() < 1e-9, "radius {radius}: {a} vs {b}");
            }
            assert_eq!(
                band.triangles.len() * 3,
                buffer.indices.len(),
                "radius {radius}"
            );
        }
    }

    /// Far blocks keep the field's sign: a sample inside a big solid stays negative.
    #[test]
    fn narrow_band_keeps_signs_far_from_the_surface() {
        let distance = |p: DVec3| (p.length() - 0.9) as f32;
        let dims = [40u32, 40, 40];
        let cell = 0.05;
        let origin = DVec3::splat(-1.0);
        let whole = |p: [DVec3; 8]| p.map(distance);
        let grid = sample_narrow_band(&whole, &|_, _| whole, origin, cell, dims);
        for z in 0..40usize {
            for y in 0..40usize {
                for x in 0..40usize {
                    let p = origin + DVec3::new(x as f64, y as f64, z as f64) * cell;
                    let v = grid[(z * 40 + y) * 40 + x];
                    let exact = distance(p);
                    assert_eq!(v.signum(), exact.signum(), "at {p}");
                    assert!(v.abs() <= exact.abs() + 1e-6, "at {p}: {v} vs {exact}");
                }
            }
        }
    }

    /// Sampling each near block through the field restricted to it gives the mesh the whole
    /// field gives, vertex for vertex (a molecule of smooth-blended spheres, as in the
    /// sculpted suite, whose restricted programs hold a few of its children).
    #[test]
    fn blocks_read_through_restricted_fields_mesh_like_the_whole_field() {
        use glam::DAffine3;
        use marchmesh_scene::{NodeKind, Shape, SmoothOp};
        let leaf = |c: DVec3| Node {
            transform: DAffine3::from_translation(c),
            material: 0,
            name: None,
            json_path: "test".into(),
            kind: NodeKind::Leaf(Shape::Sphere { radius: 0.032 }),
        };
        let mut c = DVec3::ZERO;
        let children = (0..120u32)
            .map(|i| {
                let a = f64::from(i) * 2.4;
                c += DVec3::new(a.cos(), (a * 0.7).sin(), (a * 1.3).cos()).normalize() * 0.04;
                leaf(c)
            })
            .collect();
        let node = Node {
            transform: DAffine3::IDENTITY,
            material: 0,
            name: None,
            json_path: "test".into(),
            kind: NodeKind::Smooth {
                op: SmoothOp::Union,
                children,
                blend_radius: 0.026,
            },
        };
        let field = Field::compile_node(&node, DAffine3::IDENTITY, &FieldOptions::default())
            .expect("compiles");
        let field = &field;
        let bounds = field.bounds().expect("bounded");
        let whole = |p: [DVec3; 8]| field.distance_x8(p.map(DVec3::as_vec3));
        let restricted_nodes = std::sync::atomic::AtomicUsize::new(usize::MAX);
        let pruned = extract_surface_blocks(
            &whole,
            |centre, radius| {
                let ball = field.restricted_to_ball(centre, radius, PRUNE_MAX_ERROR_REL);
                restricted_nodes.fetch_min(ball.node_count(), std::sync::atomic::Ordering::Relaxed);
                move |p: [DVec3; 8]| field.ball_distance_x8(&ball, p.map(DVec3::as_vec3))
            },
            |_| 0,
            bounds,
            96,
        );
        let plain = extract_surface_x8(whole, |_| 0, bounds, 96);
        assert!(!plain.triangles.is_empty());
        let smallest = restricted_nodes.into_inner();
        assert!(
            smallest < field.node_count(),
            "{smallest} of {} nodes",
            field.node_count()
        );
        assert_eq!(pruned.positions.len(), plain.positions.len());
        // The restricted fields are within 2^-24 of the box of the whole one: vertices move
        // by far less than a thousandth of a cell, if at all.
        let cell = (bounds.1 - bounds.0).max_element() / 96.0;
        for (a, b) in pruned.positions.iter().zip(&plain.positions) {
            assert!((*a - *b).length() < 1e-3 * cell, "{a} vs {b}");
        }
        assert_eq!(pruned.triangles, plain.triangles);
    }
}
