//! Repetition in the reference: the ray walks the lattice cells it crosses and intersects the
//! copies that can reach each cell, exactly, with a bound on the work per query.

use std::collections::HashSet;

use glam::DVec3;

use crate::node::{CompiledNode, MAX_WORK_PER_QUERY, Work, ray_box, union_many};
use crate::spans::{Boundary, Span, first_boundary};

/// Domain repetition of one child.
#[derive(Debug)]
pub(crate) struct Repeat {
    pub(crate) child: CompiledNode,
    pub(crate) period: DVec3,
    /// Per axis: `Some((j_min, j_max, offset))` copies at `(j + offset) * period`; `None` for
    /// an axis that is not repeated.
    pub(crate) range: [Option<(i64, i64, f64)>; 3],
    /// Child bounds in the repetition frame (before the copy offset).
    pub(crate) child_bounds: (DVec3, DVec3),
    /// Neighbour offsets whose copies can reach into a cell, per axis.
    pub(crate) reach: [(i64, i64); 3],
    /// Some copy reaches beyond its cell (`reach` is not all zero), so copies may overlap.
    pub(crate) copies_overlap: bool,
    pub(crate) max_cells: u32,
}

impl Repeat {
    pub(crate) fn offset(&self, j: [i64; 3]) -> DVec3 {
        let mut off = DVec3::ZERO;
        for a in 0..3 {
            if let Some((_, _, c)) = self.range[a] {
                off[a] = (j[a] as f64 + c) * self.period[a];
            }
        }
        off
    }

    pub(crate) fn in_range(&self, j: [i64; 3]) -> bool {
        (0..3).all(|a| match self.range[a] {
            Some((lo, hi, _)) => j[a] >= lo && j[a] <= hi,
            None => j[a] == 0,
        })
    }

    /// Walks the cells the ray crosses within `[t0, t1]` (Amanatides-Woo over the repeated
    /// axes) and calls `visit(copy)` for every copy that can reach into each cell, once per
    /// copy. `visit` returns false to stop; the walk also stops after `max_cells` cells
    /// (flagged as exhausted) or when `stop_after(t_cell_exit)` says so.
    #[allow(clippy::too_many_arguments)] // A walk's ray, range, counters and two callbacks.
    pub(crate) fn walk(
        &self,
        o: DVec3,
        d: DVec3,
        t0: f64,
        t1: f64,
        work: &mut Work,
        visit: &mut dyn FnMut([i64; 3], &mut Work) -> bool,
        stop_after: &dyn Fn(f64) -> bool,
    ) {
        let p0 = o + t0 * d;
        let mut cell = [0i64; 3];
        let mut t_next = [f64::INFINITY; 3];
        let mut t_delta = [f64::INFINITY; 3];
        let mut step = [0i64; 3];
        for a in 0..3 {
            let Some((_, _, c)) = self.range[a] else {
                continue;
            };
            let p = self.period[a];
            let x = p0[a] / p - c;
            cell[a] = x.round() as i64;
            if d[a] != 0.0 {
                step[a] = if d[a] > 0.0 { 1 } else { -1 };
                let boundary = (cell[a] as f64 + c + 0.5 * step[a] as f64) * p;
                t_next[a] = t0 + ((boundary - p0[a]) / d[a]).max(0.0);
                t_delta[a] = p / d[a].abs();
            }
        }
        let mut seen: HashSet<[i64; 3]> = HashSet::new();
        let mut cells = 0u32;
        loop {
            cells += 1;
            if cells > self.max_cells || work.steps.saturating_add(cells) > MAX_WORK_PER_QUERY {
                work.exhausted = true;
                break;
            }
            // Copies that reach into this cell, clipped to the copies that exist.
            let span = |a: usize| {
                let (lo, hi) = (cell[a] + self.reach[a].0, cell[a] + self.reach[a].1);
                match self.range[a] {
                    Some((j0, j1, _)) => (lo.max(j0), hi.min(j1)),
                    None => (0, 0),
                }
            };
            let (sx, sy, sz) = (span(0), span(1), span(2));
            for jx in sx.0..=sx.1 {
                for jy in sy.0..=sy.1 {
                    for jz in sz.0..=sz.1 {
                        let j = [jx, jy, jz];
                        if self.in_range(j) && seen.insert(j) && !visit(j, work) {
                            work.steps = work.steps.saturating_add(cells);
                            return;
                        }
                    }
                }
            }
            let (axis, t_exit) = (0..3)
                .map(|a| (a, t_next[a]))
                .min_by(|x, y| x.1.total_cmp(&y.1))
                .unwrap_or((0, f64::INFINITY));
            if t_exit > t1 || stop_after(t_exit) || !t_exit.is_finite() {
                break;
            }
            cell[axis] += step[axis];
            t_next[axis] += t_delta[axis];
        }
        work.steps = work.steps.saturating_add(cells);
    }

