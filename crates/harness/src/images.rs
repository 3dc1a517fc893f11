//! Image-space measurements and outputs: SSIM, the size of the visible scene, difference
//! heatmaps, non-finite counts and step histograms.

use std::path::Path;

use glam::Vec3;
use marchmesh_core::Framebuffer;
use marchmesh_scene::Scene;

/// Mean SSIM of the 8-bit luma of two equally sized framebuffers, over 8x8 windows with
/// stride 4 (constants of Wang et al. 2004, L = 255). 1 when identical; `None` when the
/// sizes differ or the image is smaller than a window.
pub fn ssim(a: &Framebuffer, b: &Framebuffer) -> Option<f64> {
    if (a.width, a.height) != (b.width, b.height) || a.width < 8 || a.height < 8 {
        return None;
    }
    let luma = |fb: &Framebuffer| -> Vec<f64> {
        fb.to_rgb8()
            .pixels()
            .map(|p| 0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64)
            .collect()
    };
    let (x, y) = (luma(a), luma(b));
    let (w, h) = (a.width as usize, a.height as usize);
    let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
    let (mut sum, mut count) = (0.0, 0usize);
    let mut wy = 0;
    while wy + 8 <= h {
        let mut wx = 0;
        while wx + 8 <= w {
            let (mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for j in wy..wy + 8 {
                for i in wx..wx + 8 {
                    let (p, q) = (x[j * w + i], y[j * w + i]);
                    sx += p;
                    sy += q;
                    sxx += p * p;
                    syy += q * q;
                    sxy += p * q;
                }
            }
            let n = 64.0;
            let (mx, my) = (sx / n, sy / n);
            let vx = sxx / n - mx * mx;
            let vy = syy / n - my * my;
            let cov = sxy / n - mx * my;
            sum += ((2.0 * mx * my + c1) * (2.0 * cov + c2))
                / ((mx * mx + my * my + c1) * (vx + vy + c2));
            count += 1;
            wx += 4;
        }
        wy += 4;
    }
    Some(sum / count as f64)
}

/// Diagonal of the axis-aligned box around the points the primary rays of `fb` hit (camera
/// of `scene`), world units; `None` when nothing is hit. Depth errors divided by it are
/// comparable across scenes of different scale.
pub fn visible_scene_size(scene: &Scene, fb: &Framebuffer) -> Option<f64> {
    let cam = &scene.camera;
    let (mut lo, mut hi) = (
        glam::DVec3::splat(f64::INFINITY),
        glam::DVec3::splat(f64::NEG_INFINITY),
    );
    let mut any = false;
    for py in 0..fb.height {
        for px in 0..fb.width {
            let i = (py * fb.width + px) as usize;
            if !fb.is_hit(i) {
                continue;
            }
            let p =
                cam.position + cam.direction(px as f64 + 0.5, py as f64 + 0.5) * fb.depth[i] as f64;
            lo = lo.min(p);
            hi = hi.max(p);
            any = true;
        }
    }
    any.then(|| (hi - lo).length())
}

/// NaN/inf values in the colour of every pixel and the depth of hit pixels.
pub fn non_finite(fb: &Framebuffer) -> u64 {
    (0..fb.len())
        .filter(|&i| !fb.color[i].is_finite() || fb.depth[i].is_nan() || !fb.normal[i].is_finite())
        .count() as u64
}

/// Primary-ray step counts in power-of-two bins: bin 0 = 0 steps, bin k = 2^(k-1)..2^k-1.
/// Trailing empty bins are dropped.
pub fn steps_histogram(fb: &Framebuffer) -> Vec<u64> {
    let mut bins = vec![0u64; 33];
    for w in &fb.work {
        let b = (32 - w.steps.leading_zeros()) as usize;
        bins[b] += 1;
    }
    while bins.len() > 1 && bins.last() == Some(&0) {
        bins.pop();
    }
    bins
}

/// A colour ramp from dark blue through green to yellow for `t` in [0, 1].
fn ramp(t: f64) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0);
    let stops = [
        [0.05, 0.03, 0.25],
        [0.15, 0.35, 0.60],
        [0.15, 0.65, 0.45],
        [0.95, 0.90, 0.15],
    ];
    let s = t * 3.0;
    let i = (s.floor() as usize).min(2);
    let f = s - i as f64;
    let c: Vec<u8> = (0..3)
        .map(|k| ((stops[i][k] * (1.0 - f) + stops[i + 1][k] * f) * 255.0).round() as u8)
        .collect();
    [c[0], c[1], c[2]]
}

