//! Small procedural textures for the benchmark models of the IAS paper (Azim et al. 2014,
//! Table 2): bark, maple leaf, stone, wood, roof tiles, plaster, grass and cobbles, each a
//! 64×64 or 128×128 PNG built from seeded value noise. Repeating textures tile seamlessly.

use std::f32::consts::TAU;

use glam::{Vec2, Vec3};
use horizon_mesh::{Texture, Wrap};
use image::codecs::png::PngEncoder;
use image::{Rgb, RgbImage};

use crate::noise::{cell_hash, tileable_fbm, tileable_fbm_aniso};
use crate::WorldgenError;

/// Bark: dark vertical furrows between lighter ridges. 128×128, repeating.
pub fn bark(seed: u64) -> Result<Texture, WorldgenError> {
    let image = paint(128, |u, v| {
        let ridges = tileable_fbm_aniso(seed, u, v, (8, 1), 4);
        let fine = tileable_fbm(seed ^ 0xB, u, v, 16, 2);
        let dark = Vec3::new(0.17, 0.12, 0.09);
        let light = Vec3::new(0.46, 0.39, 0.31);
        dark.lerp(light, smoothstep(0.35, 0.7, ridges)) * (0.8 + 0.4 * fine)
    });
    encode(&image, Wrap::Repeat)
}

/// A maple leaf: green with lighter veins radiating from the petiole at the centre towards the
/// five lobes (matching [`crate::shapes::leaf_blade`]'s UV layout). 128×128, clamped.
pub fn maple_leaf(seed: u64) -> Result<Texture, WorldgenError> {
    let veins: Vec<Vec2> = [0.0f32, 50.0, -50.0, 100.0, -100.0]
        .iter()
        .map(|deg| {
            // The tip axis (+Y of the blade) is -v in the image.
            let a = deg.to_radians();
            Vec2::new(a.sin(), -a.cos())
        })
        .collect();
    let image = paint(128, |u, v| {
        let p = Vec2::new(u, v) - Vec2::splat(0.5);
        let mottle = tileable_fbm(seed, u, v, 6, 4);
        let mut colour = Vec3::new(0.20, 0.42, 0.09).lerp(Vec3::new(0.35, 0.55, 0.14), mottle);
        for d in &veins {
            let along = p.dot(*d);
            if along > 0.0 {
                let across = p.perp_dot(*d).abs();
                let width = 0.012 * (1.0 - along).max(0.2);
                if across < width {
                    colour = colour.lerp(Vec3::new(0.62, 0.70, 0.34), 0.7);
                }
            }
        }
        colour
    });
    encode(&image, Wrap::ClampToEdge)
}

/// Weathered stone: grey mottling with yellow-green lichen patches. 128×128, repeating.
pub fn stone(seed: u64) -> Result<Texture, WorldgenError> {
    let image = paint(128, |u, v| {
        let body = tileable_fbm(seed, u, v, 4, 5);
        let lichen = tileable_fbm(seed ^ 0x11C, u, v, 6, 3);
        let grit = tileable_fbm(seed ^ 0x6, u, v, 32, 1);
        let grey = Vec3::splat(0.38 + 0.35 * body) * (0.9 + 0.2 * grit);
        grey.lerp(
            Vec3::new(0.55, 0.56, 0.30),
            smoothstep(0.6, 0.7, lichen) * 0.45,
        )
    });
    encode(&image, Wrap::Repeat)
}

/// Wood: grain lines along v with a little waviness. 128×128, repeating.
pub fn wood(seed: u64) -> Result<Texture, WorldgenError> {
    let image = paint(128, |u, v| {
        let warp = tileable_fbm_aniso(seed, u, v, (3, 1), 3);
        let grain = 0.5 + 0.5 * ((u * 10.0 + warp * 3.0) * TAU).sin();
        let fine = tileable_fbm_aniso(seed ^ 0x3, u, v, (32, 2), 2);
        Vec3::new(0.42, 0.27, 0.15).lerp(Vec3::new(0.62, 0.45, 0.28), grain * 0.7 + fine * 0.3)
    });
    encode(&image, Wrap::Repeat)
}

/// Clay roof tiles: 8 staggered rows of 8, each tile its own shade, shadowed at its lower edge.
/// 128×128, repeating.
pub fn roof_tiles(seed: u64) -> Result<Texture, WorldgenError> {
    let image = paint(128, |u, v| {
        let rows = 8.0;
        let row = (v * rows).floor();
        let shift = if row as i64 % 2 == 0 { 0.0 } else { 0.5 };
        let column = (u * rows + shift).floor();
        let (fu, fv) = ((u * rows + shift).fract(), (v * rows).fract());
        let shade = 0.85 + 0.3 * cell_hash(seed, column as i64 % 8, row as i64);
        let edge =
            smoothstep(0.75, 1.0, fv) * 0.5 + smoothstep(0.9, 1.0, (2.0 * fu - 1.0).abs()) * 0.3;
        let grain = tileable_fbm(seed ^ 0x7, u, v, 16, 2);
        Vec3::new(0.60, 0.27, 0.17) * shade * (1.0 - edge) * (0.9 + 0.2 * grain)
    });
    encode(&image, Wrap::Repeat)
}

