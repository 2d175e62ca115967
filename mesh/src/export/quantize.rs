//! Quantization (KHR_mesh_quantization): positions as unsigned 16-bit integers on a grid over
//! their run's box, and unit vectors, UVs, colours and rotations as normalized integers.
//!
//! A run's positions are quantized where that keeps every vertex, in every placement, within
//! the position tolerance in world space ([`Dequantize::fits`]), else they stay float;
//! compression quantizes every submesh over its own box, whatever the tolerance. One step
//! serves all three axes, so stored positions map back to model space by an offset and a
//! uniform scale ([`Dequantize`]), which a TRS node or instance can carry (see
//! `instancing.rs`).

use glam::{Affine3A, Quat, Vec3};

use super::attributes::{type_name, Attribute, BYTE, SHORT, UNSIGNED_SHORT};
use crate::model::Aabb;
use crate::transform::Trs;

/// Steps of a 16-bit quantisation grid across its box.
pub(super) const STEPS: f32 = 65535.0;

/// How stored positions map back to model space: `offset + step * stored`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Dequantize {
    pub(super) offset: Vec3,
    pub(super) step: f32,
}

impl Dequantize {
    /// Float positions, stored as they are.
    pub(super) const NONE: Self = Self {
        offset: Vec3::ZERO,
        step: 1.0,
    };

    pub(super) fn affine(&self) -> Affine3A {
        Affine3A::from_scale_rotation_translation(
            Vec3::splat(self.step),
            Quat::IDENTITY,
            self.offset,
        )
    }

    /// The translation of an instance placed by `trs` under a node scaled by the step (see
    /// `instancing.rs`): where it puts stored position zero, in units of the step. The offset
    /// is turned by `rotation`, the instance's rotation as a reader will decode it, so that
    /// rounding the rotation turns the vertices about the instance's origin exactly as it does
    /// with float positions, and moves them no further.
    pub(super) fn instance_translation(&self, trs: &Trs, rotation: Quat) -> Vec3 {
        (trs.translation + rotation * (trs.scale * self.offset)) / self.step
    }

    /// Whether placing these stored positions by `placed` stays finite both ways they are
    /// written (a node matrix, or an instance under a scaled node, with room to spare for the
    /// rotation a reader decodes), and keeps every vertex within `tolerance` of its place in
    /// every placement: rounding moves a stored position by at most half a step on each axis,
    /// which a placement stretches by at most [`rounding_stretch`].
    pub(super) fn fits(&self, placed: &[Affine3A], tolerance: f32) -> bool {
        self.affine().is_finite()
            && placed.iter().all(|t| {
                let origin = t.transform_point3(self.offset) / self.step;
                (*t * self.affine()).is_finite()
                    && origin.abs().max_element() < f32::MAX / 2.0
                    && self.step * rounding_stretch(t) <= tolerance
            })
    }

    /// The largest box extent whose 16-bit step keeps positions placed by `placed` within
    /// `tolerance` ([`Dequantize::fits`]' bound, solved for the extent); unbounded for a
    /// submesh placed nowhere, zero (float positions) for a tolerance that is not a positive
    /// number.
    pub(super) fn reach(placed: &[Affine3A], tolerance: f32) -> f32 {
        let stretch = placed.iter().map(rounding_stretch).fold(0.0f32, f32::max);
        if tolerance.is_nan() || tolerance <= 0.0 {
            0.0
        } else if stretch > 0.0 {
            // The step is rounded up by under a tenth (`short_step`).
            tolerance / stretch * STEPS / 1.1
        } else {
            f32::INFINITY
        }
    }
}

/// How far, in steps, a placement can move a position that rounding moved by up to half a step
/// on each axis: the longest image under its linear part of a half-step box's corner,
/// `(+-1/2, +-1/2, +-1/2)`. For a TRS placement that is half the length of its scale vector;
/// shear can stretch a diagonal further than any axis.
fn rounding_stretch(t: &Affine3A) -> f32 {
    const CORNERS: [Vec3; 4] = [
        Vec3::new(0.5, 0.5, 0.5),
        Vec3::new(0.5, 0.5, -0.5),
        Vec3::new(0.5, -0.5, 0.5),
        Vec3::new(-0.5, 0.5, 0.5),
    ];
    CORNERS
        .iter()
        .map(|&c| (t.matrix3 * c).length())
        .fold(0.0f32, f32::max)
}

/// The 16-bit grid over the box of `positions`, one step for all axes so that the
/// dequantisation is a uniform scale (which a TRS node or instance can carry); with `short`,
/// the step rounded up to two significant digits ([`short_step`]).
pub(super) fn grid(positions: impl Iterator<Item = Vec3>, short: bool) -> Dequantize {
    let mut bounds = Aabb::EMPTY;
    positions.for_each(|p| bounds.grow(p));
    if bounds.is_empty() {
        return Dequantize {
            offset: Vec3::ZERO,
            step: 1.0,
        };
    }
    let extent = (bounds.max - bounds.min).max_element();
    // A step below f32's normal range rounds positions past the grid's 65,535 steps (and
    // one of zero or infinity has no grid): such a box is stored on a step that fits nothing
    // (infinite), which `fits` refuses, so its positions stay float.
    let step = match extent / STEPS {
        step if step.is_normal() && short => short_step(step),
        step if step.is_normal() => step,
        _ if extent == 0.0 => 1.0,
        _ => f32::INFINITY,
    };
    Dequantize {
        offset: bounds.min,
        step,
    }
}

