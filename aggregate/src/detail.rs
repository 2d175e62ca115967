//! Detail culling to the triangle budget: what IAS cannot remove, the smallest placements give
//! up.
//!
//! IAS (core paper section 6) stops where no collapse is legal: a closed part never goes
//! below a tetrahedron's 4 triangles, however far away. An upper aggregate is made of hundreds
//! of thousands of such parts, so simplification alone can leave it an order of magnitude
//! over the budget that its screen size (`budget.rs`) allows. This stage then drops whole
//! instances, smallest on screen first, until the aggregate fits: the detail that vanishes is
//! the detail least visible from the aggregate's nearest display distance, and the largest
//! footprint dropped is reported as the stage's error, in pixels.
//!
//! Only instances whose triangles are on average smaller than a budget triangle
//! (`pixels < pixels_per_triangle x triangles`) may go, and never the last one: a part big
//! enough to pay for its triangles stays, over budget or not.

use horizon_mesh::{InstancedMesh, Submesh};

use crate::budget::Display;
use crate::options::AggregateOptions;

/// What [`cull_to_budget`] removed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DetailCull {
    /// Instances dropped.
    pub instances: usize,
    /// Expanded triangles dropped.
    pub triangles: u64,
    /// The largest footprint dropped, pixels at the nearest display distance (0 if none).
    pub largest_pixels: f64,
}

/// Drops the smallest instances of `mesh` until its expanded triangles fit `budget` (see the
/// module comment for which may go). Submeshes left without instances are removed; the order
/// of everything kept is unchanged.
pub fn cull_to_budget(
    mesh: InstancedMesh,
    budget: u64,
    display: &Display,
    options: &AggregateOptions,
) -> (InstancedMesh, DetailCull) {
    let mut total = mesh.expanded_triangle_count();
    let mut cull = DetailCull::default();
    if total <= budget || mesh.instances.len() <= 1 {
        return (mesh, cull);
    }
    // Stage 1: every instance's footprint, and the candidates, smallest first.
    let spheres: Vec<(glam::Vec3, f32)> = mesh.submeshes.iter().map(model_sphere).collect();
    let mut candidates: Vec<(f64, usize)> = mesh
        .instances
        .iter()
        .enumerate()
        .filter_map(|(k, inst)| {
            let sub = &mesh.submeshes[inst.submesh];
            let (centre, radius) = spheres[inst.submesh];
            let scale = horizon_mesh::transform::max_axis_scale(&inst.transform);
            let pixels =
                display.object_pixels(inst.transform.transform_point3(centre), radius * scale);
            let affords = pixels >= options.pixels_per_triangle * sub.triangle_count() as f64;
            (!affords).then_some((pixels, k))
        })
        .collect();
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    // Stage 2: drop while over budget, keeping at least one instance.
    let mut dropped = vec![false; mesh.instances.len()];
    for &(pixels, k) in &candidates {
        if total <= budget || cull.instances + 1 == mesh.instances.len() {
            break;
        }
        let t = mesh.submeshes[mesh.instances[k].submesh].triangle_count();
        dropped[k] = true;
        total -= t;
        cull.instances += 1;
        cull.triangles += t;
        cull.largest_pixels = cull.largest_pixels.max(pixels);
    }
    if cull.instances == 0 {
        return (mesh, cull);
    }
    // Stage 3: the kept instances, and the submeshes they still use, renumbered in order.
    let mut mesh = mesh;
    let mut k = 0;
    mesh.instances.retain(|_| {
        k += 1;
        !dropped[k - 1]
    });
    let mut used = vec![false; mesh.submeshes.len()];
    for inst in &mesh.instances {
        used[inst.submesh] = true;
    }
    mesh.retain_submeshes(&used);
    (mesh, cull)
}

