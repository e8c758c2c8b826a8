// vpl_depth: depth of the scene seen from one VPL through one hemicube face (faces tiled in array layers).
// Prepended with hemicube.wgsl. Depth-only: no fragment shader, so the rasteriser's fast path runs;
// the stored depth is the standard perspective one, which the gather pass turns back into a
// distance along the face axis before comparing with a bias in scene units.

// prm-gpu's DepthFrame and FaceSelect (crates/prm-gpu/src/vpl_depth.rs), checked there through naga.
struct DepthFrame {
    near: f32,
    far: f32,
    lift: f32,
    _pad: f32,
}

struct FaceSelect {
    vpl: u32,
    face: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<storage, read> vpls: array<Vpl>;
@group(0) @binding(1) var<uniform> frame: DepthFrame;
@group(1) @binding(0) var<uniform> select_face: FaceSelect;

@vertex
fn vs_main(@location(0) p: vec3<f32>) -> @builtin(position) vec4<f32> {
    let v = vpls[select_face.vpl];
    let origin = v.position + v.normal * frame.lift;
    return hemicube_clip(vpl_local(v, p - origin), select_face.face, frame.near, frame.far);
}
