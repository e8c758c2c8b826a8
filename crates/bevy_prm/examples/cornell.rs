//! A baked scene in Bevy with a point light circling under its ceiling: Bevy draws the direct
//! light, PRM's lightmap the indirect light.
//!
//! ```sh
//! cargo xtask demo                                    # bakes out/cornell-box.prm
//! cargo run -p bevy_prm --example cornell             # in a window
//! cargo run -p bevy_prm --example cornell -- --headless out/bevy-cornell.png
//! cargo run -p bevy_prm --example cornell -- --screenshot out/window.png
//! ```
//!
//! (Add `--ignore-rust-version` after `cargo run` on a compiler older than Bevy's 1.97.1.)
//! The first argument that is not an option is the archive (default `out/cornell-box.prm`); its
//! scene file must lie beside it, as `prm-bake bake` leaves it. `--headless OUT.png` renders
//! into an image, `--screenshot OUT.png` into the window; either saves one frame once the
//! meshes have had the lightmap for a while, and exits.

use std::path::{Path, PathBuf};
use std::time::Duration;

use bevy::app::ScheduleRunnerPlugin;
use bevy::asset::LoadState;
use bevy::camera::RenderTarget;
use bevy::prelude::*;
use bevy::render::settings::{Backends, WgpuSettings};
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};
use bevy::render::RenderPlugin;
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;
use bevy_prm::{PrmArchive, PrmGi, PrmLightmap, PrmPlugin};

/// Side of the headless frame, in pixels.
const HEADLESS_SIZE: u32 = 512;
/// Frames the app waits after the meshes receive the lightmap before it saves one.
const SETTLE_FRAMES: u32 = 30;

#[derive(Resource)]
struct Settings {
    archive: String,
    headless: bool,
    /// Where to save one frame before exiting.
    out: Option<PathBuf>,
}

/// The render target of the headless camera.
#[derive(Resource)]
struct Frame(Handle<Image>);

fn main() -> AppExit {
    let mut args = std::env::args().skip(1);
    let (mut archive, mut headless, mut out) = (PathBuf::from("out/cornell-box.prm"), false, None);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--headless" | "--screenshot" => {
                headless = arg == "--headless";
                out = Some(PathBuf::from(args.next().unwrap_or_else(|| "bevy-cornell.png".into())));
            }
            "-h" | "--help" => {
                println!("usage: cornell [ARCHIVE.prm] [--headless OUT.png | --screenshot OUT.png]");
                return AppExit::Success;
            }
            _ => archive = PathBuf::from(arg),
        }
    }
    if !archive.is_file() {
        eprintln!(
            "error: no archive at {}: bake one first (`cargo xtask demo` writes out/cornell-box.prm)",
            archive.display()
        );
        return AppExit::error();
    }
    let archive = std::path::absolute(&archive).unwrap_or(archive);
    let folder = archive
        .parent()
        .unwrap_or(Path::new("."))
        .to_string_lossy()
        .into_owned();
    let name = archive.file_name().unwrap_or_default().to_string_lossy().into_owned();
    let asset_plugin = AssetPlugin {
        file_path: folder,
        ..default()
    };
    // Vulkan, Metal or DirectX 12 (or WGPU_BACKEND): no OpenGL probe and its driver messages.
    let render = RenderPlugin {
        render_creation: WgpuSettings {
            backends: Some(Backends::from_env().unwrap_or(Backends::PRIMARY)),
            ..default()
        }
        .into(),
        ..default()
    };
    let plugins = DefaultPlugins.set(asset_plugin).set(render);
    let mut app = App::new();
    if headless {
        prm_gpu_kit::silence_wayland_probe();
        let window = WindowPlugin {
            primary_window: None,
            exit_condition: ExitCondition::DontExit,
            ..default()
        };
        app.add_plugins((
            plugins.set(window).disable::<WinitPlugin>(),
            ScheduleRunnerPlugin::run_loop(Duration::from_millis(1)),
        ));
    } else {
        app.add_plugins(plugins);
    }
    app.add_plugins(PrmPlugin)
        .insert_resource(Settings {
            archive: name,
            headless,
            out,
        })
        .add_systems(Startup, setup)
        .add_systems(Update, (exit_on_failed_load, spawn_scene, move_light, save_frame))
        .run()
}

fn setup(mut commands: Commands, settings: Res<Settings>, server: Res<AssetServer>, mut images: ResMut<Assets<Image>>) {
    let archive: Handle<PrmArchive> = server.load(settings.archive.clone());
    commands.spawn((PrmGi { archive }, Transform::default(), Visibility::default()));
    if settings.headless {
        let format = bevy::render::render_resource::TextureFormat::Rgba8UnormSrgb;
        let image = images.add(Image::new_target_texture(HEADLESS_SIZE, HEADLESS_SIZE, format, None));
        commands.insert_resource(Frame(image));
    }
}

