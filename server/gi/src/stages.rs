//! Every pipeline stage: the shared passes' (`passes::stages`) and each registered method's
//! (`MethodEntry::stages`). Frame headers carry a stage's index into [`names`], which
//! `/v1/server` lists as `stages`.

use crate::gpu::timing::Stage;

/// Every stage, by index.
pub fn all() -> Vec<Stage> {
    let mut stages: Vec<Stage> = crate::passes::stages::ALL
        .iter()
        .chain(super::REGISTRY.iter().flat_map(|e| e.stages))
        .copied()
        .collect();
    stages.sort();
    stages.dedup();
    stages
}

/// The stages' names, indexed by [`Stage::index`].
pub fn names() -> Vec<&'static str> {
    all().iter().map(|s| s.name()).collect()
}

/// The index of the stage named `name`.
pub fn index_of(name: &str) -> Option<u16> {
    all().iter().find(|s| s.name() == name).map(|s| s.index())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    /// Indices run 0..N without a gap or a repeat, and names are unique: a frame header's
    /// index means one stage, and `/v1/server`'s list is indexed by it.
    #[test]
    fn stage_indices_run_without_gaps_and_names_are_unique() {
        let stages = all();
        for (i, s) in stages.iter().enumerate() {
            assert_eq!(
                usize::from(s.index()),
                i,
                "stage {} has index {} where {i} is free: a new stage takes index {}",
                s.name(),
                s.index(),
                stages.len()
            );
        }
        let names: BTreeSet<&str> = stages.iter().map(|s| s.name()).collect();
        assert_eq!(names.len(), stages.len(), "two stages share a name");
    }

    /// The indices released before the registry owned them (frame headers of older servers).
    #[test]
    fn released_stage_indices_keep_their_names() {
        let released = [
            "shadow_map",
            "gbuffer",
            "rsm",
            "importance",
            "cumulative_sums",
            "val_select",
            "cache_lighting",
            "proxy_occlusion",
            "indirect_light",
            "indirect_clear",
            "direct_light",
            "exposure",
            "tonemap",
            "readback_copy",
            "path_trace",
            "reference_resolve",
            "vpl_generation",
            "clustering",
            "clustered_indirect",
            "geometry_blur",
            "gbuffer_reduce",
            "indirect_upsample",
            "surfel_light",
            "surfel_shade",
            "paraboloid_maps",
            "cssm_basis",
            "yuv420",
            "surfel_pull",
            "surfel_cache_light",
        ];
        assert_eq!(names()[..released.len()], released);
    }
}
