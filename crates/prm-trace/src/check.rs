//! The bake's estimate of its own accuracy: the archive's indirect light, blended as the player
//! blends it, against [`ReferenceTracer`] over a sample of small surface patches, for a few
//! point lights the check places itself.
//!
//! **Lights** ([`check_lights`]): the first [`CHECK_LIGHTS`] of [`CANDIDATES`] (fractions of the
//! scene's bounds, as a user would first try) neither inside geometry
//! ([`crate::probes::is_inside`]) nor closer than [`CLEARANCE`] of the bounds' diagonal to a
//! surface; then one hard light ([`hard_light`]): a lamp [`HARD_DISTANCE`] under the ceiling
//! above the first (or by a wall beside it), where the entry points' spacing decides the light
//! next to it and the method is weakest.
//!
//! **Where** ([`CheckPoints`]): points drawn in proportion to the surface area their texels
//! stand for ([`area_exits`], [`Atlas::exit_areas`]), each compared as the mean of the 3×3
//! texels around it in its chart, as an image's error is measured after a 4×4 downsample. An
//! image shows surfaces by their area, while the atlas gives small charts more texels each
//! (every triangle owns one): drawn evenly over the texels, the modern hall's lamps read 14.7%
//! and 22.9% against the images' 4.5% and 9.9%, and the fireplace room 8.3–11.7% against
//! 4.7–5.1%; drawn by area, 4.0% and 9.1%, and 4.3–4.8% (`prm-bake check --light` on the
//! `cargo xtask eval --targets` bakes; the table is in `docs/technique.md`).
//!
//! **The archive's side** ([`check_accuracy`]): entries' direct irradiance ray-cast with the run
//! time's disk bound ([`entry_irradiance`]), clusters weighed by pane energy ([`energy_weight`]),
//! the top K kept and faded and the rest carried by the residual groups ([`select_with_residuals`],
//! [`select_top_k`] for a player without groups), and the near field's shares added as the player
//! adds them ([`crate::NearPlay`]). Shadow maps are not modelled: ray-cast and shadow-mapped light
//! agree within 0.1 points on the boxes and 2 points on chairs (`cargo xtask eval --budget`).
//!
//! **The reference** is [`ReferenceTracer::indirect_at_exits`] with [`CheckParams::paths`] paths
//! a patch, shared by its texels ([`reference_params`]), its streams keyed by the bake's seed,
//! [`CHECK_STREAM`] and the light. Its own noise `Σ var` is removed from both sums:
//! `(Σ|p − r̂|² − Σ var) / (Σ|r̂|² − Σ var)` estimates the squared error without the noise's
//! bias.
//!
//! **How much** ([`CheckParams::DEFAULT`], 2048 points × 512 paths × 4 lights): a few seconds of
//! a bake. Fewer points do not hold still: McGuire's box under its ceiling light read 2.5%, 7.4%
//! and 2.7% at three draws of 512 single exit points (4096 paths each), and 2.6–3.1% at 4096
//! points of 512 paths (`cargo xtask eval experiment check_weights`).
//!
//! **What it does not see.** It measures the whole surface, an image one view: on chairs it
//! reads 2.2% against the image's 3.2%; there the patches the image's camera sees read 3.1%
//! and all of them, weighed by area, 2.6% (`cargo xtask eval experiment check_weights`). It
//! compares texel centres, where an image also shows the lightmap's bilinear lookup between
//! them. Weighing the patches by the solid angle they take from random places in the scene, as
//! a viewer's image would, was tried and left out: under the hall's ceiling lamp it read 5.7%,
//! 13.0% and 16.2% with three sets of viewpoints, against the image's 4.5%.

use glam::Vec3;
use prm_format::{Accuracy, LightAccuracy};
use prm_scene::{Atlas, ExitPoint, Light, Scene};

use crate::bvh::Bvh;
use crate::cluster::energy_weight;
use crate::direct::entry_irradiance;
use crate::reference::{Lighting, ReferenceParams, ReferenceTracer};
use crate::sampling::SurfaceSample;
use crate::TraceError;

/// Test lights of a check.
pub const CHECK_LIGHTS: usize = 3;

/// Candidate positions of the test lights, as fractions of the scene's bounds (y up), tried in
/// order.
pub const CANDIDATES: [[f32; 3]; 9] = [
    [0.5, 0.8, 0.5],
    [0.25, 0.4, 0.3],
    [0.75, 0.3, 0.7],
    [0.5, 0.5, 0.5],
    [0.3, 0.65, 0.7],
    [0.7, 0.6, 0.3],
    [0.5, 0.25, 0.5],
    [0.2, 0.2, 0.8],
    [0.8, 0.8, 0.2],
];

