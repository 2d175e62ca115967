//! The village of the IAS paper (Azim et al. 2014, Table 2 and figure 7): 79 submeshes,
//! 13,523 instances, about 1.25M expanded triangles.
//!
//! As in the paper, the houses in the middle are instances of six house kinds and the
//! surrounding forest is instances of a single tree; the other submeshes are the ground, roads,
//! parts of houses (roofs, doors, windows, shutters, chimneys, ...), fences, rocks, bushes, grass,
//! and the props of a market square with a church. Layout, in metres, Y up:
//!
//! - a 360 m square of ground, flat in the middle, hilly outside;
//! - four roads each way at ±30 and ±90 m, crossing in 16 places, so 3 × 3 blocks of 54 m;
//! - eight blocks of 12 houses (3 per side, facing the road), the middle one of each side with a
//!   fenced garden, the corner ones with a tree and sometimes a woodpile;
//! - the central block is the market square: church, well, pond, stalls, benches, lamps;
//! - a forest, rocks, bushes and fields all around; grass tufts everywhere fill the instance
//!   count of Table 2.
//!
//! Trees, rocks and bushes are about 15% mirrored; so are left shutters and left cart wheels.

use std::f32::consts::{FRAC_PI_2, PI, TAU};

use glam::{Affine3A, Quat, Vec2, Vec3, Vec4};
use horizon_mesh::{AlphaMode, Material};

use crate::assembly::{double_sided, plain, srgb, textured, trs, ModelBuilder};
use crate::noise::fbm3;
use crate::rng::Rng;
use crate::shapes::{
    cone, cuboid, extrude, frustum, grass_blade, height_field, polar_sheet, subdivided_box, tube,
    uv_sphere, MeshBuilder,
};
use crate::{textures, GeneratedModel, WorldgenError};

/// Builds the village; `seed` shuffles the house kinds over the lots and places everything
/// that grows or lies around.
pub(crate) fn generate(seed: u64) -> Result<GeneratedModel, WorldgenError> {
    let rng = Rng::new(seed);
    let mut model = ModelBuilder::new();
    let materials = Materials::new(&mut model, seed)?;
    let terrain = Terrain {
        seed: rng.fork(9).next_u64(),
    };
    let parts = Parts::new(&mut model, &materials, &terrain, &mut rng.fork(1));
    model.place(parts.ground, Affine3A::IDENTITY);
    place_roads(&mut model, &parts, &mut rng.fork(2));
    place_houses(&mut model, &parts, &terrain, &mut rng.fork(3));
    place_market_square(&mut model, &parts, &mut rng.fork(4));
    place_countryside(&mut model, &parts, &terrain, &mut rng.fork(5));
    place_grass(&mut model, &parts, &terrain, &mut rng.fork(6));
    Ok(model.finish())
}

/// Instances in all, from Table 2; grass tufts fill whatever the other parts leave.
const TOTAL_INSTANCES: usize = 13_523;
/// Trees of the forest around the village (64 more stand behind houses).
const FOREST_TREES: usize = 2_536;
/// Share of trees, rocks and bushes placed mirrored.
const MIRRORED: f32 = 0.15;

/// Road centre lines, each way.
const ROAD_LINES: [f32; 4] = [-90.0, -30.0, 30.0, 90.0];
/// Roads run out to this distance from the centre.
const ROAD_END: f32 = 120.0;
/// Width of a road.
const ROAD_WIDTH: f32 = 6.0;
/// Length of the straight road tile before scaling.
const ROAD_TILE: f32 = 10.0;
/// Half the side of a block between roads.
const BLOCK_HALF: f32 = 27.0;
/// Half the side of the ground square.
const GROUND_HALF: f32 = 180.0;
/// The forest starts this far (in the max norm) from the centre.
const FOREST_START: f32 = 128.0;

// ---------------------------------------------------------------------------------------------
// Materials and terrain
// ---------------------------------------------------------------------------------------------

/// Material indices of the village.
struct Materials {
    grass: usize,
    cobbles: usize,
    plaster: usize,
    roof_tiles: usize,
    wood: usize,
    stone: usize,
    /// White, untextured: vertex colours give the colour.
    painted: usize,
    /// Like `painted`, drawn from both sides, for grass and flowers.
    foliage: usize,
    canvas: usize,
    burlap: usize,
    iron: usize,
    hay: usize,
    soil: usize,
    water: usize,
}

impl Materials {
    fn new(model: &mut ModelBuilder, seed: u64) -> Result<Self, WorldgenError> {
        let mut texture_material = |name: &str, texture, tint, roughness| {
            let t = model.texture(texture);
            model.material(textured(name, t, tint, roughness))
        };
        let grass = texture_material("grass", textures::grass(seed)?, Vec4::ONE, 1.0);
        let cobbles = texture_material("cobbles", textures::cobbles(seed)?, Vec4::ONE, 0.9);
        let plaster = texture_material("plaster", textures::plaster(seed)?, Vec4::ONE, 0.95);
        let roof_tiles =
            texture_material("roof-tiles", textures::roof_tiles(seed)?, Vec4::ONE, 0.8);
        let wood = texture_material("wood", textures::wood(seed)?, srgb(0.85, 0.8, 0.75), 0.8);
        let stone = texture_material("stone", textures::stone(seed)?, Vec4::ONE, 0.9);
        Ok(Self {
            grass,
            cobbles,
            plaster,
            roof_tiles,
            wood,
            stone,
            painted: model.material(plain("painted", Vec4::ONE, 0.7)),
            foliage: model.material(double_sided(plain("foliage", Vec4::ONE, 0.9))),
            canvas: model.material(plain("canvas", srgb(0.75, 0.2, 0.15), 0.9)),
            burlap: model.material(plain("burlap", srgb(0.7, 0.6, 0.42), 1.0)),
            iron: model.material(Material {
                metallic_factor: 0.9,
                ..plain("iron", srgb(0.18, 0.18, 0.2), 0.5)
            }),
            hay: model.material(plain("hay", srgb(0.85, 0.74, 0.38), 1.0)),
            soil: model.material(plain("soil", srgb(0.3, 0.22, 0.15), 1.0)),
            water: model.material(Material {
                alpha_mode: AlphaMode::Blend,
                ..plain("water", Vec4::new(0.1, 0.25, 0.35, 0.8), 0.1)
            }),
        })
    }
}

/// The ground's height: flat in the village square, rolling hills outside.
#[derive(Clone, Copy, Debug)]
struct Terrain {
    seed: u64,
}

impl Terrain {
    fn height(&self, x: f32, z: f32) -> f32 {
        let from_centre = x.abs().max(z.abs());
        let hills = (fbm3(self.seed, Vec3::new(x, 0.0, z) * 0.012, 4) - 0.5) * 14.0;
        hills * smoothstep(125.0, 150.0, from_centre)
    }

    /// A point on the ground.
    fn at(&self, x: f32, z: f32) -> Vec3 {
        Vec3::new(x, self.height(x, z), z)
    }
}

// ---------------------------------------------------------------------------------------------
// Houses
// ---------------------------------------------------------------------------------------------

/// The walls of a house, in its own frame: front +X (facing the road), back −X, gables ±Z.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Wall {
    Front,
    Back,
    RightGable,
    LeftGable,
}

