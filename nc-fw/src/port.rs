//! The embassy-stm32 port of the node's end of the link: [`SlavePort`] over SPI1 in slave
//! mode with DMA and hardware NSS, a chip-select sense input (EXTI) and the handshake output.
//!
//! Every transfer gets a freshly constructed `Spi`: constructing resets SPI1 through RCC, so a
//! transfer the RC ended early (they all end before the bank is full: the DMA is armed for a
//! whole bank) leaves no byte behind in the transmit buffer to shift out first next time.
//!
//! ## The slave-pin workaround (embassy-stm32 0.6.0)
//! `Spi::new_slave` sets the pins up as for a master: MOSI as an AF *output* (push-pull, the
//! config's speed) and MISO as an AF *input* (low speed, the config's `miso_pull`). On the
//! F4's GPIO (v2) the AF mode leaves the direction to the SPI peripheral, so nothing is
//! driven backwards; what goes wrong is the electrical set-up: MISO, the slave's only output,
//! is left at OSPEEDR = low speed (edges for ~2 MHz, too slow for a 21-42 MHz SPI clock) with
//! a pull resistor meant for an input. [`fix_slave_pins`] rewrites MISO to very-high speed,
//! push-pull, no pull, and MOSI to no pull, through the PAC right after construction (fixed
//! only on embassy's main branch; drop this when a release has it). The G0's GPIO is the same
//! (v2) and gets the same fix (its MISO and MOSI are on GPIOB).
//!
//! The F4's SPI slave also keeps driving MISO while NSS is high, so on a shared MISO line
//! every node would fight the selected one: the port switches MISO to a high-impedance input
//! ([`miso_drive`]) except while its chip-select is low.

use core::future::Future;
use core::pin::pin;
use core::task::Poll;
use embassy_futures::poll_once;
use embassy_futures::select::{select, Either};
use embassy_stm32::exti::ExtiInput;
use embassy_stm32::gpio::Output;
use embassy_stm32::mode::Async;
use embassy_stm32::pac::gpio::vals;
use embassy_stm32::peripherals::SPI1;
use embassy_stm32::spi::{self, Spi};
use embassy_stm32::{bind_interrupts, dma, exti, interrupt, Peri};
use links_core::spi::{Armed, PortError, SlavePort};

use crate::pins::{MISO_PIN, MOSI_PIN};

/// The F4 and F2 boards: SPI1 on PA5 (SCK), PA6 (MISO), PA7 (MOSI), PA4 (NSS); DMA2 stream 3
/// (TX) and stream 0 (RX), channel 3; the chip-select sense on EXTI0.
#[cfg(not(feature = "board-g0b1"))]
mod board {
    pub use embassy_stm32::pac::GPIOA as DATA_GPIO;
    pub use embassy_stm32::peripherals::{
        DMA2_CH0 as RxDma, DMA2_CH3 as TxDma, PA4 as Nss, PA5 as Sck, PA6 as Miso, PA7 as Mosi,
    };
}
#[cfg(not(feature = "board-g0b1"))]
bind_interrupts!(pub struct Irqs {
    DMA2_STREAM0 => dma::InterruptHandler<board::RxDma>;
    DMA2_STREAM3 => dma::InterruptHandler<board::TxDma>;
    EXTI0 => exti::InterruptHandler<interrupt::typelevel::EXTI0>;
});

/// The G0B1 board: SPI1 on PB3 (SCK), PB4 (MISO), PB5 (MOSI), PA4 (NSS); DMA1 channel 2
/// (TX) and channel 1 (RX) through the DMAMUX (each with an interrupt line of its own among
/// the G0's three: the backup line's channels 4 and 5 share the third); the chip-select
/// sense on EXTI0 (the G0's EXTI0_1 interrupt).
#[cfg(feature = "board-g0b1")]
mod board {
    pub use embassy_stm32::pac::GPIOB as DATA_GPIO;
    pub use embassy_stm32::peripherals::{
        DMA1_CH1 as RxDma, DMA1_CH2 as TxDma, PA4 as Nss, PB3 as Sck, PB4 as Miso, PB5 as Mosi,
    };
}
#[cfg(feature = "board-g0b1")]
bind_interrupts!(pub struct Irqs {
    DMA1_CHANNEL1 => dma::InterruptHandler<board::RxDma>;
    DMA1_CHANNEL2_3 => dma::InterruptHandler<board::TxDma>;
    EXTI0_1 => exti::InterruptHandler<interrupt::typelevel::EXTI0_1>;
});

