//! [`AssetCache`]: an on-disk cache of the service's immutable blobs (`GET /assets/{hash}`),
//! kept as `dir/ab/<hash>` (the hash's first two digits name the folder). A present file is
//! revalidated with `If-None-Match: "<hash>"` and a 304 is a hit; downloaded bytes are kept
//! only if their BLAKE3-256 is the hash, written to a temporary name and renamed into place.
//! Bodies are asked for uncompressed (`Accept-Encoding: identity`), so what is counted is what
//! was sent. [`TokenBucket`] throttles downloads to a bandwidth.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use reqwest::header::{ACCEPT_ENCODING, CONTENT_ENCODING, IF_NONE_MATCH};
use reqwest::StatusCode;

use crate::http::{checked, ClientError};

/// An on-disk cache of one server's assets.
#[derive(Debug)]
pub struct AssetCache {
    dir: PathBuf,
    base: String,
    http: reqwest::Client,
    temp: AtomicU64,
}

/// An asset's bytes, and how they were had.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Fetched {
    /// The asset.
    pub bytes: Vec<u8>,
    /// Whether the bytes came over the network (false: the cached file, revalidated by a 304).
    pub fetched: bool,
    /// Body bytes received for it (0 for a 304).
    pub downloaded: u64,
}

impl AssetCache {
    /// A cache in `dir` (created if missing) of the server at `base_url`.
    ///
    /// # Errors
    /// [`AssetError::Io`] if `dir` cannot be created, [`AssetError::Client`] if the HTTP
    /// client cannot be built.
    pub fn new(dir: impl Into<PathBuf>, base_url: &str) -> Result<Self, AssetError> {
        let client = crate::Client::new(base_url)?;
        Self::with_client(dir, &client)
    }

    /// A cache in `dir` (created if missing) of `client`'s server, sharing its connections.
    ///
    /// # Errors
    /// [`AssetError::Io`] if `dir` cannot be created.
    pub fn with_client(
        dir: impl Into<PathBuf>,
        client: &crate::Client,
    ) -> Result<Self, AssetError> {
        let dir = dir.into();
        std::fs::create_dir_all(&dir).map_err(|e| AssetError::Io(dir.clone(), e))?;
        Ok(Self {
            dir,
            base: client.base_url().to_owned(),
            http: client.http().clone(),
            temp: AtomicU64::new(0),
        })
    }

    /// The cache's folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Where the asset `hash` is kept (whether or not it is there).
    pub fn path(&self, hash: &str) -> PathBuf {
        self.dir.join(hash.get(..2).unwrap_or("__")).join(hash)
    }

    /// The asset `hash`: see the module docs.
    ///
    /// # Errors
    /// As [`AssetCache::get_throttled`].
    pub async fn get(&self, hash: &str) -> Result<Fetched, AssetError> {
        self.get_throttled(hash, None).await
    }

