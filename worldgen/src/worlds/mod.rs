//! The seeded benchmark worlds of the core paper (Azim et al. 2014, section 8):
//! `village` (6 unique models, 10,000 objects), `island` (236 unique models, 2,362 objects),
//! `city` (60,000 objects on a street grid, about two thousand distinct house and ground models
//! with as many 32×32 textures, 3% of the objects replaced by user models) and `city9` (9
//! tiled copies of city, 540,000 objects sharing city's models).
//!
//! The same name and seed always give the same world.
//!
//! # Layout
//! - [`generate_world`], [`generate_world_with`]: the entry points; [`World`], [`WorldObject`].
//! - `village`, `island`, `city` below: one layout function per world.
//! - [`parts`]: the parametric models and small textures the worlds are built from.

pub mod distinct;
pub mod parts;

use std::collections::HashMap;
use std::f32::consts::{FRAC_PI_2, PI};

use glam::{Affine3A, Quat, Vec2, Vec3, Vec4};
use horizon_mesh::InstancedMesh;

use crate::assembly::srgb;
use crate::rng::Rng;
use crate::{textures, WorldgenError};
use parts::{HouseParams, Roof, TreeParams};

/// The names [`generate_world`] accepts.
pub const WORLD_NAMES: [&str; 4] = ["village", "island", "city", "city9"];

/// Fraction of city objects replaced by user models (core paper section 8).
pub const USER_MODEL_FRACTION: f64 = 0.03;

/// A generated world: unique models and the objects placing them.
#[derive(Clone, Debug, Default)]
pub struct World {
    /// Unique models with a descriptive name; every model is used by at least one object.
    pub models: Vec<(String, InstancedMesh)>,
    /// The objects, in a deterministic order (their index is their id).
    pub objects: Vec<WorldObject>,
}

/// One placed object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldObject {
    /// Index into [`World::models`].
    pub model: usize,
    /// Model-to-world transform.
    pub transform: Affine3A,
}

/// Generates the named world (see [`WORLD_NAMES`]) from `seed`, with no user models (city and
/// city9 then keep their generated objects in place of the 3% user models).
///
/// # Errors
/// As [`generate_world_with`].
pub fn generate_world(name: &str, seed: u64) -> Result<World, WorldgenError> {
    generate_world_with(name, seed, &[])
}

/// Generates the named world from `seed`. In `city` and `city9`, exactly 3% of the objects
/// (houses, trees, lamps and benches, never ground) are replaced by `extra_models` (real
/// user-generated models), each scaled to 2-8 m and stood on the ground; the other worlds
/// ignore them.
///
/// # Errors
/// [`WorldgenError::UnknownWorld`] for a name not in [`WORLD_NAMES`];
/// [`WorldgenError::Texture`] if a procedural texture cannot be encoded.
pub fn generate_world_with(
    name: &str,
    seed: u64,
    extra_models: &[InstancedMesh],
) -> Result<World, WorldgenError> {
    match name {
        "village" => village(seed),
        "island" => island(seed),
        "city" => city(seed, extra_models),
        "city9" => {
            let base = city(seed, extra_models)?;
            let extent = CITY_BLOCKS as f32 * BLOCK_PITCH + ROAD_WIDTH;
            let mut objects = Vec::with_capacity(base.objects.len() * 9);
            for tile in 0..9 {
                let offset = Vec3::new((tile % 3) as f32, 0.0, (tile / 3) as f32) * extent;
                let shift = Affine3A::from_translation(offset);
                objects.extend(base.objects.iter().map(|o| WorldObject {
                    model: o.model,
                    transform: shift * o.transform,
                }));
            }
            Ok(World {
                models: base.models,
                objects,
            })
        }
        _ => Err(WorldgenError::UnknownWorld {
            name: name.to_owned(),
            valid: &WORLD_NAMES,
        }),
    }
}

