//! The third-party baseline: meshoptimizer's `meshopt_simplify` (through the `meshopt` crate)
//! on the expanded mesh, welded by position as our yardstick scripts weld it. It keeps no
//! attributes and merges all submeshes into one; it is there to compare time and error.

use std::time::Instant;

use glam::Affine3A;
use horizon_mesh::{Instance, InstancedMesh, Submesh};

use crate::options::{SimplifyReport, Target};
use crate::weld::Welder;
use crate::{Simplified, SimplifyError};

/// meshoptimizer on the expanded, position-welded mesh (timed: the simplification call only),
/// asked for `target` triangles with no error bound (it may still stop above the target where
/// its topology rules forbid more).
pub fn simplify_meshopt(mesh: &InstancedMesh, target: Target) -> Result<Simplified, SimplifyError> {
    let triangles_target = crate::checked_target(mesh, target)?;
    let triangles_in = mesh.expanded_triangle_count();
    // Expand and weld by position.
    let expanded = mesh.expand();
    let mut welder = Welder::with_capacity(expanded.positions.len());
    let mut positions: Vec<[f32; 3]> = Vec::new();
    let remap: Vec<u32> = expanded
        .positions
        .iter()
        .map(|p| {
            let next = positions.len() as u32;
            let id = welder.id(*p, next);
            if id == next {
                positions.push(p.to_array());
            }
            id
        })
        .collect();
    let indices: Vec<u32> = expanded
        .indices
        .iter()
        .map(|&i| remap[i as usize])
        .collect();
    let start = Instant::now();
    let mut error = 0.0f32;
    let out = meshopt::simplify_decoder(
        &indices,
        &positions,
        triangles_target as usize * 3,
        f32::MAX,
        meshopt::SimplifyOptions::empty(),
        Some(&mut error),
    );
    let seconds = start.elapsed().as_secs_f64();
    // Compact into one submesh.
    let mut used = vec![u32::MAX; positions.len()];
    let mut sub = Submesh::default();
    for &i in &out {
        if used[i as usize] == u32::MAX {
            used[i as usize] = sub.positions.len() as u32;
            sub.positions.push(positions[i as usize].into());
        }
        sub.indices.push(used[i as usize]);
    }
    let triangles_out = sub.triangle_count();
    let mesh = InstancedMesh {
        submeshes: vec![sub],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        materials: Vec::new(),
        textures: Vec::new(),
    };
    let diagonal = f64::from(mesh.bounds().diagonal());
    Ok(Simplified {
        mesh,
        report: SimplifyReport {
            method: "meshopt",
            triangles_in,
            triangles_out,
            triangles_target,
            unique_triangles_in: triangles_in,
            unique_triangles_out: triangles_out,
            collapses: 0,
            // meshopt reports error relative to the mesh extent.
            error: f64::from(error) * diagonal / 3f64.sqrt(),
            seconds,
        },
        kept: Vec::new(),
    })
}
