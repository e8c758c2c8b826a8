//! The probes section (kind 9): irradiance probes in the scene's empty space, baked as extra
//! exit points of the same panes. For every cluster `c` and probe `p` it stores the nine
//! spherical-harmonic coefficients (RGB, basis [`crate::sh_basis`]) of the indirect irradiance
//! the cluster's VPLs give the probe per unit weight, already convolved with the clamped cosine:
//! with the run time's cluster weights `w_c`, a surface of unit normal `n` at the probe receives
//! `E(n) = Σ_c w_c ⊙ Σ_i T[c][p][i] · Y_i(n)`.
//!
//! Layout (formats/prm.md §5.4), little-endian: a 48-byte header (probe count `N`, cluster
//! count `C`, coefficient count = [`SH_COEFFS`], flags = 0, grid dimensions `nx, ny, nz`,
//! reserved = 0, grid origin `[f32; 3]`, cell spacing `f32`), then `N` probe records of 16 bytes
//! (cell index `u32`, position `[f32; 3]`), then `C × N` transfers of 9 RGB `f16` (54 bytes),
//! cluster by cluster, and with flag bit 0 ([`FLAG_SKY`]) `N` sky transfers of 9 × 9 RGB `f16`
//! (486 bytes): probe `p`'s irradiance coefficient `i` per unit of the sky's coefficient `k`
//! (direct and after bounces). Cell `(i, j, k)` is index `i + nx·(j + ny·k)`, its centre
//! `origin + spacing·(i + ½, j + ½, k + ½)`; cells without a probe (inside geometry) are absent,
//! and the indices increase strictly. `f16` for the same reason as the sky section: noise that
//! does not compress, carried far above its precision.

use crate::layout::{check_flags, Cursor, PutLe};
use crate::sh::SH_COEFFS;

/// Size of the probes section's fixed header.
pub const PROBES_HEADER_SIZE: usize = 48;
/// Bytes of one probe record.
pub(crate) const PROBE_RECORD_SIZE: usize = 16;
/// Bytes of one cluster's transfer to one probe.
pub(crate) const PROBE_TRANSFER_BYTES: usize = SH_COEFFS * 6;
/// Flag bit 0: the section holds the sky's transfer to every probe.
pub const FLAG_SKY: u32 = 1;
/// Bytes of one probe's sky transfer.
pub(crate) const PROBE_SKY_BYTES: usize = SH_COEFFS * SH_COEFFS * 6;
/// A probe's sky transfer: `[i][k]` is irradiance coefficient `i` (RGB) per unit of the sky's
/// coefficient `k`.
pub type ProbeSkyTransfer = [[[f32; 3]; SH_COEFFS]; SH_COEFFS];

/// Most probes a section may hold.
pub const MAX_PROBES: u32 = 1 << 16;
/// Most grid cells a section may span.
pub const MAX_PROBE_CELLS: u64 = 1 << 24;

/// The regular grid the probes sit on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeGrid {
    /// Cells along x, y and z (each at least 1).
    pub dims: [u32; 3],
    /// World position of the grid's lower corner.
    pub origin: [f32; 3],
    /// Edge of a (cubic) cell, positive.
    pub spacing: f32,
}

impl ProbeGrid {
    /// Number of cells.
    pub fn cells(&self) -> u64 {
        self.dims.iter().map(|&d| u64::from(d)).product()
    }

    /// Centre of cell `index` (`i + nx·(j + ny·k)`).
    pub fn cell_centre(&self, index: u32) -> [f32; 3] {
        let [nx, ny, _] = self.dims;
        let ijk = [index % nx, (index / nx) % ny, index / (nx * ny)];
        std::array::from_fn(|a| self.origin[a] + self.spacing * (ijk[a] as f32 + 0.5))
    }
}

