//! Emissive surfaces at run time: the archive's emitter groups (formats/prm.md §5.2) scaled by
//! the caller. A scale change sums each group's baked arrays on the CPU, `Σ_g s_g · entry_g` into
//! the entries' `emitted` irradiance (which the weights pass adds to the lights', so the panes
//! carry the emitters' indirect light) and `Σ_g s_g · direct_g` into the emitter lightmap (their
//! direct light, which the caller adds like the lights' own). On the McGuire Cornell box (one
//! group, 16 384 entries, 256² texels) that is about 1 ms and two uploads: less than a moved
//! light's shadow maps.

use prm_gpu_kit::pipeline;

use crate::{GpuEntry, RuntimeError, LIGHTMAP_FORMAT};

/// One emitter group of the archive, as [`crate::Runtime::emitters`] lists it.
#[derive(Clone, Debug, PartialEq)]
pub struct EmitterInfo {
    /// The material's name.
    pub name: String,
    /// The material's index in the scene.
    pub material: u32,
    /// Radiance at unit scale (W/(m²·sr), RGB).
    pub radiance: [f32; 3],
}

impl From<&prm_format::EmitterGroup> for EmitterInfo {
    fn from(g: &prm_format::EmitterGroup) -> EmitterInfo {
        EmitterInfo {
            name: g.name.clone(),
            material: g.material,
            radiance: g.radiance,
        }
    }
}

/// The groups, their current scales and the emitter lightmap.
pub(crate) struct EmitterState {
    pub info: Vec<EmitterInfo>,
    entry_irradiance: Vec<Vec<[f32; 3]>>,
    direct: Vec<Vec<[f32; 3]>>,
    pub scales: Vec<[f32; 3]>,
    /// The direct irradiance of the current scales, row-major (empty without groups).
    pub combined: Vec<[f32; 3]>,
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
}

impl EmitterState {
    /// The archive's groups at scale 1; the lightmap is `resolution`² (1² without groups).
    pub fn new(device: &wgpu::Device, groups: &[prm_format::EmitterGroup], resolution: u32) -> EmitterState {
        let side = if groups.is_empty() { 1 } else { resolution };
        let texture = pipeline::texture(
            device,
            "prm emitter lightmap",
            [side, side, 1],
            LIGHTMAP_FORMAT,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        );
        let view = texture.create_view(&Default::default());
        EmitterState {
            info: groups.iter().map(EmitterInfo::from).collect(),
            entry_irradiance: groups.iter().map(|g| g.entry_irradiance.clone()).collect(),
            direct: groups.iter().map(|g| g.direct.clone()).collect(),
            scales: vec![[1.0; 3]; groups.len()],
            combined: Vec::new(),
            texture,
            view,
        }
    }

    /// Checks `scales` (one finite, non-negative RGB triple per group).
    pub fn check(&self, scales: &[[f32; 3]]) -> Result<(), RuntimeError> {
        if scales.len() != self.info.len() {
            return Err(RuntimeError::Emitters(format!(
                "{} scales for {} emitter groups",
                scales.len(),
                self.info.len()
            )));
        }
        if let Some((g, s)) = scales
            .iter()
            .enumerate()
            .find(|(_, s)| s.iter().any(|c| !c.is_finite() || *c < 0.0))
        {
            return Err(RuntimeError::Emitters(format!(
                "emitter group {:?}'s scale {s:?} is negative or not finite",
                self.info[g].name
            )));
        }
        Ok(())
    }

    /// Sums the groups at the current scales into `entries[i].emitted` and the lightmap, and
    /// uploads the lightmap.
    pub fn apply(&mut self, queue: &wgpu::Queue, entries: &mut [GpuEntry]) {
        if self.info.is_empty() {
            return;
        }
        for e in entries.iter_mut() {
            e.emitted = [0.0; 3];
        }
        let texels = self.direct[0].len();
        self.combined = vec![[0.0; 3]; texels];
        for g in 0..self.info.len() {
            let s = self.scales[g];
            for (e, v) in entries.iter_mut().zip(&self.entry_irradiance[g]) {
                (0..3).for_each(|k| e.emitted[k] += s[k] * v[k]);
            }
            for (t, v) in self.combined.iter_mut().zip(&self.direct[g]) {
                (0..3).for_each(|k| t[k] += s[k] * v[k]);
            }
        }
        let rgba: Vec<[f32; 4]> = self.combined.iter().map(|&[r, g, b]| [r, g, b, 1.0]).collect();
        let side = self.texture.width();
        pipeline::write_layer(queue, &self.texture, 0, bytemuck::cast_slice(&rgba), side * 16);
    }
}
