//! [`Models`]: the world's models as the rebuild and the tree see them, by number. Each is
//! read from its blob and prepared ([`SourceModel`]) on first use, then kept while the
//! prepared models fit [`MODEL_CACHE_BYTES`]: over it, the least recently used go, so a world
//! of 60,000 distinct models builds in bounded memory (a model dropped is read again when a
//! node needs it). Descriptors (about 600 bytes a model) are all kept. Thread-safe: the
//! rebuild reads models on every core while requests add them.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, RwLock};

use horizon_aggregate::{AggregateError, ModelSource, SourceModel};
use horizon_mesh::{import_bytes, Format, ImportOptions};

use crate::error::WorldError;
use crate::store::{BlobStore, MetaStore, ModelDescriptors, ModelRow};
use crate::tree::Describe;

/// The world's models by number (see the module docs).
#[derive(Debug)]
pub struct Models {
    meta: Arc<dyn MetaStore>,
    blobs: Arc<dyn BlobStore>,
    state: RwLock<State>,
    sources: Mutex<SourceCache>,
}

/// Estimated bytes of prepared models [`Models`] keeps by default (see the module docs).
pub const MODEL_CACHE_BYTES: usize = 1 << 30;

#[derive(Debug, Default)]
struct State {
    rows: Vec<ModelRow>,
    by_asset: HashMap<String, u64>,
    descriptors: HashMap<u64, Arc<ModelDescriptors>>,
}

/// Prepared models by number, least recently used dropped first once their estimated bytes
/// ([`SourceModel::bytes`]) pass `budget`.
#[derive(Debug, Default)]
struct SourceCache {
    budget: usize,
    bytes: usize,
    clock: u64,
    /// Model number -> (model, its bytes, when last used).
    entries: HashMap<u64, (Arc<SourceModel>, usize, u64)>,
}

impl SourceCache {
    fn get(&mut self, number: u64) -> Option<Arc<SourceModel>> {
        self.clock += 1;
        let clock = self.clock;
        self.entries.get_mut(&number).map(|e| {
            e.2 = clock;
            e.0.clone()
        })
    }

    /// Keeps `model`, then, if over the budget, drops the least recently used down to three
    /// quarters of it (one sort per eviction round, not one per model).
    fn put(&mut self, number: u64, model: Arc<SourceModel>) {
        self.clock += 1;
        let bytes = model.bytes();
        if let Some(old) = self.entries.insert(number, (model, bytes, self.clock)) {
            self.bytes -= old.1;
        }
        self.bytes += bytes;
        if self.bytes <= self.budget {
            return;
        }
        let mut by_use: Vec<(u64, u64, usize)> =
            self.entries.iter().map(|(&n, e)| (e.2, n, e.1)).collect();
        by_use.sort_unstable();
        let target = self.budget / 4 * 3;
        for (_, n, b) in by_use {
            if self.bytes <= target {
                break;
            }
            self.entries.remove(&n);
            self.bytes -= b;
        }
    }
}

impl Models {
    /// The models the metadata store holds.
    pub fn load(meta: Arc<dyn MetaStore>, blobs: Arc<dyn BlobStore>) -> Result<Self, WorldError> {
        Self::load_with_cache(meta, blobs, MODEL_CACHE_BYTES)
    }

    /// [`Models::load`], keeping prepared models up to `cache_bytes` (estimated).
    pub fn load_with_cache(
        meta: Arc<dyn MetaStore>,
        blobs: Arc<dyn BlobStore>,
        cache_bytes: usize,
    ) -> Result<Self, WorldError> {
        let models = Self {
            meta,
            blobs,
            state: RwLock::new(State::default()),
            sources: Mutex::new(SourceCache {
                budget: cache_bytes,
                ..SourceCache::default()
            }),
        };
        for row in models.meta.models()? {
            models.add(row)?;
        }
        Ok(models)
    }

