//! Helpers shared by the end-to-end tests of `prm-tests` (the test files sit beside this
//! folder, one `[[test]]` each in `tests/Cargo.toml`).

use std::path::{Path, PathBuf};

use prm_gpu_kit::{Backend, GpuContext};

/// A path inside the repository.
pub fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

/// A fresh, empty scratch folder under the target directory, named for the test.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = repo("target/prm-tests").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create a scratch folder under target/");
    dir
}

/// A bake configuration that fixes the sizes a test depends on: entry points, clusters, atlas
/// resolution and seed; with no accuracy check (the tests measure the played light against the
/// reference themselves, and its estimate would be in the archive too). Everything else is the
/// plan's.
pub fn sized(entries: usize, clusters: usize, resolution: u32, seed: u64) -> prm_bake::BakeConfig {
    prm_bake::BakeConfig {
        accuracy_points: Some(0),
        entries: Some(entries),
        clusters: Some(clusters),
        resolution: Some(resolution),
        seed: Some(seed),
        ..Default::default()
    }
}

/// Loads the repository's `scene` and bakes it with `config` on the CPU renderer, through the
/// library as `prm-bake bake` does, into `archive` in a fresh scratch folder named for the test
/// `name`: the scene and the archive's path.
pub fn baked(name: &str, scene: &str, archive: &str, config: &prm_bake::BakeConfig) -> (prm_scene::Scene, PathBuf) {
    let scene_path = repo(scene);
    let loaded = prm_scene::load(&scene_path).expect("a bundled scene loads");
    let output = temp_dir(name).join(archive);
    let plan = prm_bake::Plan::new(config, &loaded).expect("a valid plan");
    let job = prm_bake::BakeJob {
        scene: &loaded,
        scene_path: &scene_path,
        plan: &plan,
        output: &output,
        shard: None,
    };
    prm_bake::bake(&job, prm_bake::Renderer::Cpu, &mut prm_bake::NoProgress).expect("the bake");
    (loaded, output)
}

/// ‖t − r‖ / ‖r‖ over every channel.
pub fn rel_error(t: &[glam::Vec3], r: &[glam::Vec3]) -> f64 {
    let num: f64 = t.iter().zip(r).map(|(a, b)| (*a - *b).length_squared() as f64).sum();
    let den: f64 = r.iter().map(|b| b.length_squared() as f64).sum();
    (num / den).sqrt()
}

/// The sum of every channel.
pub fn channel_sum(v: &[glam::Vec3]) -> f64 {
    v.iter().map(|x| x.element_sum() as f64).sum()
}

/// Every gather point's radiance as the CPU computes it: albedo / π × (its ray-cast direct
/// irradiance under `lights` + `more` of it).
pub fn gather_radiance(
    bvh: &prm_trace::Bvh,
    lights: &[prm_scene::Light],
    points: &[prm_format::GatherPoint],
    more: impl Fn(&prm_format::GatherPoint) -> glam::Vec3,
) -> Vec<glam::Vec3> {
    points
        .iter()
        .map(|g| {
            let (p, n) = (glam::Vec3::from(g.position), glam::Vec3::from(g.normal));
            let direct = prm_trace::direct_irradiance(bvh, lights, p, n, n, u32::MAX);
            glam::Vec3::from(g.albedo) / std::f32::consts::PI * (direct + more(g))
        })
        .collect()
}

/// Where [`reference_indirect`] estimates the light.
pub enum At<'a> {
    /// At the atlas's exit points.
    Exits(&'a [prm_scene::ExitPoint]),
    /// At points (position, normal).
    Points(&'a [(glam::Vec3, glam::Vec3)]),
}

/// The mean of `tracer`'s indirect irradiance `at` the exit points or points, about `spp` paths
/// each, from `seed`.
pub fn reference_indirect(tracer: &prm_trace::ReferenceTracer<'_>, at: At<'_>, spp: u32, seed: u64) -> Vec<glam::Vec3> {
    let params = prm_trace::ReferenceParams {
        seed,
        ..prm_trace::ReferenceParams::with_spp(spp)
    };
    let estimate = match at {
        At::Exits(exits) => tracer.indirect_at_exits(exits, &params, &mut |_, _| {}),
        At::Points(points) => tracer.indirect_at_points(points, &params, &mut |_, _| {}),
    };
    estimate.unwrap().mean
}

/// `played` against `reference`: prints `what` with the relative error ([`rel_error`]) and the
/// energy ratio (`Σ played / Σ reference` over every channel), then asserts the energy within
/// `max_energy_off` of 1 and the error under `max_error`.
pub fn assert_close(what: &str, played: &[glam::Vec3], reference: &[glam::Vec3], max_error: f64, max_energy_off: f64) {
    let error = rel_error(played, reference);
    let energy = channel_sum(played) / channel_sum(reference);
    println!("{what}: error {error:.4}, energy {energy:.4}");
    assert!((energy - 1.0).abs() < max_energy_off, "{what}: energy {energy:.3}");
    assert!(error < max_error, "{what}: error {error:.3}");
}

/// Encodes and runs one frame of `rt` without punctual lights (its baked light as set) and
/// reads back the indirect lightmap and the full irradiance lightmap.
pub fn unlit_frame(ctx: &GpuContext, rt: &mut prm_runtime::Runtime) -> (Vec<glam::Vec3>, Vec<glam::Vec3>) {
    rt.update(&[]).unwrap();
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    rt.encode(&mut enc, prm_runtime::Shadows::Own, None);
    ctx.queue.submit([enc.finish()]);
    let lightmap = rt.read_lightmap().unwrap().into_iter().map(glam::Vec3::from).collect();
    let full = rt
        .read_irradiance_lightmap()
        .unwrap()
        .into_iter()
        .map(glam::Vec3::from)
        .collect();
    (lightmap, full)
}

/// A Vulkan device, explicitly: a missing driver fails loudly instead of falling back to GL.
pub fn gpu() -> GpuContext {
    GpuContext::new(Backend::Vulkan).expect("a Vulkan adapter (apt-get install mesa-vulkan-drivers)")
}

/// Runs the compute kernel `main` of the module `parts` (joined in order, see
/// [`prm_gpu_kit::pipeline::compute`]) once per element of `count` (workgroups of 64 along x),
/// with group 0 bound to `resources` in binding order, and returns the bytes of `output` (a
/// storage buffer made with `COPY_SRC`). Any validation error of the shader or the dispatch fails
/// the test with wgpu's message.
pub fn run_kernel(
    ctx: &GpuContext,
    label: &'static str,
    parts: &[&str],
    resources: &[wgpu::BindingResource],
    count: u32,
    output: &wgpu::Buffer,
) -> Vec<u8> {
    use prm_gpu_kit::{pipeline, readback, ErrorScopes};
    let device = &ctx.device;
    let scope = ErrorScopes::push(device);
    let kernel = pipeline::compute(device, label, parts);
    let group = pipeline::compute_group(device, label, &kernel, resources);
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&kernel);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(count.div_ceil(64), 1, 1);
    }
    ctx.queue.submit([encoder.finish()]);
    let bytes = readback::read_buffer(device, &ctx.queue, output, output.size()).unwrap_or_else(|e| panic!("{e}"));
    scope.pop(label).unwrap_or_else(|e| panic!("{e}"));
    ctx.take_uncaptured().unwrap_or_else(|e| panic!("{e}"));
    bytes
}

