//! Materials: the one a submesh draws with, and the one material of the atlased output.

use glam::Vec4;
use horizon_mesh::model::{AlphaMode, InstancedMesh, Material, Submesh, TextureRef};

/// The material of a submesh, with `None` meaning the glTF default material.
pub(crate) fn material_of<'a>(
    mesh: &'a InstancedMesh,
    sub: &Submesh,
    default: &'a Material,
) -> &'a Material {
    sub.material
        .and_then(|m| mesh.materials.get(m))
        .unwrap_or(default)
}

/// The one output material: factors baked (white), no UV transform, alpha mode strong enough for
/// every input (Blend > Mask > Opaque), double-sided if any input is, and the mean metallic and
/// roughness over the submeshes' materials (one vote per submesh).
pub(crate) fn merge_materials(mesh: &InstancedMesh) -> Material {
    let default = Material::default();
    let used: Vec<&Material> = mesh
        .submeshes
        .iter()
        .map(|s| material_of(mesh, s, &default))
        .collect();
    let n = used.len().max(1) as f32;
    let blend = used.iter().any(|m| m.alpha_mode == AlphaMode::Blend);
    let mask = used
        .iter()
        .any(|m| matches!(m.alpha_mode, AlphaMode::Mask { .. }));
    let alpha_mode = if blend {
        AlphaMode::Blend
    } else if mask {
        AlphaMode::Mask { cutoff: 0.5 }
    } else {
        AlphaMode::Opaque
    };
    Material {
        name: Some("atlas".to_string()),
        base_color_factor: Vec4::ONE,
        base_color_texture: Some(TextureRef {
            texture: 0,
            transform: None,
        }),
        metallic_factor: if used.is_empty() {
            0.0
        } else {
            used.iter().map(|m| m.metallic_factor).sum::<f32>() / n
        },
        roughness_factor: if used.is_empty() {
            1.0
        } else {
            used.iter().map(|m| m.roughness_factor).sum::<f32>() / n
        },
        alpha_mode,
        double_sided: used.iter().any(|m| m.double_sided),
    }
}
