//! The viewer's frame: the run time ([`prm_runtime::Runtime`]: shadow maps → cluster weights →
//! rank → top-K selection with fade → lightmap blend), then the shading of every pixel
//! ([`crate::shade`]). Everything inside a frame stays on the GPU; the CPU only uploads the
//! frame's constants (camera, lights, shadow-view matrices) and reads results on request.

use std::time::Instant;

use glam::{Mat4, Vec3};
use prm_format::Archive;
use prm_gpu_kit::{pipeline, readback, ErrorScopes, GpuContext, PassTimer};
use prm_runtime::{look_to, perspective, ClusterWeight, Runtime, RuntimeError, RuntimeOptions, Shadows};
use prm_scene::{Aabb, Camera, Light, Scene};

use crate::shade::{ShadePass, COLOR_FORMAT, DEPTH_FORMAT};
use crate::sphere::{ProbeSphere, SpherePass};
use crate::PlayError;

pub use prm_runtime::MAX_LIGHTS;

/// Names of the timed passes, in frame order: the run time's, then the shading.
pub const PASS_NAMES: [&str; prm_runtime::PASS_NAMES.len() + 1] = {
    let r = prm_runtime::PASS_NAMES;
    let mut names = ["shade"; prm_runtime::PASS_NAMES.len() + 1];
    let mut i = 0;
    while i < r.len() {
        names[i] = r[i];
        i += 1;
    }
    names
};

/// What a frame shows; the codes are `MODE_*` in `shade.wgsl`.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Mode {
    /// Direct + indirect (global illumination).
    #[default]
    Gi = 0,
    /// Direct light only (local illumination).
    Direct = 1,
    /// Indirect light only.
    Indirect = 2,
    /// Left half direct, right half global.
    Split = 3,
}

impl Mode {
    /// The mode as `Camera.mode` holds it (`MODE_*` in `shade.wgsl`).
    pub fn code(self) -> u32 {
        self as u32
    }
    /// The mode's name as `--mode` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Gi => "gi",
            Mode::Direct => "direct",
            Mode::Indirect => "indirect",
            Mode::Split => "split",
        }
    }
    fn needs_indirect(self) -> bool {
        self != Mode::Direct
    }
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "gi" => Ok(Mode::Gi),
            "direct" => Ok(Mode::Direct),
            "indirect" => Ok(Mode::Indirect),
            "split" => Ok(Mode::Split),
            _ => Err(format!("unknown mode '{s}' (expected gi, direct, indirect or split)")),
        }
    }
}

/// Renderer settings.
#[derive(Clone, Debug)]
pub struct PlayOptions {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// The run time's options (top K, shadow maps, fade band, shadow offsets).
    pub runtime: RuntimeOptions,
    /// Time every pass with GPU timestamp queries (when the device has them).
    pub timestamps: bool,
}

impl PlayOptions {
    /// Checks the options against each other and `limits` before any GPU allocation, naming
    /// the `prm-play` option and the limit it breaks.
    pub fn validate(&self, limits: &wgpu::Limits) -> Result<(), PlayError> {
        let bad = |option: &'static str, message: String| Err(PlayError::Option { option, message });
        let max_dim = limits.max_texture_dimension_2d;
        if self.width == 0 || self.height == 0 || self.width > max_dim || self.height > max_dim {
            return bad(
                "--size",
                format!(
                    "{}x{} is outside this device's 1..={max_dim} texels per side (max_texture_dimension_2d)",
                    self.width, self.height
                ),
            );
        }
        let readback = readback_bytes(self.width, self.height);
        if readback > limits.max_buffer_size {
            return bad(
                "--size",
                format!(
                    "{}x{} needs a {readback}-byte image buffer (16 bytes a pixel), over this device's \
                     max_buffer_size of {} bytes",
                    self.width, self.height, limits.max_buffer_size
                ),
            );
        }
        self.runtime.validate(limits).map_err(|e| match e {
            // The run time names its fields; the player's flags spell them with dashes.
            RuntimeError::Option { option, message } => PlayError::Option {
                option: match option {
                    "shadow_resolution" => "--shadow-resolution",
                    "sun_tiles" => "--sun-tiles",
                    "top_k" => "--top-k",
                    "fade_band" => "--fade-band",
                    "near_bounces" => "--near-bounces",
                    other => other,
                },
                message,
            },
            e => e.into(),
        })
    }
}

/// Bytes of the buffer a `width × height` frame is read back through (rgba32float rows padded
/// to wgpu's copy alignment).
fn readback_bytes(width: u32, height: u32) -> u64 {
    readback::padded_size(width, height, 16)
}

impl Default for PlayOptions {
    fn default() -> Self {
        PlayOptions {
            width: 1024,
            height: 768,
            runtime: RuntimeOptions::default(),
            timestamps: false,
        }
    }
}

/// One frame's camera, lights and mode.
#[derive(Clone, Copy, Debug)]
pub struct FrameInput<'a> {
    /// Camera.
    pub camera: Camera,
    /// Lights (at most [`MAX_LIGHTS`]).
    pub lights: &'a [Light],
    /// What to show.
    pub mode: Mode,
}

