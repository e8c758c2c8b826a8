//! Atomic archive writer: the panes are collected, then compressed to a low-rank basis per tile.
//!
//! Over 600 lines on purpose: the destination rules, the temporary-file discipline and the
//! section writers share one invariant (nothing but a complete archive ever appears at the
//! destination, formats/prm.md §9), which is easiest to audit in one file.
//!
//! Decisions about the destination and the temporary file:
//!
//! * **Symlinks are written through.** A destination that is a symbolic link
//!   (possibly a chain, possibly dangling) is resolved to its final target;
//!   the temporary file is created beside that target and renamed onto it,
//!   so the link itself stays. Relative link targets are resolved against
//!   the link's own directory, without lexical `..` normalisation (the OS
//!   resolves `..` after following symlinked directories).
//! * **Only regular files are replaced.** A destination that exists and is
//!   a directory, device, FIFO or socket is refused with
//!   [`Error::Destination`] naming the path and what it is, before anything
//!   is written (renaming over `/dev/full` as root would otherwise replace
//!   the device node). So is a non-empty file that does not begin as an
//!   archive does. [`resolve_destination`] applies these rules and
//!   [`probe_directory`] tries the temporary file's directory, so a binary
//!   can fail before a long bake.
//! * **Stale temporary files are swept.** The temporary file is
//!   `.<name>.tmp-<pid>-<n>` beside the target. A process killed with
//!   SIGKILL cannot remove its own, so creating a writer removes the files
//!   of that pattern, for the same destination name, whose `<pid>` is not a
//!   live process. Liveness is `/proc/<pid>` on Linux (only when `/proc`
//!   shows our own pid, i.e. is mounted for our pid namespace); elsewhere
//!   nothing is swept. Files of live processes, including our own, are never
//!   touched. Caveat: a directory shared with another pid namespace (a
//!   container volume) can hold a live writer's file whose pid we cannot see.
//! * **Signals are the binary's business.** The library keeps no global
//!   registry; [`ArchiveWriter::temp_path`] tells a binary which file to
//!   remove from its own signal handler.

use std::ffi::OsStr;
use std::fs::{self, File, OpenOptions};
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::basis::{DenseTiles, PaneBasis, MAX_PANE_RANK, PANE_TOLERANCE};
use crate::error::{Error, Result};
use crate::layout::{
    checksum, compression, kind, Header, SectionRecord, HEADER_SIZE, MAGIC, VERSION_MAJOR, VERSION_MINOR,
};
use crate::metadata::Metadata;
use crate::rgb9e5::{RGB9E5_MAX_RELATIVE_ERROR, RGB9E5_NAME};
use crate::sections::{
    encode_clusters, encode_entries, encode_entry_energy, validate_entries_clusters, AtlasSection, Cluster, Entry,
};

/// Tuning knobs of [`ArchiveWriter`].
#[derive(Clone, Debug)]
pub struct WriterOptions {
    /// zstd level for the sections (1..=19 recommended; default 3).
    pub zstd_level: i32,
    /// Compress the sections with zstd (each is stored uncompressed anyway when that is not
    /// smaller).
    pub compress_sections: bool,
    /// Relative tolerance ε of the panes' low-rank basis, in `[0, 1)`: each tile keeps the fewest
    /// basis vectors whose discarded singular values hold at most ε of the tile's Frobenius norm
    /// (default [`PANE_TOLERANCE`], whose docs say how it was chosen; 0 keeps every vector the
    /// sketch finds, up to [`max_pane_rank`](Self::max_pane_rank)).
    pub pane_tolerance: f32,
    /// Largest rank of a tile's basis, at least 1 (default [`MAX_PANE_RANK`]): it bounds a
    /// tile's size and the compression's work whatever the tolerance asks.
    pub max_pane_rank: u32,
}

impl Default for WriterOptions {
    fn default() -> Self {
        WriterOptions {
            zstd_level: 3,
            compress_sections: true,
            pane_tolerance: PANE_TOLERANCE,
            max_pane_rank: MAX_PANE_RANK,
        }
    }
}

/// A temporary file next to the destination, removed on drop unless persisted.
struct TempFile {
    path: PathBuf,
    file: Option<BufWriter<File>>,
}

