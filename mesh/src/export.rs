//! GLB export of an instanced mesh (glTF 2.0 spec; EXT_mesh_gpu_instancing;
//! KHR_mesh_quantization; EXT_meshopt_compression; KHR_texture_transform).
//!
//! Each submesh with triangles becomes one glTF mesh (one without draws nothing, and glTF has
//! no empty accessor, so it is left out). A submesh with two or more instances that are all TRS is
//! one node with EXT_mesh_gpu_instancing; otherwise each instance is a node with a matrix, or,
//! when the transform has shear (which a glTF matrix may not), a parent and child pair from
//! [`crate::transform::decompose_svd`]. Mirrored instances keep their negative determinant,
//! which glTF renderers answer by flipping the winding, as [`InstancedMesh::expand`] does.
//!
//! With `share_vertices` (aggregates), submeshes of one attribute layout write their vertices
//! into shared runs of up to 65,535 vertices (one position, normal, UV and colour accessor per
//! run), and each primitive indexes its part of the run with its own 16-bit index accessor,
//! as glTF allows; readers that want a primitive alone drop the vertices it does not index
//! (ours does, in import). With `short_attributes` (aggregates too) normals are 8-bit and
//! UVs and colours 16-bit normalized integers (KHR_mesh_quantization). With
//! `position_tolerance` (aggregates, format 11) a run's positions are 16-bit integers over the
//! run's box, where that keeps every placed vertex within the tolerance in world space (else
//! float).
//!
//! Quantized positions are mapped back by one dequantisation per run, an offset and a uniform
//! step. A GPU-instanced node carries the step as its own uniform scale and each instance's
//! translation absorbs the offset, so the instances' rotations and scales are written
//! unchanged (and an identity stream stays left out); a node with a matrix takes the whole
//! dequantisation into its matrix.
//!
//! With compression (the approach of meshoptimizer's gltfpack): indices are optimised for the
//! vertex cache and vertices for fetch order; positions become 16-bit integers over each
//! submesh's box, whatever the tolerance, with the whole dequantisation folded into every
//! instance transform (a constant scale stream costs next to nothing once encoded), normals
//! 8-bit, UVs in [0, 1] and colours 16-bit (KHR_mesh_quantization); every vertex, index and
//! instance stream is then meshopt-encoded (EXT_meshopt_compression, with a fallback buffer).

use std::collections::{BTreeMap, BTreeSet};

use glam::{Affine3A, Mat4, Quat, Vec3, Vec4};
use serde_json::{json, Map, Value};

use crate::error::ExportError;
use crate::model::{Aabb, AlphaMode, InstancedMesh, Material, Submesh, Texture, Wrap};
use crate::transform::{decompose_svd, decompose_trs, Trs};

/// Options for [`export_glb`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExportOptions {
    /// Quantize and meshopt-encode geometry (lossy for positions at 16 bits per axis).
    pub compress: bool,
    /// Store instance rotations as normalized 16-bit quaternions (EXT_mesh_gpu_instancing
    /// allows it without KHR_mesh_quantization): 8 bytes instead of 16 per instance, at most
    /// about 3e-5 rad off.
    pub short_rotations: bool,
    /// Let submeshes of one attribute layout share their vertex accessors, up to 65,535
    /// vertices per shared run, each primitive keeping its own 16-bit index accessor into the
    /// run (see [`vertex_runs`]). Ignored when compressing (each submesh then has its own
    /// quantisation grid).
    pub share_vertices: bool,
    /// Normals as 8-bit and UVs in [0, 1] and colours as 16-bit normalized integers
    /// (KHR_mesh_quantization): with float positions 20 bytes a vertex instead of 32, normals
    /// within about 0.5 degrees. Compression always does this (and quantizes positions too).
    pub short_attributes: bool,
    /// Positions as unsigned 16-bit integers over each vertex run's box (KHR_mesh_quantization),
    /// 8 bytes a vertex instead of 12, for every run whose rounding keeps each of its vertices,
    /// in every placement, within this distance (world units) of where it was; the other runs
    /// keep float positions. `None`: float positions (unless compressing).
    pub position_tolerance: Option<f32>,
}

impl ExportOptions {
    /// Plain float attributes, readable by every glTF loader.
    pub fn plain() -> Self {
        Self {
            compress: false,
            short_rotations: false,
            share_vertices: false,
            short_attributes: false,
            position_tolerance: None,
        }
    }

    /// Quantized, meshopt-compressed output for serving.
    pub fn compressed() -> Self {
        Self {
            compress: true,
            short_rotations: true,
            share_vertices: false,
            short_attributes: true,
            position_tolerance: None,
        }
    }

    /// Lossless and compact, for files only Horizon reads back (an aggregate's parts): float
    /// attributes and rotations exactly as in memory, vertices shared in runs.
    pub fn parts() -> Self {
        Self {
            share_vertices: true,
            ..Self::plain()
        }
    }

    /// What aggregates are written as, seen from afar and made mostly of instances: short
    /// normals, UVs and instance rotations, vertices shared in runs, and positions 16-bit
    /// wherever that keeps them within `position_tolerance` (world units) of their place.
    pub fn aggregate(position_tolerance: f32) -> Self {
        Self {
            compress: false,
            short_rotations: true,
            share_vertices: true,
            short_attributes: true,
            position_tolerance: Some(position_tolerance),
        }
    }
}

/// Writes `mesh` as a self-contained GLB.
pub fn export_glb(mesh: &InstancedMesh, options: &ExportOptions) -> Result<Vec<u8>, ExportError> {
    // Stage 1: refuse a mesh that breaks the model's invariants; leave out submeshes without
    // triangles, which draw nothing and would need accessors of no elements, which glTF
    // forbids.
    mesh.validate()?;
    let drawn: InstancedMesh;
    let mesh = if mesh.submeshes.iter().any(|s| s.indices.is_empty()) {
        let mut copy = mesh.clone();
        let keep: Vec<bool> = copy
            .submeshes
            .iter()
            .map(|s| !s.indices.is_empty())
            .collect();
        copy.retain_submeshes(&keep);
        drawn = copy;
        &drawn
    } else {
        mesh
    };
    let mut w = GlbWriter::new(*options);
    // Stage 2: geometry, one glTF mesh per submesh, its vertices in a run of their own or one
    // shared with other submeshes; remember each dequantisation transform.
    let placed: Vec<Vec<Affine3A>> = mesh
        .instances_by_submesh()
        .iter()
        .map(|ks| ks.iter().map(|&k| mesh.instances[k].transform).collect())
        .collect();
    let share = options.share_vertices && !options.compress;
    let reach: Option<Vec<f32>> = options
        .position_tolerance
        .filter(|_| share)
        .map(|tolerance| {
            placed
                .iter()
                .map(|p| Dequantize::reach(p, tolerance))
                .collect()
        });
    let (runs, run_of) = vertex_runs(&mesh.submeshes, share, reach.as_deref());
    let mut written: Vec<Option<SharedRun>> = (0..runs.len()).map(|_| None).collect();
    let mut dequantize = Vec::with_capacity(mesh.submeshes.len());
    for (s, sub) in mesh.submeshes.iter().enumerate() {
        let (run, at) = run_of[s];
        if runs[run].len() == 1 {
            dequantize.push(w.write_submesh(sub, &placed[s])?);
            continue;
        }
        // A shared run's vertices are written when its first submesh comes, in run order.
        if written[run].is_none() {
            let members: Vec<(&Submesh, &[Affine3A])> = runs[run]
                .iter()
                .map(|&m| (&mesh.submeshes[m], placed[m].as_slice()))
                .collect();
            written[run] = Some(w.write_shared_vertices(&members)?);
        }
        let shared = written[run].as_ref().expect("written above");
        w.write_primitive(
            shared.attributes.clone(),
            sub.indices.iter().map(|&i| i + shared.bases[at]).collect(),
            shared.count,
            sub.material,
        )?;
        dequantize.push(shared.dequantize);
    }
    // Stage 3: textures and materials.
    w.write_textures(&mesh.textures);
    for m in &mesh.materials {
        w.write_material(m);
    }
    // Stage 4: nodes, GPU-instanced where every instance of a submesh is TRS.
    w.write_nodes(&placed, &dequantize)?;
    // Stage 5: the JSON document and the GLB container.
    w.finish()
}

