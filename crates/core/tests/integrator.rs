//! Integrator tests against a minimal analytic sphere geometry defined here, so the core is
//! tested without any backend.

use glam::Vec3;
use marchmesh_core::{
    BackgroundSampler, Geometry, GeometryReport, Hit, OcclusionResult, Ray, RayWork, RenderOptions,
    Termination, TraceResult, render, render_into,
};
use marchmesh_scene::{Scene, parse_scene};

/// Spheres (render-space centre, radius, material) intersected in closed form.
struct Spheres(Vec<(Vec3, f32, u32)>);

impl Spheres {
    fn from_scene(scene: &Scene) -> Self {
        let origin = scene.camera.position;
        let mut v = Vec::new();
        scene.visit_nodes(|n| {
            if let marchmesh_scene::NodeKind::Leaf(marchmesh_scene::Shape::Sphere { radius }) =
                n.kind
            {
                let c = (n.transform.translation - origin).as_vec3();
                v.push((c, radius as f32, n.material));
            }
        });
        Spheres(v)
    }
}

impl Geometry for Spheres {
    fn closest_hit(&self, ray: &Ray) -> TraceResult {
        let mut best: Option<Hit> = None;
        for &(c, r, m) in &self.0 {
            let oc = ray.origin - c;
            let b = oc.dot(ray.dir);
            let disc = b * b - (oc.length_squared() - r * r);
            if disc < 0.0 {
                continue;
            }
            let s = disc.sqrt();
            for t in [-b - s, -b + s] {
                if t >= ray.t_min && t <= ray.t_max && best.is_none_or(|h| t < h.t) {
                    let p = ray.at(t);
                    best = Some(Hit {
                        t,
                        position: p,
                        normal: (p - c) / r,
                        material: m,
                    });
                    break;
                }
            }
        }
        TraceResult::found_or_miss(
            best,
            RayWork {
                primitive_tests: self.0.len() as u32,
                ..Default::default()
            },
        )
    }

    fn occluded(&self, ray: &Ray) -> OcclusionResult {
        let r = self.closest_hit(ray);
        OcclusionResult {
            occluded: r.hit().is_some(),
            termination: r.termination(),
            work: r.work,
        }
    }

    fn report(&self) -> GeometryReport {
        GeometryReport {
            backend: "test-spheres".into(),
            ..Default::default()
        }
    }
}

use marchmesh_testkit::scene;

fn run(scene: &Scene, threads: usize) -> marchmesh_core::RenderOutput {
    marchmesh_testkit::render_with(scene, &Spheres::from_scene(scene), threads)
}

const ONE_SPHERE: &str = r#"{
  "camera": {"position": [0, 0, -5], "look_at": [0, 0, 0], "vfov_deg": 30, "width": 33, "height": 33},
  "background": {"color": [0.1, 0.2, 0.3]},
  "lights": [{"ambient": {"intensity": 0.25}},
             {"directional": {"direction": [0, 0, -1], "intensity": 0.5, "casts_shadows": false}}],
  "objects": [{"shape": {"sphere": {"radius": 1}}, "material": {"color": [0.8, 0.4, 0.2]}}]
}"#;

#[test]
fn diffuse_and_ambient_match_the_phong_formula_and_misses_show_the_background() {
    let s = scene(ONE_SPHERE);
    let out = run(&s, 1);
    let fb = &out.framebuffer;
    // Centre pixel looks straight at the sphere: n.l = 1 -> colour * (0.25 + 0.5).
    let c = fb.color[16 * 33 + 16];
    assert!(
        (c - Vec3::new(0.8, 0.4, 0.2) * 0.75).length() < 1e-5,
        "{c:?}"
    );
    assert!((fb.depth[16 * 33 + 16] - 4.0).abs() < 1e-5);
    assert!((fb.normal[16 * 33 + 16] - Vec3::NEG_Z).length() < 1e-5);
    // Corner pixel misses.
    assert_eq!(fb.color[0], Vec3::new(0.1, 0.2, 0.3));
    assert!(fb.depth[0].is_infinite());
    assert_eq!(fb.termination[0], Termination::Miss);
    // No shadow rays for a light that casts none, no reflection rays without reflectivity.
    assert_eq!(out.stats.shadow_rays, 0);
    assert_eq!(out.stats.reflection_rays, 0);
    assert_eq!(out.stats.primary_rays, 33 * 33);
}