use board::DATA_GPIO;
pub use board::{Miso, Mosi, Nss, RxDma, Sck, TxDma};

/// Correct the electrical set-up embassy-stm32 0.6.0's `new_slave` gives the data pins (see
/// the module documentation), and release MISO until the node is selected.
pub fn fix_slave_pins() {
    DATA_GPIO
        .ospeedr()
        .modify(|w| w.set_ospeedr(MISO_PIN, vals::Ospeedr::VERY_HIGH_SPEED));
    DATA_GPIO
        .otyper()
        .modify(|w| w.set_ot(MISO_PIN, vals::Ot::PUSH_PULL));
    DATA_GPIO.pupdr().modify(|w| {
        w.set_pupdr(MISO_PIN, vals::Pupdr::FLOATING);
        w.set_pupdr(MOSI_PIN, vals::Pupdr::FLOATING);
    });
    miso_drive(false);
}

/// Drive MISO (AF mode, the SPI's output) or release it (input, high impedance).
pub fn miso_drive(on: bool) {
    let mode = if on {
        vals::Moder::ALTERNATE
    } else {
        vals::Moder::INPUT
    };
    DATA_GPIO.moder().modify(|w| w.set_moder(MISO_PIN, mode));
}

/// The node's link hardware.
pub struct NcPort {
    pub spi: Peri<'static, SPI1>,
    pub sck: Peri<'static, Sck>,
    pub miso: Peri<'static, Miso>,
    pub mosi: Peri<'static, Mosi>,
    pub nss: Peri<'static, Nss>,
    pub tx_dma: Peri<'static, TxDma>,
    pub rx_dma: Peri<'static, RxDma>,
    /// The RC's chip-select, sensed (same net as NSS).
    pub cs: ExtiInput<'static, Async>,
    pub ready: Output<'static>,
    /// The protocol wants the handshake line up: raised only once the DMA is armed.
    pub want_ready: bool,
}

impl SlavePort for NcPort {
    async fn transfer(
        &mut self,
        tx: &[u8],
        rx: &mut [u8],
        cancel: impl Future<Output = ()>,
    ) -> Result<Armed, PortError> {
        if tx.len() != rx.len() {
            return Err(PortError);
        }
        let mut cfg = spi::Config::default();
        cfg.mode = spi::MODE_0;
        let mut spi = Spi::new_slave(
            self.spi.reborrow(),
            self.sck.reborrow(),
            self.mosi.reborrow(),
            self.miso.reborrow(),
            self.nss.reborrow(),
            self.tx_dma.reborrow(),
            self.rx_dma.reborrow(),
            Irqs,
            cfg,
        );
        fix_slave_pins();
        let mut dma = pin!(spi.transfer(rx, tx));
        // The first poll arms both DMA streams; the bank is larger than any transfer, so it
        // cannot finish here.
        if let Poll::Ready(r) = poll_once(dma.as_mut()) {
            return r.map(|()| Armed::Done).map_err(|_| PortError);
        }
        // Armed: now the RC may select us.
        if self.want_ready {
            self.ready.set_high();
        }
        if self.cs.is_high() {
            if let Either::Second(()) = select(self.cs.wait_for_low(), cancel).await {
                if self.cs.is_high() {
                    // Not selected: drop the line, then disarm (dropping the transfer stops
                    // the DMA).
                    self.ready.set_low();
                    return Ok(Armed::Cancelled);
                }
            }
        }
        // Selected: acknowledge by dropping the handshake line, then drive MISO. The RC
        // waits its set-up time before the first clock edge.
        self.want_ready = false;
        self.ready.set_low();
        miso_drive(true);
        let ended = select(dma.as_mut(), self.cs.wait_for_high()).await;
        if let Either::First(_) = ended {
            self.cs.wait_for_high().await;
        }
        miso_drive(false);
        Ok(Armed::Done)
    }

    fn set_ready(&mut self, high: bool) {
        // Raising waits for the next arming (in `transfer`); dropping is immediate.
        self.want_ready = high;
        if !high {
            self.ready.set_low();
        }
    }
}
