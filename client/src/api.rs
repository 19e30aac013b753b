//! A thin typed client of the lightcast HTTP API and the session WebSocket.

use futures_util::{SinkExt, StreamExt};
use lightcast_protocol::{
    ClientMessage, ErrorBody, FrameHeader, RenderReport, SceneInfo, ServerEvent, SessionCreated,
    SessionInfo,
};
use serde::de::DeserializeOwned;
use std::path::Path;
use std::sync::Arc;
use tokio_tungstenite::tungstenite::Message;

/// Why a request failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("{url}: cannot reach the server: {}", causes(error))]
    Unreachable { url: String, error: reqwest::Error },
    #[error("server answered {status}: {}{}", body.message, body.field.as_ref().map(|f| format!(" (field {f})")).unwrap_or_default())]
    Api {
        status: reqwest::StatusCode,
        body: ErrorBody,
    },
    #[error("server answered {status} with an unexpected body: {text}")]
    Unexpected {
        status: reqwest::StatusCode,
        text: String,
    },
    #[error("WebSocket {url}: {error}")]
    WebSocket {
        url: String,
        error: Box<tokio_tungstenite::tungstenite::Error>,
    },
    #[error("the server sent a malformed frame: {0}")]
    Frame(#[from] lightcast_protocol::FrameHeaderError),
    #[error("the server sent a malformed event: {0}")]
    Event(serde_json::Error),
    #[error("{0}")]
    Invalid(String),
}

/// The server's address and the caller's token.
#[derive(Clone)]
pub struct Client {
    base: String,
    token: Option<String>,
    http: reqwest::Client,
    /// TLS of `wss://` streams, the same as of the HTTP requests.
    tls: Arc<rustls::ClientConfig>,
}

/// An error with its causes (reqwest's own message hides why: a refused certificate, a
/// refused connection).
fn causes(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(e) = source {
        text += &format!(": {e}");
        source = e.source();
    }
    text
}

