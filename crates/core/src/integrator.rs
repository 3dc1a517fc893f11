//! The Whitted-style integrator: Phong shading, hard shadows (soft for area lights), ambient
//! occlusion, iterative mirror reflections and Halton anti-aliasing, traced as wavefronts per
//! screen tile ([`TILE_WIDTH`] x [`TILE_HEIGHT`] pixels, or wider: [`tile_width`]) so
//! backends get coherent rays in batches. [`render`] runs the path tracer ([`crate::path`])
//! instead when the scene asks for it.
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
use crate::camera::{PrimarySamples, Tile, TileRays, sample_offset};
use crate::clock::Clock;
use crate::emitter::Emitter;
use crate::framebuffer::{Framebuffer, NO_HIT_DEPTH};
use crate::geometry::{BatchPolicy, RenderSpace};
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
    /// Record the AOV planes of the framebuffer (depth, normal, material, termination,
    /// work). `false` leaves them empty (length 0; [`Framebuffer::has_aovs`] is false) and
    /// skips their writes, for renders whose colour and statistics are all that is read
    /// (the harness's timed repeats). Colour and statistics are the same either way.
    pub aovs: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            threads: 0,
            memory_limit_bytes: DEFAULT_MEMORY_LIMIT_BYTES,
            aovs: true,
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

impl Default for RenderOutput {
    /// An empty (0x0) output, for [`render_into`] to fill.
    fn default() -> Self {
        Self {
            framebuffer: Framebuffer::new(0, 0),
            stats: RenderStats::default(),
            elapsed: Duration::ZERO,
        }
    }
}

/// Columns of the screen tiles the integrators trace as one batch, unless the geometry
/// asks for wider ones ([`Geometry::tile_width`], see [`tile_width`]).
pub const TILE_WIDTH: u32 = 8;

/// Most camera rays (pixels times samples per pixel) of a tile widened beyond [`TILE_WIDTH`].
pub const TILE_RAYS: u32 = 512;

/// Columns of the screen tiles a render traces: the geometry's preference
/// (`preferred`, [`Geometry::tile_width`]) as far as its camera rays stay within
/// [`TILE_RAYS`] at `samples_per_pixel`, rounded down to a multiple of [`TILE_WIDTH`],
/// and from [`TILE_WIDTH`] to 64 (the widest tile the camera builds rays for).
pub fn tile_width(preferred: u32, samples_per_pixel: u32) -> u32 {
    let fits = TILE_RAYS / (TILE_HEIGHT * samples_per_pixel.max(1));
    (preferred.min(fits) / TILE_WIDTH * TILE_WIDTH)
        .clamp(TILE_WIDTH, crate::camera::MAX_TILE_WIDTH as u32)
}

/// Rows of the screen tiles the integrators trace as one batch (and of the bands of rows
/// handed to worker threads).
pub const TILE_HEIGHT: u32 = 8;

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
    let mut out = RenderOutput::default();
    render_into(scene, geometry, background, options, on_row, &mut out)?;
    Ok(out)
}

