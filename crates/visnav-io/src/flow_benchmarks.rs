//! Discovery of optical-flow benchmark layouts (Middlebury `other-data` + `other-gt-flow`, KITTI
//! 2012/2015 `image_0|image_2` + `flow_noc|flow_occ`, MPI Sintel `training/flow` + a pass) and
//! reading their ground truth as flow + known mask.

use std::path::{Path, PathBuf};

use crate::error::{IoError, Result};
use crate::flo::{FlowField, read_flo};

/// Which KITTI ground truth to score against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KittiGt {
    /// `flow_noc` (non-occluded pixels).
    Noc,
    /// `flow_occ` (all pixels).
    Occ,
}

/// One image pair with its ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct FlowPair {
    /// Name of the pair (sequence, stem or scene/frame).
    pub name: String,
    /// First image.
    pub image1: PathBuf,
    /// Second image.
    pub image2: PathBuf,
    /// Ground truth.
    pub gt: GtFile,
}

/// A ground-truth flow file.
#[derive(Debug, Clone, PartialEq)]
pub enum GtFile {
    /// Middlebury `.flo` (Middlebury, Sintel).
    Flo(PathBuf),
    /// KITTI 16-bit PNG.
    KittiPng(PathBuf),
}

impl GtFile {
    /// The file.
    #[must_use]
    pub fn path(&self) -> &Path {
        match self {
            Self::Flo(p) | Self::KittiPng(p) => p,
        }
    }

    /// The ground truth as flow + known mask.
    ///
    /// # Errors
    /// An unreadable or malformed file.
    pub fn load(&self) -> Result<(FlowField, Vec<bool>)> {
        match self {
            Self::Flo(p) => {
                let f = read_flo(p)?;
                let known = (0..f.width * f.height)
                    .map(|i| f.is_known(i % f.width, i / f.width))
                    .collect();
                Ok((f, known))
            }
            Self::KittiPng(p) => crate::kitti_flow::read_kitti_flow_png(p),
        }
    }
}

/// The entries of `dir`, sorted.
fn sorted_dirs(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| IoError::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    v.sort();
    Ok(v)
}

/// The layout under `root` (`"middlebury"`, `"kitti"` or `"sintel"`) and its pairs, in name
/// order. Middlebury sequences without published ground truth are left out (logged).
///
/// # Errors
/// [`IoError::NotFound`] when `root` does not exist, [`IoError::Format`] when it is not a
/// folder or holds no known layout; an unlistable directory, or a KITTI pair without its ground
/// truth.
pub fn discover_flow_pairs(
    root: &Path,
    kitti_gt: KittiGt,
    sintel_pass: &str,
) -> Result<(&'static str, Vec<FlowPair>)> {
    // a missing folder (or a file) is named as such, not reported as an unknown layout
    if !root.is_dir() {
        return Err(if root.exists() {
            IoError::Format {
                path: root.to_path_buf(),
                message: "not a folder (give the dataset's root folder)".into(),
            }
        } else {
            IoError::NotFound {
                path: root.to_path_buf(),
                what: "flow dataset folder".into(),
            }
        });
    }
    if root.join("other-data").is_dir() {
        let mut pairs = Vec::new();
        for seq in sorted_dirs(&root.join("other-data"))? {
            let Some(name) = seq.file_name().map(|n| n.to_string_lossy().into_owned()) else {
                continue;
            };
            let gt = root.join("other-gt-flow").join(&name).join("flow10.flo");
            // Middlebury publishes ground truth for 8 of its 12 `other-data` sequences
            if !gt.is_file() {
                log::info!(
                    "{}: no ground truth {}; not scored",
                    seq.display(),
                    gt.display()
                );
            } else {
                pairs.push(FlowPair {
                    image1: seq.join("frame10.png"),
                    image2: seq.join("frame11.png"),
                    gt: GtFile::Flo(gt),
                    name,
                });
            }
        }
        return Ok(("middlebury", pairs));
    }
    let kitti_root = if root.join("training").is_dir() {
        root.join("training")
    } else {
        root.to_path_buf()
    };
    let img_dir = ["image_0", "image_2"]
        .iter()
        .map(|d| kitti_root.join(d))
        .find(|d| d.is_dir());
    if let Some(img_dir) = img_dir {
        let gt_dir = kitti_root.join(match kitti_gt {
            KittiGt::Noc => "flow_noc",
            KittiGt::Occ => "flow_occ",
        });
        let mut pairs = Vec::new();
        for p in sorted_dirs(&img_dir)? {
            let Some(fname) = p.file_name().map(|n| n.to_string_lossy().into_owned()) else {
                continue;
            };
            let Some(stem) = fname.strip_suffix("_10.png") else {
                continue;
            };
            let gt = gt_dir.join(&fname);
            // every KITTI training pair has ground truth: a missing file is an error, not a
            // pair silently left out of the means
            if !gt.is_file() {
                return Err(IoError::Format {
                    message: format!(
                        "no ground truth for the pair {} (expected in {}, --kitti-gt {})",
                        p.display(),
                        gt_dir.display(),
                        match kitti_gt {
                            KittiGt::Noc => "noc",
                            KittiGt::Occ => "occ",
                        }
                    ),
                    path: gt,
                });
            }
            pairs.push(FlowPair {
                name: stem.to_string(),
                image1: p.clone(),
                image2: img_dir.join(format!("{stem}_11.png")),
                gt: GtFile::KittiPng(gt),
            });
        }
        return Ok(("kitti", pairs));
    }
    let sintel_flow = kitti_root.join("flow");
    let sintel_img = kitti_root.join(sintel_pass);
    if sintel_flow.is_dir() && sintel_img.is_dir() {
        let mut pairs = Vec::new();
        for scene in sorted_dirs(&sintel_flow)? {
            let Some(sname) = scene.file_name().map(|n| n.to_string_lossy().into_owned()) else {
                continue;
            };
            for f in sorted_dirs(&scene)? {
                let Some(stem) = f
                    .file_name()
                    .and_then(|n| n.to_str())
                    .and_then(|n| n.strip_suffix(".flo"))
                    .map(str::to_string)
                else {
                    continue;
                };
                let Some(idx) = stem
                    .strip_prefix("frame_")
                    .and_then(|n| n.parse::<u32>().ok())
                else {
                    continue;
                };
                let dir = sintel_img.join(&sname);
                pairs.push(FlowPair {
                    name: format!("{sname}/{stem}"),
                    image1: dir.join(format!("frame_{idx:04}.png")),
                    image2: dir.join(format!("frame_{:04}.png", idx + 1)),
                    gt: GtFile::Flo(f.clone()),
                });
            }
        }
        return Ok(("sintel", pairs));
    }
    Err(IoError::Format {
        path: root.to_path_buf(),
        message: "no Middlebury (other-data), KITTI (image_0/image_2 + flow_noc) or Sintel (training/flow) layout found".into(),
    })
}
