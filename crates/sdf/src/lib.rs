//! The SDF backend of marchmesh: the scene compiled into a distance field
//! ([`marchmesh_field::Field`], render space, f32) and sphere traced.
//!
//! * Top-level objects far from the camera ([`marchmesh_core::FarFrame::of_box`]) are
//!   compiled into fields of their own, centred on them: a ray is advanced to the object's
//!   bounding sphere in f64, marched there in f32 by the same tracer, and its hit reassembled
//!   in f64, so the object is not sampled on the f32 grid out there (0.06 units at 1e6).
//!
//! * Hit test in two stages (see `march/`): a sample closer than the cone epsilon
//!   ([`HitEpsilon::PixelCone`], a twentieth of the pixel footprint by default) does not end
//!   the ray; the tracer then decides hit or near miss with secant predictions of the
//!   crossing and regula falsi on a sign change, to 1e-3 of the epsilon. Silhouettes are
//!   therefore not dilated by the epsilon (0.00% silhouette mismatch against the exact
//!   reference on every analytic conformance case) and depth is exact to ~1e-5 relative.
//! * Over-relaxation (Keinert et al. 2014) with the overlap test and plain-step fallback.
//! * Rays starting on a surface (reflection and shadow rays, offset by the core integrator by
//!   `ray_offset * |p|` along the normal) first leave that surface's epsilon shell: while the
//!   field is below `eps` they step by the (safe) field value and only count a hit if the
//!   field drops below half of its starting value (another surface closing in, e.g. at a
//!   contact), so a ray never re-hits the surface it leaves yet still sees contacts.
//! * Normals: the analytic gradient of the flattened program's ([`marchmesh_field::tape`])
//!   leaf nearest to the hit, differentiated alone ([`marchmesh_field::Dual1`]); the 8 hits
//!   of a lockstep batch find their leaves in one 8-lane evaluation, and a single ray gets
//!   the same bits ([`marchmesh_field::Field::nearest_gradient`]). Where there is no tape (CSG, repetition, large
//!   nested unions), the nearest leaf is a mesh grid (no derivative), or the gradient is shorter than 0.9 (an unsigned surface at its
//!   zero set, a smooth blend, an ellipsoid's bound), central differences of the field with a
//!   step that is a fraction of the pixel footprint ([`SdfOptions::normal_step`]), evaluated
//!   as one 8-lane field call (the two spare lanes detect a stencil straddling an unsigned
//!   surface, see [`SdfGeometry::normal_at`]).
//! * Every ray reports its evaluations and whether it ended by hit, miss (left the scene's
//!   box), max steps or max distance.
//! * [`Geometry::closest_hits`] / [`Geometry::occluded_many`] trace 8 rays in lockstep: one
//!   8-lane field evaluation per step, a lane that finishes is refilled with the next ray.

mod beam;
mod cone;
mod far;
mod inside;
mod march;
mod options;
mod settings;

use std::time::Instant;

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_core::{
    Cone, FarFrame, FrameEntry, Geometry, GeometryReport, Hit, NoHit, OcclusionResult,
    PrimarySamples, Ray, RayWork, Shortcuts, SurfacePoint, Termination, TraceResult, Visibility,
};
use marchmesh_field::prune::Cells;
use marchmesh_field::{F32x8, Field, FieldError, FieldOptions, MeshGrid, RayCone, Restricted, V3};
use marchmesh_scene::{MaterialId, Scene};

use beam::BEAM_BATCH;
use inside::Inside;
use march::{Lanes8, March, Next, Params};
/// The types of [`SdfOptions::quantize`] and [`SdfOptions::recon`].
pub use marchmesh_field::bake::{Quantization, Reconstruction};
pub use options::{GridKind, HitEpsilon, PruneCells, SdfOptions};
pub use settings::SdfBackend;

/// Why the SDF backend could not build a scene.
#[derive(Debug, thiserror::Error)]
pub enum SdfError {
    /// The field could not be compiled (the message names the node and the reason).
    #[error(transparent)]
    Field(#[from] FieldError),
    /// Baking the scene's mesh grids would need more memory than
    /// [`SdfOptions::memory_limit_bytes`]; refused before baking.
    #[error(
        "baking {meshes} mesh grid(s) at resolution {resolution} would take about {needed_mib} MiB, over the memory limit of {limit_mib} MiB; raise --memory-limit-mib or lower --opt grid_res"
    )]
    OverMemoryLimit {
        /// Distinct mesh files in the scene.
        meshes: u64,
        /// [`SdfOptions::grid_res`].
        resolution: u32,
        /// Estimated bytes, MiB (rounded up).
        needed_mib: u64,
        /// The limit, MiB.
        limit_mib: u64,
    },
    /// An option is out of range.
    #[error("sdf option {name}: {reason}")]
    Option {
        /// Field name in [`SdfOptions`].
        name: &'static str,
        /// Why it is rejected.
        reason: String,
    },
}

/// Bytes per cell of a baked mesh grid for the memory estimate (the field compiler's).
pub use marchmesh_field::BAKE_BYTES_PER_CELL;

/// Rays per bundle restricted together by [`SdfOptions::cull`]: consecutive rays of a
/// batch. The integrator hands 8x8-pixel screen tiles row-major, so at one sample per pixel a
/// bundle is an 8x4-pixel block (the pruning, and so the last bits of a hit, depend on how
/// rays are batched; the per-ray result is deterministic for a given batching). Smaller bundles
/// have narrower wedges (fewer objects kept) but more restriction work and more idle lanes
/// at the end of each bundle. Measured: `docs/decisions/0013`.
pub const CULL_BUNDLE: usize = 32;

/// Fields of fewer nodes are never restricted: there is too little to drop for the work of
/// a bundle's wedge to pay off. Measured: `docs/decisions/0013`.
pub const CULL_MIN_NODES: usize = 8;

