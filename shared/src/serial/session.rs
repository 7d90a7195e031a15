//! The RC's side of the PC conversation, byte by byte: scene upload (answered at once), film
//! frames into two scene banks ([`super::film`]), and the requests the firmware acts on
//! (render, resend, acknowledgement). The firmware feeds it the bytes of USB CDC packets;
//! host tests feed it what the PC side of `crate::serial` encodes.

use crate::serial::film::{Begin, FilmState};
use crate::serial::{
    Decoder, Encoder, RcError, Reply, SerialError, ToPc, ToRc, UploadEvent, UploadReceiver,
    MAX_TO_PC, MAX_TO_RC,
};

/// What one byte from the PC asks the firmware to do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// Nothing yet (inside a frame).
    Nothing,
    /// Send [`Session::reply`]'s `n` bytes (an upload reply, a NAK, an error).
    Reply(usize),
    /// Render `frames` frames of the uploaded scene (at least 1).
    Render { frames: u16 },
    /// Send pixels `start .. start + len` of `frame` again, then its `FrameEnd`.
    Resend { frame: u16, start: u32, len: u32 },
    /// The PC has frame `frame` (in a film, its bank is free again: see
    /// [`Session::start_next`]).
    Acked { frame: u16 },
}

/// The PC conversation's state.
pub struct Session<'b> {
    /// The even scene bank: still scenes, and the even frames of a film.
    pub upload: UploadReceiver<'b>,
    /// The odd scene bank: the odd frames of a film.
    pub odd: UploadReceiver<'b>,
    /// Which film frame holds which bank.
    pub film: FilmState,
    dec: Decoder<MAX_TO_RC>,
    /// The RC's frame numbering (shared with the readback, which takes it for a render).
    pub enc: Encoder,
    out: [u8; MAX_TO_PC],
}

impl<'b> Session<'b> {
    /// A session storing uploaded scenes in `scene` (no odd bank: films need
    /// [`Session::with_banks`]).
    pub fn new(scene: &'b mut [u8]) -> Self {
        Self::with_banks(scene, &mut [])
    }

    /// A session with two scene banks: `even` (still scenes and even film frames) and `odd`.
    pub fn with_banks(even: &'b mut [u8], odd: &'b mut [u8]) -> Self {
        Session {
            upload: UploadReceiver::new(even),
            odd: UploadReceiver::new(odd),
            film: FilmState::default(),
            dec: Decoder::new(),
            enc: Encoder::new(),
            out: [0; MAX_TO_PC],
        }
    }

