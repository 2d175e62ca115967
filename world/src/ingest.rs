//! Ingest: how a model enters a world. Import (untrusted bytes, under [`UploadLimits`]) ->
//! validate -> normalise (the stored form, a plain GLB named by its content hash) -> describe
//! (the similarity descriptors the BVH and dedup compare, with the model's bounding sphere)
//! and level (its chain of coarser levels of detail, `horizon_levels`).
//!
//! An upload is glTF (binary, or JSON with embedded buffers) and nothing else: it is read with
//! no folder to resolve relative URIs against, so an external or `file:` reference is refused
//! and nothing outside the bytes is ever read. Texture sizes are checked from the image headers
//! before any decode.

use std::path::Path;

use horizon_descriptors::{describe, DescriptorOptions};
use horizon_levels::{build_chain, level_zero, Chain, LevelInfo, LevelOptions};
use horizon_mesh::{
    export_glb, import_bytes, import_file, ExportOptions, Format, ImageCheck, ImportError,
    ImportOptions, InstancedMesh, Limit, Limits, MeshStats,
};

use crate::error::{BadModel, WorldError};
use crate::store::ModelDescriptors;

/// What an upload may be.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UploadLimits {
    /// Bytes of the upload. Default 64 MiB.
    pub max_bytes: u64,
    /// Expanded triangles. Default 4M.
    pub max_triangles: u64,
    /// Placements of submeshes. Default 100,000.
    pub max_instances: u64,
    /// The longer side of any texture, pixels. Default 8,192.
    pub max_texture_side: u64,
    /// Pixels over all textures. Default 64M.
    pub max_texture_pixels: u64,
}

impl Default for UploadLimits {
    fn default() -> Self {
        Self {
            max_bytes: 64 << 20,
            max_triangles: 4_000_000,
            max_instances: 100_000,
            max_texture_side: 8192,
            max_texture_pixels: 64 << 20,
        }
    }
}

/// A model imported and checked: valid, and with some geometry.
#[derive(Debug)]
pub struct IngestedModel {
    /// The model.
    pub mesh: InstancedMesh,
    /// What the importer skipped or repaired, for the user.
    pub warnings: Vec<String>,
}

/// Imports uploaded bytes (GLB, or glTF JSON with embedded buffers) under `limits`.
pub fn import_upload(bytes: &[u8], limits: &UploadLimits) -> Result<IngestedModel, WorldError> {
    let malformed = |reason: String| WorldError::BadModel {
        kind: BadModel::Malformed,
        reason,
    };
    if bytes.len() as u64 > limits.max_bytes {
        return Err(WorldError::BadModel {
            kind: BadModel::TooLarge,
            reason: format!(
                "the model is {} bytes, over the limit of {}",
                bytes.len(),
                limits.max_bytes
            ),
        });
    }
    let format = match Format::detect(None, bytes) {
        Ok(f @ (Format::Glb | Format::Gltf)) => f,
        _ => return Err(malformed("the body is neither GLB nor glTF JSON".into())),
    };
    let options = ImportOptions {
        limits: Limits {
            max_bytes: limits.max_bytes,
            max_triangles: limits.max_triangles,
            max_instances: limits.max_instances,
            max_textures: 4096,
            max_texture_pixels: limits.max_texture_pixels,
            max_texture_side: limits.max_texture_side,
        },
        images: ImageCheck::Header,
    };
    let imported = import_bytes(bytes, format, None, &options).map_err(upload_error)?;
    checked(imported.mesh, imported.warnings, "the model").map_err(|e| match e {
        WorldError::Model { reason, .. } => malformed(reason),
        other => other,
    })
}

/// Imports a model file (glTF, GLB, PLY, OBJ or STL) from a trusted folder, and validates it.
pub fn import_model(path: &Path) -> Result<IngestedModel, WorldError> {
    let name = path.display().to_string();
    let imported =
        import_file(path, &ImportOptions::default()).map_err(|e| WorldError::model(&name, e))?;
    checked(imported.mesh, imported.warnings, &name)
}

/// `mesh` if it is valid and has some geometry.
fn checked(
    mesh: InstancedMesh,
    warnings: Vec<String>,
    name: &str,
) -> Result<IngestedModel, WorldError> {
    mesh.validate().map_err(|e| WorldError::model(name, e))?;
    if mesh.bounds().is_empty() {
        return Err(WorldError::model(name, "it has no geometry"));
    }
    Ok(IngestedModel { mesh, warnings })
}

/// An import error as the upload rule it broke.
fn upload_error(e: ImportError) -> WorldError {
    let kind = match e.limit() {
        Some(Limit::Bytes) => BadModel::TooLarge,
        Some(Limit::Triangles) => BadModel::TooManyTriangles,
        Some(Limit::Instances) => BadModel::TooManyInstances,
        Some(Limit::Textures) => BadModel::TextureTooLarge,
        Some(Limit::Structure) | None => BadModel::Malformed,
    };
    WorldError::BadModel {
        kind,
        reason: e.to_string(),
    }
}

/// The stored form of a model: a plain GLB (no compression, lossless).
pub fn normalise(name: &str, mesh: &InstancedMesh) -> Result<Vec<u8>, WorldError> {
    export_glb(mesh, &ExportOptions::plain()).map_err(|e| WorldError::model(name, e))
}

/// What a model holds, for its metadata.
pub fn stats(mesh: &InstancedMesh) -> serde_json::Value {
    serde_json::to_value(MeshStats::of(mesh)).unwrap_or(serde_json::Value::Null)
}

/// A stored model read back from its GLB bytes: what descriptors and levels are computed
/// from, so that a world built from its blobs alone gets the same numbers.
pub fn read_stored(name: &str, glb: &[u8]) -> Result<InstancedMesh, WorldError> {
    Ok(
        import_bytes(glb, Format::Glb, None, &ImportOptions::trusted())
            .map_err(|e| WorldError::model(name, e))?
            .mesh,
    )
}

/// The descriptors and local bounding sphere of a stored model ([`read_stored`]).
pub fn describe_stored(name: &str, glb: &[u8]) -> Result<ModelDescriptors, WorldError> {
    describe_read(name, &read_stored(name, glb)?)
}

/// The descriptors and local bounding sphere of `mesh`, a stored model read back.
pub fn describe_read(name: &str, mesh: &InstancedMesh) -> Result<ModelDescriptors, WorldError> {
    let d = describe(mesh, &DescriptorOptions::default())
        .map_err(|e| WorldError::model(name, e))?
        .descriptors;
    let b = mesh.bounds();
    Ok(ModelDescriptors {
        zernike: d.zernike,
        csd: d.csd,
        centre: ((b.min + b.max) * 0.5).to_array(),
        radius: (b.max - b.min).length() * 0.5,
    })
}

/// A stored model's levels of detail ([`read_stored`]): level 0 (the stored GLB, `glb`) and
/// the coarser chain (`horizon_levels`).
pub fn level_stored(name: &str, glb: &[u8]) -> Result<(LevelInfo, Chain), WorldError> {
    Ok(level_read(&read_stored(name, glb)?, glb.len() as u64))
}

/// The levels of detail of `mesh`, a stored model of `bytes` read back.
pub fn level_read(mesh: &InstancedMesh, bytes: u64) -> (LevelInfo, Chain) {
    let chain = build_chain(mesh, bytes, &LevelOptions::default());
    (level_zero(mesh, bytes), chain)
}