/// Translation, rotation about +Y and uniform scale.
fn place(position: Vec3, yaw: f32, scale: f32) -> Affine3A {
    Affine3A::from_scale_rotation_translation(
        Vec3::splat(scale),
        Quat::from_rotation_y(yaw),
        position,
    )
}

/// The village: 1,200 plots on a 30 × 40 grid, each with a house of one of three kinds and four
/// fence segments, plus 3,000 trees and 1,000 rocks scattered over it. 6 models, 10,000
/// objects.
fn village(seed: u64) -> Result<World, WorldgenError> {
    let mut rng = Rng::new(seed).fork(0x0011_1A6E);
    let plaster = textures::plaster(seed)?;
    let roof_tiles = textures::roof_tiles(seed)?;
    let wood = textures::wood(seed)?;
    let house = |width, depth, floors, roof, chimney| HouseParams {
        width,
        depth,
        floors,
        floor_height: 2.8,
        roof,
        facade: plaster.clone(),
        facade_tile: 2.0,
        roof_texture: Some(roof_tiles.clone()),
        roof_colour: Vec4::ONE,
        trim_colour: srgb(0.35, 0.22, 0.12),
        chimney,
    };
    let models = vec![
        (
            "cottage".to_owned(),
            parts::house(&house(7.0, 6.0, 1, Roof::Gable, true)),
        ),
        (
            "townhouse".to_owned(),
            parts::house(&house(8.0, 8.0, 2, Roof::Hip, false)),
        ),
        (
            "barn".to_owned(),
            parts::house(&house(12.0, 8.0, 1, Roof::Gable, false)),
        ),
        (
            "tree".to_owned(),
            parts::tree(&TreeParams {
                seed,
                height: 8.0,
                crown_radius: 2.5,
                conifer: false,
                leaf_colour: srgb(0.25, 0.45, 0.15),
                bark_colour: srgb(0.35, 0.25, 0.18),
            }),
        ),
        (
            "fence".to_owned(),
            parts::fence(20.0, Some(wood), srgb(0.8, 0.7, 0.6)),
        ),
        (
            "rock".to_owned(),
            parts::rock(seed, 1.2, srgb(0.5, 0.5, 0.48)),
        ),
    ];
    let (cols, rows, pitch) = (30usize, 40usize, 24.0f32);
    let mut objects = Vec::with_capacity(10_000);
    for row in 0..rows {
        for col in 0..cols {
            let centre = Vec3::new(col as f32 * pitch, 0.0, row as f32 * pitch);
            let kind = rng.below(3);
            let yaw = rng.below(4) as f32 * FRAC_PI_2;
            let jitter = Vec3::new(rng.jitter(2.0), 0.0, rng.jitter(2.0));
            objects.push(WorldObject {
                model: kind,
                transform: place(centre + jitter, yaw, 1.0),
            });
            for side in 0..4 {
                let yaw = side as f32 * FRAC_PI_2;
                let offset = Quat::from_rotation_y(yaw) * Vec3::new(0.0, 0.0, pitch * 0.45);
                objects.push(WorldObject {
                    model: 4,
                    transform: place(centre + offset, yaw, 1.0),
                });
            }
        }
    }
    let extent = Vec2::new(cols as f32 * pitch, rows as f32 * pitch);
    for (model, count) in [(3usize, 3_000usize), (5, 1_000)] {
        for _ in 0..count {
            let p = Vec3::new(
                rng.range(-pitch * 0.5, extent.x - pitch * 0.5),
                0.0,
                rng.range(-pitch * 0.5, extent.y - pitch * 0.5),
            );
            objects.push(WorldObject {
                model,
                transform: place(p, rng.angle(), rng.range(0.8, 1.25)),
            });
        }
    }
    Ok(World { models, objects })
}

/// Unique models of the island.
const ISLAND_MODELS: usize = 236;
/// Objects of the island.
const ISLAND_OBJECTS: usize = 2_362;

