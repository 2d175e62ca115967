//! The aggregate store of a world directory: [`AggregateDir`], the
//! [`horizon_aggregate::AggregateStore`] the product's rebuild writes through.
//!
//! ```text
//! DIR/aggregates/<hash>.glb         every aggregate, named by the content hash of its bytes
//! DIR/aggregates/parts/<hash>.glb   what a node hands its parent (model versions)
//! DIR/aggregates/journal.jsonl      one line per aggregate built: its key and entry
//! DIR/aggregates/manifest.json      the current aggregate of every node of the tree
//! ```
//!
//! Files are immutable and content-addressed; a changed aggregate gets a new name. A build
//! writes in batches ([`AggregateDir::stage_blob`] and [`AggregateDir::stage_entry`], then
//! [`AggregateDir::commit`] once per tree level): the level's temporary files are made
//! durable together (`durable::sync_files`), then renamed, then each folder is synced once,
//! and only then are the level's journal lines appended. The manifest is written last, so a
//! crash mid-build leaves the previous manifest valid and naming files that all exist, and
//! the journal lets the next build reuse what the crashed one finished (a torn last line is
//! ignored). A crash loses at most the level being built, whose files are still temporary.
//!
//! After a build completes, [`AggregateDir::collect_garbage`] keeps the store at the size of
//! one build: the journal is rewritten to the manifest's entries, then every GLB and parts
//! file the manifest does not name is deleted (a crash in between only leaves files behind).

use std::collections::{HashMap, HashSet};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

use horizon_aggregate::{
    AggregateEntry, AggregateError, AggregateManifest, AggregateStore, NodeStats, PartList,
};
use serde::{Deserialize, Serialize};

use crate::durable::{is_temporary, sync_files, sync_folder, write_atomically, write_temporary};
use crate::error::WorldError;
use crate::hash::content_hash;

/// What [`AggregateDir::collect_garbage`] removed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Garbage {
    /// Files deleted.
    pub files: usize,
    /// Their bytes.
    pub bytes: u64,
}

/// The two kinds of blob an aggregate store holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlobKind {
    /// An aggregate's GLB, what a client draws: `<root>/<hash>.glb`.
    Aggregate,
    /// A handoff's parts file, what a parent is built from: `<root>/parts/<hash>.glb`.
    Parts,
}

/// The aggregate store in one folder of a world directory (see the module docs).
#[derive(Debug)]
pub struct AggregateDir {
    root: PathBuf,
    journal: Mutex<Option<std::fs::File>>,
    /// What was staged since the last commit.
    staged: Mutex<Staged>,
    /// Held by a commit from taking the staged writes until their journal lines are
    /// appended, so that a later commit (whose lines may name files an earlier one took)
    /// appends only after those files are in place.
    committing: Mutex<()>,
}

/// Writes not yet committed: temporary files, not yet durable, under their own names.
#[derive(Debug, Default)]
struct Staged {
    /// (temporary file, final path), in the order written.
    files: Vec<(PathBuf, PathBuf)>,
    /// The final paths among them (a content-addressed file is written once).
    paths: HashSet<PathBuf>,
    /// Journal lines of the staged entries.
    journal: Vec<u8>,
}

impl Drop for AggregateDir {
    /// Staged files that were never committed are not durable: they go (a build that stops
    /// with an error commits first).
    fn drop(&mut self) {
        if let Ok(staged) = self.staged.get_mut() {
            for (tmp, _) in &staged.files {
                let _ = std::fs::remove_file(tmp);
            }
        }
    }
}

impl AggregateDir {
    /// The store in folder `root` (created on first write).
    pub fn new(root: &Path) -> Self {
        Self {
            root: root.to_path_buf(),
            journal: Mutex::new(None),
            staged: Mutex::new(Staged::default()),
            committing: Mutex::new(()),
        }
    }

    /// The folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Where the blob of `kind` named `hash` lives.
    pub fn blob(&self, kind: BlobKind, hash: &str) -> PathBuf {
        match kind {
            BlobKind::Aggregate => self.root.join(format!("{hash}.glb")),
            BlobKind::Parts => self.root.join("parts").join(format!("{hash}.glb")),
        }
    }

