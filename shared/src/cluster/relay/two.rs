//! The root of relays on two SPI buses: [`TwoLinks`], one [`RootBus`] over the nodes behind
//! two [`super::RelayedBus`]es, so `run_bus` (and the RC's render code around it) runs
//! unchanged while each link carries half the relays' traffic.
//!
//! Why two: the root's one link is what idles the nodes of a 64-node tree at both ends of a
//! frame (`docs/cluster.md`, "Where the firmware's relay code loses"): the scene's chunks
//! and 64 nodes' first exchanges at the start, the short last jobs' frames at the end. The
//! F407 has three SPI peripherals; the second one halves each link's load
//! ([`crate::board::LinkProfile::root_links`]).

use crate::cluster::link::{LinkError, NodeId, RootBus, Transfer};
use embassy_futures::join::join;
use embassy_futures::select::{select, Either};

/// Two root buses as one: `first`'s nodes, then `second`'s (their numbers must follow on),
/// each keeping its own exchanges in flight. A reply is composed in `first`'s idle TX bank
/// and copied into `second`'s when it goes there; a broadcast goes on both and ends when
/// both have ended. Made for buses that keep several exchanges in flight
/// ([`RootBus::in_flight`] above 1, as [`super::RelayedBus`] does): `finish_node` waits on
/// the node's own bus, the other bus's link goes on in every [`RootBus::poll`] and
/// [`RootBus::wait_ready`].
pub struct TwoLinks<A, B> {
    first: A,
    second: B,
    /// A broadcast started on both and not yet finished.
    cast: bool,
}

impl<A: RootBus, B: RootBus> TwoLinks<A, B> {
    /// `first` and `second`, or [`LinkError::NoSuchNode`] (the first number `second` should
    /// start at) when `second`'s nodes do not follow `first`'s.
    pub fn new(first: A, second: B) -> Result<Self, LinkError> {
        let (f, n) = first.nodes();
        let next = f.checked_add(n).ok_or(LinkError::NoSuchNode { node: f })?;
        let (s, m) = second.nodes();
        if s != next || next.checked_add(m).is_none() {
            return Err(LinkError::NoSuchNode { node: next });
        }
        Ok(TwoLinks {
            first,
            second,
            cast: false,
        })
    }

    /// The two buses.
    pub fn links(&self) -> (&A, &B) {
        (&self.first, &self.second)
    }

    /// Whether `node` is on the second bus.
    fn on_second(&self, node: NodeId) -> bool {
        node >= self.second.nodes().0
    }
}

impl<A: RootBus, B: RootBus> RootBus for TwoLinks<A, B> {
    fn nodes(&self) -> (NodeId, u16) {
        let (f, n) = self.first.nodes();
        (f, n.saturating_add(self.second.nodes().1))
    }

    async fn wait_ready(&mut self) -> NodeId {
        if let Some(n) = self.arrived().or_else(|| self.ready()) {
            return n;
        }
        match select(self.first.wait_ready(), self.second.wait_ready()).await {
            Either::First(n) | Either::Second(n) => n,
        }
    }

    fn ready(&self) -> Option<NodeId> {
        self.first.ready().or_else(|| self.second.ready())
    }

    fn ask_ahead(&self, node: NodeId) -> bool {
        if self.on_second(node) {
            self.second.ask_ahead(node)
        } else {
            self.first.ask_ahead(node)
        }
    }

    fn line(&self, node: NodeId) -> bool {
        if self.on_second(node) {
            self.second.line(node)
        } else {
            self.first.line(node)
        }
    }

