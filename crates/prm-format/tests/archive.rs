//! Integration tests of the `.prm` archive: round trip, corruption, atomicity, spec conformance.
//!
//! Long on purpose: one test per corruption, hostile size and atomicity case of the spec, each
//! spelled out so a failure names the case.

use std::path::{Path, PathBuf};
use std::process::Command;

use prm_format::*;

// ---------------------------------------------------------------- allocation meter

/// Counts the bytes live on the *current thread* (allocations minus frees
/// made by it) and their peak, so one test can bound what the reader
/// allocates while other tests run in parallel.
struct ThreadMeter;

thread_local! {
    static LIVE: std::cell::Cell<isize> = const { std::cell::Cell::new(0) };
    static PEAK: std::cell::Cell<isize> = const { std::cell::Cell::new(0) };
}

fn meter(delta: isize) {
    let _ = LIVE.try_with(|live| {
        let now = live.get() + delta;
        live.set(now);
        let _ = PEAK.try_with(|peak| peak.set(peak.get().max(now)));
    });
}

unsafe impl std::alloc::GlobalAlloc for ThreadMeter {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        meter(layout.size() as isize);
        unsafe { std::alloc::System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        meter(-(layout.size() as isize));
        unsafe { std::alloc::System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: std::alloc::Layout) -> *mut u8 {
        meter(layout.size() as isize);
        unsafe { std::alloc::System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        meter(new_size as isize - layout.size() as isize);
        unsafe { std::alloc::System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: ThreadMeter = ThreadMeter;

/// Runs `f` and returns its result with the peak of bytes it kept live on this thread.
fn peak_allocation<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = LIVE.with(|l| l.get());
    PEAK.with(|p| p.set(base));
    let out = f();
    let peak = PEAK.with(|p| p.get()) - base;
    (out, peak.max(0) as usize)
}

// ---------------------------------------------------------------- helpers

#[path = "common/splitmix.rs"]
mod splitmix;
use splitmix::Rng;

impl Rng {
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Nothing compressed: every section as it is.
const UNCOMPRESSED: WriterOptions = WriterOptions {
    zstd_level: 1,
    compress_sections: false,
    pane_tolerance: PANE_TOLERANCE,
    max_pane_rank: MAX_PANE_RANK,
};

/// A fresh, empty directory under cargo's per-target temp dir.
fn test_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("prm-format-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn dir_listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

struct Scene {
    metadata: Metadata,
    atlas: AtlasSection,
    entries: Vec<Entry>,
    clusters: Vec<Cluster>,
    panes: Vec<Vec<[f32; 3]>>,
}

/// A small scene: `clusters` clusters of 0..3 entries, panes of smooth data
/// with some all-zero tiles (pane 0 entirely zero).
fn scene(resolution: u32, tile_size: u32, clusters: usize, seed: u64) -> Scene {
    let mut rng = Rng(seed);
    let mut metadata = Metadata::new("prm-format-tests", "0.0.0");
    metadata.seed = seed;
    metadata.params.insert("bounces".into(), 3.into());
    metadata
        .params
        .insert("samples".into(), serde_json::json!({"per_texel": 64}));
    metadata.timings.insert("trace".into(), 1.25);
    metadata.timings.insert("cluster".into(), 0.5);
    metadata.source_scene = "../scenes/box.gltf".into();
    metadata.scene_fingerprint = 0x0123_4567_89ab_cdef ^ seed;

    let mut atlas = AtlasSection::new(resolution, tile_size);
    for _ in 0..5 {
        atlas.triangle_uvs.push([
            [rng.unit(), rng.unit()],
            [rng.unit(), rng.unit()],
            [rng.unit(), rng.unit()],
        ]);
    }
    for y in 0..resolution {
        for x in 0..resolution {
            atlas.set_covered(x, y, (x + 2 * y) % 3 != 0);
        }
    }

    let mut entries = Vec::new();
    let mut cl = Vec::new();
    for c in 0..clusters {
        let first = entries.len() as u32;
        let n = (rng.below(3)) as u32;
        for _ in 0..n {
            entries.push(Entry {
                position: [rng.unit(), rng.unit(), c as f32],
                normal: [0.0, 1.0, 0.0],
                cluster: c as u32,
            });
        }
        cl.push(Cluster::new(first, n, [0.5, 0.5, c as f32], [0.0, 1.0, 0.0]));
    }

    let res = resolution as usize;
    let panes = (0..clusters)
        .map(|p| {
            let (cx, cy) = (rng.unit() * res as f32, rng.unit() * res as f32);
            let scale = 0.1 + 4.0 * rng.unit();
            (0..res * res)
                .map(|i| {
                    let (x, y) = ((i % res) as f32, (i / res) as f32);
                    // pane 0 is all zero; left quarter zero elsewhere
                    if p == 0 || x < res as f32 / 4.0 {
                        return [0.0; 3];
                    }
                    let d2 = (x - cx).powi(2) + (y - cy).powi(2);
                    let v = scale / (1.0 + d2 / 16.0);
                    [v, 0.5 * v, 0.25 * v + 0.01]
                })
                .collect()
        })
        .collect();
    Scene {
        metadata,
        atlas,
        entries,
        clusters: cl,
        panes,
    }
}

/// A fresh [`test_dir`] `name` holding `file`, the archive of `s` with the default options: the
/// directory and the archive's path.
fn written(name: &str, file: &str, s: &Scene) -> (PathBuf, PathBuf) {
    let dir = test_dir(name);
    let path = dir.join(file);
    write_scene(&path, s, WriterOptions::default());
    (dir, path)
}

fn write_scene(path: &Path, s: &Scene, options: WriterOptions) -> u64 {
    add_panes_and_finish(start_writer_with(path, s, options).unwrap(), s)
}

/// A writer of the archive of `s` at `path`, with the default options.
fn start_writer(path: &Path, s: &Scene) -> Result<ArchiveWriter> {
    ArchiveWriter::create(path, s.metadata.clone(), &s.atlas, &s.entries, &s.clusters)
}

/// A writer of the archive of `s` at `path`, with `options`.
fn start_writer_with(path: &Path, s: &Scene, options: WriterOptions) -> Result<ArchiveWriter> {
    ArchiveWriter::create_with_options(path, s.metadata.clone(), &s.atlas, &s.entries, &s.clusters, options)
}

/// For tests that write the archive of `s` a second way: a fresh [`test_dir`] `name` holding
/// `file`, the archive of `s` with the default options (see [`written`]), and a writer of `s`
/// started beside it at `again`. Returns the directory, both paths and the writer.
fn written_and_started(name: &str, s: &Scene, file: &str, again: &str) -> (PathBuf, PathBuf, PathBuf, ArchiveWriter) {
    let (dir, path) = written(name, file, s);
    let again = dir.join(again);
    let w = start_writer(&again, s).unwrap();
    (dir, path, again, w)
}

/// The bytes of the test scene's archive, written in a fresh directory `name` with `set`
/// called on the writer before the panes are added.
fn written_with(name: &str, s: &Scene, set: impl FnOnce(&mut ArchiveWriter)) -> Vec<u8> {
    let path = test_dir(name).join("archive.prm");
    let mut w = start_writer(&path, s).unwrap();
    set(&mut w);
    add_panes_and_finish(w, s);
    std::fs::read(&path).unwrap()
}

/// Writes `s` with one optional section, `value`, that `set` puts in, after `set` refused a copy
/// of it that `spoil` made unfit for the archive; checks that the archive is 2.0 and that `get`
/// reads `value` back from it, and that an archive without the section has none. Returns the
/// archive's bytes.
fn optional_section_round_trip<T: Clone + PartialEq + std::fmt::Debug>(
    name: &str,
    s: &Scene,
    value: &T,
    spoil: impl FnOnce(&mut T),
    set: impl Fn(&mut ArchiveWriter, T) -> Result<()>,
    get: impl for<'a, 'b> Fn(&'a Archive<std::io::Cursor<&'b [u8]>>) -> Option<&'a T>,
) -> Vec<u8> {
    let bytes = written_with(name, s, |w| {
        let mut wrong = value.clone();
        spoil(&mut wrong);
        assert!(set(w, wrong).is_err());
        set(w, value.clone()).unwrap();
    });
    let a = Archive::from_bytes(&bytes).unwrap();
    assert_eq!((a.info().major, a.info().minor), (2, 0));
    assert_eq!(get(&a), Some(value));
    let (plain, _) = small_archive(&format!("{name}-none"), WriterOptions::default());
    assert!(get(&Archive::from_bytes(&plain).unwrap()).is_none());
    bytes
}

/// Adds the scene's panes to `w` and finishes the archive; returns its size.
fn add_panes_and_finish(mut w: ArchiveWriter, s: &Scene) -> u64 {
    for p in &s.panes {
        w.add_pane(p).unwrap();
    }
    w.finish().unwrap()
}

/// The small archive most corruption tests mutate.
fn small_archive(name: &str, options: WriterOptions) -> (Vec<u8>, Scene) {
    let dir = test_dir(name);
    let s = scene(16, 8, 3, 7);
    let path = dir.join("small.prm");
    write_scene(&path, &s, options);
    (std::fs::read(&path).unwrap(), s)
}

/// Everything a reader can produce from an archive.
#[derive(Debug, PartialEq)]
struct Contents {
    metadata: Metadata,
    atlas: AtlasSection,
    entries: Vec<Entry>,
    clusters: Vec<Cluster>,
    panes: Vec<Vec<[f32; 3]>>,
}

fn read_all(bytes: &[u8]) -> Result<Contents> {
    let a = Archive::from_bytes(bytes)?;
    let panes = (0..a.pane_count())
        .map(|p| a.read_pane(p))
        .collect::<Result<Vec<_>>>()?;
    Ok(Contents {
        metadata: a.metadata().clone(),
        atlas: a.atlas().clone(),
        entries: a.entries().to_vec(),
        clusters: a.clusters().to_vec(),
        panes,
    })
}

fn verify_bytes(bytes: &[u8]) -> Result<VerifyReport> {
    Archive::from_bytes(bytes)?.verify()
}

// Test-side view of the container, written from the spec (not the library).
fn u32_at(b: &[u8], o: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(o..o.checked_add(4)?)?.try_into().ok()?))
}
fn u64_at(b: &[u8], o: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(o..o.checked_add(8)?)?.try_into().ok()?))
}
fn put_u64(b: &mut [u8], o: usize, v: u64) {
    if let Some(s) = b.get_mut(o..o.saturating_add(8)) {
        s.copy_from_slice(&v.to_le_bytes());
    }
}
fn put_u16(b: &mut [u8], o: usize, v: u16) {
    b[o..o + 2].copy_from_slice(&v.to_le_bytes());
}

#[derive(Debug, Clone, Copy)]
struct Sec {
    kind: u32,
    offset: usize,
    size: usize,
}

fn sections(b: &[u8]) -> Vec<Sec> {
    let (Some(n), Some(off)) = (u32_at(b, 12), u64_at(b, 16)) else {
        return vec![];
    };
    (0..n as usize)
        .map_while(|i| {
            let r = (off as usize).checked_add(i.checked_mul(48)?)?;
            Some(Sec {
                kind: u32_at(b, r)?,
                offset: u64_at(b, r.saturating_add(8))? as usize,
                size: u64_at(b, r.saturating_add(16))? as usize,
            })
        })
        .collect()
}

/// Recomputes every checksum after a mutation (sections, table, header), so
/// that the mutation reaches structural validation. Robust against any
/// garbage: skips whatever does not parse.
fn resign(b: &mut [u8]) {
    let secs = sections(b);
    let table = u64_at(b, 16).unwrap_or(0) as usize;
    for (i, s) in secs.iter().enumerate() {
        if let Some(data) = b.get(s.offset..s.offset.saturating_add(s.size)) {
            let sum = checksum(data);
            put_u64(b, table.saturating_add(i * 48 + 32), sum);
        }
    }
    let n = u32_at(b, 12).unwrap_or(0) as usize;
    if let Some(t) = b.get(table..table.saturating_add(n.saturating_mul(48))) {
        let sum = checksum(t);
        put_u64(b, 48, sum);
    }
    if b.len() >= 64 {
        let sum = checksum(&b[..56]);
        put_u64(b, 56, sum);
    }
}

// ---------------------------------------------------------------- tests

/// Per tile of the atlas, `‖M − M̂‖_F / ‖M‖_F` over every pane and channel: `panes` the dense
/// panes, `decoded` what the archive gives back (0 for a tile where `panes` are all zero).
fn tile_errors(panes: &[Vec<[f32; 3]>], decoded: &[Vec<[f32; 3]>], res: usize, t: usize) -> Vec<f64> {
    let s = res / t;
    (0..s * s)
        .map(|tile| {
            let (x0, y0) = (tile % s * t, tile / s * t);
            let (mut diff, mut norm) = (0f64, 0f64);
            for (p, d) in panes.iter().zip(decoded) {
                for j in 0..t {
                    for i in 0..t {
                        let k = (y0 + j) * res + x0 + i;
                        for ch in 0..3 {
                            diff += (f64::from(p[k][ch]) - f64::from(d[k][ch])).powi(2);
                            norm += f64::from(p[k][ch]).powi(2);
                        }
                    }
                }
            }
            if norm == 0.0 {
                assert_eq!(diff, 0.0, "tile {tile} of zeros decodes to zeros");
                0.0
            } else {
                (diff / norm).sqrt()
            }
        })
        .collect()
}

/// Whether a tile's relative error `e` is what the format promises for tolerance `eps`: the
/// truncation's `ε`, with the `f16` rounding of the basis (relative `2⁻¹¹` at most per value)
/// added in quadrature.
fn within_tolerance(e: f64, eps: f32) -> bool {
    e <= (f64::from(eps).powi(2) + 2f64.powi(-20)).sqrt()
}

/// Energy and peak of a decoded pane, recomputed here from the spec's words (§6): binary64 sums
/// over the tiles in tile order, texels row-major within a tile, rounded to binary32.
fn spec_energy_peak(pane: &[[f32; 3]], res: usize, t: usize) -> ([f32; 3], [f32; 3]) {
    let mut energy = [0f64; 3];
    let mut peak = [0f32; 3];
    for tile in 0..(res / t) * (res / t) {
        let (x0, y0) = (tile % (res / t) * t, tile / (res / t) * t);
        for j in 0..t {
            for i in 0..t {
                let v = pane[(y0 + j) * res + x0 + i];
                for ch in 0..3 {
                    energy[ch] += f64::from(v[ch]);
                    peak[ch] = peak[ch].max(v[ch]);
                }
            }
        }
    }
    (energy.map(|e| e as f32), peak)
}

#[test]
fn round_trip() {
    let dir = test_dir("round-trip");
    let s = scene(32, 8, 5, 1);
    let path = dir.join("a.prm");
    let size = write_scene(&path, &s, WriterOptions::default());
    assert_eq!(size, std::fs::metadata(&path).unwrap().len());
    assert_eq!(dir_listing(&dir), vec!["a.prm"]);

    let mut a = Archive::open(&path).unwrap();
    let info = a.info().clone();
    assert_eq!((info.major, info.minor), (2, 0));
    assert_eq!((info.pane_count, info.tiles), (5, 16));
    // Pane 0 is all zero, and so is the left quarter (one tile column) of the others.
    let ranks = a.pane_basis().ranks().to_vec();
    for (t, &r) in ranks.iter().enumerate() {
        assert_eq!(r == 0, t % 4 == 0, "tile {t}: rank {r} ({ranks:?})");
        assert!(r <= 15, "at most 3P");
    }
    assert_eq!(info.max_rank, *ranks.iter().max().unwrap());
    assert_eq!(info.rank_sum, ranks.iter().map(|&r| u64::from(r)).sum::<u64>());
    assert_eq!(info.basis_bytes, 2 * 64 * info.rank_sum);
    assert_eq!(info.coefficient_bytes, 6 * 5 * info.rank_sum + 4 * 5 * 16);
    assert_eq!(info.pane_texel_bytes, 5 * 32 * 32 * 4);
    let panes_section = info.sections.iter().find(|x| x.name == "panes").unwrap();
    assert_eq!(panes_section.raw_size, a.pane_basis().byte_size());
    assert_eq!(
        panes_section.raw_size,
        16 + 4 * 16 + info.basis_bytes + info.coefficient_bytes
    );
    let names: Vec<&str> = info.sections.iter().map(|s| s.name.as_str()).collect();
    for n in ["metadata", "atlas", "entries", "clusters", "panes"] {
        assert!(names.contains(&n), "{names:?}");
    }

    let mut expected_meta = s.metadata.clone();
    expected_meta.texel_encoding = "rgb9e5ufloat".into();
    expected_meta.texel_relative_error_bound = RGB9E5_MAX_RELATIVE_ERROR;
    assert_eq!(a.metadata(), &expected_meta);
    assert_eq!(a.atlas(), &s.atlas);
    assert_eq!(a.entries(), &s.entries[..]);
    assert_eq!(a.clusters().len(), s.clusters.len());

    let decoded: Vec<Vec<[f32; 3]>> = (0..5).map(|p| a.read_pane(p).unwrap()).collect();
    for (t, e) in tile_errors(&s.panes, &decoded, 32, 8).into_iter().enumerate() {
        assert!(within_tolerance(e, PANE_TOLERANCE), "tile {t}: relative error {e}");
    }
    for (p, pane) in decoded.iter().enumerate() {
        let rgb9e5 = a.read_pane_rgb9e5(p).unwrap();
        assert_eq!(rgb9e5, pane.iter().map(|&t| encode_rgb9e5(t)).collect::<Vec<_>>());
        let cl = &a.clusters()[p];
        let (energy, peak) = spec_energy_peak(pane, 32, 8);
        assert_eq!(cl.energy.map(f32::to_bits), energy.map(f32::to_bits), "pane {p}");
        assert_eq!(cl.peak.map(f32::to_bits), peak.map(f32::to_bits), "pane {p}");
        assert_eq!((cl.first, cl.count), (s.clusters[p].first, s.clusters[p].count));
        assert_eq!(cl.centroid, s.clusters[p].centroid);
        assert!(pane.iter().flatten().all(|v| *v >= 0.0 && v.is_sign_positive()));
    }
    assert_eq!(a.clusters()[0].energy, [0.0; 3]);
    assert!(matches!(a.read_pane(5), Err(Error::InvalidInput(_))));
    assert!(matches!(a.read_pane_rgb9e5(5), Err(Error::InvalidInput(_))));

    let report = a.verify().unwrap();
    assert_eq!(report.panes, 5);
    assert_eq!(report.sections, 5);
    assert_eq!(report.bytes_hashed + 64 + 5 * 48, size);

    // from_bytes agrees with open
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(read_all(&bytes).unwrap().panes[3], a.read_pane(3).unwrap());
}

/// Writing the same input twice gives the same bytes, whether the panes are compressed by
/// `finish` or before it by `compress_panes`, which fills in the cluster table as written.
#[test]
fn the_same_input_writes_the_same_bytes() {
    let s = scene(32, 8, 6, 3);
    let (_, a_path, b_path, mut w) = written_and_started("same-bytes", &s, "first.prm", "second.prm");
    assert_eq!(w.panes_remaining(), 6);
    assert!(w.compress_panes().is_err(), "panes are missing");
    for pane in &s.panes {
        w.add_pane(pane).unwrap();
    }
    assert!(w.add_pane(&s.panes[0]).is_err(), "one pane too many");
    assert!(w.clusters().iter().all(|c| c.energy == [0.0; 3]), "not compressed yet");
    let ranks = w.compress_panes().unwrap().ranks().to_vec();
    let clusters = w.clusters().to_vec();
    assert!(clusters[1..].iter().all(|c| c.energy[0] > 0.0 && c.peak[0] > 0.0));
    assert_eq!(w.compress_panes().unwrap().ranks(), &ranks[..]);
    w.metadata_mut().timings.insert("compress".into(), 0.125);
    w.finish().unwrap();
    let a = std::fs::read(&a_path).unwrap();
    let b = std::fs::read(&b_path).unwrap();
    let (ra, rb) = (read_all(&a).unwrap(), read_all(&b).unwrap());
    assert_eq!(ra.panes, rb.panes);
    assert_eq!(rb.clusters, clusters);
    assert_eq!(ra.clusters, clusters);
    assert_eq!(rb.metadata.timings["compress"], 0.125);
    // Without the extra timing, byte for byte.
    let third = a_path.with_file_name("third.prm");
    write_scene(&third, &s, WriterOptions::default());
    assert_eq!(std::fs::read(&third).unwrap(), a);
}

#[test]
fn uncompressed_sections_round_trip() {
    let (bytes, s) = small_archive("uncompressed", UNCOMPRESSED);
    let c = read_all(&bytes).unwrap();
    assert_eq!(c.entries, s.entries);
    let a = Archive::from_bytes(&bytes).unwrap();
    for sec in &a.info().sections {
        assert_eq!(sec.compression, compression::NONE, "{}", sec.name);
    }
    verify_bytes(&bytes).unwrap();
}

#[test]
fn truncation_at_every_offset_is_an_error() {
    let (bytes, _) = small_archive("truncation", WriterOptions::default());
    assert!(bytes.len() > 500, "{}", bytes.len());
    for len in 0..bytes.len() {
        match Archive::from_bytes(&bytes[..len]) {
            Err(Error::Truncated { .. }) => {}
            Err(e) => panic!("truncated to {len}: expected Truncated, got {e}"),
            Ok(_) => panic!("truncated to {len} bytes opened successfully"),
        }
    }
    // appended bytes are refused too
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(Archive::from_bytes(&longer), Err(Error::Inconsistent { .. })));
}

#[test]
fn bit_flips_never_give_silently_different_data() {
    let (bytes, _) = small_archive("bitflips", WriterOptions::default());
    let original = read_all(&bytes).unwrap();
    let mut rng = Rng(0xB17F11B5);
    let mut kinds = std::collections::BTreeMap::<String, usize>::new();
    for _ in 0..1000 {
        let mut m = bytes.clone();
        let bit = rng.below(m.len() as u64 * 8) as usize;
        m[bit / 8] ^= 1 << (bit % 8);
        match read_all(&m) {
            Ok(c) => assert_eq!(c, original, "flip of bit {bit} changed the data silently"),
            Err(e) => {
                let k = format!("{e:?}");
                let k = k.split([' ', '{', '(']).next().unwrap().to_string();
                *kinds.entry(k).or_default() += 1;
            }
        }
        // Every byte is covered by a checksum, so verification always notices.
        assert!(verify_bytes(&m).is_err(), "flip of bit {bit} passed verify()");
    }
    println!("bit flip outcomes: {kinds:?}");
    assert!(kinds.contains_key("ChecksumMismatch"));
}

#[test]
fn unknown_sections_are_skipped() {
    let dir = test_dir("unknown");
    let s = scene(16, 8, 2, 11);
    let path = dir.join("custom.prm");
    let mut w = start_writer(&path, &s).unwrap();
    assert!(w.add_custom_section(kind::ATLAS, vec![1]).is_err());
    assert!(w.add_custom_section(0, vec![1]).is_err());
    w.add_custom_section(kind::PRIVATE_FIRST + 7, b"hello, extension".repeat(10))
        .unwrap();
    add_panes_and_finish(w, &s);
    let bytes = std::fs::read(&path).unwrap();
    let mut a = Archive::from_bytes(&bytes).unwrap();
    assert_eq!(a.info().sections.len(), 6);
    assert!(a.info().sections.iter().any(|s| s.name.starts_with("unknown")));
    assert_eq!(
        a.read_custom_section(kind::PRIVATE_FIRST + 7).unwrap().unwrap(),
        b"hello, extension".repeat(10)
    );
    assert_eq!(a.read_custom_section(99).unwrap(), None);
    a.verify().unwrap();

    // Splice in, by hand, a section of an unknown kind with an unknown
    // compression code: a reader must skip it without interpreting it.
    let secs = sections(&bytes);
    let table_off = u64_at(&bytes, 16).unwrap() as usize;
    let n = secs.len();
    let payload = b"future data, compression 9".to_vec();
    let mut out = bytes[..table_off].to_vec();
    let payload_off = out.len();
    out.extend_from_slice(&payload);
    let new_table_off = out.len();
    out.extend_from_slice(&bytes[table_off..table_off + n * 48]);
    let mut rec = Vec::new();
    rec.extend_from_slice(&1234u32.to_le_bytes());
    rec.extend_from_slice(&9u32.to_le_bytes());
    rec.extend_from_slice(&(payload_off as u64).to_le_bytes());
    rec.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    rec.extend_from_slice(&(1u64 << 40).to_le_bytes());
    rec.extend_from_slice(&checksum(&payload).to_le_bytes());
    rec.extend_from_slice(&0u64.to_le_bytes());
    out.extend_from_slice(&rec);
    out[12..16].copy_from_slice(&(n as u32 + 1).to_le_bytes());
    let len = out.len() as u64;
    put_u64(&mut out, 16, new_table_off as u64);
    put_u64(&mut out, 24, len);
    resign(&mut out);
    let mut a = Archive::from_bytes(&out).unwrap();
    assert_eq!(a.info().sections.len(), 7);
    assert_eq!(read_all(&out).unwrap(), read_all(&bytes).unwrap());
    a.verify().unwrap();
    assert!(
        a.read_custom_section(1234).is_err(),
        "unknown compression cannot be decoded"
    );
}

/// The metadata's `accuracy` key is the bake's estimate (formats/prm.md §3.1): a malformed one
/// is corrupt metadata.
#[test]
fn a_malformed_accuracy_key_is_refused() {
    let (bytes, _) = small_archive("accuracy-key", WriterOptions::default());
    let a = Archive::from_bytes(&bytes).unwrap();
    assert!(a.metadata().accuracy.is_none());
    let mut json = serde_json::to_value(a.metadata()).unwrap();
    json["accuracy"] = serde_json::json!("an extension of some other writer");
    let raw = serde_json::to_vec(&json).unwrap();
    let bad = replace_section(&bytes, kind::METADATA, &raw, compression::NONE, raw.len() as u64);
    let err = Archive::from_bytes(&bad).err().unwrap();
    assert!(matches!(err, Error::Inconsistent { .. }), "{err}");
    assert!(err.to_string().to_lowercase().contains("accuracy"), "{err}");
}

#[test]
fn other_majors_are_refused_later_minors_accepted() {
    let (bytes, _) = small_archive("versions", WriterOptions::default());
    let mut newer = bytes.clone();
    put_u16(&mut newer, 8, 3);
    put_u16(&mut newer, 10, 3);
    resign(&mut newer);
    let err = Archive::from_bytes(&newer).err().unwrap();
    assert!(matches!(err, Error::UnsupportedVersion { major: 3, minor: 3 }), "{err}");
    assert!(err.to_string().contains("3.3"), "{err}");

    // A later minor than this reader knows (2.1) may use reserved fields; it ignores them.
    let mut minor = bytes.clone();
    put_u16(&mut minor, 10, VERSION_MINOR + 1);
    put_u64(&mut minor, 32, 0xdead_beef);
    resign(&mut minor);
    let a = Archive::from_bytes(&minor).unwrap();
    assert_eq!((a.info().major, a.info().minor), (2, VERSION_MINOR + 1));
    // ... but in a 2.0 file they must be zero.
    let mut strict = bytes.clone();
    put_u64(&mut strict, 32, 0xdead_beef);
    resign(&mut strict);
    assert!(matches!(Archive::from_bytes(&strict), Err(Error::Inconsistent { .. })));

    let mut bad = bytes.clone();
    bad[1] = b'Q';
    assert!(matches!(Archive::from_bytes(&bad), Err(Error::BadMagic)));
    assert!(matches!(
        Archive::from_bytes(b"PK\x03\x04 not an archive"),
        Err(Error::BadMagic)
    ));
}

/// A format 1 archive is refused, before anything else of it is read, with a message that says
/// what it is and that the scene must be baked again.
#[test]
fn format_1_archives_are_refused_with_the_re_bake_message() {
    let (bytes, _) = small_archive("format-1", WriterOptions::default());
    for minor in [0u16, 9] {
        let mut old = bytes.clone();
        put_u16(&mut old, 8, 1);
        put_u16(&mut old, 10, minor);
        resign(&mut old);
        let err = Archive::from_bytes(&old).err().unwrap();
        assert!(
            matches!(err, Error::Rebake { major: 1, minor: m } if m == minor),
            "{err}"
        );
        let msg = err.to_string();
        assert!(msg.contains(&format!("format 1.{minor}")), "{msg}");
        assert!(msg.contains("re-bake") && msg.contains("prm-bake"), "{msg}");
        // Even with a header checksum of another layout: the version comes first.
        old[56] ^= 0xff;
        assert!(matches!(Archive::from_bytes(&old), Err(Error::Rebake { .. })));
    }
    // Through a file, and in an anyhow chain, the same sentence.
    let dir = test_dir("format-1-file");
    let mut old = bytes.clone();
    put_u16(&mut old, 8, 1);
    put_u16(&mut old, 10, 0);
    resign(&mut old);
    std::fs::write(dir.join("old.prm"), &old).unwrap();
    let err = Archive::open(dir.join("old.prm")).err().unwrap();
    let chain = format!("{:#}", anyhow::Error::from(err).context("cannot open old.prm"));
    assert!(chain.contains("format 1.0") && chain.contains("re-bake"), "{chain}");
}

#[test]
fn atomic_write_leaves_old_archive_untouched() {
    let s = scene(16, 8, 2, 5);
    let (dir, path) = written("atomic", "scene.prm", &s);
    let old = std::fs::read(&path).unwrap();
    let other = scene(16, 8, 2, 6);
    // The old archive is still there, unchanged, and nothing else is.
    let untouched = || {
        assert_eq!(std::fs::read(&path).unwrap(), old);
        assert_eq!(dir_listing(&dir), vec!["scene.prm"]);
    };

    // 1. dropped without finish
    {
        let mut w = start_writer(&path, &other).unwrap();
        w.add_pane(&other.panes[0]).unwrap();
        assert_eq!(dir_listing(&dir).len(), 2, "temp file exists while writing");
    }
    untouched();

    // 2. finish with a pane missing
    let mut w = start_writer(&path, &other).unwrap();
    w.add_pane(&other.panes[0]).unwrap();
    assert!(matches!(w.finish(), Err(Error::InvalidInput(_))));
    untouched();

    // 3. wrong pane size, then finish
    let mut w = start_writer(&path, &other).unwrap();
    assert!(matches!(w.add_pane(&[[1.0; 3]; 10]), Err(Error::InvalidInput(_))));
    assert!(w.finish().is_err());
    untouched();

    // 4. the pane producer panics after a pane
    let r = std::panic::catch_unwind(|| {
        let mut w = start_writer(&path, &other).unwrap();
        w.add_pane(&other.panes[0]).unwrap();
        panic!("producer failed");
    });
    assert!(r.is_err());
    untouched();

    // 5. the destination becomes a (non-empty) directory during the write:
    // `finish` refuses it instead of renaming over it
    let blocked = dir.join("blocked.prm");
    let mut w = start_writer(&blocked, &other).unwrap();
    std::fs::create_dir(&blocked).unwrap();
    std::fs::write(blocked.join("keep"), b"x").unwrap();
    for p in &other.panes {
        w.add_pane(p).unwrap();
    }
    let err = w.finish().unwrap_err();
    assert!(matches!(err, Error::Destination { .. }), "{err}");
    assert_eq!(dir_listing(&dir), vec!["blocked.prm", "scene.prm"]);

    // 6. invalid inputs are refused before any file is created
    let mut bad = other.clusters.clone();
    bad[1].first = 0;
    assert!(ArchiveWriter::create(&path, other.metadata.clone(), &other.atlas, &other.entries, &bad).is_err());
    let mut meta = other.metadata.clone();
    meta.timings.insert("nan".into(), f64::NAN);
    assert!(ArchiveWriter::create(&path, meta, &other.atlas, &other.entries, &other.clusters).is_err());
    assert_eq!(dir_listing(&dir), vec!["blocked.prm", "scene.prm"]);

    // and a successful write replaces the archive
    write_scene(&path, &other, WriterOptions::default());
    assert_ne!(std::fs::read(&path).unwrap(), old);
    assert_eq!(dir_listing(&dir), vec!["blocked.prm", "scene.prm"]);
}

/// Random byte mutations, insertions and deletions, with and without
/// re-signed checksums: the reader must never panic, and must either fail
/// or return data (re-signed mutations can legitimately change data).
#[test]
fn fuzz_mutated_archives_never_panic() {
    let mut rng = Rng(0xF022);
    for (name, opts) in [("fuzz-zstd", WriterOptions::default()), ("fuzz-raw", UNCOMPRESSED)] {
        let (bytes, _) = small_archive(name, opts);
        let mut outcomes = std::collections::BTreeMap::<String, usize>::new();
        for iter in 0..1500 {
            let mut m = bytes.clone();
            for _ in 0..1 + rng.below(4) {
                let pos = rng.below(m.len() as u64 + 1) as usize;
                match rng.below(6) {
                    0 if pos < m.len() => {
                        m.remove(pos);
                    }
                    1 => m.insert(pos.min(m.len()), rng.next() as u8),
                    2 if pos + 8 <= m.len() => {
                        // plausible-looking integers: small, huge, boundary
                        let v: u64 = match rng.below(4) {
                            0 => rng.below(256),
                            1 => u64::MAX - rng.below(4),
                            2 => 1 << rng.below(64),
                            _ => m.len() as u64 + rng.below(64) - 32,
                        };
                        let w = [1usize, 2, 4, 8][rng.below(4) as usize];
                        m[pos..pos + w].copy_from_slice(&v.to_le_bytes()[..w]);
                    }
                    _ if pos < m.len() => m[pos] = rng.next() as u8,
                    _ => {}
                }
            }
            // Half the time, fix lengths and checksums so structural checks run.
            if iter % 2 == 0 {
                let len = m.len() as u64;
                if rng.below(2) == 0 {
                    put_u64(&mut m, 24, len);
                }
                resign(&mut m);
            }
            let k = match read_all(&m) {
                Ok(_) => "opened".to_string(),
                Err(e) => format!("{e:?}").split([' ', '{', '(']).next().unwrap().to_string(),
            };
            *outcomes.entry(k).or_default() += 1;
            let _ = verify_bytes(&m);
        }
        println!("{name}: {outcomes:?}");
        assert!(
            outcomes.len() >= 4,
            "mutations should reach several checks: {outcomes:?}"
        );
    }
}

/// Hostile sizes: huge declared raw sizes or counts fail fast, without
/// allocating what they declare.
#[test]
fn hostile_sizes_are_rejected_before_allocation() {
    let (bytes, _) = small_archive("hostile", UNCOMPRESSED);
    let secs = sections(&bytes);
    let table = u64_at(&bytes, 16).unwrap() as usize;
    for (i, s) in secs.iter().enumerate() {
        for raw in [u64::MAX, 1 << 40, (s.size as u64) + 1] {
            let mut m = bytes.clone();
            put_u64(&mut m, table + i * 48 + 24, raw); // raw_size
            m[table + i * 48 + 4] = 1; // pretend zstd
            resign(&mut m);
            assert!(Archive::from_bytes(&m).is_err());
        }
    }
    // a pane count of 2^32-1 in the panes header
    let p = secs.iter().find(|s| s.kind == kind::PANES).unwrap();
    let mut m = bytes.clone();
    m[p.offset + 8..p.offset + 12].copy_from_slice(&u32::MAX.to_le_bytes());
    resign(&mut m);
    assert!(matches!(Archive::from_bytes(&m), Err(Error::Inconsistent { .. })));
    // a section count of 2^32-1
    let mut m = bytes.clone();
    m[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
    resign(&mut m);
    assert!(matches!(Archive::from_bytes(&m), Err(Error::Inconsistent { .. })));
    // an atlas resolution of 2^31 (section stored uncompressed)
    let a = secs.iter().find(|s| s.kind == kind::ATLAS).unwrap();
    let mut m = bytes.clone();
    m[a.offset..a.offset + 4].copy_from_slice(&(1u32 << 31).to_le_bytes());
    resign(&mut m);
    assert!(matches!(Archive::from_bytes(&m), Err(Error::Inconsistent { .. })));
}

#[test]
fn python_reader_agrees_with_rust() {
    let dir = test_dir("python");
    for (name, options) in [("zstd", WriterOptions::default()), ("plain", UNCOMPRESSED)] {
        if !python_reader_check(&dir.join(format!("{name}.prm")), options) {
            return;
        }
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../formats/read_prm.py");
    // An archive with none of the optional sections reads too.
    let (bytes, _) = small_archive("python-plain", WriterOptions::default());
    let path = dir.join("small.prm");
    std::fs::write(&path, &bytes).unwrap();
    let out = Command::new("python3").arg(&script).arg(&path).output().unwrap();
    assert!(
        out.status.success(),
        "read_prm.py failed on an archive without optional sections: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["version"], "2.0");
    assert!(j["near_field"].is_null() && j["probe_rays"].is_null());
    // A format 1 archive is refused with the re-bake message.
    let mut old = bytes.clone();
    put_u16(&mut old, 8, 1);
    put_u16(&mut old, 10, 9);
    resign(&mut old);
    std::fs::write(&path, &old).unwrap();
    let out = Command::new("python3").arg(&script).arg(&path).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("1.9") && err.contains("re-bake"), "{err}");
}

/// Writes an archive, reads it with `formats/read_prm.py` and compares;
/// returns false if the test had to be skipped.
/// Every element of the JSON array `v` through `item`.
fn json_list<T>(v: &serde_json::Value, item: impl FnMut(&serde_json::Value) -> T) -> Vec<T> {
    v.as_array().unwrap().iter().map(item).collect()
}

fn python_reader_check(path: &Path, opts: WriterOptions) -> bool {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../formats/read_prm.py");
    let dir = path.parent().unwrap();
    let s = scene(16, 8, 4, 21);
    let mut metadata = s.metadata.clone();
    let accuracy = prm_format::Accuracy {
        exit_points: 1024,
        paths: 64,
        top_k: 4,
        residual_groups: 2,
        lights: vec![prm_format::LightAccuracy {
            position: [0.25, 1.5, -0.5],
            error: 0.125,
            measured: 0.25,
            reference_noise: 0.2,
            energy: 0.96875,
            error_all_clusters: 0.0625,
            standard_error: 0.015625,
        }],
    };
    metadata.accuracy = Some(accuracy.clone());
    let mut w = ArchiveWriter::create_with_options(path, metadata, &s.atlas, &s.entries, &s.clusters, opts).unwrap();
    w.add_custom_section(kind::PRIVATE_FIRST, b"skip me".to_vec()).unwrap();
    let energy: Vec<[f32; 3]> = (0..s.entries.len()).map(|i| [0.25 * i as f32, 1.0, 3.5]).collect();
    w.set_entry_energy(energy.clone()).unwrap();
    let groups = emitter_groups(&s, 2);
    w.set_emitters(groups.clone()).unwrap();
    let sky = sky_transfer(&s);
    w.set_sky(sky.clone()).unwrap();
    let probes = probe_set(&s);
    w.set_probes(probes.clone()).unwrap();
    let rays = probe_ray_set(&s);
    w.set_probe_rays(rays.clone()).unwrap();
    let near = near_set(&s);
    w.set_near_field(near.clone()).unwrap();
    add_panes_and_finish(w, &s);

    let out = match Command::new("python3")
        .arg(&script)
        .arg("--pane")
        .arg("2")
        .arg(path)
        .output()
    {
        Ok(o) => o,
        // A skip is a failure in CI, which has python3 and zstd (`.ci/run`).
        Err(e) if std::env::var_os("CI").is_none() => {
            println!("SKIPPED python_reader_agrees_with_rust: cannot run python3 ({e})");
            return false;
        }
        Err(e) => panic!("cannot run python3 ({e})"),
    };
    if out.status.code() == Some(3) {
        let why = String::from_utf8_lossy(&out.stderr).trim().to_string();
        assert!(std::env::var_os("CI").is_none(), "read_prm.py cannot run in CI: {why}");
        println!("SKIPPED python_reader_agrees_with_rust: {why}");
        return false;
    }
    assert!(
        out.status.success(),
        "read_prm.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let a = Archive::open(path).unwrap();
    assert_eq!(j["version"], "2.0");
    assert_eq!(j["checksums_verified"], true);
    let ja = &j["accuracy"];
    assert_eq!(ja["exit_points"], 1024);
    assert_eq!(ja["top_k"], 4);
    assert_eq!(ja["residual_groups"], 2);
    assert_eq!(ja["mean_error"], 0.125);
    let l = &ja["lights"][0];
    assert_eq!(l["position"], serde_json::json!([0.25, 1.5, -0.5]));
    for (k, v) in [
        ("measured", 0.25),
        ("reference_noise", 0.2),
        ("energy", 0.96875),
        ("error_all_clusters", 0.0625),
        ("standard_error", 0.015625),
    ] {
        assert_eq!(l[k], v, "{k}");
    }
    assert_eq!(Archive::open(path).unwrap().metadata().accuracy, Some(accuracy));
    let jb = &j["panes"];
    let ranks: Vec<u32> = json_list(&jb["ranks"], |v| v.as_u64().unwrap() as u32);
    assert_eq!(ranks, a.pane_basis().ranks());
    assert_eq!(jb["max_rank"], a.info().max_rank);
    assert_eq!(jb["basis_bytes"], a.info().basis_bytes);
    assert_eq!(jb["coefficient_bytes"], a.info().coefficient_bytes);
    assert_eq!(j["resolution"], 16);
    assert_eq!(j["tile_size"], 8);
    assert_eq!(j["covered_texels"], a.atlas().covered_texels());
    assert_eq!(j["sections"].as_array().unwrap().len(), 12);
    let je = j["emitters"].as_array().unwrap();
    assert_eq!(je.len(), groups.len());
    let f3 = |v: &serde_json::Value| [0, 1, 2].map(|k| v[k].as_f64().unwrap() as f32);
    for (jg, g) in je.iter().zip(a.emitters()) {
        assert_eq!(jg["name"], g.name.as_str());
        assert_eq!(jg["material"], g.material);
        assert_eq!(f3(&jg["radiance"]), g.radiance);
        assert_eq!(json_list(&jg["entry_irradiance"], f3), g.entry_irradiance);
        assert_eq!(json_list(&jg["direct"], f3), g.direct);
        let indirect: Option<Vec<[f32; 3]>> = jg["indirect"].as_array().map(|v| v.iter().map(f3).collect());
        assert_eq!(indirect, g.indirect);
    }
    assert_eq!(a.emitters(), &groups[..]);
    let f = |v: &serde_json::Value| v.as_f64().unwrap() as f32;
    let direct = json_list(&j["sky"]["direct"], |t| json_list(t, f));
    assert_eq!(
        direct,
        a.sky().unwrap().direct.iter().map(|t| t.to_vec()).collect::<Vec<_>>()
    );
    let indirect = json_list(&j["sky"]["indirect"], |t| json_list(t, f3));
    assert_eq!(
        indirect,
        a.sky().unwrap().indirect.iter().map(|t| t.to_vec()).collect::<Vec<_>>()
    );
    assert_eq!(a.sky(), Some(&sky));
    let jp = &j["probes"];
    let u = |v: &serde_json::Value| v.as_u64().unwrap() as u32;
    let back = Probes {
        grid: ProbeGrid {
            dims: [0, 1, 2].map(|k| u(&jp["dims"][k])),
            origin: f3(&jp["origin"]),
            spacing: f(&jp["spacing"]),
        },
        cells: json_list(&jp["cells"], u),
        positions: json_list(&jp["positions"], f3),
        transfer: json_list(&jp["transfer"], |t| std::array::from_fn(|c| f3(&t[c]))),
        sky: jp["sky"].as_array().map(|s| {
            s.iter()
                .map(|m| std::array::from_fn(|i| std::array::from_fn(|k| f3(&m[i][k]))))
                .collect()
        }),
    };
    assert_eq!(a.probes(), Some(&back));
    assert_eq!(a.probes(), Some(&probes));
    let gather_points = |v: &serde_json::Value| -> Vec<GatherPoint> {
        json_list(v, |g| GatherPoint {
            texel: u(&g["texel"]),
            position: f3(&g["position"]),
            normal: f3(&g["normal"]),
            albedo: f3(&g["albedo"]),
            emission: f3(&g["emission"]),
            emitter: u(&g["emitter"]),
        })
    };
    let jr = &j["probe_rays"];
    let back = ProbeRays {
        rays_per_probe: u(&jr["rays_per_probe"]),
        points: gather_points(&jr["points"]),
        hits: json_list(&jr["hits"], u),
    };
    assert_eq!(a.probe_rays(), Some(&back));
    assert_eq!(a.probe_rays(), Some(&rays));
    let jn = &j["near_field"];
    let back = NearField {
        rays_per_exit: u(&jn["rays_per_exit"]),
        disk: jn["disk"].as_f64().unwrap() as f32,
        indirect_disk: jn["indirect_disk"].as_f64().unwrap() as f32,
        complement: jn["complement"].as_bool().unwrap(),
        points: gather_points(&jn["points"]),
        exits: json_list(&jn["exits"], |x| NearExit {
            texel: u(&x["texel"]),
            end: u(&x["end"]),
        }),
        hits: json_list(&jn["hits"], |h| NearHit {
            point: u(&h["point"]),
            distance2: h["distance2"].as_f64().unwrap() as f32,
        }),
    };
    assert_eq!(a.near_field(), Some(&back));
    assert_eq!(a.near_field(), Some(&near));
    assert_eq!(json_list(&j["entry_energy"], f3), energy);
    assert_eq!(
        j["metadata"]["scene_fingerprint"],
        format!("{:016x}", s.metadata.scene_fingerprint)
    );
    let f = |v: &serde_json::Value| v.as_f64().unwrap() as f32;
    let v3 = |v: &serde_json::Value| [f(&v[0]), f(&v[1]), f(&v[2])];
    let clusters = j["clusters"].as_array().unwrap();
    assert_eq!(clusters.len(), a.clusters().len());
    for (jc, c) in clusters.iter().zip(a.clusters()) {
        assert_eq!(jc["first"], c.first);
        assert_eq!(jc["count"], c.count);
        assert_eq!(v3(&jc["energy"]), c.energy);
        assert_eq!(v3(&jc["peak"]), c.peak);
    }
    let entries = j["entries"].as_array().unwrap();
    assert_eq!(entries.len(), a.entries().len());
    for (je, e) in entries.iter().zip(a.entries()) {
        assert_eq!(v3(&je["position"]), e.position);
        assert_eq!(v3(&je["normal"]), e.normal);
        assert_eq!(je["cluster"], e.cluster);
    }
    let pane = a.read_pane(2).unwrap();
    let texels = j["pane"]["texels"].as_array().unwrap();
    assert_eq!(texels.len(), pane.len());
    for (jt, t) in texels.iter().zip(&pane) {
        assert_eq!(v3(jt), *t, "the spec pins every decoded value's rounding");
    }
    // The spec pins the summation order, so Python's energy is bit-identical.
    assert_eq!(v3(&j["pane"]["energy"]), a.clusters()[2].energy);
    assert_eq!(v3(&j["pane"]["peak"]), a.clusters()[2].peak);

    // The Python reader rejects damage too.
    let mut bytes = std::fs::read(path).unwrap();
    let n = bytes.len();
    bytes[n / 2] ^= 0x10;
    let bad = dir.join("bad.prm");
    std::fs::write(&bad, &bytes).unwrap();
    let out = Command::new("python3").arg(&script).arg(&bad).output().unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stdout));
    true
}

/// Compression time, size and accuracy at the bundled Cornell box's size: 512 panes of 256²
/// texels in 64² tiles, synthetic smooth light. Run with
/// `cargo test -p prm-format --release --test archive -- --ignored --nocapture cornell`.
#[test]
#[ignore]
fn measure_cornell_size_panes() {
    let (res, tile, panes) = (256u32, 64u32, 512usize);
    let mut rng = Rng(2026);
    let entries: Vec<Entry> = (0..panes)
        .map(|c| Entry {
            position: [rng.unit(), rng.unit(), rng.unit()],
            normal: [0.0, 0.0, 1.0],
            cluster: c as u32,
        })
        .collect();
    let clusters: Vec<Cluster> = (0..panes)
        .map(|c| Cluster::new(c as u32, 1, entries[c].position, [0.0, 0.0, 1.0]))
        .collect();
    let atlas = AtlasSection::new(res, tile);
    let mut rng = Rng(7);
    let dense: Vec<Vec<[f32; 3]>> = (0..panes).map(|_| sharp_pane(&mut rng, res)).collect();
    let path = test_dir("measure").join("cornell-size.prm");
    let mut w = ArchiveWriter::create(&path, Metadata::new("measure", "0"), &atlas, &entries, &clusters).unwrap();
    for p in &dense {
        w.add_pane(p).unwrap();
    }
    let started = std::time::Instant::now();
    w.compress_panes().unwrap();
    let compress = started.elapsed();
    let size = w.finish().unwrap();
    let written = started.elapsed();
    let mut a = Archive::open(&path).unwrap();
    let info = a.info().clone();
    let t0 = std::time::Instant::now();
    a.verify().unwrap();
    let verify = t0.elapsed();
    let t0 = std::time::Instant::now();
    a.pane_basis().energy_peak();
    let energy_peak = t0.elapsed();
    let t0 = std::time::Instant::now();
    let decoded: Vec<Vec<[f32; 3]>> = (0..panes).map(|p| a.read_pane(p).unwrap()).collect();
    let decode = t0.elapsed();
    let errors = tile_errors(&dense, &decoded, res as usize, tile as usize);
    let worst = errors.iter().copied().fold(0f64, f64::max);
    // A lit combination: random positive weights, relative RMSE against the dense panes.
    let weights: Vec<f32> = (0..panes).map(|_| rng.unit()).collect();
    let lit = |set: &[Vec<[f32; 3]>]| -> Vec<f64> {
        let mut out = vec![0f64; (res * res * 3) as usize];
        for (p, w) in set.iter().zip(&weights) {
            for (o, v) in out.chunks_exact_mut(3).zip(p) {
                for ch in 0..3 {
                    o[ch] += f64::from(*w) * f64::from(v[ch]);
                }
            }
        }
        out
    };
    let (want, got) = (lit(&dense), lit(&decoded));
    let num: f64 = want.iter().zip(&got).map(|(a, b)| (a - b).powi(2)).sum();
    let den: f64 = want.iter().map(|a| a * a).sum();
    let panes_bytes = info.sections.iter().find(|x| x.name == "panes").unwrap();
    println!(
        "{panes} panes of {res}² in {tile}² tiles: compressed in {compress:.2?} (archive written in {written:.2?}, \
         verified in {verify:.2?}, of which energy and peak {energy_peak:.2?}; every pane decoded in {decode:.2?}); ranks mean {:.1}, max {}; panes section {:.2} MiB raw, {:.2} MiB stored \
         (dense RGB9E5 {:.1} MiB); archive {:.2} MiB; worst tile error {worst:.4}; lit combination {:.4}%",
        info.rank_sum as f64 / info.tiles as f64,
        info.max_rank,
        panes_bytes.raw_size as f64 / 1048576.0,
        panes_bytes.stored_size as f64 / 1048576.0,
        info.pane_texel_bytes as f64 / 1048576.0,
        size as f64 / 1048576.0,
        100.0 * (num / den).sqrt(),
    );
    assert!(within_tolerance(worst, PANE_TOLERANCE), "{worst}");
}

/// A cluster's light as a bake of a room gives it, roughly: one falloff of 1 to 7 texels about the
/// cluster's own place, a broad one about another place, and a soft tinted floor, with the band
/// of [`zero_region`] empty. Sharper than [`smooth_pane`], so that the tiles near a cluster need
/// a rank of a few tens, as in the bundled Cornell box.
fn sharp_pane(rng: &mut Rng, res: u32) -> Vec<[f32; 3]> {
    let near = [rng.unit() * res as f32, rng.unit() * res as f32];
    let radius = (0.004 + 0.024 * rng.unit()) * res as f32;
    let far = [rng.unit() * res as f32, rng.unit() * res as f32];
    let tint = [0.2 + rng.unit(), 0.2 + rng.unit(), 0.2 + rng.unit()];
    let floor = 0.02 * rng.unit();
    pane_image(res, |x, y| {
        let d2 = |c: [f32; 2]| (x as f32 - c[0]).powi(2) + (y as f32 - c[1]).powi(2);
        let f = 4.0 / (1.0 + d2(near) / (radius * radius)) + 0.5 / (1.0 + d2(far) / (0.09 * (res * res) as f32));
        std::array::from_fn(|k| (f + floor) * tint[k])
    })
}

/// A `res`² pane of `texel(x, y)`, but for the empty band of [`zero_region`].
fn pane_image(res: u32, texel: impl Fn(u32, u32) -> [f32; 3]) -> Vec<[f32; 3]> {
    (0..res)
        .flat_map(|y| (0..res).map(move |x| (x, y)))
        .map(|(x, y)| if zero_region(x, y, res) { [0.0; 3] } else { texel(x, y) })
        .collect()
}

/// 10% of the atlas (a band at the bottom) is empty.
fn zero_region(_x: u32, y: u32, res: u32) -> bool {
    y >= res - res / 10
}

/// Sum of a few smooth radial falloffs with colour tints.
fn smooth_pane(rng: &mut Rng, res: u32) -> Vec<[f32; 3]> {
    let lights: Vec<([f32; 2], f32, [f32; 3])> = (0..4)
        .map(|_| {
            (
                [rng.unit() * res as f32, rng.unit() * res as f32],
                (0.05 + 0.3 * rng.unit()) * res as f32,
                [0.2 + rng.unit(), 0.2 + rng.unit(), 0.2 + rng.unit()],
            )
        })
        .collect();
    pane_image(res, |x, y| {
        let mut v = [0.0f32; 3];
        for (c, r, tint) in &lights {
            let d2 = (x as f32 - c[0]).powi(2) + (y as f32 - c[1]).powi(2);
            let f = 2.0 / (1.0 + d2 / (r * r));
            for k in 0..3 {
                v[k] += f * tint[k];
            }
        }
        v
    })
}

/// The pure-Python XXH3 of `read_prm.py` against the Rust crate, for every
/// length class (0, 1–3, 4–8, 9–16, 17–128, 129–240, long, multi-block).
#[test]
fn python_xxh3_matches_rust() {
    let formats = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../formats");
    let lengths: Vec<usize> = (0..=260).chain([511, 1023, 1024, 1025, 2047, 4096 + 13]).collect();
    let code = format!(
        "import sys, json; sys.path.insert(0, {dir:?}); import read_prm\n\
         data = bytes(((i * 131) ^ (i >> 3)) & 0xff for i in range(5000))\n\
         print(json.dumps([read_prm.xxh3_64_pure(data[:n]) for n in {lengths:?}]))",
        dir = formats.to_string_lossy(),
    );
    let out = match Command::new("python3").arg("-c").arg(&code).output() {
        Ok(o) if o.status.success() => o,
        Ok(o) => panic!("python failed: {}", String::from_utf8_lossy(&o.stderr)),
        Err(e) => {
            // A skip is a failure in CI, which has python3 (`.ci/run`).
            assert!(std::env::var_os("CI").is_none(), "cannot run python3 in CI: {e}");
            println!("SKIPPED python_xxh3_matches_rust: cannot run python3 ({e})");
            return;
        }
    };
    let got: Vec<u64> = serde_json::from_slice(&out.stdout).unwrap();
    let data: Vec<u8> = (0..5000usize).map(|i| (((i * 131) ^ (i >> 3)) & 0xff) as u8).collect();
    for (n, h) in lengths.iter().zip(got) {
        assert_eq!(h, checksum(&data[..*n]), "length {n}");
    }
    assert_eq!(checksum(b""), 0x2d06_8005_38d3_94c2, "value quoted in the spec");
}

// ---------------------------------------------------------------- declared sizes vs counts

/// Replaces the stored bytes of the `kind` section: the new bytes go just
/// before a copy of the section table (the old bytes stay as an unreferenced
/// gap, which readers ignore), and every checksum is recomputed.
fn replace_section(bytes: &[u8], kind: u32, data: &[u8], compression: u32, raw_size: u64) -> Vec<u8> {
    let table_off = u64_at(bytes, 16).unwrap() as usize;
    let n = u32_at(bytes, 12).unwrap() as usize;
    let mut out = bytes[..table_off].to_vec();
    let data_off = out.len();
    out.extend_from_slice(data);
    let new_table = out.len();
    out.extend_from_slice(&bytes[table_off..table_off + n * 48]);
    let i = sections(bytes).iter().position(|s| s.kind == kind).unwrap();
    let r = new_table + i * 48;
    out[r + 4..r + 8].copy_from_slice(&compression.to_le_bytes());
    put_u64(&mut out, r + 8, data_off as u64);
    put_u64(&mut out, r + 16, data.len() as u64);
    put_u64(&mut out, r + 24, raw_size);
    let len = out.len() as u64;
    put_u64(&mut out, 16, new_table as u64);
    put_u64(&mut out, 24, len);
    resign(&mut out);
    out
}

/// The `kind` section of `bytes` replaced by a zstd stream of 64 MiB that begins with `head`
/// (zeros after it): the reader refuses it, naming `what`, before it decompresses the rest.
fn assert_hostile_header_refused(bytes: &[u8], kind: u32, head: &[u8], what: &str) {
    let raw = 64u64 << 20;
    let mut data = head.to_vec();
    data.resize(raw as usize, 0);
    let stream = zstd::bulk::compress(&data, 3).unwrap();
    let m = replace_section(bytes, kind, &stream, compression::ZSTD, raw);
    assert_refused_in_bounded_memory(&m, what);
}

/// Little-endian words, as section headers store their counts.
fn le_words(words: &[u32]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}

/// A zstd stream of `n` zero bytes, compressed in 1 MiB steps.
/// Reading `archive` fails as inconsistent, naming `what`, with under 8 MiB kept live.
fn assert_refused_in_bounded_memory(archive: &[u8], what: &str) {
    let (result, peak) = peak_allocation(|| Archive::from_bytes(archive).map(|_| ()));
    let err = result.unwrap_err();
    assert!(matches!(err, Error::Inconsistent { .. }), "{err}");
    assert!(err.to_string().contains(what), "{err}");
    assert!(peak < 8 << 20, "the reader kept {peak} bytes live");
}

fn zstd_zeros(n: u64) -> Vec<u8> {
    use std::io::Write;
    let mut enc = zstd::stream::write::Encoder::new(Vec::new(), 19).unwrap();
    let chunk = vec![0u8; 1 << 20];
    let mut left = n;
    while left > 0 {
        let k = left.min(chunk.len() as u64) as usize;
        enc.write_all(&chunk[..k]).unwrap();
        left -= k as u64;
    }
    enc.finish().unwrap()
}

/// A ~15 KB entries section declaring the maximum 448 MiB raw (2^24 entries)
/// must not cost ~900 MB RSS: the raw size must equal 28 × the entries the
/// cluster ranges cover, checked before decompression.
#[test]
fn decompression_bomb_in_entries_is_refused_without_allocating() {
    let (bytes, _) = small_archive("bomb-entries", WriterOptions::default());
    let raw = limits::MAX_ENTRIES * 28;
    let bomb = zstd_zeros(raw);
    assert!(bomb.len() < 64 << 10, "bomb is {} bytes", bomb.len());
    let m = replace_section(&bytes, kind::ENTRIES, &bomb, compression::ZSTD, raw);
    assert_refused_in_bounded_memory(&m, "entries");
}

/// The same rule for the clusters (56 × the panes header's pane count) and
/// the atlas (its own 16-byte header: resolution and triangle count).
#[test]
fn declared_raw_sizes_must_match_the_counts() {
    let (bytes, _) = small_archive("bomb-others", WriterOptions::default());
    // clusters: 2^20 records declared, 3 panes
    let raw = limits::MAX_CLUSTERS * 56;
    let m = replace_section(&bytes, kind::CLUSTERS, &zstd_zeros(raw), compression::ZSTD, raw);
    assert_refused_in_bounded_memory(&m, "3 panes");

    // atlas: a valid 16×16 header followed by 400 MiB of zeros
    let data = le_words(&[16, 8, 0, 0]);
    let raw = 400u64 << 20;
    let stream = {
        use std::io::Write;
        let mut enc = zstd::stream::write::Encoder::new(Vec::new(), 19).unwrap();
        enc.write_all(&data).unwrap();
        let chunk = vec![0u8; 1 << 20];
        for _ in 0..400 {
            enc.write_all(&chunk).unwrap();
        }
        enc.finish().unwrap()
    };
    let m = replace_section(&bytes, kind::ATLAS, &stream, compression::ZSTD, raw + 16);
    assert_refused_in_bounded_memory(&m, "atlas");

    // entries: the right declared size but a stream that ends early is a
    // decompression failure, found without allocating the declared size
    let (bytes, s) = small_archive("bomb-short", WriterOptions::default());
    let raw = s.entries.len() as u64 * 28;
    assert!(raw >= 28);
    let short = zstd::bulk::compress(&vec![0u8; raw as usize - 1], 3).unwrap();
    let m = replace_section(&bytes, kind::ENTRIES, &short, compression::ZSTD, raw);
    let err = Archive::from_bytes(&m).err().unwrap();
    assert!(matches!(err, Error::Decompress { .. }), "{err}");
    // ... and one that holds more than declared, too
    let long = zstd::bulk::compress(&vec![0u8; raw as usize + 1], 3).unwrap();
    let m = replace_section(&bytes, kind::ENTRIES, &long, compression::ZSTD, raw);
    let err = Archive::from_bytes(&m).err().unwrap();
    assert!(matches!(err, Error::Decompress { .. }), "{err}");
}

// ---------------------------------------------------------------- destinations

/// A fresh [`test_dir`] `name` and the small scene of `seed` (16² atlas, tiles of 8, two
/// clusters) that the tests of destinations and temporary files write there.
fn destination_case(name: &str, seed: u64) -> (PathBuf, Scene) {
    (test_dir(name), scene(16, 8, 2, seed))
}

#[cfg(unix)]
#[test]
fn symlink_destination_is_written_through() {
    let (dir, s) = destination_case("symlink", 21);
    let target = dir.join("target.prm");
    std::fs::write(&target, b"").unwrap();
    let link = dir.join("link.prm");
    std::os::unix::fs::symlink("target.prm", &link).unwrap();
    assert_eq!(resolve_destination(&link).unwrap(), dir.join("target.prm"));
    write_scene(&link, &s, WriterOptions::default());
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read_link(&link).unwrap(), Path::new("target.prm"));
    Archive::open(&target).unwrap().verify().unwrap();
    assert_eq!(dir_listing(&dir), vec!["link.prm", "target.prm"]);

    // a chain of links into another directory, the last one dangling: the
    // target is created, the temporary file lives beside it, the links stay
    let sub = dir.join("sub");
    std::fs::create_dir(&sub).unwrap();
    std::os::unix::fs::symlink("sub/hop.prm", dir.join("chain.prm")).unwrap();
    std::os::unix::fs::symlink("fresh.prm", sub.join("hop.prm")).unwrap();
    let w = start_writer(&dir.join("chain.prm"), &s).unwrap();
    assert_eq!(w.destination(), sub.join("fresh.prm"));
    assert_eq!(w.temp_path().parent().unwrap(), sub);
    drop(w);
    write_scene(&dir.join("chain.prm"), &s, WriterOptions::default());
    assert!(std::fs::symlink_metadata(sub.join("fresh.prm")).unwrap().is_file());
    assert_eq!(dir_listing(&sub), vec!["fresh.prm", "hop.prm"]);
    assert_eq!(dir_listing(&dir), vec!["chain.prm", "link.prm", "sub", "target.prm"]);
}

#[test]
fn directory_destination_is_refused_before_writing() {
    let (dir, s) = destination_case("dest-dir", 22);
    let out = dir.join("out.prm");
    std::fs::create_dir(&out).unwrap();
    let err = resolve_destination(&out).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, Error::Destination { .. }), "{msg}");
    assert!(msg.contains("out.prm") && msg.contains("a directory"), "{msg}");
    let err = start_writer(&out, &s).err().unwrap();
    assert!(matches!(err, Error::Destination { .. }), "{err}");
    assert_eq!(dir_listing(&dir), vec!["out.prm"], "nothing was created");
}

