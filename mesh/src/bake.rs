//! Baking cheap instances into shared geometry: fewer draw calls and smaller files for meshes
//! made of many small parts, such as aggregates.
//!
//! An instanced submesh costs its geometry once, a transform per instance, and a fixed
//! overhead per draw (a glTF mesh, its accessors and a node: a few hundred bytes of JSON,
//! and a draw call for the client). A submesh placed once, or a tiny one placed a few times,
//! is cheaper written out in world space: [`InstancedMesh::bake_cheap_instances`] moves every
//! such placement into one baked submesh per material and attribute layout, drawn by a single
//! identity instance. What the mesh shows does not change: positions are transformed,
//! normals by the inverse transpose, and mirrored placements get their winding reversed (as
//! [`InstancedMesh::expand`] does; [`Submesh::append_placed`]).

use std::collections::BTreeMap;

use glam::{Affine3A, Mat3};

use crate::model::{Instance, InstancedMesh, Submesh};

/// Bytes a written instance transform costs (translation, 16-bit rotation, scale).
const INSTANCE_BYTES: u64 = 32;
/// Bytes a separate draw costs in the file: a glTF mesh, its primitive and accessors, and a
/// node. An underestimate of the JSON a draw takes (mesh, node, index accessor, instance
/// accessors, a share of the vertex accessors); the measured figure bakes almost no more
/// draws and changes the aggregates' size by a few hundred bytes in hundreds of megabytes,
/// so this value stays, and with it every aggregate's bytes.
const DRAW_BYTES: u64 = 350;

/// What baked placements are grouped by: they share one submesh only when its material and
/// its attribute arrays agree.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Layout {
    material: Option<usize>,
    normals: bool,
    uvs: bool,
    colors: bool,
}

impl InstancedMesh {
    /// The same mesh with submeshes of one layout that are placed by exactly the same
    /// transforms, in the same order, concatenated into one (at the first one's place).
    pub fn merge_coplaced_submeshes(&self) -> InstancedMesh {
        let placed = self.instances_by_submesh();
        // Group by layout and the exact bits of every transform.
        let mut group_of: BTreeMap<(Layout, Vec<u32>), usize> = BTreeMap::new();
        let mut groups: Vec<Vec<usize>> = Vec::new();
        for (s, ks) in placed.iter().enumerate() {
            if ks.is_empty() {
                groups.push(vec![s]);
                continue;
            }
            let bits: Vec<u32> = ks
                .iter()
                .flat_map(|&k| {
                    let t = &self.instances[k].transform;
                    let m = t.matrix3;
                    [m.x_axis, m.y_axis, m.z_axis, t.translation]
                        .into_iter()
                        .flat_map(|v| v.to_array().map(f32::to_bits))
                })
                .collect();
            let next = groups.len();
            let g = *group_of
                .entry((layout(&self.submeshes[s]), bits))
                .or_insert(next);
            if g == next {
                groups.push(vec![s]);
            } else {
                groups[g].push(s);
            }
        }
        if groups.len() == self.submeshes.len() {
            return self.clone();
        }
        let mut out = InstancedMesh {
            materials: self.materials.clone(),
            textures: self.textures.clone(),
            ..InstancedMesh::default()
        };
        for (g, members) in groups.iter().enumerate() {
            let mut merged = empty(layout(&self.submeshes[members[0]]));
            for &s in members {
                merged.append_placed(&self.submeshes[s], &Affine3A::IDENTITY);
            }
            out.submeshes.push(merged);
            out.instances
                .extend(placed[members[0]].iter().map(|&k| Instance {
                    submesh: g,
                    transform: self.instances[k].transform,
                }));
        }
        out
    }

    /// The same mesh with every placement that is cheaper baked than instanced (see the module
    /// comment) merged into one world-space submesh per layout. A layout with a single such
    /// placement is left as it was. Kept submeshes keep their order; baked ones follow.
    pub fn bake_cheap_instances(&self) -> InstancedMesh {
        // Stage 1: which submeshes to bake, and into which layout.
        let placed = self.instances_by_submesh();
        let bake: Vec<Option<Layout>> = self
            .submeshes
            .iter()
            .zip(&placed)
            .map(|(s, ks)| cheaper_baked(s, ks.len() as u64).then(|| layout(s)))
            .collect();
        let mut members: BTreeMap<Layout, usize> = BTreeMap::new();
        for (b, ks) in bake.iter().zip(&placed) {
            if let Some(l) = b {
                *members.entry(*l).or_default() += ks.len();
            }
        }
        let baked = |s: usize| bake[s].filter(|l| members[l] >= 2);
        if (0..self.submeshes.len()).all(|s| baked(s).is_none()) {
            return self.clone();
        }
        // Stage 2: kept submeshes, renumbered, with their instances.
        let mut out = InstancedMesh {
            materials: self.materials.clone(),
            textures: self.textures.clone(),
            ..InstancedMesh::default()
        };
        let mut new_index = vec![usize::MAX; self.submeshes.len()];
        for (s, sub) in self.submeshes.iter().enumerate() {
            if baked(s).is_none() {
                new_index[s] = out.submeshes.len();
                out.submeshes.push(sub.clone());
            }
        }
        for inst in &self.instances {
            if baked(inst.submesh).is_none() {
                out.instances.push(Instance {
                    submesh: new_index[inst.submesh],
                    transform: inst.transform,
                });
            }
        }
        // Stage 3: one baked submesh per layout, placements in instance order.
        let mut merged: BTreeMap<Layout, Submesh> = BTreeMap::new();
        for inst in &self.instances {
            if let Some(l) = baked(inst.submesh) {
                let target = merged.entry(l).or_insert_with(|| empty(l));
                target.append_placed(&self.submeshes[inst.submesh], &inst.transform);
            }
        }
        for sub in merged.into_values() {
            out.instances.push(Instance {
                submesh: out.submeshes.len(),
                transform: Affine3A::IDENTITY,
            });
            out.submeshes.push(sub);
        }
        out
    }
}

