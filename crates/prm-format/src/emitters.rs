//! The emitters section (kind 7): every emitter group's name, radiance, irradiance at the
//! entry points, and direct and (when baked) indirect irradiance at the atlas texels, per unit of
//! the group's scale.
//!
//! Layout (formats/prm.md §5.2), all little-endian: a 16-byte header (group count, entry count,
//! atlas resolution, reserved), one 88-byte record per group (a 64-byte NUL-padded UTF-8 name,
//! the material index, flags, the radiance, reserved), then per group its entry irradiance (one
//! RGB `f32` triple per entry), its direct and its indirect irradiance (one RGB9E5 word per atlas
//! texel each; the indirect all zero unless flag bit 0 is set). The sizes are fixed by the
//! header, so a reader checks the raw size before it decompresses anything past it.

use crate::layout::{check_reserved, limits, Cursor, PutLe};
use crate::rgb9e5::{decode_rgb9e5, encode_rgb9e5};

/// Size of the emitters section's fixed header.
pub const EMITTERS_HEADER_SIZE: usize = 16;
/// Size of one emitter group record.
pub const EMITTER_GROUP_RECORD_SIZE: usize = 88;
/// Group flag: the group's indirect lightmap is baked (else the player lights the entry points
/// with it and the panes carry its indirect light).
const FLAG_INDIRECT: u32 = 1;
/// Bytes of an emitter group's name field (UTF-8, NUL-padded).
pub const EMITTER_NAME_BYTES: usize = 64;

/// One group of emissive surfaces (one emissive material), as baked at scale 1.
#[derive(Clone, Debug, PartialEq)]
pub struct EmitterGroup {
    /// The material's name: at most [`EMITTER_NAME_BYTES`] bytes of UTF-8, without NUL.
    pub name: String,
    /// Index of the material in the scene the archive was baked from.
    pub material: u32,
    /// The emitted radiance (W/(m²·sr), RGB), what a surface of the group shows.
    pub radiance: [f32; 3],
    /// Irradiance at every entry point from the group (RGB, in the entries' order).
    pub entry_irradiance: Vec<[f32; 3]>,
    /// Direct irradiance at every atlas texel from the group, with visibility (RGB, row-major,
    /// `resolution²` texels; stored as RGB9E5).
    pub direct: Vec<[f32; 3]>,
    /// Indirect irradiance at every atlas texel from the group, when the bake traced it (like
    /// `direct`); `None`: the group's indirect light comes from the panes through
    /// `entry_irradiance`.
    pub indirect: Option<Vec<[f32; 3]>>,
}

/// Raw size of an emitters section, `None` on overflow.
pub(crate) fn raw_size_for(groups: u64, entries: u64, resolution: u32) -> Option<u64> {
    let texels = u64::from(resolution) * u64::from(resolution);
    let per_group = (EMITTER_GROUP_RECORD_SIZE as u64)
        .checked_add(entries.checked_mul(12)?)?
        .checked_add(texels.checked_mul(8)?)?;
    groups.checked_mul(per_group)?.checked_add(EMITTERS_HEADER_SIZE as u64)
}

fn finite_non_negative(v: &[f32; 3]) -> bool {
    v.iter().all(|c| c.is_finite() && *c >= 0.0)
}

/// Checks `groups` against the archive's entry count and atlas resolution.
pub(crate) fn validate(groups: &[EmitterGroup], entries: usize, resolution: u32) -> Result<(), String> {
    if groups.is_empty() || groups.len() as u64 > u64::from(limits::MAX_EMITTER_GROUPS) {
        return Err(format!(
            "{} emitter groups outside 1..={}",
            groups.len(),
            limits::MAX_EMITTER_GROUPS
        ));
    }
    let texels = resolution as usize * resolution as usize;
    for (g, group) in groups.iter().enumerate() {
        if group.name.len() > EMITTER_NAME_BYTES || group.name.contains('\0') {
            return Err(format!(
                "emitter group {g}'s name {:?} is longer than {EMITTER_NAME_BYTES} bytes or holds a NUL",
                group.name
            ));
        }
        if !finite_non_negative(&group.radiance) {
            return Err(format!(
                "emitter group {g}'s radiance {:?} is not finite and non-negative",
                group.radiance
            ));
        }
        if group.entry_irradiance.len() != entries {
            return Err(format!(
                "emitter group {g} has {} entry irradiances for {entries} entries",
                group.entry_irradiance.len()
            ));
        }
        if group.direct.len() != texels {
            return Err(format!(
                "emitter group {g} has {} direct texels, resolution {resolution} needs {texels}",
                group.direct.len()
            ));
        }
        if let Some(i) = group.entry_irradiance.iter().position(|e| !finite_non_negative(e)) {
            return Err(format!(
                "emitter group {g}: entry {i}'s irradiance is not finite and non-negative"
            ));
        }
        if let Some(i) = group.direct.iter().position(|e| !finite_non_negative(e)) {
            return Err(format!(
                "emitter group {g}: texel {i}'s irradiance is not finite and non-negative"
            ));
        }
        if let Some(indirect) = &group.indirect {
            if indirect.len() != texels {
                return Err(format!(
                    "emitter group {g} has {} indirect texels, resolution {resolution} needs {texels}",
                    indirect.len()
                ));
            }
            if let Some(i) = indirect.iter().position(|e| !finite_non_negative(e)) {
                return Err(format!(
                    "emitter group {g}: texel {i}'s indirect irradiance is not finite and non-negative"
                ));
            }
        }
    }
    Ok(())
}

