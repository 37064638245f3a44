//! An index of the messages of one or more MCAP files, built by one pass over their records,
//! and random access to a message by that index.
//!
//! The pass reads the record framing itself (`opcode: u8, length: u64, body`), decompresses
//! chunks itself (zstd, lz4) and hands each record body to the `mcap` crate's `parse_record`:
//! it needs the file offset of each chunk, which the crate's readers do not report; it must
//! survive a file cut short by a killed recorder (the records before the cut are kept, with a
//! warning); and the crate's chunk reader allocates whatever a corrupt length claims (found by
//! `tests/bag.rs`), where here every length is checked against the bytes that exist first. The
//! summary section is not needed, so an unindexed file works too. Memory holds one record body
//! at a time plus ~40 bytes a message.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use mcap::records::{Record, op};

use crate::error::{IoError, Result};

/// The 8 magic bytes at the start (and end) of an MCAP file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Largest record body read into memory, bytes (a chunk or an uncompressed image).
const MAX_RECORD_BYTES: u64 = 1 << 31;

/// A channel: topic, message type and encoding.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    /// Topic name (`/left/image_raw`).
    pub topic: String,
    /// Schema name, the ROS 2 message type (`sensor_msgs/msg/Image`).
    pub message_type: String,
    /// Message encoding (`cdr` for ROS 2).
    pub message_encoding: String,
}

/// Where one message's bytes are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Location {
    /// A message record outside chunks: the body's offset and length.
    Record { offset: u64, len: u64 },
    /// The `ordinal`-th record of the chunk whose body starts at `offset`.
    InChunk { offset: u64, len: u64, ordinal: u32 },
}

/// One message of the index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageRef {
    file: usize,
    location: Location,
    /// `log_time` of the record, ns.
    pub log_time_ns: u64,
}

/// What the pass keeps of one message: its place and, via `inspect`, a small summary.
#[derive(Debug, Clone)]
pub struct IndexedMessage<T> {
    /// Where it is.
    pub at: MessageRef,
    /// What `inspect` returned for it.
    pub info: T,
}

/// The messages of a set of MCAP files, per topic, in file order.
#[derive(Debug)]
pub struct McapIndex<T> {
    files: Vec<PathBuf>,
    /// Channels by topic.
    pub channels: HashMap<String, ChannelInfo>,
    /// Messages by topic.
    pub messages: HashMap<String, Vec<IndexedMessage<T>>>,
    /// Files cut short (path and the byte where the last complete record ended).
    pub truncated: Vec<(PathBuf, u64)>,
    chunk_cache: Mutex<Option<CachedChunk>>,
}

/// The decompressed message bodies of the chunk read last (stereo pairs and consecutive frames
/// often share one).
#[derive(Debug)]
struct CachedChunk {
    file: usize,
    offset: u64,
    bodies: Arc<Vec<Option<Vec<u8>>>>,
}

/// The state of one pass.
struct Pass<'a, T> {
    file: usize,
    path: &'a Path,
    schemas: HashMap<u16, String>,
    by_id: HashMap<u16, ChannelInfo>,
    inspect: &'a dyn Fn(&ChannelInfo, &[u8]) -> T,
}

impl<T> McapIndex<T> {
    /// Indexes `files` in order, calling `inspect(channel, message bytes)` once per message.
    ///
    /// # Errors
    /// An unreadable file, a file that does not start with the MCAP magic, or a record that the
    /// `mcap` crate cannot parse (named with the file and byte offset).
    pub fn build(files: &[PathBuf], inspect: &dyn Fn(&ChannelInfo, &[u8]) -> T) -> Result<Self> {
        let mut index = Self {
            files: files.to_vec(),
            channels: HashMap::new(),
            messages: HashMap::new(),
            truncated: Vec::new(),
            chunk_cache: Mutex::new(None),
        };
        for (i, path) in files.iter().enumerate() {
            index.scan_file(i, path, inspect)?;
        }
        Ok(index)
    }

