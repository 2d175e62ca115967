//! The world directory (issues 5 and 6, "World directory"): a content-addressed model store
//! and the files describing a world.
//!
//! ```text
//! DIR/world.json        WorldManifest: format, name, seed, counts, the models (hash, name)
//! DIR/objects.json      ObjectList: per object its id, model hash and 3x4 transform
//! DIR/models/<hash>.glb every unique model, named by the FNV-1a 128 hash of its GLB bytes
//! DIR/descriptors.json  DescriptorCache: per model hash its descriptors and local bounds
//! DIR/bvh.json          the BVH snapshot (horizon_bvh::Bvh, serde)
//! ```
//!
//! Every file is written atomically (temporary file, then rename), so a reader never sees a
//! half-written file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::mesh_cmd::write_atomically;

/// Version of the world directory format written by this build.
pub const FORMAT: u32 = 1;

/// `DIR/world.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WorldManifest {
    /// [`FORMAT`].
    pub format: u32,
    /// The world's generator name (village, island, city, city9).
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
    /// The generator's name for it.
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

/// `DIR/descriptors.json`: what `horizon build` computed per model, so a rebuild reuses it.
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

/// Paths inside a world directory.
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

    /// Reads and parses a JSON file, with the path in the error.
    pub fn read_json<T: DeserializeOwned>(path: &Path) -> anyhow::Result<T> {
        let bytes =
            std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        serde_json::from_slice(&bytes).with_context(|| format!("corrupt {}", path.display()))
    }

    /// Serialises `value` as JSON and writes it atomically.
    pub fn write_json<T: Serialize>(path: &Path, value: &T) -> anyhow::Result<()> {
        let bytes = serde_json::to_vec(value)?;
        write_atomically(path, &bytes)
    }

    /// The manifest and the object list, checked against each other.
    pub fn load(&self) -> anyhow::Result<(WorldManifest, ObjectList)> {
        if !self.root.is_dir() {
            anyhow::bail!("{} is not a world directory", self.root.display());
        }
        let manifest: WorldManifest = Self::read_json(&self.manifest())?;
        if manifest.format != FORMAT {
            anyhow::bail!(
                "{}: format {} is not supported (expected {FORMAT})",
                self.manifest().display(),
                manifest.format
            );
        }
        let objects: ObjectList = Self::read_json(&self.objects())?;
        if objects.objects.len() != manifest.object_count {
            anyhow::bail!(
                "{} holds {} objects but world.json says {}",
                self.objects().display(),
                objects.objects.len(),
                manifest.object_count
            );
        }
        let known: std::collections::HashSet<&str> =
            manifest.models.iter().map(|m| m.hash.as_str()).collect();
        for (i, o) in objects.objects.iter().enumerate() {
            if o.id as usize != i {
                anyhow::bail!("object {i} has id {}", o.id);
            }
            if !known.contains(o.model.as_str()) {
                anyhow::bail!("object {i} uses unknown model {}", o.model);
            }
            if !o.transform.iter().all(|v| v.is_finite()) {
                anyhow::bail!("object {i} has a non-finite transform");
            }
        }
        Ok((manifest, objects))
    }
}

/// The content address of a model: FNV-1a 128 as 32 hex digits (shared with the aggregate
/// store, `horizon_aggregate::store::content_hash`).
pub use horizon_aggregate::store::content_hash;
