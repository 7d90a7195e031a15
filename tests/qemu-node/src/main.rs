//! The node computer's firmware logic on a real Cortex-M instruction set, under QEMU.
//!
//! This is a thin cortex-m-rt binary (embassy-stm32's `init` hangs on QEMU) around the very
//! `links_core::node::run_node` loop the simulator and the STM32 firmware run, with the
//! tracing kernels of its features ([`Renderer`], as nc-fw picks them: the f32 tracer on the
//! Cortex-M4F build, the Q16.16 tracer on the FPU-less Cortex-M3 build) and the hardware
//! clock ([`RealTime`]). Only the link differs: instead of SPI + DMA banks, [`SemihostLink`]
//! carries the IMSU's transfers through two FIFOs that QEMU's semihosting opens on the host
//! (`nc-down`: RC -> NC, `nc-up`: NC -> RC, relative to QEMU's working directory). On the
//! other end the host runs the real RC logic (`links_core::root::run_bus`,
//! `host-sim/src/qemu_node/`).
//!
//! Records on the FIFOs: a kind byte, a little-endian u32 length, then that many bytes.
//! - NC -> RC: `P` a frame posted to the TX bank (the ready line goes up); `W` the node waits
//!   in [`NodeLink::recv`]; `E` the node loop returned (a text report, the last record).
//! - RC -> NC: `X` the RC's half of an exchange (our posted frame went out); `B` a broadcast.
//!
//! The RC acts only while the node waits (`W`), so the order of events, and with it every
//! frame and every instruction count, depends on nothing but the two programs: blocking in a
//! semihosting read executes no instruction, and with `-icount shift=0` virtual time is the
//! instruction count (SysTick ticks x 40 = instructions).
//!
//! Exits through semihosting: status 0 when the node loop ended by the RC's `Stop`.

#![no_std]
#![no_main]

use core::fmt::Write as _;
use core::hint::black_box;
use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::{debug, hio, syscall};
use links_core::image::SceneView;
use links_core::link::{Incoming, LinkError, NodeLink};
use links_core::node::{run_node, Kernels, NodeConfig, NodeReport, RealTime, RunRenderer};
use links_core::num::Storage;
use links_core::render::{RenderError, Rgb8, Stats};
use links_core::wire::{CRC32, MAX_MESSAGE, MAX_SCENE};

/// QEMU mps2: SysTick counts the 25 MHz clock; with `-icount shift=0` one instruction takes
/// 1 ns, so one tick is 40 instructions.
const INSTR_PER_TICK: u64 = 40;
const RELOAD: u32 = 0x00FF_FFFF;

static WRAPS: AtomicU32 = AtomicU32::new(0);

#[exception]
fn SysTick() {
    WRAPS.store(
        WRAPS.load(Ordering::Relaxed).wrapping_add(1),
        Ordering::Relaxed,
    );
}

/// SysTick ticks since start.
#[inline(always)]
fn ticks() -> u64 {
    loop {
        let w = WRAPS.load(Ordering::SeqCst);
        let cur = SYST::get_current();
        if WRAPS.load(Ordering::SeqCst) == w {
            return ((w as u64) << 24) + (RELOAD - cur) as u64;
        }
    }
}

/// Semihosting file handle.
#[derive(Clone, Copy)]
struct Fd(usize);

/// Semihosting `SYS_OPEN` modes (ISO C `fopen` modes by number).
const MODE_RB: usize = 1;
const MODE_WB: usize = 5;

fn open(name_nul: &str, mode: usize) -> Option<Fd> {
    let b = name_nul.as_bytes();
    if b.last() != Some(&0) {
        return None;
    }
    // SAFETY: SYS_OPEN reads `len` bytes of the name (without its NUL) from the pointer.
    let fd = unsafe { syscall!(OPEN, b.as_ptr(), mode, b.len() - 1) } as isize;
    (fd >= 0).then_some(Fd(fd as usize))
}

/// Write all of `buf` (SYS_WRITE returns the bytes *not* written).
fn write_all(fd: Fd, mut buf: &[u8]) -> Result<(), LinkError> {
    while !buf.is_empty() {
        // SAFETY: SYS_WRITE reads `len` bytes from the pointer.
        let left = unsafe { syscall!(WRITE, fd.0, buf.as_ptr(), buf.len()) };
        if left >= buf.len() {
            return Err(LinkError::Aborted);
        }
        buf = &buf[buf.len() - left..];
    }
    Ok(())
}

/// Fill all of `buf` (SYS_READ returns the bytes *not* read; a pipe may deliver less than
/// asked; nothing at all means the other end closed).
fn read_exact(fd: Fd, buf: &mut [u8]) -> Result<(), LinkError> {
    let mut at = 0;
    while at < buf.len() {
        let want = buf.len() - at;
        // SAFETY: SYS_READ writes at most `want` bytes at the pointer.
        let left = unsafe { syscall!(READ, fd.0, buf[at..].as_mut_ptr(), want) };
        if left >= want {
            return Err(LinkError::Aborted);
        }
        at += want - left;
    }
    Ok(())
}

