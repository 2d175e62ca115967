//! glTF 2.0 import into the instanced mesh model (core paper, section 6.2).
//!
//! Follows the Khronos glTF 2.0 specification (sections 3.5 scenes and nodes, 3.7 meshes, 3.9
//! materials) and the extensions EXT_mesh_gpu_instancing, KHR_mesh_quantization,
//! KHR_texture_transform and EXT_meshopt_compression. The `gltf` crate splits the GLB container
//! and deserialises the JSON; its own validation is not used because it refuses
//! KHR_mesh_quantization and EXT_meshopt_compression, so every reference is checked here.
//!
//! A primitive becomes one submesh however many nodes (or GPU instances) place its mesh, and
//! each placement becomes one instance whose transform is the product from the scene root.

use std::borrow::Cow;
use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::rc::Rc;

use glam::{Affine3A, DMat4, DQuat, DVec3, Vec2, Vec3, Vec4};
use gltf::json::material::AlphaMode as GltfAlphaMode;
use gltf::json::mesh::{Mode, Primitive, Semantic};
use gltf::json::texture::WrappingMode;
use gltf::json::validation::Checked;
use gltf::json::Root;
use serde::Deserialize;

use super::buffers::{missing, read_floats, read_indices, AccessorValues, BinaryData};
use super::{
    compact_vertices, images, uri, ImportOptions, Imported, Limits, INSTANCES, TEXTURES, TRIANGLES,
};
use crate::error::ImportError;
use crate::model::{
    AlphaMode, Instance, InstancedMesh, Material, Submesh, Texture, TextureRef, UvTransform, Wrap,
};

/// Extensions whose absence from a reader would change what the file means; we read these.
const READ_EXTENSIONS: &[&str] = &[
    "EXT_mesh_gpu_instancing",
    "EXT_meshopt_compression",
    "KHR_mesh_quantization",
    "KHR_texture_transform",
];

/// Imports a .glb or .gltf file already in memory.
pub(crate) fn import(
    bytes: &[u8],
    base_dir: Option<&Path>,
    options: &ImportOptions,
) -> Result<Imported, ImportError> {
    let limits = &options.limits;
    let mut budget = limits.max_bytes.saturating_sub(bytes.len() as u64);
    // Stage 1: split the GLB container, or take the file as JSON.
    let (json, bin) = split_container(bytes)?;
    // Stage 2: parse the document and refuse required extensions we cannot honour.
    let doc: Root = serde_json::from_slice(&json).map_err(|e| ImportError::Json(e.to_string()))?;
    check_required_extensions(&doc)?;
    // Stage 3: load every buffer and decompress EXT_meshopt_compression views.
    let data = BinaryData::load(&doc, bin.as_deref(), base_dir, &mut budget)?;
    let reader = Reader {
        doc: &doc,
        data: &data,
        // Accessors without a buffer view cost memory without costing file bytes; allow as
        // many elements as a sixteenth of the byte limit (a VEC4 of f32 is 16 bytes).
        max_elements: limits.max_bytes / 16,
        shared: RefCell::new(shared_vertex_accessors(&doc)),
    };
    // Stage 4: flatten the scene graph into placements of meshes.
    let placements = flatten_scenes(&reader, limits)?;
    // Stage 5: materials and the textures they use.
    let (materials, textures, uv_sets) = read_materials(&reader, base_dir, &mut budget, options)?;
    // Stage 6: one submesh per used primitive, one instance per placement and primitive.
    build_instanced_mesh(&reader, &placements, materials, textures, &uv_sets, limits)
}

/// The parsed document and its binary data, read together.
struct Reader<'a> {
    doc: &'a Root,
    data: &'a BinaryData<'a>,
    max_elements: u64,
    /// Vertex accessors that several primitive attributes name (an aggregate's primitives
    /// share runs of vertices, `ExportOptions::share_vertices`): the reads still to come, and
    /// once read, the decoded values and whether all are finite. Each is decoded once and
    /// dropped after its last reader, so a file of many primitives over one big accessor
    /// costs the accessor once, not once per primitive.
    shared: RefCell<HashMap<usize, SharedAccessor>>,
}

/// A vertex accessor several primitives read: reads left, and its values once decoded.
struct SharedAccessor {
    readers_left: usize,
    decoded: Option<(Rc<AccessorValues>, bool)>,
}

