//! Writing images and float AOVs.
//!
//! Colour goes to 8-bit PNG. Float AOVs go to PFM (Portable Float Map): a text header
//! `PF\n<width> <height>\n-1.0\n` (`Pf` for one channel) followed by little-endian f32 pixels,
//! rows from the *bottom* of the image to the top, as the format requires. PFM is read by
//! ImageMagick, GIMP, OpenCV and numpy in a few lines.

use std::io::{BufWriter, Write};
use std::path::Path;

use glam::Vec3;

use crate::framebuffer::Framebuffer;
use crate::geometry::Termination;

/// Why an image could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum ImageIoError {
    /// File system error.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// Encoder error.
    #[error("{}: {reason}", path.display())]
    Encode {
        /// The file.
        path: std::path::PathBuf,
        /// The encoder's message.
        reason: String,
    },
    /// A PFM file that does not follow the format.
    #[error("{}: not a valid PFM file: {reason}", path.display())]
    BadPfm {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        reason: String,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> ImageIoError + '_ {
    move |source| ImageIoError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Writes the colour buffer as an 8-bit PNG (see [`Framebuffer::to_rgb8`]).
pub fn write_png(fb: &Framebuffer, path: &Path) -> Result<(), ImageIoError> {
    fb.to_rgb8()
        .save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| ImageIoError::Encode {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })
}

