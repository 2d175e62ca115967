//! What a hit looks like: materials as a glTF client reads them, textures sampled
//! trilinearly from a mip chain built in linear light, and the fixed lighting every render
//! shares.

use std::sync::{Arc, OnceLock};

use glam::{Vec2, Vec3, Vec4};
use horizon_mesh::{AlphaMode, Material, Texture, UvTransform, Wrap};

/// Direction towards the sun (normalised at use).
pub const SUN: Vec3 = Vec3::new(0.4, 1.0, 0.3);
/// Share of the light that is ambient; the rest is the sun, Lambertian.
pub const AMBIENT: f32 = 0.4;
/// The sky's colour, sRGB.
pub const SKY: [u8; 3] = [178, 202, 229];

/// A material ready to shade with.
#[derive(Clone, Debug)]
pub(crate) struct Shading {
    /// Linear base colour factor.
    pub base: Vec4,
    /// The base colour texture and its UV transform.
    pub texture: Option<(Arc<MipChain>, Option<UvTransform>)>,
    pub alpha: AlphaMode,
    pub double_sided: bool,
}

impl Shading {
    /// The glTF default material.
    pub fn default_material() -> Self {
        Self::of(&Material::default(), &[])
    }

    /// `material`, with its texture from `textures` (decoded already, `None` where the
    /// image could not be decoded: it then draws with its factor alone).
    pub fn of(material: &Material, textures: &[Option<Arc<MipChain>>]) -> Self {
        let texture = material.base_color_texture.as_ref().and_then(|t| {
            let chain = textures.get(t.texture)?.clone()?;
            Some((chain, t.transform))
        });
        Self {
            base: material.base_color_factor,
            texture,
            alpha: material.alpha_mode,
            double_sided: material.double_sided,
        }
    }

    /// The linear base colour at `uv` with mip level `lod`.
    pub fn base_color(&self, uv: Vec2, lod: f32) -> Vec4 {
        match &self.texture {
            Some((chain, transform)) => {
                let uv = transform.map_or(uv, |t| t.apply(uv));
                self.base * chain.sample(uv, lod)
            }
            None => self.base,
        }
    }

    /// Whether alpha testing discards the surface at `uv` (only `MASK` materials test).
    pub fn discards(&self, uv: Vec2) -> bool {
        match self.alpha {
            AlphaMode::Mask { cutoff } => self.base_color(uv, 0.0).w < cutoff,
            _ => false,
        }
    }
}

/// Lambertian light with ambient: the factor a base colour is multiplied by.
pub fn light(normal: Vec3) -> f32 {
    AMBIENT + (1.0 - AMBIENT) * normal.dot(SUN.normalize()).max(0.0)
}

/// A texture's mip chain: sRGB colour and linear alpha, each level half the one before
/// (box filtered in linear light), down to 1 x 1.
#[derive(Debug)]
pub(crate) struct MipChain {
    levels: Vec<Level>,
    wrap: (Wrap, Wrap),
}

#[derive(Debug)]
struct Level {
    width: u32,
    height: u32,
    texels: Vec<[u8; 4]>,
}

impl MipChain {
    /// Decodes `texture` and builds its chain; `None` if it cannot be decoded.
    pub fn of(texture: &Texture) -> Option<Self> {
        let image = texture.decode().ok()?;
        let (width, height) = image.dimensions();
        if width == 0 || height == 0 {
            return None;
        }
        let texels = image.pixels().map(|p| p.0).collect();
        let mut levels = vec![Level {
            width,
            height,
            texels,
        }];
        while let Some(last) = levels.last().filter(|l| l.width > 1 || l.height > 1) {
            levels.push(last.halved());
        }
        Some(Self {
            levels,
            wrap: (texture.wrap_u, texture.wrap_v),
        })
    }

    /// Texels of the full-resolution level.
    pub fn texels(&self) -> u32 {
        self.levels[0].width * self.levels[0].height
    }

    /// Trilinear sample at `uv`, `lod` levels down (0: full resolution), linear RGBA.
    pub fn sample(&self, uv: Vec2, lod: f32) -> Vec4 {
        let top = (self.levels.len() - 1) as f32;
        let lod = if lod.is_finite() {
            lod.clamp(0.0, top)
        } else {
            0.0
        };
        let lo = lod.floor() as usize;
        let hi = (lo + 1).min(self.levels.len() - 1);
        let f = lod - lo as f32;
        let a = self.bilinear(lo, uv);
        if f == 0.0 || hi == lo {
            return a;
        }
        a.lerp(self.bilinear(hi, uv), f)
    }

    fn bilinear(&self, level: usize, uv: Vec2) -> Vec4 {
        let l = &self.levels[level];
        let x = uv.x * l.width as f32 - 0.5;
        let y = uv.y * l.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let at = |dx: i64, dy: i64| {
            let tx = wrap(x0 + dx, l.width, self.wrap.0);
            let ty = wrap(y0 + dy, l.height, self.wrap.1);
            linear(l.texels[ty * l.width as usize + tx])
        };
        let top = at(0, 0).lerp(at(1, 0), fx);
        let bottom = at(0, 1).lerp(at(1, 1), fx);
        top.lerp(bottom, fy)
    }
}

