//! The backend conformance suite.
//!
//! Every backend runs the same small scenes (64x64 unless a case states its own size) and
//! compares its AOVs with the exact reference pixel by pixel (`marchmesh_core::compare`). A
//! backend's test file instantiates
//! the suite with [`conformance_suite!`], giving its [`Backend`] type, optionally its settings
//! (default: the backend's defaults), and its tolerances per case (the way `fidget` runs one
//! test suite on every evaluator):
//!
//! ```ignore
//! marchmesh_conformance::conformance_suite!(
//!     backend = marchmesh_sdf::SdfBackend,
//!     tolerance = |case: marchmesh_conformance::CaseId| marchmesh_conformance::Tolerance::default(),
//! );
//! ```
//!
//! To add a case: add `name => json` to the `cases!` list (which defines [`CaseId`] and
//! [`CASES`]) and the name to one of [`conformance_suite!`]'s lists; the compiler flags a
//! case missing from the macro and a tolerance naming a case that does not exist.

use std::path::{Path, PathBuf};

pub use marchmesh_core::Backend;
use marchmesh_core::{
    Accuracy, BackgroundSampler, DEFAULT_MEMORY_LIMIT_BYTES, Geometry, RenderOptions, RenderStats,
    compare, render,
};
use marchmesh_reference::ReferenceBackend;
use marchmesh_scene::Scene;

/// Image side of a conformance render, pixels, unless its case states its size.
pub const SIDE: u32 = 64;

/// What a backend must meet on one case: the core's [`Tolerance`], shared with the
/// stability study's verdicts.
pub use marchmesh_core::Tolerance;

/// A conformance scene: its id, its name, its image size and its JSON (the camera's size in
/// the JSON is replaced by `size`).
pub struct Case {
    /// Which case.
    pub id: CaseId,
    /// Test name (the id's name).
    pub name: &'static str,
    /// Image width and height: [`SIDE`] x [`SIDE`] unless the case states its own (a
    /// situation that shows only at a finer pixel grid).
    pub size: (u32, u32),
    /// Scene JSON; relative mesh paths resolve against `scenes/` of the repository.
    pub json: &'static str,
}

macro_rules! cam {
    () => {
        r#""camera": {"position": [0, 1.5, -5], "look_at": [0, 0, 0], "vfov_deg": 40}"#
    };
}

/// Declares every case once: the [`CaseId`] enum (tolerances match on it, so a misspelt case
/// fails to compile) and [`CASES`]. `name => json` renders at [`SIDE`] x [`SIDE`],
/// `name (W x H) => json` at W x H.
macro_rules! cases {
    ($($name:ident $(($w:literal x $h:literal))? => $json:expr,)*) => {
        /// A conformance case. [`conformance_suite!`] must list every variant (an exhaustive
        /// match in its expansion fails to compile otherwise).
        #[allow(non_camel_case_types)]
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum CaseId {
            $(
                #[doc = concat!("The `", stringify!($name), "` case.")]
                $name,
            )*
        }

        /// Every case, each a small scene exercising one shape, operator or numerical
        /// situation.
        pub const CASES: &[Case] = &[$(Case {
            id: CaseId::$name,
            name: stringify!($name),
            size: cases!(@size $(($w, $h))?),
            json: $json,
        }),*];
    };
    (@size) => { (SIDE, SIDE) };
    (@size ($w:literal, $h:literal)) => { ($w, $h) };
}

