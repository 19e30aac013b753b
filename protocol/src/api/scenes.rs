//! Scenes as `/v1/scenes` lists them, with the state of their precomputations.

use super::*;

/// State of one of a scene's precomputations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum PrecomputeState {
    Queued,
    Running,
    Ready,
    Failed,
}

/// One per-scene precomputation of a GI method, one per distinct parameters in use: the
/// light caches of `lightskin`/`brsm` (kind `light_caches`), the BVH of `reference` (kind
/// `bvh`). Frames of a method whose precomputation is not ready show direct light.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Precomputed {
    /// `light_caches` or `bvh`.
    pub kind: String,
    /// What people call it (`light caches`, `BVH`).
    pub label: String,
    /// Its parameters by their names in the render's `gi` object (e.g. `cache_distance`),
    /// the scene's defaults filled in.
    pub params: std::collections::BTreeMap<String, f32>,
    pub state: PrecomputeState,
    /// Its size in the units the server budgets it in, once ready; absent for kinds whose
    /// size follows from the scene's triangles.
    pub units: Option<u64>,
    /// What `units` counts (`light caches`).
    pub unit: Option<String>,
    /// Current step while running (e.g. `clustering`), with progress in [0, 1].
    pub step: Option<String>,
    pub progress: Option<f32>,
    /// Time the precomputation (or loading it from the store) took.
    pub seconds: Option<f64>,
    pub from_store: Option<bool>,
    pub error: Option<String>,
}

/// Kind of [`Precomputed`] for the light caches.
pub const LIGHT_CACHES: &str = "light_caches";

impl CacheVariant {
    /// The light-cache view of a [`Precomputed`] of kind [`LIGHT_CACHES`].
    pub fn from_precomputed(p: &Precomputed) -> Option<Self> {
        if p.kind != LIGHT_CACHES {
            return None;
        }
        let param = |name: &str| p.params.get(name).copied().unwrap_or(f32::NAN);
        Some(Self {
            state: p.state,
            cache_distance: param("cache_distance"),
            cache_angle: param("cache_angle"),
            caches: p.units,
            step: p.step.clone(),
            progress: p.progress,
            seconds: p.seconds,
            from_store: p.from_store,
            error: p.error.clone(),
        })
    }
}

/// One set of light caches of a scene (one per distinct cache parameters in use): the
/// `light_caches` entries of [`SceneInfo::precomputed`], as older clients read them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct CacheVariant {
    pub state: PrecomputeState,
    pub cache_distance: f32,
    pub cache_angle: f32,
    /// Number of caches, once ready, as the cache budgets count them: with `cache_visibility`
    /// (in `SceneInfo::precomputed`'s parameters) each cache's visibility map counts as
    /// ⌈(n + 1)²/16⌉ caches more.
    pub caches: Option<u64>,
    /// Current step while running (e.g. `clustering`), with progress.
    pub step: Option<String>,
    pub progress: Option<f32>,
    /// Time the precomputation (or loading from the cache store) took.
    pub seconds: Option<f64>,
    pub from_store: Option<bool>,
    pub error: Option<String>,
}

/// JSON body of `POST /v1/scenes` that builds a procedural scene instead of uploading one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ProceduralScene {
    /// `cornell`, or `street?blocks=N&detail=D&seed=S&materials=M&cars=C` (see the README).
    pub procedural: String,
    /// Display name; default: the spec.
    #[serde(default)]
    pub name: Option<String>,
}

/// Axis-aligned bounds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Bounds {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

/// The equirectangular HDR image uploaded with a scene (`render.environment.kind` `image`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct EnvironmentImageInfo {
    /// The uploaded file's name.
    pub name: String,
    /// The file's size in texels.
    pub width: u32,
    pub height: u32,
    /// The size it is kept and lit with (at most 1024×512: larger images are averaged down,
    /// keeping their power).
    pub kept_width: u32,
    pub kept_height: u32,
}

/// A node of a scene (`SceneInfo::nodes`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct NodeInfo {
    pub id: u32,
    /// As authored (may be empty or repeated).
    pub name: String,
    /// The parent's id; absent for a root.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parent: Option<u32>,
    /// Whether clients may pose it (everything under it moves with it): a procedural scene's
    /// movable parts; in a glTF file the nodes an animation's translation, rotation or scale
    /// targets or whose `extras` hold `"movable": true`, and the nodes under them that have a
    /// translation, rotation and scale (not a general matrix).
    pub movable: bool,
    /// World bounds of it and everything under it, at rest; absent without geometry.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounds: Option<Bounds>,
    /// Its own translation, rotation (quaternion x, y, z, w) and scale in its parent's space,
    /// at rest: what a pose's fields replace. Absent for a node given as a general matrix.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translation: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[f32; 4]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<[f32; 3]>,
    /// Its transform to world space at rest, a column-major 4×4 matrix (a viewer turns a drag
    /// in world space into a translation in the parent's space with the parent's). Zeros
    /// from a server older than it.
    #[serde(default)]
    pub world: [f32; 16],
}

/// A glTF animation of a scene (`SceneInfo::animations`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct AnimationInfo {
    /// As authored, else `animation N` (its index in the file).
    pub name: String,
    /// Seconds from 0 to its last key.
    pub duration: f32,
    /// The ids of the nodes it moves.
    pub nodes: Vec<u32>,
}

/// A scene as `GET /v1/scenes/{id}` shows it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SceneInfo {
    pub id: String,
    pub name: String,
    /// Where it came from: `procedural:…` or `upload`.
    pub source: String,
    pub triangles: u64,
    pub vertices: u64,
    pub materials: u64,
    pub textures: u64,
    pub bounds: Bounds,
    /// The file's `KHR_lights_punctual` lights.
    pub lights: Vec<Light>,
    /// The file's cameras.
    pub cameras: Vec<Camera>,
    /// What a render uses when it names no camera or lights: `default_lights` (the file's
    /// lights up to the server's `max_lights`, else one light standing in for its emissive
    /// surfaces, else a sun); `default_light` is the first of them.
    pub default_camera: Camera,
    pub default_light: Light,
    #[serde(default)]
    pub default_lights: Vec<Light>,
    /// Where the viewer keeps the camera while orbiting, panning and flying: a room's inside
    /// (and, for a room open on one side, the space in front of that side), whose walls
    /// are black from outside. Absent: anywhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_region: Option<Bounds>,
    /// The `.hdr`/`.exr` file uploaded with the scene, which `render.environment` of kind
    /// `image` lights it with. Absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub environment_image: Option<EnvironmentImageInfo>,
    /// The node hierarchy, parents before children: glTF nodes (ids are the file's node
    /// indices), or a procedural scene's parts (the Cornell box's boxes). Empty: the scene is
    /// one static whole.
    #[serde(default)]
    pub nodes: Vec<NodeInfo>,
    /// The glTF file's animations.
    #[serde(default)]
    pub animations: Vec<AnimationInfo>,
    /// Light caches: the default set first (the `light_caches` entries of `precomputed`).
    pub caches: Vec<CacheVariant>,
    /// Every precomputation of the scene (light caches, BVH) with its state, oldest first.
    #[serde(default)]
    pub precomputed: Vec<Precomputed>,
    /// Sessions using the scene (it cannot be deleted while any do).
    pub sessions: u64,
    pub load_ms: f64,
}
