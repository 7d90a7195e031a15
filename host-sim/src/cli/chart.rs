//! `links chart`: charts of measured results (`links chart accuracy`).

use std::path::PathBuf;

use clap::Subcommand;

use super::CliError;
use crate::chart;
use crate::limits;

/// The charts `links chart` draws.
#[derive(Subcommand)]
pub enum ChartCmd {
    /// Speed (Cortex-M instructions per pixel) against accuracy (PSNR vs f64) for every
    /// number backend and bundled scene; writes the SVG, a PNG and a CSV beside it, and the
    /// table in docs/numerics.md
    Accuracy {
        /// The SVG to write (the PNG and CSV get the same name with their extension)
        #[arg(short, long, default_value = "docs/accuracy.svg")]
        output: PathBuf,
        /// Instruction counts measured by scripts/qemu-bench
        #[arg(long, default_value = "docs/cortex-m-bench.csv")]
        bench: PathBuf,
        /// Directory of the bundled scenes
        #[arg(long, default_value = "scenes")]
        scenes: PathBuf,
        /// Document whose generated table section to replace ("" = none)
        #[arg(long, default_value = "docs/numerics.md")]
        doc: PathBuf,
        #[arg(long, default_value_t = crate::chart::WIDTH, value_parser = limits::parse_image_side)]
        width: u32,
        #[arg(long, default_value_t = crate::chart::HEIGHT, value_parser = limits::parse_image_side)]
        height: u32,
    },
}

/// Runs `links chart ...`.
pub fn run(cmd: ChartCmd) -> Result<(), CliError> {
    let ChartCmd::Accuracy {
        output,
        bench,
        scenes,
        doc,
        width,
        height,
    } = cmd;
    let bench_csv = limits::read_text_bounded(&bench, limits::MAX_TEXT_BYTES, "CSV file")
        .map_err(|e| CliError::Failed(format!("{e} (run scripts/qemu-bench first)")))?;
    let speed = chart::parse_bench(&bench_csv).map_err(CliError::failed)?;
    let images = chart::bundled_images(&scenes, width, height).map_err(CliError::failed)?;
    eprintln!(
        "measuring {} backends x {} scenes at {width}x{height} against f64 ...",
        chart::BACKENDS.len(),
        images.len()
    );
    let acc = chart::measure(&images).map_err(CliError::failed)?;
    let pts = chart::points(&acc, &speed);
    let svg = chart::svg(&pts).map_err(CliError::failed)?;
    chart::write(&output, svg.as_bytes()).map_err(CliError::failed)?;
    let png_path = output.with_extension("png");
    let png = chart::png(&pts).map_err(CliError::failed)?;
    chart::write(&png_path, &png).map_err(CliError::failed)?;
    let csv_path = output.with_extension("csv");
    chart::write(&csv_path, chart::csv(&acc, &speed).as_bytes()).map_err(CliError::failed)?;
    let with_doc = !doc.as_os_str().is_empty();
    if with_doc {
        let text = limits::read_text_bounded(&doc, limits::MAX_TEXT_BYTES, "document")
            .map_err(CliError::failed)?;
        let new = chart::replace_table(&text, &chart::markdown(&acc, &speed))
            .map_err(|e| CliError::Failed(format!("{}: {e}", doc.display())))?;
        chart::write(&doc, new.as_bytes()).map_err(CliError::failed)?;
    }
    outln!(
        "{} points; wrote {}, {}, {}{}",
        pts.len(),
        output.display(),
        png_path.display(),
        csv_path.display(),
        if with_doc {
            format!(" and the table in {}", doc.display())
        } else {
            String::new()
        }
    );
    Ok(())
}
