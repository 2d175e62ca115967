//! Orthoviews (Chaudhuri et al. 2009, sections 3-4): orthographic depth images of a box's
//! content from a canonical direction, with colour (sRGB, unlit), depth (16 bits across the
//! box's depth) and normals (octahedral, 2 x 8 bits).
//!
//! - [`Orthoview::render`] ray-casts a [`Scene`] (a leaf's content) from outside the box along
//!   the direction, one ray per pixel centre, only hits inside the box counted.
//! - [`Orthoview::composite`] makes a parent's orthoview from its children's without geometry
//!   (the paper's figure 4): every child pixel is re-projected into a double-size buffer over
//!   the parent's image plane, nearest depth kept; each 2 x 2 block then becomes one pixel whose
//!   depth is the block's minimum and whose colour and normal are the mean of the block's
//!   pixels within [`DEPTH_THRESHOLD`] pixels of depth of it.
//! - [`resolution`] is the paper's q with the solid-angle contract in place of its screen:
//!   `q = s / (cos(theta) * r * pixel_angle)`, where the paper's `2 r tan(alpha / 2) / p` (the
//!   width of a screen pixel at distance r) is `r * pixel_angle` and `pixel_angle` is the square
//!   root of the view's `pixel_solid_angle`: adjacent orthoview pixels then land on adjacent
//!   screen pixels for a surface seen `theta` from the nearest direction at distance `r`.
//! - [`node_resolution`] sets `r`, the nearest distance an impostor is shown from, to where
//!   the cut would first draw the node with its aggregate: where an object of the node's
//!   largest radius `r_max` subtends `min_solid_angle` (`r = r_max sqrt(pi /
//!   min_solid_angle)`), for the clients' default pixel. The impostor then takes over from the
//!   aggregate at that very distance. q is kept within [`MIN_Q`]..=[`MAX_Q`]: above it a
//!   node's impostor is used only farther out, where its pixels shrink under a screen pixel.
//! - [`WORLD_DIRECTIONS`] are the nine a world's impostors are made from (why: see there).
//!
//! An orthoview's image plane is perpendicular to its direction and covers the projection of
//! its box; pixels are square. Depth 0 is an empty pixel; 1..=65535 spans the box's extent
//! along the direction, nearest first.
//!
//! Where impostors are built and served: `horizon-aggregate`'s `impostors.rs` (the rebuild)
//! and the server's cut.

use glam::{Vec2, Vec3};
use horizon_mesh::Aabb;
use rayon::prelude::*;

use crate::scene::Scene;
use crate::shade::to_srgb;

/// The paper's canonical directions, `{-1, 0, +1}^3` without the zero vector: 26, of which a
/// client uses at most 9 (those nearest its view direction).
pub fn canonical_directions() -> Vec<[i8; 3]> {
    let mut out = Vec::with_capacity(26);
    for x in -1..=1 {
        for y in -1..=1 {
            for z in -1..=1 {
                if (x, y, z) != (0, 0, 0) {
                    out.push([x, y, z]);
                }
            }
        }
    }
    out
}

/// The canonical directions a world's orthoviews look along: straight down, the four
/// downward diagonals `(+-1, -1, +-1)` and the four horizontal diagonals `(+-1, 0, +-1)`.
///
/// Why these nine of the 26 (the paper's figure 5: five views disocclude badly, nine do well,
/// and a client needs about three of them per cell):
/// - Clients stand on or above the ground, so no view looks up: nine suffice where the sphere
///   would need 26.
/// - A regular street grid, the paper's own warning case, runs along x and z. Views along those
///   axes (`(1, 0, 0)`, `(1, -1, 0)`, ...) look straight down its streets: every facade along
///   a street is seen edge-on and every cross street hides behind the block in front. The
///   diagonals see two faces of every block at 45 degrees, and straight down sees the streets
///   themselves.
/// - Every view from above or level lies within [`WORLD_THETA`] (46.4 degrees) of one of them.
pub const WORLD_DIRECTIONS: [[i8; 3]; 9] = [
    [0, -1, 0],
    [1, -1, 1],
    [1, -1, -1],
    [-1, -1, 1],
    [-1, -1, -1],
    [1, 0, 1],
    [1, 0, -1],
    [-1, 0, 1],
    [-1, 0, -1],
];

