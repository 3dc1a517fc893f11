//! The backend registry, re-exported: it lives in `marchmesh-registry` so the viewer and the
//! stability study can build backends without depending on the harness's runner and reports.

pub use marchmesh_registry::*;
