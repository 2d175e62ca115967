//! Decoded source textures shared between atlases.
//!
//! A world's aggregates draw the same few textures again and again: every aggregate above an
//! object atlases that object's textures, and decoding them anew for each atlas would repeat
//! the same work many times over. The cache keeps decoded images by their encoded bytes, up to
//! a byte budget, so each decodes once per build. A hit compares the bytes themselves, so two
//! textures share an image only when they are the same file. Each image's mip chain (the bake
//! samples shrunk charts from it) is built on first use and kept with it.

use std::collections::hash_map::DefaultHasher;
use std::collections::{HashMap, VecDeque};
use std::hash::{Hash, Hasher};
use std::sync::{Arc, Mutex, OnceLock};

use horizon_mesh::model::Texture;
use image::{Rgba, RgbaImage};

use crate::color::{linear_to_srgb8, texel_linear};

/// A decoded texture and, once asked for, its mip chain.
#[derive(Debug)]
pub struct DecodedTexture {
    /// RGBA8: sRGB colour, linear alpha.
    pub image: RgbaImage,
    /// Levels 1, 2, ... down to 1 x 1, each half the one above (rounded up).
    mips: OnceLock<Vec<RgbaImage>>,
}

impl DecodedTexture {
    /// `image` with no mip chain built yet.
    pub fn new(image: RgbaImage) -> Self {
        Self {
            image,
            mips: OnceLock::new(),
        }
    }

    /// Levels in the chain, the image itself included (from the image's size: the chain
    /// is not built for this).
    pub fn levels(&self) -> usize {
        level_sides(self.image.dimensions()).count()
    }

    /// Level `k` of the chain (0: the image), clamped to the last.
    pub fn level(&self, k: usize) -> &RgbaImage {
        match k {
            0 => &self.image,
            k => {
                let chain = self.mip_chain();
                chain.get(k - 1).or(chain.last()).unwrap_or(&self.image)
            }
        }
    }

    fn mip_chain(&self) -> &[RgbaImage] {
        self.mips.get_or_init(|| mip_chain(&self.image))
    }
}

/// Every level below `image`: each texel the mean, in linear light (alpha linear), of the 2 x 2
/// texels above it, so texel `i` of level `k` covers texels `i 2^k .. (i + 1) 2^k` of the
/// image; past an odd side the edge texel is repeated (clamp to edge). The bake samples these
/// so that a chart shrunk by any factor is filtered rather than aliased (`bake.rs`).
fn mip_chain(image: &RgbaImage) -> Vec<RgbaImage> {
    let mut out: Vec<RgbaImage> = Vec::new();
    loop {
        let above = out.last().unwrap_or(image);
        let (w, h) = above.dimensions();
        if (w <= 1 && h <= 1) || w == 0 || h == 0 {
            return out;
        }
        let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
        let next = RgbaImage::from_fn(nw, nh, |x, y| {
            let xs = [2 * x, (2 * x + 1).min(w - 1)];
            let ys = [2 * y, (2 * y + 1).min(h - 1)];
            let mut sum = glam::Vec4::ZERO;
            for &yy in &ys {
                for &xx in &xs {
                    sum += texel_linear(above.get_pixel(xx, yy));
                }
            }
            let mean = sum * 0.25;
            Rgba([
                linear_to_srgb8(mean.x),
                linear_to_srgb8(mean.y),
                linear_to_srgb8(mean.z),
                (mean.w.clamp(0.0, 1.0) * 255.0).round() as u8,
            ])
        });
        out.push(next);
    }
}

/// Decoded textures by content, up to a budget of decoded bytes; the oldest entries go first.
#[derive(Debug)]
pub struct TextureCache {
    budget: usize,
    inner: Mutex<Entries>,
}

#[derive(Debug, Default)]
struct Entries {
    /// By hash of the encoded bytes: the bytes (to confirm a hit) and the image.
    map: HashMap<u64, Vec<Entry>>,
    /// Insertion order, for eviction.
    order: VecDeque<(u64, Arc<[u8]>)>,
    /// Decoded bytes held.
    bytes: usize,
}

#[derive(Debug)]
struct Entry {
    encoded: Arc<[u8]>,
    image: Arc<DecodedTexture>,
}

impl TextureCache {
    /// A cache holding up to `budget` bytes of decoded RGBA; 0 keeps nothing.
    pub fn new(budget: usize) -> Self {
        Self {
            budget,
            inner: Mutex::new(Entries::default()),
        }
    }

