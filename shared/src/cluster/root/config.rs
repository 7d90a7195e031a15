//! The RC's configuration, its errors and its report counters.

use super::*;
use crate::cluster::link::LinkError;
use crate::cluster::sched::{Policy, SchedError};
use core::fmt;

/// What the RC runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RootConfig {
    pub policy: Policy,
    pub nodes: u16,
    pub frames: u16,
    /// A node holding jobs that has not been heard from for this long (µs) is declared dead
    /// and its jobs are re-issued; 0 = never. It must exceed the longest run a node renders
    /// between two exchanges ([`RootConfig::DEFAULT_TIMEOUT_US`]).
    pub timeout_us: u64,
    /// RC-side DMA double buffering: compose the next transfer and take the previous
    /// node's frame while a transfer is on the wire ([`RootBus::start`](crate::cluster::link::RootBus::start) /
    /// [`RootBus::finish`](crate::cluster::link::RootBus::finish)). `false`: one transfer at a time, the bus idle while the RC
    /// composes and decodes.
    pub double_buffer: bool,
}

impl RootConfig {
    /// The F407 node's silence bound, 0.5 s (each board's:
    /// [`BoardProfile::node_timeout_us`](crate::cluster::profile::BoardProfile::node_timeout_us)).
    pub const DEFAULT_TIMEOUT_US: u64 = crate::cluster::profile::BoardProfile::F407.node_timeout_us;
}

/// Why the RC cannot run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RootError {
    TooManyNodes {
        nodes: u16,
    },
    /// Frame `frame` has no scene, or it is not a valid SceneImage.
    BadScene {
        frame: u16,
    },
    /// Frame `frame`'s scene image is `len` bytes, more than the protocol carries (`max`,
    /// [`wire::MAX_SCENE`](crate::cluster::wire::MAX_SCENE)).
    SceneTooLarge {
        frame: u16,
        len: u32,
        max: u32,
    },
    /// Frames of one animation differ in screen size.
    SizeChanged {
        frame: u16,
    },
    Sched(SchedError),
    Link(LinkError),
}

impl fmt::Display for RootError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RootError::TooManyNodes { nodes } => {
                write!(f, "{nodes} nodes (at most {MAX_NODES})")
            }
            RootError::BadScene { frame } => write!(f, "frame {frame} has no usable scene image"),
            RootError::SceneTooLarge { frame, len, max } => write!(
                f,
                "frame {frame}'s scene image is {len} bytes, more than the {max} bytes a scene may have"
            ),
            RootError::SizeChanged { frame } => write!(f, "frame {frame} changes the screen size"),
            RootError::Sched(e) => write!(f, "scheduling: {e}"),
            RootError::Link(e) => write!(f, "link: {e}"),
        }
    }
}

impl core::error::Error for RootError {}

impl From<LinkError> for RootError {
    fn from(e: LinkError) -> Self {
        RootError::Link(e)
    }
}

/// Counters of what the RC saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RootReport {
    pub exchanges: u32,
    pub broadcasts: u32,
    pub jobs: u32,
    pub pixels: u64,
    /// Node frames that failed CRC or decoding.
    pub bad_messages: u32,
    /// Node frames out of sequence (duplicates after a lost acknowledgement, or frames
    /// behind a lost one), dropped.
    pub out_of_order: u32,
    /// Valid frames whose contents were not plausible (unknown job, run outside the frame).
    pub rejected: u32,
    /// Scene chunks re-sent point-to-point.
    pub repairs: u32,
    pub polls: u32,
    /// Node frames accepted in sequence.
    pub accepted: u64,
    /// Nodes declared dead (silent past their deadline while holding jobs or owing their
    /// static region).
    pub timeouts: u32,
    /// Jobs of dead nodes handed to other nodes.
    pub reissued: u32,
    /// Nodes declared dead that spoke again (and were taken back).
    pub revived: u32,
    /// The time-out in force (µs): the configured one, raised by false alarms.
    pub timeout_us: u64,
    /// Pixel runs taken from nodes over the serial backup line.
    pub backup_runs: u64,
}
