//! Shared geometry for the benchmark models of the IAS paper (Azim et al. 2014, Table 2):
//! closed primitives (box, tube, frustum, cone, sphere, extruded profile) and open sheets (leaf
//! blade, grass blade, polar disc, height field).
//!
//! Every primitive has normals and UVs, with seams where a modelling tool would put them: a box
//! has its own vertices per face (hard-edge normal seams), a tube or sphere repeats its first
//! column of vertices with `u = 1` (a UV seam along one side) and has separate cap vertices, an
//! extrusion splits its vertices at sharp profile corners. Closed primitives are watertight when
//! welded by position (coincident vertices are computed by the same expression, so they are
//! bit-identical) and wound counter-clockwise seen from outside.

use std::collections::HashMap;
use std::f32::consts::TAU;

use glam::{Affine3A, Mat3, Vec2, Vec3, Vec4};
use horizon_mesh::Submesh;

/// Geometry of one submesh under construction: vertices with normal and UV, optional colours,
/// and a triangle list wound counter-clockwise seen from the front.
#[derive(Clone, Debug, Default)]
pub struct MeshBuilder {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Unit normals, one per vertex.
    pub normals: Vec<Vec3>,
    /// Texture coordinates, one per vertex.
    pub uvs: Vec<Vec2>,
    /// Linear RGBA colours, one per vertex, if the geometry is painted.
    pub colors: Option<Vec<Vec4>>,
    /// Triangle list.
    pub indices: Vec<u32>,
}

impl MeshBuilder {
    /// An empty builder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Merges several pieces into one (a compound of closed parts stays closed).
    pub fn merge(parts: impl IntoIterator<Item = MeshBuilder>) -> Self {
        let mut out = Self::new();
        for p in parts {
            out.append(p);
        }
        out
    }

    /// Adds a vertex and returns its index.
    pub fn vertex(&mut self, position: Vec3, normal: Vec3, uv: Vec2) -> u32 {
        self.positions.push(position);
        self.normals.push(normal);
        self.uvs.push(uv);
        if let Some(c) = &mut self.colors {
            c.push(Vec4::ONE);
        }
        (self.positions.len() - 1) as u32
    }

    /// Adds one triangle, counter-clockwise seen from its front.
    pub fn triangle(&mut self, a: u32, b: u32, c: u32) {
        self.indices.extend([a, b, c]);
    }

    /// Adds a quad `a b c d`, counter-clockwise seen from its front, as two triangles.
    pub fn quad(&mut self, a: u32, b: u32, c: u32, d: u32) {
        self.indices.extend([a, b, c, a, c, d]);
    }

    /// Adds triangle `a b c`, or `a c b` if that is the order whose front faces `outward`.
    pub fn oriented_triangle(&mut self, a: u32, b: u32, c: u32, outward: Vec3) {
        let [pa, pb, pc] = [a, b, c].map(|i| self.positions[i as usize]);
        if (pb - pa).cross(pc - pa).dot(outward) >= 0.0 {
            self.triangle(a, b, c);
        } else {
            self.triangle(a, c, b);
        }
    }

    /// Number of triangles so far.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Appends another builder's geometry.
    pub fn append(&mut self, other: MeshBuilder) {
        let base = self.positions.len() as u32;
        match (&mut self.colors, other.colors) {
            (Some(mine), Some(theirs)) => mine.extend(theirs),
            (Some(mine), None) => {
                mine.extend(std::iter::repeat_n(Vec4::ONE, other.positions.len()))
            }
            (None, Some(theirs)) => {
                let mut c = vec![Vec4::ONE; self.positions.len()];
                c.extend(theirs);
                self.colors = Some(c);
            }
            (None, None) => {}
        }
        self.positions.extend(other.positions);
        self.normals.extend(other.normals);
        self.uvs.extend(other.uvs);
        self.indices.extend(other.indices.iter().map(|&i| base + i));
    }

    /// The geometry moved by `t`; normals follow, and a mirroring `t` flips the winding so that
    /// front faces stay front faces.
    pub fn transformed(mut self, t: Affine3A) -> Self {
        let linear = Mat3::from(t.matrix3);
        let normal_matrix = linear.inverse().transpose();
        for p in &mut self.positions {
            *p = t.transform_point3(*p);
        }
        for n in &mut self.normals {
            *n = (normal_matrix * *n).normalize_or_zero();
        }
        if linear.determinant() < 0.0 {
            self.flip_winding();
        }
        self
    }

    /// Reverses every triangle.
    pub fn flip_winding(&mut self) {
        for t in self.indices.chunks_exact_mut(3) {
            t.swap(1, 2);
        }
    }

