//! `upload` and `readback` against scripted misbehaving RCs, in memory and on a virtual
//! clock: every pattern must end with its own error, within a bounded number of messages.
//!
//! The scripted port hands the PC at most `cap` bytes; past that its reads fail, so a PC
//! that would never give up ends the test (with an I/O error the assertions reject) instead
//! of hanging it.

use links_core::serial::{
    Decoder, Encoder, ToPc, ToRc, UploadReceiver, MAX_DIM, MAX_TO_PC, MAX_TO_RC,
};
use links_core::wire::CRC32;
use links_host::serial_host::{
    readback_with_clock, upload_deadline, upload_with_clock, Clock, HostSerialError,
    ReadbackOptions, UploadOptions, VirtualClock,
};
use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::time::Duration;

/// The RC's end of the line: what it has sent and not yet been read.
struct Tx {
    enc: Encoder,
    queue: VecDeque<u8>,
    buf: [u8; MAX_TO_PC],
    /// Messages sent.
    sent: u64,
}

impl Tx {
    fn send(&mut self, msg: &ToPc<'_>) {
        let n = self.enc.encode(msg, &mut self.buf).expect("fits");
        self.queue.extend(&self.buf[..n]);
        self.sent += 1;
    }

    /// The `FrameHeader` of a `W` x `H` frame `frame`.
    fn header(&mut self, frame: u16) {
        self.send(&ToPc::FrameHeader {
            frame,
            width: W,
            height: H,
        });
    }
}

/// A misbehaving RC.
trait Script {
    /// The PC sent `msg`.
    fn on_pc(&mut self, _msg: &ToRc<'_>, _tx: &mut Tx) {}
    /// The PC waits and nothing is queued: send more, or nothing (silence).
    fn chatter(&mut self, _tx: &mut Tx) {}
}

/// What the PC sent.
#[derive(Default, Debug)]
struct PcLog {
    chunks: u32,
    resends: u32,
    begins: u32,
}

/// An in-memory serial port with a scripted RC at the other end.
struct Port<S> {
    script: S,
    tx: Tx,
    dec: Decoder<MAX_TO_RC>,
    pc: PcLog,
    /// Bytes handed to the PC.
    read: u64,
    cap: u64,
}

impl<S: Script> Port<S> {
    fn new(script: S, cap: u64) -> Self {
        Port {
            script,
            tx: Tx {
                enc: Encoder::new(),
                queue: VecDeque::new(),
                buf: [0; MAX_TO_PC],
                sent: 0,
            },
            dec: Decoder::new(),
            pc: PcLog::default(),
            read: 0,
            cap,
        }
    }
}

impl<S: Script> Read for Port<S> {
    fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
        if self.read >= self.cap {
            return Err(io::Error::other(format!(
                "harness cap: the PC read {} bytes and did not give up",
                self.read
            )));
        }
        if self.tx.queue.is_empty() {
            self.script.chatter(&mut self.tx);
        }
        if self.tx.queue.is_empty() {
            return Err(io::ErrorKind::WouldBlock.into());
        }
        let n = out
            .len()
            .min(self.tx.queue.len())
            .min((self.cap - self.read) as usize);
        for (o, b) in out.iter_mut().zip(self.tx.queue.drain(..n)) {
            *o = b;
        }
        self.read += n as u64;
        Ok(n)
    }
}

