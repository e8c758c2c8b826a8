//! Integration tests of the GPU passes on the Vulkan backend (lavapipe on machines without a GPU).

use prm_gpu::{Backend, GpuContext};

/// Vulkan explicitly, so that a missing driver fails loudly instead of falling back to GL.
fn vulkan() -> GpuContext {
    match GpuContext::new(Backend::Vulkan) {
        Ok(ctx) => ctx,
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn smoke_pass_computes_on_vulkan() {
    let ctx = vulkan();
    eprintln!("adapter: {}", ctx.describe());
    assert_eq!(ctx.info.backend, wgpu::Backend::Vulkan);
    let xs: Vec<f32> = (0..1000).map(|i| i as f32 * 0.5 - 17.0).collect();
    let ys = prm_gpu::smoke::run(&ctx, 3.0, -2.0, &xs).expect("smoke pass");
    assert_eq!(ys.len(), xs.len());
    for (x, y) in xs.iter().zip(&ys) {
        assert_eq!(*y, 3.0 * x - 2.0, "x = {x}");
    }
}

#[test]
fn missing_adapter_error_names_the_fix() {
    let e = prm_gpu::GpuError::NoAdapter {
        backend: Backend::Vulkan,
    }
    .to_string();
    assert!(e.contains("mesa-vulkan-drivers"), "{e}");
}
