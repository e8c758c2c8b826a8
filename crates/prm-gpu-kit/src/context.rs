//! Opening a wgpu device on a chosen backend, with errors that say how to get one.

use std::fmt;
use std::sync::{Arc, Mutex};

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
    #[error("no {backend} GPU adapter found. {}", install_hint(*.backend))]
    NoAdapter {
        /// The backend that was asked for.
        backend: Backend,
    },
    /// The adapter refused to open a device.
    #[error("the {adapter} adapter could not open a device")]
    Device {
        /// Adapter name.
        adapter: String,
        /// wgpu's reason.
        source: wgpu::RequestDeviceError,
    },
    /// Waiting for the device failed (device lost, timeout).
    #[error("GPU device error")]
    Poll(#[from] wgpu::PollError),
    /// Reading a buffer back failed.
    #[error("reading back a GPU buffer failed")]
    Map(#[from] wgpu::BufferAsyncError),
    /// A validation, out-of-memory or internal error (a shader the backend cannot translate, for
    /// one) caught by [`ErrorScopes`] or by the device's uncaptured-error handler.
    #[error("GPU error in {pass}: {message}")]
    Validation {
        /// The pass that raised it.
        pass: &'static str,
        /// wgpu's message.
        message: String,
    },
}

/// What to install for `backend` on a machine without a GPU.
fn install_hint(backend: Backend) -> &'static str {
    match backend {
        Backend::Vulkan => {
            "On a machine without a GPU install Mesa's software Vulkan driver (lavapipe): \
             `apt-get install mesa-vulkan-drivers`"
        }
        Backend::Gl => {
            "On a machine without a GPU install Mesa's software OpenGL driver (llvmpipe): \
             `apt-get install libgl1-mesa-dri libegl1`"
        }
        Backend::Auto => {
            "On a machine without a GPU install Mesa's software drivers: \
             `apt-get install mesa-vulkan-drivers` (Vulkan via lavapipe) or \
             `apt-get install libgl1-mesa-dri libegl1` (OpenGL via llvmpipe)"
        }
    }
}

/// How to open a [`GpuContext`].
#[derive(Clone, Copy, Debug)]
pub struct ContextOptions<'a> {
    /// The backend, or the order to try them in.
    pub backend: Backend,
    /// Features requested when the adapter has them (the device is opened without the others;
    /// check `device.features()`), e.g. `TIMESTAMP_QUERY` for pass timers.
    pub optional_features: wgpu::Features,
    /// Present to this surface: only adapters of `instance` that support it are taken.
    pub surface: Option<(&'a wgpu::Instance, &'a wgpu::Surface<'a>)>,
}

impl ContextOptions<'_> {
    /// Headless, on `backend`, without optional features.
    pub const fn headless(backend: Backend) -> ContextOptions<'static> {
        ContextOptions {
            backend,
            optional_features: wgpu::Features::empty(),
            surface: None,
        }
    }
}

/// The first error that no [`ErrorScopes`] caught, kept for [`GpuContext::wait`] instead of
/// wgpu's default of panicking.
type Uncaptured = Arc<Mutex<Option<String>>>;

/// An open device and queue, and what they are.
pub struct GpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter it was opened on (surface configuration needs it).
    pub adapter: wgpu::Adapter,
    /// Adapter name, driver and backend.
    pub info: wgpu::AdapterInfo,
    uncaptured: Uncaptured,
}

/// A headless wgpu instance for one backend. Creating a GL instance probes EGL and window
/// systems, which is slow and noisy when Vulkan is there anyway, hence one backend at a time.
pub fn instance(backends: wgpu::Backends) -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = backends;
    wgpu::Instance::new(desc)
}

/// The window-system probes of wgpu's backends call `wl_display_connect`, and libwayland prints
/// `error: XDG_RUNTIME_DIR is invalid or not set in the environment.` to stderr when that
/// variable is missing, even on headless runs that succeed. With no Wayland display named there
/// is nothing to connect to, so the probe is pointed at an absolute socket path that does not
/// exist, which libwayland tries without reading XDG_RUNTIME_DIR and fails silently.
///
/// For headless programs only (a window needs the real display variables), and it changes the
/// process environment: call it first thing in `main`, before any thread exists.
pub fn silence_wayland_probe() {
    let unset = |k: &str| std::env::var_os(k).is_none_or(|v| v.is_empty());
    if unset("XDG_RUNTIME_DIR") && unset("WAYLAND_DISPLAY") && unset("WAYLAND_SOCKET") {
        // SAFETY: the caller runs this before starting threads (see above), so nothing reads
        // the environment concurrently.
        unsafe { std::env::set_var("WAYLAND_DISPLAY", "/nonexistent/prm-no-wayland") };
    }
}

impl GpuContext {
    /// Opens a headless device on `backend` with the adapter's own limits (lavapipe's are
    /// generous).
    pub fn new(backend: Backend) -> Result<GpuContext, GpuError> {
        GpuContext::open(&ContextOptions::headless(backend))
    }

