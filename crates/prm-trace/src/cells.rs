//! Entry cells: the surface every entry point stands for, as points, and the irradiance an
//! entry point takes from its whole cell (prm-format's `EntryCells`, formats/prm.md §5.7).
//!
//! The entry points are area-uniform but not evenly spaced: a lamp 0.4 m under Sponza's arcade
//! ceiling finds 3 entry points within 1 m where the area there stands for 5 of them, and 6 by a
//! column where it stands for 3.7. Weighed by their own irradiance, the entry points then carry
//! 45% too little of the light within 1 m of the first lamp and 11% too much by the second.
//! Weighed by their cells, they carry what the surface receives, whatever their spacing.
//! A light farther than [`prm_scene::CELL_NEAR_RADII`] varies too little over a cell to need
//! its points, and is taken at the entry point times the cell's area ([`cell_irradiance`]).

use glam::Vec3;
use prm_format::{CellPoint, EntryCells};
use prm_scene::{Light, Scene};
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::error::TraceError;
use crate::sampling::{sample_surface, EntryParams, SurfaceSample};

/// Points sampled per entry point for the cells.
///
/// Measured on the lamps of `cargo xtask eval --lamps` (6 lamps near a ceiling or wall in
/// Sponza, Sibenik and the modern hall, 6 positions each, the default bakes played by the CPU
/// player, each point given to its nearest entry point and every light summed over the cells):
/// each lamp's mean energy lay within 0.920–1.145 at 8 points, 0.945–1.070 at 16,
/// 0.965–1.034 at 32 and 0.962–1.046 at 64, and the errors at 32 and 64 within 0.2 points.
pub const CELL_POINTS_PER_ENTRY: usize = 32;

/// How far apart in normal a point and an entry point count, in units of the entry points'
/// radius² `A/(Nπ)` per unit of `1 − cos`: a point goes to the entry point nearest by
/// `d² + CELL_NORMAL_COST · A/(Nπ) · (1 − n·nₑ)`, so a cell keeps to its own face of a corner.
/// On the same lamps at 16 points, without it (0) the mean errors were 0.3–6.0 points worse
/// (Sponza's ceiling lamp 23.9% against 17.9%); 16 gave what 4 gives within 0.2 points.
pub const CELL_NORMAL_COST: f32 = 4.0;

/// The cells of the entry points `entries` on `scene` (its BVH `bvh`): `N ×`
/// [`CELL_POINTS_PER_ENTRY`] area-uniform points of seed `seed`, each given to the nearest
/// entry point (by [`CELL_NORMAL_COST`]) that it sees from the front of its surface, in the
/// entries' order. A point sees none of its [`CELL_CANDIDATES`] nearest where it lies behind
/// other geometry (under a lamp's shade flush with a ceiling, inside a wall); it then goes to
/// the nearest, which such geometry shades as it shades the point.
pub fn entry_cells(scene: &Scene, bvh: &Bvh, entries: &[SurfaceSample], seed: u64) -> Result<EntryCells, TraceError> {
    let n = entries.len();
    if n == 0 {
        return Err(TraceError::InvalidParameter("entry cells need entry points".into()));
    }
    let count = n * CELL_POINTS_PER_ENTRY;
    let samples = sample_surface(scene, &EntryParams { count, seed })?;
    let radius2 = (scene.area() / n as f64 / std::f64::consts::PI) as f32;
    let grid = EntryGrid::new(entries, 2.0 * radius2.sqrt());
    let owners: Vec<u32> = samples
        .par_iter()
        .map(|s| {
            let near = grid.nearest(entries, s, CELL_NORMAL_COST * radius2);
            let sees = |&i: &u32| front_visible(bvh, s, &entries[i as usize]);
            near.iter().copied().find(|i| sees(i)).unwrap_or(near[0])
        })
        .collect();
    // Counting sort by owner, keeping the sampling order within a cell.
    let mut ends = vec![0u32; n];
    for &o in &owners {
        ends[o as usize] += 1;
    }
    let mut next: Vec<u32> = Vec::with_capacity(n);
    let mut acc = 0u32;
    for e in &mut ends {
        next.push(acc);
        acc += *e;
        *e = acc;
    }
    let mut points = vec![CellPoint::default(); count];
    for (s, &o) in samples.iter().zip(&owners) {
        let offset = (s.position - entries[o as usize].position).to_array();
        let p = CellPoint::new(offset, s.normal.to_array()).ok_or_else(|| {
            TraceError::InvalidParameter(format!(
                "a cell point {offset:?} from its entry point is beyond f16's range"
            ))
        })?;
        points[next[o as usize] as usize] = p;
        next[o as usize] += 1;
    }
    Ok(EntryCells { ends, points })
}

