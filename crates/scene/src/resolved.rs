//! The resolved scene: validated, in f64 glam types, with materials inherited down the tree
//! and numbered, and mesh paths made absolute. Every backend builds from this, never from the
//! serde types, so they all agree on material ids, transforms and defaults.

use std::path::PathBuf;

use glam::{DAffine3, DMat3, DQuat, DVec3};

/// Index into [`Scene::materials`].
pub type MaterialId = u32;

/// Validated surface appearance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Diffuse colour, linear RGB in [0, 1].
    pub color: DVec3,
    /// Phong exponent; `None` for no specular term.
    pub specular_exponent: Option<f64>,
    /// Mirror reflectivity in [0, 1].
    pub reflectivity: f64,
}

/// Validated pinhole camera; see [`crate::CameraSpec`] for the ray-generation formulas.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Eye position, world units.
    pub position: DVec3,
    /// Unit view direction.
    pub forward: DVec3,
    /// Unit right vector, `normalize(cross(forward, up))`.
    pub right: DVec3,
    /// Unit up vector orthogonal to both, `cross(right, forward)`.
    pub up: DVec3,
    /// Vertical field of view in radians.
    pub vfov_rad: f64,
    /// Image width in pixels (>= 1).
    pub width: u32,
    /// Image height in pixels (>= 1).
    pub height: u32,
}

impl Camera {
    /// Builds a camera; `None` if `look_at == position`, `up` is parallel to the view
    /// direction, or any value is not finite.
    pub fn look_at(
        position: DVec3,
        look_at: DVec3,
        up: DVec3,
        vfov_deg: f64,
        width: u32,
        height: u32,
    ) -> Option<Self> {
        let forward = (look_at - position).try_normalize()?;
        let right = forward.cross(up).try_normalize()?;
        if !(position.is_finite() && vfov_deg > 0.0 && vfov_deg < 180.0) {
            return None;
        }
        Some(Self {
            position,
            forward,
            right,
            up: right.cross(forward),
            vfov_rad: vfov_deg.to_radians(),
            width,
            height,
        })
    }

    /// Unit direction (world space) through image-plane point `(px, py)` in pixel units,
    /// `(0, 0)` being the top-left corner of the image. Loops over many rays should take
    /// [`Camera::image_plane`] once and call its `direction` (same bits, no tangent per ray).
    pub fn direction(&self, px: f64, py: f64) -> DVec3 {
        self.image_plane().direction(px, py)
    }

    /// The image plane with the field-of-view tangents computed once.
    pub fn image_plane(&self) -> ImagePlane {
        let half_h = (self.vfov_rad * 0.5).tan();
        ImagePlane {
            forward: self.forward,
            right: self.right,
            up: self.up,
            width: self.width as f64,
            height: self.height as f64,
            half_w: half_h * self.width as f64 / self.height as f64,
            half_h,
        }
    }

    /// Angle in radians subtended by one pixel at the image centre (vertical). Tolerances
    /// proportional to `pixel_angle * distance` are one pixel's footprint on screen.
    pub fn pixel_angle(&self) -> f64 {
        2.0 * (self.vfov_rad * 0.5).tan() / self.height as f64
    }
}

/// A camera's image plane, ready to turn pixel coordinates into ray directions: the
/// pinhole formulas of [`crate::CameraSpec`] with `tan(vfov / 2)` evaluated once.
/// [`ImagePlane::direction`] gives exactly the bits of [`Camera::direction`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImagePlane {
    forward: DVec3,
    right: DVec3,
    up: DVec3,
    width: f64,
    height: f64,
    half_w: f64,
    half_h: f64,
}

impl ImagePlane {
    /// Unit direction (world space) through image-plane point `(px, py)` in pixel units,
    /// `(0, 0)` being the top-left corner of the image.
    pub fn direction(&self, px: f64, py: f64) -> DVec3 {
        (self.column(px) + self.row_offset(py)).normalize()
    }

