//! Locating the shared real data for tests and benchmarks.
//!
//! Tests that need real data call [`shared_data`] with the sub-path they need. The directory comes
//! from `VISNAV_DATA`; when it is unset or the path is missing the test is skipped (the function
//! returns `None`) — unless `VISNAV_REQUIRE_DATA=1`, as in CI, where it panics so that a data test
//! fails rather than silently skips.

use std::path::PathBuf;

/// The path `$VISNAV_DATA/<sub>` if it exists.
///
/// # Panics
/// When `VISNAV_REQUIRE_DATA=1` and the path is unavailable (intended for tests only).
#[must_use]
pub fn shared_data(sub: &str) -> Option<PathBuf> {
    let required = std::env::var("VISNAV_REQUIRE_DATA").is_ok_and(|v| v == "1");
    let found = std::env::var_os("VISNAV_DATA")
        .map(|d| PathBuf::from(d).join(sub))
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
