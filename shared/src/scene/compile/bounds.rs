//! Bounding boxes (LINKS-1 4.2), rounded outward to f32 so they still contain their shapes,
//! and the splits that build a mesh's hierarchy (median or binned SAH, see
//! [`MeshHierarchy`]).

use super::*;

/// An f32 box that contains an f64 box.
#[derive(Clone, Copy, Debug)]
pub(super) struct Bounds {
    pub(super) min: [f32; 3],
    pub(super) max: [f32; 3],
}

impl Bounds {
    pub(super) fn empty() -> Self {
        Self {
            min: [f32::MAX; 3],
            max: [f32::MIN; 3],
        }
    }
    pub(super) fn from_f64(min: [f64; 3], max: [f64; 3]) -> Self {
        let lo = min.map(|v| (v as f32).next_down());
        let hi = max.map(|v| (v as f32).next_up());
        Self { min: lo, max: hi }
    }
    pub(super) fn union(self, o: Bounds) -> Self {
        Self {
            min: [0, 1, 2].map(|i| self.min[i].min(o.min[i])),
            max: [0, 1, 2].map(|i| self.max[i].max(o.max[i])),
        }
    }
    pub(super) fn is_empty(&self) -> bool {
        (0..3).any(|i| self.min[i] > self.max[i])
    }
}

pub(super) fn longest_axis(b: &Bounds) -> usize {
    let ext = [0, 1, 2].map(|k| b.max[k] - b.min[k]);
    if ext[0] >= ext[1] && ext[0] >= ext[2] {
        0
    } else if ext[1] >= ext[2] {
        1
    } else {
        2
    }
}

/// Sort by centroid along the longest axis and split in the middle.
pub(super) fn median_split(tris: &mut [TriData]) -> usize {
    let all = tris
        .iter()
        .fold(Bounds::empty(), |b, t| b.union(t.bounds()));
    let axis = longest_axis(&all);
    tris.sort_by(|a, b| a.centroid(axis).total_cmp(&b.centroid(axis)));
    tris.len() / 2
}

pub(super) fn half_area(b: &Bounds) -> f64 {
    if b.is_empty() {
        return 0.0;
    }
    let e = [0, 1, 2].map(|k| f64::from(b.max[k]) - f64::from(b.min[k]));
    e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
}

pub(super) const SAH_BINS: usize = 16;

/// Centroid bin of a triangle along `axis` for centroids spanning `[lo, hi]`.
pub(super) fn sah_bin(t: &TriData, axis: usize, lo: f32, hi: f32) -> usize {
    (((t.centroid(axis) - lo) / (hi - lo) * SAH_BINS as f32) as usize).min(SAH_BINS - 1)
}

/// Best bin boundary on one axis: (Σ area·count of both sides, first bin of the right side).
pub(super) fn sah_best_on_axis(
    tris: &[TriData],
    axis: usize,
    lo: f32,
    hi: f32,
) -> Option<(f64, usize)> {
    let mut counts = [0usize; SAH_BINS];
    let mut boxes = [Bounds::empty(); SAH_BINS];
    for t in tris {
        let k = sah_bin(t, axis, lo, hi);
        counts[k] += 1;
        boxes[k] = boxes[k].union(t.bounds());
    }
    let mut best: Option<(f64, usize)> = None;
    for split in 1..SAH_BINS {
        let side = |r: core::ops::Range<usize>| {
            r.fold((Bounds::empty(), 0), |(b, n), k| {
                (b.union(boxes[k]), n + counts[k])
            })
        };
        let ((bl, nl), (br, nr)) = (side(0..split), side(split..SAH_BINS));
        if nl == 0 || nr == 0 {
            continue;
        }
        let c = half_area(&bl) * nl as f64 + half_area(&br) * nr as f64;
        if best.is_none_or(|b| c < b.0) {
            best = Some((c, split));
        }
    }
    best
}

/// Binned SAH split. Costs in units of one box test: a triangle leaf costs its box test
/// plus about two more for the triangle test; a cluster node one box test. Returns the
/// split point after reordering, or `None` to make a leaf run (only when the set is small
/// enough, <= `leaf_size`, and splitting would not pay).
pub(super) fn sah_split(tris: &mut [TriData], leaf_size: usize) -> Option<usize> {
    pub(super) const COST_NODE: f64 = 1.0;
    pub(super) const COST_TRI: f64 = 3.0;
    let n = tris.len();
    if n <= leaf_size {
        // A leaf holds the range (a node record costs more bytes than the tests it saves).
        return None;
    }
    let all = tris
        .iter()
        .fold(Bounds::empty(), |b, t| b.union(t.bounds()));
    let cent = tris.iter().fold(Bounds::empty(), |b, t| {
        let c = [0, 1, 2].map(|k| t.centroid(k));
        b.union(Bounds { min: c, max: c })
    });
    let best = (0..3)
        .filter(|&a| cent.max[a] > cent.min[a])
        .filter_map(|a| sah_best_on_axis(tris, a, cent.min[a], cent.max[a]).map(|(c, k)| (c, a, k)))
        .min_by(|x, y| x.0.total_cmp(&y.0));
    let Some((area_cost, axis, edge)) = best else {
        // All centroids coincide: fall back to a median split for large sets.
        return (n > leaf_size).then(|| median_split(tris));
    };
    let cost = 2.0 * COST_NODE + area_cost * COST_TRI / half_area(&all).max(f64::MIN_POSITIVE);
    if n <= leaf_size && cost >= n as f64 * COST_TRI {
        return None;
    }
    let (lo, hi) = (cent.min[axis], cent.max[axis]);
    // Stable partition: left bins first, original order kept within each side.
    tris.sort_by_key(|t| sah_bin(t, axis, lo, hi) >= edge);
    Some(
        tris.iter()
            .take_while(|t| sah_bin(t, axis, lo, hi) < edge)
            .count(),
    )
}