    /// The decoded image of `texture`: from the cache, or decoded now and kept.
    pub fn decode(&self, texture: &Texture) -> Result<Arc<DecodedTexture>, image::ImageError> {
        let hash = hash_of(&texture.bytes);
        if let Some(image) = self.get(hash, &texture.bytes) {
            return Ok(image);
        }
        // Decoded outside the lock: other atlases keep going meanwhile (two may decode the
        // same texture at once; the first kept wins).
        let image = Arc::new(DecodedTexture::new(texture.decode()?));
        self.insert(hash, &texture.bytes, &image);
        Ok(image)
    }

    /// Decoded bytes held now.
    pub fn held_bytes(&self) -> usize {
        self.lock().bytes
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Entries> {
        // A panic elsewhere cannot leave the entries half-changed: every change below is
        // complete before the guard drops.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn get(&self, hash: u64, bytes: &[u8]) -> Option<Arc<DecodedTexture>> {
        let entries = self.lock();
        entries
            .map
            .get(&hash)?
            .iter()
            .find(|e| *e.encoded == *bytes)
            .map(|e| Arc::clone(&e.image))
    }

    fn insert(&self, hash: u64, bytes: &[u8], image: &Arc<DecodedTexture>) {
        let size = held_size(image);
        if size > self.budget {
            return;
        }
        let mut entries = self.lock();
        let bucket = entries.map.entry(hash).or_default();
        if bucket.iter().any(|e| *e.encoded == *bytes) {
            return;
        }
        let encoded: Arc<[u8]> = bytes.into();
        bucket.push(Entry {
            encoded: Arc::clone(&encoded),
            image: Arc::clone(image),
        });
        entries.order.push_back((hash, encoded));
        entries.bytes += size;
        while entries.bytes > self.budget {
            let Some((old_hash, old)) = entries.order.pop_front() else {
                break;
            };
            let mut freed = 0;
            if let Some(bucket) = entries.map.get_mut(&old_hash) {
                if let Some(k) = bucket.iter().position(|e| Arc::ptr_eq(&e.encoded, &old)) {
                    freed = held_size(&bucket.swap_remove(k).image);
                }
                if bucket.is_empty() {
                    entries.map.remove(&old_hash);
                }
            }
            entries.bytes -= freed;
        }
    }
}

/// Bytes an entry holds: the image and (built or not) its mip chain.
fn held_size(image: &DecodedTexture) -> usize {
    level_sides(image.image.dimensions())
        .map(|(w, h)| w as usize * h as usize * 4)
        .sum()
}

/// The sides of every level of an image of side `(w, h)`, the image first: each half the one
/// before, rounded up, down to 1 x 1 (an image without texels is its only level).
fn level_sides((w, h): (u32, u32)) -> impl Iterator<Item = (u32, u32)> {
    std::iter::successors(Some((w, h)), |&(w, h)| {
        (w > 0 && h > 0 && (w > 1 || h > 1)).then(|| (w.div_ceil(2), h.div_ceil(2)))
    })
}

fn hash_of(bytes: &[u8]) -> u64 {
    let mut h = DefaultHasher::new();
    bytes.hash(&mut h);
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_mip_level_halves_and_keeps_the_mean() {
        let mut state = 7u64;
        let image = RgbaImage::from_fn(13, 6, |_, _| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let b = (state >> 24).to_le_bytes();
            Rgba([b[0], b[1], b[2], 255])
        });
        let chain = mip_chain(&image);
        let sides: Vec<(u32, u32)> = chain.iter().map(RgbaImage::dimensions).collect();
        assert_eq!(sides, vec![(7, 3), (4, 2), (2, 1), (1, 1)]);
        // The level count comes from the size alone, without building the chain.
        assert_eq!(DecodedTexture::new(image.clone()).levels(), 1 + chain.len());
        for (w, h, levels) in [(1, 1, 1), (1, 9, 5), (64, 64, 7), (65, 2, 8)] {
            assert_eq!(DecodedTexture::new(RgbaImage::new(w, h)).levels(), levels);
        }
        // A level of even sides keeps its mean in linear light (up to 8-bit rounding).
        let mean = |im: &RgbaImage| {
            let n = f64::from(im.width() * im.height());
            im.pixels()
                .fold(glam::DVec4::ZERO, |a, p| a + texel_linear(p).as_dvec4())
                / n
        };
        let (a, b) = (mean(&chain[1]), mean(&chain[2]));
        assert!((a - b).abs().max_element() < 0.01, "{a} {b}");
    }
}
