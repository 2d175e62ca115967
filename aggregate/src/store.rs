//! The aggregate store inside a world directory (issue 6, "World directory").
//!
//! ```text
//! DIR/aggregates/<hash>.glb         every aggregate, named by the hash of its bytes
//! DIR/aggregates/parts/<hash>.glb   what a node hands its parent (model versions)
//! DIR/aggregates/journal.jsonl      one line per aggregate ever built: its key and entry
//! DIR/aggregates/manifest.json      the current aggregate of every node of the tree
//! ```
//!
//! A *measuring* store ([`AggregateStore::measuring`]) keeps everything but the aggregate GLBs
//! themselves: their hashes and sizes are journalled, their bytes dropped. The report's
//! unoptimised baseline lives in one, since only its sizes are ever read and its GLBs, each
//! carrying every source texture below it, would fill gigabytes.
//!
//! After a build completes, [`AggregateStore::collect_garbage`] keeps the store at the size of
//! one build: the journal is rewritten to the manifest's entries, then every GLB and parts
//! file the manifest does not name is deleted (a crash in between only leaves files behind).
//!
//! Files are immutable and content-addressed; a changed aggregate gets a new name. Every
//! file is written atomically: to a temporary file, made durable, renamed, and the folder
//! synced; only then is its journal line appended. The manifest is written last, so a crash
//! mid-build leaves the previous manifest valid and naming files that all exist. The journal
//! lets the next build reuse what a crashed one finished: a torn last line is ignored.
//!
//! A build writes in batches ([`AggregateStore::stage`], then [`AggregateStore::commit`]
//! once per tree level): the level's temporary files are made durable together (one
//! `syncfs` on Linux, else one fsync each), then renamed, then each folder is synced once.
//! An fsync and a folder sync per file took 18% of the city's full build. A crash loses
//! at most the level being built, whose files are still temporary (garbage collection
//! deletes them).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use serde::{Deserialize, Serialize};

use crate::error::AggregateError;
use crate::generate::NodeStats;
use crate::options::AggregateOptions;

/// Where each submesh of a parts file came from: (model content hash, submesh index) for the
/// optimised pipeline's versions; (model content hash, material index of that model) for the
/// unoptimised baseline's world-space submeshes, with an empty hash for none.
pub type PartList = Vec<(String, u32)>;

/// One node's aggregate, as the manifest and the journal record it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AggregateEntry {
    /// Hash of everything the aggregate was made from (`build.rs`, "keys").
    pub key: String,
    /// Content hash of the GLB: `aggregates/<glb>.glb`.
    pub glb: String,
    /// Content hash of the handoff parts, `aggregates/parts/<parts>.glb`, if any.
    pub parts: Option<String>,
    /// For each submesh of the parts file: where it came from ([`PartList`]).
    pub part_keys: PartList,
    /// What building it did.
    pub stats: NodeStats,
}

/// What [`AggregateStore::collect_garbage`] removed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Garbage {
    /// Files deleted.
    pub files: usize,
    /// Their bytes.
    pub bytes: u64,
}

/// `aggregates/manifest.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AggregateManifest {
    /// [`crate::FORMAT`].
    pub format: u32,
    /// The options every aggregate was built with.
    pub options: AggregateOptions,
    /// Whether aggregates were atlased.
    pub atlas: bool,
    /// Key of the root's aggregate (identifies the whole build).
    pub root_key: String,
    /// Per node number, its aggregate.
    pub nodes: BTreeMap<u32, AggregateEntry>,
}

/// Paths and writes of one aggregate store.
#[derive(Debug)]
pub struct AggregateStore {
    root: PathBuf,
    journal: Mutex<Option<std::fs::File>>,
    /// Whether aggregate GLBs are written (false for a measuring store).
    keep_glbs: bool,
    /// What [`AggregateStore::stage`] wrote since the last commit.
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

impl Drop for AggregateStore {
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

impl AggregateStore {
    /// The store in folder `root` (created on first write).
    pub fn new(root: &Path) -> Self {
        Self {
            root: root.to_path_buf(),
            journal: Mutex::new(None),
            keep_glbs: true,
            staged: Mutex::new(Staged::default()),
            committing: Mutex::new(()),
        }
    }

