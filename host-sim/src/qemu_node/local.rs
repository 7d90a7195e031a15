//! The host's node: the same `run_node` compiled for the host, polled in lock step
//! ([`LocalNode`]), with the kernels of the firmware it stands for (f32, Q16.16 or both).

use super::*;
use links_core::link::{Incoming, LinkError, NodeLink};
use links_core::node::{
    run_node, Kernels, NodeConfig, NodeError, NodeReport, RealTime, RunRenderer, Tracing,
    TracingByImage,
};
use links_core::num::Fx;
use links_core::wire::MAX_SCENE;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::future::Future;
use std::pin::Pin;
use std::rc::Rc;
use std::task::{Context, Poll, Waker};

#[derive(Default)]
struct LocalShared {
    inbox: VecDeque<(bool, Vec<u8>)>,
    posted: Vec<Vec<u8>>,
    tx_full: bool,
}

struct LocalLink(Rc<RefCell<LocalShared>>);

impl NodeLink for LocalLink {
    fn post(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        let mut s = self.0.borrow_mut();
        if s.tx_full {
            return Err(LinkError::Busy);
        }
        s.tx_full = true;
        s.posted.push(frame.to_vec());
        Ok(())
    }

    async fn recv(&mut self, rx: &mut [u8]) -> Result<Incoming, LinkError> {
        let (exchanged, frame) =
            std::future::poll_fn(|_| match self.0.borrow_mut().inbox.pop_front() {
                Some(f) => Poll::Ready(f),
                None => Poll::Pending,
            })
            .await;
        let len = frame.len();
        let max = rx.len() as u32;
        rx.get_mut(..len)
            .ok_or(LinkError::TooLong {
                len: len as u32,
                max,
            })?
            .copy_from_slice(&frame);
        Ok(if exchanged {
            self.0.borrow_mut().tx_full = false;
            Incoming::Exchanged { len }
        } else {
            Incoming::Broadcast { len }
        })
    }
}

type NodeFuture = Pin<Box<dyn Future<Output = (Result<(), NodeError>, NodeReport)>>>;

/// `run_node` compiled for the host, with 128 KB banks as the firmware's.
pub struct LocalNode {
    shared: Rc<RefCell<LocalShared>>,
    fut: NodeFuture,
    end: Option<NodeEnd>,
}

impl Default for LocalNode {
    fn default() -> Self {
        Self::new()
    }
}

impl LocalNode {
    /// A node with the f32 kernel (the Cortex-M4F firmware's).
    pub fn new() -> Self {
        Self::with_kernels(Kernels::F32)
    }

    /// A node carrying `kernels`, as the firmware built with the same `kernel-*` features:
    /// [`Tracing<f32>`], [`Tracing<Fx>`] or [`TracingByImage`].
    pub fn with_kernels(kernels: Kernels) -> Self {
        match kernels {
            Kernels::F32 => Self::with_renderer(Tracing::<f32>::new()),
            Kernels::Fixed => Self::with_renderer(Tracing::<Fx>::new()),
            Kernels::Both => Self::with_renderer(TracingByImage::default()),
        }
    }

    fn with_renderer<R: RunRenderer + 'static>(mut renderer: R) -> Self {
        let shared = Rc::new(RefCell::new(LocalShared::default()));
        let mut link = LocalLink(shared.clone());
        let fut: NodeFuture = Box::pin(async move {
            let mut b0 = vec![0u8; MAX_SCENE];
            let mut b1 = vec![0u8; MAX_SCENE];
            let mut report = NodeReport::default();
            let r = run_node(
                NodeConfig::default(),
                &mut link,
                &mut RealTime,
                &mut renderer,
                [b0.as_mut_slice(), b1.as_mut_slice()],
                &mut report,
            )
            .await;
            (r, report)
        });
        Self {
            shared,
            fut,
            end: None,
        }
    }
}

impl NodeSide for LocalNode {
    fn settle(&mut self) -> Result<Settled, String> {
        if let Some(e) = &self.end {
            return Ok(Settled::Ended(e.clone()));
        }
        match self
            .fut
            .as_mut()
            .poll(&mut Context::from_waker(Waker::noop()))
        {
            Poll::Ready((r, report)) => {
                let end = NodeEnd {
                    result: format!("{r:?}"),
                    report: format!("{report:?}"),
                    counters: Vec::new(),
                };
                self.end = Some(end.clone());
                Ok(Settled::Ended(end))
            }
            Poll::Pending => Ok(Settled::Waiting {
                posted: std::mem::take(&mut self.shared.borrow_mut().posted),
            }),
        }
    }

    fn deliver(&mut self, exchanged: bool, frame: &[u8]) -> Result<(), String> {
        self.shared
            .borrow_mut()
            .inbox
            .push_back((exchanged, frame.to_vec()));
        Ok(())
    }
}
