use super::*;
use serde_json::{json, Value};
use std::sync::atomic::{AtomicUsize, Ordering};

const CORNELL_BOX: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../tests/data/cornell-box/cornell-box.glb"
);

/// A directory under the system temp dir, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> Self {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let dir = std::env::temp_dir().join(format!(
            "lightcast-gltf-{}-{tag}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        fs::create_dir_all(&dir).expect("create temp dir");
        Self(dir)
    }

    fn write(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let path = self.0.join(name);
        fs::write(&path, bytes).expect("write fixture");
        path
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

/// A little-endian binary buffer with one buffer view and accessor per pushed array.
#[derive(Default)]
struct Bin {
    bytes: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Bin {
    fn push(&mut self, data: &[u8], mut accessor: Value) -> usize {
        while !self.bytes.len().is_multiple_of(4) {
            self.bytes.push(0);
        }
        self.views.push(json!({
            "buffer": 0,
            "byteOffset": self.bytes.len(),
            "byteLength": data.len(),
        }));
        self.bytes.extend_from_slice(data);
        accessor["bufferView"] = json!(self.views.len() - 1);
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    fn floats<const N: usize>(&mut self, data: &[[f32; N]], ty: &str) -> usize {
        let bytes: Vec<u8> = data
            .iter()
            .flatten()
            .flat_map(|f| f.to_le_bytes())
            .collect();
        self.push(
            &bytes,
            json!({"componentType": 5126, "type": ty, "count": data.len()}),
        )
    }

    fn vec3(&mut self, data: &[[f32; 3]]) -> usize {
        self.floats(data, "VEC3")
    }

    fn vec2(&mut self, data: &[[f32; 2]]) -> usize {
        self.floats(data, "VEC2")
    }

    fn indices(&mut self, data: &[u16]) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|i| i.to_le_bytes()).collect();
        self.push(
            &bytes,
            json!({"componentType": 5123, "type": "SCALAR", "count": data.len()}),
        )
    }

    /// The glTF document: `rest`'s top-level fields plus asset, buffer, views, accessors.
    fn document(&self, uri: Option<&str>, rest: Value) -> Value {
        let mut buffer = json!({"byteLength": self.bytes.len()});
        if let Some(uri) = uri {
            buffer["uri"] = json!(uri);
        }
        let mut doc = json!({
            "asset": {"version": "2.0"},
            "buffers": [buffer],
            "bufferViews": self.views,
            "accessors": self.accessors,
        });
        if let (Some(doc), Value::Object(rest)) = (doc.as_object_mut(), rest) {
            doc.extend(rest);
        }
        doc
    }
}

/// Counter-clockwise seen from +Y, so its geometric normal is +Y.
const QUAD: [[f32; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [0.0, 0.0, 1.0],
    [1.0, 0.0, 1.0],
    [1.0, 0.0, 0.0],
];
const QUAD_UV: [[f32; 2]; 4] = [[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]];
const QUAD_INDICES: [u16; 6] = [0, 1, 2, 0, 2, 3];

fn quad_primitive(bin: &mut Bin, with_normals: bool) -> Value {
    let mut attributes = json!({"POSITION": bin.vec3(&QUAD), "TEXCOORD_0": bin.vec2(&QUAD_UV)});
    if with_normals {
        attributes["NORMAL"] = json!(bin.vec3(&[[0.0, 1.0, 0.0]; 4]));
    }
    json!({"attributes": attributes, "indices": bin.indices(&QUAD_INDICES)})
}

/// Scene fields for one node holding one mesh named "quad" with the given primitives.
fn single_mesh(primitives: Value) -> Value {
    json!({
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"name": "quad", "primitives": primitives}],
    })
}

fn quad_document(uri: Option<&str>) -> (Value, Bin) {
    let mut bin = Bin::default();
    let primitive = quad_primitive(&mut bin, true);
    (bin.document(uri, single_mesh(json!([primitive]))), bin)
}

/// Writes `doc` as scene.gltf next to `bin` as data.bin and loads it.
fn load_document(doc: &Value, bin: &[u8]) -> Result<Scene, LoadError> {
    let dir = TempDir::new("doc");
    dir.write("data.bin", bin);
    let path = dir.write("scene.gltf", &serde_json::to_vec(doc).expect("serialise"));
    load_gltf(&path)
}

fn load_error(doc: &Value, bin: &[u8]) -> String {
    load_document(doc, bin)
        .expect_err("fixture must be refused")
        .to_string()
}

