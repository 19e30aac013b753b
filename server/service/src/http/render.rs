//! `POST /v1/render`: one frame, returned as an image with its timing report.

use super::scenes::{is_multipart, load_upload, read_body, read_multipart, split_scene_files};
use super::{AppState, Caller};
use crate::gi::precompute::PrecomputeKey;
use crate::gi::reference::params::SPP;
use crate::service::cost::{
    check_frame, chunk_spp, one_shot_spp, request_seconds, Compared, Submission,
};
use crate::service::encode;
use crate::service::error::ApiError;
use crate::service::params::{check_gi, check_quality, frame_shape, resolve};
use crate::service::render_loop::{Command, CompareWith, OneShot};
use crate::service::scenes::{precompute_failed, precompute_label, Now, SceneEntry};
use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::{header, HeaderValue};
use axum::response::{IntoResponse, Response};
use axum::Extension;
use lightcast_protocol::{Codec, ImageFormat, RenderReport, RenderRequest};
use sha2::{Digest, Sha256};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Samples per pixel of a `compare_to: reference` render when the request names none.
const DEFAULT_COMPARE_SPP: u32 = 256;

/// Header carrying the JSON [`RenderReport`].
pub const REPORT_HEADER: &str = "x-lightcast-report";

/// The request and, for a multipart body, an uploaded scene to render instead of a stored one.
async fn read_request(
    state: &Arc<AppState>,
    caller: &Caller,
    request: Request,
) -> Result<(RenderRequest, bool, Option<Arc<SceneEntry>>), ApiError> {
    if !is_multipart(&request) {
        let body = read_body(request, &state.limits).await?;
        return Ok((state.defaults.parse(&body)?, names_spp(&body), None));
    }
    let _upload = state.admission.upload(caller.0.as_deref())?;
    let multipart = Multipart::from_request(request, state)
        .await
        .map_err(|e| ApiError::bad_request("malformed_multipart", e.body_text()))?;
    let mut req = None;
    let mut spp_named = false;
    let mut files = Vec::new();
    for (part, file) in read_multipart(multipart).await? {
        if part == "request" {
            let limit = state.limits.max_message_bytes;
            if file.bytes.len() as u64 > limit {
                return Err(ApiError::new(
                    axum::http::StatusCode::PAYLOAD_TOO_LARGE,
                    "too_large",
                    format!(
                        "the 'request' part exceeds this server's limit of {limit} bytes for \
                         JSON (--max-message-bytes)"
                    ),
                ));
            }
            req = Some(state.defaults.parse::<RenderRequest>(&file.bytes)?);
            spp_named = names_spp(&file.bytes);
        } else {
            files.push(file);
        }
    }
    let req = req.ok_or_else(|| {
        ApiError::field(
            "request",
            "a multipart render needs a 'request' part (JSON)",
        )
    })?;
    let (main, resources) = split_scene_files(files)?;
    let started = Instant::now();
    let scene = load_upload(state, main, resources).await?;
    // Not registered: the scene lives for this request only (its light caches stay in the
    // cache store, so the same file renders faster next time).
    let entry = state
        .scenes
        .detached(scene, started.elapsed().as_secs_f64() * 1e3)?;
    Ok((req, spp_named, Some(entry)))
}

/// Whether a request body sets `render.gi.spp` itself (else a one-shot `reference` takes
/// [`one_shot_spp`]).
fn names_spp(body: &[u8]) -> bool {
    serde_json::from_slice::<serde_json::Value>(body)
        .ok()
        .and_then(|v| v.pointer("/render/gi/spp").map(|spp| !spp.is_null()))
        .unwrap_or(false)
}

/// Waits until the precomputation `key` a frame needs is ready (or failed), within the
/// deadline.
async fn wait_for_precomputed(
    state: &AppState,
    entry: &Arc<SceneEntry>,
    key: &PrecomputeKey,
    deadline: Instant,
) -> Result<(), ApiError> {
    let what = precompute_label(key);
    loop {
        match state.scenes.precomputed(entry, key) {
            Now::Ready(_) => return Ok(()),
            Now::Failed(e) => return Err(precompute_failed(entry, key, &e).within("render")),
            Now::Busy => {
                return Err(ApiError::unavailable(format!(
                    "the server is busy precomputing other scenes and has not queued the \
                     {what} of this scene yet; try again shortly"
                )))
            }
            Now::Pending if Instant::now() >= deadline => {
                return Err(ApiError::unavailable(format!(
                    "still computing the {what} of this scene; try again shortly"
                )))
            }
            Now::Pending => tokio::time::sleep(Duration::from_millis(20)).await,
        }
    }
}

