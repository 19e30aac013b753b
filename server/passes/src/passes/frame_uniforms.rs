//! Uniforms every pass shares: the camera (`shaders/common.wgsl`) and the frame's lights with
//! their shadow projections (`shaders/lights.wgsl`).

use crate::scene::Aabb;
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3, Vec4};
use lightcast_protocol::{Camera, Light, LightKind};

/// Mirrors `CameraUniform` in `shaders/common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct CameraUniform {
    pub view_proj: [[f32; 4]; 4],
    pub position: [f32; 3],
    /// Roughness for every material, overriding theirs; 0 keeps the materials' own.
    pub roughness: f32,
    /// Clip to world: the ray through a pixel (the environment behind the geometry).
    pub inv_view_proj: [[f32; 4]; 4],
}

/// Mirrors `LightUniform` in `shaders/lights.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct LightUniform {
    pub face_view_proj: [[[f32; 4]; 4]; 6],
    pub position: [f32; 3],
    pub kind: u32,
    pub direction: [f32; 3],
    pub cos_inner: f32,
    pub radiance: [f32; 3],
    pub cos_outer: f32,
    pub shadow_texel: f32,
    pub normal_bias: f32,
    /// The light's first layer in the frame's shadow-map array.
    pub first_layer: u32,
    /// Its faces (layers): 6 for a point light, 2 for a directional light fitted to the view
    /// (near and far cascade), else 1.
    pub face_count: u32,
}

/// Most lights a frame lights with (`MAX_LIGHTS` in `shaders/lights.wgsl`), its punctual
/// lights and the directional lights a real-time method splits its environment into
/// together: the list is a fixed-size storage struct every lighting shader loops over.
pub const MAX_LIGHTS: usize = 16;

/// Mirrors `Lights` in `shaders/lights.wgsl`: the frame's lights, `count` of them used, the
/// first `punctual` the scene's punctual lights, the rest its environment's directions.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct LightsUniform {
    pub count: u32,
    pub punctual: u32,
    pub pad1: u32,
    pub pad2: u32,
    pub list: [LightUniform; MAX_LIGHTS],
}

/// What the faces of a directional light (its shadow map and RSM) cover. Spot and point
/// lights cover what their cones and cubes see either way.
#[derive(Clone, Copy, Debug)]
pub enum Coverage<'a> {
    /// The whole scene: one face, a square around its bounding sphere.
    Scene,
    /// What a camera of aspect ratio `aspect` sees of the scene, and a margin around it for
    /// the light that reaches it from just outside (see [`visible_region`]), in two cascades:
    /// a near face over what it sees up to [`NEAR_CASCADE`] of the way to the farthest
    /// surface it sees, and a far face over all it sees, whose RSM leaves out (and whose
    /// shadow lookups leave to the near face) what the near face covers. The same texels
    /// over far less ground where a city seen from its streets has most of it out of view,
    /// and the finest where the viewer is.
    View { camera: &'a Camera, aspect: f32 },
}

impl Coverage<'_> {
    /// Faces a light of `kind` renders from.
    pub fn faces(&self, kind: LightKind) -> u32 {
        match (kind, self) {
            (LightKind::Point, _) => 6,
            (LightKind::Directional, Self::View { .. }) => 2,
            _ => 1,
        }
    }
}

/// The near cascade of a view-fitted directional light reaches this fraction of the way from
/// the camera to the farthest surface it sees.
pub const NEAR_CASCADE: f32 = 0.25;

/// Margin around the visible region a directional light's fitted faces cover, as a fraction
/// of the region's side on each side: the surfaces just outside the view that light it.
const VIEW_MARGIN: f32 = 0.05;
/// A fitted face's side is the scene's (2 × radius) times a power of 2^(1/8) and its centre a
/// multiple of side / 16 in the light's plane: the face stays put while the camera moves a
/// little (no texel of its shadow map or RSM changes, so nor do the VPLs and VALs drawn from
/// them), then moves by whole texels of any map whose side is a multiple of 16, and changes
/// scale in steps. A finer step (side / 4096) slid the maps under the VPLs as the camera moved:
/// `clustered`'s indirect light changed 10.8 % of its mean between frames 13 cm apart on the
/// street, against 6.5 % with the whole scene's map.
const SIDE_STEPS_PER_OCTAVE: f32 = 8.0;
const SNAP_TEXELS: f32 = 16.0;

