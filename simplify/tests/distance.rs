//! Tests of the Metro-style Hausdorff distance: analytic cases, the closest-point routine against
//! independent references, and the BVH against brute force.

use glam::{DVec3, Vec3};
use horizon_mesh::{ExpandedMesh, Instance, InstancedMesh, Submesh};
use horizon_simplify::distance::{
    closest_point_on_segment, closest_point_on_triangle, hausdorff, hausdorff_instanced, one_sided,
    surface_samples, DistanceError, DistanceOptions, TriangleBvh,
};
use proptest::prelude::*;

fn mesh(positions: Vec<Vec3>, indices: Vec<u32>) -> ExpandedMesh {
    let triangles = indices.len() / 3;
    ExpandedMesh {
        positions,
        indices,
        triangle_instance: vec![0; triangles],
    }
}

/// The unit square [0, 1]^2 at height `z`, as two triangles.
fn square(z: f32) -> ExpandedMesh {
    mesh(
        vec![
            Vec3::new(0.0, 0.0, z),
            Vec3::new(1.0, 0.0, z),
            Vec3::new(1.0, 1.0, z),
            Vec3::new(0.0, 1.0, z),
        ],
        vec![0, 1, 2, 0, 2, 3],
    )
}

/// The unit square with its centre lifted to height `h`: four triangles.
fn tent(h: f32) -> ExpandedMesh {
    mesh(
        vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.5, 0.5, h),
        ],
        vec![0, 1, 4, 1, 2, 4, 2, 3, 4, 3, 0, 4],
    )
}

/// A UV sphere: a closed, curved surface with many triangles.
fn sphere(radius: f32, center: Vec3, rings: u32, segments: u32) -> ExpandedMesh {
    let mut positions = Vec::new();
    for r in 0..=rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            positions.push(
                center
                    + radius
                        * Vec3::new(
                            theta.sin() * phi.cos(),
                            theta.sin() * phi.sin(),
                            theta.cos(),
                        ),
            );
        }
    }
    let mut indices = Vec::new();
    for r in 0..rings {
        for s in 0..segments {
            let (a, b) = (r * segments + s, r * segments + (s + 1) % segments);
            let (c, d) = (a + segments, b + segments);
            indices.extend([a, c, b, b, c, d]);
        }
    }
    mesh(positions, indices)
}

fn options(samples: usize) -> DistanceOptions {
    DistanceOptions { samples, seed: 7 }
}

/// Ground truth for the closest-point routine, written independently: the projection onto the
/// plane when it falls inside (by signed areas), otherwise the nearest of the three edges.
fn reference_distance(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let edges = [(a, b), (b, c), (c, a)]
        .map(|(s, e)| closest_point_on_segment(p, s, e).distance(p))
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    let n = (b - a).cross(c - a);
    let n2 = n.length_squared();
    if n2 == 0.0 {
        return edges;
    }
    let q = p - n * ((p - a).dot(n) / n2);
    let inside = [(a, b), (b, c), (c, a)]
        .iter()
        .all(|&(s, e)| (e - s).cross(q - s).dot(n) >= 0.0);
    if inside {
        edges.min(q.distance(p))
    } else {
        edges
    }
}

fn brute_force(triangles: &[[Vec3; 3]], p: DVec3) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| v.as_dvec3());
            closest_point_on_triangle(p, a, b, c).distance_squared(p)
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn identical_meshes_are_at_distance_zero() {
    let s = sphere(3.0, Vec3::new(10.0, -4.0, 2.5), 24, 48);
    let r = hausdorff(&s, &s, &options(20_000)).expect("distance");
    assert!(r.hausdorff <= 1e-7 * r.diagonal, "{r:?}");
    assert!(r.forward.mean <= 1e-9 * r.diagonal && r.backward.rms <= 1e-9 * r.diagonal);
    let sq = square(0.0);
    let r = hausdorff(&sq, &sq, &options(10_000)).expect("distance");
    assert_eq!(r.hausdorff, 0.0, "{r:?}");
}

