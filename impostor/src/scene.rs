//! The ray caster: a two-level BVH over placed meshes (obvhs compressed wide BVHs), closest
//! hits with glTF's face culling and alpha masks, and shading.
//!
//! Each submesh of a [`PreparedMesh`] gets its own BVH over its triangles, built once and
//! shared by every placement. A [`Scene`] places meshes: each (placement x mesh instance)
//! becomes an item with its world box, and one BVH over the items finds which submeshes a ray
//! may hit. The ray is taken into the submesh's space by the item's inverse transform without
//! renormalising its direction, so the distance along it is the same in both spaces.

use std::sync::Arc;
use std::time::Duration;

use glam::{Vec2, Vec3, Vec4};
use glam34::{Affine3A as Affine34, Vec3A as V};
use horizon_mesh::{InstancedMesh, Submesh};
use obvhs::aabb::Aabb as BoxA;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use rayon::prelude::*;

use crate::camera::Camera;
use crate::frame::Frame;
use crate::shade::{light, to_srgb, MipChain, Shading, SKY};

/// A mesh ready to be placed in scenes: a BVH per submesh, materials with decoded textures.
#[derive(Debug)]
pub struct PreparedMesh {
    submeshes: Vec<Option<Blas>>,
    /// The mesh's own instances: submesh and model transform.
    instances: Vec<(usize, Affine34)>,
    /// Expanded triangles (one placement).
    triangles: u64,
}

/// One submesh's triangles in BVH order, with what shading reads.
struct Blas {
    bvh: CwBvh,
    tris: Vec<Tri>,
    submesh: Submesh,
    shading: Shading,
}

impl std::fmt::Debug for Blas {
    /// A summary (obvhs's BVH has no `Debug`).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Blas")
            .field("triangles", &self.tris.len())
            .finish()
    }
}

/// A triangle as the intersection test wants it: a corner and two edges.
#[derive(Clone, Copy, Debug)]
struct Tri {
    v0: V,
    e1: V,
    e2: V,
    /// Its index in the submesh's triangle list.
    index: u32,
}

impl PreparedMesh {
    /// Builds every submesh's BVH (in parallel) and decodes every texture. A texture that
    /// cannot be decoded leaves its material drawing with its factor alone.
    pub fn new(mesh: &InstancedMesh) -> Self {
        let textures: Vec<Option<Arc<MipChain>>> = mesh
            .textures
            .par_iter()
            .map(|t| MipChain::of(t).map(Arc::new))
            .collect();
        let submeshes = mesh
            .submeshes
            .par_iter()
            .map(|sub| {
                let shading = match sub.material.and_then(|m| mesh.materials.get(m)) {
                    Some(m) => Shading::of(m, &textures),
                    None => Shading::default_material(),
                };
                Blas::new(sub, shading)
            })
            .collect();
        let instances = mesh
            .instances
            .iter()
            .map(|i| (i.submesh, affine34(&i.transform)))
            .collect();
        Self {
            submeshes,
            instances,
            triangles: mesh.expanded_triangle_count(),
        }
    }

    /// Expanded triangles of one placement.
    pub fn triangles(&self) -> u64 {
        self.triangles
    }
}

impl Blas {
    fn new(sub: &Submesh, shading: Shading) -> Option<Self> {
        let p = |i: u32| {
            let v = sub.positions[i as usize];
            V::new(v.x, v.y, v.z)
        };
        let corners: Vec<[V; 3]> = sub
            .indices
            .chunks_exact(3)
            .map(|t| [p(t[0]), p(t[1]), p(t[2])])
            .collect();
        if corners.is_empty() {
            return None;
        }
        let prims: Vec<Triangle> = corners
            .iter()
            .map(|c| Triangle {
                v0: c[0],
                v1: c[1],
                v2: c[2],
            })
            .collect();
        let bvh = build_cwbvh(
            &prims,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        let tris = bvh
            .primitive_indices
            .iter()
            .map(|&i| {
                let c = corners[i as usize];
                Tri {
                    v0: c[0],
                    e1: c[1] - c[0],
                    e2: c[2] - c[0],
                    index: i,
                }
            })
            .collect();
        Some(Self {
            bvh,
            tris,
            submesh: sub.clone(),
            shading,
        })
    }

    /// The three vertex indices of triangle `t`.
    fn corners(&self, t: u32) -> [usize; 3] {
        let i = &self.submesh.indices[t as usize * 3..t as usize * 3 + 3];
        [i[0] as usize, i[1] as usize, i[2] as usize]
    }

    /// Texture coordinates at barycentrics (u, v) of triangle `t`, if the submesh has them.
    fn uv(&self, t: u32, u: f32, v: f32) -> Option<Vec2> {
        let uvs = self.submesh.uvs.as_ref()?;
        let [a, b, c] = self.corners(t);
        Some(uvs[a] * (1.0 - u - v) + uvs[b] * u + uvs[c] * v)
    }
}

/// Places prepared meshes; [`SceneBuilder::build`] makes the scene.
#[derive(Debug, Default)]
pub struct SceneBuilder {
    meshes: Vec<Arc<PreparedMesh>>,
    items: Vec<Item>,
    placements: u32,
}

/// One placed submesh.
#[derive(Clone, Copy, Debug)]
struct Item {
    /// Which placement (in the order of `add` calls) it belongs to.
    placement: u32,
    mesh: u32,
    submesh: u32,
    to_world: Affine34,
    to_local: Affine34,
    /// A negative determinant: the winding flips.
    mirrored: bool,
}

impl SceneBuilder {
    /// Places `mesh` with the model-to-world `placement`. Instances whose transform cannot be
    /// inverted (they draw nothing) are left out.
    pub fn add(&mut self, mesh: &Arc<PreparedMesh>, placement: &glam::Affine3A) {
        let index = match self.meshes.iter().position(|m| Arc::ptr_eq(m, mesh)) {
            Some(i) => i,
            None => {
                self.meshes.push(mesh.clone());
                self.meshes.len() - 1
            }
        };
        self.add_at(index, mesh, placement);
    }

