//! Companion of `scripts/anchor_embree.py`: frames a mesh file as `benches/bvh.rs` does
//! (500x500, 40 deg), then either exports the exact camera rays and render-space triangles
//! for Embree, or times the mesh backend on the same rays (1 thread, primary rays only).
//!
//! `anchor_rays export MESH OUT_DIR`: writes `tris.f32` (9 f32 per triangle: v0 v1 v2),
//! `rays.f32` (6 f32 per ray: origin, direction) little-endian, in render space.
//! `anchor_rays time MESH BVH REPEATS [PRESET]`: builds with the build preset `PRESET`
//! (`fastest|very_fast|fast|medium|tuned|slow|very_slow`, default `tuned` as in renders) and `bvh`
//! (bvh2|cwbvh|wide|wide1|wide4x2|wide8|wide8x8|raw; `wide1` traces single rays one call each,
//! `wide` row batches with packets of 8 consecutive pixels of a row, `wide4x2` the same rays
//! reordered into 4x2-pixel tiles, handed over a tile row at a time; `wide8` row batches
//! without packets and `wide8x8` 8x8-pixel tiles without packets, a tile row at a time (both
//! interleaved single rays on a large mesh, see `INTERLEAVE_MIN_BYTES`; packet modes fall back
//! to the same there)) and prints
//! one Mrays/s figure per timed repeat (CPU time of the tracing thread) after one warm-up (`raw` is obvhs' own Bvh2
//! traversal with no marchmesh code in the loop).
//!
//! `anchor_rays time-rays MESH BVH QUERY RAYS_FILE REPEATS OUT_FILE [PRESET]`: times the mesh
//! backend on given rays, the incoherent rays of the anchor (ambient-occlusion and bounce
//! rays, `scripts/anchor_incoherent.py`). `RAYS_FILE` holds 7 little-endian f32 per ray
//! (origin, direction, tmax; tmin 0) in render space; `QUERY` is `occluded`
//! (`Geometry::occluded_many`, the call the integrators make for shadow and AO rays) or
//! `closest` (`Geometry::closest_hits`, their call for bounce and reflection rays), handed
//! over in batches of one tile's worth of rays ([`BATCH`]); `BVH` is `wide` (the default
//! layout, built as renders build it), `bvh2` or `cwbvh`. Prints one `Mrays/s count` line per
//! timed repeat after one warm-up (count: rays that hit or are occluded) and writes each
//! ray's answer of the last repeat to `OUT_FILE` as little-endian f32: the hit distance
//! (+inf on a miss), or 1 / 0 for occluded / not.

#[path = "../benches/support/mod.rs"]
mod support;

use std::io::Write;
use std::time::Instant;

use glam::{Vec3, Vec3A};
use marchmesh_core::{Geometry, OcclusionResult, Ray, TraceResult};
use marchmesh_mesh::{BvhKind, MeshOptions, build};
use obvhs::triangle::Triangle;
use support::*;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// The scene and render-space triangles of a mesh file framed like the benchmark.
fn framed(path: &str) -> Res<(marchmesh_scene::Scene, Vec<Triangle>)> {
    let abs = std::fs::canonicalize(path)?;
    let mesh = marchmesh_meshio::load_mesh(&abs)?;
    let (lo, hi) = mesh.bounds();
    let json = format!(
        r#"{{{}, "objects": [{{"shape": {{"mesh": {{"path": {:?}}}}}}}]}}"#,
        camera_json(lo.as_dvec3(), hi.as_dvec3()),
        abs.display().to_string()
    );
    let scene = marchmesh_scene::parse_scene(&json, "anchor", &scenes_dir())?;
    let cam = scene.camera.position;
    let p = |i: u32| Vec3A::from((mesh.positions[i as usize].as_dvec3() - cam).as_vec3());
    let tris = mesh
        .triangles
        .iter()
        .map(|t| Triangle {
            v0: p(t[0]),
            v1: p(t[1]),
            v2: p(t[2]),
        })
        .collect();
    Ok((scene, tris))
}

