//! A small software renderer for the Table 1 calibration (Azim et al. 2014, section 5.1: "we
//! render each model as images from three mutually orthogonal directions and also store smaller
//! versions of these images that are downsampled by powers of two").
//!
//! Each model is first put in a frame: area-weighted centroid at the origin and bounding sphere
//! of radius 1, with either its own axes ([`CanonicalFrame::unrotated`], what the calibration
//! uses: a model and its variants share their base's frame) or its principal axes
//! ([`CanonicalFrame::of`], the frame deduplication aligns distinct models in). The views are
//! orthographic along the axes, with the unit disk filling the image, a z-buffer, base colour
//! x texture x vertex colour, and a two-sided headlight so shape shows in the image, not only
//! silhouette.

use glam::{Mat3, Vec2, Vec3, Vec4};
use horizon_mesh::{InstancedMesh, Wrap};
use image::RgbaImage;

use crate::DescriptorError;

/// An RGB image with channels in [0, 1] (sRGB-encoded), row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width and height in pixels (images are square).
    pub size: usize,
    /// `size * size` pixels.
    pub pixels: Vec<Vec3>,
}

impl Image {
    /// A square image filled with `background`.
    pub fn new(size: usize, background: Vec3) -> Self {
        Self {
            size,
            pixels: vec![background; size * size],
        }
    }

    /// The image mirrored left-right (`horizontal`) and/or top-bottom (`vertical`).
    pub fn mirrored(&self, horizontal: bool, vertical: bool) -> Self {
        let n = self.size;
        let mut pixels = Vec::with_capacity(n * n);
        for y in 0..n {
            let sy = if vertical { n - 1 - y } else { y };
            for x in 0..n {
                let sx = if horizontal { n - 1 - x } else { x };
                pixels.push(self.pixels[sy * n + sx]);
            }
        }
        Self { size: n, pixels }
    }

    /// The image at half the size (floor), each pixel the mean of a 2x2 block.
    pub fn halved(&self) -> Self {
        let size = self.size / 2;
        let mut pixels = Vec::with_capacity(size * size);
        for y in 0..size {
            for x in 0..size {
                let at = |dx: usize, dy: usize| self.pixels[(2 * y + dy) * self.size + 2 * x + dx];
                pixels.push((at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1)) * 0.25);
            }
        }
        Self { size, pixels }
    }
}

/// A model ready to draw: expanded triangles in the canonical frame, with their shading inputs.
#[derive(Clone, Debug)]
pub struct Scene {
    triangles: Vec<SceneTriangle>,
    textures: Vec<Option<RgbaImage>>,
    wraps: Vec<(Wrap, Wrap)>,
}

#[derive(Clone, Debug)]
struct SceneTriangle {
    corners: [Vec3; 3],
    uvs: [Vec2; 3],
    colors: [Vec4; 3],
    texture: Option<usize>,
}

/// The background, a mid grey, so black and white models both stand out.
pub const BACKGROUND: Vec3 = Vec3::splat(0.5);

impl Scene {
    /// Expands `mesh` into its canonical frame (see the module comment).
    pub fn new(mesh: &InstancedMesh) -> Result<Self, DescriptorError> {
        Self::with_frame(mesh, &CanonicalFrame::of(mesh)?)
    }

    /// Expands `mesh` into a given frame (for example its base model's, so a variant and its
    /// base share one pose).
    pub fn with_frame(
        mesh: &InstancedMesh,
        frame: &CanonicalFrame,
    ) -> Result<Self, DescriptorError> {
        if mesh.expanded_triangle_count() == 0 {
            return Err(DescriptorError::Empty);
        }
        let textures = mesh
            .textures
            .iter()
            .map(|t| t.decode().ok())
            .collect::<Vec<_>>();
        let wraps = mesh.textures.iter().map(|t| (t.wrap_u, t.wrap_v)).collect();
        let mut triangles = Vec::new();
        for instance in &mesh.instances {
            let sub = &mesh.submeshes[instance.submesh];
            let material = sub.material.and_then(|m| mesh.materials.get(m));
            let factor = material.map_or(Vec4::ONE, |m| m.base_color_factor);
            let texture = material.and_then(|m| m.base_color_texture);
            let mirrored = instance.transform.matrix3.determinant() < 0.0;
            for tri in sub.indices.chunks_exact(3) {
                let mut ids = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
                if mirrored {
                    ids.swap(1, 2);
                }
                let corners =
                    ids.map(|i| frame.apply(instance.transform.transform_point3(sub.positions[i])));
                if !corners.iter().all(|c| c.is_finite()) {
                    continue;
                }
                let uvs = ids.map(|i| {
                    let uv = sub.uvs.as_ref().map_or(Vec2::ZERO, |u| u[i]);
                    texture
                        .and_then(|t| t.transform)
                        .map_or(uv, |transform| transform.apply(uv))
                });
                let colors = ids.map(|i| factor * sub.colors.as_ref().map_or(Vec4::ONE, |c| c[i]));
                triangles.push(SceneTriangle {
                    corners,
                    uvs,
                    colors,
                    texture: texture.map(|t| t.texture),
                });
            }
        }
        Ok(Self {
            triangles,
            textures,
            wraps,
        })
    }