#[test]
fn translated_square_is_at_exactly_half() {
    let r = hausdorff(&square(0.0), &square(0.5), &options(20_000)).expect("distance");
    for side in [r.forward, r.backward] {
        assert_eq!(side.max, 0.5, "{r:?}");
        assert!(
            (side.mean - 0.5).abs() < 1e-12 && (side.rms - 0.5).abs() < 1e-12,
            "{r:?}"
        );
    }
    assert_eq!(r.hausdorff, 0.5);
    assert!((r.diagonal - 2f64.sqrt()).abs() < 1e-12);
    assert!((r.hausdorff_rel_diag - 0.5 / 2f64.sqrt()).abs() < 1e-12);
}

#[test]
fn symmetric_against_an_analytic_answer() {
    // Flat square A against a tent B of height h over it. B -> A is at most h (the apex, a
    // vertex sample); A -> B peaks at A's centre, whose distance to each tent face's plane is
    // 0.5 h / sqrt(h^2 + 0.25).
    let h = 1.0f64;
    let forward_exact = 0.5 * h / (h * h + 0.25).sqrt();
    let (a, b) = (square(0.0), tent(h as f32));
    let ab = hausdorff(&a, &b, &options(20_000)).expect("distance");
    let ba = hausdorff(&b, &a, &options(20_000)).expect("distance");
    for r in [ab, ba] {
        assert!((r.hausdorff - h).abs() <= 0.01 * h, "{r:?}");
    }
    assert!(
        (ab.forward.max - forward_exact).abs() <= 0.01 * forward_exact,
        "{ab:?}"
    );
    assert!(
        (ba.backward.max - forward_exact).abs() <= 0.01 * forward_exact,
        "{ba:?}"
    );
    assert!((ab.backward.max - h).abs() <= 1e-12 && (ba.forward.max - h).abs() <= 1e-12);

    // Two concentric spheres: every point of one is r2 - r1 from the other (up to faceting).
    let inner = sphere(1.0, Vec3::ZERO, 48, 96);
    let outer = sphere(1.25, Vec3::ZERO, 48, 96);
    let io = hausdorff(&inner, &outer, &options(20_000)).expect("distance");
    let oi = hausdorff(&outer, &inner, &options(20_000)).expect("distance");
    for r in [io, oi] {
        assert!((r.hausdorff - 0.25).abs() <= 0.01 * 0.25, "{r:?}");
    }
}

#[test]
fn containment_makes_the_two_directions_differ() {
    // A small triangle inside a big coplanar one: every point of the small one lies on the big
    // one, but the big one's far corner is far from the small one.
    let big = mesh(
        vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(0.0, 10.0, 0.0),
        ],
        vec![0, 1, 2],
    );
    let small = mesh(
        vec![
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(2.0, 1.0, 0.0),
            Vec3::new(1.0, 2.0, 0.0),
        ],
        vec![0, 1, 2],
    );
    let r = hausdorff(&big, &small, &options(10_000)).expect("distance");
    assert_eq!(r.backward.max, 0.0, "{r:?}");
    // Farthest point of the big triangle from the small one: corner (10, 0) to (2, 1).
    let expected = (64.0f64 + 1.0).sqrt();
    assert!((r.forward.max - expected).abs() < 1e-9, "{r:?}");
    assert!(r.forward.mean > 1.0);
    assert_eq!(r.hausdorff, r.forward.max);
}

#[test]
fn sample_counts_follow_the_budget() {
    let s = sphere(1.0, Vec3::ZERO, 8, 16);
    let used = s.positions.len();
    let points = surface_samples(&s, &options(5_000)).expect("samples");
    assert_eq!(points.len(), used + 5_000 + 5_000);
    let r = hausdorff(&s, &square(0.0), &options(5_000)).expect("distance");
    assert_eq!(r.forward.samples, used + 10_000);
    assert_eq!(r.backward.samples, 4 + 10_000);
    // Face samples lie on the sphere's triangles.
    let bvh = TriangleBvh::from_mesh(&s).expect("bvh");
    for p in points.iter().step_by(97) {
        let c = bvh.closest(*p).expect("closest");
        assert!(c.distance_squared < 1e-24, "{p} is {c:?}");
    }
}

