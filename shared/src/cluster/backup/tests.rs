use super::*;
use crate::cluster::wire::{rle_decode, Region};

fn job(id: u32) -> Job {
    Job {
        id,
        frame: 3,
        region: Region::Span {
            start: 1000,
            len: 700,
        },
    }
}

fn every_message<'a>(data: &'a [u8]) -> [Msg<'a>; 8] {
    [
        Msg::RollCall,
        Msg::Health(Health {
            frame: 7,
            scene_bytes: 70_000,
            scene_ok: true,
            jobs_done: u32::MAX,
            errors: 3,
            firmware: FIRMWARE_ID,
        }),
        Msg::Scene {
            frame: u16::MAX,
            offset: u32::MAX,
            total: u32::MAX,
            crc: u32::MAX,
            data: &data[..SCENE_DATA],
        },
        Msg::Work { job: job(u32::MAX) },
        Msg::Poll { ack: u16::MAX },
        Msg::Idle,
        Msg::Pixels {
            seq: u16::MAX,
            job: u32::MAX,
            frame: u16::MAX,
            y: u16::MAX,
            x: u16::MAX,
            len: u16::MAX,
            done: true,
            rle: &data[..PIXEL_DATA],
        },
        Msg::Ack,
    ]
}

/// Every message, with its fields at their widest, round-trips and fits one frame.
#[test]
fn every_message_round_trips_within_a_frame() {
    let data = [0xA5u8; 256];
    for msg in every_message(&data) {
        for addr in [1, MAX_ADDR, BROADCAST] {
            let mut buf = [0u8; MAX_FRAME];
            let n = encode(addr, &msg, &mut buf).unwrap();
            assert!(n <= MAX_FRAME);
            assert_eq!(frame_len(&buf[..n]), Some(n));
            assert_eq!(decode(&buf[..n]), Ok((addr, msg)));
        }
    }
}

/// The layout is the documented one, worked by hand for a roll call of node 5.
#[test]
fn a_roll_call_frame_is_laid_out_as_documented() {
    let mut buf = [0u8; 16];
    let n = encode(5, &Msg::RollCall, &mut buf).unwrap();
    // sync, address 5, body length 1, body = variant 0, CRC-32 of [5, 1, 0].
    assert_eq!(n, 8);
    assert_eq!(&buf[..4], &[SYNC, 5, 1, 0]);
    assert_eq!(&buf[4..8], &CRC32.checksum(&[5, 1, 0]).to_le_bytes());
}

#[test]
fn damaged_frames_are_typed_errors() {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(2, &Msg::Poll { ack: 9 }, &mut buf).unwrap();
    let f = &buf[..n];
    assert_eq!(decode(&f[..n - 1]), Err(BackupError::Truncated));
    assert_eq!(decode(&f[1..]), Err(BackupError::NoSync));
    for bit in 8..8 * n {
        let mut g = f.to_vec();
        g[bit / 8] ^= 1 << (bit % 8);
        assert!(decode(&g).is_err(), "bit {bit} flipped decoded");
    }
    assert_eq!(
        encode(0, &Msg::Idle, &mut buf),
        Err(BackupError::BadAddress { addr: 0 })
    );
    assert_eq!(
        encode(MAX_ADDR + 1, &Msg::Idle, &mut buf),
        Err(BackupError::BadAddress { addr: MAX_ADDR + 1 })
    );
    let big = [0u8; MAX_BODY];
    let scene = Msg::Scene {
        frame: 0,
        offset: 0,
        total: 0,
        crc: 0,
        data: &big,
    };
    assert_eq!(encode(1, &scene, &mut buf), Err(BackupError::TooLong));
    assert_eq!(
        encode(1, &Msg::Idle, &mut buf[..6]),
        Err(BackupError::TooLong)
    );
}

/// A reader fed a stream of garbage, frames, and a corrupted frame finds exactly the good
/// frames.
#[test]
fn the_reader_finds_frames_in_a_noisy_stream() {
    let mut stream = vec![0x00, 0x13, 0x7F, 0xFF];
    let mut frames = Vec::new();
    for (i, msg) in [Msg::RollCall, Msg::Ack, Msg::Poll { ack: 0x7E7E }]
        .iter()
        .enumerate()
    {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(i as u8 + 1, msg, &mut buf).unwrap();
        stream.extend_from_slice(&buf[..n]);
        frames.push((i as u8 + 1, *msg));
    }
    let mut r = FrameReader::new();
    let mut got = Vec::new();
    for b in stream {
        if let Some(n) = r.push(b) {
            if let Ok((a, m)) = decode(r.frame(n)) {
                got.push((a, format!("{m:?}")));
            }
        }
    }
    let want: Vec<_> = frames.iter().map(|(a, m)| (*a, format!("{m:?}"))).collect();
    assert_eq!(got, want);
}

