//! Locating the shared real data for tests and benchmarks.
//!
//! Tests that need real data call [`shared_data`] with the sub-path they need. The directory comes
//! from `VISNAV_DATA`; when it is unset or the path is missing the test is skipped (the function
//! returns `None`) — unless `VISNAV_REQUIRE_DATA=1`, as in CI, where it panics so that a data test
//! fails rather than silently skips.

use std::path::{Path, PathBuf};

/// The data directory itself: as given when it exists from the current directory, else — for a
/// relative path such as `../shared/data` given at the repository root — relative to the workspace
/// root (cargo runs each test binary in its crate's directory, two levels below the root).
fn resolve(dir: &Path) -> Option<PathBuf> {
    if dir.exists() || dir.is_absolute() {
        return Some(dir.to_path_buf());
    }
    let cwd = std::env::current_dir().ok()?;
    cwd.ancestors()
        .filter(|a| a.join("Cargo.lock").exists())
        .map(|root| root.join(dir))
        .find(|p| p.exists())
}

/// The path `$VISNAV_DATA/<sub>` if it exists.
///
/// # Panics
/// When `VISNAV_REQUIRE_DATA=1` and the path is unavailable (intended for tests only).
#[must_use]
pub fn shared_data(sub: &str) -> Option<PathBuf> {
    let required = std::env::var("VISNAV_REQUIRE_DATA").is_ok_and(|v| v == "1");
    let found = std::env::var_os("VISNAV_DATA")
        .and_then(|d| resolve(&PathBuf::from(d)))
        .map(|d| d.join(sub))
        .filter(|p| p.exists());
    match found {
        Some(p) => Some(p),
        None if required => panic!(
            "VISNAV_REQUIRE_DATA=1 but '{sub}' is not under VISNAV_DATA={:?}",
            std::env::var_os("VISNAV_DATA")
        ),
        None => {
            eprintln!("skipping: '{sub}' not found (set VISNAV_DATA to the shared data directory)");
            None
        }
    }
}
