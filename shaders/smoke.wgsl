// smoke: y[i] = a * x[i] + b for every element; proves a device can compile, dispatch and read back.

struct Params {
    a: f32,
    b: f32,
    count: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> xs: array<f32>;
@group(0) @binding(2) var<storage, read_write> ys: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i < params.count) {
        ys[i] = params.a * xs[i] + params.b;
    }
}