impl Reader<'_> {
    fn floats(&self, accessor: usize) -> Result<AccessorValues, ImportError> {
        read_floats(self.doc, self.data, accessor, self.max_elements)
    }

    /// A vertex attribute accessor's values and whether every one is finite, decoded once
    /// however many primitives read it.
    fn vertex_floats(&self, accessor: usize) -> Result<(Rc<AccessorValues>, bool), ImportError> {
        let decode = || -> Result<(Rc<AccessorValues>, bool), ImportError> {
            let v = self.floats(accessor)?;
            let finite = v.values.iter().all(|x| x.is_finite());
            Ok((Rc::new(v), finite))
        };
        let mut shared = self.shared.borrow_mut();
        let Some(entry) = shared.get_mut(&accessor) else {
            return decode();
        };
        let out = match &entry.decoded {
            Some((v, finite)) => (v.clone(), *finite),
            None => {
                let d = decode()?;
                entry.decoded = Some(d.clone());
                d
            }
        };
        entry.readers_left = entry.readers_left.saturating_sub(1);
        if entry.readers_left == 0 {
            shared.remove(&accessor);
        }
        Ok(out)
    }
}

/// Every accessor that more than one primitive attribute names, with how many do.
fn shared_vertex_accessors(doc: &Root) -> HashMap<usize, SharedAccessor> {
    let mut readers: HashMap<usize, usize> = HashMap::new();
    for mesh in &doc.meshes {
        for prim in &mesh.primitives {
            for a in prim.attributes.values() {
                *readers.entry(a.value()).or_default() += 1;
            }
        }
    }
    readers
        .into_iter()
        .filter(|&(_, n)| n > 1)
        .map(|(a, n)| {
            let entry = SharedAccessor {
                readers_left: n,
                decoded: None,
            };
            (a, entry)
        })
        .collect()
}

/// One mesh placed in the world.
struct Placement {
    mesh: usize,
    transform: Affine3A,
}

/// The JSON chunk and the optional binary chunk of a file.
type Chunks<'a> = (Cow<'a, [u8]>, Option<Cow<'a, [u8]>>);

fn split_container(bytes: &[u8]) -> Result<Chunks<'_>, ImportError> {
    if !bytes.starts_with(b"glTF") {
        let text = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
        let first = text.iter().find(|b| !b.is_ascii_whitespace());
        return match first {
            Some(b'{') => Ok((Cow::Borrowed(text), None)),
            Some(_) => Err(ImportError::BadMagic(
                "neither the GLB magic 'glTF' nor a JSON object".into(),
            )),
            None => Err(ImportError::Truncated("the file is empty".into())),
        };
    }
    // The gltf crate trusts the header's length field, so check the header first.
    if bytes.len() < 12 {
        return Err(ImportError::Truncated(format!(
            "a GLB header is 12 bytes, the file has {}",
            bytes.len()
        )));
    }
    let word =
        |at: usize| u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
    let (version, length) = (word(4), word(8) as usize);
    if version != 2 {
        return Err(ImportError::Unsupported(format!("GLB version {version}")));
    }
    if length < 20 || length > bytes.len() {
        return Err(ImportError::Truncated(format!(
            "the GLB header declares {length} bytes and the file has {}",
            bytes.len()
        )));
    }
    let glb = gltf::Glb::from_slice(&bytes[..length]).map_err(|e| match e {
        gltf::Error::Binary(
            gltf::binary::Error::Length { .. }
            | gltf::binary::Error::ChunkLength { .. }
            | gltf::binary::Error::Io(_),
        ) => ImportError::Truncated(format!("GLB: {e}")),
        other => ImportError::BadMagic(format!("GLB: {other}")),
    })?;
    Ok((glb.json, glb.bin))
}

fn check_required_extensions(doc: &Root) -> Result<(), ImportError> {
    for ext in &doc.extensions_required {
        // Material extensions only refine shading; the base colour we keep stays meaningful.
        if !READ_EXTENSIONS.contains(&ext.as_str()) && !ext.starts_with("KHR_materials_") {
            return Err(ImportError::Unsupported(format!(
                "required extension {ext}"
            )));
        }
    }
    Ok(())
}