/// glTF component types and buffer view targets.
const FLOAT: u32 = 5126;
const UNSIGNED_SHORT: u32 = 5123;
const UNSIGNED_INT: u32 = 5125;
const BYTE: u32 = 5120;
const SHORT: u32 = 5122;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// How a buffer view's bytes are stored.
enum Encoding<'a> {
    /// meshopt vertex codec, for vertex and instance attributes.
    Attributes { stride: usize },
    /// meshopt index codec, for triangle lists.
    Triangles {
        indices: &'a [u32],
        vertex_count: usize,
    },
}

/// How stored positions map back to model space: `offset + step * stored`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Dequantize {
    offset: Vec3,
    step: f32,
}

impl Dequantize {
    /// Float positions, stored as they are.
    const NONE: Self = Self {
        offset: Vec3::ZERO,
        step: 1.0,
    };

    fn affine(&self) -> Affine3A {
        Affine3A::from_scale_rotation_translation(
            Vec3::splat(self.step),
            Quat::IDENTITY,
            self.offset,
        )
    }

    /// The translation of an instance placed by `trs` under a node scaled by the step (see
    /// the module docs): where it puts stored position zero, in units of the step. The offset
    /// is turned by `rotation`, the instance's rotation as a reader will decode it, so that
    /// rounding the rotation turns the vertices about the instance's origin exactly as it does
    /// with float positions, and moves them no further.
    fn instance_translation(&self, trs: &Trs, rotation: Quat) -> Vec3 {
        (trs.translation + rotation * (trs.scale * self.offset)) / self.step
    }

    /// Whether placing these stored positions by `placed` stays finite both ways they are
    /// written (a node matrix, or an instance under a scaled node, with room to spare for the
    /// rotation a reader decodes), and keeps every vertex within `tolerance` of its place in
    /// every placement: rounding moves a stored position by at most half a step on each axis,
    /// which a placement stretches by at most [`rounding_stretch`].
    fn fits(&self, placed: &[Affine3A], tolerance: f32) -> bool {
        self.affine().is_finite()
            && placed.iter().all(|t| {
                let origin = t.transform_point3(self.offset) / self.step;
                (*t * self.affine()).is_finite()
                    && origin.abs().max_element() < f32::MAX / 2.0
                    && self.step * rounding_stretch(t) <= tolerance
            })
    }

    /// The largest box extent whose 16-bit step keeps positions placed by `placed` within
    /// `tolerance` ([`Dequantize::fits`]' bound, solved for the extent); unbounded for a
    /// submesh placed nowhere, zero (float positions) for a tolerance that is not a positive
    /// number.
    fn reach(placed: &[Affine3A], tolerance: f32) -> f32 {
        let stretch = placed.iter().map(rounding_stretch).fold(0.0f32, f32::max);
        if tolerance.is_nan() || tolerance <= 0.0 {
            0.0
        } else if stretch > 0.0 {
            // The step is rounded up by under a tenth (`short_step`).
            tolerance / stretch * STEPS / 1.1
        } else {
            f32::INFINITY
        }
    }
}

/// Steps of a 16-bit quantisation grid across its box.
const STEPS: f32 = 65535.0;

/// How far, in steps, a placement can move a position that rounding moved by up to half a step
/// on each axis: the longest image under its linear part of a half-step box's corner,
/// `(+-1/2, +-1/2, +-1/2)`. For a TRS placement that is half the length of its scale vector;
/// shear can stretch a diagonal further than any axis.
fn rounding_stretch(t: &Affine3A) -> f32 {
    const CORNERS: [Vec3; 4] = [
        Vec3::new(0.5, 0.5, 0.5),
        Vec3::new(0.5, 0.5, -0.5),
        Vec3::new(0.5, -0.5, 0.5),
        Vec3::new(-0.5, 0.5, 0.5),
    ];
    CORNERS
        .iter()
        .map(|&c| (t.matrix3 * c).length())
        .fold(0.0f32, f32::max)
}

/// A vertex attribute ready to write: tightly packed elements of `stride` bytes.
struct Attribute {
    bytes: Vec<u8>,
    stride: usize,
    component_type: u32,
    normalized: bool,
    type_name: &'static str,
    count: usize,
    bounds: Option<(Vec<f32>, Vec<f32>)>,
}

/// Where the bytes of uncompressed accessors go: one buffer view per kind of data, shared by
/// every accessor of that kind (each at its own `byteOffset`), rather than one view per
/// accessor, which on an aggregate of many small submeshes was a third of the JSON.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct PoolKey {
    stride: Option<usize>,
    target: Option<u32>,
}

/// One shared buffer view being filled; laid out in the binary chunk by `finish`.
struct Pool {
    key: PoolKey,
    view: usize,
    bytes: Vec<u8>,
}

/// Accumulates the glTF JSON arrays and the binary chunk.
struct GlbWriter {
    compress: bool,
    short_rotations: bool,
    /// Normals, UVs and colours as normalized integers (`short_attributes`, or compressing).
    short_attributes: bool,
    /// Whether an attribute was written as integers (KHR_mesh_quantization).
    quantized: bool,
    /// The largest distance a quantized position may move (`ExportOptions::position_tolerance`;
    /// unbounded when compressing, `None` for float positions).
    position_tolerance: Option<f32>,
    pools: Vec<Pool>,
    /// The GLB binary chunk (buffer 0).
    bin: Vec<u8>,
    /// Size of the virtual uncompressed buffer (buffer 1) that compressed views decode into.
    fallback_len: usize,
    accessors: Vec<Value>,
    buffer_views: Vec<Value>,
    meshes: Vec<Value>,
    materials: Vec<Value>,
    textures: Vec<Value>,
    images: Vec<Value>,
    samplers: Vec<Value>,
    nodes: Vec<Value>,
    roots: Vec<usize>,
    extensions_used: BTreeSet<&'static str>,
    extensions_required: BTreeSet<&'static str>,
}