impl<S: Script> Write for Port<S> {
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        for &b in bytes {
            if let Some(Ok(p)) = self.dec.feed::<ToRc>(b) {
                match p.msg {
                    ToRc::SceneChunk { .. } => self.pc.chunks += 1,
                    ToRc::Resend { .. } => self.pc.resends += 1,
                    ToRc::SceneBegin { .. } => self.pc.begins += 1,
                    _ => {}
                }
                self.script.on_pc(&p.msg, &mut self.tx);
            }
        }
        Ok(bytes.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

const CAP: u64 = 8 << 20;

fn clock() -> VirtualClock {
    VirtualClock::new(Duration::from_millis(1))
}

fn readback_of<S: Script>(port: &mut Port<S>, clock: &VirtualClock) -> HostSerialError {
    readback_with_clock(port, "script", &ReadbackOptions::default(), clock, &|_| {})
        .expect_err("a misbehaving RC")
}

// ---- readback ----

const W: u16 = 16;
const H: u16 = 8;
const TOTAL: u32 = W as u32 * H as u32;

fn rgb() -> Vec<u8> {
    (0..3 * TOTAL).map(|i| (i * 7 % 251) as u8).collect()
}

/// Send frame `frame` (header, every row but `skip`, FrameEnd with the right CRC).
fn stream_frame(tx: &mut Tx, frame: u16, rgb: &[u8], skip: Option<u16>) {
    tx.header(frame);
    for y in (0..H).filter(|&y| Some(y) != skip) {
        let row = 3 * W as usize * y as usize;
        tx.send(&ToPc::Pixels {
            frame,
            y,
            x: 0,
            rgb: &rgb[row..row + 3 * W as usize],
        });
    }
    tx.send(&ToPc::FrameEnd {
        frame,
        crc: CRC32.checksum(rgb),
    });
}

/// A header, then `Progress` with the same `done` forever.
struct EndlessProgress {
    started: bool,
}

impl Script for EndlessProgress {
    fn chatter(&mut self, tx: &mut Tx) {
        if !std::mem::replace(&mut self.started, true) {
            tx.header(3);
        }
        tx.send(&ToPc::Progress {
            frame: 3,
            done: 5,
            total: TOTAL,
        });
    }
}

#[test]
fn endless_progress_ends_after_1000_messages_without_pixels() {
    let clock = clock();
    let mut port = Port::new(EndlessProgress { started: false }, CAP);
    let e = readback_of(&mut port, &clock);
    assert_eq!(
        e,
        HostSerialError::NoProgress {
            messages: 1000,
            last: "Progress"
        }
    );
    // The header, then exactly the 1000 idle messages.
    assert_eq!(port.tx.sent, 1001);
    assert!(e
        .to_string()
        .contains("the RC sent 1000 messages in a row without progress (last: Progress)"));
}

/// `Progress` one pixel further each time, forever, and never a header.
struct CreepingProgress {
    done: u32,
    header: bool,
}

impl Script for CreepingProgress {
    fn chatter(&mut self, tx: &mut Tx) {
        if self.header && self.done == 0 {
            tx.header(0);
        }
        self.done += 1;
        tx.send(&ToPc::Progress {
            frame: 0,
            done: self.done,
            total: TOTAL,
        });
    }
}

#[test]
fn creeping_progress_counts_only_whole_rows_and_ends() {
    // Before a header, no Progress is progress.
    let clock = clock();
    let mut port = Port::new(
        CreepingProgress {
            done: 0,
            header: false,
        },
        CAP,
    );
    let e = readback_of(&mut port, &clock);
    assert_eq!(
        e,
        HostSerialError::NoProgress {
            messages: 1000,
            last: "Progress"
        }
    );
    assert_eq!(port.tx.sent, 1000);
    // In a frame, a Progress counts when it is a whole row (16 pixels) further than the last
    // one that counted, up to the frame's 128 pixels: the 128th Progress is the last that
    // counts, then 1000 more end it.
    let mut port = Port::new(
        CreepingProgress {
            done: 0,
            header: true,
        },
        CAP,
    );
    let e = readback_of(&mut port, &clock);
    assert_eq!(
        e,
        HostSerialError::NoProgress {
            messages: 1000,
            last: "Progress"
        }
    );
    assert_eq!(port.tx.sent, 1 + TOTAL as u64 + 1000);
}

/// A new `FrameHeader` (a new frame number) per message.
struct HeaderPerMessage {
    frame: u16,
}

impl Script for HeaderPerMessage {
    fn chatter(&mut self, tx: &mut Tx) {
        tx.header(self.frame);
        self.frame = self.frame.wrapping_add(1);
    }
}

#[test]
fn a_new_frame_header_per_message_ends_at_the_8th_restart() {
    let clock = clock();
    let mut port = Port::new(HeaderPerMessage { frame: 0 }, CAP);
    let e = readback_of(&mut port, &clock);
    assert_eq!(
        e,
        HostSerialError::FrameRestarts {
            restarts: 8,
            frame: 8
        }
    );
    assert_eq!(port.tx.sent, 9);
    assert_eq!(
        e.to_string(),
        "the RC restarted the frame 8 times without finishing one (now frame 8); giving up"
    );
}

/// A header, then the same row of pixels forever.
struct SamePixels {
    rgb: Vec<u8>,
    started: bool,
}

impl Script for SamePixels {
    fn chatter(&mut self, tx: &mut Tx) {
        if !std::mem::replace(&mut self.started, true) {
            tx.header(1);
        }
        tx.send(&ToPc::Pixels {
            frame: 1,
            y: 2,
            x: 0,
            rgb: &self.rgb[..3 * W as usize],
        });
    }
}

#[test]
fn the_same_pixels_forever_end_after_one_frame_of_repeats() {
    let clock = clock();
    let mut port = Port::new(
        SamePixels {
            rgb: rgb(),
            started: false,
        },
        CAP,
    );
    let e = readback_of(&mut port, &clock);
    // 16 new pixels, then repeats: the 9th repeated row (144 > 128 pixels) ends it.
    assert_eq!(
        e,
        HostSerialError::RepeatedPixels {
            frame: Some(1),
            stale: 144,
            allowed: TOTAL as u64
        }
    );
    assert_eq!(port.tx.sent, 1 + 1 + 9);
}

/// Flat 256-pixel runs of a frame the PC never sees the header of, forever.
struct HeaderlessPixels;

impl Script for HeaderlessPixels {
    fn chatter(&mut self, tx: &mut Tx) {
        // One (count-1, r, g, b) quadruple: 256 grey pixels.
        tx.send(&ToPc::PixelsRle {
            frame: 0,
            y: 0,
            x: 0,
            len: 256,
            data: &[255, 9, 9, 9],
        });
    }
}

#[test]
fn pixels_without_a_header_end_after_one_largest_frame() {
    let clock = clock();
    let mut port = Port::new(HeaderlessPixels, CAP);
    let e = readback_of(&mut port, &clock);
    let max = MAX_DIM as u64 * MAX_DIM as u64;
    assert_eq!(
        e,
        HostSerialError::RepeatedPixels {
            frame: None,
            stale: max + 256,
            allowed: max
        }
    );
    assert_eq!(port.tx.sent, max / 256 + 1);
}

/// A frame with one row missing; every `Resend` is answered by a new frame (the same
/// picture, the same row missing).
struct RestartOnResend {
    rgb: Vec<u8>,
    frame: u16,
    started: bool,
}

impl Script for RestartOnResend {
    fn on_pc(&mut self, msg: &ToRc<'_>, tx: &mut Tx) {
        if let ToRc::Resend { .. } = msg {
            self.frame += 1;
            stream_frame(tx, self.frame, &self.rgb, Some(3));
        }
    }

    fn chatter(&mut self, tx: &mut Tx) {
        if !std::mem::replace(&mut self.started, true) {
            stream_frame(tx, self.frame, &self.rgb, Some(3));
        }
    }
}

#[test]
fn restarting_the_frame_on_every_resend_ends_at_the_8th_restart() {
    let clock = clock();
    let mut port = Port::new(
        RestartOnResend {
            rgb: rgb(),
            frame: 0,
            started: false,
        },
        CAP,
    );
    let e = readback_of(&mut port, &clock);
    assert_eq!(
        e,
        HostSerialError::FrameRestarts {
            restarts: 8,
            frame: 8
        }
    );
    // One Resend per frame 0..=7 (row 3 each time), none for frame 8.
    assert_eq!(port.pc.resends, 8);
    // Nothing waited on the clock.
    assert_eq!(clock.now(), Duration::ZERO);
}

/// A frame with one row missing, and every `Resend` answered with the `FrameEnd` alone.
struct SameGapOnResend {
    rgb: Vec<u8>,
    started: bool,
}

impl Script for SameGapOnResend {
    fn on_pc(&mut self, msg: &ToRc<'_>, tx: &mut Tx) {
        if let ToRc::Resend { .. } = msg {
            tx.send(&ToPc::FrameEnd {
                frame: 4,
                crc: CRC32.checksum(&self.rgb),
            });
        }
    }

    fn chatter(&mut self, tx: &mut Tx) {
        if !std::mem::replace(&mut self.started, true) {
            stream_frame(tx, 4, &self.rgb, Some(5));
        }
    }
}

#[test]
fn the_same_gap_after_every_resend_ends_after_5_rounds() {
    let clock = clock();
    let mut port = Port::new(
        SameGapOnResend {
            rgb: rgb(),
            started: false,
        },
        CAP,
    );
    let e = readback_of(&mut port, &clock);
    assert_eq!(
        e,
        HostSerialError::Retries {
            what: "frame 4 still lacks 16 pixels".into(),
            tries: 5
        }
    );
    assert_eq!(port.pc.resends, 5);
}

/// Advancing `Progress` of a 1024-pixel-wide frame, one every 100 ms: a slow RC that keeps
/// every rule.
struct SlowProgress {
    ticks: u32,
    done: u32,
}

impl Script for SlowProgress {
    fn chatter(&mut self, tx: &mut Tx) {
        self.ticks += 1;
        if self.ticks == 1 {
            tx.send(&ToPc::FrameHeader {
                frame: 0,
                width: MAX_DIM,
                height: MAX_DIM,
            });
        } else if self.ticks.is_multiple_of(100) {
            self.done += MAX_DIM as u32;
            tx.send(&ToPc::Progress {
                frame: 0,
                done: self.done,
                total: MAX_DIM as u32 * MAX_DIM as u32,
            });
        }
    }
}

#[test]
fn the_overall_deadline_ends_a_slow_readback() {
    let clock = clock();
    let mut port = Port::new(SlowProgress { ticks: 0, done: 0 }, CAP);
    let opts = ReadbackOptions {
        deadline: Some(Duration::from_secs(2)),
        ..ReadbackOptions::default()
    };
    let e = readback_with_clock(&mut port, "script", &opts, &clock, &|_| {}).unwrap_err();
    assert_eq!(
        e,
        HostSerialError::Deadline {
            port: "script".into(),
            ms: 2000,
            doing: "frame 0: 0 of 1048576 pixels received".into()
        }
    );
    // Virtual time: ended at the deadline, not at a silence time-out.
    assert_eq!(clock.now(), Duration::from_secs(2));
}

/// A well-behaved RC the PC joins mid-way: the tail of frame 0 (no header seen), then
/// frame 1 with a `Progress` after every row and rows 1 and 6 lost on the line; a `Resend`
/// is answered with exactly its span (rows 1..=6, 64 of its 96 pixels repeats).
struct Legit {
    rgb: Vec<u8>,
    started: bool,
}

impl Script for Legit {
    fn on_pc(&mut self, msg: &ToRc<'_>, tx: &mut Tx) {
        if let ToRc::Resend {
            frame: 1,
            start,
            len,
        } = *msg
        {
            let (a, b) = (3 * start as usize, 3 * (start + len) as usize);
            for (i, px) in self.rgb[a..b].chunks(3 * W as usize).enumerate() {
                tx.send(&ToPc::Pixels {
                    frame: 1,
                    y: (start / W as u32) as u16 + i as u16,
                    x: 0,
                    rgb: px,
                });
            }
            tx.send(&ToPc::FrameEnd {
                frame: 1,
                crc: CRC32.checksum(&self.rgb),
            });
        }
    }

    fn chatter(&mut self, tx: &mut Tx) {
        if std::mem::replace(&mut self.started, true) {
            return;
        }
        let row = |y: u16| 3 * W as usize * y as usize..3 * W as usize * (y as usize + 1);
        for y in 4..H {
            tx.send(&ToPc::Pixels {
                frame: 0,
                y,
                x: 0,
                rgb: &self.rgb[row(y)],
            });
        }
        tx.send(&ToPc::FrameEnd { frame: 0, crc: 1 });
        tx.header(1);
        for y in 0..H {
            if y != 1 && y != 6 {
                tx.send(&ToPc::Pixels {
                    frame: 1,
                    y,
                    x: 0,
                    rgb: &self.rgb[row(y)],
                });
            }
            tx.send(&ToPc::Progress {
                frame: 1,
                done: (y as u32 + 1) * W as u32,
                total: TOTAL,
            });
        }
        tx.send(&ToPc::FrameEnd {
            frame: 1,
            crc: CRC32.checksum(&self.rgb),
        });
    }
}

#[test]
fn a_well_behaved_rc_joined_mid_frame_passes_every_rule() {
    let clock = clock();
    let mut port = Port::new(
        Legit {
            rgb: rgb(),
            started: false,
        },
        CAP,
    );
    let r = readback_with_clock(
        &mut port,
        "script",
        &ReadbackOptions::default(),
        &clock,
        &|_| {},
    )
    .expect("a good frame");
    assert_eq!((r.frame, r.width, r.height), (1, W as u32, H as u32));
    assert_eq!(r.rgb, rgb());
    assert_eq!(r.resends, 1);
    assert_eq!(port.pc.resends, 1);
}

// ---- upload ----

fn image() -> Vec<u8> {
    (0..3000u32).map(|i| (i * 13 % 256) as u8).collect()
}

fn upload_of<S: Script>(port: &mut Port<S>, clock: &VirtualClock) -> HostSerialError {
    upload_with_clock(
        port,
        "script",
        &image(),
        &UploadOptions::default(),
        clock,
        &|_| {},
    )
    .expect_err("a misbehaving RC")
}

/// `Ack(0)` to the `SceneBegin`, then chunks answered by `answer(offset, len, k)` (k: the
/// chunk's index among those received).
struct Answers<F: FnMut(u32, u32, u32) -> Option<ToPc<'static>>> {
    answer: F,
    chunks: u32,
    /// Repeat the last answer whenever the PC waits.
    flood: bool,
    last: Option<ToPc<'static>>,
}

fn answers<F: FnMut(u32, u32, u32) -> Option<ToPc<'static>>>(answer: F) -> Answers<F> {
    Answers {
        answer,
        chunks: 0,
        flood: false,
        last: None,
    }
}

