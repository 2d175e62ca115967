//! Budgets from the display model: how close an aggregate can be shown, how many pixels it
//! then covers, and what that buys in triangles, texels and kept objects.
//!
//! The cut (core paper eq. 3 and `DESIGN.md`, "Cut test") returns a node as an aggregate only
//! while an object of radius `r_max` at the node sphere's nearest point subtends less than
//! `Omega_min`. Inverting eq. 3, that point is at least `d = r_max / sqrt(1 - (1 -
//! Omega_min / 2 pi)^2)` from the viewer, so the viewer is at least `Rc + d` from the centre,
//! and the whole aggregate (radius `Rc + r_max`) covers at most `solid_angle(Rc + r_max,
//! Rc + d)`, capped by the screen. That pixel count, in Table 1's display model (1920 x 1080
//! on 34 inches at 24 inches, `horizon_descriptors::calibrate::pixel_solid_angle`), is the
//! one number every budget follows from.
//!
//! **Triangle budget rule**: one expanded triangle per `pixels_per_triangle` pixels of that
//! worst case. Triangles smaller than a few pixels cannot change the image, so a budget
//! proportional to covered pixels bounds the on-screen error while keeping far-away, small
//! aggregates tiny. The default 16 (a 4 x 4 pixel footprint per triangle) is the coarsest of
//! those tried that keeps the simplification error under one pixel at the nearest display
//! distance; finer budgets leave almost nothing simplified. The sweep is
//! `lab/bench/budget_sweep.py`, its figures `lab/results/budget_village.md`.

use glam::Vec3;
use horizon_descriptors::calibrate::pixel_solid_angle;

use crate::options::AggregateOptions;

/// Fewest expanded triangles an aggregate is asked to keep.
pub const MIN_TRIANGLES: u64 = 64;

/// Smallest and largest atlas side the budget may ask for. 512 x 512 is about what a 128 KiB
/// JPEG holds at good quality; starting larger only bakes an atlas to throw away.
pub const ATLAS_SIDE: (u32, u32) = (32, 512);

/// Where and how large a node's aggregate can appear.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Display {
    /// The node's sphere around its children's centres.
    pub centre: Vec3,
    /// Its radius `Rc`.
    pub radius: f64,
    /// The largest object radius below the node.
    pub r_max: f64,
    /// Least distance from the viewer to the sphere `(centre, radius)`: `d` above.
    pub distance: f64,
    /// Pixels the whole aggregate covers from that distance, at most the screen.
    pub pixels: f64,
}

/// Solid angle of a sphere of radius `r` at distance `d` from its centre (eq. 3).
pub fn solid_angle(r: f64, d: f64) -> f64 {
    if d <= r {
        4.0 * std::f64::consts::PI
    } else {
        let s = r / d;
        2.0 * std::f64::consts::PI * (1.0 - (1.0 - s * s).sqrt())
    }
}

/// Eq. 3 inverted: the distance at which a sphere of radius `r` subtends `omega`.
pub fn distance_for(r: f64, omega: f64) -> f64 {
    let c = 1.0 - omega / (2.0 * std::f64::consts::PI);
    let s = (1.0 - c * c).max(f64::MIN_POSITIVE).sqrt();
    r / s
}

/// Solid angle of the whole screen in Table 1's display model.
pub fn screen_solid_angle() -> f64 {
    1920.0 * 1080.0 * pixel_solid_angle()
}

impl Display {
    /// The worst case for a node with bound `(centre, radius)` and largest object `r_max`.
    pub fn of(centre: Vec3, radius: f32, r_max: f32, options: &AggregateOptions) -> Self {
        let (radius, r_max) = (f64::from(radius), f64::from(r_max));
        let distance = distance_for(r_max, options.min_solid_angle);
        let omega = solid_angle(radius + r_max, radius + distance).min(screen_solid_angle());
        Self {
            centre,
            radius,
            r_max,
            distance,
            pixels: omega / pixel_solid_angle(),
        }
    }

    /// The expanded triangle budget: one triangle per `pixels_per_triangle` pixels.
    pub fn triangle_budget(&self, options: &AggregateOptions) -> u64 {
        ((self.pixels / options.pixels_per_triangle).ceil() as u64).max(MIN_TRIANGLES)
    }