    /// Renders the orthographic view along `axis` (0, 1 or 2) at `size` x `size` pixels, seen
    /// from the + side of the axis when `from_positive`, else from the - side. The image's
    /// right and up are the next two axes in cyclic order in both cases, so flipping an axis of
    /// the model is the same as viewing from the other side or mirroring the image (see
    /// [`Image::mirrored`]). The light is a headlight, so shading is unchanged by such flips.
    pub fn render(&self, axis: usize, from_positive: bool, size: usize) -> Image {
        let mut image = Image::new(size, BACKGROUND);
        let mut depth = vec![f32::NEG_INFINITY; size * size];
        let (u_axis, v_axis) = ((axis + 1) % 3, (axis + 2) % 3);
        let toward = if from_positive { 1.0 } else { -1.0 };
        let half = size as f32 * 0.5;
        for tri in &self.triangles {
            let [a, b, c] = tri.corners;
            let normal = (b - a).cross(c - a);
            if normal.length_squared() <= 0.0 {
                continue;
            }
            let shade = 0.35 + 0.65 * normal.normalize()[axis].abs();
            let screen = tri.corners.map(|p| {
                Vec3::new(
                    (p[u_axis] + 1.0) * half,
                    (1.0 - p[v_axis]) * half,
                    toward * p[axis],
                )
            });
            self.raster(&mut image, &mut depth, tri, screen, shade);
        }
        image
    }

    fn raster(
        &self,
        image: &mut Image,
        depth: &mut [f32],
        tri: &SceneTriangle,
        s: [Vec3; 3],
        shade: f32,
    ) {
        let size = image.size;
        let area = edge(s[0], s[1], s[2]);
        if area.abs() <= f32::EPSILON {
            return;
        }
        let min = s[0].min(s[1]).min(s[2]);
        let max = s[0].max(s[1]).max(s[2]);
        let x0 = (min.x.floor().max(0.0)) as usize;
        let y0 = (min.y.floor().max(0.0)) as usize;
        let x1 = (max.x.ceil().min(size as f32)) as usize;
        let y1 = (max.y.ceil().min(size as f32)) as usize;
        for y in y0..y1 {
            for x in x0..x1 {
                let p = Vec3::new(x as f32 + 0.5, y as f32 + 0.5, 0.0);
                let w0 = edge(s[1], s[2], p) / area;
                let w1 = edge(s[2], s[0], p) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = w0 * s[0].z + w1 * s[1].z + w2 * s[2].z;
                let at = y * size + x;
                if z <= depth[at] {
                    continue;
                }
                depth[at] = z;
                let color = w0 * tri.colors[0] + w1 * tri.colors[1] + w2 * tri.colors[2];
                let mut linear = color.truncate();
                if let Some(t) = tri.texture {
                    let uv = w0 * tri.uvs[0] + w1 * tri.uvs[1] + w2 * tri.uvs[2];
                    linear *= self.sample(t, uv);
                }
                image.pixels[at] = (linear * shade).clamp(Vec3::ZERO, Vec3::ONE).map(to_srgb);
            }
        }
    }

