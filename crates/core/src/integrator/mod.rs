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
//!
//! One concept per file: this file holds the render entry points, their options and the
//! tiling; `band` the image bands workers write; `shading` Phong shading and light
//! sampling; `wavefront` batched queries and the resolution of rays that hit nothing;
//! `whitted` the per-tile wavefronts of the Whitted integrator; `direct` its hit pass for
//! scenes of point, directional and ambient lights without ambient occlusion.

use std::time::{Duration, Instant};

use marchmesh_scene::{Integrator, Scene};
use rayon::prelude::*;

use crate::background::BackgroundSampler;
use crate::camera::TileRays;
use crate::clock::Clock;
use crate::framebuffer::Framebuffer;
use crate::geometry::{BatchPolicy, Geometry};
use crate::stats::RenderStats;

mod band;
mod direct;
mod shading;
mod wavefront;
mod whitted;

use band::Planes;
pub(crate) use band::{Band, Frame};
use shading::Shading;
pub(crate) use shading::{DirectLight, ShadingLight};
pub(crate) use wavefront::{Vertex, resolve_vertex, timed, trace_wavefront};
use whitted::trace_band;
pub(crate) use whitted::zero_sums;

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
    // Tiles write a band's AOVs into a worker's own planes (which stay in cache from band
    // to band), copied into the framebuffer row-contiguously once the band is done:
    // scattered tile-row stores straight into the framebuffer cost more than the copy. The
    // colour, averaged from the worker's sums once the band is done, is streamed straight
    // into the framebuffer.
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
