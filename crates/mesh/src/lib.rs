//! The mesh backend of marchmesh: every object becomes triangles in obvhs BVHs.
//!
//! * Analytic shapes are tessellated to an error budget ([`Tessellation`]): by default the
//!   chord error, seen from the shape's nearest distance to the camera, stays under a quarter
//!   of a pixel. Planes become a finite quad grid covering `render.max_distance` around the
//!   camera's foot point.
//! * Meshes load through `marchmesh-meshio` (OBJ, glTF/.glb).
//! * CSG intersections, subtractions and smooth unions have no exact triangle form: their
//!   surface is extracted from the shared distance field (`marchmesh-field`) with surface
//!   nets, restricted to the object's bounds. Plain unions need no extraction: their
//!   children are traced directly (same first hit for rays starting outside the solid).
//! * Shapes placed more than once (repetition, a mesh used twice) are built once as a
//!   bottom-level BVH and instanced under a top-level BVH with object-to-render transforms;
//!   everything placed once is flattened into one render-space BVH. Infinite repetition is
//!   bounded to the cells within `max_distance` of the camera (reported in the notes).
//! * Shading normals interpolate vertex normals with barycentrics where the surface has
//!   them (tessellations, meshes with normals), geometric normals otherwise.
//!
//! All data is in render space (world minus camera position, in f64 before converting to
//! f32), as the [`marchmesh_core::Geometry`] contract requires, except placements far from
//! the camera ([`marchmesh_core::FarFrame::of_box`]): those are instances in their own frame
//! whatever the instancing option, which rays enter through f64 (advanced to the placement's
//! bounding sphere, primary rays along their exact camera directions), so their triangles
//! are not rounded to the f32 grid out there.

mod blas;
mod budget;
mod build;
pub mod extract;
mod flat;
mod options;
// SIMD traversal: std::arch intrinsics behind runtime feature detection (each unsafe call
// states why the CPU feature is present); the only unsafe code besides the counting allocator.
#[allow(unsafe_code)]
mod packet;
mod pipeline;
mod settings;
pub mod tessellate;
#[allow(unsafe_code)]
mod wide;

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use glam::{Affine3A, DAffine3, DVec3, Vec3, Vec3A};
use marchmesh_core::{
    FarFrame, FrameEntry, Geometry, GeometryReport, Hit, NoHit, OcclusionResult, PrimarySamples,
    Ray, RayWork, RenderSpace, Termination, TraceResult,
};
use marchmesh_meshio::MeshLoadError;
use marchmesh_scene::{MaterialId, Scene};
use obvhs::ray::Ray as ObRay;

use blas::{Blas, BlasHit, Tree};
use pipeline::{Assembled, ShapeInputs, describe, group_by_shape, load_meshes};

pub use extract::MAX_SURFACE_RESOLUTION;
pub use options::{
    BUILD_BYTES_PER_TRIANGLE, BuildQuality, BvhKind, Extraction, MAX_SEGMENTS_PER_TURN,
    MAX_TESS_LEVEL, MeshOptions, MeshPreset, Tessellation,
};
pub use settings::MeshBackend;

/// Why the mesh backend could not build a scene.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// A mesh file could not be loaded (the message names the file and the reason).
    #[error("{json_path}: {source}")]
    Load {
        /// The scene object that uses the mesh.
        json_path: String,
        /// What went wrong.
        source: MeshLoadError,
    },
    /// The scene uses something this backend cannot turn into triangles.
    #[error("{json_path}: not supported by the mesh backend: {reason}")]
    Unsupported {
        /// The offending object.
        json_path: String,
        /// Why.
        reason: String,
    },
    /// A repetition places more copies than `MeshOptions::max_instances`: a finite one by its
    /// counts, an infinite one by the cells within `max_distance` of the camera.
    #[error(
        "{json_path}: {} would need {cells} cells{} (limit {limit}); {} or raise max_instances",
        if *infinite { "infinite repetition" } else { "finite repetition" },
        if *infinite { " within max_distance" } else { " by its counts" },
        if *infinite { "lower render.max_distance" } else { "lower its counts" }
    )]
    TooManyInstances {
        /// The repeat node.
        json_path: String,
        /// Cells needed.
        cells: u64,
        /// The limit.
        limit: u64,
        /// Whether some repeated axis has no count (cells counted within `max_distance`).
        infinite: bool,
    },
    /// The build would need more memory than [`MeshOptions::memory_limit_bytes`]; refused
    /// before allocating it.
    #[error(
        "{json_path}: {what} would bring the mesh backend's build to about {needed_mib} MiB, over the memory limit of {limit_mib} MiB; raise --memory-limit-mib or coarsen {knob}"
    )]
    OverMemoryLimit {
        /// The object whose geometry crossed the limit.
        json_path: String,
        /// What was about to be built (e.g. "16433316 triangles of tessellation").
        what: String,
        /// Estimated build memory including this object, MiB (rounded up).
        needed_mib: u64,
        /// The limit, MiB.
        limit_mib: u64,
        /// The option that controls this object's size.
        knob: &'static str,
    },
    /// An option is out of range.
    #[error("invalid mesh backend option: {0}")]
    InvalidOption(String),
}

