//! Error quadrics (Garland and Heckbert 1997), as used by the IAS paper (Azim et al. 2014,
//! section 6.1): the area-weighted plane quadric of eq. 4, the cost of eq. 5 and the optimal
//! placement of eq. 6.
//!
//! A quadric is the symmetric 4x4 matrix `[[A, b], [b^T, c]]`, so that the squared distance of a
//! point `x` from the planes it sums is `x^T A x + 2 b.x + c`. Beside it we keep the total
//! weight (world-space area) it was built from, so that `cost / weight` is a mean squared
//! distance and its square root an error in world units.

use glam::DVec3;

/// A symmetric 4x4 error quadric and the weight it sums.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Quadric {
    /// Upper triangle of the 4x4 matrix: a00 a01 a02 b0 a11 a12 b1 a22 b2 c.
    m: [f64; 10],
    /// Total weight (area, or area-equivalent for constraint planes).
    weight: f64,
}

impl Quadric {
    /// The zero quadric.
    pub const ZERO: Self = Self {
        m: [0.0; 10],
        weight: 0.0,
    };

    /// `weight * p p^T` for the plane `n.x + d = 0`, `n` of unit length (eq. 4).
    pub fn from_plane(n: DVec3, d: f64, weight: f64) -> Self {
        let (x, y, z) = (n.x, n.y, n.z);
        Self {
            m: [
                weight * x * x,
                weight * x * y,
                weight * x * z,
                weight * x * d,
                weight * y * y,
                weight * y * z,
                weight * y * d,
                weight * z * z,
                weight * z * d,
                weight * d * d,
            ],
            weight,
        }
    }

    /// The quadric of a family of planes through the point `a`, given by the weighted sum of
    /// their normals' outer products `U = sum w n n^T` (upper triangle u00 u01 u02 u11 u12 u22).
    /// Every plane passes through `a`, so `b = -U a` and `c = a^T U a`.
    pub fn from_planes_through(u: [f64; 6], a: DVec3, weight: f64) -> Self {
        let ua = DVec3::new(
            u[0] * a.x + u[1] * a.y + u[2] * a.z,
            u[1] * a.x + u[3] * a.y + u[4] * a.z,
            u[2] * a.x + u[4] * a.y + u[5] * a.z,
        );
        Self {
            m: [
                u[0],
                u[1],
                u[2],
                -ua.x,
                u[3],
                u[4],
                -ua.y,
                u[5],
                -ua.z,
                a.dot(ua),
            ],
            weight,
        }
    }

    /// The same matrix, bookkeeping `weight` instead (the world area behind it).
    pub fn with_weight(mut self, weight: f64) -> Self {
        self.weight = weight;
        self
    }

    /// Total weight summed into this quadric.
    pub fn weight(&self) -> f64 {
        self.weight
    }

    /// A value read from both ends of the quadric's storage, to pull it into the cache ahead
    /// of use.
    #[inline]
    pub(crate) fn touch(&self) -> f64 {
        self.m[0] + self.weight
    }

    /// `x^T Q x` (eq. 5), clamped at zero against rounding.
    pub fn eval(&self, x: DVec3) -> f64 {
        let m = &self.m;
        let v = m[0] * x.x * x.x
            + m[4] * x.y * x.y
            + m[7] * x.z * x.z
            + 2.0 * (m[1] * x.x * x.y + m[2] * x.x * x.z + m[5] * x.y * x.z)
            + 2.0 * (m[3] * x.x + m[6] * x.y + m[8] * x.z)
            + m[9];
        v.max(0.0)
    }

    /// `A x + b`, half the gradient.
    fn half_gradient(&self, x: DVec3) -> DVec3 {
        let m = &self.m;
        DVec3::new(
            m[0] * x.x + m[1] * x.y + m[2] * x.z + m[3],
            m[1] * x.x + m[4] * x.y + m[5] * x.z + m[6],
            m[2] * x.x + m[5] * x.y + m[7] * x.z + m[8],
        )
    }

    /// `d^T A d`.
    fn quadratic(&self, d: DVec3) -> f64 {
        let m = &self.m;
        m[0] * d.x * d.x
            + m[4] * d.y * d.y
            + m[7] * d.z * d.z
            + 2.0 * (m[1] * d.x * d.y + m[2] * d.x * d.z + m[5] * d.y * d.z)
    }