fn request_hash(req: &RenderRequest) -> String {
    let canonical = serde_json::to_vec(req).unwrap_or_default();
    Sha256::digest(&canonical)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// JSON with every non-ASCII character escaped, so it fits an HTTP header.
fn ascii_json(json: &str) -> String {
    let mut out = String::with_capacity(json.len());
    for c in json.chars() {
        if c.is_ascii() && !c.is_ascii_control() {
            out.push(c);
        } else {
            let mut units = [0u16; 2];
            for unit in c.encode_utf16(&mut units) {
                out.push_str(&format!("\\u{unit:04x}"));
            }
        }
    }
    out
}

fn floats_le(data: &[[f32; 4]]) -> Vec<u8> {
    data.iter()
        .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
        .collect()
}

/// Renders one frame and answers with the image (PNG, JPEG, or raw little-endian float32
/// RGBA of the HDR or indirect buffer). The timing report is in the `x-lightcast-report`
/// header (JSON). The body is JSON (`RenderRequest`), or multipart with a `request` part
/// (JSON) and a `.glb`/`.gltf` file (plus the files it references) to render instead of a
/// stored scene. The same request on the same build and adapter gives identical pixels.
#[utoipa::path(post, path = "/v1/render", tag = "render",
    request_body(content(
        (RenderRequest = "application/json"),
        (Vec<u8> = "multipart/form-data"))),
    responses(
        (status = 200, description = "The image; `x-lightcast-report` holds the RenderReport JSON",
            headers(("x-lightcast-report" = String, description = "RenderReport as JSON")),
            content(
                (Vec<u8> = "image/png"),
                (Vec<u8> = "image/jpeg"),
                (Vec<u8> = "application/octet-stream"))),
        (status = 400, description = "A parameter is invalid; `field` names it", body = lightcast_protocol::ErrorBody),
        (status = 413, description = "The uploaded scene exceeds a memory budget", body = lightcast_protocol::ErrorBody),
        (status = 429, description = "Too many renders or uploads at once, for the server or the token", body = lightcast_protocol::ErrorBody),
        (status = 503, description = "The GI method's per-scene precomputation (light caches, BVH) still computing, or shutting down", body = lightcast_protocol::ErrorBody)))]
