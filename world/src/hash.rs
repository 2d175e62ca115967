//! Content addresses: every model and aggregate file is named by the hash of its bytes, so a
//! changed file gets a new name and nothing stale is ever served under an old one.
//!
//! The hash is FNV-1a 128 ([`horizon_aggregate::KeyHasher`], the same function the rebuild
//! hashes its keys with) as 32 hex digits. It guards against accidental collisions only.

use horizon_aggregate::KeyHasher;

/// The content address of `bytes`: FNV-1a 128 as 32 hex digits.
pub fn content_hash(bytes: &[u8]) -> String {
    let mut h = KeyHasher::new();
    h.write(bytes);
    h.finish_hex()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn content_hashes_are_fnv1a_128_hex() {
        // IETF draft-eastlake-fnv test vector.
        assert_eq!(content_hash(b"a"), "d228cb696f1a8caf78912b704e4a8964");
    }
}
