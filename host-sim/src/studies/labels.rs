//! Labels beside chart points that never overlap one another (nor another point's marker).
//!
//! Greedy, in the order given (put the labels that matter most first): a point at (almost)
//! the spot of an earlier one with the same text shares its label; otherwise the label tries a
//! few positions around its point and takes the first whose box is clear; a label whose every
//! position is taken is left out, and counted unless a label with the same text stands nearby
//! (the reader takes it from there). Works in pixels, so it knows nothing of the chart's axes.

/// A point to label, in pixels, and its text.
#[derive(Clone, Debug, PartialEq)]
pub struct Anchor {
    pub x: i32,
    pub y: i32,
    pub text: String,
}

/// Where a label went: its text's top-left corner in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Placed {
    pub x: i32,
    pub y: i32,
}

/// An axis-aligned box in pixels, `[x0, x1) x [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    pub x0: i32,
    pub y0: i32,
    pub x1: i32,
    pub y1: i32,
}

impl Rect {
    fn overlaps(&self, o: &Rect) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1 && self.y0 < o.y1 && o.y0 < self.y1
    }

    fn inside(&self, o: &Rect) -> bool {
        self.x0 >= o.x0 && self.y0 >= o.y0 && self.x1 <= o.x1 && self.y1 <= o.y1
    }
}

/// The text's size: `char_w` pixels per character, `line_h` high.
#[derive(Clone, Copy, Debug)]
pub struct Font {
    pub char_w: f64,
    pub line_h: i32,
}

/// The labels' placement, one entry per anchor (`None`: left out), and how many were left
/// out with no same-text label nearby.
pub struct Layout {
    pub placed: Vec<Option<Placed>>,
    pub dropped: usize,
}

/// How far (pixels) a same-text label may stand for a left-out one.
const NEARBY: i32 = 60;
/// Points closer than this (pixels, each axis) with the same text share one label.
const SAME_SPOT: i32 = 10;

/// Place `anchors`' labels inside `plot`, clear of each other and of every anchor's marker
/// (a square of `marker` pixels around it).
pub fn place(anchors: &[Anchor], font: Font, marker: i32, plot: Rect) -> Layout {
    let markers: Vec<Rect> = anchors
        .iter()
        .map(|a| Rect {
            x0: a.x - marker,
            y0: a.y - marker,
            x1: a.x + marker + 1,
            y1: a.y + marker + 1,
        })
        .collect();
    let mut boxes: Vec<(Rect, &str)> = Vec::new();
    let mut labelled: Vec<&Anchor> = Vec::new();
    let mut placed = Vec::with_capacity(anchors.len());
    let mut dropped = 0;
    for a in anchors {
        let shared = labelled.iter().any(|o| {
            o.text == a.text && (o.x - a.x).abs() < SAME_SPOT && (o.y - a.y).abs() < SAME_SPOT
        });
        if shared {
            placed.push(None);
            continue;
        }
        let w = (a.text.chars().count() as f64 * font.char_w).ceil() as i32;
        let h = font.line_h;
        let gap = marker + 2;
        // Right, left, above, below, then the four diagonals.
        let tries = [
            (gap, -h / 2),
            (-gap - w, -h / 2),
            (-w / 2, -gap - h),
            (-w / 2, gap),
            (gap, -gap - h),
            (gap, gap),
            (-gap - w, -gap - h),
            (-gap - w, gap),
        ];
        let free = tries.iter().find_map(|&(dx, dy)| {
            let r = Rect {
                x0: a.x + dx,
                y0: a.y + dy,
                x1: a.x + dx + w,
                y1: a.y + dy + h,
            };
            let clear = r.inside(&plot)
                && !boxes.iter().any(|(b, _)| b.overlaps(&r))
                && !markers.iter().any(|m| m.overlaps(&r));
            clear.then_some(r)
        });
        match free {
            Some(r) => {
                boxes.push((r, &a.text));
                labelled.push(a);
                placed.push(Some(Placed { x: r.x0, y: r.y0 }));
            }
            None => {
                let near = boxes.iter().any(|(b, t)| {
                    *t == a.text && (b.x0 - a.x).abs() < NEARBY && (b.y0 - a.y).abs() < NEARBY
                });
                dropped += usize::from(!near);
                placed.push(None);
            }
        }
    }
    Layout { placed, dropped }
}

