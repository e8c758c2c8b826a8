//! The probe rays section (kind 10): where each of a fixed set of directions from every probe
//! meets the scene, so that the run time gathers each probe's irradiance from the surfaces'
//! radiance of the frame (their direct light, the lightmap's indirect light and the emitters'
//! and sky's baked light) instead of from the panes' VPLs.
//!
//! Direction `d` of `M` ([`probe_ray_direction`]) is the `d`-th point of a spherical Fibonacci
//! set about +Y, the polar axis of [`crate::sh_basis`]. A ray ends at a *gather point* (a
//! covered lightmap texel: its index `y·R + x`, the exit point's position, normal, albedo and,
//! on an emissive surface, its emitted radiance and emitter group),
//! at the sky ([`RAY_SKY`]: it left the scene), or nowhere ([`RAY_BLOCKED`]: it met a back face or
//! a surface without a texel, which sends no light, as in the reference tracer). With `L_g` the
//! radiance a gather point sends (`albedo/π × irradiance` plus its emission times its group's
//! scale), probe `p`'s irradiance coefficients
//! are `c_i = Â_i · 4π/M · Σ_d Y_i(ω_d) · L(hit[p][d])` ([`ProbeRays::irradiance_sh`], `Â` the
//! clamped-cosine factors [`SH_COSINE_LOBE`]), and the sky's direct light reaches the probe
//! along the rays marked [`RAY_SKY`] ([`ProbeRays::sky_transfer`]).
//!
//! Layout (formats/prm.md §5.5), little-endian: a 32-byte header (probe count `N`, rays per
//! probe `M`, gather point count `G`, flags = 0, the atlas resolution `R`, three reserved
//! `u32` = 0), `G` gather point records of 56 bytes (texel `u32`, position, normal, albedo and
//! emission `[f32; 3]` each, emitter group `u32`), then `N × M` hits (`u32`), probe by probe.

use crate::layout::{check_flags, check_ray_count, u32_at, Cursor, PutLe};
use crate::probes::ProbeSkyTransfer;
use crate::sh::{sh_basis, SH_COEFFS};

/// Size of the section's fixed header.
pub const PROBE_RAYS_HEADER_SIZE: usize = 32;
/// Bytes of one gather point record.
pub(crate) const GATHER_POINT_SIZE: usize = 56;
/// A gather point's `emitter` when its surface emits nothing.
pub const NO_EMITTER: u32 = u32::MAX;
/// A ray that left the scene: it sees the sky.
pub const RAY_SKY: u32 = u32::MAX;
/// A ray that met a back face or a surface without a texel: it sees nothing.
pub const RAY_BLOCKED: u32 = u32::MAX - 1;
/// Most rays per probe.
pub const MAX_PROBE_RAYS: u32 = 1 << 16;
/// The clamped cosine's spherical-harmonic factors (Ramamoorthi and Hanrahan's `Â_l`: `π`,
/// `2π/3`, `π/4` for orders 0, 1, 2), per coefficient in storage order: radiance coefficients
/// times these are irradiance coefficients.
pub const SH_COSINE_LOBE: [f32; SH_COEFFS] = {
    let pi = std::f32::consts::PI;
    let (a1, a2) = (2.0 * pi / 3.0, pi / 4.0);
    [pi, a1, a1, a1, a2, a2, a2, a2, a2]
};

/// Where a probe ray ends on a surface: a covered lightmap texel and its exit point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GatherPoint {
    /// Texel index `y·R + x` in the atlas.
    pub texel: u32,
    /// The exit point's world position.
    pub position: [f32; 3],
    /// The exit point's unit normal.
    pub normal: [f32; 3],
    /// The exit point's albedo (RGB, 0 to 1).
    pub albedo: [f32; 3],
    /// The radiance its surface emits at scale 1 (RGB, W/m²/sr; zero when it emits nothing).
    pub emission: [f32; 3],
    /// The emitter group (index into the emitters section) whose run-time scale multiplies
    /// `emission`, or [`NO_EMITTER`].
    pub emitter: u32,
}

