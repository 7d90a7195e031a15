//! Analytic cases: renders compared with eq. 2.1 / 2.2 worked out independently here.

use links_core::desc::*;
use links_tests::*;

/// Direction of pixel (x, y)'s primary ray in view coordinates, computed from the camera.
fn pixel_dir(w: u32, h: u32, fov_y_deg: f64, x: u32, y: u32) -> [f64; 3] {
    let tan_half = (fov_y_deg.to_radians() / 2.0).tan();
    let d = 2.0 * tan_half / h as f64;
    let v = [
        -d * w as f64 / 2.0 + (x as f64 + 0.5) * d,
        tan_half - (y as f64 + 0.5) * d,
        1.0,
    ];
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / l)
}

use links_host::vec3::dot;

fn q8(v: f64) -> i32 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5).floor() as i32
}

#[test]
fn sphere_under_parallel_light_matches_eq_2_1() {
    let (w, h, fov) = (64, 48, 40.0);
    let mut s = scene(
        w,
        h,
        fov,
        vec![Shape::Ellipsoid {
            center: [0.0, 0.0, -10.0],
            radii: [3.0; 3],
            rotate_deg: [0.0; 3],
            cut: None,
            material: 0,
        }],
    );
    s.ambient = [0.2, 0.2, 0.2];
    s.materials[0] = Material {
        diffuse: [0.7, 0.5, 0.3],
        specular: 0.4,
        specular_edge: 0.9,
        shininess: 12.0,
        ..Material::default()
    };
    // World direction the light travels; in view coordinates z flips.
    let lw = [-1.0f64, -2.0, -1.5];
    s.lights = vec![Light::Directional {
        dir: lw,
        color: [0.9, 0.9, 0.8],
    }];
    let img = image_of(&s);

    let ll = dot(lw, lw).sqrt();
    let to_light = [-lw[0] / ll, -lw[1] / ll, lw[2] / ll];
    let mut checked = 0;
    for (x, y) in [(32, 24), (28, 20), (36, 30), (25, 27), (40, 18), (31, 14)] {
        let d = pixel_dir(w, h, fov, x, y);
        // |t d - c|² = r² with c = (0, 0, 10) in view coordinates.
        let c = [0.0, 0.0, 10.0];
        let b = dot(d, c);
        let disc = b * b - (dot(c, c) - 9.0);
        assert!(disc > 0.0, "pixel ({x},{y}) must see the sphere");
        let t = b - disc.sqrt();
        let p = d.map(|v| v * t);
        let n = [0, 1, 2].map(|k| (p[k] - c[k]) / 3.0);
        let cos_t = dot(n, to_light).max(0.0);
        let view = d.map(|v| -v);
        let r = [0, 1, 2].map(|k| 2.0 * cos_t * n[k] - to_light[k]);
        let cos_p = dot(r, view).max(0.0);
        let src = 0.4 + (0.9 - 0.4) * (1.0 - cos_t).powi(5);
        let diffuse = [0.7, 0.5, 0.3];
        let ls = [0.9, 0.9, 0.8];
        let expect: Vec<i32> = (0..3)
            .map(|k| {
                let spec = if cos_t > 0.0 {
                    src * ls[k] * cos_p.powf(12.0)
                } else {
                    0.0
                };
                q8(diffuse[k] * 0.2 + diffuse[k] * ls[k] * cos_t + spec)
            })
            .collect();
        for got in [pixel::<f64>(&img, x, y), pixel::<f32>(&img, x, y)] {
            for k in 0..3 {
                assert!(
                    (got[k] as i32 - expect[k]).abs() <= 1,
                    "pixel ({x},{y}) channel {k}: got {got:?}, eq. 2.1 gives {expect:?}"
                );
            }
        }
        checked += 1;
    }
    assert_eq!(checked, 6);
}