    /// A store in `root` that journals each aggregate's hash and size but never writes its
    /// GLB (parts files, journal and manifest are kept as usual): for aggregates that are
    /// only measured.
    pub fn measuring(root: &Path) -> Self {
        let mut store = Self::new(root);
        store.keep_glbs = false;
        store
    }

    /// The folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `<root>/<hash>.glb`.
    pub fn glb(&self, hash: &str) -> PathBuf {
        self.root.join(format!("{hash}.glb"))
    }

    /// `<root>/parts/<hash>.glb`.
    pub fn parts(&self, hash: &str) -> PathBuf {
        self.root.join("parts").join(format!("{hash}.glb"))
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
    pub fn manifest(&self) -> Result<Option<AggregateManifest>, AggregateError> {
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

    /// Every aggregate this store knows by key: the manifest's, then the journal's (later
    /// lines win), keeping only those whose files exist (for a measuring store, whose GLBs
    /// are never written, their parts files). A manifest that does not parse is
    /// skipped (the next build replaces it), so a damaged file never blocks a rebuild.
    pub fn known(&self) -> Result<HashMap<String, AggregateEntry>, AggregateError> {
        let mut out = HashMap::new();
        match self.manifest() {
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
                    // A crash can tear the last line; anything unparsable is skipped.
                    if let Ok(e) = serde_json::from_str::<AggregateEntry>(line) {
                        out.insert(e.key.clone(), e);
                    }
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(AggregateError::io(path, e)),
        }
        out.retain(|_, e| self.holds(e));
        Ok(out)
    }

    /// Whether every file `entry` names is in the store (for a measuring store, whose GLBs
    /// are never written, its parts file).
    pub fn holds(&self, entry: &AggregateEntry) -> bool {
        (!self.keep_glbs || self.glb(&entry.glb).exists())
            && entry.parts.as_ref().is_none_or(|p| self.parts(p).exists())
    }

    /// Stores an aggregate's GLB (unless the store is measuring) and parts, then journals its
    /// entry: [`AggregateStore::stage`] and [`AggregateStore::commit`].
    pub fn put(
        &self,
        key: String,
        glb: &[u8],
        parts: Option<(&[u8], PartList)>,
        stats: NodeStats,
    ) -> Result<AggregateEntry, AggregateError> {
        let entry = self.stage(key, glb, parts, stats)?;
        self.commit()?;
        Ok(entry)
    }

    /// Writes an aggregate's GLB (unless the store is measuring) and parts as temporary files
    /// and holds back its journal line, until [`AggregateStore::commit`]: before that, neither
    /// the files nor the entry are in the store.
    pub fn stage(
        &self,
        key: String,
        glb: &[u8],
        parts: Option<(&[u8], PartList)>,
        stats: NodeStats,
    ) -> Result<AggregateEntry, AggregateError> {
        let glb_hash = content_hash(glb);
        if self.keep_glbs {
            self.stage_file(self.glb(&glb_hash), glb)?;
        }
        let (parts_hash, part_keys) = match parts {
            Some((bytes, keys)) => {
                let h = content_hash(bytes);
                self.stage_file(self.parts(&h), bytes)?;
                (Some(h), keys)
            }
            None => (None, Vec::new()),
        };
        let entry = AggregateEntry {
            key,
            glb: glb_hash,
            parts: parts_hash,
            part_keys,
            stats,
        };
        let line = self.journal_line(&entry)?;
        self.lock_staged()?.journal.extend(line);
        Ok(entry)
    }

    /// Makes every staged file durable and puts it in place, then journals the staged
    /// entries. Nothing staged: nothing done.
    pub fn commit(&self) -> Result<(), AggregateError> {
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
        self.journal(&staged.journal)
    }

    /// Durable, then renamed, then each folder synced once.
    fn put_in_place(&self, files: &[(PathBuf, PathBuf)]) -> Result<(), AggregateError> {
        if files.is_empty() {
            return Ok(());
        }
        sync_files(&self.root, files.iter().map(|(tmp, _)| tmp.as_path()))?;
        let mut folders: Vec<PathBuf> = Vec::new();
        for (tmp, path) in files {
            std::fs::rename(tmp, path).map_err(|e| AggregateError::io(path, e))?;
            let folder = path.parent().map(Path::to_path_buf).unwrap_or_default();
            if !folders.contains(&folder) {
                folders.push(folder);
            }
        }
        // The renames are durable once their folders are synced (not supported everywhere).
        for folder in folders {
            if let Ok(d) = std::fs::File::open(&folder) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }

    /// Writes `bytes` to a temporary file beside `path`, unless `path` exists or is staged
    /// (content-addressed files never change).
    fn stage_file(&self, path: PathBuf, bytes: &[u8]) -> Result<(), AggregateError> {
        if path.exists() || self.lock_staged()?.paths.contains(&path) {
            return Ok(());
        }
        let tmp = write_temporary(&path, bytes)?;
        let mut staged = self.lock_staged()?;
        if staged.paths.insert(path.clone()) {
            staged.files.push((tmp, path));
        } else {
            // Another thread staged the same content meanwhile.
            let _ = std::fs::remove_file(&tmp);
        }
        Ok(())
    }

    /// The staged writes, locked.
    fn lock_staged(&self) -> Result<std::sync::MutexGuard<'_, Staged>, AggregateError> {
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
    fn lock_journal(
        &self,
    ) -> Result<std::sync::MutexGuard<'_, Option<std::fs::File>>, AggregateError> {
        self.journal
            .lock()
            .map_err(|_| AggregateError::Tree("journal lock poisoned".into()))
    }

    /// Appends journal lines and flushes them.
    fn journal(&self, lines: &[u8]) -> Result<(), AggregateError> {
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
            write_atomically(&self.journal_path(), &journal)?;
            *guard = None;
        }
        let glbs: std::collections::HashSet<&str> =
            manifest.nodes.values().map(|e| e.glb.as_str()).collect();
        let parts: std::collections::HashSet<&str> = manifest
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
                    _ => name.starts_with('.') && name.ends_with(".tmp"),
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

    /// Replaces the manifest atomically.
    pub fn write_manifest(&self, manifest: &AggregateManifest) -> Result<(), AggregateError> {
        let path = self.manifest_path();
        let bytes = serde_json::to_vec(manifest).map_err(|e| AggregateError::Corrupt {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        write_atomically(&path, &bytes)
    }
}

/// Writes `bytes` to a new, uniquely named temporary file in `path`'s folder (created if
/// need be), not yet synced; returns its path. Garbage collection deletes such files.
fn write_temporary(path: &Path, bytes: &[u8]) -> Result<PathBuf, AggregateError> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).map_err(|e| AggregateError::io(&dir, e))?;
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
        AggregateError::io(path, e)
    })?;
    Ok(tmp)
}

/// Makes `files` durable: on Linux one `syncfs` of the file system holding `root` (every
/// dirty page of it, in one flush), else, or if that fails, an fsync of each file.
fn sync_files<'a>(
    root: &Path,
    files: impl Iterator<Item = &'a Path>,
) -> Result<(), AggregateError> {
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
            .map_err(|e| AggregateError::io(f, e))?;
    }
    Ok(())
}

