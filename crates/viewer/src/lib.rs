//! `marchmesh view`: fly through a scene and watch the sdf and mesh backends trade speed for
//! accuracy live.
//!
//! - [`state`]: the view state (camera position, yaw, pitch, backends shown, split, quality
//!   levels, refinement level) and its one update rule `(state, event) -> state`.
//! - [`session`]: the scene and the backends built so far (each once, kept, rebuilt only at
//!   a new quality level or, for still frames, at a new camera position), and the renderer:
//!   coarse frames while moving (a quarter of each side, scaled up), refining to full
//!   resolution when still, through `marchmesh_core::render` like `marchmesh render`.
//! - [`offset`]: moving frames trace a geometry built at an earlier camera position.
//! - [`quality`]: the `+`/`-` knob (sdf hit epsilon, mesh tessellation budget).
//! - [`overlay`]: text over the picture (8x8 bitmap font).
//! - [`script`], [`headless`]: input events from a JSON file replayed into PNG frames and
//!   `frames.json`; [`window`]: the same loop in a `minifb` window.
//! - [`save`]: P, a screenshot and the camera as a scene file.

pub mod headless;
pub mod offset;
pub mod overlay;
pub mod quality;
pub mod save;
pub mod script;
pub mod session;
pub mod state;
pub mod window;

use std::path::PathBuf;

pub use script::Script;
pub use session::{Frame, Session, SessionOptions, ViewReport};
pub use state::{Event, Key, ViewConfig, ViewState, update};

/// Why the viewer stopped.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// The scene file could not be read or is invalid (the message names the file).
    #[error(transparent)]
    Scene(#[from] marchmesh_scene::SceneError),
    /// A backend option is bad or a backend failed to build.
    #[error(transparent)]
    Backend(#[from] marchmesh_registry::BackendError),
    /// A render could not run.
    #[error(transparent)]
    Render(#[from] marchmesh_core::RenderError),
    /// The scene's environment map could not be loaded.
    #[error(transparent)]
    Background(#[from] marchmesh_core::BackgroundError),
    /// Two frames of different sizes were compared (an internal error).
    #[error(transparent)]
    Compare(#[from] marchmesh_core::compare::SizeMismatch),
    /// An image could not be encoded.
    #[error(transparent)]
    Image(#[from] marchmesh_core::image_io::ImageIoError),
    /// A file could not be read or written safely (names the file).
    #[error(transparent)]
    Io(#[from] marchmesh_safeio::SafeIoError),
    /// The scene's camera cannot be flown.
    #[error("camera: {0}")]
    Camera(String),
    /// An option of the session is out of range.
    #[error("{0}")]
    Options(String),
    /// A script entry is malformed.
    #[error("{}: {}line {line}: {reason}", file.display(), entry.map_or(String::new(), |e| format!("entry {e}, ")))]
    Script {
        /// The script file.
        file: PathBuf,
        /// 0-based index of the entry, when the error is inside one.
        entry: Option<usize>,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// An output file or folder cannot be written.
    #[error("{}: {reason}", path.display())]
    Output {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// No window could be opened.
    #[error(
        "cannot open a window: {0} (is DISPLAY set and libX11 installed? Without a display use --headless --script FILE --frames DIR)"
    )]
    Window(String),
}

/// Bytes as `1.2 MiB`.
pub fn human_bytes(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= (1u64 << 30) as f64 {
        format!("{:.2} GiB", b / (1u64 << 30) as f64)
    } else if b >= (1u64 << 20) as f64 {
        format!("{:.1} MiB", b / (1u64 << 20) as f64)
    } else {
        format!("{:.1} KiB", b / 1024.0)
    }
}

/// The overlay text of `frame` (lines of at most ~60 characters): frame time and
/// resolution; per shown backend its knob, render time, Mrays/s and (refined frames)
/// accuracy against the reference; the memory of every backend built so far; the keys.
pub fn overlay_lines(session: &Session, frame: &Frame) -> Vec<String> {
    let s = &frame.state;
    let (w, h) = session.window_size();
    let mut lines = vec![format!(
        "{:.1} ms/frame  {}x{} {}",
        frame.frame_ms,
        frame.image.width,
        frame.image.height,
        if s.is_refined() {
            "full res".to_string()
        } else {
            format!("1/{} res", s.scale())
        }
    )];
    for (i, v) in frame.views.iter().enumerate() {
        let side = match (s.split, i) {
            (false, _) => "",
            (true, 0) => "L ",
            (true, _) => "R ",
        };
        lines.push(format!(
            "{side}{} {}: {:.1} ms {:.2} Mrays/s{}{}",
            v.backend,
            v.knob,
            v.render_ms,
            v.mrays_per_s,
            v.build_ms
                .map_or(String::new(), |b| format!(" +build {b:.0} ms")),
            if v.shifted { " moving" } else { "" }
        ));
        if let Some(a) = &v.accuracy {
            lines.push(format!(
                "{side} vs ref {w}x{h}: {} dB sil {:.2}% depth p95 {:.1e}",
                if a.psnr_db.is_finite() {
                    format!("{:.1}", a.psnr_db)
                } else {
                    "inf".into()
                },
                a.silhouette_mismatch_pct,
                a.depth_rel_p95,
            ));
        }
    }
    let memory: Vec<String> = session
        .memory()
        .iter()
        .map(|(k, b)| format!("{k} {}", human_bytes(*b)))
        .collect();
    lines.push(format!("mem {}", memory.join(", ")));
    lines.push("WASDQE move, drag look, 1 sdf 2 mesh 3 ref".into());
    lines.push("Tab split, +/- quality, R reset, P save".into());
    lines
}

/// Draws `lines` over `pixels` (the window, `width x height`) and, in split mode, the
/// divider between the two backends.
pub fn draw_overlay(pixels: &mut [u32], width: u32, height: u32, frame: &Frame, lines: &[String]) {
    let mut canvas = overlay::Canvas {
        pixels,
        width: width as usize,
        height: height as usize,
    };
    if frame.state.split && frame.image.width > 0 {
        // The composed image switches backend at column image_width / 2, scaled up.
        let split_px =
            (frame.image.width / 2) as usize * width as usize / frame.image.width as usize;
        canvas.vline(split_px.saturating_sub(1), 0x00ff_ffff);
    }
    canvas.text_block(0, 0, lines, 0x00ff_ff80);
}