    /// Every vertex painted with colour `c` (linear RGBA).
    pub fn painted(mut self, c: Vec4) -> Self {
        self.colors = Some(vec![c; self.positions.len()]);
        self
    }

    /// Every vertex painted with `colour(position)`; a pure function of the position keeps
    /// coincident vertices alike.
    pub fn painted_with(mut self, colour: impl Fn(Vec3) -> Vec4) -> Self {
        self.colors = Some(self.positions.iter().map(|&p| colour(p)).collect());
        self
    }

    /// Texture coordinates multiplied by `scale` (e.g. metres to texture tiles).
    pub fn scaled_uvs(mut self, scale: Vec2) -> Self {
        for uv in &mut self.uvs {
            *uv *= scale;
        }
        self
    }

    /// Texture coordinates remapped by `f` (e.g. swapped, so that rows of roof tiles run along
    /// the eaves).
    pub fn mapped_uvs(mut self, f: impl Fn(Vec2) -> Vec2) -> Self {
        for uv in &mut self.uvs {
            *uv = f(*uv);
        }
        self
    }

    /// Every position moved by `f`, then normals recomputed (see
    /// [`MeshBuilder::recompute_normals`]). `f` must be a pure function of the position, so that
    /// coincident vertices stay coincident and closed geometry stays closed.
    pub fn displaced(mut self, f: impl Fn(Vec3) -> Vec3) -> Self {
        for p in &mut self.positions {
            *p = f(*p);
        }
        self.recompute_normals();
        self
    }

    /// Recomputes normals from the triangles, area-weighted. Vertices that share a position and
    /// had the same normal are smoothed together (across UV seams); vertices at the same
    /// position with different normals stay apart, which keeps hard edges hard.
    pub fn recompute_normals(&mut self) {
        let mut groups: HashMap<[u32; 6], usize> = HashMap::new();
        let group_of: Vec<usize> = self
            .positions
            .iter()
            .zip(&self.normals)
            .map(|(p, n)| {
                let key = [p.x, p.y, p.z, n.x, n.y, n.z].map(canonical_bits);
                let next = groups.len();
                *groups.entry(key).or_insert(next)
            })
            .collect();
        let mut sums = vec![Vec3::ZERO; groups.len()];
        for t in self.indices.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| self.positions[i as usize]);
            let face = (b - a).cross(c - a);
            for &i in t {
                sums[group_of[i as usize]] += face;
            }
        }
        for (n, &g) in self.normals.iter_mut().zip(&group_of) {
            if let Some(unit) = sums[g].try_normalize() {
                *n = unit;
            }
        }
    }

    /// The finished submesh: identical vertices (same position, normal, UV and colour) welded,
    /// so that only real seams remain as duplicated positions.
    pub fn into_submesh(self, material: usize) -> Submesh {
        let mut index_of: HashMap<[u32; 12], u32> = HashMap::new();
        let mut remap = Vec::with_capacity(self.positions.len());
        let mut out = Submesh {
            material: Some(material),
            ..Submesh::default()
        };
        let (mut normals, mut uvs) = (Vec::new(), Vec::new());
        let mut colors = self.colors.as_ref().map(|_| Vec::new());
        for v in 0..self.positions.len() {
            let (p, n, uv) = (self.positions[v], self.normals[v], self.uvs[v]);
            let c = self.colors.as_ref().map_or(Vec4::ONE, |c| c[v]);
            let key =
                [p.x, p.y, p.z, n.x, n.y, n.z, uv.x, uv.y, c.x, c.y, c.z, c.w].map(canonical_bits);
            let next = out.positions.len() as u32;
            let slot = *index_of.entry(key).or_insert(next);
            if slot == next {
                out.positions.push(p);
                normals.push(n);
                uvs.push(uv);
                if let Some(cs) = &mut colors {
                    cs.push(c);
                }
            }
            remap.push(slot);
        }
        out.indices = self.indices.iter().map(|&i| remap[i as usize]).collect();
        out.normals = Some(normals);
        out.uvs = Some(uvs);
        out.colors = colors;
        out
    }
}

/// The bits of `x` with negative zero folded onto positive zero, for welding.
pub fn canonical_bits(x: f32) -> u32 {
    (x + 0.0).to_bits()
}

