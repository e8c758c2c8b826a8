//! The entry cells section (kind 12): the surface every entry point stands for, as points, so
//! that a run time weighs an entry point by the light its whole cell receives.
//!
//! An entry point stands for the area `A/N` around it. Its pane is lit by its irradiance `E_i`,
//! so the light the entry points carry into the panes is `Σ E_i · A/N`. Taken at the entry point
//! alone, that sum misses or doubles the light of a lamp close to a surface: a few entry points
//! sample its bright spot, and they lie closer together or farther apart than `A/N` by chance.
//! The bake therefore samples `M` points uniformly over the scene's area, gives each to the
//! entry point whose cell it lies in, and stores them here. Under the lights of a frame, entry
//! `i` takes
//!
//! `E_i = N/M · Σ_{p in cell i} E(p)`,
//!
//! the light its cell receives over the area `A/N` it stands for, so `Σ E_i · A/N` is the flux
//! on the whole scene whatever the entry points' spacing.
//!
//! Layout (formats/prm.md §5.7), little-endian: a 16-byte header (entry count `N`, point count
//! `M`, two reserved words 0), `N` `u32` ends (entry `i`'s points are `[end[i−1], end[i])`,
//! the last end `M`), then `M` points of 8 bytes: the offset from the entry point as three
//! `f16` (x, y, z), then the unit normal octahedral in two `u8` ([`CellPoint`]).

use crate::layout::{Cursor, PutLe};

/// Size of the section's fixed header.
pub const ENTRY_CELLS_HEADER_SIZE: usize = 16;
/// Bytes of one point.
pub(crate) const CELL_POINT_SIZE: usize = 8;

/// A point of an entry point's cell: where it is from the entry point and which way its
/// surface faces, at the precision the archive stores (three `f16`, two `u8` octahedral).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CellPoint {
    packed: [u32; 2],
}

impl CellPoint {
    /// The point at `offset` from its entry point with unit normal `normal`, rounded to the
    /// stored precision. A non-finite offset or one beyond the `f16` range is refused.
    pub fn new(offset: [f32; 3], normal: [f32; 3]) -> Option<CellPoint> {
        let h = offset.map(half::f16::from_f32);
        if !h.iter().all(|v| v.is_finite()) {
            return None;
        }
        let [u, v] = octahedral_u8(normal);
        let x = u32::from(h[0].to_bits()) | (u32::from(h[1].to_bits()) << 16);
        let y = u32::from(h[2].to_bits()) | (u32::from(u) << 16) | (u32::from(v) << 24);
        Some(CellPoint { packed: [x, y] })
    }

    /// The offset from the entry point.
    pub fn offset(&self) -> [f32; 3] {
        let [x, y] = self.packed;
        [x & 0xFFFF, x >> 16, y & 0xFFFF].map(|b| half::f16::from_bits(b as u16).to_f32())
    }

    /// The unit normal.
    pub fn normal(&self) -> [f32; 3] {
        let y = self.packed[1];
        let e = [(y >> 16) & 0xFF, y >> 24].map(|q| q as f32 / 255.0 * 2.0 - 1.0);
        let mut n = [e[0], e[1], 1.0 - e[0].abs() - e[1].abs()];
        if n[2] < 0.0 {
            let (x, y) = (n[0], n[1]);
            n[0] = (1.0 - y.abs()) * x.signum();
            n[1] = (1.0 - x.abs()) * y.signum();
        }
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        n.map(|c| c / len)
    }

    /// The two words as stored (and as prm-runtime's weights pass reads them).
    pub fn packed(&self) -> [u32; 2] {
        self.packed
    }
}

/// Octahedral coordinates of the unit vector `n`, each in `u8` (0 ↦ −1, 255 ↦ 1).
fn octahedral_u8(n: [f32; 3]) -> [u8; 2] {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    let (mut x, mut y) = if l1 > 0.0 { (n[0] / l1, n[1] / l1) } else { (0.0, 0.0) };
    if n[2] < 0.0 {
        let (px, py) = (x, y);
        x = (1.0 - py.abs()) * if px >= 0.0 { 1.0 } else { -1.0 };
        y = (1.0 - px.abs()) * if py >= 0.0 { 1.0 } else { -1.0 };
    }
    [x, y].map(|c| ((c.clamp(-1.0, 1.0) * 0.5 + 0.5) * 255.0).round() as u8)
}

/// Every entry point's cell (module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EntryCells {
    /// Entry by entry (in the archive's entry order), one past its last point.
    pub ends: Vec<u32>,
    /// The points, entry by entry.
    pub points: Vec<CellPoint>,
}

impl EntryCells {
    /// Entry `i`'s points (empty when `i` is out of bounds).
    pub fn points_of(&self, i: usize) -> &[CellPoint] {
        let start = if i == 0 { Some(&0) } else { self.ends.get(i - 1) };
        match (start, self.ends.get(i)) {
            (Some(&start), Some(&end)) => self.points.get(start as usize..end as usize).unwrap_or(&[]),
            _ => &[],
        }
    }

    /// What each point's irradiance counts for in its entry's, `N/M` (0 without points).
    pub fn point_weight(&self) -> f32 {
        if self.points.is_empty() {
            0.0
        } else {
            self.ends.len() as f32 / self.points.len() as f32
        }
    }
}

