//! The maple tree of the IAS paper (Azim et al. 2014, Table 2 and figure 8): 18 submeshes,
//! 9,324 instances, about 1.82M expanded triangles, almost all of them in leaves.
//!
//! | submesh                  | triangles | instances |
//! |--------------------------|-----------|-----------|
//! | `trunk`                  | 3,136     | 1         |
//! | `limb-00` .. `limb-14`   | 1,520     | 1 each    |
//! | `leaf-sun` (five lobes)  | 196       | 4,654     |
//! | `leaf-shade` (three)     | 189       | 4,654     |
//!
//! Wood is stored once per piece and placed once; the two leaf kinds are stored once and placed
//! thousands of times around the twigs with varied rotations, non-uniform scales and, for about
//! 15% of them, a mirror.

use glam::{Mat3, Quat, Vec3, Vec4};

use crate::assembly::{double_sided, srgb, textured, trs, ModelBuilder};
use crate::rng::Rng;
use crate::shapes::{leaf_blade, tube, LeafShape, MeshBuilder};
use crate::{textures, GeneratedModel, WorldgenError};

/// Limbs growing from the trunk, each its own submesh.
const LIMBS: usize = 15;
/// Leaves of each of the two kinds: 2 × 4,654 + 16 wood pieces = 9,324 instances.
const LEAVES_PER_KIND: usize = 4_654;
/// Share of leaves placed mirrored.
const MIRRORED_LEAVES: f32 = 0.15;

/// Builds the tree; `seed` shapes the trunk and limbs and places every leaf.
pub(crate) fn generate(seed: u64) -> Result<GeneratedModel, WorldgenError> {
    let rng = Rng::new(seed);
    let mut model = ModelBuilder::new();
    let bark_texture = model.texture(textures::bark(seed)?);
    let leaf_texture = model.texture(textures::maple_leaf(seed)?);
    let bark = model.material(textured("bark", bark_texture, Vec4::ONE, 0.95));
    let sun_green = textured("leaf-sun", leaf_texture, Vec4::ONE, 0.6);
    let sun_leaf_material = model.material(double_sided(sun_green));
    let shade_green = textured("leaf-shade", leaf_texture, srgb(0.8, 0.85, 0.7), 0.6);
    let shade_leaf_material = model.material(double_sided(shade_green));

    // Trunk.
    let mut shape_rng = rng.fork(1);
    let mut place_rng = rng.fork(2);
    let trunk_path = trunk_path(&mut shape_rng);
    let trunk_radii: Vec<f32> = (0..trunk_path.len())
        .map(|k| {
            let t = k as f32 / (trunk_path.len() - 1) as f32;
            0.2 + 0.08 * (1.0 - t) + 0.2 * (-t * 10.0).exp()
        })
        .collect();
    let trunk = model.submesh("trunk", true, tube(&trunk_path, &trunk_radii, 32), bark);
    let trunk_transform = trs(
        Vec3::ZERO,
        Quat::from_rotation_y(place_rng.angle()),
        Vec3::new(1.05, 1.0, 0.95),
    );
    model.place(trunk, trunk_transform);

    // Limbs, each its own submesh placed once on the trunk; collect where leaves grow.
    let mut leaf_lines: Vec<Vec<Vec3>> = Vec::new();
    for i in 0..LIMBS {
        let height_share = (i as f32 + 0.5) / LIMBS as f32;
        let limb = limb(&mut shape_rng, height_share);
        let id = model.submesh(format!("limb-{i:02}"), true, limb.geometry, bark);
        let along = ((0.38 + 0.6 * height_share) * (trunk_path.len() - 1) as f32) as usize;
        let attach = trunk_transform.transform_point3(trunk_path[along]);
        let yaw = i as f32 * GOLDEN_ANGLE + place_rng.jitter(0.3);
        let tilt = (72.0 - 40.0 * height_share + place_rng.jitter(8.0)).to_radians();
        // Tilt +Y outward towards +X, then turn about the trunk.
        let rotation = Quat::from_rotation_y(yaw) * Quat::from_rotation_z(-tilt);
        let scale = Vec3::new(
            place_rng.range(0.9, 1.1),
            place_rng.range(0.92, 1.08),
            place_rng.range(0.9, 1.1),
        );
        let transform = trs(attach, rotation, scale);
        model.place(id, transform);
        for line in limb.leaf_lines {
            leaf_lines.push(
                line.iter()
                    .map(|&p| transform.transform_point3(p))
                    .collect(),
            );
        }
    }

    // Leaves: two kinds, alternating, so each has exactly LEAVES_PER_KIND instances.
    let sun_leaf = model.submesh(
        "leaf-sun",
        false,
        leaf_blade(&sun_leaf_shape()),
        sun_leaf_material,
    );
    let shade_leaf = model.submesh(
        "leaf-shade",
        false,
        leaf_blade(&shade_leaf_shape()),
        shade_leaf_material,
    );
    let mut leaf_rng = rng.fork(3);
    for k in 0..2 * LEAVES_PER_KIND {
        let kind = if k % 2 == 0 { sun_leaf } else { shade_leaf };
        model.place(kind, leaf_transform(&mut leaf_rng, &leaf_lines));
    }
    Ok(model.finish())
}

/// The golden angle, which spreads successive limbs evenly around the trunk.
const GOLDEN_ANGLE: f32 = 2.399_963;

