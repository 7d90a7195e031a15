//! The node's side of the backup line: answers the RC's frames, assembles a scene sent over
//! the line into its bank, holds one job for its renderer and one scanline piece of finished
//! pixels, which it returns in run-length coded chunks (stop-and-wait, re-sent until
//! acknowledged).

use super::{
    decode, encode, rle_chunk, BackupError, Health, Msg, BROADCAST, FIRMWARE_ID, OUTBOX_PIXELS,
    PIXEL_DATA,
};
use crate::cluster::wire::{Job, CRC32};

/// A scene image arriving over the line into a bank, in order.
pub struct NodeScene<'b> {
    bank: &'b mut [u8],
    frame: u16,
    total: u32,
    crc: u32,
    have: u32,
    ok: bool,
}

impl<'b> NodeScene<'b> {
    pub fn new(bank: &'b mut [u8]) -> Self {
        Self {
            bank,
            frame: 0,
            total: 0,
            crc: 0,
            have: 0,
            ok: false,
        }
    }

    /// Take a chunk: a chunk of another scene (frame, length or CRC) starts over; the chunk
    /// at the first missing byte is appended; any other is ignored (the RC resumes from the
    /// byte count the node reports). A scene larger than the bank is refused (also while
    /// the bank is lent out: [`BackupNode::take_bank`]).
    fn take(
        &mut self,
        frame: u16,
        offset: u32,
        total: u32,
        crc: u32,
        data: &[u8],
    ) -> Result<(), BackupError> {
        if total as usize > self.bank.len() {
            return Err(BackupError::TooLong);
        }
        if (frame, total, crc) != (self.frame, self.total, self.crc) {
            *self = Self {
                bank: core::mem::take(&mut self.bank),
                frame,
                total,
                crc,
                have: 0,
                ok: false,
            };
        }
        if offset != self.have || self.ok {
            return Ok(());
        }
        let end = offset
            .checked_add(data.len() as u32)
            .filter(|&e| e <= total)
            .ok_or(BackupError::Malformed)?;
        self.bank[offset as usize..end as usize].copy_from_slice(data);
        self.have = end;
        if end == total {
            self.ok = CRC32.checksum(&self.bank[..total as usize]) == crc;
            if !self.ok {
                self.have = 0;
            }
        }
        Ok(())
    }

    /// The complete, CRC-checked scene and its frame (`None` while the bank is lent out).
    pub fn ready(&self) -> Option<(u16, &[u8])> {
        let bytes = self.bank.get(..self.total as usize)?;
        self.ok.then_some((self.frame, bytes))
    }

    /// The complete scene's frame and CRC-32: what identifies it (also while the bank is lent
    /// out).
    pub fn key(&self) -> Option<(u16, u32)> {
        self.ok.then_some((self.frame, self.crc))
    }
}

/// Finished pixels waiting for the line: one scanline piece.
struct Outbox {
    rgb: [u8; 3 * OUTBOX_PIXELS],
    /// Pixels held, and how many of them the RC accepted.
    len: usize,
    sent: usize,
    job: u32,
    frame: u16,
    y: u16,
    x: u16,
    /// The piece is its job's last.
    last: bool,
    /// The chunk on the line, not yet acknowledged: its pixel count.
    in_flight: Option<usize>,
}

/// The node's backup-line state.
pub struct BackupNode<'b> {
    addr: u8,
    pub scene: NodeScene<'b>,
    job: Option<Job>,
    out: Outbox,
    /// Sequence number of the chunk in flight (or the next one).
    seq: u16,
    jobs_done: u32,
    errors: u32,
    /// Work or a scene arrived while the node had no bank for the line.
    wants_bank: bool,
}

impl<'b> BackupNode<'b> {
    /// Node `addr` (1..=MAX_ADDR) with a scene bank.
    pub fn new(addr: u8, bank: &'b mut [u8]) -> Self {
        Self {
            addr,
            scene: NodeScene::new(bank),
            job: None,
            out: Outbox {
                rgb: [0; 3 * OUTBOX_PIXELS],
                len: 0,
                sent: 0,
                job: 0,
                frame: 0,
                y: 0,
                x: 0,
                last: false,
                in_flight: None,
            },
            seq: 0,
            jobs_done: 0,
            errors: 0,
            wants_bank: false,
        }
    }

    /// Give the line a scene bank (the firmware shares the SPI path's bank once the RC serves
    /// the node over the line). A scene received before keeps its state: a bank taken back
    /// with [`BackupNode::take_bank`] and lent again still holds it.
    pub fn lend_bank(&mut self, bank: &'b mut [u8]) {
        self.scene.bank = bank;
        self.wants_bank = false;
    }