impl LightsUniform {
    /// Every light of `lights` (at most [`MAX_LIGHTS`]; callers check), all punctual, with
    /// its shadow faces fitted to the scene bounds, their layers following each other in
    /// light order.
    pub fn new(lights: &[Light], bounds: &Aabb, shadow_size: u32) -> Self {
        let faces = lights_faces(lights, bounds, Coverage::Scene);
        Self::with_punctual(lights, lights.len(), &faces, shadow_size)
    }

    /// [`Self::new`] where only the first `punctual` lights are punctual and the rest light
    /// for the environment (the direct-light pass counts their light as the environment's,
    /// with the indirect light).
    /// `faces` are every light's, as [`lights_faces`] lists them (the frame's RSM faces).
    pub fn with_punctual(
        lights: &[Light],
        punctual: usize,
        faces: &[(u32, LightFace)],
        shadow_size: u32,
    ) -> Self {
        debug_assert!(lights.len() <= MAX_LIGHTS, "{} lights", lights.len());
        let mut all = Self::zeroed();
        let mut first_layer = 0;
        for (i, (slot, light)) in all.list.iter_mut().zip(lights).enumerate() {
            let own: Vec<LightFace> = faces
                .iter()
                .filter(|(l, _)| *l as usize == i)
                .map(|(_, f)| *f)
                .collect();
            *slot = LightUniform::with_faces(light, &own, shadow_size);
            slot.first_layer = first_layer;
            first_layer += slot.face_count;
        }
        all.count = lights.len().min(MAX_LIGHTS) as u32;
        all.punctual = punctual.min(lights.len()).min(MAX_LIGHTS) as u32;
        all
    }

    /// The lights in use.
    pub fn used(&self) -> &[LightUniform] {
        &self.list[..self.count as usize]
    }

    /// The view-projection of every shadow-map layer, in layer order.
    pub fn layer_view_proj(&self) -> Vec<[[f32; 4]; 4]> {
        self.used()
            .iter()
            .flat_map(|l| l.face_view_proj[..l.face_count as usize].iter().copied())
            .collect()
    }
}

/// The index of face `at` of `faces` (as [`lights_faces`] lists them) among its own light's
/// faces: a directional light's cascade or a point light's cube face.
pub fn face_index(faces: &[(u32, LightFace)], at: usize) -> u32 {
    let light = faces[at].0;
    faces[..at]
        .iter()
        .rev()
        .take_while(|(l, _)| *l == light)
        .count() as u32
}

/// Shadow-map layers (and RSM faces) of all `lights` together.
pub fn face_count(lights: &[Light], coverage: Coverage) -> u32 {
    lights.iter().map(|l| coverage.faces(l.kind)).sum()
}

/// The faces of every light in light order, each with its light's index in the list.
pub fn lights_faces(lights: &[Light], bounds: &Aabb, coverage: Coverage) -> Vec<(u32, LightFace)> {
    lights
        .iter()
        .enumerate()
        .flat_map(|(i, l)| {
            light_faces(l, bounds, coverage)
                .into_iter()
                .map(move |f| (i as u32, f))
        })
        .collect()
}

/// Widest spot cone a single perspective shadow map covers; light outside it is unshadowed.
const MAX_SPOT_SHADOW_HALF_ANGLE: f32 = 80.0 * std::f32::consts::PI / 180.0;
/// Normal offset in shadow-map texels: the 3×3 PCF kernel reaches one texel out, plus one
/// for the bilinear comparison.
const NORMAL_BIAS_TEXELS: f32 = 2.0;

/// World-to-clip matrix of a camera, with near/far planes fitted to the scene bounds.
pub fn camera_view_proj(camera: &Camera, aspect: f32, bounds: &Aabb) -> Mat4 {
    let eye = Vec3::from(camera.position);
    let target = Vec3::from(camera.target);
    let forward = (target - eye).normalize_or(Vec3::NEG_Z);
    let up = stable_up(forward);
    let view = Mat4::look_to_rh(eye, forward, up);
    let (near, far) = depth_range(eye, bounds);
    Mat4::perspective_rh(camera.fov_y_degrees.to_radians(), aspect, near, far) * view
}

