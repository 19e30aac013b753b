//! Bind groups declared once. `bind_group!` declares a group's bindings in binding order
//! under their WGSL variable names and produces both halves from that one list: a
//! [`BindGroupDesc`] constant, which makes the layout, and a struct with one field per
//! binding, whose `bind` makes the bind group. Binding numbers are never written in Rust, and a
//! missing, extra or misnamed resource does not compile. A test over every pass
//! (`gi::shader_tests`, through [`super::ShaderPass`]) checks its descriptions against naga's
//! reflection of its WGSL (`wgsl_mismatches`).
//!
//! ```ignore
//! bind_group! {
//!     /// Group 0 of `shaders/tonemap.wgsl`.
//!     pub struct Resources as GROUP("tonemap", wgpu::ShaderStages::COMPUTE) {
//!         hdr: bind::TEXTURE,
//!         exposure: bind::STORAGE,
//!         ldr_out: bind::storage_texture(LDR_FORMAT),
//!     }
//! }
//! let layout = GROUP.layout(device);
//! let group = Resources { hdr: &hdr.view, exposure, ldr_out: &ldr.view }.bind(device, &layout);
//! ```

use super::{ParamSlots, Target, PARAMS_BINDING};

/// One binding: its WGSL variable name and what it binds. Its index is its position in
/// [`BindGroupDesc::entries`].
#[derive(Clone, Copy, Debug)]
pub struct Bind {
    pub name: &'static str,
    pub kind: BindKind,
}

/// What a binding binds, as its layout entry needs it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BindKind {
    /// A parameter struct written by the queue: a read-only storage buffer, never a uniform
    /// buffer (see [`PARAMS_BINDING`]).
    Params,
    /// One `size`-byte slot of a [`ParamSlots`], picked by a dynamic offset.
    ParamSlot {
        size: u64,
    },
    /// A storage buffer (`var<storage, read>` or `var<storage, read_write>`).
    Storage {
        read_only: bool,
    },
    /// A sampled texture (`texture_2d<f32>`, `texture_depth_2d_array`, …).
    Texture {
        sample_type: wgpu::TextureSampleType,
        dimension: wgpu::TextureViewDimension,
    },
    /// A write-only 2D storage texture (`texture_storage_2d<format, write>`).
    StorageTexture {
        format: wgpu::TextureFormat,
    },
    Sampler(wgpu::SamplerBindingType),
}

pub const PARAMS: BindKind = BindKind::Params;
/// `var<storage, read>` data.
pub const STORAGE: BindKind = BindKind::Storage { read_only: true };
/// `var<storage, read_write>`.
pub const STORAGE_RW: BindKind = BindKind::Storage { read_only: false };
/// A `texture_2d<f32>` read with `textureLoad` (not filterable: 32-bit float formats too).
pub const TEXTURE: BindKind = BindKind::Texture {
    sample_type: wgpu::TextureSampleType::Float { filterable: false },
    dimension: wgpu::TextureViewDimension::D2,
};

/// A `texture_2d<u32>` read with `textureLoad`.
pub const UINT_TEXTURE: BindKind = BindKind::Texture {
    sample_type: wgpu::TextureSampleType::Uint,
    dimension: wgpu::TextureViewDimension::D2,
};

/// A slot of a [`ParamSlots`] holding one `T`.
pub const fn param_slot<T>() -> BindKind {
    BindKind::ParamSlot {
        size: std::mem::size_of::<T>() as u64,
    }
}

pub const fn storage_texture(format: wgpu::TextureFormat) -> BindKind {
    BindKind::StorageTexture { format }
}

impl BindKind {
    fn binding_type(self) -> wgpu::BindingType {
        let buffer = |ty, has_dynamic_offset, min_binding_size| wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset,
            min_binding_size,
        };
        match self {
            Self::Params => buffer(PARAMS_BINDING, false, None),
            Self::ParamSlot { size } => buffer(PARAMS_BINDING, true, wgpu::BufferSize::new(size)),
            Self::Storage { read_only } => {
                buffer(wgpu::BufferBindingType::Storage { read_only }, false, None)
            }
            Self::Texture {
                sample_type,
                dimension,
            } => wgpu::BindingType::Texture {
                sample_type,
                view_dimension: dimension,
                multisampled: false,
            },
            Self::StorageTexture { format } => wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
            Self::Sampler(ty) => wgpu::BindingType::Sampler(ty),
        }
    }

    /// Whether `resource` is what this kind binds (wgpu would reject it later, with binding
    /// numbers instead of names).
    fn accepts(self, resource: &wgpu::BindingResource) -> bool {
        match (self, resource) {
            (Self::ParamSlot { size }, wgpu::BindingResource::Buffer(b)) => {
                b.size == wgpu::BufferSize::new(size)
            }
            (Self::Params | Self::Storage { .. }, wgpu::BindingResource::Buffer(_)) => true,
            (
                Self::Texture { .. } | Self::StorageTexture { .. },
                wgpu::BindingResource::TextureView(_),
            ) => true,
            (Self::Sampler(_), wgpu::BindingResource::Sampler(_)) => true,
            _ => false,
        }
    }
}

