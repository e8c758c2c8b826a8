// prm-play camera: the view and the mode every player pass draws with (shade.wgsl, sphere.wgsl).

// What a frame shows (prm_play::Mode).
const MODE_GI: u32 = 0u;
const MODE_DIRECT: u32 = 1u;
const MODE_INDIRECT: u32 = 2u;
// Left half direct, right half gi.
const MODE_SPLIT: u32 = 3u;

struct Camera {
    view_proj: mat4x4<f32>,
    eye: vec3<f32>,
    mode: u32,
    // image width in pixels (split mode)
    width: f32,
    _pad0: f32,
    _pad1: f32,
    _pad2: f32,
};