/// The colour buffer encoded as 8-bit PNG (`jpeg == false`) or JPEG (quality 95) bytes, for
/// callers that publish files atomically. Errors: the encoder fails (named with `path`).
pub fn encode_color(fb: &Framebuffer, jpeg: bool, path: &Path) -> Result<Vec<u8>, ImageIoError> {
    let mut bytes = std::io::Cursor::new(Vec::new());
    let rgb = fb.to_rgb8();
    let result = if jpeg {
        rgb.write_with_encoder(image::codecs::jpeg::JpegEncoder::new_with_quality(
            &mut bytes, 95,
        ))
    } else {
        rgb.write_to(&mut bytes, image::ImageFormat::Png)
    };
    result.map_err(|e| ImageIoError::Encode {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    Ok(bytes.into_inner())
}

/// File names [`aov_files`] produces, in order: `color.pfm` (the linear, unclamped radiance of
/// each pixel, RGB), `depth.pfm` (distance along the primary ray, +inf for no hit),
/// `normal.pfm` (unit normal facing the camera, xyz), `mask.pfm` (1 hit, 0 no hit), `work.pfm`
/// (steps, node visits, primitive tests) and `termination.pfm` (0 hit, 1 miss, 2 max steps,
/// 3 max distance).
pub const AOV_FILE_NAMES: [&str; 6] = [
    "color.pfm",
    "depth.pfm",
    "normal.pfm",
    "mask.pfm",
    "work.pfm",
    "termination.pfm",
];

/// The AOVs of `fb` as `(file name, PFM bytes)` in [`AOV_FILE_NAMES`] order, so a caller can
/// publish them all-or-nothing.
pub fn aov_files(fb: &Framebuffer) -> Vec<(&'static str, Vec<u8>)> {
    let (w, h) = (fb.width, fb.height);
    let colors: Vec<f32> = fb.color.iter().flat_map(|c: &Vec3| c.to_array()).collect();
    let normals: Vec<f32> = fb.normal.iter().flat_map(|n: &Vec3| n.to_array()).collect();
    let mask: Vec<f32> = fb
        .depth
        .iter()
        .map(|d| if d.is_finite() { 1.0 } else { 0.0 })
        .collect();
    let work: Vec<f32> = fb
        .work
        .iter()
        .flat_map(|w| {
            [
                w.steps as f32,
                w.node_visits as f32,
                w.primitive_tests as f32,
            ]
        })
        .collect();
    let term: Vec<f32> = fb
        .termination
        .iter()
        .map(|t: &Termination| *t as u8 as f32)
        .collect();
    vec![
        (AOV_FILE_NAMES[0], encode_pfm(w, h, 3, &colors)),
        (AOV_FILE_NAMES[1], encode_pfm(w, h, 1, &fb.depth)),
        (AOV_FILE_NAMES[2], encode_pfm(w, h, 3, &normals)),
        (AOV_FILE_NAMES[3], encode_pfm(w, h, 1, &mask)),
        (AOV_FILE_NAMES[4], encode_pfm(w, h, 3, &work)),
        (AOV_FILE_NAMES[5], encode_pfm(w, h, 1, &term)),
    ]
}

/// `channels` (1 or 3) floats per pixel, `data` row-major from the top, as PFM bytes.
pub fn encode_pfm(width: u32, height: u32, channels: usize, data: &[f32]) -> Vec<u8> {
    let tag = if channels == 1 { "Pf" } else { "PF" };
    let mut out = format!("{tag}\n{width} {height}\n-1.0\n").into_bytes();
    let row = width as usize * channels;
    for r in (0..height as usize).rev() {
        for v in &data[r * row..(r + 1) * row] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// Writes `channels` (1 or 3) floats per pixel, `data` row-major from the top, as PFM.
pub fn write_pfm(
    path: &Path,
    width: u32,
    height: u32,
    channels: usize,
    data: &[f32],
) -> Result<(), ImageIoError> {
    let tag = if channels == 1 { "Pf" } else { "PF" };
    let f = std::fs::File::create(path).map_err(io_err(path))?;
    let mut w = BufWriter::new(f);
    let row = width as usize * channels;
    write!(w, "{tag}\n{width} {height}\n-1.0\n").map_err(io_err(path))?;
    for r in (0..height as usize).rev() {
        for v in &data[r * row..(r + 1) * row] {
            w.write_all(&v.to_le_bytes()).map_err(io_err(path))?;
        }
    }
    w.flush().map_err(io_err(path))
}

/// A PFM image read back: `(width, height, channels, data row-major from the top)`.
pub type PfmImage = (u32, u32, usize, Vec<f32>);

/// Reads a PFM written by [`write_pfm`] (either endianness).
pub fn read_pfm(path: &Path) -> Result<PfmImage, ImageIoError> {
    let bytes = marchmesh_safeio::read_regular(path).map_err(|e| ImageIoError::BadPfm {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let bad = |reason: &str| ImageIoError::BadPfm {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    };
    // Header: three whitespace-separated lines.
    let mut fields = Vec::new();
    let mut pos = 0;
    while fields.len() < 4 && pos < bytes.len() {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        fields.push(String::from_utf8_lossy(&bytes[start..pos]).to_string());
    }
    pos += 1; // the single whitespace after the scale
    if fields.len() < 4 {
        return Err(bad("truncated header"));
    }
    let channels = match fields[0].as_str() {
        "PF" => 3,
        "Pf" => 1,
        _ => return Err(bad("magic is neither PF nor Pf")),
    };
    let width: u32 = fields[1].parse().map_err(|_| bad("bad width"))?;
    let height: u32 = fields[2].parse().map_err(|_| bad("bad height"))?;
    let scale: f32 = fields[3].parse().map_err(|_| bad("bad scale"))?;
    let n = width as usize * height as usize * channels;
    let body = bytes
        .get(pos..pos + 4 * n)
        .ok_or_else(|| bad("truncated pixel data"))?;
    let mut data = vec![0.0f32; n];
    let row = width as usize * channels;
    for (i, chunk) in body.chunks_exact(4).enumerate() {
        let b = [chunk[0], chunk[1], chunk[2], chunk[3]];
        let v = if scale < 0.0 {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        };
        let (r, c) = (i / row, i % row);
        data[(height as usize - 1 - r) * row + c] = v;
    }
    Ok((width, height, channels, data))
}

/// Writes the AOVs of `fb` ([`AOV_FILE_NAMES`]) into `dir` (created if missing), replacing
/// files of those names (callers that must not overwrite publish [`aov_files`] themselves).
pub fn write_aovs(fb: &Framebuffer, dir: &Path) -> Result<(), ImageIoError> {
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    for (name, bytes) in aov_files(fb) {
        let path = dir.join(name);
        std::fs::write(&path, bytes).map_err(io_err(&path))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pfm_round_trips_and_stores_bottom_row_first() {
        let dir = std::env::temp_dir().join(format!("marchmesh-pfm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.pfm");
        let data: Vec<f32> = (0..6).map(|i| i as f32 * 1.5).collect(); // 3x2, 1 channel
        write_pfm(&p, 3, 2, 1, &data).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let header = b"Pf\n3 2\n-1.0\n";
        assert_eq!(&bytes[..header.len()], header);
        // First stored pixel is the bottom-left one (index 3).
        let first = f32::from_le_bytes(bytes[header.len()..header.len() + 4].try_into().unwrap());
        assert_eq!(first, 4.5);
        let (w, h, c, back) = read_pfm(&p).unwrap();
        assert_eq!((w, h, c), (3, 2, 1));
        assert_eq!(back, data);
        std::fs::write(&p, b"PF\n3 2\n-1.0\n\0\0").unwrap();
        assert!(matches!(read_pfm(&p), Err(ImageIoError::BadPfm { .. })));
        std::fs::remove_dir_all(&dir).ok();
    }
}