/// Fields of fewer nodes are not pruned per region ([`SdfOptions::prune_depth`]); nor are
/// fields without smooth unions, whose hard unions the per-bundle culling already restricts
/// to a tape (see the decision record on pruning per region).
pub const PRUNE_MIN_NODES: usize = 16;

/// Largest change pruning per region may make to the field, as a fraction of the field's
/// box: 2^-24, below the f32 rounding of a point in the box, so the tracer cannot tell.
pub const PRUNE_MAX_ERROR_REL: f64 = 1.0 / 16_777_216.0;

/// From this many camera samples times field nodes on, [`PruneCells::Auto`] gives the
/// octree its whole work budget (up to about 0.7 s of build). Below it the octree gets
/// [`PRUNE_TRIAL_WORK`], and a field whose refinement that cuts short is pruned as one cell
/// over its box instead (a root smooth union's children in fold order, skipped eight at a
/// time where far): on so few samples a long build costs more than it saves. 2^27: the
/// crossover measured between 1000 blended spheres at 256x256 (one cell wins) and at
/// 512x512, or 10^4 spheres at 128x128 (the octree wins); see
/// `docs/decisions/0030-prune-cells-by-image-size.md`.
pub const PRUNE_OCTREE_MIN_SAMPLE_NODES: u64 = 1 << 27;

/// [`PRUNE_OCTREE_MIN_SAMPLE_NODES`] for a field whose root is a blend
/// ([`marchmesh_scene::SmoothOp::Blend`]): 2^25. One cell over the box reads every child at
/// every step of a blend (no fold skips far blocks wholesale there), while the octree's
/// cells list the children near each finest cell: 1000 blended spheres at 256x256 render in
/// 0.48-0.59 s with the octree against 1.1-1.4 s with one cell, 100 in 40 ms with one cell
/// against 0.3-0.4 s with the octree; see `docs/decisions/0031-an-order-free-blend.md`.
pub const PRUNE_OCTREE_MIN_SAMPLE_NODES_BLEND: u64 = 1 << 25;

/// Work ([`marchmesh_field::prune::Cells::build_within`]) [`PruneCells::Auto`] lets an
/// octree spend below [`PRUNE_OCTREE_MIN_SAMPLE_NODES`]: 2^18, about 10-20 ms, enough to
/// finish the octree of a small carved part.
pub const PRUNE_TRIAL_WORK: usize = 1 << 18;

/// Deepest octree [`SdfOptions::prune_depth`] accepts (`2^8` finest cells per axis: a 64 MiB
/// index).
pub const MAX_PRUNE_DEPTH: u32 = 8;

/// Estimated peak bytes of baking one mesh grid with `opts`, before any mesh is read
/// ([`FieldOptions::mesh_grid_bytes_bound`]).
pub fn mesh_grid_bytes_bound(opts: &SdfOptions) -> u64 {
    field_options(opts).mesh_grid_bytes_bound()
}

/// The field compiler's options for `opts`: mesh grids, cache and memory limit.
fn field_options(opts: &SdfOptions) -> FieldOptions {
    FieldOptions {
        mesh_grid_resolution: opts.grid_res,
        cache_dir: opts.cache_dir.clone(),
        mesh_grid: opts.mesh_grid(),
        memory_limit_bytes: opts.memory_limit_bytes,
    }
}

/// Refuses scenes whose mesh grids would not fit in `opts.memory_limit_bytes`.
fn check_bake_memory(scene: &Scene, opts: &SdfOptions) -> Result<(), SdfError> {
    let mut paths = std::collections::HashSet::new();
    scene.visit_nodes(|n| {
        if let marchmesh_scene::NodeKind::Leaf(marchmesh_scene::Shape::Mesh { path }) = &n.kind {
            paths.insert(path.clone());
        }
    });
    let meshes = paths.len() as u64;
    let needed = meshes.saturating_mul(mesh_grid_bytes_bound(opts));
    if needed > opts.memory_limit_bytes {
        return Err(SdfError::OverMemoryLimit {
            meshes,
            resolution: opts.grid_res,
            needed_mib: needed.div_ceil(1 << 20),
            limit_mib: opts.memory_limit_bytes >> 20,
        });
    }
    Ok(())
}

/// A lockstep hit waiting for its normal: ray index, `t`, work, and the point, ray
/// direction and normal step the normal is computed from.
type PendingHit = (usize, f32, RayWork, (Vec3, Vec3, f32));

/// The field a lockstep bundle is traced through.
#[derive(Clone, Copy)]
enum Scope<'a> {
    /// The whole field.
    Whole,
    /// The field restricted to the bundle's cone.
    Restricted(&'a Restricted),
}

/// What [`SdfGeometry::lockstep`] reports, with the [`Scope`] of the bundle.
enum Event<'a> {
    /// Ray `i` finished (`march` is `None` when it missed the scene box before any step).
    Done(usize, Option<&'a March>, Termination),
    /// The bundle's last ray has been reported.
    BundleEnd,
}

/// A scene compiled for sphere tracing.
#[derive(Debug)]
pub struct SdfGeometry {
    field: Field,
    params: Params,
    /// Normal step per unit path length (world units).
    normal_step: f32,
    lockstep: bool,
    /// Restrict bundles of rays sharing an origin to what their cone reaches.
    cull: bool,
    /// Start lockstep rays sharing an origin where their beam stops ([`SdfOptions::beams`]).
    beams: bool,
    /// The one-query approximations enabled by the options.
    shortcuts: Shortcuts,
    /// Field taps per ambient-occlusion estimate.
    ao_taps: u32,
    /// Per-object fields for rays starting inside a solid (only when the camera is inside).
    inside: Option<Inside>,
    /// Top-level objects far from the camera, each traced in a frame of its own (rays
    /// enter it through f64, [`FarFrame::enter`]); empty for most scenes.
    far: Vec<FarPart>,
    /// Whether `field` holds any object (false when every object is far).
    near: bool,
    /// The path length from the camera to this part's frame (0 in render space), added to a
    /// ray's for its normal step.
    path_base: f32,
    report: GeometryReport,
}

