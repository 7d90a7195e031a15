//! The places ray-tracing numerics fail, one named test per case and number type (the
//! numerics issue's stability suite: f32, f64 and Q16.16 fixed point; fixed-point scenes
//! are the DM's Q16.16 rewrite of the same image). Cases
//! already covered elsewhere: shared edges and vertices and self-intersection
//! (`robustness.rs`), total internal reflection and nesting beyond the depth cap
//! (`analytic.rs`), thin metaball necks and tangent rays (`shared/src/shape/blob.rs`),
//! degenerate input (`host-sim/src/scene_file`, `shared/src/scene/compile`).

use links_core::desc::*;
use links_core::fixed_image::to_fixed;
use links_core::geom::{Aabb, Ray, RayInv, Vec3};
use links_core::image::SceneView;
use links_core::num::{Fx, Real};
use links_core::render::Tracer;
use links_core::shape::boxshape::BoxShape;
use links_tests::*;
use std::path::Path;

/// A length the backend resolves: f32 and f64 keep ~1e-7 relative; Q16.16 keeps 2^-16
/// absolute (1.5e-5) of the scaled scene.
fn resolution<T: Real>() -> f64 {
    if T::ABSOLUTE_ROUNDING {
        1e-3
    } else {
        1e-5
    }
}

fn v<T: Real>(x: f64, y: f64, z: f64) -> Vec3<T> {
    Vec3::new(T::from_f64(x), T::from_f64(y), T::from_f64(z))
}

/// Rays in the plane of a slab, along a box edge, and through its corners: the slab test
/// meets 0 * inf = NaN there and must neither report NaN-driven hits nor drop real ones.
fn slab_parallel_and_edge_rays<T: Real>() {
    let b = Aabb {
        min: v::<T>(-1.0, -1.0, -1.0),
        max: v::<T>(1.0, 1.0, 1.0),
    };
    let cases: [(Vec3<T>, Vec3<T>, bool); 8] = [
        // In the y = 1 face plane, parallel to it: touching counts as a hit.
        (v(0.0, 1.0, -5.0), v(0.0, 0.0, 1.0), true),
        // Along the edge x = 1, y = 1.
        (v(1.0, 1.0, -5.0), v(0.0, 0.0, 1.0), true),
        // Just outside the face plane.
        (v(0.0, 1.0 + 1e-3, -5.0), v(0.0, 0.0, 1.0), false),
        // Through a corner diagonally.
        (v(-3.0, -3.0, -3.0), v(1.0, 1.0, 1.0), true),
        // Grazing past a corner.
        (v(-3.0, -3.0, -3.0 + 1e-2), v(1.0, 1.0, -1.0), false),
        // Axis-aligned with two zero components, inside the slab of both.
        (v(0.5, 0.5, 9.0), v(0.0, 0.0, -1.0), true),
        // Axis-aligned, outside one slab.
        (v(2.0, 0.5, 9.0), v(0.0, 0.0, -1.0), false),
        // Starting inside.
        (v(0.0, 0.0, 0.0), v(0.0, 1.0, 0.0), true),
    ];
    for (k, (o, d, want)) in cases.into_iter().enumerate() {
        let ray = Ray::new(o, d);
        assert_eq!(
            b.hit(&ray, &RayInv::new(d), T::MAX),
            want,
            "{} slab case {k}",
            T::NAME
        );
    }
    // The box primitive: a ray along its face plane touches it (no NaN normal).
    let bx = BoxShape {
        center: v::<T>(0.0, 0.0, 10.0),
        m: links_core::geom::Mat3 {
            r: [v(0.5, 0.0, 0.0), v(0.0, 0.5, 0.0), v(0.0, 0.0, 0.5)],
        },
        l: links_core::geom::Mat3 {
            r: [v(2.0, 0.0, 0.0), v(0.0, 2.0, 0.0), v(0.0, 0.0, 2.0)],
        },
    };
    let ray = Ray::new(v::<T>(2.0, 0.0, 0.0), v::<T>(0.0, 0.0, 1.0));
    let h = bx
        .intersect(&ray, T::MAX)
        .expect("a ray in a face plane touches the box");
    let s = bx.surface(&ray, &h, T::ZERO);
    assert!(s.n.is_finite() && s.p.is_finite(), "{}: {s:?}", T::NAME);
}

