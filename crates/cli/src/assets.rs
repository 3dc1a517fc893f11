//! Where the built-in suites and scenes come from, so `bench --suite NAME` and `stability`
//! work from an installed binary in any folder. The first of:
//!
//! 1. `$MARCHMESH_ROOT`, a folder holding `scenes/suites/` (e.g. a checkout elsewhere);
//! 2. the current folder, when it holds `scenes/suites/` (a checkout);
//! 3. the copy embedded in the binary at build time (`build.rs`), extracted once into
//!    `$XDG_CACHE_HOME/marchmesh/<version>-<content hash>/` (or `~/.cache/...`, else the
//!    temporary folder): extraction goes to a unique folder renamed into place, so concurrent
//!    runs never see a half-written copy.
//!
//! Results always go under the current folder unless `--out` says otherwise.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

include!(concat!(env!("OUT_DIR"), "/embedded_scenes.rs"));

/// The root whose `scenes/` holds the built-in suites and scenes (see the module docs).
///
/// Errors: the embedded copy cannot be written to the cache folder.
pub fn root() -> Result<PathBuf> {
    if let Some(dir) = std::env::var_os("MARCHMESH_ROOT") {
        return Ok(PathBuf::from(dir));
    }
    let cwd = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."));
    if cwd.join("scenes/suites").is_dir() {
        return Ok(cwd);
    }
    extracted()
}

/// FNV-1a over every embedded file's name and bytes: a new build with other scenes gets
/// its own cache folder.
fn content_hash() -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for (name, bytes) in EMBEDDED_SCENES {
        for b in name.bytes().chain([0]).chain(bytes.iter().copied()) {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01B3);
        }
    }
    h
}

fn cache_base() -> PathBuf {
    std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir)
        .join("marchmesh")
}

fn extracted() -> Result<PathBuf> {
    let base = cache_base();
    let root = base.join(format!(
        "{}-{:016x}",
        env!("CARGO_PKG_VERSION"),
        content_hash()
    ));
    if root.join("scenes/suites").is_dir() {
        return Ok(root);
    }
    std::fs::create_dir_all(&base).with_context(|| format!("creating {}", base.display()))?;
    let staging = base.join(format!(
        ".extract-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos())
    ));
    let write = |staging: &Path| -> Result<()> {
        for (name, bytes) in EMBEDDED_SCENES {
            let path = staging.join("scenes").join(name);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent)
                    .with_context(|| format!("creating {}", parent.display()))?;
            }
            std::fs::write(&path, bytes).with_context(|| format!("writing {}", path.display()))?;
        }
        Ok(())
    };
    let result = write(&staging).and_then(|()| {
        match std::fs::rename(&staging, &root) {
            Ok(()) => Ok(()),
            // Another run extracted it first: use theirs.
            Err(_) if root.join("scenes/suites").is_dir() => Ok(()),
            Err(e) => {
                Err(e).with_context(|| format!("moving the built-in scenes to {}", root.display()))
            }
        }
    });
    let _ = std::fs::remove_dir_all(&staging);
    result.map(|()| root)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_suites_and_their_scenes_are_embedded() {
        let names: Vec<&str> = EMBEDDED_SCENES.iter().map(|(n, _)| *n).collect();
        for must in [
            "suites/default.json",
            "suites/smoke.json",
            "csg.json",
            "seed-spheres.json",
            "meshes/bunny.obj",
        ] {
            assert!(names.contains(&must), "{must} not embedded: {names:?}");
        }
        assert!(EMBEDDED_SCENES.iter().all(|(_, b)| !b.is_empty()));
    }
}
