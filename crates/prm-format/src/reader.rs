//! Validating archive reader: `Archive` over a file, a byte slice or any `Read + Seek`.
//!
//! Over 600 lines on purpose: every section's bounds and size checks sit next to the read they
//! guard (hostile sizes are refused before any allocation), so splitting by section would
//! separate checks from reads.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use xxhash_rust::xxh3::Xxh3Default;

use crate::basis::{self, PaneBasis, PANES_HEADER_SIZE};
use crate::emitters::EmitterGroup;
use crate::error::{Error, Result};
use crate::layout::{
    checksum, compression, kind, limits, Cursor, Header, SectionRecord, ATLAS_HEADER_SIZE, CLUSTER_RECORD_SIZE,
    ENTRY_ENERGY_RECORD_SIZE, ENTRY_RECORD_SIZE, HEADER_SIZE, SECTION_RECORD_SIZE,
};
use crate::metadata::Metadata;
use crate::probes::Probes;
use crate::rgb9e5::encode_rgb9e5;
use crate::sections::{
    decode_clusters, decode_entries, decode_entry_energy, entries_covered, validate_entries_clusters, AtlasSection,
    Cluster, Entry,
};
use crate::sky::SkyTransfer;

/// Largest raw size this reader decompresses for a section kind it does not
/// interpret (see [`Archive::read_custom_section`]).
const MAX_CUSTOM_SECTION_BYTES: u64 = 1 << 30;

/// One record of the section table.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SectionInfo {
    /// Kind code.
    pub kind: u32,
    /// `"metadata"`, `"atlas"`, … or `"unknown (kind N)"`.
    pub name: String,
    /// Compression code (0 none, 1 zstd).
    pub compression: u32,
    /// Byte offset in the file.
    pub offset: u64,
    /// Bytes stored in the file.
    pub stored_size: u64,
    /// Bytes after decompression.
    pub raw_size: u64,
    /// xxh3-64 of the stored bytes.
    pub checksum: u64,
}

/// Summary of an archive's structure.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ArchiveInfo {
    /// Major format version.
    pub major: u16,
    /// Minor format version.
    pub minor: u16,
    /// File size in bytes.
    pub file_length: u64,
    /// The section table, in file order of the table.
    pub sections: Vec<SectionInfo>,
    /// Number of panes (= clusters).
    pub pane_count: u32,
    /// Atlas tiles (`(resolution / tile_size)²`), each with its own basis.
    pub tiles: u64,
    /// The largest rank of a tile's basis.
    pub max_rank: u32,
    /// The ranks of all tiles summed (their mean is this over [`tiles`](Self::tiles)).
    pub rank_sum: u64,
    /// Bytes of the tiles' bases (`f16`) in the panes section.
    pub basis_bytes: u64,
    /// Bytes of the tiles' coefficients (`f16`) and their scales (`f32`) in the panes section.
    pub coefficient_bytes: u64,
    /// Bytes of all panes as dense RGB9E5 texels (`pane_count × resolution² × 4`), what a run
    /// time that uploads them whole holds.
    pub pane_texel_bytes: u64,
}

/// What [`Archive::verify`] checked.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VerifyReport {
    /// Sections whose checksum was verified (including unknown ones).
    pub sections: usize,
    /// Panes decoded and checked against their cluster's energy and peak.
    pub panes: u32,
    /// Bytes hashed.
    pub bytes_hashed: u64,
}

/// An open archive. Every section it interprets (metadata, atlas, entries, clusters, the panes'
/// bases and the optional ones) is read and validated on open; [`verify`](Self::verify) also
/// checks every checksum and the clusters' energy and peak.
pub struct Archive<R> {
    src: R,
    info: ArchiveInfo,
    records: Vec<SectionRecord>,
    metadata: Metadata,
    atlas: AtlasSection,
    entries: Vec<Entry>,
    optional: OptionalSections,
    clusters: Vec<Cluster>,
    panes: PaneBasis,
}

impl Archive<BufReader<File>> {
    /// Opens and validates the archive at `path`.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        Archive::from_reader(BufReader::new(File::open(path)?))
    }
}

impl<'a> Archive<std::io::Cursor<&'a [u8]>> {
    /// Opens and validates an archive held in memory.
    pub fn from_bytes(bytes: &'a [u8]) -> Result<Self> {
        Archive::from_reader(std::io::Cursor::new(bytes))
    }
}

fn section_name(kind: u32) -> String {
    match kind::name(kind) {
        Some(n) => n.to_string(),
        None => format!("unknown (kind {kind})"),
    }
}

/// Reads exactly `len` bytes at `offset`; a short read is `Truncated`.
fn read_at<R: Read + Seek>(src: &mut R, offset: u64, len: u64, what: &str) -> Result<Vec<u8>> {
    let len_usize = usize::try_from(len).map_err(|_| Error::inconsistent(format!("{what} too large")))?;
    src.seek(SeekFrom::Start(offset))?;
    let mut buf = Vec::new();
    src.take(len).read_to_end(&mut buf)?;
    if buf.len() != len_usize {
        return Err(Error::truncated(format!(
            "{what}: expected {len} bytes at offset {offset}, got {}",
            buf.len()
        )));
    }
    Ok(buf)
}

/// Reads and checks the header against the file's length; returns it and that length.
fn read_header<R: Read + Seek>(src: &mut R) -> Result<(Header, u64)> {
    let file_length = src.seek(SeekFrom::End(0))?;
    let head_len = file_length.min(HEADER_SIZE as u64);
    let head = read_at(src, 0, head_len, "header")?;
    let header = Header::decode(&head)?;
    if header.file_length > file_length {
        return Err(Error::truncated(format!(
            "the header declares {} bytes, the file has {file_length}",
            header.file_length
        )));
    }
    if header.file_length < file_length {
        return Err(Error::inconsistent(format!(
            "{} bytes follow the declared end of the archive",
            file_length - header.file_length
        )));
    }
    if header.strict_reserved() && header.reserved != [0, 0] {
        return Err(Error::inconsistent("reserved header fields are not zero"));
    }
    if header.section_count > limits::MAX_SECTIONS {
        return Err(Error::inconsistent(format!(
            "{} sections exceed the limit",
            header.section_count
        )));
    }
    Ok((header, file_length))
}