/// The largest angle between a view from above or level and the nearest of
/// [`WORLD_DIRECTIONS`], 46.4 degrees: a view along an axis 12.6 degrees below the horizon,
/// between two level and two downward diagonals (a test checks it on a grid of views).
pub const WORLD_THETA: f32 = 0.8094;

/// How many of a node's orthoviews a cut sends: those nearest the view direction. The paper's
/// figure 5: two leave disocclusions, a third largely removes them.
pub const VIEWS_SERVED: usize = 3;

/// A splat's side in orthoview pixels ([`Orthoview::splats`]): over 1 so that splats seen up
/// to [`WORLD_THETA`] from their direction still close up (1 / cos(46.4 degrees) = 1.45).
pub const SPLAT_SCALE: f32 = 1.5;

/// A splat's side in pixels for a pixel covered `alpha` (0..=1): of the pixel's covered area,
/// grown towards [`SPLAT_SCALE`] as the pixel fills, so that full pixels overlap their
/// neighbours (no cracks seen obliquely) and thin features keep their area.
pub fn splat_side(alpha: f32) -> f32 {
    alpha.sqrt() * (1.0 + (SPLAT_SCALE - 1.0) * alpha * alpha)
}

/// Pixels of depth within which composited pixels are averaged together.
pub const DEPTH_THRESHOLD: f32 = 1.5;

/// The paper's orthoview resolution q for a box of linear extent `extent`, shown as an
/// impostor from `distance` and beyond, to a client whose pixel subtends `pixel_angle`
/// radians, for surfaces seen at most `theta` radians from the nearest direction. At least 1.
pub fn resolution(extent: f32, distance: f32, pixel_angle: f32, theta: f32) -> u32 {
    let pixel = (distance * pixel_angle * theta.cos()).max(f32::MIN_POSITIVE);
    let q = (extent / pixel).ceil();
    if q.is_finite() {
        q.clamp(1.0, 8192.0) as u32
    } else {
        1
    }
}

/// The fewest pixels along an orthoview's longer side.
pub const MIN_Q: u32 = 16;
/// The most: storage and ray casting grow with its square.
pub const MAX_Q: u32 = 128;

/// The q of a node's orthoviews (see the module docs): [`resolution`] for a node of linear
/// extent `extent` whose largest object has radius `r_max`, shown from where that object
/// subtends `min_solid_angle`, to clients whose pixel subtends `pixel_solid_angle`, over
/// [`WORLD_DIRECTIONS`]; within [`MIN_Q`]..=[`MAX_Q`].
pub fn node_resolution(
    extent: f32,
    r_max: f32,
    min_solid_angle: f32,
    pixel_solid_angle: f32,
) -> u32 {
    let distance = r_max * (std::f32::consts::PI / min_solid_angle).sqrt();
    resolution(extent, distance, pixel_solid_angle.sqrt(), WORLD_THETA).clamp(MIN_Q, MAX_Q)
}

/// The [`VIEWS_SERVED`] directions of `directions` nearest to looking along `view` (from the
/// eye towards the node), nearest first; only those less than 90 degrees from it.
pub fn facing(directions: &[[i8; 3]], view: Vec3) -> Vec<usize> {
    let view = view.normalize_or_zero();
    let mut order: Vec<(f32, usize)> = directions
        .iter()
        .enumerate()
        .map(|(i, d)| (unit(*d).dot(view), i))
        .filter(|(c, _)| *c > 0.0)
        .collect();
    order.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    order.truncate(VIEWS_SERVED);
    order.into_iter().map(|(_, i)| i).collect()
}

/// A canonical direction as a unit vector.
pub fn unit(direction: [i8; 3]) -> Vec3 {
    Vec3::new(
        f32::from(direction[0]),
        f32::from(direction[1]),
        f32::from(direction[2]),
    )
    .normalize_or_zero()
}

/// One orthographic depth image (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Orthoview {
    /// The canonical direction it looks along.
    pub direction: [i8; 3],
    /// The box it shows.
    pub bounds: Aabb,
    /// Pixels across and down.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// sRGB colour and coverage (alpha 0 where empty), row by row.
    pub color: Vec<[u8; 4]>,
    /// Depth: 0 empty, else 1..=65535 across the box along the direction.
    pub depth: Vec<u16>,
    /// Octahedral unit normals, 2 x 8 bits.
    pub normal: Vec<[u8; 2]>,
}

