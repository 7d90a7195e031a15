//! A simulated RC for the serial link: the same no_std [`FrameStreamer`] and
//! [`UploadReceiver`] the firmware drives, over any `std::io` byte stream. The tests run
//! `links readback` / `links upload` against it over a pseudo-terminal; fault injection
//! corrupts chosen frames on the line.

use crate::frame::{render_frame, Precision};
use links_core::serial::{
    Decoder, Encoder, FrameStreamer, SerialError, ToRc, UploadEvent, UploadReceiver, MAX_TO_PC,
    MAX_TO_RC,
};
use std::io::{self, Read, Write};
use std::path::Path;
use std::time::{Duration, Instant};

/// Compile a scene file at `width` x `height` and render it (f32, as the nodes do):
/// returns the RGB8 rows.
pub fn render_scene(path: &Path, width: u32, height: u32) -> Result<Vec<u8>, String> {
    let image = crate::scene_file::compile_at(path, width, height).map_err(|e| e.to_string())?;
    let frame = render_frame(&image, Precision::F32, 1, &|| {}).map_err(|e| e.to_string())?;
    Ok(frame.rgb)
}

/// Flip one byte in the middle of a frame on the line (never to zero, so the frame keeps
/// its length and only its CRC can catch it).
fn corrupt(frame: &mut [u8]) {
    let i = frame.len() / 2;
    frame[i] = if frame[i] == 0x55 { 0x2a } else { 0x55 };
}

/// What the simulated RC saw while serving a readback.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ServeReport {
    /// Retransmit requests answered.
    pub resends: u32,
    /// Malformed frames received from the PC.
    pub bad_frames: u32,
}

/// The RC end of a frame readback: one rendered frame and the protocol state.
pub struct SimRc {
    rgb: Vec<u8>,
    streamer: FrameStreamer,
    enc: Encoder,
    buf: [u8; MAX_TO_PC],
    /// Indices (0-based) of the pixel messages of the first pass to corrupt on the line.
    pub corrupt_runs: Vec<usize>,
    /// Announce a wrong frame CRC (flip its lowest bit) in every `FrameEnd`.
    pub wrong_crc: bool,
    /// Corrupt the first `FrameEnd` on the line (the PC must notice the silence).
    pub corrupt_first_end: bool,
}

impl SimRc {
    /// A frame of `width` x `height` RGB8 pixels (`rgb`, rows top first).
    pub fn new(frame: u16, width: u16, height: u16, rgb: Vec<u8>) -> Result<Self, String> {
        if rgb.len() != 3 * width as usize * height as usize {
            return Err(format!(
                "{} bytes are not a {width}x{height} RGB8 frame",
                rgb.len()
            ));
        }
        let streamer = FrameStreamer::new(frame, width, height).map_err(|e| e.to_string())?;
        Ok(SimRc {
            rgb,
            streamer,
            enc: Encoder::new(),
            buf: [0; MAX_TO_PC],
            corrupt_runs: Vec::new(),
            wrong_crc: false,
            corrupt_first_end: false,
        })
    }

    fn row_runs(&self, y: u16) -> impl Iterator<Item = (u16, u16, u16)> {
        let w = self.streamer.width() as u32;
        self.streamer.span_runs(y as u32 * w, w)
    }

    fn pixels(&self, y: u16, x: u16, n: u16) -> std::ops::Range<usize> {
        let first = y as usize * self.streamer.width() as usize + x as usize;
        3 * first..3 * (first + n as usize)
    }

    fn write_end<W: Write>(&mut self, out: &mut W) -> io::Result<()> {
        let n = self
            .streamer
            .end(&mut self.enc, &mut self.buf)
            .map_err(other)?;
        if std::mem::take(&mut self.corrupt_first_end) {
            corrupt(&mut self.buf[..n]);
            return out.write_all(&self.buf[..n]);
        }
        if self.wrong_crc {
            // Re-encode the same FrameEnd with its CRC off by one bit.
            let crc = self.streamer_crc() ^ 1;
            let msg = links_core::serial::ToPc::FrameEnd {
                frame: self.streamer.frame(),
                crc,
            };
            let seq = self.enc.next_seq().wrapping_sub(1);
            let n = links_core::serial::encode_packet(seq, &msg, &mut self.buf).map_err(other)?;
            return out.write_all(&self.buf[..n]);
        }
        out.write_all(&self.buf[..n])
    }

    fn streamer_crc(&self) -> u32 {
        links_core::wire::CRC32.checksum(&self.rgb)
    }

    /// Stream the whole frame: header, rows (odd rows first, as nodes return them out of
    /// order), a progress message every 8 rows, and the frame end with its CRC.
    pub fn stream<W: Write>(&mut self, out: &mut W) -> io::Result<()> {
        let n = self
            .streamer
            .header(&mut self.enc, &mut self.buf)
            .map_err(other)?;
        out.write_all(&self.buf[..n])?;
        let h = self.streamer.height();
        let order = (1..h).step_by(2).chain((0..h).step_by(2));
        let mut index = 0usize;
        for (i, y) in order.enumerate() {
            for (y, x, len) in self.row_runs(y).collect::<Vec<_>>() {
                let px = self.pixels(y, x, len);
                let n = self
                    .streamer
                    .run(y, x, &self.rgb[px], &mut self.enc, &mut self.buf)
                    .map_err(other)?;
                if self.corrupt_runs.contains(&index) {
                    corrupt(&mut self.buf[..n]);
                }
                out.write_all(&self.buf[..n])?;
                index += 1;
            }
            if i % 8 == 7 {
                let done = self.streamer.folded();
                let n = self
                    .streamer
                    .progress(done, &mut self.enc, &mut self.buf)
                    .map_err(other)?;
                out.write_all(&self.buf[..n])?;
            }
        }
        self.write_end(out)?;
        out.flush()
    }

