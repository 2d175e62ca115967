//! Known answers and promises of the voxelizer + 3D Zernike descriptor (Novotni and Klein
//! 2004; Azim et al. 2014, section 4.1):
//! - the chi tables are orthonormal on the unit ball (exact monomial integrals);
//! - a uniform ball matches its closed form, and has energy only in the l = 0 norms;
//! - distinct shapes order as anyone would expect;
//! - exact lattice symmetries change nothing but rounding;
//! - rigid motions with uniform scale barely move the descriptor, for generated shapes
//!   (proptest) and for every shared model, relative to the spread between distinct models.
//!
//! The shared-model invariance test runs 20 motions per model in release (`cargo test
//! --release`) and 3 per model in debug builds, where the crate itself is unoptimised (the
//! proptest likewise runs 16 or 3 cases); the assertions are the same in both.

use std::f64::consts::PI;
use std::path::PathBuf;
use std::time::Instant;

use glam::{Affine3A, Quat, Vec3};
use horizon_descriptors::voxel::{self, VoxelGrid, VoxelizeOptions};
use horizon_descriptors::zernike::{
    self, zernike_index, zernike_pairs, zernike_polynomial, ZernikeTerm,
};
use horizon_descriptors::ZERNIKE_LEN;
use horizon_mesh::rng::Rng;
use horizon_mesh::{ImportOptions, Instance, InstancedMesh, Submesh};
use proptest::prelude::*;

// ---------------------------------------------------------------------------------------------
// Fixtures
// ---------------------------------------------------------------------------------------------

/// The eight shared models under `assets/models`.
const SHARED_MODELS: [&str; 8] = [
    "bunny_trimesh/bunny.ply",
    "BoxTextured/BoxTextured.glb",
    "CesiumMilkTruck/CesiumMilkTruck.glb",
    "DamagedHelmet/DamagedHelmet.glb",
    "GlassVaseFlowers/GlassVaseFlowers.glb",
    "SimpleInstancing/SimpleInstancing.glb",
    "NegativeScaleTest/NegativeScaleTest.glb",
    "GpuInstancesMetadata/GpuInstancesMetadata.gltf",
];

fn load(relative: &str) -> InstancedMesh {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../assets/models")
        .join(relative);
    horizon_mesh::import_file(&path, &ImportOptions::trusted())
        .unwrap_or_else(|e| panic!("{relative}: {e}"))
        .mesh
}

fn single(sub: Submesh) -> InstancedMesh {
    InstancedMesh {
        submeshes: vec![sub],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        ..InstancedMesh::default()
    }
}

/// Icosphere of radius 1 at the origin: an icosahedron subdivided `levels` times.
fn icosphere(levels: u32) -> Submesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut midpoints = std::collections::HashMap::new();
        let mut midpoint = |a: u32, b: u32, positions: &mut Vec<Vec3>| -> u32 {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let p = (positions[a as usize] + positions[b as usize]).normalize();
                positions.push(p);
                (positions.len() - 1) as u32
            })
        };
        let mut next = Vec::new();
        for [a, b, c] in faces {
            let ab = midpoint(a, b, &mut positions);
            let bc = midpoint(b, c, &mut positions);
            let ca = midpoint(c, a, &mut positions);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    Submesh {
        positions,
        indices: faces.into_iter().flatten().collect(),
        ..Submesh::default()
    }
}

/// Axis-aligned box from `min` to `max`, each face split into an n x n grid of quads so that
/// the triangles are not all huge.
fn boxed(min: Vec3, max: Vec3, n: u32) -> Submesh {
    let mut sub = Submesh::default();
    // Each face: a fixed axis at min or max, two free axes spanning the face.
    for axis in 0..3 {
        for high in [false, true] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let base = sub.positions.len() as u32;
            for j in 0..=n {
                for i in 0..=n {
                    let mut p = Vec3::ZERO;
                    p[axis] = if high { max[axis] } else { min[axis] };
                    p[u] = min[u] + (max[u] - min[u]) * i as f32 / n as f32;
                    p[v] = min[v] + (max[v] - min[v]) * j as f32 / n as f32;
                    sub.positions.push(p);
                }
            }
            for j in 0..n {
                for i in 0..n {
                    let a = base + j * (n + 1) + i;
                    let (b, c, d) = (a + 1, a + n + 1, a + n + 2);
                    // Outward winding: (u, v) is counter-clockwise seen from +axis.
                    if high {
                        sub.indices.extend([a, b, d, a, d, c]);
                    } else {
                        sub.indices.extend([a, d, b, a, c, d]);
                    }
                }
            }
        }
    }
    sub
}

