//! lightcast server: scenes, the GPU pipeline and the network service, as one library for the
//! binary and its tests.
//!
//! The pipeline is layered in crates, each depending only on those below it, so an import
//! against the direction does not compile: [`scene`] (`lightcast-scene`), [`gpu`] and
//! [`passes`] (`lightcast-passes`), [`gi`] (`lightcast-gi`: the methods and their registry),
//! [`renderer`], [`debug_views`], [`quality`] and [`offline`] (`lightcast-render`), [`service`]
//! (`lightcast-service`) and [`bench`] (`lightcast-bench`). None of the pipeline has an async
//! runtime in it, so the offline `render` command and tests drive it directly; [`service`]
//! puts it behind HTTP and WebSocket.

pub use lightcast_bench as bench;
pub use lightcast_gi as gi;
pub use lightcast_passes::{gpu, passes};
pub use lightcast_render::{debug_views, offline, quality, renderer};
pub use lightcast_scene as scene;
pub use lightcast_service as service;
