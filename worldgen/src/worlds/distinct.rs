//! `city-distinct`: a city of distinct buildings, like the paper's 60,000 CityEngine buildings
//! (core paper section 8), where naive download is every building's bytes. Each building is
//! its own model: its own footprint, height, bay rhythm, window proportions and roof, its own
//! facade and roof textures, and windows as geometry (openings with jambs, sill, head and a
//! recessed pane). Three materials: textured walls, glass, textured roof. Near-duplicates
//! occur (two buildings of similar parameters); exact duplicates do not, since every
//! texture is painted from the building's own seed.
//!
//! The world is too large to hold in memory (about 300 KB per building), so it is described
//! lazily: [`city_distinct_layout`] places the objects, and [`distinct_building`] makes
//! building `k` on demand.

use glam::{Affine3A, Quat, Vec2, Vec3, Vec4};
use horizon_mesh::{InstancedMesh, Texture, Wrap};

use crate::assembly::{plain, srgb, textured, ModelBuilder};
use crate::noise::tileable_fbm;
use crate::rng::Rng;
use crate::shapes::MeshBuilder;
use crate::textures::{encode, paint};
use crate::WorldgenError;

/// Default number of buildings.
pub const CITY_DISTINCT_OBJECTS: usize = 60_000;

/// A lot's side, metres: one building per lot.
const LOT: f32 = 32.0;
/// Lots per block side.
const LOTS_PER_BLOCK: usize = 3;
/// Street width between blocks, metres.
const STREET: f32 = 16.0;

/// Where each of `objects` buildings stands: building `k` at lot `k` of a square grid of
/// blocks (3 x 3 lots of 32 m, 16 m streets), turned to a seeded multiple of 90 degrees.
pub fn city_distinct_layout(seed: u64, objects: usize) -> Vec<Affine3A> {
    let root = Rng::new(seed).fork(0x0D15_71C7);
    let per_block = LOTS_PER_BLOCK * LOTS_PER_BLOCK;
    let blocks = objects.div_ceil(per_block);
    let side = (blocks as f64).sqrt().ceil().max(1.0) as usize;
    let pitch = LOTS_PER_BLOCK as f32 * LOT + STREET;
    (0..objects)
        .map(|k| {
            let (block, lot) = (k / per_block, k % per_block);
            let (bx, bz) = ((block % side) as f32, (block / side) as f32);
            let (lx, lz) = ((lot % LOTS_PER_BLOCK) as f32, (lot / LOTS_PER_BLOCK) as f32);
            let centre = Vec3::new(
                bx * pitch + (lx + 0.5) * LOT,
                0.0,
                bz * pitch + (lz + 0.5) * LOT,
            );
            let mut r = root.fork(k as u64);
            let yaw = r.below(4) as f32 * std::f32::consts::FRAC_PI_2;
            Affine3A::from_rotation_translation(Quat::from_rotation_y(yaw), centre)
        })
        .collect()
}

/// The parameters of one building, drawn from its seed.
#[derive(Clone, Debug)]
struct Building {
    width: f32,
    depth: f32,
    floors: u32,
    floor_height: f32,
    /// Target bay width; each facade fits a whole number of bays.
    bay: f32,
    /// Window width and height as shares of a bay and of a floor.
    window: Vec2,
    /// How deep the panes sit behind the wall.
    recess: f32,
    /// A gable roof (else flat).
    gable: bool,
    wall: Vec3,
    accent: Vec3,
    glass: Vec3,
    roof: Vec3,
}

impl Building {
    fn draw(seed: u64) -> Self {
        let mut r = Rng::new(seed).fork(0xB1D6);
        let tall = r.chance(0.25);
        Self {
            width: r.range(10.0, 28.0),
            depth: r.range(9.0, 24.0),
            floors: if tall {
                6 + r.below(9) as u32
            } else {
                2 + r.below(4) as u32
            },
            floor_height: r.range(2.9, 3.8),
            bay: r.range(2.4, 4.2),
            window: Vec2::new(r.range(0.35, 0.7), r.range(0.4, 0.7)),
            recess: r.range(0.12, 0.35),
            gable: !tall && r.chance(0.4),
            wall: Vec3::new(r.range(0.35, 0.9), r.range(0.3, 0.8), r.range(0.25, 0.7)),
            accent: Vec3::new(r.range(0.2, 0.9), r.range(0.2, 0.9), r.range(0.2, 0.9)),
            glass: Vec3::new(r.range(0.1, 0.3), r.range(0.15, 0.35), r.range(0.2, 0.45)),
            roof: Vec3::new(r.range(0.25, 0.6), r.range(0.2, 0.45), r.range(0.2, 0.4)),
        }
    }
}

