//! Baked light at run time: the archive's emitter groups (formats/prm.md §5.2) scaled by the
//! caller, and the sky (§5.3) given by the caller as spherical-harmonic coefficients. A change
//! sums the baked arrays on the CPU: `Σ_g s_g · direct_g` plus the sky's `Σ_c T_c · L_c` into
//! the baked direct lightmap (which the caller adds to the lights' direct light); for groups
//! with a traced indirect lightmap `Σ_g s_g · indirect_g`, plus the sky's indirect transfer, into
//! a texture the blend pass adds to the indirect lightmap; for the other groups
//! `Σ_g s_g · entry_g` into the entries' `emitted` irradiance, which the weights pass adds to
//! the lights', so the panes carry their indirect light. On the McGuire Cornell box (one group,
//! 256² texels) that is a few milliseconds and three uploads, no more than a moved light costs
//! (`cargo xtask eval --emitters`, `--sky`).

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

/// The groups, their current scales, the sky's transfer and coefficients, and the baked
/// lightmaps.
pub(crate) struct BakedLights {
    pub info: Vec<EmitterInfo>,
    /// The archive's groups: entry irradiance, direct and (traced) indirect lightmaps.
    groups: Vec<prm_format::EmitterGroup>,
    pub scales: Vec<[f32; 3]>,
    /// The archive's sky transfer, if it has one.
    pub sky: Option<prm_format::SkyTransfer>,
    /// The sky's current coefficients (zero: no sky).
    pub sky_coeffs: [[f32; 3]; prm_format::SH_COEFFS],
    /// The baked direct irradiance now, row-major (empty without groups or sky).
    pub combined: Vec<[f32; 3]>,
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    /// The traced indirect irradiance now (1×1 when neither a group nor the sky has it; the
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

/// `Σ s · map` over `(map, s)` pairs, `texels` long.
fn sum<'a>(texels: usize, maps: impl Iterator<Item = (&'a [[f32; 3]], [f32; 3])>) -> Vec<[f32; 3]> {
    let mut sum = vec![[0.0f32; 3]; texels];
    for (map, s) in maps {
        for (t, v) in sum.iter_mut().zip(map) {
            (0..3).for_each(|k| t[k] += s[k] * v[k]);
        }
    }
    sum
}

/// Uploads `texels` (the texture's size) to `texture`.
fn upload(queue: &wgpu::Queue, texture: &wgpu::Texture, texels: &[[f32; 3]]) {
    let rgba: Vec<[f32; 4]> = texels.iter().map(|&[r, g, b]| [r, g, b, 1.0]).collect();
    pipeline::write_layer(queue, texture, 0, bytemuck::cast_slice(&rgba), texture.width() * 16);
}

impl BakedLights {
    /// The archive's groups at scale 1 and its sky transfer, with no sky yet; the lightmaps are
    /// `resolution`² (1² when unused).
    pub fn new(
        device: &wgpu::Device,
        groups: &[prm_format::EmitterGroup],
        sky: Option<&prm_format::SkyTransfer>,
        resolution: u32,
    ) -> BakedLights {
        let side = if groups.is_empty() && sky.is_none() {
            1
        } else {
            resolution
        };
        let (texture, view) = lightmap(device, "prm baked direct lightmap", side);
        let traced = groups.iter().any(|g| g.indirect.is_some()) || sky.is_some();
        let (indirect_texture, indirect_view) = lightmap(
            device,
            "prm baked indirect lightmap",
            if traced { resolution } else { 1 },
        );
        BakedLights {
            info: groups.iter().map(EmitterInfo::from).collect(),
            groups: groups.to_vec(),
            scales: vec![[1.0; 3]; groups.len()],
            sky: sky.cloned(),
            sky_coeffs: [[0.0; 3]; prm_format::SH_COEFFS],
            combined: Vec::new(),
            texture,
            view,
            indirect_texture,
            indirect_view,
        }
    }

    /// Marks in `lit` (one flag per texel of the `resolution`² atlas) every texel the traced
    /// indirect lightmap can light: a group's traced indirect light or the sky's indirect
    /// transfer is not zero there.
    pub fn mark_indirect(&self, lit: &mut [bool]) {
        for map in self.groups.iter().filter_map(|g| g.indirect.as_deref()) {
            for (l, v) in lit.iter_mut().zip(map) {
                *l |= v.iter().any(|&c| c != 0.0);
            }
        }
        if let Some(sky) = &self.sky {
            for (l, t) in lit.iter_mut().zip(&sky.indirect) {
                *l |= t.iter().flatten().any(|&c| c != 0.0);
            }
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

    /// Checks sky coefficients: the archive must have the sky's transfer, and every value be
    /// finite.
    pub fn check_sky(&self, coeffs: &[[f32; 3]; prm_format::SH_COEFFS]) -> Result<(), RuntimeError> {
        if self.sky.is_none() && coeffs.iter().flatten().any(|&v| v != 0.0) {
            return Err(RuntimeError::Sky(
                "the archive has no sky transfer: bake it with `prm-bake bake --sky`".into(),
            ));
        }
        if coeffs.iter().flatten().any(|v| !v.is_finite()) {
            return Err(RuntimeError::Sky(format!("sky coefficients {coeffs:?} are not finite")));
        }
        Ok(())
    }

    /// Sums the groups at the current scales and the sky: into `entries[i].emitted` for the
    /// groups whose indirect light goes through the panes, and into the two lightmaps, which it
    /// uploads.
    pub fn apply(&mut self, queue: &wgpu::Queue, entries: &mut [GpuEntry]) {
        if self.groups.is_empty() && self.sky.is_none() {
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
        let texels = (self.texture.width() * self.texture.width()) as usize;
        let mut direct = sum(texels, scaled().map(|(g, s)| (&g.direct[..], s)));
        let indirect_texels = (self.indirect_texture.width() * self.indirect_texture.width()) as usize;
        let mut indirect = sum(
            indirect_texels,
            scaled().filter_map(|(g, s)| g.indirect.as_deref().map(|m| (m, s))),
        );
        if let Some(sky) = self
            .sky
            .as_ref()
            .filter(|_| self.sky_coeffs.iter().flatten().any(|&v| v != 0.0))
        {
            for (t, (d, i)) in direct.iter_mut().zip(indirect.iter_mut()).enumerate() {
                let (sd, si) = sky.irradiance(t, &self.sky_coeffs);
                // A sky with a small bright spot (a sun in the map) rings in the order-2
                // basis: its light goes negative away from the spot. No light is negative.
                (0..3).for_each(|k| {
                    d[k] += sd[k].max(0.0);
                    i[k] += si[k].max(0.0);
                });
            }
        }
        upload(queue, &self.texture, &direct);
        if indirect_texels > 1 {
            upload(queue, &self.indirect_texture, &indirect);
        }
        self.combined = direct;
    }
}
