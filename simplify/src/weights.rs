//! How instances enter the quadrics (Azim et al. 2014, section 6.2, step 1: the world-space
//! plane quadric of eq. 4 pulled back as M^T Q M and summed over instances) without a loop
//! over instances per quadric.
//!
//! For an instance x = A v + t and a local triangle with unit normal n and area a, the world
//! plane pulled back to local space is the local plane scaled by det(A) / |cof(A) n|, and the
//! world area is a |cof(A) n| (cof(A) = det(A) A^-T maps normals). So the pulled-back,
//! area-weighted quadric M^T Q_p M is exactly the local plane quadric times
//!
//! ```text
//! w(n) = det(A)^2 / |cof(A) n|,   with |cof(A) n|^2 = n^T C n,  C = cof(A)^T cof(A).
//! ```
//!
//! Summed over a submesh's instances, the IAS quadric of a triangle is its local plane quadric
//! times W(n) = sum_i w_i(n). Similarities (rotation, uniform scale s, mirror) have C = s^4 I
//! and w = s^4 whatever n is, so they fold into one constant; only non-uniformly scaled
//! instances cost a few multiplies per triangle. Mirrors change nothing: det^2 and C do not
//! see the sign.

use glam::{DMat3, DVec3};
use horizon_mesh::Instance;
use rayon::prelude::*;

/// The instances of one submesh, reduced to what the quadrics and flip tests need.
#[derive(Debug, Clone, Default)]
pub(crate) struct InstanceSet {
    count: usize,
    /// Sum of s^4 over the similarity instances: their plane weight, whatever the normal.
    iso_plane: f64,
    /// Sum of s^2 over the similarity instances: their area factor.
    iso_area: f64,
    /// The other instances.
    aniso: Vec<Anisotropic>,
}

#[derive(Debug, Clone, Copy)]
struct Anisotropic {
    a: DMat3,
    cof: DMat3,
    /// C = cof^T cof, upper triangle c00 c01 c02 c11 c12 c22.
    c: [f64; 6],
    det2: f64,
}

/// Below this relative spread, C counts as a multiple of the identity (f32 rotations carry
/// about 1e-7 of noise).
const ISOTROPY_TOLERANCE: f64 = 1e-5;
/// Beyond this many distinct anisotropic metrics, the flip test uses a cone bound.
const MAX_METRICS: usize = 128;