/// Building `index` of the city with `seed`: distinct geometry and textures, windows as
/// geometry, walls, glass and roof materials. Its origin is the centre of its footprint at
/// ground level.
///
/// # Errors
/// [`WorldgenError::Texture`] if a texture cannot be encoded.
pub fn distinct_building(seed: u64, index: usize) -> Result<InstancedMesh, WorldgenError> {
    let own = Rng::new(seed).fork(0xD157_B1D6 ^ index as u64).next_u64();
    let b = Building::draw(own);
    let mut m = ModelBuilder::new();
    let facade = m.texture(facade_texture(own, &b)?);
    let roof_texture = m.texture(roof_texture(own, &b)?);
    let wall = m.material(textured("wall", facade, Vec4::ONE, 0.9));
    let glass = m.material(plain("glass", srgb(b.glass.x, b.glass.y, b.glass.z), 0.1));
    let roof = m.material(textured("roof", roof_texture, Vec4::ONE, 0.8));
    let (walls, panes, top) = shell(&b);
    for (name, geometry, material) in [
        ("walls", walls, wall),
        ("glass", panes, glass),
        ("roof", top, roof),
    ] {
        let s = m.submesh(name, false, geometry, material);
        m.place(s, Affine3A::IDENTITY);
    }
    Ok(m.finish().mesh)
}

/// Metres of facade one texture repeat covers.
const FACADE_TILE: f32 = 6.0;

