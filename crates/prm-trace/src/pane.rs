//! CPU pane evaluators: the pane of every cluster at every exit point, by ray casting.
//!
//! `pane_c(x) = Σ_{k ∈ c} Σ_{v ∈ VPLs of k} Φ_v/π · cos θ_x · cos θ_v · b(r², v) · V(x, v)` where
//! `b` is the bounded `1/r²` ([`VplBound`]) and `V` is a shadow ray ([`Bvh::visible`]); `cos θ_x`
//! uses the exit point's (shading) normal, `cos θ_v` the VPL's geometric normal. Values are
//! indirect irradiance in W/m² per W/m² of entry irradiance. At run time
//! `E_ind(x) = Σ_c weight_c · pane_c(x)` with `weight_c` the direct irradiance of the cluster's
//! members weighed by their pane energy ([`crate::Clustering::weights_by_energy`],
//! [`Panes::combine`]).
//!
//! Two evaluators, on one kernel (the VPLs in blocks of 64, structure of arrays, so that the
//! unoccluded term vectorises: the Cornell box's exact panes take 23.3 s, against 28.0 s with
//! one VPL at a time):
//! * [`evaluate_panes`]: one shadow ray per exit point and VPL, over any list of exit points. The
//!   exact yardstick for every other renderer.
//! * [`evaluate_atlas_panes`]: over an atlas, sharing shadow rays between neighbouring texels
//!   ([`Lattice`]). Each chart is cut into tiles of its own bounding box, and every ray is cast
//!   at the exit points of a coarse lattice anchored at the box's corner: every `step`-th texel
//!   in x and y, and the box's far edges (halved for a chart narrower than the step). Then,
//!   halving the spacing down to 1, each new point takes a VPL's visibility from the lattice
//!   corners around it when they all agree, and casts its own ray where they do not (shadow
//!   edges) or where a corner is missing or unlike it (chart borders, creases). The unoccluded
//!   term is evaluated at every exit point. With `step: 1` it is the exact evaluator, bit for
//!   bit.
//!
//! Measured (release, 2 cores, `cargo xtask eval experiment lattice SCENE
//! ENTRIES CLUSTERS RES WALKS` with the bake's sizes; difference = relative L2 of all pane values
//! against exact, worst pane in brackets):
//!
//! | scene | step | shadow rays | pane rendering | difference (worst pane) | energy |
//! | --- | --- | ---: | ---: | ---: | ---: |
//! | Cornell box, default (42,912 exits, 10,668 VPLs, 15 charts) | exact | 303 M | 20.2 s | | |
//! | | 2 | 90 M | 7.4 s | 0.04 % (0.2 %) | 1.0000 |
//! | | **4** | **32 M** | **3.7 s** | **0.12 % (0.8 %)** | 1.0000 |
//! | | 8 | 16 M | 2.6 s | 0.15 % (0.9 %) | 1.0000 |
//! | chairs, `--preset paper` (35,717 exits, 11,547 VPLs, 913 charts) | exact | 271 M | 26.7 s | | |
//! | | 2 | 112 M | 15.4 s | 1.7 % (11.7 %) | 1.0011 |
//! | | **4** | **59 M** | **10.2 s** | **2.7 % (13.0 %)** | 1.0025 |
//! | | 8 | 42 M | 8.3 s | 5.4 % (36.6 %) | 1.0036 |
//!
//! Step 4 is the default: step 8 saves 19 % of chairs' time for 2.7 points more difference,
//! since a shadow narrower than the coarse lattice is lost. For scale, lavapipe's depth-map panes
//! (`--backend vulkan`) differ from exact by 1.8 % on the Cornell box and by 10.7 % on chairs
//! (energy 1.046): the shared visibility is closer to exact than the GPU path. Chairs' time is
//! mostly shadow rays; the lattice already shares most of the rays an occluder cache per VPL
//! ([`Bvh::occluded_cached`]) would save.
//!
//! Work is parallel over exit points (tiles of the atlas); each exit point sums its VPLs in a
//! fixed order and the work items are fixed by the atlas alone, so the result does not depend on
//! the thread count.

use glam::Vec3;
use prm_scene::{Atlas, ExitPoint, EMPTY_TEXEL};
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::cluster::Clustering;
use crate::vpl::VplBound;
use crate::walk::{Vpl, VplSet};
use crate::TraceError;

/// Pane evaluation parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PaneParams {
    /// Singularity bound.
    pub bound: VplBound,
}

