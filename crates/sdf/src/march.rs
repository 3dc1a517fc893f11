//! The per-ray sphere-tracing state machine. It never evaluates the field itself: it names
//! the point it needs ([`March::point`]) and consumes the distance there ([`March::feed`]), so
//! single rays and 8-ray lockstep batches run exactly the same logic.
//!
//! # Phases
//! * `March`: sphere tracing with step `omega * d` (Keinert over-relaxation with the overlap
//!   fallback). A sample below the hit epsilon `eps` (the *shell*) enters `Fine`.
//! * `Fine`: decides whether the ray really meets the surface it came close to, instead of
//!   calling every ray that passes within `eps` a hit (which would grow silhouettes by `eps`
//!   and let grazing rays stop on the wrong object). While approaching, a secant step
//!   predicts where the ray crosses the surface; the sample there is a hit if it is within
//!   the fine threshold `thr`, brackets the crossing if it is inside (then `Bracket`), and
//!   otherwise means the ray passes the surface by (a near miss): marching goes on from
//!   there. When not approaching, steps are `max(d, eps / 2)`; leaving the shell
//!   (`d >= eps`) returns to `March`. Only a feature thinner than `eps / 2` can be stepped
//!   over in the shell: the same merging the hit epsilon stands for. A visit to the shell
//!   that cannot decide within 48 evaluations (a long passage nearly parallel to a surface,
//!   e.g. the horizon of a huge sphere) ends as a hit, as a plain epsilon test would, unless
//!   its closest approach clears the surface: a parabola through the visit's first sample,
//!   with its approach slope, and through the current one (the distance along a ray
//!   passing a smooth surface curves up) that bottoms out above half the current distance
//!   renews the budget.
//!   A prediction is only trusted where the unbounding spheres of the sample before it and of
//!   the predicted sample cover the jump (Keinert's overlap test): otherwise the gap between
//!   them may hide a surface without an inside (a triangle, an open mesh: the field does not
//!   change sign there), which `Sweep` looks for before the prediction is used.
//! * `Sweep`: tracing through such a gap, from the earlier sample's sphere to the
//!   prediction's; a distance below the fine threshold there is a hit, reaching the
//!   prediction's sphere clears the gap, running out of [`SWEEP_BUDGET`] while the distance
//!   still shrinks decides the surface closed in on as a shell visit. With segment tracing
//!   on (and an 8-lane tape to answer the queries, [`Params::segment_sweeps`]), each
//!   sample is a segment
//!   query over the rest of the gap and the step its safe step (the field keeps its sign
//!   over it, so no sheet is stepped over): where the field has local bounds one query
//!   usually clears a gap that plain steps crossed in up to [`SWEEP_BUDGET`] (a ray
//!   approaching a curved surface at a shallow angle, whose prediction undershoots).
//! * `Bracket`: regula falsi (Illinois) on a sign change, to the fine threshold.
//! * `Segment`: segment tracing (Galin et al. 2020, "Segment Tracing Using Local Lipschitz
//!   Bounds"): the step is the field's safe step along the ray from local directional
//!   Lipschitz bounds ([`marchmesh_field::Field::segment_step`], `|f| / lambda` with
//!   `lambda` a bound of `|df/dt|` over the next segment), which the caller supplies through
//!   [`March::feed_segment`]. Sphere tracing a ray at angle `theta` over a plane shrinks the
//!   distance by `1 - sin(theta)` per step (at 0.01 degree every ray exhausted 512 steps);
//!   with `lambda = sin(theta)` the step reaches the surface at once. Entered from `March`
//!   only when progress is slow (after [`SEGMENT_MIN_EVALS`] evaluations, a distance that
//!   changed by less than a factor [`SEGMENT_RATIO`] either way), or from the shell when a
//!   ray recedes from a surface (`SHELL_SEGMENT_WAIT`), so ordinary rays stay on the 8-lane
//!   plain path;
//!   left for `March` again when the bound gains nothing, for the shell logic below when it
//!   gains nothing within `eps` of a surface. Every step is a safe step (never past a sign
//!   change), so a sheet or a thin feature is not skipped; a hit is a sample below `thr`
//!   whose safe step is below `thr` too, so grazing hits are not called `thr / sin(theta)`
//!   early.
//! * `Escape`: a ray starting on a surface (secondary rays) first leaves that surface's shell
//!   stepping by the (safe) distance; a hit there is a distance below half the starting
//!   clearance (another surface closing in, e.g. at a contact), or, for a ray starting
//!   within rounding of its surface, a value inside by more than that rounding (a solid
//!   touching the start surface, as where an object rests on a floor: stepping by `|d|`
//!   would walk through it).

