//! Clocking one transfer on the wire (header phase, body, ACK/NAK trailer; or a
//! broadcast), the part of the RC's link both [`super::MasterLink`] (inside `finish`) and
//! [`super::MasterTask`] (on its own executor, while the RC composes) run.

use super::framing::*;
use super::master::{MasterCounters, MasterPort, Select};

/// What to clock: an exchange with the node at this index on the bus, or a broadcast.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(super) enum Clocked {
    Exchange(u16),
    Broadcast,
}

/// One transfer's port, banks and counters.
pub(super) struct Wire<'a, P> {
    pub port: &'a mut P,
    pub tx: &'a mut Bank,
    pub rx: &'a mut Bank,
    pub counters: &'a mut MasterCounters,
}

impl<P: MasterPort> Wire<'_, P> {
    /// Clock `what` with the first `n` bytes of frame in the TX bank (after the header
    /// room); returns the length of the node's intact frame now in the RX bank (after the
    /// header room; 0: a broadcast, no frame, or a damaged one).
    pub async fn clock(&mut self, what: Clocked, n: usize) -> usize {
        match what {
            Clocked::Exchange(i) => self.exchange(i, n).await,
            Clocked::Broadcast => {
                self.broadcast(n).await;
                0
            }
        }
    }

    /// The node frame of an exchange (after the header phase): clock the body and trailer.
    /// Returns the node frame's length if intact.
    async fn body(&mut self, n: usize) -> Result<Option<usize>, PortError> {
        let Some(h) = nc_header(&self.rx[..HEADER]) else {
            self.counters.bad_headers += 1;
            return Ok(None);
        };
        let nlen = if h.kind & FLAG_POSTED != 0 {
            h.len as usize
        } else {
            0
        };
        let l = n.max(nlen);
        self.tx[HEADER + n..HEADER + l].fill(0);
        self.port
            .transfer(
                &self.tx[HEADER..HEADER + l],
                &mut self.rx[HEADER..HEADER + l],
            )
            .await?;
        let ok = nlen == 0 || body_ok(&self.rx[..], &h);
        let t = [if ok { ACK } else { NAK }];
        let mut back = [0u8];
        self.port.transfer(&t, &mut back).await?;
        self.counters.bytes += (HEADER + l + TRAILER) as u64;
        if ok {
            Ok(Some(nlen))
        } else {
            self.counters.naks += 1;
            Ok(None)
        }
    }

    /// Clock an exchange (`n` bytes of frame) with node index `i`.
    async fn exchange(&mut self, i: u16, n: usize) -> usize {
        // Handshake ordering: never clock a node that is not armed.
        if !self.port.ready(i) {
            self.counters.not_ready += 1;
            return 0;
        }
        let h = rc_header(false, &self.tx[HEADER..HEADER + n]);
        self.tx[..HEADER].copy_from_slice(&h);
        self.rx[..HEADER].fill(0);
        self.port.select(Select::One(i)).await;
        if self.port.ready(i) {
            // The node drops its line when selected (the handshake's acknowledgement); a
            // line still high means it is not listening: clock nothing.
            self.port.deselect().await;
            self.counters.no_ack += 1;
            return 0;
        }
        let got = match self
            .port
            .transfer(&self.tx[..HEADER], &mut self.rx[..HEADER])
            .await
        {
            Ok(()) => self.body(n).await,
            Err(e) => Err(e),
        };
        self.port.deselect().await;
        self.counters.exchanges += 1;
        match got {
            Ok(Some(len)) => len,
            Ok(None) => 0,
            Err(PortError) => {
                self.counters.port_errors += 1;
                0
            }
        }
    }

    /// Clock a broadcast (`n` bytes of frame) to every node.
    async fn broadcast(&mut self, n: usize) {
        let h = rc_header(true, &self.tx[HEADER..HEADER + n]);
        self.tx[..HEADER].copy_from_slice(&h);
        self.port.select(Select::All).await;
        let r = self
            .port
            .transfer(&self.tx[..HEADER + n], &mut self.rx[..HEADER + n])
            .await;
        self.port.deselect().await;
        self.counters.broadcasts += 1;
        self.counters.bytes += (HEADER + n) as u64;
        if r.is_err() {
            self.counters.port_errors += 1;
        }
    }
}
