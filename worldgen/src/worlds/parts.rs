//! The small parametric models the worlds are made of (core paper section 8: village, island
//! and city): houses, trees, rocks, fences, ground tiles, lamps and benches, each a few hundred
//! triangles built from [`crate::shapes`], plus the 32×32 procedural facade, paving and road
//! textures that make the city's thousands of distinct textures.

use std::f32::consts::{FRAC_PI_2, FRAC_PI_4};

use glam::{Affine3A, Quat, Vec2, Vec3, Vec4};
use horizon_mesh::{InstancedMesh, Texture, Wrap};

use crate::assembly::{plain, textured, trs, ModelBuilder};
use crate::noise::{cell_hash, fbm3, tileable_fbm};
use crate::rng::Rng;
use crate::shapes::{cone, cuboid, extrude, frustum, uv_sphere};
use crate::textures::{encode, paint};
use crate::WorldgenError;

/// The shape of a house's roof.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Roof {
    /// Two slopes meeting at a ridge along the depth.
    Gable,
    /// Four slopes meeting at a point.
    Hip,
    /// A flat slab with a rooftop box.
    Flat,
}

/// Parameters of [`house`].
#[derive(Clone, Debug)]
pub struct HouseParams {
    /// Width along X, metres.
    pub width: f32,
    /// Depth along Z, metres (the door faces +Z).
    pub depth: f32,
    /// Number of storeys.
    pub floors: u32,
    /// Storey height, metres.
    pub floor_height: f32,
    /// Roof shape.
    pub roof: Roof,
    /// Wall texture, repeated every `facade_tile` metres.
    pub facade: Texture,
    /// Metres covered by one repeat of the facade texture.
    pub facade_tile: f32,
    /// Roof texture (repeated every 2 m), or `None` for a plain roof of `roof_colour`.
    pub roof_texture: Option<Texture>,
    /// Roof colour (a tint when textured), linear RGBA.
    pub roof_colour: Vec4,
    /// Window frame and door colour, linear RGBA.
    pub trim_colour: Vec4,
    /// Whether the house has a chimney.
    pub chimney: bool,
}

