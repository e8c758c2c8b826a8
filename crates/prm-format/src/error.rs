//! The error type shared by the archive reader and writer.
//!
//! Decision: an underlying error (today only [`std::io::Error`]) is exposed
//! as the variant's `source()` and is **not** interpolated into its
//! `Display`. `anyhow`'s `{:#}` and `{:?}` walk the source chain, so
//! interpolating it as well printed the OS text twice ("I/O error: No such
//! file (os error 2): No such file (os error 2)"). Every variant follows this
//! rule; callers that print a bare `{}` see the variant's own sentence only
//! and should print the chain (`{:#}` with anyhow) to see the cause.

/// Everything that can go wrong reading or writing a `.prm` archive.
///
/// The variants keep apart the causes a caller may want to react to
/// differently: an I/O failure, a file that ends too early, a file that is
/// not an archive at all, an archive of another major version, damaged bytes
/// (checksum), a damaged compressed stream, and bytes that are intact but
/// describe something impossible.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An operating-system level read, write, rename or sync failed. The OS
    /// error is the `source()`, not part of the message.
    #[error("I/O error")]
    Io(#[from] std::io::Error),
    /// The file ends before a structure it declares.
    #[error("archive is truncated: {what}")]
    Truncated {
        /// What was being read when the data ran out.
        what: String,
    },
    /// The first eight bytes are not the `.prm` magic.
    #[error("not a .prm archive (bad magic bytes)")]
    BadMagic,
    /// The archive's major version is not one this library reads.
    #[error(
        "unsupported .prm version {major}.{minor}: this reader supports major version {}",
        crate::VERSION_MAJOR
    )]
    UnsupportedVersion {
        /// Major version found in the file.
        major: u16,
        /// Minor version found in the file.
        minor: u16,
    },
    /// The archive is of format 1, whose panes this library does not read: the scene must be
    /// baked again.
    #[error(
        "this archive is .prm format {major}.{minor}, and this reader reads format {}.x only: re-bake the scene with this version of prm-bake",
        crate::VERSION_MAJOR
    )]
    Rebake {
        /// Major version found in the file (1).
        major: u16,
        /// Minor version found in the file.
        minor: u16,
    },
    /// Stored bytes do not match their xxh3-64 checksum.
    #[error("checksum mismatch in {section}")]
    ChecksumMismatch {
        /// The damaged structure, e.g. `"header"`, `"atlas"`, `"panes"`.
        section: String,
    },
    /// A zstd stream with a valid checksum failed to decompress or
    /// decompressed to the wrong size.
    #[error("cannot decompress {section}: {reason}")]
    Decompress {
        /// The structure being decompressed.
        section: String,
        /// What went wrong.
        reason: String,
    },
    /// The bytes are intact but describe something the format forbids
    /// (overlapping sections, out-of-range indices, sizes that disagree, …).
    #[error("inconsistent archive: {what}")]
    Inconsistent {
        /// Description of the inconsistency.
        what: String,
    },
    /// The writer was given data that cannot be stored (wrong pane size,
    /// non-finite values, cluster ranges that do not tile the entries, …).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// The writer's destination cannot receive an archive: it exists and is
    /// not a regular file (directory, device, FIFO, socket) or not an
    /// archive, its directory is missing, or no file can be created there.
    /// Raised before any data is written (see
    /// [`resolve_destination`](crate::resolve_destination)).
    #[error("cannot write an archive to {}: {reason}", path.display())]
    Destination {
        /// The destination as given (or the symlink target it resolved to).
        path: std::path::PathBuf,
        /// What is wrong with it, e.g. `"it is a directory"`.
        reason: String,
        /// The OS error behind it, if any.
        #[source]
        source: Option<std::io::Error>,
    },
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub(crate) fn truncated(what: impl Into<String>) -> Self {
        Error::Truncated { what: what.into() }
    }
    pub(crate) fn inconsistent(what: impl Into<String>) -> Self {
        Error::Inconsistent { what: what.into() }
    }
    pub(crate) fn checksum(section: impl Into<String>) -> Self {
        Error::ChecksumMismatch {
            section: section.into(),
        }
    }
}
