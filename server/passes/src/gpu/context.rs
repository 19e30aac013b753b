//! Picks an adapter and opens a device with the features the pipeline can use.

use std::fmt;

/// Which wgpu backend to open. `Auto` lets wgpu choose among the primary backends (Vulkan,
/// Metal, DX12).
///
/// `Gl` is accepted only to refuse it with a reason: on wgpu's GL backend every frame failed
/// ("Tried to wait using a submission index … that has not been returned by a successful
/// submission"), and the pipeline relies on compute shaders and storage buffers that GL
/// drivers often lack. It is hidden from `--help` and the docs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    #[default]
    Auto,
    Vulkan,
    #[value(hide = true)]
    Gl,
}

impl BackendChoice {
    fn backends(self) -> wgpu::Backends {
        match self {
            Self::Auto => wgpu::Backends::PRIMARY,
            Self::Vulkan => wgpu::Backends::VULKAN,
            Self::Gl => wgpu::Backends::GL,
        }
    }
}

/// Switches off Mesa's Vulkan device-select layer on a machine without a display. The layer
/// asks Wayland and X for the default GPU; with neither, libwayland prints "error:
/// XDG_RUNTIME_DIR is invalid or not set in the environment." at every instance, which reads
/// like a failure in the server's first log lines. wgpu picks the adapter itself (high
/// performance first), so nothing is lost; a user who steers the layer
/// (`MESA_VK_DEVICE_SELECT`, `NODEVICE_SELECT`) or has a display keeps it. It sets an
/// environment variable: call it before any other thread starts.
pub fn quiet_headless_device_select() {
    const DISPLAY_OR_CHOICE: &[&str] = &[
        "XDG_RUNTIME_DIR",
        "WAYLAND_DISPLAY",
        "DISPLAY",
        "MESA_VK_DEVICE_SELECT",
        "NODEVICE_SELECT",
    ];
    if DISPLAY_OR_CHOICE
        .iter()
        .all(|name| std::env::var_os(name).is_none())
    {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
}

/// Where Debian and Ubuntu install lavapipe's ICD file (one per architecture).
const LAVAPIPE_ICD_DIRS: &[&str] = &["/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d"];

/// Lavapipe's ICD file, when it is installed.
pub fn lavapipe_icd() -> Option<std::path::PathBuf> {
    LAVAPIPE_ICD_DIRS
        .iter()
        .filter_map(|dir| std::fs::read_dir(dir).ok())
        .flatten()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("lvp_icd") && n.ends_with(".json"))
        })
}

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter found for backend {backend:?}: {error} (on a machine without a GPU install a software Vulkan driver, e.g. `apt-get install mesa-vulkan-drivers libvulkan1`)")]
    NoAdapter {
        backend: BackendChoice,
        error: wgpu::RequestAdapterError,
    },
    #[error("the OpenGL backend is not supported: wgpu's GL backend fails every frame and lacks what the GI passes need; use `--backend vulkan` (or `auto`), with Mesa's lavapipe (`apt-get install mesa-vulkan-drivers`) on machines without a Vulkan GPU")]
    GlUnsupported,
    #[error("adapter {adapter} refused to open a device: {error}")]
    RequestDevice {
        adapter: String,
        error: wgpu::RequestDeviceError,
    },
    #[error(
        "adapter {adapter} lacks compute shaders (wgpu downlevel flags); use a Vulkan adapter"
    )]
    NoCompute { adapter: String },
    #[error("out of GPU memory allocating {what}: {message}")]
    OutOfMemory { what: String, message: String },
    #[error("waiting for the GPU failed: {0}")]
    Poll(wgpu::PollError),
    #[error("mapping a readback buffer failed: {0}")]
    Map(String),
}

impl From<wgpu::PollError> for GpuError {
    fn from(error: wgpu::PollError) -> Self {
        Self::Poll(error)
    }
}

/// The adapter, device and queue, plus what the pipeline learned about them. Clones share the
/// same device.
#[derive(Clone)]
pub struct GpuContext {
    /// Kept for [`GpuContext::resource_counts`]: wgpu's report of live objects is per instance.
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    /// True when timestamps can be written between passes on an encoder (per-pass GPU times).
    pub timestamps: bool,
    /// True when fragment shaders can read primitive indices, so the G-buffer can store
    /// triangle ids and indirect light blends the light caches of a triangle's three vertices.
    /// Set it to false before creating a renderer to use provoking vertices instead.
    pub primitive_index: bool,
}

/// Human-readable adapter description (name, type, backend, driver).
pub struct AdapterSummary<'a>(pub &'a wgpu::AdapterInfo);

