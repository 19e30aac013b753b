//! Light from one virtual point light, the CPU reference of `shaders/vpl_light.wgsl` shared
//! by the VPL methods (seed paper 003's §4; Dachsbacher & Stamminger 2005's pixel lights).

use crate::passes::rsm::GlossySender;
use crate::scene::brdf::Brdf;
use glam::Vec3;
use std::f32::consts::PI;

/// A VPL: where it is, its unit normal, its diffuse flux Φ, its glossy lobe, its disk area A
/// and the area its glossy lobe is widened by (the texels it stands for).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VplLight {
    pub position: Vec3,
    pub normal: Vec3,
    pub flux: Vec3,
    pub glossy: GlossySender,
    pub area: f32,
    pub footprint: f32,
}

/// L(x, ω_o) from `vpl` at surface point `x` with unit normal `n` and BRDF `s`, seen from
/// direction `v` (unit, towards the viewer): f_r·Φ(ω)·cosθ_i·cosθ_x over A + π d² (the
/// irradiance of the VPL's disk on its axis, finite at d = 0), Φ(ω) the flux the VPL sends
/// towards x ([`GlossySender::sent_flux`], widened by its footprint).
pub fn vpl_light(vpl: &VplLight, x: Vec3, n: Vec3, v: Vec3, s: &Brdf) -> Vec3 {
    let to_vpl = vpl.position - x;
    let d2 = to_vpl.length_squared();
    if d2 <= 0.0 {
        return Vec3::ZERO;
    }
    let w = to_vpl / d2.sqrt();
    let cos_x = n.dot(w).max(0.0);
    let cos_i = vpl.normal.dot(-w).max(0.0);
    s.eval(n, w, v)
        * vpl
            .glossy
            .sent_flux(vpl.flux, -w, GlossySender::spread(vpl.footprint, d2))
        * (cos_i * cos_x / (vpl.area + PI * d2))
}
