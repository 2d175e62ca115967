//! What the world's test files share.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// A fresh path under the system's temporary folder, removed on drop.
pub struct TempDir(PathBuf);

impl TempDir {
    /// A path that does not exist yet.
    pub fn new(tag: &str) -> Self {
        static N: AtomicU64 = AtomicU64::new(0);
        let path = std::env::temp_dir().join(format!(
            "horizon-world-test-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&path);
        Self(path)
    }

    /// An empty folder.
    #[allow(dead_code)]
    pub fn created(tag: &str) -> Self {
        let dir = Self::new(tag);
        std::fs::create_dir_all(&dir.0).expect("temp dir");
        dir
    }

    /// The path.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