/// A house: a textured box body, instanced window frames on every storey and side, a door, a
/// roof and optionally a chimney. About 100-400 triangles.
pub fn house(p: &HouseParams) -> InstancedMesh {
    let mut m = ModelBuilder::new();
    let facade = m.texture(p.facade.clone());
    let wall = m.material(textured("wall", facade, Vec4::ONE, 0.9));
    let trim = m.material(plain("trim", p.trim_colour, 0.6));
    let roof_material = match &p.roof_texture {
        Some(t) => {
            let t = m.texture(t.clone());
            m.material(textured("roof", t, p.roof_colour, 0.8))
        }
        None => m.material(plain("roof", p.roof_colour, 0.8)),
    };
    let (w, d) = (p.width, p.depth);
    let h = p.floors as f32 * p.floor_height;
    let body = cuboid(Vec3::new(w, h, d))
        .transformed(Affine3A::from_translation(Vec3::new(0.0, h * 0.5, 0.0)))
        .scaled_uvs(Vec2::splat(1.0 / p.facade_tile));
    let body = m.submesh("body", true, body, wall);
    m.place(body, Affine3A::IDENTITY);

    // Window frames: one submesh, an instance per window.
    let frame = m.submesh("window", true, cuboid(Vec3::new(1.0, 1.3, 0.12)), trim);
    let spacing = 2.8;
    for floor in 0..p.floors {
        let y = floor as f32 * p.floor_height + p.floor_height * 0.55;
        for (half_along, half_across, rotation) in [
            (w * 0.5, d * 0.5, 0.0),
            (w * 0.5, -d * 0.5, 0.0),
            (d * 0.5, w * 0.5, FRAC_PI_2),
            (d * 0.5, -w * 0.5, FRAC_PI_2),
        ] {
            let count = ((2.0 * half_along / spacing).floor() as i32).max(1);
            for k in 0..count {
                let along = (k as f32 + 0.5) / count as f32 * 2.0 * half_along - half_along;
                // Leave the middle of the front ground floor for the door.
                if floor == 0 && rotation == 0.0 && half_across > 0.0 && along.abs() < 1.0 {
                    continue;
                }
                let local = Vec3::new(along, y, half_across);
                let rot = Quat::from_rotation_y(rotation);
                m.place(frame, trs(rot * local, rot, Vec3::ONE));
            }
        }
    }
    let door = m.submesh("door", true, cuboid(Vec3::new(1.1, 2.1, 0.14)), trim);
    m.place(
        door,
        trs(Vec3::new(0.0, 1.05, d * 0.5), Quat::IDENTITY, Vec3::ONE),
    );

    let overhang = 0.3;
    let roof_height = 0.45 * w.min(d);
    match p.roof {
        Roof::Gable => {
            let half = w * 0.5 + overhang;
            let profile = [
                Vec2::new(-half, 0.0),
                Vec2::new(half, 0.0),
                Vec2::new(0.0, roof_height),
            ];
            let length = d + 2.0 * overhang;
            let roof = extrude(&profile, length, 1, 10.0)
                .transformed(Affine3A::from_translation(Vec3::new(0.0, h, -length * 0.5)))
                .scaled_uvs(Vec2::splat(0.5));
            let roof = m.submesh("roof", true, roof, roof_material);
            m.place(roof, Affine3A::IDENTITY);
        }
        Roof::Hip => {
            // A 4-sided cone turned 45 degrees has a square base of half-side 1/sqrt(2).
            let scale = Vec3::new(
                (w * 0.5 + overhang) * 2f32.sqrt(),
                roof_height,
                (d * 0.5 + overhang) * 2f32.sqrt(),
            );
            let roof = cone(1.0, 1.0, 4)
                .transformed(Affine3A::from_rotation_y(FRAC_PI_4))
                .transformed(trs(Vec3::new(0.0, h, 0.0), Quat::IDENTITY, scale))
                .scaled_uvs(Vec2::splat(0.5));
            let roof = m.submesh("roof", true, roof, roof_material);
            m.place(roof, Affine3A::IDENTITY);
        }
        Roof::Flat => {
            let slab = cuboid(Vec3::new(w + 0.2, 0.4, d + 0.2))
                .transformed(Affine3A::from_translation(Vec3::new(0.0, h + 0.2, 0.0)));
            let slab = m.submesh("roof", true, slab, roof_material);
            m.place(slab, Affine3A::IDENTITY);
            let unit = m.submesh("rooftop-unit", true, cuboid(Vec3::splat(1.5)), trim);
            m.place(
                unit,
                Affine3A::from_translation(Vec3::new(w * 0.2, h + 1.15, -d * 0.15)),
            );
        }
    }
    if p.chimney {
        let chimney = cuboid(Vec3::new(0.6, 1.6, 0.6));
        let chimney = m.submesh("chimney", true, chimney, trim);
        m.place(
            chimney,
            Affine3A::from_translation(Vec3::new(w * 0.25, h + roof_height * 0.6, -d * 0.2)),
        );
    }
    m.finish().mesh
}

/// Parameters of [`tree`].
#[derive(Clone, Debug)]
pub struct TreeParams {
    /// Seed of the crown's placement and lumpiness.
    pub seed: u64,
    /// Total height, metres.
    pub height: f32,
    /// Crown radius, metres.
    pub crown_radius: f32,
    /// Stacked cones instead of round crowns.
    pub conifer: bool,
    /// Foliage colour, linear RGBA.
    pub leaf_colour: Vec4,
    /// Bark colour, linear RGBA.
    pub bark_colour: Vec4,
}

