//! The near field passes (`shaders/runtime/near_radiance.wgsl`, `near_field.wgsl`; both sums
//! through `near_sum.wgsl`), for archives that hold the near field: first the
//! radiance every gather point sends this frame from the lights' direct light (through the
//! shadow maps, times albedo/π), then every exit point's share of what the panes' VPL disk bound
//! removes, summed along its near rays into the near lightmap the blend adds. The panes' depth-0
//! VPLs sample the entry points' direct light with a bounded falloff, which leaves inner edges
//! and contacts too dark; this gathers that light back.
//! The deeper VPLs are bounded by a disk as large, and two more passes after
//! the blend gather their share back from the blended lightmap itself
//! (`near_indirect_radiance.wgsl`, `near_indirect.wgsl`), once per
//! [`crate::RuntimeOptions::near_bounces`], each time from the lightmap the previous gather
//! completed.

use prm_format::NearField;
use prm_gpu_kit::{linear_workgroups, pipeline, ComputePass, PassTimer};
use prm_scene::MergeNearHits;
use rayon::prelude::*;

use crate::gather::{at_least_one, GatherPasses, GatherPoints};
use crate::lit::{LitBindings, LitPass};
use crate::{Buffers, GpuNearExit, GpuNearField, GpuNearHit, NearTail};

/// The passes and the buffers they own.
pub(crate) struct NearFieldPass {
    /// Before the blend: the radiance pass (one invocation per gather point), then the sum (one
    /// per exit point with near hits) into the near lightmap.
    pub gathered: GatherPasses<RadianceBindings>,
    indirect: Option<IndirectShare>,
    exit_count: u32,
    /// Bytes of the exit records and hits, which every gather reads.
    pub bytes_per_gather: u64,
}

/// The deeper VPLs' share, after the blend: from a copy of its lightmap (`source`,
/// which holds the direct share already), the gather points' indirect radiance, then each exit
/// point's sum of it added to `source` and written into the lightmap; then, for each further
/// gather ([`crate::RuntimeOptions::near_bounces`]), the same from a copy of the lightmap the
/// previous sum completed (`again`), added to `source` again. The last sum adds the rest of the
/// series ([`NearTail::Extrapolated`]). Summing both shares after the blend in one walk along the
/// hits, without the direct share in the indirect light, played the fireplace room's 120 s bake
/// at 13.14% instead of 11.95% (McGuire's box 3.70% / 4.44% instead of 3.60% / 4.24%).
struct IndirectShare {
    radiance_pass: ComputePass,
    /// The last sum (with the tail, if any).
    last: ComputePass,
    source: wgpu::Texture,
    /// What the gathers after the first need; `None` with one.
    again: Option<Again>,
    gathers: u32,
}

/// The gathers after the first: the copy of the lightmap the previous sum completed, the
/// radiance pass reading it, and the sums before the last (without the tail).
struct Again {
    completed: wgpu::Texture,
    radiance_pass: ComputePass,
    sum: ComputePass,
}

/// How the run time sums the deeper share's series: [`crate::RuntimeOptions::near_bounces`]
/// and [`crate::RuntimeOptions::near_tail`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct NearSeries {
    pub gathers: u32,
    pub tail: NearTail,
}

/// Every exit record's tail factor (RGB, then 0) at `gathers` gathers
/// ([`prm_scene::DeeperOperator::series_tail`], its terms summed on every thread), from the
/// merged hits' f32 weights.
pub(crate) fn series_tail(near: &NearField, merged: &Merged, gathers: u32) -> Vec<[f32; 4]> {
    let op = prm_scene::DeeperOperator::new(near, &merged.ends, &merged.hits);
    op.series_tail(gathers, |v| {
        (0..op.len()).into_par_iter().map(|i| op.row(i, v)).collect()
    })
    .into_iter()
    .map(|[r, g, b]| [r, g, b, 0.0])
    .collect()
}