/// A composited sample: depth along the direction, colour, normal.
type Sample = (f32, [u8; 4], [u8; 2]);

/// An orthoview's frame: where its pixels and depths are in the world.
#[derive(Clone, Copy, Debug)]
struct Frame {
    d: Vec3,
    u: Vec3,
    v: Vec3,
    /// The image plane's corner (pixel (0, 0)'s corner) at depth 0.
    origin: Vec3,
    /// Size of a pixel, world units.
    pixel: f32,
    /// The box's extent along `d`.
    depth: f32,
    width: u32,
    height: u32,
}

impl Frame {
    /// The frame over `bounds` looking along `direction`, `q` pixels along its longer side.
    fn new(bounds: &Aabb, direction: [i8; 3], q: u32) -> Frame {
        let d = unit(direction);
        // An up-ish second axis: world Y unless the direction is vertical.
        let helper = if d.y.abs() > 0.9 { Vec3::Z } else { Vec3::Y };
        let u = helper.cross(d).normalize();
        let v = d.cross(u);
        let corners = if bounds.is_empty() {
            [Vec3::ZERO; 8]
        } else {
            bounds.corners()
        };
        let range = |axis: Vec3| {
            corners
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), c| {
                    let x = c.dot(axis);
                    (lo.min(x), hi.max(x))
                })
        };
        let ((u0, u1), (v0, v1), (d0, d1)) = (range(u), range(v), range(d));
        let side = (u1 - u0).max(v1 - v0).max(f32::MIN_POSITIVE);
        let pixel = side / q.max(1) as f32;
        let width = (((u1 - u0) / pixel).ceil() as u32).clamp(1, q.max(1));
        let height = (((v1 - v0) / pixel).ceil() as u32).clamp(1, q.max(1));
        Frame {
            d,
            u,
            v,
            origin: u * u0 + v * v0 + d * d0,
            pixel,
            depth: (d1 - d0).max(0.0),
            width,
            height,
        }
    }

    /// The world point at pixel (`x`, `y`) (fractional) and depth `t` along the direction.
    fn point(&self, x: f32, y: f32, t: f32) -> Vec3 {
        self.origin + self.u * (x * self.pixel) + self.v * (y * self.pixel) + self.d * t
    }

    /// A depth along the direction as stored (1..=65535), 0 outside the box.
    fn quantize(&self, t: f32) -> u16 {
        if !(0.0..=self.depth * 1.0001).contains(&t) {
            return 0;
        }
        let unit = if self.depth > 0.0 {
            t / self.depth
        } else {
            0.0
        };
        (1.0 + unit.clamp(0.0, 1.0) * 65534.0).round() as u16
    }

    /// A stored depth back along the direction.
    fn unquantize(&self, z: u16) -> f32 {
        f32::from(z.saturating_sub(1)) / 65534.0 * self.depth
    }
}

impl Orthoview {
    /// Renders `scene` inside `bounds` along `direction` at `q` pixels along the longer side.
    pub fn render(scene: &Scene, bounds: &Aabb, direction: [i8; 3], q: u32) -> Orthoview {
        let f = Frame::new(bounds, direction, q);
        let n = (f.width * f.height) as usize;
        let pixels: Vec<([u8; 4], u16, [u8; 2])> = (0..n)
            .into_par_iter()
            .map(|i| {
                let (x, y) = ((i as u32 % f.width) as f32, (i as u32 / f.width) as f32);
                if bounds.is_empty() {
                    return ([0; 4], 0, [0; 2]);
                }
                // From just outside the box, so that a surface on its face is hit.
                let margin = f.pixel.max(f.depth * 1e-3);
                let from = f.point(x + 0.5, y + 0.5, -margin);
                match scene.surface(from, f.d, f.pixel) {
                    Some(s) => {
                        let z = f.quantize(s.t - margin);
                        if z == 0 {
                            return ([0; 4], 0, [0; 2]);
                        }
                        let [r, g, b] = to_srgb(s.albedo.truncate());
                        ([r, g, b, 255], z, octahedral(s.normal))
                    }
                    None => ([0; 4], 0, [0; 2]),
                }
            })
            .collect();
        Orthoview {
            direction,
            bounds: *bounds,
            width: f.width,
            height: f.height,
            color: pixels.iter().map(|p| p.0).collect(),
            depth: pixels.iter().map(|p| p.1).collect(),
            normal: pixels.iter().map(|p| p.2).collect(),
        }
    }

