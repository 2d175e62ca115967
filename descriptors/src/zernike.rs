//! 3D Zernike descriptor of a voxel grid (Novotni and Klein 2004, "Shape retrieval using 3D
//! Zernike descriptors", Computer-Aided Design 36(11), section 3), at order 20: the 121 norms
//! that Azim et al. 2014 (section 4.1) compare with L2.
//!
//! Equations implemented (Novotni and Klein's notation):
//! - the Zernike functions `Z_nl^m(x) = R_nl(|x|) Y_l^m(x/|x|)` for `n <= 20`, `l <= n`,
//!   `n - l = 2k` even, written as polynomials `Z_nl^m(x) = sum_nu q_kl^nu |x|^(2 nu) e_l^m(x)`
//!   where `e_l^m = |x|^l Y_l^m` are the regular solid harmonics;
//! - orthonormality on the unit ball: `3/(4 pi) int Z_nl^m conj(Z_n'l'^m') dx = delta`;
//! - the moments `Omega_nl^m = 3/(4 pi) int f(x) conj(Z_nl^m(x)) dx`, evaluated from geometric
//!   moments as `Omega_nl^m = 3/(4 pi) sum_{r+s+t<=n} conj(chi_nlm^rst) M_rst`;
//! - the rotation-invariant norms `F_nl = ||Omega_nl|| = (sum_{m=-l..l} |Omega_nl^m|^2)^(1/2)`.
//!
//! The solid harmonics come from the associated-Legendre recurrence lifted to polynomials in
//! x, y, z; the radial polynomials are shifted Jacobi polynomials in `|x|^2` (the closed form
//! of Novotni and Klein's `q_kl^nu`, derived here by orthogonality; the integration tests check
//! orthonormality against exact monomial integrals over the ball). Everything is f64 inside.

use std::f64::consts::PI;
use std::sync::OnceLock;

use crate::voxel::VoxelGrid;
use crate::DescriptorError;

/// Maximum order n.
pub const ZERNIKE_ORDER: usize = 20;
/// Number of norms for order 20: the pairs (n, l) with `l <= n <= 20` and `n - l` even.
pub const ZERNIKE_LEN: usize = 121;

/// Exponents per axis in the moment tables: `0..=ZERNIKE_ORDER`.
const DIM: usize = ZERNIKE_ORDER + 1;

/// Root-mean-square radius the solid is scaled to by default (see [`ScaleNormalisation`]).
pub const DEFAULT_RMS_RADIUS: f64 = 0.4;

/// 3D Zernike norms `F_nl` of the shape in `grid`, ordered by n then l (see [`zernike_index`]),
/// with the default [`ZernikeOptions`].
///
/// The grid is read as a solid made of its occupied cells: each a cube of uniform density
/// proportional to the cell's weight (the surface area inside it, for the voxelizer's
/// area-weighted grids; one for unweighted and solid grids). It is normalised in three ways
/// before the moments are taken:
/// - translation: the centre of mass of the cubes becomes the origin;
/// - scale: see [`ScaleNormalisation`]; by default the root-mean-square radius becomes
///   [`DEFAULT_RMS_RADIUS`], unless that would put the farthest corner of an occupied cube
///   beyond radius 1, in which case that corner lands on radius 1. Either way the whole solid
///   (not just the cell centres) lies in the unit ball, where the Zernike functions live;
/// - mass: the density is divided by the total mass (the total weight), so the shape is a
///   density of mass 1. The moments are then averages over the shape rather than sums: a
///   surface voxelized two cells thick gives, to first order, the same descriptor as one
///   voxelized one cell thick, a model does not weigh more for covering more cells or for
///   having more area, and the descriptor does not depend on the voxel count. With this
///   normalisation `F_00 = 3/(4 pi)` for every shape.
///
/// Each cube's moments are integrated exactly (separably, per axis), not sampled at its
/// centre. An empty grid is [`DescriptorError::Empty`]; the result is always finite.
pub fn zernike(grid: &VoxelGrid) -> Result<[f32; ZERNIKE_LEN], DescriptorError> {
    zernike_with(grid, &ZernikeOptions::default())
}