    /// `<root>/manifest.json`.
    pub fn manifest_path(&self) -> PathBuf {
        self.root.join("manifest.json")
    }

    /// `<root>/journal.jsonl`.
    pub fn journal_path(&self) -> PathBuf {
        self.root.join("journal.jsonl")
    }

    /// The current manifest, if a build ever completed.
    pub fn read_manifest(&self) -> Result<Option<AggregateManifest>, AggregateError> {
        let path = self.manifest_path();
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(AggregateError::io(path, e)),
        };
        serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|e| AggregateError::Corrupt {
                path,
                reason: e.to_string(),
            })
    }

    /// Every entry recorded, by key: the manifest's, then the journal's (later lines win),
    /// whether or not its files exist. A manifest that does not parse is skipped (the next
    /// build replaces it), so a damaged file never blocks a rebuild; so is a torn journal
    /// line.
    pub fn entries(&self) -> Result<HashMap<String, AggregateEntry>, AggregateError> {
        let mut out = HashMap::new();
        match self.read_manifest() {
            Ok(Some(m)) => {
                for e in m.nodes.into_values() {
                    out.insert(e.key.clone(), e);
                }
            }
            Ok(None) | Err(AggregateError::Corrupt { .. }) => {}
            Err(e) => return Err(e),
        }
        let path = self.journal_path();
        match std::fs::read_to_string(&path) {
            Ok(text) => {
                for line in text.lines() {
                    if let Ok(e) = serde_json::from_str::<AggregateEntry>(line) {
                        out.insert(e.key.clone(), e);
                    }
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(AggregateError::io(path, e)),
        }
        Ok(out)
    }

    /// Whether every file `entry` names is in the store.
    pub fn holds(&self, entry: &AggregateEntry) -> bool {
        self.blob(BlobKind::Aggregate, &entry.glb).exists()
            && entry
                .parts
                .as_ref()
                .is_none_or(|p| self.blob(BlobKind::Parts, p).exists())
    }

    /// Writes a blob as a temporary file, to be put in place by the next
    /// [`AggregateDir::commit`]; returns its content hash. A blob already stored or staged
    /// is not written again.
    pub fn stage_blob(&self, kind: BlobKind, bytes: &[u8]) -> Result<String, AggregateError> {
        let hash = content_hash(bytes);
        let path = self.blob(kind, &hash);
        if path.exists() || self.lock_staged()?.paths.contains(&path) {
            return Ok(hash);
        }
        let tmp = write_temporary(&path, bytes).map_err(AggregateError::from_world)?;
        let mut staged = self.lock_staged()?;
        if staged.paths.insert(path.clone()) {
            staged.files.push((tmp, path));
        } else {
            // Another thread staged the same content meanwhile.
            let _ = std::fs::remove_file(&tmp);
        }
        Ok(hash)
    }

    /// Holds back `entry`'s journal line until the next [`AggregateDir::commit`].
    pub fn stage_entry(&self, entry: &AggregateEntry) -> Result<(), AggregateError> {
        let line = self.journal_line(entry)?;
        self.lock_staged()?.journal.extend(line);
        Ok(())
    }

    /// Makes every staged file durable and puts it in place, then journals the staged
    /// entries. Nothing staged: nothing done.
    pub fn commit_staged(&self) -> Result<(), AggregateError> {
        let _one_at_a_time = self
            .committing
            .lock()
            .map_err(|_| AggregateError::Tree("commit lock poisoned".into()))?;
        let staged = std::mem::take(&mut *self.lock_staged()?);
        if staged.journal.is_empty() && staged.files.is_empty() {
            return Ok(());
        }
        let result = self.put_in_place(&staged.files);
        if result.is_err() {
            for (tmp, _) in &staged.files {
                let _ = std::fs::remove_file(tmp);
            }
        }
        result?;
        self.append_journal(&staged.journal)
    }

    /// Durable, then renamed, then each folder synced once.
    fn put_in_place(&self, files: &[(PathBuf, PathBuf)]) -> Result<(), AggregateError> {
        if files.is_empty() {
            return Ok(());
        }
        sync_files(&self.root, files.iter().map(|(tmp, _)| tmp.as_path()))
            .map_err(AggregateError::from_world)?;
        let mut synced: Vec<&Path> = Vec::new();
        for (tmp, path) in files {
            std::fs::rename(tmp, path).map_err(|e| AggregateError::io(path, e))?;
        }
        for (_, path) in files {
            let folder = path.parent().unwrap_or(Path::new("."));
            if !synced.contains(&folder) {
                sync_folder(path);
                synced.push(folder);
            }
        }
        Ok(())
    }

    /// The staged writes, locked.
    fn lock_staged(&self) -> Result<MutexGuard<'_, Staged>, AggregateError> {
        self.staged
            .lock()
            .map_err(|_| AggregateError::Tree("staging lock poisoned".into()))
    }

    /// One journal line: the entry as JSON and a newline.
    fn journal_line(&self, entry: &AggregateEntry) -> Result<Vec<u8>, AggregateError> {
        let mut line = serde_json::to_vec(entry).map_err(|e| AggregateError::Corrupt {
            path: self.journal_path(),
            reason: e.to_string(),
        })?;
        line.push(b'\n');
        Ok(line)
    }

    /// The open journal file (`None` until the first append), locked.
    fn lock_journal(&self) -> Result<MutexGuard<'_, Option<std::fs::File>>, AggregateError> {
        self.journal
            .lock()
            .map_err(|_| AggregateError::Tree("journal lock poisoned".into()))
    }

    /// Appends journal lines.
    fn append_journal(&self, lines: &[u8]) -> Result<(), AggregateError> {
        let path = self.journal_path();
        let mut guard = self.lock_journal()?;
        if guard.is_none() {
            std::fs::create_dir_all(&self.root).map_err(|e| AggregateError::io(&self.root, e))?;
            let file = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&path)
                .map_err(|e| AggregateError::io(&path, e))?;
            *guard = Some(file);
        }
        if let Some(file) = guard.as_mut() {
            file.write_all(lines)
                .map_err(|e| AggregateError::io(&path, e))?;
        }
        Ok(())
    }

    /// Removes what `manifest` no longer needs: the journal is rewritten (atomically) to
    /// hold just its entries, then every aggregate and parts file it does not name, and every
    /// temporary file a crashed write left, is deleted. Files the manifest names are never
    /// touched, so a crash at any point leaves it valid.
    pub fn collect_garbage(&self, manifest: &AggregateManifest) -> Result<Garbage, AggregateError> {
        let mut journal = Vec::new();
        for e in manifest.nodes.values() {
            journal.extend(self.journal_line(e)?);
        }
        {
            // Later appends must go to the new file, not the replaced one.
            let mut guard = self.lock_journal()?;
            write_atomically(&self.journal_path(), &journal).map_err(AggregateError::from_world)?;
            *guard = None;
        }
        let glbs: HashSet<&str> = manifest.nodes.values().map(|e| e.glb.as_str()).collect();
        let parts: HashSet<&str> = manifest
            .nodes
            .values()
            .filter_map(|e| e.parts.as_deref())
            .collect();
        let mut removed = Garbage::default();
        for (dir, keep) in [
            (self.root.clone(), &glbs),
            (self.root.join("parts"), &parts),
        ] {
            let entries = match std::fs::read_dir(&dir) {
                Ok(entries) => entries,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
                Err(e) => return Err(AggregateError::io(&dir, e)),
            };
            for entry in entries {
                let entry = entry.map_err(|e| AggregateError::io(&dir, e))?;
                let name = entry.file_name().to_string_lossy().into_owned();
                let stale = match name.strip_suffix(".glb") {
                    Some(hash) if !name.starts_with('.') => !keep.contains(hash),
                    _ => is_temporary(&name),
                };
                if stale {
                    let len = entry.metadata().map(|m| m.len()).unwrap_or(0);
                    std::fs::remove_file(entry.path())
                        .map_err(|e| AggregateError::io(entry.path(), e))?;
                    removed.files += 1;
                    removed.bytes += len;
                }
            }
        }
        Ok(removed)
    }
}