fn check(ok: bool, name: &'static str, reason: &str) -> Result<(), SdfError> {
    if ok {
        Ok(())
    } else {
        Err(SdfError::Option {
            name,
            reason: reason.to_string(),
        })
    }
}

/// Checks the options that need no scene: every range, whether or not the scene has meshes
/// to bake (a `grid_res` out of range is an error on a scene of spheres too, so a suite
/// fails when loaded rather than when its first mesh scene is built). Errors name the key.
pub fn check_options(opts: &SdfOptions) -> Result<(), SdfError> {
    match opts.hit_epsilon() {
        HitEpsilon::Absolute(e) => check(
            e > 0.0 && e.is_finite(),
            "eps_abs",
            &format!("must be a finite length in world units > 0, got {e}"),
        )?,
        HitEpsilon::PixelCone(k) => check(
            k > 0.0 && k.is_finite(),
            "eps_px",
            &format!("must be a finite fraction of the pixel footprint > 0, got {k}"),
        )?,
    }
    check(opts.max_steps >= 1, "max_steps", "must be >= 1")?;
    check(
        (1.0..2.0).contains(&opts.relaxation),
        "relaxation",
        "must be in [1, 2)",
    )?;
    check(
        opts.normal_step > 0.0 && opts.normal_step.is_finite(),
        "normal_step",
        "must be > 0",
    )?;
    if let Some(d) = opts.max_distance {
        check(d > 0.0, "max_distance", "must be > 0")?;
    }
    use marchmesh_field::bake::{MAX_BAND_VOXELS, MAX_RESOLUTION, MIN_BAND_VOXELS, MIN_RESOLUTION};
    check(
        (MIN_RESOLUTION..=MAX_RESOLUTION).contains(&opts.grid_res),
        "grid_res",
        &format!(
            "must be in {MIN_RESOLUTION}..={MAX_RESOLUTION} cells, got {}",
            opts.grid_res
        ),
    )?;
    if let MeshGrid::Sparse { band_voxels, .. } = opts.mesh_grid() {
        check(
            (MIN_BAND_VOXELS..=MAX_BAND_VOXELS).contains(&band_voxels),
            "band",
            &format!("must be in {MIN_BAND_VOXELS}..={MAX_BAND_VOXELS} cells"),
        )?;
    }
    check(
        opts.prune_depth <= MAX_PRUNE_DEPTH,
        "prune_depth",
        &format!("must be in 0..={MAX_PRUNE_DEPTH}"),
    )
}

/// Compiles `scene` for sphere tracing. Errors name the offending node, mesh file or option.
pub fn build(scene: &Scene, opts: &SdfOptions) -> Result<SdfGeometry, SdfError> {
    check_options(opts)?;
    let max_distance = opts.max_distance.unwrap_or(scene.render.max_distance);
    check(max_distance > 0.0, "max_distance", "must be > 0")?;
    check_bake_memory(scene, opts)?;
    let t0 = Instant::now();
    let field_opts = field_options(opts);
    let frames = far_frames(scene);
    if frames.iter().all(Option::is_none) {
        let field = Field::compile_scene(scene, &field_opts)?;
        return build_part(scene, opts, field, None, t0);
    }
    // Far objects each get a field compiled in a frame centred on their bounding sphere;
    // the rest stay in the render-space field.
    let cam = scene.camera.position;
    let mut near = scene.clone();
    near.objects = scene
        .objects
        .iter()
        .zip(&frames)
        .filter(|(_, f)| f.is_none())
        .map(|(o, _)| o.clone())
        .collect();
    let mut far = Vec::new();
    for (object, frame) in scene.objects.iter().zip(&frames) {
        let Some(frame) = *frame else { continue };
        let to_frame = DAffine3::from_translation(-(cam + frame.centre()));
        let field = Field::compile_node(object, to_frame, &field_opts)?;
        far.push(FarPart {
            frame,
            part: build_part(scene, opts, field, Some(frame), Instant::now())?,
        });
    }
    let field = Field::compile_scene(&near, &field_opts)?;
    let mut geometry = build_part(&near, opts, field, None, t0)?;
    geometry.near = !near.objects.is_empty();
    // The one-query shortcuts read the render-space field only: shadows and occlusion of
    // far objects need their rays.
    geometry.shortcuts = Shortcuts::default();
    geometry.report.memory_bytes += far.iter().map(|f| f.part.report.memory_bytes).sum::<u64>();
    geometry.report.notes.push(format!(
        "{} top-level object(s) farther than {} radii from the camera traced in frames of their own (rays advanced to their bounding spheres in f64)",
        far.len(),
        marchmesh_core::FAR_RATIO
    ));
    geometry
        .report
        .counters
        .push(("far_objects".into(), far.len() as f64));
    geometry.far = far;
    Ok(geometry)
}

/// The frame of each top-level object of `scene` (in order) that lies far from the camera
/// ([`FarFrame::of_box`] on its render-space bounds); `None` for the others, and for objects
/// whose bounds are unknown before baking (mesh files) or infinite.
fn far_frames(scene: &Scene) -> Vec<Option<FarFrame>> {
    let cam = scene.camera.position;
    scene
        .objects
        .iter()
        .map(|o| {
            let (lo, hi) = o.bounds_in_parent(&|_| None)?.finite()?;
            FarFrame::of_box(lo - cam, hi - cam)
        })
        .collect()
}

