//! The ROS 2 messages visnav reads from a bag (`sensor_msgs/msg/Image`, `CompressedImage`,
//! `CameraInfo`) and writes (`geometry_msgs/msg/PoseStamped`), decoded from / encoded to CDR.

use nalgebra::{Matrix3, Matrix3x4, UnitQuaternion};
use visnav_core::{GrayImage, Pose};

use super::cdr::{CdrError, CdrReader, CdrWriter};

/// `sensor_msgs/msg/Image`.
pub const IMAGE: &str = "sensor_msgs/msg/Image";
/// `sensor_msgs/msg/CompressedImage`.
pub const COMPRESSED_IMAGE: &str = "sensor_msgs/msg/CompressedImage";
/// `sensor_msgs/msg/CameraInfo`.
pub const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";
/// `geometry_msgs/msg/PoseStamped`.
pub const POSE_STAMPED: &str = "geometry_msgs/msg/PoseStamped";

/// The raw encodings of `sensor_msgs/Image` visnav decodes.
pub const RAW_ENCODINGS: [&str; 6] = ["mono8", "mono16", "rgb8", "bgr8", "rgba8", "bgra8"];

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    /// `stamp` in seconds (`sec + nanosec · 1e-9`).
    pub stamp_s: f64,
    /// `stamp` in nanoseconds since the epoch (exact, for pairing).
    pub stamp_ns: i64,
    /// `frame_id`.
    pub frame_id: String,
}

/// Reads the header at the start of a message.
///
/// # Errors
/// A truncated or malformed message.
pub fn read_header(r: &mut CdrReader<'_>) -> Result<Header, CdrError> {
    let sec = r.i32("header.stamp.sec")?;
    let nanosec = r.u32("header.stamp.nanosec")?;
    let frame_id = r.string("header.frame_id")?;
    Ok(Header {
        stamp_s: f64::from(sec) + f64::from(nanosec) * 1e-9,
        stamp_ns: i64::from(sec) * 1_000_000_000 + i64::from(nanosec),
        frame_id,
    })
}

/// The header of any stamped message (the first field of all three image and camera types).
///
/// # Errors
/// A truncated or malformed message.
pub fn header_of(data: &[u8]) -> Result<Header, CdrError> {
    read_header(&mut CdrReader::new(data)?)
}