/// [`render`] into an existing output, reusing its framebuffer's memory (resized to the
/// scene's image; every pixel is overwritten, and the AOV planes are emptied when
/// `options.aovs` is false). Repeated renders of one size (benchmarks,
/// interactive views) then allocate no framebuffer; what a render still allocates is
/// small: each worker's ray and result buffers (a tile's worth) and the camera's column
/// and row terms (24 bytes per image column and row).
///
/// The image is cut into bands of [`TILE_HEIGHT`] rows, one per worker task, and each band
/// into tiles of at most [`tile_width`] x [`TILE_HEIGHT`] pixels; each tile's rays are
/// traced as wavefronts (camera rays, then shadow and other secondary rays, then
/// reflections), so a backend gets coherent batches. Every pixel's result is independent of
/// the batching and of the thread count.
pub fn render_into(
    scene: &Scene,
    geometry: &dyn Geometry,
    background: &BackgroundSampler,
    options: &RenderOptions,
    on_row: &(dyn Fn() + Sync),
    out: &mut RenderOutput,
) -> Result<(), RenderError> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    // The final buffers; the per-worker scratch is a few tiles' worth.
    let needed = Framebuffer::bytes_for(w, h);
    if needed > options.memory_limit_bytes {
        return Err(RenderError::TooLarge {
            width: w,
            height: h,
            needed_bytes: needed,
            limit_bytes: options.memory_limit_bytes,
        });
    }
    // One thread renders on the caller's thread: no pool to start and join. So does a
    // geometry that takes whole columns of the image from one thread.
    let policy = geometry.batch_policy();
    let pool = match (policy, options.threads) {
        (BatchPolicy::Columns, _) | (_, 1) => None,
        (BatchPolicy::Tiles, threads) => Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .map_err(|e| RenderError::ThreadPool {
                    threads,
                    reason: e.to_string(),
                })?,
        ),
    };
    let band_rows = match policy {
        BatchPolicy::Tiles => TILE_HEIGHT,
        BatchPolicy::Columns => h.max(1),
    };
    let shading = Shading::new(scene);
    let frame = Frame {
        scene,
        sh: &shading,
        geometry,
        background,
        camera: TileRays::new(&scene.camera, scene.render.max_distance),
    };
    let fb = &mut out.framebuffer;
    fb.resize_planes(w, h, options.aovs);
    if shading.spp == 0 {
        // No camera ray writes the pixels: leave them cleared.
        fb.clear();
    }
    // Calibrated before the render's clock starts (once per process).
    Clock::get();
    let start = Instant::now();
    let bands = Band::split(fb, band_rows, options.aovs);
    let stats = match scene.render.integrator {
        Integrator::Whitted => run_bands(pool.as_ref(), bands, on_row, |s, b| {
            trace_band(&frame, s, b)
        }),
        Integrator::Path => run_bands(pool.as_ref(), bands, on_row, |s, b| {
            crate::path::trace_band(&frame, s, b)
        }),
    };
    out.elapsed = start.elapsed();
    out.stats = stats;
    Ok(())
}

/// Traces every band with `trace` (on `pool`'s workers, or in order on this thread) and
/// sums their counters.
fn run_bands<S: Default + Send>(
    pool: Option<&rayon::ThreadPool>,
    bands: Vec<Band<'_>>,
    on_row: &(dyn Fn() + Sync),
    trace: impl Fn(&mut S, &mut Band<'_>) -> RenderStats + Sync,
) -> RenderStats {
    // Tiles write a band's pixels into a worker's own planes (which stay in cache from
    // band to band), copied into the framebuffer row-contiguously once the band is done:
    // scattered tile-row stores straight into the framebuffer cost more than the copy.
    let one = |(scratch, planes): &mut (S, Planes), mut band: Band<'_>| {
        let stats = trace(scratch, &mut band.staged(planes));
        band.copy_from(planes);
        for _ in 0..band.rows {
            on_row();
        }
        stats
    };
    let mut total = RenderStats::default();
    match pool {
        None => {
            let mut scratch = Default::default();
            for band in bands {
                total.merge(&one(&mut scratch, band));
            }
        }
        Some(pool) => {
            let per_band: Vec<RenderStats> = pool.install(|| {
                bands
                    .into_par_iter()
                    .with_max_len(1)
                    .map_init(Default::default, one)
                    .collect()
            });
            for s in &per_band {
                total.merge(s);
            }
        }
    }
    total
}

/// One worker's copy of a band's pixel planes (see [`run_bands`]).
#[derive(Default)]
struct Planes {
    color: Vec<Vec3>,
    depth: Vec<f32>,
    normal: Vec<Vec3>,
    material: Vec<u32>,
    termination: Vec<Termination>,
    work: Vec<RayWork>,
}

/// What every tile of one render reads.
pub(crate) struct Frame<'a> {
    pub(crate) scene: &'a Scene,
    pub(crate) sh: &'a Shading,
    pub(crate) geometry: &'a dyn Geometry,
    pub(crate) background: &'a BackgroundSampler,
    pub(crate) camera: TileRays,
}