    /// Nearest-texel lookup in linear colour, honouring the wrap modes; white when the texture
    /// is missing or undecodable.
    fn sample(&self, texture: usize, uv: Vec2) -> Vec3 {
        let Some(Some(img)) = self.textures.get(texture) else {
            return Vec3::ONE;
        };
        let (wu, wv) = self.wraps[texture];
        let (w, h) = img.dimensions();
        let x = wrap_texel(uv.x, w, wu);
        let y = wrap_texel(uv.y, h, wv);
        let p = img.get_pixel(x, y).0;
        Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32).map(|c| to_linear(c / 255.0))
    }
}

/// The renders of one model: for each of the six views (axis 0, 1, 2, each from the positive
/// then the negative side: index `2 * axis + side`), the image at `base_size` and every
/// halving down to `min_size`, largest first.
pub fn render_pyramid(scene: &Scene, base_size: usize, min_size: usize) -> Vec<Vec<Image>> {
    (0..6)
        .map(|view| {
            let mut levels = vec![scene.render(view / 2, view % 2 == 0, base_size)];
            while let Some(last) = levels.last() {
                if last.size / 2 < min_size.max(1) {
                    break;
                }
                let next = last.halved();
                levels.push(next);
            }
            levels
        })
        .collect()
}

fn edge(a: Vec3, b: Vec3, p: Vec3) -> f32 {
    (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x)
}

fn wrap_texel(coord: f32, extent: u32, wrap: Wrap) -> u32 {
    let coord = if coord.is_finite() { coord } else { 0.0 };
    let t = match wrap {
        Wrap::Repeat => coord - coord.floor(),
        Wrap::MirroredRepeat => {
            let period = coord.rem_euclid(2.0);
            if period > 1.0 {
                2.0 - period
            } else {
                period
            }
        }
        Wrap::ClampToEdge => coord.clamp(0.0, 1.0),
    };
    ((t * extent as f32) as u32).min(extent.saturating_sub(1))
}

fn to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// The frame deduplication aligns models in: centroid, principal axes, unit bounding sphere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CanonicalFrame {
    /// Area-weighted centroid of the expanded surface.
    pub centroid: Vec3,
    /// Rows are the principal axes, largest variance first, signs fixed by the third moment,
    /// right-handed.
    pub axes: Mat3,
    /// 1 / the largest distance from the centroid to a vertex.
    pub scale: f32,
}

impl CanonicalFrame {
    /// The canonical frame of `mesh`'s expanded surface.
    pub fn of(mesh: &InstancedMesh) -> Result<Self, DescriptorError> {
        let mut area_sum = 0.0f64;
        let mut centroid = glam::DVec3::ZERO;
        let mut second = [[0.0f64; 3]; 3];
        let mut points = Vec::new();
        for instance in &mesh.instances {
            let sub = &mesh.submeshes[instance.submesh];
            for tri in sub.indices.chunks_exact(3) {
                let p = [tri[0], tri[1], tri[2]].map(|i| {
                    instance
                        .transform
                        .transform_point3(sub.positions[i as usize])
                });
                if !p.iter().all(|c| c.is_finite()) {
                    continue;
                }
                points.extend_from_slice(&p);
                let area = 0.5 * f64::from((p[1] - p[0]).cross(p[2] - p[0]).length());
                if area <= 0.0 {
                    continue;
                }
                let d = p.map(|c| c.as_dvec3());
                centroid += area * (d[0] + d[1] + d[2]) / 3.0;
                area_sum += area;
                // Second moment of a triangle: area/12 * (sum p p^T + (sum p)(sum p)^T).
                let s = d[0] + d[1] + d[2];
                for (r, row) in second.iter_mut().enumerate() {
                    for (c, cell) in row.iter_mut().enumerate() {
                        let pp: f64 = d.iter().map(|v| v[r] * v[c]).sum();
                        *cell += area / 12.0 * (pp + s[r] * s[c]);
                    }
                }
            }
        }
        if area_sum <= 0.0 || !area_sum.is_finite() {
            return Err(DescriptorError::Empty);
        }
        let centroid = centroid / area_sum;
        let mut cov = [[0.0f64; 3]; 3];
        for r in 0..3 {
            for c in 0..3 {
                cov[r][c] = second[r][c] / area_sum - centroid[r] * centroid[c];
            }
        }
        let c = centroid.as_vec3();
        let axes = fix_signs(principal_axes(cov), &points, c);
        let radius = points
            .iter()
            .map(|p| (*p - c).length())
            .fold(0.0f32, f32::max);
        if radius <= 0.0 || !radius.is_finite() {
            return Err(DescriptorError::Empty);
        }
        Ok(Self {
            centroid: c,
            axes,
            scale: 1.0 / radius,
        })
    }

