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

/// [`Merged`] as the passes read it.
struct GpuMerged {
    exits: Vec<GpuNearExit>,
    /// The direct share's hits, and the deeper share's where their disks are one.
    hits: Vec<GpuNearHit>,
    /// The deeper share's hits where its disk differs.
    deeper_hits: Option<Vec<GpuNearHit>>,
}

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
/// gather ([`crate::RuntimeOptions::near_bounces`]), the same from the lightmap the previous sum
/// completed (`again`), added to `source` again. The sums before the last write the exit texels
/// of the near lightmap, free once the blend has added it, which then holds that completed
/// lightmap at the exit texels (and `source` at the others, which no sum changes): each gather
/// point reads one or the other by its [`crate::GpuNearPoint::EXIT`] flag. The near lightmap's other
/// texels stay zero for the next blend, and the lightmap needs no third copy. The last sum adds
/// the rest of the series ([`NearTail::Extrapolated`]). Summing both shares after the blend in one walk along the
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

/// The gathers after the first: the radiance pass reading the lightmap the previous sum
/// completed, and the sum before the last (without the tail), into the near lightmap.
struct Again {
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
    /// `rgba32float`; zero but at the exit texels), which the deeper share's gathers before the
    /// last then reuse ([`IndirectShare`]).
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
    /// The hits with the deeper VPLs' weights, where they differ from the direct share's (a
    /// deeper disk other than the direct share's); `None`: `hits` serve both.
    deeper_hits: Option<wgpu::Buffer>,
    /// Gather points as uploaded (at least one).
    point_slots: u64,
}