/// The vertex accessors of a shared run, where each member's vertices start in them, and how
/// its positions map back to model space.
struct SharedRun {
    attributes: Map<String, Value>,
    bases: Vec<u32>,
    count: usize,
    dequantize: Dequantize,
}

/// Most vertices in a shared run: every index into it stays 16-bit.
const RUN_VERTICES: usize = 65_535;

/// Most runs of one layout open at once (each a box of its own), so that finding a run for a
/// submesh stays a bounded scan however scattered the boxes.
const OPEN_RUNS: usize = 16;

/// Which submeshes write their vertices together: with `share`, submeshes of one attribute
/// layout (normals, UVs, colours present or not) fill a run until the next would take it past
/// [`RUN_VERTICES`], or, with `reach` (quantized positions), past the box extent a member
/// tolerates; a submesh that alone exceeds the vertex limit, and every submesh without
/// `share`, has a run of its own. Returns the runs (submesh numbers in order) and, for each
/// submesh, its run and its place in it.
///
/// A submesh in its own run costs three or four accessors more than one sharing a run (a
/// position accessor with its bounds, normals, UVs): on an aggregate of many small instanced
/// submeshes that was a third of the JSON, and the JSON a fifth of the file.
///
/// `reach[s]` is the largest box extent over which submesh `s`'s positions can be quantized
/// within the tolerance (see [`Dequantize::fits`]). An aggregate mixes parts in model space,
/// a metre or two across, with geometry baked in world space a kilometre from the origin; one
/// run over both would round the small parts by centimetres, so a submesh joins the first open
/// run of its layout whose box, grown by its own, stays within every member's reach. A run
/// full of vertices closes, and past [`OPEN_RUNS`] of a layout the oldest does; with every
/// reach unbounded this is one open run per layout. A submesh whose own box is beyond its
/// reach keeps float positions wherever it goes, so it shares the runs of its layout kept for
/// such submeshes, unbounded; an empty one joins any run and bounds none.
fn vertex_runs(
    submeshes: &[Submesh],
    share: bool,
    reach: Option<&[f32]>,
) -> (Vec<Vec<usize>>, Vec<(usize, usize)>) {
    /// A run still taking members: its number, vertices, box and the least reach among them.
    struct Open {
        run: usize,
        count: usize,
        bounds: Aabb,
        reach: f32,
    }
    let mut runs: Vec<Vec<usize>> = Vec::new();
    let mut run_of = Vec::with_capacity(submeshes.len());
    /// Normals, UVs and colours present or not, and whether the positions stay float.
    type Kind = ((bool, bool, bool), bool);
    // Per kind, the runs still open.
    let mut open: BTreeMap<Kind, Vec<Open>> = BTreeMap::new();
    for (s, sub) in submeshes.iter().enumerate() {
        let n = sub.positions.len();
        let layout = (
            sub.normals.is_some(),
            sub.uvs.is_some(),
            sub.colors.is_some(),
        );
        let mut bounds = Aabb::EMPTY;
        sub.positions.iter().for_each(|&p| bounds.grow(p));
        let own_extent = (bounds.max - bounds.min).max_element();
        let (own_reach, float) = match reach {
            Some(_) if n == 0 => (f32::INFINITY, false),
            Some(r) if own_extent <= r[s] => (r[s], false),
            Some(_) => (f32::INFINITY, true),
            None => (f32::INFINITY, false),
        };
        let candidates = open.entry((layout, float)).or_default();
        let fits_box = |o: &Open| {
            let grown = o.bounds.union(&bounds);
            n == 0 || (grown.max - grown.min).max_element() <= o.reach.min(own_reach)
        };
        let joined = share
            .then(|| {
                candidates
                    .iter()
                    .position(|o| o.count + n <= RUN_VERTICES && fits_box(o))
            })
            .flatten();
        if let Some(k) = joined {
            let o = &mut candidates[k];
            o.count += n;
            o.bounds = o.bounds.union(&bounds);
            o.reach = o.reach.min(own_reach);
            run_of.push((o.run, runs[o.run].len()));
            runs[o.run].push(s);
        } else {
            runs.push(vec![s]);
            run_of.push((runs.len() - 1, 0));
            if share && n <= RUN_VERTICES {
                // Runs this one's vertices would overflow are as good as full.
                candidates.retain(|o| o.count + n <= RUN_VERTICES);
                if candidates.len() == OPEN_RUNS {
                    candidates.remove(0);
                }
                candidates.push(Open {
                    run: runs.len() - 1,
                    count: n,
                    bounds,
                    reach: own_reach,
                });
            }
        }
    }
    (runs, run_of)
}

impl GlbWriter {
    fn new(options: ExportOptions) -> Self {
        Self {
            compress: options.compress,
            short_rotations: options.short_rotations,
            short_attributes: options.compress || options.short_attributes,
            quantized: false,
            position_tolerance: if options.compress {
                Some(f32::INFINITY)
            } else {
                options.position_tolerance
            },
            pools: Vec::new(),
            bin: Vec::new(),
            fallback_len: 0,
            accessors: Vec::new(),
            buffer_views: Vec::new(),
            meshes: Vec::new(),
            materials: Vec::new(),
            textures: Vec::new(),
            images: Vec::new(),
            samplers: Vec::new(),
            nodes: Vec::new(),
            roots: Vec::new(),
            extensions_used: BTreeSet::new(),
            extensions_required: BTreeSet::new(),
        }
    }

    fn align_bin(&mut self) {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
    }