/// Encodes validated groups.
pub(crate) fn encode(groups: &[EmitterGroup], entries: usize, resolution: u32) -> Vec<u8> {
    let size = raw_size_for(groups.len() as u64, entries as u64, resolution).unwrap_or(0);
    let mut b = Vec::with_capacity(size as usize);
    b.put_u32(groups.len() as u32);
    b.put_u32(entries as u32);
    b.put_u32(resolution);
    b.put_u32(0);
    for g in groups {
        let mut name = [0u8; EMITTER_NAME_BYTES];
        name[..g.name.len()].copy_from_slice(g.name.as_bytes());
        b.extend_from_slice(&name);
        b.put_u32(g.material);
        b.put_u32(if g.indirect.is_some() { FLAG_INDIRECT } else { 0 });
        b.put_vec3(g.radiance);
        b.put_u32(0);
    }
    for g in groups {
        for e in &g.entry_irradiance {
            b.put_vec3(*e);
        }
        for t in &g.direct {
            b.put_u32(encode_rgb9e5(*t));
        }
        match &g.indirect {
            Some(indirect) => indirect.iter().for_each(|t| b.put_u32(encode_rgb9e5(*t))),
            None => b.resize(b.len() + g.direct.len() * 4, 0),
        }
    }
    b
}

/// Parses the header: `(groups, entries, resolution)`; checks the group limit and, if `strict`,
/// the reserved field. The caller checks entries and resolution against the archive.
pub(crate) fn decode_header(head: &[u8], strict: bool) -> Result<(u32, u32, u32), String> {
    let [groups, entries, resolution, reserved] = Cursor::new(head, "emitters").u32s().map_err(|e| e.to_string())?;
    check_reserved("emitters", strict, reserved)?;
    if groups == 0 || groups > limits::MAX_EMITTER_GROUPS {
        return Err(format!(
            "{groups} emitter groups outside 1..={}",
            limits::MAX_EMITTER_GROUPS
        ));
    }
    Ok((groups, entries, resolution))
}

/// Decodes whole 88-byte group records into groups with empty arrays (`indirect` is
/// `Some(empty)` where flag bit 0 is set); `strict` demands a zero reserved field.
pub(crate) fn decode_groups(raw: &[u8], strict: bool) -> Result<Vec<EmitterGroup>, String> {
    let err = |e: crate::Error| e.to_string();
    let mut c = Cursor::new(raw, "emitter group");
    let mut out = Vec::with_capacity(raw.len() / EMITTER_GROUP_RECORD_SIZE);
    while out.len() < raw.len() / EMITTER_GROUP_RECORD_SIZE {
        let g = out.len();
        let name = c.bytes(EMITTER_NAME_BYTES).map_err(err)?;
        let len = name.iter().position(|&b| b == 0).unwrap_or(EMITTER_NAME_BYTES);
        if name[len..].iter().any(|&b| b != 0) {
            return Err(format!("emitter group {g}'s name has bytes after its NUL padding"));
        }
        let name = std::str::from_utf8(&name[..len])
            .map_err(|_| format!("emitter group {g}'s name is not UTF-8"))?
            .to_owned();
        let material = c.u32().map_err(err)?;
        let flags = c.u32().map_err(err)?;
        let radiance = c.vec3().map_err(err)?;
        let reserved = c.u32().map_err(err)?;
        if flags & !FLAG_INDIRECT != 0 || (strict && reserved != 0) {
            return Err(format!(
                "emitter group {g} has unknown flags {flags:#x} or a non-zero reserved field"
            ));
        }
        if !finite_non_negative(&radiance) {
            return Err(format!(
                "emitter group {g}'s radiance {radiance:?} is not finite and non-negative"
            ));
        }
        out.push(EmitterGroup {
            name,
            material,
            radiance,
            entry_irradiance: Vec::new(),
            direct: Vec::new(),
            indirect: (flags & FLAG_INDIRECT != 0).then(Vec::new),
        });
    }
    Ok(out)
}