impl<F: FnMut(u32, u32, u32) -> Option<ToPc<'static>>> Script for Answers<F> {
    fn on_pc(&mut self, msg: &ToRc<'_>, tx: &mut Tx) {
        let reply = match *msg {
            ToRc::SceneBegin { .. } => Some(ToPc::Ack { offset: 0 }),
            ToRc::SceneChunk { offset, data } => {
                self.chunks += 1;
                (self.answer)(offset, data.len() as u32, self.chunks - 1)
            }
            _ => None,
        };
        if let Some(r) = reply {
            tx.send(&r);
            self.last = Some(r);
        }
    }

    fn chatter(&mut self, tx: &mut Tx) {
        if let (true, Some(r)) = (self.flood, self.last) {
            tx.send(&r);
        }
    }
}

#[test]
fn alternating_ack_and_nak_0_ends_after_8_sends_without_progress() {
    let clock = clock();
    let mut port = Port::new(
        answers(|offset, len, k| {
            Some(if k % 2 == 0 {
                ToPc::Ack {
                    offset: offset + len,
                }
            } else {
                ToPc::Nak { offset: 0 }
            })
        }),
        CAP,
    );
    let e = upload_of(&mut port, &clock);
    assert_eq!(
        e,
        HostSerialError::Rewinds {
            tries: 8,
            nak: 0,
            acked: 512
        }
    );
    // The first chunk, then 8 sends that never got past byte 512.
    assert_eq!(port.pc.chunks, 9);
    assert_eq!(clock.now(), Duration::ZERO);
}

