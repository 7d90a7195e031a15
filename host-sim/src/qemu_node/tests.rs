use super::bus::LockstepBus;
use super::*;
use links_core::dm::{compile, CompileOptions};
use links_core::link::{LinkError, RootBus, Transfer};
use links_core::node::Kernels;
use links_core::wire::{self, Down, Up, MAX_MESSAGE};
use std::future::Future;
use std::task::{Context, Poll, Waker};

fn image(scene: &str, w: u32, h: u32) -> Vec<u8> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(scene);
    let desc = crate::scene_file::load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
    let opts = CompileOptions {
        width: Some(w),
        height: Some(h),
        ..Default::default()
    };
    compile(&desc, &opts).expect("compiles").bytes
}

/// A node that changes what it posts: `f` may rewrite the `n`-th posted frame.
struct Tamper<F> {
    inner: LocalNode,
    n: usize,
    seen: usize,
    f: F,
}

impl<F: FnMut(&mut Vec<u8>) -> bool> NodeSide for Tamper<F> {
    fn settle(&mut self) -> Result<Settled, String> {
        let mut s = self.inner.settle()?;
        if let Settled::Waiting { posted } = &mut s {
            for p in posted {
                if self.seen >= self.n && (self.f)(p) {
                    self.n = usize::MAX;
                }
                self.seen += 1;
            }
        }
        Ok(s)
    }
    fn deliver(&mut self, exchanged: bool, frame: &[u8]) -> Result<(), String> {
        self.inner.deliver(exchanged, frame)
    }
}

#[test]
fn lock_step_rc_and_host_node_give_the_simulators_frame() {
    let img = image("photo1.ron", 24, 20);
    let want = simulated_frame(&img).unwrap();
    let a = run_rc(&img, LocalNode::new()).unwrap();
    check_outcome(&a, &want, 0).unwrap();
    assert_eq!(a.root.pixels, 24 * 20);
    // The scene went out chunk by chunk, each once, and the last broadcast is the Stop.
    let bcasts: Vec<Down> = a
        .transcript
        .iter()
        .filter_map(|e| match e {
            Event::Down {
                exchanged: false,
                frame,
            } => Some(wire::decode::<Down>(frame).unwrap().msg),
            _ => None,
        })
        .collect();
    let chunks = bcasts
        .iter()
        .filter(|d| matches!(d, Down::Scene { .. }))
        .count();
    assert_eq!(chunks, img.len().div_ceil(wire::SCENE_CHUNK));
    assert_eq!(bcasts.last(), Some(&Down::Stop));
    // Deterministic: a second run transfers the same bytes.
    let b = run_rc(&img, LocalNode::new()).unwrap();
    compare_transcripts(&b, &a).unwrap();
}

#[test]
fn lock_step_rc_single_and_double_buffered_assemble_the_same_frame() {
    let img = image("photo1.ron", 24, 20);
    let want = simulated_frame(&img).unwrap();
    let single = run_rc_buffered(&img, LocalNode::new(), false).unwrap();
    let double = run_rc_buffered(&img, LocalNode::new(), true).unwrap();
    check_outcome(&single, &want, 0).unwrap();
    check_outcome(&double, &want, 0).unwrap();
    assert_eq!(single.frame, double.frame);
    assert_eq!(single.root.pixels, double.root.pixels);
}

#[test]
fn lock_step_bus_keeps_one_transfer_in_flight() {
    let mut bus = LockstepBus::new(LocalNode::new());
    let mut rx = [0u8; MAX_MESSAGE];
    fn poll<F: Future>(f: F) -> F::Output {
        let mut f = std::pin::pin!(f);
        match f.as_mut().poll(&mut Context::from_waker(Waker::noop())) {
            Poll::Ready(r) => r,
            Poll::Pending => panic!("lock-step transfers never wait"),
        }
    }
    // Nothing in flight: finish fails instead of waiting forever.
    assert_eq!(poll(bus.finish(&mut rx)), Err(LinkError::Aborted));
    let n = wire::encode(0, 0, &Down::Stop, bus.tx_bank()).unwrap();
    let first = bus.idle;
    bus.start(Transfer::Broadcast, n).unwrap();
    assert_ne!(bus.idle, first, "the RC composes into the other bank");
    assert_eq!(bus.start(Transfer::Broadcast, n), Err(LinkError::Busy));
    assert_eq!(poll(bus.finish(&mut rx)), Ok(0));
    // Past the bank, and nodes not on the bus, are errors.
    assert!(matches!(
        bus.start(Transfer::Broadcast, MAX_MESSAGE + 1),
        Err(LinkError::TooLong { .. })
    ));
    assert_eq!(
        bus.start(Transfer::Exchange(1), n),
        Err(LinkError::NoSuchNode { node: 1 })
    );
}