/// Reads the section table and checks its checksum and that every section lies after the
/// header, inside the file, and overlaps neither another section nor the table.
fn read_section_table<R: Read + Seek>(src: &mut R, header: &Header, file_length: u64) -> Result<Vec<SectionRecord>> {
    let strict = header.strict_reserved();
    let table_len = u64::from(header.section_count) * SECTION_RECORD_SIZE as u64;
    let table_end = header.table_offset.checked_add(table_len);
    if header.table_offset < HEADER_SIZE as u64 || table_end.is_none_or(|e| e > file_length) {
        return Err(Error::inconsistent(format!(
            "section table ({} records at offset {}) lies outside the file",
            header.section_count, header.table_offset
        )));
    }
    let table = read_at(src, header.table_offset, table_len, "section table")?;
    if checksum(&table) != header.table_checksum {
        return Err(Error::checksum("section table"));
    }
    let mut c = Cursor::new(&table, "section table");
    let mut records = Vec::with_capacity(header.section_count as usize);
    for _ in 0..header.section_count {
        records.push(SectionRecord::decode(&mut c)?);
    }
    let mut spans: Vec<(u64, u64, String)> = vec![(
        header.table_offset,
        header.table_offset + table_len,
        "section table".into(),
    )];
    for r in &records {
        let name = section_name(r.kind);
        if strict && r.reserved != 0 {
            return Err(Error::inconsistent(format!("{name}: reserved field is not zero")));
        }
        if r.kind == 0 {
            return Err(Error::inconsistent("section kind 0 is invalid"));
        }
        let end = r.offset.checked_add(r.stored_size);
        if r.offset < HEADER_SIZE as u64 || end.is_none_or(|e| e > file_length) {
            return Err(Error::inconsistent(format!(
                "{name} section ({} bytes at offset {}) lies outside the file",
                r.stored_size, r.offset
            )));
        }
        spans.push((r.offset, r.offset + r.stored_size, name));
    }
    spans.sort();
    for w in spans.windows(2) {
        if w[0].1 > w[1].0 {
            return Err(Error::inconsistent(format!("{} overlaps {}", w[0].2, w[1].2)));
        }
    }
    Ok(records)
}

/// The records of the sections the reader interprets.
struct SectionRecords {
    metadata: SectionRecord,
    atlas: SectionRecord,
    entries: SectionRecord,
    clusters: SectionRecord,
    panes: SectionRecord,
    entry_energy: Option<SectionRecord>,
    emitters: Option<SectionRecord>,
    sky: Option<SectionRecord>,
    probes: Option<SectionRecord>,
    probe_rays: Option<SectionRecord>,
    near_field: Option<SectionRecord>,
    entry_cells: Option<SectionRecord>,
}

impl SectionRecords {
    /// Finds the required sections and the optional ones; each kind at most once.
    fn find(records: &[SectionRecord]) -> Result<SectionRecords> {
        let required = |k: u32| {
            optional_section(records, k)?
                .ok_or_else(|| Error::inconsistent(format!("required {} section is missing", section_name(k))))
        };
        Ok(SectionRecords {
            metadata: required(kind::METADATA)?,
            atlas: required(kind::ATLAS)?,
            entries: required(kind::ENTRIES)?,
            clusters: required(kind::CLUSTERS)?,
            panes: required(kind::PANES)?,
            entry_energy: optional_section(records, kind::ENTRY_ENERGY)?,
            emitters: optional_section(records, kind::EMITTERS)?,
            sky: optional_section(records, kind::SKY)?,
            probes: optional_section(records, kind::PROBES)?,
            probe_rays: optional_section(records, kind::PROBE_RAYS)?,
            near_field: optional_section(records, kind::NEAR_FIELD)?,
            entry_cells: optional_section(records, kind::ENTRY_CELLS)?,
        })
    }
}

/// The one record of `kind`, if any; a kind twice is refused.
fn optional_section(records: &[SectionRecord], kind: u32) -> Result<Option<SectionRecord>> {
    let mut of_kind = records.iter().filter(|r| r.kind == kind);
    let first = of_kind.next().cloned();
    if of_kind.next().is_some() {
        return Err(Error::inconsistent(format!(
            "{} section appears more than once",
            section_name(kind)
        )));
    }
    Ok(first)
}

/// Reads the metadata section (at most 16 MiB of JSON) and validates it.
fn read_metadata<R: Read + Seek>(src: &mut R, rec: &SectionRecord) -> Result<Metadata> {
    let meta = open_section(src, rec)?;
    if meta.record.raw_size > limits::MAX_METADATA_BYTES {
        return Err(Error::inconsistent(format!(
            "metadata section declares {} raw bytes, more than the limit {}",
            meta.record.raw_size,
            limits::MAX_METADATA_BYTES
        )));
    }
    let raw = meta.read_all()?;
    drop(meta);
    let json = |e: serde_json::Error| Error::inconsistent(format!("metadata JSON: {e}"));
    let metadata: Metadata = serde_json::from_slice(&raw).map_err(json)?;
    metadata
        .validate()
        .map_err(|e| Error::inconsistent(format!("metadata: {e}")))?;
    Ok(metadata)
}

