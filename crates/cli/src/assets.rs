//! Where the built-in suites and scenes come from, so `bench --suite NAME` and `stability`
//! work from an installed binary in any folder. The first of:
//!
//! 1. `$MARCHMESH_ROOT`, a folder holding `scenes/suites/` (e.g. a checkout elsewhere);
//! 2. the current folder, when it holds `scenes/suites/` (a checkout);
//! 3. the copy embedded in the binary at build time (`build.rs`), extracted once into
//!    `$XDG_CACHE_HOME/marchmesh/<version>-<content hash>/` (or `~/.cache/...`; when that is
//!    unset or not writable, `marchmesh-<uid>` in the temporary folder): extraction goes to a
//!    unique folder renamed into place, so concurrent runs never see a half-written copy. The
//!    `marchmesh` folder is private (mode 0700, owned by the user: anything else is not
//!    used), and an existing copy is used only if every file still holds the embedded bytes
//!    (otherwise it is replaced).
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

/// The names of the built-in scenes (`seed-spheres` for `scenes/seed-spheres.json`; scenes
/// in subfolders as `folder/name`), sorted.
pub fn scene_names() -> Vec<String> {
    let mut v: Vec<String> = EMBEDDED_SCENES
        .iter()
        .filter(|(n, _)| !n.starts_with("suites/"))
        .filter_map(|(n, _)| n.strip_suffix(".json"))
        .map(str::to_string)
        .collect();
    v.sort();
    v
}

/// The names of the built-in suites (`default` for `scenes/suites/default.json`), sorted.
pub fn suite_names() -> Vec<String> {
    let mut v: Vec<String> = EMBEDDED_SCENES
        .iter()
        .filter_map(|(n, _)| n.strip_prefix("suites/")?.strip_suffix(".json"))
        .map(str::to_string)
        .collect();
    v.sort();
    v
}

/// Every embedded file: its path under `scenes/` and its bytes.
pub fn embedded_files() -> &'static [(&'static str, &'static [u8])] {
    EMBEDDED_SCENES
}

/// Whether `arg` names something rather than being a path: no extension and no folder.
fn is_bare_name(arg: &Path) -> bool {
    arg.extension().is_none() && arg.components().count() == 1
}

/// A scene argument as a file: a path that exists (even as a link or special file) is the
/// user's file as given; otherwise a name `marchmesh scenes` lists (`seed-spheres`,
/// `lighting/cornell-box`) is that built-in scene, found under [`root`]; any other argument
/// with a folder or extension is a path as given (its loader names the missing file).
///
/// Errors: an unknown bare name (the error lists the built-in scenes); the built-in copy
/// cannot be extracted.
pub fn scene_file(arg: &Path) -> Result<PathBuf> {
    if arg.symlink_metadata().is_ok() {
        return Ok(arg.to_path_buf());
    }
    let name = arg.to_string_lossy();
    if scene_names().iter().any(|n| *n == name) {
        return Ok(root()?.join("scenes").join(format!("{name}.json")));
    }
    if !is_bare_name(arg) {
        return Ok(arg.to_path_buf());
    }
    anyhow::bail!(
        "{name}: no such scene file, nor a built-in scene; built-in scenes: {} (`marchmesh scenes` lists them)",
        scene_names().join(", ")
    )
}

/// A suite argument as a file: a path that exists is the user's file; otherwise a name
/// `marchmesh scenes` lists as a suite is that built-in suite under [`root`]; any other
/// argument with an extension or a folder is a path as given.
///
/// Errors: an unknown suite name or a missing suite file (the error lists the built-in
/// suites); the built-in copy cannot be extracted.
pub fn suite_file(arg: &str) -> Result<PathBuf> {
    if Path::new(arg).symlink_metadata().is_err() && suite_names().iter().any(|n| n == arg) {
        return Ok(root()?.join("scenes/suites").join(format!("{arg}.json")));
    }
    let path = marchmesh_harness::suite::locate(arg, root)?;
    // Anything that exists (a regular file, or a FIFO or device the suite loader refuses
    // with its own message without opening it for reading) is the user's file.
    if path.symlink_metadata().is_ok() {
        return Ok(path);
    }
    if is_bare_name(Path::new(arg)) {
        anyhow::bail!(
            "no suite named {arg:?}; built-in suites: {} (or give the path of a suite file)",
            suite_names().join(", ")
        );
    }
    let reason = match path.metadata() {
        Err(e) => e.to_string(),
        Ok(_) => "not found".into(),
    };
    anyhow::bail!(
        "suite file {arg}: {reason}; built-in suites by name: {}",
        suite_names().join(", ")
    )
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

/// The user id of this process: the owner of `/proc/self` (no libc needed).
#[cfg(unix)]
fn my_uid() -> Option<u32> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata("/proc/self").ok().map(|m| m.uid())
}

