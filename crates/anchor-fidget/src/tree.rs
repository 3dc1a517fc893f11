//! A marchmesh scene as one fidget [`Tree`] in render space (camera at the origin).
//!
//! Every leaf is the same signed distance function marchmesh's field compiles
//! (`crates/field/src/shapes.rs`), written out in fidget's operations over the render-space
//! axes: sphere `|p| - r`, box `|max(q, 0)| + min(max(qx, qy, qz), 0)` with `q = |p| - h`.
//! Transforms are inverted in f64 and folded into each leaf's coordinates as affine
//! expressions of `x, y, z` (zero coefficients dropped, so a translated sphere costs three
//! subtractions). Unions are balanced `min` trees, intersections `max`, subtractions
//! `max(a, -b)`.
//!
//! A plane becomes a **slab** of thickness [`TreeOptions::slab_thickness`] below it (fidget
//! clips every shape to its voxel volume, so an infinite half-space and a slab look the same
//! from above): the committed anchor scenes use a `box` instead, so marchmesh and fidget see
//! exactly the same finite solid. Other shapes are refused with an error naming them.

use anyhow::{Result, bail};
use fidget::context::Tree;
use glam::{DAffine3, DVec3};
use marchmesh_scene::{Node, NodeKind, Scene, Shape};

/// How scene shapes that fidget cannot take as they are become fidget trees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TreeOptions {
    /// Thickness (world units, > 0) of the slab a `plane` becomes, below the plane.
    pub slab_thickness: f64,
}

impl Default for TreeOptions {
    fn default() -> Self {
        Self {
            slab_thickness: 1.0,
        }
    }
}

/// The scene as one fidget tree.
#[derive(Debug, Clone)]
pub struct Translation {
    /// The shape's tree over render-space `x, y, z`.
    pub tree: Tree,
    /// Leaf shapes translated.
    pub leaves: usize,
    /// What was approximated (planes made slabs).
    pub notes: Vec<String>,
}

/// Translates every object of `scene` (an implicit union) into one tree over render-space
/// coordinates. Errors name the JSON path and the shape that fidget cannot be given.
pub fn scene_tree(scene: &Scene, opts: &TreeOptions) -> Result<Translation> {
    if !(opts.slab_thickness > 0.0 && opts.slab_thickness.is_finite()) {
        bail!("slab thickness must be > 0, got {}", opts.slab_thickness);
    }
    if scene.objects.is_empty() {
        bail!("{}: the scene has no objects", scene.source);
    }
    // Render space -> world space.
    let render_to_world = DAffine3::from_translation(scene.camera.position);
    let mut t = Translator {
        opts: *opts,
        leaves: 0,
        notes: Vec::new(),
    };
    let trees = scene
        .objects
        .iter()
        .map(|o| t.node(o, render_to_world))
        .collect::<Result<Vec<_>>>()?;
    Ok(Translation {
        tree: balanced(trees, |a, b| a.min(b)),
        leaves: t.leaves,
        notes: t.notes,
    })
}

struct Translator {
    opts: TreeOptions,
    leaves: usize,
    notes: Vec<String>,
}

