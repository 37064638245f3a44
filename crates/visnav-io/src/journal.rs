//! The trajectory of a running odometry, one KITTI line appended and flushed per frame to
//! `<output>.partial`, so a killed run (SIGKILL, power loss) keeps every frame it finished;
//! [`PoseJournal::commit`] writes the final poses atomically onto the output
//! ([`crate::atomic::write_atomic`]) when the run completes.

use std::io::Write;
use std::path::{Path, PathBuf};

use visnav_core::Pose;

use crate::atomic::parent_dir;
use crate::error::{IoError, Result};

/// The trajectory of a running odometry, appended frame by frame (module docs).
#[derive(Debug)]
pub struct PoseJournal {
    output: PathBuf,
    partial: PathBuf,
    file: std::io::BufWriter<std::fs::File>,
    lines: usize,
}

impl PoseJournal {
    /// `<output>.partial` beside `output`.
    #[must_use]
    pub fn partial_path(output: &Path) -> PathBuf {
        let mut name = output.file_name().unwrap_or_default().to_os_string();
        name.push(".partial");
        output.with_file_name(name)
    }

    /// Starts a journal for `output` (truncating an older `<output>.partial`).
    ///
    /// # Errors
    /// The journal file cannot be created.
    pub fn create(output: &Path) -> Result<Self> {
        parent_dir(output)?;
        let partial = Self::partial_path(output);
        let file = std::fs::File::create(&partial).map_err(|e| IoError::io(&partial, e))?;
        Ok(Self {
            output: output.to_path_buf(),
            partial,
            file: std::io::BufWriter::new(file),
            lines: 0,
        })
    }

    /// Appends one pose (KITTI line) and flushes it to the file.
    ///
    /// # Errors
    /// The journal cannot be written.
    pub fn append(&mut self, world_from_cam: &Pose) -> Result<()> {
        let line = crate::trajectory::kitti_line(world_from_cam);
        self.file
            .write_all(line.as_bytes())
            .and_then(|()| self.file.flush())
            .map_err(|e| IoError::io(&self.partial, e))?;
        self.lines += 1;
        Ok(())
    }

    /// Poses written so far.
    #[must_use]
    pub fn len(&self) -> usize {
        self.lines
    }

    /// `true` before the first pose.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.lines == 0
    }

    /// Where the poses go while the run lasts.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.partial
    }

    /// Ends the run: the final poses (which may differ from the journal's, e.g. after loop
    /// closure) are written atomically to the output and the journal is removed.
    ///
    /// # Errors
    /// The output cannot be written (the journal is then kept).
    pub fn commit(self, poses: &[Pose]) -> Result<PathBuf> {
        drop(self.file);
        crate::trajectory::write_kitti(&self.output, poses)?;
        // the journal's frames are in the output now; a failure to remove it is harmless
        let _ = std::fs::remove_file(&self.partial);
        Ok(self.output)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_journal_keeps_every_appended_pose_until_commit() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("poses.txt");
        std::fs::write(&out, "previous\n").unwrap();
        let mut j = PoseJournal::create(&out).unwrap();
        let poses: Vec<Pose> = (0..3)
            .map(|i| {
                Pose::from_parts(
                    nalgebra::Translation3::new(f64::from(i), 0.0, 0.0),
                    nalgebra::UnitQuaternion::identity(),
                )
            })
            .collect();
        for p in &poses {
            j.append(p).unwrap();
        }
        // as if killed now: the journal holds 3 readable poses, the output is untouched
        let partial = PoseJournal::partial_path(&out);
        let read = crate::trajectory::read_kitti(&partial).unwrap();
        assert_eq!(read.len(), 3);
        assert_eq!(std::fs::read_to_string(&out).unwrap(), "previous\n");
        j.commit(&poses).unwrap();
        assert_eq!(crate::trajectory::read_kitti(&out).unwrap().len(), 3);
        assert!(!partial.exists());
    }
}
