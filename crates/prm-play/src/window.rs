//! Window mode (winit): the same renderer presented to a window, with an orbit camera.
//!
//! See [`CONTROLS`] for the mouse and keys. The title shows the mode, K, the frame time and the
//! selected light. [`WindowConfig::frames`] quits by itself after that many presented frames and
//! [`WindowConfig::screenshot`] saves the last presented frame as a PNG (read back from the
//! swapchain image itself when the surface allows copies), so the mode can be tested under Xvfb.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use glam::{Quat, Vec3};
use prm_scene::{Camera, Light, Scene};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use crate::animation::Animation;
use crate::present::Presenter;
use crate::{FileArchive, FrameInput, Mode, PlayError, PlayOptions, Renderer};

/// The window's mouse and key bindings (also printed by `prm-play --help`).
pub const CONTROLS: &str = "\
Window controls:
  left drag          orbit the camera around its target
  wheel              zoom (move the camera towards / away from the target)
  1 / 2 / 3 / 4      mode gi / direct / indirect / split
  + (or =) / -       double / halve K, the clusters blended per frame
  Tab                select the next light
  arrows             move the selected light left/right and away/towards (relative to the view);
                     a directional light turns instead
  PageUp / PageDown  move the selected light up / down
  space              pause / resume the animation
  Esc                quit
The title shows the mode, K / clusters, the frame time and frame rate, and the selected light.";

/// Fraction of the scene's bounding-box diagonal a light moves per key press.
pub const LIGHT_STEP: f32 = 0.02;
/// Degrees a directional light turns per key press.
pub const LIGHT_TURN_DEG: f32 = 5.0;

/// What window mode starts with.
pub struct WindowConfig {
    /// The scene.
    pub scene: Scene,
    /// Its archive.
    pub archive: FileArchive,
    /// Renderer options (width and height: the initial window size).
    pub options: PlayOptions,
    /// Initial camera (the orbit's target and distance come from it).
    pub camera: Camera,
    /// Lights when no animation drives them.
    pub lights: Vec<Light>,
    /// Keyframed lights (and camera, ignored once the user orbits).
    pub animation: Option<Animation>,
    /// Initial mode.
    pub mode: Mode,
    /// Exposure of the displayed image.
    pub exposure: f32,
    /// Quit after this many presented frames (`None`: run until closed).
    pub frames: Option<u32>,
    /// Save the last presented frame here (PNG, 8-bit sRGB) when the window closes.
    pub screenshot: Option<PathBuf>,
    /// Scales of the archive's emitter groups ([`crate::emitter_scales`]; empty: all 1).
    pub emitter_scales: Vec<[f32; 3]>,
    /// The sky ([`crate::sky`]), for archives with the sky's transfer.
    pub sky: Option<prm_scene::Sky>,
    /// Show the probe sphere ([`crate::ProbeSphere::orbit`], on the window's clock).
    pub probe_sphere: bool,
}

/// Moves `light` by key presses: `right`, `forward` and `up` in steps of `step` scene units along
/// the camera's right, its forward direction flattened onto the horizontal plane, and +Y. A
/// directional light turns instead: `right` about +Y, `forward` towards/away from vertical, by
/// [`LIGHT_TURN_DEG`] per step.
pub fn nudge_light(light: &mut Light, camera: &Camera, right: f32, forward: f32, up: f32, step: f32) {
    let fwd = {
        let f = camera.target - camera.eye;
        Vec3::new(f.x, 0.0, f.z).try_normalize().unwrap_or(Vec3::NEG_Z)
    };
    let side = fwd.cross(Vec3::Y);
    let offset = (side * right + fwd * forward + Vec3::Y * up) * step;
    if let Some(position) = light.position_mut() {
        *position += offset;
    } else if let Light::Directional { direction, .. } = light {
        let turn = LIGHT_TURN_DEG.to_radians();
        let mut d = Quat::from_rotation_y(-right * turn) * *direction;
        // Tilt about the horizontal axis across the light (the view's side for a vertical one).
        let (axis, vertical) = match d.cross(Vec3::Y).try_normalize() {
            Some(a) => (a, false),
            None => (side, true),
        };
        let tilted = Quat::from_axis_angle(axis, forward * turn) * d;
        // Never tip over the vertical (the turn about +Y would flip).
        if vertical || tilted.cross(Vec3::Y).dot(axis) > 0.0 {
            d = tilted;
        }
        *direction = d.normalize_or(*direction);
    }
}

