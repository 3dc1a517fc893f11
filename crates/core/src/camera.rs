//! Primary ray generation and the Halton sample sequence.

use glam::{DVec2, DVec3};
use marchmesh_scene::{Camera, ImagePlane};

use crate::geometry::Ray;

/// Radical inverse of `index` in `base` (the van der Corput sequence), in [0, 1).
pub fn radical_inverse(mut index: u32, base: u32) -> f64 {
    let inv_base = 1.0 / base as f64;
    let mut factor = inv_base;
    let mut result = 0.0;
    while index > 0 {
        result += (index % base) as f64 * factor;
        index /= base;
        factor *= inv_base;
    }
    result
}

/// Sub-pixel offset in [0, 1)^2 of anti-aliasing sample `sample`.
///
/// Sample 0 is the pixel centre `(0.5, 0.5)`, so one sample per pixel (and every AOV, which
/// records sample 0) samples exactly the centre; sample `s >= 1` is the Halton (2, 3) point of
/// index `s`, a low-discrepancy sequence that fills the pixel evenly.
pub fn sample_offset(sample: u32) -> DVec2 {
    if sample == 0 {
        DVec2::splat(0.5)
    } else {
        DVec2::new(radical_inverse(sample, 2), radical_inverse(sample, 3))
    }
}

/// Exact unit direction (f64, render space) of the camera ray through pixel `(column, row)`
/// (row 0 at the top) at sub-pixel `offset`: the README's camera model, before any rounding.
pub fn primary_direction(camera: &Camera, column: u32, row: u32, offset: DVec2) -> DVec3 {
    camera.direction(column as f64 + offset.x, row as f64 + offset.y)
}

/// Primary ray through pixel `(column, row)` (row 0 at the top) at sub-pixel `offset`, in render
/// space (camera at the origin): [`primary_direction`] rounded to f32. `t_max` is the scene's
/// maximum distance.
pub fn primary_ray(camera: &Camera, column: u32, row: u32, offset: DVec2, t_max: f64) -> Ray {
    primary_ray_on(&camera.image_plane(), column, row, offset, t_max)
}

/// [`primary_ray`] on a camera's precomputed [`ImagePlane`] (`Camera::image_plane`), for
/// loops over many pixels: the same ray, without a tangent per ray.
pub fn primary_ray_on(plane: &ImagePlane, column: u32, row: u32, offset: DVec2, t_max: f64) -> Ray {
    let d = plane.direction(column as f64 + offset.x, row as f64 + offset.y);
    Ray {
        origin: glam::Vec3::ZERO,
        dir: d.as_vec3().normalize(),
        t_min: 0.0,
        t_max: t_max as f32,
    }
}

/// The camera samples behind one batch of primary rays (one image row), so a backend that
/// computes in f64 can trace the exact camera ray instead of widening its f32 rounding
/// (which turns an off-axis ray by up to ~3e-8 rad: whole silhouette pixels at 1e5 units).
///
/// Ray `i` of the batch is anti-aliasing sample `i / width` ([`sample_offset`]) of pixel
/// column `i % width` in `row`, and starts at the camera (the render-space origin).
#[derive(Debug, Clone, Copy)]
pub struct PrimarySamples<'a> {
    camera: &'a Camera,
    plane: ImagePlane,
    row: u32,
    first_sample: u32,
}

impl<'a> PrimarySamples<'a> {
    /// The samples of image row `row` of `camera`, ordered as the integrator batches them.
    pub fn row(camera: &'a Camera, row: u32) -> Self {
        Self {
            camera,
            plane: camera.image_plane(),
            row,
            first_sample: 0,
        }
    }

    /// The same row's samples from sample `first` on (a batch holding samples `first..`, as
    /// the path tracer's chunks do): ray `i` is sample `first + i / width`.
    pub fn starting_at(self, first: u32) -> Self {
        Self {
            first_sample: first,
            ..self
        }
    }

