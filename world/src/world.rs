//! [`World`]: one world directory, opened, and everything the product does to it as functions
//! over it. Thread-safe: requests, the rebuild and readers share one `World`.
//!
//! ```text
//! DIR/world.db     the metadata (SqliteMeta): models, objects, users, generations, log, entries
//! DIR/blobs/       the content-addressed blobs (BlobDir): models, aggregates, manifests, trees
//! ```
//!
//! The pipeline: create or upload (ingest every model, place the objects) -> describe the
//! models -> the similarity-aware BVH (core paper eq. 1, section 4.3) -> the aggregates
//! (sections 5 to 7), published as one step -> cuts (eq. 3).
//!
//! **Generations.** Every committed mutation is a generation. A mutation commits in the
//! metadata store first (durable when the call returns), then goes into the tree, under one
//! writer lock, so the tree applies changes in generation order and can be replayed from its
//! snapshot and the log after a crash (`tree.rs`). The rebuild takes a copy of the tree at
//! generation g, builds what changed, and publishes g; changes made meanwhile stay dirty for
//! the next rebuild.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, RwLock};
use std::time::{Duration, Instant};

use glam::Affine3A;
use horizon_aggregate::{
    build_aggregates_until, AggregateManifest, AggregateOptions, BuildOptions, BuildReport,
    ImpostorPolicy, Progress,
};
use horizon_bvh::{Aabb, BvhOptions, Cut, CutQuery, NodeId};
use horizon_descriptors::{csd_distance, zernike_distance};
use horizon_mesh::rng::Rng;
use horizon_mesh::InstancedMesh;
use rayon::prelude::*;
use serde::Serialize;

use crate::aggregates::{named_blobs, recorded_entries, stored_entries, AggregateSink};
use crate::error::WorldError;
use crate::hash::content_hash;
use crate::ingest::{
    describe_read, describe_stored, import_upload, level_read, level_stored, normalise,
    read_stored, stats, UploadLimits,
};
use crate::legacy::{is_legacy, LegacyWorld};
use crate::models::Models;
use crate::store::{
    Applied, BlobDir, BlobStore, MetaStore, ModelDescriptors, ModelLevel, ModelRow, Mutation,
    NewModel, ObjectRow, Published, Snapshot, SqliteMeta, User,
};
use crate::tree::{Describe, Tree};
use horizon_levels::{Chain, LevelInfo};

/// Distinct models up to which the BVH's descriptor scales come from every pair of them;
/// above it, from [`SCALE_SAMPLE_PAIRS`] seeded pairs.
const SCALE_ALL_PAIRS_UP_TO: usize = 400;
/// Pairs sampled for the descriptor scales of a world with many models.
const SCALE_SAMPLE_PAIRS: usize = 40_000;
/// Seed of that sample, fixed so that a world always gets the same tree.
const SCALE_SAMPLE_SEED: u64 = 0x5CA1E;
/// Changes logged after which the rebuild writes a new tree snapshot, so that a restart
/// replays at most about this many.
pub const SNAPSHOT_EVERY: u64 = 10_000;

/// What ingest derived from a model, stored with its row when given.
#[derive(Clone, Copy, Default)]
struct Derived<'a> {
    descriptors: Option<&'a ModelDescriptors>,
    levels: Option<&'a (LevelInfo, Chain)>,
}

/// Models levelled per batch by [`World::level_models`]: their blobs made durable in one
/// flush, their level lists recorded in one transaction.
const LEVEL_BATCH: usize = 128;

/// A world, opened (see the module docs).
#[derive(Debug)]
pub struct World {
    root: PathBuf,
    meta: Arc<dyn MetaStore>,
    blobs: Arc<dyn BlobStore>,
    models: Models,
    limits: UploadLimits,
    /// The exclusive lock on `DIR/world.lock`, if this process got it: only its holder
    /// serves, builds, or clears what interrupted writes left.
    lock: Option<std::fs::File>,
    /// Held while a model's blob is stored and its row recorded, so that rows enter the
    /// model list in number order and a refused model's blob is judged unused correctly.
    storing: Mutex<()>,
    /// Held by a mutation from its commit until the tree has it.
    writer: Mutex<()>,
    tree: RwLock<Option<Tree>>,
    status: Mutex<Status>,
    /// Published manifests read or written, by blob hash (the current one and the one
    /// before it are what the service reads).
    manifests: Mutex<HashMap<String, Arc<AggregateManifest>>>,
    /// The recorded aggregate entries whose blobs are stored, by key, once read: the
    /// rebuild's reuse index, kept in step with what builds commit and collection removes.
    entries: Mutex<Option<HashMap<String, horizon_aggregate::AggregateEntry>>>,
    /// Signalled on every committed mutation and publish.
    changed: Condvar,
    /// Called after every committed mutation and publish ([`World::on_change`]).
    listeners: Listeners,
    /// Which nodes rebuilds give impostors ([`World::set_impostors`]).
    impostors: Mutex<ImpostorPolicy>,
}

/// The functions told of every committed mutation and publish.
#[derive(Default)]
struct Listeners(RwLock<Vec<Box<dyn Fn() + Send + Sync>>>);

impl std::fmt::Debug for Listeners {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.0.read().map_or(0, |l| l.len());
        write!(f, "Listeners({n})")
    }
}

/// What changes between rebuilds.
#[derive(Debug, Default)]
struct Status {
    generation: u64,
    published: Published,
    objects: u64,
    /// Nodes changed since the published generation, with the generation that last changed
    /// each.
    dirty: BTreeMap<NodeId, u64>,
    /// When the first change not yet published was committed.
    first_change: Option<Instant>,
    /// When the last change was committed.
    last_change: Option<Instant>,
    /// The snapshot's generation.
    snapshot: u64,
}

/// What a cut reads ([`World::with_served`]).
#[derive(Debug)]
pub struct Served<'a> {
    /// The tree at the last committed generation.
    pub tree: &'a Tree,
    /// The generation whose aggregates are served.
    pub published: u64,
    /// Its manifest (none before the first rebuild).
    pub manifest: Option<Arc<AggregateManifest>>,
}

/// A summary of the world, for `GET /v1/world` and the command line.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WorldStatus {
    /// The last committed generation.
    pub generation: u64,
    /// The published generation.
    pub published: u64,
    /// Objects.
    pub objects: u64,
    /// Models.
    pub models: u64,
    /// Nodes dirty since the published generation.
    pub dirty_nodes: u64,
    /// Wall time of the rebuild that published, milliseconds.
    pub last_rebuild_ms: Option<u64>,
    /// The box of every object, if the tree is loaded and not empty.
    pub bounds: Option<Aabb>,
}