/// One placement of a BLAS: the render-to-local transform, the fallback material and, for a
/// placement far from the camera, its frame.
#[derive(Debug, Clone, Copy)]
struct Instance {
    to_local: Affine3A,
    blas: u32,
    material: MaterialId,
    /// Index of its [`FarInstance`], or [`NEAR`] for an instance rays enter in f32.
    far: u32,
}

/// [`Instance::far`] of an instance near the camera (rays enter it through `to_local`).
const NEAR: u32 = u32::MAX;

/// A placement far from the camera: rays enter its BLAS's frame through f64
/// ([`FarFrame::enter`], then `to_local` in f64), so its triangles are intersected near the
/// frame's origin in f32 however far the placement is from the camera.
#[derive(Debug, Clone, Copy)]
struct FarInstance {
    frame: FarFrame,
    to_local: DAffine3,
}

/// Where a closest hit was found.
#[derive(Debug, Clone, Copy)]
enum HitSource {
    Flat,
    Instance(u32),
}

/// Wide BVH size (nodes and triangle blocks, bytes) above which [`Geometry::closest_hits`]
/// traces its batches as interleaved single rays ([`wide::WideBvh::closest_interleaved`])
/// instead of packets or one ray after another. Interleaving hides the cache misses of a
/// tree far larger than the caches but costs bookkeeping on a cached one. Measured: `docs/decisions/0013`.
const INTERLEAVE_MIN_BYTES: u64 = 16 << 20;

/// The built mesh backend: a render-space BVH of everything placed once, plus instanced
/// BLASes under a TLAS. Implements [`Geometry`].
#[derive(Clone)]
pub struct MeshGeometry {
    flat: Option<Blas>,
    flat_materials_default: MaterialId,
    packets: bool,
    /// Whether batches are traced as interleaved single rays (a flat wide BVH larger than
    /// [`INTERLEAVE_MIN_BYTES`], no instances).
    interleave: bool,
    blases: Vec<Blas>,
    instances: Vec<Instance>,
    far_instances: Vec<FarInstance>,
    tlas: Option<Tree>,
    max_distance: f32,
    report: GeometryReport,
}

/// Builds the mesh representation of `scene`.
///
/// Errors: an unreadable or invalid mesh file, an infinite repetition of an unbounded
/// child or with more cells than `options.max_instances`, a CSG object when the distance
/// field cannot be evaluated, or an out-of-range option.
pub fn build(scene: &Scene, options: &MeshOptions) -> Result<MeshGeometry, MeshError> {
    check_options(options)?;
    let mut report = GeometryReport {
        backend: <MeshBackend as marchmesh_core::Backend>::NAME.into(),
        ..GeometryReport::default()
    };
    let space = RenderSpace::of(scene);

    // Phase 1: load every mesh file once.
    let t0 = Instant::now();
    let meshes = load_meshes(scene, &mut report)?;
    let mesh_bounds: HashMap<PathBuf, (DVec3, DVec3)> = meshes
        .iter()
        .map(|(p, m)| {
            let (lo, hi) = m.bounds();
            (p.clone(), (lo.as_dvec3(), hi.as_dvec3()))
        })
        .collect();
    let load_ms = ms(t0.elapsed());

    // Phase 2: walk the scene, group placements by shape, make each shape's triangles.
    let t1 = Instant::now();
    let walk = build::walk(scene, options, space.from_world(), &mesh_bounds)?;
    report.notes.extend(walk.notes.iter().cloned());
    let groups = group_by_shape(&walk.placements);
    let shapes = ShapeInputs {
        scene,
        options,
        meshes: &meshes,
        mesh_bounds: &mesh_bounds,
    };
    let (local_meshes, extract_time) =
        shapes.triangulate(&groups, walk.placements.len(), &mut report)?;
    let tessellate_ms = ms(t1.elapsed().saturating_sub(extract_time));
    let extract_ms = ms(extract_time);

    // Phase 3: assemble flat and instanced geometry and build the BVHs.
    let t2 = Instant::now();
    let built = shapes.assemble(&groups, &local_meshes, &walk, &mut report);
    let bvh_ms = ms(t2.elapsed());
    report.build_phases_ms = vec![
        ("load".into(), load_ms),
        ("tessellate".into(), tessellate_ms),
        ("extract".into(), extract_ms),
        ("bvh".into(), bvh_ms),
    ];
    describe(&built, &walk, options, &mut report);
    let Assembled {
        flat_blas,
        flat_material,
        blases,
        instances,
        far_instances,
        tlas,
        ..
    } = built;
    let interleave = tlas.is_none()
        && flat_blas
            .as_ref()
            .and_then(Blas::wide)
            .is_some_and(|w| w.memory_bytes() > INTERLEAVE_MIN_BYTES);
    if interleave {
        report.notes.push(format!(
            "the wide BVH exceeds {} MiB: batches are traced as {} interleaved single rays",
            INTERLEAVE_MIN_BYTES >> 20,
            wide::INTERLEAVE
        ));
    }
    Ok(MeshGeometry {
        flat: flat_blas,
        flat_materials_default: flat_material,
        packets: options.packets(),
        interleave,
        blases,
        instances,
        far_instances,
        tlas,
        max_distance: scene.render.max_distance as f32,
        report,
    })
}

