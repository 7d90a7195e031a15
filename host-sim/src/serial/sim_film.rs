//! A simulated RC serving a film (`links upload --frames`): the firmware's own session
//! ([`Session::with_banks`], [`links_core::serial::film`]) over two byte streams, with the
//! host's renderer in place of the cluster. A frame is streamed one row per turn of the
//! loop, and the PC's bytes are taken between rows, so the next frame's upload overlaps the
//! readback as on the board. Every film event is logged for the tests' order checks; faults
//! can corrupt one scene chunk of a frame, one pixel message, or a frame's CRC.

use super::sim_rc::{block_on, corrupt, Faults, Room0};
use crate::frame::{render_frame, Precision};
use links_core::serial::film::bank_of;
use links_core::serial::readback::{ByteQueue, Readback};
use links_core::serial::render::resend_runs;
use links_core::serial::render::RenderFail;
use links_core::serial::session::{Session, Step};
use links_core::serial::{Encoder, FrameStreamer};
use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

/// What the simulated RC does wrong, per film frame.
#[derive(Clone, Debug, Default)]
pub struct FilmFaults {
    /// Corrupt the first line frame (a scene chunk) after this frame's `FrameBegin`.
    pub corrupt_chunk_of: Option<u16>,
    /// Corrupt the first pixel message of this frame.
    pub corrupt_run_of: Option<u16>,
    /// Announce a wrong CRC in every `FrameEnd` of this frame.
    pub wrong_crc_of: Option<u16>,
    /// Lose this frame's `FrameStarted` on the line (the PC must take its header as the
    /// start).
    pub lose_started_of: Option<u16>,
}

/// A film event on the RC, in the order it happened.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FilmLog {
    /// The PC began uploading the frame (`FrameBegin` accepted, first time).
    Begin(u16),
    /// The frame started rendering (`FrameStarted` sent).
    Started(u16),
    /// Its `FrameEnd` went out.
    Rendered(u16),
    /// The PC acknowledged it.
    Acked(u16),
}

/// What the simulated RC saw.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FilmServed {
    pub log: Vec<FilmLog>,
    /// Retransmit requests (`Nak`s) sent during uploads.
    pub naks: u32,
    /// Pixel retransmit requests answered.
    pub resends: u32,
    /// Malformed frames received from the PC.
    pub bad_packets: u32,
}

/// Frames queued for the line, faults applied per frame.
struct Queue {
    bytes: Vec<u8>,
    faults: Faults,
}

impl ByteQueue for Queue {
    fn free(&self) -> usize {
        usize::MAX
    }

    fn push(&mut self, b: &[u8]) -> bool {
        let f = self.faults.apply(b);
        self.bytes.extend_from_slice(&f);
        true
    }
}

/// The frame the "cluster" is streaming: its pixels and the rows still to send.
struct Job {
    frame: u16,
    rgb: Vec<u8>,
    width: usize,
    rb: Readback<Queue>,
    /// Rows still to send, bottom first (any order is allowed).
    rows: Vec<u16>,
}

/// The last frame streamed, for `Resend`s.
struct Done {
    frame: u16,
    rgb: Vec<u8>,
    fs: FrameStreamer,
    faults: Faults,
}

/// The simulated RC's state between turns.
struct Rc<'b, 'w, W> {
    session: Session<'b>,
    tx: &'w mut W,
    faults: &'w FilmFaults,
    served: FilmServed,
    job: Option<Job>,
    done: Option<Done>,
    /// The film encoder: frame messages (the session's numbers upload replies).
    enc: Encoder,
    /// The frame whose `FrameBegin` was logged last.
    begun: Option<u16>,
    /// Corrupt the next line frame from the PC.
    corrupt_next: bool,
}

