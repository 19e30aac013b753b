//! `/v1/scenes`: upload, list, inspect and delete scenes.

use super::{AppState, Caller};
use crate::scene::environment_image::{
    is_environment_image, EnvironmentImage, EnvironmentImageError,
};
use crate::scene::gltf_loader::{load_gltf_slice, LoadError, LoadLimits};
use crate::scene::procedural::Spec;
use crate::scene::Scene;
use crate::service::budget::over_budget;
use crate::service::error::{echo, parse_json, ApiError};
use crate::service::scene_store::{
    owner_digest, plain_file_name, Recipe, SceneStore, StoredScene, UploadedFile,
};
use crate::service::scenes::{owner_allows, triangles_over_budget, SceneEntry};
use axum::body::Bytes;
use axum::extract::{FromRequest, Multipart, Path, Query, Request, State};
use axum::http::{header, StatusCode};
use axum::{Extension, Json};
use http_body_util::BodyExt;
use lightcast_protocol::{Limits, ProceduralScene, SceneInfo};
use std::sync::Arc;
use std::time::Instant;

/// Reads every part of a multipart body: (part name, file).
pub async fn read_multipart(
    mut multipart: Multipart,
) -> Result<Vec<(String, UploadedFile)>, ApiError> {
    let mut parts = Vec::new();
    while let Some(field) = multipart.next_field().await.map_err(multipart_error)? {
        let part = field.name().unwrap_or_default().to_string();
        let name = field.file_name().unwrap_or(&part).to_string();
        let bytes = field.bytes().await.map_err(multipart_error)?;
        parts.push((part, UploadedFile { name, bytes }));
    }
    Ok(parts)
}

fn multipart_error(e: axum::extract::multipart::MultipartError) -> ApiError {
    let status = e.status();
    if status == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::new(status, "too_large", e.body_text())
    } else {
        ApiError::bad_request("malformed_multipart", e.body_text())
    }
}

/// Reads the whole body, answering one over its [`super::body_limit`] with 413 (a JSON body
/// to an endpoint that also takes uploads is held to the JSON limit, not the upload's).
pub async fn read_body(request: Request, limits: &Limits) -> Result<Bytes, ApiError> {
    let (limit, flag) = super::body_limit(limits, &request);
    let limited = http_body_util::Limited::new(
        request.into_body(),
        usize::try_from(limit).unwrap_or(usize::MAX),
    );
    match limited.collect().await {
        Ok(collected) => Ok(collected.to_bytes()),
        Err(e) if e.is::<http_body_util::LengthLimitError>() => Err(super::too_large(limit, flag)),
        Err(e) => Err(ApiError::bad_request("unreadable_body", e.to_string())),
    }
}

/// Refuses a name or spec the server would keep (and list) longer than
/// [`super::MAX_NAME_BYTES`].
pub fn bounded_name(field: &str, value: &str) -> Result<(), ApiError> {
    let max = super::MAX_NAME_BYTES as usize;
    if value.len() > max {
        return Err(ApiError::field(
            field,
            format!("{} bytes exceed this server's limit of {max}", value.len()),
        ));
    }
    Ok(())
}

fn content_type_is(request: &Request, mime: &str) -> bool {
    request
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.starts_with(mime))
}

pub fn is_multipart(request: &Request) -> bool {
    content_type_is(request, "multipart/form-data")
}

pub fn is_json(request: &Request) -> bool {
    content_type_is(request, "application/json")
}

/// Refuses a display name the server could not keep as data: empty, longer than
/// [`super::MAX_NAME_BYTES`], or with control characters (a NUL would cut it short in logs
/// and terminals). Any other text is fine: a name is never a path.
pub fn display_name(field: &str, value: &str) -> Result<(), ApiError> {
    bounded_name(field, value)?;
    if value.is_empty() {
        return Err(ApiError::field(field, "must not be empty"));
    }
    if let Some(c) = value.chars().find(|c| c.is_control()) {
        return Err(ApiError::field(
            field,
            format!("must not contain control characters ({c:?})"),
        ));
    }
    Ok(())
}

