//! Levels of detail per model (issue 28; the progressive models of Terrace et al., ICME 2012,
//! and the progressive texture maps of Marvie and Bouatouch 2003, as one chain of static
//! levels): every model gets a chain of coarser versions of itself, each served as its own
//! content-addressed GLB, so a cut can send an object at the detail its pixels need.
//!
//! [`build_chain`] first re-encodes the model as stored (level 0) compactly (stage 4 below);
//! that is level 1 when it saves enough bytes. Then it runs a loop of named stages:
//! 1. **geometry**: instance-aware simplification (`horizon_simplify::simplify`; on a model
//!    whose parts are each placed once it is the plain quadric simplifier) to about
//!    [`LevelOptions::ratio`] of the previous level's triangles, never below
//!    [`LevelOptions::floor_triangles`]; a simplification that keeps more than
//!    [`LevelOptions::stall`] of its input, that drops whole parts holding more than
//!    [`DROPPED_AREA`] of its area, or that keeps under [`SIDE_KEPT`] of the area the model
//!    shows towards any side, has stalled (seams, materials or thin parts hold it), and the
//!    geometry stays as it was from then on;
//! 2. **textures**: every texture longer than [`LevelOptions::min_texture_side`] halved (a
//!    box-filtered mip level), re-encoded in its own format;
//! 3. **measure**: the symmetric Hausdorff distance to level 0 (Metro sampling,
//!    `horizon_simplify::distance`), in model units, kept monotone along the chain (a level
//!    is at least as far from the model as the one before it); the texel density (texels per
//!    model unit, over the textured surface);
//! 4. **encode**: the GLB a client downloads, the smaller of two encodings: as aggregates
//!    are written (instances in EXT_mesh_gpu_instancing, short normals, UVs and rotations,
//!    16-bit positions wherever they stay within the model's diagonal over 65,535), or
//!    quantized over each submesh's box and meshopt-compressed (16-bit positions: under a
//!    millimetre on a 20 m part); a level's error counts that quantization too. A level that
//!    saves less than [`LevelOptions::min_saving`] of the previous level's bytes is not kept.
//!
//! The chain ends when neither geometry nor textures can be reduced. Geometry and texture
//! reductions go together, one level for both: a level is one GLB.

use glam::Vec2;
use horizon_mesh::{export_glb, ExportOptions, InstancedMesh, Texture};
use horizon_simplify::distance::{hausdorff_instanced, DistanceOptions};
use horizon_simplify::{simplify, SimplifyOptions, Target};
use serde::{Deserialize, Serialize};

/// A simplification that removes whole parts holding more than this share of the model's
/// area has not simplified the model but dropped what shows: it counts as stalled.
pub const DROPPED_AREA: f64 = 0.01;

/// The share of the area the model shows towards each direction that a level must keep.
pub const SIDE_KEPT: f64 = 0.9;

/// A geometry step is taken with the texture step unless it makes the level usable only at
/// more than this multiple of the distance the texture step alone would: then the level
/// halves the textures alone, and the geometry waits.
pub const GEOMETRY_LEAD: f64 = 2.0;

/// How a chain is built. The defaults are the product's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LevelOptions {
    /// Each level's triangles as a share of the level before it.
    pub ratio: f64,
    /// No level has fewer triangles than this (unless the model has).
    pub floor_triangles: u64,
    /// A simplification that keeps more than this share of its input has stalled.
    pub stall: f64,
    /// Textures are not halved below this many texels along their longer side.
    pub min_texture_side: u32,
    /// A level must save this share of the previous level's bytes, or the chain ends.
    pub min_saving: f64,
    /// Face samples per direction of the Hausdorff distance.
    pub distance_samples: usize,
    /// The most coarser levels (besides level 0).
    pub max_levels: usize,
}

impl Default for LevelOptions {
    fn default() -> Self {
        Self {
            ratio: 0.25,
            floor_triangles: 64,
            stall: 0.75,
            min_texture_side: 16,
            min_saving: 0.1,
            distance_samples: 20_000,
            max_levels: 8,
        }
    }
}