/// Whether `field` (to be pruned per region) is worth the octree's whole work budget on
/// `scene`'s image ([`PruneCells::Auto`]): its camera samples times its nodes reach
/// [`PRUNE_OCTREE_MIN_SAMPLE_NODES`] ([`PRUNE_OCTREE_MIN_SAMPLE_NODES_BLEND`] for a root
/// blend).
fn octree_pays(scene: &Scene, field: &Field) -> bool {
    let samples = u64::from(scene.camera.width)
        * u64::from(scene.camera.height)
        * u64::from(scene.render.samples_per_pixel.max(1));
    let threshold = if field.program_f64().root_is_blend() {
        PRUNE_OCTREE_MIN_SAMPLE_NODES_BLEND
    } else {
        PRUNE_OCTREE_MIN_SAMPLE_NODES
    };
    samples.saturating_mul(field.node_count() as u64) >= threshold
}

/// One traced part built from its compiled `field`: the render-space field of `scene`'s
/// objects (`frame` `None`), or a far object's field in the frame centred on `frame`, whose
/// hit epsilon and normal step count the path from the camera to the frame. Errors: the
/// per-object fields of a camera inside a solid could not be compiled.
fn build_part(
    scene: &Scene,
    opts: &SdfOptions,
    field: Field,
    frame: Option<FarFrame>,
    t0: Instant,
) -> Result<SdfGeometry, SdfError> {
    let (eps_abs, eps_cone) = match opts.hit_epsilon() {
        HitEpsilon::Absolute(e) => (e, 0.0),
        HitEpsilon::PixelCone(k) => (0.0, k * scene.camera.pixel_angle()),
    };
    // In a far frame a ray's start lies about the frame's distance (less its radius) along
    // its path from the camera: the cone epsilon there is a constant part of the epsilon.
    let path_base = frame.map_or(0.0, |f| (f.distance() - f.radius()).max(0.0));
    let eps_abs = eps_abs + eps_cone * path_base;
    let max_distance = opts.max_distance.unwrap_or(scene.render.max_distance);
    let field_opts = field_options(opts);
    let mut field = if opts.bounds {
        field
    } else {
        field.without_bounds()
    };
    field.set_kernels(opts.kernels);
    field.set_jit(opts.jit);
    if opts.prune_depth > 0
        && field.node_count() >= PRUNE_MIN_NODES
        && field.has_smooth_unions_or_blends()
    {
        let whole = Cells::max_work(field.node_count());
        let (work, root_if_cut) = match opts.prune_cells {
            PruneCells::Octree => (whole, false),
            PruneCells::Root => (0, false),
            PruneCells::Auto if octree_pays(scene, &field) => (whole, false),
            PruneCells::Auto => (PRUNE_TRIAL_WORK, true),
        };
        field.build_cells_within(opts.prune_depth, PRUNE_MAX_ERROR_REL, work, root_if_cut);
    }
    let inside = match frame {
        None => Inside::build(scene, &field, &field_opts)?,
        // The camera is never inside a far object.
        Some(_) => None,
    };
    let total_ms = t0.elapsed().as_secs_f64() * 1e3;
    let bounds = field.bounds().map(|(lo, hi)| {
        // Pad by a relative margin so f32 rounding never clips a surface.
        let pad = (hi - lo).length() * 1e-4 + (lo.abs().max(hi.abs())).max_element() * 1e-6;
        (
            (lo - DVec3::splat(pad)).as_vec3(),
            (hi + DVec3::splat(pad)).as_vec3(),
        )
    });
    let fr = field.report();
    let mut notes = fr.notes.clone();
    notes.push(format!(
        "sphere tracing: {:?}, max_steps {}, max_distance {}, relaxation {}, normals by central differences with step {} pixel footprints",
        opts.hit_epsilon(), opts.max_steps, max_distance, opts.relaxation, opts.normal_step
    ));
    notes.push(
        "memory counts the f32 program the tracer reads, the f64 program (shared field API) and mesh grids"
            .into(),
    );
    if let Some(inside) = &inside {
        notes.push(format!(
            "camera inside a solid: rays starting inside one trace the nearest of the {} top-level surfaces (min_k of each distance oriented by the side of it the ray starts on), one field per object",
            inside.len()
        ));
    } else if frame.is_none() && field.distance_f64(DVec3::ZERO) < 0.0 {
        notes.push(format!(
            "camera inside a solid of more than {} top-level objects: rays starting inside see the union's boundary, not surfaces inside other solids",
            inside::MAX_INSIDE_OBJECTS
        ));
    }
    let mut counters = fr.counters.clone();
    counters.push(("field_bytes_f32".into(), field.memory_bytes_f32() as f64));
    let mut phases = fr.phases_ms.clone();
    let accounted: f64 = phases.iter().map(|p| p.1).sum();
    phases.push(("other".into(), (total_ms - accounted).max(0.0)));
    let report = GeometryReport {
        backend: <SdfBackend as marchmesh_core::Backend>::NAME.into(),
        triangles: None,
        memory_bytes: field.memory_bytes() + inside.as_ref().map_or(0, Inside::memory_bytes),
        build_phases_ms: phases,
        counters,
        notes,
    };
    Ok(SdfGeometry {
        params: Params {
            eps_abs: eps_abs as f32,
            eps_cone: eps_cone as f32,
            omega: opts.relaxation as f32,
            max_steps: opts.max_steps,
            refine_steps: opts.refine_steps,
            max_distance: max_distance as f32,
            bounds,
            segment: opts.segment,
            segment_sweeps: opts.segment && field.has_tape(),
            recede_checks: opts.recede && opts.bounds && field.has_tape(),
        },
        normal_step: (opts.normal_step * scene.camera.pixel_angle()) as f32,
        lockstep: opts.lockstep,
        // Without bounds (the naive level) nothing is culled either.
        cull: opts.cull && opts.bounds && !field.has_cells(),
        beams: opts.beams && opts.bounds,
        shortcuts: Shortcuts {
            cone_shadows: opts.cone_shadows,
            ambient_occlusion: opts.ao_taps > 0,
        },
        ao_taps: opts.ao_taps,
        inside,
        field,
        far: Vec::new(),
        near: true,
        path_base: path_base as f32,
        report,
    })
}

