//! The Whitted-style integrator: Phong shading, hard shadows (soft for area lights), ambient
//! occlusion, iterative mirror reflections and Halton anti-aliasing, traced as a wavefront per
//! image row so backends get rays in batches. [`render`] runs the path tracer
//! ([`crate::path`]) instead when the scene asks for it.
//!
//! Shading follows the source study ("Computer Graphics from Scratch", Gambetta): the local
//! colour is `colour * (ambient + sum diffuse + sum specular)` with
//! `diffuse = I * max(0, n.l)` and `specular = I * max(0, r.v)^s`, `r = 2 n (n.l) - l`; a
//! reflective surface mixes `(1 - reflectivity) * local + reflectivity * reflected`.
//! Lights have no distance falloff. Secondary rays start at the hit point moved
//! `ray_offset * max(|p|, 1e-30)` along the normal (|p| = distance from the camera), and
//! shadow rays towards a point light stop the same distance short of it.
//!
//! An area light is shaded as `render.area_light_samples` point lights of `1/N` of its
//! intensity each, at stratified points of the light (Hammersley points with a per-pixel
//! rotation), each with its own shadow ray: the penumbra is the fraction of the light a point
//! sees. Ambient occlusion scales the ambient term by the fraction of cosine-distributed
//! hemisphere rays that meet nothing within its distance.

use std::time::{Duration, Instant};

use glam::Vec3;
use marchmesh_scene::{Integrator, Light, Material, Scene};
use rayon::prelude::*;

use crate::background::BackgroundSampler;
use crate::camera::{PrimarySamples, primary_ray_on, sample_offset};
use crate::emitter::Emitter;
use crate::framebuffer::{Framebuffer, NO_HIT_DEPTH};
use crate::geometry::RenderSpace;
use crate::geometry::{
    Cone, Geometry, Hit, OcclusionResult, Ray, RayWork, SurfacePoint, Termination, TraceResult,
    Visibility,
};
use crate::sampling::{cosine_hemisphere, hammersley, mix64, sample_key, unit_from_key};
use crate::stats::RenderStats;

/// Most worker threads a render, benchmark or suite may ask for: far more than any machine's
/// cores, few enough that a typo cannot start a million threads. Front ends refuse above it.
pub const MAX_THREADS: usize = 1024;

/// Default limit on the memory a render may allocate for its buffers: 4 GiB.
pub const DEFAULT_MEMORY_LIMIT_BYTES: u64 = 4 << 30;

/// How to run a render.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Worker threads; 0 means one per logical core.
    pub threads: usize,
    /// The render fails with [`RenderError::TooLarge`] before allocating more than this.
    pub memory_limit_bytes: u64,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            threads: 0,
            memory_limit_bytes: DEFAULT_MEMORY_LIMIT_BYTES,
        }
    }
}

/// Why a render could not run.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The image buffers would exceed the memory limit.
    #[error(
        "a {width}x{height} render needs {needed_bytes} bytes of buffers, over the limit of {limit_bytes} bytes"
    )]
    TooLarge {
        /// Image width.
        width: u32,
        /// Image height.
        height: u32,
        /// Bytes the buffers would take.
        needed_bytes: u64,
        /// The limit.
        limit_bytes: u64,
    },
    /// The thread pool could not be created.
    #[error("cannot create a pool of {threads} threads: {reason}")]
    ThreadPool {
        /// Requested threads.
        threads: usize,
        /// rayon's message.
        reason: String,
    },
}

/// A finished render.
#[derive(Debug, Clone)]
pub struct RenderOutput {
    /// Image and AOVs.
    pub framebuffer: Framebuffer,
    /// Ray and stability counters.
    pub stats: RenderStats,
    /// Wall time of the render phase (rays only; no geometry build).
    pub elapsed: Duration,
}