/// A box of `size` centred on the origin, each face its own grid of `cells` (per axis) quads.
///
/// Closed; 4 (nx ny + ny nz + nz nx) triangles. Per-face vertices give hard edges; UVs are in
/// metres, upright (v along +Y) on the side faces.
pub fn subdivided_box(size: Vec3, cells: [u32; 3]) -> MeshBuilder {
    let half = size * 0.5;
    // Lattice coordinates come from one expression, so edges shared by two faces weld exactly.
    let coord =
        |axis: usize, index: u32| -half[axis] + size[axis] * (index as f32 / cells[axis] as f32);
    let mut b = MeshBuilder::new();
    for axis in 0..3 {
        for positive in [false, true] {
            // (u, v) span the face with u × v pointing outward, so the quads below are CCW.
            let (u, v) = if positive {
                ((axis + 1) % 3, (axis + 2) % 3)
            } else {
                ((axis + 2) % 3, (axis + 1) % 3)
            };
            let mut normal = Vec3::ZERO;
            normal[axis] = if positive { 1.0 } else { -1.0 };
            let (tex_u, tex_v) = face_texture_axes(normal);
            let fixed = if positive { cells[axis] } else { 0 };
            let base = b.positions.len() as u32;
            for j in 0..=cells[v] {
                for i in 0..=cells[u] {
                    let mut p = Vec3::ZERO;
                    p[axis] = coord(axis, fixed);
                    p[u] = coord(u, i);
                    p[v] = coord(v, j);
                    let uv = Vec2::new(
                        p.dot(tex_u) + half.dot(tex_u.abs()),
                        p.dot(tex_v) + half.dot(tex_v.abs()),
                    );
                    b.vertex(p, normal, uv);
                }
            }
            let row = cells[u] + 1;
            for j in 0..cells[v] {
                for i in 0..cells[u] {
                    let k = base + j * row + i;
                    b.quad(k, k + 1, k + 1 + row, k + row);
                }
            }
        }
    }
    b
}

/// A box of `size` centred on the origin: 24 vertices, 12 triangles.
pub fn cuboid(size: Vec3) -> MeshBuilder {
    subdivided_box(size, [1, 1, 1])
}

/// Texture axes for a planar face with outward `normal`: v up on walls, and `u × v = normal` so
/// textures are not mirrored.
fn face_texture_axes(normal: Vec3) -> (Vec3, Vec3) {
    if normal.y.abs() > 0.5 {
        (Vec3::X, normal.cross(Vec3::X))
    } else {
        (Vec3::Y.cross(normal), Vec3::Y)
    }
}

/// A closed tube swept along `path` with radius `radii[k]` at point `k`, `segments` around,
/// capped flat at both ends.
///
/// 2 segments (points − 1) + 2 segments triangles. The side repeats its first column of vertices
/// at `u = 1` (a UV seam) and the caps have their own vertices (hard edges). UVs are in metres:
/// u around the mean circumference, v along the path.
pub fn tube(path: &[Vec3], radii: &[f32], segments: u32) -> MeshBuilder {
    let n = segments as usize;
    let k_count = path.len();
    assert!(k_count >= 2 && radii.len() == k_count && n >= 3, "bad tube");
    let tangents: Vec<Vec3> = (0..k_count)
        .map(|k| {
            let ahead = path[(k + 1).min(k_count - 1)];
            let behind = path[k.saturating_sub(1)];
            (ahead - behind).normalize()
        })
        .collect();
    // Parallel-transported frames (n1, n2) with n1 × n2 = tangent.
    let helper = if tangents[0].y.abs() < 0.9 {
        Vec3::Y
    } else {
        Vec3::X
    };
    let mut n1 = tangents[0].cross(helper).normalize();
    let mut frames = Vec::with_capacity(k_count);
    for &t in &tangents {
        n1 = (n1 - t * n1.dot(t)).normalize();
        frames.push((n1, t.cross(n1)));
    }
    let directions: Vec<Vec2> = (0..n)
        .map(|j| {
            let a = TAU * j as f32 / n as f32;
            Vec2::new(a.cos(), a.sin())
        })
        .collect();
    // Ring positions once, shared by the side and the caps so that they weld exactly.
    let rings: Vec<Vec<Vec3>> = (0..k_count)
        .map(|k| {
            let (a, b) = frames[k];
            directions
                .iter()
                .map(|d| path[k] + (a * d.x + b * d.y) * radii[k])
                .collect()
        })
        .collect();
    let mut arc = vec![0.0f32; k_count];
    for k in 1..k_count {
        arc[k] = arc[k - 1] + (path[k] - path[k - 1]).length();
    }
    let circumference = TAU * radii.iter().sum::<f32>() / k_count as f32;

    let mut b = MeshBuilder::new();
    // Side.
    for k in 0..k_count {
        let (lo, hi) = (k.saturating_sub(1), (k + 1).min(k_count - 1));
        let slope = (radii[hi] - radii[lo]) / (arc[hi] - arc[lo]).max(1e-6);
        let (a, c) = frames[k];
        for j in 0..=n {
            let d = directions[j % n];
            let radial = a * d.x + c * d.y;
            let normal = (radial - tangents[k] * slope).normalize();
            let uv = Vec2::new(circumference * j as f32 / n as f32, arc[k]);
            b.vertex(rings[k][j % n], normal, uv);
        }
    }
    let row = (n + 1) as u32;
    for k in 0..k_count as u32 - 1 {
        for j in 0..n as u32 {
            let a = k * row + j;
            b.quad(a, a + 1, a + 1 + row, a + row);
        }
    }
    // Caps: a fan around the centre, facing backwards at the start and forwards at the end.
    for (k, facing) in [(0, -1.0f32), (k_count - 1, 1.0)] {
        let normal = tangents[k] * facing;
        let (a, c) = frames[k];
        let planar = |p: Vec3| Vec2::new((p - path[k]).dot(a), (p - path[k]).dot(c));
        let centre = b.vertex(path[k], normal, Vec2::ZERO);
        let first = b.positions.len() as u32;
        for &p in &rings[k] {
            b.vertex(p, normal, planar(p));
        }
        for j in 0..n as u32 {
            let (p, q) = (first + j, first + (j + 1) % n as u32);
            if facing > 0.0 {
                b.triangle(centre, p, q);
            } else {
                b.triangle(centre, q, p);
            }
        }
    }
    b
}