impl InstanceSet {
    /// Summarises the instances of one submesh.
    pub(crate) fn new<'a>(instances: impl IntoIterator<Item = &'a Instance>) -> Self {
        let mut out = Self::default();
        for inst in instances {
            out.count += 1;
            let a = glam::Mat3::from(inst.transform.matrix3).as_dmat3();
            let cof = cofactor(&a);
            let c = gram(&cof);
            let det = a.determinant();
            let trace = c[0] + c[3] + c[5];
            let mean = trace / 3.0;
            let spread = (c[0] - mean).abs()
                + (c[3] - mean).abs()
                + (c[5] - mean).abs()
                + c[1].abs()
                + c[2].abs()
                + c[4].abs();
            if mean <= 0.0 || !mean.is_finite() {
                continue; // a singular instance draws nothing
            }
            if spread <= ISOTROPY_TOLERANCE * mean {
                out.iso_plane += det * det / mean.sqrt();
                out.iso_area += mean.sqrt();
            } else {
                out.aniso.push(Anisotropic {
                    a,
                    cof,
                    c,
                    det2: det * det,
                });
            }
        }
        out
    }

    /// Number of instances.
    pub(crate) fn count(&self) -> usize {
        self.count
    }

    /// For each triangle (given by an unnormalised normal), the plane weight W(n) and the
    /// area factor sum_i |cof(A_i) n|.
    pub(crate) fn face_weights(&self, normals: &[DVec3]) -> Vec<(f64, f64)> {
        let one = |n2: &DVec3| {
            let n = n2.normalize_or_zero();
            let mut plane = self.iso_plane;
            let mut area = self.iso_area;
            for x in &self.aniso {
                let s = quad_form(&x.c, n).sqrt();
                if s > 0.0 {
                    plane += x.det2 / s;
                    area += s;
                }
            }
            (plane, area)
        };
        if normals.len() * self.aniso.len() > 1 << 16 {
            normals.par_iter().with_min_len(256).map(one).collect()
        } else {
            normals.iter().map(one).collect()
        }
    }

    /// The constraint planes of a boundary or seam edge `a b` of a triangle with unit normal
    /// `n`, summed over instances: each world plane contains the edge and is perpendicular to
    /// the face, weighted by the squared world edge length (area units, like the face
    /// quadrics), and pulled back to local space. Returned as the sum of `w u u^T`.
    pub(crate) fn edge_constraint(&self, a: DVec3, b: DVec3, n: DVec3) -> [f64; 6] {
        let e = b - a;
        let mut u = [0.0; 6];
        let m = e.cross(n);
        if m.length_squared() > 0.0 {
            let m = m.normalize();
            add_outer(&mut u, m, self.iso_plane * e.length_squared());
        }
        for x in &self.aniso {
            let ew = x.a * e;
            let mw = ew.cross(x.cof * n);
            let len = mw.length();
            if len == 0.0 {
                continue;
            }
            let local = x.a.transpose() * (mw / len);
            add_outer(&mut u, local, ew.length_squared());
        }
        u
    }

    /// The test that keeps triangles from flipping in any instance.
    pub(crate) fn flip_guard(&self) -> FlipGuard {
        let mut metrics: Vec<[f64; 6]> = Vec::new();
        if self.iso_area > 0.0 {
            metrics.push([1.0, 0.0, 0.0, 1.0, 0.0, 1.0]);
        }
        let mut worst_condition: f64 = 1.0;
        for x in &self.aniso {
            let trace = x.c[0] + x.c[3] + x.c[5];
            let c = x.c.map(|v| v / trace);
            worst_condition = worst_condition.max(condition(&c));
            if !metrics
                .iter()
                .any(|m| m.iter().zip(&c).all(|(a, b)| (a - b).abs() < 1e-12))
            {
                metrics.push(c);
            }
        }
        if metrics.len() <= MAX_METRICS {
            FlipGuard::Metrics(metrics)
        } else {
            // Wielandt's inequality: for C with condition number k, n0^T C n1 > 0 whenever the
            // angle between n0 and n1 has tan < (k + 1) / ((k - 1) sqrt(k)).
            let k = worst_condition;
            let tan = (k + 1.0) / ((k - 1.0).max(1e-12) * k.sqrt());
            FlipGuard::Cone {
                cos_min: 1.0 / (1.0 + tan * tan).sqrt(),
            }
        }
    }
}

/// Whether a triangle's normal keeps its side through a collapse, in every instance.
#[derive(Debug, Clone)]
pub(crate) enum FlipGuard {
    /// `n0^T C n1 > 0` for each distinct normalised metric C.
    Metrics(Vec<[f64; 6]>),
    /// The angle between `n0` and `n1` stays inside a cone safe for every instance.
    Cone { cos_min: f64 },
}

impl FlipGuard {
    /// True when `n1` (after) is on the same side as `n0` (before) in every instance.
    pub(crate) fn same_side(&self, n0: DVec3, n1: DVec3) -> bool {
        match self {
            FlipGuard::Metrics(ms) => ms.iter().all(|c| bilinear(c, n0, n1) > 0.0),
            FlipGuard::Cone { cos_min } => n0.dot(n1) > cos_min * n0.length() * n1.length(),
        }
    }
}

/// The cofactor matrix, det(A) A^-T, whose columns are cross products of A's columns.
fn cofactor(a: &DMat3) -> DMat3 {
    DMat3::from_cols(
        a.y_axis.cross(a.z_axis),
        a.z_axis.cross(a.x_axis),
        a.x_axis.cross(a.y_axis),
    )
}

/// M^T M, upper triangle.
fn gram(m: &DMat3) -> [f64; 6] {
    let (x, y, z) = (m.x_axis, m.y_axis, m.z_axis);
    [x.dot(x), x.dot(y), x.dot(z), y.dot(y), y.dot(z), z.dot(z)]
}

