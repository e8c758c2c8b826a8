//! Irradiance probes for moving objects: placed on a grid over the scene's empty space, and
//! baked as extra exit points of the same panes, so the run-time cluster weights light them.
//!
//! **Placement** ([`place_probes`]): a grid of cubic cells centred on the scene's bounds, its
//! spacing the smallest (growing by 2% steps) that keeps the cell count within the budget. A
//! probe sits at each cell's centre unless that point is inside geometry: of
//! [`INSIDE_DIRECTIONS`] rays in a spherical Fibonacci set, more than [`INSIDE_BACK_FRACTION`]
//! hit a back face (a closed solid shows only back faces from within, an open room none). Such
//! cells get no probe. A probe is never moved: the point a surface is close to is still a point
//! of empty space, and the test against the reference is taken exactly there.
//!
//! **Transfer** ([`probe_transfer`]): the panes' estimator with the probe in place of an exit
//! point and no receiving cosine. A VPL `v` of cluster `c` at distance `r` in direction `ω`
//! gives a surface at the probe facing `ω` the irradiance `Φ_v/π · cos θ_v · b(r², v)` per unit
//! weight (`b` the panes' bounded `1/r²`, [`VplBound`]), visible by one shadow ray. Projected
//! onto the nine spherical harmonics and convolved with the clamped cosine (the factors
//! `π, 2π/3, π/4` of orders 0, 1, 2), the coefficients give the irradiance for any normal `n`
//! as `Σ_i T_i Y_i(n)` ([`prm_format::sh_irradiance`]). The cost is one shadow ray per probe and
//! VPL (0.3 s for the Cornell box's 473 probes and 10,668 VPLs).
//!
//! Measured (`cargo xtask eval experiment probe_split SCENE ENTRIES WALKS
//! DISK`, our Cornell box, 473 probes, one point light, no clustering, six axis normals per
//! probe; error = relative L2 against `ReferenceTracer::indirect_at_points` at 16,384 paths):
//!
//! | entries × walks, disk | SH against the exact VPL sum | exact VPL sum against the reference (energy) |
//! | --- | ---: | ---: |
//! | 1024 × 8 (the default bake's), 1 | 2.1% | 17.3% (0.929) |
//! | 1024 × 32, 1 | 2.0% | 15.9% (0.940) |
//! | 4096 × 8, 1 | 1.6% | 9.3% (0.968) |
//! | 16384 × 8, 1 | 1.6% | 4.5% (0.989) |
//! | 1024 × 8, 0.25 | 2.3% | 14.6% (0.972) |
//! | 1024 × 8, 2 | 1.8% | 26.7% (0.856) |
//!
//! So order 2 costs 2%, and the rest is the panes' own estimator: it falls with the entry points
//! (the point sampling of the direct light) and not with the walks. A smaller disk
//! bound would lose less energy here, but the probes keep the panes' bound, so that a probe and
//! a surface beside it agree.

use glam::Vec3;
use prm_format::{
    probe_ray_direction, sh_basis, sh_irradiance, GatherPoint, ProbeGrid, ProbeRays, ProbeSkyTransfer, AXIS_NORMALS,
    NO_EMITTER, RAY_BLOCKED, RAY_SKY, SH_COEFFS, SH_COSINE_LOBE,
};
use prm_scene::Scene;
use prm_scene::{Atlas, EMPTY_TEXEL};
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::cluster::Clustering;
use crate::reference::{validate, walk_path, ReferenceParams, Step};
use crate::rng::Rng;
use crate::vpl::VplBound;
use crate::walk::VplSet;
use crate::TraceError;

/// Every probe position paired with each of the six axis normals ([`AXIS_NORMALS`]), probe by
/// probe: the points at which a probe's irradiance is compared with the reference.
pub fn axis_points(positions: &[[f32; 3]]) -> Vec<(Vec3, Vec3)> {
    positions
        .iter()
        .flat_map(|p| AXIS_NORMALS.map(|n| (Vec3::from(*p), Vec3::from(n))))
        .collect()
}

/// Each probe's irradiance at the six axis normals, in [`axis_points`]' order, negative values
/// clamped as `probe_volume.wgsl` does.
pub fn axis_irradiance(coeffs: &[[[f32; 3]; SH_COEFFS]]) -> Vec<Vec3> {
    coeffs
        .iter()
        .flat_map(|c| AXIS_NORMALS.map(|n| Vec3::from(sh_irradiance(c, n)).max(Vec3::ZERO)))
        .collect()
}

