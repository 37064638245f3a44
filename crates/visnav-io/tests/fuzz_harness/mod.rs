//! The fuzzing harness of issue 21 and 53, shared by `visnav-io/tests/fuzz.rs` (every parser of
//! `visnav-io`) and `visnav-batch/tests/fuzz.rs` (the batch manifest, the TOML configuration,
//! the run report JSON): proptest mutates real files (byte flips, truncation, inserted bytes,
//! duplicated, deleted and swapped lines, a byte-order mark, CRLF line ends, numbers replaced by
//! 1e308, -0, 1e-320, NaN, inf, huge integers) and every parser must, on every mutant,
//!
//! * not panic (a panic fails the case and proptest shrinks it),
//! * not hang (each parse must return within [`MAX_PARSE_S`]),
//! * allocate in proportion to its input (what it returns is bounded by the file's size),
//! * either return a result or an error that names the file (and a line that exists),
//! * and read a file with only a BOM and CRLF added exactly as the original.
//!
//! Case counts: `VISNAV_FUZZ_CASES` cases per parser (default 48, what CI runs).
#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::time::Instant;

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use visnav_io::IoError;

/// Longest a single parse may take, seconds (a parse of these small files takes microseconds).
pub const MAX_PARSE_S: f64 = 2.0;

/// Numbers that break naive parsers.
pub const EXTREMES: [&str; 16] = [
    "1e308",
    "-1e308",
    "1.7976931348623157e308",
    "-0",
    "-0.0",
    "1e-320",
    "NaN",
    "nan",
    "inf",
    "-inf",
    "18446744073709551616",
    "4294967296",
    "-1",
    "0",
    "1e400",
    "0x10",
];

/// Cases per parser: `VISNAV_FUZZ_CASES`, default 48.
pub fn cases() -> u32 {
    std::env::var("VISNAV_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(48)
}

/// One mutation of a file.
#[derive(Debug, Clone)]
pub enum Mutation {
    /// XOR the byte at this position (modulo the length) with a mask.
    Flip(usize, u8),
    /// Cut the file at this position.
    Truncate(usize),
    /// Insert bytes at this position.
    Insert(usize, Vec<u8>),
    /// Repeat a line.
    DuplicateLine(usize),
    /// Remove a line.
    DeleteLine(usize),
    /// Swap two lines.
    SwapLines(usize, usize),
    /// Replace the k-th number of the file by an extreme value.
    Extreme(usize, usize),
    /// Prepend a UTF-8 byte-order mark.
    Bom,
    /// `\n` → `\r\n`.
    Crlf,
}

pub fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 1..=255u8).prop_map(|(i, m)| Mutation::Flip(i, m)),
        any::<usize>().prop_map(Mutation::Truncate),
        (any::<usize>(), proptest::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(i, b)| Mutation::Insert(i, b)),
        any::<usize>().prop_map(Mutation::DuplicateLine),
        any::<usize>().prop_map(Mutation::DeleteLine),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::SwapLines(a, b)),
        (any::<usize>(), 0..EXTREMES.len()).prop_map(|(k, e)| Mutation::Extreme(k, e)),
        (any::<usize>(), 0..EXTREMES.len()).prop_map(|(k, e)| Mutation::Extreme(k, e)),
        Just(Mutation::Bom),
        Just(Mutation::Crlf),
    ]
}

/// Lines of `bytes` with their `\n`.
pub fn split_lines(bytes: &[u8]) -> Vec<Vec<u8>> {
    bytes
        .split_inclusive(|&b| b == b'\n')
        .map(<[u8]>::to_vec)
        .collect()
}

/// Whether `token` reads as a number (what [`Mutation::Extreme`] replaces).
pub fn is_number(token: &[u8]) -> bool {
    std::str::from_utf8(token).is_ok_and(|t| t.parse::<f64>().is_ok())
}

pub fn apply(bytes: &mut Vec<u8>, m: &Mutation) {
    let len = bytes.len();
    match m {
        Mutation::Flip(i, mask) if len > 0 => bytes[i % len] ^= mask,
        Mutation::Truncate(i) => bytes.truncate(i % (len + 1)),
        Mutation::Insert(i, b) => {
            let at = i % (len + 1);
            bytes.splice(at..at, b.iter().copied());
        }
        Mutation::DuplicateLine(i) | Mutation::DeleteLine(i) => {
            let mut lines = split_lines(bytes);
            if lines.is_empty() {
                return;
            }
            let k = i % lines.len();
            if matches!(m, Mutation::DuplicateLine(_)) {
                let mut line = lines[k].clone();
                if !line.ends_with(b"\n") {
                    line.push(b'\n');
                }
                lines.insert(k, line);
            } else {
                lines.remove(k);
            }
            *bytes = lines.concat();
        }
        Mutation::SwapLines(a, b) => {
            let mut lines = split_lines(bytes);
            if lines.len() > 1 {
                let n = lines.len();
                lines.swap(a % n, b % n);
                *bytes = lines.concat();
            }
        }
        Mutation::Extreme(k, e) => {
            // the k-th token between separators that is a number
            let is_sep = |b: u8| b.is_ascii_whitespace() || b == b',' || b == b'[' || b == b']';
            let mut spans = Vec::new();
            let mut start = None;
            for (i, &b) in bytes
                .iter()
                .enumerate()
                .chain(std::iter::once((len, &b' ')))
            {
                match (is_sep(b), start) {
                    (false, None) => start = Some(i),
                    (true, Some(s)) => {
                        if is_number(&bytes[s..i]) {
                            spans.push((s, i));
                        }
                        start = None;
                    }
                    _ => {}
                }
            }
            if !spans.is_empty() {
                let (s, t) = spans[k % spans.len()];
                bytes.splice(s..t, EXTREMES[*e].bytes());
            }
        }
        Mutation::Bom => {
            bytes.splice(0..0, *b"\xEF\xBB\xBF");
        }
        Mutation::Crlf => {
            let mut out = Vec::with_capacity(len + len / 8);
            for &b in bytes.iter() {
                if b == b'\n' {
                    out.push(b'\r');
                }
                out.push(b);
            }
            *bytes = out;
        }
        Mutation::Flip(..) => {}
    }
}

