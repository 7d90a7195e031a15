//! A deterministic discrete-event executor in virtual time.
//!
//! Tasks are ordinary futures (the very `run_node` / `run_bus` the firmware runs). The loop
//! polls every live task in a fixed order until a whole pass changes nothing in the
//! [`World`], then advances virtual time to the earliest pending event. No waker is used (a
//! no-op one is passed): quiescence is detected by the world's change counter, so the
//! schedule, and with it every result, depends only on the inputs.

use std::cell::RefCell;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::future::Future;
use std::pin::Pin;
use std::rc::Rc;
use std::task::{Context, Poll, Waker};

/// Virtual time in picoseconds.
pub type Ps = u64;

/// The clock and event queue every simulated part shares.
#[derive(Default)]
pub struct Clock {
    pub now: Ps,
    events: BinaryHeap<Reverse<Ps>>,
    /// Bumped on every change of simulated state; a pass that leaves it alone is quiescent.
    pub changes: u64,
}

impl Clock {
    /// Ask to be polled again at `t`.
    pub fn at(&mut self, t: Ps) {
        self.events.push(Reverse(t));
        self.changes += 1;
    }

    /// Advance to the next event after now; false if there is none.
    fn advance(&mut self) -> bool {
        while let Some(Reverse(t)) = self.events.pop() {
            if t > self.now {
                self.now = t;
                return true;
            }
        }
        false
    }
}

pub type SharedClock = Rc<RefCell<Clock>>;

/// Resolves once virtual time reaches `until`.
pub struct Delay {
    clock: SharedClock,
    until: Ps,
}

impl Delay {
    pub fn new(clock: &SharedClock, until: Ps) -> Self {
        clock.borrow_mut().at(until);
        Self {
            clock: clock.clone(),
            until,
        }
    }
}

impl Future for Delay {
    type Output = ();
    fn poll(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<()> {
        if self.clock.borrow().now >= self.until {
            Poll::Ready(())
        } else {
            Poll::Pending
        }
    }
}

/// Resolves when `f` returns `Some` (re-checked on every poll).
pub struct PollFn<F>(pub F);

impl<T, F: FnMut() -> Option<T> + Unpin> Future for PollFn<F> {
    type Output = T;
    fn poll(mut self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<T> {
        match (self.0)() {
            Some(v) => Poll::Ready(v),
            None => Poll::Pending,
        }
    }
}

pub type Task<'a> = Pin<Box<dyn Future<Output = ()> + 'a>>;

/// Why a simulation stopped without finishing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExecError {
    /// Every task waits and no event is pending.
    Deadlock { at: Ps },
    /// Virtual time passed the limit.
    TimeLimit { at: Ps },
    /// The observer saw no progress for too long (e.g. frames lost in step with a protocol
    /// period, forever).
    Livelock { at: Ps },
}

impl ExecError {
    /// When the simulation stopped (s of virtual time).
    pub fn at_s(&self) -> f64 {
        let (ExecError::Deadlock { at } | ExecError::TimeLimit { at } | ExecError::Livelock { at }) =
            *self;
        at as f64 * 1e-12
    }
}

impl std::fmt::Display for ExecError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let at = self.at_s();
        match self {
            ExecError::Deadlock { .. } => {
                write!(f, "stalled at {at:.3} s of virtual time: no event pending")
            }
            ExecError::TimeLimit { .. } => {
                write!(f, "reached its time limit at {at:.3} s of virtual time")
            }
            ExecError::Livelock { .. } => write!(
                f,
                "stopped at {at:.3} s of virtual time: no node frame accepted in a long run of events (livelock)"
            ),
        }
    }
}

impl std::error::Error for ExecError {}

/// Poll `tasks` until `done()` holds. `after_pass` runs after each quiescent pass (to take
/// time stamps) and returns false to give up (no progress).
pub fn run(
    clock: &SharedClock,
    tasks: &mut [Option<Task<'_>>],
    limit: Ps,
    mut done: impl FnMut() -> bool,
    mut after_pass: impl FnMut(Ps) -> bool,
) -> Result<Ps, ExecError> {
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        loop {
            let before = clock.borrow().changes;
            for slot in tasks.iter_mut() {
                if let Some(t) = slot {
                    if t.as_mut().poll(&mut cx).is_ready() {
                        *slot = None;
                        clock.borrow_mut().changes += 1;
                    }
                }
            }
            if clock.borrow().changes == before {
                break;
            }
        }
        let now = clock.borrow().now;
        if !after_pass(now) {
            return Err(ExecError::Livelock { at: now });
        }
        if done() {
            return Ok(now);
        }
        if now > limit {
            return Err(ExecError::TimeLimit { at: now });
        }
        if !clock.borrow_mut().advance() {
            return Err(ExecError::Deadlock { at: now });
        }
    }
}

/// The RC's time base in virtual time (microseconds, rounded down), for node time-outs.
pub struct VirtualClock(pub SharedClock);

impl links_core::root::RootClock for VirtualClock {
    fn now_us(&self) -> u64 {
        self.0.borrow().now / 1_000_000
    }

    async fn at_us(&self, t: u64) {
        Delay::new(&self.0, t.saturating_mul(1_000_000)).await
    }
}
