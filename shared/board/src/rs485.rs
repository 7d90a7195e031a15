//! The serial backup line's port on both boards: USART2 with DMA (TX PA2, RX PA3) and the
//! RS-485 transceiver's driver-enable pin (PA1, tied to the receiver's /RE: a board never
//! hears its own frames), as [`LinePort`] for `links_core::backup`'s conversations.

use embassy_stm32::gpio::Output;
use embassy_stm32::mode::Async;
use embassy_stm32::usart::{self, Uart};
use embassy_time::{with_timeout, Duration};
use links_core::backup::{LineError, LinePort};

/// The line's UART settings: the board profile's bit rate, 8N1.
pub fn config() -> usart::Config {
    let mut c = usart::Config::default();
    c.baudrate = crate::PROFILE.backup.bit_rate_hz;
    c
}

/// USART2 and the transceiver's driver enable.
pub struct Rs485 {
    pub uart: Uart<'static, Async>,
    /// High while sending (driver on, receiver off).
    pub de: Output<'static>,
}

impl LinePort for Rs485 {
    async fn send(&mut self, frame: &[u8]) -> Result<(), LineError> {
        self.de.set_high();
        let r = match self.uart.write(frame).await {
            // The DMA is done when the last byte is in the shift register: wait for the
            // stop bit to leave before the driver lets go of the line.
            Ok(()) => self.uart.flush().await,
            Err(e) => Err(e),
        };
        self.de.set_low();
        r.map_err(|_| LineError::Uart)
    }

    async fn receive(
        &mut self,
        buf: &mut [u8],
        timeout_us: Option<u32>,
    ) -> Result<usize, LineError> {
        let read = self.uart.read_until_idle(buf);
        let r = match timeout_us {
            Some(t) => match with_timeout(Duration::from_micros(t as u64), read).await {
                Ok(r) => r,
                Err(_) => return Ok(0),
            },
            None => read.await,
        };
        r.map_err(|_| LineError::Uart)
    }
}