/// A top-level object far from the camera, traced in its own frame.
#[derive(Debug)]
struct FarPart {
    /// Its bounding sphere (render space), whose centre is the frame's origin.
    frame: FarFrame,
    /// Its field in that frame, traced by the render-space tracer's code.
    part: SdfGeometry,
}

impl SdfGeometry {
    /// The compiled render-space field (without the far objects, which have fields of their
    /// own).
    pub fn field(&self) -> &Field {
        &self.field
    }

    /// Field normal at `p` (render space) by central differences of step `h`.
    ///
    /// On an unsigned surface (a triangle: the field is `|distance|`) the stencil straddles
    /// the zero set and the differences collapse; that is detected from the field on both
    /// sides of the hit along the ray (positive on both) together with a gradient shorter
    /// than 0.9, and the normal is then taken at a point backed off `4 h` along the ray.
    pub fn normal_at(&self, p: Vec3, dir: Vec3, h: f32) -> Vec3 {
        self.normal_material(p, dir, h).0
    }

    /// [`SdfGeometry::normal_at`] and the material, both from one 8-lane evaluation: the
    /// material is the field's at `p - 2 h dir`, just in front of the hit along the ray.
    fn normal_material(&self, p: Vec3, dir: Vec3, h: f32) -> (Vec3, MaterialId) {
        // A baked mesh that stores its facets' normals (`recon=normals`) gives the facet's
        // normal, where differences of the smooth field would round the facet edges off.
        if let Some(n) = self.field.stored_normal(p) {
            return (n, self.field.distance_material(p - dir * (2.0 * h)).1);
        }
        let (x, y, z) = (Vec3::X * h, Vec3::Y * h, Vec3::Z * h);
        let (d, m) = self.field.distance_material_x8([
            p + x,
            p - x,
            p + y,
            p - y,
            p + z,
            p - z,
            p - dir * (2.0 * h),
            p + dir * (2.0 * h),
        ]);
        let material = m[6];
        let g = Vec3::new(d[0] - d[1], d[2] - d[3], d[4] - d[5]) / (2.0 * h);
        let len = g.length();
        let straddles = d[6] > 0.0 && d[7] > 0.0 && len < 0.9;
        if straddles || len == 0.0 || !len.is_finite() {
            let g2 = self.gradient(p - dir * (4.0 * h), h);
            let len2 = g2.length();
            if len2 > 0.0 && len2.is_finite() {
                return (g2 / len2, material);
            }
        }
        if len > 0.0 && len.is_finite() {
            (g / len, material)
        } else {
            (-dir, material)
        }
    }

    /// Normals and materials of up to 8 hits at once (`hits[..n]`: point, ray direction,
    /// normal step). The normal is the analytic gradient of the field's leaf nearest to the
    /// point, the surface hit ([`Field::nearest_gradients_x8`]: one 8-lane evaluation to
    /// find the leaf, then that leaf alone differentiated per lane; as accurate as the f32
    /// distance, where central differences lose `ulp(|p|) / h`; a dual-number evaluation
    /// of the whole tape cost twice as much on 4-5 leaves), the material the field's at
    /// `p - 2 h dir` as in [`SdfGeometry::normal_material`] (one 8-lane evaluation). A hit
    /// whose gradient is shorter than 0.9 or not finite (an unsigned surface at its zero
    /// set, an ellipsoid's bound, a mesh grid, which has no derivative), or whose field has
    /// no tape (CSG, smooth blends), takes [`SdfGeometry::normal_material`] instead, with its
    /// straddle fallback.
    ///
    /// Hits of a bundle traced through a restricted field (`scope`) take the gradient of the
    /// nearest kept leaf ([`Field::restricted_nearest_gradients_x8`]: the surface hit, whose
    /// object is kept; unlike a large whole field, a restriction usually has a tape) and the
    /// material of that field.
    fn normals_material_x8(
        &self,
        scope: Scope<'_>,
        hits: &[(Vec3, Vec3, f32)],
    ) -> [(Vec3, MaterialId); 8] {
        let n = hits.len().min(8);
        let mut out = [(Vec3::ZERO, 0); 8];
        let Some(&first) = hits.first() else {
            return out;
        };
        // Idle lanes repeat the first hit (finite points).
        let hit = |k: usize| if k < n { hits[k] } else { first };
        let points = std::array::from_fn(|k| hit(k).0);
        let grads = match scope {
            Scope::Whole => self.field.nearest_gradients_x8(points),
            Scope::Restricted(r) => self.field.restricted_nearest_gradients_x8(r, points),
        };
        let Some(g) = grads else {
            for (o, &(p, dir, h)) in out.iter_mut().zip(&hits[..n]) {
                *o = self.normal_material(p, dir, h);
            }
            return out;
        };
        let behind = std::array::from_fn(|k| {
            let (p, dir, h) = hit(k);
            p - dir * (2.0 * h)
        });
        let (_, m) = match scope {
            Scope::Whole => self.field.distance_material_x8(behind),
            Scope::Restricted(r) => self.field.restricted_distance_material_x8(r, behind),
        };
        for (k, o) in out.iter_mut().enumerate().take(n) {
            let len = g[k].length();
            *o = if len >= 0.9 && len.is_finite() {
                (g[k] / len, m[k])
            } else {
                let (p, dir, h) = hits[k];
                self.normal_material(p, dir, h)
            };
        }
        out
    }

    fn gradient(&self, p: Vec3, h: f32) -> Vec3 {
        let (x, y, z) = (Vec3::X * h, Vec3::Y * h, Vec3::Z * h);
        let d = self
            .field
            .distance_x8([p + x, p - x, p + y, p - y, p + z, p - z, p, p]);
        Vec3::new(d[0] - d[1], d[2] - d[3], d[4] - d[5]) / (2.0 * h)
    }

    fn finish(&self, m: &March, term: Termination) -> TraceResult {
        self.finish_with(m, term, |p, dir, h| self.normal_material_one(p, dir, h))
    }