/// A unit cube centred at the origin.
fn cube() -> InstancedMesh {
    single(boxed(Vec3::splat(-0.5), Vec3::splat(0.5), 4))
}

/// A unit sphere.
fn sphere() -> InstancedMesh {
    single(icosphere(3))
}

/// A tree-like shape: a thin trunk, two thin branches and a round crown on top, as instances
/// of one box and one sphere.
fn tree() -> InstancedMesh {
    let trunk = Affine3A::from_scale_rotation_translation(
        Vec3::new(0.15, 2.0, 0.15),
        Quat::IDENTITY,
        Vec3::new(0.0, 1.0, 0.0),
    );
    let branch = |angle: f32| {
        Affine3A::from_rotation_translation(Quat::from_rotation_z(angle), Vec3::new(0.0, 1.6, 0.0))
            * Affine3A::from_scale_rotation_translation(
                Vec3::new(0.08, 1.0, 0.08),
                Quat::IDENTITY,
                Vec3::new(0.0, 0.5, 0.0),
            )
    };
    let crown = Affine3A::from_scale_rotation_translation(
        Vec3::splat(0.9),
        Quat::IDENTITY,
        Vec3::new(0.0, 2.8, 0.0),
    );
    InstancedMesh {
        submeshes: vec![boxed(Vec3::splat(-0.5), Vec3::splat(0.5), 2), icosphere(2)],
        instances: vec![
            Instance {
                submesh: 0,
                transform: trunk,
            },
            Instance {
                submesh: 0,
                transform: branch(0.7),
            },
            Instance {
                submesh: 0,
                transform: branch(-0.9),
            },
            Instance {
                submesh: 1,
                transform: crown,
            },
        ],
        ..InstancedMesh::default()
    }
}

/// Every instance moved by `motion` (applied in world space, after the instance's own
/// transform).
fn moved(mesh: &InstancedMesh, motion: Affine3A) -> InstancedMesh {
    let mut out = mesh.clone();
    for inst in &mut out.instances {
        inst.transform = motion * inst.transform;
    }
    out
}

/// A rigid motion with uniform scale from seven numbers in [0, 1): a uniformly random
/// rotation (Shoemake's subgroup algorithm), a log-uniform scale in [1/20, 20] and a
/// translation of up to 100 units per axis.
fn motion_from(u: [f32; 7]) -> Affine3A {
    let (s1, s2) = ((1.0 - u[0]).sqrt(), u[0].sqrt());
    let (a, b) = (
        2.0 * std::f32::consts::PI * u[1],
        2.0 * std::f32::consts::PI * u[2],
    );
    let rotation = Quat::from_xyzw(s1 * a.sin(), s1 * a.cos(), s2 * b.sin(), s2 * b.cos());
    let scale = 20f32.powf(2.0 * u[3] - 1.0);
    let translation = (Vec3::new(u[4], u[5], u[6]) * 2.0 - 1.0) * 100.0;
    Affine3A::from_scale_rotation_translation(Vec3::splat(scale), rotation, translation)
}

/// A seeded motion as [`motion_from`] makes them, for seeded motions outside proptest.
fn random_motion(rng: &mut Rng) -> Affine3A {
    motion_from([0.0; 7].map(|_| rng.unit()))
}

