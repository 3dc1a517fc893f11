//! Validation of a parsed [`SceneFile`] and its conversion to the resolved [`Scene`].
//!
//! Every rejected value is reported with its JSON path and a reason; all problems in a file
//! are collected, not just the first.

use std::path::Path;

use glam::{DAffine3, DVec3};

use crate::format::*;
use crate::resolved::*;

/// Largest accepted image side in pixels.
pub const MAX_IMAGE_SIDE: u32 = 16_384;
/// Largest accepted pixel count (width * height).
pub const MAX_PIXELS: u64 = 64 * 1024 * 1024;
/// Deepest accepted object nesting in a file (CSG and repeat nodes): a left-deep binary
/// tree of 10,000 blended primitives, as modelling tools write them, is 10,000 levels deep.
/// Parsing and validation walk it on stacks grown by [`crate::deep::guard`].
pub const MAX_NESTING_DEPTH: usize = 16_384;
/// Deepest accepted JSON nesting (objects and arrays): four per object level (the object,
/// `shape`, the operator, `children`) and a few for the top level and leaf parameters.
/// Deeper text is refused before parsing, with its line and column.
pub const MAX_JSON_DEPTH: usize = 4 * MAX_NESTING_DEPTH + 16;
/// Deepest accepted object nesting of the resolved scene, after every node whose first
/// child is the same operation (same blend radius, no transform of its own) took over that
/// child's children, which keeps the value: a fold is left to right. Every backend's
/// compiler and evaluator recurses this deep on its caller's stack (a rayon worker's).
pub const MAX_MERGED_DEPTH: usize = 64;
/// Longest JSON path a node keeps for its messages: beyond it a run of one repeated step is
/// written once with its count, `(.shape.union.children[0]){9999}`, and other long paths
/// keep their start and end around `...`.
pub const MAX_JSON_PATH_CHARS: usize = 256;
/// Most nodes accepted in one scene.
pub const MAX_NODES: usize = 100_000;
/// Largest accepted finite repetition count on one axis.
pub const MAX_REPEAT_COUNT_PER_AXIS: u32 = 1_000_000;
/// Largest accepted product, over a chain of nested repeat nodes, of the copies of each
/// node's child evaluated per query ([`repeat_copies_per_query`]): nested repetitions
/// multiply, so ten nested infinite repeats along one axis of a small child cost `2 * 5^9`
/// (3.9 million) child evaluations per query on the sdf backend. 1024 keeps the worst
/// accepted scene to about a thousand child evaluations per query (e.g. two nested 3-axis
/// repeats whose children fit their periods, the inner one finite: 27 x 27 = 729).
pub const MAX_NESTED_REPEAT_FACTOR: u64 = 1024;
/// Most copies of a repeated child the sdf backend evaluates per repeated axis and query:
/// the copies whose box overlaps a window around the point at most a period wide, so 3 for a
/// child that fits its period, more for a wider one, this many for a child wider than
/// `REPEAT_WINDOW - 1` periods or unbounded along the axis (another infinite repetition along
/// it, a plane, a mesh whose box is not known before loading). The field compiler's window.
pub const REPEAT_WINDOW: u64 = 5;
/// Largest accepted magnitude of any coordinate or length (world units).
pub const MAX_COORDINATE: f64 = 1e12;
/// Most samples per pixel for the Whitted integrator (all samples of a row are traced as one
/// wavefront).
pub const MAX_SAMPLES_PER_PIXEL: u32 = 1024;
/// Most samples per pixel for the path tracer (traced in bounded chunks, for converged
/// ground truth).
pub const MAX_PATH_SAMPLES_PER_PIXEL: u32 = 65_536;
/// The samples-per-pixel cap of `integrator`.
pub fn max_samples_per_pixel(integrator: Integrator) -> u32 {
    match integrator {
        Integrator::Whitted => MAX_SAMPLES_PER_PIXEL,
        Integrator::Path => MAX_PATH_SAMPLES_PER_PIXEL,
    }
}
/// Most area-light shadow rays or ambient-occlusion rays per shading point.
pub const MAX_LIGHT_SAMPLES: u32 = 4096;
/// Most path-tracer bounces.
pub const MAX_BOUNCES: u32 = 64;

/// One thing wrong with a scene.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// JSON path of the offending value, e.g. `objects[0].shape.sphere.radius`.
    pub json_path: String,
    /// Why it is rejected.
    pub reason: String,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "at `{}`: {}", shown_path(&self.json_path), self.reason)
    }
}