/// A step of the iterative depth-first walk; `Leave` clears the on-path mark.
enum Step {
    Enter(usize, DMat4),
    Leave(usize),
}

/// Walks the default scene (or every scene when none is set, or the parentless nodes when there
/// are no scenes) and returns each mesh placement with its world transform.
fn flatten_scenes(r: &Reader<'_>, limits: &Limits) -> Result<Vec<Placement>, ImportError> {
    let doc = r.doc;
    let roots = scene_roots(doc)?;
    // A node may have several parents (a DAG), so paths can multiply: refuse a graph whose
    // paths exceed the limits before walking it.
    let max_visits = limits
        .max_instances
        .saturating_mul(4)
        .saturating_add(doc.nodes.len() as u64);
    if let Some(paths) = count_paths(doc, &roots)? {
        let visits = paths.iter().fold(0u64, |a, &p| a.saturating_add(p));
        Limits::check("node visits while flattening the scene", visits, max_visits)?;
        let placed = doc
            .nodes
            .iter()
            .zip(&paths)
            .filter(|(node, _)| node.mesh.is_some())
            .fold(0u64, |a, (_, &p)| a.saturating_add(p));
        Limits::check(INSTANCES, placed, limits.max_instances)?;
    }
    let mut on_path = vec![false; doc.nodes.len()];
    let mut stack: Vec<Step> = roots
        .iter()
        .rev()
        .map(|&n| Step::Enter(n, DMat4::IDENTITY))
        .collect();
    let mut placements = Vec::new();
    let mut visits = 0u64;
    while let Some(step) = stack.pop() {
        let (n, parent) = match step {
            Step::Leave(n) => {
                on_path[n] = false;
                continue;
            }
            Step::Enter(n, parent) => (n, parent),
        };
        let node = doc
            .nodes
            .get(n)
            .ok_or_else(|| missing("scene graph", "node", n))?;
        if on_path[n] {
            return Err(ImportError::NodeCycle { node: n });
        }
        visits += 1;
        Limits::check("node visits while flattening the scene", visits, max_visits)?;
        let world = parent * local_matrix(node, n)?;
        if let Some(mesh) = node.mesh {
            let mesh = mesh.value();
            if mesh >= doc.meshes.len() {
                return Err(missing(&format!("node {n}"), "mesh", mesh));
            }
            for t in gpu_instances(r, node, n)? {
                let transform = to_affine(world * t, || format!("node {n} world transform"))?;
                placements.push(Placement { mesh, transform });
            }
            Limits::check(INSTANCES, placements.len() as u64, limits.max_instances)?;
        }
        on_path[n] = true;
        stack.push(Step::Leave(n));
        for child in node.children.iter().flatten().rev() {
            stack.push(Step::Enter(child.value(), world));
        }
    }
    Ok(placements)
}

/// How many paths from the roots reach each node (Kahn's topological order, saturating), or
/// `None` when the reachable graph has a cycle, which the walk then reports precisely.
fn count_paths(doc: &Root, roots: &[usize]) -> Result<Option<Vec<u64>>, ImportError> {
    let n = doc.nodes.len();
    let children = |i: usize| doc.nodes[i].children.iter().flatten().map(|c| c.value());
    // Stage 1: the reachable nodes and their in-degrees within that set.
    let mut reachable = vec![false; n];
    let mut stack = Vec::new();
    for &r in roots {
        if r >= n {
            return Err(missing("scene", "node", r));
        }
        stack.push(r);
    }
    while let Some(i) = stack.pop() {
        if std::mem::replace(&mut reachable[i], true) {
            continue;
        }
        for c in children(i) {
            if c >= n {
                return Err(missing(&format!("node {i}"), "child node", c));
            }
            stack.push(c);
        }
    }
    let mut indegree = vec![0usize; n];
    for i in (0..n).filter(|&i| reachable[i]) {
        for c in children(i) {
            indegree[c] += 1;
        }
    }
    // Stage 2: propagate path counts in topological order.
    let mut paths = vec![0u64; n];
    for &r in roots {
        paths[r] += 1;
    }
    let mut ready: Vec<usize> = (0..n)
        .filter(|&i| reachable[i] && indegree[i] == 0)
        .collect();
    let mut done = 0;
    while let Some(i) = ready.pop() {
        done += 1;
        for c in children(i) {
            paths[c] = paths[c].saturating_add(paths[i]);
            indegree[c] -= 1;
            if indegree[c] == 0 {
                ready.push(c);
            }
        }
    }
    let reachable_count = reachable.iter().filter(|&&r| r).count();
    Ok((done == reachable_count).then_some(paths))
}

