//! Embeds the built-in scenes and suites (`scenes/` of the workspace) into the binary, so an
//! installed `marchmesh` finds `--suite default` and its scenes in any folder (see
//! `src/assets.rs`). Only the bytes are embedded; no build-machine path reaches the binary.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Files above this size stay out of the binary (large meshes are fetched by scripts).
const MAX_EMBEDDED_FILE_BYTES: u64 = 4 << 20;

fn walk(dir: &Path, root: &Path, out: &mut Vec<(String, PathBuf)>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            walk(&p, root, out);
        } else if p.is_file()
            && p.metadata()
                .is_ok_and(|m| m.len() <= MAX_EMBEDDED_FILE_BYTES)
            && let Ok(rel) = p.strip_prefix(root)
        {
            let rel = rel.to_string_lossy().replace('\\', "/");
            out.push((rel, p.clone()));
        }
    }
}

fn main() {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default());
    let scenes = manifest.join("../../scenes");
    println!("cargo:rerun-if-changed={}", scenes.display());
    let mut files = Vec::new();
    walk(&scenes, &scenes, &mut files);
    let mut code = String::from("/// Built-in scene files: (path under `scenes/`, bytes).\n");
    code.push_str("pub static EMBEDDED_SCENES: &[(&str, &[u8])] = &[\n");
    for (rel, path) in &files {
        println!("cargo:rerun-if-changed={}", path.display());
        let abs = path.canonicalize().unwrap_or_else(|_| path.clone());
        let _ = writeln!(
            code,
            "    ({rel:?}, include_bytes!({:?})),",
            abs.display().to_string()
        );
    }
    code.push_str("];\n");
    let out =
        PathBuf::from(std::env::var("OUT_DIR").unwrap_or_default()).join("embedded_scenes.rs");
    if let Err(e) = std::fs::write(&out, code) {
        panic!("writing {}: {e}", out.display());
    }
}