impl Translator {
    /// `to_parent` maps render space to the node's parent frame.
    fn node(&mut self, n: &Node, to_parent: DAffine3) -> Result<Tree> {
        let inv = n.transform.inverse();
        if !inv.is_finite() {
            bail!("{}: singular transform", n.json_path);
        }
        let to_local = inv * to_parent;
        let children = |t: &mut Self, c: &[Node]| -> Result<Vec<Tree>> {
            c.iter().map(|c| t.node(c, to_local)).collect()
        };
        Ok(match &n.kind {
            NodeKind::Leaf(Shape::Sphere { radius }) => {
                self.leaves += 1;
                let [x, y, z] = affine_axes(&to_local);
                (x.square() + y.square() + z.square()).sqrt() - *radius
            }
            NodeKind::Leaf(Shape::Box { half_extents }) => {
                self.leaves += 1;
                let [x, y, z] = affine_axes(&to_local);
                let qx = x.abs() - half_extents.x;
                let qy = y.abs() - half_extents.y;
                let qz = z.abs() - half_extents.z;
                let outside =
                    (qx.max(0.0).square() + qy.max(0.0).square() + qz.max(0.0).square()).sqrt();
                let inside = qx.max(qy.max(qz)).min(0.0);
                outside + inside
            }
            NodeKind::Leaf(Shape::Plane { normal, offset }) => {
                self.leaves += 1;
                self.notes.push(format!(
                    "{}: plane made a slab {} thick below it (fidget clips it to its volume; marchmesh's plane reaches max_distance)",
                    n.json_path, self.opts.slab_thickness
                ));
                let [x, y, z] = affine_axes(&to_local);
                let s = linear(&normal.to_array(), [x, y, z], -*offset);
                s.max(-s.clone() - self.opts.slab_thickness)
            }
            NodeKind::Union(c) => balanced(children(self, c)?, |a, b| a.min(b)),
            NodeKind::Intersection(c) => balanced(children(self, c)?, |a, b| a.max(b)),
            NodeKind::Subtraction(c) => {
                let mut trees = children(self, c)?;
                if trees.len() == 1 {
                    trees.remove(0)
                } else {
                    let base = trees.remove(0);
                    base.max(-balanced(trees, |a, b| a.min(b)))
                }
            }
            _ => bail!(
                "{}.shape: not supported by the fidget anchor (supported: sphere, box, plane as a slab, union, intersection, subtraction)",
                n.json_path
            ),
        })
    }
}

/// `c . axes + k`, dropping zero terms and unit factors.
fn linear(c: &[f64; 3], axes: [Tree; 3], k: f64) -> Tree {
    let mut out: Option<Tree> = None;
    for (ci, a) in c.iter().zip(axes) {
        if *ci == 0.0 {
            continue;
        }
        let term = if *ci == 1.0 { a } else { a * *ci };
        out = Some(match out {
            None => term,
            Some(o) => o + term,
        });
    }
    match out {
        None => Tree::constant(k),
        Some(o) if k == 0.0 => o,
        Some(o) => o + k,
    }
}

/// The three local coordinates `to_local(p)` as trees over render-space `x, y, z`.
fn affine_axes(to_local: &DAffine3) -> [Tree; 3] {
    let m = to_local.matrix3;
    let t: DVec3 = to_local.translation;
    std::array::from_fn(|r| {
        let row = [m.x_axis[r], m.y_axis[r], m.z_axis[r]];
        linear(&row, [Tree::x(), Tree::y(), Tree::z()], t[r])
    })
}

/// Reduces `items` pairwise into a balanced tree (depth log2 n, so deep unions neither
/// overflow a recursive import nor defeat interval pruning). `items` must not be empty.
fn balanced(mut items: Vec<Tree>, op: impl Fn(Tree, Tree) -> Tree + Copy) -> Tree {
    while items.len() > 1 {
        let mut next = Vec::with_capacity(items.len().div_ceil(2));
        let mut it = items.into_iter();
        while let Some(a) = it.next() {
            next.push(match it.next() {
                Some(b) => op(a, b),
                None => a,
            });
        }
        items = next;
    }
    items.pop().unwrap_or_else(|| Tree::constant(f64::INFINITY))
}

#[cfg(test)]
mod tests {
    use super::*;
    use fidget::context::Context;
    use fidget::jit::JitShape;
    use fidget::shape::EzShape;
    use glam::Vec3;
    use marchmesh_sdf::SdfOptions;

    fn scene(json: &str) -> Scene {
        marchmesh_scene::parse_scene(json, "test", std::path::Path::new(".")).expect("scene")
    }

