//! Scene parsing: defaults, every kind of error, and the committed scenes.

use std::path::Path;

use glam::DVec3;
use marchmesh_scene::{
    Background, Light, NodeKind, SceneError, Shape, SmoothOp, load, parse_scene,
};

fn parse(json: &str) -> Result<marchmesh_scene::Scene, SceneError> {
    parse_scene(json, "test.json", Path::new("/scenes"))
}

fn problems(json: &str) -> Vec<(String, String)> {
    match parse(json) {
        Err(SceneError::Invalid { problems, .. }) => problems
            .into_iter()
            .map(|p| (p.json_path, p.reason))
            .collect(),
        other => panic!("expected a validation error, got {other:?}"),
    }
}

#[test]
fn empty_object_gets_every_documented_default() {
    let s = parse("{}").unwrap();
    assert_eq!(s.camera.position, DVec3::ZERO);
    assert!((s.camera.forward - DVec3::Z).length() < 1e-12);
    assert!((s.camera.vfov_rad - 60f64.to_radians()).abs() < 1e-12);
    assert_eq!((s.camera.width, s.camera.height), (500, 500));
    assert_eq!(s.background, Background::Color(DVec3::ZERO));
    assert_eq!(s.lights.len(), 2);
    assert!(matches!(s.lights[0], Light::Ambient { intensity } if intensity == 0.2));
    assert!(s.objects.is_empty());
    assert_eq!(s.render.samples_per_pixel, 1);
    assert_eq!(s.render.max_reflection_depth, 3);
    assert_eq!(s.render.max_distance, 1000.0);
    assert_eq!(s.materials.len(), 1);
}

#[test]
fn explicit_empty_lights_means_no_light() {
    let s = parse(r#"{"lights": []}"#).unwrap();
    assert!(s.lights.is_empty());
}

#[test]
fn shape_defaults_transforms_and_material_inheritance() {
    let s = parse(
        r#"{"objects": [
        {"shape": {"union": {"children": [
            {"shape": {"sphere": {}}},
            {"shape": {"box": {}}, "material": {"color": [0, 1, 0]}}
        ]}},
         "material": {"color": [1, 0, 0], "reflectivity": 0.5},
         "transform": {"translate": [1, 2, 3], "rotate_deg": [0, 90, 0], "scale": 2}},
        {"shape": {"mesh": {"path": "meshes/bunny.obj"}}}
    ]}"#,
    )
    .unwrap();
    let u = &s.objects[0];
    // translate * rotate * scale: the local x axis goes to world -z, doubled.
    let x = u.transform.transform_vector3(DVec3::X);
    assert!((x - DVec3::new(0.0, 0.0, -2.0)).length() < 1e-12, "{x:?}");
    assert_eq!(u.transform.translation, DVec3::new(1.0, 2.0, 3.0));
    let NodeKind::Union(children) = &u.kind else {
        panic!("not a union")
    };
    assert_eq!(
        children[0].kind,
        NodeKind::Leaf(Shape::Sphere { radius: 1.0 })
    );
    assert_eq!(children[0].material, u.material, "inherited");
    assert_ne!(children[1].material, u.material, "own material");
    assert_eq!(s.materials[u.material as usize].reflectivity, 0.5);
    assert_eq!(
        children[1].kind,
        NodeKind::Leaf(Shape::Box {
            half_extents: DVec3::splat(0.5)
        })
    );
    assert_eq!(s.objects[1].material, 0, "default material");
    assert_eq!(
        s.mesh_paths(),
        vec![Path::new("/scenes/meshes/bunny.obj").to_path_buf()]
    );
}

#[test]
fn syntax_error_names_file_line_and_column() {
    let err = parse("{\n  \"camera\": {\n    \"width\": 10,,\n  }\n}").unwrap_err();
    let SceneError::Parse { line, column, .. } = &err else {
        panic!("{err:?}")
    };
    assert_eq!(*line, 3);
    assert!(*column > 0);
    assert!(err.to_string().starts_with("test.json:3:"), "{err}");
}

