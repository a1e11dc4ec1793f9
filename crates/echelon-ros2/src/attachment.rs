//! The attachment rmw_zenoh puts on every published sample; Jazzy's
//! subscriptions drop a sample without one ("Unable to obtain attachment").
//!
//! rmw_zenoh Jazzy 0.2.x (`attachment_helpers.cpp`) writes it with
//! zenoh-cpp's `ext::Serializer`: the sequence number (`int64`), the source
//! timestamp (`int64`, ns since the UNIX epoch) and the publisher GID, a
//! `std::array<uint8_t, 16>` that the serializer writes as a sequence: its
//! length as a LEB128 varint (one byte, 16) and the 16 bytes. 33 bytes in all:
//!
//! | offset | bytes | field |
//! |---|---|---|
//! | 0 | 8 | sequence number, i64 LE (rmw_zenoh starts at 1) |
//! | 8 | 8 | source timestamp, i64 LE, ns |
//! | 16 | 1 | GID length, 16 |
//! | 17 | 16 | publisher GID |

/// Length of an encoded attachment.
pub const ATTACHMENT_LEN: usize = 33;
/// Length of a publisher GID (`RMW_GID_STORAGE_SIZE`).
pub const GID_LEN: usize = 16;

/// A publisher GID.
pub type Gid = [u8; GID_LEN];

/// The metadata of one published sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    /// Per publisher, +1 per sample.
    pub sequence_number: i64,
    /// Publication time, ns since the UNIX epoch.
    pub source_timestamp_ns: i64,
    /// The publisher's GID.
    pub gid: Gid,
}

/// Why an attachment was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum AttachmentError {
    /// Not 33 bytes.
    #[error("attachment of {0} bytes, expected {ATTACHMENT_LEN}")]
    Length(usize),
    /// The GID length byte is not 16.
    #[error("attachment GID length byte {0}, expected {GID_LEN}")]
    GidLength(u8),
}

impl Attachment {
    /// The 33 bytes.
    pub fn encode(&self) -> [u8; ATTACHMENT_LEN] {
        let mut out = [0u8; ATTACHMENT_LEN];
        out[..8].copy_from_slice(&self.sequence_number.to_le_bytes());
        out[8..16].copy_from_slice(&self.source_timestamp_ns.to_le_bytes());
        out[16] = GID_LEN as u8;
        out[17..].copy_from_slice(&self.gid);
        out
    }

    /// Reads the 33 bytes.
    pub fn decode(bytes: &[u8]) -> Result<Attachment, AttachmentError> {
        let bytes: &[u8; ATTACHMENT_LEN] = bytes
            .try_into()
            .map_err(|_| AttachmentError::Length(bytes.len()))?;
        if usize::from(bytes[16]) != GID_LEN {
            return Err(AttachmentError::GidLength(bytes[16]));
        }
        let mut seq = [0u8; 8];
        seq.copy_from_slice(&bytes[..8]);
        let mut ts = [0u8; 8];
        ts.copy_from_slice(&bytes[8..16]);
        let mut gid = [0u8; GID_LEN];
        gid.copy_from_slice(&bytes[17..]);
        Ok(Attachment {
            sequence_number: i64::from_le_bytes(seq),
            source_timestamp_ns: i64::from_le_bytes(ts),
            gid,
        })
    }
}

/// A stable GID for a publisher, derived from its liveliness token (two
/// FNV-1a 64-bit hashes with different offsets). rmw_zenoh derives its own
/// GIDs as XXH3-128 of the token; its subscriptions only pass the
/// attachment's GID on as `message_info.publisher_gid` and do not compare
/// it with the token, so any GID unique per publisher works.
pub fn gid_from_token(token: &str) -> Gid {
    fn fnv1a(offset: u64, bytes: &[u8]) -> u64 {
        bytes.iter().fold(offset, |h, &b| {
            (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
        })
    }
    let lo = fnv1a(0xcbf2_9ce4_8422_2325, token.as_bytes());
    let hi = fnv1a(0x6c62_272e_07bb_0142, token.as_bytes());
    let mut gid = [0u8; GID_LEN];
    gid[..8].copy_from_slice(&lo.to_le_bytes());
    gid[8..].copy_from_slice(&hi.to_le_bytes());
    gid
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_layout_is_two_i64_a_length_byte_and_the_gid() {
        let a = Attachment {
            sequence_number: 1,
            source_timestamp_ns: -2,
            gid: core::array::from_fn(|i| i as u8 + 0xa0),
        };
        let bytes = a.encode();
        assert_eq!(&bytes[..8], &[1, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(
            &bytes[8..16],
            &[0xfe, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff]
        );
        assert_eq!(bytes[16], 16);
        assert_eq!(bytes[17], 0xa0);
        assert_eq!(bytes[32], 0xaf);
        assert_eq!(Attachment::decode(&bytes), Ok(a));
        assert_eq!(
            Attachment::decode(&bytes[..32]),
            Err(AttachmentError::Length(32))
        );
        let mut bad = bytes;
        bad[16] = 15;
        assert_eq!(
            Attachment::decode(&bad),
            Err(AttachmentError::GidLength(15))
        );
    }

    #[test]
    fn gids_differ_between_tokens() {
        assert_ne!(
            gid_from_token("@ros2_lv/0/a/0/1/MP"),
            gid_from_token("@ros2_lv/0/a/0/2/MP")
        );
        assert_eq!(gid_from_token("x"), gid_from_token("x"));
    }
}
