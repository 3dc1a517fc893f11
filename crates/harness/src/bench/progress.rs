//! Progress of a run: the callbacks a run reports to, and the estimate of the time left.

use super::Outcome;

/// Progress callbacks.
pub trait Progress {
    /// The run starts with `total` configurations.
    fn start(&mut self, total: usize);
    /// Configuration `index` starts.
    fn config(&mut self, index: usize, id: &str);
    /// A phase of the current configuration (`build`, `warm-up`, `repeat 3`, ...).
    fn phase(&mut self, what: &str);
    /// The current configuration finished (measured or failed).
    fn done(&mut self, index: usize);
    /// A message for the user.
    fn note(&mut self, message: &str);
    /// Configuration `index` is this far (0 to 1) through its work: half when it is built and
    /// warmed up, the other half over its timed rounds as its repeat policy is met
    /// ([`RepeatPolicy::progress`](crate::stats::RepeatPolicy::progress));
    /// [`Progress::done`] means 1. The CLI's ETA ([`Eta`]) counts these, so it moves with every
    /// round rather than once per rotation block.
    fn advanced(&mut self, _index: usize, _fraction: f64) {}
    /// Everything measured so far, after each rotation block: the CLI writes it to disk so a
    /// crash or kill loses at most one block.
    fn checkpoint(&mut self, _so_far: &Outcome) {}
}

/// The share of a configuration's work [`Progress::advanced`] reports once it is built and
/// warmed up (the rest is its timed rounds).
pub const PREPARED_FRACTION: f64 = 0.5;

/// The remaining time of a run from how far its configurations are ([`Progress::advanced`]).
/// Preparing a configuration (builds, reference renders, the warm-up: the first
/// [`PREPARED_FRACTION`] of its work) and timing it (the rest) cost differently, so the
/// elapsed times seen at each query are fitted as `a * prepared + b * timed` work (least
/// squares, `a, b >= 0`) and the work left is priced at those rates; with too few queries to
/// tell them apart, at the mean rate so far. Meaningful from the first prepared
/// configuration on.
#[derive(Debug, Clone)]
pub struct Eta {
    fractions: Vec<f64>,
    /// `(elapsed s, prepared work, timed work)` at each query.
    samples: std::cell::RefCell<Vec<(f64, f64, f64)>>,
}

impl Eta {
    /// A run of `total` configurations, none started.
    pub fn new(total: usize) -> Self {
        Self {
            fractions: vec![0.0; total],
            samples: std::cell::RefCell::new(Vec::new()),
        }
    }

    /// Configuration `index` is `fraction` (clamped to 0..=1; never moving back) through its
    /// work.
    pub fn advance(&mut self, index: usize, fraction: f64) {
        if let Some(f) = self.fractions.get_mut(index) {
            *f = f.max(fraction.clamp(0.0, 1.0));
        }
    }

    /// The work done, in configurations (fractional).
    pub fn done(&self) -> f64 {
        self.fractions.iter().sum()
    }

    /// The number of configurations.
    pub fn total(&self) -> usize {
        self.fractions.len()
    }

    /// Prepared and timed work done, in configurations.
    fn split(&self) -> (f64, f64) {
        self.fractions.iter().fold((0.0, 0.0), |(p, t), f| {
            (
                p + f.min(PREPARED_FRACTION),
                t + (f - PREPARED_FRACTION).max(0.0),
            )
        })
    }

