//! Lightmap atlas: charts of connected, similarly oriented triangles, packed into one square
//!
//! Over 600 lines on purpose: charting, packing, conservative rasterisation and dilation share
//! the texel-grid invariants listed in ARCHITECTURE.md (no texel shared by two charts, gutters,
//! coverage of every triangle), which each step relies on the previous one to keep.
//! texture with gutters; every covered texel centre becomes an *exit point*.
//!
//! Steps: (1) charts by flood fill over shared edges while a triangle's normal stays within
//! [`AtlasParams::chart_angle_deg`] of the chart's seed; (2) each chart projected onto the plane
//! of its seed normal; (3) charts shelf-packed, each in a cell with `gutter` empty texels on every
//! side, so two charts are at least `2 × gutter` texels apart; (4) conservative rasterisation:
//! a texel belongs to the triangle that contains its centre or, failing that, lies nearest to it,
//! among the triangles that overlap it, and its exit point is the nearest point of that triangle;
//! triangles left without a texel take one from a neighbour that has several; (5) gutter texels
//! next to a chart copy their nearest covered texel (dilation), so bilinear filtering at chart
//! borders reads no black.
//!
//! When the scene brings lightmap UVs (glTF `TEXCOORD_1`) steps 1–3 are skipped and the file's
//! layout is rasterised as it is; its gutters are then the file's business.

use glam::{Vec2, Vec3};
use std::collections::HashMap;

use crate::{Scene, SceneError};

/// Marks a texel with no exit point in [`Atlas::texel_exit`].
pub const EMPTY_TEXEL: u32 = u32::MAX;

/// How big the atlas is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sizing {
    /// Derived from the scene: enough texels that every triangle can own several.
    Auto,
    /// Square atlas of this many texels on a side; the texel size follows.
    Resolution(u32),
    /// Texel edge length in scene units; the resolution follows.
    TexelSize(f32),
}

/// Atlas parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AtlasParams {
    /// How big the atlas is.
    pub sizing: Sizing,
    /// Empty texels on every side of a chart (two charts are at least twice this apart).
    pub gutter: u32,
    /// Largest angle between a triangle's normal and its chart's seed normal, degrees.
    pub chart_angle_deg: f32,
}

impl AtlasParams {
    /// Automatic size, 1-texel gutters per side (2 between charts), 44° charts.
    pub const DEFAULT: AtlasParams = AtlasParams {
        sizing: Sizing::Auto,
        gutter: 1,
        chart_angle_deg: 44.0,
    };

    /// The default parameters with the given sizing.
    pub fn with_sizing(sizing: Sizing) -> Self {
        AtlasParams {
            sizing,
            ..Self::DEFAULT
        }
    }
}

impl Default for AtlasParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The surface point behind one covered texel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExitPoint {
    /// Texel index, `y * resolution + x`.
    pub texel: u32,
    /// World position (on the owning triangle).
    pub position: Vec3,
    /// Unit shading normal.
    pub normal: Vec3,
    /// Diffuse albedo there (texture included).
    pub albedo: Vec3,
    /// Owning triangle.
    pub triangle: u32,
    /// Fraction of the texel's square covered by its chart's triangles, in (0, 1].
    pub coverage: f32,
}

/// Statistics for `prm-bake atlas`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct AtlasStats {
    /// Texels on a side.
    pub resolution: u32,
    /// Texel edge length in scene units (mean, for file-provided UVs).
    pub texel_size: f32,
    /// Number of charts.
    pub charts: u32,
    /// Covered texels / all texels.
    pub utilization: f32,
    /// Covered texels (exit points).
    pub covered_texels: u32,
    /// Gutter texels filled by dilation.
    pub dilated_texels: u32,
    /// Triangles whose lightmap footprint touches no covered texel (they would sample nothing).
    pub uncovered_triangles: u32,
    /// Triangles that touch covered texels but own none of their exit points (smaller than a
    /// texel, crowded by neighbours): they are lit by the neighbours' exit points nearby.
    pub triangles_without_exit: u32,
    /// Fewest texels owned by a triangle.
    pub texels_per_triangle_min: u32,
    /// Median texels owned by a triangle.
    pub texels_per_triangle_median: u32,
    /// Texels whose centre lies inside two triangles of one chart (a folded projection).
    pub overlapping_texels: u32,
    /// Texels touched by two different charts (0 for generated atlases).
    pub shared_texels: u32,
}

/// A lightmap atlas and its exit points.
#[derive(Clone, Debug)]
pub struct Atlas {
    /// Texels on a side (the atlas is square).
    pub resolution: u32,
    /// Lightmap UVs per triangle corner, in [0, 1] (texel `(x, y)` spans `[x, x+1]/resolution`).
    pub uvs: Vec<[Vec2; 3]>,
    /// Chart of every triangle.
    pub chart_of_triangle: Vec<u32>,
    /// Exit points, in texel order.
    pub exits: Vec<ExitPoint>,
    /// For every texel, its index in `exits` or [`EMPTY_TEXEL`].
    pub texel_exit: Vec<u32>,
    /// Gutter texels and the covered texel each copies: `(gutter texel, source texel)`.
    pub dilation: Vec<(u32, u32)>,
    /// Chart of every texel touched by a chart (covered or dilated), else [`EMPTY_TEXEL`].
    pub texel_chart: Vec<u32>,
    /// Statistics.
    pub stats: AtlasStats,
}

