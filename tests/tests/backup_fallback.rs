//! The backup line's fallback end to end with links-core alone (no simulator): the RC's side
//! (`backup::serve_root`: `BackupRc` over `RootState`, through `PortLine` on a `LinePort`)
//! and `BackupNode`s rendering their jobs with `BackupRender` (the SPI path's tracer), over
//! an in-memory RS-485 line. Every node's SPI link is dead: the line is the only path. The
//! frame is bit-identical to the single-node render; a node that dies mid-frame has its job
//! reassigned; frames with flipped bits fail their CRC and are asked for again.

use links_core::backup::{
    self, serve_root, BackupNode, BackupRc, BackupRender, FrameReader, LineError, LinePort,
    PortLine, RootWork, ServeConfig, MAX_FRAME,
};
use links_core::node::Tracing;
use links_core::render::Rgb8;
use links_core::root::{PixelSink, RootClock, RootConfig, RootState};
use links_core::sched::Policy;
use links_tests::{bundled_image as image, host_reference as reference};
use std::cell::{Cell, RefCell};

/// Microseconds the test clock moves per frame on the line (a 262-byte frame at 1 Mbit/s is
/// ~2.6 ms; the exact figure does not matter here).
const FRAME_US: u64 = 500;
/// More exchanges than any run below needs (a stalled run fails instead of spinning).
const MAX_EXCHANGES: u64 = 400_000;

struct Node {
    proto: BackupNode<'static>,
    render: BackupRender,
    reader: FrameReader,
    tracer: Tracing<f32>,
    /// Exchanges after which it stops answering for good.
    dies_after: Option<u64>,
}

/// Deterministic xorshift for the bit flips.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

/// The RC's end of the in-memory line; the nodes hang on it. Every frame the RC sends
/// reaches every live node (each renders one piece of its job first: the nodes compute
/// while the RC talks); the addressed node's answer waits for `receive`.
struct MemLine<'c> {
    nodes: Vec<Node>,
    clock: &'c TestClock,
    answer: Vec<u8>,
    exchanges: u64,
    /// One frame in `flip_one_in` (each direction) gets one bit flipped (0: never).
    flip_one_in: u64,
    flips: u64,
    rng: Rng,
}

impl MemLine<'_> {
    fn maybe_flip(&mut self, frame: &mut [u8]) {
        if self.flip_one_in > 0 && self.rng.next().is_multiple_of(self.flip_one_in) {
            let bit = self.rng.next() as usize % (8 * frame.len());
            frame[bit / 8] ^= 1 << (bit % 8);
            self.flips += 1;
        }
    }
}

impl LinePort for MemLine<'_> {
    async fn send(&mut self, frame: &[u8]) -> Result<(), LineError> {
        self.exchanges += 1;
        if self.exchanges > MAX_EXCHANGES {
            return Err(LineError::Uart);
        }
        self.clock.now.set(self.clock.now.get() + FRAME_US);
        let mut sent = frame.to_vec();
        self.maybe_flip(&mut sent);
        self.answer.clear();
        // 20 pixels: a 48-pixel row goes in three pieces (20, 20, 8).
        let mut px = [Rgb8::default(); 20];
        let mut reply = [0u8; MAX_FRAME];
        let mut answers = Vec::new();
        for n in self.nodes.iter_mut() {
            if n.dies_after.is_some_and(|d| self.exchanges > d) {
                continue;
            }
            n.render
                .render_pending(&mut n.proto, &mut n.tracer, &mut px)
                .expect("a valid job renders");
            for &b in &sent {
                if let Some(len) = n.reader.push(b) {
                    if let Ok(Some(r)) = n.proto.handle(n.reader.frame(len), &mut reply) {
                        answers.push(reply[..r].to_vec());
                    }
                }
            }
        }
        assert!(answers.len() <= 1, "two nodes answered one frame");
        if let Some(mut a) = answers.pop() {
            self.maybe_flip(&mut a);
            self.clock.now.set(self.clock.now.get() + FRAME_US);
            self.answer = a;
        }
        Ok(())
    }

    async fn receive(&mut self, buf: &mut [u8], _: Option<u32>) -> Result<usize, LineError> {
        let n = self.answer.len().min(buf.len());
        buf[..n].copy_from_slice(&self.answer[..n]);
        self.answer.clear();
        Ok(n)
    }
}

struct TestClock {
    now: Cell<u64>,
}

impl RootClock for TestClock {
    fn now_us(&self) -> u64 {
        self.now.get()
    }
    async fn at_us(&self, t: u64) {
        self.now.set(self.now.get().max(t));
    }
}

/// The frame the RC assembles.
struct Frame {
    width: usize,
    rgb: Vec<u8>,
}

impl PixelSink for Frame {
    fn pixels(&mut self, _: u16, y: u16, x: u16, rgb: &[u8]) {
        let at = 3 * (y as usize * self.width + x as usize);
        self.rgb[at..at + rgb.len()].copy_from_slice(rgb);
    }
}