    /// Places `bytes` in a buffer view and returns the view and the offset in it: a shared
    /// view per kind of data when not compressing, else a view of its own, meshopt-encoded.
    fn add_view(
        &mut self,
        bytes: &[u8],
        stride: Option<usize>,
        target: Option<u32>,
        encoding: Encoding<'_>,
    ) -> Result<(usize, usize), ExportError> {
        if !self.compress {
            let key = PoolKey { stride, target };
            let k = match self.pools.iter().position(|p| p.key == key) {
                Some(k) => k,
                None => {
                    // Offset and length are filled in by `finish`.
                    let mut view = Map::new();
                    view.insert("buffer".into(), json!(0));
                    if let Some(s) = stride {
                        view.insert("byteStride".into(), json!(s));
                    }
                    if let Some(t) = target {
                        view.insert("target".into(), json!(t));
                    }
                    self.buffer_views.push(Value::Object(view));
                    self.pools.push(Pool {
                        key,
                        view: self.buffer_views.len() - 1,
                        bytes: Vec::new(),
                    });
                    self.pools.len() - 1
                }
            };
            let pool = &mut self.pools[k];
            // Every accessor starts on a 4-byte boundary (vertex attributes must).
            while !pool.bytes.len().is_multiple_of(4) {
                pool.bytes.push(0);
            }
            let offset = pool.bytes.len();
            pool.bytes.extend_from_slice(bytes);
            return Ok((pool.view, offset));
        }
        self.align_bin();
        let mut view = Map::new();
        let encoded = match encoding {
            _ if !self.compress => None,
            Encoding::Attributes { stride } => Some((
                crate::meshopt_stream::encode_vertex_stream(bytes, stride)
                    .map_err(|e| ExportError::Encode(format!("{e:?}")))?,
                "ATTRIBUTES",
                stride,
                bytes.len() / stride,
            )),
            Encoding::Triangles {
                indices,
                vertex_count,
            } => Some((
                meshopt::encode_index_buffer(indices, vertex_count)
                    .map_err(|e| ExportError::Encode(format!("{e:?}")))?,
                "TRIANGLES",
                bytes.len() / indices.len().max(1),
                indices.len(),
            )),
        };
        match encoded {
            None => {
                view.insert("buffer".into(), json!(0));
                view.insert("byteOffset".into(), json!(self.bin.len()));
                self.bin.extend_from_slice(bytes);
            }
            Some((data, mode, ext_stride, count)) => {
                view.insert("buffer".into(), json!(1));
                view.insert("byteOffset".into(), json!(self.fallback_len));
                self.fallback_len += bytes.len().div_ceil(4) * 4;
                view.insert(
                    "extensions".into(),
                    json!({"EXT_meshopt_compression": {
                        "buffer": 0,
                        "byteOffset": self.bin.len(),
                        "byteLength": data.len(),
                        "byteStride": ext_stride,
                        "count": count,
                        "mode": mode,
                    }}),
                );
                self.bin.extend_from_slice(&data);
            }
        }
        view.insert("byteLength".into(), json!(bytes.len()));
        if let Some(s) = stride {
            view.insert("byteStride".into(), json!(s));
        }
        if let Some(t) = target {
            view.insert("target".into(), json!(t));
        }
        self.buffer_views.push(Value::Object(view));
        Ok((self.buffer_views.len() - 1, 0))
    }

    fn add_accessor(&mut self, (view, offset): (usize, usize), a: &Attribute) -> usize {
        let mut acc = Map::new();
        acc.insert("bufferView".into(), json!(view));
        if offset > 0 {
            acc.insert("byteOffset".into(), json!(offset));
        }
        acc.insert("componentType".into(), json!(a.component_type));
        if a.normalized {
            acc.insert("normalized".into(), json!(true));
        }
        acc.insert("count".into(), json!(a.count));
        acc.insert("type".into(), json!(a.type_name));
        if let Some((min, max)) = &a.bounds {
            acc.insert("min".into(), numbers(min));
            acc.insert("max".into(), numbers(max));
        }
        self.accessors.push(Value::Object(acc));
        self.accessors.len() - 1
    }

    /// Writes a vertex or instance attribute: its view (meshopt-encoded when compressing) and
    /// its accessor.
    fn write_attribute(
        &mut self,
        a: &Attribute,
        target: Option<u32>,
    ) -> Result<usize, ExportError> {
        let view = self.add_view(
            &a.bytes,
            target.map(|_| a.stride),
            target,
            Encoding::Attributes { stride: a.stride },
        )?;
        Ok(self.add_accessor(view, a))
    }

    /// Writes one submesh as a glTF mesh and returns how its stored positions map back to model
    /// space.
    fn write_submesh(
        &mut self,
        s: &Submesh,
        placed: &[Affine3A],
    ) -> Result<Dequantize, ExportError> {
        // Stage 1: vertex order; compression optimises for the vertex cache and fetch.
        let (indices, order) = if self.compress {
            optimise_order(s)
        } else {
            (s.indices.clone(), (0..s.positions.len() as u32).collect())
        };
        let n = order.len();
        // Stage 2: attributes, positions quantized where the tolerance allows.
        let mut attributes = Map::new();
        let dequantize = self.write_positions(&[(s, &order, placed)], &mut attributes)?;
        self.write_other_attributes(&[(s, &order)], &mut attributes)?;
        // Stage 3: indices and the primitive.
        self.write_primitive(attributes, indices, n, s.material)?;
        Ok(dequantize)
    }

    /// POSITION of `parts` (one run; each submesh's vertices in the order given, placed by its
    /// transforms), one accessor over all of them: 16-bit integers over the run's box where
    /// that keeps every placed vertex within the tolerance and the dequantisation folds into
    /// every placement without overflowing f32, else floats. Returns the dequantisation.
    fn write_positions(
        &mut self,
        parts: &[(&Submesh, &[u32], &[Affine3A])],
        attributes: &mut Map<String, Value>,
    ) -> Result<Dequantize, ExportError> {
        let positions = || {
            parts
                .iter()
                .flat_map(|&(m, order, _)| order.iter().map(|&v| m.positions[v as usize]))
        };
        // The grid first, from the box alone; the positions are encoded once, on it or as
        // floats.
        let fitting = self.position_tolerance.and_then(|tolerance| {
            let d = grid(positions(), !self.compress);
            parts
                .iter()
                .all(|&(_, _, placed)| d.fits(placed, tolerance))
                .then_some(d)
        });
        let (position, dequantize) = match fitting {
            Some(d) => {
                self.quantized = true;
                (quantized_attribute(positions(), &d), d)
            }
            None => (
                float_attribute(positions().map(|p| p.to_array()), true),
                Dequantize::NONE,
            ),
        };
        let p = self.write_attribute(&position, Some(ARRAY_BUFFER))?;
        attributes.insert("POSITION".into(), json!(p));
        Ok(dequantize)
    }

    /// NORMAL, TEXCOORD_0 and COLOR_0 of `parts` (one layout; each submesh's vertices in the
    /// order given), one accessor each over all the parts: floats, or with short attributes
    /// normalized integers. UVs stay float unless every UV of every part is in [0, 1].
    fn write_other_attributes(
        &mut self,
        parts: &[(&Submesh, &[u32])],
        attributes: &mut Map<String, Value>,
    ) -> Result<(), ExportError> {
        if let Some(normals) = concatenated(parts, |m| m.normals.as_ref()) {
            let unit = normals.map(|n| n.try_normalize().unwrap_or(Vec3::Z).to_array());
            let a = self.normal_attribute(unit);
            let i = self.write_attribute(&a, Some(ARRAY_BUFFER))?;
            attributes.insert("NORMAL".into(), json!(i));
        }
        if let Some(uvs) = concatenated(parts, |m| m.uvs.as_ref()) {
            let in_unit = parts
                .iter()
                .all(|(m, _)| m.uvs.iter().flatten().all(|&t| in_unit_square(t)));
            let a = self.unit_attribute(uvs.map(|t| t.to_array()), in_unit);
            let i = self.write_attribute(&a, Some(ARRAY_BUFFER))?;
            attributes.insert("TEXCOORD_0".into(), json!(i));
        }
        if let Some(colors) = concatenated(parts, |m| m.colors.as_ref()) {
            // glTF colours live in [0, 1].
            let values = colors.map(|c| c.clamp(Vec4::ZERO, Vec4::ONE).to_array());
            let a = self.unit_attribute(values, true);
            let i = self.write_attribute(&a, Some(ARRAY_BUFFER))?;
            attributes.insert("COLOR_0".into(), json!(i));
        }
        Ok(())
    }

