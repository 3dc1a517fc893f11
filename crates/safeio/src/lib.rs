//! Hostile-input-safe file I/O, in one place for every marchmesh crate.
//!
//! - [`read_capped`] reads a *regular* file of at most a byte cap: `/dev/zero`, FIFOs and
//!   folders are refused up front instead of growing until the kernel kills the process.
//!   The cap is [`DEFAULT_READ_CAP_BYTES`] (1 GiB) unless the environment variable
//!   [`READ_CAP_ENV`] (`MARCHMESH_MAX_READ_MIB`, in MiB) overrides it.
//! - [`publish_new`] writes bytes to a unique temporary file beside the target and publishes
//!   it with a hard link, which fails if the target exists: exactly one of concurrent writers
//!   wins, the others get [`SafeIoError::Exists`], and a failed write leaves no partial file.
//! - [`own_folder`] creates or reuses a folder the tools own inside a run folder or beside
//!   an output (`plots/`, `images/`, `<stem>-plots/`) and refuses one that is a symbolic link
//!   or not a folder, so nothing is ever written or deleted through a planted link.
//! - [`create_folder`] creates a folder the user named, and [`check_folder_path`] says which
//!   component of its path is a file or a dangling symbolic link, instead of the OS's
//!   "Not a directory" or "File exists".

use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Default largest file [`read_capped`] accepts: 1 GiB.
pub const DEFAULT_READ_CAP_BYTES: u64 = 1 << 30;

/// Environment variable overriding the read cap, in MiB (a positive integer).
pub const READ_CAP_ENV: &str = "MARCHMESH_MAX_READ_MIB";

/// Why a safe read or write failed. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum SafeIoError {
    /// The OS refused an operation.
    #[error("{}: {action}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What was attempted.
        action: &'static str,
        /// The OS error.
        source: std::io::Error,
    },
    /// The path is a folder, device, FIFO or socket, not a regular file.
    #[error("{}: not a regular file ({kind})", path.display())]
    NotRegularFile {
        /// The path.
        path: PathBuf,
        /// What it is instead (`"folder"`, `"device, FIFO or socket"`).
        kind: &'static str,
    },
    /// The file is larger than the read cap.
    #[error(
        "{}: file is larger than the read limit of {cap_bytes} bytes (set {READ_CAP_ENV} in MiB to raise it)",
        path.display()
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The cap in bytes.
        cap_bytes: u64,
    },
    /// [`READ_CAP_ENV`] is set but is not a positive integer.
    #[error("{READ_CAP_ENV}={value:?}: must be a positive whole number of MiB")]
    BadReadCap {
        /// The value found.
        value: String,
    },
    /// A folder the tools own (created or reused inside a run folder or beside an output) is
    /// a symbolic link, file or special file: nothing is written or deleted through it.
    #[error("{} is {kind}, not a folder of its own (nothing was written through it)", path.display())]
    NotOwnFolder {
        /// The path.
        path: PathBuf,
        /// What it is instead (`"a symbolic link"`, `"a file"`, `"a device, FIFO or socket"`).
        kind: &'static str,
    },
    /// A folder to write into, or one of the folders above it, exists but is not a folder
    /// (a file, a special file, or a symbolic link to one or to nothing): the OS would only
    /// say "Not a directory" or "File exists".
    #[error("{}{} {reason} (nothing was written)", above(path, at), at.display())]
    NotAFolderOnPath {
        /// The folder asked for.
        path: PathBuf,
        /// The component of it (the folder itself or one above it) that is not a folder.
        at: PathBuf,
        /// What it is instead, as a predicate (`"is a file, not a folder"`).
        reason: String,
    },
    /// The target already exists (or was created by a concurrent writer) and overwriting
    /// was not allowed.
    #[error("{}: already exists (nothing was overwritten)", path.display())]
    Exists {
        /// The target.
        path: PathBuf,
    },
}

/// `"{path}: "` when the component `at` that is not a folder lies above `path`, else nothing
/// (the message then names the path once).
fn above(path: &Path, at: &Path) -> String {
    if path == at {
        String::new()
    } else {
        format!("{}: ", path.display())
    }
}

