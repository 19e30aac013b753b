//! The shared scene store (`--scene-store DIR`): how a scene uploaded to one replica becomes
//! usable on every replica. Each added scene is written to `DIR/<id>/` — its uploaded files
//! (or its procedural recipe) and `scene.json` with its name, source, the SHA-256 of the token
//! that uploaded it (never the token) and its description — and a replica that is asked for
//! an id it does not hold loads it from there under its own budgets. Deleting a scene removes
//! its directory, and every replica forgets its copy at the next request naming it.
//!
//! A shared volume was chosen over fanning uploads out to every replica (each replica would
//! need every other's address and a retry story for the ones that are down, and a new replica
//! would start without the scenes) and over re-upload on a miss (every client would have to
//! keep its files): the chart mounts one ReadWriteMany volume on every pod, and a replica
//! needs nothing but the directory. Entries appear by rename, so a replica never reads half a
//! scene.

use crate::service::http::scenes::UploadedFile;
use lightcast_protocol::SceneInfo;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// The SHA-256 of a token, in hex: what the server keeps of the token that uploaded a scene.
pub fn owner_digest(token: &str) -> String {
    Sha256::digest(token.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// How to rebuild a stored scene.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Recipe {
    /// Uploaded files: the `.gltf`/`.glb` first, then the files it references.
    Upload { files: Vec<String> },
    /// A procedural scene's spec (`procedural:…` without the prefix).
    Procedural { spec: String },
}

/// `scene.json` of a stored scene.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StoredScene {
    pub id: String,
    /// The display name the scene was given.
    pub name: String,
    pub recipe: Recipe,
    /// [`owner_digest`] of the uploading token (`None`: auth off).
    pub owner_sha256: Option<String>,
    /// The scene as the replica that added it described it.
    pub info: SceneInfo,
}

#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("scene store {path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("scene store {path}: {error}")]
    Json {
        path: PathBuf,
        error: serde_json::Error,
    },
}

const RECORD: &str = "scene.json";

/// A directory of stored scenes, shared by every replica.
#[derive(Clone, Debug)]
pub struct SceneStore {
    dir: PathBuf,
}

