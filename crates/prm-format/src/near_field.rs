//! The near field section (kind 11): what the panes' VPL bound removes next to every exit point, as cosine rays that end close by, so that a run time gathers it back from the
//! surfaces' radiance of the frame.
//!
//! A VPL standing for the area `a` reaches an exit point at distance `r` through `1/(r² + R²)`
//! instead of `1/r²`, `R² = a/π` (prm-trace's `VplBound::Disk`). Over the VPLs this leaves out
//! `∫ L(ω) · R²/(r² + R²) cos θ dω`: the near field's radiance, weighted towards the closest
//! surfaces. The section gathers it back for the depth-0 VPLs (area `A/N`, disk `R²` =
//! [`NearField::disk`]), which carry the direct light the entry points receive: with `M`
//! cosine-distributed rays from the exit point, of which the ones ending at gather point `g`
//! at squared distance `r²` are stored, the missing irradiance is
//! `π/M · Σ D_g · R²/(r² + R²)` ([`NearField::irradiance`]), `D_g` the radiance the gather
//! point sends from the lights' direct light, `albedo/π × irradiance` (emitters and the sky
//! reach the lightmap traced, not through the VPLs, when the archive holds their indirect
//! light). Rays whose weight would be under [`MIN_WEIGHT`] are not
//! stored: they miss or end too far away to matter. The bake may bound the deeper VPLs (the ones
//! its walks leave after the entry point) by a disk `R₁²` = [`NearField::indirect_disk`] too,
//! and the player then adds their share, `π/M · Σ I_g · R₁²/(r² + R₁²)` along the same rays,
//! `I_g` the radiance the gather point sends from the lights' indirect light of the frame
//! (albedo/π × the blended lightmap there). `R₁² = 0` leaves that share out (disks of the area
//! one walk stands for, `A/(N·W)`, are too small to gather).
//!
//! The cut at [`MIN_WEIGHT`] loses what the bound removes beyond it (up to a sixteenth of every
//! VPL's light there), a loss that grows with the disk. The section may say
//! ([`NearField::complement`], flag bit 0) that the panes were rendered with the kernel that
//! completes the cut weights instead: `1/max(r², (1 − w₀)(r² + R²))` (prm-trace's
//! `VplBound::Near`), `w₀` = [`MIN_WEIGHT`], against the weight `(R²/(r² + R²) − w₀)/(1 − w₀)`
//! (zero where a hit was not stored). The two sum to `1/r²` at every distance, so nothing is
//! lost at the cut and nothing counted twice; the same holds for the deeper VPLs with `R₁²`.
//!
//! Layout (formats/prm.md §5.6), little-endian: a 32-byte header (exit count `E`, rays per exit
//! `M`, gather point count `G`, flags (bit 0: [`FLAG_COMPLEMENT`]), the atlas resolution `R`, hit
//! count `H`, `R²` as `f32`, `R₁²` as `f32`), `G` gather point records of 56
//! bytes (as the probe rays', §5.5), `E` exit records of 8 bytes (texel `u32`, the end of its hits `u32`: exit `i`'s hits are
//! `[end[i−1], end[i])`), then `H` hits of 8 bytes (gather point `u32`, `r²` `f32`).

use crate::layout::{check_flags, check_ray_count, from_planes, to_planes, u32_at, Cursor, PutLe};
use crate::probe_rays::{self, GatherPoint, GATHER_POINT_SIZE};

/// Size of the section's fixed header.
pub const NEAR_FIELD_HEADER_SIZE: usize = 32;
/// Bytes of one exit record.
pub(crate) const NEAR_EXIT_SIZE: usize = 8;
/// Bytes of one hit: its gather point's index difference (`u32`) and its distance code (`u8`).
pub(crate) const NEAR_HIT_SIZE: usize = 5;
/// Most rays per exit point.
pub const MAX_NEAR_RAYS: u32 = 1 << 16;
/// The smallest depth-0 weight `R₀²/(r² + R₀²)` a stored hit has: farther hits are left out.
pub const MIN_WEIGHT: f32 = 1.0 / 16.0;
/// Header flag: the weights complement the panes' kernel at the cut ([`NearField::complement`]).
pub const FLAG_COMPLEMENT: u32 = 1;

