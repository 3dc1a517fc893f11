//! The marchmesh ray-tracer core.
//!
//! The core owns everything but intersection: camera ray generation, the Phong integrator
//! (ambient, diffuse, specular), hard shadows via occlusion rays, iterative reflections,
//! Halton anti-aliasing, framebuffers with per-pixel AOVs, and image output. It talks to
//! geometry only through [`Geometry`].

pub mod geometry;

pub use geometry::*;
