//! Welding of vertices by exact position, with a small multiplicative hash (the inputs are
//! float bit patterns, so a cryptographic hash would only cost time).

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use glam::Vec3;

/// A submesh's vertices numbered by position.
#[derive(Debug, Clone)]
pub(crate) struct Weld {
    /// For every vertex, the number of its position among the distinct positions, in order
    /// of first use.
    pub ids: Vec<u32>,
    /// How many distinct positions there are.
    pub positions: u32,
}

impl Weld {
    /// The positions of triangle `t` (three vertex indices), or `None` when two of them are
    /// the same: such a triangle is a point or a segment, draws nothing and would only
    /// confuse the topology, so the engine drops it (the count goes down).
    pub fn triangle(&self, t: &[u32]) -> Option<[u32; 3]> {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| self.ids[i as usize]);
        (a != b && b != c && a != c).then_some([a, b, c])
    }
}

/// Numbers the vertices of `sub` by position.
pub(crate) fn weld(sub: &horizon_mesh::Submesh) -> Weld {
    let mut welder = Welder::with_capacity(sub.positions.len());
    let mut next = 0;
    let ids = sub
        .positions
        .iter()
        .map(|&p| {
            let id = welder.id(p, next);
            if id == next {
                next += 1;
            }
            id
        })
        .collect();
    Weld {
        ids,
        positions: next,
    }
}

/// Gives each distinct position one id; `-0.0` and `0.0` weld.
#[derive(Debug)]
pub(crate) struct Welder {
    ids: HashMap<u128, u32, BuildHasherDefault<MixHasher>>,
}

impl Welder {
    pub(crate) fn with_capacity(n: usize) -> Self {
        Self {
            ids: HashMap::with_capacity_and_hasher(n, BuildHasherDefault::default()),
        }
    }

    /// The id of `p`: an earlier one if the position was seen, else `next`.
    pub(crate) fn id(&mut self, p: Vec3, next: u32) -> u32 {
        let [x, y, z] = [p.x, p.y, p.z].map(|c| if c == 0.0 { 0 } else { c.to_bits() });
        let key = u128::from(x) | (u128::from(y) << 32) | (u128::from(z) << 64);
        *self.ids.entry(key).or_insert(next)
    }
}

/// A multiply-rotate hasher for short keys of integers.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct MixHasher(u64);

impl Hasher for MixHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u32(&mut self, i: u32) {
        self.write_u64(u64::from(i));
    }

    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }

    fn write_u128(&mut self, i: u128) {
        self.write_u64(i as u64);
        self.write_u64((i >> 64) as u64);
    }

    fn write_usize(&mut self, i: usize) {
        self.write_u64(i as u64);
    }
}
