//! lightcast server: scenes, the GPU pipeline and the network service.
//!
//! The GPU pipeline ([`renderer`], [`passes`], [`gpu`]) has no async runtime in it, so the
//! offline `render` command ([`offline`]) and tests can drive it directly; [`service`] puts
//! it behind HTTP and WebSocket.

pub mod bench;
pub mod debug_views;
pub mod gi;
pub mod gpu;
pub mod offline;
pub mod passes;
pub mod quality;
pub mod renderer;
pub mod scene;
pub mod service;
