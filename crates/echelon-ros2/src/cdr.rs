//! A little-endian CDR (XCDR1, "plain CDR") reader and writer: what Fast-CDR
//! produces for ROS 2 messages and what `rclpy.serialization` and rmw_zenoh
//! exchange.
//!
//! A payload is the 4-byte encapsulation header [`ENCAPSULATION_CDR_LE`]
//! (`00 01` = CDR little-endian, then two option bytes) followed by the
//! fields in declaration order. Every primitive is aligned to its own size
//! *relative to the first byte after the header*, as Fast-CDR does. Padding
//! bytes are written as zeros but their content is ignored on reading:
//! Fast-CDR leaves them uninitialised. A string is a `u32` length counting
//! the terminating NUL, the UTF-8 bytes and the NUL.
//!
//! The reader never panics: every way a payload can be wrong is a
//! [`CdrError`] naming the field.

/// Encapsulation header of a little-endian CDR payload: `00 01` (CDR_LE) and
/// two option bytes (zero when written; ignored when read).
pub const ENCAPSULATION_CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// The longest string accepted, in bytes including the NUL. Frame ids are
/// short; a longer length is garbage, not a name.
pub const MAX_STRING_LEN: u32 = 4096;

/// Why a CDR payload was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    /// The payload ends before a field.
    #[error("truncated CDR: {field} needs {needed} bytes at offset {offset}, {available} left")]
    Truncated {
        /// The field being read.
        field: &'static str,
        /// Its offset from the start of the payload (header included).
        offset: usize,
        /// Bytes it needs.
        needed: usize,
        /// Bytes left.
        available: usize,
    },
    /// The encapsulation id is not CDR little-endian (`00 01`).
    #[error("encapsulation id {:02x} {:02x}, expected CDR little-endian 00 01", found[0], found[1])]
    WrongEncapsulation {
        /// The first two bytes of the payload.
        found: [u8; 2],
    },
    /// A string length over [`MAX_STRING_LEN`].
    #[error("{field}: string length {len} exceeds {MAX_STRING_LEN}")]
    StringTooLong {
        /// The field.
        field: &'static str,
        /// The length read.
        len: u32,
    },
    /// A string whose last byte is not NUL.
    #[error("{field}: string is not NUL-terminated")]
    MissingNul {
        /// The field.
        field: &'static str,
    },
    /// A string with a NUL before its end.
    #[error("{field}: string contains a NUL before its end")]
    InteriorNul {
        /// The field.
        field: &'static str,
    },
    /// A string that is not UTF-8.
    #[error("{field}: string is not UTF-8")]
    NotUtf8 {
        /// The field.
        field: &'static str,
    },
    /// A `bool` byte that is neither 0 nor 1 (Fast-CDR refuses it too).
    #[error("{field}: byte {value} is not a bool (0 or 1)")]
    NotBool {
        /// The field.
        field: &'static str,
        /// The byte read.
        value: u8,
    },
    /// A sequence longer than the bytes left could hold (every element
    /// takes at least one byte): garbage, never allocated for.
    #[error("{field}: sequence of {len} elements, only {available} bytes left")]
    SequenceTooLong {
        /// The field.
        field: &'static str,
        /// The length read.
        len: u32,
        /// Bytes left after it.
        available: usize,
    },
    /// A NaN or infinite number where the caller needs a finite one.
    #[error("{field} is not finite")]
    NonFinite {
        /// The field.
        field: &'static str,
    },
}

/// Writes one CDR little-endian payload into a reusable buffer.
#[derive(Debug)]
pub struct CdrWriter<'a> {
    buf: &'a mut Vec<u8>,
}

