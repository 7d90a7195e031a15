//! The SPI link driver's protocol: the IMSU exchange over a real SPI star, independent of the
//! MCU. The firmware (`nc-fw`, `rc-fw`) implements the two small port traits with embassy-stm32
//! (SPI + DMA, chip-select GPIOs, handshake lines, EXTI); host tests implement them with a fake
//! bus that enforces the same rules and injects faults. Everything here is `no_std`, no heap,
//! and nothing read from the bus can make it panic.
//!
//! ## One transfer (chip-select low throughout)
//! ```text
//! RC -> NC   header (8)  | body, L bytes                  | trailer (1, exchange only)
//! NC -> RC   header (8)  | body, L bytes                  | (ignored)
//! header = magic, kind/flags, len u16 LE, CRC-16 of the body u16 LE, CRC-16 of bytes 0..6
//! ```
//! - **exchange** (one chip-select): the RC clocks the 8-byte header phase, reads the node's
//!   header (its frame's length), clocks a body of `L = max(rc_len, nc_len)` bytes (the
//!   shorter side padded), checks the node's body against its CRC and clocks one trailer
//!   byte: [`ACK`] or [`NAK`]. A NAK is the link's **retransmit request**: the node keeps the
//!   frame in its TX bank, raises its ready line again and the frame goes out in the next
//!   exchange; the RC counts the malformed frame and hands the root logic an empty frame
//!   (which it counts as bad, never a crash).
//! - **broadcast** (every chip-select): header and body only; the nodes' MISO output is
//!   ignored (and current-limited by the series resistors in `docs/hardware.md`).
//!
//! The node arms its DMA for a whole bank before a transfer and learns where it ended from
//! the chip-select's rising edge, so a short, truncated or garbled transfer only costs that
//! transfer: banks are zeroed before arming, and every length and CRC is checked.
//!
//! ## Handshake line (one GPIO per node, node -> RC)
//! High = "my DMA is armed with a posted frame in the TX bank and I have a free RX bank".
//! The RC clocks an exchange only with a node whose line is high (and re-checks it just
//! before asserting the chip-select). After a transfer the node drops the line and raises it
//! again once re-armed. A lost edge costs at most one polling period ([`MasterPort::
//! wait_any_ready`] also wakes on a timer), never a hang.
//!
//! ## The RC's two halves (overlap)
//! [`MasterFront`] is the [`crate::link::RootBus`] the root logic drives; it hands each
//! started transfer (with its TX and RX banks) to [`MasterTask`], which owns the
//! [`MasterPort`] and clocks the phases on an executor of its own (`rc-fw`: an interrupt
//! executor above the thread executor), then hands the banks back; `finish` waits for that.
//! The task also publishes the handshake lines it reads, which the front's `ready` and
//! `wait_ready` use. So the wire runs while the RC composes the next transfer and decodes the
//! last ([`RC_OVERLAPS`]). [`MasterLink`] is the same protocol clocked inside `finish` (one
//! task, no overlap): both call the same transfer code.
//!
//! ## Banks
//! The node's link owns two TX banks (the one armed in DMA, the one `post` fills: double
//! buffer), two RX banks handed to the node logic in turn (double buffer: a broadcast can
//! land while the node still reads the previous frame) and a scratch bank that absorbs a
//! transfer when both RX banks are full (counted as an overflow; scene chunks lost that way
//! are repaired by the root logic). While the node logic renders, it lends the link the
//! scene bank it is not reading ([`crate::landing`]): an intact broadcast scene chunk for that
//! bank is written straight into it and takes no RX bank.

mod bus_task;
mod clock;
mod framing;
mod master;
mod slave;

pub use bus_task::{MasterFront, MasterShared, MasterTask};
pub use framing::{
    nc_header, rc_header, Bank, Header, PortError, ACK, BANK, CRC16, HEADER, NAK, TRAILER,
};
pub use master::{MasterCounters, MasterLink, MasterPort, Select, RC_OVERLAPS};
pub use slave::{Armed, SlaveBanks, SlaveCounters, SlaveHandle, SlavePort, SlaveShared, SlaveTask};
