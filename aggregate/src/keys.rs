//! Every node's key (core paper section 5's lazy rebuild, made exact): the hash of the
//! options and, for a leaf, its objects (model content hash and transform), for an internal
//! node, its children's keys.
//!
//! A key changes exactly when something below the node changed, so after adding, moving or
//! removing k objects only their ancestors (and nodes a split reshaped) have new keys; every
//! other aggregate is found in the store under its unchanged key and reused. Computing the
//! keys hashes each object once; the aggregates rebuilt are O(k log n).

use std::collections::HashMap;

use horizon_bvh::{Bvh, NodeId};
use horizon_descriptors::calibrate::Table1;
use rayon::prelude::*;

use crate::error::AggregateError;
use crate::options::AggregateOptions;
use crate::source::ModelSource;

/// Every node's key, bottom-up.
pub fn node_keys(
    bvh: &Bvh,
    models: &dyn ModelSource,
    levels: &[Vec<NodeId>],
    options: &AggregateOptions,
    atlas: bool,
    table: &Table1,
) -> Result<HashMap<NodeId, String>, AggregateError> {
    // Table 1's thresholds decide every dedup: a recalibrated table changes every key.
    let fingerprint = format!(
        "{}|atlas={atlas}|table1={:?}",
        options.fingerprint(),
        table.rows
    );
    let mut keys: HashMap<NodeId, String> = HashMap::new();
    for level in levels.iter().rev() {
        let computed: Vec<(NodeId, String)> = level
            .par_iter()
            .map(|&n| -> Result<(NodeId, String), AggregateError> {
                let node = bvh
                    .node(n)
                    .ok_or_else(|| AggregateError::Tree(format!("no node {}", n.0)))?;
                let mut parts: Vec<Vec<u8>> = Vec::new();
                if node.is_leaf() {
                    for o in node.objects() {
                        let obj = bvh
                            .object(o)
                            .ok_or_else(|| AggregateError::Tree(format!("no object {}", o.0)))?;
                        let mut bytes = models.hash(obj.model())?.into_bytes();
                        for v in obj.transform().to_cols_array() {
                            bytes.extend_from_slice(&v.to_bits().to_le_bytes());
                        }
                        parts.push(bytes);
                    }
                } else {
                    for c in node.child_nodes() {
                        let k = keys
                            .get(&c)
                            .ok_or_else(|| AggregateError::Tree(format!("no key for {}", c.0)))?;
                        parts.push(k.clone().into_bytes());
                    }
                }
                parts.sort();
                let mut h = KeyHasher::new();
                h.write(fingerprint.as_bytes());
                h.write(if node.is_leaf() { b"L" } else { b"I" });
                for p in &parts {
                    h.write(&(p.len() as u64).to_le_bytes());
                    h.write(p);
                }
                Ok((n, h.finish_hex()))
            })
            .collect::<Result<_, _>>()?;
        keys.extend(computed);
    }
    Ok(keys)
}

/// Streaming FNV-1a 128, for keys built from many pieces.
#[derive(Clone, Debug)]
pub struct KeyHasher(u128);

impl KeyHasher {
    const OFFSET: u128 = 0x6c62_272e_07bb_0142_62b8_2175_6295_c58d;
    const PRIME: u128 = 0x0000_0000_0100_0000_0000_0000_0000_013b;

    /// A fresh hasher.
    pub fn new() -> Self {
        Self(Self::OFFSET)
    }

    /// Feeds bytes.
    pub fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u128::from(b);
            self.0 = self.0.wrapping_mul(Self::PRIME);
        }
    }

    /// The hash as 32 hex digits.
    pub fn finish_hex(&self) -> String {
        format!("{:032x}", self.0)
    }
}

impl Default for KeyHasher {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a_128_matches_reference_values() {
        // Reference values of FNV-1a 128 (IETF draft-eastlake-fnv test vectors).
        let hex = |bytes: &[u8]| {
            let mut h = KeyHasher::new();
            h.write(bytes);
            h.finish_hex()
        };
        assert_eq!(hex(b""), "6c62272e07bb014262b821756295c58d");
        assert_eq!(hex(b"a"), "d228cb696f1a8caf78912b704e4a8964");
    }
}