/// Rays per candidate of the inside test.
pub const INSIDE_DIRECTIONS: u32 = 32;
/// Share of back-face hits above which a candidate is inside geometry.
pub const INSIDE_BACK_FRACTION: f32 = 0.25;
/// Probes per progress report of [`probe_transfer`].
pub const PROGRESS_CHUNK: usize = 32;
/// Growth of the spacing per step while the grid has more cells than the budget.
const SPACING_STEP: f32 = 1.02;

/// One probe's nine irradiance coefficients (RGB).
pub type ProbeCoefficients = [[f32; 3]; SH_COEFFS];

/// Where the probes are.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeLayout {
    /// The grid.
    pub grid: ProbeGrid,
    /// Each probe's cell, increasing.
    pub cells: Vec<u32>,
    /// Each probe's position (its cell's centre).
    pub positions: Vec<Vec3>,
    /// Cells left without a probe because they are inside geometry.
    pub inside: u32,
}

/// The grid over the scene's bounds with the smallest spacing that keeps at most `max_cells`
/// cells.
pub fn probe_grid(scene: &Scene, max_cells: u32) -> Result<ProbeGrid, TraceError> {
    if max_cells == 0 || u64::from(max_cells) > prm_format::MAX_PROBE_CELLS {
        return Err(TraceError::InvalidParameter(format!(
            "probe budget {max_cells}: need between 1 and {} cells",
            prm_format::MAX_PROBE_CELLS
        )));
    }
    let b = scene.bounds();
    let extent = b.max - b.min;
    if !extent.is_finite() || extent.max_element() <= 0.0 {
        return Err(TraceError::InvalidParameter(
            "the scene has no extent to place probes in".to_string(),
        ));
    }
    // A flat axis still gets one layer: measure it as a hundredth of the largest one.
    let e = extent.max(Vec3::splat(extent.max_element() * 0.01));
    let dims_for = |s: f32| (e / s).ceil().max(Vec3::ONE).as_uvec3();
    let cells = |d: glam::UVec3| u64::from(d.x) * u64::from(d.y) * u64::from(d.z);
    let mut spacing = (e.x * e.y * e.z / max_cells as f32).cbrt();
    while cells(dims_for(spacing)) > u64::from(max_cells) {
        spacing *= SPACING_STEP;
    }
    let dims = dims_for(spacing);
    let centre = (b.min + b.max) * 0.5;
    let origin = centre - dims.as_vec3() * spacing * 0.5;
    Ok(ProbeGrid {
        dims: dims.to_array(),
        origin: origin.to_array(),
        spacing,
    })
}

/// Direction `i` of `n` spread evenly over the sphere (a spherical Fibonacci set).
pub(crate) fn fibonacci_direction(i: u32, n: u32) -> Vec3 {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
    let r = (1.0 - y * y).max(0.0).sqrt();
    let phi = golden * i as f32;
    Vec3::new(r * phi.cos(), y, r * phi.sin())
}

/// Whether `p` is inside geometry: more than [`INSIDE_BACK_FRACTION`] of
/// [`INSIDE_DIRECTIONS`] rays hit a back face first.
pub fn is_inside(bvh: &Bvh, p: Vec3) -> bool {
    let back = (0..INSIDE_DIRECTIONS)
        .filter(|&i| {
            let d = fibonacci_direction(i, INSIDE_DIRECTIONS);
            bvh.closest_hit(p, d, f32::INFINITY, u32::MAX).is_some_and(|h| !h.front)
        })
        .count();
    back as f32 > INSIDE_BACK_FRACTION * INSIDE_DIRECTIONS as f32
}

/// Places probes at the centres of [`probe_grid`]'s cells that are not inside geometry.
pub fn place_probes(scene: &Scene, bvh: &Bvh, max_cells: u32) -> Result<ProbeLayout, TraceError> {
    let grid = probe_grid(scene, max_cells)?;
    let total = grid.cells() as u32;
    let kept: Vec<(u32, Vec3)> = (0..total)
        .into_par_iter()
        .filter_map(|c| {
            let p = Vec3::from(grid.cell_centre(c));
            (!is_inside(bvh, p)).then_some((c, p))
        })
        .collect();
    if kept.is_empty() {
        return Err(TraceError::InvalidParameter(format!(
            "all {total} probe cells are inside geometry"
        )));
    }
    Ok(ProbeLayout {
        grid,
        inside: total - kept.len() as u32,
        cells: kept.iter().map(|k| k.0).collect(),
        positions: kept.iter().map(|k| k.1).collect(),
    })
}