/// Every external URI of a glTF JSON document (buffers and images, not `data:` URIs).
fn external_uris(json: &[u8]) -> Result<Vec<String>, ApiError> {
    let doc: serde_json::Value = serde_json::from_slice(json)
        .map_err(|e| ApiError::bad_request("invalid_scene", format!("glTF JSON: {e}")))?;
    let mut uris = Vec::new();
    for list in ["buffers", "images"] {
        if let Some(items) = doc.get(list).and_then(|v| v.as_array()) {
            for uri in items.iter().filter_map(|i| i.get("uri")?.as_str()) {
                if !uri.starts_with("data:") {
                    uris.push(uri.to_string());
                }
            }
        }
    }
    Ok(uris)
}

/// What an upload may build: what is left of the per-scene and total budgets of triangles
/// and texture memory. Declared triangle counts are checked against it before each primitive
/// is read, so a scene that cannot be held costs no loading.
fn load_limits(state: &AppState) -> LoadLimits {
    let budget = state.scenes.budget();
    let left = budget.texture_bytes.available();
    LoadLimits {
        max_texture_bytes: state.limits.max_scene_texture_bytes.min(left),
        max_texture_size: state.limits.max_texture_size,
        ..LoadLimits::upload(state.limits.max_triangles.min(budget.triangles.available()))
    }
}

/// Loads an uploaded `.glb`/`.gltf` (`main`) with the files it references (`resources`).
/// Runs the loader on a blocking thread, at most [`AppState::loads`] at once: a load goes on
/// after its request times out, so unbounded, retries could pile up loads. External URIs must
/// name uploaded files.
pub async fn load_upload(
    state: &AppState,
    main: UploadedFile,
    resources: Vec<UploadedFile>,
) -> Result<Scene, ApiError> {
    let limits = load_limits(state);
    let permit = Arc::clone(&state.loads)
        .acquire_owned()
        .await
        .map_err(|_| ApiError::unavailable("the server is shutting down"))?;
    let max_side = state.limits.max_texture_size;
    let (max_triangles, total_triangles) =
        (state.limits.max_triangles, state.limits.max_total_triangles);
    let scene_texture_bytes = state.limits.max_scene_texture_bytes;
    let total_texture_bytes = state.limits.max_total_texture_bytes;
    let name = main
        .name
        .rsplit_once('.')
        .map_or(main.name.as_str(), |(stem, _)| stem)
        .to_string();
    let task = tokio::task::spawn_blocking(move || -> Result<Scene, ApiError> {
        let _permit = permit;
        let invalid = |e: LoadError| match e {
            LoadError::TextureBudget { .. } => over_budget(
                "texture_budget",
                format!(
                    "{}: {e} (at most {} MiB per scene, --max-scene-texture-bytes, and {} MiB \
                     over all scenes, --max-total-texture-bytes; textures are kept at most \
                     {max_side} texels a side, --max-texture-size)",
                    main.name,
                    scene_texture_bytes >> 20,
                    total_texture_bytes >> 20,
                ),
            ),
            LoadError::TriangleBudget { limit, .. } if limit < max_triangles => over_budget(
                "triangle_budget",
                format!(
                    "{}: {e}: the rest of the {total_triangles} this server holds over all \
                     scenes (--max-total-triangles); delete a scene first",
                    main.name
                ),
            ),
            e => ApiError::bad_request("invalid_scene", format!("{}: {e}", main.name)),
        };
        let scene = if main.bytes.starts_with(b"glTF") || resources.is_empty() {
            load_gltf_slice(&main.bytes, None, &name, limits).map_err(invalid)?
        } else {
            for uri in external_uris(&main.bytes)? {
                if !plain_file_name(&uri) || !resources.iter().any(|r| r.name == uri) {
                    return Err(ApiError::bad_request(
                        "invalid_scene",
                        format!(
                            "{}: URI '{uri}' must name one of the uploaded files by a plain file name",
                            main.name
                        ),
                    ));
                }
            }
            let dir = std::env::temp_dir().join(crate::service::ids::new_id("lightcast-upload"));
            let write = || -> std::io::Result<()> {
                std::fs::create_dir_all(&dir)?;
                for r in &resources {
                    std::fs::write(dir.join(&r.name), &r.bytes)?;
                }
                Ok(())
            };
            let written = write();
            let loaded = written
                .map_err(|e| ApiError::internal(format!("storing the upload: {e}")))
                .and_then(|()| {
                    load_gltf_slice(&main.bytes, Some(&dir), &name, limits).map_err(invalid)
                });
            let _ = std::fs::remove_dir_all(&dir);
            loaded?
        };
        let mut scene = scene;
        scene.environment_image = environment_image(&resources, &scene, &limits)?;
        Ok(scene)
    });
    task.await
        .map_err(|e| ApiError::internal(format!("the scene loader failed: {e}")))?
}

