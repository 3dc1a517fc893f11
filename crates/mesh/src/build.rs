//! Scene walk: placements of shapes with their object-to-render transforms, repetition
//! expansion, bounds, and the per-shape tessellation budget.

use std::collections::HashMap;
use std::path::PathBuf;

use glam::{DAffine3, DMat3, DVec3};
use marchmesh_scene::bounds::{Aabb, singular_values};
use marchmesh_scene::{MaterialId, Node, NodeKind, Scene, Shape};

use crate::MeshError;
use crate::options::{MeshOptions, Tessellation};
use crate::tessellate::Detail;

/// What a placed shape is; equal keys share one BLAS.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(crate) enum ShapeKey {
    /// An analytic shape: its `Debug` form, every parameter bit included.
    Analytic(String),
    /// A mesh file.
    Mesh(PathBuf),
    /// A CSG / smooth-union subtree, by node address (stable while the scene is borrowed).
    Composite(usize),
}

/// One shape placed in render space.
#[derive(Debug, Clone)]
pub(crate) struct Placement<'a> {
    pub node: &'a Node,
    pub key: ShapeKey,
    pub to_render: DAffine3,
    pub material: MaterialId,
}

/// Everything the walk found.
#[derive(Debug, Default)]
pub(crate) struct Walk<'a> {
    pub placements: Vec<Placement<'a>>,
    pub planes: Vec<(&'a Node, DAffine3)>,
    pub notes: Vec<String>,
    pub repeat_cells: u64,
}

/// Local bounds of a node in its parent's frame (its transform applied); `None` when
/// unbounded (planes, infinite repetition). The scene's one definition of shape bounds
/// (`marchmesh_scene::bounds`), with mesh files' boxes from `mesh_bounds`.
pub(crate) fn node_bounds(
    node: &Node,
    mesh_bounds: &HashMap<PathBuf, (DVec3, DVec3)>,
) -> Option<(DVec3, DVec3)> {
    node.bounds_in_parent(&mesh_box(mesh_bounds))?.finite()
}

/// Bounds of a node in its own frame (before its transform); `None` when unbounded.
pub(crate) fn local_bounds(
    node: &Node,
    mesh_bounds: &HashMap<PathBuf, (DVec3, DVec3)>,
) -> Option<(DVec3, DVec3)> {
    node.bounds_in_own_frame(&mesh_box(mesh_bounds))?.finite()
}

fn mesh_box(
    mesh_bounds: &HashMap<PathBuf, (DVec3, DVec3)>,
) -> impl Fn(&std::path::Path) -> Option<Aabb> + '_ {
    |path| mesh_bounds.get(path).map(|&(lo, hi)| Aabb::new(lo, hi))
}

/// The axis-aligned bounds of a transformed box.
pub(crate) fn transform_bounds(m: &DAffine3, (lo, hi): (DVec3, DVec3)) -> (DVec3, DVec3) {
    let b = Aabb::new(lo, hi).transformed(m);
    (b.lo, b.hi)
}

/// Distance from the render-space origin (the camera) to a box; 0 inside.
pub(crate) fn distance_to_box((lo, hi): (DVec3, DVec3)) -> f64 {
    Aabb::new(lo, hi).distance_to(DVec3::ZERO)
}

/// Largest singular value of a 3x3 matrix, rounded up by 0.1% and capped by the Frobenius
/// norm (a hard upper bound), for error budgets that must not be exceeded.
pub(crate) fn max_stretch(m: &DMat3) -> f64 {
    let frobenius =
        (m.x_axis.length_squared() + m.y_axis.length_squared() + m.z_axis.length_squared()).sqrt();
    (singular_values(m)[2] * 1.001)
        .min(frobenius)
        .max(f64::MIN_POSITIVE)
}

/// Walks the scene tree. `mesh_bounds` must hold every mesh path.
pub(crate) fn walk<'a>(
    scene: &'a Scene,
    options: &MeshOptions,
    from_world: DAffine3,
    mesh_bounds: &HashMap<PathBuf, (DVec3, DVec3)>,
) -> Result<Walk<'a>, MeshError> {
    let mut w = Walk::default();
    let ctx = Ctx {
        options,
        max_distance: scene.render.max_distance,
        mesh_bounds,
    };
    for object in &scene.objects {
        visit(object, from_world, &ctx, &mut w)?;
    }
    Ok(w)
}

struct Ctx<'b> {
    options: &'b MeshOptions,
    max_distance: f64,
    mesh_bounds: &'b HashMap<PathBuf, (DVec3, DVec3)>,
}

/// The key under which equal analytic shapes share one tessellation: every shape but a
/// plane and a mesh file is tessellated from its parameters alone, so shapes whose `Debug`
/// forms agree (which keeps every f64 bit: shortest round-trip digits) are equal.
fn analytic_key(shape: &Shape) -> Option<ShapeKey> {
    match shape {
        Shape::Plane { .. } | Shape::Mesh { .. } => None,
        _ => Some(ShapeKey::Analytic(format!("{shape:?}"))),
    }
}