/// A mistyped `-o` naming the scene, a report or any other file is refused and the file kept;
/// an empty file and an archive, even a damaged one, may be replaced.
#[test]
fn a_file_that_is_not_an_archive_is_not_replaced() {
    let (dir, s) = destination_case("dest-foreign", 24);
    let scene_file = dir.join("room.obj");
    std::fs::write(&scene_file, b"v 0 0 0\n").unwrap();
    let err = resolve_destination(&scene_file).unwrap_err();
    assert!(matches!(err, Error::Destination { .. }), "{err}");
    assert!(
        err.to_string().contains("room.obj") && err.to_string().contains("not a .prm archive"),
        "{err}"
    );
    assert!(matches!(start_writer(&scene_file, &s), Err(Error::Destination { .. })));
    assert_eq!(std::fs::read(&scene_file).unwrap(), b"v 0 0 0\n");

    let empty = dir.join("empty.prm");
    std::fs::write(&empty, b"").unwrap();
    assert_eq!(resolve_destination(&empty).unwrap(), empty);
    let damaged = dir.join("damaged.prm");
    write_scene(&damaged, &s, WriterOptions::default());
    let len = std::fs::metadata(&damaged).unwrap().len();
    std::fs::OpenOptions::new()
        .write(true)
        .open(&damaged)
        .unwrap()
        .set_len(len / 2)
        .unwrap();
    assert_eq!(resolve_destination(&damaged).unwrap(), damaged);
    // Cut inside the magic bytes: still the beginning of an archive.
    std::fs::OpenOptions::new()
        .write(true)
        .open(&damaged)
        .unwrap()
        .set_len(3)
        .unwrap();
    assert_eq!(resolve_destination(&damaged).unwrap(), damaged);
    write_scene(&damaged, &s, WriterOptions::default());
    Archive::open(&damaged).unwrap().verify().unwrap();
}