/// A chart during construction: its triangles and their projected corners (scene units).
struct Chart {
    triangles: Vec<u32>,
    corners: Vec<[Vec2; 3]>,
    min: Vec2,
    max: Vec2,
}

impl Atlas {
    /// The warning for triangles that touch no texel and so get no indirect light (`None` when
    /// every triangle touches one); `triangles` is the scene's count.
    pub fn coverage_warning(&self, triangles: usize) -> Option<String> {
        (self.stats.uncovered_triangles > 0).then(|| {
            format!(
                "{} of {triangles} triangles touch no lightmap texel (texel size {}): they get no indirect \
                 light; a smaller --texel-size or a larger --resolution gives them some",
                self.stats.uncovered_triangles, self.stats.texel_size
            )
        })
    }

    /// The surface area each exit point stands for, in scene units squared: the covered
    /// fraction of its texel at its owning triangle's scale (area over texels spanned).
    pub fn exit_areas(&self, scene: &Scene) -> Vec<f32> {
        let texels = (self.resolution as f32).powi(2);
        self.exits
            .iter()
            .map(|e| {
                let [a, b, c] = self.uvs[e.triangle as usize];
                let spanned = 0.5 * (b - a).perp_dot(c - a).abs() * texels;
                if spanned > 0.0 {
                    e.coverage * scene.triangles[e.triangle as usize].area() / spanned
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Builds the atlas of `scene`.
    pub fn build(scene: &Scene, params: &AtlasParams) -> Result<Atlas, SceneError> {
        if params.gutter > 64 {
            return Err(SceneError::Atlas(format!("gutter {} is over 64 texels", params.gutter)));
        }
        if let Sizing::Resolution(r) = params.sizing {
            if !(4..=16384).contains(&r) {
                return Err(SceneError::Atlas(format!("resolution {r} is outside 4..=16384")));
            }
        }
        if let Sizing::TexelSize(s) = params.sizing {
            if !(s.is_finite() && s > 0.0) {
                return Err(SceneError::Atlas(format!("texel size {s} must be a positive number")));
            }
        }
        match &scene.lightmap_uvs {
            Some(uvs) => Self::from_file_uvs(scene, uvs, params),
            None => Self::generate(scene, params),
        }
    }

    fn generate(scene: &Scene, params: &AtlasParams) -> Result<Atlas, SceneError> {
        let charts = make_charts(scene, params.chart_angle_deg.to_radians().cos());
        let g = params.gutter as f32;
        // Small charts are scaled up (boost 1) unless that costs the rest of the atlas more than
        // a fifth of its texel density (or, at a fixed texel size, a quarter more resolution);
        // then half, a quarter, and finally no boost.
        let plain = Lay { gutter: g, boost: 0.0 };
        let (resolution, scale, cells, lay) = match params.sizing {
            Sizing::TexelSize(s) => {
                let scale = 1.0 / s;
                let r0 = fit_resolution(&charts, scale, plain)?;
                let mut chosen = (r0, plain);
                for boost in [1.0, 0.5, 0.25] {
                    let lay = Lay { gutter: g, boost };
                    let r = fit_resolution(&charts, scale, lay)?;
                    if r as f32 <= 1.25 * r0 as f32 {
                        chosen = (r, lay);
                        break;
                    }
                }
                let (r, lay) = chosen;
                let cells = pack(&charts, scale, lay, r).expect("fit_resolution found a fitting size");
                (r, scale, cells, lay)
            }
            Sizing::Resolution(_) | Sizing::Auto => {
                let r = match params.sizing {
                    Sizing::Resolution(r) => r,
                    _ => auto_resolution(scene.triangles.len(), charts.len()),
                };
                let (s0, cells0) = fit_scale(&charts, plain, r)?;
                let mut chosen = (s0, cells0, plain);
                for boost in [1.0, 0.5, 0.25] {
                    let lay = Lay { gutter: g, boost };
                    if let Ok((s, cells)) = fit_scale(&charts, lay, r) {
                        if s >= 0.8 * s0 {
                            chosen = (s, cells, lay);
                            break;
                        }
                    }
                }
                let (s, cells, lay) = chosen;
                (r, s, cells, lay)
            }
        };
        let mut uvs = vec![[Vec2::ZERO; 3]; scene.triangles.len()];
        let mut chart_of_triangle = vec![0u32; scene.triangles.len()];
        for (ci, (chart, origin)) in charts.iter().zip(&cells).enumerate() {
            let cs = chart_scale(chart, scale, lay);
            let size = (chart.max - chart.min) * cs;
            // Centre the chart in its whole-texel footprint, `gutter` texels in from the cell edge.
            let pad = (footprint(chart, scale, lay) - size) * 0.5;
            let offset = *origin + Vec2::splat(g) + pad;
            for (&t, corners) in chart.triangles.iter().zip(&chart.corners) {
                uvs[t as usize] = corners.map(|c| ((c - chart.min) * cs + offset) / resolution as f32);
                chart_of_triangle[t as usize] = ci as u32;
            }
        }
        Ok(rasterize(
            scene,
            resolution,
            uvs,
            chart_of_triangle,
            charts.len() as u32,
            1.0 / scale,
            params.gutter,
        ))
    }

    fn from_file_uvs(scene: &Scene, file_uvs: &[[Vec2; 3]], params: &AtlasParams) -> Result<Atlas, SceneError> {
        if let Some(t) = file_uvs.iter().position(|c| c.iter().any(|u| !u.is_finite())) {
            return Err(SceneError::Atlas(format!(
                "lightmap UVs of triangle {t} are not finite"
            )));
        }
        let uv_area: f64 = file_uvs
            .iter()
            .map(|c| 0.5 * ((c[1] - c[0]).perp_dot(c[2] - c[0])).abs() as f64)
            .sum::<f64>()
            .max(1e-12);
        // Charts: triangles joined by edges whose two endpoints share position and lightmap UV.
        let chart_of_triangle = connected_components(scene, |t, c| (scene.triangles[t].positions[c], file_uvs[t][c]));
        let charts = chart_of_triangle.iter().max().map_or(0, |m| m + 1);
        let resolution = match params.sizing {
            Sizing::Resolution(r) => r,
            Sizing::TexelSize(s) => ((scene.area() / uv_area).sqrt() / s as f64).ceil().clamp(4.0, 16384.0) as u32,
            Sizing::Auto => auto_resolution(scene.triangles.len(), charts as usize),
        };
        let texel_size = ((scene.area() / uv_area).sqrt() / resolution as f64) as f32;
        Ok(rasterize(
            scene,
            resolution,
            file_uvs.to_vec(),
            chart_of_triangle,
            charts,
            texel_size,
            params.gutter,
        ))
    }

    /// World-space texel edge length.
    pub fn texel_size(&self) -> f32 {
        self.stats.texel_size
    }
}

/// Default resolution: about [`TEXELS_PER_TRIANGLE`] texels a triangle and
/// [`TEXELS_PER_CHART`] a chart, whichever asks more, rounded up to a multiple of 64 and clamped
/// to 128..=4096.
fn auto_resolution(triangles: usize, charts: usize) -> u32 {
    let texels = (TEXELS_PER_TRIANGLE * triangles as f64).max(TEXELS_PER_CHART * charts as f64);
    let r = (texels.sqrt() / 64.0).ceil() as u32 * 64;
    r.clamp(128, 4096)
}

/// Automatic atlas texels per triangle: enough that a scene's triangles each own exit points.
const TEXELS_PER_TRIANGLE: f64 = 12.0;

/// Automatic atlas texels per chart. A chart's gutters take texels from its interior, so many
/// small charts need more texels than their triangles do. Chosen by the error-against-bytes front
/// (`cargo xtask eval --full`, image error against the reference): the bundled chairs (913 charts,
/// 2910 triangles) lose from 0.058 at 256² to 0.098 at 128², while the Cornell boxes (15 and 38
/// charts) keep 0.046 and 0.040 at 128² for half the archive and a quarter of the pane rendering.
/// At 64 texels a chart, the chairs keep 256² and the boxes drop to 128², where McGuire's box
/// reads 2.7% and 2.5% under its two lights (`cargo xtask eval --targets`) against 2.2% and 1.9%
/// at 256².
const TEXELS_PER_CHART: f64 = 64.0;

/// Position key for adjacency: coordinates quantised to a grid fine enough to tell vertices apart.
fn quantise(p: Vec3, cell: f32) -> [i64; 3] {
    (p / cell).round().as_i64vec3().to_array()
}

/// Union of triangles over shared edges, where an edge's endpoints are keyed by `key(tri, corner)`.
fn connected_components(scene: &Scene, key: impl Fn(usize, usize) -> (Vec3, Vec2)) -> Vec<u32> {
    let cell = (scene.bounds().diagonal() * 1e-6).max(f32::MIN_POSITIVE);
    let n = scene.triangles.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let mut edges: HashMap<([i64; 5], [i64; 5]), u32> = HashMap::new();
    for t in 0..n {
        for c in 0..3 {
            let k = |c: usize| {
                let (p, uv) = key(t, c);
                let q = quantise(p, cell);
                let u = (uv * 1e6).round().as_i64vec2();
                [q[0], q[1], q[2], u.x, u.y]
            };
            let (a, b) = (k(c), k((c + 1) % 3));
            let e = if a < b { (a, b) } else { (b, a) };
            match edges.get(&e) {
                Some(&other) => {
                    let (ra, rb) = (find(&mut parent, t as u32), find(&mut parent, other));
                    parent[ra.max(rb) as usize] = ra.min(rb);
                }
                None => {
                    edges.insert(e, t as u32);
                }
            }
        }
    }
    // Renumber roots densely in order of first appearance.
    let mut ids = HashMap::new();
    (0..n as u32)
        .map(|t| {
            let r = find(&mut parent, t);
            let next = ids.len() as u32;
            *ids.entry(r).or_insert(next)
        })
        .collect()
}

/// Grows charts over shared edges from the largest unassigned triangle.
fn make_charts(scene: &Scene, cos_max: f32) -> Vec<Chart> {
    let tris = &scene.triangles;
    let cell = (scene.bounds().diagonal() * 1e-6).max(f32::MIN_POSITIVE);
    let mut edge_tris: HashMap<([i64; 3], [i64; 3]), Vec<u32>> = HashMap::new();
    for (t, tri) in tris.iter().enumerate() {
        for c in 0..3 {
            let a = quantise(tri.positions[c], cell);
            let b = quantise(tri.positions[(c + 1) % 3], cell);
            edge_tris
                .entry(if a < b { (a, b) } else { (b, a) })
                .or_default()
                .push(t as u32);
        }
    }
    let normals: Vec<Vec3> = tris.iter().map(|t| t.normal()).collect();
    let mut order: Vec<u32> = (0..tris.len() as u32).collect();
    order.sort_by(|&a, &b| {
        tris[b as usize]
            .area()
            .total_cmp(&tris[a as usize].area())
            .then(a.cmp(&b))
    });
    let mut assigned = vec![false; tris.len()];
    let mut charts = Vec::new();
    for &seed in &order {
        if assigned[seed as usize] {
            continue;
        }
        let n = normals[seed as usize];
        let mut members = vec![seed];
        assigned[seed as usize] = true;
        let mut i = 0;
        while i < members.len() {
            let t = members[i] as usize;
            i += 1;
            for c in 0..3 {
                let a = quantise(tris[t].positions[c], cell);
                let b = quantise(tris[t].positions[(c + 1) % 3], cell);
                for &o in &edge_tris[&if a < b { (a, b) } else { (b, a) }] {
                    if !assigned[o as usize] && normals[o as usize].dot(n) >= cos_max {
                        assigned[o as usize] = true;
                        members.push(o);
                    }
                }
            }
        }
        // Basis of the seed's plane: aligned with one of the first members' edges, the one that
        // gives the smallest bounding rectangle (rectangular walls then pack without waste).
        let project = |u: Vec3, v: Vec3| {
            let corners: Vec<[Vec2; 3]> = members
                .iter()
                .map(|&t| tris[t as usize].positions.map(|p| Vec2::new(p.dot(u), p.dot(v))))
                .collect();
            let (mut min, mut max) = (Vec2::INFINITY, Vec2::NEG_INFINITY);
            for c in corners.iter().flatten() {
                min = min.min(*c);
                max = max.max(*c);
            }
            (corners, min, max)
        };
        let mut best: Option<(Vec3, f32)> = None;
        for &t in members.iter().take(8) {
            let p = tris[t as usize].positions;
            for c in 0..3 {
                let e = p[(c + 1) % 3] - p[c];
                let u = (e - n * e.dot(n)).normalize_or_zero();
                if u == Vec3::ZERO {
                    continue;
                }
                let v = n.cross(u);
                let (mut lo, mut hi) = (Vec2::INFINITY, Vec2::NEG_INFINITY);
                for &m in &members {
                    for q in tris[m as usize].positions {
                        let x = Vec2::new(q.dot(u), q.dot(v));
                        lo = lo.min(x);
                        hi = hi.max(x);
                    }
                }
                let area = (hi - lo).x * (hi - lo).y;
                if best.is_none_or(|(_, a)| area < a) {
                    best = Some((u, area));
                }
            }
        }
        // (u, v, n) is right-handed, so projected triangles keep their winding.
        let u = best.map_or_else(|| n.any_orthonormal_pair().0, |(u, _)| u);
        let (corners, min, max) = project(u, n.cross(u));
        charts.push(Chart {
            triangles: members,
            corners,
            min,
            max,
        });
    }
    charts
}

/// Gutter (texels per side) and how strongly small charts are scaled up (0: not at all).
#[derive(Clone, Copy, Debug)]
struct Lay {
    gutter: f32,
    boost: f32,
}

/// Shortest side, in texels, that a chart of several triangles is scaled up to (at most
/// [`MAX_BOOST`] times), so that each of its triangles can own a texel centre: 2 texels, and
/// 2·√k for a chart of k triangles (a fan of k wedges needs a ring of texels around its hub).
fn min_chart_texels(triangles: usize) -> f32 {
    (2.0 * (triangles as f32).sqrt()).max(2.0)
}
/// Largest factor by which a small chart's texel density exceeds the atlas's.
const MAX_BOOST: f32 = 64.0;

/// Texels per scene unit for `chart` when the atlas has `scale`: small multi-triangle charts get
/// more, so that thin parts (chair legs, mouldings) keep one texel per triangle.
fn chart_scale(chart: &Chart, scale: f32, lay: Lay) -> f32 {
    let short = (chart.max - chart.min).min_element() * scale;
    let long = (chart.max - chart.min).max_element() * scale;
    let min = min_chart_texels(chart.triangles.len()) * lay.boost;
    if chart.triangles.len() < 2 || short >= min || lay.boost <= 0.0 {
        return scale;
    }
    // Slivers stop growing once their long side reaches four times the minimum.
    let boost = if short > 0.0 {
        (min / short).min(MAX_BOOST)
    } else {
        MAX_BOOST
    };
    let boost = if long > 0.0 {
        boost.min((4.0 * min / long).max(1.0))
    } else {
        boost
    };
    scale * boost
}

/// Size in texels of a chart's footprint (whole texels, at least one).
fn footprint(chart: &Chart, scale: f32, lay: Lay) -> Vec2 {
    ((chart.max - chart.min) * chart_scale(chart, scale, lay))
        .ceil()
        .max(Vec2::ONE)
}

/// Cell size of a chart in texels at `scale` texels per scene unit: footprint plus gutters.
fn cell_size(chart: &Chart, scale: f32, lay: Lay) -> Vec2 {
    footprint(chart, scale, lay) + Vec2::splat(2.0 * lay.gutter)
}

/// Shelf packing into a `r × r` square; the cell origin of every chart, or `None` when it overflows.
fn pack(charts: &[Chart], scale: f32, lay: Lay, r: u32) -> Option<Vec<Vec2>> {
    let sizes: Vec<Vec2> = charts.iter().map(|c| cell_size(c, scale, lay)).collect();
    let mut order: Vec<usize> = (0..charts.len()).collect();
    order.sort_by(|&a, &b| {
        sizes[b]
            .y
            .total_cmp(&sizes[a].y)
            .then(sizes[b].x.total_cmp(&sizes[a].x))
            .then(a.cmp(&b))
    });
    let r = r as f32;
    let mut origins = vec![Vec2::ZERO; charts.len()];
    let (mut x, mut y, mut shelf) = (0.0f32, 0.0f32, 0.0f32);
    for i in order {
        let s = sizes[i];
        if s.x > r {
            return None;
        }
        if x + s.x > r {
            y += shelf;
            x = 0.0;
            shelf = 0.0;
        }
        if y + s.y > r {
            return None;
        }
        origins[i] = Vec2::new(x, y);
        x += s.x;
        shelf = shelf.max(s.y);
    }
    Some(origins)
}

/// The largest scale (texels per scene unit) whose packing fits `r × r`.
fn fit_scale(charts: &[Chart], lay: Lay, r: u32) -> Result<(f32, Vec<Vec2>), SceneError> {
    let g = lay.gutter;
    let Some(mut best) = pack(charts, 0.0, lay, r) else {
        let min_side = ((charts.len() as f64).sqrt() * (1.0 + 2.0 * g as f64)).ceil();
        return Err(SceneError::Atlas(format!(
            "resolution {r} cannot hold {} charts even at one texel each (with gutters); use a resolution of at least about {min_side}",
            charts.len()
        )));
    };
    let area: f64 = charts
        .iter()
        .map(|c| ((c.max - c.min).x * (c.max - c.min).y) as f64)
        .sum();
    let longest = charts
        .iter()
        .map(|c| (c.max - c.min).max_element())
        .fold(0.0f32, f32::max);
    let (mut lo, mut hi) = (
        0.0f32,
        (r as f32 / longest).min((r as f64 / area.max(1e-30).sqrt()) as f32 * 1.01),
    );
    if !hi.is_finite() || hi <= 0.0 {
        hi = r as f32;
    }
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        match pack(charts, mid, lay, r) {
            Some(cells) => {
                lo = mid;
                best = cells;
            }
            None => hi = mid,
        }
    }
    if lo <= 0.0 {
        return Err(SceneError::Atlas(format!(
            "resolution {r} is too small to give the charts any size"
        )));
    }
    Ok((lo, best))
}

/// The smallest multiple-of-8 resolution whose packing at `scale` fits.
fn fit_resolution(charts: &[Chart], scale: f32, lay: Lay) -> Result<u32, SceneError> {
    let area: f64 = charts
        .iter()
        .map(|c| (cell_size(c, scale, lay).x * cell_size(c, scale, lay).y) as f64)
        .sum();
    let mut r = ((area.sqrt() / 8.0).ceil() as u32 * 8).max(8);
    loop {
        if r > 16384 {
            return Err(SceneError::Atlas(format!(
                "texel size {} needs an atlas larger than 16384² texels; choose a larger texel size",
                1.0 / scale
            )));
        }
        if pack(charts, scale, lay, r).is_some() {
            return Ok(r);
        }
        r = ((r as f32 * 1.03) as u32 / 8 + 1) * 8;
    }
}

/// Barycentric coordinates `(b0, b1, b2)` of `p` in the 2D triangle `t` (for example its corners'
/// lightmap UVs in texels), negative outside it; `None` for a degenerate triangle.
pub fn barycentric(t: &[Vec2; 3], p: Vec2) -> Option<(f32, f32, f32)> {
    let d = (t[1] - t[0]).perp_dot(t[2] - t[0]);
    if d == 0.0 || !d.is_finite() {
        return None;
    }
    let b1 = (p - t[0]).perp_dot(t[2] - t[0]) / d;
    let b2 = (t[1] - t[0]).perp_dot(p - t[0]) / d;
    Some((1.0 - b1 - b2, b1, b2))
}

/// Nearest point of 2D triangle `t` to `p`, as barycentric `(b1, b2)`, and its distance.
fn nearest_on_triangle(t: &[Vec2; 3], p: Vec2) -> (f32, f32, f32) {
    if let Some((b0, b1, b2)) = barycentric(t, p) {
        if b0 >= 0.0 && b1 >= 0.0 && b2 >= 0.0 {
            return (b1, b2, 0.0);
        }
    }
    let mut best = (0.0, 0.0, f32::INFINITY);
    for i in 0..3 {
        let (a, b) = (t[i], t[(i + 1) % 3]);
        let ab = b - a;
        let s = if ab.length_squared() > 0.0 {
            ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = (a + ab * s).distance(p);
        if d < best.2 {
            // Barycentric weights of corners i and i+1 are (1-s, s).
            let mut w = [0.0f32; 3];
            w[i] = 1.0 - s;
            w[(i + 1) % 3] = s;
            best = (w[1], w[2], d);
        }
    }
    best
}

/// Sub-samples per texel side used to estimate how much of a texel a triangle covers.
const SUB: usize = 4;

/// The `SUB × SUB` sub-sample points of texel `(x, y)` that lie in 2D triangle `t`, row by row.
fn covered_subsamples(t: &[Vec2; 3], x: usize, y: usize) -> impl Iterator<Item = Vec2> + '_ {
    (0..SUB)
        .flat_map(move |sy| {
            (0..SUB).map(move |sx| {
                Vec2::new(
                    x as f32 + (sx as f32 + 0.5) / SUB as f32,
                    y as f32 + (sy as f32 + 0.5) / SUB as f32,
                )
            })
        })
        .filter(move |&p| barycentric(t, p).is_some_and(|(a, b, c)| a >= 0.0 && b >= 0.0 && c >= 0.0))
}

/// The fraction of texel `(x, y)` that 2D triangle `t` covers, from its sub-samples.
fn subsample_coverage(t: &[Vec2; 3], x: usize, y: usize) -> f32 {
    covered_subsamples(t, x, y).count() as f32 / (SUB * SUB) as f32
}

/// Barycentric `(b1, b2)` of the centroid of the sub-samples of texel `(x, y)` that lie in
/// 2D triangle `t`; `None` when none does.
fn covered_centroid(t: &[Vec2; 3], x: usize, y: usize) -> Option<(f32, f32)> {
    let (mut sum, mut n) = (Vec2::ZERO, 0);
    for p in covered_subsamples(t, x, y) {
        sum += p;
        n += 1;
    }
    if n == 0 {
        return None;
    }
    // The centroid of points inside a triangle is inside it (convexity).
    barycentric(t, sum / n as f32).map(|(_, b1, b2)| (b1.max(0.0), b2.max(0.0)))
}

/// Whether `p` lies inside 2D triangle `t`, away from its edges.
fn strictly_inside(t: &[Vec2; 3], p: Vec2) -> bool {
    barycentric(t, p).is_some_and(|(a, b, c)| a.min(b).min(c) > 1e-5)
}

/// Whether 2D triangle `t` overlaps the axis-aligned unit square at `(x, y)` (separating axes).
fn overlaps_texel(t: &[Vec2; 3], x: f32, y: f32) -> bool {
    let (min, max) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
    if min.x >= x + 1.0 || max.x <= x || min.y >= y + 1.0 || max.y <= y {
        return false;
    }
    let square = [
        Vec2::new(x, y),
        Vec2::new(x + 1.0, y),
        Vec2::new(x, y + 1.0),
        Vec2::new(x + 1.0, y + 1.0),
    ];
    for i in 0..3 {
        let e = t[(i + 1) % 3] - t[i];
        let axis = Vec2::new(-e.y, e.x);
        if axis == Vec2::ZERO {
            // A collapsed edge separates nothing.
            continue;
        }
        let tri_proj = t.map(|p| p.dot(axis));
        let (tmin, tmax) = (
            tri_proj.iter().copied().fold(f32::INFINITY, f32::min),
            tri_proj.iter().copied().fold(f32::NEG_INFINITY, f32::max),
        );
        let sq = square.map(|p| p.dot(axis));
        let (smin, smax) = (
            sq.iter().copied().fold(f32::INFINITY, f32::min),
            sq.iter().copied().fold(f32::NEG_INFINITY, f32::max),
        );
        if smin >= tmax || smax <= tmin {
            return false;
        }
    }
    true
}

/// A texel's owning triangle: its index, its distance to the texel centre and the barycentric
/// coordinates `(b1, b2)` of its point nearest that centre.
type Owner = (u32, f32, f32, f32);

/// The texel grid being rasterised: what each texel holds so far.
struct Raster {
    /// Texels per side.
    r: usize,
    owner: Vec<Owner>,
    /// Whether the texel centre lies strictly inside its owner (not on a shared edge): two such
    /// owners for one texel mean the chart folds over itself.
    owner_strict: Vec<bool>,
    /// Summed fraction of the texel covered by the triangles that overlap it.
    coverage: Vec<f32>,
    texel_chart: Vec<u32>,
    /// Per triangle: whether it overlaps any texel.
    touches: Vec<bool>,
    /// Texels overlapped by two charts.
    shared: u32,
    /// Texels whose centre lies strictly inside two triangles.
    overlapping: u32,
}

/// Rasterises the triangles at their lightmap UVs into exit points, then dilates into the gutters.
fn rasterize(
    scene: &Scene,
    resolution: u32,
    uvs: Vec<[Vec2; 3]>,
    chart_of_triangle: Vec<u32>,
    charts: u32,
    texel_size: f32,
    gutter: u32,
) -> Atlas {
    let mut raster = Raster::new(resolution, uvs.len());
    for (t, uv) in uvs.iter().enumerate() {
        raster.draw_triangle(t, uv, chart_of_triangle[t]);
    }
    let (owned, without_exit) = raster.give_every_triangle_a_texel(&uvs);
    let (exits, texel_exit) = raster.exit_points(scene, &uvs);
    let dilation = raster.dilate(&texel_exit, gutter);

    let r = raster.r;
    let mut counts: Vec<u32> = owned;
    counts.sort_unstable();
    let stats = AtlasStats {
        resolution,
        texel_size,
        charts,
        utilization: exits.len() as f32 / (r * r) as f32,
        covered_texels: exits.len() as u32,
        dilated_texels: dilation.len() as u32,
        uncovered_triangles: raster.touches.iter().filter(|&&t| !t).count() as u32,
        triangles_without_exit: without_exit,
        texels_per_triangle_min: counts.first().copied().unwrap_or(0),
        texels_per_triangle_median: counts.get(counts.len() / 2).copied().unwrap_or(0),
        overlapping_texels: raster.overlapping,
        shared_texels: raster.shared,
    };
    Atlas {
        resolution,
        uvs,
        chart_of_triangle,
        exits,
        texel_exit,
        dilation,
        texel_chart: raster.texel_chart,
        stats,
    }
}

impl Raster {
    /// An empty grid of `resolution²` texels for `triangles` triangles.
    fn new(resolution: u32, triangles: usize) -> Raster {
        let r = resolution as usize;
        Raster {
            r,
            owner: vec![(EMPTY_TEXEL, f32::INFINITY, 0.0f32, 0.0f32); r * r],
            owner_strict: vec![false; r * r],
            coverage: vec![0.0f32; r * r],
            texel_chart: vec![EMPTY_TEXEL; r * r],
            touches: vec![false; triangles],
            shared: 0,
            overlapping: 0,
        }
    }

    /// UVs scaled to texel units.
    fn texel_space(&self, uv: &[Vec2; 3]) -> [Vec2; 3] {
        let rf = self.r as f32;
        uv.map(|u| u * rf)
    }

    /// Draws triangle `t` of chart `chart`: every texel it overlaps records the chart, gains
    /// its coverage, and takes it as owner when it lies nearer the centre than the owner so far
    /// (or strictly contains the centre where the owner so far does not).
    fn draw_triangle(&mut self, t: usize, uv: &[Vec2; 3], chart: u32) {
        let (r, rf) = (self.r, self.r as f32);
        let tex = self.texel_space(uv);
        let (min, max) = (tex[0].min(tex[1]).min(tex[2]), tex[0].max(tex[1]).max(tex[2]));
        let x0 = (min.x.floor().max(0.0)) as usize;
        let y0 = (min.y.floor().max(0.0)) as usize;
        let x1 = (max.x.ceil().min(rf) as usize).max(x0 + 1).min(r);
        let y1 = (max.y.ceil().min(rf) as usize).max(y0 + 1).min(r);
        for y in y0..y1 {
            for x in x0..x1 {
                if !overlaps_texel(&tex, x as f32, y as f32) {
                    continue;
                }
                let i = y * r + x;
                self.touches[t] = true;
                if self.texel_chart[i] != EMPTY_TEXEL && self.texel_chart[i] != chart {
                    self.shared += 1;
                }
                self.texel_chart[i] = chart;
                let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let (b1, b2, d) = nearest_on_triangle(&tex, centre);
                let strict = d == 0.0 && strictly_inside(&tex, centre);
                if strict && self.owner_strict[i] {
                    self.overlapping += 1;
                }
                if d < self.owner[i].1 || (strict && !self.owner_strict[i]) {
                    self.owner[i] = (t as u32, d, b1, b2);
                    self.owner_strict[i] = strict;
                }
                self.coverage[i] += subsample_coverage(&tex, x, y);
            }
        }
    }

    /// Triangles that lost every texel take one they overlap from an owner that has several.
    /// Returns the texels each triangle owns and how many triangles still own none.
    fn give_every_triangle_a_texel(&mut self, uvs: &[[Vec2; 3]]) -> (Vec<u32>, u32) {
        let (r, rf) = (self.r, self.r as f32);
        let owner = &mut self.owner;
        let mut owned = vec![0u32; uvs.len()];
        for o in owner.iter() {
            if o.0 != EMPTY_TEXEL {
                owned[o.0 as usize] += 1;
            }
        }
        let mut without_exit = 0u32;
        for t in 0..uvs.len() {
            if owned[t] > 0 {
                continue;
            }
            let tex = uvs[t].map(|u| u * rf);
            let (min, max) = (tex[0].min(tex[1]).min(tex[2]), tex[0].max(tex[1]).max(tex[2]));
            let mut best: Option<(usize, u32)> = None;
            for y in (min.y.floor().max(0.0) as usize)..(max.y.ceil().min(rf) as usize).max(1) {
                for x in (min.x.floor().max(0.0) as usize)..(max.x.ceil().min(rf) as usize).max(1) {
                    let i = y * r + x;
                    if i >= owner.len() || !overlaps_texel(&tex, x as f32, y as f32) {
                        continue;
                    }
                    let holder = owner[i].0;
                    if holder != EMPTY_TEXEL
                        && owned[holder as usize] > 1
                        && best.is_none_or(|(_, n)| owned[holder as usize] > n)
                    {
                        best = Some((i, owned[holder as usize]));
                    }
                }
            }
            match best {
                Some((i, _)) => {
                    owned[owner[i].0 as usize] -= 1;
                    let (x, y) = ((i % r) as f32, (i / r) as f32);
                    let (b1, b2, d) = nearest_on_triangle(&tex, Vec2::new(x + 0.5, y + 0.5));
                    owner[i] = (t as u32, d, b1, b2);
                    owned[t] = 1;
                }
                None => without_exit += 1,
            }
        }
        (owned, without_exit)
    }

    /// One exit point per owned texel, and each texel's exit index (`EMPTY_TEXEL` where none).
    fn exit_points(&self, scene: &Scene, uvs: &[[Vec2; 3]]) -> (Vec<ExitPoint>, Vec<u32>) {
        let r = self.r;
        let mut exits = Vec::new();
        let mut texel_exit = vec![EMPTY_TEXEL; r * r];
        for (i, &(t, _, b1, b2)) in self.owner.iter().enumerate() {
            if t == EMPTY_TEXEL {
                continue;
            }
            let tri = &scene.triangles[t as usize];
            // The exit point is the centroid of the part of the texel its triangle covers (the
            // texel centre when it covers it all). A point on the triangle's boundary instead
            // would sit exactly in a concave edge, where half the surroundings meet it at
            // grazing angles.
            let (b1, b2) = covered_centroid(&self.texel_space(&uvs[t as usize]), i % r, i / r).unwrap_or((b1, b2));
            texel_exit[i] = exits.len() as u32;
            exits.push(ExitPoint {
                texel: i as u32,
                position: tri.point(b1, b2),
                normal: tri.shading_normal(b1, b2),
                albedo: scene.albedo(t as usize, b1, b2),
                triangle: t,
                coverage: self.coverage[i].clamp(1.0 / (SUB * SUB) as f32, 1.0),
            });
        }
        (exits, texel_exit)
    }

    /// Dilation: `max(gutter, 1)` rings; each empty texel copies a filled 8-neighbour's source
    /// (and chart). Returns `(texel, source texel)` pairs in the order they were filled.
    fn dilate(&mut self, texel_exit: &[u32], gutter: u32) -> Vec<(u32, u32)> {
        let r = self.r;
        let mut source: Vec<u32> = (0..(r * r) as u32)
            .map(|i| {
                if texel_exit[i as usize] != EMPTY_TEXEL {
                    i
                } else {
                    EMPTY_TEXEL
                }
            })
            .collect();
        let mut dilation = Vec::new();
        for _ in 0..gutter.max(1) {
            let mut ring = Vec::new();
            for y in 0..r {
                for x in 0..r {
                    let i = y * r + x;
                    if source[i] != EMPTY_TEXEL {
                        continue;
                    }
                    'n: for (dx, dy) in [
                        (-1i64, 0i64),
                        (1, 0),
                        (0, -1),
                        (0, 1),
                        (-1, -1),
                        (1, -1),
                        (-1, 1),
                        (1, 1),
                    ] {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        if nx < 0 || ny < 0 || nx >= r as i64 || ny >= r as i64 {
                            continue;
                        }
                        let n = ny as usize * r + nx as usize;
                        if source[n] != EMPTY_TEXEL {
                            ring.push((i, source[n], self.texel_chart[n]));
                            break 'n;
                        }
                    }
                }
            }
            for (i, s, c) in ring {
                source[i] = s;
                self.texel_chart[i] = c;
                dilation.push((i as u32, s));
            }
        }
        dilation
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texel_overlap_is_conservative_and_exact_at_edges() {
        let t = [Vec2::new(0.1, 0.1), Vec2::new(0.3, 0.1), Vec2::new(0.1, 0.3)];
        assert!(overlaps_texel(&t, 0.0, 0.0));
        assert!(!overlaps_texel(&t, 1.0, 0.0));
        // A thin diagonal sliver crosses the texel's corner region but not the texel at (1, 1).
        let s = [Vec2::new(0.0, 0.0), Vec2::new(2.0, 0.0), Vec2::new(0.0, 1.9)];
        assert!(!overlaps_texel(&s, 1.0, 1.0));
        assert!(overlaps_texel(&s, 1.0, 0.0));
    }

    #[test]
    fn nearest_point_inside_and_outside() {
        let t = [Vec2::ZERO, Vec2::new(1.0, 0.0), Vec2::new(0.0, 1.0)];
        let (b1, b2, d) = nearest_on_triangle(&t, Vec2::new(0.25, 0.25));
        assert_eq!(d, 0.0);
        assert!((b1 - 0.25).abs() < 1e-6 && (b2 - 0.25).abs() < 1e-6);
        let (b1, b2, d) = nearest_on_triangle(&t, Vec2::new(0.5, -1.0));
        assert!((d - 1.0).abs() < 1e-6 && (b1 - 0.5).abs() < 1e-6 && b2 == 0.0);
    }

    #[test]
    fn exit_areas_sum_to_the_surface() {
        let scene = crate::analytic::furnace_box(2, 0.5);
        for resolution in [32, 75] {
            let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(resolution))).unwrap();
            let areas = atlas.exit_areas(&scene);
            assert_eq!(areas.len(), atlas.exits.len());
            let sum: f64 = areas.iter().map(|&a| f64::from(a)).sum();
            let ratio = sum / scene.area();
            assert!((ratio - 1.0).abs() < 0.02, "{resolution}²: {ratio}");
        }
    }

    #[test]
    fn auto_resolution_grows_with_triangles_and_charts() {
        assert_eq!(auto_resolution(36, 16), 128);
        assert_eq!(auto_resolution(2910, 913), 256);
        assert_eq!(auto_resolution(2188, 38), 192);
        assert_eq!(auto_resolution(100_000, 3000), 1152);
        assert_eq!(auto_resolution(10_000, 20_000), 1152);
        assert_eq!(auto_resolution(10_000_000, 1), 4096);
    }
}
