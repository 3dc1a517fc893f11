//! The foundation scenes and the mesh scenes render through the core integrator with the
//! mesh backend: finite pixels, the expected objects hit, counters filled.

mod common;

use marchmesh_core::{BackgroundSampler, RenderOptions, render};
use marchmesh_mesh::{MeshError, MeshOptions, build};

fn render_file(name: &str, side: u32) -> Result<marchmesh_core::RenderOutput, MeshError> {
    let scene = marchmesh_scene::load(&common::scenes_dir().join(name))
        .expect("scene loads")
        .with_image_size(side, side)
        .expect("size");
    let g = build(&scene, &MeshOptions::DEFAULT)?;
    let bg = BackgroundSampler::load(&scene.background).expect("background");
    let opts = RenderOptions {
        threads: 1,
        ..Default::default()
    };
    Ok(render(&scene, &g, &bg, &opts, &|| {}).expect("render"))
}

#[test]
fn seed_spheres_and_primitives_render() {
    for name in ["seed-spheres.json", "primitives.json"] {
        let out = render_file(name, 48).unwrap_or_else(|e| panic!("{name}: {e}"));
        let s = &out.stats;
        assert_eq!(s.non_finite_hits + s.non_finite_pixels, 0, "{name}");
        assert!(s.hits > 48 * 48 / 2, "{name}: {} hits", s.hits);
        assert!(
            s.node_visits > 0 && s.primitive_tests > 0,
            "{name}: counters empty"
        );
        assert!(out.framebuffer.depth.iter().any(|d| d.is_finite()));
    }
}

#[test]
fn csg_scene_renders_or_names_the_missing_field_crate() {
    match render_file("csg.json", 32) {
        Ok(out) => assert_eq!(out.stats.non_finite_pixels, 0),
        Err(MeshError::Unsupported { json_path, reason }) => {
            assert!(json_path.starts_with("objects["), "{json_path}");
            assert!(reason.contains("marchmesh-field"), "{reason}");
        }
        Err(e) => panic!("unexpected error: {e}"),
    }
}

#[test]
fn mesh_scenes_render() {
    for (file, scale) in [
        ("bunny.obj", 0.25),
        ("teapot.obj", 0.3),
        ("dragon_res3.obj", 12.0),
    ] {
        let json = format!(
            r#"{{"camera": {{"position": [0, 2, -6], "look_at": [0, 1, 0], "vfov_deg": 40, "width": 32, "height": 32}},
                "objects": [{{"shape": {{"mesh": {{"path": "meshes/{file}"}}}}, "transform": {{"scale": {scale}}}}},
                            {{"shape": {{"plane": {{}}}}, "transform": {{"translate": [0, -0.5, 0]}}}}]}}"#
        );
        let scene = common::scene(&json);
        let g = build(&scene, &MeshOptions::DEFAULT).unwrap_or_else(|e| panic!("{file}: {e}"));
        let bg = BackgroundSampler::load(&scene.background).expect("background");
        let out = render(
            &scene,
            &g,
            &bg,
            &RenderOptions {
                threads: 1,
                ..Default::default()
            },
            &|| {},
        )
        .expect("render");
        assert_eq!(out.stats.non_finite_pixels, 0, "{file}");
        assert!(out.stats.hits > 100, "{file}: {} hits", out.stats.hits);
        let report = marchmesh_core::Geometry::report(&g);
        assert!(
            report.memory_bytes > 0 && report.build_phases_ms.len() == 4,
            "{report:?}"
        );
    }
}
