//! The one trait through which the core talks to geometry, and the ray and hit types.
//!
//! # Render space
//! Every ray handed to a [`Geometry`] is in *render space*: world space translated so that the
//! camera sits at the origin (no rotation, no scale). Backends build their data in render
//! space (subtract [`RenderSpace::origin`] in f64 before converting to f32), so f32 keeps its
//! precision near the camera however far the scene is from the world origin. Distances `t`
//! are world units along unit-length directions.

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_scene::{MaterialId, Scene};

use crate::camera::PrimarySamples;

/// How a render hands camera rays to a geometry ([`Geometry::batch_policy`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BatchPolicy {
    /// Tiles of [`crate::TILE_HEIGHT`] rows and [`Geometry::tile_width`] columns (at most
    /// [`crate::TILE_RAYS`] camera rays, [`crate::tile_width`]), bands of rows traced by
    /// every worker of the render's thread pool.
    #[default]
    Tiles,
    /// Tiles of the widest camera tile (64 columns) spanning every row of the image, traced
    /// one after another from the calling thread whatever the render's thread count: each
    /// wavefront holds `64 x height x samples` camera rays (and its shadow and reflection
    /// rays), for a geometry that spreads one batch over its own workers.
    Columns,
}

/// A ray in render space. `dir` is unit length; valid hits have `t_min <= t <= t_max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Origin, render space.
    pub origin: Vec3,
    /// Unit direction.
    pub dir: Vec3,
    /// Smallest accepted hit distance (>= 0).
    pub t_min: f32,
    /// Largest accepted hit distance.
    pub t_max: f32,
}

impl Ray {
    /// Point at distance `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// A surface hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the ray, world units.
    pub t: f32,
    /// Hit position, render space (a backend may compute it more precisely than `at(t)`).
    pub position: Vec3,
    /// Unit shading normal pointing out of the solid (for surfaces without an inside,
    /// either side); the integrator flips it to face the ray.
    pub normal: Vec3,
    /// Material of the surface hit.
    pub material: MaterialId,
}

/// Why a ray's traversal ended. Step exhaustion is a distinct outcome, never silently a miss.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[repr(u8)]
pub enum Termination {
    /// A surface was found within `[t_min, t_max]`.
    Hit = 0,
    /// Nothing was hit: the ray left the scene's bounds.
    #[default]
    Miss = 1,
    /// An iterative method ran out of steps before deciding (counted as no hit).
    MaxSteps = 2,
    /// The ray reached `t_max` or the backend's maximum distance without a hit.
    MaxDistance = 3,
}

/// Work done for one ray; backends fill what applies to them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RayWork {
    /// Distance-field evaluations (sphere-tracing steps, root-finding iterations).
    pub steps: u32,
    /// BVH nodes visited.
    pub node_visits: u32,
    /// Primitive (triangle, shape) intersection tests.
    pub primitive_tests: u32,
}

/// The result of a closest-hit query: it holds a hit exactly when its termination is
/// [`Termination::Hit`] (the constructors make any other combination unrepresentable).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[must_use]
pub struct TraceResult {
    hit: Option<Hit>,
    termination: Termination,
    /// Work done.
    pub work: RayWork,
}

/// How a closest-hit query ended without a hit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoHit {
    /// Nothing was hit: the ray left the scene's bounds.
    Miss,
    /// An iterative method ran out of steps before deciding.
    MaxSteps,
    /// The ray reached `t_max` or the backend's maximum distance without a hit.
    MaxDistance,
}

impl From<NoHit> for Termination {
    fn from(n: NoHit) -> Termination {
        match n {
            NoHit::Miss => Termination::Miss,
            NoHit::MaxSteps => Termination::MaxSteps,
            NoHit::MaxDistance => Termination::MaxDistance,
        }
    }
}

impl TryFrom<Termination> for NoHit {
    type Error = Termination;

    /// The no-hit reason of a termination; `Err(Termination::Hit)` for a hit.
    fn try_from(t: Termination) -> Result<NoHit, Termination> {
        match t {
            Termination::Hit => Err(t),
            Termination::Miss => Ok(NoHit::Miss),
            Termination::MaxSteps => Ok(NoHit::MaxSteps),
            Termination::MaxDistance => Ok(NoHit::MaxDistance),
        }
    }
}

impl TraceResult {
    /// A query that found `hit`.
    pub const fn found(hit: Hit, work: RayWork) -> TraceResult {
        TraceResult {
            hit: Some(hit),
            termination: Termination::Hit,
            work,
        }
    }

    /// A query that ended without a hit, for the reason `why`.
    pub fn not_found(why: NoHit, work: RayWork) -> TraceResult {
        TraceResult {
            hit: None,
            termination: why.into(),
            work,
        }
    }

