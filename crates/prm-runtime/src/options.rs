//! The run time's options, with the checks that name a field and the device limit it breaks,
//! and its error type.

use prm_format::Archive;
use prm_gpu_kit::GpuError;

use crate::MAX_LIGHTS;

/// Largest shadow-map side [`RuntimeOptions::validate`] accepts: a point light's six faces take
/// 6 × 8192² × 4 bytes = 1.5 GiB of depth at this size; beyond it lavapipe runs out of memory
/// with a single light.
pub const MAX_SHADOW_RESOLUTION: u32 = 8192;
/// Most tiles on a side of a directional light's shadow map ([`RuntimeOptions::sun_tiles`]):
/// 64 views, each a pass over the scene.
pub const MAX_SUN_TILES: u32 = 8;

/// Most gathers of the near field's deeper share a frame ([`RuntimeOptions::near_bounces`]):
/// 64 reach the series' limit on the fireplace room (7.16%; 7 gathers 7.25%, 4 7.36%), and each
/// costs a pass over every gather point and every near exit point.
pub const MAX_NEAR_BOUNCES: u32 = 64;
/// Why the run time could not load an archive or run a frame.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RuntimeError {
    /// A GPU error (validation, out of memory, device lost).
    #[error(transparent)]
    Gpu(#[from] GpuError),
    /// The archive and the scene disagree.
    #[error("archive does not fit the scene: {0}")]
    Mismatch(String),
    /// The archive is one shard of a sharded bake (`params.shard`): the other shards' panes are
    /// empty.
    #[error("the archive is shard {0} of a sharded bake, without the other shards' panes: join the parts with `prm-bake merge`")]
    PartialArchive(String),
    /// One atlas tile of the panes' basis or coefficients (with the residual groups') takes
    /// more than one storage binding of the device.
    #[error(
        "the archive has {panes} panes (with the residual groups); one tile of them takes {bytes} bytes but this \
         GPU binds at most {binding} at once"
    )]
    TooManyPanes {
        /// Panes with the residual groups.
        panes: usize,
        /// Bytes of the largest tile's basis or coefficients.
        bytes: u64,
        /// Bytes one storage binding (or the chunk cap) holds.
        binding: u64,
    },
    /// More lights than [`MAX_LIGHTS`].
    #[error("{count} lights, at most {MAX_LIGHTS} are supported")]
    TooManyLights {
        /// Lights given.
        count: usize,
    },
    /// The frame's lights need more shadow views than the run time holds (a point light takes
    /// 6, a directional light `sun_tiles`²).
    #[error(
        "the lights need {views} shadow views, at most {max} fit (a point light takes 6, a directional light sun_tiles² = {per_sun}); fewer lights or fewer sun tiles"
    )]
    TooManyShadowViews {
        /// Views the lights need.
        views: usize,
        /// Views that fit: the views buffer and the device's `max_texture_array_layers`.
        max: usize,
        /// Views of one directional light.
        per_sun: u32,
    },
    /// Emitter scales that do not fit the archive's emitter groups.
    #[error("emitters: {0}")]
    Emitters(String),
    /// Sky coefficients the archive cannot take (no sky transfer) or not finite.
    #[error("sky: {0}")]
    Sky(String),
    /// The archive's near field does not fit this device.
    #[error("near field: {0}")]
    NearField(String),
    /// The archive's probes do not fit this device.
    #[error("probes: {0}")]
    Probes(String),
    /// An option is out of range for the run time or this device.
    #[error("{option}: {message}")]
    Option {
        /// The [`RuntimeOptions`] field.
        option: &'static str,
        /// What is wrong and which limit it breaks.
        message: String,
    },
}

/// How the run time lights the probes of an archive that has them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ProbeLight {
    /// Along the probes' rays, from the surfaces' light of the frame, when the archive holds
    /// them; through the panes otherwise.
    #[default]
    Rays,
    /// Through the panes: the clusters' transfer under the frame's weights (what archives
    /// without probe rays hold), for comparison.
    Panes,
}

