//! Small helpers every GPU module uses: the device error, the error scopes around a render,
//! and buffer creation. A leaf: it uses no other module of `gpu/`.

use crate::error::{Error, Result};

/// An error of the device or of wgpu, as the crate's [`Error::Device`].
pub(super) fn device_error(msg: impl Into<String>) -> Error {
    Error::Device(msg.into())
}

/// Run `f` inside validation and out-of-memory error scopes on `dev`: an error either
/// scope caught is returned in place of `f`'s result (out of memory first).
pub(super) fn error_scoped<T>(dev: &wgpu::Device, f: impl FnOnce() -> Result<T>) -> Result<T> {
    let scope_v = dev.push_error_scope(wgpu::ErrorFilter::Validation);
    let scope_m = dev.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let result = f();
    let oom = pollster::block_on(scope_m.pop());
    let val = pollster::block_on(scope_v.pop());
    if let Some(e) = oom {
        return Err(device_error(format!(
            "out of device memory (try a smaller resolution or batch): {e}"
        )));
    }
    if let Some(e) = val {
        return Err(device_error(format!("wgpu validation error: {e}")));
    }
    result
}

/// A buffer of `size` bytes (at least 16: no binding is empty).
pub(super) fn create_buffer(
    dev: &wgpu::Device,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    dev.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage,
        mapped_at_creation: false,
    })
}
