//! Build options of the mesh backend: BVH kind and build preset, tessellation budget,
//! surface-extraction resolution, instancing. One flat serde type, [`MeshOptions`], whose
//! fields are the `key=value` options: the first paragraph of each field's doc comment is its
//! `--opt help` line, the whole comment its JSON Schema description. A key left unset takes
//! its preset's value ([`MeshPreset::values`]); structured views
//! ([`MeshOptions::tessellation`], [`MeshOptions::bvh`], ...) are methods. A new option is a
//! field here, its value in [`MeshPreset::values`] and its use (through a view or
//! [`MeshOptions::pick`]).

use obvhs::BvhBuildParams;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Which obvhs BVH layout the triangles are traversed in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum BvhKind {
    /// Binary BVH (`obvhs::bvh2::Bvh2`), 48-byte nodes, up to 8 triangles per leaf (per preset).
    Bvh2,
    /// Compressed 8-wide BVH (`obvhs::cwbvh::CwBvh`, Ylitie et al. 2017), 80-byte nodes,
    /// SIMD node tests, up to 3 triangles per leaf.
    CwBvh,
    /// 8-wide BVH converted from the Bvh2 build (`crate::wide`): 224-byte nodes with SoA
    /// child boxes tested 8 at a time (AVX, runtime-detected, portable fallback), triangles
    /// in SoA blocks of 4 tested with SSE; same hits as [`BvhKind::Bvh2`]. Its Bvh2 build
    /// caps leaves at 4 triangles (one block), whatever the preset says.
    Wide,
}

/// obvhs build presets (`BvhBuildParams::*_build()`, and one of our own), from fastest build
/// to best traversal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum BuildQuality {
    /// `fastest_build`: PLOC with minimal search, no reinsertion, one triangle per leaf.
    Fastest,
    /// `very_fast_build`.
    VeryFast,
    /// `fast_build`.
    Fast,
    /// `medium_build`: about Embree's build time with faster traversal.
    Medium,
    /// `medium_build` with a better tree for more build time (the default): the first PLOC
    /// pass pairs nearest neighbours only (`search_depth_threshold: 1`) and reinsertion
    /// (Meister and Bittner 2018, "Parallel Reinsertion for Bounding Volume Hierarchy
    /// Optimization") visits half the nodes instead of 5% (`reinsertion_batch_ratio: 0.5`).
    /// Measured against `Medium`: `docs/decisions/0007`.
    Tuned,
    /// `slow_build`: spatial pre-splits, wider PLOC search.
    Slow,
    /// `very_slow_build`: full reinsertion pass.
    VerySlow,
}

impl BuildQuality {
    /// The obvhs parameters of this preset.
    pub const fn params(self) -> BvhBuildParams {
        match self {
            Self::Fastest => BvhBuildParams::fastest_build(),
            Self::VeryFast => BvhBuildParams::very_fast_build(),
            Self::Fast => BvhBuildParams::fast_build(),
            Self::Medium => BvhBuildParams::medium_build(),
            Self::Tuned => BvhBuildParams {
                search_depth_threshold: 1,
                reinsertion_batch_ratio: 0.5,
                ..BvhBuildParams::medium_build()
            },
            Self::Slow => BvhBuildParams::slow_build(),
            Self::VerySlow => BvhBuildParams::very_slow_build(),
        }
    }
}

/// How finely CSG and smooth-blend objects are extracted from their distance field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Extraction {
    /// An extraction cell, projected on screen from the object's nearest distance to the
    /// camera, spans at most `pixels` pixels: cell `pixels * camera.pixel_angle() * distance`
    /// (the grid at least `128 / pixels` and at most [`crate::MAX_SURFACE_RESOLUTION`]
    /// cells on the longest side). The distance is the larger of two lower bounds: the
    /// distance to the object's bounds and, for a camera near or inside them, the magnitude of
    /// the object's distance field at the camera. Features thinner than a cell can vanish, so
    /// this is what keeps blended content right on screen. `pixels` must be > 0.
    ScreenCell {
        /// Cell size on screen in pixels (e.g. 1).
        pixels: f64,
    },
    /// A fixed grid: this many cells along the longest side of the object's bounds.
    Cells(u32),
}

