//! Measures shared visibility ([`prm_trace::Lattice`]) against exact panes, as `pane.rs` records.
//!
//! `cargo xtask eval experiment lattice SCENE ENTRIES CLUSTERS RESOLUTION WALKS`
//!
//! Builds what `prm-bake bake` builds for those sizes (seed 0: the same atlas, entry points,
//! walks and clusters), evaluates the panes exactly and with lattice steps 2, 4 and 8, and prints
//! for each step the shadow rays, the seconds, and the relative L2 difference from exact over
//! all pane values (worst pane in brackets) with the energy ratio. The bake's own sizes are
//! printed by `prm-bake bake SCENE --plan`: the Cornell box's default is `1024 64 256 8`,
//! chairs' paper preset `4096 256 256 1`. (The module's table compares the archives' RGB9E5
//! panes; this compares the floats, so its differences differ a little: 0.59 % at step 4 on the
//! Cornell box against 0.57 %.)

use std::time::Instant;

use glam::Vec3;
use prm_scene::{Atlas, AtlasParams, Sizing};
use prm_trace::{
    evaluate_atlas_panes, Bvh, BvhParams, Clustering, EntryParams, Lattice, PaneParams, Panes, WalkParams,
};

/// (relative L2 over everything, worst pane's relative L2, energy ratio) of `a` against `b`.
fn difference(a: &Panes, b: &Panes) -> (f64, f64, f64) {
    let (mut d2, mut r2, mut sa, mut sb, mut worst) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for c in 0..a.clusters {
        let (mut pd, mut pr) = (0.0f64, 0.0f64);
        for (x, y) in a.pane(c).iter().zip(b.pane(c)) {
            pd += (*x - *y).as_dvec3().length_squared();
            pr += y.as_dvec3().length_squared();
            sa += x.element_sum() as f64;
            sb += y.element_sum() as f64;
        }
        worst = worst.max((pd / pr.max(1e-300)).sqrt());
        d2 += pd;
        r2 += pr;
    }
    ((d2 / r2.max(1e-300)).sqrt(), worst, sa / sb.max(1e-300))
}

pub fn run(args: Vec<String>) {
    let [scene, entries, clusters, resolution, walks] = &args[..] else {
        eprintln!("usage: lattice SCENE ENTRIES CLUSTERS RESOLUTION WALKS (e.g. scenes/cornell-box/cornell-box.obj 1024 64 256 8)");
        std::process::exit(2);
    };
    let number = |s: &str| -> usize { s.parse().unwrap_or_else(|_| panic!("`{s}` is not a count")) };
    let scene = prm_scene::load(std::path::Path::new(scene)).expect("loading the scene");
    let atlas = Atlas::build(
        &scene,
        &AtlasParams::with_sizing(Sizing::Resolution(number(resolution) as u32)),
    )
    .expect("building the atlas");
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).expect("building the BVH");
    let samples = prm_trace::sample_surface(
        &scene,
        &EntryParams {
            count: number(entries),
            seed: 0,
        },
    )
    .expect("sampling entry points");
    let walk_params = WalkParams {
        walks_per_entry: number(walks) as u32,
        seed: 0,
        ..WalkParams::PREVIEW
    };
    let vpls = prm_trace::trace_walks(&scene, &bvh, &samples, &walk_params).expect("tracing walks");
    let clustering = Clustering::kmeans_separated(&samples, &bvh, scene.bounds().diagonal(), number(clusters), 0)
        .expect("clustering");
    println!(
        "{} exit points, {} VPLs, {} clusters, {} charts",
        atlas.exits.len(),
        vpls.vpls.len(),
        clustering.len(),
        atlas.stats.charts
    );
    let run = |lattice: Lattice| {
        let t = Instant::now();
        let panes = evaluate_atlas_panes(
            &bvh,
            &vpls,
            &clustering,
            &atlas,
            &PaneParams::DEFAULT,
            &lattice,
            &mut |_| {},
        )
        .expect("evaluating panes");
        (panes, t.elapsed().as_secs_f64())
    };
    let (exact, seconds) = run(Lattice::EXACT);
    println!("exact: {:.0} M rays, {seconds:.1} s", exact.rays as f64 / 1e6);
    for step in [2, 4, 8] {
        let (shared, seconds) = run(Lattice { step });
        let (diff, worst, energy) = difference(&shared, &exact);
        let total: Vec3 = shared.data.iter().copied().sum();
        assert!(total.is_finite(), "non-finite panes at step {step}");
        println!(
            "step {step}: {:.0} M rays, {seconds:.1} s, difference {:.2}% (worst pane {:.1}%), energy {energy:.4}",
            shared.rays as f64 / 1e6,
            100.0 * diff,
            100.0 * worst
        );
    }
}
