//! A viewing session: the scene, the state, the backends built so far, and the renderer that
//! turns a state into a frame through the same code paths as `marchmesh render` (the
//! backend registry and `marchmesh_core::render`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DVec2, DVec3, Vec3};
use marchmesh_core::{
    Accuracy, BackgroundSampler, Framebuffer, Geometry, RenderOptions, RenderOutput,
};
use marchmesh_registry::{self as backend, BackendId};
use marchmesh_scene::{Scene, SceneFile};

use crate::ViewerError;
use crate::offset::Offset;
use crate::quality::{self, Knob};
use crate::state::{Event, ViewConfig, ViewState, update};

/// How to start a session.
#[derive(Debug, Clone)]
pub struct SessionOptions {
    /// The scene file.
    pub scene: PathBuf,
    /// The backend shown first.
    pub backend: BackendId,
    /// The user's `key=value` options of each backend (the quality knob is applied on top).
    pub options: BTreeMap<BackendId, Vec<(String, String)>>,
    /// Window width in pixels (default: the scene's image width).
    pub width: Option<u32>,
    /// Window height in pixels (default: the scene's image height).
    pub height: Option<u32>,
    /// Render threads (0 = one per logical core).
    pub threads: usize,
    /// World units per movement key event; `None`: [`default_step`] of the scene.
    pub step: Option<f64>,
    /// Each backend build and each render stays within this many bytes.
    pub memory_limit_bytes: u64,
    /// Measure refined frames against the reference at the same camera.
    pub accuracy: bool,
}

impl SessionOptions {
    /// Defaults for `scene`: the first backend of [`crate::state::view_order`] (sdf) first,
    /// the scene's size, all cores, accuracy on.
    pub fn new(scene: impl Into<PathBuf>) -> Self {
        SessionOptions {
            scene: scene.into(),
            backend: crate::state::view_order()[0],
            options: BTreeMap::new(),
            width: None,
            height: None,
            threads: 0,
            step: None,
            memory_limit_bytes: marchmesh_core::DEFAULT_MEMORY_LIMIT_BYTES,
            accuracy: true,
        }
    }
}

/// A backend built for the session.
struct Built {
    geometry: Box<dyn Geometry>,
    /// Camera position it was built at (the origin of its render space), world units.
    anchor: DVec3,
    /// Quality level it was built at.
    quality: i32,
    /// Build wall time, milliseconds.
    build_ms: f64,
    /// Bytes of the representation (its report).
    memory_bytes: u64,
}

/// What one shown backend did for a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewReport {
    /// The backend.
    pub backend: BackendId,
    /// Its quality knob, e.g. `eps_px 0.25 px (q+0)`.
    pub knob: String,
    /// The full `key=value` options it was built with (user's, then the knob's).
    pub options: Vec<(String, String)>,
    /// Wall time of the render, milliseconds (no build).
    pub render_ms: f64,
    /// Wall time of a (re)build done for this frame, milliseconds.
    pub build_ms: Option<f64>,
    /// Rays traced (all kinds).
    pub rays: u64,
    /// Rays per second of render wall time, millions.
    pub mrays_per_s: f64,
    /// Bytes of the built representation.
    pub memory_bytes: u64,
    /// Traced through a geometry built at an earlier camera position ([`crate::offset`]):
    /// only moving (coarse) frames are.
    pub shifted: bool,
    /// Against the reference at the same camera and resolution; refined frames only.
    pub accuracy: Option<Accuracy>,
}

/// One rendered frame.
#[derive(Debug, Clone)]
pub struct Frame {
    /// The picture at the render resolution (window size / [`ViewState::scale`]); in split
    /// mode the left columns come from the first view, the rest from the second.
    pub image: Framebuffer,
    /// The state it shows.
    pub state: ViewState,
    /// One report per shown backend, left first.
    pub views: Vec<ViewReport>,
    /// Wall time of the whole frame (builds, renders, compositing; accuracy excluded),
    /// milliseconds.
    pub frame_ms: f64,
    /// Wall time of the accuracy measurement (reference build and render), milliseconds.
    pub accuracy_ms: f64,
}