    /// The normal and material of one hit as [`SdfGeometry::normals_material_x8`] computes
    /// them (bit for bit: a single ray and the lockstep lanes report the same hit).
    fn normal_material_one(&self, p: Vec3, dir: Vec3, h: f32) -> (Vec3, MaterialId) {
        if let Some(g) = self.field.nearest_gradient(p) {
            let len = g.length();
            if len >= 0.9 && len.is_finite() {
                let (_, m) = self.field.distance_material(p - dir * (2.0 * h));
                return (g / len, m);
            }
        }
        self.normal_material(p, dir, h)
    }

    /// The trace result of a finished march, the hit's normal and material from
    /// `normal_material(point, direction, normal step)`.
    fn finish_with(
        &self,
        m: &March,
        term: Termination,
        normal_material: impl Fn(Vec3, Vec3, f32) -> (Vec3, MaterialId),
    ) -> TraceResult {
        let work = RayWork {
            steps: m.work_steps(),
            ..RayWork::default()
        };
        if let Ok(why) = NoHit::try_from(term) {
            return TraceResult::not_found(why, work);
        }
        let (p, h) = self.hit_point(m);
        let (normal, material) = normal_material(p, m.dir(), h);
        TraceResult::found(
            Hit {
                t: m.t,
                position: p,
                normal,
                material,
            },
            work,
        )
    }

    /// The hit point of a march ended by a hit and its normal step.
    fn hit_point(&self, m: &March) -> (Vec3, f32) {
        let p = m.point();
        let h = (self.normal_step * (self.path_base + m.path_length()))
            .max(p.length() * 1e-6)
            .max(1e-30);
        (p, h)
    }

    fn occ(m: &March, term: Termination) -> OcclusionResult {
        OcclusionResult {
            occluded: term == Termination::Hit,
            termination: term,
            work: RayWork {
                steps: m.work_steps(),
                ..RayWork::default()
            },
        }
    }

    fn run(&self, m: &mut March) -> Termination {
        Self::run_with(
            m,
            &self.params,
            |p| self.field.distance(p),
            |p, d, len| self.field.segment_step(p, d, len),
            |p, d| self.field.recedes(p, d),
        )
    }

    /// [`Self::run_with`] on the distance to the nearest top-level surface of `inside` (rays
    /// starting inside a solid), each object's distance oriented by the side of it the ray
    /// starts on ([`Inside::sides`]), with plain steps: the per-object fields have no
    /// directional bounds. `m` must not have been fed yet.
    fn run_inside(m: &mut March, params: &Params, inside: &Inside) -> Termination {
        let sides = inside.sides(m.point(), m.shell(params));
        Self::run_with(
            m,
            // The per-object fields answer no receding checks either.
            &Params {
                recede_checks: false,
                ..*params
            },
            |p| inside.oriented(p, &sides),
            |p, _, _| {
                let d = inside.oriented(p, &sides);
                (d, d.abs())
            },
            |_, _| false,
        )
    }

    /// Marches `m` to its end with the distance function `distance`, while it is segment
    /// tracing the safe-step function `segment(point, direction, length)`, and at its
    /// receding checks `recedes(point, direction)` ([`Next::Check`]).
    fn run_with(
        m: &mut March,
        params: &Params,
        distance: impl Fn(Vec3) -> f32,
        segment: impl Fn(Vec3, Vec3, f32) -> (f32, f32),
        recedes: impl Fn(Vec3, Vec3) -> bool,
    ) -> Termination {
        loop {
            match Self::advance(m, params, None, &distance, &segment) {
                Next::Done(t) => return t,
                Next::Check if recedes(m.check_point(), m.dir()) => return m.receded(),
                Next::Check | Next::Continue => {}
            }
        }
    }

    /// One scalar step of `m`: a segment-tracing sample when it asks for one, else the plain
    /// distance (`known` when the caller already evaluated it at [`March::point`]).
    #[inline]
    fn advance(
        m: &mut March,
        params: &Params,
        known: Option<f32>,
        distance: &impl Fn(Vec3) -> f32,
        segment: &impl Fn(Vec3, Vec3, f32) -> (f32, f32),
    ) -> Next {
        match m.segment_len() {
            Some(len) => {
                let (d, step) = segment(m.point(), m.dir(), len);
                m.feed_segment(d, step, params)
            }
            None => m.feed(known.unwrap_or_else(|| distance(m.point())), params),
        }
    }

    /// The per-object fields when `ray` starts inside a solid (camera-inside scenes only).
    fn inside_of(&self, ray: &Ray) -> Option<&Inside> {
        self.inside
            .as_ref()
            .filter(|_| self.field.distance(ray.origin) < 0.0)
    }

    /// A ray starting inside a solid: the first top-level surface it crosses.
    fn closest_from_inside(&self, inside: &Inside, ray: &Ray) -> TraceResult {
        let mut m = match March::new(ray, &self.params, true) {
            Ok(m) => m,
            Err(why) => return TraceResult::not_found(why, RayWork::default()),
        };
        let term = Self::run_inside(&mut m, &self.params, inside);
        self.finish_with(&m, term, |p, dir, h| {
            inside.normal_material(inside.nearest(p).1, p, dir, h)
        })
    }

    /// One finished lockstep ray into `out`, or into `pending` when it hit (its normal waits
    /// for [`Self::flush_normals`]); true when 8 hits are pending.
    #[inline(always)]
    fn record(
        &self,
        (i, m, t): (usize, Option<&March>, Termination),
        pending: &mut Vec<PendingHit>,
        out: &mut [TraceResult],
    ) -> bool {
        out[i] = match m {
            Some(m) if t == Termination::Hit => {
                let (p, h) = self.hit_point(m);
                let work = RayWork {
                    steps: m.work_steps(),
                    ..RayWork::default()
                };
                pending.push((i, m.t, work, (p, m.dir(), h)));
                return pending.len() == 8;
            }
            Some(m) => self.finish(m, t),
            // A ray that never started marching (March::new refused it) has no hit.
            None => TraceResult::not_found(
                NoHit::try_from(t).unwrap_or(NoHit::Miss),
                RayWork::default(),
            ),
        };
        false
    }