/// The island: 236 seeded variants of six kinds (broadleaf tree, conifer, palm-like tall tree,
/// rock, hut, bush) scattered over a disc of 300 m radius, every model used at least once.
fn island(seed: u64) -> Result<World, WorldgenError> {
    let rng = Rng::new(seed).fork(0x0015_1A4D);
    let mut models = Vec::with_capacity(ISLAND_MODELS);
    for i in 0..ISLAND_MODELS {
        let mut r = rng.fork(i as u64);
        let model_seed = r.next_u64();
        let kind = i % 6;
        let green = parts::near(&mut r, Vec3::new(0.25, 0.5, 0.18), 0.12);
        let bark = parts::near(&mut r, Vec3::new(0.38, 0.28, 0.2), 0.08);
        let tree = |conifer, height: f32, crown: f32| TreeParams {
            seed: model_seed,
            height,
            crown_radius: crown,
            conifer,
            leaf_colour: srgb(green.x, green.y, green.z),
            bark_colour: srgb(bark.x, bark.y, bark.z),
        };
        let (label, mesh) = match kind {
            0 => (
                "tree",
                parts::tree(&tree(false, r.range(5.0, 10.0), r.range(1.8, 3.5))),
            ),
            1 => (
                "conifer",
                parts::tree(&tree(true, r.range(6.0, 14.0), r.range(1.5, 3.0))),
            ),
            2 => (
                "palm",
                parts::tree(&tree(false, r.range(9.0, 14.0), r.range(1.2, 2.0))),
            ),
            3 => {
                let c = parts::near(&mut r, Vec3::splat(0.5), 0.15);
                (
                    "rock",
                    parts::rock(model_seed, r.range(0.8, 4.0), srgb(c.x, c.y, c.z)),
                )
            }
            4 => {
                let wall = parts::near(&mut r, Vec3::new(0.75, 0.65, 0.5), 0.2);
                let roofs = [Roof::Gable, Roof::Hip, Roof::Flat];
                let roof = parts::near(&mut r, Vec3::new(0.55, 0.35, 0.2), 0.2);
                let params = HouseParams {
                    width: r.range(4.0, 9.0),
                    depth: r.range(4.0, 8.0),
                    floors: 1 + r.below(2) as u32,
                    floor_height: 2.8,
                    roof: roofs[r.below(3)],
                    facade: parts::facade_texture(model_seed, wall, Vec3::splat(0.15))?,
                    facade_tile: 3.0,
                    roof_texture: None,
                    roof_colour: srgb(roof.x, roof.y, roof.z),
                    trim_colour: srgb(0.3, 0.2, 0.12),
                    chimney: r.chance(0.5),
                };
                ("hut", parts::house(&params))
            }
            _ => (
                "bush",
                parts::tree(&tree(false, r.range(1.0, 2.0), r.range(0.6, 1.2))),
            ),
        };
        models.push((format!("{label}-{i}"), mesh));
    }
    let mut r = rng.fork(u64::MAX);
    let objects = (0..ISLAND_OBJECTS)
        .map(|i| {
            let model = if i < ISLAND_MODELS {
                i
            } else {
                r.below(ISLAND_MODELS)
            };
            let radius = 300.0 * r.unit().sqrt();
            let angle = r.angle();
            let p = Vec3::new(radius * angle.cos(), 0.0, radius * angle.sin());
            WorldObject {
                model,
                transform: place(p, r.angle(), r.range(0.85, 1.2)),
            }
        })
        .collect();
    Ok(World { models, objects })
}

/// Objects of the city.
const CITY_OBJECTS: usize = 60_000;
/// City blocks per side (the grid holds a little more than `CITY_OBJECTS`; the last row is
/// cut short).
const CITY_BLOCKS: usize = 24;
/// Distance between block origins, metres.
const BLOCK_PITCH: f32 = 70.0;
/// Width of a road, metres.
const ROAD_WIDTH: f32 = 10.0;
/// Distinct house models (each with its own facade texture).
const HOUSE_VARIANTS: usize = 1_500;
/// Distinct pavement tile models (each with its own paving texture).
const PAVEMENT_VARIANTS: usize = 400;
/// Distinct courtyard ground models (each with its own ground texture).
const COURTYARD_VARIANTS: usize = 100;
/// Distinct tree models.
const TREE_VARIANTS: usize = 12;

