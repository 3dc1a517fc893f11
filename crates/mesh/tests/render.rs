//! The foundation scenes and the mesh scenes render through the core integrator with the
//! mesh backend: finite pixels, the expected objects hit, counters filled.

use marchmesh_testkit as common;

use marchmesh_core::Geometry;
use marchmesh_mesh::{MeshError, MeshOptions, build};

fn render_file(name: &str, side: u32) -> Result<marchmesh_core::RenderOutput, MeshError> {
    let scene = marchmesh_scene::load(&common::scenes_dir().join(name))
        .expect("scene loads")
        .with_image_size(side, side)
        .expect("size");
    let g = build(&scene, &MeshOptions::default())?;
    Ok(common::render_1t(&scene, &g))
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
fn csg_scene_renders_with_extracted_surfaces() {
    let out = render_file("csg.json", 32).unwrap_or_else(|e| panic!("csg.json: {e}"));
    assert_eq!(out.stats.non_finite_pixels, 0);
    assert!(out.stats.hits > 0, "nothing hit");
}

#[test]
fn unbounded_csg_is_declined_with_its_path() {
    let scene = common::scene(
        r#"{"objects": [{"shape": {"subtraction": {"children": [
            {"shape": {"plane": {}}},
            {"shape": {"sphere": {"radius": 1}}}]}}}]}"#,
    );
    match build(&scene, &MeshOptions::fast()) {
        Err(MeshError::Unsupported { json_path, reason }) => {
            assert_eq!(json_path, "objects[0]");
            assert!(reason.contains("unbounded"), "{reason}");
        }
        Err(e) => panic!("unexpected error: {e}"),
        Ok(_) => panic!("an unbounded subtraction cannot be tessellated"),
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
        let g = build(&scene, &MeshOptions::default()).unwrap_or_else(|e| panic!("{file}: {e}"));
        let out = common::render_1t(&scene, &g);
        assert_eq!(out.stats.non_finite_pixels, 0, "{file}");
        assert!(out.stats.hits > 100, "{file}: {} hits", out.stats.hits);
        let report = marchmesh_core::Geometry::report(&g);
        assert!(
            report.memory_bytes > 0 && report.build_phases_ms.len() == 4,
            "{report:?}"
        );
    }
}

#[test]
fn single_triangle_and_empty_scenes_build() {
    let s = common::scene(
        r#"{"camera": {"position": [0, 1.5, -5], "look_at": [0, 0, 0], "vfov_deg": 40, "width": 16, "height": 16},
            "objects": [{"shape": {"triangle": {"vertices": [[-1.2, -0.8, 0.3], [1.3, -0.6, -0.2], [0.1, 1.2, 0.1]]}}}]}"#,
    );
    for bvh in [
        marchmesh_mesh::BvhKind::Bvh2,
        marchmesh_mesh::BvhKind::CwBvh,
    ] {
        let g = build(
            &s,
            &MeshOptions {
                bvh: Some(bvh),
                ..MeshOptions::default()
            },
        )
        .expect("one triangle");
        let hits = common::camera_rays(&s, 16)
            .iter()
            .filter(|r| marchmesh_core::Geometry::closest_hit(&g, r).hit().is_some())
            .count();
        assert!(hits > 20, "{bvh:?}: {hits}");
    }
    let empty = common::scene(r#"{"camera": {"width": 8, "height": 8}}"#);
    let g = build(&empty, &MeshOptions::default()).expect("empty scene");
    let r = marchmesh_core::Geometry::closest_hit(&g, &common::camera_rays(&empty, 1)[0]);
    assert!(r.hit().is_none());
}

