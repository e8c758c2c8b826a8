// prm-runtime: the direct irradiance of a point from every light, with shadow-map visibility.
// Shared by the passes that light points (weights.wgsl here, and an engine's or prm-play's
// shading); comes after shared.wgsl. The including pass declares `frame: Frame`,
// `lights: array<Light>`, `views: array<ShadowView>` and `shadow_maps: texture_depth_2d_array`
// (light_bindings.wgsl declares them as bindings 0 to 3 of group 0).

// Linear depth (distance along the view axis) of a stored depth-buffer value.
fn linear_depth(z: f32, v: ShadowView) -> f32 {
    let n = v.near;
    let f = v.far;
    if v.orthographic != 0u {
        return n + z * (f - n);
    }
    return n * f / (f - z * (f - n));
}

// Most shadow texels per texel of depth tolerance (`frame.depth_bias`) that a lookup takes for
// light at a grazing angle: the tolerance grows with the tangent of the light's angle from the
// normal, from 1 (light within 45° of the normal) to this (76°). RuntimeOptions::
// DEFAULT_NORMAL_OFFSET (crates/prm-runtime/src/options.rs) records the measurement.
const DEPTH_BIAS_MAX_SLOPE: f32 = 4.0;

// Fraction of the light `l` that reaches `p` (surface normal `n`, `cos_t` the cosine of the
// light's angle from it), 2×2 percentage-closer filter.
// The lookup moves `p` along `n` by `frame.normal_offset` shadow texels, and its depth
// tolerance is `frame.depth_bias` texels times the slope above: the filter's taps a texel away
// on a surface the light grazes lie deeper by about the tangent, which a small normal offset
// alone no longer covers (acne), and a larger one widens every lit area past its shadows.
fn visibility(l: Light, p: vec3<f32>, n: vec3<f32>, dist: f32, cos_t: f32) -> f32 {
    let cos_c = clamp(cos_t, 1e-3, 1.0);
    let slope = clamp(sqrt(1.0 - cos_c * cos_c) / cos_c, 1.0, DEPTH_BIAS_MAX_SLOPE);
    var face = 0u;
    if l.kind == LIGHT_DIRECTIONAL && l.view_count > 1u {
        // A tiled orthographic map (lights.rs): the tile under the looked-up point (p moved
        // along n as below; every tile has the same texel), row-major from the map's
        // bottom-left; position is the map's centre, tan_x half its side, up its vertical (unit and
        // perpendicular to direction, so direction × up is the map's unit horizontal).
        let tiles = u32(round(sqrt(f32(l.view_count))));
        let d = p + n * (frame.normal_offset * views[l.first_view].texel) - l.position;
        let xy = vec2<f32>(dot(d, cross(l.direction, l.up)), dot(d, l.up));
        let cell = clamp(floor((xy + l.tan_x) / (2.0 * l.tan_x) * f32(tiles)), vec2<f32>(0.0), vec2<f32>(f32(tiles - 1u)));
        face = u32(cell.y) * tiles + u32(cell.x);
    } else if l.view_count == 6u {
        let d = p - l.position;
        let a = abs(d);
        if a.x >= a.y && a.x >= a.z {
            face = select(1u, 0u, d.x > 0.0);
        } else if a.y >= a.z {
            face = select(3u, 2u, d.y > 0.0);
        } else {
            face = select(5u, 4u, d.z > 0.0);
        }
    }
    let layer = l.first_view + face;
    let v = views[layer];
    let ortho = v.orthographic != 0u;
    let texel = select(v.texel * dist, v.texel, ortho);
    let q = p + n * (frame.normal_offset * texel);
    let c = v.view_proj * vec4<f32>(q, 1.0);
    let ndc = c.xyz / c.w;
    if c.w <= 0.0 || any(abs(ndc.xy) > vec2<f32>(1.0)) {
        return 1.0;
    }
    var mine = c.w;
    if ortho {
        mine = linear_depth(ndc.z, v);
    }
    let bias = frame.depth_bias * texel * slope;
    let res = frame.shadow_resolution;
    let uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5) * res - 0.5;
    let base = floor(uv);
    let f = uv - base;
    let hi = i32(res) - 1;
    var lit = array<f32, 4>(0.0, 0.0, 0.0, 0.0);
    for (var k = 0; k < 4; k++) {
        let t = clamp(vec2<i32>(base) + vec2<i32>(k & 1, k >> 1), vec2<i32>(0), vec2<i32>(hi));
        let stored = linear_depth(textureLoad(shadow_maps, t, i32(layer), 0), v);
        lit[k] = select(0.0, 1.0, mine <= stored + bias);
    }
    return mix(mix(lit[0], lit[1], f.x), mix(lit[2], lit[3], f.x), f.y);
}

