//! A counting global allocator: current and peak heap bytes, with the peak reset per phase.
//!
//! Install it in a binary with
//! `#[global_allocator] static ALLOC: marchmesh_harness::alloc::CountingAlloc = CountingAlloc;`.
//! Without it the counters stay at zero and [`is_installed`] is false, so callers report
//! `None` rather than a fake zero.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static INSTALLED: AtomicBool = AtomicBool::new(false);

/// Wraps the system allocator and counts live bytes (requested sizes, not allocator slack).
#[derive(Debug, Clone, Copy, Default)]
pub struct CountingAlloc;

#[inline]
fn grow(n: usize) {
    if !INSTALLED.load(Ordering::Relaxed) {
        INSTALLED.store(true, Ordering::Relaxed);
    }
    let now = CURRENT.fetch_add(n, Ordering::Relaxed) + n;
    PEAK.fetch_max(now, Ordering::Relaxed);
}

#[inline]
fn shrink(n: usize) {
    CURRENT.fetch_sub(n, Ordering::Relaxed);
}

// SAFETY: every call is forwarded unchanged to `System`; only counters are updated.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            grow(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            grow(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) };
        shrink(layout.size());
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            if new_size >= layout.size() {
                grow(new_size - layout.size());
            } else {
                shrink(layout.size() - new_size);
            }
        }
        p
    }
}

/// Whether a [`CountingAlloc`] is the global allocator of this process (it has counted at
/// least one allocation).
pub fn is_installed() -> bool {
    INSTALLED.load(Ordering::Relaxed)
}

/// Live heap bytes now (0 when not installed).
pub fn current_bytes() -> usize {
    CURRENT.load(Ordering::Relaxed)
}

/// Largest live heap bytes since the last [`reset_peak`] (or process start).
pub fn peak_bytes() -> usize {
    PEAK.load(Ordering::Relaxed)
}

/// Starts a new phase: the peak becomes the current live bytes. Returns that value.
pub fn reset_peak() -> usize {
    let now = CURRENT.load(Ordering::Relaxed);
    PEAK.store(now, Ordering::Relaxed);
    // An allocation racing with the store may have raised CURRENT above PEAK.
    PEAK.fetch_max(CURRENT.load(Ordering::Relaxed), Ordering::Relaxed);
    now
}

/// A phase of heap measurement: [`HeapPhase::start`] resets the peak, [`HeapPhase::finish`]
/// returns how far the heap rose above its level at the start.
#[derive(Debug, Clone, Copy)]
pub struct HeapPhase {
    start: usize,
}

impl HeapPhase {
    /// Resets the peak and remembers the live bytes now.
    pub fn start() -> Self {
        Self {
            start: reset_peak(),
        }
    }

    /// Peak live bytes during the phase minus live bytes at its start; `None` when the
    /// counting allocator is not installed.
    pub fn finish(self) -> Option<u64> {
        is_installed().then(|| peak_bytes().saturating_sub(self.start) as u64)
    }
}