/// An exit point with near hits.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NearExit {
    /// Texel index `y·R + x` in the atlas.
    pub texel: u32,
    /// One past its last hit in [`NearField::hits`]; its first is the previous exit's `end`.
    pub end: u32,
}

/// A near ray's end.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NearHit {
    /// Gather point index.
    pub point: u32,
    /// Squared distance from the exit point, scene units².
    pub distance2: f32,
}

/// Every exit point's near rays.
#[derive(Clone, Debug, PartialEq)]
pub struct NearField {
    /// Cosine-distributed rays traced per exit point, `M` (stored or not).
    pub rays_per_exit: u32,
    /// The depth-0 VPLs' disk, `R² = A/(N·π)` (scene units²).
    pub disk: f32,
    /// The deeper VPLs' disk `R₁²` (scene units², at most [`NearField::disk`]), whose share
    /// the player gathers from the lightmap's indirect light; 0: none (the deeper VPLs' disks
    /// too small to gather).
    pub indirect_disk: f32,
    /// The weights are cut at [`MIN_WEIGHT`] and rescaled to complete the panes' kernel
    /// (module docs); false: `R²/(r² + R²)` beside `1/(r² + R²)`.
    pub complement: bool,
    /// The surface points the rays end at.
    pub points: Vec<GatherPoint>,
    /// Exit points with at least one stored hit, in texel order.
    pub exits: Vec<NearExit>,
    /// Exit by exit, the stored hits.
    pub hits: Vec<NearHit>,
}

impl NearField {
    /// The weight of a hit at squared distance `r2`: `R²/(r² + R²)`, or with
    /// [`NearField::complement`] `(R²/(r² + R²) − w₀)/(1 − w₀)`, at least 0.
    pub fn weight(&self, r2: f32) -> f32 {
        self.weight_for(self.disk, r2)
    }

    /// The deeper VPLs' weight of a hit at squared distance `r2`, as [`NearField::weight`] with
    /// `R₁²` (0 without their share).
    pub fn indirect_weight(&self, r2: f32) -> f32 {
        if self.indirect_disk > 0.0 {
            self.weight_for(self.indirect_disk, r2)
        } else {
            0.0
        }
    }

    /// Puts the hits in the form the archive stores, so that what a writer holds reads back the
    /// same: each squared distance rounded to its distance code's (formats/prm.md §5.6; a hit
    /// beyond the cut [`MIN_WEIGHT`] comes back at it) and each exit's hits ordered by gather
    /// point (which the sum does not see, and which leaves the stored index differences small).
    pub fn round_to_stored(&mut self) {
        let disk = self.disk;
        for h in &mut self.hits {
            h.distance2 = stored_distance2(h.distance2, disk);
        }
        let mut start = 0;
        for x in &self.exits {
            let end = (x.end as usize).min(self.hits.len());
            if let Some(hits) = self.hits.get_mut(start..end) {
                hits.sort_by(|a, b| a.point.cmp(&b.point).then(a.distance2.total_cmp(&b.distance2)));
            }
            start = end;
        }
    }

    fn weight_for(&self, disk: f32, r2: f32) -> f32 {
        let w = disk / (r2 + disk);
        if self.complement {
            ((w - MIN_WEIGHT) / (1.0 - MIN_WEIGHT)).max(0.0)
        } else {
            w
        }
    }

    /// Exit record `i`'s hits (empty when `i` or its range is out of bounds).
    pub fn hits_of(&self, i: usize) -> &[NearHit] {
        let start = if i == 0 { 0 } else { self.exits[i - 1].end as usize };
        self.exits
            .get(i)
            .and_then(|x| self.hits.get(start..x.end as usize))
            .unwrap_or(&[])
    }

