//! The GPU context ([`gpu`]: adapter, timing, read-back, shader sources) and the passes every
//! frame shares ([`passes`]: shadow map, G-buffer, RSM, direct light, exposure, tone map,
//! Y'CbCr), below the GI methods: nothing here can name a method.

pub mod gpu;
pub mod passes;

// Paths as when the layers were modules of one crate: `crate::scene::…`.
use lightcast_scene as scene;
