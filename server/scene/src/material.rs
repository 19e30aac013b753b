//! Materials: glTF's metallic/roughness parameters (shaded by [`crate::brdf`]) and the
//! diffuse/glossy lobes the paper's equations use (seed 004, eq. 3–4), fitted to them.

use glam::Vec3;

/// A surface material. Factors are linear; the texture (if any) multiplies `base_color`.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Linear RGBA base colour factor.
    pub base_color: [f32; 4],
    pub metallic: f32,
    pub roughness: f32,
    /// Dielectric specular weight (`KHR_materials_specular`'s `specularFactor`; 1 without it,
    /// 0 makes a dielectric Lambertian).
    pub specular: f32,
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
            specular: 1.0,
            emissive: [0.0; 3],
            base_color_texture: None,
            alpha_cutoff: None,
        }
    }
}

/// The paper's reflectance model for one surface point: a Lambertian of albedo ρ_d plus a
/// normalised Phong lobe of colour ρ_g and exponent k about the mirror direction (eq. 3–4),
/// as [`crate::brdf::Brdf::lobes`] fits it to the material's BRDF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiffuseGlossy {
    pub diffuse: Vec3,
    pub glossy: Vec3,
    pub exponent: f32,
}

impl Material {
    /// The BRDF of the untextured factors.
    pub fn brdf(&self) -> crate::brdf::Brdf {
        self.brdf_with(Vec3::ONE)
    }

    /// The BRDF where the base-colour texture reads `texel` (linear).
    pub fn brdf_with(&self, texel: Vec3) -> crate::brdf::Brdf {
        let [r, g, b, _] = self.base_color;
        crate::brdf::Brdf::new(
            Vec3::new(r, g, b) * texel,
            self.metallic,
            self.roughness,
            self.specular,
        )
    }

    pub fn is_emissive(&self) -> bool {
        self.emissive.iter().any(|&e| e > 0.0)
    }
}
