//! Principal-axis frames and the alignment of a replacement model onto the model it replaces
//! (core paper section 5.1: "aligned to its twin by PCA axes"; `DESIGN.md`, "Dedup
//! thresholds": try the sign flips and keep the best).
//!
//! A frame is the area-weighted centroid, the eigenvectors of the area-weighted covariance of
//! the surface (largest variance first) and the RMS radius. Zernike descriptors are scale
//! invariant, so twins may differ in size: the alignment scales by the ratio of RMS radii.
//! The eigenvectors' signs are arbitrary, so each of the eight sign patterns is scored by the
//! mean distance from the replacement's surface samples to the replaced model's, and the
//! best kept (a mirroring pattern is allowed: the exporter keeps mirrored instances).

use glam::{Affine3A, DMat3, DVec3, Mat3A, Vec3, Vec3A};
use horizon_mesh::InstancedMesh;

/// Surface samples kept per model for scoring alignments.
const SAMPLES: usize = 192;

/// A model's principal frame and a few surface samples.
#[derive(Clone, Debug, PartialEq)]
pub struct PcaFrame {
    /// Area-weighted centroid.
    pub centroid: Vec3,
    /// Principal axes as columns, largest variance first, right-handed.
    pub axes: Mat3A,
    /// Root-mean-square distance of the surface from the centroid.
    pub rms_radius: f32,
    /// Area-weighted surface samples (triangle centroids), in model space.
    pub samples: Vec<Vec3>,
}

impl PcaFrame {
    /// The frame of `mesh` as drawn (every instance), or `None` for a mesh without area.
    pub fn of(mesh: &InstancedMesh) -> Option<Self> {
        let expanded = mesh.expand();
        let tris: Vec<(Vec3, f64)> = expanded
            .indices
            .chunks_exact(3)
            .map(|t| {
                let [a, b, c] = [0, 1, 2].map(|k| expanded.positions[t[k] as usize]);
                (
                    (a + b + c) / 3.0,
                    f64::from((b - a).cross(c - a).length() * 0.5),
                )
            })
            .filter(|(_, w)| *w > 0.0 && w.is_finite())
            .collect();
        let total: f64 = tris.iter().map(|(_, w)| w).sum();
        if total <= 0.0 {
            return None;
        }
        let centroid: DVec3 = tris.iter().map(|(p, w)| p.as_dvec3() * *w).sum::<DVec3>() / total;
        let mut cov = DMat3::ZERO;
        for (p, w) in &tris {
            let d = p.as_dvec3() - centroid;
            cov += DMat3::from_cols(d * d.x, d * d.y, d * d.z) * *w;
        }
        cov *= 1.0 / total;
        let rms_radius = (cov.x_axis.x + cov.y_axis.y + cov.z_axis.z).max(0.0).sqrt() as f32;
        let axes = principal_axes(cov);
        Some(Self {
            centroid: centroid.as_vec3(),
            axes,
            rms_radius,
            samples: samples(&tris, total),
        })
    }

    /// The transform that places the model of frame `replacement` where the model of this
    /// frame is: centroid onto centroid, axes onto axes (best of the eight sign flips), RMS
    /// radius onto RMS radius. Also returns its score: the mean distance from the moved
    /// replacement samples to this model's nearest samples, relative to this RMS radius.
    pub fn align(&self, replacement: &PcaFrame) -> (Affine3A, f32) {
        let scale = if replacement.rms_radius > 0.0 {
            self.rms_radius / replacement.rms_radius
        } else {
            1.0
        };
        let mut best = (Affine3A::IDENTITY, f32::INFINITY);
        for flip in 0..8u32 {
            let signs = Vec3A::new(
                if flip & 1 == 0 { 1.0 } else { -1.0 },
                if flip & 2 == 0 { 1.0 } else { -1.0 },
                if flip & 4 == 0 { 1.0 } else { -1.0 },
            );
            let flipped = Mat3A::from_cols(
                self.axes.x_axis * signs.x,
                self.axes.y_axis * signs.y,
                self.axes.z_axis * signs.z,
            );
            // model-space of the replacement -> its PCA frame -> this PCA frame -> this model.
            let rotation = flipped * replacement.axes.transpose();
            let linear = rotation * scale;
            let translation =
                Vec3A::from(self.centroid) - linear * Vec3A::from(replacement.centroid);
            let t = Affine3A::from_mat3_translation(linear.into(), translation.into());
            let score = mean_nearest(&replacement.samples, &t, &self.samples)
                / self.rms_radius.max(f32::MIN_POSITIVE);
            if score < best.1 {
                best = (t, score);
            }
        }
        best
    }
}

