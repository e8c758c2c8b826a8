//! Every estimator that exists in Rust and in WGSL, tested function against function on grids of inputs.
//!
//! Long on purpose: each estimator pair needs its WGSL harness, its input grid and its CPU twin side
//! by side, so that a failure reads in one place.
//!
//! Each test builds a compute kernel from the real shader files (the prelude files, the function
//! file, then a few lines that call the WGSL function for every element of a storage buffer),
//! runs it on lavapipe and compares every result with the Rust function on the same input:
//!
//! * direct light, `light_irradiance_ng` / `light_irradiance_disk` / `direct_irradiance_disk`
//!   (`shaders/runtime/lights.wgsl`) against `prm_trace::bounded_irradiance` and
//!   `prm_trace::entry_irradiance`, every light kind, the `ENTRY_DISK` bound at several disk
//!   sizes;
//! * the weights pass (`shaders/runtime/weights.wgsl`, whole) against `entry_irradiance` and
//!   `Clustering::weights_by_energy`;
//! * the VPL estimator `vpl_irradiance` (`shaders/vpl.wgsl`, which the pane gather calls) against
//!   `VplBound::irradiance`, every bound.
//!
//! Shadows are left out on both sides: the GPU reads shadow maps cleared to the far plane
//! (everything lit), the CPU a BVH of a box 9 km away from every ray.
//!
//! **The geometric normal.** The CPU counts a light only when it is above both the shading normal
//! `n` and the geometric normal `ng`: a light below the geometric plane is behind the surface
//! itself, and the shadow map cannot see that (the surface is the nearest thing to the light
//! along that ray, so the receiver passes the depth test, and the normal offset along `n` pushes
//! it towards the light). On the grid below (ng tilted ±10° from n on two thirds of the inputs),
//! an `n`-only function differs from the CPU on 2200 of the 32760 inputs with `ng ≠ n` (the light
//! leaks through, up to 0.087 of its value before the cosine, i.e. `cos θ` up to sin 5°);
//! `light_irradiance_ng` / `direct_irradiance_ng` test both normals and agree on all 49140.
//! `light_irradiance_disk` and `direct_irradiance_disk` take `ng = n`, which is exact for the
//! weights pass (an entry point's normal is its triangle's geometric normal). prm-play's shading
//! calls `direct_irradiance` with its interpolated normal only (it has no geometric normal at
//! hand): it keeps the leak, which the test below counts.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use prm_format::{CellPoint, EntryCells};
use prm_gpu::pane_gather::{VplBoundKind, VPL_WGSL};
use prm_gpu::vpl_depth::{GpuVpl, HEMICUBE_WGSL};
use prm_gpu_kit::pipeline::{buffer_init, storage};
use prm_runtime::{shadow_views, GpuCluster, GpuEntry, GpuFrame, GpuWeight, LIGHTS_WGSL, SHARED_WGSL};
use prm_scene::{Aabb, Light, ENTRY_DISK};
use prm_tests::{cleared_depth_array, gpu, run_kernel, Agreement};
use prm_trace::{bounded_irradiance, entry_irradiance, Bvh, BvhParams, Clustering, SurfaceSample, Vpl, VplBound};

/// Where every receiver and light of the grids lies (the shadow views cover it).
const BOUNDS: Aabb = Aabb {
    min: Vec3::splat(-10.0),
    max: Vec3::splat(10.0),
};
/// Shadow-map side of the cleared maps.
const SHADOW_RES: u32 = 16;
/// Triangle index the CPU's shadow rays ignore (none: the scene is elsewhere).
const NO_TRIANGLE: u32 = u32::MAX;

/// A BVH over a unit box 9 km from the grids, so that no shadow ray meets anything.
fn far_bvh() -> Bvh {
    let mut scene = prm_scene::analytic::furnace_box(1, 0.5);
    for t in &mut scene.triangles {
        for p in &mut t.positions {
            *p += Vec3::new(3000.0, 7000.0, -5000.0);
        }
    }
    Bvh::build(&scene, &BvhParams::default()).expect("a BVH of the far box")
}

/// `w` turned by `deg` degrees towards `t` (both unit, `t ⟂ w`).
fn tilt(w: Vec3, t: Vec3, deg: f32) -> Vec3 {
    let (s, c) = deg.to_radians().sin_cos();
    (w * c + t * s).normalize()
}

