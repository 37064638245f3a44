//! Frame prefetching: a small thread loads the frames of a [`Sequence`] ahead of the consumer
//! through a bounded channel, so PNG decoding overlaps with processing. Frames arrive in order
//! as `(index, Result<Frames, IoError>)`: a bad image is an error for that frame only.
//! Dropping the [`Prefetcher`] stops the thread.

use std::ops::Range;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use visnav_core::GrayImage;
use visnav_io::{IoError, Sequence};

/// The images of one frame.
#[derive(Debug, Clone)]
pub struct Frames {
    /// Left (reference) image.
    pub left: GrayImage,
    /// Right image, when stereo frames were requested and the sequence has them.
    pub right: Option<GrayImage>,
}

/// One prefetched frame: its index and its images or the error loading them.
pub type Prefetched = (usize, Result<Frames, IoError>);

fn load(seq: &Sequence, i: usize, stereo: bool) -> Result<Frames, IoError> {
    let left = seq.load_left(i)?;
    let right = if stereo && seq.has_stereo() {
        Some(seq.load_right(i)?)
    } else {
        None
    };
    Ok(Frames { left, right })
}

enum Source {
    Thread {
        rx: Receiver<Prefetched>,
        handle: Option<JoinHandle<()>>,
    },
    /// Fallback when no thread can be spawned: frames are loaded on `next()`.
    Inline {
        seq: Box<Sequence>,
        next: usize,
        end: usize,
        stereo: bool,
    },
}

/// An iterator over the frames `range` of a sequence, loaded up to `depth` frames ahead on a
/// background thread.
pub struct Prefetcher {
    source: Source,
}

impl Prefetcher {
    /// Starts loading frames `range` (clamped to the sequence) of `seq`; right images too when
    /// `stereo` and the sequence has them. `depth` is the number of frames loaded ahead (at
    /// least 1).
    #[must_use]
    pub fn new(seq: &Sequence, range: Range<usize>, stereo: bool, depth: usize) -> Self {
        let end = range.end.min(seq.len());
        let start = range.start.min(end);
        let (tx, rx): (SyncSender<Prefetched>, Receiver<Prefetched>) = sync_channel(depth.max(1));
        let worker_seq = seq.clone();
        let spawned = std::thread::Builder::new()
            .name("visnav-prefetch".into())
            .spawn(move || {
                for i in start..end {
                    let item = (i, load(&worker_seq, i, stereo));
                    if tx.send(item).is_err() {
                        break; // the consumer is gone
                    }
                }
            });
        let source = match spawned {
            Ok(handle) => Source::Thread {
                rx,
                handle: Some(handle),
            },
            Err(e) => {
                log::warn!("cannot start the prefetch thread ({e}); loading frames inline");
                Source::Inline {
                    seq: Box::new(seq.clone()),
                    next: start,
                    end,
                    stereo,
                }
            }
        };
        Self { source }
    }
}

impl Iterator for Prefetcher {
    type Item = Prefetched;

    fn next(&mut self) -> Option<Prefetched> {
        match &mut self.source {
            Source::Thread { rx, .. } => rx.recv().ok(),
            Source::Inline {
                seq,
                next,
                end,
                stereo,
            } => {
                if *next >= *end {
                    return None;
                }
                let i = *next;
                *next += 1;
                Some((i, load(seq, i, *stereo)))
            }
        }
    }
}

impl Drop for Prefetcher {
    fn drop(&mut self) {
        if let Source::Thread { rx, handle } = &mut self.source {
            // close the channel first so that a blocked `send` returns, then wait for the thread
            let (_, dead_rx) = sync_channel(1);
            drop(std::mem::replace(rx, dead_rx));
            if let Some(h) = handle.take()
                && h.join().is_err()
            {
                log::error!("the prefetch thread panicked");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use visnav_io::image_io::save_gray_png;

    fn make_seq(dir: &std::path::Path, n: usize) {
        for cam in ["image_0", "image_1"] {
            std::fs::create_dir_all(dir.join(cam)).unwrap();
            for i in 0..n {
                let img = GrayImage::from_fn(8, 4, |x, y| (x + y + i) as f32);
                save_gray_png(&img, &dir.join(cam).join(format!("{i:06}.png"))).unwrap();
            }
        }
        std::fs::write(
            dir.join("calib.txt"),
            "P0: 700 0 4 0 0 700 2 0 0 0 1 0\nP1: 700 0 4 -350 0 700 2 0 0 0 1 0\n",
        )
        .unwrap();
    }

    #[test]
    fn frames_arrive_in_order_and_a_bad_frame_is_an_error_for_that_frame_only() {
        let dir = tempfile::tempdir().unwrap();
        make_seq(dir.path(), 12);
        std::fs::write(dir.path().join("image_1/000005.png"), b"garbage").unwrap();
        let seq = Sequence::open(dir.path()).unwrap();
        let got: Vec<Prefetched> = Prefetcher::new(&seq, 2..100, true, 3).collect();
        assert_eq!(got.len(), 10);
        for (k, (i, r)) in got.iter().enumerate() {
            assert_eq!(*i, k + 2);
            if *i == 5 {
                let e = r.as_ref().unwrap_err().to_string();
                assert!(e.contains("000005.png"), "{e}");
            } else {
                let f = r.as_ref().unwrap();
                assert_eq!(f.left.get(0, 0), *i as f32);
                assert!(f.right.is_some());
            }
        }
        // mono request: no right images
        let mono: Vec<Prefetched> = Prefetcher::new(&seq, 0..2, false, 1).collect();
        assert!(
            mono.iter()
                .all(|(_, r)| r.as_ref().unwrap().right.is_none())
        );
    }

    #[test]
    fn dropping_early_stops_the_thread() {
        let dir = tempfile::tempdir().unwrap();
        make_seq(dir.path(), 20);
        let seq = Sequence::open(dir.path()).unwrap();
        let mut p = Prefetcher::new(&seq, 0..20, true, 1);
        assert_eq!(p.next().unwrap().0, 0);
        drop(p); // must not hang on the blocked sender
        // an empty or out-of-range request yields nothing
        let (start, end) = (5, 3);
        assert_eq!(Prefetcher::new(&seq, start..end, true, 2).count(), 0);
        assert_eq!(Prefetcher::new(&seq, 30..40, true, 2).count(), 0);
    }
}