/// A closed frustum (a cylinder when the radii are equal) standing on the origin along +Y, with
/// `rings` bands of side quads. 2 segments (rings + 1) triangles.
pub fn frustum(
    bottom_radius: f32,
    top_radius: f32,
    height: f32,
    segments: u32,
    rings: u32,
) -> MeshBuilder {
    let (path, radii): (Vec<Vec3>, Vec<f32>) = (0..=rings)
        .map(|i| {
            let t = i as f32 / rings as f32;
            (
                Vec3::new(0.0, height * t, 0.0),
                bottom_radius + (top_radius - bottom_radius) * t,
            )
        })
        .unzip();
    tube(&path, &radii, segments)
}

/// A closed cone standing on the origin along +Y, apex at `height`. 2 segments triangles; the
/// apex has one vertex per segment (its UV and normal differ per side).
pub fn cone(radius: f32, height: f32, segments: u32) -> MeshBuilder {
    let n = segments as usize;
    let ring: Vec<Vec3> = (0..n)
        .map(|j| {
            let a = TAU * j as f32 / n as f32;
            Vec3::new(radius * a.cos(), 0.0, -radius * a.sin())
        })
        .collect();
    let slant = (radius * radius + height * height).sqrt();
    let side_normal = |a: f32| Vec3::new(height * a.cos(), radius, -height * a.sin()).normalize();
    let circumference = TAU * radius;
    let apex = Vec3::new(0.0, height, 0.0);
    let mut b = MeshBuilder::new();
    let base_row: Vec<u32> = (0..=n)
        .map(|j| {
            let a = TAU * j as f32 / n as f32;
            b.vertex(
                ring[j % n],
                side_normal(a),
                Vec2::new(circumference * j as f32 / n as f32, 0.0),
            )
        })
        .collect();
    for j in 0..n {
        let a = TAU * (j as f32 + 0.5) / n as f32;
        let u = circumference * (j as f32 + 0.5) / n as f32;
        let top = b.vertex(apex, side_normal(a), Vec2::new(u, slant));
        b.oriented_triangle(top, base_row[j], base_row[j + 1], side_normal(a));
    }
    let centre = b.vertex(Vec3::ZERO, Vec3::NEG_Y, Vec2::ZERO);
    let first = b.positions.len() as u32;
    for &p in &ring {
        b.vertex(p, Vec3::NEG_Y, Vec2::new(p.x, p.z));
    }
    for j in 0..n as u32 {
        b.oriented_triangle(centre, first + j, first + (j + 1) % n as u32, Vec3::NEG_Y);
    }
    b
}

