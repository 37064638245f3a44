//! Frame sources: one trait for "a sequence of timestamped frames", whatever the input layout.
//!
//! * [`FrameSource`]: random access to the frames of a stream by their position in it
//!   (`0..len()`), each with its frame index in the underlying data and its timestamp.
//!   Implemented by [`Sequence`] (every on-disk layout: KITTI odometry and raw, EuRoC, TUM RGB-D,
//!   TUM monoVO, image folders, video) and by [`InMemorySource`] (images a program already holds).
//! * [`Palindrome`]: a source adaptor that plays `0..N` forward then back (`2N − 1` positions,
//!   the drift test of §6.2 of the monocular paper).
//! * [`Prefetch`]: a wrapper that loads the next frames on one background thread through a
//!   bounded channel (decoding overlaps with processing) and yields [`SourceItem`]s in order.
//!
//! A missing or unreadable frame is an explicit item of the stream: [`SourceItem::frame`] is an
//! `Err` naming the file and the problem, never an empty image.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;
use std::time::Instant;

use visnav_core::GrayImage;

use crate::{IoError, Sequence};

/// The images of one frame.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Left (or only) image.
    pub left: GrayImage,
    /// Right image of a stereo pair, when asked for and present.
    pub right: Option<GrayImage>,
}

/// One item of a stream: where it is, and its images or why they could not be read.
#[derive(Debug)]
pub struct SourceItem {
    /// Position in the stream (`0..len()`).
    pub position: usize,
    /// Frame index in the underlying data (differs from `position` on the way back of a
    /// [`Palindrome`]).
    pub index: usize,
    /// Timestamp, seconds, when the data has one.
    pub timestamp_s: Option<f64>,
    /// The images, or the error that made them unreadable (a recoverable skip).
    pub frame: Result<Frame, IoError>,
    /// When the frame arrived: a live frame's last byte out of the decoder, a recorded
    /// frame's end of loading (the latency of its pose is measured from here).
    pub received: Instant,
    /// Frames of a live stream dropped just before this one by the frame policy
    /// (`crate::live::FramePolicy::Newest`); 0 for recordings.
    pub dropped_before: usize,
}

/// A sequence of timestamped frames with random access by position.
pub trait FrameSource: Send + Sync {
    /// Number of positions in the stream.
    fn len(&self) -> usize;

    /// `true` when the stream has no frames.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Frame index in the underlying data of `position` (identity unless an adaptor reorders).
    fn index_of(&self, position: usize) -> usize {
        position
    }

    /// Timestamp of `position`, seconds, when the data has timestamps.
    fn timestamp_s(&self, position: usize) -> Option<f64>;

    /// Whether the frames have a right image.
    fn has_stereo(&self) -> bool;

    /// The images of `position` (the right one too when `stereo` and the source has them).
    ///
    /// # Errors
    /// The [`IoError`] of an unreadable or missing frame (named file and problem).
    fn load(&self, position: usize, stereo: bool) -> Result<Frame, IoError>;

    /// The whole item of `position`: its index, timestamp and images or error.
    fn item(&self, position: usize, stereo: bool) -> SourceItem {
        let frame = self.load(position, stereo);
        SourceItem {
            position,
            index: self.index_of(position),
            timestamp_s: self.timestamp_s(position),
            frame,
            received: Instant::now(),
            dropped_before: 0,
        }
    }
}

impl FrameSource for Sequence {
    fn len(&self) -> usize {
        Sequence::len(self)
    }

    fn timestamp_s(&self, position: usize) -> Option<f64> {
        if self.timestamped {
            self.timestamps.get(position).copied()
        } else {
            None
        }
    }

    fn has_stereo(&self) -> bool {
        Sequence::has_stereo(self)
    }

    fn load(&self, position: usize, stereo: bool) -> Result<Frame, IoError> {
        let left = self.load_left(position)?;
        let right = if stereo && Sequence::has_stereo(self) {
            Some(self.load_right(position)?)
        } else {
            None
        };
        Ok(Frame { left, right })
    }
}

