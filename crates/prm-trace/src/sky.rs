//! The sky's transfer at exit points: for each of the nine basis functions `Y_c` of
//! [`prm_format::sh_basis`], the irradiance a texel would receive if the sky's radiance were
//! `Y_c`, split into direct (the first ray from the texel leaves the scene: visibility × cosine)
//! and indirect (a later ray of the path leaves it, weighted by the albedos met). With the sky's
//! coefficients `L_c`, the texel's sky irradiance is `Σ_c T_c · L_c` up to the sky's detail
//! above order 2 (precomputed radiance transfer).
//!
//! The estimator is the reference tracer's own ([`crate::reference`]): cosine-sampled paths
//! with Russian roulette, where a ray leaving the scene along `ω` with path weight `w` scores
//! `w · π · Y_c(ω)`, exactly what [`crate::ReferenceTracer::with_sky`] scores with `L(ω)` in
//! place of `Y_c(ω)`. So against the reference the transfer differs only by noise and by the
//! order-2 truncation of the sky; for a constant sky the truncation is nil (a test below).
//!
//! The first rays of an exit point's paths, over all passes, are one Owen-scrambled Sobol set
//! (scrambled per exit point) rather than independent draws: the direct part, the sky's
//! visibility, is then stratified over the hemisphere. Measured on the Dabrovic Sponza's default
//! `--sky` bake under `cargo xtask eval --sky`'s blue sky (seed 0): the full image 3.74% off the
//! reference (4.33% with independent draws); the indirect light, whose noise lies in the later
//! bounces and the panes, 6.30% (6.21%).

use glam::Vec3;
use prm_format::{sh_basis, SkyTransfer, SH_COEFFS};
use prm_scene::{ExitPoint, Scene};
use rayon::prelude::*;

use crate::reference::{validate, walk_path, ReferenceParams, Step};
use crate::sampling::sobol2;
use crate::{Bvh, Rng, TraceError};

/// Least cosine between two exit points' normals for [`smooth_transfer`] to average them
/// (about 26°: creases such as a wall meeting the floor stay sharp). Measured with the bake's
/// 256 paths (`cargo xtask eval --sky`, indirect image error after a 4×4 downsample, both parts
/// smoothed, unsmoothed in parentheses): the Dabrovic Sponza under a uniform sky 14.9% (18.1%;
/// 1024 paths unsmoothed 12.9%), our courtyard under a turned map 3.5% (4.1%), and with a low
/// sun 6.9% (7.0%): its noise falls by more than the blur costs. The direct
/// part is left alone: it holds the sky's shadows, and on `tests/sky.rs`'s coarse 48² atlas
/// smoothing it makes its per-texel error 5.9% instead of 3.8% (the full images of the eval moved by
/// less than 0.1 point either way).
pub const SKY_SMOOTH_MIN_COS: f32 = 0.9;

/// Texels on each side of an exit point that [`smooth_transfer`] averages: 2, a 5 × 5
/// neighbourhood. Measured with the bake's 256 paths (the indirect image against
/// `prm-bake reference --indirect-only` at 1024 paths, 4×4 downsample): the Dabrovic Sponza
/// under a uniform sky (`--time-budget 60`, the eval's camera) 3 × 3: 11.09%, **5 × 5: 9.20%**,
/// 7 × 7: 9.87%, Gaussian weights of σ = 1.5 texels over 7 × 7: 9.52%, of σ = 1 over 5 × 5:
/// 10.60%; our courtyard under the turned map 3.52%, **3.27%**, –, 3.27%, 3.43%. Past 5 × 5
/// the blur costs more than the noise it removes.
pub const SKY_SMOOTH_RADIUS: u32 = 2;

/// The transfer at `exits` (in their order) with its indirect part averaged over each exit
/// point's (2·[`SKY_SMOOTH_RADIUS`] + 1)² texel neighbourhood in the `resolution`² atlas, over the
/// neighbours that are exit points and whose normals are within [`SKY_SMOOTH_MIN_COS`] of its
/// own, on the same chart (`chart_of_triangle`, the atlas's: covered texels of two charts may be
/// two texels apart); the direct part is kept as it is (see the constant).
pub fn smooth_transfer(
    transfer: &SkyTransfer,
    exits: &[ExitPoint],
    chart_of_triangle: &[u32],
    resolution: u32,
) -> SkyTransfer {
    let r = resolution as i64;
    let chart = |e: &ExitPoint| chart_of_triangle[e.triangle as usize];
    let mut at = vec![u32::MAX; (r * r) as usize];
    for (i, x) in exits.iter().enumerate() {
        at[x.texel as usize] = i as u32;
    }
    let indirect = (0..exits.len())
        .into_par_iter()
        .map(|i| {
            let x = &exits[i];
            let (tx, ty) = (i64::from(x.texel) % r, i64::from(x.texel) / r);
            let mut sum = [[0.0f32; 3]; SH_COEFFS];
            let mut n = 0.0f32;
            let r2 = i64::from(SKY_SMOOTH_RADIUS);
            for (dx, dy) in (-r2..=r2).flat_map(|dy| (-r2..=r2).map(move |dx| (dx, dy))) {
                let (nx, ny) = (tx + dx, ty + dy);
                if !(0..r).contains(&nx) || !(0..r).contains(&ny) {
                    continue;
                }
                let j = at[(ny * r + nx) as usize];
                if j == u32::MAX {
                    continue;
                }
                let y = &exits[j as usize];
                if chart(y) != chart(x) || y.normal.dot(x.normal) < SKY_SMOOTH_MIN_COS {
                    continue;
                }
                for (s, v) in sum
                    .iter_mut()
                    .flatten()
                    .zip(transfer.indirect[j as usize].iter().flatten())
                {
                    *s += v;
                }
                n += 1.0;
            }
            sum.map(|c| c.map(|v| v / n))
        })
        .collect();
    SkyTransfer {
        direct: transfer.direct.clone(),
        indirect,
    }
}

