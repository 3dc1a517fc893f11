//! Scripts of input events for `marchmesh view --headless --script FILE --frames DIR`.
//!
//! A script is a JSON array of entries, each one of:
//!
//! | entry | frames rendered |
//! |---|---|
//! | `{"key": "W", "frames": 10}` | a movement key (`W A S D Q E`) held for 10 frames: one step each (default 1) |
//! | `{"key": "2"}`, `{"key": "Tab", "frames": 3}` | the key pressed once on the first frame, then still frames up to `frames` (default 1); keys `1 2 3 Tab + - R` |
//! | `{"mouse_drag": [dx, dy]}` | a drag of `dx, dy` window pixels on each of `frames` frames (default 1) |
//! | `{"wait": 3}` | 3 still frames: the picture refines one level per frame |
//! | `{"key": "P"}` | no frame: saves the last frame (or renders one first) as `shot-NNN.png` and its camera as `shot-NNN.json` |
//!
//! Unknown fields, unknown keys, zero or too many frames and non-finite drags are errors that
//! name the file, the entry (0-based) and its line.

use std::path::Path;

use serde::Deserialize;

use crate::ViewerError;
use crate::state::{Event, Key};

/// Most frames one entry may ask for.
pub const MAX_FRAMES_PER_ENTRY: u32 = 10_000;

/// Most frames a whole script may render.
pub const MAX_FRAMES: u64 = 100_000;

/// Largest drag of one entry per frame, window pixels.
pub const MAX_DRAG_PX: f64 = 100_000.0;

/// What the script runner does next.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Step {
    /// Apply the event, then render and write a frame.
    Frame(Event),
    /// Save the last frame and the camera (P).
    Save,
}

/// One entry as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEntry {
    key: Option<String>,
    frames: Option<u32>,
    mouse_drag: Option<[f64; 2]>,
    wait: Option<u32>,
}

/// A parsed script.
#[derive(Debug, Clone, PartialEq)]
pub struct Script {
    /// The steps in order.
    pub steps: Vec<Step>,
}

impl Script {
    /// Frames the script renders (P with no frame before it renders one).
    pub fn frame_count(&self) -> u64 {
        let frames = self
            .steps
            .iter()
            .filter(|s| matches!(s, Step::Frame(_)))
            .count() as u64;
        let save_first = matches!(self.steps.first(), Some(Step::Save));
        frames + u64::from(save_first)
    }

    /// Reads and parses a script file (capped read of a regular file).
    pub fn load(path: &Path) -> Result<Script, ViewerError> {
        let bytes = marchmesh_safeio::read_regular(path)?;
        let text = std::str::from_utf8(&bytes).map_err(|e| ViewerError::Script {
            file: path.to_path_buf(),
            entry: None,
            line: 1,
            reason: format!("not UTF-8 text (byte offset {})", e.valid_up_to()),
        })?;
        Script::parse(text, path)
    }

    /// Parses script text; `path` names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Script, ViewerError> {
        let err = |entry: Option<usize>, line: usize, reason: String| ViewerError::Script {
            file: path.to_path_buf(),
            entry,
            line,
            reason,
        };
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut de = serde_json::Deserializer::from_str(text);
        let raw: Vec<RawEntry> = serde_path_to_error::deserialize(&mut de).map_err(|e| {
            let path = e.path().to_string();
            let entry = entry_index(&path);
            let inner = e.into_inner();
            let reason = strip_position(&inner.to_string());
            // Name the field when the error is inside an entry (`[0].mouse_drag`).
            let reason = match path.split_once('.') {
                Some((_, field)) if entry.is_some() && !field.is_empty() => {
                    format!("\"{field}\": {reason}")
                }
                _ => reason,
            };
            err(entry, inner.line(), reason)
        })?;
        de.end()
            .map_err(|e| err(None, e.line(), strip_position(&e.to_string())))?;
        let lines = entry_lines(text, raw.len());
        let mut steps = Vec::new();
        let mut frames_total = 0u64;
        for (i, entry) in raw.iter().enumerate() {
            let line = lines.get(i).copied().unwrap_or(1);
            let new = entry_steps(entry).map_err(|reason| err(Some(i), line, reason))?;
            frames_total += new.iter().filter(|s| matches!(s, Step::Frame(_))).count() as u64;
            if frames_total > MAX_FRAMES {
                return Err(err(
                    Some(i),
                    line,
                    format!("the script renders more than {MAX_FRAMES} frames"),
                ));
            }
            steps.extend(new);
        }
        if steps.is_empty() {
            return Err(err(None, 1, "the script has no entries".into()));
        }
        Ok(Script { steps })
    }
}

