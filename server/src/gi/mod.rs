//! Global illumination: LightSkin light caches fed by Bidirectional Reflective Shadow Maps
//! (seed paper 004). [`sampling`] runs the per-frame BRSM stages (RSM, importance, cumulative
//! sums, VAL selection); the GPU passes themselves live in `crate::passes`.

pub mod sampling;