/// Whether the run time gathers back what the panes' VPL bound removes, for an archive that
/// holds the near field (its direct share and its deeper VPLs' share).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NearLight {
    /// Gathered each frame along the near rays: from the surfaces' direct light, and from the
    /// blended lightmap's indirect light.
    #[default]
    Gather,
    /// Left out: the panes' light only, for comparison (an archive with a near field, whose
    /// VPL disks are large, then plays too dark).
    Off,
}

/// What follows the last gather of the near field's deeper share ([`RuntimeOptions::near_tail`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NearTail {
    /// The rest of the share's series, extrapolated at every exit point from its last term:
    /// that term times the ratio of the rest to it for uniform light
    /// ([`prm_scene::DeeperOperator::series_tail`], summed once at load on the CPU: 0.5 s for
    /// the fireplace room's 185k near exit points on two cores). Light passed back and forth between close surfaces converges
    /// slowly where they enclose a space (under furniture, between a sofa's cushions, behind a
    /// picture: the terms fall by about 0.87 each on the fireplace room), and this takes it
    /// close to the series' limit at no cost a frame: the fireplace room's lightmap against its
    /// reference (1024 paths a texel, every covered texel) 54.0% off after two gathers, 15.8%
    /// with the tail, 15.1% at the limit (64 gathers).
    #[default]
    Extrapolated,
    /// The series cut after the gathers.
    Off,
}

/// When [`crate::Runtime::encode`] records the indirect light's passes (weights, near field,
/// rank, select, blend, probes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GiUpdate {
    /// Only when something they read changed since the last recorded update: the lights
    /// ([`crate::Runtime::update`] with other lights), K, the emitter groups' scales or the sky;
    /// always with [`crate::Shadows::External`] shadow maps, whose contents the run time cannot
    /// see. A frame whose lights stand still (the camera moves, or nothing does) then costs its
    /// direct light alone: McGuire's box at 1024×768 on lavapipe 24–25 ms instead of 52–56 ms
    /// (`prm-play --headless --frames 12 --timings`, medians, with `--gi-update every-frame`).
    #[default]
    OnChange,
    /// Every frame: what a frame whose lights move costs (benchmarks, and `cargo xtask eval`'s
    /// frame times).
    EveryFrame,
}

/// Run-time settings.
#[derive(Clone, Debug, PartialEq)]
pub struct RuntimeOptions {
    /// Clusters kept per frame.
    pub top_k: u32,
    /// Residual groups ([`prm_format::residual_groups`], at most one per
    /// [`prm_format::CLUSTERS_PER_GROUP`] clusters): when the top K drops clusters, their light
    /// (and the faded share of the kept ones) is blended through each group's summed pane, so a
    /// frame blends up to K + this many panes. 0: no groups, the kept clusters are scaled up to
    /// the dropped ones' energy instead (the paper's top K with its energy kept). Default
    /// [`prm_format::RESIDUAL_GROUPS`] (64; its measurements): on chairs (240 clusters, K = 32)
    /// 4 groups had already given 12.3% from the reference against 23.7% with scaling.
    pub residual_groups: u32,
    /// Shadow-map side in texels (every view).
    pub shadow_resolution: u32,
    /// A directional light's shadow map is this many tiles on a side, one view of
    /// `shadow_resolution`² each, over the scene's bounding sphere (1 to [`MAX_SUN_TILES`]).
    /// Default [`RuntimeOptions::DEFAULT_SUN_TILES`].
    pub sun_tiles: u32,
    /// Fade band: kept clusters whose score is within `band × threshold` above the threshold
    /// (the first dropped cluster's score) are faded by a smoothstep.
    pub fade_band: f32,
    /// Shadow lookups move the point this many shadow texels along its normal. Default
    /// [`RuntimeOptions::DEFAULT_NORMAL_OFFSET`].
    pub normal_offset: f32,
    /// Depth tolerance of a shadow lookup, in shadow texels (world size at the point), times
    /// the tangent of the light's angle from the normal between 1 and 4 (`lights.wgsl`,
    /// `DEPTH_BIAS_MAX_SLOPE`).
    pub depth_bias: f32,
    /// How the probes are lit ([`ProbeLight::Rays`] by default).
    pub probe_light: ProbeLight,
    /// Whether the near field is gathered ([`NearLight::Gather`] by default).
    pub near_light: NearLight,
    /// How many times the deeper VPLs' share of the near field is gathered after the blend
    /// ([`RuntimeOptions::DEFAULT_NEAR_BOUNCES`] by default); 0 leaves it out.
    pub near_bounces: u32,
    /// What follows the last of those gathers ([`NearTail::Extrapolated`] by default).
    pub near_tail: NearTail,
    /// Most bytes one buffer of panes takes (the panes' tiles are grouped in chunks, each one
    /// buffer of basis rows and one of coefficients: `blend.rs`); `None`: the device's storage
    /// binding limit. A smaller cap
    /// costs a dispatch per chunk and nothing measurable; for engines that bound their
    /// allocations, and for tests of the chunked path.
    pub pane_chunk_bytes: Option<u64>,
    /// When the indirect light is computed again ([`GiUpdate::OnChange`] by default).
    pub gi_update: GiUpdate,
}

