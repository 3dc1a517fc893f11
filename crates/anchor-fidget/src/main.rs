//! `anchor-fidget`: marchmesh's sdf backend against fidget on the same camera rays.
//!
//! For each scene: load it (`marchmesh_scene::load`), set the image size, translate its
//! objects into one fidget tree ([`tree`]), JIT-compile it, and lay fidget's voxel volume
//! over the camera's frustum so that every voxel column is marchmesh's camera ray through
//! that pixel's centre ([`view`]). Then, interleaved per round (one warm-up round, then
//! `--repeats` timed rounds whose order alternates: fidget first in even rounds, sdf first in
//! odd ones):
//!
//! * **fidget**: `VoxelRenderConfig::run` of the JIT shape (depth image with normals, fidget's
//!   one 3D render call; its root tape is compiled inside the call, as for any user);
//! * **sdf**: `Geometry::closest_hits` of marchmesh's sdf geometry (`marchmesh_sdf::build`,
//!   default options) on the image's rows of primary rays (`primary_ray_on` at the pixel
//!   centres, the integrator's own rays), generated before timing; closest hits only: no
//!   lights, no shading, no reflections.
//!
//! Both run on `--threads` threads (1 by default: fidget with no pool, the sdf rows in a
//! plain loop; more: one rayon pool each). Depths are compared per pixel with the exact
//! reference (`marchmesh_reference`, f64 camera rays): mean / p95 / max over the pixels both
//! hit, and the silhouette mismatches. fidget's depth `d` (the frontmost inside voxel is
//! `d - 1`, the one in front of it outside) is read as the middle of that bracket, `d - 0.5`,
//! turned into the distance along the ray.

mod generate;
mod stats;
mod tree;
mod view;

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, Result, bail};
use clap::Parser;
use fidget::context::Context;
use fidget::jit::{JitFunction, JitShape};
use fidget::raster::{GeometryBuffer, VoxelRenderConfig};
use fidget::render::{RenderHints, ThreadPool};
use glam::DVec3;
use marchmesh_core::camera::{primary_ray_on, sample_offset};
use marchmesh_core::{Geometry, PrimarySamples, Ray, TraceResult};
use marchmesh_scene::Scene;
use rayon::prelude::*;
use serde::Serialize;

use stats::{DepthErrors, Timing, median};
use tree::{TreeOptions, scene_tree};
use view::VoxelView;

/// Command line of `anchor-fidget`.
#[derive(Debug, Parser)]
#[command(
    name = "anchor-fidget",
    about = "Renders marchmesh scenes with fidget (JIT, interval pruning) and marchmesh's sdf backend on the same camera rays, interleaved, and compares pixel rates and depth errors against the exact reference."
)]
struct Args {
    /// Scene files (sphere, box, plane as a slab, union, intersection, subtraction).
    scenes: Vec<PathBuf>,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 512)]
    size: u32,
    /// Timed rounds per scene (after one warm-up round).
    #[arg(long, default_value_t = 15)]
    repeats: u32,
    /// Threads for each renderer.
    #[arg(long, default_value_t = 1)]
    threads: usize,
    /// fidget voxels per pixel column (depth resolution), comma-separated for several
    /// measurements per scene (each timed against its own sdf run); default: the image size.
    #[arg(long, value_delimiter = ',')]
    depth: Vec<u32>,
    /// View depth of fidget's front face (along the camera's forward axis); default: the
    /// nearest corner of the scene's bounding box.
    #[arg(long)]
    near: Option<f64>,
    /// View depth of fidget's back face; default: the farthest corner of the scene's box.
    #[arg(long)]
    far: Option<f64>,
    /// Thickness of the slab a `plane` becomes (world units).
    #[arg(long, default_value_t = 1.0)]
    slab_thickness: f64,
    /// Write the results as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write the results as a Markdown table here.
    #[arg(long)]
    markdown: Option<PathBuf>,
    /// Instead of measuring: write `spheres-N.json` (union of N separate spheres) for each N
    /// given (comma-separated) into `--out-dir`.
    #[arg(long, value_delimiter = ',')]
    generate_spheres: Vec<u32>,
    /// Folder for `--generate-spheres`.
    #[arg(long, default_value = ".")]
    out_dir: PathBuf,
}

