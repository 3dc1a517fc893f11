//! The viewer's state and its one update rule, `(state, event) -> state`, shared by the window
//! and the headless script mode: what a key or a mouse drag does is decided here and nowhere
//! else, so a script replays exactly what a person at the window would see.

use glam::DVec3;
use marchmesh_registry::{BackendId, COUNT};
use marchmesh_scene::{Camera, CameraSpec};

/// Refinement levels: the image is rendered at `1 / REFINE_SCALES[level]` of the window's
/// width and height and scaled up. Level 0 (a quarter of each side, 1/16 of the pixels) is
/// drawn while anything changes; every still frame goes one level up, to full resolution.
pub const REFINE_SCALES: [u32; 3] = [4, 2, 1];

/// The highest refinement level: full resolution, the frame a one-off `marchmesh render`
/// of the same camera gives.
pub const MAX_REFINE: u8 = (REFINE_SCALES.len() - 1) as u8;

/// Quality levels run from `-MAX_QUALITY` to `MAX_QUALITY`; each step halves (`+`) or doubles
/// (`-`) the backend's main knob ([`crate::quality`]).
pub const MAX_QUALITY: i32 = 3;

/// Degrees of yaw or pitch per pixel of mouse drag.
pub const LOOK_DEG_PER_PX: f64 = 0.25;

/// Pitch stays within this many degrees of the horizon (looking straight up or down would
/// make the up vector parallel to the view).
pub const MAX_PITCH_DEG: f64 = 89.0;

/// A key the viewer reacts to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Key {
    /// Move forward (along the view direction) one step.
    W,
    /// Move left one step.
    A,
    /// Move backward one step.
    S,
    /// Move right one step.
    D,
    /// Move down (along the scene's up axis) one step.
    Q,
    /// Move up one step.
    E,
    /// Show the first backend of [`view_order`] (sdf).
    Digit1,
    /// Show the second backend of [`view_order`] (mesh).
    Digit2,
    /// Show the third backend of [`view_order`] (the reference).
    Digit3,
    /// Toggle the split view (active backend left, the previously shown one right).
    Tab,
    /// Raise the active backend's quality one level.
    Plus,
    /// Lower the active backend's quality one level.
    Minus,
    /// Reset the camera and the quality levels to the start.
    R,
    /// Save a screenshot and the camera as a scene file (no change of state).
    P,
}

impl Key {
    /// Every key, in the order of the help text.
    pub const ALL: [Key; 14] = [
        Key::W,
        Key::A,
        Key::S,
        Key::D,
        Key::Q,
        Key::E,
        Key::Digit1,
        Key::Digit2,
        Key::Digit3,
        Key::Tab,
        Key::Plus,
        Key::Minus,
        Key::R,
        Key::P,
    ];

    /// The name used in scripts and `frames.json` (`"W"`, `"1"`, `"Tab"`, `"+"`, ...).
    pub const fn name(self) -> &'static str {
        match self {
            Key::W => "W",
            Key::A => "A",
            Key::S => "S",
            Key::D => "D",
            Key::Q => "Q",
            Key::E => "E",
            Key::Digit1 => "1",
            Key::Digit2 => "2",
            Key::Digit3 => "3",
            Key::Tab => "Tab",
            Key::Plus => "+",
            Key::Minus => "-",
            Key::R => "R",
            Key::P => "P",
        }
    }

    /// Parses a script key name: letters in either case, `1` `2` `3`, `Tab`, `+` (or `=`,
    /// `plus`), `-` (or `minus`).
    pub fn parse(name: &str) -> Option<Key> {
        let lower = name.trim().to_ascii_lowercase();
        match lower.as_str() {
            "=" | "plus" => return Some(Key::Plus),
            "minus" => return Some(Key::Minus),
            _ => {}
        }
        Key::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(&lower))
    }

    /// Whether the key moves the camera (held keys move once per frame).
    pub const fn is_movement(self) -> bool {
        matches!(self, Key::W | Key::A | Key::S | Key::D | Key::Q | Key::E)
    }

    /// The backend a digit key selects (`None` past the last backend).
    pub fn backend(self) -> Option<BackendId> {
        let place = match self {
            Key::Digit1 => 0,
            Key::Digit2 => 1,
            Key::Digit3 => 2,
            _ => return None,
        };
        view_order().get(place).copied()
    }
}

