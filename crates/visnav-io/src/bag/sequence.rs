//! A [`Sequence`] of the image topic(s) of a bag.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion};
use visnav_core::{CalibratedCamera, Distortion, GrayImage, PinholeCamera, Pose};

use super::mcap_file::MessageRef;
use super::msgs::{self, CameraInfo};
use super::recording::{Bag, MessageMeta};
use crate::calibration::{Rectifier, RigCalibration, read_camera_file};
use crate::error::{IoError, Result};
use crate::sequence::{DecodedFrames, Sequence, SequenceLayout};

/// How to read a bag as a sequence.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BagOptions {
    /// The (left) image topic; `None`: the bag's only image topic.
    pub topic: Option<String>,
    /// The right image topic of a stereo pair.
    pub right_topic: Option<String>,
    /// A camera file overriding the bags' `CameraInfo` (`crate::calibration`).
    pub camera: Option<PathBuf>,
    /// Largest stamp difference of a stereo pair, seconds; `None`: a tenth of the median
    /// interval between left frames.
    pub pair_tolerance_s: Option<f64>,
}

/// How the messages of one image topic are decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Raw,
    Compressed,
}

/// The image messages of a bag's sequence, decoded on demand.
#[derive(Debug)]
pub struct BagFrames {
    bag: Bag,
    left: Vec<MessageRef>,
    left_kind: Kind,
    /// Per left frame, its right partner (`None`: none within the tolerance).
    right: Option<(Vec<Option<MessageRef>>, Kind, String)>,
    raw_size: (usize, usize),
}

impl BagFrames {
    /// Number of frames (left images).
    #[must_use]
    pub fn len(&self) -> usize {
        self.left.len()
    }

    /// Whether there are no frames (never for an opened sequence).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.left.is_empty()
    }

    /// Whether a right topic was paired.
    #[must_use]
    pub fn has_right(&self) -> bool {
        self.right.is_some()
    }

    /// The raw left image `i`.
    ///
    /// # Errors
    /// A read error or a message that does not decode, named with the bag file and topic.
    pub fn left(&self, i: usize) -> Result<GrayImage> {
        self.decode(&self.left[i], self.left_kind)
    }

    /// The raw right image `i`.
    ///
    /// # Errors
    /// No right topic, no partner within the tolerance, or a message that does not decode.
    pub fn right(&self, i: usize) -> Result<GrayImage> {
        let Some((pairs, kind, topic)) = &self.right else {
            return Err(IoError::NotFound {
                path: self.bag.path.clone(),
                what: "right image topic".into(),
            });
        };
        match &pairs[i] {
            Some(at) => self.decode(at, *kind),
            None => Err(IoError::NotFound {
                path: self.bag.path.clone(),
                what: format!("a {topic} image within the pairing tolerance of left frame {i}"),
            }),
        }
    }

    /// One image message, decoded and checked against the sequence's size.
    fn decode(&self, at: &MessageRef, kind: Kind) -> Result<GrayImage> {
        let img = self.decode_unchecked(at, kind)?;
        crate::image_io::check_size(img, self.bag.index.file_of(at), self.raw_size)
    }

    /// One image message, decoded (the first frame sets the sequence's size).
    fn decode_unchecked(&self, at: &MessageRef, kind: Kind) -> Result<GrayImage> {
        let data = self.bag.index.read(at)?;
        let decoded = match kind {
            Kind::Raw => msgs::decode_image(&data),
            Kind::Compressed => msgs::decode_compressed(&data),
        };
        decoded.map(|(_, img)| img).map_err(|e| IoError::Image {
            path: self.bag.index.file_of(at).to_path_buf(),
            message: format!("message at log time {} ns: {e}", at.log_time_ns),
        })
    }
}

