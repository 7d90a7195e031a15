//! `links chart accuracy`: speed against accuracy for every number backend.
//! Accuracy is measured here, on the host (each backend's render of every bundled
//! scene against the f64 render); speed comes from the Cortex-M instruction counts that
//! `scripts/qemu-bench` measured under QEMU (`docs/cortex-m-bench.csv`). One point per
//! target x backend x scene: x = instructions per pixel (log), y = PSNR vs f64.
//!
//! Outputs: an SVG and a PNG chart, the data as CSV, and a Markdown table that replaces the
//! marked section of `docs/numerics.md`. Everything but the PNG is plain text from
//! deterministic numbers, so a test can regenerate the CSV and compare it with the committed
//! copy.

use crate::studies::accuracy::{compare_to, reference, Accuracy, AccuracyError};
use crate::studies::backend::Backend;
use crate::studies::labels;
use crate::studies::report::{replace_between, table_head, write_file};
use links_core::num::{FastF32, Fx};
use plotters::prelude::*;
use std::fmt::{self, Write as _};
use std::path::Path;

/// The backends the chart compares (f64 is the reference).
pub const BACKENDS: [&str; 3] = Backend::NAMES;

/// Cortex-M targets of the benchmark, with the label the chart uses.
pub const TARGETS: [(&str, &str); 3] = [
    ("thumbv7em-none-eabihf", "M4F"),
    ("thumbv7m-none-eabi", "M3"),
    ("thumbv6m-none-eabi", "M0"),
];

/// The size the committed chart's accuracy is measured at.
pub const WIDTH: u32 = 256;
pub const HEIGHT: u32 = 240;

/// Compile every `.ron` scene of `dir` (sorted by name) at `width` x `height`.
pub fn bundled_images(
    dir: &Path,
    width: u32,
    height: u32,
) -> Result<Vec<(String, Vec<u8>)>, ChartError> {
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .map_err(|e| ChartError::Io(format!("{}: {e}", dir.display())))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "ron"))
        // Films (scenes with frames) are their still scenes plus tracks: charted as stills.
        .filter(|p| crate::scene_file::load_film(p).map_or(true, |f| f.is_still()))
        .collect();
    paths.sort();
    let mut out = Vec::new();
    for p in paths {
        let img = crate::scene_file::compile_at(&p, width, height)
            .map_err(|e| ChartError::Io(e.to_string()))?;
        let name = p
            .file_stem()
            .map_or(String::new(), |s| s.to_string_lossy().into_owned());
        out.push((name, img));
    }
    Ok(out)
}

/// Markers of the generated table in `docs/numerics.md`.
pub const TABLE_BEGIN: &str = "<!-- accuracy-table:begin (links chart accuracy) -->";
pub const TABLE_END: &str = "<!-- accuracy-table:end -->";

#[derive(Debug)]
pub enum ChartError {
    Accuracy(String, AccuracyError),
    /// A line of the benchmark CSV could not be read.
    Bench(String),
    Draw(String),
    Io(String),
}

impl fmt::Display for ChartError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ChartError::Accuracy(scene, e) => write!(f, "{scene}: {e}"),
            ChartError::Bench(e) => write!(f, "benchmark CSV: {e}"),
            ChartError::Draw(e) => write!(f, "chart: {e}"),
            ChartError::Io(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for ChartError {}

/// How far one backend's render of one scene is from f64.
#[derive(Clone, Debug)]
pub struct SceneAccuracy {
    pub scene: String,
    pub backend: &'static str,
    /// `Err` holds why the backend can't render the scene (a fixed-point range error).
    pub accuracy: Result<Accuracy, String>,
}

/// Measure every backend on every scene (name, f32 SceneImage).
pub fn measure(scenes: &[(String, Vec<u8>)]) -> Result<Vec<SceneAccuracy>, ChartError> {
    let mut out = Vec::new();
    for (name, image) in scenes {
        let f64_render = reference(image).map_err(|e| ChartError::Accuracy(name.clone(), e))?;
        for backend in Backend::ALL {
            let r = match backend {
                Backend::F32 => compare_to::<f32>(image, &f64_render),
                Backend::F32Fast => compare_to::<FastF32>(image, &f64_render),
                Backend::Fixed => compare_to::<Fx>(image, &f64_render),
            };
            let accuracy = match r {
                Ok(a) => Ok(a),
                // A scene the format can't hold is a result (the table says why).
                Err(AccuracyError::Fixed(e)) => Err(e.to_string()),
                Err(e) => return Err(ChartError::Accuracy(name.clone(), e)),
            };
            out.push(SceneAccuracy {
                scene: name.clone(),
                backend: backend.name(),
                accuracy,
            });
        }
    }
    Ok(out)
}

/// Instructions per pixel of one whole-frame benchmark run.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchSpeed {
    pub target: String,
    pub backend: String,
    pub scene: String,
    pub pixels: u64,
    pub instructions_per_pixel: f64,
}

