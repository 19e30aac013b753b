//! Built-in scenes generated in code, so the renderer can run without any asset files.
//!
//! `build` takes the text after `procedural:` on the command line: a scene name, optionally
//! followed by `?key=value&key=value` parameters, e.g. `street?blocks=40&seed=7`.
//!
//! * `cornell` (alias `cornell-box`): a Cornell-box-like room, the default scene.
//! * `street`: a city grid whose triangle count scales from thousands to tens of millions, for
//!   stress tests. Parameters `blocks` (grid side), `seed`, `detail` (face subdivision),
//!   `materials` (`authored`, or `diffuse`: every surface Lambertian of its base colour, the
//!   light transport the RSM-based methods model, for measuring what the rest costs them) and
//!   `cars` (0 to 4 parked cars in view of the default camera, each a movable node; default 1).
//!
//! All geometry is Y up, in metres, with counter-clockwise winding seen from the side the
//! normal points to.

use super::nodes::{Node, Transform};
use super::{Aabb, Material, Scene, SceneError, Vertex};
use glam::{Mat4, Vec3};
use lightcast_protocol::{Camera, Light, LightKind};

/// Scene names accepted by [`build`], as listed in error messages.
const KNOWN_SCENES: &str = "cornell (alias cornell-box), street";
const STREET_PARAMETERS: &str = "blocks, seed, detail, materials, cars";

const BLOCKS_RANGE: (u64, u64) = (1, 2000);
const DETAIL_RANGE: (u64, u64) = (1, 64);
/// Parked cars: a row along one curb of the block beside the default camera, all in its view.
const CARS_RANGE: (u64, u64) = (0, 4);
/// Beyond this the vertex and index buffers alone pass several GiB.
pub const MAX_TRIANGLES: u64 = 50_000_000;

/// Why [`build`] or [`street`] refused a request.
#[derive(Debug, thiserror::Error)]
pub enum ProceduralError {
    #[error("unknown procedural scene \"{0}\"; known scenes: {KNOWN_SCENES}")]
    UnknownScene(String),
    #[error("scene \"{scene}\" has no parameter \"{parameter}\" (known parameters: {known})")]
    UnknownParameter {
        scene: &'static str,
        parameter: String,
        known: &'static str,
    },
    #[error("malformed parameter \"{0}\": expected key=value")]
    Malformed(String),
    #[error("parameter \"{0}\" is given more than once")]
    Duplicate(String),
    #[error("parameter \"{parameter}\": cannot parse \"{value}\" as a non-negative integer")]
    InvalidValue {
        parameter: &'static str,
        value: String,
    },
    #[error("parameter \"{parameter}\" is \"{value}\"; expected one of {expected}")]
    InvalidChoice {
        parameter: &'static str,
        value: String,
        expected: &'static str,
    },
    #[error("parameter \"{parameter}\" is {value}, outside the allowed range {min}..={max}")]
    OutOfRange {
        parameter: &'static str,
        value: u64,
        min: u64,
        max: u64,
    },
    #[error(
        "street with blocks={blocks} and detail={detail} would have {triangles} triangles; \
         at most {MAX_TRIANGLES} are allowed"
    )]
    TooLarge {
        blocks: u32,
        detail: u32,
        triangles: u64,
    },
    #[error("generated scene is invalid: {0}")]
    Scene(#[from] SceneError),
}

/// A parsed procedural scene name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Spec {
    Cornell,
    Street(StreetParams),
}

impl Spec {
    /// Parses `name` or `name?key=value&...`.
    pub fn parse(spec: &str) -> Result<Self, ProceduralError> {
        let (name, query) = spec.split_once('?').unwrap_or((spec, ""));
        let parameters = parse_query(query)?;
        match name {
            "cornell" | "cornell-box" => match parameters.first() {
                Some((key, _)) => Err(ProceduralError::UnknownParameter {
                    scene: "cornell",
                    parameter: (*key).to_owned(),
                    known: "none",
                }),
                None => Ok(Self::Cornell),
            },
            "street" => Ok(Self::Street(StreetParams::from_parameters(&parameters)?)),
            _ => Err(ProceduralError::UnknownScene(name.to_owned())),
        }
    }

    /// Triangles the scene will have, without building it (so callers can refuse large ones
    /// first).
    pub fn triangle_count(&self) -> u64 {
        match self {
            Self::Cornell => cornell_box().triangle_count() as u64,
            Self::Street(params) => params.counts().1,
        }
    }

    pub fn build(&self) -> Result<Scene, ProceduralError> {
        match self {
            Self::Cornell => Ok(cornell_box()),
            Self::Street(params) => street(params),
        }
    }
}

/// Builds the scene named by `spec` (`name` or `name?key=value&...`).
pub fn build(spec: &str) -> Result<Scene, ProceduralError> {
    Spec::parse(spec)?.build()
}

/// Splits `a=1&b=2` into pairs. Empty items are skipped so that `street?` and a trailing `&`
/// are harmless.
fn parse_query(query: &str) -> Result<Vec<(&str, &str)>, ProceduralError> {
    let mut pairs: Vec<(&str, &str)> = Vec::new();
    for item in query.split('&').filter(|item| !item.is_empty()) {
        let (key, value) = item
            .split_once('=')
            .ok_or_else(|| ProceduralError::Malformed(item.to_owned()))?;
        if pairs.iter().any(|(k, _)| *k == key) {
            return Err(ProceduralError::Duplicate(key.to_owned()));
        }
        pairs.push((key, value));
    }
    Ok(pairs)
}

fn parse_u64(parameter: &'static str, value: &str) -> Result<u64, ProceduralError> {
    value
        .parse::<u64>()
        .map_err(|_| ProceduralError::InvalidValue {
            parameter,
            value: value.to_owned(),
        })
}

fn check_range(
    parameter: &'static str,
    value: u64,
    range: (u64, u64),
) -> Result<(), ProceduralError> {
    let (min, max) = range;
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(ProceduralError::OutOfRange {
            parameter,
            value,
            min,
            max,
        })
    }
}

/// Parameters of [`street`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StreetParams {
    /// The grid has `blocks × blocks` city blocks.
    pub blocks: u32,
    /// Seed of the generator that picks building sizes, colours and signs.
    pub seed: u64,
    /// Every building face, sidewalk and street cell is split into `detail × detail` quads.
    pub detail: u32,
    pub materials: StreetMaterials,
    /// Cars parked along the curb in front of the default camera (at most 4), each a movable
    /// node named `car` (the first), `car 2`, ... under the static root `street`.
    pub cars: u32,
}

/// The street's surfaces: as designed (glass and steel facades, glossy signs) or all
/// Lambertian.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StreetMaterials {
    #[default]
    Authored,
    /// Every material Lambertian of its base colour (metallic 0, no specular lobe): the same
    /// geometry and sun with only the light transport that methods with diffuse VPLs/VALs
    /// and diffuse receivers model exactly.
    Diffuse,
}

impl StreetMaterials {
    const CHOICES: &'static str = "authored, diffuse";

    fn parse(value: &str) -> Result<Self, ProceduralError> {
        match value {
            "authored" => Ok(Self::Authored),
            "diffuse" => Ok(Self::Diffuse),
            _ => Err(ProceduralError::InvalidChoice {
                parameter: "materials",
                value: value.to_owned(),
                expected: Self::CHOICES,
            }),
        }
    }
}

