//! [`MeasuringStore`]: an aggregate store that keeps everything but the aggregate GLBs
//! themselves. Their hashes and sizes are journalled and their bytes dropped; parts files,
//! journal and manifest are kept (a parent is built from its children's parts). The report's
//! unoptimised baseline lives in one, since only its sizes are ever read and its GLBs, each
//! carrying every source texture below it, would fill gigabytes.
//!
//! ```text
//! DIR/parts/<hash>.glb   what a node hands its parent
//! DIR/journal.jsonl      one line per aggregate built: its key and entry
//! DIR/manifest.json      the last build's aggregate of every node it built
//! ```

use std::collections::{HashMap, HashSet};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use horizon_aggregate::{
    AggregateEntry, AggregateError, AggregateManifest, AggregateStore, NodeStats, PartList,
};
use horizon_world::{content_hash, write_atomically};

/// An [`AggregateStore`] that measures aggregates without keeping them (module docs).
#[derive(Debug)]
pub struct MeasuringStore {
    root: PathBuf,
    /// Journal lines of the entries staged since the last commit.
    staged: Mutex<Vec<u8>>,
}

impl MeasuringStore {
    /// The store in folder `root` (created on first write).
    pub fn new(root: &Path) -> Self {
        Self {
            root: root.to_path_buf(),
            staged: Mutex::new(Vec::new()),
        }
    }

    fn parts_path(&self, hash: &str) -> PathBuf {
        self.root.join("parts").join(format!("{hash}.glb"))
    }

    fn journal_path(&self) -> PathBuf {
        self.root.join("journal.jsonl")
    }

    fn manifest_path(&self) -> PathBuf {
        self.root.join("manifest.json")
    }

    /// Rewrites the journal to `manifest`'s entries and deletes every parts file it does not
    /// name, so the store holds one build. Returns the files deleted.
    pub fn collect_garbage(&self, manifest: &AggregateManifest) -> Result<usize, AggregateError> {
        let mut journal = Vec::new();
        for e in manifest.nodes.values() {
            journal.extend(line(e)?);
        }
        write_atomically(&self.journal_path(), &journal).map_err(io)?;
        let keep: HashSet<String> = manifest
            .nodes
            .values()
            .filter_map(|e| e.parts.as_ref().map(|p| format!("{p}.glb")))
            .collect();
        let mut removed = 0;
        let dir = self.root.join("parts");
        if let Ok(entries) = std::fs::read_dir(&dir) {
            for entry in entries.flatten() {
                let name = entry.file_name().to_string_lossy().into_owned();
                if !keep.contains(&name) && std::fs::remove_file(entry.path()).is_ok() {
                    removed += 1;
                }
            }
        }
        Ok(removed)
    }
}

impl AggregateStore for MeasuringStore {
    /// The manifest's entries and the journal's (later lines win) whose parts file is kept;
    /// a damaged manifest or a torn journal line is skipped.
    fn known(&self) -> Result<HashMap<String, AggregateEntry>, AggregateError> {
        let mut out = HashMap::new();
        if let Ok(Some(m)) = self.manifest() {
            out.extend(m.nodes.into_values().map(|e| (e.key.clone(), e)));
        }
        if let Ok(text) = std::fs::read_to_string(self.journal_path()) {
            for l in text.lines() {
                if let Ok(e) = serde_json::from_str::<AggregateEntry>(l) {
                    out.insert(e.key.clone(), e);
                }
            }
        }
        out.retain(|_, e| e.parts.as_ref().is_none_or(|p| self.parts_path(p).exists()));
        Ok(out)
    }