/// rle_chunk over random-ish rows: chunks cover the row exactly and decode to it.
#[test]
fn rle_chunks_cover_a_row_and_decode_to_it() {
    let mut s = 0x1234_5678u32;
    for round in 0..200 {
        let n = 1 + (round * 7) % MAX_RUN;
        let mut rgb = vec![0u8; 3 * n];
        for p in rgb.chunks_exact_mut(3) {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            // A few colours, so runs of all lengths occur.
            let c = if s.is_multiple_of(3) {
                (s >> 8) as u8
            } else {
                9
            };
            p.copy_from_slice(&[c, c / 2, 1]);
        }
        let mut at = 0;
        let mut back = Vec::new();
        while at < n {
            let mut out = [0u8; PIXEL_DATA];
            let (px, bytes) = rle_chunk(&rgb[3 * at..], &mut out);
            assert!(px > 0 && bytes <= PIXEL_DATA);
            let mut dec = vec![0u8; 3 * px];
            rle_decode(&out[..bytes], &mut dec).unwrap();
            back.extend_from_slice(&dec);
            at += px;
        }
        assert_eq!(back, rgb);
    }
}

fn scene_frames(scene: &[u8], frame: u16, addr: u8) -> Vec<Vec<u8>> {
    let crc = CRC32.checksum(scene);
    scene
        .chunks(SCENE_DATA)
        .enumerate()
        .map(|(i, data)| {
            let mut buf = [0u8; MAX_FRAME];
            let msg = Msg::Scene {
                frame,
                offset: (i * SCENE_DATA) as u32,
                total: scene.len() as u32,
                crc,
                data,
            };
            let n = encode(addr, &msg, &mut buf).unwrap();
            buf[..n].to_vec()
        })
        .collect()
}

fn ask(node: &mut BackupNode<'_>, addr: u8, msg: Msg<'_>) -> Option<(u8, Vec<u8>)> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(addr, &msg, &mut buf).unwrap();
    let mut reply = [0u8; MAX_FRAME];
    let r = node.handle(&buf[..n], &mut reply).unwrap()?;
    let (a, _) = decode(&reply[..r]).unwrap();
    Some((a, reply[..r].to_vec()))
}

/// A broadcast scene with a lost chunk: the node reports where it stopped, takes the rest
/// addressed, checks the CRC; a second scene starts over.
#[test]
fn a_node_assembles_a_scene_and_resumes_after_a_gap() {
    let scene: Vec<u8> = (0..1000u32).map(|i| (i * 31 % 251) as u8).collect();
    let mut bank = [0u8; 2048];
    let mut node = BackupNode::new(4, &mut bank);
    let bcast = scene_frames(&scene, 1, BROADCAST);
    let mut reply = [0u8; MAX_FRAME];
    for (i, f) in bcast.iter().enumerate() {
        if i != 2 {
            assert_eq!(node.handle(f, &mut reply), Ok(None));
        }
    }
    let h = node.health();
    assert_eq!(
        (h.frame, h.scene_bytes, h.scene_ok),
        (1, 2 * SCENE_DATA as u32, false)
    );
    assert!(node.scene.ready().is_none());
    for f in &scene_frames(&scene, 1, 4)[2..] {
        let n = node.handle(f, &mut reply).unwrap().unwrap();
        assert_eq!(decode(&reply[..n]), Ok((4, Msg::Ack)));
    }
    assert_eq!(node.scene.ready(), Some((1, &scene[..])));
    // Another node's frames are not answered.
    assert_eq!(ask(&mut node, 5, Msg::RollCall), None);
    // Too big for the bank: refused and counted.
    let big = vec![0u8; 4096];
    let f = &scene_frames(&big, 2, 4)[0];
    assert_eq!(node.handle(f, &mut reply), Err(BackupError::TooLong));
    assert_eq!(node.health().errors, 1);
}