fn check_options(o: &MeshOptions) -> Result<(), MeshError> {
    match o.tessellation()? {
        Tessellation::ScreenError { pixels } if !(pixels.is_finite() && pixels > 0.0) => {
            return Err(MeshError::InvalidOption(format!(
                "tess_px must be a finite number of pixels > 0, got {pixels}"
            )));
        }
        Tessellation::ChordError { world } if !(world > 0.0 && world.is_finite()) => {
            return Err(MeshError::InvalidOption(format!(
                "tess_chord must be a finite length in world units > 0, got {world}"
            )));
        }
        Tessellation::FixedLevel(l) if l > MAX_TESS_LEVEL => {
            return Err(MeshError::InvalidOption(format!(
                "tess_level must be in 0..={MAX_TESS_LEVEL}, got {l}"
            )));
        }
        _ => {}
    }
    match o.extraction()? {
        Extraction::Cells(cells) if !(8..=extract::MAX_SURFACE_RESOLUTION).contains(&cells) => {
            return Err(MeshError::InvalidOption(format!(
                "surface_res must be in 8..={}, got {cells}",
                extract::MAX_SURFACE_RESOLUTION,
            )));
        }
        Extraction::ScreenCell { pixels } if !(pixels.is_finite() && pixels > 0.0) => {
            return Err(MeshError::InvalidOption(format!(
                "surface_px must be > 0, got {pixels}"
            )));
        }
        _ => {}
    }
    if !(8..=MAX_SEGMENTS_PER_TURN).contains(&o.max_segments_per_turn()) {
        return Err(MeshError::InvalidOption(format!(
            "max_segments_per_turn must be in 8..={MAX_SEGMENTS_PER_TURN}, got {}",
            o.max_segments_per_turn()
        )));
    }
    Ok(())
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

impl std::fmt::Debug for MeshGeometry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MeshGeometry")
            .field("triangles", &self.triangle_count())
            .field("blases", &self.blases.len())
            .field("instances", &self.instances.len())
            .field("memory_bytes", &self.report.memory_bytes)
            .finish()
    }
}

impl MeshGeometry {
    /// Distinct triangles held (flat plus one copy per BLAS).
    pub fn triangle_count(&self) -> u64 {
        (self.flat.as_ref().map_or(0, |b| b.triangle_count)
            + self.blases.iter().map(|b| b.triangle_count).sum::<usize>()) as u64
    }

    /// Number of instances under the TLAS.
    pub fn instance_count(&self) -> usize {
        self.instances.len()
    }

    #[inline(always)]
    fn ob_ray(&self, ray: &Ray) -> ObRay {
        ob_ray_new(
            Vec3A::from(ray.origin),
            Vec3A::from(ray.dir),
            ray.t_min,
            ray.t_max.min(self.max_distance),
        )
    }

    fn local_ray(inst: &Instance, r: &ObRay) -> ObRay {
        ObRay::new(
            inst.to_local.transform_point3a(r.origin),
            inst.to_local.transform_vector3a(r.direction),
            r.tmin,
            r.tmax,
        )
    }

