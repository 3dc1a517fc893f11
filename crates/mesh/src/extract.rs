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
    let mut field =
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
    // Pruned per region: a sample reads only the children that matter near it, and a
    // sample in a cell without surface reads that cell's far bound. A far cell's field is at
    // least half its bounding radius, so at least a quarter of its longest edge; with that
    // edge at least eight extraction cells long, no corner of an extraction cell the surface
    // crosses (whose field is below a cell diagonal, sqrt(3) cells) reads a far bound: the
    // mesh is the one the whole field gives.
    if field.node_count() >= PRUNE_MIN_NODES {
        let depth = (resolution.clamp(8, MAX_SURFACE_RESOLUTION) / 8)
            .ilog2()
            .min(6);
        field.build_cells(depth);
    }
    Ok(extract_surface(
        |p| field.distance_bound_f64(p) as f32,
        |p| field.distance_material_f64(p).1,
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
pub fn extract_surface(
    distance: impl Fn(DVec3) -> f32 + Sync,
    material_at: impl Fn(DVec3) -> MaterialId,
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
    let slice = (dims[0] * dims[1]) as usize;
    let mut sdf = vec![0f32; slice * dims[2] as usize];
    sdf.par_chunks_mut(slice)
        .enumerate()
        .for_each(|(z, plane)| {
            for y in 0..dims[1] as usize {
                for x in 0..dims[0] as usize {
                    let p = origin + DVec3::new(x as f64, y as f64, z as f64) * cell;
                    let d = distance(p);
                    // Non-finite samples would poison the mesher: treat them as outside.
                    plane[y * dims[0] as usize + x] = if d.is_finite() { d } else { f32::MAX };
                }
            }
        });
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
    let materials = triangles
        .iter()
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