    /// Opens a device as `options` say: a real GPU before a software one, Vulkan before GL.
    pub fn open(options: &ContextOptions) -> Result<GpuContext, GpuError> {
        let backend = options.backend;
        let order: &[wgpu::Backends] = match (options.surface, backend) {
            (Some(_), _) => &[wgpu::Backends::all()],
            (None, Backend::Auto) => &[wgpu::Backends::VULKAN, wgpu::Backends::GL],
            (None, Backend::Vulkan) => &[wgpu::Backends::VULKAN],
            (None, Backend::Gl) => &[wgpu::Backends::GL],
        };
        let wanted = match backend {
            Backend::Auto => wgpu::Backends::VULKAN | wgpu::Backends::GL,
            Backend::Vulkan => wgpu::Backends::VULKAN,
            Backend::Gl => wgpu::Backends::GL,
        };
        let adapter = order
            .iter()
            .find_map(|&b| {
                let owned;
                let inst = match options.surface {
                    Some((inst, _)) => inst,
                    None => {
                        owned = instance(b);
                        &owned
                    }
                };
                let mut adapters = pollster::block_on(inst.enumerate_adapters(b & wanted));
                adapters.retain(|a| {
                    wanted.contains(a.get_info().backend.into())
                        && options.surface.is_none_or(|(_, s)| a.is_surface_supported(s))
                });
                // A real GPU before a software one, Vulkan before GL.
                adapters.sort_by_key(|a| {
                    let i = a.get_info();
                    (
                        i.device_type == wgpu::DeviceType::Cpu,
                        i.backend != wgpu::Backend::Vulkan,
                    )
                });
                adapters.into_iter().next()
            })
            .ok_or(GpuError::NoAdapter { backend })?;
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("prm"),
            required_features: adapter.features() & options.optional_features,
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|source| GpuError::Device {
            adapter: info.name.clone(),
            source,
        })?;
        let uncaptured: Uncaptured = Arc::default();
        let sink = uncaptured.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let mut first = sink.lock().unwrap_or_else(|p| p.into_inner());
            first.get_or_insert_with(|| e.to_string());
        }));
        Ok(GpuContext {
            device,
            queue,
            adapter,
            info,
            uncaptured,
        })
    }

    /// Whether the adapter is a software rasterizer (lavapipe, llvmpipe, WARP).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// One line: adapter name, backend, driver.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?}, driver {} {})",
            self.info.name, self.info.backend, self.info.device_type, self.info.driver, self.info.driver_info
        )
    }

    /// Blocks until all submitted work is done; fails if any error escaped the error scopes
    /// since the last call.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        self.take_uncaptured()
    }

    /// The first error no error scope caught since the last call, as an error.
    pub fn take_uncaptured(&self) -> Result<(), GpuError> {
        let taken = self.uncaptured.lock().unwrap_or_else(|p| p.into_inner()).take();
        match taken {
            Some(message) => Err(GpuError::Validation {
                pass: "uncaptured",
                message,
            }),
            None => Ok(()),
        }
    }

    /// Copies `buffer` (which must have `MAP_READ`) to the CPU; fails if any error escaped
    /// the error scopes since the last check.
    pub fn read_buffer(&self, buffer: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
        let bytes = crate::readback::map_read(&self.device, buffer)?;
        self.take_uncaptured()?;
        Ok(bytes)
    }
}

/// Error scopes for validation, out-of-memory and internal errors, pushed and popped together:
/// a shader that a backend cannot translate (WGSL depth `textureLoad` on GL) is an *internal*
/// error, which a validation scope alone lets through to the uncaptured handler.
#[must_use = "pop the scopes to see their errors"]
pub struct ErrorScopes(Vec<wgpu::ErrorScopeGuard>);

impl Drop for ErrorScopes {
    /// Scopes left unpopped (an early return) are dropped innermost first, as wgpu requires.
    fn drop(&mut self) {
        while let Some(scope) = self.0.pop() {
            drop(scope);
        }
    }
}

impl ErrorScopes {
    /// Pushes the three scopes on `device`.
    pub fn push(device: &wgpu::Device) -> ErrorScopes {
        ErrorScopes(
            [
                wgpu::ErrorFilter::Validation,
                wgpu::ErrorFilter::OutOfMemory,
                wgpu::ErrorFilter::Internal,
            ]
            .into_iter()
            .map(|f| device.push_error_scope(f))
            .collect(),
        )
    }

    /// Pops them (innermost first) and returns the first error any of them caught, as raised by
    /// `pass`.
    pub fn pop(mut self, pass: &'static str) -> Result<(), GpuError> {
        let mut first = None;
        while let Some(scope) = self.0.pop() {
            if let Some(e) = pollster::block_on(scope.pop()) {
                first.get_or_insert(e);
            }
        }
        match first {
            Some(e) => Err(GpuError::Validation {
                pass,
                message: e.to_string(),
            }),
            None => Ok(()),
        }
    }
}