fn scene_roots(doc: &Root) -> Result<Vec<usize>, ImportError> {
    let scene_nodes = |s: usize| -> Result<Vec<usize>, ImportError> {
        let scene = doc
            .scenes
            .get(s)
            .ok_or_else(|| missing("the document", "scene", s))?;
        Ok(scene.nodes.iter().map(|i| i.value()).collect())
    };
    if let Some(s) = doc.scene {
        return scene_nodes(s.value());
    }
    if !doc.scenes.is_empty() {
        let mut roots = Vec::new();
        for s in 0..doc.scenes.len() {
            roots.extend(scene_nodes(s)?);
        }
        return Ok(roots);
    }
    // No scene at all: show every node that is nobody's child.
    let mut is_child = vec![false; doc.nodes.len()];
    for node in &doc.nodes {
        for c in node.children.iter().flatten() {
            if let Some(flag) = is_child.get_mut(c.value()) {
                *flag = true;
            }
        }
    }
    Ok((0..doc.nodes.len()).filter(|&n| !is_child[n]).collect())
}

/// A node's local transform: its matrix, or T * R * S.
fn local_matrix(node: &gltf::json::Node, n: usize) -> Result<DMat4, ImportError> {
    let m = match node.matrix {
        Some(cols) => DMat4::from_cols_array(&cols.map(f64::from)),
        None => {
            let t = node.translation.unwrap_or([0.0; 3]).map(f64::from);
            let r = node.rotation.map_or([0.0, 0.0, 0.0, 1.0], |q| q.0);
            let s = node.scale.unwrap_or([1.0; 3]).map(f64::from);
            let q = unit_quaternion(r, || format!("node {n} rotation"))?;
            DMat4::from_scale_rotation_translation(DVec3::from(s), q, DVec3::from(t))
        }
    };
    if !m.is_finite() {
        return Err(ImportError::NonFinite(format!("node {n} transform")));
    }
    Ok(m)
}

fn unit_quaternion(q: [f32; 4], what: impl Fn() -> String) -> Result<DQuat, ImportError> {
    let q = DQuat::from_array(q.map(f64::from));
    if !q.is_finite() {
        return Err(ImportError::NonFinite(what()));
    }
    let len = q.length();
    // Writers round unit quaternions; a length far from one is a broken file, not rounding.
    if len.partial_cmp(&1e-6) != Some(std::cmp::Ordering::Greater) {
        return Err(ImportError::Json(format!("{} has zero length", what())));
    }
    Ok(q / len)
}

fn to_affine(m: DMat4, what: impl Fn() -> String) -> Result<Affine3A, ImportError> {
    let a = Affine3A::from_mat4(m.as_mat4());
    if !a.is_finite() {
        return Err(ImportError::NonFinite(what()));
    }
    Ok(a)
}

/// The EXT_mesh_gpu_instancing object on a node.
#[derive(Deserialize)]
struct GpuInstancing {
    attributes: BTreeMap<String, usize>,
}