/// Opens the image topic(s) of a bag as a sequence.
///
/// # Errors
/// Everything [`Bag::open`] reports; no image topic, several without `topic` (the message lists
/// them), a topic that is missing or not an image (listing the image topics), no calibration
/// (no `CameraInfo` and no camera file), or calibration that does not fit the images.
pub fn open_bag_sequence(path: &Path, options: &BagOptions) -> Result<Sequence> {
    let bag = Bag::open(path)?;
    let left_topic = choose_topic(&bag, options.topic.as_deref())?;
    let (left, stamps_ns, left_kind) = image_messages(&bag, &left_topic)?;
    let right = match &options.right_topic {
        Some(t) => {
            let t = choose_topic(&bag, Some(t))?;
            let (msgs, right_stamps, kind) = image_messages(&bag, &t)?;
            let tol_ns = tolerance_ns(&stamps_ns, options.pair_tolerance_s);
            let pairs = pair_by_stamp(&stamps_ns, &right_stamps, &msgs, tol_ns);
            let unpaired = pairs.iter().filter(|p| p.is_none()).count();
            if unpaired > 0 {
                log::warn!(
                    "{}: {unpaired} of {} left frames have no {t} image within {:.1} ms: they keep their place, without stereo",
                    path.display(),
                    pairs.len(),
                    tol_ns as f64 * 1e-6
                );
            }
            Some((pairs, kind, t))
        }
        None => None,
    };
    let mut frames = BagFrames {
        bag,
        left,
        left_kind,
        right,
        raw_size: (0, 0),
    };
    let first = frames.decode_unchecked(&frames.left[0], frames.left_kind)?;
    frames.raw_size = (first.width(), first.height());
    let calib = calibration(&frames, &left_topic, options)?;
    let timestamps: Vec<f64> = stamps_ns.iter().map(|&t| t as f64 * 1e-9).collect();
    Sequence::from_bag(path, Arc::new(frames), calib, timestamps)
}

/// The topic to read: the one asked for (checked), or the bag's only image topic.
fn choose_topic(bag: &Bag, asked: Option<&str>) -> Result<String> {
    let images = bag.image_topics();
    let listing = || {
        if images.is_empty() {
            "the bag has no sensor_msgs/msg/Image or CompressedImage topic".to_owned()
        } else {
            format!("image topics: {}", images.join(", "))
        }
    };
    match asked {
        Some(t) if images.iter().any(|i| i == t) => Ok(t.to_owned()),
        Some(t) => Err(IoError::Format {
            path: bag.path.clone(),
            message: match bag.index.channels.get(t) {
                Some(c) => format!(
                    "topic {t} carries {}, not images ({})",
                    c.message_type,
                    listing()
                ),
                None => format!("no topic {t} ({})", listing()),
            },
        }),
        None if images.len() == 1 => Ok(images[0].clone()),
        None => Err(IoError::Format {
            path: bag.path.clone(),
            message: format!("give the image topic with --topic ({})", listing()),
        }),
    }
}

/// The messages of an image topic sorted by header stamp, their stamps (ns) and their kind.
fn image_messages(bag: &Bag, topic: &str) -> Result<(Vec<MessageRef>, Vec<i64>, Kind)> {
    let kind = match bag
        .index
        .channels
        .get(topic)
        .map(|c| c.message_type.as_str())
    {
        Some(msgs::COMPRESSED_IMAGE) => Kind::Compressed,
        _ => Kind::Raw,
    };
    let all = bag.index.messages.get(topic).map_or(&[][..], Vec::as_slice);
    let mut stamped: Vec<(i64, u64, MessageRef)> = Vec::with_capacity(all.len());
    for m in all {
        let MessageMeta { stamp_ns, .. } = &m.info;
        let Some(s) = stamp_ns else {
            return Err(IoError::Format {
                path: bag.index.file_of(&m.at).to_path_buf(),
                message: format!(
                    "a {topic} message at log time {} ns has no readable header",
                    m.at.log_time_ns
                ),
            });
        };
        stamped.push((*s, m.at.log_time_ns, m.at));
    }
    if stamped.is_empty() {
        return Err(IoError::EmptySequence {
            path: bag.path.clone(),
        });
    }
    stamped.sort_by_key(|&(s, log, _)| (s, log));
    let stamps = stamped.iter().map(|s| s.0).collect();
    Ok((stamped.into_iter().map(|s| s.2).collect(), stamps, kind))
}

/// The pairing tolerance, ns: given, or a tenth of the median left interval (1 ms at least).
fn tolerance_ns(left_ns: &[i64], given_s: Option<f64>) -> i64 {
    if let Some(s) = given_s {
        return (s * 1e9).round() as i64;
    }
    let mut d: Vec<i64> = left_ns.windows(2).map(|w| w[1] - w[0]).collect();
    d.sort_unstable();
    d.get(d.len() / 2)
        .map_or(1_000_000, |m| (m / 10).max(1_000_000))
}