fn glb(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut json = serde_json::to_vec(doc).expect("serialise");
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut bin = bin.to_vec();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let mut b = [0u8; 3];
        b[..chunk.len()].copy_from_slice(chunk);
        let n = u32::from(b[0]) << 16 | u32::from(b[1]) << 8 | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(char::from(ALPHABET[(n >> (18 - 6 * i)) as usize & 63]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn png(width: u32, height: u32, pixels: &[u8]) -> Vec<u8> {
    let image = image::RgbaImage::from_raw(width, height, pixels.to_vec()).expect("pixels");
    let mut out = io::Cursor::new(Vec::new());
    image
        .write_to(&mut out, image::ImageFormat::Png)
        .expect("encode png");
    out.into_inner()
}

fn position(scene: &Scene, index: u32) -> Vec3 {
    Vec3::from(scene.vertices[index as usize].position)
}

fn geometric_normals(scene: &Scene) -> Vec<Vec3> {
    scene
        .indices
        .chunks_exact(3)
        .map(|t| {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| position(scene, i));
            (b - a).cross(c - a).normalize()
        })
        .collect()
}

fn assert_close(actual: Vec3, expected: Vec3) {
    assert!(
        actual.abs_diff_eq(expected, 1e-5),
        "{actual} is not {expected}"
    );
}

#[test]
fn loads_the_cornell_box() {
    let scene = load_gltf(Path::new(CORNELL_BOX)).expect("cornell box loads");
    assert_eq!(scene.name, "cornell-box");
    assert!(scene.triangle_count() > 500, "{}", scene.triangle_count());
    let size = scene.bounds.max - scene.bounds.min;
    assert!(
        size.cmpgt(Vec3::splat(1.5)).all() && size.cmplt(Vec3::splat(2.6)).all(),
        "size {size}"
    );
    assert!(
        scene.bounds.center().length() < 0.5,
        "centre {}",
        scene.bounds.center()
    );

    let find = |dominant: usize| {
        scene
            .materials
            .iter()
            .position(|m| {
                let c = m.base_color;
                (0..3).all(|i| i == dominant || c[dominant] > 2.0 * c[i] + 0.2)
            })
            .unwrap_or_else(|| panic!("no material dominated by channel {dominant}")) as u32
    };
    let xs_of = |material: u32| -> Vec<f32> {
        scene
            .vertices
            .iter()
            .filter(|v| v.material == material)
            .map(|v| v.position[0])
            .collect()
    };
    let red = xs_of(find(0));
    let green = xs_of(find(1));
    assert!(!red.is_empty() && red.iter().all(|&x| x < 0.0), "{red:?}");
    assert!(
        !green.is_empty() && green.iter().all(|&x| x > 0.0),
        "{green:?}"
    );
    assert!(scene.materials.iter().any(Material::is_emissive));
    assert!(scene
        .vertices
        .iter()
        .all(|v| (Vec3::from(v.normal).length() - 1.0).abs() < 1e-3));
}

#[test]
fn loads_an_external_bin_buffer() {
    let (doc, bin) = quad_document(Some("data.bin"));
    let scene = load_document(&doc, &bin.bytes).expect("loads");
    assert_eq!(scene.name, "scene");
    assert_eq!(scene.vertices.len(), 4);
    assert_eq!(scene.triangle_count(), 2);
    assert_eq!(scene.materials, vec![Material::default()]);
    for (v, (p, uv)) in scene.vertices.iter().zip(QUAD.iter().zip(QUAD_UV)) {
        assert_eq!(v.position, *p);
        assert_eq!(v.uv, uv);
        assert_eq!(v.normal, [0.0, 1.0, 0.0]);
        assert_eq!(v.material, 0);
    }
    for n in geometric_normals(&scene) {
        assert_close(n, Vec3::Y);
    }
    // Parts not referenced by the scene's nodes are not needed.
    assert!(scene.lights.is_empty() && scene.cameras.is_empty());
}

#[test]
fn loads_an_embedded_base64_buffer_from_memory() {
    let (_, bin) = quad_document(None);
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64(&bin.bytes)
    );
    let (doc, _) = quad_document(Some(&uri));
    let bytes = serde_json::to_vec(&doc).expect("serialise");
    let scene = load_gltf_slice(&bytes, None, "embedded", LoadLimits::NONE)
        .expect("loads without base dir");
    let (external, bin) = quad_document(Some("data.bin"));
    let reference = load_document(&external, &bin.bytes).expect("loads");
    assert_eq!(scene.name, "embedded");
    assert_eq!(scene.vertices, reference.vertices);
    assert_eq!(scene.indices, reference.indices);
}

#[test]
fn loads_a_hand_assembled_glb() {
    let (doc, bin) = quad_document(None);
    let bytes = glb(&doc, &bin.bytes);
    let dir = TempDir::new("glb");
    let scene = load_gltf(&dir.write("box.glb", &bytes)).expect("loads");
    let (external, bin) = quad_document(Some("data.bin"));
    let reference = load_document(&external, &bin.bytes).expect("loads");
    assert_eq!(scene.name, "box");
    assert_eq!(scene.vertices, reference.vertices);
    assert_eq!(scene.indices, reference.indices);
    let from_memory =
        load_gltf_slice(&bytes, None, "mem", LoadLimits::NONE).expect("glb needs no base dir");
    assert_eq!(from_memory.vertices, reference.vertices);
}

#[test]
fn generates_normals_for_indexed_and_non_indexed_triangles() {
    let mut bin = Bin::default();
    let position = bin.vec3(&QUAD);
    let indices = bin.indices(&QUAD_INDICES);
    let indexed = json!({"attributes": {"POSITION": position}, "indices": indices});
    let soup: Vec<[f32; 3]> = QUAD_INDICES.iter().map(|&i| QUAD[i as usize]).collect();
    let soup = bin.vec3(&soup);
    let non_indexed = json!({"attributes": {"POSITION": soup}});
    let doc = bin.document(Some("data.bin"), single_mesh(json!([indexed, non_indexed])));
    let scene = load_document(&doc, &bin.bytes).expect("loads");
    assert_eq!(scene.vertices.len(), 4 + 6);
    assert_eq!(scene.triangle_count(), 4);
    for v in &scene.vertices {
        assert_close(Vec3::from(v.normal), Vec3::Y);
        assert_eq!(v.uv, [0.0, 0.0]);
    }
    for n in geometric_normals(&scene) {
        assert_close(n, Vec3::Y);
    }
}

#[test]
fn converts_strips_and_fans_with_consistent_winding() {
    let mut bin = Bin::default();
    let strip = bin.vec3(&[
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 0.0],
        [1.0, 0.0, 1.0],
    ]);
    let fan = bin.vec3(&QUAD);
    let doc = bin.document(
        Some("data.bin"),
        single_mesh(json!([
            {"attributes": {"POSITION": strip}, "mode": 5},
            {"attributes": {"POSITION": fan}, "mode": 6},
        ])),
    );
    let scene = load_document(&doc, &bin.bytes).expect("loads");
    assert_eq!(scene.triangle_count(), 4);
    for n in geometric_normals(&scene) {
        assert_close(n, Vec3::Y);
    }
}

#[test]
fn applies_the_node_hierarchy_and_loads_all_roots_without_scenes() {
    let mut bin = Bin::default();
    let primitive = quad_primitive(&mut bin, true);
    let doc = bin.document(
        Some("data.bin"),
        json!({
            "nodes": [
                // Column-major: uniform scale 2, then translate by (10, 0, 0).
                {"children": [1], "matrix": [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 10, 0, 0, 1]},
                {"mesh": 0, "translation": [0, 1, 0]},
            ],
            "meshes": [{"primitives": [primitive]}],
        }),
    );
    let scene = load_document(&doc, &bin.bytes).expect("loads");
    assert_eq!(scene.vertices.len(), 4, "the child is visited once");
    assert_close(scene.bounds.min, Vec3::new(10.0, 2.0, 0.0));
    assert_close(scene.bounds.max, Vec3::new(12.0, 2.0, 2.0));
    for v in &scene.vertices {
        assert_close(Vec3::from(v.normal), Vec3::Y);
    }
}

#[test]
fn negative_scale_flips_winding_to_keep_front_faces() {
    let mut bin = Bin::default();
    let primitive = quad_primitive(&mut bin, true);
    let mut fields = single_mesh(json!([primitive]));
    fields["nodes"][0]["scale"] = json!([-1, 1, 1]);
    let doc = bin.document(Some("data.bin"), fields);
    let scene = load_document(&doc, &bin.bytes).expect("loads");
    assert_close(scene.bounds.min, Vec3::new(-1.0, 0.0, 0.0));
    for v in &scene.vertices {
        assert_close(Vec3::from(v.normal), Vec3::Y);
    }
    for n in geometric_normals(&scene) {
        assert_close(n, Vec3::Y);
    }
}