impl Default for GatherPoint {
    /// Texel 0 at the origin, facing +y, black, emitting nothing ([`NO_EMITTER`]).
    fn default() -> Self {
        GatherPoint {
            texel: 0,
            position: [0.0; 3],
            normal: [0.0, 1.0, 0.0],
            albedo: [0.0; 3],
            emission: [0.0; 3],
            emitter: NO_EMITTER,
        }
    }
}

/// Every probe's rays: `hits[p * M + d]` is where direction `d` from probe `p` ends.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeRays {
    /// Rays per probe, `M`.
    pub rays_per_probe: u32,
    /// The surface points the rays end at.
    pub points: Vec<GatherPoint>,
    /// Probe by probe, a gather point index, [`RAY_SKY`] or [`RAY_BLOCKED`] per direction.
    pub hits: Vec<u32>,
}

/// Direction `d` of `m` (unit, world space): `y = 1 − (2d + 1)/m`, azimuth `2π · frac(d·(√5 − 1)/2)`
/// from +Z towards +X, as in [`crate::sh_basis`].
pub fn probe_ray_direction(d: u32, m: u32) -> [f32; 3] {
    let y = 1.0 - (2.0 * f64::from(d) + 1.0) / f64::from(m.max(1));
    let r = (1.0 - y * y).max(0.0).sqrt();
    let golden = (5f64.sqrt() - 1.0) / 2.0;
    let phi = 2.0 * std::f64::consts::PI * (f64::from(d) * golden).fract();
    [(r * phi.sin()) as f32, y as f32, (r * phi.cos()) as f32]
}

impl ProbeRays {
    /// Number of probes.
    pub fn probes(&self) -> usize {
        self.hits.len().checked_div(self.rays_per_probe as usize).unwrap_or(0)
    }

    /// Every probe's irradiance coefficients when gather point `g` sends the radiance
    /// `radiance[g]` (RGB, W/m²/sr) and the sky nothing.
    pub fn irradiance_sh(&self, radiance: &[[f32; 3]]) -> Vec<[[f32; 3]; SH_COEFFS]> {
        let m = self.rays_per_probe;
        if m == 0 {
            return Vec::new();
        }
        let basis: Vec<[f32; SH_COEFFS]> = (0..m).map(|d| sh_basis(probe_ray_direction(d, m))).collect();
        let scale: [f32; SH_COEFFS] =
            std::array::from_fn(|i| SH_COSINE_LOBE[i] * 4.0 * std::f32::consts::PI / m as f32);
        self.hits
            .chunks_exact(m as usize)
            .map(|rays| {
                let mut c = [[0.0f32; 3]; SH_COEFFS];
                for (hit, y) in rays.iter().zip(&basis) {
                    let Some(l) = radiance.get(*hit as usize) else {
                        continue;
                    };
                    for (ci, yi) in c.iter_mut().zip(y) {
                        (0..3).for_each(|k| ci[k] += yi * l[k]);
                    }
                }
                for (ci, s) in c.iter_mut().zip(scale) {
                    ci.iter_mut().for_each(|v| *v *= s);
                }
                c
            })
            .collect()
    }

