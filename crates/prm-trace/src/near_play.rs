//! The player's near field on the CPU, over the whole atlas, read at a few exit points: what
//! the bake's accuracy check ([`crate::check`]) adds to the blended panes so that it plays what
//! prm-runtime plays.
//!
//! prm-runtime adds to the blend the near field's direct share (its gather points' direct light
//! through the shadow maps; here ray-cast) and then gathers the deeper share from the lightmap,
//! [`NEAR_GATHERS`] times by default, each time from the lightmap the previous gather
//! completed, and extrapolates the rest of that series ([`prm_scene::DeeperOperator`]). With
//! `S` the blend plus the direct share and `N` the deeper share's operator, an exit point plays
//! `Σ_{k ≤ K} Nᵏ S + f ⊙ Nᴷ S`, linear in `S`: so each pane's part of it is taken once, when
//! the pane is made ([`NearPlay::series`]), the direct share's once per light
//! ([`NearPlay::direct`]), and a light's blend of the former plus the latter is what the
//! player shows. The second and later gathers reach texels far from the checked ones (the
//! whole atlas, in the end), which is why the model runs over every exit record.
//!
//! The deeper share of the direct share and the gathers after the first are most of the near
//! field's light where the disks are large: a check that took the direct share and one gather
//! only estimated the fireplace room's default bake at 38.7% (energy 0.76–0.79) where the
//! player's lightmap is 15–16% off.

use glam::Vec3;
use prm_format::NearField;
use prm_scene::{DeeperOperator, Light, MergeNearHits};
use rayon::prelude::*;

use crate::bvh::Bvh;

/// The deeper share's gathers a frame, and its series extrapolated after them: prm-runtime's
/// defaults (`RuntimeOptions::DEFAULT_NEAR_BOUNCES`, `NearTail::Extrapolated`; `tests/check.rs`
/// keeps the two equal).
pub const NEAR_GATHERS: u32 = 2;

/// The near field as the player sums it, and where the checked exit points are in it.
#[derive(Debug)]
pub struct NearPlay<'a> {
    near: &'a NearField,
    op: DeeperOperator,
    /// Every record's tail factor.
    tail: Vec<[f32; 3]>,
    gathers: u32,
    /// Every exit record's exit point (index into the values [`NearPlay::series`] reads), or
    /// `u32::MAX` for a gutter texel's copy.
    record_exit: Vec<u32>,
    /// Every checked exit point's record, or `u32::MAX` where it has no near rays.
    checked_record: Vec<u32>,
    /// Every checked exit point.
    checked_exit: Vec<usize>,
    /// The records within `gathers − 1` steps of the checked ones along the deeper share's
    /// terms, ascending: where the terms before the last are needed.
    reached: Vec<u32>,
}

