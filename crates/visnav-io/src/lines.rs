//! The data lines of the text formats (EuRoC `data.csv`, TUM `rgb.txt`, monoVO `times.txt`): the
//! file is read whole, blank lines and `#` comments are skipped, and every error names the file
//! and the 1-based line.

use std::path::Path;

use crate::error::{IoError, Result};

/// One data line of a text file: its trimmed text and where it is, for messages.
#[derive(Debug, Clone, Copy)]
pub(crate) struct DataLine<'a> {
    /// The file.
    pub path: &'a Path,
    /// 1-based line number.
    pub number: usize,
    /// The trimmed line.
    pub text: &'a str,
}

impl DataLine<'_> {
    /// A parse error at this line.
    pub fn error(&self, message: String) -> IoError {
        IoError::Parse {
            path: self.path.to_path_buf(),
            line: self.number,
            message,
        }
    }

    /// `token` as a finite number, or an error saying it is not `what`.
    pub fn number(&self, token: &str, what: &str) -> Result<f64> {
        token
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| self.error(format!("'{token}' is not {what}")))
    }
}

/// Calls `parse` on every data line of `path` (blank lines and `#` comments skipped) and
/// collects what it returns.
///
/// # Errors
/// A missing or unreadable file, or the first error of `parse`.
pub(crate) fn parse_data_lines<T>(
    path: &Path,
    mut parse: impl FnMut(DataLine<'_>) -> Result<T>,
) -> Result<Vec<T>> {
    let text = crate::text::read_text(path)?;
    text.lines()
        .enumerate()
        .map(|(i, line)| (i + 1, line.trim()))
        .filter(|(_, line)| !line.is_empty() && !line.starts_with('#'))
        .map(|(number, text)| parse(DataLine { path, number, text }))
        .collect()
}