/// The whole-frame rows of `docs/cortex-m-bench.csv` rendered with every technique
/// (`techniques` = `all`). A CSV without a `backend` column predates the other backends:
/// its rows are f32.
pub fn parse_bench(csv: &str) -> Result<Vec<BenchSpeed>, ChartError> {
    let mut lines = csv.lines().filter(|l| !l.trim().is_empty());
    let header: Vec<&str> = lines
        .next()
        .ok_or_else(|| ChartError::Bench("empty file".into()))?
        .split(',')
        .collect();
    let col = |name: &str| header.iter().position(|h| *h == name);
    let need =
        |name: &str| col(name).ok_or_else(|| ChartError::Bench(format!("no '{name}' column")));
    let (target, scene, tech, pixels, instr) = (
        need("target")?,
        need("scene")?,
        need("techniques")?,
        need("pixels")?,
        need("instructions")?,
    );
    let backend = col("backend");
    let mut out = Vec::new();
    for (n, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').collect();
        let cell = |i: usize| {
            cells.get(i).copied().ok_or_else(|| {
                ChartError::Bench(format!(
                    "line {}: {} cells, expected more",
                    n + 2,
                    cells.len()
                ))
            })
        };
        if cell(tech)? != "all" {
            continue;
        }
        let num = |i: usize| -> Result<u64, ChartError> {
            cell(i)?.parse().map_err(|_| {
                ChartError::Bench(format!("line {}: '{}' is not a count", n + 2, cells[i]))
            })
        };
        let (px, ins) = (num(pixels)?, num(instr)?);
        if px == 0 {
            return Err(ChartError::Bench(format!("line {}: zero pixels", n + 2)));
        }
        out.push(BenchSpeed {
            target: cell(target)?.to_string(),
            backend: match backend {
                Some(i) => cell(i)?.to_string(),
                None => "f32".to_string(),
            },
            scene: cell(scene)?.to_string(),
            pixels: px,
            instructions_per_pixel: ins as f64 / px as f64,
        });
    }
    Ok(out)
}

/// Instructions per pixel of a backend x scene on a target, if measured.
fn speed_of(speed: &[BenchSpeed], target: &str, a: &SceneAccuracy) -> Option<f64> {
    speed
        .iter()
        .find(|s| s.target == target && s.backend == a.backend && s.scene == a.scene)
        .map(|s| s.instructions_per_pixel)
}

/// One point of the chart.
#[derive(Clone, Debug)]
pub struct Point {
    pub target: &'static str,
    pub backend: &'static str,
    pub scene: String,
    pub instructions_per_pixel: f64,
    pub psnr_db: f64,
}

/// PSNR shown for a render identical to f64's (the chart needs a finite y).
pub const IDENTICAL_DB: f64 = 150.0;

/// Join accuracy (per backend x scene) with speed (per target x backend x scene).
pub fn points(acc: &[SceneAccuracy], speed: &[BenchSpeed]) -> Vec<Point> {
    let mut out = Vec::new();
    for (target, label) in TARGETS {
        for a in acc {
            let Ok(accuracy) = &a.accuracy else { continue };
            let Some(ipp) = speed_of(speed, target, a) else {
                continue;
            };
            out.push(Point {
                target: label,
                backend: a.backend,
                scene: a.scene.clone(),
                instructions_per_pixel: ipp,
                psnr_db: accuracy.psnr_db.min(IDENTICAL_DB),
            });
        }
    }
    out
}

/// Whether each point is on its scene's Pareto front: no other point of the same scene is
/// as fast or faster and as accurate or more, and strictly better in one of the two.
pub fn pareto_front(pts: &[Point]) -> Vec<bool> {
    pts.iter()
        .map(|p| {
            !pts.iter().any(|q| {
                q.scene == p.scene
                    && q.instructions_per_pixel <= p.instructions_per_pixel
                    && q.psnr_db >= p.psnr_db
                    && (q.instructions_per_pixel < p.instructions_per_pixel
                        || q.psnr_db > p.psnr_db)
            })
        })
        .collect()
}