impl CameraUniform {
    /// `roughness` overrides every material's (`None`: their own).
    pub fn new(camera: &Camera, aspect: f32, bounds: &Aabb, roughness: Option<f32>) -> Self {
        let view_proj = camera_view_proj(camera, aspect, bounds);
        Self {
            view_proj: view_proj.to_cols_array_2d(),
            position: camera.position,
            roughness: roughness.unwrap_or(0.0),
            inv_view_proj: view_proj.inverse().to_cols_array_2d(),
        }
    }
}

/// An up vector that is never parallel to `forward`. Looking straight down, -Z is up on screen
/// so that +X stays to the right, as in a map of the scene seen from above.
fn stable_up(forward: Vec3) -> Vec3 {
    if forward.y.abs() > 0.999 {
        Vec3::new(0.0, 0.0, forward.y.signum())
    } else {
        Vec3::Y
    }
}

/// Near and far planes that enclose the whole scene as seen from `eye`.
fn depth_range(eye: Vec3, bounds: &Aabb) -> (f32, f32) {
    let far = bounds
        .corners()
        .iter()
        .map(|c| c.distance(eye))
        .fold(0.0f32, f32::max)
        .max(1e-3)
        * 1.01;
    (far * 1e-4, far)
}

/// One face of a light's projection (shadow map and RSM share them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightFace {
    pub view_proj: Mat4,
    /// Viewing axis of the face (unit).
    pub axis: Vec3,
    /// Side of the face's frustum at unit depth (perspective), or of the orthographic box.
    pub extent: f32,
    pub perspective: bool,
}

/// The faces a light renders from, fitted to the scene bounds: one orthographic face for a
/// directional light (over what `coverage` says), one perspective face for a spot light, six
/// cube faces for a point light.
pub fn light_faces(light: &Light, bounds: &Aabb, coverage: Coverage) -> Vec<LightFace> {
    let direction = Vec3::from(light.direction).normalize_or(Vec3::NEG_Y);
    let position = Vec3::from(light.position);
    match light.kind {
        LightKind::Directional => directional_faces(direction, bounds, coverage),
        LightKind::Spot => {
            let half = light.outer_cone.clamp(1e-3, MAX_SPOT_SHADOW_HALF_ANGLE);
            let (near, far) = depth_range(position, bounds);
            let view = Mat4::look_to_rh(position, direction, stable_up(direction));
            vec![LightFace {
                view_proj: Mat4::perspective_rh(2.0 * half, 1.0, near, far) * view,
                axis: direction,
                extent: 2.0 * half.tan(),
                perspective: true,
            }]
        }
        LightKind::Point => {
            let (near, far) = depth_range(position, bounds);
            let proj = Mat4::perspective_rh(std::f32::consts::FRAC_PI_2, 1.0, near, far);
            [
                Vec3::X,
                Vec3::NEG_X,
                Vec3::Y,
                Vec3::NEG_Y,
                Vec3::Z,
                Vec3::NEG_Z,
            ]
            .map(|axis| LightFace {
                view_proj: proj * Mat4::look_to_rh(position, axis, stable_up(axis)),
                axis,
                extent: 2.0,
                perspective: true,
            })
            .to_vec()
        }
    }
}

/// A directional light's orthographic faces: along the light their depth range holds the
/// whole scene (every caster and every surface it lights); across it a square over the
/// scene's bounding sphere, or the near and far cascades of [`Coverage::View`], each over its
/// region and a margin (never more than the sphere's).
fn directional_faces(direction: Vec3, bounds: &Aabb, coverage: Coverage) -> Vec<LightFace> {
    let radius = bounds.radius().max(1e-3);
    let center = bounds.center();
    let eye = center - direction * 2.0 * radius;
    let view = Mat4::look_to_rh(eye, direction, stable_up(direction));
    let face = |square: Option<(f32, f32, f32)>| {
        let (x, y, half) = square.unwrap_or((0.0, 0.0, radius));
        let proj =
            Mat4::orthographic_rh(x - half, x + half, y - half, y + half, radius, 3.0 * radius);
        LightFace {
            view_proj: proj * view,
            axis: direction,
            extent: 2.0 * half,
            perspective: false,
        }
    };
    match coverage {
        Coverage::Scene => vec![face(None)],
        Coverage::View { camera, aspect } => {
            let all = visible_region(camera, aspect, bounds, None);
            let forward = camera_forward(camera);
            let farthest = all
                .iter()
                .map(|p| (*p - Vec3::from(camera.position)).dot(forward))
                .fold(0.0f32, f32::max);
            let near = visible_region(camera, aspect, bounds, Some(NEAR_CASCADE * farthest));
            let far = fitted_square(&view, &all, radius);
            // A camera that sees nothing near it (outside the scene) keeps the far square for
            // both: the near face then holds every shadow and every sender.
            vec![face(fitted_square(&view, &near, radius).or(far)), face(far)]
        }
    }
}

