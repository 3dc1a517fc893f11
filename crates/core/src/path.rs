//! The path tracer (`render.integrator: "path"`): unbiased light transport with next-event
//! estimation, traced as wavefronts so backends get rays in batches.
//!
//! Model (Kajiya, "The Rendering Equation", 1986; estimator as in pbrt-v3's `PathIntegrator`
//! without multiple importance sampling):
//! - surfaces are Lambertian with albedo `color` (BRDF `color / pi`), or, with probability
//!   `reflectivity`, perfect mirrors; specular exponents and ambient lights are ignored;
//! - at each diffuse vertex one shadow ray goes to every light (next-event estimation):
//!   area lights are sampled by solid angle (spheres) or area (rectangles) and emit radiance
//!   `intensity * color`; point lights have radiant intensity `intensity` and fall off with
//!   the squared distance; directional lights give irradiance `intensity` on a surface facing
//!   them;
//! - emission seen directly by the camera or after a mirror bounce is added (after a diffuse
//!   bounce it was already counted by next-event estimation); an area light's emitting side
//!   absorbs the path (a black emitter), its back side is invisible;
//! - rays that leave the scene see the background as environment radiance;
//! - bounce directions are cosine-distributed; after three bounces Russian roulette ends a
//!   path with probability `1 - min(max throughput channel, 0.95)` and divides the survivors
//!   by the survival probability;
//! - random numbers are a randomized Halton sequence per pixel ([`halton_dim`]) keyed by the
//!   scene's seed, the pixel and the sample: the image is the same at any thread count.
//!
//! `max_bounces = 0` gives direct lighting only. A screen tile's samples are traced in chunks
//! of `max(1, PATHS_PER_WAVEFRONT / image width)` samples (what one image row's chunk held,
//! so each pixel sums its contributions in one fixed order), so the memory does not grow with
//! the sample count.

use glam::Vec3;

use crate::camera::{Tile, sample_offset};
use crate::geometry::{OcclusionResult, Ray, TraceResult};
use crate::integrator::{
    Band, DirectLight, Frame, ShadingLight, Vertex, resolve_vertex, timed, trace_wavefront,
};
use crate::sampling::{cosine_hemisphere, halton_dim, sample_key};
use crate::stats::RenderStats;

/// Most paths of one image row traced together: sets the samples per chunk (module docs).
pub const PATHS_PER_WAVEFRONT: usize = 4096;

/// Halton dimensions used per bounce: mirror choice, Russian roulette, bounce direction (2),
/// then two per light.
const DIMS_PER_BOUNCE_FIXED: u32 = 4;

const INV_PI: f32 = std::f32::consts::FRAC_1_PI;

/// One path in the tile's wavefront; its ray is at the same index of the wavefront's rays.
#[derive(Clone, Copy)]
struct PathState {
    /// Band index of the pixel.
    pixel: u32,
    sample: u32,
    throughput: Vec3,
    /// Emission met by this ray counts (camera rays and rays after a mirror bounce).
    count_emission: bool,
    bounce: u32,
}

/// A shadow ray's pending contribution to a pixel.
struct Pending {
    pixel: u32,
    amount: Vec3,
}

/// One worker's buffers, reused from tile to tile.
#[derive(Default)]
pub(crate) struct Scratch {
    paths: Vec<PathState>,
    rays: Vec<Ray>,
    next: Vec<PathState>,
    next_rays: Vec<Ray>,
    results: Vec<TraceResult>,
    shadow_rays: Vec<Ray>,
    pending: Vec<Pending>,
    occlusion: Vec<OcclusionResult>,
    /// Colour sums, indexed like the band's pixels.
    sum: Vec<Vec3>,
}

/// Traces one band with the path tracer, tile by tile; the frame's [`crate::integrator`]
/// shading data holds the materials, lights and limits.
pub(crate) fn trace_band(f: &Frame<'_>, s: &mut Scratch, band: &mut Band<'_>) -> RenderStats {
    let mut stats = RenderStats::default();
    crate::integrator::zero_sums(&mut s.sum, band.color_len());
    for tile in band.tiles(f.tile_width()) {
        trace_tile(f, s, band, tile, &mut stats);
    }
    band.set_colors(&s.sum, f.sh.spp, &mut stats);
    stats
}

