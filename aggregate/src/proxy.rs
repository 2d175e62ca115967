//! Box proxies: what stands for an object whose simplified parts no longer show its shape, or
//! that the triangle budget cannot afford. Nothing that shows is dropped.
//!
//! IAS (core paper section 6) cannot take a closed part below a tetrahedron, and at an upper
//! aggregate's budget (`budget.rs`: 16 pixels per triangle at the nearest display distance)
//! most of a building's parts reach that floor: each box becomes a shard that covers a third
//! of what it stood for, and where the budget binds and a cut shows the aggregate nearer than
//! it was built for, the shards are what the viewer sees. Dropping the smallest instances
//! instead (the detail culling this stage replaces) left holes where whole objects had been.
//!
//! So, per model drawn in the aggregate, this stage compares the surface area its simplified
//! parts keep with the area of the model's own parts ([`SHAPE_KEPT`]). A model that lost its
//! shape is drawn at every placement as its proxy instead, if a box can stand for it (its
//! surface fills the box's faces, [`BOX_FILL`]; a fence's box would be a wall): its box in
//! model space, 12 triangles, each face textured with what the model shows on that side,
//! ray-cast orthographically (an orthoview of Chaudhuri et al. 2009 with one view per face, a
//! texel per pixel at the nearest display distance, at most [`TILE`] along a side). If the aggregate is still over its budget, more such
//! objects take their proxies, smallest on screen first, while a proxy has fewer triangles
//! than what it replaces. The others keep their simplified parts, over the budget if need
//! be. A model's proxy is one submesh instanced at every placement, so its bytes are paid
//! once per aggregate; the atlas takes its texture in with the others.
//!
//! Proxies are this aggregate's only: the handoff to the parent keeps the simplified parts,
//! and the parent decides again at its own budget.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::{Arc, Mutex};

use glam::{Affine3A, Vec2, Vec3, Vec4};
use horizon_impostor::{to_srgb, PreparedMesh, SceneBuilder};
use horizon_mesh::{Instance, InstancedMesh, Material, Submesh, Texture, TextureRef, Wrap};
use rayon::prelude::*;

use crate::budget::Display;
use crate::generate::PartKey;
use crate::source::{ModelSource, SourceModel};

/// The share of a model's surface area its simplified parts must keep to be drawn as
/// themselves; below it the model's box proxy is drawn. A box reduced to a tetrahedron keeps
/// about 58% of its area, a box that lost a face 83%.
pub const SHAPE_KEPT: f64 = 0.7;

/// A side of a model (the area facing one axis direction) holding at least this share of the
/// largest side must keep [`SHAPE_KEPT`] of its area, or the model is drawn as its proxy.
pub const SIDE_SHARE: f64 = 0.2;

/// The share of a box face the model's surface facing that way must cover for the box to
/// stand for the model.
pub const BOX_FILL: f64 = 0.6;

/// Triangles of a box proxy.
pub const PROXY_TRIANGLES: u64 = 12;

/// One object of the aggregate: the model drawn and where.
#[derive(Clone, Copy, Debug)]
pub struct ObjectPlacement {
    /// The model drawn (after dedup).
    pub model: u64,
    /// Model-to-world transform.
    pub transform: Affine3A,
    /// Centre of its world bounding sphere.
    pub centre: Vec3,
    /// Radius of its world bounding sphere.
    pub radius: f32,
}

/// What [`apply`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProxyReport {
    /// Objects drawn as proxies because their simplified parts lost their shape.
    pub shape: usize,
    /// Objects drawn as proxies to fit the budget.
    pub budget: usize,
    /// The largest footprint among the latter, pixels at the nearest display distance.
    pub largest_pixels: f64,
}