/// Longest JSON path a message shows whole; a longer one (a value thousands of levels deep)
/// is shown as its start, the number of characters left out and its end.
pub const SHOWN_PATH_MAX_CHARS: usize = 240;

/// `json_path` as messages show it: whole up to [`SHOWN_PATH_MAX_CHARS`] characters,
/// otherwise its first 80 and last 120 characters around a count of those left out.
pub fn shown_path(json_path: &str) -> std::borrow::Cow<'_, str> {
    let chars = json_path.chars().count();
    if chars <= SHOWN_PATH_MAX_CHARS {
        return json_path.into();
    }
    let head: String = json_path.chars().take(80).collect();
    let tail: String = json_path.chars().skip(chars - 120).collect();
    format!("{head}...({} characters)...{tail}", chars - 200).into()
}

/// Checks an image size against the limits.
pub fn check_image_size(width: u32, height: u32) -> Result<(), String> {
    if width == 0 || height == 0 {
        return Err(format!("image size {width}x{height} is empty"));
    }
    if width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
        return Err(format!(
            "image size {width}x{height} exceeds the limit of {MAX_IMAGE_SIDE} pixels per side"
        ));
    }
    if width as u64 * height as u64 > MAX_PIXELS {
        return Err(format!(
            "image size {width}x{height} exceeds the limit of {MAX_PIXELS} pixels"
        ));
    }
    Ok(())
}

struct Ctx<'a> {
    base_dir: &'a Path,
    problems: Vec<Problem>,
    materials: Vec<Material>,
    nodes: usize,
}