/// A viewing session.
pub struct Session {
    source: PathBuf,
    /// The scene file as parsed (saved back with a new camera by [`crate::save`]).
    pub(crate) file: SceneFile,
    /// Folder relative asset paths of the scene resolve against (absolute).
    pub(crate) base_dir: PathBuf,
    /// The resolved scene; its camera is replaced per frame.
    scene: Scene,
    background: BackgroundSampler,
    config: ViewConfig,
    state: ViewState,
    user_options: BTreeMap<BackendId, Vec<(String, String)>>,
    knobs: BTreeMap<BackendId, Knob>,
    built: BTreeMap<BackendId, Built>,
    threads: usize,
    memory_limit_bytes: u64,
    accuracy: bool,
    /// The last reference frame rendered for accuracy: (camera bits, framebuffer).
    reference_frame: Option<([u64; 5], Framebuffer)>,
    /// A folder of this session's baked mesh grids for the sdf backend (scenes with meshes,
    /// unless the user gave `cache_dir`): the bake does not depend on the camera, so
    /// rebuilding at a new still camera reads it back instead of baking again. Removed when
    /// the session ends.
    bake_cache: Option<PathBuf>,
}

impl Drop for Session {
    fn drop(&mut self) {
        if let Some(dir) = &self.bake_cache {
            std::fs::remove_dir_all(dir).ok();
        }
    }
}

impl Session {
    /// Loads the scene, checks every backend's options and builds the first backend (so a
    /// bad scene or option fails before a window opens).
    ///
    /// Errors: the scene cannot be read or is invalid, an option is unknown or bad, the
    /// camera cannot be flown (`up` parallel to the view), the first build fails.
    pub fn open(opts: &SessionOptions) -> Result<Session, ViewerError> {
        let scene = marchmesh_scene::load(&opts.scene)?;
        let source_name = opts.scene.display().to_string();
        let bytes = marchmesh_safeio::read_regular(&opts.scene)?;
        let text = marchmesh_scene::decode_text(&bytes, &source_name)?;
        let file = marchmesh_scene::parse_file_format(text, &source_name)?;
        let parent = opts
            .scene
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let base_dir = std::fs::canonicalize(parent).unwrap_or_else(|_| parent.to_path_buf());
        let (w, h) = (
            opts.width.unwrap_or(scene.camera.width),
            opts.height.unwrap_or(scene.camera.height),
        );
        let scene = scene
            .with_image_size(w, h)
            .map_err(|reason| ViewerError::Options(format!("--width/--height: {reason}")))?;
        let background = BackgroundSampler::load(&scene.background)?;
        let mut spec = file.camera.clone();
        (spec.width, spec.height) = (w, h);
        if opts.threads > marchmesh_core::MAX_THREADS {
            return Err(ViewerError::Options(format!(
                "--threads {} is over the limit of {}",
                opts.threads,
                marchmesh_core::MAX_THREADS
            )));
        }
        let mut knobs = BTreeMap::new();
        let mut user_options = BTreeMap::new();
        for kind in BackendId::ALL {
            let user = opts.options.get(&kind).cloned().unwrap_or_default();
            knobs.insert(kind, Knob::of(kind, &user)?);
            user_options.insert(kind, user);
        }
        if let Some(step) = opts.step
            && !(step.is_finite() && step > 0.0)
        {
            return Err(ViewerError::Options(format!(
                "--step must be a positive number of world units, got {step}"
            )));
        }
        // A provisional step; replaced below once the first backend can probe the scene.
        let provisional = opts.step.unwrap_or(1.0);
        let config = ViewConfig::new(&spec, opts.backend, provisional)
            .map_err(|reason| ViewerError::Camera(format!("{source_name}: {reason}")))?;
        let mut session = Session {
            source: opts.scene.clone(),
            file,
            base_dir,
            scene,
            background,
            state: config.home,
            config,
            user_options,
            knobs,
            built: BTreeMap::new(),
            threads: opts.threads,
            memory_limit_bytes: opts.memory_limit_bytes,
            accuracy: opts.accuracy,
            reference_frame: None,
            bake_cache: None,
        };
        let user_cache = BackendId::ALL
            .into_iter()
            .filter(|k| caches_bakes(*k))
            .all(|k| {
                opts.options
                    .get(&k)
                    .is_some_and(|o| o.iter().any(|(key, _)| key == CACHE_DIR_KEY))
            });
        if !session.scene.mesh_paths().is_empty() && !user_cache {
            let dir = std::env::temp_dir().join(format!(
                "marchmesh-view-bakes-{}-{}",
                std::process::id(),
                BAKE_CACHES.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
            ));
            // A new folder (never one that exists, nor a symlink planted under its name);
            // without it a backend that bakes (sdf) bakes at every rebuild: slower, not wrong.
            if std::fs::create_dir(&dir).is_ok() {
                session.bake_cache = Some(dir);
            }
        }
        session.ensure_built(opts.backend, true)?;
        if opts.step.is_none() {
            let step = session.built.get(&opts.backend).map_or(DEFAULT_STEP, |b| {
                default_step(&session.scene, b.geometry.as_ref())
            });
            session.config.step = step;
        }
        Ok(session)
    }