/// The backends in the order of the digit keys: the measured ones in registry order, then
/// the ground truth (sdf, mesh, reference).
pub fn view_order() -> [BackendId; COUNT] {
    let mut order = BackendId::ALL;
    order.sort_by_key(|k| k.is_ground_truth());
    order
}

/// One input to the update rule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// A key press (movement keys move one step per event).
    Key(Key),
    /// The mouse dragged by this many window pixels (x right, y down) with the button held.
    Drag {
        /// Horizontal drag in pixels (positive: to the right, turns right).
        dx_px: f64,
        /// Vertical drag in pixels (positive: downwards, looks down).
        dy_px: f64,
    },
    /// A frame with no input: the picture refines one level.
    Still,
}

/// Per-backend quality levels (0 = the backend's defaults or the user's options), indexed by
/// [`BackendId::index`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Quality {
    levels: [i32; COUNT],
}

impl Quality {
    /// The level of `kind` (backends without a quality knob, like the reference: always 0).
    pub fn of(&self, kind: BackendId) -> i32 {
        self.levels[kind.index()]
    }

    fn adjust(mut self, kind: BackendId, by: i32) -> Self {
        if kind.has_quality_knob() {
            let q = &mut self.levels[kind.index()];
            *q = (*q + by).clamp(-MAX_QUALITY, MAX_QUALITY);
        }
        self
    }
}

/// Everything the picture depends on that input changes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewState {
    /// Camera position, world units.
    pub position: DVec3,
    /// Turn to the right of the start direction about the up axis, degrees in (-180, 180].
    pub yaw_deg: f64,
    /// Elevation above the horizontal plane, degrees in [-89, 89].
    pub pitch_deg: f64,
    /// The backend shown (the left half in split mode).
    pub active: BackendId,
    /// The backend shown in the right half in split mode: the one shown before `active`.
    pub partner: BackendId,
    /// Whether the window is split between `active` (left) and `partner` (right).
    pub split: bool,
    /// Quality level of each backend.
    pub quality: Quality,
    /// Refinement level, 0..=[`MAX_REFINE`] (see [`REFINE_SCALES`]).
    pub refine: u8,
}

impl ViewState {
    /// The backends on screen: `active`, then `partner` in split mode.
    pub fn shown(&self) -> Vec<BackendId> {
        if self.split {
            vec![self.active, self.partner]
        } else {
            vec![self.active]
        }
    }

    /// Whether the frame is at full resolution.
    pub const fn is_refined(&self) -> bool {
        self.refine >= MAX_REFINE
    }

    /// The divisor of the window's width and height at the current refinement level.
    pub fn scale(&self) -> u32 {
        REFINE_SCALES[usize::from(self.refine.min(MAX_REFINE))]
    }
}

/// The fixed frame the camera turns in: yaw turns about `up`, pitch tilts towards it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orientation {
    /// The scene camera's up hint, normalized: the axis of yaw and of `Q`/`E`.
    pub up: DVec3,
    /// Horizontal direction of yaw 0 (the start direction projected off `up`).
    pub ahead: DVec3,
    /// `ahead x up`: the direction of yaw +90 degrees.
    pub right: DVec3,
}

impl Orientation {
    /// Unit view direction at `yaw_deg`, `pitch_deg`.
    pub fn forward(&self, yaw_deg: f64, pitch_deg: f64) -> DVec3 {
        let (sy, cy) = yaw_deg.to_radians().sin_cos();
        let (sp, cp) = pitch_deg.to_radians().sin_cos();
        (cp * (cy * self.ahead + sy * self.right) + sp * self.up).normalize()
    }