/// A tree: a tapered trunk and either 3-5 lumpy spheres (instances of one crown submesh) or
/// 3-4 stacked cones. About 300-700 triangles.
pub fn tree(p: &TreeParams) -> InstancedMesh {
    let mut rng = Rng::new(p.seed).fork(0x7EE);
    let mut m = ModelBuilder::new();
    let bark = m.material(plain("bark", p.bark_colour, 0.9));
    let leaf = m.material(plain("leaf", p.leaf_colour, 0.8));
    let trunk_height = p.height * if p.conifer { 0.35 } else { 0.55 };
    let r = p.crown_radius;
    let trunk = frustum(r * 0.14, r * 0.08, trunk_height, 8, 2);
    let trunk = m.submesh("trunk", true, trunk, bark);
    m.place(trunk, Affine3A::IDENTITY);
    if p.conifer {
        let tier = m.submesh("tier", true, cone(1.0, 1.0, 12), leaf);
        let tiers = 3 + rng.below(2);
        let span = p.height - trunk_height * 0.8;
        for k in 0..tiers {
            let t = k as f32 / tiers as f32;
            let radius = r * (1.0 - 0.7 * t);
            let y = trunk_height * 0.8 + span * t * 0.75;
            let tier_height = span * 0.45;
            m.place(
                tier,
                trs(
                    Vec3::new(0.0, y, 0.0),
                    Quat::from_rotation_y(rng.angle()),
                    Vec3::new(radius, tier_height, radius),
                ),
            );
        }
    } else {
        let seed = p.seed;
        let mut crown = uv_sphere(1.0, 12, 8)
            .displaced(|q| q * (0.8 + 0.4 * fbm3(seed, q * 1.7 + Vec3::splat(3.0), 3)));
        crown.recompute_normals();
        let crown = m.submesh("crown", true, crown, leaf);
        let blobs = 3 + rng.below(3);
        let centre_y = p.height - r;
        for _ in 0..blobs {
            let offset = Vec3::new(rng.jitter(0.5), rng.jitter(0.35), rng.jitter(0.5)) * r;
            let s = r * rng.range(0.55, 0.8);
            m.place(
                crown,
                trs(
                    Vec3::new(0.0, centre_y, 0.0) + offset,
                    Quat::from_rotation_y(rng.angle()),
                    Vec3::splat(s),
                ),
            );
        }
    }
    m.finish().mesh
}

/// A lumpy boulder of about `size` metres across and `colour`. 160 triangles.
pub fn rock(seed: u64, size: f32, colour: Vec4) -> InstancedMesh {
    let mut m = ModelBuilder::new();
    let stone = m.material(plain("stone", colour, 0.95));
    let mut body = uv_sphere(0.5, 10, 9)
        .displaced(|q| q * (0.7 + 0.6 * fbm3(seed, q * 3.0 + Vec3::splat(7.0), 3)));
    body.recompute_normals();
    let body = m.submesh("rock", true, body, stone);
    m.place(
        body,
        trs(
            Vec3::new(0.0, size * 0.3, 0.0),
            Quat::IDENTITY,
            Vec3::new(size, size * 0.7, size * 0.85),
        ),
    );
    m.finish().mesh
}

/// A fence of `length` metres along X: posts every ~2 m (instances of one post) and two rails.
pub fn fence(length: f32, wood: Option<Texture>, colour: Vec4) -> InstancedMesh {
    let mut m = ModelBuilder::new();
    let material = match wood {
        Some(t) => {
            let t = m.texture(t);
            m.material(textured("fence", t, colour, 0.8))
        }
        None => m.material(plain("fence", colour, 0.8)),
    };
    let post = m.submesh("post", true, cuboid(Vec3::new(0.12, 1.2, 0.12)), material);
    let posts = (length / 2.0).ceil() as u32 + 1;
    for k in 0..posts {
        let x = -length * 0.5 + length * k as f32 / (posts - 1) as f32;
        m.place(post, Affine3A::from_translation(Vec3::new(x, 0.6, 0.0)));
    }
    let rail = m.submesh("rail", true, cuboid(Vec3::new(length, 0.1, 0.05)), material);
    for y in [0.45, 0.95] {
        m.place(rail, Affine3A::from_translation(Vec3::new(0.0, y, 0.06)));
    }
    m.finish().mesh
}

/// A flat textured slab of `size` (X by Z) metres and 0.2 m thick, its top at `top` metres,
/// the texture repeated every `tile` metres.
pub fn ground_tile(size: Vec2, top: f32, texture: Texture, tile: f32) -> InstancedMesh {
    let mut m = ModelBuilder::new();
    let t = m.texture(texture);
    let material = m.material(textured("ground", t, Vec4::ONE, 0.95));
    let slab = cuboid(Vec3::new(size.x, 0.2, size.y))
        .transformed(Affine3A::from_translation(Vec3::new(0.0, top - 0.1, 0.0)))
        .scaled_uvs(Vec2::splat(1.0 / tile));
    let slab = m.submesh("slab", true, slab, material);
    m.place(slab, Affine3A::IDENTITY);
    m.finish().mesh
}

