use super::frame_crc::CRC32_RAW;
use super::*;
use crate::wire::CRC32;

/// xorshift64*: deterministic random numbers for the property tests.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn bytes(&mut self, out: &mut [u8]) {
        for b in out {
            *b = self.next() as u8;
        }
    }
}

/// Feed `bytes` and collect what the decoder reports: decoded packets are re-encoded
/// (with their seq) so they can be compared after the borrow ends.
fn feed_all(dec: &mut Decoder<MAX_TO_PC>, bytes: &[u8]) -> Vec<Result<Vec<u8>, SerialError>> {
    let mut out = Vec::new();
    for &b in bytes {
        if let Some(r) = dec.feed::<ToPc>(b) {
            out.push(r.map(|p| {
                let mut buf = vec![0u8; MAX_TO_PC];
                let n = encode_packet(p.seq, &p.msg, &mut buf).unwrap();
                buf.truncate(n);
                buf
            }));
        }
    }
    out
}

/// Decode one complete frame, byte at a time, and return its seq and the message re-encoded.
fn decode_one_to_pc(frame: &[u8]) -> (u16, Vec<u8>) {
    let mut dec = Decoder::<MAX_TO_PC>::new();
    let mut got = None;
    for (i, &b) in frame.iter().enumerate() {
        if let Some(r) = dec.feed::<ToPc>(b) {
            assert_eq!(i, frame.len() - 1, "frame ends at its last byte");
            let p = r.expect("decodes");
            assert_eq!(p.version, VERSION);
            let mut buf = vec![0u8; MAX_TO_PC];
            let n = encode_packet(p.seq, &p.msg, &mut buf).unwrap();
            got = Some((p.seq, buf[..n].to_vec()));
        }
    }
    got.expect("one frame")
}

fn to_pc_messages(rgb: &[u8], rle: &[u8]) -> Vec<ToPc<'static>> {
    let rgb: &'static [u8] = Vec::leak(rgb.to_vec());
    let rle: &'static [u8] = Vec::leak(rle.to_vec());
    vec![
        ToPc::Ack { offset: 0 },
        ToPc::Ack { offset: u32::MAX },
        ToPc::Nak { offset: 512 },
        ToPc::SceneDone {
            len: 90_000,
            crc: 0xdead_beef,
        },
        ToPc::FrameHeader {
            frame: 3,
            width: 1024,
            height: 1024,
        },
        ToPc::Pixels {
            frame: u16::MAX,
            y: 1023,
            x: 768,
            rgb,
        },
        ToPc::PixelsRle {
            frame: 1,
            y: 2,
            x: 3,
            len: 256,
            data: rle,
        },
        ToPc::FrameEnd {
            frame: 9,
            crc: 0x0000_0001,
        },
        ToPc::Progress {
            frame: 0,
            done: 100,
            total: 3072,
        },
        ToPc::Error {
            code: RcError::SceneTooLarge { len: 5, max: 4 },
        },
        ToPc::Error {
            code: RcError::EmptyScene,
        },
        ToPc::Error {
            code: RcError::SceneCrc {
                expected: 1,
                found: 2,
            },
        },
        ToPc::Error {
            code: RcError::NotUploading,
        },
        ToPc::Error {
            code: RcError::Version { found: 7 },
        },
        ToPc::Error {
            code: RcError::NoScene,
        },
    ]
}

#[test]
fn every_message_round_trips_through_encoder_and_decoder() {
    let rgb: Vec<u8> = (0..3 * MAX_RUN).map(|i| (i * 7) as u8).collect();
    let rle = [0xff, 0, 0, 0, 0, 1, 2, 3];
    let mut enc = Encoder::new();
    for (i, msg) in to_pc_messages(&rgb, &rle).iter().enumerate() {
        let mut buf = [0u8; MAX_TO_PC];
        let n = enc.encode(msg, &mut buf).unwrap();
        assert!(n <= MAX_TO_PC);
        assert_eq!((buf[0], buf[n - 1]), (0, 0), "delimited");
        assert!(!buf[1..n - 1].contains(&0), "no zero inside a frame");
        let mut dec = Decoder::<MAX_TO_PC>::new();
        let mut seen = None;
        for &b in &buf[..n] {
            if let Some(r) = dec.feed::<ToPc>(b) {
                let p = r.unwrap();
                assert_eq!(p.seq, i as u16);
                assert_eq!(&p.msg, msg);
                seen = Some(());
            }
        }
        assert!(seen.is_some(), "message {i} decoded");
    }
    let chunk = [0u8; MAX_CHUNK];
    let to_rc = [
        ToRc::SceneBegin {
            len: u32::MAX,
            crc: u32::MAX,
        },
        ToRc::SceneChunk {
            offset: u32::MAX,
            data: &chunk,
        },
        ToRc::StartRender { frames: 2 },
        ToRc::Resend {
            frame: 1,
            start: 5,
            len: 0,
        },
        ToRc::FrameAck { frame: u16::MAX },
    ];
    let mut enc = Encoder::new();
    for msg in to_rc {
        let mut buf = [0u8; MAX_TO_RC];
        let n = enc.encode(&msg, &mut buf).unwrap();
        let mut dec = Decoder::<MAX_TO_RC>::new();
        let got: Vec<_> = buf[..n]
            .iter()
            .filter_map(|&b| dec.feed::<ToRc>(b).map(|r| r.map(|p| p.msg == msg)))
            .collect();
        assert_eq!(got, vec![Ok(true)]);
    }
    assert_eq!(enc.next_seq(), 5);
}