    /// The scene file this session shows.
    pub fn source(&self) -> &Path {
        &self.source
    }

    /// The current state.
    pub fn state(&self) -> &ViewState {
        &self.state
    }

    /// The session's fixed configuration (start camera, orientation, step).
    pub fn config(&self) -> &ViewConfig {
        &self.config
    }

    /// Window size in pixels (the scene's image size unless overridden).
    pub fn window_size(&self) -> (u32, u32) {
        (self.config.camera.width, self.config.camera.height)
    }

    /// Applies one input event ([`update`]).
    pub fn apply(&mut self, event: &Event) {
        self.state = update(&self.state, event, &self.config);
    }

    /// Bytes of every backend built so far, in [`BackendId`] order.
    pub fn memory(&self) -> Vec<(BackendId, u64)> {
        self.built
            .iter()
            .map(|(k, b)| (*k, b.memory_bytes))
            .collect()
    }

    /// The `key=value` options `kind` is built with at quality `level`.
    pub fn options_of(&self, kind: BackendId, level: i32) -> Vec<(String, String)> {
        quality::spec(kind, &self.user(kind), &self.knob(kind), level).options
    }

    fn user(&self, kind: BackendId) -> Vec<(String, String)> {
        self.user_options.get(&kind).cloned().unwrap_or_default()
    }

    fn knob(&self, kind: BackendId) -> Knob {
        self.knobs.get(&kind).cloned().unwrap_or_default()
    }

    /// The scene at the current camera and full window size.
    fn scene_at_camera(&self) -> Result<Scene, ViewerError> {
        let camera = self.config.camera(&self.state).ok_or_else(|| {
            ViewerError::Camera(format!("invalid camera for state {:?}", self.state))
        })?;
        let mut scene = self.scene.clone();
        scene.camera = camera;
        Ok(scene)
    }

    /// Builds `kind` if it is not built at the current quality, or (`exact`) not at the
    /// current camera position. Returns the build time when it built.
    fn ensure_built(&mut self, kind: BackendId, exact: bool) -> Result<Option<f64>, ViewerError> {
        let level = self.state.quality.of(kind);
        let position = self.state.position;
        let current = self.built.get(&kind);
        let needed = match current {
            None => true,
            Some(b) => b.quality != level || (exact && b.anchor != position),
        };
        if !needed {
            return Ok(None);
        }
        // Drop the old build first: at most one copy of each backend is held.
        self.built.remove(&kind);
        let scene = self.scene_at_camera()?;
        let mut spec = quality::spec(kind, &self.user(kind), &self.knob(kind), level);
        if let (true, Some(dir)) = (caches_bakes(kind), &self.bake_cache) {
            // Not a picture setting: kept out of the options the frames report. First, so a
            // `cache_dir` the user gave wins.
            spec.options
                .insert(0, (CACHE_DIR_KEY.into(), dir.display().to_string()));
        }
        let t0 = Instant::now();
        let geometry = backend::build_within(&scene, &spec, self.memory_limit_bytes)?;
        let build_ms = t0.elapsed().as_secs_f64() * 1e3;
        let memory_bytes = geometry.report().memory_bytes;
        self.built.insert(
            kind,
            Built {
                geometry,
                anchor: position,
                quality: level,
                build_ms,
                memory_bytes,
            },
        );
        Ok(Some(build_ms))
    }