/// A scratch archive beside a destination, and the writer's temporary file for it, are this
/// process's temporary files of that destination.
#[test]
fn scratch_archives_count_as_temporary_files_of_their_destination() {
    let (dir, s) = destination_case("dest-scratch", 25);
    let out = dir.join("out.prm");
    let scratch = prm_format::scratch_path(&out);
    assert_eq!(scratch.parent().unwrap(), dir);
    let w = start_writer(&scratch, &s).unwrap();
    let inner = w.temp_path().to_path_buf();
    assert_eq!(prm_format::own_temp_files(&out), vec![inner.clone()]);
    drop(w);
    write_scene(&scratch, &s, WriterOptions::default());
    assert_eq!(prm_format::own_temp_files(&out), vec![scratch.clone()]);
    assert!(prm_format::own_temp_files(dir.join("other.prm")).is_empty());
    std::fs::remove_file(&scratch).unwrap();
    assert!(dir_listing(&dir).is_empty());
}

#[cfg(unix)]
#[test]
fn device_and_fifo_destinations_are_refused() {
    let s = scene(16, 8, 2, 23);
    let null = Path::new("/dev/null");
    if null.exists() {
        let err = resolve_destination(null).unwrap_err();
        assert!(err.to_string().contains("a character device"), "{err}");
        assert!(err.to_string().contains("/dev/null"), "{err}");
        assert!(matches!(start_writer(null, &s), Err(Error::Destination { .. })));
        assert!(!std::fs::metadata(null).unwrap().file_type().is_file());
    }
    let dir = test_dir("dest-fifo");
    let fifo = dir.join("pipe.prm");
    let made = Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success());
    if made {
        let err = resolve_destination(&fifo).unwrap_err();
        assert!(err.to_string().contains("FIFO"), "{err}");
        assert!(matches!(start_writer(&fifo, &s), Err(Error::Destination { .. })));
        // through a symlink too, naming the link
        std::os::unix::fs::symlink("pipe.prm", dir.join("link.prm")).unwrap();
        let err = resolve_destination(dir.join("link.prm")).unwrap_err();
        assert!(err.to_string().contains("link.prm"), "{err}");
        assert_eq!(dir_listing(&dir), vec!["link.prm", "pipe.prm"]);
    }
    assert!(null.exists() || made, "neither /dev/null nor mkfifo is available");
}

