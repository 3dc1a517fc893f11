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
//!
//! This file holds the machine's state, its set-up and the queries on it; `phases` how
//! each sample moves it between phases; `lanes` the 8-lane lockstep form of plain marching.

use glam::Vec3;
use marchmesh_core::{NoHit, Ray, Termination};

mod lanes;
mod phases;

pub(crate) use lanes::Lanes8;

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

    /// The shell epsilon at the current point ([`March::point`]): before the first sample,
    /// how close to a surface the ray's start counts as starting on it.
    #[inline]
    pub fn shell(&self, p: &Params) -> f32 {
        self.eps(p)
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
