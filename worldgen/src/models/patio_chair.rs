//! The patio chair of the IAS paper (Azim et al. 2014, Table 2 and figure 9): a slatted garden
//! chair of 6 submeshes and 68 instances, exactly 2,240 expanded triangles.
//!
//! | submesh     | triangles | instances | placed as                                      |
//! |-------------|-----------|-----------|------------------------------------------------|
//! | `leg`       | 28        | 4         | front legs stretched up to the arms            |
//! | `slat`      | 44        | 24        | 11 seat slats across, 13 back slats upright    |
//! | `rail`      | 12        | 10        | seat frame, stretchers, back frame             |
//! | `armrest`   | 52        | 2         | right arm, and its mirror image on the left    |
//! | `bolt`      | 20        | 26        | two per seat slat, two per arm                 |
//! | `back-post` | 164       | 2         | right post, and its mirror image on the left   |

use std::f32::consts::{FRAC_PI_2, PI};

use glam::{Affine3A, Quat, Vec2, Vec3};
use horizon_mesh::Material;

use crate::assembly::{plain, srgb, textured, trs, ModelBuilder};
use crate::rng::Rng;
use crate::shapes::{extrude, MeshBuilder};
use crate::{textures, GeneratedModel, WorldgenError};

/// Builds the chair; `seed` jitters slats and bolts by millimetres and varies the wood.
pub(crate) fn generate(seed: u64) -> Result<GeneratedModel, WorldgenError> {
    let mut rng = Rng::new(seed).fork(0xC4A1);
    let mut model = ModelBuilder::new();
    let wood_texture = model.texture(textures::wood(seed)?);
    let teak = model.material(textured("teak", wood_texture, srgb(0.95, 0.8, 0.65), 0.7));
    let steel = model.material(Material {
        metallic_factor: 1.0,
        ..plain("steel", srgb(0.6, 0.6, 0.62), 0.4)
    });

    let leg = model.submesh("leg", true, leg_geometry(), teak);
    let slat = model.submesh("slat", true, slat_geometry(), teak);
    let rail = model.submesh("rail", true, rail_geometry(), teak);
    let armrest = model.submesh("armrest", true, armrest_geometry(), teak);
    let bolt = model.submesh("bolt", true, bolt_geometry(), steel);
    let back_post = model.submesh("back-post", true, back_post_geometry(), teak);

    // Every piece is built along +Z (so its wood grain runs along it): a quarter turn about Y
    // turns it along X, `upright` turns it up.
    let quarter_turn = Quat::from_rotation_y(FRAC_PI_2);
    let upright = Quat::from_rotation_x(-FRAC_PI_2);
    let recline = Quat::from_rotation_x(-BACK_RECLINE);
    let back_direction = recline * Vec3::Y;
    let back_base = |x: f32| Vec3::new(x, SEAT_FRAME_TOP - 0.05, -0.24);

    // Legs: the front pair reaches up to the arms, a non-uniform stretch of the same leg.
    for x in [-0.26, 0.26] {
        let front = ARM_HEIGHT / LEG_LENGTH;
        model.place(
            leg,
            trs(Vec3::new(x, 0.0, 0.22), upright, Vec3::new(1.0, 1.0, front)),
        );
        model.place(leg, trs(Vec3::new(x, 0.0, -0.22), upright, Vec3::ONE));
    }
    // Rails: seat frame, low stretchers, and the back frame holding the back slats.
    let rail_y = SEAT_FRAME_TOP - 0.025;
    let across = |y: f32, z: f32| {
        trs(
            Vec3::new(0.0, y, z),
            quarter_turn,
            Vec3::new(1.0, 1.0, 0.56 / RAIL_LENGTH),
        )
    };
    let lengthwise = |x: f32, y: f32| {
        trs(
            Vec3::new(x, y, 0.0),
            Quat::IDENTITY,
            Vec3::new(1.0, 1.0, 0.48 / RAIL_LENGTH),
        )
    };
    for t in [
        across(rail_y, 0.23),
        across(rail_y, -0.23),
        lengthwise(-0.26, rail_y),
        lengthwise(0.26, rail_y),
        across(0.15, 0.22),
        across(0.15, -0.22),
        lengthwise(-0.26, 0.15),
        lengthwise(0.26, 0.15),
    ] {
        model.place(rail, t);
    }
    for s in [0.1, 0.46] {
        let centre = back_base(0.0) + back_direction * s + Vec3::new(0.0, 0.0, -0.02);
        model.place(
            rail,
            trs(
                centre,
                recline * quarter_turn,
                Vec3::new(1.0, 1.0, 0.52 / RAIL_LENGTH),
            ),
        );
    }
    // Seat slats across the frame, each screwed down at both ends.
    let slat_y = SEAT_FRAME_TOP + SLAT_THICKNESS * 0.5;
    for k in 0..SEAT_SLATS {
        let z = -0.22 + 0.44 * k as f32 / (SEAT_SLATS - 1) as f32 + rng.jitter(0.0015);
        let turn = Quat::from_rotation_y(FRAC_PI_2 + rng.jitter(0.006));
        let length = 0.58 / SLAT_LENGTH * (1.0 + rng.jitter(0.01));
        model.place(
            slat,
            trs(
                Vec3::new(rng.jitter(0.002), slat_y, z),
                turn,
                Vec3::new(1.0, 1.0, length),
            ),
        );
        for x in [-0.26, 0.26] {
            let head = Vec3::new(x, SEAT_FRAME_TOP + SLAT_THICKNESS, z);
            model.place(
                bolt,
                trs(
                    head,
                    Quat::from_rotation_y(rng.angle()) * upright,
                    Vec3::ONE,
                ),
            );
        }
    }
    // Back slats: upright, narrower and shorter than the seat slats (same submesh, scaled).
    for k in 0..BACK_SLATS {
        let x = -0.22 + 0.44 * k as f32 / (BACK_SLATS - 1) as f32 + rng.jitter(0.0015);
        // The slat submesh is centred on its length, which runs from 0.07 to 0.49 up the back.
        let centre = back_base(x) + back_direction * 0.28;
        let length = 0.42 / SLAT_LENGTH;
        let rotation = recline * upright * Quat::from_rotation_z(rng.jitter(0.006));
        model.place(slat, trs(centre, rotation, Vec3::new(0.85, 1.0, length)));
    }
    // Back posts and arms: the left ones are mirror images of the right ones.
    for side in [1.0f32, -1.0] {
        let mirror = Vec3::new(side, 1.0, 1.0);
        model.place(
            back_post,
            trs(back_base(0.26 * side), recline * upright, mirror),
        );
        let arm_origin = Vec3::new(0.29 * side, ARM_HEIGHT, -0.27);
        model.place(armrest, trs(arm_origin, upright, mirror));
        for z in [-0.24, 0.22] {
            let head = Vec3::new(0.29 * side, ARM_HEIGHT + ARM_THICKNESS, z);
            model.place(
                bolt,
                trs(
                    head,
                    Quat::from_rotation_y(rng.angle()) * upright,
                    Vec3::ONE,
                ),
            );
        }
    }
    Ok(model.finish())
}