/// The textures the near field reads and writes besides its own buffers.
pub(crate) struct NearTargets<'a> {
    /// The near lightmap the direct share's sum writes and the blend adds (the atlas's size,
    /// `rgba32float`).
    pub near_map: &'a wgpu::TextureView,
    /// The runtime's lightmap, which the deeper VPLs' share completes after the blend.
    pub lightmap: &'a wgpu::TextureView,
    /// The emitters' and sky's traced indirect lightmap (1×1 without one).
    pub emitted: &'a wgpu::TextureView,
    /// The atlas's side in texels: the lightmap's and the near lightmap's.
    pub resolution: u32,
}

/// The radiance pass's own bindings; the shadow maps and the frame's buffers come per bind group.
pub(crate) struct RadianceBindings {
    gather: GatherPoints,
    info: wgpu::Buffer,
}

impl LitBindings for RadianceBindings {
    /// The radiance pass's own bindings, in the order of `near_radiance.wgsl`.
    fn own<'a>(&'a self, _: &'a Buffers) -> Vec<wgpu::BindingResource<'a>> {
        vec![
            self.gather.points.as_entire_binding(),
            self.gather.radiance.as_entire_binding(),
            self.info.as_entire_binding(),
        ]
    }
}

/// The near field's buffers: the radiance pass's bindings, the constants and the exit records
/// and merged hits every sum walks.
struct NearBuffers {
    inputs: RadianceBindings,
    constants: GpuNearField,
    exits: wgpu::Buffer,
    hits: wgpu::Buffer,
    /// Gather points as uploaded (at least one).
    point_slots: u64,
}

impl NearBuffers {
    /// Uploads `near`'s gather points, its constants and its `merged` exit records and hits.
    fn upload(device: &wgpu::Device, near: &NearField, merged: &Merged) -> NearBuffers {
        let st = wgpu::BufferUsages::STORAGE;
        let gather = GatherPoints::upload(device, "prm near", &near.points);
        let constants = GpuNearField {
            exits: merged.ends.len() as u32,
            points: near.points.len() as u32,
            scale: std::f32::consts::PI / near.rays_per_exit.max(1) as f32,
            tail: 0,
        };
        let info = constants_buffer(device, "prm near field", &constants);
        let (exits, hits) = merged.gpu(near);
        let (exits, hits) = (at_least_one(exits), at_least_one(hits));
        let exits = pipeline::buffer_init(device, "prm near exits", bytemuck::cast_slice(&exits), st);
        let hits = pipeline::buffer_init(device, "prm near hits", bytemuck::cast_slice(&hits), st);
        NearBuffers {
            inputs: RadianceBindings { gather, info },
            constants,
            exits,
            hits,
            point_slots: near.points.len().max(1) as u64,
        }
    }

    /// The direct share's sum into `near_map` (`near_field.wgsl`).
    fn sum_pass(&self, device: &wgpu::Device, near_map: &wgpu::TextureView) -> ComputePass {
        ComputePass::new(
            device,
            "near field",
            &[
                crate::SHARED_WGSL,
                NEAR_SUM_WGSL,
                include_str!("../../../shaders/runtime/near_field.wgsl"),
            ],
            &[
                self.sum_bindings(&self.inputs.info, &self.inputs.gather.radiance)
                    .as_slice(),
                &[wgpu::BindingResource::TextureView(near_map)],
            ]
            .concat(),
        )
    }

    /// Bindings 0 to 3 of both sums, which `near_sum.wgsl` declares: the constants
    /// `constants`, the exit records, their hits and the gather points' `radiance`.
    fn sum_bindings<'a>(
        &'a self,
        constants: &'a wgpu::Buffer,
        radiance: &'a wgpu::Buffer,
    ) -> [wgpu::BindingResource<'a>; 4] {
        [
            constants.as_entire_binding(),
            self.exits.as_entire_binding(),
            self.hits.as_entire_binding(),
            radiance.as_entire_binding(),
        ]
    }
}

/// What both sums share (`near_sum.wgsl`): bindings 0 to 3, the entry point (one invocation per
/// exit record) and the walk along an exit record's hits.
const NEAR_SUM_WGSL: &str = include_str!("../../../shaders/runtime/near_sum.wgsl");