// ---------------------------------------------------------------- temporary files

/// SIGKILL leaves `.NAME.tmp-<pid>-<n>`; the next writer to the same
/// destination removes those of dead processes and nothing else.
#[cfg(target_os = "linux")]
#[test]
fn stale_temp_files_of_dead_processes_are_swept() {
    let (dir, s) = destination_case("stale", 24);
    let me = std::process::id();
    // Above PID_MAX_LIMIT (2^22): no process can have this pid.
    let dead = 4_194_304 + 17;
    let stale = [format!(".scene.prm.tmp-{dead}-0"), format!(".scene.prm.tmp-{dead}-12")];
    let keep = [
        format!(".scene.prm.tmp-{me}-999"), // ours: alive
        ".scene.prm.tmp-1-0".to_string(),   // pid 1 is alive
        format!(".other.prm.tmp-{dead}-0"), // another destination
        format!(".scene.prm.tmp-{dead}-x"), // not the pattern
        format!(".scene.prm.tmp-{dead}"),   // not the pattern
        format!("scene.prm.tmp-{dead}-0"),  // not hidden: not ours
    ];
    for f in stale.iter().chain(&keep) {
        std::fs::write(dir.join(f), b"partial").unwrap();
    }
    let w = start_writer(&dir.join("scene.prm"), &s).unwrap();
    let listing = dir_listing(&dir);
    for f in &stale {
        assert!(!listing.contains(f), "{f} survived: {listing:?}");
    }
    for f in &keep {
        assert!(listing.contains(f), "{f} was removed: {listing:?}");
    }
    // What a signal handler would remove: this process's files only.
    let own = own_temp_files(dir.join("scene.prm"));
    assert_eq!(own.len(), 2, "{own:?}");
    assert!(own.contains(&w.temp_path().to_path_buf()));
    assert!(own.contains(&dir.join(format!(".scene.prm.tmp-{me}-999"))));
    drop(w);
    assert_eq!(own_temp_files(dir.join("scene.prm")).len(), 1);
}