/// The IMSU link over the two FIFOs, with the TX-bank rule of the SPI link (one posted frame
/// until the RC exchanges it).
struct SemihostLink {
    down: Fd,
    up: Fd,
    /// The TX bank holds a frame not yet exchanged.
    posted: bool,
    /// One record: kind, length, frame.
    out: [u8; 5 + MAX_MESSAGE],
    /// Instructions spent in `post` and `recv` (copies and semihosting calls; waiting for
    /// the RC executes none).
    instr: u64,
    records_in: u32,
    records_out: u32,
    bytes_in: u64,
    bytes_out: u64,
}

impl SemihostLink {
    fn send(&mut self, kind: u8, payload: &[u8]) -> Result<(), LinkError> {
        let n = payload.len();
        let rec = self.out.get_mut(..5 + n).ok_or(LinkError::TooLong {
            len: n as u32,
            max: MAX_MESSAGE as u32,
        })?;
        rec[0] = kind;
        rec[1..5].copy_from_slice(&(n as u32).to_le_bytes());
        rec[5..].copy_from_slice(payload);
        self.records_out += 1;
        self.bytes_out += n as u64;
        write_all(self.up, &self.out[..5 + n])
    }
}

impl NodeLink for SemihostLink {
    fn post(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        let t0 = ticks();
        let r = if self.posted {
            Err(LinkError::Busy)
        } else {
            self.posted = true;
            self.send(b'P', frame)
        };
        self.instr += (ticks() - t0) * INSTR_PER_TICK;
        r
    }

    async fn recv(&mut self, rx: &mut [u8]) -> Result<Incoming, LinkError> {
        let t0 = ticks();
        let r = (|| {
            self.send(b'W', &[])?;
            let mut head = [0u8; 5];
            read_exact(self.down, &mut head)?;
            let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]);
            let max = rx.len() as u32;
            let dst = rx
                .get_mut(..len as usize)
                .ok_or(LinkError::TooLong { len, max })?;
            read_exact(self.down, dst)?;
            self.records_in += 1;
            self.bytes_in += len as u64;
            let len = len as usize;
            match head[0] {
                b'X' => {
                    self.posted = false;
                    Ok(Incoming::Exchanged { len })
                }
                b'B' => Ok(Incoming::Broadcast { len }),
                _ => Err(LinkError::Aborted),
            }
        })();
        self.instr += (ticks() - t0) * INSTR_PER_TICK;
        r
    }
}

/// The node's renderer: both kernels (the image picks) or the one built (features
/// `kernel-f32` / `kernel-fixed`, as nc-fw's).
#[cfg(all(feature = "kernel-f32", feature = "kernel-fixed"))]
type Renderer = links_core::node::TracingByImage;
/// The node's renderer: both kernels (the image picks) or the one built (features
/// `kernel-f32` / `kernel-fixed`, as nc-fw's).
#[cfg(all(feature = "kernel-f32", not(feature = "kernel-fixed")))]
type Renderer = links_core::node::Tracing<f32>;
/// The node's renderer: both kernels (the image picks) or the one built (features
/// `kernel-f32` / `kernel-fixed`, as nc-fw's).
#[cfg(all(feature = "kernel-fixed", not(feature = "kernel-f32")))]
type Renderer = links_core::node::Tracing<links_core::num::Fx>;
#[cfg(not(any(feature = "kernel-f32", feature = "kernel-fixed")))]
compile_error!("the QEMU node needs a kernel: feature kernel-f32 or kernel-fixed");

/// The real tracer, with the instructions it executes counted.
struct Counted {
    inner: Renderer,
    instr: u64,
    runs: u32,
}

impl RunRenderer for Counted {
    fn render(
        &mut self,
        scene: SceneView<'_>,
        frame: u16,
        y: u32,
        x: u32,
        out: &mut [Rgb8],
    ) -> Result<Stats, RenderError> {
        let t0 = ticks();
        let r = self.inner.render(scene, frame, y, x, out);
        self.instr += (ticks() - t0) * INSTR_PER_TICK;
        self.runs += 1;
        r
    }

    fn kernels(&self) -> Kernels {
        self.inner.kernels()
    }

    fn forget(&mut self) {
        self.inner.forget();
    }
}

/// The node's two scene banks (frame `f`'s scene lands in bank `f % 2`), 128 KB each as
/// LINKS-1's IMSU banks: in .bss.
static mut BANKS: [[u8; MAX_SCENE]; 2] = [[0; MAX_SCENE]; 2];