/// How finely analytic shapes are tessellated.
///
/// The chord error is the largest distance between the exact surface and its triangles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tessellation {
    /// Chord error, projected on screen from the shape's nearest distance to the camera,
    /// stays below `pixels` pixels: world error `pixels * camera.pixel_angle() * distance`.
    /// Shapes far away get few triangles, near ones many. `pixels` must be > 0.
    ScreenError {
        /// Screen-space budget in pixels (e.g. 0.25).
        pixels: f64,
    },
    /// A fixed chord error in world units (> 0), whatever the distance.
    ChordError {
        /// World-space budget.
        world: f64,
    },
    /// A fixed subdivision: `8 * 2^level` segments per full turn (half that per half turn,
    /// e.g. sphere latitudes), independent of size and camera. `level <= 12`.
    FixedLevel(u32),
}

/// A starting point for the other mesh options.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum MeshPreset {
    /// [`MeshOptions::fast`]: Bvh2, fast build, 1-pixel tessellation, 2-pixel extraction cells.
    Fast,
    /// The documented defaults ([`MeshOptions::default`]: every key unset).
    #[default]
    Default,
    /// [`MeshOptions::quality`]: CwBvh, slow build, 0.1-pixel tessellation, half-pixel
    /// extraction cells.
    Quality,
}

impl MeshPreset {
    /// Every key set to its value under this preset (the tessellation by `tess_px`; `preset`
    /// and the other two tessellation keys unset). The default preset's values are the
    /// documented defaults.
    pub const fn values(self) -> MeshOptions {
        const DEFAULT: MeshOptions = MeshOptions {
            preset: None,
            bvh: Some(BvhKind::Wide),
            build: Some(BuildQuality::Tuned),
            tess_px: Some(0.25),
            tess_chord: None,
            tess_level: None,
            surface_px: Some(1.0),
            surface_res: None,
            packets: Some(true),
            instancing: Some(true),
            max_instances: Some(1 << 22),
            max_segments: Some(4096),
            memory_limit_bytes: Some(4 << 30),
        };
        match self {
            MeshPreset::Default => DEFAULT,
            MeshPreset::Fast => MeshOptions {
                bvh: Some(BvhKind::Bvh2),
                build: Some(BuildQuality::Fast),
                tess_px: Some(1.0),
                surface_px: Some(2.0),
                ..DEFAULT
            },
            MeshPreset::Quality => MeshOptions {
                bvh: Some(BvhKind::CwBvh),
                build: Some(BuildQuality::Slow),
                tess_px: Some(0.1),
                surface_px: Some(0.5),
                ..DEFAULT
            },
        }
    }
}