impl AggregateStore for AggregateDir {
    fn known(&self) -> Result<HashMap<String, AggregateEntry>, AggregateError> {
        let mut out = self.entries()?;
        out.retain(|_, e| self.holds(e));
        Ok(out)
    }

    fn manifest(&self) -> Result<Option<AggregateManifest>, AggregateError> {
        self.read_manifest()
    }

    /// Writes the GLB and parts as temporary files and holds back the journal line, until
    /// [`AggregateStore::commit`]: before that, neither the files nor the entry are in the
    /// store.
    fn stage(
        &self,
        key: String,
        glb: &[u8],
        parts: Option<(&[u8], PartList)>,
        stats: NodeStats,
    ) -> Result<AggregateEntry, AggregateError> {
        let glb = self.stage_blob(BlobKind::Aggregate, glb)?;
        let (parts, part_keys) = match parts {
            Some((bytes, keys)) => (Some(self.stage_blob(BlobKind::Parts, bytes)?), keys),
            None => (None, Vec::new()),
        };
        let entry = AggregateEntry {
            key,
            glb,
            parts,
            part_keys,
            stats,
        };
        self.stage_entry(&entry)?;
        Ok(entry)
    }

    fn commit(&self) -> Result<(), AggregateError> {
        self.commit_staged()
    }