/// Writes `bytes` to `path` so that a reader (or a crash) sees the old file or the whole new
/// one: a uniquely named temporary file in the same folder, fsync, rename, fsync the folder.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), AggregateError> {
    let tmp = write_temporary(path, bytes)?;
    let result = (|| {
        std::fs::File::open(&tmp)?.sync_all()?;
        std::fs::rename(&tmp, path)?;
        // The rename is durable once the folder is synced (not supported everywhere).
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        if let Ok(d) = std::fs::File::open(dir) {
            let _ = d.sync_all();
        }
        Ok(())
    })();
    result.map_err(|e: std::io::Error| {
        let _ = std::fs::remove_file(&tmp);
        AggregateError::io(path, e)
    })
}

/// The FNV-1a 128-bit hash of `bytes` as 32 hex digits: a stable, dependency-free content
/// address. It guards against accidental collisions only; a store of untrusted uploads would
/// want a cryptographic hash.
pub fn content_hash(bytes: &[u8]) -> String {
    let mut h = KeyHasher::new();
    h.write(bytes);
    h.finish_hex()
}

/// Streaming FNV-1a 128, for keys built from many pieces.
#[derive(Clone, Debug)]
pub struct KeyHasher(u128);

impl KeyHasher {
    const OFFSET: u128 = 0x6c62_272e_07bb_0142_62b8_2175_6295_c58d;
    const PRIME: u128 = 0x0000_0000_0100_0000_0000_0000_0000_013b;