impl Ctx<'_> {
    fn fail(&mut self, path: &str, reason: impl Into<String>) {
        self.problems.push(Problem {
            json_path: path.to_string(),
            reason: reason.into(),
        });
    }

    fn finite(&mut self, path: &str, v: f64) -> f64 {
        self.finite_or_fail(path, v).unwrap_or(0.0)
    }

    /// `v` when finite and within [`MAX_COORDINATE`] in magnitude; otherwise the one problem
    /// is recorded and `None` returned, so range checks on the value are not made as well.
    fn finite_or_fail(&mut self, path: &str, v: f64) -> Option<f64> {
        if !v.is_finite() {
            self.fail(path, format!("{v} is not a finite number"));
            None
        } else if v.abs() > MAX_COORDINATE {
            self.fail(
                path,
                format!("{v:e} exceeds the magnitude limit {MAX_COORDINATE:e}"),
            );
            None
        } else {
            Some(v)
        }
    }

    fn positive(&mut self, path: &str, v: f64) -> f64 {
        let Some(v) = self.finite_or_fail(path, v) else {
            return 0.0;
        };
        if v <= 0.0 {
            self.fail(path, format!("must be > 0, got {v}"));
        }
        v
    }

    fn non_negative(&mut self, path: &str, v: f64) -> f64 {
        let Some(v) = self.finite_or_fail(path, v) else {
            return 0.0;
        };
        if v < 0.0 {
            self.fail(path, format!("must be >= 0, got {v}"));
        }
        v.max(0.0)
    }

    fn in_range(&mut self, path: &str, v: f64, lo: f64, hi: f64) -> f64 {
        let Some(v) = self.finite_or_fail(path, v) else {
            return 0.0;
        };
        if !(lo..=hi).contains(&v) {
            self.fail(path, format!("must be in [{lo}, {hi}], got {v}"));
        }
        v
    }

    /// A count in `1..=max`.
    fn count_in(&mut self, path: &str, v: u32, max: u32) {
        if !(1..=max).contains(&v) {
            self.fail(path, format!("must be in 1..={max}, got {v}"));
        }
    }

    /// An emitter's `intensity * color`, both checked (`path` is the light's JSON path).
    fn emission(&mut self, path: &str, intensity: f64, color: [f64; 3]) -> DVec3 {
        let i = self.in_range(&format!("{path}.intensity"), intensity, 0.0, 1e6);
        i * self.color(&format!("{path}.color"), color)
    }

    fn vec3(&mut self, path: &str, v: [f64; 3]) -> DVec3 {
        DVec3::new(
            self.finite(&format!("{path}[0]"), v[0]),
            self.finite(&format!("{path}[1]"), v[1]),
            self.finite(&format!("{path}[2]"), v[2]),
        )
    }

    fn unit(&mut self, path: &str, v: [f64; 3]) -> DVec3 {
        let d = self.vec3(path, v);
        match d.try_normalize() {
            Some(u) => u,
            None => {
                self.fail(path, "must not be the zero vector");
                DVec3::Y
            }
        }
    }

    fn color(&mut self, path: &str, c: [f64; 3]) -> DVec3 {
        DVec3::new(
            self.in_range(&format!("{path}[0]"), c[0], 0.0, 1.0),
            self.in_range(&format!("{path}[1]"), c[1], 0.0, 1.0),
            self.in_range(&format!("{path}[2]"), c[2], 0.0, 1.0),
        )
    }

    fn material(&mut self, path: &str, m: &MaterialSpec) -> MaterialId {
        let color = self.color(&format!("{path}.color"), m.color);
        let specular_exponent = m
            .specular_exponent
            .map(|s| self.positive(&format!("{path}.specular_exponent"), s));
        let reflectivity = self.in_range(&format!("{path}.reflectivity"), m.reflectivity, 0.0, 1.0);
        self.materials.push(Material {
            color,
            specular_exponent,
            reflectivity,
        });
        (self.materials.len() - 1) as MaterialId
    }

    fn object(
        &mut self,
        path: &str,
        o: &ObjectSpec,
        inherited: MaterialId,
        depth: usize,
    ) -> Option<Node> {
        crate::deep::guard(|| self.object_here(path, o, inherited, depth))
    }

    /// [`Ctx::object`] on the current stack.
    fn object_here(
        &mut self,
        path: &str,
        o: &ObjectSpec,
        inherited: MaterialId,
        depth: usize,
    ) -> Option<Node> {
        self.nodes += 1;
        if self.nodes > MAX_NODES {
            if self.nodes == MAX_NODES + 1 {
                self.fail(path, format!("the scene has more than {MAX_NODES} objects"));
            }
            return None;
        }
        if depth > MAX_NESTING_DEPTH {
            self.fail(
                path,
                format!("objects nest deeper than the limit of {MAX_NESTING_DEPTH} levels"),
            );
            return None;
        }
        let material = match &o.material {
            Some(m) => self.material(&format!("{path}.material"), m),
            None => inherited,
        };
        let t = &o.transform;
        let tp = format!("{path}.transform");
        let translate = self.vec3(&format!("{tp}.translate"), t.translate);
        let rotate = self.vec3(&format!("{tp}.rotate_deg"), t.rotate_deg);
        let scale = match t.scale {
            ScaleSpec::Uniform(s) => DVec3::splat(self.positive(&format!("{tp}.scale"), s)),
            ScaleSpec::PerAxis(s) => DVec3::new(
                self.positive(&format!("{tp}.scale[0]"), s[0]),
                self.positive(&format!("{tp}.scale[1]"), s[1]),
                self.positive(&format!("{tp}.scale[2]"), s[2]),
            ),
        };
        let sp = format!("{path}.shape");
        let kind = merge_first_child(self.shape(&sp, &o.shape, material, depth)?);
        Some(Node {
            transform: compose_transform(translate, rotate, scale),
            material,
            name: o.name.clone(),
            json_path: path.to_string(),
            kind,
        })
    }

    fn children(
        &mut self,
        path: &str,
        children: &[ObjectSpec],
        material: MaterialId,
        depth: usize,
    ) -> Vec<Node> {
        if children.is_empty() {
            self.fail(path, "needs at least one child");
        }
        children
            .iter()
            .enumerate()
            .filter_map(|(i, c)| self.object(&child_path(path, i), c, material, depth + 1))
            .collect()
    }

    /// A smooth CSG node `{"key": {...}}` at `path`.
    fn smooth(
        &mut self,
        path: &str,
        key: &str,
        op: SmoothOp,
        s: &SmoothUnionSpec,
        material: MaterialId,
        depth: usize,
    ) -> NodeKind {
        NodeKind::Smooth {
            op,
            children: self.children(
                &format!("{path}.{key}.children"),
                &s.children,
                material,
                depth,
            ),
            blend_radius: self.positive(&format!("{path}.{key}.blend_radius"), s.blend_radius),
        }
    }

    fn shape(
        &mut self,
        path: &str,
        s: &ShapeSpec,
        material: MaterialId,
        depth: usize,
    ) -> Option<NodeKind> {
        Some(match s {
            ShapeSpec::Sphere(s) => NodeKind::Leaf(Shape::Sphere {
                radius: self.positive(&format!("{path}.sphere.radius"), s.radius),
            }),
            ShapeSpec::Plane(p) => NodeKind::Leaf(Shape::Plane {
                normal: self.unit(&format!("{path}.plane.normal"), p.normal),
                offset: self.finite(&format!("{path}.plane.offset"), p.offset),
            }),
            ShapeSpec::Triangle(t) => {
                let p = format!("{path}.triangle.vertices");
                let v = [
                    self.vec3(&format!("{p}[0]"), t.vertices[0]),
                    self.vec3(&format!("{p}[1]"), t.vertices[1]),
                    self.vec3(&format!("{p}[2]"), t.vertices[2]),
                ];
                let n = (v[1] - v[0]).cross(v[2] - v[0]);
                let scale = (v[1] - v[0]).length() * (v[2] - v[0]).length();
                let area_ok = n.length() > 1e-12 * scale; // false for NaN too
                if !area_ok {
                    self.fail(&p, "the vertices are collinear or coincide (zero area)");
                }
                NodeKind::Leaf(Shape::Triangle { vertices: v })
            }
            ShapeSpec::Box(b) => {
                let p = format!("{path}.box.half_extents");
                NodeKind::Leaf(Shape::Box {
                    half_extents: DVec3::new(
                        self.positive(&format!("{p}[0]"), b.half_extents[0]),
                        self.positive(&format!("{p}[1]"), b.half_extents[1]),
                        self.positive(&format!("{p}[2]"), b.half_extents[2]),
                    ),
                })
            }
            ShapeSpec::Ellipsoid(e) => {
                let p = format!("{path}.ellipsoid.radii");
                NodeKind::Leaf(Shape::Ellipsoid {
                    radii: DVec3::new(
                        self.positive(&format!("{p}[0]"), e.radii[0]),
                        self.positive(&format!("{p}[1]"), e.radii[1]),
                        self.positive(&format!("{p}[2]"), e.radii[2]),
                    ),
                })
            }
            ShapeSpec::Cylinder(c) => NodeKind::Leaf(Shape::Cylinder {
                radius: self.positive(&format!("{path}.cylinder.radius"), c.radius),
                half_height: 0.5 * self.positive(&format!("{path}.cylinder.height"), c.height),
            }),
            ShapeSpec::Torus(t) => {
                let major = self.positive(&format!("{path}.torus.major_radius"), t.major_radius);
                let minor = self.positive(&format!("{path}.torus.minor_radius"), t.minor_radius);
                if minor > major {
                    self.fail(
                        &format!("{path}.torus.minor_radius"),
                        format!("must be <= major_radius ({major}), got {minor}"),
                    );
                }
                NodeKind::Leaf(Shape::Torus {
                    major_radius: major,
                    minor_radius: minor,
                })
            }
            ShapeSpec::RoundedBox(b) => {
                let p = format!("{path}.rounded_box");
                let half_extents = DVec3::new(
                    self.positive(&format!("{p}.half_extents[0]"), b.half_extents[0]),
                    self.positive(&format!("{p}.half_extents[1]"), b.half_extents[1]),
                    self.positive(&format!("{p}.half_extents[2]"), b.half_extents[2]),
                );
                let rp = format!("{p}.rounding_radius");
                let r = self.non_negative(&rp, b.rounding_radius);
                let smallest = half_extents.min_element();
                if r > smallest {
                    self.fail(
                        &rp,
                        format!("must be <= the smallest half extent ({smallest}), got {r}"),
                    );
                }
                NodeKind::Leaf(Shape::RoundedBox {
                    half_extents,
                    rounding_radius: r.min(smallest),
                })
            }
            ShapeSpec::Capsule(c) => NodeKind::Leaf(Shape::Capsule {
                radius: self.positive(&format!("{path}.capsule.radius"), c.radius),
                half_height: 0.5 * self.non_negative(&format!("{path}.capsule.height"), c.height),
            }),
            ShapeSpec::CappedCone(c) => {
                let p = format!("{path}.capped_cone");
                let half_height = 0.5 * self.positive(&format!("{p}.height"), c.height);
                let bottom = self.non_negative(&format!("{p}.bottom_radius"), c.bottom_radius);
                let top = self.non_negative(&format!("{p}.top_radius"), c.top_radius);
                if bottom == 0.0 && top == 0.0 {
                    self.fail(&p, "bottom_radius and top_radius are both 0 (no volume)");
                }
                NodeKind::Leaf(Shape::CappedCone {
                    half_height,
                    bottom_radius: bottom,
                    top_radius: top,
                })
            }
            ShapeSpec::Mesh(m) => {
                let full = self.base_dir.join(&m.path);
                if m.path.trim().is_empty() {
                    self.fail(&format!("{path}.mesh.path"), "must not be empty");
                } else if let Some(reason) = not_a_readable_file(&full) {
                    self.fail(
                        &format!("{path}.mesh.path"),
                        format!("{}: {reason}", full.display()),
                    );
                }
                NodeKind::Leaf(Shape::Mesh { path: full })
            }
            ShapeSpec::Union(c) => NodeKind::Union(self.children(
                &format!("{path}.union.children"),
                &c.children,
                material,
                depth,
            )),
            ShapeSpec::Intersection(c) => NodeKind::Intersection(self.children(
                &format!("{path}.intersection.children"),
                &c.children,
                material,
                depth,
            )),
            ShapeSpec::Subtraction(c) => NodeKind::Subtraction(self.children(
                &format!("{path}.subtraction.children"),
                &c.children,
                material,
                depth,
            )),
            ShapeSpec::SmoothUnion(s) => {
                self.smooth(path, "smooth_union", SmoothOp::Union, s, material, depth)
            }
            ShapeSpec::SmoothIntersection(s) => self.smooth(
                path,
                "smooth_intersection",
                SmoothOp::Intersection,
                s,
                material,
                depth,
            ),
            ShapeSpec::SmoothSubtraction(s) => self.smooth(
                path,
                "smooth_subtraction",
                SmoothOp::Subtraction,
                s,
                material,
                depth,
            ),
            ShapeSpec::Blend(s) => self.smooth(path, "blend", SmoothOp::Blend, s, material, depth),
            ShapeSpec::Repeat(r) => {
                let p = format!("{path}.repeat");
                let mut period = DVec3::ZERO;
                for axis in 0..3 {
                    period[axis] =
                        self.non_negative(&format!("{p}.period[{axis}]"), r.period[axis]);
                    if let Some(n) = r.count[axis]
                        && (n == 0 || n > MAX_REPEAT_COUNT_PER_AXIS)
                    {
                        self.fail(
                            &format!("{p}.count[{axis}]"),
                            format!("must be in 1..={MAX_REPEAT_COUNT_PER_AXIS}, got {n}"),
                        );
                    }
                }
                if period.max_element() <= 0.0 {
                    self.fail(
                        &format!("{p}.period"),
                        "at least one axis needs a period > 0",
                    );
                }
                let child = self.object(&format!("{p}.child"), &r.child, material, depth + 1);
                if let Some(child) = &child {
                    // Counted from the innermost repeat out: the first (innermost) repeat whose
                    // chain crosses the limit is the one reported.
                    let below = nested_repeat_work(child);
                    let copies =
                        repeat_copies_per_query(period, r.count, child.bounds_in_parent(&|_| None));
                    let work = below.saturating_mul(copies);
                    if work > MAX_NESTED_REPEAT_FACTOR && below <= MAX_NESTED_REPEAT_FACTOR {
                        self.fail(
                            &p,
                            format!(
                                "nested repetitions evaluate {work} copies of the innermost child per query ({copies} copies of this repeat's child times {below} below it), over the limit of {MAX_NESTED_REPEAT_FACTOR}: the sdf backend evaluates up to 3 copies per repeated axis of a child that fits its period and {REPEAT_WINDOW} of one wider than {} periods or unbounded along the axis (such as another infinite repetition along it); nest fewer repeats, repeat fewer axes or give them counts",
                                REPEAT_WINDOW - 1
                            ),
                        );
                    }
                }
                let child = child?;
                NodeKind::Repeat {
                    child: Box::new(child),
                    period,
                    count: r.count,
                }
            }
        })
    }
}