/// [`zernike`] with explicit options.
pub fn zernike_with(
    grid: &VoxelGrid,
    options: &ZernikeOptions,
) -> Result<[f32; ZERNIKE_LEN], DescriptorError> {
    // Translation and scale into the unit ball.
    let frame = BallFrame::of(grid, options.scale).ok_or(DescriptorError::Empty)?;
    // Geometric moments M_rst of the mass-1 density, summed one axis at a time.
    let moments = geometric_moments(grid, &frame);
    // Zernike moments against the chi tables, folded into rotation-invariant norms.
    let norms = zernike_norms(&moments, chi_tables());
    // Non-finite norms cannot arise from a non-empty grid (every quantity above is bounded);
    // refuse rather than hand a NaN to the BVH if one ever did.
    if norms.iter().all(|v| v.is_finite()) {
        Ok(norms)
    } else {
        Err(DescriptorError::Empty)
    }
}

/// Options of [`zernike_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ZernikeOptions {
    /// How the shape is scaled into the unit ball.
    pub scale: ScaleNormalisation,
}

/// How the shape is scaled into the unit ball.
///
/// Why the default is not the farthest point: near radius 1 the order-20 radial functions
/// oscillate fastest. `R_nl(r)` behaves like `J_0((n/2 + 3/4) theta)` with
/// `1 - r ~ theta^2 / 8`, so its outermost lobe is `1 - r < 0.007` thick: under half a cell
/// at the 128^3 grid's scale. The farthest occupied corner is only known to about a cell, so
/// mapping it to radius 1 both jitters the scale by ~1% and puts the far end of every shape
/// where the high orders are most sensitive; the RMS radius averages over every cell. Under
/// rigid motions with uniform scale of the shared models,
/// [`ScaleNormalisation::FarthestCorner`] lets BoxTextured's moved copies drift past a tenth
/// of the median distance between distinct models (the bound `tests/zernike.rs` asserts),
/// while the RMS radius keeps every model well inside it, more so at 0.4 than at 0.5. Novotni
/// and Klein's own code also scales by the RMS radius (to 0.5, cutting off whatever falls
/// outside the ball); the cap here never cuts anything off.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ScaleNormalisation {
    /// The farthest corner of an occupied cube lands on radius 1.
    FarthestCorner,
    /// The root-mean-square radius of the solid lands on the given radius, capped so that
    /// the farthest corner of an occupied cube stays within radius 1 (for shapes whose
    /// farthest point is more than `1 / radius` times their RMS radius). The scale is
    /// continuous in the shape: at the cap both rules agree.
    RmsRadius(f64),
}

impl Default for ScaleNormalisation {
    fn default() -> Self {
        Self::RmsRadius(DEFAULT_RMS_RADIUS)
    }
}

/// Position of `F_nl` in the descriptor, or `None` unless `l <= n <= ZERNIKE_ORDER` and
/// `n - l` is even. Order: n ascending, then l ascending.
pub fn zernike_index(n: usize, l: usize) -> Option<usize> {
    if n > ZERNIKE_ORDER || l > n || !(n - l).is_multiple_of(2) {
        return None;
    }
    // Before order n come sum_{n' < n} (floor(n'/2) + 1) entries.
    let before: usize = (0..n).map(|k| k / 2 + 1).sum();
    Some(before + l / 2)
}

/// The pairs (n, l) in descriptor order.
pub fn zernike_pairs() -> impl Iterator<Item = (usize, usize)> {
    (0..=ZERNIKE_ORDER).flat_map(|n| (n % 2..=n).step_by(2).map(move |l| (n, l)))
}

/// One term `(re + i im) x^r y^s z^t` of a 3D Zernike polynomial.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZernikeTerm {
    /// The exponents `[r, s, t]` of x, y and z.
    pub exponents: [usize; 3],
    /// Real part of the coefficient.
    pub re: f64,
    /// Imaginary part of the coefficient.
    pub im: f64,
}