impl<S: FrameSource + ?Sized> FrameSource for Arc<S> {
    fn len(&self) -> usize {
        (**self).len()
    }
    fn index_of(&self, position: usize) -> usize {
        (**self).index_of(position)
    }
    fn timestamp_s(&self, position: usize) -> Option<f64> {
        (**self).timestamp_s(position)
    }
    fn has_stereo(&self) -> bool {
        (**self).has_stereo()
    }
    fn load(&self, position: usize, stereo: bool) -> Result<Frame, IoError> {
        (**self).load(position, stereo)
    }
}

/// Frames held in memory (a program's own images, a rendered sequence).
#[derive(Debug, Clone, Default)]
pub struct InMemorySource {
    frames: Vec<Frame>,
    timestamps_s: Option<Vec<f64>>,
}

impl InMemorySource {
    /// Monocular frames.
    #[must_use]
    pub fn mono(images: Vec<GrayImage>) -> Self {
        Self {
            frames: images
                .into_iter()
                .map(|left| Frame { left, right: None })
                .collect(),
            timestamps_s: None,
        }
    }

    /// Stereo frames (left, right).
    #[must_use]
    pub fn stereo(pairs: Vec<(GrayImage, GrayImage)>) -> Self {
        Self {
            frames: pairs
                .into_iter()
                .map(|(left, right)| Frame {
                    left,
                    right: Some(right),
                })
                .collect(),
            timestamps_s: None,
        }
    }

    /// The same frames with timestamps, seconds (one per frame).
    ///
    /// # Errors
    /// [`IoError::Format`] when the count differs from the frame count.
    pub fn with_timestamps(mut self, timestamps_s: Vec<f64>) -> Result<Self, IoError> {
        if timestamps_s.len() != self.frames.len() {
            return Err(IoError::Format {
                path: "<memory>".into(),
                message: format!(
                    "{} timestamps for {} frames",
                    timestamps_s.len(),
                    self.frames.len()
                ),
            });
        }
        self.timestamps_s = Some(timestamps_s);
        Ok(self)
    }
}

impl FrameSource for InMemorySource {
    fn len(&self) -> usize {
        self.frames.len()
    }

    fn timestamp_s(&self, position: usize) -> Option<f64> {
        self.timestamps_s.as_ref()?.get(position).copied()
    }

    fn has_stereo(&self) -> bool {
        self.frames.first().is_some_and(|f| f.right.is_some())
    }

    fn load(&self, position: usize, stereo: bool) -> Result<Frame, IoError> {
        let f = self.frames.get(position).ok_or_else(|| IoError::NotFound {
            path: "<memory>".into(),
            what: format!("frame {position} of {}", self.frames.len()),
        })?;
        Ok(Frame {
            left: f.left.clone(),
            right: if stereo { f.right.clone() } else { None },
        })
    }
}

/// The palindrome order of `n` frames: `0, 1, …, n−1, n−2, …, 0` (`2n − 1` positions).
#[must_use]
pub fn palindrome_order(n: usize) -> Vec<usize> {
    (0..n).chain((0..n.saturating_sub(1)).rev()).collect()
}

/// A source played forward then back (§6.2 of the monocular paper: the drift test). Timestamps
/// of the way back continue forward by the mirrored intervals, so they stay increasing.
#[derive(Debug, Clone)]
pub struct Palindrome<S> {
    inner: S,
    order: Vec<usize>,
}

impl<S: FrameSource> Palindrome<S> {
    /// The first `frames` frames of `inner` (all when `None`), forward then back.
    pub fn new(inner: S, frames: Option<usize>) -> Self {
        let n = frames.map_or(inner.len(), |f| f.min(inner.len()));
        Self {
            order: palindrome_order(n),
            inner,
        }
    }

    /// The wrapped source.
    pub fn inner(&self) -> &S {
        &self.inner
    }
}