    /// Unit normals as written: 8-bit signed normalized with short attributes, else floats.
    fn normal_attribute(&mut self, unit: impl Iterator<Item = [f32; 3]>) -> Attribute {
        if self.short_attributes {
            self.quantized = true;
            snorm8_attribute(unit)
        } else {
            float_attribute(unit, false)
        }
    }

    /// Values in [0, 1] (`in_unit`: UVs that may not be) as written: 16-bit unsigned
    /// normalized with short attributes, else floats.
    fn unit_attribute<const N: usize>(
        &mut self,
        values: impl Iterator<Item = [f32; N]>,
        in_unit: bool,
    ) -> Attribute {
        if self.short_attributes && in_unit {
            self.quantized = true;
            norm16_attribute(values, false)
        } else {
            float_attribute(values, false)
        }
    }

    /// The vertex attributes of `members` (one layout, each with its placements), concatenated
    /// into one accessor each, where each member's vertices start, and the run's
    /// dequantisation.
    fn write_shared_vertices(
        &mut self,
        members: &[(&Submesh, &[Affine3A])],
    ) -> Result<SharedRun, ExportError> {
        let mut bases = Vec::with_capacity(members.len());
        let mut count = 0u32;
        for (m, _) in members {
            bases.push(count);
            count += m.positions.len() as u32;
        }
        let orders: Vec<Vec<u32>> = members
            .iter()
            .map(|(m, _)| (0..m.positions.len() as u32).collect())
            .collect();
        let placed: Vec<(&Submesh, &[u32], &[Affine3A])> = members
            .iter()
            .zip(&orders)
            .map(|(&(m, placed), order)| (m, order.as_slice(), placed))
            .collect();
        let parts: Vec<(&Submesh, &[u32])> = placed.iter().map(|&(m, o, _)| (m, o)).collect();
        let mut attributes = Map::new();
        let dequantize = self.write_positions(&placed, &mut attributes)?;
        self.write_other_attributes(&parts, &mut attributes)?;
        Ok(SharedRun {
            attributes,
            bases,
            count: count as usize,
            dequantize,
        })
    }

    /// One glTF mesh of one primitive: `indices` into vertex accessors of `vertex_count`
    /// elements, 16-bit when every index fits below the primitive-restart value.
    fn write_primitive(
        &mut self,
        attributes: Map<String, Value>,
        indices: Vec<u32>,
        vertex_count: usize,
        material: Option<usize>,
    ) -> Result<(), ExportError> {
        let n = vertex_count;
        let wide = n > 65535;
        let bytes: Vec<u8> = if wide {
            indices.iter().flat_map(|i| i.to_le_bytes()).collect()
        } else {
            indices
                .iter()
                .flat_map(|&i| (i as u16).to_le_bytes())
                .collect()
        };
        let view = self.add_view(
            &bytes,
            None,
            Some(ELEMENT_ARRAY_BUFFER),
            Encoding::Triangles {
                indices: &indices,
                vertex_count: n,
            },
        )?;
        let index_accessor = self.add_accessor(
            view,
            &Attribute {
                bytes: Vec::new(),
                stride: 0,
                component_type: if wide { UNSIGNED_INT } else { UNSIGNED_SHORT },
                normalized: false,
                type_name: "SCALAR",
                count: indices.len(),
                bounds: None,
            },
        );
        let mut primitive = Map::new();
        primitive.insert("attributes".into(), Value::Object(attributes));
        primitive.insert("indices".into(), json!(index_accessor));
        if let Some(m) = material {
            primitive.insert("material".into(), json!(m));
        }
        self.meshes.push(json!({ "primitives": [primitive] }));
        Ok(())
    }

    fn write_textures(&mut self, textures: &[Texture]) {
        let mut sampler_of: BTreeMap<(u32, u32), usize> = BTreeMap::new();
        for t in textures {
            self.align_bin();
            let offset = self.bin.len();
            self.bin.extend_from_slice(&t.bytes);
            self.buffer_views.push(json!({
                "buffer": 0, "byteOffset": offset, "byteLength": t.bytes.len(),
            }));
            self.images.push(json!({
                "bufferView": self.buffer_views.len() - 1,
                "mimeType": t.mime_type,
            }));
            let key = (wrap_code(t.wrap_u), wrap_code(t.wrap_v));
            let next = sampler_of.len();
            let sampler = *sampler_of.entry(key).or_insert(next);
            if sampler == self.samplers.len() {
                self.samplers
                    .push(json!({ "wrapS": key.0, "wrapT": key.1 }));
            }
            self.textures.push(json!({
                "source": self.images.len() - 1,
                "sampler": sampler,
            }));
        }
    }

    fn write_material(&mut self, m: &Material) {
        let unit = |x: f32| x.clamp(0.0, 1.0);
        let mut pbr = Map::new();
        pbr.insert(
            "baseColorFactor".into(),
            numbers(&m.base_color_factor.to_array().map(unit)),
        );
        if let Some(t) = &m.base_color_texture {
            let mut info = json!({ "index": t.texture });
            if let Some(x) = &t.transform {
                self.extensions_used.insert("KHR_texture_transform");
                info["extensions"] = json!({"KHR_texture_transform": {
                    "offset": numbers(&x.offset.to_array()),
                    "rotation": number(x.rotation),
                    "scale": numbers(&x.scale.to_array()),
                }});
            }
            pbr.insert("baseColorTexture".into(), info);
        }
        pbr.insert("metallicFactor".into(), number(unit(m.metallic_factor)));
        pbr.insert("roughnessFactor".into(), number(unit(m.roughness_factor)));
        let mut out = Map::new();
        if let Some(name) = &m.name {
            out.insert("name".into(), json!(name));
        }
        out.insert("pbrMetallicRoughness".into(), Value::Object(pbr));
        match m.alpha_mode {
            AlphaMode::Opaque => {}
            AlphaMode::Mask { cutoff } => {
                out.insert("alphaMode".into(), json!("MASK"));
                out.insert("alphaCutoff".into(), number(cutoff.max(0.0)));
            }
            AlphaMode::Blend => {
                out.insert("alphaMode".into(), json!("BLEND"));
            }
        }
        if m.double_sided {
            out.insert("doubleSided".into(), json!(true));
        }
        self.materials.push(Value::Object(out));
    }