impl Frame<'_> {
    /// Columns of the tiles this render traces ([`BatchPolicy`]).
    pub(crate) fn tile_width(&self) -> u32 {
        match self.geometry.batch_policy() {
            BatchPolicy::Tiles => tile_width(self.geometry.tile_width(), self.sh.spp),
            BatchPolicy::Columns => crate::camera::MAX_TILE_WIDTH as u32,
        }
    }
}

/// The framebuffer's pixels of one band of whole image rows, written in place by the tiles
/// traced in it. Pixel `i` of the band is column `i % width` of row `y + i / width`.
pub(crate) struct Band<'a> {
    pub(crate) width: usize,
    pub(crate) y: u32,
    pub(crate) rows: u32,
    /// The band records AOVs (its AOV slices are as long as `color`; empty otherwise).
    pub(crate) aovs: bool,
    color: &'a mut [Vec3],
    depth: &'a mut [f32],
    normal: &'a mut [Vec3],
    material: &'a mut [u32],
    termination: &'a mut [Termination],
    work: &'a mut [RayWork],
}

impl<'a> Band<'a> {
    /// `fb` cut into bands of `rows` rows (the last may be shorter); with `aovs` false the
    /// bands' AOV slices are empty (and so must `fb`'s AOV planes be).
    fn split(fb: &'a mut Framebuffer, rows: u32, aovs: bool) -> Vec<Band<'a>> {
        let width = fb.width as usize;
        let n = (width * rows as usize).max(1);
        let aov_len = if aovs { fb.color.len() } else { 0 };
        assert!(
            fb.aov_planes_hold(aov_len),
            "framebuffer AOV planes differ in length from what the render records"
        );
        // Empty planes give every band an empty slice.
        fn cut<T>(plane: &mut [T], n: usize) -> impl Iterator<Item = &mut [T]> {
            plane
                .chunks_mut(n)
                .chain(std::iter::repeat_with(Default::default))
        }
        let mut depth = cut(&mut fb.depth, n);
        let mut normal = cut(&mut fb.normal, n);
        let mut material = cut(&mut fb.material, n);
        let mut termination = cut(&mut fb.termination, n);
        let mut work = cut(&mut fb.work, n);
        let mut bands = Vec::new();
        for (k, color) in fb.color.chunks_mut(n).enumerate() {
            let (Some(depth), Some(normal), Some(material), Some(termination), Some(work)) = (
                depth.next(),
                normal.next(),
                material.next(),
                termination.next(),
                work.next(),
            ) else {
                unreachable!("framebuffer planes differ in length");
            };
            bands.push(Band {
                width,
                y: k as u32 * rows,
                rows: (color.len() / width.max(1)) as u32,
                aovs,
                color,
                depth,
                normal,
                material,
                termination,
                work,
            });
        }
        bands
    }

    /// A band of the same rows over `planes` (resized to the band's pixels).
    fn staged<'p>(&self, planes: &'p mut Planes) -> Band<'p> {
        let n = self.color.len();
        let m = self.depth.len();
        planes.color.resize(n, Vec3::ZERO);
        planes.depth.resize(m, NO_HIT_DEPTH);
        planes.normal.resize(m, Vec3::ZERO);
        planes.material.resize(m, u32::MAX);
        planes.termination.resize(m, Termination::Miss);
        planes.work.resize(m, RayWork::default());
        Band {
            width: self.width,
            y: self.y,
            rows: self.rows,
            aovs: self.aovs,
            color: &mut planes.color[..n],
            depth: &mut planes.depth[..m],
            normal: &mut planes.normal[..m],
            material: &mut planes.material[..m],
            termination: &mut planes.termination[..m],
            work: &mut planes.work[..m],
        }
    }

    /// Copies the pixels [`Band::staged`] traced into `planes` into this band, with
    /// non-temporal stores (the framebuffer is not read again during the render).
    fn copy_from(&mut self, planes: &Planes) {
        let (n, m) = (self.color.len(), self.depth.len());
        crate::stream::copy_streaming(self.color, &planes.color[..n]);
        crate::stream::copy_streaming(self.depth, &planes.depth[..m]);
        crate::stream::copy_streaming(self.normal, &planes.normal[..m]);
        crate::stream::copy_streaming(self.material, &planes.material[..m]);
        crate::stream::copy_streaming(self.termination, &planes.termination[..m]);
        crate::stream::copy_streaming(self.work, &planes.work[..m]);
    }

    /// The band's tiles of `tile_width` columns (the last may be narrower), left to right.
    pub(crate) fn tiles(&self, tile_width: u32) -> impl Iterator<Item = Tile> + use<> {
        let (width, y, rows) = (self.width as u32, self.y, self.rows);
        let step = tile_width.max(1);
        (0..width).step_by(step as usize).map(move |x| Tile {
            x,
            y,
            width: step.min(width - x),
            height: rows,
        })
    }

    /// Band indices of `tile`'s pixels, row-major (the order of its camera rays), as one
    /// range per tile row.
    pub(crate) fn rows_of(&self, tile: Tile) -> impl Iterator<Item = std::ops::Range<u32>> + use<> {
        let (w, x, y0) = (self.width as u32, tile.x, tile.y - self.y);
        (y0..y0 + tile.height).map(move |r| r * w + x..r * w + x + tile.width)
    }

    /// Pixels in the band.
    pub(crate) fn color_len(&self) -> usize {
        self.color.len()
    }

    /// `(column, row)` of band pixel `i`.
    pub(crate) fn column_row(&self, i: u32) -> (u32, u32) {
        let w = self.width as u32;
        (i % w, self.y + i / w)
    }

    /// Records band pixel `i`'s AOVs from its sample-0 camera ray: how it ended, its work
    /// and, for a surface, distance, facing normal and material.
    fn set_aov(&mut self, i: usize, res: &TraceResult, surface: Option<(&Hit, Vec3)>) {
        self.termination[i] = res.termination();
        self.work[i] = res.work;
        match surface {
            Some((hit, normal)) => {
                self.depth[i] = hit.t;
                self.normal[i] = normal;
                self.material[i] = hit.material;
            }
            None => {
                self.depth[i] = NO_HIT_DEPTH;
                self.normal[i] = Vec3::ZERO;
                self.material[i] = u32::MAX;
            }
        }
    }

    /// Writes the average of `sums` over `samples` into the colour of every pixel of the
    /// band (`sums` indexed like the band's pixels, each pixel's sum complete), counting
    /// (and blackening) a non-finite result in `stats`. One pass over the whole band, after
    /// its last tile: contiguous, so it vectorises (per tile row it cost 23 instructions a
    /// pixel, most of them per-row setup).
    ///
    /// # Panics
    /// If `sums` is shorter than the band (a programming error).
    pub(crate) fn set_colors(&mut self, sums: &[Vec3], samples: u32, stats: &mut RenderStats) {
        const EXPONENT: u32 = 0x7f80_0000;
        let scale = 1.0 / samples as f32;
        let sums = &sums[..self.color.len()];
        // Whether any channel's exponent field is all ones (infinite or NaN): a compare and
        // an or per channel, which vectorise with baseline SSE2.
        let mut non_finite = false;
        let channels: &mut [f32] = bytemuck::cast_slice_mut(self.color);
        for (c, s) in channels
            .iter_mut()
            .zip(bytemuck::cast_slice::<Vec3, f32>(sums))
        {
            let v = *s * scale;
            *c = v;
            non_finite |= v.to_bits() & EXPONENT == EXPONENT;
        }
        if non_finite {
            for c in self.color.iter_mut().filter(|c| !c.is_finite()) {
                *c = Vec3::ZERO;
                stats.non_finite_pixels += 1;
            }
        }
    }
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