#[test]
fn acks_that_never_advance_end_without_a_silence_time_out() {
    // Every chunk is answered by an Ack of its own offset, over and over.
    let clock = clock();
    let mut script = answers(|offset, _, _| Some(ToPc::Ack { offset }));
    script.flood = true;
    let mut port = Port::new(script, CAP);
    let e = upload_of(&mut port, &clock);
    // 16 stale answers to each of 8 sends.
    assert_eq!(
        e,
        HostSerialError::StaleAcks {
            tries: 8,
            at: 0,
            answers: 128
        }
    );
    assert_eq!(port.pc.chunks, 8);
    assert_eq!(clock.now(), Duration::ZERO);
    // Answered once per send (no flood): each wait ends at the reply time-out, and the
    // error still names what the RC did.
    let clock = self::clock();
    let mut port = Port::new(answers(|offset, _, _| Some(ToPc::Ack { offset })), CAP);
    let e = upload_of(&mut port, &clock);
    assert_eq!(
        e,
        HostSerialError::StaleAcks {
            tries: 8,
            at: 0,
            answers: 8
        }
    );
    assert_eq!(clock.now(), Duration::from_secs(8));
}

#[test]
fn acks_of_the_whole_scene_without_scene_done_end() {
    // Every chunk acknowledged, the last one too, but never a SceneDone.
    let clock = clock();
    let mut port = Port::new(
        answers(|offset, len, _| {
            Some(ToPc::Ack {
                offset: offset + len,
            })
        }),
        CAP,
    );
    let e = upload_of(&mut port, &clock);
    assert_eq!(
        e,
        HostSerialError::StaleAcks {
            tries: 8,
            at: 3000,
            answers: 8
        }
    );
    // 6 chunks, then the last one 8 times.
    assert_eq!(port.pc.chunks, 6 + 8);
}

