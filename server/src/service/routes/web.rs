//! The web viewer: the files of `web/` (our modules and the vendored three.js), embedded in the
//! binary so that `horizon serve` needs nothing beside it. `/` is `web/index.html`; every other
//! file is at `/web/<path>`. They change with the binary, so clients revalidate them
//! (`no-cache`, with an `ETag` of the binary's version and the file's length).

use axum::extract::Path;
use axum::http::header::{CACHE_CONTROL, CONTENT_TYPE, ETAG, IF_NONE_MATCH};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use horizon_protocol::ErrorCode;

use crate::service::AppError;

/// One embedded file of `web/`.
#[derive(Debug)]
pub struct WebFile {
    /// Its path under `web/`.
    pub path: &'static str,
    /// Its media type.
    pub mime: &'static str,
    /// Its bytes.
    pub bytes: &'static [u8],
}

macro_rules! web_files {
    ($($path:literal => $mime:expr,)*) => {
        &[$(WebFile {
            path: $path,
            mime: $mime,
            bytes: include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/../web/", $path)),
        },)*]
    };
}

const JS: &str = "text/javascript; charset=utf-8";

/// Every file of `web/` (a test checks that none is missing).
pub static FILES: &[WebFile] = web_files! {
    "index.html" => "text/html; charset=utf-8",
    "style.css" => "text/css; charset=utf-8",
    "js/assets.js" => JS,
    "js/fly.js" => JS,
    "js/full.js" => JS,
    "js/impostor.js" => JS,
    "js/main.js" => JS,
    "js/png.js" => JS,
    "js/stream.js" => JS,
    "js/upload.js" => JS,
    "js/world.js" => JS,
    "vendor/three/LICENSE" => "text/plain; charset=utf-8",
    "vendor/three/README.md" => "text/markdown; charset=utf-8",
    "vendor/three/three.core.js" => JS,
    "vendor/three/three.module.js" => JS,
    "vendor/three/addons/libs/meshopt_decoder.module.js" => JS,
    "vendor/three/addons/loaders/GLTFLoader.js" => JS,
    "vendor/three/addons/utils/BufferGeometryUtils.js" => JS,
    "vendor/three/addons/utils/SkeletonUtils.js" => JS,
};

/// The viewer's page.
#[utoipa::path(get, path = "/", tag = "service",
    responses((status = 200, description = "The web viewer", content_type = "text/html")))]
pub async fn index(headers: HeaderMap) -> Response {
    serve("index.html", &headers).unwrap_or_else(IntoResponse::into_response)
}

/// A file of the viewer, `GET /web/{*path}`.
pub async fn file(Path(path): Path<String>, headers: HeaderMap) -> Response {
    serve(&path, &headers).unwrap_or_else(IntoResponse::into_response)
}

fn serve(path: &str, headers: &HeaderMap) -> Result<Response, AppError> {
    let file = FILES
        .iter()
        .find(|f| f.path == path)
        .ok_or_else(|| AppError::new(ErrorCode::NotFound, format!("no viewer file {path}")))?;
    let etag = format!("\"{}-{}\"", env!("CARGO_PKG_VERSION"), file.bytes.len());
    let cached = headers
        .get(IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == etag));
    if cached {
        return Ok((StatusCode::NOT_MODIFIED, [(ETAG, etag)]).into_response());
    }
    Ok((
        [
            (CONTENT_TYPE, file.mime.to_owned()),
            (CACHE_CONTROL, "no-cache".to_owned()),
            (ETAG, etag),
        ],
        file.bytes,
    )
        .into_response())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_file_of_web_is_embedded() {
        fn walk(dir: &std::path::Path, root: &std::path::Path, out: &mut Vec<String>) {
            for entry in std::fs::read_dir(dir).expect("web/ is readable") {
                let path = entry.expect("entry").path();
                if path.is_dir() {
                    walk(&path, root, out);
                } else {
                    let rel = path.strip_prefix(root).expect("under web/");
                    out.push(rel.to_string_lossy().replace('\\', "/"));
                }
            }
        }
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../web");
        let mut on_disk = Vec::new();
        walk(&root, &root, &mut on_disk);
        on_disk.sort();
        let mut embedded: Vec<String> = FILES.iter().map(|f| f.path.to_owned()).collect();
        embedded.sort();
        assert_eq!(on_disk, embedded, "web/ and routes/web.rs FILES differ");
    }
}