/// Options of [`crate::build`], and the mesh backend's `key=value` options: a key left out
/// (`None`) keeps the preset's value. Unknown keys are refused. Build one with
/// [`MeshOptions::default`] (every key unset: the default preset) or a preset and set fields.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct MeshOptions {
    /// Start from the fast, default or quality preset; the other keys override it.
    pub preset: Option<MeshPreset>,
    /// BVH layout: binary, compressed 8-wide, or SIMD 8-wide converted from bvh2.
    ///
    /// Default [`BvhKind::Wide`] (measured against the other layouts and Embree: `docs/decisions/0007` and `0009`).
    pub bvh: Option<BvhKind>,
    /// BVH build preset: an obvhs preset, or tuned (medium, more reinsertion; the default).
    ///
    /// Default [`BuildQuality::Tuned`].
    pub build: Option<BuildQuality>,
    /// Tessellation chord error on screen, pixels.
    ///
    /// [`Tessellation::ScreenError`]; default 0.25.
    pub tess_px: Option<f64>,
    /// Tessellation chord error, world units (instead of tess_px).
    ///
    /// [`Tessellation::ChordError`].
    pub tess_chord: Option<f64>,
    /// Fixed tessellation: 8*2^level segments per turn, <= 12 (instead of tess_px).
    ///
    /// [`Tessellation::FixedLevel`], at most [`MAX_TESS_LEVEL`].
    pub tess_level: Option<u32>,
    /// Surface-extraction cell on screen, pixels, at the object's nearest point.
    ///
    /// [`Extraction::ScreenCell`]: CSG and smooth-blend objects are meshed (surface nets)
    /// on a grid whose cells project to at most this many pixels; default 1.
    pub surface_px: Option<f64>,
    /// Fixed surface-nets cells on the longest side of CSG objects, 8..=512 (instead of surface_px).
    ///
    /// [`Extraction::Cells`]: grid cells along the longest side of the object's bounds,
    /// whatever the camera.
    pub surface_res: Option<u32>,
    /// Trace 8 rays of a batch as one packet (bvh=wide, no instances).
    ///
    /// Interval culling (`crate::packet`) when the BVH is [`BvhKind::Wide`], nothing is
    /// instanced and the tree is below the interleaving size (above it batches are
    /// interleaved single rays either way); same hits as single rays. Default `true` (measured: `docs/decisions/0013`).
    pub packets: Option<bool>,
    /// Instance repeated shapes under a TLAS (false = flatten into one BVH).
    ///
    /// Shapes used more than once (repetition, a mesh placed twice) come from one BLAS.
    /// `false` gives the same image with more memory. Default `true`.
    pub instancing: Option<bool>,
    /// Largest instance count a repetition may expand to.
    ///
    /// A finite repetition's cells by its counts, an infinite one's cells within
    /// `render.max_distance` of the camera; exceeding it is an error. Default 4,194,304.
    pub max_instances: Option<u64>,
    /// Cap on segments per full turn of any parametric direction (8..=65536).
    ///
    /// Bounds triangle counts when the camera touches a shape, `8..=`
    /// [`MAX_SEGMENTS_PER_TURN`]. Default 4096.
    pub max_segments: Option<u32>,
    /// The build refuses, before allocating, to plan more than this many bytes
    /// ([`crate::MeshError::OverMemoryLimit`]); estimated at [`BUILD_BYTES_PER_TRIANGLE`] per
    /// triangle plus extraction grids and instances. Not a `key=value` option: the registry
    /// sets it from `--memory-limit-mib`. Default 4 GiB.
    #[serde(skip)]
    #[schemars(skip)]
    pub memory_limit_bytes: Option<u64>,
}

/// Largest accepted [`Tessellation::FixedLevel`] (`8 * 2^12` segments per turn).
pub const MAX_TESS_LEVEL: u32 = 12;

/// Largest accepted [`MeshOptions::max_segments_per_turn`] (the angle lists alone would
/// otherwise take gigabytes before any triangle exists).
pub const MAX_SEGMENTS_PER_TURN: u32 = 1 << 16;

/// Peak bytes a build takes per triangle, for the memory estimate: measured as peak RSS over
/// triangles for one sphere tessellated to 16.4M triangles (5.2 GB, about 317 bytes each: the
/// f64 local mesh, its f32 render-space copy, the Bvh2 build and the wide layout) and for a
/// 10M-triangle OBJ (2.9 GB).
pub const BUILD_BYTES_PER_TRIANGLE: u64 = 320;

impl MeshOptions {
    /// The fast preset: Bvh2, `fast_build`, 1-pixel tessellation error, 2-pixel surface
    /// extraction cells. For previews and tests.
    pub fn fast() -> Self {
        Self {
            preset: Some(MeshPreset::Fast),
            ..Self::default()
        }
    }

    /// The quality preset: CwBvh, `slow_build`, 0.1-pixel tessellation error, half-pixel
    /// surface extraction cells.
    pub fn quality() -> Self {
        Self {
            preset: Some(MeshPreset::Quality),
            ..Self::default()
        }
    }

    /// The value of one key: as given, else its preset's. `key` reads the field, e.g.
    /// `o.pick(|o| o.bvh)`.
    pub fn pick<T>(&self, key: impl Fn(&MeshOptions) -> Option<T>) -> T {
        key(self)
            .or_else(|| key(&self.preset.unwrap_or_default().values()))
            .or_else(|| key(&MeshPreset::Default.values()))
            .expect("MeshPreset::values sets every key but preset, tess_chord and tess_level")
    }

    /// BVH layout (`bvh`).
    pub fn bvh(&self) -> BvhKind {
        self.pick(|o| o.bvh)
    }

    /// Build preset (`build`).
    pub fn build_quality(&self) -> BuildQuality {
        self.pick(|o| o.build)
    }

