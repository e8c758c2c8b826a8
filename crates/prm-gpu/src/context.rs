//! Opening a wgpu device on a chosen backend, with errors that say how to get one.

use std::fmt;

/// Which wgpu backend to open.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Backend {
    /// Vulkan first, then OpenGL.
    #[default]
    Auto,
    /// Vulkan only (lavapipe on a machine without a GPU).
    Vulkan,
    /// OpenGL (ES) only (llvmpipe on a machine without a GPU).
    Gl,
}

impl fmt::Display for Backend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Backend::Auto => "auto",
            Backend::Vulkan => "vulkan",
            Backend::Gl => "gl",
        })
    }
}

impl std::str::FromStr for Backend {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "auto" => Ok(Backend::Auto),
            "vulkan" | "vk" => Ok(Backend::Vulkan),
            "gl" | "gles" | "opengl" => Ok(Backend::Gl),
            _ => Err(format!("unknown backend '{s}' (expected auto, vulkan or gl)")),
        }
    }
}

/// Why no GPU work could be done.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter of the requested backend exists.
    #[error(
        "no {backend} GPU adapter found. On a machine without a GPU install Mesa's software \
         drivers: `apt-get install mesa-vulkan-drivers` (Vulkan via lavapipe) or \
         `apt-get install libgl1-mesa-dri libegl1` (OpenGL via llvmpipe)"
    )]
    NoAdapter {
        /// The backend that was asked for.
        backend: Backend,
    },
    /// The adapter refused to open a device.
    #[error("the {adapter} adapter could not open a device: {source}")]
    Device {
        /// Adapter name.
        adapter: String,
        /// wgpu's reason.
        source: wgpu::RequestDeviceError,
    },
    /// Waiting for the device failed (device lost, timeout).
    #[error("GPU device error: {0}")]
    Poll(#[from] wgpu::PollError),
    /// Reading a buffer back failed.
    #[error("reading back a GPU buffer failed: {0}")]
    Map(#[from] wgpu::BufferAsyncError),
    /// A validation or out-of-memory error caught by an error scope.
    #[error("GPU error in {pass}: {message}")]
    Validation {
        /// The pass that raised it.
        pass: &'static str,
        /// wgpu's message.
        message: String,
    },
}

/// An open device and queue, and what they are.
pub struct GpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Adapter name, driver and backend.
    pub info: wgpu::AdapterInfo,
}

impl GpuContext {
    /// Opens a device on `backend` with the adapter's own limits (lavapipe's are generous).
    pub fn new(backend: Backend) -> Result<GpuContext, GpuError> {
        // One instance per backend, Vulkan first: creating a GL instance probes EGL and window
        // systems, which is slow and noisy when Vulkan is there anyway.
        let order: &[wgpu::Backends] = match backend {
            Backend::Auto => &[wgpu::Backends::VULKAN, wgpu::Backends::GL],
            Backend::Vulkan => &[wgpu::Backends::VULKAN],
            Backend::Gl => &[wgpu::Backends::GL],
        };
        let adapter = order
            .iter()
            .find_map(|&b| {
                let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
                desc.backends = b;
                let instance = wgpu::Instance::new(desc);
                let mut adapters = pollster::block_on(instance.enumerate_adapters(b));
                // A real GPU before a software one.
                adapters.sort_by_key(|a| a.get_info().device_type == wgpu::DeviceType::Cpu);
                adapters.into_iter().next()
            })
            .ok_or(GpuError::NoAdapter { backend })?;
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("prm"),
            required_features: wgpu::Features::empty(),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|source| GpuError::Device {
            adapter: info.name.clone(),
            source,
        })?;
        Ok(GpuContext { device, queue, info })
    }

    /// One line: adapter name, backend, driver.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?}, driver {} {})",
            self.info.name, self.info.backend, self.info.device_type, self.info.driver, self.info.driver_info
        )
    }

    /// Blocks until all submitted work is done.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        Ok(())
    }

    /// Copies `buffer` (which must have `MAP_READ`) to the CPU.
    pub fn read_buffer(&self, buffer: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
        let (tx, rx) = std::sync::mpsc::channel();
        buffer.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        rx.recv().unwrap_or(Err(wgpu::BufferAsyncError))?;
        let bytes = buffer.get_mapped_range(..).map(|v| v.to_vec());
        buffer.unmap();
        bytes.map_err(|_| GpuError::Map(wgpu::BufferAsyncError))
    }
}