impl<'a> CdrWriter<'a> {
    /// Clears `buf` (keeping its allocation) and writes the encapsulation header.
    pub fn new(buf: &'a mut Vec<u8>) -> CdrWriter<'a> {
        buf.clear();
        buf.extend_from_slice(&ENCAPSULATION_CDR_LE);
        CdrWriter { buf }
    }

    /// Zero padding up to a multiple of `n` after the header.
    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - ENCAPSULATION_CDR_LE.len();
        let pad = (n - pos % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    /// A `bool` (one byte, 0 or 1).
    pub fn write_bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }

    /// A `uint8`.
    pub fn write_u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// The length of an unbounded sequence (its elements follow).
    pub fn write_sequence_len(&mut self, n: usize) {
        // A sequence of more than u32::MAX elements cannot be in memory here.
        self.write_u32(u32::try_from(n).unwrap_or(u32::MAX));
    }

    /// An `int32`.
    pub fn write_i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `uint32`.
    pub fn write_u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `float64`.
    pub fn write_f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `string`: length with the NUL, bytes, NUL.
    pub fn write_string(&mut self, s: &str) {
        // A frame id longer than u32::MAX bytes cannot exist in memory here.
        self.write_u32(u32::try_from(s.len() + 1).unwrap_or(u32::MAX));
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
}

/// Reads one CDR little-endian payload.
#[derive(Debug, Clone)]
pub struct CdrReader<'a> {
    data: &'a [u8],
    /// Absolute position in `data`.
    pos: usize,
}

impl<'a> CdrReader<'a> {
    /// Checks the encapsulation header; the option bytes are ignored.
    pub fn new(data: &'a [u8]) -> Result<CdrReader<'a>, CdrError> {
        if data.len() < ENCAPSULATION_CDR_LE.len() {
            return Err(CdrError::Truncated {
                field: "encapsulation header",
                offset: 0,
                needed: ENCAPSULATION_CDR_LE.len(),
                available: data.len(),
            });
        }
        if data[..2] != ENCAPSULATION_CDR_LE[..2] {
            return Err(CdrError::WrongEncapsulation {
                found: [data[0], data[1]],
            });
        }
        Ok(CdrReader {
            data,
            pos: ENCAPSULATION_CDR_LE.len(),
        })
    }

    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    /// Skips padding (whatever its content) to a multiple of `n` after the
    /// header, then takes `n` bytes.
    fn take<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], CdrError> {
        let rel = self.pos - ENCAPSULATION_CDR_LE.len();
        let start = self.pos + (N - rel % N) % N;
        let bytes = self
            .data
            .get(start..start + N)
            .and_then(|s| <[u8; N]>::try_from(s).ok())
            .ok_or(CdrError::Truncated {
                field,
                offset: start,
                needed: N,
                available: self.data.len().saturating_sub(start),
            })?;
        self.pos = start + N;
        Ok(bytes)
    }

    /// A `bool`: the byte 0 or 1, anything else refused.
    pub fn read_bool(&mut self, field: &'static str) -> Result<bool, CdrError> {
        match self.take::<1>(field)? {
            [0] => Ok(false),
            [1] => Ok(true),
            [value] => Err(CdrError::NotBool { field, value }),
        }
    }

    /// A `uint8`.
    pub fn read_u8(&mut self, field: &'static str) -> Result<u8, CdrError> {
        self.take::<1>(field).map(|[b]| b)
    }

    /// The length of an unbounded sequence, refused when the bytes left
    /// could not hold that many elements (so a forged length never makes
    /// the caller allocate).
    pub fn read_sequence_len(&mut self, field: &'static str) -> Result<usize, CdrError> {
        let len = self.read_u32(field)?;
        let available = self.remaining();
        if len as usize > available {
            return Err(CdrError::SequenceTooLong {
                field,
                len,
                available,
            });
        }
        Ok(len as usize)
    }

    /// An `int32`.
    pub fn read_i32(&mut self, field: &'static str) -> Result<i32, CdrError> {
        self.take::<4>(field).map(i32::from_le_bytes)
    }

    /// A `uint32`.
    pub fn read_u32(&mut self, field: &'static str) -> Result<u32, CdrError> {
        self.take::<4>(field).map(u32::from_le_bytes)
    }

    /// A `float64` (any bit pattern; see [`CdrError::NonFinite`] for refusing NaN).
    pub fn read_f64(&mut self, field: &'static str) -> Result<f64, CdrError> {
        self.take::<8>(field).map(f64::from_le_bytes)
    }