/// Nearest entry points a cell point tries, in order, for one it sees.
pub const CELL_CANDIDATES: usize = 8;

/// Whether the point `s` and the entry point `e` see each other from the front of their
/// surfaces: the segment between them, each lifted off its surface along its own normal, meets
/// nothing, their own triangles included. A point on a ceiling hidden behind a shade flush with
/// it does not see the shade's entry points, nor a point of the shade the ceiling's hidden ones.
fn front_visible(bvh: &Bvh, s: &SurfaceSample, e: &SurfaceSample) -> bool {
    let eps = bvh.epsilon();
    let o = s.position + s.normal * eps;
    let v = (e.position + e.normal * eps) - o;
    let len = v.length();
    if len.is_nan() || len <= 0.0 {
        return true;
    }
    !bvh.occluded(o, v / len, len, [u32::MAX, u32::MAX])
}

/// The cells of [`entry_cells`] with the entries reordered: entry `k` of the result is entry
/// `order[k]` of `cells`.
pub fn reorder_cells(cells: &EntryCells, order: &[u32]) -> EntryCells {
    let mut out = EntryCells {
        ends: Vec::with_capacity(order.len()),
        points: Vec::with_capacity(cells.points.len()),
    };
    for &i in order {
        out.points.extend_from_slice(cells.points_of(i as usize));
        out.ends.push(out.points.len() as u32);
    }
    out
}

/// Every entry point's irradiance from its cell under `lights`, the entry points at
/// `positions` with unit normals `normals`: a point or spot light within `√reach2`
/// ([`prm_scene::cell_reach2`]) summed over the cell's points (shadow rays), `N/M · Σ E(p)`; any other
/// light at the entry point, times the cell's area, `|cell| · N/M · E(entry)`.
pub fn cell_irradiance(
    bvh: &Bvh,
    lights: &[Light],
    positions: &[Vec3],
    normals: &[Vec3],
    cells: &EntryCells,
    reach2: f32,
) -> Vec<Vec3> {
    let w = cells.point_weight();
    (0..positions.len())
        .into_par_iter()
        .map(|i| {
            let (at, n) = (positions[i], normals[i]);
            let points = cells.points_of(i);
            let mut sum = Vec3::ZERO;
            for light in lights {
                let near = light_position(light).is_some_and(|p| p.distance_squared(at) < reach2);
                let one = std::slice::from_ref(light);
                if near {
                    for p in points {
                        let pn = Vec3::from(p.normal());
                        sum += crate::direct_irradiance(bvh, one, at + Vec3::from(p.offset()), pn, pn, u32::MAX) * w;
                    }
                } else {
                    sum += crate::direct_irradiance(bvh, one, at, n, n, u32::MAX) * (points.len() as f32 * w);
                }
            }
            sum
        })
        .collect()
}

/// Where a point, spot or rectangular spot light is (None for a directional one).
fn light_position(light: &Light) -> Option<Vec3> {
    match *light {
        Light::Point { position, .. } | Light::Spot { position, .. } | Light::Rect { position, .. } => Some(position),
        Light::Directional { .. } => None,
    }
}

/// Entry points in a uniform grid, for the nearest ones to a point.
struct EntryGrid {
    cell: f32,
    cells: std::collections::HashMap<[i32; 3], Vec<u32>>,
}

