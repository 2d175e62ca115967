//! Ingest: how a model enters a world. Import (untrusted bytes, bounded by
//! [`ImportOptions::default`]'s limits) -> validate -> normalise (the stored form, a plain GLB,
//! named by its content hash) -> describe (the similarity descriptors the BVH and dedup
//! compare, with the model's bounding sphere).
//!
//! Descriptors are computed from the stored GLB read back, not from the mesh in hand, so that
//! a world built from its directory alone gets the same numbers.

use std::path::Path;

use horizon_descriptors::{describe, DescriptorOptions};
use horizon_mesh::{export_glb, import_file, ExportOptions, ImportOptions, InstancedMesh};

use crate::dir::ModelDescriptors;
use crate::error::WorldError;

/// A model imported from a file and checked: valid, and with some geometry.
#[derive(Debug)]
pub struct IngestedModel {
    /// The model.
    pub mesh: InstancedMesh,
    /// What the importer skipped or repaired, for the user.
    pub warnings: Vec<String>,
}

/// Imports a model file (glTF, GLB, PLY, OBJ or STL) and validates it.
pub fn import_model(path: &Path) -> Result<IngestedModel, WorldError> {
    let name = || path.display().to_string();
    let imported =
        import_file(path, &ImportOptions::default()).map_err(|e| WorldError::model(name(), e))?;
    imported
        .mesh
        .validate()
        .map_err(|e| WorldError::model(name(), e))?;
    if imported.mesh.bounds().is_empty() {
        return Err(WorldError::model(name(), "it has no geometry"));
    }
    Ok(IngestedModel {
        mesh: imported.mesh,
        warnings: imported.warnings,
    })
}

/// The stored form of a model: a plain GLB (no compression, lossless).
pub fn normalise(name: &str, mesh: &InstancedMesh) -> Result<Vec<u8>, WorldError> {
    export_glb(mesh, &ExportOptions::plain()).map_err(|e| WorldError::model(name, e))
}

/// The descriptors and local bounding sphere of a stored model, read back from its GLB.
pub fn describe_stored(path: &Path) -> Result<ModelDescriptors, WorldError> {
    let name = || path.display().to_string();
    let mesh = import_file(path, &ImportOptions::default())
        .map_err(|e| WorldError::model(name(), e))?
        .mesh;
    let d = describe(&mesh, &DescriptorOptions::default())
        .map_err(|e| WorldError::model(name(), e))?
        .descriptors;
    let b = mesh.bounds();
    Ok(ModelDescriptors {
        zernike: d.zernike,
        csd: d.csd,
        centre: ((b.min + b.max) * 0.5).to_array(),
        radius: (b.max - b.min).length() * 0.5,
    })
}
