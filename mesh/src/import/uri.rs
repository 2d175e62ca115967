//! Resolution of the URIs a glTF or OBJ file uses for its buffers and images.
//!
//! Only two kinds are followed: `data:` URIs, and relative paths that stay inside the folder of
//! the file being imported. Remote URIs (http, https or any other scheme), absolute paths and
//! paths that climb out of the folder (`..`, or a symbolic link pointing elsewhere) are refused,
//! so an upload can never make the server read its own files or reach the network.

use std::path::{Component, Path, PathBuf};

use base64::Engine as _;

use crate::error::ImportError;

/// The bytes a URI points to, and the MIME type a data: URI declares.
#[derive(Debug)]
pub(crate) struct Resolved {
    pub bytes: Vec<u8>,
    pub mime_type: Option<String>,
}

/// Reads what `uri` points to, counting the bytes against `budget` (bytes still allowed).
pub(crate) fn resolve(
    uri: &str,
    base_dir: Option<&Path>,
    budget: &mut u64,
) -> Result<Resolved, ImportError> {
    // Stage 1: inline data.
    if let Some(rest) = uri.strip_prefix("data:") {
        let resolved = decode_data_uri(uri, rest)?;
        take_budget(budget, resolved.bytes.len() as u64)?;
        return Ok(resolved);
    }
    // Stage 2: refuse anything that is not a plain relative path.
    let path = relative_path(uri)?;
    let Some(base) = base_dir else {
        return Err(ImportError::ForbiddenUri {
            uri: uri.into(),
            reason: "external files need the model's folder, and none was given",
        });
    };
    // Stage 3: the canonical target must still be inside the canonical folder (symlinks).
    let io_error = |reason| ImportError::Io {
        path: uri.into(),
        reason,
    };
    let base = base.canonicalize().map_err(io_error)?;
    let full = base.join(&path).canonicalize().map_err(io_error)?;
    if !full.starts_with(&base) {
        return Err(ImportError::ForbiddenUri {
            uri: uri.into(),
            reason: "it leaves the model's folder",
        });
    }
    // Stage 4: read it within the byte budget.
    let size = std::fs::metadata(&full).map_err(io_error)?.len();
    take_budget(budget, size)?;
    let bytes = std::fs::read(&full).map_err(io_error)?;
    Ok(Resolved {
        bytes,
        mime_type: None,
    })
}

/// Subtracts `n` from the remaining byte budget, or fails if it does not fit.
pub(crate) fn take_budget(budget: &mut u64, n: u64) -> Result<(), ImportError> {
    *budget = budget.checked_sub(n).ok_or(ImportError::LimitExceeded {
        what: super::BYTES,
        value: n,
        limit: *budget,
    })?;
    Ok(())
}

fn decode_data_uri(uri: &str, rest: &str) -> Result<Resolved, ImportError> {
    let (header, payload) = rest.split_once(',').ok_or(ImportError::ForbiddenUri {
        uri: abbreviate(uri),
        reason: "a data: URI without a comma",
    })?;
    let mut parts = header.split(';');
    let mime = parts.next().filter(|m| !m.is_empty()).map(str::to_owned);
    let is_base64 = parts.any(|p| p.eq_ignore_ascii_case("base64"));
    let bytes = if is_base64 {
        base64::engine::general_purpose::STANDARD
            .decode(payload.trim_end())
            .map_err(|e| ImportError::Json(format!("bad base64 in data: URI: {e}")))?
    } else {
        percent_encoding::percent_decode_str(payload).collect()
    };
    Ok(Resolved {
        bytes,
        mime_type: mime,
    })
}

/// Turns a URI into a relative path with no `..` that escapes, or refuses it.
fn relative_path(uri: &str) -> Result<PathBuf, ImportError> {
    let forbid = |reason| ImportError::ForbiddenUri {
        uri: abbreviate(uri),
        reason,
    };
    if has_scheme(uri) {
        return Err(forbid("remote and non-file URIs are not followed"));
    }
    let decoded = percent_encoding::percent_decode_str(uri)
        .decode_utf8()
        .map_err(|_| forbid("not valid UTF-8 once percent-decoded"))?;
    if decoded.contains('\\') || decoded.contains('\0') {
        return Err(forbid("backslashes and NUL are not allowed in paths"));
    }
    let mut out = PathBuf::new();
    for component in Path::new(decoded.as_ref()).components() {
        match component {
            Component::Normal(part) => out.push(part),
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    return Err(forbid("it leaves the model's folder"));
                }
            }
            Component::RootDir | Component::Prefix(_) => {
                return Err(forbid("absolute paths are not allowed"));
            }
        }
    }
    if out.as_os_str().is_empty() {
        return Err(forbid("it names no file"));
    }
    Ok(out)
}

/// Whether the URI starts with `scheme:` as in RFC 3986 (a letter, then letters, digits, `+`,
/// `-` or `.`), as `http:`, `https:` and `file:` do.
fn has_scheme(uri: &str) -> bool {
    let Some((scheme, _)) = uri.split_once(':') else {
        return false;
    };
    let mut chars = scheme.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.'))
}

/// Keeps error messages on one short line even for megabyte-long data: URIs.
fn abbreviate(uri: &str) -> String {
    match uri.char_indices().nth(80) {
        Some((cut, _)) => format!("{}...", &uri[..cut]),
        None => uri.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remote_absolute_and_escaping_uris_are_refused() {
        // Each of these would let an upload read outside its own folder or reach the network.
        for uri in [
            "http://example.com/a.bin",
            "https://example.com/a.bin",
            "file:///etc/passwd",
            "/etc/passwd",
            "../secret.bin",
            "a/../../secret.bin",
            "%2E%2E/secret.bin",
            "a\\..\\..\\b",
        ] {
            let err = relative_path(uri).expect_err(uri);
            assert!(matches!(err, ImportError::ForbiddenUri { .. }), "{uri}");
        }
    }

    #[test]
    fn relative_uris_inside_the_folder_are_followed() {
        // `..` that stays inside the folder is fine; %20 is a space.
        assert_eq!(
            relative_path("textures/../a%20b.png").ok(),
            Some(PathBuf::from("a b.png"))
        );
    }

    #[test]
    fn data_uris_decode_base64_and_keep_their_mime_type() {
        let mut budget = 100;
        let r = resolve("data:image/png;base64,AAEC", None, &mut budget).expect("valid");
        assert_eq!(r.bytes, vec![0, 1, 2]);
        assert_eq!(r.mime_type.as_deref(), Some("image/png"));
        assert_eq!(budget, 97);
    }
}