/// The per-instance local transforms of a node: one identity without EXT_mesh_gpu_instancing,
/// else one T * R * S per instance.
fn gpu_instances(
    r: &Reader<'_>,
    node: &gltf::json::Node,
    n: usize,
) -> Result<Vec<DMat4>, ImportError> {
    let Some(ext) = node
        .extensions
        .as_ref()
        .and_then(|e| e.others.get("EXT_mesh_gpu_instancing"))
    else {
        return Ok(vec![DMat4::IDENTITY]);
    };
    let what = |attr: &str| format!("node {n} EXT_mesh_gpu_instancing {attr}");
    let ext: GpuInstancing = serde_json::from_value(ext.clone())
        .map_err(|e| ImportError::Json(format!("{}: {e}", what("object"))))?;
    let read = |name: &str, components: usize| -> Result<Option<Vec<f32>>, ImportError> {
        let Some(&a) = ext.attributes.get(name) else {
            return Ok(None);
        };
        let v = r.floats(a)?;
        if v.components != components {
            return Err(ImportError::Json(format!(
                "{} must have {components} components",
                what(name)
            )));
        }
        if v.values.iter().any(|x| !x.is_finite()) {
            return Err(ImportError::NonFinite(what(name)));
        }
        Ok(Some(v.values))
    };
    let t = read("TRANSLATION", 3)?;
    let q = read("ROTATION", 4)?;
    let s = read("SCALE", 3)?;
    let counts: Vec<usize> = [(&t, 3), (&q, 4), (&s, 3)]
        .iter()
        .filter_map(|(v, c)| v.as_ref().map(|v| v.len() / c))
        .collect();
    let Some(&count) = counts.first() else {
        return Err(ImportError::Json(format!(
            "{} has none of TRANSLATION, ROTATION, SCALE",
            what("attributes")
        )));
    };
    if counts.iter().any(|&c| c != count) {
        return Err(ImportError::Json(format!(
            "{} have different counts",
            what("attributes")
        )));
    }
    (0..count)
        .map(|k| {
            let tk = t.as_ref().map_or(DVec3::ZERO, |v| vec3_at(v, k).as_dvec3());
            let sk = s.as_ref().map_or(DVec3::ONE, |v| vec3_at(v, k).as_dvec3());
            let qk = match &q {
                Some(v) => {
                    unit_quaternion([v[4 * k], v[4 * k + 1], v[4 * k + 2], v[4 * k + 3]], || {
                        format!("{} {k}", what("ROTATION"))
                    })?
                }
                None => DQuat::IDENTITY,
            };
            Ok(DMat4::from_scale_rotation_translation(sk, qk, tk))
        })
        .collect()
}

fn vec3_at(v: &[f32], k: usize) -> Vec3 {
    Vec3::new(v[3 * k], v[3 * k + 1], v[3 * k + 2])
}

/// KHR_texture_transform on a texture reference.
#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct TextureTransformExt {
    #[serde(default)]
    offset: Option<[f32; 2]>,
    #[serde(default)]
    rotation: Option<f32>,
    #[serde(default)]
    scale: Option<[f32; 2]>,
    #[serde(default)]
    tex_coord: Option<u32>,
}

/// Materials, the textures they use, and the UV set each material's base colour texture samples.
type MaterialTables = (Vec<Material>, Vec<Texture>, Vec<u32>);

/// Reads the materials and the textures they use (each glTF texture once).
fn read_materials(
    r: &Reader<'_>,
    base_dir: Option<&Path>,
    budget: &mut u64,
    options: &ImportOptions,
) -> Result<MaterialTables, ImportError> {
    let doc = r.doc;
    let mut textures = Vec::new();
    let mut texture_slot: HashMap<usize, usize> = HashMap::new();
    let mut pixel_budget = options.limits.max_texture_pixels;
    let mut materials = Vec::with_capacity(doc.materials.len());
    let mut uv_sets = Vec::with_capacity(doc.materials.len());
    for (mi, m) in doc.materials.iter().enumerate() {
        let pbr = &m.pbr_metallic_roughness;
        let mut uv_set = 0;
        let base_color_texture = match &pbr.base_color_texture {
            None => None,
            Some(info) => {
                let t = info.index.value();
                let slot = match texture_slot.get(&t) {
                    Some(&slot) => slot,
                    None => {
                        let texture =
                            read_texture(r, t, base_dir, budget, options, &mut pixel_budget)?;
                        Limits::check(
                            TEXTURES,
                            textures.len() as u64 + 1,
                            options.limits.max_textures,
                        )?;
                        textures.push(texture);
                        texture_slot.insert(t, textures.len() - 1);
                        textures.len() - 1
                    }
                };
                uv_set = info.tex_coord;
                let ext = info
                    .extensions
                    .as_ref()
                    .and_then(|e| e.others.get("KHR_texture_transform"));
                let transform = match ext {
                    None => None,
                    Some(v) => {
                        let x: TextureTransformExt =
                            serde_json::from_value(v.clone()).map_err(|e| {
                                ImportError::Json(format!(
                                    "material {mi} KHR_texture_transform: {e}"
                                ))
                            })?;
                        uv_set = x.tex_coord.unwrap_or(uv_set);
                        Some(UvTransform {
                            offset: Vec2::from(x.offset.unwrap_or([0.0; 2])),
                            rotation: x.rotation.unwrap_or(0.0),
                            scale: Vec2::from(x.scale.unwrap_or([1.0; 2])),
                        })
                    }
                };
                Some(TextureRef {
                    texture: slot,
                    transform,
                })
            }
        };
        let alpha_mode = match m.alpha_mode {
            Checked::Valid(GltfAlphaMode::Opaque) => AlphaMode::Opaque,
            Checked::Valid(GltfAlphaMode::Mask) => AlphaMode::Mask {
                cutoff: m.alpha_cutoff.map_or(0.5, |c| c.0),
            },
            Checked::Valid(GltfAlphaMode::Blend) => AlphaMode::Blend,
            Checked::Invalid => {
                return Err(ImportError::Json(format!("material {mi}: bad alphaMode")))
            }
        };
        materials.push(Material {
            name: m.name.clone(),
            base_color_factor: Vec4::from_array(pbr.base_color_factor.0),
            base_color_texture,
            metallic_factor: pbr.metallic_factor.0,
            roughness_factor: pbr.roughness_factor.0,
            alpha_mode,
            double_sided: m.double_sided,
        });
        uv_sets.push(uv_set);
    }
    Ok((materials, textures, uv_sets))
}

