//! The Whitted integrator's wavefronts per tile: primary rays, the shadow rays of every
//! light in one occlusion batch, ambient occlusion, and reflections as the next wavefront.

use glam::Vec3;

use super::band::{Band, Frame};
use super::direct::{Shadows, Wavefront, shade_direct};
use super::shading::{DirectLight, ShadingLight, phong, rotation_of};
use super::wavefront::{Vertex, resolve_no_hits, resolve_vertex, timed, trace_wavefront};
use crate::camera::{Tile, sample_offset};
use crate::geometry::{
    Cone, Geometry, OcclusionResult, Ray, SurfacePoint, TraceResult, Visibility,
};
use crate::sampling::{cosine_hemisphere, hammersley, mix64, sample_key};
use crate::stats::RenderStats;

/// One path (one sample of one pixel) in the tile's wavefront; its ray is at the same index
/// of the wavefront's rays.
#[derive(Clone, Copy)]
pub(super) struct Path {
    /// Band index of the pixel.
    pub(super) pixel: u32,
    pub(super) sample: u32,
    pub(super) throughput: f32,
}

/// A shadow ray's pending contribution: added to its path's pixel if the ray is not blocked.
pub(super) struct PendingLight {
    /// Wavefront index of the path.
    pub(super) path: u32,
    pub(super) amount: Vec3,
}

/// Most shadow (or ambient-occlusion) rays one batch holds: a wavefront's rays are traced
/// whenever this many are queued, so the buffers stay bounded (about 64 MiB per kind) however
/// many light and AO samples a shading point takes (4096 x 4096 at 1024 spp would otherwise
/// queue gigabytes). Ordinary scenes queue far fewer, so their batches are unchanged.
pub(crate) const MAX_OCCLUSION_BATCH: usize = 1 << 20;

/// What tracing a batch of occlusion rays needs besides the rays: the geometry, the result
/// buffer, the paths and colour sums the unblocked contributions go to, and the counters.
pub(super) struct OcclusionBatch<'a, 'g> {
    geometry: &'g dyn Geometry,
    occlusion: &'a mut Vec<OcclusionResult>,
    paths: &'a [Path],
    sum: &'a mut [Vec3],
    stats: &'a mut RenderStats,
}

impl OcclusionBatch<'_, '_> {
    /// Traces `rays`, adds the contribution in `pending` of each unblocked ray to its path's
    /// pixel, counts them (as ambient occlusion when `ao`, else as shadows) and empties both.
    fn flush(self, rays: &mut Vec<Ray>, pending: &mut Vec<PendingLight>, ao: bool) {
        if rays.is_empty() {
            return;
        }
        let Self {
            geometry,
            occlusion,
            paths,
            sum,
            stats,
        } = self;
        let ns = timed(occlusion, rays.len(), |o| geometry.occluded_many(rays, o));
        if ao {
            stats.trace_time.ambient_occlusion_ns += ns;
            stats.ao_rays += rays.len() as u64;
        } else {
            stats.trace_time.shadow_ns += ns;
            stats.shadow_rays += rays.len() as u64;
        }
        // The counters tallied in a local (kept in registers; through `stats` every ray's
        // sums waited on the previous ray's stores), then merged: the same sums and maxima.
        let mut tally = RenderStats::default();
        for (p, o) in pending.iter().zip(occlusion.iter()) {
            tally.add_work(&o.work);
            tally.add_termination(o.termination, true);
            if !o.occluded {
                sum[paths[p.path as usize].pixel as usize] += p.amount;
            }
        }
        stats.merge(&tally);
        rays.clear();
        pending.clear();
    }

    /// [`OcclusionBatch::flush`] once `rays` holds [`MAX_OCCLUSION_BATCH`] rays, so a
    /// wavefront's occlusion buffers stay bounded however many samples a point takes.
    fn flush_when_full(self, rays: &mut Vec<Ray>, pending: &mut Vec<PendingLight>, ao: bool) {
        if rays.len() >= MAX_OCCLUSION_BATCH {
            self.flush(rays, pending, ao);
        }
    }
}

