//! Framing: [`encode_packet`] / [`Encoder`] write `0x00 ++ COBS(postcard ++ CRC-32) ++ 0x00`
//! frames, [`Decoder`] takes line bytes one at a time and yields each frame's [`Packet`].

use super::protocol::*;
use crate::wire::{CRC32, CRC_LEN};
use postcard::ser_flavors::{crc::CrcModifier, Cobs, Slice};
use serde::{Deserialize, Serialize};

/// Encode one packet into `out` as a complete frame (both delimiters); returns its length.
pub fn encode_packet<M: Serialize>(
    seq: u16,
    msg: &M,
    out: &mut [u8],
) -> Result<usize, SerialError> {
    let (first, rest) = out.split_first_mut().ok_or(SerialError::BufferFull)?;
    *first = 0;
    let packet = Packet {
        version: VERSION,
        seq,
        msg,
    };
    let cobs = Cobs::try_new(Slice::new(rest)).map_err(|_| SerialError::BufferFull)?;
    // CRC innermost: the CRC covers the postcard bytes and is stuffed with them.
    let used = postcard::serialize_with_flavor(&packet, CrcModifier::new(cobs, CRC32.digest()))
        .map_err(|_| SerialError::BufferFull)?;
    Ok(1 + used.len())
}

/// Decode a packet body (COBS already removed: postcard bytes ++ CRC-32), checking CRC and
/// version. The message borrows from `body`.
pub fn decode_body<'a, M: Deserialize<'a>>(body: &'a [u8]) -> Result<Packet<M>, SerialError> {
    if body.len() < CRC_LEN + 1 {
        return Err(SerialError::Truncated);
    }
    let (data, tail) = body.split_at(body.len() - CRC_LEN);
    let want = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
    if CRC32.checksum(data) != want {
        return Err(SerialError::BadCrc);
    }
    match data.first() {
        Some(&VERSION) => {}
        Some(&found) => return Err(SerialError::Version { found }),
        None => return Err(SerialError::Truncated),
    }
    let (packet, rest): (Packet<M>, &[u8]) =
        postcard::take_from_bytes(data).map_err(|_| SerialError::Malformed)?;
    if rest.is_empty() {
        Ok(packet)
    } else {
        Err(SerialError::Malformed)
    }
}

/// Numbers outgoing frames and writes them into caller buffers. One per direction of a
/// link (the RC's upload receiver and frame streamer share the RC's).
#[derive(Clone, Debug, Default)]
pub struct Encoder {
    seq: u16,
}

impl Encoder {
    pub const fn new() -> Self {
        Encoder { seq: 0 }
    }

    /// The sequence number the next frame will carry.
    pub fn next_seq(&self) -> u16 {
        self.seq
    }

    /// Encode `msg` ([`ToRc`] or [`ToPc`]) as a frame into `out`; returns its length. The
    /// sequence number advances only when the frame fits.
    pub fn encode<M: Serialize>(&mut self, msg: &M, out: &mut [u8]) -> Result<usize, SerialError> {
        let n = encode_packet(self.seq, msg, out)?;
        self.seq = self.seq.wrapping_add(1);
        Ok(n)
    }
}

/// Streaming frame decoder with room for `N` line bytes between delimiters (use
/// [`MAX_TO_RC`] on the RC, [`MAX_TO_PC`] on the PC).
pub struct Decoder<const N: usize> {
    buf: heapless::Vec<u8, N>,
    overflow: bool,
    /// The buffer holds the frame returned last; clear before the next byte.
    stale: bool,
    good: u32,
    bad: u32,
}

impl<const N: usize> Default for Decoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Decoder<N> {
    pub const fn new() -> Self {
        Decoder {
            buf: heapless::Vec::new(),
            overflow: false,
            stale: false,
            good: 0,
            bad: 0,
        }
    }

    /// Take one byte from the line. Returns `Some` when the byte ends a frame: the packet
    /// (borrowing from the decoder until the next call) or why the frame was bad. Empty
    /// frames (two delimiters in a row) return `None`. A frame longer than `N` is skipped
    /// up to the next delimiter and reported as [`SerialError::Oversize`].
    pub fn feed<'a, M: Deserialize<'a>>(
        &'a mut self,
        byte: u8,
    ) -> Option<Result<Packet<M>, SerialError>> {
        if self.stale {
            self.buf.clear();
            self.stale = false;
        }
        if byte != 0 {
            if !self.overflow && self.buf.push(byte).is_err() {
                self.overflow = true;
            }
            return None;
        }
        self.stale = true;
        if self.overflow {
            self.overflow = false;
            self.bad = self.bad.wrapping_add(1);
            return Some(Err(SerialError::Oversize));
        }
        if self.buf.is_empty() {
            return None;
        }
        let result = match cobs::decode_in_place(&mut self.buf) {
            Ok(n) => decode_body(self.buf.get(..n).unwrap_or(&[])),
            Err(_) => Err(SerialError::Cobs),
        };
        match result {
            Ok(_) => self.good = self.good.wrapping_add(1),
            Err(_) => self.bad = self.bad.wrapping_add(1),
        }
        Some(result)
    }

    /// Forget a partly received frame (e.g. after a line reset).
    pub fn reset(&mut self) {
        self.buf.clear();
        self.overflow = false;
        self.stale = false;
    }

    /// Frames decoded so far.
    pub fn good_packets(&self) -> u32 {
        self.good
    }

    /// Malformed frames seen so far (bad CRC, stuffing, version, layout, oversize).
    pub fn bad_packets(&self) -> u32 {
        self.bad
    }
}
