//! The per-ray sphere-tracing state machine. It never evaluates the field itself: it names
//! the point it needs ([`March::point`]) and consumes the distance there ([`March::feed`]), so
//! single rays and 8-ray lockstep batches run exactly the same logic.

use glam::Vec3;
use marchmesh_core::{Ray, Termination};

/// Per-ray constants shared by every ray of a geometry.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Params {
    /// Absolute epsilon part (world units).
    pub eps_abs: f32,
    /// Cone epsilon per unit distance from the camera.
    pub eps_cone: f32,
    /// Relaxation omega.
    pub omega: f32,
    /// Marching steps allowed.
    pub max_steps: u32,
    /// Refinement steps after a hit.
    pub refine_steps: u32,
    /// Backend max distance (world units).
    pub max_distance: f32,
    /// Scene bounds (render space), if finite.
    pub bounds: Option<(Vec3, Vec3)>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// The first evaluation, at `t_min`.
    Start,
    /// Leaving the epsilon shell of the surface the ray starts on: hits only below `thr`.
    Escape { thr: f32 },
    /// Plain (or relaxed) marching.
    March,
    /// Moving a found hit onto the surface by secant steps along the ray: `(ta, da)` and
    /// `(tb, db)` are the last two accepted samples (signed, ray-side positive), `best` the
    /// accepted sample closest to the surface.
    Refine {
        left: u32,
        ta: f32,
        da: f32,
        tb: f32,
        db: f32,
        best_t: f32,
        best_d: f32,
    },
}

/// What [`March::feed`] decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Next {
    /// Evaluate the field at [`March::point`] again.
    Continue,
    /// Finished with this termination (`Hit`: the hit is at [`March::t`]).
    Done(Termination),
}

/// One ray being traced.
#[derive(Debug, Clone, Copy)]
pub(crate) struct March {
    o: Vec3,
    dir: Vec3,
    /// Current distance along the ray.
    pub t: f32,
    t_end: f32,
    end_is_miss: bool,
    base: f32,
    sign: f32,
    omega: f32,
    t_prev: f32,
    r_prev: f32,
    phase: Phase,
    /// Marching evaluations so far (what `max_steps` limits).
    pub steps: u32,
    /// Every field evaluation fed, refinement included.
    pub evals: u32,
    /// Closest hit (refine) or occlusion (no refine).
    refine: bool,
}