    /// A fresh hasher.
    pub fn new() -> Self {
        Self(Self::OFFSET)
    }

    /// Feeds bytes.
    pub fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u128::from(b);
            self.0 = self.0.wrapping_mul(Self::PRIME);
        }
    }

    /// The hash as 32 hex digits.
    pub fn finish_hex(&self) -> String {
        format!("{:032x}", self.0)
    }
}

impl Default for KeyHasher {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a_128_matches_reference_values() {
        // Reference values of FNV-1a 128 (IETF draft-eastlake-fnv test vectors).
        assert_eq!(content_hash(b""), "6c62272e07bb014262b821756295c58d");
        assert_eq!(content_hash(b"a"), "d228cb696f1a8caf78912b704e4a8964");
    }

    #[test]
    fn a_torn_journal_line_is_ignored() {
        let dir = std::env::temp_dir().join(format!("horizon-store-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = AggregateStore::new(&dir);
        let e = store
            .put("k1".into(), b"glb bytes", None, NodeStats::default())
            .expect("put");
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
        let store = AggregateStore::new(&dir);
        let parts = |b: &'static [u8]| Some((b, Vec::new()));
        let old = store
            .put(
                "old".into(),
                b"old glb",
                parts(b"old parts"),
                NodeStats::default(),
            )
            .expect("put");
        let kept = store
            .put(
                "kept".into(),
                b"kept glb",
                parts(b"kept parts"),
                NodeStats::default(),
            )
            .expect("put");
        std::fs::write(dir.join(".x.glb.1.2.tmp"), b"torn").expect("tmp");
        let manifest = AggregateManifest {
            format: crate::FORMAT,
            options: AggregateOptions::default(),
            atlas: true,
            root_key: "kept".into(),
            nodes: BTreeMap::from([(0, kept.clone())]),
        };
        store.write_manifest(&manifest).expect("manifest");
        let removed = store.collect_garbage(&manifest).expect("gc");
        assert_eq!(removed.files, 3, "old GLB, old parts, temporary file");
        assert!(!store.glb(&old.glb).exists());
        assert!(!store.parts(old.parts.as_deref().expect("parts")).exists());
        assert!(store.glb(&kept.glb).exists());
        assert!(store.parts(kept.parts.as_deref().expect("parts")).exists());
        // The journal now holds the manifest's entries alone, and appends still work.
        let known = store.known().expect("known");
        assert_eq!(known.len(), 1);
        assert_eq!(known["kept"], kept);
        store
            .put("new".into(), b"new glb", None, NodeStats::default())
            .expect("put after gc");
        assert_eq!(store.known().expect("known").len(), 2);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn staged_writes_appear_only_on_commit() {
        let dir = std::env::temp_dir().join(format!("horizon-stage-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = AggregateStore::new(&dir);
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
        assert!(!store.glb(&e.glb).exists());
        assert!(!store.parts(e.parts.as_deref().expect("parts")).exists());
        assert!(store.known().expect("known").is_empty());
        store.commit().expect("commit");
        assert!(store.glb(&e.glb).exists());
        assert!(store.parts(e.parts.as_deref().expect("parts")).exists());
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
            let store = AggregateStore::new(&dir);
            let kept = store
                .put("kept".into(), b"kept glb", None, NodeStats::default())
                .expect("put");
            store
                .stage("lost".into(), b"lost glb", None, NodeStats::default())
                .expect("stage");
            kept
        };
        let store = AggregateStore::new(&dir);
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
    fn a_measuring_store_journals_sizes_but_writes_no_glb() {
        let dir = std::env::temp_dir().join(format!("horizon-measure-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = AggregateStore::measuring(&dir);
        let e = store
            .put(
                "k1".into(),
                b"glb bytes",
                Some((b"parts", Vec::new())),
                NodeStats::default(),
            )
            .expect("put");
        assert!(!store.glb(&e.glb).exists());
        assert!(store.parts(e.parts.as_deref().expect("parts")).exists());
        // Still known (for reuse) although its GLB was never written.
        assert_eq!(store.known().expect("known")["k1"], e);
        // The same folder opened as a full store does not claim a GLB it lacks.
        assert!(AggregateStore::new(&dir).known().expect("known").is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