#[test]
fn mirror_reflects_a_known_colour() {
    // A mirror square facing the eye, tilted 45° about Y, reflects a red box to the side.
    let (w, h, fov) = (33, 33, 20.0);
    let mirror = Shape::Box {
        min: [-2.0, -2.0, -0.05],
        max: [2.0, 2.0, 0.05],
        material: 1,
    };
    let mut s = scene(
        w,
        h,
        fov,
        vec![Shape::Box {
            min: [8.0, -3.0, -14.0],
            max: [9.0, 3.0, -6.0],
            material: 2,
        }],
    );
    s.root.children.push(Node::Cluster(Cluster {
        name: "mirror".into(),
        transform: Transform {
            translate: [0.0, 0.0, -10.0],
            rotate_deg: [0.0, 45.0, 0.0],
            scale: [1.0; 3],
        },
        children: vec![Node::Shape(mirror)],
    }));
    s.ambient = [1.0, 1.0, 1.0];
    s.materials.push(Material {
        name: "mirror".into(),
        diffuse: [0.0; 3],
        reflect: 1.0,
        reflect_edge: 1.0,
        ..Material::default()
    });
    s.materials.push(matte("red", [0.9, 0.1, 0.0]));
    let img = image_of(&s);
    // The centre ray meets the mirror at 45° and leaves along +X in view space: the box.
    assert_eq!(
        pixel::<f64>(&img, 16, 16),
        [q8(0.9) as u8, q8(0.1) as u8, 0]
    );
    assert_eq!(
        pixel::<f32>(&img, 16, 16),
        [q8(0.9) as u8, q8(0.1) as u8, 0]
    );
    // Without the reflection the mirror itself is black.
    let mut dull = s.clone();
    dull.materials[1].reflect = 0.0;
    dull.materials[1].reflect_edge = 0.0;
    assert_eq!(pixel::<f64>(&image_of(&dull), 16, 16), [0, 0, 0]);
}

#[test]
fn glass_slab_shifts_a_ray_by_the_snell_offset() {
    // Slab between view z = 4 and 6 (world z = -4..-6), ior 1.5, clear; a black wall at
    // z = 10 with a 0.02-wide white stripe. The stripe is seen only where Snell says.
    let (w, h, fov) = (101, 3, 40.0);
    let x = 80;
    let d = pixel_dir(w, h, fov, x, 1);
    assert_eq!(d[1], 0.0, "middle row of an odd-height frame is level");
    let tan_i = d[0] / d[2];
    let sin_i = d[0];
    let sin_t = sin_i / 1.5;
    let tan_t = sin_t / (1.0 - sin_t * sin_t).sqrt();
    let landing = 4.0 * tan_i + 2.0 * tan_t + 4.0 * tan_i;
    let straight = 10.0 * tan_i;
    let shift = straight - landing;
    assert!(shift > 0.1, "the test needs a visible shift, got {shift}");
    let build = |stripe_x: f64, slab: bool| {
        let mut shapes = vec![
            Shape::Box {
                min: [-50.0, -50.0, -10.5],
                max: [50.0, 50.0, -10.0],
                material: 1,
            },
            Shape::Box {
                min: [stripe_x - 0.01, -5.0, -10.0],
                max: [stripe_x + 0.01, 5.0, -9.999],
                material: 2,
            },
        ];
        if slab {
            shapes.push(Shape::Box {
                min: [-50.0, -50.0, -6.0],
                max: [50.0, 50.0, -4.0],
                material: 3,
            });
        }
        let mut s = scene(w, h, fov, shapes);
        s.ambient = [1.0; 3];
        s.materials.push(matte("wall", [0.0; 3]));
        s.materials.push(matte("stripe", [1.0; 3]));
        s.materials.push(Material {
            name: "glass".into(),
            diffuse: [0.0; 3],
            transmit: [1.0; 3],
            ior: 1.5,
            ..Material::default()
        });
        image_of(&s)
    };
    let lit = |img: &[u8]| pixel::<f64>(img, x, 1)[0] > 128;
    assert!(
        lit(&build(landing, true)),
        "refracted ray lands on the Snell-predicted spot"
    );
    assert!(!lit(&build(landing + 0.03, true)) && !lit(&build(landing - 0.03, true)));
    assert!(
        !lit(&build(straight, true)),
        "not where an unrefracted ray would land"
    );
    assert!(
        lit(&build(straight, false)),
        "without the slab the ray goes straight"
    );
    assert!(lit(&build(landing, true)) && pixel::<f32>(&build(landing, true), x, 1)[0] > 128);
}