/// One worker's buffers, reused from tile to tile.
#[derive(Default)]
pub(crate) struct Scratch {
    paths: Vec<Path>,
    rays: Vec<Ray>,
    next: Vec<Path>,
    next_rays: Vec<Ray>,
    results: Vec<TraceResult>,
    shadow_rays: Vec<Ray>,
    pending: Vec<PendingLight>,
    occlusion: Vec<OcclusionResult>,
    ao_rays: Vec<Ray>,
    ao_pending: Vec<PendingLight>,
    cones: Vec<Cone>,
    cone_pending: Vec<PendingLight>,
    ao_points: Vec<SurfacePoint>,
    ao_point_pending: Vec<PendingLight>,
    visibility: Vec<Visibility>,
    /// Indices into `paths` of the wavefront's rays that hit a surface.
    hits: Vec<u32>,
    /// Band pixels of a tile at column 0, row-major: camera ray `k` of a tile at column `x`
    /// is pixel `x + camera_offsets[k % len]` (paths for camera rays are built only for a
    /// tile with a hit).
    camera_offsets: Vec<u32>,
    /// (tile width, tile height, band width) `camera_offsets` was built for.
    camera_shape: (u32, u32, usize),
    /// Colour sums, indexed like the band's pixels.
    sum: Vec<Vec3>,
}

/// Sets `sum` to `len` zero colours, as bytes: one `memset` (`clear` and `resize` stored a
/// `Vec3` at a time); what each integrator's band starts from.
pub(crate) fn zero_sums(sum: &mut Vec<Vec3>, len: usize) {
    sum.truncate(len);
    bytemuck::cast_slice_mut::<Vec3, u8>(sum).fill(0);
    sum.resize(len, Vec3::ZERO);
}

/// Traces one band with the Whitted integrator, tile by tile.
pub(super) fn trace_band(f: &Frame<'_>, s: &mut Scratch, band: &mut Band<'_>) -> RenderStats {
    let mut stats = RenderStats::default();
    zero_sums(&mut s.sum, band.color_len());
    for tile in band.tiles(f.tile_width()) {
        trace_tile(f, s, band, tile, &mut stats);
    }
    band.set_colors(&s.sum, f.sh.spp, &mut stats);
    stats
}