fn read_texture(
    r: &Reader<'_>,
    t: usize,
    base_dir: Option<&Path>,
    budget: &mut u64,
    options: &ImportOptions,
    pixel_budget: &mut u64,
) -> Result<Texture, ImportError> {
    let doc = r.doc;
    let texture = doc
        .textures
        .get(t)
        .ok_or_else(|| missing("material", "texture", t))?;
    let i = texture.source.value();
    let image = doc
        .images
        .get(i)
        .ok_or_else(|| missing(&format!("texture {t}"), "image", i))?;
    let mut declared = image.mime_type.as_ref().map(|m| m.0.clone());
    let bytes = match (&image.buffer_view, &image.uri) {
        (Some(v), _) => r.data.view(doc, v.value())?.0.to_vec(),
        (None, Some(u)) => {
            let resolved = uri::resolve(u, base_dir, budget)?;
            declared = declared.or(resolved.mime_type);
            resolved.bytes
        }
        (None, None) => {
            return Err(ImportError::Json(format!(
                "image {i} has neither a buffer view nor a URI"
            )))
        }
    };
    let wrap = match texture.sampler {
        None => (Wrap::Repeat, Wrap::Repeat),
        Some(s) => {
            let sampler = doc
                .samplers
                .get(s.value())
                .ok_or_else(|| missing(&format!("texture {t}"), "sampler", s.value()))?;
            (wrap_mode(sampler.wrap_s), wrap_mode(sampler.wrap_t))
        }
    };
    images::checked_texture(
        &format!("{i}"),
        bytes,
        declared.as_deref(),
        wrap,
        options.images,
        options.limits.max_texture_side,
        pixel_budget,
    )
}

fn wrap_mode(w: Checked<WrappingMode>) -> Wrap {
    match w {
        Checked::Valid(WrappingMode::ClampToEdge) => Wrap::ClampToEdge,
        Checked::Valid(WrappingMode::MirroredRepeat) => Wrap::MirroredRepeat,
        // The glTF default, and the kindest reading of an unknown value.
        _ => Wrap::Repeat,
    }
}

/// What became of one glTF primitive.
enum Converted {
    Submesh(Submesh),
    /// Points or lines.
    NotTriangles,
    /// A triangle primitive with no whole triangle.
    Empty,
}