/// The environment image among an upload's `resources` (a `.hdr` or `.exr` file), decoded
/// within what is left of the scene's texture budget after `scene`'s own textures.
fn environment_image(
    resources: &[UploadedFile],
    scene: &Scene,
    limits: &LoadLimits,
) -> Result<Option<Arc<EnvironmentImage>>, ApiError> {
    let mut images = resources.iter().filter(|r| is_environment_image(&r.name));
    let (file, None) = (images.next(), images.next()) else {
        return Err(ApiError::field(
            "files",
            "more than one environment image (.hdr/.exr) uploaded; a scene has at most one",
        ));
    };
    let Some(file) = file else {
        return Ok(None);
    };
    let left = limits
        .max_texture_bytes
        .saturating_sub(crate::service::scenes::texture_bytes(scene));
    let image = EnvironmentImage::decode(&file.name, &file.bytes, left).map_err(|e| match e {
        EnvironmentImageError::Budget { .. } => over_budget(
            "texture_budget",
            format!(
                "{}: {e} (--max-scene-texture-bytes per scene, --max-total-texture-bytes over \
                 all scenes)",
                echo(&file.name)
            ),
        ),
        e => ApiError::bad_request("invalid_scene", format!("{}: {e}", echo(&file.name))),
    })?;
    Ok(Some(Arc::new(image)))
}

/// Splits uploaded files into the scene file and the files it references.
pub fn split_scene_files(
    files: Vec<UploadedFile>,
) -> Result<(UploadedFile, Vec<UploadedFile>), ApiError> {
    let (mains, resources): (Vec<_>, Vec<_>) = files.into_iter().partition(|f| {
        let lower = f.name.to_ascii_lowercase();
        lower.ends_with(".gltf") || lower.ends_with(".glb")
    });
    let mut mains = mains.into_iter();
    match (mains.next(), mains.next()) {
        (Some(main), None) => {
            bounded_name("files", &main.name)?;
            let names = || std::iter::once(&main).chain(&resources).map(|f| &f.name);
            if let Some(bad) = names().find(|name| !plain_file_name(name)) {
                return Err(ApiError::field(
                    "files",
                    format!(
                        "'{}' is not a plain file name (no '/', '\\', ':', '%', control \
                         characters or leading '.')",
                        echo(bad)
                    ),
                ));
            }
            let mut seen = std::collections::HashSet::new();
            if let Some(twice) = names().find(|name| !seen.insert(*name)) {
                return Err(ApiError::field(
                    "files",
                    format!("'{}' is uploaded twice", echo(twice)),
                ));
            }
            Ok((main, resources))
        }
        (None, _) => Err(ApiError::field(
            "files",
            "no .gltf or .glb file among the uploaded parts",
        )),
        (Some(_), Some(_)) => Err(ApiError::field(
            "files",
            "more than one .gltf/.glb file; upload one scene at a time",
        )),
    }
}

#[derive(serde::Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
#[serde(deny_unknown_fields)]
pub struct UploadQuery {
    /// Display name, kept as data, never as a file name: any text of 1 to 256 bytes without
    /// control characters (default: the uploaded file's stem, `upload` for a `.glb` body).
    #[param(min_length = 1)]
    name: Option<String>,
}