impl Default for StreetParams {
    fn default() -> Self {
        Self {
            blocks: 8,
            seed: 1,
            detail: 1,
            materials: StreetMaterials::Authored,
            cars: 1,
        }
    }
}

impl StreetParams {
    fn from_parameters(parameters: &[(&str, &str)]) -> Result<Self, ProceduralError> {
        let mut params = Self::default();
        for &(key, value) in parameters {
            match key {
                "blocks" => {
                    let v = parse_u64("blocks", value)?;
                    check_range("blocks", v, BLOCKS_RANGE)?;
                    params.blocks = v as u32;
                }
                "detail" => {
                    let v = parse_u64("detail", value)?;
                    check_range("detail", v, DETAIL_RANGE)?;
                    params.detail = v as u32;
                }
                "seed" => params.seed = parse_u64("seed", value)?,
                "materials" => params.materials = StreetMaterials::parse(value)?,
                "cars" => {
                    let v = parse_u64("cars", value)?;
                    check_range("cars", v, CARS_RANGE)?;
                    params.cars = v as u32;
                }
                _ => {
                    return Err(ProceduralError::UnknownParameter {
                        scene: "street",
                        parameter: key.to_owned(),
                        known: STREET_PARAMETERS,
                    })
                }
            }
        }
        Ok(params)
    }

    /// Exact vertex and triangle counts of the street these parameters describe, computed
    /// without generating it (saturating, so absurd parameters still compare as too large).
    pub fn counts(&self) -> (u64, u64) {
        let d = u64::from(self.detail);
        let grid = (d + 1) * (d + 1);
        // Street cell and sidewalk top: one grid each; curbs: 4 strips of d × 1 quads.
        let slab_vertices = 2 * grid + 4 * 2 * (d + 1);
        let slab_triangles = 4 * d * d + 4 * 2 * d;
        // Buildings: roof and four walls, one grid each, plus one two-sided sign (2 quads).
        let building_vertices = 5 * grid + 8;
        let building_triangles = 10 * d * d + 4;
        let per_block_vertices = slab_vertices + BUILDINGS_PER_BLOCK * building_vertices;
        let per_block_triangles = slab_triangles + BUILDINGS_PER_BLOCK * building_triangles;
        let blocks = u64::from(self.blocks) * u64::from(self.blocks);
        // A car: six bottomless boxes of one quad a face (body, cabin, four wheels) and the
        // body's underside.
        let car_vertices = CAR_BOXES * 5 * 4 + 4;
        let car_triangles = CAR_BOXES * 5 * 2 + 2;
        let cars = u64::from(self.cars);
        (
            blocks
                .saturating_mul(per_block_vertices)
                .saturating_add(cars * car_vertices),
            blocks
                .saturating_mul(per_block_triangles)
                .saturating_add(cars * car_triangles),
        )
    }
}

/// Vertex and index lists under construction.
#[derive(Default)]
struct Mesh {
    vertices: Vec<Vertex>,
    indices: Vec<u32>,
}

impl Mesh {
    /// The vertices `add` appends: one movable part's.
    fn part(&mut self, add: impl FnOnce(&mut Self)) -> std::ops::Range<u32> {
        let start = self.vertices.len() as u32;
        add(self);
        start..self.vertices.len() as u32
    }

    fn with_capacity(vertices: usize, triangles: usize) -> Self {
        Self {
            vertices: Vec::with_capacity(vertices),
            indices: Vec::with_capacity(triangles * 3),
        }
    }

    /// Adds the parallelogram `center ± half_u ± half_v`, split into `nu × nv` quads, with its
    /// front side towards `facing` (only the sign of the projection matters, so callers need
    /// not work out the handedness of every face).
    fn quad(
        &mut self,
        center: Vec3,
        half_u: Vec3,
        half_v: Vec3,
        facing: Vec3,
        (nu, nv): (u32, u32),
        material: u32,
    ) {
        let (half_u, half_v, nu, nv) = if half_u.cross(half_v).dot(facing) < 0.0 {
            (half_v, half_u, nv, nu)
        } else {
            (half_u, half_v, nu, nv)
        };
        let normal = half_u.cross(half_v).normalize().to_array();
        let origin = center - half_u - half_v;
        // The caller's triangle budget (MAX_TRIANGLES) keeps vertex counts far below u32::MAX.
        let base = self.vertices.len() as u32;
        for j in 0..=nv {
            let t = j as f32 / nv as f32;
            for i in 0..=nu {
                let s = i as f32 / nu as f32;
                self.vertices.push(Vertex {
                    position: (origin + half_u * (2.0 * s) + half_v * (2.0 * t)).to_array(),
                    normal,
                    uv: [s, t],
                    material,
                });
            }
        }
        let row = nu + 1;
        for j in 0..nv {
            for i in 0..nu {
                let a = base + j * row + i;
                let (b, c, d) = (a + 1, a + row + 1, a + row);
                self.indices.extend_from_slice(&[a, b, c, a, c, d]);
            }
        }
    }

    /// A thin sign visible from both sides: two quads 2 cm apart, so that neither z-fights the
    /// other nor is lost to back-face culling.
    fn two_sided_quad(
        &mut self,
        center: Vec3,
        half_u: Vec3,
        half_v: Vec3,
        facing: Vec3,
        material: u32,
    ) {
        let offset = half_u.cross(half_v).normalize() * 0.01;
        let offset = if offset.dot(facing) < 0.0 {
            -offset
        } else {
            offset
        };
        self.quad(center + offset, half_u, half_v, facing, (1, 1), material);
        self.quad(center - offset, half_u, half_v, -facing, (1, 1), material);
    }

    /// A box standing on `base` (the centre of its bottom face) with horizontal half-axes
    /// `half_x` and `half_z`. It has no bottom, which would never be seen. The roof is split
    /// `n_horizontal²`, the sides `n_horizontal × n_vertical`.
    fn open_box(
        &mut self,
        base: Vec3,
        half_x: Vec3,
        half_z: Vec3,
        height: f32,
        (n_horizontal, n_vertical): (u32, u32),
        material: u32,
    ) {
        let half_up = Vec3::Y * (height * 0.5);
        self.quad(
            base + Vec3::Y * height,
            half_x,
            half_z,
            Vec3::Y,
            (n_horizontal, n_horizontal),
            material,
        );
        for (out, along) in [
            (half_x, half_z),
            (-half_x, half_z),
            (half_z, half_x),
            (-half_z, half_x),
        ] {
            self.quad(
                base + half_up + out,
                along,
                half_up,
                out,
                (n_horizontal, n_vertical),
                material,
            );
        }
    }

    fn into_scene(
        self,
        name: String,
        materials: Vec<Material>,
        lights: Vec<Light>,
        cameras: Vec<Camera>,
    ) -> Result<Scene, SceneError> {
        Scene::new(
            name,
            self.vertices,
            self.indices,
            materials,
            Vec::new(),
            lights,
            cameras,
        )
    }
}