fn build_instanced_mesh(
    r: &Reader<'_>,
    placements: &[Placement],
    materials: Vec<Material>,
    textures: Vec<Texture>,
    uv_sets: &[u32],
    limits: &Limits,
) -> Result<Imported, ImportError> {
    let doc = r.doc;
    let mut mesh = InstancedMesh {
        materials,
        textures,
        ..Default::default()
    };
    let mut skipped_non_triangle = 0u64;
    let mut empty = 0u64;
    // Each glTF mesh's primitives become submeshes once, on first placement.
    let mut submeshes_of_mesh: HashMap<usize, Vec<usize>> = HashMap::new();
    let mut expanded = 0u64;
    for placement in placements {
        if let std::collections::hash_map::Entry::Vacant(slot) =
            submeshes_of_mesh.entry(placement.mesh)
        {
            let mut ids = Vec::new();
            for (p, prim) in doc.meshes[placement.mesh].primitives.iter().enumerate() {
                match convert_primitive(r, placement.mesh, p, prim, uv_sets)? {
                    Converted::Submesh(s) => {
                        mesh.submeshes.push(s);
                        ids.push(mesh.submeshes.len() - 1);
                    }
                    Converted::NotTriangles => skipped_non_triangle += 1,
                    Converted::Empty => empty += 1,
                }
            }
            slot.insert(ids);
        }
        for &submesh in &submeshes_of_mesh[&placement.mesh] {
            mesh.instances.push(Instance {
                submesh,
                transform: placement.transform,
            });
            expanded += mesh.submeshes[submesh].triangle_count();
        }
        Limits::check(INSTANCES, mesh.instances.len() as u64, limits.max_instances)?;
        Limits::check(TRIANGLES, expanded, limits.max_triangles)?;
    }
    let mut warnings = Vec::new();
    if skipped_non_triangle > 0 {
        warnings.push(format!(
            "skipped {skipped_non_triangle} point or line primitive(s)"
        ));
    }
    if empty > 0 {
        warnings.push(format!(
            "skipped {empty} primitive(s) with no whole triangle"
        ));
    }
    Ok(Imported {
        mesh,
        skipped_non_triangle,
        warnings,
    })
}

fn convert_primitive(
    r: &Reader<'_>,
    m: usize,
    p: usize,
    prim: &Primitive,
    uv_sets: &[u32],
) -> Result<Converted, ImportError> {
    let what = format!("mesh {m} primitive {p}");
    let mode = match prim.mode {
        Checked::Valid(mode) => mode,
        Checked::Invalid => return Err(ImportError::Json(format!("{what}: bad mode"))),
    };
    if !matches!(
        mode,
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    ) {
        return Ok(Converted::NotTriangles);
    }
    let material = match prim.material {
        None => None,
        Some(i) if i.value() < uv_sets.len() => Some(i.value()),
        Some(i) => return Err(missing(&what, "material", i.value())),
    };
    let attribute = |s: Semantic| prim.attributes.get(&Checked::Valid(s)).map(|a| a.value());
    // Stage 1: positions.
    let position = attribute(Semantic::Positions)
        .ok_or_else(|| ImportError::Json(format!("{what} has no POSITION")))?;
    let positions = vectors::<3>(r, position, &what, "POSITION", None)?;
    let n = positions.values.len() / 3;
    // Stage 2: indices, checked, then triangulated by mode.
    let raw = match prim.indices {
        Some(a) => read_indices(r.doc, r.data, a.value(), r.max_elements)?,
        None => {
            let n32 = u32::try_from(n).map_err(|_| ImportError::LimitExceeded {
                what: "vertex count",
                value: n as u64,
                limit: u64::from(u32::MAX),
            })?;
            (0..n32).collect()
        }
    };
    if let Some(&bad) = raw.iter().find(|&&i| i as usize >= n) {
        return Err(ImportError::IndexOutOfRange {
            what,
            index: u64::from(bad),
            vertices: n,
        });
    }
    let mut indices = triangulate(mode, &raw);
    if indices.is_empty() {
        return Ok(Converted::Empty);
    }
    // Stage 3: drop vertices no triangle uses (primitives often share one big accessor).
    let kept = compact_vertices(&mut indices, n);
    // Stage 4: the kept vertices of every attribute, each with one entry per vertex.
    let normals = attribute(Semantic::Normals)
        .map(|a| vectors::<3>(r, a, &what, "NORMAL", Some(n)))
        .transpose()?
        .map(|v| pick::<3>(&v, &kept).map(Vec3::from).collect());
    let uv_set = material.map_or(0, |mi| uv_sets[mi]);
    let uvs = attribute(Semantic::TexCoords(uv_set))
        .map(|a| vectors::<2>(r, a, &what, "TEXCOORD", Some(n)))
        .transpose()?
        .map(|v| pick::<2>(&v, &kept).map(Vec2::from).collect());
    let colors = attribute(Semantic::Colors(0))
        .map(|a| colors(r, a, &what, n, &kept))
        .transpose()?;
    Ok(Converted::Submesh(Submesh {
        positions: pick::<3>(&positions, &kept).map(Vec3::from).collect(),
        normals,
        uvs,
        colors,
        indices,
        material,
    }))
}

