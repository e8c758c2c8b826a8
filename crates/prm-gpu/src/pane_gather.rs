//! The pane gather pass (`shaders/pane_gather.wgsl`): adds a batch of VPLs, with depth-map
//! visibility, into the panes of their clusters at every exit point.

use bytemuck::{Pod, Zeroable};
use prm_gpu_kit::ComputePass;
use prm_trace::VplBound;

use crate::vpl_depth::HEMICUBE_WGSL;

/// The VPL estimator and its bound (`shaders/vpl.wgsl`), the GPU twin of
/// [`VplBound::irradiance`]; needs [`HEMICUBE_WGSL`] before it and declares no bindings.
pub const VPL_WGSL: &str = include_str!("../../../shaders/vpl.wgsl");
/// The gather pass (`shaders/pane_gather.wgsl`); needs [`HEMICUBE_WGSL`] and [`VPL_WGSL`] before it.
pub const PANE_GATHER_WGSL: &str = include_str!("../../../shaders/pane_gather.wgsl");

/// How the `1/r²` of a VPL is bounded on the GPU, as [`GatherParams::bound_kind`] holds it (the
/// `VPL_BOUND_*` constants of `vpl.wgsl`); [`VplBoundKind::of`] gives it with its parameter.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VplBoundKind {
    /// `VPL_BOUND_NONE`: plain `1/r²`.
    None = 0,
    /// `VPL_BOUND_CLAMP`: `1/max(r², value)`, value `d_min²`.
    Clamp = 1,
    /// `VPL_BOUND_DISK`: `1/(r² + value · area)`, value `scale²/π`.
    Disk = 2,
    /// `VPL_BOUND_NEAR`: `1/max(r², (1 − w₀)(r² + value · area))`, value `scale²/π`.
    Near = 3,
}

impl VplBoundKind {
    /// The code and parameter (`bound_value`) the shader evaluates `bound` with.
    pub fn of(bound: VplBound) -> (VplBoundKind, f32) {
        match bound {
            VplBound::None => (VplBoundKind::None, 0.0),
            VplBound::Clamp { min_distance } => (VplBoundKind::Clamp, min_distance * min_distance),
            VplBound::Disk { scale } => (VplBoundKind::Disk, scale * scale * std::f32::consts::FRAC_1_PI),
            VplBound::Near { scale } => (VplBoundKind::Near, scale * scale * std::f32::consts::FRAC_1_PI),
        }
    }
}

/// An exit point as the GPU sees it; layout shared with WGSL.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuExit {
    /// Position.
    pub position: [f32; 3],
    /// Padding.
    pub _pad0: f32,
    /// Unit normal.
    pub normal: [f32; 3],
    /// Padding.
    pub _pad1: f32,
}
const _: () = assert!(std::mem::size_of::<GpuExit>() == 32);

/// Uniforms of one gather dispatch; layout shared with WGSL.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GatherParams {
    /// Exit points.
    pub exit_count: u32,
    /// VPLs in the batch.
    pub vpl_count: u32,
    /// Cluster stored at slot 0 of the pane buffer.
    pub first_cluster: u32,
    /// [`VplBoundKind`] as `u32`.
    pub bound_kind: u32,
    /// Parameter of the bound: clamp `d_min²`, disk `scale²/π` (see [`VplBoundKind::of`]).
    pub bound_value: f32,
    /// Hemicube near plane.
    pub near: f32,
    /// Hemicube far plane.
    pub far: f32,
    /// VPL lift off its surface.
    pub lift: f32,
    /// Receiver offset along its normal.
    pub receiver_offset: f32,
    /// Constant distance bias, scene units.
    pub bias_constant: f32,
    /// Slope bias, in depth texels (multiplied by the texel footprint and tan θ of the receiver).
    pub bias_slope: f32,
    /// Angle subtended by one depth texel at the face centre, radians.
    pub texel_angle: f32,
    /// [`DepthFilter`](crate::DepthFilter) as `u32`.
    pub depth_filter: u32,
    /// Texels on a side of a hemicube face.
    pub face_resolution: u32,
    /// Faces on a row of a depth layer.
    pub faces_per_row: u32,
    /// Padding.
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<GatherParams>() == 64);

/// Pipeline and bindings of the gather pass.
pub struct PaneGatherPass(ComputePass);

impl PaneGatherPass {
    /// Creates the pass over the given buffers and depth array.
    pub fn new(
        device: &wgpu::Device,
        vpls: &wgpu::Buffer,
        exits: &wgpu::Buffer,
        panes: &wgpu::Buffer,
        params: &wgpu::Buffer,
        depth: &wgpu::TextureView,
    ) -> PaneGatherPass {
        // Bilinear comparison: 2×2 percentage-closer filtering softens the depth maps' texels.
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("pane_gather shadow"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            compare: Some(wgpu::CompareFunction::LessEqual),
            ..Default::default()
        });
        PaneGatherPass(ComputePass::new(
            device,
            "pane_gather",
            &[HEMICUBE_WGSL, VPL_WGSL, PANE_GATHER_WGSL],
            &[
                vpls.as_entire_binding(),
                exits.as_entire_binding(),
                panes.as_entire_binding(),
                params.as_entire_binding(),
                wgpu::BindingResource::TextureView(depth),
                wgpu::BindingResource::Sampler(&sampler),
            ],
        ))
    }

    /// Records one dispatch over `exit_count` exit points.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, exit_count: u32) {
        self.0.encode(encoder, [exit_count.div_ceil(64), 1, 1], None);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DepthFilter;
    use prm_gpu_kit::layout::check_consts;
    use prm_gpu_kit::wgsl_layout;

    fn source() -> String {
        [HEMICUBE_WGSL, VPL_WGSL, PANE_GATHER_WGSL].join("\n")
    }

    #[test]
    fn rust_structs_match_the_shader() {
        let s = source();
        wgsl_layout!(&s, GpuExit, "Exit", [position, _pad0, normal, _pad1]).unwrap();
        wgsl_layout!(
            &s,
            GatherParams,
            "Gather",
            [
                exit_count,
                vpl_count,
                first_cluster,
                bound_kind,
                bound_value,
                near,
                far,
                lift,
                receiver_offset,
                bias_constant,
                bias_slope,
                texel_angle,
                depth_filter,
                face_resolution,
                faces_per_row,
                _pad
            ]
        )
        .unwrap();
    }

    #[test]
    fn codes_match_the_shader_constants() {
        let s = source();
        check_consts(
            &s,
            &[
                ("VPL_BOUND_NONE", VplBoundKind::None as i64),
                ("VPL_BOUND_CLAMP", VplBoundKind::Clamp as i64),
                ("VPL_BOUND_DISK", VplBoundKind::Disk as i64),
                ("VPL_BOUND_NEAR", VplBoundKind::Near as i64),
                ("DEPTH_NEAREST", DepthFilter::Nearest as i64),
                ("DEPTH_PCF2X2", DepthFilter::Pcf2x2 as i64),
            ],
        )
        .unwrap();
        // The one float constant: `1 − w₀` of the near field's cut.
        let keep = format!("const VPL_NEAR_KEEP: f32 = {};", prm_trace::vpl::NEAR_KEEP);
        assert!(s.contains(&keep), "vpl.wgsl lacks `{keep}`");
    }
}