    /// The receiver of scene bank `bank` (0 even, otherwise odd).
    pub fn bank(&mut self, bank: usize) -> &mut UploadReceiver<'b> {
        if bank == 0 {
            &mut self.upload
        } else {
            &mut self.odd
        }
    }

    /// The reply frame of the last [`Step::Reply`].
    pub fn reply(&self, n: usize) -> &[u8] {
        self.out.get(..n).unwrap_or(&[])
    }

    /// Malformed frames received from the PC so far.
    pub fn bad_packets(&self) -> u32 {
        self.dec.bad_packets()
    }

    /// The line was reset (USB reconnect): forget a partial frame, and any film (a new
    /// connection begins its own).
    pub fn line_reset(&mut self) {
        self.dec.reset();
        self.film = FilmState::default();
    }

    /// If the cluster is free and a film frame is stored, start it: returns its number and
    /// the length of the [`ToPc::FrameStarted`] reply to send (in [`Session::reply`]). The
    /// firmware calls this after every step and after each frame it finishes.
    pub fn start_next(&mut self) -> Option<(u16, usize)> {
        let frame = self.film.start_next()?;
        let n = self
            .enc
            .encode(&ToPc::FrameStarted { frame }, &mut self.out)
            .unwrap_or(0);
        Some((frame, n))
    }

    /// Take one byte from the PC.
    pub fn feed(&mut self, byte: u8) -> Step {
        let reply = match self.dec.feed::<ToRc>(byte) {
            None => return Step::Nothing,
            Some(Ok(p)) => match p.msg {
                ToRc::StartRender { frames } if self.upload.image().is_some() => {
                    return Step::Render {
                        frames: frames.max(1),
                    }
                }
                ToRc::StartRender { .. } => self.error(RcError::NoScene),
                ToRc::FrameAck { frame } => {
                    self.film.acked(frame);
                    return Step::Acked { frame };
                }
                ToRc::Resend { frame, start, len } => return Step::Resend { frame, start, len },
                ToRc::FrameBegin {
                    frame,
                    frames,
                    len,
                    crc,
                } => self.frame_begin(frame, frames, len, crc),
                // A still upload ends a film's upload: a frame loaded and not started is
                // dropped (the still goes to the even bank).
                msg @ ToRc::SceneBegin { .. } => {
                    self.film.loading = None;
                    to_bank(
                        &mut self.film,
                        [&mut self.upload, &mut self.odd],
                        &mut self.enc,
                        &mut self.out,
                        &msg,
                    )
                }
                msg => to_bank(
                    &mut self.film,
                    [&mut self.upload, &mut self.odd],
                    &mut self.enc,
                    &mut self.out,
                    &msg,
                ),
            },
            Some(Err(e)) => {
                let bank = self.film.loading_bank().unwrap_or(0);
                let (r, enc, out) = self.parts(bank);
                r.on_bad_frame(e, enc, out).map(|r| r.len)
            }
        };
        match reply {
            Ok(n) if n > 0 => Step::Reply(n),
            _ => Step::Nothing,
        }
    }

    fn error(&mut self, code: RcError) -> Result<usize, SerialError> {
        self.enc.encode(&ToPc::Error { code }, &mut self.out)
    }

    /// The receiver of `bank`, the encoder and the reply buffer, borrowed apart.
    fn parts(&mut self, bank: usize) -> (&mut UploadReceiver<'b>, &mut Encoder, &mut [u8]) {
        let r = if bank == 0 {
            &mut self.upload
        } else {
            &mut self.odd
        };
        (r, &mut self.enc, &mut self.out)
    }

    fn frame_begin(
        &mut self,
        frame: u16,
        frames: u16,
        len: u32,
        crc: u32,
    ) -> Result<usize, SerialError> {
        match self.film.begin(frame, frames) {
            // The begin goes to the new loading frame's bank; a refusal there (too large,
            // empty) frees it again.
            Ok(Begin::New { .. } | Begin::Again { .. }) => to_bank(
                &mut self.film,
                [&mut self.upload, &mut self.odd],
                &mut self.enc,
                &mut self.out,
                &ToRc::SceneBegin { len, crc },
            ),
            Err(code) => self.error(code),
        }
    }
}

