//! What a lock-step run must show: the simulator's frame ([`simulated_frame`]), the
//! outcome's checks ([`check_outcome`]), two transcripts compared ([`compare_transcripts`]),
//! and frames damaged on purpose ([`Corrupt`]).

use super::*;
use crate::cluster::{render_cluster, SimConfig};
use crate::frame::{render_single, Precision};
use links_core::image::SceneView;
use links_core::num::Storage;
use links_core::wire::{self, Down, Up};
use std::fmt;

/// The simulator's single-node render of `image` (`render_cluster` with one node): the
/// frame the lock-step RC must assemble.
pub fn simulated_frame(image: &[u8]) -> Result<Vec<u8>, String> {
    let cfg = SimConfig {
        nodes: 1,
        buses: 1,
        ..SimConfig::default()
    };
    let mut r = render_cluster(image, &cfg).map_err(|e| e.to_string())?;
    r.report
        .frames
        .pop()
        .ok_or_else(|| "the simulator kept no frame".to_string())
}

/// The frame [`simulated_frame`] gave for `image` must equal host-sim's single-node render
/// (`links render` without `--nodes`) in the kernel the image's storage picks: f32, or
/// Q16.16 for the DM's fixed-point image. Returns that precision.
pub fn check_single_render(image: &[u8], cluster: &[u8]) -> Result<Precision, String> {
    let storage = SceneView::new(image).map_err(|e| e.to_string())?.storage();
    let precision = match storage {
        Storage::F32 => Precision::F32,
        Storage::Q16_16 => Precision::Fixed,
    };
    let single = render_single(image, precision, 1, &|| {}).map_err(|e| e.to_string())?;
    if single.rgb != cluster {
        let p = (0..single.rgb.len().min(cluster.len()) / 3)
            .find(|&p| single.rgb[3 * p..3 * p + 3] != cluster[3 * p..3 * p + 3]);
        return Err(format!(
            "the simulator's single-node cluster frame differs from the {} single render (first differing pixel index {p:?})",
            precision.name()
        ));
    }
    Ok(precision)
}

/// Every check of one run against the expected frame; the first failure, or Ok.
/// `corrupted`: RC -> NC messages damaged on purpose ([`Corrupt`]): the node must count
/// exactly these as bad, and the RC may then see re-sent duplicates (a lost acknowledgement),
/// nothing else.
pub fn check_outcome(o: &RcOutcome, want: &[u8], corrupted: u32) -> Result<(), String> {
    let r = &o.root;
    let dup = if corrupted == 0 { r.out_of_order } else { 0 };
    if r.bad_messages > 0 || r.rejected > 0 || dup > 0 {
        return Err(format!(
            "the RC could not use every node frame: {} failed CRC/decoding, {} rejected, {} out of order",
            r.bad_messages, r.rejected, r.out_of_order
        ));
    }
    if o.end.result != "Ok(())" {
        return Err(format!("the node loop failed: {}", o.end.result));
    }
    for want in [format!("bad_messages: {corrupted},"), "bad_jobs: 0,".into()] {
        if !o.end.report.contains(&want) {
            return Err(format!(
                "the node's count of bad input is wrong (want {want}): {}",
                o.end.report
            ));
        }
    }
    if o.stray_runs > 0 {
        return Err(format!("{} pixel runs outside the frame", o.stray_runs));
    }
    if let Some(i) = o.writes.iter().position(|&w| w != 1) {
        return Err(format!(
            "pixel ({}, {}) was written {} times (every pixel exactly once)",
            i % o.width as usize,
            i / o.width as usize,
            o.writes[i]
        ));
    }
    if want.len() != o.frame.len() {
        return Err(format!(
            "the reference frame has {} bytes, the RC's {}",
            want.len(),
            o.frame.len()
        ));
    }
    let diff: Vec<usize> = (0..o.frame.len() / 3)
        .filter(|&p| o.frame[3 * p..3 * p + 3] != want[3 * p..3 * p + 3])
        .collect();
    if let Some(&p) = diff.first() {
        let w = o.width as usize;
        return Err(format!(
            "{} of {} pixels differ from the simulator's render; the first at ({}, {}): {:?}, want {:?}",
            diff.len(),
            o.frame.len() / 3,
            p % w,
            p / w,
            &o.frame[3 * p..3 * p + 3],
            &want[3 * p..3 * p + 3]
        ));
    }
    Ok(())
}