/// Exits with an error when the archive (or its scene) cannot be loaded.
fn exit_on_failed_load(server: Res<AssetServer>, gis: Query<&PrmGi>, mut exit: MessageWriter<AppExit>) {
    for gi in &gis {
        if let Some(LoadState::Failed(e)) = server.get_load_state(&gi.archive) {
            // The loader's message, without the backtrace note Bevy's errors carry.
            let message = e.to_string();
            eprintln!("error: {}", message.lines().next().unwrap_or_default());
            exit.write(AppExit::error());
        }
    }
}

/// Once the archive has loaded: its meshes, a camera on its scene's first camera (or in front
/// of its bounds) and a point light.
fn spawn_scene(
    mut commands: Commands,
    gis: Query<(Entity, &PrmGi), Without<Children>>,
    archives: Res<Assets<PrmArchive>>,
    frame: Option<Res<Frame>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    for (root, gi) in &gis {
        let Some(archive) = archives.get(&gi.archive) else {
            continue;
        };
        for (mesh, albedo) in archive.meshes() {
            let material = materials.add(StandardMaterial {
                base_color: albedo.into(),
                perceptual_roughness: 1.0,
                reflectance: 0.0,
                ..default()
            });
            commands.spawn((Mesh3d(meshes.add(mesh)), MeshMaterial3d(material), ChildOf(root)));
        }
        let scene = archive.scene();
        let b = scene.bounds();
        let centre = Vec3::from_array(((b.min + b.max) * 0.5).to_array());
        let (eye, target, fov) =
            scene
                .cameras
                .first()
                .map_or((centre + Vec3::Z * b.diagonal() * 1.2, centre, 45.0f32), |c| {
                    (
                        Vec3::from_array(c.eye.to_array()),
                        Vec3::from_array(c.target.to_array()),
                        c.fov_y_deg,
                    )
                });
        let mut camera = commands.spawn((
            Camera3d::default(),
            Projection::Perspective(PerspectiveProjection {
                fov: fov.to_radians(),
                ..default()
            }),
            // Radiometric scene units: show them at unit exposure.
            bevy::camera::Exposure { ev100: 0.0 },
            // A curve that needs no lookup tables (Bevy's default needs `tonemapping_luts`).
            bevy::core_pipeline::tonemapping::Tonemapping::Reinhard,
            Transform::from_translation(eye).looking_at(target, Vec3::Y),
        ));
        if let Some(frame) = &frame {
            camera.insert(RenderTarget::Image(frame.0.clone().into()));
        }
        // (diagonal/2)² W/sr: a few W/m² on the far wall.
        let intensity = (b.diagonal() * 0.5).powi(2);
        commands.spawn((
            PointLight {
                intensity: 4.0 * std::f32::consts::PI * intensity,
                shadow_maps_enabled: true,
                range: b.diagonal() * 4.0,
                ..default()
            },
            Transform::from_translation(light_position(archive, 0.0)),
        ));
    }
}

/// Where the light is at `t` seconds: on a circle a quarter of the height under the top.
fn light_position(archive: &PrmArchive, t: f32) -> Vec3 {
    let b = archive.scene().bounds();
    let (c, e) = ((b.min + b.max) * 0.5, b.extent());
    let r = 0.25 * e.x.min(e.z);
    Vec3::new(c.x + r * t.cos(), b.max.y - 0.25 * e.y, c.z + r * t.sin())
}

fn move_light(
    time: Res<Time>,
    gis: Query<&PrmGi>,
    archives: Res<Assets<PrmArchive>>,
    mut lights: Query<&mut Transform, With<PointLight>>,
) {
    let Some(archive) = gis.iter().next().and_then(|gi| archives.get(&gi.archive)) else {
        return;
    };
    for mut t in &mut lights {
        t.translation = light_position(archive, time.elapsed_secs());
    }
}

/// Headless: once the meshes have had the lightmap for a while, saves one frame and exits.
fn save_frame(
    mut commands: Commands,
    settings: Res<Settings>,
    frame: Option<Res<Frame>>,
    lit: Query<(), With<PrmLightmap>>,
    mut waited: Local<u32>,
) {
    let Some(out) = settings.out.clone() else { return };
    if lit.is_empty() {
        return;
    }
    *waited += 1;
    if *waited != SETTLE_FRAMES {
        return;
    }
    let screenshot = frame.map_or_else(Screenshot::primary_window, |f| Screenshot::image(f.0.clone()));
    commands.spawn(screenshot).observe(
        move |captured: On<ScreenshotCaptured>, mut exit: MessageWriter<AppExit>| {
            let saved = captured
                .image
                .clone()
                .try_into_dynamic()
                .map_err(|e| e.to_string())
                .and_then(|image| image.to_rgb8().save(&out).map_err(|e| e.to_string()));
            match saved {
                Ok(()) => {
                    println!("cornell: wrote {}", out.display());
                    exit.write(AppExit::Success);
                }
                Err(e) => {
                    eprintln!("error: cannot write {}: {e}", out.display());
                    exit.write(AppExit::error());
                }
            }
        },
    );
}
