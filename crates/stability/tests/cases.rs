//! The generated stability cases are valid scenes, their meshes are what they claim, and the
//! verdict and report logic behave on synthetic inputs.

use std::path::PathBuf;

use glam::Vec3;
use marchmesh_core::Framebuffer;
use marchmesh_meshio::load_mesh;
use marchmesh_scene::parse_scene;
use marchmesh_stability::cases::{
    CaseContext, cube_with_degenerates_obj, sliver_cylinder_obj, uv_sphere_obj,
};
use marchmesh_stability::report::{csv_header, psnr_bounds, to_csv};
use marchmesh_stability::runner::interior_holes;
use marchmesh_stability::{Metrics, Row, Verdict, all_cases};

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("marchmesh-stability-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn ctx(name: &str, include_large: bool) -> CaseContext {
    CaseContext {
        generated_dir: scratch(name),
        scenes_dir: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes"),
        include_large,
    }
}

#[test]
fn every_generated_case_is_a_valid_scene_with_a_unique_id() {
    let cases = all_cases(&ctx("valid", true)).unwrap();
    assert!(cases.len() > 60, "only {} cases", cases.len());
    let mut ids = std::collections::HashSet::new();
    for c in &cases {
        assert!(ids.insert(c.id()), "duplicate case id {}", c.id());
        assert!(!c.variants.is_empty(), "{} measures nothing", c.id());
        for json in std::iter::once(&c.scene_json).chain(c.truth_json.as_ref()) {
            if let Err(e) = parse_scene(json, &c.id(), &c.base_dir) {
                panic!("{}: generated scene is invalid: {e}", c.id());
            }
        }
    }
    for family in [
        "scale",
        "distance",
        "distance_off_axis",
        "far_origin",
        "grazing_plane",
        "grazing_box",
        "thin_box",
        "thin_cylinder",
        "thin_torus",
        "sdf_epsilon",
        "sdf_max_steps",
        "sdf_relaxation",
        "mesh_degenerate",
        "mesh_slivers",
        "mesh_watertight",
        "bake_teapot_open",
        "acne",
        "shadow_light_size",
        "shadow_light_aspect",
        "shadow_occluder_height",
        "shadow_sphere_light",
    ] {
        assert!(
            cases.iter().any(|c| c.family == family),
            "family {family} missing"
        );
    }
}

#[test]
fn generated_meshes_are_closed_and_degenerates_are_reported() {
    let dir = scratch("meshes");
    let write = |name: &str, text: String| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        load_mesh(&p).unwrap()
    };
    let cube = write("cube.obj", cube_with_degenerates_obj(0.5));
    assert_eq!(cube.triangles.len(), 12, "only the 12 real faces survive");
    assert!(cube.is_closed());
    let skipped = cube.report.degenerate_skipped + cube.report.duplicate_skipped;
    assert_eq!(skipped, 18, "{:?}", cube.report);

    let cyl = write("cyl.obj", sliver_cylinder_obj(1.0, 0.5, 256));
    assert_eq!(cyl.triangles.len(), 2 * 256 + 2 * 254);
    assert!(cyl.is_closed());

    let sphere = write("sphere.obj", uv_sphere_obj(1.0, 8, 16));
    assert_eq!(sphere.triangles.len(), 2 * 8 * 16 - 2 * 16);
    assert!(sphere.is_closed());
    for p in &sphere.positions {
        assert!((p.length() - 1.0).abs() < 1e-5);
    }
    // Outward winding: every face normal points away from the centre.
    for t in &sphere.triangles {
        let [a, b, c] = t.map(|i| sphere.positions[i as usize]);
        assert!(
            (b - a).cross(c - a).dot(a + b + c) > 0.0,
            "inward face {t:?}"
        );
    }
}

fn metrics() -> Metrics {
    Metrics {
        non_finite: 0,
        silhouette_mismatch_pct: 0.1,
        interior_holes: 0,
        depth_rel_p95: 1e-5,
        depth_max_over_scene: 1e-4,
        depth_rel_max: 1e-4,
        depth_rel_tail_px: 0,
        normal_deg_tail_px: 0,
        normal_deg_mean: 0.1,
        normal_deg_p95: 0.3,
        psnr_db: 50.0,
        step_exhaustion_pct: 0.0,
        mean_steps: 10.0,
    }
}

#[test]
fn verdict_thresholds() {
    let m = metrics();
    assert_eq!(m.verdict(false), Verdict::Exact);
    assert_eq!(
        Metrics {
            silhouette_mismatch_pct: 2.0,
            ..m
        }
        .verdict(false),
        Verdict::Degraded
    );
    assert_eq!(
        Metrics {
            depth_rel_p95: 0.1,
            ..m
        }
        .verdict(false),
        Verdict::Broken
    );
    assert_eq!(
        Metrics {
            step_exhaustion_pct: 1.0,
            ..m
        }
        .verdict(false),
        Verdict::Degraded
    );
    assert_eq!(
        Metrics { non_finite: 1, ..m }.verdict(false),
        Verdict::Broken
    );
    assert_eq!(
        Metrics { non_finite: 1, ..m }.verdict(true),
        Verdict::Broken
    );
    // Nothing hit by both: depth/normal errors are NaN and the silhouette decides.
    let none = Metrics {
        depth_rel_p95: f64::NAN,
        normal_deg_mean: f64::NAN,
        ..m
    };
    assert_eq!(none.verdict(false), Verdict::Exact);
    assert_eq!(
        Metrics {
            silhouette_mismatch_pct: 50.0,
            ..none
        }
        .verdict(false),
        Verdict::Broken
    );
    assert_eq!(
        Metrics { psnr_db: 30.0, ..m }.verdict(true),
        Verdict::Degraded
    );
    assert_eq!(
        Metrics { psnr_db: 10.0, ..m }.verdict(true),
        Verdict::Broken
    );
}

