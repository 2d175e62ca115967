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
//! parts keep with the area of the model's own parts. Below [`SHAPE_KEPT`], every placement
//! of the model is drawn as the model's proxy instead: its box in model space, 12 triangles,
//! each face coloured (vertex colours, linear) with the mean colour of the model's surface
//! facing that way (material factor x mean texel x mean vertex colour, weighted by area). If
//! the aggregate is still over its budget, more objects take their proxies, smallest on
//! screen first, as long as a proxy has fewer triangles than what it replaces. A model's proxy
//! is one submesh instanced at every placement, so its bytes are paid once per aggregate.
//!
//! Proxies are this aggregate's only: the handoff to the parent keeps the simplified parts,
//! and the parent decides again at its own budget.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use glam::{Affine3A, Vec3, Vec4};
use horizon_atlas::TextureCache;
use horizon_mesh::{Instance, InstancedMesh, Material, Submesh};

use crate::budget::Display;
use crate::generate::PartKey;
use crate::source::SourceModel;

/// The share of a model's surface area its simplified parts must keep to be drawn as
/// themselves; below it the model's box proxy is drawn. A box reduced to a tetrahedron keeps
/// about 58% of its area, a box that lost a face 83%.
pub const SHAPE_KEPT: f64 = 0.7;

/// A side of a model (the area facing one axis direction) holding at least this share of the
/// largest side must keep [`SHAPE_KEPT`] of its area, or the model is drawn as its proxy.
pub const SIDE_SHARE: f64 = 0.2;

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
#[derive(Debug)]
pub struct ProxyInput<'a> {
    /// For every instance of the mesh, its object (index into `objects`).
    pub instance_objects: &'a [usize],
    /// The objects.
    pub objects: &'a [ObjectPlacement],
    /// Every model part simplified, with its submesh in the mesh (`None` if IAS removed it).
    pub parts: &'a [(PartKey, Option<usize>)],
    /// The source models by number.
    pub sources: &'a BTreeMap<u64, Arc<SourceModel>>,
    /// The triangle budget.
    pub budget: u64,
    /// Where the aggregate is shown.
    pub display: &'a Display,
    /// Decoded textures, for mean colours.
    pub textures: &'a TextureCache,
}