/// Renders `scene` with `geometry` (which must have been built for this scene and camera).
///
/// `on_row` is called once per finished image row, from worker threads (for progress bars).
pub fn render(
    scene: &Scene,
    geometry: &dyn Geometry,
    background: &BackgroundSampler,
    options: &RenderOptions,
    on_row: &(dyn Fn() + Sync),
) -> Result<RenderOutput, RenderError> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    // Final buffers plus the per-row copies made while tracing.
    let needed = 2 * Framebuffer::bytes_for(w, h);
    if needed > options.memory_limit_bytes {
        return Err(RenderError::TooLarge {
            width: w,
            height: h,
            needed_bytes: needed,
            limit_bytes: options.memory_limit_bytes,
        });
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(options.threads)
        .build()
        .map_err(|e| RenderError::ThreadPool {
            threads: options.threads,
            reason: e.to_string(),
        })?;
    let shading = Shading::new(scene);
    let start = Instant::now();
    let rows: Vec<RowOutput> = pool.install(|| {
        (0..h)
            .into_par_iter()
            .with_max_len(1)
            .map(|row| {
                let out = match scene.render.integrator {
                    Integrator::Whitted => trace_row(scene, &shading, geometry, background, row),
                    Integrator::Path => {
                        crate::path::trace_row(scene, &shading, geometry, background, row)
                    }
                };
                on_row();
                out
            })
            .collect()
    });
    let elapsed = start.elapsed();
    let mut fb = Framebuffer::new(w, h);
    let mut stats = RenderStats::default();
    for (row, r) in rows.into_iter().enumerate() {
        let base = row * w as usize;
        let range = base..base + w as usize;
        fb.color[range.clone()].copy_from_slice(&r.color);
        fb.depth[range.clone()].copy_from_slice(&r.depth);
        fb.normal[range.clone()].copy_from_slice(&r.normal);
        fb.material[range.clone()].copy_from_slice(&r.material);
        fb.termination[range.clone()].copy_from_slice(&r.termination);
        fb.work[range].copy_from_slice(&r.work);
        stats.merge(&r.stats);
    }
    Ok(RenderOutput {
        framebuffer: fb,
        stats,
        elapsed,
    })
}

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
}

pub(crate) enum ShadingLight {
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
    Area(Emitter),
}

impl Shading {
    fn new(scene: &Scene) -> Self {
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
                } => lights.push(ShadingLight::Point {
                    position: (position - origin).as_vec3(),
                    intensity: intensity as f32,
                    shadows: casts_shadows,
                }),
                Light::Directional {
                    direction,
                    intensity,
                    casts_shadows,
                } => lights.push(ShadingLight::Directional {
                    to_light: direction.as_vec3().normalize(),
                    intensity: intensity as f32,
                    shadows: casts_shadows,
                }),
                Light::Sphere { .. } | Light::Rectangle { .. } => {}
            }
        }
        let r = &scene.render;
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
}

/// One image row's pixels, AOVs and counters.
pub(crate) struct RowOutput {
    pub(crate) color: Vec<Vec3>,
    pub(crate) depth: Vec<f32>,
    pub(crate) normal: Vec<Vec3>,
    pub(crate) material: Vec<u32>,
    pub(crate) termination: Vec<Termination>,
    pub(crate) work: Vec<RayWork>,
    pub(crate) stats: RenderStats,
}

impl RowOutput {
    /// A row of `width` pixels with nothing hit yet.
    pub(crate) fn new(width: usize) -> Self {
        Self {
            color: vec![Vec3::ZERO; width],
            depth: vec![NO_HIT_DEPTH; width],
            normal: vec![Vec3::ZERO; width],
            material: vec![u32::MAX; width],
            termination: vec![Termination::Miss; width],
            work: vec![RayWork::default(); width],
            stats: RenderStats::default(),
        }
    }

    /// Writes the per-pixel average of `sum` over `samples`, counting (and blackening)
    /// non-finite pixels.
    pub(crate) fn finish(&mut self, sum: &[Vec3], samples: u32) {
        let inv = 1.0 / samples as f32;
        for (c, s) in self.color.iter_mut().zip(sum) {
            let v = *s * inv;
            if v.is_finite() {
                *c = v;
            } else {
                self.stats.non_finite_pixels += 1;
                *c = Vec3::ZERO;
            }
        }
    }
}

