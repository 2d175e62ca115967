//! Stonehenge as in the IAS paper (Azim et al. 2014, Table 2): 59 submeshes, 80 instances,
//! about 10k expanded triangles. Most stones are unique and placed once; a few are reused.
//!
//! | part                         | submeshes | instances | triangles each |
//! |------------------------------|-----------|-----------|----------------|
//! | ground with bank and ditch   | 1         | 1         | 1,984          |
//! | sarsen circle uprights       | 19        | 24        | 144            |
//! | sarsen circle lintels        | 6         | 8         | 80             |
//! | trilithon uprights           | 7         | 7         | 184            |
//! | trilithon lintels            | 3         | 3         | 80             |
//! | bluestones                   | 14        | 28        | 56             |
//! | altar, slaughter, heel stone | 3         | 3         | 80, 80, 156    |
//! | station stones               | 2         | 2         | 80             |
//! | fallen stones                | 4         | 4         | 144, 80, 104   |
//!
//! Every stone is a subdivided block weathered by noise, closed, with hard edges between its
//! faces. Reused stones are turned around and some mirrored.

use std::f32::consts::{FRAC_PI_2, PI, TAU};

use glam::{Affine3A, Quat, Vec2, Vec3};

use crate::assembly::{plain, srgb, textured, trs, ModelBuilder};
use crate::noise::fbm3;
use crate::rng::Rng;
use crate::shapes::{polar_sheet, subdivided_box, MeshBuilder};
use crate::{textures, GeneratedModel, WorldgenError};

