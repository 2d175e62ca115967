//! The instanced mesh model of the core paper (Azim et al. 2014, section 6.2).
//!
//! An aggregate is a set of *submeshes*, each an indexed triangle list stored once, and a set of
//! *instances*, each placing one submesh in the world with an affine transform. The "expanded"
//! mesh is what a renderer draws: every instance's copy of its submesh. IAS simplifies the
//! submeshes while counting triangles in the expanded mesh.

use glam::{Affine3A, Vec2, Vec3, Vec4};

/// An instanced triangle mesh: submeshes stored once, placed many times.
///
/// Invariants (checked by [`InstancedMesh::validate`]):
/// - every index of every submesh is below that submesh's vertex count, and the index count is a
///   multiple of three;
/// - optional attribute arrays have exactly one entry per vertex;
/// - every instance names an existing submesh, every submesh's material exists, and every
///   material's texture exists;
/// - every position, attribute and transform is finite.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InstancedMesh {
    /// Geometry stored once per distinct primitive.
    pub submeshes: Vec<Submesh>,
    /// Placements of submeshes. The node hierarchy is already flattened: each transform is the
    /// product of every transform from the scene root down to the placed mesh.
    pub instances: Vec<Instance>,
    /// Materials referenced by submeshes.
    pub materials: Vec<Material>,
    /// Encoded images referenced by materials.
    pub textures: Vec<Texture>,
}

/// One indexed triangle list with per-vertex attributes and one material.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Submesh {
    /// Vertex positions in the submesh's own (model) space.
    pub positions: Vec<Vec3>,
    /// Per-vertex normals, if the source had them.
    pub normals: Option<Vec<Vec3>>,
    /// Per-vertex texture coordinates for the base colour texture (UV0).
    pub uvs: Option<Vec<Vec2>>,
    /// Per-vertex linear RGBA colours.
    pub colors: Option<Vec<Vec4>>,
    /// Triangle list: three indices per triangle, counter-clockwise front faces.
    pub indices: Vec<u32>,
    /// Index into [`InstancedMesh::materials`]; `None` means the glTF default material.
    pub material: Option<usize>,
}

/// One placement of a submesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// Index into [`InstancedMesh::submeshes`].
    pub submesh: usize,
    /// Model-to-world transform. A negative determinant mirrors the submesh; a renderer (and
    /// [`InstancedMesh::expand`]) then flips the winding so front faces stay front faces.
    pub transform: Affine3A,
}

/// How a material's alpha channel is interpreted (glTF `alphaMode`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum AlphaMode {
    /// Alpha is ignored.
    #[default]
    Opaque,
    /// Alpha below the cut-off is fully transparent, otherwise fully opaque.
    Mask {
        /// The cut-off (glTF `alphaCutoff`, default 0.5).
        cutoff: f32,
    },
    /// Alpha blends with what is behind.
    Blend,
}

/// A metallic-roughness material reduced to what aggregates need.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Optional human-readable name from the source.
    pub name: Option<String>,
    /// Linear RGBA multiplier of the base colour.
    pub base_color_factor: Vec4,
    /// Base colour texture, if any.
    pub base_color_texture: Option<TextureRef>,
    /// glTF `metallicFactor`; kept so that a re-exported material does not turn into metal.
    pub metallic_factor: f32,
    /// glTF `roughnessFactor`.
    pub roughness_factor: f32,
    /// How alpha is used.
    pub alpha_mode: AlphaMode,
    /// Whether back faces are drawn.
    pub double_sided: bool,
}

impl Default for Material {
    /// The glTF default material: white, fully metallic and rough, opaque, single-sided.
    fn default() -> Self {
        Self {
            name: None,
            base_color_factor: Vec4::ONE,
            base_color_texture: None,
            metallic_factor: 1.0,
            roughness_factor: 1.0,
            alpha_mode: AlphaMode::Opaque,
            double_sided: false,
        }
    }
}

/// A reference from a material to a texture, with its UV transform.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureRef {
    /// Index into [`InstancedMesh::textures`].
    pub texture: usize,
    /// KHR_texture_transform, applied to UV0 before sampling.
    pub transform: Option<UvTransform>,
}

/// KHR_texture_transform: `uv' = T(offset) * R(rotation) * S(scale) * uv`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    /// Translation in UV units.
    pub offset: Vec2,
    /// Counter-clockwise rotation in radians.
    pub rotation: f32,
    /// Scale along U and V.
    pub scale: Vec2,
}