#[test]
fn shadow_behind_a_half_transmitting_sheet_is_lit_at_half() {
    // A floor at y = 0 under parallel light at 45°; a sheet of tc = 0.5 hangs above x < 0.
    let (w, h, fov) = (41, 41, 60.0);
    let floor = Shape::Box {
        min: [-20.0, -1.0, -30.0],
        max: [20.0, 0.0, 0.0],
        material: 1,
    };
    let sheet = |y: f64| Shape::Triangle {
        v: [[-10.0, y, -2.0], [-10.0, y, -30.0], [0.0, y, -30.0]],
        normals: None,
        uv: None,
        material: 2,
    };
    let sheet2 = |y: f64| Shape::Triangle {
        v: [[-10.0, y, -2.0], [0.0, y, -30.0], [0.0, y, -2.0]],
        normals: None,
        uv: None,
        material: 2,
    };
    let mut s = scene(w, h, fov, vec![floor, sheet(3.0), sheet2(3.0)]);
    s.camera = Camera {
        eye: [0.0, 10.0, 5.0],
        look_at: [0.0, 0.0, -10.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: fov,
    };
    s.materials.push(matte("floor", [0.8, 0.8, 0.8]));
    s.materials.push(Material {
        name: "sheet".into(),
        diffuse: [0.0; 3],
        transmit: [0.5; 3],
        ..Material::default()
    });
    // Light travels toward +x and down: the sheet's shadow is shifted 3 units to +x.
    s.lights = vec![Light::Directional {
        dir: [1.0, -1.0, 0.0],
        color: [1.0; 3],
    }];
    s.transparency = TransparencyMode::NonRefractive;
    let img = image_of(&s);
    let full = q8(0.8 * std::f64::consts::FRAC_1_SQRT_2);
    let half = q8(0.4 * std::f64::consts::FRAC_1_SQRT_2);
    // Find floor pixels seen without crossing the sheet (right half of the screen), and
    // classify them by where the shadow must fall: x in (0, 3) is behind the sheet.
    let view = links_core::image::SceneView::new(&img).unwrap();
    let mut tracer = links_core::render::Tracer::<f64>::new(view);
    let fl = (100.0f64 + 225.0).sqrt();
    let fwd = [0.0, -10.0 / fl, -15.0 / fl];
    // up = right x forward with right = +x.
    let up = [0.0, -fwd[2], fwd[1]];
    let (mut n_full, mut n_half) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let ray = tracer.primary_ray(x, y);
            let Some((_, surf)) = tracer.first_surface(&ray) else {
                continue;
            };
            // View -> world: p = eye + right x + up y + forward z.
            let [vx, vy, vz] = surf.p.to_f64();
            let (wx, wy) = (vx, 10.0 + up[1] * vy + fwd[1] * vz);
            let wz = 5.0 + up[2] * vy + fwd[2] * vz;
            if surf.material != 1 || wy.abs() > 1e-6 {
                continue;
            }
            let px = pixel::<f64>(&img, x, y)[0] as i32;
            if wx > 0.2 && wx < 2.8 && wz < -2.2 && wz > -29.0 {
                assert!(
                    (px - half).abs() <= 1,
                    "({x},{y}) wx={wx}: {px} vs half {half}"
                );
                n_half += 1;
            } else if wx > 3.2 || wz > -1.8 {
                assert!(
                    (px - full).abs() <= 1,
                    "({x},{y}) wx={wx}: {px} vs full {full}"
                );
                n_full += 1;
            }
        }
    }
    assert!(n_half > 10 && n_full > 10, "half {n_half}, full {n_full}");

    // Without shadows the same floor is fully lit everywhere and no shadow ray is cast.
    let opts = links_core::dm::CompileOptions {
        no_shadows: true,
        ..Default::default()
    };
    let img = links_core::dm::compile(&s, &opts).unwrap().bytes;
    let (rgb, stats) = render_all_with::<f64>(&img, links_core::render::Techniques::ALL);
    assert_eq!(stats.shadow_rays, 0);
    let view = links_core::image::SceneView::new(&img).unwrap();
    let mut tracer = links_core::render::Tracer::<f64>::new(view);
    let mut lit = 0;
    for y in 0..h {
        for x in 0..w {
            let Some((_, surf)) = tracer.first_surface(&tracer.primary_ray(x, y)) else {
                continue;
            };
            let [vx, vy, vz] = surf.p.to_f64();
            let wz = 5.0 + up[2] * vy + fwd[2] * vz;
            let wy = 10.0 + up[1] * vy + fwd[1] * vz;
            if surf.material == 1 && wy.abs() < 1e-6 && vx > 0.2 && vx < 2.8 && wz < -2.2 {
                let px = rgb[((y * w + x) * 3) as usize] as i32;
                assert!(
                    (px - full).abs() <= 1,
                    "no shadows: ({x},{y}) {px} vs {full}"
                );
                lit += 1;
            }
        }
    }
    assert!(lit > 10);
}