/// The unit direction a camera looks in.
fn camera_forward(camera: &Camera) -> Vec3 {
    (Vec3::from(camera.target) - Vec3::from(camera.position)).normalize_or(Vec3::NEG_Z)
}

/// Centre (x, y in the light's view space) and half side of the snapped square that covers
/// `region`'s points (world space) plus [`VIEW_MARGIN`], at most `radius`; `None` when the
/// region is empty or the square would be the scene's anyway.
fn fitted_square(view: &Mat4, region: &[Vec3], radius: f32) -> Option<(f32, f32, f32)> {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in region {
        let q = view.transform_point3(*p);
        lo = lo.min(q);
        hi = hi.max(q);
    }
    if region.is_empty() {
        return None;
    }
    // The margin on both sides, and room for the centre's rounding to the snapping grid (half
    // a step either way).
    let side = (hi.x - lo.x).max(hi.y - lo.y) * (1.0 + 2.0 * VIEW_MARGIN + 2.0 / SNAP_TEXELS);
    let steps = ((2.0 * radius) / side.max(1e-6)).log2() * SIDE_STEPS_PER_OCTAVE;
    if steps < 1.0 {
        return None;
    }
    let half = radius * 2f32.powf(-steps.floor() / SIDE_STEPS_PER_OCTAVE);
    let snap = 2.0 * half / SNAP_TEXELS;
    let centre = |a: f32, b: f32| (0.5 * (a + b) / snap).round() * snap;
    Some((centre(lo.x, hi.x), centre(lo.y, hi.y), half))
}

/// The vertices of what `camera` (aspect `aspect`) sees of `bounds`: the intersection of its
/// view frustum (near and far planes as [`camera_view_proj`] puts them) with the box, a
/// convex polyhedron whose vertices lie on the box's faces clipped by the frustum and the
/// frustum's faces clipped by the box. Empty when the camera sees none of it. With `far`, the
/// frustum ends that far from the camera instead.
pub fn visible_region(camera: &Camera, aspect: f32, bounds: &Aabb, far: Option<f32>) -> Vec<Vec3> {
    let view_proj = match far {
        None => camera_view_proj(camera, aspect, bounds),
        Some(far) => {
            let eye = Vec3::from(camera.position);
            let forward = camera_forward(camera);
            let view = Mat4::look_to_rh(eye, forward, stable_up(forward));
            let far = far.max(1e-3);
            Mat4::perspective_rh(camera.fov_y_degrees.to_radians(), aspect, far * 1e-4, far) * view
        }
    };
    let inverse = view_proj.inverse();
    // Clip space z runs 0 (near) … 1 (far) in wgpu.
    let corner = |x: f32, y: f32, z: f32| inverse.project_point3(Vec3::new(x, y, z));
    let frustum: [Vec3; 8] = [
        corner(-1.0, -1.0, 0.0),
        corner(1.0, -1.0, 0.0),
        corner(1.0, 1.0, 0.0),
        corner(-1.0, 1.0, 0.0),
        corner(-1.0, -1.0, 1.0),
        corner(1.0, -1.0, 1.0),
        corner(1.0, 1.0, 1.0),
        corner(-1.0, 1.0, 1.0),
    ];
    let (r0, r1, r2, r3) = (
        view_proj.row(0),
        view_proj.row(1),
        view_proj.row(2),
        view_proj.row(3),
    );
    // Inside: plane · (p, 1) ≥ 0 (Gribb & Hartmann's planes for z in 0 … w).
    let frustum_planes = [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r2, r3 - r2];
    let (a, b) = (bounds.min, bounds.max);
    let box_planes = [
        Vec4::new(1.0, 0.0, 0.0, -a.x),
        Vec4::new(-1.0, 0.0, 0.0, b.x),
        Vec4::new(0.0, 1.0, 0.0, -a.y),
        Vec4::new(0.0, -1.0, 0.0, b.y),
        Vec4::new(0.0, 0.0, 1.0, -a.z),
        Vec4::new(0.0, 0.0, -1.0, b.z),
    ];
    // Faces as corner indices, for the box (`Aabb::corners` order) and the frustum alike.
    let faces_of = |c: &[Vec3; 8], quads: &[[usize; 4]; 6]| {
        quads
            .iter()
            .map(|q| q.map(|i| c[i]).to_vec())
            .collect::<Vec<_>>()
    };
    const FRUSTUM_QUADS: [[usize; 4]; 6] = [
        [0, 1, 2, 3],
        [4, 5, 6, 7],
        [0, 1, 5, 4],
        [3, 2, 6, 7],
        [0, 3, 7, 4],
        [1, 2, 6, 5],
    ];
    let mut points = Vec::new();
    let clipped = |polygon: Vec<Vec3>, planes: &[Vec4; 6]| {
        planes
            .iter()
            .fold(polygon, |poly, plane| clip_polygon(&poly, *plane))
    };
    for face in faces_of(&frustum, &FRUSTUM_QUADS) {
        points.extend(clipped(face, &box_planes));
    }
    for face in box_faces(bounds) {
        points.extend(clipped(face, &frustum_planes));
    }
    points
}