pub async fn render(
    State(state): State<Arc<AppState>>,
    Extension(caller): Extension<Caller>,
    request: Request,
) -> Result<Response, ApiError> {
    let deadline = Instant::now()
        + Duration::from_millis(state.limits.request_timeout_ms)
            .saturating_sub(Duration::from_millis(50));
    // Held until the answer is made: the queue of renders and their frames stay bounded.
    let _render = state.admission.render(caller.0.as_deref())?;
    let (mut req, spp_named, uploaded) = read_request(&state, &caller, request).await?;
    let entry = match uploaded {
        Some(e) => e,
        None => super::scenes::scene(&state, &req.render.scene).await?,
    };
    let quality = check_quality(req.quality)?;
    let raw = matches!(req.format, ImageFormat::RawFinal | ImageFormat::RawIndirect);
    if raw && req.render.view != lightcast_protocol::View::FINAL {
        return Err(ApiError::field(
            "format",
            "raw buffers are of the final frame; use view 'final'",
        ));
    }
    if req.format == ImageFormat::RawIndirect && req.render.gi.method == crate::gi::none::NONE {
        return Err(ApiError::field(
            "format",
            "raw_indirect needs GI; set render.gi.method to anything but none",
        ));
    }
    let compare = match req.compare_to {
        None if req.compare_modelled => {
            return Err(ApiError::field(
                "compare_modelled",
                "compares with the reference of the modelled light transport beside the full \
                 one: set compare_to to 'reference'",
            ))
        }
        None => None,
        Some(crate::gi::reference::REFERENCE) => {
            let spp = req.compare_spp.unwrap_or(DEFAULT_COMPARE_SPP);
            // The comparison render's parameters, checked like any reference render's; its
            // sample count is the request's `compare_spp`.
            let mut truth = req.render.gi.clone();
            truth.method = crate::gi::reference::REFERENCE;
            truth.set(SPP.name, spp);
            check_gi(&truth, &state.limits).map_err(|mut e| {
                if e.body.field.as_deref() == Some("gi.spp") {
                    e.body.field = Some("compare_spp".into());
                    e.body.message = e.body.message.replacen("gi.spp", "compare_spp", 1);
                    e
                } else {
                    e.within("render")
                }
            })?;
            // The modelled transport's reference only where it differs from the full one.
            let modelled = Some(crate::gi::reference_senders(&req.render.gi))
                .filter(|s| req.compare_modelled && *s != lightcast_protocol::Senders::Full);
            Some(CompareWith {
                method: crate::gi::reference::REFERENCE,
                spp,
                modelled,
            })
        }
        Some(other) => {
            return Err(ApiError::field(
                "compare_to",
                format!("renders compare with 'reference' only, not '{other}'"),
            ))
        }
    };
    let mut resolved = resolve(&req.render, &entry, &state.limits, state.max_texture)
        .map_err(|e| e.within("render"))?;
    let shape = frame_shape(&resolved.settings, &entry);
    let set_units = |g: &lightcast_protocol::GiParams| entry.estimated_set_units(g);
    let comparing = compare.map(|c| Compared {
        spp: c.spp,
        renders: 1 + u32::from(c.modelled.is_some()),
    });
    if !spp_named && req.render.gi.method == crate::gi::reference::REFERENCE {
        let spp = one_shot_spp(
            &req.render.gi,
            shape,
            &set_units,
            comparing,
            &state.limits,
            SPP.u32(&req.render.gi),
        );
        req.render.gi.set(SPP.name, spp);
        resolved.settings.gi.set(SPP.name, spp);
    }
    check_frame(
        &req.render.gi,
        shape,
        &set_units,
        Submission::OneShot { compare: comparing },
        &state.limits,
    )
    .map_err(|e| {
        if e.body.field.as_deref() == Some("compare_spp") {
            e
        } else {
            e.within("render")
        }
    })?;
    resolved.settings.capture_hdr |= raw;
    let compared = match compare {
        Some(c) => entry.precompute_key(&lightcast_protocol::GiParams::new(c.method))?,
        None => None,
    };
    // Both are queued before either is waited for, so they are built back to back.
    for key in resolved.precompute.iter().chain(&compared) {
        state.scenes.precomputed(&entry, key);
    }
    if let Some(key) = &resolved.precompute {
        wait_for_precomputed(&state, &entry, key, deadline).await?;
    }
    if let Some(key) = &compared {
        // A failure of the comparison's data is the comparison's, not the render's method.
        wait_for_precomputed(&state, &entry, key, deadline)
            .await
            .map_err(|mut e| {
                if e.body.field.is_some() {
                    e.body.field = Some("compare_to".into());
                }
                e
            })?;
    }
    let estimated_seconds =
        request_seconds(&req.render.gi, shape, &set_units, comparing, &state.limits);
    // The report and hash name what was actually rendered, defaults included.
    req.render.camera = Some(resolved.settings.camera.clone());
    // One light stays the shorthand, so a single-light request hashes as it always did.
    match resolved.settings.lights.as_slice() {
        [one] => (req.render.light, req.render.lights) = (Some(one.clone()), None),
        many => (req.render.light, req.render.lights) = (None, Some(many.to_vec())),
    }
    req.quality = Some(quality);
    let hash = request_hash(&req);
    let (tx, rx) = tokio::sync::oneshot::channel();
    state
        .render_tx
        .send(Command::Render(Box::new(OneShot::new(
            Arc::clone(&entry),
            resolved.clone(),
            tx,
            compare,
            chunk_spp(&req.render.gi, shape, comparing, &state.limits),
        ))))
        .map_err(|_| ApiError::unavailable("the render loop has stopped"))?;
    let result = rx
        .await
        .map_err(|_| ApiError::unavailable("the render loop has stopped"))??;
    let rendered = result.rendered;
    let mut comparisons = result.comparisons.into_iter();
    let (gpu_ms, stages) = (rendered.gpu_ms(), rendered.stages());
    let format = req.format;
    let encode_started = Instant::now();
    let body = match format {
        ImageFormat::Png | ImageFormat::Jpeg => {
            let codec = if format == ImageFormat::Png {
                Codec::Png
            } else {
                Codec::Jpeg
            };
            let image = rendered.image;
            let task = tokio::task::spawn_blocking(move || encode::encode(&image, codec, quality));
            task.await
                .map_err(|e| ApiError::internal(e.to_string()))?
                .map_err(|e| ApiError::internal(e.to_string()))?
        }
        ImageFormat::RawFinal => floats_le(rendered.hdr.as_deref().unwrap_or_default()),
        ImageFormat::RawIndirect => floats_le(rendered.indirect.as_deref().unwrap_or_default()),
    };
    let report = RenderReport {
        build: state.build.clone(),
        adapter: state.adapter.clone(),
        request_hash: hash,
        width: resolved.settings.width,
        height: resolved.settings.height,
        format,
        gpu_ms,
        stages,
        timing_source: serde_json::to_value(rendered.timing_source)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default(),
        encode_ms: encode_started.elapsed().as_secs_f64() * 1e3,
        queue_ms: result.queue_ms,
        exposure_scale: rendered.exposure_scale,
        camera: resolved.settings.camera,
        light: resolved.settings.lights.first().cloned(),
        lights: resolved.settings.lights,
        environment: resolved.settings.environment,
        samples: rendered.progress.map(|p| p.samples),
        relative_error: rendered
            .progress
            .map(|p| f64::from(p.relative_standard_error)),
        comparison: comparisons.next(),
        comparison_modelled: comparisons.next(),
        estimated_seconds: Some(estimated_seconds),
        timing_note: rendered.timing_source.note(state.adapter_is_cpu),
    };
    let report_json =
        ascii_json(&serde_json::to_string(&report).map_err(|e| ApiError::internal(e.to_string()))?);
    let mut response = body.into_response();
    let headers = response.headers_mut();
    headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(format.content_type()),
    );
    headers.insert(
        REPORT_HEADER,
        HeaderValue::from_str(&report_json).map_err(|e| ApiError::internal(e.to_string()))?,
    );
    Ok(response)
}