#[test]
fn deterministic_and_seeded() {
    let a = sphere(1.0, Vec3::ZERO, 12, 24);
    let b = sphere(1.1, Vec3::new(0.05, 0.0, 0.0), 9, 17);
    let r1 = hausdorff(&a, &b, &options(30_000)).expect("distance");
    let r2 = hausdorff(&a, &b, &options(30_000)).expect("distance");
    assert_eq!(
        (r1.forward, r1.backward, r1.hausdorff),
        (r2.forward, r2.backward, r2.hausdorff)
    );
    let other = DistanceOptions {
        samples: 30_000,
        seed: 8,
    };
    let r3 = hausdorff(&a, &b, &other).expect("distance");
    assert_ne!(r1.forward.mean, r3.forward.mean);
    assert!((r1.forward.mean - r3.forward.mean).abs() < 0.01 * r1.forward.mean);
}

#[test]
fn one_sided_matches_the_forward_direction() {
    let a = sphere(1.0, Vec3::ZERO, 12, 24);
    let b = sphere(1.1, Vec3::new(0.05, 0.0, 0.0), 9, 17);
    let r = hausdorff(&a, &b, &options(10_000)).expect("distance");
    let bvh = TriangleBvh::from_mesh(&b).expect("bvh");
    let f = one_sided(&a, &bvh, &options(10_000)).expect("distance");
    assert_eq!(f, r.forward);
}

#[test]
fn instanced_meshes_are_expanded() {
    let quad = Submesh {
        positions: square(0.0).positions,
        indices: vec![0, 1, 2, 0, 2, 3],
        ..Submesh::default()
    };
    let placed = |z: f32| InstancedMesh {
        submeshes: vec![quad.clone()],
        instances: vec![
            Instance {
                submesh: 0,
                transform: glam::Affine3A::from_translation(Vec3::new(0.0, 0.0, z)),
            },
            Instance {
                submesh: 0,
                transform: glam::Affine3A::from_translation(Vec3::new(3.0, 0.0, z)),
            },
        ],
        ..InstancedMesh::default()
    };
    let r = hausdorff_instanced(&placed(0.0), &placed(0.25), &options(5_000)).expect("distance");
    assert_eq!(r.hausdorff, 0.25);
    assert!((r.diagonal - 17f64.sqrt()).abs() < 1e-9);
}

#[test]
fn bad_input_is_a_typed_error() {
    let empty = ExpandedMesh::default();
    assert_eq!(
        hausdorff(&empty, &square(0.0), &options(10)),
        Err(DistanceError::Empty { mesh: "first" })
    );
    assert_eq!(
        hausdorff(&square(0.0), &empty, &options(10)),
        Err(DistanceError::Empty { mesh: "second" })
    );
    let dangling = mesh(vec![Vec3::ZERO; 2], vec![0, 1, 2]);
    assert!(matches!(
        hausdorff(&square(0.0), &dangling, &options(10)),
        Err(DistanceError::IndexOutOfRange { index: 2, .. })
    ));
    let nan = mesh(vec![Vec3::ZERO, Vec3::X, Vec3::NAN], vec![0, 1, 2]);
    assert!(matches!(
        hausdorff(&nan, &square(0.0), &options(10)),
        Err(DistanceError::NonFinite { vertex: 2, .. })
    ));
    let partial = mesh(vec![Vec3::ZERO; 3], vec![0, 1]);
    assert!(matches!(
        hausdorff(&partial, &square(0.0), &options(10)),
        Err(DistanceError::PartialTriangle { count: 2, .. })
    ));
}

