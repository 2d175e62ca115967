//! The offline rebuild on a small world whose right answers are obvious: a grid of boxes
//! (two byte-different uploads of the same textured box) and spikes.

use std::collections::{BTreeSet, HashMap, HashSet};
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::{Affine3A, Vec2, Vec3, Vec4};
#[cfg(feature = "baseline")]
use horizon_aggregate::build_subtrees;
use horizon_aggregate::{
    build_aggregates, AggregateEntry, AggregateError, AggregateManifest, AggregateOptions,
    AggregateStore, BuildOptions, ImpostorPolicy, InMemoryModels, MemoryStore, NodeStats, PartList,
    SourceModel,
};
use horizon_bvh::{Bvh, BvhOptions, NewObject, NodeId, Sphere};
use horizon_descriptors::{describe, DescriptorOptions};
use horizon_mesh::{
    import_bytes, Format, ImportOptions, Instance, InstancedMesh, Material, Submesh, Texture,
    TextureRef, Wrap,
};

/// A unit box with UVs and a 4x4 checker texture.
fn textured_box() -> InstancedMesh {
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    let mut indices = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let n = Vec3::from_array({
                let mut a = [0.0; 3];
                a[axis] = sign;
                a
            });
            let u = Vec3::from_array({
                let mut a = [0.0; 3];
                a[(axis + 1) % 3] = 1.0;
                a
            });
            let v = n.cross(u);
            let base = positions.len() as u32;
            for (du, dv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                positions.push((n + u * du + v * dv) * 0.5);
                uvs.push(Vec2::new((du + 1.0) * 0.5, (dv + 1.0) * 0.5));
            }
            indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
    }
    let mut img = image::RgbaImage::new(4, 4);
    for (x, y, p) in img.enumerate_pixels_mut() {
        *p = if (x + y) % 2 == 0 {
            image::Rgba([200, 40, 40, 255])
        } else {
            image::Rgba([240, 240, 240, 255])
        };
    }
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .expect("encode png");
    InstancedMesh {
        submeshes: vec![Submesh {
            positions,
            uvs: Some(uvs),
            indices,
            material: Some(0),
            ..Submesh::default()
        }],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        materials: vec![Material {
            base_color_texture: Some(TextureRef {
                texture: 0,
                transform: None,
            }),
            ..Material::default()
        }],
        textures: vec![Texture {
            bytes: png,
            mime_type: "image/png".into(),
            size: (4, 4),
            wrap_u: Wrap::Repeat,
            wrap_v: Wrap::Repeat,
        }],
    }
}

/// A tall blue four-sided spike: clearly not a box.
fn spike() -> InstancedMesh {
    let positions = vec![
        Vec3::new(-0.3, 0.0, -0.3),
        Vec3::new(0.3, 0.0, -0.3),
        Vec3::new(0.3, 0.0, 0.3),
        Vec3::new(-0.3, 0.0, 0.3),
        Vec3::new(0.0, 3.0, 0.0),
    ];
    let indices = vec![0, 1, 2, 0, 2, 3, 0, 4, 1, 1, 4, 2, 2, 4, 3, 3, 4, 0];
    InstancedMesh {
        submeshes: vec![Submesh {
            positions,
            indices,
            material: Some(0),
            ..Submesh::default()
        }],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        materials: vec![Material {
            base_color_factor: Vec4::new(0.1, 0.2, 0.9, 1.0),
            ..Material::default()
        }],
        textures: Vec::new(),
    }
}

struct World {
    models: InMemoryModels,
    /// Per model: its shape and texture descriptors, lent to the tree's new objects.
    descriptors: Vec<(Vec<f32>, Vec<f32>)>,
    /// Per object: model number and transform.
    objects: Vec<(u64, Affine3A)>,
    radii: Vec<f32>,
}

/// Models 0 and 1 are the same box (two uploads), model 2 a spike; 48 objects on a grid.
fn world() -> World {
    let options = DescriptorOptions::default();
    let meshes = [textured_box(), textured_box(), spike()];
    let models: Vec<SourceModel> = meshes
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let d = describe(m, &options).expect("describe").descriptors;
            SourceModel::new(format!("model{i}"), m.clone(), d.zernike, d.csd)
        })
        .collect();
    let radii = meshes
        .iter()
        .map(|m| {
            let b = m.bounds();
            (b.max - b.min).length() * 0.5
        })
        .collect();
    let mut objects = Vec::new();
    for k in 0..48u32 {
        let model = u64::from(k % 3);
        let t =
            Affine3A::from_translation(Vec3::new((k % 8) as f32 * 3.0, 0.0, (k / 8) as f32 * 3.0));
        objects.push((model, t));
    }
    let descriptors = models
        .iter()
        .map(|m| (m.shape.clone(), m.texture.clone()))
        .collect();
    World {
        models: InMemoryModels::new(models),
        descriptors,
        objects,
        radii,
    }
}