/// A hit skips the secondary rays' origin and the sample key when no light casts shadows: the
/// colours are the bits of a render whose light casts shadows that nothing blocks (a lone
/// convex sphere never shadows its own lit side), and the counters of the camera rays agree.
#[test]
fn shadowless_lights_shade_the_bits_of_unblocked_shadowed_ones() {
    let lit = ONE_SPHERE.replace(
        r#""direction": [0, 0, -1]"#,
        r#""direction": [0.3, 0.5, -1]"#,
    );
    let shadowed = lit.replace(r#""casts_shadows": false"#, r#""casts_shadows": true"#);
    assert_ne!(lit, shadowed);
    let (a, b) = (run(&scene(&lit), 1), run(&scene(&shadowed), 1));
    assert_eq!(a.stats.shadow_rays, 0);
    assert!(b.stats.shadow_rays > 0);
    let bits = |c: &[Vec3]| -> Vec<[u32; 3]> {
        c.iter().map(|v| v.to_array().map(f32::to_bits)).collect()
    };
    assert_eq!(bits(&a.framebuffer.color), bits(&b.framebuffer.color));
    assert_eq!(a.stats.hits, b.stats.hits);
    assert!(a.stats.hits > 0);
    assert_eq!(a.stats.primary_rays, b.stats.primary_rays);
}

/// The direct hit pass (a scene of point, directional and ambient lights without ambient
/// occlusion) shades the bits of the general hit loop: the same scene with one more light, an
/// area light far out of view that casts no shadows (so every hit takes the general loop) and
/// emits nothing (so it adds nothing), gives the same colours, AOV planes and counters. Point
/// and directional lights, with and without shadows (the spheres shadow each other), a
/// specular and a half-mirror sphere (its hits left to the general loop, their reflections
/// shaded by the direct pass at depth 1), one sample a pixel (hits shaded eight at a time)
/// and three, tiles cut at the image's edges.
#[test]
fn direct_hit_pass_shades_the_bits_of_the_general_loop() {
    for spp in [1, 3] {
        for shadows in [false, true] {
            direct_pass_matches_the_general_loop(spp, shadows);
        }
    }
}

fn direct_pass_matches_the_general_loop(spp: u32, shadows: bool) {
    let direct = r#"{
      "camera": {"position": [0.3, 0.2, -6], "look_at": [0, 0, 0], "vfov_deg": 40, "width": 37, "height": 21},
      "background": {"color": [0.1, 0.2, 0.3]},
      "lights": [{"ambient": {"intensity": 0.15}},
                 {"point": {"position": [3, 4, -5], "intensity": 0.6, "casts_shadows": SHADOWS}},
                 {"directional": {"direction": [-0.4, 0.5, -1], "intensity": 0.35, "casts_shadows": SHADOWS}},
                 {"point": {"position": [-4, -1, -2], "intensity": 0.3, "casts_shadows": false}}],
      "objects": [
        {"shape": {"sphere": {"radius": 1}}, "transform": {"translate": [-1.1, 0, 0]},
         "material": {"color": [0.8, 0.4, 0.2], "specular_exponent": 12}},
        {"shape": {"sphere": {"radius": 0.9}}, "transform": {"translate": [1.0, 0.1, 0.4]},
         "material": {"color": [0.3, 0.7, 0.9], "reflectivity": 0.4}}
      ],
      "render": {"samples_per_pixel": SPP, "max_reflection_depth": 2}
    }"#
    .replace("SPP", &spp.to_string())
    .replace("SHADOWS", &shadows.to_string());
    let general = direct.replace(
        r#"{"ambient": {"intensity": 0.15}},"#,
        r#"{"ambient": {"intensity": 0.15}},
           {"sphere_light": {"position": [0, -60, 0], "radius": 1e-4, "intensity": 0, "casts_shadows": false}},"#,
    );
    assert_ne!(direct, general);
    let (a, b) = (run(&scene(&direct), 1), run(&scene(&general), 2));
    let bits = |v: &[Vec3]| -> Vec<[u32; 3]> {
        v.iter().map(|c| c.to_array().map(f32::to_bits)).collect()
    };
    let (fa, fb) = (&a.framebuffer, &b.framebuffer);
    assert_eq!(bits(&fa.color), bits(&fb.color));
    assert_eq!(bits(&fa.normal), bits(&fb.normal));
    assert_eq!(
        fa.depth.iter().map(|d| d.to_bits()).collect::<Vec<_>>(),
        fb.depth.iter().map(|d| d.to_bits()).collect::<Vec<_>>()
    );
    assert_eq!(fa.material, fb.material);
    assert_eq!(fa.termination, fb.termination);
    assert_eq!(fa.work, fb.work);
    assert!(fa.material.contains(&1) && fa.material.contains(&2));
    assert_eq!(a.stats.shadow_rays, b.stats.shadow_rays);
    assert_eq!(a.stats.shadow_rays > 0, shadows);
    assert!(a.stats.reflection_rays > 0);
    let counters = |s: &marchmesh_core::RenderStats| {
        (
            s.primary_rays,
            s.reflection_rays,
            s.hits,
            s.primitive_tests,
            s.non_finite_pixels,
        )
    };
    assert_eq!(counters(&a.stats), counters(&b.stats));
}