/// The selected light for the title: kind and position (direction for a directional light).
fn light_label(light: &Light) -> String {
    let v = |p: Vec3| format!("({:.2}, {:.2}, {:.2})", p.x, p.y, p.z);
    match light {
        Light::Point { position, .. } => format!("point at {}", v(*position)),
        Light::Spot { position, .. } => format!("spot at {}", v(*position)),
        Light::Rect { position, .. } => format!("rectangular spot at {}", v(*position)),
        Light::Directional { direction, .. } => format!("directional towards {}", v(*direction)),
    }
}

/// Where the last presented frame is kept for `--screenshot`.
enum Capture {
    /// A copy of the swapchain image (same format), made just before presenting.
    Swapchain(wgpu::Texture),
    /// The surface cannot be copied from (or has an unusual format): the present pass drawn a
    /// second time into an `Rgba8Unorm` texture.
    Offscreen(wgpu::Texture, Box<Presenter>),
}

impl Capture {
    fn texture(&self) -> &wgpu::Texture {
        match self {
            Capture::Swapchain(t) | Capture::Offscreen(t, _) => t,
        }
    }
}

struct Gpu {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    renderer: Renderer,
    presenter: Presenter,
    /// Whether `--screenshot` can copy the swapchain image.
    copyable: bool,
    capture: Option<Capture>,
}

/// 8-bit formats whose bytes a PNG can take (after swapping B and R for the BGRA ones).
fn png_compatible(format: wgpu::TextureFormat) -> bool {
    use wgpu::TextureFormat as F;
    matches!(
        format,
        F::Rgba8Unorm | F::Rgba8UnormSrgb | F::Bgra8Unorm | F::Bgra8UnormSrgb
    )
}

/// A capture texture: of the swapchain's `format` when it can be copied (`Some`), else an
/// `Rgba8Unorm` one with its own present pass.
fn new_capture(
    renderer: &Renderer,
    width: u32,
    height: u32,
    swapchain_format: Option<wgpu::TextureFormat>,
    exposure: f32,
) -> Capture {
    let ctx = renderer.context();
    let format = swapchain_format.unwrap_or(wgpu::TextureFormat::Rgba8Unorm);
    let texture = prm_gpu_kit::pipeline::texture(
        &ctx.device,
        "prm-play screenshot",
        [width, height, 1],
        format,
        wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::RENDER_ATTACHMENT,
    );
    match swapchain_format {
        Some(_) => Capture::Swapchain(texture),
        None => {
            let mut p = Presenter::new(ctx, format, exposure);
            p.bind(renderer);
            Capture::Offscreen(texture, Box::new(p))
        }
    }
}

impl Gpu {
    /// The capture texture for the current size, (re)created when the size changed.
    fn capture_target(&mut self, exposure: f32) -> &Capture {
        let (w, h) = (self.config.width, self.config.height);
        if self
            .capture
            .as_ref()
            .is_some_and(|c| (c.texture().width(), c.texture().height()) != (w, h))
        {
            self.capture = None;
        }
        let swapchain = self.copyable && png_compatible(self.config.format);
        let (renderer, format) = (&self.renderer, self.config.format);
        self.capture
            .get_or_insert_with(|| new_capture(renderer, w, h, swapchain.then_some(format), exposure))
    }