/// The Cartesian expansion of `Z_nl^m` (the coefficients `chi_nlm^rst`) for `m >= 0`, or
/// `None` for indices outside the order-20 set. Normalised so that
/// `3/(4 pi) int_ball Z conj(Z') = delta`; `Z_nl^-m = (-1)^m conj(Z_nl^m)`.
pub fn zernike_polynomial(n: usize, l: usize, m: usize) -> Option<Vec<ZernikeTerm>> {
    let index = zernike_index(n, l)?;
    if m > l {
        return None;
    }
    let tables = chi_tables();
    let radial = tables.radial.get(index)?;
    let block = tables.harmonics.get(harmonic_index(l, m))?;
    let mut out = Vec::new();
    for (j, &q) in radial.iter().enumerate() {
        let range = block.get(j)?.clone();
        out.extend(tables.terms.get(range)?.iter().map(|t| ZernikeTerm {
            exponents: t.exponents(),
            re: q * t.re,
            im: q * t.im,
        }));
    }
    Some(out)
}

/// The translation and scale that put the grid's solid into the unit ball.
#[derive(Clone, Copy, Debug)]
struct BallFrame {
    /// Centre of mass in grid coordinates (cell `i` spans `[i, i + 1]`).
    centre: [f64; 3],
    /// Grid units to ball units.
    scale: f64,
    /// Total weight of the occupied cells: the mass before normalisation.
    mass: f64,
}

impl BallFrame {
    /// The frame of `grid`'s occupied cubes; `None` for an empty grid.
    fn of(grid: &VoxelGrid, normalisation: ScaleNormalisation) -> Option<Self> {
        let n = grid.resolution;
        // Centre of mass: per column, the weight and the weighted sum of the cell centres
        // along z.
        let mut mass = 0.0;
        let mut sum = [0.0f64; 3];
        let mut cells = WeightedCells::new(grid);
        for x in 0..n {
            for y in 0..n {
                let mut column_count = 0.0;
                let mut column_z = 0.0;
                for (z, w) in cells.column(x, y) {
                    column_count += w;
                    column_z += w * (z as f64 + 0.5);
                }
                mass += column_count;
                sum[0] += column_count * (x as f64 + 0.5);
                sum[1] += column_count * (y as f64 + 0.5);
                sum[2] += column_z;
            }
        }
        if mass <= 0.0 || !mass.is_finite() {
            return None;
        }
        let centre = sum.map(|s| s / mass);
        // Farthest corner: a cube centred at offset d has its farthest corner at
        // |(|d_x| + 1/2, |d_y| + 1/2, |d_z| + 1/2)|; along a column only the lowest and the
        // highest occupied cells can be farthest. The mean squared radius sums every cell.
        let mut farthest2 = 0.0f64;
        let mut sum2 = 0.0;
        let mut cells = WeightedCells::new(grid);
        for x in 0..n {
            for y in 0..n {
                let Some((lo, hi)) = grid.column_extent(x, y) else {
                    continue;
                };
                let dx = x as f64 + 0.5 - centre[0];
                let dy = y as f64 + 0.5 - centre[1];
                let dz = (lo as f64 + 0.5 - centre[2])
                    .abs()
                    .max((hi as f64 + 0.5 - centre[2]).abs());
                let far = [dx.abs() + 0.5, dy.abs() + 0.5, dz + 0.5];
                farthest2 = farthest2.max(far[0] * far[0] + far[1] * far[1] + far[2] * far[2]);
                for (z, w) in cells.column(x, y) {
                    let dz = z as f64 + 0.5 - centre[2];
                    sum2 += w * (dx * dx + dy * dy + dz * dz);
                }
            }
        }
        // Every cube has a corner at least sqrt(3)/2 from any point, so farthest > 0.
        let farthest = farthest2.sqrt();
        // A unit cube adds 3/12 to the mean squared radius of its centre.
        let rms = (sum2 / mass + 0.25).sqrt();
        let scale = match normalisation {
            ScaleNormalisation::FarthestCorner => 1.0 / farthest,
            // A non-finite or non-positive target falls back on the cap alone.
            ScaleNormalisation::RmsRadius(r) if r.is_finite() && r > 0.0 => {
                (r / rms).min(1.0 / farthest)
            }
            ScaleNormalisation::RmsRadius(_) => 1.0 / farthest,
        };
        Some(Self {
            centre,
            scale,
            mass,
        })
    }
}