fn visit<'a>(
    node: &'a Node,
    parent: DAffine3,
    ctx: &Ctx,
    w: &mut Walk<'a>,
) -> Result<(), MeshError> {
    let m = parent * node.transform;
    match &node.kind {
        NodeKind::Leaf(Shape::Plane { .. }) => w.planes.push((node, m)),
        NodeKind::Leaf(Shape::Mesh { path }) => w.placements.push(Placement {
            node,
            key: ShapeKey::Mesh(path.clone()),
            to_render: m,
            material: node.material,
        }),
        NodeKind::Union(_) | NodeKind::Repeat { .. }
            if may_show_inner_faces(node, ctx) && camera_inside_solid(node, parent, ctx) =>
        {
            // A union (and a repetition, the union of its copies) is one solid: a camera
            // inside it sees its boundary, never the inner faces that separately placed
            // children or overlapping copies would show (scenes/README.md).
            w.notes.push(format!(
                "{}: the camera is inside this union: extracted as one surface so its inner faces stay hidden",
                node.json_path
            ));
            w.placements.push(Placement {
                node,
                key: ShapeKey::Composite(node as *const Node as usize),
                to_render: m,
                material: node.material,
            })
        }
        NodeKind::Union(children) => {
            // Tracing the children's surfaces gives the union's first hit for rays starting
            // outside every child; the arm above handles a camera inside. Secondary rays start
            // on the union's boundary, outside every child.
            for c in children {
                visit(c, m, ctx, w)?;
            }
        }
        NodeKind::Intersection(_) | NodeKind::Subtraction(_) | NodeKind::Smooth { .. } => {
            w.placements.push(Placement {
                node,
                key: ShapeKey::Composite(node as *const Node as usize),
                to_render: m,
                material: node.material,
            })
        }
        NodeKind::Repeat {
            child,
            period,
            count,
        } => {
            let offsets = repeat_offsets(node, child, *period, *count, m, ctx, w)?;
            for o in offsets {
                visit(child, m * DAffine3::from_translation(o), ctx, w)?;
            }
        }
        NodeKind::Leaf(shape) => {
            let key = analytic_key(shape).ok_or_else(|| MeshError::Unsupported {
                json_path: node.json_path.clone(),
                reason: "unknown shape".into(),
            })?;
            w.placements.push(Placement {
                node,
                key,
                to_render: m,
                material: node.material,
            });
        }
    }
    Ok(())
}

/// Whether placing `node`'s parts separately can show faces inside the solid: always for a
/// union, for a repetition only when the child exceeds its cell (copies overlap).
fn may_show_inner_faces(node: &Node, ctx: &Ctx) -> bool {
    match &node.kind {
        NodeKind::Repeat { child, period, .. } => {
            node_bounds(child, ctx.mesh_bounds).is_some_and(|(lo, hi)| {
                (0..3).any(|a| {
                    period[a] > 0.0 && (lo[a] < -0.5 * period[a] || hi[a] > 0.5 * period[a])
                })
            })
        }
        _ => true,
    }
}

/// Whether the camera (the render-space origin) lies inside `node`, a bounded union or
/// repetition of analytic solids whose parent-to-render transform is `parent`. Nodes holding
/// a plane, a mesh, a triangle or an infinite repetition are never extracted here (false).
fn camera_inside_solid(node: &Node, parent: DAffine3, ctx: &Ctx) -> bool {
    node_bounds(node, ctx.mesh_bounds).is_some()
        && camera_field_value(node, parent).is_some_and(|d| d < 0.0)
}

/// The distance field of `node` (its parent-to-render transform `parent`) at the camera, the
/// render-space origin; `None` when the node is not all analytic solids (its field would
/// need a bake) or its field does not compile.
fn camera_field_value(node: &Node, parent: DAffine3) -> Option<f64> {
    if !analytic_solids(node) {
        return None;
    }
    marchmesh_field::Field::compile_node(node, parent, &marchmesh_field::FieldOptions::default())
        .ok()
        .map(|f| f.distance_f64(DVec3::ZERO))
}

/// Whether every leaf under `n` is an analytic solid (no plane, mesh or triangle), so its
/// distance field compiles without baking anything.
fn analytic_solids(n: &Node) -> bool {
    match &n.kind {
        NodeKind::Leaf(shape) => shape.is_analytic_solid(),
        NodeKind::Union(c) | NodeKind::Intersection(c) | NodeKind::Subtraction(c) => {
            c.iter().all(analytic_solids)
        }
        NodeKind::Smooth { children, .. } => children.iter().all(analytic_solids),
        NodeKind::Repeat { child, .. } => analytic_solids(child),
    }
}

/// A lower bound of the distance in render units from the camera (the render-space origin)
/// to the surface of `node`, an analytic composite placed by `to_render` (its own transform
/// included): the magnitude of its distance field at the camera. The field is 1-Lipschitz
/// (every backend sphere-traces it), so no surface point is nearer than its value. `None`
/// when the node holds a plane, mesh or triangle (its field would need a bake) or its field
/// does not compile; the caller then keeps its own estimate.
pub(crate) fn camera_surface_distance(node: &Node, to_render: DAffine3) -> Option<f64> {
    camera_field_value(node, to_render * node.transform.inverse())
        .map(f64::abs)
        .filter(|d| d.is_finite())
}

