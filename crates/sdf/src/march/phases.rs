//! The phase transitions: how each field sample fed to a [`March`] moves it on (plain
//! marching, the shell's fine decision, sweeps, brackets, segment tracing and escape).

use marchmesh_core::Termination;

use super::*;

impl March {
    /// Consumes the field value `d` at [`March::point`]. In the segment phase the safe step
    /// is taken as `|d|` (plain sphere tracing); use [`March::feed_segment`] there.
    #[inline]
    pub fn feed(&mut self, d: f32, p: &Params) -> Next {
        self.feed_with(d, d.abs(), p)
    }

    /// Consumes the field value `d` at [`March::point`] and the safe step `step` along the
    /// ray over [`March::segment_len`] (`Field::segment_step`: the field keeps its sign on
    /// `[t, t + step)`; at least `|d|`).
    #[inline]
    pub fn feed_segment(&mut self, d: f32, step: f32, p: &Params) -> Next {
        self.feed_with(d, step, p)
    }

    /// Slow progress in `March`: the switch to segment tracing (the same test as in
    /// [`Lanes8::step`]). `s` is the new sample, `evals` already counts it.
    #[inline]
    fn slow(&self, s: f32, p: &Params) -> bool {
        p.segment
            && self.evals >= self.seg_from
            && s * SEGMENT_RATIO < self.r_prev
            && s > SEGMENT_RATIO * self.r_prev
    }

