//! [`AggregateSink`]: the [`AggregateStore`] the world's rebuild writes through. Aggregate
//! GLBs and parts files go to the blob store, staged and committed once per tree level (one
//! flush for the level); entries go to the metadata store as the journal, after their blobs
//! are durable, so an entry never names a missing blob. The manifest a build writes is kept
//! here for the world to publish (`World::rebuild_aggregates`).

use std::collections::{HashMap, HashSet};
use std::sync::Mutex;

use horizon_aggregate::{
    AggregateEntry, AggregateError, AggregateManifest, AggregateStore, NodeStats, PartList,
};

use crate::error::WorldError;
use crate::store::{BlobStore, MetaStore};

/// The rebuild's store over the world's metadata and blobs (see the module docs).
#[derive(Debug)]
pub struct AggregateSink<'a> {
    meta: &'a dyn MetaStore,
    blobs: &'a dyn BlobStore,
    /// The published manifest the build started from.
    published: Option<AggregateManifest>,
    /// What the store can serve, by key, as the build starts; `None`: read from the stores.
    known: Option<HashMap<String, AggregateEntry>>,
    /// Entries committed by this build.
    committed: Mutex<Vec<AggregateEntry>>,
    /// Entries staged since the last commit.
    staged: Mutex<Vec<AggregateEntry>>,
    /// The manifest the build wrote.
    written: Mutex<Option<AggregateManifest>>,
}

impl<'a> AggregateSink<'a> {
    /// A sink over `meta` and `blobs`; `published` is the manifest being served.
    pub fn new(
        meta: &'a dyn MetaStore,
        blobs: &'a dyn BlobStore,
        published: Option<AggregateManifest>,
    ) -> Self {
        Self {
            meta,
            blobs,
            published,
            known: None,
            committed: Mutex::new(Vec::new()),
            staged: Mutex::new(Vec::new()),
            written: Mutex::new(None),
        }
    }

    /// A sink that starts from `known`, the entries the caller holds in memory (every blob
    /// they name stored), instead of reading them back from the stores.
    pub fn with_known(mut self, known: HashMap<String, AggregateEntry>) -> Self {
        self.known = Some(known);
        self
    }

    /// The entries this build committed.
    pub fn committed(&self) -> Vec<AggregateEntry> {
        self.committed.lock().map(|c| c.clone()).unwrap_or_default()
    }
}

/// Every recorded entry whose blobs are all stored, by key.
pub fn stored_entries(
    meta: &dyn MetaStore,
    blobs: &dyn BlobStore,
) -> Result<HashMap<String, AggregateEntry>, WorldError> {
    let mut out = HashMap::new();
    for e in recorded_entries(meta)? {
        let held = |hash: &str| blobs.size(hash).ok().flatten().is_some();
        if held(&e.glb) && e.parts.as_deref().is_none_or(held) {
            out.insert(e.key.clone(), e);
        }
    }
    Ok(out)
}

/// Every aggregate entry the metadata store records, parsed (unparsable lines are skipped:
/// the next build replaces them).
pub fn recorded_entries(meta: &dyn MetaStore) -> Result<Vec<AggregateEntry>, WorldError> {
    Ok(meta
        .aggregate_entries()?
        .into_iter()
        .filter_map(|(_, json)| serde_json::from_str::<AggregateEntry>(&json).ok())
        .collect())
}

/// The blobs `manifest` names: every aggregate GLB, parts file and orthoview image.
pub fn named_blobs(manifest: &AggregateManifest) -> HashSet<String> {
    manifest.blobs().cloned().collect()
}

impl AggregateStore for AggregateSink<'_> {
    fn known(&self) -> Result<HashMap<String, AggregateEntry>, AggregateError> {
        match &self.known {
            Some(known) => Ok(known.clone()),
            None => stored_entries(self.meta, self.blobs).map_err(store_error),
        }
    }

    fn manifest(&self) -> Result<Option<AggregateManifest>, AggregateError> {
        Ok(self.published.clone())
    }

    fn stage(
        &self,
        key: String,
        glb: &[u8],
        parts: Option<(&[u8], PartList)>,
        stats: NodeStats,
    ) -> Result<AggregateEntry, AggregateError> {
        let glb = self.blobs.stage(glb).map_err(store_error)?;
        let (parts, part_keys) = match parts {
            Some((bytes, keys)) => (Some(self.blobs.stage(bytes).map_err(store_error)?), keys),
            None => (None, Vec::new()),
        };
        let entry = AggregateEntry {
            key,
            glb,
            parts,
            part_keys,
            stats,
        };
        self.staged
            .lock()
            .map_err(|_| AggregateError::Tree("staging lock poisoned".into()))?
            .push(entry.clone());
        Ok(entry)
    }

    fn stage_blob(&self, bytes: &[u8]) -> Result<String, AggregateError> {
        self.blobs.stage(bytes).map_err(store_error)
    }

    fn commit(&self) -> Result<(), AggregateError> {
        let staged = std::mem::take(
            &mut *self
                .staged
                .lock()
                .map_err(|_| AggregateError::Tree("staging lock poisoned".into()))?,
        );
        self.blobs.commit_staged().map_err(store_error)?;
        let rows = staged
            .iter()
            .map(|e| {
                serde_json::to_string(e)
                    .map(|json| (e.key.clone(), json))
                    .map_err(|e| AggregateError::Corrupt {
                        path: "aggregate entry".into(),
                        reason: e.to_string(),
                    })
            })
            .collect::<Result<Vec<_>, _>>()?;
        self.meta
            .put_aggregate_entries(&rows)
            .map_err(store_error)?;
        self.committed
            .lock()
            .map_err(|_| AggregateError::Tree("commit lock poisoned".into()))?
            .extend(staged);
        Ok(())
    }

    fn parts(&self, hash: &str) -> Result<Vec<u8>, AggregateError> {
        self.blobs
            .get(hash)
            .map_err(store_error)?
            .ok_or_else(|| AggregateError::Corrupt {
                path: hash.into(),
                reason: "no such parts file".into(),
            })
    }

    fn write_manifest(&self, manifest: &AggregateManifest) -> Result<(), AggregateError> {
        *self
            .written
            .lock()
            .map_err(|_| AggregateError::Tree("manifest lock poisoned".into()))? =
            Some(manifest.clone());
        Ok(())
    }
}

/// A store failure as the rebuild reports it.
fn store_error(e: WorldError) -> AggregateError {
    match e {
        WorldError::Io { path, source } => AggregateError::Io { path, source },
        WorldError::Aggregate(e) => e,
        other => AggregateError::Io {
            path: "world store".into(),
            source: std::io::Error::other(other.to_string()),
        },
    }
}
