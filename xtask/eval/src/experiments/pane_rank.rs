//! Experiment: how far the panes compress as a low-rank basis per atlas tile.
//!
//! `cargo xtask eval experiment pane_rank SCENE ARCHIVE.prm [TILE]`
//!
//! Per tile of `TILE`² texels (64 by default), the panes restricted to the tile form a matrix
//! `M`. With `SHARED=1` (the default) one basis serves the three channels: `TILE²` rows (texels)
//! by `3P` columns (cluster and channel); with `SHARED=0` each channel has its own rows
//! (`3·TILE²` rows by `P` columns). Its thin SVD `M = U Σ Vᵀ` truncated to rank `r` stores `U`
//! as `f16` and `ΣVᵀ` as `f32`; a lit combination `M w` then costs `r` multiply-adds per texel
//! and channel. Each tile's rank is the smallest that leaves at most `ε` of its Frobenius norm.
//!
//! For the bake check's test lights (ray-cast, disk-bounded entry irradiance and energy weights,
//! every cluster kept) it prints, against the dense panes: bytes, the lit lightmap's relative
//! RMSE over every exit point and its energy; and the error of the panes alone (without the
//! near field, so far above the played error) against the reference tracer at `POINTS` sampled
//! exit points (2048; `REFSPP` paths, 256, its noise removed).
//!
//! Measured on the bundled Cornell box's default bake (512 clusters, 256² atlas, dense panes
//! 128 MiB as RGB9E5; MiB and relative RMSE against the dense panes, energy 1.000 throughout):
//!
//! | ε | per channel, 64² tiles | shared, 64² | shared, 32² | shared, 128² |
//! | --- | --- | --- | --- | --- |
//! | 0.01 | 33.4 MiB, 0.15% | 13.9 MiB, 0.16% | 11.8 MiB, 0.22% | 18.0 MiB, 0.34% |
//! | 0.02 | 22.9 MiB, 0.31% | 9.3 MiB, 0.34% | 7.6 MiB, 0.46% | 15.9 MiB, 0.37% |
//! | 0.04 | 14.8 MiB, 0.78% | 6.3 MiB, 0.84% | 5.1 MiB, 1.15% | 12.4 MiB, 0.57% |
//! | 0.08 | 9.2 MiB, 1.74% | 3.9 MiB, 1.89% | 3.3 MiB, 2.56% | 7.6 MiB, 1.45% |
//!
//! (128² tiles are capped at rank 128, `MAX_RANK`.) One basis for the three channels takes 2.5
//! times fewer bytes at the same error; 32² and 64² tiles lie on one front.
//!
//! On the modern hall's default bake (205 clusters, 512² atlas, dense panes 205 MiB, shared
//! basis in 64² tiles, the check's four lights): ε 0.005 keeps 40.7 MiB at 1.56%, 0.02 20.5 MiB
//! at 1.92%, 0.04 14.1 MiB at 2.64%, 0.08 9.2 MiB at 5.51%. A basis kept in `f32` (`F32=1`) gives
//! the same figures, so the `f16` rounding costs nothing measurable.

use glam::Vec3;

use super::common::{denoised_error, entry_energy, env_or, rel_rmse};
use faer::Mat;
use prm_scene::{Atlas, AtlasParams, Light, Sizing};
use prm_trace::check::{check_exits, check_lights};
use prm_trace::{Bvh, BvhParams, Lighting, ReferenceParams, ReferenceTracer};
use rayon::prelude::*;
use std::path::Path;

/// Per test light: relative RMSE against the dense panes, energy, error against the reference.
type PerLight = Vec<(f64, f64, f64)>;

/// The residual thresholds tried.
const EPSILONS: [f64; 6] = [0.005, 0.01, 0.02, 0.04, 0.08, 0.16];

/// One tile's truncated basis: `u` is `rows × rank` (row-major, rounded through `f16`), `sv` is
/// `P × rank` (`Σ Vᵀ`, transposed), the singular values, and the tile's texels.
struct TileBasis {
    texels: Vec<usize>,
    u: Vec<f32>,
    sv: Vec<f32>,
    sigma: Vec<f64>,
    shared: bool,
}

impl TileBasis {
    fn rows(&self) -> usize {
        self.texels.len() * if self.shared { 1 } else { 3 }
    }

    /// The largest rank kept.
    fn kept(&self) -> usize {
        self.u.len() / self.rows()
    }

    /// Smallest rank whose discarded singular values hold at most `eps` of the norm.
    fn rank_for(&self, eps: f64) -> usize {
        let total: f64 = self.sigma.iter().map(|s| s * s).sum();
        let mut tail = total;
        for (r, s) in self.sigma.iter().enumerate() {
            if tail <= eps * eps * total {
                return r;
            }
            tail -= s * s;
        }
        self.sigma.len()
    }
}

