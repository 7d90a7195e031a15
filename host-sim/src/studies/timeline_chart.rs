//! The picture of one cluster frame (`links render --nodes N --timeline t.svg`): with the
//! firmware's relay code a row for the root's link to its relays (exchanges blue), a row per
//! bus (its transfers, coloured by the node exchanged with; broadcasts orange), a row for
//! the RC's CPU (the root's, under the firmware's relay code; else the sum of the leaf
//! relays' under a relay tree), a row per node (computing in the node's colour, waiting grey, its exchanges
//! on the wire as a black strip along the row's foot), a time axis in ms of virtual time, and
//! a map of the frame coloured by the node that rendered each pixel.
//!
//! Plain SVG written as text (no fonts needed to write it; the viewer's sans-serif draws the
//! labels).

use crate::sim::cluster::exec::Ps;
use crate::sim::cluster::timeline::{Interval, Timeline, NO_NODE};
use crate::sim::cluster::SimReport;
use std::fmt::Write as _;

const WIDTH: f64 = 1200.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 20.0;
const PLOT: f64 = WIDTH - LEFT - RIGHT;
const BUS_ROW: f64 = 14.0;
const GAP: f64 = 4.0;
const MAP_SIDE: f64 = 320.0;
const WAITING: &str = "#e4e4e4";
const BROADCAST: &str = "#f28e2b";
const RC_WORK: &str = "#7b4fa0";
const WIRE: &str = "#111111";
/// An exchange on the root's link to its relays (the firmware's relay code).
const ROOT_LINK: &str = "#2b5fa8";

/// Node `i`'s colour: hues a golden angle apart, so neighbours differ.
pub fn node_colour(i: u16) -> String {
    let h = (i as f64 * 137.508) % 360.0;
    let (s, l) = (0.62, if i.is_multiple_of(2) { 0.48 } else { 0.62 });
    let c = (1.0 - (2.0 * l - 1.0_f64).abs()) * s;
    let x = c * (1.0 - ((h / 60.0) % 2.0 - 1.0).abs());
    let m = l - c / 2.0;
    let (r, g, b) = match (h / 60.0) as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let byte = |v: f64| ((v + m) * 255.0).round().clamp(0.0, 255.0) as u8;
    format!("#{:02x}{:02x}{:02x}", byte(r), byte(g), byte(b))
}

/// Maps virtual time onto the plot's x axis.
struct Axis {
    end: Ps,
}

impl Axis {
    fn x(&self, t: Ps) -> f64 {
        LEFT + PLOT * (t.min(self.end) as f64 / self.end.max(1) as f64)
    }

    /// A rectangle for `iv` on a row at `y`, `h` high (at least a hair wide).
    fn rect(&self, out: &mut String, iv: &Interval, y: f64, h: f64, fill: &str) {
        let (x0, x1) = (self.x(iv.start), self.x(iv.end));
        let _ = writeln!(
            out,
            r#"<rect x="{x0:.2}" y="{y:.2}" width="{:.2}" height="{h:.2}" fill="{fill}"/>"#,
            (x1 - x0).max(0.15)
        );
    }

    /// Tick step in ms: 1, 2 or 5 x 10^k, about ten ticks over the axis.
    fn step_ms(&self) -> f64 {
        let span = self.end as f64 * 1e-9;
        let raw = (span / 10.0).max(1e-6);
        let p = 10f64.powf(raw.log10().floor());
        [1.0, 2.0, 5.0, 10.0]
            .into_iter()
            .map(|k| k * p)
            .find(|&s| s >= raw)
            .unwrap_or(10.0 * p)
    }

    /// Vertical grid lines from `top` to `bottom`, labelled in ms below.
    fn draw(&self, out: &mut String, top: f64, bottom: f64) {
        let step = self.step_ms();
        let span_ms = self.end as f64 * 1e-9;
        let mut k = 0u32;
        while (k as f64 * step) <= span_ms + 1e-12 && k <= 200 {
            let ms = k as f64 * step;
            let x = LEFT + PLOT * ms / span_ms.max(1e-12);
            let _ = writeln!(
                out,
                r##"<line x1="{x:.2}" y1="{top:.2}" x2="{x:.2}" y2="{bottom:.2}" stroke="#999" stroke-width="0.5" stroke-dasharray="2,3"/>"##
            );
            let _ = writeln!(
                out,
                r#"<text x="{x:.2}" y="{:.2}" font-size="10" text-anchor="middle">{}</text>"#,
                bottom + 12.0,
                trim_ms(ms)
            );
            k += 1;
        }
        let _ = writeln!(
            out,
            r#"<text x="{:.2}" y="{:.2}" font-size="11" text-anchor="middle">virtual time (ms)</text>"#,
            LEFT + PLOT / 2.0,
            bottom + 26.0
        );
    }
}

