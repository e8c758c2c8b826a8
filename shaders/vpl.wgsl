// vpl: the unoccluded irradiance a VPL gives a receiver, with the bound of its 1/r² singularity;
// the GPU twin of prm-trace's VplBound (crates/prm-trace/src/vpl.rs), tested function against
// function in tests/estimators.rs. Comes after hemicube.wgsl (struct Vpl); declares no bindings.
// The bound codes are prm-gpu's VplBoundKind (crates/prm-gpu/src/pane_gather.rs).

// Plain 1/r².
const VPL_BOUND_NONE: u32 = 0u;
// 1/max(r², value), value = d_min².
const VPL_BOUND_CLAMP: u32 = 1u;
// 1/(r² + value · area), value = scale²/π.
const VPL_BOUND_DISK: u32 = 2u;
// 1/max(r², VPL_NEAR_KEEP · (r² + value · area)), value = scale²/π: the complement of a near
// field's cut weights (prm-trace's VplBound::Near).
const VPL_BOUND_NEAR: u32 = 3u;
// 1 − the near field's cut, prm-trace's NEAR_KEEP (checked in prm-gpu's pane_gather.rs).
const VPL_NEAR_KEEP: f32 = 0.9375;

const INV_PI: f32 = 0.31830988618379067;

// The bounded replacement for 1/r² (bound `kind`, parameter `value`) of a VPL of area `area`.
fn inverse_square(r2: f32, area: f32, kind: u32, value: f32) -> f32 {
    if (kind == VPL_BOUND_CLAMP) {
        return 1.0 / max(r2, value);
    }
    if (kind == VPL_BOUND_DISK) {
        return 1.0 / (r2 + value * area);
    }
    if (kind == VPL_BOUND_NEAR) {
        return 1.0 / max(r2, VPL_NEAR_KEEP * (r2 + value * area));
    }
    return 1.0 / r2;
}

// Unoccluded irradiance of VPL v at x (unit normal nx), per unit entry irradiance, in rgb, and
// cos θ_x in a: all zero when either side faces away or x is at the VPL.
fn vpl_irradiance(v: Vpl, x: vec3<f32>, nx: vec3<f32>, kind: u32, value: f32) -> vec4<f32> {
    let d = v.position - x;
    let r2 = dot(d, d);
    if (r2 <= 0.0) {
        return vec4<f32>(0.0);
    }
    let r = sqrt(r2);
    let cx = dot(nx, d) / r;
    let cv = -dot(v.normal, d) / r;
    if (cx <= 0.0 || cv <= 0.0) {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(v.power * (INV_PI * cx * cv * inverse_square(r2, v.area, kind, value)), cx);
}