    fn parts(&self, hash: &str) -> Result<Vec<u8>, AggregateError> {
        let path = self.blob(BlobKind::Parts, hash);
        std::fs::read(&path).map_err(|e| AggregateError::io(path, e))
    }

    fn write_manifest(&self, manifest: &AggregateManifest) -> Result<(), AggregateError> {
        let path = self.manifest_path();
        let bytes = serde_json::to_vec(manifest).map_err(|e| AggregateError::Corrupt {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        write_atomically(&path, &bytes).map_err(AggregateError::from_world)
    }
}

/// How a world error reaches the rebuild, which reports store failures as its own.
trait FromWorld {
    fn from_world(e: WorldError) -> Self;
}

impl FromWorld for AggregateError {
    fn from_world(e: WorldError) -> Self {
        match e {
            WorldError::Io { path, source } => AggregateError::Io { path, source },
            WorldError::Aggregate(e) => e,
            other => AggregateError::Tree(other.to_string()),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use horizon_aggregate::AggregateOptions;

    use super::*;

    /// Stages and commits one aggregate.
    fn put(
        store: &AggregateDir,
        key: &str,
        glb: &[u8],
        parts: Option<(&[u8], PartList)>,
    ) -> AggregateEntry {
        let e = store
            .stage(key.into(), glb, parts, NodeStats::default())
            .expect("stage");
        store.commit().expect("commit");
        e
    }

    #[test]
    fn a_torn_journal_line_is_ignored() {
        let dir = std::env::temp_dir().join(format!("horizon-store-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = AggregateDir::new(&dir);
        let e = put(&store, "k1", b"glb bytes", None);
        std::fs::OpenOptions::new()
            .append(true)
            .open(store.journal_path())
            .and_then(|mut f| f.write_all(b"{\"key\":\"k2\",\"gl"))
            .expect("tear");
        let known = store.known().expect("known");
        assert_eq!(known.len(), 1);
        assert_eq!(known["k1"], e);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn garbage_collection_keeps_exactly_what_the_manifest_names() {
        let dir = std::env::temp_dir().join(format!("horizon-gc-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = AggregateDir::new(&dir);
        let parts = |b: &'static [u8]| Some((b, Vec::new()));
        let old = put(&store, "old", b"old glb", parts(b"old parts"));
        let kept = put(&store, "kept", b"kept glb", parts(b"kept parts"));
        std::fs::write(dir.join(".x.glb.1.2.tmp"), b"torn").expect("tmp");
        let manifest = AggregateManifest {
            format: horizon_aggregate::FORMAT,
            options: AggregateOptions::default(),
            atlas: true,
            root_key: "kept".into(),
            nodes: BTreeMap::from([(0, kept.clone())]),
        };
        store.write_manifest(&manifest).expect("manifest");
        let removed = store.collect_garbage(&manifest).expect("gc");
        assert_eq!(removed.files, 3, "old GLB, old parts, temporary file");
        assert!(!store.blob(BlobKind::Aggregate, &old.glb).exists());
        assert!(!store
            .blob(BlobKind::Parts, old.parts.as_deref().expect("parts"))
            .exists());
        assert!(store.blob(BlobKind::Aggregate, &kept.glb).exists());
        assert!(store
            .blob(BlobKind::Parts, kept.parts.as_deref().expect("parts"))
            .exists());
        // The journal now holds the manifest's entries alone, and appends still work.
        let known = store.known().expect("known");
        assert_eq!(known.len(), 1);
        assert_eq!(known["kept"], kept);
        put(&store, "new", b"new glb", None);
        assert_eq!(store.known().expect("known").len(), 2);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn staged_writes_appear_only_on_commit() {
        let dir = std::env::temp_dir().join(format!("horizon-stage-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = AggregateDir::new(&dir);
        let parts = Some((&b"staged parts"[..], Vec::new()));
        let e = store
            .stage("k1".into(), b"staged glb", parts, NodeStats::default())
            .expect("stage");
        // The same content staged twice is written once.
        let twin = store
            .stage("k2".into(), b"staged glb", None, NodeStats::default())
            .expect("stage");
        assert_eq!(twin.glb, e.glb);
        // Before the commit: temporary files only, and no entry.
        assert!(!store.blob(BlobKind::Aggregate, &e.glb).exists());
        assert!(!store
            .blob(BlobKind::Parts, e.parts.as_deref().expect("parts"))
            .exists());
        assert!(store.known().expect("known").is_empty());
        store.commit().expect("commit");
        assert!(store.blob(BlobKind::Aggregate, &e.glb).exists());
        assert!(store
            .blob(BlobKind::Parts, e.parts.as_deref().expect("parts"))
            .exists());
        let known = store.known().expect("known");
        assert_eq!(known.len(), 2);
        assert_eq!(known["k1"], e);
        // No temporary file is left, and an empty commit does nothing.
        store.commit().expect("empty commit");
        let temporaries = |d: &Path| {
            std::fs::read_dir(d)
                .map(|r| {
                    r.filter_map(Result::ok)
                        .filter(|f| f.file_name().to_string_lossy().ends_with(".tmp"))
                        .count()
                })
                .unwrap_or(0)
        };
        assert_eq!(temporaries(&dir) + temporaries(&dir.join("parts")), 0);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_store_dropped_before_its_commit_leaves_nothing_behind() {
        let dir = std::env::temp_dir().join(format!("horizon-uncommitted-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let kept = {
            let store = AggregateDir::new(&dir);
            let kept = put(&store, "kept", b"kept glb", None);
            store
                .stage("lost".into(), b"lost glb", None, NodeStats::default())
                .expect("stage");
            kept
        };
        let store = AggregateDir::new(&dir);
        let known = store.known().expect("known");
        assert_eq!(known.len(), 1);
        assert_eq!(known["kept"], kept);
        let files: Vec<String> = std::fs::read_dir(&dir)
            .expect("dir")
            .filter_map(Result::ok)
            .map(|f| f.file_name().to_string_lossy().into_owned())
            .collect();
        assert!(files.iter().all(|f| !f.ends_with(".tmp")), "{files:?}");
        assert_eq!(files.iter().filter(|f| f.ends_with(".glb")).count(), 1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_damaged_manifest_still_leaves_every_journalled_aggregate_known() {
        let dir = std::env::temp_dir().join(format!("horizon-damaged-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = AggregateDir::new(&dir);
        let e = put(&store, "k1", b"glb", None);
        std::fs::write(store.manifest_path(), b"{ not json").expect("damage");
        assert!(store.manifest().is_err());
        assert_eq!(store.known().expect("known")["k1"], e);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
