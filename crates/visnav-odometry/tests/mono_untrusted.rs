//! Frames the monocular pipeline cannot trust (issue 21 item 3), on the real KITTI 00 clip: a
//! black, a white, a noise and an upside-down frame and two frames of another place are inserted
//! between real frames. The test
//! drives `MonoFlow` + `MonoOdometry` frame by frame as a driver would: a rejected frame
//! (`MonoError::UntrustedFrame`) is skipped and the next frame's flow is computed from the last
//! accepted image. Every corrupted frame must be rejected, no real frame may be, and the real
//! frames' poses must stay within a bound of the ground truth that the same stream with the
//! trust tests off violates.
#![allow(clippy::unwrap_used)]

use std::collections::HashMap;

use visnav_core::{GrayImage, Pose};
use visnav_io::Sequence;
use visnav_io::trajectory::read_kitti;
use visnav_odometry::mono::trust::Thumbnail;
use visnav_odometry::mono::{
    MonoConfig, MonoError, MonoFlow, MonoFlowConfig, MonoOdometry, TrustConfig, UntrustedReason,
};

/// Real frames of the clip used.
const FRAMES: usize = 28;

/// Bound on the rotation error of every real frame against the ground truth, degrees.
const MAX_ROTATION_ERROR_DEG: f64 = 2.5;
/// Bound on the position error of every real frame against the ground truth, metres.
const MAX_POSITION_ERROR_M: f64 = 2.0;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Corruption {
    Black,
    White,
    Noise,
    Flipped,
    /// A real frame of another place (150 frames, about 110 m, later): a sudden global change.
    Foreign,
}

/// A frame of the stream: a real frame (index into the clip) or a corrupted one.
#[derive(Clone, Copy, Debug)]
enum Frame {
    Real(usize),
    Corrupted(Corruption, usize),
}

fn corrupt(kind: Corruption, real: &GrayImage) -> GrayImage {
    let (w, h) = (real.width(), real.height());
    match kind {
        Corruption::Black => GrayImage::from_fn(w, h, |_, _| 0.0),
        Corruption::White => GrayImage::from_fn(w, h, |_, _| 255.0),
        Corruption::Noise => {
            let mut state = 0x2545_F491_4F6C_DD1D_u64;
            GrayImage::from_fn(w, h, |_, _| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state % 256) as f32
            })
        }
        Corruption::Flipped => GrayImage::from_fn(w, h, |x, y| real.get(x, h - 1 - y)),
        Corruption::Foreign => real.clone(),
    }
}

/// The stream: the real frames with a corrupted frame inserted after frames 6, 9, 12, 18, 20
/// and 24 (the flipped one is the preceding real frame upside down, the foreign ones frames
/// 159 and 170).
fn stream() -> Vec<Frame> {
    let inserts = [
        (6, Corruption::Black),
        (12, Corruption::White),
        (18, Corruption::Noise),
        (24, Corruption::Flipped),
        (9, Corruption::Foreign),
        (20, Corruption::Foreign),
    ];
    let mut out = Vec::new();
    for k in 0..FRAMES {
        out.push(Frame::Real(k));
        if let Some((_, c)) = inserts.iter().find(|(at, _)| *at == k) {
            out.push(Frame::Corrupted(*c, k));
        }
    }
    out
}

struct Outcome {
    /// Per corrupted frame: the reason it was rejected (None: accepted).
    corrupted: Vec<(Corruption, Option<UntrustedReason>)>,
    /// Real frames rejected.
    real_rejected: Vec<usize>,
    /// Per accepted real frame: its index and `world_from_cam`.
    poses: Vec<(usize, Pose)>,
    /// Worst rotation error over the real frames, degrees, and the frame.
    max_rotation_error_deg: (f64, usize),
    /// Worst position error over the real frames, metres, and the frame.
    max_position_error_m: (f64, usize),
}

struct Clip {
    seq: Sequence,
    gt: Vec<Pose>,
    flow: MonoFlow,
    /// Flows of (previous, current) stream positions already computed.
    cache: HashMap<(String, String), visnav_flow::DenseFlow>,
}

fn key(f: Frame) -> String {
    format!("{f:?}")
}

impl Clip {
    fn open() -> Option<Self> {
        let root = visnav_core::testdata::shared_data("kitti/odometry/sequences/00")?;
        let poses = visnav_core::testdata::shared_data("kitti/odometry/poses/00.txt")?;
        let seq = Sequence::open(&root).unwrap();
        let gt = read_kitti(&poses).unwrap()[..FRAMES].to_vec();
        let flow = MonoFlow::new(&MonoFlowConfig::default()).unwrap();
        Some(Self {
            seq,
            gt,
            flow,
            cache: HashMap::new(),
        })
    }