// ---------------------------------------------------------------- error messages

fn occurrences(haystack: &str, needle: &str) -> usize {
    haystack.matches(needle).count()
}

/// The OS text appears once in an anyhow chain, and the error kinds stay apart.
#[test]
fn os_error_text_appears_once_in_anyhow_chain() {
    let dir = test_dir("messages");
    let missing = dir.join("missing.prm");
    let err = Archive::open(&missing).err().unwrap();
    assert!(matches!(err, Error::Io(_)), "{err:?}");
    let chain = format!("{:#}", anyhow::Error::from(err).context("cannot open archive"));
    assert_eq!(occurrences(&chain, "os error"), 1, "{chain}");
    assert!(chain.starts_with("cannot open archive: I/O error: "), "{chain}");

    // a writer whose directory is missing: path, reason, then the OS text once
    let s = scene(16, 8, 2, 25);
    let err = start_writer(&dir.join("no/such/dir/out.prm"), &s).err().unwrap();
    assert!(matches!(err, Error::Destination { .. }), "{err:?}");
    let chain = format!("{:#}", anyhow::Error::from(err));
    assert_eq!(occurrences(&chain, "os error"), 1, "{chain}");
    assert!(chain.contains("out.prm") && chain.contains("temporary file"), "{chain}");

    // corrupt data and versions carry no OS text, and are told apart
    let (bytes, _) = small_archive("messages-small", WriterOptions::default());
    let mut bad = bytes.clone();
    let last = bad.len() - 1;
    bad[last] ^= 1;
    let err = Archive::from_bytes(&bad).err().unwrap();
    assert!(matches!(err, Error::ChecksumMismatch { .. }), "{err}");
    let mut newer = bytes.clone();
    put_u16(&mut newer, 8, 3);
    assert!(matches!(
        Archive::from_bytes(&newer),
        Err(Error::UnsupportedVersion { .. })
    ));
}