/// The probes of an archive and every cluster's transfer to them.
#[derive(Clone, Debug, PartialEq)]
pub struct Probes {
    /// The grid.
    pub grid: ProbeGrid,
    /// Each probe's cell, strictly increasing.
    pub cells: Vec<u32>,
    /// Each probe's world position (its cell's centre, or moved off a surface).
    pub positions: Vec<[f32; 3]>,
    /// Cluster-major: `transfer[c * N + p]` is cluster `c`'s irradiance coefficients at probe `p`
    /// per unit weight.
    pub transfer: Vec<[[f32; 3]; SH_COEFFS]>,
    /// The sky's transfer to every probe (bakes with the sky), `[p]`: the probes' irradiance
    /// coefficients under a sky of coefficients `L_k` are `Σ_k sky[p][i][k] ⊙ L_k`.
    pub sky: Option<Vec<ProbeSkyTransfer>>,
}

impl Probes {
    /// Number of probes.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Number of clusters the transfer covers.
    pub fn clusters(&self) -> usize {
        self.transfer.len().checked_div(self.len()).unwrap_or(0)
    }

    /// Every probe's irradiance coefficients under the cluster weights `weights` (one RGB
    /// weight per cluster): `Σ_c w_c ⊙ T[c][p]`.
    pub fn irradiance_sh(&self, weights: &[[f32; 3]]) -> Vec<[[f32; 3]; SH_COEFFS]> {
        let n = self.len();
        let mut out = vec![[[0.0f32; 3]; SH_COEFFS]; n];
        for (c, w) in weights.iter().enumerate().take(self.clusters()) {
            for (p, o) in out.iter_mut().enumerate() {
                for (oi, ti) in o.iter_mut().zip(&self.transfer[c * n + p]) {
                    for k in 0..3 {
                        oi[k] += w[k] * ti[k];
                    }
                }
            }
        }
        out
    }

    /// Every probe's irradiance coefficients from the sky of coefficients `coeffs` (RGB radiance
    /// in the basis of [`crate::sh_basis`], turned and scaled), direct and bounced; zeros without
    /// a sky transfer.
    pub fn sky_irradiance_sh(&self, coeffs: &[[f32; 3]; SH_COEFFS]) -> Vec<[[f32; 3]; SH_COEFFS]> {
        match &self.sky {
            Some(sky) => sky_irradiance_sh(sky, coeffs),
            None => vec![[[0.0; 3]; SH_COEFFS]; self.len()],
        }
    }
}

/// Each probe's irradiance coefficients from its sky transfer `sky[p]` under the sky `coeffs`:
/// `Σ_k sky[p][i][k] ⊙ coeffs[k]` ([`Probes::sky_irradiance_sh`] on a transfer kept alone).
pub fn sky_irradiance_sh(sky: &[ProbeSkyTransfer], coeffs: &[[f32; 3]; SH_COEFFS]) -> Vec<[[f32; 3]; SH_COEFFS]> {
    sky.iter()
        .map(|m| {
            std::array::from_fn(|i| {
                let mut e = [0.0f32; 3];
                for (t, l) in m[i].iter().zip(coeffs) {
                    for c in 0..3 {
                        e[c] += t[c] * l[c];
                    }
                }
                e
            })
        })
        .collect()
}

/// The six axis directions, +X −X +Y −Y +Z −Z: the normals probes are compared and summarised at.
pub const AXIS_NORMALS: [[f32; 3]; 6] = [
    [1.0, 0.0, 0.0],
    [-1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.0, 0.0, -1.0],
];

/// The irradiance (RGB) on a surface of unit normal `n` from irradiance coefficients `coeffs`.
pub fn sh_irradiance(coeffs: &[[f32; 3]; SH_COEFFS], n: [f32; 3]) -> [f32; 3] {
    let y = crate::sh::sh_basis(n);
    let mut e = [0.0f32; 3];
    for (c, yi) in coeffs.iter().zip(y) {
        for k in 0..3 {
            e[k] += c[k] * yi;
        }
    }
    e
}

/// Raw size of a probes section, `None` on overflow.
pub(crate) fn raw_size_for(probes: u64, clusters: u64, sky: bool) -> Option<u64> {
    let sky_bytes = if sky { PROBE_SKY_BYTES as u64 } else { 0 };
    probes
        .checked_mul(clusters)?
        .checked_mul(PROBE_TRANSFER_BYTES as u64)?
        .checked_add(probes.checked_mul(PROBE_RECORD_SIZE as u64 + sky_bytes)?)?
        .checked_add(PROBES_HEADER_SIZE as u64)
}