/// One of the six house kinds. Its body is a profile in the XY plane (X across, Y up)
/// extruded along Z (the ridge); its roof follows the profile's top edges.
#[derive(Clone, Copy, Debug)]
struct HouseKind {
    name: &'static str,
    /// Size across the ridge (X).
    depth: f32,
    /// Size along the ridge (Z).
    frontage: f32,
    front_wall: f32,
    back_wall: f32,
    ridge_height: f32,
    /// Offset of the ridge from the middle, towards the front (a saltbox has it off centre).
    ridge_x: f32,
    arched_door: bool,
    door_z: f32,
    door_scale: Vec3,
    tall_windows: bool,
    /// (wall, storey, offset along the wall).
    windows: &'static [(Wall, u32, f32)],
    shutters: bool,
    flower_boxes: bool,
    chimney: Option<Chimney>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Chimney {
    Square,
    Round,
}

// Short wall names, so that the window lists below read as a table.
use Wall::{Back, Front, LeftGable, RightGable};

const HOUSE_KINDS: [HouseKind; 6] = [
    HouseKind {
        name: "cottage",
        depth: 6.0,
        frontage: 8.0,
        front_wall: 3.0,
        back_wall: 3.0,
        ridge_height: 5.6,
        ridge_x: 0.0,
        arched_door: false,
        door_z: 0.0,
        door_scale: Vec3::ONE,
        tall_windows: false,
        windows: &[
            (Front, 0, -2.0),
            (Front, 0, 2.0),
            (Back, 0, -2.0),
            (Back, 0, 2.0),
            (RightGable, 0, 0.0),
            (LeftGable, 0, 0.0),
        ],
        shutters: true,
        flower_boxes: false,
        chimney: Some(Chimney::Square),
    },
    HouseKind {
        name: "longhouse",
        depth: 7.0,
        frontage: 10.0,
        front_wall: 3.2,
        back_wall: 3.2,
        ridge_height: 6.4,
        ridge_x: 0.0,
        arched_door: true,
        door_z: -3.0,
        door_scale: Vec3::ONE,
        tall_windows: false,
        windows: &[
            (Front, 0, -0.5),
            (Front, 0, 1.8),
            (Front, 0, 4.0),
            (Back, 0, -3.0),
            (Back, 0, 0.0),
            (Back, 0, 3.0),
        ],
        shutters: false,
        flower_boxes: true,
        chimney: Some(Chimney::Round),
    },
    HouseKind {
        name: "townhouse",
        depth: 7.0,
        frontage: 8.0,
        front_wall: 6.0,
        back_wall: 6.0,
        ridge_height: 9.0,
        ridge_x: 0.0,
        arched_door: false,
        door_z: -2.0,
        door_scale: Vec3::ONE,
        tall_windows: true,
        windows: &[
            (Front, 0, 1.8),
            (Front, 1, -2.0),
            (Front, 1, 0.0),
            (Front, 1, 2.0),
            (Back, 0, -2.0),
            (Back, 0, 2.0),
            (Back, 1, -2.0),
            (Back, 1, 2.0),
            (RightGable, 1, 0.0),
            (LeftGable, 1, 0.0),
        ],
        shutters: true,
        flower_boxes: false,
        chimney: Some(Chimney::Square),
    },
    HouseKind {
        name: "saltbox",
        depth: 8.0,
        frontage: 9.0,
        front_wall: 5.6,
        back_wall: 3.0,
        ridge_height: 7.6,
        ridge_x: 1.5,
        arched_door: true,
        door_z: 0.0,
        door_scale: Vec3::ONE,
        tall_windows: true,
        windows: &[
            (Front, 0, -2.5),
            (Front, 0, 2.5),
            (Front, 1, -2.5),
            (Front, 1, 2.5),
            (Back, 0, -2.0),
            (Back, 0, 2.0),
            (RightGable, 0, 0.0),
            (LeftGable, 0, 0.0),
        ],
        shutters: false,
        flower_boxes: true,
        chimney: Some(Chimney::Round),
    },
    HouseKind {
        name: "barn-house",
        depth: 8.0,
        frontage: 10.0,
        front_wall: 3.5,
        back_wall: 3.5,
        ridge_height: 7.5,
        ridge_x: 0.0,
        arched_door: false,
        door_z: 0.0,
        door_scale: Vec3::new(1.6, 1.2, 1.0),
        tall_windows: false,
        windows: &[
            (Front, 0, -3.0),
            (Front, 0, 3.0),
            (RightGable, 0, -2.0),
            (RightGable, 0, 2.0),
            (LeftGable, 0, -2.0),
            (LeftGable, 0, 2.0),
        ],
        shutters: true,
        flower_boxes: false,
        chimney: None,
    },
    HouseKind {
        name: "villa",
        depth: 8.0,
        frontage: 10.0,
        front_wall: 6.0,
        back_wall: 6.0,
        ridge_height: 9.5,
        ridge_x: 0.0,
        arched_door: true,
        door_z: 0.0,
        door_scale: Vec3::ONE,
        tall_windows: true,
        windows: &[
            (Front, 0, -3.5),
            (Front, 0, -1.8),
            (Front, 0, 1.8),
            (Front, 0, 3.5),
            (Front, 1, -3.5),
            (Front, 1, 0.0),
            (Front, 1, 3.5),
            (Back, 0, -3.0),
            (Back, 0, 3.0),
            (RightGable, 0, 0.0),
            (LeftGable, 0, 0.0),
        ],
        shutters: false,
        flower_boxes: true,
        chimney: None,
    },
];

impl HouseKind {
    /// The body's cross-section, counter-clockwise.
    fn profile(&self) -> [Vec2; 5] {
        let h = self.depth * 0.5;
        [
            Vec2::new(-h, 0.0),
            Vec2::new(h, 0.0),
            Vec2::new(h, self.front_wall),
            Vec2::new(self.ridge_x, self.ridge_height),
            Vec2::new(-h, self.back_wall),
        ]
    }

    /// Height of the roof's underside at `x`.
    fn roof_height(&self, x: f32) -> f32 {
        let h = self.depth * 0.5;
        if x <= self.ridge_x {
            let t = (x + h) / (self.ridge_x + h);
            self.back_wall + (self.ridge_height - self.back_wall) * t
        } else {
            let t = (h - x) / (h - self.ridge_x);
            self.front_wall + (self.ridge_height - self.front_wall) * t
        }
    }