    /// Every exit's missing irradiance (in [`NearField::exits`] order) when gather point `g`
    /// sends `direct[g]` from the lights' direct light and `indirect[g]` from their indirect
    /// light (radiance, RGB; `indirect` is read only with [`NearField::indirect_disk`] > 0, and
    /// may be empty).
    pub fn irradiance(&self, direct: &[[f32; 3]], indirect: &[[f32; 3]]) -> Vec<[f32; 3]> {
        let scale = std::f32::consts::PI / self.rays_per_exit.max(1) as f32;
        (0..self.exits.len())
            .map(|i| {
                let mut e = [0.0f32; 3];
                for h in self.hits_of(i) {
                    let w = self.weight(h.distance2);
                    if let Some(d) = direct.get(h.point as usize) {
                        (0..3).for_each(|k| e[k] += d[k] * w);
                    }
                    if let Some(d) = indirect.get(h.point as usize) {
                        let w1 = self.indirect_weight(h.distance2);
                        (0..3).for_each(|k| e[k] += d[k] * w1);
                    }
                }
                e.map(|v| v * scale)
            })
            .collect()
    }
}

/// Steps of a hit's distance code between the cut and the exit point.
const DISTANCE_CODES: f32 = 255.0;

/// The distance code of a hit at squared distance `r2` from the disk `disk` (`R²`): its depth-0
/// weight `w = R²/(r² + R²)` as `q = (w − w₀)/(1 − w₀)·255` rounded, clamped to `0 ..= 255`
/// (formats/prm.md §5.6).
fn distance_code(r2: f32, disk: f32) -> u8 {
    let w = disk / (r2 + disk);
    ((w - MIN_WEIGHT) / (1.0 - MIN_WEIGHT) * DISTANCE_CODES)
        .round()
        .clamp(0.0, DISTANCE_CODES) as u8
}

/// The squared distance code `q` stands for: `R²·(1/w − 1)`, `w = w₀ + (1 − w₀)·q/255`.
fn code_distance2(q: u8, disk: f32) -> f32 {
    let w = MIN_WEIGHT + (1.0 - MIN_WEIGHT) * (f32::from(q) / DISTANCE_CODES);
    disk * (1.0 / w - 1.0)
}

/// The squared distance `r2` as an archive with the disk `disk` stores it.
pub(crate) fn stored_distance2(r2: f32, disk: f32) -> f32 {
    code_distance2(distance_code(r2, disk), disk)
}

/// Raw size of a section of `e` exits, `g` gather points and `h` hits; `None` on overflow.
pub(crate) fn raw_size_for(e: u64, g: u64, h: u64) -> Option<u64> {
    e.checked_mul(NEAR_EXIT_SIZE as u64)?
        .checked_add(g.checked_mul(GATHER_POINT_SIZE as u64)?)?
        .checked_add(h.checked_mul(NEAR_HIT_SIZE as u64)?)?
        .checked_add(NEAR_FIELD_HEADER_SIZE as u64)
}

/// Checks `near` against the atlas resolution and the emitter groups.
pub(crate) fn validate(near: &NearField, resolution: u32, groups: usize) -> Result<(), String> {
    let m = near.rays_per_exit;
    if m == 0 || m > MAX_NEAR_RAYS {
        return Err(format!("{m} near rays per exit, not between 1 and {MAX_NEAR_RAYS}"));
    }
    if !(near.disk.is_finite() && near.disk > 0.0) {
        return Err(format!("near field disk {}, not finite and positive", near.disk));
    }
    if !(near.indirect_disk >= 0.0 && near.indirect_disk <= near.disk) {
        return Err(format!(
            "near field indirect disk {}, not between 0 and the disk {}",
            near.indirect_disk, near.disk
        ));
    }
    let texels = u64::from(resolution) * u64::from(resolution);
    probe_rays::validate_points(&near.points, texels, groups)?;
    let mut last: Option<u32> = None;
    let mut end = 0u32;
    for (i, x) in near.exits.iter().enumerate() {
        if u64::from(x.texel) >= texels || last.is_some_and(|t| x.texel <= t) {
            return Err(format!(
                "near exit {i} has texel {} of {texels}, not after the previous one",
                x.texel
            ));
        }
        if x.end <= end || x.end as usize > near.hits.len() || x.end - end > m {
            return Err(format!(
                "near exit {i} ends its hits at {}, not after {end}, within {} and at most {m} rays on",
                x.end,
                near.hits.len()
            ));
        }
        last = Some(x.texel);
        end = x.end;
    }
    if end as usize != near.hits.len() {
        return Err(format!("{} near hits, the exits cover {end}", near.hits.len()));
    }
    let g = near.points.len() as u32;
    if let Some(i) = near
        .hits
        .iter()
        .position(|h| h.point >= g || !h.distance2.is_finite() || h.distance2 < 0.0)
    {
        return Err(format!(
            "near hit {i} ends at gather point {} of {g} at squared distance {}",
            near.hits[i].point, near.hits[i].distance2
        ));
    }
    Ok(())
}