    /// Unit right direction at `yaw_deg` (horizontal: independent of pitch).
    pub fn right_at(&self, yaw_deg: f64) -> DVec3 {
        let (sy, cy) = yaw_deg.to_radians().sin_cos();
        (cy * self.right - sy * self.ahead).normalize()
    }
}

/// What the update rule needs besides the state: where R goes back to, the frame the camera
/// turns in and the step sizes. Fixed for a session.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewConfig {
    /// The state R returns to (camera and quality; backend and split are kept).
    pub home: ViewState,
    /// The frame yaw and pitch are measured in.
    pub orientation: Orientation,
    /// World units one movement key moves per event (per frame while held).
    pub step: f64,
    /// The scene camera this session starts from: field of view and the full window size.
    pub camera: CameraSpec,
}

impl ViewConfig {
    /// The configuration of a session starting from the scene camera `spec` with backend
    /// `active`, moving `step` world units per key event. Errors: the camera is invalid
    /// (`look_at == position`, `up` parallel to the view, non-finite values).
    pub fn new(spec: &CameraSpec, active: BackendId, step: f64) -> Result<Self, String> {
        let position = DVec3::from(spec.position);
        let forward = (DVec3::from(spec.look_at) - position)
            .try_normalize()
            .ok_or("camera look_at equals position")?;
        let up = DVec3::from(spec.up)
            .try_normalize()
            .ok_or("camera up is a zero vector")?;
        let ahead = (forward - forward.dot(up) * up)
            .try_normalize()
            .ok_or("camera up is parallel to the view direction")?;
        if !(step.is_finite() && step > 0.0) {
            return Err(format!("step must be a positive number, got {step}"));
        }
        let orientation = Orientation {
            up,
            ahead,
            right: ahead.cross(up),
        };
        let pitch_deg = forward
            .dot(up)
            .clamp(-1.0, 1.0)
            .asin()
            .to_degrees()
            .clamp(-MAX_PITCH_DEG, MAX_PITCH_DEG);
        // The second backend of the digit keys' order, or the first when it is the active
        // one (sdf and mesh show each other; the reference shows mesh).
        let order = view_order();
        let partner = if active == order[1] {
            order[0]
        } else {
            order[1]
        };
        Ok(ViewConfig {
            home: ViewState {
                position,
                yaw_deg: 0.0,
                pitch_deg,
                active,
                partner,
                split: false,
                quality: Quality::default(),
                refine: 0,
            },
            orientation,
            step,
            camera: spec.clone(),
        })
    }

    /// The camera of `state` as a scene file states it: `look_at = position + forward`, the
    /// start's up hint, field of view and window size. At the start camera it is the scene
    /// file's own camera (window size), so the start frame is `marchmesh render`'s of the
    /// scene itself.
    pub fn camera_spec(&self, state: &ViewState) -> CameraSpec {
        let home = &self.home;
        if (state.position, state.yaw_deg, state.pitch_deg)
            == (home.position, home.yaw_deg, home.pitch_deg)
        {
            return self.camera.clone();
        }
        let forward = self.orientation.forward(state.yaw_deg, state.pitch_deg);
        CameraSpec {
            position: state.position.to_array(),
            look_at: (state.position + forward).to_array(),
            up: self.orientation.up.to_array(),
            ..self.camera.clone()
        }
    }

    /// The camera of `state` exactly as `marchmesh render` builds it from the scene file the
    /// viewer saves for this state: the numbers go through the same JSON text and the same
    /// constructor, so a saved camera renders the same pixels. `None` if it is invalid (it
    /// cannot be: pitch stays below 90 degrees).
    pub fn camera(&self, state: &ViewState) -> Option<Camera> {
        let spec = self.camera_spec(state);
        let text = serde_json::to_string(&spec).ok()?;
        let c: CameraSpec = serde_json::from_str(&text).ok()?;
        Camera::look_at(
            DVec3::from(c.position),
            DVec3::from(c.look_at),
            DVec3::from(c.up),
            c.vfov_deg,
            c.width,
            c.height,
        )
    }
}

