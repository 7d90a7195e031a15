//! A simulated RC for the serial link: a thin host port of the firmware's own session
//! (`links_core::serial::{session, readback, render}`) over any `std::io` byte stream, with
//! a pre-rendered frame in place of the cluster. The tests run `links readback` /
//! `links upload` against it over a pseudo-terminal; fault injection corrupts chosen frames
//! on the line.

use crate::frame::{render_frame, Precision};
use links_core::root::PixelSink;
use links_core::serial::readback::{ByteQueue, Ended, Readback};
use links_core::serial::render::{resend_runs, RenderFail};
use links_core::serial::session::{Session, Step};
use links_core::serial::throttle::Room;
use links_core::serial::{encode_packet, Decoder, Encoder, Packet, SerialError, ToPc, MAX_TO_PC};
use std::future::Future;
use std::io::{self, Read, Write};
use std::path::Path;
use std::pin::pin;
use std::task::{Context, Poll};
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
pub(super) fn corrupt(frame: &mut [u8]) {
    let i = frame.len() / 2;
    frame[i] = if frame[i] == 0x55 { 0x2a } else { 0x55 };
}

/// The line faults to inject into the RC's frames to the PC.
#[derive(Clone, Debug, Default)]
pub(super) struct Faults {
    /// Indices (0-based) of the pixel messages of the first pass to corrupt.
    pub(super) corrupt_runs: Vec<usize>,
    /// Announce a wrong frame CRC (flip its lowest bit) in every `FrameEnd`.
    pub(super) wrong_crc: bool,
    /// Corrupt the first `FrameEnd`.
    pub(super) corrupt_first_end: bool,
    /// Pixel messages seen so far (first pass and resends).
    pub(super) runs: usize,
}

impl Faults {
    /// Apply the faults to one frame the RC queues (`bytes`, one whole frame).
    pub(super) fn apply(&mut self, bytes: &[u8]) -> Vec<u8> {
        let mut frame = bytes.to_vec();
        let mut dec = Decoder::<MAX_TO_PC>::new();
        let mut end = None;
        let mut run = false;
        for &b in bytes {
            if let Some(Ok(p)) = dec.feed::<ToPc>(b) {
                let p: Packet<ToPc> = p;
                match p.msg {
                    ToPc::Pixels { .. } | ToPc::PixelsRle { .. } => run = true,
                    ToPc::FrameEnd { frame, crc } => end = Some((p.seq, frame, crc)),
                    _ => {}
                }
            }
        }
        if run {
            if self.corrupt_runs.contains(&self.runs) {
                corrupt(&mut frame);
            }
            self.runs += 1;
        }
        if let Some((seq, f, crc)) = end {
            if std::mem::take(&mut self.corrupt_first_end) {
                corrupt(&mut frame);
            } else if self.wrong_crc {
                // The same FrameEnd with its CRC off by one bit.
                let msg = ToPc::FrameEnd {
                    frame: f,
                    crc: crc ^ 1,
                };
                let mut buf = [0u8; MAX_TO_PC];
                if let Ok(n) = encode_packet(seq, &msg, &mut buf) {
                    frame = buf[..n].to_vec();
                }
            }
        }
        frame
    }
}

/// The RC's byte queue on the host: every frame goes straight to the line (through the
/// fault injection); the first write error is kept.
struct Line<'w, W> {
    out: &'w mut W,
    faults: &'w mut Faults,
    error: Option<io::Error>,
}

impl<W: Write> ByteQueue for Line<'_, W> {
    fn free(&self) -> usize {
        usize::MAX
    }

    fn push(&mut self, bytes: &[u8]) -> bool {
        if self.error.is_some() {
            return false;
        }
        let frame = self.faults.apply(bytes);
        match self.out.write_all(&frame) {
            Ok(()) => true,
            Err(e) => {
                self.error = Some(e);
                false
            }
        }
    }
}