/// Work, then polls: chunks carry the row, a poll that does not acknowledge gets the same
/// chunk again, the last chunk is marked done and counted once acknowledged.
#[test]
fn a_node_returns_pixels_in_acknowledged_chunks() {
    let mut bank = [0u8; 16];
    let mut node = BackupNode::new(2, &mut bank);
    assert!(ask(&mut node, 2, Msg::Work { job: job(11) }).is_some());
    let j = node.take_job().unwrap();
    assert_eq!(j, job(11));
    // 300 pixels, all different: 300 quadruples = 6 chunks of 56 (the last 20).
    let rgb: Vec<u8> = (0..300u32)
        .flat_map(|i| [i as u8, (i >> 8) as u8, 7])
        .collect();
    node.push_pixels(&j, 1, 424, &rgb, true).unwrap();
    assert!(!node.outbox_free());
    assert!(node.push_pixels(&j, 1, 424, &rgb, true).is_err());
    let mut ack = 0u16;
    let mut back = Vec::new();
    let mut chunks = 0;
    loop {
        let (_, f) = ask(&mut node, 2, Msg::Poll { ack }).unwrap();
        let (_, m) = decode(&f).unwrap();
        let Msg::Pixels {
            seq,
            x,
            len,
            done,
            rle,
            ..
        } = m
        else {
            assert_eq!(m, Msg::Idle);
            break;
        };
        assert_eq!((seq, x as usize), (ack, 424 + back.len() / 3));
        // The first poll of each chunk is "lost": asking again gives the same chunk.
        let (_, again) = ask(&mut node, 2, Msg::Poll { ack }).unwrap();
        assert_eq!(again, f);
        let mut dec = vec![0u8; 3 * len as usize];
        rle_decode(rle, &mut dec).unwrap();
        back.extend_from_slice(&dec);
        chunks += 1;
        assert_eq!(done, back.len() == rgb.len());
        ack = ack.wrapping_add(1);
    }
    assert_eq!(chunks, 6);
    assert_eq!(back, rgb);
    assert!(node.outbox_free());
    assert_eq!(node.health().jobs_done, 1);
}

/// Roll call over 4 addresses where node 3 is silent and node 4 answers as node 1.
#[test]
fn roll_call_finds_the_silent_nodes() {
    let mut banks = [[0u8; 8]; 4];
    let mut nodes: Vec<BackupNode<'_>> = banks
        .iter_mut()
        .enumerate()
        .map(|(i, b)| BackupNode::new(i as u8 + 1, b))
        .collect();
    let mut rc = RollCall::new(4);
    let mut req = [0u8; MAX_FRAME];
    let mut reply = [0u8; MAX_FRAME];
    while let RollCallStep::Ask(a) = rc.step() {
        let n = rc.request(&mut req).unwrap();
        let r = match a {
            3 => None,
            4 => {
                let m = encode(1, &Msg::Health(Health::default()), &mut reply).unwrap();
                Some(m)
            }
            _ => nodes[a as usize - 1].handle(&req[..n], &mut reply).unwrap(),
        };
        let res = rc.answered(r.map(|m| &reply[..m]));
        assert_eq!(res.is_err(), a == 4);
    }
    assert_eq!(rc.absent().collect::<Vec<_>>(), vec![3, 4]);
    assert_eq!(rc.health(1).map(|h| h.firmware), Some(FIRMWARE_ID));
    assert_eq!(rc.health(0), None);
    assert_eq!(rc.step(), RollCallStep::Done);
}

/// A fake line: nodes 1 and 2 on it (node 2 silent), every frame the RC sends answered at
/// once by the node's serve loop.
struct FakeLine<'a, 'b> {
    node: &'a mut BackupNode<'b>,
    pending: Vec<u8>,
    sent: usize,
}

impl LinePort for FakeLine<'_, '_> {
    async fn send(&mut self, frame: &[u8]) -> Result<(), LineError> {
        self.sent += 1;
        let mut reply = [0u8; MAX_FRAME];
        if let Ok(Some(n)) = self.node.handle(frame, &mut reply) {
            self.pending.extend_from_slice(&reply[..n]);
        }
        Ok(())
    }
    async fn receive(&mut self, buf: &mut [u8], _: Option<u32>) -> Result<usize, LineError> {
        let n = self.pending.len().min(buf.len());
        buf[..n].copy_from_slice(&self.pending[..n]);
        self.pending.drain(..n);
        Ok(n)
    }
}

#[test]
fn the_rc_calls_the_roll_over_a_port() {
    let mut bank = [0u8; 4];
    let mut node = BackupNode::new(1, &mut bank);
    let mut line = FakeLine {
        node: &mut node,
        pending: Vec::new(),
        sent: 0,
    };
    let rc = embassy_futures::block_on(call_roll(&mut line, 2, 1000)).unwrap();
    assert_eq!(line.sent, 2);
    assert_eq!(rc.absent().collect::<Vec<_>>(), vec![2]);
    assert_eq!(rc.health(1).unwrap().firmware, FIRMWARE_ID);
}