    /// The orthoview of `bounds` along `direction` at `q`, composited from `children`' (each
    /// along the same direction) without geometry (see the module docs).
    pub fn composite(
        children: &[&Orthoview],
        bounds: &Aabb,
        direction: [i8; 3],
        q: u32,
    ) -> Orthoview {
        let f = Frame::new(bounds, direction, q);
        // Stage 1: every child pixel into the double-size buffer, nearest depth kept.
        let (w2, h2) = (f.width * 2, f.height * 2);
        let mut fine: Vec<Option<Sample>> = vec![None; (w2 * h2) as usize];
        for child in children.iter().filter(|c| c.direction == direction) {
            let cf = Frame::new(&child.bounds, direction, child.width.max(child.height));
            for y in 0..child.height {
                for x in 0..child.width {
                    let i = (y * child.width + x) as usize;
                    let z = child.depth[i];
                    if z == 0 {
                        continue;
                    }
                    // A child's sample may sit up to its own rounding outside its box;
                    // clamped into this box, this view's samples stay within 0.71 of its
                    // pixels of it however many levels it was composited up.
                    let p = cf.point(x as f32 + 0.5, y as f32 + 0.5, cf.unquantize(z));
                    let p = if bounds.is_empty() {
                        p
                    } else {
                        p.clamp(bounds.min, bounds.max)
                    };
                    let rel = p - f.origin;
                    let (px, py, t) = (
                        rel.dot(f.u) / f.pixel * 2.0,
                        rel.dot(f.v) / f.pixel * 2.0,
                        rel.dot(f.d),
                    );
                    if px < 0.0 || py < 0.0 || px >= w2 as f32 || py >= h2 as f32 {
                        continue;
                    }
                    let j = (py as u32 * w2 + px as u32) as usize;
                    if fine[j].is_none_or(|(old, _, _)| t < old) {
                        fine[j] = Some((t, child.color[i], child.normal[i]));
                    }
                }
            }
        }
        // Stage 2: each 2 x 2 block to one pixel.
        let threshold = DEPTH_THRESHOLD * f.pixel;
        let n = (f.width * f.height) as usize;
        let mut out = Orthoview {
            direction,
            bounds: *bounds,
            width: f.width,
            height: f.height,
            color: vec![[0; 4]; n],
            depth: vec![0; n],
            normal: vec![[0; 2]; n],
        };
        for y in 0..f.height {
            for x in 0..f.width {
                let block: Vec<Sample> = [(0, 0), (1, 0), (0, 1), (1, 1)]
                    .iter()
                    .filter_map(|&(dx, dy)| fine[((2 * y + dy) * w2 + 2 * x + dx) as usize])
                    .collect();
                let Some(nearest) = block.iter().map(|b| b.0).reduce(f32::min) else {
                    continue;
                };
                let near: Vec<&Sample> = block
                    .iter()
                    .filter(|b| b.0 <= nearest + threshold)
                    .collect();
                let k = near.len() as f32;
                let mut color = [0f32; 3];
                let mut normal = Vec3::ZERO;
                for b in &near {
                    for (sum, &c) in color.iter_mut().zip(&b.1) {
                        *sum += f32::from(c) / k;
                    }
                    normal += from_octahedral(b.2);
                }
                let i = (y * f.width + x) as usize;
                // Coverage: the mean of the block's four samples' coverage (0 where empty),
                // so that partial coverage carries up the tree.
                let covered: f32 = block.iter().map(|b| f32::from(b.1[3])).sum();
                let alpha = (covered / 4.0).round() as u8;
                out.color[i] = [
                    color[0].round() as u8,
                    color[1].round() as u8,
                    color[2].round() as u8,
                    alpha.max(1),
                ];
                out.depth[i] = f.quantize(nearest).max(1);
                out.normal[i] = octahedral(normal.normalize_or(Vec3::Y));
            }
        }
        out
    }