/// Checks the grid's own fields.
fn validate_grid(grid: &ProbeGrid) -> Result<(), String> {
    if grid.dims.contains(&0) || grid.cells() > MAX_PROBE_CELLS {
        return Err(format!(
            "probe grid {:?} is empty or has more than {MAX_PROBE_CELLS} cells",
            grid.dims
        ));
    }
    let finite = grid.spacing.is_finite() && grid.spacing > 0.0 && grid.origin.iter().all(|v| v.is_finite());
    if !finite {
        return Err(format!(
            "probe grid origin {:?} or spacing {} is not finite and positive",
            grid.origin, grid.spacing
        ));
    }
    Ok(())
}

/// Checks `probes` against the archive's cluster count.
pub(crate) fn validate(probes: &Probes, clusters: usize) -> Result<(), String> {
    validate_grid(&probes.grid)?;
    let n = probes.len();
    if n == 0 || n > MAX_PROBES as usize || probes.positions.len() != n {
        return Err(format!(
            "{n} probe cells and {} positions: need as many, between 1 and {MAX_PROBES}",
            probes.positions.len()
        ));
    }
    if probes.transfer.len() != n * clusters {
        return Err(format!(
            "probe transfer has {} values, {clusters} clusters × {n} probes need {}",
            probes.transfer.len(),
            n * clusters
        ));
    }
    let cells = probes.grid.cells();
    if probes.cells.windows(2).any(|w| w[0] >= w[1]) || u64::from(*probes.cells.last().unwrap_or(&0)) >= cells {
        return Err("probe cells must increase strictly and lie in the grid".to_string());
    }
    if let Some(p) = probes.positions.iter().position(|v| !v.iter().all(|x| x.is_finite())) {
        return Err(format!("probe {p}'s position is not finite"));
    }
    let storable = |v: &f32| v.abs() <= crate::sky::SKY_MAX_VALUE;
    if let Some(sky) = &probes.sky {
        if sky.len() != n {
            return Err(format!("{} probe sky transfers for {n} probes", sky.len()));
        }
        if let Some(p) = sky.iter().position(|m| !m.iter().flatten().flatten().all(storable)) {
            return Err(format!(
                "probe {p}'s sky transfer is not finite within ±{}",
                crate::sky::SKY_MAX_VALUE
            ));
        }
    }
    if let Some(i) = probes.transfer.iter().position(|t| !t.iter().flatten().all(storable)) {
        return Err(format!(
            "probe transfer {i} (cluster {}, probe {}) is not finite within ±{}",
            i / n,
            i % n,
            crate::sky::SKY_MAX_VALUE
        ));
    }
    Ok(())
}

/// Encodes validated probes.
pub(crate) fn encode(probes: &Probes) -> Vec<u8> {
    let n = probes.len() as u64;
    let clusters = probes.clusters() as u64;
    let mut b = Vec::with_capacity(raw_size_for(n, clusters, probes.sky.is_some()).unwrap_or(0) as usize);
    b.put_u32(n as u32);
    b.put_u32(clusters as u32);
    b.put_u32(SH_COEFFS as u32);
    b.put_u32(if probes.sky.is_some() { FLAG_SKY } else { 0 });
    for d in probes.grid.dims {
        b.put_u32(d);
    }
    b.put_u32(0);
    for o in probes.grid.origin {
        b.put_f32(o);
    }
    b.put_f32(probes.grid.spacing);
    for (cell, pos) in probes.cells.iter().zip(&probes.positions) {
        b.put_u32(*cell);
        for v in pos {
            b.put_f32(*v);
        }
    }
    for v in probes.transfer.iter().flatten().flatten() {
        b.extend_from_slice(&half::f16::from_f32(*v).to_le_bytes());
    }
    for v in probes.sky.iter().flatten().flatten().flatten().flatten() {
        b.extend_from_slice(&half::f16::from_f32(*v).to_le_bytes());
    }
    b
}