use glam::Vec3;
use marchmesh_core::{NoHit, Ray, Termination};
use marchmesh_field::{F32x8, Lane, M8, V3};

/// Per-ray constants shared by every ray of a geometry.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Params {
    /// Absolute epsilon part (world units).
    pub eps_abs: f32,
    /// Cone epsilon per unit distance from the camera.
    pub eps_cone: f32,
    /// Relaxation omega.
    pub omega: f32,
    /// Field evaluations allowed per ray.
    pub max_steps: u32,
    /// Regula-falsi iterations allowed on a sign change.
    pub refine_steps: u32,
    /// Backend max distance (world units).
    pub max_distance: f32,
    /// Scene bounds (render space), if finite.
    pub bounds: Option<(Vec3, Vec3)>,
    /// Switch slowly progressing rays to segment tracing (`Phase::Segment`).
    pub segment: bool,
    /// Sweeps through a prediction's gap take segment steps (`segment`, and the field
    /// answers segment queries eight lanes at a time).
    pub segment_sweeps: bool,
    /// Rays in plain marching whose distance grows ask, every [`RECEDE_EVERY`] evaluations,
    /// whether they can still meet a surface ([`Next::Check`]; the field has a tape).
    pub recede_checks: bool,
}

/// Evaluations between two receding checks of a ray ([`Params::recede_checks`]). A check
/// takes the ray out of the 8-lane fast path for a scalar pass over the tape's leaves, and
/// the checks of a ray still passing objects fail. Measured: `docs/decisions/0013`.
pub(crate) const RECEDE_EVERY: u32 = 8;

/// Whether a ray that has made `evals` evaluations is due a receding check.
#[inline]
pub(crate) fn recede_checkpoint(evals: u32) -> bool {
    evals.is_multiple_of(RECEDE_EVERY)
}

/// Field evaluations one visit to the shell may spend deciding hit or near miss (a visit
/// that runs out ends as a hit unless its closest approach is clear,
/// [`March::passes_clear`]). Measured (24, 48 and 96): `docs/decisions/0013`.
const FINE_BUDGET: u32 = 48;

/// Field evaluations one sweep of a gap before a prediction may spend. A sweep out of
/// budget takes up the prediction, unless its distances still shrink: then a surface in the
/// gap is being closed in on (a sheet crossed at a shallow angle), and the shell logic
/// decides it from the sweep's last two samples.
const SWEEP_BUDGET: u32 = 32;

/// Evaluations a ray spends sphere tracing before slow progress switches it to segment
/// tracing (and the wait after a switch that gained nothing): rays that hit or leave within
/// that many pay nothing for the mechanism, and a segment step (the bounds on top of the
/// distance, then a scalar decision) costs more than a plain 8-lane step. Measured (8, 16 and 32): `docs/decisions/0013`.
pub(crate) const SEGMENT_MIN_EVALS: u32 = 32;

/// Slow progress: a distance staying within this factor of the previous one, shrinking or
/// growing. A ray at angle `theta` to a plane keeps `1 -+ omega sin(theta)` per step (0.979 at
/// 1 degree with omega 1.2), so this engages below about 2.4 degrees, approaching or receding
/// (a ray skimming away from a cylinder's cap used to crawl at steps of its height).
pub(crate) const SEGMENT_RATIO: f32 = 0.95;

/// Evaluations between two switches to segment tracing from the shell (receding samples,
/// [`March::fine`]): a surface without a local bound (the global fallback) gains nothing, and
/// each attempt costs one segment query.
const SHELL_SEGMENT_WAIT: u32 = 8;