/// Traces one tile's paths, wavefront by wavefront, into the band's pixels.
pub(super) fn trace_tile(
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
        ao_rays,
        ao_pending,
        cones,
        cone_pending,
        ao_points,
        ao_point_pending,
        visibility,
        hits,
        camera_offsets,
        camera_shape,
        sum,
    } = s;
    let (sh, geometry, background) = (f.sh, f.geometry, f.background);
    // The occlusion batch over this tile's buffers; a macro, so its borrows end at each flush.
    macro_rules! occlusion_batch {
        () => {
            OcclusionBatch {
                geometry,
                occlusion: &mut *occlusion,
                paths: &paths[..],
                sum: &mut sum[..],
                stats: &mut *stats,
            }
        };
    }
    let pixels = tile.pixels();
    paths.clear();
    rays.clear();
    // The same for every full tile of a band: rebuilt for the band's last, narrower tile.
    if *camera_shape != (tile.width, tile.height, band.width) {
        *camera_shape = (tile.width, tile.height, band.width);
        camera_offsets.clear();
        for row in band.rows_of(Tile { x: 0, ..tile }) {
            camera_offsets.extend(row);
        }
    }
    for sample in 0..sh.spp {
        f.camera.push(tile, sample_offset(sample), rays);
    }
    // `sum` was zeroed for the whole band (`trace_band`); each pixel is in one tile.
    stats.primary_rays += rays.len() as u64;

    // Geometry shortcuts: one cone per shading point and area light, one AO estimate per
    // shading point; their pending amounts are scaled by the visible fraction.
    let shortcuts = geometry.shortcuts();
    let mut depth = 0;
    // `paths` holds the wavefront's paths from the first hit on (camera paths are named by
    // `camera_pixels` until then).
    while !rays.is_empty() {
        // Camera rays: `rays` are ordered sample-major, as `PrimarySamples` documents.
        let camera = (depth == 0).then(|| f.camera.samples(&f.scene.camera, tile));
        trace_wavefront(geometry, rays, camera, results, stats);
        shadow_rays.clear();
        pending.clear();
        ao_rays.clear();
        ao_pending.clear();
        cones.clear();
        cone_pending.clear();
        ao_points.clear();
        ao_point_pending.clear();
        next.clear();
        next_rays.clear();
        // Rays without a hit first (most camera rays of a small object), in a lean loop;
        // the hits after, in order.
        hits.clear();
        if depth == 0 {
            // Sample-major: camera ray `k` is pixel `tile.x + camera_offsets[k % n]`, sample `k / n`,
            // throughput 1; sample 0 records the AOVs.
            let n = camera_offsets.len();
            for sample in 0..sh.spp as usize {
                let from = sample * n;
                let to = from + n;
                resolve_no_hits(
                    (
                        camera_offsets,
                        &rays[from..to],
                        &results[from..to],
                        from,
                        tile.x,
                    ),
                    band,
                    (if sample == 0 && band.aovs { n } else { 0 }, sample == 0),
                    sum,
                    (sh, background),
                    hits,
                    stats,
                );
            }
            if !hits.is_empty() {
                for sample in 0..sh.spp {
                    paths.extend(camera_offsets.iter().map(|&offset| Path {
                        pixel: tile.x + offset,
                        sample,
                        throughput: 1.0,
                    }));
                }
            }
        } else {
            resolve_no_hits(
                (paths, rays, results, 0, 0),
                band,
                (0, false),
                sum,
                (sh, background),
                hits,
                stats,
            );
        }
        // A scene with only point, directional and ambient lights and no ambient occlusion
        // shades its plain hits in the direct pass (queueing their shadow rays as the loop
        // below would); the loop takes the hits it stops at, one at a time, in order.
        let direct = sh.direct_pass;
        // One sample a pixel: no two paths of a wavefront share a pixel (a path spawns at
        // most one reflection), so the direct pass may shade hits eight at a time.
        let distinct = sh.spp == 1;
        let wavefront = direct.then(|| Wavefront {
            paths,
            rays,
            results,
            aov_paths: if depth == 0 && band.aovs { pixels } else { 0 },
            depth,
        });
        let mut next_hit = 0;
        while next_hit < hits.len() {
            if let Some(w) = &wavefront {
                let shadows = Shadows::of(shadow_rays, pending);
                next_hit += shade_direct(&hits[next_hit..], w, sum, band, shadows, sh, distinct);
                if next_hit == hits.len() {
                    break;
                }
            }
            let pi = hits[next_hit] as usize;
            next_hit += 1;
            let (path, ray, res) = (&paths[pi], &rays[pi], &results[pi]);
            let px = path.pixel as usize;
            let aov = (depth == 0 && pi < pixels && band.aovs).then_some((&mut *band, px));
            let (hit, n) = match resolve_vertex::<true>(stats, aov, sh, background, ray, res) {
                Vertex::Emitter(radiance) | Vertex::Background(radiance) => {
                    sum[px] += path.throughput * radiance;
                    continue;
                }
                Vertex::Surface { hit, normal } => (hit, normal),
            };
            let d = ray.dir;
            let m = sh.surface(hit.material);
            let color = m.color;
            let refl = m.reflectivity;
            let reflect = refl > 0.0 && depth < sh.max_depth && path.throughput * refl > sh.cutoff;
            let local_weight = if reflect {
                path.throughput * (1.0 - refl)
            } else {
                path.throughput
            };
            // Where secondary rays start, and the sample's random key: skipped (their square
            // root, division and hashing) when no light, occlusion or mirror reads them.
            let (offset, origin) = if reflect || sh.spawns {
                let offset = sh.ray_offset * hit.position.length().max(1e-30);
                (offset, hit.position + n * offset)
            } else {
                (0.0, hit.position)
            };
            let pixel_key = if sh.keyed {
                let (column, row) = band.column_row(path.pixel);
                sample_key(sh.seed, column, row, path.sample) ^ mix64(depth as u64)
            } else {
                0
            };
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
                    occlusion_batch!().flush_when_full(ao_rays, ao_pending, true);
                }
                _ => sum[px] += ambient,
            }
            for (li, light) in sh.lights.iter().enumerate() {
                let (to_light, intensity, shadows, dist) = match *light {
                    ShadingLight::Direct(DirectLight::Point {
                        position,
                        intensity,
                        shadows,
                    }) => {
                        let v = position - hit.position;
                        let len = v.length();
                        (v / len, intensity, shadows, len - offset)
                    }
                    ShadingLight::Direct(DirectLight::Directional {
                        to_light,
                        intensity,
                        shadows,
                    }) => (to_light, intensity, shadows, sh.max_distance),
                    ShadingLight::Area(emitter)
                        if emitter.casts_shadows() && shortcuts.cone_shadows =>
                    {
                        // Shade the sampled points without rays, then scale the sum by the
                        // cone-visibility estimates of the light's parts, weighted by their
                        // solid angles (one cone for spheres and squarish rectangles).
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
                        let (parts, count) = emitter.cones_from(hit.position);
                        if total != Vec3::ZERO {
                            for part in &parts[..count] {
                                cones.push(Cone {
                                    origin,
                                    dir: part.dir,
                                    t_max: (part.dist - offset).max(0.0),
                                    tan_half_angle: part.tan_half_angle,
                                });
                                cone_pending.push(PendingLight {
                                    path: pi as u32,
                                    amount: total * part.weight,
                                });
                            }
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
                                Shadows::of(shadow_rays, pending).push(
                                    pi,
                                    origin,
                                    s.dir,
                                    dist,
                                    contribution,
                                );
                            } else {
                                sum[px] += contribution;
                            }
                        }
                        occlusion_batch!().flush_when_full(shadow_rays, pending, false);
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
                    Shadows::of(shadow_rays, pending).push(
                        pi,
                        origin,
                        to_light,
                        dist,
                        contribution,
                    );
                } else {
                    sum[px] += contribution;
                }
            }
            if reflect {
                next.push(Path {
                    pixel: path.pixel,
                    sample: path.sample,
                    throughput: path.throughput * refl,
                });
                next_rays.push(Ray {
                    origin,
                    dir: (d - 2.0 * d.dot(n) * n).normalize(),
                    t_min: 0.0,
                    t_max: sh.max_distance,
                });
            }
        }
        occlusion_batch!().flush(shadow_rays, pending, false);
        if !cones.is_empty() {
            stats.trace_time.shadow_ns += timed(visibility, cones.len(), |v| {
                geometry.cone_visibility(cones, v)
            });
            stats.shadow_rays += cones.len() as u64;
            for (p, v) in cone_pending.iter().zip(visibility.iter()) {
                stats.add_work(&v.work);
                stats.add_termination(v.termination, true);
                sum[paths[p.path as usize].pixel as usize] += p.amount * v.fraction.clamp(0.0, 1.0);
            }
        }
        if !ao_points.is_empty() {
            let distance = sh.ambient_occlusion.map_or(0.0, |a| a.1);
            stats.trace_time.ambient_occlusion_ns += timed(visibility, ao_points.len(), |v| {
                geometry.ambient_openness(ao_points, distance, v)
            });
            stats.ao_rays += ao_points.len() as u64;
            for (p, v) in ao_point_pending.iter().zip(visibility.iter()) {
                stats.add_work(&v.work);
                stats.add_termination(v.termination, true);
                sum[paths[p.path as usize].pixel as usize] += p.amount * v.fraction.clamp(0.0, 1.0);
            }
        }
        occlusion_batch!().flush(ao_rays, ao_pending, true);
        stats.reflection_rays += next.len() as u64;
        std::mem::swap(paths, next);
        std::mem::swap(rays, next_rays);
        depth += 1;
    }
}