#[test]
fn interior_holes_count_only_misses_inside_the_truth() {
    let mut truth = Framebuffer::new(5, 5);
    let mut test = Framebuffer::new(5, 5);
    for fb in [&mut truth, &mut test] {
        fb.depth.fill(1.0);
        fb.normal.fill(Vec3::Z);
    }
    // A miss in the middle (a crack) and one on the border (not interior).
    test.depth[12] = f32::INFINITY;
    test.depth[0] = f32::INFINITY;
    assert_eq!(interior_holes(&test, &truth), 1);
    // If the truth misses a neighbour, the pixel is on an edge, not a hole.
    truth.depth[7] = f32::INFINITY;
    assert_eq!(interior_holes(&test, &truth), 0);
}

#[test]
fn the_image_error_bound_is_the_lowest_psnr_over_the_sweep() {
    let row = |value: f64, psnr_db: f64| Row {
        case: format!("shadow_light_size/side={value}"),
        family: "shadow_light_size".into(),
        parameter: "side".into(),
        value,
        backend: "sdf".into(),
        configuration: "sdf[cone_shadows=true]".into(),
        verdict: Verdict::Exact,
        metrics: Some(Metrics {
            psnr_db,
            ..metrics()
        }),
        build_ms: 1.0,
        render_ms: 2.0,
        memory_bytes: 100,
        error: None,
        notes: vec![],
    };
    let refused = Row {
        metrics: None,
        verdict: Verdict::Refused,
        ..row(8.0, 0.0)
    };
    let rows = [
        row(0.5, 45.0),
        row(2.0, 31.5),
        row(4.0, f64::INFINITY),
        refused,
    ];
    let bounds = psnr_bounds(&rows);
    let key = (
        "shadow_light_size".to_string(),
        "sdf[cone_shadows=true]".to_string(),
    );
    assert_eq!(bounds.get(&key), Some(&(31.5, 2.0, f64::INFINITY)));
    assert_eq!(bounds.len(), 1);
}

#[test]
fn csv_rows_have_as_many_fields_as_the_header() {
    let row = Row {
        case: "scale/scale=1".into(),
        family: "scale".into(),
        parameter: "scale".into(),
        value: 1.0,
        backend: "sdf".into(),
        configuration: "sdf[eps_abs=0.001]".into(),
        verdict: Verdict::Exact,
        metrics: Some(metrics()),
        build_ms: 1.0,
        render_ms: 2.0,
        memory_bytes: 100,
        error: None,
        notes: vec![],
    };
    let refused = Row {
        verdict: Verdict::Refused,
        metrics: None,
        error: Some("bad, \"quoted\" reason".into()),
        ..row.clone()
    };
    let csv = to_csv(&[row, refused]);
    let n = csv_header().split(',').count();
    assert_eq!(
        csv_header(),
        "case,family,parameter,value,backend,configuration,verdict,non_finite,silhouette_mismatch_pct,interior_holes_px,depth_rel_p95,depth_max_over_scene,depth_rel_max,depth_rel_tail_px,normal_deg_mean,normal_deg_tail_px,normal_deg_p95,psnr_db,step_exhaustion_pct,mean_steps,build_ms,render_ms,memory_bytes,error",
        "the columns scripts read keep their names and order"
    );
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 3);
    assert_eq!(lines[1].split(',').count(), n);
    // The quoted error holds one comma inside quotes.
    assert_eq!(lines[2].split(',').count(), n + 1);
    assert!(lines[2].ends_with("\"bad, \"\"quoted\"\" reason\""));
}

#[test]
fn written_scenes_reload_with_their_meshes_from_another_folder() {
    let c = ctx("write", false);
    let cases = all_cases(&c).unwrap();
    let picked: Vec<_> = cases
        .iter()
        .filter(|k| {
            k.family == "mesh_degenerate" || k.family == "bake_teapot_open" || k.family == "scale"
        })
        .collect();
    let out = scratch("written").join("nested/extreme");
    let files = marchmesh_stability::runner::write_scenes(&picked, &out).unwrap();
    assert!(files.iter().any(|f| f.ends_with(".truth.json")));
    for f in &files {
        let text = std::fs::read_to_string(out.join(f)).unwrap();
        let scene = parse_scene(&text, f, &out).unwrap();
        for p in scene.mesh_paths() {
            assert!(
                p.exists(),
                "{f}: mesh {} not found from the written folder",
                p.display()
            );
        }
    }
}

#[test]
fn relative_paths() {
    use marchmesh_stability::runner::relative_path;
    use std::path::Path;
    assert_eq!(
        relative_path(Path::new("/a/b/c.obj"), Path::new("/a/d")),
        Path::new("../b/c.obj")
    );
    assert_eq!(
        relative_path(Path::new("/a/x/../b/c.obj"), Path::new("/a/b")),
        Path::new("c.obj")
    );
}