    /// The nodes placing submesh `s` by `placed[s]`, its stored positions mapped back by
    /// `dequantize[s]`: one GPU-instanced node scaled by the step, or matrix nodes.
    fn write_nodes(
        &mut self,
        placed: &[Vec<Affine3A>],
        dequantize: &[Dequantize],
    ) -> Result<(), ExportError> {
        for (s, (placed, d)) in placed.iter().zip(dequantize).enumerate() {
            // Compression folds the whole dequantisation into every placement: its instance
            // streams are meshopt-encoded, where a constant scale stream costs next to nothing
            // and translations divided by the step would compress worse.
            let folded: Vec<Affine3A>;
            let instances = if self.compress {
                folded = placed.iter().map(|t| *t * d.affine()).collect();
                &folded
            } else {
                placed
            };
            // The positions are quantized only where every form here stays finite, so this
            // needs an instance transform that was not finite to begin with.
            if !instances.iter().all(Affine3A::is_finite) {
                return Err(ExportError::Encode(format!(
                    "submesh {s}: transform overflows f32"
                )));
            }
            let all_trs: Option<Vec<Trs>> = instances.iter().map(decompose_trs).collect();
            match all_trs {
                Some(trs) if trs.len() >= 2 && self.compress => {
                    self.write_gpu_instanced_node(s, &trs, 1.0)?;
                }
                Some(mut trs) if trs.len() >= 2 => {
                    for x in &mut trs {
                        let read = if self.short_rotations {
                            read_back_rotation(x.rotation)
                        } else {
                            x.rotation
                        };
                        x.translation = d.instance_translation(x, read);
                    }
                    self.write_gpu_instanced_node(s, &trs, d.step)?;
                }
                _ => {
                    for t in placed {
                        self.write_matrix_node(s, &(*t * d.affine()));
                    }
                }
            }
        }
        Ok(())
    }

    /// One node drawing `mesh` at every transform of `trs`, itself scaled by `scale` (the
    /// positions' dequantisation step; 1 for float positions).
    fn write_gpu_instanced_node(
        &mut self,
        mesh: usize,
        trs: &[Trs],
        scale: f32,
    ) -> Result<(), ExportError> {
        self.extensions_used.insert("EXT_mesh_gpu_instancing");
        // Every attribute is optional: a rotation or scale that is the identity for every
        // instance (to float precision) is left out.
        let mut attributes = Map::new();
        let t = float_attribute(trs.iter().map(|x| x.translation.to_array()), false);
        attributes.insert("TRANSLATION".into(), json!(self.write_attribute(&t, None)?));
        if !trs
            .iter()
            .all(|x| x.rotation.abs_diff_eq(Quat::IDENTITY, 1e-7))
        {
            let rotations = trs.iter().map(|x| x.rotation.to_array());
            let r = if self.short_rotations {
                norm16_attribute(rotations, true)
            } else {
                float_attribute(rotations, false)
            };
            attributes.insert("ROTATION".into(), json!(self.write_attribute(&r, None)?));
        }
        if !trs.iter().all(|x| x.scale.abs_diff_eq(Vec3::ONE, 1e-7)) {
            let s = float_attribute(trs.iter().map(|x| x.scale.to_array()), false);
            attributes.insert("SCALE".into(), json!(self.write_attribute(&s, None)?));
        }
        let mut node = Map::new();
        node.insert("mesh".into(), json!(mesh));
        if scale != 1.0 {
            node.insert("scale".into(), numbers(&[scale; 3]));
        }
        node.insert(
            "extensions".into(),
            json!({"EXT_mesh_gpu_instancing": {"attributes": attributes}}),
        );
        self.nodes.push(Value::Object(node));
        self.roots.push(self.nodes.len() - 1);
        Ok(())
    }

    /// One node with a matrix, or a parent and child pair when the transform has shear.
    fn write_matrix_node(&mut self, mesh: usize, world: &Affine3A) {
        let matrix = |a: &Affine3A| numbers(&Mat4::from(*a).to_cols_array());
        if decompose_trs(world).is_some() {
            self.nodes
                .push(json!({ "mesh": mesh, "matrix": matrix(world) }));
            self.roots.push(self.nodes.len() - 1);
        } else if let Some((parent, child)) = decompose_svd(world) {
            self.nodes.push(json!({
                "mesh": mesh,
                "matrix": matrix(&Affine3A::from_quat(child)),
            }));
            let child_index = self.nodes.len() - 1;
            self.nodes.push(json!({
                "matrix": matrix(&parent.to_affine()),
                "children": [child_index],
            }));
            self.roots.push(self.nodes.len() - 1);
        } else {
            // Shear with singular values past f32's range: no TRS pair can hold it, so keep the
            // matrix itself. The transform survives; a strict validator flags the node.
            self.nodes
                .push(json!({ "mesh": mesh, "matrix": matrix(world) }));
            self.roots.push(self.nodes.len() - 1);
        }
    }

    fn finish(mut self) -> Result<Vec<u8>, ExportError> {
        for pool in std::mem::take(&mut self.pools) {
            self.align_bin();
            let view = &mut self.buffer_views[pool.view];
            view["byteOffset"] = json!(self.bin.len());
            view["byteLength"] = json!(pool.bytes.len());
            self.bin.extend_from_slice(&pool.bytes);
        }
        self.align_bin();
        let mut buffers = Vec::new();
        if !self.bin.is_empty() {
            buffers.push(json!({ "byteLength": self.bin.len() }));
        }
        if self.fallback_len > 0 {
            self.extensions_used.insert("EXT_meshopt_compression");
            self.extensions_required.insert("EXT_meshopt_compression");
            buffers.push(json!({
                "byteLength": self.fallback_len,
                "extensions": {"EXT_meshopt_compression": {"fallback": true}},
            }));
        }
        if (self.compress && !self.meshes.is_empty()) || self.quantized {
            self.extensions_used.insert("KHR_mesh_quantization");
            self.extensions_required.insert("KHR_mesh_quantization");
        }
        let mut doc = Map::new();
        doc.insert(
            "asset".into(),
            json!({"version": "2.0", "generator": "Horizon"}),
        );
        doc.insert("scene".into(), json!(0));
        doc.insert("scenes".into(), json!([{ "nodes": self.roots }]));
        let arrays = [
            ("nodes", self.nodes),
            ("meshes", self.meshes),
            ("materials", self.materials),
            ("textures", self.textures),
            ("images", self.images),
            ("samplers", self.samplers),
            ("accessors", self.accessors),
            ("bufferViews", self.buffer_views),
            ("buffers", buffers),
        ];
        for (name, values) in arrays {
            if !values.is_empty() {
                doc.insert(name.into(), Value::Array(values));
            }
        }
        if !self.extensions_used.is_empty() {
            doc.insert("extensionsUsed".into(), json!(self.extensions_used));
        }
        if !self.extensions_required.is_empty() {
            doc.insert("extensionsRequired".into(), json!(self.extensions_required));
        }
        let doc = Value::Object(doc);
        // serde_json writes a non-finite float as null; every number here is checked finite
        // upstream, and this keeps any miss from becoming a silently broken file.
        if contains_null(&doc) {
            return Err(ExportError::Encode(
                "a non-finite number reached the output".into(),
            ));
        }
        let json = serde_json::to_vec(&doc).map_err(|e| ExportError::Encode(e.to_string()))?;
        let total = json.len() as u64 + self.bin.len() as u64 + 28;
        if total > u64::from(u32::MAX) {
            return Err(ExportError::TooLarge(total));
        }
        let glb = gltf::Glb {
            header: gltf::binary::Header {
                magic: *b"glTF",
                version: 2,
                length: 0,
            },
            json: json.into(),
            bin: (!self.bin.is_empty()).then_some(self.bin.into()),
        };
        glb.to_vec().map_err(|e| ExportError::Encode(e.to_string()))
    }
}