/// Each segment is this many times the last step (Galin et al. grow the segment by a
/// constant factor): long enough that a bound valid far ahead lets the step grow
/// geometrically, short enough that bounds of curved surfaces stay tight.
const SEGMENT_GROWTH: f32 = 4.0;

/// A segment step shorter than this many plain steps (`|f|`) gains nothing: marching
/// returns to the 8-lane plain path (or, within `eps` of a surface, to the shell logic).
const SEGMENT_GAIN: f32 = 1.5;

/// A segment longer than this many distances whose bound gains nothing is retried at the
/// same point over [`SEGMENT_RETRY_LEN`] distances.
const SEGMENT_RETRY: f32 = 8.0;

/// The retried segment, in distances: short enough for the bound to be the local one.
const SEGMENT_RETRY_LEN: f32 = 2.0;

/// Steps with a sample below `thr` whose safe step is still above `thr` (approaching a
/// surface at a grazing angle, where `thr` on the field is `thr / sin(theta)` along the ray)
/// before the sample is called a hit anyway.
const SEGMENT_EXTRA: u32 = 8;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// The first evaluation, at the start.
    Start,
    /// Leaving the shell of the surface the ray starts on: hits only below `thr`.
    Escape { thr: f32 },
    /// Plain (or relaxed) marching.
    March,
    /// In the shell: `(ta, sa)` the previous sample, `trial` whether the current point is a
    /// secant prediction.
    Fine {
        ta: f32,
        sa: f32,
        trial: bool,
        left: u32,
    },
    /// Plain steps at `self.t` through the gap before a prediction: the prediction was the
    /// sample `s_land` at `t_land`, made from `(ta, sa)`; `left` as in `Fine`.
    Sweep {
        ta: f32,
        sa: f32,
        t_land: f32,
        s_land: f32,
        left: u32,
        evals: u32,
        /// Steps are safe segment steps over the rest of the gap (`Params::segment_sweeps`),
        /// not plain distances.
        segmented: bool,
    },
    /// Segment tracing: the caller evaluates [`Field::segment_step`] over `len` at the
    /// current point. `extra` counts samples below `thr` stepped past (see
    /// [`SEGMENT_EXTRA`]).
    ///
    /// [`Field::segment_step`]: marchmesh_field::Field::segment_step
    Segment { len: f32, extra: u32 },
    /// A crossing between `lo` (outside) and `hi` (inside); `side` for Illinois.
    Bracket {
        lo: f32,
        slo: f32,
        hi: f32,
        shi: f32,
        side: i8,
        left: u32,
    },
}

/// What [`March::feed`] decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Next {
    /// Evaluate the field at [`March::point`] again.
    Continue,
    /// Finished with this termination (`Hit`: the hit is at [`March::t`]).
    Done(Termination),
    /// Ask the field whether the ray, from [`March::check_point`] along [`March::dir`], can
    /// still meet a surface: if not, end it with [`March::receded`], else evaluate at
    /// [`March::point`] as for `Continue`.
    Check,
}

/// One ray being traced.
#[derive(Debug, Clone, Copy)]
pub(crate) struct March {
    o: Vec3,
    dir: Vec3,
    /// Current distance along the ray.
    pub t: f32,
    t_end: f32,
    t_min: f32,
    end_is_miss: bool,
    base: f32,
    sign: f32,
    omega: f32,
    t_prev: f32,
    r_prev: f32,
    phase: Phase,
    /// Field evaluations so far.
    pub evals: u32,
    /// Slow progress switches to segment tracing from this many evaluations on
    /// ([`SEGMENT_MIN_EVALS`], pushed back each time segment tracing gained nothing).
    seg_from: u32,
    /// Closest hit (find the crossing) or occlusion (any crossing will do).
    refine: bool,
    /// The start [`March::advance_start`] moved the ray from (NaN when it did not): the
    /// first sample falls back to it if the advanced start is not clear of every surface.
    t_restart: f32,
    /// Evaluations made for this ray and others together (its beam's), reported in its work
    /// but not counted against its budget.
    shared_evals: u32,
    /// The current visit to the shell began (or its budget was last renewed) at this ray
    /// parameter, with this distance and this approach slope (`-dd/dt`): what
    /// [`March::passes_clear`] fits the visit's closest approach to.
    shell_t: f32,
    shell_s: f32,
    shell_k: f32,
}

