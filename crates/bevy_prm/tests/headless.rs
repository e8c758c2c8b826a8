//! A headless Bevy app with [`PrmPlugin`] plays a synthetic archive of the bundled Cornell box
//! under one point light. The image that Bevy's `Lightmap` samples on every mesh is read back
//! from Bevy's render device and compared with the lightmap prm-runtime blends on its own device
//! for the same light (as `prm-play` plays it), divided by π.

use std::path::{Path, PathBuf};

use bevy::app::PluginsState;
use bevy::pbr::Lightmap;
use bevy::prelude::*;
use bevy::render::render_asset::RenderAssets;
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy::render::settings::{Backends, WgpuSettings};
use bevy::render::texture::GpuImage;
use bevy::render::{RenderApp, RenderPlugin};
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;
use bevy_prm::{PrmArchive, PrmGi, PrmLightmap, PrmPlugin, PrmRenderState};
use prm_runtime::synthetic::{cornell_box_path, write_archive, SyntheticParams};

/// Frames the app may take to load the archive, start the run time and blend once.
const MAX_FRAMES: usize = 2000;

/// Point-light intensity (W/sr, white) under the top of the box.
const INTENSITY: f32 = 2.0;

/// A scratch folder of this test, `name`, holding the archive and the scene it names.
fn archive_folder(name: &str) -> (PathBuf, prm_scene::Scene) {
    let dir = std::env::temp_dir().join(format!("bevy-prm-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let source = cornell_box_path();
    let scene_dir = source.parent().unwrap();
    for entry in std::fs::read_dir(scene_dir).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), dir.join(entry.file_name())).unwrap();
    }
    let scene_path = dir.join(source.file_name().unwrap());
    let scene = prm_scene::load(&scene_path).unwrap();
    write_archive(
        &scene,
        &scene_path,
        &dir.join("cornell.prm"),
        SyntheticParams::default(),
    )
    .unwrap();
    (dir, scene)
}

fn light_position(scene: &prm_scene::Scene) -> glam::Vec3 {
    let b = scene.bounds();
    let c = (b.min + b.max) * 0.5;
    glam::Vec3::new(c.x, b.max.y - 0.25 * b.extent().y, c.z)
}

/// A headless app: Bevy's default plugins without a window system, and PRM's.
fn headless_app(dir: &Path) -> App {
    let mut app = App::new();
    app.add_plugins((
        DefaultPlugins
            .set(WindowPlugin {
                primary_window: None,
                exit_condition: ExitCondition::DontExit,
                ..default()
            })
            .set(AssetPlugin {
                file_path: dir.to_string_lossy().into_owned(),
                ..default()
            })
            .set(RenderPlugin {
                render_creation: WgpuSettings {
                    backends: Some(Backends::PRIMARY),
                    ..default()
                }
                .into(),
                ..default()
            })
            .disable::<WinitPlugin>(),
        PrmPlugin,
    ));
    while app.plugins_state() == PluginsState::Adding {
        bevy::tasks::tick_global_task_pools_on_main_thread();
    }
    app.finish();
    app.cleanup();
    app
}

/// Spawns the archive's meshes under a [`PrmGi`] entity once it has loaded.
fn spawn_scene(
    mut commands: Commands,
    server: Res<AssetServer>,
    archives: Res<Assets<PrmArchive>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut spawned: Local<bool>,
    mut handle: Local<Option<Handle<PrmArchive>>>,
) {
    let handle = handle.get_or_insert_with(|| server.load("cornell.prm"));
    let Some(archive) = archives.get(&*handle) else { return };
    if std::mem::replace(&mut *spawned, true) {
        return;
    }
    let root = commands
        .spawn((
            PrmGi {
                archive: handle.clone(),
            },
            Transform::default(),
            Visibility::default(),
        ))
        .id();
    for (mesh, albedo) in archive.meshes() {
        let material = materials.add(StandardMaterial::from(Color::from(albedo)));
        commands.spawn((Mesh3d(meshes.add(mesh)), MeshMaterial3d(material), ChildOf(root)));
    }
}

/// The RGB of the image behind `handle`, read back from Bevy's render device.
fn read_bevy_lightmap(app: &App, handle: &Handle<Image>) -> Vec<[f32; 3]> {
    let world = app.sub_app(RenderApp).world();
    let gpu = world
        .resource::<RenderAssets<GpuImage>>()
        .get(handle)
        .expect("the lightmap is on the GPU");
    let device = world.resource::<RenderDevice>();
    let queue = world.resource::<RenderQueue>();
    let bytes = prm_gpu_kit::readback::read_texture(device.wgpu_device(), queue, &gpu.texture, 0).unwrap();
    let halves: &[u16] = bytemuck::cast_slice(&bytes);
    halves
        .chunks_exact(4)
        .map(|t| std::array::from_fn(|c| half::f16::from_bits(t[c]).to_f32()))
        .collect()
}

