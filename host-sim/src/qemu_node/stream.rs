//! The QEMU node: the firmware's `run_node` on Cortex-M (M4F or M3) under QEMU, speaking
//! records over two streams (the FIFOs it opens through semihosting): [`StreamNode`],
//! [`QemuNode`].

use super::*;
use links_core::wire::MAX_SCENE;
use std::io::{Read, Write};

/// The firmware's end of the link: records over a byte stream each way (the FIFOs the
/// firmware opens through semihosting).
pub struct StreamNode<R, W> {
    up: R,
    pub(super) down: W,
    end: Option<NodeEnd>,
}

impl<R: Read, W: Write> StreamNode<R, W> {
    /// `up`: what the node writes (NC -> RC); `down`: what it reads.
    pub fn new(up: R, down: W) -> Self {
        Self {
            up,
            down,
            end: None,
        }
    }

    fn record(&mut self) -> Result<(u8, Vec<u8>), String> {
        let gone =
            |e: std::io::Error| format!("the node's link closed ({e}): QEMU exited or crashed");
        let mut head = [0u8; 5];
        self.up.read_exact(&mut head).map_err(gone)?;
        let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
        if len > MAX_SCENE {
            return Err(format!(
                "record of {len} bytes from the node: the link is out of step"
            ));
        }
        let mut body = vec![0u8; len];
        self.up.read_exact(&mut body).map_err(gone)?;
        Ok((head[0], body))
    }
}

/// The QEMU firmware's link (FIFO files).
pub type QemuNode = StreamNode<std::io::BufReader<std::fs::File>, std::fs::File>;

impl<R: Read, W: Write> NodeSide for StreamNode<R, W> {
    fn settle(&mut self) -> Result<Settled, String> {
        if let Some(e) = &self.end {
            return Ok(Settled::Ended(e.clone()));
        }
        let mut posted = Vec::new();
        loop {
            let (kind, body) = self.record()?;
            match kind {
                record::POST => posted.push(body),
                record::WAIT => return Ok(Settled::Waiting { posted }),
                record::END => {
                    if !posted.is_empty() {
                        return Err("the node ended with a frame just posted".into());
                    }
                    let text = String::from_utf8(body)
                        .map_err(|_| "the node's end record is not UTF-8".to_string())?;
                    let end = NodeEnd::parse(&text)?;
                    self.end = Some(end.clone());
                    return Ok(Settled::Ended(end));
                }
                k => return Err(format!("unknown record kind {k:#04x} from the node")),
            }
        }
    }

    fn deliver(&mut self, exchanged: bool, frame: &[u8]) -> Result<(), String> {
        let kind = if exchanged {
            record::EXCHANGE
        } else {
            record::BROADCAST
        };
        let mut rec = Vec::with_capacity(5 + frame.len());
        rec.push(kind);
        rec.extend_from_slice(&(frame.len() as u32).to_le_bytes());
        rec.extend_from_slice(frame);
        self.down
            .write_all(&rec)
            .and_then(|_| self.down.flush())
            .map_err(|e| format!("cannot write to the node's link ({e}): QEMU exited or crashed"))
    }
}
