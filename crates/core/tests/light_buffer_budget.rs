//! Light and ambient-occlusion samples at their caps do not queue unbounded ray buffers: at
//! 1024 samples per pixel, 4096 area-light samples and 4096 AO samples one pixel's wavefront
//! would queue 4M shadow and 4M AO rays (over half a gigabyte) in one batch; they are traced
//! in bounded batches instead. Peak heap is measured by a counting allocator in this test
//! binary; the geometry is one analytic sphere, so the test needs no backend.

// A global allocator is `unsafe` to implement; this one only forwards and counts.
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::Vec3;
use marchmesh_core::{
    BackgroundSampler, Geometry, GeometryReport, Hit, OcclusionResult, Ray, RayWork, RenderOptions,
    TraceResult, render,
};

struct Counting;

static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator; only counts sizes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let now = CURRENT.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
        PEAK.fetch_max(now, Ordering::Relaxed);
        // SAFETY: the caller upholds `GlobalAlloc::alloc`'s contract.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        CURRENT.fetch_sub(layout.size(), Ordering::Relaxed);
        // SAFETY: `ptr` was allocated by `alloc` with `layout`.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// A unit sphere at the render-space point `centre`.
struct Sphere {
    centre: Vec3,
}

impl Geometry for Sphere {
    fn closest_hit(&self, ray: &Ray) -> TraceResult {
        let oc = ray.origin - self.centre;
        let b = oc.dot(ray.dir);
        let disc = b * b - (oc.length_squared() - 1.0);
        let hit = (disc >= 0.0)
            .then(|| {
                let s = disc.sqrt();
                [-b - s, -b + s]
                    .into_iter()
                    .find(|&t| t >= ray.t_min && t <= ray.t_max)
            })
            .flatten()
            .map(|t| {
                let p = ray.at(t);
                Hit {
                    t,
                    position: p,
                    normal: p - self.centre,
                    material: 0,
                }
            });
        TraceResult::found_or_miss(hit, RayWork::default())
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
            backend: "test-sphere".into(),
            ..Default::default()
        }
    }
}

#[test]
fn samples_at_their_caps_are_traced_in_bounded_batches() {
    let scene = marchmesh_testkit::scene(
        r#"{
      "camera": {"position": [0, 0, -5], "look_at": [0, 0, 0], "vfov_deg": 10, "width": 1, "height": 1},
      "lights": [{"ambient": {"intensity": 0.3}},
                 {"rectangle_light": {"corner": [-1, 3, -3], "edge_u": [2, 0, 0], "edge_v": [0, 0, 2], "intensity": 1}}],
      "objects": [{"shape": {"sphere": {"radius": 1}}}],
      "render": {"samples_per_pixel": 1024, "area_light_samples": 4096,
                 "ambient_occlusion": {"samples": 4096, "distance": 1}}
    }"#,
    );
    let geometry = Sphere {
        centre: (-scene.camera.position).as_vec3(),
    };
    let background = BackgroundSampler::load(&scene.background).expect("colour");
    let options = RenderOptions {
        threads: 1,
        ..Default::default()
    };
    let before = CURRENT.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    let out = render(&scene, &geometry, &background, &options, &|| {}).expect("render");
    let peak = PEAK.load(Ordering::Relaxed) - before;
    // Every sample was still traced.
    assert_eq!(out.stats.ao_rays, 1024 * 4096);
    assert!(
        out.stats.shadow_rays > 1024 * 1024,
        "{}",
        out.stats.shadow_rays
    );
    assert!(out.framebuffer.color[0].max_element() > 0.0);
    // Unbatched, the shadow and AO queues alone took over 500 MB.
    assert!(peak < 256 << 20, "peak heap {} MiB", peak >> 20);
}