#[test]
fn largest_messages_fit_the_limits_and_a_small_buffer_is_refused() {
    let rgb = [0xffu8; 3 * MAX_RUN];
    let msg = ToPc::Pixels {
        frame: u16::MAX,
        y: u16::MAX,
        x: u16::MAX,
        rgb: &rgb,
    };
    let mut buf = [0u8; MAX_TO_PC];
    let n = encode_packet(u16::MAX, &msg, &mut buf).unwrap();
    assert!(n <= MAX_TO_PC, "{n}");
    let chunk = [0xffu8; MAX_CHUNK];
    let msg = ToRc::SceneChunk {
        offset: u32::MAX,
        data: &chunk,
    };
    let mut buf = [0u8; MAX_TO_RC];
    let n = encode_packet(u16::MAX, &msg, &mut buf).unwrap();
    assert!(n <= MAX_TO_RC, "{n}");
    // One byte short fails cleanly, and the sequence number stays.
    let n = encode_packet(0, &msg, &mut buf).unwrap();
    let mut enc = Encoder::new();
    assert_eq!(
        enc.encode(&msg, &mut buf[..n - 1]),
        Err(SerialError::BufferFull)
    );
    assert_eq!(enc.encode(&msg, &mut []), Err(SerialError::BufferFull));
    assert_eq!(enc.next_seq(), 0);
    assert_eq!(enc.encode(&msg, &mut buf), Ok(n));
    assert_eq!(enc.next_seq(), 1);
}

#[test]
fn every_corrupted_byte_is_an_error_never_a_wrong_message() {
    let rgb: Vec<u8> = (0..60u8).collect();
    let msg = ToPc::Pixels {
        frame: 2,
        y: 7,
        x: 9,
        rgb: &rgb,
    };
    let mut frame = [0u8; MAX_TO_PC];
    let n = encode_packet(5, &msg, &mut frame).unwrap();
    let good = decode_one_to_pc(&frame[..n]);
    for i in 1..n - 1 {
        for flip in [0x01u8, 0x80, 0xff] {
            let mut bad = frame[..n].to_vec();
            bad[i] ^= flip;
            let mut dec = Decoder::<MAX_TO_PC>::new();
            let results = feed_all(&mut dec, &bad);
            assert!(
                results.iter().all(|r| r.is_err()),
                "byte {i} ^ {flip:#x} decoded: {results:?}"
            );
            assert!(!results.is_empty(), "byte {i} ^ {flip:#x}: reported");
            assert_eq!(dec.good_packets(), 0);
            assert_eq!(dec.bad_packets() as usize, results.len());
            // The decoder is in step again for the next frame.
            let next = feed_all(&mut dec, &frame[..n]);
            assert_eq!(next, vec![Ok(good.1.clone())]);
        }
    }
    // A changed payload byte with the stuffing intact is exactly a CRC error.
    let mut bad = frame[..n].to_vec();
    let i = bad.iter().rposition(|&b| b == 59).unwrap();
    bad[i] = 58;
    let mut dec = Decoder::<MAX_TO_PC>::new();
    assert_eq!(feed_all(&mut dec, &bad), vec![Err(SerialError::BadCrc)]);
}

#[test]
fn decoder_resynchronises_after_garbage() {
    let mut rng = Rng(0x1234_5678_9abc_def1);
    let mut enc = Encoder::new();
    let mut frame = [0u8; MAX_TO_PC];
    for round in 0..300 {
        let mut garbage = vec![0u8; rng.below(3 * MAX_TO_PC)];
        rng.bytes(&mut garbage);
        if round % 3 == 0 {
            // Garbage without any delimiter runs straight into the next frame.
            for b in &mut garbage {
                *b |= 1;
            }
        }
        let msg = ToPc::Progress {
            frame: round,
            done: rng.next() as u32,
            total: u32::MAX,
        };
        let n = enc.encode(&msg, &mut frame).unwrap();
        let mut stream = garbage.clone();
        stream.extend_from_slice(&frame[..n]);
        let mut dec = Decoder::<MAX_TO_PC>::new();
        let mut found = Vec::new();
        for &b in &stream {
            if let Some(Ok(p)) = dec.feed::<ToPc>(b) {
                found.push(p.msg == msg);
            }
        }
        // Random garbage could in principle hold a valid frame; the real one is last.
        assert_eq!(found.last(), Some(&true), "round {round}");
    }
}

