//! Uniforms every pass shares: the camera (`shaders/common.wgsl`) and the frame's lights with
//! their shadow projections (`shaders/lights.wgsl`).

use crate::scene::Aabb;
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};
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
    pub pad0: f32,
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

impl LightsUniform {
    /// Every light of `lights` (at most [`MAX_LIGHTS`]; callers check), all punctual, with
    /// its shadow faces fitted to the scene bounds, their layers following each other in
    /// light order.
    pub fn new(lights: &[Light], bounds: &Aabb, shadow_size: u32) -> Self {
        Self::with_punctual(lights, lights.len(), bounds, shadow_size)
    }

    /// [`Self::new`] where only the first `punctual` lights are punctual and the rest light
    /// for the environment (the direct-light pass counts their light as the environment's,
    /// with the indirect light).
    pub fn with_punctual(
        lights: &[Light],
        punctual: usize,
        bounds: &Aabb,
        shadow_size: u32,
    ) -> Self {
        debug_assert!(lights.len() <= MAX_LIGHTS, "{} lights", lights.len());
        let mut all = Self::zeroed();
        let mut first_layer = 0;
        for (slot, light) in all.list.iter_mut().zip(lights) {
            *slot = LightUniform::new(light, bounds, shadow_size);
            slot.first_layer = first_layer;
            first_layer += LightUniform::face_count(light.kind);
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
            .flat_map(|l| {
                l.face_view_proj[..LightUniform::face_count_of(l.kind) as usize]
                    .iter()
                    .copied()
            })
            .collect()
    }
}

/// Shadow-map layers (and RSM faces) of all `lights` together.
pub fn face_count(lights: &[Light]) -> u32 {
    lights
        .iter()
        .map(|l| LightUniform::face_count(l.kind))
        .sum()
}

/// The faces of every light in light order, each with its light's index in the list.
pub fn lights_faces(lights: &[Light], bounds: &Aabb) -> Vec<(u32, LightFace)> {
    lights
        .iter()
        .enumerate()
        .flat_map(|(i, l)| {
            light_faces(l, bounds)
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
/// directional light, one perspective face for a spot light, six cube faces for a point light.
pub fn light_faces(light: &Light, bounds: &Aabb) -> Vec<LightFace> {
    let direction = Vec3::from(light.direction).normalize_or(Vec3::NEG_Y);
    let position = Vec3::from(light.position);
    let radius = bounds.radius().max(1e-3);
    let center = bounds.center();
    match light.kind {
        LightKind::Directional => {
            let eye = center - direction * 2.0 * radius;
            let view = Mat4::look_to_rh(eye, direction, stable_up(direction));
            let proj =
                Mat4::orthographic_rh(-radius, radius, -radius, radius, radius, 3.0 * radius);
            vec![LightFace {
                view_proj: proj * view,
                axis: direction,
                extent: 2.0 * radius,
                perspective: false,
            }]
        }
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

impl LightUniform {
    /// The light's parameters and the view-projection of each shadow-map face, fitted to the
    /// scene bounds.
    pub fn new(light: &Light, bounds: &Aabb, shadow_size: u32) -> Self {
        let direction = Vec3::from(light.direction).normalize_or(Vec3::NEG_Y);
        let faces = light_faces(light, bounds);
        let mut face_view_proj = [Mat4::IDENTITY.to_cols_array_2d(); 6];
        for (slot, face) in face_view_proj.iter_mut().zip(&faces) {
            *slot = face.view_proj.to_cols_array_2d();
        }
        // World size of one shadow texel (per metre of distance for perspective faces).
        let texel_world = faces[0].extent / shadow_size as f32;
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
            pad0: 0.0,
        }
    }

    /// Shadow-map layers this light renders.
    pub fn face_count(kind: LightKind) -> u32 {
        match kind {
            LightKind::Point => 6,
            LightKind::Directional | LightKind::Spot => 1,
        }
    }

    /// [`Self::face_count`] of a light's `kind` code.
    fn face_count_of(kind: u32) -> u32 {
        if kind == light_kind_code(LightKind::Point) {
            6
        } else {
            1
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
                ("pad0", offset_of!(LightUniform, pad0)),
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
        assert_eq!(face_count(&lights), 8);
        let layers = u.layer_view_proj();
        assert_eq!(layers.len(), 8);
        assert_eq!(layers[1..7], u.list[1].face_view_proj[..]);
        assert_eq!(layers[7], u.list[2].face_view_proj[0]);
        let faces = lights_faces(&lights, &unit_box());
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
        let u = LightUniform::new(&light(LightKind::Directional), &unit_box(), 512);
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
        let u = LightUniform::new(&light(LightKind::Point), &unit_box(), 256);
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

    #[test]
    fn spot_cone_cosines_are_ordered_and_radiance_scales() {
        let u = LightUniform::new(&light(LightKind::Spot), &unit_box(), 256);
        assert!(u.cos_inner > u.cos_outer);
        assert_eq!(u.radiance, [2.0; 3]);
        assert_eq!(LightUniform::face_count(LightKind::Point), 6);
    }
}
