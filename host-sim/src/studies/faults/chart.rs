//! The fault sweep's chart: three panels (kill moment, bit-error rate, fraction killed), as
//! SVG or PNG.

use super::{mean, FaultSweep};
use crate::sim::cluster::SimError;
use crate::studies::chart::draw_legend;
use crate::studies::cluster_sweep::chart_err;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// The series colours, in order.
const COLOURS: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
];

/// Size of the chart (pixels).
const CHART: (u32, u32) = (820, 1500);

fn draw_all<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    s: &FaultSweep,
) -> Result<(), SimError>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(chart_err)?;
    let panels = root.split_evenly((3, 1));
    draw_kills(&panels[0], s)?;
    draw_bers(&panels[1], s)?;
    draw_fractions(&panels[2], s)?;
    root.present().map_err(chart_err)
}

/// The three panels: kill moment, bit-error rate, fraction killed. An SVG file.
pub fn write_faults_chart(path: &Path, s: &FaultSweep) -> Result<(), SimError> {
    crate::studies::chart::ensure_font().map_err(chart_err)?;
    draw_all(SVGBackend::new(path, CHART).into_drawing_area(), s)
}

/// The same chart as a PNG.
pub fn faults_png(s: &FaultSweep) -> Result<Vec<u8>, SimError> {
    crate::studies::chart::ensure_font().map_err(chart_err)?;
    let (w, h) = CHART;
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    draw_all(
        BitMapBackend::with_buffer(&mut rgb, CHART).into_drawing_area(),
        s,
    )?;
    crate::sim::single::encode_png(w, h, &rgb).map_err(chart_err)
}

/// A panel over a fraction (x from 0 to 1) against frame time (0 to `ymax`), with its
/// caption and axes drawn.
fn linear_panel<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: String,
    ymax: f64,
    x_desc: &str,
) -> Result<ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>, SimError>
where
    DB::ErrorType: 'static,
{
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 18))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0f64..1.0, 0f64..ymax)
        .map_err(chart_err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc("frame time, s (virtual)")
        .draw()
        .map_err(chart_err)?;
    Ok(chart)
}

fn draw_kills<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    s: &FaultSweep,
) -> Result<(), SimError>
where
    DB::ErrorType: 'static,
{
    let tmax = s
        .kills
        .iter()
        .map(|k| k.time_s.max(k.bound_s))
        .fold(0.0, f64::max);
    let mut chart = linear_panel(
        area,
        format!(
            "node {} of {} killed at a moment of the frame (τ = {} s, board {})",
            s.victim, s.nodes, s.timeout_s, s.board
        ),
        tmax * 1.4,
        "moment of death (fraction of the fault-free frame)",
    )?;
    for (i, c) in s.clean.iter().enumerate() {
        let col = COLOURS[i % COLOURS.len()];
        let pts: Vec<(f64, f64)> = s
            .kills
            .iter()
            .filter(|k| k.policy == c.policy)
            .map(|k| (k.at_frac, k.time_s))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), col.stroke_width(2)))
            .map_err(chart_err)?
            .label(c.policy.clone())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col.stroke_width(2)));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 2, col.filled())))
            .map_err(chart_err)?;
        let bound = c.time_s + 2.0 * s.timeout_s + c.victim_work_s;
        chart
            .draw_series(DashedLineSeries::new(
                [(0.0, bound), (1.0, bound)],
                6,
                4,
                col.stroke_width(1),
            ))
            .map_err(chart_err)?;
    }
    chart
        .draw_series(std::iter::once(PathElement::new(
            [(0.0, 0.0), (0.0, 0.0)],
            BLACK,
        )))
        .map_err(chart_err)?
        .label("dashed: each policy's bound, clean + 2τ + W")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.6)));
    draw_legend(&mut chart, SeriesLabelPosition::UpperLeft).map_err(chart_err)
}

