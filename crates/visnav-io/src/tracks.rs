//! Stereo feature tracks as CSV (`NNNNNN.tracks.csv`, written by `visnav odometry --save-tracks`,
//! read by `visnav report`): one row per track, [`TRACKS_CSV_HEADER`].

use std::fmt::Write as _;
use std::path::Path;

use crate::error::{IoError, Result};

/// Header of a tracks file.
pub const TRACKS_CSV_HEADER: &str = "prev_u,prev_v,u,v,depth_m,inlier";

/// One track: previous and current left pixel, depth in metres, inlier flag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackRow {
    /// Pixel in the previous left image.
    pub prev_px: [f64; 2],
    /// Pixel in the current left image.
    pub cur_px: [f64; 2],
    /// Depth of the point, metres.
    pub depth_m: f64,
    /// Whether the estimation kept it.
    pub inlier: bool,
}

/// Writes `rows` to `path` atomically.
///
/// # Errors
/// The file cannot be written.
pub fn write_tracks_csv(path: &Path, rows: &[TrackRow]) -> Result<()> {
    let mut text = String::with_capacity(48 * (rows.len() + 1));
    text.push_str(TRACKS_CSV_HEADER);
    text.push('\n');
    for t in rows {
        let _ = writeln!(
            text,
            "{:.3},{:.3},{:.3},{:.3},{:.4},{}",
            t.prev_px[0],
            t.prev_px[1],
            t.cur_px[0],
            t.cur_px[1],
            t.depth_m,
            u8::from(t.inlier)
        );
    }
    crate::atomic::write_atomic(path, text.as_bytes())
}

/// Reads a tracks file; errors name the file and the line.
///
/// # Errors
/// [`IoError::Parse`] for a line that is not six finite numbers with an inlier flag of 0 or 1.
pub fn read_tracks_csv(path: &Path) -> Result<Vec<TrackRow>> {
    let text = crate::text::read_text(path)?;
    let mut rows = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || (k == 0 && line.starts_with("prev_u")) {
            continue;
        }
        let numbers: Option<Vec<f64>> = line.split(',').map(|f| f.trim().parse().ok()).collect();
        match numbers.as_deref() {
            Some(&[pu, pv, u, v, z, inlier])
                if [pu, pv, u, v, z].iter().all(|x| x.is_finite())
                    && (inlier == 0.0 || inlier == 1.0) =>
            {
                rows.push(TrackRow {
                    prev_px: [pu, pv],
                    cur_px: [u, v],
                    depth_m: z,
                    inlier: inlier == 1.0,
                });
            }
            _ => {
                return Err(IoError::Parse {
                    path: path.to_path_buf(),
                    line: k + 1,
                    message: format!(
                        "expected `{TRACKS_CSV_HEADER}` (finite numbers, inlier 0 or 1), got `{line}`"
                    ),
                });
            }
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tracks_round_trip_and_a_bad_line_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("000001.tracks.csv");
        let rows = vec![TrackRow {
            prev_px: [1.5, 2.25],
            cur_px: [3.0, 4.0],
            depth_m: 12.5,
            inlier: true,
        }];
        write_tracks_csv(&p, &rows).unwrap();
        assert_eq!(read_tracks_csv(&p).unwrap(), rows);
        std::fs::write(&p, "prev_u,prev_v,u,v,depth_m,inlier\n1,2,3,4,5,2\n").unwrap();
        let e = read_tracks_csv(&p).unwrap_err().to_string();
        assert!(e.contains(":2:"), "{e}");
    }
}