/// Least distance from a test light to the nearest surface, as a fraction of the bounds'
/// diagonal: a light closer than that is the method's known failure (the stability suite's),
/// not what a first estimate should report.
pub const CLEARANCE: f32 = 0.03;

/// Largest distance of the hard test light below the ceiling, in scene units (metres in glTF):
/// a lamp within half a metre of a ceiling is common in game levels. Smaller scenes take
/// [`CLEARANCE`] of their diagonal instead (2.8 cm in the bundled Cornell box).
pub const HARD_DISTANCE: f32 = 0.4;

/// Directions of the clearance test.
const CLEARANCE_DIRECTIONS: u32 = 64;

/// The width of the run time's fade band above the K-th score (prm-runtime's
/// `RuntimeOptions::fade_band` default; `tests/check.rs` keeps the two equal).
pub const FADE_BAND: f32 = 0.25;

/// How much the check measures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CheckParams {
    /// Exit points compared (see [`check_exits`]).
    pub exit_points: u32,
    /// Reference paths per exit point and light.
    pub paths: u32,
    /// Seed of the reference.
    pub seed: u64,
}

impl CheckParams {
    /// 2048 points × 512 paths (see the module's *How much*).
    pub const DEFAULT: CheckParams = CheckParams {
        exit_points: 2048,
        paths: 512,
        seed: 0,
    };
}

impl Default for CheckParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Positions of at most [`CHECK_LIGHTS`] clear test lights in `scene` (fewer when fewer
/// candidates are free), then the [`hard_light`] when there is one.
pub fn check_lights(scene: &Scene, bvh: &Bvh) -> Vec<Vec3> {
    let b = scene.bounds();
    let clearance = CLEARANCE * b.diagonal();
    let mut lights: Vec<Vec3> = CANDIDATES
        .iter()
        .map(|f| b.min + (b.max - b.min) * Vec3::from_array(*f))
        .filter(|&p| !crate::probes::is_inside(bvh, p) && nearest_surface(bvh, p, clearance) >= clearance)
        .take(CHECK_LIGHTS)
        .collect();
    if let Some(hard) = lights.iter().find_map(|&p| hard_light(scene, bvh, p)) {
        lights.push(hard);
    }
    lights
}

/// A test light close to the surface above `p` (the ceiling), or else beside it (a wall, along
/// ±x then ±z): `min(HARD_DISTANCE, CLEARANCE · diagonal)` from it; `None` when no surface is
/// far enough from `p` in those directions for a light between them.
pub fn hard_light(scene: &Scene, bvh: &Bvh, p: Vec3) -> Option<Vec3> {
    let distance = HARD_DISTANCE.min(CLEARANCE * scene.bounds().diagonal());
    [Vec3::Y, Vec3::X, Vec3::NEG_X, Vec3::Z, Vec3::NEG_Z]
        .into_iter()
        .find_map(|d| {
            let hit = bvh.closest_hit(p, d, f32::INFINITY, u32::MAX)?;
            let light = p + d * (hit.t - distance);
            (hit.t > 2.0 * distance && !crate::probes::is_inside(bvh, light)).then_some(light)
        })
}

/// Distance from `p` to the nearest surface along [`CLEARANCE_DIRECTIONS`] rays, at most `tmax`.
fn nearest_surface(bvh: &Bvh, p: Vec3, tmax: f32) -> f32 {
    (0..CLEARANCE_DIRECTIONS)
        .filter_map(|i| {
            let d = crate::probes::fibonacci_direction(i, CLEARANCE_DIRECTIONS);
            bvh.closest_hit(p, d, tmax, u32::MAX).map(|h| h.t)
        })
        .fold(tmax, f32::min)
}

/// Indices of `sample` exit points out of `count`, ascending: one drawn at random (seeded) from
/// each of `sample` equal runs of the atlas's exit points (all of them when `sample ≥ count`).
///
/// Exit points run in texel order, row by row, so an even stride samples the atlas along
/// diagonal lines and a light's error along them: on our Cornell box, five strides near 256
/// points gave 9.1–14.3% where 2048 points × 4096 paths gave 11.7% (one light).
pub fn check_exits(count: usize, sample: u32, seed: u64) -> Vec<usize> {
    let s = (sample as usize).min(count);
    (0..s)
        .map(|i| {
            let (a, b) = (i * count / s, (i + 1) * count / s);
            let mut rng = crate::rng::Rng::new(seed, CHECK_STREAM, i as u64);
            a + ((rng.next_f32() * (b - a) as f32) as usize).min(b - a - 1)
        })
        .collect()
}

/// Indices of `sample` exit points drawn in proportion to the surface area each stands for
/// (`areas`, from [`Atlas::exit_areas`]): one at random (seeded) from each of `sample` equal
/// runs of the cumulative area in texel order, so a texel larger than a run may come twice.
pub fn area_exits(areas: &[f32], sample: u32, seed: u64) -> Vec<usize> {
    let cumulative: Vec<f64> = areas
        .iter()
        .scan(0.0f64, |sum, &a| {
            *sum += f64::from(a.max(0.0));
            Some(*sum)
        })
        .collect();
    let total = cumulative.last().copied().unwrap_or(0.0);
    if total <= 0.0 {
        return Vec::new();
    }
    (0..sample)
        .map(|i| {
            let mut rng = crate::rng::Rng::new(seed, CHECK_STREAM, u64::from(i));
            let u = (f64::from(i) + f64::from(rng.next_f32())) / f64::from(sample) * total;
            cumulative.partition_point(|&c| c <= u).min(areas.len() - 1)
        })
        .collect()
}

/// The random streams of [`check_exits`], [`area_exits`] and the check's reference (apart from
/// every other use of the bake's seed).
pub const CHECK_STREAM: u64 = 0x636865636b;

/// The check's exit points: around each point [`check_exits`] draws, a patch of the texels
/// next to it, compared as their mean.
///
/// An image's error is measured after a 4×4 downsample, which averages out what changes from
/// texel to texel (the near field's gathers, the panes' detail); a texel alone keeps it all.
/// With 2048 points (`cargo xtask eval experiment check_weights`), McGuire's box under its
/// ceiling light read 3.7–5.1% at single exit points and 2.2% over patches, against 2.7% in
/// the image; the fireplace room 9.6–10.3% and 8.5–9.0%.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CheckPoints {
    /// Exit point indices, patch after patch, each patch's drawn point first.
    pub exits: Vec<usize>,
    /// One past each patch's last entry in `exits`.
    pub ends: Vec<usize>,
}