#[test]
fn specular_highlight_adds_to_diffuse() {
    let json = ONE_SPHERE.replace(
        r#""material": {"color": [0.8, 0.4, 0.2]}"#,
        r#""material": {"color": [0.8, 0.4, 0.2], "specular_exponent": 10}"#,
    );
    let out = run(&scene(&json), 1);
    // At the centre r = n = v, so r.v = 1 and specular = intensity 0.5: colour * (0.75 + 0.5).
    let c = out.framebuffer.color[16 * 33 + 16];
    assert!(
        (c - Vec3::new(0.8, 0.4, 0.2) * 1.25).length() < 1e-5,
        "{c:?}"
    );
}

#[test]
fn shadows_block_direct_light_but_not_ambient() {
    // A small sphere, out of the camera's view, between a point light and a big sphere.
    let json = r#"{
      "camera": {"position": [0, 0, -10], "look_at": [0, 0, 0], "vfov_deg": 20, "width": 21, "height": 21},
      "lights": [{"ambient": {"intensity": 0.1}},
                 {"point": {"position": [5, 0, -9], "intensity": 0.9}}],
      "objects": [
        {"shape": {"sphere": {"radius": 2}}, "transform": {"translate": [0, 0, 3]}, "material": {"color": [1, 1, 1]}},
        {"shape": {"sphere": {"radius": 0.3}}, "transform": {"translate": [2.46, 0, -2.91]}, "material": {"color": [1, 0, 0]}}
      ]
    }"#;
    let s = scene(json);
    let out = run(&s, 1);
    assert!(out.stats.shadow_rays > 0);
    let fb = &out.framebuffer;
    // The small sphere is outside the image.
    assert!(fb.material.iter().all(|&m| m != 2));
    // Some pixel of the big sphere must be in the small sphere's shadow: only ambient (0.1).
    let shadowed = (0..fb.len())
        .filter(|&i| fb.material[i] == 1 && (fb.color[i] - Vec3::splat(0.1)).length() < 1e-4)
        .count();
    assert!(shadowed > 0, "no shadowed pixel on the big sphere");
}

