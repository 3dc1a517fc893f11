//! The Whitted-style integrator: Phong shading, hard shadows, iterative mirror reflections and
//! Halton anti-aliasing, traced as a wavefront per image row so backends get rays in batches.
//!
//! Shading follows the source study ("Computer Graphics from Scratch", Gambetta): the local
//! colour is `colour * (ambient + sum diffuse + sum specular)` with
//! `diffuse = I * max(0, n.l)` and `specular = I * max(0, r.v)^s`, `r = 2 n (n.l) - l`; a
//! reflective surface mixes `(1 - reflectivity) * local + reflectivity * reflected`.
//! Lights have no distance falloff. Secondary rays start at the hit point moved
//! `ray_offset * max(|p|, 1e-30)` along the normal (|p| = distance from the camera), and
//! shadow rays towards a point light stop the same distance short of it.

use std::time::{Duration, Instant};

use glam::Vec3;
use marchmesh_scene::{Light, Material, Scene};
use rayon::prelude::*;

use crate::background::BackgroundSampler;
use crate::camera::{PrimarySamples, primary_ray, sample_offset};
use crate::framebuffer::{Framebuffer, NO_HIT_DEPTH};
use crate::geometry::{Geometry, OcclusionResult, Ray, RayWork, Termination, TraceResult};
use crate::stats::RenderStats;

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
                let out = trace_row(scene, &shading, geometry, background, row);
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

/// Scene data the shading loop reads, converted once to f32 render space.
struct Shading {
    ambient: f32,
    lights: Vec<ShadingLight>,
    materials: Vec<Material>,
    max_depth: u32,
    cutoff: f32,
    ray_offset: f32,
    max_distance: f32,
    spp: u32,
}

enum ShadingLight {
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

impl Shading {
    fn new(scene: &Scene) -> Self {
        let origin = scene.camera.position;
        let mut ambient = 0.0;
        let mut lights = Vec::new();
        for l in &scene.lights {
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
        }
    }

    fn material(&self, id: u32) -> Material {
        self.materials
            .get(id as usize)
            .copied()
            .unwrap_or(self.materials[0])
    }
}

struct RowOutput {
    color: Vec<Vec3>,
    depth: Vec<f32>,
    normal: Vec<Vec3>,
    material: Vec<u32>,
    termination: Vec<Termination>,
    work: Vec<RayWork>,
    stats: RenderStats,
}

/// One path (one sample of one pixel) in the row's wavefront.
#[derive(Clone, Copy)]
struct Path {
    pixel: u32,
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
    let mut out = RowOutput {
        color: vec![Vec3::ZERO; w],
        depth: vec![NO_HIT_DEPTH; w],
        normal: vec![Vec3::ZERO; w],
        material: vec![u32::MAX; w],
        termination: vec![Termination::Miss; w],
        work: vec![RayWork::default(); w],
        stats: RenderStats::default(),
    };
    let mut sum = vec![Vec3::ZERO; w];
    let mut paths: Vec<Path> = Vec::with_capacity(w * sh.spp as usize);
    for s in 0..sh.spp {
        let off = sample_offset(s);
        for col in 0..w as u32 {
            paths.push(Path {
                pixel: col,
                ray: primary_ray(&scene.camera, col, row, off, scene.render.max_distance),
                throughput: 1.0,
            });
        }
    }
    out.stats.primary_rays += paths.len() as u64;

    let mut results: Vec<TraceResult> = Vec::new();
    let mut shadow_rays: Vec<Ray> = Vec::new();
    let mut pending: Vec<PendingLight> = Vec::new();
    let mut occlusion: Vec<OcclusionResult> = Vec::new();
    let mut next: Vec<Path> = Vec::new();
    let mut depth = 0;
    while !paths.is_empty() {
        results.clear();
        results.resize(paths.len(), TraceResult::default());
        let rays = paths.iter().map(|p| p.ray).collect::<Vec<_>>();
        if depth == 0 {
            // Primary rays: `paths` is ordered sample-major, as `PrimarySamples` documents.
            let samples = PrimarySamples::row(&scene.camera, row);
            geometry.closest_hits_primary(&rays, samples, &mut results);
        } else {
            geometry.closest_hits(&rays, &mut results);
        }
        shadow_rays.clear();
        pending.clear();
        next.clear();
        for (pi, (path, res)) in paths.iter().zip(&results).enumerate() {
            out.stats.add_work(&res.work);
            out.stats.add_termination(res.termination, false);
            let px = path.pixel as usize;
            let hit = res.hit.filter(|h| {
                let ok = h.t.is_finite() && h.position.is_finite() && h.normal.is_finite();
                if !ok {
                    out.stats.non_finite_hits += 1;
                }
                ok
            });
            // AOVs: primary ray of sample 0 (the first `w` paths of depth 0).
            if depth == 0 && pi < w {
                out.termination[px] = res.termination;
                out.work[px] = res.work;
            }
            let Some(hit) = hit else {
                sum[px] += path.throughput * background.sample(path.ray.dir);
                continue;
            };
            let d = path.ray.dir;
            let mut n = hit.normal.normalize_or_zero();
            if n.dot(d) > 0.0 {
                n = -n;
            }
            if depth == 0 && pi < w {
                out.depth[px] = hit.t;
                out.normal[px] = n;
                out.material[px] = hit.material;
            }
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
            sum[px] += local_weight * sh.ambient * color;
            for light in &sh.lights {
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
                };
                let ndl = n.dot(to_light);
                let facing = ndl > 0.0; // false for NaN too
                if !facing || intensity <= 0.0 || !to_light.is_finite() {
                    continue;
                }
                let mut amount = intensity * ndl;
                if let Some(s) = m.specular_exponent {
                    let r = 2.0 * n * ndl - to_light;
                    let rv = r.dot(-d);
                    if rv > 0.0 {
                        amount += intensity * rv.powf(s as f32);
                    }
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
            occlusion.clear();
            occlusion.resize(shadow_rays.len(), OcclusionResult::default());
            geometry.occluded_many(&shadow_rays, &mut occlusion);
            out.stats.shadow_rays += shadow_rays.len() as u64;
            for (p, o) in pending.iter().zip(&occlusion) {
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
    let inv = 1.0 / sh.spp as f32;
    for (c, s) in out.color.iter_mut().zip(&sum) {
        let v = *s * inv;
        if v.is_finite() {
            *c = v;
        } else {
            out.stats.non_finite_pixels += 1;
            *c = Vec3::ZERO;
        }
    }
    out
}