/// Resizes `out` to `len` default results, runs `trace` on it and returns the nanoseconds the
/// trace took: every batched geometry query of the integrators is timed through this, so the
/// per-ray-type times in [`RenderStats::trace_time`] measure the geometry alone.
pub(crate) fn timed<T: Clone + Default>(
    out: &mut Vec<T>,
    len: usize,
    trace: impl FnOnce(&mut [T]),
) -> u64 {
    out.clear();
    out.resize(len, T::default());
    let start = Instant::now();
    trace(out);
    start.elapsed().as_nanos() as u64
}

/// Traces one wavefront's `rays` into `results`: camera rays (with their exact `camera`
/// samples) through [`Geometry::closest_hits_primary`], timed as camera rays; any other
/// wavefront through [`Geometry::closest_hits`], timed as bounce rays.
pub(crate) fn trace_wavefront(
    geometry: &dyn Geometry,
    rays: &[Ray],
    camera: Option<PrimarySamples<'_>>,
    results: &mut Vec<TraceResult>,
    stats: &mut RenderStats,
) {
    match camera {
        Some(samples) => {
            stats.trace_time.camera_ns += timed(results, rays.len(), |r| {
                geometry.closest_hits_primary(rays, samples, r)
            })
        }
        None => {
            stats.trace_time.bounce_ns +=
                timed(results, rays.len(), |r| geometry.closest_hits(rays, r))
        }
    }
}

/// What a traced path vertex met.
pub(crate) enum Vertex {
    /// An area light's emitting side, before any surface: its emission.
    Emitter(Vec3),
    /// Nothing: the background's radiance in the ray's direction.
    Background(Vec3),
    /// A surface, with its unit normal turned to face the ray.
    Surface {
        /// The hit.
        hit: Hit,
        /// Normal facing the incoming ray.
        normal: Vec3,
    },
}

/// Classifies one closest-hit result of a wavefront: counts its work and termination, drops a
/// non-finite hit (counted), records pixel `px`'s AOVs when `aov` (sample 0 of a camera ray),
/// and decides whether the ray met an area light, the background or a surface.
pub(crate) fn resolve_vertex(
    out: &mut RowOutput,
    sh: &Shading,
    background: &BackgroundSampler,
    ray: &Ray,
    res: &TraceResult,
    px: usize,
    aov: bool,
) -> Vertex {
    out.stats.add_work(&res.work);
    out.stats.add_termination(res.termination(), false);
    let hit = res.hit().filter(|h| {
        let ok = h.t.is_finite() && h.position.is_finite() && h.normal.is_finite();
        if !ok {
            out.stats.non_finite_hits += 1;
        }
        ok
    });
    if aov {
        out.termination[px] = res.termination();
        out.work[px] = res.work;
    }
    let t_geometry = hit.map_or(ray.t_max, |h| h.t);
    if let Some(emission) = sh.emitter_before(ray, t_geometry) {
        return Vertex::Emitter(emission);
    }
    let Some(hit) = hit else {
        return Vertex::Background(background.sample(ray.dir));
    };
    let mut normal = hit.normal.normalize_or_zero();
    if normal.dot(ray.dir) > 0.0 {
        normal = -normal;
    }
    if aov {
        out.depth[px] = hit.t;
        out.normal[px] = normal;
        out.material[px] = hit.material;
    }
    Vertex::Surface { hit, normal }
}

/// One path (one sample of one pixel) in the row's wavefront.
#[derive(Clone, Copy)]
struct Path {
    pixel: u32,
    sample: u32,
    ray: Ray,
    throughput: f32,
}

/// A shadow ray's pending contribution: added to its path's pixel if the ray is not blocked.
struct PendingLight {
    path: u32,
    amount: Vec3,
}

