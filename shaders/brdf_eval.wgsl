// The BRDF of brdf.wgsl evaluated: glTF's GGX/Smith/Schlick specular lobe and a diffuse lobe
// weighted by what the specular lobe leaves (energy-conserving), and the paper's diffuse and
// Phong lobes fitted to it for the methods written for them (seed 004, eq. 3–4). Mirrored by
// `scene::brdf`; the shader that includes this declares
//     var<storage, read> brdf_table: array<vec4<f32>>;
// holding `scene::brdf::BrdfTable` (`SceneBuffers::brdf_table`).

// Mirrored by `scene::brdf::TABLE_SIZE`, `DIELECTRIC_F0` and `MIN_LOBE_ALBEDO` (and
// `phong_exponent`'s range by `MIN_EXPONENT`, `MAX_EXPONENT`).
const BRDF_TABLE_SIZE: u32 = 32u;
const DIELECTRIC_F0: f32 = 0.04;
const MIN_LOBE_ALBEDO: f32 = 1e-4;

// [A, B, Ē, P] at cosine `mu` and roughness `roughness`, bilinear in (√μ, roughness)
// (`BrdfTable::terms`).
fn brdf_terms(mu: f32, roughness: f32) -> vec4<f32> {
    let last = f32(BRDF_TABLE_SIZE - 1u);
    let p = vec2<f32>(sqrt(clamp(mu, 0.0, 1.0)), clamp(roughness, 0.0, 1.0)) * last;
    let i = min(vec2<u32>(p), vec2<u32>(BRDF_TABLE_SIZE - 2u));
    let f = p - vec2<f32>(i);
    let row = i.y * BRDF_TABLE_SIZE + i.x;
    let lo = mix(brdf_table[row], brdf_table[row + 1u], f.x);
    let hi = mix(brdf_table[row + BRDF_TABLE_SIZE], brdf_table[row + BRDF_TABLE_SIZE + 1u], f.x);
    return mix(lo, hi, f.y);
}

// A dielectric's specular albedo E(μ) = 0.04·A + B (`BrdfTable::dielectric`).
fn dielectric_albedo(mu: f32, roughness: f32) -> f32 {
    let t = brdf_terms(mu, roughness);
    return DIELECTRIC_F0 * t.x + t.y;
}

// Its cosine-weighted mean Ē (`BrdfTable::dielectric_mean`).
fn dielectric_mean_albedo(roughness: f32) -> f32 {
    return brdf_terms(1.0, roughness).z;
}

// Schlick's F0 (per channel) and F90: glTF's mix of the dielectric and the metal by
// `metallic`.
fn fresnel_f0(s: SurfaceBrdf) -> vec3<f32> {
    return mix(vec3<f32>(DIELECTRIC_F0 * s.specular), s.base, s.metallic);
}

fn fresnel_f90(s: SurfaceBrdf) -> f32 {
    return mix(s.specular, 1.0, s.metallic);
}

// Smith's separable G / (4 n·l n·v), finite at n·v = 0 (`scene::brdf::smith_v`).
fn smith_visibility(nl: f32, nv: f32, a2: f32) -> f32 {
    let ll = nl + sqrt(a2 + (1.0 - a2) * nl * nl);
    let lv = nv + sqrt(a2 + (1.0 - a2) * nv * nv);
    return 1.0 / (ll * lv);
}

fn ggx_d(nh: f32, a2: f32) -> f32 {
    let d = nh * nh * (a2 - 1.0) + 1.0;
    return select(0.0, a2 / (PI * d * d), nh > 0.0);
}

// The specular lobe's directional albedo at cosine `mu`, F0·A + F90·B.
fn specular_albedo(s: SurfaceBrdf, mu: f32) -> vec3<f32> {
    let t = brdf_terms(mu, s.roughness);
    return fresnel_f0(s) * t.x + fresnel_f90(s) * t.y;
}

// The share of what the surface reflects of light arriving at cosine `mu` that its specular
// lobe carries, by Rec. 709 luminance (`Brdf::specular_share`); by reciprocity also the share
// of what reaches a viewer at that cosine. Comparisons sort pixels into diffuse and specular
// receivers by it.
fn specular_share(s: SurfaceBrdf, mu: f32) -> f32 {
    let rec709 = vec3<f32>(0.2126, 0.7152, 0.0722);
    let specular = dot(specular_albedo(s, mu), rec709);
    let total = specular + dot(diffuse_albedo(s, mu), rec709);
    return select(0.0, specular / total, total > 0.0);
}