cases! {
    sphere => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"sphere": {"radius": 1}}}]}"#
        ),
    box_rotated => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"box": {"half_extents": [0.8, 0.5, 0.6]}}, "transform": {"rotate_deg": [20, 35, 10]}}]}"#
        ),
    ellipsoid => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"ellipsoid": {"radii": [1.3, 0.6, 0.8]}}, "transform": {"rotate_deg": [0, 30, 0]}}]}"#
        ),
    cylinder => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"cylinder": {"radius": 0.7, "height": 1.6}}, "transform": {"rotate_deg": [25, 0, 15]}}]}"#
        ),
    torus => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"torus": {"major_radius": 1.1, "minor_radius": 0.35}}, "transform": {"rotate_deg": [-40, 0, 0]}}]}"#
        ),
    plane_and_sphere_shadow => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"plane": {}}, "transform": {"translate": [0, -1, 0]}},
                {"shape": {"sphere": {"radius": 0.8}}, "transform": {"translate": [0, -0.2, 0]}}]}"#
        ),
    triangle => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"triangle": {"vertices": [[-1.2, -0.8, 0.3], [1.3, -0.6, -0.2], [0.1, 1.2, 0.1]]}}}]}"#
        ),
    nonuniform_scale => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"sphere": {"radius": 1}}, "transform": {"scale": [1.5, 0.5, 0.8], "rotate_deg": [0, 0, 20]}}]}"#
        ),
    union => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"union": {"children": [
                {"shape": {"box": {"half_extents": [0.6, 0.6, 0.6]}}},
                {"shape": {"sphere": {"radius": 0.75}}, "transform": {"translate": [0.4, 0.4, -0.4]}, "material": {"color": [1, 0, 0]}}]}}}]}"#
        ),
    intersection => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"intersection": {"children": [
                {"shape": {"box": {"half_extents": [0.8, 0.8, 0.8]}}},
                {"shape": {"sphere": {"radius": 1.05}}, "material": {"color": [1, 0, 0]}}]}}, "transform": {"rotate_deg": [0, 30, 0]}}]}"#
        ),
    subtraction => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"subtraction": {"children": [
                {"shape": {"box": {"half_extents": [0.8, 0.8, 0.8]}}},
                {"shape": {"sphere": {"radius": 0.9}}, "transform": {"translate": [0, 0.5, -0.5]}, "material": {"color": [1, 0, 0]}}]}}, "transform": {"rotate_deg": [0, -25, 0]}}]}"#
        ),
    smooth_union => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"smooth_union": {"blend_radius": 0.4, "children": [
                {"shape": {"sphere": {"radius": 0.7}}, "transform": {"translate": [-0.5, 0, 0]}},
                {"shape": {"sphere": {"radius": 0.6}}, "transform": {"translate": [0.6, 0.1, 0]}}]}}}]}"#
        ),
    smooth_intersection => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"smooth_intersection": {"blend_radius": 0.3, "children": [
                {"shape": {"sphere": {"radius": 1.0}}, "transform": {"translate": [-0.35, 0, 0]}},
                {"shape": {"box": {"half_extents": [0.8, 0.7, 0.7]}}, "transform": {"translate": [0.3, 0, 0], "rotate_deg": [0, 30, 0]}}]}}}]}"#
        ),
    smooth_subtraction => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"smooth_subtraction": {"blend_radius": 0.25, "children": [
                {"shape": {"box": {"half_extents": [0.8, 0.8, 0.8]}}},
                {"shape": {"sphere": {"radius": 0.7}}, "transform": {"translate": [0, 0.6, -0.6]}, "material": {"color": [1, 0, 0]}},
                {"shape": {"capsule": {"radius": 0.25, "height": 1.2}}, "transform": {"translate": [0.7, 0, -0.7], "rotate_deg": [0, 0, 90]}}]}}, "transform": {"rotate_deg": [0, -25, 0]}}]}"#
        ),
    blend => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"blend": {"blend_radius": 0.45, "children": [
                {"shape": {"sphere": {"radius": 0.55}}, "transform": {"translate": [-0.55, -0.1, 0]}},
                {"shape": {"sphere": {"radius": 0.5}}, "transform": {"translate": [0.45, 0.05, 0]}, "material": {"color": [1, 0, 0]}},
                {"shape": {"sphere": {"radius": 0.4}}, "transform": {"translate": [0, 0.6, 0.1]}},
                {"shape": {"capsule": {"radius": 0.18, "height": 1.4}}, "transform": {"translate": [0, -0.3, -0.3], "rotate_deg": [0, 0, 90]}}]}}, "transform": {"rotate_deg": [0, 20, 0]}}]}"#
        ),
    rounded_box => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"rounded_box": {"half_extents": [0.9, 0.6, 0.7], "rounding_radius": 0.25}},
                "transform": {"rotate_deg": [20, 35, 0]}}]}"#
        ),
    capsule => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"capsule": {"radius": 0.45, "height": 1.4}},
                "transform": {"rotate_deg": [0, 0, 60]}}]}"#
        ),
    capped_cone => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"capped_cone": {"height": 1.6, "bottom_radius": 0.8, "top_radius": 0.3}},
                "transform": {"rotate_deg": [-25, 0, 15]}},
                {"shape": {"capped_cone": {"height": 0.8, "bottom_radius": 0.4, "top_radius": 0}},
                "transform": {"translate": [1.4, 0.2, 0]}}]}"#
        ),
    repeat_finite => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"repeat": {"period": [1, 0, 1], "count": [3, null, 2],
                "child": {"shape": {"sphere": {"radius": 0.35}}}}}}]}"#
        ),
    // Copies wider than their cells: the union of whole copies, never clipped at the border
    // (a clipped rendering of this scene differs on ~400 px at 256x256).
    repeat_overlapping => concat!(
            "{",
            cam!(),
            r#", "objects": [{"shape": {"repeat": {"period": [1, 0, 1], "count": [3, null, 3],
                "child": {"shape": {"sphere": {"radius": 0.45}}, "transform": {"translate": [0.3, 0, 0.2]}}}}}]}"#
        ),
    repeat_infinite => r#"{"camera": {"position": [0, 2, -6], "look_at": [0, 0, 0], "vfov_deg": 50},
            "objects": [{"shape": {"repeat": {"period": [2, 0, 2],
                "child": {"shape": {"box": {"half_extents": [0.4, 0.4, 0.4]}}}}}}],
            "render": {"max_distance": 40}}"#,
    tiny_scale => r#"{"camera": {"position": [0, 1.5e-3, -5e-3], "look_at": [0, 0, 0], "vfov_deg": 40},
            "objects": [{"shape": {"torus": {"major_radius": 1.1e-3, "minor_radius": 0.35e-3}}, "transform": {"rotate_deg": [-40, 0, 0]}},
                        {"shape": {"box": {"half_extents": [3e-3, 1e-4, 3e-3]}}, "transform": {"translate": [0, -1e-3, 0]}}],
            "render": {"max_distance": 1}}"#,
    huge_scale => r#"{"camera": {"position": [0, 1.5e3, -5e3], "look_at": [0, 0, 0], "vfov_deg": 40},
            "objects": [{"shape": {"torus": {"major_radius": 1.1e3, "minor_radius": 0.35e3}}, "transform": {"rotate_deg": [-40, 0, 0]}},
                        {"shape": {"box": {"half_extents": [3e3, 1e2, 3e3]}}, "transform": {"translate": [0, -1e3, 0]}}],
            "render": {"max_distance": 1e5}}"#,
    far_from_origin => r#"{"camera": {"position": [1e5, 1e5, 1e5], "look_at": [1e5, 1e5, 1.00005e5]},
            "objects": [{"shape": {"sphere": {"radius": 1}}, "transform": {"translate": [1e5, 1e5, 1.00005e5]}}]}"#,
    // A ray starting inside a solid (scenes/README.md, "Rays that start inside a solid"):
    // top-level objects are independent surfaces, so a ray sees the first boundary crossing
    // of any object; a CSG node is one solid whose boundary is seen.
    camera_inside_one => r#"{"camera": {"position": [0, 0, 0], "look_at": [0, 0, 1], "vfov_deg": 60},
            "objects": [{"shape": {"sphere": {"radius": 5}}},
                        {"shape": {"sphere": {"radius": 0.5}}, "transform": {"translate": [0, 0, 2]}, "material": {"color": [1, 0, 0]}}]}"#,
    camera_inside_two => r#"{"camera": {"position": [0, 0, 0], "look_at": [0, 0, 1], "vfov_deg": 70},
            "objects": [{"shape": {"sphere": {"radius": 3}}, "transform": {"translate": [0, 0, 0.5]}},
                        {"shape": {"box": {"half_extents": [1.5, 1.2, 4]}}, "transform": {"translate": [0.4, 0.2, 0], "rotate_deg": [0, 15, 10]}, "material": {"color": [1, 0, 0]}}]}"#,
    camera_inside_subtraction => r#"{"camera": {"position": [0, 0, 0], "look_at": [0, 0, 1], "vfov_deg": 70},
            "objects": [{"shape": {"subtraction": {"children": [
                {"shape": {"box": {"half_extents": [3, 3, 4]}}},
                {"shape": {"sphere": {"radius": 1}}, "transform": {"translate": [0.3, 0, 2.5]}, "material": {"color": [1, 0, 0]}}]}}}]}"#,
    // The camera inside a box minus a sphere, looking at the exit surface across the seam
    // where the removed sphere meets the box's face, which is also the scene box's (sphere
    // tracing once left holes along it, seen at this size: rays that run within the hit shell
    // along the sphere and leave through the face).
    camera_inside_subtraction_seam (256 x 192) => r#"{"camera": {"position": [0.2, 0.1, -0.3], "look_at": [0.5, -0.2, 3], "vfov_deg": 70, "width": 256, "height": 192},
            "objects": [{"shape": {"subtraction": {"children": [
                {"shape": {"box": {"half_extents": [1.5, 1.0, 1.5]}}},
                {"shape": {"sphere": {"radius": 0.7}}, "transform": {"translate": [0.6, 0.2, 1.6]}}]}},
              "transform": {"translate": [0, 0, 0.5]}}]}"#,
    camera_inside_union => r#"{"camera": {"position": [0, 0, 0], "look_at": [0, 0, 1], "vfov_deg": 70},
            "objects": [{"shape": {"union": {"children": [
                {"shape": {"sphere": {"radius": 2}}, "transform": {"translate": [0, 0, 0.5]}},
                {"shape": {"sphere": {"radius": 2}}, "transform": {"translate": [1.5, 0, 1.5]}, "material": {"color": [1, 0, 0]}}]}}}]}"#,
    camera_inside_repeat => r#"{"camera": {"position": [0, 0, 0], "look_at": [0.3, 0.2, 1], "vfov_deg": 80},
            "objects": [{"shape": {"repeat": {"period": [1.2, 0, 1.2], "count": [3, null, 3],
                "child": {"shape": {"sphere": {"radius": 1}}}}}}]}"#,
    // A flattened, rotated sphere in front of a two-sided triangle, seen with a 5 degree
    // field of view: sphere tracing once reported interior pixels of the triangle as misses.
    flat_ellipsoid_before_triangle => r#"{"camera": {"position": [6, 8, -60], "look_at": [0, 0.5, 0], "vfov_deg": 5},
            "objects": [
                {"shape": {"triangle": {"vertices": [[-2, -1, 1], [2, -0.8, 1.5], [0.2, 2.2, 2]]}}},
                {"shape": {"sphere": {"radius": 2}}, "transform": {"translate": [0.3, -1.2, -0.5],
                    "rotate_deg": [-10, 0, 5], "scale": [0.6, 0.08, 0.5]}, "material": {"color": [1, 0, 0]}}]}"#,
    bunny => r#"{"camera": {"position": [0, 2, -5.5], "look_at": [0, 1.2, 0], "vfov_deg": 40},
            "objects": [{"shape": {"mesh": {"path": "meshes/bunny.obj"}}, "transform": {"scale": 0.25}}]}"#,
}

