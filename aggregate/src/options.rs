//! What the aggregate rebuild is asked for: the display model its budgets assume, and which
//! optimisations run.

use serde::{Deserialize, Serialize};

/// When aggregates get a texture atlas (core paper section 7).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum AtlasPolicy {
    /// Every aggregate: one material and one texture, so one draw call, whatever the world.
    Always,
    /// The paper's rule: only when the world has more than 100 textures or more than 64 MB
    /// of them. Below that, aggregates keep their source materials.
    Auto,
    /// Never: aggregates keep their source materials and textures.
    Never,
}

/// How an aggregate's merged mesh is simplified.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Method {
    /// The optimised pipeline: dedup, instanced merge, IAS, atlas.
    Optimized,
    /// The unoptimised baseline (`baseline.rs`, feature `baseline`): no dedup, the children
    /// expanded into one mesh, classic QEM to the same budget, no atlas.
    #[cfg(feature = "baseline")]
    Unoptimized,
}

/// Knobs of the rebuild. Start from [`AggregateOptions::default`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct AggregateOptions {
    /// The smallest solid angle (steradians) a client asks to see as itself. It fixes how
    /// close an aggregate can be shown (`budget.rs`), hence its triangle and texel budgets.
    /// Default: the cut's, [`horizon_bvh::DEFAULT_MIN_SOLID_ANGLE`].
    pub min_solid_angle: f64,
    /// The largest solid angle at which an aggregate is returned, for the dedup distance of
    /// section 5.1 (the paper's `Omega = 1.0`).
    pub dedup_solid_angle: f64,
    /// Screen pixels per expanded triangle at the aggregate's nearest display distance (the
    /// budget rule, `budget.rs`). Default 16.
    pub pixels_per_triangle: f64,
    /// Objects under this many pixels at the aggregate's nearest display distance are left
    /// out of it. Default 1.
    pub cull_pixels: f64,
    /// Replace near-duplicate models by instances of one (section 5.1, Table 1).
    pub dedup: bool,
    /// When to atlas.
    pub atlas: AtlasPolicy,
    /// Encoded size limit of an atlas texture. Default 128 KiB (section 7).
    pub atlas_bytes: usize,
    /// Atlas texels per pixel the aggregate covers at its nearest display distance. Default
    /// 0.25 (one texel per 2 x 2 pixels): an aggregate stands for objects each under
    /// `min_solid_angle`, and at one texel per pixel its atlas would be most of what a client
    /// downloads for it.
    pub texels_per_pixel: f64,
    /// Optimised pipeline or the unoptimised baseline.
    pub method: Method,
}

impl Default for AggregateOptions {
    fn default() -> Self {
        Self {
            min_solid_angle: horizon_bvh::DEFAULT_MIN_SOLID_ANGLE,
            dedup_solid_angle: 1.0,
            pixels_per_triangle: 16.0,
            cull_pixels: 1.0,
            dedup: true,
            atlas: AtlasPolicy::Always,
            atlas_bytes: 128 * 1024,
            texels_per_pixel: 0.25,
            method: Method::Optimized,
        }
    }
}

impl AggregateOptions {
    /// The unoptimised baseline with the same display model and budget.
    #[cfg(feature = "baseline")]
    pub fn unoptimized(&self) -> Self {
        Self {
            dedup: false,
            atlas: AtlasPolicy::Never,
            method: Method::Unoptimized,
            ..*self
        }
    }

    /// Checks every field; the message names the bad one.
    pub fn validate(&self) -> Result<(), String> {
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{name} must be a positive number, got {v}"))
            }
        };
        positive("min_solid_angle", self.min_solid_angle)?;
        positive("dedup_solid_angle", self.dedup_solid_angle)?;
        positive("pixels_per_triangle", self.pixels_per_triangle)?;
        if !(self.cull_pixels.is_finite() && self.cull_pixels >= 0.0) {
            return Err(format!(
                "cull_pixels must be >= 0, got {}",
                self.cull_pixels
            ));
        }
        if self.min_solid_angle >= 4.0 * std::f64::consts::PI {
            return Err("min_solid_angle must be below 4 pi".into());
        }
        if self.dedup_solid_angle >= 2.0 * std::f64::consts::PI {
            return Err("dedup_solid_angle must be below 2 pi".into());
        }
        positive("texels_per_pixel", self.texels_per_pixel)?;
        if self.atlas_bytes < 1024 {
            return Err(format!("atlas_bytes {} is below 1 KiB", self.atlas_bytes));
        }
        Ok(())
    }

    /// A stable text naming every option, hashed into every aggregate's key so that changed
    /// options never reuse an aggregate built under other ones.
    pub fn fingerprint(&self) -> String {
        format!(
            "v{}|{:e}|{:e}|{:e}|{:e}|{}|{:?}|{}|{:e}|{:?}",
            crate::FORMAT,
            self.min_solid_angle,
            self.dedup_solid_angle,
            self.pixels_per_triangle,
            self.cull_pixels,
            self.dedup,
            self.atlas,
            self.atlas_bytes,
            self.texels_per_pixel,
            self.method
        )
    }
}