    /// The unnormalised direction's part that depends on the column only:
    /// `forward + x right` at image-plane x-coordinate `px` (pixel units). Adding
    /// [`ImagePlane::row_offset`] and normalising gives [`ImagePlane::direction`] bit for bit,
    /// so callers tracing many rows can compute columns once.
    pub fn column(&self, px: f64) -> DVec3 {
        let x = (2.0 * px / self.width - 1.0) * self.half_w;
        self.forward + x * self.right
    }

    /// The part that depends on the row only: `y up` at image-plane y-coordinate `py`
    /// (pixel units, 0 at the top edge).
    pub fn row_offset(&self, py: f64) -> DVec3 {
        let y = (1.0 - 2.0 * py / self.height) * self.half_h;
        y * self.up
    }
}

/// A light with validated, world-space parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Light {
    /// Unshadowed light from everywhere.
    Ambient {
        /// Intensity >= 0.
        intensity: f64,
    },
    /// A point light (no falloff).
    Point {
        /// Position, world units.
        position: DVec3,
        /// Intensity >= 0.
        intensity: f64,
        /// Whether occlusion rays are traced.
        casts_shadows: bool,
    },
    /// A light at infinity.
    Directional {
        /// Unit direction *towards* the light.
        direction: DVec3,
        /// Intensity >= 0.
        intensity: f64,
        /// Whether occlusion rays are traced.
        casts_shadows: bool,
    },
    /// A spherical area light (see `format::SphereLight` for what intensity means).
    Sphere {
        /// Centre, world units.
        center: DVec3,
        /// Radius > 0, world units.
        radius: f64,
        /// `intensity * color`: per-channel intensity (Whitted) or radiance (path tracer).
        emission: DVec3,
        /// Whether occlusion rays are traced.
        casts_shadows: bool,
    },
    /// A one-sided rectangular area light `corner + s edge_u + t edge_v`, emitting towards
    /// `cross(edge_u, edge_v)`.
    Rectangle {
        /// Corner, world units.
        corner: DVec3,
        /// First edge, world units.
        edge_u: DVec3,
        /// Second edge, world units (not parallel to `edge_u`).
        edge_v: DVec3,
        /// `intensity * color`: per-channel intensity (Whitted) or radiance (path tracer).
        emission: DVec3,
        /// Whether occlusion rays are traced.
        casts_shadows: bool,
    },
}

/// What rays that hit nothing see.
#[derive(Debug, Clone, PartialEq)]
pub enum Background {
    /// A constant linear RGB colour.
    Color(DVec3),
    /// An equirectangular image at an absolute path, scaled by `intensity`.
    Environment {
        /// Absolute (or scene-relative resolved) image path.
        path: PathBuf,
        /// Multiplier >= 0.
        intensity: f64,
    },
}

/// Validated integrator settings (see [`crate::RenderSpec`] for meanings).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    /// Samples per pixel >= 1.
    pub samples_per_pixel: u32,
    /// Maximum mirror bounces.
    pub max_reflection_depth: u32,
    /// Minimum path reflectivity for a reflection ray.
    pub reflection_cutoff: f64,
    /// Relative secondary-ray offset.
    pub ray_offset: f64,
    /// Maximum ray distance, world units.
    pub max_distance: f64,
    /// The light transport.
    pub integrator: Integrator,
    /// Shadow rays per shading point towards each area light (>= 1).
    pub area_light_samples: u32,
    /// Ambient occlusion of the ambient term, if enabled.
    pub ambient_occlusion: Option<AmbientOcclusion>,
    /// Path tracer: most bounces after the camera ray.
    pub max_bounces: u32,
    /// Seed of every random choice.
    pub seed: u64,
}

/// The light transport of a render (see `format::IntegratorSpec`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Integrator {
    /// Phong shading, shadows, ambient occlusion, mirror reflections.
    #[default]
    Whitted,
    /// Unbiased path tracing with next-event estimation.
    Path,
}