/// The walls (with openings and their reveals), the panes and the roof of `b`.
fn shell(b: &Building) -> (MeshBuilder, MeshBuilder, MeshBuilder) {
    let (mut walls, mut panes, mut roof) =
        (MeshBuilder::new(), MeshBuilder::new(), MeshBuilder::new());
    let height = b.floors as f32 * b.floor_height;
    let (hw, hd) = (b.width * 0.5, b.depth * 0.5);
    // The four facades: outward normal, length, and the corner they start from (seen from
    // outside, left to right).
    let facades = [
        (Vec3::Z, b.width, Vec3::new(-hw, 0.0, hd)),
        (Vec3::X, b.depth, Vec3::new(hw, 0.0, hd)),
        (Vec3::NEG_Z, b.width, Vec3::new(hw, 0.0, -hd)),
        (Vec3::NEG_X, b.depth, Vec3::new(-hw, 0.0, -hd)),
    ];
    for (side, &(out, length, start)) in facades.iter().enumerate() {
        let along = Vec3::Y.cross(out);
        let at = |a: f32, y: f32, depth: f32| start + along * a + Vec3::Y * y - out * depth;
        let uv = |a: f32, y: f32| Vec2::new(a / FACADE_TILE, 1.0 - y / FACADE_TILE);
        let bays = ((length / b.bay).round() as usize).max(1);
        let bay = length / bays as f32;
        for floor in 0..b.floors {
            let (y0, y1) = (
                floor as f32 * b.floor_height,
                (floor + 1) as f32 * b.floor_height,
            );
            for k in 0..bays {
                let (a0, a1) = (k as f32 * bay, (k + 1) as f32 * bay);
                // The opening: a window, or on the ground floor's middle bay of the first
                // facade a door down to the ground.
                let door = floor == 0 && side == 0 && k == bays / 2;
                let half_w = bay * b.window.x * 0.5;
                let (w0, w1) = ((a0 + a1) * 0.5 - half_w, (a0 + a1) * 0.5 + half_w);
                let (o0, o1) = if door {
                    (y0, y0 + (b.floor_height * 0.8).min(2.6))
                } else {
                    let h = b.floor_height * b.window.y;
                    let sill = y0 + (b.floor_height - h) * 0.55;
                    (sill, sill + h)
                };
                // Wall around the opening: left, right, below, above.
                for (p, q) in [
                    ((a0, y0), (w0, y1)),
                    ((w1, y0), (a1, y1)),
                    ((w0, y0), (w1, o0)),
                    ((w0, o1), (w1, y1)),
                ] {
                    if q.0 - p.0 > 1e-4 && q.1 - p.1 > 1e-4 {
                        rect(
                            &mut walls,
                            [
                                at(p.0, p.1, 0.0),
                                at(q.0, p.1, 0.0),
                                at(q.0, q.1, 0.0),
                                at(p.0, q.1, 0.0),
                            ],
                            out,
                            [uv(p.0, p.1), uv(q.0, p.1), uv(q.0, q.1), uv(p.0, q.1)],
                        );
                    }
                }
                // The reveals: jambs, sill and head, from the wall plane back to the pane.
                let r = b.recess;
                let reveal_uv = |a: f32, y: f32, d: f32| uv(a + d, y);
                rect(
                    &mut walls,
                    [
                        at(w0, o0, r),
                        at(w0, o0, 0.0),
                        at(w0, o1, 0.0),
                        at(w0, o1, r),
                    ],
                    along,
                    [
                        reveal_uv(w0, o0, -r),
                        reveal_uv(w0, o0, 0.0),
                        reveal_uv(w0, o1, 0.0),
                        reveal_uv(w0, o1, -r),
                    ],
                );
                rect(
                    &mut walls,
                    [
                        at(w1, o0, 0.0),
                        at(w1, o0, r),
                        at(w1, o1, r),
                        at(w1, o1, 0.0),
                    ],
                    -along,
                    [
                        reveal_uv(w1, o0, 0.0),
                        reveal_uv(w1, o0, r),
                        reveal_uv(w1, o1, r),
                        reveal_uv(w1, o1, 0.0),
                    ],
                );
                if !door {
                    rect(
                        &mut walls,
                        [
                            at(w0, o0, r),
                            at(w1, o0, r),
                            at(w1, o0, 0.0),
                            at(w0, o0, 0.0),
                        ],
                        Vec3::Y,
                        [uv(w0, o0 + r), uv(w1, o0 + r), uv(w1, o0), uv(w0, o0)],
                    );
                }
                rect(
                    &mut walls,
                    [
                        at(w0, o1, 0.0),
                        at(w1, o1, 0.0),
                        at(w1, o1, r),
                        at(w0, o1, r),
                    ],
                    Vec3::NEG_Y,
                    [uv(w0, o1), uv(w1, o1), uv(w1, o1 - r), uv(w0, o1 - r)],
                );
                // The pane.
                let unit =
                    |a: f32, y: f32| Vec2::new((a - w0) / (w1 - w0), 1.0 - (y - o0) / (o1 - o0));
                rect(
                    &mut panes,
                    [at(w0, o0, r), at(w1, o0, r), at(w1, o1, r), at(w0, o1, r)],
                    out,
                    [unit(w0, o0), unit(w1, o0), unit(w1, o1), unit(w0, o1)],
                );
            }
        }
        // A gable end above the eaves on the two short facades.
        if b.gable && side % 2 == 1 {
            let rise = b.width.min(b.depth) * 0.35;
            let (p, q, t) = (
                at(0.0, height, 0.0),
                at(length, height, 0.0),
                at(length * 0.5, height + rise, 0.0),
            );
            let (i, j, k) = (
                walls.vertex(p, out, uv(0.0, height)),
                walls.vertex(q, out, uv(length, height)),
                walls.vertex(t, out, uv(length * 0.5, height + rise)),
            );
            walls.triangle(i, j, k);
        }
    }
    // The roof: flat, or two slopes along the longer axis (gable ends on the +x and -x
    // facades, so the ridge runs along x when the gable is on the depth sides).
    let uv_top = |p: Vec3| Vec2::new(p.x / 8.0, p.z / 8.0);
    if b.gable {
        let rise = b.width.min(b.depth) * 0.35;
        let ridge_a = Vec3::new(-hw, height + rise, 0.0);
        let ridge_b = Vec3::new(hw, height + rise, 0.0);
        for (eave_a, eave_b) in [
            (Vec3::new(-hw, height, hd), Vec3::new(hw, height, hd)),
            (Vec3::new(hw, height, -hd), Vec3::new(-hw, height, -hd)),
        ] {
            let (ra, rb) = if eave_a.z > 0.0 {
                (ridge_a, ridge_b)
            } else {
                (ridge_b, ridge_a)
            };
            let n = (eave_b - eave_a).cross(rb - eave_a).normalize();
            rect(
                &mut roof,
                [eave_a, eave_b, rb, ra],
                n,
                [
                    uv_top(eave_a),
                    uv_top(eave_b),
                    Vec2::new(uv_top(rb).x, uv_top(rb).y + rise / 8.0),
                    Vec2::new(uv_top(ra).x, uv_top(ra).y + rise / 8.0),
                ],
            );
        }
    } else {
        let c = [
            Vec3::new(-hw, height, hd),
            Vec3::new(hw, height, hd),
            Vec3::new(hw, height, -hd),
            Vec3::new(-hw, height, -hd),
        ];
        rect(&mut roof, c, Vec3::Y, c.map(uv_top));
    }
    (walls, panes, roof)
}

