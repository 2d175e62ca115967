//! Solid angle of a sphere (core paper eq. 3) and the max-sphere worst case (`DESIGN.md`,
//! "Cut test"), against their closed forms.

use std::f32::consts::PI;

use glam::Vec3;
use horizon_bvh::{solid_angle, worst_case_solid_angle};

fn close(a: f32, b: f32, relative: f32) -> bool {
    (a - b).abs() <= relative * b.abs().max(f32::MIN_POSITIVE)
}

#[test]
fn solid_angle_matches_closed_form() {
    // Omega = 2 pi (1 - sqrt(1 - r^2/d^2)), evaluated in f64 as the reference.
    for (r, d) in [
        (1.0f32, 2.0f32),
        (1.0, 1.5),
        (3.0, 10.0),
        (0.5, 0.75),
        (20.0, 100.0),
    ] {
        let (r64, d64) = (f64::from(r), f64::from(d));
        let exact = 2.0 * std::f64::consts::PI * (1.0 - (1.0 - r64 * r64 / (d64 * d64)).sqrt());
        assert!(
            close(solid_angle(r, d), exact as f32, 1e-5),
            "r {r} d {d}: {} vs {exact}",
            solid_angle(r, d)
        );
    }
    // Known value: r/d = 1/2 gives 2 pi (1 - sqrt(3)/2) = 0.841787.
    assert!(close(solid_angle(1.0, 2.0), 0.841_787, 1e-5));
}

#[test]
fn solid_angle_keeps_precision_for_tiny_angles() {
    // Far away, Omega -> pi r^2 / d^2 (the disc's area over d^2); the naive formula cancels
    // to 0 in f32 at r/d = 1e-4, the rearranged one must not.
    let (r, d) = (1.0f32, 10_000.0f32);
    let expected = PI * r * r / (d * d);
    assert!(close(solid_angle(r, d), expected, 1e-4));
}

#[test]
fn solid_angle_is_the_full_sphere_inside() {
    // A viewer inside or on the sphere sees it in every direction: 4 pi.
    for (r, d) in [
        (1.0f32, 0.0f32),
        (1.0, 0.5),
        (1.0, 1.0),
        (0.0, 0.0),
        (5.0, f32::NAN),
    ] {
        assert_eq!(solid_angle(r, d), 4.0 * PI, "r {r} d {d}");
    }
}

#[test]
fn solid_angle_decreases_with_distance() {
    // Strictly monotone from just outside the sphere to far away.
    let r = 2.0f32;
    let mut previous = 4.0 * PI;
    let mut d = r * 1.0001;
    while d < 1e6 {
        let omega = solid_angle(r, d);
        assert!(omega < previous, "d {d}: {omega} >= {previous}");
        assert!(omega > 0.0);
        previous = omega;
        d *= 1.3;
    }
    // A point (radius 0) subtends nothing from outside.
    assert_eq!(solid_angle(0.0, 1.0), 0.0);
}

#[test]
fn worst_case_places_r_max_at_the_nearest_point_of_the_bound() {
    let centre = Vec3::new(10.0, 0.0, 0.0);
    // Viewer 30 m from the centre of a bound of radius 10: the worst-case object of radius 2
    // sits 20 m away.
    let viewer = Vec3::new(10.0, 30.0, 0.0);
    assert_eq!(
        worst_case_solid_angle(viewer, centre, 10.0, 2.0),
        solid_angle(2.0, 20.0)
    );
    // Inside the bound the worst case is at distance 0: the full sphere.
    assert_eq!(
        worst_case_solid_angle(Vec3::new(12.0, 0.0, 0.0), centre, 10.0, 2.0),
        4.0 * PI
    );
    // Never below the solid angle of an r_max object at the centre itself.
    for y in [11.0f32, 15.0, 50.0, 500.0] {
        let viewer = Vec3::new(10.0, y, 0.0);
        assert!(
            worst_case_solid_angle(viewer, centre, 10.0, 2.0) >= solid_angle(2.0, y),
            "y {y}"
        );
    }
}