#[test]
fn loads_materials_and_shares_textures_per_image() {
    let pixels: Vec<u8> = [
        [255, 0, 0, 255],
        [0, 255, 0, 255],
        [0, 0, 255, 255],
        [255, 255, 255, 128],
    ]
    .concat();
    let mut bin = Bin::default();
    let primitives: Vec<Value> = (0..4)
        .map(|material| {
            let mut p = quad_primitive(&mut bin, true);
            p["material"] = json!(material);
            p
        })
        .collect();
    let mut fields = single_mesh(json!(primitives));
    fields["extensionsUsed"] = json!(["KHR_materials_emissive_strength", "EXT_unknown"]);
    fields["images"] = json!([{"uri": "tex%20ture.png"}, {"uri": "unused-missing.png"}]);
    fields["textures"] = json!([{"source": 0}, {"source": 0}, {"source": 1}]);
    fields["materials"] = json!([
        {
            "name": "masked",
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.5, 0.5, 0.5, 1],
                "baseColorTexture": {"index": 0},
                "metallicFactor": 0.25,
                "roughnessFactor": 0.75,
            },
            "alphaMode": "MASK",
            "alphaCutoff": 0.3,
            "emissiveFactor": [1, 0.5, 0],
            "extensions": {
                "KHR_materials_emissive_strength": {"emissiveStrength": 4},
                "KHR_materials_specular": {"specularFactor": 0.25},
            },
        },
        {"name": "shared", "pbrMetallicRoughness": {"baseColorTexture": {"index": 1}}},
        {
            "name": "second-uv-set",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 2, "texCoord": 1}},
            "alphaMode": "BLEND",
        },
        {"name": "mask-default", "alphaMode": "MASK"},
    ]);
    let doc = bin.document(Some("data.bin"), fields);
    let dir = TempDir::new("texture");
    dir.write("tex ture.png", &png(2, 2, &pixels));
    dir.write("data.bin", &bin.bytes);
    let path = dir.write("scene.gltf", &serde_json::to_vec(&doc).expect("serialise"));
    let scene = load_gltf(&path).expect("loads");

    assert_eq!(scene.textures.len(), 1, "one texture per image");
    let texture = &scene.textures[0];
    assert_eq!((texture.width, texture.height), (2, 2));
    assert_eq!(texture.rgba8, pixels);
    assert_eq!(texture.name, "tex%20ture.png");

    let material = |name: &str| {
        scene
            .materials
            .iter()
            .find(|m| m.name == name)
            .unwrap_or_else(|| panic!("material {name}"))
    };
    let masked = material("masked");
    assert_eq!(masked.base_color, [0.5, 0.5, 0.5, 1.0]);
    assert_eq!((masked.metallic, masked.roughness), (0.25, 0.75));
    assert_eq!(masked.specular, 0.25);
    assert_eq!(
        material("shared").specular,
        1.0,
        "glTF's default without the extension"
    );
    assert_eq!(masked.emissive, [4.0, 2.0, 0.0]);
    assert_eq!(masked.alpha_cutoff, Some(0.3));
    assert_eq!(masked.base_color_texture, Some(0));
    assert_eq!(material("shared").base_color_texture, Some(0));
    assert_eq!(material("shared").base_color, [1.0; 4]);
    let ignored = material("second-uv-set");
    assert_eq!(ignored.base_color_texture, None);
    assert_eq!(ignored.alpha_cutoff, None);
    assert_eq!(material("mask-default").alpha_cutoff, Some(0.5));
    let mut used: Vec<u32> = scene.vertices.iter().map(|v| v.material).collect();
    used.dedup();
    assert_eq!(used.len(), 4);
}

#[test]
fn decodes_an_image_from_a_glb_buffer_view_without_mime_type() {
    let pixels = [10u8, 20, 30, 255];
    let mut bin = Bin::default();
    let mut primitive = quad_primitive(&mut bin, true);
    primitive["material"] = json!(0);
    let encoded = png(1, 1, &pixels);
    let view = bin.push(
        &encoded,
        json!({"componentType": 5121, "type": "SCALAR", "count": 0}),
    );
    let mut fields = single_mesh(json!([primitive]));
    fields["images"] = json!([{"bufferView": view}]);
    fields["textures"] = json!([{"source": 0}]);
    fields["materials"] = json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
    let doc = bin.document(None, fields);
    let scene =
        load_gltf_slice(&glb(&doc, &bin.bytes), None, "t", LoadLimits::NONE).expect("loads");
    assert_eq!(scene.textures.len(), 1);
    assert_eq!(scene.textures[0].rgba8, pixels);
}

