//! The shared scene store (`--scene-store`): how a scene uploaded to one replica becomes
//! usable on every replica. Each added scene is written to `DIR/<id>/`: its uploaded files
//! (or its procedural recipe) and `scene.json` with its name, source, the SHA-256 of the token
//! that uploaded it (never the token) and its description. A replica that is asked for an id
//! it does not hold loads it from there under its own budgets. Deleting a scene removes its
//! directory, and every replica forgets its copy at the next request naming it.
//!
//! Nothing a client sends becomes a path: a stored file is named by the SHA-256 of its bytes,
//! and the name it was uploaded under (what the glTF's URIs refer to) and the display name are
//! data in the record. A record is checked when it is read (its id is its directory's, its
//! files are hashes that the bytes still match), so a record written by hand or by an older
//! server cannot make a replica read outside its entry.
//!
//! A shared volume was chosen over fanning uploads out to every replica (each replica would
//! need every other's address and a retry story for the ones that are down, and a new replica
//! would start without the scenes) and over re-upload on a miss (every client would have to
//! keep its files): the chart mounts one ReadWriteMany volume on every pod, and a replica
//! needs nothing but the directory. Entries appear by rename, so a replica never reads half a
//! scene.

use lightcast_protocol::SceneInfo;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

/// An uploaded file: its name (from the multipart filename, or the stored one) and bytes.
#[derive(Clone)]
pub struct UploadedFile {
    pub name: String,
    pub bytes: bytes::Bytes,
}

/// The SHA-256 of `bytes`, in lowercase hex.
fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The SHA-256 of a token, in hex: what the server keeps of the token that uploaded a scene.
pub fn owner_digest(token: &str) -> String {
    sha256_hex(token.as_bytes())
}

/// A file name an upload may use (and a glTF URI may name): no separators, no parent
/// references or hidden names, no percent escapes (so a URI that names it cannot decode to
/// anything else), no control characters. Uploaded files are only ever written under such a
/// name into a fresh temporary directory; the store names them by their hash.
pub fn plain_file_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 255
        && !name.starts_with('.')
        && !name.contains(['/', '\\', '%', ':'])
        && !name.chars().any(char::is_control)
}

/// One uploaded file of a stored scene.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StoredFile {
    /// The name it was uploaded under: data (what the glTF's URIs name), never a path.
    pub name: String,
    /// The SHA-256 of its bytes, lowercase hex: its file name in the scene's entry.
    pub sha256: String,
}

impl StoredFile {
    pub fn of(file: &UploadedFile) -> Self {
        Self {
            name: file.name.clone(),
            sha256: sha256_hex(&file.bytes),
        }
    }
}

/// How to rebuild a stored scene.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Recipe {
    /// Uploaded files: the `.gltf`/`.glb` first, then the files it references.
    Upload { files: Vec<StoredFile> },
    /// A procedural scene's spec (`procedural:…` without the prefix).
    Procedural { spec: String },
}

impl Recipe {
    /// The recipe of uploaded files, the scene file first.
    pub fn upload(files: &[UploadedFile]) -> Self {
        Self::Upload {
            files: files.iter().map(StoredFile::of).collect(),
        }
    }
}

/// `scene.json` of a stored scene.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StoredScene {
    pub id: String,
    /// The display name the scene was given: data, never a path.
    pub name: String,
    pub recipe: Recipe,
    /// [`owner_digest`] of the uploading token (`None`: auth off).
    pub owner_sha256: Option<String>,
    /// The scene as the replica that added it described it.
    pub info: SceneInfo,
}

impl StoredScene {
    /// Why this record is not one the store would write for entry `id` (`None`: it is).
    fn defect(&self, id: &str) -> Option<String> {
        if self.id != id {
            return Some(format!("names id '{}'", self.id));
        }
        let Recipe::Upload { files } = &self.recipe else {
            return None;
        };
        if files.is_empty() {
            return Some("lists no files".into());
        }
        files.iter().find_map(|f| {
            if !is_sha256_hex(&f.sha256) {
                Some(format!(
                    "names a stored file '{}' that is not a SHA-256",
                    f.sha256
                ))
            } else if !plain_file_name(&f.name) {
                Some(format!(
                    "names an uploaded file '{}' that is not a plain name",
                    f.name
                ))
            } else {
                None
            }
        })
    }
}

fn is_sha256_hex(s: &str) -> bool {
    s.len() == 64 && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
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
    #[error("scene store {path}: not a record this server writes: it {defect}")]
    Invalid { path: PathBuf, defect: String },
}

