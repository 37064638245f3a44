//! The small subset of YAML that calibration files use, parsed into a [`serde_json::Value`] so
//! that typed `serde` structs (with `deny_unknown_fields`) can be read from it.
//!
//! Supported: block mappings by indentation (`key: value`, `key:` + indented block), block
//! sequences (`- item`), flow sequences over one or several lines (`[1, 2, [3, 4]]`), numbers,
//! booleans, `null`/`~`, plain and quoted strings, `#` comments, the `%YAML:1.0` / `%YAML 1.2`
//! directive line that OpenCV and EuRoC files start with, `---`, `!!tags` (ignored, e.g.
//! OpenCV's `!!opencv-matrix`), and OpenCV's `key:value` without a space after the colon.
//! Not supported (an error naming the line): anchors, aliases, multi-line strings, flow
//! mappings, and mappings inside block sequences.
//!
//! Why not a YAML crate: the maintained serde YAML crates reject the `%YAML:1.0` directive that
//! OpenCV writes (the EuRoC sample starts with it), and calibration files need only this subset.

use std::path::Path;

use serde_json::{Map, Number, Value};

use crate::error::{IoError, Result};

/// One logical line: indentation, content (comment stripped; flow sequences joined), line number.
struct Line {
    indent: usize,
    text: String,
    line_no: usize,
}

/// Parses YAML `text` (read from `path`, used in errors) into a JSON value.
///
/// # Errors
/// [`IoError::Parse`] naming the line of an unsupported or malformed construct.
pub fn parse(text: &str, path: &Path) -> Result<Value> {
    let lines = logical_lines(text, path)?;
    if lines.is_empty() {
        return Ok(Value::Object(Map::new()));
    }
    let mut pos = 0;
    let value = parse_block(&lines, &mut pos, lines[0].indent, path)?;
    if let Some(l) = lines.get(pos) {
        return Err(err(path, l.line_no, "unexpected indentation"));
    }
    Ok(value)
}

fn err(path: &Path, line: usize, message: impl Into<String>) -> IoError {
    IoError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// Removes a `#` comment that is not inside quotes.
fn strip_comment(line: &str) -> &str {
    let mut quote: Option<char> = None;
    let mut prev_space = true;
    for (i, c) in line.char_indices() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None if c == '"' || c == '\'' => quote = Some(c),
            None if c == '#' && prev_space => return &line[..i],
            None => {}
        }
        prev_space = c.is_whitespace();
    }
    line
}

fn bracket_depth(s: &str) -> i64 {
    s.chars()
        .map(|c| match c {
            '[' => 1,
            ']' => -1,
            _ => 0,
        })
        .sum()
}

fn logical_lines(text: &str, path: &Path) -> Result<Vec<Line>> {
    let mut out: Vec<Line> = Vec::new();
    let mut open: Option<(Line, i64)> = None;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        if raw.starts_with('%') || raw.trim() == "---" || raw.trim() == "..." {
            continue;
        }
        if raw.contains('\t') && raw.trim_start().len() != raw.trim_start_matches('\t').len() {
            return Err(err(path, line_no, "tabs are not allowed for indentation"));
        }
        let content = strip_comment(raw).trim_end();
        if let Some((mut line, depth)) = open.take() {
            line.text.push(' ');
            line.text.push_str(content.trim());
            let depth = depth + bracket_depth(content);
            if depth > 0 {
                open = Some((line, depth));
            } else {
                out.push(line);
            }
            continue;
        }
        if content.trim().is_empty() {
            continue;
        }
        let indent = content.len() - content.trim_start().len();
        let line = Line {
            indent,
            text: content.trim().to_string(),
            line_no,
        };
        let depth = bracket_depth(&line.text);
        if depth > 0 {
            open = Some((line, depth));
        } else {
            out.push(line);
        }
    }
    if let Some((line, _)) = open {
        return Err(err(path, line.line_no, "unclosed '['"));
    }
    Ok(out)
}

