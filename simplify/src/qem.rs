//! The classic quadric baseline (Garland and Heckbert 1997; the "Quadric" column of Azim et
//! al. 2014, Table 3): the instanced mesh expanded into one instance, then the same engine.

use glam::Affine3A;
use horizon_mesh::{Instance, InstancedMesh, Submesh};

/// Bakes every instance into its submesh's vertices: one submesh per input submesh, holding
/// all its instances, placed once by the identity. Normals go through the inverse transpose,
/// and mirrored instances flip their winding, as [`InstancedMesh::expand`] does.
pub fn expand_to_single_instance(mesh: &InstancedMesh) -> InstancedMesh {
    let by_submesh = mesh.instances_by_submesh();
    let mut submeshes = Vec::new();
    for (sub, placed) in mesh.submeshes.iter().zip(&by_submesh) {
        if placed.is_empty() {
            continue;
        }
        let n = sub.positions.len() * placed.len();
        let mut out = Submesh {
            positions: Vec::with_capacity(n),
            normals: sub.normals.as_ref().map(|_| Vec::with_capacity(n)),
            uvs: sub.uvs.as_ref().map(|_| Vec::with_capacity(n)),
            colors: sub.colors.as_ref().map(|_| Vec::with_capacity(n)),
            indices: Vec::with_capacity(sub.indices.len() * placed.len()),
            material: sub.material,
        };
        for &k in placed {
            let m = mesh.instances[k].transform;
            let base = out.positions.len() as u32;
            out.positions
                .extend(sub.positions.iter().map(|&p| m.transform_point3(p)));
            if let (Some(dst), Some(src)) = (out.normals.as_mut(), sub.normals.as_ref()) {
                let normal_matrix = m.matrix3.inverse().transpose();
                dst.extend(src.iter().map(|&n| (normal_matrix * n).normalize_or_zero()));
            }
            if let (Some(dst), Some(src)) = (out.uvs.as_mut(), sub.uvs.as_ref()) {
                dst.extend_from_slice(src);
            }
            if let (Some(dst), Some(src)) = (out.colors.as_mut(), sub.colors.as_ref()) {
                dst.extend_from_slice(src);
            }
            let mirrored = m.matrix3.determinant() < 0.0;
            for t in sub.indices.chunks_exact(3) {
                let t = if mirrored {
                    [t[0], t[2], t[1]]
                } else {
                    [t[0], t[1], t[2]]
                };
                out.indices.extend(t.map(|i| base + i));
            }
        }
        submeshes.push(out);
    }
    let instances = (0..submeshes.len())
        .map(|submesh| Instance {
            submesh,
            transform: Affine3A::IDENTITY,
        })
        .collect();
    InstancedMesh {
        submeshes,
        instances,
        materials: mesh.materials.clone(),
        textures: mesh.textures.clone(),
    }
}
