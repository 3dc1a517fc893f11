//! The JSON scene format as serde types.
//!
//! Every field that may be omitted has its default written in its doc comment; unknown fields
//! are rejected. Enums are externally tagged (`{"sphere": {...}}`) so a parse error keeps its
//! JSON path and line/column. The prose description of the format lives in `scenes/README.md`.
//!
//! Conventions: world space is right-handed, y is up by default, lengths are world units,
//! angles are degrees, colours are linear RGB with components in [0, 1].

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// A whole scene: camera, lights, background, objects and render settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Free text shown by `marchmesh validate`. Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// The pinhole camera. Default: see [`CameraSpec`].
    #[serde(default)]
    pub camera: CameraSpec,
    /// What rays that hit nothing see. Default: black.
    #[serde(default)]
    pub background: BackgroundSpec,
    /// Light sources. Default (field omitted): [`default_lights`]. An explicit empty list
    /// means no light at all (a black image but for the background).
    #[serde(default = "default_lights")]
    pub lights: Vec<LightSpec>,
    /// The objects. Default: none (an empty scene renders the background).
    #[serde(default)]
    pub objects: Vec<ObjectSpec>,
    /// Integrator settings. Default: see [`RenderSpec`].
    #[serde(default)]
    pub render: RenderSpec,
}

/// The lights a scene gets when it omits `lights`: ambient 0.2 and a directional light of
/// intensity 0.8 towards (1, 2, -1) (direction *towards* the light) that casts shadows.
pub fn default_lights() -> Vec<LightSpec> {
    vec![
        LightSpec::Ambient(AmbientLight { intensity: 0.2 }),
        LightSpec::Directional(DirectionalLight {
            direction: [1.0, 2.0, -1.0],
            intensity: 0.8,
            casts_shadows: true,
        }),
    ]
}

/// A pinhole camera.
///
/// Ray generation (reproducible by an independent renderer): `forward = normalize(look_at -
/// position)`, `right = normalize(cross(forward, up))`, `true_up = cross(right, forward)`.
/// Pixel (i, j), with column i from the left and row j from the *top*, samples the point
/// `(i + 0.5, j + 0.5)` (sample 0; later anti-aliasing samples are jittered within the pixel):
/// `x = (2 (i + 0.5) / width - 1) * tan(vfov/2) * width/height`,
/// `y = (1 - 2 (j + 0.5) / height) * tan(vfov/2)`,
/// `direction = normalize(forward + x right + y true_up)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Eye position in world units. Default `[0, 0, 0]`.
    #[serde(default = "zero3")]
    pub position: [f64; 3],
    /// Point looked at; must differ from `position`. Default `[0, 0, 1]`.
    #[serde(default = "unit_z")]
    pub look_at: [f64; 3],
    /// Up hint; must not be parallel to the view direction. Default `[0, 1, 0]`.
    #[serde(default = "unit_y")]
    pub up: [f64; 3],
    /// Vertical field of view in degrees, across the image height, in (0, 180). Default 60.
    #[serde(default = "default_vfov_deg")]
    pub vfov_deg: f64,
    /// Image width in pixels, 1..=16384. Default 500.
    #[serde(default = "default_image_size")]
    pub width: u32,
    /// Image height in pixels, 1..=16384. Default 500.
    #[serde(default = "default_image_size")]
    pub height: u32,
}

impl Default for CameraSpec {
    fn default() -> Self {
        Self {
            position: zero3(),
            look_at: unit_z(),
            up: unit_y(),
            vfov_deg: default_vfov_deg(),
            width: default_image_size(),
            height: default_image_size(),
        }
    }
}

/// What a ray that leaves the scene sees.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum BackgroundSpec {
    /// A constant linear RGB colour, e.g. `{"color": [1, 1, 1]}`.
    Color([f64; 3]),
    /// An equirectangular image (PNG, JPEG or Radiance HDR), path relative to the scene file.
    Environment(EnvironmentSpec),
}

impl Default for BackgroundSpec {
    fn default() -> Self {
        BackgroundSpec::Color([0.0, 0.0, 0.0])
    }
}