    /// Renders `scene` with `kind`'s geometry (shifted when built elsewhere).
    fn render_kind(
        &self,
        kind: BackendId,
        scene: &Scene,
    ) -> Result<(RenderOutput, bool), ViewerError> {
        let built = self.built.get(&kind).ok_or_else(|| {
            ViewerError::Options(format!("backend {kind} was not built (internal error)"))
        })?;
        let shift = (scene.camera.position - built.anchor).as_vec3();
        let options = RenderOptions {
            threads: self.threads,
            memory_limit_bytes: self.memory_limit_bytes,
            ..Default::default()
        };
        let out = if shift == Vec3::ZERO {
            marchmesh_core::render(
                scene,
                built.geometry.as_ref(),
                &self.background,
                &options,
                &|| {},
            )?
        } else {
            let shifted = Offset {
                inner: built.geometry.as_ref(),
                shift,
            };
            marchmesh_core::render(scene, &shifted, &self.background, &options, &|| {})?
        };
        Ok((out, shift != Vec3::ZERO))
    }

    /// Renders the current state: every shown backend at the refinement level's resolution
    /// (building what is missing; still frames rebuild at the camera so they are exactly
    /// `marchmesh render`'s), composes the split, and measures refined frames against the
    /// reference when accuracy is on.
    pub fn render_frame(&mut self) -> Result<Frame, ViewerError> {
        let t0 = Instant::now();
        let state = self.state;
        let exact = state.refine > 0;
        let shown = state.shown();
        let mut builds = Vec::new();
        for kind in &shown {
            builds.push(self.ensure_built(*kind, exact)?);
        }
        let full = self.scene_at_camera()?;
        let (w, h) = (full.camera.width, full.camera.height);
        let scale = state.scale();
        let mut scene = full.clone();
        scene.camera.width = w.div_ceil(scale).max(1);
        scene.camera.height = h.div_ceil(scale).max(1);
        let mut outputs = Vec::new();
        let mut views = Vec::new();
        for (kind, build_ms) in shown.iter().zip(builds) {
            let (out, shifted) = self.render_kind(*kind, &scene)?;
            let secs = out.elapsed.as_secs_f64();
            let rays = out.stats.total_rays();
            let level = state.quality.of(*kind);
            views.push(ViewReport {
                backend: *kind,
                knob: self.knob(*kind).describe(level),
                options: self.options_of(*kind, level),
                render_ms: secs * 1e3,
                build_ms,
                rays,
                mrays_per_s: rays as f64 / secs.max(1e-9) / 1e6,
                memory_bytes: self.built.get(kind).map_or(0, |b| b.memory_bytes),
                shifted,
                accuracy: None,
            });
            outputs.push(out.framebuffer);
        }
        let image = compose(&outputs);
        let frame_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = Instant::now();
        if self.accuracy && state.is_refined() {
            for (view, fb) in views.iter_mut().zip(&outputs) {
                if view.backend != BackendId::REFERENCE {
                    view.accuracy = Some(self.accuracy_of(fb, &full)?);
                }
            }
        }
        Ok(Frame {
            image,
            state,
            views,
            frame_ms,
            accuracy_ms: t1.elapsed().as_secs_f64() * 1e3,
        })
    }

    /// `fb` (a full-resolution render at `scene`'s camera) against the reference there. The
    /// reference is built in its own slot (as when it is shown: once, and again only at a
    /// new camera) and its frame is kept for the last camera measured.
    fn accuracy_of(&mut self, fb: &Framebuffer, scene: &Scene) -> Result<Accuracy, ViewerError> {
        let s = &self.state;
        let key = [
            s.position.x.to_bits(),
            s.position.y.to_bits(),
            s.position.z.to_bits(),
            s.yaw_deg.to_bits(),
            s.pitch_deg.to_bits(),
        ];
        let reference = match self.reference_frame.take() {
            Some((k, frame)) if k == key => frame,
            _ => {
                self.ensure_built(BackendId::REFERENCE, true)?;
                self.render_kind(BackendId::REFERENCE, scene)?.0.framebuffer
            }
        };
        let accuracy = marchmesh_core::compare(fb, &reference);
        self.reference_frame = Some((key, reference));
        Ok(accuracy?)
    }

    /// Build wall time of each built backend, milliseconds.
    pub fn build_times(&self) -> Vec<(BackendId, f64)> {
        self.built.iter().map(|(k, b)| (*k, b.build_ms)).collect()
    }
}

/// The option key of backends that keep baked data in a folder across builds.
const CACHE_DIR_KEY: &str = "cache_dir";