impl CaseId {
    /// The case's entry in [`CASES`].
    pub fn case(self) -> &'static Case {
        // Declared in variant order by `cases!`.
        &CASES[self as usize]
    }

    /// The test name.
    pub fn name(self) -> &'static str {
        self.case().name
    }
}

/// The repository's `scenes/` folder (mesh paths in cases resolve against it).
pub fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

/// Parses case `id` at its size ([`Case::size`]).
pub fn case_scene(id: CaseId) -> Scene {
    let case = id.case();
    let name = case.name;
    let (w, h) = case.size;
    marchmesh_scene::parse_scene(case.json, case.name, &scenes_dir())
        .and_then(|s| s.with_image_size(w, h).map_err(|e| panic!("{e}")))
        .unwrap_or_else(|e| panic!("conformance case {name} is invalid: {e}"))
}

/// The outcome of one case.
#[derive(Debug, Clone)]
pub struct CaseResult {
    /// Accuracy against the reference.
    pub accuracy: Accuracy,
    /// The backend's render counters.
    pub stats: RenderStats,
}

/// A function that builds a geometry for a scene.
pub type Builder<'a, E> = &'a dyn Fn(&Scene) -> Result<Box<dyn Geometry>, E>;

/// Renders case `id` with both builders and compares.
pub fn run_case<E1: std::fmt::Display, E2: std::fmt::Display>(
    id: CaseId,
    backend: Builder<'_, E1>,
    reference: Builder<'_, E2>,
) -> CaseResult {
    let name = id.name();
    let scene = case_scene(id);
    let bg = BackgroundSampler::load(&scene.background).expect("colour background");
    let opts = RenderOptions {
        threads: 1,
        ..Default::default()
    };
    let g = backend(&scene).unwrap_or_else(|e| panic!("{name}: backend failed to build: {e}"));
    let r = reference(&scene).unwrap_or_else(|e| panic!("{name}: reference failed to build: {e}"));
    let test = render(&scene, g.as_ref(), &bg, &opts, &|| {}).expect("render");
    let truth = render(&scene, r.as_ref(), &bg, &opts, &|| {}).expect("reference render");
    let accuracy = compare(&test.framebuffer, &truth.framebuffer).expect("same size");
    assert!(
        truth.framebuffer.depth.iter().any(|d| d.is_finite()),
        "{name}: the reference hit nothing; the case is broken"
    );
    CaseResult {
        accuracy,
        stats: test.stats,
    }
}