// The diffuse lobe's albedo for light arriving at cosine `mu` (`Brdf::diffuse_albedo`).
fn diffuse_albedo(s: SurfaceBrdf, mu: f32) -> vec3<f32> {
    return s.base * ((1.0 - s.metallic) * (1.0 - s.specular * dielectric_albedo(mu, s.roughness)));
}

// A surface point's BRDF seen from one direction, with what does not depend on the light's
// direction worked out once: a pixel lit by many lights (VPLs, RSM texels) evaluates it per
// light with `eval_viewed`, two table lookups fewer each.
struct ViewedBrdf {
    brdf: SurfaceBrdf,
    // Unit shading normal and direction towards the viewer.
    n: vec3<f32>,
    v: vec3<f32>,
    nv: f32,
    // The diffuse lobe's viewer-side weight (1 − s·E(n·v))/(1 − s·Ē), over π.
    diffuse_view: f32,
}

fn view_brdf(s: SurfaceBrdf, n: vec3<f32>, to_viewer: vec3<f32>) -> ViewedBrdf {
    let nv = max(dot(n, to_viewer), 0.0);
    let diffuse_view = (1.0 - s.specular * dielectric_albedo(nv, s.roughness))
        / (1.0 - s.specular * dielectric_mean_albedo(s.roughness)) / PI;
    return ViewedBrdf(s, n, to_viewer, nv, diffuse_view);
}

// f_r for light arriving from `to_light` at the viewed surface (`Brdf::eval`).
fn eval_viewed(viewed: ViewedBrdf, to_light: vec3<f32>) -> vec3<f32> {
    let s = viewed.brdf;
    let nl = dot(viewed.n, to_light);
    if nl <= 0.0 {
        return vec3<f32>(0.0);
    }
    let alpha = s.roughness * s.roughness;
    let a2 = alpha * alpha;
    let diffuse = diffuse_albedo(s, nl) * viewed.diffuse_view;
    let sum = to_light + viewed.v;
    let len2 = dot(sum, sum);
    if len2 <= 0.0 {
        return diffuse;
    }
    let h = sum * inverseSqrt(len2);
    let f0 = fresnel_f0(s);
    let fresnel = f0 + (fresnel_f90(s) - f0) * pow(1.0 - clamp(dot(viewed.v, h), 0.0, 1.0), 5.0);
    return diffuse + fresnel * (ggx_d(dot(viewed.n, h), a2) * smith_visibility(nl, viewed.nv, a2));
}

// f_r for light arriving from `to_light` and leaving towards `to_viewer` (`Brdf::eval`).
fn eval_brdf(s: SurfaceBrdf, n: vec3<f32>, to_light: vec3<f32>, to_viewer: vec3<f32>) -> vec3<f32> {
    return eval_viewed(view_brdf(s, n, to_viewer), to_light);
}

// Its diffuse lobe alone (`Brdf::eval_diffuse`).
fn eval_diffuse(s: SurfaceBrdf, n: vec3<f32>, to_light: vec3<f32>, to_viewer: vec3<f32>) -> vec3<f32> {
    let nl = dot(n, to_light);
    if nl <= 0.0 {
        return vec3<f32>(0.0);
    }
    return diffuse_albedo(s, nl) * view_brdf(s, n, to_viewer).diffuse_view;
}

// The paper's lobes fitted to the BRDF (`scene::material::DiffuseGlossy`).
struct PhongLobes {
    diffuse: vec3<f32>,
    glossy: vec3<f32>,
    exponent: f32,
}

// `scene::brdf::phong_exponent`.
fn phong_exponent(roughness: f32) -> f32 {
    let alpha = roughness * roughness;
    return clamp((2.0 / (alpha * alpha) - 2.0) * 0.25, 1.0, 4096.0);
}

// `Brdf::lobes`: seen from cosine `mu`, the diffuse lobe's albedo, the specular lobe's
// directional albedo over the Phong lobe's own (P) as the Phong lobe's colour, and the Phong
// exponent of the roughness.
fn phong_lobes(s: SurfaceBrdf, mu: f32) -> PhongLobes {
    let t = brdf_terms(mu, s.roughness);
    return PhongLobes(
        diffuse_albedo(s, mu),
        (fresnel_f0(s) * t.x + fresnel_f90(s) * t.y) / max(t.w, MIN_LOBE_ALBEDO),
        phong_exponent(s.roughness),
    );
}
