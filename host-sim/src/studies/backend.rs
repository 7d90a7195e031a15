//! The number backends a render can be measured in against f64: one enum for the names the
//! command line takes, the accuracy chart measures and the QEMU bench report prints.

use std::fmt;
use std::str::FromStr;

/// A number backend of the node's render, measured against f64.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// IEEE single precision.
    F32,
    /// f32 with micromath's approximations of sqrt and the like.
    F32Fast,
    /// Q16.16 fixed point.
    Fixed,
}

impl Backend {
    /// Every backend, in report order.
    pub const ALL: [Backend; 3] = [Backend::F32, Backend::F32Fast, Backend::Fixed];

    /// Every backend's name, in report order.
    pub const NAMES: [&'static str; 3] = [
        Backend::F32.name(),
        Backend::F32Fast.name(),
        Backend::Fixed.name(),
    ];

    /// The name reports print (`f32`, `f32-fast`, `q16.16`).
    pub const fn name(self) -> &'static str {
        match self {
            Backend::F32 => "f32",
            Backend::F32Fast => "f32-fast",
            Backend::Fixed => "q16.16",
        }
    }

    /// This backend's render of `image` compared with f64's.
    pub fn compare_to_f64(
        self,
        image: &[u8],
    ) -> Result<crate::accuracy::Accuracy, crate::accuracy::AccuracyError> {
        use crate::accuracy::compare_to_f64;
        match self {
            Backend::F32 => compare_to_f64::<f32>(image),
            Backend::F32Fast => compare_to_f64::<links_core::num::FastF32>(image),
            Backend::Fixed => compare_to_f64::<links_core::num::Fx>(image),
        }
    }
}

impl fmt::Display for Backend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A name the command line does not know as a backend.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownBackend(pub String);

impl fmt::Display for UnknownBackend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "unknown backend '{}' (expected f32, f32-fast or fixed)",
            self.0
        )
    }
}

impl std::error::Error for UnknownBackend {}

impl FromStr for Backend {
    type Err = UnknownBackend;
    fn from_str(s: &str) -> Result<Self, UnknownBackend> {
        match s {
            "f32" => Ok(Backend::F32),
            "f32-fast" => Ok(Backend::F32Fast),
            "fixed" | "q16.16" => Ok(Backend::Fixed),
            other => Err(UnknownBackend(other.to_string())),
        }
    }
}
