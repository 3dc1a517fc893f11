//! What rays that leave the scene see: a colour or an equirectangular environment map.

use std::path::PathBuf;

use glam::Vec3;
use marchmesh_scene::Background;

/// Why an environment map could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum BackgroundError {
    /// The image could not be opened or decoded.
    #[error("{}: cannot load environment map: {reason}", path.display())]
    Load {
        /// The image file.
        path: PathBuf,
        /// The decoder's message.
        reason: String,
    },
    /// Decoding the image would need more memory than the limit allows (checked from its
    /// header, before any pixel is decoded).
    #[error(
        "{}: environment map of {width}x{height} pixels needs about {needed_bytes} bytes to load, over the memory limit of {limit_bytes} bytes",
        path.display()
    )]
    TooLarge {
        /// The image file.
        path: PathBuf,
        /// Width in pixels, from the header.
        width: u32,
        /// Height in pixels, from the header.
        height: u32,
        /// The estimate ([`ENVIRONMENT_BYTES_PER_TEXEL`] per pixel).
        needed_bytes: u64,
        /// The limit.
        limit_bytes: u64,
    },
    /// The image has no pixels.
    #[error("{}: environment map is empty", path.display())]
    Empty {
        /// The image file.
        path: PathBuf,
    },
}

/// A loaded background, sampled by direction.
#[derive(Debug, Clone, PartialEq)]
pub enum BackgroundSampler {
    /// Constant colour.
    Color(Vec3),
    /// Equirectangular image, linear RGB, row-major from the top.
    Environment {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// Pixels (already multiplied by the intensity).
        texels: Vec<Vec3>,
    },
}

/// Bytes loading an environment map takes per pixel at its peak: the decoded image (at most
/// 16, four f32 channels), its f32 RGB copy (12) and the texels (12).
pub const ENVIRONMENT_BYTES_PER_TEXEL: u64 = 40;

/// The bytes of the environment map at `path`: a regular file within the read cap, read
/// without blocking on a FIFO.
fn environment_bytes(path: &std::path::Path) -> Result<Vec<u8>, BackgroundError> {
    marchmesh_safeio::read_regular(path).map_err(|e| BackgroundError::Load {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

/// A reader of image `bytes` with the format guessed from them; errors name `path`.
fn environment_reader<'a>(
    path: &std::path::Path,
    bytes: &'a [u8],
) -> Result<image::ImageReader<std::io::Cursor<&'a [u8]>>, BackgroundError> {
    image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| BackgroundError::Load {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })
}

/// Checks the environment map of `background` (if any) from its header alone: readable,
/// decodable format, not empty, and loadable within `memory_limit_bytes` (what `validate`
/// reports before a render would fail).
///
/// Errors: as [`BackgroundSampler::load_within`], without decoding the pixels.
pub fn check_background(
    background: &Background,
    memory_limit_bytes: u64,
) -> Result<(), BackgroundError> {
    if let Background::Environment { path, .. } = background {
        environment_size(path, &environment_bytes(path)?, memory_limit_bytes)?;
    }
    Ok(())
}