/// The JSON path of child `i` of the child list at `list` (`...children`): `list[i]`,
/// with a trailing run of one repeated object step kept as `(step){n}` and long paths cut,
/// so that paths stay short however deep the tree ([`MAX_JSON_PATH_CHARS`]).
fn child_path(list: &str, i: usize) -> String {
    let full = format!("{list}[{i}]");
    // The step from the parent object to this child: `.shape.<op>.children[i]`.
    if let Some(at) = list.rfind(".shape.") {
        let (parent, op_list) = list.split_at(at);
        let step = format!("{op_list}[{i}]");
        let run = format!("({step}){{");
        let mut head = parent;
        let mut n = 1u64;
        while let Some(h) = head.strip_suffix(step.as_str()) {
            head = h;
            n += 1;
        }
        // Steps that follow a run of the same step join it.
        if let Some(open) = head.rfind(&run)
            && let Some(m) = head[open + run.len()..]
                .strip_suffix('}')
                .and_then(|m| m.parse::<u64>().ok())
        {
            return format!("{}{run}{}}}", &head[..open], m + n);
        }
        if n > 1 && full.len() > MAX_JSON_PATH_CHARS {
            return format!("{head}{run}{n}}}");
        }
    }
    elide(&full)
}

/// `path` cut to its first and last characters around `...` when longer than
/// [`MAX_JSON_PATH_CHARS`].
fn elide(path: &str) -> String {
    if path.len() <= MAX_JSON_PATH_CHARS {
        return path.to_string();
    }
    let keep = MAX_JSON_PATH_CHARS / 2 - 2;
    let mut a = keep;
    while !path.is_char_boundary(a) {
        a -= 1;
    }
    let mut b = path.len() - keep;
    while !path.is_char_boundary(b) {
        b += 1;
    }
    format!("{}...{}", &path[..a], &path[b..])
}