/// One bind group: the stages that see it and its bindings in binding order.
#[derive(Clone, Copy, Debug)]
pub struct BindGroupDesc {
    pub label: &'static str,
    pub visibility: wgpu::ShaderStages,
    pub entries: &'static [Bind],
}

impl BindGroupDesc {
    pub fn layout(&self, device: &wgpu::Device) -> wgpu::BindGroupLayout {
        let entries: Vec<wgpu::BindGroupLayoutEntry> = (0..)
            .zip(self.entries)
            .map(|(binding, entry)| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: self.visibility,
                ty: entry.kind.binding_type(),
                count: None,
            })
            .collect();
        device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(self.label),
            entries: &entries,
        })
    }

    /// A bind group of `layout` (made by [`Self::layout`]) with `resources` in binding order.
    /// Called by the structs `bind_group!` declares, which get the order right.
    pub fn bind(
        &self,
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
        resources: &[&dyn Resource],
    ) -> wgpu::BindGroup {
        assert_eq!(
            resources.len(),
            self.entries.len(),
            "{}: one resource per binding",
            self.label
        );
        let entries: Vec<wgpu::BindGroupEntry> = (0..)
            .zip(self.entries.iter().zip(resources))
            .map(|(binding, (entry, resource))| {
                let resource = resource.resource();
                assert!(
                    entry.kind.accepts(&resource),
                    "{}: {} is bound to {resource:?}, not a {:?}",
                    self.label,
                    entry.name,
                    entry.kind
                );
                wgpu::BindGroupEntry { binding, resource }
            })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.label),
            layout,
            entries: &entries,
        })
    }
}

/// Something a binding can be bound to.
pub trait Resource {
    fn resource(&self) -> wgpu::BindingResource<'_>;
}

impl Resource for wgpu::Buffer {
    fn resource(&self) -> wgpu::BindingResource<'_> {
        self.as_entire_binding()
    }
}

impl Resource for wgpu::TextureView {
    fn resource(&self) -> wgpu::BindingResource<'_> {
        wgpu::BindingResource::TextureView(self)
    }
}

impl Resource for Target {
    fn resource(&self) -> wgpu::BindingResource<'_> {
        self.view.resource()
    }
}

impl Resource for wgpu::Sampler {
    fn resource(&self) -> wgpu::BindingResource<'_> {
        wgpu::BindingResource::Sampler(self)
    }
}

/// One slot; the dynamic offset picks which.
impl Resource for ParamSlots {
    fn resource(&self) -> wgpu::BindingResource<'_> {
        wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer: &self.buffer,
            offset: 0,
            size: wgpu::BufferSize::new(self.slot_size),
        })
    }
}

