//! Scene parsing: defaults, every kind of error, and the committed scenes.

use std::path::Path;

use glam::DVec3;
use marchmesh_scene::{Background, Light, NodeKind, SceneError, Shape, load, parse_scene};

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
    let mut nested = r#"{"shape": {"sphere": {}}}"#.to_string();
    for _ in 0..28 {
        nested = format!(r#"{{"shape": {{"union": {{"children": [{nested}]}}}}}}"#);
    }
    let p = problems(&format!(r#"{{"objects": [{nested}]}}"#));
    assert!(p[0].1.contains("nest deeper"), "{p:?}");
    // Far deeper: serde_json's recursion limit answers with an error, not a stack overflow.
    for _ in 0..2000 {
        nested = format!(r#"{{"shape": {{"union": {{"children": [{nested}]}}}}}}"#);
    }
    let msg = parse(&format!(r#"{{"objects": [{nested}]}}"#))
        .unwrap_err()
        .to_string();
    assert!(msg.contains("recursion limit"), "{msg}");
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
        "repeat",
    ] {
        assert!(schema.contains(&format!("\"{shape}\"")), "{shape} missing");
    }
}
