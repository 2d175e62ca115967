//! Solid angle of a sphere (core paper eq. 3; Sirikata's `SolidAngle.cpp`) and the max-sphere
//! worst case of a node (`DESIGN.md`, "Cut test").

use glam::Vec3;

/// Solid angle in steradians subtended by a sphere of `radius` whose centre is `distance`
/// away: `Omega = 2 pi (1 - sqrt(1 - r^2/d^2))`, and the whole sphere of directions, `4 pi`,
/// when the viewer is inside (`d <= r`) or the distance is not a number.
///
/// Evaluated as `2 pi x / (1 + sqrt(1 - x))` with `x = r^2/d^2`, the same value rearranged so
/// that small angles (x near 0) do not cancel to zero in f32.
#[inline]
pub fn solid_angle(radius: f32, distance: f32) -> f32 {
    // NaN compares as unordered and is treated as "inside": never hide an object.
    if distance.partial_cmp(&radius) != Some(std::cmp::Ordering::Greater) {
        return 4.0 * std::f32::consts::PI;
    }
    let ratio = radius / distance;
    let x = ratio * ratio;
    2.0 * std::f32::consts::PI * x / (1.0 + (1.0 - x).sqrt())
}

/// The worst-case solid angle of anything below a node with max-sphere bound
/// (`centre`, `bound_radius`) and largest object radius `r_max`, seen from `viewer`: an
/// object of radius `r_max` at the point of the bound nearest the viewer, at distance
/// `d = max(|viewer - centre| - bound_radius, 0)`.
///
/// No object below the node can subtend more, because every object centre below lies inside
/// the bound and no object radius exceeds `r_max`.
#[inline]
pub fn worst_case_solid_angle(viewer: Vec3, centre: Vec3, bound_radius: f32, r_max: f32) -> f32 {
    let distance = ((viewer - centre).length() - bound_radius).max(0.0);
    solid_angle(r_max, distance)
}
