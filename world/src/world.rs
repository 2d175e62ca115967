//! [`World`]: one world directory opened, and everything the product does to it as functions
//! over it. Create (ingest every model, place the objects) -> describe the models -> build
//! the similarity-aware BVH (core paper eq. 1, section 4.3) -> rebuild the aggregates
//! (sections 5 to 7) -> cut (eq. 3).

use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::{Affine3A, Vec3};
use horizon_aggregate::{
    build_aggregates, AggregateOptions, BuildOptions, BuildReport, InMemoryModels, Progress,
    SourceModel,
};
use horizon_bvh::{Bvh, BvhOptions, Cut, CutQuery, NewObject, Sphere};
use horizon_descriptors::{csd_distance, zernike_distance};
use horizon_mesh::rng::Rng;
use horizon_mesh::{import_file, ImportOptions, InstancedMesh};
use rayon::prelude::*;
use serde::Serialize;

use crate::aggregates::{AggregateDir, Garbage};
use crate::dir::{
    DescriptorCache, ModelDescriptors, ModelRecord, ObjectList, ObjectRecord, WorldDir,
    WorldManifest, FORMAT,
};
use crate::durable::write_atomically;
use crate::error::WorldError;
use crate::hash::content_hash;
use crate::ingest::{describe_stored, normalise};

/// Distinct models up to which the BVH's descriptor scales come from every pair of them;
/// above it, from [`SCALE_SAMPLE_PAIRS`] seeded pairs.
const SCALE_ALL_PAIRS_UP_TO: usize = 400;
/// Pairs sampled for the descriptor scales of a world with many models.
const SCALE_SAMPLE_PAIRS: usize = 40_000;
/// Seed of that sample, fixed so that a world always gets the same tree.
const SCALE_SAMPLE_SEED: u64 = 0x5CA1E;

/// A world directory, opened: its manifest, objects and descriptor cache in memory, and the
/// BVH once built or loaded.
#[derive(Debug)]
pub struct World {
    dir: WorldDir,
    manifest: WorldManifest,
    objects: ObjectList,
    descriptors: DescriptorCache,
    tree: Option<Bvh>,
}

/// What [`World::rebuild_aggregates`] did.
#[derive(Clone, Debug, Serialize)]
pub struct RebuildReport {
    /// The rebuild.
    #[serde(flatten)]
    pub build: BuildReport,
    /// Files of earlier builds that the new manifest no longer names, deleted.
    pub removed: Garbage,
}

impl World {
    /// Writes a new world into `root`: every model normalised and stored under its content
    /// hash (models whose GLBs are identical share one file and one record, the first name
    /// kept), then the objects, each `(index into models, model-to-world transform)`.
    pub fn create(
        root: &Path,
        name: &str,
        seed: u64,
        models: &[(String, InstancedMesh)],
        objects: &[(usize, Affine3A)],
    ) -> Result<World, WorldError> {
        let dir = WorldDir::new(root);
        std::fs::create_dir_all(dir.models()).map_err(|e| WorldError::io(dir.models(), e))?;
        // Normalise, hash and store every model in parallel.
        let stored: Vec<(String, u64)> = models
            .par_iter()
            .map(|(model_name, mesh)| -> Result<(String, u64), WorldError> {
                let glb = normalise(model_name, mesh)?;
                let hash = content_hash(&glb);
                let path = dir.model(&hash);
                if !path.exists() {
                    write_atomically(&path, &glb)?;
                }
                Ok((hash, glb.len() as u64))
            })
            .collect::<Result<_, _>>()?;
        let mut records: Vec<ModelRecord> = Vec::new();
        let mut seen = HashMap::new();
        for ((model_name, _), (hash, bytes)) in models.iter().zip(&stored) {
            seen.entry(hash.clone()).or_insert_with(|| {
                records.push(ModelRecord {
                    hash: hash.clone(),
                    name: model_name.clone(),
                    bytes: *bytes,
                });
            });
        }
        let objects = ObjectList {
            objects: objects
                .iter()
                .enumerate()
                .map(
                    |(i, (model, transform))| -> Result<ObjectRecord, WorldError> {
                        let (hash, _) = stored.get(*model).ok_or_else(|| {
                            WorldError::Inconsistent(format!(
                                "object {i} places model {model} of {}",
                                stored.len()
                            ))
                        })?;
                        Ok(ObjectRecord {
                            id: i as u32,
                            model: hash.clone(),
                            transform: transform.to_cols_array(),
                        })
                    },
                )
                .collect::<Result<_, _>>()?,
        };
        let manifest = WorldManifest {
            format: FORMAT,
            name: name.to_owned(),
            seed,
            object_count: objects.objects.len(),
            model_count: records.len(),
            models: records,
        };
        WorldDir::write_json(&dir.objects(), &objects)?;
        WorldDir::write_json(&dir.manifest(), &manifest)?;
        Ok(World {
            dir,
            manifest,
            objects,
            descriptors: DescriptorCache::default(),
            tree: None,
        })
    }

