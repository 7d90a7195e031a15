//! The frames on a relay's link to its parent: a forwarded broadcast, or a batch of routed
//! node frames (up) and replies (down). Each is the body of one link frame (at most
//! [`MAX_MESSAGE`] bytes), so the relay link runs on the same banks and framing as any bus.
//!
//! ```text
//! forward  [TAG_FORWARD] root broadcast frame (re-broadcast unchanged on the relay's bus)
//! batch    [TAG_BATCH] waiting u32 LE | record* ;  record = kind u8, node u16 LE, len u16 LE, len bytes
//! ```
//! `waiting` (up; 0 down) has bit `i` set for the relay's `i`-th node when its ready line
//! is up and it waits to be asked (the parent then composes its reply). Records: a
//! [`Kind::Request`] (down) is the root's reply for a node, to clock in the node's next
//! exchange (a [`Kind::Ahead`] the same, sent before the node's line rose); a [`Kind::Frame`] (up) is what the node sent in that exchange; a
//! [`Kind::Forwarded`] (up, node 0, 2 bytes: u16 LE) is how many root broadcasts the relay
//! has passed on to its bus in this run (the root sends the next one only when each relay
//! has passed on all but one, so none is dropped for want of a receive bank). Decoding
//! checks every length against the frame and never panics.

use super::RelayError;
use crate::cluster::link::NodeId;
use crate::cluster::wire::MAX_MESSAGE;

/// First byte of a forwarded broadcast.
pub const TAG_FORWARD: u8 = 0xF0;
/// First byte of a batch.
pub const TAG_BATCH: u8 = 0xB7;
/// Bytes before a batch's records: the tag and the `waiting` bitmap.
pub const BATCH_HEADER: usize = 1 + 4;
/// Bytes of a record's header: kind, node, length.
pub const RECORD: usize = 1 + 2 + 2;
/// Most bytes of records (headers included) one relay-link exchange carries each way: what
/// one link frame holds after the batch header. The simulator's relay tree batches up to
/// this too (`host-sim/src/sim/cluster/relay.rs`).
pub const BATCH_BYTES: usize = MAX_MESSAGE - BATCH_HEADER;
/// The longest node frame or reply a batch can carry (alone in its batch).
pub const MAX_ROUTED: usize = BATCH_BYTES - RECORD;
/// Most nodes on one relay's bus (one bit of `waiting` each).
pub const MAX_RELAY_NODES: u16 = 32;

/// What a record carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Kind {
    /// Down: the root's reply for the node.
    Request,
    /// Up: the node's frame from the exchange that carried the reply (empty: nothing intact).
    Frame,
    /// Up: the root broadcasts the relay has passed on so far (u16 LE; node 0).
    Forwarded,
    /// Down: the root's reply for a node whose line is not up (yet): sent ahead, once
    /// ([`super::RelayedBus::with_ahead`]). A leaf relay holds it and clocks the node with
    /// it when its line rises; a middle relay begins the exchange with the leaf relay.
    Ahead,
}

impl Kind {
    const fn byte(self) -> u8 {
        match self {
            Kind::Request => 1,
            Kind::Frame => 2,
            Kind::Forwarded => 3,
            Kind::Ahead => 4,
        }
    }

    fn from_byte(b: u8) -> Result<Kind, RelayError> {
        match b {
            1 => Ok(Kind::Request),
            2 => Ok(Kind::Frame),
            3 => Ok(Kind::Forwarded),
            4 => Ok(Kind::Ahead),
            kind => Err(RelayError::UnknownKind { kind }),
        }
    }
}

/// One routed frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record<'a> {
    pub kind: Kind,
    pub node: NodeId,
    pub data: &'a [u8],
}

