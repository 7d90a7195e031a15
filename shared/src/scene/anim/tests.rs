//! Interpolation checked against values computed by hand, and films against the still scene.

use super::interp::{sample, Blend, Interpolation as I, Key};
use super::quat::Quat;
use super::*;
use crate::desc::{Ball, BlobKernel, Camera, Material, Transform};
use std::vec;

fn keys<V: Copy>(list: &[(f64, V)]) -> Vec<Key<V>> {
    list.iter()
        .map(|&(frame, value)| Key { frame, value })
        .collect()
}

/// A deterministic xorshift generator for the property tests.
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
}

#[test]
fn step_holds_each_key_until_the_next() {
    let k = keys(&[(0.0, 1.0), (10.0, 5.0), (12.0, -2.0)]);
    assert_eq!(sample(&k, I::Step, -3.0), Some(1.0));
    assert_eq!(sample(&k, I::Step, 4.0), Some(1.0));
    assert_eq!(sample(&k, I::Step, 9.999), Some(1.0));
    assert_eq!(sample(&k, I::Step, 10.0), Some(5.0));
    assert_eq!(sample(&k, I::Step, 11.5), Some(5.0));
    assert_eq!(sample(&k, I::Step, 40.0), Some(-2.0));
    assert_eq!(sample::<f64>(&[], I::Step, 0.0), None);
}

#[test]
fn linear_is_the_straight_line_between_keys() {
    let k = keys(&[(0.0, [0.0, 0.0, 0.0]), (10.0, [10.0, 20.0, -30.0])]);
    assert_eq!(sample(&k, I::Linear, 2.5), Some([2.5, 5.0, -7.5]));
    assert_eq!(sample(&k, I::Linear, 5.0), Some([5.0, 10.0, -15.0]));
    let k = keys(&[(2.0, 1.0), (6.0, 3.0), (7.0, 0.0)]);
    // 1 + (3 - 1) * 3/4 = 2.5; 3 + (0 - 3) * 1/2 = 1.5.
    assert_eq!(sample(&k, I::Linear, 5.0), Some(2.5));
    assert_eq!(sample(&k, I::Linear, 6.5), Some(1.5));
}

#[test]
fn smooth_is_catmull_rom() {
    // Uniform keys 0, 1, 0, 0 at 0..3: the classic spline at the middle of segment 1..2 is
    // 0.5 (2 P1 + (P2 - P0) u + (2 P0 - 5 P1 + 4 P2 - P3) u² + (-P0 + 3 P1 - 3 P2 + P3) u³)
    // = 0.5 (2 - 1.25 + 0.375) = 0.5625.
    let k = keys(&[(0.0, 0.0), (1.0, 1.0), (2.0, 0.0), (3.0, 0.0)]);
    assert_eq!(sample(&k, I::Smooth, 1.5), Some(0.5625));
    // The first segment extrapolates a key -1 at time -1: with P = (-1, 0, 1, 0), u = 1/2,
    // 0.5 (0 + 2 · 0.5 + 2 · 0.25 - 2 · 0.125) = 0.625.
    assert_eq!(sample(&k, I::Smooth, 0.5), Some(0.625));
    // Symmetric keys give a symmetric curve: u = 1/4 and 3/4 of (0, 1, 1, 0) on 1..2 are
    // both 0.5 (2 + 0.25 - 0.0625) = 1.09375.
    let k = keys(&[(0.0, 0.0), (1.0, 1.0), (2.0, 1.0), (3.0, 0.0)]);
    assert_eq!(sample(&k, I::Smooth, 1.25), Some(1.09375));
    assert_eq!(sample(&k, I::Smooth, 1.75), Some(1.09375));
}

#[test]
fn smooth_reproduces_a_straight_line_with_uneven_keys() {
    let line = |t: f64| 3.0 * t - 1.0;
    let k = keys(&[0.0, 2.0, 3.0, 7.0].map(|t| (t, line(t))));
    for i in 0..=70 {
        let t = f64::from(i) * 0.1;
        let v = sample(&k, I::Smooth, t).unwrap();
        assert!((v - line(t)).abs() < 1e-12, "t {t}: {v} vs {}", line(t));
    }
}

#[test]
fn every_interpolation_passes_through_its_keys_exactly() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let k: Vec<Key<[f64; 3]>> = (0..6)
        .map(|i| Key {
            frame: f64::from(i) * 1.7 + 0.3,
            value: [0; 3].map(|_| rng.range(-1e3, 1e3)),
        })
        .collect();
    for interp in [I::Step, I::Linear, I::Smooth] {
        for key in &k {
            assert_eq!(sample(&k, interp, key.frame), Some(key.value));
        }
    }
}