/// The node's serve loop answers a burst holding a roll call and a poll, and ignores a
/// frame for another node.
#[test]
fn the_node_serves_a_burst_of_frames() {
    struct Burst(Vec<u8>, Vec<Vec<u8>>);
    impl LinePort for Burst {
        async fn send(&mut self, frame: &[u8]) -> Result<(), LineError> {
            self.1.push(frame.to_vec());
            Ok(())
        }
        async fn receive(&mut self, buf: &mut [u8], _: Option<u32>) -> Result<usize, LineError> {
            let n = self.0.len().min(buf.len());
            buf[..n].copy_from_slice(&self.0[..n]);
            Ok(n)
        }
    }
    let mut burst = Vec::new();
    for (a, m) in [
        (3, Msg::RollCall),
        (4, Msg::RollCall),
        (3, Msg::Poll { ack: 0 }),
    ] {
        let mut b = [0u8; MAX_FRAME];
        let n = encode(a, &m, &mut b).unwrap();
        burst.extend_from_slice(&b[..n]);
    }
    let mut port = Burst(burst, Vec::new());
    let mut bank = [0u8; 4];
    let mut node = BackupNode::new(3, &mut bank);
    let mut reader = FrameReader::new();
    let handled = embassy_futures::block_on(serve(&mut port, &mut node, &mut reader)).unwrap();
    assert_eq!(handled, 3);
    let got: Vec<_> = port.1.iter().map(|f| decode(f).unwrap()).collect();
    assert_eq!(got.len(), 2);
    assert!(matches!(got[0], (3, Msg::Health(_))));
    assert_eq!(got[1], (3, Msg::Idle));
}

/// An RC line that answers every exchange with the next of `answers` (`None`: silence) and
/// keeps the RC's requests.
struct Scripted {
    answers: Vec<Option<Vec<u8>>>,
    requests: Vec<(u8, Vec<u8>)>,
}

impl RcLine for Scripted {
    type Error = BackupError;
    async fn exchange(
        &mut self,
        to: u8,
        buf: &mut [u8; MAX_FRAME],
        len: usize,
    ) -> Result<Option<usize>, BackupError> {
        self.requests.push((to, buf[..len].to_vec()));
        let Some(a) = self.answers.remove(0) else {
            return Ok(None);
        };
        buf[..a.len()].copy_from_slice(&a);
        Ok(Some(a.len()))
    }
}

/// Job 9 for node 2; records every run handed in.
#[derive(Default)]
struct Recorder {
    runs: Vec<(u16, u16, Vec<u8>, bool)>,
    lost: Vec<u8>,
}

impl BackupWork for Recorder {
    fn assign(&mut self, _: u8) -> Option<Job> {
        Some(job(9))
    }
    fn missing_scene(&self, _: u8) -> Option<u16> {
        None
    }
    fn scene(&self, _: u16) -> Option<&[u8]> {
        None
    }
    fn scene_ready(&mut self, _: u8, _: u16) {}
    fn pixels(&mut self, _: u8, _: u32, y: u16, x: u16, rgb: &[u8], done: bool) -> bool {
        self.runs.push((y, x, rgb.to_vec(), done));
        true
    }
    fn lost(&mut self, addr: u8) {
        self.lost.push(addr);
    }
}

fn reply(addr: u8, msg: Msg<'_>) -> Option<Vec<u8>> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(addr, &msg, &mut buf).unwrap();
    Some(buf[..n].to_vec())
}

fn pixels(seq: u16, len: u16, rle: &[u8]) -> Option<Vec<u8>> {
    let msg = Msg::Pixels {
        seq,
        job: 9,
        frame: 3,
        y: 4,
        x: 5,
        len,
        done: true,
        rle,
    };
    reply(2, msg)
}

