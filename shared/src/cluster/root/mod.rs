//! The root computer (RC): broadcast each frame's scene, hand out sub-screens, collect the
//! finished pixels, detect completion.
//!
//! The shared state is one [`RootState`] in a `RefCell`; one [`run_bus`] future per SPI bus
//! drives that bus (they run concurrently on one executor, so several buses overlap their
//! transfers). No heap: per-node bookkeeping is a fixed table of [`MAX_NODES`] entries.
//!
//! Per exchange the RC must fill its half of the swap *before* it sees the node's half, so
//! its reply carries state: the node's job list (idempotent) and the highest in-order frame
//! it has received from that node (`ack`). Animation: frame `f`'s scene goes to node bank
//! `f % 2` while frame `f - 1` renders; its jobs are handed out as soon as frame `f - 1`'s are
//! all issued, to nodes that have reported the scene ready.
//!
//! The DM stage: a [`SceneSource`] may produce scenes over time ([`SceneSource::produced`]);
//! frame `f` is broadcast only once it exists.
//!
//! Node failure: a node holding jobs that the RC has not exchanged with for
//! [`RootConfig::timeout_us`] (checked only while no ready line on its bus is up, so bus
//! congestion is never mistaken for silence) is declared dead; its jobs stay in its slot as
//! orphans, are handed (with fresh ids) to the next live nodes that ask, and every bus
//! broadcasts [`Down::Wake`](crate::cluster::wire::Down::Wake) so idle nodes ask. Under a static split a node also owes the RC
//! its region of the frame being handed out: silent for two time-outs after its bus
//! broadcast that frame's scene (one for the roll call that reaches a node which missed the
//! broadcast, one for its answer), it is declared dead and its region becomes an orphan.
//! A "dead" node that speaks again is live again; if it was declared dead while holding
//! jobs, the time-out becomes at least twice the silence it was declared dead for (it was
//! too short). The time-out in force therefore never exceeds the larger of the configured
//! one and twice the longest silence of a node that was rendering, however many false alarms
//! there are (see docs/reliability.md for the recovery bound).

mod backup;
mod bus;
mod config;
mod exchange;
mod failure;
mod handout;
mod ports;
mod state;

pub use bus::run_bus;
pub use config::{RootConfig, RootError, RootReport};
pub use ports::{NoClock, PixelSink, RcWork, RootClock, SceneSource};
pub use state::RootState;
use state::{Finished, Pieces};

/// Most buses (concurrent [`run_bus`] tasks) one RC drives.
pub const MAX_BUSES: usize = 8;

/// Most nodes the RC serves over the serial backup line at once (a fixed table: the line
/// carries a few nodes' work at best, docs/cluster.md).
pub const BACKUP_NODES: usize = 8;

/// Most nodes an RC drives (LINKS-1's design limit).
pub const MAX_NODES: usize = 256;