impl CheckPoints {
    /// [`area_exits`]`(scene's exit areas, sample, seed)`, each with the exit points of the
    /// eight texels around it that lie in its chart.
    pub fn draw(scene: &Scene, atlas: &Atlas, sample: u32, seed: u64) -> CheckPoints {
        let side = i64::from(atlas.resolution);
        let mut points = CheckPoints::default();
        for centre in area_exits(&atlas.exit_areas(scene), sample, seed) {
            let texel = atlas.exits[centre].texel as usize;
            let (x, y) = (texel as i64 % side, texel as i64 / side);
            points.exits.push(centre);
            for (dx, dy) in (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (dx, dy))) {
                let (u, v) = (x + dx, y + dy);
                if (dx, dy) == (0, 0) || !(0..side).contains(&u) || !(0..side).contains(&v) {
                    continue;
                }
                let next = (v * side + u) as usize;
                let exit = atlas.texel_exit[next];
                if exit != prm_scene::EMPTY_TEXEL && atlas.texel_chart[next] == atlas.texel_chart[texel] {
                    points.exits.push(exit as usize);
                }
            }
            points.ends.push(points.exits.len());
        }
        points
    }

    /// Whether nothing is checked.
    pub fn is_empty(&self) -> bool {
        self.ends.is_empty()
    }

    /// Each patch's mean of the per-texel `values` (given at [`CheckPoints::exits`]).
    pub fn means(&self, values: &[Vec3]) -> Vec<Vec3> {
        self.patches()
            .map(|r| {
                let n = r.len() as f32;
                values[r].iter().sum::<Vec3>() / n
            })
            .collect()
    }

    /// Each patch's range in [`CheckPoints::exits`].
    pub fn patches(&self) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
        self.ends.iter().scan(0, |start, &end| {
            let range = *start..end;
            *start = end;
            Some(range)
        })
    }
}

/// The run time's fade of every cluster (prm-runtime's rank pass and the select pass's fade):
/// with `score_c = Σ_rgb weight_c · energy_c`, the `top_k` clusters of highest score (ties to
/// the lower index) get `smoothstep(t, t·(1 + fade_band), score)` where `t` is the score of the
/// first one dropped, the others 0. `None` when `top_k ≥` the cluster count (nothing dropped).
fn fades(weights: &[Vec3], cluster_energy: &[Vec3], top_k: usize, fade_band: f32) -> Option<(Vec<f32>, Vec<f32>)> {
    let n = weights.len();
    if top_k >= n {
        return None;
    }
    let score: Vec<f32> = weights.iter().zip(cluster_energy).map(|(w, e)| w.dot(*e)).collect();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| score[b].total_cmp(&score[a]).then(a.cmp(&b)));
    let t = score[order[top_k]];
    let width = t * fade_band;
    let mut fade = vec![0f32; n];
    for &c in &order[..top_k] {
        fade[c] = if width <= 0.0 {
            f32::from(score[c] > t)
        } else {
            let x = ((score[c] - t) / width).clamp(0.0, 1.0);
            x * x * (3.0 - 2.0 * x)
        };
    }
    Some((score, fade))
}