/// Voxelize with the paper's options (128^3, surface) and take the descriptor.
fn describe(mesh: &InstancedMesh) -> [f32; ZERNIKE_LEN] {
    let grid = voxel::voxelize(mesh, &VoxelizeOptions::default()).expect("voxelize");
    grid.validate().expect("valid grid");
    zernike::zernike(&grid).expect("zernike")
}

/// Table 1's z_diff: L2 between descriptors.
fn z_diff(a: &[f32; ZERNIKE_LEN], b: &[f32; ZERNIKE_LEN]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| f64::from(x - y).powi(2))
        .sum::<f64>()
        .sqrt()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let k = v.len() / 2;
    if v.len() % 2 == 1 {
        v[k]
    } else {
        0.5 * (v[k - 1] + v[k])
    }
}

// ---------------------------------------------------------------------------------------------
// Orthonormality of the chi tables
// ---------------------------------------------------------------------------------------------

/// `int_{|x| <= 1} x^r y^s z^t dx`: zero unless all exponents are even; otherwise, with
/// r = 2a, s = 2b, t = 2c, the sphere integral `4 pi (2a-1)!! (2b-1)!! (2c-1)!! /
/// (2(a+b+c)+1)!!` (Folland, "How to integrate a polynomial over a sphere") times the radial
/// `int_0^1 rho^(r+s+t+2) d rho = 1 / (r+s+t+3)`.
fn ball_monomial_integral(e: [usize; 3]) -> f64 {
    ball_monomial_ratio(e).map_or(0.0, |(num, den)| 4.0 * PI * num as f64 / den as f64)
}

/// The rational part of [`ball_monomial_integral`], exactly: `(num, den)` with the integral
/// equal to `4 pi num / den`, or `None` when it is zero. Fits in u128 for total degree <= 40.
fn ball_monomial_ratio([r, s, t]: [usize; 3]) -> Option<(u128, u128)> {
    if r % 2 == 1 || s % 2 == 1 || t % 2 == 1 {
        return None;
    }
    // k!! for odd k, with (-1)!! = 1.
    let double_factorial = |k: usize| -> u128 { (1..=k as u128).rev().step_by(2).product() };
    let num = double_factorial(r.saturating_sub(1))
        * double_factorial(s.saturating_sub(1))
        * double_factorial(t.saturating_sub(1));
    let den = double_factorial(r + s + t + 1) * (r + s + t + 3) as u128;
    Some((num, den))
}

/// A double-double number `hi + lo` (about 32 significant digits), enough to sum the
/// monomial expansion of a Gram entry, whose terms reach 1e10 while the sum is 0 or 1.
#[derive(Clone, Copy, Debug, Default)]
struct DoubleDouble {
    hi: f64,
    lo: f64,
}

impl DoubleDouble {
    /// Knuth's error-free sum.
    fn two_sum(a: f64, b: f64) -> (f64, f64) {
        let s = a + b;
        let bb = s - a;
        (s, (a - (s - bb)) + (b - bb))
    }

    /// Error-free product through a fused multiply-add.
    fn two_prod(a: f64, b: f64) -> (f64, f64) {
        let p = a * b;
        (p, a.mul_add(b, -p))
    }

    fn add(&mut self, x: f64) {
        let (s, e) = Self::two_sum(self.hi, x);
        self.hi = s;
        self.lo += e;
    }

    /// `num / den` for integers below 2^127, to double-double precision.
    fn ratio(num: u128, den: u128) -> Self {
        let split = |n: u128| {
            let hi = n as f64;
            (hi, (n as i128 - hi as i128) as f64)
        };
        let ((nh, nl), (dh, dl)) = (split(num), split(den));
        let q1 = nh / dh;
        // Remainder n - q1 d, exactly enough: q1 dh is split error-free.
        let (p, pe) = Self::two_prod(q1, dh);
        let rem = (nh - p) + (nl - pe - q1 * dl);
        let q2 = rem / dh;
        let (hi, lo) = Self::two_sum(q1, q2);
        Self { hi, lo }
    }

