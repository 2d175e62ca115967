//! MPEG-7 Color Structure Descriptor (CSD; ISO/IEC 15938-3, Manjunath et al. 2001, section
//! IV.C; Messing et al. 2001) of a whole textured model, on charted textures as the core paper
//! asks (Azim et al. 2014, section 4.1).
//!
//! MPEG-7 describes one image: the colours, quantised to HMMD cells, present in each position
//! of an 8x8 structuring element, counted over all positions. A model is not one image: it
//! has many textures and untextured colours, uses parts of its textures, and repeats wrapped
//! ones. So, following the paper's charting (Terrace et al. 2012), the descriptor here is
//! measured on what the surface shows:
//! - each textured submesh's triangles are grouped into UV islands and each island is
//!   rasterised in *unwrapped* texel space into its own chart, so unused texels never count
//!   and a UV range of 0..3 charts (and counts) three repeats;
//! - the structuring element slides over each chart's covered cells only;
//! - every chart weighs as much as the world surface it paints (every instance counted), and
//!   untextured surfaces add their colour with their area.
//!
//! Bins are MPEG-7's: extraction in 256 HMMD cells, unification into 32, and the standard's
//! non-uniform amplitude quantisation to 0..=255, so L1 distances between descriptors are on
//! the scale of the paper's Table 1 (`t_diff`). The tables are in `hmmd.rs`.
//!
//! Choices MPEG-7 does not make, each explained where it is made:
//! - colours are the 8-bit sRGB texels as stored, tinted in linear space by the material's
//!   base colour factor and vertex colours, and re-encoded to sRGB (`chart.rs`);
//! - one subsampling factor `k` serves all charts, from MPEG-7's rule applied to their
//!   summed footprints; each `k x k` block is sampled at one texel picked by a fixed hash,
//!   not its corner, so tiled textures do not alias (`chart.rs`, [`CsdOptions`]);
//! - the element is anchored on covered cells and normalised by their number, since a chart
//!   is not a rectangle (`structure.rs`);
//! - texels an alpha mask cuts out are not drawn, and an island weighs only its visible share;
//! - an untextured triangle adds base colour x mean vertex colour with its area, and so
//!   does a textured material's triangle without UVs (the texture is ignored there).

mod chart;
mod hmmd;
mod islands;
mod structure;
mod texels;

use glam::{DMat3, DVec2, DVec3, Vec4};
use horizon_mesh::{AlphaMode, InstancedMesh, Material, Submesh};

use crate::DescriptorError;
use chart::{chart_size, rasterize_island, Shading};
use islands::{place_island, uv_islands, Placement};
use structure::{structure_histogram, Chart, StructureScratch};
use texels::Texels;

pub use hmmd::{quantize_amplitude, unify_bin, Hmmd};

/// Number of CSD bins: MPEG-7's 32-cell HMMD quantisation.
pub const CSD_BINS: usize = 32;

/// Cells of the HMMD quantisation the structure is extracted in, before unification into
/// [`CSD_BINS`] (MPEG-7 extracts at 256 cells for every descriptor size).
pub const CSD_BASE_CELLS: usize = 256;

/// Options for [`color_structure`]. The defaults are MPEG-7's where it has one.
#[derive(Clone, Debug, PartialEq)]
pub struct CsdOptions {
    /// Side of the square structuring element, in chart cells (clamped to 1..=64). MPEG-7: 8.
    pub element: u32,
    /// Base-2 logarithm of the chart area MPEG-7's subsampling aims at: the factor `k`
    /// (a power of two) is `2^max(0, round(log2(area) / 2 - target_log2_area / 2))`, so a
    /// chart of `area` texels is measured on about `2^target_log2_area` cells. MPEG-7: 16
    /// (256 x 256).
    pub target_log2_area: f64,
    /// Most repeats of a texture an island counts along each axis; an island whose UVs span
    /// more is shrunk to this many (see `place_island`). Clamped to 1..=65536.
    pub max_repeats: f64,
    /// Most chart cells over the whole model; when the charts would need more (sparse
    /// islands have large bounding boxes), the subsampling factor doubles until they fit.
    pub max_cells: u64,
}