/// The weights the run time blends without residual groups, on the CPU (prm-runtime's rank
/// and select passes with `residual_groups: 0`): the top K faded (`fades`), and all kept
/// weights scaled by `Σ_all score / Σ_kept score · fade`; the others get 0. With `top_k ≥` the
/// cluster count the weights are returned as they are.
pub fn select_top_k(weights: &[Vec3], cluster_energy: &[Vec3], top_k: usize, fade_band: f32) -> Vec<Vec3> {
    let Some((score, fade)) = fades(weights, cluster_energy, top_k, fade_band) else {
        return weights.to_vec();
    };
    let all: f32 = score.iter().sum();
    let kept: f32 = score.iter().zip(&fade).map(|(s, f)| s * f).sum();
    let factor = if kept > 0.0 { all / kept } else { 1.0 };
    weights.iter().zip(&fade).map(|(w, f)| *w * (f * factor)).collect()
}

/// The weights the run time blends with residual groups (prm-runtime's select pass with
/// `group_of`, from [`prm_format::residual_groups`]): the top K faded (`fades`) and not
/// scaled, and for every group `g` the weight of its summed pane, `Σ_{c∈g} w_c ⊙ e_c ⊙ (1 −
/// fade_c) / E_g` per channel (0 where `E_g`, the group pane's energy, is 0). Returns the
/// clusters' weights and the groups'; with `top_k ≥` the cluster count, the weights as they
/// are and no group light. The run time and the bake's check ([`played_indirect`]) both take
/// `E_g` as the members' summed energies.
pub fn select_with_residuals(
    weights: &[Vec3],
    cluster_energy: &[Vec3],
    top_k: usize,
    fade_band: f32,
    group_of: &[u32],
    group_energy: &[Vec3],
) -> (Vec<Vec3>, Vec<Vec3>) {
    let Some((_, fade)) = fades(weights, cluster_energy, top_k, fade_band) else {
        return (weights.to_vec(), vec![Vec3::ZERO; group_energy.len()]);
    };
    let mut left = vec![Vec3::ZERO; group_energy.len()];
    for (c, (w, f)) in weights.iter().zip(&fade).enumerate() {
        left[group_of[c] as usize] += *w * cluster_energy[c] * (1.0 - f);
    }
    let groups = left
        .iter()
        .zip(group_energy)
        .map(|(l, e)| Vec3::select(e.cmpgt(Vec3::ZERO), *l / *e, Vec3::ZERO))
        .collect();
    (weights.iter().zip(&fade).map(|(w, f)| *w * *f).collect(), groups)
}

/// What an archive holds, at the checked exit points.
#[derive(Clone, Copy, Debug)]
pub struct CheckedArchive<'a> {
    /// The checked patches; [`CheckedArchive::panes`] and the near field are given at their
    /// exit points, in their order.
    pub points: &'a CheckPoints,
    /// Entry points, in sampling order.
    pub entries: &'a [SurfaceSample],
    /// Every entry point's cell, in sampling order (`None`: each entry point's own irradiance,
    /// bounded by the entry disk, as the player does with archives without them).
    pub cells: Option<&'a prm_format::EntryCells>,
    /// Entry points of every cluster (indices into `entries`).
    pub members: &'a [Vec<u32>],
    /// Every entry's pane energy, in sampling order (`None`: members weigh equally, as the
    /// player does with archives without them).
    pub entry_energy: Option<&'a [Vec3]>,
    /// Every pane's energy (the archive's cluster table, the sum of its texels).
    pub cluster_energy: &'a [Vec3],
    /// Every pane as the player shows it at the checked exit points, `[cluster][point]`: with
    /// the near field, its light and the deeper share's series from it
    /// ([`crate::NearPlay::series`]).
    pub panes: &'a [Vec<Vec3>],
    /// Clusters the player blends.
    pub top_k: usize,
    /// The residual group of every cluster ([`prm_format::residual_groups`]), or empty for a
    /// player without residual groups.
    pub groups: &'a [u32],
    /// The player's fade band ([`FADE_BAND`]).
    pub fade_band: f32,
    /// The near field as the player sums it, whose direct share ([`crate::NearPlay::direct`])
    /// is added to the panes' light; `None` without one.
    pub near: Option<&'a crate::NearPlay<'a>>,
}

