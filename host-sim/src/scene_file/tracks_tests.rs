//! Films in the scene file: frames and tracks parsed, their errors located, and a frame equal
//! to the still scene with the track values written in.

use std::path::Path;

use links_core::anim::{track_value, Film, Value};
use links_core::desc::*;
use links_core::dm::{compile, CompileOptions};

use super::*;

/// A film whose camera, cluster, light, material and ball move; `{EYE}`-style holes are
/// filled by [`film_text`] and [`still_text`].
const TEMPLATE: &str = r#"Scene(
    camera: (eye: {EYE}, look_at: (0, 1, 0), up: {UP}, fov_y: {FOV}),
    image: (width: 24, height: 18),
    materials: {
        "red": (diffuse: {DIFFUSE}, specular: {SPEC}, shininess: 30),
        "floor": (),
    },
    lights: [ Directional(dir: (0, -1, 0.5)), Point(pos: {LIGHT}, color: 0.5) ],
    root: (name: "world", children: [
        Box(min: (-5, -1, -5), max: (5, 0, 5), material: "floor"),
        Cluster(name: "arm", transform: (translate: {T}, rotate: {R}, scale: {S}), children: [
            Sphere(center: (0, 1, 0), radius: 1, material: "red"),
            Blobs(name: "goo", threshold: 0.5, balls: [
                (center: (2, 1, 0), radius: 1.5),
                (center: {BALL}, radius: 1.2),
            ]),
        ]),
    ]),
    {FILM}
)"#;

const TRACKS: &str = r#"frames: (start: 0, end: 9, rate: 12),
    tracks: [
        Track(target: Camera(Eye), interpolation: Smooth,
              keys: [(0, (0, 2, -8)), (3, (4, 2, -7)), (6, (6, 3, -2)), (8, (4, 3, 4))]),
        Track(target: Camera(Up), keys: [(0, (0, 1, 0)), (8, (0.3, 1, 0))]),
        Track(target: Camera(FovY), interpolation: Smooth, keys: [(0, 40), (4, 55), (8, 45)]),
        Track(target: Cluster("arm", Translate), keys: [(0, (0, 0, 0)), (8, (1, 0.5, -2))]),
        Track(target: Cluster("arm", Rotate), interpolation: Smooth,
              keys: [(0, (0, 0, 0)), (4, (10, 60, 0)), (8, (0, 120, 20))]),
        Track(target: Cluster("arm", Scale), interpolation: Step, keys: [(0, 1), (5, 1.5)]),
        Track(target: Light(1, Position), keys: [(0, (0, 5, 0)), (8, (3, 5, -3))]),
        Track(target: Material("red", Diffuse), keys: [(0, (0.8, 0.1, 0.1)), (8, 0.5)]),
        Track(target: Material("red", Specular), interpolation: Smooth,
              keys: [(0, 0.1), (2, 0.9), (5, 0.2), (8, 0.6)]),
        Track(target: Ball("goo", 1, Center), keys: [(0, (3, 1, 0)), (8, (3.5, 2, 0.5))]),
    ],"#;

/// The still values the template is filled with, in the order of its holes.
const STILL: [(&str, &str); 11] = [
    ("{EYE}", "(0, 2, -8)"),
    ("{UP}", "(0, 1, 0)"),
    ("{FOV}", "40"),
    ("{DIFFUSE}", "(0.8, 0.1, 0.1)"),
    ("{SPEC}", "0.1"),
    ("{LIGHT}", "(0, 5, 0)"),
    ("{T}", "(0, 0, 0)"),
    ("{R}", "(0, 0, 0)"),
    ("{S}", "1"),
    ("{BALL}", "(3, 1, 0)"),
    ("{FILM}", ""),
];

fn fill(values: &[(&str, String)]) -> String {
    let mut text = TEMPLATE.to_string();
    for (hole, value) in values {
        text = text.replace(hole, value);
    }
    text
}

fn film_text() -> String {
    let mut v: Vec<(&str, String)> = STILL.iter().map(|(h, s)| (*h, s.to_string())).collect();
    v.last_mut().unwrap().1 = TRACKS.to_string();
    fill(&v)
}

fn film() -> Film {
    parse_film(&film_text(), "film.ron", Path::new(".")).unwrap()
}

/// `(x, y, z)` with every bit of each f64 kept (`{:?}` round-trips).
fn vec_text(v: [f64; 3]) -> String {
    format!("({:?}, {:?}, {:?})", v[0], v[1], v[2])
}