impl<W> Line<'_, W> {
    fn result(&mut self) -> io::Result<()> {
        self.error.take().map_or(Ok(()), Err)
    }
}

/// Poll `f` to completion (the RC's futures here only yield, never wait).
pub(super) fn block_on<F: Future>(f: F) -> F::Output {
    let mut f = pin!(f);
    let mut cx = Context::from_waker(std::task::Waker::noop());
    loop {
        if let Poll::Ready(v) = f.as_mut().poll(&mut cx) {
            return v;
        }
    }
}

/// What the simulated RC saw while serving a readback.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ServeReport {
    /// Retransmit requests answered.
    pub resends: u32,
    /// Malformed frames received from the PC.
    pub bad_packets: u32,
}

/// The RC end of a frame readback: one rendered frame and the protocol state.
pub struct SimRc {
    rgb: Vec<u8>,
    frame: u16,
    width: u16,
    height: u16,
    enc: Encoder,
    faults: Faults,
    /// The streamed frame's state, for `Resend` (after [`SimRc::stream`]).
    streamer: Option<links_core::serial::FrameStreamer>,
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
        links_core::serial::FrameStreamer::new(frame, width, height).map_err(|e| e.to_string())?;
        Ok(SimRc {
            rgb,
            frame,
            width,
            height,
            enc: Encoder::new(),
            faults: Faults::default(),
            streamer: None,
            corrupt_runs: Vec::new(),
            wrong_crc: false,
            corrupt_first_end: false,
        })
    }

    /// Stream the whole frame through the firmware's readback sink: header, rows (odd rows
    /// first, as nodes return them out of order), a progress message every 8 rows, and the
    /// frame end with its CRC.
    pub fn stream<W: Write>(&mut self, out: &mut W) -> io::Result<()> {
        self.faults = Faults {
            corrupt_runs: self.corrupt_runs.clone(),
            wrong_crc: self.wrong_crc,
            corrupt_first_end: self.corrupt_first_end,
            runs: 0,
        };
        let mut line = Line {
            out: &mut *out,
            faults: &mut self.faults,
            error: None,
        };
        let enc = std::mem::take(&mut self.enc);
        let (w, h) = (self.width, self.height);
        let mut rb = Readback::new(&mut line, enc, self.frame, w, h).map_err(other)?;
        let row = 3 * w as usize;
        let order = (1..h).step_by(2).chain((0..h).step_by(2));
        for y in order {
            let at = y as usize * row;
            rb.pixels(self.frame, y, 0, &self.rgb[at..at + row]);
        }
        let Ended {
            enc,
            streamer,
            result,
            ..
        } = rb.end();
        self.enc = enc;
        self.streamer = Some(streamer);
        line.result()?;
        result.map_err(other)?;
        self.faults.corrupt_runs.clear();
        out.flush()
    }

    /// Answer the PC's requests after [`SimRc::stream`] with the firmware's session:
    /// `Resend` (the pixels again, then the frame end), until the PC acknowledges the frame
    /// or `timeout` of silence.
    pub fn answer<P: Read + Write>(
        &mut self,
        port: &mut P,
        timeout: Duration,
    ) -> io::Result<ServeReport> {
        let Some(fs) = self.streamer.clone() else {
            return Err(io::Error::other("answer before stream"));
        };
        let mut session = Session::new(&mut []);
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
            if !read_byte(port, &mut byte)? {
                continue;
            }
            let step = session.feed(byte[0]);
            report.bad_packets = session.bad_packets();
            match step {
                Step::Nothing | Step::Reply(_) => continue,
                _ => deadline = Instant::now() + timeout,
            }
            match step {
                Step::Acked { frame } if frame == fs.frame() => return Ok(report),
                Step::Resend { frame, start, len } if frame == fs.frame() => {
                    report.resends += 1;
                    let mut line = Line {
                        out: &mut *port,
                        faults: &mut self.faults,
                        error: None,
                    };
                    let (rgb, w) = (&self.rgb, self.width as usize);
                    let pixels = |y: u16, x: u16, px: &mut [[u8; 3]]| {
                        let at = 3 * (y as usize * w + x as usize);
                        let src = rgb.get(at..at + 3 * px.len()).ok_or(RenderFail::BadScene)?;
                        px.as_flattened_mut().copy_from_slice(src);
                        Ok(())
                    };
                    let room = Room0;
                    let r = block_on(resend_runs(
                        &fs,
                        start,
                        len,
                        &mut self.enc,
                        &room,
                        &mut line,
                        pixels,
                    ));
                    line.result()?;
                    r.map_err(io::Error::other)?;
                    port.flush()?;
                }
                _ => {}
            }
        }
    }
}