/// Height of the seat frame's top, where the slats rest.
const SEAT_FRAME_TOP: f32 = 0.47;
/// Height of the underside of the arms.
const ARM_HEIGHT: f32 = 0.64;
/// Thickness of an arm.
const ARM_THICKNESS: f32 = 0.025;
/// Length of the leg submesh (a back leg; the front legs are stretched).
const LEG_LENGTH: f32 = 0.42;
/// Length of the rail submesh before scaling.
const RAIL_LENGTH: f32 = 0.5;
/// Length of the slat submesh before scaling.
const SLAT_LENGTH: f32 = 0.5;
/// Thickness of a slat.
const SLAT_THICKNESS: f32 = 0.018;
/// How far the back leans back, in radians.
const BACK_RECLINE: f32 = 12.0 * PI / 180.0;
const SEAT_SLATS: usize = 11;
const BACK_SLATS: usize = 13;

/// A square leg with chamfered edges: an octagon extruded along +Z. 28 triangles.
fn leg_geometry() -> MeshBuilder {
    let (h, c) = (0.0225, 0.007);
    let octagon = [
        Vec2::new(h - c, -h),
        Vec2::new(h, -h + c),
        Vec2::new(h, h - c),
        Vec2::new(h - c, h),
        Vec2::new(-h + c, h),
        Vec2::new(-h, h - c),
        Vec2::new(-h, -h + c),
        Vec2::new(-h + c, -h),
    ];
    extrude(&octagon, LEG_LENGTH, 1, 30.0)
}