/// A vertex accessor of N-component vectors, checked: all finite, with `expected` elements
/// if given. Shared by every primitive that reads it; [`pick`] takes a primitive's vertices.
fn vectors<const N: usize>(
    r: &Reader<'_>,
    a: usize,
    what: &str,
    name: &str,
    expected: Option<usize>,
) -> Result<Rc<AccessorValues>, ImportError> {
    let (v, finite) = r.vertex_floats(a)?;
    checked::<N>(v, finite, &format!("{what} {name}"), expected)
}

/// `v` if it has N components, `expected` elements (if given) and only finite values.
fn checked<const N: usize>(
    v: Rc<AccessorValues>,
    finite: bool,
    what: &str,
    expected: Option<usize>,
) -> Result<Rc<AccessorValues>, ImportError> {
    if v.components != N {
        return Err(ImportError::Json(format!(
            "{what} has {} components, not {N}",
            v.components
        )));
    }
    let count = v.values.len() / N;
    if let Some(e) = expected.filter(|&e| e != count) {
        return Err(ImportError::OutOfBounds {
            what: what.to_string(),
            reason: format!("{count} elements for {e} vertices"),
        });
    }
    if !finite {
        return Err(ImportError::NonFinite(what.to_string()));
    }
    Ok(v)
}

/// The elements of `v` (N components each) at `kept`, in order.
fn pick<'v, const N: usize>(
    v: &'v AccessorValues,
    kept: &'v [u32],
) -> impl Iterator<Item = [f32; N]> + 'v {
    kept.iter().map(move |&k| {
        let at = k as usize * N;
        std::array::from_fn(|i| v.values[at + i])
    })
}

/// COLOR_0 at `kept`, RGB or RGBA (alpha 1 when absent).
fn colors(
    r: &Reader<'_>,
    a: usize,
    what: &str,
    n: usize,
    kept: &[u32],
) -> Result<Vec<Vec4>, ImportError> {
    let (v, finite) = r.vertex_floats(a)?;
    let what = format!("{what} COLOR_0");
    Ok(match v.components {
        3 => pick::<3>(&*checked::<3>(v, finite, &what, Some(n))?, kept)
            .map(|c| Vec3::from(c).extend(1.0))
            .collect(),
        _ => pick::<4>(&*checked::<4>(v, finite, &what, Some(n))?, kept)
            .map(Vec4::from)
            .collect(),
    })
}

/// A triangle list from list, strip or fan indices (glTF 2.0 spec, 3.7.2.1). Strips alternate
/// winding so every triangle faces the same way; a trailing partial triangle is dropped.
fn triangulate(mode: Mode, v: &[u32]) -> Vec<u32> {
    match mode {
        Mode::TriangleStrip if v.len() >= 3 => (0..v.len() - 2)
            .flat_map(|i| {
                let odd = i % 2;
                [v[i], v[i + 1 + odd], v[i + 2 - odd]]
            })
            .collect(),
        Mode::TriangleFan if v.len() >= 3 => (0..v.len() - 2)
            .flat_map(|i| [v[i + 1], v[i + 2], v[0]])
            .collect(),
        Mode::Triangles => v[..v.len() / 3 * 3].to_vec(),
        _ => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_triangulate_with_consistent_winding() {
        // A strip 0-1-2-3 is the quad (0,1,2) + (2,1,3): the second triangle swaps its first
        // two vertices so both wind the same way.
        assert_eq!(
            triangulate(Mode::TriangleStrip, &[0, 1, 2, 3]),
            vec![0, 1, 2, 1, 3, 2]
        );
        // A fan around vertex 0 of a quad 0-1-2-3.
        assert_eq!(
            triangulate(Mode::TriangleFan, &[0, 1, 2, 3]),
            vec![1, 2, 0, 2, 3, 0]
        );
        // Two vertices make no triangle.
        assert!(triangulate(Mode::TriangleStrip, &[0, 1]).is_empty());
    }
}
