//! What the links' rays are traced against (eq. 3's visibility), shared by the CPU rays
//! ([`super::links`]) and the adapter's ([`super::link_rays`]).

use super::hierarchy::Tree;
use super::sampling::Surfel;
use crate::gi::common::bvh::SceneBvh;

/// The scene as the links see it: surfels in the hierarchy's leaf order, each of `area`.
pub struct Senders<'a> {
    pub surfels: &'a [Surfel],
    pub area: f64,
    pub tree: &'a Tree,
    /// For visibility rays.
    pub bvh: &'a SceneBvh,
    /// For the facing of what the rays hit.
    pub scene: &'a crate::scene::Scene,
    /// Length of the scene's bounds diagonal: ray offsets are relative to it.
    pub extent: f32,
}

impl Senders<'_> {
    /// How far short of its surfel a link ray stops, and how near a cache a surfel counts as
    /// at it: far above f32 rounding at the scene's coordinates, far below its features (as
    /// the reference tracer's ray offset). The CPU and GPU rays use the same.
    pub fn ray_offset(&self) -> f32 {
        1e-5 * self.extent
    }
}
