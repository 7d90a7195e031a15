//! What the RC's CPU spends per bus transfer, in instructions on the Cortex-M4F: encoding and
//! decoding wire frames (postcard + CRC-32), the CRC alone, run-length decoding, copying.
//! Each line is one operation at two sizes, so the per-byte slope and the fixed part can be
//! read off; host-sim's RC cost model (`host-sim/src/sim/cluster/rccost.rs`) is fitted to them.
//!
//! Shared by `main.rs` (scripts/qemu-bench prints them as `WIRE` lines) and usable alone.

use core::hint::black_box;
use links_core::wire::{self, Down, Job, Region, SceneState, Up, MAX_MESSAGE, MAX_RUN};

/// A counter of instructions (the benchmark's SysTick-based one).
pub trait Meter {
    /// Instructions `f` executed, net of the counter's own cost.
    fn instr(&mut self, f: &mut dyn FnMut()) -> u64;
    /// Print one result line.
    fn line(&mut self, name: &str, bytes: usize, extra: usize, instr: u64);
}

const REPS: u64 = 16;

fn per(m: &mut impl Meter, f: &mut dyn FnMut()) -> u64 {
    let t = m.instr(&mut || {
        for _ in 0..REPS {
            f()
        }
    });
    t / REPS
}

/// Run every measurement; returns false if a round trip failed.
pub fn run(m: &mut impl Meter) -> bool {
    let mut ok = true;
    let mut buf = [0u8; MAX_MESSAGE];
    let mut data = [0u8; 3 * MAX_RUN];
    for (i, d) in data.iter_mut().enumerate() {
        *d = (i * 7 + i / 5) as u8;
    }

    // CRC-32 alone (the scene's whole-image CRC is this per byte).
    for n in [64usize, 1024] {
        let t = per(m, &mut || {
            black_box(wire::CRC32.checksum(black_box(&data[..n])));
        });
        m.line("crc32", n, 0, t);
    }

    // A scene chunk: encode (RC, broadcast) and decode (node), empty and 1 KB of data.
    for n in [0usize, 1024] {
        let msg = Down::Scene {
            frame: 1,
            offset: 4096,
            total: 116_720,
            crc: 0x1234_5678,
            data: &data[..n],
        };
        let mut len = 0;
        let t = per(m, &mut || {
            len = wire::encode(0, 0, black_box(&msg), &mut buf).unwrap_or(0);
        });
        m.line("encode_scene", len, n, t);
        let t = per(m, &mut || {
            ok &= black_box(wire::decode::<Down>(black_box(&buf[..len]))).is_ok();
        });
        m.line("decode_scene", len, n, t);
    }

    // The RC's exchange reply: a job list.
    let job = Job {
        id: 1234,
        frame: 0,
        region: Region::Span {
            start: 100_000,
            len: 1500,
        },
    };
    let work = Down::Work {
        jobs: [Some(job), Some(Job { id: 1235, ..job })],
    };
    let mut len = 0;
    let t = per(m, &mut || {
        len = wire::encode(300, 301, black_box(&work), &mut buf).unwrap_or(0);
    });
    m.line("encode_work", len, 0, t);

    // NC frames as the RC takes them: a status, raw pixels, RLE pixels (+ expansion).
    let status = Up::Status {
        scene: SceneState::Ready { frame: 1 },
    };
    let n = wire::encode(300, 3, &status, &mut buf).unwrap_or(0);
    let t = per(m, &mut || {
        ok &= black_box(wire::decode::<Up>(black_box(&buf[..n]))).is_ok();
    });
    m.line("decode_status", n, 0, t);
    for px in [128usize, 512] {
        let msg = Up::Pixels {
            job: 1234,
            frame: 0,
            y: 200,
            x: 0,
            rgb: &data[..3 * px],
            done: false,
        };
        let n = wire::encode(300, 3, &msg, &mut buf).unwrap_or(0);
        let t = per(m, &mut || {
            ok &= black_box(wire::decode::<Up>(black_box(&buf[..n]))).is_ok();
        });
        m.line("decode_pixels", n, px, t);
    }
    // RLE: 512 pixels in `quads` runs (flat background: few; detailed shading: many).
    let mut coded = [0u8; 4 * MAX_RUN];
    let mut out = [0u8; 3 * MAX_RUN];
    for quads in [4usize, 128] {
        let each = MAX_RUN / quads;
        for q in 0..quads {
            coded[4 * q] = (each - 1) as u8;
            coded[4 * q + 1..4 * q + 4].copy_from_slice(&[q as u8, 2, 3]);
        }
        let msg = Up::PixelsRle {
            job: 1234,
            frame: 0,
            y: 200,
            x: 0,
            len: MAX_RUN as u16,
            data: &coded[..4 * quads],
            done: false,
        };
        let n = wire::encode(300, 3, &msg, &mut buf).unwrap_or(0);
        let t = per(m, &mut || {
            ok &= black_box(wire::decode::<Up>(black_box(&buf[..n]))).is_ok();
        });
        m.line("decode_rle_frame", n, MAX_RUN, t);
        let t = per(m, &mut || {
            ok &= wire::rle_decode(black_box(&coded[..4 * quads]), &mut out).is_ok();
        });
        m.line("rle_expand", 4 * quads, MAX_RUN, t);
    }

    // Delta coding: 512 pixels of a shading gradient (one operation a pixel, one or two
    // bytes each) and of a flat run (a literal and 8 run bytes).
    for gradient in [true, false] {
        let mut rgb = [0u8; 3 * MAX_RUN];
        for (i, p) in rgb.chunks_exact_mut(3).enumerate() {
            let v = if gradient { i } else { 0 };
            p.copy_from_slice(&[(40 + v / 2) as u8, (60 + v) as u8, (v * 9 / 8) as u8]);
        }
        let n = wire::delta_encode(&rgb, &mut coded).unwrap_or(0);
        let t = per(m, &mut || {
            ok &= wire::delta_decode(black_box(&coded[..n]), &mut out).is_ok();
        });
        m.line("delta_expand", n, MAX_RUN, t);
    }

    // Copying pixels into a frame memory (the RC as the pixel sink, no snooping collector).
    for n in [384usize, 1536] {
        let t = per(m, &mut || {
            out[..n].copy_from_slice(black_box(&data[..n]));
            black_box(&out);
        });
        m.line("copy", n, 0, t);
    }
    ok
}