/// Declares a bind group once: `$desc`, its [`BindGroupDesc`] (bindings numbered in the
/// order written), and `$resources`, a struct with one `&dyn Resource` field per binding
/// whose `bind` makes the bind group. Field names are the WGSL variable names.
#[macro_export]
macro_rules! bind_group {
    (
        $(#[$doc:meta])*
        $vis:vis struct $resources:ident as $desc:ident($label:literal, $stages:expr) {
            $($name:ident: $kind:expr),+ $(,)?
        }
    ) => {
        $(#[$doc])*
        $vis const $desc: $crate::passes::bind::BindGroupDesc =
            $crate::passes::bind::BindGroupDesc {
                label: $label,
                visibility: $stages,
                entries: &[$($crate::passes::bind::Bind {
                    name: stringify!($name),
                    kind: $kind,
                }),+],
            };

        #[doc = concat!("What [`", stringify!($desc), "`] binds, by WGSL name.")]
        $vis struct $resources<'a> {
            $(pub $name: &'a dyn $crate::passes::bind::Resource,)+
        }

        impl $resources<'_> {
            #[doc = concat!("A bind group of `layout`, made by [`", stringify!($desc), "`].")]
            $vis fn bind(
                &self,
                device: &wgpu::Device,
                layout: &wgpu::BindGroupLayout,
            ) -> wgpu::BindGroup {
                $desc.bind(device, layout, &[$(self.$name),+])
            }
        }
    };
}
pub use crate::bind_group;

/// How the bind groups `groups` (group `i` is `groups[i]`) disagree with the WGSL of `source`:
/// every global with `@group(g) @binding(b)` must be entry `b` of group `g` with the same name
/// and a compatible kind, and every entry must be declared in the WGSL.
// Not `cfg(test)`: the GI methods' tests (another crate) check their passes with it.
pub fn wgsl_mismatches(
    source: &crate::gpu::shaders::ShaderSource,
    groups: &[&BindGroupDesc],
) -> Vec<String> {
    let module = crate::gpu::shaders::layout_check::parse(source);
    let mut layouter = naga::proc::Layouter::default();
    layouter
        .update(module.to_ctx())
        .expect("layout of a valid module");
    let mut errors = Vec::new();
    let mut declared = std::collections::BTreeSet::new();
    for (_, var) in module.global_variables.iter() {
        let Some(naga::ResourceBinding { group, binding }) = var.binding else {
            continue;
        };
        declared.insert((group, binding));
        let name = var.name.as_deref().unwrap_or("?");
        let Some(entry) = groups
            .get(group as usize)
            .and_then(|g| g.entries.get(binding as usize))
        else {
            errors.push(format!(
                "@group({group}) @binding({binding}) {name} is not in the pass's bind groups"
            ));
            continue;
        };
        if entry.name != name {
            errors.push(format!(
                "@group({group}) @binding({binding}) is {name} in WGSL, {} in Rust",
                entry.name
            ));
        }
        if let Err(wgsl) = compatible(entry.kind, var, &module, &layouter) {
            errors.push(format!(
                "@group({group}) @binding({binding}) {name}: {:?} in Rust, {wgsl} in WGSL",
                entry.kind
            ));
        }
    }
    for (group, desc) in (0..).zip(groups) {
        for (binding, entry) in (0..).zip(desc.entries) {
            if !declared.contains(&(group, binding)) {
                errors.push(format!(
                    "{} ({}, binding {binding} of group {group}) is not declared in WGSL",
                    entry.name, desc.label
                ));
            }
        }
    }
    errors
}

/// `Err` with the WGSL side when `var` cannot be bound as `kind`.
fn compatible(
    kind: BindKind,
    var: &naga::GlobalVariable,
    module: &naga::Module,
    layouter: &naga::proc::Layouter,
) -> Result<(), String> {
    use naga::{AddressSpace, ImageClass, ImageDimension, ScalarKind, StorageAccess, TypeInner};
    let inner = &module.types[var.ty].inner;
    let ok = match (kind, var.space, inner) {
        (BindKind::Storage { read_only: false }, AddressSpace::Storage { access }, _) => {
            access.contains(StorageAccess::STORE)
        }
        (BindKind::Params | BindKind::Storage { .. }, AddressSpace::Storage { access }, _) => {
            !access.contains(StorageAccess::STORE)
        }
        (BindKind::ParamSlot { size }, AddressSpace::Storage { access }, _) => {
            !access.contains(StorageAccess::STORE) && u64::from(layouter[var.ty].size) == size
        }
        (
            BindKind::Texture {
                sample_type,
                dimension,
            },
            AddressSpace::Handle,
            TypeInner::Image {
                dim,
                arrayed,
                class,
            },
        ) => {
            let sample_type_ok = match (sample_type, class) {
                (wgpu::TextureSampleType::Depth, ImageClass::Depth { multi: false }) => true,
                (sample_type, ImageClass::Sampled { kind, multi: false }) => matches!(
                    (sample_type, kind),
                    (wgpu::TextureSampleType::Float { .. }, ScalarKind::Float)
                        | (wgpu::TextureSampleType::Uint, ScalarKind::Uint)
                        | (wgpu::TextureSampleType::Sint, ScalarKind::Sint)
                ),
                _ => false,
            };
            let dimension_ok = match dimension {
                wgpu::TextureViewDimension::D1 => (*dim, *arrayed) == (ImageDimension::D1, false),
                wgpu::TextureViewDimension::D2 => (*dim, *arrayed) == (ImageDimension::D2, false),
                wgpu::TextureViewDimension::D2Array => {
                    (*dim, *arrayed) == (ImageDimension::D2, true)
                }
                wgpu::TextureViewDimension::Cube => {
                    (*dim, *arrayed) == (ImageDimension::Cube, false)
                }
                wgpu::TextureViewDimension::CubeArray => {
                    (*dim, *arrayed) == (ImageDimension::Cube, true)
                }
                wgpu::TextureViewDimension::D3 => (*dim, *arrayed) == (ImageDimension::D3, false),
            };
            sample_type_ok && dimension_ok
        }
        (
            BindKind::StorageTexture { format },
            AddressSpace::Handle,
            TypeInner::Image {
                dim: ImageDimension::D2,
                arrayed: false,
                class:
                    ImageClass::Storage {
                        format: wgsl,
                        access,
                    },
            },
        ) => {
            // naga's and wgpu's format enums spell the WGSL formats alike.
            format!("{wgsl:?}") == format!("{format:?}") && *access == StorageAccess::STORE
        }
        (BindKind::Sampler(ty), AddressSpace::Handle, TypeInner::Sampler { comparison }) => {
            *comparison == (ty == wgpu::SamplerBindingType::Comparison)
        }
        _ => false,
    };
    if ok {
        Ok(())
    } else {
        Err(format!("{:?} {inner:?}", var.space))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shaders::TONEMAP;

    /// `shaders/tonemap.wgsl`'s group 0 with `entries`.
    fn tonemap<const N: usize>(entries: [Bind; N]) -> Vec<String> {
        let desc = BindGroupDesc {
            entries: Box::leak(Box::new(entries)),
            ..crate::passes::tonemap::GROUP
        };
        wgsl_mismatches(&TONEMAP, &[&desc])
    }

    const fn bind(name: &'static str, kind: BindKind) -> Bind {
        Bind { name, kind }
    }

    #[test]
    fn the_check_accepts_a_matching_description() {
        assert_eq!(
            wgsl_mismatches(&TONEMAP, &[&crate::passes::tonemap::GROUP]),
            Vec::<String>::new()
        );
    }

    #[test]
    fn the_check_reports_every_kind_of_mismatch() {
        let ldr = storage_texture(crate::passes::tonemap::LDR_FORMAT);
        // Two bindings swapped.
        let swapped = tonemap([
            bind("exposure", STORAGE),
            bind("hdr", TEXTURE),
            bind("ldr_out", ldr),
        ]);
        assert_eq!(swapped.len(), 4, "{swapped:?}");
        // A misspelt name.
        assert_eq!(
            tonemap([
                bind("hdr", TEXTURE),
                bind("exposur", STORAGE),
                bind("ldr_out", ldr)
            ])
            .len(),
            1
        );
        // read_write vs read, a wrong storage format, a wrong sample type.
        for wrong in [
            [
                bind("hdr", TEXTURE),
                bind("exposure", STORAGE_RW),
                bind("ldr_out", ldr),
            ],
            [
                bind("hdr", TEXTURE),
                bind("exposure", STORAGE),
                bind("ldr_out", storage_texture(wgpu::TextureFormat::Rgba16Float)),
            ],
            [
                bind(
                    "hdr",
                    BindKind::Texture {
                        sample_type: wgpu::TextureSampleType::Uint,
                        dimension: wgpu::TextureViewDimension::D2,
                    },
                ),
                bind("exposure", STORAGE),
                bind("ldr_out", ldr),
            ],
            [
                bind("hdr", TEXTURE),
                bind("exposure", param_slot::<[f32; 8]>()),
                bind("ldr_out", ldr),
            ],
        ] {
            let errors = tonemap(wrong);
            assert_eq!(errors.len(), 1, "{wrong:?}: {errors:?}");
        }
        // A binding missing, and one the WGSL does not declare.
        assert_eq!(
            tonemap([bind("hdr", TEXTURE), bind("exposure", STORAGE)]).len(),
            1
        );
        assert_eq!(
            tonemap([
                bind("hdr", TEXTURE),
                bind("exposure", STORAGE),
                bind("ldr_out", ldr),
                bind("extra", STORAGE),
            ])
            .len(),
            1
        );
        // A group the pass does not describe.
        assert_eq!(wgsl_mismatches(&TONEMAP, &[]).len(), 3);
    }
}