    /// Take the bank back (empty from now on: scene chunks are refused, the scene's state
    /// and key stay). The renderer reads the scene from it while the line has none.
    pub fn take_bank(&mut self) -> &'b mut [u8] {
        core::mem::take(&mut self.scene.bank)
    }

    /// Whether the RC sent work or a scene chunk while the node had no bank (since the last
    /// call): the firmware should lend it one ([`BackupNode::lend_bank`]).
    pub fn take_bank_request(&mut self) -> bool {
        core::mem::take(&mut self.wants_bank)
    }

    pub fn addr(&self) -> u8 {
        self.addr
    }

    /// What a roll call answers.
    pub fn health(&self) -> Health {
        Health {
            frame: self.scene.frame,
            scene_bytes: self.scene.have,
            scene_ok: self.scene.ok,
            jobs_done: self.jobs_done,
            errors: self.errors,
            firmware: FIRMWARE_ID,
        }
    }

    /// The job the RC handed over, for the renderer (once).
    pub fn take_job(&mut self) -> Option<Job> {
        self.job.take()
    }

    /// Whether the outbox is empty (every pixel pushed was acknowledged).
    pub fn outbox_free(&self) -> bool {
        self.out.sent == self.out.len
    }

    /// Hand finished pixels (RGB8) of scanline `y` from column `x` of `job` to the line;
    /// `last`: the job's last piece. Refused while the outbox holds pixels or if longer than
    /// [`OUTBOX_PIXELS`].
    pub fn push_pixels(
        &mut self,
        job: &Job,
        y: u16,
        x: u16,
        rgb: &[u8],
        last: bool,
    ) -> Result<(), BackupError> {
        let n = rgb.len() / 3;
        if !self.outbox_free() || n > OUTBOX_PIXELS || !rgb.len().is_multiple_of(3) || n == 0 {
            return Err(BackupError::TooLong);
        }
        let o = &mut self.out;
        o.rgb[..rgb.len()].copy_from_slice(rgb);
        (o.len, o.sent, o.in_flight) = (n, 0, None);
        (o.job, o.frame, o.y, o.x, o.last) = (job.id, job.frame, y, x, last);
        Ok(())
    }

    /// Act on one received frame; returns the length of the reply written to `reply` if the
    /// frame was for this node (broadcasts and other nodes' frames get none). A frame that
    /// does not decode is counted in the health's errors.
    pub fn handle(&mut self, frame: &[u8], reply: &mut [u8]) -> Result<Option<usize>, BackupError> {
        let (addr, msg) = match decode(frame) {
            Ok(m) => m,
            Err(e) => {
                self.errors = self.errors.saturating_add(1);
                return Err(e);
            }
        };
        if addr != self.addr && addr != BROADCAST {
            return Ok(None);
        }
        let answer = match msg {
            Msg::RollCall => Msg::Health(self.health()),
            Msg::Scene {
                frame,
                offset,
                total,
                crc,
                data,
            } => {
                if let Err(e) = self.scene.take(frame, offset, total, crc, data) {
                    self.errors = self.errors.saturating_add(1);
                    self.wants_bank |= self.scene.bank.is_empty() && addr == self.addr;
                    return Err(e);
                }
                Msg::Ack
            }
            Msg::Work { job } => {
                self.job = Some(job);
                self.wants_bank |= self.scene.bank.is_empty();
                Msg::Ack
            }
            Msg::Poll { ack } => return self.poll(ack, reply).map(Some),
            // Other nodes' replies, heard on the shared line.
            Msg::Health(_) | Msg::Idle | Msg::Pixels { .. } | Msg::Ack => return Ok(None),
        };
        if addr == BROADCAST {
            return Ok(None);
        }
        encode(self.addr, &answer, reply).map(Some)
    }

    /// Answer a poll: accept the chunk in flight if `ack` acknowledges it, then send it
    /// again (not acknowledged), the next chunk, or [`Msg::Idle`].
    fn poll(&mut self, ack: u16, reply: &mut [u8]) -> Result<usize, BackupError> {
        let o = &mut self.out;
        if let Some(n) = o.in_flight {
            if ack == self.seq.wrapping_add(1) {
                o.sent += n;
                o.in_flight = None;
                self.seq = ack;
                if o.sent == o.len && o.last {
                    self.jobs_done = self.jobs_done.saturating_add(1);
                }
            }
        }
        if o.sent == o.len {
            return encode(self.addr, &Msg::Idle, reply);
        }
        let mut rle = [0u8; PIXEL_DATA];
        let (n, bytes) = rle_chunk(&o.rgb[3 * o.sent..3 * o.len], &mut rle);
        o.in_flight = Some(n);
        let msg = Msg::Pixels {
            seq: self.seq,
            job: o.job,
            frame: o.frame,
            y: o.y,
            // x + sent <= x + MAX_RUN fits the frame's u16 column (a piece lies in a row).
            x: o.x.saturating_add(o.sent as u16),
            len: n as u16,
            done: o.last && o.sent + n == o.len,
            rle: &rle[..bytes],
        };
        encode(self.addr, &msg, reply)
    }
}
