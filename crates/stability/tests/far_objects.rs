//! The `distance` families at 1e6 units, on- and off-axis, are exact on both f32 backends:
//! the far sphere is traced in a frame of its own (`marchmesh_core::FarFrame`). In render
//! space the sdf backend lost 16% of the silhouette's pixels there and the mesh backend
//! cracked between triangles.

use std::path::PathBuf;

use marchmesh_stability::{CaseContext, RunOptions, Verdict, all_cases, run_case};

#[test]
fn the_distance_families_are_exact_on_every_backend_at_a_million_units() {
    let dir = std::env::temp_dir().join(format!("marchmesh-stability-far-{}", std::process::id()));
    let ctx = CaseContext {
        generated_dir: dir.clone(),
        scenes_dir: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes"),
        include_large: false,
    };
    let cases = all_cases(&ctx).expect("cases");
    let wanted = [
        "distance/camera_distance=1e6",
        "distance_off_axis/camera_distance=1e6",
    ];
    let options = RunOptions {
        threads: 1,
        ..RunOptions::default()
    };
    let mut rows = 0;
    for case in cases.iter().filter(|c| wanted.contains(&c.id().as_str())) {
        for row in run_case(case, &options).expect("runs") {
            rows += 1;
            assert_eq!(
                row.verdict,
                Verdict::Exact,
                "{} on {}: {:?}",
                row.case,
                row.configuration,
                row.metrics
            );
        }
    }
    assert_eq!(rows, 4, "two cases, two backends each");
    let _ = std::fs::remove_dir_all(dir);
}