/// The targets (chart labels) on which backend x scene `a` is on its scene's Pareto front,
/// space-separated.
fn front_targets(a: &SceneAccuracy, pts: &[Point], front: &[bool]) -> String {
    let on: Vec<&str> = pts
        .iter()
        .zip(front)
        .filter(|(p, &f)| f && p.scene == a.scene && p.backend == a.backend)
        .map(|(p, _)| p.target)
        .collect();
    on.join(" ")
}

/// The data behind the chart and the table, one row per backend x scene, with the
/// instructions per pixel on each target (empty where not measured).
pub fn csv(acc: &[SceneAccuracy], speed: &[BenchSpeed]) -> String {
    let mut s = String::from(
        "scene,backend,width,height,psnr_db,max_channel_error,pct_off_by_more_than_1,non_finite_pixels,hit_mismatches,hit_mismatches_off_silhouette,instr_per_pixel_m4f,instr_per_pixel_m3,instr_per_pixel_m0,pareto_front,note\n",
    );
    let pts = points(acc, speed);
    let front = pareto_front(&pts);
    for a in acc {
        let ipp =
            |target: &str| speed_of(speed, target, a).map_or(String::new(), |v| format!("{v:.0}"));
        match &a.accuracy {
            Ok(x) => {
                let _ = writeln!(
                    s,
                    "{},{},{},{},{:.2},{},{:.3},{},{},{},{},{},{},{},",
                    a.scene,
                    a.backend,
                    x.width,
                    x.height,
                    x.psnr_db,
                    x.max_channel_error,
                    100.0 * x.frac_off_by_more_than_1,
                    x.non_finite_pixels,
                    x.hit_mismatches,
                    x.hit_mismatches_off_silhouette,
                    ipp(TARGETS[0].0),
                    ipp(TARGETS[1].0),
                    ipp(TARGETS[2].0),
                    front_targets(a, &pts, &front),
                );
            }
            Err(why) => {
                let _ = writeln!(
                    s,
                    "{},{},,,,,,,,,,,,,\"{}\"",
                    a.scene,
                    a.backend,
                    why.replace('"', "'")
                );
            }
        }
    }
    s
}

/// The Markdown table for `docs/numerics.md`.
pub fn markdown(acc: &[SceneAccuracy], speed: &[BenchSpeed]) -> String {
    let mut s = String::new();
    let size = acc
        .iter()
        .find_map(|a| a.accuracy.as_ref().ok())
        .map_or(String::new(), |a| format!("{}x{}", a.width, a.height));
    let _ = writeln!(
        s,
        "Every backend against the f64 render of the same scene at {size} (host). Instructions per pixel: Cortex-M under QEMU from `docs/cortex-m-bench.csv` (smaller frames: see that file); `-` = not measured. Pareto front: the targets on which this backend is on the scene's front (no other backend x target of the scene as fast and as accurate, and better in one).\n"
    );
    s.push_str(&table_head([
        "scene",
        "backend",
        "PSNR (dB)",
        "max error (/255)",
        "pixels off > 1/255",
        "NaN/inf pixels",
        "hit-mask mismatches (off silhouettes)",
        "instr/pixel M4F",
        "M3",
        "M0",
        "Pareto front",
    ]));
    let pts = points(acc, speed);
    let front = pareto_front(&pts);
    for a in acc {
        let ipp = |target: &str| speed_of(speed, target, a).map_or("-".to_string(), group);
        match &a.accuracy {
            Ok(x) => {
                let psnr = if x.psnr_db.is_infinite() {
                    "identical".to_string()
                } else {
                    format!("{:.1}", x.psnr_db)
                };
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {} | {:.3}% | {} | {} ({}) | {} | {} | {} | {} |",
                    a.scene,
                    a.backend,
                    psnr,
                    x.max_channel_error,
                    100.0 * x.frac_off_by_more_than_1,
                    x.non_finite_pixels,
                    x.hit_mismatches,
                    x.hit_mismatches_off_silhouette,
                    ipp(TARGETS[0].0),
                    ipp(TARGETS[1].0),
                    ipp(TARGETS[2].0),
                    front_targets(a, &pts, &front),
                );
            }
            Err(why) => {
                let _ = writeln!(
                    s,
                    "| {} | {} | rejected: {why} | | | | | | | | |",
                    a.scene, a.backend
                );
            }
        }
    }
    s
}