#[test]
fn slerp_stays_unit_length_and_halves_the_angle() {
    let mut rng = Rng(12345);
    for _ in 0..2000 {
        let a = Quat::from_euler_deg([0; 3].map(|_| rng.range(-180.0, 180.0)));
        let b = Quat::from_euler_deg([0; 3].map(|_| rng.range(-180.0, 180.0)));
        let s = rng.range(-1.0, 2.0);
        let q = Quat::slerp(a, b, s);
        assert!((q.norm() - 1.0).abs() < 1e-12, "|q| = {}", q.norm());
    }
    // Halfway from no rotation to 90° about Y is 45° about Y.
    let half = Quat::slerp(Quat::IDENTITY, Quat::from_euler_deg([0.0, 90.0, 0.0]), 0.5);
    let e = half.to_euler_deg();
    assert!(
        e[0].abs() < 1e-12 && (e[1] - 45.0).abs() < 1e-12 && e[2].abs() < 1e-12,
        "{e:?}"
    );
    // The shorter way: from 170° to -170° about Z passes 180°, not 0°.
    let q = Quat::slerp(
        Quat::from_euler_deg([0.0, 0.0, 170.0]),
        Quat::from_euler_deg([0.0, 0.0, -170.0]),
        0.5,
    );
    assert!(
        (q.to_euler_deg()[2].abs() - 180.0).abs() < 1e-9,
        "{:?}",
        q.to_euler_deg()
    );
}

#[test]
fn spherical_catmull_rom_stays_unit_length() {
    let mut rng = Rng(777);
    let k: Vec<Key<Quat>> = (0..5)
        .map(|i| Key {
            frame: f64::from(i) * 3.0,
            value: Quat::from_euler_deg([0; 3].map(|_| rng.range(-90.0, 90.0))),
        })
        .collect();
    for i in 0..=120 {
        let q = sample(&k, I::Smooth, f64::from(i) * 0.1).unwrap();
        assert!((q.norm() - 1.0).abs() < 1e-12, "|q| = {}", q.norm());
    }
}

/// Rz · Ry · Rx computed directly from the angles.
fn euler_matrix(deg: [f64; 3]) -> [[f64; 3]; 3] {
    let [x, y, z] = deg.map(f64::to_radians);
    let (sx, cx) = x.sin_cos();
    let (sy, cy) = y.sin_cos();
    let (sz, cz) = z.sin_cos();
    [
        [cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
        [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
        [-sy, cy * sx, cy * cx],
    ]
}

#[test]
fn euler_angles_round_trip_through_quaternions() {
    let mut rng = Rng(42);
    let mut cases: Vec<[f64; 3]> = (0..500)
        .map(|_| [0; 3].map(|_| rng.range(-180.0, 180.0)))
        .collect();
    cases.extend([[10.0, 90.0, 0.0], [-30.0, -90.0, 0.0], [0.0; 3]]);
    for deg in cases {
        let q = Quat::from_euler_deg(deg);
        let m = euler_matrix(deg);
        let back = euler_matrix(q.to_euler_deg());
        for (r, (a, b)) in m.iter().zip(&back).enumerate() {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 1e-9, "{deg:?} row {r}");
                assert!((a[c] - q.matrix()[r][c]).abs() < 1e-12, "{deg:?} row {r}");
            }
        }
    }
}

#[test]
fn blend_of_vectors_is_per_component() {
    assert_eq!(
        <[f64; 3]>::blend([1.0, 2.0, 3.0], [3.0, 2.0, -1.0], 0.25),
        [1.5, 2.0, 2.0]
    );
}

// ---- films --------------------------------------------------------------------------------

fn scene() -> SceneDesc {
    let camera = Camera {
        eye: [0.0, 0.0, -8.0],
        look_at: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 40.0,
    };
    let blobs = Shape::Blobs {
        balls: vec![Ball {
            center: [0.0; 3],
            radius: 1.0,
            strength: 1.0,
        }],
        threshold: 0.5,
        kernel: BlobKernel::Links,
        material: 0,
    };
    let arm = Cluster {
        name: "arm".into(),
        transform: Transform::default(),
        children: vec![Node::Shape(blobs)],
    };
    SceneDesc {
        materials: vec![Material::default()],
        lights: vec![Light::Directional {
            dir: [0.0, -1.0, 0.0],
            color: [1.0; 3],
        }],
        ..crate::testkit::scene::scene_desc(camera, 16, 16, vec![Node::Cluster(arm)])
    }
}

fn track(target: Target, interpolation: I, keys: Keys) -> Track {
    Track {
        target,
        interpolation,
        keys,
    }
}

fn timeline(start: u32, end: u32) -> Timeline {
    Timeline {
        start,
        end,
        rate: 24.0,
    }
}

