mod common;
use common::*;
use glam::{Vec2, Vec4};
use horizon_atlas::{build_atlas, AtlasOptions};
use horizon_mesh::model::{AlphaMode, Wrap};
#[test]
fn timing() {
    let tex = noise(2048, 2048, 7, false);
    let input = mesh(
        vec![quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0))],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
        vec![png_texture(&tex, Wrap::Repeat)],
    );
    let t = std::time::Instant::now();
    let (_, r) = build_atlas(&input, &AtlasOptions::default()).unwrap();
    println!("noise {:?} {r:?}", t.elapsed());
    // 40 submeshes, 10 textures 256^2 smooth gradients, 4 quads each at various UVs
    let texs: Vec<_> = (0..10)
        .map(|i| {
            png_texture(
                &image::RgbaImage::from_fn(256, 256, |x, y| {
                    image::Rgba([(x as u8).wrapping_add(i * 20), y as u8, 100, 255])
                }),
                Wrap::Repeat,
            )
        })
        .collect();
    let mats: Vec<_> = (0..10)
        .map(|i| material(Vec4::ONE, Some(i), AlphaMode::Opaque))
        .collect();
    let subs: Vec<_> = (0..40)
        .map(|k| {
            let o = (k % 4) as f32 * 0.25;
            quad(box_uvs(Vec2::splat(o), Vec2::splat(o + 0.2)), Some(k / 4))
        })
        .collect();
    let input = mesh(subs, mats, texs);
    let t = std::time::Instant::now();
    let (_, r) = build_atlas(&input, &AtlasOptions::default()).unwrap();
    println!("many {:?} {r:?}", t.elapsed());
}