/// Cell offsets (repeat node's frame) of a repetition: all cells of finite axes; on infinite
/// axes the cells whose copy of the child comes within `max_distance` of the camera.
fn repeat_offsets(
    node: &Node,
    child: &Node,
    period: DVec3,
    count: [Option<u32>; 3],
    m: DAffine3,
    ctx: &Ctx,
    w: &mut Walk,
) -> Result<Vec<DVec3>, MeshError> {
    let child_bounds = node_bounds(child, ctx.mesh_bounds);
    let infinite = (0..3).any(|a| period[a] > 0.0 && count[a].is_none());
    let Some((clo, chi)) = child_bounds.or(if infinite {
        None
    } else {
        Some((DVec3::ZERO, DVec3::ZERO))
    }) else {
        return Err(MeshError::Unsupported {
            json_path: node.json_path.clone(),
            reason:
                "infinite repetition of an unbounded child (a plane?) has no finite tessellation"
                    .into(),
        });
    };
    // A child wider than its cell: copies overlap (the repetition is the union of whole
    // copies, as in every backend); say so, since it often means a mistyped period.
    for a in 0..3 {
        if period[a] > 0.0
            && child_bounds.is_some()
            && (clo[a] < -period[a] * 0.5 - 1e-12 || chi[a] > period[a] * 0.5 + 1e-12)
        {
            w.notes.push(format!(
                "{}: the child exceeds its repetition cell on axis {a}: neighbouring copies overlap (a repetition is the union of whole copies)",
                node.json_path
            ));
            break;
        }
    }
    // Camera position and reach in the repeat node's frame.
    let inverse = m.inverse();
    let camera = inverse.transform_point3(DVec3::ZERO);
    let stretch_inv = max_stretch(&inverse.matrix3);
    let reach = ctx.max_distance * stretch_inv;
    let mut ranges: [(i64, i64); 3] = [(0, 0); 3];
    let mut centre = DVec3::ZERO;
    let mut total: u128 = 1;
    for a in 0..3 {
        let s = period[a];
        if s <= 0.0 {
            continue;
        }
        match count[a] {
            Some(n) => {
                ranges[a] = (0, i64::from(n) - 1);
                centre[a] = (f64::from(n) - 1.0) * 0.5;
            }
            None => {
                let lo_k = ((camera[a] - reach - chi[a]) / s).floor();
                let hi_k = ((camera[a] + reach - clo[a]) / s).ceil();
                let clamp = |k: f64| k.clamp(-9.0e15, 9.0e15) as i64;
                ranges[a] = (clamp(lo_k), clamp(hi_k));
            }
        }
        total = total.saturating_mul((ranges[a].1 - ranges[a].0 + 1).max(0) as u128);
    }
    if total > u128::from(ctx.options.max_instances()) {
        return Err(MeshError::TooManyInstances {
            json_path: node.json_path.clone(),
            cells: total.min(u128::from(u64::MAX)) as u64,
            limit: ctx.options.max_instances(),
            infinite,
        });
    }
    let mut out = Vec::new();
    for i in ranges[0].0..=ranges[0].1 {
        for j in ranges[1].0..=ranges[1].1 {
            for k in ranges[2].0..=ranges[2].1 {
                let idx = DVec3::new(i as f64, j as f64, k as f64);
                let o = (idx - centre) * period;
                if infinite {
                    // Cull copies entirely beyond max_distance (in render space).
                    let b = transform_bounds(&(m * DAffine3::from_translation(o)), (clo, chi));
                    if distance_to_box(b) > ctx.max_distance {
                        continue;
                    }
                }
                out.push(o);
            }
        }
    }
    if infinite {
        w.notes.push(format!(
            "{}: infinite repetition bounded to the {} cells whose copy comes within max_distance = {} of the camera (index ranges x {:?}, y {:?}, z {:?})",
            node.json_path,
            out.len(),
            ctx.max_distance,
            ranges[0],
            ranges[1],
            ranges[2]
        ));
    }
    w.repeat_cells += out.len() as u64;
    Ok(out)
}

/// Tessellation detail (shape-local) a placement needs under a fixed level or world chord
/// error (screen budgets are built per band, see `ScreenBudget`).
pub(crate) fn placement_detail(p: &Placement, tessellation: Tessellation) -> Detail<'static> {
    match tessellation {
        Tessellation::FixedLevel(level) => Detail::Level(level.min(12)),
        Tessellation::ChordError { world } => {
            Detail::ChordError(world / max_stretch(&p.to_render.matrix3))
        }
        // Not used for screen budgets; the coarsest level as a harmless fallback.
        Tessellation::ScreenError { .. } => Detail::Level(0),
    }
}

/// The finer of two details.
pub(crate) fn finer<'a>(a: Detail<'a>, b: Detail<'a>) -> Detail<'a> {
    match (a, b) {
        (Detail::ChordError(x), Detail::ChordError(y)) => Detail::ChordError(x.min(y)),
        (Detail::Level(x), Detail::Level(y)) => Detail::Level(x.max(y)),
        (x, _) => x,
    }
}
