//! Smooth unions in the reference: the exact surface of the blended distance field found by f64
//! root finding along the ray, bracketed by the children's boxes.

use glam::DVec3;
use marchmesh_field::Field;

use crate::node::{MAX_WORK_PER_QUERY, Work, ray_box};
use crate::spans::{Boundary, Span};

/// A smooth union: its f64 field in the node's local frame and the search settings.
#[derive(Debug)]
pub(crate) struct Smooth {
    pub(crate) field: Field,
    pub(crate) bounds: Option<(DVec3, DVec3)>,
    /// Absolute root tolerance and minimum march step, local units.
    pub(crate) eps: f64,
    /// Central-difference step for normals, local units.
    pub(crate) h: f64,
    pub(crate) max_steps: u32,
}

impl Smooth {
    pub(crate) fn boundary(&self, o: DVec3, d: DVec3, t: f64) -> Boundary {
        let p = o + t * d;
        let h = self.h;
        let g = |q: DVec3| self.field.distance_f64(q);
        let normal = DVec3::new(
            g(p + DVec3::X * h) - g(p - DVec3::X * h),
            g(p + DVec3::Y * h) - g(p - DVec3::Y * h),
            g(p + DVec3::Z * h) - g(p - DVec3::Z * h),
        );
        Boundary {
            t,
            normal,
            material: self.field.distance_material_f64(p).1,
        }
    }

    /// Sign changes of the field along the ray by sphere tracing in f64 (steps never pass
    /// the zero set) and bisection of each bracketed change to the last bit.
    pub(crate) fn spans(
        &self,
        o: DVec3,
        d: DVec3,
        t_min: f64,
        t_max: f64,
        work: &mut Work,
    ) -> Vec<Span> {
        // The box grown by a few root tolerances: a smooth intersection's or subtraction's
        // surface lies on its box (a smooth maximum equals its first argument away from the
        // blends), and a march starting exactly on the surface can read the inside's sign
        // first and lose the hit.
        let grown = self.bounds.map(|(lo, hi)| {
            let margin = DVec3::splat(4.0 * self.eps);
            (lo - margin, hi + margin)
        });
        let (mut t, t_end) = match grown {
            Some(b) => match ray_box(o, d, b, t_min, t_max) {
                Some(r) => r,
                None => return Vec::new(),
            },
            None => (t_min, t_max),
        };
        let len = d.length();
        // A bound with the field's sign: exact where a surface may be, the far cells'
        // bound elsewhere (see `Field::distance_bound_f64`).
        let f = |t: f64| self.field.distance_bound_f64(o + t * d);
        let mut g = f(t);
        let mut inside = g < 0.0;
        let mut open = inside.then(|| Boundary::infinite(f64::NEG_INFINITY));
        let mut spans = Vec::new();
        let mut steps = 0u32;
        while t < t_end {
            steps += 1;
            if steps > self.max_steps || work.steps.saturating_add(steps) > MAX_WORK_PER_QUERY {
                work.exhausted = true;
                break;
            }
            let step = (g.abs() / len).max(self.eps / len);
            let t_next = (t + step).min(t_end);
            let g_next = f(t_next);
            if (g_next < 0.0) != inside {
                // Bisect [t, t_next] on the sign.
                let (mut a, mut b) = (t, t_next);
                for _ in 0..80 {
                    let m = 0.5 * (a + b);
                    if m <= a || m >= b {
                        break;
                    }
                    if (f(m) < 0.0) == inside {
                        a = m;
                    } else {
                        b = m;
                    }
                    steps += 1;
                }
                let root = 0.5 * (a + b);
                let bd = self.boundary(o, d, root);
                if inside {
                    spans.push(Span {
                        enter: open.take().unwrap_or(Boundary::infinite(f64::NEG_INFINITY)),
                        exit: bd,
                    });
                } else {
                    open = Some(bd);
                }
                inside = !inside;
            }
            t = t_next;
            g = g_next;
        }
        if let Some(e) = open {
            spans.push(Span {
                enter: e,
                exit: Boundary::infinite(f64::INFINITY),
            });
        }
        work.steps = work.steps.saturating_add(steps);
        spans
    }
}