fn new_object<'a>(w: &'a World, model: u64, t: Affine3A) -> NewObject<'a> {
    let m = horizon_aggregate::ModelSource::model(&w.models, model).expect("model");
    let b = m.mesh.bounds();
    // The BVH copies the descriptors it is lent.
    let (shape, texture) = &w.descriptors[model as usize];
    NewObject {
        model,
        transform: t,
        sphere: Sphere::new(
            t.transform_point3((b.min + b.max) * 0.5),
            w.radii[model as usize],
        ),
        shape,
        texture,
    }
}

fn tree(w: &World) -> Bvh {
    tree_with(w, BvhOptions::with_branching(4))
}

fn tree_with(w: &World, options: BvhOptions) -> Bvh {
    let objects: Vec<NewObject> = w
        .objects
        .iter()
        .map(|&(m, t)| new_object(w, m, t))
        .collect();
    let bvh = Bvh::bulk_build(options, &objects).expect("bulk build");
    bvh.validate().expect("valid tree");
    bvh
}

fn options(w: &World) -> BuildOptions {
    BuildOptions {
        aggregate: AggregateOptions::default(),
        world_textures: w.models.texture_totals(),
        impostors: ImpostorPolicy::Everywhere,
    }
}

/// The bytes of a stored aggregate.
fn glb(store: &MemoryStore, e: &AggregateEntry) -> Vec<u8> {
    store.blob(&e.glb).expect("the aggregate is stored")
}

/// A store that fails, as a crashed disk would, once it has taken `limit` aggregates.
struct FailingStore {
    inner: MemoryStore,
    limit: AtomicUsize,
    staged: AtomicUsize,
}

impl AggregateStore for FailingStore {
    fn known(&self) -> Result<HashMap<String, AggregateEntry>, AggregateError> {
        self.inner.known()
    }
    fn manifest(&self) -> Result<Option<AggregateManifest>, AggregateError> {
        self.inner.manifest()
    }
    fn stage(
        &self,
        key: String,
        glb: &[u8],
        parts: Option<(&[u8], PartList)>,
        stats: NodeStats,
    ) -> Result<AggregateEntry, AggregateError> {
        if self.staged.fetch_add(1, Ordering::SeqCst) >= self.limit.load(Ordering::SeqCst) {
            return Err(AggregateError::io(
                "aggregates",
                std::io::Error::other("the disk went away"),
            ));
        }
        self.inner.stage(key, glb, parts, stats)
    }
    fn stage_blob(&self, bytes: &[u8]) -> Result<String, AggregateError> {
        self.inner.stage_blob(bytes)
    }
    fn commit(&self) -> Result<(), AggregateError> {
        self.inner.commit()
    }
    fn parts(&self, hash: &str) -> Result<Vec<u8>, AggregateError> {
        self.inner.parts(hash)
    }
    fn write_manifest(&self, manifest: &AggregateManifest) -> Result<(), AggregateError> {
        self.inner.write_manifest(manifest)
    }
}

#[test]
fn every_node_gets_one_valid_single_texture_aggregate_and_the_build_is_deterministic() {
    let w = world();
    let bvh = tree(&w);
    let (sa, sb) = (MemoryStore::new(), MemoryStore::new());
    let ra = build_aggregates(&bvh, &w.models, &sa, &options(&w), &|_| {})
        .expect("build a")
        .report;
    let rb = build_aggregates(&bvh, &w.models, &sb, &options(&w), &|_| {}).expect("build b");
    assert!(ra.failed.is_empty(), "{:?}", ra.failed);
    assert_eq!(ra.nodes, bvh.node_count());
    assert_eq!(ra.built, ra.nodes);
    let ma = sa.manifest().expect("read").expect("manifest");
    let mb = sb.manifest().expect("read").expect("manifest");
    assert_eq!(ma.nodes.len(), bvh.node_count());
    for (node, e) in &ma.nodes {
        assert_eq!(
            mb.nodes[node].glb, e.glb,
            "node {node} differs between two builds"
        );
        let bytes = glb(&sa, e);
        let mesh = import_bytes(&bytes, Format::Glb, None, &ImportOptions::default())
            .expect("aggregate imports")
            .mesh;
        mesh.validate().expect("valid");
        assert_eq!(mesh.materials.len(), 1, "node {node}");
        assert_eq!(mesh.textures.len(), 1, "node {node}");
        assert!(mesh.textures[0].bytes.len() <= 128 * 1024);
        assert!(mesh.expanded_triangle_count() > 0);
    }
    assert_eq!(rb.report.built, ra.built);
}