    fn scan_file(
        &mut self,
        file: usize,
        path: &Path,
        inspect: &dyn Fn(&ChannelInfo, &[u8]) -> T,
    ) -> Result<()> {
        let f = File::open(path).map_err(|e| IoError::io(path, e))?;
        let size = f.metadata().map_err(|e| IoError::io(path, e))?.len();
        let mut r = BufReader::with_capacity(1 << 20, f);
        let mut magic = [0u8; 8];
        if r.read_exact(&mut magic).is_err() || &magic != MAGIC {
            return Err(bad(path, 0, "not an MCAP file (no MCAP magic bytes)"));
        }
        let mut pass = Pass {
            file,
            path,
            schemas: HashMap::new(),
            by_id: HashMap::new(),
            inspect,
        };
        let mut pos = 8u64;
        loop {
            let mut head = [0u8; 9];
            if read_full(&mut r, &mut head).map_err(|e| IoError::io(path, e))? < 9 {
                self.truncated.push((path.to_path_buf(), pos));
                break;
            }
            let opcode = head[0];
            let len = u64::from_le_bytes(head[1..].try_into().unwrap_or([0; 8]));
            let body_at = pos + 9;
            if len > size.saturating_sub(body_at) {
                self.truncated.push((path.to_path_buf(), pos));
                break;
            }
            if opcode == op::DATA_END || opcode == op::FOOTER {
                break;
            }
            if matches!(opcode, op::CHUNK | op::SCHEMA | op::CHANNEL | op::MESSAGE) {
                let body = read_body(&mut r, len, path, body_at)?;
                self.record(&mut pass, opcode, &body, body_at, len)?;
            } else {
                r.seek_relative(i64::try_from(len).unwrap_or(i64::MAX))
                    .map_err(|e| IoError::io(path, e))?;
            }
            pos = body_at + len;
        }
        Ok(())
    }

    /// One top-level record.
    fn record(
        &mut self,
        pass: &mut Pass<'_, T>,
        opcode: u8,
        body: &[u8],
        offset: u64,
        len: u64,
    ) -> Result<()> {
        let record = mcap::parse_record(opcode, body)
            .map_err(|e| bad(pass.path, offset, &format!("record {opcode:#04x}: {e}")))?;
        if let Record::Chunk { header, data } = record {
            let records = decompress_chunk(&header, &data, pass.path, offset)?;
            for (ordinal, (op, body)) in framed_records(&records, pass.path, offset)?
                .into_iter()
                .enumerate()
            {
                let rec = mcap::parse_record(op, body)
                    .map_err(|e| bad(pass.path, offset, &format!("chunk record {op:#04x}: {e}")))?;
                let ordinal = u32::try_from(ordinal).unwrap_or(u32::MAX);
                self.inner(
                    pass,
                    rec,
                    Location::InChunk {
                        offset,
                        len,
                        ordinal,
                    },
                );
            }
        } else {
            self.inner(pass, record, Location::Record { offset, len });
        }
        Ok(())
    }

    /// A schema, channel or message record (inside a chunk or not).
    fn inner(&mut self, pass: &mut Pass<'_, T>, record: Record<'_>, location: Location) {
        match record {
            Record::Schema { header, .. } => {
                pass.schemas.insert(header.id, header.name);
            }
            Record::Channel(c) => {
                let info = ChannelInfo {
                    message_type: pass.schemas.get(&c.schema_id).cloned().unwrap_or_default(),
                    topic: c.topic,
                    message_encoding: c.message_encoding,
                };
                self.channels.insert(info.topic.clone(), info.clone());
                pass.by_id.insert(c.id, info);
            }
            Record::Message { header, data } => {
                let Some(channel) = pass.by_id.get(&header.channel_id) else {
                    log::warn!(
                        "{}: a message on channel {} that was never declared: ignored",
                        pass.path.display(),
                        header.channel_id
                    );
                    return;
                };
                let info = (pass.inspect)(channel, &data);
                self.messages
                    .entry(channel.topic.clone())
                    .or_default()
                    .push(IndexedMessage {
                        at: MessageRef {
                            file: pass.file,
                            location,
                            log_time_ns: header.log_time,
                        },
                        info,
                    });
            }
            _ => {}
        }
    }

    /// The path of the file a message is in.
    #[must_use]
    pub fn file_of(&self, at: &MessageRef) -> &Path {
        &self.files[at.file]
    }

    /// The bytes of one message.
    ///
    /// # Errors
    /// A read error, or a file changed since it was indexed.
    pub fn read(&self, at: &MessageRef) -> Result<Vec<u8>> {
        let path = &self.files[at.file];
        match at.location {
            Location::Record { offset, len } => {
                let body = read_at(path, offset, len)?;
                match mcap::parse_record(op::MESSAGE, &body) {
                    Ok(Record::Message { data, .. }) => Ok(data.into_owned()),
                    _ => Err(bad(path, offset, "message record changed since indexing")),
                }
            }
            Location::InChunk {
                offset,
                len,
                ordinal,
            } => {
                let bodies = self.chunk_bodies(at.file, offset, len)?;
                bodies
                    .get(ordinal as usize)
                    .and_then(Clone::clone)
                    .ok_or_else(|| bad(path, offset, "chunk changed since indexing"))
            }
        }
    }