/// What a city object is, before models are assigned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum CityKind {
    Road,
    Crossing,
    Pavement,
    Courtyard,
    House,
    Tree,
    Lamp,
    Bench,
}

/// The city: square blocks on a street grid. Each block has road tiles along two edges and a
/// crossing, a ring of pavement tiles, 16 houses facing the street, street trees and lamps,
/// and a courtyard with trees and benches (104 objects). Models are parametric variants,
/// assigned round-robin so that every variant is used.
fn city(seed: u64, extra_models: &[InstancedMesh]) -> Result<World, WorldgenError> {
    let root = Rng::new(seed).fork(0xC17E);
    let mut models: Vec<(String, InstancedMesh)> = Vec::new();
    let mut first_of: HashMap<&'static str, (usize, usize)> = HashMap::new();

    // Houses.
    let start = models.len();
    for i in 0..HOUSE_VARIANTS {
        let mut r = root.fork(1 << 32 | i as u64);
        let s = r.next_u64();
        let wall = parts::near(&mut r, Vec3::new(0.7, 0.62, 0.52), 0.25);
        let window = parts::near(&mut r, Vec3::new(0.2, 0.25, 0.3), 0.1);
        let roof = parts::near(&mut r, Vec3::new(0.45, 0.3, 0.25), 0.2);
        let roofs = [Roof::Gable, Roof::Hip, Roof::Flat];
        let params = HouseParams {
            width: r.range(7.0, 11.0),
            depth: r.range(7.0, 10.0),
            floors: 1 + r.below(5) as u32,
            floor_height: r.range(2.8, 3.4),
            roof: roofs[r.below(3)],
            facade: parts::facade_texture(s, wall, window)?,
            facade_tile: 3.0,
            roof_texture: None,
            roof_colour: srgb(roof.x, roof.y, roof.z),
            trim_colour: srgb(0.25, 0.22, 0.2),
            chimney: r.chance(0.3),
        };
        models.push((format!("house-{i}"), parts::house(&params)));
    }
    first_of.insert("house", (start, HOUSE_VARIANTS));
    // Pavement and courtyard ground.
    for (label, count, size, cells, base) in [
        (
            "pavement",
            PAVEMENT_VARIANTS,
            Vec2::new(5.0, 4.0),
            4u32,
            Vec3::new(0.6, 0.58, 0.55),
        ),
        (
            "courtyard",
            COURTYARD_VARIANTS,
            Vec2::splat(28.0),
            0,
            Vec3::new(0.35, 0.45, 0.25),
        ),
    ] {
        let start = models.len();
        for i in 0..count {
            let mut r = root.fork(2 << 32 | (start + i) as u64);
            let s = r.next_u64();
            let colour = parts::near(&mut r, base, 0.15);
            let cells = if cells == 0 {
                0
            } else {
                cells + r.below(3) as u32
            };
            let texture = parts::paving_texture(s, colour, cells)?;
            let tile = if cells == 0 { 4.0 } else { 2.0 };
            models.push((
                format!("{label}-{i}"),
                parts::ground_tile(size, 0.15, texture, tile),
            ));
        }
        first_of.insert(label, (start, count));
    }
    // Roads: three straight variants and a crossing.
    let start = models.len();
    for (i, line) in [
        Vec3::new(0.9, 0.9, 0.9),
        Vec3::new(0.9, 0.8, 0.2),
        Vec3::new(0.8, 0.8, 0.8),
    ]
    .into_iter()
    .enumerate()
    {
        let texture = parts::road_texture(seed ^ i as u64, line)?;
        models.push((
            format!("road-{i}"),
            parts::ground_tile(Vec2::splat(ROAD_WIDTH), 0.0, texture, ROAD_WIDTH),
        ));
    }
    first_of.insert("road", (start, 3));
    let crossing_texture = parts::paving_texture(seed ^ 0xC055, Vec3::splat(0.25), 0)?;
    first_of.insert("crossing", (models.len(), 1));
    models.push((
        "crossing".to_owned(),
        parts::ground_tile(Vec2::splat(ROAD_WIDTH), 0.0, crossing_texture, 5.0),
    ));
    // Trees, lamps and benches.
    let start = models.len();
    for i in 0..TREE_VARIANTS {
        let mut r = root.fork(3 << 32 | i as u64);
        let green = parts::near(&mut r, Vec3::new(0.25, 0.5, 0.18), 0.12);
        let params = TreeParams {
            seed: r.next_u64(),
            height: r.range(6.0, 12.0),
            crown_radius: r.range(1.8, 3.2),
            conifer: i % 3 == 2,
            leaf_colour: srgb(green.x, green.y, green.z),
            bark_colour: srgb(0.35, 0.26, 0.2),
        };
        models.push((format!("street-tree-{i}"), parts::tree(&params)));
    }
    first_of.insert("tree", (start, TREE_VARIANTS));
    first_of.insert("lamp", (models.len(), 2));
    models.push(("lamp-0".to_owned(), parts::lamp(5.0, srgb(0.2, 0.2, 0.22))));
    models.push(("lamp-1".to_owned(), parts::lamp(6.5, srgb(0.1, 0.25, 0.15))));
    first_of.insert("bench", (models.len(), 2));
    models.push(("bench-0".to_owned(), parts::bench(srgb(0.5, 0.35, 0.2))));
    models.push(("bench-1".to_owned(), parts::bench(srgb(0.3, 0.3, 0.32))));

    // Layout.
    let mut rng = root.fork(0x1A70);
    let mut counters: HashMap<&'static str, usize> = HashMap::new();
    let mut pick = |label: &'static str| {
        let (start, count) = first_of[label];
        let c = counters.entry(label).or_insert(0);
        *c += 1;
        start + (*c - 1) % count
    };
    let mut objects: Vec<WorldObject> = Vec::with_capacity(CITY_OBJECTS + 200);
    let mut kinds: Vec<CityKind> = Vec::with_capacity(CITY_OBJECTS + 200);
    let mut push = |objects: &mut Vec<WorldObject>, kind, model, transform| {
        objects.push(WorldObject { model, transform });
        kinds.push(kind);
    };
    'blocks: for bz in 0..CITY_BLOCKS + 2 {
        for bx in 0..CITY_BLOCKS {
            if objects.len() >= CITY_OBJECTS {
                break 'blocks;
            }
            let o = Vec3::new(bx as f32 * BLOCK_PITCH, 0.0, bz as f32 * BLOCK_PITCH);
            let half_road = ROAD_WIDTH * 0.5;
            let crossing = pick("crossing");
            push(
                &mut objects,
                CityKind::Crossing,
                crossing,
                place(o + Vec3::new(half_road, 0.0, half_road), 0.0, 1.0),
            );
            for k in 0..6 {
                let along = ROAD_WIDTH + half_road + ROAD_WIDTH * k as f32;
                let m = pick("road");
                push(
                    &mut objects,
                    CityKind::Road,
                    m,
                    place(o + Vec3::new(along, 0.0, half_road), FRAC_PI_2, 1.0),
                );
                let m = pick("road");
                push(
                    &mut objects,
                    CityKind::Road,
                    m,
                    place(o + Vec3::new(half_road, 0.0, along), 0.0, 1.0),
                );
            }
            // The block interior is [10, 70]^2 relative to o; its centre:
            let centre = o + Vec3::new(40.0, 0.0, 40.0);
            for side in 0..4 {
                let yaw = side as f32 * FRAC_PI_2;
                let rot = Quat::from_rotation_y(yaw);
                // Pavement ring: 12 tiles of 5 m along each side, 2 m in from the kerb.
                for k in 0..12 {
                    let along = -30.0 + 2.5 + 5.0 * k as f32;
                    let m = pick("pavement");
                    push(
                        &mut objects,
                        CityKind::Pavement,
                        m,
                        place(centre + rot * Vec3::new(along, 0.0, 28.0), yaw, 1.0),
                    );
                }
                // Houses facing the street (+Z of the house points outward).
                for k in 0..4 {
                    let along = -19.5 + 13.0 * k as f32 + rng.jitter(0.5);
                    let m = pick("house");
                    push(
                        &mut objects,
                        CityKind::House,
                        m,
                        place(centre + rot * Vec3::new(along, 0.0, 20.0), yaw, 1.0),
                    );
                }
                // Street trees between the houses, and a lamp at the corner.
                for k in 0..4 {
                    let along = -26.0 + 13.0 * k as f32;
                    let m = pick("tree");
                    push(
                        &mut objects,
                        CityKind::Tree,
                        m,
                        place(
                            centre + rot * Vec3::new(along, 0.0, 28.5),
                            rng.angle(),
                            rng.range(0.85, 1.15),
                        ),
                    );
                }
                let m = pick("lamp");
                push(
                    &mut objects,
                    CityKind::Lamp,
                    m,
                    place(centre + rot * Vec3::new(28.5, 0.0, 28.5), yaw + PI, 1.0),
                );
            }
            let m = pick("courtyard");
            push(
                &mut objects,
                CityKind::Courtyard,
                m,
                place(centre, 0.0, 1.0),
            );
            for k in 0..4 {
                let rot = Quat::from_rotation_y(k as f32 * FRAC_PI_2);
                let m = pick("tree");
                push(
                    &mut objects,
                    CityKind::Tree,
                    m,
                    place(
                        centre + rot * Vec3::new(7.0, 0.0, 7.0),
                        rng.angle(),
                        rng.range(0.8, 1.2),
                    ),
                );
            }
            for k in 0..2 {
                let m = pick("bench");
                let z = if k == 0 { 3.0 } else { -3.0 };
                push(
                    &mut objects,
                    CityKind::Bench,
                    m,
                    place(centre + Vec3::new(0.0, 0.0, z), k as f32 * PI, 1.0),
                );
            }
        }
    }
    objects.truncate(CITY_OBJECTS);
    kinds.truncate(CITY_OBJECTS);

    // User models: exactly 3% of the objects, chosen among the props.
    if !extra_models.is_empty() {
        let first_extra = models.len();
        for (i, m) in extra_models.iter().enumerate() {
            models.push((format!("user-{i}"), m.clone()));
        }
        let mut candidates: Vec<usize> = (0..objects.len())
            .filter(|&i| {
                matches!(
                    kinds[i],
                    CityKind::House | CityKind::Tree | CityKind::Lamp | CityKind::Bench
                )
            })
            .collect();
        let mut r = root.fork(0x05E7);
        r.shuffle(&mut candidates);
        let replaced = (objects.len() as f64 * USER_MODEL_FRACTION).round() as usize;
        for (n, &i) in candidates.iter().take(replaced).enumerate() {
            let which = n % extra_models.len();
            let fit = stand_and_fit(&extra_models[which], r.range(2.0, 8.0));
            objects[i] = WorldObject {
                model: first_extra + which,
                transform: objects[i].transform * fit,
            };
        }
    }
    Ok(prune_unused(World { models, objects }))
}