/// An axis perpendicular to `w`, turned `az` radians about it.
fn perpendicular(w: Vec3, az: f32) -> Vec3 {
    let (a, b) = w.any_orthonormal_pair();
    a * az.cos() + b * az.sin()
}

/// Receiver normals: angle from the direction to the light, grazing and back-facing included.
const NORMAL_DEG: [f32; 9] = [0.0, 30.0, 60.0, 85.0, 89.9, 90.0, 90.1, 120.0, 180.0];
/// Tilts of the geometric normal from the shading normal, degrees.
const NG_TILT_DEG: [f32; 3] = [0.0, 10.0, -10.0];
/// Entry weights `A/N` (the disk is `ENTRY_DISK · A/(Nπ)`; 0: the plain point value).
const WEIGHTS: [f32; 5] = [0.0, 1e-6, 1e-3, 0.1, 1.0];
/// Distances from point and spot lights, from well inside the disk bound to far.
const DISTANCES: [f32; 8] = [1e-4, 1e-3, 1e-2, 0.05, 0.2, 1.0, 3.0, 8.0];

/// One input of the direct-light kernel; `Query` in its WGSL.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct LightQuery {
    position: [f32; 3],
    disk: f32,
    ng: [f32; 3],
    light: u32,
    n: [f32; 3],
    weight: f32,
}

const LIGHT_KERNEL: &str = "
struct Query {
    position: vec3<f32>,
    disk: f32,
    ng: vec3<f32>,
    light: u32,
    n: vec3<f32>,
    weight: f32,
};
@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> views: array<ShadowView>;
@group(0) @binding(3) var shadow_maps: texture_depth_2d_array;
@group(0) @binding(4) var<storage, read> queries: array<Query>;
@group(0) @binding(5) var<storage, read_write> out: array<vec4<f32>>;

fn answer(i: u32, q: Query) {
    out[3u * i] = vec4<f32>(light_irradiance_ng(q.light, q.position, q.ng, q.n, q.disk), 0.0);
    out[3u * i + 1u] = vec4<f32>(light_irradiance_disk(q.light, q.position, q.n, q.disk), 0.0);
    out[3u * i + 2u] = vec4<f32>(direct_irradiance_disk(q.position, q.n, q.disk), 0.0);
}
";

/// The entry point of a query kernel, after it: `answer(i, queries[i])` for every query `i`
/// (the kernel declares `Query`, `queries` and `answer`, which writes its results to `out`).
const QUERY_MAIN: &str = "
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&queries) {
        return;
    }
    answer(i, queries[i]);
}
";

/// Runs the query kernel ending `parts` (see [`QUERY_MAIN`]) once per element of `queries`,
/// with `bindings` first in group 0, then `queries`, then `out` with room for `per_query`
/// `vec4<f32>` results each, and returns those results.
fn run_queries<Q: Pod>(
    ctx: &prm_gpu_kit::GpuContext,
    label: &'static str,
    parts: &[&str],
    bindings: &[wgpu::BindingResource],
    queries: &[Q],
    per_query: usize,
) -> Vec<Vec3> {
    let d = &ctx.device;
    let query_buffer = buffer_init(d, "queries", bytemuck::cast_slice(queries), wgpu::BufferUsages::STORAGE);
    let out = storage(
        d,
        "out",
        (queries.len() * per_query * 16) as u64,
        wgpu::BufferUsages::COPY_SRC,
    );
    let mut resources = bindings.to_vec();
    resources.extend([query_buffer.as_entire_binding(), out.as_entire_binding()]);
    let bytes = run_kernel(
        ctx,
        label,
        &[parts, &[QUERY_MAIN]].concat(),
        &resources,
        queries.len() as u32,
        &out,
    );
    vec3s(&bytes)
}

