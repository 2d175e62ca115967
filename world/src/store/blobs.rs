//! [`BlobDir`]: the embedded [`BlobStore`], a folder of immutable files named by their content
//! hash, fanned out by the hash's first two digits (`blobs/ab/abcdef....`).
//!
//! A blob is written to a temporary file, made durable, renamed into place, and its folder
//! synced (`durable.rs`), so a reader or a crash sees the whole blob or none of it. A batch
//! ([`BlobStore::stage`], then [`BlobStore::commit_staged`]) makes all its files durable with
//! one flush. Temporary files a crash leaves behind are removed by [`BlobStore::sweep`].

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::durable::{is_temporary, sync_dir, sync_files, write_atomically, write_temporary};
use crate::error::WorldError;
use crate::hash::{content_hash, is_content_hash};
use crate::store::BlobStore;

/// The content-addressed blob folder (see the module docs).
#[derive(Debug)]
pub struct BlobDir {
    root: PathBuf,
    staged: Mutex<Staged>,
}

/// Blobs written as temporary files, waiting for the commit.
#[derive(Debug, Default)]
struct Staged {
    /// (temporary file, final path), in the order written.
    files: Vec<(PathBuf, PathBuf)>,
    /// Their hashes (a blob is written once).
    hashes: HashSet<String>,
}

impl Drop for BlobDir {
    /// Staged blobs never committed were never promised: they go.
    fn drop(&mut self) {
        if let Ok(staged) = self.staged.get_mut() {
            for (tmp, _) in &staged.files {
                let _ = std::fs::remove_file(tmp);
            }
        }
    }
}

impl BlobDir {
    /// The blob folder at `root` (created on first write).
    pub fn new(root: &Path) -> Self {
        Self {
            root: root.to_path_buf(),
            staged: Mutex::new(Staged::default()),
        }
    }

    /// Where the blob named `hash` lives.
    fn path(&self, hash: &str) -> PathBuf {
        let fan = hash.get(..2).unwrap_or("__");
        self.root.join(fan).join(hash)
    }

    /// The path of `hash`, refusing anything that is not a content hash (so no name can
    /// reach outside the folder).
    fn checked(&self, hash: &str) -> Result<PathBuf, WorldError> {
        if is_content_hash(hash) {
            Ok(self.path(hash))
        } else {
            Err(WorldError::NotFound(format!("no blob {hash:?}")))
        }
    }

    fn lock(&self) -> Result<std::sync::MutexGuard<'_, Staged>, WorldError> {
        self.staged
            .lock()
            .map_err(|_| WorldError::Inconsistent("blob staging lock poisoned".into()))
    }
}

impl BlobStore for BlobDir {
    fn put(&self, bytes: &[u8]) -> Result<String, WorldError> {
        let hash = content_hash(bytes);
        let path = self.path(&hash);
        if !path.exists() {
            write_atomically(&path, bytes)?;
        }
        Ok(hash)
    }

    fn stage(&self, bytes: &[u8]) -> Result<String, WorldError> {
        let hash = content_hash(bytes);
        let path = self.path(&hash);
        if path.exists() || self.lock()?.hashes.contains(&hash) {
            return Ok(hash);
        }
        let tmp = write_temporary(&path, bytes)?;
        let mut staged = self.lock()?;
        if staged.hashes.insert(hash.clone()) {
            staged.files.push((tmp, path));
        } else {
            // Another thread staged the same bytes meanwhile.
            let _ = std::fs::remove_file(&tmp);
        }
        Ok(hash)
    }

    fn commit_staged(&self) -> Result<(), WorldError> {
        let staged = std::mem::take(&mut *self.lock()?);
        if staged.files.is_empty() {
            return Ok(());
        }
        let result = (|| {
            sync_files(
                &self.root,
                staged.files.iter().map(|(tmp, _)| tmp.as_path()),
            )?;
            let mut folders: Vec<&Path> = Vec::new();
            for (tmp, path) in &staged.files {
                std::fs::rename(tmp, path).map_err(|e| WorldError::io(path, e))?;
                let folder = path.parent().unwrap_or(Path::new("."));
                if !folders.contains(&folder) {
                    folders.push(folder);
                }
            }
            for folder in folders {
                sync_dir(folder);
            }
            Ok(())
        })();
        if result.is_err() {
            for (tmp, _) in &staged.files {
                let _ = std::fs::remove_file(tmp);
            }
        }
        result
    }

    fn get(&self, hash: &str) -> Result<Option<Vec<u8>>, WorldError> {
        let path = match self.checked(hash) {
            Ok(p) => p,
            Err(_) => return Ok(None),
        };
        match std::fs::read(&path) {
            Ok(bytes) => Ok(Some(bytes)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(WorldError::io(path, e)),
        }
    }

    fn size(&self, hash: &str) -> Result<Option<u64>, WorldError> {
        let path = match self.checked(hash) {
            Ok(p) => p,
            Err(_) => return Ok(None),
        };
        match std::fs::metadata(&path) {
            Ok(m) => Ok(Some(m.len())),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(WorldError::io(path, e)),
        }
    }

    fn delete(&self, hash: &str) -> Result<(), WorldError> {
        let path = self.checked(hash)?;
        match std::fs::remove_file(&path) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(WorldError::io(path, e)),
        }
    }

    fn list(&self) -> Result<Vec<String>, WorldError> {
        let mut out = Vec::new();
        let fans = match std::fs::read_dir(&self.root) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(out),
            Err(e) => return Err(WorldError::io(&self.root, e)),
        };
        for fan in fans {
            let fan = fan.map_err(|e| WorldError::io(&self.root, e))?.path();
            if !fan.is_dir() {
                continue;
            }
            for entry in std::fs::read_dir(&fan).map_err(|e| WorldError::io(&fan, e))? {
                let name = entry
                    .map_err(|e| WorldError::io(&fan, e))?
                    .file_name()
                    .to_string_lossy()
                    .into_owned();
                if is_content_hash(&name) {
                    out.push(name);
                }
            }
        }
        out.sort();
        Ok(out)
    }

    fn sweep(&self) -> Result<usize, WorldError> {
        let mut removed = 0;
        let Ok(fans) = std::fs::read_dir(&self.root) else {
            return Ok(0);
        };
        for fan in fans.flatten() {
            let Ok(entries) = std::fs::read_dir(fan.path()) else {
                continue;
            };
            for entry in entries.flatten() {
                if is_temporary(&entry.file_name().to_string_lossy())
                    && std::fs::remove_file(entry.path()).is_ok()
                {
                    removed += 1;
                }
            }
        }
        Ok(removed)
    }
}