#[test]
fn exact_duplicates_merge_and_different_models_do_not() {
    let w = world();
    let bvh = tree(&w);
    let store = MemoryStore::new();
    build_aggregates(&bvh, &w.models, &store, &options(&w), &|_| {}).expect("build");
    let m = store.manifest().expect("read").expect("manifest");
    // The root holds all three models: the second box upload is replaced, the spike is not.
    let root = &m.nodes[&bvh.root().0];
    assert_eq!(root.stats.models, 3);
    assert_eq!(root.stats.replaced, 1, "{:?}", root.stats);
    // No aggregate ever replaces more than the duplicate box.
    for (node, e) in &m.nodes {
        assert!(e.stats.replaced <= 1, "node {node}: {:?}", e.stats);
    }
}

#[test]
fn a_crash_mid_build_keeps_the_old_manifest_and_the_next_build_completes() {
    let w = world();
    let mut bvh = tree(&w);
    let store = FailingStore {
        inner: MemoryStore::new(),
        limit: AtomicUsize::new(usize::MAX),
        staged: AtomicUsize::new(0),
    };
    build_aggregates(&bvh, &w.models, &store, &options(&w), &|_| {}).expect("first build");
    let before = store.manifest().expect("read").expect("manifest");

    // Change the world, then crash after two aggregates.
    for k in 0..6u32 {
        let t = Affine3A::from_translation(Vec3::new(100.0 + k as f32 * 3.0, 0.0, 0.0));
        bvh.insert(&new_object(&w, 2, t)).expect("insert");
    }
    store
        .limit
        .store(store.staged.load(Ordering::SeqCst) + 2, Ordering::SeqCst);
    let err = build_aggregates(&bvh, &w.models, &store, &options(&w), &|_| {}).expect_err("crash");
    assert!(matches!(err, AggregateError::Io { .. }), "{err}");
    // The previous manifest is intact and every blob it names is stored.
    let after = store.manifest().expect("read").expect("manifest");
    assert_eq!(after.root_key, before.root_key);
    for e in after.nodes.values() {
        assert!(store.inner.blob(&e.glb).is_some());
    }
    store.limit.store(usize::MAX, Ordering::SeqCst);
    // The next build completes, reusing what the crashed one finished.
    let report = build_aggregates(&bvh, &w.models, &store, &options(&w), &|_| {})
        .expect("resume")
        .report;
    assert!(report.failed.is_empty());
    assert_eq!(report.built + report.reused, bvh.node_count());
    let done = store.manifest().expect("read").expect("manifest");
    assert_eq!(done.nodes.len(), bvh.node_count());
    assert_ne!(done.root_key, before.root_key);
}

#[test]
fn adding_objects_rebuilds_only_their_ancestors() {
    let w = world();
    let mut bvh = tree(&w);
    let store = MemoryStore::new();
    build_aggregates(&bvh, &w.models, &store, &options(&w), &|_| {}).expect("first build");
    let before: BTreeSet<String> = store
        .manifest()
        .expect("read")
        .expect("manifest")
        .nodes
        .values()
        .map(|e| e.key.clone())
        .collect();
    let t = Affine3A::from_translation(Vec3::new(1.5, 0.0, 1.5));
    let id = bvh.insert(&new_object(&w, 0, t)).expect("insert");
    // The ancestors of the new object.
    let mut ancestors = BTreeSet::new();
    let mut at = bvh.object(id).map(|o| o.leaf());
    while let Some(n) = at {
        ancestors.insert(n.0);
        at = bvh.node(n).and_then(|r| r.parent());
    }
    let report = build_aggregates(&bvh, &w.models, &store, &options(&w), &|_| {})
        .expect("rebuild")
        .report;
    let after = store.manifest().expect("read").expect("manifest");
    let rebuilt: BTreeSet<u32> = after
        .nodes
        .iter()
        .filter(|(_, e)| !before.contains(&e.key))
        .map(|(&n, _)| n)
        .collect();
    assert_eq!(report.built, rebuilt.len());
    // Every ancestor is rebuilt. Beyond them, only the other halves of splits on the way up:
    // at most two changed nodes per level.
    assert!(
        ancestors.is_subset(&rebuilt),
        "{ancestors:?} vs {rebuilt:?}"
    );
    let bound = 2 * (bvh.height() as usize + 1);
    assert!(
        rebuilt.len() <= bound,
        "{} > {bound}: {rebuilt:?}",
        rebuilt.len()
    );
    assert!(report.built < bvh.node_count());
}