/// Why an image message could not become a gray image.
#[derive(Debug, thiserror::Error)]
pub enum ImageMessageError {
    /// Bad CDR.
    #[error(transparent)]
    Cdr(#[from] CdrError),
    /// An encoding visnav does not read.
    #[error("image encoding '{0}' is not supported (visnav reads {list})", list = RAW_ENCODINGS.join(", "))]
    Encoding(String),
    /// Width, height, step and data length disagree.
    #[error("{0}")]
    Layout(String),
    /// A compressed image that does not decode.
    #[error("compressed image ({format}): {message}")]
    Decode {
        /// The message's `format` field.
        format: String,
        /// The decoder's message.
        message: String,
    },
}

/// A `sensor_msgs/msg/Image` (raw) as a gray image (0–255), with its header. Colour images are
/// converted as the image files of the other layouts are (`crate::image_io`), 16-bit ones
/// scaled by 1/257.
///
/// # Errors
/// Bad CDR, an unsupported encoding or inconsistent sizes.
pub fn decode_image(data: &[u8]) -> Result<(Header, GrayImage), ImageMessageError> {
    let mut r = CdrReader::new(data)?;
    let header = read_header(&mut r)?;
    let height = r.u32("height")? as usize;
    let width = r.u32("width")? as usize;
    let encoding = r.string("encoding")?;
    let big_endian = r.u8("is_bigendian")? != 0;
    let step = r.u32("step")? as usize;
    let pixels = r.bytes("data")?;
    let channels = match encoding.as_str() {
        "mono8" => 1,
        "mono16" => 2,
        "rgb8" | "bgr8" => 3,
        "rgba8" | "bgra8" => 4,
        other => return Err(ImageMessageError::Encoding(other.to_owned())),
    };
    let row_bytes = width.saturating_mul(channels);
    if width == 0 || height == 0 || step < row_bytes || pixels.len() < step.saturating_mul(height) {
        return Err(ImageMessageError::Layout(format!(
            "{width}x{height} {encoding} image with step {step} needs {} bytes, has {}",
            step.saturating_mul(height),
            pixels.len()
        )));
    }
    let packed: Vec<u8> = (0..height)
        .flat_map(|y| &pixels[y * step..y * step + row_bytes])
        .copied()
        .collect();
    let dynamic = to_dynamic(&encoding, width, height, packed, big_endian)
        .ok_or_else(|| ImageMessageError::Layout("buffer size mismatch".into()))?;
    Ok((header, crate::image_io::gray_from_dynamic(dynamic)))
}

/// The raw pixels of a supported encoding as an `image` crate image.
fn to_dynamic(
    encoding: &str,
    width: usize,
    height: usize,
    mut packed: Vec<u8>,
    big_endian: bool,
) -> Option<image::DynamicImage> {
    let (w, h) = (u32::try_from(width).ok()?, u32::try_from(height).ok()?);
    if encoding.starts_with("bgr") {
        let c = if encoding == "bgra8" { 4 } else { 3 };
        for px in packed.chunks_exact_mut(c) {
            px.swap(0, 2);
        }
    }
    Some(match encoding {
        "mono8" => image::DynamicImage::ImageLuma8(image::GrayImage::from_raw(w, h, packed)?),
        "mono16" => {
            let v: Vec<u16> = packed
                .chunks_exact(2)
                .map(|b| {
                    if big_endian {
                        u16::from_be_bytes([b[0], b[1]])
                    } else {
                        u16::from_le_bytes([b[0], b[1]])
                    }
                })
                .collect();
            image::DynamicImage::ImageLuma16(image::ImageBuffer::from_raw(w, h, v)?)
        }
        "rgb8" | "bgr8" => image::DynamicImage::ImageRgb8(image::RgbImage::from_raw(w, h, packed)?),
        _ => image::DynamicImage::ImageRgba8(image::RgbaImage::from_raw(w, h, packed)?),
    })
}

/// A `sensor_msgs/msg/CompressedImage` (JPEG or PNG) as a gray image, with its header.
///
/// # Errors
/// Bad CDR or data that does not decode.
pub fn decode_compressed(data: &[u8]) -> Result<(Header, GrayImage), ImageMessageError> {
    let mut r = CdrReader::new(data)?;
    let header = read_header(&mut r)?;
    let format = r.string("format")?;
    let bytes = r.bytes("data")?;
    let image =
        crate::image_io::decode_gray(bytes).map_err(|message| ImageMessageError::Decode {
            format: format.clone(),
            message,
        })?;
    Ok((header, image))
}

/// `sensor_msgs/msg/CameraInfo`, the fields visnav uses.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    /// Header (its `frame_id` names the camera).
    pub header: Header,
    /// Image size, pixels.
    pub width: usize,
    /// Image size, pixels.
    pub height: usize,
    /// `distortion_model` (`plumb_bob`, `rational_polynomial`, `equidistant`, or empty).
    pub distortion_model: String,
    /// Distortion coefficients `D`.
    pub d: Vec<f64>,
    /// Intrinsics `K` of the raw images.
    pub k: Matrix3<f64>,
    /// Rectification rotation `R` (stereo: raw camera → rectified frame).
    pub r: Matrix3<f64>,
    /// Projection `P` of the rectified images (stereo right: `P[0][3] = −fx′·baseline`).
    pub p: Matrix3x4<f64>,
}

/// Decodes a `sensor_msgs/msg/CameraInfo`.
///
/// # Errors
/// A truncated or malformed message.
pub fn decode_camera_info(data: &[u8]) -> Result<CameraInfo, CdrError> {
    let mut r = CdrReader::new(data)?;
    let header = read_header(&mut r)?;
    let height = r.u32("height")? as usize;
    let width = r.u32("width")? as usize;
    let distortion_model = r.string("distortion_model")?;
    let d = r.f64_seq("d")?;
    let k = r.f64_array::<9>("k")?;
    let rr = r.f64_array::<9>("r")?;
    let p = r.f64_array::<12>("p")?;
    Ok(CameraInfo {
        header,
        width,
        height,
        distortion_model,
        d,
        k: Matrix3::from_row_slice(&k),
        r: Matrix3::from_row_slice(&rr),
        p: Matrix3x4::from_row_slice(&p),
    })
}