/// Builds the monument; `seed` weathers every stone, picks the missing ones and jitters the
/// placements.
pub(crate) fn generate(seed: u64) -> Result<GeneratedModel, WorldgenError> {
    let rng = Rng::new(seed);
    let mut shapes = rng.fork(1);
    let mut placing = rng.fork(2);
    let mut model = ModelBuilder::new();
    let stone_texture = model.texture(textures::stone(seed)?);
    let grass_texture = model.texture(textures::grass(seed)?);
    let sarsen = model.material(textured(
        "sarsen",
        stone_texture,
        srgb(0.95, 0.92, 0.85),
        0.9,
    ));
    let bluestone = model.material(textured(
        "bluestone",
        stone_texture,
        srgb(0.7, 0.76, 0.85),
        0.8,
    ));
    let altar_sandstone = model.material(plain("altar-sandstone", srgb(0.45, 0.48, 0.40), 0.85));
    let turf = model.material(textured("turf", grass_texture, srgb(1.0, 1.0, 1.0), 1.0));

    // Ground: a polar sheet with the circular bank and ditch.
    let ground_seed = shapes.next_u64();
    let ground_height = move |x: f32, z: f32| ground_height(ground_seed, x, z);
    let ground = polar_sheet(
        64,
        16,
        Vec3::Y,
        |theta, f| {
            let r = GROUND_RADIUS * f;
            let (x, z) = (r * theta.cos(), r * theta.sin());
            Vec3::new(x, ground_height(x, z), z)
        },
        |p| Vec2::new(p.x, p.z) * 0.25,
    );
    let ground = model.submesh("ground", false, ground, turf);
    model.place(ground, Affine3A::IDENTITY);

    // The sarsen circle: 30 slots; the 9 under the surviving lintels are always standing, and
    // 15 of the other 21 survive.
    let mut others: Vec<usize> = (9..30).collect();
    placing.shuffle(&mut others);
    let mut standing: Vec<usize> = (0..9).chain(others[..15].iter().copied()).collect();
    standing.sort_unstable();
    let upright_ids: Vec<usize> = (0..19)
        .map(|i| {
            let geometry = weathered_block(&mut shapes, Vec3::new(2.1, 4.6, 1.1), [3, 6, 2], 0.12);
            model.submesh(format!("sarsen-upright-{i:02}"), true, geometry, sarsen)
        })
        .collect();
    // Five uprights are used twice, turned round; two of those are mirrored.
    let mut uses: Vec<(usize, bool)> = (0..19).map(|i| (i, false)).collect();
    uses.extend([3, 7, 11, 15, 18].map(|i| (i, true)));
    placing.shuffle(&mut uses);
    for (k, (&slot, &(stone, repeat))) in standing.iter().zip(&uses).enumerate() {
        let angle = slot as f32 * TAU / 30.0;
        let carries_lintel = slot <= 8;
        let lean = if carries_lintel {
            0.0
        } else {
            placing.jitter(0.06)
        };
        let turn = if repeat { PI } else { 0.0 };
        let rotation = Quat::from_rotation_y(tangent_yaw(angle) + turn + placing.jitter(0.04))
            * Quat::from_rotation_x(lean);
        let height = if carries_lintel {
            1.0
        } else {
            placing.range(0.85, 1.05)
        };
        let mirror = if repeat && k % 2 == 0 { -1.0 } else { 1.0 };
        let scale = Vec3::new(
            mirror * placing.range(0.92, 1.08),
            height,
            placing.range(0.9, 1.1),
        );
        let centre = on_circle(SARSEN_RADIUS, angle, 4.6 * height * 0.5 - BURIED);
        model.place(upright_ids[stone], trs(centre, rotation, scale));
    }
    // Lintels over slots 0-8: 8 lintels from 6 stones (two reused).
    let lintel_ids: Vec<usize> = (0..6)
        .map(|i| {
            let geometry = weathered_block(&mut shapes, Vec3::new(3.2, 0.8, 1.0), [6, 1, 2], 0.0);
            model.submesh(format!("sarsen-lintel-{i}"), true, geometry, sarsen)
        })
        .collect();
    let chord = 2.0 * SARSEN_RADIUS * (PI / 30.0).sin();
    for k in 0..8 {
        let angle = (k as f32 + 0.5) * TAU / 30.0;
        let centre = on_circle(SARSEN_RADIUS * (PI / 30.0).cos(), angle, 4.6 - BURIED + 0.4);
        let turn = if k >= 6 { PI } else { 0.0 };
        let rotation = Quat::from_rotation_y(tangent_yaw(angle) + turn + placing.jitter(0.02));
        let scale = Vec3::new(
            chord / 3.2,
            placing.range(0.95, 1.05),
            placing.range(0.95, 1.05),
        );
        model.place(lintel_ids[k % 6], trs(centre, rotation, scale));
    }

    // Trilithons in a horseshoe opening towards the heel stone (+X): three complete, the great
    // trilithon with one upright left standing, one fallen altogether.
    let trilithons = [
        (60.0f32, 8.0, 0.82, true),
        (-60.0, 8.0, 0.82, true),
        (115.0, 7.4, 0.9, true),
        (180.0, 6.5, 1.0, false),
    ];
    let mut trilithon_upright = 0;
    for (t, &(degrees, radius, height, complete)) in trilithons.iter().enumerate() {
        let angle = degrees.to_radians();
        let yaw = tangent_yaw(angle);
        let tangent = Vec3::new(-angle.sin(), 0.0, angle.cos());
        let legs: &[f32] = if complete { &[-1.3, 1.3] } else { &[1.3] };
        for &offset in legs {
            let geometry = weathered_block(&mut shapes, Vec3::new(2.4, 7.3, 1.3), [3, 8, 2], 0.1);
            let id = model.submesh(
                format!("trilithon-upright-{trilithon_upright}"),
                true,
                geometry,
                sarsen,
            );
            trilithon_upright += 1;
            let centre = on_circle(radius, angle, 7.3 * height * 0.5 - 1.0) + tangent * offset;
            let scale = Vec3::new(placing.range(0.95, 1.05), height, placing.range(0.95, 1.05));
            model.place(
                id,
                trs(
                    centre,
                    Quat::from_rotation_y(yaw + placing.jitter(0.03)),
                    scale,
                ),
            );
        }
        if complete {
            let geometry = weathered_block(&mut shapes, Vec3::new(4.8, 1.0, 1.2), [6, 1, 2], 0.0);
            let id = model.submesh(format!("trilithon-lintel-{t}"), true, geometry, sarsen);
            let centre = on_circle(radius, angle, 7.3 * height - 1.0 + 0.5);
            model.place(
                id,
                trs(
                    centre,
                    Quat::from_rotation_y(yaw + placing.jitter(0.02)),
                    Vec3::ONE,
                ),
            );
        }
    }

    // Bluestones: 28 in a circle and an inner horseshoe, from 14 stones (10 used twice, 2 three
    // times); every repeat is mirrored.
    let blue_ids: Vec<usize> = (0..14)
        .map(|i| {
            let geometry = weathered_block(&mut shapes, Vec3::new(0.7, 2.2, 0.5), [2, 4, 1], 0.15);
            model.submesh(format!("bluestone-{i:02}"), true, geometry, bluestone)
        })
        .collect();
    let mut blue_uses: Vec<(usize, bool)> = (0..14).map(|i| (i, false)).collect();
    blue_uses.extend((0..10).chain([10, 11, 10, 11]).map(|i| (i, true)));
    placing.shuffle(&mut blue_uses);
    let mut circle_slots: Vec<usize> = (0..40).collect();
    placing.shuffle(&mut circle_slots);
    let circle = circle_slots[..20]
        .iter()
        .map(|&s| (11.5, s as f32 * TAU / 40.0));
    let horseshoe = (0..8).map(|k| (5.0, (50.0 + 260.0 * k as f32 / 7.0).to_radians()));
    for ((radius, angle), &(stone, repeat)) in circle.chain(horseshoe).zip(&blue_uses) {
        let height = placing.range(0.7, 1.1);
        let mirror = if repeat { -1.0 } else { 1.0 };
        let scale = Vec3::new(
            mirror * placing.range(0.85, 1.15),
            height,
            placing.range(0.85, 1.15),
        );
        let rotation = Quat::from_rotation_y(tangent_yaw(angle) + placing.jitter(0.3))
            * Quat::from_rotation_z(placing.jitter(0.08));
        let centre = on_circle(
            radius + placing.jitter(0.3),
            angle,
            2.2 * height * 0.5 - 0.4,
        );
        model.place(blue_ids[stone], trs(centre, rotation, scale));
    }

    // The named single stones.
    let lying =
        |shapes: &mut Rng, size: Vec3, cells: [u32; 3]| weathered_block(shapes, size, cells, 0.0);
    let altar = lying(&mut shapes, Vec3::new(4.9, 0.5, 1.0), [6, 1, 2]);
    let altar = model.submesh("altar-stone", true, altar, altar_sandstone);
    model.place(
        altar,
        trs(
            Vec3::new(-4.2, 0.15, 0.4),
            Quat::from_rotation_y(FRAC_PI_2 + placing.jitter(0.1)),
            Vec3::ONE,
        ),
    );
    let slaughter = lying(&mut shapes, Vec3::new(6.4, 0.8, 2.1), [6, 1, 2]);
    let slaughter = model.submesh("slaughter-stone", true, slaughter, sarsen);
    let at = Vec3::new(32.0, 0.0, 2.0);
    let at = at + Vec3::Y * (ground_height(at.x, at.z) + 0.2);
    model.place(
        slaughter,
        trs(
            at,
            Quat::from_rotation_y(0.2 + placing.jitter(0.1)),
            Vec3::ONE,
        ),
    );
    let heel = weathered_block(&mut shapes, Vec3::new(2.4, 5.0, 2.0), [3, 5, 3], 0.25);
    let heel = model.submesh("heel-stone", true, heel, sarsen);
    let at = Vec3::new(77.0, 0.0, 3.0);
    let at = at + Vec3::Y * (ground_height(at.x, at.z) + 1.5);
    model.place(
        heel,
        trs(
            at,
            Quat::from_rotation_z(0.4) * Quat::from_rotation_y(placing.angle()),
            Vec3::ONE,
        ),
    );
    for (i, degrees) in [120.0f32, 300.0].into_iter().enumerate() {
        let station = weathered_block(&mut shapes, Vec3::new(1.2, 2.6, 0.9), [2, 4, 2], 0.1);
        let station = model.submesh(format!("station-stone-{i}"), true, station, sarsen);
        let angle = degrees.to_radians();
        let ground = on_circle(40.0, angle, 0.0);
        let centre = ground + Vec3::Y * (ground_height(ground.x, ground.z) + 0.8);
        model.place(
            station,
            trs(centre, Quat::from_rotation_y(placing.angle()), Vec3::ONE),
        );
    }

    // Fallen stones, lying where they fell: the great trilithon's second upright in two pieces,
    // an upright of the fallen trilithon, and a sarsen lintel.
    let fallen = [
        (
            "fallen-great-upright-top",
            Vec3::new(3.6, 1.3, 2.4),
            [4, 2, 3],
            Vec3::new(-5.0, 0.4, -3.5),
        ),
        (
            "fallen-great-upright-base",
            Vec3::new(3.6, 1.3, 2.4),
            [4, 2, 3],
            Vec3::new(-8.5, 0.3, -2.0),
        ),
        (
            "fallen-trilithon-upright",
            Vec3::new(4.1, 1.1, 2.1),
            [6, 2, 3],
            Vec3::new(-4.5, 0.3, -6.5),
        ),
        (
            "fallen-sarsen-lintel",
            Vec3::new(3.2, 0.8, 1.0),
            [6, 1, 2],
            Vec3::new(-13.0, 0.2, 9.0),
        ),
    ];
    for (name, size, cells, at) in fallen {
        let geometry = lying(&mut shapes, size, cells);
        let id = model.submesh(name, true, geometry, sarsen);
        let rotation =
            Quat::from_rotation_y(placing.angle()) * Quat::from_rotation_x(placing.jitter(0.12));
        model.place(id, trs(at, rotation, Vec3::ONE));
    }
    Ok(model.finish())
}

