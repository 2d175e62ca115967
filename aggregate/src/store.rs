//! Where a rebuild keeps what it builds: the [`AggregateStore`] trait, the records it holds,
//! and [`MemoryStore`], an implementation in memory.
//!
//! The rebuild never touches a file system. It hands every aggregate's GLB and parts file to
//! a store, which names them by content and journals one [`AggregateEntry`] per aggregate
//! under its key. `horizon-world` implements the trait over a world directory, with atomic,
//! durable writes; the lab wraps it to measure aggregates without keeping them.
//!
//! The protocol a build follows, which every implementation must honour:
//! 1. [`AggregateStore::known`] gives every entry the store can serve, by key: a node whose
//!    key is known is reused, not rebuilt.
//! 2. [`AggregateStore::stage`] takes an aggregate; until [`AggregateStore::commit`] neither
//!    its blobs nor its entry are part of the store (a build commits once per tree level).
//! 3. [`AggregateStore::write_manifest`] comes last and replaces the manifest as one step, so
//!    a build that stops early leaves the previous manifest valid.

use std::collections::{BTreeMap, HashMap};
use std::sync::{Mutex, MutexGuard};

use serde::{Deserialize, Serialize};

use crate::error::AggregateError;
use crate::generate::NodeStats;
use crate::impostors::ImpostorEntry;
use crate::keys::KeyHasher;
use crate::options::AggregateOptions;

/// Where each submesh of a parts file came from: (model content hash, submesh index) for the
/// optimised pipeline's versions; (model content hash, material index of that model) for the
/// unoptimised baseline's world-space submeshes, with an empty hash for none.
pub type PartList = Vec<(String, u32)>;

/// One node's aggregate, as the manifest and the journal record it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AggregateEntry {
    /// Hash of everything the aggregate was made from (`keys.rs`).
    pub key: String,
    /// Content hash of the GLB.
    pub glb: String,
    /// Content hash of the handoff parts, if any.
    pub parts: Option<String>,
    /// For each submesh of the parts file: where it came from ([`PartList`]).
    pub part_keys: PartList,
    /// What building it did.
    pub stats: NodeStats,
}

/// The aggregates of one whole build: what a cut serves.
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
    /// Per node number, its impostor (only nodes that get one: `impostors.rs`).
    #[serde(default)]
    pub impostors: BTreeMap<u32, ImpostorEntry>,
}

impl AggregateManifest {
    /// Every blob it names: aggregate GLBs, parts files and orthoview images.
    pub fn blobs(&self) -> impl Iterator<Item = &String> {
        self.nodes
            .values()
            .flat_map(|e| std::iter::once(&e.glb).chain(e.parts.as_ref()))
            .chain(self.impostors.values().flat_map(ImpostorEntry::blobs))
    }
}

/// Where a rebuild keeps aggregates (see the module docs for the protocol).
pub trait AggregateStore: Sync {
    /// Every aggregate the store can serve, by key: the manifest's and every committed
    /// entry's, each with all of its blobs present.
    fn known(&self) -> Result<HashMap<String, AggregateEntry>, AggregateError>;

    /// The manifest of the last whole build, if any.
    fn manifest(&self) -> Result<Option<AggregateManifest>, AggregateError>;

    /// Takes an aggregate's GLB and optional parts file (with its [`PartList`]) under `key`,
    /// to be kept at the next [`AggregateStore::commit`]; returns its entry.
    fn stage(
        &self,
        key: String,
        glb: &[u8],
        parts: Option<(&[u8], PartList)>,
        stats: NodeStats,
    ) -> Result<AggregateEntry, AggregateError>;

    /// Takes a blob (an orthoview image) to be kept at the next [`AggregateStore::commit`];
    /// returns its content hash.
    fn stage_blob(&self, bytes: &[u8]) -> Result<String, AggregateError>;

    /// Keeps everything staged since the last commit. Nothing staged: nothing done.
    fn commit(&self) -> Result<(), AggregateError>;

    /// The bytes of a committed parts file.
    fn parts(&self, hash: &str) -> Result<Vec<u8>, AggregateError>;

    /// The bytes of any committed blob (parts file or orthoview image).
    fn blob(&self, hash: &str) -> Result<Vec<u8>, AggregateError> {
        self.parts(hash)
    }

    /// Replaces the manifest as one step.
    fn write_manifest(&self, manifest: &AggregateManifest) -> Result<(), AggregateError>;
}