/// The cache folders to try, in order: `$XDG_CACHE_HOME/marchmesh` (absolute only) or
/// `~/.cache/marchmesh`, then `marchmesh-<uid>` in the temporary folder (never a folder
/// shared between users).
fn cache_bases() -> Vec<PathBuf> {
    let mut bases: Vec<PathBuf> = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| {
            std::env::var_os("HOME")
                .map(PathBuf::from)
                .filter(|p| p.is_absolute())
                .map(|h| h.join(".cache"))
        })
        .map(|p| p.join("marchmesh"))
        .into_iter()
        .collect();
    #[cfg(unix)]
    if let Some(uid) = my_uid() {
        bases.push(std::env::temp_dir().join(format!("marchmesh-{uid}")));
    }
    bases
}

/// Creates `base` (mode 0700) if absent and checks that it is a real folder owned by this
/// user that nobody else can write into.
///
/// Errors: it cannot be created, is a symlink or not a folder, has another owner, or is
/// writable by group or others.
fn private_folder(base: &Path) -> Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::{DirBuilderExt, MetadataExt};
        let mut builder = std::fs::DirBuilder::new();
        builder.recursive(true).mode(0o700);
        builder
            .create(base)
            .with_context(|| format!("creating {}", base.display()))?;
        let meta = std::fs::symlink_metadata(base)
            .with_context(|| format!("checking {}", base.display()))?;
        if !meta.is_dir() {
            anyhow::bail!("{} is not a folder (a symlink?)", base.display());
        }
        if Some(meta.uid()) != my_uid() {
            anyhow::bail!("{} belongs to another user", base.display());
        }
        if meta.mode() & 0o022 != 0 {
            anyhow::bail!(
                "{} is writable by other users (mode {:o})",
                base.display(),
                meta.mode() & 0o777
            );
        }
    }
    #[cfg(not(unix))]
    std::fs::create_dir_all(base).with_context(|| format!("creating {}", base.display()))?;
    Ok(())
}

/// Whether `root` holds exactly the embedded bytes of every embedded file.
fn holds_the_embedded_copy(root: &Path) -> bool {
    let scenes = root.join("scenes");
    EMBEDDED_SCENES.iter().all(|(name, bytes)| {
        marchmesh_safeio::read_capped(&scenes.join(name), bytes.len() as u64)
            .is_ok_and(|b| b == *bytes)
    })
}

fn extracted() -> Result<PathBuf> {
    let mut errors = Vec::new();
    for base in cache_bases() {
        match extract_into(&base) {
            Ok(root) => return Ok(root),
            Err(e) => errors.push(format!("{e:#}")),
        }
    }
    anyhow::bail!(
        "no private cache folder for the built-in scenes ({}); set MARCHMESH_ROOT to a checkout or XDG_CACHE_HOME to a writable folder",
        errors.join("; ")
    )
}

fn extract_into(base: &Path) -> Result<PathBuf> {
    private_folder(base)?;
    let root = base.join(format!(
        "{}-{:016x}",
        env!("CARGO_PKG_VERSION"),
        content_hash()
    ));
    if root.join("scenes/suites").is_dir() && holds_the_embedded_copy(&root) {
        return Ok(root);
    }
    let unique = format!(
        "{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos())
    );
    if std::fs::symlink_metadata(&root).is_ok() {
        // A damaged or altered copy: move it aside and extract afresh.
        let stale = base.join(format!(".stale-{unique}"));
        std::fs::rename(&root, &stale)
            .with_context(|| format!("moving the altered copy {} aside", root.display()))?;
        let _ = std::fs::remove_dir_all(&stale);
    }
    let staging = base.join(format!(".extract-{unique}"));
    let write = |staging: &Path| -> Result<()> {
        for (name, bytes) in EMBEDDED_SCENES {
            let path = staging.join("scenes").join(name);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent)
                    .with_context(|| format!("creating {}", parent.display()))?;
            }
            marchmesh_safeio::publish_new(&path, bytes)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        Ok(())
    };
    let result = write(&staging).and_then(|()| {
        match std::fs::rename(&staging, &root) {
            Ok(()) => Ok(()),
            // Another run extracted it first: use theirs if it is intact.
            Err(_) if holds_the_embedded_copy(&root) => Ok(()),
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

    #[test]
    fn built_in_names_list_scenes_and_suites_apart() {
        let scenes = scene_names();
        assert!(scenes.iter().any(|n| n == "seed-spheres"), "{scenes:?}");
        assert!(
            !scenes.iter().any(|n| n.starts_with("suites/")),
            "{scenes:?}"
        );
        let suites = suite_names();
        assert!(suites.iter().any(|n| n == "default"), "{suites:?}");
        assert!(is_bare_name(Path::new("csg")));
        assert!(!is_bare_name(Path::new("csg.json")));
        assert!(!is_bare_name(Path::new("scenes/csg")));
        let e = scene_file(Path::new("no-such-scene"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("built-in scenes: ") && e.contains("seed-spheres"),
            "{e}"
        );
    }
}
