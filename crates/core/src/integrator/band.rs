//! The image bands a render is cut into: the frame every worker reads and each worker's
//! own band of colour and AOV planes, copied into the framebuffer once per band.

use glam::Vec3;
use marchmesh_scene::Scene;

use super::shading::Shading;
use super::tile_width;
use crate::background::BackgroundSampler;
use crate::camera::{Tile, TileRays};
use crate::framebuffer::{Framebuffer, NO_HIT_DEPTH};
use crate::geometry::{BatchPolicy, Geometry, Hit, RayWork, Termination, TraceResult};
use crate::stats::RenderStats;

/// One worker's copy of a band's AOV planes (see [`run_bands`](super::run_bands)); the
/// colour is written into the framebuffer once per band ([`Band::set_colors`]).
#[derive(Default)]
pub(super) struct Planes {
    depth: Vec<f32>,
    normal: Vec<Vec3>,
    material: Vec<u32>,
    termination: Vec<Termination>,
    work: Vec<RayWork>,
}

/// What every tile of one render reads.
pub(crate) struct Frame<'a> {
    pub(crate) scene: &'a Scene,
    pub(crate) sh: &'a Shading,
    pub(crate) geometry: &'a dyn Geometry,
    pub(crate) background: &'a BackgroundSampler,
    pub(crate) camera: TileRays,
}

impl Frame<'_> {
    /// Columns of the tiles this render traces ([`BatchPolicy`]).
    pub(crate) fn tile_width(&self) -> u32 {
        match self.geometry.batch_policy() {
            BatchPolicy::Tiles => tile_width(self.geometry.tile_width(), self.sh.spp),
            BatchPolicy::Columns => crate::camera::MAX_TILE_WIDTH as u32,
        }
    }
}

/// The framebuffer's pixels of one band of whole image rows, written in place by the tiles
/// traced in it. Pixel `i` of the band is column `i % width` of row `y + i / width`.
pub(crate) struct Band<'a> {
    pub(crate) width: usize,
    pub(crate) y: u32,
    pub(crate) rows: u32,
    /// The band records AOVs (its AOV slices are as long as `color`; empty otherwise).
    pub(crate) aovs: bool,
    color: &'a mut [Vec3],
    pub(super) depth: &'a mut [f32],
    pub(super) normal: &'a mut [Vec3],
    pub(super) material: &'a mut [u32],
    pub(super) termination: &'a mut [Termination],
    pub(super) work: &'a mut [RayWork],
}

