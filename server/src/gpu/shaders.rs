//! WGSL sources. Each pass is one file in `shaders/`, prefixed by the shared snippets it uses
//! (WGSL has no includes, so a pass module is the concatenation of its files).

/// The files one pass module is made of, in order.
pub struct ShaderSource {
    pub name: &'static str,
    pub files: &'static [(&'static str, &'static str)],
}

macro_rules! wgsl {
    ($file:literal) => {
        ($file, include_str!(concat!("../../../shaders/", $file)))
    };
}

/// The G-buffer writing provoking-vertex ids (adapters without primitive indices).
pub const GBUFFER: ShaderSource = ShaderSource {
    name: "gbuffer",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("materials.wgsl"),
        wgsl!("gbuffer.wgsl"),
        wgsl!("gbuffer_vertex_ids.wgsl"),
    ],
};

/// The G-buffer writing scene-wide triangle ids (needs `Features::PRIMITIVE_INDEX`).
pub const GBUFFER_TRIANGLE_IDS: ShaderSource = ShaderSource {
    name: "gbuffer_triangle_ids",
    files: &[
        wgsl!("enable_primitive_index.wgsl"),
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("materials.wgsl"),
        wgsl!("gbuffer.wgsl"),
        wgsl!("gbuffer_triangle_ids.wgsl"),
    ],
};

pub const SHADOW_MAP: ShaderSource = ShaderSource {
    name: "shadow_map",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("materials.wgsl"),
        wgsl!("shadow_map.wgsl"),
    ],
};

pub const DIRECT_LIGHT: ShaderSource = ShaderSource {
    name: "direct_light",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("lights.wgsl"),
        wgsl!("direct_light.wgsl"),
    ],
};

pub const EXPOSURE: ShaderSource = ShaderSource {
    name: "exposure",
    files: &[wgsl!("exposure_result.wgsl"), wgsl!("exposure.wgsl")],
};

pub const TONEMAP: ShaderSource = ShaderSource {
    name: "tonemap",
    files: &[wgsl!("exposure_result.wgsl"), wgsl!("tonemap.wgsl")],
};

/// The G-buffer reduced for indirect light at a lower resolution.
/// The tone-mapped frame as Y'CbCr 4:2:0 for the video encoder.
pub const YUV420: ShaderSource = ShaderSource {
    name: "yuv420",
    files: &[wgsl!("yuv420.wgsl")],
};

pub const GBUFFER_REDUCE: ShaderSource = ShaderSource {
    name: "gbuffer_reduce",
    files: &[wgsl!("gbuffer_reduce.wgsl")],
};

/// Reduced-resolution indirect light upsampled to the output's pixels.
pub const INDIRECT_UPSAMPLE: ShaderSource = ShaderSource {
    name: "indirect_upsample",
    files: &[wgsl!("common.wgsl"), wgsl!("indirect_upsample.wgsl")],
};

pub const RSM: ShaderSource = ShaderSource {
    name: "rsm",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("lights.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("materials.wgsl"),
        wgsl!("rsm.wgsl"),
    ],
};

pub const IMPORTANCE: ShaderSource = ShaderSource {
    name: "importance",
    files: &[
        wgsl!("halton.wgsl"),
        wgsl!("lightskin/view_samples.wgsl"),
        wgsl!("lightskin/importance.wgsl"),
    ],
};

pub const CUMULATIVE_SUMS: ShaderSource = ShaderSource {
    name: "cumulative_sums",
    files: &[wgsl!("lightskin/cumulative_sums.wgsl")],
};

pub const VAL_SELECT: ShaderSource = ShaderSource {
    name: "val_select",
    files: &[
        wgsl!("lightskin/vals.wgsl"),
        wgsl!("lightskin/val_select.wgsl"),
    ],
};

pub const CACHE_LIGHTING: ShaderSource = ShaderSource {
    name: "cache_lighting",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("lightskin/vals.wgsl"),
        wgsl!("lightskin/light_caches.wgsl"),
        wgsl!("lightskin/cache_lighting.wgsl"),
    ],
};

pub const INDIRECT_LIGHT: ShaderSource = ShaderSource {
    name: "indirect_light",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("lightskin/light_caches.wgsl"),
        wgsl!("lightskin/indirect_light.wgsl"),
    ],
};

pub const PROXY_OCCLUSION: ShaderSource = ShaderSource {
    name: "proxy_occlusion",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("lightskin/light_caches.wgsl"),
        wgsl!("lightskin/proxy_occlusion.wgsl"),
    ],
};

/// The reference path tracer (`gi::reference`).
pub const REFERENCE_PATH_TRACE: ShaderSource = ShaderSource {
    name: "reference_path_trace",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("lights.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("bvh.wgsl"),
        wgsl!("reference/surfaces.wgsl"),
        wgsl!("reference/path_trace.wgsl"),
    ],
};

