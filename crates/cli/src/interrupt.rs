//! Ctrl-C during training: the first SIGINT asks the training loop to stop at the
//! next update, save a checkpoint and exit; a second one ends the process at once
//! (the last checkpoint still resumes exactly).

use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

#[cfg(unix)]
extern "C" fn on_sigint(_: libc::c_int) {
    REQUESTED.store(true, Ordering::SeqCst);
    // SAFETY: `signal` is async-signal-safe; the next SIGINT takes the default action.
    unsafe {
        libc::signal(libc::SIGINT, libc::SIG_DFL);
    }
}

/// Installs the handler (training commands call this before their loop).
pub fn install() {
    #[cfg(unix)]
    // SAFETY: the handler only stores to an atomic and resets the disposition, both
    // async-signal-safe.
    unsafe {
        libc::signal(libc::SIGINT, on_sigint as *const () as libc::sighandler_t);
    }
}

/// Whether Ctrl-C was pressed since [`install`].
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}

/// The exit status of a run stopped by Ctrl-C (128 + SIGINT, as shells report it).
pub const EXIT_CODE: u8 = 130;

/// The error a training command returns after saving on Ctrl-C.
#[derive(Debug)]
pub struct Interrupted {
    /// What was saved, and how to continue.
    pub message: String,
}

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Interrupted {}

/// The error for a run in `dir` stopped by Ctrl-C after saving `what`.
pub fn stopped(dir: &std::path::Path, what: String) -> anyhow::Error {
    Interrupted { message: format!("interrupted: saved {what} in {}; continue with --resume", dir.display()) }
        .into()
}
