//! A [`RootBus`] wrapper that makes an exchange wait until the readback queue has room for
//! what it may bring back ([`crate::readback::RUN_RESERVE`]): the root logic's pixel sink
//! cannot wait, so the bus does, and no accepted pixel is ever dropped for want of USB
//! bandwidth (the nodes simply wait with their frames posted).

use links_core::link::{LinkError, NodeId, RootBus};

/// Something that can wait for queue space.
#[allow(async_fn_in_trait)]
pub trait Room {
    /// Resolve once at least `n` bytes are free.
    async fn wait_room(&self, n: usize);
}

/// A bus whose exchanges wait for `room`.
pub struct Throttle<'r, B, R> {
    pub bus: &'r mut B,
    pub room: &'r R,
    pub need: usize,
}

impl<B: RootBus, R: Room> RootBus for Throttle<'_, B, R> {
    fn nodes(&self) -> (NodeId, u16) {
        self.bus.nodes()
    }

    async fn wait_ready(&mut self) -> NodeId {
        self.bus.wait_ready().await
    }

    fn ready(&self) -> Option<NodeId> {
        self.bus.ready()
    }

    async fn exchange(
        &mut self,
        node: NodeId,
        tx: &[u8],
        rx: &mut [u8],
    ) -> Result<usize, LinkError> {
        self.room.wait_room(self.need).await;
        self.bus.exchange(node, tx, rx).await
    }

    async fn broadcast(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        self.bus.broadcast(frame).await
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
        exchanges: Cell<u32>,
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
        async fn exchange(
            &mut self,
            _: NodeId,
            _: &[u8],
            _: &mut [u8],
        ) -> Result<usize, LinkError> {
            self.exchanges.set(self.exchanges.get() + 1);
            Ok(0)
        }
        async fn broadcast(&mut self, _: &[u8]) -> Result<(), LinkError> {
            Ok(())
        }
    }

    struct Queue {
        free: Cell<usize>,
    }

    impl Room for Queue {
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
    fn exchanges_wait_for_room_broadcasts_do_not() {
        let q = Queue {
            free: Cell::new(10),
        };
        let mut bus = Bus {
            exchanges: Cell::new(0),
        };
        let mut t = Throttle {
            bus: &mut bus,
            room: &q,
            need: 100,
        };
        let mut cx = Context::from_waker(std::task::Waker::noop());
        assert!(pin!(t.broadcast(b"x")).poll(&mut cx).is_ready());
        let mut rx = [0u8; 4];
        {
            let mut ex = pin!(t.exchange(0, b"x", &mut rx));
            for _ in 0..10 {
                assert!(ex.as_mut().poll(&mut cx).is_pending());
            }
            q.free.set(100);
            assert!(ex.as_mut().poll(&mut cx).is_ready());
        }
        assert_eq!(t.bus.exchanges.get(), 1);
    }
}
