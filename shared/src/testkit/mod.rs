//! Test doubles shared by every test: scene builders, SPI fakes.

pub mod scene;
pub mod serial;
pub mod spi;
