//! The seeded viewers every benchmark asks from: standing at eye height, uniform over the
//! world's horizontal extent.

use glam::Vec3;
use horizon_bvh::Aabb;
use horizon_mesh::rng::Rng;

/// Eye height of the benchmark viewers, metres (the worlds are Y-up, ground at 0).
pub const EYE_HEIGHT: f32 = 2.0;

/// `count` seeded viewpoints at eye height, uniform over the horizontal extent of `bounds`.
pub fn viewpoints(bounds: &Aabb, seed: u64, count: usize) -> Vec<Vec3> {
    let mut rng = Rng::new(seed);
    (0..count)
        .map(|_| {
            Vec3::new(
                bounds.min.x + rng.unit() * (bounds.max.x - bounds.min.x),
                EYE_HEIGHT,
                bounds.min.z + rng.unit() * (bounds.max.z - bounds.min.z),
            )
        })
        .collect()
}
