//! Emissive surfaces at run time: the archive's emitter groups (formats/prm.md §5.2) scaled by
//! the caller. A scale change sums each group's baked arrays on the CPU: `Σ_g s_g · direct_g`
//! into the emitter lightmap (their direct light, which the caller adds like the lights' own);
//! for groups with a traced indirect lightmap `Σ_g s_g · indirect_g` into a texture the blend
//! pass adds to the indirect lightmap; for the others `Σ_g s_g · entry_g` into the entries'
//! `emitted` irradiance, which the weights pass adds to the lights', so the panes carry their
//! indirect light. On the McGuire Cornell box (one group, 256² texels) that is a few
//! milliseconds and three uploads, no more than a moved light costs (`cargo xtask eval
//! --emitters`).

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

/// The groups, their current scales and the emitter lightmaps.
pub(crate) struct EmitterState {
    pub info: Vec<EmitterInfo>,
    /// The archive's groups: entry irradiance, direct and (traced) indirect lightmaps.
    groups: Vec<prm_format::EmitterGroup>,
    pub scales: Vec<[f32; 3]>,
    /// The direct irradiance of the current scales, row-major (empty without groups).
    pub combined: Vec<[f32; 3]>,
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    /// The traced indirect irradiance of the current scales (1×1 when no group has it; the
    /// blend pass adds it).
    indirect_texture: wgpu::Texture,
    pub indirect_view: wgpu::TextureView,
}

/// An `rgba32float` texture of `side`² for the emitter lightmaps.
fn lightmap(device: &wgpu::Device, label: &str, side: u32) -> (wgpu::Texture, wgpu::TextureView) {
    let texture = pipeline::texture(
        device,
        label,
        [side, side, 1],
        LIGHTMAP_FORMAT,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    );
    let view = texture.create_view(&Default::default());
    (texture, view)
}

/// `Σ s · map` over `(map, s)` pairs, uploaded to `texture` (whose size the maps have).
fn sum_into<'a>(
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    maps: impl Iterator<Item = (&'a [[f32; 3]], [f32; 3])>,
) -> Vec<[f32; 3]> {
    let side = texture.width();
    let mut sum = vec![[0.0f32; 3]; (side * side) as usize];
    for (map, s) in maps {
        for (t, v) in sum.iter_mut().zip(map) {
            (0..3).for_each(|k| t[k] += s[k] * v[k]);
        }
    }
    let rgba: Vec<[f32; 4]> = sum.iter().map(|&[r, g, b]| [r, g, b, 1.0]).collect();
    pipeline::write_layer(queue, texture, 0, bytemuck::cast_slice(&rgba), side * 16);
    sum
}

impl EmitterState {
    /// The archive's groups at scale 1; the lightmaps are `resolution`² (1² when unused).
    pub fn new(device: &wgpu::Device, groups: &[prm_format::EmitterGroup], resolution: u32) -> EmitterState {
        let side = if groups.is_empty() { 1 } else { resolution };
        let (texture, view) = lightmap(device, "prm emitter lightmap", side);
        let traced = groups.iter().any(|g| g.indirect.is_some());
        let (indirect_texture, indirect_view) =
            lightmap(device, "prm emitter indirect", if traced { resolution } else { 1 });
        EmitterState {
            info: groups.iter().map(EmitterInfo::from).collect(),
            groups: groups.to_vec(),
            scales: vec![[1.0; 3]; groups.len()],
            combined: Vec::new(),
            texture,
            view,
            indirect_texture,
            indirect_view,
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

    /// Sums the groups at the current scales: into `entries[i].emitted` for the groups whose
    /// indirect light goes through the panes, and into the two lightmaps, which it uploads.
    pub fn apply(&mut self, queue: &wgpu::Queue, entries: &mut [GpuEntry]) {
        if self.groups.is_empty() {
            return;
        }
        let scaled = || self.groups.iter().zip(self.scales.iter().copied());
        for e in entries.iter_mut() {
            e.emitted = [0.0; 3];
        }
        for (g, s) in scaled().filter(|(g, _)| g.indirect.is_none()) {
            for (e, v) in entries.iter_mut().zip(&g.entry_irradiance) {
                (0..3).for_each(|k| e.emitted[k] += s[k] * v[k]);
            }
        }
        self.combined = sum_into(queue, &self.texture, scaled().map(|(g, s)| (&g.direct[..], s)));
        if self.groups.iter().any(|g| g.indirect.is_some()) {
            let traced = scaled().filter_map(|(g, s)| g.indirect.as_deref().map(|m| (m, s)));
            sum_into(queue, &self.indirect_texture, traced);
        }
    }
}