    /// Takes in a model just added to the metadata store.
    pub fn add(&self, row: ModelRow) -> Result<(), WorldError> {
        let mut s = self.write()?;
        if row.number as usize != s.rows.len() {
            return Err(WorldError::Inconsistent(format!(
                "model {} is numbered {} but {} models are known",
                row.id,
                row.number,
                s.rows.len()
            )));
        }
        s.by_asset.entry(row.asset.clone()).or_insert(row.number);
        s.rows.push(row);
        Ok(())
    }

    /// Number of models.
    pub fn len(&self) -> usize {
        self.state.read().map_or(0, |s| s.rows.len())
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The number of a model storing the GLB with this content hash, if any.
    pub fn by_asset(&self, asset: &str) -> Option<u64> {
        self.state.read().ok()?.by_asset.get(asset).copied()
    }

    /// The row of the model numbered `number`.
    pub fn row(&self, number: u64) -> Result<ModelRow, WorldError> {
        self.read()?
            .rows
            .get(number as usize)
            .cloned()
            .ok_or_else(|| WorldError::NotFound(format!("no model numbered {number}")))
    }

    /// Every row, by number.
    pub fn rows(&self) -> Result<Vec<ModelRow>, WorldError> {
        Ok(self.read()?.rows.clone())
    }

    /// Numbers of the models whose stored GLB has no descriptors yet.
    pub fn undescribed(&self) -> Result<Vec<u64>, WorldError> {
        let rows = self.rows()?;
        let mut out = Vec::new();
        for row in rows {
            if self.meta.descriptors(&row.asset)?.is_none() {
                out.push(row.number);
            }
        }
        Ok(out)
    }

    /// The stored GLB of the model numbered `number`.
    pub fn glb(&self, number: u64) -> Result<Vec<u8>, WorldError> {
        let row = self.row(number)?;
        self.blobs.get(&row.asset)?.ok_or_else(|| {
            WorldError::Inconsistent(format!("model {} has no stored GLB {}", row.id, row.asset))
        })
    }

    /// Texture count and encoded bytes over every model, for the atlas rule
    /// ([`horizon_aggregate::AUTO_ATLAS_TEXTURES`] textures or
    /// [`horizon_aggregate::AUTO_ATLAS_BYTES`]). The count comes from the models' stored
    /// statistics. The bytes are exact while the count alone does not decide the rule; past
    /// it they are the textured models' GLB bytes, an upper bound, so that a world of many
    /// textured models is not read whole to learn what its count already says.
    pub fn texture_totals(&self) -> Result<(usize, u64), WorldError> {
        let rows = self.rows()?;
        let textures = |row: &ModelRow| {
            row.stats
                .get("textures")
                .and_then(|t| t.as_u64())
                .unwrap_or(0) as usize
        };
        let count: usize = rows.iter().map(textures).sum();
        let bytes = if count > horizon_aggregate::AUTO_ATLAS_TEXTURES {
            rows.iter()
                .filter(|r| textures(r) > 0)
                .map(|r| r.bytes)
                .sum()
        } else {
            let mut bytes = 0;
            for row in rows.iter().filter(|r| textures(r) > 0) {
                let m = self.source(row.number)?;
                bytes += m
                    .mesh
                    .textures
                    .iter()
                    .map(|t| t.bytes.len() as u64)
                    .sum::<u64>();
            }
            bytes
        };
        Ok((count, bytes))
    }

    /// The prepared model numbered `number`.
    pub fn source(&self, number: u64) -> Result<Arc<SourceModel>, WorldError> {
        if let Some(m) = self.cache()?.get(number) {
            return Ok(m);
        }
        let row = self.row(number)?;
        let glb = self.glb(number)?;
        let mesh = import_bytes(&glb, Format::Glb, None, &ImportOptions::trusted())
            .map_err(|e| WorldError::model(&row.id, e))?
            .mesh;
        let d = self.descriptors_of(number)?;
        let source = Arc::new(SourceModel::new(
            row.asset.clone(),
            mesh,
            d.zernike.clone(),
            d.csd.clone(),
        ));
        self.cache()?.put(number, source.clone());
        Ok(source)
    }

    /// Estimated bytes of the prepared models kept, and how many they are.
    pub fn cached(&self) -> Result<(usize, usize), WorldError> {
        let c = self.cache()?;
        Ok((c.bytes, c.entries.len()))
    }

    fn cache(&self) -> Result<std::sync::MutexGuard<'_, SourceCache>, WorldError> {
        self.sources
            .lock()
            .map_err(|_| WorldError::Inconsistent("model cache lock poisoned".into()))
    }