fn write_f32(path: std::path::PathBuf, values: impl Iterator<Item = f32>) -> Res<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(&path)?);
    for v in values {
        out.write_all(&v.to_le_bytes())?;
    }
    out.flush()?;
    Ok(())
}

/// Seconds the calling thread has run on a CPU (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`, as
/// Python's `time.thread_time` on the Embree side): on a loaded machine it leaves out the time
/// the tracer waits descheduled, which wall time would count. Wall seconds since `start` off
/// Linux or if the clock fails. (`/proc/thread-self/schedstat`, used before, is only brought
/// up to date at scheduler ticks for a running thread: 4 ms steps on a 32-36 ms trace of the
/// full dragon made every repeat read either 6.94 or 7.81 Mrays/s.)
#[allow(unsafe_code)] // one libc call, no std equivalent
fn thread_seconds(start: Instant) -> f64 {
    #[cfg(target_os = "linux")]
    {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: `ts` is a valid, writable timespec.
        if unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) } == 0 {
            return ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9;
        }
    }
    start.elapsed().as_secs_f64()
}

/// `rays` (row-major, `side` wide) reordered tile by tile: each run of `tw * th` rays is one
/// `tw x th` tile (row-major inside), tiles row-major; a ragged edge keeps what fits.
fn tiled<T: Copy>(rays: &[T], side: usize, tw: usize, th: usize) -> Vec<T> {
    let height = rays.len() / side;
    let mut out = Vec::with_capacity(rays.len());
    for ty in (0..height).step_by(th) {
        for tx in (0..side).step_by(tw) {
            for y in ty..(ty + th).min(height) {
                for x in tx..(tx + tw).min(side) {
                    out.push(rays[y * side + x]);
                }
            }
        }
    }
    out
}

/// Rays per batch query in `time-rays`: one tile's worth of camera rays, the size of the
/// wavefronts the integrator hands over.
const BATCH: usize = marchmesh_core::integrator::TILE_RAYS as usize;

/// The build preset by its option name (`build=...`, through the same serde names); the
/// renders' default when `None`.
fn preset(name: Option<&String>) -> Res<marchmesh_mesh::BuildQuality> {
    let Some(name) = name else {
        return Ok(MeshOptions::default().build_quality());
    };
    use serde::{Deserialize, de::value::StrDeserializer};
    let de = StrDeserializer::<serde::de::value::Error>::new(name);
    Ok(marchmesh_mesh::BuildQuality::deserialize(de)
        .map_err(|e| format!("unknown preset `{name}`: {e}"))?)
}

/// Rays of 7 little-endian f32 each (origin, direction, tmax), tmin 0.
fn read_rays(path: &str) -> Res<Vec<Ray>> {
    let bytes = std::fs::read(path)?;
    if bytes.is_empty() || !bytes.len().is_multiple_of(28) {
        return Err(format!(
            "{path}: {} bytes, not a positive multiple of 7 f32",
            bytes.len()
        )
        .into());
    }
    let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    Ok(bytes
        .chunks_exact(28)
        .map(|r| {
            let v: [f32; 7] = std::array::from_fn(|k| f(&r[4 * k..]));
            Ray {
                origin: Vec3::new(v[0], v[1], v[2]),
                dir: Vec3::new(v[3], v[4], v[5]),
                t_min: 0.0,
                t_max: v[6],
            }
        })
        .collect())
}