/// The still scene of `frame` written by hand: each hole filled with the track's value
/// at that frame (the specular edge follows specular, as the format says).
fn still_text(film: &Film, frame: u32) -> String {
    let holes = [
        "{EYE}",
        "{UP}",
        "{FOV}",
        "{T}",
        "{R}",
        "{S}",
        "{LIGHT}",
        "{DIFFUSE}",
        "{SPEC}",
        "{BALL}",
    ];
    let mut v: Vec<(&str, String)> = holes
        .iter()
        .zip(film.tracks())
        .map(|(hole, track)| {
            let text = match track_value(track, f64::from(frame)).unwrap() {
                Value::Number(n) => format!("{n:?}"),
                Value::Vector(v) => vec_text(v),
            };
            (*hole, text)
        })
        .collect();
    v.push(("{FILM}", String::new()));
    fill(&v)
}

#[test]
fn a_frame_is_the_still_scene_with_the_track_values_written_in() {
    let film = film();
    assert_eq!(film.timeline().frames(), 0..9);
    assert_eq!(film.timeline().rate, 12.0);
    // Ten tracks as written plus the specular edge that follows specular.
    assert_eq!(film.tracks().len(), 11);
    let opts = CompileOptions::default();
    let mut images = Vec::new();
    for frame in film.timeline().frames() {
        let text = still_text(&film, frame);
        let still = parse_scene(&text, "still.ron", Path::new(".")).unwrap();
        let moving = film.scene_at(frame).unwrap();
        assert_eq!(moving, still, "frame {frame}");
        let a = film.compile_frame(frame, &opts).unwrap().bytes;
        let b = compile(&still, &opts).unwrap().bytes;
        assert!(a == b, "frame {frame}: the compiled images differ");
        images.push(a);
    }
    // Every frame differs from the others (everything moves).
    for i in 0..images.len() {
        for j in 0..i {
            assert!(images[i] != images[j], "frames {j} and {i} compile alike");
        }
    }
}

#[test]
fn tracks_land_on_their_targets() {
    let film = film();
    let s = film.scene_at(4).unwrap();
    let Node::Cluster(arm) = &s.root.children[1] else {
        panic!("arm")
    };
    // Linear, halfway: (1, 0.5, -2) / 2.
    assert_eq!(arm.transform.translate, [0.5, 0.25, -1.0]);
    // A key's angles as written; step scale still 1 before frame 5.
    assert_eq!(arm.transform.rotate_deg, [10.0, 60.0, 0.0]);
    assert_eq!(arm.transform.scale, [1.0; 3]);
    // The field of view is the key's 55 at frame 4, and stays between its keys after.
    assert_eq!(s.camera.fov_y_deg, 55.0);
    let fov = film.scene_at(5).unwrap().camera.fov_y_deg;
    assert!((45.0..55.0).contains(&fov), "{fov}");
    // Diffuse halfway from (0.8, 0.1, 0.1) to 0.5 (a single number for every channel).
    let red = &s.materials[0];
    assert_eq!(red.diffuse, [0.65, 0.3, 0.3].map(|x: f64| x as f32));
    assert_eq!(red.specular_edge, red.specular);
    let Node::Shape(Shape::Blobs { balls, .. }) = &arm.children[1] else {
        panic!("goo")
    };
    assert_eq!(balls[1].center, [3.25, 1.5, 0.25]);
    // load_scene gives the first frame.
    let first = parse_scene(&film_text(), "film.ron", Path::new(".")).unwrap();
    assert_eq!(first, film.scene_at(0).unwrap());
}

#[test]
fn a_still_scene_is_the_film_of_frame_0() {
    let text = fill(&STILL.map(|(h, v)| (h, v.to_string())));
    let film = parse_film(&text, "still.ron", Path::new(".")).unwrap();
    assert!(film.is_still());
    assert_eq!(film.timeline().frames(), 0..1);
    assert_eq!(
        film.scene_at(0).unwrap(),
        parse_scene(&text, "still.ron", Path::new(".")).unwrap()
    );
}

/// The film text with `old` replaced by `new`, and the (line, col, message) of its error.
fn error_with(old: &str, new: &str) -> (usize, usize, String) {
    let text = film_text();
    assert!(text.contains(old), "{old}");
    let text = text.replacen(old, new, 1);
    let e = match parse_film(&text, "t.ron", Path::new(".")) {
        Ok(_) => panic!("expected an error for {new}"),
        Err(e) => e,
    };
    let (_, line, col) = e.location().unwrap_or_else(|| panic!("no location: {e}"));
    let at = text.find(new).unwrap();
    let (l0, c0) = locate::line_col(&text, at);
    assert_eq!(line, l0, "{e}");
    (line, col - c0, e.message())
}