/// `kind` with its first child's children spliced in when that child is the same operation
/// (the same blend radius for smooth ones) with the identity transform: every operation
/// folds its children left to right, so `op(op(a, b), c)` is `op(a, b, c)` exactly, and a
/// left-deep chain of N levels becomes one node of N + 1 children (built bottom-up, each
/// level moves only its own further children).
fn merge_first_child(mut kind: NodeKind) -> NodeKind {
    let plain = |n: &Node| n.transform == DAffine3::IDENTITY;
    let mergeable = match &kind {
        NodeKind::Union(c) | NodeKind::Intersection(c) | NodeKind::Subtraction(c) => {
            c.first().is_some_and(|f| {
                plain(f) && std::mem::discriminant(&f.kind) == std::mem::discriminant(&kind)
            })
        }
        NodeKind::Smooth {
            op,
            children,
            blend_radius,
        } => children.first().is_some_and(|f| {
            // A blend is not a fold: blend(blend(a, b), c) is not blend(a, b, c).
            *op != SmoothOp::Blend
                && plain(f)
                && matches!(&f.kind, NodeKind::Smooth { op: o, blend_radius: k, .. }
                    if o == op && k.to_bits() == blend_radius.to_bits())
        }),
        NodeKind::Leaf(_) | NodeKind::Repeat { .. } => false,
    };
    if let (
        true,
        NodeKind::Union(c)
        | NodeKind::Intersection(c)
        | NodeKind::Subtraction(c)
        | NodeKind::Smooth { children: c, .. },
    ) = (mergeable, &mut kind)
    {
        let rest = c.split_off(1);
        if let Some(mut first) = c.pop() {
            let mut merged = first.kind.take_children();
            merged.extend(rest);
            *c = merged;
        }
    }
    kind
}

