//! The headless mode: a script of input events replayed through the same update rule and
//! renderer as the window, every frame written as a PNG, with `frames.json` listing each
//! frame's camera, backend, refinement level and times.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::ViewerError;
use crate::save::Shot;
use crate::script::{Script, Step};
use crate::session::{Frame, Session, pixels_to_framebuffer, window_pixels};
use crate::state::Event;

/// The file listing the frames, written into the frames folder at the end.
pub const FRAMES_JSON: &str = "frames.json";

/// The PNG of frame `index` (`frame-00000.png`, ...).
pub fn frame_file_name(index: u64) -> String {
    format!("frame-{index:05}.png")
}

/// Accuracy against the reference, as listed in `frames.json`.
#[derive(Debug, Clone, Serialize)]
pub struct AccuracyRecord {
    /// PSNR of the 8-bit colours, dB (`null` when identical).
    pub psnr_db: Option<f64>,
    /// Pixels hit in exactly one of the two renders, percent.
    pub silhouette_mismatch_pct: f64,
    /// 95th percentile of |depth error| / reference depth.
    pub depth_rel_p95: f64,
    /// Mean normal angle error, degrees.
    pub normal_deg_mean: f64,
}

/// One backend of a frame, as listed in `frames.json`.
#[derive(Debug, Clone, Serialize)]
pub struct ViewRecord {
    /// Backend name.
    pub backend: String,
    /// Its `key=value` options (the user's, then the quality knob's).
    pub options: Vec<String>,
    /// Render wall time, milliseconds.
    pub render_ms: f64,
    /// Build wall time when it was (re)built for this frame, milliseconds.
    pub build_ms: Option<f64>,
    /// Rays per second of render time, millions.
    pub mrays_per_s: f64,
    /// Bytes of the built representation.
    pub memory_bytes: u64,
    /// Traced through a geometry built at an earlier camera position (moving frames).
    pub shifted: bool,
    /// Against the reference (refined frames of a non-reference backend).
    pub accuracy: Option<AccuracyRecord>,
}

/// One frame, as listed in `frames.json`.
#[derive(Debug, Clone, Serialize)]
pub struct FrameRecord {
    /// Frame number (0-based).
    pub frame: u64,
    /// PNG file name in the frames folder.
    pub file: String,
    /// The input applied before it: a key name, `drag dx dy` or `still`.
    pub input: String,
    /// Camera position, world units.
    pub position: [f64; 3],
    /// Yaw, degrees.
    pub yaw_deg: f64,
    /// Pitch, degrees.
    pub pitch_deg: f64,
    /// Unit view direction.
    pub forward: [f64; 3],
    /// The active backend (left half in split mode).
    pub backend: String,
    /// The right half's backend in split mode.
    pub split_with: Option<String>,
    /// Refinement level (0 = coarse).
    pub refine: u8,
    /// Render resolution divisor at this level.
    pub scale: u32,
    /// Render resolution, pixels.
    pub render_size: [u32; 2],
    /// Frame wall time (builds, renders, compositing), milliseconds.
    pub ms: f64,
    /// Accuracy measurement wall time, milliseconds.
    pub accuracy_ms: f64,
    /// Each shown backend, left first.
    pub views: Vec<ViewRecord>,
}

/// Everything `frames.json` holds.
#[derive(Debug, Clone, Serialize)]
pub struct FramesFile {
    /// The scene file.
    pub scene: String,
    /// Window size, pixels.
    pub window: [u32; 2],
    /// World units per movement event.
    pub step: f64,
    /// The frames in order.
    pub frames: Vec<FrameRecord>,
    /// Screenshots saved with P.
    pub shots: Vec<ShotRecord>,
}

/// One P, as listed in `frames.json`.
#[derive(Debug, Clone, Serialize)]
pub struct ShotRecord {
    /// The frame saved.
    pub frame: u64,
    /// The files written.
    #[serde(flatten)]
    pub files: Shot,
}