/// One level of a chain, as stored and served.
#[derive(Clone, Debug, PartialEq)]
pub struct Level {
    /// The level's GLB.
    pub glb: Vec<u8>,
    /// What it costs and how far it is from the model.
    pub info: LevelInfo,
}

/// What a level is, without its bytes: what a cut chooses by.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LevelInfo {
    /// Symmetric Hausdorff distance to the model (level 0), model units.
    pub error: f64,
    /// Triangles drawn, instances expanded.
    pub triangles: u64,
    /// Draw calls: one per submesh.
    pub submeshes: u64,
    /// Bytes of its GLB.
    pub bytes: u64,
    /// Texels per model unit over the textured surface; `None` without textures.
    pub texel_density: Option<f64>,
}

/// A model's coarser levels (level 0 is the model itself, described by [`level_zero`]).
#[derive(Clone, Debug, Default)]
pub struct Chain {
    /// Levels 1, 2, ...: errors rise, triangles and bytes fall.
    pub levels: Vec<Level>,
    /// Why the chain stopped before it reached its floor, when something failed (the model
    /// keeps the levels made before the failure, or its full level alone).
    pub failure: Option<String>,
}

/// Level 0's figures: the model as stored, `bytes` long.
pub fn level_zero(mesh: &InstancedMesh, bytes: u64) -> LevelInfo {
    LevelInfo {
        error: 0.0,
        triangles: mesh.expanded_triangle_count(),
        submeshes: mesh.submeshes.len() as u64,
        bytes,
        texel_density: texel_density(mesh),
    }
}

/// The chain of coarser levels of `model` (see the module docs). `bytes` is the size of the
/// model's own stored GLB (level 0).
pub fn build_chain(model: &InstancedMesh, bytes: u64, options: &LevelOptions) -> Chain {
    let mut chain = Chain::default();
    let mut previous: Option<InstancedMesh> = None;
    let mut previous_info = level_zero(model, bytes);
    let mut geometry_done = previous_info.triangles <= options.floor_triangles;
    let mut textures_done = false;
    let full_sides = facing_areas(model);
    let diagonal = model.bounds().diagonal();
    let quantization = f64::from(diagonal) / 65535.0;
    let distance = DistanceOptions {
        samples: options.distance_samples,
        seed: 0,
    };
    // Stage 0: the model itself in the compact encoding, when that alone saves enough. Its
    // error is what quantization may move a vertex: half a 16-bit step along each axis of a
    // part's box, at most the model's diagonal over 65,535.
    match encode(model, diagonal) {
        Ok(glb) if glb.len() as f64 <= (1.0 - options.min_saving) * bytes as f64 => {
            let info = LevelInfo {
                error: quantization,
                bytes: glb.len() as u64,
                ..previous_info.clone()
            };
            previous_info = info.clone();
            chain.levels.push(Level { glb, info });
        }
        Ok(_) => {}
        Err(e) => {
            chain.failure = Some(format!("the model could not be re-encoded: {e}"));
            return chain;
        }
    }
    let mut last_bytes = previous_info.bytes;
    let mut pixels: Vec<Option<image::RgbaImage>> = vec![None; model.textures.len()];
    let mut masks = masks_of(model);
    let mut steps = 0;
    while chain.levels.len() < options.max_levels && steps < 4 * options.max_levels {
        steps += 1;
        let from = previous.as_ref().unwrap_or(model);
        // Stage 1: geometry, measured.
        let mut simplified = None;
        if !geometry_done {
            let triangles = from.expanded_triangle_count();
            let target =
                ((triangles as f64 * options.ratio).round() as u64).max(options.floor_triangles);
            match simplify(
                from,
                Target::Triangles(target),
                &SimplifyOptions::balanced(),
            ) {
                Ok(s)
                    if (s.report.triangles_out as f64) <= options.stall * triangles as f64
                        && dropped_area(from, &s.kept) <= DROPPED_AREA
                        && keeps_sides(&full_sides, &facing_areas(&s.mesh)) =>
                {
                    match hausdorff_instanced(model, &s.mesh, &distance) {
                        Ok(r) => simplified = Some((s.mesh, r.hausdorff.max(previous_info.error))),
                        Err(e) => {
                            chain.failure =
                                Some(format!("the level's error could not be measured: {e}"));
                            break;
                        }
                    }
                }
                Ok(_) => geometry_done = true,
                Err(e) => {
                    chain.failure = Some(format!("simplification failed: {e}"));
                    break;
                }
            }
        }
        // Stage 2: textures.
        let mut textures = from.textures.clone();
        let mut next_pixels = pixels.clone();
        let halved = if textures_done {
            false
        } else {
            match halve_textures(
                &mut textures,
                &mut next_pixels,
                &mut masks,
                options.min_texture_side,
            ) {
                Ok(halved) => halved,
                Err(e) => {
                    chain.failure = Some(format!("a texture could not be resampled: {e}"));
                    break;
                }
            }
        };
        let mut geometry_step = false;
        // Stage 3: choose. The geometry step is taken unless its error would make the level
        // usable only much farther away than the halved textures alone would.
        let density = previous_info
            .texel_density
            .map(|d| if halved { d * 0.5 } else { d });
        let footprint = |error: f64| error.max(density.map_or(0.0, |d| 1.0 / d));
        let (mut mesh, error) = match simplified {
            Some((mesh, error))
                if !halved
                    || footprint(error) <= GEOMETRY_LEAD * footprint(previous_info.error) =>
            {
                geometry_done = mesh.expanded_triangle_count() <= options.floor_triangles;
                geometry_step = true;
                (mesh, error)
            }
            _ if halved => (from.clone(), previous_info.error),
            _ => break,
        };
        // What quantization may add (see `encode`), once: the first level carries it.
        let error = error.max(quantization);
        if halved {
            mesh.textures = textures;
        }
        // Stage 4: encode.
        let glb = match encode(&mesh, diagonal) {
            Ok(glb) => glb,
            Err(e) => {
                chain.failure = Some(format!("the level could not be written: {e}"));
                break;
            }
        };
        let info = LevelInfo {
            error,
            triangles: mesh.expanded_triangle_count(),
            submeshes: mesh.submeshes.len() as u64,
            bytes: glb.len() as u64,
            texel_density: texel_density(&mesh),
        };
        if glb.len() as f64 > (1.0 - options.min_saving) * last_bytes as f64 {
            if geometry_step {
                // Not worth a level of its own: the next step goes on from it.
                previous_info = info;
                previous = Some(mesh);
                if halved {
                    pixels = next_pixels;
                }
                continue;
            }
            // Halving the textures no longer pays: the geometry goes on alone.
            textures_done = true;
            continue;
        }
        last_bytes = glb.len() as u64;
        if halved {
            pixels = next_pixels;
        }
        previous_info = info.clone();
        chain.levels.push(Level { glb, info });
        previous = Some(mesh);
    }
    chain
}