/// The lights of the grid: a point light, spot lights narrow (one view), wide and beyond 60°
/// (a cube), directional lights from three sides.
fn grid_lights() -> Vec<Light> {
    let c = Vec3::new(0.3, 0.2, -0.1);
    let mut lights = vec![Light::Point {
        position: c,
        intensity: Vec3::new(10.0, 20.0, 5.0),
    }];
    for (deg, axis) in [
        (20.0f32, Vec3::NEG_Y),
        (45.0, Vec3::new(1.0, -2.0, 0.5)),
        (75.0, Vec3::X),
    ] {
        lights.push(Light::Spot {
            position: c + Vec3::new(0.5, -0.25, 0.125),
            direction: axis.normalize(),
            angle: deg.to_radians(),
            intensity: Vec3::new(3.0, 1.0, 7.0),
        });
    }
    // Rectangular spots: square and narrow, and one wide and tilted.
    for (half, axis, up) in [
        ([30.0f32, 30.0], Vec3::NEG_Y, Vec3::Z),
        ([50.0, 12.0], Vec3::new(1.0, -2.0, 0.5), Vec3::Y),
        ([80.0, 60.0], Vec3::X, Vec3::new(0.0, 1.0, 1.0)),
    ] {
        let direction = axis.normalize();
        lights.push(Light::Rect {
            position: c + Vec3::new(-0.25, 0.5, 0.125),
            direction,
            up: (up - up.dot(direction) * direction).normalize(),
            half_angles: half.map(f32::to_radians),
            intensity: Vec3::new(2.0, 6.0, 1.0),
        });
    }
    for d in [Vec3::NEG_Y, Vec3::new(1.0, -1.0, 0.3), Vec3::new(-0.2, 0.5, -1.0)] {
        lights.push(Light::Directional {
            direction: d.normalize(),
            irradiance: Vec3::new(2.0, 1.5, 0.25),
        });
    }
    lights
}

/// Magnitude of light `l` at `p` before its cosine (for the absolute tolerance).
fn light_scale(l: &Light, p: Vec3, disk: f32) -> f32 {
    match *l {
        Light::Point { position, intensity }
        | Light::Spot {
            position, intensity, ..
        }
        | Light::Rect {
            position, intensity, ..
        } => intensity.max_element() / (position.distance_squared(p) + disk),
        Light::Directional { irradiance, .. } => irradiance.max_element(),
    }
}

/// The receivers of light `k`: position, direction to the light, and a description.
fn receivers(k: usize, light: &Light) -> Vec<(Vec3, Vec3, String)> {
    let mut out = Vec::new();
    match *light {
        Light::Point { position, .. } | Light::Spot { position, .. } => {
            let (axis, off): (Vec3, Vec<f32>) = match *light {
                Light::Spot { direction, angle, .. } => {
                    let a = angle.to_degrees();
                    (
                        direction,
                        vec![0.0, 0.5 * a, a - 1.0, a + 1.0, (2.0 * a).min(170.0), 170.0],
                    )
                }
                _ => (Vec3::NEG_Y, vec![0.0, 50.0, 100.0, 150.0]),
            };
            for &o in &off {
                for az in [0.0f32, 2.1] {
                    let dir = tilt(axis, perpendicular(axis, az), o);
                    for &r in &DISTANCES {
                        let p = position + dir * r;
                        let wi = (position - p).normalize();
                        out.push((p, wi, format!("light {k} off-axis {o}° az {az} r {r}")));
                    }
                }
            }
        }
        Light::Rect {
            position,
            direction,
            up,
            half_angles,
            ..
        } => {
            // Inside, just inside and just outside each side and corner, far outside, behind.
            let right = direction.cross(up);
            let (tx, ty) = (half_angles[0].tan(), half_angles[1].tan());
            let mut dirs = Vec::new();
            for fx in [0.0f32, 0.5, 0.97, 1.03, 2.0] {
                for fy in [0.0f32, -0.5, 0.97, -1.03, 2.0] {
                    dirs.push((direction + right * (fx * tx) + up * (fy * ty)).normalize());
                }
            }
            dirs.push(-direction);
            for (i, dir) in dirs.iter().enumerate() {
                for &r in &DISTANCES {
                    let p = position + *dir * r;
                    let wi = (position - p).normalize();
                    out.push((p, wi, format!("light {k} frustum direction {i} r {r}")));
                }
            }
        }
        Light::Directional { direction, .. } => {
            for p in [
                Vec3::ZERO,
                Vec3::new(4.0, -3.0, 1.0),
                Vec3::new(-5.0, 5.0, -5.0),
                Vec3::splat(0.01),
            ] {
                out.push((p, -direction, format!("light {k} at {p}")));
            }
        }
    }
    out
}