const RECORD: &str = "scene.json";
/// Where a scene is written before it is renamed into place.
const STAGING_PREFIX: &str = ".incoming-";
/// A staging directory older than this was left by a replica that died while writing: a
/// write takes seconds, so it is removed when a replica opens the store.
const STALE_STAGING: Duration = Duration::from_secs(3600);

/// A directory of stored scenes, shared by every replica.
#[derive(Clone, Debug)]
pub struct SceneStore {
    dir: PathBuf,
}

impl SceneStore {
    /// The store in `dir`, created if missing; refused unless it can be written. Staging
    /// directories a dead replica left behind are removed.
    pub fn open(dir: &Path) -> Result<Self, StoreError> {
        let io = |error| StoreError::Io {
            path: dir.to_path_buf(),
            error,
        };
        std::fs::create_dir_all(dir).map_err(io)?;
        let probe = dir.join(format!(".probe-{}", std::process::id()));
        std::fs::write(&probe, b"").map_err(io)?;
        std::fs::remove_file(&probe).map_err(io)?;
        let store = Self {
            dir: dir.to_path_buf(),
        };
        store.remove_stale_staging(STALE_STAGING);
        Ok(store)
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn remove_stale_staging(&self, older_than: Duration) {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return;
        };
        let now = SystemTime::now();
        for entry in entries.filter_map(Result::ok) {
            let stale = entry
                .metadata()
                .and_then(|m| m.modified())
                .is_ok_and(|t| now.duration_since(t).unwrap_or_default() > older_than);
            if stale
                && entry
                    .file_name()
                    .to_string_lossy()
                    .starts_with(STAGING_PREFIX)
            {
                tracing::warn!(path = %entry.path().display(), "removing an abandoned scene write");
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
    }

    /// Ids are the server's own (`sc_…`, letters, digits and `_`); anything else is no
    /// stored scene, so a request's id never becomes a path outside the store.
    fn entry(&self, id: &str) -> Option<PathBuf> {
        let plain = !id.is_empty()
            && id.len() <= 64
            && id.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_');
        plain.then(|| self.dir.join(id))
    }

    /// Writes a scene: its files under their hashes and its record into a hidden directory,
    /// then renamed into place. `files` are the recipe's, in its order. On failure nothing
    /// is left behind.
    pub fn put(&self, record: &StoredScene, files: &[UploadedFile]) -> Result<(), StoreError> {
        let invalid = |defect: String| StoreError::Invalid {
            path: self.dir.join(&record.id),
            defect,
        };
        let Some(target) = self.entry(&record.id) else {
            return Err(invalid(format!("has the id '{}'", record.id)));
        };
        if let Some(defect) = record.defect(&record.id) {
            return Err(invalid(defect));
        }
        let stored: &[StoredFile] = match &record.recipe {
            Recipe::Upload { files } => files,
            Recipe::Procedural { .. } => &[],
        };
        if stored.len() != files.len()
            || stored
                .iter()
                .zip(files)
                .any(|(s, f)| *s != StoredFile::of(f))
        {
            return Err(invalid("does not describe the files given with it".into()));
        }
        let staging = self.dir.join(format!("{STAGING_PREFIX}{}", record.id));
        let written = self.write_entry(&staging, record, stored, files);
        let renamed = written.and_then(|()| {
            std::fs::rename(&staging, &target).map_err(|error| StoreError::Io {
                path: target.clone(),
                error,
            })
        });
        if renamed.is_err() {
            let _ = std::fs::remove_dir_all(&staging);
        }
        renamed
    }

    fn write_entry(
        &self,
        staging: &Path,
        record: &StoredScene,
        stored: &[StoredFile],
        files: &[UploadedFile],
    ) -> Result<(), StoreError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |error| StoreError::Io { path, error }
        };
        std::fs::create_dir(staging).map_err(io(staging))?;
        for (s, f) in stored.iter().zip(files) {
            let path = staging.join(&s.sha256);
            std::fs::write(&path, &f.bytes).map_err(io(&path))?;
        }
        let path = staging.join(RECORD);
        let json = serde_json::to_vec_pretty(record).map_err(|error| StoreError::Json {
            path: path.clone(),
            error,
        })?;
        std::fs::write(&path, json).map_err(io(&path))
    }

