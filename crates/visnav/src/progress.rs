//! Progress bars for commands that walk a sequence: hidden with `--quiet` or when stdout is not
//! a terminal, so logs and pipes stay clean.

use std::io::IsTerminal;
use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressStyle};

/// A progress bar over `len` items labelled `what`.
#[must_use]
pub fn bar(len: u64, what: &str, quiet: bool) -> ProgressBar {
    if quiet || !std::io::stdout().is_terminal() {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(len);
    let style =
        ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} {per_sec} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");
    pb.set_style(style);
    pb.set_message(what.to_string());
    pb
}

/// Draws the progress the libraries report ([`visnav_core::Progress`]): one bar per stage,
/// cleared when the stage is done.
pub struct Bars {
    quiet: bool,
    current: Mutex<Option<(String, ProgressBar)>>,
}

impl Bars {
    /// Bars, hidden with `quiet`.
    #[must_use]
    pub fn new(quiet: bool) -> Self {
        Self {
            quiet,
            current: Mutex::new(None),
        }
    }
}

impl visnav_core::Progress for Bars {
    fn step(&self, stage: &str, done: u64, total: u64) {
        let Ok(mut current) = self.current.lock() else {
            return;
        };
        if current.as_ref().is_none_or(|(s, _)| s != stage) {
            *current = Some((stage.to_owned(), bar(total, stage, self.quiet)));
        }
        if let Some((_, pb)) = current.as_ref() {
            pb.set_position(done);
            if done >= total {
                pb.finish_and_clear();
            }
        }
    }
}