    /// Whether lockstep batches are cut into bundles traced through restricted fields.
    fn culls(&self) -> bool {
        self.cull && self.field.node_count() >= CULL_MIN_NODES
    }

    /// Gives the `pending` hits their normals and materials (one
    /// [`Self::normals_material_x8`]) and writes them to `out`. Out of line: the lockstep
    /// loop's per-ray callback stays small enough to inline.
    #[inline(never)]
    fn flush_normals(
        &self,
        scope: Scope<'_>,
        pending: &mut Vec<PendingHit>,
        out: &mut [TraceResult],
    ) {
        let mut hits = [(Vec3::ZERO, Vec3::ZERO, 0.0); 8];
        for (h, p) in hits.iter_mut().zip(pending.iter()) {
            *h = p.3;
        }
        let nm = self.normals_material_x8(scope, &hits[..pending.len()]);
        for (&(i, t, work, (p, _, _)), &(normal, material)) in pending.iter().zip(&nm) {
            out[i] = TraceResult::found(
                Hit {
                    t,
                    position: p,
                    normal,
                    material,
                },
                work,
            );
        }
        pending.clear();
    }

    /// Traces `rays` 8 at a time in lockstep; `report` receives each finished ray
    /// ([`Event::Done`]) and the end of each bundle ([`Event::BundleEnd`]), with the field
    /// the bundle was traced through. With culling on, bundles of up to [`CULL_BUNDLE`]
    /// consecutive rays sharing an origin are traced through the field restricted to their
    /// cone; otherwise all of `rays` is one bundle.
    fn lockstep(&self, rays: &[Ray], refine: bool, mut report: impl FnMut(Scope<'_>, Event<'_>)) {
        if !self.culls() {
            self.lockstep_whole(rays, 0, refine, &mut report);
            return;
        }
        let mut restricted = Restricted::default();
        for (k, bundle) in rays.chunks(CULL_BUNDLE).enumerate() {
            match self.cone_of(bundle) {
                Some(cone) => {
                    self.field.restrict_to(&cone, &mut restricted);
                    let scope = Scope::Restricted(&restricted);
                    self.lockstep_with(
                        bundle,
                        k * CULL_BUNDLE,
                        refine,
                        &mut |i, m, t| report(scope, Event::Done(i, m, t)),
                        |p| self.field.restricted_distance_lanes(&restricted, p),
                        |p, d, len| self.field.restricted_segment_step(&restricted, p, d, len),
                        |p, d, len| self.field.restricted_segment_lanes(&restricted, p, d, len),
                        |p, d| self.field.restricted_recedes(&restricted, p, d),
                        restricted.is_taped(),
                    );
                    report(scope, Event::BundleEnd);
                }
                None => self.lockstep_whole(bundle, k * CULL_BUNDLE, refine, &mut report),
            }
        }
    }

    /// [`Self::lockstep`] of one bundle through the whole field.
    #[inline(always)]
    fn lockstep_whole(
        &self,
        rays: &[Ray],
        first_index: usize,
        refine: bool,
        report: &mut impl FnMut(Scope<'_>, Event<'_>),
    ) {
        self.lockstep_with(
            rays,
            first_index,
            refine,
            &mut |i, m, t| report(Scope::Whole, Event::Done(i, m, t)),
            |p| self.field.distance_lanes(p),
            |p, d, len| self.field.segment_step(p, d, len),
            |p, d, len| self.field.segment_lanes(p, d, len),
            |p, d| self.field.recedes(p, d),
            self.field.has_tape(),
        );
        report(Scope::Whole, Event::BundleEnd);
    }

    /// The cone of a bundle of rays sharing an origin, widened by twice the hit shell (a ray
    /// may decide a hit anywhere within the shell), or `None` when the origins differ or the
    /// directions spread too wide.
    fn cone_of(&self, bundle: &[Ray]) -> Option<RayCone> {
        let first = bundle.first()?;
        if bundle.iter().any(|r| r.origin != first.origin) {
            return None;
        }
        let t_max = bundle
            .iter()
            .map(|r| f64::from(r.t_max.min(self.params.max_distance)))
            .fold(0.0, f64::max);
        RayCone::around(
            first.origin,
            bundle.iter().map(|r| r.dir),
            t_max,
            2.0 * f64::from(self.params.eps_abs),
            2.0 * f64::from(self.params.eps_cone) + 1e-6,
        )
    }