/// Geometric moments `M_rst = int f x^r y^s z^t` for `r + s + t <= ZERNIKE_ORDER` of the
/// mass-1 density on the occupied cubes, in ball coordinates, stored densely at
/// `(r * DIM + s) * DIM + t`.
///
/// Separable summation: with `P_a[i][p]` the mean of `u^p` over cell i along axis a and
/// `w_xyz` the cell weights, `M_rst = (1/mass) sum_x P_x[x][r] sum_y P_y[y][s] sum_z w_xyz
/// P_z[z][t]`. Each occupied cell adds one row of `P_z` to its column's sums (21
/// multiply-adds), each non-empty column folds into its x slice (231), and each x slice into
/// the moments (1771); never one voxel times one moment.
fn geometric_moments(grid: &VoxelGrid, frame: &BallFrame) -> Vec<f64> {
    let n = grid.resolution;
    let table = |axis: usize| axis_table(n, frame.centre[axis], frame.scale);
    let (px, py, pz) = (table(0), table(1), table(2));
    let mut moments = vec![0.0; DIM * DIM * DIM];
    let mut slice = [0.0f64; DIM * DIM];
    let mut cells = WeightedCells::new(grid);
    for (x, px_row) in px.iter().enumerate() {
        slice.fill(0.0);
        let mut slice_used = false;
        for (y, py_row) in py.iter().enumerate() {
            // Fold z: sum of P_z rows over the column's occupied cells.
            let mut column = [0.0f64; DIM];
            let mut used = false;
            for (z, w) in cells.column(x, y) {
                used = true;
                if let Some(row) = pz.get(z) {
                    for (c, p) in column.iter_mut().zip(row) {
                        *c += w * p;
                    }
                }
            }
            if !used {
                continue;
            }
            // Fold y into the slice's (s, t) sums.
            slice_used = true;
            for (s, &w) in py_row.iter().enumerate() {
                let row = &mut slice[s * DIM..s * DIM + DIM - s];
                for (acc, c) in row.iter_mut().zip(&column) {
                    *acc += w * c;
                }
            }
        }
        if !slice_used {
            continue;
        }
        // Fold x into the moments.
        for (r, &w) in px_row.iter().enumerate() {
            for s in 0..DIM - r {
                let out = &mut moments[(r * DIM + s) * DIM..(r * DIM + s) * DIM + DIM - r - s];
                for (acc, v) in out.iter_mut().zip(&slice[s * DIM..]) {
                    *acc += w * v;
                }
            }
        }
    }
    let inverse_mass = 1.0 / frame.mass;
    for m in &mut moments {
        *m *= inverse_mass;
    }
    moments
}

/// Per-axis table: for each of the `n` cells, the mean of `u^p` (p = 0..=ZERNIKE_ORDER) over
/// the cell, where `u = (g - centre) * scale` maps grid coordinate g into the ball.
///
/// Over `[a - h, a + h]` the mean of `u^p` is `sum_{j even} C(p, j) a^(p-j) h^j / (j + 1)`:
/// the odd terms cancel, and the even ones all share the sign of `a^p`, so nothing cancels.
fn axis_table(n: usize, centre: f64, scale: f64) -> Vec<[f64; DIM]> {
    let binomial = binomials();
    let h = 0.5 * scale;
    let mut h_pow = [1.0f64; DIM];
    for j in 1..DIM {
        h_pow[j] = h_pow[j - 1] * h;
    }
    (0..n)
        .map(|i| {
            let a = (i as f64 + 0.5 - centre) * scale;
            let mut a_pow = [1.0f64; DIM];
            for j in 1..DIM {
                a_pow[j] = a_pow[j - 1] * a;
            }
            let mut row = [0.0f64; DIM];
            for (p, out) in row.iter_mut().enumerate() {
                *out = (0..=p)
                    .step_by(2)
                    .map(|j| binomial[p][j] * a_pow[p - j] * h_pow[j] / (j + 1) as f64)
                    .sum();
            }
            row
        })
        .collect()
}