/// Replaces the objects that lost their shape, then as many more as the budget needs, by
/// their models' box proxies (see the module comment). The instances of every other object
/// keep their order; proxy submeshes and instances come after them.
pub fn apply(mesh: InstancedMesh, input: &ProxyInput<'_>) -> (InstancedMesh, ProxyReport) {
    let mut report = ProxyReport::default();
    // Stage 1: which models lost their shape.
    let lost = shape_lost(&mesh, input);
    // Stage 2: every object's triangles, and those of the lost shapes' proxies.
    let mut triangles = vec![0u64; input.objects.len()];
    for (inst, &o) in mesh.instances.iter().zip(input.instance_objects) {
        triangles[o] += mesh.submeshes[inst.submesh].triangle_count();
    }
    let mut proxied: Vec<bool> = input
        .objects
        .iter()
        .map(|o| lost.contains_key(&o.model))
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
            .filter(|&o| !proxied[o] && triangles[o] > PROXY_TRIANGLES)
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
    if !proxied.iter().any(|&p| p) {
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
    mesh.materials.push(Material {
        name: Some("proxy".into()),
        base_color_factor: Vec4::ONE,
        metallic_factor: 0.0,
        roughness_factor: 1.0,
        ..Material::default()
    });
    let material = mesh.materials.len() - 1;
    let mut proxy_of: HashMap<u64, Option<usize>> = HashMap::new();
    for (o, object) in input.objects.iter().enumerate() {
        if !proxied[o] {
            continue;
        }
        let submesh = *proxy_of.entry(object.model).or_insert_with(|| {
            let source = input.sources.get(&object.model)?;
            let mut proxy = box_proxy(source, input.textures)?;
            proxy.material = Some(material);
            mesh.submeshes.push(proxy);
            Some(mesh.submeshes.len() - 1)
        });
        if let Some(submesh) = submesh {
            mesh.instances.push(Instance {
                submesh,
                transform: object.transform,
            });
        }
    }
    (mesh, report)
}

/// The models whose simplified parts lost their shape, with the share of area kept. Areas are
/// taken in model space over every instance of every part: the total, and the area facing
/// each of the six axis directions (what a viewer from that side sees of it, before
/// occlusion). A model lost its shape when its simplified parts keep under [`SHAPE_KEPT`] of
/// the total, or of the area facing a direction that holds at least [`SIDE_SHARE`] of the
/// largest such area (a roof gone, walls turned to a shard).
fn shape_lost(mesh: &InstancedMesh, input: &ProxyInput<'_>) -> HashMap<u64, f64> {
    // Per model: source and kept areas, total then per direction.
    let mut areas: BTreeMap<u64, ([f64; 7], [f64; 7])> = BTreeMap::new();
    for &((model, s), k) in input.parts {
        let Some(source) = input.sources.get(&model) else {
            continue;
        };
        let Some(part) = source.mesh.submeshes.get(s as usize) else {
            continue;
        };
        let inner = source.placements.get(s as usize).map_or(&[][..], Vec::as_slice);
        let entry = areas.entry(model).or_default();
        for m in inner {
            add_areas(&mut entry.0, part, m);
            if let Some(k) = k {
                add_areas(&mut entry.1, &mesh.submeshes[k], m);
            }
        }
    }
    areas
        .into_iter()
        .filter_map(|(model, (source, kept))| {
            if source[0] <= 0.0 {
                return None;
            }
            let share = kept[0] / source[0];
            let largest = source[1..].iter().copied().fold(0.0, f64::max);
            let side_lost = (1..7)
                .any(|d| source[d] >= SIDE_SHARE * largest && kept[d] < SHAPE_KEPT * source[d]);
            (share < SHAPE_KEPT || side_lost).then_some((model, share))
        })
        .collect()
}

/// Adds to `out` the area of `sub` placed by `m`: the total, then the area facing +x, -x, +y,
/// -y, +z and -z (each triangle's area times the cosine to the direction, where positive).
fn add_areas(out: &mut [f64; 7], sub: &Submesh, m: &Affine3A) {
    let flip = if m.matrix3.determinant() < 0.0 {
        -1.0
    } else {
        1.0
    };
    for t in sub.indices.chunks_exact(3) {
        let [a, b, c] = [0, 1, 2].map(|i| m.transform_point3(sub.positions[t[i] as usize]));
        let v = (b - a).cross(c - a) * (0.5 * flip);
        if !v.is_finite() {
            continue;
        }
        out[0] += f64::from(v.length());
        for (d, value) in [v.x, -v.x, v.y, -v.y, v.z, -v.z].into_iter().enumerate() {
            out[d + 1] += f64::from(value.max(0.0));
        }
    }
}

/// Surface area of a submesh in its own space.
#[cfg(test)]
fn area(sub: &Submesh) -> f64 {
    let mut out = [0.0; 7];
    add_areas(&mut out, sub, &Affine3A::IDENTITY);
    out[0]
}

/// The model's box in model space, each face coloured by the surface facing its way; `None`
/// for a model without area.
fn box_proxy(source: &SourceModel, textures: &TextureCache) -> Option<Submesh> {
    let model = &source.mesh;
    let bounds = model.bounds();
    if bounds.min.cmpgt(bounds.max).any() {
        return None;
    }
    // Per face (+x, -x, +y, -y, +z, -z): area-weighted colour of the triangles facing it.
    let mut sums = [(Vec4::ZERO, 0.0f32); 6];
    let material_colors: Vec<Vec4> = model
        .materials
        .iter()
        .map(|m| {
            let texel = m
                .base_color_texture
                .as_ref()
                .and_then(|t| model.textures.get(t.texture))
                .and_then(|t| textures.decode(t).ok())
                .map_or(Vec4::ONE, |d| {
                    // The chain's last level is the mean texel, averaged in linear light.
                    let texel = d.level(d.levels() - 1).get_pixel(0, 0).0;
                    linear(texel.map(f32::from))
                });
            m.base_color_factor * texel
        })
        .collect();
    for inst in &model.instances {
        let sub = &model.submeshes[inst.submesh];
        let color = sub
            .material
            .and_then(|m| material_colors.get(m))
            .copied()
            .unwrap_or(Vec4::ONE);
        let flip = if inst.transform.matrix3.determinant() < 0.0 {
            -1.0
        } else {
            1.0
        };
        for t in sub.indices.chunks_exact(3) {
            let [a, b, c] = [0, 1, 2].map(|i| {
                inst.transform
                    .transform_point3(sub.positions[t[i] as usize])
            });
            let n = (b - a).cross(c - a) * flip;
            let area = n.length() * 0.5;
            if area <= 0.0 || !area.is_finite() {
                continue;
            }
            let vertex = sub.colors.as_ref().map_or(Vec4::ONE, |cs| {
                (cs[t[0] as usize] + cs[t[1] as usize] + cs[t[2] as usize]) / 3.0
            });
            let face = facing(n);
            sums[face].0 += color * vertex * area;
            sums[face].1 += area;
        }
    }
    let total = sums
        .iter()
        .fold((Vec4::ZERO, 0.0), |acc, s| (acc.0 + s.0, acc.1 + s.1));
    let mean = if total.1 > 0.0 {
        total.0 / total.1
    } else {
        Vec4::ONE
    };
    let colors: [Vec4; 6] = std::array::from_fn(|f| {
        let c = if sums[f].1 > 0.0 {
            sums[f].0 / sums[f].1
        } else {
            mean
        };
        c.truncate().extend(1.0)
    });
    Some(cuboid(bounds.min, bounds.max, &colors))
}

/// Which box face a normal faces: 0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z.
fn facing(n: Vec3) -> usize {
    let a = n.abs();
    if a.x >= a.y && a.x >= a.z {
        usize::from(n.x < 0.0)
    } else if a.y >= a.z {
        2 + usize::from(n.y < 0.0)
    } else {
        4 + usize::from(n.z < 0.0)
    }
}

/// The box from `lo` to `hi`: 24 vertices (four per face, with the face's normal and colour),
/// 12 triangles, counter-clockwise seen from outside. Faces without area are left out.
fn cuboid(lo: Vec3, hi: Vec3, colors: &[Vec4; 6]) -> Submesh {
    let mut out = Submesh {
        normals: Some(Vec::new()),
        colors: Some(Vec::new()),
        ..Submesh::default()
    };
    // For each face: its normal and two in-plane axes (u x v = normal).
    let faces = [
        (Vec3::X, Vec3::Y, Vec3::Z),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::Z, Vec3::X),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::Y, Vec3::X),
    ];
    let centre = (lo + hi) * 0.5;
    let half = (hi - lo) * 0.5;
    for (f, &(n, u, v)) in faces.iter().enumerate() {
        let (du, dv) = (u * half, v * half);
        if du.length_squared() == 0.0 || dv.length_squared() == 0.0 {
            continue;
        }
        let c = centre + n * half;
        let base = out.positions.len() as u32;
        for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            out.positions.push(c + du * su + dv * sv);
        }
        if let (Some(ns), Some(cs)) = (out.normals.as_mut(), out.colors.as_mut()) {
            ns.extend([n; 4]);
            cs.extend([colors[f]; 4]);
        }
        out.indices
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    out
}