/// Re-encode a pixel frame with one byte of its colours changed (a valid frame: only the
/// pixel comparison can catch it).
fn flip_pixel(f: &mut Vec<u8>) -> bool {
    let Ok(env) = wire::decode::<Up>(f) else {
        return false;
    };
    let mut data = match env.msg {
        Up::Pixels { rgb, .. } => rgb.to_vec(),
        Up::PixelsRle { data, .. } => data.to_vec(),
        _ => return false,
    };
    // The RLE's colour bytes are 1..4 of each quadruple; raw runs, every byte.
    data[1] ^= 1;
    let msg = match env.msg {
        Up::Pixels {
            job,
            frame,
            y,
            x,
            done,
            ..
        } => Up::Pixels {
            job,
            frame,
            y,
            x,
            rgb: &data,
            done,
        },
        Up::PixelsRle {
            job,
            frame,
            y,
            x,
            len,
            done,
            ..
        } => Up::PixelsRle {
            job,
            frame,
            y,
            x,
            len,
            data: &data,
            done,
        },
        _ => unreachable!(),
    };
    let mut buf = vec![0u8; wire::MAX_MESSAGE];
    let n = wire::encode(env.seq, env.ack, &msg, &mut buf).unwrap();
    buf.truncate(n);
    *f = buf;
    true
}

#[test]
fn one_changed_pixel_byte_fails_the_check() {
    let img = image("photo1.ron", 24, 20);
    let want = simulated_frame(&img).unwrap();
    let good = run_rc(&img, LocalNode::new()).unwrap();
    let node = Tamper {
        inner: LocalNode::new(),
        n: 5,
        seen: 0,
        f: flip_pixel,
    };
    let bad = run_rc(&img, node).unwrap();
    let e = check_outcome(&bad, &want, 0).unwrap_err();
    assert!(e.contains("of 480 pixels differ"), "{e}");
    let e = compare_transcripts(&bad, &good).unwrap_err();
    assert!(e.contains("differs from the host node's"), "{e}");
    // And the RC's frame alone, one byte changed, fails too.
    let mut o = good.clone();
    o.frame[3 * 100 + 2] ^= 0x80;
    assert!(check_outcome(&o, &want, 0).is_err());
    check_outcome(&good, &want, 0).unwrap();
}

#[test]
fn a_frame_failing_its_crc_fails_the_check() {
    let img = image("photo1.ron", 24, 20);
    let want = simulated_frame(&img).unwrap();
    let node = Tamper {
        inner: LocalNode::new(),
        n: 3,
        seen: 0,
        f: |f: &mut Vec<u8>| {
            let last = f.len() - 1;
            f[last] ^= 4;
            true
        },
    };
    // The node sends the frame again (go-back-N), so the frame completes, but the bad
    // frame is counted and the check fails.
    let o = run_rc(&img, node).unwrap();
    assert_eq!(o.root.bad_messages, 1);
    let e = check_outcome(&o, &want, 0).unwrap_err();
    assert!(e.contains("1 failed CRC"), "{e}");
}

#[test]
fn damaged_rc_frames_are_counted_repaired_and_change_no_pixel() {
    let img = image("photo1.ron", 24, 20);
    let want = simulated_frame(&img).unwrap();
    let good = run_rc(&img, LocalNode::new()).unwrap();
    let downs = good
        .transcript
        .iter()
        .filter(|e| matches!(e, Event::Down { .. }))
        .count();
    // A scene chunk, and a frame late in the run (an exchange reply: the repair only
    // adds deliveries, so it exists).
    let node = Corrupt::new(LocalNode::new(), vec![3, downs - 10]);
    let o = run_rc(&img, node).unwrap();
    check_outcome(&o, &want, 2).unwrap();
    // The lost chunk came back as a repair; the count must match exactly.
    assert!(o.root.repairs >= 1, "{:?}", o.root);
    assert!(check_outcome(&o, &want, 1).is_err());
    assert!(check_outcome(&o, &want, 0).is_err());
}