    /// Every probe's sky transfer along its [`RAY_SKY`] rays (the sky's direct light only; what
    /// it sends by the surfaces comes with their radiance): `[p][i][k] = Â_i · 4π/M ·
    /// Σ_{d to the sky} Y_i(ω_d) Y_k(ω_d)`, the same for the three channels.
    pub fn sky_transfer(&self) -> Vec<ProbeSkyTransfer> {
        let m = self.rays_per_probe;
        if m == 0 {
            return Vec::new();
        }
        let basis: Vec<[f32; SH_COEFFS]> = (0..m).map(|d| sh_basis(probe_ray_direction(d, m))).collect();
        let solid = 4.0 * std::f32::consts::PI / m as f32;
        self.hits
            .chunks_exact(m as usize)
            .map(|rays| {
                let mut t = [[0.0f32; SH_COEFFS]; SH_COEFFS];
                for (_, y) in rays.iter().zip(&basis).filter(|(h, _)| **h == RAY_SKY) {
                    for i in 0..SH_COEFFS {
                        for k in 0..SH_COEFFS {
                            t[i][k] += y[i] * y[k];
                        }
                    }
                }
                std::array::from_fn(|i| std::array::from_fn(|k| [t[i][k] * SH_COSINE_LOBE[i] * solid; 3]))
            })
            .collect()
    }
}

/// Raw size of a section of `n` probes, `m` rays each and `g` gather points; `None` on overflow.
pub(crate) fn raw_size_for(n: u64, m: u64, g: u64) -> Option<u64> {
    n.checked_mul(m)?
        .checked_mul(4)?
        .checked_add(g.checked_mul(GATHER_POINT_SIZE as u64)?)?
        .checked_add(PROBE_RAYS_HEADER_SIZE as u64)
}

/// Checks `rays` against the archive's probe count, atlas resolution and emitter groups.
pub(crate) fn validate(rays: &ProbeRays, probes: usize, resolution: u32, groups: usize) -> Result<(), String> {
    let m = rays.rays_per_probe;
    if m == 0 || m > MAX_PROBE_RAYS {
        return Err(format!("{m} rays per probe, not between 1 and {MAX_PROBE_RAYS}"));
    }
    if rays.hits.len() != probes * m as usize {
        return Err(format!(
            "{} probe ray hits, {probes} probes × {m} rays need {}",
            rays.hits.len(),
            probes * m as usize
        ));
    }
    let texels = u64::from(resolution) * u64::from(resolution);
    validate_points(&rays.points, texels, groups)?;
    let g = rays.points.len() as u32;
    if let Some(i) = rays
        .hits
        .iter()
        .position(|&h| h >= g && h != RAY_SKY && h != RAY_BLOCKED)
    {
        return Err(format!(
            "probe {} ray {} ends at gather point {}, of {g}",
            i / m as usize,
            i % m as usize,
            rays.hits[i]
        ));
    }
    Ok(())
}

/// Checks gather points against an atlas of `texels` and the emitter groups.
pub(crate) fn validate_points(points: &[GatherPoint], texels: u64, groups: usize) -> Result<(), String> {
    if points.len() as u64 > texels {
        return Err(format!(
            "{} gather points, more than the {texels} texels of the atlas",
            points.len()
        ));
    }
    for (i, g) in points.iter().enumerate() {
        let finite = g.position.iter().chain(&g.normal).all(|v| v.is_finite());
        let albedo = g.albedo.iter().chain(&g.emission).all(|v| v.is_finite() && *v >= 0.0);
        if u64::from(g.texel) >= texels || !finite || !albedo {
            return Err(format!(
                "gather point {i} has texel {} of {texels}, or a position, normal, albedo or emission that is not finite (albedo and emission ≥ 0)",
                g.texel
            ));
        }
        if g.emitter != NO_EMITTER && g.emitter as usize >= groups {
            return Err(format!(
                "gather point {i} belongs to emitter group {} of {groups}",
                g.emitter
            ));
        }
    }
    Ok(())
}

/// Encodes validated rays for an atlas of `resolution`.
pub(crate) fn encode(rays: &ProbeRays, resolution: u32) -> Vec<u8> {
    let n = rays.probes() as u64;
    let size = raw_size_for(n, u64::from(rays.rays_per_probe), rays.points.len() as u64).unwrap_or(0);
    let mut b = Vec::with_capacity(size as usize);
    for v in [
        n as u32,
        rays.rays_per_probe,
        rays.points.len() as u32,
        0,
        resolution,
        0,
        0,
        0,
    ] {
        b.put_u32(v);
    }
    encode_points(&rays.points, &mut b);
    for h in &rays.hits {
        b.put_u32(*h);
    }
    b
}