/// Reads the panes section (formats/prm.md §7): its 16-byte header and the tiles' ranks first,
/// checked against the atlas, then the raw size they imply, before the coefficients and the
/// bases are decompressed.
fn read_panes<R: Read + Seek>(
    src: &mut R,
    rec: &SectionRecord,
    atlas: &AtlasSection,
    strict: bool,
) -> Result<PaneBasis> {
    let header = |head: &[u8; PANES_HEADER_SIZE]| basis::decode_header(head, strict);
    read_headed_section(src, rec, header, |section, raw, h| {
        let s = atlas.tiles_per_side();
        if h.tiles_per_side != s {
            return Err(Error::inconsistent(format!(
                "panes have {} tiles per side, the atlas implies {s}",
                h.tiles_per_side
            )));
        }
        let tiles = s as usize * s as usize;
        let at_least = (PANES_HEADER_SIZE + 4 * tiles) as u64;
        if section.record.raw_size < at_least {
            return Err(Error::inconsistent(format!(
                "panes section declares {} raw bytes, less than its header and {tiles} ranks",
                section.record.raw_size
            )));
        }
        let ranks = raw.records(tiles, 4, basis::decode_ranks)?;
        let t = atlas.tile_size;
        basis::check_ranks(&h, t, &ranks).map_err(Error::inconsistent)?;
        let expected = basis::raw_size_for(h.pane_count, t, &ranks).unwrap_or(u64::MAX);
        section.expect_raw_size(expected, || {
            format!(
                "{} panes in {tiles} tiles of {t}² texels with these ranks",
                h.pane_count
            )
        })?;
        let p = h.pane_count as usize;
        let rank_sum: usize = ranks.iter().map(|&r| r as usize).sum();
        let scales = raw.records(tiles * p, 4, basis::decode_scales)?;
        let planes = raw.bytes(6 * p * rank_sum)?;
        let coefficients = basis::decode_coefficients(p, &ranks, &scales, &planes).map_err(Error::inconsistent)?;
        let texels = t as usize * t as usize;
        let planes = raw.bytes(2 * texels * rank_sum)?;
        let bases = basis::decode_basis(texels, &ranks, &planes).map_err(Error::inconsistent)?;
        Ok(PaneBasis::from_parts(&h, t, ranks, coefficients, bases))
    })
}

/// Reads a section of exactly `count` records of `size` bytes: its raw size must be that
/// (`counts` describes the counts for the message).
fn read_record_section<R: Read + Seek, T>(
    src: &mut R,
    rec: &SectionRecord,
    count: u64,
    size: usize,
    counts: impl FnOnce() -> String,
    decode: impl Fn(&[u8]) -> Result<Vec<T>, String>,
) -> Result<Vec<T>> {
    let section = open_section(src, rec)?;
    section.expect_raw_size(count * size as u64, counts)?;
    section.read_records(count as usize, size, decode)
}

/// Reads the clusters section: exactly one record per pane.
fn read_clusters<R: Read + Seek>(src: &mut R, rec: &SectionRecord, pane_count: u32) -> Result<Vec<Cluster>> {
    let panes = u64::from(pane_count);
    read_record_section(
        src,
        rec,
        panes,
        CLUSTER_RECORD_SIZE,
        || format!("{pane_count} panes"),
        decode_clusters,
    )
}

/// Reads the entries section: exactly as many as the cluster ranges cover, sorted by cluster.
fn read_entries<R: Read + Seek>(src: &mut R, rec: &SectionRecord, clusters: &[Cluster]) -> Result<Vec<Entry>> {
    let entry_count = entries_covered(clusters).map_err(Error::inconsistent)?;
    if entry_count > limits::MAX_ENTRIES {
        return Err(Error::inconsistent(format!(
            "clusters cover {entry_count} entries, more than the limit {}",
            limits::MAX_ENTRIES
        )));
    }
    let counts = || format!("{entry_count} entries covered by the cluster ranges");
    let entries = read_record_section(src, rec, entry_count, ENTRY_RECORD_SIZE, counts, decode_entries)?;
    validate_entries_clusters(&entries, clusters).map_err(Error::inconsistent)?;
    Ok(entries)
}

/// The optional sections.
struct OptionalSections {
    entry_energy: Option<Vec<[f32; 3]>>,
    emitters: Vec<EmitterGroup>,
    sky: Option<SkyTransfer>,
    probes: Option<Probes>,
    probe_rays: Option<crate::ProbeRays>,
    near_field: Option<crate::NearField>,
    entry_cells: Option<crate::EntryCells>,
}

/// What the header and the required sections fix, against which the optional sections'
/// headers are checked.
#[derive(Clone, Copy)]
struct Fixed {
    strict: bool,
    /// The atlas's.
    resolution: u32,
    entry_count: u64,
    clusters: usize,
}

/// Reads the optional sections that `found` holds, each sized by its own header and what the
/// required sections fixed.
fn read_optional_sections<R: Read + Seek>(
    src: &mut R,
    found: &SectionRecords,
    fixed: &Fixed,
) -> Result<OptionalSections> {
    let entry_count = fixed.entry_count;
    // Entry energy: exactly one record per entry.
    let entry_energy = match &found.entry_energy {
        None => None,
        Some(rec) => Some(read_record_section(
            src,
            rec,
            entry_count,
            ENTRY_ENERGY_RECORD_SIZE,
            || format!("{entry_count} entries"),
            decode_entry_energy,
        )?),
    };
    // Emitters: sizes fixed by its header, the entry count and the atlas.
    let emitters = match &found.emitters {
        None => Vec::new(),
        Some(rec) => read_emitters(src, rec, fixed)?,
    };
    // Sky: its size is fixed by the atlas resolution.
    let sky = found.sky.as_ref().map(|rec| read_sky(src, rec, fixed)).transpose()?;
    // Probes: sizes fixed by its header and the cluster count.
    let probes = found
        .probes
        .as_ref()
        .map(|rec| read_probes(src, rec, fixed))
        .transpose()?;
    // Probe rays (only beside the probes): sizes fixed by its header.
    let probe_rays = match (&found.probe_rays, &probes) {
        (None, _) => None,
        (Some(_), None) => {
            return Err(Error::inconsistent("probe_rays section without a probes section"));
        }
        (Some(rec), Some(p)) => Some(read_probe_rays(src, rec, fixed, p.len(), emitters.len())?),
    };
    // Near field: sizes fixed by its header and the atlas.
    let near_field = (found.near_field.as_ref())
        .map(|rec| read_near_field(src, rec, fixed, emitters.len()))
        .transpose()?;
    // Entry cells: sizes fixed by its header and the entry count.
    let entry_cells = (found.entry_cells.as_ref())
        .map(|rec| read_entry_cells(src, rec, fixed))
        .transpose()?;
    Ok(OptionalSections {
        entry_energy,
        emitters,
        sky,
        probes,
        probe_rays,
        near_field,
        entry_cells,
    })
}

