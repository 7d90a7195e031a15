//! Fixed-point overflow accounting: the checked build (`--features fx-checked`).
//!
//! Q16.16 ([`super::fixed::Fx`]) never wraps: an operation whose finite operands give a
//! result outside the format saturates to an infinity, an invalid one (0/0, the square
//! root of a negative number) gives NaN, and the tracer reads a non-finite value as "no
//! hit". That is safe but silent: an overflow inside the scene would drop a hit without a
//! trace. The checked build counts every such event where it happens, by kind and source
//! line. The saturations that are the intended answer are written as such
//! ([`crate::num::Real::mul_beyond`], [`crate::num::Real::recip_beyond`]: a slab test's
//! reciprocal direction and distances for a ray nearly parallel to the slab, where IEEE
//! floats give an infinity too) and not counted. Without the feature nothing is counted and
//! the hooks compile to nothing.
//!
//! The counters are process-wide (atomics; renders on several threads add up); read them
//! with [`counts`] and clear them with [`reset`]. The feature needs atomic read-modify-write
//! (not ARMv6-M): it is a host and Cortex-M3/M4 diagnostic.

/// What overflowed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Kind {
    /// A sum or difference.
    Sum,
    /// A product, or a fused product (dot product, the point of `local_mat_vec`, a cross term).
    Product,
    /// A quotient or reciprocal, division by zero included.
    Quotient,
    /// A conversion into the format (`from_f32`, `from_f64`, `from_i32`, a power-of-two scale).
    Conversion,
    /// NaN from finite operands.
    Invalid,
}

impl core::fmt::Display for Kind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Kind::Sum => "sum",
            Kind::Product => "product",
            Kind::Quotient => "quotient",
            Kind::Conversion => "conversion",
            Kind::Invalid => "invalid",
        })
    }
}

/// The events counted since the last [`reset`] (all zero without the feature).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OverflowCounts {
    pub sums: u32,
    pub products: u32,
    pub quotients: u32,
    pub conversions: u32,
    pub invalid: u32,
}

impl OverflowCounts {
    /// All events.
    pub fn total(&self) -> u32 {
        self.sums
            .saturating_add(self.products)
            .saturating_add(self.quotients)
            .saturating_add(self.conversions)
            .saturating_add(self.invalid)
    }
}

impl core::fmt::Display for OverflowCounts {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{} sums, {} products, {} quotients, {} conversions, {} invalid",
            self.sums, self.products, self.quotients, self.conversions, self.invalid
        )
    }
}

/// Whether this build counts overflows.
pub const ENABLED: bool = cfg!(feature = "fx-checked");

#[cfg(all(feature = "fx-checked", not(target_has_atomic = "32")))]
compile_error!(
    "fx-checked counts with atomic read-modify-write, which this target lacks (ARMv6-M)"
);

#[cfg(feature = "fx-checked")]
mod store {
    use super::{Kind, OverflowCounts, Site};
    use core::panic::Location;
    use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

    static SUMS: AtomicU32 = AtomicU32::new(0);
    static PRODUCTS: AtomicU32 = AtomicU32::new(0);
    static QUOTIENTS: AtomicU32 = AtomicU32::new(0);
    static CONVERSIONS: AtomicU32 = AtomicU32::new(0);
    static INVALID: AtomicU32 = AtomicU32::new(0);

    const ALL: [&AtomicU32; 5] = [&SUMS, &PRODUCTS, &QUOTIENTS, &CONVERSIONS, &INVALID];

    fn bump(c: &AtomicU32) {
        // Saturating: a counter that stops at u32::MAX still says "many".
        let _ = c.fetch_update(Relaxed, Relaxed, |v| v.checked_add(1));
    }

    /// Where events happened: the first [`super::SITES`] distinct call sites with their
    /// counts (with `std`: a host diagnostic; a node's checked build only counts).
    #[cfg(feature = "std")]
    static TABLE: std::sync::Mutex<Vec<Site>> = std::sync::Mutex::new(Vec::new());

    #[cfg(feature = "std")]
    fn place(kind: Kind, at: &'static Location<'static>) {
        // A poisoned lock only means another thread panicked while holding it; the table
        // is still a valid list.
        let mut sites = TABLE.lock().unwrap_or_else(|e| e.into_inner());
        let same = |s: &&mut Site| s.kind == kind && s.line == at.line() && s.file == at.file();
        if let Some(s) = sites.iter_mut().find(|s| same(s)) {
            s.count = s.count.saturating_add(1);
        } else if sites.len() < super::SITES {
            sites.push(Site {
                file: at.file(),
                line: at.line(),
                kind,
                count: 1,
            });
        }
    }

    #[cold]
    #[inline(never)]
    pub(super) fn record(kind: Kind, at: &'static Location<'static>) {
        #[cfg(feature = "std")]
        place(kind, at);
        #[cfg(not(feature = "std"))]
        let _ = at;
        bump(match kind {
            Kind::Sum => &SUMS,
            Kind::Product => &PRODUCTS,
            Kind::Quotient => &QUOTIENTS,
            Kind::Conversion => &CONVERSIONS,
            Kind::Invalid => &INVALID,
        });
    }

    pub(super) fn counts() -> OverflowCounts {
        OverflowCounts {
            sums: SUMS.load(Relaxed),
            products: PRODUCTS.load(Relaxed),
            quotients: QUOTIENTS.load(Relaxed),
            conversions: CONVERSIONS.load(Relaxed),
            invalid: INVALID.load(Relaxed),
        }
    }

    pub(super) fn sites(out: &mut [Option<Site>]) -> usize {
        #[cfg(feature = "std")]
        {
            let sites = TABLE.lock().unwrap_or_else(|e| e.into_inner());
            let mut n = 0;
            for (o, s) in out.iter_mut().zip(sites.iter()) {
                *o = Some(*s);
                n += 1;
            }
            n
        }
        #[cfg(not(feature = "std"))]
        {
            let _ = out;
            0
        }
    }

    pub(super) fn reset() {
        for c in ALL {
            c.store(0, Relaxed);
        }
        #[cfg(feature = "std")]
        TABLE.lock().unwrap_or_else(|e| e.into_inner()).clear();
    }
}

/// How many distinct call sites the checked build remembers (further ones are counted, not
/// placed).
pub const SITES: usize = 64;

/// A place where overflows happened: the source line of the operation's caller
/// (`#[track_caller]` through `Fx`'s operators and the vector operations above them).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Site {
    pub file: &'static str,
    pub line: u32,
    pub kind: Kind,
    pub count: u32,
}

/// Counts one event at the caller's line.
#[cfg(feature = "fx-checked")]
#[inline(always)]
#[track_caller]
pub(crate) fn record(kind: Kind) {
    store::record(kind, core::panic::Location::caller());
}

/// Fills `out` with the sites of the events since the last [`reset`] (in the order
/// first seen); returns how many it wrote. None without the feature, or without `std` (a
/// node's checked build counts but does not place).
pub fn sites(out: &mut [Option<Site>]) -> usize {
    #[cfg(feature = "fx-checked")]
    return store::sites(out);
    #[cfg(not(feature = "fx-checked"))]
    {
        let _ = out;
        0
    }
}

/// The events counted since the last [`reset`].
pub fn counts() -> OverflowCounts {
    #[cfg(feature = "fx-checked")]
    return store::counts();
    #[cfg(not(feature = "fx-checked"))]
    OverflowCounts::default()
}

/// Clears the counters.
pub fn reset() {
    #[cfg(feature = "fx-checked")]
    store::reset();
}