impl SceneStore {
    /// The store in `dir`, created if missing; refused unless it can be written.
    pub fn open(dir: &Path) -> Result<Self, StoreError> {
        let io = |error| StoreError::Io {
            path: dir.to_path_buf(),
            error,
        };
        std::fs::create_dir_all(dir).map_err(io)?;
        let probe = dir.join(format!(".probe-{}", std::process::id()));
        std::fs::write(&probe, b"").map_err(io)?;
        std::fs::remove_file(&probe).map_err(io)?;
        Ok(Self {
            dir: dir.to_path_buf(),
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Ids are the server's own (`sc_…`, letters, digits and `_`); anything else is no
    /// stored scene, so a request's id never becomes a path outside the store.
    fn entry(&self, id: &str) -> Option<PathBuf> {
        let plain = !id.is_empty()
            && id.len() <= 64
            && id.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_');
        plain.then(|| self.dir.join(id))
    }

    /// Writes a scene: into a hidden directory first, then renamed into place.
    pub fn put(&self, record: &StoredScene, files: &[UploadedFile]) -> Result<(), StoreError> {
        let Some(target) = self.entry(&record.id) else {
            return Err(StoreError::Io {
                path: self.dir.clone(),
                error: std::io::Error::other(format!("'{}' is not a scene id", record.id)),
            });
        };
        let staging = self.dir.join(format!(".incoming-{}", record.id));
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |error| StoreError::Io { path, error }
        };
        std::fs::create_dir_all(&staging).map_err(io(&staging))?;
        for f in files {
            let path = staging.join(&f.name);
            std::fs::write(&path, &f.bytes).map_err(io(&path))?;
        }
        let json = serde_json::to_vec_pretty(record).map_err(|error| StoreError::Json {
            path: staging.join(RECORD),
            error,
        })?;
        std::fs::write(staging.join(RECORD), json).map_err(io(&staging))?;
        std::fs::rename(&staging, &target).map_err(io(&target))
    }

    /// The record of scene `id`, if stored.
    pub fn record(&self, id: &str) -> Result<Option<StoredScene>, StoreError> {
        let Some(dir) = self.entry(id) else {
            return Ok(None);
        };
        let path = dir.join(RECORD);
        match std::fs::read(&path) {
            Ok(bytes) => serde_json::from_slice(&bytes)
                .map(Some)
                .map_err(|error| StoreError::Json { path, error }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(error) => Err(StoreError::Io { path, error }),
        }
    }

    /// The files of stored upload `record`, main file first.
    pub fn files(&self, record: &StoredScene) -> Result<Vec<UploadedFile>, StoreError> {
        let Recipe::Upload { files } = &record.recipe else {
            return Ok(Vec::new());
        };
        let dir = self.dir.join(&record.id);
        files
            .iter()
            .map(|name| {
                let path = dir.join(name);
                std::fs::read(&path)
                    .map(|bytes| UploadedFile {
                        name: name.clone(),
                        bytes: bytes.into(),
                    })
                    .map_err(|error| StoreError::Io { path, error })
            })
            .collect()
    }

    /// Whether scene `id` is stored.
    pub fn contains(&self, id: &str) -> bool {
        self.entry(id).is_some_and(|dir| dir.join(RECORD).is_file())
    }

    /// Removes scene `id` (nothing if it is not stored).
    pub fn remove(&self, id: &str) -> Result<(), StoreError> {
        let Some(dir) = self.entry(id) else {
            return Ok(());
        };
        match std::fs::remove_dir_all(&dir) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(StoreError::Io {
                path: dir,
                error: e,
            }),
            _ => Ok(()),
        }
    }

    /// Every stored scene's record (unreadable entries are logged and skipped).
    pub fn list(&self) -> Vec<StoredScene> {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return Vec::new();
        };
        let mut out: Vec<StoredScene> = entries
            .filter_map(Result::ok)
            .filter_map(|e| e.file_name().to_str().map(str::to_string))
            .filter(|name| !name.starts_with('.'))
            .filter_map(|id| match self.record(&id) {
                Ok(record) => record,
                Err(e) => {
                    tracing::warn!("{e}");
                    None
                }
            })
            .collect();
        out.sort_by(|a, b| a.id.cmp(&b.id));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info(id: &str) -> SceneInfo {
        let camera = lightcast_protocol::Camera {
            position: [0.0, 0.0, 3.0],
            target: [0.0; 3],
            fov_y_degrees: 45.0,
        };
        let light = lightcast_protocol::Light {
            kind: lightcast_protocol::LightKind::Point,
            position: [0.0, 1.0, 0.0],
            direction: [0.0, -1.0, 0.0],
            color: [1.0; 3],
            intensity: 1.0,
            inner_cone: 0.4,
            outer_cone: 0.6,
        };
        SceneInfo {
            id: id.into(),
            name: "box".into(),
            source: "upload".into(),
            triangles: 12,
            vertices: 24,
            materials: 1,
            textures: 0,
            bounds: lightcast_protocol::Bounds {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            lights: Vec::new(),
            cameras: Vec::new(),
            default_camera: camera,
            default_light: light,
            caches: Vec::new(),
            precomputed: Vec::new(),
            sessions: 0,
            load_ms: 1.0,
        }
    }

    #[test]
    fn stored_scenes_round_trip_and_keep_no_token() {
        let dir = tempfile::tempdir().expect("tempdir");
        let store = SceneStore::open(dir.path()).expect("open");
        let record = StoredScene {
            id: "sc_abc123".into(),
            name: "box".into(),
            recipe: Recipe::Upload {
                files: vec!["box.gltf".into(), "box.bin".into()],
            },
            owner_sha256: Some(owner_digest("secret-token-0123456789")),
            info: info("sc_abc123"),
        };
        let files = [
            UploadedFile {
                name: "box.gltf".into(),
                bytes: b"{}".to_vec().into(),
            },
            UploadedFile {
                name: "box.bin".into(),
                bytes: vec![1, 2, 3].into(),
            },
        ];
        store.put(&record, &files).expect("put");
        assert!(store.contains("sc_abc123"));
        assert_eq!(
            store.record("sc_abc123").expect("read"),
            Some(record.clone())
        );
        let back = store.files(&record).expect("files");
        assert_eq!(back.len(), 2);
        assert_eq!(&back[1].bytes[..], &[1, 2, 3]);
        assert_eq!(store.list(), vec![record]);
        let json =
            std::fs::read_to_string(dir.path().join("sc_abc123").join(RECORD)).expect("scene.json");
        assert!(!json.contains("secret-token"), "{json}");
        // Ids that are not the server's never become paths.
        for id in ["../etc", "sc_a/b", "", "sc_.."] {
            assert!(!store.contains(id));
            assert_eq!(store.record(id).expect("no error"), None);
        }
        store.remove("sc_abc123").expect("remove");
        assert!(!store.contains("sc_abc123"));
        assert!(store.list().is_empty());
        store.remove("sc_abc123").expect("removing twice is fine");
    }

    #[test]
    fn owner_digests_are_sha256_hex() {
        assert_eq!(
            owner_digest("abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
