//! LightSkin light caches fed by Bidirectional Reflective Shadow Maps (seed paper 004), the
//! `lightskin` and `brsm` methods. Per model, [`caches`] are precomputed once and kept by
//! [`cache_store`]; per frame, [`sampling`] runs the BRSM stages (RSM, [`importance`],
//! [`cumulative_sums`], [`val_select`]), [`cache_lighting`] lights every cache from the VALs,
//! [`proxy_occlusion`] dims hidden proxies and [`indirect_light`] interpolates them per pixel.
//! [`cache_buffers`] holds the caches on the GPU; [`cpu`] is the CPU reference of the equations.

pub mod cache_buffers;
pub mod cache_lighting;
pub mod cache_store;
pub mod caches;
pub mod cpu;
pub mod cumulative_sums;
pub mod importance;
pub mod indirect_light;
pub mod proxy_occlusion;
pub mod sampling;
pub mod val_select;