impl March {
    /// Starts a ray; `Err` when it cannot reach the scene's bounds (no evaluation needed).
    pub fn new(ray: &Ray, p: &Params, refine: bool) -> Result<March, NoHit> {
        let mut t0 = ray.t_min.max(0.0);
        let mut t1 = ray.t_max.min(p.max_distance);
        let mut end_is_miss = false;
        if let Some((lo, hi)) = p.bounds {
            // Slab test against the scene box.
            let inv = ray.dir.recip();
            let a = (lo - ray.origin) * inv;
            let b = (hi - ray.origin) * inv;
            let tn = a.min(b);
            let tf = a.max(b);
            let enter = nan_max(nan_max(tn.x, tn.y), tn.z);
            let exit = nan_min(nan_min(tf.x, tf.y), tf.z);
            if exit < enter || exit < t0 {
                return Err(NoHit::Miss);
            }
            if enter > t1 {
                return Err(NoHit::MaxDistance);
            }
            // Start a little before the box (the field is a bound everywhere anyway).
            t0 = t0.max(enter * 0.999);
            if exit < t1 {
                t1 = exit;
                end_is_miss = true;
            }
        }
        if t1.is_nan() || t1 < t0 {
            return Err(NoHit::MaxDistance);
        }
        Ok(March {
            o: ray.origin,
            dir: ray.dir,
            t: t0,
            t_end: t1,
            t_min: ray.t_min.max(0.0),
            end_is_miss,
            base: ray.origin.length(),
            sign: 1.0,
            omega: p.omega,
            t_prev: t0,
            r_prev: 0.0,
            phase: Phase::Start,
            evals: 0,
            seg_from: SEGMENT_MIN_EVALS,
            refine,
            t_restart: f32::NAN,
            shared_evals: 0,
            shell_t: 0.0,
            shell_s: 0.0,
            shell_k: 0.0,
        })
    }

    /// Moves a ray that has not been evaluated yet to start at `t` (ray parameter) when `t`
    /// lies past its start: the caller vouches that the ray meets no surface before `t` and
    /// stays at least a shell ([`March::eps`]) clear of every surface there (a beam's cone
    /// march, `crate::beam`). A start beyond the ray's end is clamped to the end. If the
    /// first sample there is nonetheless inside the shell (a field that is no strict
    /// bound, such as a mesh grid, let the beam overshoot), the ray restarts from its own
    /// start: the result is then the unadvanced ray's, one evaluation later. `t` NaN or not
    /// past the start changes nothing.
    #[inline]
    pub fn advance_start(&mut self, t: f32) {
        debug_assert!(self.phase == Phase::Start && self.evals == 0);
        if t > self.t {
            self.t_restart = self.t;
            self.t = t.min(self.t_end);
            self.t_prev = self.t;
        }
    }

    /// The plain-marching state when the ray is in the `March` phase (the only state the
    /// lockstep fast path [`Lanes8::step`] changes), else `None`.
    #[inline]
    pub fn plain(&self) -> Option<Plain> {
        (self.phase == Phase::March).then_some(Plain {
            t: self.t,
            t_prev: self.t_prev,
            r_prev: self.r_prev,
            omega: self.omega,
            evals: self.evals,
        })
    }

    /// The state [`Lanes8::step`] starts from when the ray has not been evaluated yet
    /// (`Start` phase), else `None`.
    #[inline]
    pub fn start(&self) -> Option<Plain> {
        (self.phase == Phase::Start).then_some(Plain {
            t: self.t,
            t_prev: self.t_prev,
            r_prev: self.r_prev,
            omega: self.omega,
            evals: self.evals,
        })
    }