/// Rays passing a sphere and an ellipsoid at distances just inside and outside their
/// silhouette: hit exactly when inside, never NaN.
fn grazing_rays_on_spheres_and_ellipsoids<T: Real>() {
    for (name, radii) in [("sphere", [2.0; 3]), ("ellipsoid", [3.0, 1.5, 0.5])] {
        let s = scene(
            4,
            4,
            40.0,
            vec![Shape::Ellipsoid {
                center: [0.0, 0.0, -20.0],
                radii,
                rotate_deg: [0.0; 3],
                cut: None,
                material: 0,
            }],
        );
        let img = for_backend::<T>(image_of(&s));
        let mut tracer = Tracer::<T>::new(SceneView::new(&img).unwrap());
        let rx = radii[0];
        // The image stores the shape in f32 (1/3 is not exact), so the silhouette is known to
        // ~1e-7 relative for the floats: test 1e-5 either side of it (1e-3 for Q16.16).
        let eps = resolution::<T>();
        for (off, want) in [(-eps, true), (eps, false), (-0.1, true), (0.1, false)] {
            let x = rx * (1.0 + off);
            let ray = Ray::new(v::<T>(x, 0.0, 0.0), v::<T>(0.0, 0.0, 1.0));
            let hit = tracer.first_surface(&ray);
            assert_eq!(hit.is_some(), want, "{} {name} at x = {x}", T::NAME);
            if let Some((t, surf)) = hit {
                assert!(
                    t.is_finite() && surf.ng.is_finite() && surf.p.is_finite(),
                    "{} {name}",
                    T::NAME
                );
            }
        }
    }
}

/// The eye inside a sphere, a box and a blob: every pixel sees the inside, finite colours.
fn eye_inside_an_object<T: Real>() {
    let shapes = [
        (
            "sphere",
            Shape::Ellipsoid {
                center: [0.0, 0.0, -1.0],
                radii: [5.0; 3],
                rotate_deg: [0.0; 3],
                cut: None,
                material: 1,
            },
        ),
        (
            "box",
            Shape::Box {
                min: [-3.0, -2.0, -4.0],
                max: [3.0, 2.0, 4.0],
                material: 1,
            },
        ),
        (
            "blob",
            Shape::Blobs {
                balls: vec![Ball {
                    center: [0.0; 3],
                    radius: 8.0,
                    strength: 1.0,
                }],
                threshold: 0.5,
                kernel: BlobKernel::Links,
                material: 1,
            },
        ),
    ];
    for (name, shape) in shapes {
        for glass in [false, true] {
            let mut s = scene(12, 10, 90.0, vec![shape.clone()]);
            s.ambient = [0.3; 3];
            s.lights = vec![Light::Point {
                pos: [0.5, 0.5, 0.0],
                color: [1.0; 3],
                falloff: false,
            }];
            s.materials.push(Material {
                name: "m".into(),
                diffuse: [0.6, 0.5, 0.4],
                transmit: if glass { [0.8; 3] } else { [0.0; 3] },
                ior: if glass { 1.5 } else { 1.0 },
                ..Material::default()
            });
            let img = for_backend::<T>(image_of(&s));
            let mut tracer = Tracer::<T>::new(SceneView::new(&img).unwrap());
            for y in 0..10 {
                for x in 0..12 {
                    let ray = tracer.primary_ray(x, y);
                    assert!(
                        tracer.first_surface(&ray).is_some(),
                        "{} {name}: pixel ({x},{y}) sees no inside",
                        T::NAME
                    );
                    let c = tracer.pixel(x, y);
                    assert!(
                        c.is_finite(),
                        "{} {name} glass={glass}: pixel ({x},{y}) = {c:?}",
                        T::NAME
                    );
                    assert!(
                        c.max_component() > T::ZERO,
                        "{} {name}: the inside is lit",
                        T::NAME
                    );
                }
            }
        }
    }
}