/// Lists the scenes.
#[utoipa::path(get, path = "/v1/scenes", tag = "scenes",
    responses((status = 200, body = Vec<SceneInfo>)))]
pub async fn list(State(state): State<Arc<AppState>>) -> Json<Vec<SceneInfo>> {
    let mut infos: Vec<SceneInfo> = state.scenes.list().iter().map(|e| e.info()).collect();
    if let Some(store) = &state.scene_store {
        let store = store.clone();
        let stored = tokio::task::spawn_blocking(move || store.list())
            .await
            .unwrap_or_default();
        // Scenes another replica added, as it described them, until one is used here.
        for record in stored {
            if !infos.iter().any(|i| i.id == record.id) {
                infos.push(record.info);
            }
        }
    }
    Json(infos)
}

/// Adds a scene: a `.glb` body (any content type but JSON or multipart), a
/// `multipart/form-data` body with one `.gltf`/`.glb` file, the files it references and at most
/// one equirectangular `.hdr`/`.exr` image (`render.environment` kind `image`), or a
/// JSON body naming a procedural scene. Its light caches are computed in the background;
/// `caches[0].state` shows progress.
#[utoipa::path(post, path = "/v1/scenes", tag = "scenes",
    params(UploadQuery),
    request_body(content(
        (Vec<u8> = "model/gltf-binary"),
        (ProceduralScene = "application/json"),
        (Vec<u8> = "multipart/form-data"))),
    responses(
        (status = 201, body = SceneInfo),
        (status = 400, description = "Invalid or hostile glTF, or bad parameters", body = lightcast_protocol::ErrorBody),
        (status = 413, description = "Upload too large, or its textures or triangles exceed a memory budget", body = lightcast_protocol::ErrorBody),
        (status = 429, description = "Too many scenes or uploads, for the server or the token", body = lightcast_protocol::ErrorBody)))]
