//! The exact reference backend: the ground truth every other backend is measured against.
//!
//! * Every computation is f64. Primary rays are traced as the exact f64 camera rays
//!   ([`Geometry::closest_hits_primary`] rebuilds them from the camera samples), so the
//!   ground truth is exact for the README's camera model, not for its f32 rounding (which
//!   turns an off-axis ray by ~2e-8 rad: hundreds of silhouette pixels at 1e6 units).
//!   Secondary rays arrive as the core's f32 render-space rays and are widened: exact *for
//!   the ray given*.
//! * Primitives are intersected in closed form in their local frames ([`primitives`]):
//!   sphere and ellipsoid by the perpendicular-distance quadratic, box and cylinder by
//!   slabs, plane as a half-space, triangle by Möller-Trumbore, torus by its quartic solved
//!   with derivative recursion and bisection ([`poly`]) to the last bit.
//! * CSG is exact: solids produce sorted span lists along the ray and union, intersection
//!   and subtraction combine them ([`spans`]).
//! * Repetition walks the cells the ray crosses (Amanatides-Woo) and tests every copy that
//!   can reach into each cell, so copies larger than their cell are still exact. The walk
//!   is bounded by [`ReferenceOptions::max_repeat_cells`]; running out is reported as
//!   `Termination::MaxSteps`, never drawn as a miss.
//! * Smooth unions have no closed form: their surface is the zero set of the shared f64
//!   field (`marchmesh-field`), found by sphere tracing in f64 and bisecting each sign change
//!   to the last bit. That one case is exact to root-finding precision
//!   ([`ReferenceOptions::smooth_union_tolerance`] of the object's size for features
//!   thinner than the minimum step).
//! * Meshes use an f64 median-split BVH only to prune candidates; every hit is decided by
//!   the f64 triangle test, edges inclusive (no ray slips between two triangles). Shading
//!   normals interpolate the file's vertex normals like the mesh backend does. Open meshes
//!   are surfaces; only closed ones may take part in intersection or subtraction.

mod compile;
pub mod meshbvh;
mod node;
pub mod poly;
pub mod primitives;
mod repeat;
mod smooth;
pub mod spans;

use std::collections::HashMap;
use std::time::Instant;

use glam::{DAffine3, DVec3};
use marchmesh_core::{
    Geometry, GeometryReport, Hit, NoHit, OcclusionResult, PrimarySamples, Ray, RayWork,
    RenderSpace, Termination, TraceResult,
};
use marchmesh_scene::Scene;

use compile::Compiler;
use node::{CompiledNode, Work, ray_box};

/// Why the reference cannot build a scene.
#[derive(Debug, thiserror::Error)]
pub enum ReferenceError {
    /// A mesh file could not be loaded (the reason names the file).
    #[error("{json_path}: {reason}")]
    Mesh {
        /// The mesh node.
        json_path: String,
        /// The loader's message.
        reason: String,
    },
    /// The scene uses something the reference cannot intersect exactly.
    #[error("{json_path}: not supported by the reference backend: {reason}")]
    Unsupported {
        /// The offending node.
        json_path: String,
        /// Why.
        reason: String,
    },
    /// An option is out of range.
    #[error("invalid reference option: {0}")]
    InvalidOption(String),
}

/// Options of the reference. The defaults make it exact for every committed scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceOptions {
    /// Largest number of repetition cells one ray may walk (each cell tests the copies that
    /// reach into it). Default 1,000,000. Running out ends the ray with `MaxSteps`.
    pub max_repeat_cells: u32,
    /// Smooth-union root tolerance and minimum march step, relative to the smooth union's
    /// bounding-box diagonal. Default 1e-9.
    pub smooth_union_tolerance: f64,
    /// Largest number of field evaluations per smooth-union query. Default 100,000.
    pub smooth_union_max_steps: u32,
    /// What the scene's meshes may take (default unlimited; the backend passes
    /// `--memory-limit-mib`): before each mesh file is read, and again before it is decoded,
    /// the meshes already loaded, the load's bound ([`marchmesh_meshio::LoadBound`]) and the
    /// f64 copy with its BVH ([`MESH_BYTES_PER_TRIANGLE`], [`MESH_BYTES_PER_VERTEX`]) must
    /// fit, else [`ReferenceError::Mesh`] refuses the mesh.
    pub memory_limit_bytes: u64,
}