/// A transform scaling `mesh` uniformly so its largest extent is `size`, centred on the
/// origin in X and Z and standing on Y = 0. The identity for an empty or degenerate mesh.
fn stand_and_fit(mesh: &InstancedMesh, size: f32) -> Affine3A {
    let b = mesh.bounds();
    if b.is_empty() {
        return Affine3A::IDENTITY;
    }
    let extent = (b.max - b.min).max_element();
    if !(extent.is_finite() && extent > 0.0) {
        return Affine3A::IDENTITY;
    }
    let s = size / extent;
    let foot = Vec3::new(
        (b.min.x + b.max.x) * 0.5,
        b.min.y,
        (b.min.z + b.max.z) * 0.5,
    );
    Affine3A::from_scale(Vec3::splat(s)) * Affine3A::from_translation(-foot)
}

/// Drops the models no object uses and renumbers the rest, keeping their order.
fn prune_unused(world: World) -> World {
    let mut used = vec![false; world.models.len()];
    for o in &world.objects {
        used[o.model] = true;
    }
    let mut remap = vec![usize::MAX; world.models.len()];
    let mut models = Vec::new();
    for (i, m) in world.models.into_iter().enumerate() {
        if used[i] {
            remap[i] = models.len();
            models.push(m);
        }
    }
    let objects = world
        .objects
        .into_iter()
        .map(|o| WorldObject {
            model: remap[o.model],
            transform: o.transform,
        })
        .collect();
    World { models, objects }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(world: &World, models: Option<usize>, objects: usize) {
        if let Some(m) = models {
            assert_eq!(world.models.len(), m);
        }
        assert_eq!(world.objects.len(), objects);
        let mut used = vec![false; world.models.len()];
        for o in &world.objects {
            used[o.model] = true;
            assert!(o.transform.is_finite());
        }
        assert!(used.iter().all(|&u| u), "every model is used");
        for (name, m) in &world.models {
            m.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
            let t = m.expanded_triangle_count();
            assert!((10..=5_000).contains(&t), "{name}: {t} triangles");
        }
    }

    #[test]
    fn village_has_6_models_and_10000_objects() -> Result<(), WorldgenError> {
        check(&generate_world("village", 1)?, Some(6), 10_000);
        Ok(())
    }

    #[test]
    fn island_has_236_models_and_2362_objects() -> Result<(), WorldgenError> {
        check(&generate_world("island", 1)?, Some(236), 2_362);
        Ok(())
    }

    #[test]
    fn city_has_60000_objects_and_3_percent_user_models() -> Result<(), WorldgenError> {
        let user = parts::rock(9, 1.0, Vec4::ONE);
        let world = generate_world_with("city", 1, &[user])?;
        check(&world, None, 60_000);
        assert!(world.models.len() > 2_000, "{} models", world.models.len());
        let user_index = world
            .models
            .iter()
            .position(|(n, _)| n == "user-0")
            .expect("user model kept");
        let replaced = world
            .objects
            .iter()
            .filter(|o| o.model == user_index)
            .count();
        assert_eq!(replaced, 1_800);
        let textures: usize = world.models.iter().map(|(_, m)| m.textures.len()).sum();
        assert!(textures >= 2_000, "{textures} textures");
        Ok(())
    }

    #[test]
    fn city9_tiles_city_nine_times_sharing_its_models() -> Result<(), WorldgenError> {
        let city = generate_world("city", 2)?;
        let city9 = generate_world("city9", 2)?;
        assert_eq!(city9.objects.len(), 9 * city.objects.len());
        assert_eq!(city9.models.len(), city.models.len());
        assert_eq!(city9.objects[..city.objects.len()], city.objects[..]);
        Ok(())
    }

    #[test]
    fn worlds_are_deterministic_and_seeds_differ() -> Result<(), WorldgenError> {
        let a = generate_world("island", 5)?;
        let b = generate_world("island", 5)?;
        let c = generate_world("island", 6)?;
        assert_eq!(a.objects, b.objects);
        for ((_, x), (_, y)) in a.models.iter().zip(&b.models) {
            assert_eq!(x, y);
        }
        assert_ne!(a.objects, c.objects);
        Ok(())
    }

    #[test]
    fn unknown_world_is_an_error() {
        assert!(matches!(
            generate_world("moon", 1),
            Err(WorldgenError::UnknownWorld { .. })
        ));
    }
}