/// Every cluster's irradiance coefficients at every probe per unit weight, cluster-major
/// (`[c * positions.len() + p]`, the layout of [`prm_format::Probes::transfer`]), and the shadow
/// rays cast. Probes are done in parallel, [`PROGRESS_CHUNK`] at a time; `progress(done)` is
/// called after each chunk with the probes done so far.
pub fn probe_transfer(
    bvh: &Bvh,
    vpls: &VplSet,
    clustering: &Clustering,
    positions: &[Vec3],
    bound: VplBound,
    progress: &mut dyn FnMut(u64),
) -> Result<(Vec<ProbeCoefficients>, u64), TraceError> {
    if clustering.of_entry.len() != vpls.entries() {
        return Err(TraceError::InvalidParameter(format!(
            "clustering covers {} entry points, the VPL set {}",
            clustering.of_entry.len(),
            vpls.entries()
        )));
    }
    let clusters = clustering.len();
    let one = |p: Vec3| {
        let mut acc = vec![[[0.0f32; 3]; SH_COEFFS]; clusters];
        let mut rays = 0u64;
        for v in &vpls.vpls {
            let d = v.position - p;
            let r2 = d.length_squared();
            let r = r2.sqrt();
            let cos_v = -v.normal.dot(d) / r;
            if !(r2 > 0.0 && cos_v > 0.0) {
                continue;
            }
            let w = d / r;
            rays += 1;
            if !bvh.visible(p, w, u32::MAX, v.position, v.normal, v.triangle) {
                continue;
            }
            let e = v.power * (cos_v * bound.inverse_square(r2, v) * std::f32::consts::FRAC_1_PI);
            let y = sh_basis(w.to_array());
            let slot = &mut acc[clustering.of_entry[v.entry as usize] as usize];
            for i in 0..SH_COEFFS {
                let f = SH_COSINE_LOBE[i] * y[i];
                for k in 0..3 {
                    slot[i][k] += e[k] * f;
                }
            }
        }
        (acc, rays)
    };
    let mut per_probe = Vec::with_capacity(positions.len());
    for chunk in positions.chunks(PROGRESS_CHUNK) {
        per_probe.par_extend(chunk.par_iter().map(|&p| one(p)));
        progress(per_probe.len() as u64);
    }
    let n = positions.len();
    let mut out = vec![[[0.0f32; 3]; SH_COEFFS]; clusters * n];
    let mut rays = 0;
    for (p, (acc, r)) in per_probe.into_iter().enumerate() {
        rays += r;
        for (c, t) in acc.into_iter().enumerate() {
            out[c * n + p] = t;
        }
    }
    Ok((out, rays))
}

/// The sky's transfer to every probe: `[p][i][k]`, probe `p`'s irradiance coefficient `i` (RGB)
/// per unit of the sky's coefficient `k` ([`prm_format::sh_basis`]), the sky seen directly and
/// after one or more bounces, with the reference tracer's path estimator and
/// `passes × samples_per_pass` paths per probe. A path leaves the probe in a direction `ω` uniform
/// over the sphere (a cosine sample about a uniform axis, whose density over `ω` is `1/4π`);
/// the radiance it brings back per unit of `Y_k`, `T · Y_k(d)` for a path that leaves the scene
/// along `d` with throughput `T`, is projected onto `Â_i Y_i(ω)`. Probe `p` in pass `q` draws
/// from the stream `(seed, p, q)`; `progress(pass, passes)` after every pass.
pub fn sky_transfer_at_probes(
    scene: &Scene,
    bvh: &Bvh,
    positions: &[Vec3],
    params: &ReferenceParams,
    progress: &mut dyn FnMut(u32, u32),
) -> Result<Vec<ProbeSkyTransfer>, TraceError> {
    validate(params)?;
    let mut sums = vec![[[Vec3::ZERO; SH_COEFFS]; SH_COEFFS]; positions.len()];
    for pass in 0..params.passes {
        sums.par_iter_mut().enumerate().for_each(|(p, m)| {
            let x = positions[p];
            let mut rng = Rng::new(params.seed, p as u64, u64::from(pass));
            for _ in 0..params.samples_per_pass {
                let u = rng.next_vec2();
                let z = 1.0 - 2.0 * u.x;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let phi = std::f32::consts::TAU * u.y;
                let axis = Vec3::new(r * phi.cos(), r * phi.sin(), z);
                let mut first = Vec3::ZERO;
                walk_path(
                    scene,
                    bvh,
                    (x, axis, axis, u32::MAX),
                    None,
                    params,
                    &mut rng,
                    &mut |step, _| match step {
                        Step::Vertex(v) => {
                            if v.bounce == 0 {
                                first = v.dir;
                            }
                        }
                        Step::Escape {
                            bounce,
                            throughput,
                            dir,
                        } => {
                            if bounce == 0 {
                                first = dir;
                            }
                            let yi = sh_basis(first.to_array());
                            let yk = sh_basis(dir.to_array());
                            for i in 0..SH_COEFFS {
                                let wi = 4.0 * std::f32::consts::PI * SH_COSINE_LOBE[i] * yi[i];
                                for k in 0..SH_COEFFS {
                                    m[i][k] += throughput * (wi * yk[k]);
                                }
                            }
                        }
                    },
                );
            }
        });
        progress(pass + 1, params.passes);
    }
    let n = (params.passes * params.samples_per_pass) as f32;
    Ok(sums
        .iter()
        .map(|m| std::array::from_fn(|i| std::array::from_fn(|k| (m[i][k] / n).to_array())))
        .collect())
}