impl RuntimeOptions {
    /// Top K when neither the caller nor the archive's `params.top_k` says otherwise.
    pub const DEFAULT_TOP_K: u32 = 32;

    /// Gathers of the deeper VPLs' share after the blend. That share is the light of the
    /// surfaces around an exit point, which the indirect light it completes is part of: the
    /// first gather reads the blended lightmap (the panes and the direct share), each further
    /// one the lightmap the previous gather completed, so that light passing back and forth
    /// between close surfaces (a sofa's cushions, a moulding) is counted more than once; the
    /// rest of that series is extrapolated after the last ([`NearTail`]). `cargo xtask eval
    /// --targets`' fireplace room (default bake) with 1, 2, 3, 4 and 7 gathers and no tail:
    /// 8.73%, 7.55%, 7.42%, 7.36% and 7.25% (energy 0.989, 1.013, 1.020, 1.023, 1.025), 64:
    /// 7.16%; with the tail 7.51% after one gather (a texel at a wall lamp spikes: local error
    /// 6.1×), **7.08%** after two, 7.27% after three. Each gather costs the fireplace room's
    /// 1024×768 `gi` frame about 30 ms of its 405 ms on lavapipe (`prm-play --timings
    /// --gi-update every-frame`, medians of 10, two runs: 405, 436 and 480 ms with 1, 2 and 4
    /// gathers).
    pub const DEFAULT_NEAR_BOUNCES: u32 = 2;

    /// Shadow texels a shadow lookup moves its point along the normal. Moved out of its
    /// surface, a point near a shadow's edge looks past the occluder's rim, so the offset widens
    /// every lit area by about its length times the tangent of the light's angle; acne is left to
    /// the depth tolerance, which grows with the same tangent (`lights.wgsl`,
    /// `DEPTH_BIAS_MAX_SLOPE`). Measured on the eval's archives (direct light, 512×384, 512²
    /// views, against the same frame with 4096² views): at 0.5 energy within 0.4% of 1 everywhere
    /// but Sponza's high sun (1.026; 1.072 at 1.5), and below 0.5 surfaces shadow themselves. The
    /// indirect light reads the same lookups: `cargo xtask eval --sky` measures it on Sponza.
    pub const DEFAULT_NORMAL_OFFSET: f32 = 0.5;