/// LINKS-1's density kernel, written out independently of the renderer.
fn links_kernel(r: f64, d: f64, b: f64) -> f64 {
    if r <= d / 3.0 {
        b * (1.0 - 3.0 * r * r / (d * d))
    } else if r <= d {
        1.5 * b * (1.0 - r / d).powi(2)
    } else {
        0.0
    }
}

#[test]
fn metaball_surface_points_satisfy_the_iso_equation() {
    // Three balls in view space (world z negated); every hit pixel's point must satisfy
    // sum f = T to within the root finder's stated tolerance: |F - T| <= L * tol with
    // L = sum 2b/d and tol ~ 1.2e-4 d (f32) -- we allow 1e-3 absolute in f32, 1e-8 in f64.
    let balls = [
        ([-1.2, 0.0, -10.0], 2.5, 1.0),
        ([1.0, 0.4, -10.5], 2.0, 1.0),
        ([0.0, -1.5, -9.5], 1.8, 0.8),
    ];
    let mut s = scene(
        48,
        40,
        40.0,
        vec![Shape::Blobs {
            balls: balls
                .iter()
                .map(|&(c, d, b)| Ball {
                    center: c,
                    radius: d,
                    strength: b,
                })
                .collect(),
            threshold: 0.4,
            kernel: BlobKernel::Links,
            material: 0,
        }],
    );
    s.ambient = [1.0; 3];
    let img = image_of(&s);
    let view = links_core::image::SceneView::new(&img).unwrap();
    // The balls as the image stores them (f32), so only the root finder's error is measured.
    let stored: Vec<([f64; 3], f64, f64)> = (0..3)
        .map(|i| {
            let b = view.ball::<f64>(i);
            (b.center.to_f64(), b.radius, b.strength)
        })
        .collect();
    let field = |p: [f64; 3]| -> f64 {
        stored
            .iter()
            .map(|&(c, d, b)| {
                let v = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
                links_kernel(dot(v, v).sqrt(), d, b)
            })
            .sum()
    };
    let mut t64 = links_core::render::Tracer::<f64>::new(view);
    let mut t32 = links_core::render::Tracer::<f32>::new(view);
    let (mut hits, mut worst64, mut worst32) = (0, 0.0f64, 0.0f64);
    for y in 0..40 {
        for x in 0..48 {
            let r = t64.primary_ray(x, y);
            if let Some((_, s)) = t64.first_surface(&r) {
                hits += 1;
                worst64 = worst64.max((field(s.p.to_f64()) - 0.4).abs());
            }
            let r = t32.primary_ray(x, y);
            if let Some((_, s)) = t32.first_surface(&r) {
                worst32 = worst32.max((field(s.p.to_f64()) - 0.4).abs());
            }
        }
    }
    assert!(
        hits > 300,
        "the blob covers a good part of the frame ({hits} hits)"
    );
    assert!(worst64 <= 1e-8, "f64: |F - T| up to {worst64:e}");
    assert!(worst32 <= 1e-3, "f32: |F - T| up to {worst32:e}");
}

