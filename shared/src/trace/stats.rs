//! The renderer's deterministic operation counts ([`Stats`]), defined from one list of
//! counters by `define_stats!`.

/// Defines [`Stats`] from one list of counters: the struct, its field names in order, its
/// values in the same order, and addition. Every other list of the counters (the cost model's
/// CSV columns, the firmware's `RUN` line, the CLI's stats line) is derived from
/// [`Stats::NAMES`] and [`Stats::values`], so a new counter is written here once.
macro_rules! define_stats {
    ($(#[$meta:meta])* pub struct $name:ident { $($(#[$fmeta:meta])* $field:ident,)* }) => {
        $(#[$meta])*
        pub struct $name {
            $($(#[$fmeta])* pub $field: u64,)*
        }

        impl $name {
            /// How many counters there are.
            pub const COUNT: usize = [$(stringify!($field)),*].len();
            /// The counters' field names, in declaration order.
            pub const NAMES: [&'static str; Self::COUNT] = [$(stringify!($field)),*];

            /// The counters' values, in [`Self::NAMES`] order.
            pub fn values(&self) -> [u64; Self::COUNT] {
                [$(self.$field),*]
            }

            /// The counts whose values are `values`, in [`Self::NAMES`] order.
            pub fn from_values(values: [u64; Self::COUNT]) -> Self {
                let [$($field),*] = values;
                Self { $($field),* }
            }

            /// Adds `o`'s counts to these.
            pub fn add(&mut self, o: &$name) {
                $(self.$field += o.$field;)*
            }
        }
    };
}

define_stats! {
    /// Deterministic operation counts (the cost model's input).
    #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
    pub struct Stats {
        primary_rays,
        shadow_rays,
        reflect_rays,
        refract_rays,
        /// Straight-through (non-refractive) transmission rays.
        straight_rays,
        box_tests,
        triangle_tests,
        ellipsoid_tests,
        box_shape_tests,
        blob_tests,
        blob_field_evals,
        /// Evaluations of eq. 2.1 (one per shaded surface point).
        shadings,
        /// Integer compares made by Y and X clipping.
        clip_compares,
        /// Runs whose row kept more leaves than the clip buffer holds (plain traversal used).
        clip_overflows,
        /// Shadow rays settled by the first pass (an opaque blocker, or nothing at all in the way).
        shadow_early_exits,
    }
}

impl Stats {
    /// Every ray traced: primary, shadow and the three secondary kinds.
    pub fn rays(&self) -> u64 {
        self.primary_rays
            + self.shadow_rays
            + self.reflect_rays
            + self.refract_rays
            + self.straight_rays
    }

    /// The value of the counter called `name` (one of [`Self::NAMES`]).
    pub fn get(&self, name: &str) -> Option<u64> {
        let at = Self::NAMES.iter().position(|n| *n == name)?;
        Some(self.values()[at])
    }
}