/// The state after `event`. Pure: the window and the script mode both call it once per
/// input, and everything they draw follows from the state it returns.
///
/// - `W`/`S` move `step` along the view direction (forward/back), `A`/`D` along the
///   horizontal right vector, `Q`/`E` along the up axis (down/up).
/// - a drag turns by [`LOOK_DEG_PER_PX`] per pixel: right turns right, down looks down;
///   pitch stays within [`MAX_PITCH_DEG`].
/// - `1`/`2`/`3` show the backends of [`view_order`] (sdf/mesh/reference); the one shown before becomes the split partner.
/// - `Tab` toggles the split; `+`/`-` change the active backend's quality level within
///   [`MAX_QUALITY`]; `R` restores the start camera and quality levels; `P` changes nothing.
/// - a still frame refines one level; anything that changes the picture restarts at level 0.
pub fn update(state: &ViewState, event: &Event, config: &ViewConfig) -> ViewState {
    let mut s = *state;
    match *event {
        Event::Still => {
            s.refine = (s.refine + 1).min(MAX_REFINE);
            return s;
        }
        Event::Drag { dx_px, dy_px } => {
            if !(dx_px.is_finite() && dy_px.is_finite()) || (dx_px == 0.0 && dy_px == 0.0) {
                return s;
            }
            s.yaw_deg = wrap_deg(s.yaw_deg + dx_px * LOOK_DEG_PER_PX);
            s.pitch_deg =
                (s.pitch_deg - dy_px * LOOK_DEG_PER_PX).clamp(-MAX_PITCH_DEG, MAX_PITCH_DEG);
        }
        Event::Key(key) => {
            let o = &config.orientation;
            let step = config.step;
            match key {
                Key::W => s.position += step * o.forward(s.yaw_deg, s.pitch_deg),
                Key::S => s.position -= step * o.forward(s.yaw_deg, s.pitch_deg),
                Key::D => s.position += step * o.right_at(s.yaw_deg),
                Key::A => s.position -= step * o.right_at(s.yaw_deg),
                Key::E => s.position += step * o.up,
                Key::Q => s.position -= step * o.up,
                Key::Digit1 | Key::Digit2 | Key::Digit3 => {
                    let Some(kind) = key.backend() else {
                        return s;
                    };
                    if kind == s.active {
                        return s;
                    }
                    s.partner = s.active;
                    s.active = kind;
                }
                Key::Tab => s.split = !s.split,
                Key::Plus => s.quality = s.quality.adjust(s.active, 1),
                Key::Minus => s.quality = s.quality.adjust(s.active, -1),
                Key::R => {
                    s.position = config.home.position;
                    s.yaw_deg = config.home.yaw_deg;
                    s.pitch_deg = config.home.pitch_deg;
                    s.quality = config.home.quality;
                }
                Key::P => return s,
            }
        }
    }
    if s != *state {
        s.refine = 0;
    }
    s
}

/// `deg` wrapped into (-180, 180].
fn wrap_deg(deg: f64) -> f64 {
    let w = deg.rem_euclid(360.0);
    if w > 180.0 { w - 360.0 } else { w }
}

#[cfg(test)]
mod tests {
    use super::*;
    use marchmesh_mesh::MeshBackend;
    use marchmesh_sdf::SdfBackend;

    const SDF: BackendId = BackendId::of::<SdfBackend>();
    const MESH: BackendId = BackendId::of::<MeshBackend>();

    fn config() -> ViewConfig {
        let spec = CameraSpec {
            position: [0.0, 0.0, 0.0],
            look_at: [0.0, 0.0, 1.0],
            up: [0.0, 1.0, 0.0],
            vfov_deg: 60.0,
            width: 64,
            height: 48,
        };
        ViewConfig::new(&spec, SDF, 0.5).expect("valid camera")
    }

    fn apply(events: &[Event]) -> ViewState {
        let c = config();
        events.iter().fold(c.home, |s, e| update(&s, e, &c))
    }