    /// Tiny deterministic generator (SplitMix64) for sample points.
    fn next(state: &mut u64) -> f64 {
        *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        (z ^ (z >> 31)) as f64 / u64::MAX as f64
    }

    /// fidget's JIT evaluation of the translated tree equals marchmesh's field (bounds off,
    /// so it evaluates every node exactly) at random render-space points around the shapes.
    #[test]
    fn translated_tree_gives_marchmesh_field_distances() {
        let s = scene(
            r#"{"camera": {"position": [0.5, 1, -4], "look_at": [0, 0, 0]},
                "objects": [
                  {"shape": {"sphere": {"radius": 1.3}}, "transform": {"translate": [0.2, -0.4, 0.7]}},
                  {"shape": {"box": {"half_extents": [0.5, 0.3, 0.8]}},
                   "transform": {"translate": [1.5, 0.5, 0], "rotate_deg": [10, 35, -20]}},
                  {"shape": {"union": {"children": [
                      {"shape": {"sphere": {"radius": 0.4}}, "transform": {"translate": [-1.5, 0, 0]}},
                      {"shape": {"box": {}}, "transform": {"translate": [0, 1.5, 0]}}]}},
                   "transform": {"translate": [0, 0, 1], "rotate_deg": [0, 0, 30]}}
                ]}"#,
        );
        let t = scene_tree(&s, &TreeOptions::default()).expect("translates");
        assert_eq!(t.leaves, 4);
        let mut ctx = Context::new();
        let node = ctx.import(&t.tree);
        let shape = JitShape::new(&ctx, node).expect("jit");
        let tape = shape.ez_point_tape();
        let mut eval = JitShape::new_point_eval();
        let sdf = marchmesh_sdf::build(
            &s,
            &SdfOptions {
                bounds: false,
                ..SdfOptions::DEFAULT
            },
        )
        .expect("sdf");
        let mut rng = 7u64;
        let cam = s.camera.position;
        for _ in 0..2000 {
            let world = DVec3::new(
                next(&mut rng) * 6.0 - 3.0,
                next(&mut rng) * 6.0 - 3.0,
                next(&mut rng) * 6.0 - 3.0,
            );
            let p = (world - cam).as_vec3();
            let (f, _) = eval.eval(&tape, p.x, p.y, p.z).expect("eval");
            let m = sdf.field().distance(Vec3::new(p.x, p.y, p.z));
            assert!(
                (f - m).abs() <= 2e-5 * (1.0 + m.abs()),
                "at {world:?}: fidget {f} vs marchmesh {m}"
            );
        }
    }

    #[test]
    fn unsupported_shapes_are_named() {
        let s = scene(r#"{"objects": [{"shape": {"torus": {}}}]}"#);
        let e = scene_tree(&s, &TreeOptions::default()).expect_err("torus");
        let msg = e.to_string();
        assert!(
            msg.contains("objects[0]") && msg.contains("`torus`"),
            "{msg}"
        );
    }

    #[test]
    fn planes_become_slabs() {
        let s = scene(r#"{"objects": [{"shape": {"plane": {"offset": -1}}}]}"#);
        let t = scene_tree(
            &s,
            &TreeOptions {
                slab_thickness: 0.5,
            },
        )
        .expect("plane");
        assert_eq!(t.notes.len(), 1);
        let mut ctx = Context::new();
        let node = ctx.import(&t.tree);
        let shape = JitShape::new(&ctx, node).expect("jit");
        let tape = shape.ez_point_tape();
        let mut eval = JitShape::new_point_eval();
        // Camera at the origin: render space is world space. Top at y = -1, bottom at -1.5.
        for (y, expect) in [(0.0f32, 1.0f32), (-1.2, -0.2), (-1.4, -0.1), (-2.0, 0.5)] {
            let (f, _) = eval.eval(&tape, 0.3, y, 4.0).expect("eval");
            assert!((f - expect).abs() < 1e-6, "y {y}: {f} vs {expect}");
        }
    }
}