/// A fixed-capacity text buffer.
struct Text {
    buf: [u8; 2048],
    len: usize,
}

impl core::fmt::Write for Text {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let b = s.as_bytes();
        let dst = self
            .buf
            .get_mut(self.len..self.len + b.len())
            .ok_or(core::fmt::Error)?;
        dst.copy_from_slice(b);
        self.len += b.len();
        Ok(())
    }
}

fn fail(msg: &str) -> ! {
    if let Ok(mut e) = hio::hstderr() {
        let _ = e.write_all(b"qemu-node: ");
        let _ = e.write_all(msg.as_bytes());
        let _ = e.write_all(b"\n");
    }
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

#[entry]
fn main() -> ! {
    let Some(mut cp) = cortex_m::Peripherals::take() else {
        fail("core peripherals taken twice");
    };
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(RELOAD);
    cp.SYST.clear_current();
    cp.SYST.enable_interrupt();
    cp.SYST.enable_counter();

    // The RC opens its ends in the same order (down, then up), so neither open blocks forever.
    let Some(down) = open("nc-down\0", MODE_RB) else {
        fail("cannot open the link FIFO nc-down (run through the host's qemu-node-rc)");
    };
    let Some(up) = open("nc-up\0", MODE_WB) else {
        fail("cannot open the link FIFO nc-up");
    };
    let mut link = SemihostLink {
        down,
        up,
        posted: false,
        out: [0; 5 + MAX_MESSAGE],
        instr: 0,
        records_in: 0,
        records_out: 0,
        bytes_in: 0,
        bytes_out: 0,
    };
    let mut renderer = Counted {
        inner: Renderer::default(),
        instr: 0,
        runs: 0,
    };
    // SAFETY: the only reference ever made to BANKS, taken once here.
    let [b0, b1] = unsafe { &mut *core::ptr::addr_of_mut!(BANKS) };
    let mut report = NodeReport::default();

    let t0 = ticks();
    let result = embassy_futures::block_on(run_node(
        NodeConfig::default(),
        &mut link,
        &mut RealTime,
        &mut renderer,
        [b0.as_mut_slice(), b1.as_mut_slice()],
        &mut report,
    ));
    let total = (ticks() - t0) * INSTR_PER_TICK;

    // Unit costs behind the loop's protocol work, measured on the scene now in bank 0 (its
    // length is in its header): one full validation (`SceneView::new`, which `run_node` does
    // once per scene received), one cheap open of the validated bank
    // (`SceneView::open_validated`, before every run it renders and on every `Work` reply) and
    // one CRC-32 over the scene (which every frame's check costs per byte).
    let len = u32::from_le_bytes([b0[8], b0[9], b0[10], b0[11]]).min(MAX_SCENE as u32) as usize;
    let t1 = ticks();
    let valid = black_box(SceneView::new(black_box(&b0[..len]))).is_ok();
    let t2 = ticks();
    black_box(CRC32.checksum(black_box(&b0[..len])));
    let t3 = ticks();
    let _ = black_box(SceneView::open_validated(black_box(&b0[..len])));
    let t4 = ticks();
    let empty = ticks() - t4;
    let validate = (t2 - t1).saturating_sub(empty) * INSTR_PER_TICK;
    let scene_crc = (t3 - t2).saturating_sub(empty) * INSTR_PER_TICK;
    let open = (t4 - t3).saturating_sub(empty) * INSTR_PER_TICK;

    let mut t = Text {
        buf: [0; 2048],
        len: 0,
    };
    let _ = write!(
        t,
        "instr_total={} instr_render={} instr_link={} render_calls={} records_in={} records_out={} bytes_in={} bytes_out={} scene_bytes={} scene_valid={} validations={} opens={} unit_validate={} unit_open={} unit_scene_crc={} kernels_f32={} kernels_fixed={}\nresult={:?}\nreport={:?}",
        total,
        renderer.instr,
        link.instr,
        renderer.runs,
        link.records_in,
        link.records_out,
        link.bytes_in,
        link.bytes_out,
        len,
        valid as u8,
        report.validations,
        report.opens,
        validate,
        open,
        scene_crc,
        renderer.kernels().run(Storage::F32) as u8,
        renderer.kernels().run(Storage::Q16_16) as u8,
        result,
        report
    );
    let len = t.len;
    if link.send(b'E', &t.buf[..len]).is_err() {
        fail("could not send the end record");
    }
    if result.is_ok() {
        debug::exit(debug::EXIT_SUCCESS);
    } else {
        debug::exit(debug::EXIT_FAILURE);
    }
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    let mut t = Text {
        buf: [0; 2048],
        len: 0,
    };
    let _ = write!(t, "PANIC {info}");
    let len = t.len;
    fail(core::str::from_utf8(&t.buf[..len]).unwrap_or("PANIC"))
}