    fn close(a: DVec3, b: DVec3) -> bool {
        (a - b).length() < 1e-12
    }

    #[test]
    fn w_moves_forward_by_one_step_and_s_back() {
        let s = apply(&[Event::Key(Key::W)]);
        assert!(close(s.position, DVec3::new(0.0, 0.0, 0.5)), "{s:?}");
        let s = apply(&[Event::Key(Key::W), Event::Key(Key::W), Event::Key(Key::S)]);
        assert!(close(s.position, DVec3::new(0.0, 0.0, 0.5)), "{s:?}");
    }

    #[test]
    fn a_d_strafe_and_q_e_move_along_up() {
        // Looking along +z with up +y: right = forward x up = -x (right-handed).
        let s = apply(&[Event::Key(Key::D)]);
        assert!(close(s.position, DVec3::new(-0.5, 0.0, 0.0)), "{s:?}");
        let s = apply(&[Event::Key(Key::A), Event::Key(Key::E), Event::Key(Key::E)]);
        assert!(close(s.position, DVec3::new(0.5, 1.0, 0.0)), "{s:?}");
        let s = apply(&[Event::Key(Key::Q)]);
        assert!(close(s.position, DVec3::new(0.0, -0.5, 0.0)), "{s:?}");
    }

    #[test]
    fn the_start_camera_is_the_scene_files() {
        let c = config();
        let mut spec = c.camera.clone();
        spec.look_at = [0.0, 0.5, 7.0];
        let c = ViewConfig::new(&spec, SDF, 1.0).expect("valid");
        assert_eq!(c.camera_spec(&c.home), spec);
        let moved = update(&c.home, &Event::Key(Key::W), &c);
        let back = update(&moved, &Event::Key(Key::R), &c);
        assert_eq!(c.camera_spec(&back), spec, "R returns to it exactly");
        assert_ne!(c.camera_spec(&moved).position, spec.position);
    }

    #[test]
    fn right_matches_the_camera_right_vector() {
        let c = config();
        let cam = c.camera(&c.home).expect("camera");
        assert!(close(c.orientation.right_at(0.0), cam.right));
        assert!(close(c.orientation.forward(0.0, 0.0), cam.forward));
    }

