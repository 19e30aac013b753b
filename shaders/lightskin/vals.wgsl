// A selected virtual area light, as written by val_select.wgsl and read by cache lighting.

// Mirrored by `Val` in server/passes/src/passes/val_select.rs.
struct Val {
    position: vec3<f32>,
    // Disk area A_l (eq. 1).
    area: f32,
    normal: vec3<f32>,
    // Monte Carlo weight 1 / (N_sVAL · P_VAL) of eq. 13–15; 0 for an unused slot.
    weight: f32,
    flux: vec3<f32>,
    // Row-major index of the RSM texel it came from.
    texel: u32,
    // The texel's glossy lobe (rsm_glossy.wgsl).
    glossy: GlossySender,
}