    /// Opens the world in `root`: its manifest and objects, checked against each other, and
    /// the descriptors computed so far.
    pub fn open(root: &Path) -> Result<World, WorldError> {
        let dir = WorldDir::new(root);
        let (manifest, objects) = dir.load()?;
        let descriptors = if dir.descriptors().exists() {
            WorldDir::read_json(&dir.descriptors())?
        } else {
            DescriptorCache::default()
        };
        Ok(World {
            dir,
            manifest,
            objects,
            descriptors,
            tree: None,
        })
    }

    /// The directory's paths.
    pub fn dir(&self) -> &WorldDir {
        &self.dir
    }

    /// `world.json`.
    pub fn manifest(&self) -> &WorldManifest {
        &self.manifest
    }

    /// The placed objects, by id.
    pub fn objects(&self) -> &[ObjectRecord] {
        &self.objects.objects
    }

    /// The descriptors computed so far, by model hash.
    pub fn descriptors(&self) -> &DescriptorCache {
        &self.descriptors
    }

    /// Describes every model that has no descriptors yet (in parallel, reporting
    /// `progress(done, total)`), and saves the cache. Returns how many were computed.
    pub fn describe_models(
        &mut self,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<usize, WorldError> {
        let missing: Vec<&ModelRecord> = self
            .manifest
            .models
            .iter()
            .filter(|m| !self.descriptors.models.contains_key(&m.hash))
            .collect();
        let done = AtomicUsize::new(0);
        progress(0, missing.len());
        let computed: Vec<(String, ModelDescriptors)> = missing
            .par_iter()
            .map(|m| -> Result<(String, ModelDescriptors), WorldError> {
                let d = describe_stored(&self.dir.model(&m.hash))?;
                progress(done.fetch_add(1, Ordering::Relaxed) + 1, missing.len());
                Ok((m.hash.clone(), d))
            })
            .collect::<Result<_, _>>()?;
        let count = computed.len();
        if count > 0 {
            self.descriptors.models.extend(computed);
            WorldDir::write_json(&self.dir.descriptors(), &self.descriptors)?;
        }
        Ok(count)
    }

    /// BVH options for this world: eq. 1's `mu` and `w`, and the two descriptor distances
    /// normalised by this world's own scales, the median z_diff and the median t_diff between
    /// its distinct models (every pair up to [`SCALE_ALL_PAIRS_UP_TO`] models, else a seeded
    /// sample). One unit of either term then means "as different as two typical models of
    /// this world", which keeps shape, texture and volume on comparable footings whatever the
    /// world. Worlds with fewer than two described models, or whose medians are 0, keep the
    /// defaults.
    pub fn bvh_options(&self, mu: f32, w: f32) -> BvhOptions {
        let mut options = BvhOptions::default().with_weights(mu, w);
        let models: Vec<&ModelDescriptors> = self
            .manifest
            .models
            .iter()
            .filter_map(|m| self.descriptors.models.get(&m.hash))
            .collect();
        let n = models.len();
        if n < 2 {
            return options;
        }
        let pairs: Vec<(usize, usize)> = if n <= SCALE_ALL_PAIRS_UP_TO {
            (0..n)
                .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
                .collect()
        } else {
            let mut rng = Rng::new(SCALE_SAMPLE_SEED);
            (0..SCALE_SAMPLE_PAIRS)
                .map(|_| {
                    let a = ((rng.unit() * n as f32) as usize).min(n - 1);
                    let b = ((rng.unit() * (n - 1) as f32) as usize).min(n - 2);
                    (a, if b >= a { b + 1 } else { b })
                })
                .collect()
        };
        let median = |mut v: Vec<f32>| {
            v.sort_by(f32::total_cmp);
            v[v.len() / 2]
        };
        let z = median(
            pairs
                .iter()
                .map(|&(a, b)| zernike_distance(&models[a].zernike, &models[b].zernike))
                .collect(),
        );
        let t = median(
            pairs
                .iter()
                .map(|&(a, b)| csd_distance(&models[a].csd, &models[b].csd))
                .collect(),
        );
        if z.is_finite() && z > 0.0 {
            options.shape_scale = z;
        }
        if t.is_finite() && t > 0.0 {
            options.texture_scale = t;
        }
        options
    }

    /// The BVH's input: each object's world bounding sphere (its model's sphere through its
    /// transform) and its model's descriptors, the model numbered by its place in the
    /// manifest. Every model must be described.
    pub fn bvh_input(&self) -> Result<Vec<NewObject<'_>>, WorldError> {
        let index: HashMap<&str, usize> = self
            .manifest
            .models
            .iter()
            .enumerate()
            .map(|(i, m)| (m.hash.as_str(), i))
            .collect();
        self.objects
            .objects
            .iter()
            .map(|o| {
                let d = self.descriptors.models.get(&o.model).ok_or_else(|| {
                    WorldError::model(&o.model, "no descriptors (run horizon build)")
                })?;
                let t = Affine3A::from_cols_array(&o.transform);
                let scale = horizon_mesh::transform::max_axis_scale(&t);
                Ok(NewObject {
                    model: index[o.model.as_str()] as u64,
                    transform: t,
                    sphere: Sphere::new(
                        t.transform_point3(Vec3::from_array(d.centre)),
                        d.radius * scale,
                    ),
                    shape: &d.zernike,
                    texture: &d.csd,
                })
            })
            .collect()
    }

