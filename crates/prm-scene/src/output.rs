//! The binaries' checks of their output paths, run before any work: that an archive or another
//! output file (an image, a report) can be written where the user asked, and that an output is
//! not one of the inputs.
//!
//! The archive writer's own rules (symbolic links written through, only regular files and
//! archives replaced) are [`prm_format::resolve_destination`]'s; these checks add the
//! directory: the nearest existing ancestor must be a directory, and where the directory exists
//! a file must be creatable in it ([`prm_format::probe_directory`]). Missing directories pass:
//! the caller creates them.

use std::ffi::OsStr;
use std::fs;
use std::path::{Path, PathBuf};

use prm_format::describe_file_type;

/// The directory holding `path` (`.` for a bare file name).
fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

fn destination_error(path: &Path, reason: impl Into<String>, source: Option<std::io::Error>) -> prm_format::Error {
    prm_format::Error::Destination {
        path: path.to_path_buf(),
        reason: reason.into(),
        source,
    }
}

/// Whether `a` and `b` name the same file as destinations: symbolic links resolved as the
/// writer resolves them, then the path made canonical (for a file still to be created, its
/// directory's path, with the file name). Binaries use it to refuse an output that is one of
/// their inputs (the scene, a part of a merge, the archive a report would replace).
pub fn same_destination(a: impl AsRef<Path>, b: impl AsRef<Path>) -> bool {
    let key = |p: &Path| -> Option<PathBuf> {
        let p = prm_format::resolve_destination(p).unwrap_or_else(|_| p.to_path_buf());
        match fs::canonicalize(&p) {
            Ok(c) => Some(c),
            Err(_) => Some(fs::canonicalize(parent_dir(&p)).ok()?.join(p.file_name()?)),
        }
    };
    matches!((key(a.as_ref()), key(b.as_ref())), (Some(x), Some(y)) if x == y)
}

/// Checks, before any work, that an archive can be written at `path`, and
/// returns the path the writer will replace (symbolic links resolved).
///
/// Refuses ([`prm_format::Error::Destination`]) what the writer refuses
/// ([`prm_format::resolve_destination`]: a destination that exists and is not a
/// regular file, a non-empty file that does not begin as an archive does), one
/// whose nearest existing ancestor is not a directory, and one whose directory
/// exists but where no file can be created (checked by creating and removing a
/// probe file named like the writer's temporary files). Missing directories are
/// accepted: a caller may create them before [`prm_format::ArchiveWriter::create`].
pub fn check_destination(path: impl AsRef<Path>) -> prm_format::Result<PathBuf> {
    let dest = prm_format::resolve_destination(path.as_ref())?;
    let name = dest
        .file_name()
        .ok_or_else(|| destination_error(&dest, "it has no file name", None))?
        .to_os_string();
    check_directory(&parent_dir(&dest), &name).map_err(|(reason, source)| destination_error(&dest, reason, source))?;
    Ok(dest)
}

/// Checks, before any work, that an output file other than an archive (an image, a report)
/// can be written at `path`: what exists there must be a regular file (not a directory, a
/// device or a FIFO), the nearest existing ancestor of its directory must be a directory, and
/// where the directory exists a file must be creatable in it (a probe file, removed at once).
/// Missing directories pass: the caller creates them. The error is the reason; the caller
/// names the option and the path.
pub fn check_output_path(path: impl AsRef<Path>) -> Result<(), String> {
    let path = path.as_ref();
    if let Ok(m) = fs::metadata(path) {
        if !m.is_file() {
            return Err(format!(
                "it is {}, not a regular file",
                describe_file_type(m.file_type())
            ));
        }
    }
    let name = path.file_name().unwrap_or(OsStr::new("output"));
    check_directory(&parent_dir(path), name).map_err(|(reason, source)| match source {
        Some(e) => format!("{reason}: {e}"),
        None => reason,
    })
}