    /// The tessellation: by whichever of `tess_px`, `tess_chord`, `tess_level` is given,
    /// else the preset's. Errors: more than one of them is given.
    pub fn tessellation(&self) -> Result<Tessellation, crate::MeshError> {
        Ok(match (self.tess_px, self.tess_chord, self.tess_level) {
            (None, None, None) => Tessellation::ScreenError {
                pixels: self.pick(|o| o.tess_px),
            },
            (Some(pixels), None, None) => Tessellation::ScreenError { pixels },
            (None, Some(world), None) => Tessellation::ChordError { world },
            (None, None, Some(level)) => Tessellation::FixedLevel(level),
            _ => {
                return Err(crate::MeshError::InvalidOption(
                    "give one of tess_px, tess_chord, tess_level".into(),
                ));
            }
        })
    }

    /// The extraction grid: by `surface_px` or `surface_res` if given, else the preset's.
    /// Errors: both are given.
    pub fn extraction(&self) -> Result<Extraction, crate::MeshError> {
        Ok(match (self.surface_px, self.surface_res) {
            (None, None) => Extraction::ScreenCell {
                pixels: self.pick(|o| o.surface_px),
            },
            (Some(pixels), None) => Extraction::ScreenCell { pixels },
            (None, Some(cells)) => Extraction::Cells(cells),
            (Some(_), Some(_)) => {
                return Err(crate::MeshError::InvalidOption(
                    "give one of surface_px, surface_res".into(),
                ));
            }
        })
    }

    /// Whether batches are traced as packets (`packets`).
    pub fn packets(&self) -> bool {
        self.pick(|o| o.packets)
    }

    /// Whether repeated shapes are instanced (`instancing`).
    pub fn instancing(&self) -> bool {
        self.pick(|o| o.instancing)
    }

    /// Largest instance count of a repetition (`max_instances`).
    pub fn max_instances(&self) -> u64 {
        self.pick(|o| o.max_instances)
    }

    /// Cap on segments per full turn (`max_segments`).
    pub fn max_segments_per_turn(&self) -> u32 {
        self.pick(|o| o.max_segments)
    }

    /// The build's memory limit in bytes (`memory_limit_bytes`, set by the registry).
    pub fn memory_limit_bytes(&self) -> u64 {
        self.pick(|o| o.memory_limit_bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_sets_every_key_and_keys_override_it() {
        for preset in [MeshPreset::Fast, MeshPreset::Default, MeshPreset::Quality] {
            let o = MeshOptions {
                preset: Some(preset),
                ..MeshOptions::default()
            };
            let v = preset.values();
            assert_eq!(
                (o.bvh(), o.build_quality(), o.extraction().expect("valid")),
                (
                    v.bvh.expect("set"),
                    v.build.expect("set"),
                    Extraction::ScreenCell {
                        pixels: v.surface_px.expect("set")
                    }
                )
            );
            assert_eq!(
                (o.packets(), o.instancing(), o.max_instances()),
                (
                    v.packets.expect("set"),
                    v.instancing.expect("set"),
                    v.max_instances.expect("set")
                )
            );
            assert_eq!(o.max_segments_per_turn(), v.max_segments.expect("set"));
            assert_eq!(
                o.tessellation().expect("valid"),
                Tessellation::ScreenError {
                    pixels: v.tess_px.expect("set")
                }
            );
        }
        let o = MeshOptions {
            bvh: Some(BvhKind::CwBvh),
            ..MeshOptions::fast()
        };
        assert_eq!(o.bvh(), BvhKind::CwBvh);
        assert_eq!(
            o.extraction().expect("valid"),
            Extraction::ScreenCell { pixels: 2.0 }
        );
        let fixed = MeshOptions {
            surface_res: Some(96),
            ..MeshOptions::fast()
        };
        assert_eq!(fixed.extraction().expect("valid"), Extraction::Cells(96));
        let both = MeshOptions {
            surface_px: Some(1.0),
            ..fixed
        };
        assert!(both.extraction().is_err());
        assert_eq!(MeshOptions::default().bvh(), BvhKind::Wide);
        let both = MeshOptions {
            tess_px: Some(1.0),
            tess_level: Some(2),
            ..MeshOptions::default()
        };
        assert!(both.tessellation().is_err());
    }
}