/// What the header gives: probe count, cluster count, grid and whether the sky transfer follows.
#[derive(Debug, PartialEq)]
pub(crate) struct Header {
    pub probes: u32,
    pub clusters: u32,
    pub grid: ProbeGrid,
    pub sky: bool,
}

/// Parses and checks the header. The caller checks the cluster count against the archive.
pub(crate) fn decode_header(head: &[u8], strict: bool) -> Result<Header, String> {
    let err = |e: crate::Error| e.to_string();
    let mut c = Cursor::new(head, "probes");
    let [n, clusters, coeffs, flags, dx, dy, dz, reserved] = c.u32s().map_err(err)?;
    let dims = [dx, dy, dz];
    let origin = c.vec3().map_err(err)?;
    let spacing = c.f32().map_err(err)?;
    if coeffs != SH_COEFFS as u32 {
        return Err(format!(
            "probes section has {coeffs} coefficients per probe, this reader knows {SH_COEFFS}"
        ));
    }
    check_flags("probes", flags, FLAG_SKY, strict && reserved != 0)?;
    if n == 0 || n > MAX_PROBES {
        return Err(format!("probes section has {n} probes, not between 1 and {MAX_PROBES}"));
    }
    let grid = ProbeGrid { dims, origin, spacing };
    validate_grid(&grid)?;
    Ok(Header {
        probes: n,
        clusters,
        grid,
        sky: flags & FLAG_SKY != 0,
    })
}

/// Decodes whole probe records; positions must be finite.
pub(crate) fn decode_records(raw: &[u8]) -> Result<Vec<(u32, [f32; 3])>, String> {
    raw.chunks_exact(PROBE_RECORD_SIZE)
        .map(|r| {
            let mut c = Cursor::new(r, "probe");
            let cell = c.u32().map_err(|e| e.to_string())?;
            let pos = c.vec3().map_err(|e| e.to_string())?;
            if !pos.iter().all(|v| v.is_finite()) {
                return Err(format!("probe in cell {cell} has a position that is not finite"));
            }
            Ok((cell, pos))
        })
        .collect()
}

/// Decodes whole sky transfers; infinities and NaNs are refused.
pub(crate) fn decode_sky(raw: &[u8]) -> Result<Vec<ProbeSkyTransfer>, String> {
    let v = decode_transfer(raw)?;
    Ok(v.chunks_exact(SH_COEFFS)
        .map(|m| std::array::from_fn(|i| m[i]))
        .collect())
}