    /// [`TraceResult::found`] for `Some`, a [`NoHit::Miss`] for `None`.
    pub fn found_or_miss(hit: Option<Hit>, work: RayWork) -> TraceResult {
        match hit {
            Some(h) => TraceResult::found(h, work),
            None => TraceResult::not_found(NoHit::Miss, work),
        }
    }

    /// The closest hit, if the query found one.
    pub fn hit(&self) -> Option<Hit> {
        self.hit
    }

    /// How the query ended.
    pub fn termination(&self) -> Termination {
        self.termination
    }
}

/// The result of an occlusion query.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OcclusionResult {
    /// Something lies within `[t_min, t_max]`. A query that ran out of steps counts as
    /// not occluded (and says so in `termination`).
    pub occluded: bool,
    /// How the query ended.
    pub termination: Termination,
    /// Work done.
    pub work: RayWork,
}

/// A cone from a surface point towards an area light, for one-query soft-shadow estimates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cone {
    /// Apex: the shading point moved off its surface, render space.
    pub origin: Vec3,
    /// Unit axis towards the light's centre.
    pub dir: Vec3,
    /// Distance to the light along the axis; nothing farther blocks it.
    pub t_max: f32,
    /// Tangent of the half angle the light subtends at the apex (> 0).
    pub tan_half_angle: f32,
}

/// A surface point for few-tap ambient-occlusion estimates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    /// The point moved off its surface, render space.
    pub position: Vec3,
    /// Unit normal facing the side the point was seen from.
    pub normal: Vec3,
}

/// An approximate visibility from one query.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Visibility {
    /// Unblocked fraction in [0, 1].
    pub fraction: f32,
    /// How the query ended.
    pub termination: Termination,
    /// Work done.
    pub work: RayWork,
}

/// Approximate queries a geometry answers in one query where other representations need
/// many rays (a distance field gives cone visibility from one march). The integrator uses a
/// shortcut only when the geometry offers it; otherwise it samples rays.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Shortcuts {
    /// [`Geometry::cone_visibility`] estimates soft shadows of area lights.
    pub cone_shadows: bool,
    /// [`Geometry::ambient_openness`] estimates ambient occlusion.
    pub ambient_occlusion: bool,
}

/// What a built geometry holds and what building it cost, for reports.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GeometryReport {
    /// Backend name, e.g. `"sdf"`.
    pub backend: String,
    /// Exact bytes of the representation (counted from lengths, not capacities).
    pub memory_bytes: u64,
    /// Build phases in order with their wall time in milliseconds (e.g. `("bvh_build", 3.2)`).
    pub build_phases_ms: Vec<(String, f64)>,
    /// Triangles stored by the representation (each instanced triangle once), for backends
    /// that trace triangles; `None` for the others. The harness's `triangles` column.
    pub triangles: Option<u64>,
    /// Named counts for diagnostics (e.g. `("grid_cells", 262144.0)`); columns read typed
    /// fields such as [`GeometryReport::triangles`], never these names.
    pub counters: Vec<(String, f64)>,
    /// Human-readable notes on conversions and approximations made (e.g. "plane clipped to
    /// a 2000-unit quad", "mesh is open: sign from generalized winding number").
    pub notes: Vec<String>,
}

/// Geometry that rays can be traced against. Implementations never shade.
///
/// The batch methods exist so a backend can trace rays together (packets, lockstep sphere
/// tracing); their default implementations loop over the single-ray methods. `out` has the
/// same length as `rays`; implementations may panic if it does not (a programming error).
/// They must write every element of `out`: the integrator reuses its result buffers from
/// one wavefront to the next without clearing them.
pub trait Geometry: Send + Sync {
    /// The closest hit within `[ray.t_min, ray.t_max]`.
    fn closest_hit(&self, ray: &Ray) -> TraceResult;

    /// Whether anything lies within `[ray.t_min, ray.t_max]`; may stop at the first hit.
    fn occluded(&self, ray: &Ray) -> OcclusionResult;

    /// [`Geometry::closest_hit`] for many rays.
    fn closest_hits(&self, rays: &[Ray], out: &mut [TraceResult]) {
        assert_eq!(
            rays.len(),
            out.len(),
            "closest_hits: rays and out differ in length"
        );
        for (r, o) in rays.iter().zip(out.iter_mut()) {
            *o = self.closest_hit(r);
        }
    }