/// A closed latitude-longitude sphere of `radius` centred on the origin, `segments` around and
/// `rings` bands from pole to pole. 2 segments (rings − 1) triangles; a UV seam along one
/// meridian, and one pole vertex per segment.
pub fn uv_sphere(radius: f32, segments: u32, rings: u32) -> MeshBuilder {
    let (n, r) = (segments as usize, rings as usize);
    let point = |i: usize, j: usize| -> Vec3 {
        if i == 0 {
            return Vec3::new(0.0, radius, 0.0);
        }
        if i == r {
            return Vec3::new(0.0, -radius, 0.0);
        }
        let phi = std::f32::consts::PI * i as f32 / r as f32;
        let theta = TAU * (j % n) as f32 / n as f32;
        radius * Vec3::new(phi.sin() * theta.cos(), phi.cos(), phi.sin() * theta.sin())
    };
    let mut b = MeshBuilder::new();
    // Rows of n + 1 vertices (the last repeats the first with u = 1); at the poles the extra
    // column is unused but keeps the indexing uniform.
    let row = (n + 1) as u32;
    for i in 0..=r {
        for j in 0..=n {
            let u = if i == 0 || i == r {
                (j as f32 + 0.5) / n as f32
            } else {
                j as f32 / n as f32
            };
            let p = point(i, j);
            b.vertex(p, p / radius, Vec2::new(u, 1.0 - i as f32 / r as f32));
        }
    }
    for i in 0..r as u32 {
        for j in 0..n as u32 {
            let a = i * row + j;
            let (a, b1, c, d) = (a, a + 1, a + 1 + row, a + row);
            let mid = point(i as usize, j as usize) + point(i as usize + 1, j as usize + 1);
            if i == 0 {
                b.oriented_triangle(a, c, d, mid);
            } else if i == r as u32 - 1 {
                b.oriented_triangle(a, b1, d, mid);
            } else {
                b.oriented_triangle(a, b1, c, mid);
                b.oriented_triangle(a, c, d, mid);
            }
        }
    }
    // The unused extra pole column is dropped by welding only if identical; remove it here.
    drop_unused_vertices(&mut b);
    b
}

/// The entries of `values` whose `used` flag is set.
fn keep_used<T: Copy>(values: &[T], used: &[bool]) -> Vec<T> {
    values
        .iter()
        .zip(used)
        .filter(|(_, &u)| u)
        .map(|(&v, _)| v)
        .collect()
}

/// Removes vertices no triangle uses, keeping order.
fn drop_unused_vertices(b: &mut MeshBuilder) {
    let mut used = vec![false; b.positions.len()];
    for &i in &b.indices {
        used[i as usize] = true;
    }
    let mut remap = vec![0u32; used.len()];
    let mut next = 0u32;
    for (v, &u) in used.iter().enumerate() {
        remap[v] = next;
        if u {
            next += 1;
        }
    }
    b.positions = keep_used(&b.positions, &used);
    b.normals = keep_used(&b.normals, &used);
    b.uvs = keep_used(&b.uvs, &used);
    if let Some(c) = &mut b.colors {
        *c = keep_used(c, &used);
    }
    for i in &mut b.indices {
        *i = remap[*i as usize];
    }
}

/// A closed prism: the simple polygon `profile` (in the XY plane, any orientation) extruded
/// along +Z from 0 to `depth` in `slices` steps. 2 k slices + 2 (k − 2) triangles for k points.
///
/// Profile corners turning by more than `smooth_below_degrees` are hard edges (split vertices);
/// gentler ones are smoothed. UVs are in metres: u along the perimeter (with a seam at the first
/// point), v along Z; the caps are mapped in plan.
pub fn extrude(
    profile: &[Vec2],
    depth: f32,
    slices: u32,
    smooth_below_degrees: f32,
) -> MeshBuilder {
    let mut points = profile.to_vec();
    if signed_area(&points) < 0.0 {
        points.reverse();
    }
    let k = points.len();
    let edge = |j: usize| points[(j + 1) % k] - points[j];
    // Outward edge normals of a counter-clockwise polygon.
    let edge_normal = |j: usize| {
        let d = edge(j).normalize();
        Vec3::new(d.y, -d.x, 0.0)
    };
    let cos_limit = smooth_below_degrees.to_radians().cos();
    let smooth_at =
        |j: usize| edge(j).normalize().dot(edge((j + k - 1) % k).normalize()) >= cos_limit;
    let corner_normal = |j: usize, own: usize| {
        if smooth_at(j) {
            (edge_normal((j + k - 1) % k) + edge_normal(j)).normalize()
        } else {
            edge_normal(own)
        }
    };
    let mut perimeter = vec![0.0f32; k + 1];
    for j in 0..k {
        perimeter[j + 1] = perimeter[j] + edge(j).length();
    }
    let z_at = |s: u32| depth * (s as f32 / slices as f32);

    let mut b = MeshBuilder::new();
    for j in 0..k {
        let next = (j + 1) % k;
        let (na, nb) = (corner_normal(j, j), corner_normal(next, j));
        let base = b.positions.len() as u32;
        for s in 0..=slices {
            let z = z_at(s);
            b.vertex(points[j].extend(z), na, Vec2::new(perimeter[j], z));
            b.vertex(points[next].extend(z), nb, Vec2::new(perimeter[j + 1], z));
        }
        for s in 0..slices {
            let a = base + 2 * s;
            // (p_j, z) → (p_j+1, z) → (p_j+1, z + dz): CCW seen from outside (normal (dy, -dx)).
            b.quad(a, a + 1, a + 3, a + 2);
        }
    }
    let tris = triangulate(&points);
    for (z, normal) in [(z_at(slices), Vec3::Z), (z_at(0), Vec3::NEG_Z)] {
        let base = b.positions.len() as u32;
        for p in &points {
            b.vertex(p.extend(z), normal, *p);
        }
        for [x, y, w] in &tris {
            let [x, y, w] = [*x, *y, *w].map(|i| base + i as u32);
            if normal.z > 0.0 {
                b.triangle(x, y, w);
            } else {
                b.triangle(x, w, y);
            }
        }
    }
    b
}