/// Eigenvectors of a symmetric 3x3 matrix by Jacobi rotations, as columns sorted by
/// decreasing eigenvalue, made right-handed.
fn principal_axes(m: DMat3) -> Mat3A {
    let mut a = m.to_cols_array_2d();
    let mut v = [[1.0f64, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off < 1e-15 {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-30 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // a' = J^T a J with J the rotation in the (p, q) plane.
            for row in &mut a {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = c * row_p[k] - s * row_q[k];
                a[q][k] = s * row_p[k] + c * row_q[k];
            }
            for row in &mut v {
                let vp = row[p];
                let vq = row[q];
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| a[j][j].total_cmp(&a[i][i]));
    let col = |k: usize| Vec3::new(v[0][k] as f32, v[1][k] as f32, v[2][k] as f32);
    let x = col(order[0]).normalize_or(Vec3::X);
    let y = col(order[1]).normalize_or(Vec3::Y);
    let z = x.cross(y).normalize_or(Vec3::Z);
    let y = z.cross(x);
    Mat3A::from_cols(x.into(), y.into(), z.into())
}

/// Up to [`SAMPLES`] triangle centroids, picked evenly along the cumulative area so that big
/// triangles are sampled more.
fn samples(tris: &[(Vec3, f64)], total: f64) -> Vec<Vec3> {
    let n = SAMPLES.min(tris.len());
    let mut out = Vec::with_capacity(n);
    let mut acc = 0.0;
    let mut next = 0;
    for (p, w) in tris {
        acc += w;
        while next < n && (next as f64 + 0.5) * total / n as f64 <= acc {
            out.push(*p);
            next += 1;
        }
    }
    if out.is_empty() {
        out.extend(tris.iter().take(n).map(|(p, _)| *p));
    }
    out
}

/// Mean over `from` (moved by `t`) of the distance to the nearest point of `to`.
fn mean_nearest(from: &[Vec3], t: &Affine3A, to: &[Vec3]) -> f32 {
    if from.is_empty() || to.is_empty() {
        return f32::INFINITY;
    }
    let sum: f32 = from
        .iter()
        .map(|&p| {
            let q = t.transform_point3(p);
            to.iter()
                .map(|&r| q.distance_squared(r))
                .fold(f32::INFINITY, f32::min)
                .sqrt()
        })
        .sum();
    sum / from.len() as f32
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use glam::Quat;
    use horizon_mesh::{Instance, Submesh};

    /// An irregular, asymmetric tetrahedron-ish solid, so the PCA axes are distinct.
    pub(crate) fn lump() -> InstancedMesh {
        let positions = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(4.0, 0.0, 0.0),
            Vec3::new(0.0, 2.0, 0.0),
            Vec3::new(0.5, 0.3, 1.0),
            Vec3::new(3.0, 1.5, 0.2),
        ];
        let indices = vec![0, 2, 1, 0, 1, 3, 1, 2, 3, 2, 0, 3, 1, 4, 3, 2, 4, 1];
        InstancedMesh {
            submeshes: vec![Submesh {
                positions,
                indices,
                ..Submesh::default()
            }],
            instances: vec![Instance {
                submesh: 0,
                transform: Affine3A::IDENTITY,
            }],
            ..InstancedMesh::default()
        }
    }

    #[test]
    fn a_moved_copy_aligns_back_onto_the_original() {
        let original = lump();
        let moved_by = Affine3A::from_scale_rotation_translation(
            Vec3::splat(2.5),
            Quat::from_euler(glam::EulerRot::XYZ, 0.7, -1.1, 2.0),
            Vec3::new(10.0, -3.0, 4.0),
        );
        let mut copy = original.clone();
        for p in &mut copy.submeshes[0].positions {
            *p = moved_by.transform_point3(*p);
        }
        let a = PcaFrame::of(&original).expect("area");
        let b = PcaFrame::of(&copy).expect("area");
        let (t, score) = a.align(&b);
        assert!(score < 1e-3, "score {score}");
        // t maps the copy back onto the original: t * moved_by is the identity.
        let back = t * moved_by;
        for p in &original.submeshes[0].positions {
            assert!(back.transform_point3(*p).distance(*p) < 1e-3, "{p}");
        }
    }

    #[test]
    fn a_flat_mesh_has_no_frame() {
        let mut m = lump();
        m.submeshes[0].positions = vec![Vec3::ZERO; 5];
        assert!(PcaFrame::of(&m).is_none());
    }
}