    /// The ray `r` (direction `dir` in f64: the exact camera direction of a primary ray, else
    /// `r`'s) in the frame of far instance `fi`, started where it enters the instance's
    /// bounding sphere, with that start's render-space ray parameter; `None` when it misses
    /// the sphere within its interval. Its parameter is render-space length from the start.
    fn far_local_ray(fi: &FarInstance, r: &ObRay, dir: DVec3) -> Option<(ObRay, FrameEntry)> {
        let e = fi.frame.enter(Vec3::from(r.origin), dir, r.tmin, r.tmax)?;
        let origin = fi.to_local.transform_point3(e.start).as_vec3();
        let direction = fi.to_local.transform_vector3(dir).as_vec3();
        Some((
            ObRay::new(origin.into(), direction.into(), e.t_min, e.t_max),
            e,
        ))
    }
}

/// `obvhs::ray::Ray::new(origin, direction, tmin, tmax)`, bit for bit, with the inverse
/// direction computed on the 3 lanes at once (one vector division and a select) instead of
/// obvhs' `safe_inverse` branch per axis: `|x| <= EPSILON` gives `signum(x) / EPSILON`,
/// which is `copysign(2^23, x)` exactly; every other `x` gives `1 / x`.
#[inline(always)]
fn ob_ray_new(origin: Vec3A, direction: Vec3A, tmin: f32, tmax: f32) -> ObRay {
    let small = direction.abs().cmple(Vec3A::splat(f32::EPSILON));
    let clamped = Vec3A::splat(1.0 / f32::EPSILON).copysign(direction);
    ObRay {
        origin,
        direction,
        inv_direction: Vec3A::select(small, clamped, Vec3A::ONE / direction),
        tmin,
        tmax,
    }
}

impl MeshGeometry {
    /// Closest hits of 8 rays of a batch as one packet through the flat wide BVH; `false`
    /// (nothing written) when packets are off, the scene has instances, the flat BVH is not
    /// wide, or the rays do not share an origin.
    fn closest_packet(&self, rays: &[Ray], out: &mut [TraceResult]) -> bool {
        let (true, Some(flat), None) = (self.packets, &self.flat, &self.tlas) else {
            return false;
        };
        let (Some(wide), Ok(rays8), true) = (
            flat.wide(),
            <&[Ray; packet::PACKET]>::try_from(rays),
            out.len() == packet::PACKET,
        ) else {
            return false;
        };
        // Incoherent rays (bounces, reflections) rarely share their origin: find out before
        // converting eight rays that the fallback converts again.
        let origin = rays8[0].origin.to_array().map(f32::to_bits);
        if rays8
            .iter()
            .any(|r| r.origin.to_array().map(f32::to_bits) != origin)
        {
            return false;
        }
        let mut r: [ObRay; packet::PACKET] = std::array::from_fn(|k| self.ob_ray(&rays8[k]));
        if r.iter().any(|r| r.tmax.is_nan() || r.tmax < r.tmin) {
            return false;
        }
        let mut visits = 0;
        let mut tests = [0; packet::PACKET];
        let Some(best) = packet::closest8(wide, &mut r, &mut visits, &mut tests) else {
            return false;
        };
        for k in 0..packet::PACKET {
            let work = RayWork {
                node_visits: visits.div_ceil(packet::PACKET as u32),
                primitive_tests: tests[k],
                ..RayWork::default()
            };
            out[k] = match best[k] {
                Some((prim, t)) => {
                    let hit = BlasHit { t, prim };
                    TraceResult::found(
                        Hit {
                            t,
                            position: rays8[k].origin + rays8[k].dir * t,
                            normal: flat.normal(&r[k], &hit),
                            material: flat.material(&hit).unwrap_or(self.flat_materials_default),
                        },
                        work,
                    )
                }
                None => TraceResult::not_found(NoHit::Miss, work),
            };
        }
        true
    }
}