impl PaneParams {
    /// [`VplBound::DEFAULT`].
    pub const DEFAULT: PaneParams = PaneParams {
        bound: VplBound::DEFAULT,
    };
}

impl Default for PaneParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The panes of all clusters over a list of exit points.
#[derive(Clone, Debug, PartialEq)]
pub struct Panes {
    /// Number of clusters.
    pub clusters: usize,
    /// Number of exit points.
    pub exits: usize,
    /// Cluster-major: `data[c * exits + i]` is cluster `c`'s pane at exit point `i`.
    pub data: Vec<Vec3>,
    /// Shadow rays cast.
    pub rays: u64,
    /// Every entry point's pane energy: the sum over `exits` of the indirect irradiance its own
    /// VPLs give (RGB), which the player weighs a cluster's members by (formats/prm.md §5.1).
    /// Empty when the producer did not compute it.
    pub entry_energy: Vec<Vec3>,
}

impl Panes {
    /// Cluster `c`'s pane, one value per exit point.
    pub fn pane(&self, c: usize) -> &[Vec3] {
        &self.data[c * self.exits..(c + 1) * self.exits]
    }

    /// `Σ_c weights[c] · pane_c` at every exit point (component-wise product).
    pub fn combine(&self, weights: &[Vec3]) -> Vec<Vec3> {
        assert_eq!(weights.len(), self.clusters, "one weight per cluster");
        (0..self.exits)
            .map(|i| {
                (0..self.clusters)
                    .map(|c| weights[c] * self.data[c * self.exits + i])
                    .sum()
            })
            .collect()
    }
}

/// VPLs per block of the per-exit loop: one word of the visibility bit sets.
const BLOCK: usize = 64;

/// The VPLs as the per-exit loop reads them: structure of arrays padded to whole blocks, so the
/// unoccluded term of a block is one loop of fixed length that the compiler vectorises.
struct Kernel<'a> {
    bvh: &'a Bvh,
    vpls: &'a [Vpl],
    px: Vec<f32>,
    py: Vec<f32>,
    pz: Vec<f32>,
    nx: Vec<f32>,
    ny: Vec<f32>,
    nz: Vec<f32>,
    /// The bound as `1/max(k·r² + add, r², min)` ([`VplBound`]).
    k: f32,
    add: Vec<f32>,
    min: Vec<f32>,
    cluster: Vec<u32>,
    clusters: usize,
    entries: usize,
}

/// Where [`Kernel::sum_exit`] adds one exit point's sums.
struct ExitSums<'s> {
    /// Per cluster, the pane value at the exit.
    acc: &'s mut [Vec3],
    /// Per entry point, the energy its VPLs delivered.
    entry_energy: &'s mut [Vec3],
    /// Each VPL's last occluder ([`Kernel::occluder_cache`]).
    cache: &'s mut [u32],
    /// Shadow rays cast.
    rays: &'s mut u64,
}