    /// Seconds left after `elapsed_s` seconds; `None` before any work is done.
    pub fn remaining_s(&self, elapsed_s: f64) -> Option<f64> {
        let done = self.done();
        if done <= 1e-9 {
            return None;
        }
        let (prepared, timed) = self.split();
        let total = self.total() as f64;
        let (left_p, left_t) = (
            (total * PREPARED_FRACTION - prepared).max(0.0),
            (total * (1.0 - PREPARED_FRACTION) - timed).max(0.0),
        );
        let mean = elapsed_s * (total - done).max(0.0) / done;
        let mut samples = self.samples.borrow_mut();
        // One sample per state of the work: the first query after it moved.
        let moved = samples
            .last()
            .is_none_or(|&(_, p, q)| (p, q) != (prepared, timed));
        if moved && elapsed_s.is_finite() && samples.len() < MAX_ETA_SAMPLES {
            samples.push((elapsed_s, prepared, timed));
        }
        // Normal equations of t = a p + b q.
        let (mut spp, mut spq, mut sqq, mut stp, mut stq) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(t, p, q) in samples.iter() {
            spp += p * p;
            spq += p * q;
            sqq += q * q;
            stp += t * p;
            stq += t * q;
        }
        let det = spp * sqq - spq * spq;
        if samples.len() < 4 || det <= 1e-9 * spp * sqq {
            return Some(mean);
        }
        let a = (stp * sqq - stq * spq) / det;
        let b = (stq * spp - stp * spq) / det;
        if !(a.is_finite() && b.is_finite()) || a < 0.0 || b < 0.0 {
            return Some(mean);
        }
        Some(a * left_p + b * left_t)
    }
}

/// Queries [`Eta`] keeps for its fit (a run's progress bar asks a few times a second).
const MAX_ETA_SAMPLES: usize = 100_000;

/// A progress sink that ignores everything.
#[derive(Debug, Default)]
pub struct Silent;

impl Progress for Silent {
    fn start(&mut self, _: usize) {}
    fn config(&mut self, _: usize, _: &str) {}
    fn phase(&mut self, _: &str) {}
    fn done(&mut self, _: usize) {}
    fn note(&mut self, _: &str) {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::RepeatPolicy;

    /// A simulated run of `blocks` rotation blocks of `per_block` configurations: each built
    /// in 2 s (the block's first also renders its reference, 10 s), then 3 rounds of 1 s per
    /// configuration. Returns (elapsed, estimated remaining, true remaining) at every event.
    fn simulate_eta(blocks: usize, per_block: usize) -> Vec<(f64, f64, f64)> {
        let policy = RepeatPolicy::default();
        let total = blocks * per_block;
        let mut eta = Eta::new(total);
        let mut t = 0.0;
        let mut events = Vec::new();
        for b in 0..blocks {
            for k in 0..per_block {
                t += if k == 0 { 12.0 } else { 2.0 };
                eta.advance(b * per_block + k, PREPARED_FRACTION);
                events.push((t, eta.remaining_s(t)));
            }
            for round in 1..=3u32 {
                for k in 0..per_block {
                    t += 1.0;
                    let timed = policy.progress(round, f64::from(round));
                    eta.advance(
                        b * per_block + k,
                        PREPARED_FRACTION + (1.0 - PREPARED_FRACTION) * timed,
                    );
                    events.push((t, eta.remaining_s(t)));
                }
            }
        }
        events
            .into_iter()
            .map(|(at, est)| (at, est.unwrap_or(f64::NAN), t - at))
            .collect()
    }

    #[test]
    fn the_eta_is_within_30_percent_after_the_first_block() {
        let per_block = 6;
        let events = simulate_eta(8, per_block);
        // The first block's events: its builds, then three rounds.
        let first_block = per_block + 3 * per_block;
        for (at, est, truth) in &events[first_block - 1..events.len() - 1] {
            let err = (est - truth).abs() / truth.max(1.0);
            // Within 30%, or 10 s near the end of the run (where the last block's reference
            // render, priced at the mean preparation rate, is a large share of what is left).
            assert!(
                err <= 0.3 || (est - truth).abs() < 10.0,
                "at {at} s: estimated {est:.0} s left, truly {truth:.0} s"
            );
        }
        // Before any configuration is built there is no estimate (not "eta 0s").
        assert!(Eta::new(3).remaining_s(40.0).is_none());
    }
}