impl MeshGeometry {
    /// Closest hits of a batch (a multiple of [`wide::INTERLEAVE`] rays) traced in turns
    /// through the flat wide BVH ([`wide::WideBvh::closest_interleaved`]), each hit exactly
    /// the single-ray hit; `false` (nothing written) unless interleaving is on for this
    /// geometry (see [`INTERLEAVE_MIN_BYTES`]) and the batch fits.
    fn closest_interleaved(&self, rays: &[Ray], out: &mut [TraceResult]) -> bool {
        let (true, Some(flat), None) = (self.interleave, &self.flat, &self.tlas) else {
            return false;
        };
        let Some(wide) = flat.wide() else {
            return false;
        };
        if rays.len() != out.len() || !rays.len().is_multiple_of(wide::INTERLEAVE) {
            return false;
        }
        for (rays, out) in rays
            .chunks_exact(wide::INTERLEAVE)
            .zip(out.chunks_exact_mut(wide::INTERLEAVE))
        {
            let Ok(rays) = <&[Ray; wide::INTERLEAVE]>::try_from(rays) else {
                return false;
            };
            let mut r: [ObRay; wide::INTERLEAVE] = std::array::from_fn(|k| self.ob_ray(&rays[k]));
            // A ray with an empty interval is not traced (as in `closest_hit`): tmax = -inf
            // enters no box and passes no triangle test.
            let empty = r.map(|r| r.tmax.is_nan() || r.tmax < r.tmin);
            for (ray, &e) in r.iter_mut().zip(&empty) {
                if e {
                    ray.tmax = f32::NEG_INFINITY;
                }
            }
            let mut work = [RayWork::default(); wide::INTERLEAVE];
            let best = wide.closest_interleaved(&mut r, &mut work);
            for k in 0..wide::INTERLEAVE {
                out[k] = match (best[k], empty[k]) {
                    (_, true) => TraceResult::not_found(NoHit::Miss, RayWork::default()),
                    (None, false) => TraceResult::not_found(NoHit::Miss, work[k]),
                    (Some((prim, t)), false) => {
                        let hit = BlasHit { t, prim };
                        TraceResult::found(
                            Hit {
                                t,
                                position: rays[k].origin + rays[k].dir * t,
                                normal: flat.normal(&r[k], &hit),
                                material: flat
                                    .material(&hit)
                                    .unwrap_or(self.flat_materials_default),
                            },
                            work[k],
                        )
                    }
                };
            }
        }
        true
    }
}

impl MeshGeometry {
    /// [`MeshGeometry::closest_with`] for a scene without instances (no TLAS): the flat
    /// BVH's closest hit alone, with the same ray, hit and work as the general form but
    /// none of its instance bookkeeping (its frame, its far-instance ray, its TLAS
    /// traversal). Measured: `docs/decisions/0027`.
    #[inline]
    fn closest_flat(&self, ray: &Ray) -> TraceResult {
        let mut work = RayWork::default();
        let mut r = self.ob_ray(ray);
        if r.tmax.is_nan() || r.tmax < r.tmin {
            return TraceResult::not_found(NoHit::Miss, work);
        }
        let Some(flat) = &self.flat else {
            return TraceResult::not_found(NoHit::Miss, work);
        };
        let Some(hit) = flat.closest(&mut r, &mut work) else {
            return TraceResult::not_found(NoHit::Miss, work);
        };
        let t = r.tmax;
        TraceResult::found(
            Hit {
                t,
                position: ray.origin + ray.dir * t,
                normal: flat.normal(&r, &hit),
                material: flat.material(&hit).unwrap_or(self.flat_materials_default),
            },
            work,
        )
    }

    /// The closest hit of `ray`; far instances are entered along `exact_dir` when given (the
    /// exact camera direction `ray.dir` was rounded from), else along `ray.dir`.
    #[inline]
    fn closest_with(&self, ray: &Ray, exact_dir: Option<DVec3>) -> TraceResult {
        let mut work = RayWork::default();
        let mut r = self.ob_ray(ray);
        if r.tmax.is_nan() || r.tmax < r.tmin {
            return TraceResult::not_found(NoHit::Miss, work);
        }
        let mut best: Option<(HitSource, BlasHit)> = None;
        // The local ray of the last far instance hit (its hit's `t` is measured in it).
        let mut far_local: Option<ObRay> = None;
        if let Some(flat) = &self.flat
            && let Some(h) = flat.closest(&mut r, &mut work)
        {
            best = Some((HitSource::Flat, h));
        }
        if let Some(tlas) = &self.tlas {
            let mut inner = RayWork::default();
            let prims = tlas.primitive_indices();
            tlas.traverse(&mut r, &mut work, |r, slot| {
                let Some(&i) = prims.get(slot as usize) else {
                    return true;
                };
                let inst = &self.instances[i as usize];
                let blas = &self.blases[inst.blas as usize];
                if inst.far == NEAR {
                    let mut local = Self::local_ray(inst, r);
                    if let Some(h) = blas.closest(&mut local, &mut inner) {
                        r.tmax = h.t;
                        best = Some((HitSource::Instance(i), h));
                    }
                } else if let Some((mut local, e)) = Self::far_local_ray(
                    &self.far_instances[inst.far as usize],
                    r,
                    exact_dir.unwrap_or_else(|| Vec3::from(r.direction).as_dvec3()),
                ) && let Some(h) = blas.closest(&mut local, &mut inner)
                {
                    let t = e.render_t(h.t);
                    if t <= r.tmax {
                        r.tmax = t;
                        best = Some((HitSource::Instance(i), h));
                        far_local = Some(local);
                    }
                }
                true
            });
            work.node_visits += inner.node_visits;
            work.primitive_tests += inner.primitive_tests;
        }
        let Some((source, hit)) = best else {
            return TraceResult::not_found(NoHit::Miss, work);
        };
        let t = r.tmax;
        let (normal, material) = match source {
            HitSource::Flat => match &self.flat {
                Some(flat) => (
                    flat.normal(&r, &hit),
                    flat.material(&hit).unwrap_or(self.flat_materials_default),
                ),
                None => (Vec3::Z, 0),
            },
            HitSource::Instance(i) => {
                let inst = &self.instances[i as usize];
                let blas = &self.blases[inst.blas as usize];
                let local = match far_local {
                    Some(local) if inst.far != NEAR => local,
                    _ => Self::local_ray(inst, &r),
                };
                let n_local = Vec3A::from(blas.normal(&local, &hit));
                let n = inst.to_local.matrix3.transpose() * n_local;
                (
                    Vec3::from(n).try_normalize().unwrap_or(Vec3::Z),
                    blas.material(&hit).unwrap_or(inst.material),
                )
            }
        };
        TraceResult::found(
            Hit {
                t,
                position: ray.origin + ray.dir * t,
                normal,
                material,
            },
            work,
        )
    }
}

