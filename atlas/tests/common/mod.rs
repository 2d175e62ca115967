//! Shared fixtures: hand-built textures, quads and triangles, seeded noise, and reading the
//! atlas back.

#![allow(dead_code)]

use glam::{Affine3A, Vec2, Vec3, Vec4};
use horizon_atlas::{build_atlas, AtlasOptions, AtlasReport};
use horizon_mesh::model::{
    AlphaMode, Instance, InstancedMesh, Material, Submesh, Texture, TextureRef, Wrap,
};
use horizon_mesh::rng::Rng;
use image::{Rgba, RgbaImage};

/// Encodes an image as a PNG texture with the given wrap modes.
pub fn png_texture(image: &RgbaImage, wrap: Wrap) -> Texture {
    let mut bytes = Vec::new();
    image
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .expect("encoding a PNG into memory cannot fail");
    Texture {
        bytes,
        mime_type: "image/png".to_string(),
        size: image.dimensions(),
        wrap_u: wrap,
        wrap_v: wrap,
    }
}

/// An image whose every texel is distinct: red = 16 x, green = 16 y (for sides up to 16).
pub fn gradient(width: u32, height: u32) -> RgbaImage {
    RgbaImage::from_fn(width, height, |x, y| {
        Rgba([(x * 16) as u8, (y * 16) as u8, 77, 255])
    })
}

/// Seeded noise from the workspace's generator, opaque unless `alpha`.
pub fn noise(width: u32, height: u32, seed: u64, alpha: bool) -> RgbaImage {
    let mut rng = Rng::new(seed);
    RgbaImage::from_fn(width, height, |_, _| {
        let b = rng.next_u64().to_le_bytes();
        Rgba([b[0], b[1], b[2], if alpha { b[3] } else { 255 }])
    })
}

/// A unit quad (two triangles sharing an edge) with the given corner UVs, in order
/// (0,0), (1,0), (1,1), (0,1) of position.
pub fn quad(uvs: [Vec2; 4], material: Option<usize>) -> Submesh {
    Submesh {
        positions: vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ],
        normals: Some(vec![Vec3::Z; 4]),
        uvs: Some(uvs.to_vec()),
        colors: None,
        indices: vec![0, 1, 2, 0, 2, 3],
        material,
    }
}

/// Corner UVs of the axis-aligned box `lo..hi`.
pub fn box_uvs(lo: Vec2, hi: Vec2) -> [Vec2; 4] {
    [
        Vec2::new(lo.x, lo.y),
        Vec2::new(hi.x, lo.y),
        Vec2::new(hi.x, hi.y),
        Vec2::new(lo.x, hi.y),
    ]
}

/// A material with a base colour factor and an optional texture.
pub fn material(factor: Vec4, texture: Option<usize>, alpha_mode: AlphaMode) -> Material {
    Material {
        name: None,
        base_color_factor: factor,
        base_color_texture: texture.map(|texture| TextureRef {
            texture,
            transform: None,
        }),
        metallic_factor: 0.0,
        roughness_factor: 1.0,
        alpha_mode,
        double_sided: false,
    }
}

/// A mesh with one identity instance per submesh.
pub fn mesh(
    submeshes: Vec<Submesh>,
    materials: Vec<Material>,
    textures: Vec<Texture>,
) -> InstancedMesh {
    let instances = (0..submeshes.len())
        .map(|submesh| Instance {
            submesh,
            transform: Affine3A::IDENTITY,
        })
        .collect();
    InstancedMesh {
        submeshes,
        instances,
        materials,
        textures,
    }
}

/// Builds the atlas with `options`, checks the output's structural promises (valid mesh, one
/// material and texture, same geometry, every UV inside the atlas) and returns it with the
/// decoded atlas.
pub fn atlased(
    input: &InstancedMesh,
    options: &AtlasOptions,
) -> (InstancedMesh, AtlasReport, RgbaImage) {
    let (out, report) = build_atlas(input, options).expect("atlas builds");
    out.validate().expect("output mesh is valid");
    assert_eq!(out.materials.len(), 1);
    assert_eq!(out.textures.len(), 1);
    assert_eq!(out.instances, input.instances);
    assert_eq!(out.submeshes.len(), input.submeshes.len());
    for (a, b) in out.submeshes.iter().zip(&input.submeshes) {
        assert_eq!(a.positions, b.positions);
        assert_eq!(a.normals, b.normals);
        assert_eq!(a.colors, b.colors);
        assert_eq!(a.indices, b.indices);
        assert_eq!(a.material, Some(0));
        let uvs = a.uvs.as_ref().expect("every submesh has UVs");
        assert!(uvs
            .iter()
            .all(|uv| (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y)));
    }
    let mat = &out.materials[0];
    assert_eq!(mat.base_color_factor, Vec4::ONE);
    assert_eq!(mat.base_color_texture.and_then(|t| t.transform), None);
    assert!(report.bytes <= options.max_bytes);
    assert_eq!(out.textures[0].bytes.len(), report.bytes);
    assert_eq!(out.textures[0].mime_type, report.mime_type);
    assert_eq!(out.textures[0].wrap_u, Wrap::ClampToEdge);
    let image = out.textures[0].decode().expect("the atlas decodes");
    assert_eq!(image.dimensions(), (report.width, report.height));
    assert_eq!(out.textures[0].size, image.dimensions());
    (out, report, image)
}

/// The atlas texel under a UV (nearest, clamped).
pub fn texel_at(image: &RgbaImage, uv: Vec2) -> Rgba<u8> {
    let x = ((uv.x * image.width() as f32).floor() as i64).clamp(0, image.width() as i64 - 1);
    let y = ((uv.y * image.height() as f32).floor() as i64).clamp(0, image.height() as i64 - 1);
    *image.get_pixel(x as u32, y as u32)
}

/// Folds an integer texel index by a wrap mode.
pub fn wrap(i: i64, n: u32, mode: Wrap) -> u32 {
    let n = n as i64;
    (match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::MirroredRepeat => {
            let m = i.rem_euclid(2 * n);
            if m >= n {
                2 * n - 1 - m
            } else {
                m
            }
        }
        Wrap::ClampToEdge => i.clamp(0, n - 1),
    }) as u32
}