    /// [`SceneBuilder::add`] for a mesh known by the caller's own number `index` among the
    /// meshes added with [`SceneBuilder::register`] (no search).
    pub fn add_registered(&mut self, index: usize, placement: &glam::Affine3A) {
        let mesh = self.meshes[index].clone();
        self.add_at(index, &mesh, placement);
    }

    /// Registers `mesh` and returns its number for [`SceneBuilder::add_registered`].
    pub fn register(&mut self, mesh: Arc<PreparedMesh>) -> usize {
        self.meshes.push(mesh);
        self.meshes.len() - 1
    }

    fn add_at(&mut self, index: usize, mesh: &PreparedMesh, placement: &glam::Affine3A) {
        let number = self.placements;
        self.placements += 1;
        let placement = affine34(placement);
        for &(submesh, model) in &mesh.instances {
            if mesh.submeshes[submesh].is_none() {
                continue;
            }
            let to_world = placement * model;
            let det = to_world.matrix3.determinant();
            if !det.is_finite() || det.abs() < 1e-18 {
                continue;
            }
            self.items.push(Item {
                placement: number,
                mesh: index as u32,
                submesh: submesh as u32,
                to_world,
                to_local: to_world.inverse(),
                mirrored: det < 0.0,
            });
        }
    }

    /// Builds the BVH over every placed submesh.
    pub fn build(self) -> Scene {
        let boxes: Vec<BoxA> = self
            .items
            .par_iter()
            .map(|item| {
                let blas = self.meshes[item.mesh as usize].submeshes[item.submesh as usize]
                    .as_ref()
                    .expect("items only name submeshes with triangles");
                world_box(&blas.bvh.total_aabb, &item.to_world)
            })
            .collect();
        let tlas = (!boxes.is_empty()).then(|| {
            build_cwbvh(
                &boxes,
                BvhBuildParams::fast_build(),
                &mut Duration::default(),
            )
        });
        Scene {
            meshes: self.meshes,
            items: self.items,
            tlas,
        }
    }
}

/// Placed meshes under one BVH, ready to render.
pub struct Scene {
    meshes: Vec<Arc<PreparedMesh>>,
    items: Vec<Item>,
    tlas: Option<CwBvh>,
}

impl std::fmt::Debug for Scene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scene")
            .field("meshes", &self.meshes.len())
            .field("items", &self.items.len())
            .finish()
    }
}

/// The closest hit of a ray.
#[derive(Clone, Copy, Debug)]
struct Hit {
    item: u32,
    triangle: u32,
    u: f32,
    v: f32,
    t: f32,
}

impl Scene {
    /// Placed submeshes.
    pub fn items(&self) -> usize {
        self.items.len()
    }

    /// The placement (numbered in the order of the builder's `add` calls) seen at image point
    /// (`x`, `y`), and its distance.
    pub fn pick(&self, camera: &Camera, x: f32, y: f32) -> Option<(u32, f32)> {
        let d = camera.direction(x, y);
        let eye = V::new(camera.eye.x, camera.eye.y, camera.eye.z);
        let hit = self.trace(eye, V::new(d.x, d.y, d.z))?;
        Some((self.items[hit.item as usize].placement, hit.t))
    }

    /// The distance along the ray from `origin` in direction `dir` (normalised here) to the
    /// nearest surface that draws, if any.
    pub fn cast(&self, origin: Vec3, dir: Vec3) -> Option<f32> {
        let d = dir.try_normalize()?;
        let hit = self.trace(V::new(origin.x, origin.y, origin.z), V::new(d.x, d.y, d.z))?;
        Some(hit.t)
    }