impl<'a> Kernel<'a> {
    fn new(bvh: &'a Bvh, vpls: &'a VplSet, clustering: &Clustering, bound: VplBound) -> Result<Kernel<'a>, TraceError> {
        if clustering.of_entry.len() != vpls.entries() {
            return Err(TraceError::InvalidParameter(format!(
                "clustering covers {} entry points, the VPL set {}",
                clustering.of_entry.len(),
                vpls.entries()
            )));
        }
        let padded = vpls.vpls.len().div_ceil(BLOCK) * BLOCK;
        let column = |f: &dyn Fn(&Vpl) -> f32| -> Vec<f32> {
            let mut c: Vec<f32> = vpls.vpls.iter().map(f).collect();
            // Padding: a zero normal makes `cos θ_v` zero, so these never count.
            c.resize(padded, 0.0);
            c
        };
        // `1/max(k·r² + k·disk·area, r², clamp)` is each bound of [`VplBound`] (`k = 1` but
        // for `Near`, whose `k` is `1 − w₀`; with `k = 1` the `r²` term never wins).
        let (k, disk, clamp) = match bound {
            VplBound::None => (1.0, 0.0, 0.0),
            VplBound::Clamp { min_distance } => (1.0, 0.0, min_distance * min_distance),
            VplBound::Disk { scale } => (1.0, scale * scale * std::f32::consts::FRAC_1_PI, 0.0),
            VplBound::Near { scale } => {
                let k = crate::vpl::NEAR_KEEP;
                (k, k * scale * scale * std::f32::consts::FRAC_1_PI, 0.0)
            }
        };
        Ok(Kernel {
            bvh,
            vpls: &vpls.vpls,
            px: column(&|v| v.position.x),
            py: column(&|v| v.position.y),
            pz: column(&|v| v.position.z),
            nx: column(&|v| v.normal.x),
            ny: column(&|v| v.normal.y),
            nz: column(&|v| v.normal.z),
            k,
            add: column(&|v| disk * v.area),
            min: column(&|_| clamp),
            cluster: vpls
                .vpls
                .iter()
                .map(|v| clustering.of_entry[v.entry as usize])
                .collect(),
            clusters: clustering.len(),
            entries: vpls.entries(),
        })
    }

    /// Words of a per-VPL bit set (= blocks).
    fn words(&self) -> usize {
        self.px.len() / BLOCK
    }

    /// The unoccluded irradiance factor `cos θ_x cos θ_v b(r²)/π` of block `b`'s VPLs at `x`
    /// (zero where either side faces away), and the mask of the non-zero ones.
    #[inline(always)]
    fn block_factors(&self, b: usize, x: Vec3, n: Vec3, g: &mut [f32; BLOCK]) -> u64 {
        fn block(c: &[f32], b: usize) -> &[f32; BLOCK] {
            c[b * BLOCK..(b + 1) * BLOCK].try_into().expect("whole blocks")
        }
        let (px, py, pz) = (block(&self.px, b), block(&self.py, b), block(&self.pz, b));
        let (nx, ny, nz) = (block(&self.nx, b), block(&self.ny, b), block(&self.nz, b));
        let (add, min) = (block(&self.add, b), block(&self.min, b));
        // Branch-free, so that it vectorises: `cx`, `cv` are the cosines times r.
        for j in 0..BLOCK {
            let (dx, dy, dz) = (px[j] - x.x, py[j] - x.y, pz[j] - x.z);
            let r2 = dx * dx + dy * dy + dz * dz;
            let cx = n.x * dx + n.y * dy + n.z * dz;
            let cv = -(nx[j] * dx + ny[j] * dy + nz[j] * dz);
            let denominator = r2 * (self.k * r2 + add[j]).max(r2).max(min[j]);
            let f = std::f32::consts::FRAC_1_PI * cx * cv / denominator;
            let facing = (cx > 0.0) & (cv > 0.0) & (denominator > 0.0);
            g[j] = if facing { f } else { 0.0 };
        }
        let mut mask = 0u64;
        for (j, &f) in g.iter().enumerate() {
            mask |= u64::from(f > 0.0) << j;
        }
        mask
    }

    /// An occluder cache per VPL ([`Bvh::occluded_cached`]), empty.
    fn occluder_cache(&self) -> Vec<u32> {
        vec![crate::NO_OCCLUDER; self.px.len()]
    }

    /// Sums every VPL at exit `x` into `sums`, per cluster and per entry point. `corners` gives,
    /// per word, the VPLs that the lattice corners all see and all miss; every other VPL facing
    /// `x` costs a shadow ray, whose answer is recorded in `bits` (known, visible) when given.
    /// `sums.cache` holds each VPL's last occluder ([`Kernel::occluder_cache`]); a VPL's rays go
    /// through it in a fixed order, so the answers do not depend on which other VPLs are summed.
    fn sum_exit(
        &self,
        x: &ExitPoint,
        corners: Option<(&[u64], &[u64])>,
        bits: Option<(&mut [u64], &mut [u64])>,
        sums: ExitSums<'_>,
    ) {
        #[cfg(target_arch = "x86_64")]
        if crate::isa::avx2() {
            // SAFETY: `isa::avx2` checked that the CPU has every feature the variant is built for.
            return unsafe { self.sum_exit_avx2(x, corners, bits, sums) };
        }
        self.sum_exit_inline(x, corners, bits, sums)
    }

    /// [`Kernel::sum_exit`] built for AVX2 and FMA ([`crate::isa`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt")]
    fn sum_exit_avx2(
        &self,
        x: &ExitPoint,
        corners: Option<(&[u64], &[u64])>,
        bits: Option<(&mut [u64], &mut [u64])>,
        sums: ExitSums<'_>,
    ) {
        self.sum_exit_inline(x, corners, bits, sums)
    }

    /// The body of [`Kernel::sum_exit`], inlined into each instruction-set variant.
    #[inline(always)]
    fn sum_exit_inline(
        &self,
        x: &ExitPoint,
        corners: Option<(&[u64], &[u64])>,
        mut bits: Option<(&mut [u64], &mut [u64])>,
        sums: ExitSums<'_>,
    ) {
        let ExitSums {
            acc,
            entry_energy,
            cache,
            rays,
        } = sums;
        let ng = self.bvh.geometric_normal(x.triangle);
        let mut g = [0.0f32; BLOCK];
        for w in 0..self.words() {
            let facing = self.block_factors(w, x.position, x.normal, &mut g);
            if facing == 0 {
                continue;
            }
            let (mut visible, mut unknown) = match corners {
                Some((seen, missed)) => (facing & seen[w], facing & !seen[w] & !missed[w]),
                None => (0, facing),
            };
            *rays += u64::from(unknown.count_ones());
            let mut vis_w = 0u64;
            while unknown != 0 {
                let j = unknown.trailing_zeros() as usize;
                unknown &= unknown - 1;
                let k = w * BLOCK + j;
                let v = &self.vpls[k];
                if self.bvh.visible_cached(
                    x.position,
                    ng,
                    x.triangle,
                    v.position,
                    v.normal,
                    v.triangle,
                    &mut cache[k],
                ) {
                    vis_w |= 1 << j;
                }
            }
            visible |= vis_w;
            if let Some((known, vis)) = bits.as_mut() {
                known[w] = facing;
                vis[w] = visible;
            }
            while visible != 0 {
                let j = visible.trailing_zeros() as usize;
                visible &= visible - 1;
                let k = w * BLOCK + j;
                let e = self.vpls[k].power * g[j];
                acc[self.cluster[k] as usize] += e;
                entry_energy[self.vpls[k].entry as usize] += e;
            }
        }
    }
}