/// The directory checks of [`check_output_path`] and [`check_destination`] for a file `name`
/// in `dir`: the reason and the OS error, if any.
fn check_directory(dir: &Path, name: &OsStr) -> Result<(), (String, Option<std::io::Error>)> {
    let mut ancestor = dir;
    loop {
        match fs::metadata(ancestor) {
            Ok(m) if m.is_dir() => break,
            Ok(m) => {
                let reason = format!(
                    "{} is {}, not a directory",
                    ancestor.display(),
                    describe_file_type(m.file_type())
                );
                return Err((reason, None));
            }
            // Not found, or below a file (ENOTDIR): the ancestor above says which.
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory
                ) =>
            {
                match ancestor.parent() {
                    Some(p) if !p.as_os_str().is_empty() => ancestor = p,
                    _ => return Ok(()),
                }
            }
            Err(e) => return Err((format!("cannot inspect {}", ancestor.display()), Some(e))),
        }
    }
    if ancestor != dir {
        return Ok(()); // the directory is still to be created
    }
    prm_format::probe_directory(dir, name).map_err(|e| (format!("cannot create a file in {}", dir.display()), Some(e)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("prm-scene-output-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// The number of files in `dir`: the probe files leave none behind.
    fn files_in(dir: &Path) -> usize {
        fs::read_dir(dir).unwrap().count()
    }

    /// What the writer refuses, a file where a directory should be; missing directories pass
    /// (a bake creates them), and the probe file leaves nothing behind.
    #[test]
    fn archive_destinations_are_checked_before_any_work() {
        let dir = test_dir("archive");
        let out = dir.join("out.prm");
        fs::create_dir(&out).unwrap();
        let err = check_destination(&out).unwrap_err();
        assert!(matches!(err, prm_format::Error::Destination { .. }), "{err}");
        assert!(
            err.to_string().contains("out.prm") && err.to_string().contains("a directory"),
            "{err}"
        );

        let scene = dir.join("room.obj");
        fs::write(&scene, b"v 0 0 0\n").unwrap();
        let err = check_destination(&scene).unwrap_err();
        assert!(err.to_string().contains("not a .prm archive"), "{err}");
        let empty = dir.join("empty.prm");
        fs::write(&empty, b"").unwrap();
        assert_eq!(check_destination(&empty).unwrap(), empty);

        assert_eq!(check_destination(dir.join("a/b/c.prm")).unwrap(), dir.join("a/b/c.prm"));
        fs::write(dir.join("file"), b"x").unwrap();
        let err = check_destination(dir.join("file/c.prm")).unwrap_err();
        assert!(matches!(err, prm_format::Error::Destination { .. }), "{err}");
        assert!(err.to_string().contains("file/c.prm"), "{err}");
        assert_eq!(files_in(&dir), 4);
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn other_outputs_must_be_regular_files_in_a_directory() {
        let dir = test_dir("other");
        assert_eq!(check_output_path(dir.join("image.png")), Ok(()));
        assert_eq!(check_output_path(dir.join("new/image.png")), Ok(()));
        fs::write(dir.join("report.json"), b"{}").unwrap();
        assert_eq!(check_output_path(dir.join("report.json")), Ok(()));
        assert_eq!(
            check_output_path(&dir),
            Err("it is a directory, not a regular file".to_string())
        );
        let err = check_output_path(dir.join("report.json/image.png")).unwrap_err();
        assert!(err.ends_with("report.json is a regular file, not a directory"), "{err}");
        assert_eq!(files_in(&dir), 1);
        let _ = fs::remove_dir_all(&dir);
    }

    /// Two paths name one destination when they reach one file: through `..`, through a
    /// symbolic link, or (not yet created) through the same directory.
    #[cfg(unix)]
    #[test]
    fn same_destination_sees_through_paths_and_links() {
        let dir = test_dir("same");
        fs::create_dir_all(dir.join("sub")).unwrap();
        fs::write(dir.join("a.prm"), b"").unwrap();
        std::os::unix::fs::symlink("a.prm", dir.join("link.prm")).unwrap();
        assert!(same_destination(dir.join("a.prm"), dir.join("sub/../a.prm")));
        assert!(same_destination(dir.join("link.prm"), dir.join("a.prm")));
        assert!(same_destination(dir.join("new.prm"), dir.join("sub/../new.prm")));
        assert!(!same_destination(dir.join("new.prm"), dir.join("a.prm")));
        assert!(!same_destination(dir.join("sub/new.prm"), dir.join("new.prm")));
        // A file that is not an archive, through a link, is still the same file.
        fs::write(dir.join("room.obj"), b"v 0 0 0\n").unwrap();
        std::os::unix::fs::symlink("room.obj", dir.join("scene.obj")).unwrap();
        assert!(same_destination(dir.join("scene.obj"), dir.join("room.obj")));
        let _ = fs::remove_dir_all(&dir);
    }
}
