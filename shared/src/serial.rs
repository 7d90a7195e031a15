//! The PC <-> RC serial protocol (USB CDC or a UART): scene upload and frame readback.
//!
//! See `docs/serial.md` for the message table and the rules; this is the code.
//!
//! ## Framing
//! ```text
//! 0x00 ++ COBS( postcard(Packet { version, seq, msg }) ++ CRC-32 (4 bytes LE) ) ++ 0x00
//! ```
//! Each frame starts and ends with a zero byte, and COBS removes every zero from the bytes
//! in between, so a receiver that lost its place (garbage, a cut cable, a frame that
//! overflowed its buffer) is back in step at the next zero: at most the frame being
//! received is lost. The CRC is [`crate::wire::CRC32`], as on the cluster bus. The first
//! byte of every packet is [`VERSION`], checked right after the CRC and before the message,
//! so a version mismatch is reported as such and not as garbage.
//!
//! ## Pieces
//! - [`Encoder`]: writes frames into caller buffers and numbers them (`seq`).
//! - [`Decoder`]: takes a byte at a time into a fixed buffer (a `heapless::Vec`) and yields
//!   each frame's [`Packet`], which borrows its payload from that buffer.
//! - [`UploadReceiver`]: the RC side of a scene upload: assembles the SceneImage in a
//!   caller buffer, acknowledges progress and asks for retransmission of bad or lost chunks.
//! - [`FrameStreamer`]: the RC side of readback: turns rows of pixels into messages and
//!   keeps the frame's CRC ([`FrameCrc`]) in whatever order the rows come.
//!
//! The RC's half of the conversation, generic over the board (bus, clock, USB queue) so the
//! firmware and the host tests run the same code:
//! - [`session`]: the PC's bytes in, upload replies out, render / resend / ack requests.
//! - [`render`]: one render request over the cluster bus, and the answer to a `Resend`.
//! - [`film`]: which scene bank holds which film frame, and the flow control of a film.
//! - [`readback`]: the pixel sink that turns accepted bus runs into serial frames.
//! - [`throttle`]: the bus wrapper that holds exchanges back while the byte queue is full.
//!
//! Nothing here panics or allocates on any input; every failure is a [`SerialError`].

mod codec;
mod frame_crc;
mod protocol;
mod streamer;
mod upload;

pub mod film;
pub mod readback;
pub mod render;
pub mod session;
pub mod throttle;

pub use codec::{decode_body, encode_packet, Decoder, Encoder};
pub use frame_crc::FrameCrc;
pub use protocol::*;
pub use streamer::{pixel_count, pixels_into, FrameStreamer, SpanRuns};
pub use upload::{Reply, UploadEvent, UploadReceiver};

#[cfg(test)]
mod tests;