impl Default for CsdOptions {
    fn default() -> Self {
        Self {
            element: 8,
            target_log2_area: 16.0,
            max_repeats: 64.0,
            max_cells: 1 << 19,
        }
    }
}

/// Color Structure Descriptor of a model's charted textures and base colours: 32 bins on
/// MPEG-7's 8-bit amplitude scale (0..=255, returned as `f32`).
///
/// Errors: [`DescriptorError::InvalidMesh`] when the mesh breaks its invariants,
/// [`DescriptorError::Empty`] when no triangle has finite, non-zero world area, and
/// [`DescriptorError::Texture`] when a texture the surface shows cannot be decoded. A model
/// whose whole surface is cut out by alpha masks describes as all zeros.
pub fn color_structure(
    mesh: &InstancedMesh,
    options: &CsdOptions,
) -> Result<[f32; CSD_BINS], DescriptorError> {
    // Everything below indexes freely: validation guarantees every reference resolves.
    mesh.validate()?;
    // World area of every triangle, over all instances of its submesh.
    let areas = triangle_areas(mesh);
    // Areas are finite and non-negative, so the sum is a number.
    if areas.iter().flatten().sum::<f64>() <= 0.0 {
        return Err(DescriptorError::Empty);
    }
    // Untextured surfaces go straight into the histogram; textured ones become UV islands.
    let mut histogram = Histogram::default();
    let islands = collect_islands(mesh, &areas, &mut histogram);
    // Decode each texture the islands show once.
    let decoded = decode_textures(mesh, &islands)?;
    // Place each island in its own chart of unwrapped texels.
    let placed: Vec<Placement> = islands
        .iter()
        .map(|island| place_textured_island(mesh, island, &decoded, options))
        .collect();
    // One subsampling factor for all charts, as if they were packed into one atlas.
    let k = subsampling_factor(&placed, options);
    // Rasterise each chart, slide the structuring element, weigh by surface area.
    let mut chart = Chart::default();
    let mut scratch = StructureScratch::default();
    for (island, placement) in islands.iter().zip(&placed) {
        let shading = island_shading(mesh, island, &decoded);
        let visible = rasterize_island(placement, &shading, k, &mut chart);
        let element = options.element.clamp(1, 64) as usize;
        if let Some(bins) = structure_histogram(&chart, element, &mut scratch) {
            // What an alpha mask cuts out of the island is not surface anyone sees.
            histogram.add(&bins, island.area * visible);
        }
    }
    // Normalise by the visible area and quantise the amplitudes.
    Ok(histogram.quantize())
}

/// The area-weighted sum of normalised 32-bin structure histograms.
#[derive(Debug, Default)]
struct Histogram {
    /// Sum over surfaces of area x normalised bin value.
    bins: [f64; CSD_BINS],
    /// Total area added: the surface that shows a colour.
    area: f64,
}

impl Histogram {
    /// Adds a surface of `area` whose normalised histogram is `bins`.
    fn add(&mut self, bins: &[f64; CSD_BINS], area: f64) {
        for (sum, b) in self.bins.iter_mut().zip(bins) {
            *sum += area * b;
        }
        self.area += area;
    }

    /// Adds a surface of one colour: every element position on it holds that colour alone.
    fn add_color(&mut self, color: Hmmd, area: f64) {
        self.bins[unify_bin(color.bin_256())] += area;
        self.area += area;
    }

    /// Divides by the area and applies MPEG-7's amplitude quantisation.
    fn quantize(&self) -> [f32; CSD_BINS] {
        self.bins.map(|sum| {
            let value = if self.area > 0.0 {
                sum / self.area
            } else {
                0.0
            };
            f32::from(quantize_amplitude(value))
        })
    }
}