/// A street lamp `height` metres tall: a pole, an arm and a globe.
pub fn lamp(height: f32, colour: Vec4) -> InstancedMesh {
    let mut m = ModelBuilder::new();
    let metal = m.material(plain("metal", colour, 0.4));
    let glass = m.material(plain("glass", Vec4::new(1.0, 0.95, 0.8, 1.0), 0.1));
    let pole = m.submesh("pole", true, frustum(0.1, 0.06, height, 8, 1), metal);
    m.place(pole, Affine3A::IDENTITY);
    let arm = m.submesh("arm", true, cuboid(Vec3::new(0.8, 0.06, 0.06)), metal);
    m.place(
        arm,
        Affine3A::from_translation(Vec3::new(0.35, height, 0.0)),
    );
    let globe = m.submesh("globe", true, uv_sphere(0.22, 10, 6), glass);
    m.place(
        globe,
        Affine3A::from_translation(Vec3::new(0.7, height - 0.2, 0.0)),
    );
    m.finish().mesh
}

/// A bench: seat, back and four legs (instances of one leg).
pub fn bench(colour: Vec4) -> InstancedMesh {
    let mut m = ModelBuilder::new();
    let wood = m.material(plain("wood", colour, 0.8));
    let seat = m.submesh("seat", true, cuboid(Vec3::new(1.8, 0.06, 0.45)), wood);
    m.place(seat, Affine3A::from_translation(Vec3::new(0.0, 0.45, 0.0)));
    m.place(
        seat,
        trs(
            Vec3::new(0.0, 0.75, -0.22),
            Quat::from_rotation_x(-1.35),
            Vec3::new(1.0, 1.0, 0.8),
        ),
    );
    let leg = m.submesh("leg", true, cuboid(Vec3::new(0.06, 0.45, 0.4)), wood);
    for x in [-0.8, 0.8] {
        m.place(leg, Affine3A::from_translation(Vec3::new(x, 0.225, 0.0)));
    }
    m.finish().mesh
}

/// A facade texture: a wall of `wall` (sRGB) with mottling and one window of `window` per
/// repeat. 32×32, repeating.
pub fn facade_texture(seed: u64, wall: Vec3, window: Vec3) -> Result<Texture, WorldgenError> {
    let image = paint(32, |u, v| {
        let n = tileable_fbm(seed, u, v, 4, 3);
        let in_window = (0.3..0.7).contains(&u) && (0.25..0.7).contains(&v);
        let sill = (0.25..0.75).contains(&u) && (0.7..0.76).contains(&v);
        if in_window {
            window * (0.8 + 0.4 * n)
        } else if sill {
            wall * 0.6
        } else {
            wall * (0.85 + 0.3 * n)
        }
    });
    encode(&image, Wrap::Repeat)
}

/// A paving texture: `cells` × `cells` slabs of `colour` (sRGB), each its own shade, in
/// darker joints; `cells` 0 gives unjointed ground (earth, grass). 32×32, repeating.
pub fn paving_texture(seed: u64, colour: Vec3, cells: u32) -> Result<Texture, WorldgenError> {
    let image = paint(32, |u, v| {
        let n = tileable_fbm(seed, u, v, 8, 2);
        if cells == 0 {
            return colour * (0.8 + 0.4 * n);
        }
        let c = cells as f32;
        let (fu, fv) = ((u * c).fract(), (v * c).fract());
        let shade = 0.85 + 0.3 * cell_hash(seed, (u * c) as i64, (v * c) as i64);
        let joint = fu < 0.08 || fv < 0.08;
        if joint {
            colour * 0.55
        } else {
            colour * shade * (0.9 + 0.2 * n)
        }
    });
    encode(&image, Wrap::Repeat)
}

/// A road texture: asphalt with a dashed centre line along v. 32×32, repeating.
pub fn road_texture(seed: u64, line: Vec3) -> Result<Texture, WorldgenError> {
    let image = paint(32, |u, v| {
        let n = tileable_fbm(seed, u, v, 8, 3);
        let asphalt = Vec3::splat(0.22 + 0.08 * n);
        if (0.47..0.53).contains(&u) && v < 0.5 {
            line
        } else {
            asphalt
        }
    });
    encode(&image, Wrap::Repeat)
}

/// A linear RGBA colour from a random sRGB colour near `base` (each channel ± `spread`).
pub fn near(rng: &mut Rng, base: Vec3, spread: f32) -> Vec3 {
    (base + Vec3::new(rng.jitter(spread), rng.jitter(spread), rng.jitter(spread)))
        .clamp(Vec3::ZERO, Vec3::ONE)
}