    /// Answer the PC's requests after [`SimRc::stream`]: `Resend` (the pixels again, then
    /// the frame end), until the PC acknowledges the frame or `timeout` of silence.
    pub fn answer<P: Read + Write>(
        &mut self,
        port: &mut P,
        timeout: Duration,
    ) -> io::Result<ServeReport> {
        let mut dec = Decoder::<MAX_TO_RC>::new();
        let mut report = ServeReport::default();
        let mut byte = [0u8; 1];
        let mut deadline = Instant::now() + timeout;
        loop {
            if Instant::now() >= deadline {
                return Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    "no FrameAck from the PC",
                ));
            }
            match port.read(&mut byte) {
                Ok(0) => std::thread::sleep(Duration::from_millis(1)),
                Ok(_) => {}
                Err(e) if e.kind() == io::ErrorKind::TimedOut => continue,
                Err(e) => return Err(e),
            }
            let request = match dec.feed::<ToRc>(byte[0]) {
                None => continue,
                Some(Err(_)) => {
                    report.bad_frames += 1;
                    continue;
                }
                Some(Ok(p)) => p.msg,
            };
            deadline = Instant::now() + timeout;
            match request {
                ToRc::FrameAck { frame } if frame == self.streamer.frame() => return Ok(report),
                ToRc::Resend { frame, start, len } if frame == self.streamer.frame() => {
                    report.resends += 1;
                    for (y, x, n) in self.streamer.span_runs(start, len).collect::<Vec<_>>() {
                        let px = self.pixels(y, x, n);
                        let n = self
                            .streamer
                            .resend(y, x, &self.rgb[px], &mut self.enc, &mut self.buf)
                            .map_err(other)?;
                        port.write_all(&self.buf[..n])?;
                    }
                    self.write_end(port)?;
                    port.flush()?;
                }
                _ => {}
            }
        }
    }
}

fn other(e: SerialError) -> io::Error {
    io::Error::other(e.to_string())
}

/// What the simulated RC received in an upload.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReceivedUpload {
    pub image: Vec<u8>,
    /// Retransmit requests sent.
    pub naks: u32,
    /// Frames that failed to decode (corrupted on the line).
    pub bad_frames: u32,
    /// Whether a `StartRender` followed, and for how many frames.
    pub start_render: Option<u16>,
}

/// Receive a scene upload into a buffer of `capacity` bytes with the firmware's
/// [`UploadReceiver`]. The PC frames whose 0-based indices are in `corrupt_frames` are
/// corrupted on arrival (as by line noise). Returns once the scene is complete (and a
/// `StartRender`, if the PC sends one within `linger`), or fails after `timeout` of
/// silence.
pub fn receive_upload<P: Read + Write>(
    port: &mut P,
    capacity: usize,
    corrupt_frames: &[usize],
    timeout: Duration,
    linger: Duration,
) -> io::Result<ReceivedUpload> {
    let mut store = vec![0u8; capacity];
    let mut rx = UploadReceiver::new(&mut store);
    let mut enc = Encoder::new();
    let mut dec = Decoder::<MAX_TO_RC>::new();
    let mut out = [0u8; MAX_TO_PC];
    let mut frame = Vec::new();
    let mut index = 0usize;
    let mut done_at: Option<Instant> = None;
    let mut bad_frames = 0;
    let mut start_render = None;
    let mut deadline = Instant::now() + timeout;
    let mut byte = [0u8; 1];
    loop {
        let now = Instant::now();
        if done_at.is_some_and(|t| now >= t + linger) || start_render.is_some() {
            let image = rx.image().map(<[u8]>::to_vec).unwrap_or_default();
            return Ok(ReceivedUpload {
                image,
                naks: rx.naks(),
                bad_frames,
                start_render,
            });
        }
        if now >= deadline {
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                format!("upload incomplete: {} bytes received", rx.received()),
            ));
        }
        match port.read(&mut byte) {
            Ok(0) => {
                std::thread::sleep(Duration::from_millis(1));
                continue;
            }
            Ok(_) => {}
            Err(e) if e.kind() == io::ErrorKind::TimedOut => continue,
            Err(e) => return Err(e),
        }
        // Collect one line frame, corrupt it if asked, then decode it.
        frame.push(byte[0]);
        if byte[0] != 0 || frame.len() == 1 {
            continue;
        }
        if corrupt_frames.contains(&index) {
            corrupt(&mut frame);
        }
        index += 1;
        for &b in &frame {
            let reply = match dec.feed::<ToRc>(b) {
                None => continue,
                Some(Ok(p)) => {
                    if let ToRc::StartRender { frames } = p.msg {
                        start_render = Some(frames);
                    }
                    rx.on_message(&p.msg, &mut enc, &mut out)
                }
                Some(Err(e)) => {
                    bad_frames += 1;
                    rx.on_bad_frame(e, &mut enc, &mut out)
                }
            }
            .map_err(other)?;
            if let UploadEvent::Complete { .. } = reply.event {
                done_at.get_or_insert(Instant::now());
            }
            port.write_all(&out[..reply.len])?;
            port.flush()?;
        }
        frame.clear();
        deadline = Instant::now() + timeout;
    }
}