    /// The point minimising the quadric (eq. 6), or `None` when `A` is singular or
    /// ill-conditioned (flat or creased neighbourhoods).
    pub fn optimum(&self) -> Option<DVec3> {
        let m = &self.m;
        let (a00, a01, a02, a11, a12, a22) = (m[0], m[1], m[2], m[4], m[5], m[7]);
        let c00 = a11 * a22 - a12 * a12;
        let c01 = a02 * a12 - a01 * a22;
        let c02 = a01 * a12 - a02 * a11;
        let det = a00 * c00 + a01 * c01 + a02 * c02;
        let scale = a00.abs().max(a11.abs()).max(a22.abs());
        if scale <= 0.0 || det.abs() <= 1e-9 * scale * scale * scale {
            return None;
        }
        let c11 = a00 * a22 - a02 * a02;
        let c12 = a01 * a02 - a00 * a12;
        let c22 = a00 * a11 - a01 * a01;
        let b = DVec3::new(-m[3], -m[6], -m[8]);
        let inv = 1.0 / det;
        let x = DVec3::new(
            (c00 * b.x + c01 * b.y + c02 * b.z) * inv,
            (c01 * b.x + c11 * b.y + c12 * b.z) * inv,
            (c02 * b.x + c12 * b.y + c22 * b.z) * inv,
        );
        x.is_finite().then_some(x)
    }

    /// The minimiser of the quadric on the segment `p..q`, as the parameter `t` in `[0, 1]`.
    /// The quadric is convex, so this covers the endpoints and the midpoint.
    pub fn best_on_segment(&self, p: DVec3, q: DVec3) -> f64 {
        let d = q - p;
        let dad = self.quadratic(d);
        if dad <= f64::EPSILON * self.m[0].abs().max(self.m[4].abs()).max(self.m[7].abs()) {
            return 0.5;
        }
        let t = -d.dot(self.half_gradient(p)) / dad;
        if t.is_finite() {
            t.clamp(0.0, 1.0)
        } else {
            0.5
        }
    }
}

impl std::ops::Add for Quadric {
    type Output = Self;
    fn add(mut self, rhs: Self) -> Self {
        self += rhs;
        self
    }
}

impl std::ops::AddAssign for Quadric {
    fn add_assign(&mut self, rhs: Self) {
        for (a, b) in self.m.iter_mut().zip(rhs.m) {
            *a += b;
        }
        self.weight += rhs.weight;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_quadric_measures_squared_distance() {
        let q = Quadric::from_plane(DVec3::Z, -2.0, 3.0);
        assert!((q.eval(DVec3::new(5.0, -1.0, 4.0)) - 3.0 * 4.0).abs() < 1e-12);
        assert_eq!(q.eval(DVec3::new(1.0, 1.0, 2.0)), 0.0);
    }

    #[test]
    fn three_planes_meet_at_the_optimum() {
        let q = Quadric::from_plane(DVec3::X, -1.0, 1.0)
            + Quadric::from_plane(DVec3::Y, -2.0, 1.0)
            + Quadric::from_plane(DVec3::Z, -3.0, 1.0);
        let x = q.optimum().expect("regular");
        assert!((x - DVec3::new(1.0, 2.0, 3.0)).length() < 1e-12);
    }

    #[test]
    fn one_plane_is_singular_and_the_segment_search_takes_over() {
        let q = Quadric::from_plane(DVec3::Z, 0.0, 1.0);
        assert!(q.optimum().is_none());
        let t = q.best_on_segment(DVec3::new(0.0, 0.0, 1.0), DVec3::new(0.0, 0.0, -3.0));
        assert!((t - 0.25).abs() < 1e-12);
    }

    #[test]
    fn planes_through_a_point_match_the_sum_of_plane_quadrics() {
        let a = DVec3::new(1.0, -2.0, 0.5);
        let n1 = DVec3::new(1.0, 2.0, 2.0) / 3.0;
        let n2 = DVec3::new(0.0, 0.6, 0.8);
        let direct =
            Quadric::from_plane(n1, -n1.dot(a), 2.0) + Quadric::from_plane(n2, -n2.dot(a), 0.5);
        let outer = |n: DVec3, w: f64| {
            [
                w * n.x * n.x,
                w * n.x * n.y,
                w * n.x * n.z,
                w * n.y * n.y,
                w * n.y * n.z,
                w * n.z * n.z,
            ]
        };
        let (u1, u2) = (outer(n1, 2.0), outer(n2, 0.5));
        let mut u = [0.0; 6];
        for k in 0..6 {
            u[k] = u1[k] + u2[k];
        }
        let field = Quadric::from_planes_through(u, a, 2.5);
        let x = DVec3::new(0.3, 0.7, -1.1);
        assert!((direct.eval(x) - field.eval(x)).abs() < 1e-12);
    }
}
