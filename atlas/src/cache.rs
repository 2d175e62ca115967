//! Decoded source textures shared between atlases.
//!
//! A world's aggregates draw the same few textures again and again: every aggregate above an
//! object atlases that object's textures, and on the city, decoding them was a third of the
//! aggregate build. The cache keeps decoded images by their encoded bytes, up to a byte
//! budget, so each decodes once per build. A hit compares the bytes themselves, so two
//! textures share an image only when they are the same file.

use std::collections::hash_map::DefaultHasher;
use std::collections::{HashMap, VecDeque};
use std::hash::{Hash, Hasher};
use std::sync::{Arc, Mutex};

use horizon_mesh::model::Texture;
use image::RgbaImage;

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
    image: Arc<RgbaImage>,
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
    pub fn decode(&self, texture: &Texture) -> Result<Arc<RgbaImage>, image::ImageError> {
        let hash = hash_of(&texture.bytes);
        if let Some(image) = self.get(hash, &texture.bytes) {
            return Ok(image);
        }
        // Decoded outside the lock: other atlases keep going meanwhile (two may decode the
        // same texture at once; the first kept wins).
        let image = Arc::new(texture.decode()?);
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

    fn get(&self, hash: u64, bytes: &[u8]) -> Option<Arc<RgbaImage>> {
        let entries = self.lock();
        entries
            .map
            .get(&hash)?
            .iter()
            .find(|e| *e.encoded == *bytes)
            .map(|e| Arc::clone(&e.image))
    }

    fn insert(&self, hash: u64, bytes: &[u8], image: &Arc<RgbaImage>) {
        let size = image.as_raw().len();
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
                    freed = bucket.swap_remove(k).image.as_raw().len();
                }
                if bucket.is_empty() {
                    entries.map.remove(&old_hash);
                }
            }
            entries.bytes -= freed;
        }
    }
}

fn hash_of(bytes: &[u8]) -> u64 {
    let mut h = DefaultHasher::new();
    bytes.hash(&mut h);
    h.finish()
}