    /// Renders the scene from `camera` with `samples` x `samples` rays per pixel (at least 1),
    /// rows in parallel.
    pub fn render(&self, camera: &Camera, samples: u32) -> Frame {
        let k = samples.max(1);
        let (w, h) = (camera.width, camera.height);
        // A sample's footprint picks the mip level, as a GPU's pixel does.
        let spread = camera.pixel_angle() / k as f32;
        let eye = V::new(camera.eye.x, camera.eye.y, camera.eye.z);
        let rows: Vec<Vec<([u8; 3], f32, f32)>> = (0..h)
            .into_par_iter()
            .map(|y| {
                (0..w)
                    .map(|x| {
                        let (mut sum, mut hits, mut depth) = (Vec3::ZERO, 0u32, f32::INFINITY);
                        for j in 0..k {
                            for i in 0..k {
                                let sx = x as f32 + (i as f32 + 0.5) / k as f32;
                                let sy = y as f32 + (j as f32 + 0.5) / k as f32;
                                let d = camera.direction(sx, sy);
                                let dir = V::new(d.x, d.y, d.z);
                                match self.trace(eye, dir) {
                                    Some(hit) => {
                                        sum += self.shade(&hit, dir, spread);
                                        hits += 1;
                                        depth = depth.min(hit.t);
                                    }
                                    None => sum += sky_linear(),
                                }
                            }
                        }
                        let n = (k * k) as f32;
                        (to_srgb(sum / n), hits as f32 / n, depth)
                    })
                    .collect()
            })
            .collect();
        let mut frame = Frame {
            width: w,
            height: h,
            color: Vec::with_capacity(w as usize * h as usize),
            coverage: Vec::with_capacity(w as usize * h as usize),
            depth: Vec::with_capacity(w as usize * h as usize),
        };
        for (c, cov, d) in rows.into_iter().flatten() {
            frame.color.push(c);
            frame.coverage.push(cov);
            frame.depth.push(d);
        }
        frame
    }

    /// The closest surface along the ray from `origin` in direction `dir` (unit), if any.
    fn trace(&self, origin: V, dir: V) -> Option<Hit> {
        let tlas = self.tlas.as_ref()?;
        // obvhs picks a ray's octant by comparison and its inverse direction by sign bit, so a
        // negative zero component would send the traversal the wrong way: adding zero makes
        // every zero positive.
        let ray = Ray::new(origin, dir + V::ZERO, 1e-4, f32::INFINITY);
        let mut best: Option<Hit> = None;
        let mut top = RayHit::none();
        tlas.ray_traverse(ray, &mut top, |r, id| {
            let k = tlas.primitive_indices[id];
            let item = &self.items[k as usize];
            let Some(blas) = &self.meshes[item.mesh as usize].submeshes[item.submesh as usize]
            else {
                return f32::INFINITY;
            };
            let local = Ray::new(
                item.to_local.transform_point3a(r.origin),
                item.to_local.transform_vector3a(r.direction) + V::ZERO,
                r.tmin,
                r.tmax,
            );
            let cull = !blas.shading.double_sided;
            let mut found: Option<(u32, f32, f32)> = None;
            let mut inner = RayHit::none();
            blas.bvh.ray_traverse(local, &mut inner, |lr, j| {
                let tri = &blas.tris[j];
                let Some((t, u, v)) = intersect(tri, lr, cull) else {
                    return f32::INFINITY;
                };
                if let Some(uv) = blas.uv(tri.index, u, v) {
                    if blas.shading.discards(uv) {
                        return f32::INFINITY;
                    }
                }
                found = Some((tri.index, u, v));
                t
            });
            match found {
                Some((triangle, u, v)) => {
                    best = Some(Hit {
                        item: k,
                        triangle,
                        u,
                        v,
                        t: inner.t,
                    });
                    inner.t
                }
                None => f32::INFINITY,
            }
        });
        best
    }

    /// The lit linear colour of `hit` seen along `dir`, with the mip level of a footprint of
    /// `spread` radians.
    fn shade(&self, hit: &Hit, dir: V, spread: f32) -> Vec3 {
        let s = self.surface_of(hit, dir, spread, 0.0);
        s.albedo.truncate() * light(s.normal)
    }

    /// What the ray from `origin` along `dir` meets first, unlit: `width` is the world size of
    /// the sample (for the mip level), as for an orthographic view.
    pub fn surface(&self, origin: Vec3, dir: Vec3, width: f32) -> Option<Surface> {
        let d = dir.try_normalize()?;
        let dir = V::new(d.x, d.y, d.z);
        let hit = self.trace(V::new(origin.x, origin.y, origin.z), dir)?;
        Some(self.surface_of(&hit, dir, 0.0, width))
    }