fn material(name: &str, rgb: [f32; 3], metallic: f32, roughness: f32) -> Material {
    Material {
        name: name.to_owned(),
        base_color: [rgb[0], rgb[1], rgb[2], 1.0],
        metallic,
        roughness,
        ..Material::default()
    }
}

// ---------------------------------------------------------------------------------------------
// Cornell box
// ---------------------------------------------------------------------------------------------

/// Room size in metres (the classic box is 5.5 m; 2 m keeps the numbers round).
const ROOM: f32 = 2.0;
/// Wall subdivision: finer walls give per-vertex caches more samples across each wall.
const WALL_SPLIT: u32 = 8;
/// Target illuminance on the floor below the lamp.
const CORNELL_FLOOR_LUX: f32 = 15.0;
const CORNELL_LIGHT_COLOR: [f32; 3] = [1.0, 0.9, 0.75];

/// The default scene: a Cornell-box-like room, open towards +Z where the camera stands.
pub fn cornell_box() -> Scene {
    const WHITE: u32 = 0;
    const RED: u32 = 1;
    const GREEN: u32 = 2;
    const BLOCKS: u32 = 3;
    const LAMP: u32 = 4;
    let white = [0.73, 0.73, 0.73];
    let materials = vec![
        material("cornell-white", white, 0.0, 1.0),
        material("cornell-red", [0.63, 0.065, 0.05], 0.0, 1.0),
        material("cornell-green", [0.14, 0.45, 0.09], 0.0, 1.0),
        // Same colour as the walls, but its own material so the boxes can be told apart from
        // the room shell (which faces inwards) by material alone.
        material("cornell-blocks", white, 0.0, 1.0),
        Material {
            emissive: CORNELL_LIGHT_COLOR.map(|c| c * 10.0),
            ..material("cornell-lamp", [0.78, 0.78, 0.78], 0.0, 1.0)
        },
    ];

    let h = ROOM * 0.5;
    let split = (WALL_SPLIT, WALL_SPLIT);
    let (x, y, z) = (Vec3::X * h, Vec3::Y * h, Vec3::Z * h);
    let mut mesh = Mesh::default();
    mesh.quad(Vec3::ZERO, x, z, Vec3::Y, split, WHITE); // floor
    mesh.quad(Vec3::Y * ROOM, x, z, -Vec3::Y, split, WHITE); // ceiling
    mesh.quad(y - z, x, y, Vec3::Z, split, WHITE); // back wall
    mesh.quad(y - x, z, y, Vec3::X, split, RED); // left wall
    mesh.quad(y + x, z, y, -Vec3::X, split, GREEN); // right wall

    // The classic layout, scaled from 5.5 m: a short cube at the front right and a tall box at
    // the back left, each turned about 17° the opposite way.
    let yawed = |half: f32, yaw: f32| {
        let (sin, cos) = yaw.sin_cos();
        (
            Vec3::new(cos, 0.0, -sin) * half,
            Vec3::new(sin, 0.0, cos) * half,
        )
    };
    let (sx, sz) = yawed(0.3, -0.29);
    let short = Vec3::new(0.33, 0.0, 0.37);
    let short_vertices = mesh.part(|m| m.open_box(short, sx, sz, 0.6, (4, 4), BLOCKS));
    let (tx, tz) = yawed(0.3, 0.29);
    let tall = Vec3::new(-0.33, 0.0, -0.28);
    let tall_vertices = mesh.part(|m| m.open_box(tall, tx, tz, 1.2, (4, 8), BLOCKS));

    // Just under the ceiling so it does not z-fight with it; the classic lamp is 1.3 × 1.05 m.
    let lamp_y = ROOM - 0.005;
    mesh.quad(
        Vec3::new(0.0, lamp_y, 0.0),
        Vec3::X * 0.235,
        Vec3::Z * 0.19,
        -Vec3::Y,
        (1, 1),
        LAMP,
    );

    // The emissive quad is only seen, not sampled as a light; this spot stands in for it.
    let light_y = lamp_y - 0.015;
    let light = Light {
        kind: LightKind::Spot,
        position: [0.0, light_y, 0.0],
        direction: [0.0, -1.0, 0.0],
        color: CORNELL_LIGHT_COLOR,
        // Inverse-square law: E = I / d² straight below the lamp.
        intensity: CORNELL_FLOOR_LUX * light_y * light_y,
        inner_cone: 50f32.to_radians(),
        outer_cone: 75f32.to_radians(),
    };
    // A 40° vertical field of view frames the 2 m opening from 2.9 m in front of it, as the
    // classic camera does.
    let camera = Camera {
        position: [0.0, h, h + 2.9],
        target: [0.0, h, 0.0],
        fov_y_degrees: 40.0,
    };
    let mut scene = mesh
        .into_scene("cornell".to_owned(), materials, vec![light], vec![camera])
        .expect("the built-in Cornell box is a valid scene");
    scene.lights_stand_in_for_emitters = true;
    // The boxes move (issue 35: a box moved through the room); the room holds them. Each box's
    // own frame stands on the floor at its centre.
    let room = Node {
        id: 0,
        name: "room".into(),
        parent: None,
        movable: false,
        local: Some(Transform::IDENTITY),
        rest_world: Mat4::IDENTITY,
        vertices: 0..scene.vertices.len() as u32,
    };
    let block = |id: u32, name: &str, base: Vec3, vertices| {
        let local = Transform {
            translation: base,
            ..Transform::IDENTITY
        };
        Node {
            id,
            name: name.into(),
            parent: Some(0),
            movable: true,
            local: Some(local),
            rest_world: local.matrix(),
            vertices,
        }
    };
    scene
        .set_nodes(
            vec![
                room,
                block(1, "short box", short, short_vertices),
                block(2, "tall box", tall, tall_vertices),
            ],
            Vec::new(),
        )
        .expect("the Cornell box's boxes are parts of it");
    // Inside the room, or in front of its open side (up to five times the default camera's
    // distance): from anywhere else some wall is seen from behind, black.
    scene.camera_region = Some(Aabb {
        min: Vec3::new(-h, 0.0, -h),
        max: Vec3::new(h, ROOM, h + 5.0 * 2.9),
    });
    scene
}

// ---------------------------------------------------------------------------------------------
// Street
// ---------------------------------------------------------------------------------------------

/// Side of the buildable area of one block.
const BLOCK: f32 = 40.0;
const SIDEWALK: f32 = 4.0;
const STREET: f32 = 12.0;
const PITCH: f32 = BLOCK + 2.0 * SIDEWALK + STREET;
const CURB: f32 = 0.15;
/// A 2 × 2 grid of lots, so that every building fronts two streets.
const LOTS_PER_SIDE: u32 = 2;
const BUILDINGS_PER_BLOCK: u64 = (LOTS_PER_SIDE * LOTS_PER_SIDE) as u64;

const ASPHALT: u32 = 0;
const PAVEMENT: u32 = 1;
/// Facade materials are `FACADES.start..FACADES.end`, sign materials follow.
const FACADES: std::ops::Range<u32> = 2..10;
const SIGNS: std::ops::Range<u32> = 10..16;
/// The cars' materials follow the signs', only in streets with cars (so that a street without
/// them is the street as it was before them, material for material).
const CAR_PAINT: u32 = 16;
const CAR_GLASS: u32 = 17;
const CAR_TYRE: u32 = 18;