// Direct irradiance (RGB, W/m²) at `p` with unit normal `n` from light `i`.
fn light_irradiance(i: u32, p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return light_irradiance_disk(i, p, n, 0.0);
}

// Irradiance from light i at p, a point that stands for a disk of radius² `disk`: the
// inverse square of point and spot lights becomes 1 / (r² + disk) (0: the plain point value).
// The receiving normal n is also taken for the surface's geometric normal; see
// light_irradiance_ng where they differ.
fn light_irradiance_disk(i: u32, p: vec3<f32>, n: vec3<f32>, disk: f32) -> vec3<f32> {
    return light_irradiance_ng(i, p, n, n, disk);
}

// light_irradiance_disk on a surface of unit geometric normal ng shaded with unit normal n: zero
// unless the light is above both, as prm-trace's bounded_irradiance (crates/prm-trace/src/direct.rs,
// tested against this in tests/estimators.rs). A light below the geometric plane lies behind the
// surface itself, which the shadow map (normal-offset along n) does not see: without the ng test
// such a light leaks onto a smooth-shaded surface past its terminator.
fn light_irradiance_ng(i: u32, p: vec3<f32>, ng: vec3<f32>, n: vec3<f32>, disk: f32) -> vec3<f32> {
    let l = lights[i];
    var wi: vec3<f32>;
    var scale: vec3<f32>;
    var dist = 1.0;
    if l.kind == LIGHT_DIRECTIONAL {
        wi = -l.direction;
        scale = l.color;
    } else {
        let d = l.position - p;
        dist = max(length(d), 1e-6);
        wi = d / dist;
        scale = l.color / (dist * dist + disk);
        if l.kind == LIGHT_SPOT && dot(-wi, l.direction) < l.cos_cutoff {
            return vec3<f32>(0.0);
        }
        if l.kind == LIGHT_RECT {
            // Inside the frustum, boundaries included (prm_scene::Light::emits_towards).
            let z = dot(-wi, l.direction);
            let x = dot(-wi, cross(l.direction, l.up));
            let y = dot(-wi, l.up);
            if z <= 0.0 || abs(x) > z * l.tan_x || abs(y) > z * l.tan_y {
                return vec3<f32>(0.0);
            }
        }
    }
    let cos_t = dot(n, wi);
    if cos_t <= 0.0 || dot(ng, wi) <= 0.0 {
        return vec3<f32>(0.0);
    }
    return scale * cos_t * visibility(l, p, n, dist, cos_t);
}

// Direct irradiance (RGB, W/m²) at `p` with unit normal `n` from every light.
fn direct_irradiance(p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return direct_irradiance_disk(p, n, 0.0);
}

// direct_irradiance at a point standing for a disk of radius² `disk` (see light_irradiance_disk).
fn direct_irradiance_disk(p: vec3<f32>, n: vec3<f32>, disk: f32) -> vec3<f32> {
    return direct_irradiance_ng(p, n, n, disk);
}

// direct_irradiance_disk with a geometric normal ng apart from the shading normal n (see
// light_irradiance_ng).
fn direct_irradiance_ng(p: vec3<f32>, ng: vec3<f32>, n: vec3<f32>, disk: f32) -> vec3<f32> {
    var e = vec3<f32>(0.0);
    // The bound also reads the lights buffer's length: a loop bounded by a uniform alone is
    // specialised by lavapipe to the uniform's value, and with two lights that specialisation
    // is redone, and its memory kept, on every draw (3 MB a frame).
    let count = min(frame.light_count, arrayLength(&lights));
    for (var i = 0u; i < count; i++) {
        e += light_irradiance_ng(i, p, ng, n, disk);
    }
    return e;
}
