//! GPU pass timers from timestamp queries: one begin/end pair per named pass, resolved and read
//! back on request. On lavapipe a timestamp is a synchronisation point, so frames are timed on
//! request only (`prm-play --timestamps`, the frame benchmark), never by default.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::GpuError;

/// Timestamp queries for up to 64 named passes. Each pass asks for its writes by name; the
/// passes that asked since the last [`PassTimer::read`] are the ones resolved and reported.
pub struct PassTimer {
    names: Vec<&'static str>,
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
    used: AtomicU64,
}

/// Bytes between two passes' results in the resolve buffer (wgpu's query resolve alignment).
const SLOT: u64 = wgpu::QUERY_RESOLVE_BUFFER_ALIGNMENT;

impl PassTimer {
    /// Timers for `names` (at most 64), or `None` when the device was opened without
    /// `TIMESTAMP_QUERY`.
    pub fn new(device: &wgpu::Device, names: &[&'static str]) -> Option<PassTimer> {
        assert!(names.len() <= 64, "at most 64 timed passes");
        if !device.features().contains(wgpu::Features::TIMESTAMP_QUERY) || names.is_empty() {
            return None;
        }
        let size = names.len() as u64 * SLOT;
        let buffer = |label, usage| crate::pipeline::buffer(device, label, size, usage);
        Some(PassTimer {
            names: names.to_vec(),
            set: device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass timer"),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * names.len() as u32,
            }),
            resolve: buffer(
                "pass timer resolve",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            read: buffer(
                "pass timer read",
                wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            ),
            used: AtomicU64::new(0),
        })
    }

    fn slot(&self, pass: &str) -> Option<u32> {
        let i = self.names.iter().position(|n| *n == pass)?;
        self.used.fetch_or(1 << i, Ordering::Relaxed);
        Some(i as u32)
    }

    /// The writes of compute pass `pass` (begin and end), `None` for a name not timed.
    pub fn compute(&self, pass: &str) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let i = self.slot(pass)?;
        Some(wgpu::ComputePassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: Some(2 * i),
            end_of_pass_write_index: Some(2 * i + 1),
        })
    }

    /// The writes of a render pass that is part `first`..`last` of pass `pass` (a pass made of
    /// several render passes, such as one per shadow view, writes its begin in the first and its
    /// end in the last); `None` for a middle part or a name not timed.
    pub fn render(&self, pass: &str, first: bool, last: bool) -> Option<wgpu::RenderPassTimestampWrites<'_>> {
        if !(first || last) {
            return None;
        }
        let i = self.slot(pass)?;
        Some(wgpu::RenderPassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: first.then_some(2 * i),
            end_of_pass_write_index: last.then_some(2 * i + 1),
        })
    }

    /// Records the resolve of every pass that asked for writes, and the copy for [`read`](Self::read).
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        let used = self.used.load(Ordering::Relaxed);
        for i in (0..self.names.len() as u32).filter(|i| used & (1 << i) != 0) {
            encoder.resolve_query_set(&self.set, 2 * i..2 * i + 2, &self.resolve, i as u64 * SLOT);
        }
        encoder.copy_buffer_to_buffer(&self.resolve, 0, &self.read, 0, self.resolve.size());
    }

    /// Milliseconds of every pass resolved by the last [`resolve`](Self::resolve), in the order
    /// of the names given to [`new`](Self::new); waits for the device.
    pub fn read(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Vec<(&'static str, f64)>, GpuError> {
        let bytes = crate::readback::map_read(device, &self.read)?;
        let used = self.used.swap(0, Ordering::Relaxed);
        let period = queue.get_timestamp_period() as f64;
        Ok(self
            .names
            .iter()
            .enumerate()
            .filter(|(i, _)| used & (1 << i) != 0)
            .map(|(i, name)| {
                let at = i * SLOT as usize;
                let b: u64 = bytemuck::pod_read_unaligned(&bytes[at..at + 8]);
                let e: u64 = bytemuck::pod_read_unaligned(&bytes[at + 8..at + 16]);
                (*name, e.saturating_sub(b) as f64 * period * 1e-6)
            })
            .collect())
    }
}