/// For each submesh, the world area of each triangle summed over the submesh's instances.
///
/// An affine map `A` takes a triangle's doubled-area vector `n = e1 x e2` to `cof(A) n`, where
/// the cofactor matrix `cof(A) = det(A) A^-T` has columns `a1 x a2, a2 x a0, a0 x a1`; this
/// holds for mirrored and singular maps too. Similarity instances (the common case) scale
/// every area alike, so they add up to one scalar per submesh; other instances cost one
/// matrix product per triangle. Areas are `f64`, so rigid motions change them by rounding
/// only. Non-finite areas count as zero.
fn triangle_areas(mesh: &InstancedMesh) -> Vec<Vec<f64>> {
    let mut similarity_scale = vec![0.0f64; mesh.submeshes.len()];
    let mut general: Vec<Vec<DMat3>> = vec![Vec::new(); mesh.submeshes.len()];
    for instance in &mesh.instances {
        let m = glam::Mat3::from(instance.transform.matrix3).as_dmat3();
        let cof = DMat3::from_cols(
            m.y_axis.cross(m.z_axis),
            m.z_axis.cross(m.x_axis),
            m.x_axis.cross(m.y_axis),
        );
        match similarity_factor(&cof) {
            Some(s) => similarity_scale[instance.submesh] += s,
            None => general[instance.submesh].push(cof),
        }
    }
    mesh.submeshes
        .iter()
        .enumerate()
        .map(|(s, sub)| {
            triangles(sub)
                .map(|[a, b, c]| {
                    let p = |i: u32| DVec3::from(sub.positions[i as usize]);
                    let n = (p(b) - p(a)).cross(p(c) - p(a));
                    let mut doubled = similarity_scale[s] * n.length();
                    for cof in &general[s] {
                        doubled += (*cof * n).length();
                    }
                    let area = 0.5 * doubled;
                    if area.is_finite() {
                        area
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect()
}

/// The area factor of a cofactor matrix that is a scaled rotation (or reflection), or `None`.
fn similarity_factor(cof: &DMat3) -> Option<f64> {
    let cols = [cof.x_axis, cof.y_axis, cof.z_axis];
    let s = cols.map(DVec3::length_squared);
    let scale = (s[0] + s[1] + s[2]) / 3.0;
    // Loose enough for f32 rotation matrices, tight enough that the area error (relative,
    // about the tolerance) is far below what moves a quantised bin.
    let tolerance = 1e-5 * scale;
    let orthogonal = cols[0].dot(cols[1]).abs() <= tolerance
        && cols[1].dot(cols[2]).abs() <= tolerance
        && cols[0].dot(cols[2]).abs() <= tolerance;
    let equal = s.iter().all(|&si| (si - scale).abs() <= tolerance);
    (orthogonal && equal && scale.is_finite()).then(|| scale.sqrt())
}

/// A submesh's triangles as index triples.
fn triangles(sub: &Submesh) -> impl Iterator<Item = [u32; 3]> + '_ {
    sub.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]])
}

/// The textured triangles of one submesh that share a UV island.
#[derive(Debug)]
struct Island {
    /// Index into the mesh's submeshes.
    submesh: usize,
    /// Index into the mesh's textures.
    texture: usize,
    /// Triangles (index triples into the submesh's vertices).
    triangles: Vec<[u32; 3]>,
    /// Linear vertex colours of each triangle's corners, when the submesh has colours.
    colors: Option<Vec<[Vec4; 3]>>,
    /// World area of the triangles, over all instances: the island's weight.
    area: f64,
}

/// Splits the visible triangles: those of textured materials (with UVs that stay finite
/// through the texture transform) into UV islands, returned; all others add their colour to
/// `histogram` directly, with their area. Triangles of zero world area are dropped.
fn collect_islands(
    mesh: &InstancedMesh,
    areas: &[Vec<f64>],
    histogram: &mut Histogram,
) -> Vec<Island> {
    let default_material = Material::default();
    let mut islands = Vec::new();
    for (s, sub) in mesh.submeshes.iter().enumerate() {
        let material = sub
            .material
            .map_or(&default_material, |m| &mesh.materials[m]);
        let corner_colors = |[a, b, c]: [u32; 3]| {
            sub.colors
                .as_ref()
                .map(|colors| [a, b, c].map(|i| colors[i as usize]))
        };
        let textured_uvs =
            material
                .base_color_texture
                .zip(sub.uvs.as_ref())
                .map(|(texture, uvs)| {
                    let mapped: Vec<glam::Vec2> = uvs
                        .iter()
                        .map(|&uv| texture.transform.map_or(uv, |t| t.apply(uv)))
                        .collect();
                    (texture.texture, mapped)
                });

        let mut textured: Vec<(usize, [u32; 3])> = Vec::new();
        for (t, tri) in triangles(sub).enumerate() {
            let area = areas[s][t];
            if area <= 0.0 {
                continue;
            }
            let charted = textured_uvs
                .as_ref()
                .is_some_and(|(_, uvs)| tri.iter().all(|&i| uvs[i as usize].is_finite()));
            if charted {
                textured.push((t, tri));
            } else if let Some(color) = untextured_color(material, corner_colors(tri)) {
                histogram.add_color(color, area);
            }
        }
        let Some((texture, uvs)) = textured_uvs else {
            continue;
        };
        let tris: Vec<[u32; 3]> = textured.iter().map(|&(_, tri)| tri).collect();
        for members in uv_islands(&uvs, &tris) {
            let triangles: Vec<[u32; 3]> = members.iter().map(|&i| tris[i]).collect();
            islands.push(Island {
                submesh: s,
                texture,
                colors: sub
                    .colors
                    .as_ref()
                    .map(|_| triangles.iter().filter_map(|&t| corner_colors(t)).collect()),
                area: members.iter().map(|&i| areas[s][textured[i].0]).sum(),
                triangles,
            });
        }
    }
    islands
}

/// The colour an untextured triangle shows: base colour factor times its mean vertex colour
/// (both linear), encoded to 8-bit sRGB; `None` when an alpha mask cuts it out.
fn untextured_color(material: &Material, corners: Option<[Vec4; 3]>) -> Option<Hmmd> {
    let tint = corners.map_or(Vec4::ONE, |[a, b, c]| (a + b + c) / 3.0);
    let color = material.base_color_factor * tint;
    if let AlphaMode::Mask { cutoff } = material.alpha_mode {
        if color.w.is_nan() || color.w < cutoff {
            return None;
        }
    }
    let rgb = [color.x, color.y, color.z].map(hmmd::linear_to_srgb8);
    Some(Hmmd::from_rgb8(rgb))
}

/// The decoded pixels of every texture an island shows, indexed like the mesh's textures.
/// Textures with identical bytes (one image under two samplers) are decoded once.
fn decode_textures(
    mesh: &InstancedMesh,
    islands: &[Island],
) -> Result<DecodedTextures, DescriptorError> {
    let mut decoded = DecodedTextures {
        slot: vec![None; mesh.textures.len()],
        texels: Vec::new(),
    };
    let mut sources: Vec<usize> = Vec::new(); // mesh texture decoded into each slot
    for island in islands {
        let t = island.texture;
        if decoded.slot[t].is_some() {
            continue;
        }
        let bytes = &mesh.textures[t].bytes;
        let same = sources
            .iter()
            .position(|&other| mesh.textures[other].bytes == *bytes);
        decoded.slot[t] = Some(match same {
            Some(slot) => slot,
            None => {
                decoded.texels.push(Texels::decode(t, &mesh.textures[t])?);
                sources.push(t);
                decoded.texels.len() - 1
            }
        });
    }
    Ok(decoded)
}

/// Decoded textures shared between the mesh textures that hold the same bytes.
#[derive(Debug)]
struct DecodedTextures {
    /// For each mesh texture, its entry in `texels` if an island shows it.
    slot: Vec<Option<usize>>,
    /// Distinct decoded images.
    texels: Vec<Texels>,
}

impl DecodedTextures {
    /// The pixels of mesh texture `texture`, which an island shows.
    fn get(&self, texture: usize) -> &Texels {
        // Every island's texture was decoded before any island is placed.
        let slot = self.slot[texture].unwrap_or(0);
        &self.texels[slot]
    }
}

/// An island's triangles in absolute texel coordinates, placed in their own chart.
fn place_textured_island(
    mesh: &InstancedMesh,
    island: &Island,
    decoded: &DecodedTextures,
    options: &CsdOptions,
) -> Placement {
    let sub = &mesh.submeshes[island.submesh];
    let material = sub.material.map(|m| &mesh.materials[m]);
    let transform = material
        .and_then(|m| m.base_color_texture)
        .and_then(|t| t.transform);
    let (w, h) = decoded.get(island.texture).size();
    let size = DVec2::new(w, h);
    let uvs = sub.uvs.as_deref().unwrap_or_default();
    let texel = |i: u32| {
        let uv = uvs.get(i as usize).copied().unwrap_or_default();
        // glTF's UV origin is the image's top-left corner, like the texel grid's.
        DVec2::from(transform.map_or(uv, |t| t.apply(uv))) * size
    };
    let triangles: Vec<[DVec2; 3]> = island.triangles.iter().map(|tri| tri.map(texel)).collect();
    place_island(&triangles, size, options.max_repeats.clamp(1.0, 65536.0))
}

/// How an island's texels are tinted and masked.
fn island_shading<'a>(
    mesh: &'a InstancedMesh,
    island: &'a Island,
    decoded: &'a DecodedTextures,
) -> Shading<'a> {
    let sub = &mesh.submeshes[island.submesh];
    let default_material = Material::default();
    let material = sub
        .material
        .map_or(&default_material, |m| &mesh.materials[m]);
    let texture = &mesh.textures[island.texture];
    Shading {
        texels: decoded.get(island.texture),
        wrap: [texture.wrap_u, texture.wrap_v],
        factor: material.base_color_factor,
        vertex_colors: island.colors.as_deref(),
        cutoff: match material.alpha_mode {
            AlphaMode::Mask { cutoff } => Some(cutoff),
            _ => None,
        },
    }
}