impl Level {
    /// The next level: 2 x 2 texels averaged in linear light (an odd last row or column is
    /// averaged into its neighbour's texel).
    fn halved(&self) -> Level {
        let width = (self.width / 2).max(1);
        let height = (self.height / 2).max(1);
        let mut texels = Vec::with_capacity(width as usize * height as usize);
        for y in 0..height {
            for x in 0..width {
                let xs = (x * 2)..((x * 2 + 2).min(self.width)).max(x * 2 + 1);
                let ys = (y * 2)..((y * 2 + 2).min(self.height)).max(y * 2 + 1);
                let (mut sum, mut n) = (Vec4::ZERO, 0.0);
                for sy in ys {
                    for sx in xs.clone() {
                        sum += linear(self.texels[(sy * self.width + sx) as usize]);
                        n += 1.0;
                    }
                }
                texels.push(encode(sum / n));
            }
        }
        Level {
            width,
            height,
            texels,
        }
    }
}

/// Folds texel coordinate `i` into [0, size) by the wrap mode.
fn wrap(i: i64, size: u32, mode: Wrap) -> usize {
    let n = i64::from(size);
    let folded = match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::ClampToEdge => i.clamp(0, n - 1),
        Wrap::MirroredRepeat => {
            let m = i.rem_euclid(2 * n);
            if m < n {
                m
            } else {
                2 * n - 1 - m
            }
        }
    };
    folded as usize
}

/// sRGB colour and linear alpha to linear RGBA.
fn linear(t: [u8; 4]) -> Vec4 {
    let lut = srgb_table();
    Vec4::new(
        lut[t[0] as usize],
        lut[t[1] as usize],
        lut[t[2] as usize],
        f32::from(t[3]) / 255.0,
    )
}

/// Linear RGBA to sRGB colour and linear alpha.
fn encode(c: Vec4) -> [u8; 4] {
    let [r, g, b] = to_srgb(c.truncate());
    [r, g, b, (c.w.clamp(0.0, 1.0) * 255.0).round() as u8]
}

/// An sRGB byte to linear light.
pub fn from_srgb(c: u8) -> f32 {
    srgb_table()[c as usize]
}

/// Linear colour to sRGB bytes.
pub fn to_srgb(c: Vec3) -> [u8; 3] {
    c.to_array().map(|v| {
        let v = v.clamp(0.0, 1.0);
        let s = if v <= 0.003_130_8 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0).round() as u8
    })
}

/// sRGB byte to linear light, for every byte.
fn srgb_table() -> &'static [f32; 256] {
    static TABLE: OnceLock<[f32; 256]> = OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|i| {
            let s = i as f32 / 255.0;
            if s <= 0.040_45 {
                s / 12.92
            } else {
                ((s + 0.055) / 1.055).powf(2.4)
            }
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker(size: u32) -> Texture {
        let image = image::RgbaImage::from_fn(size, size, |x, y| {
            if (x + y) % 2 == 0 {
                image::Rgba([255, 255, 255, 255])
            } else {
                image::Rgba([0, 0, 0, 255])
            }
        });
        let mut bytes = Vec::new();
        image
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .expect("encodes");
        Texture {
            bytes,
            mime_type: "image/png".into(),
            size: (size, size),
            wrap_u: Wrap::Repeat,
            wrap_v: Wrap::Repeat,
        }
    }

    #[test]
    fn a_checker_averages_to_half_the_light_at_the_top_of_its_chain() {
        let chain = MipChain::of(&checker(8)).expect("decodes");
        assert_eq!(chain.levels.len(), 4);
        let top = chain.sample(Vec2::new(0.3, 0.7), 10.0);
        // Half white, half black in linear light is 0.5 linear, not sRGB 128.
        assert!((top.x - 0.5).abs() < 0.01, "{top}");
        // At full resolution a texel centre is the texel itself.
        let texel = chain.sample(Vec2::new(0.5 / 8.0, 0.5 / 8.0), 0.0);
        assert!((texel.x - 1.0).abs() < 1e-6, "{texel}");
    }

    #[test]
    fn wrap_modes_fold_coordinates_like_a_gpu_sampler() {
        assert_eq!(wrap(-1, 4, Wrap::Repeat), 3);
        assert_eq!(wrap(5, 4, Wrap::Repeat), 1);
        assert_eq!(wrap(-1, 4, Wrap::ClampToEdge), 0);
        assert_eq!(wrap(9, 4, Wrap::ClampToEdge), 3);
        assert_eq!(wrap(4, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap(-1, 4, Wrap::MirroredRepeat), 0);
    }
}