/// Parses the block of lines at exactly `indent` starting at `pos`.
fn parse_block(lines: &[Line], pos: &mut usize, indent: usize, path: &Path) -> Result<Value> {
    let first = &lines[*pos];
    if first.text == "-" || first.text.starts_with("- ") {
        let mut items = Vec::new();
        while let Some(l) = lines.get(*pos) {
            if l.indent < indent {
                break;
            }
            if l.indent > indent {
                return Err(err(path, l.line_no, "unexpected indentation"));
            }
            let Some(rest) = l.text.strip_prefix('-') else {
                return Err(err(
                    path,
                    l.line_no,
                    "expected '- item' like the lines above",
                ));
            };
            let rest = rest.trim();
            *pos += 1;
            if rest.is_empty() {
                items.push(nested(lines, pos, indent, path, l.line_no)?);
            } else if split_key(rest).is_some() {
                return Err(err(
                    path,
                    l.line_no,
                    "mappings inside block sequences are not supported",
                ));
            } else {
                items.push(scalar_or_flow(rest, path, l.line_no)?);
            }
        }
        return Ok(Value::Array(items));
    }
    let mut map = Map::new();
    while let Some(l) = lines.get(*pos) {
        if l.indent < indent {
            break;
        }
        if l.indent > indent {
            return Err(err(path, l.line_no, "unexpected indentation"));
        }
        let Some((key, rest)) = split_key(&l.text) else {
            return Err(err(path, l.line_no, "expected 'key: value'"));
        };
        *pos += 1;
        let rest = strip_tag(rest);
        let value = if rest.is_empty() {
            nested(lines, pos, indent, path, l.line_no)?
        } else {
            scalar_or_flow(rest, path, l.line_no)?
        };
        if map.insert(key.to_string(), value).is_some() {
            return Err(err(path, l.line_no, format!("duplicate key '{key}'")));
        }
    }
    Ok(Value::Object(map))
}

/// The indented block after `key:` or `-` (null when there is none). A block sequence may sit
/// at the same indentation as its key, as YAML allows.
fn nested(
    lines: &[Line],
    pos: &mut usize,
    indent: usize,
    path: &Path,
    _line_no: usize,
) -> Result<Value> {
    match lines.get(*pos) {
        Some(n) if n.indent > indent => parse_block(lines, pos, n.indent, path),
        Some(n) if n.indent == indent && (n.text == "-" || n.text.starts_with("- ")) => {
            let mut items = Vec::new();
            while let Some(l) = lines.get(*pos) {
                if l.indent != indent || !(l.text == "-" || l.text.starts_with("- ")) {
                    break;
                }
                let rest = l.text[1..].trim();
                *pos += 1;
                items.push(scalar_or_flow(rest, path, l.line_no)?);
            }
            Ok(Value::Array(items))
        }
        _ => Ok(Value::Null),
    }
}

/// `key: rest` with a plain or quoted key; `None` when the text is not a mapping entry. OpenCV's
/// `FileStorage` also writes and reads `key:value` without the space (`data:[1, 2]`,
/// `Viewer.PointSize:2` in ORB-SLAM's settings files): accepted for a key of letters, digits,
/// `_` and `.` (starting with a letter) followed by a number, a `[` or a quote.
fn split_key(text: &str) -> Option<(&str, &str)> {
    if text.starts_with('[') || text.starts_with('"') || text.starts_with('\'') {
        return None;
    }
    let i = text
        .find(": ")
        .or_else(|| text.ends_with(':').then(|| text.len() - 1))
        .or_else(|| opencv_compact_key(text))?;
    Some((text[..i].trim(), text[i + 1..].trim()))
}

/// The position of the `:` of an OpenCV `key:value` entry (see [`split_key`]).
fn opencv_compact_key(text: &str) -> Option<usize> {
    let i = text.find(':')?;
    let (key, value) = (&text[..i], &text[i + 1..]);
    let key_ok = key.starts_with(|c: char| c.is_ascii_alphabetic())
        && key
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.');
    let value_ok = value.starts_with(|c: char| {
        c.is_ascii_digit() || matches!(c, '[' | '-' | '+' | '.' | '"' | '\'')
    });
    (key_ok && value_ok).then_some(i)
}

fn strip_tag(rest: &str) -> &str {
    if rest.starts_with("!!") {
        rest.split_once(char::is_whitespace)
            .map_or("", |(_, r)| r.trim())
    } else {
        rest
    }
}

fn scalar_or_flow(text: &str, path: &Path, line: usize) -> Result<Value> {
    let text = strip_tag(text.trim());
    if text.starts_with('[') {
        let mut chars = text.chars().peekable();
        let v = parse_flow(&mut chars, path, line)?;
        if chars.any(|c| !c.is_whitespace()) {
            return Err(err(path, line, "text after the closing ']'"));
        }
        return Ok(v);
    }
    if text.starts_with('{')
        || text.starts_with('&')
        || text.starts_with('*')
        || text.starts_with('|')
        || text.starts_with('>')
    {
        return Err(err(
            path,
            line,
            format!("unsupported YAML construct '{text}' (flow mappings, anchors, block strings)"),
        ));
    }
    Ok(scalar(text))
}