#[test]
fn truncated_frames_are_errors_and_the_next_frame_decodes() {
    let rgb = [1u8, 2, 3, 4, 5, 6];
    let msg = ToPc::Pixels {
        frame: 0,
        y: 1,
        x: 2,
        rgb: &rgb,
    };
    let mut frame = [0u8; MAX_TO_PC];
    let n = encode_packet(0, &msg, &mut frame).unwrap();
    let whole = decode_one_to_pc(&frame[..n]);
    for cut in 1..n - 1 {
        // The frame stops after `cut` bytes (its leading delimiter and part of the body),
        // then a complete frame follows.
        let mut stream = frame[..cut].to_vec();
        stream.extend_from_slice(&frame[..n]);
        let mut dec = Decoder::<MAX_TO_PC>::new();
        let results = feed_all(&mut dec, &stream);
        let (last, before) = results.split_last().unwrap();
        assert_eq!(last, &Ok(whole.1.clone()), "cut at {cut}");
        if cut > 1 {
            assert_eq!(before.len(), 1, "cut at {cut}: {results:?}");
            assert!(matches!(
                before[0],
                Err(SerialError::Truncated | SerialError::BadCrc | SerialError::Cobs)
            ));
        } else {
            assert!(before.is_empty());
        }
    }
    // The shortest frames: one or a few bytes between delimiters.
    let mut dec = Decoder::<MAX_TO_PC>::new();
    assert_eq!(
        feed_all(
            &mut dec,
            &[0, 6, 1, 2, 3, 4, 0, 0, 5, 1, 2, 3, 4, 0, 0, 1, 0]
        ),
        vec![
            Err(SerialError::Cobs),
            Err(SerialError::Truncated),
            Err(SerialError::Truncated)
        ]
    );
}

#[test]
fn oversize_frames_are_skipped_without_panic() {
    let rgb = [9u8; 3 * 100];
    let big = ToPc::Pixels {
        frame: 0,
        y: 0,
        x: 0,
        rgb: &rgb,
    };
    let small = ToPc::Ack { offset: 77 };
    let mut buf = [0u8; MAX_TO_PC];
    let mut stream = Vec::new();
    for m in [&big, &small, &big, &big, &small] {
        let n = encode_packet(1, m, &mut buf).unwrap();
        stream.extend_from_slice(&buf[..n]);
    }
    let mut dec = Decoder::<64>::new();
    let mut got = Vec::new();
    for &b in &stream {
        if let Some(r) = dec.feed::<ToPc>(b) {
            got.push(r.map(|p| p.msg == small));
        }
    }
    let o = Err(SerialError::Oversize);
    assert_eq!(got, vec![o, Ok(true), o, o, Ok(true)]);
    assert_eq!((dec.good_packets(), dec.bad_packets()), (2, 3));
}

#[test]
fn another_version_is_reported_as_such() {
    // Build a frame by hand whose version byte is 2, CRC correct.
    let mut body = vec![2u8, 0, 0, 0, 5];
    body.extend_from_slice(&CRC32.checksum(&body).to_le_bytes());
    let mut line = vec![0u8; framed_len(body.len())];
    line[0] = 0;
    let n = cobs::encode(&body, &mut line[1..]);
    line.truncate(1 + n);
    line.push(0);
    let mut dec = Decoder::<MAX_TO_PC>::new();
    assert_eq!(
        feed_all(&mut dec, &line),
        vec![Err(SerialError::Version { found: 2 })]
    );
    // Same with version 1 but an unknown message variant: malformed, not a version error.
    let mut body = vec![VERSION, 0, 99];
    body.extend_from_slice(&CRC32.checksum(&body).to_le_bytes());
    assert_eq!(decode_body::<ToPc>(&body), Err(SerialError::Malformed));
    // Trailing bytes after a valid message are malformed too.
    let mut body = vec![VERSION, 0, 0, 5, 0];
    body.extend_from_slice(&CRC32.checksum(&body).to_le_bytes());
    assert_eq!(decode_body::<ToPc>(&body), Err(SerialError::Malformed));
}

