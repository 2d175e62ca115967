//! Bounding spheres and axis-aligned boxes, and the sphere fit behind Sirikata's max-sphere
//! bound (a sphere around the children's centres; `DESIGN.md`, "Cut test").

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// A sphere: an object's bounding sphere, or a node's bound on its objects' centres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Sphere {
    /// Centre in world space.
    pub centre: Vec3,
    /// Radius, never negative.
    pub radius: f32,
}

impl Sphere {
    /// A sphere from its centre and radius.
    pub const fn new(centre: Vec3, radius: f32) -> Self {
        Self { centre, radius }
    }

    /// True when the centre and radius are finite and the radius is not negative.
    pub fn is_valid(&self) -> bool {
        self.centre.is_finite() && self.radius.is_finite() && self.radius >= 0.0
    }
}

/// An axis-aligned box `[min, max]`.
///
/// A box with `min > max` on some axis is empty ([`Aabb::EMPTY`]); it is used only while
/// accumulating and never stored in a tree (an empty node stores the zero box), so that every
/// stored number is finite and serialises in any format.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Vec3,
    /// Largest corner.
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::ZERO
    }
}

impl Aabb {
    /// The identity of [`Aabb::union`]: contains nothing.
    pub const EMPTY: Self = Self {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };

    /// The degenerate box at the origin, stored for an empty node.
    pub const ZERO: Self = Self {
        min: Vec3::ZERO,
        max: Vec3::ZERO,
    };

    /// The box of a sphere.
    #[inline]
    pub fn of_sphere(sphere: Sphere) -> Self {
        let r = Vec3::splat(sphere.radius);
        Self {
            min: sphere.centre - r,
            max: sphere.centre + r,
        }
    }

    /// The smallest box holding both.
    #[inline]
    #[must_use]
    pub fn union(self, other: Self) -> Self {
        Self {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// The smallest box holding `self` and the point `p`.
    #[inline]
    #[must_use]
    pub fn with_point(self, p: Vec3) -> Self {
        Self {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// True for a box that contains nothing.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// Edge lengths, zero for an empty box.
    #[inline]
    pub fn extent(&self) -> Vec3 {
        (self.max - self.min).max(Vec3::ZERO)
    }

    /// Volume, zero for an empty box.
    #[inline]
    pub fn volume(&self) -> f32 {
        let e = self.extent();
        e.x * e.y * e.z
    }

    /// Surface area, zero for an empty box.
    #[inline]
    pub fn surface_area(&self) -> f32 {
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// Centre (meaningless for an empty box).
    #[inline]
    pub fn centre(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// True when `other` lies inside `self` up to `tolerance` on every side.
    pub fn contains(&self, other: &Self, tolerance: f32) -> bool {
        let t = Vec3::splat(tolerance);
        (other.min + t).cmpge(self.min).all() && (other.max - t).cmple(self.max).all()
    }
}

/// A sphere holding every sphere of `parts` (points are spheres of radius 0).
///
/// The centre is the middle of the parts' box and the radius the largest reach
/// `|c - c_i| + r_i` from it: two passes, within a factor `sqrt(3)` of the smallest enclosing
/// sphere and exact for one part. An empty input gives the zero sphere at the origin.
pub(crate) fn fit_sphere<I>(parts: I) -> Sphere
where
    I: Iterator<Item = Sphere> + Clone,
{
    // Pass 1: the box of the parts.
    let mut bounds = Aabb::EMPTY;
    for s in parts.clone() {
        bounds = bounds.union(Aabb::of_sphere(s));
    }
    if bounds.is_empty() {
        return Sphere::default();
    }
    // Pass 2: the farthest reach from the box's centre.
    let centre = bounds.centre();
    let mut radius = 0.0f32;
    for s in parts {
        radius = radius.max((s.centre - centre).length() + s.radius);
    }
    Sphere::new(centre, radius)
}