/// Everything [`apply`] reads besides the mesh.
pub struct ProxyInput<'a> {
    /// For every instance of the mesh, its object (index into `objects`).
    pub instance_objects: &'a [usize],
    /// The objects.
    pub objects: &'a [ObjectPlacement],
    /// Every model part simplified, with its submesh in the mesh (`None` if IAS removed it).
    pub parts: &'a [(PartKey, Option<usize>)],
    /// The source models by number.
    pub sources: &'a BTreeMap<u64, Arc<SourceModel>>,
    /// Objects drawn as proxies that are not in the mesh at all (the merge's bound,
    /// `generate::MERGE_TRIANGLES`), whatever their shape; their models are read from
    /// `models` one at a time.
    pub forced: &'a [ObjectPlacement],
    /// Where models not in `sources` are read from.
    pub models: &'a dyn ModelSource,
    /// The triangle budget.
    pub budget: u64,
    /// Where the aggregate is shown.
    pub display: &'a Display,
}

impl std::fmt::Debug for ProxyInput<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ProxyInput")
            .field("objects", &self.objects.len())
            .field("forced", &self.forced.len())
            .field("budget", &self.budget)
            .finish_non_exhaustive()
    }
}

/// Replaces the objects that lost their shape, then as many more as the budget needs, by
/// their models' box proxies (see the module comment). The instances of every other object
/// keep their order; proxy submeshes and instances come after them.
pub fn apply(mesh: InstancedMesh, input: &ProxyInput<'_>) -> (InstancedMesh, ProxyReport) {
    let mut report = ProxyReport::default();
    // Stage 1: which models lost their shape, and which a box can stand for.
    let shapes = assess(&mesh, input);
    let boxable = |model: u64| shapes.get(&model).is_some_and(|s| s.boxable);
    // Stage 2: every object's triangles, and those of the lost shapes' proxies.
    let mut triangles = vec![0u64; input.objects.len()];
    for (inst, &o) in mesh.instances.iter().zip(input.instance_objects) {
        triangles[o] += mesh.submeshes[inst.submesh].triangle_count();
    }
    let mut proxied: Vec<bool> = input
        .objects
        .iter()
        .map(|o| shapes.get(&o.model).is_some_and(|s| s.lost && s.boxable))
        .collect();
    report.shape = proxied.iter().filter(|&&p| p).count();
    let mut total: u64 = triangles
        .iter()
        .zip(&proxied)
        .map(|(&t, &p)| if p { PROXY_TRIANGLES } else { t })
        .sum();
    // Stage 3: over budget, the smallest objects on screen take their proxies, where that
    // saves triangles.
    if total > input.budget {
        let mut candidates: Vec<(f64, usize)> = (0..input.objects.len())
            .filter(|&o| {
                !proxied[o] && triangles[o] > PROXY_TRIANGLES && boxable(input.objects[o].model)
            })
            .map(|o| {
                let ob = &input.objects[o];
                (input.display.object_pixels(ob.centre, ob.radius), o)
            })
            .collect();
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for (pixels, o) in candidates {
            if total <= input.budget {
                break;
            }
            proxied[o] = true;
            total -= triangles[o] - PROXY_TRIANGLES;
            report.budget += 1;
            report.largest_pixels = report.largest_pixels.max(pixels);
        }
    }
    report.budget += input.forced.len();
    if let Some(largest) = input
        .forced
        .iter()
        .map(|o| input.display.object_pixels(o.centre, o.radius))
        .max_by(f64::total_cmp)
    {
        report.largest_pixels = report.largest_pixels.max(largest);
    }
    if !proxied.iter().any(|&p| p) && input.forced.is_empty() {
        return (mesh, report);
    }
    // Stage 4: the mesh without the proxied objects' instances, plus one proxy submesh per
    // model and one instance per proxied object.
    let mut mesh = mesh;
    let mut k = 0;
    mesh.instances.retain(|_| {
        k += 1;
        !proxied[input.instance_objects[k - 1]]
    });
    let mut used = vec![false; mesh.submeshes.len()];
    for inst in &mesh.instances {
        used[inst.submesh] = true;
    }
    mesh.retain_submeshes(&used);
    let drawn: Vec<&ObjectPlacement> = input
        .objects
        .iter()
        .zip(&proxied)
        .filter(|(_, &p)| p)
        .map(|(o, _)| o)
        .chain(input.forced)
        .collect();
    // The proxies of the models drawn, in parallel (each ray-casts its model's faces; at an
    // upper node thousands of them), in order of first use.
    let mut models: Vec<u64> = Vec::new();
    let mut seen: HashSet<u64> = HashSet::new();
    for object in &drawn {
        if seen.insert(object.model) {
            models.push(object.model);
        }
    }
    let texel = input.display.nearest_length_of_pixels(1.0) as f32;
    let made: Vec<Option<Proxy>> = models
        .par_iter()
        .map(|&model| {
            let source = match input.sources.get(&model) {
                Some(s) => s.clone(),
                None => input.models.model(model).ok()?,
            };
            box_proxy(&source, texel)
        })
        .collect();
    let mut proxy_of: HashMap<u64, Option<usize>> = HashMap::new();
    for (model, proxy) in models.into_iter().zip(made) {
        let submesh = proxy.map(|made| {
            let (mut proxy, texture) = (*made).clone();
            mesh.textures.push(texture);
            mesh.materials.push(Material {
                name: Some("proxy".into()),
                base_color_texture: Some(TextureRef {
                    texture: mesh.textures.len() - 1,
                    transform: None,
                }),
                metallic_factor: 0.0,
                roughness_factor: 1.0,
                ..Material::default()
            });
            proxy.material = Some(mesh.materials.len() - 1);
            mesh.submeshes.push(proxy);
            mesh.submeshes.len() - 1
        });
        proxy_of.insert(model, submesh);
    }
    for object in drawn {
        if let Some(&Some(submesh)) = proxy_of.get(&object.model) {
            mesh.instances.push(Instance {
                submesh,
                transform: object.transform,
            });
        }
    }
    (mesh, report)
}