/// An equirectangular environment map. Direction `d` (unit, world space) maps to
/// `u = 0.5 + atan2(d.x, -d.z) / (2 pi)`, `v = acos(d.y) / pi` (v = 0 is the top row).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EnvironmentSpec {
    /// Image path, relative to the scene file.
    pub path: String,
    /// Multiplier on the image's values. Default 1.
    #[serde(default = "one")]
    pub intensity: f64,
}

/// A light source. Intensities are scalar multipliers of material colour.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum LightSpec {
    /// Light from everywhere, unshadowed: `{"ambient": {"intensity": 0.2}}`.
    Ambient(AmbientLight),
    /// A point light: `{"point": {"position": [2, 1, 0], "intensity": 0.6}}`.
    Point(PointLight),
    /// A light at infinity: `{"directional": {"direction": [1, 4, 4], "intensity": 0.2}}`.
    Directional(DirectionalLight),
    /// A spherical area light (soft shadows):
    /// `{"sphere_light": {"position": [0, 4, 0], "radius": 0.5, "intensity": 0.8}}`.
    SphereLight(SphereLight),
    /// A one-sided rectangular area light (soft shadows):
    /// `{"rectangle_light": {"corner": [-1, 4, -1], "edge_u": [0, 0, 2], "edge_v": [2, 0, 0],
    /// "intensity": 0.8}}`. It emits towards `cross(edge_u, edge_v)`.
    RectangleLight(RectangleLight),
}

/// A spherical area light.
///
/// Whitted integrator: `intensity * color` is the light's total intensity, split evenly over
/// `render.area_light_samples` points on the part of the sphere the shading point sees, each
/// shaded like a point light (no falloff) with its own shadow ray. Path tracer: `intensity *
/// color` is the radiance the sphere's surface emits. Lights are not geometry: rays pass
/// through them and they cast no shadows; camera rays and mirror paths see their emission.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SphereLight {
    /// Centre, world units.
    pub position: [f64; 3],
    /// Radius, world units, > 0.
    pub radius: f64,
    /// Intensity (Whitted) or radiance scale (path tracer), in [0, 1e6].
    pub intensity: f64,
    /// Linear RGB tint in [0, 1]. Default `[1, 1, 1]`.
    #[serde(default = "white")]
    pub color: [f64; 3],
    /// Whether shadow rays are traced towards it. Default true.
    #[serde(default = "yes")]
    pub casts_shadows: bool,
}

/// A one-sided rectangular area light: the parallelogram `corner + s edge_u + t edge_v`,
/// `s, t` in [0, 1], emitting on the side `cross(edge_u, edge_v)` points to.
///
/// `intensity` and `color` mean what they mean for [`SphereLight`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RectangleLight {
    /// One corner, world units.
    pub corner: [f64; 3],
    /// First edge from the corner, world units (non-zero).
    pub edge_u: [f64; 3],
    /// Second edge from the corner, world units (non-zero, not parallel to `edge_u`).
    pub edge_v: [f64; 3],
    /// Intensity (Whitted) or radiance scale (path tracer), in [0, 1e6].
    pub intensity: f64,
    /// Linear RGB tint in [0, 1]. Default `[1, 1, 1]`.
    #[serde(default = "white")]
    pub color: [f64; 3],
    /// Whether shadow rays are traced towards it. Default true.
    #[serde(default = "yes")]
    pub casts_shadows: bool,
}

/// Ambient light.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AmbientLight {
    /// Intensity, >= 0.
    pub intensity: f64,
}

/// A point light.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PointLight {
    /// Position in world units.
    pub position: [f64; 3],
    /// Intensity, >= 0 (no distance falloff, as in the source study).
    pub intensity: f64,
    /// Whether occlusion rays are traced towards it. Default true.
    #[serde(default = "yes")]
    pub casts_shadows: bool,
}

/// A directional light.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DirectionalLight {
    /// Direction *towards* the light (need not be unit length, must not be zero).
    pub direction: [f64; 3],
    /// Intensity, >= 0.
    pub intensity: f64,
    /// Whether occlusion rays are traced towards it. Default true.
    #[serde(default = "yes")]
    pub casts_shadows: bool,
}