    /// The asset `hash`, its download's body taken from `throttle` chunk by chunk.
    ///
    /// # Errors
    /// [`AssetError::BadHash`] for a name that is not 64 lowercase hex digits,
    /// [`AssetError::Client`] for a failed request or a non-2xx answer (the server's error
    /// body with it), [`AssetError::Encoded`] for a compressed body, [`AssetError::Corrupt`]
    /// for bytes whose hash is not `hash`, [`AssetError::Io`] if the file cannot be written.
    pub async fn get_throttled(
        &self,
        hash: &str,
        throttle: Option<&TokenBucket>,
    ) -> Result<Fetched, AssetError> {
        if !is_hash(hash) {
            return Err(AssetError::BadHash(hash.to_owned()));
        }
        let path = self.path(hash);
        let cached = match tokio::fs::read(&path).await {
            Ok(bytes) if hash_of(&bytes) == hash => Some(bytes),
            // A damaged file is dropped and fetched again.
            Ok(_) => {
                let _ = tokio::fs::remove_file(&path).await;
                None
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => return Err(AssetError::Io(path, e)),
        };
        let mut request = self
            .http
            .get(format!("{}/assets/{hash}", self.base))
            .header(ACCEPT_ENCODING, "identity");
        if cached.is_some() {
            request = request.header(IF_NONE_MATCH, format!("\"{hash}\""));
        }
        let response = request.send().await.map_err(ClientError::from)?;
        if response.status() == StatusCode::NOT_MODIFIED {
            if let Some(bytes) = cached {
                return Ok(Fetched {
                    bytes,
                    fetched: false,
                    downloaded: 0,
                });
            }
        }
        let mut response = checked(response).await?;
        if let Some(encoding) = response.headers().get(CONTENT_ENCODING) {
            if encoding.as_bytes() != b"identity" {
                return Err(AssetError::Encoded(
                    String::from_utf8_lossy(encoding.as_bytes()).into_owned(),
                ));
            }
        }
        let mut bytes = Vec::with_capacity(
            usize::try_from(response.content_length().unwrap_or(0)).unwrap_or(0),
        );
        while let Some(chunk) = response.chunk().await.map_err(ClientError::from)? {
            if let Some(bucket) = throttle {
                bucket.take(chunk.len() as u64).await;
            }
            bytes.extend_from_slice(&chunk);
        }
        let got = hash_of(&bytes);
        if got != hash {
            return Err(AssetError::Corrupt {
                expected: hash.to_owned(),
                got,
            });
        }
        self.keep(&path, &bytes).await?;
        let downloaded = bytes.len() as u64;
        Ok(Fetched {
            bytes,
            fetched: true,
            downloaded,
        })
    }

    /// Writes `bytes` to `path` through a temporary name in the same folder.
    async fn keep(&self, path: &Path, bytes: &[u8]) -> Result<(), AssetError> {
        let folder = path.parent().unwrap_or(&self.dir);
        tokio::fs::create_dir_all(folder)
            .await
            .map_err(|e| AssetError::Io(folder.to_owned(), e))?;
        let temp = folder.join(format!(
            ".tmp-{}-{}",
            std::process::id(),
            self.temp.fetch_add(1, Ordering::Relaxed)
        ));
        if let Err(e) = tokio::fs::write(&temp, bytes).await {
            let _ = tokio::fs::remove_file(&temp).await;
            return Err(AssetError::Io(temp, e));
        }
        if let Err(e) = tokio::fs::rename(&temp, path).await {
            let _ = tokio::fs::remove_file(&temp).await;
            return Err(AssetError::Io(path.to_owned(), e));
        }
        Ok(())
    }
}

/// BLAKE3-256 of `bytes`, lowercase hex: the name the service gives a blob.
fn hash_of(bytes: &[u8]) -> String {
    blake3::hash(bytes).to_hex().to_string()
}

/// Whether `hash` is 64 lowercase hex digits (anything else never names a file).
fn is_hash(hash: &str) -> bool {
    hash.len() == 64 && hash.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

/// Why an asset could not be had.
#[derive(Debug, thiserror::Error)]
pub enum AssetError {
    /// The name is not a content hash.
    #[error("{0:?} is not an asset hash")]
    BadHash(String),
    /// The request failed or the server refused it.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// The server sent a compressed body although it was asked not to.
    #[error("the asset came with content-encoding {0}")]
    Encoded(String),
    /// The bytes are not the asset: their hash differs.
    #[error("asset {expected} arrived with hash {got}")]
    Corrupt {
        /// The hash asked for.
        expected: String,
        /// The hash of what came.
        got: String,
    },
    /// A file of the cache could not be read or written.
    #[error("{path}: {error}", path = .0.display(), error = .1)]
    Io(PathBuf, std::io::Error),
}

/// A token bucket: `rate` bytes per second on average, bursts of up to `burst` bytes. A take
/// larger than what is left borrows against the future and waits until it is paid back, so
/// concurrent takers share the rate.
#[derive(Debug)]
pub struct TokenBucket {
    rate: f64,
    burst: f64,
    state: Mutex<(f64, Instant)>,
}

impl TokenBucket {
    /// A full bucket of `burst` bytes refilled at `rate` bytes per second (`rate` above 0).
    pub fn new(rate: f64, burst: f64) -> Self {
        Self::starting_at(rate, burst, Instant::now())
    }

    /// A full bucket as [`TokenBucket::new`], its clock starting at `now`.
    pub fn starting_at(rate: f64, burst: f64, now: Instant) -> Self {
        let rate = if rate > 0.0 { rate } else { f64::MIN_POSITIVE };
        let burst = burst.max(0.0);
        Self {
            rate,
            burst,
            state: Mutex::new((burst, now)),
        }
    }

    /// The rate, bytes per second.
    pub fn rate(&self) -> f64 {
        self.rate
    }

    /// Takes `n` bytes at `now` and says how long the taker must wait before using them.
    pub fn reserve_at(&self, n: u64, now: Instant) -> Duration {
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        let (tokens, last) = &mut *state;
        if now > *last {
            let refill = now.duration_since(*last).as_secs_f64() * self.rate;
            *tokens = (*tokens + refill).min(self.burst);
            *last = now;
        }
        *tokens -= n as f64;
        if *tokens >= 0.0 {
            Duration::ZERO
        } else {
            Duration::from_secs_f64(-*tokens / self.rate).min(Duration::from_secs(86_400))
        }
    }

    /// Takes `n` bytes, waiting as long as the rate asks.
    pub async fn take(&self, n: u64) {
        let wait = self.reserve_at(n, Instant::now());
        if !wait.is_zero() {
            tokio::time::sleep(wait).await;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Duration, b: f64) -> bool {
        (a.as_secs_f64() - b).abs() < 1e-9
    }

    #[test]
    fn the_bucket_lets_a_burst_through_then_holds_the_rate() {
        let t0 = Instant::now();
        let bucket = TokenBucket::starting_at(1000.0, 100.0, t0);
        assert_eq!(bucket.reserve_at(100, t0), Duration::ZERO);
        // Empty: the next 100 bytes wait 0.1 s.
        assert!(close(bucket.reserve_at(100, t0), 0.1));
        // 0.1 s later the debt is paid; 50 more bytes wait 0.05 s.
        let t1 = t0 + Duration::from_millis(100);
        assert!(close(bucket.reserve_at(50, t1), 0.05));
        // A long idle refills to the burst, not beyond.
        let t2 = t1 + Duration::from_secs(60);
        assert_eq!(bucket.reserve_at(100, t2), Duration::ZERO);
        assert!(close(bucket.reserve_at(1, t2), 0.001));
    }

    #[test]
    fn many_takers_share_the_rate() {
        let t0 = Instant::now();
        let bucket = TokenBucket::starting_at(1000.0, 100.0, t0);
        let mut last = Duration::ZERO;
        for _ in 0..100 {
            last = bucket.reserve_at(100, t0);
        }
        // 10,000 bytes at 1,000 B/s after a 100-byte burst: the last waits 9.9 s.
        assert!(close(last, 9.9), "{last:?}");
    }

    #[test]
    fn hashes_are_64_lowercase_hex_digits() {
        let h = hash_of(b"horizon");
        assert!(is_hash(&h));
        assert!(!is_hash(&h.to_uppercase()));
        assert!(!is_hash("../../etc/passwd"));
        assert!(!is_hash(&h[..63]));
    }

    #[tokio::test]
    async fn a_bad_hash_never_reaches_the_network_or_the_disk() {
        let dir =
            std::env::temp_dir().join(format!("horizon-client-assets-{}", std::process::id()));
        let cache = AssetCache::new(&dir, "http://127.0.0.1:9").expect("a cache");
        let path = cache.path(&hash_of(b"x"));
        assert!(path.starts_with(&dir));
        assert!(matches!(
            cache.get("../secret").await,
            Err(AssetError::BadHash(_))
        ));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
