//! The counting allocator installed as the global allocator: a known allocation pattern
//! gives the known peak. One test only, so no other test thread allocates meanwhile.

use std::hint::black_box;

use marchmesh_harness::alloc::{self, CountingAlloc, HeapPhase};

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

const MIB: usize = 1 << 20;
/// Slack for the test harness's own allocations racing with ours.
const SLACK: u64 = 64 * 1024;

fn near(got: Option<u64>, want: usize) {
    let got = got.expect("allocator installed");
    assert!(
        got >= want as u64 && got <= want as u64 + SLACK,
        "peak {got} bytes, expected {want} (+ at most {SLACK})"
    );
}

#[test]
fn known_pattern_gives_known_peak() {
    let _warm = black_box(vec![1u8; 16]);
    assert!(alloc::is_installed());

    // 3 MiB + 1 MiB live together, then 3 MiB freed and 2 MiB allocated: peak 4 MiB.
    let phase = HeapPhase::start();
    let a = black_box(vec![1u8; 3 * MIB]);
    let b = black_box(vec![2u8; MIB]);
    drop(a);
    let c = black_box(vec![3u8; 2 * MIB]);
    near(phase.finish(), 4 * MIB);

    // A new phase starts from the live 3 MiB. A 1 MiB vector grown by realloc to 5 MiB:
    // a realloc counts as its size difference, so the phase peaks 5 MiB above its start.
    let phase = HeapPhase::start();
    let before = alloc::current_bytes();
    let mut d: Vec<u8> = Vec::with_capacity(MIB);
    d.resize(MIB, 7);
    d.reserve_exact(4 * MIB); // capacity 5 MiB
    black_box(&d);
    near(phase.finish(), 5 * MIB);
    assert!(alloc::current_bytes() >= before + 5 * MIB);

    // Freed memory lowers the current count, not the peak of the phase.
    let peak = alloc::peak_bytes();
    drop((b, c, d));
    assert!(alloc::current_bytes() + 8 * MIB <= peak + SLACK as usize);
    assert_eq!(alloc::peak_bytes(), peak);
    // A phase that allocates nothing has a peak of (almost) nothing.
    let phase = HeapPhase::start();
    near(phase.finish(), 0);
}