/// One exit point's transfer sums (direct, indirect).
type Sums = ([f32; SH_COEFFS], [Vec3; SH_COEFFS]);

/// The sky's transfer at every exit point, `passes × samples_per_pass` paths each, in the
/// exits' order (the caller places them in texels). Exit `i` in pass `p` draws from the stream
/// `(seed, i, p)`; `progress(pass, passes)` is called after every pass.
pub fn sky_transfer_at_exits(
    scene: &Scene,
    bvh: &Bvh,
    exits: &[ExitPoint],
    params: &ReferenceParams,
    progress: &mut dyn FnMut(u32, u32),
) -> Result<SkyTransfer, TraceError> {
    validate(params)?;
    let mut sums: Vec<Sums> = vec![([0.0; SH_COEFFS], [Vec3::ZERO; SH_COEFFS]); exits.len()];
    for pass in 0..params.passes {
        sums.par_iter_mut().enumerate().for_each(|(i, (direct, indirect))| {
            let x = &exits[i];
            let ng = bvh.geometric_normal(x.triangle);
            let mut rng = Rng::new(params.seed, i as u64, u64::from(pass));
            // The first rays of all passes are one Owen-scrambled Sobol set per exit point.
            let scramble = Rng::new(params.seed, i as u64, u64::MAX).next_u32();
            for s in 0..params.samples_per_pass {
                let first = sobol2(pass * params.samples_per_pass + s, scramble);
                walk_path(
                    scene,
                    bvh,
                    (x.position, ng, x.normal, x.triangle),
                    Some(first),
                    params,
                    &mut rng,
                    &mut |step, _| {
                        if let Step::Escape {
                            bounce,
                            throughput,
                            dir,
                        } = step
                        {
                            let y = sh_basis(dir.to_array());
                            if bounce == 0 {
                                direct
                                    .iter_mut()
                                    .zip(y)
                                    .for_each(|(d, y)| *d += std::f32::consts::PI * y);
                            } else {
                                let w = throughput * std::f32::consts::PI;
                                indirect.iter_mut().zip(y).for_each(|(t, y)| *t += w * y);
                            }
                        }
                    },
                );
            }
        });
        progress(pass + 1, params.passes);
    }
    let n = (params.passes * params.samples_per_pass) as f32;
    let mut out = SkyTransfer::zeros(exits.len());
    for ((d, t), (direct, indirect)) in out.direct.iter_mut().zip(out.indirect.iter_mut()).zip(&sums) {
        *d = direct.map(|v| v / n);
        *t = indirect.map(|v| (v / n).to_array());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BvhParams, Lighting, Receiver, ReferenceTracer};
    use prm_scene::{Material, Sky, Triangle};

    /// A floor (albedo 0.5) and a red wall standing on it along x = 0, facing +x: the floor
    /// sees the wall, the wall the floor, both the sky.
    fn corner() -> Scene {
        let tri = |p: [[f32; 3]; 3], material| Triangle::flat(p.map(Vec3::from), material);
        Scene::from_parts(
            vec![
                tri([[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [1.0, 0.0, 0.0]], 0),
                tri([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 1.0]], 0),
                tri([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0]], 1),
                tri([[0.0, 0.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]], 1),
            ],
            vec![
                Material::diffuse("grey", Vec3::splat(0.5)),
                Material::diffuse("red", Vec3::new(0.8, 0.2, 0.1)),
            ],
        )
    }

    /// Two floor points (near and far from the wall) and one on the wall.
    fn exits() -> Vec<ExitPoint> {
        [
            (Vec3::new(0.1, 0.0, 0.5), Vec3::Y, 1),
            (Vec3::new(0.6, 0.0, 0.5), Vec3::Y, 0),
            (Vec3::new(0.0, 0.3, 0.7), Vec3::X, 3),
        ]
        .map(|(position, normal, triangle)| ExitPoint {
            texel: 0,
            position,
            normal,
            albedo: Vec3::ONE,
            triangle,
            coverage: 1.0,
        })
        .to_vec()
    }

    /// Smoothing keeps a constant transfer, averages a neighbourhood of one chart, and leaves
    /// out neighbours whose normals turn away.
    #[test]
    fn smoothing_averages_neighbours_that_face_alike() {
        // A 3 × 3 atlas: every texel an exit point facing +Y but the last, facing +X.
        let exits: Vec<ExitPoint> = (0..9)
            .map(|t| ExitPoint {
                texel: t,
                position: Vec3::ZERO,
                normal: if t == 8 { Vec3::X } else { Vec3::Y },
                albedo: Vec3::ONE,
                triangle: 0,
                coverage: 1.0,
            })
            .collect();
        let mut t = SkyTransfer::zeros(9);
        for (i, (d, ind)) in t.direct.iter_mut().zip(t.indirect.iter_mut()).enumerate() {
            d[0] = i as f32;
            ind[0] = [i as f32, 0.0, 1.0];
            ind[4] = [2.0; 3];
        }
        let s = smooth_transfer(&t, &exits, &[0], 3);
        // The centre sees the eight +Y texels (0..=7, itself among them): mean 3.5.
        assert!(
            (s.indirect[4][0][0] - 28.0 / 8.0).abs() < 1e-6,
            "{:?}",
            s.indirect[4][0]
        );
        assert!(
            s.indirect.iter().all(|c| c[4] == [2.0; 3] && c[0][2] == 1.0),
            "constants stay"
        );
        assert_eq!(s.indirect[8][0][0], 8.0, "the +X texel has no neighbour facing like it");
        // Texel 0 reaches the whole 3 × 3 atlas within two texels: the same eight.
        assert_eq!(SKY_SMOOTH_RADIUS, 2);
        assert!((s.indirect[0][0][0] - 3.5).abs() < 1e-6);
        assert_eq!(s.direct, t.direct, "the direct part is kept");
    }

    #[test]
    fn an_open_plane_sees_pi_times_a_uniform_sky() {
        let mut s = corner();
        s.triangles.truncate(2);
        let bvh = Bvh::build(&s, &BvhParams::default()).unwrap();
        let x = exits();
        let t = sky_transfer_at_exits(&s, &bvh, &x[..2], &ReferenceParams::with_spp(64), &mut |_, _| {}).unwrap();
        let sky = Sky::uniform(Vec3::new(1.0, 0.5, 2.0));
        for i in 0..2 {
            let (d, ind) = t.irradiance(i, &sky.sh());
            // Cosine sampling makes Y₀₀'s score constant and the other bands' integrate to
            // zero over the open hemisphere up to noise; the band-0 part alone is π·L exactly.
            let want = std::f32::consts::PI * Vec3::new(1.0, 0.5, 2.0);
            assert!(
                (Vec3::from(d) - want).length() < 1e-3 * want.length(),
                "{d:?} vs {want}"
            );
            assert_eq!(ind, [0.0; 3], "nothing to bounce off");
        }
    }

    #[test]
    fn transfer_matches_the_reference_tracer_under_a_uniform_sky() {
        let s = corner();
        let bvh = Bvh::build(&s, &BvhParams::default()).unwrap();
        let x = exits();
        let params = ReferenceParams::with_spp(4096);
        let t = sky_transfer_at_exits(&s, &bvh, &x, &params, &mut |_, _| {}).unwrap();
        let sky = Sky::uniform(Vec3::new(1.0, 0.8, 0.6));
        let tracer = ReferenceTracer::new(&s, &bvh, Lighting::Lights(&[])).with_sky(&sky);
        let reference = tracer
            .indirect_at_exits(&x, &ReferenceParams { seed: 9, ..params }, &mut |_, _| {})
            .unwrap();
        // The tracer's own direct estimate at many samples, so that its noise is small.
        let direct: Vec<Vec3> = x
            .iter()
            .enumerate()
            .map(|(i, e)| tracer.sky_direct(&Receiver::at_exit(&bvh, e), 1 << 16, &mut Rng::new(3, i as u64, 0)))
            .collect();
        for (i, direct) in direct.iter().enumerate() {
            let (d, ind) = t.irradiance(i, &sky.sh());
            let (d, ind) = (Vec3::from(d), Vec3::from(ind));
            let sigma = reference.variance[i].max_element().sqrt();
            assert!(
                (ind - reference.mean[i]).abs().max_element() < 4.0 * sigma + 1e-3,
                "exit {i}: indirect {ind} vs reference {} ± {sigma}",
                reference.mean[i]
            );
            assert!(ind.max_element() > 0.02, "exit {i} sees a lit surface: {ind}");
            assert!(
                (d - *direct).abs().max_element() < 0.02 * direct.max_element(),
                "exit {i}: direct {d} vs reference {direct}"
            );
        }
    }
}