    #[inline]
    fn feed_with(&mut self, d: f32, seg_step: f32, p: &Params) -> Next {
        self.evals += 1;
        if d.is_nan() {
            return Next::Done(Termination::Miss);
        }
        if self.phase == Phase::Start && !self.t_restart.is_nan() {
            // An advanced start (`advance_start`) must be clear of every surface; where it is
            // not, the ray starts over from its own start.
            let t0 = std::mem::replace(&mut self.t_restart, f32::NAN);
            if d < self.eps(p) {
                self.t = t0;
                self.t_prev = t0;
                return self.budget(p);
            }
        }
        if self.phase == Phase::Start {
            // Start inside a solid: march to its exit surface with the sign flipped; but a
            // ray starting on a surface (within eps of it, at its own origin) keeps the sign
            // even if rounding or a missing offset put its origin just inside.
            let on_surface = d.abs() < self.eps(p) && self.t == self.t_min;
            self.sign = if d < 0.0 && !on_surface { -1.0 } else { 1.0 };
        }
        let s = d * self.sign;
        match self.phase {
            Phase::Start => {
                // Only a ray that starts on a surface (at its own origin, not where the scene
                // box clipped it) escapes first.
                self.phase = if s < self.eps(p) && self.t == self.t_min {
                    // Hits count below half the starting clearance; an origin on (or just
                    // inside) its own surface first has to clear the rounding level.
                    Phase::Escape {
                        thr: if s > 4.0 * self.noise() {
                            s * 0.5
                        } else {
                            f32::NEG_INFINITY
                        },
                    }
                } else {
                    Phase::March
                };
                self.step_from(s, p)
            }
            Phase::Escape { thr } => {
                if s < thr {
                    // Another surface closing in: pin it down like any shell entry.
                    return if self.refine {
                        self.enter_shell(s, p)
                    } else {
                        Next::Done(Termination::Hit)
                    };
                }
                if thr == f32::NEG_INFINITY && s < -4.0 * self.noise() {
                    // Inside a solid by more than the rounding of the start: not the own
                    // surface (left outward) but a solid touching it, as where an object
                    // rests on a floor. Stepping on by |s| would walk through it.
                    return if self.refine {
                        self.enter_shell(s, p)
                    } else {
                        Next::Done(Termination::Hit)
                    };
                }
                if s >= self.eps(p) {
                    self.phase = Phase::March;
                } else if thr == f32::NEG_INFINITY && s > 4.0 * self.noise() {
                    // Clear of the own surface: from now on a closing surface is a hit.
                    self.phase = Phase::Escape { thr: s * 0.5 };
                }
                self.step_from(s, p)
            }
            Phase::March => {
                let r = s.abs();
                let step = self.t - self.t_prev;
                if self.omega > 1.0 && r + self.r_prev < step + self.thr(p) {
                    // The relaxed step left the previous unbounding sphere uncovered: undo it,
                    // take the plain step, and stop relaxing (Keinert et al. 2014). Spheres
                    // that merely touch count as uncovered: exact spheres on either side of a
                    // sheet (a triangle, or any surface of the unsigned field traced from
                    // inside a solid) touch exactly on it.
                    self.omega = 1.0;
                    self.t = self.t_prev + self.r_prev;
                    return self.budget(p);
                }
                if s < self.eps(p) {
                    return self.enter_shell(s, p);
                }
                if self.slow(s, p) {
                    // A plain (unrelaxed) step, so no overlap check is owed, then segments.
                    self.t_prev = self.t;
                    self.r_prev = s;
                    if self.t + s > self.t_end {
                        return self.end();
                    }
                    self.t += s;
                    self.phase = Phase::Segment {
                        len: SEGMENT_GROWTH * s,
                        extra: 0,
                    };
                    return self.budget(p);
                }
                let receding = s > self.r_prev;
                let next = self.step_from(s, p);
                if next == Next::Continue
                    && p.recede_checks
                    && receding
                    && recede_checkpoint(self.evals)
                {
                    return Next::Check;
                }
                next
            }
            Phase::Segment { len, extra } => self.segment(s, seg_step, len, extra, p),
            Phase::Fine {
                ta,
                sa,
                trial,
                left,
            } => self.fine(s, ta, sa, trial, left, p),
            Phase::Sweep {
                ta,
                sa,
                t_land,
                s_land,
                left,
                evals,
                segmented,
            } => {
                if s < 0.0 {
                    // A solid after all: bracket from the last outside sample.
                    return self.crossing(self.t_prev, self.r_prev, self.t, s, p);
                }
                if s <= self.thr(p) {
                    return Next::Done(Termination::Hit);
                }
                // A segment step (at least `s`) certifies its whole length at once.
                let next = self.t + if segmented { seg_step.max(s) } else { s };
                // Clear only with an overlap of more than the fine threshold: a sheet exactly
                // where the two spheres touch is reached by the next step instead.
                let clear = next > t_land - s_land + self.thr(p);
                if !clear && evals >= SWEEP_BUDGET && s < self.r_prev {
                    // Out of budget while still closing in on a surface inside the gap (a
                    // sheet crossed at a shallow angle: the distance shrinks by `1 -
                    // sin(angle)` per step, and the prediction overshot its crossing, where
                    // the distance of a sheet has no sign to show it): decide that surface as
                    // any shell visit, from the sweep's last two samples. Taking up the
                    // prediction let shadow rays through primitives' triangle at 7 degrees.
                    let (ta, sa) = (self.t_prev, self.r_prev);
                    return self.fine_clear(s, ta, sa, false, left, p);
                }
                if clear || evals >= SWEEP_BUDGET {
                    // The gap is clear (or too long to sweep: keep the prediction, as
                    // before the sweep existed): take up the predicted sample.
                    self.t = t_land;
                    return self.predicted(s_land, ta, sa, left, p);
                }
                self.t_prev = self.t;
                self.r_prev = s;
                self.phase = Phase::Sweep {
                    ta,
                    sa,
                    t_land,
                    s_land,
                    left,
                    evals: evals + 1,
                    segmented,
                };
                self.t = next;
                self.budget(p)
            }
            Phase::Bracket {
                lo,
                slo,
                hi,
                shi,
                side,
                left,
            } => {
                if s.abs() <= self.thr(p) || left <= 1 {
                    return Next::Done(Termination::Hit);
                }
                let t = self.t;
                // Illinois: when the same end moves twice, halve the other end's value.
                if s > 0.0 {
                    let shi = if side == 1 { shi * 0.5 } else { shi };
                    self.bracket(t, s, hi, shi, 1, left - 1, p)
                } else {
                    let slo = if side == -1 { slo * 0.5 } else { slo };
                    self.bracket(lo, slo, t, s, -1, left - 1, p)
                }
            }
        }
    }

    /// A segment-tracing sample `s` at `self.t` with safe step `step` over `len`.
    #[inline]
    fn segment(&mut self, s: f32, step: f32, len: f32, extra: u32, p: &Params) -> Next {
        if s < 0.0 {
            // Rounding put the step just past the surface: the last sample is outside.
            return self.crossing(self.t_prev, self.r_prev, self.t, s, p);
        }
        let thr = self.thr(p);
        if s <= thr && (step <= thr || extra >= SEGMENT_EXTRA) {
            return Next::Done(Termination::Hit);
        }
        let gains = step >= SEGMENT_GAIN * s;
        if !gains && len > SEGMENT_RETRY * s {
            // The segment reached far past the distance, e.g. beyond a box's far edge, where
            // the bound is 1: ask again here over a short one (one evaluation), whose bound
            // is the local one. Without this, grazing rays near a box top's far end fell back
            // to the shell logic and its 24-evaluation limit (depth error 1e-3).
            self.phase = Phase::Segment {
                len: (SEGMENT_RETRY_LEN * s).max(thr),
                extra,
            };
            return self.budget(p);
        }
        if !gains {
            if s < self.eps(p) {
                // Near a surface the bound is no better than the distance: decide hit or
                // near miss as plain marching does, from this sample alone. (A secant from
                // the previous segment sample, far back, could predict a crossing past the
                // solid's far side, and the bracket then converged there: found by the
                // random grazing-ray test on a CSG box at 1.2 degree.)
                self.t_prev = self.t;
                self.r_prev = s;
                return self.enter_shell(s, p);
            }
            // Not grazing after all (e.g. passing a silhouette): back to the 8-lane path, and
            // no new switch for a while (each costs scalar samples).
            self.seg_from = self.evals + SEGMENT_MIN_EVALS;
            self.phase = Phase::March;
            return self.step_from(s, p);
        }
        // The field keeps its sign on [t, t + step): step slightly short of it, so rounding
        // of the bound cannot carry the ray past a surface.
        let adv = (step * (1.0 - 1.0 / 1024.0)).max(s);
        self.t_prev = self.t;
        self.r_prev = s;
        if self.t + adv > self.t_end {
            return self.end();
        }
        self.t += adv;
        self.phase = Phase::Segment {
            len: SEGMENT_GROWTH * adv,
            extra: extra + u32::from(s <= thr),
        };
        self.budget(p)
    }