    /// Adds `a * b * r` with `a`, `b` plain and `r` double-double.
    fn add_product(&mut self, a: f64, b: f64, r: Self) {
        let (p, pe) = Self::two_prod(a, b);
        let (q, qe) = Self::two_prod(p, r.hi);
        self.add(q);
        self.add(qe + p * r.lo + pe * r.hi);
    }

    fn value(self) -> f64 {
        self.hi + self.lo
    }
}

/// `3/(4 pi) int_ball Z_a conj(Z_b)` from the monomial expansions, summed in double-double
/// with exact rational monomial integrals, so that only the tables' own rounding remains.
fn ball_inner_product(a: &[ZernikeTerm], b: &[ZernikeTerm]) -> (f64, f64) {
    let (mut re, mut im) = (DoubleDouble::default(), DoubleDouble::default());
    for p in a {
        for q in b {
            let e = [0, 1, 2].map(|k| p.exponents[k] + q.exponents[k]);
            let Some((num, den)) = ball_monomial_ratio(e) else {
                continue;
            };
            // 3/(4 pi) * 4 pi num/den = 3 num/den.
            let r = DoubleDouble::ratio(3 * num, den);
            // (p.re + i p.im)(q.re - i q.im)
            re.add_product(p.re, q.re, r);
            re.add_product(p.im, q.im, r);
            im.add_product(p.im, q.re, r);
            im.add_product(-p.re, q.im, r);
        }
    }
    (re.value(), im.value())
}

#[test]
fn monomial_integrals_match_known_values() {
    // Volume 4 pi / 3; int x^2 = 4 pi / 15; int x^2 y^2 = 4 pi / 105; int x^4 = 4 pi / 35.
    let close = |a: f64, b: f64| (a - b).abs() < 1e-14;
    assert!(close(ball_monomial_integral([0, 0, 0]), 4.0 * PI / 3.0));
    assert!(close(ball_monomial_integral([2, 0, 0]), 4.0 * PI / 15.0));
    assert!(close(ball_monomial_integral([2, 2, 0]), 4.0 * PI / 105.0));
    assert!(close(ball_monomial_integral([0, 0, 4]), 4.0 * PI / 35.0));
    assert_eq!(ball_monomial_integral([1, 2, 0]), 0.0);
    // The double-double ratio is exact to ~1e-30: 1/3 times 3 is 1.
    let third = DoubleDouble::ratio(1, 3);
    let mut one = DoubleDouble::default();
    one.add_product(3.0, 1.0, third);
    assert!((one.value() - 1.0).abs() < 1e-30);
}

#[test]
fn chi_tables_are_orthonormal_on_the_unit_ball() {
    // Every (n, l, m >= 0) for a spread of (l, m), with every pair inside a family (the
    // radial orthogonality in n, the cancellation-prone part) and every pair across families
    // at equal n (orthogonality in l and m).
    let families = [
        (0, 0),
        (1, 1),
        (2, 1),
        (3, 3),
        (4, 2),
        (6, 0),
        (7, 5),
        (10, 4),
        (12, 12),
        (15, 1),
        (20, 0),
        (20, 20),
    ];
    let mut polys = Vec::new();
    for &(l, m) in &families {
        for n in (l..=20).step_by(2) {
            let z = zernike_polynomial(n, l, m).expect("valid index");
            assert!(!z.is_empty());
            polys.push(((n, l, m), z));
        }
    }
    let mut worst: f64 = 0.0;
    let mut pairs = 0;
    for (i, (a_index, a)) in polys.iter().enumerate() {
        for (b_index, b) in &polys[i..] {
            let same_family = (a_index.1, a_index.2) == (b_index.1, b_index.2);
            if !same_family && a_index.0 != b_index.0 {
                continue;
            }
            pairs += 1;
            let (re, im) = ball_inner_product(a, b);
            let expected = if a_index == b_index { 1.0 } else { 0.0 };
            let error = (re - expected).abs().max(im.abs());
            worst = worst.max(error);
            assert!(
                error < 1e-6,
                "<Z{a_index:?}, Z{b_index:?}> = {re} + {im}i, expected {expected}"
            );
        }
    }
    eprintln!(
        "{} polynomials, {pairs} pairs, worst Gram error {worst:.2e}",
        polys.len()
    );
}