/// Upload messages: to the loading film frame's bank, else the even bank (`banks`: even,
/// odd); the film learns whether the frame was stored or refused.
fn to_bank(
    film: &mut FilmState,
    banks: [&mut UploadReceiver<'_>; 2],
    enc: &mut Encoder,
    out: &mut [u8],
    msg: &ToRc<'_>,
) -> Result<usize, SerialError> {
    let bank = film.loading_bank();
    let [even, odd] = banks;
    let r = if bank == Some(1) { odd } else { even };
    let Reply { len, event } = r.on_message(msg, enc, out)?;
    if bank.is_some() {
        match event {
            UploadEvent::Complete { .. } => film.stored(),
            UploadEvent::Failed(_) => film.failed(),
            _ => {}
        }
    }
    Ok(len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serial::{Packet, MAX_CHUNK};
    use crate::wire::CRC32;

    /// Feed `frame` to the session; return the replies decoded and the other steps.
    fn feed(s: &mut Session<'_>, frame: &[u8]) -> (Vec<String>, Vec<Step>) {
        let mut replies = Vec::new();
        let mut steps = Vec::new();
        for &b in frame {
            match s.feed(b) {
                Step::Nothing => {}
                Step::Reply(n) => {
                    let mut dec = Decoder::<MAX_TO_PC>::new();
                    for &c in s.reply(n) {
                        if let Some(r) = dec.feed::<ToPc>(c) {
                            let p: Packet<ToPc> = r.expect("valid reply");
                            replies.push(format!("{:?}", p.msg));
                        }
                    }
                }
                other => steps.push(other),
            }
        }
        (replies, steps)
    }

    fn pc_frame(enc: &mut Encoder, msg: &ToRc<'_>) -> Vec<u8> {
        let mut buf = [0u8; MAX_TO_RC];
        let n = enc.encode(msg, &mut buf).expect("fits");
        buf[..n].to_vec()
    }

    #[test]
    fn upload_render_resend_and_errors() {
        let image: Vec<u8> = (0..1300u32).map(|i| (i * 13 % 256) as u8).collect();
        let crc = CRC32.checksum(&image);
        let mut store = vec![0u8; 4096];
        let mut s = Session::new(&mut store);
        let mut pc = Encoder::new();

        // No scene yet: a render is refused with a reason.
        let (r, steps) = feed(&mut s, &pc_frame(&mut pc, &ToRc::StartRender { frames: 1 }));
        assert_eq!(r, ["Error { code: NoScene }"]);
        assert!(steps.is_empty());

        let len = image.len() as u32;
        let (r, _) = feed(&mut s, &pc_frame(&mut pc, &ToRc::SceneBegin { len, crc }));
        assert_eq!(r, ["Ack { offset: 0 }"]);
        // A damaged chunk frame is answered with a NAK from the stored length.
        let mut bad = pc_frame(
            &mut pc,
            &ToRc::SceneChunk {
                offset: 0,
                data: &image[..MAX_CHUNK],
            },
        );
        bad[20] ^= 0x10;
        let (r, _) = feed(&mut s, &bad);
        assert_eq!(r, ["Nak { offset: 0 }"]);
        let mut last = Vec::new();
        for (k, c) in image.chunks(MAX_CHUNK).enumerate() {
            let offset = (k * MAX_CHUNK) as u32;
            let (r, _) = feed(
                &mut s,
                &pc_frame(&mut pc, &ToRc::SceneChunk { offset, data: c }),
            );
            last = r;
        }
        assert_eq!(last, [format!("SceneDone {{ len: {len}, crc: {crc} }}")]);
        assert_eq!(s.upload.image(), Some(&image[..]));

        let (r, steps) = feed(&mut s, &pc_frame(&mut pc, &ToRc::StartRender { frames: 0 }));
        assert!(r.is_empty());
        assert_eq!(steps, [Step::Render { frames: 1 }]);
        let msg = ToRc::Resend {
            frame: 0,
            start: 5,
            len: 9,
        };
        let (_, steps) = feed(&mut s, &pc_frame(&mut pc, &msg));
        assert_eq!(
            steps,
            [Step::Resend {
                frame: 0,
                start: 5,
                len: 9
            }]
        );
        let (_, steps) = feed(&mut s, &pc_frame(&mut pc, &ToRc::FrameAck { frame: 0 }));
        assert_eq!(steps, [Step::Acked { frame: 0 }]);
        // Garbage between frames costs at most the frame it hits.
        let (r, _) = feed(&mut s, &[0, 1, 2, 3, 0]);
        assert_eq!(r.len(), 1, "one NAK for the garbled frame: {r:?}");
    }

    /// Upload `image` as film frame `frame` of 3; the replies.
    fn film_frame(s: &mut Session<'_>, pc: &mut Encoder, frame: u16, image: &[u8]) -> Vec<String> {
        let (len, crc) = (image.len() as u32, CRC32.checksum(image));
        let msg = ToRc::FrameBegin {
            frame,
            frames: 3,
            len,
            crc,
        };
        let (mut r, _) = feed(s, &pc_frame(pc, &msg));
        if r != ["Ack { offset: 0 }"] {
            return r;
        }
        for (k, c) in image.chunks(MAX_CHUNK).enumerate() {
            let offset = (k * MAX_CHUNK) as u32;
            r = feed(s, &pc_frame(pc, &ToRc::SceneChunk { offset, data: c })).0;
        }
        r
    }

    #[test]
    fn film_frames_alternate_banks_and_wait_for_their_turn() {
        let frames: Vec<Vec<u8>> = (0..3u32)
            .map(|f| (0..700 + 100 * f).map(|i| (i * 7 + f) as u8).collect())
            .collect();
        let (mut even, mut odd) = (vec![0u8; 1024], vec![0u8; 1024]);
        let mut s = Session::with_banks(&mut even, &mut odd);
        let mut pc = Encoder::new();
        let done = |f: &[u8]| {
            let crc = CRC32.checksum(f);
            vec![format!("SceneDone {{ len: {}, crc: {crc} }}", f.len())]
        };
        assert_eq!(film_frame(&mut s, &mut pc, 0, &frames[0]), done(&frames[0]));
        // The cluster is free: frame 0 starts at once, and says so.
        let (f, n) = s.start_next().expect("frame 0 starts");
        assert_eq!(f, 0);
        let mut dec = Decoder::<MAX_TO_PC>::new();
        let mut said = Vec::new();
        for &b in s.reply(n) {
            if let Some(r) = dec.feed::<ToPc>(b) {
                let p: Packet<ToPc> = r.expect("valid reply");
                said.push(format!("{:?}", p.msg));
            }
        }
        assert_eq!(said, ["FrameStarted { frame: 0 }"]);
        // Frame 1 goes to the odd bank while frame 0 renders from the even one.
        let (buf, len) = s.upload.lend().expect("frame 0 stored");
        assert_eq!(&buf[..len], &frames[0][..]);
        assert_eq!(film_frame(&mut s, &mut pc, 1, &frames[1]), done(&frames[1]));
        assert_eq!(s.odd.image(), Some(&frames[1][..]));
        assert_eq!(s.start_next(), None, "frame 0 still renders");
        // Frame 2 would need frame 0's bank: refused, the PC is too far ahead.
        assert_eq!(
            film_frame(&mut s, &mut pc, 2, &frames[2]),
            ["Error { code: FilmBusy { frame: 2, holder: 1 } }"]
        );
        s.film.rendered(0);
        assert_eq!(s.start_next(), None, "frame 0 waits for its FrameAck");
        let (_, steps) = feed(&mut s, &pc_frame(&mut pc, &ToRc::FrameAck { frame: 0 }));
        assert_eq!(steps, [Step::Acked { frame: 0 }]);
        s.upload.restore(buf);
        assert_eq!(s.start_next().map(|(f, _)| f), Some(1));
        assert_eq!(film_frame(&mut s, &mut pc, 2, &frames[2]), done(&frames[2]));
        assert_eq!(s.upload.image(), Some(&frames[2][..]));
        // A still upload drops frame 2 (stored, not started) and takes the even bank.
        let still = &frames[0][..300];
        let (len, crc) = (still.len() as u32, CRC32.checksum(still));
        let (r, _) = feed(&mut s, &pc_frame(&mut pc, &ToRc::SceneBegin { len, crc }));
        assert_eq!(r, ["Ack { offset: 0 }"]);
        assert_eq!(s.film.loading, None);
        let chunk = ToRc::SceneChunk {
            offset: 0,
            data: still,
        };
        let (r, _) = feed(&mut s, &pc_frame(&mut pc, &chunk));
        assert_eq!(r, [format!("SceneDone {{ len: {len}, crc: {crc} }}")]);
        assert_eq!(s.upload.image(), Some(still));
        assert_eq!(s.start_next(), None, "a still is no film frame");
    }
}