/// Work items of [`evaluate_panes`]: the exits are cut into this many chunks (of 64 to 4096
/// exits), each keeping one energy per entry point, so the bookkeeping stays at most 256 ×
/// entries × 12 bytes while 2 cores still get 128 items each. Fixed by the exit count alone, so
/// the sums' order, hence the result, does not depend on the thread count.
const WORK_ITEMS: usize = 256;

/// Evaluates every cluster's pane at every exit point in `exits`, and every entry point's pane
/// energy, with one shadow ray per exit point and VPL.
pub fn evaluate_panes(
    bvh: &Bvh,
    vpls: &VplSet,
    clustering: &Clustering,
    exits: &[ExitPoint],
    params: &PaneParams,
) -> Result<Panes, TraceError> {
    let kernel = Kernel::new(bvh, vpls, clustering, params.bound)?;
    let c = kernel.clusters;
    // Exits in fixed chunks, each summing its VPLs' energy too; the chunks' sums are added in
    // order, so the energies do not depend on the thread count either.
    let chunk_len = exits.len().div_ceil(WORK_ITEMS).clamp(64, 4096);
    let per_chunk: Vec<WorkPanes> = exits
        .par_chunks(chunk_len)
        .enumerate()
        .map(|(k, chunk)| {
            let mut out = WorkPanes::new(kernel.entries);
            out.exits = (k * chunk_len..k * chunk_len + chunk.len()).map(|i| i as u32).collect();
            out.accs = vec![Vec3::ZERO; chunk.len() * c];
            let mut cache = kernel.occluder_cache();
            for (x, acc) in chunk.iter().zip(out.accs.chunks_mut(c.max(1))) {
                let sums = ExitSums {
                    acc,
                    entry_energy: &mut out.entry_energy,
                    cache: &mut cache,
                    rays: &mut out.rays,
                };
                kernel.sum_exit(x, None, None, sums);
            }
            out
        })
        .collect();
    let mut panes = Panes::assembling(c, exits.len(), kernel.entries);
    for out in per_chunk {
        panes.add(out);
    }
    Ok(panes)
}

/// What one work item (a chunk or tile of exit points) produced.
struct WorkPanes {
    /// Exit point indices, in the order of `accs`.
    exits: Vec<u32>,
    /// `exits.len() × clusters` pane values, exit-major.
    accs: Vec<Vec3>,
    entry_energy: Vec<Vec3>,
    rays: u64,
}

impl WorkPanes {
    fn new(entries: usize) -> WorkPanes {
        WorkPanes {
            exits: Vec::new(),
            accs: Vec::new(),
            entry_energy: vec![Vec3::ZERO; entries],
            rays: 0,
        }
    }
}

impl Panes {
    /// Empty panes, to [`add`](Self::add) work items to.
    fn assembling(clusters: usize, exits: usize, entries: usize) -> Panes {
        Panes {
            clusters,
            exits,
            data: vec![Vec3::ZERO; clusters * exits],
            rays: 0,
            entry_energy: vec![Vec3::ZERO; entries],
        }
    }