/// The reference's accumulation into the indirect buffer, with its convergence sums.
pub const REFERENCE_RESOLVE: ShaderSource = ShaderSource {
    name: "reference_resolve",
    files: &[wgsl!("reference/resolve.wgsl")],
};

/// Nearest hits of a list of rays, to test the BVH traversal against the CPU.
pub const REFERENCE_BVH_TEST: ShaderSource = ShaderSource {
    name: "reference_bvh_test",
    files: &[wgsl!("bvh.wgsl"), wgsl!("bvh_test.wgsl")],
};

/// VPL generation and k-means clustering of `clustered` (`gi::clustered`).
pub const CLUSTERING: ShaderSource = ShaderSource {
    name: "clustering",
    files: &[
        wgsl!("halton.wgsl"),
        wgsl!("clustered/vpls.wgsl"),
        wgsl!("clustered/kmeans.wgsl"),
    ],
};

/// Interleaved shading from the VPLs of `clustered`.
pub const CLUSTERED_INDIRECT: ShaderSource = ShaderSource {
    name: "clustered_indirect",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("clustered/vpls.wgsl"),
        wgsl!("clustered/paraboloid.wgsl"),
        wgsl!("clustered/visibility.wgsl"),
        wgsl!("clustered/indirect.wgsl"),
    ],
};

/// `clustered`: one paraboloid depth map per VAL or VPL, all in one instanced draw.
pub const PARABOLOID_MAPS: ShaderSource = ShaderSource {
    name: "paraboloid_maps",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("clustered/vpls.wgsl"),
        wgsl!("clustered/paraboloid.wgsl"),
        wgsl!("clustered/paraboloid_maps.wgsl"),
    ],
};

/// `clustered`: the Fourier basis of the paraboloid depth maps.
pub const CSSM_BASIS: ShaderSource = ShaderSource {
    name: "cssm_basis",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("clustered/vpls.wgsl"),
        wgsl!("clustered/paraboloid.wgsl"),
        wgsl!("clustered/cssm_basis.wgsl"),
    ],
};

/// `clustered`: one mip level of the basis textures.
pub const CSSM_MIPS: ShaderSource = ShaderSource {
    name: "cssm_mips",
    files: &[wgsl!("clustered/cssm_mips.wgsl")],
};

/// The geometry-aware blur of `clustered`.
pub const GEOMETRY_BLUR: ShaderSource = ShaderSource {
    name: "geometry_blur",
    files: &[wgsl!("clustered/vpls.wgsl"), wgsl!("clustered/blur.wgsl")],
};

/// `surfels`: every surfel's radiosity from the light, emission and the previous bounce.
pub const SURFEL_LIGHT: ShaderSource = ShaderSource {
    name: "surfel_light",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("lights.wgsl"),
        wgsl!("surfels/sh.wgsl"),
        wgsl!("surfels/caches.wgsl"),
        wgsl!("surfels/surfel_light.wgsl"),
    ],
};

/// `surfels`: flux pulled up one level of the hierarchy.
pub const SURFEL_PULL: ShaderSource = ShaderSource {
    name: "surfel_pull",
    files: &[wgsl!("surfels/pull.wgsl")],
};

/// `surfels`: every cache's SH radiance over its links (eq. 4).
pub const SURFEL_CACHE_LIGHT: ShaderSource = ShaderSource {
    name: "surfel_cache_light",
    files: &[wgsl!("surfels/cache_light.wgsl")],
};

/// `surfels`: per-pixel indirect light from the caches (eq. 5–8).
pub const SURFEL_SHADE: ShaderSource = ShaderSource {
    name: "surfel_shade",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("surfels/sh.wgsl"),
        wgsl!("surfels/caches.wgsl"),
        wgsl!("surfels/shade.wgsl"),
    ],
};

/// `surfels`: debug view `cache-sh`, the caches' SH radiance along each pixel's normal.
pub const SURFEL_CACHE_SH_VIEW: ShaderSource = ShaderSource {
    name: "surfel_cache_sh_view",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("surfels/sh.wgsl"),
        wgsl!("surfels/caches.wgsl"),
        wgsl!("surfels/cache_sh_view.wgsl"),
    ],
};

/// Eq. 3's visibility rays of the surfels' links, from caches to surfels (precomputation).
pub const SURFEL_LINK_RAYS: ShaderSource = ShaderSource {
    name: "surfel_link_rays",
    files: &[wgsl!("bvh.wgsl"), wgsl!("surfels/link_rays.wgsl")],
};

