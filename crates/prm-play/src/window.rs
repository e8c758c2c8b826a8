//! Window mode (winit): the same renderer presented to a window, with an orbit camera.
//!
//! Mouse: left drag orbits around the camera's target, wheel zooms. Keys: `1` gi, `2` direct,
//! `3` indirect, `4` split, `+`/`-` double/halve K, `space` pauses the animation, `Esc` quits.
//! The title shows the mode, K and the frame rate.

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use prm_scene::{Camera, Light, Scene};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use crate::animation::Animation;
use crate::{FileArchive, FrameInput, Mode, PlayError, PlayOptions, Renderer};

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
}

/// The present pass (`play_present.wgsl`): the renderer's linear frame, × exposure, clamped and
/// sRGB-encoded (by the shader unless the target format is sRGB), onto a target of `format`.
pub struct Presenter {
    pipeline: wgpu::RenderPipeline,
    uniform: wgpu::Buffer,
    group: Option<wgpu::BindGroup>,
}

impl Presenter {
    /// Builds the pass for targets of `format`.
    pub fn new(ctx: &prm_gpu::GpuContext, format: wgpu::TextureFormat, exposure: f32) -> Presenter {
        let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("play_present"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/play_present.wgsl").into()),
        });
        let pipeline = ctx.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("play_present"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(format.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let uniform = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("play_present"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let encode = u32::from(!format.is_srgb());
        ctx.queue
            .write_buffer(&uniform, 0, bytemuck::cast_slice(&[exposure.to_bits(), encode, 0, 0]));
        Presenter {
            pipeline,
            uniform,
            group: None,
        }
    }

    /// Binds the renderer's colour target (again after [`Renderer::resize`]).
    pub fn bind(&mut self, renderer: &Renderer) {
        self.group = Some(renderer.context().device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("play_present"),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(renderer.color_view()),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: self.uniform.as_entire_binding(),
                },
            ],
        }));
    }

    /// Records the pass drawing onto `target` (same size as the renderer's image).
    pub fn draw(&self, encoder: &mut wgpu::CommandEncoder, target: &wgpu::TextureView) {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("play_present"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        if let Some(group) = &self.group {
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, group, &[]);
            pass.draw(0..3, 0..1);
        }
    }
}

struct Gpu {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    renderer: Renderer,
    presenter: Presenter,
}

struct App {
    config: Option<WindowConfig>,
    lights: Vec<Light>,
    animation: Option<Animation>,
    mode: Mode,
    exposure: f32,
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
    frames: u32,
    fps_since: Instant,
    fps: f32,
}

impl App {
    fn camera(&self) -> Camera {
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
        let (ctx, adapter) = crate::open_vulkan_for(&instance, Some(&surface))?;
        let size = window.inner_size();
        let mut config = surface
            .get_default_config(&adapter, size.width.max(1), size.height.max(1))
            .ok_or_else(|| PlayError::Window("the surface does not fit the adapter".into()))?;
        config.present_mode = wgpu::PresentMode::AutoVsync;
        surface.configure(&ctx.device, &config);
        let mut presenter = Presenter::new(&ctx, config.format, self.exposure);
        cfg.options.width = config.width;
        cfg.options.height = config.height;
        let renderer = Renderer::new(ctx, &cfg.scene, &mut cfg.archive, cfg.options)?;
        presenter.bind(&renderer);
        self.gpu = Some(Gpu {
            window,
            surface,
            config,
            renderer,
            presenter,
        });
        Ok(())
    }

    fn redraw(&mut self) -> Result<(), PlayError> {
        let now = Instant::now();
        let dt = (now - self.last).as_secs_f32();
        self.last = now;
        if !self.paused {
            self.clock += dt;
        }
        let (lights, anim_camera) = match &self.animation {
            Some(a) => (
                if a.lights.is_empty() {
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
            _ => self.camera(),
        };
        let mode = self.mode;
        let Some(gpu) = self.gpu.as_mut() else {
            return Ok(());
        };
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
                return Ok(());
            }
            _ => {
                gpu.window.request_redraw();
                return Ok(());
            }
        };
        let ctx = gpu.renderer.context();
        let view = frame.texture.create_view(&Default::default());
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        gpu.presenter.draw(&mut enc, &view);
        ctx.queue.submit([enc.finish()]);
        ctx.queue.present(frame);
        self.frames += 1;
        let since = self.fps_since.elapsed().as_secs_f32();
        if since >= 1.0 {
            self.fps = self.frames as f32 / since;
            self.frames = 0;
            self.fps_since = Instant::now();
        }
        gpu.window.set_title(&format!(
            "prm-play — {:?}, K = {}, {:.1} fps{}",
            self.mode,
            gpu.renderer.options().top_k,
            self.fps,
            if self.paused { " (paused)" } else { "" }
        ));
        gpu.window.request_redraw();
        Ok(())
    }
}

impl ApplicationHandler for App {
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
                match event.logical_key.as_ref() {
                    Key::Named(NamedKey::Escape) => event_loop.exit(),
                    Key::Named(NamedKey::Space) => self.paused = !self.paused,
                    Key::Character("1") => self.mode = Mode::Gi,
                    Key::Character("2") => self.mode = Mode::Direct,
                    Key::Character("3") => self.mode = Mode::Indirect,
                    Key::Character("4") => self.mode = Mode::Split,
                    Key::Character("+") | Key::Character("=") => {
                        if let Some(g) = self.gpu.as_mut() {
                            let k = g.renderer.options().top_k;
                            g.renderer
                                .set_top_k(k.saturating_mul(2).min(g.renderer.cluster_count().max(1)));
                        }
                    }
                    Key::Character("-") => {
                        if let Some(g) = self.gpu.as_mut() {
                            let k = g.renderer.options().top_k;
                            g.renderer.set_top_k(k.min(g.renderer.cluster_count().max(1)) / 2);
                        }
                    }
                    _ => {}
                }
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.redraw() {
                    self.error = Some(e);
                    event_loop.exit();
                }
            }
            _ => {}
        }
    }
}

/// Opens a window and plays until it is closed. Fails with a clear error when no display is
/// available (use headless mode then).
pub fn run(config: WindowConfig) -> Result<(), PlayError> {
    let no_display =
        |e: String| PlayError::Window(format!("cannot open a window ({e}); without a display use --headless"));
    let event_loop = EventLoop::new().map_err(|e| no_display(e.to_string()))?;
    let c = config.camera;
    let offset = c.eye - c.target;
    let distance = offset.length().max(1e-3);
    let dir = offset / distance;
    let mut app = App {
        lights: config.lights.clone(),
        animation: config.animation.clone(),
        mode: config.mode,
        exposure: config.exposure,
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
        frames: 0,
        fps_since: Instant::now(),
        fps: 0.0,
        config: Some(config),
    };
    event_loop.run_app(&mut app).map_err(|e| no_display(e.to_string()))?;
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}