fn describe(e: &Event) -> String {
    match e {
        Event::Up(f) => match wire::decode::<Up>(f) {
            Ok(env) => {
                let msg = match env.msg {
                    Up::Pixels {
                        job, y, x, rgb, done, ..
                    } => format!("Pixels {{ job: {job}, y: {y}, x: {x}, {} pixels, done: {done} }}", rgb.len() / 3),
                    Up::PixelsRle {
                        job, y, x, len, data, done, ..
                    } => format!(
                        "PixelsRle {{ job: {job}, y: {y}, x: {x}, {len} pixels in {} bytes, done: {done} }}",
                        data.len()
                    ),
                    m => format!("{m:?}"),
                };
                format!(
                    "NC -> RC {} bytes, seq {} ack {}: {msg}",
                    f.len(),
                    env.seq,
                    env.ack
                )
            }
            Err(err) => format!("NC -> RC {} bytes: {err}", f.len()),
        },
        Event::Down { exchanged, frame } => {
            let how = if *exchanged { "exchange" } else { "broadcast" };
            match wire::decode::<Down>(frame) {
                Ok(env) => {
                    let msg = match env.msg {
                        Down::Scene {
                            frame: f,
                            offset,
                            total,
                            data,
                            ..
                        } => format!(
                            "Scene {{ frame: {f}, offset: {offset}, total: {total}, {} bytes }}",
                            data.len()
                        ),
                        m => format!("{m:?}"),
                    };
                    format!(
                        "RC -> NC {how} {} bytes, ack {}: {msg}",
                        frame.len(),
                        env.ack
                    )
                }
                Err(err) => format!("RC -> NC {how} {} bytes: {err}", frame.len()),
            }
        }
    }
}

/// The two runs' transfers must be the same bytes in the same order, and the nodes' reports
/// equal.
pub fn compare_transcripts(got: &RcOutcome, want: &RcOutcome) -> Result<(), String> {
    if let Some(i) = (0..got.transcript.len().max(want.transcript.len()))
        .find(|&i| got.transcript.get(i) != want.transcript.get(i))
    {
        let show = |e: Option<&Event>| e.map_or("nothing".to_string(), describe);
        return Err(format!(
            "transfer {i} of {} differs from the host node's:\n  got  {}\n  want {}",
            want.transcript.len(),
            show(got.transcript.get(i)),
            show(want.transcript.get(i))
        ));
    }
    if got.end.report != want.end.report {
        return Err(format!(
            "the node reports differ:\n  got  {}\n  want {}",
            got.end.report, want.end.report
        ));
    }
    Ok(())
}

/// A node whose link damages some of the RC's frames on the way in: one bit flipped in the
/// middle of deliveries number `at` (0-based, broadcasts and exchange replies counted
/// together), as a bus error would. The transcript keeps what the RC sent.
pub struct Corrupt<N> {
    pub inner: N,
    pub at: Vec<usize>,
    delivered: usize,
    /// What each damaged frame was, in order.
    pub hits: Vec<String>,
}

impl<N> Corrupt<N> {
    pub fn new(inner: N, at: Vec<usize>) -> Self {
        Self {
            inner,
            at,
            delivered: 0,
            hits: Vec::new(),
        }
    }
}

impl<N: NodeSide> NodeSide for Corrupt<N> {
    fn settle(&mut self) -> Result<Settled, String> {
        self.inner.settle()
    }

    fn deliver(&mut self, exchanged: bool, frame: &[u8]) -> Result<(), String> {
        let i = self.delivered;
        self.delivered += 1;
        if !self.at.contains(&i) || frame.is_empty() {
            return self.inner.deliver(exchanged, frame);
        }
        self.hits.push(format!(
            "delivery {i}: {}",
            describe(&Event::Down {
                exchanged,
                frame: frame.to_vec()
            })
        ));
        let mut bad = frame.to_vec();
        bad[frame.len() / 2] ^= 0x10;
        self.inner.deliver(exchanged, &bad)
    }
}

impl fmt::Display for Event {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&describe(self))
    }
}