    /// Writes back a state taken by [`March::plain`] (or [`March::start`]) and advanced by
    /// [`Lanes8::step`]: the ray is in the `March` phase from then on (a ray that starts
    /// takes the lane's first step there only when it enters `March`).
    #[inline]
    fn set_plain(&mut self, s: Plain) {
        debug_assert!(matches!(self.phase, Phase::March | Phase::Start));
        self.phase = Phase::March;
        self.t = s.t;
        self.t_prev = s.t_prev;
        self.r_prev = s.r_prev;
        self.omega = s.omega;
        self.evals = s.evals;
    }

    /// When the ray is segment tracing: the segment length over which the next sample's
    /// safe step is wanted ([`March::feed_segment`]); `None` when [`March::feed`] wants a
    /// plain distance.
    #[inline]
    pub fn segment_len(&self) -> Option<f32> {
        match self.phase {
            Phase::Segment { len, .. } => Some(len),
            // The rest of the gap, up to the prediction (positive: a sweep ends before it).
            Phase::Sweep {
                t_land,
                segmented: true,
                ..
            } => Some((t_land - self.t).max(f32::MIN_POSITIVE)),
            _ => None,
        }
    }

    /// The point whose distance [`March::feed`] needs next.
    #[inline]
    pub fn point(&self) -> Vec3 {
        self.o + self.dir * self.t
    }

    /// The ray direction.
    #[inline]
    pub fn dir(&self) -> Vec3 {
        self.dir
    }

    /// The point a receding check ([`Next::Check`]) asks from: the last sample, whose
    /// unbounding sphere is verified (the step taken from it may be a relaxed one that the
    /// next sample has yet to check, and may have jumped a thin surface).
    #[inline]
    pub fn check_point(&self) -> Vec3 {
        self.o + self.dir * self.t_prev
    }

    /// Ends a ray the field found receding from every surface after [`Next::Check`]: the
    /// termination it would reach at the end of its range (`Miss` at the scene box,
    /// `MaxDistance` otherwise). The check is reported as one evaluation of its work.
    #[inline]
    pub fn receded(&mut self) -> Termination {
        self.shared_evals += 1;
        match self.end() {
            Next::Done(t) => t,
            Next::Continue | Next::Check => unreachable!("end() is always Done"),
        }
    }

    /// Charges `evals` shared evaluations (a beam's) to this ray's reported work.
    #[inline]
    pub fn charge_shared(&mut self, evals: u32) {
        self.shared_evals += evals;
    }

    /// Field evaluations to report for this ray: its own and those charged to it.
    #[inline]
    pub fn work_steps(&self) -> u32 {
        self.evals + self.shared_evals
    }

    /// The ray origin.
    #[inline]
    pub fn origin(&self) -> Vec3 {
        self.o
    }

    /// `(t, t_end)`: where the ray is now and where its range ends (ray parameter).
    #[inline]
    pub fn range(&self) -> (f32, f32) {
        (self.t, self.t_end)
    }

    /// Distance from the camera along the path so far (for footprints).
    #[inline]
    pub fn path_length(&self) -> f32 {
        self.base + self.t
    }

    /// The shell epsilon, never below f32 resolution of positions here (a smaller one could
    /// never be reached and would exhaust the steps).
    #[inline]
    fn eps(&self, p: &Params) -> f32 {
        (p.eps_abs + p.eps_cone * (self.base + self.t)).max(4.0 * self.noise())
    }

    /// Rounding level of field values near the current point: two f32 ulps of the
    /// position's magnitude (2 * 2^-23 relative), which bounds the error of `p - c` in every
    /// primitive. (It was 1e-6: 8x larger, which at 1e5 units from the camera made the shell
    /// wider than the pixel footprint of a narrow camera and inflated silhouettes by
    /// several pixels; see the stability study's `distance` family.)
    #[inline]
    fn noise(&self) -> f32 {
        2.4e-7 * (self.base + self.t)
    }

    /// The fine threshold: 1e-3 of the shell, but never below f32 resolution of positions.
    #[inline]
    fn thr(&self, p: &Params) -> f32 {
        (self.eps(p) * 1e-3).max(self.noise())
    }

    #[inline]
    fn end(&self) -> Next {
        Next::Done(if self.end_is_miss {
            Termination::Miss
        } else {
            Termination::MaxDistance
        })
    }