/// Renders case `id` with backend `B` at `settings` and with the reference (both within the
/// default memory limit), and compares.
pub fn run_backend_case<B: Backend>(id: CaseId, settings: &B::Settings) -> CaseResult {
    let backend = |scene: &Scene| {
        B::build(scene, settings, DEFAULT_MEMORY_LIMIT_BYTES)
            .map(|g| Box::new(g) as Box<dyn Geometry>)
    };
    let reference = |scene: &Scene| {
        ReferenceBackend::build(scene, &Default::default(), DEFAULT_MEMORY_LIMIT_BYTES)
            .map(|g| Box::new(g) as Box<dyn Geometry>)
    };
    run_case(id, &backend, &reference)
}

/// Cases whose silhouette must match the reference to [`TWO_PIXEL_SILHOUETTE`] pixels on every
/// backend, whatever its tolerance says: minimal scenes where any disagreement is a bug in
/// what the scene means, not an approximation (the camera-inside and sdf-holes scenes).
pub const TWO_PIXEL_CASES: &[CaseId] = &[
    CaseId::camera_inside_one,
    CaseId::camera_inside_subtraction_seam,
    CaseId::flat_ellipsoid_before_triangle,
];

/// Silhouette pixels allowed on [`TWO_PIXEL_CASES`].
pub const TWO_PIXEL_SILHOUETTE: usize = 2;

