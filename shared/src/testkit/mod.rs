//! Test doubles shared by every test: scene builders, SPI fakes, numbers.

pub mod numbers;
pub mod scene;
pub mod serial;
pub mod spi;