    #[inline]
    fn budget(&self, p: &Params) -> Next {
        if self.evals >= p.max_steps {
            Next::Done(Termination::MaxSteps)
        } else if self.t > self.t_end {
            self.end()
        } else {
            Next::Continue
        }
    }

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
        self.t = t + s.max(0.5 * eps);
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

#[inline]
fn nan_max(a: f32, b: f32) -> f32 {
    if a > b || b.is_nan() { a } else { b }
}

#[inline]
fn nan_min(a: f32, b: f32) -> f32 {
    if a < b || b.is_nan() { a } else { b }
}

/// The part of a ray's state that plain marching changes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Plain {
    t: f32,
    t_prev: f32,
    r_prev: f32,
    omega: f32,
    evals: u32,
}

/// Eight rays marched in lockstep, structure of arrays. The common case, a step of plain
/// (relaxed) marching that enters no shell, leaves no range and exhausts no budget (or a
/// ray's first sample that is such a step into `March`), and the undoing of a relaxed step
/// whose sphere does not cover the gap, runs on all lanes at once in [`Lanes8::step`] with
/// exactly the
/// arithmetic of [`March::feed`]'s `March` phase in 8-lane vector operations (so results
/// are bit for bit those of single rays); a lane that needs any other decision, or is in
/// another phase, is handed to its scalar [`March`] for that step.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Lanes8 {
    o: V3<F32x8>,
    dir: V3<F32x8>,
    base: F32x8,
    sign: F32x8,
    t_end: F32x8,
    t: F32x8,
    t_prev: F32x8,
    r_prev: F32x8,
    omega: F32x8,
    evals: [u32; 8],
    seg_from: [u32; 8],
    /// Lane holds a ray in the `March` phase whose plain state lives here (all ones).
    fast: M8,
    /// Lane holds a ray in the `Start` phase whose state lives here (all ones): its first
    /// sample, when it is a plain step into `March`, is taken here too.
    start: M8,
    /// Lane holds a ray that entered the shell approaching the surface in [`Lanes8::step`]
    /// and waits for its secant prediction's sample at `t` (all ones): its `March` is in
    /// `Fine { ta: t_prev, sa: r_prev, trial: true, left: FINE_BUDGET - 1 }`, its shell
    /// visit began at `(t_prev, r_prev)` with approach slope `shell_k`, once
    /// [`Lanes8::store`] has written that back.
    fine: M8,
    /// Per lane the approach slope of a `fine` lane's shell entry.
    shell_k: F32x8,
    /// Per lane the segment its ray's next sample wants ([`March::segment_len`]; 0 when
    /// the ray is not segment tracing).
    seg_len: F32x8,
    /// Bit `k`: lane `k`'s ray is segment tracing.
    segmenting: u8,
}

impl Lanes8 {
    /// Lane `k` now traces `m` (or, after [`March::feed`] returned `Continue`, continues
    /// it): takes its constants and current state.
    #[inline]
    pub fn load(&mut self, k: usize, m: &March) {
        self.o.x.0[k] = m.o.x;
        self.o.y.0[k] = m.o.y;
        self.o.z.0[k] = m.o.z;
        self.dir.x.0[k] = m.dir.x;
        self.dir.y.0[k] = m.dir.y;
        self.dir.z.0[k] = m.dir.z;
        self.base.0[k] = m.base;
        self.sign.0[k] = m.sign;
        self.t_end.0[k] = m.t_end;
        self.t.0[k] = m.t;
        let seg = m.segment_len();
        self.seg_len.0[k] = seg.unwrap_or(0.0);
        self.segmenting = (self.segmenting & !(1 << k)) | (u8::from(seg.is_some()) << k);
        let (plain, start) = (m.plain(), m.start());
        self.fast.0[k] = if plain.is_some() { !0 } else { 0 };
        self.start.0[k] = if start.is_some() { !0 } else { 0 };
        self.fine.0[k] = 0;
        if let Some(s) = plain.or(start) {
            self.t_prev.0[k] = s.t_prev;
            self.r_prev.0[k] = s.r_prev;
            self.omega.0[k] = s.omega;
            self.evals[k] = s.evals;
            self.seg_from[k] = m.seg_from;
        }
    }