    fn manifest(&self) -> Result<Option<AggregateManifest>, AggregateError> {
        let path = self.manifest_path();
        match std::fs::read(&path) {
            Ok(bytes) => {
                serde_json::from_slice(&bytes)
                    .map(Some)
                    .map_err(|e| AggregateError::Corrupt {
                        path,
                        reason: e.to_string(),
                    })
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(AggregateError::io(path, e)),
        }
    }

    fn stage(
        &self,
        key: String,
        glb: &[u8],
        parts: Option<(&[u8], PartList)>,
        stats: NodeStats,
    ) -> Result<AggregateEntry, AggregateError> {
        let (parts, part_keys) = match parts {
            Some((bytes, keys)) => {
                let hash = content_hash(bytes);
                let path = self.parts_path(&hash);
                if !path.exists() {
                    write_atomically(&path, bytes).map_err(io)?;
                }
                (Some(hash), keys)
            }
            None => (None, Vec::new()),
        };
        let entry = AggregateEntry {
            key,
            glb: content_hash(glb),
            parts,
            part_keys,
            stats,
        };
        self.staged
            .lock()
            .map_err(|_| AggregateError::Tree("staging lock poisoned".into()))?
            .extend(line(&entry)?);
        Ok(entry)
    }

    /// The baseline it measures has no impostors: nothing to keep.
    fn stage_blob(&self, _bytes: &[u8]) -> Result<String, AggregateError> {
        Err(AggregateError::Tree(
            "the measuring store keeps no impostors".into(),
        ))
    }

    fn commit(&self) -> Result<(), AggregateError> {
        let lines = std::mem::take(
            &mut *self
                .staged
                .lock()
                .map_err(|_| AggregateError::Tree("staging lock poisoned".into()))?,
        );
        if lines.is_empty() {
            return Ok(());
        }
        std::fs::create_dir_all(&self.root).map_err(|e| AggregateError::io(&self.root, e))?;
        let path = self.journal_path();
        std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .and_then(|mut f| f.write_all(&lines))
            .map_err(|e| AggregateError::io(path, e))
    }

    fn parts(&self, hash: &str) -> Result<Vec<u8>, AggregateError> {
        let path = self.parts_path(hash);
        std::fs::read(&path).map_err(|e| AggregateError::io(path, e))
    }

    fn write_manifest(&self, manifest: &AggregateManifest) -> Result<(), AggregateError> {
        let bytes = serde_json::to_vec(manifest).map_err(|e| AggregateError::Corrupt {
            path: self.manifest_path(),
            reason: e.to_string(),
        })?;
        write_atomically(&self.manifest_path(), &bytes).map_err(io)
    }
}

/// An entry as one journal line.
fn line(entry: &AggregateEntry) -> Result<Vec<u8>, AggregateError> {
    let mut l = serde_json::to_vec(entry).map_err(|e| AggregateError::Corrupt {
        path: "journal".into(),
        reason: e.to_string(),
    })?;
    l.push(b'\n');
    Ok(l)
}

fn io(e: horizon_world::WorldError) -> AggregateError {
    match e {
        horizon_world::WorldError::Io { path, source } => AggregateError::Io { path, source },
        other => AggregateError::Tree(other.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_measuring_store_journals_sizes_but_writes_no_glb() {
        let dir = std::env::temp_dir().join(format!("horizon-measure-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = MeasuringStore::new(&dir);
        let e = store
            .stage(
                "k1".into(),
                b"glb bytes",
                Some((b"parts", Vec::new())),
                NodeStats::default(),
            )
            .expect("stage");
        assert!(
            store.known().expect("known").is_empty(),
            "not before the commit"
        );
        store.commit().expect("commit");
        let files: Vec<String> = walk(&dir);
        assert!(files.iter().all(|f| !f.contains(&e.glb)), "{files:?}");
        let parts = e.parts.as_deref().expect("parts");
        assert_eq!(store.parts(parts).expect("parts"), b"parts");
        // Known (for reuse) although its GLB was never written.
        assert_eq!(store.known().expect("known")["k1"], e);
        let _ = std::fs::remove_dir_all(&dir);
    }

    fn walk(dir: &Path) -> Vec<String> {
        let mut out = Vec::new();
        for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            let path = entry.path();
            if path.is_dir() {
                out.extend(walk(&path));
            } else {
                out.push(path.display().to_string());
            }
        }
        out
    }
}