    /// Pixels an object with world sphere `(p, r)` covers at most while the aggregate is
    /// shown: the viewer stays outside the sphere of radius `radius + distance` around the
    /// centre, so the object is at least that minus its offset from the centre away.
    pub fn object_pixels(&self, p: Vec3, r: f32) -> f64 {
        let offset = f64::from((p - self.centre).length());
        let d = (self.radius + self.distance - offset).max(0.0);
        solid_angle(f64::from(r), d).min(screen_solid_angle()) / pixel_solid_angle()
    }

    /// How many pixels a length seen face-on at the nearest display distance spans.
    pub fn pixels_of_length(&self, length: f64) -> f64 {
        length / (self.distance.max(f64::MIN_POSITIVE) * pixel_solid_angle().sqrt())
    }

    /// The length that spans `pixels` pixels seen face-on at the nearest display distance
    /// (the inverse of [`Display::pixels_of_length`]).
    pub fn length_of_pixels(&self, pixels: f64) -> f64 {
        pixels * self.distance * pixel_solid_angle().sqrt()
    }

    /// The length that spans `pixels` pixels seen face-on as near as any of the aggregate's
    /// geometry can come: an object's centre stays `distance` away, its surface up to `r_max`
    /// nearer.
    pub fn nearest_length_of_pixels(&self, pixels: f64) -> f64 {
        pixels * (self.distance - self.r_max).max(0.0) * pixel_solid_angle().sqrt()
    }

    /// Atlas side: `texels_per_pixel` texels per covered pixel, a power of two in
    /// [`ATLAS_SIDE`].
    pub fn atlas_side(&self, options: &AggregateOptions) -> u32 {
        let side = (self.pixels * options.texels_per_pixel)
            .sqrt()
            .ceil()
            .max(1.0) as u32;
        side.next_power_of_two().clamp(ATLAS_SIDE.0, ATLAS_SIDE.1)
    }
}

/// The dedup distance of section 5.1 (the paper's eq. 2, inverted properly; `DESIGN.md`):
/// where an aggregate of outer radius `outer` subtends `dedup_solid_angle`.
pub fn dedup_distance(outer: f32, options: &AggregateOptions) -> f64 {
    distance_for(f64::from(outer), options.dedup_solid_angle)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_for_inverts_the_solid_angle() {
        for &(r, omega) in &[(1.0, 1e-3), (5.0, 0.5), (0.1, 2.0)] {
            let d = distance_for(r, omega);
            assert!(
                (solid_angle(r, d) - omega).abs() < 1e-9 * omega.max(1.0),
                "{r} {omega}"
            );
        }
    }

    #[test]
    fn a_bigger_node_gets_a_bigger_budget() {
        let o = AggregateOptions::default();
        let small = Display::of(Vec3::ZERO, 10.0, 1.0, &o);
        let big = Display::of(Vec3::ZERO, 100.0, 1.0, &o);
        assert!(big.triangle_budget(&o) > small.triangle_budget(&o));
        assert!(big.pixels <= 1920.0 * 1080.0 + 1.0);
    }

    #[test]
    fn length_of_pixels_inverts_pixels_of_length() {
        let o = AggregateOptions::default();
        let d = Display::of(Vec3::ZERO, 30.0, 2.0, &o);
        for px in [0.125, 1.0, 40.0] {
            let back = d.pixels_of_length(d.length_of_pixels(px));
            assert!((back - px).abs() < 1e-9 * px, "{px} -> {back}");
        }
    }

    #[test]
    fn the_nearest_geometry_is_r_max_inside_the_display_distance() {
        // An r_max object centred on the sphere, towards the viewer: its surface is r_max
        // nearer than `distance`, so a length there spans more pixels.
        let o = AggregateOptions::default();
        let d = Display::of(Vec3::ZERO, 30.0, 2.0, &o);
        let near = d.nearest_length_of_pixels(1.0);
        let expected = d.length_of_pixels(1.0) * (d.distance - d.r_max) / d.distance;
        assert!(
            (near - expected).abs() < 1e-12 * expected,
            "{near} vs {expected}"
        );
        assert!(near < d.length_of_pixels(1.0));
    }

    #[test]
    fn an_object_at_the_near_side_covers_about_omega_min() {
        let o = AggregateOptions::default();
        let d = Display::of(Vec3::ZERO, 10.0, 1.0, &o);
        // An r_max object on the sphere, towards the viewer: it subtends Omega_min.
        let px = d.object_pixels(Vec3::new(10.0, 0.0, 0.0), 1.0);
        let expected = o.min_solid_angle / pixel_solid_angle();
        assert!(
            (px - expected).abs() < 1e-6 * expected,
            "{px} vs {expected}"
        );
    }
}