/// A level's GLB: the smaller of the two encodings (see the module docs). Either moves a
/// position by at most the model's `diagonal` over 65,535: 16-bit positions over a part's box
/// (half a step per axis), or positions kept within that tolerance.
fn encode(mesh: &InstancedMesh, diagonal: f32) -> Result<Vec<u8>, horizon_mesh::ExportError> {
    let c = export_glb(mesh, &ExportOptions::compressed())?;
    // The instanced encoding can only win where parts are placed more than once.
    if mesh.instances.len() <= mesh.submeshes.len() {
        return Ok(c);
    }
    let a = export_glb(mesh, &ExportOptions::aggregate(diagonal / 65535.0))?;
    Ok(if c.len() < a.len() { c } else { a })
}

/// The area of `mesh`, every instance counted, per submesh: the total, then the area facing
/// +x, -x, +y, -y, +z and -z ([`horizon_mesh::Submesh::add_placed_areas`]).
fn placed_areas(mesh: &InstancedMesh) -> Vec<[f64; 7]> {
    let mut out = vec![[0.0f64; 7]; mesh.submeshes.len()];
    for inst in &mesh.instances {
        mesh.submeshes[inst.submesh].add_placed_areas(&inst.transform, &mut out[inst.submesh]);
    }
    out
}

/// The area `mesh` shows towards +x, -x, +y, -y, +z and -z.
fn facing_areas(mesh: &InstancedMesh) -> [f64; 6] {
    let mut out = [0.0f64; 6];
    for areas in placed_areas(mesh) {
        for (o, a) in out.iter_mut().zip(&areas[1..]) {
            *o += a;
        }
    }
    out
}