/// Everything measured in one run.
#[derive(Debug, Serialize)]
struct Report {
    tool: &'static str,
    fidget_version: String,
    unix_time: u64,
    date_utc: String,
    cpu: String,
    load_average_start: String,
    load_average_end: String,
    size: u32,
    threads: usize,
    repeats: u32,
    protocol: &'static str,
    scenes: Vec<SceneResult>,
}

/// One scene's measurements.
#[derive(Debug, Serialize)]
struct SceneResult {
    scene: String,
    leaves: usize,
    notes: Vec<String>,
    width: u32,
    height: u32,
    fidget_depth_voxels: u32,
    near: f64,
    far: f64,
    fidget_build_ms: f64,
    sdf_build_ms: f64,
    fidget: Timing,
    sdf: Timing,
    /// sdf Mpixels/s over fidget Mpixels/s, from the medians.
    ratio_sdf_over_fidget: f64,
    /// Median over rounds of the same ratio within each round (robust to load drift).
    ratio_sdf_over_fidget_per_round_median: f64,
    sdf_mean_steps_per_ray: f64,
    sdf_max_steps_rays: u64,
    fidget_saturated_pixels: u64,
    reference_hits: u64,
    fidget_depth_error: DepthErrors,
    sdf_depth_error: DepthErrors,
    /// fidget's depth quantum at the median reference hit distance (one voxel, world units).
    fidget_voxel_at_median_hit: f64,
}

const PROTOCOL: &str = "per scene: 1 warm-up round, then N timed rounds; each round times one fidget VoxelRenderConfig::run and one sdf closest_hits over all primary rows, fidget first in even rounds and sdf first in odd ones; median and min over rounds";

