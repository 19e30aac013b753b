//! Device setup and the plumbing every pass shares: shader loading, pass timing, readback.

pub mod context;
pub mod readback;
pub mod shaders;
pub mod timing;

pub use context::{BackendChoice, GpuContext, GpuError};