    /// Adds a work item's results (items are added in a fixed order, so the sums are too).
    fn add(&mut self, out: WorkPanes) {
        let (c, n) = (self.clusters, self.exits);
        self.rays += out.rays;
        for (total, e) in self.entry_energy.iter_mut().zip(&out.entry_energy) {
            *total += *e;
        }
        for (k, &i) in out.exits.iter().enumerate() {
            for cl in 0..c {
                self.data[cl * n + i as usize] = out.accs[k * c + cl];
            }
        }
    }
}

/// Shadow-ray sharing between neighbouring texels in [`evaluate_atlas_panes`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lattice {
    /// Texels, in x and in y, between the exit points that cast every shadow ray: a power of
    /// two; 1 casts every ray at every exit point (exact).
    pub step: u32,
}

impl Lattice {
    /// Every shadow ray at every exit point: the same panes as [`evaluate_panes`].
    pub const EXACT: Lattice = Lattice { step: 1 };
    /// Every fourth texel in x and y, refined through every second: 11–22 % of the exact rays,
    /// within 0.1–2.7 % of exact (module docs).
    pub const DEFAULT: Lattice = Lattice { step: 4 };
}

impl Default for Lattice {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A lattice corner stands for an exit point only if its normal is within about 18° of the exit
/// point's (cos 18° ≈ 0.95): across a crease or on a tight curve the corners see a different
/// horizon.
const CORNER_MIN_COS: f32 = 0.95;

/// … and if it lies within this many corner spacings of it, in the atlas's mean texel size (a
/// diagonal corner is √2 spacings away; farther means the chart is stretched or folded there).
const CORNER_MAX_SPACINGS: f32 = 2.0;

/// Tiles of a chart's box are at most this many texels on a side (or the lattice step, if
/// larger): the coarsest lattice points on a tile's far edges inside the chart are cast again by
/// the next tile.
const TILE_TEXELS: u32 = 32;

/// Items evaluated in parallel before their results are added up in order: bounds the per-item
/// entry energies held at once to this many × entries × 12 bytes.
const ITEMS_PER_BATCH: usize = 64;

/// A work item of [`evaluate_atlas_panes`]: the texels of one chart inside one tile of the
/// chart's own bounding box. The lattice is anchored at the box's corner and includes the box's
/// far edges, so that every chart, however small, has lattice points at its own corners: with a
/// lattice over the whole atlas, a chart a few texels wide had most of its texels without a
/// corner on their chart, and they cast all their rays.
#[derive(Clone, Copy, Debug)]
struct Item {
    chart: u32,
    /// First texel.
    x0: u32,
    y0: u32,
    /// Last local coordinate in x and in y: the item's far edges.
    tx: u32,
    ty: u32,
    /// Whether the far edge is the chart's own last column (row), evaluated here, or the next
    /// item's first, evaluated here only for its answers as a corner.
    end_x: bool,
    end_y: bool,
    /// Lattice step of this item.
    step: u32,
}

/// The items of every chart of `atlas`, tiles of `tile` texels anchored at each chart's
/// bounding box, charts in order; lattice `step`, halved for a chart narrower than it (on
/// chairs, 913 charts: 55 M rays and 3.3 % from exact with `step` everywhere, 59 M and 2.7 %
/// halved below the step, 61 M and 2.5 % halved below twice the step).
fn items(atlas: &Atlas, tile: u32, step: u32) -> Vec<Item> {
    let res = atlas.resolution;
    let mut boxes: Vec<Option<[u32; 4]>> = Vec::new();
    for x in &atlas.exits {
        let c = atlas.chart_of_triangle[x.triangle as usize] as usize;
        if boxes.len() <= c {
            boxes.resize(c + 1, None);
        }
        let (tx, ty) = (x.texel % res, x.texel / res);
        let b = boxes[c].get_or_insert([tx, ty, tx, ty]);
        *b = [b[0].min(tx), b[1].min(ty), b[2].max(tx), b[3].max(ty)];
    }
    // Tiles of `[first, last]`: (start, far edge, far edge is `last`).
    let cut = |first: u32, last: u32| {
        let mut out = Vec::new();
        let mut o = first;
        loop {
            if last - o <= tile {
                out.push((o, last - o, true));
                return out;
            }
            out.push((o, tile, false));
            o += tile;
        }
    };
    let mut out = Vec::new();
    for (chart, b) in boxes.iter().enumerate() {
        let Some([bx0, by0, bx1, by1]) = *b else { continue };
        // A chart narrower than the step would have its coarse points at its two edges only.
        let item_step = if (bx1 - bx0).min(by1 - by0) < step {
            (step / 2).max(1)
        } else {
            step
        };
        for (y0, ty, end_y) in cut(by0, by1) {
            for &(x0, tx, end_x) in &cut(bx0, bx1) {
                out.push(Item {
                    chart: chart as u32,
                    x0,
                    y0,
                    tx,
                    ty,
                    end_x,
                    end_y,
                    step: item_step,
                });
            }
        }
    }
    out
}

/// The chart items of an atlas, evaluated coarse to fine.
struct Tiler<'a> {
    kernel: Kernel<'a>,
    atlas: &'a Atlas,
}

