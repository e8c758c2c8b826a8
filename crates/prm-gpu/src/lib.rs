//! GPU passes of PRM on wgpu: device selection and, one module per pass, the compute and render work.
//!
//! Every pass runs on lavapipe (Mesa's Vulkan on the CPU), so nothing here may rely on ray
//! queries, binding arrays or storage bindings over 128 MiB.

#![warn(missing_docs)]

pub mod pane;
pub mod pane_gather;
pub mod smoke;
pub mod vpl_depth;

pub use pane::{
    check_support, render_panes, render_panes_with, DepthFilter, PaneInputs, PaneOutput, PaneRenderParams,
    PaneRenderStats, ShadowBias,
};
pub use prm_gpu_kit::{instance, silence_wayland_probe, Backend, ContextOptions, ErrorScopes, GpuContext, GpuError};