    /// The record of scene `id`, if stored; a record this server would not have written is
    /// an error, never followed.
    pub fn record(&self, id: &str) -> Result<Option<StoredScene>, StoreError> {
        let Some(dir) = self.entry(id) else {
            return Ok(None);
        };
        let path = dir.join(RECORD);
        let bytes = match std::fs::read(&path) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(error) => return Err(StoreError::Io { path, error }),
        };
        let record: StoredScene =
            serde_json::from_slice(&bytes).map_err(|error| StoreError::Json {
                path: path.clone(),
                error,
            })?;
        match record.defect(id) {
            Some(defect) => Err(StoreError::Invalid { path, defect }),
            None => Ok(Some(record)),
        }
    }

    /// The files of stored upload `record` (as [`Self::record`] returned it), main file
    /// first, each checked against its hash.
    pub fn files(&self, record: &StoredScene) -> Result<Vec<UploadedFile>, StoreError> {
        let Recipe::Upload { files } = &record.recipe else {
            return Ok(Vec::new());
        };
        let Some(dir) = self.entry(&record.id) else {
            return Ok(Vec::new());
        };
        files
            .iter()
            .map(|f| {
                let path = dir.join(&f.sha256);
                let bytes = std::fs::read(&path).map_err(|error| StoreError::Io {
                    path: path.clone(),
                    error,
                })?;
                if sha256_hex(&bytes) != f.sha256 {
                    return Err(StoreError::Invalid {
                        path,
                        defect: "holds bytes that no longer match their hash".into(),
                    });
                }
                Ok(UploadedFile {
                    name: f.name.clone(),
                    bytes: bytes.into(),
                })
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

    /// Every stored scene's record (unreadable or invalid entries are logged and skipped).
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
            default_light: light.clone(),
            default_lights: vec![light],
            camera_region: None,
            environment_image: None,
            nodes: Vec::new(),
            animations: Vec::new(),
            caches: Vec::new(),
            precomputed: Vec::new(),
            sessions: 0,
            load_ms: 1.0,
        }
    }

    fn upload(name: &str, bytes: &[u8]) -> UploadedFile {
        UploadedFile {
            name: name.into(),
            bytes: bytes.to_vec().into(),
        }
    }

    fn record_of(id: &str, files: &[UploadedFile]) -> StoredScene {
        StoredScene {
            id: id.into(),
            name: "box".into(),
            recipe: Recipe::upload(files),
            owner_sha256: Some(owner_digest("secret-token-0123456789")),
            info: info(id),
        }
    }

    /// Every path under `dir`, relative to it.
    fn tree(dir: &Path) -> Vec<String> {
        let mut out = Vec::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d)
                .expect("read_dir")
                .filter_map(Result::ok)
            {
                let p = e.path();
                out.push(p.strip_prefix(dir).expect("inside").display().to_string());
                if p.is_dir() {
                    stack.push(p);
                }
            }
        }
        out.sort();
        out
    }

    #[test]
    fn stored_scenes_round_trip_and_keep_no_token() {
        let dir = tempfile::tempdir().expect("tempdir");
        let store = SceneStore::open(dir.path()).expect("open");
        let files = [upload("box.gltf", b"{}"), upload("box.bin", &[1, 2, 3])];
        let record = record_of("sc_abc123", &files);
        store.put(&record, &files).expect("put");
        assert!(store.contains("sc_abc123"));
        assert_eq!(
            store.record("sc_abc123").expect("read"),
            Some(record.clone())
        );
        let back = store.files(&record).expect("files");
        assert_eq!(back.len(), 2);
        assert_eq!(
            (back[1].name.as_str(), &back[1].bytes[..]),
            ("box.bin", &[1u8, 2, 3][..])
        );
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
    fn stored_files_are_named_by_their_hash_whatever_they_were_uploaded_as() {
        let outer = tempfile::tempdir().expect("tempdir");
        let root = outer.path().join("store");
        let store = SceneStore::open(&root).expect("open");
        let files = [upload("scene.json", b"glTF bytes")];
        let record = record_of("sc_one", &files);
        store.put(&record, &files).expect("put");
        let hash = sha256_hex(b"glTF bytes");
        assert_eq!(
            tree(&root),
            ["sc_one", &format!("sc_one/{hash}"), "sc_one/scene.json"]
        );
        assert_eq!(store.record("sc_one").expect("read"), Some(record.clone()));
        assert_eq!(
            &store.files(&record).expect("files")[0].bytes[..],
            b"glTF bytes"
        );
    }

    #[test]
    fn records_that_name_paths_are_refused_and_leave_nothing_behind() {
        let outer = tempfile::tempdir().expect("tempdir");
        let root = outer.path().join("store");
        let store = SceneStore::open(&root).expect("open");
        let files = [upload("box.glb", b"glTF")];
        let mut record = record_of("sc_two", &files);
        let secret = outer.path().join("secret.glb");
        std::fs::write(&secret, b"not the store's").expect("write");
        for hostile in [
            "../secret.glb".to_string(),
            "../../secret.glb".to_string(),
            secret.display().to_string(),
            String::new(),
        ] {
            // Written as given, a record naming a path is never followed on read.
            let Recipe::Upload { files: stored } = &mut record.recipe else {
                unreachable!("an upload recipe");
            };
            stored[0].sha256 = hostile.clone();
            let before = tree(&root);
            assert!(matches!(
                store.put(&record, &files),
                Err(StoreError::Invalid { .. })
            ));
            assert_eq!(tree(&root), before, "{hostile}");
            let entry = root.join("sc_two");
            std::fs::create_dir_all(&entry).expect("mkdir");
            std::fs::write(
                entry.join(RECORD),
                serde_json::to_vec(&record).expect("json"),
            )
            .expect("write");
            let read = store.record("sc_two");
            assert!(
                matches!(&read, Err(StoreError::Invalid { defect, .. }) if defect.contains("not a SHA-256")),
                "{hostile}: {read:?}"
            );
            assert!(store.list().is_empty());
            assert!(
                store.files(&record).is_err(),
                "{hostile}: read a file it names"
            );
        }
        // An uploaded name that is a path, and a record filed under another id.
        let mut record = record_of("sc_two", &files);
        let Recipe::Upload { files: stored } = &mut record.recipe else {
            unreachable!("an upload recipe");
        };
        stored[0].name = "../x.glb".into();
        std::fs::write(
            root.join("sc_two").join(RECORD),
            serde_json::to_vec(&record).expect("json"),
        )
        .expect("write");
        assert!(matches!(
            store.record("sc_two"),
            Err(StoreError::Invalid { .. })
        ));
        let elsewhere = record_of("sc_victim", &files);
        std::fs::write(
            root.join("sc_two").join(RECORD),
            serde_json::to_vec(&elsewhere).expect("json"),
        )
        .expect("write");
        assert!(matches!(
            store.record("sc_two"),
            Err(StoreError::Invalid { .. })
        ));
        assert_eq!(std::fs::read(&secret).expect("read"), b"not the store's");
    }

    #[test]
    fn files_whose_bytes_changed_are_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let store = SceneStore::open(dir.path()).expect("open");
        let files = [upload("box.glb", b"glTF original")];
        let record = record_of("sc_three", &files);
        store.put(&record, &files).expect("put");
        let Recipe::Upload { files: stored } = &record.recipe else {
            unreachable!("an upload recipe");
        };
        std::fs::write(
            dir.path().join("sc_three").join(&stored[0].sha256),
            b"glTF other",
        )
        .expect("overwrite");
        assert!(matches!(
            store.files(&record),
            Err(StoreError::Invalid { .. })
        ));
        // A record that does not describe the files given with it is not written.
        let other = [upload("box.glb", b"glTF another")];
        assert!(matches!(
            store.put(&record_of("sc_four", &files), &other),
            Err(StoreError::Invalid { .. })
        ));
        assert!(!store.contains("sc_four"));
    }

    #[test]
    fn abandoned_writes_are_removed_when_the_store_opens() {
        let dir = tempfile::tempdir().expect("tempdir");
        let store = SceneStore::open(dir.path()).expect("open");
        let staging = dir.path().join(format!("{STAGING_PREFIX}sc_dead"));
        std::fs::create_dir(&staging).expect("mkdir");
        std::fs::write(staging.join("x"), b"half").expect("write");
        store.remove_stale_staging(STALE_STAGING);
        assert!(staging.exists(), "a fresh write is another replica's");
        store.remove_stale_staging(Duration::ZERO);
        assert!(!staging.exists());
    }

    #[test]
    fn plain_file_names_are_never_paths() {
        for good in ["box.glb", "scene.json", "a b.png", "ünï.bin"] {
            assert!(plain_file_name(good), "{good}");
        }
        for bad in [
            "", ".", "..", ".hidden", "../x", "a/b", "a\\b", "/abs", "C:x", "%2e%2e", "a\0b",
            "a\nb",
        ] {
            assert!(!plain_file_name(bad), "{bad:?}");
        }
        assert!(!plain_file_name(&"x".repeat(256)));
    }

    #[test]
    fn owner_digests_are_sha256_hex() {
        assert_eq!(
            owner_digest("abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
