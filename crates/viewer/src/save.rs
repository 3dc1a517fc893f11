//! P: a screenshot and the camera as a scene file, published without overwriting anything.
//!
//! The scene file is the session's own scene file with the camera replaced (position,
//! `look_at = position + view direction`, the start's up hint and field of view, the window
//! size) and relative asset paths made absolute, so `marchmesh render shot-000.json` renders
//! the same picture from any folder. Its description says which backend and options the
//! screenshot was taken with.

use std::path::{Path, PathBuf};

use marchmesh_scene::{BackgroundSpec, ObjectSpec, SceneFile, ShapeSpec};

use crate::ViewerError;
use crate::session::{Frame, Session, window_pixels};

/// Most shot numbers tried before giving up (`shot-000` ... `shot-9999`).
pub const MAX_SHOTS: u32 = 10_000;

/// The files one P wrote.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Shot {
    /// The screenshot (PNG, window size, no overlay).
    pub png: PathBuf,
    /// The scene file with the camera of the screenshot.
    pub scene: PathBuf,
}

impl Session {
    /// The scene file of `frame`'s camera as JSON text (validated by parsing it back).
    pub fn scene_json(&self, frame: &Frame) -> Result<String, ViewerError> {
        let mut file: SceneFile = self.file.clone();
        file.camera = self.config().camera_spec(&frame.state);
        let views: Vec<String> = frame
            .views
            .iter()
            .map(|v| {
                let opts: Vec<String> = v.options.iter().map(|(k, x)| format!("{k}={x}")).collect();
                if opts.is_empty() {
                    v.backend.to_string()
                } else {
                    format!("{} --opt {}", v.backend, opts.join(" --opt "))
                }
            })
            .collect();
        let note = format!(
            "camera saved by marchmesh view from {} (shown: {})",
            self.source().display(),
            views.join("; ")
        );
        file.description = Some(match file.description.as_deref().map(str::trim) {
            Some(d) if !d.is_empty() => format!("{d} | {note}"),
            _ => note,
        });
        absolute_paths(&mut file, &self.base_dir);
        let text = serde_json::to_string_pretty(&file)
            .map_err(|e| ViewerError::Options(format!("cannot write the scene as JSON: {e}")))?;
        marchmesh_scene::parse_file_format(&text, "saved scene")?;
        Ok(text + "\n")
    }

    /// Saves `frame` as `DIR/shot-NNN.png` (window size, nearest-pixel scaled when coarse, no
    /// overlay) and its camera as `DIR/shot-NNN.json`, with the first number for which
    /// neither file exists. Nothing is overwritten: a name taken meanwhile moves on to the
    /// next number.
    pub fn save_shot(&self, frame: &Frame, dir: &Path) -> Result<Shot, ViewerError> {
        let (w, h) = self.window_size();
        let pixels = window_pixels(&frame.image, w, h);
        let fb = crate::session::pixels_to_framebuffer(&pixels, w, h);
        let json = self.scene_json(frame)?;
        for n in 0..MAX_SHOTS {
            let png = dir.join(format!("shot-{n:03}.png"));
            let scene = dir.join(format!("shot-{n:03}.json"));
            if std::fs::symlink_metadata(&png).is_ok() || std::fs::symlink_metadata(&scene).is_ok()
            {
                continue;
            }
            let bytes = marchmesh_core::image_io::encode_color(&fb, false, &png)?;
            match marchmesh_safeio::publish_new(&scene, json.as_bytes()) {
                Err(marchmesh_safeio::SafeIoError::Exists { .. }) => continue,
                other => other?,
            }
            match marchmesh_safeio::publish_new(&png, &bytes) {
                Ok(()) => return Ok(Shot { png, scene }),
                Err(marchmesh_safeio::SafeIoError::Exists { .. }) => {
                    std::fs::remove_file(&scene).ok();
                }
                Err(e) => {
                    std::fs::remove_file(&scene).ok();
                    return Err(e.into());
                }
            }
        }
        Err(ViewerError::Options(format!(
            "{}: shot-000 ... shot-{} all exist",
            dir.display(),
            MAX_SHOTS - 1
        )))
    }
}

/// Makes every relative asset path of `file` (meshes, environment map) absolute against
/// `base`, the folder the original scene file resolves them against.
fn absolute_paths(file: &mut SceneFile, base: &Path) {
    let fix = |p: &mut String| {
        if Path::new(p.as_str()).is_relative() {
            *p = base.join(p.as_str()).display().to_string();
        }
    };
    if let BackgroundSpec::Environment(env) = &mut file.background {
        fix(&mut env.path);
    }
    // One guarded level per object: scene trees nest as deep as their files.
    fn visit(o: &mut ObjectSpec, fix: &dyn Fn(&mut String)) {
        marchmesh_scene::deep::guard(|| match &mut o.shape {
            ShapeSpec::Mesh(m) => fix(&mut m.path),
            ShapeSpec::Union(c) | ShapeSpec::Intersection(c) | ShapeSpec::Subtraction(c) => {
                c.children.iter_mut().for_each(|c| visit(c, fix));
            }
            ShapeSpec::SmoothUnion(s)
            | ShapeSpec::SmoothIntersection(s)
            | ShapeSpec::SmoothSubtraction(s)
            | ShapeSpec::Blend(s) => {
                s.children.iter_mut().for_each(|c| visit(c, fix));
            }
            ShapeSpec::Repeat(r) => visit(&mut r.child, fix),
            ShapeSpec::Sphere(_)
            | ShapeSpec::Plane(_)
            | ShapeSpec::Triangle(_)
            | ShapeSpec::Box(_)
            | ShapeSpec::RoundedBox(_)
            | ShapeSpec::Capsule(_)
            | ShapeSpec::CappedCone(_)
            | ShapeSpec::Ellipsoid(_)
            | ShapeSpec::Cylinder(_)
            | ShapeSpec::Torus(_) => {}
        })
    }
    for o in &mut file.objects {
        visit(o, &fix);
    }
}
