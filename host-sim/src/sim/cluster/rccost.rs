//! The RC's CPU in virtual time: what composing, checking and decoding wire frames costs.
//!
//! The RC (an STM32F407, like the nodes) reports every piece of work to its clock
//! ([`links_core::root::RcWork`]); [`RcClock`] turns it into busy time of the one RC CPU
//! shared by all bus tasks (work queues behind work already running), so a bus waits for the
//! RC exactly when the RC's work for its next transfer is not done yet.
//!
//! Constants: instructions on the Cortex-M4F measured under QEMU with `-icount`
//! (`tests/qemu-bench/src/wire_bench.rs`, printed as `WIRE` lines by `scripts/qemu-bench`;
//! release build, fat LTO, as the firmware), each operation at two sizes so the per-byte
//! slope and the fixed part separate (fitted to a standalone build of that file; the full
//! benchmark binary agrees within 1.5%, the RLE per-quadruple cost within 7%). `per_transfer` (the bookkeeping of `run_bus`,
//! `reply` and `take` apart from the wire work: choosing the node, the job table, the
//! scheduler, the acknowledgement, arming the DMA) is **not measured**: 500 instructions is
//! an estimate (docs/cluster.md shows what it changes). Cycles per instruction 1.3 and
//! 168 MHz as for the nodes (`crate::cost`; the RC is the same STM32F407).

use super::exec::{Delay, Ps, SharedClock};
use super::timeline::SharedTimeline;
use links_core::board::{BoardProfile, Core};
use links_core::root::{RcWork, RootClock};
use links_core::wire::{self, Up};
use std::cell::Cell;
use std::rc::Rc;

/// Instructions per piece of RC work, and the RC's clock.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RcCost {
    /// RC core clock (Hz).
    pub clock_hz: f64,
    pub cycles_per_instruction: f64,
    /// Per transfer: choosing it, the job table / scheduler / acknowledgement bookkeeping
    /// of `reply` and `take`, arming the DMA.
    pub per_transfer: f64,
    /// `wire::encode`: fixed part and per byte of the frame (postcard + CRC-32 per byte).
    pub encode_fixed: f64,
    pub encode_per_byte: f64,
    /// `wire::decode` (CRC check + postcard, payloads borrowed): fixed and per byte.
    pub decode_fixed: f64,
    pub decode_per_byte: f64,
    /// `wire::rle_decode`: per `(count, r, g, b)` quadruple and per pixel written.
    pub rle_per_quad: f64,
    pub rle_per_pixel: f64,
    /// `wire::delta_decode`: per coded byte and per pixel written.
    pub delta_per_byte: f64,
    pub delta_per_pixel: f64,
    /// CRC-32 of a scene image, per byte.
    pub crc_per_byte: f64,
    /// Copying pixels to the frame memory when the RC is the pixel sink, per byte.
    pub copy_per_byte: f64,
}

impl RcCost {
    /// The STM32F407 at 168 MHz, QEMU-measured instruction counts (see the module doc).
    pub const CORTEX_M4F: RcCost = RcCost {
        clock_hz: crate::cost::DEFAULT_CLOCK_HZ,
        cycles_per_instruction: 1.3,
        per_transfer: 500.0,
        encode_fixed: 450.0,
        encode_per_byte: 8.75,
        decode_fixed: 230.0,
        decode_per_byte: 5.25,
        rle_per_quad: 30.0,
        rle_per_pixel: 4.8,
        // The full benchmark binary's `delta_expand` lines (a shading gradient: 578 bytes,
        // 13,085 instructions; a flat run: 12 bytes, 2,257; both 512 pixels).
        delta_per_byte: 19.1,
        delta_per_pixel: 3.96,
        crc_per_byte: 5.25,
        copy_per_byte: 1.06,
    };

    /// An RC whose work takes no time (the bus never waits for it).
    pub const FREE: RcCost = RcCost {
        clock_hz: crate::cost::DEFAULT_CLOCK_HZ,
        cycles_per_instruction: 0.0,
        per_transfer: 0.0,
        encode_fixed: 0.0,
        encode_per_byte: 0.0,
        decode_fixed: 0.0,
        decode_per_byte: 0.0,
        rle_per_quad: 0.0,
        rle_per_pixel: 0.0,
        delta_per_byte: 0.0,
        delta_per_pixel: 0.0,
        crc_per_byte: 0.0,
        copy_per_byte: 0.0,
    };

    /// Instructions of one piece of work; `sink_pixels`: the RC copies pixels it accepts
    /// into the frame memory (no snooping collector).
    pub fn instructions(&self, work: &RcWork<'_>, sink_pixels: bool) -> f64 {
        match *work {
            RcWork::Encode { bytes } => {
                self.per_transfer + self.encode_fixed + self.encode_per_byte * bytes as f64
            }
            RcWork::Checksum { bytes } => self.crc_per_byte * bytes as f64,
            RcWork::Decode { frame } => {
                let mut i = self.decode_fixed + self.decode_per_byte * frame.len() as f64;
                let pixels = match wire::decode::<Up>(frame).map(|e| e.msg) {
                    Ok(Up::Pixels { rgb, .. }) => rgb.len() / 3,
                    Ok(Up::PixelsRle { len, data, .. }) => {
                        i += self.rle_per_quad * (data.len() / 4) as f64
                            + self.rle_per_pixel * len as f64;
                        len as usize
                    }
                    Ok(Up::PixelsDelta { len, data, .. }) => {
                        i += self.delta_per_byte * data.len() as f64
                            + self.delta_per_pixel * len as f64;
                        len as usize
                    }
                    _ => 0,
                };
                if sink_pixels {
                    i += self.copy_per_byte * (3 * pixels) as f64;
                }
                i
            }
        }
    }