/// An f32 as a JSON number in its shortest round-trip form ("0.15", not
/// "0.15000000596046448", which is what widening to f64 prints): a reader parsing the text as
/// f32 gets the same value back.
fn number(x: f32) -> Value {
    json!(x.to_string().parse::<f64>().unwrap_or(f64::from(x)))
}

/// [`number`] for each value, as a JSON array.
fn numbers(values: &[f32]) -> Value {
    Value::Array(values.iter().map(|&x| number(x)).collect())
}

fn contains_null(v: &Value) -> bool {
    match v {
        Value::Null => true,
        Value::Array(items) => items.iter().any(contains_null),
        Value::Object(map) => map.values().any(contains_null),
        _ => false,
    }
}

fn wrap_code(w: Wrap) -> u32 {
    match w {
        Wrap::Repeat => 10497,
        Wrap::MirroredRepeat => 33648,
        Wrap::ClampToEdge => 33071,
    }
}

/// Indices optimised for the vertex cache, and the vertex order optimised for fetch: returns
/// the new indices and, for each new vertex, its old index. Unused vertices are dropped.
///
/// The fetch order is first use in the optimised index stream, which is what
/// `meshopt_optimizeVertexFetchRemap` computes; it is done here because the `meshopt` crate's
/// wrapper (0.7) truncates the remap table to the used-vertex count, losing the entries of
/// higher-numbered vertices whenever some vertex is unused.
fn optimise_order(s: &Submesh) -> (Vec<u32>, Vec<u32>) {
    let n = s.positions.len();
    let mut indices = meshopt::optimize_vertex_cache(&s.indices, n);
    let mut remap = vec![u32::MAX; n];
    let mut order = Vec::new();
    for i in indices.iter_mut() {
        let slot = &mut remap[*i as usize];
        if *slot == u32::MAX {
            *slot = order.len() as u32;
            order.push(*i);
        }
        *i = *slot;
    }
    (indices, order)
}

/// Float vectors of any width, tightly packed; with `bounds`, min and max per component.
fn float_attribute<const N: usize>(
    values: impl Iterator<Item = [f32; N]>,
    bounds: bool,
) -> Attribute {
    let mut bytes = Vec::new();
    let mut lo = [f32::INFINITY; N];
    let mut hi = [f32::NEG_INFINITY; N];
    let mut count = 0;
    for v in values {
        for c in 0..N {
            bytes.extend_from_slice(&v[c].to_le_bytes());
            lo[c] = lo[c].min(v[c]);
            hi[c] = hi[c].max(v[c]);
        }
        count += 1;
    }
    Attribute {
        bytes,
        stride: 4 * N,
        component_type: FLOAT,
        normalized: false,
        type_name: type_name(N),
        count,
        bounds: (bounds && count > 0).then(|| (lo.to_vec(), hi.to_vec())),
    }
}

/// The attribute `get` finds in each of `parts`, each part's vertices in its order, one part
/// after another; `None` when the first part lacks it (all parts share one layout).
fn concatenated<'p, T: Copy + 'p>(
    parts: &'p [(&'p Submesh, &'p [u32])],
    get: impl Fn(&'p Submesh) -> Option<&'p Vec<T>> + Copy + 'p,
) -> Option<impl Iterator<Item = T> + 'p> {
    get(parts.first()?.0)?;
    Some(parts.iter().flat_map(move |&(m, order)| {
        let values = get(m).expect("the parts share one layout");
        order.iter().map(move |&v| values[v as usize])
    }))
}

/// Whether a UV lies in [0, 1]^2, where 16-bit normalized integers can hold it.
fn in_unit_square(t: glam::Vec2) -> bool {
    t.cmpge(glam::Vec2::ZERO).all() && t.cmple(glam::Vec2::ONE).all()
}

/// Unit vectors as signed normalized bytes, padded to 4 bytes per element.
fn snorm8_attribute(values: impl Iterator<Item = [f32; 3]>) -> Attribute {
    let mut bytes = Vec::new();
    let mut count = 0;
    for v in values {
        for x in v {
            bytes.push(meshopt::quantize_snorm(x, 8) as i8 as u8);
        }
        bytes.push(0);
        count += 1;
    }
    Attribute {
        bytes,
        stride: 4,
        component_type: BYTE,
        normalized: true,
        type_name: "VEC3",
        count,
        bounds: None,
    }
}

/// Values as normalized 16-bit integers (VEC2 or VEC4, already aligned): signed for values in
/// [-1, 1] (unit quaternions), unsigned for values in [0, 1] (UVs, colours).
fn norm16_attribute<const N: usize>(
    values: impl Iterator<Item = [f32; N]>,
    signed: bool,
) -> Attribute {
    let mut bytes = Vec::new();
    let mut count = 0;
    for v in values {
        for x in v {
            let code = if signed {
                snorm16(x) as u16
            } else {
                meshopt::quantize_unorm(x, 16) as u16
            };
            bytes.extend_from_slice(&code.to_le_bytes());
        }
        count += 1;
    }
    Attribute {
        bytes,
        stride: 2 * N,
        component_type: if signed { SHORT } else { UNSIGNED_SHORT },
        normalized: true,
        type_name: type_name(N),
        count,
        bounds: None,
    }
}

/// `x` in [-1, 1] as a signed normalized 16-bit integer, as instance rotations are stored.
fn snorm16(x: f32) -> i16 {
    meshopt::quantize_snorm(x, 16) as i16
}

/// A rotation as a reader decodes it from normalized 16-bit integers ([`norm16_attribute`]):
/// each component rounded to a multiple of 1/32767, the whole normalised again.
fn read_back_rotation(q: Quat) -> Quat {
    let round = |x: f32| f32::from(snorm16(x)) / 32767.0;
    let back = Vec4::new(round(q.x), round(q.y), round(q.z), round(q.w));
    back.try_normalize().map_or(q, Quat::from_vec4)
}