#[test]
fn mirror_sphere_reflects_background_and_obeys_depth_limit() {
    let json = r#"{
      "camera": {"position": [0, 0, -5], "look_at": [0, 0, 0], "vfov_deg": 30, "width": 9, "height": 9},
      "background": {"color": [0.2, 0.6, 1.0]},
      "lights": [],
      "objects": [{"shape": {"sphere": {"radius": 1}}, "material": {"color": [1, 1, 1], "reflectivity": 1}}],
      "render": {"max_reflection_depth": 1}
    }"#;
    let out = run(&scene(json), 1);
    let c = out.framebuffer.color[4 * 9 + 4];
    assert!((c - Vec3::new(0.2, 0.6, 1.0)).length() < 1e-6, "{c:?}");
    assert!(out.stats.reflection_rays > 0);
    let none = json.replace(
        r#""max_reflection_depth": 1"#,
        r#""max_reflection_depth": 0"#,
    );
    let out = run(&scene(&none), 1);
    assert_eq!(out.stats.reflection_rays, 0);
    // No lights, no reflection: black.
    assert_eq!(out.framebuffer.color[4 * 9 + 4], Vec3::ZERO);
}

#[test]
fn antialiasing_smooths_edges_but_aovs_stay_at_the_pixel_centre() {
    let s1 = scene(ONE_SPHERE);
    let mut s8 = s1.clone();
    s8.render.samples_per_pixel = 8;
    let a = run(&s1, 1);
    let b = run(&s8, 1);
    assert_eq!(b.stats.primary_rays, 8 * 33 * 33);
    assert_eq!(a.framebuffer.depth, b.framebuffer.depth);
    // Some edge pixel gets a colour strictly between background and surface.
    let bg = Vec3::new(0.1, 0.2, 0.3);
    let mixed = a
        .framebuffer
        .color
        .iter()
        .zip(&b.framebuffer.color)
        .filter(|(x, y)| (**x - **y).length() > 1e-3)
        .count();
    assert!(mixed > 0);
    assert!(
        b.framebuffer
            .color
            .iter()
            .all(|c| c.is_finite() && c.min_element() >= 0.0)
    );
    assert!(
        b.framebuffer
            .color
            .iter()
            .any(|c| (*c - bg).length() < 1e-6)
    );
}

#[test]
fn thread_count_does_not_change_the_image() {
    let s = scene(ONE_SPHERE);
    let a = run(&s, 1);
    let b = run(&s, 2);
    assert_eq!(a.framebuffer, b.framebuffer);
    // Every counter but the measured trace times.
    let untimed = |mut s: marchmesh_core::RenderStats| {
        s.trace_time = Default::default();
        s
    };
    assert_eq!(untimed(a.stats), untimed(b.stats));
}

#[test]
fn renders_without_aovs_have_the_same_colour_and_counters_and_empty_aov_planes() {
    // A mirror sphere over a matte one (reflection wavefronts, hits and misses), 3 samples;
    // the same scene through the path tracer.
    let whitted = r#"{
  "camera": {"position": [0, 0, -5], "look_at": [0, 0, 0], "vfov_deg": 40, "width": 21, "height": 19},
  "background": {"color": [0.1, 0.2, 0.3]},
  "lights": [{"ambient": {"intensity": 0.2}},
             {"point": {"position": [3, 4, -4], "intensity": 0.7}}],
  "render": {"samples_per_pixel": 3, "integrator": "INTEGRATOR"},
  "objects": [
    {"shape": {"sphere": {"radius": 1}}, "material": {"color": [0.8, 0.8, 0.8], "reflectivity": 0.6}},
    {"shape": {"sphere": {"radius": 0.5}}, "transform": {"translate": [1.2, 0.8, -1]},
     "material": {"color": [0.9, 0.3, 0.1]}}]
}"#;
    for integrator in ["whitted", "path"] {
        let s = scene(&whitted.replace("INTEGRATOR", integrator));
        let g = Spheres::from_scene(&s);
        let bg = BackgroundSampler::load(&s.background).unwrap();
        let with = |aovs| RenderOptions {
            threads: 1,
            aovs,
            ..Default::default()
        };
        let full = render(&s, &g, &bg, &with(true), &|| {}).unwrap();
        assert!(full.framebuffer.has_aovs());
        assert!(full.framebuffer.is_hit(10 * 21 + 10) && !full.framebuffer.is_hit(0));
        // One reused output, switching between the two layouts.
        let mut out = marchmesh_core::RenderOutput::default();
        for aovs in [false, true, false] {
            render_into(&s, &g, &bg, &with(aovs), &|| {}, &mut out).unwrap();
            let fb = &out.framebuffer;
            assert_eq!(
                fb.color, full.framebuffer.color,
                "{integrator}, aovs {aovs}"
            );
            assert_eq!(fb.has_aovs(), aovs);
            if aovs {
                assert_eq!(*fb, full.framebuffer);
            } else {
                assert!(fb.depth.is_empty() && fb.normal.is_empty() && fb.material.is_empty());
                assert!(fb.termination.is_empty() && fb.work.is_empty());
            }
            let untimed = |mut s: marchmesh_core::RenderStats| {
                s.trace_time = Default::default();
                s
            };
            assert_eq!(untimed(out.stats), untimed(full.stats), "{integrator}");
        }
    }
}