#[test]
fn random_bytes_never_panic_the_decoder() {
    let mut rng = Rng(42);
    let mut dec = Decoder::<MAX_TO_RC>::new();
    let mut stream = vec![0u8; 200_000];
    rng.bytes(&mut stream);
    // Mostly non-zero bytes so long frames (and overflows) happen too.
    for b in stream.iter_mut().skip(100_000) {
        if *b == 0 && rng.below(8) != 0 {
            *b = 1;
        }
    }
    let mut reported = 0u32;
    for &b in &stream {
        if dec.feed::<ToRc>(b).is_some() {
            reported += 1;
        }
    }
    assert!(reported > 100);
    assert_eq!(dec.good_packets() + dec.bad_packets(), reported);
    assert_eq!(
        dec.good_packets(),
        0,
        "random bytes pass a CRC-32 (1 in 4e9)"
    );
}

/// Drive an UploadReceiver with PC frames; returns the reply message's re-encoding and the event.
fn upload_step(
    rx: &mut UploadReceiver<'_>,
    enc_pc: &mut Encoder,
    enc_rc: &mut Encoder,
    msg: &ToRc<'_>,
    corrupt: bool,
) -> (ToPc<'static>, UploadEvent) {
    let mut line = [0u8; MAX_TO_RC];
    let n = enc_pc.encode(msg, &mut line).unwrap();
    if corrupt {
        let i = n / 2;
        line[i] = if line[i] == 1 { 2 } else { 1 };
    }
    let mut dec = Decoder::<MAX_TO_RC>::new();
    let mut reply = [0u8; MAX_TO_PC];
    let mut result = None;
    for &b in &line[..n] {
        match dec.feed::<ToRc>(b) {
            None => {}
            Some(Ok(p)) => result = Some(rx.on_message(&p.msg, enc_rc, &mut reply).unwrap()),
            Some(Err(e)) => result = Some(rx.on_bad_frame(e, enc_rc, &mut reply).unwrap()),
        }
    }
    let r = result.expect("one frame");
    assert!(r.len > 0, "every upload message is answered");
    let mut pc = Decoder::<MAX_TO_PC>::new();
    let mut msg = None;
    for &b in &reply[..r.len] {
        if let Some(p) = pc.feed::<ToPc>(b) {
            // Only reply kinds without borrowed data occur here.
            msg = Some(match p.unwrap().msg {
                ToPc::Ack { offset } => ToPc::Ack { offset },
                ToPc::Nak { offset } => ToPc::Nak { offset },
                ToPc::SceneDone { len, crc } => ToPc::SceneDone { len, crc },
                ToPc::Error { code } => ToPc::Error { code },
                other => panic!("unexpected reply {other:?}"),
            });
        }
    }
    (msg.unwrap(), r.event)
}

#[test]
fn upload_assembles_the_image_and_retransmits_bad_chunks() {
    let mut rng = Rng(7);
    let mut image = vec![0u8; 3000];
    rng.bytes(&mut image);
    let crc = CRC32.checksum(&image);
    let mut store = [0u8; 4096];
    let mut rx = UploadReceiver::new(&mut store);
    let (mut pc, mut rc) = (Encoder::new(), Encoder::new());
    let len = image.len() as u32;

    let chunk = |o: usize| &image[o..(o + MAX_CHUNK).min(image.len())];
    let (r, e) = upload_step(
        &mut rx,
        &mut pc,
        &mut rc,
        &ToRc::SceneChunk {
            offset: 0,
            data: chunk(0),
        },
        false,
    );
    assert_eq!(
        (r, e),
        (
            ToPc::Error {
                code: RcError::NotUploading
            },
            UploadEvent::Failed(RcError::NotUploading)
        )
    );
    let begin = ToRc::SceneBegin { len, crc };
    let (r, e) = upload_step(&mut rx, &mut pc, &mut rc, &begin, false);
    assert_eq!(
        (r, e),
        (ToPc::Ack { offset: 0 }, UploadEvent::Started { len })
    );
    let (r, _) = upload_step(
        &mut rx,
        &mut pc,
        &mut rc,
        &ToRc::SceneChunk {
            offset: 0,
            data: chunk(0),
        },
        false,
    );
    assert_eq!(r, ToPc::Ack { offset: 512 });
    // A corrupted chunk: Nak from the stored length, nothing stored.
    let (r, e) = upload_step(
        &mut rx,
        &mut pc,
        &mut rc,
        &ToRc::SceneChunk {
            offset: 512,
            data: chunk(512),
        },
        true,
    );
    assert_eq!(
        (r, e),
        (ToPc::Nak { offset: 512 }, UploadEvent::Nak { offset: 512 })
    );
    // A chunk past a gap: Nak too.
    let (r, _) = upload_step(
        &mut rx,
        &mut pc,
        &mut rc,
        &ToRc::SceneChunk {
            offset: 1024,
            data: chunk(1024),
        },
        false,
    );
    assert_eq!(r, ToPc::Nak { offset: 512 });
    assert_eq!(rx.naks(), 2);
    // A repeated SceneBegin keeps what is stored.
    let (r, _) = upload_step(&mut rx, &mut pc, &mut rc, &begin, false);
    assert_eq!(r, ToPc::Ack { offset: 512 });
    // A duplicate of an old chunk is acknowledged with the stored length.
    let (r, _) = upload_step(
        &mut rx,
        &mut pc,
        &mut rc,
        &ToRc::SceneChunk {
            offset: 0,
            data: chunk(0),
        },
        false,
    );
    assert_eq!(r, ToPc::Ack { offset: 512 });
    let mut o = 512;
    while o < image.len() {
        let (r, e) = upload_step(
            &mut rx,
            &mut pc,
            &mut rc,
            &ToRc::SceneChunk {
                offset: o as u32,
                data: chunk(o),
            },
            false,
        );
        o += chunk(o).len();
        if o < image.len() {
            assert_eq!(r, ToPc::Ack { offset: o as u32 });
            assert_eq!(e, UploadEvent::Progress { received: o as u32 });
        } else {
            assert_eq!(r, ToPc::SceneDone { len, crc });
            assert_eq!(e, UploadEvent::Complete { len });
        }
        assert!(rx.image().is_none() || o == image.len());
    }
    assert_eq!(rx.image(), Some(&image[..]));
    // The last chunk again (our SceneDone lost): SceneDone again.
    let last = image.len() - image.len() % MAX_CHUNK;
    let (r, _) = upload_step(
        &mut rx,
        &mut pc,
        &mut rc,
        &ToRc::SceneChunk {
            offset: last as u32,
            data: chunk(last),
        },
        false,
    );
    assert_eq!(r, ToPc::SceneDone { len, crc });
    assert_eq!(rx.image(), Some(&image[..]));
}