/// Difference heatmap of `test` against `reference` (same size): magenta where exactly one
/// of them hits (silhouette error), black where neither hits, otherwise the colour ramp of
/// the 8-bit colour difference (0 .. 64 levels mapped to the full ramp), as PNG bytes (the
/// caller publishes them, see [`publish_png`]).
pub fn diff_png(test: &Framebuffer, reference: &Framebuffer) -> image::ImageResult<Vec<u8>> {
    let (a, b) = (test.to_rgb8(), reference.to_rgb8());
    let mut img = image::RgbImage::new(test.width, test.height);
    for (i, px) in img.pixels_mut().enumerate() {
        let (th, rh) = (test.is_hit(i), reference.is_hit(i));
        let (x, y) = (i as u32 % test.width, i as u32 / test.width);
        *px = if th != rh {
            image::Rgb([255, 0, 255])
        } else if !th && a.get_pixel(x, y) == b.get_pixel(x, y) {
            image::Rgb([0, 0, 0])
        } else {
            let (p, q) = (a.get_pixel(x, y), b.get_pixel(x, y));
            let d = (0..3)
                .map(|k| (p[k] as i32 - q[k] as i32).unsigned_abs())
                .max()
                .unwrap_or(0);
            image::Rgb(ramp(d as f64 / 64.0))
        };
    }
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png)?;
    Ok(bytes.into_inner())
}

/// Publishes PNG bytes as a new file at `path` ([`marchmesh_safeio::publish_new`]): nothing
/// existing is overwritten (a symlink neither) and a failed write (a full disk) leaves no
/// partial file behind. Errors name the file.
pub fn publish_png(
    bytes: Result<Vec<u8>, impl std::fmt::Display>,
    path: &Path,
) -> Result<(), String> {
    let bytes = bytes.map_err(|e| format!("cannot encode: {e}"))?;
    marchmesh_safeio::publish_new(path, &bytes).map_err(|e| e.to_string())
}

/// The mean colour, for quick sanity checks.
pub fn mean_color(fb: &Framebuffer) -> Vec3 {
    fb.color.iter().copied().sum::<Vec3>() / fb.len().max(1) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(w: u32, h: u32, shift: f32) -> Framebuffer {
        let mut fb = Framebuffer::new(w, h);
        for (i, c) in fb.color.iter_mut().enumerate() {
            let v = ((i as u32 % w) as f32 / w as f32 + shift).clamp(0.0, 1.0);
            *c = Vec3::splat(v);
        }
        fb
    }

    #[test]
    fn ssim_is_one_for_identical_and_lower_for_different() {
        let a = gradient(32, 16, 0.0);
        assert!((ssim(&a, &a).unwrap() - 1.0).abs() < 1e-12);
        let b = gradient(32, 16, 0.3);
        let s = ssim(&a, &b).unwrap();
        assert!(s < 0.99 && s > -1.0, "{s}");
        assert!(ssim(&a, &gradient(32, 8, 0.0)).is_none());
    }

    #[test]
    fn histogram_bins_are_powers_of_two() {
        let mut fb = Framebuffer::new(4, 1);
        for (w, s) in fb.work.iter_mut().zip([0, 1, 3, 4]) {
            w.steps = s;
        }
        assert_eq!(steps_histogram(&fb), vec![1, 1, 1, 1]);
    }

    #[test]
    fn non_finite_counts_nan_colour() {
        let mut fb = Framebuffer::new(2, 1);
        assert_eq!(non_finite(&fb), 0);
        fb.color[1] = Vec3::NAN;
        assert_eq!(non_finite(&fb), 1);
        assert_eq!(mean_color(&Framebuffer::new(1, 1)), Vec3::ZERO);
    }
}