    /// Tiles on a side of a directional light's shadow map. Measured on Sponza under a high sun
    /// (`cargo xtask eval --sky`'s view, 192×144, 512² per view; direct light against the
    /// references, 4×4 error): one map over the bounding sphere 23.5% off, light leaking through
    /// thin geometry; 2², 4² and 8² tiles 20.0%, 13.1% and 8.3%, for whole 1024×768 frames on
    /// lavapipe of 417–450, 461–474 and 615 ms (`prm-play --timings --gi-update every-frame`).
    /// Larger views sharpen sun shadows more cheaply than more tiles (4² of 1024²: 8.4%), but
    /// `shadow_resolution` is shared with the point lights' cube faces, which would pay four
    /// times their fill too.
    pub const DEFAULT_SUN_TILES: u32 = 4;

    /// The defaults with the top K the archive asks for ([`archive_top_k`]).
    pub fn for_archive<R: std::io::Read + std::io::Seek>(archive: &Archive<R>) -> RuntimeOptions {
        RuntimeOptions {
            top_k: archive_top_k(archive),
            ..RuntimeOptions::default()
        }
    }

    /// Checks the options against `limits` before any GPU allocation, naming the field and the
    /// limit it breaks.
    pub fn validate(&self, limits: &wgpu::Limits) -> Result<(), RuntimeError> {
        let bad = |option: &'static str, message: String| Err(RuntimeError::Option { option, message });
        let max_dim = limits.max_texture_dimension_2d;
        let max_shadow = max_dim.min(MAX_SHADOW_RESOLUTION);
        if !(16..=max_shadow).contains(&self.shadow_resolution) {
            return bad(
                "shadow_resolution",
                format!(
                    "{} is outside 16..={max_shadow} (the least of this device's max_texture_dimension_2d \
                     {max_dim} and {MAX_SHADOW_RESOLUTION}, where one point light's six faces take 1.5 GiB)",
                    self.shadow_resolution
                ),
            );
        }
        if !(1..=MAX_SUN_TILES).contains(&self.sun_tiles) {
            return bad(
                "sun_tiles",
                format!("{} is outside 1..={MAX_SUN_TILES}", self.sun_tiles),
            );
        }
        if self.top_k == 0 {
            return bad("top_k", "must be at least 1".into());
        }
        if self.near_bounces > MAX_NEAR_BOUNCES {
            return bad(
                "near_bounces",
                format!("{} is over {MAX_NEAR_BOUNCES}", self.near_bounces),
            );
        }
        for (option, v) in [
            ("fade_band", self.fade_band),
            ("normal_offset", self.normal_offset),
            ("depth_bias", self.depth_bias),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(option, format!("{v} must be a finite number >= 0"));
            }
        }
        Ok(())
    }
}

impl Default for RuntimeOptions {
    fn default() -> Self {
        RuntimeOptions {
            top_k: RuntimeOptions::DEFAULT_TOP_K,
            residual_groups: prm_format::RESIDUAL_GROUPS,
            shadow_resolution: 512,
            sun_tiles: RuntimeOptions::DEFAULT_SUN_TILES,
            fade_band: 0.25,
            normal_offset: Self::DEFAULT_NORMAL_OFFSET,
            depth_bias: 1.5,
            probe_light: ProbeLight::default(),
            near_light: NearLight::default(),
            near_bounces: Self::DEFAULT_NEAR_BOUNCES,
            near_tail: NearTail::default(),
            pane_chunk_bytes: None,
            gi_update: GiUpdate::default(),
        }
    }
}

/// The top K an archive asks for (`params.top_k`), else [`RuntimeOptions::DEFAULT_TOP_K`].
pub fn archive_top_k<R: std::io::Read + std::io::Seek>(archive: &Archive<R>) -> u32 {
    archive
        .metadata()
        .params
        .get("top_k")
        .and_then(|v| v.as_u64())
        .map(|k| k.clamp(1, u32::MAX as u64) as u32)
        .unwrap_or(RuntimeOptions::DEFAULT_TOP_K)
}