fn layout(s: &Submesh) -> Layout {
    Layout {
        material: s.material,
        normals: s.normals.is_some(),
        uvs: s.uvs.is_some(),
        colors: s.colors.is_some(),
    }
}

/// A submesh of layout `l` with no vertices yet.
fn empty(l: Layout) -> Submesh {
    Submesh {
        normals: l.normals.then(Vec::new),
        uvs: l.uvs.then(Vec::new),
        colors: l.colors.then(Vec::new),
        material: l.material,
        ..Submesh::default()
    }
}

/// Whether `instances` placements of `s` cost fewer bytes written out than instanced.
fn cheaper_baked(s: &Submesh, instances: u64) -> bool {
    if instances == 0 {
        return false;
    }
    let vertex = 12
        + if s.normals.is_some() { 12 } else { 0 }
        + if s.uvs.is_some() { 8 } else { 0 }
        + if s.colors.is_some() { 16 } else { 0 };
    let geometry = s.positions.len() as u64 * vertex + s.indices.len() as u64 * 2;
    instances * geometry <= geometry + instances * INSTANCE_BYTES + DRAW_BYTES
}

impl Submesh {
    /// Appends `other` placed by `t` (its layout, i.e. which attribute arrays it has, must
    /// match): positions transformed, normals by the inverse transpose (computed as the
    /// cofactor matrix times the sign of the determinant, which stays defined for a singular
    /// `t`; a normal that vanishes stays zero), UVs and colours copied, and the winding
    /// reversed when `t` mirrors, as [`InstancedMesh::expand`] does.
    pub fn append_placed(&mut self, other: &Submesh, t: &Affine3A) {
        let base = self.positions.len() as u32;
        self.positions
            .extend(other.positions.iter().map(|&p| t.transform_point3(p)));
        let m = Mat3::from(t.matrix3);
        let det = m.determinant();
        if let (Some(out), Some(normals)) = (self.normals.as_mut(), &other.normals) {
            let normal_matrix = Mat3::from_cols(
                m.y_axis.cross(m.z_axis),
                m.z_axis.cross(m.x_axis),
                m.x_axis.cross(m.y_axis),
            ) * if det < 0.0 { -1.0 } else { 1.0 };
            out.extend(
                normals
                    .iter()
                    .map(|&n| (normal_matrix * n).normalize_or_zero()),
            );
        }
        if let (Some(out), Some(uvs)) = (self.uvs.as_mut(), &other.uvs) {
            out.extend_from_slice(uvs);
        }
        if let (Some(out), Some(colors)) = (self.colors.as_mut(), &other.colors) {
            out.extend_from_slice(colors);
        }
        for tri in other.indices.chunks_exact(3) {
            let tri = if det < 0.0 {
                [tri[0], tri[2], tri[1]]
            } else {
                [tri[0], tri[1], tri[2]]
            };
            self.indices.extend(tri.iter().map(|&i| base + i));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn a_mirrored_normal_points_out_of_the_mirrored_surface() {
        // A +x facing quad at x = 1, mirrored in x, lands at x = -1 facing -x.
        let mut wall = quad();
        wall.positions = vec![
            Vec3::X,
            Vec3::X + Vec3::Y,
            Vec3::X + Vec3::Y + Vec3::Z,
            Vec3::X + Vec3::Z,
        ];
        wall.normals = Some(vec![Vec3::X; 4]);
        let mut out = Submesh {
            normals: Some(Vec::new()),
            ..Submesh::default()
        };
        out.append_placed(&wall, &Affine3A::from_scale(Vec3::new(-2.0, 1.0, 1.0)));
        assert_eq!(out.normals.as_ref().expect("normals")[0], -Vec3::X);
        assert_eq!(out.positions[0], -2.0 * Vec3::X);
        // And the reversed winding's geometric normal agrees.
        let [a, b, c] = [0, 1, 2].map(|k| out.positions[out.indices[k] as usize]);
        assert!((b - a).cross(c - a).dot(-Vec3::X) > 0.0);
    }

    fn quad() -> Submesh {
        Submesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::X + Vec3::Y, Vec3::Y],
            normals: Some(vec![Vec3::Z; 4]),
            uvs: None,
            colors: None,
            indices: vec![0, 1, 2, 0, 2, 3],
            material: None,
        }
    }