/// Surface appearance (Phong).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// Diffuse colour, linear RGB in [0, 1]. Default `[0.8, 0.8, 0.8]`.
    #[serde(default = "default_color")]
    pub color: [f64; 3],
    /// Phong specular exponent (> 0); omitted means no specular highlight. Default none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub specular_exponent: Option<f64>,
    /// Fraction of light reflected as a mirror, in [0, 1]. Default 0 (no reflection rays).
    #[serde(default)]
    pub reflectivity: f64,
}

impl Default for MaterialSpec {
    fn default() -> Self {
        Self {
            color: default_color(),
            specular_exponent: None,
            reflectivity: 0.0,
        }
    }
}

/// Object-to-parent transform: `translate * rotate * scale`, where the rotation applies
/// `rotate_deg[0]` about x first, then `[1]` about y, then `[2]` about z (matrix `Rz Ry Rx`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TransformSpec {
    /// Translation in world units. Default `[0, 0, 0]`.
    #[serde(default = "zero3")]
    pub translate: [f64; 3],
    /// Rotation angles in degrees about x, y, z. Default `[0, 0, 0]`.
    #[serde(default = "zero3")]
    pub rotate_deg: [f64; 3],
    /// Scale: one number (uniform) or three (per axis, all > 0). Default 1.
    #[serde(default)]
    pub scale: ScaleSpec,
}

impl Default for TransformSpec {
    fn default() -> Self {
        Self {
            translate: zero3(),
            rotate_deg: zero3(),
            scale: ScaleSpec::default(),
        }
    }
}

/// A uniform (`2.0`) or per-axis (`[1, 2, 1]`) scale.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum ScaleSpec {
    /// The same factor on every axis.
    Uniform(f64),
    /// One factor per axis.
    PerAxis([f64; 3]),
}

impl Default for ScaleSpec {
    fn default() -> Self {
        ScaleSpec::Uniform(1.0)
    }
}

/// One object: a shape (primitive, mesh, CSG or repetition), its transform and material.
///
/// A material given on a CSG or repeat node is inherited by every descendant that gives none;
/// an object with no material anywhere up its tree gets the default [`MaterialSpec`].
#[derive(Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    /// A label for messages and reports. Default none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// What the object is.
    pub shape: ShapeSpec,
    /// Object-to-parent transform. Default identity.
    #[serde(default)]
    pub transform: TransformSpec,
    /// Appearance; default inherited from the parent, else [`MaterialSpec::default`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<MaterialSpec>,
}

// Object trees nest as deep as the files do: the recursive impls go through `deep::guard`
// once per level and dropping is iterative.
impl Drop for ObjectSpec {
    fn drop(&mut self) {
        let children = self.take_children();
        if !children.is_empty() {
            crate::deep::drop_tree(children, ObjectSpec::take_children);
        }
    }
}

impl ObjectSpec {
    /// Moves the direct children out (a repetition's child replaced by a unit sphere).
    fn take_children(&mut self) -> Vec<ObjectSpec> {
        match &mut self.shape {
            ShapeSpec::Union(c) | ShapeSpec::Intersection(c) | ShapeSpec::Subtraction(c) => {
                std::mem::take(&mut c.children)
            }
            ShapeSpec::SmoothUnion(s)
            | ShapeSpec::SmoothIntersection(s)
            | ShapeSpec::SmoothSubtraction(s)
            | ShapeSpec::Blend(s) => std::mem::take(&mut s.children),
            ShapeSpec::Repeat(r) => {
                let leaf = ObjectSpec {
                    name: None,
                    shape: ShapeSpec::Sphere(SphereSpec { radius: 1.0 }),
                    transform: TransformSpec::default(),
                    material: None,
                };
                vec![std::mem::replace(&mut *r.child, leaf)]
            }
            // Leaves: nothing below.
            _ => Vec::new(),
        }
    }
}

impl Clone for ObjectSpec {
    fn clone(&self) -> Self {
        crate::deep::guard(|| ObjectSpec {
            name: self.name.clone(),
            shape: self.shape.clone(),
            transform: self.transform.clone(),
            material: self.material.clone(),
        })
    }
}