/// Appends gather point records.
pub(crate) fn encode_points(points: &[GatherPoint], b: &mut Vec<u8>) {
    for g in points {
        b.put_u32(g.texel);
        for v in g.position.iter().chain(&g.normal).chain(&g.albedo).chain(&g.emission) {
            b.put_f32(*v);
        }
        b.put_u32(g.emitter);
    }
}

/// What the header gives: probes, rays per probe, gather points and the atlas resolution.
#[derive(Debug, PartialEq)]
pub(crate) struct Header {
    pub probes: u32,
    pub rays_per_probe: u32,
    pub points: u32,
    pub resolution: u32,
}

/// Parses and checks the header's own fields.
pub(crate) fn decode_header(head: &[u8], strict: bool) -> Result<Header, String> {
    let [probes, rays_per_probe, points, flags, resolution, r0, r1, r2] =
        Cursor::new(head, "probe rays").u32s().map_err(|e| e.to_string())?;
    check_flags("probe rays", flags, 0, strict && (r0 | r1 | r2) != 0)?;
    check_ray_count("probe rays", rays_per_probe, "probe", MAX_PROBE_RAYS)?;
    Ok(Header {
        probes,
        rays_per_probe,
        points,
        resolution,
    })
}

/// Decodes whole gather point records (checked by [`validate`] afterwards).
pub(crate) fn decode_points(raw: &[u8]) -> Result<Vec<GatherPoint>, String> {
    raw.chunks_exact(GATHER_POINT_SIZE)
        .map(|r| {
            let mut c = Cursor::new(r, "gather point");
            let err = |e: crate::Error| e.to_string();
            Ok(GatherPoint {
                texel: c.u32().map_err(err)?,
                position: c.vec3().map_err(err)?,
                normal: c.vec3().map_err(err)?,
                albedo: c.vec3().map_err(err)?,
                emission: c.vec3().map_err(err)?,
                emitter: c.u32().map_err(err)?,
            })
        })
        .collect()
}

/// Decodes whole hits.
pub(crate) fn decode_hits(raw: &[u8]) -> Result<Vec<u32>, String> {
    Ok(raw.chunks_exact(4).map(|b| u32_at(b, 0)).collect())
}