    /// A `string`. A zero length reads as the empty string, as Fast-CDR accepts it.
    pub fn read_string(&mut self, field: &'static str) -> Result<&'a str, CdrError> {
        let len = self.read_u32(field)?;
        if len > MAX_STRING_LEN {
            return Err(CdrError::StringTooLong { field, len });
        }
        if len == 0 {
            return Ok("");
        }
        let n = len as usize;
        let bytes = self
            .data
            .get(self.pos..self.pos + n)
            .ok_or(CdrError::Truncated {
                field,
                offset: self.pos,
                needed: n,
                available: self.remaining(),
            })?;
        let (text, nul) = bytes.split_at(n - 1);
        if nul != [0] {
            return Err(CdrError::MissingNul { field });
        }
        if text.contains(&0) {
            return Err(CdrError::InteriorNul { field });
        }
        let text = std::str::from_utf8(text).map_err(|_| CdrError::NotUtf8 { field })?;
        self.pos += n;
        Ok(text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alignment_is_relative_to_the_end_of_the_header() {
        let mut buf = Vec::new();
        let mut w = CdrWriter::new(&mut buf);
        w.write_u32(7);
        w.write_f64(1.5);
        w.write_string("ab");
        w.write_f64(-2.0);
        // Offsets after the 4-byte header: u32 at 0, pad to 8, f64 at 8,
        // string length at 16, "ab\0" at 20..23, pad to 24, f64 at 24.
        assert_eq!(&buf[..4], &ENCAPSULATION_CDR_LE);
        assert_eq!(&buf[4..8], &7u32.to_le_bytes());
        assert_eq!(&buf[8..12], &[0; 4]);
        assert_eq!(&buf[12..20], &1.5f64.to_le_bytes());
        assert_eq!(&buf[20..24], &3u32.to_le_bytes());
        assert_eq!(&buf[24..27], b"ab\0");
        assert_eq!(&buf[27..28], &[0]);
        assert_eq!(&buf[28..36], &(-2.0f64).to_le_bytes());
        assert_eq!(buf.len(), 36);

        let mut r = CdrReader::new(&buf).expect("header");
        assert_eq!(r.read_u32("a"), Ok(7));
        assert_eq!(r.read_f64("b"), Ok(1.5));
        assert_eq!(r.read_string("c"), Ok("ab"));
        assert_eq!(r.read_f64("d"), Ok(-2.0));
        assert_eq!(r.remaining(), 0);
    }

    #[test]
    fn padding_content_is_ignored() {
        let mut buf = Vec::new();
        let mut w = CdrWriter::new(&mut buf);
        w.write_u32(1);
        w.write_f64(3.25);
        buf[8..12].copy_from_slice(&[0xde, 0xad, 0xbe, 0xef]);
        let mut r = CdrReader::new(&buf).expect("header");
        assert_eq!(r.read_u32("a"), Ok(1));
        assert_eq!(r.read_f64("b"), Ok(3.25));
    }

    #[test]
    fn bad_headers_and_strings_are_refused_by_kind() {
        assert!(matches!(
            CdrReader::new(&[0, 1, 0]),
            Err(CdrError::Truncated { .. })
        ));
        assert_eq!(
            CdrReader::new(&[0, 0, 0, 0]).err(),
            Some(CdrError::WrongEncapsulation { found: [0, 0] })
        );
        let string = |len: u32, bytes: &[u8]| {
            let mut v = ENCAPSULATION_CDR_LE.to_vec();
            v.extend_from_slice(&len.to_le_bytes());
            v.extend_from_slice(bytes);
            v
        };
        let read =
            |v: &[u8]| CdrReader::new(v).and_then(|mut r| r.read_string("s").map(str::to_owned));
        assert_eq!(read(&string(3, b"ok\0")), Ok("ok".to_owned()));
        assert_eq!(read(&string(0, b"")), Ok(String::new()));
        assert_eq!(
            read(&string(3, b"okX")),
            Err(CdrError::MissingNul { field: "s" })
        );
        assert_eq!(
            read(&string(3, b"o\0\0")),
            Err(CdrError::InteriorNul { field: "s" })
        );
        assert_eq!(
            read(&string(3, b"\xff\xfe\0")),
            Err(CdrError::NotUtf8 { field: "s" })
        );
        assert_eq!(
            read(&string(u32::MAX, b"")),
            Err(CdrError::StringTooLong {
                field: "s",
                len: u32::MAX
            })
        );
        assert!(matches!(
            read(&string(10, b"short\0")),
            Err(CdrError::Truncated {
                field: "s",
                needed: 10,
                available: 6,
                ..
            })
        ));
    }
}
