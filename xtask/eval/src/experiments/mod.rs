//! Experiments behind the tuned choices that the crates' docs cite: each prints the measurement
//! the doc quotes. They run in release: `cargo xtask eval experiment NAME [ARGS]`.

mod bench_trace;
mod check_weights;
mod cluster_weights;
mod common;
mod lamp_distance;
mod lattice;
mod lightmap_floor;
mod near_field;
mod pane_rank;
mod probe_split;
mod residual_panes;
mod tile_sparsity;

use anyhow::{anyhow, bail, Result};

/// The experiments by name, with the arguments each takes.
const EXPERIMENTS: [(&str, &str); 11] = [
    (
        "bench_trace",
        "(no arguments) ray throughput of the BVH on the bundled scenes",
    ),
    (
        "check_weights",
        "SCENE ARCHIVE.prm LIGHT CAMERA WxH  the check's exit points weighed as an image weighs them",
    ),
    (
        "cluster_weights",
        "[SCENE] [ENTRIES] [CLUSTERS] [RES]  how a cluster's weight combines its members",
    ),
    (
        "lamp_distance",
        "SCENE ARCHIVE.prm LIGHT  a lamp's indirect light by distance: panes, near field, reference",
    ),
    (
        "lattice",
        "SCENE ENTRIES CLUSTERS RESOLUTION WALKS  the pane evaluation lattice",
    ),
    (
        "lightmap_floor",
        "SCENE ARCHIVE.prm LIGHT CAMERA REFERENCE.exr OUT  the atlas's error floor against the method's",
    ),
    (
        "near_field",
        "SCENE ARCHIVE.prm FX FY FZ  the near field against the reference at one light",
    ),
    (
        "pane_rank",
        "SCENE ARCHIVE.prm [TILE]  the panes as a low-rank basis per tile",
    ),
    (
        "probe_split",
        "SCENE ENTRIES WALKS DISK  the probes' split between VPLs and rays",
    ),
    ("residual_panes", "SCENE ARCHIVE.prm [K] [GROUPS]  residual pane groups"),
    (
        "tile_sparsity",
        "SCENE ARCHIVE.prm LIGHT...  the panes with only their largest coefficient blocks",
    ),
];

/// Runs the experiment named by `args[0]` with the rest of `args`.
pub fn run(args: &[String]) -> Result<()> {
    let Some(name) = args.first() else {
        bail!("usage: cargo xtask eval experiment NAME [ARGS]\n{}", listing());
    };
    let rest = args[1..].to_vec();
    match name.as_str() {
        "bench_trace" => bench_trace::run(rest),
        "check_weights" => check_weights::run(rest)?,
        "cluster_weights" => cluster_weights::run(rest),
        "lamp_distance" => lamp_distance::run(rest)?,
        "lattice" => lattice::run(rest),
        "lightmap_floor" => lightmap_floor::run(rest)?,
        "near_field" => near_field::run(rest),
        "pane_rank" => pane_rank::run(rest),
        "probe_split" => probe_split::run(rest).map_err(|e| anyhow!("{e}"))?,
        "residual_panes" => residual_panes::run(rest),
        "tile_sparsity" => tile_sparsity::run(rest)?,
        other => bail!("no experiment named {other:?}\n{}", listing()),
    }
    Ok(())
}

fn listing() -> String {
    EXPERIMENTS.iter().map(|(n, a)| format!("  {n} {a}\n")).collect()
}
