//! [`Models`]: the world's models as the rebuild and the tree see them, by number. Each is
//! read from its blob and prepared ([`SourceModel`]) on first use, then kept; descriptors are
//! kept likewise. Thread-safe: the rebuild reads models on every core while requests add them.

use std::collections::HashMap;
use std::sync::{Arc, RwLock};

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
}

#[derive(Debug, Default)]
struct State {
    rows: Vec<ModelRow>,
    by_asset: HashMap<String, u64>,
    sources: HashMap<u64, Arc<SourceModel>>,
    descriptors: HashMap<u64, Arc<ModelDescriptors>>,
}

impl Models {
    /// The models the metadata store holds.
    pub fn load(meta: Arc<dyn MetaStore>, blobs: Arc<dyn BlobStore>) -> Result<Self, WorldError> {
        let models = Self {
            meta,
            blobs,
            state: RwLock::new(State::default()),
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

    /// Texture count and encoded bytes over every model (for the atlas rule).
    pub fn texture_totals(&self) -> Result<(usize, u64), WorldError> {
        let mut totals = (0, 0);
        for number in 0..self.len() as u64 {
            let m = self.source(number)?;
            totals.0 += m.mesh.textures.len();
            totals.1 += m
                .mesh
                .textures
                .iter()
                .map(|t| t.bytes.len() as u64)
                .sum::<u64>();
        }
        Ok(totals)
    }

    /// The prepared model numbered `number`.
    pub fn source(&self, number: u64) -> Result<Arc<SourceModel>, WorldError> {
        if let Some(m) = self.read()?.sources.get(&number) {
            return Ok(m.clone());
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
        self.write()?.sources.insert(number, source.clone());
        Ok(source)
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

    fn by_hash(&self, hash: &str) -> Option<u64> {
        self.state.read().ok()?.by_asset.get(hash).copied()
    }
}
