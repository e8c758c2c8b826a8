//! Removes a bake's temporary archive file when the bake is ended by SIGINT, SIGTERM or SIGHUP.
//!
//! Decisions:
//!
//! * The registry lives here, in the binary, not in `prm-format`: it holds the destinations
//!   (`-o` paths) of the writers this process may have open. On a signal, the handler asks
//!   [`prm_format::own_temp_files`] for this process's temporary files of each destination and
//!   removes them. Registering the destination rather than the writer's temp path means no
//!   window between creating the writer and registering it, and no edit at the writer's call site.
//! * The handler runs on a `signal-hook` iterator thread, not in async-signal context, so it may
//!   lock a mutex and use `std::fs`. It then exits with 128 + the signal number (130 for SIGINT,
//!   143 for SIGTERM, 129 for SIGHUP), the status a shell reports for a process the signal killed.
//!   Destructors of the main thread do not run (nor would they when killed by the signal).
//! * SIGKILL cannot be caught: its temporary file stays until the next write to the same
//!   destination, which sweeps temporary files of dead processes (see `prm_format`'s writer).
//! * Elsewhere than Unix, [`install`] does nothing.

use std::path::PathBuf;
use std::sync::{Mutex, Once};

/// Destinations whose temporary files are removed on a signal.
static DESTINATIONS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Registers `destination` (an archive path, as given or resolved) and, the first time, installs
/// the handler for SIGINT, SIGTERM and SIGHUP. If the handler cannot be installed, a warning is
/// printed and the default behaviour (death without cleanup) stays.
pub fn install(destination: PathBuf) {
    DESTINATIONS
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
        .push(destination);
    static INSTALL: Once = Once::new();
    INSTALL.call_once(|| {
        if let Err(e) = spawn_handler() {
            eprintln!("warning: cannot install signal handlers ({e}); an interrupted bake leaves its temporary file");
        }
    });
}

/// Removes every registered destination's temporary files of this process; returns how many.
fn remove_temp_files() -> usize {
    let destinations = DESTINATIONS.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    destinations
        .iter()
        .flat_map(prm_format::own_temp_files)
        .filter(|f| std::fs::remove_file(f).is_ok())
        .count()
}

#[cfg(unix)]
fn spawn_handler() -> std::io::Result<()> {
    use signal_hook::consts::signal::{SIGHUP, SIGINT, SIGTERM};
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])?;
    std::thread::Builder::new().name("signals".into()).spawn(move || {
        if let Some(signal) = signals.forever().next() {
            let name = match signal {
                SIGINT => "SIGINT",
                SIGTERM => "SIGTERM",
                _ => "SIGHUP",
            };
            let removed = remove_temp_files();
            eprintln!(
                "\nerror: interrupted by {name}; removed {removed} temporary file{}",
                if removed == 1 { "" } else { "s" }
            );
            std::process::exit(128 + signal);
        }
    })?;
    Ok(())
}

#[cfg(not(unix))]
fn spawn_handler() -> std::io::Result<()> {
    let _ = remove_temp_files;
    Ok(())
}