impl UvTransform {
    /// Maps one texture coordinate through the transform.
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        let (s, c) = self.rotation.sin_cos();
        let scaled = uv * self.scale;
        // KHR_texture_transform's rotation matrix is [c s; -s c] in row-major order.
        Vec2::new(c * scaled.x + s * scaled.y, -s * scaled.x + c * scaled.y) + self.offset
    }
}

/// How a texture coordinate outside [0, 1] is folded back (glTF sampler wrap modes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    /// The texture tiles.
    #[default]
    Repeat,
    /// The texture tiles, mirrored every other tile.
    MirroredRepeat,
    /// Coordinates clamp to the edge.
    ClampToEdge,
}

/// An encoded image, decoded only on demand.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// The encoded bytes exactly as they came (PNG or JPEG).
    pub bytes: Vec<u8>,
    /// MIME type of `bytes`: `image/png` or `image/jpeg`.
    pub mime_type: String,
    /// Width and height in pixels, read from the image header at import.
    pub size: (u32, u32),
    /// Wrap mode along U.
    pub wrap_u: Wrap,
    /// Wrap mode along V.
    pub wrap_v: Wrap,
}

impl Texture {
    /// Decodes the image into RGBA8. This is the only place pixels are materialised.
    pub fn decode(&self) -> Result<image::RgbaImage, image::ImageError> {
        let format =
            image::ImageFormat::from_mime_type(&self.mime_type).unwrap_or(image::ImageFormat::Png);
        Ok(image::load_from_memory_with_format(&self.bytes, format)?.to_rgba8())
    }
}

/// An axis-aligned bounding box. An empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Vec3,
    /// Largest corner.
    pub max: Vec3,
}

impl Aabb {
    /// The empty box, identity for [`Aabb::grow`].
    pub const EMPTY: Self = Self {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// Whether the box contains no point.
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// Extends the box to contain `p`.
    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// The smallest box containing both.
    pub fn union(&self, other: &Self) -> Self {
        Self {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// Length of the diagonal; zero for an empty box.
    pub fn diagonal(&self) -> f32 {
        if self.is_empty() {
            0.0
        } else {
            (self.max - self.min).length()
        }
    }

    /// The eight corners.
    pub fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min, self.max);
        [
            Vec3::new(a.x, a.y, a.z),
            Vec3::new(b.x, a.y, a.z),
            Vec3::new(a.x, b.y, a.z),
            Vec3::new(b.x, b.y, a.z),
            Vec3::new(a.x, a.y, b.z),
            Vec3::new(b.x, a.y, b.z),
            Vec3::new(a.x, b.y, b.z),
            Vec3::new(b.x, b.y, b.z),
        ]
    }
}

/// A single-instance indexed mesh: the expansion of an [`InstancedMesh`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExpandedMesh {
    /// World-space positions.
    pub positions: Vec<Vec3>,
    /// Triangle list into `positions`; mirrored instances have their winding flipped.
    pub indices: Vec<u32>,
    /// For each triangle, the instance it came from.
    pub triangle_instance: Vec<u32>,
}

/// A broken invariant found by [`InstancedMesh::validate`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InvalidMesh {
    /// A submesh's index list is not a whole number of triangles.
    #[error("submesh {submesh}: {count} indices is not a multiple of 3")]
    PartialTriangle {
        /// The submesh.
        submesh: usize,
        /// Its index count.
        count: usize,
    },
    /// An index points past the vertex array.
    #[error("submesh {submesh}: index {index} is past its {vertices} vertices")]
    IndexOutOfRange {
        /// The submesh.
        submesh: usize,
        /// The offending index value.
        index: u32,
        /// The vertex count.
        vertices: usize,
    },
    /// An attribute array has the wrong length.
    #[error("submesh {submesh}: {attribute} has {len} entries for {vertices} vertices")]
    AttributeLength {
        /// The submesh.
        submesh: usize,
        /// Which attribute.
        attribute: &'static str,
        /// Its length.
        len: usize,
        /// The vertex count.
        vertices: usize,
    },
    /// A value is NaN or infinite.
    #[error("{what} is not finite")]
    NonFinite {
        /// Where the value is.
        what: String,
    },
    /// A reference between parts points nowhere.
    #[error("{what} refers to missing {target} {index}")]
    DanglingReference {
        /// The referring item.
        what: String,
        /// The kind of the missing item.
        target: &'static str,
        /// The missing index.
        index: usize,
    },
}

impl InstancedMesh {
    /// Triangles stored once per submesh.
    pub fn unique_triangle_count(&self) -> u64 {
        self.submeshes.iter().map(Submesh::triangle_count).sum()
    }

