//! A world made by `horizon-worldgen` (the village, island and cities of the core paper's
//! evaluation), written as a world directory. The demo writes the village; the lab writes
//! every benchmark world.

use std::path::Path;
use std::time::Instant;

use horizon_mesh::InstancedMesh;
use horizon_world::World;

/// A generated world, written.
#[derive(Debug)]
pub struct Generated {
    /// The world, opened.
    pub world: World,
    /// Seconds the generator took.
    pub generate_seconds: f64,
    /// Seconds normalising, hashing and writing took.
    pub write_seconds: f64,
}

/// Generates the world `name` from `seed` (`user_models`: the city's user uploads) and writes
/// it into `dir`.
pub fn write_world(
    name: &str,
    dir: &Path,
    seed: u64,
    user_models: &[InstancedMesh],
) -> anyhow::Result<Generated> {
    let started = Instant::now();
    let generated = horizon_worldgen::generate_world_with(name, seed, user_models)?;
    let generate_seconds = started.elapsed().as_secs_f64();
    let started = Instant::now();
    let objects: Vec<(usize, glam::Affine3A)> = generated
        .objects
        .iter()
        .map(|o| (o.model, o.transform))
        .collect();
    let world = World::create(dir, name, seed, &generated.models, &objects)?;
    Ok(Generated {
        world,
        generate_seconds,
        write_seconds: started.elapsed().as_secs_f64(),
    })
}