/// 12345.6 -> "12,346".
fn group(v: f64) -> String {
    let n = v.round() as u64;
    let digits = n.to_string();
    let mut out = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// Replace the generated table between [`TABLE_BEGIN`] and [`TABLE_END`] in `doc`.
pub fn replace_table(doc: &str, table: &str) -> Result<String, ChartError> {
    replace_between(doc, (TABLE_BEGIN, TABLE_END), table, "table").map_err(ChartError::Io)
}

const COLOURS: [RGBColor; 3] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
];

fn draw_err<E: fmt::Display>(e: E) -> ChartError {
    ChartError::Draw(e.to_string())
}

/// The legend every chart of the studies draws: at `position`, on a translucent white box.
pub(crate) fn draw_legend<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<(), String>
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    CT: plotters::coord::CoordTranslate,
{
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK.mix(0.3))
        .draw()
        .map_err(|e| e.to_string())
}

/// Draw the chart on any plotters backend.
fn draw<DB: DrawingBackend>(
    area: DrawingArea<DB, plotters::coord::Shift>,
    pts: &[Point],
) -> Result<(), ChartError>
where
    DB::ErrorType: 'static,
{
    area.fill(&WHITE).map_err(draw_err)?;
    let (mut x_lo, mut x_hi) = (f64::MAX, f64::MIN);
    let (mut y_lo, mut y_hi) = (f64::MAX, f64::MIN);
    for p in pts {
        x_lo = x_lo.min(p.instructions_per_pixel);
        x_hi = x_hi.max(p.instructions_per_pixel);
        y_lo = y_lo.min(p.psnr_db);
        y_hi = y_hi.max(p.psnr_db);
    }
    if pts.is_empty() {
        (x_lo, x_hi, y_lo, y_hi) = (1e3, 1e6, 30.0, 100.0);
    }
    let mut chart = ChartBuilder::on(&area)
        .caption(
            "Speed vs accuracy per number backend (Cortex-M under QEMU; PSNR vs f64)",
            ("sans-serif", 18),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d(
            ((x_lo * 0.7)..(x_hi * 1.6)).log_scale(),
            (y_lo - 5.0).min(35.0)..(y_hi + 8.0),
        )
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc("instructions per pixel (log)")
        .x_label_formatter(&|v| group(*v))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .y_desc("PSNR vs f64 (dB)")
        .draw()
        .map_err(draw_err)?;
    // The accuracy floors.
    for (db, label) in [
        (45.0, "45 dB (fixed-point floor)"),
        (60.0, "60 dB (f32 floor)"),
    ] {
        chart
            .draw_series(LineSeries::new(
                [(x_lo * 0.7, db), (x_hi * 1.6, db)],
                BLACK.mix(0.25),
            ))
            .map_err(draw_err)?;
        chart
            .draw_series([Text::new(
                label,
                (x_lo * 0.72, db + 0.8),
                ("sans-serif", 12),
            )])
            .map_err(draw_err)?;
    }
    draw_markers(&mut chart, pts)?;
    let front = pareto_front(pts);
    // A ring around each point on its scene's Pareto front.
    let rings = pts.iter().zip(&front).filter(|(_, &f)| f).map(|(p, _)| {
        Circle::new(
            (p.instructions_per_pixel, p.psnr_db),
            8,
            BLACK.stroke_width(1),
        )
    });
    chart
        .draw_series(rings)
        .map_err(draw_err)?
        .label("on its scene's Pareto front")
        .legend(|(x, y)| Circle::new((x + 8, y), 7, BLACK.stroke_width(1)));
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight).map_err(draw_err)?;
    // Scene names beside the points, front points first, never over each other.
    let mut order: Vec<usize> = (0..pts.len()).collect();
    order.sort_by_key(|&i| !front[i]);
    let anchors: Vec<labels::Anchor> = order
        .iter()
        .map(|&i| {
            let (x, y) = chart.backend_coord(&(pts[i].instructions_per_pixel, pts[i].psnr_db));
            labels::Anchor {
                x,
                y,
                text: pts[i].scene.clone(),
            }
        })
        .collect();
    let (xr, yr) = chart.plotting_area().get_pixel_range();
    let plot = labels::Rect {
        x0: xr.start,
        y0: yr.start,
        x1: xr.end,
        y1: yr.end,
    };
    let layout = labels::place(&anchors, LABEL_FONT, 5, plot);
    for (a, p) in anchors.iter().zip(&layout.placed) {
        if let Some(p) = p {
            area.draw(&Text::new(a.text.clone(), (p.x, p.y), ("sans-serif", 10)))
                .map_err(draw_err)?;
        }
    }
    if layout.dropped > 0 {
        let note = format!(
            "{} point label(s) left out where the points crowd (docs/accuracy.csv has every point)",
            layout.dropped
        );
        let at = (plot.x0 + 4, plot.y1 - 14);
        area.draw(&Text::new(note, at, ("sans-serif", 10)))
            .map_err(draw_err)?;
    }
    area.present().map_err(draw_err)
}

