//! Import of glTF 2.0 (.glb, .gltf), PLY, OBJ and STL into an [`InstancedMesh`].
//!
//! Every importer treats its input as hostile: sizes are checked against [`Limits`] before
//! anything large is allocated, every reference and byte range is bounds-checked, and every
//! failure is an [`ImportError`] with a one-line message. Nothing here panics on bad input;
//! `fuzz/` holds the cargo-fuzz target that keeps it so.

mod buffers;
mod gltf;
mod images;
mod obj;
mod ply;
mod stl;
mod uri;

use std::path::Path;

use crate::error::ImportError;
use crate::model::InstancedMesh;

/// Size limits an import refuses to exceed, so that the upload service can turn away oversized
/// input before it costs memory or time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Bytes read or decompressed in all: the file, the buffers and images it references, and
    /// any EXT_meshopt_compression buffer views once decoded.
    pub max_bytes: u64,
    /// Triangles in the expanded mesh (every instance counted).
    pub max_triangles: u64,
    /// Instances, i.e. placements of submeshes.
    pub max_instances: u64,
    /// Distinct textures.
    pub max_textures: u64,
    /// Pixels over all textures (width times height, summed).
    pub max_texture_pixels: u64,
    /// The longer side of any one texture, in pixels (read from the image header, before any
    /// decode).
    pub max_texture_side: u64,
}

impl Default for Limits {
    /// Generous limits for a single user upload on a 24 GiB server: large enough for the
    /// paper's biggest aggregate models (about 2M expanded triangles) with a wide margin.
    fn default() -> Self {
        Self {
            max_bytes: 1 << 30,
            max_triangles: 200_000_000,
            max_instances: 10_000_000,
            max_textures: 4096,
            max_texture_pixels: 1 << 30,
            max_texture_side: 1 << 16,
        }
    }
}

impl Limits {
    /// No limits at all; for trusted, offline input.
    pub fn unlimited() -> Self {
        Self {
            max_bytes: u64::MAX,
            max_triangles: u64::MAX,
            max_instances: u64::MAX,
            max_textures: u64::MAX,
            max_texture_pixels: u64::MAX,
            max_texture_side: u64::MAX,
        }
    }

    /// Fails with [`ImportError::LimitExceeded`] when `value` is over `limit`.
    pub(crate) fn check(what: &'static str, value: u64, limit: u64) -> Result<(), ImportError> {
        if value > limit {
            Err(ImportError::LimitExceeded { what, value, limit })
        } else {
            Ok(())
        }
    }
}

/// How much of each image is checked at import.
/// What [`ImportError::LimitExceeded`] names when the input is over [`Limits::max_bytes`].
pub(crate) const BYTES: &str = "bytes read, including referenced files and decoded buffers";
/// ... over [`Limits::max_bytes`] for the file itself.
pub(crate) const FILE_BYTES: &str = "file size in bytes";
/// ... over [`Limits::max_triangles`].
pub(crate) const TRIANGLES: &str = "expanded triangle count";
/// ... over [`Limits::max_instances`].
pub(crate) const INSTANCES: &str = "instance count";
/// ... over [`Limits::max_textures`].
pub(crate) const TEXTURES: &str = "texture count";
/// ... over [`Limits::max_texture_pixels`].
pub(crate) const TEXTURE_PIXELS: &str = "texture pixels";
/// ... over [`Limits::max_texture_side`].
pub(crate) const TEXTURE_SIDE: &str = "texture side in pixels";

/// Which of the [`Limits`] an import exceeded (see [`ImportError::limit`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Limit {
    /// Bytes of the file or of what it references and decodes to.
    Bytes,
    /// Expanded triangles.
    Triangles,
    /// Instances (or the node visits that would make them).
    Instances,
    /// Texture count, pixels or side.
    Textures,
    /// A structural bound of the reader (vertex or element counts).
    Structure,
}