/// A parser's error, reduced to what the properties need.
#[derive(Debug)]
pub struct Failure {
    /// The whole message the user sees (the error chain).
    pub message: String,
    /// The line the error names, if any.
    pub line: Option<usize>,
}

impl From<IoError> for Failure {
    fn from(e: IoError) -> Self {
        let line = match &e {
            IoError::Parse { line, .. } => Some(*line),
            _ => None,
        };
        Self {
            message: e.to_string(),
            line,
        }
    }
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

/// What a parse returned, reduced to what the properties need.
pub struct Outcome {
    /// `Ok`: a rendering of the value (to compare two parses); `Err`: the error.
    pub result: Result<String, Failure>,
    /// Values held by the result (numbers, pixels): bounded by the input size.
    pub size: usize,
}

pub type Parser = fn(&Path) -> Outcome;

/// The outcome of a parse whose error converts into a [`Failure`].
pub fn outcome<T: std::fmt::Debug, E: Into<Failure>>(
    r: Result<T, E>,
    size: impl Fn(&T) -> usize,
) -> Outcome {
    match r {
        Ok(v) => Outcome {
            size: size(&v),
            result: Ok(format!("{v:?}")),
        },
        Err(e) => Outcome {
            result: Err(e.into()),
            size: 0,
        },
    }
}

/// Checks the properties of one mutant (module doc).
pub fn check(parse: Parser, path: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    std::fs::write(path, bytes).unwrap();
    let t = Instant::now();
    let out = parse(path);
    let secs = t.elapsed().as_secs_f64();
    prop_assert!(secs < MAX_PARSE_S, "parse took {secs} s");
    // a parsed value holds at most one value per input byte (plus a constant)
    prop_assert!(
        out.size <= bytes.len() + 64,
        "{} values from {} bytes",
        out.size,
        bytes.len()
    );
    if let Err(e) = &out.result {
        let msg = &e.message;
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        prop_assert!(
            msg.contains(&name),
            "the error does not name the file: {msg}"
        );
        if let Some(line) = e.line {
            // a line that exists, or the one after the last ("missing line")
            let lines = bytes.split(|&b| b == b'\n').count();
            prop_assert!(
                line >= 1 && line <= lines + 1,
                "line {line} of {lines}: {msg}"
            );
        }
    }
    Ok(())
}

/// Runs the campaign of one parser on its seeds: mutants, then BOM + CRLF on each seed.
pub fn campaign(name: &str, file_name: &str, parse: Parser, seeds: &[Vec<u8>], text: bool) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(file_name);
    let t = Instant::now();
    let n = cases();
    let mut runner = TestRunner::new(Config {
        cases: n,
        failure_persistence: None,
        ..Config::default()
    });
    let strategy = (0..seeds.len(), proptest::collection::vec(mutation(), 1..4));
    let result = runner.run(&strategy, |(seed, mutations)| {
        let mut bytes = seeds[seed].clone();
        for m in &mutations {
            apply(&mut bytes, m);
        }
        check(parse, &path, &bytes)
    });
    if let Err(e) = result {
        panic!("{name}: {e}");
    }
    if text {
        for seed in seeds {
            std::fs::write(&path, seed).unwrap();
            let clean = parse(&path).result.map_err(|e| e.message);
            let mut bytes = seed.clone();
            apply(&mut bytes, &Mutation::Crlf);
            apply(&mut bytes, &Mutation::Bom);
            std::fs::write(&path, &bytes).unwrap();
            let dirty = parse(&path).result.map_err(|e| e.message);
            assert_eq!(
                clean.is_ok(),
                dirty.is_ok(),
                "{name}: BOM + CRLF changed {clean:?} into {dirty:?}"
            );
            if let (Ok(a), Ok(b)) = (&clean, &dirty) {
                assert_eq!(a, b, "{name}: BOM + CRLF changed the result");
            }
        }
    }
    eprintln!(
        "fuzz {name}: {n} cases in {:.2} s",
        t.elapsed().as_secs_f64()
    );
}

/// `$VISNAV_DATA/<sub>`, first `max_lines` lines, when the data is there (no skip message: the
/// embedded seeds run anyway).
pub fn real(sub: &str, max_lines: usize) -> Option<Vec<u8>> {
    let dir = PathBuf::from(std::env::var_os("VISNAV_DATA")?);
    let text = std::fs::read(dir.join(sub)).ok()?;
    Some(
        split_lines(&text)
            .into_iter()
            .take(max_lines)
            .collect::<Vec<_>>()
            .concat(),
    )
}

/// The embedded seeds and the real files found.
pub fn seeds(embedded: &[&str], real_files: &[(&str, usize)]) -> Vec<Vec<u8>> {
    let mut v: Vec<Vec<u8>> = embedded.iter().map(|s| s.as_bytes().to_vec()).collect();
    v.extend(real_files.iter().filter_map(|(p, n)| real(p, *n)));
    v
}
