//! Wavefront OBJ import with MTL materials, through the `tobj` crate. Each OBJ object (or
//! material group) becomes one submesh placed once. A material's diffuse colour and dissolve
//! become the base colour factor, and its diffuse map the base colour texture, read under the
//! same URI rules as glTF (inside the model's folder only).

use std::cell::Cell;
use std::io::BufReader;
use std::path::Path;

use glam::{Vec2, Vec3, Vec4};

use super::{images, uri, ImportOptions, Imported, Limits};
use crate::error::ImportError;
use crate::model::{AlphaMode, Instance, InstancedMesh, Material, Submesh, TextureRef, Wrap};

pub(crate) fn import(
    bytes: &[u8],
    base_dir: Option<&Path>,
    options: &ImportOptions,
) -> Result<Imported, ImportError> {
    let budget = Cell::new(options.limits.max_bytes.saturating_sub(bytes.len() as u64));
    let parse_error = |e: tobj::LoadError| ImportError::Parse {
        format: "OBJ",
        reason: e.to_string(),
    };
    // Stage 1: geometry, triangulated and indexed once for all attributes.
    let load = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    // The MTL loader can only answer tobj with tobj's errors; keep ours to report it instead.
    let refused: Cell<Option<ImportError>> = Cell::new(None);
    let (models, materials) =
        tobj::load_obj_buf(&mut BufReader::new(bytes), &load, |mtl: &Path| {
            let mut left = budget.get();
            let result = mtl
                .to_str()
                .ok_or(ImportError::ForbiddenUri {
                    uri: mtl.display().to_string(),
                    reason: "not valid UTF-8",
                })
                .and_then(|name| uri::resolve(name, base_dir, &mut left));
            budget.set(left);
            match result {
                Ok(r) => tobj::load_mtl_buf(&mut BufReader::new(&r.bytes[..])),
                Err(e) => {
                    refused.set(Some(e));
                    Err(tobj::LoadError::OpenFileFailed)
                }
            }
        })
        .map_err(parse_error)?;
    if let Some(e) = refused.take() {
        return Err(e);
    }
    // A missing or unreadable MTL file leaves the geometry usable; say so and go on.
    let mut warnings = Vec::new();
    let materials = materials.unwrap_or_else(|e| {
        warnings.push(format!("materials not loaded: {e}"));
        Vec::new()
    });
    // Stage 2: materials and their diffuse textures.
    let mut mesh = InstancedMesh::default();
    let mut pixel_budget = options.limits.max_texture_pixels;
    for m in &materials {
        let [r, g, b] = m.diffuse.unwrap_or([1.0; 3]);
        let alpha = m.dissolve.unwrap_or(1.0);
        let base_color_texture = match &m.diffuse_texture {
            None => None,
            Some(name) => {
                let mut left = budget.get();
                let bytes = uri::resolve(name, base_dir, &mut left)?.bytes;
                budget.set(left);
                let texture = images::checked_texture(
                    name,
                    bytes,
                    None,
                    (Wrap::Repeat, Wrap::Repeat),
                    options.images,
                    options.limits.max_texture_side,
                    &mut pixel_budget,
                )?;
                mesh.textures.push(texture);
                Limits::check(
                    super::TEXTURES,
                    mesh.textures.len() as u64,
                    options.limits.max_textures,
                )?;
                Some(TextureRef {
                    texture: mesh.textures.len() - 1,
                    transform: None,
                })
            }
        };
        mesh.materials.push(Material {
            name: Some(m.name.clone()),
            base_color_factor: Vec4::new(r, g, b, alpha),
            base_color_texture,
            // OBJ describes dielectric (Phong) surfaces.
            metallic_factor: 0.0,
            roughness_factor: 1.0,
            alpha_mode: if alpha < 1.0 {
                AlphaMode::Blend
            } else {
                AlphaMode::Opaque
            },
            double_sided: false,
        });
    }
    // Stage 3: one submesh per model, placed once.
    for model in models {
        let m = model.mesh;
        let n = m.positions.len() / 3;
        let positions: Vec<Vec3> = m.positions.chunks_exact(3).map(Vec3::from_slice).collect();
        if positions.iter().any(|p| !p.is_finite()) {
            return Err(ImportError::NonFinite(format!(
                "OBJ {} positions",
                model.name
            )));
        }
        let normals = (m.normals.len() == 3 * n && n > 0)
            .then(|| m.normals.chunks_exact(3).map(Vec3::from_slice).collect());
        // OBJ's V axis points up; glTF's points down.
        let uvs = (m.texcoords.len() == 2 * n && n > 0).then(|| {
            m.texcoords
                .chunks_exact(2)
                .map(|t| Vec2::new(t[0], 1.0 - t[1]))
                .collect()
        });
        let colors = (m.vertex_color.len() == 3 * n && n > 0).then(|| {
            m.vertex_color
                .chunks_exact(3)
                .map(|c| Vec3::from_slice(c).extend(1.0))
                .collect()
        });
        if let Some(&bad) = m.indices.iter().find(|&&i| i as usize >= n) {
            return Err(ImportError::IndexOutOfRange {
                what: format!("OBJ {}", model.name),
                index: u64::from(bad),
                vertices: n,
            });
        }
        let material = m.material_id.filter(|&id| id < mesh.materials.len());
        let mut submesh = Submesh {
            positions,
            normals,
            uvs,
            colors,
            indices: m.indices[..m.indices.len() / 3 * 3].to_vec(),
            material,
        };
        super::stl::compact_submesh(&mut submesh);
        mesh.submeshes.push(submesh);
        mesh.instances.push(Instance {
            submesh: mesh.submeshes.len() - 1,
            transform: glam::Affine3A::IDENTITY,
        });
    }
    Ok(Imported {
        mesh,
        skipped_non_triangle: 0,
        warnings,
    })
}
