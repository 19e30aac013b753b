//! The renderer (the shared stages plus one GI method per frame), the debug views drawn from
//! a frame, the quality metrics against a reference and the offline `render` command: what
//! the service, the bench and the tests drive, with no async runtime.

pub mod debug_views;
pub mod offline;
pub mod quality;
pub mod renderer;

// Paths as when the layers were modules of one crate: `crate::gi::…`, `crate::passes::…`.
use lightcast_gi as gi;
use lightcast_passes::{gpu, passes};
use lightcast_scene as scene;