/// A model-space sphere holding the submesh's used vertices: its bounding box's centre and the
/// farthest vertex from it.
fn model_sphere(sub: &Submesh) -> (glam::Vec3, f32) {
    let used = sub.used_positions();
    if used.is_empty() {
        return (glam::Vec3::ZERO, 0.0);
    }
    let mut bounds = horizon_mesh::Aabb::EMPTY;
    for &p in &used {
        bounds.grow(p);
    }
    let centre = (bounds.min + bounds.max) * 0.5;
    let radius = used.iter().map(|p| p.distance(centre)).fold(0.0, f32::max);
    (centre, radius)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Affine3A, Vec3};
    use horizon_mesh::Instance;

    /// A closed unit cube (12 triangles).
    fn cube() -> Submesh {
        let positions: Vec<Vec3> = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
            .collect();
        let faces = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let indices = faces
            .iter()
            .flat_map(|f| [f[0], f[1], f[2], f[0], f[2], f[3]])
            .collect();
        Submesh {
            positions,
            indices,
            ..Submesh::default()
        }
    }

    /// One big cube at the centre and `n` small ones in a row, far from it.
    fn scene(n: usize) -> InstancedMesh {
        let mut instances = vec![Instance {
            submesh: 0,
            transform: Affine3A::from_scale(Vec3::splat(20.0)),
        }];
        for k in 0..n {
            instances.push(Instance {
                submesh: 1,
                transform: Affine3A::from_scale_rotation_translation(
                    Vec3::splat(0.1 + 0.01 * k as f32),
                    glam::Quat::IDENTITY,
                    Vec3::new(30.0 + k as f32, 0.0, 0.0),
                ),
            });
        }
        InstancedMesh {
            submeshes: vec![cube(), cube()],
            instances,
            materials: Vec::new(),
            textures: Vec::new(),
        }
    }

    fn display() -> Display {
        Display::of(Vec3::ZERO, 100.0, 20.0, &AggregateOptions::default())
    }

    #[test]
    fn within_budget_nothing_goes() {
        let mesh = scene(10);
        let (out, cull) = cull_to_budget(mesh.clone(), 1_000, &display(), &Default::default());
        assert_eq!(cull, DetailCull::default());
        assert_eq!(out, mesh);
    }

    #[test]
    fn the_smallest_go_first_until_the_budget_fits() {
        // 1 + 50 cubes = 612 triangles; a budget of 300 takes 26 of the small ones, smallest
        // (the first ones in the row) first, and keeps the big cube.
        let mesh = scene(50);
        let (out, cull) = cull_to_budget(mesh.clone(), 300, &display(), &Default::default());
        out.validate().expect("a valid mesh");
        assert!(out.expanded_triangle_count() <= 300);
        assert_eq!(cull.instances, 26);
        assert_eq!(cull.triangles, 26 * 12);
        assert_eq!(out.instances[0], mesh.instances[0]);
        // The survivors are the last 24 of the row, in their order.
        assert_eq!(&out.instances[1..], &mesh.instances[27..]);
        assert!(cull.largest_pixels > 0.0);
    }

    #[test]
    fn a_part_that_pays_for_its_triangles_stays_even_over_budget() {
        // Only the big cube: it covers far more than 16 pixels per triangle, so it stays, and
        // so would a lone small one (never the last instance).
        let mut mesh = scene(0);
        let (out, cull) = cull_to_budget(mesh.clone(), 1, &display(), &Default::default());
        assert_eq!((out, cull.instances), (mesh.clone(), 0));
        mesh.instances[0].transform = Affine3A::from_scale(Vec3::splat(0.01));
        mesh.instances.push(mesh.instances[0]);
        let (out, cull) = cull_to_budget(mesh, 1, &display(), &Default::default());
        assert_eq!((out.instances.len(), cull.instances), (1, 1));
    }

    #[test]
    fn submeshes_left_without_instances_are_removed() {
        // Every small cube goes: submesh 1 disappears and the big cube keeps submesh 0.
        let mesh = scene(5);
        let (out, cull) = cull_to_budget(mesh, 12, &display(), &Default::default());
        out.validate().expect("a valid mesh");
        assert_eq!(cull.instances, 5);
        assert_eq!(out.submeshes.len(), 1);
        assert_eq!(out.instances.len(), 1);
        assert_eq!(out.instances[0].submesh, 0);
    }
}
