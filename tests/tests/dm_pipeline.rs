//! The DM pipeline of a film on the simulated cluster: the steady state of a film is measured
//! on its own, distinct frames (not on one still repeated), every frame equals the host's
//! render of its own image, and frame n+1's scene is broadcast into the nodes' other bank
//! while frame n renders (virtual time stamps of the bus log).

use std::path::Path;

use links_core::dm::CompileOptions;
use links_core::wire::SCENE_CHUNK;
use links_host::cluster::dmcost::{DmCost, DmMachine};
use links_host::cluster::timeline::BusTransfer;
use links_host::cluster::{steady_state_interval, SimConfig};
use links_host::scene_file::load_film;
use links_host::sim::film::{compile_film, simulate_film, FilmImages};
use links_tests::host_reference as reference;

fn photo1(opts: &CompileOptions) -> Vec<u8> {
    let film = load_film(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1.ron"))
        .expect("photo1 loads");
    film.compile_frame(0, opts).expect("compiles").bytes
}

fn film_of(images: Vec<Vec<u8>>) -> FilmImages {
    FilmImages {
        first: 0,
        dm_instructions: vec![0.0; images.len()],
        images,
    }
}

#[test]
fn a_films_steady_state_comes_from_its_distinct_frames() {
    let size = CompileOptions {
        width: Some(64),
        height: Some(60),
        ..Default::default()
    };
    // Heavy: photo1 as written. Light: the same view without shadows or reflections.
    let heavy = photo1(&size);
    let light = photo1(&CompileOptions {
        no_shadows: true,
        max_depth: Some(1),
        ..size
    });
    // The F407's firmware link (the default): the next frame's scene lands in the nodes'
    // lent banks while they render.
    let cfg = SimConfig {
        nodes: 8,
        ..SimConfig::default()
    };
    let t_light = steady_state_interval(&light, &cfg, 6).expect("simulates");
    let t_heavy = steady_state_interval(&heavy, &cfg, 6).expect("simulates");
    assert!(t_heavy > 1.5 * t_light, "{t_heavy} vs {t_light}");
    // Light and heavy frames alternate: the film's interval is their mean, far from either
    // repeated alone (it would equal the light one if frame 0 were repeated). Seven frames:
    // the steady state, (T(7) - T(1)) / 6, then spans three of each kind (with six it spanned
    // three heavy and two light and leaned 16% towards the heavy one).
    let images: Vec<Vec<u8>> = (0..7)
        .map(|f| {
            if f % 2 == 0 {
                light.clone()
            } else {
                heavy.clone()
            }
        })
        .collect();
    let run = simulate_film(
        &film_of(images.clone()),
        &SimConfig {
            keep_frames: true,
            ..cfg
        },
        DmMachine::PC,
    )
    .expect("simulates");
    let mean = 0.5 * (t_light + t_heavy);
    let got = run.steady_s();
    assert!((got - mean).abs() < 0.1 * mean, "{got} vs mean {mean}");
    assert!(got > 1.2 * t_light && got < 0.9 * t_heavy, "{got}");
    // Each frame is its own image's render, bit for bit; the two kinds differ.
    let (want_light, want_heavy) = (reference(&light), reference(&heavy));
    assert_ne!(want_light, want_heavy);
    for (f, rgb) in run.report.frames.iter().enumerate() {
        let want = if f % 2 == 0 { &want_light } else { &want_heavy };
        assert!(rgb == want, "frame {f} differs from its host render");
    }
    // The one-node reference rendered the same film: its interval is the nodes' total work
    // per frame, so the speed-up is below the node count and well above 1.
    assert!(
        run.speedup() > 4.0 && run.speedup() < 8.0,
        "{}",
        run.speedup()
    );
}

/// The broadcasts on bus 0, in order (exchanges left out).
fn broadcasts(run: &links_host::sim::film::FilmRun) -> Vec<BusTransfer> {
    let log = run.report.timeline.as_ref().expect("a timeline");
    assert!(log.complete(), "the log dropped entries");
    log.bus[0]
        .iter()
        .filter(|t| t.node.is_none())
        .copied()
        .collect()
}

#[test]
fn frame_n_plus_1_is_broadcast_into_the_other_bank_while_frame_n_renders() {
    let film = load_film(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1-orbit.ron"))
        .expect("film loads");
    let opts = CompileOptions {
        width: Some(96),
        height: Some(90),
        ..Default::default()
    };
    let images = compile_film(&film, 0..3, &opts, &DmCost::ESTIMATE).expect("compiles");
    assert_ne!(images.images[0], images.images[1]);
    let cfg = SimConfig {
        nodes: 16,
        timeline: Some(1_000_000),
        ..SimConfig::default()
    };
    let run = simulate_film(&images, &cfg, DmMachine::PC).expect("simulates");
    let ps = |s: f64| (s * 1e12).round() as u64;
    let done: Vec<u64> = run.report.frame_done_s.iter().map(|&s| ps(s)).collect();
    // Each scene is its chunks and a SceneEnd, broadcast in frame order.
    let parts: Vec<usize> = images
        .images
        .iter()
        .map(|i| i.len().div_ceil(SCENE_CHUNK) + 1)
        .collect();
    let bc = broadcasts(&run);
    assert!(
        bc.len() >= parts.iter().sum::<usize>(),
        "{} broadcasts",
        bc.len()
    );
    let first_of = |f: usize| parts[..f].iter().sum::<usize>();
    let last_of = |f: usize| first_of(f + 1) - 1;
    // The DM's stamps: frame f's scene goes out only once the DM has compiled frames 0..=f.
    let mut ready = 0u64;
    for f in 0..3 {
        ready += ps(run.dm_s[f]);
        assert!(run.dm_s[f] > 0.0);
        assert!(
            bc[first_of(f)].at.start >= ready,
            "frame {f} before the DM made it"
        );
    }
    // Frame 1's whole scene goes out while frame 0 renders (after frame 0's SceneEnd, before
    // frame 0 completes): it fills the other bank.
    assert!(bc[first_of(1)].at.start >= bc[last_of(0)].at.end);
    assert!(
        bc[last_of(1)].at.end < done[0],
        "frame 1's scene ended at {} ps, frame 0 done at {} ps",
        bc[last_of(1)].at.end,
        done[0]
    );
    // Frame 2's goes into frame 0's bank: not before frame 0 is complete.
    assert!(bc[first_of(2)].at.start >= done[0]);
    // The frames are the host's renders of their own images.
    for (f, rgb) in run.report.frames.iter().enumerate() {
        assert!(*rgb == reference(&images.images[f]), "frame {f}");
    }
}