#[test]
fn track_errors_name_the_place() {
    // Offsets are columns from the start of the replaced text.
    let (_, dc, m) = error_with("(3, (4, 2, -7))", "(7, (4, 2, -7))");
    assert_eq!(dc, 18, "at the time of the next key, (6, ...)");
    assert!(
        m.starts_with("keys out of order: a key at frame 6 follows one at frame 7"),
        "{m}"
    );
    let (_, dc, m) = error_with("(8, (4, 3, 4))", "(9.5, (4, 3, 4))");
    assert_eq!(dc, 1);
    assert!(
        m.starts_with("a key at frame 9.5 is outside the film's frames 0..9"),
        "{m}"
    );
    let (_, dc, m) = error_with("Cluster(\"arm\", Scale)", "Cluster(\"leg\", Scale)");
    assert_eq!(dc, 0);
    assert!(
        m.starts_with("unknown cluster \"leg\"; the scene names clusters \"arm\", \"world\""),
        "{m}"
    );
    let (_, _, m) = error_with("Material(\"red\", Diffuse)", "Material(\"blue\", Diffuse)");
    assert!(m.starts_with("unknown material \"blue\""), "{m}");
    let (_, _, m) = error_with("Light(1, Position)", "Light(0, Position)");
    assert_eq!(m, "light 0 is Directional: it has no position");
    let (_, _, m) = error_with("Light(1, Position)", "Light(2, Position)");
    assert_eq!(m, "there is no light 2: the scene has 2 lights (0 to 1)");
    let (_, _, m) = error_with("Ball(\"goo\", 1, Center)", "Ball(\"goo\", 2, Center)");
    assert!(
        m.contains("has 2 balls (0 to 1); there is no ball 2"),
        "{m}"
    );
    // A value wrong for its target: at the value.
    let (_, dc, m) = error_with("(5, 0.2)", "(5, 1.2)");
    assert_eq!(dc, 4);
    assert_eq!(m, "expected a coefficient between 0 and 1, found 1.2");
    let (_, dc, m) = error_with("(4, 55)", "(4, (1, 2, 3))");
    assert_eq!(dc, 4);
    assert!(
        m.starts_with("expected a single number (field of view)"),
        "{m}"
    );
    let (_, _, m) = error_with("(8, (0.3, 1, 0))", "(8, (0, 0, 0))");
    assert!(m.starts_with("expected a direction"), "{m}");
    let (_, _, m) = error_with(
        "(start: 0, end: 9, rate: 12)",
        "(start: 9, end: 9, rate: 12)",
    );
    assert!(m.starts_with("the film has no frames"), "{m}");
}

#[test]
fn tracks_without_frames_and_ambiguous_names_are_refused() {
    let text = film_text().replace("frames: (start: 0, end: 9, rate: 12),", "");
    let e = parse_film(&text, "t.ron", Path::new(".")).unwrap_err();
    assert!(
        e.message().starts_with("tracks need the film's frames"),
        "{e}"
    );
    let text = film_text().replace("name: \"world\"", "name: \"arm\"");
    let e = parse_film(&text, "t.ron", Path::new(".")).unwrap_err();
    assert!(
        e.message().starts_with("2 clusters are named \"arm\""),
        "{e}"
    );
}

/// A material's `ambient` is read as a colour (a number is grey), defaults to none, and a
/// track drives it like `diffuse`.
#[test]
fn material_ambient_parses_and_a_track_drives_it() {
    let text = r#"Scene(
    camera: (eye: (0, 0, 0), look_at: (0, 0, 1)),
    materials: {
        "lit": (diffuse: 0.5, ambient: (0.2, 0.4, 0.6)),
        "grey": (ambient: 0.25),
        "plain": (),
    },
    root: (name: "world", children: [ Sphere(center: (0, 0, 5), radius: 1, material: "lit") ]),
    frames: (start: 0, end: 5),
    tracks: [ Track(target: Material("plain", Ambient), keys: [(0, (0, 0, 0)), (4, 0.8)]) ],
)"#;
    let film = parse_film(text, "a.ron", Path::new(".")).unwrap();
    let s = film.scene_at(0).unwrap();
    assert_eq!(s.materials[0].ambient, Some([0.2, 0.4, 0.6]));
    assert_eq!(s.materials[1].ambient, Some([0.25; 3]));
    assert_eq!(
        film.scene_at(2).unwrap().materials[2].ambient,
        Some([0.4; 3])
    );
    assert_eq!(s.materials[2].ambient, Some([0.0; 3]));
    let still = text.replace("frames: (start: 0, end: 5),", "").replace(
        "tracks: [ Track(target: Material(\"plain\", Ambient), keys: [(0, (0, 0, 0)), (4, 0.8)]) ],",
        "",
    );
    let s = parse_scene(&still, "s.ron", Path::new(".")).unwrap();
    assert_eq!(s.materials[2].ambient, None);
    let bad = still.replace("ambient: 0.25", "ambient: 1.5");
    let e = parse_scene(&bad, "s.ron", Path::new(".")).unwrap_err();
    let (_, line, _) = e.location().unwrap();
    assert_eq!(line, 5, "{e}");
    assert!(e.to_string().contains("colour coefficient"), "{e}");
}