/// Encodes a validated near field for an atlas of `resolution`.
pub(crate) fn encode(near: &NearField, resolution: u32) -> Vec<u8> {
    let size = raw_size_for(
        near.exits.len() as u64,
        near.points.len() as u64,
        near.hits.len() as u64,
    )
    .unwrap_or(0);
    let mut b = Vec::with_capacity(size as usize);
    for v in [
        near.exits.len() as u32,
        near.rays_per_exit,
        near.points.len() as u32,
        if near.complement { FLAG_COMPLEMENT } else { 0 },
        resolution,
        near.hits.len() as u32,
    ] {
        b.put_u32(v);
    }
    b.put_f32(near.disk);
    b.put_f32(near.indirect_disk);
    probe_rays::encode_points(&near.points, &mut b);
    for x in &near.exits {
        b.put_u32(x.texel);
        b.put_u32(x.end);
    }
    let mut last = 0u32;
    b.extend(to_planes(near.hits.iter().map(|h| {
        let d = h.point.wrapping_sub(last);
        last = h.point;
        d.to_le_bytes()
    })));
    b.extend(near.hits.iter().map(|h| distance_code(h.distance2, near.disk)));
    b
}

/// What the header gives.
#[derive(Debug, PartialEq)]
pub(crate) struct Header {
    pub exits: u32,
    pub rays_per_exit: u32,
    pub points: u32,
    pub resolution: u32,
    pub hits: u32,
    pub disk: f32,
    pub indirect_disk: f32,
    pub complement: bool,
}

/// Parses and checks the header's own fields (the section has no reserved field).
pub(crate) fn decode_header(head: &[u8]) -> Result<Header, String> {
    let mut c = Cursor::new(head, "near field");
    let [exits, rays_per_exit, points, flags, resolution, hits] = c.u32s().map_err(|e| e.to_string())?;
    let disk = c.f32().map_err(|e| e.to_string())?;
    let indirect_disk = c.f32().map_err(|e| e.to_string())?;
    check_flags("near field", flags, FLAG_COMPLEMENT, false)?;
    check_ray_count("near field", rays_per_exit, "exit", MAX_NEAR_RAYS)?;
    Ok(Header {
        exits,
        rays_per_exit,
        points,
        resolution,
        hits,
        disk,
        indirect_disk,
        complement: flags & FLAG_COMPLEMENT != 0,
    })
}

/// Decodes whole exit records.
pub(crate) fn decode_exits(raw: &[u8]) -> Result<Vec<NearExit>, String> {
    Ok(raw
        .chunks_exact(NEAR_EXIT_SIZE)
        .map(|r| NearExit {
            texel: u32_at(r, 0),
            end: u32_at(r, 4),
        })
        .collect())
}