    /// Triangles as drawn: each instance draws its submesh's triangles once.
    pub fn expanded_triangle_count(&self) -> u64 {
        self.instances
            .iter()
            .map(|i| self.submeshes[i.submesh].triangle_count())
            .sum()
    }

    /// Exact world-space bounds of the expanded mesh: every vertex a triangle uses, placed by
    /// every instance of its submesh.
    pub fn bounds(&self) -> Aabb {
        let used: Vec<Vec<Vec3>> = self.submeshes.iter().map(Submesh::used_positions).collect();
        let mut out = Aabb::EMPTY;
        for inst in &self.instances {
            for &p in &used[inst.submesh] {
                out.grow(inst.transform.transform_point3(p));
            }
        }
        out
    }

    /// Expands every instance into one indexed mesh in world space.
    pub fn expand(&self) -> ExpandedMesh {
        let mut out = ExpandedMesh::default();
        for (k, inst) in self.instances.iter().enumerate() {
            let sub = &self.submeshes[inst.submesh];
            let base = out.positions.len() as u32;
            out.positions.extend(
                sub.positions
                    .iter()
                    .map(|&p| inst.transform.transform_point3(p)),
            );
            let mirrored = inst.transform.matrix3.determinant() < 0.0;
            for t in sub.indices.chunks_exact(3) {
                let tri = if mirrored {
                    [t[0], t[2], t[1]]
                } else {
                    [t[0], t[1], t[2]]
                };
                out.indices.extend(tri.iter().map(|&i| base + i));
                out.triangle_instance.push(k as u32);
            }
        }
        out
    }

    /// Checks every invariant listed on the type.
    pub fn validate(&self) -> Result<(), InvalidMesh> {
        for (s, sub) in self.submeshes.iter().enumerate() {
            sub.validate(s)?;
            if let Some(m) = sub.material {
                if m >= self.materials.len() {
                    return Err(InvalidMesh::DanglingReference {
                        what: format!("submesh {s}"),
                        target: "material",
                        index: m,
                    });
                }
            }
        }
        for (k, inst) in self.instances.iter().enumerate() {
            if inst.submesh >= self.submeshes.len() {
                return Err(InvalidMesh::DanglingReference {
                    what: format!("instance {k}"),
                    target: "submesh",
                    index: inst.submesh,
                });
            }
            if !inst.transform.is_finite() {
                return Err(InvalidMesh::NonFinite {
                    what: format!("instance {k} transform"),
                });
            }
        }
        for (m, mat) in self.materials.iter().enumerate() {
            if let Some(t) = mat.base_color_texture {
                if t.texture >= self.textures.len() {
                    return Err(InvalidMesh::DanglingReference {
                        what: format!("material {m}"),
                        target: "texture",
                        index: t.texture,
                    });
                }
            }
            let transform_finite =
                mat.base_color_texture
                    .and_then(|t| t.transform)
                    .is_none_or(|x| {
                        x.offset.is_finite() && x.rotation.is_finite() && x.scale.is_finite()
                    });
            let cutoff_finite = match mat.alpha_mode {
                AlphaMode::Mask { cutoff } => cutoff.is_finite(),
                _ => true,
            };
            if !(mat.base_color_factor.is_finite()
                && mat.metallic_factor.is_finite()
                && mat.roughness_factor.is_finite()
                && transform_finite
                && cutoff_finite)
            {
                return Err(InvalidMesh::NonFinite {
                    what: format!("material {m} factors"),
                });
            }
        }
        Ok(())
    }

    /// Keeps the submeshes with `keep[s]` and the instances that draw them, both in their
    /// order, renumbered; returns each old submesh's new index (`None` if it went).
    pub fn retain_submeshes(&mut self, keep: &[bool]) -> Vec<Option<usize>> {
        let mut next = 0;
        let index: Vec<Option<usize>> = (0..self.submeshes.len())
            .map(|s| {
                keep.get(s).copied().unwrap_or(false).then(|| {
                    next += 1;
                    next - 1
                })
            })
            .collect();
        let mut s = 0;
        self.submeshes.retain(|_| {
            s += 1;
            index[s - 1].is_some()
        });
        self.instances.retain_mut(|inst| match index[inst.submesh] {
            Some(n) => {
                inst.submesh = n;
                true
            }
            None => false,
        });
        index
    }

    /// Instances of each submesh, in instance order.
    pub fn instances_by_submesh(&self) -> Vec<Vec<usize>> {
        let mut out = vec![Vec::new(); self.submeshes.len()];
        for (k, inst) in self.instances.iter().enumerate() {
            out[inst.submesh].push(k);
        }
        out
    }
}

impl Submesh {
    /// Number of triangles in the index list.
    pub fn triangle_count(&self) -> u64 {
        (self.indices.len() / 3) as u64
    }