#[test]
fn answers_about_bytes_never_sent_are_refused() {
    let crc = CRC32.checksum(&image());
    // Acks a chunk ahead (and SceneDone once that reaches the end): the PC would skip bytes.
    let clock = clock();
    let mut port = Port::new(
        answers(|offset, _, _| {
            let a = (offset + 1024).min(3000);
            Some(if a == 3000 {
                ToPc::SceneDone { len: 3000, crc }
            } else {
                ToPc::Ack { offset: a }
            })
        }),
        CAP,
    );
    assert_eq!(
        upload_of(&mut port, &clock),
        HostSerialError::BeyondSent {
            answer: "Ack",
            offset: 1024,
            sent: 512
        }
    );
    // SceneDone after the first chunk.
    let mut port = Port::new(
        answers(|_, _, _| Some(ToPc::SceneDone { len: 3000, crc })),
        CAP,
    );
    assert_eq!(
        upload_of(&mut port, &clock),
        HostSerialError::BeyondSent {
            answer: "SceneDone",
            offset: 3000,
            sent: 512
        }
    );
    // A Nak asking to go on from a byte never sent.
    let mut port = Port::new(
        answers(|offset, _, _| {
            Some(ToPc::Nak {
                offset: offset + 1024,
            })
        }),
        CAP,
    );
    let e = upload_of(&mut port, &clock);
    assert_eq!(
        e,
        HostSerialError::BeyondSent {
            answer: "Nak",
            offset: 1024,
            sent: 512
        }
    );
    assert_eq!(
        e.to_string(),
        "the RC's Nak names byte 1024, but only 512 bytes were sent; giving up"
    );
}

