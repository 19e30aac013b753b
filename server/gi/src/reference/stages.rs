//! The stages of `reference`.

use crate::gpu::timing::Stage;

/// Path-traced samples added to the accumulation.
pub const PATH_TRACE: Stage = Stage::new(14, "path_trace");
/// The accumulated mean written to the indirect buffer.
pub const REFERENCE_RESOLVE: Stage = Stage::new(15, "reference_resolve");

pub const ALL: &[Stage] = &[PATH_TRACE, REFERENCE_RESOLVE];
