//! GLB export of an instanced mesh (glTF 2.0; EXT_mesh_gpu_instancing, KHR_mesh_quantization,
//! EXT_meshopt_compression, KHR_texture_transform).
//!
//! [`export_glb`] fills one writer (`writer.rs`) in five stages:
//! 1. refuse an invalid mesh, and leave out submeshes without triangles (they draw nothing,
//!    and glTF has no empty accessor);
//! 2. geometry (`geometry.rs`): one glTF mesh per submesh, its vertices in a run of their own
//!    or shared with other submeshes of its layout (`vertex_runs.rs`), positions float or
//!    16-bit on the run's grid and other attributes float or normalized integers
//!    (`quantize.rs`), every stream meshopt-encoded when compressing (`compression.rs`);
//! 3. textures, images, samplers and materials (`textures.rs`);
//! 4. nodes (`instancing.rs`): one GPU-instanced node where every instance of a submesh is
//!    TRS, else a node with a matrix per instance, each mapping the stored positions back
//!    through its run's dequantisation;
//! 5. the JSON document and the GLB container (`writer.rs`).
//!
//! [`ExportOptions`] (`options.rs`) chooses between plain floats, compression, and the shared
//! runs and short attributes of aggregates. Shared by several stages: accessor data
//! (`attributes.rs`) and JSON numbers (`json.rs`).

mod attributes;
mod compression;
mod geometry;
mod instancing;
mod json;
mod options;
mod quantize;
mod textures;
mod vertex_runs;
mod writer;

use glam::Affine3A;

pub use options::ExportOptions;

use self::geometry::SharedRun;
use self::quantize::Dequantize;
use self::vertex_runs::vertex_runs;
use self::writer::GlbWriter;
use crate::error::ExportError;
use crate::model::{InstancedMesh, Submesh};

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
