//! The summary `horizon mesh stats` prints.

use serde::Serialize;

use crate::model::InstancedMesh;

/// Counts and bounds of an instanced mesh.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MeshStats {
    /// Distinct submeshes.
    pub submeshes: usize,
    /// Placements of submeshes.
    pub instances: usize,
    /// Triangles stored, each submesh once.
    pub triangles_unique: u64,
    /// Triangles drawn, each instance counted.
    pub triangles_expanded: u64,
    /// Materials.
    pub materials: usize,
    /// Textures.
    pub textures: usize,
    /// World-space bounds of the expanded mesh.
    pub bounds: BoundsStats,
}

/// An axis-aligned box as two corners; both are `null` in JSON for an empty mesh.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BoundsStats {
    /// Smallest corner.
    pub min: Option<[f32; 3]>,
    /// Largest corner.
    pub max: Option<[f32; 3]>,
}

impl MeshStats {
    /// Computes the summary.
    pub fn of(mesh: &InstancedMesh) -> Self {
        let b = mesh.bounds();
        let (min, max) = if b.is_empty() {
            (None, None)
        } else {
            (Some(b.min.to_array()), Some(b.max.to_array()))
        };
        Self {
            submeshes: mesh.submeshes.len(),
            instances: mesh.instances.len(),
            triangles_unique: mesh.unique_triangle_count(),
            triangles_expanded: mesh.expanded_triangle_count(),
            materials: mesh.materials.len(),
            textures: mesh.textures.len(),
            bounds: BoundsStats { min, max },
        }
    }
}
