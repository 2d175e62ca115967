//! World directories of format 1, read for the upgrade on first open (`World::open`):
//!
//! ```text
//! DIR/world.json        the manifest: format 1, name, seed, counts, the models (hash, name)
//! DIR/objects.json      per object its id, model hash and 3x4 transform
//! DIR/models/<hash>.glb every unique model, named by its FNV-1a 128 hash
//! DIR/descriptors.json  per model hash its descriptors and local bounds (if built)
//! ```
//!
//! The upgrade re-addresses every model by BLAKE3, carries the descriptors over and places the
//! objects; trees and aggregates are rebuilt. The old files are left as they were.

use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::Deserialize;

use crate::error::WorldError;
use crate::store::ModelDescriptors;

/// The format these files carry.
const FORMAT: u32 = 1;

/// `DIR/world.json`.
#[derive(Debug, Clone, Deserialize)]
pub struct Manifest {
    /// [`FORMAT`].
    pub format: u32,
    /// The world's name.
    pub name: String,
    /// The generator's seed.
    pub seed: u64,
    /// Number of objects in `objects.json`.
    pub object_count: usize,
    /// The unique models, in the order the BVH numbered them.
    pub models: Vec<ModelRecord>,
}

/// One unique model.
#[derive(Debug, Clone, Deserialize)]
pub struct ModelRecord {
    /// Its FNV-1a 128 hash: `models/<hash>.glb`.
    pub hash: String,
    /// The generator's name for it.
    pub name: String,
}

/// `DIR/objects.json`.
#[derive(Debug, Clone, Deserialize)]
struct ObjectList {
    objects: Vec<ObjectRecord>,
}

/// One placed object.
#[derive(Debug, Clone, Deserialize)]
pub struct ObjectRecord {
    /// Its id, its index in the list.
    pub id: u32,
    /// Its model's hash.
    pub model: String,
    /// Model-to-world transform, 3x4 by columns.
    pub transform: [f32; 12],
}

/// `DIR/descriptors.json`.
#[derive(Debug, Clone, Default, Deserialize)]
struct DescriptorCache {
    models: BTreeMap<String, ModelDescriptors>,
}

/// A format-1 world, read and checked.
#[derive(Debug)]
pub struct LegacyWorld {
    /// Its directory.
    pub root: PathBuf,
    /// `world.json`.
    pub manifest: Manifest,
    /// `objects.json`, by id.
    pub objects: Vec<ObjectRecord>,
    /// `descriptors.json` (empty if the world was never built).
    pub descriptors: BTreeMap<String, ModelDescriptors>,
}

/// Whether `root` holds a format-1 world.
pub fn is_legacy(root: &Path) -> bool {
    root.join("world.json").is_file()
}

impl LegacyWorld {
    /// Reads the world in `root`, checking its files against each other.
    pub fn read(root: &Path) -> Result<Self, WorldError> {
        let manifest: Manifest = read_json(&root.join("world.json"))?;
        if manifest.format != FORMAT {
            return Err(WorldError::Corrupt {
                path: root.join("world.json"),
                reason: format!(
                    "format {} is not one this version upgrades (expected {FORMAT})",
                    manifest.format
                ),
            });
        }
        let objects: ObjectList = read_json(&root.join("objects.json"))?;
        if objects.objects.len() != manifest.object_count {
            return Err(WorldError::Inconsistent(format!(
                "objects.json holds {} objects but world.json says {}",
                objects.objects.len(),
                manifest.object_count
            )));
        }
        let known: HashSet<&str> = manifest.models.iter().map(|m| m.hash.as_str()).collect();
        for (i, o) in objects.objects.iter().enumerate() {
            if o.id as usize != i {
                return Err(WorldError::Inconsistent(format!(
                    "object {i} has id {}",
                    o.id
                )));
            }
            if !known.contains(o.model.as_str()) {
                return Err(WorldError::Inconsistent(format!(
                    "object {i} uses unknown model {}",
                    o.model
                )));
            }
            if !o.transform.iter().all(|v| v.is_finite()) {
                return Err(WorldError::Inconsistent(format!(
                    "object {i} has a non-finite transform"
                )));
            }
        }
        let descriptors_path = root.join("descriptors.json");
        let descriptors = if descriptors_path.is_file() {
            read_json::<DescriptorCache>(&descriptors_path)?.models
        } else {
            BTreeMap::new()
        };
        Ok(Self {
            root: root.to_path_buf(),
            manifest,
            objects: objects.objects,
            descriptors,
        })
    }

    /// The bytes of a model's GLB.
    pub fn model_bytes(&self, hash: &str) -> Result<Vec<u8>, WorldError> {
        let path = self.root.join("models").join(format!("{hash}.glb"));
        std::fs::read(&path).map_err(|e| WorldError::io(path, e))
    }
}

/// Reads and parses a JSON file, with the path in the error.
fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T, WorldError> {
    let bytes = std::fs::read(path).map_err(|e| WorldError::io(path, e))?;
    serde_json::from_slice(&bytes).map_err(|e| WorldError::Corrupt {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}