/// Replays `script` in `session`, writing `frame-NNNNN.png` per frame (window size, what the
/// window would show; with `overlay` also its text) and finally `frames.json` into `dir`
/// (created if missing). Every file is published new: existing frame files or `frames.json`
/// are an error before anything is rendered, and nothing is ever overwritten.
pub fn run(
    session: &mut Session,
    script: &Script,
    dir: &Path,
    overlay: bool,
) -> Result<FramesFile, ViewerError> {
    marchmesh_safeio::create_folder(dir).map_err(|e| ViewerError::Output {
        path: dir.to_path_buf(),
        reason: format!("cannot create the frames folder: {e}"),
    })?;
    let mut targets: Vec<PathBuf> = (0..script.frame_count())
        .map(|i| dir.join(frame_file_name(i)))
        .collect();
    targets.push(dir.join(FRAMES_JSON));
    if let Some(taken) = targets
        .iter()
        .find(|p| std::fs::symlink_metadata(p).is_ok())
    {
        return Err(ViewerError::Output {
            path: taken.clone(),
            reason: "already exists (nothing was overwritten; use a new or empty --frames folder)"
                .into(),
        });
    }
    let (w, h) = session.window_size();
    let mut out = FramesFile {
        scene: session.source().display().to_string(),
        window: [w, h],
        step: session.config().step,
        frames: Vec::new(),
        shots: Vec::new(),
    };
    let mut last: Option<Frame> = None;
    for step in &script.steps {
        let event = match step {
            Step::Frame(e) => Some(*e),
            Step::Save if last.is_none() => None,
            Step::Save => {
                if let Some(frame) = &last {
                    let files = session.save_shot(frame, dir)?;
                    out.shots.push(ShotRecord {
                        frame: out.frames.len() as u64 - 1,
                        files,
                    });
                }
                continue;
            }
        };
        if let Some(e) = &event {
            session.apply(e);
        }
        let frame = session.render_frame()?;
        let index = out.frames.len() as u64;
        let mut pixels = window_pixels(&frame.image, w, h);
        if overlay {
            let lines = crate::overlay_lines(session, &frame);
            crate::draw_overlay(&mut pixels, w, h, &frame, &lines);
        }
        let fb = pixels_to_framebuffer(&pixels, w, h);
        let path = dir.join(frame_file_name(index));
        let bytes = marchmesh_core::image_io::encode_color(&fb, false, &path)?;
        marchmesh_safeio::publish_new(&path, &bytes)?;
        out.frames
            .push(record(index, event.as_ref(), session, &frame));
        if matches!(step, Step::Save) {
            let files = session.save_shot(&frame, dir)?;
            out.shots.push(ShotRecord {
                frame: index,
                files,
            });
        }
        last = Some(frame);
    }
    let json = serde_json::to_string_pretty(&out)
        .map_err(|e| ViewerError::Options(format!("cannot write {FRAMES_JSON}: {e}")))?;
    marchmesh_safeio::publish_new(&dir.join(FRAMES_JSON), (json + "\n").as_bytes())?;
    Ok(out)
}

/// The input as text for `frames.json`.
pub fn input_name(event: Option<&Event>) -> String {
    match event {
        None | Some(Event::Still) => "still".into(),
        Some(Event::Key(k)) => k.name().into(),
        Some(Event::Drag { dx_px, dy_px }) => format!("drag {dx_px} {dy_px}"),
    }
}

fn record(index: u64, event: Option<&Event>, session: &Session, frame: &Frame) -> FrameRecord {
    let s = &frame.state;
    let forward = session.config().orientation.forward(s.yaw_deg, s.pitch_deg);
    FrameRecord {
        frame: index,
        file: frame_file_name(index),
        input: input_name(event),
        position: s.position.to_array(),
        yaw_deg: s.yaw_deg,
        pitch_deg: s.pitch_deg,
        forward: forward.to_array(),
        backend: s.active.to_string(),
        split_with: s.split.then(|| s.partner.to_string()),
        refine: s.refine,
        scale: s.scale(),
        render_size: [frame.image.width, frame.image.height],
        ms: frame.frame_ms,
        accuracy_ms: frame.accuracy_ms,
        views: frame
            .views
            .iter()
            .map(|v| ViewRecord {
                backend: v.backend.to_string(),
                options: v.options.iter().map(|(k, x)| format!("{k}={x}")).collect(),
                render_ms: v.render_ms,
                build_ms: v.build_ms,
                mrays_per_s: v.mrays_per_s,
                memory_bytes: v.memory_bytes,
                shifted: v.shifted,
                accuracy: v.accuracy.map(|a| AccuracyRecord {
                    psnr_db: a.psnr_db.is_finite().then_some(a.psnr_db),
                    silhouette_mismatch_pct: a.silhouette_mismatch_pct,
                    depth_rel_p95: a.depth_rel_p95,
                    normal_deg_mean: a.normal_deg_mean,
                }),
            })
            .collect(),
    }
}