/// The read cap in bytes: [`READ_CAP_ENV`] in MiB if set, else [`DEFAULT_READ_CAP_BYTES`].
///
/// Errors: [`SafeIoError::BadReadCap`] when the variable is set but is not a positive
/// integer (`0`, `-5`, `abc`): a mistyped limit is an error, never silently the default.
pub fn read_cap_bytes() -> Result<u64, SafeIoError> {
    match std::env::var(READ_CAP_ENV) {
        Err(std::env::VarError::NotPresent) => Ok(DEFAULT_READ_CAP_BYTES),
        Err(std::env::VarError::NotUnicode(v)) => Err(SafeIoError::BadReadCap {
            value: v.to_string_lossy().into_owned(),
        }),
        Ok(v) => match v.trim().parse::<u64>() {
            Ok(mib) if mib > 0 => Ok(mib.saturating_mul(1 << 20)),
            _ => Err(SafeIoError::BadReadCap { value: v }),
        },
    }
}

/// `O_NONBLOCK`: opening a FIFO for reading does not wait for a writer (the type check
/// after the open then refuses it).
#[cfg(any(target_os = "linux", target_os = "android"))]
const O_NONBLOCK: i32 = 0o4000;
#[cfg(all(unix, not(any(target_os = "linux", target_os = "android"))))]
const O_NONBLOCK: i32 = 0x0004;

fn not_regular(path: &Path, meta: &std::fs::Metadata) -> SafeIoError {
    SafeIoError::NotRegularFile {
        path: path.to_path_buf(),
        kind: if meta.is_dir() {
            "folder"
        } else {
            "device, FIFO or socket"
        },
    }
}

/// The conversion of an OS error met while doing `action` on `path` into a
/// [`SafeIoError::Io`] naming both.
fn io_error(path: &Path, action: &'static str) -> impl FnOnce(std::io::Error) -> SafeIoError {
    let path = path.to_path_buf();
    move |source| SafeIoError::Io {
        path,
        action,
        source,
    }
}

/// Opens a regular file of at most `cap_bytes` bytes for reading (symlinks are followed)
/// without ever blocking: the type is checked on the path before the open, the open does not
/// wait (a FIFO swapped in meanwhile opens at once), and the type and size are checked again
/// on the open handle. Returns the handle and its length in bytes.
///
/// Errors: [`SafeIoError::NotRegularFile`] for a folder, device, FIFO or socket,
/// [`SafeIoError::TooLarge`] over the cap, or the OS error naming the file.
pub fn open_regular(path: &Path, cap_bytes: u64) -> Result<(File, u64), SafeIoError> {
    let io = |action| io_error(path, action);
    let meta = std::fs::metadata(path).map_err(io("cannot open"))?;
    if !meta.is_file() {
        return Err(not_regular(path, &meta));
    }
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(O_NONBLOCK);
    }
    let file = options.open(path).map_err(io("cannot open"))?;
    let meta = file.metadata().map_err(io("cannot stat"))?;
    if !meta.is_file() {
        return Err(not_regular(path, &meta));
    }
    if meta.len() > cap_bytes {
        return Err(SafeIoError::TooLarge {
            path: path.to_path_buf(),
            cap_bytes,
        });
    }
    Ok((file, meta.len()))
}