#[test]
fn stream_node_speaks_the_record_protocol() {
    // A node that posts one frame, waits, then ends: as the firmware writes it.
    let mut up = Vec::new();
    for (k, body) in [
        (record::POST, &b"abc"[..]),
        (record::WAIT, &b""[..]),
        (
            record::END,
            &b"instr_total=120 instr_render=80\nresult=Ok(())\nreport=NodeReport { jobs: 1 }"[..],
        ),
    ] {
        up.push(k);
        up.extend_from_slice(&(body.len() as u32).to_le_bytes());
        up.extend_from_slice(body);
    }
    let mut node = StreamNode::new(&up[..], Vec::new());
    assert_eq!(
        node.settle().unwrap(),
        Settled::Waiting {
            posted: vec![b"abc".to_vec()]
        }
    );
    node.deliver(true, b"xy").unwrap();
    assert_eq!(node.down, [b'X', 2, 0, 0, 0, b'x', b'y']);
    let Settled::Ended(end) = node.settle().unwrap() else {
        panic!("not ended")
    };
    assert_eq!(end.counter("instr_render"), Some(80));
    assert_eq!(end.result, "Ok(())");
    assert_eq!(end.report, "NodeReport { jobs: 1 }");
    // A truncated stream is an error, not a hang or a panic.
    let mut cut = StreamNode::new(&up[..7], Vec::new());
    assert!(cut.settle().unwrap_err().contains("QEMU exited"));
}

/// The M3 run's path on the host: the DM's Q16.16 image, the node carrying the fixed-point
/// kernel only. Its frame is the simulator's fixed render (and `links render`'s single fixed
/// render), and it is not the f32 frame: the check would catch a node rendering in f32.
#[test]
fn fixed_point_node_gives_the_simulators_fixed_frame_not_the_f32_one() {
    let f32_img = image("photo1.ron", 24, 20);
    let fixed = crate::frame::fixed_image(&f32_img).unwrap();
    let want = simulated_frame(&fixed).unwrap();
    assert_eq!(
        check_single_render(&fixed, &want).unwrap(),
        crate::frame::Precision::Fixed
    );
    let q = run_rc(&fixed, LocalNode::with_kernels(Kernels::Fixed)).unwrap();
    check_outcome(&q, &want, 0).unwrap();
    assert_eq!(q.root.pixels, 24 * 20);

    let f32_frame = simulated_frame(&f32_img).unwrap();
    assert_eq!(
        check_single_render(&f32_img, &f32_frame).unwrap(),
        crate::frame::Precision::F32
    );
    let err = check_outcome(&q, &f32_frame, 0).unwrap_err();
    assert!(err.contains("pixels differ"), "{err}");
    // A node carrying both kernels renders the fixed image with the fixed one: the same
    // transfers byte for byte.
    let both = run_rc(&fixed, LocalNode::with_kernels(Kernels::Both)).unwrap();
    compare_transcripts(&both, &q).unwrap();
    // The single render check compares real pixels: the f32 frame is not the fixed image's.
    assert!(check_single_render(&fixed, &f32_frame).is_err());
}

/// A node without the image's kernel (the f32 firmware sent a Q16.16 image) stops with
/// `NoKernel`, and the check says so.
#[test]
fn a_node_without_the_images_kernel_fails_the_check() {
    let fixed = crate::frame::fixed_image(&image("photo1.ron", 8, 6)).unwrap();
    let want = simulated_frame(&fixed).unwrap();
    let err = match run_rc(&fixed, LocalNode::with_kernels(Kernels::F32)) {
        Ok(o) => check_outcome(&o, &want, 0).unwrap_err(),
        Err(e) => e,
    };
    assert!(err.contains("NoKernel"), "{err}");
}