impl fmt::Display for AdapterSummary<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let i = self.0;
        write!(
            f,
            "{} ({:?}, {:?}, driver {} {})",
            i.name, i.device_type, i.backend, i.driver, i.driver_info
        )
    }
}

impl GpuContext {
    /// Opens the preferred (high-performance) adapter for `backend`; with `Auto`, a
    /// `WGPU_BACKEND` in the environment names the backends to try (wgpu's convention).
    pub fn new(backend: BackendChoice) -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async(backend))
    }

    async fn new_async(backend: BackendChoice) -> Result<Self, GpuError> {
        // WGPU_BACKEND, when set, overrides `Auto` (wgpu's own convention).
        let backends = wgpu::Backends::from_env()
            .filter(|_| backend == BackendChoice::Auto)
            .unwrap_or(backend.backends());
        if backends.contains(wgpu::Backends::GL) {
            return Err(GpuError::GlUnsupported);
        }
        let (instance, adapter) = match request_adapter(backends).await {
            Ok(found) => found,
            Err(error) => {
                match lavapipe_icd().filter(|_| backends.contains(wgpu::Backends::VULKAN)) {
                    // A Vulkan ICD is installed but opens no adapter (a driver without its GPU,
                    // a broken install): the CPU driver still renders, slowly, which beats not
                    // starting. Only the Vulkan loader reads these variables, when the instance
                    // is created below; nothing else in the process is running yet.
                    Some(icd) => {
                        tracing::warn!(
                        "no adapter opened with the installed drivers ({error}); falling back to lavapipe ({})",
                        icd.display()
                    );
                        std::env::set_var("VK_DRIVER_FILES", &icd);
                        std::env::set_var("VK_ICD_FILENAMES", &icd);
                        request_adapter(wgpu::Backends::VULKAN)
                            .await
                            .map_err(|error| GpuError::NoAdapter { backend, error })?
                    }
                    None => return Err(GpuError::NoAdapter { backend, error }),
                }
            }
        };
        let info = adapter.get_info();
        let name = AdapterSummary(&info).to_string();
        if !adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
        {
            return Err(GpuError::NoCompute { adapter: name });
        }
        let timestamp_features =
            wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
        let timestamps = adapter.features().contains(timestamp_features);
        let primitive_index = adapter.features().contains(wgpu::Features::PRIMITIVE_INDEX);
        let mut required_features = wgpu::Features::empty();
        if timestamps {
            required_features |= timestamp_features;
        }
        if primitive_index {
            required_features |= wgpu::Features::PRIMITIVE_INDEX;
        }
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("lightcast"),
                required_features,
                required_limits: adapter.limits(),
                experimental_features: wgpu::ExperimentalFeatures::disabled(),
                memory_hints: wgpu::MemoryHints::Performance,
                trace: wgpu::Trace::Off,
            })
            .await
            .map_err(|error| GpuError::RequestDevice {
                adapter: name,
                error,
            })?;
        Ok(Self {
            instance,
            adapter,
            device,
            queue,
            info,
            timestamps,
            primitive_index,
        })
    }

    /// Blocks until `submission` has finished (every submission when `None`), and runs the
    /// callbacks of buffers mapped for it.
    pub fn wait_for(&self, submission: Option<&wgpu::SubmissionIndex>) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::Wait {
            submission_index: submission.cloned(),
            timeout: None,
        })?;
        Ok(())
    }

    /// Blocks until all submitted work has finished.
    pub fn wait_idle(&self) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        Ok(())
    }
}

/// The preferred (high-performance) adapter among `backends`, with its instance.
async fn request_adapter(
    backends: wgpu::Backends,
) -> Result<(wgpu::Instance, wgpu::Adapter), wgpu::RequestAdapterError> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    desc.backends = backends;
    let instance = wgpu::Instance::new(desc);
    let adapter = instance
        .request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            apply_limit_buckets: false,
        })
        .await?;
    Ok((instance, adapter))
}

/// Live GPU objects, from wgpu's own registry (what a leak of GPU resources would grow).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ResourceCounts {
    pub buffers: usize,
    pub textures: usize,
    pub bind_groups: usize,
}

/// Counts of `instance`'s live objects; `None` where wgpu keeps no report (web backends).
pub fn resource_counts(instance: &wgpu::Instance) -> Option<ResourceCounts> {
    let report = instance.generate_report()?;
    let hub = report.hub_report();
    Some(ResourceCounts {
        buffers: hub.buffers.num_allocated,
        textures: hub.textures.num_allocated,
        bind_groups: hub.bind_groups.num_allocated,
    })
}