impl Limit {
    /// The limit a [`ImportError::LimitExceeded`] with this `what` belongs to.
    pub(crate) fn of(what: &str) -> Self {
        match what {
            BYTES | FILE_BYTES => Self::Bytes,
            TRIANGLES => Self::Triangles,
            INSTANCES => Self::Instances,
            w if w.starts_with("node visits") => Self::Instances,
            TEXTURES | TEXTURE_PIXELS | TEXTURE_SIDE => Self::Textures,
            _ => Self::Structure,
        }
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ImageCheck {
    /// Read only the header: format and size. Fast; a corrupt body is found only when the
    /// texture is decoded later.
    Header,
    /// Decode every image once and drop the pixels, so a corrupt image is refused at upload.
    #[default]
    Decode,
}

/// Options for every importer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ImportOptions {
    /// Size limits.
    pub limits: Limits,
    /// How thoroughly images are checked.
    pub images: ImageCheck,
}

impl ImportOptions {
    /// Trusted offline input: no limits, headers only.
    pub fn trusted() -> Self {
        Self {
            limits: Limits::unlimited(),
            images: ImageCheck::Header,
        }
    }
}

/// The file formats Horizon reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Binary glTF.
    Glb,
    /// JSON glTF, with data: URIs or files beside it.
    Gltf,
    /// Stanford PLY, ASCII or binary.
    Ply,
    /// Wavefront OBJ, with its MTL materials.
    Obj,
    /// STL, ASCII or binary.
    Stl,
}

impl Format {
    /// Guesses the format from the file name's extension, then from the first bytes.
    pub fn detect(path: Option<&Path>, bytes: &[u8]) -> Result<Self, ImportError> {
        let ext = path
            .and_then(|p| p.extension())
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("glb") => return Ok(Self::Glb),
            Some("gltf") => return Ok(Self::Gltf),
            Some("ply") => return Ok(Self::Ply),
            Some("obj") => return Ok(Self::Obj),
            Some("stl") => return Ok(Self::Stl),
            _ => {}
        }
        let head = trim_start(bytes);
        if bytes.starts_with(b"glTF") {
            Ok(Self::Glb)
        } else if head.starts_with(b"{") {
            Ok(Self::Gltf)
        } else if bytes.starts_with(b"ply") {
            Ok(Self::Ply)
        } else if head.starts_with(b"solid") || stl::looks_binary(bytes) {
            Ok(Self::Stl)
        } else if head.starts_with(b"v ") || head.starts_with(b"#") || head.starts_with(b"o ") {
            Ok(Self::Obj)
        } else {
            Err(ImportError::UnknownFormat(match ext {
                Some(e) => format!("extension .{e} and unrecognised content"),
                None => "no extension and unrecognised content".into(),
            }))
        }
    }
}

/// An imported model and what the importer had to leave out.
#[derive(Clone, Debug, Default)]
pub struct Imported {
    /// The model.
    pub mesh: InstancedMesh,
    /// Primitives skipped because they are points or lines.
    pub skipped_non_triangle: u64,
    /// One-line notes about anything else dropped or repaired.
    pub warnings: Vec<String>,
}

/// Reads a model file, and for glTF the buffers and images beside it.
pub fn import_file(path: &Path, options: &ImportOptions) -> Result<Imported, ImportError> {
    let io_error = |reason| ImportError::Io {
        path: path.display().to_string(),
        reason,
    };
    let size = std::fs::metadata(path).map_err(io_error)?.len();
    Limits::check(FILE_BYTES, size, options.limits.max_bytes)?;
    let bytes = std::fs::read(path).map_err(io_error)?;
    let format = Format::detect(Some(path), &bytes)?;
    let base = path.parent().unwrap_or(Path::new("."));
    import_bytes(&bytes, format, Some(base), options)
}