    /// Reads the captured frame back and writes it as an RGB PNG.
    fn save_capture(&self, path: &std::path::Path) -> Result<(), PlayError> {
        let Some(capture) = &self.capture else {
            return Err(PlayError::Window(format!(
                "no frame was presented, so there is no screenshot for {}",
                path.display()
            )));
        };
        let texture = capture.texture();
        let ctx = self.renderer.context();
        let (w, h) = (texture.width(), texture.height());
        let bytes = prm_gpu_kit::readback::read_texture(&ctx.device, &ctx.queue, texture, 0)?;
        ctx.take_uncaptured()?;
        let bgra = matches!(
            texture.format(),
            wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
        );
        let mut rgb = Vec::with_capacity((w * h * 3) as usize);
        for p in bytes.chunks_exact(4) {
            if bgra {
                rgb.extend([p[2], p[1], p[0]]);
            } else {
                rgb.extend([p[0], p[1], p[2]]);
            }
        }
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| PlayError::Output {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
        }
        image::save_buffer(path, &rgb, w, h, image::ExtendedColorType::Rgb8).map_err(|e| PlayError::Output {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
    }
}

struct App {
    config: Option<WindowConfig>,
    lights: Vec<Light>,
    /// The user moved a light: the animation no longer drives the lights.
    user_lights: bool,
    selected: usize,
    step: f32,
    animation: Option<Animation>,
    /// The `--emitter` scales (empty: all 1); an animation's emitter keys replace its groups'.
    emitter_scales: Vec<[f32; 3]>,
    /// The `--sky`, whose intensity and rotation an animation's sky keys drive.
    sky: Option<prm_scene::Sky>,
    /// The scene's bounds, when the probe sphere is shown.
    probe_sphere: Option<prm_scene::Aabb>,
    mode: Mode,
    exposure: f32,
    frame_limit: Option<u32>,
    screenshot: bool,
    gpu: Option<Gpu>,
    error: Option<PlayError>,
    target: Vec3,
    distance: f32,
    yaw: f32,
    pitch: f32,
    fov: f32,
    dragging: bool,
    last_cursor: Option<(f64, f64)>,
    user_camera: bool,
    paused: bool,
    clock: f32,
    last: Instant,
    presented: u32,
    /// Smoothed interval between presented frames, milliseconds.
    frame_ms: Option<f32>,
    /// Set by SIGINT, SIGTERM or SIGHUP: close as the window's close button does, once a frame
    /// was presented (so `--screenshot` has one to save).
    stop: Arc<AtomicBool>,
}

impl App {
    fn orbit_camera(&self) -> Camera {
        let dir = Vec3::new(
            self.pitch.cos() * self.yaw.sin(),
            self.pitch.sin(),
            self.pitch.cos() * self.yaw.cos(),
        );
        Camera {
            eye: self.target + dir * self.distance,
            target: self.target,
            fov_y_deg: self.fov,
        }
    }

    /// The camera and lights of the current moment.
    fn frame_state(&self) -> (Camera, Vec<Light>) {
        let (lights, anim_camera) = match &self.animation {
            Some(a) => (
                if a.lights.is_empty() || self.user_lights {
                    self.lights.clone()
                } else {
                    a.lights_at(self.clock)
                },
                a.camera_at(self.clock),
            ),
            None => (self.lights.clone(), None),
        };
        let camera = match anim_camera {
            Some(c) if !self.user_camera => c,
            _ => self.orbit_camera(),
        };
        (camera, lights)
    }

    fn start(&mut self, event_loop: &ActiveEventLoop) -> Result<(), PlayError> {
        let Some(mut cfg) = self.config.take() else {
            return Ok(());
        };
        let attrs = Window::default_attributes()
            .with_title("prm-play")
            .with_inner_size(winit::dpi::PhysicalSize::new(cfg.options.width, cfg.options.height));
        let window = Arc::new(
            event_loop
                .create_window(attrs)
                .map_err(|e| PlayError::Window(e.to_string()))?,
        );
        let instance = crate::vulkan_instance();
        let surface = instance
            .create_surface(window.clone())
            .map_err(|e| PlayError::Window(e.to_string()))?;
        let ctx = crate::open_vulkan_for(&instance, &surface)?;
        let adapter = ctx.adapter.clone();
        eprintln!("GPU: {}", ctx.describe());
        let size = window.inner_size();
        let mut config = surface
            .get_default_config(&adapter, size.width.max(1), size.height.max(1))
            .ok_or_else(|| PlayError::Window("the surface does not fit the adapter".into()))?;
        config.present_mode = wgpu::PresentMode::AutoVsync;
        let copyable = surface
            .get_capabilities(&adapter)
            .usages
            .contains(wgpu::TextureUsages::COPY_SRC);
        if self.screenshot && copyable {
            config.usage |= wgpu::TextureUsages::COPY_SRC;
        }
        surface.configure(&ctx.device, &config);
        let mut presenter = Presenter::new(&ctx, config.format, self.exposure);
        cfg.options.width = config.width;
        cfg.options.height = config.height;
        let mut renderer = Renderer::new(ctx, &cfg.scene, &mut cfg.archive, cfg.options)?;
        if !cfg.emitter_scales.is_empty() {
            renderer.set_emitter_scales(&cfg.emitter_scales)?;
        }
        if let Some(sky) = &cfg.sky {
            renderer.set_sky(sky)?;
        }
        presenter.bind(&renderer);
        self.gpu = Some(Gpu {
            window,
            surface,
            config,
            renderer,
            presenter,
            copyable,
            capture: None,
        });
        Ok(())
    }

    /// Renders and presents a frame; `true` once the frame limit is reached.
    fn redraw(&mut self) -> Result<bool, PlayError> {
        let now = Instant::now();
        let dt = (now - self.last).as_secs_f32();
        self.last = now;
        if !self.paused {
            self.clock += dt;
        }
        let (camera, lights) = self.frame_state();
        let (mode, exposure, screenshot) = (self.mode, self.exposure, self.screenshot);
        let Some(gpu) = self.gpu.as_mut() else {
            return Ok(false);
        };
        if let Some(a) = self.animation.as_ref().filter(|a| !a.emitters.is_empty()) {
            let infos = gpu.renderer.runtime().emitters();
            let names: Vec<&str> = infos.iter().map(|g| g.name.as_str()).collect();
            let base = if self.emitter_scales.is_empty() {
                vec![[1.0; 3]; names.len()]
            } else {
                self.emitter_scales.clone()
            };
            let scales = a
                .emitter_scales_at(&names, &base, self.clock)
                .map_err(PlayError::Window)?;
            gpu.renderer.set_emitter_scales(&scales)?;
        }
        if let Some(s) = self
            .animation
            .as_ref()
            .zip(self.sky.as_ref())
            .and_then(|(a, s)| a.sky_state_at(s, self.clock))
        {
            gpu.renderer.set_sky(&s)?;
        }
        if let Some(b) = &self.probe_sphere {
            gpu.renderer
                .set_probe_sphere(Some(crate::ProbeSphere::orbit(b, self.clock)))?;
        }
        gpu.renderer.render(&FrameInput {
            camera,
            lights: &lights,
            mode,
        })?;
        let frame = match gpu.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f) | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                let device = &gpu.renderer.context().device;
                gpu.surface.configure(device, &gpu.config);
                gpu.window.request_redraw();
                return Ok(false);
            }
            _ => {
                gpu.window.request_redraw();
                return Ok(false);
            }
        };
        let view = frame.texture.create_view(&Default::default());
        let mut enc = gpu
            .renderer
            .context()
            .device
            .create_command_encoder(&Default::default());
        gpu.presenter.draw(&mut enc, &view);
        if screenshot {
            match gpu.capture_target(exposure) {
                Capture::Swapchain(t) => {
                    enc.copy_texture_to_texture(frame.texture.as_image_copy(), t.as_image_copy(), frame.texture.size())
                }
                Capture::Offscreen(t, p) => p.draw(&mut enc, &t.create_view(&Default::default())),
            }
        }
        let ctx = gpu.renderer.context();
        ctx.queue.submit([enc.finish()]);
        ctx.queue.present(frame);
        self.presented += 1;
        // Frame time: the interval between presented frames, smoothed.
        let ms = dt * 1e3;
        self.frame_ms = Some(match self.frame_ms {
            Some(m) if self.presented > 2 => m * 0.8 + ms * 0.2,
            _ => ms,
        });
        let ms = self.frame_ms.unwrap_or(ms);
        let light = match lights.get(self.selected) {
            Some(l) => format!(", light {}/{} {}", self.selected + 1, lights.len(), light_label(l)),
            None => ", no lights".to_string(),
        };
        gpu.window.set_title(&format!(
            "prm-play — {}, K {}/{}, {:.1} ms ({:.1} fps){}{}",
            self.mode.name(),
            gpu.renderer.runtime().options().top_k,
            gpu.renderer.cluster_count(),
            ms,
            1e3 / ms.max(1e-3),
            light,
            if self.paused { " (paused)" } else { "" }
        ));
        if self.frame_limit.is_some_and(|n| self.presented >= n) {
            return Ok(true);
        }
        gpu.window.request_redraw();
        Ok(false)
    }

    /// Moves (or turns) the selected light; the animation stops driving the lights.
    fn nudge(&mut self, right: f32, forward: f32, up: f32) {
        let (camera, lights) = self.frame_state();
        if lights.is_empty() {
            return;
        }
        self.lights = lights;
        self.user_lights = true;
        let i = self.selected % self.lights.len();
        nudge_light(&mut self.lights[i], &camera, right, forward, up, self.step);
    }

    fn key(&mut self, event_loop: &ActiveEventLoop, key: Key<&str>) {
        match key {
            Key::Named(NamedKey::Escape) => event_loop.exit(),
            Key::Named(NamedKey::Space) => self.paused = !self.paused,
            Key::Named(NamedKey::Tab) => {
                let n = self.frame_state().1.len().max(1);
                self.selected = (self.selected + 1) % n;
            }
            Key::Named(NamedKey::ArrowLeft) => self.nudge(-1.0, 0.0, 0.0),
            Key::Named(NamedKey::ArrowRight) => self.nudge(1.0, 0.0, 0.0),
            Key::Named(NamedKey::ArrowUp) => self.nudge(0.0, 1.0, 0.0),
            Key::Named(NamedKey::ArrowDown) => self.nudge(0.0, -1.0, 0.0),
            Key::Named(NamedKey::PageUp) => self.nudge(0.0, 0.0, 1.0),
            Key::Named(NamedKey::PageDown) => self.nudge(0.0, 0.0, -1.0),
            Key::Character("1") => self.mode = Mode::Gi,
            Key::Character("2") => self.mode = Mode::Direct,
            Key::Character("3") => self.mode = Mode::Indirect,
            Key::Character("4") => self.mode = Mode::Split,
            Key::Character("+") | Key::Character("=") => {
                if let Some(g) = self.gpu.as_mut() {
                    let k = g.renderer.runtime().options().top_k;
                    g.renderer
                        .set_top_k(k.saturating_mul(2).min(g.renderer.cluster_count().max(1)));
                }
            }
            Key::Character("-") => {
                if let Some(g) = self.gpu.as_mut() {
                    let k = g.renderer.runtime().options().top_k;
                    g.renderer.set_top_k(k.min(g.renderer.cluster_count().max(1)) / 2);
                }
            }
            _ => {}
        }
    }
}