/// The six faces of `bounds` as quads.
fn box_faces(bounds: &Aabb) -> Vec<Vec<Vec3>> {
    let (a, b) = (bounds.min, bounds.max);
    let p = |x: bool, y: bool, z: bool| {
        Vec3::new(
            if x { b.x } else { a.x },
            if y { b.y } else { a.y },
            if z { b.z } else { a.z },
        )
    };
    (0..3)
        .flat_map(|axis| {
            [false, true].map(move |side| {
                // The other two axes' four combinations, in order around the quad.
                [(false, false), (true, false), (true, true), (false, true)]
                    .map(|(u, v)| match axis {
                        0 => p(side, u, v),
                        1 => p(u, side, v),
                        _ => p(u, v, side),
                    })
                    .to_vec()
            })
        })
        .collect()
}

/// Sutherland–Hodgman: the part of convex `polygon` where plane · (p, 1) ≥ 0.
fn clip_polygon(polygon: &[Vec3], plane: Vec4) -> Vec<Vec3> {
    let side = |p: Vec3| plane.dot(p.extend(1.0));
    let mut out = Vec::with_capacity(polygon.len() + 1);
    for (i, &p) in polygon.iter().enumerate() {
        let q = polygon[(i + 1) % polygon.len()];
        let (sp, sq) = (side(p), side(q));
        if sp >= 0.0 {
            out.push(p);
        }
        if (sp >= 0.0) != (sq >= 0.0) {
            out.push(p + (q - p) * (sp / (sp - sq)));
        }
    }
    out
}

impl LightUniform {
    /// The light's parameters and the view-projection of each shadow-map face, fitted to the
    /// scene bounds (a directional light's to what `coverage` says).
    pub fn new(light: &Light, bounds: &Aabb, coverage: Coverage, shadow_size: u32) -> Self {
        Self::with_faces(light, &light_faces(light, bounds, coverage), shadow_size)
    }

    /// [`Self::new`] with the light's faces ([`light_faces`]) already worked out.
    pub fn with_faces(light: &Light, faces: &[LightFace], shadow_size: u32) -> Self {
        let direction = Vec3::from(light.direction).normalize_or(Vec3::NEG_Y);
        let mut face_view_proj = [Mat4::IDENTITY.to_cols_array_2d(); 6];
        for (slot, face) in face_view_proj.iter_mut().zip(faces) {
            *slot = face.view_proj.to_cols_array_2d();
        }
        // World size of one shadow texel (per metre of distance for perspective faces).
        let texel_world = faces[0].extent / shadow_size as f32;
        let face_count = faces.len() as u32;
        let (cos_inner, cos_outer) = match light.kind {
            LightKind::Spot => {
                let outer = light.outer_cone.max(1e-4);
                let inner = light.inner_cone.clamp(0.0, outer * 0.999);
                (inner.cos(), outer.cos())
            }
            _ => (1.0, -1.0),
        };
        let radiance = Vec3::from(light.color) * light.intensity;
        Self {
            face_view_proj,
            position: light.position,
            kind: light_kind_code(light.kind),
            direction: direction.into(),
            cos_inner,
            radiance: radiance.into(),
            cos_outer,
            shadow_texel: 1.0 / shadow_size as f32,
            normal_bias: NORMAL_BIAS_TEXELS * texel_world,
            first_layer: 0,
            face_count,
        }
    }
}