/// `F_nl = 3/(4 pi) (|H_nl0|^2 + 2 sum_{m>0} |H_nlm|^2)^(1/2)` with
/// `H_nlm = sum_rst conj(chi_nlm^rst) M_rst`.
///
/// Only `m >= 0` is evaluated: for a real density `Omega_nl^-m = (-1)^m conj(Omega_nl^m)`, so
/// the negative orders repeat the positive ones' magnitudes. The chi tables factor as a radial
/// coefficient times a harmonic term (see [`ChiTables`]): the harmonic sums
/// `G_lmj = sum conj(coef(|x|^(2j) e_l^m)) M` are shared by every n, and each
/// `H_nlm = sum_j q_kl^j G_lmj`.
fn zernike_norms(moments: &[f64], tables: &ChiTables) -> [f32; ZERNIKE_LEN] {
    // Harmonic sums per (l, m, j).
    let harmonic_sums: Vec<Vec<(f64, f64)>> = tables
        .harmonics
        .iter()
        .map(|block| {
            block
                .iter()
                .map(|range| {
                    tables.terms[range.clone()]
                        .iter()
                        .fold((0.0, 0.0), |(re, im), t| {
                            let m = moments[t.index as usize];
                            // conj(coefficient) * M
                            (re + t.re * m, im - t.im * m)
                        })
                })
                .collect()
        })
        .collect();
    let mut out = [0.0f32; ZERNIKE_LEN];
    for ((slot, (_, l)), radial) in out.iter_mut().zip(zernike_pairs()).zip(&tables.radial) {
        let mut energy = 0.0;
        for m in 0..=l {
            let sums = &harmonic_sums[harmonic_index(l, m)];
            let (re, im) = radial
                .iter()
                .zip(sums)
                .fold((0.0, 0.0), |(re, im), (q, s)| (re + q * s.0, im + q * s.1));
            let weight = if m == 0 { 1.0 } else { 2.0 };
            energy += weight * (re * re + im * im);
        }
        *slot = (3.0 / (4.0 * PI) * energy.sqrt()) as f32;
    }
    out
}

/// The chi coefficient tables, built once.
///
/// `chi_nlm^rst` factors as `q_kl^j * coef_rst(|x|^(2j) e_l^m)` where `r + s + t = l + 2j`:
/// each polynomial `|x|^(2j) e_l^m` is homogeneous of its own degree, so the terms of different
/// j never overlap and `Z_nl^m` is the concatenation of the scaled blocks. Storing the blocks
/// once per (l, m, j) and the radial coefficients once per (n, l) keeps the table small
/// (tens of thousands of terms instead of the ~200k of the expanded chi).
#[derive(Debug)]
struct ChiTables {
    /// All harmonic terms, block after block.
    terms: Vec<ChiTerm>,
    /// For each (l, m) at [`harmonic_index`], the range of `terms` holding
    /// `|x|^(2j) e_l^m` for `j = 0..=(ZERNIKE_ORDER - l) / 2`.
    harmonics: Vec<Vec<std::ops::Range<usize>>>,
    /// For each (n, l) in descriptor order, `q_kl^j` for `j = 0..=k`, including the
    /// normalisation `sqrt(4 pi (2n + 3) / 3)` of the radial function.
    radial: Vec<Vec<f64>>,
}

/// One monomial of a harmonic block.
#[derive(Clone, Copy, Debug)]
struct ChiTerm {
    /// Dense moment index `(r * DIM + s) * DIM + t`.
    index: u16,
    /// Real part of the coefficient.
    re: f64,
    /// Imaginary part of the coefficient.
    im: f64,
}

impl ChiTerm {
    fn exponents(&self) -> [usize; 3] {
        let i = self.index as usize;
        [i / (DIM * DIM), i / DIM % DIM, i % DIM]
    }
}

/// Position of (l, m), `m <= l <= ZERNIKE_ORDER`, in [`ChiTables::harmonics`].
fn harmonic_index(l: usize, m: usize) -> usize {
    l * (l + 1) / 2 + m
}

/// The tables, built on first use.
fn chi_tables() -> &'static ChiTables {
    static TABLES: OnceLock<ChiTables> = OnceLock::new();
    TABLES.get_or_init(build_chi_tables)
}