#[test]
fn non_finite_colours_are_written_black_and_counted() {
    // Lights so bright that the centre of the sphere overflows f32: those pixels are
    // blackened and counted, the rest keep their colour, with one sample and with several.
    for spp in [1, 4] {
        let mut s = scene(&ONE_SPHERE.replace(
            r#""height": 33}"#,
            &format!(r#""height": 33}}, "render": {{"samples_per_pixel": {spp}}}"#),
        ));
        // Past the scene format's validation limits, set on the parsed scene.
        for l in &mut s.lights {
            // The sum of the samples, 0.8 x (2e38 + 3e38 n.l), overflows where n.l > 0.75.
            let share = 1.0 / spp as f64;
            match l {
                marchmesh_scene::Light::Ambient { intensity } => *intensity = 2e38 * share,
                marchmesh_scene::Light::Directional { intensity, .. } => *intensity = 3e38 * share,
                _ => unreachable!("ONE_SPHERE has an ambient and a directional light"),
            }
        }
        let out = run(&s, 1);
        let fb = &out.framebuffer;
        let black = fb.color.iter().filter(|c| **c == Vec3::ZERO).count();
        assert!(fb.color.iter().all(|c| c.is_finite()));
        assert!(black > 10 && black < fb.len() / 2, "{black} black pixels");
        assert_eq!(out.stats.non_finite_pixels, black as u64, "spp {spp}");
        assert!((0..fb.len()).any(|i| fb.is_hit(i) && fb.color[i] != Vec3::ZERO));
    }
}

#[test]
fn render_refuses_buffers_over_the_memory_limit() {
    let s = scene(ONE_SPHERE);
    let g = Spheres::from_scene(&s);
    let bg = BackgroundSampler::load(&s.background).unwrap();
    let err = render(
        &s,
        &g,
        &bg,
        &RenderOptions {
            threads: 1,
            memory_limit_bytes: 1000,
            ..Default::default()
        },
        &|| {},
    )
    .unwrap_err();
    assert!(err.to_string().contains("over the limit"), "{err}");
}

/// Checks that each primary batch's `PrimarySamples` are the exact rays the f32 rays round,
/// in the documented order (sample-major, then the tile's pixels row-major), and counts the primary batches.
struct PrimaryOrderProbe {
    batches: std::sync::atomic::AtomicUsize,
    rays: std::sync::atomic::AtomicUsize,
    /// What `Geometry::tile_width` answers.
    tile_width: u32,
    /// Width of the widest tile a camera batch came from.
    widest: std::sync::atomic::AtomicU32,
}

impl PrimaryOrderProbe {
    fn new(tile_width: u32) -> Self {
        Self {
            batches: 0.into(),
            rays: 0.into(),
            tile_width,
            widest: 0.into(),
        }
    }
}

impl Geometry for PrimaryOrderProbe {
    fn tile_width(&self) -> u32 {
        self.tile_width
    }

    fn closest_hit(&self, _ray: &Ray) -> TraceResult {
        TraceResult::default()
    }

    fn occluded(&self, _ray: &Ray) -> OcclusionResult {
        OcclusionResult::default()
    }

    fn closest_hits_primary(
        &self,
        rays: &[Ray],
        samples: marchmesh_core::PrimarySamples<'_>,
        out: &mut [TraceResult],
    ) {
        for (i, r) in rays.iter().enumerate() {
            let exact = samples.direction(i);
            assert!(
                (r.dir.as_dvec3() - exact).length() < 1e-6,
                "ray {i}: f32 {:?} is not the rounding of {exact:?}",
                r.dir
            );
            assert_eq!(r.origin, Vec3::ZERO);
        }
        self.batches
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.rays
            .fetch_add(rays.len(), std::sync::atomic::Ordering::Relaxed);
        self.widest.fetch_max(
            samples.tile_bounds().width,
            std::sync::atomic::Ordering::Relaxed,
        );
        self.closest_hits(rays, out);
    }

    fn report(&self) -> GeometryReport {
        GeometryReport::default()
    }
}

#[test]
fn primary_batches_carry_their_exact_camera_samples_in_order() {
    let scene = parse_scene(
        r#"{"camera": {"position": [3, 1, -2], "look_at": [0, 0.5, 1], "vfov_deg": 50, "width": 13, "height": 7},
            "objects": [{"shape": {"sphere": {}}}], "render": {"samples_per_pixel": 3}}"#,
        "<test>",
        std::path::Path::new("."),
    )
    .unwrap();
    let probe = PrimaryOrderProbe::new(marchmesh_core::TILE_WIDTH);
    let bg = BackgroundSampler::load(&scene.background).unwrap();
    let opts = RenderOptions {
        threads: 1,
        ..Default::default()
    };
    render(&scene, &probe, &bg, &opts, &|| {}).unwrap();
    // One primary batch per screen tile: 13x7 pixels are an 8x7 and a 5x7 tile.
    assert_eq!(
        probe.batches.into_inner(),
        13usize.div_ceil(marchmesh_core::TILE_WIDTH as usize)
            * 7usize.div_ceil(marchmesh_core::TILE_HEIGHT as usize)
    );
    assert_eq!(probe.rays.into_inner(), 13 * 7 * 3);
}