/// Validated ambient-occlusion settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmbientOcclusion {
    /// Rays per shading point (>= 1).
    pub samples: u32,
    /// Longest occlusion ray, world units (> 0).
    pub distance: f64,
}

/// One node of the object tree, in its parent's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// Object-to-parent transform (`translate * rotate * scale`).
    pub transform: DAffine3,
    /// The material of this node (inherited if the file gave none).
    pub material: MaterialId,
    /// The object's name, if given.
    pub name: Option<String>,
    /// JSON path of the object in its file (e.g. `objects[2].shape.union.children[0]`), for
    /// error messages.
    pub json_path: String,
    /// What it is.
    pub kind: NodeKind,
}

/// A node's shape, in the node's local frame: a leaf or a combinator of child nodes.
#[derive(Debug, Clone, PartialEq)]
pub enum NodeKind {
    /// A primitive (analytic shape, triangle or mesh file).
    Leaf(Shape),
    /// Union of >= 1 children.
    Union(Vec<Node>),
    /// Intersection of >= 1 children.
    Intersection(Vec<Node>),
    /// First child minus the others.
    Subtraction(Vec<Node>),
    /// A smooth union, intersection or subtraction of >= 1 children: the children's values
    /// folded left to right by the polynomial smooth minimum (or maximum) of `blend_radius`,
    /// so a flat node gives the same value as a left-deep binary tree of the same operator;
    /// or a blend ([`SmoothOp::Blend`]) of all children at once.
    Smooth {
        /// Which boolean operation is blended.
        op: SmoothOp,
        /// Children.
        children: Vec<Node>,
        /// Blend radius > 0, local units.
        blend_radius: f64,
    },
    /// Domain repetition.
    Repeat {
        /// The repeated node.
        child: Box<Node>,
        /// Period per axis; 0 = not repeated on that axis.
        period: DVec3,
        /// Copies per axis on repeated axes; `None` = infinite.
        count: [Option<u32>; 3],
    },
}

/// The boolean operation a [`NodeKind::Smooth`] node blends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SmoothOp {
    /// `smin` fold: a union with rounded seams.
    Union,
    /// `smax` fold: an intersection with rounded seams.
    Intersection,
    /// `smax(first, -child)` fold: the first child minus the others, cuts rounded.
    Subtraction,
    /// Not a fold: the union of all children blended at once, the same value in any child
    /// order: `f` with `sum_i max(0, 1 - (c_i - f) / k)^2 = 1` (see
    /// [`crate::bounds::blend_deficit`]).
    Blend,
}

/// A primitive in its local frame, with validated parameters.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// Sphere at the origin.
    Sphere {
        /// Radius > 0.
        radius: f64,
    },
    /// Plane `dot(normal, p) = offset` with the normal made unit length, solid below.
    Plane {
        /// Unit normal.
        normal: DVec3,
        /// Offset along the normal.
        offset: f64,
    },
    /// Two-sided triangle with non-collinear vertices.
    Triangle {
        /// Corners.
        vertices: [DVec3; 3],
    },
    /// Box at the origin.
    Box {
        /// Half extents, all > 0.
        half_extents: DVec3,
    },
    /// Ellipsoid at the origin.
    Ellipsoid {
        /// Semi-axes, all > 0.
        radii: DVec3,
    },
    /// Capped cylinder along y.
    Cylinder {
        /// Radius > 0.
        radius: f64,
        /// Half the height > 0.
        half_height: f64,
    },
    /// Torus around y.
    Torus {
        /// Major radius > 0.
        major_radius: f64,
        /// Minor radius in (0, major_radius].
        minor_radius: f64,
    },
    /// Box at the origin with rounded edges and corners: the box of half extents
    /// `half_extents - rounding_radius` grown by `rounding_radius`.
    RoundedBox {
        /// Outer half extents, all > 0.
        half_extents: DVec3,
        /// Rounding radius in [0, min(half_extents)].
        rounding_radius: f64,
    },
    /// The points within `radius` of the segment `|y| <= half_height` on the y axis.
    Capsule {
        /// Radius > 0.
        radius: f64,
        /// Half the segment's length >= 0.
        half_height: f64,
    },
    /// Cone along y cut at `y = -half_height` (radius `bottom_radius`) and `y = half_height`
    /// (radius `top_radius`).
    CappedCone {
        /// Half the height > 0.
        half_height: f64,
        /// Radius at the bottom cap >= 0.
        bottom_radius: f64,
        /// Radius at the top cap >= 0 (not both radii 0).
        top_radius: f64,
    },
    /// Mesh file (existence is checked by the loader, not here).
    Mesh {
        /// Path resolved against the scene file's folder.
        path: PathBuf,
    },
}