/// The lightmap prm-runtime blends on a device of its own for a white point light.
fn runtime_lightmap(archive: &Path, scene: &prm_scene::Scene, position: glam::Vec3) -> Vec<[f32; 3]> {
    let instance = prm_gpu_kit::instance(wgpu::Backends::PRIMARY);
    let adapter = pollster::block_on(instance.request_adapter(&Default::default())).unwrap();
    let (device, queue) = pollster::block_on(adapter.request_device(&Default::default())).unwrap();
    let mut archive = prm_format::Archive::open(archive).unwrap();
    let options = prm_runtime::RuntimeOptions::for_archive(&archive);
    let mut runtime = prm_runtime::Runtime::new(&device, &queue, &mut archive, scene, options).unwrap();
    let light = prm_scene::Light::Point {
        position,
        intensity: glam::Vec3::splat(INTENSITY),
    };
    runtime.update(&[light]).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    runtime.encode(&mut encoder, prm_runtime::Shadows::Own, None);
    queue.submit([encoder.finish()]);
    runtime.read_lightmap().unwrap()
}

#[test]
fn bevy_samples_the_runtime_lightmap_for_its_own_lights() {
    prm_gpu_kit::silence_wayland_probe();
    let (dir, scene) = archive_folder("lightmap");
    let position = light_position(&scene);
    let mut app = headless_app(&dir);
    app.add_systems(Update, spawn_scene);
    // Φ = 4π·I lumens of white light is I W/sr.
    app.world_mut().spawn((
        PointLight {
            intensity: 4.0 * std::f32::consts::PI * INTENSITY,
            color: Color::WHITE,
            ..default()
        },
        Transform::from_translation(Vec3::from_array(position.to_array())),
    ));
    let updates = |app: &App| app.sub_app(RenderApp).world().resource::<PrmRenderState>().updates();
    let mut frames = 0;
    while updates(&app) == 0 {
        assert!(frames < MAX_FRAMES, "no lightmap after {MAX_FRAMES} frames");
        app.update();
        frames += 1;
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    // A frame without changes blends nothing again.
    app.update();
    assert_eq!(updates(&app), 1, "an unchanged light blended the lightmap again");

    // Every mesh samples the one image of the PrmGi entity.
    let world = app.world_mut();
    let image = world.query::<&PrmLightmap>().single(world).unwrap().0.clone();
    let mut lightmaps = world.query::<(&Mesh3d, &Lightmap)>();
    let lit: Vec<_> = lightmaps.iter(world).map(|(_, l)| l.image.id()).collect();
    let mesh_count = world.query::<&Mesh3d>().iter(world).count();
    assert!(
        mesh_count > 0 && lit.len() == mesh_count,
        "{} of {mesh_count} meshes have a lightmap",
        lit.len()
    );
    assert!(lit.iter().all(|&id| id == image.id()));

    let bevy = read_bevy_lightmap(&app, &image);
    let reference = runtime_lightmap(&dir.join("cornell.prm"), &scene, position);
    assert_eq!(bevy.len(), reference.len());
    let sum = |v: &[[f32; 3]]| v.iter().flatten().map(|&x| x as f64).sum::<f64>();
    println!(
        "lightmap sums: bevy {:.4}, run time / pi {:.4}",
        sum(&bevy),
        sum(&reference) / std::f64::consts::PI
    );
    let peak = reference.iter().flatten().fold(0.0f32, |m, &v| m.max(v)) / std::f32::consts::PI;
    assert!(peak > 0.0, "the reference lightmap is black");
    let mut worst = 0.0f32;
    for (b, r) in bevy.iter().zip(&reference) {
        for c in 0..3 {
            let expected = r[c] / std::f32::consts::PI;
            // binary16 keeps 11 significant bits.
            let err = (b[c] - expected).abs() / (expected.abs() + 1e-4 * peak);
            worst = worst.max(err);
        }
    }
    assert!(
        worst < 2e-3,
        "Bevy's lightmap differs from the run time's E/π by {worst:.2e} (relative)"
    );

    // Moving the light blends again.
    let world = app.world_mut();
    let mut lights = world.query_filtered::<&mut Transform, With<PointLight>>();
    for mut t in lights.iter_mut(world) {
        t.translation.x += 0.1;
    }
    app.update();
    assert_eq!(updates(&app), 2, "a moved light did not blend the lightmap again");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The command of the README's "Use it in Bevy" section.
fn readme_bevy_command() -> String {
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md")).unwrap();
    let section = readme
        .split("\n## Use it in Bevy")
        .nth(1)
        .expect("the README has a Bevy section");
    let block = section
        .split("```sh\n")
        .nth(1)
        .expect("the Bevy section has a sh block");
    block.lines().next().unwrap().to_owned()
}

/// `archive_folder(name)` with the archive renamed to `archive` (a relative path) under
/// `work/`; returns the scratch folder and `work/`.
fn work_folder(name: &str, archive: &Path) -> (PathBuf, PathBuf) {
    let (dir, _) = archive_folder(name);
    let work = dir.join("work");
    let out = work.join(archive.parent().unwrap());
    std::fs::create_dir_all(&out).unwrap();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let entry = entry.unwrap();
        if entry.file_type().unwrap().is_file() {
            let name = if entry.file_name() == "cornell.prm" {
                archive.file_name().unwrap().to_owned()
            } else {
                entry.file_name()
            };
            std::fs::copy(entry.path(), out.join(name)).unwrap();
        }
    }
    (dir, work)
}

/// The example, which `cargo test` builds beside the test binaries.
fn example_binary() -> PathBuf {
    let deps = std::env::current_exe().unwrap().parent().unwrap().to_path_buf();
    let example = deps
        .parent()
        .unwrap()
        .join("examples")
        .join(format!("cornell{}", std::env::consts::EXE_SUFFIX));
    assert!(
        example.is_file(),
        "{} is missing: `cargo test -p bevy_prm` builds it",
        example.display()
    );
    example
}

/// Runs `command` and checks that it succeeded and that the PNG it wrote is mostly lit.
fn check_frame(mut command: std::process::Command, png: &Path) {
    let output = command.env_remove("RUST_BACKTRACE").output().unwrap();
    assert!(
        output.status.success(),
        "{command:?} failed ({}):\n{}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    let frame = image::open(png).unwrap().to_rgb8();
    let lit = frame.pixels().filter(|p| p.0.iter().any(|&c| c > 16)).count();
    assert!(lit * 2 > frame.pixels().len(), "the frame is mostly black");
}

/// The README's Bevy command, as written, in a folder where `out/cb.prm` is a (synthetic)
/// archive of the bundled Cornell box beside its scene: the example renders headless with the
/// plugin and writes its frame.
#[test]
fn the_readme_bevy_command_runs_as_written() {
    let command = readme_bevy_command();
    let words: Vec<&str> = command.split_whitespace().collect();
    let dash = words
        .iter()
        .position(|w| *w == "--")
        .expect("the command passes arguments");
    assert_eq!(words[..3], ["cargo", "run", "-p"], "{command}");
    assert!(words.windows(2).any(|w| w == ["--example", "cornell"]), "{command}");
    let args = &words[dash + 1..];
    let archive = args
        .iter()
        .find(|a| a.ends_with(".prm"))
        .expect("the command names an archive");
    let png = args
        .iter()
        .find(|a| a.ends_with(".png"))
        .expect("the command names a PNG");
    let (dir, work) = work_folder("readme", Path::new(archive));
    let mut run = std::process::Command::new(example_binary());
    run.args(args).current_dir(&work);
    check_frame(run, &work.join(png));
    let _ = std::fs::remove_dir_all(&dir);
}

/// The example in a window under Xvfb (lavapipe): it opens, receives the lightmap, saves the
/// window's frame and exits by itself.
#[test]
fn the_example_runs_in_a_window() {
    let xvfb = std::process::Command::new("xvfb-run").arg("--help").output();
    assert!(
        xvfb.is_ok(),
        "xvfb-run not found: the window test needs a virtual X server (apt-get install xvfb xauth)"
    );
    let (dir, work) = work_folder("window", Path::new("cb.prm"));
    let mut run = std::process::Command::new("xvfb-run");
    run.args(["-a", "-s", "-screen 0 640x480x24"])
        .arg(example_binary())
        .args(["cb.prm", "--screenshot", "window.png"])
        .current_dir(&work);
    check_frame(run, &work.join("window.png"));
    let _ = std::fs::remove_dir_all(&dir);
}