/// What both radiance passes share (`near_points.wgsl`): the entry point, one invocation per
/// gather point writing albedo/π × the irradiance the pass gathers.
const NEAR_POINTS_WGSL: &str = include_str!("../../../shaders/runtime/near_points.wgsl");

/// A uniform buffer holding the near field's constants `c`.
fn constants_buffer(device: &wgpu::Device, label: &str, c: &GpuNearField) -> wgpu::Buffer {
    pipeline::buffer_init(device, label, bytemuck::bytes_of(c), wgpu::BufferUsages::UNIFORM)
}

/// A copy of the lightmap (`resolution`², [`crate::LIGHTMAP_FORMAT`]) that the passes sample.
fn lightmap_copy(device: &wgpu::Device, label: &str, resolution: u32) -> wgpu::Texture {
    pipeline::texture(
        device,
        label,
        [resolution, resolution, 1],
        crate::LIGHTMAP_FORMAT,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    )
}

impl IndirectShare {
    /// The deeper share's passes for `gathers` gathers (at least one), the last sum adding
    /// `tail` (every exit record's tail factor; empty: none).
    fn new(
        device: &wgpu::Device,
        bufs: &NearBuffers,
        targets: &NearTargets,
        tail: Vec<[f32; 4]>,
        gathers: u32,
    ) -> IndirectShare {
        let with_tail = !tail.is_empty();
        let view = |t: &wgpu::Texture| t.create_view(&Default::default());
        let indirect = pipeline::storage(
            device,
            "prm near indirect radiance",
            bufs.point_slots * 16,
            wgpu::BufferUsages::empty(),
        );
        let info = &bufs.inputs.info;
        let radiance_from = |from: &wgpu::Texture| {
            ComputePass::new(
                device,
                "near indirect radiance",
                &[
                    crate::SHARED_WGSL,
                    NEAR_POINTS_WGSL,
                    include_str!("../../../shaders/runtime/near_indirect_radiance.wgsl"),
                ],
                &[
                    info.as_entire_binding(),
                    bufs.inputs.gather.points.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&view(from)),
                    wgpu::BindingResource::TextureView(targets.emitted),
                    indirect.as_entire_binding(),
                ],
            )
        };
        let source = lightmap_copy(device, "prm near source", targets.resolution);
        let completed = (gathers > 1).then(|| lightmap_copy(device, "prm near completed", targets.resolution));
        let tail_buf = pipeline::buffer_init(
            device,
            "prm near tail",
            bytemuck::cast_slice(&at_least_one(tail)),
            wgpu::BufferUsages::STORAGE,
        );
        // The sum after `previous`'s gather, with or without the series' tail.
        let sum_after = |previous: &wgpu::Texture, constants: &wgpu::Buffer| {
            ComputePass::new(
                device,
                "near indirect",
                &[
                    crate::SHARED_WGSL,
                    NEAR_SUM_WGSL,
                    include_str!("../../../shaders/runtime/near_indirect.wgsl"),
                ],
                &[
                    bufs.sum_bindings(constants, &indirect).as_slice(),
                    &[
                        wgpu::BindingResource::TextureView(&view(&source)),
                        wgpu::BindingResource::TextureView(targets.lightmap),
                        wgpu::BindingResource::TextureView(&view(previous)),
                        tail_buf.as_entire_binding(),
                    ],
                ]
                .concat(),
            )
        };
        let last_info = constants_buffer(
            device,
            "prm near field, last sum",
            &GpuNearField {
                tail: u32::from(with_tail),
                ..bufs.constants
            },
        );
        let previous = completed.as_ref().unwrap_or(&source);
        IndirectShare {
            radiance_pass: radiance_from(&source),
            last: sum_after(previous, &last_info),
            again: completed.map(|c| Again {
                radiance_pass: radiance_from(&c),
                sum: sum_after(&c, info),
                completed: c,
            }),
            source,
            gathers,
        }
    }
}

