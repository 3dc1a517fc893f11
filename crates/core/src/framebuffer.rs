//! The rendered image and its per-pixel AOVs (arbitrary output values).

use glam::Vec3;

use crate::geometry::{RayWork, Termination};

/// Marker for "no hit" in [`Framebuffer::depth`].
pub const NO_HIT_DEPTH: f32 = f32::INFINITY;

/// A rendered image with AOVs recorded from each pixel's primary ray through the pixel centre
/// (sample 0), so AOVs of different backends are comparable pixel by pixel.
///
/// Pixels are stored row-major, row 0 at the top. A render with `RenderOptions::aovs` off
/// leaves every plane but `color` empty ([`Framebuffer::has_aovs`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Framebuffer {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Final linear RGB colour, averaged over samples (unclamped).
    pub color: Vec<Vec3>,
    /// Distance along the primary ray to the first hit, world units; [`NO_HIT_DEPTH`] if none.
    pub depth: Vec<f32>,
    /// Unit surface normal at the primary hit, facing the camera; zero if no hit.
    pub normal: Vec<Vec3>,
    /// Material id at the primary hit; `u32::MAX` if none.
    pub material: Vec<u32>,
    /// How the primary ray ended.
    pub termination: Vec<Termination>,
    /// Work done by the primary ray.
    pub work: Vec<RayWork>,
}

impl Framebuffer {
    /// A cleared framebuffer (background everywhere, no hits).
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            color: vec![Vec3::ZERO; n],
            depth: vec![NO_HIT_DEPTH; n],
            normal: vec![Vec3::ZERO; n],
            material: vec![u32::MAX; n],
            termination: vec![Termination::Miss; n],
            work: vec![RayWork::default(); n],
        }
    }

    /// Makes this a `width` x `height` framebuffer, keeping its memory where it suffices;
    /// pixel values are unspecified until written (the renderer overwrites every pixel).
    pub fn resize(&mut self, width: u32, height: u32) {
        self.resize_planes(width, height, true);
    }

    /// [`Framebuffer::resize`], with the AOV planes emptied (length 0, memory kept) when
    /// `aovs` is false: the layout of a render that records no AOVs.
    pub fn resize_planes(&mut self, width: u32, height: u32, aovs: bool) {
        let n = width as usize * height as usize;
        self.width = width;
        self.height = height;
        self.color.resize(n, Vec3::ZERO);
        let n = if aovs { n } else { 0 };
        self.depth.resize(n, NO_HIT_DEPTH);
        self.normal.resize(n, Vec3::ZERO);
        self.material.resize(n, u32::MAX);
        self.termination.resize(n, Termination::Miss);
        self.work.resize(n, RayWork::default());
    }

    /// Clears every pixel: background black, no hits.
    pub fn clear(&mut self) {
        self.color.fill(Vec3::ZERO);
        self.depth.fill(NO_HIT_DEPTH);
        self.normal.fill(Vec3::ZERO);
        self.material.fill(u32::MAX);
        self.termination.fill(Termination::Miss);
        self.work.fill(RayWork::default());
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.color.len()
    }

    /// True for a 0-pixel buffer.
    pub fn is_empty(&self) -> bool {
        self.color.is_empty()
    }

    /// Whether the AOV planes hold one value per pixel; false for a render with
    /// `RenderOptions::aovs` off, whose AOV planes are empty.
    pub fn has_aovs(&self) -> bool {
        self.aov_planes_hold(self.color.len())
    }

    /// Whether every AOV plane holds `n` values.
    pub(crate) fn aov_planes_hold(&self, n: usize) -> bool {
        [
            self.depth.len(),
            self.normal.len(),
            self.material.len(),
            self.termination.len(),
            self.work.len(),
        ]
        .iter()
        .all(|&l| l == n)
    }

    /// Whether the primary ray of pixel `i` hit a surface.
    ///
    /// # Panics
    /// If `i` is outside the depth plane (also: a framebuffer without AOVs).
    pub fn is_hit(&self, i: usize) -> bool {
        self.depth[i].is_finite()
    }

    /// Bytes of the pixel buffers a `width` x `height` framebuffer allocates.
    pub fn bytes_for(width: u32, height: u32) -> u64 {
        let per_pixel = std::mem::size_of::<Vec3>() * 2
            + std::mem::size_of::<f32>()
            + std::mem::size_of::<u32>()
            + std::mem::size_of::<Termination>()
            + std::mem::size_of::<RayWork>();
        width as u64 * height as u64 * per_pixel as u64
    }

    /// 8-bit sRGB-less RGB: each linear channel clamped to [0, 1] and scaled to 0..=255 (no
    /// gamma, as in the source study).
    pub fn to_rgb8(&self) -> image::RgbImage {
        let mut img = image::RgbImage::new(self.width, self.height);
        for (px, c) in img.pixels_mut().zip(&self.color) {
            let q = |v: f32| {
                if v.is_nan() {
                    0
                } else {
                    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
                }
            };
            *px = image::Rgb([q(c.x), q(c.y), q(c.z)]);
        }
        img
    }
}
