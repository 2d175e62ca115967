//! Atomic, durable file writes: a reader, or a crash, sees either the old file or the whole
//! new one, never a part of it.
//!
//! A file is written to a uniquely named temporary file in the same folder (`.NAME.PID.N.tmp`),
//! made durable, renamed over its final name, and the folder is synced so that the rename is
//! durable too. Temporary files a crash leaves behind are recognised by that name and removed
//! by garbage collection.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::WorldError;

/// Writes `bytes` to `path` atomically and durably (see the module docs).
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), WorldError> {
    let tmp = write_temporary(path, bytes)?;
    let result = (|| {
        std::fs::File::open(&tmp)?.sync_all()?;
        std::fs::rename(&tmp, path)?;
        sync_folder(path);
        Ok(())
    })();
    result.map_err(|e: std::io::Error| {
        let _ = std::fs::remove_file(&tmp);
        WorldError::io(path, e)
    })
}

/// Writes `bytes` to a new, uniquely named temporary file in `path`'s folder (created if
/// need be), not yet synced; returns its path.
pub(crate) fn write_temporary(path: &Path, bytes: &[u8]) -> Result<PathBuf, WorldError> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let dir = folder_of(path);
    std::fs::create_dir_all(dir).map_err(|e| WorldError::io(dir, e))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(
        ".{name}.{}.{}.tmp",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = std::fs::File::create(&tmp).and_then(|mut file| file.write_all(bytes));
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        WorldError::io(path, e)
    })?;
    Ok(tmp)
}

/// Whether a file name is one [`write_temporary`] gives.
pub(crate) fn is_temporary(name: &str) -> bool {
    name.starts_with('.') && name.ends_with(".tmp")
}

/// Makes `files` durable: on Linux one `syncfs` of the file system holding `root` (every
/// dirty page of it, in one flush, far cheaper than an fsync per file), else, or if that
/// fails, an fsync of each file.
pub(crate) fn sync_files<'a>(
    root: &Path,
    files: impl Iterator<Item = &'a Path>,
) -> Result<(), WorldError> {
    #[cfg(target_os = "linux")]
    {
        if let Ok(d) = std::fs::File::open(root) {
            if rustix::fs::syncfs(&d).is_ok() {
                return Ok(());
            }
        }
    }
    let _ = root;
    for f in files {
        std::fs::File::open(f)
            .and_then(|file| file.sync_all())
            .map_err(|e| WorldError::io(f, e))?;
    }
    Ok(())
}

/// Syncs the folder holding `path`, so that a rename into it is durable (not supported on
/// every platform; a failure is not an error).
pub(crate) fn sync_folder(path: &Path) {
    sync_dir(folder_of(path));
}

/// Syncs the folder `dir` itself (see [`sync_folder`]).
pub(crate) fn sync_dir(dir: &Path) {
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

/// The folder holding `path` (`.` for a bare file name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_atomic_write_replaces_the_whole_file_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("horizon-durable-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("a.json");
        write_atomically(&path, b"first").expect("write");
        write_atomically(&path, b"second, longer").expect("rewrite");
        assert_eq!(std::fs::read(&path).expect("read"), b"second, longer");
        let names: Vec<String> = std::fs::read_dir(&dir)
            .expect("dir")
            .filter_map(Result::ok)
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["a.json"]);
        assert!(is_temporary(".a.json.1.2.tmp") && !is_temporary("a.json"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
