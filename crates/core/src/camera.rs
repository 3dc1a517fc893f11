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
/// space (camera at the origin): [`primary_direction`] rounded to f32 per component. There is
/// no f32 renormalisation: the rounding is within a relative 2^-24 of unit length, and
/// renormalising (rounding a second time) would not bring it closer to the exact direction.
/// `t_max` is the scene's maximum distance.
pub fn primary_ray(camera: &Camera, column: u32, row: u32, offset: DVec2, t_max: f64) -> Ray {
    primary_ray_on(&camera.image_plane(), column, row, offset, t_max)
}

/// [`primary_ray`] on a camera's precomputed [`ImagePlane`] (`Camera::image_plane`), for
/// loops over many pixels: the same ray, without a tangent per ray.
pub fn primary_ray_on(plane: &ImagePlane, column: u32, row: u32, offset: DVec2, t_max: f64) -> Ray {
    let d = plane.direction(column as f64 + offset.x, row as f64 + offset.y);
    Ray {
        origin: glam::Vec3::ZERO,
        dir: d.as_vec3(),
        t_min: 0.0,
        t_max: t_max as f32,
    }
}

/// A rectangle of image pixels: columns `x..x + width`, rows `y..y + height` (row 0 at the
/// top). The integrator traces the camera rays of one tile as one batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tile {
    /// First column.
    pub x: u32,
    /// First row.
    pub y: u32,
    /// Columns (>= 1).
    pub width: u32,
    /// Rows (>= 1).
    pub height: u32,
}

impl Tile {
    /// Pixels in the tile.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

/// The camera samples behind one batch of primary rays (one screen [`Tile`]), so a backend
/// that computes in f64 can trace the exact camera ray instead of widening its f32 rounding
/// (which turns an off-axis ray by up to ~3e-8 rad: whole silhouette pixels at 1e5 units).
///
/// Ray `i` of the batch is anti-aliasing sample `first + i / n` ([`sample_offset`]) of the
/// tile's pixel `j = i % n` (`n` the tile's pixel count), counted row-major within the tile:
/// column `x + j % width`, row `y + j / width` ([`PrimarySamples::pixel`]). Every ray starts
/// at the camera (the render-space origin).
#[derive(Debug, Clone, Copy)]
pub struct PrimarySamples<'a> {
    camera: &'a Camera,
    plane: ImagePlane,
    tile: Tile,
    first_sample: u32,
}

impl<'a> PrimarySamples<'a> {
    /// The samples of image row `row` of `camera` (a tile of the full width, one row high).
    pub fn row(camera: &'a Camera, row: u32) -> Self {
        Self::tile(
            camera,
            Tile {
                x: 0,
                y: row,
                width: camera.width,
                height: 1,
            },
        )
    }

    /// The samples of `tile` of `camera`, ordered as the integrator batches them.
    pub fn tile(camera: &'a Camera, tile: Tile) -> Self {
        Self {
            camera,
            plane: camera.image_plane(),
            tile,
            first_sample: 0,
        }
    }

    /// The same tile's samples from sample `first` on (a batch holding samples `first..`, as
    /// the path tracer's chunks do): ray `i` is sample `first + i / n`.
    pub fn starting_at(self, first: u32) -> Self {
        Self {
            first_sample: first,
            ..self
        }
    }

    /// The camera the samples belong to.
    pub fn camera(&self) -> &'a Camera {
        self.camera
    }

    /// The tile the batch covers.
    pub fn tile_bounds(&self) -> Tile {
        self.tile
    }

    /// `(column, row, sample)` of ray `index` of the batch. An index past the tile's samples
    /// wraps to further samples.
    pub fn pixel(&self, index: usize) -> (u32, u32, u32) {
        let width = self.tile.width.max(1) as usize;
        let n = self.tile.pixels().max(1);
        let sample = u32::try_from(index / n)
            .unwrap_or(u32::MAX)
            .saturating_add(self.first_sample);
        let j = index % n;
        // j < n, so both fit the tile's u32 bounds.
        let column = self.tile.x + (j % width) as u32;
        let row = self.tile.y + (j / width) as u32;
        (column, row, sample)
    }

    /// Exact unit direction (f64, render space) of ray `index` of the batch; the batch's f32
    /// ray `index` is its rounding.
    pub fn direction(&self, index: usize) -> DVec3 {
        let (column, row, sample) = self.pixel(index);
        let offset = sample_offset(sample);
        self.plane
            .direction(column as f64 + offset.x, row as f64 + offset.y)
    }
}

