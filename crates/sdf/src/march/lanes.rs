//! Eight rays marched in lockstep as structure of arrays: the plain marching steps in
//! vector operations, every other decision handed to each lane's scalar [`March`].

use marchmesh_field::{F32x8, Lane, M8, V3};

use super::*;

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