/// Whether `kind` has a [`CACHE_DIR_KEY`] option (the session then lends it a folder of its
/// own, so a rebuild at a new camera reads its bakes back).
fn caches_bakes(kind: BackendId) -> bool {
    kind.option_docs().iter().any(|d| d.key == CACHE_DIR_KEY)
}

/// Sessions opened by this process so far (names their bake cache folders apart).
static BAKE_CACHES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// The step when the scene gives nothing to measure: 0.1 world units.
pub const DEFAULT_STEP: f64 = 0.1;

/// A movement step suited to the scene: 1/20 of the median distance to the surfaces seen
/// through a 9 x 9 grid of the start camera's pixels (traced with `geometry`), so a scene
/// takes as many key presses to cross at any scale; [`DEFAULT_STEP`] when no ray hits.
pub fn default_step(scene: &Scene, geometry: &dyn Geometry) -> f64 {
    let plane = scene.camera.image_plane();
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut distances: Vec<f64> = Vec::new();
    for j in 0..9u32 {
        for i in 0..9u32 {
            let (col, row) = ((2 * i + 1) * w / 18, (2 * j + 1) * h / 18);
            let ray = marchmesh_core::camera::primary_ray_on(
                &plane,
                col.min(w - 1),
                row.min(h - 1),
                DVec2::splat(0.5),
                scene.render.max_distance,
            );
            if let Some(hit) = geometry.closest_hit(&ray).hit()
                && hit.t.is_finite()
                && hit.t > 0.0
            {
                distances.push(f64::from(hit.t));
            }
        }
    }
    if distances.is_empty() {
        return DEFAULT_STEP;
    }
    let median = marchmesh_core::compare::quantile(&mut distances, 0.5);
    median / 20.0
}

/// One framebuffer, or two side by side: the left half of the first (columns `0..w/2`) and
/// the right half of the second.
fn compose(frames: &[Framebuffer]) -> Framebuffer {
    match frames {
        [left, right] if (left.width, left.height) == (right.width, right.height) => {
            let mut out = left.clone();
            let (w, half) = (left.width as usize, left.width as usize / 2);
            for y in 0..left.height as usize {
                let range = y * w + half..(y + 1) * w;
                out.color[range.clone()].copy_from_slice(&right.color[range.clone()]);
                out.depth[range.clone()].copy_from_slice(&right.depth[range.clone()]);
                out.normal[range.clone()].copy_from_slice(&right.normal[range.clone()]);
                out.material[range.clone()].copy_from_slice(&right.material[range.clone()]);
                out.termination[range.clone()].copy_from_slice(&right.termination[range.clone()]);
                out.work[range.clone()].copy_from_slice(&right.work[range]);
            }
            out
        }
        [first, ..] => first.clone(),
        [] => Framebuffer::new(1, 1),
    }
}

/// `fb` scaled up (nearest pixel) to `width x height` as `0RGB` pixels, with the same 8-bit
/// conversion as the PNG files ([`Framebuffer::to_rgb8`]).
pub fn window_pixels(fb: &Framebuffer, width: u32, height: u32) -> Vec<u32> {
    let rgb = fb.to_rgb8();
    let (sw, sh) = (fb.width as u64, fb.height as u64);
    let mut out = Vec::with_capacity(width as usize * height as usize);
    for y in 0..height as u64 {
        let sy = (y * sh / height.max(1) as u64).min(sh.saturating_sub(1)) as u32;
        for x in 0..width as u64 {
            let sx = (x * sw / width.max(1) as u64).min(sw.saturating_sub(1)) as u32;
            let p = rgb.get_pixel(sx, sy).0;
            out.push(u32::from(p[0]) << 16 | u32::from(p[1]) << 8 | u32::from(p[2]));
        }
    }
    out
}

/// `0RGB` pixels as a framebuffer whose 8-bit conversion gives the same pixels back, so
/// PNGs of what the window shows go through the same encoder as `marchmesh render`.
pub fn pixels_to_framebuffer(pixels: &[u32], width: u32, height: u32) -> Framebuffer {
    let mut fb = Framebuffer::new(width, height);
    for (c, p) in fb.color.iter_mut().zip(pixels) {
        let ch = |shift: u32| ((p >> shift) & 0xff) as f32 / 255.0;
        *c = Vec3::new(ch(16), ch(8), ch(0));
    }
    fb
}