/// Bytes per triangle of the reference's mesh for the memory estimate: indices, the BVH's
/// order, nodes and build centroids, and the closedness test's edge map.
pub const MESH_BYTES_PER_TRIANGLE: u64 = 160;

/// Bytes per vertex of the reference's mesh for the memory estimate: f64 positions and
/// normals and the closedness test's welding map.
pub const MESH_BYTES_PER_VERTEX: u64 = 80;

impl ReferenceOptions {
    /// The documented defaults.
    pub const DEFAULT: Self = Self {
        max_repeat_cells: 1_000_000,
        smooth_union_tolerance: 1e-9,
        smooth_union_max_steps: 100_000,
        memory_limit_bytes: u64::MAX,
    };
}

impl Default for ReferenceOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The built reference for one scene (in its render space).
#[derive(Debug)]
pub struct ReferenceGeometry {
    objects: Vec<CompiledNode>,
    report: GeometryReport,
}

/// Builds the reference for `scene`: loads meshes, compiles smooth-union fields, computes
/// bounds. Errors name the JSON path of the object at fault.
pub fn build(
    scene: &Scene,
    options: &ReferenceOptions,
) -> Result<ReferenceGeometry, ReferenceError> {
    if options.max_repeat_cells == 0
        || options.smooth_union_max_steps == 0
        || !(options.smooth_union_tolerance > 0.0 && options.smooth_union_tolerance < 1e-2)
    {
        return Err(ReferenceError::InvalidOption(format!(
            "max_repeat_cells and smooth_union_max_steps must be >= 1 and smooth_union_tolerance in (0, 0.01); got {options:?}"
        )));
    }
    let t0 = Instant::now();
    let from_world: DAffine3 = RenderSpace::of(scene).from_world();
    let mut compiler = Compiler {
        options,
        meshes: HashMap::new(),
        mesh_bytes: 0,
        notes: Vec::new(),
    };
    let objects = scene
        .objects
        .iter()
        .map(|o| compiler.compile(o, from_world))
        .collect::<Result<Vec<_>, _>>()?;
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let node_bytes = count_nodes(&scene.objects) * std::mem::size_of::<CompiledNode>() as u64;
    let report = GeometryReport {
        backend: <ReferenceBackend as marchmesh_core::Backend>::NAME.into(),
        triangles: None,
        memory_bytes: node_bytes + compiler.mesh_bytes,
        build_phases_ms: vec![("reference_build".into(), build_ms)],
        counters: vec![
            ("objects".into(), objects.len() as f64),
            ("meshes".into(), compiler.meshes.len() as f64),
        ],
        notes: compiler.notes,
    };
    Ok(ReferenceGeometry { objects, report })
}

fn count_nodes(nodes: &[marchmesh_scene::Node]) -> u64 {
    nodes.iter().map(|n| 1 + count_nodes(n.children())).sum()
}

/// A ray in f64: origin, unit direction, accepted `t` range.
#[derive(Debug, Clone, Copy)]
struct DRay {
    o: DVec3,
    d: DVec3,
    t_min: f64,
    t_max: f64,
}

impl DRay {
    /// The widened f32 ray.
    fn of(ray: &Ray) -> Self {
        Self {
            o: ray.origin.as_dvec3(),
            d: ray.dir.as_dvec3(),
            t_min: f64::from(ray.t_min),
            t_max: f64::from(ray.t_max),
        }
    }
}

