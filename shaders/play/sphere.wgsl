// prm-play probe sphere: a moving object lit by the probes, radiance = albedo/π × (direct
// irradiance through the run time's shadow maps + the probe volume's indirect irradiance at the
// sphere's centre for each normal). Comes after the run time's shared.wgsl, light_bindings.wgsl
// (bindings 0 to 3), lights.wgsl and probe_volume.wgsl, and play/camera.wgsl. The sphere casts no shadow and the scene's panes do
// not see it: it receives light only.

struct Sphere {
    centre: vec3<f32>,
    radius: f32,
    albedo: vec3<f32>,
    _pad0: f32,
};

@group(0) @binding(4) var<uniform> camera: Camera;
@group(0) @binding(5) var<uniform> sphere: Sphere;
@group(0) @binding(6) var<uniform> probe_grid: ProbeGrid;
@group(0) @binding(7) var<storage, read> probe_cells: array<i32>;
@group(0) @binding(8) var<storage, read> probe_sh: array<vec4<f32>>;

struct VsIn {
    // A point of the unit sphere (also its normal).
    @location(0) unit: vec3<f32>,
};

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
};

@vertex
fn vs_main(v: VsIn) -> VsOut {
    var o: VsOut;
    o.position = sphere.centre + sphere.radius * v.unit;
    o.normal = v.unit;
    o.clip = camera.view_proj * vec4<f32>(o.position, 1.0);
    return o;
}

@fragment
fn fs_main(v: VsOut) -> @location(0) vec4<f32> {
    let n = normalize(v.normal);
    var mode = camera.mode;
    if mode == MODE_SPLIT {
        mode = select(MODE_GI, MODE_DIRECT, v.clip.x < camera.width * 0.5);
    }
    var e = vec3<f32>(0.0);
    if mode != MODE_INDIRECT {
        e += direct_irradiance_ng(v.position, n, n, 0.0);
    }
    if mode != MODE_DIRECT {
        e += probe_irradiance(sphere.centre, n);
    }
    return vec4<f32>(sphere.albedo / 3.14159265358979 * e, 1.0);
}