/// TLS for `https://` and `wss://` (rustls with ring): the system's trusted certificates
/// (Debian's ca-certificates) plus every PEM certificate in `ca_cert` (a private CA).
pub fn tls_config(ca_cert: Option<&Path>) -> Result<Arc<rustls::ClientConfig>, ClientError> {
    use rustls::pki_types::{pem::PemObject, CertificateDer};
    let mut roots = rustls::RootCertStore::empty();
    // Unreadable system certificates leave those out; a --ca-cert can still be trusted.
    let system = rustls_native_certs::load_native_certs();
    roots.add_parsable_certificates(system.certs);
    if let Some(path) = ca_cert {
        let invalid =
            |why: String| ClientError::Invalid(format!("--ca-cert {}: {why}", path.display()));
        let pem = std::fs::read(path).map_err(|e| invalid(e.to_string()))?;
        let certs: Vec<CertificateDer<'static>> = CertificateDer::pem_slice_iter(&pem)
            .collect::<Result<_, _>>()
            .map_err(|e| invalid(format!("not PEM certificates: {e}")))?;
        if certs.is_empty() {
            return Err(invalid("no PEM certificate in the file".into()));
        }
        for cert in certs {
            roots
                .add(cert)
                .map_err(|e| invalid(format!("unusable certificate: {e}")))?;
        }
    }
    let config = rustls::ClientConfig::builder_with_provider(Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .map_err(|e| ClientError::Invalid(format!("TLS: {e}")))?
    .with_root_certificates(roots)
    .with_no_client_auth();
    Ok(Arc::new(config))
}

impl Client {
    /// A client of `server` (`http://` or `https://`), trusting `ca_cert` besides the
    /// system's certificates.
    pub fn new(
        server: &str,
        token: Option<String>,
        ca_cert: Option<&Path>,
    ) -> Result<Self, ClientError> {
        let base = server.trim_end_matches('/').to_string();
        if !(base.starts_with("http://") || base.starts_with("https://")) {
            return Err(ClientError::Invalid(format!(
                "--server must be an http:// or https:// URL, got '{server}'"
            )));
        }
        let tls = tls_config(ca_cert)?;
        let http = reqwest::Client::builder()
            .tls_backend_preconfigured((*tls).clone())
            .build()
            .map_err(|e| ClientError::Invalid(format!("HTTP client: {e}")))?;
        Ok(Self {
            base,
            token,
            http,
            tls,
        })
    }

    pub fn base(&self) -> &str {
        &self.base
    }

    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    fn request(&self, method: reqwest::Method, path: &str) -> reqwest::RequestBuilder {
        let req = self.http.request(method, self.url(path));
        match &self.token {
            Some(t) => req.bearer_auth(t),
            None => req,
        }
    }

    async fn send(
        &self,
        req: reqwest::RequestBuilder,
        path: &str,
    ) -> Result<reqwest::Response, ClientError> {
        let resp = req.send().await.map_err(|error| ClientError::Unreachable {
            url: self.url(path),
            error,
        })?;
        if resp.status().is_success() {
            return Ok(resp);
        }
        let status = resp.status();
        let text = resp.text().await.unwrap_or_default();
        Err(match serde_json::from_str::<ErrorBody>(&text) {
            Ok(body) => ClientError::Api { status, body },
            Err(_) => ClientError::Unexpected { status, text },
        })
    }

    async fn json<T: DeserializeOwned>(
        &self,
        req: reqwest::RequestBuilder,
        path: &str,
    ) -> Result<T, ClientError> {
        let resp = self.send(req, path).await?;
        let status = resp.status();
        let text = resp
            .text()
            .await
            .map_err(|error| ClientError::Unreachable {
                url: self.url(path),
                error,
            })?;
        serde_json::from_str(&text).map_err(|_| ClientError::Unexpected { status, text })
    }

    /// `/v1/server`: build, adapter, limits and the defaults of fields requests leave out.
    pub async fn server_info(&self) -> Result<lightcast_protocol::ServerInfo, ClientError> {
        self.json(
            self.request(reqwest::Method::GET, "/v1/server"),
            "/v1/server",
        )
        .await
    }

    pub async fn scenes(&self) -> Result<Vec<SceneInfo>, ClientError> {
        self.json(
            self.request(reqwest::Method::GET, "/v1/scenes"),
            "/v1/scenes",
        )
        .await
    }

    pub async fn scene(&self, id: &str) -> Result<SceneInfo, ClientError> {
        let path = format!("/v1/scenes/{id}");
        self.json(self.request(reqwest::Method::GET, &path), &path)
            .await
    }

    /// Uploads a `.glb`, or a `.gltf` with the files next to it that it references, and an
    /// environment image (`.hdr`/`.exr`) with it if given.
    pub async fn upload_scene(
        &self,
        file: &std::path::Path,
        name: Option<&str>,
        environment_image: Option<&std::path::Path>,
    ) -> Result<SceneInfo, ClientError> {
        let read = |p: &std::path::Path| {
            std::fs::read(p)
                .map_err(|e| ClientError::Invalid(format!("reading {}: {e}", p.display())))
        };
        let bytes = read(file)?;
        let file_name = file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene.glb".into());
        let mut path = "/v1/scenes".to_string();
        if let Some(n) = name {
            path = format!("{path}?name={}", encode_query(n));
        }
        let req = self.request(reqwest::Method::POST, &path);
        let req = if bytes.starts_with(b"glTF") && environment_image.is_none() {
            req.header("content-type", "model/gltf-binary").body(bytes)
        } else {
            let uris = if bytes.starts_with(b"glTF") {
                Vec::new()
            } else {
                let doc: serde_json::Value = serde_json::from_slice(&bytes).map_err(|e| {
                    ClientError::Invalid(format!("{}: not glTF JSON: {e}", file.display()))
                })?;
                external_uris(&doc)
            };
            let dir = file.parent().unwrap_or(std::path::Path::new("."));
            let mut form = reqwest::multipart::Form::new().part(
                "scene",
                reqwest::multipart::Part::bytes(bytes).file_name(file_name),
            );
            let image = environment_image.map(|p| {
                let name = p
                    .file_name()
                    .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
                (p.to_path_buf(), name)
            });
            let files = uris
                .into_iter()
                .map(|uri| (dir.join(&uri), uri))
                .chain(image);
            for (path, name) in files {
                let data = read(&path)?;
                form = form.part(
                    name.clone(),
                    reqwest::multipart::Part::bytes(data).file_name(name),
                );
            }
            req.multipart(form)
        };
        self.json(req, &path).await
    }

    pub async fn delete_scene(&self, id: &str) -> Result<(), ClientError> {
        let path = format!("/v1/scenes/{id}");
        self.send(self.request(reqwest::Method::DELETE, &path), &path)
            .await
            .map(drop)
    }

    /// One-shot render: the image bytes and the report.
    /// `request` is a `RenderRequest` as JSON: fields it leaves out get the server's defaults.
    pub async fn render(
        &self,
        request: &serde_json::Value,
    ) -> Result<(Vec<u8>, RenderReport), ClientError> {
        let path = "/v1/render";
        let resp = self
            .send(
                self.request(reqwest::Method::POST, path).json(request),
                path,
            )
            .await?;
        let status = resp.status();
        let report = resp
            .headers()
            .get("x-lightcast-report")
            .and_then(|v| v.to_str().ok())
            .and_then(|v| serde_json::from_str::<RenderReport>(v).ok())
            .ok_or_else(|| ClientError::Unexpected {
                status,
                text: "missing or malformed x-lightcast-report header".into(),
            })?;
        let bytes = resp
            .bytes()
            .await
            .map_err(|error| ClientError::Unreachable {
                url: self.url(path),
                error,
            })?;
        Ok((bytes.to_vec(), report))
    }

    pub async fn create_session(
        &self,
        params: &serde_json::Value,
    ) -> Result<SessionCreated, ClientError> {
        let path = "/v1/sessions";
        self.json(self.request(reqwest::Method::POST, path).json(params), path)
            .await
    }

    pub async fn session(&self, id: &str) -> Result<SessionInfo, ClientError> {
        let path = format!("/v1/sessions/{id}");
        self.json(self.request(reqwest::Method::GET, &path), &path)
            .await
    }

    pub async fn delete_session(&self, id: &str) -> Result<(), ClientError> {
        let path = format!("/v1/sessions/{id}");
        self.send(self.request(reqwest::Method::DELETE, &path), &path)
            .await
            .map(drop)
    }

    /// Opens a session's WebSocket with the ticket it was created with.
    pub async fn connect(&self, created: &SessionCreated) -> Result<Stream, ClientError> {
        let ws_base = self.base.replacen("http", "ws", 1);
        let url = format!(
            "{ws_base}{}?ticket={}",
            created.session.stream, created.ticket.ticket
        );
        let connector = tokio_tungstenite::Connector::Rustls(Arc::clone(&self.tls));
        let (ws, _) =
            tokio_tungstenite::connect_async_tls_with_config(&url, None, false, Some(connector))
                .await
                .map_err(|error| ClientError::WebSocket {
                    url: url.clone(),
                    error: Box::new(error),
                })?;
        Ok(Stream { ws, url })
    }
}

/// Query-string escaping of a value.
fn encode_query(v: &str) -> String {
    v.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}

/// External (non-`data:`) URIs of a glTF document's buffers and images.
fn external_uris(doc: &serde_json::Value) -> Vec<String> {
    ["buffers", "images"]
        .iter()
        .filter_map(|k| doc.get(*k)?.as_array())
        .flatten()
        .filter_map(|item| item.get("uri")?.as_str())
        .filter(|uri| !uri.starts_with("data:"))
        .map(str::to_string)
        .collect()
}

/// What arrives on a session's WebSocket.
pub enum Incoming {
    /// A frame: its header, the encoded image and its size on the wire.
    Frame {
        header: FrameHeader,
        payload: Vec<u8>,
        wire_bytes: usize,
    },
    Event(ServerEvent),
    Closed,
}

/// A session's WebSocket.
pub struct Stream {
    ws: tokio_tungstenite::WebSocketStream<
        tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
    >,
    url: String,
}

impl Stream {
    pub async fn send(&mut self, message: &ClientMessage) -> Result<(), ClientError> {
        let text = serde_json::to_string(message).map_err(ClientError::Event)?;
        self.ws
            .send(Message::Text(text.into()))
            .await
            .map_err(|error| ClientError::WebSocket {
                url: self.url.clone(),
                error: Box::new(error),
            })
    }

    pub async fn next(&mut self) -> Result<Incoming, ClientError> {
        loop {
            match self.ws.next().await {
                None | Some(Ok(Message::Close(_))) => return Ok(Incoming::Closed),
                Some(Err(error)) => {
                    return Err(ClientError::WebSocket {
                        url: self.url.clone(),
                        error: Box::new(error),
                    })
                }
                Some(Ok(Message::Binary(bytes))) => {
                    let (header, payload) = FrameHeader::decode(&bytes)?;
                    return Ok(Incoming::Frame {
                        payload: payload.to_vec(),
                        header,
                        wire_bytes: bytes.len(),
                    });
                }
                Some(Ok(Message::Text(text))) => {
                    return serde_json::from_str(&text)
                        .map(Incoming::Event)
                        .map_err(ClientError::Event)
                }
                Some(Ok(_)) => {}
            }
        }
    }

    pub async fn close(mut self) {
        let _ = self.ws.close(None).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn query_values_are_escaped() {
        assert_eq!(encode_query("a b&c=d"), "a%20b%26c%3Dd");
    }

    #[test]
    fn finds_external_uris_only() {
        let doc = serde_json::json!({"buffers": [{"uri": "a.bin"}, {"uri": "data:application/octet-stream;base64,AA=="}],
                                      "images": [{"uri": "t.png"}, {"bufferView": 0}]});
        assert_eq!(external_uris(&doc), vec!["a.bin", "t.png"]);
    }

    #[test]
    fn rejects_non_http_servers() {
        assert!(Client::new("ftp://x", None, None).is_err());
        assert!(Client::new("http://127.0.0.1:8080/", None, None).is_ok());
    }
}
