//! OMG CDR (XCDR1, plain CDR as ROS 2 serialises its messages): a bounded reader for the three
//! message types visnav reads and a writer for the one it writes.
//!
//! A ROS 2 message in an MCAP file is a 4-byte encapsulation header (`00 01` little-endian,
//! `00 00` big-endian, then two option bytes) followed by the fields in declaration order, each
//! aligned to its own size (at most 8) relative to the end of the header. Strings are a `u32`
//! length counting the trailing NUL, then the bytes; sequences a `u32` count then the elements.
//!
//! Hand-written rather than a serde CDR crate: the layouts read here are fixed
//! (`std_msgs/Header`, `sensor_msgs/Image`, `CompressedImage`, `CameraInfo`), and a serde
//! decoder would read an image's `uint8[]` one element at a time. Every read is bounds-checked:
//! a corrupt length gives an error, never a panic or an allocation beyond the message.

/// Why a message could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    /// The message ends before a field.
    #[error("message ends at byte {len} while reading {field} (needs {need} more bytes)")]
    Truncated {
        /// Field being read.
        field: &'static str,
        /// Message length, bytes.
        len: usize,
        /// Bytes missing.
        need: usize,
    },
    /// The encapsulation header is not plain CDR.
    #[error("encapsulation {0:#06x} is not plain CDR (0x0000 big-endian or 0x0001 little-endian)")]
    Encapsulation(u16),
    /// A string is not UTF-8 or lacks its terminating NUL.
    #[error("field {0} is not a NUL-terminated UTF-8 string")]
    BadString(&'static str),
}

/// Reads CDR fields in order from one message.
#[derive(Debug)]
pub struct CdrReader<'a> {
    data: &'a [u8],
    /// Offset of the next byte, from the start of the message (header included).
    pos: usize,
    little_endian: bool,
}

/// Bytes of the encapsulation header before the first field.
const HEADER_BYTES: usize = 4;

impl<'a> CdrReader<'a> {
    /// A reader after the encapsulation header of `data`.
    ///
    /// # Errors
    /// A message shorter than the header, or an encapsulation other than plain CDR.
    pub fn new(data: &'a [u8]) -> Result<Self, CdrError> {
        let Some(head) = data.get(..HEADER_BYTES) else {
            return Err(CdrError::Truncated {
                field: "encapsulation header",
                len: data.len(),
                need: HEADER_BYTES - data.len(),
            });
        };
        let kind = u16::from_be_bytes([head[0], head[1]]);
        let little_endian = match kind {
            0x0000 => false,
            0x0001 => true,
            other => return Err(CdrError::Encapsulation(other)),
        };
        Ok(Self {
            data,
            pos: HEADER_BYTES,
            little_endian,
        })
    }

    /// The next `n` bytes after aligning to `align`.
    fn take(&mut self, n: usize, align: usize, field: &'static str) -> Result<&'a [u8], CdrError> {
        let rel = self.pos - HEADER_BYTES;
        let start = self.pos + (align - rel % align) % align;
        let end = start.checked_add(n).filter(|&e| e <= self.data.len());
        let Some(end) = end else {
            return Err(CdrError::Truncated {
                field,
                len: self.data.len(),
                need: start.saturating_add(n).saturating_sub(self.data.len()),
            });
        };
        self.pos = end;
        Ok(&self.data[start..end])
    }

    fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], CdrError> {
        let b = self.take(N, N, field)?;
        let mut out = [0u8; N];
        out.copy_from_slice(b);
        if !self.little_endian {
            out.reverse();
        }
        Ok(out)
    }

    /// A `uint8` / `bool`.
    ///
    /// # Errors
    /// The message ends.
    pub fn u8(&mut self, field: &'static str) -> Result<u8, CdrError> {
        Ok(self.take(1, 1, field)?[0])
    }

    /// A `uint32`.
    ///
    /// # Errors
    /// The message ends.
    pub fn u32(&mut self, field: &'static str) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.array::<4>(field)?))
    }

    /// An `int32`.
    ///
    /// # Errors
    /// The message ends.
    pub fn i32(&mut self, field: &'static str) -> Result<i32, CdrError> {
        Ok(i32::from_le_bytes(self.array::<4>(field)?))
    }

    /// A `float64`.
    ///
    /// # Errors
    /// The message ends.
    pub fn f64(&mut self, field: &'static str) -> Result<f64, CdrError> {
        Ok(f64::from_le_bytes(self.array::<8>(field)?))
    }

    /// A `string`.
    ///
    /// # Errors
    /// The message ends, or the bytes are not a NUL-terminated UTF-8 string.
    pub fn string(&mut self, field: &'static str) -> Result<String, CdrError> {
        let n = self.u32(field)? as usize;
        if n == 0 {
            // some writers encode the empty string without its NUL
            return Ok(String::new());
        }
        let bytes = self.take(n, 1, field)?;
        match bytes.split_last() {
            Some((0, text)) => std::str::from_utf8(text)
                .map(str::to_owned)
                .map_err(|_| CdrError::BadString(field)),
            _ => Err(CdrError::BadString(field)),
        }
    }

