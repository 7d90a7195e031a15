//! The camera model: the analog of LINKS-1's "Photo 1", a 35 mm single-lens-reflex camera
//! of exactly 738 triangles.
//!
//! About 14 units wide (x), 9 tall (y, bottom at y = 0) and 4.4 deep (z) for the body, with
//! the lens reaching about 5 units further towards -z (where the viewer is): the lens axis is
//! `(0, 3.2, z)`, its front glass at z = -7.3.
//!
//! Triangle tally (part -> triangles; `n` = segments around):
//!
//! | part            | construction                                                    | tris |
//! |-----------------|-----------------------------------------------------------------|------|
//! | body            | loft of 6 octagons (5 bands x 16) + 2 octagon fans (2 x 6)      |   92 |
//! | prism housing   | loft of 3 octagons (2 x 16) + 2 fans (2 x 6)                    |   44 |
//! | eyepiece        | box                                                             |   12 |
//! | hot shoe        | box                                                             |   12 |
//! | lens            | lathe, n = 18, 12 profile points from axis to axis: 2n(12 - 2) |  360 |
//! | shutter dial    | cylinder n = 16: side 32 + top centre fan 16 + bottom fan 14    |   62 |
//! | shutter button  | cylinder n = 10: side 20 + top centre fan 10 + bottom fan 8     |   38 |
//! | rewind knob     | cylinder n = 12: side 24 + top centre fan 12 + bottom fan 10    |   46 |
//! | advance lever   | box (rotated in plan)                                           |   12 |
//! | strap lugs      | 2 boxes                                                         |   24 |
//! | self-timer lever| box                                                             |   12 |
//! | lens release    | cylinder n = 6: side 12 + 2 centre fans 2 x 6                   |   24 |
//! | **total**       |                                                                 |  738 |

use super::mesh::{octagon, Basis, Cap, GenMesh, MeshBuilder};

/// Triangles in [`camera_mesh`], as in the paper's Photo 1.
pub const CAMERA_TRIANGLES: usize = 738;

/// Crease angle for hard-edged parts (bevels are 45 degrees, so they stay sharp).
const HARD: f64 = 30.0;
/// Crease angle for turned parts: smooth around (20 degrees between sides), sharp at steps.
const TURNED: f64 = 40.0;

/// Lens axis height and segments.
const LENS_Y: f64 = 3.2;
const LENS_SEGMENTS: u32 = 18;

/// The camera: see the module docs for the parts and their triangle counts.
pub fn camera_mesh() -> GenMesh {
    let mut b = MeshBuilder::new();
    add_body(&mut b);
    add_lens(&mut b);
    add_controls(&mut b);
    b.finish()
}

/// The body, the pentaprism housing, the eyepiece and the hot shoe.
fn add_body(b: &mut MeshBuilder) {
    let up = Basis::y_up([0.0; 3]);
    let xz = Basis::xz;

    // Body: the leather-covered lower body (bevelled at the bottom), a small ledge, and the
    // top plate (bevelled at the top). Octagons in plan: corners cut by 0.5.
    b.begin_part("body", true, HARD);
    let body = |hx: f64, hz: f64, k: f64| octagon(xz(0.0, 0.0), [hx, hz], k);
    b.add_loft(
        &up,
        &[
            (0.0, body(6.7, 1.9, 0.3)),
            (0.3, body(7.0, 2.2, 0.5)),
            (5.6, body(7.0, 2.2, 0.5)),
            (5.6, body(6.85, 2.05, 0.45)),
            (6.4, body(6.85, 2.05, 0.45)),
            (6.6, body(6.65, 1.85, 0.35)),
        ],
        Cap::Fan,
        Cap::Fan,
    );

    // Pentaprism housing: vertical at the bottom, then sloping in (more at the front).
    b.begin_part("prism housing", true, HARD);
    b.add_loft(
        &up,
        &[
            (6.55, octagon(xz(0.0, -0.1), [2.3, 1.9], 0.25)),
            (7.5, octagon(xz(0.0, -0.1), [2.3, 1.9], 0.25)),
            (8.7, octagon(xz(0.0, 0.45), [1.25, 0.85], 0.15)),
        ],
        Cap::Fan,
        Cap::Fan,
    );

    b.begin_part("eyepiece", true, HARD);
    b.add_box([-0.9, 7.0, 1.6], [0.9, 8.1, 2.6]);

    b.begin_part("hot shoe", true, HARD);
    b.add_box([-0.65, 8.69, -0.15], [0.65, 8.95, 1.05]);
}