fn main() -> Result<()> {
    let args = Args::parse();
    if !args.generate_spheres.is_empty() {
        return generate_scenes(&args.generate_spheres, &args.out_dir);
    }
    if args.scenes.is_empty() {
        bail!("no scene given (pass SCENE.json..., or --generate-spheres N,...)");
    }
    if args.threads == 0 {
        bail!("--threads must be >= 1");
    }
    if args.repeats == 0 {
        bail!("--repeats must be >= 1");
    }
    let load_start = load_average();
    let fidget_pool = if args.threads > 1 {
        Some(ThreadPool::Custom(
            rayon::ThreadPoolBuilder::new()
                .num_threads(args.threads)
                .build()
                .context("building fidget's thread pool")?,
        ))
    } else {
        None
    };
    let sdf_pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .build()
        .context("building the sdf thread pool")?;
    let depths = if args.depth.is_empty() {
        vec![args.size]
    } else {
        args.depth.clone()
    };
    let mut results = Vec::new();
    for path in &args.scenes {
        for &depth in &depths {
            let r = measure(path, depth, &args, fidget_pool.as_ref(), &sdf_pool)
                .with_context(|| format!("scene {} at depth {depth}", path.display()))?;
            print_row(&r);
            results.push(r);
        }
    }
    let unix_time = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let report = Report {
        tool: "anchor-fidget",
        fidget_version: fidget_version(),
        unix_time,
        date_utc: utc_string(unix_time),
        cpu: cpu_model(),
        load_average_start: load_start,
        load_average_end: load_average(),
        size: args.size,
        threads: args.threads,
        repeats: args.repeats,
        protocol: PROTOCOL,
        scenes: results,
    };
    let md = markdown(&report);
    println!("\n{md}");
    if let Some(p) = &args.json {
        let text = serde_json::to_string_pretty(&report).context("serialising the report")?;
        std::fs::write(p, text + "\n").with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(p) = &args.markdown {
        std::fs::write(p, md).with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}

/// Writes `spheres-N.json` for each `n`.
fn generate_scenes(ns: &[u32], dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for &n in ns {
        if n == 0 {
            bail!("--generate-spheres: N must be >= 1");
        }
        let path = dir.join(format!("spheres-{n}.json"));
        std::fs::write(&path, generate::spheres_scene(n))
            .with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// Loads, builds and measures one scene.
fn measure(
    path: &Path,
    depth: u32,
    args: &Args,
    fidget_pool: Option<&ThreadPool>,
    sdf_pool: &rayon::ThreadPool,
) -> Result<SceneResult> {
    let scene = marchmesh_scene::load(path)?
        .with_image_size(args.size, args.size)
        .map_err(|e| anyhow::anyhow!("--size {}: {e}", args.size))?;
    let cam = scene.camera;
    let (w, h) = (cam.width, cam.height);
    let pixels = u64::from(w) * u64::from(h);

    // fidget: tree, JIT, voxel volume on the camera rays.
    let t0 = Instant::now();
    let translation = scene_tree(
        &scene,
        &TreeOptions {
            slab_thickness: args.slab_thickness,
        },
    )?;
    let mut ctx = Context::new();
    let node = ctx.import(&translation.tree);
    let shape = JitShape::new(&ctx, node).context("JIT-compiling the fidget shape")?;
    let fidget_build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let (near, far) = match (args.near, args.far) {
        (Some(n), Some(f)) => (n, f),
        (n, f) => {
            let (bn, bf) = bracket(&scene)?;
            (n.unwrap_or(bn), f.unwrap_or(bf))
        }
    };
    let view = VoxelView::new(&cam, depth, near, far)?;
    let cfg = VoxelRenderConfig {
        image_size: view.voxel_size(),
        world_to_model: view.world_to_model()?,
        tile_sizes: JitFunction::tile_sizes_3d(),
        threads: fidget_pool,
        ..Default::default()
    };

    // marchmesh: sdf geometry, reference, primary rays.
    let t0 = Instant::now();
    let sdf = marchmesh_sdf::build(&scene, &marchmesh_sdf::SdfOptions::default())
        .context("building the sdf geometry")?;
    let sdf_build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let reference = marchmesh_reference::build(&scene, &Default::default())
        .context("building the reference")?;
    let rays = primary_rays(&scene);
    let truth = reference_depths(&scene, &reference, &rays);

    let run_fidget = || -> Result<(f64, GeometryBuffer)> {
        let s = shape.clone();
        let t = Instant::now();
        let img = cfg.run(s).context("fidget render was cancelled")?;
        Ok((t.elapsed().as_secs_f64(), img))
    };
    let mut hits = vec![TraceResult::default(); rays.len()];
    let run_sdf = |hits: &mut [TraceResult]| -> f64 {
        let t = Instant::now();
        if args.threads == 1 {
            for (r, o) in rays.chunks(w as usize).zip(hits.chunks_mut(w as usize)) {
                sdf.closest_hits(r, o);
            }
        } else {
            sdf_pool.install(|| {
                rays.par_chunks(w as usize)
                    .zip(hits.par_chunks_mut(w as usize))
                    .for_each(|(r, o)| sdf.closest_hits(r, o));
            });
        }
        t.elapsed().as_secs_f64()
    };

    // Warm-up round: its images are the ones compared (every round renders the same).
    let (_, fidget_img) = run_fidget()?;
    run_sdf(&mut hits);
    let mut ft = Vec::new();
    let mut st = Vec::new();
    for round in 0..args.repeats {
        if round % 2 == 0 {
            ft.push(run_fidget()?.0);
            st.push(run_sdf(&mut hits));
        } else {
            st.push(run_sdf(&mut hits));
            ft.push(run_fidget()?.0);
        }
    }
    let round_ratios: Vec<f64> = ft.iter().zip(&st).map(|(f, s)| f / s).collect();
    let fidget = Timing::new(ft, pixels);
    let sdf_t = Timing::new(st, pixels);

    // Depths.
    let (fidget_depths, saturated) = fidget_depths(&view, &fidget_img);
    let sdf_depths: Vec<Option<f64>> = hits
        .iter()
        .map(|r| r.hit().map(|h| f64::from(h.t)))
        .collect();
    let steps: u64 = hits.iter().map(|r| u64::from(r.work.steps)).sum();
    let max_steps = hits
        .iter()
        .filter(|r| r.termination() == marchmesh_core::Termination::MaxSteps)
        .count() as u64;
    let ref_hits: Vec<f64> = truth.iter().flatten().copied().collect();
    let median_hit = median(&ref_hits);
    // One voxel at the median hit: d(view depth)/dz = -b s^2.
    let voxel_at_median = if median_hit.is_finite() {
        let s = median_hit; // distance along the ray ~ view depth near the centre
        s * s * (1.0 / near - 1.0 / far) / f64::from(depth)
    } else {
        f64::NAN
    };
    Ok(SceneResult {
        scene: path.display().to_string(),
        leaves: translation.leaves,
        notes: translation.notes,
        width: w,
        height: h,
        fidget_depth_voxels: depth,
        near,
        far,
        fidget_build_ms,
        sdf_build_ms,
        ratio_sdf_over_fidget: fidget.median_s / sdf_t.median_s,
        ratio_sdf_over_fidget_per_round_median: median(&round_ratios),
        fidget,
        sdf: sdf_t,
        sdf_mean_steps_per_ray: steps as f64 / pixels as f64,
        sdf_max_steps_rays: max_steps,
        fidget_saturated_pixels: saturated,
        reference_hits: ref_hits.len() as u64,
        fidget_depth_error: DepthErrors::new(&fidget_depths, &truth),
        sdf_depth_error: DepthErrors::new(&sdf_depths, &truth),
        fidget_voxel_at_median_hit: voxel_at_median,
    })
}

/// The integrator's primary rays (sample 0 = pixel centre), row by row.
fn primary_rays(scene: &Scene) -> Vec<Ray> {
    let plane = scene.camera.image_plane();
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut rays = Vec::with_capacity(w as usize * h as usize);
    for row in 0..h {
        for col in 0..w {
            rays.push(primary_ray_on(
                &plane,
                col,
                row,
                sample_offset(0),
                scene.render.max_distance,
            ));
        }
    }
    rays
}

/// The reference's depth per pixel, traced as the exact f64 camera rays.
fn reference_depths(scene: &Scene, reference: &dyn Geometry, rays: &[Ray]) -> Vec<Option<f64>> {
    let w = scene.camera.width as usize;
    let mut out = vec![TraceResult::default(); rays.len()];
    for (row, (r, o)) in rays.chunks(w).zip(out.chunks_mut(w)).enumerate() {
        let samples = PrimarySamples::row(&scene.camera, row as u32);
        reference.closest_hits_primary(r, samples, o);
    }
    out.iter()
        .map(|r| r.hit().map(|h| f64::from(h.t)))
        .collect()
}

/// fidget's depth image as distances along the camera rays (`None` where empty), and the
/// number of saturated pixels (filled up to the front face).
fn fidget_depths(view: &VoxelView, img: &GeometryBuffer) -> (Vec<Option<f64>>, u64) {
    let w = view.width as usize;
    let mut saturated = 0;
    let depths = img
        .iter()
        .enumerate()
        .map(|(i, p)| {
            if p.depth <= 0.0 {
                return None;
            }
            if p.depth >= view.depth as f32 {
                saturated += 1;
            }
            let (col, row) = ((i % w) as u32, (i / w) as u32);
            Some(view.ray_distance(col, row, f64::from(p.depth) - 0.5))
        })
        .collect();
    (depths, saturated)
}

/// View depths (along the camera's forward axis) of the nearest and farthest corners of the
/// scene's bounding box, padded by 0.1%: fidget's volume then holds every visible surface.
fn bracket(scene: &Scene) -> Result<(f64, f64)> {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for o in &scene.objects {
        let b = o
            .bounds_in_parent(&|_| None)
            .filter(|b| b.is_finite())
            .with_context(|| {
                format!(
                    "{}: unbounded (a plane?): pass --near and --far to bracket it",
                    o.json_path
                )
            })?;
        lo = lo.min(b.lo);
        hi = hi.max(b.hi);
    }
    let cam = &scene.camera;
    let mut near = f64::INFINITY;
    let mut far = f64::NEG_INFINITY;
    for i in 0..8 {
        let c = DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        let s = (c - cam.position).dot(cam.forward);
        near = near.min(s);
        far = far.max(s);
    }
    if !(near > 0.0 && far > near) {
        bail!(
            "the scene's box spans view depths {near:.4} to {far:.4}: the camera is beside or inside it; pass --near (> 0) and --far"
        );
    }
    Ok((near * 0.999, far * 1.001))
}

/// One line per scene on stdout while running.
fn print_row(r: &SceneResult) {
    println!(
        "{} (depth {}): fidget {:.3} Mpix/s, sdf {:.3} Mpix/s, sdf/fidget {:.3} (per-round median {:.3}); depth error mean fidget {:.2e} sdf {:.2e}; silhouette mismatches fidget {} sdf {}",
        r.scene,
        r.fidget_depth_voxels,
        r.fidget.mpix_per_s_median,
        r.sdf.mpix_per_s_median,
        r.ratio_sdf_over_fidget,
        r.ratio_sdf_over_fidget_per_round_median,
        r.fidget_depth_error.mean,
        r.sdf_depth_error.mean,
        r.fidget_depth_error.silhouette_mismatch,
        r.sdf_depth_error.silhouette_mismatch
    );
    let _ = std::io::stdout().flush();
}

/// The Markdown table of a report.
fn markdown(r: &Report) -> String {
    let mut s = format!(
        "fidget {} vs marchmesh sdf, {}x{} primary rays, {} thread(s), {} timed rounds (median), {} UTC, {}; load average at start {}, at end {}\n\n",
        r.fidget_version,
        r.size,
        r.size,
        r.threads,
        r.repeats,
        r.date_utc,
        r.cpu,
        r.load_average_start,
        r.load_average_end
    );
    s.push_str("| scene | leaves | fidget voxels per column | fidget Mpix/s | sdf Mpix/s | sdf / fidget | fidget depth error mean / p95 / max | sdf depth error mean / p95 / max | wrong-surface pixels fidget / sdf | silhouette mismatches fidget / sdf |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|---|\n");
    for x in &r.scenes {
        let name = Path::new(&x.scene)
            .file_stem()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| x.scene.clone());
        let e = |d: &DepthErrors| format!("{:.1e} / {:.1e} / {:.1e}", d.mean, d.p95, d.max);
        s.push_str(&format!(
            "| {} | {} | {} | {:.2} | {:.2} | {:.2} | {} | {} | {} / {} | {} / {} |\n",
            name,
            x.leaves,
            x.fidget_depth_voxels,
            x.fidget.mpix_per_s_median,
            x.sdf.mpix_per_s_median,
            x.ratio_sdf_over_fidget,
            e(&x.fidget_depth_error),
            e(&x.sdf_depth_error),
            x.fidget_depth_error.over_1e2_relative,
            x.sdf_depth_error.over_1e2_relative,
            x.fidget_depth_error.silhouette_mismatch,
            x.sdf_depth_error.silhouette_mismatch
        ));
    }
    s
}

/// The fidget version this binary was built against, from the crate's committed lockfile.
fn fidget_version() -> String {
    let lock = include_str!("../Cargo.lock");
    let mut lines = lock.lines();
    while let Some(l) = lines.next() {
        if l.trim() == "name = \"fidget\""
            && let Some(v) = lines
                .next()
                .and_then(|v| v.trim().strip_prefix("version = "))
        {
            return v.trim_matches('"').to_string();
        }
    }
    "unknown".into()
}

/// `/proc/loadavg`'s three load averages, or `n/a`.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "n/a".into())
}

/// The first CPU model name in `/proc/cpuinfo`, or `unknown CPU`.
fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into())
}

/// `YYYY-MM-DD HH:MM:SS` (UTC) of a Unix time (Hinnant's civil-from-days).
fn utc_string(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02}",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates_are_right() {
        assert_eq!(utc_string(0), "1970-01-01 00:00:00");
        assert_eq!(utc_string(951_782_400), "2000-02-29 00:00:00");
        assert_eq!(utc_string(1_700_000_000), "2023-11-14 22:13:20");
    }

    #[test]
    fn the_lockfile_names_a_fidget_0_4() {
        assert!(fidget_version().starts_with("0.4."), "{}", fidget_version());
    }
}