pub async fn create(
    State(state): State<Arc<AppState>>,
    Extension(caller): Extension<Caller>,
    query: Result<Query<UploadQuery>, axum::extract::rejection::QueryRejection>,
    request: Request,
) -> Result<(StatusCode, Json<SceneInfo>), ApiError> {
    let Query(query) = query.map_err(|e| ApiError::bad_request("invalid_query", e.body_text()))?;
    if let Some(name) = &query.name {
        display_name("name", name)?;
    }
    // An upload's body may take --max-upload-bytes: its place is taken before it is read.
    let _upload = if is_json(&request) {
        None
    } else {
        Some(state.admission.upload(caller.0.as_deref())?)
    };
    if let Some(store) = &state.scene_store {
        check_store_room(store, &state.limits)?;
    }
    let started = Instant::now();
    let max_triangles = state.limits.max_triangles;
    // What the scene store keeps to rebuild the scene on another replica.
    let recipe_files: (Recipe, Vec<UploadedFile>);
    let (mut scene, source) = if is_multipart(&request) {
        let multipart = Multipart::from_request(request, &state)
            .await
            .map_err(|e| ApiError::bad_request("malformed_multipart", e.body_text()))?;
        let files = read_multipart(multipart)
            .await?
            .into_iter()
            .map(|(_, f)| f)
            .collect();
        let (main, resources) = split_scene_files(files)?;
        let kept: Vec<UploadedFile> = std::iter::once(main.clone())
            .chain(resources.iter().cloned())
            .collect();
        recipe_files = (Recipe::upload(&kept), kept);
        (
            load_upload(&state, main, resources).await?,
            "upload".to_string(),
        )
    } else if is_json(&request) {
        let body = read_body(request, &state.limits).await?;
        let spec: ProceduralScene = parse_json(&body)?;
        bounded_name("procedural", &spec.procedural)?;
        if let Some(name) = &spec.name {
            display_name("name", name)?;
        }
        let parsed = Spec::parse(&spec.procedural)
            .map_err(|e| ApiError::field("procedural", e.to_string()))?;
        recipe_files = (
            Recipe::Procedural {
                spec: spec.procedural.clone(),
            },
            Vec::new(),
        );
        let triangles = parsed.triangle_count();
        if triangles > max_triangles {
            return Err(ApiError::field(
                "procedural",
                format!("{triangles} triangles exceed this server's limit of {max_triangles}"),
            ));
        }
        let left = &state.scenes.budget().triangles;
        if triangles > left.available() {
            return Err(triangles_over_budget(triangles, left));
        }
        let mut scene = tokio::task::spawn_blocking(move || parsed.build())
            .await
            .map_err(|e| ApiError::internal(e.to_string()))?
            .map_err(|e| ApiError::field("procedural", e.to_string()))?;
        if let Some(name) = spec.name {
            scene.name = name;
        }
        (scene, format!("procedural:{}", spec.procedural))
    } else {
        let body = read_body(request, &state.limits).await?;
        if body.is_empty() {
            return Err(ApiError::bad_request(
                "empty_body",
                "send a .glb file as the body, a multipart upload or a procedural scene as JSON",
            ));
        }
        // The display name (`?name=`) is applied below, as data; the file's own name is
        // the server's.
        let main = UploadedFile {
            name: "upload.glb".into(),
            bytes: body,
        };
        recipe_files = (
            Recipe::upload(std::slice::from_ref(&main)),
            vec![main.clone()],
        );
        (
            load_upload(&state, main, Vec::new()).await?,
            "upload".to_string(),
        )
    };
    if let Some(name) = query.name {
        scene.name = name;
    }
    let load_ms = started.elapsed().as_secs_f64() * 1e3;
    let owner = caller.0.as_deref().map(owner_digest);
    let entry = state
        .scenes
        .insert(scene, source, None, load_ms, owner.clone())?;
    if let Some(store) = &state.scene_store {
        let (recipe, files) = recipe_files;
        let record = StoredScene {
            id: entry.id.clone(),
            name: entry.scene.name.clone(),
            recipe,
            owner_sha256: owner,
            info: entry.info(),
        };
        let store = store.clone();
        if let Err(e) = off_thread(move || store.put(&record, &files)).await {
            // Without its stored copy the other replicas could not use it: undo the add.
            let _ = state.scenes.remove(&entry.id, caller.0.as_deref());
            return Err(e);
        }
    }
    tracing::info!(scene = %entry.id, triangles = entry.scene.triangle_count(), "scene added");
    Ok((StatusCode::CREATED, Json(entry.info())))
}

/// Refuses an addition when the shared store already holds `--max-scenes` scenes (each
/// replica's own limit is checked when the scene is added to it).
fn check_store_room(store: &SceneStore, limits: &Limits) -> Result<(), ApiError> {
    let stored = store.list().len();
    if stored >= limits.max_scenes as usize {
        return Err(ApiError::too_many(
            "too_many_scenes",
            format!(
                "the scene store holds {stored} scenes, the limit (--max-scenes); delete one first"
            ),
        ));
    }
    Ok(())
}

/// `work` on a blocking thread; its error, or the thread's, as a 500 (the store's files, or a
/// recipe the server wrote itself, failing is the server's problem, not the request's).
async fn off_thread<T, E>(
    work: impl FnOnce() -> Result<T, E> + Send + 'static,
) -> Result<T, ApiError>
where
    T: Send + 'static,
    E: std::fmt::Display + Send + 'static,
{
    tokio::task::spawn_blocking(work)
        .await
        .map_err(|e| ApiError::internal(e.to_string()))?
        .map_err(|e| ApiError::internal(e.to_string()))
}

/// Whether scene `id` is one a client added (the server's own scenes are never stored).
fn client_scene(id: &str) -> bool {
    id.starts_with("sc_")
}