impl NearBuffers {
    /// Uploads `near`'s gather points, its constants and its `merged` exit records and hits.
    fn upload(device: &wgpu::Device, near: &NearField, merged: &Merged) -> NearBuffers {
        let st = wgpu::BufferUsages::STORAGE;
        let gather = GatherPoints::upload_near(device, "prm near", &near.points, &near.exits);
        let points = near.points.len() as u32;
        let constants = GpuNearField {
            exits: merged.ends.len() as u32,
            points,
            scale: std::f32::consts::PI / near.rays_per_exit.max(1) as f32,
            weight_bits: GpuNearHit::weight_bits(points),
            ..Default::default()
        };
        let info = constants_buffer(device, "prm near field", &constants);
        let gpu = merged.gpu(near, constants.weight_bits);
        let upload = |label, hits: Vec<GpuNearHit>| {
            pipeline::buffer_init(device, label, bytemuck::cast_slice(&at_least_one(hits)), st)
        };
        let exits = at_least_one(gpu.exits);
        let exits = pipeline::buffer_init(device, "prm near exits", bytemuck::cast_slice(&exits), st);
        NearBuffers {
            inputs: RadianceBindings { gather, info },
            constants,
            exits,
            hits: upload("prm near hits", gpu.hits),
            deeper_hits: gpu.deeper_hits.map(|h| upload("prm near deeper hits", h)),
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
                self.sum_bindings(&self.inputs.info, &self.hits, &self.inputs.gather.radiance)
                    .as_slice(),
                &[wgpu::BindingResource::TextureView(near_map)],
            ]
            .concat(),
        )
    }

    /// Bindings 0 to 3 of both sums, which `near_sum.wgsl` declares: the constants
    /// `constants`, the exit records, their `hits` and the gather points' `radiance`.
    fn sum_bindings<'a>(
        &'a self,
        constants: &'a wgpu::Buffer,
        hits: &'a wgpu::Buffer,
        radiance: &'a wgpu::Buffer,
    ) -> [wgpu::BindingResource<'a>; 4] {
        [
            constants.as_entire_binding(),
            self.exits.as_entire_binding(),
            hits.as_entire_binding(),
            radiance.as_entire_binding(),
        ]
    }

    /// The hits the deeper share's sums walk.
    fn deeper(&self) -> &wgpu::Buffer {
        self.deeper_hits.as_ref().unwrap_or(&self.hits)
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
        // From `source`, and at exit texels from `completed`.
        let radiance_from = |source: &wgpu::TextureView, completed: &wgpu::TextureView| {
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
                    wgpu::BindingResource::TextureView(source),
                    wgpu::BindingResource::TextureView(targets.emitted),
                    indirect.as_entire_binding(),
                    wgpu::BindingResource::TextureView(completed),
                ],
            )
        };
        let source = lightmap_copy(device, "prm near source", targets.resolution);
        let source_view = view(&source);
        // Half floats, RGB then 0: the factors need no more than the gathers they scale.
        let half = |v: f32| u32::from(half::f16::from_f32(v.min(65504.0)).to_bits());
        let packed: Vec<[u32; 2]> = tail
            .iter()
            .map(|t| [half(t[0]) | half(t[1]) << 16, half(t[2])])
            .collect();
        let tail_buf = pipeline::buffer_init(
            device,
            "prm near tail",
            bytemuck::cast_slice(&at_least_one(packed)),
            wgpu::BufferUsages::STORAGE,
        );
        // A sum into `target`, after the gather that completed `previous` at the exit texels,
        // with or without the series' tail.
        let sum_into = |target: &wgpu::TextureView, previous: &wgpu::TextureView, constants: &wgpu::Buffer| {
            ComputePass::new(
                device,
                "near indirect",
                &[
                    crate::SHARED_WGSL,
                    NEAR_SUM_WGSL,
                    include_str!("../../../shaders/runtime/near_indirect.wgsl"),
                ],
                &[
                    bufs.sum_bindings(constants, bufs.deeper(), &indirect).as_slice(),
                    &[
                        wgpu::BindingResource::TextureView(&source_view),
                        wgpu::BindingResource::TextureView(target),
                        wgpu::BindingResource::TextureView(previous),
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
        let near_map = targets.near_map;
        let previous = if gathers > 1 { near_map } else { &source_view };
        IndirectShare {
            radiance_pass: radiance_from(&source_view, &source_view),
            last: sum_into(targets.lightmap, previous, &last_info),
            again: (gathers > 1).then(|| Again {
                radiance_pass: radiance_from(&source_view, near_map),
                sum: sum_into(near_map, &source_view, info),
            }),
            source,
            gathers,
        }
    }
}

/// The near field's hits with each exit record's hits on one gather point merged into one
/// ([`MergeNearHits::merged_hits`]): without merging, each walk along them cost lavapipe about
/// 50 ms more a frame on the fireplace room. The passes read each merged hit as one `u32`
/// ([`GpuNearHit`]: the point's index and the summed weight's half float), and one set of them
/// serves both shares where their disks are one.
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

    /// The exit records and their hits as the passes read them, the weights in `weight_bits`.
    fn gpu(&self, near: &NearField, weight_bits: u32) -> GpuMerged {
        let exits = near
            .exits
            .iter()
            .zip(&self.ends)
            .map(|(x, &end)| GpuNearExit { texel: x.texel, end })
            .collect();
        let pack = |weight: fn(&prm_scene::MergedHit) -> f32| {
            self.hits
                .iter()
                .map(|h| GpuNearHit::new(h.point, weight(h), weight_bits))
                .collect()
        };
        let one_disk = self.hits.iter().all(|h| h.weight == h.indirect_weight);
        GpuMerged {
            exits,
            hits: pack(|h| h.weight),
            deeper_hits: (!one_disk && near.indirect_disk > 0.0).then(|| pack(|h| h.indirect_weight)),
        }
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
    /// that share completed, added to the blended copy. Nothing without a deeper disk.
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
                let again = again.expect("passes for every gather after the first");
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
        let bits = GpuNearHit::weight_bits(6);
        let gpu = Merged::new(&near).gpu(&near, bits);
        assert_eq!(
            gpu.exits.iter().map(|x| (x.texel, x.end)).collect::<Vec<_>>(),
            [(3, 2), (7, 3)]
        );
        let unpack = |hits: &[GpuNearHit]| hits.iter().map(|h| h.unpack(bits)).collect::<Vec<_>>();
        let (direct, deeper) = (unpack(&gpu.hits), unpack(gpu.deeper_hits.as_ref().unwrap()));
        // R² = 1: weights 1, ½, ¼ at r² 0, 1, 3; R₁² = ½: 1, ⅓, ⅐.
        let want = [(2, 1.0 + 0.5, 1.0 + 1.0 / 3.0), (5, 0.25, 1.0 / 7.0), (2, 1.0, 1.0)];
        for ((d, i), w) in direct.iter().zip(&deeper).zip(want) {
            assert_eq!((d.0, i.0), (w.0, w.0));
            // Half floats: 11 significant bits.
            assert!(
                (d.1 - w.1).abs() < 1e-3 * w.1 && (i.1 - w.2).abs() < 1e-3 * w.2,
                "{direct:?} {deeper:?}"
            );
        }
        for indirect_disk in [0.0, 1.0] {
            let one = NearField {
                indirect_disk,
                ..near.clone()
            };
            assert!(
                Merged::new(&one).gpu(&one, bits).deeper_hits.is_none(),
                "{indirect_disk}"
            );
        }
    }

    #[test]
    fn a_hit_packs_its_point_and_weight_into_one_word() {
        assert_eq!(GpuNearHit::weight_bits(1), 15);
        assert_eq!(GpuNearHit::weight_bits(1 << 17), 15);
        assert_eq!(GpuNearHit::weight_bits((1 << 17) + 1), 14);
        assert_eq!(GpuNearHit::weight_bits(8192 * 8192), 6);
        for bits in [15, 14, 10, 6] {
            let last = (1u32 << (32 - bits)) - 1;
            for point in [0, 1, last] {
                for w in [0.0, 1.0 / 16.0, 0.3, 1.0, 7.25, 60000.0] {
                    let (p, got) = GpuNearHit::new(point, w, bits).unpack(bits);
                    assert_eq!(p, point);
                    // A half float's 11 significant bits less the dropped ones, rounded.
                    let tolerance = w * 2f32.powi(-11 - bits as i32 + 15);
                    assert!((got - w).abs() <= tolerance, "{bits} bits: {w} became {got}");
                }
            }
        }
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