/// Twice the signed area of a polygon: positive when counter-clockwise.
fn signed_area(points: &[Vec2]) -> f32 {
    let k = points.len();
    (0..k)
        .map(|j| points[j].perp_dot(points[(j + 1) % k]))
        .sum()
}

/// Triangulates a simple counter-clockwise polygon by ear clipping: k − 2 triangles.
pub fn triangulate(points: &[Vec2]) -> Vec<[usize; 3]> {
    let mut remaining: Vec<usize> = (0..points.len()).collect();
    let mut out = Vec::with_capacity(points.len().saturating_sub(2));
    while remaining.len() > 3 {
        let m = remaining.len();
        let ear = (0..m).find(|&i| {
            let (a, b, c) = (
                remaining[(i + m - 1) % m],
                remaining[i],
                remaining[(i + 1) % m],
            );
            let (pa, pb, pc) = (points[a], points[b], points[c]);
            if (pb - pa).perp_dot(pc - pb) <= 0.0 {
                return false;
            }
            !remaining
                .iter()
                .filter(|&&o| o != a && o != b && o != c)
                .any(|&o| inside_triangle(points[o], pa, pb, pc))
        });
        // A degenerate polygon has no proper ear; clip anyway so the count stays k − 2.
        let i = ear.unwrap_or(0);
        out.push([
            remaining[(i + m - 1) % m],
            remaining[i],
            remaining[(i + 1) % m],
        ]);
        remaining.remove(i);
    }
    if let [a, b, c] = remaining[..] {
        out.push([a, b, c]);
    }
    out
}

fn inside_triangle(p: Vec2, a: Vec2, b: Vec2, c: Vec2) -> bool {
    (b - a).perp_dot(p - a) >= 0.0
        && (c - b).perp_dot(p - b) >= 0.0
        && (a - c).perp_dot(p - c) >= 0.0
}

/// An open disc-like sheet on a polar grid: a centre vertex and `rings` rings of `sectors`
/// vertices at `point(angle, fraction)` (fraction 0 is the centre, 1 the rim). Wound so its
/// front faces `up`. sectors (2 rings − 1) triangles; normals from the surface.
pub fn polar_sheet(
    sectors: u32,
    rings: u32,
    up: Vec3,
    point: impl Fn(f32, f32) -> Vec3,
    uv: impl Fn(Vec3) -> Vec2,
) -> MeshBuilder {
    let mut b = MeshBuilder::new();
    let centre_point = point(0.0, 0.0);
    let centre = b.vertex(centre_point, up, uv(centre_point));
    for r in 1..=rings {
        for s in 0..sectors {
            let p = point(TAU * s as f32 / sectors as f32, r as f32 / rings as f32);
            b.vertex(p, up, uv(p));
        }
    }
    let at = |r: u32, s: u32| 1 + (r - 1) * sectors + s % sectors;
    for s in 0..sectors {
        b.triangle(centre, at(1, s), at(1, s + 1));
    }
    for r in 1..rings {
        for s in 0..sectors {
            b.quad(at(r, s), at(r + 1, s), at(r + 1, s + 1), at(r, s + 1));
        }
    }
    orient_towards(&mut b, up);
    b.recompute_normals();
    b
}

/// Flips every triangle if the sheet as a whole faces away from `up`.
fn orient_towards(b: &mut MeshBuilder, up: Vec3) {
    let facing: f32 = b
        .indices
        .chunks_exact(3)
        .map(|t| {
            let [p, q, r] = [t[0], t[1], t[2]].map(|i| b.positions[i as usize]);
            (q - p).cross(r - p).dot(up)
        })
        .sum();
    if facing < 0.0 {
        b.flip_winding();
    }
}