impl<S: FrameSource> FrameSource for Palindrome<S> {
    fn len(&self) -> usize {
        self.order.len()
    }

    fn index_of(&self, position: usize) -> usize {
        self.order
            .get(position)
            .map_or(position, |&i| self.inner.index_of(i))
    }

    fn timestamp_s(&self, position: usize) -> Option<f64> {
        let n = self.order.len().div_ceil(2);
        if position < n {
            return self.inner.timestamp_s(position);
        }
        // mirrored: t(n-1) + (t(n-1) - t(2(n-1) - position))
        let last = self.inner.timestamp_s(n.checked_sub(1)?)?;
        let mirror = self.inner.timestamp_s(*self.order.get(position)?)?;
        Some(2.0 * last - mirror)
    }

    fn has_stereo(&self) -> bool {
        self.inner.has_stereo()
    }

    fn load(&self, position: usize, stereo: bool) -> Result<Frame, IoError> {
        let i = *self.order.get(position).ok_or_else(|| IoError::NotFound {
            path: "<palindrome>".into(),
            what: format!("position {position} of {}", self.order.len()),
        })?;
        self.inner.load(i, stereo)
    }
}

/// A source truncated to its first `n` positions.
#[derive(Debug, Clone)]
pub struct Take<S> {
    inner: S,
    n: usize,
}

impl<S: FrameSource> Take<S> {
    /// The first `n` positions of `inner` (fewer when it is shorter).
    pub fn new(inner: S, n: usize) -> Self {
        let n = n.min(inner.len());
        Self { inner, n }
    }
}

impl<S: FrameSource> FrameSource for Take<S> {
    fn len(&self) -> usize {
        self.n
    }
    fn index_of(&self, position: usize) -> usize {
        self.inner.index_of(position)
    }
    fn timestamp_s(&self, position: usize) -> Option<f64> {
        (position < self.n)
            .then(|| self.inner.timestamp_s(position))
            .flatten()
    }
    fn has_stereo(&self) -> bool {
        self.inner.has_stereo()
    }
    fn load(&self, position: usize, stereo: bool) -> Result<Frame, IoError> {
        if position >= self.n {
            return Err(IoError::NotFound {
                path: "<source>".into(),
                what: format!("position {position} of {}", self.n),
            });
        }
        self.inner.load(position, stereo)
    }
}

/// Loads the items of a source in order, `depth` items ahead on one background thread (bounded
/// channel: memory does not grow with the stream). Dropping it stops the thread. When no thread
/// can be spawned, items are loaded on `next()` instead.
pub struct Prefetch {
    rx: Option<Receiver<SourceItem>>,
    handle: Option<JoinHandle<()>>,
    inline: Option<(Arc<dyn FrameSource>, usize)>,
    end: usize,
    stereo: bool,
}

impl Prefetch {
    /// Starts loading positions `0..len()` of `source` (right images too when `stereo`).
    #[must_use]
    pub fn new(source: Arc<dyn FrameSource>, stereo: bool, depth: usize) -> Self {
        let end = source.len();
        let (tx, rx): (SyncSender<SourceItem>, Receiver<SourceItem>) = sync_channel(depth.max(1));
        let worker = Arc::clone(&source);
        let spawned = std::thread::Builder::new()
            .name("visnav-prefetch".into())
            .spawn(move || {
                for p in 0..end {
                    if tx.send(worker.item(p, stereo)).is_err() {
                        break; // the consumer is gone
                    }
                }
            });
        match spawned {
            Ok(handle) => Self {
                rx: Some(rx),
                handle: Some(handle),
                inline: None,
                end,
                stereo,
            },
            Err(e) => {
                log::warn!("cannot start the prefetch thread ({e}); loading frames inline");
                Self {
                    rx: None,
                    handle: None,
                    inline: Some((source, 0)),
                    end,
                    stereo,
                }
            }
        }
    }
}

impl Iterator for Prefetch {
    type Item = SourceItem;