/// Camera rays of whole tiles, bit for bit the rays of [`primary_ray_on`]: the pinhole
/// formulas of [`ImagePlane::direction`] with each column's and each row's term computed
/// once per tile instead of once per pixel (same operations in the same order, so the same
/// rounding; a test compares every pixel).
#[derive(Debug, Clone)]
pub(crate) struct TileRays {
    plane: ImagePlane,
    t_max: f32,
    /// The CPU has AVX (detected once): [`TileRays::push`] takes its AVX build.
    #[cfg(target_arch = "x86_64")]
    avx: bool,
    /// Column terms ([`ImagePlane::column`]) of every image column at sample 0's offset
    /// (the pixel centre, every pixel's first sample), as structure of arrays: each holds a
    /// division, and every tile of a column needs them again.
    centre_columns: [Vec<f64>; 3],
    /// Row terms ([`ImagePlane::row_offset`]) of every image row at sample 0's offset.
    centre_rows: Vec<DVec3>,
}

/// Widest tile [`TileRays::push`] accepts.
pub(crate) const MAX_TILE_WIDTH: usize = 64;

impl TileRays {
    /// The camera's rays, ending at `t_max` (the scene's maximum distance).
    pub(crate) fn new(camera: &Camera, t_max: f64) -> Self {
        let plane = camera.image_plane();
        let centre = sample_offset(0);
        // Padded to a whole group of 4 columns (see `column_terms`).
        let columns: Vec<DVec3> = (0..camera.width.next_multiple_of(4))
            .map(|c| match c < camera.width {
                true => plane.column(c as f64 + centre.x),
                false => DVec3::X,
            })
            .collect();
        Self {
            plane,
            t_max: t_max as f32,
            #[cfg(target_arch = "x86_64")]
            avx: std::arch::is_x86_feature_detected!("avx"),
            centre_columns: [
                columns.iter().map(|c| c.x).collect(),
                columns.iter().map(|c| c.y).collect(),
                columns.iter().map(|c| c.z).collect(),
            ],
            centre_rows: (0..camera.height)
                .map(|r| plane.row_offset(r as f64 + centre.y))
                .collect(),
        }
    }

    /// Calls `with` with the column terms of `tile`'s columns at sub-pixel `offset` as
    /// structure of arrays `(x, y, z)`, each padded to a whole group of 4 with the
    /// forward-looking (finite, non-zero) direction so padding lanes stay harmless: slices
    /// of the table at sample 0's offset, else computed. `tile.width` must not exceed
    /// [`MAX_TILE_WIDTH`].
    #[inline(always)]
    fn with_column_terms<R>(
        &self,
        tile: Tile,
        offset: DVec2,
        with: impl FnOnce([&[f64]; 3]) -> R,
    ) -> R {
        let (x0, tw) = (tile.x as usize, (tile.width as usize).min(MAX_TILE_WIDTH));
        let padded = tw.next_multiple_of(4);
        let [tx, ty, tz] = &self.centre_columns;
        if offset == sample_offset(0) && x0 + padded <= tx.len() {
            return with([
                &tx[x0..x0 + padded],
                &ty[x0..x0 + padded],
                &tz[x0..x0 + padded],
            ]);
        }
        let [mut cx, mut cy, mut cz] = [[0.0; MAX_TILE_WIDTH]; 3];
        for k in 0..padded {
            let c = if k < tw {
                self.plane.column((tile.x + k as u32) as f64 + offset.x)
            } else {
                DVec3::X
            };
            (cx[k], cy[k], cz[k]) = (c.x, c.y, c.z);
        }
        with([&cx[..padded], &cy[..padded], &cz[..padded]])
    }

    /// The row term of image row `row` at sub-pixel `offset`: from the table at sample 0's
    /// offset, else computed.
    #[inline(always)]
    fn row_term(&self, row: u32, offset: DVec2) -> DVec3 {
        match self.centre_rows.get(row as usize) {
            Some(&up) if offset == sample_offset(0) => up,
            _ => self.plane.row_offset(row as f64 + offset.y),
        }
    }