struct Run {
    frame: Vec<u8>,
    rc: BackupRc<4>,
    line_exchanges: u64,
    flips: u64,
    node_errors: Vec<u32>,
    reissued: u32,
}

/// Render `img` over the line alone with `nodes` nodes (`dies`: node index and the exchange
/// after which it goes silent).
fn run(img: &[u8], nodes: u8, dies: Option<(usize, u64)>, flip_one_in: u64) -> Run {
    let (w, h) = {
        let v = links_core::image::SceneView::new(img).unwrap();
        let c = v.camera::<f32>();
        (c.width as usize, c.height as usize)
    };
    let clock = TestClock {
        now: Cell::new(10_000),
    };
    let mut line = MemLine {
        nodes: (0..nodes)
            .map(|i| Node {
                proto: BackupNode::new(i + 1, Box::leak(vec![0u8; img.len()].into_boxed_slice())),
                render: BackupRender::new(),
                reader: FrameReader::new(),
                tracer: Tracing::new(),
                dies_after: dies.filter(|d| d.0 == i as usize).map(|d| d.1),
            })
            .collect(),
        clock: &clock,
        answer: Vec::new(),
        exchanges: 0,
        flip_one_in,
        flips: 0,
        rng: Rng(0x9E37_79B9_7F4A_7C15),
    };
    let cfg = RootConfig {
        policy: Policy::DECREASING,
        nodes: nodes as u16,
        frames: 1,
        // Short, so every node is a candidate for the line at once (silent on SPI).
        timeout_us: 1000,
        double_buffer: false,
    };
    let scenes = [img];
    let root = RefCell::new(RootState::new(cfg, &scenes[..]).unwrap());
    let sink = RefCell::new(Frame {
        width: w,
        rgb: vec![0; 3 * w * h],
    });
    let mut work = RootWork {
        root: &root,
        scenes: &scenes[..],
        sink: &sink,
    };
    let mut rc = BackupRc::<4>::new();
    let mut rgb = [0u8; 3 * 64];
    let serve = ServeConfig {
        nodes: nodes as u16,
        call_gap_us: 0,
        idle_us: 1000,
    };
    let mut port = PortLine {
        port: &mut line,
        timeout_us: 1000,
    };
    embassy_futures::block_on(serve_root(
        &mut rc, &mut port, &clock, &mut work, serve, &mut rgb,
    ))
    .unwrap_or_else(|e| panic!("{nodes} nodes: {e}"));
    assert!(root.borrow().finished());
    let reissued = root.borrow().report().reissued;
    Run {
        frame: sink.into_inner().rgb,
        line_exchanges: line.exchanges,
        flips: line.flips,
        node_errors: line.nodes.iter().map(|n| n.proto.health().errors).collect(),
        reissued,
        rc,
    }
}

#[test]
fn one_and_three_nodes_on_the_line_alone_render_the_single_node_frame() {
    let img = image("photo1.ron", 48, 45);
    let want = reference(&img);
    for nodes in [1u8, 3] {
        let r = run(&img, nodes, None, 0);
        println!(
            "{nodes} node(s): {} exchanges, {:?}",
            r.line_exchanges, r.rc.counters
        );
        assert_eq!(r.frame, want, "{nodes} node(s)");
        assert_eq!(r.rc.counters.pixels, 48 * 45);
        assert_eq!(r.rc.counters.lost, 0);
        assert_eq!(r.rc.addrs().count(), nodes as usize, "every node served");
        assert!(r.node_errors.iter().all(|&e| e == 0));
    }
}

#[test]
fn a_node_that_dies_mid_frame_has_its_job_reassigned() {
    let img = image("photo1.ron", 48, 45);
    let want = reference(&img);
    // Node 1 (address 2) goes silent after 250 exchanges: after it took work, well before
    // the frame ends (536 exchanges with three nodes).
    let r = run(&img, 3, Some((1, 250)), 0);
    println!("{:?}, reissued {}", r.rc.counters, r.reissued);
    assert_eq!(r.frame, want);
    assert_eq!(r.rc.counters.lost, 1);
    assert_eq!(r.rc.addrs().collect::<Vec<_>>(), vec![1, 3]);
    assert!(r.reissued >= 1, "its job went to another node");
    assert!(r.rc.counters.silent >= backup::rc::MAX_MISSES as u32);
}

#[test]
fn flipped_bits_fail_the_crc_and_the_frames_are_asked_for_again() {
    let img = image("photo1.ron", 48, 45);
    let want = reference(&img);
    let r = run(&img, 3, None, 25);
    println!(
        "{} flips in {} exchanges, node errors {:?}, {:?}",
        r.flips, r.line_exchanges, r.node_errors, r.rc.counters
    );
    assert_eq!(r.frame, want);
    assert!(r.flips > 20, "the line was noisy");
    // The nodes counted the RC's damaged frames; the RC, the damaged answers (as silence).
    assert!(r.node_errors.iter().sum::<u32>() > 0);
    assert!(r.rc.counters.silent > 0);
    assert_eq!(r.rc.counters.lost, 0);
    assert_eq!(r.rc.counters.pixels, 48 * 45);
}
