//! Stop signals: Ctrl-C (SIGINT), SIGTERM (`kill`, `timeout`, Slurm, Kubernetes, `docker stop`)
//! and SIGHUP (the terminal closed) stop a run after the frame in progress, so that the frames
//! done are written (`visnav odometry`, `visnav batch`); a second signal exits at once.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Installs the handler (once a process) and returns the flag it sets. Where no handler can be
/// installed the flag stays false and the signals keep their default action.
pub fn install_handler() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    let f = Arc::clone(&flag);
    let installed = ctrlc::set_handler(move || {
        if f.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!("interrupted: finishing the frame in progress and writing the frames done");
    });
    if let Err(e) = installed {
        log::debug!("no SIGINT/SIGTERM/SIGHUP handler ({e})");
    }
    flag
}