impl Geometry for MeshGeometry {
    /// 64 columns: the same packets (8 consecutive pixels of a tile row start at multiples
    /// of 8 either way) with an eighth of the integrator's fixed cost per tile. Measured: `docs/decisions/0013`.
    fn tile_width(&self) -> u32 {
        64
    }

    /// Traces 8 consecutive rays at a time: interleaved single rays on a large flat wide
    /// BVH (above 16 MiB), else as a packet where packets are on and the
    /// scene allows it (flat wide BVH, shared origin), else one by one; same hits either
    /// way (a packet may break an exact tie between two triangles differently).
    fn closest_hits(&self, rays: &[Ray], out: &mut [TraceResult]) {
        assert_eq!(
            rays.len(),
            out.len(),
            "closest_hits: rays and out differ in length"
        );
        for (rs, os) in rays
            .chunks(packet::PACKET)
            .zip(out.chunks_mut(packet::PACKET))
        {
            if !self.closest_interleaved(rs, os) && !self.closest_packet(rs, os) {
                for (r, o) in rs.iter().zip(os.iter_mut()) {
                    *o = self.closest_hit(r);
                }
            }
        }
    }

    fn closest_hit(&self, ray: &Ray) -> TraceResult {
        match self.tlas {
            None => self.closest_flat(ray),
            Some(_) => self.closest_with(ray, None),
        }
    }

    /// With far instances, primary rays enter them along their exact f64 directions.
    fn closest_hits_primary(
        &self,
        rays: &[Ray],
        samples: PrimarySamples<'_>,
        out: &mut [TraceResult],
    ) {
        if self.far_instances.is_empty() {
            return self.closest_hits(rays, out);
        }
        assert_eq!(
            rays.len(),
            out.len(),
            "closest_hits_primary: rays and out differ in length"
        );
        for (i, (r, o)) in rays.iter().zip(out.iter_mut()).enumerate() {
            *o = self.closest_with(r, Some(samples.direction(i)));
        }
    }

    fn occluded(&self, ray: &Ray) -> OcclusionResult {
        match self.tlas {
            None => self.occluded_flat(ray),
            Some(_) => self.occluded_with_instances(ray),
        }
    }

    fn report(&self) -> GeometryReport {
        self.report.clone()
    }
}

/// An occlusion query's answer from its outcome and work.
#[inline(always)]
fn occlusion(occluded: bool, work: RayWork) -> OcclusionResult {
    OcclusionResult {
        occluded,
        termination: if occluded {
            Termination::Hit
        } else {
            Termination::Miss
        },
        work,
    }
}

impl MeshGeometry {
    /// [`Geometry::occluded`] for a scene without instances: the flat BVH's any-hit query
    /// alone (the same ray, answer and work as [`MeshGeometry::occluded_with_instances`]).
    #[inline]
    fn occluded_flat(&self, ray: &Ray) -> OcclusionResult {
        let mut work = RayWork::default();
        let mut r = self.ob_ray(ray);
        let occluded = r.tmax >= r.tmin
            && match &self.flat {
                Some(flat) => flat.any(&mut r, &mut work),
                None => false,
            };
        occlusion(occluded, work)
    }

