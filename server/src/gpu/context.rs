//! Picks an adapter and opens a device with the features the pipeline can use.

use std::fmt;

/// Which wgpu backend to open. `Auto` lets wgpu choose (Vulkan where present).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    #[default]
    Auto,
    Vulkan,
    Gl,
}

impl BackendChoice {
    /// Backends to try, in order. `Auto` tries Vulkan before GL: probing GL first only adds
    /// EGL noise on headless machines, and GL on some drivers lacks compute.
    fn attempts(self) -> &'static [wgpu::Backends] {
        match self {
            Self::Auto => &[wgpu::Backends::VULKAN, wgpu::Backends::GL],
            Self::Vulkan => &[wgpu::Backends::VULKAN],
            Self::Gl => &[wgpu::Backends::GL],
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter found for backend {backend:?}: {error} (on a machine without a GPU install a software Vulkan driver, e.g. `apt-get install mesa-vulkan-drivers libvulkan1`)")]
    NoAdapter {
        backend: BackendChoice,
        error: wgpu::RequestAdapterError,
    },
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
        let options = wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            apply_limit_buckets: false,
        };
        // WGPU_BACKEND, when set, overrides `Auto`'s order (wgpu's own convention).
        let env_backends = wgpu::Backends::from_env().filter(|_| backend == BackendChoice::Auto);
        let attempts = match &env_backends {
            Some(b) => std::slice::from_ref(b),
            None => backend.attempts(),
        };
        let mut last_error = None;
        let mut found = None;
        for &backends in attempts {
            let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
            desc.backends = backends;
            match wgpu::Instance::new(desc).request_adapter(&options).await {
                Ok(adapter) => {
                    found = Some(adapter);
                    break;
                }
                Err(e) => last_error = Some(e),
            }
        }
        let adapter = match (found, last_error) {
            (Some(adapter), _) => adapter,
            (None, Some(error)) => return Err(GpuError::NoAdapter { backend, error }),
            (None, None) => unreachable!("every backend choice has at least one attempt"),
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
            adapter,
            device,
            queue,
            info,
            timestamps,
            primitive_index,
        })
    }

    /// Blocks until all submitted work has finished.
    pub fn wait_idle(&self) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        Ok(())
    }
}
