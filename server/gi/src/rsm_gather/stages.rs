//! The stage of `rsm_gather` (besides the shared `rsm`).

use crate::gpu::timing::Stage;

/// Every pixel's gather of RSM texels.
pub const RSM_GATHER: Stage = Stage::new(29, "rsm_gather");

pub const ALL: &[Stage] = &[RSM_GATHER];