    /// The orthoview as geometry: one square per covered pixel, at its sample's depth,
    /// perpendicular to the direction, [`splat_side`] pixels across for its coverage (alpha),
    /// with the pixel's colour
    /// (vertex colours, linear) and normal, double-sided. This is the depth-displaced splat a
    /// client draws; rendered with the meshes, it is lit by its normals as they are.
    pub fn splats(&self) -> horizon_mesh::InstancedMesh {
        use glam::Vec4;
        let f = Frame::new(&self.bounds, self.direction, self.width.max(self.height));
        let mut sub = horizon_mesh::Submesh {
            normals: Some(Vec::new()),
            colors: Some(Vec::new()),
            material: Some(0),
            ..horizon_mesh::Submesh::default()
        };
        for y in 0..self.height {
            for x in 0..self.width {
                let Some(p) = self.point(x, y) else {
                    continue;
                };
                let i = (y * self.width + x) as usize;
                let [r, g, b, a] = self.color[i];
                // A pixel partly covered is a smaller square of the same area.
                let half = 0.5 * splat_side(f32::from(a) / 255.0) * f.pixel;
                let (du, dv) = (f.u * half, f.v * half);
                let linear = |c: u8| crate::shade::from_srgb(c);
                let color = Vec4::new(linear(r), linear(g), linear(b), 1.0);
                let normal = from_octahedral(self.normal[i]);
                let base = sub.positions.len() as u32;
                sub.positions
                    .extend([p - du - dv, p + du - dv, p + du + dv, p - du + dv]);
                if let Some(n) = sub.normals.as_mut() {
                    n.extend([normal; 4]);
                }
                if let Some(c) = sub.colors.as_mut() {
                    c.extend([color; 4]);
                }
                // Facing against the direction, towards a viewer looking along it.
                sub.indices
                    .extend([base, base + 2, base + 1, base, base + 3, base + 2]);
            }
        }
        horizon_mesh::InstancedMesh {
            submeshes: vec![sub],
            instances: vec![horizon_mesh::Instance {
                submesh: 0,
                transform: glam::Affine3A::IDENTITY,
            }],
            materials: vec![horizon_mesh::Material {
                double_sided: true,
                ..horizon_mesh::Material::default()
            }],
            textures: Vec::new(),
        }
    }

    /// The world position of pixel (`x`, `y`)'s sample, if it holds one.
    pub fn point(&self, x: u32, y: u32) -> Option<Vec3> {
        let f = Frame::new(&self.bounds, self.direction, self.width.max(self.height));
        let z = *self.depth.get((y * self.width + x) as usize)?;
        (z != 0).then(|| f.point(x as f32 + 0.5, y as f32 + 0.5, f.unquantize(z)))
    }

    /// The unit normal stored at pixel (`x`, `y`).
    pub fn normal_at(&self, x: u32, y: u32) -> Vec3 {
        from_octahedral(self.normal[(y * self.width + x) as usize])
    }

    /// The world size of one pixel.
    pub fn pixel_size(&self) -> f32 {
        Frame::new(&self.bounds, self.direction, self.width.max(self.height)).pixel
    }

    /// Pixels that hold a sample.
    pub fn covered(&self) -> usize {
        self.depth.iter().filter(|&&z| z != 0).count()
    }

    /// Checks the invariants: one colour, depth and normal per pixel; a pixel is empty in all
    /// three or in none (alpha 0 exactly where depth is 0); every stored normal decodes to a
    /// unit vector; the direction is canonical; every sample lies within the bounds (to half a
    /// pixel). The error is one line.
    pub fn validate(&self) -> Result<(), String> {
        let n = (self.width as usize) * (self.height as usize);
        if self.width == 0 || self.height == 0 {
            return Err("an orthoview has at least one pixel".into());
        }
        if self.color.len() != n || self.depth.len() != n || self.normal.len() != n {
            return Err(format!(
                "{}x{} pixels but {} colours, {} depths, {} normals",
                self.width,
                self.height,
                self.color.len(),
                self.depth.len(),
                self.normal.len()
            ));
        }
        if self.direction == [0, 0, 0] || self.direction.iter().any(|c| c.abs() > 1) {
            return Err(format!("{:?} is not a canonical direction", self.direction));
        }
        let slack = self.pixel_size();
        for y in 0..self.height {
            for x in 0..self.width {
                let i = (y * self.width + x) as usize;
                if (self.depth[i] == 0) != (self.color[i][3] == 0) {
                    return Err(format!("pixel ({x}, {y}): depth and coverage disagree"));
                }
                if self.depth[i] == 0 {
                    continue;
                }
                let len = from_octahedral(self.normal[i]).length();
                if (len - 1.0).abs() > 1e-3 {
                    return Err(format!("pixel ({x}, {y}): normal of length {len}"));
                }
                if let Some(p) = self.point(x, y) {
                    let b = &self.bounds;
                    if (p - p.clamp(b.min, b.max)).length() > slack {
                        return Err(format!("pixel ({x}, {y}): sample {p} outside the bounds"));
                    }
                }
            }
        }
        Ok(())
    }