/// Whether a level showing `sides` keeps [`SIDE_KEPT`] of what the model (`full`) shows
/// towards every direction that holds a fair share of the model's largest side: thin parts
/// (a fence's rails, a tree's twigs) that simplification would thin away are within a small
/// Hausdorff distance of what remains, but their pixels would open holes.
fn keeps_sides(full: &[f64; 6], sides: &[f64; 6]) -> bool {
    let largest = full.iter().copied().fold(0.0, f64::max);
    full.iter()
        .zip(sides)
        .all(|(&f, &s)| f < 0.2 * largest || s >= SIDE_KEPT * f)
}

/// The share of `mesh`'s surface area in the submeshes that `kept` says lost all their
/// triangles.
fn dropped_area(mesh: &InstancedMesh, kept: &[Option<usize>]) -> f64 {
    let areas: Vec<f64> = placed_areas(mesh).iter().map(|a| a[0]).collect();
    let total: f64 = areas.iter().sum();
    let dropped: f64 = areas
        .iter()
        .zip(kept)
        .filter(|(_, k)| k.is_none())
        .map(|(a, _)| a)
        .sum();
    if total > 0.0 {
        dropped / total
    } else {
        0.0
    }
}

/// Halves every texture longer than `min_side` ([`half_box`], same encoding). Returns whether
/// any was.
/// `pixels` holds each texture's decoded texels when known (they are kept for the next
/// halving, so that no level decodes what the one before it encoded).
/// A texture an alpha-masked material uses keeps its coverage: the share of texels at or
/// above `masks[t]`'s cut-off is level 0's at every level (alpha scaled after the box filter,
/// as in Castaño's "alpha to coverage" mipmaps), so a fence's pickets do not thin away.
fn halve_textures(
    textures: &mut [Texture],
    pixels: &mut [Option<image::RgbaImage>],
    masks: &mut [Option<Mask>],
    min_side: u32,
) -> Result<bool, image::ImageError> {
    let mut any = false;
    for ((texture, decoded), mask) in textures.iter_mut().zip(pixels).zip(masks) {
        let (w, h) = texture.size;
        if w.max(h) <= min_side {
            continue;
        }
        if let Some(mask) = mask.as_mut().filter(|m| m.coverage.is_none()) {
            let image = match decoded.take() {
                Some(image) => image,
                None => texture.decode()?,
            };
            mask.coverage = Some(coverage(&image, mask.cutoff, 1.0));
            *decoded = Some(image);
        }
        *texture = halved(texture, decoded, mask.as_ref())?;
        any = true;
    }
    Ok(any)
}

/// An alpha-masked texture's cut-off and level 0's coverage at it.
#[derive(Clone, Copy, Debug)]
struct Mask {
    cutoff: f32,
    coverage: Option<f64>,
}

/// The masks of `mesh`'s textures: the cut-off of the first alpha-masked material using each.
fn masks_of(mesh: &InstancedMesh) -> Vec<Option<Mask>> {
    let mut out = vec![None; mesh.textures.len()];
    for m in &mesh.materials {
        if let (horizon_mesh::AlphaMode::Mask { cutoff }, Some(t)) =
            (m.alpha_mode, m.base_color_texture)
        {
            if let Some(slot) = out.get_mut(t.texture) {
                slot.get_or_insert(Mask {
                    cutoff,
                    coverage: None,
                });
            }
        }
    }
    out
}

/// The share of `image`'s texels whose alpha, times `scale`, is at least `cutoff`.
fn coverage(image: &image::RgbaImage, cutoff: f32, scale: f32) -> f64 {
    let bar = cutoff * 255.0;
    let above = image
        .pixels()
        .filter(|p| f32::from(p.0[3]) * scale >= bar)
        .count();
    above as f64 / (image.width() as f64 * image.height() as f64).max(1.0)
}