/// The unoptimised baseline streams its handoffs through parts files instead of holding a
/// level of world-space meshes: every internal node's merge is exactly the triangles its
/// children's aggregates kept (nothing lost in the round trip), each aggregate keeps its
/// materials and textures from the source models, and the build is deterministic.
#[cfg(feature = "baseline")]
#[test]
fn the_baseline_reads_its_children_back_from_parts_files() {
    let w = world();
    let bvh = tree(&w);
    let mut opts = options(&w);
    opts.aggregate = opts.aggregate.unoptimized();
    let (sa, sb) = (MemoryStore::new(), MemoryStore::new());
    let ra = build_aggregates(&bvh, &w.models, &sa, &opts, &|_| {})
        .expect("build a")
        .report;
    build_aggregates(&bvh, &w.models, &sb, &opts, &|_| {}).expect("build b");
    assert!(ra.failed.is_empty(), "{:?}", ra.failed);
    assert_eq!(ra.built, bvh.node_count());
    let ma = sa.manifest().expect("read").expect("manifest");
    let mb = sb.manifest().expect("read").expect("manifest");
    let mut internal = 0;
    for (&node, e) in &ma.nodes {
        assert_eq!(
            mb.nodes[&node].glb, e.glb,
            "node {node} differs between builds"
        );
        assert!(e.parts.is_some(), "node {node} has no parts file");
        let n = bvh.node(NodeId(node)).expect("node");
        let bytes = glb(&sa, e);
        let mesh = import_bytes(&bytes, Format::Glb, None, &ImportOptions::default())
            .expect("aggregate imports")
            .mesh;
        mesh.validate().expect("valid");
        // The boxes (models 0 and 1) are textured, the spike is not.
        let mut under = Vec::new();
        bvh.objects_under(NodeId(node), &mut under);
        let boxes = under
            .iter()
            .any(|&o| bvh.object(o).expect("object").model() < 2);
        assert_eq!(!mesh.textures.is_empty(), boxes, "node {node}: textures");
        if n.is_leaf() {
            continue;
        }
        internal += 1;
        let kept: u64 = n
            .child_nodes()
            .map(|c| ma.nodes[&c.0].stats.triangles_out)
            .sum();
        assert_eq!(e.stats.triangles_in, kept, "node {node}");
    }
    assert!(internal >= 2, "the tree has internal nodes below the root");
}

/// A build restricted to some nodes builds exactly them and everything below them, with the
/// same aggregates as the whole build, and its manifest is never taken for a whole build.
#[cfg(feature = "baseline")]
#[test]
fn a_partial_build_builds_the_named_subtrees_only() {
    let w = world();
    let bvh = tree(&w);
    let (sa, sb) = (MemoryStore::new(), MemoryStore::new());
    build_aggregates(&bvh, &w.models, &sa, &options(&w), &|_| {}).expect("whole build");
    let whole = sa.manifest().expect("read").expect("manifest");
    let root = bvh.node(bvh.root()).expect("root");
    let pick = root.child_nodes().next().expect("a child of the root");
    let mut below = Vec::new();
    let mut stack = vec![pick];
    while let Some(n) = stack.pop() {
        below.push(n.0);
        stack.extend(bvh.node(n).expect("node").child_nodes());
    }
    let roots = [pick.0].into_iter().collect();
    let report = build_subtrees(&bvh, &w.models, &sb, &options(&w), &roots, &|_| {})
        .expect("partial")
        .report;
    assert_eq!(report.built, below.len());
    let part = sb.manifest().expect("read").expect("manifest");
    let mut held: Vec<u32> = part.nodes.keys().copied().collect();
    held.sort_unstable();
    below.sort_unstable();
    assert_eq!(held, below);
    for n in &below {
        assert_eq!(part.nodes[n].glb, whole.nodes[n].glb, "node {n}");
    }
    assert_ne!(part.root_key, whole.root_key);
}

