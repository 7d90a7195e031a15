//! The building section: the analog of the 170-triangle "building section" of LINKS-1's
//! Photo 2. A two-storey house with a gable roof, cut open along its front (z = -5, facing
//! the viewer at -z) like an architect's section: the foundation and side walls, the back
//! wall with a window in the upper storey, the first floor, a stair flight up to it and a
//! column under the stairwell edge of the floor.
//!
//! About 31.6 wide (x, roof eaves; the walls are 30), 20 tall (y, bottom at y = 0) and 10
//! deep (z from -5 to 5, the roof overhangs the back by 0.5).
//!
//! Triangle tally (part -> triangles):
//!
//! | part        | construction                                                           | tris |
//! |-------------|------------------------------------------------------------------------|------|
//! | shell       | U-shaped section (foundation + side walls, 8 corners) extruded in z: 2 x 6 ends + 8 x 2 sides | 28 |
//! | back wall   | gable-shaped wall (5 corners) with a window hole (4 corners): 2 x 9 faces + 9 x 2 sides | 36 |
//! | first floor | box                                                                    |   12 |
//! | roof        | chevron section (6 corners) extruded in z: 2 x 4 ends + 6 x 2 sides    |   20 |
//! | stair       | 6 steps: 14-corner section extruded in z: 2 x 12 ends + 14 x 2 sides   |   52 |
//! | column      | hexagonal, smooth: 6 x 2 sides + 6 (top, centre fan) + 4 (bottom fan)  |   22 |
//! | **total**   |                                                                        |  170 |
//!
//! (Every extruded or lofted part has an even number of vertices and so a multiple of 4
//! triangles; the column's single centre fan gives it an odd vertex count, 22 triangles,
//! which is what makes 170 reachable.)

use super::mesh::{Basis, Cap, GenMesh, MeshBuilder};

/// Triangles in [`building_section_mesh`], as in the paper's Photo 2.
pub const BUILDING_TRIANGLES: usize = 170;

/// Everything is hard-edged except the column.
const HARD: f64 = 30.0;

/// Roof: ridge underside at (0, 19.2), 0.8 thick (vertically), slope 0.42, eaves at ±15.8.
const RIDGE_UNDER: f64 = 19.2;
const ROOF_THICK: f64 = 0.8;
const ROOF_SLOPE: f64 = 0.42;
const EAVES: f64 = 15.8;

/// The roof's underside height at `x`.
fn roof_under(x: f64) -> f64 {
    RIDGE_UNDER - x.abs() * ROOF_SLOPE
}

/// Walls: outer faces at x = ±15, 0.6 thick; the back wall's inner face at z = 4.4.
const WALL_OUT: f64 = 15.0;
const WALL_IN: f64 = 14.4;
/// Top of the foundation (the ground-floor level).
const GROUND: f64 = 0.8;
/// First floor slab.
const FLOOR_BOTTOM: f64 = 6.2;
const FLOOR_TOP: f64 = 6.8;
/// The floor's free edge over the stairwell.
const STAIRWELL_EDGE: f64 = -3.0;
const FRONT: f64 = -5.0;
const BACK_IN: f64 = 4.4;
const BACK: f64 = 5.0;

