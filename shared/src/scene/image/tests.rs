use super::*;
use crate::geom::Vec3;
use crate::num::{Real, Storage};
use crate::testkit::scene::{textured_image as textured, tiny_image as image};

/// Every pixel of an image with number type `T`.
fn render_every_pixel<T: Real>(view: SceneView<'_>) -> std::vec::Vec<crate::render::Rgb8> {
    let f = view.camera::<f32>();
    let mut tracer = crate::render::Tracer::<T>::new(view);
    let mut row = std::vec![[0u8; 3]; f.width as usize];
    let mut out = std::vec::Vec::new();
    for y in 0..f.height {
        crate::render::render_run(&mut tracer, y, 0, &mut row).unwrap();
        out.extend_from_slice(&row);
    }
    out
}

#[test]
fn a_texture_that_fits_its_texels_is_sampled_in_every_number_format() {
    let texels = [200, 100, 50].repeat(4);
    for storage in [Storage::F32, Storage::Q16_16] {
        let img = textured(storage, (2, 2, 0), &texels);
        let view = SceneView::new(&img).unwrap();
        let px: std::vec::Vec<_> = match storage {
            Storage::F32 => {
                let a = render_every_pixel::<f32>(view);
                assert_eq!(a, render_every_pixel::<f64>(view));
                a
            }
            Storage::Q16_16 => render_every_pixel::<crate::num::Fx>(view),
        };
        assert_eq!(px.len(), 16);
        for p in px {
            for (got, want) in p.iter().zip([200u8, 100, 50]) {
                assert!(got.abs_diff(want) <= 1, "{storage:?}: {p:?}");
            }
        }
    }
}

#[test]
fn texture_sizes_whose_arithmetic_overflows_are_rejected() {
    let texels = [7u8; 36];
    let textures = |section: u8| ImageError::BadReference { section, record: 0 };
    let t = Section::Textures as u8;
    // 1684887088 x 3649452082 x 3 = 2^64 + 32: a u64 product wraps to 32 bytes, which
    // the 36 texels "hold"; sampling then indexes gigabytes past them.
    let wraps_u64 = (1_684_887_088, 3_649_452_082, 0);
    // w * h * 3 = 3 * 2^32: wraps a u32 (a 32-bit usize) to 0.
    let wraps_u32 = (65_536, 65_536, 0);
    // The offset plus the texture's bytes pass u32::MAX.
    let offset_wraps = (1, 1, u32::MAX - 1);
    // One byte more than the texels: the exact bound.
    let one_past = (3, 4, 1);
    for storage in [Storage::F32, Storage::Q16_16] {
        for tex in [wraps_u64, wraps_u32, offset_wraps, one_past] {
            let img = textured(storage, tex, &texels);
            assert_eq!(
                SceneView::new(&img).err(),
                Some(textures(t)),
                "{storage:?} texture {tex:?}"
            );
        }
        // The largest texture the texels hold is accepted and rendered.
        let img = textured(storage, (3, 4, 0), &texels);
        let view = SceneView::new(&img).unwrap();
        let px = match storage {
            Storage::F32 => render_every_pixel::<f32>(view),
            Storage::Q16_16 => render_every_pixel::<crate::num::Fx>(view),
        };
        assert!(px.iter().flatten().all(|&c| c.abs_diff(7) <= 1), "{px:?}");
    }
}

#[test]
fn a_well_formed_tree_is_accepted() {
    let img = image(8, &[(3, NONE), (3, NONE), (3, 0)]);
    assert!(SceneView::new(&img).is_ok());
}

