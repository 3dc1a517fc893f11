//! Batched queries and misses: timed batches of rays through the geometry, path vertices
//! resolved from their hits, and the lean pass resolving every ray that hit nothing
//! (background or area light, counters, AOVs).

use glam::Vec3;

use super::band::Band;
use super::shading::Shading;
use super::whitted::Path;
use crate::background::BackgroundSampler;
use crate::camera::PrimarySamples;
use crate::clock::Clock;
use crate::framebuffer::NO_HIT_DEPTH;
use crate::geometry::{Geometry, Hit, Ray, RayWork, Termination, TraceResult};
use crate::stats::RenderStats;

/// Resizes `out` to `len` results (their old values stay: `trace` overwrites them all), runs `trace` on it and returns the nanoseconds the
/// trace took (by [`Clock`]: the TSC where it is invariant, two `rdtsc` instead of two
/// `clock_gettime`): every batched geometry query of the integrators is timed through this, so the
/// per-ray-type times in [`RenderStats::trace_time`] measure the geometry alone.
pub(crate) fn timed<T: Clone + Default>(
    out: &mut Vec<T>,
    len: usize,
    trace: impl FnOnce(&mut [T]),
) -> u64 {
    // Every query writes every element of its `out` (the [`Geometry`] contract), so the
    // previous wavefront's results need not be cleared.
    out.resize(len, T::default());
    let clock = Clock::get();
    let start = clock.now();
    trace(out);
    clock.elapsed_ns(start)
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

/// Classifies one closest-hit result of a wavefront: counts its work and termination (unless
/// `COUNTED`: the miss pass, [`resolve_no_hits`], counted it already), drops a non-finite hit
/// (counted), records the AOVs of band pixel `aov` (sample 0 of a camera ray), and decides
/// whether the ray met an area light, the background or a surface.
#[inline(always)]
pub(crate) fn resolve_vertex<const COUNTED: bool>(
    stats: &mut RenderStats,
    aov: Option<(&mut Band<'_>, usize)>,
    sh: &Shading,
    background: &BackgroundSampler,
    ray: &Ray,
    res: &TraceResult,
) -> Vertex {
    if !COUNTED {
        stats.add_work(&res.work);
        stats.add_termination(res.termination(), false);
    }
    let hit = res.hit().filter(|h| {
        let ok = h.t.is_finite() && h.position.is_finite() && h.normal.is_finite();
        if !ok {
            stats.non_finite_hits += 1;
        }
        ok
    });
    let t_geometry = hit.map_or(ray.t_max, |h| h.t);
    let vertex = if let Some(emission) = sh.emitter_before(ray, t_geometry) {
        Vertex::Emitter(emission)
    } else if let Some(hit) = hit {
        let mut normal = hit.normal.normalize_or_zero();
        if normal.dot(ray.dir) > 0.0 {
            normal = -normal;
        }
        Vertex::Surface { hit, normal }
    } else {
        Vertex::Background(background.sample(ray.dir))
    };
    if let Some((band, px)) = aov {
        let surface = match &vertex {
            Vertex::Surface { hit, normal } => Some((hit, *normal)),
            _ => None,
        };
        band.set_aov(px, res, surface);
    }
    vertex
}

/// What the miss pass reads of a path: its band pixel and its share of a radiance.
pub(super) trait MissPath {
    /// Band index of the path's pixel.
    fn pixel(&self) -> u32;
    /// The radiance the path carries to its pixel from `radiance` at its vertex.
    fn weigh(&self, radiance: Vec3) -> Vec3;
}

impl MissPath for Path {
    #[inline(always)]
    fn pixel(&self) -> u32 {
        self.pixel
    }

    #[inline(always)]
    fn weigh(&self, radiance: Vec3) -> Vec3 {
        self.throughput * radiance
    }
}

/// A camera path, named by its band pixel: its throughput is 1, so the radiance is added as
/// it is (`1.0 * x` is `x` bit for bit, but for a NaN's payload, and a NaN is blackened).
impl MissPath for u32 {
    #[inline(always)]
    fn pixel(&self) -> u32 {
        *self
    }

    #[inline(always)]
    fn weigh(&self, radiance: Vec3) -> Vec3 {
        radiance
    }
}

/// The first pass over (part of) a wavefront's results: counts every result's work and
/// termination (the hits' too: resolve those with `resolve_vertex::<true>`), resolves every
/// result without a hit as [`resolve_vertex`] would (area light or background radiance added
/// to its pixel's `sum`, AOVs of the first `aov_pixels` paths) and appends the wavefront
/// indices of the hits (`first` + index in the slices) to `hits`. A path's pixel is `base`
/// plus [`MissPath::pixel`]. With `fresh`, no path's pixel has a contribution yet (its sum
/// is zero: the first sample of a tile's camera rays), so a miss stores `0 + radiance`
/// instead of reading the sum.
/// Slices as arguments, so the loop keeps their addresses in registers; the loop is built
/// once per combination of "radiance is one constant" and "records AOVs", so the common
/// case (constant background, no area light) reads neither rays nor background per ray.
#[inline(never)]
pub(super) fn resolve_no_hits<P: MissPath>(
    (paths, rays, results, first, base): (&[P], &[Ray], &[TraceResult], usize, u32),
    band: &mut Band<'_>,
    (aov_pixels, fresh): (usize, bool),
    sum: &mut [Vec3],
    (sh, background): (&Shading, &BackgroundSampler),
    hits: &mut Vec<u32>,
    stats: &mut RenderStats,
) {
    let count = paths.len();
    let (rays, results) = (&rays[..count], &results[..count]);
    let aov_pixels = aov_pixels.min(count);
    let constant = match (sh.emitters.is_empty(), background.constant()) {
        (true, Some(c)) => Some(c),
        _ => None,
    };
    let radiance = |ray: &Ray| match sh.emitter_before(ray, ray.t_max) {
        Some(e) => e,
        None => background.sample(ray.dir),
    };
    let mut aov = AovPlanes::of(band, sum.len());
    let spans = [(0, aov_pixels, true), (aov_pixels, count, false)];
    for (from, to, record) in spans {
        if from == to {
            continue;
        }
        let span = (
            &paths[from..to],
            &rays[from..to],
            &results[from..to],
            first + from,
            base,
        );
        macro_rules! miss_span {
            ($record:literal, $fresh:literal, $radiance:expr) => {
                miss_span::<$record, $fresh, P>(span, $radiance, sum, &mut aov, hits)
            };
        }
        match (constant, record, fresh) {
            (Some(c), true, true) => miss_span!(true, true, |_| c),
            (Some(c), true, false) => miss_span!(true, false, |_| c),
            (Some(c), false, true) => miss_span!(false, true, |_| c),
            (Some(c), false, false) => miss_span!(false, false, |_| c),
            (None, true, true) => miss_span!(true, true, radiance),
            (None, true, false) => miss_span!(true, false, radiance),
            (None, false, true) => miss_span!(false, true, radiance),
            (None, false, false) => miss_span!(false, false, radiance),
        }
        .merge_into(stats);
    }
}

/// A band's AOV planes cut to one length (that of the colour sums), so one bounds check
/// covers a pixel's stores.
pub(super) struct AovPlanes<'b> {
    depth: &'b mut [f32],
    normal: &'b mut [Vec3],
    material: &'b mut [u32],
    termination: &'b mut [Termination],
    work: &'b mut [RayWork],
}

impl<'b> AovPlanes<'b> {
    /// The planes of `band`, each cut to `n` pixels (empty when the band records no AOVs).
    fn of(band: &'b mut Band<'_>, n: usize) -> Self {
        let n = n.min(band.depth.len());
        Self {
            depth: &mut band.depth[..n],
            normal: &mut band.normal[..n],
            material: &mut band.material[..n],
            termination: &mut band.termination[..n],
            work: &mut band.work[..n],
        }
    }
}

/// The counters of a wavefront's closest-hit rays, kept in locals and added to the render's
/// [`RenderStats`] once per wavefront (the same sums [`RenderStats::add_work`] and
/// [`RenderStats::add_termination`] would make ray by ray).
#[derive(Default)]
pub(super) struct MissTally {
    hits: u64,
    max_steps_ended: u64,
    max_distance_ended: u64,
    steps: u64,
    max_steps: u32,
    node_visits: u64,
    max_node_visits: u32,
    primitive_tests: u64,
}

impl MissTally {
    fn merge_into(&self, stats: &mut RenderStats) {
        stats.hits += self.hits;
        stats.closest_max_steps += self.max_steps_ended;
        stats.max_distance += self.max_distance_ended;
        stats.steps += self.steps;
        stats.max_steps_seen = stats.max_steps_seen.max(self.max_steps);
        stats.node_visits += self.node_visits;
        stats.max_node_visits_seen = stats.max_node_visits_seen.max(self.max_node_visits);
        stats.primitive_tests += self.primitive_tests;
    }
}

/// [`resolve_no_hits`] over one span of a wavefront (`first` = the span's index in it, `base` = what
/// its paths' pixels are relative to): `RECORD` says whether the span's paths record AOVs,
/// `FRESH` whether their sums are zero (see [`resolve_no_hits`]). Returns the span's counters (a
/// local tally, so they can stay in registers).
#[inline(never)]
pub(super) fn miss_span<const RECORD: bool, const FRESH: bool, P: MissPath>(
    (paths, rays, results, first, base): (&[P], &[Ray], &[TraceResult], usize, u32),
    radiance: impl Fn(&Ray) -> Vec3,
    sum: &mut [Vec3],
    aov: &mut AovPlanes<'_>,
    hits: &mut Vec<u32>,
) -> MissTally {
    let n = if RECORD { aov.depth.len() } else { sum.len() };
    let sum = &mut sum[..n];
    // The hits are listed into slots made for every path (a `memset`), counted in a local
    // and cut to that count after: a `Vec::push` kept the vector's length in memory and
    // checked its capacity per hit.
    let hits_before = hits.len();
    hits.resize(hits_before + paths.len(), 0);
    let slots = &mut hits[hits_before..];
    let mut listed = 0;
    // The counters in locals (never borrowed, so they stay in registers); hits are counted
    // by how many were listed: an indexed counter per termination made every ray wait on
    // the previous one's store.
    let (mut steps, mut node_visits, mut primitive_tests) = (0u64, 0u64, 0u64);
    let (mut max_steps, mut max_node_visits) = (0u32, 0u32);
    let (mut max_steps_ended, mut max_distance_ended) = (0u64, 0u64);
    // One length for the three slices, so the loop tests one end.
    let (rays, results) = (&rays[..paths.len()], &results[..paths.len()]);
    for (k, ((path, ray), res)) in paths.iter().zip(rays).zip(results).enumerate() {
        let (ended, w) = (res.termination(), res.work);
        steps += w.steps as u64;
        max_steps = max_steps.max(w.steps);
        node_visits += w.node_visits as u64;
        max_node_visits = max_node_visits.max(w.node_visits);
        primitive_tests += w.primitive_tests as u64;
        match ended {
            Termination::Hit => {
                slots[listed] = (first + k) as u32;
                listed += 1;
                continue;
            }
            Termination::Miss => {}
            Termination::MaxSteps => max_steps_ended += 1,
            Termination::MaxDistance => max_distance_ended += 1,
        }
        let px = (base + path.pixel()) as usize;
        assert!(px < n, "path pixel outside its band");
        if RECORD {
            aov.termination[px] = ended;
            aov.work[px] = res.work;
            aov.depth[px] = NO_HIT_DEPTH;
            aov.normal[px] = Vec3::ZERO;
            aov.material[px] = u32::MAX;
        }
        let r = path.weigh(radiance(ray));
        if FRESH {
            // The sum is zero: the same addition, without reading it.
            sum[px] = Vec3::ZERO + r;
        } else {
            sum[px] += r;
        }
    }
    hits.truncate(hits_before + listed);
    MissTally {
        hits: listed as u64,
        max_steps_ended,
        max_distance_ended,
        steps,
        max_steps,
        node_visits,
        max_node_visits,
        primitive_tests,
    }
}