/// The size of the environment map `bytes` (of `path`) from its header, checked against the
/// budget.
fn environment_size(
    path: &std::path::Path,
    bytes: &[u8],
    memory_limit_bytes: u64,
) -> Result<(u32, u32), BackgroundError> {
    let (width, height) = environment_reader(path, bytes)?
        .into_dimensions()
        .map_err(|e| BackgroundError::Load {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
    if width == 0 || height == 0 {
        return Err(BackgroundError::Empty {
            path: path.to_path_buf(),
        });
    }
    let needed_bytes = u64::from(width)
        .saturating_mul(u64::from(height))
        .saturating_mul(ENVIRONMENT_BYTES_PER_TEXEL);
    if needed_bytes > memory_limit_bytes {
        return Err(BackgroundError::TooLarge {
            path: path.to_path_buf(),
            width,
            height,
            needed_bytes,
            limit_bytes: memory_limit_bytes,
        });
    }
    Ok((width, height))
}

impl BackgroundSampler {
    /// Loads the scene's background (reads the environment image, if any) within
    /// [`crate::DEFAULT_MEMORY_LIMIT_BYTES`]; see [`Self::load_within`].
    pub fn load(background: &Background) -> Result<Self, BackgroundError> {
        Self::load_within(background, crate::DEFAULT_MEMORY_LIMIT_BYTES)
    }

    /// Loads the scene's background. An environment map is read as a regular file within the
    /// read cap and its size is checked from the header against `memory_limit_bytes`
    /// ([`ENVIRONMENT_BYTES_PER_TEXEL`] per pixel) before any pixel is decoded.
    ///
    /// Errors: the file is unreadable or not an image, empty, or over the limit.
    pub fn load_within(
        background: &Background,
        memory_limit_bytes: u64,
    ) -> Result<Self, BackgroundError> {
        match background {
            Background::Color(c) => Ok(Self::Color(c.as_vec3())),
            Background::Environment { path, intensity } => {
                let bytes = environment_bytes(path)?;
                environment_size(path, &bytes, memory_limit_bytes)?;
                let mut reader = environment_reader(path, &bytes)?;
                let mut limits = image::Limits::default();
                limits.max_alloc = Some(memory_limit_bytes);
                reader.limits(limits);
                let img = reader.decode().map_err(|e| BackgroundError::Load {
                    path: path.clone(),
                    reason: e.to_string(),
                })?;
                let img = img.to_rgb32f();
                if img.width() == 0 || img.height() == 0 {
                    return Err(BackgroundError::Empty { path: path.clone() });
                }
                let k = *intensity as f32;
                Ok(Self::Environment {
                    width: img.width(),
                    height: img.height(),
                    texels: img.pixels().map(|p| Vec3::from(p.0) * k).collect(),
                })
            }
        }
    }

    /// The radiance of a plain colour background (the same in every direction), else `None`.
    #[inline]
    pub fn constant(&self) -> Option<Vec3> {
        match self {
            Self::Color(c) => Some(*c),
            Self::Environment { .. } => None,
        }
    }

    /// Radiance seen along unit direction `dir` (nearest texel of the equirectangular map:
    /// `u = 0.5 + atan2(x, -z) / 2pi`, `v = acos(y) / pi`).
    #[inline]
    pub fn sample(&self, dir: Vec3) -> Vec3 {
        match self {
            Self::Color(c) => *c,
            Self::Environment {
                width,
                height,
                texels,
            } => {
                let u = 0.5 + dir.x.atan2(-dir.z) / std::f32::consts::TAU;
                let v = dir.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI;
                if !(u.is_finite() && v.is_finite()) {
                    return Vec3::ZERO;
                }
                let x = ((u * *width as f32) as i64).rem_euclid(*width as i64) as usize;
                let y = ((v * *height as f32) as usize).min(*height as usize - 1);
                texels[y * *width as usize + x]
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equirect_lookup_hits_expected_texels() {
        // 4x2 map: top row 0..4, bottom row 4..8 (value = index).
        let texels = (0..8).map(|i| Vec3::splat(i as f32)).collect();
        let env = BackgroundSampler::Environment {
            width: 4,
            height: 2,
            texels,
        };
        // Straight up: top row; -z forward: u = 0.5 -> column 2.
        assert_eq!(env.sample(Vec3::new(0.0, 0.3, -1.0).normalize()).x, 2.0);
        assert_eq!(env.sample(Vec3::new(0.0, -0.3, -1.0).normalize()).x, 6.0);
        // +x: u = 0.75 -> column 3.
        assert_eq!(env.sample(Vec3::new(1.0, 0.1, 0.0).normalize()).x, 3.0);
        assert_eq!(env.sample(Vec3::NAN), Vec3::ZERO);
    }
}