    /// A `uint8[]` (unbounded sequence), borrowed from the message.
    ///
    /// # Errors
    /// The message ends before the declared count.
    pub fn bytes(&mut self, field: &'static str) -> Result<&'a [u8], CdrError> {
        let n = self.u32(field)? as usize;
        self.take(n, 1, field)
    }

    /// A `float64[N]` (fixed array).
    ///
    /// # Errors
    /// The message ends.
    pub fn f64_array<const N: usize>(&mut self, field: &'static str) -> Result<[f64; N], CdrError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(field)?;
        }
        Ok(out)
    }

    /// A `float64[]` (unbounded sequence).
    ///
    /// # Errors
    /// The message ends before the declared count.
    pub fn f64_seq(&mut self, field: &'static str) -> Result<Vec<f64>, CdrError> {
        let n = self.u32(field)? as usize;
        let len = self.data.len();
        // bounded by the message: a corrupt count cannot allocate beyond it
        if n > len / 8 {
            return Err(CdrError::Truncated {
                field,
                len,
                need: n.saturating_mul(8).saturating_sub(len),
            });
        }
        (0..n).map(|_| self.f64(field)).collect()
    }
}

/// Writes CDR fields (little-endian) after the encapsulation header.
#[derive(Debug, Clone)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl CdrWriter {
    /// An empty little-endian message (header `00 01 00 00`).
    #[must_use]
    pub fn new() -> Self {
        Self {
            buf: vec![0, 1, 0, 0],
        }
    }

    fn align(&mut self, n: usize) {
        let rel = self.buf.len() - HEADER_BYTES;
        let pad = (n - rel % n) % n;
        self.buf.extend(std::iter::repeat_n(0u8, pad));
    }

    /// Appends a `uint8` / `bool`.
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// Appends a `uint8[]` (count, then the bytes).
    pub fn bytes(&mut self, v: &[u8]) {
        self.u32(u32::try_from(v.len()).unwrap_or(u32::MAX));
        self.buf.extend_from_slice(v);
    }

    /// Appends a `float64[]` (count, then the values).
    pub fn f64_seq(&mut self, v: &[f64]) {
        self.u32(u32::try_from(v.len()).unwrap_or(u32::MAX));
        for &x in v {
            self.f64(x);
        }
    }

    /// Appends a `uint32`.
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// Appends an `int32`.
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// Appends a `float64`.
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// Appends a `string` (with its NUL).
    ///
    /// # Panics
    /// Never for strings shorter than 4 GiB (the length is a `u32`).
    pub fn string(&mut self, s: &str) {
        let n = u32::try_from(s.len() + 1).unwrap_or(u32::MAX);
        self.u32(n);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// The serialised message.
    #[must_use]
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_with_alignment() {
        let mut w = CdrWriter::new();
        w.i32(-7);
        w.string("map");
        w.f64(1.25);
        w.u32(9);
        let bytes = w.finish();
        // after the 4-byte header: i32 0..4, length 4..8, "map\0" 8..12, padding to 16, f64
        // 16..24, u32 24..28
        assert_eq!(bytes.len(), 4 + 28);
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.i32("a").unwrap(), -7);
        assert_eq!(r.string("b").unwrap(), "map");
        assert_eq!(r.f64("c").unwrap(), 1.25);
        assert_eq!(r.u32("d").unwrap(), 9);
        assert!(matches!(r.u8("e"), Err(CdrError::Truncated { .. })));
    }

    #[test]
    fn big_endian_and_bad_input() {
        let be = [0u8, 0, 0, 0, 0, 0, 0, 5];
        assert_eq!(CdrReader::new(&be).unwrap().u32("x").unwrap(), 5);
        assert_eq!(
            CdrReader::new(&[0, 2, 0, 0]).unwrap_err(),
            CdrError::Encapsulation(2)
        );
        assert!(CdrReader::new(&[0, 1]).is_err());
        // a sequence claiming 4 G elements
        let huge = [0u8, 1, 0, 0, 0xff, 0xff, 0xff, 0xff];
        assert!(CdrReader::new(&huge).unwrap().bytes("data").is_err());
        assert!(CdrReader::new(&huge).unwrap().f64_seq("d").is_err());
        // a string without its NUL
        let s = [0u8, 1, 0, 0, 2, 0, 0, 0, b'a', b'b'];
        assert_eq!(
            CdrReader::new(&s).unwrap().string("s").unwrap_err(),
            CdrError::BadString("s")
        );
    }
}