/// What a node hands its parent in memory and what the parent reads back from the parts file
/// are the same thing: a root built in the same run as its children is byte-identical to one
/// built later over children reused from the store. Each part keeps its own source material
/// either way (in a leaf holding a box, the spike stays blue).
#[test]
fn a_parent_built_over_reused_children_equals_one_built_with_them() {
    let w = world();
    // A spatial tree (mu 0), so that leaves mix boxes and spikes.
    let bvh = tree_with(
        &w,
        BvhOptions {
            mu: 0.0,
            ..BvhOptions::with_branching(4)
        },
    );
    let (sa, sb) = (MemoryStore::new(), MemoryStore::new());
    build_aggregates(&bvh, &w.models, &sa, &options(&w), &|_| {}).expect("whole build");
    let whole = sa.manifest().expect("read").expect("manifest");
    // Store b holds every aggregate but the root's, then builds the whole tree over them.
    assert!(bvh.node(bvh.root()).expect("root").child_nodes().count() >= 2);
    for (&node, e) in &whole.nodes {
        if node == bvh.root().0 {
            continue;
        }
        let parts = e.parts.as_ref().map(|p| {
            let bytes = sa.blob(p).expect("parts stored");
            (bytes, e.part_keys.clone())
        });
        sb.stage(
            e.key.clone(),
            &glb(&sa, e),
            parts.as_ref().map(|(b, k)| (b.as_slice(), k.clone())),
            e.stats.clone(),
        )
        .expect("stage");
    }
    sb.commit().expect("commit");
    let report = build_aggregates(&bvh, &w.models, &sb, &options(&w), &|_| {})
        .expect("root")
        .report;
    assert_eq!(report.built, 1, "only the root is left to build");
    let again = sb.manifest().expect("read").expect("manifest");
    assert_eq!(again.nodes.len(), whole.nodes.len());
    for (node, e) in &whole.nodes {
        assert_eq!(again.nodes[node].glb, e.glb, "node {node}");
    }
}

/// A part that no child handed over although its model's other parts came through (every
/// child that drew the model culled it, or drew the model as a look-alike, or failed) comes
/// from the source model when it is big enough to show here.
#[test]
fn a_part_missing_from_the_children_comes_from_its_source_model() {
    use horizon_aggregate::budget::Display;
    use horizon_aggregate::{generate, Handoff, NodeInput, Placement};
    use horizon_descriptors::calibrate::Table1;
    use std::collections::BTreeMap;
    use std::sync::Arc;

    // One model of two parts: a box (12 triangles) and a spike (6).
    let (boxed, spike) = (textured_box(), spike());
    let mut mesh = boxed.clone();
    let mut tip = spike.submeshes[0].clone();
    tip.material = Some(1);
    mesh.submeshes.push(tip);
    mesh.materials.push(spike.materials[0].clone());
    mesh.instances.push(horizon_mesh::Instance {
        submesh: 1,
        transform: Affine3A::from_translation(Vec3::new(0.0, 0.5, 0.0)),
    });
    mesh.validate().expect("valid model");
    let d = describe(&mesh, &DescriptorOptions::default())
        .expect("describe")
        .descriptors;
    let models = InMemoryModels::new(vec![SourceModel::new(
        "two-part".into(),
        mesh.clone(),
        d.zernike,
        d.csd,
    )]);
    // Two placements close enough that both parts cover many pixels.
    let placements: Vec<Placement> = [0.0f32, 3.0]
        .iter()
        .map(|&x| Placement {
            model: 0,
            transform: Affine3A::from_translation(Vec3::new(x, 0.0, 0.0)),
            centre: Vec3::new(x, 1.0, 0.0),
            radius: 2.0,
        })
        .collect();
    let options = AggregateOptions {
        dedup: false,
        ..AggregateOptions::default()
    };
    // A child handed over the box part alone.
    let mut versions = BTreeMap::new();
    versions.insert((0u64, 0u32), Arc::new(mesh.submeshes[0].clone()));
    let mut input = NodeInput {
        node: 1,
        display: Display::of(Vec3::new(1.5, 1.0, 0.0), 3.5, 2.0, &options),
        outer_radius: 5.5,
        placements,
        children: vec![Arc::new(Handoff::Versions(versions))],
        atlas: false,
    };
    let out = generate(&mut input, &models, &Table1::calibrated(), &options).expect("generate");
    assert_eq!(
        out.stats.culled + out.stats.culled_parts,
        0,
        "{:?}",
        out.stats
    );
    // Both parts of both placements: 2 x (12 + 6) triangles.
    assert_eq!(out.stats.triangles_in, 36, "{:?}", out.stats);
}

/// The baseline reuses a whole earlier build or nothing: a manifest that lacks a node (the
/// mark a failed aggregate leaves) means its parents were built without that subtree's
/// geometry, so none of it is reused.
#[cfg(feature = "baseline")]
#[test]
fn the_baseline_rebuilds_everything_after_a_build_that_lacks_a_node() {
    let w = world();
    let bvh = tree(&w);
    let mut opts = options(&w);
    opts.aggregate = opts.aggregate.unoptimized();
    let store = MemoryStore::new();
    build_aggregates(&bvh, &w.models, &store, &opts, &|_| {}).expect("first build");
    let again = build_aggregates(&bvh, &w.models, &store, &opts, &|_| {})
        .expect("again")
        .report;
    assert_eq!(again.reused, bvh.node_count(), "a whole build is reused");
    // Drop one leaf from the manifest, as a failed build leaves it.
    let mut m = store.manifest().expect("read").expect("manifest");
    let leaf = *m
        .nodes
        .keys()
        .find(|&&n| bvh.node(NodeId(n)).expect("node").is_leaf())
        .expect("a leaf");
    m.nodes.remove(&leaf);
    store.write_manifest(&m).expect("write");
    let report = build_aggregates(&bvh, &w.models, &store, &opts, &|_| {})
        .expect("rebuild")
        .report;
    assert_eq!(report.reused, 0);
    assert_eq!(report.built, bvh.node_count());
}