/// `ms` without trailing zeros.
fn trim_ms(ms: f64) -> String {
    let s = format!("{ms:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Text safe inside an SVG element.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Row label at the left edge.
fn label(out: &mut String, y: f64, h: f64, text: &str, size: f64) {
    let _ = writeln!(
        out,
        r#"<text x="{:.2}" y="{:.2}" font-size="{size:.1}" text-anchor="end">{}</text>"#,
        LEFT - 4.0,
        y + h / 2.0 + size * 0.35,
        escape(text)
    );
}

/// The legend: one swatch per kind of interval.
fn legend(out: &mut String, t: &Timeline, y: f64) {
    let mut items = vec![
        (node_colour(0), "computing (the node's colour)"),
        (WAITING.to_string(), "waiting"),
        (WIRE.to_string(), "the node's exchange on the wire"),
        (BROADCAST.to_string(), "broadcast"),
        (RC_WORK.to_string(), "RC CPU busy"),
    ];
    if !(t.root_links.is_empty() && t.mid_links.is_empty()) {
        items.push((ROOT_LINK.to_string(), "exchange between RCs"));
    }
    let mut x = LEFT;
    for (fill, text) in items {
        let _ = writeln!(
            out,
            r#"<rect x="{x:.1}" y="{:.1}" width="12" height="10" fill="{fill}"/><text x="{:.1}" y="{:.1}" font-size="11">{text}</text>"#,
            y - 9.0,
            x + 16.0,
            y
        );
        x += 24.0 + 6.2 * text.len() as f64;
    }
}

/// The bus rows and the RC row (the links between RCs first, if logged: each root link,
/// then each middle relay's bus); returns the y below them.
fn bus_rows(out: &mut String, t: &Timeline, axis: &Axis, mut y: f64) -> f64 {
    let links = t
        .root_links
        .iter()
        .enumerate()
        .map(|(k, r)| ("root link", k, r));
    let mids = t
        .mid_links
        .iter()
        .enumerate()
        .map(|(k, r)| ("mid relay", k, r));
    for (name, k, row) in links.chain(mids) {
        label(out, y, BUS_ROW, &format!("{name} {k}"), 10.0);
        for tr in row {
            let fill = if tr.node.is_some() {
                ROOT_LINK
            } else {
                BROADCAST
            };
            axis.rect(out, &tr.at, y, BUS_ROW, fill);
        }
        y += BUS_ROW + 2.0;
    }
    for (b, row) in t.bus.iter().enumerate() {
        label(out, y, BUS_ROW, &format!("bus {b}"), 10.0);
        for tr in row {
            let fill = tr.node.map_or(BROADCAST.to_string(), node_colour);
            axis.rect(out, &tr.at, y, BUS_ROW, &fill);
        }
        y += BUS_ROW + 2.0;
    }
    label(out, y, BUS_ROW, "RC CPU", 10.0);
    for iv in &t.rc {
        axis.rect(out, iv, y, BUS_ROW, RC_WORK);
    }
    y + BUS_ROW + GAP
}

/// One row per node; returns the y below them.
fn node_rows(out: &mut String, t: &Timeline, axis: &Axis, mut y: f64) -> f64 {
    let n = t.compute.len().max(1);
    let h = (640.0 / n as f64).clamp(2.5, 16.0);
    let every = (9.0 / h).ceil().max(1.0) as usize;
    let whole = Interval {
        start: 0,
        end: axis.end,
    };
    for (i, (compute, wire)) in t.compute.iter().zip(&t.exchanges).enumerate() {
        if i % every == 0 {
            label(out, y, h, &format!("node {i}"), (h * 0.8).clamp(7.0, 10.0));
        }
        axis.rect(out, &whole, y, h * 0.95, WAITING);
        let colour = node_colour(i as u16);
        for iv in compute {
            axis.rect(out, iv, y, h * 0.95, &colour);
        }
        for iv in wire {
            axis.rect(out, iv, y + h * 0.6, h * 0.35, WIRE);
        }
        y += h;
    }
    y
}

/// The frame coloured by the node that rendered each pixel (runs of one owner along a row
/// are one rectangle); returns the y below it.
fn pixel_map(out: &mut String, t: &Timeline, x0: f64, y0: f64) -> f64 {
    let (w, h) = (t.width as usize, t.height as usize);
    if w == 0 || h == 0 {
        return y0;
    }
    let scale = (MAP_SIDE / w.max(h) as f64).min(4.0);
    let _ = writeln!(
        out,
        r#"<g shape-rendering="crispEdges"><rect x="{x0:.1}" y="{y0:.1}" width="{:.2}" height="{:.2}" fill="white" stroke="black" stroke-width="0.5"/>"#,
        w as f64 * scale,
        h as f64 * scale
    );
    for (y, row) in t.owner.chunks(w).enumerate() {
        let mut x = 0;
        while x < w {
            let who = row[x];
            let run = row[x..].iter().take_while(|&&o| o == who).count();
            if who != NO_NODE {
                let _ = writeln!(
                    out,
                    r#"<rect x="{:.2}" y="{:.2}" width="{:.2}" height="{:.2}" fill="{}"/>"#,
                    x0 + x as f64 * scale,
                    y0 + y as f64 * scale,
                    run as f64 * scale,
                    scale,
                    node_colour(who)
                );
            }
            x += run;
        }
    }
    out.push_str("</g>\n");
    y0 + h as f64 * scale
}

/// The whole picture as SVG text; `title` names the scene and the board profile.
pub fn timeline_svg(t: &Timeline, r: &SimReport, title: &str) -> String {
    let frame_end = (r.time_s * 1e12).round() as Ps;
    let axis = Axis {
        end: frame_end.max(1),
    };
    let mut body = String::new();
    let _ = writeln!(
        body,
        r#"<text x="{LEFT}" y="20" font-size="14" font-weight="bold">{}</text>"#,
        escape(title)
    );
    let busy: f64 = r.node_compute_s.iter().sum();
    let time = r.time_s.max(1e-18);
    // Under the firmware's relay code the RC row is the root's CPU, beside its link.
    let rc = match (&r.relayed, &r.tree) {
        (Some(_), Some(tree)) => format!(
            "root CPU busy {:.1}%, root link busy {:.1}%",
            100.0 * tree.root_busy_s / time,
            100.0 * tree.root_link_busy_s() / time
        ),
        _ => format!("RC busy {:.1}%", 100.0 * r.rc_busy_s / time),
    };
    let _ = writeln!(
        body,
        r#"<text x="{LEFT}" y="38" font-size="12">{} nodes, {}x{}, frame {:.3} ms virtual; nodes computing {:.1}% of node-time, bus busy {:.1}%, {rc}{}</text>"#,
        r.nodes,
        r.width,
        r.height,
        r.time_s * 1e3,
        100.0 * busy / (r.nodes as f64 * time),
        100.0 * r.bus_utilisation(),
        if t.complete() {
            String::new()
        } else {
            format!(" (log full: {} intervals not drawn)", t.dropped())
        }
    );
    legend(&mut body, t, 58.0);
    let top = 70.0;
    let y = bus_rows(&mut body, t, &axis, top);
    let bottom = node_rows(&mut body, t, &axis, y);
    axis.draw(&mut body, top, bottom);
    let map_y = bottom + 46.0;
    let _ = writeln!(
        body,
        r#"<text x="{LEFT}" y="{:.1}" font-size="12">which node rendered each pixel (the node colours of the rows above)</text>"#,
        map_y - 6.0
    );
    let end = pixel_map(&mut body, t, LEFT, map_y);
    let height = end + 20.0;
    format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{WIDTH}\" height=\"{height:.0}\" viewBox=\"0 0 {WIDTH} {height:.0}\" font-family=\"sans-serif\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n{body}</svg>\n"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_colours_are_hex_and_neighbours_differ() {
        let c: Vec<String> = (0..256).map(node_colour).collect();
        assert!(c.iter().all(|s| s.len() == 7 && s.starts_with('#')));
        assert!(c.windows(2).all(|w| w[0] != w[1]));
        assert_eq!(node_colour(0), "#c62f2f");
    }

    #[test]
    fn the_axis_ticks_are_round_and_cover_the_frame() {
        // 0.5234 s: a tenth is 52.34 ms, the next round step 100 ms (six ticks).
        let a = Axis {
            end: 523_400_000_000,
        };
        assert_eq!(a.step_ms(), 100.0);
        assert_eq!(a.x(0), LEFT);
        assert!((a.x(523_400_000_000) - (LEFT + PLOT)).abs() < 1e-9);
        assert_eq!(trim_ms(2.5), "2.5");
        assert_eq!(trim_ms(100.0), "100");
    }
}