    /// [`Geometry::occluded`] in general: the flat BVH, then the instances under the TLAS.
    fn occluded_with_instances(&self, ray: &Ray) -> OcclusionResult {
        let mut work = RayWork::default();
        let mut r = self.ob_ray(ray);
        let mut occluded = false;
        if r.tmax >= r.tmin {
            if let Some(flat) = &self.flat {
                occluded = flat.any(&mut r, &mut work);
            }
            if !occluded && let Some(tlas) = &self.tlas {
                let mut inner = RayWork::default();
                let prims = tlas.primitive_indices();
                tlas.traverse(&mut r, &mut work, |r, slot| {
                    let Some(&i) = prims.get(slot as usize) else {
                        return true;
                    };
                    let inst = &self.instances[i as usize];
                    let local = if inst.far == NEAR {
                        Some(Self::local_ray(inst, r))
                    } else {
                        Self::far_local_ray(
                            &self.far_instances[inst.far as usize],
                            r,
                            Vec3::from(r.direction).as_dvec3(),
                        )
                        .map(|(local, _)| local)
                    };
                    if let Some(mut local) = local
                        && self.blases[inst.blas as usize].any(&mut local, &mut inner)
                    {
                        occluded = true;
                        return false;
                    }
                    true
                });
                work.node_visits += inner.node_visits;
                work.primitive_tests += inner.primitive_tests;
            }
        }
        occlusion(occluded, work)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_extraction_options_are_refused_naming_the_key() {
        for (options, key) in [
            (
                MeshOptions {
                    surface_px: Some(0.0),
                    ..MeshOptions::default()
                },
                "surface_px",
            ),
            (
                MeshOptions {
                    surface_px: Some(-1.0),
                    ..MeshOptions::default()
                },
                "surface_px",
            ),
            (
                MeshOptions {
                    surface_px: Some(f64::NAN),
                    ..MeshOptions::default()
                },
                "surface_px",
            ),
            (
                MeshOptions {
                    surface_px: Some(f64::INFINITY),
                    ..MeshOptions::default()
                },
                "surface_px",
            ),
            (
                MeshOptions {
                    surface_res: Some(4),
                    ..MeshOptions::default()
                },
                "surface_res",
            ),
            (
                MeshOptions {
                    surface_res: Some(MAX_SURFACE_RESOLUTION + 1),
                    ..MeshOptions::default()
                },
                "surface_res",
            ),
            (
                MeshOptions {
                    surface_px: Some(1.0),
                    surface_res: Some(64),
                    ..MeshOptions::default()
                },
                "surface_px, surface_res",
            ),
        ] {
            let e = check_options(&options).expect_err(key).to_string();
            assert!(e.contains(key), "{options:?}: {e}");
        }
        // Tessellation keys too, with the accepted range, never the internal variant names.
        for (options, expected) in [
            (
                MeshOptions {
                    tess_level: Some(MAX_TESS_LEVEL + 1),
                    ..MeshOptions::default()
                },
                "tess_level must be in 0..=12",
            ),
            (
                MeshOptions {
                    tess_chord: Some(0.0),
                    ..MeshOptions::default()
                },
                "tess_chord must be",
            ),
            (
                MeshOptions {
                    tess_px: Some(0.0),
                    ..MeshOptions::default()
                },
                "tess_px must be",
            ),
        ] {
            let e = check_options(&options).expect_err(expected).to_string();
            assert!(e.contains(expected), "{options:?}: {e}");
        }
        check_options(&MeshOptions {
            surface_px: Some(0.5),
            ..MeshOptions::default()
        })
        .expect("valid");
    }

    /// A hit's distance, position and normal as bits, and its material.
    type HitBits = (u32, [u32; 3], [u32; 3], MaterialId);

    /// A closest-hit answer with every float as bits, so `-0.0` and `0.0` (or two NaNs)
    /// compare as what they are.
    fn trace_bits(r: &TraceResult) -> (Option<HitBits>, String) {
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        (
            r.hit()
                .map(|h| (h.t.to_bits(), bits(h.position), bits(h.normal), h.material)),
            format!("{:?}", (r.termination(), r.work)),
        )
    }

    #[test]
    fn flat_ray_path_answers_every_ray_as_the_general_path() {
        // `closest_flat` and `occluded_flat` (scenes without instances) repeat the flat part
        // of `closest_with` and `occluded_with_instances`: for the same ray, both must give
        // the same hit (distance, position, normal and material bit for bit), the same
        // termination and work, and the same occlusion, on every BVH layout. Random rays
        // around a bunny in all eight direction octants: from the camera's origin, from
        // points around and inside the mesh's box, long and short (AO-like), a nonzero
        // `t_min`, axis-aligned directions and empty intervals.
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
        let json = r#"{"camera": {"position": [0, 2, -5.5], "look_at": [0, 1.2, 0], "vfov_deg": 40, "width": 64, "height": 64},
            "objects": [{"shape": {"mesh": {"path": "meshes/bunny.obj"}}, "transform": {"scale": 0.25, "rotate_deg": [0, 30, 0]}}]}"#;
        let scene = marchmesh_scene::parse_scene(json, "bunny", &dir).expect("scene");
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut unit = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut rays = Vec::new();
        for k in 0..6000 {
            let around = Vec3::new(unit(), unit(), unit()) * 4.0 - 2.0;
            // The bunny sits about 5.5 units in front of the camera (render space is
            // centred on the camera).
            let target = Vec3::new(0.0, -0.6, 5.6) + (Vec3::new(unit(), unit(), unit()) - 0.5);
            let origin = match k % 3 {
                0 => Vec3::ZERO,
                1 => target + around,
                _ => Vec3::new(0.0, -0.6, 5.6) + around * 0.4,
            };
            let dir = match k % 5 {
                4 => (Vec3::new(unit(), unit(), unit()) * 2.0 - 1.0)
                    .try_normalize()
                    .unwrap_or(Vec3::X),
                _ => (target - origin).try_normalize().unwrap_or(Vec3::Z),
            };
            let (t_min, t_max) = match k % 7 {
                0 => (0.0, 0.3 * unit()),
                1 => (0.5 * unit(), 20.0),
                2 => (1.0, 0.5),
                _ => (0.0, f32::INFINITY),
            };
            rays.push(Ray {
                origin,
                dir,
                t_min,
                t_max,
            });
        }
        for d in [
            Vec3::X,
            Vec3::NEG_X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
        ] {
            for origin in [
                Vec3::ZERO,
                Vec3::new(0.0, -0.6, 5.6),
                Vec3::new(0.1, -0.5, 4.0),
            ] {
                rays.push(Ray {
                    origin: origin - d * 3.0,
                    dir: d,
                    t_min: 0.0,
                    t_max: f32::INFINITY,
                });
            }
        }
        for kind in [BvhKind::Wide, BvhKind::Bvh2, BvhKind::CwBvh] {
            let g = build(
                &scene,
                &MeshOptions {
                    bvh: Some(kind),
                    ..MeshOptions::default()
                },
            )
            .expect("build");
            assert!(g.tlas.is_none(), "one placement: no instances");
            let (mut hits, mut occluded, mut octants) = (0, 0, 0u32);
            for ray in &rays {
                let flat = g.closest_flat(ray);
                let general = g.closest_with(ray, None);
                assert_eq!(trace_bits(&flat), trace_bits(&general), "{kind:?} {ray:?}");
                let (a, b) = (g.occluded_flat(ray), g.occluded_with_instances(ray));
                assert_eq!(
                    (a.occluded, a.termination, a.work),
                    (b.occluded, b.termination, b.work),
                    "{kind:?} {ray:?}"
                );
                hits += usize::from(flat.hit().is_some());
                occluded += usize::from(a.occluded);
                let neg = ray.dir.cmplt(Vec3::ZERO).bitmask();
                octants |= 1 << neg;
            }
            assert!(
                hits > 1500,
                "{kind:?}: {hits} hits; the rays must reach the bunny"
            );
            assert!(
                occluded > hits / 2,
                "{kind:?}: {occluded} occluded of {hits}"
            );
            assert_eq!(octants, 0xff, "rays in every octant");
        }
    }