/// The direct-light grid: every light, its receivers, normals and disks.
fn light_grid(lights: &[Light]) -> (Vec<LightQuery>, Vec<String>) {
    let mut queries = Vec::new();
    let mut names = Vec::new();
    for (k, light) in lights.iter().enumerate() {
        for (p, wi, name) in receivers(k, light) {
            let u = perpendicular(wi, 0.7);
            for &theta in &NORMAL_DEG {
                let n = tilt(wi, u, theta);
                for &delta in &NG_TILT_DEG {
                    let ng = if delta == 0.0 { n } else { tilt(wi, u, theta + delta) };
                    for &w in &WEIGHTS {
                        queries.push(LightQuery {
                            position: p.to_array(),
                            disk: ENTRY_DISK * w / std::f32::consts::PI,
                            ng: ng.to_array(),
                            light: k as u32,
                            n: n.to_array(),
                            weight: w,
                        });
                        names.push(format!("{name} normal {theta}° ng {delta:+}° weight {w}"));
                    }
                }
            }
        }
    }
    (queries, names)
}

/// The GPU lights, views, frame and cleared shadow maps of `lights`.
struct LightBindings {
    frame: wgpu::Buffer,
    lights: wgpu::Buffer,
    views: wgpu::Buffer,
    shadow_maps: wgpu::TextureView,
}

fn light_bindings(ctx: &prm_gpu_kit::GpuContext, lights: &[Light]) -> LightBindings {
    let (gpu_lights, views) = shadow_views(lights, &BOUNDS, SHADOW_RES, 1);
    let frame = GpuFrame {
        light_count: gpu_lights.len() as u32,
        shadow_resolution: SHADOW_RES as f32,
        normal_offset: 1.0,
        depth_bias: 1.0,
        ..Default::default()
    };
    let d = &ctx.device;
    LightBindings {
        frame: buffer_init(d, "frame", bytemuck::bytes_of(&frame), wgpu::BufferUsages::UNIFORM),
        lights: buffer_init(
            d,
            "lights",
            bytemuck::cast_slice(&gpu_lights),
            wgpu::BufferUsages::STORAGE,
        ),
        views: buffer_init(d, "views", bytemuck::cast_slice(&views), wgpu::BufferUsages::STORAGE),
        shadow_maps: cleared_depth_array(ctx, SHADOW_RES, views.len() as u32),
    }
}

fn vec3s(bytes: &[u8]) -> Vec<Vec3> {
    bytemuck::cast_slice::<u8, [f32; 4]>(bytes)
        .iter()
        .map(|v| Vec3::new(v[0], v[1], v[2]))
        .collect()
}

#[test]
fn the_query_struct_matches_its_wgsl() {
    let s = [SHARED_WGSL, LIGHTS_WGSL, LIGHT_KERNEL].join("\n");
    prm_gpu_kit::wgsl_layout!(&s, LightQuery, "Query", [position, disk, ng, light, n, weight]).unwrap();
}

#[test]
fn direct_light_agrees_with_the_cpu_on_every_light_kind() {
    let ctx = gpu();
    let lights = grid_lights();
    let bvh = far_bvh();
    let (queries, names) = light_grid(&lights);
    let b = light_bindings(&ctx, &lights);
    let gpu_values = run_queries(
        &ctx,
        "direct light estimators",
        &[SHARED_WGSL, LIGHTS_WGSL, LIGHT_KERNEL],
        &[
            b.frame.as_entire_binding(),
            b.lights.as_entire_binding(),
            b.views.as_entire_binding(),
            wgpu::BindingResource::TextureView(&b.shadow_maps),
        ],
        &queries,
        3,
    );
    let (mut with_ng, mut shading_only, mut all_lights) =
        (Agreement::default(), Agreement::default(), Agreement::default());
    // The n-only function against the CPU's ng test, where they are allowed to differ.
    let (mut ng_differences, mut ng_inputs, mut leak) = (0usize, 0usize, 0.0f32);
    for (i, (q, name)) in queries.iter().zip(&names).enumerate() {
        let (p, ng, n) = (Vec3::from(q.position), Vec3::from(q.ng), Vec3::from(q.n));
        let light = &lights[q.light as usize];
        let scale = light_scale(light, p, q.disk);
        let cpu = bounded_irradiance(&bvh, std::slice::from_ref(light), p, ng, n, NO_TRIANGLE, q.disk);
        with_ng.check(cpu, gpu_values[3 * i], scale, || name.clone());
        let cpu_n = bounded_irradiance(&bvh, std::slice::from_ref(light), p, n, n, NO_TRIANGLE, q.disk);
        shading_only.check(cpu_n, gpu_values[3 * i + 1], scale, || name.clone());
        if ng != n {
            ng_inputs += 1;
            let d = (cpu - gpu_values[3 * i + 1]).abs().max_element();
            if d > Agreement::RELATIVE * cpu.max_element().max(gpu_values[3 * i + 1].max_element())
                + Agreement::ABSOLUTE * scale
            {
                ng_differences += 1;
                leak = leak.max(d / scale);
            }
        }
        // Every light at once, as the weights pass lights an entry point (ng = n).
        let entry = SurfaceSample {
            position: p,
            normal: n,
            albedo: Vec3::ONE,
            triangle: NO_TRIANGLE,
            barycentric: glam::Vec2::ZERO,
            weight: q.weight,
        };
        let cpu_all = entry_irradiance(&bvh, &lights, &[entry])[0];
        let scale_all: f32 = lights.iter().map(|l| light_scale(l, p, q.disk)).sum();
        all_lights.check(cpu_all, gpu_values[3 * i + 2], scale_all, || name.clone());
    }
    eprintln!(
        "light_irradiance_disk (n only) vs bounded_irradiance (n and ng): {ng_differences} of {ng_inputs} inputs with ng ≠ n differ, by up to {leak:.3} of the light's value before its cosine"
    );
    with_ng.assert("light_irradiance_ng vs bounded_irradiance");
    shading_only.assert("light_irradiance_disk vs bounded_irradiance (ng = n)");
    all_lights.assert("direct_irradiance_disk vs entry_irradiance");
    assert!(ng_differences > 0, "the grid no longer reaches the ng terminator");
}