/// What [`World::rebuild_aggregates`] did.
#[derive(Clone, Debug, Serialize)]
pub struct RebuildReport {
    /// The rebuild.
    #[serde(flatten)]
    pub build: BuildReport,
    /// The generation it published.
    pub generation: u64,
    /// Blobs of earlier builds that no published manifest names any more, deleted.
    pub removed_blobs: usize,
    /// Wall seconds outside the build itself: before it (the tree, the stored entries and
    /// the previous manifest), publishing (the manifest written, the generation recorded) and
    /// collecting what is no longer named.
    pub overhead: RebuildOverhead,
}

/// Where a rebuild's wall time goes outside [`BuildReport::seconds`].
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct RebuildOverhead {
    /// From the call to the build's start.
    pub prepare_seconds: f64,
    /// From the build's end to the generation's publication.
    pub publish_seconds: f64,
    /// Garbage collection (and a tree snapshot when one is due), after publication.
    pub collect_seconds: f64,
}

/// One change a user asks for.
#[derive(Clone, Debug, PartialEq)]
pub enum Change {
    /// Place the model with this id.
    Create {
        /// The model's id.
        model: String,
        /// Model-to-world transform.
        transform: Affine3A,
    },
    /// Give an object a new transform.
    Move {
        /// The object.
        id: u64,
        /// Its new transform.
        transform: Affine3A,
    },
    /// Remove an object.
    Delete {
        /// The object.
        id: u64,
    },
}

/// Models [`World::create_with`] makes and stores at a time.
pub const CREATE_BATCH: usize = 256;

impl World {
    /// Writes a new world into `root`: every model normalised and stored under its content
    /// hash (models whose GLBs are identical share one record, the first name kept), then
    /// the objects, each `(index into models, model-to-world transform)`, in one generation
    /// each.
    pub fn create(
        root: &Path,
        name: &str,
        seed: u64,
        models: &[(String, InstancedMesh)],
        objects: &[(usize, Affine3A)],
    ) -> Result<World, WorldError> {
        Self::create_with(
            root,
            name,
            seed,
            models.len(),
            &|k| Ok(models[k].clone()),
            objects,
            &|_, _| {},
        )
    }

