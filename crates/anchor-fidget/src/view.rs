//! The projective matrix that puts fidget's voxel columns on marchmesh's camera rays.
//!
//! fidget's 3D renderer ([`fidget::raster::VoxelRenderConfig`]) samples the shape at integer
//! screen points `(i, j, k)`: column `i` (left to right), row `j` (top to bottom) and voxel
//! `k` in `0..depth` (`depth - 1` nearest the viewer), each mapped to model space by the 4x4
//! projective matrix `world_to_model * screen_to_world` (with the perspective divide). This
//! module builds that matrix so that
//!
//! * column `(i, j)` lies exactly on the marchmesh camera ray through the pixel *centre*
//!   `(i + 0.5, j + 0.5)` (the README's pinhole model, [`marchmesh_scene::CameraSpec`]), and
//! * voxel `k` sits at view depth `s(k) = 1 / (1/far + k (1/near - 1/far) / depth)` along
//!   the camera's forward axis: `s(0) = far`, `s(depth) = near`. A projective map can only
//!   space the voxels uniformly in inverse depth (like a GPU z-buffer), so the quantisation
//!   step grows as `s^2`.
//!
//! The model space is marchmesh's render space (world minus the camera position), so the
//! shape's tree is built there too ([`crate::tree`]).

use anyhow::{Result, bail};
use glam::{DMat4, DVec3, DVec4};
use marchmesh_scene::Camera;

/// One fidget voxel volume laid over a camera's view frustum, between `near` and `far`
/// (distances along the camera's forward axis, render space).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoxelView {
    /// Image width in pixels (fidget's voxel columns).
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Voxels per column.
    pub depth: u32,
    /// View depth of the front face (`k = depth`), > 0.
    pub near: f64,
    /// View depth of the back face (`k = 0`), > `near`.
    pub far: f64,
    forward: DVec3,
    right: DVec3,
    up: DVec3,
    half_w: f64,
    half_h: f64,
}

impl VoxelView {
    /// The volume of `depth` voxels per pixel between view depths `near` and `far` of
    /// `camera` (its image size is the volume's width and height).
    pub fn new(camera: &Camera, depth: u32, near: f64, far: f64) -> Result<Self> {
        if depth < 2 {
            bail!("voxel depth must be >= 2, got {depth}");
        }
        if !(near > 0.0 && far > near && far.is_finite()) {
            bail!("need 0 < near < far < inf, got near {near}, far {far}");
        }
        // The same formulas as `marchmesh_scene::ImagePlane` (its fields are private).
        let half_h = (camera.vfov_rad * 0.5).tan();
        Ok(Self {
            width: camera.width,
            height: camera.height,
            depth,
            near,
            far,
            forward: camera.forward,
            right: camera.right,
            up: camera.up,
            half_w: half_h * camera.width as f64 / camera.height as f64,
            half_h,
        })
    }

    /// Image-plane coordinates `(x, y)` (in units of the forward vector) of the centre of
    /// pixel `(col, row)`: the camera ray's direction is `forward + x right + y up`.
    pub fn plane_xy(&self, col: f64, row: f64) -> (f64, f64) {
        let x = (2.0 * (col + 0.5) / self.width as f64 - 1.0) * self.half_w;
        let y = (1.0 - 2.0 * (row + 0.5) / self.height as f64) * self.half_h;
        (x, y)
    }

    /// `(a, b)` of the homogeneous weight `w = a + b k`, `s(k) = 1 / w`.
    fn weight(&self) -> (f64, f64) {
        let a = 1.0 / self.far;
        let b = (1.0 / self.near - 1.0 / self.far) / self.depth as f64;
        (a, b)
    }

    /// View depth (along `forward`) of screen depth `z` (voxel units, `0..=depth`).
    pub fn view_depth(&self, z: f64) -> f64 {
        let (a, b) = self.weight();
        1.0 / (a + b * z)
    }

    /// Distance along the unit camera ray of pixel `(col, row)` to screen depth `z`.
    pub fn ray_distance(&self, col: u32, row: u32, z: f64) -> f64 {
        let (x, y) = self.plane_xy(col as f64, row as f64);
        self.view_depth(z) * (1.0 + x * x + y * y).sqrt()
    }

