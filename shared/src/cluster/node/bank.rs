//! A scene bank's reception state: which chunks and pieces of which frame's scene are in,
//! whether the scene is complete and whether its bytes passed validation since the last
//! write.

use super::*;

/// Reception state of one scene bank.
pub(super) struct Bank {
    pub(super) frame: Option<u16>,
    pub(super) total: u32,
    /// CRC-32 of the whole scene (every chunk carries it).
    pub(super) crc: u32,
    pub(super) got: [u32; MAX_CHUNKS / 32],
    /// Pieces ([`SCENE_PIECE`] bytes) received, for chunks repaired piece by piece.
    pub(super) pieces: [u32; MAX_SCENE / SCENE_PIECE / 32],
    /// The broadcast's SceneEnd was seen (so missing chunks are really missing).
    pub(super) ended: bool,
    pub(super) ready: bool,
    /// The bank's bytes passed [`SceneView::new`] and no byte was written since: only then
    /// is the scene opened without the walk ([`Bank::view`]). Set by `check_scene`, cleared
    /// by every write ([`Bank::write`]) and by every reset ([`Bank::expect`]).
    pub(super) validated: bool,
}

impl Bank {
    pub(super) const EMPTY: Bank = Bank {
        frame: None,
        total: 0,
        crc: 0,
        got: [0; MAX_CHUNKS / 32],
        pieces: [0; MAX_SCENE / SCENE_PIECE / 32],
        ended: false,
        ready: false,
        validated: false,
    };

    pub(super) fn chunks(&self) -> u32 {
        self.total.div_ceil(SCENE_CHUNK as u32)
    }

    /// Which pieces of chunk `c` are in (bit `i` = piece `i` of the chunk).
    pub(super) fn pieces_of(&self, c: u32) -> u16 {
        let first = c * PIECES_PER_CHUNK as u32;
        (0..PIECES_PER_CHUNK as u32).fold(0, |m, i| {
            let p = first + i;
            let have = self
                .pieces
                .get((p / 32) as usize)
                .is_some_and(|w| w & (1 << (p % 32)) != 0);
            m | (u16::from(have) << i)
        })
    }

    /// Note pieces `first..end` received; set their chunk's bit once all its pieces are in.
    pub(super) fn got_pieces(&mut self, first: u32, end: u32) {
        for p in first..end {
            if let Some(w) = self.pieces.get_mut((p / 32) as usize) {
                *w |= 1 << (p % 32);
            }
        }
        let all = self.total.div_ceil(SCENE_PIECE as u32);
        let c = first / PIECES_PER_CHUNK as u32;
        let lo = c * PIECES_PER_CHUNK as u32;
        let hi = (lo + PIECES_PER_CHUNK as u32).min(all);
        let complete = (lo..hi).all(|p| {
            self.pieces
                .get((p / 32) as usize)
                .is_some_and(|w| w & (1 << (p % 32)) != 0)
        });
        if let (true, Some(w)) = (complete, self.got.get_mut((c / 32) as usize)) {
            *w |= 1 << (c % 32);
        }
    }

    pub(super) fn first_missing(&self) -> Option<u32> {
        (0..self.chunks()).find(|&c| self.got[(c / 32) as usize] & (1 << (c % 32)) == 0)
    }

    /// Write `data` at `offset` of the bank's bytes `mem` (the only way bytes reach a bank):
    /// the bytes are no longer the ones validated. False if the range is outside `mem`.
    pub(super) fn write(&mut self, mem: &mut [u8], offset: usize, data: &[u8]) -> bool {
        self.validated = false;
        let end = offset.checked_add(data.len());
        match end.and_then(|end| mem.get_mut(offset..end)) {
            Some(dst) => {
                dst.copy_from_slice(data);
                true
            }
            None => false,
        }
    }

    /// Frame `frame`'s scene, if this bank holds it validated (`mem` = the bank's bytes):
    /// opened without the reference walk ([`SceneView::open_validated`]).
    pub(super) fn view<'m>(&self, mem: &'m [u8], frame: u16) -> Option<SceneView<'m>> {
        if !(self.ready && self.validated && self.frame == Some(frame)) {
            return None;
        }
        SceneView::open_validated(mem.get(..self.total as usize)?).ok()
    }

    /// Start receiving another scene into this bank unless it is the one being received.
    pub(super) fn expect(&mut self, frame: u16, total: u32, crc: u32) {
        if self.frame != Some(frame) || self.total != total || self.crc != crc {
            *self = Bank::EMPTY;
            self.frame = Some(frame);
            self.total = total;
            self.crc = crc;
        }
    }
}