#[test]
fn the_overall_deadline_ends_an_upload() {
    // An RC that answers each chunk only after 900 ms of silence: every answer moves the
    // upload on, so only the overall deadline ends it.
    struct Slow {
        pending: Option<u32>,
        waited: u32,
    }
    impl Script for Slow {
        fn on_pc(&mut self, msg: &ToRc<'_>, tx: &mut Tx) {
            match *msg {
                ToRc::SceneBegin { .. } => tx.send(&ToPc::Ack { offset: 0 }),
                ToRc::SceneChunk { offset, data } => {
                    self.pending = Some(offset + data.len() as u32);
                    self.waited = 0;
                }
                _ => {}
            }
        }
        fn chatter(&mut self, tx: &mut Tx) {
            self.waited += 1;
            if self.waited >= 900 {
                if let Some(offset) = self.pending.take() {
                    tx.send(&ToPc::Ack { offset });
                }
            }
        }
    }
    let clock = clock();
    let mut port = Port::new(
        Slow {
            pending: None,
            waited: 0,
        },
        CAP,
    );
    let opts = UploadOptions {
        deadline: Some(Duration::from_secs(2)),
        ..UploadOptions::default()
    };
    let e = upload_with_clock(&mut port, "script", &image(), &opts, &clock, &|_| {}).unwrap_err();
    assert_eq!(
        e,
        HostSerialError::Deadline {
            port: "script".into(),
            ms: 2000,
            doing: "1024 of 3000 bytes acknowledged".into()
        }
    );
    assert_eq!(clock.now(), Duration::from_secs(2));
}

