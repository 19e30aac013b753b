//! The browser viewer: the files of `client/web/`, compiled into the binary so that the server
//! serves its own page with nothing fetched from elsewhere (it works offline and needs no
//! build step).

use super::not_found;
use axum::extract::Path;
use axum::http::header;
use axum::response::{IntoResponse, Redirect, Response};

/// One file of the viewer, served at `/viewer/{path}` (`index.html` also at `/`).
struct Asset {
    path: &'static str,
    content_type: &'static str,
    body: &'static [u8],
}

macro_rules! asset {
    ($path:literal, $content_type:literal) => {
        Asset {
            path: $path,
            content_type: $content_type,
            body: include_bytes!(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../../client/web/",
                $path
            )),
        }
    };
}

const ASSETS: &[Asset] = &[
    asset!("index.html", "text/html; charset=utf-8"),
    asset!("api.html", "text/html; charset=utf-8"),
    asset!("api.css", "text/css; charset=utf-8"),
    asset!("js/apidoc.js", "text/javascript; charset=utf-8"),
    asset!("viewer.css", "text/css; charset=utf-8"),
    asset!("js/main.js", "text/javascript; charset=utf-8"),
    asset!("js/api.js", "text/javascript; charset=utf-8"),
    asset!("js/frame.js", "text/javascript; charset=utf-8"),
    asset!("js/connection.js", "text/javascript; charset=utf-8"),
    asset!("js/controls.js", "text/javascript; charset=utf-8"),
    asset!("js/panel.js", "text/javascript; charset=utf-8"),
    asset!("js/stats.js", "text/javascript; charset=utf-8"),
    asset!("js/still.js", "text/javascript; charset=utf-8"),
    asset!("js/video.js", "text/javascript; charset=utf-8"),
    asset!("js/objects.js", "text/javascript; charset=utf-8"),
];

/// The page may load only its own files, draw decoded frames (blob URLs) and talk to this
/// server (HTTP and its WebSocket).
const CONTENT_SECURITY_POLICY: &str = "default-src 'self'; img-src 'self' blob: data:; \
     connect-src 'self' ws: wss:; object-src 'none'; base-uri 'self'; frame-ancestors 'none'";

fn serve(asset: &Asset) -> Response {
    (
        [
            (header::CONTENT_TYPE, asset.content_type),
            // The files change with the binary; revalidating is cheap on loopback.
            (header::CACHE_CONTROL, "no-cache"),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
            (header::CONTENT_SECURITY_POLICY, CONTENT_SECURITY_POLICY),
        ],
        asset.body,
    )
        .into_response()
}

/// The viewer's page. Needs no token: the page asks for one when the server has auth on.
#[utoipa::path(get, path = "/", tag = "viewer",
    responses((status = 200, description = "The browser viewer", content_type = "text/html")))]
pub async fn index() -> Response {
    serve_or_404("index.html").await
}

/// The API's documentation as a page, rendered in the browser from this server's
/// `/openapi.json` and `/asyncapi.json` (nothing fetched from elsewhere).
#[utoipa::path(get, path = "/api", tag = "viewer",
    responses((status = 200, description = "The API page", content_type = "text/html")))]
pub async fn api_page() -> Response {
    serve_or_404("api.html").await
}

/// The viewer's scripts and style sheet.
#[utoipa::path(get, path = "/viewer/{path}", tag = "viewer",
    params(("path" = String, Path, description = "File of client/web, e.g. js/main.js")),
    responses(
        (status = 200, description = "The file"),
        (status = 404, body = lightcast_protocol::ErrorBody)))]
pub async fn file(Path(path): Path<String>) -> Response {
    // The page's relative links only work from `/`.
    match path.as_str() {
        "index.html" => return Redirect::permanent("../").into_response(),
        "api.html" => return Redirect::permanent("../api").into_response(),
        _ => {}
    }
    serve_or_404(&path).await
}

async fn serve_or_404(path: &str) -> Response {
    match ASSETS.iter().find(|a| a.path == path) {
        Some(asset) => serve(asset),
        None => not_found().await.into_response(),
    }
}

#[cfg(test)]
mod tests {
    use super::ASSETS;
    use std::path::{Path, PathBuf};

    /// Files of `client/web/` the page loads, relative to it: everything but the test harness
    /// and its npm metadata.
    fn web_files(dir: &Path, root: &Path, out: &mut Vec<String>) {
        let entries = std::fs::read_dir(dir).expect("client/web is readable");
        for entry in entries.map(|e| e.expect("directory entry")) {
            let path: PathBuf = entry.path();
            let rel = path
                .strip_prefix(root)
                .expect("under client/web")
                .to_string_lossy()
                .replace('\\', "/");
            if ["node_modules", "tests", "package.json", "package-lock.json"]
                .contains(&rel.as_str())
            {
                continue;
            }
            if path.is_dir() {
                web_files(&path, root, out);
            } else {
                out.push(rel);
            }
        }
    }

    /// A file added to the viewer but not embedded would be missing from the served page.
    #[test]
    fn every_viewer_file_is_embedded() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../client/web");
        let mut on_disk = Vec::new();
        web_files(&root, &root, &mut on_disk);
        on_disk.sort();
        let mut embedded: Vec<String> = ASSETS.iter().map(|a| a.path.to_string()).collect();
        embedded.sort();
        assert_eq!(embedded, on_disk);
    }
}
