//! Random walks from the entry points; every visited point becomes a virtual point light (VPL).
//!
//! # The estimator
//!
//! Units: lengths in scene units (metres by convention), irradiance `E` in W/m², power `Φ` in W,
//! all per RGB channel. Surfaces are Lambertian, BRDF `ρ/π`.
//!
//! At run time the indirect irradiance at an exit point `x` is linear in the direct irradiance
//! `E(y)` of the surface: `E_ind(x) = ∫_S T(x,y) E(y) dA(y)`. With `N` entry points `y_k` drawn
//! area-uniformly (density `1/A`, [`crate::sample_surface`]):
//!
//! ```text
//! E_ind(x) ≈ Σ_k E(y_k) · P_k(x),      P_k(x) = (A/N) · T(x, y_k)
//! ```
//!
//! `P_k` is entry point `k`'s **pane**: the indirect irradiance (W/m²) at every exit point when
//! `y_k` receives unit irradiance (1 W/m²) and no other entry point receives any; it is
//! dimensionless as a ratio of irradiances (W/m² per W/m²).
//!
//! Unit irradiance on the patch of area `A/N` around `y_k`, reflected diffusely, is a VPL at `y_k`
//! of power `Φ_0 = ρ(y_k)·A/N` (W per unit irradiance) with radiant intensity `Φ_0·cos θ/π`.
//! A walk leaves `y_j` with survival probability
//!
//! ```text
//! q_j = clamp(max_channel ρ(y_j), q_min, q_max)      (Russian roulette, default [0.05, 0.95])
//! ```
//!
//! in a cosine-distributed direction about the geometric normal. Cosine sampling matches the
//! Lambertian emission, so the flux it carries only changes by the roulette: the first hit
//! `y_{j+1}` receives `Φ_j/q_j`, and the light it reflects is a new VPL of power
//!
//! ```text
//! Φ_{j+1} = Φ_j · ρ(y_{j+1}) / q_j .
//! ```
//!
//! Because `q_j ≈ ρ(y_j)`, all VPLs of a walk carry about `(A/N)·ρ(y_current)`: powers stay even.
//! With `M` walks per entry point the entry VPL (depth 0) is shared by all walks and keeps `Φ_0`;
//! the VPLs of depth ≥ 1 are averaged over the walks, i.e. stored with power `Φ_j / M`.
//!
//! A VPL `v` (position `p_v`, normal `n_v`, power `Φ_v`) gives the exit point `x` (normal `n_x`)
//! the irradiance
//!
//! ```text
//! E_v(x) = Φ_v/π · cos θ_x · cos θ_v / |x − p_v|² · V(x, p_v)
//! ```
//!
//! (W/m² per unit entry irradiance), so `P_k(x) = Σ_{v ∈ VPLs of k} E_v(x)`. The `1/r²` term is
//! bounded in practice by [`crate::VplBound`]. Walks end when the roulette says so, when the ray
//! escapes the scene, when it hits the back of a surface (surfaces are one-sided: the back of a
//! closed object is never lit), or at `max_bounces` (default 256: with `q ≤ 0.95` the truncated
//! tail is below `0.95^256 ≈ 2·10⁻⁶`).
//!
//! Determinism: walk `m` of entry `k` draws from the stream `(seed, k, m)`; its first direction is
//! point `m` of a Sobol (0,2)-sequence scrambled per entry, so the `M` first bounces are stratified.

use std::ops::Range;

use glam::Vec3;
use prm_scene::Scene;
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::rng::{hash3, Rng};
use crate::sampling::{cosine_hemisphere, sobol2, SurfaceSample};
use crate::TraceError;

/// Russian roulette: survival probability `clamp(max channel of ρ, min, max)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Roulette {
    /// Lowest survival probability (keeps dark surfaces from ending every walk at once).
    pub min: f32,
    /// Highest survival probability (guarantees termination on white surfaces).
    pub max: f32,
}

