// prm-runtime shadow pass: the scene's depth as seen by one shadow view (a cube face of a point
// light, a spot light's frustum or a directional light's orthographic box), one layer per view.

@group(0) @binding(0) var<uniform> view_proj: mat4x4<f32>;

@vertex
fn vs_main(@location(0) position: vec3<f32>) -> @builtin(position) vec4<f32> {
    return view_proj * vec4<f32>(position, 1.0);
}