    fn placed(submeshes: Vec<Submesh>, at: &[(usize, Affine3A)]) -> InstancedMesh {
        InstancedMesh {
            submeshes,
            instances: at
                .iter()
                .map(|&(submesh, transform)| Instance { submesh, transform })
                .collect(),
            ..InstancedMesh::default()
        }
    }

    #[test]
    fn single_placements_become_one_submesh_with_the_same_expansion() {
        let mirror = Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        let mesh = placed(
            vec![quad(), quad(), quad()],
            &[
                (0, Affine3A::from_translation(Vec3::Z)),
                (1, mirror),
                (2, Affine3A::from_rotation_x(1.0)),
            ],
        );
        let out = mesh.bake_cheap_instances();
        out.validate().expect("valid");
        assert_eq!(out.submeshes.len(), 1);
        assert_eq!(out.instances.len(), 1);
        // The expansion is the same triangles in the same places, facing the same way.
        let (a, b) = (mesh.expand(), out.expand());
        assert_eq!(a.indices.len(), b.indices.len());
        for (ta, tb) in a.indices.chunks(3).zip(b.indices.chunks(3)) {
            let pa = ta.iter().map(|&i| a.positions[i as usize]);
            let pb = tb.iter().map(|&i| b.positions[i as usize]);
            for (x, y) in pa.zip(pb) {
                assert!((x - y).length() < 1e-6, "{x} vs {y}");
            }
        }
        // Normals follow the placement: the rotated quad's normal turns with it, and the
        // mirrored one (mirrored in x, so its +z normal stays +z) keeps facing out.
        let normals = out.submeshes[0].normals.as_ref().expect("normals");
        assert_eq!(normals[4], Vec3::Z);
        assert_eq!(normals[0], Vec3::Z);
        assert!(
            (normals[8] - Affine3A::from_rotation_x(1.0).transform_vector3(Vec3::Z)).length()
                < 1e-6
        );
    }

    #[test]
    fn a_submesh_worth_instancing_stays_instanced() {
        // A 2,000-vertex grid placed ten times costs far less instanced than written out.
        let n = 44u32;
        let mut big = Submesh::default();
        for j in 0..=n {
            for i in 0..=n {
                big.positions.push(Vec3::new(i as f32, j as f32, 0.0));
            }
        }
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                big.indices
                    .extend([a, a + 1, a + n + 2, a, a + n + 2, a + n + 1]);
            }
        }
        let mut at: Vec<(usize, Affine3A)> = (0..10)
            .map(|k| (0, Affine3A::from_translation(Vec3::Z * k as f32)))
            .collect();
        at.push((1, Affine3A::IDENTITY));
        at.push((2, Affine3A::from_translation(Vec3::X * 100.0)));
        let mesh = placed(vec![big.clone(), quad(), quad()], &at);
        let out = mesh.bake_cheap_instances();
        out.validate().expect("valid");
        assert_eq!(out.submeshes.len(), 2);
        assert_eq!(out.submeshes[0], big);
        assert_eq!(out.instances.iter().filter(|i| i.submesh == 0).count(), 10);
        assert_eq!(
            out.expanded_triangle_count(),
            mesh.expanded_triangle_count()
        );
    }

    #[test]
    fn parts_placed_alike_become_one_submesh() {
        let at: Vec<Affine3A> = (0..5)
            .map(|k| {
                Affine3A::from_rotation_translation(
                    glam::Quat::from_rotation_y(k as f32),
                    Vec3::X * k as f32,
                )
            })
            .collect();
        let mut roof = quad();
        roof.positions.iter_mut().for_each(|p| p.z += 1.0);
        let mut pairs: Vec<(usize, Affine3A)> = Vec::new();
        for &t in &at {
            pairs.push((0, t));
            pairs.push((1, t));
        }
        // A third part placed differently stays apart.
        pairs.push((2, Affine3A::from_translation(Vec3::Y)));
        pairs.push((2, Affine3A::from_translation(Vec3::Z)));
        let mesh = placed(vec![quad(), roof, quad()], &pairs);
        let out = mesh.merge_coplaced_submeshes();
        out.validate().expect("valid");
        assert_eq!(out.submeshes.len(), 2);
        assert_eq!(out.instances.len(), 7);
        assert_eq!(
            out.expanded_triangle_count(),
            mesh.expanded_triangle_count()
        );
        let bounds = |m: &InstancedMesh| m.bounds();
        assert_eq!(bounds(&out), bounds(&mesh));
    }

    #[test]
    fn layouts_do_not_mix_and_a_lone_placement_is_left_alone() {
        let mut other = quad();
        other.material = Some(0);
        let mut mesh = placed(
            vec![quad(), other],
            &[(0, Affine3A::IDENTITY), (1, Affine3A::IDENTITY)],
        );
        mesh.materials.push(crate::model::Material::default());
        // One cheap placement per layout: nothing to merge.
        assert_eq!(mesh.bake_cheap_instances(), mesh);
    }
}