/// One receiver of the VPL kernel with its bound; `Query` in its WGSL.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct VplQuery {
    x: [f32; 3],
    kind: u32,
    nx: [f32; 3],
    value: f32,
}

const VPL_KERNEL: &str = "
struct Query {
    x: vec3<f32>,
    kind: u32,
    nx: vec3<f32>,
    value: f32,
};
@group(0) @binding(0) var<storage, read> vpls: array<Vpl>;
@group(0) @binding(1) var<storage, read> queries: array<Query>;
@group(0) @binding(2) var<storage, read_write> out: array<vec4<f32>>;

fn answer(i: u32, q: Query) {
    out[i] = vpl_irradiance(vpls[i], q.x, q.nx, q.kind, q.value);
}
";

#[test]
fn the_vpl_query_struct_matches_its_wgsl() {
    let s = [HEMICUBE_WGSL, VPL_WGSL, VPL_KERNEL].join("\n");
    prm_gpu_kit::wgsl_layout!(&s, VplQuery, "Query", [x, kind, nx, value]).unwrap();
}

#[test]
fn vpl_irradiance_agrees_with_the_cpu_on_every_bound() {
    let ctx = gpu();
    let bounds = [
        VplBound::None,
        VplBound::Clamp { min_distance: 0.01 },
        VplBound::Clamp { min_distance: 0.1 },
        VplBound::Disk { scale: 0.5 },
        VplBound::DEFAULT,
        VplBound::Disk { scale: 2.0 },
        VplBound::Near { scale: 1.0 },
        VplBound::Near { scale: 4.0 },
    ];
    let normal = Vec3::new(0.2, 1.0, -0.3).normalize();
    let mut cpu_vpls = Vec::new();
    let mut gpu_vpls = Vec::new();
    let mut queries = Vec::new();
    let mut cases = Vec::new();
    for area in [1e-4f32, 1e-2, 0.5] {
        let vpl = Vpl {
            position: Vec3::new(-0.4, 0.1, 0.7),
            normal,
            power: Vec3::new(0.2, 0.5, 1.0),
            area,
            triangle: 0,
            entry: 0,
            depth: 0,
        };
        // Directions from the VPL to the receiver, by angle from its normal (beyond 90°: behind).
        for theta_v in [0.0f32, 30.0, 60.0, 89.9, 90.1, 120.0, 180.0] {
            for az in [0.0f32, 2.5] {
                let dir = tilt(normal, perpendicular(normal, az), theta_v);
                for r in [1e-4f32, 1e-3, 0.01, 0.05, 0.2, 1.0, 5.0] {
                    let x = vpl.position + dir * r;
                    let to_vpl = (vpl.position - x).normalize();
                    for theta_x in [0.0f32, 45.0, 85.0, 89.9, 90.1, 135.0] {
                        let nx = tilt(to_vpl, perpendicular(to_vpl, 1.3), theta_x);
                        for bound in bounds {
                            let (kind, value) = VplBoundKind::of(bound);
                            cpu_vpls.push(vpl);
                            gpu_vpls.push(GpuVpl::new(vpl.position, vpl.normal, vpl.power, vpl.area, 0));
                            queries.push(VplQuery {
                                x: x.to_array(),
                                kind: kind as u32,
                                nx: nx.to_array(),
                                value,
                            });
                            cases.push((
                                x,
                                nx,
                                bound,
                                format!("area {area} θ_v {theta_v}° az {az} r {r} θ_x {theta_x}° {bound:?}"),
                            ));
                        }
                    }
                }
            }
        }
    }
    let d = &ctx.device;
    let vpl_buffer = buffer_init(d, "vpls", bytemuck::cast_slice(&gpu_vpls), wgpu::BufferUsages::STORAGE);
    let gpu_values = run_queries(
        &ctx,
        "vpl estimator",
        &[HEMICUBE_WGSL, VPL_WGSL, VPL_KERNEL],
        &[vpl_buffer.as_entire_binding()],
        &queries,
        1,
    );
    let mut agreement = Agreement::default();
    for (i, (x, nx, bound, name)) in cases.iter().enumerate() {
        let v = &cpu_vpls[i];
        let cpu = bound.irradiance(v, *x, *nx);
        let scale = v.power.max_element()
            * std::f32::consts::FRAC_1_PI
            * bound.inverse_square(v.position.distance_squared(*x), v);
        agreement.check(cpu, gpu_values[i], scale, || name.clone());
    }
    agreement.assert("vpl_irradiance vs VplBound::irradiance");
}