/// What stage 1 finds about one model drawn in the aggregate.
#[derive(Clone, Copy, Debug, Default)]
struct Shape {
    /// Its simplified parts lost its shape.
    lost: bool,
    /// Its box stands for it: seen along each axis, its surface fills most of the box's face.
    boxable: bool,
}

/// Every model drawn, assessed. Areas are taken in model space over every instance of every
/// part: the total, and the area facing each of the six axis directions (what a viewer from
/// that side sees of it, before occlusion). A model lost its shape when its simplified parts
/// keep under [`SHAPE_KEPT`] of the total, or of the area facing a direction that holds at
/// least [`SIDE_SHARE`] of the largest such area (a roof gone, walls turned to a shard). Its
/// box stands for it when, on every face of the box but the underside (worlds are Y-up and
/// objects stand on the ground) of at least [`SIDE_SHARE`] of the largest face's area, the
/// model's surface facing that way covers [`BOX_FILL`] of the face: a
/// building, not a fence or a bare tree, whose box would be a wall where the model is mostly
/// gaps.
fn assess(mesh: &InstancedMesh, input: &ProxyInput<'_>) -> HashMap<u64, Shape> {
    // Per model: source and kept areas, total then per direction.
    let mut areas: BTreeMap<u64, ([f64; 7], [f64; 7])> = BTreeMap::new();
    for &((model, s), k) in input.parts {
        let Some(source) = input.sources.get(&model) else {
            continue;
        };
        let Some(part) = source.mesh.submeshes.get(s as usize) else {
            continue;
        };
        let inner = source
            .placements
            .get(s as usize)
            .map_or(&[][..], Vec::as_slice);
        let entry = areas.entry(model).or_default();
        for m in inner {
            part.add_placed_areas(m, &mut entry.0);
            if let Some(k) = k {
                mesh.submeshes[k].add_placed_areas(m, &mut entry.1);
            }
        }
    }
    areas
        .into_iter()
        .filter_map(|(model, (source, kept))| {
            if source[0] <= 0.0 {
                return None;
            }
            let largest = source[1..].iter().copied().fold(0.0, f64::max);
            let side_lost = (1..7)
                .any(|d| source[d] >= SIDE_SHARE * largest && kept[d] < SHAPE_KEPT * source[d]);
            let lost = kept[0] < SHAPE_KEPT * source[0] || side_lost;
            let bounds = input.sources.get(&model)?.mesh.bounds();
            let e = (bounds.max - bounds.min).max(glam::Vec3::ZERO);
            let faces = [
                e.y * e.z,
                e.y * e.z,
                e.x * e.z,
                e.x * e.z,
                e.x * e.y,
                e.x * e.y,
            ]
            .map(f64::from);
            let biggest = faces.iter().copied().fold(0.0, f64::max);
            // The underside (-y, face 3) faces the ground: a building without a floor is
            // still a box to every viewer above it.
            let boxable = biggest > 0.0
                && (0..6).filter(|&d| d != 3).all(|d| {
                    faces[d] < SIDE_SHARE * biggest || source[d + 1] >= BOX_FILL * faces[d]
                });
            Some((model, Shape { lost, boxable }))
        })
        .collect()
}

