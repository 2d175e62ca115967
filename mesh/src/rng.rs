//! The workspace's one seeded random number generator: SplitMix64 (Steele, Lea and Flood
//! 2014), so that a seed gives the same models, worlds, samples and test cases on every
//! platform and with every dependency version. It lives here, in the crate every geometry
//! crate depends on; generators, samplers and tests all draw from it.

use std::f32::consts::TAU;

/// SplitMix64: a 64-bit counter passed through a strong mixing function.
///
/// Not cryptographic; fast, tiny and good enough for placing leaves and rocks.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
}

/// The SplitMix64 increment (the golden ratio in 64-bit fixed point).
const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

impl Rng {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// An independent generator for sub-stream `stream` of this one, without advancing it.
    ///
    /// Each part of a model draws from its own stream, so adding draws to one part does not move
    /// the others.
    pub fn fork(&self, stream: u64) -> Self {
        Self::new(mix(self.state ^ mix(stream.wrapping_add(GOLDEN_GAMMA))))
    }

    /// Moves the generator `draws` outputs ahead in constant time: the state is a counter, so
    /// skipping is one multiply-add.
    ///
    /// Parallel workers that each take a fixed slice of one sequence start from a clone skipped
    /// to their offset, and draw the same numbers as one sequential pass would.
    pub fn skip(&mut self, draws: u64) {
        self.state = self.state.wrapping_add(draws.wrapping_mul(GOLDEN_GAMMA));
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GOLDEN_GAMMA);
        mix(self.state)
    }

    /// A uniform float in `[0, 1)` with 24 bits of precision.
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// A uniform double in `[0, 1)` with 53 bits of precision (every double of the form
    /// `k / 2^53`), for samplers whose positions must not be quantised to 24 bits.
    pub fn unit_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// A uniform float in `[lo, hi)`.
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    /// A uniform float in `[-amount, amount)`.
    pub fn jitter(&mut self, amount: f32) -> f32 {
        self.range(-amount, amount)
    }

    /// A uniform angle in `[0, 2π)`.
    pub fn angle(&mut self) -> f32 {
        self.range(0.0, TAU)
    }

    /// A uniformly distributed unit vector.
    pub fn unit_vector(&mut self) -> glam::Vec3 {
        let z = self.range(-1.0, 1.0);
        let a = self.angle();
        let r = (1.0 - z * z).max(0.0).sqrt();
        glam::Vec3::new(r * a.cos(), r * a.sin(), z)
    }

    /// A uniform integer in `0..n`; `n` must be below 2^32 and above zero.
    pub fn below(&mut self, n: usize) -> usize {
        (((self.next_u64() >> 32) * n as u64) >> 32) as usize
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f32) -> bool {
        self.unit() < p
    }

    /// Shuffles `items` in place (Fisher-Yates).
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            items.swap(i, self.below(i + 1));
        }
    }
}

/// The SplitMix64 output function; also a good 64-bit hash.
pub fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A 64-bit hash of `words` under `seed`: each word is XORed into the running value, which one
/// SplitMix64 step (add the increment, then [`mix`]) then scrambles.
///
/// For values that must be drawn from the data itself rather than from a sequence, e.g. a
/// displacement keyed by a vertex position, so that equal inputs get equal draws in any order.
pub fn hash(seed: u64, words: impl IntoIterator<Item = u64>) -> u64 {
    words.into_iter().fold(seed ^ GOLDEN_GAMMA, |h, w| {
        mix((h ^ w).wrapping_add(GOLDEN_GAMMA))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix64_matches_the_reference_sequence() {
        // First outputs of the reference C implementation seeded with 1234567.
        let mut rng = Rng::new(1_234_567);
        assert_eq!(rng.next_u64(), 6_457_827_717_110_365_317);
        assert_eq!(rng.next_u64(), 3_203_168_211_198_807_973);
    }

    #[test]
    fn ranges_stay_in_bounds() {
        let mut rng = Rng::new(7);
        for _ in 0..10_000 {
            let u = rng.unit();
            assert!((0.0..1.0).contains(&u));
            assert!(rng.below(13) < 13);
        }
    }

    #[test]
    fn unit_f64_uses_the_top_53_bits() {
        // The same draw as `next_u64`, scaled: every value is a multiple of 2^-53 in [0, 1).
        let mut a = Rng::new(99);
        let mut b = Rng::new(99);
        for _ in 0..10_000 {
            let u = a.unit_f64();
            assert!((0.0..1.0).contains(&u));
            assert_eq!(u * (1u64 << 53) as f64, (b.next_u64() >> 11) as f64);
        }
    }

    #[test]
    fn skip_equals_drawing() {
        // Skipping n draws lands where n calls to `next_u64` do, for n = 0 and for n past the
        // point where n times the increment wraps around 2^64.
        for n in [0u64, 1, 2, 3, 17, 1000] {
            let mut drawn = Rng::new(5);
            for _ in 0..n {
                drawn.next_u64();
            }
            let mut skipped = Rng::new(5);
            skipped.skip(n);
            assert_eq!(skipped.next_u64(), drawn.next_u64(), "n = {n}");
        }
    }

    #[test]
    fn hash_is_a_chain_of_splitmix_steps() {
        // No words: the seeded start value itself. One word: one generator step from the start
        // value with the word XORed in. Order matters and equal inputs hash equally.
        assert_eq!(hash(3, []), 3 ^ GOLDEN_GAMMA);
        assert_eq!(hash(3, [7]), Rng::new(3 ^ GOLDEN_GAMMA ^ 7).next_u64());
        assert_eq!(hash(3, [1, 2]), hash(3, [1, 2]));
        assert_ne!(hash(3, [1, 2]), hash(3, [2, 1]));
        assert_ne!(hash(3, [1, 2]), hash(4, [1, 2]));
    }

    #[test]
    fn forks_differ_from_each_other_and_from_the_parent() {
        let rng = Rng::new(42);
        let a = rng.fork(1).next_u64();
        let b = rng.fork(2).next_u64();
        let parent = rng.clone().next_u64();
        assert_ne!(a, b);
        assert_ne!(a, parent);
        assert_eq!(a, rng.fork(1).next_u64());
    }
}