impl EntryGrid {
    fn new(entries: &[SurfaceSample], cell: f32) -> EntryGrid {
        let mut grid = EntryGrid {
            cell: cell.max(f32::MIN_POSITIVE),
            cells: Default::default(),
        };
        for (i, e) in entries.iter().enumerate() {
            grid.cells.entry(grid.key(e.position)).or_default().push(i as u32);
        }
        grid
    }

    fn key(&self, p: Vec3) -> [i32; 3] {
        (p / self.cell).floor().as_ivec3().to_array()
    }

    /// The [`CELL_CANDIDATES`] entry points nearest to `s` by `d² + cost · (1 − n·nₑ)`, nearest
    /// first (at least one): ring by ring of grid cells until a ring cannot hold a nearer one,
    /// else over every entry point.
    fn nearest(&self, entries: &[SurfaceSample], s: &SurfaceSample, cost: f32) -> Vec<u32> {
        let score = |i: u32| {
            let e = &entries[i as usize];
            (s.position - e.position).length_squared() + cost * (1.0 - s.normal.dot(e.normal))
        };
        let mut best: Vec<(f32, u32)> = Vec::with_capacity(CELL_CANDIDATES + 1);
        let offer = |best: &mut Vec<(f32, u32)>, i: u32| {
            let c = (score(i), i);
            let at = best.partition_point(|b| b.0 < c.0 || (b.0 == c.0 && b.1 < c.1));
            if at < CELL_CANDIDATES {
                best.insert(at, c);
                best.truncate(CELL_CANDIDATES);
            }
        };
        let k = self.key(s.position);
        for ring in 0..8i32 {
            for dx in -ring..=ring {
                for dy in -ring..=ring {
                    for dz in -ring..=ring {
                        if dx.abs().max(dy.abs()).max(dz.abs()) != ring {
                            continue;
                        }
                        for &i in self.cells.get(&[k[0] + dx, k[1] + dy, k[2] + dz]).into_iter().flatten() {
                            offer(&mut best, i);
                        }
                    }
                }
            }
            // Every entry point outside rings 0..=ring is farther than `ring` cells.
            let reach = ring as f32 * self.cell;
            if best.len() == CELL_CANDIDATES && best[CELL_CANDIDATES - 1].0 <= reach * reach {
                return best.iter().map(|b| b.1).collect();
            }
        }
        best.clear();
        (0..entries.len() as u32).for_each(|i| offer(&mut best, i));
        best.iter().map(|b| b.1).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BvhParams;

    /// A floor 10 × 10 at y = 0 and a wall 10 × 5 at z = −5, facing the room.
    fn room() -> Scene {
        let f = [
            Vec3::new(-5.0, 0.0, -5.0),
            Vec3::new(-5.0, 0.0, 5.0),
            Vec3::new(5.0, 0.0, 5.0),
            Vec3::new(5.0, 0.0, -5.0),
        ];
        let w = [
            Vec3::new(-5.0, 0.0, -5.0),
            Vec3::new(5.0, 0.0, -5.0),
            Vec3::new(5.0, 5.0, -5.0),
            Vec3::new(-5.0, 5.0, -5.0),
        ];
        crate::grey_quads(&[f, w])
    }

    #[test]
    fn cells_carry_a_close_lamps_whole_flux_where_points_miss_it() {
        let scene = room();
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        let entries = sample_surface(&scene, &EntryParams { count: 150, seed: 3 }).unwrap();
        let positions: Vec<Vec3> = entries.iter().map(|e| e.position).collect();
        let normals: Vec<Vec3> = entries.iter().map(|e| e.normal).collect();
        let cells = entry_cells(&scene, &bvh, &entries, 7).unwrap();
        assert_eq!(cells.points.len(), 150 * CELL_POINTS_PER_ENTRY);
        // Each cell keeps to its own face.
        for (i, nrm) in normals.iter().enumerate() {
            for p in cells.points_of(i) {
                assert!(
                    Vec3::from(p.normal()).dot(*nrm) > 0.99,
                    "entry {i}: a point of the other face"
                );
            }
        }
        // A lamp 0.2 above the floor: the floor receives 2π·I less what leaves past its edges.
        let per = (scene.area() / 150.0) as f32;
        let mut worst_points: f32 = 0.0;
        let mut worst_cells: f32 = 0.0;
        for (x, z) in [(0.3, 0.2), (-1.7, 2.9), (2.2, -0.6), (-3.1, -2.4)] {
            let light = Light::Point {
                position: Vec3::new(x, 0.2, z),
                intensity: Vec3::ONE,
            };
            let reach2 = prm_scene::cell_reach2(per);
            let at_cells: f32 = cell_irradiance(&bvh, &[light], &positions, &normals, &cells, reach2)
                .iter()
                .zip(&normals)
                .filter(|(_, n)| n.y > 0.5)
                .map(|(e, _)| e.x * per)
                .sum();
            let at_points: f32 = crate::direct::entry_irradiance(&bvh, &[light], &entries)
                .iter()
                .zip(&normals)
                .filter(|(_, n)| n.y > 0.5)
                .map(|(e, _)| e.x * per)
                .sum();
            // The floor's flux, by a fine midpoint rule over the 10 × 10 square.
            let k = 1000;
            let h = 10.0 / k as f32;
            let mut exact = 0.0f32;
            for i in 0..k {
                for j in 0..k {
                    let (px, pz) = (-5.0 + (i as f32 + 0.5) * h, -5.0 + (j as f32 + 0.5) * h);
                    let d2 = (px - x).powi(2) + (pz - z).powi(2) + 0.04;
                    exact += 0.2 / (d2 * d2.sqrt()) * h * h;
                }
            }
            worst_cells = worst_cells.max((at_cells / exact - 1.0).abs());
            worst_points = worst_points.max((at_points / exact - 1.0).abs());
        }
        assert!(worst_cells < 0.05, "cells off the floor's flux by {worst_cells}");
        assert!(
            worst_points > 2.0 * worst_cells,
            "points {worst_points}, cells {worst_cells}"
        );
    }

    /// A shade 1 cm under a ceiling, both facing down: the ceiling hidden behind the shade and
    /// the shade itself never share a cell, so the shade's lit points cannot go to the hidden
    /// entry points, whose panes carry nothing.
    #[test]
    fn a_shade_flush_with_a_ceiling_keeps_its_own_cells() {
        let quad = |y: f32, h: f32| {
            [
                Vec3::new(-h, y, -h),
                Vec3::new(h, y, -h),
                Vec3::new(h, y, h),
                Vec3::new(-h, y, h),
            ]
        };
        let scene = crate::grey_quads(&[quad(2.0, 2.0), quad(1.99, 0.5)]);
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        for n in scene.triangles.iter().map(|t| t.normal()) {
            assert!(n.y < -0.99, "both face down");
        }
        let entries = sample_surface(&scene, &EntryParams { count: 400, seed: 5 }).unwrap();
        let cells = entry_cells(&scene, &bvh, &entries, 9).unwrap();
        let on_shade = |p: Vec3| p.y < 1.995;
        let hidden = |p: Vec3| !on_shade(p) && p.x.abs() < 0.49 && p.z.abs() < 0.49;
        let mut checked = 0;
        for (i, e) in entries.iter().enumerate() {
            for p in cells.points_of(i) {
                let at = e.position + Vec3::from(p.offset());
                if on_shade(e.position) {
                    assert!(!hidden(at), "shade entry {i} holds a hidden ceiling point {at}");
                } else if hidden(e.position) {
                    assert!(!on_shade(at), "hidden entry {i} holds a shade point {at}");
                }
                checked += 1;
            }
        }
        assert_eq!(checked, 400 * CELL_POINTS_PER_ENTRY);
    }

    #[test]
    fn reordered_cells_follow_their_entries() {
        let scene = room();
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        let entries = sample_surface(&scene, &EntryParams { count: 20, seed: 1 }).unwrap();
        let cells = entry_cells(&scene, &bvh, &entries, 2).unwrap();
        let order: Vec<u32> = (0..20).rev().collect();
        let back = reorder_cells(&cells, &order);
        for (k, &i) in order.iter().enumerate() {
            assert_eq!(back.points_of(k), cells.points_of(i as usize));
        }
        assert_eq!(back.points.len(), cells.points.len());
    }
}