/// Decodes whole transfers; infinities and NaNs are refused.
pub(crate) fn decode_transfer(raw: &[u8]) -> Result<Vec<[[f32; 3]; SH_COEFFS]>, String> {
    crate::sky::decode_indirect(raw).map_err(|_| "a probe transfer value is not finite".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn probes(clusters: usize) -> Probes {
        let grid = ProbeGrid {
            dims: [2, 3, 1],
            origin: [-1.0, 0.0, 0.5],
            spacing: 0.5,
        };
        let cells = vec![0, 2, 5];
        let positions = cells.iter().map(|&c| grid.cell_centre(c)).collect();
        let transfer = (0..clusters * 3)
            .map(|i| std::array::from_fn(|c| [i as f32, -(c as f32), 0.25]))
            .collect();
        Probes {
            grid,
            cells,
            positions,
            transfer,
            sky: None,
        }
    }

    fn sky(n: usize) -> Vec<ProbeSkyTransfer> {
        (0..n)
            .map(|p| std::array::from_fn(|i| std::array::from_fn(|k| [p as f32, i as f32 * 0.5, -(k as f32)])))
            .collect()
    }

    #[test]
    fn round_trip_through_the_encoding() {
        for with_sky in [false, true] {
            let mut p = probes(4);
            p.sky = with_sky.then(|| sky(3));
            validate(&p, 4).unwrap();
            let raw = encode(&p);
            assert_eq!(raw.len() as u64, raw_size_for(3, 4, with_sky).unwrap());
            let h = decode_header(&raw[..PROBES_HEADER_SIZE], true).unwrap();
            assert_eq!((h.probes, h.clusters, h.grid, h.sky), (3, 4, p.grid, with_sky));
            let split = PROBES_HEADER_SIZE + 3 * PROBE_RECORD_SIZE;
            let end = split + 12 * PROBE_TRANSFER_BYTES;
            let records = decode_records(&raw[PROBES_HEADER_SIZE..split]).unwrap();
            let back = Probes {
                grid: h.grid,
                cells: records.iter().map(|r| r.0).collect(),
                positions: records.iter().map(|r| r.1).collect(),
                transfer: decode_transfer(&raw[split..end]).unwrap(),
                sky: with_sky.then(|| decode_sky(&raw[end..]).unwrap()),
            };
            assert_eq!(back, p);
        }
        assert_eq!(probes(1).grid.cell_centre(5), [-0.25, 1.25, 0.75]);
    }

    #[test]
    fn the_sky_transfer_maps_sky_coefficients_to_irradiance_coefficients() {
        let mut p = probes(1);
        assert_eq!(p.sky_irradiance_sh(&[[1.0; 3]; SH_COEFFS])[0], [[0.0; 3]; SH_COEFFS]);
        p.sky = Some(sky(3));
        let mut l = [[0.0f32; 3]; SH_COEFFS];
        l[2] = [2.0, 1.0, 1.0];
        // Probe 1, coefficient 4: [1, 2, -2] ⊙ [2, 1, 1].
        assert_eq!(p.sky_irradiance_sh(&l)[1][4], [2.0, 2.0, -2.0]);
        let mut short = p.clone();
        short.sky = Some(sky(2));
        assert!(validate(&short, 1).is_err(), "one sky transfer per probe");
    }

    #[test]
    fn rejects_what_the_layout_cannot_hold() {
        assert!(validate(&probes(4), 5).is_err(), "cluster count");
        let mut p = probes(2);
        p.cells = vec![0, 2, 2];
        assert!(validate(&p, 2).is_err(), "repeated cell");
        let mut p = probes(2);
        p.cells[2] = 6;
        assert!(validate(&p, 2).is_err(), "cell outside the grid");
        let mut p = probes(2);
        p.grid.spacing = 0.0;
        assert!(validate(&p, 2).is_err(), "spacing");
        let mut p = probes(2);
        p.transfer[1][3][0] = 1e6;
        assert!(validate(&p, 2).is_err(), "beyond f16");
        let mut p = probes(2);
        p.positions[0][1] = f32::NAN;
        assert!(validate(&p, 2).is_err(), "position");
        let raw = encode(&probes(2));
        let mut bad = raw.clone();
        bad[8] = 16;
        assert!(decode_header(&bad[..PROBES_HEADER_SIZE], true).is_err(), "coefficients");
        let mut bad = raw.clone();
        bad[0..4].copy_from_slice(&(MAX_PROBES + 1).to_le_bytes());
        assert!(decode_header(&bad[..PROBES_HEADER_SIZE], true).is_err(), "count");
        let mut bad = raw.clone();
        bad[16..20].copy_from_slice(&u32::MAX.to_le_bytes());
        bad[20..24].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode_header(&bad[..PROBES_HEADER_SIZE], true).is_err(), "grid size");
        let mut bad = raw;
        bad[28] = 1;
        assert!(decode_header(&bad[..PROBES_HEADER_SIZE], true).is_err(), "reserved");
        assert!(
            decode_header(&bad[..PROBES_HEADER_SIZE], false).is_ok(),
            "reserved, lenient"
        );
    }

    #[test]
    fn irradiance_sums_the_weighted_clusters() {
        let p = probes(2);
        let sh = p.irradiance_sh(&[[1.0, 0.0, 2.0], [0.5, 1.0, 0.0]]);
        // Probe 1: cluster 0's transfer index 1, cluster 1's index 4.
        assert_eq!(sh[1][0], [1.0 + 2.0, 0.0, 0.5]);
        let mut flat = [[0.0f32; 3]; SH_COEFFS];
        flat[0] = [1.0, 2.0, 3.0];
        let y00 = crate::sh::sh_basis([0.0, 1.0, 0.0])[0];
        assert_eq!(sh_irradiance(&flat, [0.0, 1.0, 0.0]), [y00, 2.0 * y00, 3.0 * y00]);
    }
}
