//! Phong shading of a surface point: the lights it sees (point lights, and area lights as
//! stratified point samples with their own shadow rays) and the colour they give.

use glam::Vec3;
use marchmesh_scene::{Light, Material, Scene};

use crate::emitter::Emitter;
use crate::geometry::{Ray, RenderSpace};
use crate::sampling::{mix64, unit_from_key};

/// Scene data the shading loops read, converted once to f32 render space.
pub(crate) struct Shading {
    pub(crate) ambient: f32,
    pub(crate) lights: Vec<ShadingLight>,
    pub(crate) materials: Vec<Material>,
    pub(crate) max_depth: u32,
    pub(crate) cutoff: f32,
    pub(crate) ray_offset: f32,
    pub(crate) max_distance: f32,
    pub(crate) spp: u32,
    /// Shadow rays per area light per shading point.
    pub(crate) area_samples: u32,
    /// Ambient occlusion: (rays, distance).
    pub(crate) ambient_occlusion: Option<(u32, f32)>,
    /// Every area light, also listed in `lights`, for intersecting camera and mirror rays.
    pub(crate) emitters: Vec<Emitter>,
    pub(crate) seed: u64,
    /// Path tracer: most bounces after the camera ray.
    pub(crate) max_bounces: u32,
    /// Whether a shading point may start a shadow or ambient-occlusion ray (or cone): a
    /// light that casts shadows, an area light, or ambient occlusion. Without one (and
    /// without a reflection) the Whitted integrator skips the secondary rays' origin.
    pub(crate) spawns: bool,
    /// Whether shading reads the pixel sample's random key (area lights, ambient
    /// occlusion); the Whitted integrator skips the hashing otherwise.
    pub(crate) keyed: bool,
    /// `materials` converted once to the f32 values shading reads (same index).
    pub(crate) surfaces: Vec<Surface>,
    /// The point and directional lights that can light anything (positive intensity, a
    /// finite direction), in the order of `lights`: all a shading point of a scene without
    /// area lights or ambient occlusion (`direct_pass`) reads.
    pub(crate) direct: Vec<DirectLight>,
    /// Whether every light is a point, directional or ambient light and there is no ambient
    /// occlusion: a shading point then reads only `ambient` and `direct`, and spawns at most
    /// one shadow ray per light of `direct` that casts shadows.
    pub(crate) direct_pass: bool,
}

/// A material as shading reads it: the f32 conversions of [`Material`]'s fields (the same
/// bits the shading loops got converting them per hit).
#[derive(Clone, Copy)]
pub(crate) struct Surface {
    pub(crate) color: Vec3,
    pub(crate) reflectivity: f32,
    pub(crate) specular_exponent: Option<f32>,
}

impl Surface {
    fn of(m: &Material) -> Self {
        Self {
            color: m.color.as_vec3(),
            reflectivity: m.reflectivity as f32,
            specular_exponent: m.specular_exponent.map(|s| s as f32),
        }
    }
}

/// A point or directional light as the direct-lighting pass of a scene without area lights
/// or ambient occlusion reads it; `shadows`: it casts shadows.
#[derive(Clone, Copy)]
pub(crate) enum DirectLight {
    Point {
        position: Vec3,
        intensity: f32,
        shadows: bool,
    },
    Directional {
        to_light: Vec3,
        intensity: f32,
        shadows: bool,
    },
}

impl DirectLight {
    /// Whether the Whitted loop shades anything from this light (a positive intensity and,
    /// for a directional light, a finite direction; a point light's direction depends on
    /// the point).
    fn lights_some_point(&self) -> bool {
        match *self {
            DirectLight::Point { intensity, .. } => intensity > 0.0,
            DirectLight::Directional {
                to_light,
                intensity,
                ..
            } => intensity > 0.0 && to_light.is_finite(),
        }
    }

    /// Whether the light casts shadows.
    pub(crate) fn shadows(&self) -> bool {
        match *self {
            DirectLight::Point { shadows, .. } | DirectLight::Directional { shadows, .. } => {
                shadows
            }
        }
    }
}

/// A light as the shading loops read it: a point or directional light, or an area light.
pub(crate) enum ShadingLight {
    Direct(DirectLight),
    Area(Emitter),
}