    /// The three images as lossless PNGs: colour (RGBA 8), depth (grey 16), normals (grey and
    /// alpha 8, the two octahedral coordinates).
    pub fn encode(&self) -> Result<[Vec<u8>; 3], image::ImageError> {
        let png = |img: image::DynamicImage| -> Result<Vec<u8>, image::ImageError> {
            let mut out = Vec::new();
            img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)?;
            Ok(out)
        };
        let (w, h) = (self.width, self.height);
        let color =
            image::RgbaImage::from_fn(w, h, |x, y| image::Rgba(self.color[(y * w + x) as usize]));
        let depth = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(w, h, |x, y| {
            image::Luma([self.depth[(y * w + x) as usize]])
        });
        let normal = image::GrayAlphaImage::from_fn(w, h, |x, y| {
            image::LumaA(self.normal[(y * w + x) as usize])
        });
        Ok([
            png(image::DynamicImage::ImageRgba8(color))?,
            png(image::DynamicImage::ImageLuma16(depth))?,
            png(image::DynamicImage::ImageLumaA8(normal))?,
        ])
    }

    /// The orthoview of `bounds` along `direction` read back from [`Orthoview::encode`]'s
    /// images, validated.
    pub fn decode(
        bounds: &Aabb,
        direction: [i8; 3],
        images: &[Vec<u8>; 3],
    ) -> Result<Orthoview, String> {
        let load = |bytes: &[u8]| {
            image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
                .map_err(|e| format!("an orthoview image does not decode: {e}"))
        };
        let color = load(&images[0])?.to_rgba8();
        let depth = load(&images[1])?.to_luma16();
        let normal = load(&images[2])?.to_luma_alpha8();
        let (w, h) = color.dimensions();
        if depth.dimensions() != (w, h) || normal.dimensions() != (w, h) {
            return Err("an orthoview's three images differ in size".into());
        }
        let view = Orthoview {
            direction,
            bounds: *bounds,
            width: w,
            height: h,
            color: color.pixels().map(|p| p.0).collect(),
            depth: depth.pixels().map(|p| p.0[0]).collect(),
            normal: normal.pixels().map(|p| p.0).collect(),
        };
        view.validate()?;
        Ok(view)
    }
}

/// A unit vector in two bytes (octahedral mapping, Cigolle et al. 2014).
pub fn octahedral(n: Vec3) -> [u8; 2] {
    let n = n.normalize_or(Vec3::Y);
    let l1 = n.x.abs() + n.y.abs() + n.z.abs();
    let mut p = Vec2::new(n.x, n.y) / l1;
    if n.z < 0.0 {
        p = (Vec2::ONE - Vec2::new(p.y.abs(), p.x.abs())) * Vec2::new(p.x.signum(), p.y.signum());
    }
    let q = |v: f32| ((v.clamp(-1.0, 1.0) * 0.5 + 0.5) * 255.0).round() as u8;
    [q(p.x), q(p.y)]
}

/// The unit vector two bytes of [`octahedral`] stand for.
pub fn from_octahedral(e: [u8; 2]) -> Vec3 {
    let p = Vec2::new(f32::from(e[0]), f32::from(e[1])) / 255.0 * 2.0 - Vec2::ONE;
    let z = 1.0 - p.x.abs() - p.y.abs();
    let (x, y) = if z < 0.0 {
        (
            (1.0 - p.y.abs()) * p.x.signum(),
            (1.0 - p.x.abs()) * p.y.signum(),
        )
    } else {
        (p.x, p.y)
    };
    Vec3::new(x, y, z).normalize_or(Vec3::Y)
}