impl<'a> Band<'a> {
    /// `fb` cut into bands of `rows` rows (the last may be shorter); with `aovs` false the
    /// bands' AOV slices are empty (and so must `fb`'s AOV planes be).
    pub(super) fn split(fb: &'a mut Framebuffer, rows: u32, aovs: bool) -> Vec<Band<'a>> {
        let width = fb.width as usize;
        let n = (width * rows as usize).max(1);
        let aov_len = if aovs { fb.color.len() } else { 0 };
        assert!(
            fb.aov_planes_hold(aov_len),
            "framebuffer AOV planes differ in length from what the render records"
        );
        // Empty planes give every band an empty slice.
        fn cut<T>(plane: &mut [T], n: usize) -> impl Iterator<Item = &mut [T]> {
            plane
                .chunks_mut(n)
                .chain(std::iter::repeat_with(Default::default))
        }
        let mut depth = cut(&mut fb.depth, n);
        let mut normal = cut(&mut fb.normal, n);
        let mut material = cut(&mut fb.material, n);
        let mut termination = cut(&mut fb.termination, n);
        let mut work = cut(&mut fb.work, n);
        let mut bands = Vec::new();
        for (k, color) in fb.color.chunks_mut(n).enumerate() {
            let (Some(depth), Some(normal), Some(material), Some(termination), Some(work)) = (
                depth.next(),
                normal.next(),
                material.next(),
                termination.next(),
                work.next(),
            ) else {
                unreachable!("framebuffer planes differ in length");
            };
            bands.push(Band {
                width,
                y: k as u32 * rows,
                rows: (color.len() / width.max(1)) as u32,
                aovs,
                color,
                depth,
                normal,
                material,
                termination,
                work,
            });
        }
        bands
    }

    /// A band of the same rows and colour over `planes` (resized to the band's pixels) for
    /// its AOVs.
    pub(super) fn staged<'p>(&'p mut self, planes: &'p mut Planes) -> Band<'p> {
        let m = self.depth.len();
        planes.depth.resize(m, NO_HIT_DEPTH);
        planes.normal.resize(m, Vec3::ZERO);
        planes.material.resize(m, u32::MAX);
        planes.termination.resize(m, Termination::Miss);
        planes.work.resize(m, RayWork::default());
        Band {
            width: self.width,
            y: self.y,
            rows: self.rows,
            aovs: self.aovs,
            color: &mut *self.color,
            depth: &mut planes.depth[..m],
            normal: &mut planes.normal[..m],
            material: &mut planes.material[..m],
            termination: &mut planes.termination[..m],
            work: &mut planes.work[..m],
        }
    }

    /// Copies the AOVs [`Band::staged`] traced into `planes` into this band, with
    /// non-temporal stores (the framebuffer is not read again during the render).
    pub(super) fn copy_from(&mut self, planes: &Planes) {
        let m = self.depth.len();
        crate::stream::copy_streaming(self.depth, &planes.depth[..m]);
        crate::stream::copy_streaming(self.normal, &planes.normal[..m]);
        crate::stream::copy_streaming(self.material, &planes.material[..m]);
        crate::stream::copy_streaming(self.termination, &planes.termination[..m]);
        crate::stream::copy_streaming(self.work, &planes.work[..m]);
    }

    /// The band's tiles of `tile_width` columns (the last may be narrower), left to right.
    pub(crate) fn tiles(&self, tile_width: u32) -> impl Iterator<Item = Tile> + use<> {
        let (width, y, rows) = (self.width as u32, self.y, self.rows);
        let step = tile_width.max(1);
        (0..width).step_by(step as usize).map(move |x| Tile {
            x,
            y,
            width: step.min(width - x),
            height: rows,
        })
    }

    /// Band indices of `tile`'s pixels, row-major (the order of its camera rays), as one
    /// range per tile row.
    pub(crate) fn rows_of(&self, tile: Tile) -> impl Iterator<Item = std::ops::Range<u32>> + use<> {
        let (w, x, y0) = (self.width as u32, tile.x, tile.y - self.y);
        (y0..y0 + tile.height).map(move |r| r * w + x..r * w + x + tile.width)
    }

    /// Pixels in the band.
    pub(crate) fn color_len(&self) -> usize {
        self.color.len()
    }

    /// `(column, row)` of band pixel `i`.
    pub(crate) fn column_row(&self, i: u32) -> (u32, u32) {
        let w = self.width as u32;
        (i % w, self.y + i / w)
    }

    /// Records band pixel `i`'s AOVs from its sample-0 camera ray: how it ended, its work
    /// and, for a surface, distance, facing normal and material.
    pub(super) fn set_aov(&mut self, i: usize, res: &TraceResult, surface: Option<(&Hit, Vec3)>) {
        self.termination[i] = res.termination();
        self.work[i] = res.work;
        match surface {
            Some((hit, normal)) => {
                self.depth[i] = hit.t;
                self.normal[i] = normal;
                self.material[i] = hit.material;
            }
            None => {
                self.depth[i] = NO_HIT_DEPTH;
                self.normal[i] = Vec3::ZERO;
                self.material[i] = u32::MAX;
            }
        }
    }

    /// Writes the average of `sums` over `samples` into the colour of every pixel of the
    /// band (`sums` indexed like the band's pixels, each pixel's sum complete), counting
    /// (and blackening) a non-finite result in `stats`. One pass over the whole band, after
    /// its last tile: contiguous, so it vectorises (per tile row it cost 23 instructions a
    /// pixel, most of them per-row setup), with non-temporal stores (the colour is the
    /// framebuffer's, not read again during the render).
    ///
    /// # Panics
    /// If `sums` is shorter than the band (a programming error).
    pub(crate) fn set_colors(&mut self, sums: &[Vec3], samples: u32, stats: &mut RenderStats) {
        let scale = 1.0 / samples as f32;
        let sums = &sums[..self.color.len()];
        let non_finite = crate::stream::scale_streaming(
            bytemuck::cast_slice_mut(self.color),
            bytemuck::cast_slice(sums),
            scale,
        );
        if non_finite {
            for c in self.color.iter_mut().filter(|c| !c.is_finite()) {
                *c = Vec3::ZERO;
                stats.non_finite_pixels += 1;
            }
        }
    }
}