#[test]
fn tile_width_follows_the_geometry_up_to_the_ray_cap() {
    use marchmesh_core::tile_width;
    // Multiples of 8, from 8 to 64, at most TILE_RAYS (512) camera rays a tile of 8 rows.
    assert_eq!(tile_width(64, 1), 64);
    assert_eq!(tile_width(1000, 1), 64);
    assert_eq!(tile_width(20, 1), 16);
    assert_eq!(tile_width(0, 1), 8);
    assert_eq!(tile_width(64, 2), 32);
    assert_eq!(tile_width(64, 3), 16);
    assert_eq!(tile_width(64, 16), 8);
    assert_eq!(tile_width(64, 0), 64);
    // Rendered: 70x9 pixels are two bands (8 rows and 1); a geometry asking for 64 columns
    // gets a 64-wide and a 6-wide tile per band at one sample, 16-wide tiles at three.
    for (spp, width, tiles_per_band) in [(1, 64, 2), (3, 16, 5)] {
        let scene = parse_scene(
            &format!(
                r#"{{"camera": {{"position": [3, 1, -2], "look_at": [0, 0.5, 1], "vfov_deg": 50, "width": 70, "height": 9}},
                "objects": [{{"shape": {{"sphere": {{}}}}}}], "render": {{"samples_per_pixel": {spp}}}}}"#
            ),
            "<test>",
            std::path::Path::new("."),
        )
        .unwrap();
        let probe = PrimaryOrderProbe::new(64);
        let bg = BackgroundSampler::load(&scene.background).unwrap();
        let opts = RenderOptions {
            threads: 1,
            ..Default::default()
        };
        render(&scene, &probe, &bg, &opts, &|| {}).unwrap();
        assert_eq!(probe.batches.into_inner(), 2 * tiles_per_band, "{spp} spp");
        assert_eq!(probe.widest.into_inner(), width, "{spp} spp");
        assert_eq!(probe.rays.into_inner(), 70 * 9 * spp as usize);
    }
}