/// For each left stamp, the right message whose stamp is nearest, if within `tol_ns`.
fn pair_by_stamp(
    left_ns: &[i64],
    right_ns: &[i64],
    right: &[MessageRef],
    tol_ns: i64,
) -> Vec<Option<MessageRef>> {
    left_ns
        .iter()
        .map(|&t| {
            let j = right_ns.partition_point(|&r| r < t);
            [j.checked_sub(1), Some(j)]
                .into_iter()
                .flatten()
                .filter(|&k| k < right_ns.len())
                .min_by_key(|&k| (right_ns[k] - t).abs())
                .filter(|&k| (right_ns[k] - t).abs() <= tol_ns)
                .map(|k| right[k])
        })
        .collect()
}

/// The calibration of a bag's sequence.
pub(crate) enum BagCalibration {
    /// Rectified input: the camera of `P` and the baseline of the two `P` matrices.
    Rectified {
        camera: PinholeCamera,
        baseline_m: Option<f64>,
        /// The right `P`'s `cx` minus the left one's, pixels.
        right_cx_offset_px: f64,
    },
    /// Raw input, undistorted / rectified on load.
    Rectify(Arc<Rectifier>),
}

/// From the camera file, or from the `CameraInfo` of the sibling topics.
fn calibration(
    frames: &BagFrames,
    left_topic: &str,
    options: &BagOptions,
) -> Result<BagCalibration> {
    let stereo = frames.right.is_some();
    if let Some(file) = &options.camera {
        let calib = read_camera_file(file)?;
        check_size(frames, &calib.left.pinhole, file)?;
        return Ok(BagCalibration::Rectify(Rectifier::new(
            &calib, stereo, file,
        )?));
    }
    let left = camera_info(&frames.bag, left_topic)?;
    let right = match &frames.right {
        Some((_, _, t)) => Some(camera_info(&frames.bag, t)?),
        None => None,
    };
    let path = frames.bag.path.clone();
    check_camera_info(&left, &path)?;
    if let Some(r) = &right {
        check_camera_info(r, &path)?;
        if !(r.p[(0, 0)] > 0.0 && r.p[(1, 1)] > 0.0) {
            return Err(IoError::Format {
                path: path.clone(),
                message: format!(
                    "CameraInfo of {}: the projection P of the right camera is not set (fx′ = {}, fy′ = {})",
                    r.header.frame_id,
                    r.p[(0, 0)],
                    r.p[(1, 1)]
                ),
            });
        }
    }
    let rectified = |c: &CameraInfo| {
        c.d.iter().all(|&d| d == 0.0) && (c.r == Matrix3::identity() || c.r == Matrix3::zeros())
    };
    if rectified(&left) && right.as_ref().is_none_or(rectified) {
        let camera = pinhole(&left, &left.p.fixed_view::<3, 3>(0, 0).into_owned(), &path)?;
        check_size(frames, &camera, &path)?;
        let baseline_m = right
            .as_ref()
            .map(|r| baseline_of(&left, r, &path))
            .transpose()?;
        if let (Some(b), Some(r)) = (baseline_m, &right) {
            crate::baseline::warn_if_implausible(&path, &right_p_field(r), b, &camera);
        }
        let right_cx_offset_px = right
            .as_ref()
            .map(|r| crate::baseline::right_cx_offset(&left.p, &r.p, &path))
            .transpose()?
            .unwrap_or(0.0);
        return Ok(BagCalibration::Rectified {
            camera,
            baseline_m,
            right_cx_offset_px,
        });
    }
    let calib = RigCalibration {
        left: calibrated(&left, &path)?,
        right: right
            .as_ref()
            .map(|r| Ok::<_, IoError>((calibrated(r, &path)?, right_from_left(&left, r))))
            .transpose()?,
        rate_hz: None,
    };
    check_size(frames, &calib.left.pinhole, &path)?;
    if let (Some((_, right_from_left)), Some(r)) = (&calib.right, &right) {
        let b = right_from_left.translation.vector.norm();
        crate::baseline::warn_if_implausible(&path, &right_p_field(r), b, &calib.left.pinhole);
    }
    Ok(BagCalibration::Rectify(Rectifier::new(
        &calib, stereo, &path,
    )?))
}