/// An [`AggregateStore`] in memory: blobs by content hash (FNV-1a 128, [`KeyHasher`]) and
/// entries by key. For tests and for builds whose output is consumed in place.
#[derive(Debug, Default)]
pub struct MemoryStore {
    inner: Mutex<Memory>,
}

#[derive(Debug, Default)]
struct Memory {
    blobs: HashMap<String, Vec<u8>>,
    entries: HashMap<String, AggregateEntry>,
    staged_blobs: Vec<(String, Vec<u8>)>,
    staged_entries: Vec<AggregateEntry>,
    manifest: Option<AggregateManifest>,
}

impl MemoryStore {
    /// An empty store.
    pub fn new() -> Self {
        Self::default()
    }

    /// A committed blob (aggregate GLB or parts file) by content hash.
    pub fn blob(&self, hash: &str) -> Option<Vec<u8>> {
        self.lock().ok()?.blobs.get(hash).cloned()
    }

    fn lock(&self) -> Result<MutexGuard<'_, Memory>, AggregateError> {
        self.inner
            .lock()
            .map_err(|_| AggregateError::Tree("memory store lock poisoned".into()))
    }
}

/// The content hash a [`MemoryStore`] names blobs by.
fn memory_hash(bytes: &[u8]) -> String {
    let mut h = KeyHasher::new();
    h.write(bytes);
    h.finish_hex()
}

impl AggregateStore for MemoryStore {
    fn known(&self) -> Result<HashMap<String, AggregateEntry>, AggregateError> {
        let m = self.lock()?;
        let mut out: HashMap<String, AggregateEntry> = m
            .manifest
            .iter()
            .flat_map(|manifest| manifest.nodes.values())
            .map(|e| (e.key.clone(), e.clone()))
            .collect();
        out.extend(m.entries.iter().map(|(k, e)| (k.clone(), e.clone())));
        out.retain(|_, e| {
            m.blobs.contains_key(&e.glb) && e.parts.as_ref().is_none_or(|p| m.blobs.contains_key(p))
        });
        Ok(out)
    }

    fn manifest(&self) -> Result<Option<AggregateManifest>, AggregateError> {
        Ok(self.lock()?.manifest.clone())
    }

    fn stage(
        &self,
        key: String,
        glb: &[u8],
        parts: Option<(&[u8], PartList)>,
        stats: NodeStats,
    ) -> Result<AggregateEntry, AggregateError> {
        let glb_hash = memory_hash(glb);
        let mut m = self.lock()?;
        m.staged_blobs.push((glb_hash.clone(), glb.to_vec()));
        let (parts_hash, part_keys) = match parts {
            Some((bytes, keys)) => {
                let h = memory_hash(bytes);
                m.staged_blobs.push((h.clone(), bytes.to_vec()));
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
        m.staged_entries.push(entry.clone());
        Ok(entry)
    }

    fn stage_blob(&self, bytes: &[u8]) -> Result<String, AggregateError> {
        let hash = memory_hash(bytes);
        self.lock()?
            .staged_blobs
            .push((hash.clone(), bytes.to_vec()));
        Ok(hash)
    }

    fn commit(&self) -> Result<(), AggregateError> {
        let mut m = self.lock()?;
        let blobs = std::mem::take(&mut m.staged_blobs);
        let entries = std::mem::take(&mut m.staged_entries);
        m.blobs.extend(blobs);
        m.entries
            .extend(entries.into_iter().map(|e| (e.key.clone(), e)));
        Ok(())
    }

    fn parts(&self, hash: &str) -> Result<Vec<u8>, AggregateError> {
        self.blob(hash).ok_or_else(|| AggregateError::Corrupt {
            path: hash.into(),
            reason: "no such parts file in the store".into(),
        })
    }

    fn write_manifest(&self, manifest: &AggregateManifest) -> Result<(), AggregateError> {
        self.lock()?.manifest = Some(manifest.clone());
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn staged_aggregates_are_known_only_after_the_commit() {
        let store = MemoryStore::new();
        let e = store
            .stage(
                "k1".into(),
                b"glb",
                Some((b"parts", Vec::new())),
                NodeStats::default(),
            )
            .expect("stage");
        assert!(store.known().expect("known").is_empty());
        assert!(store.blob(&e.glb).is_none());
        store.commit().expect("commit");
        assert_eq!(store.known().expect("known")["k1"], e);
        assert_eq!(store.blob(&e.glb).as_deref(), Some(&b"glb"[..]));
        let parts = e.parts.as_deref().expect("parts");
        assert_eq!(store.parts(parts).expect("parts"), b"parts");
        assert!(store.parts("nothing").is_err());
    }
}
