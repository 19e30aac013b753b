//! Materials: glTF's metallic/roughness parameters and the diffuse/glossy split the paper's
//! BRDF uses (diffuse albedo ρ_d, glossy colour ρ_g, Phong exponent k; eq. 3–4).

use glam::Vec3;

/// Reflectance at normal incidence of a dielectric (glTF's fixed 4 %).
const DIELECTRIC_F0: f32 = 0.04;
/// Exponent range kept finite: k = 1 is a broad lobe, 4096 is close to a mirror for our maps.
const MIN_EXPONENT: f32 = 1.0;
const MAX_EXPONENT: f32 = 4096.0;

/// A surface material. Factors are linear; the texture (if any) multiplies `base_color`.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Linear RGBA base colour factor.
    pub base_color: [f32; 4],
    pub metallic: f32,
    pub roughness: f32,
    /// Linear emitted radiance (emissive factor times strength).
    pub emissive: [f32; 3],
    /// Index into [`super::Scene::textures`] of the sRGB base colour texture.
    pub base_color_texture: Option<usize>,
    /// Alpha below this is cut out (glTF `alphaMode: MASK`); `None` for opaque materials.
    pub alpha_cutoff: Option<f32>,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            name: String::from("default"),
            base_color: [0.8, 0.8, 0.8, 1.0],
            metallic: 0.0,
            roughness: 1.0,
            emissive: [0.0; 3],
            base_color_texture: None,
            alpha_cutoff: None,
        }
    }
}

/// The paper's BRDF parameters for one surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiffuseGlossy {
    pub diffuse: Vec3,
    pub glossy: Vec3,
    pub exponent: f32,
}

/// Maps metallic/roughness to the diffuse/glossy split. Mirrored by `split_material` in
/// `shaders/brdf.wgsl` (the G-buffer pass applies it after texturing).
///
/// Metals reflect only glossily, tinted by the base colour; dielectrics keep their base colour
/// as diffuse albedo and reflect 4 % glossily. The exponent uses the usual Beckmann/Blinn-Phong
/// correspondence k_blinn = 2/α² − 2 with α = roughness² (Walter et al. 2007), divided by 4
/// because the paper's lobe is around the reflection vector (Phong), whose exponent is about a
/// quarter of the equivalent half-vector exponent.
pub fn split(base_color: Vec3, metallic: f32, roughness: f32) -> DiffuseGlossy {
    let metallic = metallic.clamp(0.0, 1.0);
    let alpha = (roughness.clamp(0.0, 1.0) * roughness.clamp(0.0, 1.0)).max(1e-3);
    let k_blinn = 2.0 / (alpha * alpha) - 2.0;
    DiffuseGlossy {
        diffuse: base_color * (1.0 - metallic),
        glossy: Vec3::splat(DIELECTRIC_F0).lerp(base_color, metallic),
        exponent: (k_blinn * 0.25).clamp(MIN_EXPONENT, MAX_EXPONENT),
    }
}

impl Material {
    /// Diffuse/glossy split of the untextured factors.
    pub fn diffuse_glossy(&self) -> DiffuseGlossy {
        let [r, g, b, _] = self.base_color;
        split(Vec3::new(r, g, b), self.metallic, self.roughness)
    }

    pub fn is_emissive(&self) -> bool {
        self.emissive.iter().any(|&e| e > 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dielectric_keeps_base_colour_as_diffuse() {
        let s = split(Vec3::new(0.5, 0.2, 0.1), 0.0, 1.0);
        assert_eq!(s.diffuse, Vec3::new(0.5, 0.2, 0.1));
        assert_eq!(s.glossy, Vec3::splat(0.04));
        assert_eq!(s.exponent, MIN_EXPONENT);
    }

    #[test]
    fn metal_is_glossy_only_and_smoother_means_sharper() {
        let rough = split(Vec3::new(1.0, 0.8, 0.3), 1.0, 0.6);
        let smooth = split(Vec3::new(1.0, 0.8, 0.3), 1.0, 0.2);
        assert_eq!(rough.diffuse, Vec3::ZERO);
        assert_eq!(rough.glossy, Vec3::new(1.0, 0.8, 0.3));
        assert!(smooth.exponent > rough.exponent * 10.0);
        assert!(split(Vec3::ONE, 1.0, 0.0).exponent <= MAX_EXPONENT);
    }
}