    #[test]
    fn ob_ray_new_is_bit_identical_to_obvhs_ray_new() {
        let eps = f32::EPSILON;
        let mut values = vec![
            0.0,
            -0.0,
            eps,
            -eps,
            eps * 0.5,
            -eps * 0.5,
            f32::from_bits(eps.to_bits() + 1),
            f32::MIN_POSITIVE,
            1e-30,
            1.0,
            -1.0,
            0.3,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ];
        let mut s = 12345u32;
        for _ in 0..2000 {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let v = f32::from_bits(s);
            if v.is_finite() {
                values.push(v);
            }
        }
        for w in values.windows(3) {
            let (o, d) = (Vec3A::new(1.0, -2.0, 3.0), Vec3A::new(w[0], w[1], w[2]));
            let (a, b) = (ob_ray_new(o, d, 0.5, 7.0), ObRay::new(o, d, 0.5, 7.0));
            let bits = |v: Vec3A| v.to_array().map(f32::to_bits);
            assert_eq!(bits(a.inv_direction), bits(b.inv_direction), "{d}");
            assert_eq!(bits(a.direction), bits(b.direction));
            assert_eq!(bits(a.origin), bits(b.origin));
            assert_eq!((a.tmin, a.tmax), (b.tmin, b.tmax));
        }
    }
}
