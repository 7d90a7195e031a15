//! What the RC is generic over besides its buses: where scenes come from, its clock and
//! its work costs, where finished pixels go.

/// The scene image of each animation frame (the DM's output).
#[allow(async_fn_in_trait)]
pub trait SceneSource {
    fn scene(&self, frame: u16) -> Option<&[u8]>;
    /// Whether the DM has produced frame `frame`'s scene yet (it runs ahead of the RC, one
    /// frame at a time). Default: every scene exists from the start.
    fn produced(&self, _frame: u16) -> bool {
        true
    }
    /// Resolves once [`SceneSource::produced`] holds for `frame`. Implement it together
    /// with `produced`.
    async fn wait_produced(&self, _frame: u16) {}
    /// The CRC-32 of frame `frame`'s scene if the DM delivers it with the scene (the DM
    /// wrote the bytes; the RC then need not read all of them before the first chunk).
    /// Default: `None`, the RC computes it.
    fn scene_crc(&self, _frame: u16) -> Option<u32> {
        None
    }
}

/// CPU work the RC just did, reported to its clock (hardware: time passes by itself;
/// simulator: the RC's CPU is busy for the modelled time of the work).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RcWork<'a> {
    /// Composed one transfer's frame of `bytes` (choice of node, job table, postcard, CRC).
    Encode { bytes: usize },
    /// Checked, decoded and applied a node's frame (CRC, postcard, run-length expansion,
    /// job bookkeeping, the pixel sink): the frame as received.
    Decode { frame: &'a [u8] },
    /// CRC-32 of `bytes` bytes of a whole scene image (once per frame's scene).
    Checksum { bytes: usize },
}

/// The RC's time base, for node time-outs (hardware: a timer; simulator: virtual time).
#[allow(async_fn_in_trait)]
pub trait RootClock {
    /// Microseconds since the start.
    fn now_us(&self) -> u64;
    /// Resolves once `now_us() >= t`.
    async fn at_us(&self, t: u64);
    /// The RC's CPU just did `work`; resolves when that work would be finished. Default:
    /// at once (on hardware the work took its time already).
    async fn worked(&self, _work: RcWork<'_>) {}
}

/// A clock that never advances: time-outs never fire (an RC without a timer).
pub struct NoClock;

impl RootClock for NoClock {
    fn now_us(&self) -> u64 {
        0
    }
    async fn at_us(&self, _t: u64) {
        core::future::pending::<()>().await
    }
}

impl<T: AsRef<[u8]>> SceneSource for [T] {
    fn scene(&self, frame: u16) -> Option<&[u8]> {
        self.get(frame as usize).map(|s| s.as_ref())
    }
}

/// Where the RC delivers accepted pixel runs (frame memory, serial readback). With a
/// snooping frame memory on the bus the RC needs none: use `()`.
pub trait PixelSink {
    fn pixels(&mut self, frame: u16, y: u16, x: u16, rgb: &[u8]);
}

impl PixelSink for () {
    fn pixels(&mut self, _: u16, _: u16, _: u16, _: &[u8]) {}
}
