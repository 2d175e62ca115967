//! Decomposition of affine transforms for glTF export.
//!
//! glTF requires every node transform to be decomposable into translation, rotation and scale
//! (glTF 2.0 spec, 3.5.3), and EXT_mesh_gpu_instancing stores instances as TRS. A transform with
//! shear (a rotated child of a non-uniformly scaled parent) is not TRS; it is written as two
//! nodes through the singular value decomposition `L = U * S * V^T`: a parent `T * U * S` and a
//! child `V^T`, both plain TRS. Mirrors become a negative scale.

use glam::{Affine3A, DMat3, DQuat, DVec3, Quat, Vec3};

/// Translation, rotation and (possibly negative) scale: `T * R * S`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trs {
    /// Translation.
    pub translation: Vec3,
    /// Unit quaternion rotation.
    pub rotation: Quat,
    /// Scale along the local axes; one negative component encodes a mirror.
    pub scale: Vec3,
}

impl Trs {
    /// The affine transform `T * R * S`.
    pub fn to_affine(&self) -> Affine3A {
        Affine3A::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

/// The longest image of a unit axis under `m`'s linear part: the radius factor of a sphere's
/// image, exact for TRS transforms (orthogonal axes, mirrors included); under shear the
/// sphere can reach up to sqrt(3) times further along a diagonal.
pub fn max_axis_scale(m: &Affine3A) -> f32 {
    let l = m.matrix3;
    l.x_axis
        .length()
        .max(l.y_axis.length())
        .max(l.z_axis.length())
}

/// Relative tolerance for accepting a decomposition: the rebuilt linear part may differ from
/// the original by this fraction of its largest entry. f32 storage already rounds at ~6e-8, so
/// 1e-6 accepts every transform that really is TRS and refuses visible shear.
const TRS_TOLERANCE: f64 = 1e-6;

/// Splits `m` into `T * R * S` if it has no shear, within [`TRS_TOLERANCE`].
pub fn decompose_trs(m: &Affine3A) -> Option<Trs> {
    let l = glam::Mat3::from(m.matrix3).as_dmat3();
    let mut scale = DVec3::new(l.x_axis.length(), l.y_axis.length(), l.z_axis.length());
    let largest = scale.max_element();
    // (written so that NaN also takes this branch)
    if scale.min_element().partial_cmp(&(largest * 1e-12)) != Some(std::cmp::Ordering::Greater) {
        // A zero scale leaves the rotation undetermined; a matrix node expresses it fine.
        return None;
    }
    if l.determinant() < 0.0 {
        scale.x = -scale.x;
    }
    let r = DMat3::from_cols(l.x_axis / scale.x, l.y_axis / scale.y, l.z_axis / scale.z);
    let rotation = DQuat::from_mat3(&r).normalize();
    let rebuilt = DMat3::from_quat(rotation) * DMat3::from_diagonal(scale);
    let error = (rebuilt - l)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |a, e| a.max(e.abs()));
    let magnitude = l.to_cols_array().iter().fold(0.0f64, |a, e| a.max(e.abs()));
    let trs = Trs {
        translation: Vec3::from(m.translation),
        rotation: rotation.as_quat(),
        scale: scale.as_vec3(),
    };
    // Column lengths of entries near f32::MAX can overflow f32 on the way back.
    let finite = trs.scale.is_finite() && trs.rotation.is_finite();
    (finite && error <= TRS_TOLERANCE * magnitude).then_some(trs)
}

/// Splits any affine `m` into a parent `T * U * S` and a child rotation `V^T` with
/// `m = parent * child`, both TRS; `None` if a singular value overflows f32.
pub fn decompose_svd(m: &Affine3A) -> Option<(Trs, Quat)> {
    let l = glam::Mat3::from(m.matrix3).as_dmat3();
    let (mut u, mut sigma, mut v) = svd3(&l);
    // Make both rotations proper; a reflection moves into the sign of one scale.
    if v.determinant() < 0.0 {
        v.z_axis = -v.z_axis;
        sigma.z = -sigma.z;
    }
    if u.determinant() < 0.0 {
        u.z_axis = -u.z_axis;
        sigma.z = -sigma.z;
    }
    let parent = Trs {
        translation: Vec3::from(m.translation),
        rotation: DQuat::from_mat3(&u).normalize().as_quat(),
        scale: sigma.as_vec3(),
    };
    let child = DQuat::from_mat3(&v.transpose()).normalize().as_quat();
    let finite = parent.scale.is_finite() && parent.rotation.is_finite() && child.is_finite();
    finite.then_some((parent, child))
}

/// Singular value decomposition of a 3x3 matrix, `l = u * diag(sigma) * v^T`, through the
/// symmetric eigenproblem of `l^T l` solved by cyclic Jacobi rotations.
fn svd3(l: &DMat3) -> (DMat3, DVec3, DMat3) {
    let (v, eigen) = symmetric_eigen(&(l.transpose() * *l));
    let sigma = eigen.map(|e| e.max(0.0).sqrt());
    // Columns of u are l * v_i / sigma_i; complete the basis where sigma vanishes.
    let tiny = sigma.max_element() * 1e-9;
    let mut cols = [DVec3::ZERO; 3];
    let vc = [v.x_axis, v.y_axis, v.z_axis];
    for i in 0..3 {
        if sigma[i] > tiny {
            cols[i] = (*l * vc[i]) / sigma[i];
        }
    }
    for i in 0..3 {
        if sigma[i] <= tiny {
            let (a, b) = (cols[(i + 1) % 3], cols[(i + 2) % 3]);
            cols[i] = if a != DVec3::ZERO && b != DVec3::ZERO {
                a.cross(b).normalize()
            } else if a != DVec3::ZERO {
                a.any_orthonormal_vector()
            } else if b != DVec3::ZERO {
                b.any_orthonormal_vector()
            } else {
                DVec3::AXES[i]
            };
        }
    }
    (DMat3::from_cols(cols[0], cols[1], cols[2]), sigma, v)
}

/// Eigenvectors (as columns) and eigenvalues of a symmetric 3x3 matrix, by cyclic Jacobi.
fn symmetric_eigen(a: &DMat3) -> (DMat3, DVec3) {
    let mut m = a.to_cols_array_2d();
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    // Each sweep zeroes the three off-diagonal pairs; convergence is quadratic, so a few dozen
    // sweeps reach f64 precision for any input.
    for _ in 0..50 {
        let off = m[0][1].abs() + m[0][2].abs() + m[1][2].abs();
        if off <= 1e-300 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if m[p][q].abs() <= 1e-300 {
                continue;
            }
            let theta = (m[q][q] - m[p][p]) / (2.0 * m[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // m <- J^T m J with J the rotation in the (p, q) plane.
            for row in &mut m {
                let (mkp, mkq) = (row[p], row[q]);
                row[p] = c * mkp - s * mkq;
                row[q] = s * mkp + c * mkq;
            }
            let (mp, mq) = (m[p], m[q]);
            m[p] = std::array::from_fn(|k| c * mp[k] - s * mq[k]);
            m[q] = std::array::from_fn(|k| s * mp[k] + c * mq[k]);
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    // v holds eigenvectors as columns in row-major storage; glam wants columns.
    let col = |j: usize| DVec3::new(v[0][j], v[1][j], v[2][j]);
    (
        DMat3::from_cols(col(0), col(1), col(2)),
        DVec3::new(m[0][0], m[1][1], m[2][2]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn max_difference(a: &Affine3A, b: &Affine3A) -> f32 {
        let (a, b) = (glam::Mat4::from(*a), glam::Mat4::from(*b));
        (a - b)
            .to_cols_array()
            .iter()
            .fold(0.0f32, |m, e| m.max(e.abs()))
    }

    #[test]
    fn mirrored_trs_decomposes_with_a_negative_scale() {
        // A mirror across x is scale (-1, 1, 1): determinant -1, no shear.
        let m = Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        let trs = decompose_trs(&m).expect("a mirror is TRS");
        assert!(trs.scale.x < 0.0);
        assert!(max_difference(&trs.to_affine(), &m) < 1e-6);
    }

    #[test]
    fn shear_is_not_trs_but_splits_into_two() {
        // x' = x + y is a shear: no T * R * S produces it.
        let m = Affine3A::from_mat3(glam::Mat3::from_cols(
            Vec3::X,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::Z,
        ));
        assert!(decompose_trs(&m).is_none());
        let (parent, child) = decompose_svd(&m).expect("finite");
        let rebuilt = parent.to_affine() * Affine3A::from_quat(child);
        assert!(max_difference(&rebuilt, &m) < 1e-5);
    }

    proptest! {
        #[test]
        fn svd_rebuilds_any_affine(cols in prop::array::uniform12(-10.0f32..10.0)) {
            let m = Affine3A::from_cols_array(&cols);
            let (parent, child) = decompose_svd(&m).expect("finite");
            let rebuilt = parent.to_affine() * Affine3A::from_quat(child);
            let scale = glam::Mat4::from(m).to_cols_array().iter().fold(1.0f32, |a, e| a.max(e.abs()));
            prop_assert!(max_difference(&rebuilt, &m) <= 1e-5 * scale);
        }

        #[test]
        fn trs_round_trips(t in prop::array::uniform3(-100.0f32..100.0),
                           axis in prop::array::uniform3(-1.0f32..1.0),
                           angle in -3.0f32..3.0,
                           s in prop::array::uniform3(0.1f32..10.0),
                           mirror in any::<bool>()) {
            let axis = Vec3::from(axis).try_normalize().unwrap_or(Vec3::Y);
            let mut scale = Vec3::from(s);
            if mirror { scale.y = -scale.y; }
            let m = Affine3A::from_scale_rotation_translation(scale, Quat::from_axis_angle(axis, angle), Vec3::from(t));
            let trs = decompose_trs(&m).expect("built from TRS");
            let magnitude = glam::Mat4::from(m).to_cols_array().iter().fold(1.0f32, |a, e| a.max(e.abs()));
            prop_assert!(max_difference(&trs.to_affine(), &m) <= 1e-5 * magnitude);
        }
    }
}