/// A model's box proxies, by the sizes of their six tiles (what a proxy depends on besides
/// the model): the live rebuild remakes the same upper nodes over and over, and each would
/// ray-cast the same proxies again. Kept with the model ([`SourceModel`]), so the model cache
/// bounds them, at most [`PROXY_SIZES_KEPT`] sizes and [`PROXY_BYTES_KEPT`] a model.
#[derive(Debug, Default)]
pub(crate) struct ProxyMemo(Mutex<HashMap<TileSizes, Option<Proxy>>>);

/// A box proxy made: its submesh and its texture.
type Proxy = Arc<(Submesh, Texture)>;

/// The sizes of a box proxy's six tiles, in texels ((0, 0) for a face without area).
type TileSizes = [(u32, u32); 6];

/// The most tile sizes of one model whose proxies are kept: an upper node's proxies are
/// mostly of the smallest tiles, so a few sizes serve the nodes a live rebuild remakes.
pub const PROXY_SIZES_KEPT: usize = 8;

/// The most texture bytes of one model's kept proxies: small tiles (an upper node's, a few
/// hundred bytes each) are kept, large ones are made again. The model cache does not count
/// them, so this bounds what they add to it: 32 KB of textures a cached model, plus each kept
/// proxy's box mesh (about 1 KB, so about [`PROXY_SIZES_KEPT`] KB more).
pub const PROXY_BYTES_KEPT: usize = 32 << 10;

/// The model's box in model space, each face textured with what the model shows on that side,
/// ray-cast orthographically from outside the face (`horizon_impostor`), a texel about
/// `texel` wide (one pixel at the aggregate's nearest display distance: the atlas resamples
/// it to its own density), from 2 to [`TILE`] texels along a side; `None` for a model without
/// area. The six tiles share one PNG, each with a one-texel border repeating its edge. Made
/// once per model and tile sizes ([`ProxyMemo`]).
fn box_proxy(source: &SourceModel, texel: f32) -> Option<Proxy> {
    let bounds = source.mesh.bounds();
    if bounds.min.cmpgt(bounds.max).any() {
        return None;
    }
    let half = (bounds.max - bounds.min) * 0.5;
    let sizes: TileSizes = FACES.map(|(_, u, v)| {
        let (lu, lv) = ((u * half).length() * 2.0, (v * half).length() * 2.0);
        if lu <= 0.0 || lv <= 0.0 {
            (0, 0)
        } else {
            tile_size(lu, lv, texel)
        }
    });
    let memo = &source.proxies.0;
    if let Some(made) = memo.lock().ok().and_then(|m| m.get(&sizes).cloned()) {
        return made;
    }
    let made = render_box_proxy(source, &sizes).map(Arc::new);
    if let Ok(mut m) = memo.lock() {
        let bytes = |p: &Option<Proxy>| p.as_ref().map_or(0, |p| p.1.bytes.len());
        let kept: usize = m.values().map(bytes).sum();
        if m.len() < PROXY_SIZES_KEPT && kept + bytes(&made) <= PROXY_BYTES_KEPT {
            m.insert(sizes, made.clone());
        }
    }
    made
}