/// Every bundled scene renders without a single NaN or infinite colour (before quantising).
fn no_nan_in_any_bundled_scene<T: Real>() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "ron") {
            continue;
        }
        let desc = links_host::scene_file::load_scene(&path).unwrap();
        let opts = links_core::dm::CompileOptions {
            width: Some(48),
            height: Some(45),
            ..Default::default()
        };
        let img = for_backend::<T>(links_core::dm::compile(&desc, &opts).unwrap().bytes);
        let mut tracer = Tracer::<T>::new(SceneView::new(&img).unwrap());
        for y in 0..45 {
            tracer.begin_run(y);
            for x in 0..48 {
                let c = tracer.pixel(x, y);
                assert!(
                    c.is_finite(),
                    "{} {}: pixel ({x},{y}) = {c:?}",
                    T::NAME,
                    path.display()
                );
            }
        }
        n += 1;
    }
    assert!(n >= 6);
}

/// Two overlapping coplanar triangles in separate leaves with flat boxes: every technique
/// must pick the same one as the plain walk (ties go to the lower node). Found by review:
/// a flat box's computed entry can lie an ulp beyond the triangle's computed hit.
fn coplanar_overlaps_resolve_like_the_plain_walk<T: Real>() {
    use links_core::render::Techniques;
    let tri = |x: f64, m: u32| Shape::Triangle {
        v: [[x - 3.0, -2.0, -3.0], [x + 3.0, -2.0, -3.0], [x, 3.0, -3.0]],
        normals: None,
        uv: None,
        material: m,
    };
    let mut s = scene(64, 64, 90.0, vec![tri(-0.5, 1), tri(0.5, 2)]);
    s.ambient = [1.0; 3];
    s.materials.push(matte("red", [1.0, 0.0, 0.0]));
    s.materials.push(matte("green", [0.0, 1.0, 0.0]));
    for h in [
        links_core::dm::MeshHierarchy::Flat,
        links_core::dm::MeshHierarchy::Sah,
    ] {
        let opts = links_core::dm::CompileOptions {
            mesh_hierarchy: h,
            ..Default::default()
        };
        let img = for_backend::<T>(links_core::dm::compile(&s, &opts).unwrap().bytes);
        let plain = render_all_with::<T>(&img, Techniques::PAPER_TYPE_4).0;
        for t in [
            Techniques::ALL,
            Techniques::PAPER_TYPE_1,
            Techniques::PAPER_TYPE_2,
            Techniques::PAPER_TYPE_3,
        ] {
            let got = render_all_with::<T>(&img, t).0;
            let off = got.iter().zip(&plain).filter(|(a, b)| a != b).count();
            assert_eq!(
                off,
                0,
                "{} {h:?} {t:?}: {off} values differ from the plain walk",
                T::NAME
            );
        }
    }
}

/// A spot light wider than 180° total with a fractional exponent: points behind it see a
/// negative cosine, which `powf` would turn into NaN and blacken the whole pixel.
fn wide_spot_with_fractional_exponent_stays_finite<T: Real>() {
    let mut s = scene(
        16,
        16,
        120.0,
        vec![Shape::Box {
            min: [-20.0, -20.0, -12.0],
            max: [20.0, 20.0, -10.0],
            material: 1,
        }],
    );
    s.ambient = [0.2; 3];
    s.materials.push(matte("wall", [0.8; 3]));
    s.lights = vec![Light::Spot {
        pos: [0.0, 0.0, -9.0],
        dir: [0.0, 0.0, 1.0],
        color: [1.0; 3],
        inner_deg: 30.0,
        outer_deg: 150.0,
        exponent: 1.5,
    }];
    let img = for_backend::<T>(image_of(&s));
    let mut tracer = Tracer::<T>::new(SceneView::new(&img).unwrap());
    for y in 0..16 {
        for x in 0..16 {
            let c = tracer.pixel(x, y);
            assert!(c.is_finite(), "{} ({x},{y}): {c:?}", T::NAME);
            // The wall faces away from the spot: only ambient light, never black.
            assert!(
                (c.x.to_f64() - 0.16).abs() < resolution::<T>(),
                "{} ({x},{y}): {c:?}",
                T::NAME
            );
        }
    }
}