    /// Where the walk starts and ends: the query range clipped to the copies' extent.
    pub(crate) fn range_t(&self, o: DVec3, d: DVec3, t0: f64, t1: f64) -> Option<(f64, f64)> {
        let (mut lo, mut hi) = (DVec3::splat(f64::NEG_INFINITY), DVec3::splat(f64::INFINITY));
        for a in 0..3 {
            match self.range[a] {
                None => {
                    lo[a] = self.child_bounds.0[a];
                    hi[a] = self.child_bounds.1[a];
                }
                Some((j0, j1, c)) if j0 > i64::MIN / 8 => {
                    let p = self.period[a];
                    lo[a] = (self.child_bounds.0[a] + (j0 as f64 + c) * p)
                        .min((j0 as f64 + c - 0.5) * p);
                    hi[a] = (self.child_bounds.1[a] + (j1 as f64 + c) * p)
                        .max((j1 as f64 + c + 0.5) * p);
                }
                Some(_) => {}
            }
        }
        ray_box(o, d, (lo, hi), t0, t1)
    }

    pub(crate) fn closest(
        &self,
        o: DVec3,
        d: DVec3,
        t_min: f64,
        t_max: f64,
        work: &mut Work,
    ) -> Option<Boundary> {
        // The repetition is the union of whole copies. Copies that fit their cells are
        // disjoint, so the first surface of any copy is the union's; overlapping solid
        // copies seen from inside one need the union's spans (inner faces are not seen).
        if self.copies_overlap && self.child.solid {
            let starts_inside = self
                .spans(o, d, t_min, t_min, work)
                .iter()
                .any(|s| s.enter.t <= t_min && t_min < s.exit.t);
            if starts_inside {
                return first_boundary(&self.spans(o, d, t_min, t_max, work), t_min, t_max);
            }
        }
        let (a, b) = self.range_t(o, d, t_min, t_max)?;
        let best = std::cell::Cell::new(None::<Boundary>);
        self.walk(
            o,
            d,
            a,
            b,
            work,
            &mut |j, work| {
                let hi = best.get().map_or(t_max, |h| h.t);
                if let Some(h) = self.child.closest(o - self.offset(j), d, t_min, hi, work)
                    && best.get().is_none_or(|b| h.t < b.t)
                {
                    best.set(Some(h));
                }
                true
            },
            &|t_exit| best.get().is_some_and(|h| h.t <= t_exit),
        );
        best.get()
    }

    pub(crate) fn spans(
        &self,
        o: DVec3,
        d: DVec3,
        t_min: f64,
        t_max: f64,
        work: &mut Work,
    ) -> Vec<Span> {
        // Start early enough to meet every copy that contains the point at t_min.
        let size = (self.child_bounds.1 - self.child_bounds.0).length() + self.period.length();
        let back = size / d.length();
        let Some((a, b)) = self.range_t(o, d, t_min - back, t_max) else {
            return Vec::new();
        };
        let mut all = Vec::new();
        self.walk(
            o,
            d,
            a,
            b,
            work,
            &mut |j, work| {
                all.extend(self.child.spans(o - self.offset(j), d, t_min, t_max, work));
                true
            },
            &|_| false,
        );
        union_many(all)
    }
}