/// The least number of two significant decimal digits at or above `step` (which it exceeds
/// by under a tenth): every GPU-instanced node of a quantized run carries the step as its
/// scale, and "0.000016" is a third of the JSON of "1.5259021896696422e-5".
fn short_step(step: f32) -> f32 {
    if !step.is_normal() {
        return step;
    }
    let exponent = step.log10().floor() as i32 - 1;
    let unit = 10f64.powi(exponent);
    let mut short = ((f64::from(step) / unit).ceil() * unit) as f32;
    // Rounding to f32 can land just under; the next f32 up is at or above.
    while short < step {
        short = f32::from_bits(short.to_bits() + 1);
    }
    if short.is_finite() {
        short
    } else {
        step
    }
}

/// `positions` as unsigned 16-bit integers on grid `d` (see [`grid`]), each padded to 8 bytes.
pub(super) fn quantized_attribute(
    positions: impl Iterator<Item = Vec3>,
    d: &Dequantize,
) -> Attribute {
    let mut bytes = Vec::new();
    let mut lo = [u16::MAX; 3];
    let mut hi = [0u16; 3];
    let mut count = 0;
    for p in positions {
        let q = ((p - d.offset) / d.step).round();
        for c in 0..3 {
            let x = q[c].clamp(0.0, STEPS) as u16;
            lo[c] = lo[c].min(x);
            hi[c] = hi[c].max(x);
            bytes.extend_from_slice(&x.to_le_bytes());
        }
        // Vertex attributes must start on 4-byte boundaries, so pad each element to 8 bytes.
        bytes.extend_from_slice(&[0, 0]);
        count += 1;
    }
    let bounds = (count > 0).then(|| {
        (
            lo.iter().map(|&x| f32::from(x)).collect(),
            hi.iter().map(|&x| f32::from(x)).collect(),
        )
    });
    Attribute {
        bytes,
        stride: 8,
        component_type: UNSIGNED_SHORT,
        normalized: false,
        type_name: "VEC3",
        count,
        bounds,
    }
}

/// Unit vectors as signed normalized bytes, padded to 4 bytes per element.
pub(super) fn snorm8_attribute(values: impl Iterator<Item = [f32; 3]>) -> Attribute {
    let mut bytes = Vec::new();
    let mut count = 0;
    for v in values {
        for x in v {
            bytes.push(meshopt::quantize_snorm(x, 8) as i8 as u8);
        }
        bytes.push(0);
        count += 1;
    }
    Attribute {
        bytes,
        stride: 4,
        component_type: BYTE,
        normalized: true,
        type_name: "VEC3",
        count,
        bounds: None,
    }
}

/// Values as normalized 16-bit integers (VEC2 or VEC4, already aligned): signed for values in
/// [-1, 1] (unit quaternions), unsigned for values in [0, 1] (UVs, colours).
pub(super) fn norm16_attribute<const N: usize>(
    values: impl Iterator<Item = [f32; N]>,
    signed: bool,
) -> Attribute {
    let mut bytes = Vec::new();
    let mut count = 0;
    for v in values {
        for x in v {
            let code = if signed {
                snorm16(x) as u16
            } else {
                meshopt::quantize_unorm(x, 16) as u16
            };
            bytes.extend_from_slice(&code.to_le_bytes());
        }
        count += 1;
    }
    Attribute {
        bytes,
        stride: 2 * N,
        component_type: if signed { SHORT } else { UNSIGNED_SHORT },
        normalized: true,
        type_name: type_name(N),
        count,
        bounds: None,
    }
}

/// `x` in [-1, 1] as a signed normalized 16-bit integer, as instance rotations are stored.
pub(super) fn snorm16(x: f32) -> i16 {
    meshopt::quantize_snorm(x, 16) as i16
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::json::number;

    #[test]
    fn short_steps_are_never_shorter_and_never_a_tenth_longer() {
        let mut step = 1.3e-30f32;
        // Up to boxes of 6.5e9 units (larger steps print as "1200000.0").
        while step < 1e5 {
            let short = short_step(step);
            assert!(
                short >= step && short <= step * 1.1 + f32::EPSILON * step,
                "{step} -> {short}"
            );
            // Two significant digits, as the JSON writes them: "0.000016", "1.3e-30".
            let text = number(short).to_string();
            assert!(text.len() <= 8, "{step} -> {text}");
            step *= 1.37;
        }
        assert_eq!(short_step(0.0), 0.0);
        assert_eq!(short_step(1e-42), 1e-42);
    }
}