/// The steps of one entry, or why it is wrong.
fn entry_steps(e: &RawEntry) -> Result<Vec<Step>, String> {
    let given = [e.key.is_some(), e.mouse_drag.is_some(), e.wait.is_some()];
    if given.iter().filter(|g| **g).count() != 1 {
        return Err(
            "an entry needs exactly one of \"key\", \"mouse_drag\" and \"wait\"".to_string(),
        );
    }
    let frames = |default: u32| -> Result<u32, String> {
        match e.frames {
            None => Ok(default),
            Some(0) => Err("\"frames\" must be at least 1".to_string()),
            Some(n) if n > MAX_FRAMES_PER_ENTRY => Err(format!(
                "\"frames\" is {n}, over the limit of {MAX_FRAMES_PER_ENTRY}"
            )),
            Some(n) => Ok(n),
        }
    };
    if let Some(n) = e.wait {
        if e.frames.is_some() {
            return Err("\"wait\" takes no \"frames\" (the wait is the frame count)".into());
        }
        if n == 0 || n > MAX_FRAMES_PER_ENTRY {
            return Err(format!(
                "\"wait\" must be in 1..={MAX_FRAMES_PER_ENTRY}, got {n}"
            ));
        }
        return Ok(vec![Step::Frame(Event::Still); n as usize]);
    }
    if let Some([dx, dy]) = e.mouse_drag {
        if !(dx.is_finite() && dy.is_finite()) || dx.abs() > MAX_DRAG_PX || dy.abs() > MAX_DRAG_PX {
            return Err(format!(
                "\"mouse_drag\" values must be finite and within +-{MAX_DRAG_PX} pixels"
            ));
        }
        let event = Event::Drag {
            dx_px: dx,
            dy_px: dy,
        };
        return Ok(vec![Step::Frame(event); frames(1)? as usize]);
    }
    let name = e.key.as_deref().unwrap_or_default();
    let key = Key::parse(name).ok_or_else(|| {
        let names: Vec<&str> = Key::ALL.iter().map(|k| k.name()).collect();
        format!(
            "unknown key {name:?} (keys: {}; \"mouse_drag\" and \"wait\" are entries of their own)",
            names.join(" ")
        )
    })?;
    if key == Key::P {
        if e.frames.is_some() {
            return Err("\"P\" renders no frame and takes no \"frames\"".into());
        }
        return Ok(vec![Step::Save]);
    }
    let n = frames(1)? as usize;
    if key.is_movement() {
        return Ok(vec![Step::Frame(Event::Key(key)); n]);
    }
    let mut steps = vec![Step::Frame(Event::Key(key))];
    steps.extend(std::iter::repeat_n(Step::Frame(Event::Still), n - 1));
    Ok(steps)
}

/// The entry index of a serde path like `[3].frames`.
fn entry_index(path: &str) -> Option<usize> {
    path.strip_prefix('[')?.split(']').next()?.parse().ok()
}

/// 1-based line on which each of the first `n` top-level array entries starts: the line of
/// each `{` at nesting depth 1 outside strings (the text already parsed as JSON).
fn entry_lines(text: &str, n: usize) -> Vec<usize> {
    let (mut line, mut depth, mut in_string, mut escaped) = (1usize, 0i32, false, false);
    let mut out = Vec::with_capacity(n);
    for c in text.chars() {
        if in_string {
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, '\\') => escaped = true,
                (false, '"') => in_string = false,
                _ => {}
            }
            if c == '\n' {
                line += 1;
            }
            continue;
        }
        match c {
            '\n' => line += 1,
            '"' => in_string = true,
            '[' | '{' => {
                if depth == 1 && c == '{' {
                    out.push(line);
                }
                depth += 1;
            }
            ']' | '}' => depth -= 1,
            _ => {}
        }
    }
    out
}