/// With `shared`, one basis serves the three channels: rows are texels and columns
/// `(cluster, channel)`; otherwise rows are `(texel, channel)` and columns clusters.
fn tile_basis(panes: &[Vec<[f32; 3]>], texels: Vec<usize>, max_rank: usize, shared: bool) -> Option<TileBasis> {
    let p = panes.len();
    let (rows, cols) = if shared {
        (texels.len(), 3 * p)
    } else {
        (3 * texels.len(), p)
    };
    let m = Mat::<f64>::from_fn(rows, cols, |i, j| {
        let (t, c, ch) = if shared { (i, j / 3, j % 3) } else { (i / 3, j, i % 3) };
        f64::from(panes[c][texels[t]][ch])
    });
    if m.norm_l2() == 0.0 {
        return None;
    }
    let svd = m.thin_svd().expect("SVD converged");
    let k = max_rank.min(rows).min(cols);
    let (u, s, v) = (svd.U(), svd.S(), svd.V());
    let s = s.column_vector();
    let sigma: Vec<f64> = (0..rows.min(cols)).map(|i| s[i]).collect();
    let mut uq = vec![0f32; rows * k];
    for i in 0..rows {
        for j in 0..k {
            uq[i * k + j] = if full_precision() {
                u[(i, j)] as f32
            } else {
                half::f16::from_f64(u[(i, j)]).to_f32()
            };
        }
    }
    let mut sv = vec![0f32; cols * k];
    for c in 0..cols {
        for j in 0..k {
            sv[c * k + j] = (sigma[j] * v[(c, j)]) as f32;
        }
    }
    Some(TileBasis {
        texels,
        u: uq,
        sv,
        sigma,
        shared,
    })
}

/// `F32=1` keeps the basis in `f32` instead of `f16`, to see what the rounding costs.
fn full_precision() -> bool {
    env_or("F32", 0) == 1
}

/// The lit lightmap `Σ_c w_c pane_c` through every tile's basis truncated to `ranks[t]`.
fn lit(bases: &[TileBasis], ranks: &[usize], w: &[Vec3], texels: usize) -> Vec<Vec3> {
    let mut out = vec![Vec3::ZERO; texels];
    for (b, &r) in bases.iter().zip(ranks) {
        let k = b.sv.len() / if b.shared { 3 * w.len() } else { w.len() };
        let mut z = vec![Vec3::ZERO; r];
        for (c, wc) in w.iter().enumerate() {
            for (j, zj) in z.iter_mut().enumerate() {
                *zj += if b.shared {
                    Vec3::new(
                        b.sv[3 * c * k + j],
                        b.sv[(3 * c + 1) * k + j],
                        b.sv[(3 * c + 2) * k + j],
                    ) * *wc
                } else {
                    *wc * b.sv[c * k + j]
                };
            }
        }
        for (ti, &t) in b.texels.iter().enumerate() {
            let mut v = [0f32; 3];
            for (ch, vc) in v.iter_mut().enumerate() {
                let row = if b.shared { ti } else { 3 * ti + ch };
                let row = &b.u[row * k..][..r];
                *vc = row.iter().zip(&z).map(|(u, z)| u * z[ch]).sum::<f32>().max(0.0);
            }
            out[t] = Vec3::from_array(v);
        }
    }
    out
}