#[test]
fn trees_that_could_mislead_a_walk_are_rejected() {
    let nodes_error = |r: Result<SceneView<'_>, ImageError>| matches!(r, Err(ImageError::BadReference { section, .. }) if section == Section::Nodes as u8);
    // No nodes at all: node 0 would be read from the header.
    assert!(nodes_error(SceneView::new(&image(8, &[]))));
    // Two top-level trees: closest-hit walks only node 0's.
    assert!(nodes_error(SceneView::new(&image(8, &[(1, NONE), (2, 0)]))));
    // A child's subtree ending beyond its parent's (exponential walks).
    assert!(nodes_error(SceneView::new(&image(
        8,
        &[(5, NONE), (3, NONE), (4, NONE), (4, 0), (5, 0)]
    ))));
}

#[test]
fn cameras_wider_than_the_u16_pixel_range_are_rejected() {
    assert!(SceneView::new(&image(65535, &[(1, NONE)])).is_ok());
    assert!(matches!(
        SceneView::new(&image(65536, &[(1, NONE)])),
        Err(ImageError::BadValue { .. })
    ));
}

#[test]
fn records_out_of_range_read_as_zeros_not_other_bytes() {
    let img = image(8, &[(1, NONE)]);
    let v = SceneView::new(&img).unwrap();
    // There are no ellipsoids: the section offset is 0 (the header) but nothing is read.
    let e = v.ellipsoid::<f32>(0);
    assert_eq!(e.material, 0);
    assert_eq!(e.shape.center, Vec3::zero());
    // A triangle that is not there reads as a zero record: vertex 0 three times.
    let t = v.triangle::<f32>(u32::MAX).tri.p;
    assert_eq!(t, [v.triangle::<f32>(0).tri.p[0]; 3]);
    // No textures: one black texel, not an empty one (sampling divides by its size).
    let t = v.texture(0);
    assert_eq!((t.width, t.height, t.texels), (1, 1, &[0u8, 0, 0][..]));
    assert_eq!(t.texel(0, 0), [0, 0, 0]);
    assert_eq!(v.record_range(Section::Ellipsoids, 0), None);
    assert_eq!(
        v.record_range(Section::Camera, 0),
        Some(HEADER_SIZE..HEADER_SIZE + CAMERA_SIZE)
    );
}

/// A node decoded a part at a time ([`NodeRef`]) gives what the whole decode gives, for
/// every node of a DM-built tree (clusters and leaves, boxes on the grid).
#[cfg(feature = "std")]
#[test]
fn a_node_decoded_part_by_part_equals_the_whole_decode() {
    use crate::desc::{Camera, Node, Shape};
    use crate::dm::{compile, CompileOptions};
    let camera = Camera {
        eye: [0.0, 1.0, -6.0],
        look_at: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 45.0,
    };
    let shapes = (0..40)
        .map(|k| {
            let x = k as f64 * 0.37 - 7.0;
            let z = (k % 7) as f64 * 0.9;
            Node::Shape(Shape::Triangle {
                v: [[x, -1.0, z], [x + 0.5, 0.2, z + 0.3], [x, 1.3, z - 0.4]],
                normals: None,
                uv: None,
                material: 0,
            })
        })
        .collect();
    let desc = crate::testkit::scene::scene_desc(camera, 32, 24, shapes);
    let bytes = compile(&desc, &CompileOptions::default())
        .expect("compiles")
        .bytes;
    let view = SceneView::new(&bytes).expect("valid");
    assert!(view.node_count() > 10);
    let table = view.node_table();
    assert_eq!(table.len(), view.node_count());
    for i in 0..view.node_count() {
        let (whole, part) = (view.node::<f32>(i), table.get(i));
        for axis in 0..3 {
            let (lo, hi) = part.span::<f32>(axis);
            assert_eq!(
                lo.to_bits(),
                whole.bounds.min[axis].to_bits(),
                "node {i} axis {axis}"
            );
            assert_eq!(
                hi.to_bits(),
                whole.bounds.max[axis].to_bits(),
                "node {i} axis {axis}"
            );
        }
        assert_eq!(part.leaf(), whole.leaf, "node {i}");
        assert_eq!(part.skip(i), whole.skip, "node {i}");
    }
}