/// Misses everything after busy-waiting `per_batch` (by `Instant`) in each closest-hit
/// batch, counting the batches.
struct Busy {
    per_batch: std::time::Duration,
    batches: std::sync::atomic::AtomicUsize,
}

impl Geometry for Busy {
    fn closest_hit(&self, _: &Ray) -> TraceResult {
        TraceResult::found_or_miss(None, RayWork::default())
    }

    fn occluded(&self, _: &Ray) -> OcclusionResult {
        OcclusionResult::default()
    }

    fn closest_hits(&self, rays: &[Ray], out: &mut [TraceResult]) {
        let t = std::time::Instant::now();
        while t.elapsed() < self.per_batch {}
        self.batches
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        for (r, o) in rays.iter().zip(out) {
            *o = self.closest_hit(r);
        }
    }

    fn report(&self) -> GeometryReport {
        GeometryReport::default()
    }
}

#[test]
fn geometry_times_are_the_nanoseconds_the_queries_took() {
    // 16x16 pixels: four camera batches of at least 3 ms each.
    let json = ONE_SPHERE.replace(
        r#""width": 33, "height": 33"#,
        r#""width": 16, "height": 16"#,
    );
    let scene = scene(&json);
    let busy = Busy {
        per_batch: std::time::Duration::from_millis(3),
        batches: 0.into(),
    };
    let bg = BackgroundSampler::load(&scene.background).unwrap();
    let opts = RenderOptions {
        threads: 1,
        ..Default::default()
    };
    let out = render(&scene, &busy, &bg, &opts, &|| {}).unwrap();
    assert_eq!(busy.batches.into_inner(), 4);
    let t = out.stats.trace_time;
    let least = 4 * 3_000_000;
    // At least the busy-waits, at most the whole render (which holds them), up to the
    // clock's calibration error.
    let most = out.elapsed.as_nanos() as u64 + out.elapsed.as_nanos() as u64 / 1000;
    assert!(
        t.camera_ns >= least * 99 / 100 && t.camera_ns <= most,
        "camera {} ns, render {:?}",
        t.camera_ns,
        out.elapsed
    );
    assert_eq!(
        (t.shadow_ns, t.bounce_ns, t.ambient_occlusion_ns),
        (0, 0, 0)
    );
}

/// [`Spheres`] asking for [`BatchPolicy::Columns`], recording the primary batches' sizes and
/// the threads that traced them.
struct ColumnSpheres {
    inner: Spheres,
    batches: std::sync::Mutex<Vec<(usize, std::thread::ThreadId)>>,
}

impl Geometry for ColumnSpheres {
    fn batch_policy(&self) -> marchmesh_core::BatchPolicy {
        marchmesh_core::BatchPolicy::Columns
    }

    fn closest_hit(&self, ray: &Ray) -> TraceResult {
        self.inner.closest_hit(ray)
    }

    fn occluded(&self, ray: &Ray) -> OcclusionResult {
        self.inner.occluded(ray)
    }

    fn closest_hits_primary(
        &self,
        rays: &[Ray],
        _samples: marchmesh_core::PrimarySamples<'_>,
        out: &mut [TraceResult],
    ) {
        if let Ok(mut b) = self.batches.lock() {
            b.push((rays.len(), std::thread::current().id()));
        }
        self.inner.closest_hits(rays, out);
    }

    fn report(&self) -> GeometryReport {
        self.inner.report()
    }
}