/// Classifies one closest-hit result of a wavefront: counts its work and termination, drops a
/// non-finite hit (counted), records the AOVs of band pixel `aov` (sample 0 of a camera ray),
/// and decides whether the ray met an area light, the background or a surface.
#[inline(always)]
pub(crate) fn resolve_vertex(
    stats: &mut RenderStats,
    aov: Option<(&mut Band<'_>, usize)>,
    sh: &Shading,
    background: &BackgroundSampler,
    ray: &Ray,
    res: &TraceResult,
) -> Vertex {
    stats.add_work(&res.work);
    stats.add_termination(res.termination(), false);
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
trait MissPath {
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

/// The first pass over (part of) a wavefront's results: resolves every result without a
/// hit as [`resolve_vertex`] would (counts, area light or background radiance added to its
/// pixel's `sum`, AOVs of the first `aov_pixels` paths) and appends the wavefront indices
/// of the hits (`first` + index in the slices) to `hits`. A path's pixel is `base` plus
/// [`MissPath::pixel`].
/// Slices as arguments, so the loop keeps their addresses in registers; the loop is built
/// once per combination of "radiance is one constant" and "records AOVs", so the common
/// case (constant background, no area light) reads neither rays nor background per ray.
#[inline(never)]
fn resolve_no_hits<P: MissPath>(
    (paths, rays, results, first, base): (&[P], &[Ray], &[TraceResult], usize, u32),
    band: &mut Band<'_>,
    aov_pixels: usize,
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
        match (constant, record) {
            (Some(c), true) => miss_span::<true, P>(span, |_| c, sum, &mut aov, hits),
            (Some(c), false) => miss_span::<false, P>(span, |_| c, sum, &mut aov, hits),
            (None, true) => miss_span::<true, P>(span, radiance, sum, &mut aov, hits),
            (None, false) => miss_span::<false, P>(span, radiance, sum, &mut aov, hits),
        }
        .merge_into(stats);
    }
}

/// A band's AOV planes cut to one length (that of the colour sums), so one bounds check
/// covers a pixel's stores.
struct AovPlanes<'b> {
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

/// The counters of rays without a hit, kept in locals and added to the render's
/// [`RenderStats`] once per wavefront (the same sums [`RenderStats::add_work`] and
/// [`RenderStats::add_termination`] would make ray by ray).
#[derive(Default)]
struct MissTally {
    /// Count per [`Termination`] discriminant.
    ended: [u64; 4],
    steps: u64,
    max_steps: u32,
    node_visits: u64,
    max_node_visits: u32,
    primitive_tests: u64,
}

impl MissTally {
    #[inline(always)]
    fn add(&mut self, ended: Termination, w: &RayWork) {
        self.ended[ended as usize] += 1;
        self.steps += w.steps as u64;
        self.max_steps = self.max_steps.max(w.steps);
        self.node_visits += w.node_visits as u64;
        self.max_node_visits = self.max_node_visits.max(w.node_visits);
        self.primitive_tests += w.primitive_tests as u64;
    }

    fn merge_into(&self, stats: &mut RenderStats) {
        stats.closest_max_steps += self.ended[Termination::MaxSteps as usize];
        stats.max_distance += self.ended[Termination::MaxDistance as usize];
        stats.steps += self.steps;
        stats.max_steps_seen = stats.max_steps_seen.max(self.max_steps);
        stats.node_visits += self.node_visits;
        stats.max_node_visits_seen = stats.max_node_visits_seen.max(self.max_node_visits);
        stats.primitive_tests += self.primitive_tests;
    }
}

/// [`resolve_no_hits`] over one span of a wavefront (`first` = the span's index in it, `base` = what
/// its paths' pixels are relative to): `RECORD` says whether the span's paths record AOVs. Returns the span's counters (a
/// local tally, so they can stay in registers).
#[inline(never)]
fn miss_span<const RECORD: bool, P: MissPath>(
    (paths, rays, results, first, base): (&[P], &[Ray], &[TraceResult], usize, u32),
    radiance: impl Fn(&Ray) -> Vec3,
    sum: &mut [Vec3],
    aov: &mut AovPlanes<'_>,
    hits: &mut Vec<u32>,
) -> MissTally {
    let mut tally = MissTally::default();
    let n = if RECORD { aov.depth.len() } else { sum.len() };
    let sum = &mut sum[..n];
    // One length for the three slices, so the loop tests one end.
    let (rays, results) = (&rays[..paths.len()], &results[..paths.len()]);
    for (k, ((path, ray), res)) in paths.iter().zip(rays).zip(results).enumerate() {
        let ended = res.termination();
        if ended == Termination::Hit {
            hits.push((first + k) as u32);
            continue;
        }
        tally.add(ended, &res.work);
        let px = (base + path.pixel()) as usize;
        assert!(px < n, "path pixel outside its band");
        if RECORD {
            aov.termination[px] = ended;
            aov.work[px] = res.work;
            aov.depth[px] = NO_HIT_DEPTH;
            aov.normal[px] = Vec3::ZERO;
            aov.material[px] = u32::MAX;
        }
        sum[px] += path.weigh(radiance(ray));
    }
    tally
}

/// One path (one sample of one pixel) in the tile's wavefront; its ray is at the same index
/// of the wavefront's rays.
#[derive(Clone, Copy)]
struct Path {
    /// Band index of the pixel.
    pixel: u32,
    sample: u32,
    throughput: f32,
}

/// A shadow ray's pending contribution: added to its path's pixel if the ray is not blocked.
struct PendingLight {
    path: u32,
    amount: Vec3,
}

/// Most shadow (or ambient-occlusion) rays one batch holds: a wavefront's rays are traced
/// whenever this many are queued, so the buffers stay bounded (about 64 MiB per kind) however
/// many light and AO samples a shading point takes (4096 x 4096 at 1024 spp would otherwise
/// queue gigabytes). Ordinary scenes queue far fewer, so their batches are unchanged.
pub(crate) const MAX_OCCLUSION_BATCH: usize = 1 << 20;

/// What tracing a batch of occlusion rays needs besides the rays: the geometry, the result
/// buffer, the paths and colour sums the unblocked contributions go to, and the counters.
struct OcclusionBatch<'a, 'g> {
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
        for (p, o) in pending.iter().zip(occlusion.iter()) {
            stats.add_work(&o.work);
            stats.add_termination(o.termination, true);
            if !o.occluded {
                sum[paths[p.path as usize].pixel as usize] += p.amount;
            }
        }
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
fn trace_band(f: &Frame<'_>, s: &mut Scratch, band: &mut Band<'_>) -> RenderStats {
    let mut stats = RenderStats::default();
    zero_sums(&mut s.sum, band.color_len());
    for tile in band.tiles(f.tile_width()) {
        trace_tile(f, s, band, tile, &mut stats);
    }
    band.set_colors(&s.sum, f.sh.spp, &mut stats);
    stats
}

/// Traces one tile's paths, wavefront by wavefront, into the band's pixels.
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
                    if sample == 0 && band.aovs { n } else { 0 },
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
                0,
                sum,
                (sh, background),
                hits,
                stats,
            );
        }
        for &pi in hits.iter() {
            let pi = pi as usize;
            let (path, ray, res) = (&paths[pi], &rays[pi], &results[pi]);
            let px = path.pixel as usize;
            let aov = (depth == 0 && pi < pixels && band.aovs).then_some((&mut *band, px));
            let (hit, n) = match resolve_vertex(stats, aov, sh, background, ray, res) {
                Vertex::Emitter(radiance) | Vertex::Background(radiance) => {
                    sum[px] += path.throughput * radiance;
                    continue;
                }
                Vertex::Surface { hit, normal } => (hit, normal),
            };
            let d = ray.dir;
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
            let (column, row) = band.column_row(path.pixel);
            let pixel_key = sample_key(sh.seed, column, row, path.sample) ^ mix64(depth as u64);
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