/// The RC's turns by hand: the job until acknowledged, then polls; a chunk of 4 pixels
/// (runs of 3 and 1) expanded through a 2-pixel buffer arrives as two runs at x = 5 and 7,
/// `done` on the second only; a chunk whose runs do not add up to its length is refused and
/// the next poll asks for the same sequence number; eight silent turns give the node up.
#[test]
fn the_rc_hands_out_work_and_expands_pixel_chunks_in_parts() {
    let rle = [2, 1, 2, 3, 0, 9, 9, 9];
    let mut line = Scripted {
        answers: vec![
            None,                // Work: no answer
            reply(2, Msg::Ack),  // Work again: taken
            reply(2, Msg::Idle), // Poll ack 0
            pixels(0, 5, &rle),  // runs add up to 4, not 5: refused
            pixels(0, 4, &rle),  // taken
        ],
        requests: Vec::new(),
    };
    let mut rc = BackupRc::<2>::new();
    assert_eq!(rc.serve(2), Some(0));
    let mut work = Recorder::default();
    let mut rgb = [0u8; 6];
    let mut turn =
        || embassy_futures::block_on(rc.turn(0, &mut line, &mut work, &mut rgb)).unwrap();
    assert_eq!(
        turn(),
        Turn::Work {
            job: job(9),
            taken: false
        }
    );
    assert_eq!(
        turn(),
        Turn::Work {
            job: job(9),
            taken: true
        }
    );
    assert_eq!(turn(), Turn::Idle);
    assert_eq!(turn(), Turn::Refused);
    assert_eq!(
        turn(),
        Turn::Pixels {
            len: 4,
            rle: 8,
            done: true
        }
    );
    let polls: Vec<Msg<'_>> = line.requests[2..]
        .iter()
        .map(|r| decode(&r.1).unwrap().1)
        .collect();
    assert_eq!(
        polls,
        [
            Msg::Poll { ack: 0 },
            Msg::Poll { ack: 0 },
            Msg::Poll { ack: 0 }
        ]
    );
    assert_eq!(
        work.runs,
        vec![
            (4, 5, vec![1, 2, 3, 1, 2, 3], false),
            (4, 7, vec![1, 2, 3, 9, 9, 9], true)
        ]
    );
    assert_eq!((rc.counters.pixels, rc.counters.jobs), (4, 1));
    // Silence from now on: the next poll asks for chunk 1; the eighth silent turn gives up.
    line.answers = vec![None; 8];
    let turns: Vec<Turn> = (0..8)
        .map(|_| embassy_futures::block_on(rc.turn(0, &mut line, &mut work, &mut rgb)).unwrap())
        .collect();
    assert_eq!(turns[..7], [Turn::Silent; 7]);
    assert_eq!(turns[7], Turn::Lost);
    assert_eq!(work.lost, vec![2]);
    assert_eq!(rc.addrs().count(), 0);
    let (_, last) = decode(&line.requests.last().unwrap().1).unwrap();
    assert_eq!(last, Msg::Poll { ack: 1 });
}

/// A node without a bank (the firmware's SPI path holds it) asks for one when the RC sends
/// work or a scene; a lent bank takes the scene; taken back, the scene's key stays (its
/// bytes are out: `ready` is `None`, chunks are refused) until it is lent again.
#[test]
fn a_node_borrows_a_bank_for_the_line_and_keeps_the_scene_across_loans() {
    let scene: Vec<u8> = (0..500u32).map(|i| (i * 7) as u8).collect();
    let mut node = BackupNode::new(2, &mut []);
    assert!(!node.take_bank_request());
    assert_eq!(
        ask(&mut node, 2, Msg::Work { job: job(1) }),
        Some((2, {
            let mut b = [0u8; MAX_FRAME];
            let n = encode(2, &Msg::Ack, &mut b).unwrap();
            b[..n].to_vec()
        }))
    );
    assert!(node.take_bank_request());
    assert!(!node.take_bank_request(), "asked once");
    let mut reply = [0u8; MAX_FRAME];
    let frames = scene_frames(&scene, 4, 2);
    assert_eq!(
        node.handle(&frames[0], &mut reply),
        Err(BackupError::TooLong)
    );
    assert!(node.take_bank_request());
    let mut bank = vec![0u8; 600];
    node.lend_bank(&mut bank);
    for f in &frames {
        assert!(node.handle(f, &mut reply).unwrap().is_some());
    }
    assert_eq!(node.scene.ready(), Some((4, &scene[..])));
    let key = (4, CRC32.checksum(&scene));
    assert_eq!(node.scene.key(), Some(key));
    let out = node.take_bank();
    assert_eq!(&out[..500], &scene[..]);
    assert_eq!((node.scene.ready(), node.scene.key()), (None, Some(key)));
    assert_eq!(node.health().scene_bytes, 500);
    node.lend_bank(out);
    assert_eq!(node.scene.ready(), Some((4, &scene[..])));
}
