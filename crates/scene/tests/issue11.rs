//! Hostile scene files from issue 11: non-regular and oversized files, byte-order marks and
//! UTF-16, exponential nested repetition, and asset paths that are folders.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};

fn scratch() -> PathBuf {
    static COUNTER: AtomicU32 = AtomicU32::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("marchmesh-scene11-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

const SPHERE: &str = r#"{"objects": [{"shape": {"sphere": {}}}]}"#;

#[test]
fn item2_dev_zero_and_folders_are_refused_not_read() {
    let dir = scratch();
    let zero = dir.join("zero.json");
    std::os::unix::fs::symlink("/dev/zero", &zero).expect("symlink");
    let msg = marchmesh_scene::load(&zero)
        .expect_err("/dev/zero")
        .to_string();
    assert!(
        msg.contains("zero.json") && msg.contains("not a regular file"),
        "{msg}"
    );
    let folder = dir.join("scene.json");
    std::fs::create_dir_all(&folder).expect("folder");
    let msg = marchmesh_scene::load(&folder)
        .expect_err("folder")
        .to_string();
    assert!(
        msg.contains("scene.json") && msg.contains("folder"),
        "{msg}"
    );
}

#[test]
fn item16_utf8_bom_is_accepted_and_utf16_is_named() {
    let dir = scratch();
    let bom = dir.join("bom.json");
    let mut bytes = vec![0xEF, 0xBB, 0xBF];
    bytes.extend_from_slice(SPHERE.as_bytes());
    std::fs::write(&bom, bytes).expect("write");
    marchmesh_scene::load(&bom).expect("a UTF-8 BOM is skipped");

    let utf16 = dir.join("utf16.json");
    let mut bytes = vec![0xFF, 0xFE];
    for u in SPHERE.encode_utf16() {
        bytes.extend_from_slice(&u.to_le_bytes());
    }
    std::fs::write(&utf16, bytes).expect("write");
    let msg = marchmesh_scene::load(&utf16)
        .expect_err("utf-16")
        .to_string();
    assert!(
        msg.contains("utf16.json") && msg.contains("UTF-16"),
        "{msg}"
    );
}

fn nested_repeats(levels: usize) -> String {
    let mut shape = r#"{"sphere": {"radius": 0.1}}"#.to_string();
    for _ in 0..levels {
        shape = format!(
            r#"{{"repeat": {{"child": {{"shape": {shape}}}, "period": [1, 0, 0], "count": [2, null, null]}}}}"#
        );
    }
    format!(r#"{{"objects": [{{"shape": {shape}}}]}}"#)
}

#[test]
fn item4_nested_repetition_work_is_bounded_with_a_clear_error() {
    let base = std::path::Path::new(".");
    marchmesh_scene::parse_scene(&nested_repeats(10), "ok.json", base).expect("2^10 is allowed");
    let msg = marchmesh_scene::parse_scene(&nested_repeats(14), "deep.json", base)
        .expect_err("2^14")
        .to_string();
    assert!(
        msg.contains("deep.json") && msg.contains("nested repetitions") && msg.contains("1024"),
        "{msg}"
    );
    // Reported once, at the repeat whose chain crosses the limit.
    assert_eq!(msg.matches("nested repetitions").count(), 1, "{msg}");
}

fn nested_infinite_repeats(levels: usize) -> String {
    let mut shape = r#"{"sphere": {"radius": 0.1}}"#.to_string();
    for _ in 0..levels {
        shape = format!(r#"{{"repeat": {{"child": {{"shape": {shape}}}, "period": [1, 0, 0]}}}}"#);
    }
    format!(r#"{{"objects": [{{"shape": {shape}}}]}}"#)
}

#[test]
fn nested_infinite_repeats_count_the_copies_the_sdf_backend_evaluates() {
    let base = std::path::Path::new(".");
    // One infinite repeat of a child a fifth of its period wide: 2 copies per query.
    marchmesh_scene::parse_scene(&nested_infinite_repeats(1), "one.json", base).expect("2");
    // Every outer level's child is unbounded along the axis: 5 copies each.
    marchmesh_scene::parse_scene(&nested_infinite_repeats(4), "four.json", base)
        .expect("2 * 5^3 = 250 is within the limit");
    // Ten levels were accepted as 2^10 although the sdf backend evaluates 2 * 5^9.
    let msg = marchmesh_scene::parse_scene(&nested_infinite_repeats(10), "ten.json", base)
        .expect_err("2 * 5^4 = 1250 is over the limit")
        .to_string();
    assert!(msg.contains("ten.json"), "{msg}");
    assert!(
        msg.contains("nested repetitions evaluate 1250 copies")
            && msg.contains("5 copies of this repeat's child times 250 below it")
            && msg.contains("limit of 1024")
            && msg.contains("unbounded along the axis"),
        "{msg}"
    );
    assert_eq!(msg.matches("nested repetitions").count(), 1, "{msg}");
    // The same chain with counts evaluates at most the counts.
    let counted = nested_infinite_repeats(10).replace(
        r#""period": [1, 0, 0]"#,
        r#""period": [1, 0, 0], "count": [2, null, null]"#,
    );
    marchmesh_scene::parse_scene(&counted, "counted.json", base).expect("2^10");
}

#[test]
fn item16_mesh_and_environment_paths_that_are_folders_are_invalid() {
    let dir = scratch();
    std::fs::create_dir_all(dir.join("x.obj")).expect("folder");
    std::fs::create_dir_all(dir.join("sky.hdr")).expect("folder");
    let text = r#"{"background": {"environment": {"path": "sky.hdr"}},
                   "objects": [{"shape": {"mesh": {"path": "x.obj"}}}]}"#;
    let msg = marchmesh_scene::parse_scene(text, "s.json", &dir)
        .expect_err("folders")
        .to_string();
    assert!(
        msg.contains("objects[0].shape.mesh.path") && msg.contains("x.obj: is a folder"),
        "{msg}"
    );
    assert!(
        msg.contains("background.environment.path") && msg.contains("sky.hdr: is a folder"),
        "{msg}"
    );
}

#[test]
fn item13_json_arrays_are_refused_where_the_format_has_objects() {
    let base = std::path::Path::new(".");
    for (text, path) in [
        ("[]", "."),
        (
            r#"{"objects": [{"shape": {"sphere": [2]}}]}"#,
            "objects[0].shape.sphere",
        ),
        (r#"{"camera": [[0, 0, -4]], "objects": []}"#, "camera"),
        (
            r#"{"objects": [[{"sphere": {"radius": 1}}]]}"#,
            "objects[0]",
        ),
    ] {
        let msg = marchmesh_scene::parse_scene(text, "arr.json", base)
            .expect_err(text)
            .to_string();
        assert!(
            msg.contains("arr.json")
                && msg.contains("invalid type: sequence")
                && msg.contains(path),
            "{text}: {msg}"
        );
    }
    // Vectors and the per-axis scale stay arrays.
    marchmesh_scene::parse_scene(
        r#"{"objects": [{"shape": {"sphere": {"radius": 1}},
             "transform": {"translate": [0, 1, 0], "scale": [1, 2, 1]}}]}"#,
        "ok.json",
        base,
    )
    .expect("arrays where the format has arrays");
}