#[test]
fn wrong_type_names_the_json_path() {
    let err = parse(r#"{"objects": [{"shape": {"sphere": {"radius": "big"}}}]}"#).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("objects[0].shape.sphere.radius"), "{msg}");
    assert!(msg.contains("invalid type"), "{msg}");
}

#[test]
fn unknown_fields_and_shapes_are_rejected() {
    let msg = parse(r#"{"camera": {"fov": 50}}"#).unwrap_err().to_string();
    assert!(msg.contains("unknown field `fov`"), "{msg}");
    assert!(msg.contains("camera"), "{msg}");
    let msg = parse(r#"{"objects": [{"shape": {"cone": {}}}]}"#)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("unknown variant `cone`"), "{msg}");
    assert!(msg.contains("objects[0].shape"), "{msg}");
}

#[test]
fn trailing_garbage_is_an_error() {
    assert!(matches!(parse("{} x"), Err(SceneError::Parse { .. })));
}

#[test]
fn out_of_range_values_are_all_reported_with_paths() {
    let p = problems(
        r#"{
      "camera": {"position": [0, 0, 0], "look_at": [0, 0, 0], "vfov_deg": 0, "width": 0},
      "lights": [{"directional": {"direction": [0, 0, 0], "intensity": -1}}],
      "objects": [
        {"shape": {"sphere": {"radius": -1}}},
        {"shape": {"box": {"half_extents": [1, 0, 1]}}, "transform": {"scale": [1, 1, 0]}},
        {"shape": {"torus": {"major_radius": 1, "minor_radius": 2}}},
        {"shape": {"triangle": {"vertices": [[0,0,0],[1,1,1],[2,2,2]]}}},
        {"shape": {"union": {"children": []}}},
        {"shape": {"repeat": {"child": {"shape": {"sphere": {}}}, "period": [0, 0, 0], "count": [0, null, null]}}},
        {"shape": {"sphere": {}}, "material": {"color": [2, 0, 0], "reflectivity": 1.5}}
      ]
    }"#,
    );
    let paths: Vec<&str> = p.iter().map(|(a, _)| a.as_str()).collect();
    for expected in [
        "camera.vfov_deg",
        "camera.width",
        "camera.look_at",
        "lights[0].directional.direction",
        "lights[0].directional.intensity",
        "objects[0].shape.sphere.radius",
        "objects[1].shape.box.half_extents[1]",
        "objects[1].transform.scale[2]",
        "objects[2].shape.torus.minor_radius",
        "objects[3].shape.triangle.vertices",
        "objects[4].shape.union.children",
        "objects[5].shape.repeat.period",
        "objects[5].shape.repeat.count[0]",
        "objects[6].material.color[0]",
        "objects[6].material.reflectivity",
    ] {
        assert!(paths.contains(&expected), "missing {expected} in {p:#?}");
    }
}

#[test]
fn nan_and_infinity_are_rejected() {
    // JSON has no NaN or infinity literal; numbers beyond f64 are a parse error at their path,
    // and finite values beyond the coordinate limit are a validation error.
    let msg = parse(r#"{"objects": [{"shape": {"sphere": {"radius": 1e400}}}]}"#)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("objects[0].shape.sphere.radius"), "{msg}");
    assert!(msg.contains("out of range"), "{msg}");
    let p = problems(r#"{"objects": [{"shape": {"sphere": {"radius": 1e300}}}]}"#);
    assert_eq!(p[0].0, "objects[0].shape.sphere.radius");
    let msg = parse(r#"{"objects": [{"shape": {"sphere": {"radius": NaN}}}]}"#)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("test.json:1:"), "{msg}");
}

#[test]
fn up_parallel_to_view_is_rejected() {
    let p = problems(r#"{"camera": {"look_at": [0, 5, 0], "up": [0, 1, 0]}}"#);
    assert_eq!(p[0].0, "camera.up");
}

#[test]
fn absurd_sizes_and_nesting_are_rejected() {
    let p = problems(r#"{"camera": {"width": 100000, "height": 100000}}"#);
    assert_eq!(p[0].0, "camera.width");
    // Nesting that merging cannot flatten (alternating operations) stops at the merged
    // depth limit, naming the deepest node.
    let p = problems(&chain(
        70,
        |k| if k % 2 == 0 { "union" } else { "intersection" },
        true,
    ));
    assert!(p[0].1.contains("nest deeper than 64"), "{p:?}");
    // Beyond the file limit: refused before parsing, at the position where it goes too deep.
    let msg = parse(&chain(17_000, |_| "union", true))
        .unwrap_err()
        .to_string();
    assert!(msg.contains("JSON nests deeper than"), "{msg}");
}

#[test]
fn missing_file_names_the_file() {
    let err = load(Path::new("/nonexistent/scene.json")).unwrap_err();
    assert!(err.to_string().contains("/nonexistent/scene.json"), "{err}");
}

#[test]
fn committed_scenes_are_valid() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "json") {
            load(&p).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(
        n >= 3,
        "expected the foundation scenes in {}",
        dir.display()
    );
}

#[test]
fn schema_lists_every_shape() {
    let schema = marchmesh_scene::json_schema();
    for shape in [
        "sphere",
        "plane",
        "triangle",
        "box",
        "ellipsoid",
        "cylinder",
        "torus",
        "mesh",
        "union",
        "intersection",
        "subtraction",
        "smooth_union",
        "blend",
        "repeat",
    ] {
        assert!(schema.contains(&format!("\"{shape}\"")), "{shape} missing");
    }
}

/// `levels` nested nodes of operation `op(level)` around one sphere, each the first child
/// of the next (`first = true`) or the last.
fn chain(levels: usize, op: impl Fn(usize) -> &'static str, first: bool) -> String {
    let leaf = r#"{"shape": {"sphere": {}}}"#;
    let mut s = String::from(r#"{"objects": ["#);
    for k in (0..levels).rev() {
        s.push_str(&format!(r#"{{"shape": {{"{}": {{"children": ["#, op(k)));
        if !first {
            s.push_str(leaf);
            s.push_str(", ");
        }
    }
    s.push_str(leaf);
    for _ in 0..levels {
        if first {
            s.push_str(", ");
            s.push_str(leaf);
        }
        s.push_str("]}}}");
    }
    s.push_str("]}");
    s
}

/// Runs `f` on a thread with a 256 KiB stack (rayon workers' are small too).
fn on_small_stack<R: Send + 'static>(f: impl FnOnce() -> R + Send + 'static) -> R {
    std::thread::Builder::new()
        .stack_size(256 * 1024)
        .spawn(f)
        .expect("spawn")
        .join()
        .expect("no stack overflow")
}

#[test]
fn ten_thousand_levels_load_on_a_small_stack_and_left_deep_chains_merge() {
    let left = chain(10_000, |_| "union", true);
    let right = chain(10_000, |_| "union", false);
    let (merged, path, refused) = on_small_stack(move || {
        let scene = parse(&left).expect("a left-deep chain loads");
        let NodeKind::Union(children) = &scene.objects[0].kind else {
            panic!("a union");
        };
        let last = children[1].json_path.clone();
        let refused = match parse(&right) {
            Err(SceneError::Invalid { problems, .. }) => problems[0].reason.clone(),
            other => panic!("a right-deep chain is refused, got {other:?}"),
        };
        (children.len(), last, refused)
    });
    assert_eq!(merged, 10_001, "one node of every sphere");
    assert_eq!(
        path,
        "objects[0](.shape.union.children[0]){9999}.shape.union.children[1]"
    );
    assert!(refused.contains("nest deeper than 64"), "{refused}");
}

#[test]
fn merging_keeps_transforms_other_operations_and_blend_radii_apart() {
    let scene = parse(
        r#"{"objects": [{"shape": {"smooth_union": {"blend_radius": 0.1, "children": [
            {"shape": {"smooth_union": {"blend_radius": 0.2, "children": [{"shape": {"sphere": {}}}]}}},
            {"shape": {"sphere": {}}}]}}},
          {"shape": {"union": {"children": [
            {"shape": {"union": {"children": [{"shape": {"sphere": {}}}]}}, "transform": {"translate": [1, 0, 0]}},
            {"shape": {"sphere": {}}}]}}},
          {"shape": {"smooth_subtraction": {"blend_radius": 0.1, "children": [
            {"shape": {"smooth_subtraction": {"blend_radius": 0.1, "children": [
              {"shape": {"sphere": {}}}, {"shape": {"box": {}}}]}}},
            {"shape": {"sphere": {}}}]}}}]}"#,
    )
    .expect("valid");
    let counts: Vec<usize> = scene.objects.iter().map(|o| o.children().len()).collect();
    assert_eq!(counts, [2, 2, 3]);
}

#[test]
fn a_blend_checks_its_parameters_and_nested_blends_are_not_merged() {
    // blend(blend(a, b), c) is not blend(a, b, c): unlike a fold, the nesting is kept.
    let scene = parse(
        r#"{"objects": [{"shape": {"blend": {"blend_radius": 0.1, "children": [
            {"shape": {"blend": {"blend_radius": 0.1, "children": [
              {"shape": {"sphere": {}}}, {"shape": {"box": {}}}]}}},
            {"shape": {"sphere": {}}}]}}}]}"#,
    )
    .expect("valid");
    let NodeKind::Smooth {
        op: SmoothOp::Blend,
        children,
        ..
    } = &scene.objects[0].kind
    else {
        panic!("a blend");
    };
    assert_eq!(children.len(), 2);
    assert!(matches!(
        &children[0].kind,
        NodeKind::Smooth { op: SmoothOp::Blend, children, .. } if children.len() == 2
    ));
    let p = problems(
        r#"{"objects": [
        {"shape": {"blend": {"blend_radius": 0, "children": []}}},
        {"shape": {"blend": {"blend_radius": -1, "children": [{"shape": {"sphere": {}}}]}}}]}"#,
    );
    let paths: Vec<&str> = p.iter().map(|(path, _)| path.as_str()).collect();
    assert!(
        paths.contains(&"objects[0].shape.blend.blend_radius"),
        "{p:?}"
    );
    assert!(paths.contains(&"objects[0].shape.blend.children"), "{p:?}");
    assert!(paths.iter().any(|p| p.starts_with("objects[1]")), "{p:?}");
}