/// The 16-bit grid over the box of `positions`, one step for all axes so that the
/// dequantisation is a uniform scale (which a TRS node or instance can carry); with `short`,
/// the step rounded up to two significant digits ([`short_step`]).
fn grid(positions: impl Iterator<Item = Vec3>, short: bool) -> Dequantize {
    let mut bounds = Aabb::EMPTY;
    positions.for_each(|p| bounds.grow(p));
    if bounds.is_empty() {
        return Dequantize {
            offset: Vec3::ZERO,
            step: 1.0,
        };
    }
    let extent = (bounds.max - bounds.min).max_element();
    // A step below f32's normal range rounds positions past the grid's 65,535 steps (and
    // one of zero or infinity has no grid): such a box is stored on a step that fits nothing
    // (infinite), which `fits` refuses, so its positions stay float.
    let step = match extent / STEPS {
        step if step.is_normal() && short => short_step(step),
        step if step.is_normal() => step,
        _ if extent == 0.0 => 1.0,
        _ => f32::INFINITY,
    };
    Dequantize {
        offset: bounds.min,
        step,
    }
}

/// `positions` as unsigned 16-bit integers on grid `d` (see [`grid`]), each padded to 8 bytes.
fn quantized_attribute(positions: impl Iterator<Item = Vec3>, d: &Dequantize) -> Attribute {
    let mut bytes = Vec::new();
    let mut lo = [u16::MAX; 3];
    let mut hi = [0u16; 3];
    let mut count = 0;
    for p in positions {
        let q = ((p - d.offset) / d.step).round();
        for c in 0..3 {
            let x = q[c].clamp(0.0, STEPS) as u16;
            lo[c] = lo[c].min(x);
            hi[c] = hi[c].max(x);
            bytes.extend_from_slice(&x.to_le_bytes());
        }
        // Vertex attributes must start on 4-byte boundaries, so pad each element to 8 bytes.
        bytes.extend_from_slice(&[0, 0]);
        count += 1;
    }
    let bounds = (count > 0).then(|| {
        (
            lo.iter().map(|&x| f32::from(x)).collect(),
            hi.iter().map(|&x| f32::from(x)).collect(),
        )
    });
    Attribute {
        bytes,
        stride: 8,
        component_type: UNSIGNED_SHORT,
        normalized: false,
        type_name: "VEC3",
        count,
        bounds,
    }
}

/// The least number of two significant decimal digits at or above `step` (which it exceeds
/// by under a tenth): every GPU-instanced node of a quantized run carries the step as its
/// scale, and "0.000016" is a third of the JSON of "1.5259021896696422e-5".
fn short_step(step: f32) -> f32 {
    if !step.is_normal() {
        return step;
    }
    let exponent = step.log10().floor() as i32 - 1;
    let unit = 10f64.powi(exponent);
    let mut short = ((f64::from(step) / unit).ceil() * unit) as f32;
    // Rounding to f32 can land just under; the next f32 up is at or above.
    while short < step {
        short = f32::from_bits(short.to_bits() + 1);
    }
    if short.is_finite() {
        short
    } else {
        step
    }
}

fn type_name(n: usize) -> &'static str {
    match n {
        1 => "SCALAR",
        2 => "VEC2",
        3 => "VEC3",
        _ => "VEC4",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A submesh of `n` vertices spread over `[x, x + width]` on the x axis, with or without
    /// normals.
    fn strip(n: usize, x: f32, width: f32, normals: bool) -> Submesh {
        let positions: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(x + width * i as f32 / (n.max(2) - 1) as f32, 0.0, 0.0))
            .collect();
        Submesh {
            normals: normals.then(|| vec![Vec3::Z; n]),
            indices: (0..(n - n % 3) as u32).collect(),
            positions,
            ..Default::default()
        }
    }

    /// The runs as they were before quantized positions (format 10): one open run per layout,
    /// replaced when the next submesh would take it past the vertex limit.
    fn runs_of_format_10(submeshes: &[Submesh], share: bool) -> Vec<Vec<usize>> {
        let mut runs: Vec<Vec<usize>> = Vec::new();
        let mut open: BTreeMap<(bool, bool, bool), (usize, usize)> = BTreeMap::new();
        for (s, sub) in submeshes.iter().enumerate() {
            let n = sub.positions.len();
            let layout = (
                sub.normals.is_some(),
                sub.uvs.is_some(),
                sub.colors.is_some(),
            );
            match open.get_mut(&layout) {
                Some((run, count)) if share && *count + n <= RUN_VERTICES => {
                    *count += n;
                    runs[*run].push(s);
                }
                _ => {
                    runs.push(vec![s]);
                    if share && n <= RUN_VERTICES {
                        open.insert(layout, (runs.len() - 1, n));
                    }
                }
            }
        }
        runs
    }

    proptest! {
        #[test]
        fn without_a_reach_runs_are_what_they_were(
            parts in prop::collection::vec((0usize..40_000, any::<bool>()), 0..24),
            share in any::<bool>(),
        ) {
            let submeshes: Vec<Submesh> = parts
                .iter()
                .enumerate()
                .map(|(k, &(n, normals))| strip(n, k as f32, 1.0, normals))
                .collect();
            let (runs, run_of) = vertex_runs(&submeshes, share, None);
            prop_assert_eq!(&runs, &runs_of_format_10(&submeshes, share));
            for (s, &(run, at)) in run_of.iter().enumerate() {
                prop_assert_eq!(runs[run][at], s);
            }
        }
    }

    #[test]
    fn a_submesh_joins_a_run_only_within_every_members_reach() {
        // A tolerates a box of 3, B and C of 100. B's box stretches A's run to 6: past A's
        // reach though within B's own, so B opens a run of its own; C, beside A, rejoins A's
        // run, which stayed open beside B's.
        let submeshes = [
            strip(3, 0.0, 1.0, true),
            strip(3, 5.0, 1.0, true),
            strip(3, 1.5, 1.0, true),
        ];
        let (runs, _) = vertex_runs(&submeshes, true, Some(&[3.0, 100.0, 100.0]));
        assert_eq!(runs, vec![vec![0, 2], vec![1]]);
        // A submesh wider than its own reach keeps float positions wherever it goes: it
        // shares the float runs of its layout, whatever their boxes.
        let wide = [
            strip(3, 0.0, 10.0, true),
            strip(3, 500.0, 10.0, true),
            strip(3, 0.0, 1.0, true),
        ];
        let (runs, _) = vertex_runs(&wide, true, Some(&[1.0, 1.0, 100.0]));
        assert_eq!(runs, vec![vec![0, 1], vec![2]]);
    }

    #[test]
    fn short_steps_are_never_shorter_and_never_a_tenth_longer() {
        let mut step = 1.3e-30f32;
        // Up to boxes of 6.5e9 units (larger steps print as "1200000.0").
        while step < 1e5 {
            let short = short_step(step);
            assert!(
                short >= step && short <= step * 1.1 + f32::EPSILON * step,
                "{step} -> {short}"
            );
            // Two significant digits, as the JSON writes them: "0.000016", "1.3e-30".
            let text = number(short).to_string();
            assert!(text.len() <= 8, "{step} -> {text}");
            step *= 1.37;
        }
        assert_eq!(short_step(0.0), 0.0);
        assert_eq!(short_step(1e-42), 1e-42);
    }
}