/// Every pass module; tests validate each with naga.
pub const ALL: &[&ShaderSource] = &[
    &GBUFFER,
    &GBUFFER_TRIANGLE_IDS,
    &SHADOW_MAP,
    &DIRECT_LIGHT,
    &EXPOSURE,
    &TONEMAP,
    &YUV420,
    &GBUFFER_REDUCE,
    &INDIRECT_UPSAMPLE,
    &RSM,
    &IMPORTANCE,
    &CUMULATIVE_SUMS,
    &VAL_SELECT,
    &CACHE_LIGHTING,
    &INDIRECT_LIGHT,
    &PROXY_OCCLUSION,
    &REFERENCE_PATH_TRACE,
    &REFERENCE_RESOLVE,
    &REFERENCE_BVH_TEST,
    &CLUSTERING,
    &CLUSTERED_INDIRECT,
    &PARABOLOID_MAPS,
    &CSSM_BASIS,
    &CSSM_MIPS,
    &GEOMETRY_BLUR,
    &SURFEL_LIGHT,
    &SURFEL_PULL,
    &SURFEL_CACHE_LIGHT,
    &SURFEL_SHADE,
    &SURFEL_CACHE_SH_VIEW,
    &SURFEL_LINK_RAYS,
];

impl ShaderSource {
    pub fn source(&self) -> String {
        self.files
            .iter()
            .map(|(name, text)| format!("// ---- {name}\n{text}\n"))
            .collect()
    }

    pub fn create_module(&self, device: &wgpu::Device) -> wgpu::ShaderModule {
        device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(self.name),
            source: wgpu::ShaderSource::Wgsl(self.source().into()),
        })
    }
}

#[cfg(test)]
pub(crate) mod layout_check {
    //! Checks that a `#[repr(C)]` Rust struct matches naga's layout of its WGSL mirror.

    use super::ShaderSource;

    pub fn parse(source: &ShaderSource) -> naga::Module {
        naga::front::wgsl::parse_str(&source.source())
            .unwrap_or_else(|e| panic!("{}: {}", source.name, e.emit_to_string(&source.source())))
    }