/// The archive's indirect light at `exits` (the checked exit points) under `light`, for the
/// player's K (first) and for every cluster (second).
pub fn played_indirect(bvh: &Bvh, archive: &CheckedArchive<'_>, light: Light) -> (Vec<Vec3>, Vec<Vec3>) {
    let e = match archive.cells {
        Some(cells) => {
            let positions: Vec<Vec3> = archive.entries.iter().map(|e| e.position).collect();
            let normals: Vec<Vec3> = archive.entries.iter().map(|e| e.normal).collect();
            let reach2 = crate::cell_reach2(archive.entries.first().map_or(0.0, |e| e.weight));
            crate::cell_irradiance(bvh, &[light], &positions, &normals, cells, reach2)
        }
        None => entry_irradiance(bvh, &[light], archive.entries),
    };
    let ones;
    let energy = match archive.entry_energy {
        Some(en) => en,
        None => {
            ones = vec![Vec3::ONE; archive.entries.len()];
            &ones
        }
    };
    let weights: Vec<Vec3> = archive
        .members
        .iter()
        .map(|m| energy_weight(m.iter().map(|&k| k as usize), &e, energy))
        .collect();
    let points = archive.panes.first().map_or(0, Vec::len);
    let blend = |w: &[Vec3], panes: &[Vec<Vec3>]| {
        let mut out = vec![Vec3::ZERO; points];
        for (wc, pane) in w.iter().zip(panes) {
            if *wc != Vec3::ZERO {
                for (o, v) in out.iter_mut().zip(pane) {
                    *o += *wc * *v;
                }
            }
        }
        out
    };
    let played = if archive.groups.is_empty() {
        blend(
            &select_top_k(&weights, archive.cluster_energy, archive.top_k, archive.fade_band),
            archive.panes,
        )
    } else {
        // The groups' summed panes and their energies.
        let count = archive.groups.iter().max().map_or(0, |g| *g as usize + 1);
        let mut sums = vec![vec![Vec3::ZERO; points]; count];
        let mut energy = vec![Vec3::ZERO; count];
        for ((pane, e), &g) in archive.panes.iter().zip(archive.cluster_energy).zip(archive.groups) {
            energy[g as usize] += *e;
            for (s, v) in sums[g as usize].iter_mut().zip(pane) {
                *s += *v;
            }
        }
        let (kept, residual) = select_with_residuals(
            &weights,
            archive.cluster_energy,
            archive.top_k,
            archive.fade_band,
            archive.groups,
            &energy,
        );
        let mut out = blend(&kept, archive.panes);
        for (o, r) in out.iter_mut().zip(blend(&residual, &sums)) {
            *o += r;
        }
        out
    };
    let (mut played, mut all) = (played, blend(&weights, archive.panes));
    if let Some(near) = archive.near {
        // The direct share and its series, once for both blends (the panes' series are in them).
        let direct = near.direct(bvh, &[light]);
        for out in [&mut played, &mut all] {
            for (p, d) in out.iter_mut().zip(&direct) {
                *p += *d;
            }
        }
    }
    (played, all)
}

/// Compares the archive's indirect light with the reference's over its checked patches (their
/// exit points are `exits`, in that order) for a point light at each of `lights`. The
/// patches' texels share `params.paths` paths a patch. `progress(done)` is called with the
/// reference passes done so far, out of `lights.len() × `[`reference_params`]`.passes`.
pub fn check_accuracy(
    scene: &Scene,
    bvh: &Bvh,
    exits: &[ExitPoint],
    archive: &CheckedArchive<'_>,
    lights: &[Vec3],
    params: &CheckParams,
    progress: &mut dyn FnMut(u64),
) -> Result<Accuracy, TraceError> {
    let points = archive.points;
    validate_inputs(points, exits, archive)?;
    let d = scene.bounds().diagonal();
    let texel_params = reference_params(points, params);
    let mut done = 0u64;
    let mut out = Vec::with_capacity(lights.len());
    for (i, &position) in lights.iter().enumerate() {
        let reference = ReferenceParams {
            seed: crate::rng::hash3(params.seed, CHECK_STREAM, i as u64),
            ..texel_params
        };
        let light = Light::Point {
            position,
            intensity: Vec3::splat(d * d),
        };
        let lighting = [light];
        let tracer = ReferenceTracer::new(scene, bvh, Lighting::Lights(&lighting));
        let r = tracer.indirect_at_exits(exits, &reference, &mut |pass, _| progress(done + u64::from(pass)))?;
        done += u64::from(reference.passes);
        let (played, all) = played_indirect(bvh, archive, light);
        let patch = Patches::new(points, &r.mean, &r.variance);
        let (played, all) = (points.means(&played), points.means(&all));
        out.push(patch.compare(position.to_array(), &played, &all));
    }
    let texel_paths = texel_params.passes * texel_params.samples_per_pass;
    Ok(Accuracy {
        exit_points: points.ends.len() as u32,
        paths: (texel_paths as usize * exits.len()).div_ceil(points.ends.len().max(1)) as u32,
        residual_groups: archive.groups.iter().max().map_or(0, |g| g + 1),
        top_k: archive.top_k as u32,
        lights: out,
    })
}