impl ArchiveInfo {
    fn new(header: &Header, file_length: u64, records: &[SectionRecord], panes: &PaneBasis) -> Self {
        let texels = u64::from(panes.resolution()) * u64::from(panes.resolution());
        ArchiveInfo {
            major: header.major,
            minor: header.minor,
            file_length,
            sections: records
                .iter()
                .map(|r| SectionInfo {
                    kind: r.kind,
                    name: section_name(r.kind),
                    compression: r.compression,
                    offset: r.offset,
                    stored_size: r.stored_size,
                    raw_size: r.raw_size,
                    checksum: r.checksum,
                })
                .collect(),
            pane_count: panes.pane_count() as u32,
            tiles: panes.tile_count() as u64,
            max_rank: panes.max_rank(),
            rank_sum: panes.ranks().iter().map(|&r| u64::from(r)).sum(),
            basis_bytes: panes.basis_bytes(),
            coefficient_bytes: panes.coefficient_bytes(),
            pane_texel_bytes: panes.pane_count() as u64 * texels * 4,
        }
    }
}

impl<R: Read + Seek> Archive<R> {
    /// Opens and validates an archive from any seekable source.
    ///
    /// Every section's raw size is checked against what the counts read so far imply *before*
    /// it is decompressed, so a small stream cannot make the reader produce (or hold) more than
    /// those counts need. Hence the order: metadata (16 MiB cap), atlas (its own 16-byte header
    /// gives R and N), panes (its header and the tiles' ranks, checked against the atlas, give
    /// its size and the pane count), clusters (56 × panes), last entries (28 × the entries the
    /// cluster ranges cover), then the optional sections.
    pub fn from_reader(mut src: R) -> Result<Self> {
        let (header, file_length) = read_header(&mut src)?;
        let strict = header.strict_reserved();
        let records = read_section_table(&mut src, &header, file_length)?;
        let found = SectionRecords::find(&records)?;
        let metadata = read_metadata(&mut src, &found.metadata)?;
        let atlas = read_atlas(&mut src, &found.atlas, strict)?;
        let panes = read_panes(&mut src, &found.panes, &atlas, strict)?;
        let clusters = read_clusters(&mut src, &found.clusters, panes.pane_count() as u32)?;
        let entries = read_entries(&mut src, &found.entries, &clusters)?;
        let fixed = Fixed {
            strict,
            resolution: atlas.resolution,
            entry_count: entries.len() as u64,
            clusters: clusters.len(),
        };
        let optional = read_optional_sections(&mut src, &found, &fixed)?;
        let info = ArchiveInfo::new(&header, file_length, &records, &panes);
        Ok(Archive {
            src,
            info,
            records,
            metadata,
            atlas,
            entries,
            optional,
            clusters,
            panes,
        })
    }

    /// Version, sections and sizes.
    pub fn info(&self) -> &ArchiveInfo {
        &self.info
    }

    /// The metadata section.
    pub fn metadata(&self) -> &Metadata {
        &self.metadata
    }

    /// The atlas section.
    pub fn atlas(&self) -> &AtlasSection {
        &self.atlas
    }

    /// Entry points, sorted by cluster.
    pub fn entries(&self) -> &[Entry] {
        &self.entries
    }

    /// The emitter groups (formats/prm.md §5.2); empty when the archive has none.
    pub fn emitters(&self) -> &[EmitterGroup] {
        &self.optional.emitters
    }

    /// The sky's transfer at the atlas texels (formats/prm.md §5.3), when the bake made it.
    pub fn sky(&self) -> Option<&SkyTransfer> {
        self.optional.sky.as_ref()
    }

    /// The probes and every cluster's transfer to them (formats/prm.md §5.4), when the bake
    /// placed them.
    pub fn probes(&self) -> Option<&Probes> {
        self.optional.probes.as_ref()
    }

    /// Where every probe's rays meet the scene (formats/prm.md §5.5), when the bake traced
    /// them: a run time gathers the probes' light from the surfaces with them.
    pub fn probe_rays(&self) -> Option<&crate::ProbeRays> {
        self.optional.probe_rays.as_ref()
    }

    /// Where every exit point's near rays end (formats/prm.md §5.6), when the bake traced them:
    /// a run time gathers back with them what the panes' VPL bound removes.
    pub fn near_field(&self) -> Option<&crate::NearField> {
        self.optional.near_field.as_ref()
    }

    /// The points of every entry point's cell (formats/prm.md §5.7), if the archive has them.
    pub fn entry_cells(&self) -> Option<&crate::EntryCells> {
        self.optional.entry_cells.as_ref()
    }

    /// Every entry's pane energy (RGB, the sum over the atlas of the indirect irradiance its
    /// own VPLs give for unit irradiance on it), in [`entries`](Self::entries)' order; `None` when
    /// the archive has no entry energy section. A player weighs a cluster's members by it, so that the cluster gives
    /// the indirect energy its members would give unclustered (formats/prm.md §5.1).
    pub fn entry_energy(&self) -> Option<&[[f32; 3]]> {
        self.optional.entry_energy.as_deref()
    }

    /// Clusters; cluster `i` owns pane `i`.
    pub fn clusters(&self) -> &[Cluster] {
        &self.clusters
    }

    /// Number of panes (= clusters).
    pub fn pane_count(&self) -> usize {
        self.clusters.len()
    }

    /// The panes as stored: a low-rank basis per atlas tile (formats/prm.md §7).
    pub fn pane_basis(&self) -> &PaneBasis {
        &self.panes
    }

