//! [`MeasuringStore`]: an aggregate store that keeps everything but the aggregate GLBs
//! themselves. Their hashes and sizes are journalled and their bytes dropped; parts files,
//! journal and manifest are kept as usual (a parent is built from its children's parts). The
//! report's unoptimised baseline lives in one, since only its sizes are ever read and its
//! GLBs, each carrying every source texture below it, would fill gigabytes.

use std::collections::HashMap;
use std::path::Path;

use horizon_aggregate::{
    AggregateEntry, AggregateError, AggregateManifest, AggregateStore, NodeStats, PartList,
};
use horizon_world::{content_hash, AggregateDir, BlobKind, Garbage};

/// An [`AggregateStore`] that measures aggregates without keeping them (module docs).
#[derive(Debug)]
pub struct MeasuringStore {
    dir: AggregateDir,
}

impl MeasuringStore {
    /// The store in folder `root` (created on first write).
    pub fn new(root: &Path) -> Self {
        Self {
            dir: AggregateDir::new(root),
        }
    }

    /// Deletes what `manifest` no longer names (see [`AggregateDir::collect_garbage`]).
    pub fn collect_garbage(&self, manifest: &AggregateManifest) -> Result<Garbage, AggregateError> {
        self.dir.collect_garbage(manifest)
    }
}

impl AggregateStore for MeasuringStore {
    /// Every recorded entry whose parts file is kept (its GLB never is).
    fn known(&self) -> Result<HashMap<String, AggregateEntry>, AggregateError> {
        let mut out = self.dir.entries()?;
        out.retain(|_, e| {
            e.parts
                .as_ref()
                .is_none_or(|p| self.dir.blob(BlobKind::Parts, p).exists())
        });
        Ok(out)
    }

    fn manifest(&self) -> Result<Option<AggregateManifest>, AggregateError> {
        self.dir.read_manifest()
    }

    fn stage(
        &self,
        key: String,
        glb: &[u8],
        parts: Option<(&[u8], PartList)>,
        stats: NodeStats,
    ) -> Result<AggregateEntry, AggregateError> {
        let (parts, part_keys) = match parts {
            Some((bytes, keys)) => (Some(self.dir.stage_blob(BlobKind::Parts, bytes)?), keys),
            None => (None, Vec::new()),
        };
        let entry = AggregateEntry {
            key,
            glb: content_hash(glb),
            parts,
            part_keys,
            stats,
        };
        self.dir.stage_entry(&entry)?;
        Ok(entry)
    }

    fn commit(&self) -> Result<(), AggregateError> {
        self.dir.commit_staged()
    }

    fn parts(&self, hash: &str) -> Result<Vec<u8>, AggregateError> {
        self.dir.parts(hash)
    }

    fn write_manifest(&self, manifest: &AggregateManifest) -> Result<(), AggregateError> {
        self.dir.write_manifest(manifest)
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
        store.commit().expect("commit");
        let aggregates = AggregateDir::new(&dir);
        assert!(!aggregates.blob(BlobKind::Aggregate, &e.glb).exists());
        let parts = e.parts.as_deref().expect("parts");
        assert!(aggregates.blob(BlobKind::Parts, parts).exists());
        // Still known (for reuse) although its GLB was never written.
        assert_eq!(store.known().expect("known")["k1"], e);
        // The same folder opened as a full store does not claim a GLB it lacks.
        assert!(aggregates.known().expect("known").is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
