//! The backup line's conversations over a UART port, generic over the MCU: the node's serve
//! loop and the RC's roll call. The firmware supplies a [`LinePort`] (USART2 with DMA and
//! the RS-485 driver-enable pin); the host tests a fake one.

use super::{BackupError, BackupNode, FrameReader, RollCall, RollCallStep, MAX_FRAME};
use core::fmt;

/// What went wrong on the UART itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LineError {
    /// A framing, noise, overrun or parity error the UART reported.
    Uart,
    /// A frame could not be built or read.
    Frame(BackupError),
}

impl fmt::Display for LineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LineError::Uart => write!(f, "backup line UART error"),
            LineError::Frame(e) => write!(f, "{e}"),
        }
    }
}

impl core::error::Error for LineError {}

impl From<BackupError> for LineError {
    fn from(e: BackupError) -> Self {
        LineError::Frame(e)
    }
}

/// One end of the RS-485 line.
#[allow(async_fn_in_trait)]
pub trait LinePort {
    /// Send one frame: driver enabled, every byte out, the last stop bit gone, driver off.
    async fn send(&mut self, frame: &[u8]) -> Result<(), LineError>;
    /// Receive bytes until the line goes idle after at least one, or `timeout_us` passes
    /// with none (`None`: wait for ever). Returns the bytes received (0: timed out).
    async fn receive(
        &mut self,
        buf: &mut [u8],
        timeout_us: Option<u32>,
    ) -> Result<usize, LineError>;
}

/// The node's side: take the next burst of bytes, act on every frame in it, send the
/// answers. Returns the frames handled (the firmware calls it in a loop; a UART error or a
/// bad frame is counted by the node and the loop goes on).
pub async fn serve<P: LinePort>(
    port: &mut P,
    node: &mut BackupNode<'_>,
    reader: &mut FrameReader,
) -> Result<usize, LineError> {
    serve_with(port, reader, |frame, reply| node.handle(frame, reply)).await
}

/// [`serve`] with the node reached through `handle` (firmware that shares the node with its
/// renderer locks it there, for one frame at a time).
pub async fn serve_with<P: LinePort, H>(
    port: &mut P,
    reader: &mut FrameReader,
    mut handle: H,
) -> Result<usize, LineError>
where
    H: FnMut(&[u8], &mut [u8]) -> Result<Option<usize>, BackupError>,
{
    let mut rx = [0u8; MAX_FRAME];
    let n = port.receive(&mut rx, None).await?;
    let mut handled = 0;
    let mut reply = [0u8; MAX_FRAME];
    for &b in &rx[..n.min(MAX_FRAME)] {
        let Some(len) = reader.push(b) else { continue };
        handled += 1;
        if let Ok(Some(r)) = handle(reader.frame(len), &mut reply) {
            port.send(&reply[..r]).await?;
        }
    }
    Ok(handled)
}

/// The RC's side: a roll call of nodes 1..=`nodes`, each given `timeout_us` to answer.
pub async fn call_roll<P: LinePort>(
    port: &mut P,
    nodes: u8,
    timeout_us: u32,
) -> Result<RollCall, LineError> {
    let mut rc = RollCall::new(nodes);
    let mut req = [0u8; MAX_FRAME];
    let mut rx = [0u8; MAX_FRAME];
    while let RollCallStep::Ask(_) = rc.step() {
        let n = rc.request(&mut req)?;
        port.send(&req[..n]).await?;
        let got = match port.receive(&mut rx, Some(timeout_us)).await {
            Ok(g) => g,
            Err(LineError::Uart) => 0,
            Err(e) => return Err(e),
        };
        // A garbled answer counts the node absent.
        let _ = rc.answered((got > 0).then(|| &rx[..got.min(MAX_FRAME)]));
    }
    Ok(rc)
}