/// The near field's hits with each exit record's hits on one gather point merged into one
/// ([`MergeNearHits::merged_hits`]): each walk along them cost lavapipe about 50 ms a frame on the
/// fireplace room before. The passes read the sums as half floats ([`GpuNearHit`], 8 bytes
/// instead of 16 with f32 weights and padding): the fireplace room's default archive played its
/// `gi` frame at 1024×768 in 197–205 ms instead of 221–233 (`prm-play --timings --gi-update
/// every-frame`, medians, interleaved), the images 2·10⁻⁵ apart, and twice the hits fit one
/// storage binding.
pub(crate) struct Merged {
    /// Every exit record's end in `hits`.
    pub ends: Vec<u32>,
    /// The merged hits, f32.
    pub hits: Vec<prm_scene::MergedHit>,
}

impl Merged {
    pub fn new(near: &NearField) -> Merged {
        let (ends, hits) = near.merged_hits();
        Merged { ends, hits }
    }

    /// The exit records and their hits as the passes read them.
    fn gpu(&self, near: &NearField) -> (Vec<GpuNearExit>, Vec<GpuNearHit>) {
        let exits = near
            .exits
            .iter()
            .zip(&self.ends)
            .map(|(x, &end)| GpuNearExit { texel: x.texel, end })
            .collect();
        let hits = self
            .hits
            .iter()
            .map(|h| GpuNearHit::new(h.point, h.weight, h.indirect_weight))
            .collect();
        (exits, hits)
    }
}

impl NearFieldPass {
    /// Uploads the near field for an atlas of `resolution`² texels.
    pub fn new(
        device: &wgpu::Device,
        b: &Buffers,
        near: &NearField,
        merged: &Merged,
        shadow_maps: &wgpu::TextureView,
        targets: NearTargets,
        series: NearSeries,
    ) -> NearFieldPass {
        let gathers = if near.indirect_disk > 0.0 { series.gathers } else { 0 };
        let tail = match series.tail {
            NearTail::Extrapolated if gathers > 0 => series_tail(near, merged, gathers),
            _ => Vec::new(),
        };
        let bufs = NearBuffers::upload(device, near, merged);
        let sum = bufs.sum_pass(device, targets.near_map);
        let indirect = (gathers > 0).then(|| IndirectShare::new(device, &bufs, &targets, tail, gathers));
        let parts = [
            crate::SHARED_WGSL,
            crate::LIGHT_BINDINGS_WGSL,
            crate::LIGHTS_WGSL,
            NEAR_POINTS_WGSL,
            include_str!("../../../shaders/runtime/near_radiance.wgsl"),
        ];
        let radiance = LitPass::new(device, "near radiance", &parts, bufs.inputs, b, shadow_maps);
        let (exit_count, points) = (bufs.constants.exits, bufs.constants.points);
        NearFieldPass {
            gathered: GatherPasses::new(
                radiance.bindings.gather.radiance.clone(),
                radiance,
                points,
                sum,
                linear_workgroups(exit_count),
            ),
            indirect,
            exit_count,
            bytes_per_gather: bufs.exits.size() + bufs.hits.size(),
        }
    }

