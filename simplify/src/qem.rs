//! The classic quadric baseline (Garland and Heckbert 1997; the "Quadric" column of Azim et
//! al. 2014, Table 3): the instanced mesh expanded into one instance, then the same engine.

use glam::Affine3A;
use horizon_mesh::{Instance, InstancedMesh, Submesh};

/// Bakes every instance into its submesh's vertices: one submesh per input submesh, holding
/// all its instances, placed once by the identity ([`Submesh::append_placed`]: normals through
/// the inverse transpose, mirrored instances with their winding flipped, as
/// [`InstancedMesh::expand`] does).
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
            out.append_placed(sub, &mesh.instances[k].transform);
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