/// The scene `id` from this replica, or loaded from the scene store when another replica
/// added it; a scene deleted from the store is forgotten here too.
pub async fn fetch(state: &AppState, id: &str) -> Result<Arc<SceneEntry>, ApiError> {
    let Some(store) = state.scene_store.as_ref().filter(|_| client_scene(id)) else {
        return state.scenes.get(id);
    };
    let record = {
        let (store, id) = (store.clone(), id.to_string());
        off_thread(move || store.record(&id)).await?
    };
    let Some(record) = record else {
        // Deleted on another replica: sessions holding it keep it until they end.
        let _ = state.scenes.forget(id);
        return Err(ApiError::not_found("scene", id));
    };
    if let Ok(entry) = state.scenes.get(id) {
        return Ok(entry);
    }
    let started = Instant::now();
    let scene = match &record.recipe {
        Recipe::Upload { .. } => {
            let files = {
                let (store, record) = (store.clone(), record.clone());
                off_thread(move || store.files(&record)).await?
            };
            let mut files = files.into_iter();
            let main = files
                .next()
                .ok_or_else(|| ApiError::internal(format!("stored scene '{id}' has no files")))?;
            load_upload(state, main, files.collect()).await?
        }
        Recipe::Procedural { spec } => {
            let parsed = Spec::parse(spec).map_err(|e| ApiError::internal(e.to_string()))?;
            let triangles = parsed.triangle_count();
            let left = &state.scenes.budget().triangles;
            if triangles > left.available() {
                return Err(triangles_over_budget(triangles, left));
            }
            off_thread(move || parsed.build()).await?
        }
    };
    let mut scene = scene;
    scene.name = record.name.clone();
    if let Ok(entry) = state.scenes.get(id) {
        // Another request loaded it meanwhile.
        return Ok(entry);
    }
    let load_ms = started.elapsed().as_secs_f64() * 1e3;
    let entry = state.scenes.insert(
        scene,
        record.info.source.clone(),
        Some(id),
        load_ms,
        record.owner_sha256.clone(),
    )?;
    tracing::info!(scene = %id, "scene loaded from the scene store");
    Ok(entry)
}

/// Shows a scene: size, bounds, lights, cameras and the state of its light caches.
#[utoipa::path(get, path = "/v1/scenes/{id}", tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    responses((status = 200, body = SceneInfo), (status = 404, body = lightcast_protocol::ErrorBody)))]
pub async fn show(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<SceneInfo>, ApiError> {
    Ok(Json(fetch(&state, &id).await?.info()))
}

/// Deletes a scene no session uses (409 while any does; the default scene stays). With auth
/// on, only the token that uploaded a scene can delete it.
#[utoipa::path(delete, path = "/v1/scenes/{id}", tag = "scenes",
    params(("id" = String, Path, description = "Scene id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 403, description = "Uploaded with another token", body = lightcast_protocol::ErrorBody),
        (status = 404, body = lightcast_protocol::ErrorBody),
        (status = 409, description = "In use, or the default scene", body = lightcast_protocol::ErrorBody)))]
pub async fn delete(
    State(state): State<Arc<AppState>>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let Some(store) = state.scene_store.as_ref().filter(|_| client_scene(&id)) else {
        state.scenes.remove(&id, caller.0.as_deref())?;
        return Ok(StatusCode::NO_CONTENT);
    };
    let record = store
        .record(&id)
        .map_err(|e| ApiError::internal(e.to_string()))?;
    match (state.scenes.contains(&id), record) {
        (true, _) => state.scenes.remove(&id, caller.0.as_deref())?,
        (false, Some(record)) => {
            if !owner_allows(record.owner_sha256.as_deref(), caller.0.as_deref()) {
                return Err(ApiError::forbidden(format!(
                    "scene '{id}' was uploaded with another token; only that token can delete it"
                )));
            }
        }
        (false, None) => return Err(ApiError::not_found("scene", &id)),
    }
    store
        .remove(&id)
        .map_err(|e| ApiError::internal(e.to_string()))?;
    Ok(StatusCode::NO_CONTENT)
}

/// The scene a request names (loaded from the scene store where another replica added it).
pub async fn scene(state: &AppState, id: &str) -> Result<Arc<SceneEntry>, ApiError> {
    fetch(state, id).await.map_err(|e| match e.status {
        StatusCode::NOT_FOUND => {
            ApiError::field("render.scene", format!("no scene with id '{}'", echo(id)))
        }
        _ => e,
    })
}