/// Raw size of a section of `n` entries and `m` points; `None` on overflow.
pub(crate) fn raw_size_for(n: u64, m: u64) -> Option<u64> {
    n.checked_mul(4)?
        .checked_add(m.checked_mul(CELL_POINT_SIZE as u64)?)?
        .checked_add(ENTRY_CELLS_HEADER_SIZE as u64)
}

/// Checks `cells` against the entry count.
pub(crate) fn validate(cells: &EntryCells, entries: usize) -> Result<(), String> {
    if cells.ends.len() != entries {
        return Err(format!(
            "entry cells for {} entries, the archive has {entries}",
            cells.ends.len()
        ));
    }
    if cells.points.len() > u32::MAX as usize {
        return Err(format!(
            "{} entry cell points, more than a u32 counts",
            cells.points.len()
        ));
    }
    let mut last = 0u32;
    for (i, &end) in cells.ends.iter().enumerate() {
        if end < last || end as usize > cells.points.len() {
            return Err(format!(
                "entry {i}'s cell ends at point {end}, before {last} or past the last point"
            ));
        }
        last = end;
    }
    if last as usize != cells.points.len() {
        return Err(format!("the entry cells end at point {last} of {}", cells.points.len()));
    }
    Ok(())
}

/// The section's bytes.
pub(crate) fn encode(cells: &EntryCells) -> Vec<u8> {
    let n = cells.ends.len();
    let m = cells.points.len();
    let mut out = Vec::with_capacity(raw_size_for(n as u64, m as u64).unwrap_or(0) as usize);
    out.put_u32(n as u32);
    out.put_u32(m as u32);
    out.put_u32(0);
    out.put_u32(0);
    cells.ends.iter().for_each(|&e| out.put_u32(e));
    for p in &cells.points {
        out.put_u32(p.packed[0]);
        out.put_u32(p.packed[1]);
    }
    out
}

/// The header's entry and point counts; the reserved words must be 0.
pub(crate) fn decode_header(head: &[u8; ENTRY_CELLS_HEADER_SIZE]) -> Result<(u32, u32), String> {
    let mut c = Cursor::new(head, "entry_cells");
    let [n, m, r0, r1] = c.u32s::<4>().map_err(|e| e.to_string())?;
    if r0 != 0 || r1 != 0 {
        return Err(format!("entry_cells header's reserved words are {r0} and {r1}, not 0"));
    }
    Ok((n, m))
}

/// A chunk of ends.
pub(crate) fn decode_ends(raw: &[u8]) -> Result<Vec<u32>, String> {
    let mut c = Cursor::new(raw, "entry_cells");
    (0..raw.len() / 4).map(|_| c.u32().map_err(|e| e.to_string())).collect()
}

/// A chunk of points; a non-finite offset is refused.
pub(crate) fn decode_points(raw: &[u8]) -> Result<Vec<CellPoint>, String> {
    let mut c = Cursor::new(raw, "entry_cells");
    (0..raw.len() / CELL_POINT_SIZE)
        .map(|_| {
            let packed = c.u32s::<2>().map_err(|e| e.to_string())?;
            let p = CellPoint { packed };
            if !p.offset().iter().all(|v| v.is_finite()) {
                return Err(format!("an entry cell point's offset {:?} is not finite", p.offset()));
            }
            Ok(p)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_round_trip_at_the_stored_precision() {
        for n in [[0.0, 1.0, 0.0], [0.6, 0.0, -0.8], [-0.36, 0.48, 0.8], [0.0, 0.0, -1.0]] {
            let p = CellPoint::new([0.5, -1.25, 3.0], n).unwrap();
            assert_eq!(p.offset(), [0.5, -1.25, 3.0]);
            let back = p.normal();
            let dot: f32 = (0..3).map(|k| back[k] * n[k]).sum();
            assert!(dot > 0.9995, "{n:?} came back as {back:?}");
            assert_eq!(
                decode_points(&[p.packed[0].to_le_bytes(), p.packed[1].to_le_bytes()].concat()),
                Ok(vec![p])
            );
        }
        assert!(CellPoint::new([1e6, 0.0, 0.0], [0.0, 1.0, 0.0]).is_none());
        assert!(CellPoint::new([f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]).is_none());
    }

    #[test]
    fn cells_must_cover_the_points_in_order() {
        let p = CellPoint::new([0.0; 3], [0.0, 1.0, 0.0]).unwrap();
        let cells = EntryCells {
            ends: vec![1, 1, 3],
            points: vec![p; 3],
        };
        assert_eq!(validate(&cells, 3), Ok(()));
        assert_eq!(cells.points_of(1), &[] as &[CellPoint]);
        assert_eq!(cells.points_of(2).len(), 2);
        assert!(cells.points_of(3).is_empty());
        assert_eq!(cells.point_weight(), 1.0);
        assert!(validate(&cells, 2).is_err());
        let backwards = EntryCells {
            ends: vec![2, 1, 3],
            ..cells.clone()
        };
        assert!(validate(&backwards, 3).is_err());
        let short = EntryCells {
            ends: vec![1, 1, 2],
            ..cells
        };
        assert!(validate(&short, 3).is_err());
    }
}