impl PartialEq for ObjectSpec {
    fn eq(&self, o: &Self) -> bool {
        crate::deep::guard(|| {
            self.name == o.name
                && self.shape == o.shape
                && self.transform == o.transform
                && self.material == o.material
        })
    }
}

impl std::fmt::Debug for ObjectSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        crate::deep::guard(|| {
            f.debug_struct("ObjectSpec")
                .field("name", &self.name)
                .field("shape", &self.shape)
                .field("transform", &self.transform)
                .field("material", &self.material)
                .finish()
        })
    }
}

/// The shape of an object, in its local frame (before its transform).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeSpec {
    /// A sphere centred on the origin.
    Sphere(SphereSpec),
    /// An infinite plane `dot(normalize(normal), p) = offset`: `offset` is along the *unit*
    /// normal, whatever the length of `normal`; the solid side is opposite the normal.
    Plane(PlaneSpec),
    /// A single two-sided triangle (no volume).
    Triangle(TriangleSpec),
    /// An axis-aligned box centred on the origin.
    Box(BoxSpec),
    /// An axis-aligned ellipsoid centred on the origin.
    Ellipsoid(EllipsoidSpec),
    /// A capped cylinder along y, centred on the origin.
    Cylinder(CylinderSpec),
    /// A torus in the xz-plane around the y axis.
    Torus(TorusSpec),
    /// An axis-aligned box centred on the origin with rounded edges and corners.
    RoundedBox(RoundedBoxSpec),
    /// The points within `radius` of a segment along y centred on the origin.
    Capsule(CapsuleSpec),
    /// A cone along y cut by two caps (a frustum), centred on the origin.
    CappedCone(CappedConeSpec),
    /// A triangle mesh loaded from an OBJ or glTF (.gltf/.glb) file.
    Mesh(MeshSpec),
    /// Points inside any child.
    Union(CsgSpec),
    /// Points inside every child.
    Intersection(CsgSpec),
    /// Points inside the first child and inside none of the others.
    Subtraction(CsgSpec),
    /// A union whose seams are rounded with a polynomial smooth minimum.
    SmoothUnion(SmoothUnionSpec),
    /// An intersection whose seams are rounded with a polynomial smooth maximum.
    SmoothIntersection(SmoothUnionSpec),
    /// The first child minus the others, the cuts rounded with a polynomial smooth maximum.
    SmoothSubtraction(SmoothUnionSpec),
    /// A union of all children blended at once, whatever their order: the value `f` with
    /// `sum_i max(0, 1 - (c_i - f) / k)^2 = 1`. Unlike `smooth_union` it is not a fold (a
    /// nested `blend` is not flattened), and the sdf backend evaluates it from the children
    /// near each point only.
    Blend(SmoothUnionSpec),
    /// Domain repetition of one child on a grid.
    Repeat(RepeatSpec),
}

/// Sphere parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SphereSpec {
    /// Radius in world units, > 0. Default 1.
    #[serde(default = "one")]
    pub radius: f64,
}

/// Plane parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PlaneSpec {
    /// Outward normal (need not be unit, must not be zero). Default `[0, 1, 0]`.
    #[serde(default = "unit_y")]
    pub normal: [f64; 3],
    /// Signed distance of the plane from the origin along the unit normal. Default 0.
    #[serde(default)]
    pub offset: f64,
}

/// Triangle parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TriangleSpec {
    /// The three corners; must not be collinear.
    pub vertices: [[f64; 3]; 3],
}

/// Box parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    /// Half the edge length along each axis, all > 0. Default `[0.5, 0.5, 0.5]`.
    #[serde(default = "half3")]
    pub half_extents: [f64; 3],
}

/// Ellipsoid parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EllipsoidSpec {
    /// Semi-axis lengths along x, y, z, all > 0. Default `[1, 0.5, 0.5]`.
    #[serde(default = "default_radii")]
    pub radii: [f64; 3],
}

/// Capped cylinder parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CylinderSpec {
    /// Radius, > 0. Default 0.5.
    #[serde(default = "half")]
    pub radius: f64,
    /// Total height along y, > 0 (caps at y = +-height/2). Default 1.
    #[serde(default = "one")]
    pub height: f64,
}