/// The first node (pre-order) deeper than `max` levels below the top, if any; walked with
/// an explicit stack.
fn deepest_beyond(objects: &[Node], max: usize) -> Option<&Node> {
    let mut stack: Vec<(&Node, usize)> = objects.iter().map(|o| (o, 1)).collect();
    while let Some((n, depth)) = stack.pop() {
        if depth > max {
            return Some(n);
        }
        stack.extend(n.children().iter().map(|c| (c, depth + 1)));
    }
    None
}

/// Copies of a repeat node's child the sdf backend evaluates per query (the most of any
/// backend: the reference walks cells with its own bound on work per query, the mesh backend
/// places instances under `max_instances`): per repeated axis, the copies whose box
/// (`child_box`, in the repeat's frame; `None` when unknown, e.g. a mesh file) overlaps a
/// window at most as wide as the smallest period, at most [`REPEAT_WINDOW`], and at most the
/// axis's count.
pub fn repeat_copies_per_query(
    period: DVec3,
    count: [Option<u32>; 3],
    child_box: Option<crate::bounds::Aabb>,
) -> u64 {
    let smallest = (0..3)
        .filter(|&a| period[a] > 0.0)
        .map(|a| period[a])
        .fold(f64::INFINITY, f64::min);
    (0..3)
        .filter(|&a| period[a] > 0.0)
        .map(|a| {
            let p = period[a];
            let width = child_box.map_or(f64::INFINITY, |b| b.hi[a] - b.lo[a]);
            let window = if width.is_finite() && width < (REPEAT_WINDOW - 1) as f64 * p {
                // Lattice points in an interval of length `smallest + width`.
                (((smallest + width) / p).floor() as u64 + 1).min(REPEAT_WINDOW)
            } else {
                REPEAT_WINDOW
            };
            count[a].map_or(window, |n| window.min(u64::from(n)))
        })
        .fold(1u64, u64::saturating_mul)
}

/// The largest product of [`repeat_copies_per_query`] over the chains of repeat nodes in
/// `node`'s subtree (1 without repeats).
fn nested_repeat_work(node: &Node) -> u64 {
    // One guarded level per node: trees nest as deep as their files.
    let below = crate::deep::guard(|| {
        node.children()
            .iter()
            .map(nested_repeat_work)
            .max()
            .unwrap_or(1)
    });
    match &node.kind {
        NodeKind::Repeat {
            child,
            period,
            count,
        } => below.saturating_mul(repeat_copies_per_query(
            *period,
            *count,
            child.bounds_in_parent(&|_| None),
        )),
        _ => below,
    }
}