/// Builds the harmonic blocks and the radial coefficients.
fn build_chi_tables() -> ChiTables {
    let mut terms = Vec::new();
    let mut harmonics = vec![Vec::new(); harmonic_index(ZERNIKE_ORDER, ZERNIKE_ORDER) + 1];
    for m in 0..=ZERNIKE_ORDER {
        for (l, e) in solid_harmonics(m).into_iter().enumerate().skip(m) {
            // |x|^(2j) e_l^m for every j the order allows.
            let mut p = e;
            let mut blocks = Vec::new();
            loop {
                let start = terms.len();
                terms.extend(p.terms());
                blocks.push(start..terms.len());
                if p.degree + 2 > ZERNIKE_ORDER {
                    break;
                }
                p = p.times_r2();
            }
            harmonics[harmonic_index(l, m)] = blocks;
        }
    }
    let radial = zernike_pairs()
        .map(|(n, l)| radial_coefficients(n, l))
        .collect();
    ChiTables {
        terms,
        harmonics,
        radial,
    }
}

/// `q_kl^j`, j = 0..=k with k = (n - l)/2: the radial function is
/// `R_nl(r) = sum_j q_kl^j r^(l + 2j)`, orthonormal in the sense
/// `3/(4 pi) int_0^1 R_nl R_n'l r^2 dr = delta / (4 pi)` (the sphere's share comes from the
/// unit-norm spherical harmonics).
///
/// With `t = r^2` the condition is orthogonality on [0, 1] with weight `t^(l + 1/2)`, whose
/// orthogonal polynomials are the shifted Jacobi polynomials `P_k^(0, l+1/2)(2t - 1)`:
/// `G_k(t) = (1/k!) sum_j (-1)^j C(k, j) prod_{i=1..k} (l + 1/2 + j + i) t^j`, with
/// `int_0^1 t^(l+1/2) G_k^2 dt = 1/(2k + l + 3/2)`. Then `int_0^1 r^(2l+2) G_k(r^2)^2 dr =
/// 1/(2n + 3)`, so the factor `sqrt(4 pi (2n + 3) / 3)` makes the ball integral one.
fn radial_coefficients(n: usize, l: usize) -> Vec<f64> {
    let k = (n - l) / 2;
    let beta = l as f64 + 0.5;
    let k_factorial: f64 = (1..=k).map(|i| i as f64).product();
    let norm = (4.0 * PI * (2 * n + 3) as f64 / 3.0).sqrt();
    let binomial = binomials();
    (0..=k)
        .map(|j| {
            let rising: f64 = (1..=k).map(|i| beta + (j + i) as f64).product();
            let sign = if j % 2 == 0 { 1.0 } else { -1.0 };
            norm * sign * binomial[k][j] * rising / k_factorial
        })
        .collect()
}

/// The regular solid harmonics `e_l^m = |x|^l Y_l^m` for l = 0..=ZERNIKE_ORDER at fixed
/// `m >= 0` (zero polynomials below l = m), with `Y_l^m` of unit norm on the sphere.
///
/// Lifted associated-Legendre recurrence on `R_l^m = |x|^l P_l^m(z/|x|) e^(i m phi)`:
/// `R_m^m = (2m - 1)!! (x + iy)^m` (the Condon-Shortley sign is dropped: it does not change
/// any norm), `R_(m+1)^m = (2m + 1) z R_m^m`, and
/// `(l - m + 1) R_(l+1)^m = (2l + 1) z R_l^m - (l + m) |x|^2 R_(l-1)^m`. Then
/// `e_l^m = sqrt((2l + 1)/(4 pi) (l - m)!/(l + m)!) R_l^m`.
fn solid_harmonics(m: usize) -> Vec<Homogeneous> {
    let mut r = vec![Homogeneous::zero(0); ZERNIKE_ORDER + 1];
    let double_factorial: f64 = (1..=m).map(|i| (2 * i - 1) as f64).product();
    let mut seed = Homogeneous::one();
    for _ in 0..m {
        seed = seed.times_x_plus_iy();
    }
    r[m] = seed.scaled(double_factorial);
    if m < ZERNIKE_ORDER {
        r[m + 1] = r[m].times_z().scaled((2 * m + 1) as f64);
    }
    for l in m + 1..ZERNIKE_ORDER {
        let a = r[l].times_z().scaled((2 * l + 1) as f64);
        let b = r[l - 1].times_r2().scaled((l + m) as f64);
        r[l + 1] = a.minus(&b).scaled(1.0 / (l - m + 1) as f64);
    }
    for (l, p) in r.iter_mut().enumerate().skip(m) {
        // (l - m)! / (l + m)! as a product of reciprocals, to stay in range.
        let ratio: f64 = (l - m + 1..=l + m).map(|i| 1.0 / i as f64).product();
        let norm = ((2 * l + 1) as f64 / (4.0 * PI) * ratio).sqrt();
        *p = p.scaled(norm);
    }
    r
}