/// A relay-link frame, decoded.
#[derive(Clone, Debug)]
pub enum Relayed<'a> {
    /// A root broadcast to pass on.
    Forward(&'a [u8]),
    /// A batch: the `waiting` bitmap and its records.
    Batch { waiting: u32, records: Records<'a> },
}

/// Decode a relay-link frame.
pub fn parse(frame: &[u8]) -> Result<Relayed<'_>, RelayError> {
    match frame.split_first() {
        Some((&TAG_FORWARD, rest)) => Ok(Relayed::Forward(rest)),
        Some((&TAG_BATCH, rest)) => {
            let (w, records) = rest.split_at_checked(4).ok_or(RelayError::Truncated)?;
            let waiting = u32::from_le_bytes([w[0], w[1], w[2], w[3]]);
            Ok(Relayed::Batch {
                waiting,
                records: Records { rest: records },
            })
        }
        Some((&tag, _)) => Err(RelayError::UnknownTag { tag }),
        None => Err(RelayError::Truncated),
    }
}

/// The records of a batch, in order; the first malformed one ends it with its error.
#[derive(Clone, Debug)]
pub struct Records<'a> {
    rest: &'a [u8],
}

impl<'a> Iterator for Records<'a> {
    type Item = Result<Record<'a>, RelayError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.rest.is_empty() {
            return None;
        }
        let r = self.take();
        if r.is_err() {
            self.rest = &[];
        }
        Some(r)
    }
}

impl<'a> Records<'a> {
    fn take(&mut self) -> Result<Record<'a>, RelayError> {
        let (h, body) = self
            .rest
            .split_at_checked(RECORD)
            .ok_or(RelayError::Truncated)?;
        let kind = Kind::from_byte(h[0])?;
        let node = u16::from_le_bytes([h[1], h[2]]);
        let len = u16::from_le_bytes([h[3], h[4]]) as usize;
        let (data, rest) = body.split_at_checked(len).ok_or(RelayError::TooLong {
            len: len as u32,
            max: body.len() as u32,
        })?;
        self.rest = rest;
        Ok(Record { kind, node, data })
    }
}

/// Builds a batch in a buffer (at most [`MAX_MESSAGE`] bytes of it are used).
pub struct BatchWriter<'a> {
    buf: &'a mut [u8],
    len: usize,
    records: u16,
}

impl<'a> BatchWriter<'a> {
    /// An empty batch (`waiting` 0) in `buf`.
    pub fn new(buf: &'a mut [u8]) -> Result<Self, RelayError> {
        let cap = buf.len().min(MAX_MESSAGE);
        let buf = buf.get_mut(..cap).ok_or(RelayError::Full)?;
        let head = buf.get_mut(..BATCH_HEADER).ok_or(RelayError::Full)?;
        head.copy_from_slice(&[TAG_BATCH, 0, 0, 0, 0]);
        Ok(BatchWriter {
            buf,
            len: BATCH_HEADER,
            records: 0,
        })
    }

    pub fn set_waiting(&mut self, waiting: u32) {
        self.buf[1..BATCH_HEADER].copy_from_slice(&waiting.to_le_bytes());
    }

    /// Room left for record data after one more record header.
    pub fn room(&self) -> usize {
        (self.buf.len() - self.len).saturating_sub(RECORD)
    }

    pub fn records(&self) -> u16 {
        self.records
    }

    /// Append a record; [`RelayError::Full`] (nothing written) if it does not fit.
    pub fn push(&mut self, r: Record<'_>) -> Result<(), RelayError> {
        if self.buf.len() - self.len < RECORD + r.data.len() {
            return Err(RelayError::Full);
        }
        let at = self.len;
        let n = r.data.len();
        self.buf[at] = r.kind.byte();
        self.buf[at + 1..at + 3].copy_from_slice(&r.node.to_le_bytes());
        self.buf[at + 3..at + 5].copy_from_slice(&(n as u16).to_le_bytes());
        self.buf[at + RECORD..at + RECORD + n].copy_from_slice(r.data);
        self.len += RECORD + n;
        self.records += 1;
        Ok(())
    }

    /// The batch's bytes so far.
    pub fn bytes(&self) -> &[u8] {
        &self.buf[..self.len]
    }

    /// Empty it again (`waiting` 0).
    pub fn clear(&mut self) {
        self.len = BATCH_HEADER;
        self.records = 0;
        self.set_waiting(0);
    }
}