/// Finds the exit point that stands for a ray's hit: the covered texel's exit when it lies on
/// the hit's own chart, else its gutter source's, else the nearest exit of that chart within
/// two texels. A shared or dilated texel may belong to a neighbouring surface (another
/// normal, albedo or emission), so only exits of the hit's own chart count.
pub struct HitTexels<'a> {
    atlas: &'a Atlas,
    gutter: std::collections::HashMap<u32, u32>,
}

impl<'a> HitTexels<'a> {
    /// The lookup for `atlas`.
    pub fn new(atlas: &'a Atlas) -> HitTexels<'a> {
        HitTexels {
            atlas,
            gutter: atlas.dilation.iter().copied().collect(),
        }
    }

    /// The exit (index into `atlas.exits`) for barycentrics `(b1, b2)` on triangle `tri`.
    pub fn exit(&self, tri: u32, b1: f32, b2: f32) -> Option<u32> {
        let atlas = self.atlas;
        let res = atlas.resolution as i64;
        let uv = atlas.uvs[tri as usize];
        let p = uv[0] * (1.0 - b1 - b2) + uv[1] * b1 + uv[2] * b2;
        let (x, y) = (
            ((p.x * res as f32) as i64).clamp(0, res - 1),
            ((p.y * res as f32) as i64).clamp(0, res - 1),
        );
        let texel = (y * res + x) as u32;
        let chart = atlas.chart_of_triangle[tri as usize];
        let of_chart =
            |e: u32| e != EMPTY_TEXEL && atlas.chart_of_triangle[atlas.exits[e as usize].triangle as usize] == chart;
        let own = atlas.texel_exit[texel as usize];
        if of_chart(own) {
            return Some(own);
        }
        if let Some(&src) = self.gutter.get(&texel) {
            let e = atlas.texel_exit[src as usize];
            if of_chart(e) {
                return Some(e);
            }
        }
        let mut best: Option<(i64, u32)> = None;
        for dy in -2..=2i64 {
            for dx in -2..=2i64 {
                let (nx, ny) = (x + dx, y + dy);
                if nx < 0 || ny < 0 || nx >= res || ny >= res {
                    continue;
                }
                let e = atlas.texel_exit[(ny * res + nx) as usize];
                let d = dx * dx + dy * dy;
                if of_chart(e) && best.is_none_or(|(bd, _)| d < bd) {
                    best = Some((d, e));
                }
            }
        }
        best.map(|(_, e)| e)
    }
}

/// The gather points of the exits `reached` names (other values are skipped), in exit order,
/// and every exit's gather point index (`RAY_BLOCKED` where none).
pub(crate) fn gather_points(
    scene: &Scene,
    atlas: &Atlas,
    emitters: &crate::Emitters,
    reached: impl Iterator<Item = u32>,
) -> (Vec<u32>, Vec<GatherPoint>) {
    let mut seen = vec![false; atlas.exits.len()];
    for e in reached {
        if let Some(r) = seen.get_mut(e as usize) {
            *r = true;
        }
    }
    let mut index = vec![RAY_BLOCKED; atlas.exits.len()];
    let mut points = Vec::new();
    for (e, _) in seen.iter().enumerate().filter(|(_, &r)| r) {
        index[e] = points.len() as u32;
        let x = &atlas.exits[e];
        let material = scene.triangles[x.triangle as usize].material;
        let group = emitters.groups.iter().position(|g| g.material == material);
        points.push(GatherPoint {
            texel: x.texel,
            position: x.position.to_array(),
            normal: x.normal.to_array(),
            albedo: x.albedo.to_array(),
            emission: group.map_or([0.0; 3], |g| emitters.groups[g].radiance.to_array()),
            emitter: group.map_or(NO_EMITTER, |g| g as u32),
        });
    }
    (index, points)
}

/// Where every probe's [`probe_ray_direction`] rays meet the scene (the archive's probe rays):
/// the covered texel of the front face they hit, [`RAY_SKY`] when they leave the scene, or
/// [`RAY_BLOCKED`] at a back face. A hit takes its texel's exit when that exit is on the hit's
/// chart, else the exit its gutter texel copies (same chart), else the nearest exit of the
/// same chart within two texels. Gather points are the
/// exits the rays reach, in exit order; on an emissive material's triangle they carry its
/// radiance and its group in [`crate::Emitters::from_scene`]'s order (the archive's).
pub fn probe_rays(scene: &Scene, bvh: &Bvh, atlas: &Atlas, positions: &[Vec3], rays_per_probe: u32) -> ProbeRays {
    let emitters = crate::Emitters::from_scene(scene);
    let m = rays_per_probe;
    let dirs: Vec<Vec3> = (0..m).map(|d| Vec3::from(probe_ray_direction(d, m))).collect();
    let texels = HitTexels::new(atlas);
    let per_probe: Vec<Vec<u32>> = positions
        .par_iter()
        .map(|&p| {
            dirs.iter()
                .map(|&d| match bvh.closest_hit(p, d, f32::INFINITY, u32::MAX) {
                    None => RAY_SKY,
                    Some(h) if !h.front => RAY_BLOCKED,
                    // No exit near the hit: it sends nothing.
                    Some(h) => texels.exit(h.triangle, h.b1, h.b2).unwrap_or(RAY_BLOCKED),
                })
                .collect()
        })
        .collect();
    let (index, points) = gather_points(scene, atlas, &emitters, per_probe.iter().flatten().copied());
    // Exits become their gather point; the two codes lie beyond every exit and stay.
    let hits = per_probe
        .into_iter()
        .flatten()
        .map(|e| index.get(e as usize).copied().unwrap_or(e))
        .collect();
    ProbeRays {
        rays_per_probe: m,
        points,
        hits,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed unit cube (faces outward) around the origin, and a floor below it.
    fn cube_over_floor() -> Scene {
        let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z) * 0.5;
        let f = |x: f32, z: f32| Vec3::new(x, -2.0, z);
        crate::grey_quads(&[
            // Each face wound counter-clockwise seen from outside.
            [v(-1., -1., 1.), v(1., -1., 1.), v(1., 1., 1.), v(-1., 1., 1.)],
            [v(1., -1., -1.), v(-1., -1., -1.), v(-1., 1., -1.), v(1., 1., -1.)],
            [v(1., -1., 1.), v(1., -1., -1.), v(1., 1., -1.), v(1., 1., 1.)],
            [v(-1., -1., -1.), v(-1., -1., 1.), v(-1., 1., 1.), v(-1., 1., -1.)],
            [v(-1., 1., 1.), v(1., 1., 1.), v(1., 1., -1.), v(-1., 1., -1.)],
            [v(-1., -1., -1.), v(1., -1., -1.), v(1., -1., 1.), v(-1., -1., 1.)],
            [f(-4., 4.), f(4., 4.), f(4., -4.), f(-4., -4.)],
        ])
    }

    #[test]
    fn the_grid_keeps_the_budget_and_skips_the_inside_of_a_solid() {
        let scene = cube_over_floor();
        let bvh = Bvh::build(&scene, &crate::BvhParams::DEFAULT).unwrap();
        let grid = probe_grid(&scene, 2000).unwrap();
        assert!(grid.cells() <= 2000 && grid.cells() > 1800, "{grid:?}");
        assert!(is_inside(&bvh, Vec3::ZERO));
        assert!(!is_inside(&bvh, Vec3::new(0.0, -1.5, 0.0)), "between cube and floor");
        assert!(!is_inside(&bvh, Vec3::new(2.0, 0.0, 2.0)), "beside the cube");
        let layout = place_probes(&scene, &bvh, 2000).unwrap();
        assert!(layout.inside > 0);
        assert_eq!(layout.cells.len() as u32 + layout.inside, grid.cells() as u32);
        for p in &layout.positions {
            assert!(!is_inside(&bvh, *p));
            assert!(
                p.abs().max_element() > 0.5 || p.y < -0.5,
                "probe {p} is inside the cube"
            );
        }
        assert!(probe_grid(&scene, 0).is_err());
    }

    /// Far above the scene a uniform sky of radiance `L` gives every normal `πL`, and the
    /// transfer is the cosine lobe's diagonal `Â_i δ_ik` (the harmonics are orthonormal).
    #[test]
    fn an_open_sky_gives_every_normal_pi_l() {
        let scene = cube_over_floor();
        let bvh = Bvh::build(&scene, &crate::BvhParams::DEFAULT).unwrap();
        let params = ReferenceParams {
            seed: 3,
            ..ReferenceParams::with_spp(4096)
        };
        let t = sky_transfer_at_probes(&scene, &bvh, &[Vec3::new(0.0, 60.0, 0.0)], &params, &mut |_, _| {}).unwrap();
        let l = 0.7;
        let mut coeffs = [[0.0f32; 3]; SH_COEFFS];
        coeffs[0] = [2.0 * std::f32::consts::PI.sqrt() * l; 3];
        let set = prm_format::Probes {
            grid: ProbeGrid {
                dims: [1, 1, 1],
                origin: [0.0; 3],
                spacing: 1.0,
            },
            cells: vec![0],
            positions: vec![[0.0, 60.0, 0.0]],
            transfer: vec![],
            sky: Some(t.clone()),
        };
        let sh = set.sky_irradiance_sh(&coeffs)[0];
        for n in prm_format::AXIS_NORMALS {
            let e = prm_format::sh_irradiance(&sh, n)[0];
            assert!((e / (std::f32::consts::PI * l) - 1.0).abs() < 0.03, "{n:?}: {e}");
        }
        for i in 0..SH_COEFFS {
            let d = t[0][i][i][0];
            assert!((d / SH_COSINE_LOBE[i] - 1.0).abs() < 0.1, "diagonal {i}: {d}");
        }
    }

    #[test]
    fn the_transfer_of_one_vpl_is_its_irradiance_in_every_direction() {
        use crate::walk::{Vpl, WalkStats};
        let scene = cube_over_floor();
        let bvh = Bvh::build(&scene, &crate::BvhParams::DEFAULT).unwrap();
        // One VPL on the floor, facing up, 1.5 below a probe beside the cube.
        let vpl = Vpl {
            position: Vec3::new(2.0, -2.0, 0.0),
            normal: Vec3::Y,
            power: Vec3::new(1.0, 2.0, 3.0),
            area: 1e-6,
            triangle: 12,
            entry: 0,
            depth: 0,
        };
        let vpls = VplSet {
            vpls: vec![vpl],
            offsets: vec![0, 1],
            stats: WalkStats::default(),
        };
        let clustering = Clustering {
            of_entry: vec![0],
            centroids: vec![vpl.position],
            normals: vec![Vec3::Y],
            members: vec![vec![0]],
        };
        let p = Vec3::new(2.0, -0.5, 0.0);
        let (t, rays) = probe_transfer(&bvh, &vpls, &clustering, &[p], VplBound::DEFAULT, &mut |_| {}).unwrap();
        assert_eq!(rays, 1);
        let down = prm_format::sh_irradiance(&t[0], [0.0, -1.0, 0.0]);
        let e = VplBound::DEFAULT.irradiance(&vpl, p, -Vec3::Y);
        // A single direction is the hardest case for order 2: the lobe facing it is within 15%.
        for k in 0..3 {
            assert!((down[k] / e[k] - 1.0).abs() < 0.15, "{down:?} against {e}");
        }
        // Facing away it sees nothing; order 2 rings there by a fraction of the peak.
        let up = prm_format::sh_irradiance(&t[0], [0.0, 1.0, 0.0]);
        assert!(up[2].abs() < 0.15 * e[2], "{up:?}");
    }
}