/// A homogeneous polynomial of degree `degree` in x, y, z with complex coefficients, dense
/// over the exponents (a, b) of x and y (the exponent of z is `degree - a - b`).
#[derive(Clone, Debug)]
struct Homogeneous {
    /// Total degree of every monomial.
    degree: usize,
    /// Real parts at `a * DIM + b`.
    re: Vec<f64>,
    /// Imaginary parts at `a * DIM + b`.
    im: Vec<f64>,
}

impl Homogeneous {
    fn zero(degree: usize) -> Self {
        Self {
            degree,
            re: vec![0.0; DIM * DIM],
            im: vec![0.0; DIM * DIM],
        }
    }

    fn one() -> Self {
        let mut p = Self::zero(0);
        p.re[0] = 1.0;
        p
    }

    /// The (a, b) exponents present at this degree.
    fn exponents(&self) -> impl Iterator<Item = (usize, usize)> {
        let d = self.degree;
        (0..=d).flat_map(move |a| (0..=d - a).map(move |b| (a, b)))
    }

    fn scaled(&self, k: f64) -> Self {
        Self {
            degree: self.degree,
            re: self.re.iter().map(|v| v * k).collect(),
            im: self.im.iter().map(|v| v * k).collect(),
        }
    }

    fn minus(&self, other: &Self) -> Self {
        debug_assert_eq!(self.degree, other.degree);
        Self {
            degree: self.degree,
            re: self.re.iter().zip(&other.re).map(|(a, b)| a - b).collect(),
            im: self.im.iter().zip(&other.im).map(|(a, b)| a - b).collect(),
        }
    }

    /// Times z: same (a, b), one degree more.
    fn times_z(&self) -> Self {
        Self {
            degree: self.degree + 1,
            re: self.re.clone(),
            im: self.im.clone(),
        }
    }

    /// Times `x^2 + y^2 + z^2`.
    fn times_r2(&self) -> Self {
        let mut out = Self::zero(self.degree + 2);
        for (a, b) in self.exponents() {
            let (re, im) = (self.re[a * DIM + b], self.im[a * DIM + b]);
            for target in [(a + 2) * DIM + b, a * DIM + b + 2, a * DIM + b] {
                out.re[target] += re;
                out.im[target] += im;
            }
        }
        out
    }

    /// Times `x + iy`.
    fn times_x_plus_iy(&self) -> Self {
        let mut out = Self::zero(self.degree + 1);
        for (a, b) in self.exponents() {
            let (re, im) = (self.re[a * DIM + b], self.im[a * DIM + b]);
            out.re[(a + 1) * DIM + b] += re;
            out.im[(a + 1) * DIM + b] += im;
            // i * (re + i im) = -im + i re
            out.re[a * DIM + b + 1] -= im;
            out.im[a * DIM + b + 1] += re;
        }
        out
    }

    /// The non-zero terms, as moment-table entries.
    fn terms(&self) -> Vec<ChiTerm> {
        self.exponents()
            .filter_map(|(a, b)| {
                let (re, im) = (self.re[a * DIM + b], self.im[a * DIM + b]);
                let c = self.degree - a - b;
                ((re, im) != (0.0, 0.0)).then_some(ChiTerm {
                    index: ((a * DIM + b) * DIM + c) as u16,
                    re,
                    im,
                })
            })
            .collect()
    }
}

/// Binomial coefficients `C(p, j)` for `p, j <= ZERNIKE_ORDER`, exact in f64.
fn binomials() -> [[f64; DIM]; DIM] {
    let mut c = [[0.0f64; DIM]; DIM];
    for p in 0..DIM {
        c[p][0] = 1.0;
        for j in 1..=p {
            c[p][j] = c[p - 1][j - 1] + if j < p { c[p - 1][j] } else { 0.0 };
        }
    }
    c
}