/// The reference's paths at every texel of the check: `params.paths` a patch, shared evenly
/// by the patches' texels (at least one each).
pub fn reference_params(points: &CheckPoints, params: &CheckParams) -> ReferenceParams {
    let texels = points.exits.len().max(1) as u64;
    let per_texel = (u64::from(params.paths) * points.ends.len() as u64).div_ceil(texels);
    ReferenceParams::with_spp(per_texel.clamp(1, u64::from(u32::MAX)) as u32)
}

/// Refuses inputs whose lengths disagree.
fn validate_inputs(points: &CheckPoints, exits: &[ExitPoint], archive: &CheckedArchive<'_>) -> Result<(), TraceError> {
    if archive.panes.iter().any(|p| p.len() != exits.len())
        || points.exits.len() != exits.len()
        || points.ends.last().copied().unwrap_or(0) != exits.len()
        || points.patches().any(|r| r.is_empty())
        || archive.panes.len() != archive.members.len()
        || archive.cluster_energy.len() != archive.members.len()
        || !(archive.groups.is_empty() || archive.groups.len() == archive.members.len())
        || archive.near.is_some_and(|n| n.checked() != exits.len())
    {
        return Err(TraceError::InvalidParameter(
            "every cluster needs a pane energy and one pane value per checked exit point, in whole patches".into(),
        ));
    }
    let entries = archive.entries.len();
    if archive.entry_energy.is_some_and(|e| e.len() != entries)
        || archive.members.iter().flatten().any(|&k| k as usize >= entries)
    {
        return Err(TraceError::InvalidParameter(
            "every cluster member needs an entry point (and its energy)".into(),
        ));
    }
    Ok(())
}

/// The reference over the check's patches: each patch's mean and the variance of that mean.
struct Patches {
    mean: Vec<Vec3>,
    variance: Vec<Vec3>,
}

impl Patches {
    /// The patches of `points` over the reference's per-texel `mean` and `variance`.
    fn new(points: &CheckPoints, mean: &[Vec3], variance: &[Vec3]) -> Patches {
        Patches {
            mean: points.means(mean),
            variance: points
                .patches()
                .map(|r| {
                    let n = r.len() as f32;
                    variance[r].iter().sum::<Vec3>() / (n * n)
                })
                .collect(),
        }
    }

    /// The light at `position`'s accuracy: `played` (the player's K) and `all` (every cluster)
    /// against the reference, patch by patch.
    fn compare(&self, position: [f32; 3], played: &[Vec3], all: &[Vec3]) -> LightAccuracy {
        let (reference, variance) = (&self.mean, &self.variance);
        let norm2: f64 = reference.iter().map(|v| f64::from(v.length_squared())).sum();
        let noise2: f64 = variance.iter().map(|v| f64::from(v.element_sum())).sum();
        let err2 = |t: &[Vec3]| -> f64 {
            t.iter()
                .zip(reference)
                .map(|(a, b)| f64::from((*a - *b).length_squared()))
                .sum()
        };
        let rel = |x: f64| if norm2 > 0.0 { (x / norm2).sqrt() } else { 0.0 };
        // Both sums without the reference's noise (see the module's *The reference*).
        let corrected = |e2: f64| {
            let n2 = norm2 - noise2;
            if n2 > 0.0 {
                ((e2 - noise2).max(0.0) / n2).sqrt()
            } else {
                0.0
            }
        };
        let sum = |v: &[Vec3]| -> f64 { v.iter().map(|x| f64::from(x.element_sum())).sum() };
        let (sum_ref, sum_played) = (sum(reference), sum(played));
        let error = corrected(err2(played));
        LightAccuracy {
            position,
            error,
            measured: rel(err2(played)),
            reference_noise: rel(noise2),
            energy: if sum_ref > 0.0 { sum_played / sum_ref } else { 0.0 },
            error_all_clusters: corrected(err2(all)),
            standard_error: standard_error(played, reference, variance, error),
        }
    }
}