    /// [`Geometry::closest_hits`] for one screen tile's primary rays, with the camera samples
    /// they were rounded from: `rays[i]` is the f32 rounding of the exact camera ray
    /// `samples.direction(i)` from the origin (`samples.pixel(i)` names its pixel and sample). The default ignores `samples` (an f32 backend
    /// pays nothing); a backend that computes in f64 (the reference) overrides it to trace the
    /// exact camera rays, so ground truth is exact for the camera model, not for its rounding.
    fn closest_hits_primary(
        &self,
        rays: &[Ray],
        samples: PrimarySamples<'_>,
        out: &mut [TraceResult],
    ) {
        let _ = samples;
        self.closest_hits(rays, out);
    }

    /// [`Geometry::occluded`] for many rays.
    fn occluded_many(&self, rays: &[Ray], out: &mut [OcclusionResult]) {
        assert_eq!(
            rays.len(),
            out.len(),
            "occluded_many: rays and out differ in length"
        );
        for (r, o) in rays.iter().zip(out.iter_mut()) {
            *o = self.occluded(r);
        }
    }

    /// Memory, build phases and counts of the built representation.
    fn report(&self) -> GeometryReport;

    /// Columns of the screen tiles whose camera rays this geometry would take as one batch
    /// (`TILE_HEIGHT` rows each); the integrators cap it ([`crate::tile_width`]) so a tile
    /// holds at most `TILE_RAYS` camera rays. Wider tiles spread the integrator's fixed
    /// cost per tile (camera terms, the clock reads around each batch query, the miss
    /// pass's setup) over more rays, but a wavefront spread over more pixels also reads
    /// more of the scene's data between a camera ray and its shadow rays. The default is
    /// `TILE_WIDTH` (8); an implementation returns what measures best for it. Rays, results
    /// and images do not depend on it except where a backend's results depend on its
    /// batching.
    fn tile_width(&self) -> u32 {
        crate::TILE_WIDTH
    }

    /// How the integrators cut the image into camera-ray batches and which threads call
    /// this geometry with them. The default, [`BatchPolicy::Tiles`], is what every CPU
    /// backend wants; a geometry that parallelises inside one batch (a GPU, a voxel engine
    /// with its own threads) asks for [`BatchPolicy::Columns`]. Images do not depend on it
    /// except where a backend's results depend on its batching.
    fn batch_policy(&self) -> BatchPolicy {
        BatchPolicy::Tiles
    }

    /// The one-query approximations this geometry answers (none by default).
    fn shortcuts(&self) -> Shortcuts {
        Shortcuts::default()
    }

    /// Approximate unblocked fraction of each cone; called only when
    /// [`Shortcuts::cone_shadows`] is set. The default is the hard shadow of the cone's axis
    /// (0 or 1 from one occlusion ray).
    fn cone_visibility(&self, cones: &[Cone], out: &mut [Visibility]) {
        assert_eq!(
            cones.len(),
            out.len(),
            "cone_visibility: cones and out differ in length"
        );
        for (c, o) in cones.iter().zip(out.iter_mut()) {
            let r = self.occluded(&Ray {
                origin: c.origin,
                dir: c.dir,
                t_min: 0.0,
                t_max: c.t_max,
            });
            *o = Visibility {
                fraction: if r.occluded { 0.0 } else { 1.0 },
                termination: r.termination,
                work: r.work,
            };
        }
    }

    /// Approximate fraction of each point's hemisphere that is open within `distance`;
    /// called only when [`Shortcuts::ambient_occlusion`] is set. The default is 0 or 1 from
    /// one occlusion ray along the normal.
    fn ambient_openness(&self, points: &[SurfacePoint], distance: f32, out: &mut [Visibility]) {
        assert_eq!(
            points.len(),
            out.len(),
            "ambient_openness: points and out differ in length"
        );
        for (p, o) in points.iter().zip(out.iter_mut()) {
            let r = self.occluded(&Ray {
                origin: p.position,
                dir: p.normal,
                t_min: 0.0,
                t_max: distance,
            });
            *o = Visibility {
                fraction: if r.occluded { 0.0 } else { 1.0 },
                termination: r.termination,
                work: r.work,
            };
        }
    }
}

/// The translation between world space and render space for one scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSpace {
    /// World-space position of the render-space origin (the camera position).
    pub origin: DVec3,
}

impl RenderSpace {
    /// The render space of `scene`: centred on its camera.
    pub fn of(scene: &Scene) -> Self {
        Self {
            origin: scene.camera.position,
        }
    }

    /// World point to render space (f64).
    #[inline]
    pub fn point(&self, world: DVec3) -> DVec3 {
        world - self.origin
    }

    /// The world-to-render transform, to pre-multiply object-to-world transforms with.
    pub fn from_world(&self) -> DAffine3 {
        DAffine3::from_translation(-self.origin)
    }
}