fn strip_position(msg: &str) -> String {
    match msg.rfind(" at line ") {
        Some(i) => msg[..i].to_string(),
        None => msg.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Script, ViewerError> {
        Script::parse(text, Path::new("s.json"))
    }

    #[test]
    fn entries_expand_to_frames() {
        let s = parse(
            r#"[{"key":"W","frames":3},{"mouse_drag":[4,-2]},{"key":"Tab","frames":2},
                {"wait":2},{"key":"P"},{"key":"2"}]"#,
        )
        .expect("valid");
        let w = Step::Frame(Event::Key(Key::W));
        let still = Step::Frame(Event::Still);
        assert_eq!(
            s.steps,
            vec![
                w,
                w,
                w,
                Step::Frame(Event::Drag {
                    dx_px: 4.0,
                    dy_px: -2.0
                }),
                Step::Frame(Event::Key(Key::Tab)),
                still,
                still,
                still,
                Step::Save,
                Step::Frame(Event::Key(Key::Digit2)),
            ]
        );
        assert_eq!(s.frame_count(), 9);
        assert_eq!(parse(r#"[{"key":"P"}]"#).expect("valid").frame_count(), 1);
    }

    fn error(text: &str) -> String {
        parse(text).expect_err("invalid").to_string()
    }

    #[test]
    fn errors_name_file_entry_line_and_reason() {
        let e = error("[\n{\"key\":\"W\"},\n{\"key\":\"F1\"}\n]");
        assert!(
            e.contains("s.json") && e.contains("entry 1") && e.contains("line 3"),
            "{e}"
        );
        assert!(e.contains("unknown key \"F1\""), "{e}");
        let e = error("[{\"key\":\"W\"},\n {\"kee\":\"W\"}]");
        assert!(
            e.contains("entry 1") && e.contains("line 2") && e.contains("kee"),
            "{e}"
        );
        let e = error(r#"[{"key":"W","wait":2}]"#);
        assert!(e.contains("exactly one"), "{e}");
        let e = error(r#"[{"wait":0}]"#);
        assert!(e.contains("wait"), "{e}");
        let e = error(r#"[{"key":"W","frames":0}]"#);
        assert!(e.contains("at least 1"), "{e}");
        let e = error(r#"[{"key":"W","frames":1000000}]"#);
        assert!(e.contains("limit"), "{e}");
        let e = error(r#"[{"mouse_drag":[1e300,0]}]"#);
        assert!(e.contains("mouse_drag"), "{e}");
        let e = error(r#"[{"mouse_drag":[1]}]"#);
        assert!(e.contains("entry 0"), "{e}");
        let e = error(r#"[{"key":"P","frames":2}]"#);
        assert!(e.contains("P"), "{e}");
        let e = error("[]");
        assert!(e.contains("no entries"), "{e}");
        let e = error("[{\"key\":\"W\"}");
        assert!(e.contains("s.json") && e.contains("line 1"), "{e}");
        let e = error("{\"key\":\"W\"}");
        assert!(e.contains("s.json"), "{e}");
        let e = error("[{\"key\":\"W\"}] x");
        assert!(e.contains("trailing"), "{e}");
        let many = format!("[{}]", [r#"{"wait":10000}"#; 11].join(","));
        assert!(error(&many).contains("more than"));
    }

    #[test]
    fn entry_lines_skip_strings_and_nesting() {
        let text = "[\n {\"key\": \"{[\"},\n {\"mouse_drag\": [1, 2]}, {\"wait\": 1}\n]";
        assert_eq!(entry_lines(text, 3), vec![2, 3, 3]);
    }
}
