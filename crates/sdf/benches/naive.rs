//! The naive baseline the backend is measured against: plain sphere tracing over a recursive
//! tree evaluator (boxed nodes walked per step, inverse transforms precomputed but no flat
//! program, no bounding boxes, no relaxation, no lockstep), fixed absolute hit epsilon 1e-4,
//! central-difference normals with a fixed step 1e-3, closest-leaf materials. Only what the
//! benchmark scenes use
//! (no meshes, repetition by the single nearest copy).

use glam::{DAffine3, Vec3};
use marchmesh_core::{
    Geometry, GeometryReport, Hit, NoHit, OcclusionResult, Ray, RayWork, RenderSpace, Termination,
    TraceResult,
};
use marchmesh_field::V3;
use marchmesh_field::shapes;
use marchmesh_scene::{Node, NodeKind, Scene, Shape, SmoothOp};

enum Kind {
    Sphere(f32),
    Plane(Vec3, f32),
    Box(Vec3),
    Ellipsoid(Vec3),
    Cylinder(f32, f32),
    Torus(f32, f32),
    Union(Vec<NNode>),
    Intersection(Vec<NNode>),
    Subtraction(Vec<NNode>),
    Smooth(Vec<NNode>, f32),
    Repeat(Box<NNode>, Vec3),
    Unsupported,
}

struct NNode {
    inv: glam::Affine3A,
    scale: f32,
    material: u32,
    kind: Kind,
}

fn v(p: Vec3) -> V3<f32> {
    V3::new(p.x, p.y, p.z)
}

impl NNode {
    fn new(n: &Node, xf: DAffine3) -> NNode {
        let m = xf.matrix3;
        let scale = m
            .x_axis
            .length()
            .min(m.y_axis.length())
            .min(m.z_axis.length()) as f32;
        let kids = |c: &[Node]| c.iter().map(|c| NNode::new(c, c.transform)).collect();
        let kind = match &n.kind {
            NodeKind::Leaf(Shape::Sphere { radius }) => Kind::Sphere(*radius as f32),
            NodeKind::Leaf(Shape::Plane { normal, offset }) => {
                Kind::Plane(normal.as_vec3(), *offset as f32)
            }
            NodeKind::Leaf(Shape::Box { half_extents }) => Kind::Box(half_extents.as_vec3()),
            NodeKind::Leaf(Shape::Ellipsoid { radii }) => Kind::Ellipsoid(radii.as_vec3()),
            NodeKind::Leaf(Shape::Cylinder {
                radius,
                half_height,
            }) => Kind::Cylinder(*radius as f32, *half_height as f32),
            NodeKind::Leaf(Shape::Torus {
                major_radius,
                minor_radius,
            }) => Kind::Torus(*major_radius as f32, *minor_radius as f32),
            NodeKind::Union(c) => Kind::Union(kids(c)),
            NodeKind::Intersection(c) => Kind::Intersection(kids(c)),
            NodeKind::Subtraction(c) => Kind::Subtraction(kids(c)),
            NodeKind::Smooth {
                op: SmoothOp::Union,
                children,
                blend_radius,
            } => Kind::Smooth(kids(children), *blend_radius as f32),
            NodeKind::Repeat { child, period, .. } => Kind::Repeat(
                Box::new(NNode::new(child, child.transform)),
                period.as_vec3(),
            ),
            _ => Kind::Unsupported,
        };
        let inv = xf.inverse();
        NNode {
            inv: glam::Affine3A::from_mat3_translation(
                inv.matrix3.as_mat3(),
                inv.translation.as_vec3(),
            ),
            scale,
            material: n.material,
            kind,
        }
    }