/// Glass spheres between two mirrors at depth 16: the ray tree would be 2^17 rays per pixel;
/// the per-pixel budget bounds it, and the colour stays finite.
fn deep_mirror_and_glass_trees_are_bounded<T: Real>() {
    use links_core::render::SECONDARY_RAYS_PER_PIXEL;
    let mut shapes = vec![
        Shape::Box {
            min: [-30.0, -30.0, -41.0],
            max: [30.0, 30.0, -40.0],
            material: 1,
        },
        Shape::Box {
            min: [-30.0, -30.0, 1.0],
            max: [30.0, 30.0, 2.0],
            material: 1,
        },
    ];
    for k in 0..4 {
        shapes.push(Shape::Ellipsoid {
            center: [0.0, 0.0, -8.0 - 8.0 * k as f64],
            radii: [3.0; 3],
            rotate_deg: [0.0; 3],
            cut: None,
            material: 2,
        });
    }
    let mut s = scene(3, 3, 20.0, shapes);
    s.max_depth = 16;
    s.ambient = [0.1; 3];
    s.materials.push(Material {
        name: "mirror".into(),
        diffuse: [0.1; 3],
        reflect: 1.0,
        reflect_edge: 1.0,
        ..Material::default()
    });
    s.materials.push(Material {
        name: "glass".into(),
        diffuse: [0.0; 3],
        reflect: 0.5,
        reflect_edge: 0.5,
        transmit: [0.9; 3],
        ior: 1.5,
        ..Material::default()
    });
    let img = for_backend::<T>(image_of(&s));
    let mut tracer = Tracer::<T>::new(SceneView::new(&img).unwrap());
    let c = tracer.pixel(1, 1);
    let st = tracer.stats;
    assert!(c.is_finite(), "{}: {c:?}", T::NAME);
    let recursive = st.reflect_rays + st.refract_rays;
    assert!(
        recursive > 1000,
        "{}: the scene really is deep ({recursive} rays)",
        T::NAME
    );
    assert!(
        recursive <= SECONDARY_RAYS_PER_PIXEL as u64,
        "{}: {recursive} recursive rays",
        T::NAME
    );
}