    /// Adds to `out` the area of this submesh placed by `m`: the total, then the area facing
    /// +x, -x, +y, -y, +z and -z (each triangle's area times the cosine to the direction,
    /// where positive; a mirroring placement keeps the front faces in front). Triangles whose
    /// placed area is not finite are left out.
    pub fn add_placed_areas(&self, m: &Affine3A, out: &mut [f64; 7]) {
        let flip = if m.matrix3.determinant() < 0.0 {
            -1.0
        } else {
            1.0
        };
        for t in self.indices.chunks_exact(3) {
            let [a, b, c] = [0, 1, 2].map(|i| m.transform_point3(self.positions[t[i] as usize]));
            let v = (b - a).cross(c - a) * (0.5 * flip);
            if !v.is_finite() {
                continue;
            }
            out[0] += f64::from(v.length());
            for (d, value) in [v.x, -v.x, v.y, -v.y, v.z, -v.z].into_iter().enumerate() {
                out[d + 1] += f64::from(value.max(0.0));
            }
        }
    }

    /// Model-space bounds of the vertices the triangles use.
    pub fn bounds(&self) -> Aabb {
        let mut out = Aabb::EMPTY;
        for p in self.used_positions() {
            out.grow(p);
        }
        out
    }

    /// Positions referenced by at least one triangle, each once, in vertex order.
    pub fn used_positions(&self) -> Vec<Vec3> {
        let mut used = vec![false; self.positions.len()];
        for &i in &self.indices {
            if let Some(u) = used.get_mut(i as usize) {
                *u = true;
            }
        }
        self.positions
            .iter()
            .zip(&used)
            .filter(|(_, &u)| u)
            .map(|(&p, _)| p)
            .collect()
    }

    fn validate(&self, s: usize) -> Result<(), InvalidMesh> {
        let n = self.positions.len();
        if !self.indices.len().is_multiple_of(3) {
            return Err(InvalidMesh::PartialTriangle {
                submesh: s,
                count: self.indices.len(),
            });
        }
        if let Some(&index) = self.indices.iter().find(|&&i| i as usize >= n) {
            return Err(InvalidMesh::IndexOutOfRange {
                submesh: s,
                index,
                vertices: n,
            });
        }
        let lengths = [
            ("normals", self.normals.as_ref().map(Vec::len)),
            ("uvs", self.uvs.as_ref().map(Vec::len)),
            ("colors", self.colors.as_ref().map(Vec::len)),
        ];
        for (attribute, len) in lengths {
            if let Some(len) = len.filter(|&l| l != n) {
                return Err(InvalidMesh::AttributeLength {
                    submesh: s,
                    attribute,
                    len,
                    vertices: n,
                });
            }
        }
        let finite = self.positions.iter().all(|p| p.is_finite())
            && self.normals.iter().flatten().all(|v| v.is_finite())
            && self.uvs.iter().flatten().all(|v| v.is_finite())
            && self.colors.iter().flatten().all(|v| v.is_finite());
        if !finite {
            return Err(InvalidMesh::NonFinite {
                what: format!("submesh {s} vertex data"),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retained_submeshes_keep_their_instances_renumbered_in_order() {
        // Submeshes 0, 1, 2 drawn by instances 2, 0, 1, 2: keeping 0 and 2 keeps instances
        // 0, 2 and 3, now drawing 1, 0 and 1.
        let sub = |x: f32| Submesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(x, 1.0, 0.0)],
            indices: vec![0, 1, 2],
            ..Submesh::default()
        };
        let at = |x: f32| glam::Affine3A::from_translation(Vec3::new(x, 0.0, 0.0));
        let mut mesh = InstancedMesh {
            submeshes: vec![sub(0.0), sub(1.0), sub(2.0)],
            instances: [2, 0, 1, 2]
                .iter()
                .enumerate()
                .map(|(k, &s)| Instance {
                    submesh: s,
                    transform: at(k as f32),
                })
                .collect(),
            ..InstancedMesh::default()
        };
        let index = mesh.retain_submeshes(&[true, false, true]);
        assert_eq!(index, vec![Some(0), None, Some(1)]);
        assert_eq!(mesh.submeshes, vec![sub(0.0), sub(2.0)]);
        let drawn: Vec<(usize, glam::Affine3A)> = mesh
            .instances
            .iter()
            .map(|i| (i.submesh, i.transform))
            .collect();
        assert_eq!(drawn, vec![(1, at(0.0)), (0, at(1.0)), (1, at(3.0))]);
        mesh.validate().expect("valid");
    }
}
