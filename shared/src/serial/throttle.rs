//! A [`RootBus`] wrapper that holds exchanges back until the readback queue has room for
//! what they may bring back ([`super::readback::RUN_RESERVE`] each): the root logic's pixel
//! sink cannot wait, so the bus does, and no accepted pixel is ever dropped for want of USB
//! bandwidth (the nodes simply wait with their frames posted).
//!
//! The root logic exchanges only with a node the bus reports ready, so the wrapper reports
//! none while the queue is short. With the RC double-buffered ([`RootBus::start`] /
//! [`RootBus::finish`]) the previous exchange's pixels may be taken after the next exchange
//! started, so the room asked for is two exchanges' worth: the one that may still be in
//! flight (or not yet taken) and the new one. Only the RC's own task fills the queue, so
//! room seen free stays free until that task pushes.

use crate::link::{LinkError, NodeId, RootBus, Transfer};

/// Something that can wait for queue space.
#[allow(async_fn_in_trait)]
pub trait Room {
    /// Whether at least `n` bytes are free now.
    fn has_room(&self, n: usize) -> bool;
    /// Resolve once at least `n` bytes are free.
    async fn wait_room(&self, n: usize);
}

/// A bus whose exchanges wait for `room`.
pub struct Throttle<'r, B, R> {
    pub bus: &'r mut B,
    pub room: &'r R,
    /// Bytes one exchange may push into the queue.
    pub need: usize,
}

impl<B, R> Throttle<'_, B, R> {
    /// Room a node must find before it is reported ready: two exchanges' worth, or on a bus
    /// with several in flight ([`RootBus::flying`]) one more than are in flight now.
    pub fn reserve(&self) -> usize
    where
        B: RootBus,
    {
        self.need
            .saturating_mul(self.bus.flying().max(1) as usize + 1)
    }
}

impl<B: RootBus, R: Room> RootBus for Throttle<'_, B, R> {
    fn nodes(&self) -> (NodeId, u16) {
        self.bus.nodes()
    }

    async fn wait_ready(&mut self) -> NodeId {
        loop {
            self.room.wait_room(self.reserve()).await;
            let n = self.bus.wait_ready().await;
            // (A frame that came back needs no room of its own: see `reserve`.)
            if self.bus.arrived().is_some() || self.room.has_room(self.reserve()) {
                return n;
            }
        }
    }

    fn ready(&self) -> Option<NodeId> {
        if self.room.has_room(self.reserve()) {
            self.bus.ready()
        } else {
            None
        }
    }

    fn tx_bank(&mut self) -> &mut [u8] {
        self.bus.tx_bank()
    }

    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        self.bus.start(transfer, len)
    }

    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        self.bus.finish(rx).await
    }

    fn in_flight(&self) -> u16 {
        self.bus.in_flight()
    }

    // A frame that came back was paid for when its exchange began.
    fn arrived(&self) -> Option<NodeId> {
        self.bus.arrived()
    }

    fn flying(&self) -> u16 {
        self.bus.flying()
    }

    fn pending(&self) -> Option<NodeId> {
        self.bus.pending()
    }

    async fn finish_node(&mut self, node: NodeId, rx: &mut [u8]) -> Result<usize, LinkError> {
        self.bus.finish_node(node, rx).await
    }

    fn poll(&mut self) {
        self.bus.poll()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::cell::Cell;
    use core::future::{poll_fn, Future};
    use core::pin::pin;
    use core::task::{Context, Poll};

    struct Bus {
        bank: [u8; 8],
        started: Option<Transfer>,
        exchanges: u32,
    }

    impl RootBus for Bus {
        fn nodes(&self) -> (NodeId, u16) {
            (0, 1)
        }
        async fn wait_ready(&mut self) -> NodeId {
            0
        }
        fn ready(&self) -> Option<NodeId> {
            Some(0)
        }
        fn tx_bank(&mut self) -> &mut [u8] {
            &mut self.bank
        }
        fn start(&mut self, transfer: Transfer, _: usize) -> Result<(), LinkError> {
            if self.started.replace(transfer).is_some() {
                return Err(LinkError::Busy);
            }
            if let Transfer::Exchange(_) = transfer {
                self.exchanges += 1;
            }
            Ok(())
        }
        async fn finish(&mut self, _: &mut [u8]) -> Result<usize, LinkError> {
            self.started.take().map(|_| 0).ok_or(LinkError::Aborted)
        }
    }

    struct Queue {
        free: Cell<usize>,
    }

    impl Room for Queue {
        fn has_room(&self, n: usize) -> bool {
            self.free.get() >= n
        }
        async fn wait_room(&self, n: usize) {
            poll_fn(|_| {
                if self.free.get() >= n {
                    Poll::Ready(())
                } else {
                    Poll::Pending
                }
            })
            .await
        }
    }

    #[test]
    fn nodes_are_ready_only_with_room_for_two_exchanges_broadcasts_pass() {
        let q = Queue {
            free: Cell::new(150),
        };
        let mut bus = Bus {
            bank: [0; 8],
            started: None,
            exchanges: 0,
        };
        let mut t = Throttle {
            bus: &mut bus,
            room: &q,
            need: 100,
        };
        let mut cx = Context::from_waker(std::task::Waker::noop());
        // Broadcasts never wait.
        assert!(pin!(t.broadcast(b"x")).poll(&mut cx).is_ready());
        // Room for one exchange is not enough: one may still be in flight.
        assert_eq!(t.ready(), None);
        {
            let mut w = pin!(t.wait_ready());
            for _ in 0..10 {
                assert!(w.as_mut().poll(&mut cx).is_pending());
            }
            q.free.set(200);
            assert_eq!(w.as_mut().poll(&mut cx), Poll::Ready(0));
        }
        assert_eq!(t.ready(), Some(0));
        // start / finish reach the bus (one transfer at a time).
        t.tx_bank()[0] = 7;
        assert_eq!(t.start(Transfer::Exchange(0), 1), Ok(()));
        assert_eq!(t.start(Transfer::Exchange(0), 1), Err(LinkError::Busy));
        let mut rx = [0u8; 4];
        assert!(matches!(
            pin!(t.finish(&mut rx)).poll(&mut cx),
            Poll::Ready(Ok(0))
        ));
        assert_eq!(t.bus.exchanges, 1);
        assert_eq!(t.bus.bank[0], 7);
    }
}
