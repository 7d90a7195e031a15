//! The RC's roll call: ask every address 1..=N in turn for its health; a node that does not
//! answer within the line's reply timeout (or answers garbage, or as another address) is
//! absent.

use super::{decode, encode, BackupError, Health, Msg, MAX_ADDR};

/// What the roll call does next.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RollCallStep {
    /// Send [`RollCall::request`] to this address and wait for its answer.
    Ask(u8),
    /// Every address was asked.
    Done,
}

/// One roll call over nodes 1..=N.
pub struct RollCall {
    nodes: u8,
    next: u8,
    health: [Option<Health>; MAX_ADDR as usize],
}

impl RollCall {
    /// A roll call of nodes 1..=`nodes` (at most [`MAX_ADDR`]).
    pub fn new(nodes: u8) -> Self {
        Self {
            nodes: nodes.min(MAX_ADDR),
            next: 1,
            health: [None; MAX_ADDR as usize],
        }
    }

    pub fn step(&self) -> RollCallStep {
        if self.next > self.nodes {
            RollCallStep::Done
        } else {
            RollCallStep::Ask(self.next)
        }
    }

    /// The frame asking the current address.
    pub fn request(&self, buf: &mut [u8]) -> Result<usize, BackupError> {
        encode(self.next, &Msg::RollCall, buf)
    }

    /// The current address's answer (`None`: the reply timeout passed); moves on. Returns
    /// the decode error of an answer that is not a health report from that address (the
    /// node is then counted absent).
    pub fn answered(&mut self, reply: Option<&[u8]>) -> Result<(), BackupError> {
        let asked = self.next;
        if asked > self.nodes {
            return Ok(());
        }
        self.next += 1;
        let Some(bytes) = reply else {
            return Ok(());
        };
        match decode(bytes)? {
            (a, Msg::Health(h)) if a == asked => {
                self.health[asked as usize - 1] = Some(h);
                Ok(())
            }
            (a, _) => Err(BackupError::BadAddress { addr: a }),
        }
    }

    /// The health node `addr` reported, if it answered.
    pub fn health(&self, addr: u8) -> Option<Health> {
        let i = (addr as usize).checked_sub(1)?;
        self.health.get(i).copied().flatten()
    }

    /// Nodes that did not answer.
    pub fn absent(&self) -> impl Iterator<Item = u8> + '_ {
        (1..=self.nodes).filter(|&a| self.health(a).is_none())
    }
}