/// Times of one frame.
#[derive(Clone, Debug, Default)]
pub struct FrameTimings {
    /// Wall time from recording to the GPU finishing, milliseconds.
    pub cpu_ms: f64,
    /// GPU time per pass (from [`PASS_NAMES`], only the passes that ran), milliseconds; empty
    /// without timestamp queries.
    pub gpu_ms: Vec<(&'static str, f64)>,
}

/// A linear-radiance image read back from the GPU.
#[derive(Clone, Debug)]
pub struct Image {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Row-major, top row first.
    pub rgb: Vec<[f32; 3]>,
}

/// The player's GPU state for one archive and scene: the run time and the shading.
pub struct Renderer {
    ctx: GpuContext,
    /// Image size and whether timestamps were asked for; the run time holds its own options,
    /// so [`Renderer::options`] is made from both.
    width: u32,
    height: u32,
    timestamps: bool,
    runtime: Runtime,
    shade: ShadePass,
    /// The probe sphere's pass (archives with probes), and whether a sphere is set.
    sphere: Option<SpherePass>,
    sphere_shown: bool,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    timer: Option<PassTimer>,
    /// Whether this frame writes the timestamps (see [`Renderer::set_timing`]).
    timing: bool,
}

fn check(ctx: &GpuContext, scope: ErrorScopes, pass: &'static str) -> Result<(), PlayError> {
    scope.pop(pass)?;
    ctx.take_uncaptured()?;
    Ok(())
}

/// The colour target (linear radiance; sampled by the window's present pass) and depth buffer.
fn targets(device: &wgpu::Device, width: u32, height: u32) -> (wgpu::Texture, wgpu::TextureView, wgpu::TextureView) {
    let color = pipeline::texture(
        device,
        "play color",
        [width, height, 1],
        COLOR_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::TEXTURE_BINDING,
    );
    let color_view = color.create_view(&Default::default());
    let depth = pipeline::texture(
        device,
        "play depth",
        [width, height, 1],
        DEPTH_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
    );
    (color, color_view, depth.create_view(&Default::default()))
}

impl Renderer {
    /// Uploads the scene, the archive's entries, clusters and panes, and builds the pipelines.
    /// The archive must belong to the scene (see [`crate::open`]).
    pub fn new<R: std::io::Read + std::io::Seek>(
        ctx: GpuContext,
        scene: &Scene,
        archive: &mut Archive<R>,
        opts: PlayOptions,
    ) -> Result<Renderer, PlayError> {
        opts.validate(&ctx.device.limits())?;
        let scope = ErrorScopes::push(&ctx.device);
        let PlayOptions {
            width,
            height,
            runtime,
            timestamps,
        } = opts;
        let runtime = Runtime::new(&ctx.device, &ctx.queue, archive, scene, runtime)?;
        let shade = ShadePass::new(&ctx, scene, &runtime);
        let sphere = SpherePass::new(&ctx, &runtime, shade.camera());
        let (color, color_view, depth_view) = targets(&ctx.device, width, height);
        let timer = timestamps.then(|| PassTimer::new(&ctx.device, &PASS_NAMES)).flatten();
        check(&ctx, scope, "renderer setup")?;
        Ok(Renderer {
            runtime,
            shade,
            sphere,
            sphere_shown: false,
            color,
            color_view,
            depth_view,
            timing: timer.is_some(),
            timer,
            ctx,
            width,
            height,
            timestamps,
        })
    }

    /// The GPU context.
    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// The run time the frames are made with.
    pub fn runtime(&self) -> &Runtime {
        &self.runtime
    }

    /// The options in use (the size after [`Renderer::resize`], the top K after
    /// [`Renderer::set_top_k`]).
    pub fn options(&self) -> PlayOptions {
        PlayOptions {
            width: self.width,
            height: self.height,
            runtime: self.runtime.options().clone(),
            timestamps: self.timestamps,
        }
    }

    /// Number of clusters (= panes).
    pub fn cluster_count(&self) -> u32 {
        self.runtime.cluster_count()
    }

    /// Whether per-pass GPU timestamps are recorded.
    pub fn has_timestamps(&self) -> bool {
        self.timer.is_some()
    }

    /// Pauses (`false`) or resumes per-pass timestamp queries; nothing changes without them.
    /// On lavapipe a timestamp is a synchronisation point, so frame times are cleanest without.
    pub fn set_timing(&mut self, on: bool) {
        self.timing = on;
    }

    /// The last frame (linear radiance, `rgba32float`), for presenting.
    pub fn color_view(&self) -> &wgpu::TextureView {
        &self.color_view
    }

    /// Changes the image size (re-creates the render targets only).
    pub fn resize(&mut self, width: u32, height: u32) {
        let (w, h) = (width.max(1), height.max(1));
        if (w, h) == (self.width, self.height) {
            return;
        }
        (self.color, self.color_view, self.depth_view) = targets(&self.ctx.device, w, h);
        self.width = w;
        self.height = h;
    }