/// A rail of the frame: a 2.5 × 5 cm bar along Z, centred. 12 triangles.
fn rail_geometry() -> MeshBuilder {
    let bar = [
        Vec2::new(-0.0125, -0.025),
        Vec2::new(0.0125, -0.025),
        Vec2::new(0.0125, 0.025),
        Vec2::new(-0.0125, 0.025),
    ];
    extrude(&bar, RAIL_LENGTH, 1, 30.0)
        .transformed(Affine3A::from_translation(Vec3::Z * (-0.5 * RAIL_LENGTH)))
}

/// A slat with rounded edges (12-point profile) along Z, centred. 44 triangles.
fn slat_geometry() -> MeshBuilder {
    let profile = rounded_rectangle(Vec2::new(0.04, SLAT_THICKNESS), 0.006);
    extrude(&profile, SLAT_LENGTH, 1, 50.0).transformed(Affine3A::from_translation(Vec3::new(
        0.0,
        0.0,
        -0.5 * SLAT_LENGTH,
    )))
}

/// An arm seen from above: square at the back, rounded at the front, flaring outward (+X).
/// 14-point profile extruded to the arm's thickness. 52 triangles.
fn armrest_geometry() -> MeshBuilder {
    let (length, radius, centre_x) = (0.52, 0.04, 0.005);
    let mut outline = vec![Vec2::new(0.03, 0.0)];
    outline.extend((0..12).map(|i| {
        let a = -PI * i as f32 / 11.0;
        Vec2::new(centre_x, -length) + radius * Vec2::new(a.cos(), a.sin())
    }));
    outline.push(Vec2::new(centre_x - radius, 0.0));
    extrude(&outline, ARM_THICKNESS, 1, 40.0)
}

/// A hexagonal bolt head. 20 triangles.
fn bolt_geometry() -> MeshBuilder {
    let hexagon: Vec<Vec2> = (0..6)
        .map(|j| 0.008 * Vec2::from_angle(PI / 3.0 * j as f32))
        .collect();
    extrude(&hexagon, 0.005, 1, 30.0)
}

/// A back post: a rounded bar in 6 slices, curving back and slightly outward towards its top.
/// 164 triangles.
fn back_post_geometry() -> MeshBuilder {
    let length = 0.5;
    let profile = rounded_rectangle(Vec2::new(0.045, 0.03), 0.008);
    extrude(&profile, length, 6, 50.0).displaced(|p| {
        let t = p.z / length;
        // +Y of the profile becomes -Z (backwards) once the post is stood upright.
        p + Vec3::new(0.02 * t * t, 0.06 * t * t, 0.0)
    })
}

/// A rectangle of `size` centred on the origin with corners rounded by `radius`, three points
/// per corner (12 in all), counter-clockwise.
fn rounded_rectangle(size: Vec2, radius: f32) -> Vec<Vec2> {
    let inner = size * 0.5 - Vec2::splat(radius);
    let corners = [
        (Vec2::new(inner.x, -inner.y), -FRAC_PI_2),
        (Vec2::new(inner.x, inner.y), 0.0),
        (Vec2::new(-inner.x, inner.y), FRAC_PI_2),
        (Vec2::new(-inner.x, -inner.y), PI),
    ];
    corners
        .iter()
        .flat_map(|&(centre, start)| {
            (0..3).map(move |i| {
                centre + radius * Vec2::from_angle(start + FRAC_PI_2 * i as f32 / 2.0)
            })
        })
        .collect()
}