impl March {
    /// Starts a ray; `None` when it cannot reach the scene's bounds (a miss with 0 steps).
    pub fn new(ray: &Ray, p: &Params, refine: bool) -> Result<March, Termination> {
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
                return Err(Termination::Miss);
            }
            if enter > t1 {
                return Err(if t1 < ray.t_max.min(p.max_distance) {
                    Termination::Miss
                } else {
                    Termination::MaxDistance
                });
            }
            // Start a little before the box (the field is a bound everywhere anyway).
            t0 = t0.max(enter * 0.999);
            if exit < t1 {
                t1 = exit;
                end_is_miss = true;
            }
        }
        if t1.is_nan() || t1 < t0 {
            return Err(Termination::MaxDistance);
        }
        Ok(March {
            o: ray.origin,
            dir: ray.dir,
            t: t0,
            t_end: t1,
            end_is_miss,
            base: ray.origin.length(),
            sign: 1.0,
            omega: p.omega,
            t_prev: t0,
            r_prev: 0.0,
            phase: Phase::Start,
            steps: 0,
            evals: 0,
            refine,
        })
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

    /// Distance from the camera along the path so far (for footprints).
    #[inline]
    pub fn path_length(&self) -> f32 {
        self.base + self.t
    }

    #[inline]
    fn eps(&self, p: &Params) -> f32 {
        p.eps_abs + p.eps_cone * (self.base + self.t)
    }

    #[inline]
    fn end(&self) -> Next {
        Next::Done(if self.end_is_miss {
            Termination::Miss
        } else {
            Termination::MaxDistance
        })
    }

    /// A hit at the current point with signed value `s`; the previous accepted sample is
    /// `(t_prev, r_prev)`.
    #[inline]
    fn hit_found(&mut self, s: f32, p: &Params) -> Next {
        if !(self.refine && p.refine_steps > 0) {
            return Next::Done(Termination::Hit);
        }
        let (ta, da, tb, db) = (self.t_prev, self.r_prev, self.t, s);
        self.phase = Phase::Refine {
            left: p.refine_steps,
            ta,
            da,
            tb,
            db,
            best_t: tb,
            best_d: db.abs(),
        };
        self.t = Self::secant(ta, da, tb, db);
        Next::Continue
    }

    /// Root of the line through `(ta, da)`, `(tb, db)`, or a plain step when the samples do
    /// not approach the surface.
    #[inline]
    fn secant(ta: f32, da: f32, tb: f32, db: f32) -> f32 {
        let slope = (da - db) / (tb - ta);
        if tb > ta && slope > 1e-3 {
            tb + db / slope
        } else {
            tb + db
        }
    }

    /// Consumes the field value `d` at [`March::point`].
    #[inline]
    pub fn feed(&mut self, d: f32, p: &Params) -> Next {
        self.evals += 1;
        if d.is_nan() {
            return Next::Done(Termination::Miss);
        }
        if let Phase::Refine {
            left,
            ta,
            da,
            tb,
            db,
            mut best_t,
            mut best_d,
        } = self.phase
        {
            // Secant steps onto the surface, not counted against max_steps. The ray is
            // already within `eps` of a surface, so anything a secant step could jump over
            // lies within `eps` of it too: the same merging the hit epsilon accepts. A step
            // that lands outside without getting closer (a silhouette ray passing by) is
            // rejected and the hit stays where the shell was entered; one landing inside
            // brackets the surface and the next secant interpolates.
            let ts = self.t;
            let ds = d * self.sign;
            let progress = ds < 0.0 || ds < db.abs();
            if !progress {
                // Fall back to a plain (safe) step from the best sample.
                if left <= 1 {
                    self.t = best_t;
                    return Next::Done(Termination::Hit);
                }
                self.phase = Phase::Refine {
                    left: left - 1,
                    ta,
                    da,
                    tb,
                    db,
                    best_t,
                    best_d,
                };
                self.t = best_t + best_d;
                return Next::Continue;
            }
            if ds.abs() < best_d {
                best_t = ts;
                best_d = ds.abs();
            }
            if ds.abs() <= self.eps(p) * 1e-4 || left <= 1 {
                self.t = best_t;
                return Next::Done(Termination::Hit);
            }
            self.phase = Phase::Refine {
                left: left - 1,
                ta: tb,
                da: db,
                tb: ts,
                db: ds,
                best_t,
                best_d,
            };
            self.t = Self::secant(tb, db, ts, ds);
            return Next::Continue;
        }
        self.steps += 1;
        let eps = self.eps(p);
        match self.phase {
            Phase::Start => {
                // Start inside a solid: march to its exit surface with the sign flipped.
                self.sign = if d < 0.0 { -1.0 } else { 1.0 };
                let s = d * self.sign;
                if s < eps {
                    // The ray starts on a surface (secondary rays): leave its epsilon
                    // shell first, stepping by the (safe) distance; only a distance below
                    // half the starting clearance (another surface closing in) is a hit.
                    self.phase = Phase::Escape { thr: s * 0.5 };
                } else {
                    self.phase = Phase::March;
                }
                self.t_prev = self.t;
                self.r_prev = s;
                self.advance(s, p)
            }
            Phase::Escape { thr } => {
                let s = d * self.sign;
                if s < thr {
                    return self.hit_found(s, p);
                }
                if s >= eps {
                    self.phase = Phase::March;
                }
                self.t_prev = self.t;
                self.r_prev = s;
                self.advance(s, p)
            }
            Phase::March => {
                let s = d * self.sign;
                let r = s.abs();
                let step = self.t - self.t_prev;
                if self.omega > 1.0 && r + self.r_prev < step {
                    // The relaxed step left the previous unbounding sphere uncovered: undo it,
                    // take the plain step, and stop relaxing (Keinert et al. 2014).
                    self.omega = 1.0;
                    self.t = self.t_prev + self.r_prev;
                    return self.check_budget(p);
                }
                if s < eps {
                    return self.hit_found(s, p);
                }
                self.t_prev = self.t;
                self.r_prev = s;
                self.advance(s, p)
            }
            Phase::Refine { .. } => unreachable!("handled above"),
        }
    }

    #[inline]
    fn advance(&mut self, s: f32, p: &Params) -> Next {
        let step = if matches!(self.phase, Phase::March) {
            s * self.omega
        } else {
            // Escape: never stall on a zero distance.
            s.max(1e-7 * (self.base + self.t).max(1e-30))
        };
        if self.t + s > self.t_end {
            // Even the plain step leaves the range.
            return self.end();
        }
        // A relaxed step past the end is shortened to the end (and still overlap-checked).
        self.t = (self.t + step).min(self.t_end);
        self.check_budget(p)
    }

    #[inline]
    fn check_budget(&self, p: &Params) -> Next {
        if self.steps >= p.max_steps {
            Next::Done(Termination::MaxSteps)
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
