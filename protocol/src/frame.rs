//! The binary frame message: a fixed little-endian header, per-stage timings, then the image.
//!
//! ```text
//! offset size  field
//!      0    4  magic "LCFR"
//!      4    2  format version (1)
//!      6    2  header length in bytes (the payload starts here)
//!      8    8  sequence number (per session, from 1)
//!     16    8  input id: the last client input the frame shows (0: none)
//!     24    8  render start, server clock, µs since the Unix epoch
//!     32    8  send time, server clock, µs since the Unix epoch
//!     40    4  width
//!     44    4  height
//!     48    1  codec (0 JPEG, 1 PNG, 2 H.264: one Annex B access unit)
//!     49    1  flags (bit 0 still, bit 1 GI pending: direct light only, bit 2 moving,
//!                     bit 3 keyframe: an H.264 IDR access unit a decoder can start from)
//!     50    1  stage count N
//!     51    1  JPEG quality (0 for PNG)
//!     52    4  f32 encode ms
//!     56    4  f32 readback ms (waiting for the GPU copy to be mapped)
//!     60    4  f32 GPU ms of all stages
//!     64    4  payload length in bytes
//!     68  8·N  per stage: u16 index into `/v1/server`'s `stages`, u16 flags (bit 0 reused:
//!                its output came from an earlier frame made from the same inputs, no GPU
//!                work this frame; bits 8–15 shared: the number of sessions whose frames its
//!                output serves, made once for them all, so each frame's share of the ms its
//!                maker reports is that over this number, 0 for this frame alone; all 0 from
//!                servers before them), f32 GPU ms
//! 68+8N    4  samples per pixel accumulated so far (progressive methods: `reference`; else 0)
//! 72+8N    4  f32 relative standard error of that accumulation (0 when not progressive)
//! ```
//! A reader must use the header length to find the payload, so later versions can append
//! fields. The two fields after the stage list were appended that way: a header without them
//! (an older server) reads as 0 samples.

use crate::Codec;

pub const FRAME_MAGIC: [u8; 4] = *b"LCFR";
pub const FRAME_VERSION: u16 = 1;
const FIXED_LEN: usize = 68;
const STAGE_LEN: usize = 8;
/// Bytes of the fields appended after the stage list (samples, relative error).
const PROGRESS_LEN: usize = 8;

pub const FLAG_STILL: u8 = 1;
pub const FLAG_GI_PENDING: u8 = 2;
pub const FLAG_MOVING: u8 = 4;
/// An H.264 keyframe (IDR access unit with SPS and PPS): a decoder can start here.
pub const FLAG_KEYFRAME: u8 = 8;
/// A stage's flag: its output was reused from an earlier frame (see [`FrameHeader::reused`]).
pub const STAGE_REUSED: u16 = 1;
/// Where a stage's flags hold the sessions its output serves (see [`FrameHeader::shared`]).
pub const STAGE_SHARED_SHIFT: u16 = 8;

/// The decoded header of a binary frame message.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameHeader {
    pub seq: u64,
    pub input_id: u64,
    pub render_start_us: u64,
    pub send_us: u64,
    pub width: u32,
    pub height: u32,
    pub codec: Codec,
    pub flags: u8,
    pub quality: u8,
    pub encode_ms: f32,
    pub readback_ms: f32,
    pub gpu_ms: f32,
    pub payload_len: u32,
    /// (index into `/v1/server`'s `stages`, GPU ms).
    pub stages: Vec<(u16, f32)>,
    /// The stage indices (as in `stages`) whose output was reused from an earlier frame with
    /// the same inputs (their ms are 0): work the server shared between frames. Decoded one
    /// per flagged entry of `stages`.
    pub reused: Vec<u16>,
    /// The stage indices (as in `stages`) whose output serves several sessions' frames, each
    /// with how many (at most 255): made once for them all by one of those frames, which
    /// reports its whole ms, while the others reuse it. Each frame's share of the cost is the
    /// maker's ms over the count.
    pub shared: Vec<(u16, u8)>,
    /// Samples per pixel a progressive method has accumulated for this image (0: the method
    /// is not progressive).
    pub samples: u32,
    /// Mean relative standard error of the accumulated indirect light (0 when not
    /// progressive).
    pub relative_error: f32,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FrameHeaderError {
    #[error("frame message of {0} bytes is shorter than its header")]
    Short(usize),
    #[error("not a lightcast frame (bad magic)")]
    Magic,
    #[error("frame format version {0} is newer than this client understands ({FRAME_VERSION})")]
    Version(u16),
    #[error("header length {header} does not fit the {stages} stages it lists")]
    HeaderLength { header: usize, stages: usize },
    #[error("payload length {declared} differs from the {actual} bytes that follow the header")]
    PayloadLength { declared: usize, actual: usize },
    #[error("unknown codec {0}")]
    Codec(u8),
}

