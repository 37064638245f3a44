//! Live 3-D view of an odometry run in the Rerun viewer (cargo feature `rerun`, off by default):
//! the camera path, the current frame, the dense flow (colour wheel), its uncertainty (1-sigma
//! radius) and the triangulated points of the fused depth map, logged per frame on the `frame`
//! timeline, either to a running viewer (`--rerun-connect`) or to an `.rrd` file
//! (`--rerun-save FILE`, open with `rerun FILE`).
//!
//! Entities (world = first camera frame, x right, y down, z forward, metres):
//! `world/path` (line strip of camera centres), `world/camera` (pose `world_from_cam`),
//! `world/camera/image` (pinhole + grey frame), `world/points` (depth map in world),
//! `flow` and `uncertainty` (2-D images).
//!
//! Without the feature, [`LiveView::open`] turns the options into a clear error and
//! nothing else is compiled.

use std::path::Path;

use visnav_core::{GrayImage, PinholeCamera, Pose};
use visnav_flow::DenseFlow;
use visnav_odometry::mono::DepthMap;

/// Where the live view goes.
#[derive(Debug, Clone, Default)]
pub struct LiveOptions<'a> {
    /// Write an `.rrd` recording here.
    pub save: Option<&'a Path>,
    /// Stream to a viewer on the default address.
    pub connect: bool,
}

/// What is logged for one frame.
// without the feature nothing reads it
#[cfg_attr(not(feature = "rerun"), allow(dead_code))]
pub struct LiveFrame<'a> {
    /// Position in the run (the `frame` timeline).
    pub step: usize,
    /// The current image.
    pub image: &'a GrayImage,
    /// `world_from_cam` of the current frame.
    pub world_from_cam: &'a Pose,
    /// Dense flow from the previous frame (mono).
    pub flow: Option<&'a DenseFlow>,
    /// The fused depth map of the current frame (mono).
    pub depth: Option<&'a DepthMap>,
}

/// A live view, or nothing when neither option is set.
// without the feature it is never constructed: `open` returns `None` or an error
#[cfg_attr(not(feature = "rerun"), allow(dead_code))]
pub struct LiveView {
    #[cfg(feature = "rerun")]
    rec: rerun::RecordingStream,
    #[cfg(feature = "rerun")]
    camera: PinholeCamera,
    #[cfg(feature = "rerun")]
    path_m: Vec<[f32; 3]>,
}

impl LiveView {
    /// Opens the view for a camera, `None` when no option asks for one.
    ///
    /// # Errors
    /// The binary was built without the `rerun` feature, or the recording cannot be created.
    #[cfg(not(feature = "rerun"))]
    pub fn open(options: &LiveOptions<'_>, camera: PinholeCamera) -> anyhow::Result<Option<Self>> {
        let _ = camera;
        if options.save.is_some() || options.connect {
            anyhow::bail!(
                "--rerun-save / --rerun-connect need visnav built with the `rerun` feature (cargo build --release -p visnav --features rerun)"
            );
        }
        Ok(None)
    }

    /// Logs a frame (a no-op without the feature).
    #[cfg(not(feature = "rerun"))]
    pub fn log(&mut self, frame: &LiveFrame<'_>) {
        let _ = frame;
    }
}

#[cfg(feature = "rerun")]
impl LiveView {
    /// Opens the view for a camera, `None` when no option asks for one.
    ///
    /// # Errors
    /// The recording file cannot be created or the viewer address is invalid.
    pub fn open(options: &LiveOptions<'_>, camera: PinholeCamera) -> anyhow::Result<Option<Self>> {
        use anyhow::Context as _;
        let builder = rerun::RecordingStreamBuilder::new("visnav");
        let rec = match (options.save, options.connect) {
            (None, false) => return Ok(None),
            (Some(path), false) => builder
                .save(path)
                .with_context(|| format!("creating Rerun recording {}", path.display()))?,
            (None, true) => builder
                .connect_grpc()
                .context("connecting to the Rerun viewer")?,
            (Some(_), true) => anyhow::bail!("give either --rerun-save or --rerun-connect"),
        };
        rec.log_static("world", &rerun::ViewCoordinates::RDF())?;
        Ok(Some(Self {
            rec,
            camera,
            path_m: Vec::new(),
        }))
    }

    /// Logs a frame; a failure of the recording stream is a warning (the run goes on).
    pub fn log(&mut self, frame: &LiveFrame<'_>) {
        if let Err(e) = self.try_log(frame) {
            log::warn!("live view, step {}: {e:#}", frame.step);
        }
    }

    fn try_log(&mut self, frame: &LiveFrame<'_>) -> anyhow::Result<()> {
        use visnav_report::colour;
        let rec = &self.rec;
        rec.set_time_sequence("frame", frame.step as i64);
        let t = frame.world_from_cam.translation.vector;
        let q = frame.world_from_cam.rotation.coords;
        self.path_m.push([t.x as f32, t.y as f32, t.z as f32]);
        rec.log(
            "world/path",
            &rerun::LineStrips3D::new([self.path_m.clone()]),
        )?;
        rec.log(
            "world/camera",
            &rerun::Transform3D::from_translation_rotation(
                [t.x as f32, t.y as f32, t.z as f32],
                rerun::Quaternion::from_xyzw([q.x as f32, q.y as f32, q.z as f32, q.w as f32]),
            ),
        )?;
        let (w, h) = (frame.image.width(), frame.image.height());
        rec.log(
            "world/camera/image",
            &rerun::Pinhole::from_focal_length_and_resolution(
                [self.camera.fx as f32, self.camera.fy as f32],
                [w as f32, h as f32],
            ),
        )?;
        let grey: Vec<u8> = frame
            .image
            .data()
            .iter()
            .map(|v| v.round().clamp(0.0, 255.0) as u8)
            .collect();
        rec.log(
            "world/camera/image",
            &rerun::Image::from_elements(&grey, [w as u32, h as u32], rerun::ColorModel::L),
        )?;
        if let Some(flow) = frame.flow {
            let max_px = colour::max_magnitude_px(flow.flow.iter().copied());
            let rgb: Vec<u8> = flow
                .flow
                .iter()
                .flat_map(|f| colour::flow_rgb(*f, max_px))
                .collect();
            let size = [flow.width as u32, flow.height as u32];
            rec.log("flow", &rerun::Image::from_rgb24(rgb, size))?;
            let rgb: Vec<u8> = flow
                .information
                .iter()
                .flat_map(|y| colour::sigma_rgb(colour::sigma_px(*y)))
                .collect();
            rec.log("uncertainty", &rerun::Image::from_rgb24(rgb, size))?;
        }
        if let Some(d) = frame.depth {
            let c = &self.camera;
            let mut points = Vec::new();
            for r in 0..d.rows {
                for col in 0..d.cols {
                    let z = f64::from(d.depth_m[r * d.cols + col]);
                    if !(z.is_finite() && z > 0.0) {
                        continue;
                    }
                    let (u, v) = ((col * d.stride) as f64, (r * d.stride) as f64);
                    let p_in_cam =
                        nalgebra::Point3::new((u - c.cx) / c.fx * z, (v - c.cy) / c.fy * z, z);
                    let p = frame.world_from_cam * p_in_cam;
                    points.push([p.x as f32, p.y as f32, p.z as f32]);
                }
            }
            rec.log(
                "world/points",
                &rerun::Points3D::new(points).with_radii([0.05]),
            )?;
        }
        Ok(())
    }
}