impl ReferenceGeometry {
    fn trace(&self, ray: DRay) -> (Option<(f64, DVec3, u32)>, Work) {
        let DRay { o, d, t_min, t_max } = ray;
        let mut work = Work::default();
        let mut best: Option<(f64, DVec3, u32)> = None;
        if !(o.is_finite() && d.is_finite() && d != DVec3::ZERO && t_min <= t_max) {
            return (None, work);
        }
        for obj in &self.objects {
            let hi = best.map_or(t_max, |b| b.0);
            if let Some(b) = obj.bounds
                && ray_box(o, d, b, t_min, hi).is_none()
            {
                continue;
            }
            if let Some(h) = obj.closest(o, d, t_min, hi, &mut work)
                && best.is_none_or(|b| h.t < b.0)
            {
                best = Some((h.t, h.normal, h.material));
            }
        }
        (best, work)
    }
}

fn ray_work(w: &Work) -> RayWork {
    RayWork {
        steps: w.steps,
        node_visits: w.nodes,
        primitive_tests: w.tests,
    }
}

impl ReferenceGeometry {
    fn closest_hit_f64(&self, ray: DRay) -> TraceResult {
        let (best, work) = self.trace(ray);
        let hit = best.and_then(|(t, n, material)| {
            let normal = n.try_normalize()?;
            let p = ray.o + t * ray.d;
            Some(Hit {
                t: t as f32,
                position: p.as_vec3(),
                normal: normal.as_vec3(),
                material,
            })
        });
        match (hit, work.exhausted) {
            (Some(hit), _) => TraceResult::found(hit, ray_work(&work)),
            (None, true) => TraceResult::not_found(NoHit::MaxSteps, ray_work(&work)),
            (None, false) => TraceResult::not_found(NoHit::Miss, ray_work(&work)),
        }
    }
}

impl Geometry for ReferenceGeometry {
    fn closest_hit(&self, ray: &Ray) -> TraceResult {
        self.closest_hit_f64(DRay::of(ray))
    }

    /// Traces the exact f64 camera ray of each sample (same `t` range as the f32 ray).
    fn closest_hits_primary(
        &self,
        rays: &[Ray],
        samples: PrimarySamples<'_>,
        out: &mut [TraceResult],
    ) {
        assert_eq!(
            rays.len(),
            out.len(),
            "closest_hits_primary: rays and out differ in length"
        );
        for (i, (r, o)) in rays.iter().zip(out.iter_mut()).enumerate() {
            *o = self.closest_hit_f64(DRay {
                o: DVec3::ZERO,
                d: samples.direction(i),
                ..DRay::of(r)
            });
        }
    }

    fn occluded(&self, ray: &Ray) -> OcclusionResult {
        let (best, work) = self.trace(DRay::of(ray));
        OcclusionResult {
            occluded: best.is_some(),
            termination: match (best.is_some(), work.exhausted) {
                (true, _) => Termination::Hit,
                (false, true) => Termination::MaxSteps,
                (false, false) => Termination::Miss,
            },
            work: ray_work(&work),
        }
    }

    fn report(&self) -> GeometryReport {
        self.report.clone()
    }
}

/// `key=value` options of the reference backend: none (it is exact; its internal limits
/// are [`ReferenceOptions`] and stay at their defaults). Unknown keys are refused.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct ReferenceSettings {}

/// The reference backend: exact analytic f64 ray casting, the ground truth.
#[derive(Debug, Clone, Copy, Default)]
pub struct ReferenceBackend;

impl marchmesh_core::Backend for ReferenceBackend {
    const NAME: &'static str = "reference";
    const GROUND_TRUTH: bool = true;
    type Settings = ReferenceSettings;
    type Error = ReferenceError;
    type Geometry = ReferenceGeometry;

    /// The reference allocates in proportion to the scene's meshes: each is estimated
    /// against `memory_limit_bytes` before it is read ([`ReferenceOptions::memory_limit_bytes`]).
    fn build(
        scene: &Scene,
        _settings: &ReferenceSettings,
        memory_limit_bytes: u64,
    ) -> Result<ReferenceGeometry, ReferenceError> {
        build(
            scene,
            &ReferenceOptions {
                memory_limit_bytes,
                ..ReferenceOptions::DEFAULT
            },
        )
    }
}
