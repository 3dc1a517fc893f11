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

impl BackgroundSampler {
    /// Loads the scene's background (reads the environment image, if any).
    pub fn load(background: &Background) -> Result<Self, BackgroundError> {
        match background {
            Background::Color(c) => Ok(Self::Color(c.as_vec3())),
            Background::Environment { path, intensity } => {
                let img = image::open(path).map_err(|e| BackgroundError::Load {
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
