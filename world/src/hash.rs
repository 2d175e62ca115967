//! Content addresses: every blob is named by the hash of its bytes, so a changed file gets a
//! new name and nothing stale is ever served under an old one.
//!
//! The hash is BLAKE3-256 as 64 hex digits. Strangers upload models, so the address must be
//! cryptographic: with a fast non-cryptographic hash anyone could craft a second model with
//! another's address, and dedup would serve theirs in its place.

/// The content address of `bytes`: BLAKE3-256 as 64 lower-case hex digits.
pub fn content_hash(bytes: &[u8]) -> String {
    blake3::hash(bytes).to_hex().to_string()
}

/// Whether `text` has the shape of a content address, so that it can name a file without
/// escaping the store's folder.
pub fn is_content_hash(text: &str) -> bool {
    text.len() == 64 && text.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn content_hashes_are_blake3_hex() {
        // The BLAKE3 reference vector for the empty input.
        assert_eq!(
            content_hash(b""),
            "af1349b9f5f9a1a6a0404dea36dcc9499bcb25c9adc112b7cc9a93cae41f3262"
        );
        assert!(is_content_hash(&content_hash(b"anything")));
        assert!(!is_content_hash("../../../../etc/passwd"));
        assert!(!is_content_hash(&content_hash(b"x").to_uppercase()));
    }
}