fn parse_flow(
    chars: &mut std::iter::Peekable<std::str::Chars<'_>>,
    path: &Path,
    line: usize,
) -> Result<Value> {
    // consumes the '['
    chars.next();
    let mut items = Vec::new();
    let mut token = String::new();
    loop {
        let Some(c) = chars.next() else {
            return Err(err(path, line, "unclosed '['"));
        };
        match c {
            '[' => {
                // nested list: put the '[' back by parsing from here
                let mut nested = String::from("[");
                let mut depth = 1;
                for c in chars.by_ref() {
                    nested.push(c);
                    depth += match c {
                        '[' => 1,
                        ']' => -1,
                        _ => 0,
                    };
                    if depth == 0 {
                        break;
                    }
                }
                let mut it = nested.chars().peekable();
                items.push(parse_flow(&mut it, path, line)?);
                token.clear();
                // skip to the separator
                while let Some(&n) = chars.peek() {
                    if n == ',' {
                        chars.next();
                        break;
                    }
                    if n == ']' {
                        break;
                    }
                    chars.next();
                }
            }
            ',' | ']' => {
                let t = token.trim();
                if !t.is_empty() {
                    items.push(scalar(t));
                } else if c == ',' {
                    return Err(err(path, line, "empty item in '[...]'"));
                }
                token.clear();
                if c == ']' {
                    return Ok(Value::Array(items));
                }
            }
            _ => token.push(c),
        }
    }
}

fn scalar(text: &str) -> Value {
    let t = text.trim();
    if let Some(s) = t
        .strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .or_else(|| t.strip_prefix('\'').and_then(|s| s.strip_suffix('\'')))
    {
        return Value::String(s.to_string());
    }
    match t {
        "null" | "~" | "" => return Value::Null,
        "true" | "True" => return Value::Bool(true),
        "false" | "False" => return Value::Bool(false),
        _ => {}
    }
    if let Ok(i) = t.parse::<i64>() {
        return Value::Number(Number::from(i));
    }
    if let Ok(f) = t.parse::<f64>()
        && let Some(n) = Number::from_f64(f)
    {
        return Value::Number(n);
    }
    Value::String(t.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn parses_euroc_sensor_yaml_subset() {
        let text = "%YAML:1.0\n# comment\nsensor_type: camera\ncomment: VI-Sensor cam0 (MT9M034)\n\nT_BS:\n  cols: 4\n  rows: 4\n  data: [0.5, -1, 2e-3,\n         4.0]\nrate_hz: 20\nresolution: [752, 480]\nintrinsics: [458.654, 457.296] #fu, fv\n";
        let v = parse(text, Path::new("s.yaml")).unwrap();
        assert_eq!(
            v,
            json!({
                "sensor_type": "camera",
                "comment": "VI-Sensor cam0 (MT9M034)",
                "T_BS": {"cols": 4, "rows": 4, "data": [0.5, -1, 0.002, 4.0]},
                "rate_hz": 20,
                "resolution": [752, 480],
                "intrinsics": [458.654, 457.296],
            })
        );
    }

    #[test]
    fn parses_kalibr_block_sequences_and_nesting() {
        let text = "cam1:\n  T_cn_cnm1:\n  - [1.0, 0.0, 0.0, -0.11]\n  - [0.0, 1.0, 0.0, 0.0]\n  camera_model: pinhole\n  rostopic: '/cam1/image_raw'\nflag: true\n";
        let v = parse(text, Path::new("c.yaml")).unwrap();
        assert_eq!(
            v,
            json!({"cam1": {"T_cn_cnm1": [[1.0, 0.0, 0.0, -0.11], [0.0, 1.0, 0.0, 0.0]],
                   "camera_model": "pinhole", "rostopic": "/cam1/image_raw"}, "flag": true})
        );
    }

    /// OpenCV writes and reads `key:value` without a space (ORB-SLAM's settings files).
    #[test]
    fn opencv_compact_entries() {
        let text = "%YAML:1.0\nLEFT.D: !!opencv-matrix\n   rows: 1\n   cols: 2\n   data:[-0.28, 0.07]\nViewer.PointSize:2\nrostopic: /cam0:raw\nlist:\n- a:b\n";
        let v = parse(text, Path::new("s.yaml")).unwrap();
        assert_eq!(
            v,
            json!({
                "LEFT.D": {"rows": 1, "cols": 2, "data": [-0.28, 0.07]},
                "Viewer.PointSize": 2,
                "rostopic": "/cam0:raw",
                "list": ["a:b"],
            })
        );
    }

    #[test]
    fn errors_name_the_line() {
        for (text, line, what) in [
            ("a: 1\nb: [1, 2\n", 2, "unclosed"),
            ("a: 1\n   b: 2\n", 2, "indentation"),
            ("a: 1\njust text\n", 2, "key: value"),
            ("a: 1\na: 2\n", 2, "duplicate"),
            ("a: {x: 1}\n", 1, "unsupported"),
        ] {
            let e = parse(text, Path::new("cam.yaml")).unwrap_err().to_string();
            assert!(
                e.contains(&format!("cam.yaml:{line}")) && e.contains(what),
                "{text:?}: {e}"
            );
        }
    }
}
