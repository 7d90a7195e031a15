//! The PC side of the serial link to a real RC: the upload and readback sessions over any
//! byte stream ([`host`]), and the `links upload` / `links readback` commands around them
//! ([`cli`]).

pub mod cli;
pub mod host;