    /// Picoseconds of one piece of work.
    pub fn duration_ps(&self, work: &RcWork<'_>, sink_pixels: bool) -> Ps {
        let cycles = self.instructions(work, sink_pixels) * self.cycles_per_instruction;
        (cycles * 1e12 / self.clock_hz).ceil() as Ps
    }
}

impl RcCost {
    /// The RC of `profile`: its core's instruction counts at its clock.
    pub fn for_board(profile: &BoardProfile) -> RcCost {
        let cost = match profile.core {
            // The RC's work is integer code (framing, CRCs, copies): the M3 runs the M4F's
            // Thumb-2 instructions, so the M4F's counts (an estimate until measured), at
            // the board's clock. The M0+'s Thumb-1 takes more instructions for the same
            // code (no wide immediates, fewer addressing modes): the M4F's counts are a
            // lower bound there, unmeasured.
            Core::CortexM4F | Core::CortexM3 | Core::CortexM0Plus => Self::CORTEX_M4F,
        };
        RcCost {
            clock_hz: profile.core_clock_hz as f64,
            ..cost
        }
    }
}

impl Default for RcCost {
    fn default() -> Self {
        Self::CORTEX_M4F
    }
}

/// The RC's clock in the simulator: virtual time for time-outs, and the RC CPU, one for all
/// bus tasks.
pub struct RcClock {
    pub clock: SharedClock,
    pub cost: RcCost,
    pub sink_pixels: bool,
    /// When the RC CPU finishes the work given it so far.
    pub cpu_free: Rc<Cell<Ps>>,
    /// Total RC CPU busy time.
    pub busy: Rc<Cell<Ps>>,
    /// Where the RC's work is logged, if a timeline is recorded.
    pub timeline: Option<SharedTimeline>,
}

impl RootClock for RcClock {
    fn now_us(&self) -> u64 {
        self.clock.borrow().now / 1_000_000
    }

    async fn at_us(&self, t: u64) {
        Delay::new(&self.clock, t.saturating_mul(1_000_000)).await
    }

    async fn worked(&self, work: RcWork<'_>) {
        let d = self.cost.duration_ps(&work, self.sink_pixels);
        if d == 0 {
            return;
        }
        let now = self.clock.borrow().now;
        let end = now.max(self.cpu_free.get()) + d;
        self.cpu_free.set(end);
        self.busy.set(self.busy.get() + d);
        if let Some(log) = &self.timeline {
            log.borrow_mut().rc_work(end - d, end);
        }
        Delay::new(&self.clock, end).await;
    }
}

/// Whose relay-link work a [`LinkCpu`] charges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkRole {
    /// A relay on its own bus (`links_core::relay::run_relay`).
    Relay,
    /// The root on its link to the relays (`links_core::relay::RelayedBus`).
    Root,
}

/// The CPU work the firmware's relay code does around each transfer, which no
/// [`RootClock`] reports (the relay code has no clock; the root's `run_bus` reports its own
/// composing and decoding through [`RcClock`]), charged with [`RcCost`]'s constants on an
/// RC's CPU (`cpu_free`, shared with that RC's [`RcClock`] at the root) when the emulated
/// link starts or ends a transfer ([`super::spi_bus::FirmwareBus`]):
///
/// - every transfer: `per_transfer` (the bookkeeping estimate: choosing, arming the DMA);
/// - a relay: the parent's frame copied out of its RX bank and into the bus's TX bank
///   (2 copies of the request or broadcast), the node's frame copied out of the RX bank,
///   into the batch and into the parent's TX bank (3 copies), and the `wire::decode` of
///   every broadcast it forwards (it checks for `Stop`: CRC and postcard, `decode_*`);
/// - the root: the request or broadcast copied into the link's TX bank (1 copy), what a
///   relay sent copied out of the RX bank, into the answer and out to `run_bus` (3 copies).
///
/// Not charged: parsing batch and record headers, scanning the `waiting` bitmaps.
#[derive(Clone)]
pub struct LinkCpu {
    pub clock: SharedClock,
    pub cost: RcCost,
    pub role: LinkRole,
    /// When this RC's CPU finishes the work given it so far.
    pub cpu_free: Rc<Cell<Ps>>,
    /// Its total busy time.
    pub busy: Rc<Cell<Ps>>,
}

impl LinkCpu {
    /// Instructions before a transfer of `len` bytes starts.
    pub fn before_instructions(&self, len: usize) -> f64 {
        let copies = match self.role {
            LinkRole::Relay => 2.0,
            LinkRole::Root => 1.0,
        };
        self.cost.per_transfer + copies * self.cost.copy_per_byte * len as f64
    }

    /// Instructions after a transfer ends: a broadcast of `len` bytes, or an exchange that
    /// brought `got` bytes.
    pub fn after_instructions(&self, broadcast: bool, len: usize, got: usize) -> f64 {
        match (self.role, broadcast) {
            (LinkRole::Relay, true) => {
                self.cost.decode_fixed + self.cost.decode_per_byte * len as f64
            }
            (_, true) => 0.0,
            (_, false) => 3.0 * self.cost.copy_per_byte * got as f64,
        }
    }

    /// Charge `instructions` to the CPU from now (behind its earlier work); when it is done.
    pub fn charge(&self, instructions: f64) -> Ps {
        let cycles = instructions * self.cost.cycles_per_instruction;
        let d = (cycles * 1e12 / self.cost.clock_hz).ceil() as Ps;
        let now = self.clock.borrow().now;
        let start = now.max(self.cpu_free.get());
        if d == 0 {
            return start;
        }
        self.cpu_free.set(start + d);
        self.busy.set(self.busy.get() + d);
        start + d
    }
}
