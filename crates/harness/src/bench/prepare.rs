//! What a configuration needs before it is timed: its scene loaded, its reference rendered,
//! its geometry built and rendered once untimed (heap, RSS, accuracy, work and images).

use std::path::Path;
use std::rc::Rc;
use std::time::Instant;

use marchmesh_core::{
    BackgroundSampler, Framebuffer, Geometry, RenderOptions, compare, image_io, render,
};
use marchmesh_scene::{RenderOverrides, Scene};

use super::configs::{portable_scene_path, slug};
use super::progress::Progress;
use super::{BenchOptions, Config};
use crate::alloc::HeapPhase;
use crate::backend::{BackendId, BackendSpec};
use crate::results::{ReferenceInfo, Row, TimingSample};
use crate::rss::RssPhase;
use crate::suite::Resolution;
use crate::{backend, images};

pub(super) type SceneKey = String;

pub(super) struct Loaded {
    pub(super) scene: Scene,
    pub(super) background: BackgroundSampler,
}

pub(super) struct Truth {
    pub(super) fb: Framebuffer,
    pub(super) size: Option<f64>,
}

/// A configuration's render overrides as `render.key=value` pairs for the options column.
pub(super) fn render_override_pairs(o: &RenderOverrides) -> Vec<String> {
    match serde_json::to_value(o) {
        Ok(serde_json::Value::Object(map)) => map
            .into_iter()
            .map(|(k, v)| format!("render.{k}={v}"))
            .collect(),
        _ => Vec::new(),
    }
}

pub(super) fn load_scene(
    path: &Path,
    res: Resolution,
    render: &RenderOverrides,
) -> Result<Loaded, String> {
    let scene = marchmesh_scene::load(path).map_err(|e| e.to_string())?;
    let (w, h) = res.apply(scene.camera.width, scene.camera.height);
    let scene = scene
        .with_image_size(w, h)
        .map_err(|e| format!("{}: image size {w}x{h}: {e}", path.display()))?
        .with_render_overrides(render)
        .map_err(|e| format!("{}: render settings: {e}", path.display()))?;
    let background = BackgroundSampler::load(&scene.background)
        .map_err(|e| format!("{}: background: {e}", path.display()))?;
    Ok(Loaded { scene, background })
}

/// A configuration built, warmed up and compared with the reference, holding its geometry
/// while it waits for its timed repeats.
pub(super) struct Prepared {
    pub(super) index: usize,
    pub(super) loaded: Rc<Loaded>,
    pub(super) geometry: Box<dyn Geometry>,
    /// Every column but the timing ones.
    pub(super) row: Row,
    pub(super) histogram: Vec<u64>,
    pub(super) samples: Vec<TimingSample>,
    /// A timed render failed: the configuration becomes a failure.
    pub(super) error: Option<String>,
    /// Images that could not be written.
    pub(super) write_errors: Vec<String>,
}

/// Notes a failed image write in `errors` (the run goes on; the CLI reports them and exits
/// nonzero).
pub(super) fn image_written(
    result: Result<(), impl std::fmt::Display>,
    path: &Path,
    errors: &mut Vec<String>,
) {
    if let Err(e) = result {
        let e = e.to_string();
        // Errors of safeio name the file already.
        if e.contains(&*path.to_string_lossy()) {
            errors.push(e);
        } else {
            errors.push(format!("{}: {e}", path.display()));
        }
    }
}

pub(super) fn reference_render(
    c: &Config,
    l: &Loaded,
    options: &BenchOptions,
    write_errors: &mut Vec<String>,
) -> (Result<Truth, String>, ReferenceInfo) {
    let (w, h) = (l.scene.camera.width, l.scene.camera.height);
    let mut info = ReferenceInfo {
        scene: c.scene.clone(),
        width: w,
        height: h,
        build_ms: None,
        render_ms: None,
        error: None,
    };
    let spec = BackendSpec {
        kind: BackendId::REFERENCE,
        options: Vec::new(),
    };
    let t0 = Instant::now();
    let geometry = match backend::build(&l.scene, &spec) {
        Ok(g) => g,
        Err(e) => {
            let msg = format!("reference unavailable ({e}): accuracy columns left empty");
            info.error = Some(msg.clone());
            return (Err(msg), info);
        }
    };
    info.build_ms = Some(t0.elapsed().as_secs_f64() * 1e3);
    let ropts = RenderOptions {
        threads: 0,
        ..Default::default()
    };
    match render(&l.scene, geometry.as_ref(), &l.background, &ropts, &|| {}) {
        Ok(o) => {
            info.render_ms = Some(o.elapsed.as_secs_f64() * 1e3);
            if let Some(dir) = &options.images_dir {
                let p = dir.join(format!("{}_{w}x{h}_reference.png", slug(&c.scene)));
                image_written(
                    images::publish_png(image_io::encode_color(&o.framebuffer, false, &p), &p),
                    &p,
                    write_errors,
                );
            }
            let size = images::visible_scene_size(&l.scene, &o.framebuffer);
            (
                Ok(Truth {
                    fb: o.framebuffer,
                    size,
                }),
                info,
            )
        }
        Err(e) => {
            let msg = format!("reference render failed ({e}): accuracy columns left empty");
            info.error = Some(msg.clone());
            (Err(msg), info)
        }
    }
}