/// A car's size: a compact saloon, 4.2 m long (along z), 1.8 m wide, 1.4 m tall.
const CAR_LENGTH: f32 = 4.2;
const CAR_WIDTH: f32 = 1.8;
const CAR_HEIGHT: f32 = 1.4;
/// Body, cabin and four wheels.
const CAR_BOXES: u64 = 6;
/// Centre to centre, cars stand this far apart along the curb (2.8 m between bumpers).
const CAR_SPACING: f32 = 7.0;

fn street_materials(kind: StreetMaterials, cars: bool) -> Vec<Material> {
    let mut materials = vec![
        material("asphalt", [0.06, 0.06, 0.065], 0.0, 0.9),
        material("sidewalk", [0.55, 0.55, 0.52], 0.0, 0.85),
        material("facade-concrete", [0.60, 0.56, 0.48], 0.0, 0.9),
        material("facade-brick", [0.45, 0.17, 0.11], 0.0, 0.85),
        material("facade-plaster", [0.78, 0.76, 0.70], 0.0, 0.8),
        material("facade-slate", [0.24, 0.26, 0.30], 0.0, 0.7),
        material("facade-teal", [0.10, 0.45, 0.45], 0.0, 0.75),
        material("facade-ochre", [0.75, 0.50, 0.12], 0.0, 0.8),
        material("facade-glass", [0.45, 0.55, 0.65], 0.9, 0.2),
        material("facade-steel", [0.78, 0.78, 0.80], 1.0, 0.35),
        material("sign-red", [0.85, 0.04, 0.04], 0.0, 0.5),
        material("sign-yellow", [0.90, 0.70, 0.04], 0.0, 0.4),
        material("sign-blue", [0.04, 0.18, 0.85], 0.0, 0.3),
        material("sign-green", [0.05, 0.60, 0.15], 0.0, 0.6),
        material("sign-magenta", [0.75, 0.04, 0.60], 0.0, 0.3),
        material("sign-gold", [0.95, 0.65, 0.25], 1.0, 0.25),
    ];
    debug_assert_eq!(materials.len() as u32, SIGNS.end);
    if cars {
        materials.extend([
            // Glossy red paint: a dielectric clear coat over the pigment.
            material("car-paint", [0.60, 0.04, 0.03], 0.0, 0.3),
            material("car-glass", [0.08, 0.09, 0.10], 0.0, 0.1),
            material("car-tyre", [0.03, 0.03, 0.03], 0.0, 0.9),
        ]);
        debug_assert_eq!(materials.len() as u32, CAR_TYRE + 1);
    }
    if kind == StreetMaterials::Diffuse {
        for m in &mut materials {
            m.metallic = 0.0;
            m.specular = 0.0;
        }
    }
    materials
}