/// `time-rays`: see the module documentation.
fn time_rays(scene: &marchmesh_scene::Scene, args: &[String], usage: &str) -> Res<()> {
    let arg = |k: usize| args.get(k).map(String::as_str).ok_or(usage);
    let kind = match arg(3)? {
        "wide" => BvhKind::Wide,
        "bvh2" => BvhKind::Bvh2,
        "cwbvh" => BvhKind::CwBvh,
        other => {
            return Err(format!("unknown bvh `{other}` (time-rays: wide, bvh2, cwbvh)").into());
        }
    };
    let occlusion = match arg(4)? {
        "occluded" => true,
        "closest" => false,
        other => return Err(format!("unknown query `{other}` (occluded, closest)").into()),
    };
    let rays = read_rays(arg(5)?)?;
    let repeats: usize = arg(6)?.parse()?;
    let out_path = arg(7)?;
    let g = build(
        scene,
        &MeshOptions {
            bvh: Some(kind),
            build: Some(preset(args.get(8))?),
            ..MeshOptions::default()
        },
    )?;
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let mut hits = vec![TraceResult::default(); rays.len()];
    let mut occluded = vec![OcclusionResult::default(); rays.len()];
    let start = Instant::now();
    // One pass over the rays in batches, timed on the pool's thread: Mrays/s.
    let mut pass = || {
        pool.install(|| {
            let t0 = thread_seconds(start);
            if occlusion {
                for (r, o) in rays.chunks(BATCH).zip(occluded.chunks_mut(BATCH)) {
                    g.occluded_many(r, o);
                }
            } else {
                for (r, o) in rays.chunks(BATCH).zip(hits.chunks_mut(BATCH)) {
                    g.closest_hits(r, o);
                }
            }
            rays.len() as f64 / (thread_seconds(start) - t0).max(1e-12) / 1e6
        })
    };
    pass();
    let mut rates = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        rates.push(pass());
    }
    let (answers, work): (Vec<f32>, Vec<_>) = if occlusion {
        occluded
            .iter()
            .map(|o| (if o.occluded { 1.0 } else { 0.0 }, o.work))
            .unzip()
    } else {
        hits.iter()
            .map(|o| (o.hit().map_or(f32::INFINITY, |h| h.t), o.work))
            .unzip()
    };
    let count = if occlusion {
        occluded.iter().filter(|o| o.occluded).count()
    } else {
        hits.iter().filter(|o| o.hit().is_some()).count()
    };
    let per_ray = |f: fn(&marchmesh_core::RayWork) -> u32| {
        work.iter().map(|w| f64::from(f(w))).sum::<f64>() / rays.len() as f64
    };
    eprintln!(
        "{} {} rays: {count} {}; per ray {:.2} node visits, {:.2} triangle tests",
        rays.len(),
        if occlusion {
            "occlusion"
        } else {
            "closest-hit"
        },
        if occlusion { "occluded" } else { "hit" },
        per_ray(|w| w.node_visits),
        per_ray(|w| w.primitive_tests),
    );
    write_f32(out_path.into(), answers.into_iter())?;
    for r in rates {
        println!("{r:.4} {count}");
    }
    Ok(())
}

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: anchor_rays export MESH OUT_DIR | anchor_rays time MESH BVH REPEATS \
                 [PRESET] | anchor_rays time-rays MESH BVH QUERY RAYS_FILE REPEATS OUT_FILE [PRESET]";
    let (Some(mode), Some(mesh)) = (args.get(1), args.get(2)) else {
        return Err(usage.into());
    };
    let (scene, tris) = framed(mesh)?;
    if mode == "time-rays" {
        return time_rays(&scene, &args, usage);
    }
    let rays = primary_rays(&scene);
    match mode.as_str() {
        "export" => {
            let dir = std::path::PathBuf::from(args.get(3).ok_or(usage)?);
            std::fs::create_dir_all(&dir)?;
            write_f32(
                dir.join("tris.f32"),
                tris.iter()
                    .flat_map(|t| [t.v0, t.v1, t.v2])
                    .flat_map(|v| [v.x, v.y, v.z]),
            )?;
            write_f32(
                dir.join("rays.f32"),
                rays.iter()
                    .flat_map(|r| [r.origin.to_array(), r.dir.to_array()])
                    .flatten(),
            )?;
            println!("{} triangles, {} rays", tris.len(), rays.len());
        }
        "time" => {
            let bvh = args.get(3).ok_or(usage)?.as_str();
            let repeats: usize = args.get(4).ok_or(usage)?.parse()?;
            let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
            let kind = match bvh {
                "bvh2" | "raw" => BvhKind::Bvh2,
                "cwbvh" => BvhKind::CwBvh,
                "wide" | "wide1" | "wide4x2" | "wide8" | "wide8x8" => BvhKind::Wide,
                other => return Err(format!("unknown bvh `{other}`").into()),
            };
            let build_quality = preset(args.get(5))?;
            let g = build(
                &scene,
                &MeshOptions {
                    bvh: Some(kind),
                    build: Some(build_quality),
                    packets: Some(bvh == "wide" || bvh == "wide4x2"),
                    ..MeshOptions::default()
                },
            )?;
            let report = g.report();
            eprintln!(
                "{bvh}: {} bytes, {:.1} bytes per triangle (nodes, indices, triangles, normals)",
                report.memory_bytes,
                report.memory_bytes as f64 / tris.len() as f64
            );
            let raw = raw_build(kind, &tris);
            let side = scene.camera.width as usize;
            // One batch per image row, or per row of tiles.
            let (rays, batch) = if bvh == "wide4x2" {
                (tiled(&rays, side, 4, 2), side * 2)
            } else if bvh == "wide8x8" {
                (tiled(&rays, side, 8, 8), side * 8)
            } else {
                (rays, side)
            };
            let mut out = vec![TraceResult::default(); rays.len()];
            let start = Instant::now();
            let trace = |out: &mut [TraceResult]| {
                let t0 = thread_seconds(start);
                let mut seconds = 0.0;
                let mut hits = 0usize;
                if bvh == "wide1" {
                    // Single rays only (no packets).
                    hits = rays
                        .iter()
                        .filter(|r| g.closest_hit(r).hit().is_some())
                        .count();
                } else if bvh == "raw" {
                    hits = rays
                        .iter()
                        .filter(|r| raw_closest(&raw, r).is_finite())
                        .count();
                } else {
                    seconds = pool.install(|| {
                        // Row (or tile-row) batches, as the integrator hands them over,
                        // timed on the pool's thread.
                        let t0 = thread_seconds(start);
                        for (r, o) in rays.chunks(batch).zip(out.chunks_mut(batch)) {
                            g.closest_hits(r, o);
                        }
                        thread_seconds(start) - t0
                    });
                    hits += out.iter().filter(|o| o.hit().is_some()).count();
                }
                if seconds == 0.0 {
                    seconds = thread_seconds(start) - t0;
                }
                (rays.len() as f64 / seconds / 1e6, hits)
            };
            trace(&mut out);
            if bvh == "wide1" {
                for (r, o) in rays.iter().zip(out.iter_mut()) {
                    *o = g.closest_hit(r);
                }
            }
            if bvh != "raw" {
                let mean = |hit: bool, f: fn(&TraceResult) -> u32| {
                    let sel = out.iter().filter(|o| o.hit().is_some() == hit);
                    let (n, sum) = sel.fold((0.0, 0.0), |(n, s), o| (n + 1.0, s + f64::from(f(o))));
                    sum / f64::max(n, 1.0)
                };
                let visits = |o: &TraceResult| o.work.node_visits;
                let tests = |o: &TraceResult| o.work.primitive_tests;
                eprintln!(
                    "{bvh}: per hit ray {:.2} node visits, {:.2} triangle tests; per missing ray {:.2}, {:.2}",
                    mean(true, visits),
                    mean(true, tests),
                    mean(false, visits),
                    mean(false, tests)
                );
            }
            for _ in 0..repeats {
                let (mrays, hits) = trace(&mut out);
                println!("{mrays:.4} {hits}");
            }
        }
        _ => return Err(usage.into()),
    }
    Ok(())
}
