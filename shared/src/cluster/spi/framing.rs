//! The framing both ends share: the header and trailer phases, the DMA bank, CRC-16.

use crate::cluster::profile::LinkProfile;
use crate::cluster::wire::MAX_MESSAGE;

/// Bytes of the header phase: the firmware's board's ([`LinkProfile::F407`]).
pub const HEADER: usize = LinkProfile::F407.header_bytes as usize;
/// Bytes of the trailer phase (exchange only): the firmware's board's.
pub const TRAILER: usize = LinkProfile::F407.trailer_bytes as usize;
/// Size of one DMA bank: header, the largest frame, trailer, rounded up to a word.
pub const BANK: usize = LinkProfile::F407.dma_bank_bytes();
/// One DMA bank. On the STM32F4 banks must sit in SRAM (DMA cannot reach the CCM).
pub type Bank = [u8; BANK];
const _: () = assert!(BANK >= HEADER + MAX_MESSAGE + TRAILER && BANK.is_multiple_of(4));
// The header's layout (magic, kind, length u16, body CRC-16, header CRC-16) fills it.
const _: () = assert!(HEADER == 1 + 1 + 2 + 2 + 2);
// The trailer is one ACK/NAK byte.
const _: () = assert!(TRAILER == 1);

/// Trailer byte: the node's frame arrived intact.
pub const ACK: u8 = 0xAC;
/// Trailer byte: the node's frame was malformed; send it again (the retransmit request).
pub const NAK: u8 = 0x4E;

pub(super) const RC_MAGIC: u8 = 0xA5;
pub(super) const NC_MAGIC: u8 = 0x5A;
pub(super) const KIND_EXCHANGE: u8 = 1;
pub(super) const KIND_BROADCAST: u8 = 2;
/// Node header flag: a frame is posted (the header's length is its length).
pub(super) const FLAG_POSTED: u8 = 1;

/// CRC-16 of the header and the body (CRC-16/CCITT-FALSE as CRC_16_IBM_3740).
pub const CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);

/// What a port could not do (a DMA or bus error). The protocol treats it like a garbled
/// transfer: counted, and the transfer's frames are sent again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PortError;

/// A decoded header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Header {
    /// RC: 1 = exchange, 2 = broadcast. NC: flags (bit 0 = a frame is posted).
    pub kind: u8,
    pub len: u16,
    pub body_crc: u16,
}

pub(super) fn put_header(out: &mut [u8], magic: u8, kind: u8, body: &[u8]) {
    if out.len() < HEADER {
        return;
    }
    let len = body.len().min(u16::MAX as usize) as u16;
    let crc = CRC16.checksum(body);
    out[0] = magic;
    out[1] = kind;
    out[2..4].copy_from_slice(&len.to_le_bytes());
    out[4..6].copy_from_slice(&crc.to_le_bytes());
    let hcrc = CRC16.checksum(&out[..6]);
    out[6..8].copy_from_slice(&hcrc.to_le_bytes());
}

pub(super) fn get_header(bytes: &[u8], magic: u8) -> Option<Header> {
    let h = bytes.get(..HEADER)?;
    if h[0] != magic || CRC16.checksum(&h[..6]) != u16::from_le_bytes([h[6], h[7]]) {
        return None;
    }
    let len = u16::from_le_bytes([h[2], h[3]]);
    if len as usize > MAX_MESSAGE {
        return None;
    }
    Some(Header {
        kind: h[1],
        len,
        body_crc: u16::from_le_bytes([h[4], h[5]]),
    })
}

/// Encode the RC's header for a body (exposed for tests and tools).
pub fn rc_header(broadcast: bool, body: &[u8]) -> [u8; HEADER] {
    let mut h = [0u8; HEADER];
    let kind = if broadcast {
        KIND_BROADCAST
    } else {
        KIND_EXCHANGE
    };
    put_header(&mut h, RC_MAGIC, kind, body);
    h
}

/// Decode a node's header (exposed for tests and tools).
pub fn nc_header(bytes: &[u8]) -> Option<Header> {
    get_header(bytes, NC_MAGIC)
}

pub(super) fn body_ok(bank: &[u8], h: &Header) -> bool {
    bank.get(HEADER..HEADER + h.len as usize)
        .is_some_and(|b| CRC16.checksum(b) == h.body_crc)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_round_trip_and_reject_damage() {
        let body = [1u8, 2, 3, 4, 5];
        let h = rc_header(false, &body);
        let got = get_header(&h, RC_MAGIC).expect("valid");
        assert_eq!(got.kind, KIND_EXCHANGE);
        assert_eq!(got.len, 5);
        assert_eq!(got.body_crc, CRC16.checksum(&body));
        for bit in 0..HEADER * 8 {
            let mut d = h;
            d[bit / 8] ^= 1 << (bit % 8);
            assert_eq!(get_header(&d, RC_MAGIC), None, "bit {bit}");
        }
        assert_eq!(get_header(&h[..7], RC_MAGIC), None);
        assert_eq!(nc_header(&h), None, "an RC header is no node header");
        // A length beyond a frame is refused even with a valid CRC.
        let mut big = [0u8; HEADER];
        big[0] = NC_MAGIC;
        big[2..4].copy_from_slice(&(MAX_MESSAGE as u16 + 1).to_le_bytes());
        let c = CRC16.checksum(&big[..6]).to_le_bytes();
        big[6..8].copy_from_slice(&c);
        assert_eq!(nc_header(&big), None);
    }
}
