//! Scene chunks written straight into a node's scene bank by its link, as LINKS-1's IMSU
//! broadcast wrote into every node's memory without the node's CPU.
//!
//! While the node logic renders from one scene bank it lends the other to its link
//! ([`SceneLanding::lend`]). The link's task then writes every intact broadcast
//! [`Down::Scene`] chunk for that bank into it as the transfer ends ([`LentBank::land`]),
//! instead of queueing the frame in one of its two RX banks, which the node logic empties
//! only between runs (a 512-pixel run is tens of milliseconds; a scene of 18 chunks is
//! broadcast in a few). The bank comes back with a record of what landed ([`Landed`]); the
//! node logic books it exactly as if it had handled those chunks itself (the bitmap, the
//! CRC-32 and the validation stay the node logic's).
//!
//! The rules `land` applies are the node logic's for a broadcast chunk: a whole chunk, inside
//! the bank and the scene, of the lent bank's parity; a new scene (frame, length, CRC) starts
//! the record over; a chunk of the scene the bank already holds ready is not written again.

use super::wire::{Down, MAX_CHUNKS, MAX_SCENE, SCENE_CHUNK, SCENE_PIECE};

/// Which scene a chunk belongs to: every chunk carries all three.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SceneKey {
    pub frame: u16,
    pub total: u32,
    pub crc: u32,
}

/// What landed in a lent bank.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Landed {
    /// The scene the chunks below belong to (the last one seen).
    pub key: Option<SceneKey>,
    /// Chunk `c` was written (bit `c % 32` of word `c / 32`).
    pub chunks: [u32; MAX_CHUNKS / 32],
    /// Chunks written (a chunk written twice counts twice, as the node logic counts).
    pub count: u32,
    /// The scene's last chunk was among them (the broadcast is over).
    pub ended: bool,
}

impl Landed {
    const NONE: Landed = Landed {
        key: None,
        chunks: [0; MAX_CHUNKS / 32],
        count: 0,
        ended: false,
    };

    /// Whether chunk `c` landed.
    pub fn has(&self, c: u32) -> bool {
        self.chunks
            .get((c / 32) as usize)
            .is_some_and(|w| w & (1 << (c % 32)) != 0)
    }
}

/// Where `len` bytes of scene data at `offset` of a `total`-byte scene go in a bank of `cap`
/// bytes: their end, if they are a whole chunk (the scene's last may be short) or, when
/// `pieces` (a repair in an exchange), whole pieces of one chunk, inside the scene and the
/// bank. The one rule for the node logic and for chunks landing in a lent bank.
pub(crate) fn scene_range(
    offset: u32,
    len: usize,
    total: u32,
    cap: usize,
    pieces: bool,
) -> Option<u32> {
    let (chunk, piece) = (SCENE_CHUNK as u32, SCENE_PIECE as u32);
    // Saturated on overflow: then past `total`, refused below.
    let end = offset.saturating_add(u32::try_from(len).unwrap_or(u32::MAX));
    let whole_chunk =
        offset.is_multiple_of(chunk) && end == total.min(offset.saturating_add(chunk));
    let in_pieces = pieces
        && offset.is_multiple_of(piece)
        && len > 0
        && (end.is_multiple_of(piece) || end == total)
        && offset / chunk == (end - 1) / chunk;
    let fits = total as usize <= MAX_SCENE
        && total as usize <= cap
        && total > 0
        && offset < total
        && end <= total;
    (fits && (whole_chunk || in_pieces)).then_some(end)
}

/// What [`LentBank::land`] did with a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Landing {
    /// A chunk of this bank's scene, written.
    Written,
    /// A chunk of the scene the bank holds ready: already there, nothing written.
    Held,
    /// Not a chunk for this bank (another message, the other bank, a malformed chunk): the
    /// node logic handles it as before.
    NotMine,
}

/// A scene bank lent to the link: its bytes, the scene it holds ready (if any) and what
/// landed since it was lent.
pub struct LentBank<'b> {
    /// The bank's number (a frame's scene goes to bank `frame % 2`).
    pub index: usize,
    pub bytes: &'b mut [u8],
    /// The scene the bank holds complete and checked: its chunks are not written again.
    pub holds: Option<SceneKey>,
    pub landed: Landed,
}

impl<'b> LentBank<'b> {
    /// Bank `index`'s `bytes`, holding `holds` ready, nothing landed yet.
    pub fn new(index: usize, bytes: &'b mut [u8], holds: Option<SceneKey>) -> Self {
        LentBank {
            index,
            bytes,
            holds,
            landed: Landed::NONE,
        }
    }