/// Lime plaster: warm off-white with faint blotches. 64×64, repeating.
pub fn plaster(seed: u64) -> Result<Texture, WorldgenError> {
    let image = paint(64, |u, v| {
        let n = tileable_fbm(seed, u, v, 4, 4);
        Vec3::new(0.86, 0.81, 0.70) * (0.88 + 0.16 * n)
    });
    encode(&image, Wrap::Repeat)
}

/// Grass seen from above: mottled greens with a few dry patches. 128×128, repeating.
pub fn grass(seed: u64) -> Result<Texture, WorldgenError> {
    let image = paint(128, |u, v| {
        let patches = tileable_fbm(seed, u, v, 4, 3);
        let blades = tileable_fbm(seed ^ 0x9, u, v, 64, 1);
        let green = Vec3::new(0.20, 0.40, 0.11).lerp(Vec3::new(0.42, 0.50, 0.20), patches);
        green * (0.75 + 0.5 * blades)
    });
    encode(&image, Wrap::Repeat)
}

/// Cobblestones: an 8×8 cellular pattern of rounded grey-brown stones in dark mortar.
/// 128×128, repeating.
pub fn cobbles(seed: u64) -> Result<Texture, WorldgenError> {
    let cells = 8i64;
    let feature = |cx: i64, cy: i64| {
        let (wx, wy) = (cx.rem_euclid(cells), cy.rem_euclid(cells));
        Vec2::new(
            cx as f32 + 0.2 + 0.6 * cell_hash(seed, wx, wy),
            cy as f32 + 0.2 + 0.6 * cell_hash(seed ^ 0x5, wx, wy),
        )
    };
    let image = paint(128, |u, v| {
        let p = Vec2::new(u, v) * cells as f32;
        let (cx, cy) = (p.x.floor() as i64, p.y.floor() as i64);
        let (mut f1, mut f2, mut owner) = (f32::MAX, f32::MAX, (0, 0));
        for dy in -1..=1 {
            for dx in -1..=1 {
                let d = p.distance(feature(cx + dx, cy + dy));
                if d < f1 {
                    (f2, f1, owner) = (f1, d, (cx + dx, cy + dy));
                } else if d < f2 {
                    f2 = d;
                }
            }
        }
        let tone = cell_hash(
            seed ^ 0xC0,
            owner.0.rem_euclid(cells),
            owner.1.rem_euclid(cells),
        );
        let stone = Vec3::new(0.45, 0.42, 0.38).lerp(Vec3::new(0.62, 0.56, 0.48), tone);
        let mortar = Vec3::new(0.22, 0.20, 0.17);
        mortar.lerp(stone * (1.0 - 0.25 * f1), smoothstep(0.05, 0.18, f2 - f1))
    });
    encode(&image, Wrap::Repeat)
}

/// A square image of `size` pixels, each the sRGB colour `f(u, v)` at its centre.
pub(crate) fn paint(size: u32, f: impl Fn(f32, f32) -> Vec3) -> RgbImage {
    RgbImage::from_fn(size, size, |x, y| {
        let c = f(
            (x as f32 + 0.5) / size as f32,
            (y as f32 + 0.5) / size as f32,
        );
        Rgb(c
            .to_array()
            .map(|k| (k.clamp(0.0, 1.0) * 255.0).round() as u8))
    })
}

/// PNG-encodes `image` into a texture with the same wrap mode on both axes.
pub(crate) fn encode(image: &RgbImage, wrap: Wrap) -> Result<Texture, WorldgenError> {
    let mut bytes = Vec::new();
    image.write_with_encoder(PngEncoder::new(&mut bytes))?;
    Ok(Texture {
        bytes,
        mime_type: "image/png".to_owned(),
        size: image.dimensions(),
        wrap_u: wrap,
        wrap_v: wrap,
    })
}

fn smoothstep(lo: f32, hi: f32, x: f32) -> f32 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_texture_decodes_at_its_declared_size() -> Result<(), WorldgenError> {
        let all = [
            bark(1)?,
            maple_leaf(1)?,
            stone(1)?,
            wood(1)?,
            roof_tiles(1)?,
            plaster(1)?,
            grass(1)?,
            cobbles(1)?,
        ];
        for t in &all {
            let decoded = t.decode()?;
            assert_eq!(decoded.dimensions(), t.size);
            assert!(t.bytes.len() < 80_000, "{} bytes", t.bytes.len());
        }
        Ok(())
    }
}