/// Walks the occupied cells column by column, in grid order, with their weights (one when the
/// grid has none). Weights are stored by rank, so the columns must be asked for in grid
/// order and each column's cells consumed in full.
struct WeightedCells<'a> {
    /// The grid walked.
    grid: &'a VoxelGrid,
    /// Its weights, if any.
    weights: Option<&'a [f32]>,
    /// Rank of the next occupied cell.
    next: usize,
}

impl<'a> WeightedCells<'a> {
    fn new(grid: &'a VoxelGrid) -> Self {
        Self {
            grid,
            weights: grid.weights(),
            next: 0,
        }
    }

    /// The cells of column (x, y) with their weights; (x, y) must come after the previous
    /// column asked for.
    fn column(&mut self, x: usize, y: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let weights = self.weights;
        let next = &mut self.next;
        self.grid.column_cells(x, y).map(move |z| {
            let w = weights.map_or(1.0, |w| f64::from(w.get(*next).copied().unwrap_or(0.0)));
            *next += 1;
            (z, w)
        })
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    #[test]
    fn index_covers_121_slots_in_order() {
        let pairs: Vec<_> = zernike_pairs().collect();
        assert_eq!(pairs.len(), ZERNIKE_LEN);
        for (i, &(n, l)) in pairs.iter().enumerate() {
            assert_eq!(zernike_index(n, l), Some(i));
        }
        assert_eq!(zernike_index(3, 2), None);
        assert_eq!(zernike_index(21, 1), None);
        assert_eq!(zernike_index(2, 4), None);
        assert_eq!(pairs[ZERNIKE_LEN - 1], (20, 20));
    }

    #[test]
    fn low_order_polynomials_have_known_forms() {
        // Z_000 = 1: 3/(4 pi) int_ball 1 = 1.
        let z = zernike_polynomial(0, 0, 0).expect("valid");
        assert_eq!(z.len(), 1);
        assert!((z[0].re - 1.0).abs() < 1e-12 && z[0].im == 0.0);
        // Z_110 = sqrt(5) z: r Y_10 = sqrt(3/(4 pi)) z times the radial norm sqrt(4 pi 5/3).
        let z = zernike_polynomial(1, 1, 0).expect("valid");
        assert_eq!(z.len(), 1);
        assert_eq!(z[0].exponents, [0, 0, 1]);
        assert!((z[0].re - 5f64.sqrt()).abs() < 1e-12);
        assert!(zernike_polynomial(2, 1, 0).is_none());
        assert!(zernike_polynomial(2, 2, 3).is_none());
    }

    #[test]
    fn axis_table_means_are_exact() {
        // Cell 0 of a unit grid centred at 0.5 spans u in [-0.5 s, 0.5 s]: the mean of u^2 is
        // (s/2)^2 / 3 and of odd powers zero.
        let t = axis_table(1, 0.5, 2.0);
        assert!((t[0][0] - 1.0).abs() < 1e-15);
        assert!(t[0][1].abs() < 1e-15);
        assert!((t[0][2] - 1.0 / 3.0).abs() < 1e-15);
        // Cell 1 maps to u in [1, 3]: the mean of u^3 is (3^4 - 1^4) / 4 / 2 = 10.
        let t = axis_table(2, 0.5, 2.0);
        assert!((t[1][3] - 10.0).abs() < 1e-12);
    }

    #[test]
    fn empty_grid_is_an_error_and_one_cell_is_finite() {
        let mut grid = VoxelGrid::new(8, Vec3::ZERO, 1.0);
        assert_eq!(zernike(&grid), Err(DescriptorError::Empty));
        grid.set([3, 4, 5], true);
        let f = zernike(&grid).expect("one cell");
        assert!(f.iter().all(|v| v.is_finite()));
        // Mass normalisation: F_00 = 3/(4 pi) for any shape.
        assert!((f64::from(f[0]) - 3.0 / (4.0 * PI)).abs() < 1e-6);
        grid.validate().expect("valid grid");
    }
}