/// A box of size `size` centred on the origin, every face its own UV island (seams at every
/// edge), the sides in a checker texture of `color` and the top in a second, untextured
/// material.
fn seamed_box(size: Vec3, color: [u8; 3]) -> InstancedMesh {
    let mut mesh = textured_box();
    let sub = &mut mesh.submeshes[0];
    for p in &mut sub.positions {
        *p *= size;
    }
    // The top face (+y) moves to a submesh of its own with material 1.
    let mut top = Submesh {
        material: Some(1),
        ..Submesh::default()
    };
    let mut sides = Vec::new();
    for t in sub.indices.chunks_exact(3) {
        let up = t.iter().all(|&i| sub.positions[i as usize].y > 0.0);
        if up {
            for &i in t {
                top.indices.push(top.positions.len() as u32);
                top.positions.push(sub.positions[i as usize]);
            }
        } else {
            sides.extend_from_slice(t);
        }
    }
    sub.indices = sides;
    let mut img = image::RgbaImage::new(4, 4);
    for (x, y, p) in img.enumerate_pixels_mut() {
        let [r, g, b] = color;
        *p = if (x + y) % 2 == 0 {
            image::Rgba([r, g, b, 255])
        } else {
            image::Rgba([r / 2, g / 2, b / 2, 255])
        };
    }
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .expect("encode png");
    mesh.textures[0].bytes = png;
    mesh.submeshes.push(top);
    mesh.instances.push(Instance {
        submesh: 1,
        transform: Affine3A::IDENTITY,
    });
    mesh.materials.push(Material {
        base_color_factor: Vec4::new(0.2, 0.3, 0.8, 1.0),
        ..Material::default()
    });
    mesh
}

/// Many small distinct, seam-heavy objects, far over the budget of an aggregate shown from
/// afar: nothing is dropped, and seen from above every object still covers its footprint
/// (a proxy box, not a shard or nothing), at its own height.
#[test]
fn an_aggregate_of_distinct_seamed_objects_over_its_budget_keeps_every_silhouette() {
    use horizon_aggregate::budget::Display;
    use horizon_aggregate::{generate, Handoff, NodeInput, Placement};
    use horizon_descriptors::calibrate::Table1;
    use horizon_impostor::{PreparedMesh, SceneBuilder};

    // 16 distinct models: boxes of different proportions and colours.
    let sizes: Vec<Vec3> = (0..16)
        .map(|k| Vec3::new(1.0 + 0.3 * (k % 4) as f32, 1.0 + 0.5 * (k / 4) as f32, 1.0))
        .collect();
    let sources: Vec<SourceModel> = sizes
        .iter()
        .enumerate()
        .map(|(k, &size)| {
            let mesh = seamed_box(size, [40 + 13 * k as u8, 200 - 9 * k as u8, 90]);
            let d = describe(&mesh, &DescriptorOptions::default())
                .expect("describe")
                .descriptors;
            SourceModel::new(format!("box{k}"), mesh, d.zernike, d.csd)
        })
        .collect();
    let models = InMemoryModels::new(sources);
    // 256 objects on a 16 x 16 grid, 3 m apart, each model 16 times.
    let placements: Vec<Placement> = (0..256)
        .map(|k| {
            let at = Vec3::new((k % 16) as f32 * 3.0, 0.0, (k / 16) as f32 * 3.0);
            let size = sizes[k % 16];
            Placement {
                model: (k % 16) as u64,
                transform: Affine3A::from_translation(at),
                centre: at,
                radius: size.length() * 0.5,
            }
        })
        .collect();
    let options = AggregateOptions {
        dedup: false,
        ..AggregateOptions::default()
    };
    let mut input = NodeInput {
        node: 1,
        display: Display::of(Vec3::new(22.5, 0.0, 22.5), 32.0, 24.0, &options),
        outer_radius: 34.0,
        placements: placements.clone(),
        children: Vec::new(),
        atlas: true,
    };
    let out = generate(&mut input, &models, &Table1::calibrated(), &options).expect("generate");
    let s = &out.stats;
    assert_eq!((s.culled, s.culled_parts), (0, 0), "{s:?}");
    assert!(s.triangles_in > s.budget, "{s:?}");
    // The GLB holds what the stats say.
    let back = import_bytes(&out.glb, Format::Glb, None, &ImportOptions::default())
        .expect("import")
        .mesh;
    assert_eq!(back.expanded_triangle_count(), s.triangles_out);
    // From above, rays over the inner 80% of every object's footprint meet a surface within
    // the object's height.
    let mut scene = SceneBuilder::default();
    scene.add(
        &std::sync::Arc::new(PreparedMesh::new(&back)),
        &Affine3A::IDENTITY,
    );
    let scene = scene.build();
    let mut missed = Vec::new();
    for (k, p) in placements.iter().enumerate() {
        let half = sizes[k % 16] * 0.5;
        let (mut hits, mut rays) = (0, 0);
        for i in 0..5 {
            for j in 0..5 {
                let fx = (i as f32 / 4.0 - 0.5) * 1.6;
                let fz = (j as f32 / 4.0 - 0.5) * 1.6;
                let from = p.centre + Vec3::new(fx * half.x, 50.0, fz * half.z);
                rays += 1;
                if let Some(t) = scene.cast(from, Vec3::NEG_Y) {
                    let y = 50.0 - t;
                    if y > -half.y - 0.05 && y < half.y + 0.05 {
                        hits += 1;
                    }
                }
            }
        }
        if hits * 10 < rays * 9 {
            missed.push((k, hits));
        }
    }
    assert!(
        missed.is_empty(),
        "objects that lost their footprint: {missed:?}, {s:?}"
    );
    // Proxies did it: the handoff carries the simplified parts, not the proxies.
    assert!(s.proxied_shape + s.proxied_budget > 0, "{s:?}");
    let Handoff::Versions(v) = &out.handoff else {
        panic!("optimised handoff expected")
    };
    assert!(v.values().all(|sub| sub.colors.is_none()));
}