/// A gather point on texel `t` without emission, for the tests of the sections that hold them.
#[cfg(test)]
pub(crate) fn test_point(t: u32) -> GatherPoint {
    GatherPoint {
        texel: t,
        position: [t as f32, 0.5, -1.0],
        normal: [0.0, 1.0, 0.0],
        albedo: [0.5, 0.25, 1.0],
        emission: [0.0; 3],
        emitter: NO_EMITTER,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rays() -> ProbeRays {
        let point = test_point;
        let mut lamp = point(9);
        lamp.emission = [4.0, 3.0, 2.0];
        lamp.emitter = 1;
        ProbeRays {
            rays_per_probe: 4,
            points: vec![point(3), lamp],
            hits: vec![0, 1, RAY_SKY, RAY_BLOCKED, 1, 1, 1, 0],
        }
    }

    #[test]
    fn round_trip_through_the_encoding() {
        let r = rays();
        validate(&r, 2, 4, 2).unwrap();
        let raw = encode(&r, 4);
        assert_eq!(raw.len() as u64, raw_size_for(2, 4, 2).unwrap());
        let h = decode_header(&raw[..PROBE_RAYS_HEADER_SIZE], true).unwrap();
        assert_eq!(
            h,
            Header {
                probes: 2,
                rays_per_probe: 4,
                points: 2,
                resolution: 4
            }
        );
        let split = PROBE_RAYS_HEADER_SIZE + 2 * GATHER_POINT_SIZE;
        let back = ProbeRays {
            rays_per_probe: 4,
            points: decode_points(&raw[PROBE_RAYS_HEADER_SIZE..split]).unwrap(),
            hits: decode_hits(&raw[split..]).unwrap(),
        };
        assert_eq!(back, r);
    }

    #[test]
    fn rejects_what_the_layout_cannot_hold() {
        assert!(validate(&rays(), 3, 4, 2).is_err(), "probe count");
        assert!(validate(&rays(), 2, 3, 2).is_err(), "texel 9 outside a 3² atlas");
        assert!(validate(&rays(), 2, 4, 1).is_err(), "emitter group 1 of 1");
        let mut r = rays();
        r.hits[1] = 2;
        assert!(validate(&r, 2, 4, 2).is_err(), "gather point 2 of 2");
        let mut r = rays();
        r.points[0].albedo[1] = -0.1;
        assert!(validate(&r, 2, 4, 2).is_err(), "negative albedo");
        let mut r = rays();
        r.points[1].emission[2] = f32::INFINITY;
        assert!(validate(&r, 2, 4, 2).is_err(), "infinite emission");
        let mut r = rays();
        r.points[1].position[0] = f32::NAN;
        assert!(validate(&r, 2, 4, 2).is_err(), "NaN position");
        let mut head = encode(&rays(), 4)[..PROBE_RAYS_HEADER_SIZE].to_vec();
        head[4..8].copy_from_slice(&0u32.to_le_bytes());
        assert!(decode_header(&head, true).is_err(), "zero rays per probe");
    }

    #[test]
    fn the_directions_cover_the_sphere_evenly() {
        // Fibonacci points: the mean of every non-constant basis function is near 0 and the
        // orthonormality of the basis holds to a few parts in a thousand at 1024 rays.
        let m = 1024;
        let basis: Vec<[f32; SH_COEFFS]> = (0..m).map(|d| sh_basis(probe_ray_direction(d, m))).collect();
        for i in 0..SH_COEFFS {
            for k in 0..SH_COEFFS {
                let dot: f32 = basis.iter().map(|y| y[i] * y[k]).sum::<f32>() * 4.0 * std::f32::consts::PI / m as f32;
                let want = if i == k { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 5e-3, "⟨Y{i}, Y{k}⟩ = {dot}");
            }
        }
        for d in [0, 1, 511, 1023] {
            let v = probe_ray_direction(d, m);
            let len = v.iter().map(|x| x * x).sum::<f32>().sqrt();
            assert!((len - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn a_uniform_surround_gives_its_irradiance() {
        // Every ray sees radiance 1: the irradiance on any normal is π.
        let m = 2048;
        let r = ProbeRays {
            rays_per_probe: m,
            points: vec![GatherPoint {
                albedo: [1.0; 3],
                ..Default::default()
            }],
            hits: vec![0; m as usize],
        };
        let c = r.irradiance_sh(&[[1.0, 2.0, 0.5]]);
        for n in crate::AXIS_NORMALS {
            let e = crate::sh_irradiance(&c[0], n);
            let pi = std::f32::consts::PI;
            assert!((e[0] - pi).abs() < 1e-3 && (e[1] - 2.0 * pi).abs() < 2e-3, "{e:?}");
        }
        // The same rays all to the sky: the transfer maps a uniform sky of 1 to π too.
        let sky = ProbeRays {
            hits: vec![RAY_SKY; m as usize],
            ..r
        };
        let mut l = [[0.0f32; 3]; SH_COEFFS];
        l[0] = [1.0 / crate::sh_basis([0.0, 1.0, 0.0])[0]; 3];
        let e = crate::sky_irradiance_sh(&sky.sky_transfer(), &l);
        let up = crate::sh_irradiance(&e[0], [0.0, 1.0, 0.0]);
        assert!((up[0] - std::f32::consts::PI).abs() < 1e-3, "{up:?}");
    }
}