#[test]
fn box_face_texture_is_mapped_planar_and_sampled_bilinearly() {
    // A 2x2 texture (red, green / blue, white) on the front face of a box facing the eye.
    let (w, h, fov) = (40, 40, 30.0);
    let mut s = scene(
        w,
        h,
        fov,
        vec![Shape::Box {
            min: [-2.0, -2.0, -12.0],
            max: [2.0, 2.0, -10.0],
            material: 1,
        }],
    );
    s.ambient = [1.0; 3];
    let texels = vec![255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255];
    s.textures.push(Texture {
        name: "quad".into(),
        width: 2,
        height: 2,
        rgb: texels.clone(),
    });
    s.materials.push(Material {
        name: "tex".into(),
        diffuse: [1.0; 3],
        map: Some(TextureMap {
            texture: 0,
            target: MapTarget::Diffuse,
            scale: [1.0, 1.0],
        }),
        ..Material::default()
    });
    let img = image_of(&s);
    let view = links_core::image::SceneView::new(&img).unwrap();
    let mut tracer = links_core::render::Tracer::<f64>::new(view);
    // Bilinear lookup written out: v = 0 is the bottom row, texel centres at half steps.
    let lookup = |u: f64, v: f64| -> [f64; 3] {
        let x = u * 2.0 - 0.5;
        let y = (1.0 - v) * 2.0 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let t = |xx: f64, yy: f64, k: usize| {
            let xi = (xx as i64).rem_euclid(2) as usize;
            let yi = (yy as i64).rem_euclid(2) as usize;
            texels[(yi * 2 + xi) * 3 + k] as f64 / 255.0
        };
        [0, 1, 2].map(|k| {
            let top = t(x0, y0, k) * (1.0 - fx) + t(x0 + 1.0, y0, k) * fx;
            let bot = t(x0, y0 + 1.0, k) * (1.0 - fx) + t(x0 + 1.0, y0 + 1.0, k) * fx;
            top * (1.0 - fy) + bot * fy
        })
    };
    let mut checked = 0;
    for (x, y) in [(20, 20), (12, 12), (27, 13), (14, 26), (25, 25), (17, 22)] {
        let ray = tracer.primary_ray(x, y);
        let (_, surf) = tracer
            .first_surface(&ray)
            .expect("the face fills the centre");
        // Planar mapping: u runs with view x, v with view y, across the 4-unit face.
        let p = surf.p.to_f64();
        let (u, v) = ((p[0] + 2.0) / 4.0, (p[1] + 2.0) / 4.0);
        assert!((surf.uv[0] - u).abs() < 1e-9 && (surf.uv[1] - v).abs() < 1e-9);
        let want = lookup(u, v).map(q8);
        let got = pixel::<f64>(&img, x, y);
        for k in 0..3 {
            assert!(
                (got[k] as i32 - want[k]).abs() <= 1,
                "({x},{y}) uv ({u:.3},{v:.3}): {got:?} vs {want:?}"
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 6);
    // The centre of the face samples all four texels equally.
    assert_eq!(lookup(0.5, 0.5).map(q8), [128, 128, 128]);
}

#[test]
fn point_light_falls_off_with_distance_squared_and_spot_cone_cuts_off() {
    // Floor y = 0 seen from above; a point light 4 units over it with falloff.
    let (w, h, fov) = (21, 21, 50.0);
    let floor = Shape::Box {
        min: [-30.0, -1.0, -30.0],
        max: [30.0, 0.0, 30.0],
        material: 1,
    };
    let mut s = scene(w, h, fov, vec![floor]);
    s.camera = Camera {
        eye: [0.0, 10.0, 0.0],
        look_at: [0.0, 0.0, 0.0],
        up: [0.0, 0.0, -1.0],
        fov_y_deg: fov,
    };
    s.materials.push(matte("floor", [0.5; 3]));
    s.lights = vec![Light::Point {
        pos: [0.0, 4.0, 0.0],
        color: [8.0; 3],
        falloff: true,
    }];
    let img = image_of(&s);
    // Straight below the light: 0.5 * 8 / 16 = 0.25.
    assert_eq!(pixel::<f64>(&img, 10, 10), [q8(0.25) as u8; 3]);
    let view = links_core::image::SceneView::new(&img).unwrap();
    let mut tracer = links_core::render::Tracer::<f64>::new(view);
    for (x, y) in [(3, 10), (15, 4), (18, 18)] {
        let (_, surf) = tracer.first_surface(&tracer.primary_ray(x, y)).unwrap();
        // View -> world for this camera: world x = view x, world z = view y (up = -z world).
        let p = surf.p.to_f64();
        let r2 = p[0] * p[0] + p[1] * p[1];
        let d2 = r2 + 16.0;
        let want = q8(0.5 * 8.0 / d2 * (4.0 / d2.sqrt()));
        let got = pixel::<f64>(&img, x, y)[0] as i32;
        assert!(
            (got - want).abs() <= 1,
            "({x},{y}) r²={r2:.2}: {got} vs {want}"
        );
    }

    // A spot 4 units up, pointing down, full within 20°, dark beyond 30°.
    s.lights = vec![Light::Spot {
        pos: [0.0, 4.0, 0.0],
        dir: [0.0, -1.0, 0.0],
        color: [1.0; 3],
        inner_deg: 20.0,
        outer_deg: 30.0,
        exponent: 0.0,
    }];
    let img = image_of(&s);
    let view = links_core::image::SceneView::new(&img).unwrap();
    let mut tracer = links_core::render::Tracer::<f64>::new(view);
    let (mut inside, mut outside, mut between) = (0, 0, 0);
    for y in 0..h {
        for x in 0..w {
            let (_, surf) = tracer.first_surface(&tracer.primary_ray(x, y)).unwrap();
            let p = surf.p.to_f64();
            let r = (p[0] * p[0] + p[1] * p[1]).sqrt();
            let angle = r.atan2(4.0).to_degrees();
            let cos = 4.0 / (r * r + 16.0).sqrt();
            let got = pixel::<f64>(&img, x, y)[0] as i32;
            if angle < 19.5 {
                assert!(
                    (got - q8(0.5 * cos)).abs() <= 1,
                    "inside the cone at {angle:.1}°: {got}"
                );
                inside += 1;
            } else if angle > 30.5 {
                assert_eq!(got, 0, "outside the cone at {angle:.1}°");
                outside += 1;
            } else {
                assert!(got < q8(0.5 * cos) + 1, "between the cones falls off");
                between += 1;
            }
        }
    }
    assert!(
        inside > 5 && outside > 5 && between > 5,
        "{inside} {outside} {between}"
    );
}

/// Two triangles of a quad with an explicit outward normal (which sets the outside).
fn quad(
    a: [f64; 3],
    b: [f64; 3],
    c: [f64; 3],
    d: [f64; 3],
    n: [f64; 3],
    material: u32,
) -> [Shape; 2] {
    [
        Shape::Triangle {
            v: [a, b, c],
            normals: Some([n; 3]),
            uv: None,
            material,
        },
        Shape::Triangle {
            v: [a, c, d],
            normals: Some([n; 3]),
            uv: None,
            material,
        },
    ]
}

#[test]
fn right_angle_prism_totally_reflects_at_its_hypotenuse() {
    // Cross-section in x-z: front face z = -9 (x in [-1, 1]), side face x = 1 (z in [-11, -9]),
    // hypotenuse from (-1, -9) to (1, -11). The centre ray enters the front face head-on, meets
    // the hypotenuse at 45° (> the 41.8° critical angle of ior 1.5), turns to +x and leaves
    // through the side face towards a red wall. Without bending (ior 1) it would pass the
    // hypotenuse and hit the blue wall behind.
    let (w, h, fov) = (21, 21, 10.0);
    let s2 = std::f64::consts::FRAC_1_SQRT_2;
    let mut shapes = Vec::new();
    shapes.extend(quad(
        [-1.0, -1.0, -9.0],
        [1.0, -1.0, -9.0],
        [1.0, 1.0, -9.0],
        [-1.0, 1.0, -9.0],
        [0.0, 0.0, 1.0],
        1,
    ));
    shapes.extend(quad(
        [1.0, -1.0, -9.0],
        [1.0, -1.0, -11.0],
        [1.0, 1.0, -11.0],
        [1.0, 1.0, -9.0],
        [1.0, 0.0, 0.0],
        1,
    ));
    shapes.extend(quad(
        [-1.0, -1.0, -9.0],
        [-1.0, 1.0, -9.0],
        [1.0, 1.0, -11.0],
        [1.0, -1.0, -11.0],
        [-s2, 0.0, -s2],
        1,
    ));
    shapes.push(Shape::Box {
        min: [5.0, -20.0, -30.0],
        max: [6.0, 20.0, 0.0],
        material: 2,
    });
    shapes.push(Shape::Box {
        min: [-20.0, -20.0, -31.0],
        max: [4.0, 20.0, -30.0],
        material: 3,
    });
    let mut s = scene(w, h, fov, shapes);
    s.ambient = [1.0; 3];
    s.materials.push(Material {
        name: "glass".into(),
        diffuse: [0.0; 3],
        transmit: [1.0; 3],
        ior: 1.5,
        ..Material::default()
    });
    s.materials.push(matte("red", [1.0, 0.0, 0.0]));
    s.materials.push(matte("blue", [0.0, 0.0, 1.0]));
    let img = image_of(&s);
    assert_eq!(
        pixel::<f64>(&img, 10, 10),
        [255, 0, 0],
        "f64: total internal reflection"
    );
    assert_eq!(
        pixel::<f32>(&img, 10, 10),
        [255, 0, 0],
        "f32: total internal reflection"
    );
    assert_eq!(
        pixel::<links_core::num::Fx>(&for_backend::<links_core::num::Fx>(img.clone()), 10, 10),
        [255, 0, 0],
        "Q16.16: total internal reflection"
    );
    s.materials[1].ior = 1.0;
    assert_eq!(
        pixel::<f64>(&image_of(&s), 10, 10),
        [0, 0, 255],
        "no bending: straight through"
    );
}

#[test]
fn nesting_deeper_than_the_depth_cap_stays_bright_and_bounded() {
    // Twelve nested clear spheres (24 surfaces) in front of a white wall, max_depth 3: the
    // refractive recursion stops at depth 3 and the rest is crossed straight through, so
    // the wall still shows through (attenuated by 0.98 per surface), with no stack growth.
    let (w, h, fov) = (11, 11, 10.0);
    let mut shapes: Vec<Shape> = (0..12)
        .map(|i| Shape::Ellipsoid {
            center: [0.0, 0.0, -20.0],
            radii: [6.0 - 0.45 * i as f64; 3],
            rotate_deg: [0.0; 3],
            cut: None,
            material: 1,
        })
        .collect();
    shapes.push(Shape::Box {
        min: [-50.0, -50.0, -41.0],
        max: [50.0, 50.0, -40.0],
        material: 2,
    });
    let mut s = scene(w, h, fov, shapes);
    s.ambient = [1.0; 3];
    s.max_depth = 3;
    s.materials.push(Material {
        name: "clear".into(),
        diffuse: [0.0; 3],
        transmit: [0.98; 3],
        ior: 1.0,
        ..Material::default()
    });
    s.materials.push(matte("wall", [1.0; 3]));
    let img = image_of(&s);
    let want = q8(0.98f64.powi(24));
    for (mode, t) in [
        ("refractive", TransparencyMode::Refractive),
        ("non-refractive", TransparencyMode::NonRefractive),
    ] {
        s.transparency = t;
        let img = image_of(&s);
        let fixed = for_backend::<links_core::num::Fx>(img.clone());
        for got in [
            pixel::<f64>(&img, 5, 5),
            pixel::<f32>(&img, 5, 5),
            pixel::<links_core::num::Fx>(&fixed, 5, 5),
        ] {
            assert!(
                (got[0] as i32 - want).abs() <= 1,
                "{mode}: {got:?} vs 0.98^24 = {want}"
            );
        }
    }
    // With ior 1 the path is the same either way: the cut-off causes no brightness jump.
    let deep = {
        let mut d = s.clone();
        d.max_depth = 16;
        d.transparency = TransparencyMode::Refractive;
        pixel::<f64>(&image_of(&d), 5, 5)
    };
    assert_eq!(deep, pixel::<f64>(&img, 5, 5));
}

/// Eq. 2.1's ambient term with a material's own ambient colour `arc`: with no lights a
/// surface is `arc x ambient` (not `drc x ambient`). Ambient (0.3, 0.3, 0.3) and arc
/// (0.2, 0.5, 0.9) give (0.06, 0.15, 0.27) x 255 = (15.3, 38.25, 68.85) -> (15, 38, 69); the
/// sphere beside it, without an ambient colour, is drc (0.8) x 0.3 x 255 = 61.2 -> 61.
#[test]
fn a_materials_own_ambient_colour_replaces_diffuse_in_the_ambient_term() {
    let sphere = |x: f64, material: u32| Shape::Ellipsoid {
        center: [x, 0.0, -10.0],
        radii: [2.0; 3],
        rotate_deg: [0.0; 3],
        cut: None,
        material,
    };
    let (w, h) = (40, 20);
    let mut s = scene(w, h, 30.0, vec![sphere(-2.5, 0), sphere(2.5, 1)]);
    s.lights.clear();
    s.ambient = [0.3; 3];
    s.background = [0.0; 3];
    s.materials = vec![
        Material {
            ambient: Some([0.2, 0.5, 0.9]),
            ..matte("own", [0.8; 3])
        },
        matte("plain", [0.8; 3]),
    ];
    let img = image_of(&s);
    let fixed = links_core::fixed_image::to_fixed(&img).unwrap().bytes;
    // Pixel columns 12 and 27 look at the two spheres' centres (x = -2.5, 2.5 at z = 10).
    for (x, want) in [(12, [15, 38, 69]), (27, [61, 61, 61]), (0, [0, 0, 0])] {
        assert_eq!(pixel::<f32>(&img, x, 10), want, "f32 pixel ({x}, 10)");
        assert_eq!(pixel::<f64>(&img, x, 10), want, "f64 pixel ({x}, 10)");
        assert_eq!(
            pixel::<links_core::num::Fx>(&fixed, x, 10),
            want,
            "Q16.16 pixel ({x}, 10)"
        );
    }
}