/// Scales `image`'s alpha so that its coverage at `mask.cutoff` is `mask.coverage`.
fn keep_coverage(image: &mut image::RgbaImage, mask: &Mask) {
    let Some(target) = mask.coverage else {
        return;
    };
    // Coverage rises with the scale: bisect for the scale that meets the target.
    let (mut lo, mut hi) = (0.25f32, 4.0f32);
    for _ in 0..16 {
        let mid = 0.5 * (lo + hi);
        if coverage(image, mask.cutoff, mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    for p in image.pixels_mut() {
        p.0[3] = (f32::from(p.0[3]) * hi).round().min(255.0) as u8;
    }
}

/// A texture at half its size along both sides (at least one texel); `decoded` holds its
/// texels, if known, and then the halved ones.
fn halved(
    texture: &Texture,
    decoded: &mut Option<image::RgbaImage>,
    mask: Option<&Mask>,
) -> Result<Texture, image::ImageError> {
    let image = match decoded.take() {
        Some(image) => image,
        None => texture.decode()?,
    };
    let mut small = half_box(&image);
    if let Some(mask) = mask {
        keep_coverage(&mut small, mask);
    }
    let (w, h) = small.dimensions();
    *decoded = Some(small.clone());
    let mut bytes = Vec::new();
    let mut out = std::io::Cursor::new(&mut bytes);
    if texture.mime_type == "image/jpeg" {
        let rgb = image::DynamicImage::ImageRgba8(small).to_rgb8();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 85).encode_image(&rgb)?;
    } else {
        small.write_to(&mut out, image::ImageFormat::Png)?;
    }
    Ok(Texture {
        bytes,
        mime_type: texture.mime_type.clone(),
        size: (w, h),
        wrap_u: texture.wrap_u,
        wrap_v: texture.wrap_v,
    })
}

/// A mip level: each texel the mean of the 2x2 block above it (a side of odd length folds
/// its last row or column into the block before it; a side of 1 stays 1).
fn half_box(image: &image::RgbaImage) -> image::RgbaImage {
    let (w, h) = image.dimensions();
    let (hw, hh) = ((w / 2).max(1), (h / 2).max(1));
    image::RgbaImage::from_fn(hw, hh, |x, y| {
        let xs = [2 * x, (2 * x + 1).min(w - 1)];
        let ys = [2 * y, (2 * y + 1).min(h - 1)];
        let mut sum = [0u32; 4];
        for &sy in &ys {
            for &sx in &xs {
                let p = image.get_pixel(sx, sy).0;
                for c in 0..4 {
                    sum[c] += u32::from(p[c]);
                }
            }
        }
        image::Rgba(sum.map(|v| ((v + 2) / 4) as u8))
    })
}

/// Texels per model unit over the textured surface: the square root of the texels its
/// triangles cover (UV area, after any texture transform, times the texture's size) over
/// their area in model space; `None` when nothing textured has area.
pub fn texel_density(mesh: &InstancedMesh) -> Option<f64> {
    let (mut texels, mut area) = (0.0f64, 0.0f64);
    for inst in &mesh.instances {
        let sub = &mesh.submeshes[inst.submesh];
        let Some(material) = sub.material.and_then(|m| mesh.materials.get(m)) else {
            continue;
        };
        let Some(tref) = material.base_color_texture else {
            continue;
        };
        let (Some(texture), Some(uvs)) = (mesh.textures.get(tref.texture), sub.uvs.as_ref()) else {
            continue;
        };
        let uv_scale = tref
            .transform
            .map_or(1.0, |t| f64::from((t.scale.x * t.scale.y).abs()));
        let size = f64::from(texture.size.0) * f64::from(texture.size.1);
        for t in sub.indices.chunks_exact(3) {
            let [a, b, c] = [0, 1, 2].map(|i| t[i] as usize);
            let [pa, pb, pc] = [a, b, c].map(|i| inst.transform.transform_point3(sub.positions[i]));
            let [ua, ub, uc]: [Vec2; 3] = [a, b, c].map(|i| uvs[i]);
            let a3 = f64::from((pb - pa).cross(pc - pa).length()) * 0.5;
            let a2 = f64::from((ub - ua).perp_dot(uc - ua).abs()) * 0.5;
            if a3.is_finite() && a2.is_finite() {
                area += a3;
                texels += a2 * uv_scale * size;
            }
        }
    }
    (area > 0.0 && texels > 0.0).then(|| (texels / area).sqrt())
}