/// Reads the whole of a regular file of at most `cap_bytes` bytes (symlinks are followed).
///
/// Errors: the path is not a regular file, is larger than the cap (checked on the metadata and
/// again while reading, so a growing file cannot exceed it), or the OS fails.
pub fn read_capped(path: &Path, cap_bytes: u64) -> Result<Vec<u8>, SafeIoError> {
    let io = |action| io_error(path, action);
    let (file, len) = open_regular(path, cap_bytes)?;
    let too_large = || SafeIoError::TooLarge {
        path: path.to_path_buf(),
        cap_bytes,
    };
    let mut bytes = Vec::new();
    bytes
        .try_reserve_exact(usize::try_from(len).map_err(|_| too_large())?)
        .map_err(|_| too_large())?;
    file.take(cap_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(io("cannot read"))?;
    if bytes.len() as u64 > cap_bytes {
        return Err(too_large());
    }
    Ok(bytes)
}

/// [`read_capped`] with the [`read_cap_bytes`] cap.
///
/// Errors: those of [`read_capped`], or [`SafeIoError::BadReadCap`].
pub fn read_regular(path: &Path) -> Result<Vec<u8>, SafeIoError> {
    read_capped(path, read_cap_bytes()?)
}

/// [`read_capped`] with the smaller of `cap_bytes` (a limit of the file kind, e.g. an
/// anchor file) and the [`read_cap_bytes`] cap.
///
/// Errors: those of [`read_capped`], or [`SafeIoError::BadReadCap`].
pub fn read_regular_within(path: &Path, cap_bytes: u64) -> Result<Vec<u8>, SafeIoError> {
    read_capped(path, cap_bytes.min(read_cap_bytes()?))
}

/// What `meta` (of `symlink_metadata`) is when it is not a real folder, or `None` for a
/// folder.
fn not_a_folder(meta: &std::fs::Metadata) -> Option<&'static str> {
    let t = meta.file_type();
    if t.is_symlink() {
        Some("a symbolic link")
    } else if t.is_dir() {
        None
    } else if t.is_file() {
        Some("a file")
    } else {
        Some("a device, FIFO or socket")
    }
}

/// Checks that `dir`, a folder the tools own (inside a run folder or beside an output), is
/// absent or a real folder: never a symbolic link (even to a folder), file or special file.
/// Only the last component is checked; the folders above it are the user's choice. Returns
/// whether it exists.
///
/// Errors: [`SafeIoError::NotOwnFolder`] naming the path and what it is.
pub fn check_own_folder(dir: &Path) -> Result<bool, SafeIoError> {
    match std::fs::symlink_metadata(dir) {
        Ok(meta) => match not_a_folder(&meta) {
            None => Ok(true),
            Some(kind) => Err(SafeIoError::NotOwnFolder {
                path: dir.to_path_buf(),
                kind,
            }),
        },
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
        // "Not a directory": a folder above it is a file; say which.
        Err(e) => Err(check_folder_path(dir)
            .err()
            .unwrap_or_else(|| io_error(dir, "cannot inspect")(e))),
    }
}

/// Why `at`, an existing path, cannot be walked into as a folder, or `None` when it is a
/// folder (or a symbolic link to one) or cannot be inspected (the OS error comes later).
fn not_a_folder_reason(at: &Path) -> Option<String> {
    let own = std::fs::symlink_metadata(at).ok()?;
    let link = own.file_type().is_symlink();
    let target = || std::fs::read_link(at).map_or_else(|_| "?".into(), |t| t.display().to_string());
    let meta = match std::fs::metadata(at) {
        Ok(m) => m,
        Err(e) if link && e.kind() == std::io::ErrorKind::NotFound => {
            return Some(format!(
                "is a symbolic link to {}, which does not exist",
                target()
            ));
        }
        Err(e) if link => {
            return Some(format!(
                "is a symbolic link to {} that cannot be followed ({e})",
                target()
            ));
        }
        Err(_) => return None,
    };
    if meta.is_dir() {
        return None;
    }
    let what = if meta.is_file() {
        "a file"
    } else {
        "a device, FIFO or socket"
    };
    Some(if link {
        format!("is a symbolic link to {what}, not a folder")
    } else {
        format!("is {what}, not a folder")
    })
}

/// Checks that `dir` can be a folder to write into: each component of it that exists, from
/// the top down, is a folder or a symbolic link to one (links are the user's choice). A
/// component that does not exist ends the check: it and what lies under it can be created.
///
/// Errors: [`SafeIoError::NotAFolderOnPath`] naming `dir`, the component that is a file, a
/// special file or a symbolic link to one or to nothing, and which of these it is.
pub fn check_folder_path(dir: &Path) -> Result<(), SafeIoError> {
    let mut ancestors: Vec<&Path> = dir
        .ancestors()
        .filter(|a| !a.as_os_str().is_empty())
        .collect();
    ancestors.reverse();
    for at in ancestors {
        if std::fs::symlink_metadata(at).is_err() {
            break;
        }
        if let Some(reason) = not_a_folder_reason(at) {
            return Err(SafeIoError::NotAFolderOnPath {
                path: dir.to_path_buf(),
                at: at.to_path_buf(),
                reason,
            });
        }
    }
    Ok(())
}