impl Roulette {
    /// `[0.05, 0.95]`.
    pub const DEFAULT: Roulette = Roulette { min: 0.05, max: 0.95 };

    /// Survival probability for albedo `rho`.
    pub fn survival(&self, rho: Vec3) -> f32 {
        rho.max_element().clamp(self.min, self.max)
    }

    fn validate(&self) -> Result<(), TraceError> {
        if self.min > 0.0 && self.min <= self.max && self.max <= 1.0 {
            Ok(())
        } else {
            Err(TraceError::InvalidParameter(format!(
                "roulette bounds [{}, {}] must satisfy 0 < min <= max <= 1",
                self.min, self.max
            )))
        }
    }
}

impl Default for Roulette {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Random-walk parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WalkParams {
    /// Walks per entry point `M`.
    pub walks_per_entry: u32,
    /// Russian roulette.
    pub roulette: Roulette,
    /// Hard cap on bounces after the entry point.
    pub max_bounces: u32,
    /// Seed of every walk's stream.
    pub seed: u64,
    /// The disk that bounds the deeper VPLs.
    pub deep_disk: DeepDisk,
}

/// The area of the disk that bounds a deeper VPL (one a walk leaves after its entry point;
/// [`crate::VplBound::Disk`] turns it into `R²`). The depth-0 VPL's is its entry point's `A/N`.
///
/// The disk spreads a VPL's light over its area, so a deeper VPL whose disk is the area its walk
/// stands for, `A/(N·M)`, spikes more the more walks there are: on the fireplace room, 64 walks
/// per entry point instead of 14 play at 16.9% against 14.5%, local error 19×. A disk as large as
/// its entry point's costs the light next to other surfaces, which the near field gathers back
/// from the lightmap's indirect light: the fireplace room's 120 s bake then plays at
/// 11.95% (local 3.6×), and 48 walks per entry point at 11.86%, so the walks' noise is not what
/// limits it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeepDisk {
    /// `A/(N·M)`: the area one walk of `M` stands for.
    Walk,
    /// `A/N`: its entry point's, for a run time that gathers the deeper VPLs' near field back.
    Entry,
}

impl WalkParams {
    /// 4 walks per entry point.
    pub const PREVIEW: WalkParams = WalkParams {
        walks_per_entry: 4,
        roulette: Roulette::DEFAULT,
        max_bounces: 256,
        seed: 0,
        deep_disk: DeepDisk::Walk,
    };
    /// 16 walks per entry point.
    pub const STANDARD: WalkParams = WalkParams {
        walks_per_entry: 16,
        ..Self::PREVIEW
    };
}

impl Default for WalkParams {
    fn default() -> Self {
        Self::STANDARD
    }
}

/// A virtual point light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vpl {
    /// Position on the surface.
    pub position: Vec3,
    /// Unit geometric normal of its triangle (the side it emits to).
    pub normal: Vec3,
    /// Power per unit irradiance at its entry point (W per W/m², i.e. m²), walk average included.
    pub power: Vec3,
    /// Area of the disk that bounds it: its entry point's `A/N` at depth 0, deeper as
    /// [`DeepDisk`] says (`A/(N·M)`, the area its walk stands for, or `A/N`).
    pub area: f32,
    /// Triangle it lies on.
    pub triangle: u32,
    /// Entry point it descends from.
    pub entry: u32,
    /// Bounces from the entry point (0 = the entry point itself).
    pub depth: u32,
}

/// Counters of a walk run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WalkStats {
    /// Walks started.
    pub walks: u64,
    /// Rays cast.
    pub rays: u64,
    /// Rays that left the scene.
    pub escaped: u64,
    /// Rays that hit the back of a surface.
    pub back_faces: u64,
    /// Walks stopped by `max_bounces`.
    pub truncated: u64,
}

/// All VPLs of all entry points, grouped by entry point.
#[derive(Clone, Debug, PartialEq)]
pub struct VplSet {
    /// The VPLs, entry point by entry point.
    pub vpls: Vec<Vpl>,
    /// `offsets[k]..offsets[k+1]` are entry point `k`'s VPLs.
    pub offsets: Vec<u32>,
    /// Counters.
    pub stats: WalkStats,
}