    /// Decodes one pane to linear RGB, `resolution²` texels, row-major (formats/prm.md §7.2).
    /// [`Error::InvalidInput`] if there is no such pane.
    pub fn read_pane(&self, pane: usize) -> Result<Vec<[f32; 3]>> {
        self.panes.decode_pane(pane)
    }

    /// Decodes one pane and encodes it as RGB9E5 texels (`rgb9e5ufloat`, formats/prm.md §7.3),
    /// `resolution²` of them, row-major: what a GPU run time uploads.
    pub fn read_pane_rgb9e5(&self, pane: usize) -> Result<Vec<u32>> {
        Ok(self.read_pane(pane)?.into_iter().map(encode_rgb9e5).collect())
    }

    /// Reads the first section of a kind the format does not define, decompressed;
    /// `Ok(None)` if there is none.
    pub fn read_custom_section(&mut self, kind: u32) -> Result<Option<Vec<u8>>> {
        let Some(rec) = self.records.iter().find(|r| r.kind == kind).cloned() else {
            return Ok(None);
        };
        if crate::kind::name(kind).is_some() {
            return Err(Error::InvalidInput(format!(
                "section kind {kind} is defined by the format; use the typed accessors"
            )));
        }
        let section = open_section(&mut self.src, &rec)?;
        if rec.raw_size > MAX_CUSTOM_SECTION_BYTES {
            return Err(Error::inconsistent(format!(
                "{} section declares {} raw bytes, more than the limit {MAX_CUSTOM_SECTION_BYTES}",
                section.name, rec.raw_size
            )));
        }
        section.read_all().map(Some)
    }

    /// Checks everything: every cluster's energy and peak against its decoded pane, and every
    /// section's checksum (unknown sections too).
    pub fn verify(&mut self) -> Result<VerifyReport> {
        let mut report = VerifyReport::default();
        for (pane, (energy, peak)) in self.panes.energy_peak().into_iter().enumerate() {
            let c = &self.clusters[pane];
            if energy.map(f32::to_bits) != c.energy.map(f32::to_bits) {
                return Err(Error::inconsistent(format!(
                    "cluster {pane} energy {:?} does not match its pane ({energy:?})",
                    c.energy
                )));
            }
            if peak.map(f32::to_bits) != c.peak.map(f32::to_bits) {
                return Err(Error::inconsistent(format!(
                    "cluster {pane} peak {:?} does not match its pane ({peak:?})",
                    c.peak
                )));
            }
            report.panes += 1;
        }
        let mut buf = vec![0u8; 1 << 20];
        for r in self.records.clone() {
            let name = section_name(r.kind);
            self.src.seek(SeekFrom::Start(r.offset))?;
            let mut hasher = Xxh3Default::new();
            let mut remaining = r.stored_size;
            while remaining > 0 {
                let n = remaining.min(buf.len() as u64) as usize;
                self.src.read_exact(&mut buf[..n]).map_err(|e| match e.kind() {
                    std::io::ErrorKind::UnexpectedEof => Error::truncated(name.clone()),
                    _ => Error::Io(e),
                })?;
                hasher.update(&buf[..n]);
                remaining -= n as u64;
            }
            if hasher.digest() != r.checksum {
                return Err(Error::checksum(name));
            }
            report.sections += 1;
            report.bytes_hashed += r.stored_size;
        }
        Ok(report)
    }
}

/// Energy (sum) and peak (per-channel max) of a decoded pane, `resolution²` texels row-major,
/// as the cluster table records them (formats/prm.md §6): summed in binary64 in tile order, texels
/// row-major within a tile, then rounded to binary32. NaN if the sizes do not fit.
pub fn pane_energy_peak(texels: &[[f32; 3]], resolution: u32, tile_size: u32) -> ([f32; 3], [f32; 3]) {
    let res = resolution as usize;
    let t = tile_size as usize;
    let mut energy = [0f64; 3];
    let mut peak = [0f32; 3];
    if t == 0 || !res.is_multiple_of(t) || texels.len() != res * res {
        return ([f32::NAN; 3], [f32::NAN; 3]);
    }
    let tps = res / t;
    for ty in 0..tps {
        for tx in 0..tps {
            for j in 0..t {
                let start = (ty * t + j) * res + tx * t;
                for d in &texels[start..start + t] {
                    for c in 0..3 {
                        energy[c] += f64::from(d[c]);
                        peak[c] = peak[c].max(d[c]);
                    }
                }
            }
        }
    }
    (energy.map(|e| e as f32), peak)
}

/// Raw bytes decoded per step while streaming a section: memory grows with
/// the data the stream actually produces, one chunk at a time.
const RAW_CHUNK: usize = 1 << 20;

/// Grows `v` so that `extra` more items fit, doubling but never past `total`
/// items: a vector filled as data arrives ends at most twice its length, and
/// exactly `total` when the data is complete.
fn reserve_capped<T>(v: &mut Vec<T>, extra: usize, total: usize) {
    if v.capacity() - v.len() < extra {
        let target = v.capacity().saturating_mul(2).min(total).max(v.len() + extra);
        v.reserve_exact(target - v.len());
    }
}

/// A section whose placement and compression code are known good and whose
/// stored bytes (real file bytes, so bounded by the file) passed their
/// checksum. Its raw bytes are produced on demand, capped at `raw_size`.
struct StoredSection {
    name: String,
    record: SectionRecord,
    stored: Vec<u8>,
}

/// Reads a section's stored bytes and checks its compression code and checksum.
fn open_section<R: Read + Seek>(src: &mut R, r: &SectionRecord) -> Result<StoredSection> {
    let name = section_name(r.kind);
    match r.compression {
        compression::NONE => {
            if r.raw_size != r.stored_size {
                return Err(Error::inconsistent(format!(
                    "uncompressed {name} section has raw size {} but stored size {}",
                    r.raw_size, r.stored_size
                )));
            }
        }
        compression::ZSTD => {}
        other => {
            return Err(Error::inconsistent(format!(
                "{name} section uses unknown compression {other}"
            )))
        }
    }
    let stored = read_at(src, r.offset, r.stored_size, &name)?;
    if checksum(&stored) != r.checksum {
        return Err(Error::checksum(name));
    }
    Ok(StoredSection {
        name,
        record: r.clone(),
        stored,
    })
}