/// [`box_proxy`] made: each face's tile ray-cast at its size.
fn render_box_proxy(source: &SourceModel, sizes: &TileSizes) -> Option<(Submesh, Texture)> {
    let model = &source.mesh;
    let bounds = model.bounds();
    let mut scene = SceneBuilder::default();
    scene.add(&Arc::new(PreparedMesh::new(model)), &Affine3A::IDENTITY);
    let scene = scene.build();
    let centre = (bounds.min + bounds.max) * 0.5;
    let half = (bounds.max - bounds.min) * 0.5;
    let margin = half.length().max(1e-3);
    // Stage 1: each face's tile, sampled from outside along the face's inward normal.
    let mut tiles: Vec<(usize, u32, u32, Vec<Vec4>)> = Vec::new();
    for (f, &(n, u, v)) in FACES.iter().enumerate() {
        let (lu, lv) = ((u * half).length() * 2.0, (v * half).length() * 2.0);
        let (w, h) = sizes[f];
        if lu <= 0.0 || lv <= 0.0 || w == 0 || h == 0 {
            continue;
        }
        let texel = (lu / w as f32).max(lv / h as f32);
        let face = centre + n * (n.abs().dot(half) + margin);
        let mut texels: Vec<Option<Vec4>> = Vec::with_capacity((w * h) as usize);
        for j in 0..h {
            for i in 0..w {
                let su = 2.0 * (i as f32 + 0.5) / w as f32 - 1.0;
                let sv = 2.0 * (j as f32 + 0.5) / h as f32 - 1.0;
                let from = face + u * half * su + v * half * sv;
                texels.push(scene.surface(from, -n, texel).map(|s| s.albedo));
            }
        }
        tiles.push((f, w, h, fill_misses(texels)));
    }
    if tiles.is_empty() {
        return None;
    }
    // Stage 2: the tiles side by side in one image, each framed by a copy of its edge.
    let width: u32 = tiles.iter().map(|t| t.1 + 2).sum();
    let height: u32 = tiles.iter().map(|t| t.2 + 2).max().unwrap_or(1);
    let mut image = image::RgbaImage::new(width, height);
    let mut x0 = 0;
    let mut rects = [None; 6];
    for (f, w, h, texels) in &tiles {
        for y in 0..h + 2 {
            for x in 0..w + 2 {
                let (tx, ty) = (x.clamp(1, *w) - 1, y.clamp(1, *h) - 1);
                let c = texels[(ty * w + tx) as usize];
                let [r, g, b] = to_srgb(c.truncate());
                image.put_pixel(x0 + x, y, image::Rgba([r, g, b, 255]));
            }
        }
        rects[*f] = Some((x0 + 1, 1, *w, *h));
        x0 += w + 2;
    }
    let mut png = Vec::new();
    image
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .ok()?;
    let texture = Texture {
        bytes: png,
        mime_type: "image/png".into(),
        size: (width, height),
        wrap_u: Wrap::ClampToEdge,
        wrap_v: Wrap::ClampToEdge,
    };
    // Stage 3: the box, each face's corners on its tile's corners.
    let mut out = Submesh {
        normals: Some(Vec::new()),
        uvs: Some(Vec::new()),
        ..Submesh::default()
    };
    for (f, &(n, u, v)) in FACES.iter().enumerate() {
        let Some((x, y, w, h)) = rects[f] else {
            continue;
        };
        let c = centre + n * half;
        let base = out.positions.len() as u32;
        for (su, sv) in [(-1.0f32, -1.0f32), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            out.positions.push(c + u * half * su + v * half * sv);
            let tu = (x as f32 + (su + 1.0) * 0.5 * w as f32) / width as f32;
            let tv = (y as f32 + (sv + 1.0) * 0.5 * h as f32) / height as f32;
            if let (Some(ns), Some(uvs)) = (out.normals.as_mut(), out.uvs.as_mut()) {
                ns.push(n);
                uvs.push(Vec2::new(tu, tv));
            }
        }
        out.indices
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    Some((out, texture))
}

/// The six faces of a box: outward normal and two in-plane axes with u x v = normal.
const FACES: [(Vec3, Vec3, Vec3); 6] = [
    (Vec3::X, Vec3::Y, Vec3::Z),
    (Vec3::NEG_X, Vec3::Z, Vec3::Y),
    (Vec3::Y, Vec3::Z, Vec3::X),
    (Vec3::NEG_Y, Vec3::X, Vec3::Z),
    (Vec3::Z, Vec3::X, Vec3::Y),
    (Vec3::NEG_Z, Vec3::Y, Vec3::X),
];

/// The most texels along a side of a face tile.
pub const TILE: u32 = 64;

/// A face tile's texels for sides `lu` and `lv` long: one per `texel`, from 2 to [`TILE`]
/// along each side.
fn tile_size(lu: f32, lv: f32, texel: f32) -> (u32, u32) {
    let texels = |side: f32| {
        let n = (side / texel.max(f32::MIN_POSITIVE)).ceil();
        if n.is_finite() {
            (n as u32).clamp(2, TILE)
        } else {
            TILE
        }
    };
    (texels(lu), texels(lv))
}

/// A tile's texels with every miss (a gap in the model, seen through the box's face) given
/// the mean of the hits: a box face is opaque.
fn fill_misses(texels: Vec<Option<Vec4>>) -> Vec<Vec4> {
    let hits: Vec<Vec4> = texels.iter().flatten().copied().collect();
    let mean = if hits.is_empty() {
        Vec4::new(0.5, 0.5, 0.5, 1.0)
    } else {
        hits.iter().copied().sum::<Vec4>() / hits.len() as f32
    };
    texels.into_iter().map(|t| t.unwrap_or(mean)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block of `size` made of 2 m cubes of scattered colours, each its own material: its
    /// proxies' tiles compress badly.
    fn checkered(size: Vec3) -> InstancedMesh {
        let n = (size / 2.0).ceil().as_uvec3();
        let mut out = InstancedMesh::default();
        let mut k = 0u32;
        for x in 0..n.x {
            for y in 0..n.y {
                for z in 0..n.z {
                    let lo = Vec3::new(x as f32, y as f32, z as f32) * 2.0;
                    k = k.wrapping_mul(2_654_435_761).wrapping_add(12_345);
                    let c = |shift: u32| ((k >> shift) & 255) as f32 / 255.0;
                    let cube = solid(lo, lo + 2.0, Vec4::new(c(0), c(8), c(16), 1.0));
                    out.materials.push(cube.materials[0].clone());
                    out.submeshes.push(Submesh {
                        material: Some(out.materials.len() - 1),
                        ..cube.submeshes[0].clone()
                    });
                    out.instances.push(Instance {
                        submesh: out.submeshes.len() - 1,
                        transform: Affine3A::IDENTITY,
                    });
                }
            }
        }
        out
    }

    /// A closed box from `lo` to `hi`, counter-clockwise outside, in one untextured material
    /// of `color` (linear).
    fn solid(lo: Vec3, hi: Vec3, color: Vec4) -> InstancedMesh {
        let corner = |i: usize| {
            Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        };
        let indices = vec![
            0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4,
            6, 1, 3, 5, 3, 7, 5,
        ];
        InstancedMesh {
            submeshes: vec![Submesh {
                positions: (0..8).map(corner).collect(),
                indices,
                material: Some(0),
                ..Submesh::default()
            }],
            instances: vec![Instance {
                submesh: 0,
                transform: Affine3A::IDENTITY,
            }],
            materials: vec![Material {
                base_color_factor: color,
                ..Material::default()
            }],
            textures: Vec::new(),
        }
    }

    #[test]
    fn a_proxy_is_a_closed_outward_box_textured_with_what_each_side_shows() {
        // A red block with a blue slab on its top: from above the proxy shows blue, from the
        // sides red below and blue at the top.
        let mut mesh = solid(
            Vec3::ZERO,
            Vec3::new(2.0, 3.0, 1.0),
            Vec4::new(1.0, 0.0, 0.0, 1.0),
        );
        let slab = solid(
            Vec3::new(0.0, 3.0, 0.0),
            Vec3::new(2.0, 3.2, 1.0),
            Vec4::new(0.0, 0.0, 1.0, 1.0),
        );
        mesh.submeshes.push(Submesh {
            material: Some(1),
            ..slab.submeshes[0].clone()
        });
        mesh.materials.push(slab.materials[0].clone());
        mesh.instances.push(Instance {
            submesh: 1,
            transform: Affine3A::IDENTITY,
        });
        let source = SourceModel::new("block".into(), mesh, Vec::new(), Vec::new());
        let made = box_proxy(&source, 0.1).expect("a proxy");
        let (b, texture) = &*made;
        assert_eq!(b.triangle_count(), PROXY_TRIANGLES);
        let centre = Vec3::new(1.0, 1.6, 0.5);
        let normals = b.normals.as_ref().expect("normals");
        for t in b.indices.chunks_exact(3) {
            let [p, q, r] = [0, 1, 2].map(|i| b.positions[t[i] as usize]);
            let n = (q - p).cross(r - p);
            assert!(n.dot(p - centre) > 0.0, "outward");
            assert!(n.normalize().dot(normals[t[0] as usize]) > 0.999);
        }
        // Sample the texture at each face's centre and near its top edge.
        let image = image::load_from_memory(&texture.bytes)
            .expect("png")
            .to_rgba8();
        let uvs = b.uvs.as_ref().expect("uvs");
        let at = |face: usize, fu: f32, fv: f32| {
            let k = face * 4;
            let uv = uvs[k] + (uvs[k + 1] - uvs[k]) * fu + (uvs[k + 3] - uvs[k]) * fv;
            let x = ((uv.x * texture.size.0 as f32) as u32).min(texture.size.0 - 1);
            let y = ((uv.y * texture.size.1 as f32) as u32).min(texture.size.1 - 1);
            image.get_pixel(x, y).0
        };
        // Face 2 is +y: blue. Face 0 is +x (u along y): red in the middle, blue at the top.
        let top = at(2, 0.5, 0.5);
        assert!(top[2] > 200 && top[0] < 50, "{top:?}");
        let side = at(0, 0.5, 0.5);
        assert!(side[0] > 200 && side[2] < 50, "{side:?}");
        let rim = at(0, 0.99, 0.5);
        assert!(rim[2] > 200, "{rim:?}");
    }

    /// A model's proxy at given tile sizes is made once and then taken from its memo, equal
    /// to one made afresh; other sizes are other proxies, up to the memo's bound.
    #[test]
    fn a_proxy_is_made_once_per_model_and_tile_sizes() {
        let red = Vec4::new(1.0, 0.0, 0.0, 1.0);
        let source = SourceModel::new(
            "block".into(),
            solid(Vec3::ZERO, Vec3::new(2.0, 3.0, 1.0), red),
            Vec::new(),
            Vec::new(),
        );
        let first = box_proxy(&source, 0.1).expect("a proxy");
        // A texel a little wider gives the same tile sizes: the same proxy, not made again.
        let again = box_proxy(&source, 0.1001).expect("a proxy");
        assert!(Arc::ptr_eq(&first, &again));
        let sizes: TileSizes = [(30, 10); 6];
        let fresh = {
            let memo = source.proxies.0.lock().expect("memo");
            assert_eq!(memo.len(), 1);
            let kept = memo.keys().next().copied().expect("one size");
            assert_ne!(kept, sizes);
            render_box_proxy(&source, &kept).expect("a proxy")
        };
        assert_eq!(first.0, fresh.0);
        assert_eq!(first.1.bytes, fresh.1.bytes);
        // Coarser texels, other sizes: other proxies, kept up to the bound.
        let coarse = box_proxy(&source, 0.5).expect("a proxy");
        assert!(!Arc::ptr_eq(&first, &coarse));
        for k in 0..2 * PROXY_SIZES_KEPT {
            box_proxy(&source, 0.02 + 0.01 * k as f32).expect("a proxy");
        }
        let kept = source.proxies.0.lock().expect("memo").len();
        assert_eq!(kept, PROXY_SIZES_KEPT);
        // A model whose proxies are large keeps fewer of them.
        let noisy = SourceModel::new(
            "noisy".into(),
            checkered(Vec3::new(40.0, 30.0, 20.0)),
            Vec::new(),
            Vec::new(),
        );
        for k in 0..PROXY_SIZES_KEPT {
            box_proxy(&noisy, 0.3 + 0.05 * k as f32).expect("a proxy");
        }
        let memo = noisy.proxies.0.lock().expect("memo");
        let bytes: usize = memo.values().flatten().map(|p| p.1.bytes.len()).sum();
        assert!(bytes <= PROXY_BYTES_KEPT, "{bytes}");
        assert!(memo.len() < PROXY_SIZES_KEPT, "{} sizes kept", memo.len());
    }

    #[test]
    fn objects_kept_out_of_the_merge_are_drawn_as_proxies_read_from_the_models() {
        let red = Vec4::new(1.0, 0.0, 0.0, 1.0);
        let block = SourceModel::new(
            "block".into(),
            solid(Vec3::ZERO, Vec3::new(2.0, 3.0, 1.0), red),
            Vec::new(),
            Vec::new(),
        );
        let models = crate::source::InMemoryModels::new(vec![block]);
        let forced: Vec<ObjectPlacement> = [0.0f32, 10.0]
            .iter()
            .map(|&x| ObjectPlacement {
                model: 0,
                transform: Affine3A::from_translation(Vec3::new(x, 0.0, 0.0)),
                centre: Vec3::new(x + 1.0, 1.5, 0.5),
                radius: 1.9,
            })
            .collect();
        let display = Display::of(
            Vec3::ZERO,
            20.0,
            2.0,
            &crate::options::AggregateOptions::default(),
        );
        let (mesh, report) = apply(
            InstancedMesh::default(),
            &ProxyInput {
                instance_objects: &[],
                objects: &[],
                parts: &[],
                sources: &BTreeMap::new(),
                forced: &forced,
                models: &models,
                budget: 1000,
                display: &display,
            },
        );
        assert_eq!(report.budget, 2);
        assert_eq!(mesh.submeshes.len(), 1, "one proxy for the model");
        assert_eq!(mesh.instances.len(), 2, "placed at both objects");
        assert_eq!(mesh.textures.len(), 1);
        mesh.validate().expect("a valid mesh");
    }

    #[test]
    fn tiles_have_a_texel_per_pixel_within_bounds() {
        assert_eq!(tile_size(10.0, 5.0, 0.5), (20, 10));
        assert_eq!(tile_size(0.1, 1000.0, 0.5), (2, TILE));
        assert_eq!(tile_size(3.0, 3.0, 0.0), (TILE, TILE));
    }

    #[test]
    fn gaps_in_a_face_take_the_mean_of_what_it_shows() {
        let red = Vec4::new(1.0, 0.0, 0.0, 1.0);
        let blue = Vec4::new(0.0, 0.0, 1.0, 1.0);
        let filled = fill_misses(vec![Some(red), None, Some(blue)]);
        assert_eq!(filled[1], (red + blue) * 0.5);
        assert_eq!(filled[0], red);
    }
}
