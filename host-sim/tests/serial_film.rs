//! `links upload --frames` end to end over a pseudo-terminal: a thread serves the film as the
//! RC (the firmware's session with two scene banks, `links_host::sim_film`), the `links`
//! binary streams photo1-orbit's frames and collects them. The frames must be the host
//! render's byte for byte, the PC never more than one frame ahead, line faults repaired,
//! and a frame that cannot be read named in the error.
#![cfg(unix)]

use links_host::sim_film::{serve_film, FilmFaults, FilmLog, FilmServed};
use serialport::{SerialPort, TTYPort};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

const FRAMES: usize = 3;
/// The simulated RC's patience with a silent PC.
const LONG: Duration = Duration::from_secs(20);

fn links() -> Command {
    Command::new(env!("CARGO_BIN_EXE_links"))
}

fn orbit() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1-orbit.ron")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("links-film-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Frames 0..3 at 32x30 as `links render --frames` writes them (the reference).
fn host_render(dir: &Path) {
    let o = links()
        .args(["render"])
        .arg(orbit())
        .args([
            "--frames", "0..3", "--width", "32", "--height", "30", "-q", "-o",
        ])
        .arg(dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Upload frames 0..3 to a simulated RC with `faults` over a pty; the command's output and
/// what the RC saw.
fn upload_film(
    dir: &Path,
    faults: FilmFaults,
    rc_timeout: Duration,
) -> (Output, std::io::Result<FilmServed>) {
    upload_film_to(dir, faults, rc_timeout, 62 * 1024)
}

/// [`upload_film`] to an RC whose scene banks hold `bank` bytes each.
fn upload_film_to(
    dir: &Path,
    faults: FilmFaults,
    rc_timeout: Duration,
    bank: usize,
) -> (Output, std::io::Result<FilmServed>) {
    let (mut master, slave) = TTYPort::pair().expect("a pseudo-terminal pair");
    master.set_timeout(Duration::from_secs(30)).unwrap();
    let name = slave.name().expect("the slave has a path");
    let mut rx = master
        .try_clone_native()
        .expect("a second master descriptor");
    rx.set_timeout(Duration::from_millis(2)).unwrap();
    // Kept open for the whole run (see tests/serial.rs: the PC's last flush races a close).
    std::mem::forget(master.try_clone_native().expect("a third descriptor"));
    let rc =
        std::thread::spawn(move || serve_film(&mut rx, &mut master, bank, &faults, rc_timeout));
    let o = links()
        .args(["upload"])
        .arg(orbit())
        .args(["--frames", "0..3", "--width", "32", "--height", "30"])
        .args(["--port", &name, "--timeout-ms", "2000"])
        .args(["--readback-timeout-ms", "2000", "-o"])
        .arg(dir)
        .output()
        .unwrap();
    let served = rc.join().unwrap();
    drop(slave);
    (o, served)
}

fn frame_png(dir: &Path, k: usize) -> Vec<u8> {
    std::fs::read(dir.join(format!("frame-{k:04}.png"))).expect("frame written")
}

/// Frame `k + 1` was begun only after frame `k` started rendering (and so at most one frame
/// was ever stored ahead of the cluster), and every frame went begin, start, end, ack.
fn assert_one_frame_ahead(log: &[FilmLog]) {
    let at = |e: FilmLog| {
        log.iter()
            .position(|&l| l == e)
            .unwrap_or_else(|| panic!("{e:?} missing from {log:?}"))
    };
    for k in 0..FRAMES as u16 {
        let (b, s, r, a) = (
            at(FilmLog::Begin(k)),
            at(FilmLog::Started(k)),
            at(FilmLog::Rendered(k)),
            at(FilmLog::Acked(k)),
        );
        assert!(b < s && s < r && r < a, "frame {k}: {log:?}");
        if k > 0 {
            assert!(
                at(FilmLog::Started(k - 1)) < b,
                "frame {k} begun early: {log:?}"
            );
            assert!(
                at(FilmLog::Acked(k - 1)) < s,
                "frame {k} started early: {log:?}"
            );
        }
    }
}

fn assert_same_film(got: &Path, want: &Path) {
    for k in 0..FRAMES {
        assert!(
            frame_png(got, k) == frame_png(want, k),
            "frame {k} differs from the host render"
        );
    }
    let film = |d: &Path| std::fs::read(d.join("film.png")).expect("film.png written");
    assert!(
        film(got) == film(want),
        "film.png differs from the host render's"
    );
    assert!(frame_png(want, 0) != frame_png(want, 1) && frame_png(want, 1) != frame_png(want, 2));
}

#[test]
fn a_film_uploaded_with_frames_reads_back_as_the_host_renders_it() {
    let (want, got) = (tmp("host"), tmp("board"));
    host_render(&want);
    let (o, served) = upload_film(&got, FilmFaults::default(), LONG);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let served = served.expect("the RC served the film");
    assert_same_film(&got, &want);
    assert_one_frame_ahead(&served.log);
    assert_eq!((served.naks, served.resends), (0, 0));
    for k in 0..FRAMES {
        assert!(err.contains(&format!("frame {k}: rendering")), "{err}");
        assert!(err.contains(&format!("frame-{k:04}.png 32x30")), "{err}");
    }
    assert!(err.contains("film: 3 frames (0..3)"), "{err}");
}

#[test]
fn a_corrupted_chunk_and_pixel_run_of_frame_2_are_sent_again() {
    let (want, got) = (tmp("host-faults"), tmp("board-faults"));
    host_render(&want);
    let faults = FilmFaults {
        corrupt_chunk_of: Some(2),
        corrupt_run_of: Some(2),
        ..FilmFaults::default()
    };
    let (o, served) = upload_film(&got, faults, LONG);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let served = served.expect("the RC served the film");
    assert_eq!(served.bad_packets, 1, "the corrupted chunk");
    assert_eq!(served.naks, 1, "one retransmit request for it");
    assert_eq!(served.resends, 1, "one pixel retransmit request");
    assert_same_film(&got, &want);
    assert_one_frame_ahead(&served.log);
    assert!(err.contains("1 retransmit requests"), "{err}");
}

#[test]
fn a_lost_frame_started_is_read_from_the_frame_header() {
    let (want, got) = (tmp("host-started"), tmp("board-started"));
    host_render(&want);
    let faults = FilmFaults {
        lose_started_of: Some(1),
        ..FilmFaults::default()
    };
    let (o, served) = upload_film(&got, faults, LONG);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_one_frame_ahead(&served.expect("the RC served the film").log);
    assert_same_film(&got, &want);
}

#[test]
fn readback_with_frames_collects_the_frames_an_rc_streams() {
    let (want, got) = (tmp("host-rb"), tmp("board-rb"));
    host_render(&want);
    let frames: Vec<Vec<u8>> = (0..FRAMES)
        .map(|k| {
            links_host::frame::decode_png_rgb(&frame_png(&want, k))
                .unwrap()
                .2
        })
        .collect();
    let (mut master, slave) = TTYPort::pair().expect("a pseudo-terminal pair");
    master.set_timeout(Duration::from_secs(30)).unwrap();
    let name = slave.name().expect("the slave has a path");
    std::mem::forget(master.try_clone_native().expect("a second descriptor"));
    let rc = std::thread::spawn(move || {
        for (k, rgb) in frames.into_iter().enumerate() {
            let mut rc = links_host::sim_rc::SimRc::new(k as u16, 32, 30, rgb).unwrap();
            rc.stream(&mut master).unwrap();
            rc.answer(&mut master, Duration::from_secs(20)).unwrap();
        }
    });
    let o = links()
        .args([
            "readback", "--frames", "0..3", "--rate", "12", "--port", &name, "-o",
        ])
        .arg(&got)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    rc.join().unwrap();
    drop(slave);
    for k in 0..FRAMES {
        assert!(frame_png(&got, k) == frame_png(&want, k), "frame {k}");
    }
    assert!(err.contains("film: 3 frames (0..3)"), "{err}");
}

#[test]
fn a_frame_that_fails_its_crc_is_named() {
    let got = tmp("board-crc");
    let faults = FilmFaults {
        wrong_crc_of: Some(2),
        ..FilmFaults::default()
    };
    let (o, _) = upload_film(&got, faults, Duration::from_secs(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("film frame 2: frame 2 failed its CRC check"),
        "{err}"
    );
    // The frames before it were written.
    frame_png(&got, 0);
    frame_png(&got, 1);
}

#[test]
fn a_frame_the_rc_refuses_is_named() {
    let got = tmp("board-refused");
    // photo1-orbit's frames at 32x30 are 18,292, 18,272 and 18,452 bytes: the third does
    // not fit banks of 18,400.
    let (o, _) = upload_film_to(&got, FilmFaults::default(), Duration::from_secs(1), 18_400);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains(
            "film frame 2: the RC refused: scene of 18452 bytes does not fit the RC's 18400-byte scene buffer"
        ),
        "{err}"
    );
    frame_png(&got, 0);
}