impl VplSet {
    /// Number of entry points.
    pub fn entries(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Index range of entry point `k`'s VPLs.
    pub fn range(&self, k: usize) -> Range<usize> {
        self.offsets[k] as usize..self.offsets[k + 1] as usize
    }
}

/// Traces `M` walks from every entry point in parallel; same result for any thread count.
pub fn trace_walks(
    scene: &Scene,
    bvh: &Bvh,
    entries: &[SurfaceSample],
    params: &WalkParams,
) -> Result<VplSet, TraceError> {
    params.roulette.validate()?;
    if params.walks_per_entry == 0 {
        return Err(TraceError::InvalidParameter("walks_per_entry must be positive".into()));
    }
    let per_entry: Vec<(Vec<Vpl>, WalkStats)> = entries
        .par_iter()
        .enumerate()
        .map(|(k, e)| walk_entry(scene, bvh, k as u32, e, params))
        .collect();
    let mut vpls = Vec::with_capacity(per_entry.iter().map(|p| p.0.len()).sum());
    let mut offsets = Vec::with_capacity(entries.len() + 1);
    let mut stats = WalkStats::default();
    offsets.push(0);
    for (v, s) in per_entry {
        vpls.extend(v);
        offsets.push(vpls.len() as u32);
        stats.walks += s.walks;
        stats.rays += s.rays;
        stats.escaped += s.escaped;
        stats.back_faces += s.back_faces;
        stats.truncated += s.truncated;
    }
    Ok(VplSet { vpls, offsets, stats })
}

fn walk_entry(scene: &Scene, bvh: &Bvh, k: u32, e: &SurfaceSample, p: &WalkParams) -> (Vec<Vpl>, WalkStats) {
    let m_inv = 1.0 / p.walks_per_entry as f32;
    let deep_area = match p.deep_disk {
        DeepDisk::Walk => e.weight * m_inv,
        DeepDisk::Entry => e.weight,
    };
    let phi0 = e.albedo * e.weight;
    let mut out = vec![Vpl {
        position: e.position,
        normal: e.normal,
        power: phi0,
        area: e.weight,
        triangle: e.triangle,
        entry: k,
        depth: 0,
    }];
    let mut stats = WalkStats::default();
    let scramble = hash3(p.seed, k as u64, 0xF1257) as u32;
    for m in 0..p.walks_per_entry {
        stats.walks += 1;
        let mut rng = Rng::new(p.seed, k as u64, m as u64 + 1);
        let (mut pos, mut n, mut tri, mut rho, mut phi) = (e.position, e.normal, e.triangle, e.albedo, phi0);
        let mut depth = 0;
        loop {
            if depth >= p.max_bounces {
                stats.truncated += 1;
                break;
            }
            let q = p.roulette.survival(rho);
            if rng.next_f32() >= q {
                break;
            }
            let u = if depth == 0 {
                sobol2(m, scramble)
            } else {
                rng.next_vec2()
            };
            let dir = cosine_hemisphere(u, n);
            stats.rays += 1;
            let Some(hit) = bvh.closest_hit(bvh.spawn(pos, n, dir), dir, f32::INFINITY, tri) else {
                stats.escaped += 1;
                break;
            };
            if !hit.front {
                stats.back_faces += 1;
                break;
            }
            tri = hit.triangle;
            let t = &scene.triangles[tri as usize];
            pos = t.point(hit.b1, hit.b2);
            n = bvh.geometric_normal(tri);
            let rho_hit = scene.albedo(tri as usize, hit.b1, hit.b2);
            phi = phi * rho_hit / q;
            rho = rho_hit;
            depth += 1;
            out.push(Vpl {
                position: pos,
                normal: n,
                power: phi * m_inv,
                area: deep_area,
                triangle: tri,
                entry: k,
                depth,
            });
        }
    }
    (out, stats)
}