// ---------------------------------------------------------------- bounded fuzzing

/// Offsets of the integer fields worth overwriting with hostile values: the
/// header's counts and offsets, every section record's offset and sizes, and
/// (in uncompressed sections) the panes header and first ranks, the atlas
/// header and the first cluster's range.
fn count_fields(b: &[u8]) -> Vec<(usize, usize)> {
    let mut f = vec![(12, 4), (16, 8), (24, 8)];
    let table = u64_at(b, 16).unwrap() as usize;
    for (i, s) in sections(b).iter().enumerate() {
        let r = table + i * 48;
        f.extend([(r, 4), (r + 4, 4), (r + 8, 8), (r + 16, 8), (r + 24, 8)]);
        match s.kind {
            kind::PANES => f.extend((0..8).map(|k| (s.offset + 4 * k, 4))),
            kind::ATLAS => f.extend([(s.offset, 4), (s.offset + 4, 4), (s.offset + 8, 4)]),
            kind::CLUSTERS => f.extend([(s.offset, 4), (s.offset + 4, 4), (s.offset + 60, 4)]),
            kind::ENTRIES => f.push((s.offset + 24, 4)),
            _ => {}
        }
    }
    f
}

/// Deterministic, bounded mutation fuzzing of the reader *and* of full
/// verification (what `prm-bake dump --verify` runs): byte flips,
/// truncations and hostile values in length/count fields, half of them
/// re-signed so they pass the checksums. Every case must return (Ok or Err),
/// never panic; a panic is reported with the seed that reproduces it.
#[test]
fn bounded_fuzz_reader_and_verify_never_panic() {
    let started = std::time::Instant::now();
    let bases = [
        small_archive("bfuzz-zstd", WriterOptions::default()).0,
        small_archive("bfuzz-raw", UNCOMPRESSED).0,
    ];
    let fields: Vec<_> = bases.iter().map(|b| count_fields(b)).collect();
    let mut outcomes = std::collections::BTreeMap::<String, usize>::new();
    const CASES: u64 = 5000;
    for case in 0..CASES {
        let seed = 0x5EED_0000 + case;
        let mut rng = Rng(seed);
        let which = (case % 2) as usize;
        let mut m = bases[which].clone();
        let mut what = Vec::new();
        for _ in 0..1 + rng.below(3) {
            match rng.below(4) {
                0 if !m.is_empty() => {
                    let bit = rng.below(m.len() as u64 * 8) as usize;
                    m[bit / 8] ^= 1 << (bit % 8);
                    what.push(format!("flip bit {bit}"));
                }
                0 | 1 => {
                    let len = rng.below(m.len() as u64) as usize;
                    m.truncate(len);
                    what.push(format!("truncate to {len}"));
                }
                _ => {
                    let (at, width) = fields[which][rng.below(fields[which].len() as u64) as usize];
                    let v: u64 = match rng.below(5) {
                        0 => u64::MAX,
                        1 => 1 << rng.below(64),
                        2 => (1 << rng.below(64)) - 1,
                        3 => rng.below(1 << 16),
                        _ => rng.next(),
                    };
                    if let Some(slot) = m.get_mut(at..at + width) {
                        slot.copy_from_slice(&v.to_le_bytes()[..width]);
                    }
                    what.push(format!("set {width} bytes at {at} to {v:#x}"));
                }
            }
        }
        if rng.below(2) == 0 {
            resign(&mut m);
            what.push("re-signed".into());
        }
        let result = std::panic::catch_unwind(|| {
            let read = read_all(&m).map(|_| ());
            let verified = verify_bytes(&m).map(|_| ());
            (read, verified)
        });
        match result {
            Ok((read, verified)) => {
                let k = match (&read, &verified) {
                    (Ok(()), Ok(())) => "ok".to_string(),
                    (_, Err(e)) | (Err(e), _) => format!("{e:?}").split([' ', '{', '(']).next().unwrap().to_string(),
                };
                *outcomes.entry(k).or_default() += 1;
            }
            Err(_) => panic!("fuzz case seed {seed:#x} ({}) panicked", what.join(", ")),
        }
    }
    println!("bounded fuzz, {CASES} cases in {:?}: {outcomes:?}", started.elapsed());
    assert!(
        outcomes.len() >= 4,
        "mutations should reach several checks: {outcomes:?}"
    );
    assert!(outcomes.contains_key("Inconsistent"), "{outcomes:?}");
}

/// Child side of [`sigkill_leftover_is_removed_by_the_next_writer`]: starts a
/// writer in `$PRM_KILL_CHILD_DIR`, says so, and waits to be killed.
#[test]
#[ignore = "helper process of sigkill_leftover_is_removed_by_the_next_writer"]
fn sigkill_child_helper() {
    let Some(dir) = std::env::var_os("PRM_KILL_CHILD_DIR").map(PathBuf::from) else {
        return;
    };
    let s = scene(16, 8, 2, 26);
    let mut w = start_writer(&dir.join("scene.prm"), &s).unwrap();
    w.add_pane(&s.panes[0]).unwrap();
    // Written aside and renamed, so the parent never reads half of it.
    std::fs::write(dir.join("ready.part"), w.temp_path().as_os_str().as_encoded_bytes()).unwrap();
    std::fs::rename(dir.join("ready.part"), dir.join("ready")).unwrap();
    std::thread::sleep(std::time::Duration::from_secs(60));
}

/// End to end: a writer's process killed with SIGKILL leaves its temporary
/// file; the next writer to the same destination removes it.
#[cfg(target_os = "linux")]
#[test]
fn sigkill_leftover_is_removed_by_the_next_writer() {
    let dir = test_dir("sigkill");
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "sigkill_child_helper", "--ignored", "--nocapture"])
        .env("PRM_KILL_CHILD_DIR", &dir)
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let ready = dir.join("ready");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while !ready.exists() {
        assert!(
            std::time::Instant::now() < deadline,
            "the child never started its writer"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let temp = PathBuf::from(std::fs::read_to_string(&ready).unwrap());
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    assert!(temp.exists(), "SIGKILL cannot be caught: {} stays", temp.display());
    let s = scene(16, 8, 2, 27);
    let w = start_writer(&dir.join("scene.prm"), &s).unwrap();
    assert!(!temp.exists(), "{} was not swept", temp.display());
    drop(w);
    write_scene(&dir.join("scene.prm"), &s, WriterOptions::default());
    assert_eq!(dir_listing(&dir), vec!["ready", "scene.prm"]);
}

// ---------------------------------------------------------------- entry energy

/// The entry energy section round-trips, and a damaged one is refused: wrong record count, a negative or NaN energy, or the section twice.
#[test]
fn entry_energy_round_trips_and_is_validated() {
    let dir = test_dir("entry-energy");
    let s = scene(16, 8, 3, 7);
    let n = s.entries.len();
    let energy: Vec<[f32; 3]> = (0..n).map(|i| [i as f32, 0.5, 2.0 * i as f32]).collect();
    let write = |path: &Path, energy: Option<Vec<[f32; 3]>>| {
        // Sections stored as they are, so the test can damage a value in place.
        let stored = WriterOptions {
            compress_sections: false,
            ..WriterOptions::default()
        };
        let mut w = start_writer_with(path, &s, stored).unwrap();
        if let Some(e) = energy {
            w.set_entry_energy(e).unwrap();
        }
        add_panes_and_finish(w, &s);
        std::fs::read(path).unwrap()
    };
    let with = write(&dir.join("with.prm"), Some(energy.clone()));
    let a = Archive::from_bytes(&with).unwrap();
    assert_eq!(a.entry_energy(), Some(&energy[..]));
    assert!(a.info().sections.iter().any(|x| x.name == "entry_energy"));
    let without = write(&dir.join("without.prm"), None);
    let b = Archive::from_bytes(&without).unwrap();
    assert_eq!(b.entry_energy(), None);
    assert_eq!((a.info().minor, b.info().minor), (0, 0));

    // The writer refuses a count that is not the entries' and non-finite or negative values.
    let mut w = start_writer(&dir.join("bad.prm"), &s).unwrap();
    assert!(w.set_entry_energy(vec![[1.0; 3]; n + 1]).is_err());
    let mut nan = energy.clone();
    nan[0][1] = f32::NAN;
    assert!(w.set_entry_energy(nan).is_err());
    let mut negative = energy.clone();
    negative[0][2] = -1.0;
    assert!(w.set_entry_energy(negative).is_err());
    drop(w);

    // A reader refuses a section whose size or values are wrong.
    let a = Archive::from_bytes(&with).unwrap();
    let rec = a
        .info()
        .sections
        .iter()
        .find(|x| x.name == "entry_energy")
        .unwrap()
        .clone();
    assert_eq!(rec.compression, compression::NONE);
    let at = rec.offset as usize;
    let mut damaged = with.clone();
    damaged[at..at + 4].copy_from_slice(&(-1.0f32).to_le_bytes());
    resign(&mut damaged);
    assert!(matches!(Archive::from_bytes(&damaged), Err(Error::Inconsistent { .. })));
}

/// The entry cells round-trip at their stored precision and make the archive 2.1; the Python
/// reader reads them the same; a reader refuses ends out of order and another entry count.
#[test]
fn entry_cells_round_trip_as_format_2_1() {
    let dir = test_dir("entry-cells");
    let s = scene(16, 8, 3, 7);
    let n = s.entries.len();
    let mut cells = EntryCells::default();
    for i in 0..n {
        for j in 0..i % 4 + 1 {
            let offset = [0.25 * j as f32, -0.5, i as f32 * 0.125];
            cells.points.push(CellPoint::new(offset, [0.0, 0.6, 0.8]).unwrap());
        }
        cells.ends.push(cells.points.len() as u32);
    }
    let stored = WriterOptions {
        compress_sections: false,
        ..WriterOptions::default()
    };
    let path = dir.join("cells.prm");
    let mut w = start_writer_with(&path, &s, stored).unwrap();
    assert!(w
        .set_entry_cells(EntryCells {
            ends: cells.ends[1..].to_vec(),
            points: cells.points.clone()
        })
        .is_err());
    w.set_entry_cells(cells.clone()).unwrap();
    add_panes_and_finish(w, &s);
    let bytes = std::fs::read(&path).unwrap();
    let a = Archive::from_bytes(&bytes).unwrap();
    assert_eq!(a.entry_cells(), Some(&cells));
    assert_eq!((a.info().major, a.info().minor), (2, 1));
    let last = a.entry_cells().unwrap().points_of(n - 1);
    assert_eq!(last.len(), (n - 1) % 4 + 1);
    assert_eq!(last[0].offset(), [0.0, -0.5, (n - 1) as f32 * 0.125]);

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../formats/read_prm.py");
    let out = Command::new("python3").arg(&script).arg(&path).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["version"], "2.1");
    let ends: Vec<u64> = cells.ends.iter().map(|&e| u64::from(e)).collect();
    assert_eq!(j["entry_cells"]["ends"], serde_json::json!(ends));
    let p = cells.points.len() - 1;
    assert_eq!(
        j["entry_cells"]["points"][p]["offset"],
        serde_json::json!(cells.points[p].offset())
    );

    // Damaged: the first end past the second, then a header for another entry count.
    let rec = a
        .info()
        .sections
        .iter()
        .find(|x| x.name == "entry_cells")
        .unwrap()
        .clone();
    let at = rec.offset as usize;
    let mut damaged = bytes.clone();
    damaged[at + 16..at + 20].copy_from_slice(&1000u32.to_le_bytes());
    resign(&mut damaged);
    assert!(matches!(Archive::from_bytes(&damaged), Err(Error::Inconsistent { .. })));
    let mut damaged = bytes.clone();
    damaged[at..at + 4].copy_from_slice(&(n as u32 + 1).to_le_bytes());
    resign(&mut damaged);
    assert!(Archive::from_bytes(&damaged).is_err());
}