    /// (distance, material of the closest leaf / defining child).
    fn eval(&self, p: Vec3) -> (f32, u32) {
        let q = self.inv.transform_point3(p);
        let leaf = |d: f32| (d, self.material);
        let min = |a: (f32, u32), b: (f32, u32)| if b.0 < a.0 { b } else { a };
        let max = |a: (f32, u32), b: (f32, u32)| if b.0 > a.0 { b } else { a };
        let (d, m) = match &self.kind {
            Kind::Sphere(r) => leaf(q.length() - r),
            Kind::Plane(n, o) => leaf(n.dot(q) - o),
            Kind::Box(b) => leaf(shapes::box3(v(q), v(*b))),
            Kind::Ellipsoid(r) => leaf(shapes::ellipsoid(v(q), v(r.recip()), r.min_element())),
            Kind::Cylinder(r, h) => leaf(shapes::cylinder(v(q), *r, *h)),
            Kind::Torus(a, b) => leaf(shapes::torus(v(q), *a, *b)),
            Kind::Union(c) => c.iter().map(|c| c.eval(q)).fold((f32::INFINITY, 0), min),
            Kind::Intersection(c) => c
                .iter()
                .map(|c| c.eval(q))
                .fold((f32::NEG_INFINITY, 0), max),
            Kind::Subtraction(c) => c[1..]
                .iter()
                .map(|c| {
                    let (d, m) = c.eval(q);
                    (-d, m)
                })
                .fold(c[0].eval(q), max),
            Kind::Smooth(c, k) => c[1..].iter().fold(c[0].eval(q), |a, c| {
                let b = c.eval(q);
                (
                    shapes::smin(a.0, b.0, *k, 1.0 / *k),
                    if b.0 < a.0 { b.1 } else { a.1 },
                )
            }),
            Kind::Repeat(c, per) => {
                let cell = |x: f32, p: f32| if p > 0.0 { x - p * (x / p).round() } else { x };
                c.eval(Vec3::new(
                    cell(q.x, per.x),
                    cell(q.y, per.y),
                    cell(q.z, per.z),
                ))
            }
            Kind::Unsupported => leaf(f32::INFINITY),
        };
        (d * self.scale, m)
    }
}

/// The naive tracer for one scene (render space).
pub struct NaiveGeometry {
    roots: Vec<NNode>,
    max_distance: f32,
}

const EPS: f32 = 1e-4;
const MAX_STEPS: u32 = 1000;

impl NaiveGeometry {
    /// Builds the tree.
    pub fn new(scene: &Scene) -> NaiveGeometry {
        let from_world = RenderSpace::of(scene).from_world();
        NaiveGeometry {
            roots: scene
                .objects
                .iter()
                .map(|o| NNode::new(o, from_world * o.transform))
                .collect(),
            max_distance: scene.render.max_distance as f32,
        }
    }

    fn dist_mat(&self, p: Vec3) -> (f32, u32) {
        self.roots
            .iter()
            .map(|n| n.eval(p))
            .fold((f32::INFINITY, 0), |a, b| if b.0 < a.0 { b } else { a })
    }

    fn dist(&self, p: Vec3) -> f32 {
        self.dist_mat(p).0
    }

    fn march(&self, ray: &Ray) -> (Option<f32>, Termination, u32) {
        let mut t = ray.t_min;
        let end = ray.t_max.min(self.max_distance);
        for i in 0..MAX_STEPS {
            let d = self.dist(ray.at(t));
            if d < EPS {
                return (Some(t), Termination::Hit, i + 1);
            }
            t += d;
            if t > end {
                return (None, Termination::MaxDistance, i + 1);
            }
        }
        (None, Termination::MaxSteps, MAX_STEPS)
    }
}

impl Geometry for NaiveGeometry {
    fn closest_hit(&self, ray: &Ray) -> TraceResult {
        let (t, termination, steps) = self.march(ray);
        let work = RayWork {
            steps,
            ..RayWork::default()
        };
        let hit = t.map(|t| {
            let p = ray.at(t);
            let h = 1e-3;
            let f = |o: Vec3| self.dist(p + o) - self.dist(p - o);
            let n = Vec3::new(f(Vec3::X * h), f(Vec3::Y * h), f(Vec3::Z * h)).normalize_or_zero();
            Hit {
                t,
                position: p,
                normal: n,
                material: self.dist_mat(p).1,
            }
        });
        match (hit, NoHit::try_from(termination)) {
            (Some(hit), _) => TraceResult::found(hit, work),
            (None, Ok(why)) => TraceResult::not_found(why, work),
            (None, Err(_)) => TraceResult::not_found(NoHit::Miss, work),
        }
    }

    fn occluded(&self, ray: &Ray) -> OcclusionResult {
        let (t, termination, steps) = self.march(ray);
        OcclusionResult {
            occluded: t.is_some(),
            termination,
            work: RayWork {
                steps,
                ..RayWork::default()
            },
        }
    }

    fn report(&self) -> GeometryReport {
        GeometryReport {
            backend: "naive".into(),
            ..GeometryReport::default()
        }
    }
}
