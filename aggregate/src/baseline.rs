//! The unoptimised aggregates the report compares with: no dedup, the children expanded into
//! one world-space mesh, classic QEM to the same triangle budget, no atlas. Handoffs are
//! whole world-space meshes, read back from parts files rather than held a level at a time.
//! Built only with the `baseline` feature, which the product never enables.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

use horizon_mesh::{Instance, InstancedMesh, Submesh};
use horizon_simplify::{simplify_qem, SimplifyOptions, Target};

use crate::error::AggregateError;
use crate::generate::{
    finish, load_models, ExpandedPart, Handoff, Merger, NodeInput, NodeOutput, NodeStats,
};
use crate::options::AggregateOptions;
use crate::source::ModelSource;
use crate::store::AggregateEntry;

/// The unoptimised baseline: children expanded into one mesh, QEM to the same budget.
pub(crate) fn generate_unoptimized(
    input: &NodeInput,
    models: &dyn ModelSource,
    options: &AggregateOptions,
) -> Result<NodeOutput, AggregateError> {
    let start = Instant::now();
    let mut stats = NodeStats {
        placements: input.placements.len(),
        budget: input.display.triangle_budget(options),
        ..NodeStats::default()
    };
    let mut merge = Merger::default();
    if input.children.is_empty() {
        let sources = load_models(input.placements.iter().map(|p| p.model), models)?;
        stats.models = sources.len();
        for p in &input.placements {
            let source = &sources[&p.model];
            for (s, inner) in source.placements.iter().enumerate() {
                let index = merge.submesh(p.model, source, source.mesh.submeshes[s].clone());
                for m in inner {
                    merge.mesh.instances.push(Instance {
                        submesh: index,
                        transform: p.transform * *m,
                    });
                }
            }
        }
    } else {
        for child in &input.children {
            let Handoff::Expanded(part) = child.as_ref() else {
                continue;
            };
            merge.expanded(part, models)?;
        }
    }
    let material_keys = merge.material_keys.clone();
    let merged = merge.mesh;
    stats.triangles_in = merged.expanded_triangle_count();
    let target = Target::Triangles(stats.budget.min(stats.triangles_in));
    let result = simplify_qem(&merged, target, &SimplifyOptions::default()).map_err(|source| {
        AggregateError::Simplify {
            node: input.node,
            source,
        }
    })?;
    stats.error = result.report.error;
    stats.error_pixels = input.display.pixels_of_length(result.report.error);
    let simplified = result.mesh;
    // The parent takes materials and textures from the source models (`material_keys`):
    // the handoff keeps geometry only.
    let handoff = Handoff::Expanded(Arc::new(ExpandedPart {
        mesh: InstancedMesh {
            submeshes: simplified.submeshes.clone(),
            instances: simplified.instances.clone(),
            materials: Vec::new(),
            textures: Vec::new(),
        },
        material_keys,
    }));
    let mut out = finish(input, simplified, handoff, stats)?;
    out.stats.seconds = start.elapsed().as_secs_f64();
    Ok(out)
}

/// A baseline handoff read back from its parts file: its world-space submeshes, each
/// material named by its source (model, material index) in the entry's part list.
pub(crate) fn decode_expanded(
    mesh: InstancedMesh,
    entry: &AggregateEntry,
    models: &dyn ModelSource,
) -> Option<Handoff> {
    let mut material_keys: Vec<(u64, usize)> = Vec::new();
    let mut index: HashMap<(u64, usize), usize> = HashMap::new();
    let mut submeshes = Vec::with_capacity(mesh.submeshes.len());
    for (sub, (hash, m)) in mesh.submeshes.into_iter().zip(&entry.part_keys) {
        let material = if hash.is_empty() {
            None
        } else {
            let key = (models.by_hash(hash)?, *m as usize);
            Some(*index.entry(key).or_insert_with(|| {
                material_keys.push(key);
                material_keys.len() - 1
            }))
        };
        submeshes.push(Submesh { material, ..sub });
    }
    Some(Handoff::Expanded(Arc::new(ExpandedPart {
        mesh: InstancedMesh {
            submeshes,
            instances: mesh.instances,
            materials: Vec::new(),
            textures: Vec::new(),
        },
        material_keys,
    })))
}

impl Merger {
    /// Appends a child's expanded baseline mesh, sharing materials by source: each material
    /// (and its texture) comes from the source model it names, as a leaf takes it, so no
    /// handoff carries texture bytes.
    fn expanded(
        &mut self,
        part: &ExpandedPart,
        models: &dyn ModelSource,
    ) -> Result<(), AggregateError> {
        let base = self.mesh.submeshes.len();
        for sub in &part.mesh.submeshes {
            let mut sub = sub.clone();
            sub.material = match sub.material.and_then(|m| part.material_keys.get(m)) {
                Some(&(model, source_m)) => {
                    let source = models.model(model)?;
                    self.material(model, source_m, &source.mesh)
                }
                None => None,
            };
            self.mesh.submeshes.push(sub);
        }
        for inst in &part.mesh.instances {
            self.mesh.instances.push(Instance {
                submesh: base + inst.submesh,
                transform: inst.transform,
            });
        }
        Ok(())
    }
}