/// Visibility bits, per VPL word, of an item's lattice points that are corners of finer points:
/// which VPLs' visibility is known there, and which of those are visible.
struct CornerBits {
    words: usize,
    /// Points per row: the item's width plus its far edge.
    width: usize,
    known: Vec<u64>,
    vis: Vec<u64>,
}

impl CornerBits {
    /// Room for every point of `item` when it has lattices finer than its coarsest (none
    /// otherwise, as no point is then a corner).
    fn new(item: &Item, words: usize) -> CornerBits {
        let width = (item.tx + 1) as usize;
        let known = if item.step > 1 {
            vec![0u64; width * (item.ty + 1) as usize * words]
        } else {
            Vec::new()
        };
        CornerBits {
            words,
            width,
            vis: known.clone(),
            known,
        }
    }

    /// The first word of point `(x, y)`.
    fn slot(&self, x: u32, y: u32) -> usize {
        (y as usize * self.width + x as usize) * self.words
    }

    /// Point `(x, y)`'s bits (known, visible), for [`Kernel::sum_exit`] to record.
    fn at_mut(&mut self, x: u32, y: u32) -> (&mut [u64], &mut [u64]) {
        let at = self.slot(x, y);
        (&mut self.known[at..at + self.words], &mut self.vis[at..at + self.words])
    }

    /// Sets `seen` and `missed` to the VPLs that every one of `corners` knows it sees, and
    /// knows it misses.
    fn agree(&self, corners: impl Iterator<Item = (u32, u32)>, seen: &mut [u64], missed: &mut [u64]) {
        seen.fill(!0);
        missed.fill(!0);
        for (cx, cy) in corners {
            let at = self.slot(cx, cy);
            let (k, v) = (&self.known[at..at + self.words], &self.vis[at..at + self.words]);
            for w in 0..self.words {
                seen[w] &= k[w] & v[w];
                missed[w] &= k[w] & !v[w];
            }
        }
    }
}

/// The corners of point `(dx, dy)` of `item`, new on the lattice of spacing `h`: along an axis
/// where the point lies on the coarser lattice, its own coordinate; along the other, the
/// coarser points either side, `d − h` and `min(d + h, far edge)`.
fn corner_points(item: &Item, h: u32, (dx, dy): (u32, u32), (coarse_x, coarse_y): (bool, bool)) -> [(u32, u32); 4] {
    let xs = if coarse_x {
        [dx, dx]
    } else {
        [dx - h, (dx + h).min(item.tx)]
    };
    let ys = if coarse_y {
        [dy, dy]
    } else {
        [dy - h, (dy + h).min(item.ty)]
    };
    [(xs[0], ys[0]), (xs[1], ys[0]), (xs[0], ys[1]), (xs[1], ys[1])]
}

