//! Perturbed variants of a model for the Table 1 calibration: the near-duplicates a user world
//! is full of. Small noise, a removed part, and a recoloured texture, each at a few strengths,
//! so the calibration sees pairs on both sides of "indistinguishable".

use glam::{Vec3, Vec4};
use horizon_mesh::rng::hash;
use horizon_mesh::{InstancedMesh, Material};

/// A named way to perturb a model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Perturbation {
    /// Every vertex moves by up to `relative` x its part's bounding-box diagonal, in a random
    /// direction that depends only on its position, so coincident vertices (seams) move
    /// together and no cracks open.
    Noise {
        /// Amplitude relative to the part's diagonal.
        relative: f32,
    },
    /// A part covering about `fraction` of the surface area is removed: the instance whose
    /// share is nearest `fraction` when there are several, otherwise the triangles nearest a
    /// seeded surface point.
    RemovePart {
        /// Fraction of the expanded area to remove.
        fraction: f32,
    },
    /// Every material's base colour is multiplied by `tint` (textures are multiplied by the
    /// base colour, so they are recoloured too).
    Recolour {
        /// Linear RGB multiplier.
        tint: Vec3,
    },
}

impl Perturbation {
    /// The calibration's set: four noise levels, two removals, three recolours.
    pub fn standard_set() -> Vec<Perturbation> {
        vec![
            Perturbation::Noise { relative: 0.002 },
            Perturbation::Noise { relative: 0.005 },
            Perturbation::Noise { relative: 0.01 },
            Perturbation::Noise { relative: 0.03 },
            Perturbation::RemovePart { fraction: 0.01 },
            Perturbation::RemovePart { fraction: 0.05 },
            Perturbation::Recolour {
                tint: Vec3::new(1.0, 0.95, 0.95),
            },
            Perturbation::Recolour {
                tint: Vec3::new(1.0, 0.85, 0.8),
            },
            Perturbation::Recolour {
                tint: Vec3::new(0.5, 0.8, 1.0),
            },
        ]
    }

    /// A short label for reports.
    pub fn label(&self) -> String {
        match self {
            Perturbation::Noise { relative } => format!("noise{relative}"),
            Perturbation::RemovePart { fraction } => format!("remove{fraction}"),
            Perturbation::Recolour { tint } => {
                format!("tint{:.2}_{:.2}_{:.2}", tint.x, tint.y, tint.z)
            }
        }
    }

    /// The perturbed copy of `mesh`.
    pub fn apply(&self, mesh: &InstancedMesh, seed: u64) -> InstancedMesh {
        match *self {
            Perturbation::Noise { relative } => noise(mesh, relative, seed),
            Perturbation::RemovePart { fraction } => remove_part(mesh, fraction, seed),
            Perturbation::Recolour { tint } => recolour(mesh, tint),
        }
    }
}

fn noise(mesh: &InstancedMesh, relative: f32, seed: u64) -> InstancedMesh {
    let mut out = mesh.clone();
    for sub in &mut out.submeshes {
        let diag = sub.bounds().diagonal();
        if !(diag.is_finite() && diag > 0.0) {
            continue;
        }
        let amplitude = relative * diag;
        for p in &mut sub.positions {
            let h = hash3(*p, seed);
            let dir = Vec3::new(unit(h), unit(h >> 21), unit(h >> 42));
            *p += dir * amplitude;
        }
    }
    out
}

fn remove_part(mesh: &InstancedMesh, fraction: f32, seed: u64) -> InstancedMesh {
    let areas: Vec<f32> = mesh
        .instances
        .iter()
        .map(|i| instance_area(mesh, i))
        .collect();
    let total: f32 = areas.iter().sum();
    if mesh.instances.len() > 1 && total > 0.0 {
        // The instance whose area share is nearest the fraction; ties go to the seeded one.
        let target = fraction * total;
        let start = (seed as usize) % mesh.instances.len();
        let best = (0..mesh.instances.len())
            .map(|k| (k + start) % mesh.instances.len())
            .min_by(|&a, &b| {
                (areas[a] - target)
                    .abs()
                    .total_cmp(&(areas[b] - target).abs())
            });
        let mut out = mesh.clone();
        if let Some(best) = best {
            out.instances.remove(best);
        }
        return out;
    }
    let mut out = mesh.clone();
    let Some(instance) = mesh.instances.first() else {
        return out;
    };
    let sub_id = instance.submesh;
    let sub = &mesh.submeshes[sub_id];
    let tris: Vec<[u32; 3]> = sub
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    if tris.is_empty() {
        return out;
    }
    let centre = |t: &[u32; 3]| t.iter().map(|&i| sub.positions[i as usize]).sum::<Vec3>() / 3.0;
    let area = |t: &[u32; 3]| {
        let [a, b, c] = t.map(|i| sub.positions[i as usize]);
        0.5 * (b - a).cross(c - a).length()
    };
    let seed_point = centre(&tris[(hash3(Vec3::ZERO, seed) as usize) % tris.len()]);
    let mut order: Vec<usize> = (0..tris.len()).collect();
    order.sort_by(|&a, &b| {
        (centre(&tris[a]) - seed_point)
            .length_squared()
            .total_cmp(&(centre(&tris[b]) - seed_point).length_squared())
    });
    let sub_total: f32 = tris.iter().map(area).sum();
    let mut removed = vec![false; tris.len()];
    let mut acc = 0.0;
    for &t in &order {
        if acc >= fraction * sub_total {
            break;
        }
        acc += area(&tris[t]);
        removed[t] = true;
    }
    let kept: Vec<u32> = tris
        .iter()
        .zip(&removed)
        .filter(|(_, &r)| !r)
        .flat_map(|(t, _)| t.iter().copied())
        .collect();
    if !kept.is_empty() {
        out.submeshes[sub_id].indices = kept;
    }
    out
}