#[test]
fn scene_at_writes_each_tracks_value_in() {
    let tracks = vec![
        track(
            Target::Cluster {
                path: vec![0],
                property: TransformProperty::Translate,
            },
            I::Linear,
            Keys::Vector(keys(&[(0.0, [0.0; 3]), (8.0, [4.0, 0.0, -2.0])])),
        ),
        track(
            Target::Material {
                index: 0,
                property: MaterialProperty::Specular,
            },
            I::Step,
            Keys::Number(keys(&[(0.0, 0.25), (3.0, 0.5)])),
        ),
        track(
            Target::BallCenter {
                path: vec![0, 0],
                ball: 0,
            },
            I::Linear,
            Keys::Vector(keys(&[(0.0, [0.0; 3]), (4.0, [0.0, 2.0, 0.0])])),
        ),
    ];
    let film = Film::new(scene(), timeline(0, 9), tracks).unwrap();
    let at2 = film.scene_at(2).unwrap();
    let mut expected = scene();
    let Node::Cluster(arm) = &mut expected.root.children[0] else {
        unreachable!()
    };
    arm.transform.translate = [1.0, 0.0, -0.5];
    let Node::Shape(Shape::Blobs { balls, .. }) = &mut arm.children[0] else {
        unreachable!()
    };
    balls[0].center = [0.0, 1.0, 0.0];
    expected.materials[0].specular = 0.25;
    assert_eq!(at2, expected);
    assert_eq!(film.scene_at(3).unwrap().materials[0].specular, 0.5);
    assert_eq!(
        film.scene_at(9),
        Err(AnimError::FrameOutside {
            frame: 9,
            start: 0,
            end: 9
        })
    );
}

#[test]
fn smooth_bounded_values_are_clamped_between_their_keys_and_points_are_not() {
    let k = [(0.0, 0.0), (1.0, 1.0), (2.0, 1.0), (3.0, 0.0)];
    let spec = track(
        Target::Material {
            index: 0,
            property: MaterialProperty::Specular,
        },
        I::Smooth,
        Keys::Number(keys(&k)),
    );
    // Catmull-Rom gives 1.125 at 1.5 (overshoot); a coefficient stays at its keys' 1.
    assert_eq!(track_value(&spec, 1.5), Some(Value::Number(1.0)));
    let eye = track(
        Target::Camera(CameraProperty::Eye),
        I::Smooth,
        Keys::Vector(keys(&k.map(|(t, v)| (t, [v, 0.0, -8.0])))),
    );
    assert_eq!(
        track_value(&eye, 1.5),
        Some(Value::Vector([1.125, 0.0, -8.0]))
    );
}

#[test]
fn rotation_tracks_slerp_and_keep_the_written_angles_at_keys() {
    let rot = track(
        Target::Cluster {
            path: vec![0],
            property: TransformProperty::Rotate,
        },
        I::Linear,
        Keys::Vector(keys(&[
            (0.0, [0.0; 3]),
            (10.0, [0.0, 90.0, 0.0]),
            (20.0, [400.0, 0.0, 0.0]),
        ])),
    );
    let Some(Value::Vector(v)) = track_value(&rot, 5.0) else {
        panic!("a vector")
    };
    assert!(
        v[0].abs() < 1e-12 && (v[1] - 45.0).abs() < 1e-12 && v[2].abs() < 1e-12,
        "{v:?}"
    );
    // At a key the angles are the ones written (not 40° after a round trip).
    assert_eq!(
        track_value(&rot, 20.0),
        Some(Value::Vector([400.0, 0.0, 0.0]))
    );
}

#[test]
fn opposite_directions_interpolate_to_an_error_not_a_nan() {
    let up = track(
        Target::Camera(CameraProperty::Up),
        I::Linear,
        Keys::Vector(keys(&[(0.0, [0.0, 1.0, 0.0]), (2.0, [0.0, -1.0, 0.0])])),
    );
    let film = Film::new(scene(), timeline(0, 3), vec![up]).unwrap();
    assert!(film.scene_at(0).is_ok());
    assert_eq!(
        film.scene_at(1),
        Err(AnimError::ZeroDirection { track: 0, frame: 1 })
    );
}

#[test]
fn inconsistent_films_are_refused() {
    let t = |target, k: Keys| vec![track(target, I::Linear, k)];
    let eye = Target::Camera(CameraProperty::Eye);
    let unsorted = Keys::Vector(keys(&[(2.0, [0.0; 3]), (1.0, [1.0; 3])]));
    assert!(matches!(
        Film::new(scene(), timeline(0, 3), t(eye.clone(), unsorted)),
        Err(AnimError::BadKeys { track: 0, .. })
    ));
    let numbers = Keys::Number(keys(&[(0.0, 1.0)]));
    assert!(matches!(
        Film::new(scene(), timeline(0, 3), t(eye, numbers)),
        Err(AnimError::BadKeys { track: 0, .. })
    ));
    let nowhere = Target::Cluster {
        path: vec![0, 0],
        property: TransformProperty::Scale,
    };
    let one = Keys::Vector(keys(&[(0.0, [1.0; 3])]));
    assert_eq!(
        Film::new(scene(), timeline(0, 3), t(nowhere, one.clone())),
        Err(AnimError::NoTarget { track: 0 })
    );
    let spot_pos_on_sun = Target::Light {
        index: 0,
        property: LightProperty::Position,
    };
    assert_eq!(
        Film::new(scene(), timeline(0, 3), t(spot_pos_on_sun, one)),
        Err(AnimError::NoTarget { track: 0 })
    );
    assert!(matches!(
        Film::new(scene(), timeline(3, 3), vec![]),
        Err(AnimError::BadTimeline { .. })
    ));
}