/// The first `CameraInfo` of the `camera_info` topic beside an image topic.
fn camera_info(bag: &Bag, image_topic: &str) -> Result<CameraInfo> {
    let base = image_topic
        .strip_suffix("/compressed")
        .unwrap_or(image_topic);
    let ns = base.rsplit_once('/').map_or("", |(ns, _)| ns);
    let topic = format!("{ns}/camera_info");
    let first = bag
        .index
        .messages
        .get(&topic)
        .and_then(|m| m.first())
        .ok_or_else(|| IoError::NotFound {
            path: bag.path.clone(),
            what: format!(
                "sensor_msgs/msg/CameraInfo on {topic} (the calibration of {image_topic}); give a camera file with --camera"
            ),
        })?;
    let data = bag.index.read(&first.at)?;
    msgs::decode_camera_info(&data).map_err(|e| IoError::Format {
        path: bag.index.file_of(&first.at).to_path_buf(),
        message: format!("{topic}: {e}"),
    })
}

fn pinhole(c: &CameraInfo, k: &Matrix3<f64>, path: &Path) -> Result<PinholeCamera> {
    let size = |v: usize| u32::try_from(v).unwrap_or(0);
    PinholeCamera::new(
        k[(0, 0)],
        k[(1, 1)],
        k[(0, 2)],
        k[(1, 2)],
        size(c.width),
        size(c.height),
    )
    .map_err(|e| IoError::Format {
        path: path.to_path_buf(),
        message: format!("CameraInfo of {}: {e}", c.header.frame_id),
    })
}

/// `(P_left[0][3] − P_right[0][3]) / P_right[0][0]`: the baseline of a rectified pair, metres.
/// The field a rig's translation comes from, for the impossible-baseline warning.
fn right_p_field(right: &CameraInfo) -> String {
    format!(
        "the right CameraInfo's P[0][3] (frame_id `{}`)",
        right.header.frame_id
    )
}

fn baseline_of(left: &CameraInfo, right: &CameraInfo, path: &Path) -> Result<f64> {
    let b = (left.p[(0, 3)] - right.p[(0, 3)]) / right.p[(0, 0)];
    if b.is_finite() && b > 0.0 {
        Ok(b)
    } else {
        Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!(
                "the stereo baseline from the two CameraInfo P matrices is {b} m, not positive"
            ),
        })
    }
}

/// The raw camera of a `CameraInfo`: `K` and the distortion model.
fn calibrated(c: &CameraInfo, path: &Path) -> Result<CalibratedCamera> {
    let d = |i: usize| c.d.get(i).copied().unwrap_or(0.0);
    let distortion = match c.distortion_model.as_str() {
        "" if c.d.iter().all(|&v| v == 0.0) => Distortion::None,
        "plumb_bob" | "rational_polynomial" if c.d.iter().skip(5).all(|&v| v == 0.0) => {
            Distortion::RadialTangential {
                k1: d(0),
                k2: d(1),
                p1: d(2),
                p2: d(3),
                k3: d(4),
            }
        }
        "equidistant" => Distortion::Equidistant {
            k1: d(0),
            k2: d(1),
            k3: d(2),
            k4: d(3),
        },
        other => {
            return Err(IoError::Format {
                path: path.to_path_buf(),
                message: format!(
                    "CameraInfo of {}: distortion model '{other}' with D = {:?} is not supported (plumb_bob, rational_polynomial without k4..k6, equidistant); give a camera file with --camera",
                    c.header.frame_id, c.d
                ),
            });
        }
    };
    Ok(CalibratedCamera {
        pinhole: pinhole(c, &c.k, path)?,
        distortion,
    })
}

/// Largest magnitude of a distortion coefficient accepted (rational-polynomial coefficients reach
/// tens; a corrupt message far more).
const MAX_DISTORTION_COEFFICIENT: f64 = 1e4;