    /// Write `msg` into the bank if it is a broadcast chunk of it (see the module's rules).
    pub fn land(&mut self, msg: &Down<'_>) -> Landing {
        let Down::Scene {
            frame,
            offset,
            total,
            crc,
            data,
        } = *msg
        else {
            return Landing::NotMine;
        };
        if usize::from(frame % 2) != self.index {
            return Landing::NotMine;
        }
        let Some(end) = scene_range(offset, data.len(), total, self.bytes.len(), false) else {
            // The node logic counts it as a bad message.
            return Landing::NotMine;
        };
        let key = SceneKey { frame, total, crc };
        if self.holds == Some(key) {
            return Landing::Held;
        }
        let Some(dst) = self.bytes.get_mut(offset as usize..end as usize) else {
            return Landing::NotMine;
        };
        dst.copy_from_slice(data);
        // The bank's bytes are no longer the scene it held.
        self.holds = None;
        if self.landed.key != Some(key) {
            self.landed = Landed {
                key: Some(key),
                ..Landed::NONE
            };
        }
        let c = offset / SCENE_CHUNK as u32;
        if let Some(w) = self.landed.chunks.get_mut((c / 32) as usize) {
            *w |= 1 << (c % 32);
        }
        self.landed.count += 1;
        self.landed.ended |= end == total;
        Landing::Written
    }
}

/// A link that takes a scene bank while the node logic does not use it.
pub trait SceneLanding<'b> {
    /// Lend `bank` to the link; `Err` hands it straight back (the link takes no banks, or
    /// already holds one).
    fn lend(&self, bank: LentBank<'b>) -> Result<(), LentBank<'b>>;
    /// Take the lent bank back, with what landed in it.
    fn reclaim(&self) -> Option<LentBank<'b>>;
}

/// A link that writes nothing into scene banks (every chunk goes through the node logic).
#[derive(Clone, Copy, Debug, Default)]
pub struct NoLanding;

impl<'b> SceneLanding<'b> for NoLanding {
    fn lend(&self, bank: LentBank<'b>) -> Result<(), LentBank<'b>> {
        Err(bank)
    }

    fn reclaim(&self) -> Option<LentBank<'b>> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chunk(frame: u16, offset: u32, total: u32, data: &[u8]) -> Down<'_> {
        Down::Scene {
            frame,
            offset,
            total,
            crc: 7,
            data,
        }
    }

    #[test]
    fn whole_chunks_of_the_lent_bank_land_and_others_do_not() {
        let mut mem = [0u8; 3 * SCENE_CHUNK];
        let total = 2 * SCENE_CHUNK as u32 + 5;
        let full = [0xa5u8; SCENE_CHUNK];
        let mut bank = LentBank::new(1, &mut mem, None);
        // Frame 3 goes to bank 1: chunk 1 and the short last chunk land.
        assert_eq!(bank.land(&chunk(3, 1024, total, &full)), Landing::Written);
        assert_eq!(bank.land(&chunk(3, 2048, total, &[1; 5])), Landing::Written);
        // Frame 2's chunk is bank 0's; a piece (not a whole chunk), an offset past the end,
        // a scene larger than the bank and other messages are the node logic's.
        assert_eq!(bank.land(&chunk(2, 0, total, &full)), Landing::NotMine);
        assert_eq!(
            bank.land(&chunk(3, 0, total, &full[..64])),
            Landing::NotMine
        );
        assert_eq!(bank.land(&chunk(3, 3072, total, &full)), Landing::NotMine);
        let big = 3 * SCENE_CHUNK as u32 + 1;
        assert_eq!(bank.land(&chunk(3, 0, big, &full)), Landing::NotMine);
        assert_eq!(bank.land(&Down::Stop), Landing::NotMine);
        let l = bank.landed;
        assert_eq!(
            l.key,
            Some(SceneKey {
                frame: 3,
                total,
                crc: 7
            })
        );
        assert_eq!((l.count, l.ended), (2, true));
        assert!(!l.has(0) && l.has(1) && l.has(2));
        assert_eq!(&mem[1024..2048], &full[..]);
        assert_eq!(&mem[2048..2053], &[1; 5]);
        assert_eq!(mem[0], 0);
    }

    #[test]
    fn a_new_scene_starts_the_record_over_and_a_held_scene_is_not_rewritten() {
        let mut mem = [0u8; 2 * SCENE_CHUNK];
        let total = 2 * SCENE_CHUNK as u32;
        let held = SceneKey {
            frame: 1,
            total,
            crc: 7,
        };
        let mut bank = LentBank::new(1, &mut mem, Some(held));
        assert_eq!(
            bank.land(&chunk(1, 0, total, &[9; SCENE_CHUNK])),
            Landing::Held
        );
        assert_eq!(bank.landed.count, 0);
        // Frame 3 replaces the held scene.
        assert_eq!(
            bank.land(&chunk(3, 0, total, &[3; SCENE_CHUNK])),
            Landing::Written
        );
        assert_eq!(bank.holds, None);
        // ... and frame 5 (same bank) starts the record over.
        assert_eq!(
            bank.land(&chunk(5, 1024, total, &[5; SCENE_CHUNK])),
            Landing::Written
        );
        let l = bank.landed;
        assert_eq!(l.key.map(|k| k.frame), Some(5));
        assert_eq!(
            (l.count, l.ended, l.has(0), l.has(1)),
            (1, true, false, true)
        );
        assert_eq!((mem[0], mem[1024]), (3, 5));
    }

    #[test]
    fn no_landing_hands_the_bank_back() {
        let mut mem = [0u8; 4];
        let bank = LentBank::new(0, &mut mem, None);
        let back = NoLanding.lend(bank).err().map(|b| b.bytes.len());
        assert_eq!(back, Some(4));
        assert!(SceneLanding::<'_>::reclaim(&NoLanding).is_none());
    }
}