    /// Asserts the WGSL struct `name` has size `size` and the given member offsets.
    pub fn assert_struct(
        source: &ShaderSource,
        name: &str,
        size: usize,
        members: &[(&str, usize)],
    ) {
        let module = parse(source);
        let mut layouter = naga::proc::Layouter::default();
        layouter
            .update(module.to_ctx())
            .expect("layout of a valid module");
        let (handle, ty) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("{}: no struct {name}", source.name));
        let naga::TypeInner::Struct {
            members: wgsl_members,
            span,
        } = &ty.inner
        else {
            panic!("{name} is not a struct");
        };
        assert_eq!(*span as usize, size, "{name}: WGSL size vs Rust size");
        assert_eq!(layouter[handle].size as usize, size);
        assert_eq!(wgsl_members.len(), members.len(), "{name}: member count");
        for (wgsl, (rust_name, rust_offset)) in wgsl_members.iter().zip(members) {
            assert_eq!(
                wgsl.name.as_deref(),
                Some(*rust_name),
                "{name}: member order"
            );
            assert_eq!(
                wgsl.offset as usize, *rust_offset,
                "{name}.{rust_name}: WGSL offset vs Rust offset"
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    #[test]
    fn every_pass_module_validates_with_naga() {
        for source in ALL {
            let module = layout_check::parse(source);
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::PRIMITIVE_INDEX,
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{}: {}", source.name, e.emit_to_string(&source.source())));
        }
    }

    #[test]
    fn no_pass_binds_a_uniform_buffer() {
        // lavapipe recompiles, and leaks, a shader variant per dispatch for uniform values
        // that steer control flow; parameters are bound as storage (`passes::PARAMS_BINDING`).
        for source in ALL {
            let module = layout_check::parse(source);
            let uniforms: Vec<_> = module
                .global_variables
                .iter()
                .filter(|(_, v)| v.space == naga::AddressSpace::Uniform)
                .map(|(_, v)| v.name.clone().unwrap_or_default())
                .collect();
            assert!(
                uniforms.is_empty(),
                "{}: var<uniform> {uniforms:?}; use var<storage, read>",
                source.name
            );
        }
    }

    #[test]
    fn every_pass_binds_what_its_wgsl_declares() {
        // Test-only imports upwards: the passes own their bind-group descriptions.
        use crate::gi::clustered::passes as clustered;
        use crate::gi::lightskin::{
            cache_lighting, cumulative_sums, importance, indirect_light, proxy_occlusion,
            val_select,
        };
        use crate::gi::reference::{self, resolve};
        use crate::gi::surfels::{link_rays, passes as surfels};
        use crate::passes::bind::{wgsl_mismatches, BindGroupDesc};
        use crate::passes::{
            direct_light, exposure, gbuffer, indirect_resolution, rsm, scene_buffers, shadow_map,
            tonemap, yuv420,
        };
        // Each module with its pipeline's bind groups, group i at index i.
        let passes: &[(&ShaderSource, &[&BindGroupDesc])] = &[
            (
                &GBUFFER,
                &[&gbuffer::CAMERA_GROUP, &scene_buffers::MATERIAL_GROUP],
            ),
            (
                &GBUFFER_TRIANGLE_IDS,
                &[&gbuffer::CAMERA_GROUP, &scene_buffers::MATERIAL_GROUP],
            ),
            (
                &SHADOW_MAP,
                &[&shadow_map::GROUP, &scene_buffers::MATERIAL_GROUP],
            ),
            (&DIRECT_LIGHT, &[&direct_light::GROUP]),
            (&EXPOSURE, &[&exposure::GROUP]),
            (&TONEMAP, &[&tonemap::GROUP]),
            (&YUV420, &[&yuv420::GROUP]),
            (&GBUFFER_REDUCE, &[&indirect_resolution::REDUCE_GROUP]),
            (&INDIRECT_UPSAMPLE, &[&indirect_resolution::UPSAMPLE_GROUP]),
            (&RSM, &[&rsm::GROUP, &scene_buffers::MATERIAL_GROUP]),
            (&IMPORTANCE, &[&importance::GROUP]),
            (&CUMULATIVE_SUMS, &[&cumulative_sums::GROUP]),
            (&VAL_SELECT, &[&val_select::GROUP]),
            (&CACHE_LIGHTING, &[&cache_lighting::GROUP]),
            (&INDIRECT_LIGHT, &[&indirect_light::GROUP]),
            (&PROXY_OCCLUSION, &[&proxy_occlusion::GROUP]),
            (
                &REFERENCE_PATH_TRACE,
                &[&reference::PASS_GROUP, &reference::SCENE_GROUP],
            ),
            (&REFERENCE_RESOLVE, &[&resolve::GROUP]),
            (&CLUSTERING, &[&clustered::CLUSTERING_GROUP]),
            (&CLUSTERED_INDIRECT, &[&clustered::INDIRECT_GROUP]),
            (&PARABOLOID_MAPS, &[&clustered::MAPS_GROUP]),
            (&CSSM_BASIS, &[&clustered::BASIS_GROUP]),
            (&CSSM_MIPS, &[&clustered::MIPS_GROUP]),
            (&GEOMETRY_BLUR, &[&clustered::BLUR_GROUP]),
            (&SURFEL_LIGHT, &[&surfels::LIGHT_GROUP]),
            (&SURFEL_PULL, &[&surfels::PULL_GROUP]),
            (&SURFEL_CACHE_LIGHT, &[&surfels::CACHE_LIGHT_GROUP]),
            (&SURFEL_SHADE, &[&surfels::SHADE_GROUP]),
            (&SURFEL_CACHE_SH_VIEW, &[&surfels::SH_VIEW_GROUP]),
            (
                &SURFEL_LINK_RAYS,
                &[&link_rays::RAY_GROUP, &link_rays::BVH_GROUP],
            ),
        ];
        let errors: Vec<String> = passes
            .iter()
            .flat_map(|(source, groups)| {
                wgsl_mismatches(source, groups)
                    .into_iter()
                    .map(|e| format!("{}: {e}", source.name))
            })
            .collect();
        assert!(errors.is_empty(), "{}", errors.join("\n"));
        // Every module a pass runs is checked; the BVH test module's pipeline (an
        // integration-test harness) takes its layout from the WGSL itself.
        let checked: BTreeSet<&str> = passes.iter().map(|(s, _)| s.name).collect();
        let all: BTreeSet<&str> = ALL
            .iter()
            .map(|s| s.name)
            .filter(|&n| n != REFERENCE_BVH_TEST.name)
            .collect();
        assert_eq!(
            checked, all,
            "a pass module without bind-group descriptions"
        );
    }

    #[test]
    fn every_file_in_shaders_dir_belongs_to_a_pass() {
        let root = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../shaders"));
        // shaders/ and one level of method folders (shaders/<method>/).
        let mut on_disk = BTreeSet::new();
        let mut dirs = vec![root.to_path_buf()];
        while let Some(dir) = dirs.pop() {
            for entry in std::fs::read_dir(&dir).expect("shaders/ exists") {
                let path = entry.expect("dir entry").path();
                if path.is_dir() {
                    dirs.push(path);
                } else if path.extension().is_some_and(|e| e == "wgsl") {
                    let relative = path.strip_prefix(root).expect("under shaders/");
                    on_disk.insert(relative.to_string_lossy().into_owned());
                }
            }
        }
        let used: BTreeSet<String> = ALL
            .iter()
            .flat_map(|s| s.files.iter().map(|(n, _)| n.to_string()))
            .collect();
        assert_eq!(
            on_disk, used,
            "every WGSL file must be part of a validated pass"
        );
    }
}