impl<'a> NearPlay<'a> {
    /// The model of `near` with `gathers` gathers and the series' tail after them, for an atlas
    /// whose texel `t` holds exit point `texel_exit[t]` (`prm_scene::Atlas::texel_exit`), read
    /// at the exit points on `checked_texels`.
    pub fn new(near: &'a NearField, texel_exit: &[u32], checked_texels: &[u32], gathers: u32) -> NearPlay<'a> {
        let (ends, merged) = near.merged_hits();
        let op = DeeperOperator::new(near, &ends, &merged);
        let gathers = if near.indirect_disk > 0.0 { gathers } else { 0 };
        let tail = op.series_tail(gathers, |v| apply(&op, v));
        let record_exit = near
            .exits
            .iter()
            .map(|x| texel_exit.get(x.texel as usize).copied().unwrap_or(u32::MAX))
            .collect();
        let checked_record: Vec<u32> = checked_texels
            .iter()
            .map(|t| {
                near.exits
                    .binary_search_by_key(t, |x| x.texel)
                    .map_or(u32::MAX, |i| i as u32)
            })
            .collect();
        let checked_exit = checked_texels
            .iter()
            .map(|&t| texel_exit[t as usize] as usize)
            .collect();
        let reached = reached(&op, &checked_record, gathers);
        NearPlay {
            near,
            op,
            tail,
            gathers,
            record_exit,
            checked_record,
            checked_exit,
            reached,
        }
    }

    /// Checked exit points.
    pub fn checked(&self) -> usize {
        self.checked_exit.len()
    }

    /// What the player shows at the checked exit points for `s`, one value per exit point
    /// (their order in `texel_exit`): `s` and the deeper share's series from it.
    pub fn series(&self, s: &[Vec3]) -> Vec<Vec3> {
        let at_records: Vec<[f32; 3]> = self
            .record_exit
            .iter()
            .map(|&e| s.get(e as usize).map_or([0.0; 3], |v| v.to_array()))
            .collect();
        self.series_of_records(&at_records, self.checked_exit.iter().map(|&i| s[i]))
    }

    /// The series from `s` on every record, added to `base` at the checked exit points.
    fn series_of_records(&self, s: &[[f32; 3]], base: impl Iterator<Item = Vec3>) -> Vec<Vec3> {
        if self.gathers == 0 {
            return base.collect();
        }
        // Nᵏ S for k < K where the later terms read it (the k-th term is needed within K − k
        // steps of the checked records, and `reached` holds every record within K − 1), then
        // Nᴷ S at the checked ones only.
        let mut terms = vec![s.to_vec()];
        for _ in 1..self.gathers {
            let prev = &terms[terms.len() - 1];
            let rows: Vec<[f32; 3]> = self
                .reached
                .par_iter()
                .map(|&r| self.op.row(r as usize, Some(prev)))
                .collect();
            let mut next = vec![[0.0; 3]; s.len()];
            for (&r, v) in self.reached.iter().zip(rows) {
                next[r as usize] = v;
            }
            terms.push(next);
        }
        let last = &terms[terms.len() - 1];
        base.zip(&self.checked_record)
            .map(|(b, &r)| {
                if r == u32::MAX {
                    return b;
                }
                let r = r as usize;
                let earlier: Vec3 = terms[1..].iter().map(|t| Vec3::from(t[r])).sum();
                let nk = Vec3::from(self.op.row(r, Some(last)));
                b + earlier + nk * (Vec3::ONE + Vec3::from(self.tail[r]))
            })
            .collect()
    }

    /// The direct share under `lights`, ray-cast at every gather point, with the deeper
    /// share's series from it, at the checked exit points.
    pub fn direct(&self, bvh: &Bvh, lights: &[Light]) -> Vec<Vec3> {
        let radiance: Vec<[f32; 3]> = self
            .near
            .points
            .par_iter()
            .map(|g| {
                let (p, n) = (Vec3::from(g.position), Vec3::from(g.normal));
                let e = crate::direct_irradiance(bvh, lights, p, n, n, u32::MAX);
                (Vec3::from(g.albedo) * e / std::f32::consts::PI).to_array()
            })
            .collect();
        let share = self.near.irradiance(&radiance, &[]);
        let base = self
            .checked_record
            .iter()
            .map(|&r| share.get(r as usize).map_or(Vec3::ZERO, |v| Vec3::from(*v)));
        self.series_of_records(&share, base)
    }
}

/// The records within `gathers − 1` steps of `checked` (`u32::MAX`: none) along `op`'s terms.
fn reached(op: &DeeperOperator, checked: &[u32], gathers: u32) -> Vec<u32> {
    let mut seen = vec![false; op.len()];
    let mut front: Vec<u32> = checked.iter().copied().filter(|&r| r != u32::MAX).collect();
    for _ in 1..gathers {
        let mut next = Vec::new();
        for &r in &front {
            if !std::mem::replace(&mut seen[r as usize], true) {
                let start = if r == 0 { 0 } else { op.ends[r as usize - 1] as usize };
                next.extend(
                    op.terms[start..op.ends[r as usize] as usize]
                        .iter()
                        .map(|t| t.0)
                        .filter(|&at| at != u32::MAX),
                );
            }
        }
        front = next;
    }
    for &r in &front {
        seen[r as usize] = true;
    }
    (0..op.len() as u32).filter(|&r| seen[r as usize]).collect()
}

/// `N v` at every record, on every thread.
fn apply(op: &DeeperOperator, v: Option<&[[f32; 3]]>) -> Vec<[f32; 3]> {
    (0..op.len()).into_par_iter().map(|i| op.row(i, v)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use prm_format::{GatherPoint, NearExit, NearHit};

    /// Two facing exit records (texels 0 and 1, exit points 0 and 1) whose every ray ends on
    /// the other's gather point at r² = 0, albedo ½, and a gutter copy of texel 1 (texel 2).
    fn facing() -> NearField {
        let ray = |point| NearHit { point, distance2: 0.0 };
        NearField {
            points: (0..2)
                .map(|texel| GatherPoint {
                    texel,
                    albedo: [0.5; 3],
                    ..Default::default()
                })
                .collect(),
            exits: (0..3)
                .map(|t| NearExit {
                    texel: t,
                    end: 4 * (t + 1),
                })
                .collect(),
            hits: [[1; 4], [0; 4], [0; 4]].concat().into_iter().map(ray).collect(),
            rays_per_exit: 4,
            disk: 1.0,
            indirect_disk: 1.0,
            complement: false,
        }
    }

    #[test]
    fn the_series_and_its_tail_reach_the_limit_for_uniform_light() {
        // Each term is ½ of the one before (½ · 4/4): uniform S = 1 plays 1/(1 − ½) = 2 at
        // every gather count, exactly, and with no gathers 1.
        let near = facing();
        let texel_exit = [0, 1, 7, 2, 3, 5];
        let s = vec![Vec3::ONE; 8];
        for gathers in [1, 2, 3] {
            let play = NearPlay::new(&near, &texel_exit, &[0, 1, 5], gathers);
            let got = play.series(&s);
            for v in &got[..2] {
                assert!((*v - Vec3::splat(2.0)).abs().max_element() < 1e-5, "{gathers}: {got:?}");
            }
            assert_eq!(got[2], Vec3::ONE, "an exit point without near rays plays S");
        }
        let play = NearPlay::new(&near, &texel_exit, &[0], 0);
        assert_eq!(play.series(&s), vec![Vec3::ONE]);
    }

    #[test]
    fn the_series_follows_the_light_passed_back_and_forth() {
        // S = 1 at exit 0 only: N S = (0, ½), N² S = (¼, 0), and uniform light's factor is 1
        // (every term ½ of the one before), so two gathers and the tail give exit 0
        // 1 + 0 + ¼ + ¼ · 1 and exit 1 0 + ½ + 0 + 0.
        let near = facing();
        let play = NearPlay::new(&near, &[0, 1, 7], &[0, 1], 2);
        let s = [Vec3::X, Vec3::ZERO];
        let got = play.series(&s);
        assert!((got[0].x - 1.5).abs() < 1e-5, "{got:?}");
        assert!((got[1].x - 0.5).abs() < 1e-5, "{got:?}");
        assert_eq!(got[0].y, 0.0);
    }

    #[test]
    fn checking_one_exit_point_plays_what_checking_all_plays() {
        // A chain: record i's rays end on texel i + 1 (the last's on a texel without a record),
        // so exit 0's K-th term reads K records on; the model computes the earlier terms near
        // the checked records only.
        let point = |texel| GatherPoint {
            texel,
            albedo: [0.5, 0.25, 1.0],
            ..Default::default()
        };
        let near = NearField {
            rays_per_exit: 4,
            disk: 1.0,
            indirect_disk: 1.0,
            complement: false,
            points: (1..=6).map(point).collect(),
            exits: (0..6)
                .map(|t| NearExit {
                    texel: t,
                    end: 2 * (t + 1),
                })
                .collect(),
            hits: (0..12)
                .map(|h| NearHit {
                    point: h / 2,
                    distance2: 0.5 * (h % 2) as f32,
                })
                .collect(),
        };
        let texel_exit: Vec<u32> = (0..7).collect();
        let s: Vec<Vec3> = (0..7)
            .map(|i| Vec3::new(1.0 + i as f32, 0.5, 2.0 - 0.25 * i as f32))
            .collect();
        let all: Vec<u32> = (0..6).collect();
        for gathers in 1..=5 {
            let one = NearPlay::new(&near, &texel_exit, &[0, 3], gathers);
            assert!(one.reached.len() <= (2 * gathers as usize).min(6), "{:?}", one.reached);
            let every = NearPlay::new(&near, &texel_exit, &all, gathers);
            let (a, b) = (one.series(&s), every.series(&s));
            for (x, y) in a.iter().zip([b[0], b[3]]) {
                assert!((*x - y).abs().max_element() < 1e-6, "{gathers}: {a:?} against {b:?}");
            }
        }
    }
}
