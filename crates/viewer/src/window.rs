//! The window: `minifb` (a software framebuffer with key and mouse input; X11 loaded at run
//! time) around the same update rule and renderer as the headless mode.
//!
//! Every displayed frame turns the input since the last one into events: each held movement
//! key moves one step, a mouse drag with the left button turns the camera, other keys act on
//! their press; with no input the frame is a still one and refines. Once a frame is refined
//! (and measured) nothing is rendered until the next input. Escape or closing the window
//! ends the session.

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::{Duration, Instant};

use minifb::{InputCallback, MouseButton, MouseMode, Window, WindowOptions};

use crate::ViewerError;
use crate::overlay::Canvas;
use crate::session::{Session, window_pixels};
use crate::state::{Event, Key};

/// How the window session runs.
#[derive(Debug, Clone, Default)]
pub struct WindowRun {
    /// Folder P saves screenshots and camera scenes into.
    pub shots_dir: PathBuf,
    /// End by itself after this many window updates, rendered or idle (idle updates come
    /// every 10 ms once the picture is refined; for tests under a virtual display).
    pub exit_after_frames: Option<u64>,
}

/// How a window session ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WindowSummary {
    /// Frames rendered and shown.
    pub frames: u64,
    /// Window updates, rendered frames and idle ones.
    pub updates: u64,
    /// Screenshots saved.
    pub shots: Vec<PathBuf>,
}

/// The viewer key a window key stands for (keypad keys too).
fn viewer_key(k: minifb::Key) -> Option<Key> {
    use minifb::Key as M;
    Some(match k {
        M::W => Key::W,
        M::A => Key::A,
        M::S => Key::S,
        M::D => Key::D,
        M::Q => Key::Q,
        M::E => Key::E,
        M::Key1 | M::NumPad1 => Key::Digit1,
        M::Key2 | M::NumPad2 => Key::Digit2,
        M::Key3 | M::NumPad3 => Key::Digit3,
        M::Tab => Key::Tab,
        M::Equal | M::NumPadPlus => Key::Plus,
        M::Minus | M::NumPadMinus => Key::Minus,
        M::R => Key::R,
        M::P => Key::P,
        _ => return None,
    })
}

/// Key presses as the window reports them, in order. `get_keys_pressed` compares the key
/// state between two updates, so a tap pressed and released during one slow frame would be
/// lost; the callback sees every press.
#[derive(Default, Clone)]
struct Presses(Rc<RefCell<Vec<minifb::Key>>>);

impl InputCallback for Presses {
    fn add_char(&mut self, _uni_char: u32) {}

    fn set_key_state(&mut self, key: minifb::Key, state: bool) {
        if state {
            self.0.borrow_mut().push(key);
        }
    }
}

/// Opens the window and runs until it is closed (Escape) or `exit_after_frames` updates were
/// shown. Errors: no window can be opened (no display, no X11 libraries), a frame fails to
/// render on the first frame (later render errors are shown in the window instead).
pub fn run(session: &mut Session, run: &WindowRun) -> Result<WindowSummary, ViewerError> {
    let (w, h) = session.window_size();
    let title = format!("marchmesh view {}", session.source().display());
    let mut window = Window::new(&title, w as usize, h as usize, WindowOptions::default())
        .map_err(|e| ViewerError::Window(e.to_string()))?;
    window.set_target_fps(0);
    let presses = Presses::default();
    window.set_input_callback(Box::new(presses.clone()));
    let mut summary = WindowSummary {
        frames: 0,
        updates: 0,
        shots: Vec::new(),
    };
    let mut pixels = vec![0u32; w as usize * h as usize];
    let mut last_frame = None;
    let mut last_mouse: Option<(f32, f32)> = None;
    let mut message: Option<(String, Instant)> = None;
    let mut dirty = true;
    while window.is_open() && !window.is_key_down(minifb::Key::Escape) {
        let mut events = Vec::new();
        let held: Vec<Key> = window
            .get_keys()
            .into_iter()
            .filter_map(viewer_key)
            .collect();
        let pressed: Vec<Key> = presses
            .0
            .borrow_mut()
            .drain(..)
            .filter_map(viewer_key)
            .collect();
        for key in &pressed {
            match key {
                Key::P => {
                    if let Some(frame) = &last_frame {
                        let m = save(session, frame, &run.shots_dir, &mut summary);
                        message = Some((m, Instant::now()));
                        dirty = true;
                    }
                }
                // Held movement keys move below; one tapped and released within a frame
                // still moves once.
                k if k.is_movement() && held.contains(k) => {}
                k => events.push(Event::Key(*k)),
            }
        }
        // Held movement keys move one step per frame.
        events.extend(
            held.iter()
                .filter(|k| k.is_movement())
                .map(|k| Event::Key(*k)),
        );
        let mouse = window.get_mouse_pos(MouseMode::Pass);
        if window.get_mouse_down(MouseButton::Left) {
            if let (Some((x0, y0)), Some((x1, y1))) = (last_mouse, mouse) {
                events.push(Event::Drag {
                    dx_px: f64::from(x1 - x0),
                    dy_px: f64::from(y1 - y0),
                });
            }
            last_mouse = mouse;
        } else {
            last_mouse = None;
        }
        let before = *session.state();
        for e in &events {
            session.apply(e);
        }
        if *session.state() == before && !dirty {
            // Nothing changed: refine, or rest once refined.
            if session.state().is_refined() && last_frame.is_some() {
                window.update();
                summary.updates += 1;
                if run.exit_after_frames.is_some_and(|n| summary.updates >= n) {
                    break;
                }
                std::thread::sleep(Duration::from_millis(10));
                if message
                    .as_ref()
                    .is_some_and(|(_, t)| t.elapsed() > Duration::from_secs(3))
                {
                    message = None;
                    dirty = true;
                }
                continue;
            }
            session.apply(&Event::Still);
        }
        dirty = false;
        match session.render_frame() {
            Ok(frame) => {
                pixels = window_pixels(&frame.image, w, h);
                let mut lines = crate::overlay_lines(session, &frame);
                if let Some((m, _)) = &message {
                    lines.push(m.clone());
                }
                crate::draw_overlay(&mut pixels, w, h, &frame, &lines);
                last_frame = Some(frame);
            }
            Err(e) if last_frame.is_none() => return Err(e),
            Err(e) => {
                eprintln!("marchmesh view: {e}");
                let mut canvas = Canvas {
                    pixels: &mut pixels,
                    width: w as usize,
                    height: h as usize,
                };
                canvas.text_block(0, h as usize / 2, &[format!("error: {e}")], 0x00ff_6060);
            }
        }
        window
            .update_with_buffer(&pixels, w as usize, h as usize)
            .map_err(|e| ViewerError::Window(e.to_string()))?;
        summary.frames += 1;
        summary.updates += 1;
        if run.exit_after_frames.is_some_and(|n| summary.updates >= n) {
            break;
        }
    }
    Ok(summary)
}

/// P in the window: saves and returns the message to show.
fn save(
    session: &Session,
    frame: &crate::session::Frame,
    dir: &Path,
    summary: &mut WindowSummary,
) -> String {
    match session.save_shot(frame, dir) {
        Ok(shot) => {
            let m = format!("saved {} and {}", shot.png.display(), shot.scene.display());
            println!("{m}");
            summary.shots.push(shot.png);
            m
        }
        Err(e) => {
            eprintln!("marchmesh view: {e}");
            format!("not saved: {e}")
        }
    }
}