/// The standard error of `error`, the noise-corrected `√(Σ t_i / Σ q_i)` with per point
/// `t_i = |played_i − ref_i|² − Σ_rgb var_i` and `q_i = |ref_i|² − Σ_rgb var_i`, from the points' own spread
/// (the delta method on the ratio of the two sums, and `d√x = dx / (2√x)`). The points are a
/// random sample of the exit points, so this is the spread of the estimate over draws of them
/// and of the reference's paths.
fn standard_error(played: &[Vec3], reference: &[Vec3], variance: &[Vec3], error: f64) -> f64 {
    let n = reference.len();
    if n < 2 {
        return 0.0;
    }
    let t: Vec<f64> = played
        .iter()
        .zip(reference)
        .zip(variance)
        .map(|((a, b), v)| f64::from((*a - *b).length_squared()) - f64::from(v.element_sum()))
        .collect();
    let q: Vec<f64> = reference
        .iter()
        .zip(variance)
        .map(|(v, var)| f64::from(v.length_squared()) - f64::from(var.element_sum()))
        .collect();
    let nf = n as f64;
    let (mt, mq) = (t.iter().sum::<f64>() / nf, q.iter().sum::<f64>() / nf);
    if mq <= 0.0 {
        return 0.0;
    }
    let ratio = mt / mq;
    // Var of the ratio of means: Var(t − ratio·q) / (n · mq²).
    let var: f64 = t.iter().zip(&q).map(|(a, b)| (a - ratio * b).powi(2)).sum::<f64>() / (nf - 1.0);
    let se2 = (var / nf).sqrt() / mq;
    // Near zero the square root's slope diverges: bound by the error of `√se²`.
    if error > 0.0 {
        (se2 / (2.0 * error)).min(se2.sqrt())
    } else {
        se2.sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn selection_keeps_everything_when_k_covers_the_clusters() {
        let w = vec![Vec3::new(1.0, 2.0, 3.0), Vec3::splat(0.5)];
        let e = vec![Vec3::ONE; 2];
        assert_eq!(select_top_k(&w, &e, 2, FADE_BAND), w);
        assert_eq!(select_top_k(&w, &e, 5, FADE_BAND), w);
    }

    #[test]
    fn selection_drops_the_lowest_and_keeps_the_total_score() {
        // Scores 8, 4, 2, 1 (unit energies, grey weights / 3): K = 2 drops the last two; the
        // first dropped (2) sets the fade, 4 lies above 2·1.25, so nothing fades.
        let w: Vec<Vec3> = [8.0f32, 4.0, 2.0, 1.0].iter().map(|s| Vec3::splat(s / 3.0)).collect();
        let e = vec![Vec3::ONE; 4];
        let kept = select_top_k(&w, &e, 2, FADE_BAND);
        assert_eq!(kept[2], Vec3::ZERO);
        assert_eq!(kept[3], Vec3::ZERO);
        let total = |w: &[Vec3]| w.iter().zip(&e).map(|(a, b)| a.dot(*b)).sum::<f32>();
        assert!((total(&kept) - total(&w)).abs() < 1e-5 * total(&w));
        assert!((kept[0].x / kept[1].x - 2.0).abs() < 1e-6, "{kept:?}");
        // A cluster just above the threshold fades: scores 8, 2.1, 2, 1.
        let w: Vec<Vec3> = [8.0f32, 2.1, 2.0, 1.0].iter().map(|s| Vec3::splat(s / 3.0)).collect();
        let kept = select_top_k(&w, &e, 2, FADE_BAND);
        let x = 0.1 / 0.5f32;
        let fade = x * x * (3.0 - 2.0 * x);
        assert!((kept[1].x / kept[0].x - fade * 2.1 / 8.0).abs() < 1e-5, "{kept:?}");
        assert!((total(&kept) - total(&w)).abs() < 1e-5 * total(&w));
    }

    #[test]
    fn residual_groups_carry_what_the_selection_drops() {
        // Scores 8, 4, 2, 1 (unit energies): K = 2 keeps the first two unfaded and unscaled;
        // group 0 = {0, 2}, group 1 = {1, 3}, each group's pane energy 2.
        let w: Vec<Vec3> = [8.0f32, 4.0, 2.0, 1.0].iter().map(|s| Vec3::splat(s / 3.0)).collect();
        let e = vec![Vec3::ONE; 4];
        let (kept, groups) = select_with_residuals(&w, &e, 2, FADE_BAND, &[0, 1, 0, 1], &[Vec3::splat(2.0); 2]);
        assert_eq!(&kept[..2], &w[..2]);
        assert_eq!(&kept[2..], &[Vec3::ZERO; 2]);
        assert!((groups[0] - w[2] / 2.0).abs().max_element() < 1e-6, "{groups:?}");
        assert!((groups[1] - w[3] / 2.0).abs().max_element() < 1e-6, "{groups:?}");
        // The total light is kept: Σ kept · e + Σ groups · E = Σ w · e.
        let total = |w: &[Vec3], e: &[Vec3]| w.iter().zip(e).map(|(a, b)| a.dot(*b)).sum::<f32>();
        let all = total(&w, &e);
        let played = total(&kept, &e) + total(&groups, &[Vec3::splat(2.0); 2]);
        assert!((played - all).abs() < 1e-5 * all);
        // A faded cluster hands the faded share to its group: scores 8, 2.1, 2, 1.
        let w: Vec<Vec3> = [8.0f32, 2.1, 2.0, 1.0].iter().map(|s| Vec3::splat(s / 3.0)).collect();
        let (kept, groups) = select_with_residuals(&w, &e, 2, FADE_BAND, &[0, 1, 0, 1], &[Vec3::splat(2.0); 2]);
        let x = 0.1 / 0.5f32;
        let fade = x * x * (3.0 - 2.0 * x);
        assert!((kept[1] - w[1] * fade).abs().max_element() < 1e-6);
        assert!((groups[1] - (w[1] * (1.0 - fade) + w[3]) / 2.0).abs().max_element() < 1e-6);
        // K covers everything: the weights as they are, no group light.
        let (kept, groups) = select_with_residuals(&w, &e, 4, FADE_BAND, &[0, 1, 0, 1], &[Vec3::splat(2.0); 2]);
        assert_eq!(kept, w);
        assert_eq!(groups, vec![Vec3::ZERO; 2]);
    }

    #[test]
    fn patches_hold_their_point_and_its_chart_neighbours() {
        let scene = prm_scene::analytic::furnace_box(1, 0.5);
        let params = prm_scene::AtlasParams::with_sizing(prm_scene::Sizing::Resolution(32));
        let atlas = Atlas::build(&scene, &params).unwrap();
        let points = CheckPoints::draw(&scene, &atlas, 40, 3);
        let drawn = area_exits(&atlas.exit_areas(&scene), 40, 3);
        assert_eq!(points.ends.len(), drawn.len());
        let side = atlas.resolution as i64;
        let xy = |k: usize| {
            let t = i64::from(atlas.exits[k].texel);
            (t % side, t / side)
        };
        let mut sizes = Vec::new();
        for (range, &centre) in points.patches().zip(&drawn) {
            let patch = &points.exits[range];
            assert_eq!(patch[0], centre);
            let (cx, cy) = xy(centre);
            let chart = atlas.texel_chart[atlas.exits[centre].texel as usize];
            for (n, &k) in patch.iter().enumerate() {
                let (x, y) = xy(k);
                assert!((x - cx).abs() <= 1 && (y - cy).abs() <= 1);
                assert_eq!(atlas.texel_chart[atlas.exits[k].texel as usize], chart);
                assert!(!patch[..n].contains(&k), "an exit point twice in {patch:?}");
            }
            sizes.push(patch.len());
        }
        assert!(sizes.iter().all(|&n| (1..=9).contains(&n)));
        assert!(sizes.contains(&9), "an inner texel's patch is whole: {sizes:?}");
        // The reference's paths a patch stay about `paths`.
        let texel = reference_params(&points, &CheckParams::DEFAULT);
        let per_patch = (texel.passes * texel.samples_per_pass) as f64 * points.exits.len() as f64 / 40.0;
        assert!((per_patch / 512.0 - 1.0).abs() < 0.1, "{per_patch}");
    }

    #[test]
    fn area_exits_follow_the_area() {
        // Runs of a quarter of the area: the first ends where exit 0 does, the other three fall
        // on exit 2; exit 1 stands for nothing.
        assert_eq!(area_exits(&[1.0, 0.0, 3.0], 4, 5), vec![0, 2, 2, 2]);
        let areas: Vec<f32> = (0..100).map(|i| if i < 50 { 1.0 } else { 3.0 }).collect();
        let x = area_exits(&areas, 1000, 7);
        let small = x.iter().filter(|&&k| k < 50).count();
        assert_eq!(small, 250, "a quarter of the area, a quarter of the points");
        // Runs wider than a texel: the draw within each follows the seed.
        assert_eq!(area_exits(&areas, 10, 7), area_exits(&areas, 10, 7));
        assert_ne!(area_exits(&areas, 10, 7), area_exits(&areas, 10, 8));
        assert!(area_exits(&[], 8, 0).is_empty());
        assert!(area_exits(&[0.0, 0.0], 8, 0).is_empty());
    }

    #[test]
    fn exits_are_one_per_run() {
        let x = check_exits(1000, 10, 7);
        assert_eq!(x.len(), 10);
        for (i, &k) in x.iter().enumerate() {
            assert!((i * 100..(i + 1) * 100).contains(&k), "{x:?}");
        }
        assert_eq!(x, check_exits(1000, 10, 7));
        assert_ne!(x, check_exits(1000, 10, 8));
        assert_eq!(check_exits(3, 8, 0), vec![0, 1, 2]);
        assert!(check_exits(0, 8, 0).is_empty());
    }
}
