//! Hostile input: mutated and random scene text never panics the parser or validator.

use std::path::Path;

use proptest::prelude::*;

fn committed_scenes() -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| {
            let p = e.ok()?.path();
            (p.extension()? == "json").then(|| std::fs::read_to_string(p).ok())?
        })
        .collect();
    v.sort();
    v
}

/// Byte-level edits: delete, insert or replace a character at a position.
#[derive(Debug, Clone)]
enum Edit {
    Delete(usize),
    Insert(usize, char),
    Replace(usize, char),
}

fn edit() -> impl Strategy<Value = Edit> {
    let ch = prop::sample::select(vec![
        '{', '}', '[', ']', ',', ':', '"', '-', '0', '9', 'e', '.', ' ', 'n', '\u{0}', 'é',
    ]);
    prop_oneof![
        any::<usize>().prop_map(Edit::Delete),
        (any::<usize>(), ch.clone()).prop_map(|(i, c)| Edit::Insert(i, c)),
        (any::<usize>(), ch).prop_map(|(i, c)| Edit::Replace(i, c)),
    ]
}

fn apply(text: &str, edits: &[Edit]) -> String {
    let mut chars: Vec<char> = text.chars().collect();
    for e in edits {
        if chars.is_empty() {
            break;
        }
        match *e {
            Edit::Delete(i) => {
                chars.remove(i % chars.len());
            }
            Edit::Insert(i, c) => chars.insert(i % (chars.len() + 1), c),
            Edit::Replace(i, c) => {
                let n = chars.len();
                chars[i % n] = c;
            }
        }
    }
    chars.into_iter().collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn mutated_scenes_never_panic(which in 0usize..16, edits in prop::collection::vec(edit(), 1..6)) {
        let scenes = committed_scenes();
        let text = apply(&scenes[which % scenes.len()], &edits);
        let _ = marchmesh_scene::parse_scene(&text, "<mutated>", Path::new("."));
    }

    #[test]
    fn numbers_anywhere_are_validated_not_trusted(value in prop_oneof![
        Just(0.0f64), Just(-1.0), Just(1e308), Just(-1e308), Just(1e-320), any::<f64>()
    ], slot in 0usize..12) {
        let v = if value.is_finite() { format!("{value:e}") } else { "1e999".to_string() };
        let fields = [
            format!(r#"{{"camera": {{"vfov_deg": {v}}}}}"#),
            format!(r#"{{"camera": {{"position": [{v}, 0, 0]}}}}"#),
            format!(r#"{{"objects": [{{"shape": {{"sphere": {{"radius": {v}}}}}}}]}}"#),
            format!(r#"{{"objects": [{{"shape": {{"box": {{"half_extents": [1, {v}, 1]}}}}}}]}}"#),
            format!(r#"{{"objects": [{{"shape": {{"torus": {{"minor_radius": {v}}}}}}}]}}"#),
            format!(r#"{{"objects": [{{"shape": {{"sphere": {{}}}}, "transform": {{"scale": {v}}}}}]}}"#),
            format!(r#"{{"objects": [{{"shape": {{"sphere": {{}}}}, "transform": {{"rotate_deg": [{v}, 0, 0]}}}}]}}"#),
            format!(r#"{{"objects": [{{"shape": {{"repeat": {{"child": {{"shape": {{"sphere": {{}}}}}}, "period": [{v}, 0, 0]}}}}}}]}}"#),
            format!(r#"{{"objects": [{{"shape": {{"smooth_union": {{"blend_radius": {v}, "children": [{{"shape": {{"sphere": {{}}}}}}]}}}}}}]}}"#),
            format!(r#"{{"lights": [{{"point": {{"position": [0, {v}, 0], "intensity": 1}}}}]}}"#),
            format!(r#"{{"render": {{"max_distance": {v}}}}}"#),
            format!(r#"{{"render": {{"ray_offset": {v}}}}}"#),
        ];
        match marchmesh_scene::parse_scene(&fields[slot], "<n>", Path::new(".")) {
            Ok(scene) => {
                // Whatever was accepted is finite and within the documented limits.
                prop_assert!(scene.camera.position.is_finite());
                prop_assert!(scene.camera.vfov_rad > 0.0 && scene.camera.vfov_rad < std::f64::consts::PI);
                prop_assert!(scene.render.max_distance > 0.0 && scene.render.max_distance.is_finite());
                scene.visit_nodes(|n| assert!(n.transform.is_finite()));
            }
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
    }
}