    /// The frame without the rotation: centroid and unit bounding sphere, the model's own axes.
    pub fn unrotated(mesh: &InstancedMesh) -> Result<Self, DescriptorError> {
        Ok(Self {
            axes: Mat3::IDENTITY,
            ..Self::of(mesh)?
        })
    }

    /// A world point in the frame.
    pub fn apply(&self, p: Vec3) -> Vec3 {
        self.axes * ((p - self.centroid) * self.scale)
    }
}

/// PCA leaves each axis's sign free. Fix the first two so the surface's third moment along
/// them is positive (the heavier tail points +), and the third by the right-hand rule, so two
/// near-duplicates land in the same pose without trying flips.
fn fix_signs(axes: Mat3, corners: &[Vec3], centroid: Vec3) -> Mat3 {
    let mut rows = [axes.row(0), axes.row(1)];
    for row in &mut rows {
        let mut skew = 0.0f64;
        for tri in corners.chunks_exact(3) {
            let area = f64::from(0.5 * (tri[1] - tri[0]).cross(tri[2] - tri[0]).length());
            let t = f64::from(row.dot((tri[0] + tri[1] + tri[2]) / 3.0 - centroid));
            skew += area * t * t * t;
        }
        if skew < 0.0 {
            *row = -*row;
        }
    }
    Mat3::from_cols(rows[0], rows[1], rows[0].cross(rows[1])).transpose()
}

/// Eigenvectors of a symmetric 3x3 matrix by Jacobi rotations, as the rows of a right-handed
/// rotation, largest eigenvalue first.
fn principal_axes(mut a: [[f64; 3]; 3]) -> Mat3 {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..50 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off < 1e-18 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in a.iter_mut() {
                let (x, y) = (row[p], row[q]);
                row[p] = c * x - s * y;
                row[q] = s * x + c * y;
            }
            let (rp, rq) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
            a[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
            for row in v.iter_mut() {
                let (x, y) = (row[p], row[q]);
                row[p] = c * x - s * y;
                row[q] = s * x + c * y;
            }
        }
    }
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| a[j][j].total_cmp(&a[i][i]));
    let column = |k: usize| Vec3::new(v[0][k] as f32, v[1][k] as f32, v[2][k] as f32);
    let e0 = column(order[0]);
    let e1 = column(order[1]);
    let e2 = e0.cross(e1);
    Mat3::from_cols(e0, e1, e2).transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn principal_axes_of_a_diagonal_matrix_sort_by_variance() {
        let axes = principal_axes([[1.0, 0.0, 0.0], [0.0, 9.0, 0.0], [0.0, 0.0, 4.0]]);
        assert!((axes.row(0).abs() - Vec3::Y).length() < 1e-5);
        assert!((axes.row(1).abs() - Vec3::Z).length() < 1e-5);
        assert!((axes.determinant() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn principal_axes_of_a_rotated_matrix_recover_the_rotation() {
        let r = Mat3::from_rotation_z(0.3) * Mat3::from_rotation_x(0.7);
        let d = Mat3::from_diagonal(Vec3::new(5.0, 2.0, 1.0));
        let m = r * d * r.transpose();
        let a = [0, 1, 2].map(|i| [0, 1, 2].map(|j| f64::from(m.col(j)[i])));
        let axes = principal_axes(a);
        for k in 0..3 {
            assert!(axes.row(k).dot(r.col(k)).abs() > 0.9999, "axis {k}");
        }
    }

    #[test]
    fn halving_averages_blocks() {
        let mut img = Image::new(3, Vec3::ZERO);
        img.pixels[0] = Vec3::ONE;
        let half = img.halved();
        assert_eq!(half.size, 1);
        assert!((half.pixels[0] - Vec3::splat(0.25)).length() < 1e-6);
    }

    #[test]
    fn wrap_modes_fold_coordinates() {
        assert_eq!(wrap_texel(1.25, 4, Wrap::Repeat), 1);
        assert_eq!(wrap_texel(1.25, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap_texel(-3.0, 4, Wrap::ClampToEdge), 0);
        assert_eq!(wrap_texel(f32::NAN, 4, Wrap::Repeat), 0);
    }
}