#[test]
fn upload_refusals() {
    let mut store = [0u8; 100];
    let mut rx = UploadReceiver::new(&mut store);
    let (mut pc, mut rc) = (Encoder::new(), Encoder::new());
    let (r, _) = upload_step(
        &mut rx,
        &mut pc,
        &mut rc,
        &ToRc::SceneBegin { len: 101, crc: 0 },
        false,
    );
    assert_eq!(
        r,
        ToPc::Error {
            code: RcError::SceneTooLarge { len: 101, max: 100 }
        }
    );
    let (r, _) = upload_step(
        &mut rx,
        &mut pc,
        &mut rc,
        &ToRc::SceneBegin { len: 0, crc: 0 },
        false,
    );
    assert_eq!(
        r,
        ToPc::Error {
            code: RcError::EmptyScene
        }
    );
    // Announced CRC wrong: every byte arrives, then the upload fails and starts over.
    let data = [5u8; 100];
    let wrong = CRC32.checksum(&data) ^ 1;
    upload_step(
        &mut rx,
        &mut pc,
        &mut rc,
        &ToRc::SceneBegin {
            len: 100,
            crc: wrong,
        },
        false,
    );
    // A chunk running past the announced length: Nak.
    let long = [5u8; 101];
    let (r, _) = upload_step(
        &mut rx,
        &mut pc,
        &mut rc,
        &ToRc::SceneChunk {
            offset: 0,
            data: &long,
        },
        false,
    );
    assert_eq!(r, ToPc::Nak { offset: 0 });
    let (r, e) = upload_step(
        &mut rx,
        &mut pc,
        &mut rc,
        &ToRc::SceneChunk {
            offset: 0,
            data: &data,
        },
        false,
    );
    let code = RcError::SceneCrc {
        expected: wrong,
        found: wrong ^ 1,
    };
    assert_eq!((r, e), (ToPc::Error { code }, UploadEvent::Failed(code)));
    assert_eq!((rx.image(), rx.received()), (None, 0));
    // Non-upload messages are left to the caller, with no reply.
    let mut out = [0u8; MAX_TO_PC];
    let r = rx
        .on_message(&ToRc::StartRender { frames: 1 }, &mut rc, &mut out)
        .unwrap();
    assert_eq!(
        r,
        Reply {
            len: 0,
            event: UploadEvent::Ignored
        }
    );
    // A version mismatch is answered by naming it.
    let r = rx
        .on_bad_frame(SerialError::Version { found: 9 }, &mut rc, &mut out)
        .unwrap();
    assert_eq!(r.event, UploadEvent::Failed(RcError::Version { found: 9 }));
}

#[test]
fn raw_crc_algorithm_check_value() {
    assert_eq!(CRC32_RAW.checksum(b"123456789"), CRC32_RAW.algorithm.check);
}