/// The outline and curl of a leaf blade for [`leaf_blade`].
#[derive(Clone, Debug, PartialEq)]
pub struct LeafShape {
    /// Lobes as (direction in degrees from the tip axis +Y, length, half-width in degrees).
    pub lobes: Vec<(f32, f32, f32)>,
    /// Radius of the blade between lobes.
    pub palm: f32,
    /// Grid sectors around the petiole.
    pub sectors: u32,
    /// Grid rings from the petiole to the rim.
    pub rings: u32,
    /// Upward cupping across the blade.
    pub cup: f32,
    /// Downward bend towards the tip.
    pub droop: f32,
}

/// An open leaf blade of about unit size: a polar grid around the petiole (at the origin) with a
/// lobed outline, lying in the XY plane with the tip towards +Y and its front towards +Z,
/// slightly cupped and drooping. sectors (2 rings − 1) triangles. UVs map the unit square onto
/// `[-1, 1]²` of the blade plane.
pub fn leaf_blade(shape: &LeafShape) -> MeshBuilder {
    let radius = |theta: f32| -> f32 {
        // Angle from the tip axis, in degrees within (-180, 180].
        let from_tip = (theta.to_degrees() - 90.0 + 540.0).rem_euclid(360.0) - 180.0;
        // A notch where the petiole joins.
        let notch = (-((180.0 - from_tip.abs()) / 25.0).powi(2)).exp();
        let mut r = shape.palm * (1.0 - 0.6 * notch);
        for &(dir, len, width) in &shape.lobes {
            let t = 1.0 - (from_tip - dir).abs() / width;
            if t > 0.0 {
                r = r.max(shape.palm + (len - shape.palm) * t.powf(1.6));
            }
        }
        r
    };
    polar_sheet(
        shape.sectors,
        shape.rings,
        Vec3::Z,
        |theta, f| {
            let r = radius(theta) * f;
            let (x, y) = (r * theta.cos(), r * theta.sin());
            let z = shape.cup * x * x - shape.droop * y.max(0.0).powi(2);
            Vec3::new(x, y, z)
        },
        |p| Vec2::new(0.5 + 0.5 * p.x, 0.5 - 0.5 * p.y),
    )
}

/// An open strip for a blade of grass: `segments` quads rising along +Y to `height`, tapering
/// from `width` to a tenth of it and bending by `lean` (an offset at the tip, growing with the
/// square of the height). 2 segments triangles; front towards +Z.
pub fn grass_blade(height: f32, width: f32, segments: u32, lean: Vec3) -> MeshBuilder {
    let mut b = MeshBuilder::new();
    for s in 0..=segments {
        let t = s as f32 / segments as f32;
        let centre = Vec3::new(0.0, height * t, 0.0) + lean * t * t;
        let w = width * (1.0 - 0.9 * t) * 0.5;
        b.vertex(centre - Vec3::X * w, Vec3::Z, Vec2::new(0.0, t));
        b.vertex(centre + Vec3::X * w, Vec3::Z, Vec2::new(1.0, t));
    }
    for s in 0..segments {
        let a = 2 * s;
        b.quad(a, a + 1, a + 3, a + 2);
    }
    orient_towards(&mut b, Vec3::Z);
    b.recompute_normals();
    b
}