/// Traces one tile's paths, chunk of samples by chunk, wavefront by wavefront.
fn trace_tile(
    f: &Frame<'_>,
    s: &mut Scratch,
    band: &mut Band<'_>,
    tile: Tile,
    stats: &mut RenderStats,
) {
    let Scratch {
        paths,
        rays,
        next,
        next_rays,
        results,
        shadow_rays,
        pending,
        occlusion,
        sum,
    } = s;
    let (sh, geometry, background) = (f.sh, f.geometry, f.background);
    // The same render-space lights as the Whitted integrator, read physically (see the module
    // docs): ambient lights are skipped.
    let lights = &sh.lights;
    // Samples per chunk as when a chunk held one image row's samples: each pixel then adds
    // its contributions in the same order whatever the tile shape.
    let w = f.scene.camera.width as usize;
    let chunk = (PATHS_PER_WAVEFRONT / w.max(1)).max(1) as u32;
    for pixels in band.rows_of(tile) {
        sum[pixels.start as usize..pixels.end as usize].fill(Vec3::ZERO);
    }
    let mut first = 0;
    while first < sh.spp {
        let last = (first + chunk).min(sh.spp);
        paths.clear();
        rays.clear();
        for sample in first..last {
            f.camera.push(tile, sample_offset(sample), rays);
            for pixels in band.rows_of(tile) {
                paths.extend(pixels.map(|pixel| PathState {
                    pixel,
                    sample,
                    throughput: Vec3::ONE,
                    count_emission: true,
                    bounce: 0,
                }));
            }
        }
        stats.primary_rays += paths.len() as u64;
        while !paths.is_empty() {
            let camera = paths[0].bounce == 0;
            // The chunk's camera rays are ordered sample-major from sample `first`.
            let samples =
                camera.then(|| f.camera.samples(&f.scene.camera, tile).starting_at(first));
            trace_wavefront(geometry, rays, samples, results, stats);
            next.clear();
            next_rays.clear();
            shadow_rays.clear();
            pending.clear();
            for ((path, ray), res) in paths.iter().zip(rays.iter()).zip(results.iter()) {
                let px = path.pixel as usize;
                let aov = (camera && path.sample == 0 && band.aovs).then_some((&mut *band, px));
                let (hit, n) = match resolve_vertex::<false>(stats, aov, sh, background, ray, res) {
                    Vertex::Emitter(emission) => {
                        if path.count_emission {
                            sum[px] += path.throughput * emission;
                        }
                        continue;
                    }
                    Vertex::Background(radiance) => {
                        sum[px] += path.throughput * radiance;
                        continue;
                    }
                    Vertex::Surface { hit, normal } => (hit, normal),
                };
                let d = ray.dir;
                let m = sh.material(hit.material);
                let albedo = m.color.as_vec3();
                let (column, row) = band.column_row(path.pixel);
                let key = sample_key(sh.seed, column, row, 0);
                let dim0 = path.bounce * (DIMS_PER_BOUNCE_FIXED + 2 * lights.len() as u32);
                let sample = |k: u32| halton_dim(path.sample, dim0 + k, key);
                let offset = sh.ray_offset * hit.position.length().max(1e-30);
                let origin = hit.position + n * offset;
                let can_bounce = path.bounce < sh.max_bounces;
                if (m.reflectivity as f32) > sample(0) {
                    // Perfect mirror: the throughput is unchanged (weight r / probability r).
                    if can_bounce {
                        next_rays.push(Ray {
                            origin,
                            dir: (d - 2.0 * d.dot(n) * n).normalize(),
                            t_min: 0.0,
                            t_max: sh.max_distance,
                        });
                        next.push(PathState {
                            count_emission: true,
                            bounce: path.bounce + 1,
                            ..*path
                        });
                    }
                    continue;
                }
                // Diffuse vertex: next-event estimation towards every light.
                let brdf = path.throughput * albedo * INV_PI;
                for (li, light) in lights.iter().enumerate() {
                    let u = sample(DIMS_PER_BOUNCE_FIXED + 2 * li as u32);
                    let v = sample(DIMS_PER_BOUNCE_FIXED + 2 * li as u32 + 1);
                    let (dir, dist, radiance_over_pdf, shadows) = match *light {
                        ShadingLight::Direct(DirectLight::Point {
                            position,
                            intensity,
                            shadows,
                        }) => {
                            let to = position - hit.position;
                            let dist = to.length();
                            (
                                to / dist,
                                dist,
                                Vec3::splat(intensity / (dist * dist)),
                                shadows,
                            )
                        }
                        ShadingLight::Direct(DirectLight::Directional {
                            to_light,
                            intensity,
                            shadows,
                        }) => (to_light, f32::INFINITY, Vec3::splat(intensity), shadows),
                        ShadingLight::Area(e) => match e.sample(hit.position, u, v) {
                            Some(s) => (
                                s.dir,
                                s.dist,
                                e.emission() / s.pdf_solid_angle,
                                e.casts_shadows(),
                            ),
                            None => continue,
                        },
                    };
                    let cos = n.dot(dir);
                    if cos.is_nan() || cos <= 0.0 || !dir.is_finite() {
                        continue;
                    }
                    let amount = brdf * radiance_over_pdf * cos;
                    if !amount.is_finite() || amount == Vec3::ZERO {
                        continue;
                    }
                    let t_max = if dist.is_finite() {
                        dist - offset
                    } else {
                        sh.max_distance
                    };
                    if shadows && t_max > 0.0 {
                        shadow_rays.push(Ray {
                            origin,
                            dir,
                            t_min: 0.0,
                            t_max,
                        });
                        pending.push(Pending {
                            pixel: path.pixel,
                            amount,
                        });
                    } else {
                        sum[px] += amount;
                    }
                }
                if !can_bounce {
                    continue;
                }
                // Cosine-distributed bounce: BRDF * cos / pdf = albedo.
                let mut throughput = path.throughput * albedo;
                if path.bounce >= 3 {
                    let survive = throughput.max_element().min(0.95);
                    if survive <= sample(1) {
                        continue;
                    }
                    throughput /= survive;
                }
                next_rays.push(Ray {
                    origin,
                    dir: cosine_hemisphere(n, sample(2), sample(3)),
                    t_min: 0.0,
                    t_max: sh.max_distance,
                });
                next.push(PathState {
                    throughput,
                    count_emission: false,
                    bounce: path.bounce + 1,
                    ..*path
                });
            }
            if !shadow_rays.is_empty() {
                stats.trace_time.shadow_ns += timed(occlusion, shadow_rays.len(), |o| {
                    geometry.occluded_many(shadow_rays, o)
                });
                stats.shadow_rays += shadow_rays.len() as u64;
                for (p, o) in pending.iter().zip(occlusion.iter()) {
                    stats.add_work(&o.work);
                    stats.add_termination(o.termination, true);
                    if !o.occluded {
                        sum[p.pixel as usize] += p.amount;
                    }
                }
            }
            stats.bounce_rays += next.len() as u64;
            std::mem::swap(paths, next);
            std::mem::swap(rays, next_rays);
        }
        first = last;
    }
}