/// Radius of the sarsen circle's centre line, in metres.
const SARSEN_RADIUS: f32 = 16.5;
/// How deep the sarsen uprights are set into the ground.
const BURIED: f32 = 0.5;
/// Radius of the ground disc: far enough to hold the heel stone.
const GROUND_RADIUS: f32 = 90.0;

/// A point at `radius` and `angle` (from +X towards +Z) at height `y`.
fn on_circle(radius: f32, angle: f32, y: f32) -> Vec3 {
    Vec3::new(radius * angle.cos(), y, radius * angle.sin())
}

/// The yaw that turns a stone's broad face (+X) along the circle's tangent at `angle`.
fn tangent_yaw(angle: f32) -> f32 {
    -(angle + FRAC_PI_2)
}

/// Ground height: flat inside, a circular bank with a ditch outside it at about 55 m, gentle
/// undulation beyond.
fn ground_height(seed: u64, x: f32, z: f32) -> f32 {
    let r = (x * x + z * z).sqrt();
    let bank = 0.7 * (-((r - 52.0) / 3.0).powi(2)).exp();
    let ditch = -0.6 * (-((r - 58.0) / 2.5).powi(2)).exp();
    let rolling = (fbm3(seed, Vec3::new(x, 0.0, z) * 0.03, 3) - 0.5) * 2.0;
    let away = ((r - 20.0) / 20.0).clamp(0.0, 1.0);
    bank + ditch + rolling * away
}

/// A stone: a subdivided block of `size` weathered by noise, narrowing by `taper` towards the
/// top, its vertical edges rounded. Closed; UVs tile the stone texture every 2 m.
fn weathered_block(rng: &mut Rng, size: Vec3, cells: [u32; 3], taper: f32) -> MeshBuilder {
    let noise_seed = rng.next_u64();
    let roughness = rng.range(0.06, 0.1);
    let half = size * 0.5;
    subdivided_box(size, cells)
        .displaced(move |p| {
            let q = p / half;
            let t = 0.5 * (q.y + 1.0);
            let round = 1.0 - 0.12 * (q.x * q.z).powi(2);
            let narrow = (1.0 - taper * t) * (1.0 + 0.05 * (PI * t).sin()) * round;
            let bumps = 1.0 + roughness * 2.0 * (fbm3(noise_seed, p * 0.8, 3) - 0.5);
            Vec3::new(p.x * narrow, p.y, p.z * narrow) * bumps
        })
        .scaled_uvs(Vec2::splat(0.5))
}