#[test]
fn instanced_and_flattened_images_match() {
    let s = common::scene(
        r#"{"camera": {"position": [0, 2, -6], "look_at": [0, 0, 0], "vfov_deg": 50, "width": 48, "height": 48},
            "objects": [{"shape": {"repeat": {"period": [2, 0, 2],
                "child": {"shape": {"torus": {"major_radius": 0.6, "minor_radius": 0.2}}, "transform": {"rotate_deg": [60, 0, 0]}}}}},
                {"shape": {"plane": {}}, "transform": {"translate": [0, -0.9, 0]}}],
            "render": {"max_distance": 30}}"#,
    );
    let inst = build(&s, &MeshOptions::default()).expect("instanced");
    let flat = build(
        &s,
        &MeshOptions {
            instancing: Some(false),
            ..MeshOptions::default()
        },
    )
    .expect("flat");
    assert!(inst.instance_count() > 100);
    let a = common::render_1t(&s, &inst);
    let b = common::render_1t(&s, &flat);
    let acc = marchmesh_core::compare(&a.framebuffer, &b.framebuffer).expect("same size");
    assert!(acc.silhouette_mismatch_pct < 0.1, "{acc:#?}");
    assert!(acc.depth_rel_p95 < 1e-5, "{acc:#?}");
    assert!(acc.normal_deg_mean < 0.01, "{acc:#?}");
    assert_eq!(acc.material_mismatch, 0, "{acc:#?}");
}

#[test]
fn tiny_scenes_render_with_a_cwbvh_request() {
    // A sphere of radius 1e-6 seen from 6e-6: obvhs CwBvh alone misses every ray here.
    let scene = common::scene(
        r#"{"camera": {"position": [0, 0, -6e-6], "width": 16, "height": 16},
            "objects": [{"shape": {"sphere": {"radius": 1e-6}}}], "render": {"max_distance": 1e-4}}"#,
    );
    let options = MeshOptions {
        bvh: Some(marchmesh_mesh::BvhKind::CwBvh),
        ..MeshOptions::default()
    };
    let g = build(&scene, &options).unwrap();
    let out = common::render_1t(&scene, &g);
    assert!(out.stats.hits > 8, "only {} hits", out.stats.hits);
    assert!(g.report().notes.iter().any(|n| n.contains("built as Bvh2")));
}

/// The extraction grid's cells along the longest side, from the build's note.
fn extraction_resolution(g: &impl Geometry) -> u32 {
    let notes = g.report().notes;
    notes
        .iter()
        .find_map(|n| n.split("at resolution ").nth(1)?.trim().parse().ok())
        .unwrap_or_else(|| panic!("no extraction note in {notes:?}"))
}

#[test]
fn a_camera_inside_a_union_sizes_the_extraction_grid_from_the_nearest_surface() {
    // The camera sits inside the first sphere, `depth` from its surface: the grid's cells must
    // be small on screen at that distance (finer the nearer the surface), not at the bounding
    // box's distance (zero from inside, which asked for the largest grid whatever the image).
    let at = |depth: f64| {
        let z = 0.5 - (2.0 - depth);
        let scene = common::scene(&format!(
            r#"{{"camera": {{"position": [0, 0, {z}], "look_at": [0, 0, 1], "vfov_deg": 70, "width": 64, "height": 64}},
                "objects": [{{"shape": {{"union": {{"children": [
                    {{"shape": {{"sphere": {{"radius": 2}}}}, "transform": {{"translate": [0, 0, 0.5]}}}},
                    {{"shape": {{"sphere": {{"radius": 2}}}}, "transform": {{"translate": [1.5, 0, 1.5]}}}}]}}}}}}]}}"#
        ));
        let g = build(&scene, &MeshOptions::default()).expect("build");
        let notes = g.report().notes.join("\n");
        assert!(notes.contains("the camera is inside this union"), "{notes}");
        extraction_resolution(&g)
    };
    let (far, near) = (at(1.5), at(0.3));
    // The screen budget at 1.5 units: the box's 5.5-unit side over 1 px (the default cell) *
    // 0.022 rad (a pixel at 70 degrees over 64 px) * 1.5 units, about 168 cells.
    assert!(
        (100..=200).contains(&far),
        "1.5 units from the surface: {far} cells"
    );
    assert!(
        near > 2 * far,
        "0.3 units from the surface: {near} against {far} cells"
    );
}