/// Torus parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TorusSpec {
    /// Distance from the centre to the tube's centre line, > 0. Default 1.
    #[serde(default = "one")]
    pub major_radius: f64,
    /// Tube radius, > 0 and <= major_radius. Default 0.25.
    #[serde(default = "quarter")]
    pub minor_radius: f64,
}

/// Rounded box parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RoundedBoxSpec {
    /// Half the edge length along each axis, rounding included, all > 0. Default
    /// `[0.5, 0.5, 0.5]`.
    #[serde(default = "half3")]
    pub half_extents: [f64; 3],
    /// Radius of the rounded edges and corners, >= 0 and <= the smallest half extent (0: a
    /// plain box; the smallest half extent: round along that axis). Default 0.1.
    #[serde(default = "tenth")]
    pub rounding_radius: f64,
}

/// Capsule parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CapsuleSpec {
    /// Radius, > 0. Default 0.5.
    #[serde(default = "half")]
    pub radius: f64,
    /// Length of the segment along y (from y = -height/2 to height/2) whose points within
    /// `radius` make the capsule, >= 0 (0: a sphere); the capsule's total height is
    /// `height + 2 radius`. Default 1.
    #[serde(default = "one")]
    pub height: f64,
}

/// Capped cone parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CappedConeSpec {
    /// Total height along y, > 0 (caps at y = +-height/2). Default 1.
    #[serde(default = "one")]
    pub height: f64,
    /// Radius of the cap at y = -height/2, >= 0. Default 0.5.
    #[serde(default = "half")]
    pub bottom_radius: f64,
    /// Radius of the cap at y = +height/2, >= 0 (not both radii 0). Default 0.25.
    #[serde(default = "quarter")]
    pub top_radius: f64,
}

/// A mesh file reference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MeshSpec {
    /// Path of an `.obj`, `.gltf` or `.glb` file, relative to the scene file.
    pub path: String,
}

/// Children of a boolean operation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CsgSpec {
    /// At least one child (subtraction: the first is the base).
    pub children: Vec<ObjectSpec>,
}

/// Children and blend radius of a smooth union, intersection or subtraction.
///
/// The children's values are folded left to right, `v = op(op(op(c0, c1), c2), ...)`, so a
/// node with n children is exactly the left-deep binary tree of the same operator and blend
/// radius. Union: the polynomial smooth minimum `smin(a, b) = min(a, b) - h^2 k / 4` with
/// `h = max(k - |a - b|, 0) / k` (Quilez); intersection: `smax(a, b) = -smin(-a, -b)`;
/// subtraction: `smax(a, -b)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SmoothUnionSpec {
    /// At least one child (subtraction: the first is the base).
    pub children: Vec<ObjectSpec>,
    /// Blend radius k, > 0, in the node's local units (before its transform): a `scale` on
    /// this node or an ancestor scales the blend with the shape, as every backend renders it.
    pub blend_radius: f64,
}

/// Domain repetition: copies of `child` at `index * period` on each repeated axis.
///
/// The result is the union of whole copies: a child larger than its cell is not clipped at
/// the cell border, neighbouring copies overlap (every backend renders this; it is not the
/// naive `p - period * round(p / period)` fold, which would clip).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RepeatSpec {
    /// The repeated object.
    pub child: Box<ObjectSpec>,
    /// Cell size per axis in world units; 0 means that axis is not repeated. At least one > 0.
    pub period: [f64; 3],
    /// Copies per axis (centred on the origin); `null` or omitted means infinitely many.
    /// Default `[null, null, null]`.
    #[serde(default)]
    pub count: [Option<u32>; 3],
}

