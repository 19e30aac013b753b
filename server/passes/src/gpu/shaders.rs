//! WGSL sources. Each pass is one file in `shaders/`, prefixed by the shared snippets it uses
//! (WGSL has no includes, so a pass module is the concatenation of its files). The shared
//! passes' modules are here; a GI method's are in its folder (`gi/<method>/shaders.rs`).

/// The files one pass module is made of, in order.
pub struct ShaderSource {
    pub name: &'static str,
    pub files: &'static [(&'static str, &'static str)],
}

/// `("path", its text)` of a file under `shaders/`, for a [`ShaderSource`]'s `files` (in
/// every crate under `server/`, each two levels below the repository's root).
#[macro_export]
macro_rules! wgsl {
    ($file:literal) => {
        (
            $file,
            include_str!(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../../shaders/",
                $file
            )),
        )
    };
}
pub use crate::wgsl;

/// The G-buffer writing provoking-vertex ids (adapters without primitive indices).
pub const GBUFFER: ShaderSource = ShaderSource {
    name: "gbuffer",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("materials.wgsl"),
        wgsl!("gbuffer_vertex.wgsl"),
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
        wgsl!("gbuffer_vertex.wgsl"),
        wgsl!("gbuffer.wgsl"),
        wgsl!("gbuffer_triangle_ids.wgsl"),
    ],
};

/// The thin G-buffer raster: a visibility buffer of triangle ids and base colours (needs
/// `Features::PRIMITIVE_INDEX`), resolved by [`GBUFFER_RESOLVE`].
pub const GBUFFER_VISIBILITY: ShaderSource = ShaderSource {
    name: "gbuffer_visibility",
    files: &[
        wgsl!("enable_primitive_index.wgsl"),
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("materials.wgsl"),
        wgsl!("gbuffer_vertex.wgsl"),
        wgsl!("visibility_out.wgsl"),
        wgsl!("gbuffer_visibility.wgsl"),
    ],
};

/// The visibility buffer resolved into the G-buffer's targets.
pub const GBUFFER_RESOLVE: ShaderSource = ShaderSource {
    name: "gbuffer_resolve",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("visible_point.wgsl"),
        wgsl!("gbuffer_resolve.wgsl"),
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
        wgsl!("brdf_eval.wgsl"),
        wgsl!("gbuffer_surface.wgsl"),
        wgsl!("lights.wgsl"),
        wgsl!("environment.wgsl"),
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

/// The RSM rasterising every target.
pub const RSM: ShaderSource = ShaderSource {
    name: "rsm",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("brdf_eval.wgsl"),
        wgsl!("lights.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("materials.wgsl"),
        wgsl!("octahedral.wgsl"),
        wgsl!("rsm_glossy.wgsl"),
        wgsl!("rsm_texel.wgsl"),
        wgsl!("rsm_vertex.wgsl"),
        wgsl!("rsm.wgsl"),
    ],
};

/// The thin RSM raster: a visibility buffer of triangle ids and base colours (needs
/// `Features::PRIMITIVE_INDEX`), resolved by [`RSM_RESOLVE`].
pub const RSM_VISIBILITY: ShaderSource = ShaderSource {
    name: "rsm_visibility",
    files: &[
        wgsl!("enable_primitive_index.wgsl"),
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("brdf_eval.wgsl"),
        wgsl!("lights.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("materials.wgsl"),
        wgsl!("octahedral.wgsl"),
        wgsl!("rsm_glossy.wgsl"),
        wgsl!("rsm_texel.wgsl"),
        wgsl!("rsm_vertex.wgsl"),
        wgsl!("visibility_out.wgsl"),
        wgsl!("rsm_visibility.wgsl"),
    ],
};

/// The RSM's visibility buffer resolved into its targets.
pub const RSM_RESOLVE: ShaderSource = ShaderSource {
    name: "rsm_resolve",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("brdf_eval.wgsl"),
        wgsl!("lights.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("octahedral.wgsl"),
        wgsl!("rsm_glossy.wgsl"),
        wgsl!("rsm_texel.wgsl"),
        wgsl!("visible_point.wgsl"),
        wgsl!("rsm_resolve.wgsl"),
    ],
};

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

pub mod layout_check {
    //! Checks that a `#[repr(C)]` Rust struct matches naga's layout of its WGSL mirror: for
    //! the tests of this crate and of the GI methods' (not `cfg(test)`: another crate's tests
    //! cannot see this crate's test-only items).

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