/// Panics with every violated bound of `tol` (and of [`TWO_PIXEL_CASES`]).
pub fn check(id: CaseId, r: &CaseResult, tol: &Tolerance) {
    let name = id.name();
    let a = &r.accuracy;
    let mut failures = Vec::new();
    if TWO_PIXEL_CASES.contains(&id) && a.silhouette_mismatch > TWO_PIXEL_SILHOUETTE {
        failures.push(format!(
            "{} silhouette pixels > {TWO_PIXEL_SILHOUETTE}",
            a.silhouette_mismatch
        ));
    }
    if a.non_finite > 0 || r.stats.non_finite_hits > 0 || r.stats.non_finite_pixels > 0 {
        failures.push(format!(
            "non-finite values: {} pixels, {} hits",
            a.non_finite, r.stats.non_finite_hits
        ));
    }
    failures.extend(tol.violations(&marchmesh_core::Measured::of(a, &r.stats)));
    assert!(
        failures.is_empty(),
        "conformance case `{name}` failed:\n  {}\naccuracy: {a:#?}",
        failures.join("\n  ")
    );
}

/// Instantiates one `#[test]` per conformance case for a backend.
///
/// `backend` is the backend's type (a [`Backend`]), run against the reference; `settings`
/// (optional) an expression of its settings type (default: its defaults); `tolerance` a
/// function `fn(CaseId) -> Tolerance` giving the bounds for each case. The lists below must
/// name every [`CaseId`] exactly once: an exhaustive match in the expansion fails to compile
/// when one is missing, and a misspelt one does not exist.
/// Two groups can be marked `#[ignore = reason]` for a backend that does not meet them yet:
/// `ignore_inside_overlapping = "reason"` (a camera inside overlapping solids:
/// `camera_inside_one`, `camera_inside_two`, `camera_inside_union`, `camera_inside_repeat`) and
/// `ignore_flat_ellipsoid = "reason"` (`flat_ellipsoid_before_triangle`).
#[macro_export]
macro_rules! conformance_suite {
    (backend = $backend:ty $(, settings = $settings:expr)?, tolerance = $tol:expr
     $(, ignore_inside_overlapping = $inside:literal)? $(, ignore_flat_ellipsoid = $flat:literal)? $(,)?) => {
        /// The settings every case builds the backend with.
        fn conformance_settings() -> <$backend as $crate::Backend>::Settings {
            $crate::conformance_suite!(@or_default $($settings)?)
        }
        /// Runs case `id`.
        fn conformance_run(id: $crate::CaseId) -> $crate::CaseResult {
            $crate::run_backend_case::<$backend>(id, &conformance_settings())
        }
        $crate::conformance_suite!(@all $tol, [$($inside)?], [$($flat)?];
            [sphere, box_rotated, ellipsoid, cylinder, torus, plane_and_sphere_shadow, triangle,
             nonuniform_scale, union, intersection, subtraction, smooth_union,
             smooth_intersection, smooth_subtraction, blend, rounded_box, capsule, capped_cone,
             repeat_finite,
             repeat_overlapping, repeat_infinite, tiny_scale, huge_scale, far_from_origin,
             camera_inside_subtraction, camera_inside_subtraction_seam, bunny],
            [camera_inside_one, camera_inside_two, camera_inside_union, camera_inside_repeat],
            [flat_ellipsoid_before_triangle]);
    };
    (@or_default) => { Default::default() };
    (@or_default $settings:expr) => { $settings };
    (@all $tol:expr, [$($inside:literal)?], [$($flat:literal)?];
     [$($plain:ident),*], [$($overlapping:ident),*], [$($ellipsoid:ident),*]) => {
        $crate::conformance_suite!(@group $tol, []; $($plain),*);
        $crate::conformance_suite!(@group $tol, [$($inside)?]; $($overlapping),*);
        $crate::conformance_suite!(@group $tol, [$($flat)?]; $($ellipsoid),*);
        /// Compile-time check that the lists above name every case.
        #[allow(dead_code)]
        fn every_case_is_listed(id: $crate::CaseId) {
            match id {
                $($crate::CaseId::$plain => {})*
                $($crate::CaseId::$overlapping => {})*
                $($crate::CaseId::$ellipsoid => {})*
            }
        }
    };
    (@group $tol:expr, []; $($name:ident),* $(,)?) => {
        $crate::conformance_suite!(@cases $tol, any(), ""; $($name),*);
    };
    (@group $tol:expr, [$reason:literal]; $($name:ident),* $(,)?) => {
        $crate::conformance_suite!(@cases $tol, all(), $reason; $($name),*);
    };
    (@cases $tol:expr, $ignore:meta, $reason:literal; $($name:ident),* $(,)?) => {
        $(
            #[test]
            #[cfg_attr($ignore, ignore = $reason)]
            fn $name() {
                let id = $crate::CaseId::$name;
                let tol: fn($crate::CaseId) -> $crate::Tolerance = $tol;
                let r = conformance_run(id);
                $crate::check(id, &r, &tol(id));
            }
        )*
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_case_parses_at_its_size_and_ids_index_their_entries() {
        for (k, c) in CASES.iter().enumerate() {
            assert_eq!(c.id as usize, k, "{}", c.name);
            assert_eq!(c.id.name(), c.name);
            let s = case_scene(c.id);
            assert_eq!((s.camera.width, s.camera.height), c.size, "{}", c.name);
        }
        assert_eq!(CaseId::sphere.case().size, (SIDE, SIDE));
        assert_eq!(
            CaseId::camera_inside_subtraction_seam.case().size,
            (256, 192)
        );
    }
}