    /// [`World::create`] for worlds too large to hold in memory: model `k` of `count` is
    /// made by `model(k)` when it is stored, [`CREATE_BATCH`] at a time in parallel;
    /// `progress(done, count)` follows the models.
    pub fn create_with(
        root: &Path,
        name: &str,
        seed: u64,
        count: usize,
        model: &(dyn Fn(usize) -> Result<(String, InstancedMesh), WorldError> + Sync),
        objects: &[(usize, Affine3A)],
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<World, WorldError> {
        if root.join("world.db").exists() || is_legacy(root) {
            return Err(WorldError::Inconsistent(format!(
                "{} already holds a world",
                root.display()
            )));
        }
        std::fs::create_dir_all(root).map_err(|e| WorldError::io(root, e))?;
        let world = Self::open_stores(root, name, seed)?;
        let mut numbers = Vec::with_capacity(count);
        for first in (0..count).step_by(CREATE_BATCH) {
            let batch = first..(first + CREATE_BATCH).min(count);
            let stored: Vec<(String, Vec<u8>, serde_json::Value)> = batch
                .into_par_iter()
                .map(|k| {
                    let (model_name, mesh) = model(k)?;
                    let glb = normalise(&model_name, &mesh)?;
                    Ok((model_name, glb, stats(&mesh)))
                })
                .collect::<Result<_, WorldError>>()?;
            for (model_name, glb, stats) in &stored {
                let row = world
                    .store_model(glb, glb, model_name, None, stats, Derived::default())?
                    .0;
                numbers.push(row.number);
            }
            progress(numbers.len(), count);
        }
        let mutations: Vec<Mutation> = objects
            .iter()
            .enumerate()
            .map(|(i, &(model, transform))| {
                let model = *numbers.get(model).ok_or_else(|| {
                    WorldError::Inconsistent(format!(
                        "object {i} places model {model} of {}",
                        numbers.len()
                    ))
                })?;
                Ok(Mutation::Create { model, transform })
            })
            .collect::<Result<_, WorldError>>()?;
        world.meta.apply(None, &mutations)?;
        world.refresh_status()?;
        Ok(world)
    }

    /// Opens the world in `root`. A world of format 1 (the JSON files of earlier versions) is
    /// upgraded first: its models and objects move into the database and the blob folder.
    pub fn open(root: &Path) -> Result<World, WorldError> {
        if !root.join("world.db").exists() {
            if is_legacy(root) {
                return Self::upgrade(root);
            }
            return Err(WorldError::NotAWorld(root.to_path_buf()));
        }
        let world = Self::open_stores(root, "", 0)?;
        if world.is_exclusive() {
            world.blobs.sweep()?;
            world.remove_orphans()?;
        }
        world.refresh_status()?;
        Ok(world)
    }

    /// Opens the world in `root`, or starts an empty one there (named after the folder) if
    /// `root` is missing or empty.
    pub fn open_or_create(root: &Path) -> Result<World, WorldError> {
        let empty = match std::fs::read_dir(root) {
            Ok(mut entries) => entries.next().is_none(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => true,
            Err(e) => return Err(WorldError::io(root, e)),
        };
        if !empty {
            return Self::open(root);
        }
        let name = root
            .file_name()
            .map_or_else(|| "world".to_owned(), |n| n.to_string_lossy().into_owned());
        Self::create(root, &name, 0, &[], &[])
    }

    /// Whether this process holds the world's lock: no other process serves or builds it.
    pub fn is_exclusive(&self) -> bool {
        self.lock.is_some()
    }

    /// The stores of `root`, created if missing, and the world's lock if free.
    fn open_stores(root: &Path, name: &str, seed: u64) -> Result<World, WorldError> {
        let lock_path = root.join("world.lock");
        let file = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&lock_path)
            .map_err(|e| WorldError::io(&lock_path, e))?;
        let lock = file.try_lock().is_ok().then_some(file);
        let meta: Arc<dyn MetaStore> =
            Arc::new(SqliteMeta::open(&root.join("world.db"), name, seed)?);
        let blobs: Arc<dyn BlobStore> = Arc::new(BlobDir::new(&root.join("blobs")));
        let models = Models::load(meta.clone(), blobs.clone())?;
        Ok(World {
            root: root.to_path_buf(),
            meta,
            blobs,
            models,
            limits: UploadLimits::default(),
            lock,
            storing: Mutex::new(()),
            writer: Mutex::new(()),
            tree: RwLock::new(None),
            status: Mutex::new(Status::default()),
            manifests: Mutex::new(HashMap::new()),
            entries: Mutex::new(None),
            changed: Condvar::new(),
            listeners: Listeners::default(),
            impostors: Mutex::new(ImpostorPolicy::WherePaying),
        })
    }

    /// Moves a format-1 world into the database: models re-addressed by BLAKE3, descriptors
    /// carried over, objects placed in id order. Every model is read before anything is
    /// written, and the database is built under another name and renamed into place when
    /// whole, so an interrupted upgrade is started again by the next open. The old files are
    /// left as they were.
    fn upgrade(root: &Path) -> Result<World, WorldError> {
        let legacy = LegacyWorld::read(root)?;
        let mut models = Vec::with_capacity(legacy.manifest.models.len());
        for m in &legacy.manifest.models {
            let glb = legacy.model_bytes(&m.hash)?;
            let mesh = horizon_mesh::import_bytes(
                &glb,
                horizon_mesh::Format::Glb,
                None,
                &horizon_mesh::ImportOptions::trusted(),
            )
            .map_err(|e| WorldError::model(&m.name, e))?
            .mesh;
            models.push((m, glb, stats(&mesh)));
        }
        let building = root.join("world.db.upgrading");
        for suffix in ["", "-wal", "-shm"] {
            let _ = std::fs::remove_file(format!("{}{suffix}", building.display()));
        }
        {
            let meta = SqliteMeta::open(&building, &legacy.manifest.name, legacy.manifest.seed)?;
            let blobs = BlobDir::new(&root.join("blobs"));
            let mut numbers: HashMap<&str, u64> = HashMap::new();
            for (m, glb, stats) in &models {
                let asset = blobs.put(glb)?;
                let (row, _) = meta.add_model(NewModel {
                    id: &asset,
                    asset: &asset,
                    name: &m.name,
                    owner: None,
                    bytes: glb.len() as u64,
                    stats,
                    descriptors: legacy.descriptors.get(&m.hash),
                    levels: None,
                })?;
                numbers.insert(m.hash.as_str(), row.number);
            }
            let mutations: Vec<Mutation> = legacy
                .objects
                .iter()
                .map(|o| Mutation::Create {
                    model: numbers[o.model.as_str()],
                    transform: Affine3A::from_cols_array(&o.transform),
                })
                .collect();
            meta.apply(None, &mutations)?;
            meta.checkpoint()?;
        }
        let db = root.join("world.db");
        std::fs::rename(&building, &db).map_err(|e| WorldError::io(&db, e))?;
        crate::durable::sync_dir(root);
        Self::open(root)
    }

    /// Reads the counters the status reports from the stores.
    fn refresh_status(&self) -> Result<(), WorldError> {
        let generation = self.meta.generation()?;
        let published = self.meta.published()?;
        let objects = self.meta.object_count()?;
        let snapshot = self.meta.snapshot()?.map_or(0, |s| s.generation);
        let mut s = self.lock_status()?;
        s.generation = generation;
        s.objects = objects;
        s.snapshot = snapshot;
        if generation > published.generation && s.first_change.is_none() {
            // Changes committed before this process started are due at once.
            s.first_change = Some(Instant::now());
            s.last_change = Some(Instant::now());
        }
        s.published = published;
        Ok(())
    }

    /// The world's directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The world's name and seed.
    pub fn identity(&self) -> Result<(String, u64), WorldError> {
        self.meta.identity()
    }

    /// The limits uploads are held to.
    pub fn upload_limits(&self) -> UploadLimits {
        self.limits
    }

    /// Sets the limits uploads are held to.
    pub fn set_upload_limits(&mut self, limits: UploadLimits) {
        self.limits = limits;
    }

    // ---------------------------------------------------------------------------------------
    // Models
    // ---------------------------------------------------------------------------------------

    /// Stores a model: its GLB as a blob, then its row (id: the hash of `source`, the bytes
    /// it came as). Returns the row and whether it was new.
    fn store_model(
        &self,
        source: &[u8],
        glb: &[u8],
        name: &str,
        owner: Option<&str>,
        stats: &serde_json::Value,
        derived: Derived<'_>,
    ) -> Result<(ModelRow, bool), WorldError> {
        let Derived {
            descriptors,
            levels,
        } = derived;
        let _storing = self
            .storing
            .lock()
            .map_err(|_| WorldError::Inconsistent("model store lock poisoned".into()))?;
        let asset = self.blobs.put(glb)?;
        let levels = levels
            .map(|(zero, chain)| self.list_levels(&asset, zero, chain, false))
            .transpose()?;
        let id = content_hash(source);
        let added = self.meta.add_model(NewModel {
            id: &id,
            asset: &asset,
            name,
            owner,
            bytes: glb.len() as u64,
            stats,
            descriptors,
            levels: levels.as_deref(),
        });
        let (row, created) = match added {
            Ok(added) => added,
            Err(e) => {
                // A refused model leaves no blob behind, unless another model stores it.
                if self.models.by_asset(&asset).is_none() {
                    let _ = self.blobs.delete(&asset);
                }
                return Err(e);
            }
        };
        if created {
            self.models.add(row.clone())?;
        }
        Ok((row, created))
    }

    /// Stores the blobs of a model's coarser levels (durable before any row names them, or
    /// `staged` for the caller's next `commit_staged`) and returns its level list, level 0
    /// (`asset`, the stored GLB) first.
    fn list_levels(
        &self,
        asset: &str,
        zero: &LevelInfo,
        chain: &Chain,
        staged: bool,
    ) -> Result<Vec<ModelLevel>, WorldError> {
        let mut levels = vec![ModelLevel {
            asset: asset.to_owned(),
            info: zero.clone(),
        }];
        for level in &chain.levels {
            let asset = if staged {
                self.blobs.stage(&level.glb)?
            } else {
                self.blobs.put(&level.glb)?
            };
            levels.push(ModelLevel {
                asset,
                info: level.info.clone(),
            });
        }
        Ok(levels)
    }

    /// Ingests uploaded bytes for `owner`: import under the upload limits, validate,
    /// normalise, store, describe. The same bytes uploaded again (or concurrently) give the
    /// same model, stored once: `(row, false)`.
    pub fn upload_model(
        &self,
        bytes: &[u8],
        name: &str,
        owner: &str,
    ) -> Result<(ModelRow, bool), WorldError> {
        let id = content_hash(bytes);
        if let Some(row) = self.meta.model(&id)? {
            return Ok((row, false));
        }
        let ingested = import_upload(bytes, &self.limits)?;
        let glb = normalise(name, &ingested.mesh)?;
        self.meta.check_model_quota(owner, glb.len() as u64)?;
        let asset = content_hash(&glb);
        let (need_descriptors, need_levels) = (
            self.meta.descriptors(&asset)?.is_none(),
            self.meta.levels(&asset)?.is_none(),
        );
        // Both are computed from the stored GLB read back once, side by side.
        let stored = if need_descriptors || need_levels {
            Some(read_stored(name, &glb)?)
        } else {
            None
        };
        let (described, levels) = match &stored {
            Some(mesh) => rayon::join(
                || {
                    need_descriptors
                        .then(|| describe_read(name, mesh))
                        .transpose()
                },
                || need_levels.then(|| level_read(mesh, glb.len() as u64)),
            ),
            None => (Ok(None), None),
        };
        let described = described?;
        if let Some(failure) = levels.as_ref().and_then(|l| l.1.failure.as_ref()) {
            tracing::warn!(model = name, "levels of detail stopped early: {failure}");
        }
        self.store_model(
            bytes,
            &glb,
            name,
            Some(owner),
            &stats(&ingested.mesh),
            Derived {
                descriptors: described.as_ref(),
                levels: levels.as_ref(),
            },
        )
    }

    /// The model with this id.
    pub fn model(&self, id: &str) -> Result<Option<ModelRow>, WorldError> {
        self.meta.model(id)
    }

    /// Up to `limit` models with ids after `after`, in id order.
    pub fn models_page(
        &self,
        after: Option<&str>,
        limit: usize,
    ) -> Result<Vec<ModelRow>, WorldError> {
        self.meta.models_page(after, limit)
    }

    /// The models, by number, for the rebuild and the tree.
    pub fn models(&self) -> &Models {
        &self.models
    }

    /// Describes every model that has no descriptors yet (in parallel, reporting
    /// `progress(done, total)`). Returns how many were computed.
    pub fn describe_models(
        &self,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<usize, WorldError> {
        let missing = self.models.undescribed()?;
        let done = std::sync::atomic::AtomicUsize::new(0);
        progress(0, missing.len());
        missing.par_iter().try_for_each(|&number| {
            let row = self.models.row(number)?;
            let glb = self.models.glb(number)?;
            let d = describe_stored(&row.name, &glb)?;
            self.meta.put_descriptors(&row.asset, &d)?;
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(n, missing.len());
            Ok::<(), WorldError>(())
        })?;
        Ok(missing.len())
    }

    /// Builds the levels of detail of every model that has none yet (in parallel, reporting
    /// `progress(done, total)`). Returns how many models were levelled, and for each model
    /// whose chain stopped on a failure, its name and why (it keeps the levels made before).
    pub fn level_models(
        &self,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<(usize, Vec<(String, String)>), WorldError> {
        let levelled = self.meta.all_levels()?;
        let mut missing = Vec::new();
        let mut seen = HashSet::new();
        for row in self.models.rows()? {
            if !levelled.contains_key(&row.asset) && seen.insert(row.asset.clone()) {
                missing.push(row.number);
            }
        }
        // In batches: every level blob of a batch made durable in one flush, then the
        // batch's level lists recorded in one transaction.
        let mut failures = Vec::new();
        let mut done = 0;
        progress(0, missing.len());
        for batch in missing.chunks(LEVEL_BATCH) {
            let levelled = batch
                .par_iter()
                .map(|&number| {
                    let row = self.models.row(number)?;
                    let glb = self.models.glb(number)?;
                    let (zero, chain) = level_stored(&row.name, &glb)?;
                    let levels = self.list_levels(&row.asset, &zero, &chain, true)?;
                    if let Some(failure) = &chain.failure {
                        tracing::warn!(
                            model = row.name,
                            "levels of detail stopped early: {failure}"
                        );
                    }
                    Ok(((row.asset, levels), chain.failure.map(|f| (row.name, f))))
                })
                .collect::<Result<Vec<_>, WorldError>>()?;
            self.blobs.commit_staged()?;
            let (rows, failed): (Vec<(String, Vec<ModelLevel>)>, Vec<_>) =
                levelled.into_iter().unzip();
            self.meta.put_levels_batch(&rows)?;
            failures.extend(failed.into_iter().flatten());
            done += batch.len();
            progress(done, missing.len());
        }
        Ok((missing.len(), failures))
    }

    /// The levels of detail of the stored GLB `asset` (level 0 first; empty until levelled).
    pub fn levels_of(&self, asset: &str) -> Result<Vec<ModelLevel>, WorldError> {
        Ok(self.meta.levels(asset)?.unwrap_or_default())
    }

    /// Every model's levels of detail, by the content hash of its stored GLB.
    pub fn all_levels(&self) -> Result<HashMap<String, Vec<ModelLevel>>, WorldError> {
        self.meta.all_levels()
    }

    // ---------------------------------------------------------------------------------------
    // Objects
    // ---------------------------------------------------------------------------------------

    /// Applies `changes` for `user` (`None`: the world itself) as one transaction, then puts
    /// them in the tree. Fails whole, changing nothing, if any change is refused: an unknown
    /// model or object, another user's object, a quota.
    pub fn apply(
        &self,
        user: Option<&str>,
        changes: &[Change],
    ) -> Result<Vec<Applied>, WorldError> {
        let mutations = changes
            .iter()
            .map(|c| match c {
                Change::Create { model, transform } => {
                    let row = self
                        .meta
                        .model(model)?
                        .ok_or_else(|| WorldError::UnknownModel(format!("no model {model}")))?;
                    Ok(Mutation::Create {
                        model: row.number,
                        transform: *transform,
                    })
                }
                Change::Move { id, transform } => Ok(Mutation::Move {
                    id: *id,
                    transform: *transform,
                }),
                Change::Delete { id } => Ok(Mutation::Delete { id: *id }),
            })
            .collect::<Result<Vec<_>, WorldError>>()?;
        // Every placed model must be one the tree can take, before anything commits.
        for m in &mutations {
            if let Mutation::Create { model, .. } = m {
                self.models.descriptors_of(*model)?;
            }
        }
        let _writer = self.lock_writer()?;
        self.load_tree()?;
        let applied = self.meta.apply(user, &mutations)?;
        let mut touched = Vec::new();
        {
            let mut slot = self.write_tree()?;
            if let Some(tree) = slot.as_mut() {
                for a in &applied {
                    match tree.apply(a, &self.models) {
                        Ok(nodes) => touched.extend(nodes),
                        Err(e) => {
                            // Committed but not in the tree: the next load replays it.
                            *slot = None;
                            return Err(e);
                        }
                    }
                }
            }
        }
        let mut s = self.lock_status()?;
        if let Some(last) = applied.last() {
            s.generation = last.generation;
            for n in touched {
                s.dirty.insert(n, last.generation);
            }
            let now = Instant::now();
            s.first_change.get_or_insert(now);
            s.last_change = Some(now);
        }
        for m in &mutations {
            match m {
                Mutation::Create { .. } => s.objects += 1,
                Mutation::Delete { .. } => s.objects = s.objects.saturating_sub(1),
                Mutation::Move { .. } => {}
            }
        }
        drop(s);
        self.changed.notify_all();
        self.tell_listeners();
        Ok(applied)
    }

    /// The object with this id.
    pub fn object(&self, id: u64) -> Result<Option<ObjectRow>, WorldError> {
        self.meta.object(id)
    }

    /// Up to `limit` objects with ids after `after` (of `owner`, if given), in id order.
    pub fn objects_page(
        &self,
        after: Option<u64>,
        limit: usize,
        owner: Option<&str>,
    ) -> Result<Vec<ObjectRow>, WorldError> {
        self.meta.objects_page(after, limit, owner)
    }

    /// Every object, in id order.
    pub fn all_objects(&self) -> Result<Vec<ObjectRow>, WorldError> {
        let mut out = Vec::new();
        let mut after = None;
        loop {
            let page = self.meta.objects_page(after, 100_000, None)?;
            let Some(last) = page.last() else {
                return Ok(out);
            };
            after = Some(last.id);
            out.extend(page);
        }
    }

    // ---------------------------------------------------------------------------------------
    // Users
    // ---------------------------------------------------------------------------------------

    /// Creates a token for `user` (adding the user, or updating their limits): a random
    /// 256-bit bearer token, returned once as 64 hex digits; only its hash is stored.
    pub fn create_token(&self, user: &User) -> Result<String, WorldError> {
        if user.name.is_empty() || user.name.len() > 64 || user.name.chars().any(char::is_control) {
            return Err(WorldError::Inconsistent(format!(
                "user name {:?} must be 1 to 64 printable characters",
                user.name
            )));
        }
        let mut bytes = [0u8; 32];
        getrandom::fill(&mut bytes)
            .map_err(|e| WorldError::Inconsistent(format!("no randomness for a token: {e}")))?;
        let token: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        self.meta.add_token(user, &content_hash(token.as_bytes()))?;
        Ok(token)
    }

    /// The user a bearer token belongs to.
    pub fn user_of_token(&self, token: &str) -> Result<Option<User>, WorldError> {
        self.meta.user_of_token(&content_hash(token.as_bytes()))
    }

    // ---------------------------------------------------------------------------------------
    // The tree
    // ---------------------------------------------------------------------------------------

    /// BVH options for this world: eq. 1's `mu` and `w`, and the two descriptor distances
    /// normalised by this world's own scales, the median z_diff and the median t_diff between
    /// its distinct models (every pair up to [`SCALE_ALL_PAIRS_UP_TO`] models, else a seeded
    /// sample). One unit of either term then means "as different as two typical models of
    /// this world". Worlds with fewer than two described models, or whose medians are 0,
    /// keep the defaults.
    pub fn bvh_options(&self, mu: f32, w: f32) -> Result<BvhOptions, WorldError> {
        let mut options = BvhOptions::default().with_weights(mu, w);
        let mut seen = HashSet::new();
        let mut models = Vec::new();
        for row in self.models.rows()? {
            if seen.insert(row.asset.clone()) {
                if let Some(d) = self.meta.descriptors(&row.asset)? {
                    models.push(d);
                }
            }
        }
        let n = models.len();
        if n < 2 {
            return Ok(options);
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
        Ok(options)
    }

    /// Every model, in number order.
    pub fn all_models(&self) -> Result<Vec<ModelRow>, WorldError> {
        self.meta.models()
    }

    /// Every object as the bulk build takes it: (world id, model number, transform), in id
    /// order. [`crate::new_object`] makes the BVH's input of one, with the model's
    /// descriptors ([`Describe`] on [`World::models`]).
    pub fn bulk_input(&self) -> Result<Vec<(u64, u64, Affine3A)>, WorldError> {
        Ok(bulk_input(&self.all_objects()?))
    }

    /// Bulk-builds the BVH (section 4.3) of every object with eq. 1's `mu` and `w` and this
    /// world's scales, and snapshots it. Every model must be described. Returns its size.
    pub fn build_tree(&self, mu: f32, w: f32) -> Result<(usize, usize, u32), WorldError> {
        let _writer = self.lock_writer()?;
        self.describe_models(&|_, _| {})?;
        let generation = self.meta.generation()?;
        let rows = self.all_objects()?;
        let mut tree = Tree::bulk(
            self.bvh_options(mu, w)?,
            &bulk_input(&rows),
            &self.models,
            generation,
        )?;
        tree.set_placed(rows.iter().map(|o| (o.id, o.generation)));
        let summary = (tree.bvh.len(), tree.bvh.node_count(), tree.bvh.height());
        self.save_snapshot(&tree)?;
        *self.write_tree()? = Some(tree);
        Ok(summary)
    }

    /// Loads the tree if it is not loaded: its snapshot with the log replayed, or, for a world
    /// never built, a bulk build with the default weights (its models described first), then
    /// snapshotted if this process holds the world.
    pub fn ensure_tree(&self) -> Result<(), WorldError> {
        if self.read_tree()?.is_some() {
            return Ok(());
        }
        let _writer = self.lock_writer()?;
        self.load_tree()
    }

    /// [`World::ensure_tree`] with the writer lock held, so that the generation and the
    /// objects it reads are one state.
    fn load_tree(&self) -> Result<(), WorldError> {
        if self.read_tree()?.is_some() {
            return Ok(());
        }
        let published = self.lock_status()?.published.generation;
        let mut touched = Vec::new();
        let tree = match self.meta.snapshot()? {
            Some(snapshot) => {
                let bytes = self.blobs.get(&snapshot.blob)?.ok_or_else(|| {
                    WorldError::Inconsistent(format!(
                        "the tree snapshot {} is missing",
                        snapshot.blob
                    ))
                })?;
                let mut tree = Tree::from_snapshot(&bytes)?;
                for change in self.meta.log_after(tree.generation)? {
                    let nodes = tree.apply(&change, &self.models)?;
                    if change.generation > published {
                        touched.extend(nodes.into_iter().map(|n| (n, change.generation)));
                    }
                }
                tree.set_placed(self.all_objects()?.iter().map(|o| (o.id, o.generation)));
                tree
            }
            None => {
                self.describe_models(&|_, _| {})?;
                let generation = self.meta.generation()?;
                let options = self.bvh_options(horizon_bvh::DEFAULT_MU, horizon_bvh::DEFAULT_W)?;
                let rows = self.all_objects()?;
                let objects = bulk_input(&rows);
                let mut tree = if objects.is_empty() {
                    let mut tree = Tree::empty(options)?;
                    tree.generation = generation;
                    tree
                } else {
                    Tree::bulk(options, &objects, &self.models, generation)?
                };
                tree.set_placed(rows.iter().map(|o| (o.id, o.generation)));
                // Only the world's holder writes; a reader beside it keeps its tree to itself.
                if self.is_exclusive() {
                    self.save_snapshot(&tree)?;
                }
                tree
            }
        };
        // Nodes changed since the published generation are dirty again in this process.
        self.lock_status()?.dirty.extend(touched);
        *self.write_tree()? = Some(tree);
        Ok(())
    }

    /// Runs `f` on the tree (loaded first if need be).
    pub fn with_tree<T>(&self, f: impl FnOnce(&Tree) -> T) -> Result<T, WorldError> {
        self.ensure_tree()?;
        let tree = self.read_tree()?;
        let tree = tree
            .as_ref()
            .ok_or_else(|| WorldError::NotBuilt(self.root.clone()))?;
        Ok(f(tree))
    }

    /// The cut for a viewer (eq. 3): every object subtending at least the query's solid angle
    /// as itself, everything else through exactly one ancestor aggregate, largest solid
    /// angle first under the query's budget.
    pub fn cut(&self, query: &CutQuery) -> Result<Cut, WorldError> {
        self.with_tree(|tree| tree.bvh.cut(query))
    }

    /// Runs `f` on what a cut reads: the tree at the last committed generation, the
    /// published generation and its manifest (read before the tree, so the tree is never
    /// older than the manifest).
    pub fn with_served<T>(&self, f: impl FnOnce(&Served<'_>) -> T) -> Result<T, WorldError> {
        self.ensure_tree()?;
        let (published, manifest) = self.published_and_manifest()?;
        let tree = self.read_tree()?;
        let tree = tree
            .as_ref()
            .ok_or_else(|| WorldError::NotBuilt(self.root.clone()))?;
        Ok(f(&Served {
            tree,
            published: published.generation,
            manifest,
        }))
    }

    /// [`World::record_snapshot`] of `tree`.
    fn save_snapshot(&self, tree: &Tree) -> Result<(), WorldError> {
        self.record_snapshot(tree.generation, &tree.to_snapshot()?)
    }

    /// Records `bytes` (a tree snapshot at `generation`) as the snapshot that loads replay
    /// from, which lets the log before it go, and deletes the one it replaces. The caller
    /// holds the writer lock, so that no load in this process reads the old snapshot while
    /// the log it replays is cut.
    fn record_snapshot(&self, generation: u64, bytes: &[u8]) -> Result<(), WorldError> {
        let before = self.meta.snapshot()?;
        let blob = self.blobs.put(bytes)?;
        self.meta.put_snapshot(&Snapshot {
            generation,
            blob: blob.clone(),
        })?;
        self.lock_status()?.snapshot = generation;
        // The snapshot it replaces names nothing now: the log before the new one is gone.
        if let Some(old) = before.filter(|old| old.blob != blob) {
            self.blobs.delete(&old.blob)?;
        }
        Ok(())
    }

    // ---------------------------------------------------------------------------------------
    // The rebuild
    // ---------------------------------------------------------------------------------------

    /// The manifest being served.
    pub fn published_manifest(&self) -> Result<Option<Arc<AggregateManifest>>, WorldError> {
        Ok(self.published_and_manifest()?.1)
    }

    /// The published record and its manifest. A manifest is collected once two newer ones
    /// are published, so a reader that lost that race reads the newer record again.
    fn published_and_manifest(
        &self,
    ) -> Result<(Published, Option<Arc<AggregateManifest>>), WorldError> {
        let mut published = self.lock_status()?.published.clone();
        let mut attempts = 0;
        loop {
            match self.read_manifest(published.manifest.as_deref()) {
                Ok(manifest) => return Ok((published, manifest)),
                Err(e) => {
                    attempts += 1;
                    let now = self.lock_status()?.published.clone();
                    if now.manifest == published.manifest || attempts == 3 {
                        return Err(e);
                    }
                    published = now;
                }
            }
        }
    }

    fn read_manifest(
        &self,
        hash: Option<&str>,
    ) -> Result<Option<Arc<AggregateManifest>>, WorldError> {
        let Some(hash) = hash else {
            return Ok(None);
        };
        if let Some(m) = self.lock_manifests()?.get(hash) {
            return Ok(Some(m.clone()));
        }
        let bytes = self.blobs.get(hash)?.ok_or_else(|| {
            WorldError::Inconsistent(format!("the published manifest {hash} is missing"))
        })?;
        let manifest: AggregateManifest = serde_json::from_slice(&bytes)
            .map_err(|e| WorldError::Inconsistent(format!("manifest {hash}: {e}")))?;
        let manifest = Arc::new(manifest);
        self.lock_manifests()?
            .insert(hash.to_owned(), manifest.clone());
        Ok(Some(manifest))
    }

    fn lock_manifests(
        &self,
    ) -> Result<MutexGuard<'_, HashMap<String, Arc<AggregateManifest>>>, WorldError> {
        self.manifests
            .lock()
            .map_err(|_| WorldError::Inconsistent("manifest cache lock poisoned".into()))
    }

    fn lock_entries(
        &self,
    ) -> Result<
        MutexGuard<'_, Option<HashMap<String, horizon_aggregate::AggregateEntry>>>,
        WorldError,
    > {
        self.entries
            .lock()
            .map_err(|_| WorldError::Inconsistent("entry cache lock poisoned".into()))
    }

    /// Which nodes the next rebuilds give orthoview impostors (default: where an impostor
    /// costs less to serve than the aggregate). A rebuild reuses the impostors of an earlier
    /// one only where both choose them.
    pub fn set_impostors(&self, policy: ImpostorPolicy) {
        if let Ok(mut p) = self.impostors.lock() {
            *p = policy;
        }
    }

    /// The rebuild: a copy of the tree at the current generation gets every node's aggregate
    /// (nodes whose inputs did not change are reused), the new manifest is published as one
    /// step, and blobs that neither it nor the manifest before it names go. Changes committed
    /// during the build stay dirty for the next one.
    pub fn rebuild_aggregates(
        &self,
        options: AggregateOptions,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<RebuildReport, WorldError> {
        self.rebuild_aggregates_until(options, progress, &|| false)
    }

    /// [`World::rebuild_aggregates`], stopping before the next tree level once `stop` says so
    /// (with [`horizon_aggregate::AggregateError::Stopped`]): what was built is kept for the
    /// next rebuild, nothing is published.
    pub fn rebuild_aggregates_until(
        &self,
        options: AggregateOptions,
        progress: &(dyn Fn(Progress) + Sync),
        stop: &(dyn Fn() -> bool + Sync),
    ) -> Result<RebuildReport, WorldError> {
        self.ensure_tree()?;
        let started = Instant::now();
        let tree = self
            .read_tree()?
            .clone()
            .ok_or_else(|| WorldError::NotBuilt(self.root.clone()))?;
        let generation = tree.generation;
        let previous = self.lock_status()?.published.clone();
        let known = {
            let mut entries = self.lock_entries()?;
            if entries.is_none() {
                *entries = Some(stored_entries(self.meta.as_ref(), self.blobs.as_ref())?);
            }
            entries.clone().unwrap_or_default()
        };
        let sink = AggregateSink::new(
            self.meta.as_ref(),
            self.blobs.as_ref(),
            self.read_manifest(previous.manifest.as_deref())?
                .map(|m| (*m).clone()),
        )
        .with_known(known);
        let build = BuildOptions {
            aggregate: options,
            world_textures: self.models.texture_totals()?,
            impostors: self
                .impostors
                .lock()
                .map_or(ImpostorPolicy::WherePaying, |p| *p),
        };
        let prepare_seconds = started.elapsed().as_secs_f64();
        let outcome =
            build_aggregates_until(&tree.bvh, &self.models, &sink, &build, progress, stop);
        let built_at = Instant::now();
        // What the build committed is reusable whether or not it finished.
        if let Some(entries) = self.lock_entries()?.as_mut() {
            entries.extend(sink.committed().into_iter().map(|e| (e.key.clone(), e)));
        }
        let outcome = outcome?;
        let manifest_bytes = serde_json::to_vec(&outcome.manifest)
            .map_err(|e| WorldError::Inconsistent(e.to_string()))?;
        let manifest = self.blobs.put(&manifest_bytes)?;
        self.lock_manifests()?
            .insert(manifest.clone(), Arc::new(outcome.manifest.clone()));
        let published = Published {
            generation,
            manifest: Some(manifest.clone()),
            previous_manifest: previous.manifest.clone().filter(|m| *m != manifest),
            rebuild_ms: Some(started.elapsed().as_millis() as u64),
        };
        // The manifest no longer published: its orthoview images go unless still named.
        let dropped = previous
            .previous_manifest
            .clone()
            .filter(|m| Some(m) != published.manifest.as_ref())
            .filter(|m| Some(m) != published.previous_manifest.as_ref());
        self.meta.publish(&published)?;
        {
            let mut s = self.lock_status()?;
            s.published = published.clone();
            s.dirty.retain(|_, g| *g > generation);
            if s.generation <= generation {
                s.first_change = None;
                s.last_change = None;
            } else {
                s.first_change = s.last_change;
            }
        }
        self.changed.notify_all();
        self.tell_listeners();
        let publish_seconds = built_at.elapsed().as_secs_f64();
        let published_at = Instant::now();
        let removed_blobs =
            self.collect_garbage(&outcome.manifest, &published, dropped.as_deref())?;
        if generation.saturating_sub(self.lock_status()?.snapshot) >= SNAPSHOT_EVERY {
            let bytes = tree.to_snapshot()?;
            let _writer = self.lock_writer()?;
            self.record_snapshot(tree.generation, &bytes)?;
        }
        Ok(RebuildReport {
            build: outcome.report,
            generation,
            removed_blobs,
            overhead: RebuildOverhead {
                prepare_seconds,
                publish_seconds,
                collect_seconds: published_at.elapsed().as_secs_f64(),
            },
        })
    }

    /// Deletes the aggregate blobs and entries that neither the published manifest nor the
    /// one before it names (clients may still fetch what the one before named), and the
    /// orthoview images of `dropped` (the manifest no longer published) that neither names,
    /// and `dropped` itself. Models, the two published manifests and snapshots are never
    /// collected here.
    fn collect_garbage(
        &self,
        current: &AggregateManifest,
        published: &Published,
        dropped: Option<&str>,
    ) -> Result<usize, WorldError> {
        // What the two published manifests name, borrowed from them: a build changes a few
        // nodes of thousands, so the names are many and the blobs to delete few.
        let previous = self.read_manifest(published.previous_manifest.as_deref())?;
        let manifests = std::iter::once(current).chain(previous.as_deref());
        let mut keep: HashSet<&str> = HashSet::new();
        let mut kept: HashSet<&str> = HashSet::new();
        for m in manifests {
            keep.extend(m.blobs().map(String::as_str));
            kept.extend(m.nodes.values().map(|e| e.key.as_str()));
        }
        let mut entries = self.lock_entries()?;
        let stale: Vec<horizon_aggregate::AggregateEntry> = match entries.as_ref() {
            Some(map) => map
                .values()
                .filter(|e| !kept.contains(e.key.as_str()))
                .cloned()
                .collect(),
            None => recorded_entries(self.meta.as_ref())?
                .into_iter()
                .filter(|e| !kept.contains(e.key.as_str()))
                .collect(),
        };
        // The records go first: a crash before the blobs are deleted leaves orphans, which
        // the next open removes, never a record naming a missing blob.
        match entries.as_mut() {
            // The map holds every recorded entry whose blobs are stored: the stale ones go.
            Some(map) => {
                let stale_keys: Vec<String> = stale.iter().map(|e| e.key.clone()).collect();
                self.meta.remove_aggregate_entries(&stale_keys)?;
                map.retain(|k, _| kept.contains(k.as_str()));
            }
            None => {
                let keys: Vec<String> = kept.iter().map(|k| (*k).to_owned()).collect();
                self.meta.retain_aggregate_entries(&keys)?;
            }
        }
        let mut deleted: HashSet<String> = HashSet::new();
        let mut delete = |hash: &String| -> Result<(), WorldError> {
            if !keep.contains(hash.as_str()) && deleted.insert(hash.clone()) {
                self.blobs.delete(hash)?;
            }
            Ok(())
        };
        for entry in &stale {
            for hash in std::iter::once(&entry.glb).chain(entry.parts.as_ref()) {
                delete(hash)?;
            }
        }
        if let Some(old) = self.read_manifest(dropped).ok().flatten() {
            for hash in old.impostors.values().flat_map(|e| e.blobs()) {
                delete(hash)?;
            }
        }
        // The dropped manifest itself: tens of megabytes on a large world, written by every
        // publication, so a serving world that kept them would fill its disk.
        if let Some(hash) = dropped {
            delete(&hash.to_owned())?;
        }
        // Only the two published manifests are read again.
        let names: HashSet<&String> = [&published.manifest, &published.previous_manifest]
            .into_iter()
            .flatten()
            .collect();
        self.lock_manifests()?.retain(|k, _| names.contains(k));
        Ok(deleted.len())
    }

    /// Deletes every blob nothing refers to: not a model, not named by a recorded aggregate
    /// entry (a build that stopped before publishing is reused from them) or a published
    /// manifest, not a manifest or the tree snapshot. Such blobs are what an interrupted write
    /// leaves; they are only looked for at open, before any upload can be between storing its
    /// blob and recording its model.
    fn remove_orphans(&self) -> Result<usize, WorldError> {
        let published = self.meta.published()?;
        let mut keep: HashSet<String> = self.models.rows()?.into_iter().map(|r| r.asset).collect();
        for manifest in [&published.manifest, &published.previous_manifest]
            .into_iter()
            .flatten()
        {
            keep.insert(manifest.clone());
            if let Some(m) = self.read_manifest(Some(manifest))? {
                keep.extend(named_blobs(&m));
            }
        }
        if let Some(snapshot) = self.meta.snapshot()? {
            keep.insert(snapshot.blob);
        }
        for levels in self.meta.all_levels()?.into_values() {
            keep.extend(levels.into_iter().map(|l| l.asset));
        }
        for entry in recorded_entries(self.meta.as_ref())? {
            keep.insert(entry.glb);
            keep.extend(entry.parts);
        }
        let mut removed = 0;
        for hash in self.blobs.list()? {
            if !keep.contains(&hash) {
                self.blobs.delete(&hash)?;
                removed += 1;
            }
        }
        Ok(removed)
    }

    /// Forgets every aggregate: their entries, their blobs and the published manifests, so
    /// that the next rebuild builds everything from scratch (what a benchmark of a full build
    /// needs). Clients get no aggregates until then.
    pub fn forget_aggregates(&self) -> Result<(), WorldError> {
        let published = self.meta.published()?;
        let mut hashes: HashSet<String> = HashSet::new();
        for entry in recorded_entries(self.meta.as_ref())? {
            hashes.insert(entry.glb);
            hashes.extend(entry.parts);
        }
        hashes.extend(published.manifest.clone());
        hashes.extend(published.previous_manifest.clone());
        let unpublished = Published {
            generation: 0,
            manifest: None,
            previous_manifest: None,
            rebuild_ms: None,
        };
        self.meta.publish(&unpublished)?;
        self.lock_status()?.published = unpublished;
        self.meta.retain_aggregate_entries(&[])?;
        *self.lock_entries()? = Some(HashMap::new());
        self.lock_manifests()?.clear();
        let models: HashSet<String> = self.models.rows()?.into_iter().map(|r| r.asset).collect();
        for hash in hashes.difference(&models) {
            self.blobs.delete(hash)?;
        }
        Ok(())
    }

    /// Blocks until a rebuild is due under the debounce (`quiet` after the last change, and
    /// at most `max_wait` after the first), or `timeout` passes, or `stop` says so. Returns
    /// whether a rebuild is due.
    pub fn wait_for_rebuild(
        &self,
        quiet: Duration,
        max_wait: Duration,
        timeout: Duration,
        stop: &dyn Fn() -> bool,
    ) -> Result<bool, WorldError> {
        let deadline = Instant::now() + timeout;
        let mut s = self.lock_status()?;
        loop {
            if stop() {
                return Ok(false);
            }
            let now = Instant::now();
            let due = match (s.first_change, s.last_change) {
                (Some(first), Some(last)) => {
                    let at = (last + quiet).min(first + max_wait);
                    if now >= at {
                        return Ok(true);
                    }
                    Some(at)
                }
                _ => None,
            };
            if now >= deadline {
                return Ok(false);
            }
            let until = due.map_or(deadline, |at| at.min(deadline));
            s = self
                .changed
                .wait_timeout(s, until.saturating_duration_since(now))
                .map_err(|_| WorldError::Inconsistent("status lock poisoned".into()))?
                .0;
        }
    }

    /// Calls `f` after every committed mutation and publish, from the thread that made it:
    /// `f` must be quick (a service's streams use it to wake).
    pub fn on_change(&self, f: impl Fn() + Send + Sync + 'static) {
        if let Ok(mut listeners) = self.listeners.0.write() {
            listeners.push(Box::new(f));
        }
    }

    fn tell_listeners(&self) {
        if let Ok(listeners) = self.listeners.0.read() {
            for f in listeners.iter() {
                f();
            }
        }
    }

    /// Wakes anything waiting in [`World::wait_for_rebuild`] (to see a stop).
    pub fn wake(&self) {
        self.changed.notify_all();
    }

    /// The world's counters.
    pub fn status(&self) -> Result<WorldStatus, WorldError> {
        let bounds = self
            .read_tree()?
            .as_ref()
            .filter(|t| !t.bvh.is_empty())
            .and_then(|t| t.bvh.node(t.bvh.root()).map(|n| n.aabb()));
        let s = self.lock_status()?;
        Ok(WorldStatus {
            generation: s.generation,
            published: s.published.generation,
            objects: s.objects,
            models: self.models.len() as u64,
            dirty_nodes: s.dirty.len() as u64,
            last_rebuild_ms: s.published.rebuild_ms,
            bounds,
        })
    }

    // ---------------------------------------------------------------------------------------
    // Blobs
    // ---------------------------------------------------------------------------------------

    /// The blob named `hash`, if stored.
    pub fn blob(&self, hash: &str) -> Result<Option<Vec<u8>>, WorldError> {
        self.blobs.get(hash)
    }

    /// The metadata store.
    pub fn meta(&self) -> &dyn MetaStore {
        self.meta.as_ref()
    }

    /// The blob store.
    pub fn blobs(&self) -> &dyn BlobStore {
        self.blobs.as_ref()
    }

    // ---------------------------------------------------------------------------------------
    // Locks
    // ---------------------------------------------------------------------------------------

    fn lock_writer(&self) -> Result<MutexGuard<'_, ()>, WorldError> {
        self.writer
            .lock()
            .map_err(|_| WorldError::Inconsistent("writer lock poisoned".into()))
    }

    fn lock_status(&self) -> Result<MutexGuard<'_, Status>, WorldError> {
        self.status
            .lock()
            .map_err(|_| WorldError::Inconsistent("status lock poisoned".into()))
    }

    fn read_tree(&self) -> Result<std::sync::RwLockReadGuard<'_, Option<Tree>>, WorldError> {
        self.tree
            .read()
            .map_err(|_| WorldError::Inconsistent("tree lock poisoned".into()))
    }

    fn write_tree(&self) -> Result<std::sync::RwLockWriteGuard<'_, Option<Tree>>, WorldError> {
        self.tree
            .write()
            .map_err(|_| WorldError::Inconsistent("tree lock poisoned".into()))
    }
}

/// The bulk build's input of `rows`: (world id, model number, transform).
fn bulk_input(rows: &[ObjectRow]) -> Vec<(u64, u64, Affine3A)> {
    rows.iter().map(|o| (o.id, o.model, o.transform)).collect()
}
