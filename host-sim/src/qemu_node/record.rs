//! The link between the RC and a node: the record kinds (a kind byte, a little-endian u32
//! length, the bytes), how a node side waits or ended ([`NodeEnd`], [`Settled`], [`NodeSide`])
//! and the transcript's [`Event`]s.

// Record kinds on the link (one byte, then a little-endian u32 length, then the bytes).
/// NC -> RC: a frame posted to the TX bank.
pub const POST: u8 = b'P';
/// NC -> RC: the node waits in `recv`.
pub const WAIT: u8 = b'W';
/// NC -> RC: the node loop returned; a text report follows.
pub const END: u8 = b'E';
/// RC -> NC: the RC's half of an exchange.
pub const EXCHANGE: u8 = b'X';
/// RC -> NC: a broadcast frame.
pub const BROADCAST: u8 = b'B';

/// How the node ended: its report as `{:?}` text (compared between nodes) and, from the
/// firmware, the instruction counts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeEnd {
    /// `Ok(())` or the node's error, as `{:?}`.
    pub result: String,
    /// The node's [`NodeReport`] as `{:?}`.
    pub report: String,
    /// `key=value` pairs the firmware adds (instructions, link traffic).
    pub counters: Vec<(String, u64)>,
}

impl NodeEnd {
    pub fn counter(&self, key: &str) -> Option<u64> {
        self.counters
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| *v)
    }

    /// Parse the firmware's end record: a line of `key=value` counters, `result=...`,
    /// `report=...`.
    pub fn parse(text: &str) -> Result<NodeEnd, String> {
        let mut lines = text.lines();
        let mut counters = Vec::new();
        for kv in lines.next().unwrap_or("").split_whitespace() {
            let (k, v) = kv
                .split_once('=')
                .ok_or_else(|| format!("end record: `{kv}` is not key=value"))?;
            let v = v
                .parse()
                .map_err(|_| format!("end record: `{kv}` is not a number"))?;
            counters.push((k.to_string(), v));
        }
        let field = |line: Option<&str>, key: &str| {
            line.and_then(|l| l.strip_prefix(key))
                .map(str::to_string)
                .ok_or_else(|| format!("end record lacks `{key}`: {text:?}"))
        };
        let result = field(lines.next(), "result=")?;
        let report = field(lines.next(), "report=")?;
        Ok(NodeEnd {
            result,
            report,
            counters,
        })
    }
}

/// What a node did until it next waits for the link.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Settled {
    /// Waiting in `recv`, having posted these frames (at most one, the TX bank).
    Waiting { posted: Vec<Vec<u8>> },
    /// The node loop returned.
    Ended(NodeEnd),
}

/// One node computer as the lock-step RC sees it.
pub trait NodeSide {
    /// Let the node run until it waits for the link or ends.
    fn settle(&mut self) -> Result<Settled, String>;
    /// Hand the node a frame: the RC's half of an exchange, or a broadcast.
    fn deliver(&mut self, exchanged: bool, frame: &[u8]) -> Result<(), String>;
}

/// One transfer on the link, in order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Event {
    /// The node posted this frame.
    Up(Vec<u8>),
    /// The RC sent this frame (exchange reply or broadcast).
    Down { exchanged: bool, frame: Vec<u8> },
}