    #[test]
    fn drag_turns_yaw_and_pitch_and_w_follows_the_view() {
        // 360 px right = 90 degrees: now looking along the old right vector (-x).
        let s = apply(&[Event::Drag {
            dx_px: 360.0,
            dy_px: 0.0,
        }]);
        assert!((s.yaw_deg - 90.0).abs() < 1e-12);
        let c = config();
        let s = update(&s, &Event::Key(Key::W), &c);
        assert!(close(s.position, DVec3::new(-0.5, 0.0, 0.0)), "{s:?}");
        // Dragging up looks up; pitch is clamped.
        let s = apply(&[Event::Drag {
            dx_px: 0.0,
            dy_px: -40.0,
        }]);
        assert!((s.pitch_deg - 10.0).abs() < 1e-12, "{s:?}");
        let s = apply(&[Event::Drag {
            dx_px: 0.0,
            dy_px: 1e6,
        }]);
        assert_eq!(s.pitch_deg, -MAX_PITCH_DEG);
        assert!(
            c.camera(&s).is_some(),
            "a clamped pitch is still a valid camera"
        );
        // Yaw wraps.
        let s = apply(&[Event::Drag {
            dx_px: 4.0 * 190.0,
            dy_px: 0.0,
        }]);
        assert!((s.yaw_deg + 170.0).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn r_resets_camera_and_quality_but_keeps_backend_and_split() {
        let s = apply(&[
            Event::Key(Key::W),
            Event::Drag {
                dx_px: 10.0,
                dy_px: 5.0,
            },
            Event::Key(Key::Plus),
            Event::Key(Key::Digit2),
            Event::Key(Key::Tab),
            Event::Key(Key::R),
        ]);
        let home = config().home;
        assert_eq!(s.position, home.position);
        assert_eq!((s.yaw_deg, s.pitch_deg), (home.yaw_deg, home.pitch_deg));
        assert_eq!(s.quality, Quality::default());
        assert_eq!(s.active, MESH);
        assert!(s.split);
    }

    #[test]
    fn digits_switch_backend_and_remember_the_partner() {
        let s = apply(&[Event::Key(Key::Digit2)]);
        assert_eq!((s.active, s.partner), (MESH, SDF));
        let s = apply(&[Event::Key(Key::Digit2), Event::Key(Key::Digit3)]);
        assert_eq!((s.active, s.partner), (BackendId::REFERENCE, MESH));
        let s = apply(&[Event::Key(Key::Digit1)]);
        assert_eq!(s.active, SDF, "pressing the shown backend's key");
        assert_eq!(s.partner, MESH);
    }

    #[test]
    fn tab_toggles_the_split() {
        let s = apply(&[Event::Key(Key::Tab)]);
        assert!(s.split);
        assert_eq!(s.shown(), vec![SDF, MESH]);
        let s = apply(&[Event::Key(Key::Tab), Event::Key(Key::Tab)]);
        assert!(!s.split);
        assert_eq!(s.shown(), vec![SDF]);
    }

    #[test]
    fn plus_minus_change_the_active_backend_quality_within_limits() {
        let s = apply(&[Event::Key(Key::Plus), Event::Key(Key::Plus)]);
        let levels = |s: ViewState| BackendId::ALL.map(|k| s.quality.of(k));
        let at = |sdf: i32, mesh: i32| {
            BackendId::ALL.map(|k| match k {
                SDF => sdf,
                MESH => mesh,
                _ => 0,
            })
        };
        assert_eq!(levels(s), at(2, 0));
        let s = apply(&[Event::Key(Key::Digit2), Event::Key(Key::Minus)]);
        assert_eq!(levels(s), at(0, -1));
        let many = vec![Event::Key(Key::Plus); 10];
        assert_eq!(apply(&many).quality.of(SDF), MAX_QUALITY);
        let s = apply(&[Event::Key(Key::Digit3), Event::Key(Key::Plus)]);
        assert_eq!(s.quality, Quality::default(), "the reference has no knob");
    }

    #[test]
    fn still_frames_refine_and_changes_restart_coarse() {
        let s = apply(&[Event::Still]);
        assert_eq!(s.refine, 1);
        let s = apply(&[Event::Still; 5]);
        assert_eq!(s.refine, MAX_REFINE);
        assert!(s.is_refined());
        assert_eq!(s.scale(), 1);
        let s = apply(&[Event::Still, Event::Still, Event::Key(Key::W)]);
        assert_eq!((s.refine, s.scale()), (0, 4));
        let s = apply(&[Event::Still, Event::Still, Event::Key(Key::P)]);
        assert_eq!(s.refine, MAX_REFINE, "P changes nothing");
        let s = apply(&[Event::Still, Event::Key(Key::Digit1)]);
        assert_eq!(s.refine, 1, "selecting the shown backend changes nothing");
    }

    #[test]
    fn keys_parse_from_script_names() {
        for k in Key::ALL {
            assert_eq!(Key::parse(k.name()), Some(k));
        }
        assert_eq!(Key::parse("w"), Some(Key::W));
        assert_eq!(Key::parse("tab"), Some(Key::Tab));
        assert_eq!(Key::parse("="), Some(Key::Plus));
        assert_eq!(Key::parse("F1"), None);
    }

    #[test]
    fn invalid_start_cameras_are_errors() {
        let mut spec = config().camera;
        spec.look_at = spec.position;
        assert!(ViewConfig::new(&spec, SDF, 1.0).is_err());
        let mut spec = config().camera;
        spec.up = [0.0, 0.0, 1.0];
        assert!(ViewConfig::new(&spec, SDF, 1.0).is_err());
        assert!(ViewConfig::new(&config().camera, SDF, f64::NAN).is_err());
    }
}