impl Tiler<'_> {
    /// Whether exit `c` may stand for exit `x` as a lattice corner `spacing` texels away.
    fn corner_fits(&self, x: &ExitPoint, c: &ExitPoint, spacing: u32) -> bool {
        let charts = &self.atlas.chart_of_triangle;
        let max_d = CORNER_MAX_SPACINGS * spacing as f32 * self.atlas.stats.texel_size;
        charts[x.triangle as usize] == charts[c.triangle as usize]
            && x.normal.dot(c.normal) >= CORNER_MIN_COS
            && x.position.distance(c.position) <= max_d
    }

    /// The exit at local point `(x, y)` of `item`, if the texel has one on the item's chart.
    fn exit_at(&self, item: &Item, x: u32, y: u32) -> Option<u32> {
        let res = self.atlas.resolution;
        let (gx, gy) = (item.x0 + x, item.y0 + y);
        (gx < res && gy < res)
            .then(|| self.atlas.texel_exit[(gy * res + gx) as usize])
            .filter(|&i| {
                i != EMPTY_TEXEL
                    && self.atlas.chart_of_triangle[self.atlas.exits[i as usize].triangle as usize] == item.chart
            })
    }

    /// Evaluates `item`: first the points of the coarsest lattice (every ray), then each finer
    /// lattice's new points from the corners around them on the coarser one. A lattice of
    /// spacing `h` is the multiples of `h` below the far edge, and the far edge itself; so a new
    /// point `d` (an odd multiple of `h`) has its corners at `d − h` and `min(d + h, far edge)`.
    fn evaluate_item(&self, item: &Item) -> WorkPanes {
        let s = item.step;
        let words = self.kernel.words();
        let c = self.kernel.clusters;
        let mut out = WorkPanes::new(self.kernel.entries);
        // Visibility bits of every point that is a corner of a finer one.
        let mut bits = CornerBits::new(item, words);
        let mut seen = vec![0u64; words];
        let mut missed = vec![0u64; words];
        let mut scratch = vec![Vec3::ZERO; c];
        let mut scratch_energy = vec![Vec3::ZERO; self.kernel.entries];
        let mut cache = self.kernel.occluder_cache();
        // The coordinates of the lattice of spacing `h` along an edge of length `far`.
        let lattice = |h: u32, far: u32| -> Vec<u32> { (0..far).step_by(h as usize).chain([far]).collect() };
        let on = |d: u32, h: u32, far: u32| d == far || d.is_multiple_of(h);
        let mut h = s;
        loop {
            let top = h == s;
            let (xs_h, ys_h) = (lattice(h, item.tx), lattice(h, item.ty));
            for &dy in &ys_h {
                for &dx in &xs_h {
                    let coarse = (on(dx, 2 * h, item.tx), on(dy, 2 * h, item.ty));
                    if !top && coarse.0 && coarse.1 {
                        continue;
                    }
                    let inside = (dx < item.tx || item.end_x) && (dy < item.ty || item.end_y);
                    // Far-edge points matter only as corners of finer points.
                    if !inside && h == 1 {
                        continue;
                    }
                    let Some(e) = self.exit_at(item, dx, dy) else { continue };
                    let exit = &self.atlas.exits[e as usize];
                    let corners = if top {
                        None
                    } else {
                        // Every corner must stand for the point; at chart borders and creases
                        // some do not, and the point casts its own rays. (Taking the corners
                        // that fit, if two or more do, saved 11 % of the rays on chairs and
                        // raised its difference from exact from 2.5 % to 3.3 %; at the finest
                        // spacing only, 8 % and 3.0 %, for no faster bake.)
                        let corners = corner_points(item, h, (dx, dy), coarse);
                        let fits = corners.iter().all(|&(cx, cy)| {
                            self.exit_at(item, cx, cy)
                                .is_some_and(|ce| self.corner_fits(exit, &self.atlas.exits[ce as usize], h))
                        });
                        fits.then(|| {
                            bits.agree(corners.into_iter(), &mut seen, &mut missed);
                            (seen.as_slice(), missed.as_slice())
                        })
                    };
                    let point_bits = (h > 1).then(|| bits.at_mut(dx, dy));
                    let (acc, entry_energy) = if inside {
                        let at = out.accs.len();
                        out.accs.resize(at + c, Vec3::ZERO);
                        out.exits.push(e);
                        (&mut out.accs[at..], &mut out.entry_energy[..])
                    } else {
                        scratch.fill(Vec3::ZERO);
                        (&mut scratch[..], &mut scratch_energy[..])
                    };
                    let sums = ExitSums {
                        acc,
                        entry_energy,
                        cache: &mut cache,
                        rays: &mut out.rays,
                    };
                    self.kernel.sum_exit(exit, corners, point_bits, sums);
                }
            }
            if h == 1 {
                break;
            }
            h /= 2;
        }
        out
    }
}