/// A `Depth32Float` 2D array of `layers` layers of `side`² texels, every texel cleared to 1.0
/// (the far plane: a shadow lookup finds everything lit), viewed whole.
pub fn cleared_depth_array(ctx: &GpuContext, side: u32, layers: u32) -> wgpu::TextureView {
    use prm_gpu_kit::pipeline;
    let texture = pipeline::texture(
        &ctx.device,
        "cleared depth",
        [side, side, layers.max(1)],
        wgpu::TextureFormat::Depth32Float,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
    );
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    for layer in 0..layers.max(1) {
        let view = pipeline::layer_view(&texture, layer);
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("clear depth"),
            color_attachments: &[],
            depth_stencil_attachment: pipeline::depth_attachment(&view, true),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
    }
    ctx.queue.submit([encoder.finish()]);
    pipeline::array_view(&texture)
}

/// Compares the values of an estimator on the CPU and on the GPU, input by input and channel by
/// channel: they agree within `relative · max(|cpu|, |gpu|) + absolute · scale`, where `scale`
/// is the input's own magnitude (the value before its cosines, so that a result that is zero on
/// one side and a rounding error on the other passes). Keeps the worst case for the report.
#[derive(Debug, Default)]
pub struct Agreement {
    /// Inputs compared.
    pub inputs: usize,
    /// Inputs where either side is above the absolute tolerance.
    pub nonzero: usize,
    /// Inputs that did not agree, with their description and both values.
    pub failures: Vec<String>,
    /// Largest `|cpu − gpu| / max(|cpu|, |gpu|)` over the channels where both are above the
    /// absolute tolerance, and the input it was found at.
    pub worst_relative: (f32, String),
}

impl Agreement {
    /// Relative tolerance of every comparison.
    pub const RELATIVE: f32 = 1e-4;
    /// Absolute tolerance, as a fraction of the input's scale.
    pub const ABSOLUTE: f32 = 1e-5;

    /// Compares one input's values (`describe` names the input for the report).
    pub fn check(&mut self, cpu: glam::Vec3, gpu: glam::Vec3, scale: f32, describe: impl FnOnce() -> String) {
        self.inputs += 1;
        let floor = Self::ABSOLUTE * scale.abs();
        let mut ok = true;
        let mut worst = 0.0f32;
        if cpu.abs().max(gpu.abs()).max_element() > floor {
            self.nonzero += 1;
        }
        for (a, b) in cpu.to_array().into_iter().zip(gpu.to_array()) {
            let m = a.abs().max(b.abs());
            let d = (a - b).abs();
            ok &= d <= Self::RELATIVE * m + floor && a.is_finite() == b.is_finite();
            if m > floor {
                worst = worst.max(d / m);
            }
        }
        if !ok || worst > self.worst_relative.0 {
            let text = describe();
            if worst > self.worst_relative.0 {
                self.worst_relative = (worst, text.clone());
            }
            if !ok {
                self.failures
                    .push(format!("{text}: cpu {cpu} gpu {gpu} (scale {scale})"));
            }
        }
    }

    /// Prints the summary under `name` and fails with the first failures if there are any.
    pub fn assert(&self, name: &str) {
        eprintln!(
            "{name}: {} inputs ({} not zero), largest relative difference {:.3e} at {}",
            self.inputs, self.nonzero, self.worst_relative.0, self.worst_relative.1
        );
        // Two outputs that are zero everywhere agree but test nothing: at least a tenth of the
        // inputs must be lit on one side.
        assert!(
            self.inputs > 0 && self.nonzero * 10 >= self.inputs,
            "{name}: only {} of {} inputs are not zero: the comparison tests almost nothing",
            self.nonzero,
            self.inputs
        );
        assert!(
            self.failures.is_empty(),
            "{name}: {} of {} inputs differ, first ones:\n{}",
            self.failures.len(),
            self.inputs,
            self.failures.iter().take(20).cloned().collect::<Vec<_>>().join("\n")
        );
    }
}
