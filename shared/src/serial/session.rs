//! The RC's side of the PC conversation, byte by byte: scene upload (answered at once), and
//! the requests the firmware acts on (render, resend, acknowledgement). The firmware feeds it
//! the bytes of USB CDC packets; host tests feed it what the PC side of `crate::serial`
//! encodes.

use crate::serial::{Decoder, Encoder, RcError, ToPc, ToRc, UploadReceiver, MAX_TO_PC, MAX_TO_RC};

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
    /// The PC has frame `frame`.
    Acked { frame: u16 },
}

/// The PC conversation's state.
pub struct Session<'b> {
    pub upload: UploadReceiver<'b>,
    dec: Decoder<MAX_TO_RC>,
    /// The RC's frame numbering (shared with the readback, which takes it for a render).
    pub enc: Encoder,
    out: [u8; MAX_TO_PC],
}

impl<'b> Session<'b> {
    /// A session storing uploaded scenes in `scene`.
    pub fn new(scene: &'b mut [u8]) -> Self {
        Session {
            upload: UploadReceiver::new(scene),
            dec: Decoder::new(),
            enc: Encoder::new(),
            out: [0; MAX_TO_PC],
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

    /// The line was reset (USB reconnect): forget a partial frame.
    pub fn line_reset(&mut self) {
        self.dec.reset();
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
                ToRc::StartRender { .. } => {
                    let code = RcError::NoScene;
                    self.enc.encode(&ToPc::Error { code }, &mut self.out)
                }
                ToRc::FrameAck { frame } => return Step::Acked { frame },
                ToRc::Resend { frame, start, len } => return Step::Resend { frame, start, len },
                msg => self
                    .upload
                    .on_message(&msg, &mut self.enc, &mut self.out)
                    .map(|r| r.len),
            },
            Some(Err(e)) => self
                .upload
                .on_bad_frame(e, &mut self.enc, &mut self.out)
                .map(|r| r.len),
        };
        match reply {
            Ok(n) if n > 0 => Step::Reply(n),
            _ => Step::Nothing,
        }
    }
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
}