/// Adds the quad `p` (counter-clockwise seen from the side `normal` points to) with `uvs`.
fn rect(m: &mut MeshBuilder, p: [Vec3; 4], normal: Vec3, uvs: [Vec2; 4]) {
    let v: Vec<u32> = (0..4).map(|i| m.vertex(p[i], normal, uvs[i])).collect();
    m.oriented_triangle(v[0], v[1], v[2], normal);
    m.oriented_triangle(v[0], v[2], v[3], normal);
}

/// The building's own facade: plaster or brick in its colour with noise, string courses in
/// its accent colour. 256 x 256, repeating every [`FACADE_TILE`] metres.
fn facade_texture(seed: u64, b: &Building) -> Result<Texture, WorldgenError> {
    let brick = seed.is_multiple_of(3);
    let (wall, accent) = (b.wall, b.accent);
    let image = paint(256, |u, v| {
        let n = tileable_fbm(seed, u, v, 16, 4);
        let course = (v * 6.0).fract() < 0.04;
        if course {
            return accent * (0.8 + 0.3 * n);
        }
        if brick {
            let row = (v * 48.0).floor();
            let shift = if row as i64 % 2 == 0 { 0.0 } else { 0.5 };
            let (fu, fv) = ((u * 24.0 + shift).fract(), (v * 48.0).fract());
            if fu < 0.06 || fv < 0.1 {
                return Vec3::splat(0.75) * (0.9 + 0.2 * n);
            }
        }
        wall * (0.75 + 0.5 * n)
    });
    encode(&image, Wrap::Repeat)
}

/// The building's own roof: its colour in noisy tiles or membrane. 128 x 128, repeating every
/// 8 metres.
fn roof_texture(seed: u64, b: &Building) -> Result<Texture, WorldgenError> {
    let roof = b.roof;
    let image = paint(128, |u, v| {
        let n = tileable_fbm(seed ^ 0x5EED, u, v, 8, 4);
        let seam = (u * 16.0).fract() < 0.08;
        roof * if seam { 0.6 } else { 0.8 + 0.4 * n }
    });
    encode(&image, Wrap::Repeat)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buildings_are_distinct_valid_and_have_windows_in_three_materials(
    ) -> Result<(), WorldgenError> {
        let a = distinct_building(1, 0)?;
        let b = distinct_building(1, 1)?;
        for m in [&a, &b] {
            m.validate().expect("a valid mesh");
            assert_eq!(m.materials.len(), 3);
            assert_eq!(m.textures.len(), 2);
            // At least two floors of two bays on four sides, 18 triangles a window.
            assert!(
                m.expanded_triangle_count() >= 2 * 2 * 4 * 18,
                "{}",
                m.expanded_triangle_count()
            );
            // The panes sit behind the wall plane: some glass vertex is inside the footprint.
            let bounds = m.bounds();
            let glass = &m.submeshes[1];
            assert!(glass
                .positions
                .iter()
                .all(|p| p.x > bounds.min.x && p.x < bounds.max.x));
        }
        assert_ne!(a.textures[0].bytes, b.textures[0].bytes);
        assert_ne!(a.submeshes[0].positions, b.submeshes[0].positions);
        // The same seed and index give the same building.
        assert_eq!(distinct_building(1, 0)?, a);
        Ok(())
    }

    #[test]
    fn the_layout_gives_every_building_its_own_lot() {
        let lots = city_distinct_layout(3, 100);
        assert_eq!(lots.len(), 100);
        for (i, a) in lots.iter().enumerate() {
            for b in &lots[i + 1..] {
                assert!(a.translation.distance(b.translation) >= LOT - 1e-3);
            }
        }
    }
}
