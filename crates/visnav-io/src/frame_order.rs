//! The order of the frames of an image folder: one rule for every folder visnav lists (a folder
//! sequence, `left/` + `right/`, KITTI `image_0/`, a raw drive's `data/`).
//!
//! * Every file name is one pattern around one number (`image_1.jpg` … `image_120.jpg`,
//!   `1.png` … `51.png`, `000000.png` …): the frames are in the order of that number (the last
//!   run of digits of the name without its extension), so `image_9` comes before `image_10`.
//!   Zero-padded names of one width are in the same order as by name.
//! * No name holds a digit (`alpha.png`, `beta.png`): by name.
//! * Anything else is ambiguous and an error naming the folder: names of different patterns
//!   (`a1.png` and `b2.png`, or `frame_1.png` beside `preview.png`), or two names with the same
//!   number (`1.png` and `01.png`).

use std::cmp::Ordering;
use std::path::{Path, PathBuf};

use crate::error::{IoError, Result};

/// A file name split around its last run of digits: `image_012.jpg` is `("image_", "012", "")`.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Numbered<'a> {
    prefix: &'a str,
    digits: &'a str,
    suffix: &'a str,
}

/// The stem of `path` split around its last run of ASCII digits; `None` without a digit or
/// with a name that is not UTF-8.
fn numbered(path: &Path) -> Option<Numbered<'_>> {
    let stem = path.file_stem()?.to_str()?;
    let end = stem.rfind(|c: char| c.is_ascii_digit())? + 1;
    let start = stem[..end]
        .rfind(|c: char| !c.is_ascii_digit())
        .map_or(0, |i| i + 1);
    Some(Numbered {
        prefix: &stem[..start],
        digits: &stem[start..end],
        suffix: &stem[end..],
    })
}

/// Compares two runs of decimal digits by value (any length: no overflow).
fn cmp_digits(a: &str, b: &str) -> Ordering {
    let a = a.trim_start_matches('0');
    let b = b.trim_start_matches('0');
    a.len().cmp(&b.len()).then_with(|| a.cmp(b))
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
}

/// `files` (the images of `dir`) in frame order; see the module docs for the rule.
///
/// # Errors
/// [`IoError::Format`] naming `dir` when the order is ambiguous: names of different patterns,
/// or two names with the same number.
pub fn frame_order(dir: &Path, mut files: Vec<PathBuf>) -> Result<Vec<PathBuf>> {
    files.sort();
    let split: Vec<Option<Numbered<'_>>> = files.iter().map(|p| numbered(p)).collect();
    if split.iter().all(Option::is_none) {
        return Ok(files);
    }
    let ambiguous = |message: String| IoError::Format {
        path: dir.to_path_buf(),
        message: format!(
            "the frame order is ambiguous: {message} (frames are ordered by the number in their \
             names when every name is one pattern around one number, e.g. image_1.png … image_120.png \
             or 000000.png …; move other files out of the folder or rename the frames)"
        ),
    };
    let Some(first) = split.iter().flatten().next() else {
        return Ok(files);
    };
    for (p, s) in files.iter().zip(&split) {
        let same = s
            .as_ref()
            .is_some_and(|s| s.prefix == first.prefix && s.suffix == first.suffix);
        if !same {
            return Err(ambiguous(format!(
                "{} and {} are named after different patterns",
                file_name(&files[0]),
                file_name(p)
            )));
        }
    }
    let mut keyed: Vec<(&str, &PathBuf)> = split
        .iter()
        .flatten()
        .map(|s| s.digits)
        .zip(&files)
        .collect();
    keyed.sort_by(|a, b| cmp_digits(a.0, b.0).then_with(|| a.1.cmp(b.1)));
    if let Some(w) = keyed
        .windows(2)
        .find(|w| cmp_digits(w[0].0, w[1].0) == Ordering::Equal)
    {
        return Err(ambiguous(format!(
            "{} and {} have the same number",
            file_name(w[0].1),
            file_name(w[1].1)
        )));
    }
    Ok(keyed.into_iter().map(|(_, p)| p.clone()).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn order(names: &[&str]) -> Result<Vec<String>> {
        let files = names.iter().map(|n| Path::new("/d").join(n)).collect();
        frame_order(Path::new("/d"), files).map(|v| v.iter().map(|p| file_name(p)).collect())
    }

    #[test]
    fn numbered_names_are_in_number_order_not_name_order() {
        let names: Vec<String> = (1..=120).map(|i| format!("image_{i}.jpg")).collect();
        let mut shuffled: Vec<&str> = names.iter().map(String::as_str).collect();
        shuffled.sort_unstable(); // name order: image_1, image_10, image_100, ...
        assert_eq!(shuffled[1], "image_10.jpg");
        assert_eq!(order(&shuffled).unwrap(), names);
        assert_eq!(
            order(&["10.png", "9.png", "1.png", "100.png"]).unwrap(),
            ["1.png", "9.png", "10.png", "100.png"]
        );
        // digits inside a pattern: only the last run is the frame number
        assert_eq!(
            order(&["cam2_f10_l.png", "cam2_f9_l.png"]).unwrap(),
            ["cam2_f9_l.png", "cam2_f10_l.png"]
        );
    }

    #[test]
    fn zero_padded_names_keep_name_order() {
        let names: Vec<String> = (0..1200).map(|i| format!("{i:06}.png")).collect();
        let mut rev: Vec<&str> = names.iter().map(String::as_str).collect();
        rev.reverse();
        assert_eq!(order(&rev).unwrap(), names);
        // nanosecond timestamps (EuRoC) longer than any integer type
        let t = [
            "14036365797635555840000001.png",
            "14036365797635555840000000.png",
        ];
        assert_eq!(
            order(&t).unwrap(),
            [
                "14036365797635555840000000.png",
                "14036365797635555840000001.png"
            ]
        );
    }

    #[test]
    fn names_without_digits_are_in_name_order() {
        assert_eq!(
            order(&["b.png", "a.png", "c.jpg"]).unwrap(),
            ["a.png", "b.png", "c.jpg"]
        );
    }

    #[test]
    fn mixed_patterns_and_repeated_numbers_are_errors_naming_the_folder() {
        for (names, expected) in [
            (&["a1.png", "b2.png"][..], "a1.png and b2.png"),
            (&["1.png", "2.png", "preview.png"][..], "preview.png"),
            (
                &["1.png", "01.png"][..],
                "01.png and 1.png have the same number",
            ),
        ] {
            let e = order(names).unwrap_err().to_string();
            assert!(e.starts_with("/d: the frame order is ambiguous"), "{e}");
            assert!(e.contains(expected), "{e}");
        }
    }
}