    /// [`PrimarySamples::tile`] of `camera` (the camera these rays were made for), reusing
    /// the image plane computed once in [`TileRays::new`] instead of once per tile.
    pub(crate) fn samples<'a>(&self, camera: &'a Camera, tile: Tile) -> PrimarySamples<'a> {
        PrimarySamples {
            camera,
            plane: self.plane,
            tile,
            first_sample: 0,
        }
    }

    /// Appends the rays of `tile`'s pixels at sub-pixel `offset`, row-major.
    /// `tile.width` must not exceed [`MAX_TILE_WIDTH`].
    // The one unsafe call: the AVX build behind runtime detection.
    #[allow(unsafe_code)]
    pub(crate) fn push(&self, tile: Tile, offset: DVec2, out: &mut Vec<Ray>) {
        assert!(
            tile.width as usize <= MAX_TILE_WIDTH,
            "tile wider than MAX_TILE_WIDTH"
        );
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is set only when the CPU reports AVX (`TileRays::new`).
            unsafe { self.push_avx(tile, offset, out) };
            return;
        }
        self.push_portable(tile, offset, out);
    }

    /// [`TileRays::push`] with AVX intrinsics: 4 rays a time through the f64 normalisation
    /// (`vsqrtpd`, `vdivpd`), then rounded to f32. Each lane performs [`directions`]' IEEE
    /// operations in the same order (square roots and divisions are correctly rounded in
    /// every lane width), so the rays are the same bits; a test compares every pixel.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[allow(unsafe_code)]
    fn push_avx(&self, tile: Tile, offset: DVec2, out: &mut Vec<Ray>) {
        use std::arch::x86_64::*;
        let tw = (tile.width as usize).min(MAX_TILE_WIDTH);
        self.with_column_terms(tile, offset, |[cx, cy, cz]| {
            out.reserve(tw * tile.height as usize);
            let one_d = _mm256_set1_pd(1.0);
            for row in tile.y..tile.y + tile.height {
                let up = self.row_term(row, offset);
                let (ux, uy, uz) = (
                    _mm256_set1_pd(up.x),
                    _mm256_set1_pd(up.y),
                    _mm256_set1_pd(up.z),
                );
                for k in (0..tw).step_by(4) {
                    // SAFETY: each slice `[k..k + 4]` is bounds-checked (4 f64, what the load
                    // reads; the terms are padded to whole groups of 4).
                    let (x, y, z) = unsafe {
                        (
                            _mm256_add_pd(_mm256_loadu_pd(cx[k..k + 4].as_ptr()), ux),
                            _mm256_add_pd(_mm256_loadu_pd(cy[k..k + 4].as_ptr()), uy),
                            _mm256_add_pd(_mm256_loadu_pd(cz[k..k + 4].as_ptr()), uz),
                        )
                    };
                    let dot = _mm256_add_pd(
                        _mm256_add_pd(_mm256_mul_pd(x, x), _mm256_mul_pd(y, y)),
                        _mm256_mul_pd(z, z),
                    );
                    let r = _mm256_div_pd(one_d, _mm256_sqrt_pd(dot));
                    let (mut dx, mut dy, mut dz) = ([0.0f32; 4], [0.0f32; 4], [0.0f32; 4]);
                    // SAFETY: each store writes 4 f32 into a `[f32; 4]`.
                    unsafe {
                        _mm_storeu_ps(dx.as_mut_ptr(), _mm256_cvtpd_ps(_mm256_mul_pd(x, r)));
                        _mm_storeu_ps(dy.as_mut_ptr(), _mm256_cvtpd_ps(_mm256_mul_pd(y, r)));
                        _mm_storeu_ps(dz.as_mut_ptr(), _mm256_cvtpd_ps(_mm256_mul_pd(z, r)));
                    }
                    // Written into the reserved capacity: no capacity check per ray.
                    let lanes = (tw - k).min(4);
                    let len = out.len();
                    for (i, slot) in out.spare_capacity_mut()[..lanes].iter_mut().enumerate() {
                        slot.write(Ray {
                            origin: glam::Vec3::ZERO,
                            dir: glam::Vec3::new(dx[i], dy[i], dz[i]),
                            t_min: 0.0,
                            t_max: self.t_max,
                        });
                    }
                    // SAFETY: the `lanes` slots after `len` were just initialised (the slice
                    // index above checked they are within the capacity).
                    unsafe { out.set_len(len + lanes) };
                }
            }
        })
    }

    #[inline(always)]
    fn push_portable(&self, tile: Tile, offset: DVec2, out: &mut Vec<Ray>) {
        let tw = (tile.width as usize).min(MAX_TILE_WIDTH);
        let mut columns = [DVec3::ZERO; MAX_TILE_WIDTH];
        self.with_column_terms(tile, offset, |[cx, cy, cz]| {
            for (k, c) in columns[..tw].iter_mut().enumerate() {
                *c = DVec3::new(cx[k], cy[k], cz[k]);
            }
        });
        out.reserve(tw * tile.height as usize);
        for row in tile.y..tile.y + tile.height {
            let up = self.row_term(row, offset);
            for chunk in columns[..tw].chunks(LANES) {
                let d = directions(chunk, up);
                out.extend((0..chunk.len()).map(|i| Ray {
                    origin: glam::Vec3::ZERO,
                    dir: glam::Vec3::new(d[0][i], d[1][i], d[2][i]),
                    t_min: 0.0,
                    t_max: self.t_max,
                }));
            }
        }
    }
}

/// Columns whose directions [`directions`] computes together.
const LANES: usize = 8;