impl StoredSection {
    /// Refuses the section unless its declared raw size is exactly what the
    /// counts read so far imply (`counts` describes them for the message).
    fn expect_raw_size(&self, expected: u64, counts: impl FnOnce() -> String) -> Result<()> {
        if self.record.raw_size != expected {
            return Err(Error::inconsistent(format!(
                "{} section declares {} raw bytes, {} need {expected}",
                self.name,
                self.record.raw_size,
                counts()
            )));
        }
        Ok(())
    }

    /// A reader of the raw bytes after the section's fixed `N`-byte header, and the header,
    /// read first: a section of fewer raw bytes is refused before anything is decompressed.
    fn raw_with_header<const N: usize>(&self) -> Result<(RawReader<'_>, [u8; N])> {
        if self.record.raw_size < N as u64 {
            return Err(Error::inconsistent(format!(
                "{} section has {} raw bytes, less than its {N}-byte header",
                self.name, self.record.raw_size
            )));
        }
        let mut raw = self.raw()?;
        let mut head = [0u8; N];
        raw.read_exact(&mut head)?;
        Ok((raw, head))
    }

    /// A reader of the raw bytes, producing at most `raw_size + 1` of them.
    fn raw(&self) -> Result<RawReader<'_>> {
        let inner: Box<dyn Read + '_> = if self.record.compression == compression::NONE {
            Box::new(&self.stored[..])
        } else {
            Box::new(
                zstd::stream::read::Decoder::with_buffer(&self.stored[..]).map_err(|e| Error::Decompress {
                    section: self.name.clone(),
                    reason: e.to_string(),
                })?,
            )
        };
        Ok(RawReader {
            section: self,
            inner: inner.take(self.record.raw_size.saturating_add(1)),
            produced: 0,
        })
    }

    /// All raw bytes, grown as they are decompressed.
    fn read_all(&self) -> Result<Vec<u8>> {
        let mut raw = self.raw()?;
        let total = usize::try_from(self.record.raw_size)
            .map_err(|_| Error::inconsistent(format!("{} section too large", self.name)))?;
        let bytes = raw.bytes(total)?;
        raw.finish()?;
        Ok(bytes)
    }

    /// Decodes exactly `count` records of `size` bytes (the raw size was
    /// checked to be `count × size`), a chunk at a time.
    fn read_records<T>(
        &self,
        count: usize,
        size: usize,
        decode: impl Fn(&[u8]) -> Result<Vec<T>, String>,
    ) -> Result<Vec<T>> {
        let mut raw = self.raw()?;
        let records = raw.records(count, size, decode)?;
        raw.finish()?;
        Ok(records)
    }
}

/// The raw bytes of a [`StoredSection`], as they are produced.
struct RawReader<'a> {
    section: &'a StoredSection,
    inner: std::io::Take<Box<dyn Read + 'a>>,
    produced: u64,
}

impl RawReader<'_> {
    fn error(&self, reason: String) -> Error {
        Error::Decompress {
            section: self.section.name.clone(),
            reason,
        }
    }

    fn read_exact(&mut self, buf: &mut [u8]) -> Result<()> {
        match self.inner.read_exact(buf) {
            Ok(()) => {
                self.produced += buf.len() as u64;
                Ok(())
            }
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Err(self.error(format!(
                "the stream ends before the {} bytes the section table declares",
                self.section.record.raw_size
            ))),
            Err(e) => Err(self.error(e.to_string())),
        }
    }

    /// The next `n` bytes, grown a chunk at a time.
    fn bytes(&mut self, n: usize) -> Result<Vec<u8>> {
        let mut out = Vec::new();
        while out.len() < n {
            let k = (n - out.len()).min(RAW_CHUNK);
            let start = out.len();
            reserve_capped(&mut out, k, n);
            out.resize(start + k, 0);
            self.read_exact(&mut out[start..])?;
        }
        Ok(out)
    }

    /// The next `count` records of `size` bytes, decoded a chunk at a time.
    fn records<T>(
        &mut self,
        count: usize,
        size: usize,
        decode: impl Fn(&[u8]) -> Result<Vec<T>, String>,
    ) -> Result<Vec<T>> {
        let per_chunk = (RAW_CHUNK / size).max(1);
        let mut buf = vec![0u8; per_chunk.min(count) * size];
        let mut out = Vec::new();
        while out.len() < count {
            let n = (count - out.len()).min(per_chunk);
            self.read_exact(&mut buf[..n * size])?;
            let decoded = decode(&buf[..n * size]).map_err(Error::inconsistent)?;
            reserve_capped(&mut out, decoded.len(), count);
            out.extend(decoded);
        }
        Ok(out)
    }

    /// Requires the stream to end exactly at the declared raw size.
    fn finish(mut self) -> Result<()> {
        let mut probe = [0u8; 1];
        loop {
            match self.inner.read(&mut probe) {
                Ok(0) => break,
                Ok(_) => {
                    return Err(self.error(format!(
                        "the stream holds more than the {} bytes the section table declares",
                        self.section.record.raw_size
                    )))
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(self.error(e.to_string())),
            }
        }
        if self.produced != self.section.record.raw_size {
            return Err(self.error(format!(
                "decompressed to {} bytes, the section table declares {}",
                self.produced, self.section.record.raw_size
            )));
        }
        Ok(())
    }
}

