//! `links upload` and `links readback` end to end over pseudo-terminal pairs: a thread acts
//! as the RC (the firmware's no_std `UploadReceiver` / `FrameStreamer` on the master side),
//! the `links` binary opens the slave side as its serial port.
#![cfg(unix)]

use links_core::dm::{compile, CompileOptions};
use links_core::serial::{encode_packet, ToPc};
use links_host::frame::decode_png_rgb;
use links_host::scene_file::load_scene;
use links_host::serial_host::{readback, HostSerialError, ReadbackOptions};
use links_host::sim_rc::{receive_upload, render_scene, SimRc};
use serialport::{SerialPort, TTYPort};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

fn links() -> Command {
    Command::new(env!("CARGO_BIN_EXE_links"))
}

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(name)
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("links-serial-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// A pseudo-terminal pair: the RC's end (master) and the PC's (slave), and the slave's
/// path. The slave stays open here so the pair lives while the binary opens and closes it.
fn pty() -> (TTYPort, TTYPort, String) {
    let (mut master, slave) = TTYPort::pair().expect("a pseudo-terminal pair");
    // Long enough for writes to wait for a reader that is still starting.
    master.set_timeout(Duration::from_secs(30)).unwrap();
    let name = slave.name().expect("the slave has a path");
    // A second descriptor of the master, kept open for the whole test run: when the RC
    // thread ends and drops its end, the PC side's last flush (tcdrain) would otherwise race
    // the close and fail with EIO (seen once under load). A board's RC never closes its end.
    std::mem::forget(
        master
            .try_clone_native()
            .expect("a second master descriptor"),
    );
    (master, slave, name)
}

const W: u16 = 64;
const H: u16 = 60;

fn photo1() -> Vec<u8> {
    render_scene(&scene("photo1.ron"), W as u32, H as u32).expect("renders")
}

#[test]
fn readback_over_a_pty_matches_the_simulated_frame_pixel_for_pixel() {
    let rgb = photo1();
    // A real picture, not a flat one.
    assert!(rgb.chunks_exact(3).any(|p| p != &rgb[..3]));
    let (mut master, _slave, name) = pty();
    let mut rc = SimRc::new(7, W, H, rgb.clone()).unwrap();
    // Two pixel messages are corrupted on the line: the PC must ask for them again.
    rc.corrupt_runs = vec![3, 40];
    let rc_thread = std::thread::spawn(move || {
        rc.stream(&mut master)?;
        master.set_timeout(Duration::from_millis(100))?;
        rc.answer(&mut master, Duration::from_secs(30))
    });
    let out = tmp("readback.png");
    let o = links()
        .args(["readback", "--port", &name, "--timeout-ms", "3000", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let (w, h, png) = decode_png_rgb(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!((w, h), (W as u32, H as u32));
    assert!(png == rgb, "the PNG differs from the simulated frame");
    assert!(err.contains("frame 7 64x60"), "{err}");
    assert!(err.contains("2 malformed messages repaired"), "{err}");
    let served = rc_thread.join().unwrap().expect("the RC got its FrameAck");
    assert_eq!(served.resends, 1, "one request covers both gaps");
    assert_eq!(served.bad_packets, 0);
}

#[test]
fn clean_readback_needs_no_retransmission() {
    let (mut master, mut slave, _) = pty();
    let rgb: Vec<u8> = (0..3 * 40 * 30).map(|i| (i * 31 % 251) as u8).collect();
    let mut rc = SimRc::new(0, 40, 30, rgb.clone()).unwrap();
    let rc_thread = std::thread::spawn(move || {
        rc.stream(&mut master)?;
        master.set_timeout(Duration::from_millis(100))?;
        rc.answer(&mut master, Duration::from_secs(30))
    });
    let events = std::cell::RefCell::new(Vec::new());
    let r = readback(&mut slave, "pty", &ReadbackOptions::default(), &|e| {
        events.borrow_mut().push(e)
    })
    .unwrap();
    assert_eq!((r.width, r.height, r.frame), (40, 30, 0));
    assert_eq!(r.rgb, rgb);
    assert_eq!((r.bad_packets, r.resends), (0, 0));
    assert_eq!(r.crc, links_core::wire::CRC32.checksum(&rgb));
    let served = rc_thread.join().unwrap().unwrap();
    assert_eq!(served.resends, 0);
    let events = events.into_inner();
    use links_host::serial_host::ReadbackEvent as E;
    assert!(events.contains(&E::Header {
        frame: 0,
        width: 40,
        height: 30
    }));
    assert!(events.contains(&E::Pixels {
        have: 1200,
        total: 1200
    }));
    assert!(events.iter().any(|e| matches!(e, E::Rendering { .. })));
}

#[test]
fn a_lost_frame_end_is_asked_for_after_the_silence() {
    let (mut master, mut slave, _) = pty();
    let rgb: Vec<u8> = (0..3 * 300 * 7).map(|i| (i % 7) as u8 * 30).collect();
    let mut rc = SimRc::new(1, 300, 7, rgb.clone()).unwrap();
    rc.corrupt_first_end = true;
    rc.corrupt_runs = vec![0];
    let rc_thread = std::thread::spawn(move || {
        rc.stream(&mut master)?;
        master.set_timeout(Duration::from_millis(100))?;
        rc.answer(&mut master, Duration::from_secs(30))
    });
    let opts = ReadbackOptions {
        timeout: Duration::from_millis(300),
        ..ReadbackOptions::default()
    };
    let start = Instant::now();
    let r = readback(&mut slave, "pty", &opts, &|_| {}).unwrap();
    assert!(
        start.elapsed() >= Duration::from_millis(300),
        "waited for the silence"
    );
    assert_eq!(r.rgb, rgb);
    // The first run and the FrameEnd were corrupted: a Resend after the silence repairs
    // both (more than one only if this machine stalls the RC thread for 300 ms).
    assert_eq!(r.bad_packets, 2);
    assert!(r.resends >= 1);
    assert_eq!(rc_thread.join().unwrap().unwrap().resends, r.resends);
}

#[test]
fn upload_over_a_pty_arrives_intact_after_a_corrupted_chunk() {
    let desc = load_scene(&scene("photo1.ron")).unwrap();
    let opts = CompileOptions {
        width: Some(W as u32),
        height: Some(H as u32),
        ..CompileOptions::default()
    };
    let image = compile(&desc, &opts).unwrap().bytes;
    assert!(image.len() > 4 * 512, "several chunks: {}", image.len());
    let (mut master, _slave, name) = pty();
    // PC frame 0 is SceneBegin; frame 3 (the third chunk) is corrupted on the line.
    master.set_timeout(Duration::from_millis(200)).unwrap();
    let rc_thread = std::thread::spawn(move || {
        receive_upload(
            &mut master,
            128 * 1024,
            &[3],
            Duration::from_secs(30),
            Duration::from_millis(500),
        )
    });
    let o = links()
        .args(["upload"])
        .arg(scene("photo1.ron"))
        .args(["--width", "64", "--height", "60", "--render", "1"])
        .args(["--port", &name, "--timeout-ms", "5000"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let got = rc_thread.join().unwrap().expect("upload received");
    assert!(got.image == image, "the SceneImage arrived changed");
    assert_eq!((got.naks, got.bad_packets), (1, 1));
    assert_eq!(got.start_render, Some(1));
    let chunks = image.len().div_ceil(512) + 1;
    assert!(
        err.contains(&format!(
            "uploaded {} bytes in {chunks} chunks",
            image.len()
        )) && err.contains("1 retransmit requests"),
        "{err}"
    );
}

#[test]
fn a_missing_port_is_a_clear_error() {
    for args in [
        vec!["readback", "-o", "never.png"],
        vec!["upload", "scenes/photo1.ron"],
    ] {
        let o = links()
            .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
            .args(&args)
            .args(["--port", "/dev/links-no-such-port"])
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(1));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains("serial port /dev/links-no-such-port does not exist"),
            "{err}"
        );
    }
}

#[test]
fn a_silent_rc_is_reported_as_a_timeout() {
    let (_master, _slave, name) = pty();
    let start = Instant::now();
    let o = links()
        .args(["readback", "--port", &name, "--timeout-ms", "300", "-o"])
        .arg(tmp("never.png"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("timed out after 300 ms") && err.contains("waiting for a frame"),
        "{err}"
    );
    assert!(!tmp("never.png").exists());
    let o = links()
        .arg("upload")
        .arg(scene("photo1.ron"))
        .args(["--width", "16", "--height", "15"])
        .args(["--port", &name, "--timeout-ms", "100"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("timed out after 100 ms") && err.contains("scene header"),
        "{err}"
    );
    assert!(start.elapsed() < Duration::from_secs(20));
}

#[test]
fn the_overall_deadline_ends_a_readback_before_its_silence_time_out() {
    // Progress every 100 ms, a row further each time: no rule but the deadline ends it.
    let (mut master, _slave, name) = pty();
    let rc = std::thread::spawn(move || {
        let mut line = [0u8; 64];
        let n = encode_packet(
            0,
            &ToPc::FrameHeader {
                frame: 0,
                width: 1024,
                height: 1024,
            },
            &mut line,
        )
        .unwrap();
        master.write_all(&line[..n]).unwrap();
        for k in 1..=20u32 {
            std::thread::sleep(Duration::from_millis(100));
            let msg = ToPc::Progress {
                frame: 0,
                done: k * 1024,
                total: 1024 * 1024,
            };
            let n = encode_packet(k as u16, &msg, &mut line).unwrap();
            if master.write_all(&line[..n]).is_err() {
                break;
            }
        }
    });
    let start = Instant::now();
    let o = links()
        .args(["readback", "--port", &name, "--timeout-ms", "60000"])
        .args(["--deadline-s", "1", "-o"])
        .arg(tmp("never2.png"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("at the overall deadline of 1000 ms (--deadline-s): frame 0: 0 of 1048576 pixels received"),
        "{err}"
    );
    assert!(!tmp("never2.png").exists());
    // Well before the 60 s silence time-out (and the end of the RC's 2 s of Progress).
    assert!(start.elapsed() < Duration::from_secs(30));
    rc.join().unwrap();
}

#[test]
fn a_wrong_frame_crc_is_reported_after_one_full_retry() {
    let (mut master, mut slave, _) = pty();
    let rgb: Vec<u8> = (0..3 * 16 * 8).map(|i| i as u8).collect();
    let mut rc = SimRc::new(2, 16, 8, rgb.clone()).unwrap();
    rc.wrong_crc = true;
    let rc_thread = std::thread::spawn(move || {
        rc.stream(&mut master)?;
        master.set_timeout(Duration::from_millis(100))?;
        rc.answer(&mut master, Duration::from_millis(500))
    });
    let r = readback(&mut slave, "pty", &ReadbackOptions::default(), &|_| {});
    let good = links_core::wire::CRC32.checksum(&rgb);
    assert_eq!(
        r,
        Err(HostSerialError::FrameCrc {
            frame: 2,
            expected: good ^ 1,
            found: good
        })
    );
    assert!(r.unwrap_err().to_string().contains("failed its CRC check"));
    // The RC was asked for the whole frame once, then never acknowledged.
    let served = rc_thread.join().unwrap();
    assert!(served.is_err());
}

#[test]
fn another_protocol_version_is_reported_as_a_mismatch() {
    let (mut master, mut slave, _) = pty();
    // A valid frame of this version, then one whose version byte is 9 (CRC recomputed).
    let mut line = [0u8; 64];
    let n = encode_packet(
        0,
        &ToPc::Progress {
            frame: 0,
            done: 1,
            total: 2,
        },
        &mut line,
    )
    .unwrap();
    master.write_all(&line[..n]).unwrap();
    let mut body = vec![9u8, 0, 0];
    body.extend_from_slice(&links_core::wire::CRC32.checksum(&body).to_le_bytes());
    let mut framed = vec![0u8; 16];
    let k = cobs_encode(&body, &mut framed[1..]);
    framed.truncate(1 + k);
    framed.push(0);
    master.write_all(&framed).unwrap();
    let r = readback(&mut slave, "pty", &ReadbackOptions::default(), &|_| {});
    assert_eq!(r, Err(HostSerialError::Version { found: 9 }));
    assert!(r
        .unwrap_err()
        .to_string()
        .contains("protocol version mismatch: the RC speaks serial protocol version 9"));
}

/// COBS by hand (the test must not share the code under test).
fn cobs_encode(src: &[u8], out: &mut [u8]) -> usize {
    let (mut code_at, mut n, mut code) = (0usize, 1usize, 1u8);
    for &b in src {
        if b == 0 {
            out[code_at] = code;
            code_at = n;
            n += 1;
            code = 1;
        } else {
            out[n] = b;
            n += 1;
            code += 1;
            if code == 0xff {
                out[code_at] = code;
                code_at = n;
                n += 1;
                code = 1;
            }
        }
    }
    out[code_at] = code;
    n
}