/// The trunk's centre line: 49 points from just below the ground to 6 m, gently wandering.
fn trunk_path(rng: &mut Rng) -> Vec<Vec3> {
    let (phase_x, phase_z) = (rng.angle(), rng.angle());
    (0..49)
        .map(|k| {
            let t = k as f32 / 48.0;
            Vec3::new(
                0.12 * (t * 3.0 + phase_x).sin() * t,
                -0.3 + 6.3 * t,
                0.12 * (t * 2.5 + phase_z).sin() * t,
            )
        })
        .collect()
}

/// A limb's geometry and the polylines (in its own space) where leaves grow.
struct Limb {
    geometry: MeshBuilder,
    leaf_lines: Vec<Vec<Vec3>>,
}

/// A limb growing along +Y from the origin and curling back towards the vertical (−X), with
/// three twigs. Lower limbs (`height_share` near 0) are longer and thicker.
/// 992 + 3 × 176 = 1,520 triangles.
fn limb(rng: &mut Rng, height_share: f32) -> Limb {
    let length = 4.6 - 1.6 * height_share + rng.jitter(0.3);
    let base_radius = 0.15 - 0.05 * height_share;
    let curl = rng.range(0.12, 0.22);
    let (wobble_phase, wobble) = (rng.angle(), rng.range(0.03, 0.08));
    let point = |t: f32| {
        Vec3::new(
            -curl * length * t * t,
            length * t,
            wobble * length * (t * 5.0 + wobble_phase).sin() * t,
        )
    };
    let radius = |t: f32| base_radius * (1.0 - 0.8 * t);
    let ts: Vec<f32> = (0..31).map(|k| k as f32 / 30.0).collect();
    let path: Vec<Vec3> = ts.iter().map(|&t| point(t)).collect();
    let radii: Vec<f32> = ts.iter().map(|&t| radius(t)).collect();
    let mut geometry = tube(&path, &radii, 16);
    let mut leaf_lines = vec![path[16..].to_vec()];

    for (j, t) in [0.45f32, 0.65, 0.85].into_iter().enumerate() {
        let t = t + rng.jitter(0.05);
        let start = point(t);
        let tangent = (point(t + 0.01) - start).normalize();
        // Alternate sides around the limb.
        let side_angle = if j % 2 == 0 { 1.0 } else { -1.0 } * rng.range(0.9, 1.6);
        let side = Quat::from_axis_angle(tangent, side_angle) * Vec3::Z;
        let direction = (tangent * 0.6 + side).normalize();
        let twig_length = rng.range(1.0, 1.6);
        let twig: Vec<Vec3> = (0..11)
            .map(|k| {
                let s = k as f32 / 10.0;
                start + direction * twig_length * s + Vec3::new(-0.25, 0.1, 0.0) * s * s
            })
            .collect();
        let base = (0.9 * radius(t)).min(0.045);
        let twig_radii: Vec<f32> = (0..11)
            .map(|k| base * (1.0 - 0.7 * k as f32 / 10.0))
            .collect();
        geometry.append(tube(&twig, &twig_radii, 8));
        leaf_lines.push(twig[3..].to_vec());
    }
    Limb {
        geometry,
        leaf_lines,
    }
}

/// The large five-lobed sun leaf. 28 × 7 = 196 triangles.
fn sun_leaf_shape() -> LeafShape {
    LeafShape {
        lobes: vec![
            (0.0, 1.0, 38.0),
            (52.0, 0.85, 32.0),
            (-52.0, 0.85, 32.0),
            (110.0, 0.5, 30.0),
            (-110.0, 0.5, 30.0),
        ],
        palm: 0.35,
        sectors: 28,
        rings: 4,
        cup: 0.12,
        droop: 0.15,
    }
}

/// The smaller three-lobed shade leaf. 21 × 9 = 189 triangles.
fn shade_leaf_shape() -> LeafShape {
    LeafShape {
        lobes: vec![(0.0, 0.95, 45.0), (60.0, 0.7, 38.0), (-60.0, 0.7, 38.0)],
        palm: 0.4,
        sectors: 21,
        rings: 5,
        cup: 0.08,
        droop: 0.1,
    }
}

/// A leaf near a random point of a random leaf line: blade pointing outward and a little down,
/// face turned up towards the light, 15–24 cm, non-uniformly scaled, sometimes mirrored.
fn leaf_transform(rng: &mut Rng, leaf_lines: &[Vec<Vec3>]) -> glam::Affine3A {
    let line = &leaf_lines[rng.below(leaf_lines.len())];
    let k = rng.below(line.len() - 1);
    let anchor = line[k].lerp(line[k + 1], rng.unit());
    let outward = Vec3::new(anchor.x, 0.0, anchor.z).normalize_or(Vec3::X);
    let position = anchor + rng.unit_vector() * rng.range(0.03, 0.35);

    let tip = (outward * 0.6 + rng.unit_vector() * 0.6 - Vec3::Y * 0.15).normalize_or(outward);
    let facing = Vec3::Y + rng.unit_vector() * 0.5 + outward * 0.3;
    let front = (facing - tip * facing.dot(tip)).normalize_or(tip.any_orthonormal_vector());
    let rotation = Quat::from_mat3(&Mat3::from_cols(tip.cross(front), tip, front));

    let size = rng.range(0.15, 0.24);
    let mut scale = Vec3::new(
        size * rng.range(0.85, 1.15),
        size * rng.range(0.9, 1.1),
        size,
    );
    if rng.chance(MIRRORED_LEAVES) {
        scale.x = -scale.x;
    }
    trs(position, rotation, scale)
}