/// The firmware's own `UploadReceiver`, which already holds the first two chunks of the
/// scene (an interrupted upload).
struct Receiver {
    rx: UploadReceiver<'static>,
}

impl Script for Receiver {
    fn on_pc(&mut self, msg: &ToRc<'_>, tx: &mut Tx) {
        let r = self
            .rx
            .on_message(msg, &mut tx.enc, &mut tx.buf)
            .expect("fits");
        tx.queue.extend(&tx.buf[..r.len]);
    }
}

#[test]
fn an_interrupted_upload_resumes_where_the_rc_stopped() {
    let image = image();
    let store: &'static mut [u8] = Box::leak(vec![0u8; 4096].into_boxed_slice());
    let mut rx = UploadReceiver::new(store);
    let (mut enc, mut out) = (Encoder::new(), [0u8; MAX_TO_PC]);
    let crc = CRC32.checksum(&image);
    rx.on_message(&ToRc::SceneBegin { len: 3000, crc }, &mut enc, &mut out)
        .unwrap();
    for offset in [0u32, 512] {
        let data = &image[offset as usize..offset as usize + 512];
        rx.on_message(&ToRc::SceneChunk { offset, data }, &mut enc, &mut out)
            .unwrap();
    }
    assert_eq!(rx.received(), 1024);
    let clock = clock();
    let mut port = Port::new(Receiver { rx }, CAP);
    let r = upload_with_clock(
        &mut port,
        "script",
        &image,
        &UploadOptions::default(),
        &clock,
        &|_| {},
    )
    .expect("resumed");
    // SceneBegin is answered with Ack(1024): bytes 1024..3000 in 4 chunks.
    assert_eq!((r.chunks_sent, r.naks, r.timeouts), (4, 0, 0));
    assert_eq!(port.script.rx.image(), Some(&image[..]));
}

#[test]
fn the_default_upload_deadline_follows_the_scene_size_and_baud_rate() {
    let opts = UploadOptions::default();
    // 10 s + 2 x 8 reply time-outs of 1 s + 4 x the line time: 257 frames of up to
    // 541 + 27 bytes, 10 bits each.
    let ms = |len, baud| upload_deadline(len, baud, &opts).as_millis();
    assert_eq!(ms(131_072, 115_200), 26_000 + 4 * 12_671);
    assert_eq!(ms(131_072, 9_600), 26_000 + 4 * 152_058);
    assert_eq!(ms(100, 115_200), 26_000 + 4 * 98);
    // Longer reply time-outs, longer deadline.
    let slow = UploadOptions {
        reply_timeout: Duration::from_secs(5),
        ..UploadOptions::default()
    };
    assert_eq!(
        upload_deadline(100, 115_200, &slow).as_millis(),
        10_000 + 80_000 + 4 * 98
    );
}
