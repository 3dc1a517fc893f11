//! The shared conformance suite, mesh backend against the exact reference.
//!
//! The suite's tolerances are for an accurate render, so the backend runs with a 0.05 px
//! screen-space chord budget (the default 0.25 px gives about 3e-3 relative depth error at
//! 64x64, by design: the budget is in pixels) and 128-cell CSG extraction. Loosened cases
//! say why; everything else meets the suite's default tolerances.

use marchmesh_conformance::{CaseId, Tolerance, conformance_suite};
use marchmesh_mesh::{MeshBackend, MeshOptions};

fn tolerance(case: CaseId) -> Tolerance {
    let t = Tolerance::default();
    match case {
        // Surface nets round the sharp rim where the sphere carves the box: measured 1.63 deg
        // mean normal error and 1.22% material mismatch at the rim (intersection and smooth
        // union meet the defaults).
        CaseId::subtraction => Tolerance {
            normal_deg_mean: 2.5,
            material_mismatch_pct: 2.0,
            ..t
        },
        // The camera is inside overlapping copies, so the repetition is extracted as one
        // surface (128 cells): surface nets round the creases where the copies meet,
        // measured 1.49 deg mean normal error (0 silhouette pixels).
        CaseId::camera_inside_repeat => Tolerance {
            normal_deg_mean: 2.5,
            ..t
        },
        _ => t,
    }
}

conformance_suite!(
    backend = MeshBackend,
    settings = MeshOptions {
        tess_px: Some(0.05),
        ..MeshOptions::default()
    },
    tolerance = tolerance
);