#[test]
fn frame_crc_from_pieces_in_any_order_equals_the_crc_of_the_whole() {
    let mut rng = Rng(99);
    for round in 0..200 {
        let len = 1 + rng.below(5000);
        let mut data = vec![0u8; len];
        rng.bytes(&mut data);
        // Cut into random pieces and shuffle them.
        let mut cuts = vec![0, len];
        for _ in 0..rng.below(20) {
            cuts.push(rng.below(len));
        }
        cuts.sort();
        cuts.dedup();
        let mut pieces: Vec<(usize, usize)> = cuts.windows(2).map(|w| (w[0], w[1])).collect();
        for i in (1..pieces.len()).rev() {
            let j = rng.below(i + 1);
            pieces.swap(i, j);
        }
        let mut crc = FrameCrc::new(len as u64);
        for (a, b) in pieces {
            crc.add(a as u64, &data[a..b]).unwrap();
        }
        assert_eq!(crc.value(), CRC32.checksum(&data), "round {round}");
    }
    // Empty string, and a piece past the end.
    assert_eq!(FrameCrc::new(0).value(), CRC32.checksum(&[]));
    let mut c = FrameCrc::new(4);
    assert_eq!(c.add(2, &[1, 2, 3]), Err(SerialError::OutOfRange));
    assert_eq!(c.add(u64::MAX, &[1]), Err(SerialError::OutOfRange));
    // One byte missing gives another CRC.
    let mut c = FrameCrc::new(3);
    c.add(0, &[1, 2]).unwrap();
    assert_ne!(c.value(), CRC32.checksum(&[1, 2, 0x55]));
}

/// A test frame whose pixels have long flat stretches (RLE) and noise (raw).
fn test_frame(w: usize, h: usize, rng: &mut Rng) -> Vec<u8> {
    let mut rgb = vec![0u8; 3 * w * h];
    for (i, p) in rgb.chunks_exact_mut(3).enumerate() {
        if (i / w).is_multiple_of(3) {
            p.copy_from_slice(&[10, 20, 30]);
        } else {
            rng.bytes(p);
        }
    }
    rgb
}

