//! The interactive speed target of issue 19: milliseconds per coarse frame (the frame drawn
//! while the camera moves) of a scene on each backend, at the scene's window size.
//!
//! ```sh
//! cargo run --release -p marchmesh-viewer --example coarse_frame -- [SCENE] [THREADS] [FRAMES]
//! ```
//!
//! Defaults: `scenes/seed-spheres.json`, 2 threads, 30 frames per backend. Each frame moves
//! the camera one step forward or back (alternating), so it is a real moving frame: coarse
//! resolution, traced through the build of the first frame. Prints the median and the 10th
//! and 90th percentiles of the frame time, the median process CPU time per frame (all
//! threads), and the load average before and after (a busy machine slows wall time).

use std::path::PathBuf;
use std::time::Instant;

use marchmesh_registry::BackendId;
use marchmesh_viewer::{Event, Key, Session, SessionOptions};

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".into())
}

fn cpu_ms() -> f64 {
    // user + system time of this process from /proc/self/stat, in clock ticks of 10 ms.
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| {
            let after = s.rsplit_once(')')?.1.split_whitespace().collect::<Vec<_>>();
            let user: f64 = after.get(11)?.parse().ok()?;
            let system: f64 = after.get(12)?.parse().ok()?;
            Some((user + system) * 10.0)
        })
        .unwrap_or(f64::NAN)
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let scene = args.next().map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/seed-spheres.json"),
        PathBuf::from,
    );
    let threads: usize = args.next().map_or(Ok(2), |a| a.parse())?;
    let frames: usize = args.next().map_or(Ok(30), |a| a.parse())?;
    println!(
        "scene {} threads {threads}, load average before: {}",
        scene.display(),
        load_average()
    );
    for kind in BackendId::ALL.into_iter().filter(|k| !k.is_ground_truth()) {
        let mut opts = SessionOptions::new(&scene);
        opts.backend = kind;
        opts.threads = threads;
        let mut session = Session::open(&opts)?;
        let (w, h) = session.window_size();
        let mut wall = Vec::new();
        let mut render = Vec::new();
        let cpu0 = cpu_ms();
        let t0 = Instant::now();
        for i in 0..frames {
            session.apply(&Event::Key(if i % 2 == 0 { Key::W } else { Key::S }));
            let frame = session.render_frame()?;
            assert_eq!(frame.state.refine, 0, "a moving frame is coarse");
            wall.push(frame.frame_ms);
            render.push(frame.views[0].render_ms);
        }
        let elapsed_ms = t0.elapsed().as_secs_f64() * 1e3;
        let cpu_per_frame = (cpu_ms() - cpu0) / frames as f64;
        println!(
            "{kind}: window {w}x{h}, coarse {}x{}: frame median {:.1} ms (p10 {:.1}, p90 {:.1}), render median {:.1} ms, CPU {:.1} ms/frame, {:.1} frames/s",
            w.div_ceil(4),
            h.div_ceil(4),
            percentile(&mut wall, 0.5),
            percentile(&mut wall, 0.1),
            percentile(&mut wall, 0.9),
            percentile(&mut render, 0.5),
            cpu_per_frame,
            frames as f64 / (elapsed_ms / 1e3)
        );
    }
    println!("load average after: {}", load_average());
    Ok(())
}