    /// The projective map from fidget's screen space (`i`, `j`, `k` as above) to render
    /// space, in f64: `(i, j, k, 1) -> (forward + x(i) right + y(j) up, 1/s(k))`.
    pub fn screen_to_render(&self) -> DMat4 {
        let (a, b) = self.weight();
        let (w, h) = (self.width as f64, self.height as f64);
        // x(i) = (2 (i + 0.5) / w - 1) half_w = cx * i + x0; y(j) = cy * j + y0.
        let cx = 2.0 * self.half_w / w;
        let x0 = (1.0 / w - 1.0) * self.half_w;
        let cy = -2.0 * self.half_h / h;
        let y0 = (1.0 - 1.0 / h) * self.half_h;
        let col_i = (self.right * cx).extend(0.0);
        let col_j = (self.up * cy).extend(0.0);
        let col_k = DVec4::new(0.0, 0.0, 0.0, b);
        let col_1 = (self.forward + self.right * x0 + self.up * y0).extend(a);
        DMat4::from_cols(col_i, col_j, col_k, col_1)
    }

    /// fidget's voxel size for this volume.
    pub fn voxel_size(&self) -> fidget::render::VoxelSize {
        fidget::render::VoxelSize::new(self.width, self.height, self.depth)
    }

    /// The `world_to_model` matrix to give fidget: its renderer applies
    /// `world_to_model * voxel_size.screen_to_world()`, so this is
    /// [`VoxelView::screen_to_render`] times the inverse of fidget's own screen-to-world map
    /// (a scale by a power of two and a translation by whole or half pixels for even sizes:
    /// exact in f32).
    pub fn world_to_model(&self) -> Result<nalgebra::Matrix4<f32>> {
        let s2w = self.voxel_size().screen_to_world();
        let s2w = nalgebra::Matrix4::<f64>::from_fn(|r, c| f64::from(s2w[(r, c)]));
        let Some(w2s) = s2w.try_inverse() else {
            bail!("fidget's screen-to-world matrix is singular");
        };
        let p = self.screen_to_render();
        let p = nalgebra::Matrix4::<f64>::from_fn(|r, c| p.col(c)[r]);
        Ok((p * w2s).map(|v| v as f32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fidget::raster::VoxelRenderConfig;
    use marchmesh_core::camera::{primary_direction, sample_offset};

    fn camera() -> Camera {
        Camera::look_at(
            DVec3::new(1.0, 2.0, -3.0),
            DVec3::new(0.3, 0.1, 0.7),
            DVec3::Y,
            53.13,
            512,
            384,
        )
        .expect("camera")
    }

    /// fidget's combined matrix (the one its renderer applies) maps every voxel column onto
    /// marchmesh's exact camera ray through that pixel's centre, within 1e-6, and the voxel
    /// ends onto the near and far depths.
    #[test]
    fn voxel_columns_are_the_marchmesh_camera_rays() {
        let cam = camera();
        let view = VoxelView::new(&cam, 512, 2.0, 9.0).expect("view");
        let cfg = VoxelRenderConfig {
            image_size: view.voxel_size(),
            world_to_model: view.world_to_model().expect("matrix"),
            ..Default::default()
        };
        let mat = cfg.mat();
        for (col, row) in [
            (0, 0),
            (511, 0),
            (0, 383),
            (511, 383),
            (255, 191),
            (100, 300),
        ] {
            let exact = primary_direction(&cam, col, row, sample_offset(0));
            for k in [0u32, 1, 255, 511, 512] {
                let p =
                    mat.transform_point(&nalgebra::Point3::new(col as f32, row as f32, k as f32));
                let p = DVec3::new(p.x.into(), p.y.into(), p.z.into());
                let dir = p.normalize();
                assert!(
                    (dir - exact).length() < 1e-6,
                    "pixel ({col}, {row}) voxel {k}: {dir:?} vs {exact:?}"
                );
                let s = p.dot(cam.forward);
                let expect = view.view_depth(k as f64);
                assert!((s - expect).abs() < 1e-5 * expect, "depth {s} vs {expect}");
                let t = view.ray_distance(col, row, k as f64);
                assert!((p.length() - t).abs() < 1e-5 * t, "{} vs {t}", p.length());
            }
        }
        assert!((view.view_depth(0.0) - 9.0).abs() < 1e-12);
        assert!((view.view_depth(512.0) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn bad_brackets_are_refused() {
        let cam = camera();
        assert!(VoxelView::new(&cam, 512, 0.0, 1.0).is_err());
        assert!(VoxelView::new(&cam, 512, 2.0, 1.0).is_err());
        assert!(VoxelView::new(&cam, 1, 1.0, 2.0).is_err());
    }
}