    /// Exact unit direction (f64, render space) of ray `index` of the batch; the batch's f32
    /// ray `index` is its rounding. An index past the row's samples wraps to further samples.
    pub fn direction(&self, index: usize) -> DVec3 {
        let width = self.camera.width.max(1) as usize;
        let sample = u32::try_from(index / width)
            .unwrap_or(u32::MAX)
            .saturating_add(self.first_sample);
        let offset = sample_offset(sample);
        self.plane.direction(
            (index % width) as f64 + offset.x,
            self.row as f64 + offset.y,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn study_camera() -> Camera {
        // The source study: 1x1 viewport at distance 1, looking along +z.
        let vfov = 2.0 * 0.5f64.atan();
        Camera::look_at(DVec3::ZERO, DVec3::Z, DVec3::Y, vfov.to_degrees(), 500, 500).unwrap()
    }

    #[test]
    fn centre_pixel_looks_forward_and_corners_match_hand_computed_rays() {
        let cam = study_camera();
        // Right-handed: right = cross(forward, up) = cross(z, y) = -x.
        assert!((cam.right - DVec3::NEG_X).length() < 1e-12);
        // Pixel centre of the top-left pixel: x = (2*0.5/500 - 1)*0.5, y = (1 - 2*0.5/500)*0.5.
        let x = (2.0 * 0.5 / 500.0 - 1.0) * 0.5;
        let y = (1.0 - 2.0 * 0.5 / 500.0) * 0.5;
        let expect = (DVec3::Z + x * DVec3::NEG_X + y * DVec3::Y).normalize();
        let r = primary_ray(&cam, 0, 0, sample_offset(0), 100.0);
        assert!(
            (r.dir.as_dvec3() - expect).length() < 1e-6,
            "{:?} vs {expect:?}",
            r.dir
        );
        // The image centre (between the 4 central pixels) is straight ahead.
        let d = cam.direction(250.0, 250.0);
        assert!((d - DVec3::Z).length() < 1e-12);
        // Bottom-right corner point of the image: (x, y) = (0.5, -0.5) on the viewport.
        let d = cam.direction(500.0, 500.0);
        let e = (DVec3::Z + 0.5 * DVec3::NEG_X - 0.5 * DVec3::Y).normalize();
        assert!((d - e).length() < 1e-12);
    }

    #[test]
    fn non_square_image_widens_horizontal_fov() {
        let cam = Camera::look_at(DVec3::ZERO, DVec3::Z, DVec3::Y, 90.0, 200, 100).unwrap();
        // Right edge at mid-height: x = tan(45deg) * 2 = 2.
        let d = cam.direction(200.0, 50.0);
        let e = (DVec3::Z + 2.0 * DVec3::NEG_X).normalize();
        assert!((d - e).length() < 1e-12);
    }

    #[test]
    fn halton_points_are_the_known_sequence() {
        assert_eq!(radical_inverse(1, 2), 0.5);
        assert_eq!(radical_inverse(2, 2), 0.25);
        assert_eq!(radical_inverse(3, 2), 0.75);
        assert!((radical_inverse(1, 3) - 1.0 / 3.0).abs() < 1e-15);
        assert!((radical_inverse(5, 3) - (2.0 / 3.0 + 1.0 / 9.0)).abs() < 1e-15);
        assert_eq!(sample_offset(0), DVec2::splat(0.5));
        for s in 1..64 {
            let o = sample_offset(s);
            assert!((0.0..1.0).contains(&o.x) && (0.0..1.0).contains(&o.y));
        }
    }

    #[test]
    fn primary_samples_are_the_exact_directions_the_f32_rays_round() {
        let cam = Camera::look_at(
            DVec3::new(1.0, 2.0, -3.0),
            DVec3::new(0.3, 0.1, 0.7),
            DVec3::Y,
            35.0,
            7,
            5,
        )
        .unwrap();
        let samples = PrimarySamples::row(&cam, 3);
        for s in 0..3u32 {
            for col in 0..7u32 {
                let exact = samples.direction((s * 7 + col) as usize);
                let expect = primary_direction(&cam, col, 3, sample_offset(s));
                assert_eq!(exact, expect);
                assert!((exact.length() - 1.0).abs() < 1e-15);
                let ray = primary_ray(&cam, col, 3, sample_offset(s), 10.0);
                assert!((ray.dir.as_dvec3() - exact).length() < 1e-6);
            }
        }
    }
}