/// Encodes a `geometry_msgs/msg/PoseStamped`: `world_from_cam` of one frame at `stamp_ns`, in
/// the frame `frame_id` (the trajectory's world frame).
#[must_use]
pub fn encode_pose_stamped(stamp_ns: i64, frame_id: &str, world_from_cam: &Pose) -> Vec<u8> {
    let mut w = CdrWriter::new();
    let sec = stamp_ns.div_euclid(1_000_000_000);
    let nanosec = stamp_ns.rem_euclid(1_000_000_000);
    w.i32(i32::try_from(sec).unwrap_or(i32::MAX));
    w.u32(u32::try_from(nanosec).unwrap_or(0));
    w.string(frame_id);
    let t = world_from_cam.translation.vector;
    let q: UnitQuaternion<f64> = world_from_cam.rotation;
    for v in [t.x, t.y, t.z, q.i, q.j, q.k, q.w] {
        w.f64(v);
    }
    w.finish()
}

/// The ROS 2 message definition of `geometry_msgs/msg/PoseStamped` (the schema of the output
/// channel, `ros2msg` encoding, with its dependencies as `rosbag2` writes them).
pub const POSE_STAMPED_DEFINITION: &str = "std_msgs/Header header\nPose pose\n\
================================================================================\n\
MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
================================================================================\n\
MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n\
================================================================================\n\
MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n\
================================================================================\n\
MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n\
================================================================================\n\
MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";

#[cfg(test)]
mod tests {
    use super::*;

    fn image_message(encoding: &str, w: u32, h: u32, step: u32, data: &[u8]) -> Vec<u8> {
        let mut m = CdrWriter::new();
        m.i32(12);
        m.u32(500_000_000);
        m.string("cam0");
        m.u32(h);
        m.u32(w);
        m.string(encoding);
        let mut bytes = m.finish();
        bytes.push(0); // is_bigendian
        // step (aligned to 4) and data
        while !(bytes.len() - 4).is_multiple_of(4) {
            bytes.push(0);
        }
        bytes.extend_from_slice(&step.to_le_bytes());
        bytes.extend_from_slice(&u32::try_from(data.len()).unwrap().to_le_bytes());
        bytes.extend_from_slice(data);
        bytes
    }

    #[test]
    fn raw_images_decode_with_row_padding() {
        // 2x2 mono8 with a step of 3 (one padding byte a row)
        let msg = image_message("mono8", 2, 2, 3, &[10, 20, 99, 30, 40, 99]);
        let (h, img) = decode_image(&msg).unwrap();
        assert_eq!(h.stamp_ns, 12_500_000_000);
        assert_eq!(h.frame_id, "cam0");
        assert_eq!(img.data(), &[10.0, 20.0, 30.0, 40.0]);
        // bgr8 equals the rgb8 image with the channels swapped
        let rgb = image_message("rgb8", 1, 1, 3, &[200, 100, 50]);
        let bgr = image_message("bgr8", 1, 1, 3, &[50, 100, 200]);
        assert_eq!(decode_image(&rgb).unwrap().1, decode_image(&bgr).unwrap().1);
    }

    #[test]
    fn bad_images_are_errors() {
        let short = image_message("mono8", 4, 4, 4, &[0; 10]);
        assert!(matches!(
            decode_image(&short),
            Err(ImageMessageError::Layout(_))
        ));
        let yuv = image_message("yuv422", 1, 1, 2, &[0, 0]);
        let e = decode_image(&yuv).unwrap_err().to_string();
        assert!(e.contains("yuv422") && e.contains("mono8"), "{e}");
        for cut in [0, 3, 9, 20] {
            let m = image_message("mono8", 2, 2, 2, &[1, 2, 3, 4]);
            assert!(decode_image(&m[..cut]).is_err());
        }
    }

    #[test]
    fn pose_stamped_layout() {
        let pose = Pose::from_parts(
            nalgebra::Translation3::new(1.0, 2.0, 3.0),
            UnitQuaternion::identity(),
        );
        let m = encode_pose_stamped(1_500_000_000, "world", &pose);
        let mut r = CdrReader::new(&m).unwrap();
        let h = read_header(&mut r).unwrap();
        assert_eq!((h.stamp_ns, h.frame_id.as_str()), (1_500_000_000, "world"));
        let v: Vec<f64> = (0..7).map(|_| r.f64("v").unwrap()).collect();
        assert_eq!(v, [1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0]);
    }
}