/// Reads a section that begins with a fixed `N`-byte header: `decode_header` parses and checks
/// the header's own fields, then `read` checks the raw size its counts imply (before anything
/// else is decompressed) and decodes the rest, which must end where the section table says.
fn read_headed_section<R: Read + Seek, const N: usize, H, T>(
    src: &mut R,
    rec: &SectionRecord,
    decode_header: impl FnOnce(&[u8; N]) -> Result<H, String>,
    read: impl FnOnce(&StoredSection, &mut RawReader<'_>, H) -> Result<T>,
) -> Result<T> {
    let section = open_section(src, rec)?;
    let (mut raw, head) = section.raw_with_header::<N>()?;
    let header = decode_header(&head).map_err(Error::inconsistent)?;
    let out = read(&section, &mut raw, header)?;
    raw.finish()?;
    Ok(out)
}

/// Reads the emitters section: its 16-byte header first, whose counts fix the raw size.
fn read_emitters<R: Read + Seek>(src: &mut R, rec: &SectionRecord, fixed: &Fixed) -> Result<Vec<EmitterGroup>> {
    use crate::emitters::{self, EMITTERS_HEADER_SIZE, EMITTER_GROUP_RECORD_SIZE};
    let Fixed {
        strict,
        entry_count,
        resolution,
        ..
    } = *fixed;
    let header = |head: &[u8; EMITTERS_HEADER_SIZE]| emitters::decode_header(head, strict);
    read_headed_section(src, rec, header, |section, raw, (groups, entries, res)| {
        if u64::from(entries) != entry_count || res != resolution {
            return Err(Error::inconsistent(format!(
                "emitters section is for {entries} entries at resolution {res}, the archive has {entry_count} at {resolution}"
            )));
        }
        let expected = emitters::raw_size_for(u64::from(groups), entry_count, resolution).unwrap_or(u64::MAX);
        section.expect_raw_size(expected, || {
            format!("{groups} groups, {entry_count} entries, resolution {resolution}")
        })?;
        let mut out = raw.records(groups as usize, EMITTER_GROUP_RECORD_SIZE, |b| {
            emitters::decode_groups(b, strict)
        })?;
        let texels = resolution as usize * resolution as usize;
        for g in &mut out {
            g.entry_irradiance = raw.records(entry_count as usize, 12, emitters::decode_entry_irradiance)?;
            g.direct = raw.records(texels, 4, emitters::decode_direct)?;
            // Read either way: without the flag the words are zeros, and skipped.
            let indirect = raw.records(texels, 4, emitters::decode_direct)?;
            if let Some(slot) = &mut g.indirect {
                *slot = indirect;
            }
        }
        Ok(out)
    })
}

/// Reads the sky section: its 16-byte header first, whose resolution (the atlas's) fixes the
/// raw size.
fn read_sky<R: Read + Seek>(src: &mut R, rec: &SectionRecord, fixed: &Fixed) -> Result<SkyTransfer> {
    use crate::sky::{self, DIRECT_TEXEL_BYTES, INDIRECT_TEXEL_BYTES, SKY_HEADER_SIZE};
    let Fixed { strict, resolution, .. } = *fixed;
    let header = |head: &[u8; SKY_HEADER_SIZE]| sky::decode_header(head, strict);
    read_headed_section(src, rec, header, |section, raw, res| {
        if res != resolution {
            return Err(Error::inconsistent(format!(
                "sky section is for resolution {res}, the archive's atlas is {resolution}"
            )));
        }
        section.expect_raw_size(sky::raw_size_for(resolution).unwrap_or(u64::MAX), || {
            format!("resolution {resolution}")
        })?;
        let texels = resolution as usize * resolution as usize;
        let direct = raw.records(texels, DIRECT_TEXEL_BYTES, sky::decode_direct)?;
        let indirect = raw.records(texels, INDIRECT_TEXEL_BYTES, sky::decode_indirect)?;
        Ok(SkyTransfer { direct, indirect })
    })
}

/// Reads the atlas section: its 16-byte header first, whose resolution and triangle count fix
/// the raw size.
fn read_atlas<R: Read + Seek>(src: &mut R, rec: &SectionRecord, strict: bool) -> Result<AtlasSection> {
    let header = |head: &[u8; ATLAS_HEADER_SIZE]| AtlasSection::decode_header(head, strict);
    let atlas = read_headed_section(src, rec, header, |section, raw, (resolution, tile_size, triangles)| {
        let expected = AtlasSection::raw_size_for(resolution, u64::from(triangles)).unwrap_or(u64::MAX);
        section.expect_raw_size(expected, || {
            format!("resolution {resolution} and {triangles} triangles")
        })?;
        Ok(AtlasSection {
            resolution,
            tile_size,
            triangle_uvs: raw.records(triangles as usize, 24, AtlasSection::decode_uvs)?,
            coverage: raw.bytes(AtlasSection::coverage_len(resolution))?,
        })
    })?;
    atlas.validate().map_err(Error::inconsistent)?;
    Ok(atlas)
}

/// Reads the probe rays section: its 32-byte header first, whose counts fix the raw size.
fn read_probe_rays<R: Read + Seek>(
    src: &mut R,
    rec: &SectionRecord,
    fixed: &Fixed,
    probes: usize,
    groups: usize,
) -> Result<crate::ProbeRays> {
    use crate::probe_rays::{self, GATHER_POINT_SIZE, PROBE_RAYS_HEADER_SIZE};
    let Fixed { strict, resolution, .. } = *fixed;
    let header = |head: &[u8; PROBE_RAYS_HEADER_SIZE]| probe_rays::decode_header(head, strict);
    let out = read_headed_section(src, rec, header, |section, raw, h| {
        if h.probes as usize != probes || h.resolution != resolution {
            return Err(Error::inconsistent(format!(
                "probe_rays section is for {} probes on a {}² atlas, the archive has {probes} on {resolution}²",
                h.probes, h.resolution
            )));
        }
        if u64::from(h.points) > u64::from(resolution) * u64::from(resolution) {
            return Err(Error::inconsistent(format!(
                "probe_rays section has {} gather points, more than the atlas's texels",
                h.points
            )));
        }
        let m = u64::from(h.rays_per_probe);
        let expected = probe_rays::raw_size_for(probes as u64, m, u64::from(h.points)).unwrap_or(u64::MAX);
        section.expect_raw_size(expected, || {
            format!("{probes} probes × {m} rays, {} gather points", h.points)
        })?;
        Ok(crate::ProbeRays {
            rays_per_probe: h.rays_per_probe,
            points: raw.records(h.points as usize, GATHER_POINT_SIZE, probe_rays::decode_points)?,
            hits: raw.records(probes * m as usize, 4, probe_rays::decode_hits)?,
        })
    })?;
    probe_rays::validate(&out, probes, resolution, groups).map_err(Error::inconsistent)?;
    Ok(out)
}

/// Reads the near field section: its 32-byte header first, whose counts (each bounded by the
/// atlas's texels and the rays per exit) fix the raw size.
fn read_entry_cells<R: Read + Seek>(src: &mut R, rec: &SectionRecord, fixed: &Fixed) -> Result<crate::EntryCells> {
    use crate::entry_cells::{self, CELL_POINT_SIZE, ENTRY_CELLS_HEADER_SIZE};
    let entry_count = fixed.entry_count;
    let header = |head: &[u8; ENTRY_CELLS_HEADER_SIZE]| entry_cells::decode_header(head);
    let out = read_headed_section(src, rec, header, |section, raw, (n, m)| {
        if u64::from(n) != entry_count {
            return Err(Error::inconsistent(format!(
                "entry_cells section is for {n} entries, the archive has {entry_count}"
            )));
        }
        let expected = entry_cells::raw_size_for(u64::from(n), u64::from(m)).unwrap_or(u64::MAX);
        section.expect_raw_size(expected, || format!("{n} entries, {m} points"))?;
        Ok(crate::EntryCells {
            ends: raw.records(n as usize, 4, entry_cells::decode_ends)?,
            points: raw.records(m as usize, CELL_POINT_SIZE, entry_cells::decode_points)?,
        })
    })?;
    entry_cells::validate(&out, entry_count as usize).map_err(Error::inconsistent)?;
    Ok(out)
}

fn read_near_field<R: Read + Seek>(
    src: &mut R,
    rec: &SectionRecord,
    fixed: &Fixed,
    groups: usize,
) -> Result<crate::NearField> {
    use crate::near_field::{self, NEAR_EXIT_SIZE, NEAR_FIELD_HEADER_SIZE, NEAR_HIT_SIZE};
    use crate::probe_rays::{self, GATHER_POINT_SIZE};
    let resolution = fixed.resolution;
    let header = |head: &[u8; NEAR_FIELD_HEADER_SIZE]| near_field::decode_header(head);
    let out = read_headed_section(src, rec, header, |section, raw, h| {
        let texels = u64::from(resolution) * u64::from(resolution);
        if h.resolution != resolution
            || u64::from(h.points) > texels
            || u64::from(h.exits) > texels
            || u64::from(h.hits) > u64::from(h.exits) * u64::from(h.rays_per_exit)
        {
            return Err(Error::inconsistent(format!(
                "near_field section is for a {}² atlas ({resolution}² here) with {} gather points, {} exits and {} hits of {} rays each",
                h.resolution, h.points, h.exits, h.hits, h.rays_per_exit
            )));
        }
        let expected =
            near_field::raw_size_for(u64::from(h.exits), u64::from(h.points), u64::from(h.hits)).unwrap_or(u64::MAX);
        section.expect_raw_size(expected, || {
            format!("{} gather points, {} exits, {} hits", h.points, h.exits, h.hits)
        })?;
        Ok(crate::NearField {
            rays_per_exit: h.rays_per_exit,
            disk: h.disk,
            indirect_disk: h.indirect_disk,
            complement: h.complement,
            points: raw.records(h.points as usize, GATHER_POINT_SIZE, probe_rays::decode_points)?,
            exits: raw.records(h.exits as usize, NEAR_EXIT_SIZE, near_field::decode_exits)?,
            hits: near_field::decode_hits(&raw.bytes(h.hits as usize * NEAR_HIT_SIZE)?, h.disk),
        })
    })?;
    near_field::validate(&out, resolution, groups).map_err(Error::inconsistent)?;
    Ok(out)
}

/// Reads the probes section: its 48-byte header first, whose probe count and the archive's
/// cluster count fix the raw size.
fn read_probes<R: Read + Seek>(src: &mut R, rec: &SectionRecord, fixed: &Fixed) -> Result<Probes> {
    use crate::probes::{self, PROBES_HEADER_SIZE, PROBE_RECORD_SIZE, PROBE_SKY_BYTES, PROBE_TRANSFER_BYTES};
    let Fixed { strict, clusters, .. } = *fixed;
    let header = |head: &[u8; PROBES_HEADER_SIZE]| probes::decode_header(head, strict);
    let out = read_headed_section(src, rec, header, |section, raw, h| {
        let (n, c) = (h.probes, h.clusters);
        if c as usize != clusters {
            return Err(Error::inconsistent(format!(
                "probes section is for {c} clusters, the archive has {clusters}"
            )));
        }
        let expected = probes::raw_size_for(u64::from(n), clusters as u64, h.sky).unwrap_or(u64::MAX);
        section.expect_raw_size(expected, || format!("{n} probes, {clusters} clusters"))?;
        let records = raw.records(n as usize, PROBE_RECORD_SIZE, probes::decode_records)?;
        let transfer = raw.records(n as usize * clusters, PROBE_TRANSFER_BYTES, probes::decode_transfer)?;
        let sky = if h.sky {
            Some(raw.records(n as usize, PROBE_SKY_BYTES, probes::decode_sky)?)
        } else {
            None
        };
        Ok(Probes {
            grid: h.grid,
            sky,
            cells: records.iter().map(|r| r.0).collect(),
            positions: records.iter().map(|r| r.1).collect(),
            transfer,
        })
    })?;
    probes::validate(&out, clusters).map_err(Error::inconsistent)?;
    Ok(out)
}