/// Creates `dir` and the folders above it that are missing (or reuses them), with an error
/// that names the component which is not a folder ([`check_folder_path`]) instead of the
/// OS's "Not a directory" or "File exists".
///
/// Errors: [`SafeIoError::NotAFolderOnPath`], or the OS error naming the folder.
pub fn create_folder(dir: &Path) -> Result<(), SafeIoError> {
    check_folder_path(dir)?;
    std::fs::create_dir_all(dir).map_err(|e| {
        // Something may have been put in the way since the check.
        check_folder_path(dir)
            .err()
            .unwrap_or_else(|| io_error(dir, "cannot create the folder")(e))
    })
}

/// [`create_folder`] that returns the folders this call created, top down (empty when `dir`
/// existed), each made by one `create_dir`, so a folder someone else made meanwhile is not
/// counted. A command that gives up before filling them removes them again with
/// [`remove_created_folders`], leaving nothing it made and nothing that was there before.
///
/// Errors: those of [`create_folder`]; the folders created before the error are removed.
pub fn create_folder_tracked(dir: &Path) -> Result<Vec<PathBuf>, SafeIoError> {
    check_folder_path(dir)?;
    let mut missing: Vec<&Path> = dir
        .ancestors()
        .filter(|a| !a.as_os_str().is_empty())
        .take_while(|a| std::fs::symlink_metadata(a).is_err())
        .collect();
    missing.reverse();
    let mut created = Vec::new();
    for at in missing {
        match std::fs::create_dir(at) {
            Ok(()) => created.push(at.to_path_buf()),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && at.is_dir() => {}
            Err(e) => {
                remove_created_folders(&created);
                return Err(check_folder_path(dir)
                    .err()
                    .unwrap_or_else(|| io_error(at, "cannot create the folder")(e)));
            }
        }
    }
    Ok(created)
}

/// Removes the folders of [`create_folder_tracked`], deepest first, each only if it is still
/// empty (a folder someone has put anything in stays, and so do the folders above it).
pub fn remove_created_folders(created: &[PathBuf]) {
    for dir in created.iter().rev() {
        if std::fs::remove_dir(dir).is_err() {
            return;
        }
    }
}

/// Creates `dir` (and missing parents) or reuses it if it is a real folder, refusing it when
/// it is a symbolic link, file or special file ([`check_own_folder`], checked before and
/// after creating) or when a folder above it is not one ([`check_folder_path`]).
///
/// Errors: [`SafeIoError::NotOwnFolder`], [`SafeIoError::NotAFolderOnPath`], or the OS
/// error naming the folder.
pub fn own_folder(dir: &Path) -> Result<(), SafeIoError> {
    if !check_own_folder(dir)? {
        create_folder(dir)?;
        check_own_folder(dir)?;
    }
    Ok(())
}

/// A temporary file name unique to this process and call, beside `target`.
fn unique_temporary(target: &Path) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let name = target
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    target.with_file_name(format!(".{name}.tmp-{}-{n}-{nanos}", std::process::id()))
}

/// Writes `bytes` to a new file at `target` atomically and without overwriting anything:
/// the data goes to a unique temporary file beside it, is flushed to disk, then hard-linked
/// to `target` (which fails if `target` exists, even as a dangling symlink or a special
/// file); the temporary name is always removed.
///
/// Errors: [`SafeIoError::Exists`] if `target` exists (exactly one of concurrent callers
/// succeeds), or an I/O error; on any error no file is left at `target` by this call.
pub fn publish_new(target: &Path, bytes: &[u8]) -> Result<(), SafeIoError> {
    let temporary = unique_temporary(target);
    let io = |action| io_error(target, action);
    let write = || -> Result<(), SafeIoError> {
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temporary)
            .map_err(io("cannot create a temporary file beside"))?;
        file.write_all(bytes).map_err(io("cannot write"))?;
        file.sync_all().map_err(io("cannot flush"))?;
        match std::fs::hard_link(&temporary, target) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Err(SafeIoError::Exists {
                path: target.to_path_buf(),
            }),
            Err(e) => Err(io("cannot publish")(e)),
        }
    };
    let result = write();
    let _ = std::fs::remove_file(&temporary);
    result
}