/// Reads a model from memory. `base_dir` is the folder relative URIs resolve against; without
/// one, only self-contained files (GLB, or glTF with data: URIs) can be read.
pub fn import_bytes(
    bytes: &[u8],
    format: Format,
    base_dir: Option<&Path>,
    options: &ImportOptions,
) -> Result<Imported, ImportError> {
    Limits::check(FILE_BYTES, bytes.len() as u64, options.limits.max_bytes)?;
    let imported = match format {
        Format::Glb | Format::Gltf => gltf::import(bytes, base_dir, options)?,
        Format::Ply => ply::import(bytes, options)?,
        Format::Obj => obj::import(bytes, base_dir, options)?,
        Format::Stl => stl::import(bytes, options)?,
    };
    check_totals(&imported.mesh, &options.limits)?;
    imported.mesh.validate()?;
    Ok(imported)
}

/// Checks the limits that only the finished model can tell.
fn check_totals(mesh: &InstancedMesh, limits: &Limits) -> Result<(), ImportError> {
    Limits::check(INSTANCES, mesh.instances.len() as u64, limits.max_instances)?;
    Limits::check(
        TRIANGLES,
        mesh.expanded_triangle_count(),
        limits.max_triangles,
    )?;
    Limits::check(TEXTURES, mesh.textures.len() as u64, limits.max_textures)?;
    let pixels: u64 = mesh
        .textures
        .iter()
        .map(|t| u64::from(t.size.0) * u64::from(t.size.1))
        .sum();
    Limits::check("texture pixels", pixels, limits.max_texture_pixels)
}

fn trim_start(bytes: &[u8]) -> &[u8] {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let start = bytes
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(bytes.len());
    &bytes[start..]
}

/// Removes vertices no triangle uses and renumbers the indices, keeping vertex order.
/// Returns the old index of each kept vertex. Costs O(vertices + indices) through a table
/// when the indices cover a good part of the vertices, and O(indices log indices) when a few
/// indices name part of a large shared accessor (as each primitive of an aggregate does).
pub(crate) fn compact_vertices(indices: &mut [u32], vertex_count: usize) -> Vec<u32> {
    if vertex_count / 8 > indices.len() {
        let mut kept = indices.to_vec();
        kept.sort_unstable();
        kept.dedup();
        for i in indices.iter_mut() {
            // Every index is in `kept`, which is sorted.
            *i = kept.partition_point(|&k| k < *i) as u32;
        }
        return kept;
    }
    let mut remap = vec![u32::MAX; vertex_count];
    let mut kept = Vec::new();
    for &i in indices.iter() {
        let slot = &mut remap[i as usize];
        if *slot == u32::MAX {
            *slot = 0;
        }
    }
    for (old, slot) in remap.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = kept.len() as u32;
            kept.push(old as u32);
        }
    }
    for i in indices.iter_mut() {
        *i = remap[*i as usize];
    }
    kept
}

/// Picks the entries of `values` at `kept`.
pub(crate) fn gather<T: Copy>(values: &[T], kept: &[u32]) -> Vec<T> {
    kept.iter().map(|&k| values[k as usize]).collect()
}

#[cfg(test)]
mod tests {
    use super::compact_vertices;
    use proptest::prelude::*;

    proptest! {
        /// Both ways of compacting (the table, and sorting for few indices into many vertices)
        /// keep exactly the used vertices in their order and renumber the indices to match.
        #[test]
        fn compaction_keeps_the_used_vertices_in_order(
            vertex_count in 1usize..2000,
            picks in prop::collection::vec(any::<u32>(), 0..300),
        ) {
            let indices: Vec<u32> = picks.iter().map(|&p| p % vertex_count as u32).collect();
            let mut renumbered = indices.clone();
            let kept = compact_vertices(&mut renumbered, vertex_count);
            let mut used = indices.clone();
            used.sort_unstable();
            used.dedup();
            prop_assert_eq!(&kept, &used);
            for (new, old) in renumbered.iter().zip(&indices) {
                prop_assert_eq!(kept[*new as usize], *old);
            }
        }
    }
}