impl Shading {
    pub(super) fn new(scene: &Scene) -> Self {
        let origin = scene.camera.position;
        let space = RenderSpace::of(scene);
        let mut ambient = 0.0;
        let mut lights = Vec::new();
        let mut emitters = Vec::new();
        for l in &scene.lights {
            if let Some(e) = Emitter::of(l, &space) {
                emitters.push(e);
                lights.push(ShadingLight::Area(e));
                continue;
            }
            match *l {
                Light::Ambient { intensity } => ambient += intensity as f32,
                Light::Point {
                    position,
                    intensity,
                    casts_shadows,
                } => lights.push(ShadingLight::Direct(DirectLight::Point {
                    position: (position - origin).as_vec3(),
                    intensity: intensity as f32,
                    shadows: casts_shadows,
                })),
                Light::Directional {
                    direction,
                    intensity,
                    casts_shadows,
                } => lights.push(ShadingLight::Direct(DirectLight::Directional {
                    to_light: direction.as_vec3().normalize(),
                    intensity: intensity as f32,
                    shadows: casts_shadows,
                })),
                Light::Sphere { .. } | Light::Rectangle { .. } => {}
            }
        }
        let r = &scene.render;
        let occlusion = r.ambient_occlusion.is_some() && ambient > 0.0;
        let spawns = occlusion
            || lights.iter().any(|l| match l {
                ShadingLight::Direct(d) => d.shadows(),
                ShadingLight::Area(_) => true,
            });
        let keyed = occlusion || !emitters.is_empty();
        // Lights the Whitted loop would skip for every point are left out.
        let direct = lights
            .iter()
            .filter_map(|l| match *l {
                ShadingLight::Direct(d) => d.lights_some_point().then_some(d),
                ShadingLight::Area(_) => None,
            })
            .collect();
        let direct_pass = !occlusion && emitters.is_empty();
        Self {
            ambient,
            lights,
            materials: scene.materials.clone(),
            max_depth: r.max_reflection_depth,
            cutoff: r.reflection_cutoff as f32,
            ray_offset: r.ray_offset as f32,
            max_distance: r.max_distance as f32,
            spp: r.samples_per_pixel,
            area_samples: r.area_light_samples.max(1),
            ambient_occlusion: r
                .ambient_occlusion
                .map(|ao| (ao.samples.max(1), ao.distance as f32)),
            emitters,
            seed: r.seed,
            max_bounces: r.max_bounces,
            spawns,
            keyed,
            surfaces: scene.materials.iter().map(Surface::of).collect(),
            direct,
            direct_pass,
        }
    }

    /// The emission of the nearest area light the ray meets before `t_geometry`, if any.
    pub(crate) fn emitter_before(&self, ray: &Ray, t_geometry: f32) -> Option<Vec3> {
        let mut best: Option<(f32, Vec3)> = None;
        for e in &self.emitters {
            let limit = best.map_or(t_geometry, |b| b.0);
            if let Some(t) = e.intersect(ray.origin, ray.dir, limit) {
                best = Some((t, e.emission()));
            }
        }
        best.map(|b| b.1)
    }

    pub(crate) fn material(&self, id: u32) -> Material {
        self.materials
            .get(id as usize)
            .copied()
            .unwrap_or(self.materials[0])
    }

    /// [`Shading::material`] as f32 shading values.
    #[inline(always)]
    pub(crate) fn surface(&self, id: u32) -> &Surface {
        self.surfaces.get(id as usize).unwrap_or(&self.surfaces[0])
    }
}

/// Phong's diffuse plus specular factor of a light of `intensity` in direction `to_light`
/// (unit) at a point with facing normal `n` seen along `d`; 0 when the light is behind.
#[inline(always)]
pub(super) fn phong(
    n: Vec3,
    d: Vec3,
    to_light: Vec3,
    intensity: f32,
    specular: Option<f32>,
) -> f32 {
    let ndl = n.dot(to_light);
    if ndl.is_nan() || ndl <= 0.0 {
        return 0.0;
    }
    let mut amount = intensity * ndl;
    if let Some(s) = specular {
        let r = 2.0 * n * ndl - to_light;
        let rv = r.dot(-d);
        if rv > 0.0 {
            amount += intensity * rv.powf(s);
        }
    }
    amount
}

/// The Cranley-Patterson rotation of one pixel sample's stratified set number `set`.
pub(super) fn rotation_of(pixel_key: u64, set: u64) -> (f32, f32) {
    let k = pixel_key ^ mix64(set);
    (unit_from_key(k), unit_from_key(k ^ 0x9e37_79b9))
}