    /// Where a window sits on `wall` at `storey` and `offset`, and how it is turned (its +Z
    /// out of the wall).
    fn window_spot(&self, wall: Wall, storey: u32, offset: f32) -> (Vec3, Quat) {
        let y = 1.7 + 2.8 * storey as f32;
        let (h, f) = (self.depth * 0.5 + 0.03, self.frontage * 0.5 + 0.03);
        match wall {
            Front => (Vec3::new(h, y, offset), Quat::from_rotation_y(FRAC_PI_2)),
            Back => (Vec3::new(-h, y, offset), Quat::from_rotation_y(-FRAC_PI_2)),
            RightGable => (Vec3::new(offset, y, f), Quat::IDENTITY),
            LeftGable => (Vec3::new(offset, y, -f), Quat::from_rotation_y(PI)),
        }
    }
}

/// A roof slab over the lines from `back_eave` up to `ridge` and down to `front_eave`, reaching
/// `overhang` beyond the eaves, `thickness` thick: a 6-point chevron, counter-clockwise.
fn roof_profile(
    back_eave: Vec2,
    ridge: Vec2,
    front_eave: Vec2,
    overhang: f32,
    thickness: f32,
) -> Vec<Vec2> {
    let back = back_eave + (back_eave - ridge).normalize() * overhang;
    let front = front_eave + (front_eave - ridge).normalize() * overhang;
    let up_left = (ridge - back).normalize().perp();
    let up_right = (front - ridge).normalize().perp();
    let miter = (up_left + up_right) * (thickness / (1.0 + up_left.dot(up_right)));
    // Lifted a little so the slab does not coincide with the walls' top faces.
    let lift = Vec2::new(0.0, 0.03);
    [
        back,
        ridge,
        front,
        front + up_right * thickness,
        ridge + miter,
        back + up_left * thickness,
    ]
    .map(|p| p + lift)
    .to_vec()
}

/// A roof slab: `profile` (from [`roof_profile`]) extruded over `length` along Z, centred, with
/// its texture turned so that rows of tiles run along the eaves, a tile row every 2 m.
/// 12 slices + 8 triangles.
fn roof_slab(profile: &[Vec2], length: f32, slices: u32) -> MeshBuilder {
    extrude(profile, length, slices, 20.0)
        .transformed(Affine3A::from_translation(Vec3::Z * (-0.5 * length)))
        .mapped_uvs(|uv| Vec2::new(uv.y, uv.x) * 0.5)
}

// ---------------------------------------------------------------------------------------------
// The 79 submeshes
// ---------------------------------------------------------------------------------------------

/// Submesh indices of every part of the village.
struct Parts {
    ground: usize,
    road_straight: usize,
    road_crossing: usize,
    house_bodies: Vec<usize>,
    house_roofs: Vec<usize>,
    door_plank: usize,
    door_arched: usize,
    window_square: usize,
    window_tall: usize,
    shutter: usize,
    chimney_square: usize,
    chimney_round: usize,
    doorstep: usize,
    flower_box: usize,
    tree: usize,
    fence_post: usize,
    fence_rail: usize,
    fence_gate: usize,
    rocks: Vec<usize>,
    bushes: Vec<usize>,
    grass_tufts: Vec<usize>,
    flower_patches: Vec<usize>,
    well_wall: usize,
    well_post: usize,
    well_roof: usize,
    stall_counter: usize,
    stall_awning: usize,
    crate_box: usize,
    barrel: usize,
    sack: usize,
    lamp_post: usize,
    lantern: usize,
    bench: usize,
    haystack: usize,
    church_nave: usize,
    church_roof: usize,
    church_tower: usize,
    church_spire: usize,
    stump: usize,
    log: usize,
    woodpile: usize,
    garden_bed: usize,
    pond: usize,
    stepping_stone: usize,
    cart_body: usize,
    cart_wheel: usize,
}

impl Parts {
    /// Builds and registers all 79 submeshes.
    fn new(model: &mut ModelBuilder, m: &Materials, terrain: &Terrain, rng: &mut Rng) -> Self {
        let half_metre = Vec2::splat(0.5);
        // Ground and roads.
        let ground = height_field(Vec2::splat(2.0 * GROUND_HALF), [54, 54], 0.25, |x, z| {
            terrain.height(x, z)
        });
        let ground = model.submesh("ground", false, ground, m.grass);
        let road_straight = subdivided_box(Vec3::new(ROAD_TILE, 0.2, ROAD_WIDTH), [4, 1, 2]);
        let road_straight = model.submesh(
            "road-straight",
            true,
            road_straight.scaled_uvs(Vec2::splat(0.25)),
            m.cobbles,
        );
        let road_crossing = subdivided_box(Vec3::new(ROAD_WIDTH, 0.2, ROAD_WIDTH), [2, 1, 2]);
        let road_crossing = model.submesh(
            "road-crossing",
            true,
            road_crossing.scaled_uvs(Vec2::splat(0.25)),
            m.cobbles,
        );

        // The six house kinds: a body and a roof each.
        let mut house_bodies = Vec::new();
        let mut house_roofs = Vec::new();
        for kind in &HOUSE_KINDS {
            let centre = Affine3A::from_translation(Vec3::new(0.0, 0.0, -0.5 * kind.frontage));
            let body = extrude(&kind.profile(), kind.frontage, 3, 20.0).transformed(centre);
            let body = model.submesh(
                format!("house-body-{}", kind.name),
                true,
                body.scaled_uvs(half_metre),
                m.plaster,
            );
            house_bodies.push(body);
            let [_, _, front_top, ridge, back_top] = kind.profile();
            let roof = roof_profile(back_top, ridge, front_top, 0.5, 0.25);
            let length = kind.frontage + 0.8;
            let roof = roof_slab(&roof, length, 3);
            let roof = model.submesh(
                format!("house-roof-{}", kind.name),
                true,
                roof,
                m.roof_tiles,
            );
            house_roofs.push(roof);
        }

        // Parts shared by the house kinds.
        let door_plank =
            cuboid(Vec3::new(1.0, 2.0, 0.08)).transformed(Affine3A::from_translation(Vec3::Y));
        let door_plank = model.submesh("door-plank", true, door_plank, m.wood);
        let door_arched = model.submesh("door-arched", true, arched_door(), m.wood);
        let window_square = model.submesh("window-square", true, window(1.0, 1.1, 1), m.painted);
        let window_tall = model.submesh("window-tall", true, window(0.8, 1.5, 2), m.painted);
        let shutter = model.submesh("shutter", true, shutter(), m.painted);
        let chimney_square = MeshBuilder::merge([
            cuboid(Vec3::new(0.7, 2.2, 0.7)).transformed(Affine3A::from_translation(Vec3::Y * 1.1)),
            cuboid(Vec3::new(0.9, 0.15, 0.9))
                .transformed(Affine3A::from_translation(Vec3::Y * 2.2)),
        ]);
        let chimney_square = model.submesh(
            "chimney-square",
            true,
            chimney_square.scaled_uvs(half_metre),
            m.stone,
        );
        let chimney_round = model.submesh(
            "chimney-round",
            true,
            frustum(0.32, 0.26, 2.2, 12, 1),
            m.stone,
        );
        let doorstep = subdivided_box(Vec3::new(1.4, 0.2, 0.6), [2, 1, 1]);
        let doorstep = model.submesh("doorstep", true, doorstep, m.stone);
        let flower_box = model.submesh("flower-box", true, flower_box(), m.painted);

        // The one tree, fences, and what grows and lies around.
        let tree = model.submesh("tree", true, tree(rng.next_u64()), m.painted);
        let fence_post = [
            Vec2::new(-0.06, 0.0),
            Vec2::new(0.06, 0.0),
            Vec2::new(0.06, 1.0),
            Vec2::new(0.0, 1.1),
            Vec2::new(-0.06, 1.0),
        ];
        let fence_post = extrude(&fence_post, 0.12, 1, 20.0)
            .transformed(Affine3A::from_translation(Vec3::new(0.0, 0.0, -0.06)));
        let fence_post = model.submesh("fence-post", true, fence_post, m.wood);
        let fence_rail = model.submesh(
            "fence-rail",
            true,
            cuboid(Vec3::new(2.0, 0.08, 0.04)),
            m.wood,
        );
        let fence_gate = model.submesh("fence-gate", true, gate(), m.wood);

        let rocks = (0..14)
            .map(|k| {
                let squash = Vec3::new(
                    rng.range(0.8, 1.2),
                    rng.range(0.45, 0.8),
                    rng.range(0.7, 1.0),
                );
                let rock = lumpy_sphere(rng.next_u64(), 1.0, 10, 7, rng.range(0.25, 0.45), squash);
                model.submesh(
                    format!("rock-{k:02}"),
                    true,
                    rock.scaled_uvs(Vec2::new(3.0, 1.5)),
                    m.stone,
                )
            })
            .collect();
        let bushes = (0..6)
            .map(|k| model.submesh(format!("bush-{k}"), true, bush(rng), m.painted))
            .collect();
        let grass_tufts = [5u32, 6, 4, 7]
            .iter()
            .enumerate()
            .map(|(k, &blades)| {
                model.submesh(
                    format!("grass-tuft-{k}"),
                    false,
                    grass_tuft(rng, blades),
                    m.foliage,
                )
            })
            .collect();
        let flower_colours = [
            srgb(0.8, 0.1, 0.1),
            srgb(0.95, 0.8, 0.1),
            srgb(0.55, 0.3, 0.75),
        ];
        let flower_patches = flower_colours
            .iter()
            .enumerate()
            .map(|(k, &c)| {
                model.submesh(
                    format!("flower-patch-{k}"),
                    false,
                    flower_patch(rng, c),
                    m.foliage,
                )
            })
            .collect();

        // The market square.
        let well_wall = model.submesh(
            "well-wall",
            true,
            frustum(1.0, 1.0, 0.9, 16, 2).scaled_uvs(half_metre),
            m.stone,
        );
        let well_post = cuboid(Vec3::new(0.15, 2.4, 0.15))
            .transformed(Affine3A::from_translation(Vec3::Y * 1.2));
        let well_post = model.submesh("well-post", true, well_post, m.wood);
        let well_roof = roof_profile(
            Vec2::new(-1.3, 0.0),
            Vec2::new(0.0, 0.9),
            Vec2::new(1.3, 0.0),
            0.2,
            0.08,
        );
        let well_roof = model.submesh(
            "well-roof",
            true,
            roof_slab(&well_roof, 2.0, 1),
            m.roof_tiles,
        );
        let stall_counter = model.submesh("stall-counter", true, stall_counter(), m.wood);
        let awning = roof_profile(
            Vec2::new(-1.3, 0.0),
            Vec2::new(0.0, 0.5),
            Vec2::new(1.3, 0.0),
            0.1,
            0.04,
        );
        let awning =
            extrude(&awning, 2.6, 3, 20.0).transformed(Affine3A::from_translation(Vec3::Z * -1.3));
        let stall_awning = model.submesh("stall-awning", true, awning, m.canvas);
        let crate_box = subdivided_box(Vec3::splat(0.6), [2, 2, 2])
            .transformed(Affine3A::from_translation(Vec3::Y * 0.3));
        let crate_box = model.submesh(
            "crate",
            true,
            crate_box.scaled_uvs(Vec2::splat(1.5)),
            m.wood,
        );
        let barrel_path: Vec<Vec3> = (0..5).map(|k| Vec3::Y * (0.2 * k as f32)).collect();
        let barrel = tube(&barrel_path, &[0.28, 0.33, 0.35, 0.33, 0.28], 12);
        let barrel = model.submesh("barrel", true, barrel, m.wood);
        let sack = lumpy_sphere(rng.next_u64(), 0.35, 8, 6, 0.2, Vec3::new(1.0, 1.3, 0.9));
        let sack = model.submesh(
            "sack",
            true,
            sack.transformed(Affine3A::from_translation(Vec3::Y * 0.4)),
            m.burlap,
        );
        let lamp_post = MeshBuilder::merge([
            frustum(0.08, 0.06, 3.2, 6, 1),
            cuboid(Vec3::splat(0.3)).transformed(Affine3A::from_translation(Vec3::Y * 0.15)),
            cuboid(Vec3::new(0.6, 0.05, 0.05))
                .transformed(Affine3A::from_translation(Vec3::new(0.3, 3.1, 0.0))),
        ]);
        let lamp_post = model.submesh("lamp-post", true, lamp_post, m.iron);
        let lantern = MeshBuilder::merge([
            cuboid(Vec3::new(0.22, 0.3, 0.22)).painted(srgb(1.0, 0.85, 0.4)),
            cone(0.2, 0.18, 6)
                .transformed(Affine3A::from_translation(Vec3::Y * 0.15))
                .painted(srgb(0.15, 0.15, 0.17)),
        ]);
        let lantern = model.submesh("lantern", true, lantern, m.painted);
        let bench = model.submesh("bench", true, bench(), m.wood);
        let haystack = lumpy_sphere(rng.next_u64(), 1.4, 12, 8, 0.15, Vec3::new(1.0, 0.8, 1.0));
        let haystack = model.submesh(
            "haystack",
            true,
            haystack.transformed(Affine3A::from_translation(Vec3::Y * 0.8)),
            m.hay,
        );

        // The church.
        let nave_profile = [
            Vec2::new(-5.0, 0.0),
            Vec2::new(5.0, 0.0),
            Vec2::new(5.0, 7.0),
            Vec2::new(0.0, 11.0),
            Vec2::new(-5.0, 7.0),
        ];
        let nave = extrude(&nave_profile, 20.0, 4, 20.0)
            .transformed(Affine3A::from_translation(Vec3::Z * -10.0));
        let church_nave = model.submesh("church-nave", true, nave.scaled_uvs(half_metre), m.stone);
        let church_roof = roof_profile(nave_profile[4], nave_profile[3], nave_profile[2], 0.6, 0.3);
        let church_roof = roof_slab(&church_roof, 21.0, 4);
        let church_roof = model.submesh("church-roof", true, church_roof, m.roof_tiles);
        let tower = subdivided_box(Vec3::new(5.0, 16.0, 5.0), [2, 6, 2])
            .transformed(Affine3A::from_translation(Vec3::Y * 8.0));
        let church_tower =
            model.submesh("church-tower", true, tower.scaled_uvs(half_metre), m.stone);
        let church_spire = model.submesh(
            "church-spire",
            true,
            cone(3.4, 9.0, 8).scaled_uvs(half_metre),
            m.roof_tiles,
        );

        // Wood, garden and pond props, and the carts.
        let stump = model.submesh("stump", true, frustum(0.35, 0.3, 0.5, 10, 1), m.wood);
        let log_path = [
            Vec3::new(-1.5, 0.0, 0.0),
            Vec3::new(-0.5, 0.02, 0.0),
            Vec3::new(0.5, -0.02, 0.0),
            Vec3::new(1.5, 0.0, 0.0),
        ];
        let log = tube(&log_path, &[0.22, 0.23, 0.22, 0.2], 10)
            .transformed(Affine3A::from_translation(Vec3::Y * 0.22));
        let log = model.submesh("log", true, log, m.wood);
        let woodpile = model.submesh("woodpile", true, woodpile(), m.wood);
        let garden_bed = subdivided_box(Vec3::new(2.5, 0.3, 5.0), [3, 1, 2]);
        let garden_bed = model.submesh("garden-bed", true, garden_bed, m.soil);
        let pond = polar_sheet(
            24,
            3,
            Vec3::Y,
            |theta, f| {
                let r = 5.0 * f * (1.0 + 0.15 * (3.0 * theta).sin());
                Vec3::new(r * theta.cos(), 0.0, r * theta.sin())
            },
            |p| Vec2::new(p.x, p.z) * 0.2,
        );
        let pond = model.submesh("pond", false, pond, m.water);
        let stepping_stone = lumpy_sphere(rng.next_u64(), 0.4, 8, 5, 0.2, Vec3::new(1.0, 0.3, 0.8));
        let stepping_stone = model.submesh("stepping-stone", true, stepping_stone, m.stone);
        let cart_body = model.submesh("cart-body", true, cart_body(), m.wood);
        let cart_wheel = model.submesh("cart-wheel", true, cart_wheel(), m.wood);

        Self {
            ground,
            road_straight,
            road_crossing,
            house_bodies,
            house_roofs,
            door_plank,
            door_arched,
            window_square,
            window_tall,
            shutter,
            chimney_square,
            chimney_round,
            doorstep,
            flower_box,
            tree,
            fence_post,
            fence_rail,
            fence_gate,
            rocks,
            bushes,
            grass_tufts,
            flower_patches,
            well_wall,
            well_post,
            well_roof,
            stall_counter,
            stall_awning,
            crate_box,
            barrel,
            sack,
            lamp_post,
            lantern,
            bench,
            haystack,
            church_nave,
            church_roof,
            church_tower,
            church_spire,
            stump,
            log,
            woodpile,
            garden_bed,
            pond,
            stepping_stone,
            cart_body,
            cart_wheel,
        }
    }
}

/// A door with a round top: an 11-point profile extruded 8 cm, bottom centre at the origin.
fn arched_door() -> MeshBuilder {
    let mut outline = vec![Vec2::new(-0.5, 0.0), Vec2::new(0.5, 0.0)];
    outline
        .extend((0..9).map(|i| Vec2::new(0.0, 1.6) + 0.5 * Vec2::from_angle(PI * i as f32 / 8.0)));
    extrude(&outline, 0.08, 1, 30.0).transformed(Affine3A::from_translation(Vec3::Z * -0.04))
}

/// A painted window centred on the origin, facing +Z: frame, glass, a mullion and `transoms`
/// cross bars. The boxes overlap but share no corner, so the compound stays closed when welded.
fn window(width: f32, height: f32, transoms: u32) -> MeshBuilder {
    let frame = srgb(0.92, 0.9, 0.85);
    let glass = srgb(0.16, 0.22, 0.3);
    let bar = 0.08;
    let at = |x: f32, y: f32, z: f32| Affine3A::from_translation(Vec3::new(x, y, z));
    let mut parts = vec![
        cuboid(Vec3::new(width - 0.1, height - 0.1, 0.03)).painted(glass),
        cuboid(Vec3::new(bar, height, 0.1))
            .transformed(at(-(width - bar) / 2.0, 0.0, 0.0))
            .painted(frame),
        cuboid(Vec3::new(bar, height, 0.1))
            .transformed(at((width - bar) / 2.0, 0.0, 0.0))
            .painted(frame),
        cuboid(Vec3::new(width, bar, 0.09))
            .transformed(at(0.0, (height - bar) / 2.0, 0.0))
            .painted(frame),
        cuboid(Vec3::new(width, bar, 0.09))
            .transformed(at(0.0, -(height - bar) / 2.0, 0.0))
            .painted(frame),
        cuboid(Vec3::new(0.05, height, 0.06)).painted(frame),
    ];
    for t in 0..transoms {
        let y = height * ((t + 1) as f32 / (transoms + 1) as f32 - 0.5);
        parts.push(
            cuboid(Vec3::new(width, 0.05, 0.06))
                .transformed(at(0.0, y, 0.0))
                .painted(frame),
        );
    }
    MeshBuilder::merge(parts)
}

/// A green board shutter for the right of a 1.1 m window, with a diagonal brace (so its mirror
/// image, on the left, is really different).
fn shutter() -> MeshBuilder {
    let green = srgb(0.2, 0.42, 0.3);
    let at = |y: f32| Affine3A::from_translation(Vec3::new(0.0, y, 0.03));
    MeshBuilder::merge([
        cuboid(Vec3::new(0.45, 1.1, 0.04)),
        cuboid(Vec3::new(0.45, 0.08, 0.03)).transformed(at(0.4)),
        cuboid(Vec3::new(0.45, 0.08, 0.03)).transformed(at(-0.4)),
        cuboid(Vec3::new(0.06, 0.9, 0.03)).transformed(at(0.0) * Affine3A::from_rotation_z(0.45)),
    ])
    .painted(green)
}

/// A window box of flowers: a brown box and four round blossoms.
fn flower_box() -> MeshBuilder {
    let mut parts = vec![cuboid(Vec3::new(0.9, 0.2, 0.22)).painted(srgb(0.4, 0.26, 0.15))];
    for (k, x) in [-0.3f32, -0.1, 0.1, 0.3].into_iter().enumerate() {
        let colour = if k % 2 == 0 {
            srgb(0.85, 0.15, 0.2)
        } else {
            srgb(0.95, 0.75, 0.2)
        };
        parts.push(
            uv_sphere(0.09, 6, 4)
                .transformed(Affine3A::from_translation(Vec3::new(x, 0.15, 0.0)))
                .painted(colour),
        );
    }
    MeshBuilder::merge(parts)
}

/// The village's one tree: a trunk and two overlapping lumpy crowns, painted. 272 triangles.
fn tree(seed: u64) -> MeshBuilder {
    let trunk = frustum(0.22, 0.15, 2.6, 8, 1).painted(srgb(0.35, 0.25, 0.17));
    let crown = |s: u64, radius: f32, centre: Vec3| {
        lumpy_sphere(s, radius, 10, 7, 0.3, Vec3::ONE)
            .transformed(Affine3A::from_translation(centre))
            .painted_with(move |p| {
                let n = fbm3(s ^ 0xC0, p * 1.7, 2);
                srgb(0.16, 0.36, 0.12).lerp(srgb(0.32, 0.5, 0.18), n)
            })
    };
    MeshBuilder::merge([
        trunk,
        crown(seed, 1.6, Vec3::new(0.0, 3.4, 0.0)),
        crown(seed.wrapping_add(1), 1.2, Vec3::new(0.5, 4.5, 0.3)),
    ])
}

/// A sphere of `radius` roughened by noise and squashed per axis; closed.
fn lumpy_sphere(
    seed: u64,
    radius: f32,
    segments: u32,
    rings: u32,
    roughness: f32,
    squash: Vec3,
) -> MeshBuilder {
    uv_sphere(radius, segments, rings).displaced(move |p| {
        let bump = 1.0 + roughness * 2.0 * (fbm3(seed, p / radius * 1.5, 3) - 0.5);
        p * bump * squash
    })
}

/// A bush: two overlapping lumpy spheres in greens. 160 triangles.
fn bush(rng: &mut Rng) -> MeshBuilder {
    let seed = rng.next_u64();
    let shade = rng.range(0.0, 1.0);
    let colour = move |p: Vec3| {
        let n = fbm3(seed ^ 0xB5, p * 2.0, 2);
        srgb(0.14, 0.3 + 0.08 * shade, 0.1).lerp(srgb(0.3, 0.45, 0.16), n)
    };
    let squash = Vec3::new(1.0, rng.range(0.6, 0.9), rng.range(0.8, 1.0));
    MeshBuilder::merge([
        lumpy_sphere(seed, 0.8, 8, 6, 0.35, squash)
            .transformed(Affine3A::from_translation(Vec3::Y * 0.5)),
        lumpy_sphere(seed ^ 1, 0.6, 8, 6, 0.35, squash)
            .transformed(Affine3A::from_translation(Vec3::new(0.6, 0.4, 0.2))),
    ])
    .painted_with(colour)
}

/// A tuft of `blades` grass blades leaning outwards, painted dark at the root and light at the
/// tip. Open; 6 triangles per blade.
fn grass_tuft(rng: &mut Rng, blades: u32) -> MeshBuilder {
    let parts: Vec<MeshBuilder> = (0..blades)
        .map(|b| {
            let angle = TAU * b as f32 / blades as f32 + rng.jitter(0.4);
            let height = rng.range(0.3, 0.6);
            let blade = grass_blade(height, 0.05, 3, Vec3::new(0.0, 0.0, rng.range(0.05, 0.2)));
            blade
                .transformed(
                    Affine3A::from_rotation_y(angle) * Affine3A::from_translation(Vec3::Z * 0.03),
                )
                .painted_with(move |p| {
                    srgb(0.15, 0.32, 0.08).lerp(srgb(0.45, 0.6, 0.2), p.y / height)
                })
        })
        .collect();
    MeshBuilder::merge(parts)
}

/// A patch of four leaves and three blossoms of `colour`. Open (the leaves); 132 triangles.
fn flower_patch(rng: &mut Rng, colour: Vec4) -> MeshBuilder {
    let mut parts = Vec::new();
    for b in 0..4 {
        let angle = TAU * b as f32 / 4.0 + rng.jitter(0.3);
        let blade = grass_blade(0.35, 0.08, 3, Vec3::new(0.0, 0.0, 0.12));
        parts.push(
            blade
                .transformed(Affine3A::from_rotation_y(angle))
                .painted(srgb(0.2, 0.45, 0.15)),
        );
    }
    for f in 0..3 {
        let angle = TAU * f as f32 / 3.0 + rng.jitter(0.5);
        let at = Vec3::new(0.12 * angle.cos(), rng.range(0.3, 0.45), 0.12 * angle.sin());
        parts.push(
            uv_sphere(0.05, 6, 4)
                .transformed(Affine3A::from_translation(at))
                .painted(colour),
        );
    }
    MeshBuilder::merge(parts)
}

/// Wooden boxes of (size, centre), merged.
fn boxes(parts: &[(Vec3, Vec3)]) -> MeshBuilder {
    MeshBuilder::merge(
        parts
            .iter()
            .map(|&(size, centre)| cuboid(size).transformed(Affine3A::from_translation(centre))),
    )
}

/// A 2 m field gate: stiles, rails, a brace and palings. 96 triangles.
fn gate() -> MeshBuilder {
    let mut g = boxes(&[
        (Vec3::new(0.08, 1.0, 0.05), Vec3::new(-0.95, 0.5, 0.0)),
        (Vec3::new(0.08, 1.0, 0.05), Vec3::new(0.95, 0.5, 0.0)),
        (Vec3::new(2.0, 0.08, 0.05), Vec3::new(0.0, 0.25, 0.0)),
        (Vec3::new(2.0, 0.08, 0.05), Vec3::new(0.0, 0.85, 0.0)),
        (Vec3::new(0.1, 0.9, 0.03), Vec3::new(-0.5, 0.5, 0.04)),
        (Vec3::new(0.1, 0.9, 0.03), Vec3::new(0.0, 0.5, 0.04)),
        (Vec3::new(0.1, 0.9, 0.03), Vec3::new(0.5, 0.5, 0.04)),
    ]);
    let brace =
        Affine3A::from_translation(Vec3::new(0.0, 0.55, -0.04)) * Affine3A::from_rotation_z(1.1);
    g.append(cuboid(Vec3::new(0.07, 1.9, 0.03)).transformed(brace));
    g
}

/// A market counter on four poles that carry the awning, front towards +Z. 96 triangles.
fn stall_counter() -> MeshBuilder {
    boxes(&[
        (Vec3::new(2.4, 0.08, 1.0), Vec3::new(0.0, 0.9, 0.0)),
        (Vec3::new(2.4, 0.8, 0.05), Vec3::new(0.0, 0.45, 0.48)),
        (Vec3::new(0.05, 0.8, 1.0), Vec3::new(-1.18, 0.45, 0.0)),
        (Vec3::new(0.05, 0.8, 1.0), Vec3::new(1.18, 0.45, 0.0)),
        (Vec3::new(0.08, 2.3, 0.08), Vec3::new(-1.2, 1.15, -1.2)),
        (Vec3::new(0.08, 2.3, 0.08), Vec3::new(1.2, 1.15, -1.2)),
        (Vec3::new(0.08, 2.3, 0.08), Vec3::new(-1.2, 1.15, 1.2)),
        (Vec3::new(0.08, 2.3, 0.08), Vec3::new(1.2, 1.15, 1.2)),
    ])
}

/// A bench facing +Z. 72 triangles.
fn bench() -> MeshBuilder {
    boxes(&[
        (Vec3::new(1.6, 0.06, 0.4), Vec3::new(0.0, 0.45, 0.0)),
        (Vec3::new(1.6, 0.35, 0.05), Vec3::new(0.0, 0.75, -0.18)),
        (Vec3::new(0.06, 0.45, 0.06), Vec3::new(-0.7, 0.22, -0.15)),
        (Vec3::new(0.06, 0.45, 0.06), Vec3::new(0.7, 0.22, -0.15)),
        (Vec3::new(0.06, 0.45, 0.06), Vec3::new(-0.7, 0.22, 0.15)),
        (Vec3::new(0.06, 0.45, 0.06), Vec3::new(0.7, 0.22, 0.15)),
    ])
}

/// Six logs stacked three, two, one along Z, not quite touching (touching logs would share
/// vertices and stop being closed). 192 triangles.
fn woodpile() -> MeshBuilder {
    let r = 0.14;
    let rows: [&[f32]; 3] = [&[-0.3, 0.0, 0.3], &[-0.15, 0.15], &[0.0]];
    let mut logs = Vec::new();
    for (level, xs) in rows.iter().enumerate() {
        for &x in *xs {
            let y = r + level as f32 * 0.26;
            let path = [Vec3::new(x, y, -0.6), Vec3::new(x, y, 0.6)];
            logs.push(tube(&path, &[r, r], 8));
        }
    }
    MeshBuilder::merge(logs)
}

/// A hand cart, shafts towards +Z. 72 triangles.
fn cart_body() -> MeshBuilder {
    boxes(&[
        (Vec3::new(1.4, 0.1, 2.2), Vec3::new(0.0, 0.6, 0.0)),
        (Vec3::new(0.06, 0.4, 2.2), Vec3::new(-0.67, 0.86, 0.0)),
        (Vec3::new(0.06, 0.4, 2.2), Vec3::new(0.67, 0.86, 0.0)),
        (Vec3::new(1.28, 0.4, 0.06), Vec3::new(0.0, 0.85, -1.07)),
        (Vec3::new(0.08, 0.08, 2.0), Vec3::new(-0.5, 0.6, 2.0)),
        (Vec3::new(0.08, 0.08, 2.0), Vec3::new(0.5, 0.6, 2.0)),
    ])
}

/// A cart wheel turning about X, its hub sticking out on the outer (+X) side. 96 triangles.
fn cart_wheel() -> MeshBuilder {
    MeshBuilder::merge([
        tube(
            &[Vec3::new(-0.04, 0.0, 0.0), Vec3::new(0.04, 0.0, 0.0)],
            &[0.55, 0.55],
            16,
        ),
        tube(
            &[Vec3::new(-0.06, 0.0, 0.0), Vec3::new(0.16, 0.0, 0.0)],
            &[0.1, 0.08],
            8,
        ),
    ])
}

// ---------------------------------------------------------------------------------------------
// Placement
// ---------------------------------------------------------------------------------------------

/// Road tiles along every road line, and a crossing tile where two meet. 184 instances.
fn place_roads(model: &mut ModelBuilder, parts: &Parts, rng: &mut Rng) {
    let half = ROAD_WIDTH * 0.5;
    for &x in &ROAD_LINES {
        for &z in &ROAD_LINES {
            let turn = Quat::from_rotation_y(FRAC_PI_2 * rng.below(4) as f32);
            model.place(
                parts.road_crossing,
                trs(Vec3::new(x, 0.0, z), turn, Vec3::ONE),
            );
        }
    }
    let mut stops = vec![-ROAD_END];
    for &c in &ROAD_LINES {
        stops.extend([c - half, c + half]);
    }
    stops.push(ROAD_END);
    for &line in &ROAD_LINES {
        for stretch in stops.chunks_exact(2) {
            let (start, end) = (stretch[0], stretch[1]);
            let tiles = ((end - start) / ROAD_TILE).round().max(1.0) as usize;
            let length = (end - start) / tiles as f32;
            for k in 0..tiles {
                let along = start + length * (k as f32 + 0.5);
                for along_x in [true, false] {
                    let (position, yaw) = if along_x {
                        (Vec3::new(along, 0.0, line), 0.0)
                    } else {
                        (Vec3::new(line, 0.0, along), FRAC_PI_2)
                    };
                    // Tiles are laid either way round, with a little wobble.
                    let flip = if rng.chance(0.5) { PI } else { 0.0 };
                    let turn = Quat::from_rotation_y(yaw + flip + rng.jitter(0.004));
                    let scale = Vec3::new(length / ROAD_TILE, 1.0, 1.0);
                    model.place(parts.road_straight, trs(position, turn, scale));
                }
            }
        }
    }
}

/// The 96 houses of the eight outer blocks, 16 of each kind, with their parts, gardens, trees
/// and woodpiles.
fn place_houses(model: &mut ModelBuilder, parts: &Parts, terrain: &Terrain, rng: &mut Rng) {
    let mut kinds: Vec<usize> = (0..96).map(|i| i % HOUSE_KINDS.len()).collect();
    rng.shuffle(&mut kinds);
    let mut lots = kinds.into_iter();
    for bx in [-60.0f32, 0.0, 60.0] {
        for bz in [-60.0f32, 0.0, 60.0] {
            if bx == 0.0 && bz == 0.0 {
                continue; // the market square
            }
            let block = Vec3::new(bx, 0.0, bz);
            for (outward, yaw) in [
                (Vec3::X, 0.0),
                (Vec3::NEG_Z, FRAC_PI_2),
                (Vec3::NEG_X, PI),
                (Vec3::Z, -FRAC_PI_2),
            ] {
                let along = Vec3::Y.cross(outward);
                for (position_on_side, offset) in [-13.0f32, 0.0, 13.0].into_iter().enumerate() {
                    let Some(kind_index) = lots.next() else {
                        return;
                    };
                    let kind = &HOUSE_KINDS[kind_index];
                    let centre =
                        block + outward * (BLOCK_HALF - 1.5 - kind.depth * 0.5) + along * offset;
                    let frame = trs(
                        centre,
                        Quat::from_rotation_y(yaw + rng.jitter(0.03)),
                        Vec3::ONE,
                    );
                    let scale = Vec3::new(
                        rng.range(0.94, 1.06),
                        rng.range(0.95, 1.1),
                        rng.range(0.94, 1.06),
                    );
                    place_house(
                        model,
                        parts,
                        kind_index,
                        frame * Affine3A::from_scale(scale),
                    );
                    let behind = |x: f32, z: f32| {
                        frame.transform_point3(Vec3::new(-kind.depth * 0.5 - x, 0.0, z))
                    };
                    match position_on_side {
                        1 => place_garden(model, parts, kind, frame, rng),
                        _ => {
                            let at = behind(5.0, rng.jitter(2.0));
                            place_tree(model, parts, terrain.at(at.x, at.z), rng);
                            if position_on_side == 0 {
                                let at = frame.transform_point3(Vec3::new(
                                    0.0,
                                    0.0,
                                    kind.frontage * 0.5 + 1.3,
                                ));
                                let turn = Quat::from_rotation_y(yaw + rng.jitter(0.2));
                                model.place(parts.woodpile, trs(at, turn, Vec3::ONE));
                            }
                        }
                    }
                }
            }
        }
    }
}

/// One house of `kind` placed by `house` (which may scale it non-uniformly): body, roof, door,
/// doorstep, windows with shutters or flower boxes, chimney.
fn place_house(model: &mut ModelBuilder, parts: &Parts, kind_index: usize, house: Affine3A) {
    let kind = &HOUSE_KINDS[kind_index];
    let front = kind.depth * 0.5;
    let face_front = Quat::from_rotation_y(FRAC_PI_2);
    model.place(parts.house_bodies[kind_index], house);
    model.place(parts.house_roofs[kind_index], house);
    let door = if kind.arched_door {
        parts.door_arched
    } else {
        parts.door_plank
    };
    model.place(
        door,
        house
            * trs(
                Vec3::new(front + 0.02, 0.2, kind.door_z),
                face_front,
                kind.door_scale,
            ),
    );
    model.place(
        parts.doorstep,
        house
            * trs(
                Vec3::new(front + 0.3, 0.1, kind.door_z),
                face_front,
                Vec3::ONE,
            ),
    );
    let (window, width, height) = if kind.tall_windows {
        (parts.window_tall, 0.8, 1.5)
    } else {
        (parts.window_square, 1.0, 1.1)
    };
    for &(wall, storey, offset) in kind.windows {
        let (position, rotation) = kind.window_spot(wall, storey, offset);
        let frame = house * trs(position, rotation, Vec3::ONE);
        model.place(window, frame);
        if wall == Front && kind.shutters {
            // The left shutter is the right one mirrored.
            for side in [1.0f32, -1.0] {
                let at = Vec3::new(side * (width * 0.5 + 0.25), 0.0, 0.02);
                let scale = Vec3::new(side, height / 1.1, 1.0);
                model.place(parts.shutter, frame * trs(at, Quat::IDENTITY, scale));
            }
        }
        if wall == Front && storey == 0 && kind.flower_boxes {
            let at = Vec3::new(0.0, -height * 0.5 - 0.12, 0.12);
            model.place(
                parts.flower_box,
                frame * trs(at, Quat::IDENTITY, Vec3::new(width / 0.9, 1.0, 1.0)),
            );
        }
    }
    if let Some(chimney) = kind.chimney {
        let x = kind.ridge_x - 1.2;
        let at = Vec3::new(x, kind.roof_height(x) - 0.5, kind.frontage * 0.25);
        let id = match chimney {
            Chimney::Square => parts.chimney_square,
            Chimney::Round => parts.chimney_round,
        };
        model.place(id, house * Affine3A::from_translation(at));
    }
}

/// A fenced garden behind a house (in the house's unscaled `frame`): 9 posts, 14 rails, a
/// gate, a bed and three flower patches.
fn place_garden(
    model: &mut ModelBuilder,
    parts: &Parts,
    kind: &HouseKind,
    frame: Affine3A,
    rng: &mut Rng,
) {
    let back = -kind.depth * 0.5;
    let local = |x: f32, y: f32, z: f32, yaw: f32, scale: Vec3| {
        frame * trs(Vec3::new(x, y, z), Quat::from_rotation_y(yaw), scale)
    };
    let post_yaw = |rng: &mut Rng| FRAC_PI_2 * rng.below(4) as f32 + rng.jitter(0.1);
    // Back fence along Z at `back - 8`, posts every 2.5 m; sides along X at z = ±5.
    let far = back - 8.0;
    let back_posts = [-5.0f32, -2.5, 0.0, 2.5, 5.0];
    for &z in &back_posts {
        model.place(
            parts.fence_post,
            local(far, 0.0, z, post_yaw(rng), Vec3::ONE),
        );
    }
    for z in [-5.0f32, 5.0] {
        for x in [back - 2.0, back - 5.0] {
            model.place(parts.fence_post, local(x, 0.0, z, post_yaw(rng), Vec3::ONE));
        }
    }
    for (gap, pair) in back_posts.windows(2).enumerate() {
        let z = 0.5 * (pair[0] + pair[1]);
        let stretch = Vec3::new((pair[1] - pair[0]) / 2.0, 1.0, 1.0);
        if gap == 1 {
            model.place(parts.fence_gate, local(far, 0.0, z, FRAC_PI_2, stretch));
        } else {
            for y in [0.45, 0.85] {
                model.place(parts.fence_rail, local(far, y, z, FRAC_PI_2, stretch));
            }
        }
    }
    for z in [-5.0f32, 5.0] {
        for (from, to) in [(back - 2.0, back - 5.0), (back - 5.0, far)] {
            let stretch = Vec3::new((from - to) / 2.0, 1.0, 1.0);
            for y in [0.45, 0.85] {
                model.place(
                    parts.fence_rail,
                    local(0.5 * (from + to), y, z, 0.0, stretch),
                );
            }
        }
    }
    model.place(
        parts.garden_bed,
        local(
            back - 4.5,
            0.15,
            rng.jitter(0.5),
            rng.jitter(0.05),
            Vec3::ONE,
        ),
    );
    for k in 0..3 {
        let patch = parts.flower_patches[k];
        let at = local(
            back - rng.range(1.5, 7.0),
            0.0,
            rng.range(-4.0, 4.0),
            rng.angle(),
            Vec3::splat(rng.range(0.8, 1.3)),
        );
        model.place(patch, at);
    }
}

/// A tree standing on `ground`: any yaw, 85–115% wide, 80–125% tall, mirrored sometimes.
fn place_tree(model: &mut ModelBuilder, parts: &Parts, ground: Vec3, rng: &mut Rng) {
    let size = rng.range(0.8, 1.3);
    let scale = varied_scale(rng, size, 0.15, (0.8, 1.25));
    let scale = maybe_mirrored(rng, scale);
    let at = ground - Vec3::Y * 0.2;
    model.place(
        parts.tree,
        trs(at, Quat::from_rotation_y(rng.angle()), scale),
    );
}

/// `size` times a random factor in `1 ± across` on X and Z and in `height` on Y.
fn varied_scale(rng: &mut Rng, size: f32, across: f32, height: (f32, f32)) -> Vec3 {
    let x = rng.range(1.0 - across, 1.0 + across);
    let y = rng.range(height.0, height.1);
    let z = rng.range(1.0 - across, 1.0 + across);
    size * Vec3::new(x, y, z)
}

/// `scale` with X negated (a mirror) with probability [`MIRRORED`].
fn maybe_mirrored(rng: &mut Rng, scale: Vec3) -> Vec3 {
    if rng.chance(MIRRORED) {
        Vec3::new(-scale.x, scale.y, scale.z)
    } else {
        scale
    }
}

/// The market square in the central block: church, well, pond with stepping stones, six
/// stalls with their wares, benches and lamps; and a lamp at every road crossing.
fn place_market_square(model: &mut ModelBuilder, parts: &Parts, rng: &mut Rng) {
    let along_x = Quat::from_rotation_y(FRAC_PI_2);
    let church = trs(Vec3::new(-12.0, 0.0, 0.0), along_x, Vec3::ONE);
    model.place(parts.church_nave, church);
    model.place(parts.church_roof, church);
    model.place(
        parts.church_tower,
        Affine3A::from_translation(Vec3::new(-24.5, 0.0, 0.0)),
    );
    model.place(
        parts.church_spire,
        trs(
            Vec3::new(-24.5, 16.0, 0.0),
            Quat::from_rotation_y(PI / 8.0),
            Vec3::ONE,
        ),
    );

    let well = Vec3::new(8.0, 0.0, -10.0);
    let well_turn = Quat::from_rotation_y(rng.angle());
    model.place(parts.well_wall, trs(well, well_turn, Vec3::ONE));
    for side in [-1.1f32, 1.1] {
        model.place(
            parts.well_post,
            trs(
                well + well_turn * Vec3::new(side, 0.0, 0.0),
                well_turn,
                Vec3::ONE,
            ),
        );
    }
    model.place(
        parts.well_roof,
        trs(well + Vec3::Y * 2.4, well_turn, Vec3::ONE),
    );

    let pond = Vec3::new(6.0, 0.02, 12.0);
    model.place(
        parts.pond,
        trs(
            pond,
            Quat::from_rotation_y(rng.angle()),
            Vec3::new(1.0, 1.0, 0.8),
        ),
    );
    for k in 0..20 {
        let angle = TAU * k as f32 / 20.0 + rng.jitter(0.1);
        let at = pond + Vec3::new(6.0 * angle.cos(), 0.0, 4.8 * angle.sin()) * rng.range(1.0, 1.1);
        let scale = Vec3::new(
            rng.range(0.8, 1.2),
            rng.range(0.8, 1.2),
            rng.range(0.8, 1.2),
        );
        model.place(
            parts.stepping_stone,
            trs(at, Quat::from_rotation_y(rng.angle()), scale),
        );
    }

    // Stalls along the east side, counters facing west into the square.
    let face_west = Quat::from_rotation_y(-FRAC_PI_2);
    for z in [-20.0f32, -12.0, -4.0, 4.0, 12.0, 20.0] {
        let stall = trs(Vec3::new(21.0, 0.0, z), face_west, Vec3::ONE);
        model.place(parts.stall_counter, stall);
        model.place(
            parts.stall_awning,
            stall * Affine3A::from_translation(Vec3::Y * 2.3),
        );
        let near = |rng: &mut Rng, x: f32| {
            stall
                * Affine3A::from_translation(Vec3::new(
                    x + rng.jitter(0.3),
                    0.0,
                    -1.5 + rng.jitter(0.4),
                ))
        };
        for k in 0..4 {
            let at = near(rng, -1.2 + 0.8 * k as f32) * Affine3A::from_rotation_y(rng.jitter(0.4));
            model.place(parts.crate_box, at);
        }
        for k in 0..3 {
            let at = near(rng, -0.8 + 0.8 * k as f32) * Affine3A::from_translation(Vec3::Z * -0.8);
            model.place(parts.barrel, at * Affine3A::from_rotation_y(rng.angle()));
        }
        for k in 0..3 {
            let at = stall
                * trs(
                    Vec3::new(-0.8 + 0.8 * k as f32, 0.94, rng.jitter(0.2)),
                    Quat::from_rotation_y(rng.angle()),
                    Vec3::splat(rng.range(0.7, 0.9)),
                );
            model.place(parts.sack, at);
        }
    }
    // Benches along the north and south edges, facing in.
    for (z, yaw) in [(-24.0f32, 0.0), (24.0, PI)] {
        for x in [-20.0f32, -14.0, -7.0, 4.0, 10.0, 15.0] {
            model.place(
                parts.bench,
                trs(
                    Vec3::new(x, 0.0, z),
                    Quat::from_rotation_y(yaw + rng.jitter(0.05)),
                    Vec3::ONE,
                ),
            );
        }
    }
    // Lamps: eight around the square, one at each road crossing.
    let mut lamps = vec![
        Vec2::new(-25.0, -25.0),
        Vec2::new(25.0, -25.0),
        Vec2::new(-25.0, 25.0),
        Vec2::new(25.0, 25.0),
        Vec2::new(-1.0, -25.5),
        Vec2::new(-1.0, 25.5),
        Vec2::new(12.0, -25.5),
        Vec2::new(12.0, 25.5),
    ];
    for &x in &ROAD_LINES {
        for &z in &ROAD_LINES {
            lamps.push(Vec2::new(x + 4.0, z + 4.0));
        }
    }
    for at in lamps {
        let lamp = trs(
            Vec3::new(at.x, 0.0, at.y),
            Quat::from_rotation_y(rng.angle()),
            Vec3::ONE,
        );
        model.place(parts.lamp_post, lamp);
        model.place(
            parts.lantern,
            lamp * Affine3A::from_translation(Vec3::new(0.55, 2.85, 0.0)),
        );
    }
}

/// A uniform point of the square ring between `inner` and `outer` (max norm) around the centre.
fn in_ring(rng: &mut Rng, inner: f32, outer: f32) -> Vec2 {
    loop {
        let p = Vec2::new(rng.jitter(outer), rng.jitter(outer));
        if p.x.abs().max(p.y.abs()) >= inner {
            return p;
        }
    }
}

/// The forest, rocks, bushes, haystacks, stumps, logs and carts outside the village.
fn place_countryside(model: &mut ModelBuilder, parts: &Parts, terrain: &Terrain, rng: &mut Rng) {
    let outer = GROUND_HALF - 4.0;
    for _ in 0..FOREST_TREES {
        let p = in_ring(rng, FOREST_START, outer);
        place_tree(model, parts, terrain.at(p.x, p.y), rng);
    }
    let sink = |p: Vec3, depth: f32| p - Vec3::Y * depth;
    for k in 0..420 {
        let p = in_ring(rng, 124.0, outer);
        let size = rng.range(0.4, 1.6);
        let scale = varied_scale(rng, size, 0.3, (0.6, 1.2));
        let scale = maybe_mirrored(rng, scale);
        let turn = Quat::from_rotation_y(rng.angle()) * Quat::from_rotation_x(rng.jitter(0.2));
        model.place(
            parts.rocks[k % parts.rocks.len()],
            trs(sink(terrain.at(p.x, p.y), 0.2 * size), turn, scale),
        );
    }
    for k in 0..480 {
        // Half hedge the village edge, half grow in the countryside.
        let p = if k % 2 == 0 {
            in_ring(rng, 121.0, 127.0)
        } else {
            in_ring(rng, FOREST_START, outer)
        };
        let size = rng.range(0.7, 1.4);
        let scale = varied_scale(rng, size, 0.2, (0.8, 1.2));
        let scale = maybe_mirrored(rng, scale);
        model.place(
            parts.bushes[k % parts.bushes.len()],
            trs(
                sink(terrain.at(p.x, p.y), 0.1),
                Quat::from_rotation_y(rng.angle()),
                scale,
            ),
        );
    }
    for _ in 0..40 {
        let p = in_ring(rng, 128.0, 150.0);
        let scale = Vec3::new(
            rng.range(0.9, 1.2),
            rng.range(0.8, 1.1),
            rng.range(0.9, 1.2),
        );
        model.place(
            parts.haystack,
            trs(
                sink(terrain.at(p.x, p.y), 0.2),
                Quat::from_rotation_y(rng.angle()),
                scale,
            ),
        );
    }
    for _ in 0..50 {
        let p = in_ring(rng, FOREST_START, outer);
        let scale = Vec3::new(
            rng.range(0.7, 1.3),
            rng.range(0.6, 1.4),
            rng.range(0.7, 1.3),
        );
        model.place(
            parts.stump,
            trs(
                sink(terrain.at(p.x, p.y), 0.1),
                Quat::from_rotation_y(rng.angle()),
                scale,
            ),
        );
    }
    for _ in 0..40 {
        let p = in_ring(rng, FOREST_START, outer);
        let turn = Quat::from_rotation_y(rng.angle()) * Quat::from_rotation_z(rng.jitter(0.1));
        let scale = Vec3::new(
            rng.range(0.6, 1.3),
            rng.range(0.8, 1.2),
            rng.range(0.8, 1.2),
        );
        model.place(parts.log, trs(sink(terrain.at(p.x, p.y), 0.1), turn, scale));
    }
    // Carts on the road stubs leading out of the village; the left wheels are mirrored.
    for (x, z, yaw) in [
        (106.0f32, 31.5f32, FRAC_PI_2),
        (-108.0, -28.5, -FRAC_PI_2),
        (31.5, 110.0, 0.0),
        (-28.5, -104.0, PI),
    ] {
        let cart = trs(
            Vec3::new(x, 0.1, z),
            Quat::from_rotation_y(yaw + rng.jitter(0.2)),
            Vec3::ONE,
        );
        model.place(parts.cart_body, cart);
        for side in [1.0f32, -1.0] {
            for wheel_z in [-0.6f32, 0.6] {
                let at = Vec3::new(0.78 * side, 0.55, wheel_z);
                let spin = Quat::from_rotation_x(rng.angle());
                model.place(
                    parts.cart_wheel,
                    cart * trs(at, spin, Vec3::new(side, 1.0, 1.0)),
                );
            }
        }
    }
}

/// Grass tufts everywhere off the roads, as many as the instance count of Table 2 leaves.
fn place_grass(model: &mut ModelBuilder, parts: &Parts, terrain: &Terrain, rng: &mut Rng) {
    let count = TOTAL_INSTANCES.saturating_sub(model.instance_count());
    let on_road = |p: Vec2| {
        let within = p.x.abs() < ROAD_END + 1.0 && p.y.abs() < ROAD_END + 1.0;
        within
            && ROAD_LINES.iter().any(|&line| {
                (p.x - line).abs() < ROAD_WIDTH * 0.6 || (p.y - line).abs() < ROAD_WIDTH * 0.6
            })
    };
    let limit = GROUND_HALF - 1.0;
    for k in 0..count {
        let p = loop {
            let p = Vec2::new(rng.jitter(limit), rng.jitter(limit));
            if !on_road(p) {
                break p;
            }
        };
        let size = rng.range(0.7, 1.4);
        let scale = Vec3::new(
            size * rng.range(0.8, 1.2),
            size * rng.range(0.7, 1.3),
            size * rng.range(0.8, 1.2),
        );
        let tuft = parts.grass_tufts[k % parts.grass_tufts.len()];
        model.place(
            tuft,
            trs(
                terrain.at(p.x, p.y),
                Quat::from_rotation_y(rng.angle()),
                scale,
            ),
        );
    }
}

fn smoothstep(lo: f32, hi: f32, x: f32) -> f32 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}
