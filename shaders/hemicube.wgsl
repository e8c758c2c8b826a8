// hemicube: the five faces around a VPL's normal, shared by vpl_depth and pane_gather (prepended to both).
//
// A VPL's local frame is (t, b, n), computed once on the CPU. Face 0 looks along n; faces 1-4 along +t, -t, +b, -b and keep
// only their upper half (local z >= 0), stretched over the whole face. Clip w is the distance
// along the face axis, so perspective division gives the face coordinates and depth.

// Faces per VPL (prm-gpu's FACES): depth layer tile i holds face i % 5 of VPL i / 5.
const HEMICUBE_FACES: u32 = 5u;

// A VPL with its hemicube frame; prm-gpu's GpuVpl (crates/prm-gpu/src/vpl_depth.rs).
struct Vpl {
    position: vec3<f32>,
    area: f32,
    normal: vec3<f32>,
    cluster: u32,
    power: vec3<f32>,
    _pad0: f32,
    tangent: vec3<f32>,
    _pad1: f32,
    bitangent: vec3<f32>,
    _pad2: f32,
}

// Local coordinates (along tangent, bitangent, normal) of world offset d from the VPL.
fn vpl_local(v: Vpl, d: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(d, v.tangent), dot(d, v.bitangent), dot(d, v.normal));
}

// Which face sees local direction l (l.z >= 0).
fn hemicube_face(l: vec3<f32>) -> u32 {
    let a = abs(l);
    if (l.z >= a.x && l.z >= a.y) {
        return 0u;
    }
    if (a.x >= a.y) {
        return select(2u, 1u, l.x > 0.0);
    }
    return select(4u, 3u, l.y > 0.0);
}

// Clip-space position of local point l on face f; depth is 0 at `near` and 1 at `far`.
fn hemicube_clip(l: vec3<f32>, f: u32, near: f32, far: f32) -> vec4<f32> {
    var uv: vec2<f32>;
    var w: f32;
    switch f {
        case 0u: {
            uv = l.xy;
            w = l.z;
        }
        case 1u: {
            uv = vec2<f32>(l.y, 2.0 * l.z - l.x);
            w = l.x;
        }
        case 2u: {
            uv = vec2<f32>(-l.y, 2.0 * l.z + l.x);
            w = -l.x;
        }
        case 3u: {
            uv = vec2<f32>(-l.x, 2.0 * l.z - l.y);
            w = l.y;
        }
        default: {
            uv = vec2<f32>(l.x, 2.0 * l.z + l.y);
            w = -l.y;
        }
    }
    let z = (w - near) * far / (far - near);
    return vec4<f32>(uv, z, w);
}