    /// Lane `k` now traces `m` ([`Lanes8::load`]), or with `None` is empty: it keeps
    /// evaluating its last point (finite) and is never handed to a scalar step again.
    #[inline]
    pub fn seat(&mut self, k: usize, m: Option<&March>) {
        match m {
            Some(m) => self.load(k, m),
            None => {
                self.fast.0[k] = 0;
                self.start.0[k] = 0;
                self.fine.0[k] = 0;
                self.segmenting &= !(1 << k);
            }
        }
    }

    /// Writes lane `k`'s plain state back into its ray before a scalar step.
    #[inline]
    pub fn store(&self, k: usize, m: &mut March) {
        if self.fast.0[k] != 0 {
            m.set_plain(Plain {
                t: self.t.0[k],
                t_prev: self.t_prev.0[k],
                r_prev: self.r_prev.0[k],
                omega: self.omega.0[k],
                evals: self.evals[k],
            });
        } else if self.fine.0[k] != 0 {
            // What `March::enter_shell` leaves when it predicts (see `Lanes8::step`). A ray
            // whose first sample the lanes took still says `Start` here (as for `set_plain`).
            debug_assert!(matches!(m.phase, Phase::March | Phase::Start));
            let (ta, sa) = (self.t_prev.0[k], self.r_prev.0[k]);
            m.t = self.t.0[k];
            m.t_prev = ta;
            m.r_prev = sa;
            m.omega = self.omega.0[k];
            m.evals = self.evals[k];
            m.shell_t = ta;
            m.shell_s = sa;
            m.shell_k = self.shell_k.0[k];
            m.phase = Phase::Fine {
                ta,
                sa,
                trial: true,
                left: FINE_BUDGET - 1,
            };
        }
    }

    /// Bit `k`: lane `k`'s ray is segment tracing (its next sample is a
    /// `Field::segment_step` over [`Lanes8::segment_lens`]).
    #[inline]
    pub fn segmenting(&self) -> u8 {
        self.segmenting
    }

    /// Per lane the segment length a segment-tracing ray's next sample wants (0 on other
    /// lanes).
    #[inline]
    pub fn segment_lens(&self) -> F32x8 {
        self.seg_len
    }

    /// The eight ray directions (as [`March::dir`]).
    #[inline]
    pub fn dirs(&self) -> V3<F32x8> {
        self.dir
    }

    /// The eight points to evaluate (`o + dir * t`, as [`March::point`]).
    #[inline]
    pub fn points(&self) -> V3<F32x8> {
        V3::new(
            self.o.x + self.dir.x * self.t,
            self.o.y + self.dir.y * self.t,
            self.o.z + self.dir.z * self.t,
        )
    }

