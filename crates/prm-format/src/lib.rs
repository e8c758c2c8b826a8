//! Reader and writer of `.prm` Precomputed Radiance Map archives (format 2.1).
//!
//! An archive holds the lightmap atlas of a scene, its entry points and
//! their clusters, and one *pane* per cluster: the indirect irradiance at
//! every atlas texel. The panes are stored as a low-rank basis per atlas tile
//! ([`PaneBasis`]): per tile, `f16` basis images shared by every pane and `f16`
//! coefficients per pane and channel under a scale per pane, which decode exactly the
//! same on every reader. The byte layout is specified in `formats/prm.md`.
//!
//! * [`ArchiveWriter`] collects the panes, compresses them (a randomized SVD per
//!   tile, within [`WriterOptions::pane_tolerance`]) and writes the archive into a
//!   temporary file that it renames into place atomically;
//!   [`resolve_destination`] and [`probe_directory`] let a binary refuse a bad
//!   destination before any work.
//! * [`Archive`] opens an archive from a path, a byte slice or any
//!   `Read + Seek` and validates it as it goes; [`Archive::read_pane`] decodes a
//!   pane, [`Archive::read_pane_rgb9e5`] encodes it for a GPU texture, and
//!   [`Archive::verify`] checks everything.
//! * [`EmitterGroup`]: the optional emitters section, what emissive surfaces give the
//!   entry points and the atlas texels per unit of their run-time scale.
//! * [`SkyTransfer`]: the optional sky section, the sky's transfer at the atlas texels
//!   in the spherical-harmonic basis [`sh_basis`], which [`sh_rotate_y`] turns about the vertical.
//! * [`Probes`]: the optional probes section, irradiance probes on a grid in the scene's
//!   empty space and every cluster's transfer to them, so the run-time weights light them too.
//! * [`ProbeRays`]: the optional probe rays section, where each probe's rays meet the
//!   scene, so a run time gathers the probes' light from the surfaces' radiance instead.
//! * [`NearField`]: the optional near field section, where short cosine rays from the exit
//!   points end, so a run time gathers back the light the panes' VPL bound removes.
//! * [`EntryCells`]: the optional entry cells section (format 2.1), points of the surface every
//!   entry point stands for, so a run time weighs it by the light its whole cell receives.
//! * [`residual_groups`]: the clusters' spatial groups whose summed panes carry the light of the
//!   clusters a run time drops from its top K.
//! * [`encode_rgb9e5`] / [`decode_rgb9e5`] implement the RGB9E5 texel encoding,
//!   bit-exact with WebGPU's `rgb9e5ufloat`, of the emitters' lightmaps and of
//!   the panes a GPU run time uploads.
#![warn(missing_docs)]

mod basis;
mod emitters;
mod entry_cells;
mod error;
mod groups;
mod layout;
mod metadata;
mod near_field;
mod probe_rays;
mod probes;
mod reader;
mod rgb9e5;
mod sections;
mod sh;
mod sky;
#[cfg(test)]
#[path = "../tests/common/splitmix.rs"]
mod splitmix;
mod writer;

pub use basis::{PaneBasis, MAX_PANE_RANK, PANE_TOLERANCE};
pub use emitters::{EmitterGroup, EMITTER_NAME_BYTES};
pub use entry_cells::{CellPoint, EntryCells};
pub use error::{Error, Result};
pub use groups::{residual_group_count, residual_groups, CLUSTERS_PER_GROUP, RESIDUAL_GROUPS};
pub use layout::{checksum, compression, kind, limits, MAGIC, VERSION_MAJOR, VERSION_MINOR};
pub use metadata::{Accuracy, Generator, LightAccuracy, Metadata, Units};
pub use near_field::{NearExit, NearField, NearHit, MAX_NEAR_RAYS, MIN_WEIGHT as NEAR_MIN_WEIGHT};
pub use probe_rays::{
    probe_ray_direction, GatherPoint, ProbeRays, MAX_PROBE_RAYS, NO_EMITTER, RAY_BLOCKED, RAY_SKY, SH_COSINE_LOBE,
};
pub use probes::{
    sh_irradiance, sky_irradiance_sh, ProbeGrid, ProbeSkyTransfer, Probes, AXIS_NORMALS, MAX_PROBES, MAX_PROBE_CELLS,
};
pub use reader::{pane_energy_peak, Archive, ArchiveInfo, SectionInfo, VerifyReport};
pub use rgb9e5::{
    decode_rgb9e5, decode_rgb9e5_slice, encode_rgb9e5, encode_rgb9e5_slice, RGB9E5_MANTISSAS, RGB9E5_MAX,
    RGB9E5_MAX_RELATIVE_ERROR, RGB9E5_MIN_ABS_ERROR, RGB9E5_MIN_NORMAL, RGB9E5_NAME,
};
pub use sections::{AtlasSection, Cluster, Entry};
pub use sh::{sh_basis, sh_rotate_y, SH_COEFFS};
pub use sky::SkyTransfer;
pub use writer::{
    describe_file_type, own_temp_files, probe_directory, resolve_destination, scratch_path, ArchiveWriter,
    WriterOptions,
};
