//! Assembly of a generated model in the instanced mesh form of the IAS paper (Azim et al. 2014,
//! section 6.2): textures, materials and submeshes stored once, instances placing them.

use glam::{Affine3A, Quat, Vec3, Vec4};
use horizon_mesh::{AlphaMode, Instance, InstancedMesh, Material, Texture, TextureRef};

use crate::shapes::MeshBuilder;
use crate::{GeneratedModel, SubmeshInfo};

/// Collects the parts of a model and hands out their indices.
#[derive(Debug, Default)]
pub struct ModelBuilder {
    mesh: InstancedMesh,
    info: Vec<SubmeshInfo>,
}

impl ModelBuilder {
    /// An empty model.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a texture; returns its index.
    pub fn texture(&mut self, texture: Texture) -> usize {
        self.mesh.textures.push(texture);
        self.mesh.textures.len() - 1
    }

    /// Adds a material; returns its index.
    pub fn material(&mut self, material: Material) -> usize {
        self.mesh.materials.push(material);
        self.mesh.materials.len() - 1
    }

    /// Adds a submesh built from `geometry` with `material`; `closed` declares it watertight.
    /// Returns its index.
    pub fn submesh(
        &mut self,
        name: impl Into<String>,
        closed: bool,
        geometry: MeshBuilder,
        material: usize,
    ) -> usize {
        self.mesh.submeshes.push(geometry.into_submesh(material));
        self.info.push(SubmeshInfo {
            name: name.into(),
            closed,
        });
        self.mesh.submeshes.len() - 1
    }

    /// Places `submesh` with `transform`.
    pub fn place(&mut self, submesh: usize, transform: Affine3A) {
        self.mesh.instances.push(Instance { submesh, transform });
    }

    /// Triangles of a submesh added so far.
    pub fn triangles_of(&self, submesh: usize) -> u64 {
        self.mesh.submeshes[submesh].triangle_count()
    }

    /// Instances placed so far.
    pub fn instance_count(&self) -> usize {
        self.mesh.instances.len()
    }

    /// Expanded triangles placed so far.
    pub fn expanded_triangle_count(&self) -> u64 {
        self.mesh.expanded_triangle_count()
    }

    /// The finished model.
    pub fn finish(self) -> GeneratedModel {
        GeneratedModel {
            mesh: self.mesh,
            submeshes: self.info,
        }
    }
}

/// A dielectric material with a base colour texture multiplied by `tint`.
pub fn textured(name: &str, texture: usize, tint: Vec4, roughness: f32) -> Material {
    Material {
        name: Some(name.to_owned()),
        base_color_factor: tint,
        base_color_texture: Some(TextureRef {
            texture,
            transform: None,
        }),
        metallic_factor: 0.0,
        roughness_factor: roughness,
        alpha_mode: AlphaMode::Opaque,
        double_sided: false,
    }
}

/// An untextured dielectric material of one colour (vertex colours, if any, multiply it).
pub fn plain(name: &str, colour: Vec4, roughness: f32) -> Material {
    Material {
        name: Some(name.to_owned()),
        base_color_factor: colour,
        base_color_texture: None,
        metallic_factor: 0.0,
        roughness_factor: roughness,
        alpha_mode: AlphaMode::Opaque,
        double_sided: false,
    }
}

/// The same material drawn from both sides (for open sheets: leaves, grass).
pub fn double_sided(material: Material) -> Material {
    Material {
        double_sided: true,
        ..material
    }
}

/// `T * R * S`: scale (possibly negative on one axis, a mirror), then rotate, then translate.
pub fn trs(translation: Vec3, rotation: Quat, scale: Vec3) -> Affine3A {
    Affine3A::from_scale_rotation_translation(scale, rotation, translation)
}

/// A linear RGBA colour from sRGB components in `[0, 1]`, opaque.
pub fn srgb(r: f32, g: f32, b: f32) -> Vec4 {
    let linear = |c: f32| {
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    Vec4::new(linear(r), linear(g), linear(b), 1.0)
}