/// The lens, turned around its axis.
fn add_lens(b: &mut MeshBuilder) {
    // Lens: (radius, distance forward of z = 0) from the back centre (inside the body) to
    // the centre of the front glass.
    b.begin_part("lens", true, TURNED);
    let lens = Basis::new([0.0, LENS_Y, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]);
    b.add_lathe(
        &lens,
        &[
            [0.0, 2.1],
            [2.3, 2.1],   // back of the mount
            [2.3, 2.7],   // bayonet mount ring
            [2.55, 2.8],  // aperture ring starts
            [2.55, 3.7],  //
            [2.75, 3.9],  // focusing ring starts
            [2.75, 5.9],  //
            [2.5, 6.0],   // front barrel, tapering
            [2.35, 7.3],  //
            [1.85, 7.3],  // front face
            [1.85, 7.05], // inside wall, down to the glass
            [0.0, 7.15],  // front element, slightly domed
        ],
        LENS_SEGMENTS,
        0.0,
        Cap::Open,
        Cap::Open,
    );
}

/// The controls on the top plate and the front, and the strap lugs.
fn add_controls(b: &mut MeshBuilder) {
    // Top-plate controls (they stand on the top plate at y = 6.6).
    b.begin_part("shutter dial", true, TURNED);
    b.add_frustum(
        &Basis::y_up([4.5, 0.0, 0.3]),
        0.95,
        0.95,
        6.55,
        7.1,
        16,
        Cap::Fan,
        Cap::Center,
    );

    b.begin_part("shutter button", true, TURNED);
    b.add_frustum(
        &Basis::y_up([5.6, 0.0, -1.1]),
        0.38,
        0.34,
        6.55,
        7.25,
        10,
        Cap::Fan,
        Cap::Center,
    );

    b.begin_part("rewind knob", true, TURNED);
    b.add_frustum(
        &Basis::y_up([-4.5, 0.0, 0.3]),
        0.85,
        0.8,
        6.55,
        7.35,
        12,
        Cap::Fan,
        Cap::Center,
    );

    // Film-advance lever: a flat bar pivoting on the shutter dial, swung back 20 degrees.
    b.begin_part("advance lever", true, HARD);
    let lever = Basis::new([4.5, 0.0, 0.3], [0.0, 1.0, 0.0], [0.94, 0.0, 0.342]);
    b.add_basis_box(&lever, [-0.2, -0.3], [2.6, 0.3], 7.05, 7.3);

    // Strap lugs on both ends of the top plate.
    b.begin_part("strap lugs", true, HARD);
    b.add_box([-7.35, 5.0, -0.3], [-6.9, 5.9, 0.3]);
    b.add_box([6.9, 5.0, -0.3], [7.35, 5.9, 0.3]);

    // On the front: the self-timer lever (photographer's left, -x) and the lens-release
    // button (photographer's right, beside the mount).
    b.begin_part("self-timer lever", true, HARD);
    b.add_box([-4.75, 4.0, -2.5], [-4.05, 5.3, -2.15]);

    b.begin_part("lens release", true, 65.0);
    b.add_frustum(
        &Basis::new([3.35, 5.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]),
        0.32,
        0.3,
        2.15,
        2.5,
        6,
        Cap::Center,
        Cap::Center,
    );
}

#[cfg(test)]
mod tests {
    use super::super::check;
    use super::*;

    #[test]
    fn camera_has_738_triangles() {
        let m = camera_mesh();
        assert_eq!(m.triangle_count(), CAMERA_TRIANGLES);
        let tally: Vec<(&str, usize)> = m
            .parts
            .iter()
            .map(|p| (p.name.as_str(), p.faces.len()))
            .collect();
        assert_eq!(
            tally,
            [
                ("body", 92),
                ("prism housing", 44),
                ("eyepiece", 12),
                ("hot shoe", 12),
                ("lens", 360),
                ("shutter dial", 62),
                ("shutter button", 38),
                ("rewind knob", 46),
                ("advance lever", 12),
                ("strap lugs", 24),
                ("self-timer lever", 12),
                ("lens release", 24),
            ]
        );
    }

    #[test]
    fn camera_is_well_formed_and_watertight() {
        check::all_closed(&camera_mesh());
    }

    #[test]
    fn camera_size() {
        let (lo, hi, size) = check::resting_bounds(&camera_mesh());
        assert!((13.5..=15.0).contains(&size[0]), "width {size:?}");
        assert!((8.5..=9.5).contains(&size[1]), "height {size:?}");
        // Body about 6 deep including the eyepiece; the lens adds about 5 towards -z.
        assert!(hi[2] > 2.0 && hi[2] < 3.5, "back {hi:?}");
        assert!(lo[2] < -6.5 && lo[2] > -8.5, "lens front {lo:?}");
        assert!((lo[0] + hi[0]).abs() < 0.5, "centred in x");
    }
}
