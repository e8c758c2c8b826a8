// vpl_depth: distance of the scene from one VPL through one hemicube face (one array layer per pass).
// Prepended with hemicube.wgsl. The depth written is the radial distance / far, linear and exact per
// fragment, so the gather pass can compare distances with a bias in scene units.

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

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel: vec3<f32>,
}

@vertex
fn vs_main(@location(0) p: vec3<f32>) -> VertexOut {
    let v = vpls[select_face.vpl];
    let origin = v.position + v.normal * frame.lift;
    let l = vpl_local(v, p - origin);
    return VertexOut(hemicube_clip(l, select_face.face, frame.near, frame.far), l);
}

@fragment
fn fs_main(in: VertexOut) -> @builtin(frag_depth) f32 {
    return length(in.rel) / frame.far;
}