macro_rules! per_backend {
    ($($case:ident),*) => {
        mod f32_backend {
            $( #[test] fn $case() { super::$case::<f32>() } )*
        }
        mod f64_backend {
            $( #[test] fn $case() { super::$case::<f64>() } )*
        }
        mod q16_16_backend {
            $( #[test] fn $case() { super::$case::<links_core::num::Fx>() } )*
        }
    };
}

per_backend!(
    slab_parallel_and_edge_rays,
    grazing_rays_on_spheres_and_ellipsoids,
    eye_inside_an_object,
    no_nan_in_any_bundled_scene,
    coplanar_overlaps_resolve_like_the_plain_walk,
    wide_spot_with_fractional_exponent_stays_finite,
    deep_mirror_and_glass_trees_are_bounded
);

/// A test scene (a glass sphere, a matte box, a floor, a point light) with every length
/// times `scale`.
fn scaled_scene(scale: f64) -> SceneDesc {
    let sc = |p: [f64; 3]| p.map(|x| x * scale);
    let mut s = scene(
        24,
        20,
        50.0,
        vec![
            Shape::Ellipsoid {
                center: sc([-1.5, 0.0, -8.0]),
                radii: [1.2 * scale; 3],
                rotate_deg: [0.0; 3],
                cut: None,
                material: 2,
            },
            Shape::Box {
                min: sc([0.5, -1.0, -9.0]),
                max: sc([2.5, 1.0, -7.0]),
                material: 1,
            },
            Shape::Box {
                min: sc([-20.0, -2.0, -30.0]),
                max: sc([20.0, -1.5, 0.0]),
                material: 1,
            },
        ],
    );
    s.camera.eye = sc(s.camera.eye);
    s.camera.look_at = sc(s.camera.look_at);
    s.ambient = [0.2; 3];
    s.materials.push(matte("wall", [0.7, 0.6, 0.5]));
    s.materials.push(Material {
        name: "glass".into(),
        diffuse: [0.1; 3],
        transmit: [0.8; 3],
        ior: 1.5,
        ..Material::default()
    });
    s.lights = vec![Light::Point {
        pos: sc([3.0, 6.0, 0.0]),
        color: [1.0; 3],
        falloff: false,
    }];
    s
}

/// The DM fits any scene's extent to the format by a power of two: the same scene at
/// 2^-12, 1, 2^8 and 2^13 times its size (the last far beyond Q16.16's +-32768 as given)
/// becomes the same Q16.16 image, renders the same pixels, and stays close to f64.
#[test]
fn q16_16_scenes_at_any_extent_are_rescaled_not_wrapped() {
    let base = image_of(&scaled_scene(1.0));
    let fixed = to_fixed(&base).unwrap();
    let pixels = render_all::<Fx>(&fixed.bytes);
    let reference = render_all::<f64>(&base);
    let psnr = links_host::frame::psnr(&pixels, &reference);
    assert!(psnr >= 40.0, "{psnr} dB");
    for e in [-12, 8, 13] {
        let img = image_of(&scaled_scene(2f64.powi(e)));
        let f = to_fixed(&img).unwrap();
        assert_eq!(
            f.scale_exponent as i32,
            fixed.scale_exponent as i32 - e,
            "2^{e}"
        );
        // Identical apart from the header's scale exponent.
        assert_eq!(f.bytes[..7], fixed.bytes[..7]);
        assert_eq!(f.bytes[8..], fixed.bytes[8..], "2^{e}");
        assert_eq!(render_all::<Fx>(&f.bytes), pixels, "2^{e}");
    }
}

/// A scene the format can't hold is rejected with the record that doesn't fit: a tiny
/// sphere beside a huge floor (the scale the extent allows leaves the sphere under a step),
/// and any scale that would overflow the format.
#[test]
fn q16_16_rejects_scenes_beyond_its_range() {
    use links_core::fixed_image::{to_fixed_with_scale, FixedError};
    let mut s = scaled_scene(1.0);
    s.root.children.push(Node::Shape(Shape::Box {
        min: [-1e6, -3.0, -1e6],
        max: [1e6, -2.5, -10.0],
        material: 1,
    }));
    s.root.children.push(Node::Shape(Shape::Ellipsoid {
        center: [0.0, 0.0, -6.0],
        radii: [1e-4; 3],
        rotate_deg: [0.0; 3],
        cut: None,
        material: 1,
    }));
    let img = image_of(&s);
    match to_fixed(&img) {
        Err(e @ FixedError::DetailBelowPrecision { .. }) => {
            assert!(e.to_string().contains("steps of Q16.16"), "{e}")
        }
        other => panic!("expected a precision error, got {other:?}"),
    }
    let fine = image_of(&scaled_scene(1.0));
    let k = to_fixed(&fine).unwrap().scale_exponent;
    // Twelve powers of two beyond the chosen scale: the floor no longer fits.
    match to_fixed_with_scale(&fine, k + 12) {
        Err(FixedError::OutOfRange { value, .. }) => assert!(value.abs() >= 32768.0),
        other => panic!("expected a range error, got {other:?}"),
    }
}

/// Arithmetic that overflows inside the tracer becomes an infinity or NaN that the tracer
/// treats as "no hit", never a wrapped value that would hit something at a wrong place:
/// a sphere 400 radii from the eye (|o|² = 160,000 in its unit frame) is still hit by the
/// rays aimed at it (the solver starts at the closest approach) and only there.
#[test]
fn q16_16_far_small_sphere_is_hit_where_it_is() {
    let mut s = scene(
        32,
        32,
        1.0,
        vec![Shape::Ellipsoid {
            center: [0.0, 0.0, -20.0],
            radii: [0.05; 3],
            rotate_deg: [0.0; 3],
            cut: None,
            material: 0,
        }],
    );
    s.background = [0.5, 0.5, 0.9];
    s.ambient = [1.0; 3];
    let img = image_of(&s);
    let f = to_fixed(&img).unwrap();
    let (a, b) = (render_all::<f64>(&img), render_all::<Fx>(&f.bytes));
    // Background or sphere, per pixel (colours within 2/255 of the background's).
    let bg = [128u8, 128, 230];
    let mask = |p: &[u8]| -> Vec<bool> {
        p.chunks(3)
            .map(|c| c.iter().zip(bg).any(|(x, y)| x.abs_diff(y) > 2))
            .collect()
    };
    let (ma, mb) = (mask(&a), mask(&b));
    let hits = ma.iter().filter(|h| **h).count();
    assert!(hits > 40, "the sphere covers pixels ({hits})");
    let differ = ma.iter().zip(&mb).filter(|(x, y)| x != y).count();
    assert!(
        differ <= 4,
        "{differ} of {} pixels differ in hit/miss",
        ma.len()
    );
}
