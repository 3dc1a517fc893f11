//! A cheap interval clock for the integrators' per-query geometry times
//! ([`crate::RenderStats::trace_time`]).
//!
//! Every batched geometry query is timed (two clock reads per 64-pixel tile and wavefront).
//! [`std::time::Instant`] reads `clock_gettime` through the vDSO: about 35 ns a read and
//! conversion here, a tenth of a render whose geometry costs nothing. On x86_64 CPUs with an
//! invariant time-stamp counter (CPUID leaf `0x8000_0007`, EDX bit 8: the TSC ticks at one
//! rate in every power state and on every core, Intel SDM vol. 3B, 18.17.1; AMD APM vol. 2,
//! 13.2.4) a read is one `rdtsc` (about 13 ns), and a tick count is converted to nanoseconds
//! with a rate calibrated once per process against [`Instant`]. Elsewhere, or without an
//! invariant TSC, the clock is [`Instant`].

use std::sync::OnceLock;
use std::time::Instant;

/// A start time of [`Clock`], in its own unit (TSC ticks or nanoseconds since an epoch).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Stamp(u64);

/// The interval clock: nanoseconds per TSC tick, or `None` to use [`Instant`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Clock {
    ns_per_tick: Option<f64>,
    /// Epoch of the [`Instant`] fallback's stamps.
    epoch: Instant,
}

static CLOCK: OnceLock<Clock> = OnceLock::new();

impl Clock {
    /// The process's clock, calibrated on first use (about 2 ms, so call it before timing
    /// anything: `render_into` does before its clock starts).
    pub(crate) fn get() -> &'static Clock {
        CLOCK.get_or_init(|| Clock {
            ns_per_tick: tsc::ns_per_tick(),
            epoch: Instant::now(),
        })
    }

    /// The [`Instant`] fallback, whatever the CPU (for tests).
    #[cfg(test)]
    fn fallback() -> Clock {
        Clock {
            ns_per_tick: None,
            epoch: Instant::now(),
        }
    }

    /// The current time.
    #[inline(always)]
    pub(crate) fn now(&self) -> Stamp {
        #[cfg(target_arch = "x86_64")]
        if self.ns_per_tick.is_some() {
            return Stamp(tsc::read());
        }
        Stamp(self.epoch.elapsed().as_nanos() as u64)
    }

    /// Nanoseconds from `start` (a [`Clock::now`] of this clock) to now; 0 if the reads
    /// went backwards (a thread moved between cores whose counters differ).
    #[inline(always)]
    pub(crate) fn elapsed_ns(&self, start: Stamp) -> u64 {
        let end = self.now();
        let d = end.0.saturating_sub(start.0);
        match self.ns_per_tick {
            // Rounded to nearest (`round` is a libm call without SSE4.1).
            Some(scale) => (d as f64 * scale + 0.5) as u64,
            None => d,
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod tsc {
    use std::time::{Duration, Instant};

    /// The time-stamp counter.
    #[inline(always)]
    pub(super) fn read() -> u64 {
        // SAFETY: `rdtsc` exists on every x86_64 CPU and only reads the counter.
        #[allow(unsafe_code)]
        unsafe {
            std::arch::x86_64::_rdtsc()
        }
    }

    /// Nanoseconds per tick of an invariant TSC, measured against [`Instant`] over about
    /// 2 ms; `None` if the CPU reports no invariant TSC or the measurement is implausible.
    pub(super) fn ns_per_tick() -> Option<f64> {
        // SAFETY: `cpuid` exists on every x86_64 CPU and only reads identification data;
        // leaf 0x8000_0007 is read only when the highest extended leaf includes it.
        #[allow(unsafe_code, unused_unsafe)]
        let power = unsafe {
            use std::arch::x86_64::__cpuid;
            (__cpuid(0x8000_0000).eax >= 0x8000_0007).then(|| __cpuid(0x8000_0007).edx)
        };
        if power? & (1 << 8) == 0 {
            return None;
        }
        // Each end reads `Instant` between two counter reads and takes their midpoint, and
        // keeps the narrowest of a few such brackets: an interrupt inside a bracket widens
        // it instead of skewing the rate, and the `Instant` read's own cost (tens of ns,
        // microseconds on a VM without a vDSO clock) cancels. Over 2 ms the rate is then
        // good to about the bracket width / 2 ms.
        let bracket = || {
            (0..5)
                .map(|_| {
                    let a = read();
                    let i = Instant::now();
                    let b = read();
                    (b.wrapping_sub(a), i, a / 2 + b / 2)
                })
                .min_by_key(|&(width, _, _)| width)
        };
        let (w0, i0, t0) = bracket()?;
        while i0.elapsed() < Duration::from_millis(2) {}
        let (w1, i1, t1) = bracket()?;
        let ns = (i1 - i0).as_nanos() as f64;
        let ticks = t1.wrapping_sub(t0) as f64;
        // A counter between 10 MHz and 100 GHz; anything else is not a usable TSC. A bracket
        // wider than 1/2000 of the interval (the machine kept interrupting) is not trusted.
        let scale = ns / ticks;
        let sharp = (w0.max(w1) as f64) < ticks / 2000.0;
        (ticks > 0.0 && sharp && (0.01..=100.0).contains(&scale)).then_some(scale)
    }
}

#[cfg(not(target_arch = "x86_64"))]
mod tsc {
    /// No counter off x86_64: the clock is [`std::time::Instant`].
    pub(super) fn ns_per_tick() -> Option<f64> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    /// Busy-waits `d` by [`Instant`] and returns what `clock` measured and what `Instant` did.
    fn measure(clock: &Clock, d: Duration) -> (u64, u64) {
        let i = Instant::now();
        let s = clock.now();
        while i.elapsed() < d {}
        let ns = clock.elapsed_ns(s);
        (ns, i.elapsed().as_nanos() as u64)
    }

    #[test]
    fn intervals_are_nanoseconds_as_instant_measures_them() {
        for clock in [*Clock::get(), Clock::fallback()] {
            for ms in [1, 20] {
                let want = Duration::from_millis(ms);
                // The busy-wait can be preempted on a loaded machine: the best of a few.
                let err = (0..5)
                    .map(|_| {
                        let (ns, outer) = measure(&clock, want);
                        // Inside the outer interval, up to the calibration's error.
                        let limit = outer as f64 * (1.0 + 1e-3) + 1_000.0;
                        assert!(ns as f64 <= limit, "{ns} ns inside an {outer} ns interval");
                        (ns as f64 - outer as f64).abs() / outer as f64
                    })
                    .fold(f64::INFINITY, f64::min);
                assert!(err < 0.01, "{clock:?}: {ms} ms measured off by {err}");
            }
        }
    }

    #[test]
    fn no_time_is_about_zero() {
        let clock = Clock::get();
        let i = Instant::now();
        let s = clock.now();
        let ns = clock.elapsed_ns(s);
        let outer = i.elapsed().as_nanos() as f64;
        assert!(
            ns as f64 <= outer * (1.0 + 1e-3) + 1_000.0,
            "{ns} ns in {outer} ns"
        );
    }
}