    /// The message bodies of one chunk, from the cache or decompressed anew.
    fn chunk_bodies(
        &self,
        file: usize,
        offset: u64,
        len: u64,
    ) -> Result<Arc<Vec<Option<Vec<u8>>>>> {
        let mut cache = self
            .chunk_cache
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(c) = cache
            .as_ref()
            .filter(|c| c.file == file && c.offset == offset)
        {
            return Ok(Arc::clone(&c.bodies));
        }
        let path = &self.files[file];
        let body = read_at(path, offset, len)?;
        let chunk = mcap::parse_record(op::CHUNK, &body)
            .map_err(|e| bad(path, offset, &format!("chunk: {e}")))?;
        let Record::Chunk { header, data } = chunk else {
            return Err(bad(path, offset, "not a chunk"));
        };
        let records = decompress_chunk(&header, &data, path, offset)?;
        let mut bodies = Vec::new();
        for (op, body) in framed_records(&records, path, offset)? {
            bodies.push(match mcap::parse_record(op, body) {
                Ok(Record::Message { data, .. }) => Some(data.into_owned()),
                _ => None,
            });
        }
        let bodies = Arc::new(bodies);
        *cache = Some(CachedChunk {
            file,
            offset,
            bodies: Arc::clone(&bodies),
        });
        Ok(bodies)
    }
}

/// Largest ratio of a chunk's uncompressed to compressed size accepted (zstd reaches a few
/// hundred on blank images; a corrupt header claims far more).
const MAX_COMPRESSION_RATIO: u64 = 4096;

/// The records of a chunk, decompressed here rather than by the `mcap` crate, whose chunk
/// reader allocates whatever a corrupt header or record length claims: the uncompressed size
/// is checked against the stored one first and the output never exceeds it.
fn decompress_chunk(
    header: &mcap::records::ChunkHeader,
    data: &[u8],
    path: &Path,
    offset: u64,
) -> Result<Vec<u8>> {
    let stored = data.len() as u64;
    let claimed = header.uncompressed_size;
    let fail = |what: String| {
        bad(
            path,
            offset,
            &format!("chunk ({:?}): {what}", header.compression),
        )
    };
    let plausible = if header.compression.is_empty() {
        claimed == stored
    } else {
        claimed <= MAX_RECORD_BYTES && claimed <= stored.saturating_mul(MAX_COMPRESSION_RATIO)
    };
    if !plausible {
        return Err(fail(format!(
            "the header claims {claimed} bytes uncompressed from {stored} stored"
        )));
    }
    let capacity = usize::try_from(claimed).unwrap_or(0);
    let out = match header.compression.as_str() {
        "" => data.to_vec(),
        "zstd" => zstd::bulk::decompress(data, capacity).map_err(|e| fail(e.to_string()))?,
        "lz4" => {
            let mut out = Vec::with_capacity(capacity);
            let decoder = lz4::Decoder::new(data).map_err(|e| fail(e.to_string()))?;
            decoder
                .take(claimed + 1)
                .read_to_end(&mut out)
                .map_err(|e| fail(e.to_string()))?;
            out
        }
        other => return Err(fail(format!("unknown compression '{other}'"))),
    };
    if out.len() as u64 != claimed {
        return Err(fail(format!(
            "{} bytes uncompressed, the header says {claimed}",
            out.len()
        )));
    }
    Ok(out)
}

/// The `(opcode, body)` records of a decompressed chunk, lengths checked against the buffer.
fn framed_records<'a>(mut buf: &'a [u8], path: &Path, offset: u64) -> Result<Vec<(u8, &'a [u8])>> {
    let mut out = Vec::new();
    while !buf.is_empty() {
        let Some((head, rest)) = buf.split_first_chunk::<9>() else {
            return Err(bad(path, offset, "chunk ends inside a record header"));
        };
        let len = u64::from_le_bytes(head[1..].try_into().unwrap_or([0; 8]));
        let Some(body) = usize::try_from(len).ok().and_then(|n| rest.get(..n)) else {
            return Err(bad(
                path,
                offset,
                &format!("a chunk record of {len} bytes overruns the chunk"),
            ));
        };
        out.push((head[0], body));
        buf = &rest[body.len()..];
    }
    Ok(out)
}

fn bad(path: &Path, offset: u64, message: &str) -> IoError {
    IoError::Format {
        path: path.to_path_buf(),
        message: format!("at byte {offset}: {message}"),
    }
}

/// Reads as much of `buf` as the stream has; the count read.
fn read_full(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

fn read_body(r: &mut impl Read, len: u64, path: &Path, offset: u64) -> Result<Vec<u8>> {
    if len > MAX_RECORD_BYTES {
        return Err(bad(path, offset, &format!("a record of {len} bytes")));
    }
    let mut body = vec![0u8; usize::try_from(len).unwrap_or(0)];
    r.read_exact(&mut body).map_err(|e| IoError::io(path, e))?;
    Ok(body)
}

fn read_at(path: &Path, offset: u64, len: u64) -> Result<Vec<u8>> {
    let mut f = File::open(path).map_err(|e| IoError::io(path, e))?;
    f.seek(SeekFrom::Start(offset))
        .map_err(|e| IoError::io(path, e))?;
    read_body(&mut f, len, path, offset)
}