    /// Scales the archive's emitter groups (one RGB triple per group of
    /// [`Runtime::emitters`]): their light on the scene and their own surfaces' emission, from
    /// the next frame on.
    pub fn set_emitter_scales(&mut self, scales: &[[f32; 3]]) -> Result<(), PlayError> {
        self.runtime.set_emitter_scales(scales)?;
        self.shade.write_emission(&self.ctx.queue, &self.runtime);
        Ok(())
    }

    /// Lights the scene with `sky` (its intensity and rotation as they are now), from the next
    /// frame on; refused when the archive has no sky transfer.
    pub fn set_sky(&mut self, sky: &prm_scene::Sky) -> Result<(), PlayError> {
        self.runtime.set_sky(&sky.sh())?;
        Ok(())
    }

    /// Shows `sphere` lit by the archive's probes from the next frame on (`None`: no sphere);
    /// refused when the archive has no probes.
    pub fn set_probe_sphere(&mut self, sphere: Option<ProbeSphere>) -> Result<(), PlayError> {
        match (&self.sphere, sphere) {
            (_, None) => self.sphere_shown = false,
            (None, Some(_)) => {
                return Err(PlayError::Option {
                    option: "--probe-sphere",
                    message: "the archive has no probes: bake it with prm-bake bake --probes".to_string(),
                })
            }
            (Some(pass), Some(s)) => {
                pass.write(&self.ctx.queue, &s);
                self.sphere_shown = true;
            }
        }
        Ok(())
    }

    /// Changes the number of clusters kept per frame.
    pub fn set_top_k(&mut self, k: u32) {
        self.runtime.set_top_k(k);
    }

    fn camera_matrix(&self, camera: &Camera, bounds: &Aabb) -> Mat4 {
        let aspect = self.width as f32 / self.height as f32;
        let diag = bounds.diagonal().max(1e-3);
        let centre = (bounds.min + bounds.max) * 0.5;
        let far = (camera.eye.distance(centre) + diag) * 1.1;
        let near = (diag * 1e-3).min(far * 1e-3);
        let fwd = (camera.target - camera.eye).normalize_or(Vec3::NEG_Z);
        let up = if fwd.y.abs() > 0.999 { Vec3::Z } else { Vec3::Y };
        perspective(camera.fov_y_deg.to_radians(), aspect, near, far) * look_to(camera.eye, fwd, up)
    }

    /// Renders one frame and waits for the GPU.
    pub fn render(&mut self, input: &FrameInput) -> Result<FrameTimings, PlayError> {
        let lights: &[Light] = input.lights;
        let start = Instant::now();
        let scope = ErrorScopes::push(&self.ctx.device);
        if self.runtime.update(lights)? {
            self.shade.rebind(&self.ctx, &self.runtime);
            if let Some(s) = &mut self.sphere {
                s.rebind(&self.ctx, &self.runtime, self.shade.camera());
            }
        }
        let view_proj = self.camera_matrix(&input.camera, &self.runtime.bounds());
        self.shade.write_camera(
            &self.ctx.queue,
            view_proj,
            input.camera.eye,
            input.mode.code(),
            self.width,
        );
        let timer = self.timer.as_ref().filter(|_| self.timing);
        let mut enc = self.ctx.device.create_command_encoder(&Default::default());
        if input.mode.needs_indirect() {
            self.runtime.encode(&mut enc, Shadows::Own, timer);
        } else {
            self.runtime.encode_shadow_maps(&mut enc, timer);
        }
        let sphere = self.sphere.as_ref().filter(|_| self.sphere_shown);
        self.shade
            .encode(&mut enc, &self.color_view, &self.depth_view, sphere, timer);
        if let Some(t) = timer {
            t.resolve(&mut enc);
        }
        self.ctx.queue.submit([enc.finish()]);
        self.ctx.wait()?;
        check(&self.ctx, scope, "frame")?;
        let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
        let gpu_ms = match timer {
            Some(t) => t.read(&self.ctx.device, &self.ctx.queue)?,
            None => Vec::new(),
        };
        Ok(FrameTimings { cpu_ms, gpu_ms })
    }

    /// The last frame's image (linear radiance).
    pub fn read_image(&self) -> Result<Image, PlayError> {
        let texels = readback::read_rgba32f(&self.ctx.device, &self.ctx.queue, &self.color, 0)?;
        Ok(Image {
            width: self.width,
            height: self.height,
            rgb: texels.into_iter().map(|[r, g, b, _]| [r, g, b]).collect(),
        })
    }

    /// The last indirect-irradiance lightmap (texel (x, y) at `y·R + x`).
    pub fn read_lightmap(&self) -> Result<Vec<[f32; 3]>, PlayError> {
        Ok(self.runtime.read_lightmap()?)
    }

    /// The last frame's cluster weights, scores, ranks and effective weights.
    pub fn read_weights(&self) -> Result<Vec<ClusterWeight>, PlayError> {
        Ok(self.runtime.read_weights()?)
    }
}