// ---------------------------------------------------------------- emitters

fn emitter_groups(s: &Scene, count: usize) -> Vec<EmitterGroup> {
    let texels = (s.atlas.resolution * s.atlas.resolution) as usize;
    (0..count)
        .map(|g| EmitterGroup {
            name: format!("lamp {g}"),
            material: g as u32 + 1,
            radiance: [17.0, 12.0 + g as f32, 4.0],
            entry_irradiance: (0..s.entries.len()).map(|i| [i as f32, 0.5, g as f32]).collect(),
            direct: (0..texels).map(|i| [(i % 7) as f32 * 0.25, 1.0, 0.0]).collect(),
            indirect: (g == 0).then(|| (0..texels).map(|i| [0.5, (i % 5) as f32, 0.0]).collect()),
        })
        .collect()
}

/// The emitters section round-trips (its values are exact in RGB9E5 here), and the reader refuses a header for other counts and a group count over the limit
/// before it decompresses the rest.
#[test]
fn emitters_round_trip_and_hostile_headers_are_refused() {
    let s = scene(16, 8, 3, 11);
    let groups = emitter_groups(&s, 2);
    let bytes = written_with("emitters", &s, |w| {
        // The writer refuses groups that do not fit the archive.
        let mut wrong = groups.clone();
        wrong[1].entry_irradiance.pop();
        assert!(w.set_emitters(wrong).is_err());
        assert!(w.set_emitters(Vec::new()).is_err());
        w.set_emitters(groups.clone()).unwrap();
    });
    let a = Archive::from_bytes(&bytes).unwrap();
    assert_eq!(a.emitters(), &groups[..]);
    assert!(a.info().sections.iter().any(|x| x.name == "emitters"));
    let (plain, _) = small_archive("emitters-none", WriterOptions::default());
    assert!(Archive::from_bytes(&plain).unwrap().emitters().is_empty());

    // A header naming other entry counts, or too many groups, with a stream of zeros behind it.
    let header = |groups: u32, entries: u32, res: u32| le_words(&[groups, entries, res, 0]);
    let n = s.entries.len() as u32;
    for (head, what) in [
        (header(2, n + 1, 16), "entries"),
        (header(2, n, 32), "resolution"),
        (header(limits::MAX_EMITTER_GROUPS + 1, n, 16), "emitter groups"),
    ] {
        assert_hostile_header_refused(&bytes, kind::EMITTERS, &head, what);
    }
    // The right header, a declared size the counts do not give.
    assert_hostile_header_refused(&bytes, kind::EMITTERS, &header(2, n, 16), "2 groups");
}

// ---------------------------------------------------------------- sky

fn sky_transfer(s: &Scene) -> SkyTransfer {
    let texels = (s.atlas.resolution * s.atlas.resolution) as usize;
    SkyTransfer {
        direct: (0..texels)
            .map(|t| std::array::from_fn(|c| (t % 5) as f32 - 0.25 * c as f32))
            .collect(),
        indirect: (0..texels)
            .map(|t| std::array::from_fn(|c| [0.5 * c as f32, -((t % 3) as f32), 0.375]))
            .collect(),
    }
}

/// The sky section round-trips exactly (its values are exact in f16 here), and the reader refuses
/// a header for another resolution or basis, and a declared size the resolution does not give, before it
/// decompresses the rest.
#[test]
fn sky_round_trip_and_hostile_headers_are_refused() {
    let s = scene(16, 8, 3, 12);
    let sky = sky_transfer(&s);
    let spoil = |wrong: &mut SkyTransfer| {
        wrong.direct.pop();
    };
    let bytes = optional_section_round_trip("sky", &s, &sky, spoil, ArchiveWriter::set_sky, |a| a.sky());

    let header = |res: u32, coeffs: u32| le_words(&[res, coeffs, 0, 0]);
    for (head, what) in [(header(32, 9), "resolution"), (header(16, 16), "coefficients")] {
        assert_hostile_header_refused(&bytes, kind::SKY, &head, what);
    }
    assert_hostile_header_refused(&bytes, kind::SKY, &header(16, 9), "resolution 16");
}

// ---------------------------------------------------------------- probes

fn probe_set(s: &Scene) -> Probes {
    let grid = ProbeGrid {
        dims: [3, 2, 2],
        origin: [-1.0, 0.0, 0.0],
        spacing: 0.5,
    };
    let cells = vec![0, 1, 4, 7, 11];
    let positions = cells.iter().map(|&c| grid.cell_centre(c)).collect();
    let transfer = (0..s.clusters.len() * cells.len())
        .map(|i| std::array::from_fn(|c| [(i % 7) as f32 * 0.5, -0.25 * c as f32, 2.0]))
        .collect();
    let sky = (0..5)
        .map(|p| std::array::from_fn(|i| std::array::from_fn(|k| [p as f32 * 0.25, i as f32, -0.5 * k as f32])))
        .collect();
    Probes {
        grid,
        cells,
        positions,
        transfer,
        sky: Some(sky),
    }
}

fn probe_ray_set(s: &Scene) -> ProbeRays {
    let r = s.atlas.resolution;
    let points = (0..3)
        .map(|i| GatherPoint {
            texel: (i * 7) % (r * r),
            position: [i as f32, 0.5, -0.25],
            normal: [0.0, 0.0, 1.0],
            albedo: [0.5, 0.75, 0.25 * i as f32],
            emission: [i as f32, 0.0, 0.5],
            // The test scene's two emitter groups, and none.
            emitter: if i < 2 { i } else { NO_EMITTER },
        })
        .collect();
    let hits = (0..5 * 4u32)
        .map(|i| match i % 5 {
            3 => prm_format::RAY_SKY,
            4 => prm_format::RAY_BLOCKED,
            k => k,
        })
        .collect();
    ProbeRays {
        rays_per_probe: 4,
        points,
        hits,
    }
}

fn near_set(s: &Scene) -> NearField {
    let points = probe_ray_set(s).points;
    let mut near = NearField {
        rays_per_exit: 8,
        disk: 0.03125,
        indirect_disk: 0.015625,
        complement: true,
        points,
        exits: vec![NearExit { texel: 1, end: 2 }, NearExit { texel: 4, end: 3 }],
        hits: vec![
            NearHit {
                point: 2,
                distance2: 0.0,
            },
            NearHit {
                point: 0,
                distance2: 0.125,
            },
            NearHit {
                point: 1,
                distance2: 0.5,
            },
        ],
    };
    near.round_to_stored();
    near
}

/// The probe rays section needs the probes and round-trips exactly; the reader refuses a section for another probe count, and one beside no probes section.
#[test]
fn probe_rays_round_trip_and_need_the_probes() {
    let dir = test_dir("probe-rays");
    let s = scene(16, 8, 4, 29);
    let rays = probe_ray_set(&s);
    let path = dir.join("rays.prm");
    let mut w = start_writer(&path, &s).unwrap();
    assert!(w.set_probe_rays(rays.clone()).is_err(), "rays before the probes");
    w.set_probes(probe_set(&s)).unwrap();
    assert!(
        w.set_probe_rays(rays.clone()).is_err(),
        "gather points of emitter groups the archive does not have"
    );
    w.set_emitters(emitter_groups(&s, 2)).unwrap();
    let mut wrong = rays.clone();
    wrong.hits.pop();
    assert!(w.set_probe_rays(wrong).is_err(), "one ray short");
    w.set_probe_rays(rays.clone()).unwrap();
    let mut fewer = probe_set(&s);
    fewer.cells.pop();
    fewer.positions.pop();
    fewer.transfer.truncate(fewer.cells.len() * s.clusters.len());
    fewer.sky.as_mut().unwrap().pop();
    assert!(
        w.set_probes(fewer).is_err(),
        "other probes than the rays were traced for"
    );
    assert!(
        w.set_emitters(emitter_groups(&s, 1)).is_err(),
        "fewer emitter groups than the rays name"
    );
    add_panes_and_finish(w, &s);
    let mut a = Archive::open(&path).unwrap();
    assert_eq!(a.probe_rays(), Some(&rays));
    a.verify().unwrap();

    // The same section in an archive without probes: a private section renumbered to kind 10.
    let plain = dir.join("no-probes.prm");
    let mut w = start_writer(&plain, &s).unwrap();
    w.add_custom_section(kind::PRIVATE_FIRST + 10, vec![0; 64]).unwrap();
    add_panes_and_finish(w, &s);
    let mut bytes = std::fs::read(&plain).unwrap();
    let table = u64_at(&bytes, 16).unwrap() as usize;
    let i = sections(&bytes)
        .iter()
        .position(|s| s.kind == kind::PRIVATE_FIRST + 10)
        .unwrap();
    bytes[table + 48 * i..table + 48 * i + 4].copy_from_slice(&kind::PROBE_RAYS.to_le_bytes());
    resign(&mut bytes);
    let e = Archive::from_bytes(&bytes).err().unwrap().to_string();
    assert!(e.contains("without a probes section"), "{e}");
}

/// The probes section round-trips exactly (its values are exact in f16 here); the reader refuses a header for another cluster count or basis, and a declared
/// size its counts do not give, before it decompresses the rest.
#[test]
fn probes_round_trip_and_hostile_headers_are_refused() {
    let s = scene(16, 8, 3, 13);
    let probes = probe_set(&s);
    let spoil = |wrong: &mut Probes| {
        wrong.transfer.pop();
    };
    let bytes = optional_section_round_trip("probes", &s, &probes, spoil, ArchiveWriter::set_probes, |a| a.probes());

    let origin_spacing = [-1.0f32, 0.0, 0.0, 0.5].map(f32::to_bits);
    let header = |n: u32, clusters: u32, coeffs: u32| {
        le_words(&[[n, clusters, coeffs, 0, 3, 2, 2, 0].as_slice(), &origin_spacing].concat())
    };
    let c = s.clusters.len() as u32;
    for (head, what) in [
        (header(5, c + 1, 9), "clusters"),
        (header(5, c, 16), "coefficients"),
        (header(5, c, 9), "5 probes"),
        (header(MAX_PROBES, c, 9), "probes"),
    ] {
        assert_hostile_header_refused(&bytes, kind::PROBES, &head, what);
    }
}