/// The box a placed label covers (for checks).
pub fn label_box(p: Placed, text: &str, font: Font) -> Rect {
    let w = (text.chars().count() as f64 * font.char_w).ceil() as i32;
    Rect {
        x0: p.x,
        y0: p.y,
        x1: p.x + w,
        y1: p.y + font.line_h,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FONT: Font = Font {
        char_w: 6.0,
        line_h: 10,
    };
    const PLOT: Rect = Rect {
        x0: 0,
        y0: 0,
        x1: 400,
        y1: 300,
    };

    fn anchor(x: i32, y: i32, text: &str) -> Anchor {
        Anchor {
            x,
            y,
            text: text.to_string(),
        }
    }

    fn boxes(anchors: &[Anchor], l: &Layout) -> Vec<Rect> {
        anchors
            .iter()
            .zip(&l.placed)
            .filter_map(|(a, p)| p.map(|p| label_box(p, &a.text, FONT)))
            .collect()
    }

    #[test]
    fn a_lone_label_goes_right_of_its_point() {
        let l = place(&[anchor(100, 100, "photo1")], FONT, 4, PLOT);
        // 4 px marker + 2 px gap; centred on the point's height.
        assert_eq!(l.placed, vec![Some(Placed { x: 106, y: 95 })]);
        assert_eq!(l.dropped, 0);
    }

    #[test]
    fn points_at_one_spot_with_one_name_share_a_label() {
        let a = [anchor(100, 100, "glass"), anchor(104, 98, "glass")];
        let l = place(&a, FONT, 4, PLOT);
        // Left of the first point: its right side is the second point's marker.
        assert_eq!(l.placed, vec![Some(Placed { x: 64, y: 95 }), None]);
        assert_eq!(l.dropped, 0);
    }

    #[test]
    fn two_points_at_one_spot_get_two_clear_labels() {
        let a = [anchor(100, 100, "photo1"), anchor(101, 100, "photo2")];
        let l = place(&a, FONT, 4, PLOT);
        let b = boxes(&a, &l);
        assert_eq!(b.len(), 2);
        assert!(!b[0].overlaps(&b[1]), "{b:?}");
    }

    #[test]
    fn a_crowd_never_overlaps_and_same_text_neighbours_share_a_label() {
        // 40 points in a tight random cloud, 6 names: whatever is placed is clear of every
        // other label and marker and inside the plot.
        let mut seed = 7u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 16) as i32
        };
        let names = [
            "photo1",
            "photo2",
            "glass",
            "metaballs",
            "ellipsoids",
            "reflections",
        ];
        let a: Vec<Anchor> = (0..40)
            .map(|i| anchor(150 + next() % 100, 120 + next() % 60, names[i % 6]))
            .collect();
        let l = place(&a, FONT, 4, PLOT);
        let b = boxes(&a, &l);
        for (i, r) in b.iter().enumerate() {
            assert!(r.inside(&PLOT));
            assert!(b[i + 1..].iter().all(|o| !o.overlaps(r)), "{r:?}");
            for p in &a {
                let m = Rect {
                    x0: p.x - 4,
                    y0: p.y - 4,
                    x1: p.x + 5,
                    y1: p.y + 5,
                };
                assert!(
                    !m.overlaps(r),
                    "label {r:?} covers the marker at {},{}",
                    p.x,
                    p.y
                );
            }
        }
        assert!(b.len() >= 10, "only {} of 40 placed", b.len());
        assert_eq!(l.placed.len(), 40);
    }

    #[test]
    fn a_label_that_does_not_fit_the_plot_goes_elsewhere_or_nowhere() {
        // At the right edge the label goes left of its point.
        let l = place(&[anchor(395, 100, "glass")], FONT, 4, PLOT);
        assert_eq!(l.placed, vec![Some(Placed { x: 359, y: 95 })]);
        // A label wider than the plot is left out and counted.
        let wide = "x".repeat(80);
        let l = place(&[anchor(200, 100, &wide)], FONT, 4, PLOT);
        assert_eq!((l.placed[0], l.dropped), (None, 1));
    }
}