/// Decodes the hits from their index differences (in byte planes) and distance codes
/// (`5·H` bytes in all) for the disk `disk`.
pub(crate) fn decode_hits(raw: &[u8], disk: f32) -> Vec<NearHit> {
    let h = raw.len() / NEAR_HIT_SIZE;
    let (points, codes) = raw.split_at(4 * h);
    let mut last = 0u32;
    from_planes::<4>(points)
        .zip(codes)
        .map(|(d, &q)| {
            last = last.wrapping_add(u32::from_le_bytes(d));
            NearHit {
                point: last,
                distance2: code_distance2(q, disk),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn near() -> NearField {
        let point = crate::probe_rays::test_point;
        NearField {
            rays_per_exit: 4,
            disk: 0.01,
            indirect_disk: 0.005,
            complement: false,
            points: vec![point(3), point(9)],
            exits: vec![NearExit { texel: 2, end: 2 }, NearExit { texel: 5, end: 3 }],
            hits: vec![
                NearHit {
                    point: 0,
                    distance2: 0.0,
                },
                NearHit {
                    point: 1,
                    distance2: 0.01,
                },
                NearHit {
                    point: 0,
                    distance2: 0.03,
                },
            ],
        }
    }

    #[test]
    fn round_trip_through_the_encoding() {
        let mut n = near();
        n.round_to_stored();
        validate(&n, 4, 0).unwrap();
        let raw = encode(&n, 4);
        assert_eq!(raw.len() as u64, raw_size_for(2, 2, 3).unwrap());
        let h = decode_header(&raw[..NEAR_FIELD_HEADER_SIZE]).unwrap();
        assert_eq!(
            h,
            Header {
                exits: 2,
                rays_per_exit: 4,
                points: 2,
                resolution: 4,
                hits: 3,
                disk: 0.01,
                indirect_disk: 0.005,
                complement: false,
            }
        );
        let c = encode(
            &NearField {
                complement: true,
                ..n.clone()
            },
            4,
        );
        assert!(decode_header(&c[..NEAR_FIELD_HEADER_SIZE]).unwrap().complement);
        let a = NEAR_FIELD_HEADER_SIZE + 2 * GATHER_POINT_SIZE;
        let b = a + 2 * NEAR_EXIT_SIZE;
        let back = NearField {
            rays_per_exit: 4,
            disk: h.disk,
            indirect_disk: h.indirect_disk,
            complement: h.complement,
            points: probe_rays::decode_points(&raw[NEAR_FIELD_HEADER_SIZE..a]).unwrap(),
            exits: decode_exits(&raw[a..b]).unwrap(),
            hits: decode_hits(&raw[b..], h.disk),
        };
        assert_eq!(back, n);
    }

    #[test]
    fn distance_codes_keep_the_weight_within_half_a_step() {
        let disk = 0.0095;
        for i in 0..=4000 {
            let r2 = disk * 15.0 * i as f32 / 4000.0;
            let q = distance_code(r2, disk);
            let stored = code_distance2(q, disk);
            assert_eq!(distance_code(stored, disk), q, "r² {r2}");
            let (w, ws) = (disk / (r2 + disk), disk / (stored + disk));
            assert!(
                (w - ws).abs() <= 0.5 * (1.0 - MIN_WEIGHT) / DISTANCE_CODES + 1e-6,
                "r² {r2}: {w} {ws}"
            );
        }
        assert_eq!(code_distance2(255, disk), 0.0);
        assert_eq!(distance_code(disk * 100.0, disk), 0, "beyond the cut: at the cut");
    }

    #[test]
    fn stored_hits_are_ordered_by_gather_point_within_each_exit() {
        let mut n = near();
        n.round_to_stored();
        let points: Vec<u32> = n.hits.iter().map(|h| h.point).collect();
        assert_eq!(points, [0, 1, 0]);
        n.hits.swap(0, 1);
        n.round_to_stored();
        assert_eq!(n.hits.iter().map(|h| h.point).collect::<Vec<_>>(), [0, 1, 0]);
    }

    #[test]
    fn the_irradiance_weighs_each_hit_by_its_distance() {
        let n = near();
        let direct = [[1.0, 0.0, 0.5], [2.0, 4.0, 0.0]];
        let e = NearField {
            indirect_disk: 0.0,
            ..n.clone()
        }
        .irradiance(&direct, &direct);
        let s = std::f32::consts::PI / 4.0;
        // Exit 0: a hit at distance 0 (weight 1) and one at r² = R² (½).
        let want0 = [s * (1.0 + 2.0 * 0.5), s * 4.0 * 0.5, s * 0.5];
        // Exit 1: r² = 3 R² (¼).
        let want1 = [s * 0.25, 0.0, s * 0.5 * 0.25];
        for (got, want) in e.iter().zip([want0, want1]) {
            for k in 0..3 {
                assert!((got[k] - want[k]).abs() < 1e-6, "{got:?} against {want:?}");
            }
        }
    }

    #[test]
    fn the_deeper_share_weighs_each_hit_by_the_deeper_disk() {
        // R₁² = R²/2 = 0.005: weights 1 at r² = 0, 1/3 at 0.01, 1/7 at 0.03.
        let n = near();
        let e = n.irradiance(&[[0.0; 3]; 2], &[[1.0, 0.0, 0.0], [0.0, 3.0, 0.0]]);
        let s = std::f32::consts::PI / 4.0;
        for (got, want) in e.iter().zip([[s, s, 0.0], [s / 7.0, 0.0, 0.0]]) {
            for k in 0..3 {
                assert!((got[k] - want[k]).abs() < 1e-6, "{got:?} against {want:?}");
            }
        }
        let none = NearField {
            indirect_disk: 0.0,
            ..n
        };
        assert!(none
            .irradiance(&[[0.0; 3]; 2], &[[1.0; 3]; 2])
            .iter()
            .flatten()
            .all(|v| *v == 0.0));
    }

    #[test]
    fn complemented_weights_and_the_panes_kernel_sum_to_the_inverse_square() {
        // `VplBound::Near`'s kernel, relative to 1/r², is r²/max(r², (1 − w₀)(r² + R²)).
        let n = NearField {
            complement: true,
            ..near()
        };
        for r2 in [0.0f32, 1e-4, 0.005, 0.01, 0.05, 0.1499, 0.15, 0.1501, 0.3, 10.0] {
            for (disk, w) in [(n.disk, n.weight(r2)), (n.indirect_disk, n.indirect_weight(r2))] {
                let pane = if r2 > 0.0 {
                    r2 / r2.max((1.0 - MIN_WEIGHT) * (r2 + disk))
                } else {
                    0.0
                };
                assert!((w + pane - 1.0).abs() < 1e-5, "r² {r2}, R² {disk}: {w} + {pane}");
                // Zero exactly where the cut leaves hits out.
                assert_eq!(w > 0.0, disk / (r2 + disk) > MIN_WEIGHT, "r² {r2}, R² {disk}");
            }
        }
    }

    #[test]
    fn rejects_what_the_layout_cannot_hold() {
        assert!(validate(&near(), 2, 0).is_err(), "texel 9 outside a 2² atlas");
        let mut n = near();
        n.exits[1].texel = 2;
        assert!(validate(&n, 4, 0).is_err(), "texels out of order");
        let mut n = near();
        n.exits[1].end = 2;
        assert!(validate(&n, 4, 0).is_err(), "an exit without hits");
        let mut n = near();
        n.exits[1].end = 4;
        assert!(validate(&n, 4, 0).is_err(), "hits beyond the list");
        let mut n = near();
        n.rays_per_exit = 1;
        assert!(validate(&n, 4, 0).is_err(), "two hits of one ray");
        let mut n = near();
        n.hits.push(NearHit::default());
        assert!(validate(&n, 4, 0).is_err(), "a hit no exit covers");
        let mut n = near();
        n.hits[2].point = 2;
        assert!(validate(&n, 4, 0).is_err(), "gather point 2 of 2");
        let mut n = near();
        n.hits[0].distance2 = f32::NAN;
        assert!(validate(&n, 4, 0).is_err(), "NaN distance");
        let mut n = near();
        n.disk = 0.0;
        assert!(validate(&n, 4, 0).is_err(), "zero disk");
        let mut n = near();
        n.rays_per_exit = 0;
        assert!(validate(&n, 4, 0).is_err(), "no rays");
        let mut head = encode(&near(), 4)[..NEAR_FIELD_HEADER_SIZE].to_vec();
        head[12..16].copy_from_slice(&2u32.to_le_bytes());
        assert!(decode_header(&head).is_err(), "unknown flags");
        head[12..16].copy_from_slice(&1u32.to_le_bytes());
        assert!(decode_header(&head).unwrap().complement);
        let mut n = near();
        n.indirect_disk = 0.02;
        assert!(validate(&n, 4, 0).is_err(), "indirect disk over the disk");
        n.indirect_disk = -1.0;
        assert!(validate(&n, 4, 0).is_err(), "negative indirect disk");
        n.indirect_disk = f32::NAN;
        assert!(validate(&n, 4, 0).is_err(), "NaN indirect disk");
    }
}