    fn image(&self, f: Frame) -> GrayImage {
        match f {
            Frame::Real(k) => self.seq.load_left(k).unwrap(),
            Frame::Corrupted(Corruption::Foreign, k) => self.seq.load_left(k + 150).unwrap(),
            Frame::Corrupted(c, k) => corrupt(c, &self.seq.load_left(k).unwrap()),
        }
    }

    /// Drives the odometry over `frames` as a driver does; `trust` switches the tests.
    fn run(&mut self, frames: &[Frame], trust: bool) -> Outcome {
        let mut cfg = MonoConfig::default();
        cfg.trust.enabled = trust;
        let mut vo = MonoOdometry::new(self.seq.camera, cfg).unwrap();
        // the constant-velocity prior, kept by the driver
        let mut prior = None;
        let mut last: Option<(Frame, GrayImage)> = None;
        let mut corrupted = Vec::new();
        let mut real_rejected = Vec::new();
        let mut rot = (0.0_f64, 0);
        let mut pos = (0.0_f64, 0);
        let mut poses = Vec::new();
        for &f in frames {
            let img = self.image(f);
            let flow = last.as_ref().map(|(lf, limg)| {
                self.cache
                    .entry((key(*lf), key(f)))
                    .or_insert_with(|| self.flow.compute_timed(limg, &img).unwrap().0)
                    .clone()
            });
            let result = vo.process(&img, flow.as_ref(), prior.as_ref());
            if let Ok(r) = &result {
                prior = r.motion.or(prior);
            }
            let rejected = match &result {
                Ok(_) => None,
                Err(MonoError::UntrustedFrame { reason }) => Some(*reason),
                Err(e) => panic!("{e}"),
            };
            match f {
                Frame::Corrupted(c, _) => corrupted.push((c, rejected)),
                Frame::Real(k) => {
                    if rejected.is_some() {
                        real_rejected.push(k);
                    }
                    if let Ok(r) = &result {
                        poses.push((k, r.world_from_cam));
                        let truth = self.gt[0].inverse() * self.gt[k];
                        let err = truth.inverse() * r.world_from_cam;
                        let dr = err.rotation.angle().to_degrees();
                        let dp =
                            (truth.translation.vector - r.world_from_cam.translation.vector).norm();
                        if dr > rot.0 {
                            rot = (dr, k);
                        }
                        if dp > pos.0 {
                            pos = (dp, k);
                        }
                    }
                }
            }
            if rejected.is_none() {
                last = Some((f, img));
            }
        }
        Outcome {
            corrupted,
            real_rejected,
            poses,
            max_rotation_error_deg: rot,
            max_position_error_m: pos,
        }
    }
}

#[test]
fn corrupted_frames_in_kitti_00_are_rejected_and_the_poses_stay_on_the_ground_truth() {
    let Some(mut clip) = Clip::open() else {
        eprintln!("VISNAV_DATA not set: skipped");
        return;
    };
    let frames = stream();
    let clean: Vec<Frame> = (0..FRAMES).map(Frame::Real).collect();
    let reference = clip.run(&clean, true);
    let trusted = clip.run(&frames, true);
    let untrusted = clip.run(&frames, false);
    for (name, o) in [
        ("clean clip", &reference),
        ("corrupted, trust tests on", &trusted),
        ("corrupted, trust tests off", &untrusted),
    ] {
        eprintln!(
            "{name}: max rotation error {:.3}° (frame {}), max position error {:.3} m (frame {}); corrupted frames {:?}; real frames rejected {:?}",
            o.max_rotation_error_deg.0,
            o.max_rotation_error_deg.1,
            o.max_position_error_m.0,
            o.max_position_error_m.1,
            o.corrupted,
            o.real_rejected
        );
    }
    // no real frame is rejected, with or without corrupted frames around it
    assert!(reference.real_rejected.is_empty());
    assert!(trusted.real_rejected.is_empty());
    // every corrupted frame is rejected, by the test meant for it
    assert_eq!(trusted.corrupted.len(), 6);
    for (c, reason) in &trusted.corrupted {
        let reason = reason.unwrap_or_else(|| panic!("{c:?} frame accepted"));
        match c {
            Corruption::Black | Corruption::White => {
                assert!(
                    matches!(reason, UntrustedReason::NoTexture { .. }),
                    "{reason}"
                );
            }
            Corruption::Noise => {
                assert!(
                    matches!(reason, UntrustedReason::NoiseLike { .. }),
                    "{reason}"
                );
            }
            Corruption::Flipped => {
                assert!(
                    matches!(reason, UntrustedReason::UpsideDown { .. }),
                    "{reason}"
                );
            }
            Corruption::Foreign => {
                assert!(
                    matches!(reason, UntrustedReason::NoRigidMotion { .. }),
                    "{reason}"
                );
            }
        }
    }
    // a rejected frame is as if never seen: the real frames' poses are those of the clean clip,
    // bit for bit (the next flow starts from the same last accepted image)
    assert_eq!(trusted.poses, reference.poses);
    // the poses stay within the bound with the corrupted frames rejected ...
    for o in [&reference, &trusted] {
        assert!(o.max_rotation_error_deg.0 < MAX_ROTATION_ERROR_DEG);
        assert!(o.max_position_error_m.0 < MAX_POSITION_ERROR_M);
    }
    // ... and leave it with them accepted
    assert!(untrusted.corrupted.iter().all(|(_, r)| r.is_none()));
    assert!(
        untrusted.max_rotation_error_deg.0 >= MAX_ROTATION_ERROR_DEG
            || untrusted.max_position_error_m.0 >= MAX_POSITION_ERROR_M
    );
}