// ---------------------------------------------------------------------------------------------
// Known shapes
// ---------------------------------------------------------------------------------------------

/// A solid ball of radius 0.45 N filled analytically: every cell whose centre is inside.
fn analytic_ball(n: usize) -> VoxelGrid {
    let mut grid = VoxelGrid::new(n, Vec3::ZERO, 1.0);
    let c = n as f64 / 2.0;
    let radius = 0.45 * n as f64;
    for x in 0..n {
        for y in 0..n {
            for z in 0..n {
                let d = [x, y, z].map(|i| i as f64 + 0.5 - c);
                if d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= radius * radius {
                    grid.set([x, y, z], true);
                }
            }
        }
    }
    grid
}

/// The largest l > 0 norm over the largest l = 0 norm with n > 0 (`F_00 = 3/(4 pi)` for
/// every shape, so it says nothing).
fn l_positive_ratio(f: &[f32; ZERNIKE_LEN]) -> f32 {
    let mut l_positive = 0.0f32;
    let mut l_zero = 0.0f32;
    for (i, (n, l)) in zernike_pairs().enumerate() {
        if l > 0 {
            l_positive = l_positive.max(f[i]);
        } else if n > 0 {
            l_zero = l_zero.max(f[i]);
        }
    }
    l_positive / l_zero
}

#[test]
fn solid_ball_has_energy_only_in_l_zero() {
    // A ball is invariant under every rotation, so only the rotation-invariant l = 0
    // components can be non-zero; the voxel staircase leaves a residue with cubic symmetry
    // (l = 4, 6, ...) that shrinks with the resolution.
    let grid = analytic_ball(64);
    grid.validate().expect("valid grid");
    let ball = l_positive_ratio(&zernike::zernike(&grid).expect("ball"));

    // The same through the voxelizer: a sphere mesh with solid fill.
    let options = VoxelizeOptions {
        solid: true,
        ..VoxelizeOptions::default()
    };
    let grid = voxel::voxelize(&sphere(), &options).expect("sphere");
    grid.validate().expect("valid grid");
    let voxelized = l_positive_ratio(&zernike::zernike(&grid).expect("sphere"));

    // Control: a solid cube has strong l = 4 components, so the criterion can fail.
    let mut grid = VoxelGrid::new(64, Vec3::ZERO, 1.0);
    for x in 8..56 {
        for y in 8..56 {
            for z in 8..56 {
                grid.set([x, y, z], true);
            }
        }
    }
    let cube = l_positive_ratio(&zernike::zernike(&grid).expect("cube"));
    eprintln!(
        "max F(l>0) / max F(l=0, n>0): analytic ball {ball:.2e}, voxelized solid sphere \
         {voxelized:.2e}, solid cube {cube:.2e}"
    );
    assert!(ball < 0.01, "analytic ball {ball}");
    assert!(voxelized < 0.01, "voxelized sphere {voxelized}");
    assert!(cube > 0.1, "the cube control {cube}");
}

