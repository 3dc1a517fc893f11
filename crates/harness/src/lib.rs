//! The marchmesh benchmark harness.
//!
//! [`backend`] builds any backend by name with `key=value` options; the rest of the harness
//! runs suites and writes reports.
//!
//! Rendering one scene with every backend, as `marchmesh render` does (the scene, then a
//! backend built for it, then the core's integrator):
//!
//! ```
//! use marchmesh_harness::backend::{self, BackendId, BackendSpec};
//!
//! let scene = marchmesh_scene::parse_scene(
//!     r#"{ "camera": { "position": [0, 0, -4], "look_at": [0, 0, 0], "width": 9, "height": 9 },
//!          "objects": [ { "shape": { "sphere": { "radius": 1 } } } ] }"#,
//!     "doc.json",
//!     std::path::Path::new("."),
//! )?;
//! let background = marchmesh_core::BackgroundSampler::load(&scene.background)?;
//! for kind in BackendId::ALL {
//!     let spec = BackendSpec { kind, options: vec![] };
//!     let geometry = backend::build(&scene, &spec)?;
//!     let options = marchmesh_core::RenderOptions { threads: 1, ..Default::default() };
//!     let out = marchmesh_core::render(&scene, geometry.as_ref(), &background, &options, &|| {})?;
//!     let depth = |col: usize, row: usize| out.framebuffer.depth[row * 9 + col];
//!     // The centre pixel looks straight at the sphere, 3 units away (the mesh backend's
//!     // tessellation is within a quarter of the 0.38-unit pixel footprint); a corner misses.
//!     assert!((depth(4, 4) - 3.0).abs() < 0.1, "{kind}: {}", depth(4, 4));
//!     assert!(depth(0, 0).is_infinite(), "{kind}");
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// The counting allocator is the one place that needs unsafe code (GlobalAlloc is an unsafe trait).
#[allow(unsafe_code)]
pub mod alloc;
pub mod anchors;
pub mod backend;
pub mod bench;
pub mod decision;
pub mod findings;
pub mod html;
pub mod images;
pub mod report;
pub mod results;
pub mod rss;
pub mod schedule;
pub mod stats;
pub mod suite;
pub mod verdicts;