/// `(column + up).normalize().as_vec3()` for up to [`LANES`] columns, written
/// lane by lane (structure of arrays) so the compiler can use SIMD; the same IEEE operations
/// in the same order as glam's `normalize` (`v * (1 / sqrt(x*x + y*y + z*z))`), so the same
/// bits. Lanes past `columns.len()` are unspecified.
// Lane loops index several arrays by the same lane, mirroring SIMD lanes.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn directions(columns: &[DVec3], up: DVec3) -> [[f32; LANES]; 3] {
    let (mut x, mut y, mut z) = ([1.0f64; LANES], [0.0f64; LANES], [0.0f64; LANES]);
    for (i, c) in columns.iter().enumerate().take(LANES) {
        let v = *c + up;
        (x[i], y[i], z[i]) = (v.x, v.y, v.z);
    }
    let mut out = [[0.0f32; LANES]; 3];
    for i in 0..LANES {
        let r = 1.0 / (x[i] * x[i] + y[i] * y[i] + z[i] * z[i]).sqrt();
        out[0][i] = (x[i] * r) as f32;
        out[1][i] = (y[i] * r) as f32;
        out[2][i] = (z[i] * r) as f32;
    }
    out
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
                assert_eq!(ray.dir, exact.as_vec3());
                assert!((ray.dir.as_dvec3().length() - 1.0).abs() <= 2f64.powi(-24));
            }
        }
    }

    #[test]
    fn tile_rays_are_bit_identical_to_primary_ray_on() {
        let cams = [
            study_camera(),
            Camera::look_at(
                DVec3::new(1.0, 2.0, -3.0),
                DVec3::new(0.3, 0.1, 0.7),
                DVec3::Y,
                35.0,
                37,
                23,
            )
            .unwrap(),
            Camera::look_at(
                DVec3::new(1e5, -3.0, 7.0),
                DVec3::new(1e5 + 0.1, -2.0, 9.0),
                DVec3::new(0.2, 1.0, 0.1),
                120.0,
                19,
                41,
            )
            .unwrap(),
        ];
        for cam in cams {
            let plane = cam.image_plane();
            let detected = TileRays::new(&cam, 123.25);
            // Both builds where the CPU has AVX: the intrinsics and the portable code.
            #[allow(unused_mut)]
            let mut grids = vec![detected.clone()];
            #[cfg(target_arch = "x86_64")]
            grids.push(TileRays {
                avx: false,
                ..detected.clone()
            });
            for (grid, s) in grids.iter().flat_map(|g| [0, 1, 5].map(|s| (g, s))) {
                let off = sample_offset(s);
                // Sample 0 reads the precomputed column and row terms; these tiles
                // include a right-edge tile whose width is no multiple of 4.
                for (x, y, w, h) in [
                    (0, 0, 8, 8),
                    (3, 2, 16, 4),
                    (0, 0, cam.width.min(MAX_TILE_WIDTH as u32), 1),
                    (cam.width - 5, cam.height - 3, 5, 3),
                ] {
                    let tile = Tile {
                        x,
                        y,
                        width: w.min(cam.width - x),
                        height: h.min(cam.height - y),
                    };
                    let mut rays = Vec::new();
                    grid.push(tile, off, &mut rays);
                    assert_eq!(rays.len(), tile.pixels());
                    let samples = PrimarySamples::tile(&cam, tile).starting_at(s);
                    for (i, r) in rays.iter().enumerate() {
                        let (col, row, sample) = samples.pixel(i);
                        assert_eq!(sample, s);
                        let want = primary_ray_on(&plane, col, row, off, 123.25);
                        assert_eq!(
                            (r.dir.to_array().map(f32::to_bits), r.t_max.to_bits()),
                            (want.dir.to_array().map(f32::to_bits), want.t_max.to_bits()),
                            "pixel ({col}, {row}) sample {s}"
                        );
                        assert_eq!(
                            (r.origin.to_array().map(f32::to_bits), r.t_min.to_bits()),
                            (
                                want.origin.to_array().map(f32::to_bits),
                                want.t_min.to_bits()
                            )
                        );
                        assert_eq!(samples.direction(i).as_vec3(), r.dir);
                    }
                }
            }
        }
    }

    #[test]
    fn tile_samples_count_pixels_row_major_then_samples() {
        let cam = study_camera();
        let tile = Tile {
            x: 10,
            y: 20,
            width: 4,
            height: 2,
        };
        let s = PrimarySamples::tile(&cam, tile).starting_at(3);
        assert_eq!(s.pixel(0), (10, 20, 3));
        assert_eq!(s.pixel(3), (13, 20, 3));
        assert_eq!(s.pixel(4), (10, 21, 3));
        assert_eq!(s.pixel(9), (11, 20, 4));
        assert_eq!(PrimarySamples::row(&cam, 7).pixel(501), (1, 7, 1));
    }
}