/// Write a forwarded broadcast of `frame` into `out`; its length.
pub fn forward(frame: &[u8], out: &mut [u8]) -> Result<usize, RelayError> {
    let n = frame.len() + 1;
    if n > MAX_MESSAGE {
        return Err(RelayError::TooLong {
            len: n as u32,
            max: MAX_MESSAGE as u32,
        });
    }
    let dst = out.get_mut(..n).ok_or(RelayError::Full)?;
    dst[0] = TAG_FORWARD;
    dst[1..].copy_from_slice(frame);
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_batch_round_trips_and_every_truncation_is_refused() {
        let mut buf = [0u8; MAX_MESSAGE];
        let mut w = BatchWriter::new(&mut buf).unwrap();
        w.set_waiting(0b1010);
        let a = [7u8; 300];
        w.push(Record {
            kind: Kind::Frame,
            node: 17,
            data: &a,
        })
        .unwrap();
        w.push(Record {
            kind: Kind::Request,
            node: 3,
            data: &[],
        })
        .unwrap();
        let bytes = w.bytes().to_vec();
        assert_eq!(bytes.len(), BATCH_HEADER + 2 * RECORD + 300);
        let Ok(Relayed::Batch { waiting, records }) = parse(&bytes) else {
            panic!("a batch")
        };
        assert_eq!(waiting, 0b1010);
        let got: Vec<_> = records.map(|r| r.unwrap()).collect();
        assert_eq!(got.len(), 2);
        assert_eq!(
            (got[0].kind, got[0].node, got[0].data),
            (Kind::Frame, 17, &a[..])
        );
        assert_eq!(
            (got[1].kind, got[1].node, got[1].data.len()),
            (Kind::Request, 3, 0)
        );
        // Cut anywhere inside a record: the records before it decode, then one error; a
        // cut between the two records leaves the first alone.
        let boundary = BATCH_HEADER + RECORD + 300;
        for cut in BATCH_HEADER + 1..bytes.len() {
            let Ok(Relayed::Batch { records, .. }) = parse(&bytes[..cut]) else {
                panic!("header intact at {cut}")
            };
            let v: Vec<_> = records.collect();
            let whole = usize::from(cut >= boundary);
            if cut == boundary {
                assert_eq!(v.len(), 1);
                assert!(v[0].is_ok());
            } else {
                assert_eq!(v.len(), whole + 1, "cut {cut}");
                assert!(v.last().unwrap().is_err(), "cut {cut}");
                assert!(v[..whole].iter().all(|r| r.is_ok()));
            }
        }
        assert_eq!(parse(&bytes[..3]).err(), Some(RelayError::Truncated));
        assert_eq!(parse(&[]).err(), Some(RelayError::Truncated));
        assert_eq!(parse(&[9]).err(), Some(RelayError::UnknownTag { tag: 9 }));
    }

    #[test]
    fn a_full_batch_refuses_a_record_and_keeps_what_it_has() {
        let mut buf = [0u8; MAX_MESSAGE];
        let mut w = BatchWriter::new(&mut buf).unwrap();
        assert_eq!(w.room(), MAX_ROUTED);
        let big = [1u8; MAX_ROUTED];
        w.push(Record {
            kind: Kind::Frame,
            node: 0,
            data: &big,
        })
        .unwrap();
        assert_eq!(w.bytes().len(), MAX_MESSAGE);
        let before = w.bytes().to_vec();
        let r = w.push(Record {
            kind: Kind::Frame,
            node: 1,
            data: &[],
        });
        assert_eq!(r, Err(RelayError::Full));
        assert_eq!(w.bytes(), &before[..]);
        w.clear();
        assert_eq!(w.bytes(), &[TAG_BATCH, 0, 0, 0, 0]);
        let mut out = [0u8; MAX_MESSAGE];
        assert_eq!(forward(&[5; 10], &mut out), Ok(11));
        assert!(matches!(parse(&out[..11]), Ok(Relayed::Forward(f)) if f == [5; 10]));
        assert!(forward(&[0; MAX_MESSAGE], &mut out).is_err());
    }
}