#[test]
fn new_shapes_and_smooth_operators_check_their_parameters() {
    let p = problems(
        r#"{"objects": [
        {"shape": {"rounded_box": {"half_extents": [1, 0.2, 1], "rounding_radius": 0.3}}},
        {"shape": {"rounded_box": {"rounding_radius": -0.1}}},
        {"shape": {"capsule": {"radius": 0, "height": -1}}},
        {"shape": {"capped_cone": {"bottom_radius": 0, "top_radius": 0}}},
        {"shape": {"capped_cone": {"height": 0, "top_radius": 1e300}}},
        {"shape": {"smooth_intersection": {"blend_radius": 0, "children": []}}},
        {"shape": {"smooth_subtraction": {"blend_radius": -1, "children": [{"shape": {"sphere": {}}}]}}}]}"#,
    );
    let paths: Vec<&str> = p.iter().map(|(path, _)| path.as_str()).collect();
    for want in [
        "objects[0].shape.rounded_box.rounding_radius",
        "objects[1].shape.rounded_box.rounding_radius",
        "objects[2].shape.capsule.radius",
        "objects[2].shape.capsule.height",
        "objects[3].shape.capped_cone",
        "objects[4].shape.capped_cone.height",
        "objects[4].shape.capped_cone.top_radius",
        "objects[5].shape.smooth_intersection.children",
        "objects[5].shape.smooth_intersection.blend_radius",
        "objects[6].shape.smooth_subtraction.blend_radius",
    ] {
        assert!(paths.contains(&want), "{want} missing from {p:?}");
    }
}