/// The chart's 10-pixel label text, as the label placement measures it.
const LABEL_FONT: labels::Font = labels::Font {
    char_w: 6.0,
    line_h: 11,
};

/// One series per backend x target: colour = backend, shape = target.
fn draw_markers<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, PlotCoords>,
    pts: &[Point],
) -> Result<(), ChartError>
where
    DB::ErrorType: 'static,
{
    for (i, backend) in BACKENDS.iter().enumerate() {
        let c = COLOURS[i];
        for (t, (_, target)) in TARGETS.iter().enumerate() {
            let sel: Vec<&Point> = pts
                .iter()
                .filter(|p| p.backend == *backend && p.target == *target)
                .collect();
            if sel.is_empty() {
                continue;
            }
            let series = sel.iter().map(|p| {
                let xy = (p.instructions_per_pixel, p.psnr_db);
                match t {
                    0 => Circle::new(xy, 4, c.filled()).into_dyn(),
                    1 => TriangleMarker::new(xy, 5, c.filled()).into_dyn(),
                    _ => Cross::new(xy, 4, c.stroke_width(2)).into_dyn(),
                }
            });
            chart
                .draw_series(series)
                .map_err(draw_err)?
                .label(format!("{backend} on {target}"))
                .legend(move |(x, y)| match t {
                    0 => Circle::new((x + 8, y), 4, c.filled()).into_dyn(),
                    1 => TriangleMarker::new((x + 8, y), 5, c.filled()).into_dyn(),
                    _ => Cross::new((x + 8, y), 4, c.stroke_width(2)).into_dyn(),
                });
        }
    }
    Ok(())
}

/// The chart's coordinates: instructions per pixel (log) x PSNR.
type PlotCoords = Cartesian2d<LogCoord<f64>, plotters::coord::types::RangedCoordf64>;

pub const CHART_SIZE: (u32, u32) = (960, 640);

/// The chart as an SVG document.
pub fn svg(pts: &[Point]) -> Result<String, ChartError> {
    ensure_font().map_err(ChartError::Io)?;
    let mut out = String::new();
    {
        let area = SVGBackend::with_string(&mut out, CHART_SIZE).into_drawing_area();
        draw(area, pts)?;
    }
    Ok(out)
}

/// TrueType fonts tried for the PNG's text, in order.
const FONT_PATHS: [&str; 3] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

/// Register the charts' font with plotters (once per process): every chart, SVG or PNG,
/// lays its text out with it. Needs DejaVu Sans (Debian package fonts-dejavu-core).
pub fn ensure_font() -> Result<(), String> {
    static FONT: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
    FONT.get_or_init(|| {
        let font = FONT_PATHS
            .iter()
            .find_map(|p| {
                crate::limits::read_bounded(
                    std::path::Path::new(p),
                    crate::limits::MAX_TEXT_BYTES,
                    "font file",
                )
                .ok()
            })
            .ok_or_else(|| {
                format!(
                    "no TrueType font for chart text (looked for {}); install fonts-dejavu-core",
                    FONT_PATHS.join(", ")
                )
            })?;
        // plotters keeps registered fonts for the whole process: leak this one copy.
        let font: &'static [u8] = Box::leak(font.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, font)
            .map_err(|_| "the font file is not a usable TrueType font".to_string())
    })
    .clone()
}

/// The chart as a PNG.
pub fn png(pts: &[Point]) -> Result<Vec<u8>, ChartError> {
    ensure_font().map_err(ChartError::Io)?;
    let (w, h) = CHART_SIZE;
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    {
        let area = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        draw(area, pts)?;
    }
    crate::sim::single::encode_png(w, h, &rgb).map_err(draw_err)
}