impl NodeKind {
    /// Moves the direct children out (a repetition's child replaced by a unit sphere), for
    /// dismantling deep trees without recursion.
    pub(crate) fn take_children(&mut self) -> Vec<Node> {
        match self {
            NodeKind::Union(c) | NodeKind::Intersection(c) | NodeKind::Subtraction(c) => {
                std::mem::take(c)
            }
            NodeKind::Smooth { children, .. } => std::mem::take(children),
            NodeKind::Repeat { child, .. } => {
                let leaf = Node {
                    transform: DAffine3::IDENTITY,
                    material: 0,
                    name: None,
                    json_path: String::new(),
                    kind: NodeKind::Leaf(Shape::Sphere { radius: 1.0 }),
                };
                vec![std::mem::replace(&mut **child, leaf)]
            }
            NodeKind::Leaf(_) => Vec::new(),
        }
    }
}

impl Shape {
    /// Whether the shape is a bounded solid given by its parameters alone: everything but a
    /// plane (unbounded), a triangle (no inside) and a mesh file.
    pub fn is_analytic_solid(&self) -> bool {
        !matches!(self, Shape::Triangle { .. })
            && matches!(self.local_bounds(), crate::bounds::LocalBounds::Finite(_))
    }
}

impl Node {
    /// True for CSG, smooth CSG and repetition nodes (everything but leaves).
    pub fn is_composite(&self) -> bool {
        !matches!(self.kind, NodeKind::Leaf(_))
    }

    /// Direct children (empty for leaves).
    pub fn children(&self) -> &[Node] {
        match &self.kind {
            NodeKind::Union(c) | NodeKind::Intersection(c) | NodeKind::Subtraction(c) => c,
            NodeKind::Smooth { children, .. } => children,
            NodeKind::Repeat { child, .. } => std::slice::from_ref(child),
            NodeKind::Leaf(_) => &[],
        }
    }

    /// Calls `f` on this node and every descendant, parents first.
    pub fn visit(&self, f: &mut impl FnMut(&Node)) {
        f(self);
        for c in self.children() {
            c.visit(f);
        }
    }
}

/// A validated scene ready for backends.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Where the scene came from (file path or `<string>`), for messages.
    pub source: String,
    /// Camera.
    pub camera: Camera,
    /// Lights.
    pub lights: Vec<Light>,
    /// Background.
    pub background: Background,
    /// Material table; id 0 is the default material.
    pub materials: Vec<Material>,
    /// Top-level objects (an implicit union).
    pub objects: Vec<Node>,
    /// Integrator settings.
    pub render: RenderSettings,
}

impl Scene {
    /// Calls `f` on every node of every object, parents first.
    pub fn visit_nodes(&self, mut f: impl FnMut(&Node)) {
        for o in &self.objects {
            o.visit(&mut f);
        }
    }

    /// Every distinct mesh path the scene refers to, in first-use order.
    pub fn mesh_paths(&self) -> Vec<PathBuf> {
        let mut out: Vec<PathBuf> = Vec::new();
        self.visit_nodes(|n| {
            if let NodeKind::Leaf(Shape::Mesh { path }) = &n.kind
                && !out.contains(path)
            {
                out.push(path.clone());
            }
        });
        out
    }