/// Builds configuration `index`, renders it once untimed (memory, work, accuracy and images
/// come from this render) and returns it with every column but the timing ones.
pub(super) fn prepare(
    index: usize,
    c: &Config,
    l: Rc<Loaded>,
    truth: Option<&Result<Truth, String>>,
    options: &BenchOptions,
    progress: &mut dyn Progress,
) -> Result<Prepared, String> {
    let scene = &l.scene;
    progress.phase("build");
    let heap = HeapPhase::start();
    let rss = RssPhase::start();
    let t0 = Instant::now();
    let geometry = backend::build_within(scene, &c.spec, options.hold_memory_bytes)
        .map_err(|e| e.to_string())?;
    let build_ms_total = t0.elapsed().as_secs_f64() * 1e3;
    let peak_heap_bytes_build = heap.finish();
    let peak_rss_bytes_build = rss.finish();
    let report = geometry.report();

    let ropts = RenderOptions {
        threads: c.threads,
        ..Default::default()
    };
    progress.phase("warm-up");
    let heap = HeapPhase::start();
    let rss = RssPhase::start();
    let warm = render(scene, geometry.as_ref(), &l.background, &ropts, &|| {})
        .map_err(|e| format!("render: {e}"))?;
    let peak_heap_bytes_render = heap.finish();
    let peak_rss_bytes_render = rss.finish();

    let s = &warm.stats;
    let fb = &warm.framebuffer;
    let mut notes = Vec::new();
    let slug_id = slug(&c.id);
    let mut write_errors = Vec::new();
    if let Some(dir) = &options.images_dir {
        let p = dir.join(format!("{slug_id}.png"));
        image_written(
            images::publish_png(image_io::encode_color(fb, false, &p), &p),
            &p,
            &mut write_errors,
        );
    }
    let acc = match truth {
        Some(Ok(truth)) => {
            let a = compare(fb, &truth.fb).map_err(|e| e.to_string())?;
            if let Some(dir) = &options.images_dir {
                let p = dir.join(format!("{slug_id}.diff.png"));
                image_written(
                    images::publish_png(images::diff_png(fb, &truth.fb), &p),
                    &p,
                    &mut write_errors,
                );
            }
            Some((a, truth.size, images::ssim(fb, &truth.fb)))
        }
        Some(Err(e)) => {
            notes.push(e.clone());
            None
        }
        None => {
            notes.push("accuracy not requested by the suite".into());
            None
        }
    };
    let kind = c.spec.kind.name();
    let total_rays = s.total_rays();
    let rates = s.mrays_per_thread_second();
    let mut row = Row {
        config_id: c.id.clone(),
        group: c.group.clone(),
        scene: c.scene.clone(),
        scene_file: portable_scene_path(&c.scene_path),
        backend: kind.to_string(),
        quality: c.label.clone(),
        options: c
            .spec
            .options
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .chain(render_override_pairs(&c.render))
            .collect::<Vec<_>>()
            .join(";"),
        width: scene.camera.width,
        height: scene.camera.height,
        spp: scene.render.samples_per_pixel,
        threads: c.threads,
        machine: options.machine.clone(),
        build_ms_total,
        build_phases_ms: report
            .build_phases_ms
            .iter()
            .map(|(k, v)| format!("{k}={v:.3}"))
            .collect::<Vec<_>>()
            .join(";"),
        rays_primary: s.primary_rays,
        rays_secondary: total_rays - s.primary_rays,
        mrays_camera_per_thread_s: rates.camera,
        mrays_shadow_per_thread_s: rates.shadow,
        mrays_ao_per_thread_s: rates.ambient_occlusion,
        mrays_bounce_per_thread_s: rates.bounce,
        memory_bytes: report.memory_bytes,
        triangles: report.triangles,
        peak_heap_bytes_build,
        peak_heap_bytes_render,
        peak_rss_bytes_build,
        peak_rss_bytes_render,
        steps_mean: s.mean_steps(),
        steps_max: s.max_steps_seen,
        step_exhaustion_pct: 100.0 * s.step_exhaustion_rate(),
        node_visits_per_ray: s.mean_node_visits(),
        node_visits_max: s.max_node_visits_seen,
        non_finite_count: images::non_finite(fb) + s.non_finite_hits + s.non_finite_pixels,
        notes: notes.join("; "),
        ..Row::default()
    };
    if let Some((accuracy, scene_size, ssim)) = &acc {
        row.set_accuracy(accuracy, *scene_size, *ssim);
    }
    let histogram = images::steps_histogram(fb);
    drop(warm);
    Ok(Prepared {
        index,
        loaded: l.clone(),
        geometry,
        row,
        histogram,
        samples: Vec::new(),
        error: None,
        write_errors,
    })
}
