//! The world directory: its files, their formats, and reading them back checked.
//!
//! ```text
//! DIR/world.json        WorldManifest: format, name, seed, counts, the models (hash, name)
//! DIR/objects.json      ObjectList: per object its id, model hash and 3x4 transform
//! DIR/models/<hash>.glb every unique model, normalised to GLB, named by its content hash
//! DIR/descriptors.json  DescriptorCache: per model hash its descriptors and local bounds
//! DIR/bvh.json          the BVH snapshot (horizon_bvh::Bvh, serde)
//! DIR/aggregates/       the aggregate store (`aggregates.rs`)
//! ```
//!
//! Every file is written atomically (`durable.rs`), so a reader never sees a half-written one.

use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::durable::write_atomically;
use crate::error::WorldError;

/// Version of the world directory format written by this build.
pub const FORMAT: u32 = 1;

/// `DIR/world.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WorldManifest {
    /// [`FORMAT`].
    pub format: u32,
    /// The world's name (for generated worlds, the generator's: village, island, city, city9).
    pub name: String,
    /// The generator's seed.
    pub seed: u64,
    /// Number of objects in `objects.json`.
    pub object_count: usize,
    /// Number of unique models.
    pub model_count: usize,
    /// The unique models, in the order the BVH numbers them.
    pub models: Vec<ModelRecord>,
}

/// One unique model of a world.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelRecord {
    /// The content hash: `models/<hash>.glb`.
    pub hash: String,
    /// A name for people (the generator's, or the uploaded file's).
    pub name: String,
    /// Size of the GLB file.
    pub bytes: u64,
}

/// `DIR/objects.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ObjectList {
    /// The objects; `objects[i].id == i`.
    pub objects: Vec<ObjectRecord>,
}

/// One placed object.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ObjectRecord {
    /// The object's id, its index in the list (and its BVH object id).
    pub id: u32,
    /// The model's content hash.
    pub model: String,
    /// Model-to-world transform, a 3x4 matrix by columns: x axis, y axis, z axis, translation
    /// (glam's `Affine3A::to_cols_array`).
    pub transform: [f32; 12],
}

/// `DIR/descriptors.json`: what ingest computed per model, so a rebuild reuses it.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct DescriptorCache {
    /// Per model hash.
    pub models: BTreeMap<String, ModelDescriptors>,
}

/// A model's descriptors and local bounding sphere.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelDescriptors {
    /// 3D Zernike descriptor (121 values).
    pub zernike: Vec<f32>,
    /// Color Structure Descriptor (32 bins).
    pub csd: Vec<f32>,
    /// Centre of the model's bounding sphere, in model space.
    pub centre: [f32; 3],
    /// Radius of the model's bounding sphere, in model space.
    pub radius: f32,
}

/// Paths inside a world directory, and its JSON files read and written.
#[derive(Debug, Clone)]
pub struct WorldDir {
    root: PathBuf,
}

impl WorldDir {
    /// The world directory at `root` (not checked).
    pub fn new(root: &Path) -> Self {
        Self {
            root: root.to_path_buf(),
        }
    }

    /// The directory itself.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `DIR/world.json`.
    pub fn manifest(&self) -> PathBuf {
        self.root.join("world.json")
    }

    /// `DIR/objects.json`.
    pub fn objects(&self) -> PathBuf {
        self.root.join("objects.json")
    }

    /// `DIR/descriptors.json`.
    pub fn descriptors(&self) -> PathBuf {
        self.root.join("descriptors.json")
    }

    /// `DIR/bvh.json`.
    pub fn bvh(&self) -> PathBuf {
        self.root.join("bvh.json")
    }

    /// `DIR/models`.
    pub fn models(&self) -> PathBuf {
        self.root.join("models")
    }

    /// `DIR/models/<hash>.glb`.
    pub fn model(&self, hash: &str) -> PathBuf {
        self.models().join(format!("{hash}.glb"))
    }

    /// `DIR/aggregates`.
    pub fn aggregates(&self) -> PathBuf {
        self.root.join("aggregates")
    }

    /// Reads and parses a JSON file, with the path in the error.
    pub fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T, WorldError> {
        let bytes = std::fs::read(path).map_err(|e| WorldError::io(path, e))?;
        serde_json::from_slice(&bytes).map_err(|e| WorldError::Corrupt {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })
    }

    /// Serialises `value` as JSON and writes it atomically.
    pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), WorldError> {
        let bytes = serde_json::to_vec(value).map_err(|e| WorldError::Corrupt {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        write_atomically(path, &bytes)
    }

    /// The manifest and the object list, checked against each other.
    pub fn load(&self) -> Result<(WorldManifest, ObjectList), WorldError> {
        if !self.root.is_dir() {
            return Err(WorldError::NotAWorld(self.root.clone()));
        }
        let manifest: WorldManifest = Self::read_json(&self.manifest())?;
        if manifest.format != FORMAT {
            return Err(WorldError::Corrupt {
                path: self.manifest(),
                reason: format!(
                    "format {} is not supported (expected {FORMAT})",
                    manifest.format
                ),
            });
        }
        let objects: ObjectList = Self::read_json(&self.objects())?;
        if objects.objects.len() != manifest.object_count {
            return Err(WorldError::Inconsistent(format!(
                "{} holds {} objects but world.json says {}",
                self.objects().display(),
                objects.objects.len(),
                manifest.object_count
            )));
        }
        let known: HashSet<&str> = manifest.models.iter().map(|m| m.hash.as_str()).collect();
        for (i, o) in objects.objects.iter().enumerate() {
            let problem = if o.id as usize != i {
                format!("object {i} has id {}", o.id)
            } else if !known.contains(o.model.as_str()) {
                format!("object {i} uses unknown model {}", o.model)
            } else if !o.transform.iter().all(|v| v.is_finite()) {
                format!("object {i} has a non-finite transform")
            } else {
                continue;
            };
            return Err(WorldError::Inconsistent(problem));
        }
        Ok((manifest, objects))
    }
}