#[test]
fn frame_streamer_rows_in_any_order_reassemble_with_the_frame_crc() {
    let mut rng = Rng(2024);
    let (w, h) = (300usize, 20usize);
    let rgb = test_frame(w, h, &mut rng);
    let mut st = FrameStreamer::new(4, w as u16, h as u16).unwrap();
    let mut enc = Encoder::new();
    let mut line = Vec::new();
    let mut buf = [0u8; MAX_TO_PC];
    let n = st.header(&mut enc, &mut buf).unwrap();
    line.extend_from_slice(&buf[..n]);
    let mut rows: Vec<usize> = (0..h).collect();
    for i in (1..h).rev() {
        rows.swap(i, rng.below(i + 1));
    }
    // Before all pixels are in, the end is refused.
    assert!(matches!(
        st.end(&mut enc, &mut buf),
        Err(SerialError::Incomplete { folded: 0, .. })
    ));
    for &y in &rows {
        let row = &rgb[3 * w * y..3 * w * (y + 1)];
        for (x, run) in (0..w).step_by(MAX_RUN).zip(row.chunks(3 * MAX_RUN)) {
            let n = st.run(y as u16, x as u16, run, &mut enc, &mut buf).unwrap();
            line.extend_from_slice(&buf[..n]);
        }
        let n = st.progress(st.folded(), &mut enc, &mut buf).unwrap();
        line.extend_from_slice(&buf[..n]);
    }
    let n = st.end(&mut enc, &mut buf).unwrap();
    line.extend_from_slice(&buf[..n]);

    // The PC side: assemble.
    let mut dec = Decoder::<MAX_TO_PC>::new();
    let mut got = vec![0u8; rgb.len()];
    let (mut header, mut end, mut rle, mut raw, mut last_seq) = (None, None, 0, 0, None);
    for &b in &line {
        let Some(r) = dec.feed::<ToPc>(b) else {
            continue;
        };
        let p = r.unwrap();
        if let Some(s) = last_seq {
            assert_eq!(p.seq, s + 1, "no gap");
        }
        last_seq = Some(p.seq);
        match p.msg {
            ToPc::FrameHeader {
                frame,
                width,
                height,
            } => header = Some((frame, width, height)),
            m @ (ToPc::Pixels { y, x, .. } | ToPc::PixelsRle { y, x, .. }) => {
                if matches!(m, ToPc::PixelsRle { .. }) {
                    rle += 1
                } else {
                    raw += 1
                }
                let at = 3 * (y as usize * w + x as usize);
                let n = pixel_count(&m);
                pixels_into(&m, &mut got[at..at + 3 * n]).unwrap();
            }
            ToPc::FrameEnd { frame, crc } => end = Some((frame, crc)),
            ToPc::Progress { frame, done, total } => {
                assert_eq!(frame, 4);
                assert!(done <= total && total == (w * h) as u32);
            }
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(header, Some((4, w as u16, h as u16)));
    assert_eq!(got, rgb);
    assert_eq!(end, Some((4, CRC32.checksum(&rgb))));
    assert!(rle > 0 && raw > 0, "both pixel encodings used: {rle} {raw}");
    // Resending does not count again.
    let n0 = st.folded();
    st.resend(0, 0, &rgb[..30], &mut enc, &mut buf).unwrap();
    assert_eq!(st.folded(), n0);
    // A second counting of a pixel makes the end refuse.
    st.run(0, 0, &rgb[..3], &mut enc, &mut buf).unwrap();
    assert!(st.end(&mut enc, &mut buf).is_err());
}

#[test]
fn frame_streamer_refuses_runs_outside_the_frame() {
    let mut st = FrameStreamer::new(0, 10, 5).unwrap();
    let mut enc = Encoder::new();
    let mut buf = [0u8; MAX_TO_PC];
    let px = [0u8; 3 * (MAX_RUN + 1)];
    for (y, x, n) in [(5, 0, 1), (0, 10, 1), (0, 9, 2), (0, 0, 0)] {
        assert_eq!(
            st.run(y, x, &px[..3 * n], &mut enc, &mut buf),
            Err(SerialError::OutOfRange),
            "{y} {x} {n}"
        );
    }
    assert_eq!(
        st.run(0, 0, &px[..4], &mut enc, &mut buf),
        Err(SerialError::OutOfRange)
    );
    let mut wide = FrameStreamer::new(0, 1024, 1).unwrap();
    assert_eq!(
        wide.run(0, 0, &px, &mut enc, &mut buf),
        Err(SerialError::OutOfRange)
    );
    assert_eq!(st.folded(), 0);
    assert!(FrameStreamer::new(0, 0, 5).is_err());
    assert!(FrameStreamer::new(0, 5, MAX_DIM + 1).is_err());
    assert_eq!(enc.next_seq(), 0, "no frame was written");
}

#[test]
fn span_runs_cover_the_span_row_by_row() {
    let st = FrameStreamer::new(0, 600, 4).unwrap();
    let runs: Vec<_> = st.span_runs(500, 800).collect();
    assert_eq!(
        runs,
        vec![
            (0, 500, 100),
            (1, 0, 256),
            (1, 256, 256),
            (1, 512, 88),
            (2, 0, 100)
        ]
    );
    assert_eq!(st.span_runs(0, 2401).count(), 0, "past the end");
    assert_eq!(st.span_runs(2399, 1).collect::<Vec<_>>(), vec![(3, 599, 1)]);
    assert_eq!(st.span_runs(7, 0).count(), 0);
}

#[test]
fn random_runs_and_random_faults_lose_only_the_damaged_frames() {
    let mut rng = Rng(31337);
    let (w, h) = (64usize, 30usize);
    let rgb = test_frame(w, h, &mut rng);
    let mut st = FrameStreamer::new(1, w as u16, h as u16).unwrap();
    let mut enc = Encoder::new();
    let mut buf = [0u8; MAX_TO_PC];
    let mut line = Vec::new();
    let mut damaged = 0usize;
    let mut intact = Vec::new();
    let mut y = 0;
    while y < h {
        let n = st
            .run(
                y as u16,
                0,
                &rgb[3 * w * y..3 * w * (y + 1)],
                &mut enc,
                &mut buf,
            )
            .unwrap();
        let mut frame = buf[..n].to_vec();
        if rng.below(4) == 0 {
            let i = 1 + rng.below(n - 2);
            frame[i] ^= 1 + rng.below(255) as u8;
            damaged += 1;
        } else {
            intact.push(y);
        }
        line.extend_from_slice(&frame);
        y += 1;
    }
    let mut dec = Decoder::<MAX_TO_PC>::new();
    let mut rows = Vec::new();
    for &b in &line {
        if let Some(Ok(p)) = dec.feed::<ToPc>(b) {
            match p.msg {
                ToPc::Pixels { y, .. } | ToPc::PixelsRle { y, .. } => rows.push(y as usize),
                _ => {}
            }
        }
    }
    assert!(damaged > 0);
    assert_eq!(rows, intact);
    assert!(dec.bad_packets() as usize >= damaged);
}

#[test]
fn errors_display_their_cause() {
    let s = SerialError::Version { found: 3 }.to_string();
    assert!(s.contains("version") && s.contains('3'), "{s}");
    let s = RcError::SceneTooLarge { len: 9, max: 8 }.to_string();
    assert!(s.contains('9') && s.contains('8'), "{s}");
    let e: &dyn core::error::Error = &SerialError::BadCrc;
    assert!(e.to_string().contains("CRC"));
}

#[test]
fn sizes_quoted_in_the_docs() {
    assert_eq!((MAX_TO_RC, MAX_TO_PC), (541, 798));
    let mut buf = [0u8; 32];
    let n = encode_packet(0, &ToPc::Ack { offset: 512 }, &mut buf).unwrap();
    assert_eq!(n, 12);
    let mut body = [0u8; 16];
    let m = cobs::decode(&buf[1..n - 1], &mut body).unwrap();
    assert_eq!(&body[..5], &[1, 0, 0, 0x80, 0x04]);
    assert_eq!(m, 9);
    // A full raw run of 256 pixels (small seq and coordinates).
    let rgb: Vec<u8> = (0..3 * MAX_RUN).map(|i| 1 + (i % 200) as u8).collect();
    let run = ToPc::Pixels {
        frame: 0,
        y: 5,
        x: 0,
        rgb: &rgb,
    };
    let mut buf = [0u8; MAX_TO_PC];
    let n = encode_packet(3, &run, &mut buf).unwrap();
    assert!((780..=790).contains(&n), "{n}");
}

/// A lossy line for the upload property test: frames are dropped, corrupted or duplicated.
fn lossy(rng: &mut Rng, frame: &[u8]) -> Vec<Vec<u8>> {
    match rng.below(20) {
        0 | 1 => vec![],
        2 | 3 => {
            let mut f = frame.to_vec();
            let i = 1 + rng.below(f.len() - 2);
            f[i] ^= 1 + rng.below(255) as u8;
            vec![f]
        }
        4 => vec![frame.to_vec(), frame.to_vec()],
        _ => vec![frame.to_vec()],
    }
}

#[test]
fn upload_over_a_lossy_line_always_arrives_intact() {
    let mut rng = Rng(0xfeed_f00d);
    for round in 0..40 {
        let mut image = vec![0u8; 1 + rng.below(6000)];
        rng.bytes(&mut image);
        let (len, crc) = (image.len() as u32, CRC32.checksum(&image));
        let mut store = vec![0u8; 8192];
        let mut rx = UploadReceiver::new(&mut store);
        let mut rc_dec = Decoder::<MAX_TO_RC>::new();
        let mut pc_dec = Decoder::<MAX_TO_PC>::new();
        let (mut pc, mut rc) = (Encoder::new(), Encoder::new());
        // The PC: stop-and-wait as links upload does; `None` = SceneBegin not acknowledged.
        let mut next: Option<u32> = None;
        let mut done = false;
        let mut sends = 0;
        while !done {
            sends += 1;
            assert!(sends < 2000, "round {round}: no progress");
            let mut line = [0u8; MAX_TO_RC];
            let n = match next {
                None => pc.encode(&ToRc::SceneBegin { len, crc }, &mut line),
                Some(o) => {
                    let end = (o as usize + MAX_CHUNK).min(image.len());
                    let data = &image[o as usize..end];
                    pc.encode(&ToRc::SceneChunk { offset: o, data }, &mut line)
                }
            }
            .unwrap();
            // PC -> RC over the lossy line; every decoded (or bad) frame gets one reply.
            let mut replies = Vec::new();
            for f in lossy(&mut rng, &line[..n]) {
                for b in f {
                    let mut out = [0u8; MAX_TO_PC];
                    let r = match rc_dec.feed::<ToRc>(b) {
                        None => continue,
                        Some(Ok(p)) => rx.on_message(&p.msg, &mut rc, &mut out).unwrap(),
                        Some(Err(e)) => rx.on_bad_frame(e, &mut rc, &mut out).unwrap(),
                    };
                    replies.extend(lossy(&mut rng, &out[..r.len]));
                }
            }
            // RC -> PC; no reply at all = a time-out: send the same again.
            for f in replies {
                for b in f {
                    let Some(Ok(p)) = pc_dec.feed::<ToPc>(b) else {
                        continue;
                    };
                    match p.msg {
                        ToPc::Ack { offset } => {
                            if next.is_none_or(|o| offset > o) {
                                next = Some(offset)
                            }
                        }
                        ToPc::Nak { offset } => {
                            if next.is_some() {
                                next = Some(offset)
                            }
                        }
                        ToPc::SceneDone { len: l, crc: c } => {
                            assert_eq!((l, c), (len, crc));
                            done = true;
                        }
                        other => panic!("round {round}: {other:?}"),
                    }
                }
            }
        }
        assert_eq!(rx.image(), Some(&image[..]), "round {round}");
    }
}