    /// A sample `s < eps` while marching.
    #[inline]
    fn enter_shell(&mut self, s: f32, p: &Params) -> Next {
        if s < 0.0 {
            // Stepped inside (relaxation or a bound): the last accepted sample is outside.
            return self.crossing(self.t_prev, self.r_prev, self.t, s, p);
        }
        if s <= self.thr(p) {
            return Next::Done(Termination::Hit);
        }
        let (ta, sa) = (self.t_prev, self.r_prev);
        self.shell_t = self.t;
        self.shell_s = s;
        self.shell_k = if self.t > ta {
            (sa - s) / (self.t - ta)
        } else {
            0.0
        };
        self.fine(s, ta, sa, false, FINE_BUDGET, p)
    }

    /// A shell sample `s` at `self.t`; `(ta, sa)` the previous one, `trial` whether `self.t`
    /// was a secant prediction.
    #[inline]
    fn fine(&mut self, s: f32, ta: f32, sa: f32, trial: bool, left: u32, p: &Params) -> Next {
        let t = self.t;
        if s < 0.0 {
            return self.crossing(ta, sa, t, s, p);
        }
        if s <= self.thr(p) {
            return Next::Done(Termination::Hit);
        }
        if trial && sa + s < t - ta + self.thr(p) {
            // The spheres at `ta` and at the prediction leave a gap, or merely touch (as two
            // exact spheres on either side of a sheet do, touching on the sheet): sweep it.
            self.phase = Phase::Sweep {
                ta,
                sa,
                t_land: t,
                s_land: s,
                left,
                evals: 0,
                segmented: p.segment_sweeps,
            };
            self.t_prev = ta;
            self.r_prev = sa;
            self.t = ta + sa;
            return self.budget(p);
        }
        self.fine_clear(s, ta, sa, trial, left, p)
    }

    /// Whether the shell visit that has spent its budget and is at sample `s` at `t` passes
    /// the surface by: the parabola through the visit's first sample with its approach slope
    /// and through `(t, s)` (the distance along a ray passing a smooth surface, curving
    /// away) bottoms out above `s / 2`. Renews the visit's fit from `(t, s)` when it does.
    /// A ray closing in on a plane at a shallow angle (a straight line, no curvature) or
    /// on a surface it will touch does not pass.
    #[inline]
    fn passes_clear(&mut self, t: f32, s: f32) -> bool {
        let len = t - self.shell_t;
        let (s0, k0) = (self.shell_s, self.shell_k);
        // d(x) = s0 - k0 x + c x^2 through (len, s); NaN (len 0) fails every test below.
        let c = (s - s0 + k0 * len) / (len * len);
        let lowest = if k0 > 0.0 {
            s0 - k0 * k0 / (4.0 * c)
        } else {
            s0
        };
        let clear = len > 0.0 && c > 0.0 && lowest > 0.5 * s;
        if clear {
            self.shell_t = t;
            self.shell_s = s;
            self.shell_k = k0 - 2.0 * c * len;
        }
        clear
    }

    /// A shell sample `s > thr` at `self.t` that is a prediction from `(ta, sa)` whose gap
    /// (if any) was swept clear.
    #[inline]
    fn predicted(&mut self, s: f32, ta: f32, sa: f32, left: u32, p: &Params) -> Next {
        self.fine_clear(s, ta, sa, true, left, p)
    }

