//! Process CPU time accounting, alone in its test binary so no other test's threads run
//! while the process clock is read.

#[test]
fn process_cpu_time_counts_every_thread_of_a_known_busy_loop() {
    // Two threads each burn 150 ms of their own CPU time (measured by their thread
    // clocks, so a busy machine only stretches the wall time); the process clock must
    // account for both, and for little more.
    let burn = || {
        let t = cpu_time::ThreadTime::now();
        let mut x = 0u64;
        while t.elapsed().as_secs_f64() < 0.15 {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
        }
        (x, t.elapsed().as_secs_f64() * 1e3)
    };
    let (threads_ms, cpu_ms) = marchmesh_harness::bench::with_process_cpu_ms(|| {
        std::thread::scope(|s| {
            let a = s.spawn(burn);
            let b = s.spawn(burn);
            [a, b]
                .into_iter()
                .map(|h| h.join().map_or(0.0, |r| r.1))
                .sum::<f64>()
        })
    });
    let cpu_ms = cpu_ms.expect("process CPU time on Linux");
    assert!(threads_ms >= 300.0, "{threads_ms}");
    assert!(cpu_ms >= threads_ms - 1.0, "{cpu_ms} < {threads_ms}");
    assert!(cpu_ms <= threads_ms + 60.0, "{cpu_ms} >> {threads_ms}");
}