/// Room that is always there (the host line never fills).
pub(super) struct Room0;

impl Room for Room0 {
    fn has_room(&self, _: usize) -> bool {
        true
    }

    async fn wait_room(&self, _: usize) {}
}

/// Read one byte into `byte`: `Ok(false)` when none came yet (time-out or end of input,
/// after a short sleep for the latter).
pub(super) fn read_byte<P: Read>(port: &mut P, byte: &mut [u8; 1]) -> io::Result<bool> {
    match port.read(byte) {
        Ok(0) => {
            std::thread::sleep(Duration::from_millis(1));
            Ok(false)
        }
        Ok(_) => Ok(true),
        Err(e) if e.kind() == io::ErrorKind::TimedOut => Ok(false),
        Err(e) => Err(e),
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
    pub bad_packets: u32,
    /// Whether a `StartRender` followed, and for how many frames.
    pub start_render: Option<u16>,
}

/// Receive a scene upload into a buffer of `capacity` bytes with the firmware's session
/// (its [`links_core::serial::UploadReceiver`]). The PC frames whose 0-based indices are in
/// `corrupt_frames` are corrupted on arrival (as by line noise). Returns once the scene is
/// complete (and a `StartRender`, if the PC sends one within `linger`), or fails after
/// `timeout` of silence.
pub fn receive_upload<P: Read + Write>(
    port: &mut P,
    capacity: usize,
    corrupt_frames: &[usize],
    timeout: Duration,
    linger: Duration,
) -> io::Result<ReceivedUpload> {
    let mut store = vec![0u8; capacity];
    let mut session = Session::new(&mut store);
    let mut frame = Vec::new();
    let mut index = 0usize;
    let mut done_at: Option<Instant> = None;
    let mut start_render = None;
    let mut deadline = Instant::now() + timeout;
    let mut byte = [0u8; 1];
    loop {
        let now = Instant::now();
        if done_at.is_some_and(|t| now >= t + linger) || start_render.is_some() {
            let image = session
                .upload
                .image()
                .map(<[u8]>::to_vec)
                .unwrap_or_default();
            return Ok(ReceivedUpload {
                image,
                naks: session.upload.naks(),
                bad_packets: session.bad_packets(),
                start_render,
            });
        }
        if now >= deadline {
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                format!(
                    "upload incomplete: {} bytes received",
                    session.upload.received()
                ),
            ));
        }
        if !read_byte(port, &mut byte)? {
            continue;
        }
        // Collect one line frame, corrupt it if asked, then feed it to the session.
        frame.push(byte[0]);
        if byte[0] != 0 || frame.len() == 1 {
            continue;
        }
        if corrupt_frames.contains(&index) {
            corrupt(&mut frame);
        }
        index += 1;
        for &b in &frame {
            match session.feed(b) {
                Step::Reply(n) => {
                    port.write_all(session.reply(n))?;
                    port.flush()?;
                }
                Step::Render { frames } => start_render = Some(frames),
                _ => {}
            }
            if session.upload.image().is_some() {
                done_at.get_or_insert(Instant::now());
            }
        }
        frame.clear();
        deadline = Instant::now() + timeout;
    }
}
