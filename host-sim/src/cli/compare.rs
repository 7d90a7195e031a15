//! `links compare`: render a scene in a number backend and in f64 and report how far apart
//! they are.

use super::args::SceneArgs;
use super::backend::Backend;
use super::CliError;

/// Runs `links compare`; `backend` is the name given on the command line (printed as given).
pub fn run(scene: &SceneArgs, backend: &str, threads: usize) -> Result<(), CliError> {
    let image = scene.compile()?;
    let measure: Backend = backend
        .parse()
        .map_err(|e| CliError::Usage(format!("{e}")))?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(CliError::failed)?;
    links_core::math::overflow::reset();
    let a = pool
        .install(|| measure.compare_to_f64(&image))
        .map_err(CliError::failed)?;
    outln!(
        "{}: {}x{} {backend} vs f64: PSNR {:.1} dB, max channel error {}/255, {:.3}% pixels off by > 1/255, {} NaN/inf pixels, {} hit-mask mismatches ({} off silhouettes)",
        scene.path()?.display(),
        a.width,
        a.height,
        a.psnr_db,
        a.max_channel_error,
        100.0 * a.frac_off_by_more_than_1,
        a.non_finite_pixels,
        a.hit_mismatches,
        a.hit_mismatches_off_silhouette
    );
    report_overflows();
    Ok(())
}

/// The checked build's account of the fixed-point renders since the counters were reset
/// (`--features fx-checked`; nothing otherwise): the counts and where they happened.
pub fn report_overflows() {
    use links_core::math::overflow;
    if !overflow::ENABLED {
        return;
    }
    let c = overflow::counts();
    outln!("fixed-point overflows (checked build): {c}");
    let mut sites = [None; overflow::SITES];
    let n = overflow::sites(&mut sites);
    for s in sites[..n].iter().flatten() {
        outln!("  {}:{}: {} x{}", s.file, s.line, s.kind, s.count);
    }
}
