//! Where does each representation break? Families of extreme scenes, each run on the exact
//! reference and on every approximate backend, compared pixel by pixel, with a verdict.
//!
//! * [`cases`]: the families (scale, camera distance, large coordinates, grazing rays, thin
//!   features, sphere-tracing epsilon / step / relaxation extremes, hostile meshes, shadow and
//!   reflection acne) as generated scenes.
//! * [`runner`]: renders each case, measures it against its ground truth ([`Metrics`]) and
//!   classifies it ([`Verdict`]).
//! * [`report`]: `stability.csv`, `stability.json` and `summary.md`.
//!
//! `marchmesh stability` drives it; the README's stability section summarises a run.

pub mod cases;
pub mod report;
pub mod runner;

pub use cases::{CaseContext, StabilityCase, Variant, all_cases};
pub use runner::{Metrics, Row, RunOptions, Verdict, run_case, run_cases};