/// The near field round-trips exactly, with or without the complemented weights and the deeper
/// VPLs' disk; the writer refuses gather points of emitter groups the archive lacks; headers whose counts the atlas cannot hold are
/// refused before the rest is decompressed.
#[test]
fn near_field_round_trips_and_hostile_headers_are_refused() {
    let s = scene(16, 8, 4, 31);
    let near = near_set(&s);
    let bytes = written_with("near-field", &s, |w| {
        assert!(
            w.set_near_field(near.clone()).is_err(),
            "gather points of emitter groups the archive does not have"
        );
        w.set_emitters(emitter_groups(&s, 2)).unwrap();
        let mut wrong = near.clone();
        wrong.exits[1].end = 2;
        assert!(w.set_near_field(wrong).is_err(), "an exit without hits");
        w.set_near_field(near.clone()).unwrap();
        assert!(
            w.set_emitters(emitter_groups(&s, 1)).is_err(),
            "fewer emitter groups than the near field names"
        );
    });
    let mut a = Archive::from_bytes(&bytes).unwrap();
    assert_eq!(a.near_field(), Some(&near));
    a.verify().unwrap();
    let uncut = NearField {
        complement: false,
        ..near.clone()
    };
    let direct_only = NearField {
        indirect_disk: 0.0,
        ..uncut.clone()
    };
    for (name, n) in [("uncut", &uncut), ("direct-only", &direct_only)] {
        let bytes = written_with(&format!("near-field-{name}"), &s, |w| {
            w.set_emitters(emitter_groups(&s, 2)).unwrap();
            w.set_near_field(n.clone()).unwrap();
        });
        let a = Archive::from_bytes(&bytes).unwrap();
        assert_eq!((a.info().major, a.info().minor), (2, 0));
        assert_eq!(a.near_field(), Some(n));
    }

    let texels = 16u32 * 16;
    let header = |e: u32, m: u32, g: u32, res: u32, h: u32| le_words(&[e, m, g, 0, res, h, 0.03125f32.to_bits(), 0]);
    for (head, what) in [
        (header(2, 8, 3, 32, 3), "32² atlas"),
        (header(texels + 1, 8, 3, 16, 3), "257 exits"),
        (header(2, 8, texels + 1, 16, 3), "257 gather points"),
        (header(2, 8, 3, 16, 17), "17 hits"),
        (
            header(texels, MAX_NEAR_RAYS, texels, 16, texels * MAX_NEAR_RAYS),
            "16777216 hits",
        ),
    ] {
        assert_hostile_header_refused(&bytes, kind::NEAR_FIELD, &head, what);
    }
}

// ---------------------------------------------------------------- panes

/// The archive of `panes` (one cluster of one entry each) on an atlas of `res` texels in tiles of
/// `tile`, written with `options` in a fresh directory `name`; its bytes.
fn panes_archive(name: &str, panes: &[Vec<[f32; 3]>], res: u32, tile: u32, options: WriterOptions) -> Vec<u8> {
    let entries: Vec<Entry> = (0..panes.len())
        .map(|c| Entry {
            position: [c as f32, 0.0, 0.0],
            normal: [0.0, 1.0, 0.0],
            cluster: c as u32,
        })
        .collect();
    let clusters: Vec<Cluster> = (0..panes.len())
        .map(|c| Cluster::new(c as u32, 1, [c as f32, 0.0, 0.0], [0.0, 1.0, 0.0]))
        .collect();
    let path = test_dir(name).join("panes.prm");
    let atlas = AtlasSection::new(res, tile);
    let metadata = Metadata::new("prm-format-tests", "0");
    let mut w = ArchiveWriter::create_with_options(&path, metadata, &atlas, &entries, &clusters, options).unwrap();
    for p in panes {
        w.add_pane(p).unwrap();
    }
    w.finish().unwrap();
    std::fs::read(&path).unwrap()
}

/// Relative RMSE of the lit combination `Σ_c w_c·pane_c` of `decoded` against that of `panes`,
/// with positive random weights.
fn lit_error(panes: &[Vec<[f32; 3]>], decoded: &[Vec<[f32; 3]>], rng: &mut Rng) -> f64 {
    let weights: Vec<f64> = panes.iter().map(|_| f64::from(rng.unit()) + 0.01).collect();
    let (mut num, mut den) = (0f64, 0f64);
    for k in 0..panes[0].len() {
        for ch in 0..3 {
            let want: f64 = panes.iter().zip(&weights).map(|(p, w)| w * f64::from(p[k][ch])).sum();
            let got: f64 = decoded.iter().zip(&weights).map(|(p, w)| w * f64::from(p[k][ch])).sum();
            num += (want - got).powi(2);
            den += want * want;
        }
    }
    (num / den).sqrt()
}

/// Random smooth panes come back within the tolerance in every tile, and so do their lit
/// combinations; a tighter tolerance keeps more of every tile and errs less.
#[test]
fn smooth_panes_round_trip_within_the_tolerance() {
    let mut rng = Rng(41);
    let (res, tile) = (32u32, 16u32);
    let panes: Vec<Vec<[f32; 3]>> = (0..24).map(|_| smooth_pane(&mut rng, res)).collect();
    let mut ranks = Vec::new();
    for (name, eps) in [("default", PANE_TOLERANCE), ("tight", 0.002)] {
        let options = WriterOptions {
            pane_tolerance: eps,
            ..WriterOptions::default()
        };
        let bytes = panes_archive(&format!("smooth-{name}"), &panes, res, tile, options);
        let mut a = Archive::from_bytes(&bytes).unwrap();
        let decoded: Vec<Vec<[f32; 3]>> = (0..panes.len()).map(|p| a.read_pane(p).unwrap()).collect();
        let errors = tile_errors(&panes, &decoded, res as usize, tile as usize);
        for (t, &e) in errors.iter().enumerate() {
            assert!(within_tolerance(e, eps), "ε {eps}, tile {t}: {e}");
        }
        let lit = lit_error(&panes, &decoded, &mut rng);
        assert!(lit <= f64::from(eps), "ε {eps}: lit combination off by {lit}");
        println!(
            "ε {eps}: ranks {:?}, tile errors {errors:?}, lit {lit}",
            a.pane_basis().ranks()
        );
        ranks.push(a.pane_basis().ranks().to_vec());
        a.verify().unwrap();
    }
    assert!(ranks[0].iter().zip(&ranks[1]).all(|(a, b)| a <= b), "{ranks:?}");
    assert!(ranks[0].iter().sum::<u32>() < ranks[1].iter().sum::<u32>(), "{ranks:?}");
    assert!(ranks[0].iter().all(|&r| r < 3 * 24), "compressed at all: {ranks:?}");
}

/// Panes that are combinations of two images are of rank 2 in every tile: each tile keeps two
/// basis vectors, and the panes come back up to the `f16` rounding of the basis.
#[test]
fn panes_of_rank_two_reconstruct_almost_exactly() {
    let res = 16u32;
    let n = res as usize;
    let e1: Vec<f32> = (0..n * n).map(|i| 1.0 + 0.8 * (0.9 * (i % n) as f32).sin()).collect();
    let e2: Vec<f32> = (0..n * n).map(|i| 1.0 + 0.8 * (0.7 * (i / n) as f32).cos()).collect();
    let mut rng = Rng(5);
    let panes: Vec<Vec<[f32; 3]>> = (0..6)
        .map(|_| {
            let a: [f32; 3] = std::array::from_fn(|_| 0.1 + rng.unit());
            let b: [f32; 3] = std::array::from_fn(|_| 0.1 + rng.unit());
            (0..n * n)
                .map(|i| std::array::from_fn(|ch| a[ch] * e1[i] + b[ch] * e2[i]))
                .collect()
        })
        .collect();
    let bytes = panes_archive("rank-two", &panes, res, 8, WriterOptions::default());
    let a = Archive::from_bytes(&bytes).unwrap();
    assert_eq!(a.pane_basis().ranks(), &[2, 2, 2, 2]);
    let decoded: Vec<Vec<[f32; 3]>> = (0..panes.len()).map(|p| a.read_pane(p).unwrap()).collect();
    for (t, e) in tile_errors(&panes, &decoded, n, 8).into_iter().enumerate() {
        assert!(e < 1e-3, "tile {t}: {e}");
    }
    for (p, d) in panes.iter().zip(&decoded) {
        for (want, got) in p.iter().zip(d) {
            for ch in 0..3 {
                assert!((want[ch] - got[ch]).abs() <= 2e-3 * want[ch], "{want:?} vs {got:?}");
            }
        }
    }
    // Each decoded value is the spec's sum, term by term.
    let basis = a.pane_basis();
    let (u, c) = (basis.basis(3), basis.coefficients(3));
    let texel = 5 * 8 + 6; // texel (6, 5) of tile (1, 1): atlas texel (14, 13)
    let mut v = 0f32;
    for k in 0..2 {
        v += u[texel * 2 + k] * c[(3 * 4 + 1) * 2 + k];
    }
    assert_eq!(decoded[4][13 * n + 14][1].to_bits(), v.max(0.0).to_bits());
    assert!(u.iter().all(|x| half::f16::from_f32(*x).to_f32() == *x), "f16 values");
}

/// The panes section of `bytes` (stored uncompressed): its offset.
fn panes_offset(bytes: &[u8]) -> usize {
    sections(bytes).iter().find(|s| s.kind == kind::PANES).unwrap().offset
}

/// `m` re-signed must be refused on open as inconsistent, naming `what`, and by `verify`.
fn assert_inconsistent(mut m: Vec<u8>, what: &str) {
    resign(&mut m);
    let err = Archive::from_bytes(&m).err().unwrap();
    assert!(matches!(err, Error::Inconsistent { .. }), "{what}: {err}");
    assert!(err.to_string().contains(what), "{what}: {err}");
    assert!(verify_bytes(&m).is_err());
}

/// A panes section whose header, ranks, size or values break §7 is refused, without a panic and
/// before the rest is decompressed.
#[test]
fn corrupted_panes_sections_are_refused() {
    let (bytes, _) = small_archive("panes-corrupt", UNCOMPRESSED);
    let p = panes_offset(&bytes);
    let word = |m: &mut Vec<u8>, at: usize, v: u32| m[at..at + 4].copy_from_slice(&v.to_le_bytes());
    let head: Vec<u32> = (0..8).map(|k| u32_at(&bytes, p + 4 * k).unwrap()).collect();
    let (panes, tps, max_rank, ranks) = (head[0], head[1], head[2], &head[4..8]);
    assert_eq!((panes, tps), (3, 2));
    assert_eq!(max_rank, *ranks.iter().max().unwrap());
    assert!(ranks[0] < max_rank, "{ranks:?}");
    let mut m = bytes.clone();
    word(&mut m, p + 4, 3);
    assert_inconsistent(m, "tiles per side");
    let mut m = bytes.clone();
    word(&mut m, p + 12, 1);
    assert_inconsistent(m, "reserved");
    let mut m = bytes.clone();
    word(&mut m, p + 8, max_rank + 1);
    assert_inconsistent(m, "largest rank");
    let mut m = bytes.clone();
    word(&mut m, p + 16, 10); // min(T², 3P) = 9
    word(&mut m, p + 8, 10);
    assert_inconsistent(m, "rank 10");
    let mut m = bytes.clone();
    word(&mut m, p + 16, ranks[0] + 1); // one more vector in tile 0: the size no longer matches
    assert_inconsistent(m, "raw bytes");
    let mut m = bytes.clone();
    word(&mut m, p, panes + 1);
    assert_inconsistent(m, "raw bytes");
    let mut m = bytes.clone();
    word(&mut m, p, u32::MAX);
    assert_inconsistent(m, "exceed the limit");

    // A NaN scale (the first), a NaN basis value (the last, whose high byte ends the section).
    let scales = p + 16 + 16;
    let mut m = bytes.clone();
    word(&mut m, scales, f32::NAN.to_bits());
    assert_inconsistent(m, "finite");
    let mut m = bytes.clone();
    word(&mut m, scales, (-1.0f32).to_bits());
    assert_inconsistent(m, "at least 0");
    let rank_total: usize = ranks.iter().map(|&r| r as usize).sum();
    let basis_end = scales + 4 * 3 * 4 + rank_total * (6 * 3 + 2 * 64);
    assert_eq!(
        basis_end,
        sections(&bytes)
            .iter()
            .find(|s| s.kind == kind::PANES)
            .map(|s| p + s.size)
            .unwrap()
    );
    let mut m = bytes.clone();
    m[basis_end - 1] = 0x7e;
    assert_inconsistent(m, "finite");
    // A finite change is data, not damage: it opens, and `verify` finds the energy off.
    let mut m = bytes.clone();
    m[basis_end - 1] = 0x3a;
    resign(&mut m);
    let mut a = Archive::from_bytes(&m).unwrap();
    let err = a.verify().unwrap_err();
    assert!(
        err.to_string().contains("energy") || err.to_string().contains("peak"),
        "{err}"
    );

    // A declared raw size that the ranks do not give, behind a compressed header: refused
    // before the 64 MiB are produced.
    let header = le_words(&[3, 2, 9, 0, 9, 9, 9, 9]);
    assert_hostile_header_refused(&bytes, kind::PANES, &header, "panes section declares");
    // Too short to hold its ranks.
    let short = le_words(&[3, 2, 9, 0]);
    let m = replace_section(&bytes, kind::PANES, &short, compression::NONE, short.len() as u64);
    let err = Archive::from_bytes(&m).err().unwrap();
    assert!(matches!(err, Error::Inconsistent { .. }), "{err}");
}

/// `verify` recomputes every cluster's energy and peak from the decoded panes, bit for bit.
#[test]
fn verify_finds_an_energy_or_peak_one_ulp_off() {
    let (bytes, _) = small_archive("verify-energy", UNCOMPRESSED);
    verify_bytes(&bytes).unwrap();
    let c = sections(&bytes)
        .iter()
        .find(|s| s.kind == kind::CLUSTERS)
        .unwrap()
        .offset;
    for (field, what) in [(32, "energy"), (44 + 8, "peak")] {
        let at = c + 56 + field; // cluster 1
        let mut m = bytes.clone();
        let v = f32::from_le_bytes(m[at..at + 4].try_into().unwrap());
        assert!(v > 0.0);
        m[at..at + 4].copy_from_slice(&f32::from_bits(v.to_bits() + 1).to_le_bytes());
        resign(&mut m);
        let mut a = Archive::from_bytes(&m).unwrap();
        let err = a.verify().unwrap_err();
        assert!(matches!(err, Error::Inconsistent { .. }), "{err}");
        assert!(err.to_string().contains(what), "{err}");
    }
}