/// Replaces `target` with `bytes` atomically (for `--force`): refuses if `target` exists and
/// is not a regular file (a folder, device such as `/dev/null`, FIFO, or a symlink, dangling
/// or not), otherwise writes a unique temporary file and renames it over `target`.
///
/// Errors: [`SafeIoError::NotRegularFile`] for a non-regular target, or an I/O error; a
/// failed write leaves `target` as it was and no temporary file.
pub fn replace_regular(target: &Path, bytes: &[u8]) -> Result<(), SafeIoError> {
    if let Ok(meta) = std::fs::symlink_metadata(target)
        && !meta.file_type().is_file()
    {
        return Err(SafeIoError::NotRegularFile {
            path: target.to_path_buf(),
            kind: if meta.is_dir() {
                "folder"
            } else if meta.file_type().is_symlink() {
                "symbolic link"
            } else {
                "device, FIFO or socket"
            },
        });
    }
    let temporary = unique_temporary(target);
    let io = |action| io_error(target, action);
    let write = || -> Result<(), SafeIoError> {
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temporary)
            .map_err(io("cannot create a temporary file beside"))?;
        file.write_all(bytes).map_err(io("cannot write"))?;
        file.sync_all().map_err(io("cannot flush"))?;
        std::fs::rename(&temporary, target).map_err(io("cannot publish"))
    };
    let result = write();
    if result.is_err() {
        let _ = std::fs::remove_file(&temporary);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("safeio-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn dev_zero_is_refused_not_read() {
        let e = read_capped(Path::new("/dev/zero"), 1 << 20).unwrap_err();
        assert!(matches!(e, SafeIoError::NotRegularFile { .. }), "{e}");
    }

    #[test]
    fn fifos_are_refused_without_blocking_even_behind_a_symlink() {
        let dir = scratch("fifo");
        let fifo = dir.join("pipe.json");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        assert!(made.is_ok_and(|s| s.success()), "mkfifo");
        let link = dir.join("link.json");
        std::os::unix::fs::symlink(&fifo, &link).unwrap();
        for p in [&fifo, &link] {
            // Opening a FIFO for reading without O_NONBLOCK would wait here for a writer.
            let e = read_capped(p, 1 << 20).unwrap_err();
            assert!(matches!(e, SafeIoError::NotRegularFile { .. }), "{e}");
        }
    }

    #[test]
    fn folders_are_refused_as_folders() {
        let dir = scratch("folder");
        let e = read_capped(&dir, 1 << 20).unwrap_err();
        assert!(e.to_string().contains("folder"), "{e}");
    }

    #[test]
    fn files_over_the_cap_are_refused_and_the_message_names_the_override() {
        let dir = scratch("cap");
        let f = dir.join("big.bin");
        std::fs::write(&f, vec![0u8; 100]).unwrap();
        assert_eq!(read_capped(&f, 100).unwrap().len(), 100);
        let e = read_capped(&f, 99).unwrap_err();
        assert!(e.to_string().contains(READ_CAP_ENV), "{e}");
    }

    #[test]
    fn publish_new_never_overwrites_and_one_concurrent_writer_wins() {
        let dir = scratch("publish");
        let target = dir.join("out.png");
        let winners: usize = std::thread::scope(|s| {
            let handles: Vec<_> = (0..12u8)
                .map(|k| {
                    let target = &target;
                    s.spawn(move || publish_new(target, &vec![k; 4096]).is_ok())
                })
                .collect();
            handles
                .into_iter()
                .map(|h| usize::from(h.join().unwrap()))
                .sum()
        });
        assert_eq!(winners, 1);
        let bytes = std::fs::read(&target).unwrap();
        assert!(bytes.iter().all(|&b| b == bytes[0]) && bytes.len() == 4096);
        let e = publish_new(&target, b"x").unwrap_err();
        assert!(matches!(e, SafeIoError::Exists { .. }), "{e}");
        // No temporary files are left behind.
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
    }

    #[test]
    fn own_folders_are_created_or_reused_but_never_links_or_files() {
        let dir = scratch("own");
        let plots = dir.join("a/plots");
        own_folder(&plots).unwrap();
        own_folder(&plots).unwrap();
        assert!(plots.is_dir());
        let target = dir.join("target");
        std::fs::create_dir_all(&target).unwrap();
        let link = dir.join("linked");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let file = dir.join("file");
        std::fs::write(&file, b"x").unwrap();
        for (p, kind) in [(&link, "symbolic link"), (&file, "a file")] {
            let e = own_folder(p).unwrap_err();
            assert!(matches!(e, SafeIoError::NotOwnFolder { .. }), "{e}");
            assert!(e.to_string().contains(kind), "{e}");
        }
        assert!(!check_own_folder(&dir.join("absent")).unwrap());
    }

    #[test]
    fn folders_through_a_file_or_a_dangling_link_are_refused_naming_the_component() {
        let dir = scratch("folder-path");
        let file = dir.join("file.txt");
        std::fs::write(&file, b"x").unwrap();
        let dangling = dir.join("dangling");
        std::os::unix::fs::symlink(dir.join("nowhere"), &dangling).unwrap();
        let to_file = dir.join("to-file");
        std::os::unix::fs::symlink(&file, &to_file).unwrap();
        for (path, at, reason) in [
            (file.join("x/y"), &file, "is a file, not a folder"),
            (file.clone(), &file, "is a file, not a folder"),
            (dangling.join("x"), &dangling, "which does not exist"),
            (dangling.clone(), &dangling, "which does not exist"),
            (to_file.join("x"), &to_file, "is a symbolic link to a file"),
        ] {
            let mut errors = vec![
                check_folder_path(&path).unwrap_err(),
                create_folder(&path).unwrap_err(),
            ];
            if path != *at {
                // The last component itself is `NotOwnFolder`'s case.
                errors.push(own_folder(&path).unwrap_err());
            }
            for e in errors {
                let text = e.to_string();
                let said = if path == *at {
                    format!("{} is", at.display())
                } else {
                    format!("{}: {} is", path.display(), at.display())
                };
                assert!(text.starts_with(&said) && text.contains(reason), "{text}");
            }
        }
        assert!(!dir.join("nowhere").exists());
        assert_eq!(std::fs::read(&file).unwrap(), b"x");
        let linked = dir.join("linked");
        std::os::unix::fs::symlink(&dir, &linked).unwrap();
        create_folder(&linked.join("a/b")).unwrap();
        assert!(dir.join("a/b").is_dir());
    }

    #[test]
    fn tracked_folders_are_the_ones_made_and_only_empty_ones_are_removed() {
        let dir = scratch("tracked");
        let kept = dir.join("kept");
        std::fs::create_dir(&kept).unwrap();
        let created = create_folder_tracked(&kept.join("a/b")).unwrap();
        assert_eq!(created, vec![kept.join("a"), kept.join("a/b")]);
        assert!(create_folder_tracked(&kept.join("a/b")).unwrap().is_empty());
        remove_created_folders(&created);
        assert!(!kept.join("a").exists() && kept.is_dir());
        let created = create_folder_tracked(&kept.join("a/b")).unwrap();
        std::fs::write(kept.join("a/b/mine"), b"x").unwrap();
        remove_created_folders(&created);
        assert_eq!(std::fs::read(kept.join("a/b/mine")).unwrap(), b"x");
        let file = dir.join("file");
        std::fs::write(&file, b"x").unwrap();
        let e = create_folder_tracked(&file.join("a")).unwrap_err();
        assert!(e.to_string().contains("is a file, not a folder"), "{e}");
    }

    #[test]
    fn dangling_symlinks_and_special_files_are_never_replaced() {
        let dir = scratch("symlink");
        let link = dir.join("out.png");
        std::os::unix::fs::symlink(dir.join("missing"), &link).unwrap();
        assert!(matches!(
            publish_new(&link, b"x").unwrap_err(),
            SafeIoError::Exists { .. }
        ));
        assert!(!dir.join("missing").exists());
        assert!(matches!(
            replace_regular(&link, b"x").unwrap_err(),
            SafeIoError::NotRegularFile { .. }
        ));
        assert!(matches!(
            replace_regular(Path::new("/dev/null"), b"x").unwrap_err(),
            SafeIoError::NotRegularFile { .. }
        ));
        let f = dir.join("a.txt");
        std::fs::write(&f, b"old").unwrap();
        replace_regular(&f, b"new").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"new");
    }
}