impl ApplicationHandler for App {
    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        if self.stop.load(Ordering::Relaxed) && (self.presented > 0 || self.gpu.is_none()) {
            event_loop.exit();
        } else {
            // Wake now and then to see the signal flag while no frame is asked for.
            event_loop.set_control_flow(ControlFlow::WaitUntil(Instant::now() + SIGNAL_POLL));
        }
    }

    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if let Err(e) = self.start(event_loop) {
            self.error = Some(e);
            event_loop.exit();
            return;
        }
        if let Some(g) = &self.gpu {
            g.window.request_redraw();
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let Some(g) = self.gpu.as_mut() {
                    g.config.width = size.width.max(1);
                    g.config.height = size.height.max(1);
                    g.surface.configure(&g.renderer.context().device, &g.config);
                    g.renderer.resize(g.config.width, g.config.height);
                    g.presenter.bind(&g.renderer);
                    // The offscreen capture binds the renderer's image too: rebuilt on demand.
                    g.capture = None;
                }
            }
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                self.dragging = state == ElementState::Pressed;
                self.last_cursor = None;
            }
            WindowEvent::CursorMoved { position, .. } if self.dragging => {
                if let Some((x, y)) = self.last_cursor {
                    self.yaw -= (position.x - x) as f32 * 0.005;
                    self.pitch = (self.pitch + (position.y - y) as f32 * 0.005).clamp(-1.5, 1.5);
                    self.user_camera = true;
                }
                self.last_cursor = Some((position.x, position.y));
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let d = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                self.distance *= 0.9f32.powf(d);
                self.user_camera = true;
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                self.key(event_loop, event.logical_key.as_ref());
            }
            WindowEvent::RedrawRequested => match self.redraw() {
                Ok(true) => event_loop.exit(),
                Ok(false) => {}
                Err(e) => {
                    self.error = Some(e);
                    event_loop.exit();
                }
            },
            _ => {}
        }
    }
}