#[test]
fn column_batches_come_from_the_calling_thread_and_give_the_same_image() {
    // 70x33 at one sample: columns of 64 and 6 pixels spanning all 33 rows.
    let s = scene(&ONE_SPHERE.replace(r#""width": 33"#, r#""width": 70"#));
    let tiles = run(&s, 2);
    let columns = ColumnSpheres {
        inner: Spheres::from_scene(&s),
        batches: Default::default(),
    };
    let out = marchmesh_testkit::render_with(&s, &columns, 2);
    assert_eq!(out.framebuffer, tiles.framebuffer);
    let batches = columns.batches.into_inner().expect("no panic while locked");
    let sizes: Vec<usize> = batches.iter().map(|b| b.0).collect();
    assert_eq!(sizes, vec![64 * 33, 6 * 33]);
    assert!(
        batches.iter().all(|b| b.1 == std::thread::current().id()),
        "every column batch is traced on the thread that called render"
    );
}

/// Camera rays ending every way a closest-hit query can, by direction: to the right out of
/// steps, to the left at the maximum distance, straight up a hit, else a miss.
struct Endings;

impl Geometry for Endings {
    fn closest_hit(&self, ray: &Ray) -> TraceResult {
        let work = RayWork {
            steps: 3 + (ray.dir.x.to_bits() & 7),
            node_visits: ray.dir.y.to_bits() & 15,
            primitive_tests: 1,
        };
        if ray.dir.x > 0.05 {
            TraceResult::not_found(marchmesh_core::NoHit::MaxSteps, work)
        } else if ray.dir.x < -0.05 {
            TraceResult::not_found(marchmesh_core::NoHit::MaxDistance, work)
        } else if ray.dir.y > 0.0 {
            TraceResult::found(
                Hit {
                    t: 1.0,
                    position: ray.dir,
                    normal: -ray.dir,
                    material: 0,
                },
                work,
            )
        } else {
            TraceResult::not_found(marchmesh_core::NoHit::Miss, work)
        }
    }

    fn occluded(&self, ray: &Ray) -> OcclusionResult {
        let r = self.closest_hit(ray);
        OcclusionResult {
            occluded: r.hit().is_some(),
            termination: r.termination(),
            work: r.work,
        }
    }

    fn report(&self) -> GeometryReport {
        GeometryReport {
            backend: "test-endings".into(),
            ..Default::default()
        }
    }
}

/// The miss pass counts every termination and the work of every camera ray: the counters are
/// the sums over the AOV planes (one sample a pixel, no secondary rays).
#[test]
fn counters_sum_the_terminations_and_work_of_every_ray() {
    let s = scene(
        r#"{
      "camera": {"position": [0, 0, 0], "look_at": [0, 0, 1], "vfov_deg": 60, "width": 83, "height": 19},
      "lights": [{"ambient": {"intensity": 0.3}}],
      "objects": []
    }"#,
    );
    for threads in [1, 2] {
        let out = marchmesh_testkit::render_with(&s, &Endings, threads);
        let fb = &out.framebuffer;
        let count = |t: Termination| fb.termination.iter().filter(|&&e| e == t).count() as u64;
        for t in [
            Termination::Hit,
            Termination::Miss,
            Termination::MaxSteps,
            Termination::MaxDistance,
        ] {
            assert!(count(t) > 0, "no {t:?}");
        }
        let st = &out.stats;
        assert_eq!(st.hits, count(Termination::Hit));
        assert_eq!(st.closest_max_steps, count(Termination::MaxSteps));
        assert_eq!(st.max_distance, count(Termination::MaxDistance));
        assert_eq!(st.primary_rays, fb.len() as u64);
        let sum = |f: fn(&RayWork) -> u32| fb.work.iter().map(|w| f(w) as u64).sum::<u64>();
        assert_eq!(st.steps, sum(|w| w.steps));
        assert_eq!(st.node_visits, sum(|w| w.node_visits));
        assert_eq!(st.primitive_tests, sum(|w| w.primitive_tests));
        let max = |f: fn(&RayWork) -> u32| fb.work.iter().map(f).max().unwrap_or(0);
        assert_eq!(st.max_steps_seen, max(|w| w.steps));
        assert_eq!(st.max_node_visits_seen, max(|w| w.node_visits));
    }
}