    /// The lockstep loop over `rays` (indices reported from `first_index`) with the 8-lane
    /// distance function `distance`: plain marching steps run on all lanes at once
    /// ([`Lanes8::step`]), every other decision in the lane's scalar [`March`]. Lanes in the
    /// segment-tracing phase take their samples from one 8-lane `segment_lanes` query per
    /// iteration (bit for bit the scalar `segment`'s, and its values are the other lanes'
    /// distances), or from `segment` one lane at a time where that returns `None` (no tape).
    #[allow(clippy::too_many_arguments)]
    fn lockstep_with(
        &self,
        rays: &[Ray],
        first_index: usize,
        refine: bool,
        done: &mut impl FnMut(usize, Option<&March>, Termination),
        distance: impl Fn(V3<F32x8>) -> F32x8,
        segment: impl Fn(Vec3, Vec3, f32) -> (f32, f32),
        segment_lanes: impl Fn(V3<F32x8>, V3<F32x8>, F32x8) -> Option<(F32x8, F32x8)>,
        recedes: impl Fn(Vec3, Vec3) -> bool,
        taped: bool,
    ) {
        // Sweeps take segment steps only where `segment_lanes` answers for eight lanes at
        // once (a scalar interpreter query per lane costs more than the plain steps saved),
        // and receding checks need the tape too.
        let params = &Params {
            segment_sweeps: self.params.segment_sweeps && taped,
            recede_checks: self.params.recede_checks && taped,
            ..self.params
        };
        let no_scalar = |_: Vec3| f32::NAN;
        let mut lanes: [Option<(usize, March)>; 8] = [None; 8];
        let mut soa = Lanes8::default();
        let mut next = 0usize;
        // With beams, rays are started [`BEAM_BATCH`] at a time, the batch's beams marched,
        // and the lanes fed from `prepared` (rays `prepared_from..` of `rays`).
        let beams = self.beams && beam::worth_it(rays, params);
        let mut prepared: [Option<March>; BEAM_BATCH] = [None; BEAM_BATCH];
        let mut prepared_from = 0usize;
        let mut load =
            |next: &mut usize, done: &mut dyn FnMut(usize, Option<&March>, Termination)| {
                while *next < rays.len() {
                    let i = *next;
                    *next += 1;
                    if beams {
                        if i == prepared_from + BEAM_BATCH || i == 0 {
                            prepared_from = i;
                            let batch = &rays[i..rays.len().min(i + BEAM_BATCH)];
                            for (j, (slot, ray)) in prepared.iter_mut().zip(batch).enumerate() {
                                *slot = March::new(ray, params, refine)
                                    .map_err(|t| done(first_index + i + j, None, t.into()))
                                    .ok();
                            }
                            beam::advance_by_beams(&mut prepared[..batch.len()], params, &distance);
                        }
                        match prepared[i - prepared_from].take() {
                            Some(m) => return Some((first_index + i, m)),
                            None => continue,
                        }
                    }
                    match March::new(&rays[i], params, refine) {
                        Ok(m) => return Some((first_index + i, m)),
                        Err(t) => done(first_index + i, None, t.into()),
                    }
                }
                None
            };
        let Some(first) = load(&mut next, done) else {
            return;
        };
        // Every lane starts on the first ray's point, so empty lanes evaluate finite points.
        for k in 0..8 {
            soa.load(k, &first.1);
        }
        lanes[0] = Some(first);
        for (k, lane) in lanes.iter_mut().enumerate().skip(1) {
            *lane = load(&mut next, done);
            soa.seat(k, lane.as_ref().map(|l| &l.1));
        }
        while lanes.iter().any(Option::is_some) {
            let points = soa.points();
            let segmenting = soa.segmenting();
            let seg = if segmenting != 0 {
                segment_lanes(points, soa.dirs(), soa.segment_lens())
            } else {
                None
            };
            // A segment query's value is the distance, bit for bit: no second evaluation.
            let d = match seg {
                Some((v, _)) => v,
                None => distance(points),
            };
            let slow = soa.step(d, params);
            // Only the lanes that did not advance (most iterations have none).
            let mut pending = slow;
            while pending != 0 {
                let k = pending.trailing_zeros() as usize;
                pending &= pending - 1;
                let lane = &mut lanes[k];
                let Some((i, m)) = lane.as_mut() else {
                    continue;
                };
                soa.store(k, m);
                let next_step = match seg {
                    Some((v, step)) if segmenting & (1 << k) != 0 => {
                        m.feed_segment(v.0[k], step.0[k], params)
                    }
                    _ => Self::advance(m, params, Some(d.0[k]), &no_scalar, &segment),
                };
                let finished = match next_step {
                    Next::Continue => None,
                    Next::Check => recedes(m.check_point(), m.dir()).then(|| m.receded()),
                    Next::Done(t) => Some(t),
                };
                match finished {
                    None => soa.load(k, m),
                    Some(t) => {
                        done(*i, Some(m), t);
                        *lane = load(&mut next, done);
                        soa.seat(k, lane.as_ref().map(|l| &l.1));
                    }
                }
            }
        }
    }
}

impl Geometry for SdfGeometry {
    fn closest_hit(&self, ray: &Ray) -> TraceResult {
        if self.far.is_empty() {
            return self.near_closest_hit(ray);
        }
        let mut out = [TraceResult::default()];
        self.closest_hits_far(std::slice::from_ref(ray), None, &mut out);
        out[0]
    }

    fn occluded(&self, ray: &Ray) -> OcclusionResult {
        if self.far.is_empty() {
            return self.near_occluded(ray);
        }
        let mut out = [OcclusionResult::default()];
        self.occluded_far(std::slice::from_ref(ray), &mut out);
        out[0]
    }

    fn closest_hits(&self, rays: &[Ray], out: &mut [TraceResult]) {
        if self.far.is_empty() {
            return self.near_closest_hits(rays, out);
        }
        self.closest_hits_far(rays, None, out);
    }

    /// With far objects, primary rays enter their frames along their exact f64 directions.
    fn closest_hits_primary(
        &self,
        rays: &[Ray],
        samples: PrimarySamples<'_>,
        out: &mut [TraceResult],
    ) {
        if self.far.is_empty() {
            return self.near_closest_hits(rays, out);
        }
        self.closest_hits_far(rays, Some(samples), out);
    }

    fn occluded_many(&self, rays: &[Ray], out: &mut [OcclusionResult]) {
        if self.far.is_empty() {
            return self.near_occluded_many(rays, out);
        }
        self.occluded_far(rays, out);
    }

    fn report(&self) -> GeometryReport {
        self.report.clone()
    }

    fn shortcuts(&self) -> Shortcuts {
        self.shortcuts
    }

    fn cone_visibility(&self, cones: &[Cone], out: &mut [Visibility]) {
        cone::cone_visibility(&self.field, cones, out, self.params.max_steps);
    }

    fn ambient_openness(&self, points: &[SurfacePoint], distance: f32, out: &mut [Visibility]) {
        cone::ambient_openness(&self.field, self.ao_taps, points, distance, out);
    }
}