/// Write a text file, naming it in the error.
pub fn write(path: &Path, bytes: &[u8]) -> Result<(), ChartError> {
    write_file(path, bytes).map_err(ChartError::Io)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bench_csv_rows_with_and_without_a_backend_column() {
        let old = "target,scene,techniques,pixels,instructions\nthumbv7em-none-eabihf,glass,all,240,2400\nthumbv7em-none-eabihf,glass,type1,240,9\n";
        let s = parse_bench(old).unwrap();
        assert_eq!(s.len(), 1);
        assert_eq!(
            (s[0].backend.as_str(), s[0].instructions_per_pixel),
            ("f32", 10.0)
        );
        let new = "target,backend,scene,techniques,pixels,instructions\nthumbv7m-none-eabi,q16.16,photo1,all,960,1920\n";
        let s = parse_bench(new).unwrap();
        assert_eq!(
            (
                s[0].backend.as_str(),
                s[0].target.as_str(),
                s[0].instructions_per_pixel
            ),
            ("q16.16", "thumbv7m-none-eabi", 2.0)
        );
        assert!(matches!(
            parse_bench("target,scene\n"),
            Err(ChartError::Bench(_))
        ));
        assert!(matches!(
            parse_bench("target,scene,techniques,pixels,instructions\nx,y,all,ten,5\n"),
            Err(ChartError::Bench(_))
        ));
    }

    /// The committed chart data (docs/accuracy.csv) is what `links chart accuracy` makes
    /// from the committed benchmark counts and today's renderer.
    #[test]
    fn the_pareto_front_is_what_nothing_beats_on_both_axes_per_scene() {
        let pt = |scene: &str, target: &'static str, ipp: f64, db: f64| Point {
            target,
            backend: "f32",
            scene: scene.to_string(),
            instructions_per_pixel: ipp,
            psnr_db: db,
        };
        let pts = [
            pt("a", "M4F", 100.0, 60.0), // front: fastest
            pt("a", "M3", 200.0, 70.0),  // front: most accurate
            pt("a", "M0", 300.0, 65.0),  // beaten by M3 on both
            pt("a", "M0", 100.0, 50.0),  // as fast as the first, less accurate: beaten
            pt("b", "M0", 900.0, 10.0),  // alone in its scene: front
            pt("a", "M3", 200.0, 70.0),  // a tie with the second: neither beats the other
        ];
        assert_eq!(
            pareto_front(&pts),
            vec![true, true, false, false, true, true]
        );
    }

    #[test]
    fn committed_accuracy_csv_is_current() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let bench = std::fs::read_to_string(root.join("docs/cortex-m-bench.csv")).unwrap();
        let committed = std::fs::read_to_string(root.join("docs/accuracy.csv")).unwrap();
        let images = bundled_images(&root.join("scenes"), WIDTH, HEIGHT).unwrap();
        let acc = measure(&images).unwrap();
        let fresh = csv(&acc, &parse_bench(&bench).unwrap());
        assert_eq!(
            fresh, committed,
            "docs/accuracy.csv is stale: run `links chart accuracy` and commit docs/accuracy.*"
        );
        // The issues' floors, on every bundled scene: f32 >= 60 dB, fixed point >= 45 dB
        // (issue 14), no NaN, no mismatches off silhouettes.
        for a in &acc {
            let x = a.accuracy.as_ref().unwrap();
            assert_eq!(
                (x.non_finite_pixels, x.hit_mismatches_off_silhouette),
                (0, 0),
                "{a:?}"
            );
            match a.backend {
                "f32" => assert!(x.psnr_db >= 60.0, "{a:?}"),
                "q16.16" => assert!(x.psnr_db >= 45.0, "{a:?}"),
                _ => {}
            }
        }
    }

    #[test]
    fn table_section_is_replaced_in_place() {
        let doc = format!("# T\nbefore\n{TABLE_BEGIN}\nold\n{TABLE_END}\nafter\n");
        let new = replace_table(&doc, "| a |\n").unwrap();
        assert_eq!(
            new,
            format!("# T\nbefore\n{TABLE_BEGIN}\n| a |\n{TABLE_END}\nafter\n")
        );
        assert!(replace_table("no markers", "x").is_err());
        assert_eq!(group(1234567.4), "1,234,567");
        assert_eq!(group(999.0), "999");
    }
}