fn trace_row(
    scene: &Scene,
    sh: &Shading,
    geometry: &dyn Geometry,
    background: &BackgroundSampler,
    row: u32,
) -> RowOutput {
    let w = scene.camera.width as usize;
    let mut out = RowOutput::new(w);
    let mut sum = vec![Vec3::ZERO; w];
    let mut paths: Vec<Path> = Vec::with_capacity(w * sh.spp as usize);
    let plane = scene.camera.image_plane();
    for s in 0..sh.spp {
        let off = sample_offset(s);
        for col in 0..w as u32 {
            paths.push(Path {
                pixel: col,
                sample: s,
                ray: primary_ray_on(&plane, col, row, off, scene.render.max_distance),
                throughput: 1.0,
            });
        }
    }
    out.stats.primary_rays += paths.len() as u64;

    let mut results: Vec<TraceResult> = Vec::new();
    let mut shadow_rays: Vec<Ray> = Vec::new();
    let mut pending: Vec<PendingLight> = Vec::new();
    let mut occlusion: Vec<OcclusionResult> = Vec::new();
    let mut ao_rays: Vec<Ray> = Vec::new();
    let mut ao_pending: Vec<PendingLight> = Vec::new();
    // Geometry shortcuts: one cone per shading point and area light, one AO estimate per
    // shading point; their pending amounts are scaled by the visible fraction.
    let shortcuts = geometry.shortcuts();
    let mut cones: Vec<Cone> = Vec::new();
    let mut cone_pending: Vec<PendingLight> = Vec::new();
    let mut ao_points: Vec<SurfacePoint> = Vec::new();
    let mut ao_point_pending: Vec<PendingLight> = Vec::new();
    let mut visibility: Vec<Visibility> = Vec::new();
    let mut next: Vec<Path> = Vec::new();
    let mut depth = 0;
    while !paths.is_empty() {
        let rays: Vec<Ray> = paths.iter().map(|p| p.ray).collect();
        // Primary rays: `paths` is ordered sample-major, as `PrimarySamples` documents.
        let camera = (depth == 0).then(|| PrimarySamples::row(&scene.camera, row));
        trace_wavefront(geometry, &rays, camera, &mut results, &mut out.stats);
        shadow_rays.clear();
        pending.clear();
        ao_rays.clear();
        ao_pending.clear();
        cones.clear();
        cone_pending.clear();
        ao_points.clear();
        ao_point_pending.clear();
        next.clear();
        for (pi, (path, res)) in paths.iter().zip(&results).enumerate() {
            let px = path.pixel as usize;
            let aov = depth == 0 && pi < w;
            let (hit, n) = match resolve_vertex(&mut out, sh, background, &path.ray, res, px, aov) {
                Vertex::Emitter(radiance) | Vertex::Background(radiance) => {
                    sum[px] += path.throughput * radiance;
                    continue;
                }
                Vertex::Surface { hit, normal } => (hit, normal),
            };
            let d = path.ray.dir;
            let m = sh.material(hit.material);
            let color = m.color.as_vec3();
            let refl = m.reflectivity as f32;
            let reflect = refl > 0.0 && depth < sh.max_depth && path.throughput * refl > sh.cutoff;
            let local_weight = if reflect {
                path.throughput * (1.0 - refl)
            } else {
                path.throughput
            };
            let offset = sh.ray_offset * hit.position.length().max(1e-30);
            let origin = hit.position + n * offset;
            let pixel_key = sample_key(sh.seed, path.pixel, row, path.sample) ^ mix64(depth as u64);
            let ambient = local_weight * sh.ambient * color;
            match sh.ambient_occlusion {
                Some(_) if sh.ambient > 0.0 && shortcuts.ambient_occlusion => {
                    ao_points.push(SurfacePoint {
                        position: origin,
                        normal: n,
                    });
                    ao_point_pending.push(PendingLight {
                        path: pi as u32,
                        amount: ambient,
                    });
                }
                Some((n_rays, distance)) if sh.ambient > 0.0 => {
                    let rotation = rotation_of(pixel_key, u64::MAX);
                    let share = ambient / n_rays as f32;
                    for k in 0..n_rays {
                        let (u, v) = hammersley(k, n_rays, rotation);
                        ao_rays.push(Ray {
                            origin,
                            dir: cosine_hemisphere(n, u, v),
                            t_min: 0.0,
                            t_max: distance,
                        });
                        ao_pending.push(PendingLight {
                            path: pi as u32,
                            amount: share,
                        });
                    }
                }
                _ => sum[px] += ambient,
            }
            for (li, light) in sh.lights.iter().enumerate() {
                let (to_light, intensity, shadows, dist) = match *light {
                    ShadingLight::Point {
                        position,
                        intensity,
                        shadows,
                    } => {
                        let v = position - hit.position;
                        let len = v.length();
                        (v / len, intensity, shadows, len - offset)
                    }
                    ShadingLight::Directional {
                        to_light,
                        intensity,
                        shadows,
                    } => (to_light, intensity, shadows, sh.max_distance),
                    ShadingLight::Area(emitter)
                        if emitter.casts_shadows() && shortcuts.cone_shadows =>
                    {
                        // Shade the sampled points without rays, then scale the sum by one
                        // cone-visibility estimate towards the light.
                        let rotation = rotation_of(pixel_key, li as u64);
                        let share = local_weight / sh.area_samples as f32;
                        let mut total = Vec3::ZERO;
                        for k in 0..sh.area_samples {
                            let (u, v) = hammersley(k, sh.area_samples, rotation);
                            if let Some(s) = emitter.sample(hit.position, u, v) {
                                total += share
                                    * phong(n, d, s.dir, 1.0, m.specular_exponent)
                                    * color
                                    * emitter.emission();
                            }
                        }
                        if let (true, Some((dir, dist, tan_half_angle))) =
                            (total != Vec3::ZERO, emitter.cone_from(hit.position))
                        {
                            cones.push(Cone {
                                origin,
                                dir,
                                t_max: (dist - offset).max(0.0),
                                tan_half_angle,
                            });
                            cone_pending.push(PendingLight {
                                path: pi as u32,
                                amount: total,
                            });
                        }
                        continue;
                    }
                    ShadingLight::Area(emitter) => {
                        let rotation = rotation_of(pixel_key, li as u64);
                        let share = local_weight / sh.area_samples as f32;
                        for k in 0..sh.area_samples {
                            let (u, v) = hammersley(k, sh.area_samples, rotation);
                            let Some(s) = emitter.sample(hit.position, u, v) else {
                                continue;
                            };
                            let amount = phong(n, d, s.dir, 1.0, m.specular_exponent);
                            if amount <= 0.0 {
                                continue;
                            }
                            let contribution = share * amount * color * emitter.emission();
                            let dist = s.dist - offset;
                            if emitter.casts_shadows() && dist > 0.0 {
                                shadow_rays.push(Ray {
                                    origin,
                                    dir: s.dir,
                                    t_min: 0.0,
                                    t_max: dist,
                                });
                                pending.push(PendingLight {
                                    path: pi as u32,
                                    amount: contribution,
                                });
                            } else {
                                sum[px] += contribution;
                            }
                        }
                        continue;
                    }
                };
                if intensity <= 0.0 || !to_light.is_finite() {
                    continue;
                }
                let amount = phong(n, d, to_light, intensity, m.specular_exponent);
                if amount <= 0.0 {
                    continue;
                }
                let contribution = local_weight * amount * color;
                if shadows && dist > 0.0 {
                    shadow_rays.push(Ray {
                        origin,
                        dir: to_light,
                        t_min: 0.0,
                        t_max: dist,
                    });
                    pending.push(PendingLight {
                        path: pi as u32,
                        amount: contribution,
                    });
                } else {
                    sum[px] += contribution;
                }
            }
            if reflect {
                next.push(Path {
                    pixel: path.pixel,
                    sample: path.sample,
                    ray: Ray {
                        origin,
                        dir: (d - 2.0 * d.dot(n) * n).normalize(),
                        t_min: 0.0,
                        t_max: sh.max_distance,
                    },
                    throughput: path.throughput * refl,
                });
            }
        }
        if !shadow_rays.is_empty() {
            out.stats.trace_time.shadow_ns += timed(&mut occlusion, shadow_rays.len(), |o| {
                geometry.occluded_many(&shadow_rays, o)
            });
            out.stats.shadow_rays += shadow_rays.len() as u64;
            for (p, o) in pending.iter().zip(&occlusion) {
                out.stats.add_work(&o.work);
                out.stats.add_termination(o.termination, true);
                if !o.occluded {
                    sum[paths[p.path as usize].pixel as usize] += p.amount;
                }
            }
        }
        if !cones.is_empty() {
            out.stats.trace_time.shadow_ns += timed(&mut visibility, cones.len(), |v| {
                geometry.cone_visibility(&cones, v)
            });
            out.stats.shadow_rays += cones.len() as u64;
            for (p, v) in cone_pending.iter().zip(&visibility) {
                out.stats.add_work(&v.work);
                out.stats.add_termination(v.termination, true);
                sum[paths[p.path as usize].pixel as usize] += p.amount * v.fraction.clamp(0.0, 1.0);
            }
        }
        if !ao_points.is_empty() {
            let distance = sh.ambient_occlusion.map_or(0.0, |a| a.1);
            out.stats.trace_time.ambient_occlusion_ns +=
                timed(&mut visibility, ao_points.len(), |v| {
                    geometry.ambient_openness(&ao_points, distance, v)
                });
            out.stats.ao_rays += ao_points.len() as u64;
            for (p, v) in ao_point_pending.iter().zip(&visibility) {
                out.stats.add_work(&v.work);
                out.stats.add_termination(v.termination, true);
                sum[paths[p.path as usize].pixel as usize] += p.amount * v.fraction.clamp(0.0, 1.0);
            }
        }
        if !ao_rays.is_empty() {
            out.stats.trace_time.ambient_occlusion_ns +=
                timed(&mut occlusion, ao_rays.len(), |o| {
                    geometry.occluded_many(&ao_rays, o)
                });
            out.stats.ao_rays += ao_rays.len() as u64;
            for (p, o) in ao_pending.iter().zip(&occlusion) {
                out.stats.add_work(&o.work);
                out.stats.add_termination(o.termination, true);
                if !o.occluded {
                    sum[paths[p.path as usize].pixel as usize] += p.amount;
                }
            }
        }
        out.stats.reflection_rays += next.len() as u64;
        std::mem::swap(&mut paths, &mut next);
        depth += 1;
    }
    out.finish(&sum, sh.spp);
    out
}

/// Phong's diffuse plus specular factor of a light of `intensity` in direction `to_light`
/// (unit) at a point with facing normal `n` seen along `d`; 0 when the light is behind.
fn phong(n: Vec3, d: Vec3, to_light: Vec3, intensity: f32, specular: Option<f64>) -> f32 {
    let ndl = n.dot(to_light);
    if ndl.is_nan() || ndl <= 0.0 {
        return 0.0;
    }
    let mut amount = intensity * ndl;
    if let Some(s) = specular {
        let r = 2.0 * n * ndl - to_light;
        let rv = r.dot(-d);
        if rv > 0.0 {
            amount += intensity * rv.powf(s as f32);
        }
    }
    amount
}

/// The Cranley-Patterson rotation of one pixel sample's stratified set number `set`.
fn rotation_of(pixel_key: u64, set: u64) -> (f32, f32) {
    let k = pixel_key ^ mix64(set);
    (unit_from_key(k), unit_from_key(k ^ 0x9e37_79b9))
}