#[test]
fn places_spot_and_point_lights_from_their_nodes() {
    let mut bin = Bin::default();
    let primitive = quad_primitive(&mut bin, true);
    let half = std::f32::consts::FRAC_1_SQRT_2;
    let doc = bin.document(
        Some("data.bin"),
        json!({
            "extensionsUsed": ["KHR_lights_punctual"],
            "extensionsRequired": ["KHR_lights_punctual"],
            "extensions": {"KHR_lights_punctual": {"lights": [
                {"type": "spot", "color": [1, 0.5, 0.25], "intensity": 40,
                 "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}},
                {"type": "point"},
                {"type": "directional", "name": "unattached"},
            ]}},
            "scene": 0,
            "scenes": [{"nodes": [0, 1]}],
            "nodes": [
                {"mesh": 0},
                {"translation": [0, 5, 0], "children": [2, 3]},
                // +90° about X turns the light's -Z axis to +Y.
                {"translation": [1, 0, 0], "rotation": [half, 0, 0, half],
                 "extensions": {"KHR_lights_punctual": {"light": 0}}},
                {"extensions": {"KHR_lights_punctual": {"light": 1}}},
            ],
            "meshes": [{"primitives": [primitive]}],
        }),
    );
    let scene = load_document(&doc, &bin.bytes).expect("loads");
    assert_eq!(scene.lights.len(), 2, "lights without a node are ignored");
    let spot = &scene.lights[0];
    assert_eq!(spot.kind, LightKind::Spot);
    assert_close(Vec3::from(spot.position), Vec3::new(1.0, 5.0, 0.0));
    assert_close(Vec3::from(spot.direction), Vec3::Y);
    assert_eq!(spot.color, [1.0, 0.5, 0.25]);
    assert_eq!(spot.intensity, 40.0);
    assert_eq!((spot.inner_cone, spot.outer_cone), (0.2, 0.5));
    let point = &scene.lights[1];
    assert_eq!(point.kind, LightKind::Point);
    assert_close(Vec3::from(point.position), Vec3::new(0.0, 5.0, 0.0));
    assert_eq!(point.color, [1.0; 3]);
    assert_eq!(point.intensity, 1.0);
    assert_eq!(
        (point.inner_cone, point.outer_cone),
        (0.0, std::f32::consts::FRAC_PI_4)
    );
    // Each light knows the node carrying it, so it can move with it.
    assert_eq!(scene.light_nodes, vec![Some(2), Some(3)]);
}

/// A file with five lights on five nodes: all five are the scene's lights and its default
/// lights, in node order (a frame renders them all unless the request names others).
#[test]
fn every_light_of_a_file_is_a_default_light() {
    let mut bin = Bin::default();
    let primitive = quad_primitive(&mut bin, true);
    let lights: Vec<Value> = (0..5)
        .map(|i| json!({"type": "point", "intensity": 1 + i}))
        .collect();
    let mut nodes = vec![json!({"mesh": 0})];
    nodes.extend((0..5).map(
        |i| json!({"translation": [i, 2, 0], "extensions": {"KHR_lights_punctual": {"light": i}}}),
    ));
    let doc = bin.document(
        Some("data.bin"),
        json!({
            "extensionsUsed": ["KHR_lights_punctual"],
            "extensions": {"KHR_lights_punctual": {"lights": lights}},
            "scene": 0,
            "scenes": [{"nodes": [0, 1, 2, 3, 4, 5]}],
            "nodes": nodes,
            "meshes": [{"primitives": [primitive]}],
        }),
    );
    let scene = load_document(&doc, &bin.bytes).expect("loads");
    let defaults = crate::default_light::default_lights(&scene, 16);
    assert_eq!(defaults, scene.lights);
    let intensities: Vec<f32> = defaults.iter().map(|l| l.intensity).collect();
    assert_eq!(intensities, [1.0, 2.0, 3.0, 4.0, 5.0]);
}

#[test]
fn refuses_lights_outside_their_ranges_and_clamps_extreme_fields_of_view() {
    let document = |light: Value, yfov: f64| {
        let mut bin = Bin::default();
        let primitive = quad_primitive(&mut bin, true);
        let doc = bin.document(
            Some("data.bin"),
            json!({
                "extensionsUsed": ["KHR_lights_punctual"],
                "extensions": {"KHR_lights_punctual": {"lights": [light]}},
                "cameras": [{"type": "perspective", "perspective": {"yfov": yfov, "znear": 0.1}}],
                "scene": 0,
                "scenes": [{"nodes": [0, 1, 2]}],
                "nodes": [
                    {"mesh": 0},
                    {"translation": [0, 5, 0], "extensions": {"KHR_lights_punctual": {"light": 0}}},
                    {"translation": [0, 1, 5], "camera": 0},
                ],
                "meshes": [{"primitives": [primitive]}],
            }),
        );
        (doc, bin)
    };
    for (light, expected) in [
        (
            json!({"type": "point", "color": [1, -0.5, 1]}),
            "must not be negative",
        ),
        (
            json!({"type": "point", "intensity": -3}),
            "must not be negative",
        ),
        (
            json!({"type": "spot", "spot": {"innerConeAngle": 0.6, "outerConeAngle": 0.5}}),
            "innerConeAngle ≤ outerConeAngle",
        ),
        (
            json!({"type": "spot", "spot": {"outerConeAngle": 2.0}}),
            "outerConeAngle ≤ π/2",
        ),
    ] {
        let (doc, bin) = document(light.clone(), 0.8);
        let err = load_error(&doc, &bin.bytes);
        assert!(
            err.starts_with("light 0") && err.contains(expected),
            "{light}: {err}"
        );
    }
    let (doc, bin) = document(json!({"type": "point"}), 0.001);
    let scene = load_document(&doc, &bin.bytes).expect("a tiny yfov is valid glTF");
    assert_eq!(scene.cameras[0].fov_y_degrees, 1.0);
}

#[test]
fn refuses_scenes_too_large_for_f32() {
    let mut bin = Bin::default();
    let far = [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [3e30, 0.0, 1.0]];
    let primitive = json!({"attributes": {"POSITION": bin.vec3(&far)}});
    let doc = bin.document(Some("data.bin"), single_mesh(json!([primitive])));
    let err = load_error(&doc, &bin.bytes);
    assert!(err.contains("scene spans 3e30 units"), "{err}");
}

#[test]
fn loads_perspective_cameras_and_skips_orthographic_ones() {
    let mut bin = Bin::default();
    let primitive = quad_primitive(&mut bin, true);
    let doc = bin.document(
        Some("data.bin"),
        json!({
            "scene": 0,
            "scenes": [{"nodes": [0, 1, 2]}],
            "nodes": [
                {"mesh": 0},
                {"camera": 0, "translation": [0, 1, 5]},
                {"camera": 1},
            ],
            "cameras": [
                {"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}},
                {"type": "orthographic",
                 "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.1, "zfar": 10}},
            ],
            "meshes": [{"primitives": [primitive]}],
        }),
    );
    let scene = load_document(&doc, &bin.bytes).expect("loads");
    assert_eq!(scene.cameras.len(), 1);
    let camera = &scene.cameras[0];
    assert_eq!(camera.position, [0.0, 1.0, 5.0]);
    assert_close(Vec3::from(camera.target), Vec3::new(0.0, 1.0, 4.0));
    assert!((camera.fov_y_degrees - 0.8f32.to_degrees()).abs() < 1e-4);
}

#[test]
fn refuses_truncated_glb_at_every_offset() {
    let (doc, bin) = quad_document(None);
    let bytes = glb(&doc, &bin.bytes);
    for cut in 0..bytes.len() {
        let truncated = &bytes[..cut];
        assert!(
            load_gltf_slice(truncated, None, "t", LoadLimits::NONE).is_err(),
            "cut at {cut}"
        );
        // Also with a header that agrees with the new length, to reach the chunk checks.
        if cut >= 12 {
            let mut patched = truncated.to_vec();
            patched[8..12].copy_from_slice(&(cut as u32).to_le_bytes());
            assert!(
                load_gltf_slice(&patched, None, "t", LoadLimits::NONE).is_err(),
                "patched cut at {cut}"
            );
        }
    }
    let message = |bytes: &[u8]| {
        load_gltf_slice(bytes, None, "t", LoadLimits::NONE)
            .expect_err("truncated")
            .to_string()
    };
    assert!(message(&bytes[..8]).contains("12-byte header"));
    assert!(message(&bytes[..100]).contains("truncated"));
    let json_end = 12 + 8 + u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let mut no_bin = bytes[..json_end].to_vec();
    no_bin[8..12].copy_from_slice(&(json_end as u32).to_le_bytes());
    let err = message(&no_bin);
    assert!(
        err.contains("buffer 0") && err.contains("binary chunk"),
        "{err}"
    );
    let mut short_chunk = bytes[..json_end + 20].to_vec();
    short_chunk[8..12].copy_from_slice(&((json_end + 20) as u32).to_le_bytes());
    let err = message(&short_chunk);
    assert!(
        err.contains("chunk 1") && err.contains("runs past the end"),
        "{err}"
    );
}

#[test]
fn refuses_random_bytes() {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state as u8
    };
    for length in (0..2000).step_by(37) {
        let mut bytes: Vec<u8> = (0..length).map(|_| next()).collect();
        assert!(load_gltf_slice(&bytes, None, "t", LoadLimits::NONE).is_err());
        for prefix in [&b"glTF\x02\0\0\0"[..], b"{", b"{\"asset\":"] {
            let n = prefix.len().min(bytes.len());
            bytes[..n].copy_from_slice(&prefix[..n]);
            assert!(load_gltf_slice(&bytes, None, "t", LoadLimits::NONE).is_err());
        }
    }
}

#[test]
fn refuses_wrong_json_types_and_other_versions() {
    let err = load_gltf_slice(
        br#"{"asset":{"version":"2.0"},"meshes":"nope"}"#,
        None,
        "t",
        LoadLimits::NONE,
    )
    .expect_err("wrong type")
    .to_string();
    assert!(err.starts_with("invalid glTF JSON"), "{err}");
    let err = load_gltf_slice(
        br#"{"asset":{"version":"1.0"},"meshes":{}}"#,
        None,
        "t",
        LoadLimits::NONE,
    )
    .expect_err("glTF 1")
    .to_string();
    assert!(
        err.contains("asset.version") && err.contains("1.0"),
        "{err}"
    );
    let err = load_gltf_slice(b"[1, 2]", None, "t", LoadLimits::NONE).expect_err("not an object");
    assert!(matches!(err, LoadError::Json(_)), "{err}");
}

#[test]
fn refuses_dangling_references_with_their_json_path() {
    let (mut doc, bin) = quad_document(Some("data.bin"));
    doc["meshes"][0]["primitives"][0]["indices"] = json!(99);
    let err = load_error(&doc, &bin.bytes);
    assert!(err.contains("meshes[0].primitives[0].indices"), "{err}");

    // gltf-json's own validation would panic on this one.
    let (mut doc, bin) = quad_document(Some("data.bin"));
    doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(99);
    let err = load_error(&doc, &bin.bytes);
    assert_eq!(
        err,
        "mesh 0 ('quad') primitive 0: POSITION accessor 99 does not exist"
    );
}

/// A GLB whose one primitive reuses a POSITION accessor (one real triangle) and a
/// zero-filled index accessor (`corners` indices), `primitives` times. glTF only allows an
/// accessor without a buffer view when it is sparse: the substitutions make the first 100
/// triangles (fewer when `corners` is smaller) the real one; the rest are [0, 0, 0], of zero
/// area.
fn reused_unbacked_accessors(corners: u64, primitives: usize) -> Vec<u8> {
    let mut bin = Bin::default();
    let positions = bin.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let real = (corners / 3).min(100) as u32;
    let targets: Vec<u32> = (0..real).flat_map(|t| [3 * t + 1, 3 * t + 2]).collect();
    let values: Vec<u32> = (0..real).flat_map(|_| [1, 2]).collect();
    let u32_view = |bin: &mut Bin, data: &[u32]| {
        let view = bin.views.len();
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        bin.push(&bytes, json!({}));
        bin.accessors.pop();
        view
    };
    let (targets, values) = (u32_view(&mut bin, &targets), u32_view(&mut bin, &values));
    bin.accessors.push(json!({
        "componentType": 5125, "type": "SCALAR", "count": corners,
        "sparse": {
            "count": 2 * real,
            "indices": {"bufferView": targets, "componentType": 5125},
            "values": {"bufferView": values},
        },
    }));
    let primitive = json!({"attributes": {"POSITION": positions}, "indices": 1});
    let doc = bin.document(None, single_mesh(json!(vec![primitive; primitives])));
    glb(&doc, &bin.bytes)
}

#[test]
fn refuses_reused_accessors_beyond_the_triangle_limit_before_building_them() {
    let limits = LoadLimits::upload(1_000);
    let small = reused_unbacked_accessors(300, 3);
    let scene = load_gltf_slice(&small, None, "t", limits).expect("300 triangles fit");
    assert_eq!(scene.triangle_count(), 300);

    // ~50 KB asking for 200 million triangles through one reused accessor: refused at the
    // primitive that would cross the limit, before its data is read.
    let bomb = reused_unbacked_accessors(600_000, 1_000);
    assert!(bomb.len() < 64 << 10);
    let err = load_gltf_slice(&bomb, None, "t", LoadLimits::upload(150_000))
        .expect_err("bomb")
        .to_string();
    assert!(
        err.contains("mesh 0 ('quad') primitive 0:") && err.contains("at most 150000 are allowed"),
        "{err}"
    );
    let err = load_gltf_slice(&small, None, "t", LoadLimits::upload(250))
        .expect_err("third primitive crosses")
        .to_string();
    assert!(
        err.contains("primitive 2:") && err.contains("300 triangles"),
        "{err}"
    );
    let nine_vertices_too_many = LoadLimits {
        max_vertices: 8,
        ..LoadLimits::NONE
    };
    let err = load_gltf_slice(&small, None, "t", nine_vertices_too_many)
        .expect_err("too many vertices")
        .to_string();
    assert!(
        err.contains("primitive 2:") && err.contains("9 vertices"),
        "{err}"
    );
}

#[test]
fn caps_zero_filled_elements_over_the_whole_file() {
    // One such accessor is allowed, but its reuse adds up.
    // Whole triangles, more than half the cap: twice them cross it.
    let corners = (MAX_UNBACKED_ELEMENTS / 2 / 3 + 1) * 3;
    let once = reused_unbacked_accessors(corners, 1);
    assert!(load_gltf_slice(&once, None, "t", LoadLimits::NONE).is_ok());
    let twice = reused_unbacked_accessors(corners, 2);
    let err = load_gltf_slice(&twice, None, "t", LoadLimits::NONE)
        .expect_err("second reuse crosses the cap")
        .to_string();
    assert!(
        err.contains("primitive 1") && err.contains("zero-filled"),
        "{err}"
    );
}

#[test]
fn caps_decoded_texture_memory_over_all_images() {
    // Three images that are the same 64×64 PNG (16 KiB each decoded): a cap of exactly
    // three admits them, one byte less refuses the third.
    let png = png(64, 64, &[128; 64 * 64 * 4]);
    let mut bin = Bin::default();
    let primitives: Vec<Value> = (0..3)
        .map(|material| {
            let mut p = quad_primitive(&mut bin, true);
            p["material"] = json!(material);
            p
        })
        .collect();
    let image_view = bin.views.len();
    bin.views
        .push(json!({"buffer": 0, "byteOffset": bin.bytes.len(), "byteLength": png.len()}));
    bin.bytes.extend_from_slice(&png);
    let mut fields = single_mesh(json!(primitives));
    fields["images"] = json!([
        {"bufferView": image_view, "mimeType": "image/png"},
        {"bufferView": image_view, "mimeType": "image/png"},
        {"bufferView": image_view, "mimeType": "image/png"},
    ]);
    fields["textures"] = json!([{"source": 0}, {"source": 1}, {"source": 2}]);
    fields["materials"] = json!(
        [0, 1, 2].map(|t| json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": t}}}))
    );
    let doc = glb(&bin.document(None, fields), &bin.bytes);
    let limits = |max_texture_bytes| LoadLimits {
        max_texture_bytes,
        ..LoadLimits::NONE
    };
    let scene = load_gltf_slice(&doc, None, "t", limits(3 * 64 * 64 * 4)).expect("fits");
    assert_eq!(scene.textures.len(), 3);
    let err = load_gltf_slice(&doc, None, "t", limits(3 * 64 * 64 * 4 - 1))
        .expect_err("third image crosses")
        .to_string();
    assert!(
        err.contains("texture 2 (image 2)") && err.contains("texture memory limit"),
        "{err}"
    );
}

/// A PNG of its signature, a header declaring `width`×`height` and an empty data chunk:
/// its dimensions can be read, but any attempt to decode its pixels fails.
fn png_header_only(width: u32, height: u32) -> Vec<u8> {
    let chunk = |kind: &[u8; 4], data: &[u8]| {
        let body = [&kind[..], data].concat();
        let crc = crc32(&body);
        [
            &(data.len() as u32).to_be_bytes()[..],
            &body,
            &crc.to_be_bytes(),
        ]
        .concat()
    };
    let header = [
        &width.to_be_bytes()[..],
        &height.to_be_bytes(),
        &[8, 6, 0, 0, 0],
    ]
    .concat();
    [
        &b"\x89PNG\r\n\x1a\n"[..],
        &chunk(b"IHDR", &header),
        &chunk(b"IDAT", &[]),
        &chunk(b"IEND", &[]),
    ]
    .concat()
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// A GLB of one textured quad whose base colour is `image` (PNG bytes).
fn textured_quad(image: &[u8]) -> Vec<u8> {
    let mut bin = Bin::default();
    let mut primitive = quad_primitive(&mut bin, true);
    primitive["material"] = json!(0);
    let view = bin.views.len();
    bin.views
        .push(json!({"buffer": 0, "byteOffset": bin.bytes.len(), "byteLength": image.len()}));
    bin.bytes.extend_from_slice(image);
    let mut fields = single_mesh(json!([primitive]));
    fields["images"] = json!([{"bufferView": view, "mimeType": "image/png"}]);
    fields["textures"] = json!([{"source": 0}]);
    fields["materials"] = json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
    glb(&bin.document(None, fields), &bin.bytes)
}

#[test]
fn refuses_textures_beyond_the_budget_from_their_declared_size_before_decoding() {
    // 8192² declared in a few bytes: kept at 2048² (16 MiB), more than 8 MiB allowed. The
    // error is the budget's, not a decode failure: no pixel was decoded.
    let file = textured_quad(&png_header_only(8192, 8192));
    assert!(file.len() < 2048);
    let limits = LoadLimits {
        max_texture_bytes: 8 << 20,
        max_texture_size: 2048,
        ..LoadLimits::NONE
    };
    match load_gltf_slice(&file, None, "t", limits) {
        Err(LoadError::TextureBudget {
            part,
            kept_width,
            kept_height,
            needed,
            available,
            ..
        }) => {
            assert_eq!(part, "texture 0 (image 0)");
            assert_eq!((kept_width, kept_height), (2048, 2048));
            assert_eq!((needed, available), (16 << 20, 8 << 20));
        }
        other => panic!("expected the texture budget's refusal, got {other:?}"),
    }
    // Within the budget the same file is decoded, and fails as a truncated image.
    let roomy = LoadLimits {
        max_texture_bytes: 16 << 20,
        ..limits
    };
    assert!(matches!(
        load_gltf_slice(&file, None, "t", roomy),
        Err(LoadError::ImageDecode { .. })
    ));
}

#[test]
fn downscales_textures_beyond_the_largest_kept_side() {
    // 64×32: left half red, right half blue; kept at 16×8 it keeps both halves.
    let pixels: Vec<u8> = (0..32)
        .flat_map(|_| {
            (0..64).flat_map(|x| {
                if x < 32 {
                    [255, 0, 0, 255]
                } else {
                    [0, 0, 255, 255]
                }
            })
        })
        .collect();
    let file = textured_quad(&png(64, 32, &pixels));
    let limits = LoadLimits {
        max_texture_size: 16,
        ..LoadLimits::NONE
    };
    let scene = load_gltf_slice(&file, None, "t", limits).expect("loads");
    let t = &scene.textures[0];
    assert_eq!((t.width, t.height), (16, 8));
    assert_eq!(t.rgba8.len(), 16 * 8 * 4);
    assert_eq!(&t.rgba8[4 * (16 + 1)..][..4], &[255, 0, 0, 255]);
    assert_eq!(&t.rgba8[4 * (16 + 14)..][..4], &[0, 0, 255, 255]);
    let full = load_gltf_slice(&file, None, "t", LoadLimits::NONE).expect("loads");
    assert_eq!((full.textures[0].width, full.textures[0].height), (64, 32));
    assert_eq!(kept_size(8192, 1, 2048), (2048, 1));
    assert_eq!(kept_size(100, 8192, 2048), (25, 2048));
}

#[test]
fn drops_zero_area_triangles_and_the_vertices_only_they_use() {
    // A few hundred bytes: 600,000 zero-filled positions (200,000 triangles) of which a
    // sparse substitution makes three a real triangle.
    let mut bin = Bin {
        bytes: [[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0]]
            .iter()
            .flatten()
            .flat_map(|f| f.to_le_bytes())
            .chain([1u32, 2].iter().flat_map(|i| i.to_le_bytes()))
            .collect(),
        ..Bin::default()
    };
    bin.views = vec![
        json!({"buffer": 0, "byteOffset": 0, "byteLength": 24}),
        json!({"buffer": 0, "byteOffset": 24, "byteLength": 8}),
    ];
    bin.accessors = vec![json!({
        "componentType": 5126, "type": "VEC3", "count": 600_000,
        "sparse": {
            "count": 2,
            "indices": {"bufferView": 1, "componentType": 5125},
            "values": {"bufferView": 0},
        },
    })];
    let doc = bin.document(None, single_mesh(json!([{"attributes": {"POSITION": 0}}])));
    let file = glb(&doc, &bin.bytes);
    assert!(file.len() < 1024);
    let scene = load_gltf_slice(&file, None, "t", LoadLimits::upload(1_000_000))
        .expect("one real triangle");
    assert_eq!(scene.triangle_count(), 1);
    assert_eq!(scene.vertices.len(), 3);
    let corners: Vec<[f32; 3]> = scene.vertices.iter().map(|v| v.position).collect();
    assert_eq!(corners, [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);

    // Nothing but zeros is no scene at all.
    let mut zeros = doc.clone();
    zeros["accessors"][0]["sparse"]["count"] = json!(1);
    let err = load_gltf_slice(&glb(&zeros, &bin.bytes), None, "t", LoadLimits::NONE)
        .expect_err("no area")
        .to_string();
    assert!(err.contains("no triangles"), "{err}");
}

#[test]
fn refuses_millions_of_zero_filled_positions_before_allocating_them() {
    let (mut doc, bin) = quad_document(None);
    doc["accessors"][0] = json!({
        "componentType": 5126, "type": "VEC3", "count": 3_000_000,
        "sparse": {
            "count": 1,
            "indices": {"bufferView": 2, "componentType": 5123},
            "values": {"bufferView": 0},
        },
    });
    let err = load_gltf_slice(&glb(&doc, &bin.bytes), None, "t", LoadLimits::NONE)
        .expect_err("3 million zero-filled positions")
        .to_string();
    assert!(
        err.contains("POSITION accessor 0: has no buffer view")
            && err.contains("at most 1048576 are allowed"),
        "{err}"
    );
}

#[test]
fn refuses_a_missing_bin_file() {
    let (doc, bin) = quad_document(Some("x.bin"));
    let err = load_error(&doc, &bin.bytes);
    assert!(err.starts_with("buffer 0: file 'x.bin' not found"), "{err}");
}

#[test]
fn refuses_external_files_when_loading_from_memory_without_base_dir() {
    let (doc, _) = quad_document(Some("data.bin"));
    let bytes = serde_json::to_vec(&doc).expect("serialise");
    let err = load_gltf_slice(&bytes, None, "t", LoadLimits::NONE)
        .expect_err("needs a base dir")
        .to_string();
    assert!(
        err.contains("buffer 0") && err.contains("base directory"),
        "{err}"
    );
}

#[test]
fn refuses_unsupported_required_extensions_only() {
    let (mut doc, bin) = quad_document(Some("data.bin"));
    doc["extensionsUsed"] = json!(["KHR_texture_transform", "KHR_draco_mesh_compression"]);
    load_document(&doc, &bin.bytes).expect("used-only extensions are ignored");
    doc["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    let err = load_error(&doc, &bin.bytes);
    assert_eq!(
        err,
        "required extension 'KHR_draco_mesh_compression' is not supported"
    );
}

#[test]
fn refuses_line_primitives() {
    let (mut doc, bin) = quad_document(Some("data.bin"));
    doc["meshes"][0]["primitives"][0]["mode"] = json!(1);
    let err = load_error(&doc, &bin.bytes);
    assert_eq!(
        err,
        "mesh 0 ('quad') primitive 0: mode Lines is not supported (only triangles)"
    );
}

#[test]
fn refuses_indices_out_of_vertex_range() {
    let mut bin = Bin::default();
    let position = bin.vec3(&QUAD);
    let indices = bin.indices(&[0, 1, 2, 0, 2, 7]);
    let primitive = json!({"attributes": {"POSITION": position}, "indices": indices});
    let doc = bin.document(Some("data.bin"), single_mesh(json!([primitive])));
    let err = load_error(&doc, &bin.bytes);
    assert!(
        err.starts_with(
            "mesh 0 ('quad') primitive 0: indices accessor 1: index 7 at position 5 is out \
             of range"
        ),
        "{err}"
    );
}

#[test]
fn refuses_accessors_and_views_past_the_end_of_their_data() {
    let (mut doc, bin) = quad_document(Some("data.bin"));
    doc["accessors"][0]["count"] = json!(1000);
    let err = load_error(&doc, &bin.bytes);
    assert!(
        err.starts_with("mesh 0 ('quad') primitive 0: POSITION accessor 0:")
            && err.contains("run past the end of buffer view 0"),
        "{err}"
    );

    let (mut doc, bin) = quad_document(Some("data.bin"));
    doc["bufferViews"][1]["byteLength"] = json!(100_000);
    let err = load_error(&doc, &bin.bytes);
    assert!(
        err.contains("TEXCOORD_0 accessor 1: buffer view 1: bytes")
            && err.contains("outside buffer 0"),
        "{err}"
    );

    let (mut doc, bin) = quad_document(Some("data.bin"));
    doc["buffers"][0]["byteLength"] = json!(bin.bytes.len() + 1);
    let err = load_error(&doc, &bin.bytes);
    assert!(err.starts_with("buffer 0: byteLength is"), "{err}");
}

#[test]
fn refuses_hostile_numbers_without_panicking() {
    let huge = json!(u64::MAX);
    let cases: [(&str, usize, &str, Value); 6] = [
        ("accessors", 0, "count", huge.clone()),
        ("accessors", 0, "byteOffset", json!(1u64 << 63)),
        ("bufferViews", 0, "byteOffset", huge.clone()),
        ("bufferViews", 0, "byteLength", huge.clone()),
        ("bufferViews", 0, "byteStride", json!(252)),
        ("buffers", 0, "byteLength", huge),
    ];
    for (array, index, field, value) in cases {
        let (mut doc, bin) = quad_document(Some("data.bin"));
        doc[array][index][field] = value;
        let result = load_document(&doc, &bin.bytes);
        assert!(result.is_err(), "{array}[{index}].{field}");
    }
    let (mut doc, bin) = quad_document(Some("data.bin"));
    doc["accessors"][0]
        .as_object_mut()
        .expect("object")
        .remove("bufferView");
    doc["accessors"][0]["count"] = json!(1u64 << 40);
    doc["accessors"][0]["sparse"] = json!({
        "count": 1,
        "indices": {"bufferView": 0, "componentType": 5125},
        "values": {"bufferView": 0},
    });
    let err = load_error(&doc, &bin.bytes);
    assert!(
        err.contains("POSITION accessor 0: has no buffer view")
            && err.contains(&format!("at most {MAX_UNBACKED_ELEMENTS} are allowed")),
        "{err}"
    );
}

#[test]
fn applies_sparse_substitutions() {
    let mut bin = Bin::default();
    let primitive = quad_primitive(&mut bin, true);
    let targets = bin.indices(&[2]);
    let values = bin.vec3(&[[5.0, 6.0, 7.0]]);
    let view = |accessor: usize| bin.accessors[accessor]["bufferView"].clone();
    let sparse = json!({
        "count": 1,
        "indices": {"bufferView": view(targets), "componentType": 5123},
        "values": {"bufferView": view(values)},
    });
    let mut doc = bin.document(Some("data.bin"), single_mesh(json!([primitive])));
    doc["accessors"][0]["sparse"] = sparse;
    let scene = load_document(&doc, &bin.bytes).expect("loads");
    let positions: Vec<[f32; 3]> = scene.vertices.iter().map(|v| v.position).collect();
    assert_eq!(positions, [QUAD[0], QUAD[1], [5.0, 6.0, 7.0], QUAD[3]]);
}

#[test]
fn refuses_cycles_and_non_finite_positions() {
    let (mut doc, bin) = quad_document(Some("data.bin"));
    doc["nodes"][0]["children"] = json!([0]);
    let err = load_error(&doc, &bin.bytes);
    assert!(err.starts_with("node 0: appears more than once"), "{err}");

    let mut bin = Bin::default();
    let position = bin.vec3(&[[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [1.0, 0.0, 0.0]]);
    let doc = bin.document(
        Some("data.bin"),
        single_mesh(json!([{"attributes": {"POSITION": position}}])),
    );
    let err = load_error(&doc, &bin.bytes);
    assert_eq!(err, "mesh 0 ('quad') primitive 0: POSITION 1 is not finite");
}

#[test]
fn refuses_corrupt_and_oversized_images() {
    for (image, expected) in [
        (
            b"\x89PNG\r\n\x1a\nnot really a png".to_vec(),
            "image decode failed",
        ),
        (
            png(
                MAX_TEXTURE_SIZE + 1,
                1,
                &[0; (MAX_TEXTURE_SIZE as usize + 1) * 4],
            ),
            "at most 8192",
        ),
    ] {
        let mut bin = Bin::default();
        let mut primitive = quad_primitive(&mut bin, true);
        primitive["material"] = json!(0);
        let mut fields = single_mesh(json!([primitive]));
        fields["images"] = json!([{"uri": format!("data:image/png;base64,{}", base64(&image))}]);
        fields["textures"] = json!([{"source": 0}]);
        fields["materials"] = json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
        let err = load_error(&bin.document(Some("data.bin"), fields), &bin.bytes);
        assert!(
            err.starts_with("texture 0 (image 0): ") && err.contains(expected),
            "{err}"
        );
    }
}

#[test]
fn decodes_uri_escapes() {
    assert_eq!(base64_decode("aGVsbG8=").as_deref(), Ok(&b"hello"[..]));
    assert_eq!(base64_decode("aGVs bG8").as_deref(), Ok(&b"hello"[..]));
    assert!(base64_decode("aGV*").is_err());
    assert!(base64_decode("aG=Vs").is_err());
    assert_eq!(percent_decode("a%20b%C3%A9").as_deref(), Ok("a bé"));
    assert!(percent_decode("a%2").is_err());
    assert!(percent_decode("%FF").is_err());
    assert!(has_scheme("http://x/y.bin") && has_scheme("file:x"));
    assert!(!has_scheme("dir/x.bin") && !has_scheme("C:\\x.bin"));
}

/// A root quad with two children (one with a grandchild), the first child's subtree animated
/// by translation and rotation, the second marked movable in its `extras`; `anim` is merged
/// into the animation (to break it).
fn animated_document(anim: Value) -> (Value, Bin) {
    let mut bin = Bin::default();
    let primitive = quad_primitive(&mut bin, true);
    let times = bin.floats(&[[0.0], [1.0], [2.5]], "SCALAR");
    let moves = bin.vec3(&[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
    let turns = bin.floats(&[[0.0, 0.0, 0.0, 1.0]; 3], "VEC4");
    let mut animation = json!({
        "name": "slide",
        "channels": [
            {"sampler": 0, "target": {"node": 1, "path": "translation"}},
            {"sampler": 1, "target": {"node": 1, "path": "rotation"}},
        ],
        "samplers": [
            {"input": times, "output": moves},
            {"input": times, "output": turns, "interpolation": "STEP"},
        ],
    });
    if let (Some(a), Value::Object(rest)) = (animation.as_object_mut(), anim) {
        a.extend(rest);
    }
    let doc = bin.document(
        Some("data.bin"),
        json!({
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [
                {"name": "ground", "mesh": 0, "children": [1, 3]},
                {"name": "cart", "mesh": 0, "translation": [0, 1, 0], "children": [2]},
                {"name": "wheel", "mesh": 0, "translation": [0, 0.5, 0]},
                {"name": "crate", "mesh": 0, "translation": [3, 0, 0], "extras": {"movable": true}},
            ],
            "meshes": [{"primitives": [primitive]}],
            "animations": [animation],
        }),
    );
    (doc, bin)
}

#[test]
fn keeps_the_node_hierarchy_with_each_subtrees_vertices_and_its_animations() {
    let (doc, bin) = animated_document(json!({}));
    let scene = load_document(&doc, &bin.bytes).expect("loads");
    let summary: Vec<_> = scene
        .nodes
        .iter()
        .map(|n| {
            (
                n.id,
                n.name.as_str(),
                n.parent,
                n.movable,
                n.vertices.clone(),
            )
        })
        .collect();
    assert_eq!(
        summary,
        [
            (0, "ground", None, false, 0..16),
            (1, "cart", Some(0), true, 4..12),
            (2, "wheel", Some(1), true, 8..12),
            (3, "crate", Some(0), true, 12..16),
        ]
    );
    let cart = scene.node(1).expect("listed");
    assert_eq!(
        cart.local.expect("TRS").translation,
        Vec3::new(0.0, 1.0, 0.0)
    );
    let wheel = scene.node_bounds()[2].expect("geometry");
    assert_close(wheel.min, Vec3::new(0.0, 1.5, 0.0));
    assert_close(wheel.max, Vec3::new(1.0, 1.5, 1.0));
    let [slide] = scene.animations.as_slice() else {
        panic!("one animation: {:?}", scene.animations)
    };
    assert_eq!((slide.name.as_str(), slide.duration()), ("slide", 2.5));
    assert_eq!(
        slide.channels[1].interpolation,
        crate::nodes::Interpolation::Step
    );
    assert_eq!(slide.channels[1].width(), 4);
}

#[test]
fn refuses_broken_animations_naming_the_channel() {
    let cases = [
        (
            json!({"samplers": [{"input": 4, "output": 5}, {"input": 4, "output": 5}]}),
            "animation 0 ('slide') channel 1: output accessor 5: type is Vec3, but output needs Vec4",
        ),
        (
            json!({"channels": [{"sampler": 5, "target": {"node": 1, "path": "scale"}}]}),
            "animations[0].channels[0].sampler: Index out of bounds",
        ),
    ];
    for (change, want) in cases {
        let (doc, bin) = animated_document(change);
        let error = load_error(&doc, &bin.bytes);
        assert!(error.contains(want), "{error}");
    }
    // Two translations for three keys.
    let (mut doc, bin) = animated_document(json!({}));
    doc["accessors"][5]["count"] = json!(2);
    let error = load_error(&doc, &bin.bytes);
    assert!(
        error.contains("channel 0: output holds 6 components for 3 keys (3 per key)"),
        "{error}"
    );
    // Keys out of order: the times (accessor 4, after the quad's four) 0, 3, 2.5.
    let (doc, mut bin) = animated_document(json!({}));
    assert_eq!(doc["samplers"], Value::Null);
    let offset = doc["bufferViews"][4]["byteOffset"]
        .as_u64()
        .expect("offset") as usize;
    bin.bytes[offset + 4..offset + 8].copy_from_slice(&3.0f32.to_le_bytes());
    let error = load_error(&doc, &bin.bytes);
    assert!(
        error.contains("input key 2 does not come after key 1"),
        "{error}"
    );
    // An animated node authored as a sheared matrix cannot move.
    let (mut doc, bin) = animated_document(json!({}));
    doc["nodes"][1] = json!({
        "mesh": 0,
        "matrix": [1, 0, 0, 0, 0.5, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1],
    });
    let error = load_error(&doc, &bin.bytes);
    assert!(
        error.contains("node 1") && error.contains("no translation, rotation and scale"),
        "{error}"
    );
}

/// Under an animated node any matrix moves with it: a sheared child loads (it is not posed
/// on its own), and a node authored with a negative scale keeps it on its own axis.
#[test]
fn children_of_moving_nodes_need_no_decomposable_matrix() {
    let (mut doc, bin) = animated_document(json!({}));
    doc["nodes"][2] = json!({
        "name": "wheel",
        "mesh": 0,
        "matrix": [1, 0, 0, 0, 0.5, 1, 0, 0, 0, 0, 1, 0, 0, 0.5, 0, 1],
    });
    doc["nodes"][3]["scale"] = json!([1.0, -1.0, 1.0]);
    let scene = load_document(&doc, &bin.bytes).expect("loads");
    let wheel = scene.node(2).expect("listed");
    assert!(!wheel.movable && wheel.local.is_none(), "{wheel:?}");
    let moves = crate::nodes::can_move(&scene.nodes);
    assert!(moves[2], "it moves with the cart");
    let crate_node = scene.node(3).expect("listed");
    assert_eq!(
        crate_node.local.expect("TRS").scale,
        Vec3::new(1.0, -1.0, 1.0)
    );
}