/// Impostors in the rebuild: every node gets one (policy `Everywhere`), leaves ray-cast and
/// the rest composited; each decodes to valid orthoviews inside its node's box; a second
/// identical build makes the same bytes; a rebuild after an insertion remakes exactly the
/// impostors whose aggregate was rebuilt and reuses the others.
#[test]
fn impostors_are_built_bottom_up_inside_their_nodes_and_rebuilt_with_their_aggregates() {
    let w = world();
    let mut bvh = tree(&w);
    let (store, twin) = (MemoryStore::new(), MemoryStore::new());
    let report = build_aggregates(&bvh, &w.models, &store, &options(&w), &|_| {})
        .expect("build")
        .report;
    let twin_manifest = build_aggregates(&bvh, &w.models, &twin, &options(&w), &|_| {})
        .expect("twin")
        .manifest;
    let manifest = store.manifest().expect("read").expect("manifest");
    let imp = report.impostors.expect("an impostor report");
    assert_eq!(imp.nodes, bvh.node_count());
    assert_eq!(manifest.impostors.len(), bvh.node_count());
    let leaves = (0..bvh.node_count() as u32)
        .filter(|&n| bvh.node(NodeId(n)).is_some_and(|r| r.is_leaf()))
        .count();
    assert_eq!(
        imp.rendered, leaves,
        "leaves are rendered, the rest composited"
    );
    assert_eq!(twin_manifest.impostors, manifest.impostors, "deterministic");
    for (&n, e) in &manifest.impostors {
        let node = bvh.node(NodeId(n)).expect("node");
        let (b, nb) = (e.bounds(), node.aabb());
        assert!(
            b.min.cmpge(nb.min - 1e-3).all() && b.max.cmple(nb.max + 1e-3).all(),
            "node {n}: impostor box {b:?} outside the node's {nb:?}"
        );
        let views = e.load(&store).expect("the orthoviews decode and validate");
        assert_eq!(views.len(), horizon_impostor::WORLD_DIRECTIONS.len());
        // Something of the boxes shows from above.
        assert!(views[0].covered() > 0, "node {n} shows nothing from above");
        for v in &views {
            assert!(v.width <= imp.resolution && v.height <= imp.resolution);
        }
    }
    // An insertion: the impostors of rebuilt aggregates are remade, the others reused.
    let t = Affine3A::from_translation(Vec3::new(1.5, 0.0, 1.5));
    bvh.insert(&new_object(&w, 0, t)).expect("insert");
    let second = build_aggregates(&bvh, &w.models, &store, &options(&w), &|_| {})
        .expect("rebuild")
        .report;
    let imp2 = second.impostors.expect("an impostor report");
    assert_eq!(
        imp2.built, second.built,
        "one impostor per rebuilt aggregate"
    );
    assert_eq!(imp2.reused, bvh.node_count() - second.built);
    let after = store.manifest().expect("read").expect("manifest");
    for (n, e) in &after.impostors {
        e.load(&store)
            .unwrap_or_else(|err| panic!("node {n}: {err}"));
    }
}

