//! Seeded value noise (lattice noise with smooth interpolation, Perlin 1985 style) in 2D and 3D,
//! with fractal sums. Used for textures, terrain and the weathering of stones.
//!
//! Everything is a pure function of the seed and the coordinates, so a deformation computed
//! from noise moves coincident vertices identically and keeps welded surfaces closed.

use glam::Vec3;

use crate::rng::mix;

/// A hash of a lattice point to `[0, 1)`.
fn lattice(seed: u64, x: i64, y: i64, z: i64) -> f32 {
    let h = mix(seed ^ mix((x as u64) ^ mix((y as u64) ^ mix(z as u64))));
    (h >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

/// Quintic fade, C2-continuous at lattice points.
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// 2D value noise in `[0, 1)` with one lattice cell per unit. With `period`, the lattice wraps
/// every `period` cells, so the noise tiles (for textures with repeat wrapping).
pub fn value2(seed: u64, x: f32, y: f32, period: Option<i64>) -> f32 {
    let (fx, fy) = (x.floor(), y.floor());
    let (tx, ty) = (fade(x - fx), fade(y - fy));
    let wrap = |i: i64| period.map_or(i, |p| i.rem_euclid(p));
    let (x0, y0) = (fx as i64, fy as i64);
    let corner = |dx: i64, dy: i64| lattice(seed, wrap(x0 + dx), wrap(y0 + dy), 0);
    lerp(
        lerp(corner(0, 0), corner(1, 0), tx),
        lerp(corner(0, 1), corner(1, 1), tx),
        ty,
    )
}

/// Tileable fractal noise over the unit square: `octaves` layers, the first with `cells` lattice
/// cells across, each next with twice the cells and half the amplitude. Result in `[0, 1)`.
pub fn tileable_fbm(seed: u64, u: f32, v: f32, cells: i64, octaves: u32) -> f32 {
    let (mut sum, mut norm, mut amp, mut c) = (0.0, 0.0, 1.0, cells);
    for o in 0..octaves {
        sum += amp
            * value2(
                seed.wrapping_add(u64::from(o)),
                u * c as f32,
                v * c as f32,
                Some(c),
            );
        norm += amp;
        amp *= 0.5;
        c *= 2;
    }
    sum / norm
}

/// Tileable anisotropic fractal noise: like [`tileable_fbm`] with separate cell counts along u
/// and v (for streaky bark and wood grain).
pub fn tileable_fbm_aniso(seed: u64, u: f32, v: f32, cells: (i64, i64), octaves: u32) -> f32 {
    let (mut sum, mut norm, mut amp) = (0.0, 0.0, 1.0);
    let (mut cu, mut cv) = cells;
    for o in 0..octaves {
        // Wrap each axis separately by sampling a lattice that is periodic in both.
        let n = value2_periodic(
            seed.wrapping_add(u64::from(o)),
            u * cu as f32,
            v * cv as f32,
            (cu, cv),
        );
        sum += amp * n;
        norm += amp;
        amp *= 0.5;
        cu *= 2;
        cv *= 2;
    }
    sum / norm
}

/// 2D value noise whose lattice wraps every `period.0` cells along x and `period.1` along y.
fn value2_periodic(seed: u64, x: f32, y: f32, period: (i64, i64)) -> f32 {
    let (fx, fy) = (x.floor(), y.floor());
    let (tx, ty) = (fade(x - fx), fade(y - fy));
    let (x0, y0) = (fx as i64, fy as i64);
    let corner = |dx: i64, dy: i64| {
        lattice(
            seed,
            (x0 + dx).rem_euclid(period.0),
            (y0 + dy).rem_euclid(period.1),
            0,
        )
    };
    lerp(
        lerp(corner(0, 0), corner(1, 0), tx),
        lerp(corner(0, 1), corner(1, 1), tx),
        ty,
    )
}

/// 3D value noise in `[0, 1)` with one lattice cell per unit.
pub fn value3(seed: u64, p: Vec3) -> f32 {
    let f = p.floor();
    let t = p - f;
    let (tx, ty, tz) = (fade(t.x), fade(t.y), fade(t.z));
    let (x0, y0, z0) = (f.x as i64, f.y as i64, f.z as i64);
    let c = |dx: i64, dy: i64, dz: i64| lattice(seed, x0 + dx, y0 + dy, z0 + dz);
    let face = |dz: i64| {
        lerp(
            lerp(c(0, 0, dz), c(1, 0, dz), tx),
            lerp(c(0, 1, dz), c(1, 1, dz), tx),
            ty,
        )
    };
    lerp(face(0), face(1), tz)
}

/// 3D fractal noise in `[0, 1)`: `octaves` layers of [`value3`], doubling in frequency.
pub fn fbm3(seed: u64, p: Vec3, octaves: u32) -> f32 {
    let (mut sum, mut norm, mut amp, mut freq) = (0.0, 0.0, 1.0, 1.0);
    for o in 0..octaves {
        sum += amp * value3(seed.wrapping_add(u64::from(o)), p * freq);
        norm += amp;
        amp *= 0.5;
        freq *= 2.0;
    }
    sum / norm
}

/// A hash of integer cell coordinates to `[0, 1)`, for per-cell choices in textures.
pub fn cell_hash(seed: u64, x: i64, y: i64) -> f32 {
    lattice(seed, x, y, 7)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tileable_noise_wraps_at_the_unit_square() {
        for k in 0..20 {
            let v = k as f32 / 20.0;
            let a = tileable_fbm(3, 0.0, v, 4, 3);
            let b = tileable_fbm(3, 1.0, v, 4, 3);
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
            let c = tileable_fbm_aniso(3, v, 0.0, (8, 2), 3);
            let d = tileable_fbm_aniso(3, v, 1.0, (8, 2), 3);
            assert!((c - d).abs() < 1e-5, "{c} vs {d}");
        }
    }

    #[test]
    fn noise_stays_in_the_unit_interval() {
        for k in 0..500 {
            let p = Vec3::new(k as f32 * 0.37, k as f32 * -0.11, 2.5);
            let n = fbm3(9, p, 4);
            assert!((0.0..1.0).contains(&n));
        }
    }
}
