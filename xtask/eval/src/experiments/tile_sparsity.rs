//! Experiment: how many of the panes' coefficient blocks a lit lightmap needs.
//!
//! `cargo xtask eval experiment tile_sparsity SCENE ARCHIVE.prm LIGHT [LIGHT...]`
//!
//! An archive's panes hold, per atlas tile, a block of coefficients for every pane. The run
//! time keeps only the blocks that are not zero (`prm-runtime`'s `blend.rs`). This prints how
//! many that is and their GPU bytes (a scale and four `f16` ranks a word per block, plus a
//! `u32` block index per pane and tile), and what dropping more would cost: for each loss `q`,
//! every pane also drops the blocks of the tiles it lights least, as many as hold at most `q`
//! of its light (a block's light is its texels' sum over the three channels, negatives as
//! zero). Under each light it compares the panes' lit lightmap (every cluster blended by its
//! energy weight, no near field) with the one with every block: relative RMSE over the covered
//! texels and over their dimmer half, and the energy.

use anyhow::{bail, Context, Result};
use glam::Vec3;
use prm_format::PaneBasis;
use std::path::Path;

use super::common::rel_rmse;

/// Shares of each pane's light its dropped blocks may hold (0: the zero blocks alone).
const LOSSES: [f64; 4] = [0.0, 1e-4, 1e-3, 1e-2];

pub fn run(args: Vec<String>) -> Result<()> {
    let usage = "usage: tile_sparsity SCENE ARCHIVE.prm LIGHT [LIGHT...]";
    let [scene_path, archive_path, lights @ ..] = &args[..] else {
        bail!(usage);
    };
    if lights.is_empty() {
        bail!(usage);
    }
    let (archive, scene) = prm_play::open(Path::new(archive_path), Some(Path::new(scene_path)))?;
    let lights = lights
        .iter()
        .map(|l| prm_scene::parse_light(l).with_context(|| l.clone()))
        .collect::<Result<Vec<_>>>()?;
    let entries = archive.entries();
    let energy = super::common::entry_energy(&archive);
    let bvh = prm_trace::Bvh::build(&scene, &prm_trace::BvhParams::DEFAULT)?;
    let disk = scene.entry_disk(entries.len());
    let weights: Vec<Vec<[f32; 3]>> = lights
        .iter()
        .map(|l| {
            let one = std::slice::from_ref(l);
            let w = prm_trace::archive_weights(
                &bvh,
                one,
                entries,
                &energy,
                archive.clusters(),
                disk,
                archive.entry_cells(),
            );
            w.iter().map(|v| v.to_array()).collect()
        })
        .collect();
    let basis = archive.pane_basis();
    let every = vec![true; basis.pane_count() * basis.tile_count()];
    let full: Vec<Vec<Vec3>> = weights.iter().map(|w| blend(basis, w, &every)).collect();
    let library: Vec<Vec3> = basis.blend(&weights[0]).into_iter().map(Vec3::from).collect();
    anyhow::ensure!(
        rel_rmse(&full[0], &library).0 < 1e-5,
        "the blend here differs from PaneBasis::blend"
    );
    let covered: Vec<usize> = (0..full[0].len())
        .filter(|&i| full.iter().any(|f| f[i] != Vec3::ZERO))
        .collect();
    let pick = |m: &[Vec3], at: &[usize]| at.iter().map(|&i| m[i]).collect::<Vec<_>>();
    let ranked: Vec<usize> = (0..basis.tile_count()).filter(|&t| basis.ranks()[t] > 0).collect();
    let blocks = basis.pane_count() * ranked.len();
    let dense: u64 = ranked
        .iter()
        .map(|&t| basis.pane_count() as u64 * block_bytes(basis, t))
        .sum();
    let rows: u64 = ranked
        .iter()
        .map(|&t| basis.nonzero_rows(t).count() as u64 * 8 * u64::from(basis.ranks()[t]).div_ceil(4))
        .sum();
    println!(
        "{} panes × {} tiles of rank > 0: coefficients {:.1} MiB on the GPU with every block, basis rows {:.1} MiB",
        basis.pane_count(),
        ranked.len(),
        mib(dense),
        mib(rows)
    );
    let light = block_light(basis);
    for loss in LOSSES {
        let keep = kept_blocks(basis, &light, loss);
        let kept: Vec<usize> = (0..keep.len()).filter(|&b| keep[b]).collect();
        let tiles = basis.tile_count();
        let bytes: u64 = kept.iter().map(|&b| block_bytes(basis, b % tiles)).sum::<u64>()
            + ranked.len() as u64 * 4 * basis.pane_count() as u64;
        print!(
            "loss {loss}: {:.1}% of blocks, {:.1} MiB with the index |",
            100.0 * kept.len() as f64 / blocks as f64,
            mib(bytes)
        );
        for (w, f) in weights.iter().zip(&full) {
            let s = blend(basis, w, &keep);
            let (err, energy) = rel_rmse(&pick(&s, &covered), &pick(f, &covered));
            let mut dim = covered.clone();
            dim.sort_by(|&a, &b| f[a].element_sum().total_cmp(&f[b].element_sum()));
            dim.truncate(dim.len() / 2);
            let (dim_err, _) = rel_rmse(&pick(&s, &dim), &pick(f, &dim));
            print!(
                " {:.3}% (dimmer half {:.3}%), energy {energy:.5} |",
                100.0 * err,
                100.0 * dim_err
            );
        }
        println!();
    }
    Ok(())
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}

