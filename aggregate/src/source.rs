//! The models an aggregate is made of, as the rebuild sees them.

use std::sync::Arc;

use glam::{Affine3A, Vec3};
use horizon_mesh::InstancedMesh;

use crate::error::AggregateError;
use crate::pca::PcaFrame;

/// One unique model of the world, loaded and prepared once.
#[derive(Debug)]
pub struct SourceModel {
    /// Its content hash in the model store.
    pub hash: String,
    /// The model.
    pub mesh: InstancedMesh,
    /// 3D Zernike descriptor (121 values).
    pub shape: Vec<f32>,
    /// Color Structure Descriptor (32 bins).
    pub texture: Vec<f32>,
    /// Principal frame, `None` when the model has no area.
    pub frame: Option<PcaFrame>,
    /// For each submesh, the transforms of its instances inside the model.
    pub placements: Vec<Vec<Affine3A>>,
    /// For each submesh, a bounding sphere (centre, radius) in its own space.
    pub part_spheres: Vec<(Vec3, f32)>,
    /// Its box proxies made so far (`proxy.rs`), by the sizes of their six tiles.
    pub(crate) proxies: crate::proxy::ProxyMemo,
}

impl SourceModel {
    /// Prepares a model: its principal frame and per-submesh placements.
    pub fn new(hash: String, mesh: InstancedMesh, shape: Vec<f32>, texture: Vec<f32>) -> Self {
        let frame = PcaFrame::of(&mesh);
        let placements = mesh
            .instances_by_submesh()
            .into_iter()
            .map(|ks| {
                ks.into_iter()
                    .map(|k| mesh.instances[k].transform)
                    .collect()
            })
            .collect();
        let part_spheres = mesh
            .submeshes
            .iter()
            .map(|s| {
                let b = s.bounds();
                if b.is_empty() {
                    (Vec3::ZERO, 0.0)
                } else {
                    ((b.min + b.max) * 0.5, (b.max - b.min).length() * 0.5)
                }
            })
            .collect();
        Self {
            hash,
            mesh,
            shape,
            texture,
            frame,
            placements,
            part_spheres,
            proxies: crate::proxy::ProxyMemo::default(),
        }
    }

    /// Estimated bytes it holds in memory: its vertices, indices, encoded textures and
    /// placements (what a bounded model cache weighs it by).
    pub fn bytes(&self) -> usize {
        let submeshes: usize = self.mesh.submeshes.iter().map(submesh_bytes).sum();
        let textures: usize = self.mesh.textures.iter().map(|t| t.bytes.len()).sum();
        let placements: usize = self.placements.iter().map(|p| p.len() * 48).sum();
        submeshes
            + textures
            + placements
            + self.mesh.instances.len() * 64
            + (self.shape.len() + self.texture.len()) * 4
    }
}

/// Estimated bytes a submesh holds: its vertex attributes and indices.
pub(crate) fn submesh_bytes(s: &horizon_mesh::Submesh) -> usize {
    s.positions.len() * 12
        + s.normals.as_ref().map_or(0, |n| n.len() * 12)
        + s.uvs.as_ref().map_or(0, |u| u.len() * 8)
        + s.colors.as_ref().map_or(0, |c| c.len() * 16)
        + s.indices.len() * 4
}

/// Where the rebuild gets models from, by the BVH's model number.
pub trait ModelSource: Sync {
    /// The model numbered `model`.
    fn model(&self, model: u64) -> Result<Arc<SourceModel>, AggregateError>;
    /// The content hash of the model numbered `model`. A source that keeps only some models
    /// in memory answers this without loading the model.
    fn hash(&self, model: u64) -> Result<String, AggregateError> {
        Ok(self.model(model)?.hash.clone())
    }
    /// Triangles the model stores (each submesh once). A source that keeps only some models
    /// in memory answers this without loading the model.
    fn triangles(&self, model: u64) -> Result<u64, AggregateError> {
        Ok(self.model(model)?.mesh.unique_triangle_count())
    }
    /// The number of a model by content hash, if the world has it.
    fn by_hash(&self, hash: &str) -> Option<u64>;
}

/// A [`ModelSource`] holding every model in memory.
#[derive(Debug, Default)]
pub struct InMemoryModels {
    models: Vec<Arc<SourceModel>>,
    index: std::collections::HashMap<String, u64>,
}

impl InMemoryModels {
    /// The models numbered by their position in `models`.
    pub fn new(models: Vec<SourceModel>) -> Self {
        let index = models
            .iter()
            .enumerate()
            .map(|(i, m)| (m.hash.clone(), i as u64))
            .collect();
        Self {
            models: models.into_iter().map(Arc::new).collect(),
            index,
        }
    }

    /// Number of textures and their encoded bytes over every model (for the atlas rule).
    pub fn texture_totals(&self) -> (usize, u64) {
        self.models.iter().fold((0, 0), |(n, b), m| {
            (
                n + m.mesh.textures.len(),
                b + m
                    .mesh
                    .textures
                    .iter()
                    .map(|t| t.bytes.len() as u64)
                    .sum::<u64>(),
            )
        })
    }
}

impl ModelSource for InMemoryModels {
    fn model(&self, model: u64) -> Result<Arc<SourceModel>, AggregateError> {
        self.models
            .get(model as usize)
            .cloned()
            .ok_or_else(|| AggregateError::Model {
                model,
                reason: format!("no such model (the world has {})", self.models.len()),
            })
    }

    fn by_hash(&self, hash: &str) -> Option<u64> {
        self.index.get(hash).copied()
    }
}
