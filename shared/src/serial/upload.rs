//! The RC side of a scene upload ([`UploadReceiver`]): chunks stored in order, each frame
//! answered with one reply, go-back-N retransmission.

use super::codec::Encoder;
use super::protocol::*;
use crate::wire::CRC32;

/// What an [`UploadReceiver`] step did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UploadEvent {
    /// The message was not about uploads (the caller handles it).
    Ignored,
    /// An upload of `len` bytes began.
    Started { len: u32 },
    /// `received` bytes are stored (in order from 0).
    Progress { received: u32 },
    /// The scene is complete and CRC-checked: [`UploadReceiver::image`] has it. The RC
    /// broadcasts it to the nodes now.
    Complete { len: u32 },
    /// The upload was refused or failed (the reply says why); the receiver is idle.
    Failed(RcError),
    /// A malformed frame was answered with a [`ToPc::Nak`].
    Nak { offset: u32 },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum UploadState {
    Idle,
    Receiving { len: u32, crc: u32 },
    Done { len: u32, crc: u32 },
}

/// The RC side of a scene upload: stores chunks in order into a caller buffer and answers
/// each frame with one reply (`Ack`, `Nak`, `SceneDone` or `Error`), go-back-N style: a
/// chunk that does not start where the stored bytes end is answered with a `Nak` naming
/// that offset, and so is a malformed frame.
pub struct UploadReceiver<'b> {
    buf: &'b mut [u8],
    state: UploadState,
    received: u32,
    naks: u32,
}

/// A reply frame written into the caller's buffer (`len` bytes; 0 = nothing to send) and
/// what happened.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reply {
    pub len: usize,
    pub event: UploadEvent,
}

impl<'b> UploadReceiver<'b> {
    /// A receiver storing scenes of up to `buf.len()` bytes.
    pub fn new(buf: &'b mut [u8]) -> Self {
        UploadReceiver {
            buf,
            state: UploadState::Idle,
            received: 0,
            naks: 0,
        }
    }

    /// The uploaded scene, once complete and CRC-checked.
    pub fn image(&self) -> Option<&[u8]> {
        match self.state {
            UploadState::Done { len, .. } => self.buf.get(..len as usize),
            _ => None,
        }
    }

    /// Take the buffer out with the stored scene's length, to render from while this session
    /// goes on receiving into its other bank (`None`: no complete scene). Until
    /// [`UploadReceiver::restore`] the receiver holds no buffer: [`UploadReceiver::image`] is
    /// `None` and an upload into it is refused as too large.
    pub fn lend(&mut self) -> Option<(&'b mut [u8], usize)> {
        let UploadState::Done { len, .. } = self.state else {
            return None;
        };
        let len = len as usize;
        (len <= self.buf.len()).then(|| (core::mem::take(&mut self.buf), len))
    }

    /// Give back the buffer [`UploadReceiver::lend`] took out.
    pub fn restore(&mut self, buf: &'b mut [u8]) {
        self.buf = buf;
    }

    /// Bytes stored so far in the current upload.
    pub fn received(&self) -> u32 {
        self.received
    }

    /// `Nak`s sent so far (malformed frames and out-of-order chunks).
    pub fn naks(&self) -> u32 {
        self.naks
    }

    /// Handle a decoded PC -> RC message; the reply frame goes into `out`.
    pub fn on_message(
        &mut self,
        msg: &ToRc<'_>,
        enc: &mut Encoder,
        out: &mut [u8],
    ) -> Result<Reply, SerialError> {
        let (reply, event) = match *msg {
            ToRc::SceneBegin { len, crc } => self.begin(len, crc),
            ToRc::SceneChunk { offset, data } => self.chunk(offset, data),
            _ => {
                return Ok(Reply {
                    len: 0,
                    event: UploadEvent::Ignored,
                })
            }
        };
        let len = enc.encode(&reply, out)?;
        Ok(Reply { len, event })
    }

    /// Handle a frame the [`Decoder`] rejected: answered with a `Nak` from the stored
    /// length (or an `Error` naming the version, for a version mismatch).
    pub fn on_bad_frame(
        &mut self,
        err: SerialError,
        enc: &mut Encoder,
        out: &mut [u8],
    ) -> Result<Reply, SerialError> {
        let (reply, event) = match err {
            SerialError::Version { found } => {
                let code = RcError::Version { found };
                (ToPc::Error { code }, UploadEvent::Failed(code))
            }
            _ => self.nak(),
        };
        let len = enc.encode(&reply, out)?;
        Ok(Reply { len, event })
    }

    fn nak(&mut self) -> (ToPc<'static>, UploadEvent) {
        self.naks = self.naks.wrapping_add(1);
        let offset = self.received;
        (ToPc::Nak { offset }, UploadEvent::Nak { offset })
    }

    fn fail(&mut self, code: RcError) -> (ToPc<'static>, UploadEvent) {
        self.state = UploadState::Idle;
        self.received = 0;
        (ToPc::Error { code }, UploadEvent::Failed(code))
    }

    fn begin(&mut self, len: u32, crc: u32) -> (ToPc<'static>, UploadEvent) {
        if len == 0 {
            return self.fail(RcError::EmptyScene);
        }
        let max = u32::try_from(self.buf.len()).unwrap_or(u32::MAX);
        if len > max {
            return self.fail(RcError::SceneTooLarge { len, max });
        }
        if self.state == (UploadState::Receiving { len, crc }) {
            // A repeated SceneBegin (our Ack was lost): keep what is stored.
            let offset = self.received;
            return (
                ToPc::Ack { offset },
                UploadEvent::Progress { received: offset },
            );
        }
        self.state = UploadState::Receiving { len, crc };
        self.received = 0;
        (ToPc::Ack { offset: 0 }, UploadEvent::Started { len })
    }

    fn chunk(&mut self, offset: u32, data: &[u8]) -> (ToPc<'static>, UploadEvent) {
        let (len, crc) = match self.state {
            UploadState::Idle => return self.fail(RcError::NotUploading),
            // A repeated last chunk (our SceneDone was lost): say it again.
            UploadState::Done { len, crc } => {
                return (ToPc::SceneDone { len, crc }, UploadEvent::Complete { len })
            }
            UploadState::Receiving { len, crc } => (len, crc),
        };
        let end = offset as u64 + data.len() as u64;
        if data.is_empty() || data.len() > MAX_CHUNK || end > len as u64 || offset > self.received {
            return self.nak();
        }
        let Some(dst) = self.buf.get_mut(offset as usize..end as usize) else {
            return self.nak();
        };
        dst.copy_from_slice(data);
        self.received = self.received.max(end as u32);
        if self.received < len {
            let offset = self.received;
            return (
                ToPc::Ack { offset },
                UploadEvent::Progress { received: offset },
            );
        }
        let found = CRC32.checksum(self.buf.get(..len as usize).unwrap_or(&[]));
        if found != crc {
            return self.fail(RcError::SceneCrc {
                expected: crc,
                found,
            });
        }
        self.state = UploadState::Done { len, crc };
        (ToPc::SceneDone { len, crc }, UploadEvent::Complete { len })
    }
}