#[test]
fn degenerate_meshes_are_points_and_segments() {
    // A mesh made only of zero-area triangles: a segment from (0,0,0) to (2,0,0) and a point.
    let segment = mesh(
        vec![
            Vec3::ZERO,
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(5.0, 5.0, 5.0),
        ],
        vec![0, 1, 2, 3, 3, 3],
    );
    let plane = mesh(
        vec![
            Vec3::new(-20.0, -20.0, 1.0),
            Vec3::new(20.0, -20.0, 1.0),
            Vec3::new(0.0, 20.0, 1.0),
        ],
        vec![0, 1, 2],
    );
    let r = hausdorff(&segment, &plane, &options(1_000)).expect("distance");
    assert_eq!(r.forward.max, 4.0, "{r:?}");
    // Face samples of the plane near its corners are far from the segment and the point.
    assert!(r.backward.max > 9.0);
    // Degenerate triangles as targets: distance from a point to a collinear triangle.
    let bvh = TriangleBvh::from_mesh(&segment).expect("bvh");
    bvh.validate().expect("valid");
    let c = bvh.closest(DVec3::new(1.5, -3.0, -4.0)).expect("closest");
    assert!((c.distance_squared - 25.0).abs() < 1e-12, "{c:?}");
    assert_eq!(c.triangle, 0);
    let c = bvh.closest(DVec3::new(5.0, 5.0, 6.0)).expect("closest");
    assert_eq!((c.distance_squared, c.triangle), (1.0, 1));
}

#[test]
fn closest_point_regions_and_degenerate_cases() {
    let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
    let cases = [
        (DVec3::new(0.25, 0.25, 2.0), DVec3::new(0.25, 0.25, 0.0)), // face
        (DVec3::new(-1.0, -1.0, 0.0), a),                           // vertex a
        (DVec3::new(2.0, -0.5, 1.0), b),                            // vertex b
        (DVec3::new(-0.1, 3.0, 0.0), c),                            // vertex c
        (DVec3::new(0.5, -1.0, 0.0), DVec3::new(0.5, 0.0, 0.0)),    // edge ab
        (DVec3::new(-1.0, 0.5, 0.0), DVec3::new(0.0, 0.5, 0.0)),    // edge ac
        (DVec3::new(1.0, 1.0, 0.0), DVec3::new(0.5, 0.5, 0.0)),     // edge bc
    ];
    for (p, expected) in cases {
        let q = closest_point_on_triangle(p, a, b, c);
        assert!(
            q.distance(expected) < 1e-15,
            "{p} -> {q}, expected {expected}"
        );
    }
    // A point triangle, a segment triangle with a repeated vertex, and a collinear one.
    let p = DVec3::new(3.0, 4.0, 0.0);
    assert_eq!(closest_point_on_triangle(p, a, a, a), a);
    assert_eq!(closest_point_on_triangle(p, a, b, b), b);
    assert_eq!(closest_point_on_triangle(p, a, a, b), b);
    let q = closest_point_on_triangle(p, a, DVec3::new(10.0, 0.0, 0.0), DVec3::new(5.0, 0.0, 0.0));
    assert!(q.distance(DVec3::new(3.0, 0.0, 0.0)) < 1e-15, "{q}");
    // A sliver 1e-12 wide is treated as its edges; the answer is still right to 1e-12.
    let sliver = DVec3::new(5.0, 1e-12, 0.0);
    let q = closest_point_on_triangle(
        DVec3::new(5.0, 1.0, 1.0),
        a,
        DVec3::new(10.0, 0.0, 0.0),
        sliver,
    );
    assert!(q.distance(DVec3::new(5.0, 0.0, 0.0)) < 1e-11, "{q}");
}

fn coordinate() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -10.0f32..10.0,
        1 => (-3i32..3).prop_map(|i| i as f32),
    ]
}

