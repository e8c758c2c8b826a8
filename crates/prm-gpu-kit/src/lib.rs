//! The shared wgpu kit of PRM: opening a device ([`GpuContext`]), catching every GPU error
//! ([`ErrorScopes`]), building pipelines, bind groups and buffers ([`pipeline`]) and compute passes
//! ([`ComputePass`]), reading
//! buffers and textures back ([`readback`]), timing passes ([`PassTimer`]) and checking that
//! `#[repr(C)]` structs match their WGSL twins ([`layout`]).
//!
//! It holds no PRM types and no global state: every function takes the caller's
//! `wgpu::Device` / `wgpu::Queue`, so an engine that embeds `prm-runtime` keeps its own device.
//! Everything here runs on lavapipe (Mesa's Vulkan on the CPU).

#![warn(missing_docs)]

mod compute;
mod context;
pub mod layout;
pub mod pipeline;
pub mod readback;
mod timer;

pub use compute::{linear_workgroups, ComputePass, LINEAR_GROUP_SIZE};
pub use context::{instance, silence_wayland_probe, Backend, ContextOptions, ErrorScopes, GpuContext, GpuError};
pub use timer::PassTimer;