/// GPU bytes of one pane's block in tile `tile`: its scale word and a 4-byte word a rank, the
/// rank rounded up to four.
fn block_bytes(basis: &PaneBasis, tile: usize) -> u64 {
    8 * (1 + 2 * u64::from(basis.ranks()[tile]).div_ceil(4))
}

/// Every pane's light in every tile, index `pane·tiles + tile`: `Σ_ch max(0, Σ_k s_k C[3p + ch][k])`
/// with `s_k` the tile's basis column sums.
fn block_light(basis: &PaneBasis) -> Vec<f64> {
    let tiles = basis.tile_count();
    let mut light = vec![0.0; basis.pane_count() * tiles];
    for tile in 0..tiles {
        let r = basis.ranks()[tile] as usize;
        if r == 0 {
            continue;
        }
        let mut sums = vec![0f64; r];
        for row in basis.basis(tile).chunks_exact(r) {
            sums.iter_mut().zip(row).for_each(|(s, &u)| *s += f64::from(u));
        }
        for (pane, block) in basis.coefficients(tile).chunks_exact(3 * r).enumerate() {
            light[pane * tiles + tile] = block
                .chunks_exact(r)
                .map(|c| {
                    c.iter()
                        .zip(&sums)
                        .map(|(&c, s)| f64::from(c) * s)
                        .sum::<f64>()
                        .max(0.0)
                })
                .sum();
        }
    }
    light
}

/// The blocks kept: not zero, and not among the pane's faintest that hold at most `loss` of its
/// light.
fn kept_blocks(basis: &PaneBasis, light: &[f64], loss: f64) -> Vec<bool> {
    let tiles = basis.tile_count();
    let mut keep = vec![false; light.len()];
    for pane in 0..basis.pane_count() {
        let own = &light[pane * tiles..(pane + 1) * tiles];
        let mut order: Vec<usize> = (0..tiles).filter(|&t| !basis.block_is_zero(pane, t)).collect();
        order.sort_by(|&a, &b| own[a].total_cmp(&own[b]));
        let budget = loss * own.iter().sum::<f64>();
        let mut spent = 0.0;
        for tile in order {
            spent += own[tile];
            keep[pane * tiles + tile] = loss == 0.0 || spent > budget;
        }
    }
    keep
}

/// `PaneBasis::blend` over the kept blocks only.
fn blend(basis: &PaneBasis, weights: &[[f32; 3]], keep: &[bool]) -> Vec<Vec3> {
    let (t, s) = (basis.tile_size() as usize, basis.tiles_per_side() as usize);
    let res = basis.resolution() as usize;
    let tiles = basis.tile_count();
    let mut out = vec![Vec3::ZERO; res * res];
    for tile in 0..tiles {
        let r = basis.ranks()[tile] as usize;
        if r == 0 {
            continue;
        }
        let mut mixed = vec![Vec3::ZERO; r];
        for (pane, (w, c)) in weights
            .iter()
            .zip(basis.coefficients(tile).chunks_exact(3 * r))
            .enumerate()
        {
            if keep[pane * tiles + tile] {
                for (k, a) in mixed.iter_mut().enumerate() {
                    *a += Vec3::new(w[0] * c[k], w[1] * c[r + k], w[2] * c[2 * r + k]);
                }
            }
        }
        let (x0, y0) = ((tile % s) * t, (tile / s) * t);
        for (i, u) in basis.basis(tile).chunks_exact(r).enumerate() {
            let v: Vec3 = u.iter().zip(&mixed).map(|(uk, a)| *uk * *a).sum();
            out[(y0 + i / t) * res + x0 + i % t] = v.max(Vec3::ZERO);
        }
    }
    out
}
