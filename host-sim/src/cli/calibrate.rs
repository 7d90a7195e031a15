//! `links calibrate`: fit the cycle model's weights to QEMU-measured frames and print the fit
//! beside the committed model.

use std::path::Path;

use super::CliError;
use crate::cost::{self, CycleModel};
use crate::limits;

/// Runs `links calibrate`: the frames of `target` rendered by number backend `backend`
/// (`f32`, `q16.16`), against the committed model of that core and kernel.
pub fn run(csv: &Path, target: &str, backend: &str) -> Result<(), CliError> {
    let text = limits::read_text_bounded(csv, limits::MAX_TEXT_BYTES, "CSV file")
        .map_err(CliError::failed)?;
    let in_csv = |e: &dyn std::fmt::Display| CliError::Failed(format!("{}: {e}", csv.display()));
    let mut samples = cost::parse_rows(&text).map_err(|e| in_csv(&e))?;
    samples.retain(|s| s.backend == backend);
    let committed_model = cost::committed_model(target, backend).ok_or_else(|| {
        CliError::Usage(format!(
            "no committed model for {target} {backend} (targets: thumbv7em-none-eabihf, thumbv7m-none-eabi, thumbv6m-none-eabi; backends: f32, q16.16)"
        ))
    })?;
    let fitted = cost::fit(
        &samples,
        target,
        CycleModel::CORTEX_M4F_F32.cycles_per_instruction,
    )
    .map_err(|e| in_csv(&e))?;
    outln!(
        "fitted instructions per operation ({target} {backend}, {} frames):",
        samples.iter().filter(|s| s.target == target).count()
    );
    for (name, w) in cost::FEATURES.iter().zip(fitted.weights()) {
        outln!("  {name:<18} {w:>9.1}");
    }
    outln!(
        "\n{:<28} {:>12} {:>12} {:>12}",
        "frame",
        "measured",
        "fitted",
        "committed"
    );
    let committed = cost::prediction_ratios(&committed_model, &samples, target);
    for ((s, r), (_, rc)) in cost::prediction_ratios(&fitted, &samples, target)
        .iter()
        .zip(&committed)
    {
        outln!(
            "{:<28} {:>12} {:>11.1}% {:>11.1}%",
            format!("{} {}", s.scene, s.techniques),
            s.instructions,
            (r - 1.0) * 100.0,
            (rc - 1.0) * 100.0
        );
    }
    Ok(())
}