/// The `LIGHT_*` constants of `shaders/lights.wgsl`.
fn light_kind_code(kind: LightKind) -> u32 {
    match kind {
        LightKind::Directional => 0,
        LightKind::Spot => 1,
        LightKind::Point => 2,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shaders::{layout_check::assert_struct, DIRECT_LIGHT};
    use std::mem::{offset_of, size_of};

    #[test]
    fn camera_uniform_matches_wgsl() {
        assert_struct(
            &DIRECT_LIGHT,
            "CameraUniform",
            size_of::<CameraUniform>(),
            &[
                ("view_proj", offset_of!(CameraUniform, view_proj)),
                ("position", offset_of!(CameraUniform, position)),
                ("roughness", offset_of!(CameraUniform, roughness)),
                ("inv_view_proj", offset_of!(CameraUniform, inv_view_proj)),
            ],
        );
    }

    #[test]
    fn light_uniform_matches_wgsl() {
        assert_struct(
            &DIRECT_LIGHT,
            "LightUniform",
            size_of::<LightUniform>(),
            &[
                ("face_view_proj", offset_of!(LightUniform, face_view_proj)),
                ("position", offset_of!(LightUniform, position)),
                ("kind", offset_of!(LightUniform, kind)),
                ("direction", offset_of!(LightUniform, direction)),
                ("cos_inner", offset_of!(LightUniform, cos_inner)),
                ("radiance", offset_of!(LightUniform, radiance)),
                ("cos_outer", offset_of!(LightUniform, cos_outer)),
                ("shadow_texel", offset_of!(LightUniform, shadow_texel)),
                ("normal_bias", offset_of!(LightUniform, normal_bias)),
                ("first_layer", offset_of!(LightUniform, first_layer)),
                ("face_count", offset_of!(LightUniform, face_count)),
            ],
        );
    }

    #[test]
    fn lights_uniform_matches_wgsl() {
        assert_struct(
            &DIRECT_LIGHT,
            "Lights",
            size_of::<LightsUniform>(),
            &[
                ("count", offset_of!(LightsUniform, count)),
                ("punctual", offset_of!(LightsUniform, punctual)),
                ("pad1", offset_of!(LightsUniform, pad1)),
                ("pad2", offset_of!(LightsUniform, pad2)),
                ("list", offset_of!(LightsUniform, list)),
            ],
        );
    }

    /// Each light's layers follow the previous light's: a point light between two others takes
    /// six, and the layer matrices are each light's faces in order.
    #[test]
    fn lights_take_consecutive_shadow_layers() {
        let lights = [
            light(LightKind::Spot),
            light(LightKind::Point),
            light(LightKind::Directional),
        ];
        let u = LightsUniform::new(&lights, &unit_box(), 256);
        assert_eq!(u.count, 3);
        let firsts: Vec<u32> = u.used().iter().map(|l| l.first_layer).collect();
        assert_eq!(firsts, [0, 1, 7]);
        assert_eq!(face_count(&lights, Coverage::Scene), 8);
        let layers = u.layer_view_proj();
        assert_eq!(layers.len(), 8);
        assert_eq!(layers[1..7], u.list[1].face_view_proj[..]);
        assert_eq!(layers[7], u.list[2].face_view_proj[0]);
        let faces = lights_faces(&lights, &unit_box(), Coverage::Scene);
        let owners: Vec<u32> = faces.iter().map(|(i, _)| *i).collect();
        assert_eq!(owners, [0, 1, 1, 1, 1, 1, 1, 2]);
    }

    fn unit_box() -> Aabb {
        Aabb {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        }
    }

    fn light(kind: LightKind) -> Light {
        Light {
            kind,
            position: [0.0, 0.5, 0.0],
            direction: [0.0, -1.0, 0.0],
            color: [1.0; 3],
            intensity: 2.0,
            inner_cone: 0.3,
            outer_cone: 0.6,
        }
    }

    /// Projects `p` with a face matrix into [0,1]² texture space and [0,1] depth.
    fn project(m: [[f32; 4]; 4], p: Vec3) -> Vec3 {
        let clip = Mat4::from_cols_array_2d(&m) * p.extend(1.0);
        clip.truncate() / clip.w
    }

    #[test]
    fn directional_shadow_frustum_encloses_the_scene() {
        let u = LightUniform::new(
            &light(LightKind::Directional),
            &unit_box(),
            Coverage::Scene,
            512,
        );
        for c in unit_box().corners() {
            let ndc = project(u.face_view_proj[0], c);
            assert!(ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0, "{c} -> {ndc}");
            assert!((0.0..=1.0).contains(&ndc.z), "{c} -> {ndc}");
        }
        // Closer to the light means smaller depth: the top of the box is in front of the floor.
        let top = project(u.face_view_proj[0], Vec3::new(0.0, 1.0, 0.0));
        let bottom = project(u.face_view_proj[0], Vec3::new(0.0, -1.0, 0.0));
        assert!(top.z < bottom.z);
    }

    #[test]
    fn point_light_faces_cover_their_axis() {
        let u = LightUniform::new(&light(LightKind::Point), &unit_box(), Coverage::Scene, 256);
        let axes = [
            Vec3::X,
            Vec3::NEG_X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
        ];
        for (face, axis) in axes.iter().enumerate() {
            // A point along the face's axis, slightly off-centre, lands inside that face only.
            let p = Vec3::from(u.position) + *axis * 0.4 + Vec3::splat(0.05);
            let ndc = project(u.face_view_proj[face], p);
            assert!(ndc.x.abs() < 1.0 && ndc.y.abs() < 1.0, "face {face}: {ndc}");
            assert!((0.0..=1.0).contains(&ndc.z), "face {face}: {ndc}");
        }
    }

    /// A 100 m × 100 m, 20 m high "city" seen from its southern edge at eye height, the sun
    /// from above at an angle.
    fn city_view(x: f32) -> (Aabb, Camera, Light) {
        let bounds = Aabb {
            min: Vec3::new(-50.0, 0.0, -50.0),
            max: Vec3::new(50.0, 20.0, 50.0),
        };
        let camera = Camera {
            position: [x, 5.0, 45.0],
            target: [x, 2.0, 0.0],
            fov_y_degrees: 40.0,
        };
        let sun = Light {
            direction: Vec3::new(-0.4, -0.8, -0.3).normalize().to_array(),
            ..light(LightKind::Directional)
        };
        (bounds, camera, sun)
    }

    /// Every point the camera sees of the scene lands inside the far cascade (texture space
    /// and depth), those up to the near cascade's distance inside the near one, and both cover
    /// less than the scene's face: a grid of points in the box, those inside the view frustum
    /// checked.
    #[test]
    fn a_view_fitted_face_covers_what_the_camera_sees() {
        let (bounds, camera, sun) = city_view(0.0);
        let aspect = 16.0 / 9.0;
        let view = Coverage::View {
            camera: &camera,
            aspect,
        };
        let faces = light_faces(&sun, &bounds, view);
        let (near, fitted) = (faces[0], faces[1]);
        let whole = light_faces(&sun, &bounds, Coverage::Scene)[0];
        assert_eq!(faces.len() as u32, view.faces(LightKind::Directional));
        assert!(
            fitted.extent < whole.extent && near.extent < 0.5 * fitted.extent,
            "{} {} {}",
            near.extent,
            fitted.extent,
            whole.extent
        );
        let camera_clip = camera_view_proj(&camera, aspect, &bounds);
        let eye = Vec3::from(camera.position);
        let depth = |p: Vec3| (p - eye).dot(camera_forward(&camera));
        let farthest = bounds.corners().map(depth).into_iter().fold(0.0, f32::max);
        let (mut seen, mut near_seen, n) = (0, 0, 24);
        for i in 0..=n {
            for j in 0..=n {
                for k in 0..=n {
                    let t = Vec3::new(i as f32, j as f32, k as f32) / n as f32;
                    let p = bounds.min + (bounds.max - bounds.min) * t;
                    let c = camera_clip * p.extend(1.0);
                    let ndc = c.truncate() / c.w;
                    let in_view = c.w > 0.0
                        && ndc.x.abs() <= 1.0
                        && ndc.y.abs() <= 1.0
                        && (0.0..=1.0).contains(&ndc.z);
                    if !in_view {
                        continue;
                    }
                    seen += 1;
                    let inside = |f: LightFace| {
                        let q = project(f.view_proj.to_cols_array_2d(), p);
                        q.x.abs() <= 1.0 && q.y.abs() <= 1.0 && (0.0..=1.0).contains(&q.z)
                    };
                    assert!(
                        inside(fitted),
                        "{p} seen by the camera is outside the far face"
                    );
                    // The far plane of the camera's clip space is beyond the farthest corner,
                    // so the near cascade reaches at least this far.
                    if depth(p) <= NEAR_CASCADE * 0.9 * farthest {
                        near_seen += 1;
                        assert!(inside(near), "{p} seen nearby is outside the near face");
                    }
                }
            }
        }
        assert!(seen > 1000 && near_seen > 20, "{seen} {near_seen}");
    }

    /// A camera that sees the whole scene gets the scene's face; one that moves a little keeps
    /// its faces as they were; one that moves further (sideways, so the region keeps its size)
    /// moves them by whole snapping steps (side / 16: whole texels of any map whose side is a
    /// multiple of 16); sides are the scene's over a power of 2^(1/8).
    #[test]
    fn view_fitted_faces_are_stable_and_fall_back_to_the_scene() {
        let (bounds, _, sun) = city_view(0.0);
        let overview = Camera {
            position: [0.0, 400.0, 400.0],
            target: [0.0, 0.0, 0.0],
            fov_y_degrees: 60.0,
        };
        let coverage = |camera| Coverage::View {
            camera,
            aspect: 1.5,
        };
        let whole = light_faces(&sun, &bounds, Coverage::Scene)[0];
        assert_eq!(light_faces(&sun, &bounds, coverage(&overview))[1], whole);
        let near_face = |x: f32| {
            let camera = city_view(x).1;
            light_faces(
                &sun,
                &bounds,
                Coverage::View {
                    camera: &camera,
                    aspect: 1.5,
                },
            )[0]
        };
        let fa = near_face(0.0);
        assert_eq!(near_face(0.37), fa, "a small step moves nothing");
        let fb = near_face(9.0);
        assert_eq!(fa.extent, fb.extent);
        // The same world point's texture coordinates differ by whole snapping steps.
        let p = Vec3::new(3.0, 1.0, -7.0);
        let (pa, pb) = (
            project(fa.view_proj.to_cols_array_2d(), p),
            project(fb.view_proj.to_cols_array_2d(), p),
        );
        let steps_moved = (pa - pb).truncate() * 0.5 * SNAP_TEXELS;
        assert!(
            (steps_moved - steps_moved.round()).abs().max_element() < 1e-3,
            "{steps_moved}"
        );
        assert!(steps_moved.abs().max_element() >= 1.0, "{steps_moved}");
        // A step of the side is 2^(1/8): the scene's side over the fitted one is a power of it.
        let steps = (whole.extent / fa.extent).log2() * SIDE_STEPS_PER_OCTAVE;
        assert!((steps - steps.round()).abs() < 1e-3, "{steps}");
    }

    /// Sutherland–Hodgman keeps the part of a square on the plane's positive side.
    #[test]
    fn polygons_are_clipped_to_the_positive_side() {
        let square = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(2.0, 2.0, 0.0),
            Vec3::new(0.0, 2.0, 0.0),
        ];
        // x ≤ 1.
        let half = clip_polygon(&square, Vec4::new(-1.0, 0.0, 0.0, 1.0));
        assert_eq!(half.len(), 4);
        assert!(half.iter().all(|p| p.x <= 1.0 + 1e-6));
        assert!(half.iter().any(|p| (p.x - 1.0).abs() < 1e-6));
        assert!(clip_polygon(&square, Vec4::new(1.0, 0.0, 0.0, -5.0)).is_empty());
    }

    #[test]
    fn spot_cone_cosines_are_ordered_and_radiance_scales() {
        let u = LightUniform::new(&light(LightKind::Spot), &unit_box(), Coverage::Scene, 256);
        assert!(u.cos_inner > u.cos_outer);
        assert_eq!(u.radiance, [2.0; 3]);
        assert_eq!(u.face_count, 1);
        assert_eq!(Coverage::Scene.faces(LightKind::Point), 6);
    }
}