    /// Bulk-builds the BVH (section 4.3) with eq. 1's `mu` and `w` and this world's scales,
    /// and checks it. Every model must be described.
    pub fn build_tree(&mut self, mu: f32, w: f32) -> Result<&Bvh, WorldError> {
        let bvh = Bvh::bulk_build(self.bvh_options(mu, w), &self.bvh_input()?)?;
        bvh.validate()?;
        Ok(self.tree.insert(bvh))
    }

    /// Writes the BVH snapshot, `bvh.json`.
    pub fn save_tree(&self) -> Result<(), WorldError> {
        let bvh = self.tree_or_not_built()?;
        WorldDir::write_json(&self.dir.bvh(), bvh)
    }

    /// Reads the BVH snapshot a build wrote.
    pub fn load_tree(&mut self) -> Result<&Bvh, WorldError> {
        let path = self.dir.bvh();
        let bvh: Bvh = WorldDir::read_json(&path).map_err(|e| match e {
            WorldError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
                WorldError::NotBuilt(self.dir.root().to_path_buf())
            }
            other => other,
        })?;
        Ok(self.tree.insert(bvh))
    }

    /// The BVH, once built or loaded.
    pub fn tree(&self) -> Option<&Bvh> {
        self.tree.as_ref()
    }

    /// The BVH, to change in place (a benchmark inserting objects).
    pub fn tree_mut(&mut self) -> Option<&mut Bvh> {
        self.tree.as_mut()
    }

    fn tree_or_not_built(&self) -> Result<&Bvh, WorldError> {
        self.tree
            .as_ref()
            .ok_or_else(|| WorldError::NotBuilt(self.dir.root().to_path_buf()))
    }

    /// Every model of the world imported from its stored GLB and prepared for the rebuild,
    /// numbered as the BVH numbers them. Every model must be described.
    pub fn source_models(&self) -> Result<InMemoryModels, WorldError> {
        let models = self
            .manifest
            .models
            .par_iter()
            .map(|m| -> Result<SourceModel, WorldError> {
                let path = self.dir.model(&m.hash);
                let mesh = import_file(&path, &ImportOptions::default())
                    .map_err(|e| WorldError::model(path.display().to_string(), e))?
                    .mesh;
                let d = self
                    .descriptors
                    .models
                    .get(&m.hash)
                    .ok_or_else(|| WorldError::model(&m.hash, "no descriptors"))?;
                Ok(SourceModel::new(
                    m.hash.clone(),
                    mesh,
                    d.zernike.clone(),
                    d.csd.clone(),
                ))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(InMemoryModels::new(models))
    }

    /// The world's aggregate store, `DIR/aggregates`.
    pub fn aggregate_dir(&self) -> AggregateDir {
        AggregateDir::new(&self.dir.aggregates())
    }

    /// The offline rebuild: every node of the BVH gets its aggregate in `DIR/aggregates`
    /// (nodes whose inputs did not change are reused), then what the new manifest no longer
    /// names is deleted, so the store holds one build.
    pub fn rebuild_aggregates(
        &self,
        models: &InMemoryModels,
        options: AggregateOptions,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<RebuildReport, WorldError> {
        let bvh = self.tree_or_not_built()?;
        let store = self.aggregate_dir();
        let options = BuildOptions {
            aggregate: options,
            world_textures: models.texture_totals(),
        };
        let outcome = build_aggregates(bvh, models, &store, &options, progress)?;
        let removed = store.collect_garbage(&outcome.manifest)?;
        Ok(RebuildReport {
            build: outcome.report,
            removed,
        })
    }

    /// The cut for a viewer (eq. 3): every object subtending at least the query's solid angle
    /// as itself, everything else through exactly one ancestor aggregate, largest solid
    /// angle first under the query's budget.
    pub fn cut(&self, query: &CutQuery) -> Result<Cut, WorldError> {
        Ok(self.tree_or_not_built()?.cut(query))
    }
}