/// Checks the numbers of a `CameraInfo` before they reach iterative algorithms (an SVD or a
/// rotation fit that a NaN or a non-rotation `R` would keep iterating, found by the fuzz test):
/// all finite, `D` bounded, `R` a rotation (or all zeros: unset) to 1e-3.
fn check_camera_info(c: &CameraInfo, path: &Path) -> Result<()> {
    let bad = |what: String| IoError::Format {
        path: path.to_path_buf(),
        message: format!("CameraInfo of {}: {what}", c.header.frame_id),
    };
    let finite =
        c.k.iter()
            .chain(c.r.iter())
            .chain(c.p.iter())
            .all(|v| v.is_finite());
    if !finite {
        return Err(bad("K, R or P holds a value that is not finite".into()));
    }
    if c.d
        .iter()
        .any(|v| !(v.is_finite() && v.abs() <= MAX_DISTORTION_COEFFICIENT))
    {
        return Err(bad(format!(
            "distortion coefficients D = {:?} are not plausible",
            c.d
        )));
    }
    let orthonormal = (c.r.transpose() * c.r - Matrix3::identity()).amax() < 1e-3;
    if c.r != Matrix3::zeros() && !(orthonormal && c.r.determinant() > 0.0) {
        return Err(bad(format!("R = {:?} is not a rotation", c.r.as_slice())));
    }
    Ok(())
}

/// The rotation of a checked `R` (all zeros: unset, the identity).
fn rotation_of(m: &Matrix3<f64>) -> Rotation3<f64> {
    if *m == Matrix3::zeros() {
        Rotation3::identity()
    } else {
        visnav_core::se3::project_to_so3(m)
    }
}

/// `right_from_left` of the raw cameras from the rectification rotations and the right `P`:
/// the rectified right frame is the rectified left one shifted by `(Tx/fx′, Ty/fy′, 0)`, so
/// `p_right = R_rightᵀ · (R_left · p_left + t)`.
fn right_from_left(left: &CameraInfo, right: &CameraInfo) -> Pose {
    let (r_left, r_right) = (rotation_of(&left.r), rotation_of(&right.r));
    let p = &right.p;
    let t = nalgebra::Vector3::new(
        (p[(0, 3)] - left.p[(0, 3)]) / p[(0, 0)],
        (p[(1, 3)] - left.p[(1, 3)]) / p[(1, 1)],
        0.0,
    );
    let rect_right_from_left_raw = Pose::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&r_left),
    );
    let raw_from_rect_right = Pose::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_rotation_matrix(&r_right.inverse()),
    );
    raw_from_rect_right * rect_right_from_left_raw
}

fn check_size(frames: &BagFrames, camera: &PinholeCamera, calib_path: &Path) -> Result<()> {
    let want = (camera.width as usize, camera.height as usize);
    if want != frames.raw_size {
        return Err(IoError::Format {
            path: calib_path.to_path_buf(),
            message: format!(
                "the calibration is for {}x{} images but the bag's are {}x{}",
                want.0, want.1, frames.raw_size.0, frames.raw_size.1
            ),
        });
    }
    Ok(())
}

impl DecodedFrames for BagFrames {
    fn len(&self) -> usize {
        BagFrames::len(self)
    }
    fn left(&self, i: usize) -> Result<GrayImage> {
        BagFrames::left(self, i)
    }
    fn right(&self, i: usize) -> Option<Result<GrayImage>> {
        Some(BagFrames::right(self, i))
    }
    fn has_right(&self) -> bool {
        BagFrames::has_right(self)
    }
}

impl Sequence {
    /// The sequence of a bag's frames with its calibration.
    pub(crate) fn from_bag(
        path: &Path,
        frames: Arc<BagFrames>,
        calib: BagCalibration,
        timestamps: Vec<f64>,
    ) -> Result<Self> {
        let raw_size = frames.raw_size;
        let mut seq = match calib {
            BagCalibration::Rectified {
                camera,
                baseline_m,
                right_cx_offset_px,
            } => {
                let mut s = Self::bare(
                    path,
                    SequenceLayout::RosBag,
                    camera,
                    baseline_m.filter(|_| frames.has_right()),
                    raw_size,
                );
                s.right_cx_offset_px = right_cx_offset_px;
                s
            }
            BagCalibration::Rectify(rectifier) => {
                let mut s = Self::bare(
                    path,
                    SequenceLayout::RosBag,
                    rectifier.camera,
                    rectifier.baseline_m.filter(|_| frames.has_right()),
                    raw_size,
                );
                s.set_rectifier(rectifier);
                s
            }
        };
        seq.timestamps = timestamps;
        seq.timestamped = true;
        seq.set_decoded(frames);
        Ok(seq)
    }
}