/// The image tests' margins over the whole 300-frame clip (PNG decoding only, no flow): the
/// thumbnail contrast and structure ratio of every real frame and of noise; the flip gain of
/// each real frame against the previous one and the one before (a frame after a rejected one),
/// and of its upside-down copy.
#[test]
fn image_test_margins_over_the_kitti_00_clip() {
    let Some(root) = visnav_core::testdata::shared_data("kitti/odometry/sequences/00") else {
        eprintln!("VISNAV_DATA not set: skipped");
        return;
    };
    let seq = Sequence::open(&root).unwrap();
    let cfg = TrustConfig::default();
    let images: Vec<GrayImage> = (0..seq.len()).map(|k| seq.load_left(k).unwrap()).collect();
    assert!(images.len() >= 300);
    let thumbs: Vec<Thumbnail> = images.iter().map(|i| Thumbnail::of(i, &cfg)).collect();
    let min_std = thumbs
        .iter()
        .map(Thumbnail::std)
        .fold(f64::INFINITY, f64::min);
    let min_ratio = thumbs
        .iter()
        .map(Thumbnail::structure_ratio)
        .fold(f64::INFINITY, f64::min);
    let noise = Thumbnail::of(&corrupt(Corruption::Noise, &images[0]), &cfg);
    // upside down: how much better the frame correlates with the previous one when flipped
    let flip = |cur: &Thumbnail, last: &Thumbnail| {
        let flipped = cur.flipped().correlation(last);
        (flipped, flipped - cur.correlation(last))
    };
    let real_gain = (1..thumbs.len())
        .flat_map(|k| [(k, 1), (k, 2)])
        .filter(|(k, g)| k >= g)
        .map(|(k, g)| flip(&thumbs[k], &thumbs[k - g]).1)
        .fold(f64::NEG_INFINITY, f64::max);
    let (flipped_correlation, flipped_gain) = (1..images.len())
        .flat_map(|k| [(k, k), (k, k - 1)])
        .map(|(f, l)| {
            let t = Thumbnail::of(&corrupt(Corruption::Flipped, &images[f]), &cfg);
            flip(&t, &thumbs[l])
        })
        .fold((f64::INFINITY, f64::INFINITY), |(a, b), (c, d)| {
            (a.min(c), b.min(d))
        });
    // what a plain correlation with the previous frame would have had to separate
    let plain_flipped = (0..images.len())
        .map(|k| {
            Thumbnail::of(&corrupt(Corruption::Flipped, &images[k]), &cfg).correlation(&thumbs[k])
        })
        .fold(f64::NEG_INFINITY, f64::max);
    eprintln!(
        "{} frames: thumbnail std >= {min_std:.1} (noise-free flat: 0), structure ratio >= {min_ratio:.3} (noise {:.3}); flip gain of the real frames <= {real_gain:.3}, of the flipped ones >= {flipped_gain:.3} with flipped correlation >= {flipped_correlation:.3}; plain correlation of a flipped frame with its original up to {plain_flipped:.3}",
        thumbs.len(),
        noise.structure_ratio()
    );
    assert!(min_std > 5.0 * cfg.min_intensity_std);
    assert!(min_ratio > 2.0 * cfg.min_structure_ratio);
    assert!(noise.structure_ratio() < 0.5 * cfg.min_structure_ratio);
    assert!(real_gain < cfg.max_flip_gain);
    assert!(flipped_gain > cfg.max_flip_gain && flipped_correlation > cfg.min_flipped_correlation);
}
