//! Primary ray generation and the Halton sample sequence.

use glam::DVec2;
use marchmesh_scene::Camera;

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

/// Primary ray through pixel `(column, row)` (row 0 at the top) at sub-pixel `offset`, in render
/// space (camera at the origin). `t_max` is the scene's maximum distance.
pub fn primary_ray(camera: &Camera, column: u32, row: u32, offset: DVec2, t_max: f64) -> Ray {
    let d = camera.direction(column as f64 + offset.x, row as f64 + offset.y);
    Ray {
        origin: glam::Vec3::ZERO,
        dir: d.as_vec3().normalize(),
        t_min: 0.0,
        t_max: t_max as f32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

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
}