#[test]
fn a_uniform_ball_matches_its_closed_form() {
    // A uniform ball of radius rho and mass 1 has
    // Omega_n00 = 3/(4 pi) * (1/V_rho) int_{|x|<rho} Z_n00 = 3/(4 pi) sum_i c_i rho^deg_i
    // I(e_i) / (4 pi / 3), summing the terms c_i x^e_i of Z_n00 with I the unit-ball
    // monomial integral, and Omega_nlm = 0 for l > 0. Its RMS radius is sqrt(3/5) rho, so the
    // default normalisation (RMS radius 0.4) gives rho = 0.4 sqrt(5/3). The voxel ball
    // differs from the ball by its staircase, a fraction of a cell at radius 43 cells.
    let grid = analytic_ball(96);
    let f = zernike::zernike(&grid).expect("ball");
    let rho = zernike::DEFAULT_RMS_RADIUS * (5.0f64 / 3.0).sqrt();
    let mut worst: f64 = 0.0;
    for n in (0..=20).step_by(2) {
        let z = zernike_polynomial(n, 0, 0).expect("valid index");
        let integral: f64 = z
            .iter()
            .map(|t| {
                let degree = t.exponents.iter().sum::<usize>() as i32;
                t.re * rho.powi(degree) * ball_monomial_integral(t.exponents)
            })
            .sum();
        let expected = (3.0 / (4.0 * PI)) * integral / (4.0 * PI / 3.0);
        let got = f64::from(f[zernike_index(n, 0).expect("index")]);
        worst = worst.max((got - expected.abs()).abs());
        assert!(
            (got - expected.abs()).abs() < 1e-3,
            "F_{n}0 = {got}, closed form {}",
            expected.abs()
        );
    }
    eprintln!("uniform ball: worst |F_n0 - closed form| = {worst:.2e}");
}

#[test]
fn distinct_shapes_order_sensibly() {
    let sphere = describe(&sphere());
    let cube = describe(&cube());
    let bunny = describe(&load("bunny_trimesh/bunny.ply"));
    let tree = describe(&tree());
    // Near-twins: a slightly squashed sphere, a slightly stretched cube.
    let ellipsoid = describe(&moved(
        &self::sphere(),
        Affine3A::from_scale(Vec3::new(1.0, 1.0, 0.9)),
    ));
    let cuboid = describe(&moved(
        &self::cube(),
        Affine3A::from_scale(Vec3::new(1.1, 1.0, 1.0)),
    ));
    let d = z_diff;
    eprintln!(
        "sphere-cube {:.4} sphere-bunny {:.4} sphere-tree {:.4} cube-bunny {:.4} cube-tree {:.4} \
         bunny-tree {:.4} sphere-ellipsoid {:.4} cube-cuboid {:.4}",
        d(&sphere, &cube),
        d(&sphere, &bunny),
        d(&sphere, &tree),
        d(&cube, &bunny),
        d(&cube, &tree),
        d(&bunny, &tree),
        d(&sphere, &ellipsoid),
        d(&cube, &cuboid),
    );
    // The two convex, centrally symmetric blobs are closer to each other than either is to
    // the bunny or to the tree.
    let blobs = d(&sphere, &cube);
    for other in [&bunny, &tree] {
        assert!(blobs < d(&sphere, other) && blobs < d(&cube, other));
    }
    // A 10% squash or stretch is closer than any two distinct shapes.
    let distinct = [
        d(&sphere, &cube),
        d(&sphere, &bunny),
        d(&sphere, &tree),
        d(&cube, &bunny),
        d(&cube, &tree),
        d(&bunny, &tree),
    ];
    let nearest_distinct = distinct.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(d(&sphere, &ellipsoid) < 0.5 * nearest_distinct);
    assert!(d(&cube, &cuboid) < 0.5 * nearest_distinct);
}

#[test]
fn exact_lattice_symmetries_leave_the_descriptor_unchanged() {
    // A quarter turn about z, an axis swap and a mirror are exact in floating point and map
    // the grid onto itself, and the norms are invariant under all of O(3) (a mirror maps
    // Omega_nl^m to a sign-flipped Omega_nl^-m), so the descriptor may only change by
    // rounding: far below anything a rotation by an arbitrary angle causes.
    let bunny = load("bunny_trimesh/bunny.ply");
    let original = describe(&bunny);
    let quarter_turn =
        Affine3A::from_cols_array(&[0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]);
    let swap =
        Affine3A::from_cols_array(&[0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]);
    let mirror = Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0));
    for (name, motion) in [
        ("quarter turn", quarter_turn),
        ("swap", swap),
        ("mirror", mirror),
    ] {
        let change = z_diff(&original, &describe(&moved(&bunny, motion)));
        assert!(change < 1e-4, "{name}: {change}");
    }
}

// ---------------------------------------------------------------------------------------------
// Invariance under rigid motion with uniform scale
// ---------------------------------------------------------------------------------------------