    fn read(&self) -> Result<std::sync::RwLockReadGuard<'_, State>, WorldError> {
        self.state
            .read()
            .map_err(|_| WorldError::Inconsistent("model cache lock poisoned".into()))
    }

    fn write(&self) -> Result<std::sync::RwLockWriteGuard<'_, State>, WorldError> {
        self.state
            .write()
            .map_err(|_| WorldError::Inconsistent("model cache lock poisoned".into()))
    }
}

impl Describe for Models {
    fn descriptors_of(&self, model: u64) -> Result<Arc<ModelDescriptors>, WorldError> {
        if let Some(d) = self.read()?.descriptors.get(&model) {
            return Ok(d.clone());
        }
        let row = self.row(model)?;
        let d = self
            .meta
            .descriptors(&row.asset)?
            .map(Arc::new)
            .ok_or_else(|| WorldError::model(&row.id, "no descriptors (run horizon build)"))?;
        self.write()?.descriptors.insert(model, d.clone());
        Ok(d)
    }
}

impl ModelSource for Models {
    fn model(&self, model: u64) -> Result<Arc<SourceModel>, AggregateError> {
        self.source(model).map_err(|e| AggregateError::Model {
            model,
            reason: e.to_string(),
        })
    }

    fn hash(&self, model: u64) -> Result<String, AggregateError> {
        self.row(model)
            .map(|r| r.asset)
            .map_err(|e| AggregateError::Model {
                model,
                reason: e.to_string(),
            })
    }

    fn triangles(&self, model: u64) -> Result<u64, AggregateError> {
        let row = self.row(model).map_err(|e| AggregateError::Model {
            model,
            reason: e.to_string(),
        })?;
        match row.stats.get("triangles_unique").and_then(|t| t.as_u64()) {
            Some(t) => Ok(t),
            None => Ok(self.model(model)?.mesh.unique_triangle_count()),
        }
    }

    fn by_hash(&self, hash: &str) -> Option<u64> {
        self.state.read().ok()?.by_asset.get(hash).copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use horizon_mesh::{InstancedMesh, Submesh};

    fn model(vertices: usize) -> Arc<SourceModel> {
        let mesh = InstancedMesh {
            submeshes: vec![Submesh {
                positions: vec![glam::Vec3::ZERO; vertices],
                ..Submesh::default()
            }],
            ..InstancedMesh::default()
        };
        Arc::new(SourceModel::new(
            String::new(),
            mesh,
            Vec::new(),
            Vec::new(),
        ))
    }

    #[test]
    fn the_source_cache_stays_within_its_budget_and_drops_the_least_recently_used() {
        let one = model(1000).bytes();
        let mut cache = SourceCache {
            budget: one * 4,
            ..SourceCache::default()
        };
        for n in 0..4 {
            cache.put(n, model(1000));
        }
        assert_eq!(cache.entries.len(), 4, "four fit");
        // Model 0 used last: the eviction that the fifth forces spares it.
        assert!(cache.get(0).is_some());
        cache.put(4, model(1000));
        assert!(
            cache.bytes <= cache.budget,
            "{} > {}",
            cache.bytes,
            cache.budget
        );
        assert_eq!(
            cache.bytes,
            cache.entries.values().map(|e| e.1).sum::<usize>()
        );
        assert!(cache.get(0).is_some(), "the most recently used is kept");
        assert!(cache.get(4).is_some(), "the newest is kept");
        assert!(cache.get(1).is_none(), "the least recently used goes");
    }
}