/// How often the idle event loop wakes to see whether a signal asked it to close.
const SIGNAL_POLL: std::time::Duration = std::time::Duration::from_millis(50);

/// A flag that SIGINT, SIGTERM and SIGHUP set instead of ending the process; a second signal of
/// the same kind ends it at once (exit status 1).
fn stop_on_signals() -> Result<Arc<AtomicBool>, PlayError> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let flag = Arc::new(AtomicBool::new(false));
    for signal in [SIGINT, SIGTERM, SIGHUP] {
        signal_hook::flag::register_conditional_shutdown(signal, 1, Arc::clone(&flag))
            .and_then(|_| signal_hook::flag::register(signal, Arc::clone(&flag)))
            .map_err(|e| PlayError::Window(format!("cannot handle signal {signal}: {e}")))?;
    }
    Ok(flag)
}

/// Opens a window and plays until it is closed, `config.frames` frames were presented or SIGINT,
/// SIGTERM or SIGHUP arrives, then writes `config.screenshot`. Fails with a clear error when no display is available (use
/// headless mode then).
pub fn run(config: WindowConfig) -> Result<(), PlayError> {
    let no_display =
        |e: String| PlayError::Window(format!("cannot open a window ({e}); without a display use --headless"));
    if config.frames == Some(0) {
        return Err(PlayError::Window("--frames 0: nothing to show".into()));
    }
    let event_loop = EventLoop::new().map_err(|e| no_display(e.to_string()))?;
    let c = config.camera;
    let offset = c.eye - c.target;
    let distance = offset.length().max(1e-3);
    let dir = offset / distance;
    let screenshot = config.screenshot.clone();
    let stop = stop_on_signals()?;
    let mut app = App {
        lights: config.lights.clone(),
        user_lights: false,
        selected: 0,
        step: config.scene.bounds().diagonal().max(1e-3) * LIGHT_STEP,
        animation: config.animation.clone(),
        emitter_scales: config.emitter_scales.clone(),
        sky: config.sky.clone(),
        probe_sphere: config.probe_sphere.then(|| config.scene.bounds()),
        mode: config.mode,
        exposure: config.exposure,
        frame_limit: config.frames,
        screenshot: screenshot.is_some(),
        gpu: None,
        error: None,
        target: c.target,
        distance,
        yaw: dir.x.atan2(dir.z),
        pitch: dir.y.clamp(-1.0, 1.0).asin(),
        fov: c.fov_y_deg,
        dragging: false,
        last_cursor: None,
        user_camera: false,
        paused: false,
        clock: 0.0,
        last: Instant::now(),
        presented: 0,
        frame_ms: None,
        stop,
        config: Some(config),
    };
    event_loop.run_app(&mut app).map_err(|e| no_display(e.to_string()))?;
    if let Some(e) = app.error {
        return Err(e);
    }
    if let Some(path) = &screenshot {
        let gpu = app
            .gpu
            .as_ref()
            .ok_or_else(|| PlayError::Window("the window never opened, so there is no screenshot".into()))?;
        gpu.save_capture(path)?;
        let how = match gpu.capture {
            Some(Capture::Swapchain(_)) => "copied from the swapchain image",
            _ => "present pass drawn offscreen: the surface allows no copies",
        };
        eprintln!(
            "{} frames presented; screenshot {} ({how})",
            app.presented,
            path.display()
        );
    }
    Ok(())
}
