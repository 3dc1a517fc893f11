//! `bench::run` on a tiny suite: configurations of one scene are timed in shared rounds, and
//! an image that cannot be written is reported, not ignored.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use marchmesh_harness::bench::{self, BenchOptions, Silent};
use marchmesh_harness::suite;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn one_scene_is_timed_in_shared_rounds_and_failed_image_writes_are_reported() {
    let dir = std::env::temp_dir().join(format!("marchmesh-bench-run-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(repo().join("scenes/csg.json"), dir.join("csg.json")).unwrap();
    std::fs::write(
        dir.join("suite.json"),
        r#"{"repeats": {"min_count": 3, "min_time_s": 0, "max_count": 3},
            "groups": [{"name": "g", "scenes": ["csg.json"], "resolutions": [{"max_side": 12}],
              "threads": [1], "spp": 1,
              "backends": [{"backend": "sdf"}, {"backend": "mesh"}]}]}"#,
    )
    .unwrap();
    let suite = suite::load(&dir.join("suite.json")).unwrap();
    // The images "folder" is a regular file: every image write fails.
    let not_a_folder = dir.join("images");
    std::fs::write(&not_a_folder, b"x").unwrap();
    let options = BenchOptions {
        images_dir: Some(not_a_folder),
        seed: 11,
        ..BenchOptions::default()
    };
    let configs = bench::configurations(&suite, &options);
    assert_eq!(configs.len(), 2);
    let out = bench::run(&configs, &options, &mut Silent, &AtomicBool::new(false));
    assert!(out.failures.is_empty(), "{:?}", out.failures);
    assert_eq!(out.rows.len(), 2);
    assert!(out.missing.is_empty());
    // Both configurations took part in rounds 0, 1, 2 (one render each per round).
    for c in &configs {
        let rounds: Vec<u32> = out.timings[&c.id].iter().map(|s| s.round).collect();
        assert_eq!(rounds, [0, 1, 2], "{}", c.id);
        assert!(
            out.timings[&c.id]
                .iter()
                .all(|s| s.wall_ms > 0.0 && s.cpu_ms.is_some())
        );
    }
    for r in &out.rows {
        assert_eq!(r.render_repeats, 3);
        assert!(r.render_cpu_ms_median.is_some() && r.mrays_per_cpu_s.is_some());
    }
    assert_eq!(out.rotation_seed, 11);
    // Reference PNG + a PNG and a diff per configuration: five failed writes, each named.
    assert_eq!(out.write_errors.len(), 5, "{:?}", out.write_errors);
    assert!(out.write_errors.iter().all(|e| e.contains("images")));
    std::fs::remove_dir_all(&dir).ok();
}