impl FrameHeader {
    pub fn header_len(&self) -> usize {
        FIXED_LEN + STAGE_LEN * self.stages.len().min(usize::from(u8::MAX)) + PROGRESS_LEN
    }

    /// Writes the header followed by `payload` (whose length replaces `payload_len`).
    pub fn encode_with(&self, payload: &[u8]) -> Vec<u8> {
        let stages = &self.stages[..self.stages.len().min(usize::from(u8::MAX))];
        let header_len = FIXED_LEN + STAGE_LEN * stages.len() + PROGRESS_LEN;
        let mut out = Vec::with_capacity(header_len + payload.len());
        out.extend_from_slice(&FRAME_MAGIC);
        out.extend_from_slice(&FRAME_VERSION.to_le_bytes());
        out.extend_from_slice(&(header_len as u16).to_le_bytes());
        for v in [self.seq, self.input_id, self.render_start_us, self.send_us] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&self.width.to_le_bytes());
        out.extend_from_slice(&self.height.to_le_bytes());
        out.push(self.codec.wire());
        out.push(self.flags);
        out.push(stages.len() as u8);
        out.push(self.quality);
        for v in [self.encode_ms, self.readback_ms, self.gpu_ms] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        for &(index, ms) in stages {
            out.extend_from_slice(&index.to_le_bytes());
            let reused = if self.reused.contains(&index) {
                STAGE_REUSED
            } else {
                0
            };
            let sessions = self
                .shared
                .iter()
                .find(|(i, _)| *i == index)
                .map_or(0, |&(_, n)| u16::from(n));
            let flags = reused | sessions << STAGE_SHARED_SHIFT;
            out.extend_from_slice(&flags.to_le_bytes());
            out.extend_from_slice(&ms.to_le_bytes());
        }
        out.extend_from_slice(&self.samples.to_le_bytes());
        out.extend_from_slice(&self.relative_error.to_le_bytes());
        out.extend_from_slice(payload);
        out
    }

    /// Overwrites the send time of an encoded message in place (set just before sending).
    pub fn patch_send_time(message: &mut [u8], send_us: u64) {
        if message.len() >= 40 {
            message[32..40].copy_from_slice(&send_us.to_le_bytes());
        }
    }

    /// Splits a binary message into its header and payload.
    pub fn decode(message: &[u8]) -> Result<(Self, &[u8]), FrameHeaderError> {
        if message.len() < FIXED_LEN {
            return Err(FrameHeaderError::Short(message.len()));
        }
        if message[0..4] != FRAME_MAGIC {
            return Err(FrameHeaderError::Magic);
        }
        let u16_at = |o: usize| u16::from_le_bytes([message[o], message[o + 1]]);
        let u32_at = |o: usize| {
            u32::from_le_bytes([message[o], message[o + 1], message[o + 2], message[o + 3]])
        };
        let u64_at = |o: usize| u64::from(u32_at(o)) | (u64::from(u32_at(o + 4)) << 32);
        let f32_at = |o: usize| f32::from_bits(u32_at(o));
        let version = u16_at(4);
        if version > FRAME_VERSION {
            return Err(FrameHeaderError::Version(version));
        }
        let header_len = usize::from(u16_at(6));
        let stage_count = usize::from(message[50]);
        if header_len < FIXED_LEN + STAGE_LEN * stage_count || header_len > message.len() {
            return Err(FrameHeaderError::HeaderLength {
                header: header_len,
                stages: stage_count,
            });
        }
        let codec = Codec::from_wire(message[48]).ok_or(FrameHeaderError::Codec(message[48]))?;
        let payload = &message[header_len..];
        let payload_len = u32_at(64);
        if payload_len as usize != payload.len() {
            return Err(FrameHeaderError::PayloadLength {
                declared: payload_len as usize,
                actual: payload.len(),
            });
        }
        let stages: Vec<(u16, f32)> = (0..stage_count)
            .map(|i| {
                let o = FIXED_LEN + STAGE_LEN * i;
                (u16_at(o), f32_at(o + 4))
            })
            .collect();
        let reused = (0..stage_count)
            .map(|i| FIXED_LEN + STAGE_LEN * i)
            .filter(|&o| u16_at(o + 2) & STAGE_REUSED != 0)
            .map(u16_at)
            .collect();
        let shared = (0..stage_count)
            .map(|i| FIXED_LEN + STAGE_LEN * i)
            .map(|o| (u16_at(o), (u16_at(o + 2) >> STAGE_SHARED_SHIFT) as u8))
            .filter(|&(_, n)| n > 0)
            .collect();
        let progress = FIXED_LEN + STAGE_LEN * stage_count;
        let (samples, relative_error) = if header_len >= progress + PROGRESS_LEN {
            (u32_at(progress), f32_at(progress + 4))
        } else {
            (0, 0.0)
        };
        let header = Self {
            seq: u64_at(8),
            input_id: u64_at(16),
            render_start_us: u64_at(24),
            send_us: u64_at(32),
            width: u32_at(40),
            height: u32_at(44),
            codec,
            flags: message[49],
            quality: message[51],
            encode_ms: f32_at(52),
            readback_ms: f32_at(56),
            gpu_ms: f32_at(60),
            payload_len,
            stages,
            reused,
            shared,
            samples,
            relative_error,
        };
        Ok((header, payload))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A header of a server from before the progress fields still decodes, as 0 samples.
    #[test]
    fn headers_without_progress_fields_decode() {
        let h = header();
        let mut bytes = h.encode_with(b"image");
        let end = h.header_len();
        bytes.drain(end - PROGRESS_LEN..end);
        bytes[6..8].copy_from_slice(&((end - PROGRESS_LEN) as u16).to_le_bytes());
        let (back, payload) = FrameHeader::decode(&bytes).expect("decodes");
        assert_eq!((back.samples, back.relative_error), (0, 0.0));
        assert_eq!(back.stages, h.stages);
        assert_eq!(payload, b"image");
    }

    fn header() -> FrameHeader {
        FrameHeader {
            seq: 42,
            input_id: 7,
            render_start_us: 1_700_000_000_000_001,
            send_us: 1_700_000_000_000_999,
            width: 320,
            height: 180,
            codec: Codec::Png,
            flags: FLAG_STILL | FLAG_MOVING,
            quality: 0,
            encode_ms: 1.5,
            readback_ms: 0.25,
            gpu_ms: 3.75,
            payload_len: 5,
            stages: vec![(0, 0.5), (12, 0.125), (2, 0.0)],
            reused: vec![2],
            shared: vec![(2, 16)],
            samples: 96,
            relative_error: 0.03125,
        }
    }

    #[test]
    fn round_trips_with_documented_offsets() {
        let h = header();
        let bytes = h.encode_with(b"image");
        assert_eq!(&bytes[0..4], b"LCFR");
        assert_eq!(
            u16::from_le_bytes([bytes[6], bytes[7]]) as usize,
            68 + 24 + 8
        );
        assert_eq!(u32::from_le_bytes(bytes[92..96].try_into().unwrap()), 96);
        // Stage flags: the third stage's bit 0 (reused) and 16 sessions sharing it in bits
        // 8–15, the others' 0.
        let flags = |i: usize| u16::from_le_bytes([bytes[70 + 8 * i], bytes[71 + 8 * i]]);
        assert_eq!(
            [flags(0), flags(1), flags(2)],
            [0, 0, STAGE_REUSED | 16 << 8]
        );
        assert_eq!(u64::from_le_bytes(bytes[8..16].try_into().unwrap()), 42);
        assert_eq!(u32::from_le_bytes(bytes[40..44].try_into().unwrap()), 320);
        assert_eq!(bytes[48], 1);
        let (back, payload) = FrameHeader::decode(&bytes).expect("decodes");
        assert_eq!(back, h);
        assert_eq!(payload, b"image");
        assert_eq!(back.stages[1], (12, 0.125));
    }

    #[test]
    fn send_time_is_patched_in_place() {
        let mut bytes = header().encode_with(b"x");
        FrameHeader::patch_send_time(&mut bytes, 123);
        assert_eq!(FrameHeader::decode(&bytes).unwrap().0.send_us, 123);
    }

    #[test]
    fn rejects_truncated_and_foreign_messages() {
        let bytes = header().encode_with(b"image");
        assert_eq!(
            FrameHeader::decode(&bytes[..10]),
            Err(FrameHeaderError::Short(10))
        );
        assert!(matches!(
            FrameHeader::decode(&bytes[..bytes.len() - 1]),
            Err(FrameHeaderError::PayloadLength { .. })
        ));
        let mut bad = bytes.clone();
        bad[0] = b'X';
        assert_eq!(FrameHeader::decode(&bad), Err(FrameHeaderError::Magic));
        let mut newer = bytes;
        newer[4] = 9;
        assert_eq!(
            FrameHeader::decode(&newer),
            Err(FrameHeaderError::Version(9))
        );
    }
}
