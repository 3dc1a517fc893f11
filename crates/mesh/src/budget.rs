//! The build's memory budget: the running estimate checked against the memory limit
//! before each allocation, and the byte and triangle estimates it is charged with.

use crate::{BUILD_BYTES_PER_TRIANGLE, MeshError};

/// Bytes per placement (the walk's placement, the instance and its box), for the estimate.
pub(crate) const INSTANCE_BYTES: u64 = 160;

/// Bytes per cell of a surface-extraction grid (f32 samples plus surface nets' per-cell
/// vertex map), for the estimate.
pub(crate) const EXTRACTION_BYTES_PER_CELL: u64 = 12;

/// The build's running memory estimate against [`MeshOptions::memory_limit_bytes`].
pub(crate) struct BuildBudget {
    pub(crate) limit_bytes: u64,
    pub(crate) planned_bytes: u64,
}

impl BuildBudget {
    /// Triangles that still fit, `copies` times each.
    pub(crate) fn triangles_left(&self, copies: u64) -> u64 {
        self.limit_bytes.saturating_sub(self.planned_bytes)
            / BUILD_BYTES_PER_TRIANGLE
            / copies.max(1)
    }

    /// Adds `bytes` (kept for the rest of the build when `keep`), or refuses.
    pub(crate) fn take(
        &mut self,
        bytes: u64,
        keep: bool,
        json_path: &str,
        what: impl FnOnce() -> String,
        knob: &'static str,
    ) -> Result<(), MeshError> {
        let needed = self.planned_bytes.saturating_add(bytes);
        if needed > self.limit_bytes {
            return Err(self.refusal(bytes, json_path, what(), knob));
        }
        if keep {
            self.planned_bytes = needed;
        }
        Ok(())
    }

    /// The error refusing `bytes` more.
    pub(crate) fn refusal(
        &self,
        bytes: u64,
        json_path: &str,
        what: String,
        knob: &'static str,
    ) -> MeshError {
        MeshError::OverMemoryLimit {
            json_path: json_path.to_string(),
            what,
            needed_mib: self.planned_bytes.saturating_add(bytes).div_ceil(1 << 20),
            limit_mib: self.limit_bytes >> 20,
            knob,
        }
    }
}

/// What to change when extraction is over the memory limit.
pub(crate) const EXTRACTION_KNOB: &str = "the extraction grid (--opt surface_px or surface_res)";

/// Triangles expected from extracting a surface on a grid of `resolution` cells along its
/// longest side, for the estimate made before any extraction: a sphere filling the grid
/// (surface nets emit two triangles per grid face the surface crosses: `2 pi res^2`). A
/// surface with more area in the same box (many small parts) gives more; the exact count is
/// charged after each extraction.
pub(crate) fn extracted_triangles_estimate(resolution: u32) -> u64 {
    let r = u64::from(resolution);
    (r * r).saturating_mul(2 * 314) / 100
}

/// Peak build bytes of `triangles` stored `copies` times.
pub(crate) fn triangle_bytes(triangles: u64, copies: u64) -> u64 {
    triangles
        .saturating_mul(copies)
        .saturating_mul(BUILD_BYTES_PER_TRIANGLE)
}