/// Decodes whole 12-byte entry irradiance records.
pub(crate) fn decode_entry_irradiance(raw: &[u8]) -> Result<Vec<[f32; 3]>, String> {
    let mut c = Cursor::new(raw, "emitter entry irradiance");
    let mut out = Vec::with_capacity(raw.len() / 12);
    while out.len() < raw.len() / 12 {
        let e = c.vec3().map_err(|e| e.to_string())?;
        if !finite_non_negative(&e) {
            return Err(format!("an emitter irradiance {e:?} is not finite and non-negative"));
        }
        out.push(e);
    }
    Ok(out)
}

/// Decodes whole RGB9E5 words (always finite and non-negative).
pub(crate) fn decode_direct(raw: &[u8]) -> Result<Vec<[f32; 3]>, String> {
    Ok(raw
        .chunks_exact(4)
        .map(|w| decode_rgb9e5(u32::from_le_bytes([w[0], w[1], w[2], w[3]])))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn group(name: &str, entries: usize, res: u32) -> EmitterGroup {
        EmitterGroup {
            name: name.into(),
            material: 3,
            radiance: [17.0, 12.0, 4.0],
            entry_irradiance: (0..entries).map(|i| [i as f32, 0.5, 2.0]).collect(),
            direct: (0..res * res).map(|i| [i as f32 * 0.25, 1.0, 0.0]).collect(),
            indirect: Some((0..res * res).map(|i| [0.5, i as f32, 2.0]).collect()),
        }
    }

    #[test]
    fn round_trip_through_the_encoding() {
        let mut groups = vec![group("light", 3, 4), group("lámpara", 3, 4)];
        groups[1].indirect = None;
        validate(&groups, 3, 4).unwrap();
        let raw = encode(&groups, 3, 4);
        assert_eq!(raw.len() as u64, raw_size_for(2, 3, 4).unwrap());
        let (n, entries, res) = decode_header(&raw[..EMITTERS_HEADER_SIZE], true).unwrap();
        assert_eq!((n, entries, res), (2, 3, 4));
        let mut at = EMITTERS_HEADER_SIZE + 2 * EMITTER_GROUP_RECORD_SIZE;
        let mut back = decode_groups(&raw[EMITTERS_HEADER_SIZE..at], true).unwrap();
        for g in &mut back {
            g.entry_irradiance = decode_entry_irradiance(&raw[at..at + 36]).unwrap();
            at += 36;
            g.direct = decode_direct(&raw[at..at + 64]).unwrap();
            at += 64;
            if let Some(indirect) = &mut g.indirect {
                *indirect = decode_direct(&raw[at..at + 64]).unwrap();
            }
            at += 64;
        }
        // Small integers and quarters are exact in RGB9E5.
        assert_eq!(back, groups);
    }

    #[test]
    fn rejects_what_the_layout_cannot_hold() {
        assert!(validate(&[], 3, 4).is_err(), "no group");
        let long = group(&"x".repeat(EMITTER_NAME_BYTES + 1), 3, 4);
        assert!(validate(&[long], 3, 4).is_err());
        assert!(validate(&[group("a", 2, 4)], 3, 4).is_err(), "entry count");
        assert!(validate(&[group("a", 3, 2)], 3, 4).is_err(), "resolution");
        let mut nan = group("a", 3, 4);
        nan.entry_irradiance[1][0] = f32::NAN;
        assert!(validate(&[nan], 3, 4).is_err());
        let mut head = encode(&[group("a", 3, 4)], 3, 4);
        head[..4].copy_from_slice(&(limits::MAX_EMITTER_GROUPS + 1).to_le_bytes());
        assert!(decode_header(&head[..16], true).is_err(), "group limit");
        let mut raw = encode(&[group("a", 3, 4)], 3, 4);
        raw[16 + 10] = b'z'; // after the NUL that ends "a"
        assert!(decode_groups(&raw[16..104], true).is_err());
        let mut raw = encode(&[group("a", 3, 4)], 3, 4);
        raw[16 + 68] = 2; // an unknown flag
        assert!(decode_groups(&raw[16..104], false).is_err());
    }
}