proptest! {
    // Each case voxelizes two models twice; a few cases already sample rotations well.
    #![proptest_config(ProptestConfig::with_cases(if cfg!(debug_assertions) { 3 } else { 16 }))]

    #[test]
    fn rigid_motion_barely_moves_the_descriptor(u in prop::array::uniform7(0.0f32..1.0)) {
        let motion = motion_from(u);
        let (bunny, block) = fixtures();
        let reference = bunny_block_distance();
        for (name, mesh, original) in [("bunny", &bunny.0, &bunny.1), ("box", &block.0, &block.1)] {
            let copy = describe(&moved(mesh, motion));
            let change = z_diff(original, &copy);
            // Small: a twentieth of the distance between the two shapes themselves (measured:
            // about a hundredth at worst).
            prop_assert!(
                change < 0.05 * reference,
                "{name}: moved copy at z_diff {change}, bunny-box {reference}"
            );
        }
    }
}

type Described = (InstancedMesh, [f32; ZERNIKE_LEN]);

/// The bunny and a 2 x 1 x 0.5 box with their descriptors, computed once.
fn fixtures() -> &'static (Described, Described) {
    static CELL: std::sync::OnceLock<(Described, Described)> = std::sync::OnceLock::new();
    CELL.get_or_init(|| {
        let bunny = load("bunny_trimesh/bunny.ply");
        let block = single(boxed(Vec3::ZERO, Vec3::new(2.0, 1.0, 0.5), 3));
        let (db, dk) = (describe(&bunny), describe(&block));
        ((bunny, db), (block, dk))
    })
}

fn bunny_block_distance() -> f64 {
    let (bunny, block) = fixtures();
    z_diff(&bunny.1, &block.1)
}

#[test]
fn shared_models_are_invariant_relative_to_their_spread() {
    // The descriptors' invariance target: over 20 random rigid motions with uniform scale of
    // each shared model, z_diff between the model and its moved copy stays at most 10% of the
    // median z_diff between distinct shared models. Debug builds try 3 motions per model.
    let motions = if cfg!(debug_assertions) { 3 } else { 20 };
    let mut described = Vec::new();
    for name in SHARED_MODELS {
        let mesh = load(name);
        let started = Instant::now();
        let grid = voxel::voxelize(&mesh, &VoxelizeOptions::default()).expect("voxelize");
        let voxelized = started.elapsed();
        let f = zernike::zernike(&grid).expect("zernike");
        let total = started.elapsed();
        eprintln!(
            "{name}: {} expanded triangles, {} voxels, voxelize {:.1} ms, zernike {:.1} ms",
            mesh.expanded_triangle_count(),
            grid.occupied_count(),
            voxelized.as_secs_f64() * 1e3,
            (total - voxelized).as_secs_f64() * 1e3,
        );
        described.push((name, mesh, f));
    }
    let mut distinct = Vec::new();
    for (i, a) in described.iter().enumerate() {
        for b in &described[i + 1..] {
            distinct.push(z_diff(&a.2, &b.2));
        }
    }
    let median_distinct = median(distinct.clone());
    eprintln!(
        "distinct pairs: median z_diff {median_distinct:.4}, min {:.4}",
        distinct.iter().copied().fold(f64::INFINITY, f64::min)
    );
    let mut rng = Rng::new(0x5EED_0004);
    let mut failures = Vec::new();
    for (name, mesh, f) in &described {
        let mut worst: f64 = 0.0;
        for _ in 0..motions {
            let copy = describe(&moved(mesh, random_motion(&mut rng)));
            worst = worst.max(z_diff(f, &copy));
        }
        let ratio = worst / median_distinct;
        eprintln!("{name}: worst moved z_diff {worst:.4}, ratio {ratio:.3}");
        if ratio > 0.1 {
            failures.push(format!("{name}: {ratio:.3}"));
        }
    }
    assert!(
        failures.is_empty(),
        "moved copies beyond 10% of the median distinct z_diff: {failures:?}"
    );
}