fn quad_form(c: &[f64; 6], n: DVec3) -> f64 {
    bilinear(c, n, n)
}

fn bilinear(c: &[f64; 6], a: DVec3, b: DVec3) -> f64 {
    a.x * (c[0] * b.x + c[1] * b.y + c[2] * b.z)
        + a.y * (c[1] * b.x + c[3] * b.y + c[4] * b.z)
        + a.z * (c[2] * b.x + c[4] * b.y + c[5] * b.z)
}

fn add_outer(u: &mut [f64; 6], v: DVec3, w: f64) {
    u[0] += w * v.x * v.x;
    u[1] += w * v.x * v.y;
    u[2] += w * v.x * v.z;
    u[3] += w * v.y * v.y;
    u[4] += w * v.y * v.z;
    u[5] += w * v.z * v.z;
}

/// Condition number (largest over smallest eigenvalue) of a symmetric positive definite 3x3
/// matrix, by the closed-form trigonometric eigenvalue solution.
fn condition(c: &[f64; 6]) -> f64 {
    let (a, b, d, e, f, g) = (c[0], c[3], c[5], c[1], c[4], c[2]);
    let p1 = e * e + g * g + f * f;
    let q = (a + b + d) / 3.0;
    let p2 = (a - q).powi(2) + (b - q).powi(2) + (d - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if p <= 0.0 {
        return 1.0;
    }
    let m = [(a - q) / p, e / p, g / p, (b - q) / p, f / p, (d - q) / p];
    let det = m[0] * (m[3] * m[5] - m[4] * m[4]) - m[1] * (m[1] * m[5] - m[4] * m[2])
        + m[2] * (m[1] * m[4] - m[3] * m[2]);
    let r = (det / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    if smallest <= 0.0 {
        f64::INFINITY
    } else {
        largest / smallest
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Affine3A, Quat, Vec3};

    fn weight_by_brute_force(inst: &Affine3A, n: DVec3) -> f64 {
        // Two tangent points of the local plane through the origin, mapped to world space.
        let t1 = n.any_orthonormal_vector();
        let t2 = n.cross(t1);
        let a = glam::Mat3::from(inst.matrix3).as_dmat3();
        let (w1, w2) = (a * t1, a * t2);
        let world_area = w1.cross(w2).length(); // area of the unit square's image
        let nw = w1.cross(w2).normalize();
        // Squared distance of a local point at height 1 above the plane, after mapping.
        let h = (a * n).dot(nw);
        world_area * h * h
    }

    #[test]
    fn the_folded_weight_equals_the_pulled_back_quadric() {
        let inst = Affine3A::from_scale_rotation_translation(
            Vec3::new(2.0, -0.5, 3.0),
            Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 0.7),
            Vec3::new(5.0, 1.0, -2.0),
        );
        let set = InstanceSet::new([&Instance {
            submesh: 0,
            transform: inst,
        }]);
        for n in [DVec3::X, DVec3::new(0.3, -0.4, 0.866).normalize(), DVec3::Z] {
            let (w, _) = set.face_weights(&[n])[0];
            let expected = weight_by_brute_force(&inst, n);
            assert!((w - expected).abs() < 1e-9 * expected, "{w} vs {expected}");
        }
    }

    #[test]
    fn similarities_fold_into_a_constant() {
        let inst = Affine3A::from_scale_rotation_translation(
            Vec3::new(-2.0, 2.0, 2.0),
            Quat::from_rotation_y(0.4),
            Vec3::ZERO,
        );
        let set = InstanceSet::new([&Instance {
            submesh: 0,
            transform: inst,
        }]);
        assert!(set.aniso.is_empty());
        assert!((set.iso_plane - 16.0).abs() < 1e-4, "{}", set.iso_plane);
    }

    #[test]
    fn condition_number_of_a_diagonal_metric() {
        assert!((condition(&[4.0, 0.0, 0.0, 1.0, 0.0, 2.0]) - 4.0).abs() < 1e-9);
        assert!((condition(&[1.0, 0.0, 0.0, 1.0, 0.0, 1.0]) - 1.0).abs() < 1e-9);
    }
}