pub fn run(args: Vec<String>) {
    let scene_path = Path::new(&args[0]);
    let archive = prm_format::Archive::open(Path::new(&args[1])).unwrap();
    let tile: usize = args.get(2).map_or(64, |s| s.parse().unwrap());
    let scene = prm_scene::load(scene_path).unwrap();
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let res = archive.atlas().resolution as usize;
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(res as u32))).unwrap();
    let clusters = archive.clusters().to_vec();
    let entries = archive.entries().to_vec();
    let entry_energy = entry_energy(&archive);
    let panes: Vec<Vec<[f32; 3]>> = (0..clusters.len()).map(|c| archive.read_pane(c).unwrap()).collect();
    let p = panes.len();
    let max_rank = env_or("MAX_RANK", 128) as usize;
    let shared = env_or("SHARED", 1) == 1;
    let t0 = std::time::Instant::now();
    let per_side = res.div_ceil(tile);
    let bases: Vec<TileBasis> = (0..per_side * per_side)
        .into_par_iter()
        .filter_map(|t| {
            let (tx, ty) = (t % per_side, t / per_side);
            let texels: Vec<usize> = (ty * tile..((ty + 1) * tile).min(res))
                .flat_map(|y| (tx * tile..((tx + 1) * tile).min(res)).map(move |x| y * res + x))
                .collect();
            tile_basis(&panes, texels, max_rank, shared)
        })
        .collect();
    let svd_s = t0.elapsed().as_secs_f64();
    let dense_bytes = p * res * res * 4;
    let file_bytes = std::fs::metadata(&args[1]).unwrap().len();
    println!(
        "{}: {p} clusters, {res}² atlas, {tile}² tiles ({} non-empty), SVD {svd_s:.1} s",
        scene_path.display(),
        bases.len()
    );
    println!(
        "dense panes: {:.1} MiB as RGB9E5, archive {:.1} MiB",
        mib(dense_bytes),
        mib(file_bytes as usize)
    );
    let disk = scene.entry_disk(entries.len());
    let sample = check_exits(atlas.exits.len(), env_or("POINTS", 2048), 1);
    let refspp = env_or("REFSPP", 256);
    let exit_texels: Vec<usize> = atlas.exits.iter().map(|x| x.texel as usize).collect();
    let mut rows: Vec<(String, usize, PerLight)> = Vec::new();
    let mut dense_vs_ref = Vec::new();
    let lights = check_lights(&scene, &bvh);
    for (li, &position) in lights.iter().enumerate() {
        let d = scene.bounds().diagonal();
        let lights = [Light::Point {
            position,
            intensity: Vec3::splat(d * d),
        }];
        let w = prm_trace::archive_weights(
            &bvh,
            &lights,
            &entries,
            &entry_energy,
            &clusters,
            disk,
            archive.entry_cells(),
        );
        let mut dense = vec![Vec3::ZERO; res * res];
        for (wc, pane) in w.iter().zip(&panes) {
            for (o, v) in dense.iter_mut().zip(pane) {
                *o += *wc * Vec3::from_array(*v);
            }
        }
        let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights));
        let exits: Vec<_> = sample.iter().map(|&i| atlas.exits[i]).collect();
        let params = ReferenceParams {
            seed: 77 + li as u64,
            ..ReferenceParams::with_spp(refspp)
        };
        let r = tracer.indirect_at_exits(&exits, &params, &mut |_, _| {}).unwrap();
        let at = |img: &[Vec3], idx: &[usize]| -> Vec<Vec3> { idx.iter().map(|&i| img[i]).collect() };
        let sampled: Vec<usize> = sample.iter().map(|&i| exit_texels[i]).collect();
        dense_vs_ref.push(denoised_error(&at(&dense, &sampled), &r.mean, &r.variance, |_| true).0);
        let dense_exits = at(&dense, &exit_texels);
        for (ei, &eps) in EPSILONS.iter().enumerate() {
            let ranks: Vec<usize> = bases.iter().map(|b| b.rank_for(eps).min(b.kept())).collect();
            let bytes: usize = bases
                .iter()
                .zip(&ranks)
                .map(|(b, r)| r * (2 * b.rows() + 4 * b.sv.len() / b.kept()))
                .sum();
            let img = lit(&bases, &ranks, &w, res * res);
            let (e, en) = rel_rmse(&at(&img, &exit_texels), &dense_exits);
            let er = denoised_error(&at(&img, &sampled), &r.mean, &r.variance, |_| true).0;
            if li == 0 {
                let mean_rank = ranks.iter().sum::<usize>() as f64 / ranks.len() as f64;
                rows.push((format!("ε {eps:<6} mean rank {mean_rank:5.1}"), bytes, Vec::new()));
            }
            rows[ei].2.push((e, en, er));
        }
    }
    let n = dense_vs_ref.len() as f64;
    println!(
        "dense, every cluster: against the reference {:.2}%",
        100.0 * dense_vs_ref.iter().sum::<f64>() / n
    );
    println!(
        "{:<28} {:>9} {:>9} {:>8} {:>9}",
        "basis", "MiB", "vs dense", "energy", "vs ref"
    );
    for (name, bytes, v) in rows {
        let mean = |f: fn(&(f64, f64, f64)) -> f64| v.iter().map(f).sum::<f64>() / n;
        let each: Vec<String> = v.iter().map(|x| format!("{:.2}", 100.0 * x.0)).collect();
        println!(
            "{name:<28} {:9.2} {:8.2}% {:8.3} {:8.2}%   per light {}",
            mib(bytes),
            100.0 * mean(|x| x.0),
            mean(|x| x.1),
            100.0 * mean(|x| x.2),
            each.join(" ")
        );
    }
}

fn mib(bytes: usize) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}