fn draw_bers<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    s: &FaultSweep,
) -> Result<(), SimError>
where
    DB::ErrorType: 'static,
{
    let bmin = s
        .bers
        .iter()
        .map(|b| b.ber)
        .fold(f64::MAX, f64::min)
        .min(1e-6);
    let bmax = s
        .bers
        .iter()
        .map(|b| b.ber)
        .fold(0.0, f64::max)
        .max(bmin * 10.0);
    let tmax = s.bers.iter().map(|b| b.time_s).fold(s.clean_s, f64::max);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "bit errors ({} nodes, decreasing, board {})",
                s.nodes, s.board
            ),
            ("sans-serif", 18),
        )
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (bmin * 0.7..bmax * 1.4).log_scale(),
            (s.clean_s * 0.6..tmax * 1.5).log_scale(),
        )
        .map_err(chart_err)?;
    chart
        .configure_mesh()
        .x_desc("bit-error rate (log)")
        .y_desc("frame time, s (virtual, log)")
        .x_label_formatter(&|x| format!("{x:.0e}"))
        .y_label_formatter(&|y| format!("{y:.2}"))
        .y_labels(7)
        .draw()
        .map_err(chart_err)?;
    chart
        .draw_series(LineSeries::new(
            [(bmin * 0.7, s.clean_s), (bmax * 1.4, s.clean_s)],
            BLACK.mix(0.4),
        ))
        .map_err(chart_err)?
        .label("fault-free")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.4)));
    // "both" is drawn over "down" (they nearly coincide: the down-link's errors cost), thinner.
    for (i, dir) in ["down", "up", "both"].iter().enumerate() {
        let col = COLOURS[i];
        let width = if i == 0 { 5 } else { 2 };
        let mut rates: Vec<f64> = s.bers.iter().map(|b| b.ber).collect();
        rates.dedup();
        let line: Vec<(f64, f64)> = rates
            .iter()
            .map(|&r| {
                (
                    r,
                    mean(
                        s.bers
                            .iter()
                            .filter(|b| b.ber == r && b.direction == *dir)
                            .map(|b| b.time_s),
                    ),
                )
            })
            .collect();
        chart
            .draw_series(LineSeries::new(line, col.stroke_width(width)))
            .map_err(chart_err)?
            .label(format!("{dir} (mean; dots: seeds)"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col.stroke_width(width)));
        chart
            .draw_series(
                s.bers
                    .iter()
                    .filter(|b| b.direction == *dir)
                    .map(|b| Circle::new((b.ber, b.time_s), 2, col.filled())),
            )
            .map_err(chart_err)?;
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperLeft).map_err(chart_err)
}

fn draw_fractions<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    s: &FaultSweep,
) -> Result<(), SimError>
where
    DB::ErrorType: 'static,
{
    let tmax = s
        .fractions
        .iter()
        .map(|f| f.time_s.max(f.bound_s))
        .fold(0.0, f64::max);
    let mut chart = linear_panel(
        area,
        format!(
            "nodes killed at once mid-frame ({} nodes, decreasing, board {})",
            s.nodes, s.board
        ),
        tmax * 1.1,
        "fraction of the nodes killed",
    )?;
    let mut bers: Vec<f64> = s.fractions.iter().map(|f| f.ber).collect();
    bers.dedup();
    let n = s.nodes as f64;
    for (i, ber) in bers.iter().enumerate() {
        let col = COLOURS[i % COLOURS.len()];
        let pts: Vec<(f64, f64)> = s
            .fractions
            .iter()
            .filter(|f| f.ber == *ber)
            .map(|f| (f.killed as f64 / n, f.time_s))
            .collect();
        let label = if *ber == 0.0 {
            "no bit errors".to_string()
        } else {
            format!("bit-error rate {ber:e} both ways")
        };
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), col.stroke_width(2)))
            .map_err(chart_err)?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col.stroke_width(2)));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 3, col.filled())))
            .map_err(chart_err)?;
    }
    let bound: Vec<(f64, f64)> = s
        .fractions
        .iter()
        .filter(|f| f.ber == 0.0)
        .map(|f| (f.killed as f64 / n, f.bound_s))
        .collect();
    chart
        .draw_series(DashedLineSeries::new(
            bound,
            6,
            4,
            BLACK.mix(0.6).stroke_width(1),
        ))
        .map_err(chart_err)?
        .label("bound without bit errors, clean + 2τ + ΣW")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.6)));
    draw_legend(&mut chart, SeriesLabelPosition::UpperLeft).map_err(chart_err)
}