/// The building section: see the module docs for the parts and their triangle counts.
pub fn building_section_mesh() -> GenMesh {
    let mut b = MeshBuilder::new();
    // Sections drawn in (x, y), extruded along +z.
    let along_z = Basis::new([0.0; 3], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]);

    // Foundation and side walls, one U-shaped section; the wall tops follow the roof.
    b.begin_part("shell", true, HARD);
    b.add_extruded_polygon(
        &along_z,
        &[
            [-WALL_OUT, 0.0],
            [WALL_OUT, 0.0],
            [WALL_OUT, roof_under(WALL_OUT)],
            [WALL_IN, roof_under(WALL_IN)],
            [WALL_IN, GROUND],
            [-WALL_IN, GROUND],
            [-WALL_IN, roof_under(WALL_IN)],
            [-WALL_OUT, roof_under(WALL_OUT)],
        ],
        FRONT,
        BACK,
    );

    // Back wall up into the gable, with a window in the upper storey. Hand-triangulated
    // around the hole: below (2), right (2), above (3, a convex pentagon), left (2).
    b.begin_part("back wall", true, HARD);
    let (wx0, wx1, wy0, wy1) = (3.0, 11.0, 8.8, 11.8);
    let pts = [
        [-WALL_IN, GROUND],              // 0
        [WALL_IN, GROUND],               // 1
        [WALL_IN, roof_under(WALL_IN)],  // 2
        [0.0, RIDGE_UNDER],              // 3
        [-WALL_IN, roof_under(WALL_IN)], // 4
        [wx0, wy0],                      // 5 window corners
        [wx1, wy0],                      // 6
        [wx1, wy1],                      // 7
        [wx0, wy1],                      // 8
    ];
    let tris = [
        [0, 1, 6],
        [0, 6, 5],
        [1, 2, 7],
        [1, 7, 6],
        [8, 7, 2],
        [8, 2, 3],
        [8, 3, 4],
        [0, 5, 8],
        [0, 8, 4],
    ];
    b.add_extruded_triangulation(&along_z, &pts, &tris, BACK_IN, BACK);

    // First floor, leaving the stairwell open on the left.
    b.begin_part("first floor", true, HARD);
    b.add_box(
        [STAIRWELL_EDGE, FLOOR_BOTTOM, FRONT],
        [WALL_IN, FLOOR_TOP, BACK_IN],
    );

    // Gable roof: a chevron section, overhanging the back.
    b.begin_part("roof", true, HARD);
    let top = RIDGE_UNDER + ROOF_THICK;
    b.add_extruded_polygon(
        &along_z,
        &[
            [-EAVES, roof_under(EAVES)],
            [0.0, RIDGE_UNDER],
            [EAVES, roof_under(EAVES)],
            [EAVES, roof_under(EAVES) + ROOF_THICK],
            [0.0, top],
            [-EAVES, roof_under(EAVES) + ROOF_THICK],
        ],
        FRONT,
        BACK + 0.5,
    );

    // Stair: STEPS risers from the ground floor to the first floor, arriving at the
    // stairwell edge, with a sloping soffit underneath. 2 * STEPS + 2 corners.
    b.begin_part("stair", true, HARD);
    const STEPS: usize = 6;
    let rise = (FLOOR_TOP - GROUND) / STEPS as f64;
    let tread = 1.6;
    let x = |i: usize| STAIRWELL_EDGE - (STEPS - i) as f64 * tread;
    let mut section = vec![[x(0), GROUND]];
    for i in 0..STEPS {
        let y = GROUND + (i + 1) as f64 * rise;
        section.push([x(i), y]);
        section.push([x(i + 1), y]);
    }
    section.push([STAIRWELL_EDGE, 4.6]);
    b.add_extruded_polygon(&along_z, &section, -4.6, -1.4);

    // Column under the floor's edge, beside the stair: smooth hexagon.
    b.begin_part("column", true, 65.0);
    b.add_frustum(
        &Basis::y_up([-2.4, 0.0, 1.5]),
        0.45,
        0.45,
        GROUND,
        FLOOR_BOTTOM,
        6,
        Cap::Fan,
        Cap::Center,
    );

    b.finish()
}

#[cfg(test)]
mod tests {
    use super::super::check;
    use super::*;

    #[test]
    fn building_has_170_triangles() {
        let m = building_section_mesh();
        assert_eq!(m.triangle_count(), BUILDING_TRIANGLES);
        let tally: Vec<(&str, usize)> = m
            .parts
            .iter()
            .map(|p| (p.name.as_str(), p.faces.len()))
            .collect();
        assert_eq!(
            tally,
            [
                ("shell", 28),
                ("back wall", 36),
                ("first floor", 12),
                ("roof", 20),
                ("stair", 52),
                ("column", 22),
            ]
        );
    }

    #[test]
    fn building_is_well_formed_and_watertight() {
        check::all_closed(&building_section_mesh());
    }

    #[test]
    fn building_size() {
        let (lo, hi, size) = check::resting_bounds(&building_section_mesh());
        assert!((29.0..=32.0).contains(&size[0]), "width {size:?}");
        assert!((19.0..=21.0).contains(&size[1]), "height {size:?}");
        assert!((9.5..=11.0).contains(&size[2]), "depth {size:?}");
        assert!((lo[0] + hi[0]).abs() < 0.5, "centred in x");
        assert!((lo[2] + hi[2]).abs() < 1.0, "centred in z");
    }
}