/// sRGB bytes (as floats) and linear alpha to linear RGBA.
fn linear(c: [f32; 4]) -> Vec4 {
    let l = |s: f32| {
        let s = s / 255.0;
        if s <= 0.040_45 {
            s / 12.92
        } else {
            ((s + 0.055) / 1.055).powf(2.4)
        }
    };
    Vec4::new(l(c[0]), l(c[1]), l(c[2]), c[3] / 255.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cuboid_is_closed_outward_and_coloured_per_face() {
        let colors: [Vec4; 6] = std::array::from_fn(|f| Vec4::new(f as f32 / 6.0, 0.0, 0.0, 1.0));
        let b = cuboid(Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), &colors);
        assert_eq!(b.triangle_count(), PROXY_TRIANGLES);
        assert_eq!(b.positions.len(), 24);
        let centre = Vec3::new(0.5, 1.0, 1.5);
        let normals = b.normals.as_ref().expect("normals");
        let vertex_colors = b.colors.as_ref().expect("colours");
        for t in b.indices.chunks_exact(3) {
            let [p, q, r] = [0, 1, 2].map(|i| b.positions[t[i] as usize]);
            let n = (q - p).cross(r - p);
            // Outward: the winding's normal points away from the centre and matches the
            // stored normal and the face's colour.
            assert!(n.dot(p - centre) > 0.0);
            let stored = normals[t[0] as usize];
            assert!(n.normalize().dot(stored) > 0.999);
            assert_eq!(vertex_colors[t[0] as usize], colors[facing(stored)]);
        }
        // Area: 2 (1x2 + 1x3 + 2x3) = 22.
        assert!((area(&b) - 22.0).abs() < 1e-5);
    }

    #[test]
    fn a_flat_box_leaves_out_its_empty_faces() {
        let b = cuboid(Vec3::ZERO, Vec3::new(4.0, 0.0, 4.0), &[Vec4::ONE; 6]);
        assert_eq!(b.triangle_count(), 4);
    }

    #[test]
    fn facing_picks_the_dominant_axis_and_its_sign() {
        assert_eq!(facing(Vec3::new(0.9, 0.1, -0.2)), 0);
        assert_eq!(facing(Vec3::new(-0.9, 0.1, -0.2)), 1);
        assert_eq!(facing(Vec3::new(0.1, 0.5, 0.2)), 2);
        assert_eq!(facing(Vec3::new(0.1, -0.5, 0.2)), 3);
        assert_eq!(facing(Vec3::new(0.1, 0.2, -0.5)), 5);
    }
}