#[test]
fn the_weights_pass_agrees_with_the_cpu_weights() {
    let ctx = gpu();
    let lights = grid_lights();
    let bvh = far_bvh();
    // Entry points (ng = n) from the direct-light grid, in clusters of 1 to 70 members (past the
    // pass's 32 lanes), with pane energies that vary by channel and are sometimes zero.
    let (queries, _) = light_grid(&lights);
    let entries: Vec<SurfaceSample> = queries
        .iter()
        .filter(|q| q.ng == q.n)
        .step_by(7)
        .map(|q| SurfaceSample {
            position: Vec3::from(q.position),
            normal: Vec3::from(q.n),
            albedo: Vec3::ONE,
            triangle: NO_TRIANGLE,
            barycentric: glam::Vec2::ZERO,
            weight: q.weight,
        })
        .collect();
    let energy: Vec<Vec3> = (0..entries.len())
        .map(|k| {
            let h = |s: usize| ((k * 2654435761 + s * 40503) % 1000) as f32 / 1000.0;
            Vec3::new(h(1), if k % 5 == 0 { 0.0 } else { h(2) }, 3.0 * h(3))
        })
        .collect();
    let mut members = Vec::new();
    let mut at = 0u32;
    let mut size = 1u32;
    while (at as usize) < entries.len() {
        let end = (at + size).min(entries.len() as u32);
        members.push((at..end).collect::<Vec<u32>>());
        at = end;
        size = size % 70 + 13;
    }
    let clustering = Clustering {
        of_entry: members
            .iter()
            .enumerate()
            .flat_map(|(c, m)| m.iter().map(move |_| c as u32))
            .collect(),
        centroids: vec![Vec3::ZERO; members.len()],
        normals: vec![Vec3::Y; members.len()],
        members,
    };
    // Each entry's cell: 0 to 5 points around it, off its plane a little and tilted.
    let mut cells = EntryCells::default();
    for (k, e) in entries.iter().enumerate() {
        let (t, b) = e.normal.any_orthonormal_pair();
        for j in 0..k % 6 {
            let a = j as f32 * 2.1 + k as f32;
            let offset = (t * a.cos() + b * a.sin()) * (0.02 + 0.01 * j as f32) + e.normal * 0.001;
            let normal = (e.normal + t * (0.1 * j as f32)).normalize();
            cells
                .points
                .push(CellPoint::new(offset.to_array(), normal.to_array()).unwrap());
        }
        cells.ends.push(cells.points.len() as u32);
    }
    let b = light_bindings(&ctx, &lights);
    let clusters: Vec<GpuCluster> = clustering
        .members
        .iter()
        .map(|m| GpuCluster {
            first: m[0],
            count: m.len() as u32,
            energy: [1.0, 0.5, 0.25],
            ..Default::default()
        })
        .collect();
    let frame = GpuFrame {
        light_count: lights.len() as u32,
        cluster_count: clusters.len() as u32,
        entry_count: entries.len() as u32,
        shadow_resolution: SHADOW_RES as f32,
        normal_offset: 1.0,
        depth_bias: 1.0,
        ..Default::default()
    };
    let d = &ctx.device;
    let frame = buffer_init(d, "frame", bytemuck::bytes_of(&frame), wgpu::BufferUsages::UNIFORM);
    let cluster_buffer = buffer_init(
        d,
        "clusters",
        bytemuck::cast_slice(&clusters),
        wgpu::BufferUsages::STORAGE,
    );
    let packed: Vec<[u32; 2]> = cells.points.iter().map(|p| p.packed()).collect();
    let points_buffer = buffer_init(
        d,
        "cell points",
        bytemuck::cast_slice(&packed),
        wgpu::BufferUsages::STORAGE,
    );
    // Without cells; with cells and every light far (each at the entry point times the cell's
    // area); with cells and every light near (over the cell's points).
    for reach2 in [None, Some(0.0), Some(f32::MAX)] {
        let with_cells = reach2.is_some();
        let irradiance = match reach2 {
            Some(reach2) => {
                let positions: Vec<Vec3> = entries.iter().map(|e| e.position).collect();
                let normals: Vec<Vec3> = entries.iter().map(|e| e.normal).collect();
                prm_trace::cell_irradiance(&bvh, &lights, &positions, &normals, &cells, reach2)
            }
            None => entry_irradiance(&bvh, &lights, &entries),
        };
        let cpu = clustering.weights_by_energy(&irradiance, &energy);
        let gpu_entries: Vec<GpuEntry> = entries
            .iter()
            .zip(&energy)
            .enumerate()
            .map(|(k, (e, en))| GpuEntry {
                position: e.position.to_array(),
                disk: reach2.unwrap_or(ENTRY_DISK * e.weight / std::f32::consts::PI),
                normal: e.normal.to_array(),
                energy: en.to_array(),
                cell_first: if k == 0 { 0 } else { cells.ends[k - 1] },
                cell_count: cells.points_of(k).len() as u32,
                cell_weight: if with_cells { cells.point_weight() } else { 0.0 },
                ..Default::default()
            })
            .collect();
        let entry_buffer = buffer_init(
            d,
            "entries",
            bytemuck::cast_slice(&gpu_entries),
            wgpu::BufferUsages::STORAGE,
        );
        let out = storage(
            d,
            "weights",
            (clusters.len() * std::mem::size_of::<GpuWeight>()) as u64,
            wgpu::BufferUsages::COPY_SRC,
        );
        // The kernel is the pass itself, one workgroup per cluster (run_kernel dispatches count / 64).
        let bytes = run_kernel(
            &ctx,
            "weights pass",
            &[
                SHARED_WGSL,
                LIGHTS_WGSL,
                include_str!("../shaders/runtime/weights.wgsl"),
            ],
            &[
                frame.as_entire_binding(),
                b.lights.as_entire_binding(),
                b.views.as_entire_binding(),
                wgpu::BindingResource::TextureView(&b.shadow_maps),
                cluster_buffer.as_entire_binding(),
                entry_buffer.as_entire_binding(),
                points_buffer.as_entire_binding(),
                out.as_entire_binding(),
            ],
            clusters.len() as u32 * 64,
            &out,
        );
        let weights: &[GpuWeight] = bytemuck::cast_slice(&bytes);
        let mut agreement = Agreement::default();
        for (c, m) in clustering.members.iter().enumerate() {
            // Scale: the largest member irradiance (a weight is a weighted mean of them).
            let scale = m
                .iter()
                .map(|&k| irradiance[k as usize].max_element())
                .fold(1e-30f32, f32::max);
            agreement.check(cpu[c], Vec3::from(weights[c].weight), scale, || {
                format!("cluster {c} ({} members from {}), reach² {reach2:?}", m.len(), m[0])
            });
            let score = cpu[c].dot(Vec3::new(1.0, 0.5, 0.25));
            agreement.check(Vec3::splat(score), Vec3::splat(weights[c].score), scale, || {
                format!("score of cluster {c}, reach² {reach2:?}")
            });
        }
        agreement.assert(if with_cells {
            "weights.wgsl vs Clustering::weights_by_energy over the entry cells"
        } else {
            "weights.wgsl vs Clustering::weights_by_energy"
        });
    }
}
