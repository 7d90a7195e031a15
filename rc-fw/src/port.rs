//! The embassy-stm32 port of the RC's end of one bus: [`MasterPort`] over SPI1 (master, DMA),
//! one chip-select GPIO per node (broadcast = all asserted) and one EXTI handshake input per
//! node; and the USB queue's [`Room`](crate::throttle::Room).

use embassy_futures::select::{select, select_array};
use embassy_stm32::exti::ExtiInput;
use embassy_stm32::gpio::{Level, Output};
use embassy_stm32::mode::Async;
use embassy_stm32::spi::{mode::Master, Spi};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_time::{Instant, Timer};
use links_core::root::RootClock;
use links_core::spi::{MasterPort, PortError, Select};

use crate::readback::ByteQueue;
use crate::throttle::Room;

pub use crate::link::{CS_HOLD_US, CS_SETUP_US};
/// A lost handshake edge costs at most this long (the lines are polled as well).
pub const READY_POLL_US: u64 = 500;

/// The bus hardware for `N` nodes behind a MISO multiplexer with `S` select lines.
pub struct RcPort<const N: usize, const S: usize = 3> {
    pub spi: Spi<'static, Async, Master>,
    pub cs: [Output<'static>; N],
    pub ready: [ExtiInput<'static, Async>; N],
    /// Select lines (bit 0 first) of the MISO multiplexer: each node's MISO has its own wire
    /// to the mux, so the nodes selected together by a broadcast never drive one line.
    pub miso_sel: [Output<'static>; S],
}

impl<const N: usize, const S: usize> MasterPort for RcPort<N, S> {
    fn count(&self) -> u16 {
        N as u16
    }

    fn ready(&self, i: u16) -> bool {
        self.ready.get(i as usize).is_some_and(|r| r.is_high())
    }

    async fn wait_any_ready(&mut self) {
        let edges = select_array(self.ready.each_mut().map(|r| r.wait_for_high()));
        select(edges, Timer::after_micros(READY_POLL_US)).await;
    }

    async fn select(&mut self, sel: Select) {
        match sel {
            Select::One(i) => {
                for (bit, line) in self.miso_sel.iter_mut().enumerate() {
                    line.set_level(if i >> bit & 1 == 1 {
                        Level::High
                    } else {
                        Level::Low
                    });
                }
                if let Some(cs) = self.cs.get_mut(i as usize) {
                    cs.set_low();
                }
            }
            Select::All => self.cs.iter_mut().for_each(|c| c.set_low()),
        }
        Timer::after_micros(CS_SETUP_US).await;
    }

    async fn deselect(&mut self) {
        self.cs.iter_mut().for_each(|c| c.set_high());
        Timer::after_micros(CS_HOLD_US).await;
    }

    async fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), PortError> {
        self.spi.transfer(rx, tx).await.map_err(|_| PortError)
    }
}

/// The queue of serial frames for USB.
pub type UsbPipe = Pipe<CriticalSectionRawMutex, { crate::plan::USB_QUEUE }>;

/// The readback's end of the USB queue.
pub struct PipeQueue(pub &'static UsbPipe);

impl ByteQueue for PipeQueue {
    fn free(&self) -> usize {
        self.0.free_capacity()
    }

    fn push(&mut self, bytes: &[u8]) -> bool {
        if bytes.len() > self.0.free_capacity() {
            return false;
        }
        // Only this task writes: the room checked above is still there.
        self.0.try_write(bytes).is_ok_and(|n| n == bytes.len())
    }
}

impl Room for PipeQueue {
    fn has_room(&self, n: usize) -> bool {
        self.0.free_capacity() >= n
    }

    async fn wait_room(&self, n: usize) {
        while self.0.free_capacity() < n {
            Timer::after_micros(200).await;
        }
    }
}

/// The RC's time base for node time-outs.
pub struct Clock;

impl RootClock for Clock {
    fn now_us(&self) -> u64 {
        Instant::now().as_micros()
    }

    async fn at_us(&self, t: u64) {
        Timer::at(Instant::from_micros(t)).await
    }
}
