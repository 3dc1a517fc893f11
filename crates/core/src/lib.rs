//! The marchmesh ray-tracer core.
//!
//! The core owns everything but intersection: camera ray generation ([`camera`]), the Phong
//! integrator with hard and area-light shadows, ambient occlusion, iterative reflections and
//! Halton anti-aliasing ([`integrator`]), the path tracer ([`path`]) with its area lights
//! ([`emitter`]) and samplers ([`sampling`]), framebuffers with per-pixel AOVs ([`framebuffer`]), backgrounds and image
//! output. It talks to geometry only through [`Geometry`]; backends never shade.

pub mod backend;
pub mod background;
pub mod camera;
mod clock;
pub mod compare;
pub mod emitter;
pub mod frame;
pub mod framebuffer;
pub mod geometry;
pub mod image_io;
pub mod integrator;
pub mod path;
pub mod sampling;
pub mod stats;
mod stream;
pub mod tolerance;

pub use backend::{Backend, QualityKnob};
pub use background::{
    BackgroundError, BackgroundSampler, ENVIRONMENT_BYTES_PER_TEXEL, check_background,
};
pub use camera::{PrimarySamples, Tile};
pub use compare::{Accuracy, compare};
pub use frame::{FAR_RATIO, FarFrame, FrameEntry};
pub use framebuffer::{Framebuffer, NO_HIT_DEPTH};
pub use geometry::*;
pub use integrator::{
    DEFAULT_MEMORY_LIMIT_BYTES, MAX_THREADS, RenderError, RenderOptions, RenderOutput, TILE_HEIGHT,
    TILE_RAYS, TILE_WIDTH, render, render_into, tile_width,
};
pub use stats::{RayTypeRates, RayTypeTimes, RenderStats};
pub use tolerance::{INVISIBLE_PSNR_DB, Measured, Tolerance};
