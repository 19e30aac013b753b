//! Light from one virtual point light, the CPU reference of `shaders/vpl_light.wgsl` shared
//! by the VPL methods (seed paper 003's §4; Dachsbacher & Stamminger 2005's pixel lights).

use crate::scene::brdf::Brdf;
use glam::Vec3;
use std::f32::consts::PI;

/// A diffusely emitting VPL: where it is, its unit normal, its flux Φ and its disk area A.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VplLight {
    pub position: Vec3,
    pub normal: Vec3,
    pub flux: Vec3,
    pub area: f32,
}

/// L(x, ω_o) from `vpl` at surface point `x` with unit normal `n` and BRDF `s`, seen from
/// direction `v` (unit, towards the viewer): f_r·Φ·cosθ_i·cosθ_x over A + π d² (the irradiance
/// of the VPL's disk on its axis, finite at d = 0).
pub fn vpl_light(vpl: &VplLight, x: Vec3, n: Vec3, v: Vec3, s: &Brdf) -> Vec3 {
    let to_vpl = vpl.position - x;
    let d2 = to_vpl.length_squared();
    if d2 <= 0.0 {
        return Vec3::ZERO;
    }
    let w = to_vpl / d2.sqrt();
    let cos_x = n.dot(w).max(0.0);
    let cos_i = vpl.normal.dot(-w).max(0.0);
    s.eval(n, w, v) * vpl.flux * (cos_i * cos_x / (vpl.area + PI * d2))
}