/// Evaluates every cluster's pane at every exit point of `atlas`, and every entry point's pane
/// energy, sharing shadow rays between neighbouring texels as `lattice` says (module docs).
/// `on_progress` is called on the calling thread with the number of exit points done so far.
pub fn evaluate_atlas_panes(
    bvh: &Bvh,
    vpls: &VplSet,
    clustering: &Clustering,
    atlas: &Atlas,
    params: &PaneParams,
    lattice: &Lattice,
    on_progress: &mut dyn FnMut(u64),
) -> Result<Panes, TraceError> {
    if !lattice.step.is_power_of_two() {
        return Err(TraceError::InvalidParameter(format!(
            "the lattice step must be a power of two, not {}",
            lattice.step
        )));
    }
    let tiler = Tiler {
        kernel: Kernel::new(bvh, vpls, clustering, params.bound)?,
        atlas,
    };
    let work = items(atlas, TILE_TEXELS.max(lattice.step), lattice.step);
    let mut panes = Panes::assembling(tiler.kernel.clusters, atlas.exits.len(), tiler.kernel.entries);
    let mut done = 0u64;
    for batch in work.chunks(ITEMS_PER_BATCH) {
        let outs: Vec<WorkPanes> = batch.par_iter().map(|item| tiler.evaluate_item(item)).collect();
        for out in outs {
            done += out.exits.len() as u64;
            panes.add(out);
        }
        on_progress(done);
    }
    Ok(panes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{sample_surface, trace_walks, BvhParams, ClusterParams, EntryParams, WalkParams};
    use prm_scene::{AtlasParams, Sizing};

    /// The kernel's unoccluded factors are [`VplBound::irradiance`]'s, for every bound.
    #[test]
    fn kernel_factors_are_the_bounds_irradiance() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box/cornell-box.obj");
        let scene = prm_scene::load(&path).unwrap();
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        let entries = sample_surface(&scene, &EntryParams { count: 16, seed: 2 }).unwrap();
        let walks = trace_walks(&scene, &bvh, &entries, &WalkParams::PREVIEW).unwrap();
        let clustering = Clustering::identity(&entries);
        let receivers = sample_surface(&scene, &EntryParams { count: 64, seed: 9 }).unwrap();
        for bound in [
            VplBound::None,
            VplBound::Clamp { min_distance: 0.05 },
            VplBound::DEFAULT,
            VplBound::Near { scale: 1.0 },
            VplBound::Near { scale: 3.0 },
        ] {
            let kernel = Kernel::new(&bvh, &walks, &clustering, bound).unwrap();
            for x in &receivers {
                let mut g = [0.0f32; BLOCK];
                for b in 0..kernel.words() {
                    kernel.block_factors(b, x.position, x.normal, &mut g);
                    for (j, v) in walks.vpls.iter().enumerate().skip(b * BLOCK).take(BLOCK) {
                        let want = bound.irradiance(v, x.position, x.normal);
                        let got = v.power * g[j - b * BLOCK];
                        assert!(
                            (got - want).abs().max_element() <= 1e-5 * want.abs().max_element().max(1e-3),
                            "{bound:?}: {got} against {want}"
                        );
                    }
                }
            }
        }
    }

    /// The AVX2 variant of the kernel gives the portable one's sums, bit for bit
    /// ([`crate::isa`]), at every exit point of the bundled Cornell box.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn instruction_set_variants_agree() {
        let Some(scene) = crate::isa::variant_test_scene() else {
            return;
        };
        let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(32))).unwrap();
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        let entries = sample_surface(&scene, &EntryParams { count: 128, seed: 5 }).unwrap();
        let walks = trace_walks(&scene, &bvh, &entries, &WalkParams::PREVIEW).unwrap();
        let clustering =
            Clustering::kmeans(&entries, scene.bounds().diagonal(), &ClusterParams::with_clusters(8)).unwrap();
        let kernel = Kernel::new(&bvh, &walks, &clustering, VplBound::DEFAULT).unwrap();
        let run = |avx2: bool| {
            let mut acc = vec![Vec3::ZERO; atlas.exits.len() * kernel.clusters];
            let mut energy = vec![Vec3::ZERO; kernel.entries];
            let mut cache = kernel.occluder_cache();
            let mut rays = 0;
            for (x, acc) in atlas.exits.iter().zip(acc.chunks_mut(kernel.clusters)) {
                let sums = ExitSums {
                    acc,
                    entry_energy: &mut energy,
                    cache: &mut cache,
                    rays: &mut rays,
                };
                if avx2 {
                    // SAFETY: `isa::avx2` said the CPU runs the variant.
                    unsafe { kernel.sum_exit_avx2(x, None, None, sums) };
                } else {
                    kernel.sum_exit_inline(x, None, None, sums);
                }
            }
            (acc, energy, rays)
        };
        let portable = run(false);
        assert!(portable.2 > 0 && portable.0.iter().any(|v| v.x > 0.0));
        assert!(portable == run(true), "the variants' sums differ");
    }
}