/// Integrator settings shared by every backend.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RenderSpec {
    /// Samples per pixel, 1..=1024; sample 0 is the pixel centre, others follow the Halton
    /// (2, 3) sequence. Default 1.
    #[serde(default = "one_u32")]
    pub samples_per_pixel: u32,
    /// Maximum number of mirror bounces after the primary hit, 0..=64. Default 3.
    #[serde(default = "default_depth")]
    pub max_reflection_depth: u32,
    /// A reflection ray is traced only while the path's accumulated reflectivity stays above
    /// this, in [0, 1]. Default 0.01.
    #[serde(default = "default_cutoff")]
    pub reflection_cutoff: f64,
    /// Secondary rays start `ray_offset * max(distance from camera, 1e-30)` along the surface
    /// normal, to avoid self-intersection ("acne"). Relative, so it works at every scale.
    /// Default 1e-4.
    #[serde(default = "default_ray_offset")]
    pub ray_offset: f64,
    /// Rays end after this distance in world units: every backend treats anything farther as
    /// a miss, and infinite planes and repetitions are bounded by it. Default 1000.
    #[serde(default = "default_max_distance")]
    pub max_distance: f64,
    /// Which light transport runs. Default `"whitted"`.
    #[serde(default)]
    pub integrator: IntegratorSpec,
    /// Shadow rays per shading point towards each area light, 1..=4096 (stratified over the
    /// light). Default 16.
    #[serde(default = "default_area_light_samples")]
    pub area_light_samples: u32,
    /// Ambient occlusion of the ambient term (Whitted integrator). Default none (the ambient
    /// light reaches every point unoccluded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambient_occlusion: Option<AmbientOcclusionSpec>,
    /// Path tracer: most bounces after the camera ray, 0..=64 (0 = direct light only).
    /// Default 8.
    #[serde(default = "default_max_bounces")]
    pub max_bounces: u32,
    /// Seed of every random choice (area-light and AO sample rotations, path tracing); the same
    /// seed gives the same image at any thread count. Default 0.
    #[serde(default)]
    pub seed: u64,
}

impl Default for RenderSpec {
    fn default() -> Self {
        Self {
            samples_per_pixel: one_u32(),
            max_reflection_depth: default_depth(),
            reflection_cutoff: default_cutoff(),
            ray_offset: default_ray_offset(),
            max_distance: default_max_distance(),
            integrator: IntegratorSpec::default(),
            area_light_samples: default_area_light_samples(),
            ambient_occlusion: None,
            max_bounces: default_max_bounces(),
            seed: 0,
        }
    }
}

/// The light transport of a render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum IntegratorSpec {
    /// Phong shading with shadows (hard for point and directional lights, sampled for area
    /// lights), optional ambient occlusion and mirror reflections: the source study's model.
    #[default]
    Whitted,
    /// Unbiased path tracing: Lambertian diffuse from `color`, mirror reflection with
    /// probability `reflectivity`, next-event estimation towards every light, Russian roulette
    /// after three bounces, the background as an environment light. Ambient lights and
    /// specular exponents are ignored.
    Path,
}

/// Ambient occlusion: the ambient term at a point is scaled by the fraction of `samples`
/// cosine-distributed hemisphere rays that meet nothing within `distance`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AmbientOcclusionSpec {
    /// Rays per shading point, 1..=4096. Default 16.
    #[serde(default = "default_area_light_samples")]
    pub samples: u32,
    /// Longest occlusion ray, world units, > 0. Default 1.
    #[serde(default = "one")]
    pub distance: f64,
}

fn zero3() -> [f64; 3] {
    [0.0; 3]
}
fn unit_y() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}
fn unit_z() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}
fn half3() -> [f64; 3] {
    [0.5; 3]
}
fn default_radii() -> [f64; 3] {
    [1.0, 0.5, 0.5]
}
fn default_color() -> [f64; 3] {
    [0.8; 3]
}
fn default_vfov_deg() -> f64 {
    60.0
}
fn default_image_size() -> u32 {
    500
}
fn one() -> f64 {
    1.0
}
fn half() -> f64 {
    0.5
}
fn tenth() -> f64 {
    0.1
}

fn quarter() -> f64 {
    0.25
}
fn one_u32() -> u32 {
    1
}
fn yes() -> bool {
    true
}
fn white() -> [f64; 3] {
    [1.0; 3]
}
fn default_area_light_samples() -> u32 {
    16
}
fn default_max_bounces() -> u32 {
    8
}
fn default_depth() -> u32 {
    3
}
fn default_cutoff() -> f64 {
    0.01
}
fn default_ray_offset() -> f64 {
    1e-4
}
fn default_max_distance() -> f64 {
    1000.0
}