impl Drop for TempFile {
    fn drop(&mut self) {
        drop(self.file.take());
        if !self.path.as_os_str().is_empty() {
            let _ = fs::remove_file(&self.path);
        }
    }
}

static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Longest chain of symbolic links followed to reach the destination (Linux's own limit).
const MAX_SYMLINK_HOPS: usize = 40;

/// The directory holding `path` (`.` for a bare file name).
fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

fn destination_error(path: &Path, reason: impl Into<String>, source: Option<std::io::Error>) -> Error {
    Error::Destination {
        path: path.to_path_buf(),
        reason: reason.into(),
        source,
    }
}

/// "a directory", "a character device", … for a file that is not regular, as the writer's
/// [`Error::Destination`] names it.
pub fn describe_file_type(t: fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_file() {
        "a regular file"
    } else if t.is_dir() {
        "a directory"
    } else if t.is_symlink() {
        "a symbolic link"
    } else {
        "not a regular file"
    }
}

/// Follows symbolic links from `given` to the path the archive will really
/// replace, and refuses a target that exists and is not a regular file. A
/// target that does not exist is fine here (the writer creates it).
fn follow_links(given: &Path) -> Result<PathBuf> {
    let mut path = given.to_path_buf();
    let via = |p: &Path| {
        if p == given {
            String::new()
        } else {
            format!(" (reached through the symbolic link {})", given.display())
        }
    };
    for _ in 0..=MAX_SYMLINK_HOPS {
        match fs::symlink_metadata(&path) {
            Ok(m) if m.file_type().is_symlink() => {
                let target = fs::read_link(&path)
                    .map_err(|e| destination_error(&path, "cannot read the symbolic link", Some(e)))?;
                path = if target.is_absolute() {
                    target
                } else {
                    parent_dir(&path).join(target)
                };
            }
            Ok(m) if m.is_file() => return Ok(path),
            Ok(m) => {
                let reason = format!(
                    "it is {}, not a regular file{}",
                    describe_file_type(m.file_type()),
                    via(&path)
                );
                return Err(destination_error(&path, reason, None));
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(path),
            Err(e) => {
                let reason = format!("cannot inspect it{}", via(&path));
                return Err(destination_error(&path, reason, Some(e)));
            }
        }
    }
    Err(destination_error(
        given,
        format!("more than {MAX_SYMLINK_HOPS} levels of symbolic links"),
        None,
    ))
}

/// Refuses an existing `dest` that holds something other than an archive: a bake must not
/// replace its own scene, a report or any file that a mistyped `-o` names. An empty file (as
/// `mktemp` leaves) and an archive, damaged or not, may be replaced.
fn refuse_foreign_file(dest: &Path) -> Result<()> {
    let mut head = Vec::with_capacity(MAGIC.len());
    match fs::File::open(dest) {
        Ok(f) => {
            f.take(MAGIC.len() as u64)
                .read_to_end(&mut head)
                .map_err(|e| destination_error(dest, "cannot read it", Some(e)))?;
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        // Unreadable (permissions): the probe below says whether it can be replaced.
        Err(_) => return Ok(()),
    }
    if head.is_empty() || MAGIC.starts_with(&head) {
        return Ok(());
    }
    Err(destination_error(
        dest,
        "it exists and is not a .prm archive; refusing to replace it (remove it, or name another file)",
        None,
    ))
}

/// The file that an archive written at `path` replaces, or the writer's refusal
/// ([`Error::Destination`]) as [`ArchiveWriter::create`] would give it.
///
/// Symbolic links are followed as the writer follows them (module docs). Refused: a
/// destination that exists and is not a regular file (directory, device, FIFO, socket), and a
/// non-empty file that does not begin as an archive does (the scene, a report: anything a
/// mistyped output path names). A destination that does not exist is accepted; its directory
/// is not checked.
pub fn resolve_destination(path: impl AsRef<Path>) -> Result<PathBuf> {
    let dest = follow_links(path.as_ref())?;
    refuse_foreign_file(&dest)?;
    Ok(dest)
}

/// Creates, and removes at once, a file in `dir` named as the writer names its temporary files
/// for destination `name`: whether the writer can create its temporary file there.
pub fn probe_directory(dir: &Path, name: &OsStr) -> std::io::Result<()> {
    let probe = temp_path_for(dir, name);
    drop(OpenOptions::new().write(true).create_new(true).open(&probe)?);
    let _ = fs::remove_file(&probe);
    Ok(())
}

/// `.<name>.tmp-<pid>-<n>` in `dir`.
fn temp_path_for(dir: &Path, name: &OsStr) -> PathBuf {
    dir.join(format!(
        ".{}.tmp-{}-{}",
        name.to_string_lossy(),
        std::process::id(),
        TEMP_COUNTER.fetch_add(1, Ordering::Relaxed)
    ))
}

/// The pid of a temporary file name `.<name>.tmp-<pid>-<n>` of destination `name`, or of a
/// writer's temporary file for such a file (`.<temp name>.tmp-<pid>-<m>`, the same pid: a
/// [`scratch_path`] being written).
fn temp_file_pid(file: &str, name: &str) -> Option<u32> {
    let (stem, last) = file.strip_prefix('.')?.rsplit_once(".tmp-")?;
    let (pid, n) = last.split_once('-')?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    if !digits(pid) || !digits(n) {
        return None;
    }
    let pid = pid.parse().ok()?;
    (stem == name || temp_file_pid(stem, name) == Some(pid)).then_some(pid)
}

/// A fresh path beside `dest` named as the writer names its temporary files for `dest`, for an
/// archive that a caller writes, reads and removes before writing `dest` itself (`prm-bake
/// merge --scene` checks the merged archive there, so that a failed check leaves `dest`
/// alone). [`own_temp_files`] lists it and the writer's own temporary file for it, so a
/// signal handler that knows only `dest` removes them; a later write to `dest` sweeps them
/// when their process has died. Symbolic links in `dest` are resolved as the writer does.
pub fn scratch_path(dest: impl AsRef<Path>) -> PathBuf {
    let dest = dest.as_ref();
    let dest = follow_links(dest).unwrap_or_else(|_| dest.to_path_buf());
    temp_path_for(&parent_dir(&dest), dest.file_name().unwrap_or(OsStr::new("archive")))
}

/// Removes the temporary files of destination `name` in `dir` left by
/// processes that no longer exist (see the module docs); returns how many.
fn remove_stale_temps(dir: &Path, name: &OsStr) -> usize {
    #[cfg(target_os = "linux")]
    {
        let me = std::process::id();
        let proc = Path::new("/proc");
        let (Some(name), true) = (name.to_str(), proc.join(me.to_string()).exists()) else {
            return 0;
        };
        let Ok(listing) = fs::read_dir(dir) else {
            return 0;
        };
        let mut removed = 0;
        for entry in listing.flatten() {
            let file = entry.file_name();
            let Some(pid) = file.to_str().and_then(|f| temp_file_pid(f, name)) else {
                continue;
            };
            if pid == me || proc.join(pid.to_string()).exists() {
                continue;
            }
            // Never follow a symlink or remove anything but a plain file.
            let path = entry.path();
            if fs::symlink_metadata(&path).is_ok_and(|m| m.is_file()) && fs::remove_file(&path).is_ok() {
                removed += 1;
            }
        }
        removed
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (dir, name);
        0
    }
}

/// The temporary files that writers of *this* process currently have for
/// destination `path` (symbolic links resolved as the writer resolves them).
///
/// Global-state free: it lists `.<name>.tmp-<our pid>-<n>` beside the
/// target. Meant for a binary's signal handler, which knows its `-o` path
/// but not the writer (see also [`ArchiveWriter::temp_path`]); removing the
/// files while a writer is alive makes its `finish` fail.
pub fn own_temp_files(path: impl AsRef<Path>) -> Vec<PathBuf> {
    let path = path.as_ref();
    let dest = follow_links(path).unwrap_or_else(|_| path.to_path_buf());
    let (Some(name), dir) = (dest.file_name().and_then(OsStr::to_str), parent_dir(&dest)) else {
        return Vec::new();
    };
    let me = std::process::id();
    let Ok(listing) = fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = listing
        .flatten()
        .filter(|e| e.file_name().to_str().and_then(|f| temp_file_pid(f, name)) == Some(me))
        .map(|e| e.path())
        .collect();
    files.sort();
    files
}

/// Writes a `.prm` archive.
///
/// The archive is written to a temporary file in the destination's
/// directory; [`finish`](Self::finish) flushes and fsyncs it and renames it
/// over the destination. If anything fails, or the writer is dropped without
/// `finish`, the temporary file is removed and an older archive at the
/// destination is left untouched.
///
/// Panes are added in cluster order, one per cluster, and held in memory (`f32`, 12 bytes per
/// texel and pane) until [`compress_panes`](Self::compress_panes) or [`finish`](Self::finish)
/// turns them into a low-rank basis per atlas tile ([`PaneBasis`], formats/prm.md §7) and fills
/// in the clusters' energy and peak from the decoded panes.
///
/// ```no_run
/// # use prm_format::*;
/// let atlas = AtlasSection::new(128, 64);
/// let entries = vec![Entry { position: [0.0; 3], normal: [0.0, 1.0, 0.0], cluster: 0 }];
/// let clusters = vec![Cluster::new(0, 1, [0.0; 3], [0.0, 1.0, 0.0])];
/// let mut w = ArchiveWriter::create("out.prm", Metadata::new("doc", "0"), &atlas, &entries, &clusters)?;
/// w.add_pane(&vec![[0.5, 0.5, 0.5]; 128 * 128])?;
/// w.finish()?;
/// # Ok::<(), prm_format::Error>(())
/// ```
pub struct ArchiveWriter {
    /// The path as given to `create`.
    given: PathBuf,
    /// The file the archive replaces: `given` with symlinks resolved.
    dest: PathBuf,
    temp: TempFile,
    options: WriterOptions,
    compressor: zstd::bulk::Compressor<'static>,
    metadata: Metadata,
    clusters: Vec<Cluster>,
    entry_count: usize,
    entry_energy: Option<Vec<[f32; 3]>>,
    emitters: Option<Vec<crate::EmitterGroup>>,
    sky: Option<crate::SkyTransfer>,
    probes: Option<crate::Probes>,
    probe_rays: Option<crate::ProbeRays>,
    near_field: Option<crate::NearField>,
    entry_cells: Option<crate::EntryCells>,
    custom: Vec<(u32, Vec<u8>)>,
    records: Vec<SectionRecord>,
    resolution: u32,
    tile_size: u32,
    /// Current end of written data.
    pos: u64,
    /// The panes added so far, until they are compressed.
    dense: DenseTiles,
    /// The compressed panes, once every pane was added and compressed.
    basis: Option<PaneBasis>,
    panes_done: usize,
    poisoned: bool,
}

impl ArchiveWriter {
    /// Starts an archive at `path` with default options. See
    /// [`create_with_options`](Self::create_with_options).
    pub fn create(
        path: impl AsRef<Path>,
        metadata: Metadata,
        atlas: &AtlasSection,
        entries: &[Entry],
        clusters: &[Cluster],
    ) -> Result<Self> {
        Self::create_with_options(path, metadata, atlas, entries, clusters, WriterOptions::default())
    }

    /// Starts an archive at `path`.
    ///
    /// `metadata.texel_encoding` and `metadata.texel_relative_error_bound`
    /// are set by the writer, as are the `energy` and `peak` of every cluster
    /// (computed from the decoded panes). Entries must be sorted by cluster and
    /// the cluster ranges must tile the entry list in order. One pane per
    /// cluster must then be added before [`finish`](Self::finish). Options outside
    /// their documented ranges are refused.
    pub fn create_with_options(
        path: impl AsRef<Path>,
        mut metadata: Metadata,
        atlas: &AtlasSection,
        entries: &[Entry],
        clusters: &[Cluster],
        options: WriterOptions,
    ) -> Result<Self> {
        metadata.texel_encoding = RGB9E5_NAME.into();
        metadata.texel_relative_error_bound = RGB9E5_MAX_RELATIVE_ERROR;
        metadata.validate().map_err(Error::InvalidInput)?;
        atlas.validate().map_err(Error::InvalidInput)?;
        crate::basis::check_options(options.pane_tolerance, options.max_pane_rank)?;
        let mut clusters = clusters.to_vec();
        for c in &mut clusters {
            c.energy = [0.0; 3];
            c.peak = [0.0; 3];
        }
        validate_entries_clusters(entries, &clusters).map_err(Error::InvalidInput)?;

        let given = path.as_ref().to_path_buf();
        if given.file_name().is_none() {
            return Err(Error::InvalidInput(format!("{} has no file name", given.display())));
        }
        let dest = resolve_destination(&given)?;
        let file_name = dest
            .file_name()
            .ok_or_else(|| destination_error(&dest, "it has no file name", None))?
            .to_os_string();
        let dir = parent_dir(&dest);
        remove_stale_temps(&dir, &file_name);
        let temp_path = temp_path_for(&dir, &file_name);
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&temp_path)
            .map_err(|e| {
                let reason = format!("cannot create the temporary file {}", temp_path.display());
                destination_error(&dest, reason, Some(e))
            })?;
        let temp = TempFile {
            path: temp_path,
            file: Some(BufWriter::with_capacity(1 << 20, file)),
        };

        let dense = DenseTiles::new(atlas.resolution, atlas.tile_size, clusters.len());
        let mut w = ArchiveWriter {
            given,
            dest,
            temp,
            compressor: zstd::bulk::Compressor::new(options.zstd_level)?,
            options,
            metadata,
            clusters,
            entry_count: entries.len(),
            entry_energy: None,
            emitters: None,
            sky: None,
            probes: None,
            probe_rays: None,
            near_field: None,
            entry_cells: None,
            custom: Vec::new(),
            records: Vec::new(),
            resolution: atlas.resolution,
            tile_size: atlas.tile_size,
            pos: 0,
            dense,
            basis: None,
            panes_done: 0,
            poisoned: false,
        };
        // Placeholder header, rewritten by `finish`.
        w.write_all(&[0u8; HEADER_SIZE])?;
        w.write_section(kind::ATLAS, &atlas.encode())?;
        w.write_section(kind::ENTRIES, &encode_entries(entries))?;
        Ok(w)
    }

    /// The temporary file being written, renamed onto
    /// [`destination`](Self::destination) by [`finish`](Self::finish).
    ///
    /// For a binary's signal handler: the writer removes this file itself on
    /// failure or drop, but not when the process is ended by a signal.
    pub fn temp_path(&self) -> &Path {
        &self.temp.path
    }

    /// The file the archive will replace: the path given to `create`, with
    /// symbolic links resolved.
    pub fn destination(&self) -> &Path {
        &self.dest
    }

    /// Atlas resolution (texels per pane side).
    pub fn resolution(&self) -> u32 {
        self.resolution
    }

    /// Tile size in texels per side.
    pub fn tile_size(&self) -> u32 {
        self.tile_size
    }

    /// Number of panes still to add.
    pub fn panes_remaining(&self) -> usize {
        self.clusters.len() - self.panes_done
    }

    /// The cluster table as it will be written. The energy and peak of the panes (of their
    /// decoded texels, as the spec prescribes) are known once the panes are compressed: filled in
    /// after [`compress_panes`](Self::compress_panes), 0 before.
    pub fn clusters(&self) -> &[Cluster] {
        &self.clusters
    }

    /// The metadata to be written, e.g. to record timings measured while
    /// panes are being added.
    pub fn metadata_mut(&mut self) -> &mut Metadata {
        &mut self.metadata
    }

    /// Records every entry's pane energy (RGB, in the entries' order; finite, ≥ 0), written as the
    /// entry energy section (formats/prm.md §5.1).
    pub fn set_entry_energy(&mut self, energy: Vec<[f32; 3]>) -> Result<()> {
        if energy.len() != self.entry_count {
            return Err(Error::InvalidInput(format!(
                "{} entry energies for {} entries",
                energy.len(),
                self.entry_count
            )));
        }
        if let Some((i, e)) = energy
            .iter()
            .enumerate()
            .find(|(_, e)| !e.iter().all(|v| v.is_finite() && *v >= 0.0))
        {
            return Err(Error::InvalidInput(format!(
                "entry {i}'s energy {e:?} is not finite and non-negative"
            )));
        }
        self.entry_energy = Some(energy);
        Ok(())
    }

    /// Records the emitter groups (formats/prm.md §5.2): one per emissive material, each with
    /// an irradiance per entry (in the entries' order) and a direct irradiance per atlas texel
    /// (row-major), all finite and non-negative.
    pub fn set_emitters(&mut self, groups: Vec<crate::EmitterGroup>) -> Result<()> {
        crate::emitters::validate(&groups, self.entry_count, self.resolution).map_err(Error::InvalidInput)?;
        if let Some(rays) = &self.probe_rays {
            let probes = self.probes.as_ref().map_or(0, |p| p.len());
            crate::probe_rays::validate(rays, probes, self.resolution, groups.len())
                .map_err(|e| Error::InvalidInput(format!("the probe rays already set: {e}")))?;
        }
        if let Some(near) = &self.near_field {
            crate::near_field::validate(near, self.resolution, groups.len())
                .map_err(|e| Error::InvalidInput(format!("the near field already set: {e}")))?;
        }
        self.emitters = Some(groups);
        Ok(())
    }

    /// Records the sky's transfer at the atlas texels (formats/prm.md §5.3): `resolution²` texels
    /// each, row-major, all finite.
    pub fn set_sky(&mut self, sky: crate::SkyTransfer) -> Result<()> {
        crate::sky::validate(&sky, self.resolution).map_err(Error::InvalidInput)?;
        self.sky = Some(sky);
        Ok(())
    }

    /// Records the probes and every cluster's transfer to them (formats/prm.md §5.4): one
    /// transfer per cluster of the table and probe, cluster by cluster, all finite.
    pub fn set_probes(&mut self, probes: crate::Probes) -> Result<()> {
        crate::probes::validate(&probes, self.clusters.len()).map_err(Error::InvalidInput)?;
        if let Some(rays) = &self.probe_rays {
            if rays.probes() != probes.len() {
                return Err(Error::InvalidInput(format!(
                    "the probe rays already set are for {} probes, not {}",
                    rays.probes(),
                    probes.len()
                )));
            }
        }
        self.probes = Some(probes);
        Ok(())
    }

    /// Records where every probe's rays meet the scene (formats/prm.md §5.5), after
    /// [`ArchiveWriter::set_probes`] (and [`ArchiveWriter::set_emitters`] when gather points
    /// name emitter groups): one ray set per probe, gather points on texels of this atlas.
    pub fn set_probe_rays(&mut self, rays: crate::ProbeRays) -> Result<()> {
        let probes = self.probes.as_ref().map_or(0, |p| p.len());
        if probes == 0 {
            return Err(Error::InvalidInput("probe rays need the probes: set them first".into()));
        }
        let groups = self.emitters.as_ref().map_or(0, |g| g.len());
        crate::probe_rays::validate(&rays, probes, self.resolution, groups).map_err(Error::InvalidInput)?;
        self.probe_rays = Some(rays);
        Ok(())
    }

    /// Records where every exit point's near rays end (formats/prm.md §5.6), after
    /// [`ArchiveWriter::set_emitters`] when gather points name emitter groups: exits and gather
    /// points on texels of this atlas.
    pub fn set_near_field(&mut self, near: crate::NearField) -> Result<()> {
        let groups = self.emitters.as_ref().map_or(0, |g| g.len());
        crate::near_field::validate(&near, self.resolution, groups).map_err(Error::InvalidInput)?;
        self.near_field = Some(near);
        Ok(())
    }

    /// Records the points of every entry point's cell (formats/prm.md §5.7), entry by entry in
    /// the entries' order.
    pub fn set_entry_cells(&mut self, cells: crate::EntryCells) -> Result<()> {
        crate::entry_cells::validate(&cells, self.entry_count).map_err(Error::InvalidInput)?;
        self.entry_cells = Some(cells);
        Ok(())
    }

    /// Queues an extension section of a kind the format does not define (not 0 and not
    /// one of [`kind`](crate::kind)'s); readers that do not know it skip it.
    pub fn add_custom_section(&mut self, kind: u32, data: Vec<u8>) -> Result<()> {
        if kind == 0 || crate::kind::name(kind).is_some() {
            return Err(Error::InvalidInput(format!(
                "section kind {kind} is reserved or defined by the format"
            )));
        }
        self.custom.push((kind, data));
        Ok(())
    }

    /// Adds the next pane (in cluster order) from a full `resolution²` row-major RGB image. It is
    /// held until the panes are compressed; channels are taken as [`PaneBasis::compress`] takes
    /// them (NaN and negatives as 0, values above [`RGB9E5_MAX`](crate::RGB9E5_MAX) as that).
    pub fn add_pane(&mut self, texels: &[[f32; 3]]) -> Result<()> {
        self.check_pane_wanted()?;
        self.dense.set_pane(self.panes_done, texels)?;
        self.panes_done += 1;
        Ok(())
    }

    /// Compresses the panes, once all of them were added: the low-rank basis that
    /// [`finish`](Self::finish) writes, whose decoded panes give the clusters' energy and peak
    /// ([`clusters`](Self::clusters) has them from now on). For a caller that needs the stored
    /// panes before the archive is finished, e.g. to measure them into the metadata; `finish`
    /// compresses them itself otherwise. Compressing again returns the same basis.
    pub fn compress_panes(&mut self) -> Result<&PaneBasis> {
        self.check_usable()?;
        if self.panes_done != self.clusters.len() {
            return Err(Error::InvalidInput(format!(
                "{} of {} panes were added",
                self.panes_done,
                self.clusters.len()
            )));
        }
        let basis = match self.basis.take() {
            Some(basis) => basis,
            None => {
                let (tolerance, max_rank) = (self.options.pane_tolerance, self.options.max_pane_rank);
                let basis = PaneBasis::from_dense(&self.dense, tolerance, max_rank)?;
                for (c, (energy, peak)) in self.clusters.iter_mut().zip(basis.energy_peak()) {
                    c.energy = energy;
                    c.peak = peak;
                }
                // The dense panes are not needed any more.
                self.dense = DenseTiles::new(self.resolution, self.tile_size, 0);
                basis
            }
        };
        Ok(self.basis.insert(basis))
    }

    /// [`ArchiveWriter::check_usable`], and a pane is still to come.
    fn check_pane_wanted(&self) -> Result<()> {
        self.check_usable()?;
        if self.panes_done >= self.clusters.len() {
            return Err(Error::InvalidInput(format!(
                "all {} panes have already been added",
                self.clusters.len()
            )));
        }
        Ok(())
    }

    /// Compresses the panes (unless [`compress_panes`](Self::compress_panes) did), writes the
    /// panes section and the remaining sections, the section table and the header, fsyncs, and
    /// atomically renames the archive into place. Returns the archive's size in bytes.
    pub fn finish(mut self) -> Result<u64> {
        let panes = self.compress_panes()?.encode();
        self.poisoned = true;
        self.write_section(kind::PANES, &panes)?;
        drop(panes);
        let clusters = encode_clusters(&self.clusters);
        self.write_section(kind::CLUSTERS, &clusters)?;
        self.metadata.validate().map_err(Error::InvalidInput)?;
        let json = serde_json::to_vec(&self.metadata).map_err(|e| Error::InvalidInput(format!("metadata: {e}")))?;
        if json.len() as u64 > crate::limits::MAX_METADATA_BYTES {
            return Err(Error::InvalidInput("metadata JSON exceeds 16 MiB".into()));
        }
        self.write_section(kind::METADATA, &json)?;
        self.write_optional_sections()?;
        for (k, data) in std::mem::take(&mut self.custom) {
            self.write_section(k, &data)?;
        }
        let file_length = self.write_table_and_header()?;
        self.rename_into_place()?;
        Ok(file_length)
    }

    /// Writes the optional sections that were set.
    fn write_optional_sections(&mut self) -> Result<()> {
        if let Some(e) = self.entry_energy.take() {
            self.write_section(kind::ENTRY_ENERGY, &encode_entry_energy(&e))?;
        }
        if let Some(groups) = self.emitters.take() {
            let raw = crate::emitters::encode(&groups, self.entry_count, self.resolution);
            self.write_section(kind::EMITTERS, &raw)?;
        }
        if let Some(sky) = self.sky.take() {
            self.write_section(kind::SKY, &crate::sky::encode(&sky, self.resolution))?;
        }
        if let Some(probes) = self.probes.take() {
            self.write_section(kind::PROBES, &crate::probes::encode(&probes))?;
        }
        if let Some(rays) = self.probe_rays.take() {
            self.write_section(kind::PROBE_RAYS, &crate::probe_rays::encode(&rays, self.resolution))?;
        }
        if let Some(near) = self.near_field.take() {
            self.write_section(kind::NEAR_FIELD, &crate::near_field::encode(&near, self.resolution))?;
        }
        if let Some(cells) = self.entry_cells.take() {
            self.write_section(kind::ENTRY_CELLS, &crate::entry_cells::encode(&cells))?;
        }
        Ok(())
    }

    /// Writes the section table, then the header over its placeholder, and fsyncs the file;
    /// returns the archive's size in bytes.
    fn write_table_and_header(&mut self) -> Result<u64> {
        let mut table = Vec::with_capacity(self.records.len() * crate::layout::SECTION_RECORD_SIZE);
        for r in &self.records {
            r.encode_into(&mut table);
        }
        let table_offset = self.pos;
        self.write_all(&table)?;
        let header = Header {
            major: VERSION_MAJOR,
            // The lowest minor whose features the archive uses (formats/prm.md §2.1).
            minor: if self.records.iter().any(|r| r.kind == kind::ENTRY_CELLS) {
                VERSION_MINOR
            } else {
                0
            },
            section_count: self.records.len() as u32,
            table_offset,
            file_length: self.pos,
            reserved: [0, 0],
            table_checksum: checksum(&table),
        };
        let file_length = self.pos;
        let file = self.file()?;
        file.seek(SeekFrom::Start(0))?;
        file.write_all(&header.encode())?;
        file.flush()?;
        file.get_ref().sync_all()?;
        Ok(file_length)
    }

    /// Closes the temporary file and renames it onto the destination, re-checked first, then
    /// fsyncs the directory.
    fn rename_into_place(&mut self) -> Result<()> {
        drop(self.temp.file.take());
        // The destination may have changed during the write: refuse it now
        // rather than rename over a directory, a device or a new symlink.
        let now = follow_links(&self.given)?;
        if now != self.dest {
            return Err(destination_error(
                &self.given,
                format!(
                    "it now leads to {} instead of {}; changed while the archive was written",
                    now.display(),
                    self.dest.display()
                ),
                None,
            ));
        }
        fs::rename(&self.temp.path, &self.dest)?;
        // The temp path no longer exists; make the guard's removal a no-op.
        self.temp.path = PathBuf::new();
        sync_parent_dir(&self.dest);
        Ok(())
    }

    fn check_usable(&self) -> Result<()> {
        if self.poisoned {
            return Err(Error::InvalidInput(
                "an earlier write failed; the archive cannot be completed".into(),
            ));
        }
        Ok(())
    }

    fn file(&mut self) -> Result<&mut BufWriter<File>> {
        self.temp
            .file
            .as_mut()
            .ok_or_else(|| Error::InvalidInput("archive already finished".into()))
    }

    fn write_all(&mut self, bytes: &[u8]) -> Result<()> {
        self.file()?.write_all(bytes)?;
        self.pos += bytes.len() as u64;
        Ok(())
    }

    /// Writes one whole section (compressed when allowed and smaller) and
    /// records it in the section table.
    fn write_section(&mut self, kind: u32, raw: &[u8]) -> Result<()> {
        let compressed = if self.options.compress_sections {
            Some(self.compressor.compress(raw)?).filter(|c| c.len() < raw.len())
        } else {
            None
        };
        let (stored, compression) = match &compressed {
            Some(c) => (c.as_slice(), compression::ZSTD),
            None => (raw, compression::NONE),
        };
        let record = SectionRecord {
            kind,
            compression,
            offset: self.pos,
            stored_size: stored.len() as u64,
            raw_size: raw.len() as u64,
            checksum: checksum(stored),
            reserved: 0,
        };
        self.write_all(stored)?;
        self.records.push(record);
        Ok(())
    }
}

/// Best-effort fsync of the directory holding `path`, so the rename is durable.
fn sync_parent_dir(path: &Path) {
    #[cfg(unix)]
    if let Ok(d) = File::open(parent_dir(path)) {
        let _ = d.sync_all();
    }
    #[cfg(not(unix))]
    let _ = path;
}
