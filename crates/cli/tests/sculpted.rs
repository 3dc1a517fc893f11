//! Sculpted content end to end: trees as deep as modelling tools write them render on every
//! backend, and the backends agree on what they see.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn tmp(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("marchmesh-sculpted-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

fn marchmesh(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_marchmesh"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run marchmesh")
}

/// A left-deep binary tree of `levels` two-child `op` nodes over `levels + 1` spheres of
/// radius 0.05 along a helix, written as JSON text (no recursion anywhere).
fn left_deep_chain(levels: usize, op: &str) -> String {
    let leaf = |i: usize| {
        let a = i as f64 * 0.37;
        let y = -0.8 + 1.6 * i as f64 / levels as f64;
        format!(
            r#"{{"shape":{{"sphere":{{"radius":0.05}}}},"transform":{{"translate":[{:.5},{y:.5},{:.5}]}}}}"#,
            0.5 * a.cos(),
            0.5 * a.sin()
        )
    };
    let opener = format!(r#"{{"shape":{{"{op}":{{"blend_radius":0.03,"children":["#);
    let mut tree = opener.repeat(levels);
    tree.push_str(&leaf(0));
    for i in 1..=levels {
        tree.push(',');
        tree.push_str(&leaf(i));
        tree.push_str("]}}}");
    }
    format!(
        r#"{{"camera":{{"position":[0,0,-3.2],"look_at":[0,0,0],"vfov_deg":45,"width":24,"height":24}},
"lights":[{{"ambient":{{"intensity":1}}}}],"objects":[{tree}]}}"#
    )
}

/// The `mask.pfm` AOV of a render: one value per pixel, 1 hit, 0 miss.
fn read_mask(dir: &Path) -> Vec<f32> {
    let bytes = std::fs::read(dir.join("mask.pfm")).expect("mask.pfm written");
    // Header: three text lines ("Pf", "W H", scale), then little-endian f32 rows.
    let mut lines = 0;
    let start = bytes
        .iter()
        .position(|&b| {
            if b == b'\n' {
                lines += 1;
            }
            lines == 3
        })
        .expect("a PFM header")
        + 1;
    bytes[start..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

#[test]
fn a_ten_thousand_level_left_deep_tree_renders_on_every_backend_alike() {
    let dir = tmp("deep");
    let scene = dir.join("chain.json");
    std::fs::write(&scene, left_deep_chain(10_000, "smooth_union")).expect("write scene");
    let out = marchmesh(&["validate", "chain.json"], &dir);
    assert!(
        out.status.success(),
        "validate: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_masks_agree(&masks_of_every_backend(&dir, "chain.json"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Renders `scene` (in `dir`) on every backend at 24x24 and returns each one's mask, the
/// reference's first.
fn masks_of_every_backend(dir: &Path, scene: &str) -> Vec<(&'static str, Vec<f32>)> {
    let mut masks = Vec::new();
    for backend in ["reference", "sdf", "mesh"] {
        let aov = format!("aov-{backend}");
        let png = format!("{backend}.png");
        let out = marchmesh(
            &[
                "render",
                scene,
                "--backend",
                backend,
                "--out",
                &png,
                "--aov",
                &aov,
                "--threads",
                "2",
            ],
            dir,
        );
        assert!(
            out.status.success(),
            "{backend}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let mask = read_mask(&dir.join(&aov));
        assert_eq!(mask.len(), 24 * 24, "{backend}");
        masks.push((backend, mask));
    }
    masks
}

/// Every mask covers part of the image, not all of it, and each backend's silhouette
/// differs from the reference's (the first) in at most 12 pixels, where a pixel centre
/// grazes the blend.
fn assert_masks_agree(masks: &[(&str, Vec<f32>)]) {
    for (backend, mask) in masks {
        let hits = mask.iter().filter(|&&m| m > 0.5).count();
        assert!(hits > 20 && hits < 24 * 24 - 20, "{backend}: {hits} hits");
    }
    let (_, truth) = &masks[0];
    for (backend, mask) in &masks[1..] {
        let differ = truth
            .iter()
            .zip(mask)
            .filter(|(a, b)| (**a > 0.5) != (**b > 0.5))
            .count();
        assert!(
            differ <= 12,
            "{backend}: {differ} of {} pixels differ from the reference",
            truth.len()
        );
    }
}

#[test]
fn a_blend_of_two_thousand_spheres_renders_on_every_backend_alike() {
    let dir = tmp("blend");
    // The helix of `left_deep_chain`, its spheres children of one flat blend.
    let chain = left_deep_chain(1999, "smooth_union");
    let leaves: Vec<&str> = chain
        .match_indices(r#"{"shape":{"sphere""#)
        .map(|(i, _)| {
            let end = chain[i..].find("]}}").expect("a leaf's end") + i + 3;
            &chain[i..end]
        })
        .collect();
    assert_eq!(leaves.len(), 2000);
    let scene = format!(
        r#"{{"camera":{{"position":[0,0,-3.2],"look_at":[0,0,0],"vfov_deg":45,"width":24,"height":24}},
"lights":[{{"ambient":{{"intensity":1}}}}],"objects":[{{"shape":{{"blend":{{"blend_radius":0.03,"children":[{}]}}}}}}]}}"#,
        leaves.join(",")
    );
    std::fs::write(dir.join("blend.json"), scene).expect("write scene");
    assert_masks_agree(&masks_of_every_backend(&dir, "blend.json"));
    // A blend is not a fold: nested blends are kept as written, so a deep chain of them is
    // refused at the nesting limit, naming it.
    std::fs::write(dir.join("nested.json"), left_deep_chain(100, "blend")).expect("write");
    let out = marchmesh(&["validate", "nested.json"], &dir);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("nest deeper than"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn every_scene_of_the_sculpted_suite_validates() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/generated/sculpted");
    let mut seen = 0;
    for entry in std::fs::read_dir(&root).expect("scenes/generated/sculpted") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "json") {
            let out = marchmesh(&["validate", &path.display().to_string()], &root);
            assert!(
                out.status.success(),
                "{}: {}",
                path.display(),
                String::from_utf8_lossy(&out.stderr)
            );
            seen += 1;
        }
    }
    assert!(seen >= 7, "only {seen} sculpted scenes found");
}
