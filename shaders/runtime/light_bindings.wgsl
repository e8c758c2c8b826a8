// prm-runtime: what lights.wgsl reads, bound as group 0, bindings 0 to 3, in the order
// prm_runtime::DirectLight::resources gives them. Comes after shared.wgsl; the including shader
// binds its own resources from binding 4.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> views: array<ShadowView>;
@group(0) @binding(3) var shadow_maps: texture_depth_2d_array;