/// MPEG-7's subsampling factor for the charts taken together: `k = 2^p` with
/// `p = max(0, round(log2(area) / 2 - target_log2_area / 2))`, `area` the charts' summed
/// footprints in texels, so that the charts are measured on about `2^target_log2_area` cells
/// whatever the textures' resolution and repeats. One factor for all charts keeps the
/// structuring element the same size in texels everywhere, as in the paper's single charted
/// image. `k` then doubles while the charts' bounding grids exceed `max_cells`.
fn subsampling_factor(placed: &[Placement], options: &CsdOptions) -> u64 {
    let footprint: f64 = placed.iter().map(|p| p.footprint).sum();
    let target = if options.target_log2_area.is_finite() {
        options.target_log2_area
    } else {
        16.0
    };
    let mut p = if footprint > 1.0 {
        (0.5 * footprint.log2() - 0.5 * target)
            .round()
            .clamp(0.0, 62.0) as u32
    } else {
        0
    };
    // 2^52 texels per cell puts any placed chart (at most 65536 repeats of a texture of at
    // most 2^32 texels) in a handful of cells.
    while p < 52 {
        let cells: u64 = placed
            .iter()
            .map(|pl| {
                let (w, h) = chart_size(pl.extent, 1 << p);
                (w as u64).saturating_mul(h as u64)
            })
            .fold(0u64, u64::saturating_add);
        if cells <= options.max_cells {
            break;
        }
        p += 1;
    }
    1 << p.min(62)
}