    fn next(&mut self) -> Option<SourceItem> {
        if let Some(rx) = &self.rx {
            return rx.recv().ok();
        }
        let (source, next) = self.inline.as_mut()?;
        if *next >= self.end {
            return None;
        }
        let p = *next;
        *next += 1;
        Some(source.item(p, self.stereo))
    }
}

impl Drop for Prefetch {
    fn drop(&mut self) {
        // close the channel first so that a blocked `send` returns, then wait for the thread
        drop(self.rx.take());
        if let Some(h) = self.handle.take()
            && h.join().is_err()
        {
            log::error!("the prefetch thread panicked");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image_io::save_gray_png;

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
    fn items_arrive_in_order_and_a_bad_frame_is_an_explicit_item() {
        let dir = tempfile::tempdir().unwrap();
        make_seq(dir.path(), 12);
        std::fs::write(dir.path().join("image_1/000005.png"), b"garbage").unwrap();
        let seq = Sequence::open(dir.path()).unwrap();
        let got: Vec<SourceItem> = Prefetch::new(Arc::new(seq.clone()), true, 3).collect();
        assert_eq!(got.len(), 12);
        for (k, item) in got.iter().enumerate() {
            assert_eq!(item.position, k);
            assert_eq!(item.index, k);
            if k == 5 {
                let e = item.frame.as_ref().unwrap_err().to_string();
                assert!(e.contains("000005.png"), "{e}");
            } else {
                let f = item.frame.as_ref().unwrap();
                assert_eq!(f.left.get(0, 0), k as f32);
                assert!(f.right.is_some());
            }
        }
        // mono request: no right images
        let mono: Vec<SourceItem> = Prefetch::new(Arc::new(Take::new(seq, 2)), false, 1).collect();
        assert_eq!(mono.len(), 2);
        assert!(
            mono.iter()
                .all(|i| i.frame.as_ref().unwrap().right.is_none())
        );
    }

    #[test]
    fn dropping_early_stops_the_thread() {
        let dir = tempfile::tempdir().unwrap();
        make_seq(dir.path(), 30);
        let seq = Sequence::open(dir.path()).unwrap();
        let mut p = Prefetch::new(Arc::new(seq), true, 1);
        assert!(p.next().is_some());
        drop(p); // must not hang
    }

    #[test]
    fn palindrome_plays_forward_then_back_with_increasing_timestamps() {
        let images: Vec<GrayImage> = (0..4)
            .map(|i| GrayImage::from_fn(2, 2, move |_, _| i as f32))
            .collect();
        let src = InMemorySource::mono(images)
            .with_timestamps(vec![0.0, 0.1, 0.3, 0.6])
            .unwrap();
        let p = Palindrome::new(src, None);
        assert_eq!(p.len(), 7);
        let idx: Vec<usize> = (0..7).map(|k| p.index_of(k)).collect();
        assert_eq!(idx, [0, 1, 2, 3, 2, 1, 0]);
        assert_eq!(palindrome_order(1), [0]);
        assert!(palindrome_order(0).is_empty());
        let values: Vec<f32> = (0..7)
            .map(|k| p.load(k, false).unwrap().left.get(0, 0))
            .collect();
        assert_eq!(values, [0.0, 1.0, 2.0, 3.0, 2.0, 1.0, 0.0]);
        let ts: Vec<f64> = (0..7).map(|k| p.timestamp_s(k).unwrap()).collect();
        for w in ts.windows(2) {
            assert!(w[1] > w[0], "{ts:?}");
        }
        assert!((ts[6] - 1.2).abs() < 1e-12);
        assert!(p.load(7, false).is_err());
    }

    #[test]
    fn in_memory_source_rejects_a_timestamp_count_mismatch() {
        let src = InMemorySource::mono(vec![GrayImage::new(2, 2, 0.0)]);
        assert!(src.with_timestamps(vec![0.0, 1.0]).is_err());
    }
}