/// An open height field over `size` (X by Z) centred on the origin, `cells` quads per axis,
/// front facing up. 2 nx nz triangles; UVs in metres times `uv_per_metre`.
pub fn height_field(
    size: Vec2,
    cells: [u32; 2],
    uv_per_metre: f32,
    height: impl Fn(f32, f32) -> f32,
) -> MeshBuilder {
    let mut b = MeshBuilder::new();
    let [nx, nz] = cells;
    for j in 0..=nz {
        for i in 0..=nx {
            let x = -0.5 * size.x + size.x * (i as f32 / nx as f32);
            let z = -0.5 * size.y + size.y * (j as f32 / nz as f32);
            b.vertex(
                Vec3::new(x, height(x, z), z),
                Vec3::Y,
                Vec2::new(x, z) * uv_per_metre,
            );
        }
    }
    let row = nx + 1;
    for j in 0..nz {
        for i in 0..nx {
            let a = j * row + i;
            b.quad(a, a + row, a + row + 1, a + 1);
        }
    }
    orient_towards(&mut b, Vec3::Y);
    b.recompute_normals();
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Welded by position, every directed edge appears once and its reverse once; and the signed
    /// volume is positive (outward winding).
    fn assert_closed(b: &MeshBuilder) {
        let mut id: HashMap<[u32; 3], u32> = HashMap::new();
        let welded: Vec<u32> = b
            .positions
            .iter()
            .map(|p| {
                let next = id.len() as u32;
                *id.entry([p.x, p.y, p.z].map(canonical_bits))
                    .or_insert(next)
            })
            .collect();
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        let mut volume = 0.0f64;
        for t in b.indices.chunks_exact(3) {
            let w = [t[0], t[1], t[2]].map(|i| welded[i as usize]);
            for e in 0..3 {
                *edges.entry((w[e], w[(e + 1) % 3])).or_default() += 1;
            }
            let [p, q, r] = [t[0], t[1], t[2]].map(|i| b.positions[i as usize].as_dvec3());
            volume += p.dot(q.cross(r)) / 6.0;
        }
        for (&(a, c), &count) in &edges {
            assert_eq!(count, 1, "edge {a}->{c} used {count} times");
            assert_eq!(edges.get(&(c, a)), Some(&1), "edge {a}->{c} has no twin");
        }
        assert!(volume > 0.0, "volume {volume}");
    }

    #[test]
    fn closed_primitives_are_closed_and_outward() {
        assert_closed(&cuboid(Vec3::new(1.0, 2.0, 3.0)));
        assert_closed(&subdivided_box(Vec3::new(1.0, 2.0, 0.5), [3, 5, 2]));
        assert_closed(&frustum(1.0, 0.5, 2.0, 12, 3));
        assert_closed(&cone(1.0, 2.0, 8));
        assert_closed(&uv_sphere(1.0, 10, 7));
        let bent = [
            Vec3::ZERO,
            Vec3::new(0.1, 1.0, 0.0),
            Vec3::new(0.4, 1.8, 0.2),
            Vec3::new(1.0, 2.3, 0.3),
        ];
        assert_closed(&tube(&bent, &[0.3, 0.25, 0.2, 0.1], 9));
        let chevron = [
            Vec2::new(-2.0, 0.0),
            Vec2::new(0.0, 1.5),
            Vec2::new(2.0, 0.0),
            Vec2::new(2.0, -0.3),
            Vec2::new(0.0, 1.2),
            Vec2::new(-2.0, -0.3),
        ];
        assert_closed(&extrude(&chevron, 3.0, 2, 30.0));
    }

    #[test]
    fn transformed_and_merged_pieces_stay_closed() {
        let mirror = Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        let merged = MeshBuilder::merge([
            cuboid(Vec3::ONE).transformed(mirror),
            uv_sphere(0.5, 8, 6).transformed(Affine3A::from_translation(Vec3::X * 3.0)),
        ]);
        assert_closed(&merged);
        let lumpy = uv_sphere(1.0, 10, 7).displaced(|p| p * (1.0 + 0.2 * p.x.sin()));
        assert_closed(&lumpy);
    }

    #[test]
    fn triangle_counts_follow_the_documented_formulas() {
        assert_eq!(
            subdivided_box(Vec3::ONE, [3, 5, 2]).triangle_count(),
            4 * (15 + 10 + 6)
        );
        assert_eq!(
            tube(&[Vec3::ZERO, Vec3::Y, Vec3::Y * 2.0], &[1.0; 3], 8).triangle_count(),
            2 * 8 * 2 + 16
        );
        assert_eq!(uv_sphere(1.0, 10, 7).triangle_count(), 2 * 10 * 6);
        assert_eq!(cone(1.0, 1.0, 8).triangle_count(), 16);
        let hex: Vec<Vec2> = (0..6).map(|j| Vec2::from_angle(j as f32)).collect();
        assert_eq!(
            extrude(&hex, 1.0, 3, 10.0).triangle_count(),
            2 * 6 * 3 + 2 * 4
        );
        let leaf = LeafShape {
            lobes: vec![(0.0, 1.0, 40.0)],
            palm: 0.4,
            sectors: 28,
            rings: 4,
            cup: 0.1,
            droop: 0.1,
        };
        assert_eq!(leaf_blade(&leaf).triangle_count(), 28 * 7);
        assert_eq!(grass_blade(1.0, 0.1, 4, Vec3::X).triangle_count(), 8);
    }

    #[test]
    fn a_box_has_hard_edges_and_a_cylinder_a_uv_seam() {
        let box_mesh = cuboid(Vec3::ONE).into_submesh(0);
        assert_eq!(box_mesh.positions.len(), 24);
        let cylinder = frustum(1.0, 1.0, 1.0, 8, 1).into_submesh(0);
        // Side: 2 rows of 9 (seam), caps: 2 × (1 + 8).
        assert_eq!(cylinder.positions.len(), 18 + 18);
    }

    #[test]
    fn open_sheets_face_their_up_direction() {
        let ground = height_field(Vec2::splat(10.0), [4, 4], 1.0, |x, z| 0.1 * x * z);
        let submesh = ground.into_submesh(0);
        let normals = submesh.normals.unwrap_or_default();
        assert!(normals.iter().all(|n| n.y > 0.5));
    }
}