/// Serve a film over `rx` / `tx` (the RC's ends) with two scene banks of `bank` bytes, until
/// the PC has acknowledged every frame of the film (its length from `FrameBegin`), or fail
/// after `timeout` without a byte from the PC while nothing renders. `rx` should time out
/// its reads after a few milliseconds: the RC streams a row between reads.
pub fn serve_film<R: Read, W: Write>(
    rx: &mut R,
    tx: &mut W,
    bank: usize,
    faults: &FilmFaults,
    timeout: Duration,
) -> io::Result<FilmServed> {
    let (mut even, mut odd) = (vec![0u8; bank], vec![0u8; bank]);
    let mut rc = Rc {
        session: Session::with_banks(&mut even, &mut odd),
        tx,
        faults,
        served: FilmServed::default(),
        job: None,
        done: None,
        enc: Encoder::new(),
        begun: None,
        corrupt_next: false,
    };
    let mut frame = Vec::new();
    let mut buf = [0u8; 256];
    let mut heard = Instant::now();
    loop {
        let n = match rx.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::TimedOut => 0,
            Err(e) => return Err(e),
        };
        if n > 0 {
            heard = Instant::now();
        }
        for &b in &buf[..n] {
            frame.push(b);
            if b == 0 && frame.len() > 1 {
                rc.line_frame(&mut frame)?;
                frame.clear();
            }
        }
        rc.row()?;
        let acked = rc
            .served
            .log
            .iter()
            .filter(|l| matches!(l, FilmLog::Acked(_)))
            .count();
        if rc.begun.is_some() && acked >= usize::from(rc.session.film.frames) {
            rc.served.naks = rc.session.upload.naks() + rc.session.odd.naks();
            rc.served.bad_packets = rc.session.bad_packets();
            return Ok(rc.served);
        }
        if rc.job.is_none() && heard.elapsed() > timeout {
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                format!("film stalled: {:?}", rc.served.log),
            ));
        }
        if n == 0 && rc.job.is_none() {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

impl<W: Write> Rc<'_, '_, W> {
    /// One line frame from the PC (delimiters included), corrupted if a fault says so.
    fn line_frame(&mut self, frame: &mut [u8]) -> io::Result<()> {
        if std::mem::take(&mut self.corrupt_next) {
            corrupt(frame);
        }
        for &b in frame.iter() {
            let step = self.session.feed(b);
            self.note_begin();
            match step {
                Step::Reply(n) => self.tx.write_all(self.session.reply(n))?,
                Step::Acked { frame } => self.served.log.push(FilmLog::Acked(frame)),
                Step::Resend { frame, start, len } => self.resend(frame, start, len)?,
                Step::Nothing | Step::Render { .. } => {}
            }
            self.start()?;
        }
        self.tx.flush()
    }

    /// Log a `FrameBegin` the session took (and arm the chunk fault for its frame).
    fn note_begin(&mut self) {
        let loading = self.session.film.loading.map(|l| l.frame);
        if loading.is_some() && loading != self.begun {
            self.begun = loading;
            if let Some(f) = loading {
                self.served.log.push(FilmLog::Begin(f));
                self.corrupt_next = self.faults.corrupt_chunk_of == Some(f);
            }
        }
    }

    /// Start the next stored frame if the cluster is free: render it (the host's renderer,
    /// f32 as on the nodes) and queue its header.
    fn start(&mut self) -> io::Result<()> {
        if self.job.is_some() {
            return Ok(());
        }
        let Some((frame, n)) = self.session.start_next() else {
            return Ok(());
        };
        if self.faults.lose_started_of != Some(frame) {
            self.tx.write_all(self.session.reply(n))?;
        }
        self.served.log.push(FilmLog::Started(frame));
        let image = self
            .session
            .bank(bank_of(frame))
            .image()
            .map(<[u8]>::to_vec)
            .unwrap_or_default();
        let pic = render_frame(&image, Precision::F32, 1, &|| {}).map_err(io::Error::other)?;
        let (w, h) = (pic.width as u16, pic.height as u16);
        let faults = Faults {
            corrupt_runs: if self.faults.corrupt_run_of == Some(frame) {
                vec![0]
            } else {
                Vec::new()
            },
            wrong_crc: self.faults.wrong_crc_of == Some(frame),
            ..Faults::default()
        };
        let queue = Queue {
            bytes: Vec::new(),
            faults,
        };
        let enc = std::mem::take(&mut self.enc);
        let rb = Readback::new(queue, enc, frame, w, h).map_err(io::Error::other)?;
        self.job = Some(Job {
            frame,
            rgb: pic.rgb,
            width: usize::from(w),
            rb,
            rows: (0..h).collect(),
        });
        self.flush_job()
    }

    /// Write what the job queued to the line.
    fn flush_job(&mut self) -> io::Result<()> {
        if let Some(j) = self.job.as_mut() {
            self.tx.write_all(&j.rb.queue.bytes)?;
            j.rb.queue.bytes.clear();
        }
        self.tx.flush()
    }

    /// Stream one row of the frame rendering; at its end, the `FrameEnd`.
    fn row(&mut self) -> io::Result<()> {
        let Some(j) = self.job.as_mut() else {
            return Ok(());
        };
        if let Some(y) = j.rows.pop() {
            let at = 3 * usize::from(y) * j.width;
            let px = j.rgb.get(at..at + 3 * j.width).unwrap_or(&[]).to_vec();
            links_core::root::PixelSink::pixels(&mut j.rb, j.frame, y, 0, &px);
            return self.flush_job();
        }
        let Some(j) = self.job.take() else {
            return Ok(());
        };
        let ended = j.rb.end();
        self.enc = ended.enc;
        let mut q = ended.queue;
        self.tx.write_all(&q.bytes)?;
        q.bytes.clear();
        ended.result.map_err(io::Error::other)?;
        self.session.film.rendered(j.frame);
        self.served.log.push(FilmLog::Rendered(j.frame));
        self.done = Some(Done {
            frame: j.frame,
            rgb: j.rgb,
            fs: ended.streamer,
            faults: q.faults,
        });
        self.tx.flush()?;
        self.start()
    }

    /// Answer a `Resend` of the last frame streamed (while its bank is held).
    fn resend(&mut self, frame: u16, start: u32, len: u32) -> io::Result<()> {
        let held = self.session.film.resend_bank(frame).is_some();
        let Some(d) = self.done.as_mut().filter(|d| d.frame == frame && held) else {
            return Ok(());
        };
        self.served.resends += 1;
        let w = usize::from(d.fs.width());
        let rgb = &d.rgb;
        let pixels = |y: u16, x: u16, px: &mut [[u8; 3]]| {
            let at = 3 * (usize::from(y) * w + usize::from(x));
            let src = rgb.get(at..at + 3 * px.len()).ok_or(RenderFail::BadScene)?;
            px.as_flattened_mut().copy_from_slice(src);
            Ok(())
        };
        let mut q = Queue {
            bytes: Vec::new(),
            faults: std::mem::take(&mut d.faults),
        };
        let r = block_on(resend_runs(
            &d.fs,
            start,
            len,
            &mut self.enc,
            &Room0,
            &mut q,
            pixels,
        ));
        d.faults = q.faults;
        self.tx.write_all(&q.bytes)?;
        r.map_err(io::Error::other)
    }
}