    fn tx_bank(&mut self) -> &mut [u8] {
        self.first.tx_bank()
    }

    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        let to_second = match transfer {
            Transfer::Exchange(node) => self.on_second(node),
            Transfer::Broadcast => {
                if self.cast {
                    return Err(LinkError::Busy);
                }
                true
            }
        };
        if to_second {
            let (src, dst) = (self.first.tx_bank(), self.second.tx_bank());
            let max = src.len().min(dst.len()) as u32;
            let too_long = LinkError::TooLong {
                len: len as u32,
                max,
            };
            let (Some(src), Some(dst)) = (src.get(..len), dst.get_mut(..len)) else {
                return Err(too_long);
            };
            dst.copy_from_slice(src);
            self.second.start(transfer, len)?;
        }
        match transfer {
            Transfer::Exchange(_) if to_second => Ok(()),
            Transfer::Exchange(_) => self.first.start(transfer, len),
            Transfer::Broadcast => {
                // Both buses see the same broadcasts, so the first starts it as the second
                // did (a failure here is the render's, as on one bus).
                self.first.start(transfer, len)?;
                self.cast = true;
                Ok(())
            }
        }
    }

    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        if self.cast {
            self.cast = false;
            let (a, b) = join(self.first.finish(&mut []), self.second.finish(&mut [])).await;
            a?;
            b?;
            return Ok(0);
        }
        let second = match (self.first.arrived(), self.second.arrived()) {
            (Some(_), _) => false,
            (None, Some(_)) => true,
            (None, None) => self.first.pending().is_none(),
        };
        if second {
            self.second.finish(rx).await
        } else {
            self.first.finish(rx).await
        }
    }

    fn in_flight(&self) -> u16 {
        self.first
            .in_flight()
            .saturating_add(self.second.in_flight())
    }

    fn arrived(&self) -> Option<NodeId> {
        self.first.arrived().or_else(|| self.second.arrived())
    }

    fn flying(&self) -> u16 {
        self.first.flying().saturating_add(self.second.flying())
    }

    fn pending(&self) -> Option<NodeId> {
        self.first.pending().or_else(|| self.second.pending())
    }

    async fn finish_node(&mut self, node: NodeId, rx: &mut [u8]) -> Result<usize, LinkError> {
        if self.on_second(node) {
            self.second.finish_node(node, rx).await
        } else {
            self.first.finish_node(node, rx).await
        }
    }

    fn poll(&mut self) {
        self.first.poll();
        self.second.poll();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embassy_futures::block_on;
    use std::vec::Vec;

    /// A bus of relayed nodes `first..first + count` that records what is started on it and
    /// ends each exchange at once (its frame: the node number).
    struct Fake {
        first: NodeId,
        count: u16,
        bank: [u8; 64],
        started: Vec<(Transfer, Vec<u8>)>,
        flying: Vec<NodeId>,
        cast: bool,
    }

    fn fake(first: NodeId, count: u16) -> Fake {
        Fake {
            first,
            count,
            bank: [0; 64],
            started: Vec::new(),
            flying: Vec::new(),
            cast: false,
        }
    }

    impl RootBus for Fake {
        fn nodes(&self) -> (NodeId, u16) {
            (self.first, self.count)
        }
        async fn wait_ready(&mut self) -> NodeId {
            self.first
        }
        fn ready(&self) -> Option<NodeId> {
            None
        }
        fn tx_bank(&mut self) -> &mut [u8] {
            &mut self.bank
        }
        fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
            self.started.push((transfer, self.bank[..len].to_vec()));
            match transfer {
                Transfer::Exchange(n) => self.flying.push(n),
                Transfer::Broadcast => self.cast = true,
            }
            Ok(())
        }
        async fn finish(&mut self, _rx: &mut [u8]) -> Result<usize, LinkError> {
            if core::mem::take(&mut self.cast) {
                return Ok(0);
            }
            Err(LinkError::Aborted)
        }
        fn in_flight(&self) -> u16 {
            8
        }
        fn arrived(&self) -> Option<NodeId> {
            self.flying.first().copied()
        }
        fn flying(&self) -> u16 {
            self.flying.len() as u16
        }
        fn pending(&self) -> Option<NodeId> {
            self.flying.first().copied()
        }
        async fn finish_node(&mut self, node: NodeId, rx: &mut [u8]) -> Result<usize, LinkError> {
            let i = self.flying.iter().position(|&n| n == node);
            self.flying.remove(i.ok_or(LinkError::Aborted)?);
            rx[..2].copy_from_slice(&node.to_le_bytes());
            Ok(2)
        }
    }

    #[test]
    fn the_second_links_nodes_must_follow_the_firsts() {
        assert!(TwoLinks::new(fake(0, 32), fake(32, 32)).is_ok());
        assert_eq!(
            TwoLinks::new(fake(0, 32), fake(33, 32)).err(),
            Some(LinkError::NoSuchNode { node: 32 })
        );
        assert!(TwoLinks::new(fake(0, 32), fake(0, 32)).is_err());
        assert!(TwoLinks::new(fake(u16::MAX - 1, 1), fake(u16::MAX, 4)).is_err());
    }

    /// A reply composed in the first bus's bank goes to the bus its node is on (copied to
    /// the second's bank), a broadcast to both, and each frame is taken from its own bus.
    #[test]
    fn exchanges_go_to_their_nodes_bus_and_broadcasts_to_both() {
        let mut two = TwoLinks::new(fake(0, 32), fake(32, 32)).unwrap();
        assert_eq!((two.nodes(), two.in_flight()), ((0, 64), 16));
        two.tx_bank()[..3].copy_from_slice(b"abc");
        two.start(Transfer::Exchange(40), 3).unwrap();
        two.tx_bank()[..2].copy_from_slice(b"xy");
        two.start(Transfer::Exchange(5), 2).unwrap();
        let (a, b) = two.links();
        assert_eq!(a.started, [(Transfer::Exchange(5), b"xy".to_vec())]);
        assert_eq!(b.started, [(Transfer::Exchange(40), b"abc".to_vec())]);
        assert_eq!((two.flying(), two.arrived()), (2, Some(5)));
        let mut rx = [0u8; 8];
        assert_eq!(block_on(two.finish_node(40, &mut rx)), Ok(2));
        assert_eq!(u16::from_le_bytes([rx[0], rx[1]]), 40);
        assert_eq!((two.flying(), two.pending()), (1, Some(5)));
        two.tx_bank()[..4].copy_from_slice(b"cast");
        two.start(Transfer::Broadcast, 4).unwrap();
        assert_eq!(two.start(Transfer::Broadcast, 4), Err(LinkError::Busy));
        let (a, b) = two.links();
        assert_eq!(a.started[1], (Transfer::Broadcast, b"cast".to_vec()));
        assert_eq!(b.started[1], (Transfer::Broadcast, b"cast".to_vec()));
        assert_eq!(block_on(two.finish(&mut rx)), Ok(0));
        assert!(!two.links().0.cast && !two.links().1.cast);
        // Too long for a bank: refused, nothing started.
        assert!(matches!(
            two.start(Transfer::Exchange(33), 65),
            Err(LinkError::TooLong { len: 65, .. })
        ));
        assert_eq!(two.links().1.started.len(), 2);
    }
}