    /// The surface at `hit`: its footprint is `t x spread + width`, over the cosine of the
    /// view angle.
    fn surface_of(&self, hit: &Hit, dir: V, spread: f32, width: f32) -> Surface {
        let item = &self.items[hit.item as usize];
        let Some(blas) = &self.meshes[item.mesh as usize].submeshes[item.submesh as usize] else {
            return Surface {
                t: hit.t,
                albedo: Vec4::ZERO,
                normal: Vec3::Y,
            };
        };
        let tri = blas.corners(hit.triangle);
        let (u, v) = (hit.u, hit.v);
        let w = 1.0 - u - v;
        let sub = &blas.submesh;
        let p = |i: usize| {
            let q = sub.positions[i];
            item.to_world.transform_point3a(V::new(q.x, q.y, q.z))
        };
        let (a, b, c) = (p(tri[0]), p(tri[1]), p(tri[2]));
        let geometric = (b - a).cross(c - a);
        let area = geometric.length() * 0.5;
        let mut normal = match &sub.normals {
            Some(n) => {
                let local = n[tri[0]] * w + n[tri[1]] * u + n[tri[2]] * v;
                let m = item.to_local.matrix3.transpose();
                m * glam34::Vec3A::new(local.x, local.y, local.z)
            }
            None if item.mirrored => -geometric,
            None => geometric,
        }
        .normalize_or_zero();
        if normal == V::ZERO {
            normal = geometric.normalize_or(V::Y);
        }
        if normal.dot(dir) > 0.0 {
            normal = -normal;
        }
        let cos = normal.dot(dir).abs().max(0.05);
        let mut color = match blas.uv(hit.triangle, u, v) {
            Some(uv) => {
                let lod = blas.shading.texture.as_ref().map_or(0.0, |(chain, tf)| {
                    let uvs = sub.uvs.as_ref().expect("uv() found UVs");
                    let map = |i: usize| tf.map_or(uvs[i], |t| t.apply(uvs[i]));
                    let (t0, t1, t2) = (map(tri[0]), map(tri[1]), map(tri[2]));
                    let texel_area =
                        ((t1 - t0).perp_dot(t2 - t0) * 0.5).abs() * chain.texels() as f32;
                    let footprint = (hit.t * spread + width) / cos;
                    let density = (texel_area / area.max(1e-12)).sqrt();
                    (footprint * density).max(1e-12).log2()
                });
                blas.shading.base_color(uv, lod)
            }
            None => blas.shading.base,
        };
        if let Some(colors) = &sub.colors {
            color *= colors[tri[0]] * w + colors[tri[1]] * u + colors[tri[2]] * v;
        }
        Surface {
            t: hit.t,
            albedo: color,
            normal: Vec3::new(normal.x, normal.y, normal.z),
        }
    }
}

/// What a ray meets: distance, unlit colour and the normal facing the ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Distance along the ray.
    pub t: f32,
    /// Linear base colour times vertex colour, with alpha.
    pub albedo: Vec4,
    /// Unit shading normal, turned towards the ray's origin.
    pub normal: Vec3,
}

/// Möller-Trumbore: distance and barycentrics of the hit, if the ray meets the triangle
/// within its range from the side that draws (`cull` hides the back). The test runs in the
/// submesh's own space, where counter-clockwise is the front: glTF reverses the winding under
/// a mirroring transform, which keeps the same side in front.
fn intersect(tri: &Tri, ray: &Ray, cull: bool) -> Option<(f32, f32, f32)> {
    let p = ray.direction.cross(tri.e2);
    let det = tri.e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    // det = -direction . (e1 x e2): positive when the ray meets the front face.
    if cull && det < 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let s = ray.origin - tri.v0;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(tri.e1);
    let v = ray.direction.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = tri.e2.dot(q) * inv;
    (t > ray.tmin && t < ray.tmax).then_some((t, u, v))
}

/// The world box of a local box under `m`.
fn world_box(local: &BoxA, m: &Affine34) -> BoxA {
    let mut out = BoxA::INVALID;
    for i in 0..8 {
        let corner = V::new(
            if i & 1 == 0 { local.min.x } else { local.max.x },
            if i & 2 == 0 { local.min.y } else { local.max.y },
            if i & 4 == 0 { local.min.z } else { local.max.z },
        );
        out.extend(m.transform_point3a(corner));
    }
    out
}

fn affine34(m: &glam::Affine3A) -> Affine34 {
    Affine34::from_cols_array(&m.to_cols_array())
}

fn sky_linear() -> Vec3 {
    let c = SKY.map(|s| {
        let s = f32::from(s) / 255.0;
        ((s + 0.055) / 1.055).powf(2.4)
    });
    Vec3::from_array(c)
}