/// splitmix64 (Steele, Lea & Flood 2014): tiny, fast and well mixed even for seeds 0, 1, 2...
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[lo, hi)`; the top 24 bits are exactly representable in an f32.
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        let unit = (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        lo + (hi - lo) * unit
    }

    /// Uniform in `range` (the modulo bias is far below anything visible).
    fn pick(&mut self, range: std::ops::Range<u32>) -> u32 {
        range.start + (self.next_u64() % u64::from(range.end - range.start)) as u32
    }

    fn chance(&mut self, p: f32) -> bool {
        self.range(0.0, 1.0) < p
    }
}

/// A `blocks × blocks` city grid centred at the origin: asphalt streets, raised sidewalks and
/// four buildings per block, each with a coloured awning or sign that tints the light it
/// bounces.
pub fn street(params: &StreetParams) -> Result<Scene, ProceduralError> {
    check_range("blocks", u64::from(params.blocks), BLOCKS_RANGE)?;
    check_range("detail", u64::from(params.detail), DETAIL_RANGE)?;
    check_range("cars", u64::from(params.cars), CARS_RANGE)?;
    let (vertex_count, triangle_count) = params.counts();
    if triangle_count > MAX_TRIANGLES {
        return Err(ProceduralError::TooLarge {
            blocks: params.blocks,
            detail: params.detail,
            triangles: triangle_count,
        });
    }

    let d = params.detail;
    let mut rng = SplitMix64(params.seed);
    let mut mesh = Mesh::with_capacity(vertex_count as usize, triangle_count as usize);
    let width = params.blocks as f32 * PITCH;
    let cell_center = |i: u32| -0.5 * width + (i as f32 + 0.5) * PITCH;
    let lot = BLOCK / LOTS_PER_SIDE as f32;

    for bz in 0..params.blocks {
        for bx in 0..params.blocks {
            let center = Vec3::new(cell_center(bx), 0.0, cell_center(bz));
            let half_cell = 0.5 * PITCH;
            mesh.quad(
                center,
                Vec3::X * half_cell,
                Vec3::Z * half_cell,
                Vec3::Y,
                (d, d),
                ASPHALT,
            );
            let half_slab = 0.5 * BLOCK + SIDEWALK;
            mesh.open_box(
                center,
                Vec3::X * half_slab,
                Vec3::Z * half_slab,
                CURB,
                (d, 1),
                PAVEMENT,
            );

            for lz in 0..LOTS_PER_SIDE {
                for lx in 0..LOTS_PER_SIDE {
                    // Each building fills part of its lot, pushed against the lot's street
                    // corner so that the street fronts stay continuous.
                    let size_x = lot * rng.range(0.55, 0.95);
                    let size_z = lot * rng.range(0.55, 0.95);
                    let lot_min = center - Vec3::new(0.5 * BLOCK, 0.0, 0.5 * BLOCK)
                        + Vec3::new(lx as f32 * lot, CURB, lz as f32 * lot);
                    let (min_x, out_x) = if lx == 0 {
                        (lot_min.x, -1.0)
                    } else {
                        (lot_min.x + lot - size_x, 1.0)
                    };
                    let (min_z, out_z) = if lz == 0 {
                        (lot_min.z, -1.0)
                    } else {
                        (lot_min.z + lot - size_z, 1.0)
                    };
                    let base = Vec3::new(min_x + 0.5 * size_x, CURB, min_z + 0.5 * size_z);
                    let height = if rng.chance(0.12) {
                        rng.range(40.0, 120.0)
                    } else {
                        rng.range(8.0, 36.0)
                    };
                    let facade = rng.pick(FACADES);
                    let half_x = Vec3::X * (0.5 * size_x);
                    let half_z = Vec3::Z * (0.5 * size_z);
                    mesh.open_box(base, half_x, half_z, height, (d, d), facade);

                    // The sign hangs on one of the two street-facing walls.
                    let (out, along, half_width) = if rng.chance(0.5) {
                        (Vec3::X * out_x, Vec3::Z, 0.5 * size_z)
                    } else {
                        (Vec3::Z * out_z, Vec3::X, 0.5 * size_x)
                    };
                    let wall = base + out * out.dot(half_x + half_z).abs();
                    let sign = Sign {
                        wall,
                        out,
                        along,
                        half_width,
                        height,
                        material: rng.pick(SIGNS),
                    };
                    match rng.pick(0..3) {
                        0 => sign.awning(&mut mesh),
                        1 => sign.blade(&mut mesh, rng.range(-0.8, 0.8)),
                        _ => sign.billboard(&mut mesh),
                    }
                }
            }
        }
    }

    // Down the street nearest the middle, from just beyond the grid's edge at first-floor
    // height, so the view runs between facades towards the far end of the city.
    let street_x = -0.5 * width + (params.blocks / 2) as f32 * PITCH;
    // Parked along that street's +x curb (on the camera's right), front towards −z, 30 cm from
    // the curb, the first 25 m ahead of the camera; all stand beside the first block, short of
    // the cross street beyond it (54 m into the grid). With one block the street is the
    // grid's edge: its asphalt is the 6 m on the curb's side, which is where they park.
    let car_x = street_x + 0.5 * STREET - 0.3 - 0.5 * CAR_WIDTH;
    let car_bases: Vec<Vec3> = (0..params.cars)
        .map(|k| Vec3::new(car_x, 0.0, 0.5 * width - 20.0 - k as f32 * CAR_SPACING))
        .collect();
    let car_vertices: Vec<_> = car_bases
        .iter()
        .map(|&base| mesh.part(|m| car(m, base)))
        .collect();

    let camera = Camera {
        position: [street_x, 12.0, 0.5 * width + 5.0],
        target: [street_x, 4.0, -0.5 * width],
        fov_y_degrees: 60.0,
    };
    let sun = Light {
        kind: LightKind::Directional,
        position: [0.0; 3],
        direction: Vec3::new(-0.4, -0.8, -0.3).normalize().to_array(),
        color: [1.0, 0.95, 0.85],
        intensity: 3.0,
        inner_cone: 0.0,
        outer_cone: 0.0,
    };
    let diffuse = match params.materials {
        StreetMaterials::Authored => "",
        StreetMaterials::Diffuse => ", materials=diffuse",
    };
    let car_count = if params.cars == StreetParams::default().cars {
        String::new()
    } else {
        format!(", cars={}", params.cars)
    };
    let name = format!(
        "street (blocks={}, seed={}, detail={}{diffuse}{car_count})",
        params.blocks, params.seed, params.detail
    );
    let materials = street_materials(params.materials, params.cars > 0);
    let mut scene = mesh.into_scene(name, materials, vec![sun], vec![camera])?;
    if params.cars > 0 {
        // The cars move (issue 35); the street holds them. Each car's own frame stands on the
        // road under its centre.
        let street = Node {
            id: 0,
            name: "street".into(),
            parent: None,
            movable: false,
            local: Some(Transform::IDENTITY),
            rest_world: Mat4::IDENTITY,
            vertices: 0..scene.vertices.len() as u32,
        };
        let cars =
            car_bases
                .into_iter()
                .zip(car_vertices)
                .enumerate()
                .map(|(k, (base, vertices))| {
                    let local = Transform {
                        translation: base,
                        ..Transform::IDENTITY
                    };
                    Node {
                        id: k as u32 + 1,
                        name: if k == 0 {
                            "car".into()
                        } else {
                            format!("car {}", k + 1)
                        },
                        parent: Some(0),
                        movable: true,
                        local: Some(local),
                        rest_world: local.matrix(),
                        vertices,
                    }
                });
        scene.set_nodes(std::iter::once(street).chain(cars).collect(), Vec::new())?;
    }
    Ok(scene)
}

/// A parked car standing on the road at `base` (the point under its centre), front towards −z:
/// a body on four wheels and a cabin, each a box of one quad a face.
fn car(mesh: &mut Mesh, base: Vec3) {
    let (half_width, half_length) = (0.5 * CAR_WIDTH, 0.5 * CAR_LENGTH);
    // Wheels 64 cm tall and 22 cm wide, their outer faces 4 cm inside the body's sides so the
    // two do not z-fight; their upper part is hidden in the body.
    let (wheel_x, wheel_z) = (half_width - 0.04 - 0.11, 1.35);
    for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        mesh.open_box(
            base + Vec3::new(sx * wheel_x, 0.0, sz * wheel_z),
            Vec3::X * 0.11,
            Vec3::Z * 0.32,
            0.64,
            (1, 1),
            CAR_TYRE,
        );
    }
    // The body clears the road by 30 cm, so it is closed underneath: the road's bounced light
    // and low views reach its underside.
    let (clearance, body_height) = (0.3, 0.65);
    let body = base + Vec3::Y * clearance;
    let (half_x, half_z) = (Vec3::X * half_width, Vec3::Z * half_length);
    mesh.open_box(body, half_x, half_z, body_height, (1, 1), CAR_PAINT);
    mesh.quad(body, half_x, half_z, -Vec3::Y, (1, 1), CAR_PAINT);
    // The cabin (tinted windows all round and a glass roof), narrower than the body and set
    // back from its front.
    mesh.open_box(
        base + Vec3::new(0.0, clearance + body_height, 0.25),
        Vec3::X * (half_width - 0.08),
        Vec3::Z * 1.15,
        CAR_HEIGHT - clearance - body_height,
        (1, 1),
        CAR_GLASS,
    );
}

/// A coloured plane attached to the street-facing `wall` point (centre of a wall's base) of a
/// building: the wall faces `out`, runs along `along` for ±`half_width`.
struct Sign {
    wall: Vec3,
    out: Vec3,
    along: Vec3,
    half_width: f32,
    height: f32,
    material: u32,
}

impl Sign {
    /// A shop awning over the ground floor, sloping down away from the wall.
    fn awning(&self, mesh: &mut Mesh) {
        let depth = 1.8;
        let drop = 0.5;
        let center = self.wall + self.out * (0.5 * depth) + Vec3::Y * (3.4 - 0.5 * drop);
        let half_slope = (self.out * depth - Vec3::Y * drop) * 0.5;
        let half_along = self.along * (0.8 * self.half_width);
        mesh.two_sided_quad(center, half_along, half_slope, Vec3::Y, self.material);
    }

    /// A vertical blade sign sticking out of the wall at `offset` (−1..1) along it.
    fn blade(&self, mesh: &mut Mesh, offset: f32) {
        let reach = 1.5;
        let center = self.wall
            + self.along * (offset * self.half_width)
            + self.out * (0.2 + 0.5 * reach)
            + Vec3::Y * 6.0;
        mesh.two_sided_quad(
            center,
            self.out * (0.5 * reach),
            Vec3::Y * 2.0,
            self.along,
            self.material,
        );
    }

    /// A billboard standing on the roof just behind the street-facing edge.
    fn billboard(&self, mesh: &mut Mesh) {
        let half_height = 2.5;
        let center = self.wall - self.out * 1.0 + Vec3::Y * (self.height + 0.5 + half_height);
        mesh.two_sided_quad(
            center,
            self.along * (0.7 * self.half_width).min(8.0),
            Vec3::Y * half_height,
            self.out,
            self.material,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(spec: &str) -> String {
        match build(spec) {
            Ok(_) => panic!("{spec} should have been rejected"),
            Err(e) => e.to_string(),
        }
    }

    fn assert_normals_unit(scene: &Scene) {
        for v in &scene.vertices {
            let length = Vec3::from(v.normal).length();
            assert!((length - 1.0).abs() < 1e-4, "normal length {length}");
        }
    }

    /// Every triangle's winding (counter-clockwise seen from the front) matches the normals
    /// of its vertices.
    fn assert_winding_matches_normals(scene: &Scene) {
        for t in scene.indices.chunks_exact(3) {
            let [a, b, c] = [0, 1, 2].map(|k| scene.vertices[t[k] as usize]);
            let [pa, pb, pc] = [a, b, c].map(|v| Vec3::from(v.position));
            let geometric = (pb - pa).cross(pc - pa).normalize();
            for v in [a, b, c] {
                let agreement = geometric.dot(Vec3::from(v.normal));
                assert!(agreement > 0.999, "triangle {t:?}: agreement {agreement}");
            }
        }
    }

    fn material_index(scene: &Scene, rgb: [f32; 3]) -> u32 {
        let found = scene
            .materials
            .iter()
            .position(|m| m.base_color[..3] == rgb)
            .unwrap_or_else(|| panic!("no material with colour {rgb:?}"));
        found as u32
    }

    fn triangles_with(scene: &Scene, materials: std::ops::Range<u32>) -> usize {
        scene
            .material_ranges
            .iter()
            .filter(|r| materials.contains(&r.material))
            .map(|r| r.index_count as usize / 3)
            .sum()
    }

    #[test]
    fn rejects_bad_specs_naming_the_culprit() {
        let e = err("street?blocks=0");
        assert!(e.contains("blocks") && e.contains("1..=2000"), "{e}");
        let e = err("street?detail=65");
        assert!(e.contains("detail") && e.contains("1..=64"), "{e}");
        let e = err("street?blocks=99999999999999999999");
        assert!(e.contains("blocks"), "{e}");
        let e = err("street?foo=1");
        assert!(
            e.contains("\"foo\"") && e.contains("blocks, seed, detail"),
            "{e}"
        );
        let e = err("street?blocks=abc");
        assert!(e.contains("blocks") && e.contains("abc"), "{e}");
        let e = err("street?seed=-1");
        assert!(e.contains("seed") && e.contains("-1"), "{e}");
        let e = err("street?blocks");
        assert!(e.contains("key=value"), "{e}");
        let e = err("street?blocks=2&blocks=3");
        assert!(e.contains("more than once"), "{e}");
        let e = err("castle");
        assert!(
            e.contains("castle") && e.contains("cornell") && e.contains("street"),
            "{e}"
        );
        let e = err("cornell?blocks=2");
        assert!(e.contains("cornell") && e.contains("blocks"), "{e}");
        let e = err("street?cars=5");
        assert!(e.contains("cars") && e.contains("0..=4"), "{e}");
        let e = err("street?cars=one");
        assert!(e.contains("cars") && e.contains("\"one\""), "{e}");
        let e = err("street?cars=-1");
        assert!(e.contains("cars") && e.contains("-1"), "{e}");
        let e = err("street?foo=1");
        assert!(e.contains("cars"), "{e}");
        let e = err("street?materials=matte");
        assert!(
            e.contains("materials") && e.contains("\"matte\"") && e.contains("authored, diffuse"),
            "{e}"
        );
    }

    /// The diffuse street is the authored one with every surface Lambertian of its base
    /// colour: same geometry, light and camera.
    #[test]
    fn the_diffuse_street_differs_only_in_its_materials() {
        let authored = build("street?blocks=2&materials=authored").expect("street");
        let diffuse = build("street?blocks=2&materials=diffuse").expect("street");
        assert_eq!(authored.name, "street (blocks=2, seed=1, detail=1)");
        assert_eq!(
            diffuse.name,
            "street (blocks=2, seed=1, detail=1, materials=diffuse)"
        );
        assert_eq!(authored.vertices, diffuse.vertices);
        assert_eq!(authored.indices, diffuse.indices);
        assert_eq!(authored.lights, diffuse.lights);
        assert!(authored.materials.iter().any(|m| m.metallic > 0.5));
        for (a, d) in authored.materials.iter().zip(&diffuse.materials) {
            assert_eq!(a.base_color, d.base_color);
            assert_eq!((d.metallic, d.specular), (0.0, 0.0), "{}", d.name);
            let (n, l, v) = (Vec3::Y, Vec3::new(0.6, 0.8, 0.0), Vec3::new(-0.8, 0.6, 0.0));
            let lambert = Vec3::from_slice(&a.base_color[..3]) / std::f32::consts::PI;
            let f = d.brdf().eval(n, l, v);
            assert!((f - lambert).abs().max_element() < 1e-6, "{}: {f}", d.name);
        }
    }

    #[test]
    fn parses_names_aliases_and_parameters() {
        assert_eq!(build("cornell-box").expect("alias").name, "cornell");
        let scene = build("street?blocks=3&seed=7&detail=2&").expect("valid street spec");
        assert_eq!(scene.name, "street (blocks=3, seed=7, detail=2)");
        let default = build("street").expect("default street");
        let params = StreetParams::default();
        assert_eq!(default.triangle_count() as u64, params.counts().1);
    }

    #[test]
    fn cornell_boxes_are_movable_parts_standing_on_the_floor() {
        let scene = cornell_box();
        let names: Vec<_> = scene
            .nodes
            .iter()
            .map(|n| (n.name.as_str(), n.movable))
            .collect();
        assert_eq!(
            names,
            [("room", false), ("short box", true), ("tall box", true)]
        );
        for (id, height) in [(1, 0.6), (2, 1.2)] {
            let node = scene.node(id).expect("listed");
            let b = scene.node_bounds()[id as usize].expect("geometry");
            let base = node.local.expect("TRS").translation;
            assert!(
                b.min.y.abs() < 1e-6 && (b.max.y - height).abs() < 1e-5,
                "{b:?}"
            );
            let centre = (b.min + b.max) * 0.5;
            assert!((centre.x - base.x).abs() < 1e-5 && (centre.z - base.z).abs() < 1e-5);
            // Only the blocks' material: the node holds the box and nothing else.
            let range = node.vertices.start as usize..node.vertices.end as usize;
            assert!(scene.vertices[range].iter().all(|v| v.material == 3));
        }
    }

    #[test]
    fn cornell_box_is_a_two_metre_room_open_towards_the_camera() {
        let scene = cornell_box();
        let b = scene.bounds;
        assert!(b.min.abs_diff_eq(Vec3::new(-1.0, 0.0, -1.0), 1e-5), "{b:?}");
        assert!(b.max.abs_diff_eq(Vec3::new(1.0, 2.0, 1.0), 1e-5), "{b:?}");
        assert_normals_unit(&scene);
        assert_winding_matches_normals(&scene);

        let red = material_index(&scene, [0.63, 0.065, 0.05]);
        let green = material_index(&scene, [0.14, 0.45, 0.09]);
        let white = scene
            .materials
            .iter()
            .position(|m| m.name == "cornell-white")
            .expect("white walls") as u32;
        let center = Vec3::new(0.0, 1.0, 0.0);
        let (mut reds, mut greens) = (0, 0);
        for v in &scene.vertices {
            let p = Vec3::from(v.position);
            if v.material == red {
                assert!(p.x < 0.0, "red wall vertex at {p}");
                reds += 1;
            }
            if v.material == green {
                assert!(p.x > 0.0, "green wall vertex at {p}");
                greens += 1;
            }
            if [red, green, white].contains(&v.material) {
                let inwards = Vec3::from(v.normal).dot(center - p);
                assert!(inwards > 0.0, "shell normal at {p} faces out");
            }
        }
        assert!(reds > 0 && greens > 0);
        // Nothing closes the room on the +Z side.
        assert!(scene
            .vertices
            .iter()
            .all(|v| v.position[2] < 1.0 - 1e-5 || v.normal[2].abs() < 1e-5));

        let emissive: Vec<_> = scene.materials.iter().filter(|m| m.is_emissive()).collect();
        assert_eq!(emissive.len(), 1);
    }

    #[test]
    fn cornell_light_points_down_with_plausible_floor_illuminance() {
        let scene = cornell_box();
        assert_eq!(scene.lights.len(), 1);
        let light = &scene.lights[0];
        assert_eq!(light.kind, LightKind::Spot);
        let height = light.position[1];
        assert!(height > 1.8 && height < 2.0, "{height}");
        let direction = Vec3::from(light.direction).normalize();
        assert!(direction.abs_diff_eq(-Vec3::Y, 1e-6));
        assert!(0.0 < light.inner_cone && light.inner_cone < light.outer_cone);
        assert!(light.outer_cone < std::f32::consts::FRAC_PI_2);
        let floor_lux = light.intensity / (height * height);
        assert!((10.0..=20.0).contains(&floor_lux), "{floor_lux}");
    }

    #[test]
    fn cornell_camera_sees_the_whole_room() {
        let scene = cornell_box();
        assert_eq!(scene.cameras.len(), 1);
        let camera = &scene.cameras[0];
        let position = Vec3::from(camera.position);
        let forward = (Vec3::from(camera.target) - position).normalize();
        assert!(position.z > scene.bounds.max.z && forward.z < -0.99);
        let right = forward.cross(Vec3::Y).normalize();
        let up = right.cross(forward);
        let half_fov = (camera.fov_y_degrees * 0.5).to_radians();
        // Conservatively assumes a square image: wider ones only see more.
        for corner in scene.bounds.corners() {
            let d = corner - position;
            let depth = d.dot(forward);
            assert!(depth > 0.0);
            assert!((d.dot(up).abs() / depth).atan() <= half_fov, "{corner}");
            assert!((d.dot(right).abs() / depth).atan() <= half_fov, "{corner}");
        }
    }

    /// Whether the open boxes `a` and `b` overlap by more than `eps` along every axis
    /// (touching is not overlapping).
    fn overlap(a: &Aabb, b: &Aabb, eps: f32) -> bool {
        (a.min.cmplt(b.max - eps) & b.min.cmplt(a.max - eps)).all()
    }

    fn triangle_bounds(scene: &Scene, t: &[u32]) -> Aabb {
        let p = |k: usize| Vec3::from(scene.vertices[t[k] as usize].position);
        Aabb {
            min: p(0).min(p(1)).min(p(2)),
            max: p(0).max(p(1)).max(p(2)),
        }
    }

    /// Where the segment `from`→`to` crosses the triangle `t` strictly between its ends
    /// (Möller–Trumbore), as a fraction of the segment.
    fn crosses(scene: &Scene, t: &[u32], from: Vec3, to: Vec3) -> Option<f32> {
        let [a, b, c] = [0, 1, 2].map(|k| Vec3::from(scene.vertices[t[k] as usize].position));
        let d = to - from;
        let (e1, e2) = (b - a, c - a);
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-12 {
            return None;
        }
        let s = from - a;
        let u = s.dot(p) / det;
        let q = s.cross(e1);
        let v = d.dot(q) / det;
        let f = e2.dot(q) / det;
        (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && f > 1e-4 && f < 1.0 - 1e-4).then_some(f)
    }

    /// The street's cars, as (node, its subtree's bounds at rest).
    fn cars(scene: &Scene) -> Vec<(Node, Aabb)> {
        let bounds = scene.node_bounds();
        scene
            .nodes
            .iter()
            .zip(bounds)
            .filter(|(n, _)| n.movable)
            .map(|(n, b)| (n.clone(), b.expect("a car has geometry")))
            .collect()
    }

    #[test]
    fn street_cars_are_movable_parts_parked_on_the_road_in_view() {
        let scene = build("street").expect("default street");
        let names: Vec<_> = scene
            .nodes
            .iter()
            .map(|n| (n.id, n.name.as_str(), n.parent, n.movable))
            .collect();
        assert_eq!(
            names,
            [(0, "street", None, false), (1, "car", Some(0), true)]
        );
        assert_eq!(scene.nodes[0].vertices, 0..scene.vertices.len() as u32);
        let car_materials = CAR_PAINT..CAR_TYRE + 1;
        assert_eq!(
            &scene.materials[CAR_PAINT as usize].name, "car-paint",
            "the car has its own paint"
        );

        for (blocks, count) in [(8, 1), (1, 4), (2, 4), (3, 2), (8, 4)] {
            let scene = build(&format!("street?blocks={blocks}&cars={count}")).expect("street");
            let cars = cars(&scene);
            assert_eq!(cars.len(), count, "blocks={blocks}");
            let in_cars = |v: u32| cars.iter().any(|(n, _)| n.vertices.contains(&v));
            // Every car vertex is in a car node, and a car node holds nothing else.
            for (v, vertex) in scene.vertices.iter().enumerate() {
                assert_eq!(
                    car_materials.contains(&vertex.material),
                    in_cars(v as u32),
                    "vertex {v}"
                );
            }
            let camera = &scene.cameras[0];
            let eye = Vec3::from(camera.position);
            let forward = (Vec3::from(camera.target) - eye).normalize();
            let right = forward.cross(Vec3::Y).normalize();
            let up = right.cross(forward);
            let half_fov = (camera.fov_y_degrees * 0.5).to_radians();
            for (k, (node, b)) in cars.iter().enumerate() {
                let what = format!("blocks={blocks}, car {k}");
                let local = node.local.expect("TRS");
                assert_eq!(node.rest_world, local.matrix(), "{what}");
                let base = local.translation;
                // On the road (the asphalt is at y = 0), standing on its wheels, of the size
                // of a car, its frame under its centre.
                assert_eq!(base.y, 0.0, "{what}");
                assert!(b.min.y.abs() < 1e-6, "{what}: {b:?}");
                let size = b.max - b.min;
                let expected = Vec3::new(CAR_WIDTH, CAR_HEIGHT, CAR_LENGTH);
                // (Within f32 rounding of coordinates a few hundred metres from the origin.)
                assert!(size.abs_diff_eq(expected, 1e-4), "{what}: {size}");
                let centre = (b.min + b.max) * 0.5;
                assert!(
                    (centre.x - base.x).abs() < 1e-4 && (centre.z - base.z).abs() < 1e-4,
                    "{what}: {centre} against {base}"
                );
                assert!(
                    (b.min.cmpge(scene.bounds.min) & b.max.cmple(scene.bounds.max)).all(),
                    "{what}: {b:?} outside {:?}",
                    scene.bounds
                );
                // Nothing else (buildings, sidewalks and their curbs, signs, other cars)
                // reaches into it; the road only touches its wheels.
                for t in scene.indices.chunks_exact(3) {
                    if node.vertices.contains(&t[0]) {
                        continue;
                    }
                    let tb = triangle_bounds(&scene, t);
                    assert!(!overlap(&tb, b, 1e-4), "{what}: {b:?} meets {tb:?}");
                }
                // In the default camera's view (assuming a square image: wider ones see
                // more), and its roof and body seen past everything else.
                for corner in b.corners() {
                    let d = corner - eye;
                    let depth = d.dot(forward);
                    assert!(depth > 0.0, "{what}");
                    assert!(
                        (d.dot(up).abs() / depth).atan() <= half_fov,
                        "{what}: {corner}"
                    );
                    assert!(
                        (d.dot(right).abs() / depth).atan() <= half_fov,
                        "{what}: {corner}"
                    );
                }
                let roof = Vec3::new(centre.x, b.max.y, centre.z + 0.25);
                let shoulders = [-1.0, 1.0].map(|s| base + Vec3::new(s * 0.8, 0.95, -1.9));
                for target in std::iter::once(roof).chain(shoulders) {
                    let hidden = scene.indices.chunks_exact(3).find(|t| {
                        !node.vertices.contains(&t[0]) && crosses(&scene, t, eye, target).is_some()
                    });
                    assert!(hidden.is_none(), "{what}: {target} hidden by {hidden:?}");
                }
            }
        }
    }

    #[test]
    fn a_street_without_cars_is_the_street_before_them() {
        for (blocks, detail) in [(1, 1), (3, 2), (4, 1)] {
            let spec = format!("street?blocks={blocks}&detail={detail}");
            let without = build(&format!("{spec}&cars=0")).expect("street");
            let with = build(&spec).expect("street");
            assert_eq!(
                without.name,
                format!("street (blocks={blocks}, seed=1, detail={detail}, cars=0)")
            );
            assert!(without.nodes.is_empty());
            // The triangle count the street had before its cars: N² · (44·D² + 8·D + 16).
            let (n, d) = (blocks as usize, detail as usize);
            assert_eq!(without.triangle_count(), n * n * (44 * d * d + 8 * d + 16));
            assert_eq!(without.materials.len(), SIGNS.end as usize);
            // The same city, with the car after it.
            let (v, m) = (without.vertices.len(), without.materials.len());
            assert_eq!(without.vertices, with.vertices[..v]);
            assert_eq!(without.materials, with.materials[..m]);
            assert_eq!(without.bounds, with.bounds);
            assert_eq!(without.cameras, with.cameras);
            assert_eq!(without.lights, with.lights);
            assert_eq!(with.nodes[1].vertices, v as u32..with.vertices.len() as u32);
        }
    }

    #[test]
    fn street_counts_are_exact_and_scale_quadratically() {
        let small = StreetParams {
            blocks: 4,
            ..StreetParams::default()
        };
        let large = StreetParams {
            blocks: 8,
            ..StreetParams::default()
        };
        let small_scene = street(&small).expect("small street");
        let large_scene = street(&large).expect("large street");
        for (params, scene) in [(&small, &small_scene), (&large, &large_scene)] {
            let (vertices, triangles) = params.counts();
            assert_eq!(scene.vertices.len() as u64, vertices);
            assert_eq!(scene.triangle_count() as u64, triangles);
        }
        for cars in 0..=4 {
            let params = StreetParams {
                blocks: 2,
                detail: 3,
                cars,
                ..StreetParams::default()
            };
            let scene = street(&params).expect("street");
            let (vertices, triangles) = params.counts();
            assert_eq!(scene.vertices.len() as u64, vertices, "cars={cars}");
            assert_eq!(scene.triangle_count() as u64, triangles, "cars={cars}");
        }
        let ratio = large_scene.triangle_count() as f64 / small_scene.triangle_count() as f64;
        assert!((3.0..=5.0).contains(&ratio), "{ratio}");
        let (small_b, large_b) = (small_scene.bounds, large_scene.bounds);
        assert!(large_b.max.x - large_b.min.x > 1.9 * (small_b.max.x - small_b.min.x));
        assert!(large_b.max.z - large_b.min.z > 1.9 * (small_b.max.z - small_b.min.z));

        let detailed = |detail| {
            let params = StreetParams {
                blocks: 3,
                detail,
                ..StreetParams::default()
            };
            triangles_with(&street(&params).expect("street"), FACADES)
        };
        let (coarse, fine) = (detailed(2), detailed(4));
        assert_eq!(fine, 4 * coarse);
    }

    #[test]
    fn street_is_deterministic_per_seed() {
        let with_seed = |seed| {
            street(&StreetParams {
                blocks: 3,
                seed,
                ..StreetParams::default()
            })
            .expect("street")
        };
        let (a, b, c) = (with_seed(7), with_seed(7), with_seed(8));
        assert_eq!(a.vertices, b.vertices);
        assert_eq!(a.indices, b.indices);
        assert_ne!(a.vertices, c.vertices);
    }

    #[test]
    fn street_geometry_materials_light_and_camera_are_sane() {
        let scene = build("street?blocks=5&detail=2").expect("street");
        assert!(scene.materials.len() >= 5);
        assert!(scene.materials.iter().any(|m| m.metallic > 0.5));
        assert!(scene.materials.iter().all(|m| !m.is_emissive()));
        assert_normals_unit(&scene);
        assert_winding_matches_normals(&scene);
        // Every material is used: signs and facades are all drawn from the palette.
        assert_eq!(scene.material_ranges.len(), scene.materials.len());

        assert_eq!(scene.lights.len(), 1);
        let sun = &scene.lights[0];
        assert_eq!(sun.kind, LightKind::Directional);
        assert!(sun.intensity > 0.0 && sun.direction[1] < 0.0);

        assert_eq!(scene.cameras.len(), 1);
        let camera = &scene.cameras[0];
        let b = scene.bounds;
        assert!(camera.position[1] > 1.0 && camera.position[1] < 30.0);
        assert!(camera.position[0] > b.min.x && camera.position[0] < b.max.x);
        let forward = Vec3::from(camera.target) - Vec3::from(camera.position);
        assert!(forward.z < 0.0 && forward.normalize().y < 0.0);
    }

    #[test]
    fn absurd_streets_are_refused_before_generating() {
        for (blocks, detail) in [(2000, 64), (2000, 1), (300, 8)] {
            let params = StreetParams {
                blocks,
                detail,
                ..StreetParams::default()
            };
            match street(&params) {
                Err(ProceduralError::TooLarge { triangles, .. }) => {
                    assert!(triangles > MAX_TRIANGLES)
                }
                other => panic!("blocks={blocks} detail={detail}: {other:?}"),
            }
        }
        let e = err("street?blocks=2000&detail=64");
        assert!(e.contains("triangles"), "{e}");
        let out_of_range = street(&StreetParams {
            blocks: 0,
            ..StreetParams::default()
        });
        assert!(matches!(
            out_of_range,
            Err(ProceduralError::OutOfRange {
                parameter: "blocks",
                ..
            })
        ));
    }
}