    /// Consumes the distances `d` at [`Lanes8::points`]: advances every fast lane whose
    /// step is plain and returns the mask (bit `k`) of the lanes that did not advance (not
    /// fast, or needing a decision): the caller feeds those to their [`March`].
    #[inline]
    pub fn step(&mut self, d: F32x8, p: &Params) -> u8 {
        // The `March` arm of `March::feed`, then `step_from` and `budget`, with the same
        // expressions: `eps`, `noise` and `thr` as their methods compute them.
        let c = F32x8::splat;
        let t = self.t;
        let s = d * self.sign;
        let r = s.abs();
        let path = self.base + t;
        let noise = c(2.4e-7) * path;
        let eps = (c(p.eps_abs) + c(p.eps_cone) * path).max(c(4.0) * noise);
        let thr = (eps * c(1e-3)).max(noise);
        let undo = F32x8::and(
            F32x8::lt(c(1.0), self.omega),
            F32x8::lt(r + self.r_prev, (t - self.t_prev) + thr),
        );
        // Lanes whose progress is slow switch to segment tracing in their scalar `March`
        // (`March::slow`): they leave the fast path like an exhausted budget does.
        let slow_progress = F32x8::and(
            F32x8::lt(s * c(SEGMENT_RATIO), self.r_prev),
            F32x8::lt(self.r_prev * c(SEGMENT_RATIO), s),
        );
        // Branch-free per lane (all-ones masks), so the loop vectorises: the same decision as
        // `evals + 1 < max_steps && !(segment && evals + 1 >= seg_from && slow_progress)`.
        let mask = |b: bool| 0u32.wrapping_sub(u32::from(b));
        let segment_on = mask(p.segment);
        // Lanes due a receding check (`March::feed_with`'s `March` arm) leave too.
        let receding = F32x8::lt(self.r_prev, s);
        let check_on = mask(p.recede_checks);
        let budget = M8(std::array::from_fn(|k| {
            let e = self.evals[k] + 1;
            let segment = segment_on & mask(e >= self.seg_from[k]) & slow_progress.0[k];
            let check = check_on & mask(recede_checkpoint(e)) & receding.0[k];
            mask(e < p.max_steps) & !segment & !check
        }));
        // `eps <= s` is false for NaN too; `t + s <= t_end` is `!(t + s > t_end)` there.
        let go = F32x8::and(
            F32x8::le(eps, s),
            F32x8::and(F32x8::le(t + s, self.t_end), budget),
        );
        let ok = F32x8::and(self.fast, go);
        // A ray's first sample (`Start`): a distance of at least `eps` (so the sign stays +1
        // and the ray does not start on a surface) is a plain step into `March`, with no
        // overlap check owed (`March::feed_with`'s `Start` arm then `step_from`); its
        // `r_prev` is 0, so `budget` holds no segment switch for it.
        let started = F32x8::and(self.start, go);
        let plain = M8(std::array::from_fn(|k| {
            (ok.0[k] & !undo.0[k]) | started.0[k]
        }));
        // The overlap fallback (`March::feed_with`'s first test in `March`, before the shell,
        // segment and receding tests): back to the plain step from the previous sample,
        // relaxation off, then `budget`: the lane stays fast unless that ends the ray.
        let back = self.t_prev + self.r_prev;
        let in_budget = M8(std::array::from_fn(|k| {
            mask(self.evals[k] + 1 < p.max_steps)
        }));
        let undone = F32x8::and(
            F32x8::and(self.fast, undo),
            F32x8::and(in_budget, F32x8::le(back, self.t_end)),
        );
        // Entering the shell (`thr < s < eps`, no undo) while approaching the surface:
        // `March::enter_shell` then `fine` and `fine_clear` jump to the secant prediction
        // (the visit's approach slope is that secant's slope), unless it is out of budget.
        // Crossings, hits and other shell entries stay scalar.
        let slope = (self.r_prev - s) / (t - self.t_prev);
        let approach = F32x8::and(
            F32x8::and(F32x8::lt(thr, s), F32x8::lt(s, eps)),
            F32x8::and(F32x8::lt(self.t_prev, t), F32x8::lt(c(0.01), slope)),
        );
        let entered = M8(std::array::from_fn(|k| {
            self.fast.0[k] & !undo.0[k] & approach.0[k] & in_budget.0[k]
        }));
        let predicted = (t + s / slope).min(self.t_end);
        self.fast = M8(std::array::from_fn(|k| {
            (self.fast.0[k] | started.0[k]) & !entered.0[k]
        }));
        self.start = M8(std::array::from_fn(|k| self.start.0[k] & !started.0[k]));
        self.fine = F32x8::or(self.fine, entered);
        self.shell_k = F32x8::select(entered, slope, self.shell_k);
        let stepped = (t + s * self.omega).min(self.t_end);
        let accepted = F32x8::or(plain, entered);
        self.t_prev = F32x8::select(accepted, t, self.t_prev);
        self.r_prev = F32x8::select(accepted, s, self.r_prev);
        let moved_t = F32x8::select(entered, predicted, F32x8::select(undone, back, t));
        self.t = F32x8::select(plain, stepped, moved_t);
        self.omega = F32x8::select(undone, c(1.0), self.omega);
        let mut slow = 0u8;
        for k in 0..8 {
            let moved = plain.0[k] | undone.0[k] | entered.0[k];
            self.evals[k] += moved & 1;
            slow |= u8::from(moved == 0) << k;
        }
        slow
    }
}
