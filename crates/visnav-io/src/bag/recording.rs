//! An opened bag: its MCAP files, the index of its messages with each image's header stamp and
//! encoding, and the summary of its topics (`visnav info BAG`).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use super::cdr;
use super::mcap_file::{self, ChannelInfo, McapIndex};
use super::msgs;
use crate::error::{IoError, Result};

/// What the index keeps of each message: its header stamp and image encoding, when it is an
/// image or camera-info message.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MessageMeta {
    /// `header.stamp`, ns.
    pub stamp_ns: Option<i64>,
    /// The image encoding (`mono8`, …) or compressed format (`jpeg`, …).
    pub encoding: Option<String>,
}

/// One topic of a bag.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TopicSummary {
    /// Topic name.
    pub topic: String,
    /// ROS 2 message type.
    pub message_type: String,
    /// Messages.
    pub count: usize,
    /// Image encodings or compressed formats seen (image topics only).
    pub encodings: Vec<String>,
    /// First and last `log_time`, seconds.
    pub first_s: f64,
    /// Last `log_time`, seconds.
    pub last_s: f64,
}

/// An opened bag: its files and the index of its messages.
#[derive(Debug)]
pub struct Bag {
    /// The path given (file or directory).
    pub path: PathBuf,
    /// The index.
    pub index: McapIndex<MessageMeta>,
}

impl Bag {
    /// Opens an `.mcap` file or a rosbag2 directory.
    ///
    /// # Errors
    /// A missing path, a `.db3` bag (with the conversion command), a directory without `.mcap`
    /// files, or an unreadable / malformed file.
    pub fn open(path: &Path) -> Result<Self> {
        let files = bag_files(path)?;
        let index = McapIndex::build(&files, &inspect)?;
        for (file, at) in &index.truncated {
            log::warn!(
                "{}: the file ends inside a record after byte {at} (a recording cut short?): using the messages before it",
                file.display()
            );
        }
        Ok(Self {
            path: path.to_path_buf(),
            index,
        })
    }

    /// The topics, sorted by name.
    #[must_use]
    pub fn topics(&self) -> Vec<TopicSummary> {
        let mut out: Vec<TopicSummary> = self
            .index
            .channels
            .values()
            .map(|c| {
                let msgs = self
                    .index
                    .messages
                    .get(&c.topic)
                    .map_or(&[][..], Vec::as_slice);
                let encodings: BTreeSet<String> = msgs
                    .iter()
                    .filter_map(|m| m.info.encoding.clone())
                    .collect();
                let t = |m: Option<&mcap_file::IndexedMessage<MessageMeta>>| {
                    m.map_or(0.0, |m| m.at.log_time_ns as f64 * 1e-9)
                };
                TopicSummary {
                    topic: c.topic.clone(),
                    message_type: c.message_type.clone(),
                    count: msgs.len(),
                    encodings: encodings.into_iter().collect(),
                    first_s: t(msgs.iter().min_by_key(|m| m.at.log_time_ns)),
                    last_s: t(msgs.iter().max_by_key(|m| m.at.log_time_ns)),
                }
            })
            .collect();
        out.sort_by(|a, b| a.topic.cmp(&b.topic));
        out
    }

    /// Topics of image messages (raw or compressed), sorted.
    #[must_use]
    pub fn image_topics(&self) -> Vec<String> {
        let mut t: Vec<String> = self
            .index
            .channels
            .values()
            .filter(|c| is_image_type(&c.message_type))
            .map(|c| c.topic.clone())
            .collect();
        t.sort();
        t
    }
}

/// Whether a message type is an image visnav reads.
#[must_use]
pub fn is_image_type(message_type: &str) -> bool {
    message_type == msgs::IMAGE || message_type == msgs::COMPRESSED_IMAGE
}

/// The header stamp and encoding of image and camera-info messages; nothing for the others.
fn inspect(channel: &ChannelInfo, data: &[u8]) -> MessageMeta {
    let ty = channel.message_type.as_str();
    if channel.message_encoding != "cdr" || !(is_image_type(ty) || ty == msgs::CAMERA_INFO) {
        return MessageMeta::default();
    }
    let Ok(mut r) = cdr::CdrReader::new(data) else {
        return MessageMeta::default();
    };
    let Ok(header) = msgs::read_header(&mut r) else {
        return MessageMeta::default();
    };
    let encoding = match ty {
        msgs::IMAGE => r
            .u32("height")
            .and_then(|_| r.u32("width"))
            .and_then(|_| r.string("encoding"))
            .ok(),
        msgs::COMPRESSED_IMAGE => r.string("format").ok(),
        _ => None,
    };
    MessageMeta {
        stamp_ns: Some(header.stamp_ns),
        encoding,
    }
}

/// The MCAP files of a bag: the file itself, or the `.mcap` files of a rosbag2 directory in
/// name order (rosbag2 numbers its split files `NAME_0.mcap`, `NAME_1.mcap`, …).
fn bag_files(path: &Path) -> Result<Vec<PathBuf>> {
    let db3 = |p: &Path| {
        IoError::Format {
        path: p.to_path_buf(),
        message: "is a rosbag2 SQLite bag (.db3), which visnav does not read: convert it to MCAP with `ros2 bag convert -i BAG -o out.yaml`, out.yaml holding `output_bags: [{uri: BAG_mcap, storage_id: mcap}]`".into(),
    }
    };
    if !path.exists() {
        return Err(IoError::NotFound {
            path: path.to_path_buf(),
            what: "ROS 2 bag (.mcap file or rosbag2 directory)".into(),
        });
    }
    let has_ext = |p: &Path, e: &str| {
        p.extension()
            .and_then(|x| x.to_str())
            .is_some_and(|x| x.eq_ignore_ascii_case(e))
    };
    if !path.is_dir() {
        if has_ext(path, "db3") {
            return Err(db3(path));
        }
        return Ok(vec![path.to_path_buf()]);
    }
    let mut files = Vec::new();
    let mut sqlite = None;
    for entry in std::fs::read_dir(path).map_err(|e| IoError::io(path, e))? {
        let p = entry.map_err(|e| IoError::io(path, e))?.path();
        if has_ext(&p, "mcap") {
            files.push(p);
        } else if has_ext(&p, "db3") {
            sqlite = Some(p);
        }
    }
    if files.is_empty() {
        return Err(match sqlite {
            Some(p) => db3(&p),
            None => IoError::NotFound {
                path: path.to_path_buf(),
                what: ".mcap files of a rosbag2 directory".into(),
            },
        });
    }
    files.sort();
    Ok(files)
}