    /// The rest of [`March::fine`] for a sample `s > thr` with no gap left before it.
    #[inline]
    fn fine_clear(&mut self, s: f32, ta: f32, sa: f32, trial: bool, left: u32, p: &Params) -> Next {
        let t = self.t;
        let eps = self.eps(p);
        if s >= eps {
            // Left the shell (a near miss): back to marching.
            self.phase = Phase::March;
            return self.step_from(s, p);
        }
        let mut left = left;
        if left == 0 {
            if !self.passes_clear(t, s) {
                // A long passage within the shell nearly parallel to a surface (it would cost
                // length / distance steps): called a hit, as a plain epsilon test would.
                return Next::Done(Termination::Hit);
            }
            // A pass whose closest approach stays clear of the surface: decided by going on
            // (a shadow ray skimming primitives' torus at 0.9 of the shell was called
            // blocked here).
            left = FINE_BUDGET;
        }
        self.t_prev = t;
        self.r_prev = s;
        let slope = (sa - s) / (t - ta);
        // After a prediction, keep predicting only while it converges.
        let converging = !trial || s < 0.5 * sa;
        if converging && t > ta && slope > 0.01 {
            // Approaching: jump to the predicted crossing and look.
            self.phase = Phase::Fine {
                ta: t,
                sa: s,
                trial: true,
                left: left - 1,
            };
            // Never past the end of the range: a surface between here and the prediction
            // must still be looked at (the sweep does) rather than the ray ending there.
            self.t = (t + s / slope).min(self.t_end);
            return self.budget(p);
        }
        // A failed prediction (the ray passes the surface by) or not approaching.
        // Receding samples (the ray moving away from the surface, e.g. above a horizon)
        // step like plain marching and spend no budget; only approaches do.
        let receding = s >= sa;
        self.phase = Phase::Fine {
            ta: t,
            sa: s,
            trial: false,
            left: if receding { left.max(1) } else { left - 1 },
        };
        // A step of eps / 2 is longer than the distance: where it would pass the end of the
        // range, look at the end first (a solid's exit surface can lie on the scene box, e.g.
        // a face of the box the camera is inside, and the step would leave the range
        // without the sample past the surface that shows the crossing).
        let next = t + s.max(0.5 * eps);
        self.t = if t < self.t_end {
            next.min(self.t_end)
        } else {
            next
        };
        if receding && p.segment && self.evals >= self.seg_from {
            // A ray receding from a surface it passes within the shell, nearly parallel to it
            // (skimming a cylinder's cap within 0.05 px: ~500 steps of its height), crawls at
            // steps of its distance: segment tracing's local bound takes it away in a few.
            // Should the bound gain nothing, the segment phase hands back to the shell logic
            // and the next switch waits [`SHELL_SEGMENT_WAIT`] evaluations.
            self.seg_from = self.evals + SHELL_SEGMENT_WAIT;
            self.phase = Phase::Segment {
                len: SEGMENT_GROWTH * s.max(0.5 * eps),
                extra: 0,
            };
        }
        self.budget(p)
    }

    /// A sign change between `lo` (outside, `slo > 0`) and `hi` (inside).
    #[inline]
    fn crossing(&mut self, lo: f32, slo: f32, hi: f32, shi: f32, p: &Params) -> Next {
        if !self.refine {
            return Next::Done(Termination::Hit);
        }
        if p.refine_steps == 0 {
            self.t = lo;
            return Next::Done(Termination::Hit);
        }
        self.bracket(lo, slo, hi, shi, 0, p.refine_steps, p)
    }

    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn bracket(
        &mut self,
        lo: f32,
        slo: f32,
        hi: f32,
        shi: f32,
        side: i8,
        left: u32,
        p: &Params,
    ) -> Next {
        let denom = slo - shi;
        let mut t = if denom > 0.0 {
            lo + slo * (hi - lo) / denom
        } else {
            0.5 * (lo + hi)
        };
        if !(t > lo.min(hi) && t < lo.max(hi)) {
            t = 0.5 * (lo + hi);
        }
        if (hi - lo).abs() <= 1e-7 * (self.base + hi.abs()) {
            self.t = lo;
            return Next::Done(Termination::Hit);
        }
        self.phase = Phase::Bracket {
            lo,
            slo,
            hi,
            shi,
            side,
            left,
        };
        self.t = t;
        if self.evals >= p.max_steps {
            // Out of budget inside a bracket: the crossing is known to lie in it.
            self.t = lo;
            return Next::Done(Termination::Hit);
        }
        Next::Continue
    }

    /// Steps on from an accepted sample `s` at `self.t` (March or Escape).
    #[inline]
    fn step_from(&mut self, s: f32, p: &Params) -> Next {
        self.t_prev = self.t;
        self.r_prev = s;
        let step = if matches!(self.phase, Phase::March) {
            s * self.omega
        } else {
            // Escape: |s| is a safe step on either side; never stall on a zero distance.
            s.abs().max(1e-7 * (self.base + self.t).max(1e-30))
        };
        if self.t + s > self.t_end {
            // Even the plain step leaves the range.
            return self.end();
        }
        // A relaxed step past the end is shortened to the end (and still overlap-checked).
        self.t = (self.t + step).min(self.t_end);
        self.budget(p)
    }
}