    /// Replaces the image size (a CLI override); errors as in validation.
    pub fn with_image_size(mut self, width: u32, height: u32) -> Result<Self, String> {
        crate::validate::check_image_size(width, height)?;
        self.camera.width = width;
        self.camera.height = height;
        Ok(self)
    }

    /// Replaces the samples per pixel (a CLI override); errors as in validation (the cap
    /// depends on the integrator).
    pub fn with_samples_per_pixel(mut self, samples: u32) -> Result<Self, String> {
        let max = crate::validate::max_samples_per_pixel(self.render.integrator);
        if !(1..=max).contains(&samples) {
            return Err(format!(
                "samples per pixel must be in 1..={max} for the {} integrator, got {samples}",
                self.render.integrator.name()
            ));
        }
        self.render.samples_per_pixel = samples;
        Ok(self)
    }
}

/// Render settings that replace a loaded scene's own (a benchmark's quality level or its
/// ground truth); each value is checked as in a scene file. Empty by default.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderOverrides {
    /// Samples per pixel (cap depends on the integrator).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples_per_pixel: Option<u32>,
    /// Shadow rays per shading point and area light.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub area_light_samples: Option<u32>,
    /// Ambient-occlusion rays per shading point (the scene must enable ambient occlusion).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambient_occlusion_samples: Option<u32>,
    /// Path-tracer bounces.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_bounces: Option<u32>,
    /// Seed of every random choice.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
}

impl RenderOverrides {
    /// Whether nothing is overridden.
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }
}

impl Scene {
    /// The scene with `overrides` applied; errors name the setting and its valid range, as
    /// validation does.
    pub fn with_render_overrides(mut self, overrides: &RenderOverrides) -> Result<Self, String> {
        use crate::validate::{MAX_BOUNCES, MAX_LIGHT_SAMPLES};
        let in_range = |name: &str, v: u32, lo: u32, hi: u32| {
            if (lo..=hi).contains(&v) {
                Ok(v)
            } else {
                Err(format!("{name} must be in {lo}..={hi}, got {v}"))
            }
        };
        if let Some(spp) = overrides.samples_per_pixel {
            self = self.with_samples_per_pixel(spp)?;
        }
        if let Some(n) = overrides.area_light_samples {
            self.render.area_light_samples =
                in_range("area_light_samples", n, 1, MAX_LIGHT_SAMPLES)?;
        }
        if let Some(n) = overrides.ambient_occlusion_samples {
            let ao = self.render.ambient_occlusion.as_mut().ok_or_else(|| {
                "ambient_occlusion_samples: the scene has no render.ambient_occlusion".to_string()
            })?;
            ao.samples = in_range("ambient_occlusion_samples", n, 1, MAX_LIGHT_SAMPLES)?;
        }
        if let Some(n) = overrides.max_bounces {
            self.render.max_bounces = in_range("max_bounces", n, 0, MAX_BOUNCES)?;
        }
        if let Some(seed) = overrides.seed {
            self.render.seed = seed;
        }
        Ok(self)
    }
}

impl Integrator {
    /// The name used in scene files.
    pub const fn name(self) -> &'static str {
        match self {
            Integrator::Whitted => "whitted",
            Integrator::Path => "path",
        }
    }
}

/// `translate * Rz Ry Rx * scale` with angles in degrees.
pub fn compose_transform(translate: DVec3, rotate_deg: DVec3, scale: DVec3) -> DAffine3 {
    let r = DQuat::from_rotation_z(rotate_deg.z.to_radians())
        * DQuat::from_rotation_y(rotate_deg.y.to_radians())
        * DQuat::from_rotation_x(rotate_deg.x.to_radians());
    DAffine3 {
        matrix3: DMat3::from_quat(r) * DMat3::from_diagonal(scale),
        translation: translate,
    }
}