    /// After the blend: copies the blended `lightmap`, gives every gather point
    /// its radiance from the lights' indirect light in it, and adds the deeper VPLs' share at
    /// every exit point with near hits; then once per further bounce the same from the lightmap
    /// that share completed, added to the blended copy. Nothing for 1.7.
    pub fn encode_after_blend(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        lightmap: &wgpu::Texture,
        timer: Option<&PassTimer>,
    ) {
        let Some(share) = &self.indirect else {
            return;
        };
        encoder.copy_texture_to_texture(lightmap.as_image_copy(), share.source.as_image_copy(), lightmap.size());
        share
            .radiance_pass
            .encode(encoder, linear_workgroups(self.gathered.point_count()), timer);
        for k in 1..=share.gathers {
            let again = share.again.as_ref();
            if k > 1 {
                let again = again.expect("a copy for every gather after the first");
                encoder.copy_texture_to_texture(
                    lightmap.as_image_copy(),
                    again.completed.as_image_copy(),
                    lightmap.size(),
                );
                again
                    .radiance_pass
                    .encode(encoder, linear_workgroups(self.gathered.point_count()), timer);
            }
            let sum = match again {
                Some(again) if k < share.gathers => &again.sum,
                _ => &share.last,
            };
            sum.encode(encoder, linear_workgroups(self.exit_count), timer);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use prm_format::{NearExit, NearHit};

    #[test]
    fn merging_sums_the_weights_of_an_exit_s_hits_on_one_point() {
        let hit = |point, distance2| NearHit { point, distance2 };
        let near = NearField {
            rays_per_exit: 8,
            disk: 1.0,
            indirect_disk: 0.5,
            complement: false,
            points: Vec::new(),
            exits: vec![NearExit { texel: 3, end: 3 }, NearExit { texel: 7, end: 4 }],
            // Exit 0: point 2 twice (r² 0 and 1), point 5 once; exit 1: point 2 again.
            hits: vec![hit(2, 0.0), hit(5, 3.0), hit(2, 1.0), hit(2, 0.0)],
        };
        let (exits, hits) = Merged::new(&near).gpu(&near);
        assert_eq!(
            exits.iter().map(|x| (x.texel, x.end)).collect::<Vec<_>>(),
            [(3, 2), (7, 3)]
        );
        let got: Vec<(u32, f32, f32)> = hits
            .iter()
            .map(|h| {
                let (w0, w1) = h.weights();
                (h.point, w0, w1)
            })
            .collect();
        // R² = 1: weights 1, ½, ¼ at r² 0, 1, 3; R₁² = ½: 1, ⅓, ⅐.
        let want = [(2, 1.0 + 0.5, 1.0 + 1.0 / 3.0), (5, 0.25, 1.0 / 7.0), (2, 1.0, 1.0)];
        for (g, w) in got.iter().zip(want) {
            assert_eq!(g.0, w.0);
            // Half floats: 11 significant bits.
            assert!(
                (g.1 - w.1).abs() < 1e-3 * w.1 && (g.2 - w.2).abs() < 1e-3 * w.2,
                "{got:?}"
            );
        }
        let direct_only = NearField {
            indirect_disk: 0.0,
            ..near
        };
        assert!(Merged::new(&direct_only)
            .gpu(&direct_only)
            .1
            .iter()
            .all(|h| h.weights().1 == 0.0));
    }

    #[test]
    fn the_tail_of_two_facing_exits_is_the_geometric_series() {
        // Exits at texels 0 and 1, every one of their 4 rays on the other's gather point at
        // r² = 0 (merged: one hit of weight 4 w₁): each term is f = albedo × 4 w₁ / M times the
        // one before, so
        // the rest after any term is f/(1 − f) of it. A third exit's rays end on a texel
        // without near hits (no second term).
        let point = |texel, albedo| prm_format::GatherPoint {
            texel,
            position: [0.0; 3],
            normal: [0.0, 1.0, 0.0],
            albedo: [albedo; 3],
            emission: [0.0; 3],
            emitter: prm_format::NO_EMITTER,
        };
        let hit = |point| NearHit { point, distance2: 0.0 };
        let near = NearField {
            rays_per_exit: 4,
            disk: 1.0,
            indirect_disk: 1.0,
            complement: true,
            points: vec![point(0, 0.5), point(1, 0.5), point(9, 0.8)],
            exits: vec![
                NearExit { texel: 0, end: 4 },
                NearExit { texel: 1, end: 8 },
                NearExit { texel: 5, end: 12 },
            ],
            hits: [[1; 4], [0; 4], [2; 4]].concat().into_iter().map(hit).collect(),
        };
        let merged = Merged::new(&near);
        let w = merged.hits[0].indirect_weight;
        let f = 0.5 * w / 4.0;
        assert!((f - 0.5).abs() < 1e-3, "{f}");
        for gathers in [1, 2, 3] {
            let tail = series_tail(&near, &merged, gathers);
            for t in &tail[..2] {
                for c in &t[..3] {
                    assert!((c - f / (1.0 - f)).abs() < 1e-4, "{gathers} gathers: {tail:?}, f = {f}");
                }
            }
            assert_eq!(tail[2], [0.0; 4], "nothing after its first term");
        }
    }
}