fn recolour(mesh: &InstancedMesh, tint: Vec3) -> InstancedMesh {
    let mut out = mesh.clone();
    for m in &mut out.materials {
        m.base_color_factor *= tint.extend(1.0);
    }
    if out.submeshes.iter().any(|s| s.material.is_none()) {
        let id = out.materials.len();
        out.materials.push(Material {
            base_color_factor: Vec4::ONE * tint.extend(1.0),
            ..Material::default()
        });
        for s in &mut out.submeshes {
            if s.material.is_none() {
                s.material = Some(id);
            }
        }
    }
    out
}

fn instance_area(mesh: &InstancedMesh, instance: &horizon_mesh::Instance) -> f32 {
    let sub = &mesh.submeshes[instance.submesh];
    sub.indices
        .chunks_exact(3)
        .map(|t| {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| {
                instance
                    .transform
                    .transform_point3(sub.positions[i as usize])
            });
            0.5 * (b - a).cross(c - a).length()
        })
        .filter(|a| a.is_finite())
        .sum()
}

/// A 64-bit hash of a position's bits and a seed: equal positions get equal hashes, whatever
/// the order they are visited in.
fn hash3(p: Vec3, seed: u64) -> u64 {
    hash(seed, p.to_array().map(|c| u64::from(c.to_bits())))
}

/// 21 bits of `h` as a number in [-1, 1].
fn unit(h: u64) -> f32 {
    ((h & 0x1F_FFFF) as f32 / 0x1F_FFFF as f32) * 2.0 - 1.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Affine3A;
    use horizon_mesh::{Instance, Submesh};

    fn two_quads() -> InstancedMesh {
        let sub = Submesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE.with_z(0.0)],
            indices: vec![0, 1, 2, 2, 1, 3],
            ..Submesh::default()
        };
        InstancedMesh {
            submeshes: vec![sub],
            instances: vec![
                Instance {
                    submesh: 0,
                    transform: Affine3A::IDENTITY,
                },
                Instance {
                    submesh: 0,
                    transform: Affine3A::from_scale(Vec3::splat(0.1)),
                },
            ],
            ..InstancedMesh::default()
        }
    }

    #[test]
    fn noise_moves_coincident_vertices_together() {
        let mut mesh = two_quads();
        mesh.submeshes[0].positions.push(Vec3::X);
        let out = Perturbation::Noise { relative: 0.01 }.apply(&mesh, 7);
        let p = &out.submeshes[0].positions;
        assert_eq!(p[1], p[4]);
        assert_ne!(p[1], Vec3::X);
        assert!((p[1] - Vec3::X).length() <= 0.01 * 2f32.sqrt() * 3f32.sqrt());
    }

    #[test]
    fn removing_a_part_drops_the_instance_nearest_the_fraction() {
        let out = Perturbation::RemovePart { fraction: 0.01 }.apply(&two_quads(), 0);
        assert_eq!(out.instances.len(), 1);
        assert_eq!(out.instances[0].transform, Affine3A::IDENTITY);
    }

    #[test]
    fn recolouring_gives_uncoloured_parts_a_tinted_material() {
        let out = Perturbation::Recolour {
            tint: Vec3::new(0.5, 1.0, 1.0),
        }
        .apply(&two_quads(), 0);
        let m = out.submeshes[0].material.expect("a material");
        assert_eq!(
            out.materials[m].base_color_factor,
            Vec4::new(0.5, 1.0, 1.0, 1.0)
        );
        out.validate().expect("valid");
    }
}