/// A store whose named blobs read back as damaged bytes, as a disk gone bad would, or images an
/// older impostor format wrote and this one's validation refuses.
struct DamagedStore {
    inner: MemoryStore,
    damaged: HashSet<String>,
}

impl AggregateStore for DamagedStore {
    fn known(&self) -> Result<HashMap<String, AggregateEntry>, AggregateError> {
        self.inner.known()
    }
    fn manifest(&self) -> Result<Option<AggregateManifest>, AggregateError> {
        self.inner.manifest()
    }
    fn stage(
        &self,
        key: String,
        glb: &[u8],
        parts: Option<(&[u8], PartList)>,
        stats: NodeStats,
    ) -> Result<AggregateEntry, AggregateError> {
        self.inner.stage(key, glb, parts, stats)
    }
    fn stage_blob(&self, bytes: &[u8]) -> Result<String, AggregateError> {
        self.inner.stage_blob(bytes)
    }
    fn commit(&self) -> Result<(), AggregateError> {
        self.inner.commit()
    }
    fn parts(&self, hash: &str) -> Result<Vec<u8>, AggregateError> {
        self.inner.parts(hash)
    }
    fn blob(&self, hash: &str) -> Result<Vec<u8>, AggregateError> {
        if self.damaged.contains(hash) {
            return Ok(b"not a PNG".to_vec());
        }
        AggregateStore::blob(&self.inner, hash)
    }
    fn write_manifest(&self, manifest: &AggregateManifest) -> Result<(), AggregateError> {
        self.inner.write_manifest(manifest)
    }
}

/// A reused child's stored orthoviews that cannot be read do not stop a rebuild (the live
/// rebuild would retry it forever and publish nothing): the parent that needed them is
/// ray-cast from its objects instead, and the report names it.
#[test]
fn a_child_impostor_that_cannot_be_read_makes_its_parent_ray_cast_not_a_failed_build() {
    let w = world();
    let mut bvh = tree(&w);
    let mut store = DamagedStore {
        inner: MemoryStore::new(),
        damaged: HashSet::new(),
    };
    build_aggregates(&bvh, &w.models, &store, &options(&w), &|_| {}).expect("build");
    let before = store.manifest().expect("read").expect("manifest");
    store.damaged = before
        .impostors
        .values()
        .flat_map(|e| e.blobs().cloned())
        .collect();
    let t = Affine3A::from_translation(Vec3::new(1.5, 0.0, 1.5));
    bvh.insert(&new_object(&w, 0, t)).expect("insert");
    let report = build_aggregates(&bvh, &w.models, &store, &options(&w), &|_| {})
        .expect("a rebuild over unreadable impostors completes")
        .report;
    let imp = report.impostors.expect("an impostor report");
    assert!(
        !imp.unreadable.is_empty(),
        "a rebuilt parent of reused children needed their images"
    );
    let after = store.manifest().expect("read").expect("manifest");
    let old_keys: HashSet<&String> = before.impostors.values().map(|e| &e.key).collect();
    for (node, why) in &imp.unreadable {
        assert!(why.contains("PNG") || why.contains("decode"), "{why}");
        let e = &after.impostors[node];
        assert!(!old_keys.contains(&e.key), "node {node} was rebuilt");
        e.load(&store)
            .unwrap_or_else(|err| panic!("node {node}, ray-cast: {err}"));
    }
    // The children that could not be read are not served: their nodes fall back to their
    // aggregates, and the next build makes their impostors again.
    assert!(!imp.unreadable_children.is_empty());
    for child in &imp.unreadable_children {
        assert!(
            !after.impostors.contains_key(child),
            "node {child}'s unreadable impostor is still in the manifest"
        );
        assert!(
            after.nodes.contains_key(child),
            "node {child} keeps its aggregate"
        );
    }
    store.damaged.clear();
    let again = build_aggregates(&bvh, &w.models, &store, &options(&w), &|_| {})
        .expect("the next build")
        .report
        .impostors
        .expect("an impostor report");
    assert!(again.unreadable.is_empty());
    assert!(again.built >= imp.unreadable_children.len());
    let remade = store.manifest().expect("read").expect("manifest");
    for child in &imp.unreadable_children {
        let e = remade
            .impostors
            .get(child)
            .unwrap_or_else(|| panic!("node {child}'s impostor was made again"));
        e.load(&store)
            .unwrap_or_else(|err| panic!("node {child}, made again: {err}"));
    }
}