fn point() -> impl Strategy<Value = Vec3> {
    (coordinate(), coordinate(), coordinate()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// Random triangles, a third of them degenerate: collapsed to a point, to a segment by a
/// repeated vertex, or collinear.
fn triangle() -> impl Strategy<Value = [Vec3; 3]> {
    (point(), point(), point(), 0u8..6, -2.0f32..3.0).prop_map(|(a, b, c, kind, t)| match kind {
        0 => [a, a, a],
        1 => [a, b, a],
        2 => [a, b, a + (b - a) * t],
        _ => [a, b, c],
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn closest_point_matches_an_independent_reference(t in triangle(), p in point()) {
        let [a, b, c] = t.map(|v| v.as_dvec3());
        let p = p.as_dvec3();
        let q = closest_point_on_triangle(p, a, b, c);
        let got = q.distance(p);
        let want = reference_distance(p, a, b, c);
        let scale = 1.0 + a.abs().max(b.abs()).max(c.abs()).max(p.abs()).max_element();
        prop_assert!((got - want).abs() <= 1e-9 * scale, "got {got}, want {want}");
        // The returned point lies on the triangle.
        prop_assert!(reference_distance(q, a, b, c) <= 1e-9 * scale);
    }

    #[test]
    fn bvh_query_equals_brute_force(
        triangles in prop::collection::vec(triangle(), 1..120),
        points in prop::collection::vec(point(), 1..20),
    ) {
        let bvh = TriangleBvh::new(triangles.clone());
        bvh.validate().map_err(|e| TestCaseError::fail(e.to_string()))?;
        for p in points {
            let p = p.as_dvec3() * 1.5;
            let want = brute_force(&triangles, p);
            let got = bvh.closest(p).expect("non-empty");
            prop_assert!((got.distance_squared - want).abs() <= 1e-12 * (1.0 + want),
                "got {}, want {want}", got.distance_squared);
            // The reported triangle really is at that distance.
            let [a, b, c] = triangles[got.triangle as usize].map(|v| v.as_dvec3());
            let d2 = closest_point_on_triangle(p, a, b, c).distance_squared(p);
            prop_assert!((d2 - got.distance_squared).abs() <= 1e-12 * (1.0 + want));
            prop_assert!((got.point.distance_squared(p) - got.distance_squared).abs()
                <= 1e-12 * (1.0 + want));
        }
    }

    #[test]
    fn bvh_validates_on_random_soups(
        triangles in prop::collection::vec(triangle(), 0..400),
        copies in 1usize..4,
    ) {
        // Repeated triangles (identical centroids) exercise the median fallback.
        let soup: Vec<[Vec3; 3]> = triangles.iter().cycle().take(triangles.len() * copies).copied().collect();
        let bvh = TriangleBvh::new(soup.clone());
        bvh.validate().map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(bvh.len(), soup.len());
        prop_assert!(bvh.depth() <= 64);
    }
}

#[test]
fn bvh_validates_on_a_large_soup() {
    // Large enough for the parallel build, with many coincident triangles.
    let s = sphere(2.0, Vec3::new(1.0, 2.0, 3.0), 100, 200);
    let mut triangles: Vec<[Vec3; 3]> = s
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]].map(|i| s.positions[i as usize]))
        .collect();
    triangles.extend(std::iter::repeat_n([Vec3::ONE; 3], 5_000));
    let bvh = TriangleBvh::new(triangles.clone());
    bvh.validate().expect("valid");
    assert!(bvh.depth() <= 64, "depth {}", bvh.depth());
    for k in 0..50 {
        let f = k as f64 * 1.37;
        let p = DVec3::new(f.sin() * 3.0, f.cos() * 2.5, (f * 0.3).sin() * 4.0 + 3.0);
        let want = brute_force(&triangles, p);
        let got = bvh.closest(p).expect("closest").distance_squared;
        assert!(
            (got - want).abs() <= 1e-12 * (1.0 + want),
            "{p}: {got} vs {want}"
        );
    }
}