/// Why an existing `path` cannot be a mesh or image file (a folder, a device or FIFO), or
/// `None` if it is a regular file (symlinks followed) or does not exist.
fn not_a_readable_file(path: &Path) -> Option<&'static str> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => None,
        Ok(m) if m.is_dir() => Some("is a folder, not a file"),
        Ok(_) => Some("is a device, FIFO or socket, not a regular file"),
        // A missing file is reported when the mesh or image is loaded (scenes are validated
        // before their assets exist, e.g. in tests and by generators).
        Err(_) => None,
    }
}

/// Validates `file` and converts it. `base_dir` resolves relative mesh and image paths;
/// `source` names the scene in messages.
pub fn resolve(file: &SceneFile, base_dir: &Path, source: &str) -> Result<Scene, Vec<Problem>> {
    let mut cx = Ctx {
        base_dir,
        problems: Vec::new(),
        materials: vec![Material {
            color: DVec3::from_array(MaterialSpec::default().color),
            specular_exponent: None,
            reflectivity: 0.0,
        }],
        nodes: 0,
    };

    let c = &file.camera;
    let position = cx.vec3("camera.position", c.position);
    let look_at = cx.vec3("camera.look_at", c.look_at);
    let up = cx.vec3("camera.up", c.up);
    let vfov = cx.finite_or_fail("camera.vfov_deg", c.vfov_deg);
    if let Some(vfov) = vfov
        && !(vfov > 0.0 && vfov < 180.0)
    {
        cx.fail(
            "camera.vfov_deg",
            format!("must be in (0, 180) degrees, got {vfov}"),
        );
    }
    let vfov = vfov.unwrap_or(0.0);
    if let Err(e) = check_image_size(c.width, c.height) {
        cx.fail("camera.width", e);
    }
    let forward = look_at - position;
    let rel = forward.length() / position.length().max(look_at.length()).max(1e-300);
    if forward.length() == 0.0 || rel < 1e-12 {
        cx.fail("camera.look_at", "must differ from camera.position");
    } else if up.length() == 0.0 {
        cx.fail("camera.up", "must not be the zero vector");
    } else if forward.normalize().cross(up.normalize()).length() < 1e-9 {
        cx.fail(
            "camera.up",
            "must not be parallel to the view direction (look_at - position)",
        );
    }
    let camera = Camera::look_at(position, look_at, up, vfov, c.width, c.height);

    let mut lights = Vec::new();
    for (i, l) in file.lights.iter().enumerate() {
        lights.push(match l {
            LightSpec::Ambient(a) => Light::Ambient {
                intensity: cx.in_range(
                    &format!("lights[{i}].ambient.intensity"),
                    a.intensity,
                    0.0,
                    1e6,
                ),
            },
            LightSpec::Point(p) => Light::Point {
                position: cx.vec3(&format!("lights[{i}].point.position"), p.position),
                intensity: cx.in_range(
                    &format!("lights[{i}].point.intensity"),
                    p.intensity,
                    0.0,
                    1e6,
                ),
                casts_shadows: p.casts_shadows,
            },
            LightSpec::Directional(d) => Light::Directional {
                direction: cx.unit(&format!("lights[{i}].directional.direction"), d.direction),
                intensity: cx.in_range(
                    &format!("lights[{i}].directional.intensity"),
                    d.intensity,
                    0.0,
                    1e6,
                ),
                casts_shadows: d.casts_shadows,
            },
            LightSpec::SphereLight(l) => {
                let path = format!("lights[{i}].sphere_light");
                Light::Sphere {
                    center: cx.vec3(&format!("{path}.position"), l.position),
                    radius: cx.positive(&format!("{path}.radius"), l.radius),
                    emission: cx.emission(&path, l.intensity, l.color),
                    casts_shadows: l.casts_shadows,
                }
            }
            LightSpec::RectangleLight(l) => {
                let path = format!("lights[{i}].rectangle_light");
                let edge_u = cx.vec3(&format!("{path}.edge_u"), l.edge_u);
                let edge_v = cx.vec3(&format!("{path}.edge_v"), l.edge_v);
                let area = edge_u.cross(edge_v).length();
                if area <= 1e-12 * edge_u.length() * edge_v.length() {
                    cx.fail(
                        &format!("{path}.edge_v"),
                        "must be non-zero and not parallel to edge_u (the rectangle has no area)",
                    );
                }
                Light::Rectangle {
                    corner: cx.vec3(&format!("{path}.corner"), l.corner),
                    edge_u,
                    edge_v,
                    emission: cx.emission(&path, l.intensity, l.color),
                    casts_shadows: l.casts_shadows,
                }
            }
        });
    }

    let background = match &file.background {
        BackgroundSpec::Color(c) => Background::Color(cx.color("background.color", *c)),
        BackgroundSpec::Environment(e) => {
            if e.path.trim().is_empty() {
                cx.fail("background.environment.path", "must not be empty");
            } else if let Some(reason) = not_a_readable_file(&base_dir.join(&e.path)) {
                cx.fail(
                    "background.environment.path",
                    format!("{}: {reason}", base_dir.join(&e.path).display()),
                );
            }
            Background::Environment {
                path: base_dir.join(&e.path),
                intensity: cx.in_range("background.environment.intensity", e.intensity, 0.0, 1e6),
            }
        }
    };

    let r = &file.render;
    let integrator = match r.integrator {
        IntegratorSpec::Whitted => Integrator::Whitted,
        IntegratorSpec::Path => Integrator::Path,
    };
    let max_spp = max_samples_per_pixel(integrator);
    if !(1..=max_spp).contains(&r.samples_per_pixel) {
        cx.fail(
            "render.samples_per_pixel",
            format!(
                "must be in 1..={max_spp} for the {} integrator, got {}",
                integrator.name(),
                r.samples_per_pixel
            ),
        );
    }
    cx.count_in(
        "render.area_light_samples",
        r.area_light_samples,
        MAX_LIGHT_SAMPLES,
    );
    if r.max_bounces > MAX_BOUNCES {
        cx.fail(
            "render.max_bounces",
            format!("must be in 0..={MAX_BOUNCES}, got {}", r.max_bounces),
        );
    }
    let ambient_occlusion = r.ambient_occlusion.as_ref().map(|ao| {
        cx.count_in(
            "render.ambient_occlusion.samples",
            ao.samples,
            MAX_LIGHT_SAMPLES,
        );
        AmbientOcclusion {
            samples: ao.samples,
            distance: cx.positive("render.ambient_occlusion.distance", ao.distance),
        }
    });
    if r.max_reflection_depth > 64 {
        cx.fail(
            "render.max_reflection_depth",
            format!("must be in 0..=64, got {}", r.max_reflection_depth),
        );
    }
    let render = RenderSettings {
        samples_per_pixel: r.samples_per_pixel,
        max_reflection_depth: r.max_reflection_depth,
        reflection_cutoff: cx.in_range("render.reflection_cutoff", r.reflection_cutoff, 0.0, 1.0),
        ray_offset: cx.in_range("render.ray_offset", r.ray_offset, 0.0, 0.1),
        max_distance: cx.positive("render.max_distance", r.max_distance),
        integrator,
        area_light_samples: r.area_light_samples,
        ambient_occlusion,
        max_bounces: r.max_bounces,
        seed: r.seed,
    };

    let objects: Vec<Node> = file
        .objects
        .iter()
        .enumerate()
        .filter_map(|(i, o)| cx.object(&format!("objects[{i}]"), o, 0, 1))
        .collect();
    if let Some(deep) = deepest_beyond(&objects, MAX_MERGED_DEPTH) {
        cx.fail(
            &deep.json_path,
            format!(
                "objects nest deeper than {MAX_MERGED_DEPTH} levels once chains of one operation are merged (a node whose first child is the same operation, same blend radius, no transform, takes over its children): write long chains left-deep, or group them"
            ),
        );
        crate::deep::drop_nodes(objects);
        return Err(cx.problems);
    }

    match camera {
        Some(camera) if cx.problems.is_empty() => Ok(Scene {
            source: source.to_string(),
            camera,
            lights,
            background,
            materials: cx.materials,
            objects,
            render,
        }),
        _ => {
            if cx.problems.is_empty() {
                cx.fail("camera", "does not define a valid view");
            }
            Err(cx.problems)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_paths_are_shown_shortened_with_both_ends() {
        assert_eq!(shown_path("objects[0].shape"), "objects[0].shape");
        let long = format!("objects[0]{}.radius", ".children[0]".repeat(1000));
        let shown = shown_path(&long);
        assert!(shown.len() < 300, "{shown}");
        assert!(shown.starts_with("objects[0].children[0]"), "{shown}");
        assert!(shown.ends_with(".children[0].radius"), "{shown}");
        assert!(shown.contains(&format!("({} characters)", long.len() - 200)));
    }
}
