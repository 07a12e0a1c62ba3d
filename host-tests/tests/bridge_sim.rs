//! `bridge-sim` end to end: the built binary generates and encodes VCD files, and the
//! tests read them back and re-derive every frame on their own (sampling at the clock
//! edges / bit centres, framing by SYNC) to compare with the frames the tool says it
//! sent. Plus the backchannel round trip, a capture in another tool's conventions, and
//! bad input.

use std::path::{Path, PathBuf};

mod common;

use common::{ok_in, records, run_in, Out};
use host_tests::line::sample::{xy2_port_words, xy3_spi, PartialByte, PinMap};
use host_tests::sim::jsonl::{self, BackRecord, Channel, ForwardRecord, HansRecord};
use host_tests::vcd_io::{read_vcd_file, NameMap};
use host_tests::wave::Waveform;
use shared::{hans, xy2, xy3};

fn dir(test: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("bridge_sim_{test}"));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run(args: &[&str]) -> Out {
    run_in(Path::new("."), args)
}

fn ok(args: &[&str]) -> Out {
    ok_in(Path::new("."), args)
}

/// Runs `generate` and returns the frames it reports (`--frames-out`).
fn generate<T: serde::de::DeserializeOwned>(d: &Path, name: &str, args: &[&str]) -> Vec<T> {
    records(&common::generate(d, name, args).1)
}

/// Reads `roles` from a file where they are called `names`.
fn read(path: &Path, roles: &[&str], names: &[&str]) -> Waveform {
    let mut map = NameMap::new();
    for (r, n) in roles.iter().zip(names) {
        map.set(*r, *n);
    }
    read_vcd_file(path, roles, &map).unwrap()
}

// ---------------------------------------------------------------- XY2-100

/// Frames re-derived from a capture: per sample (CLK falling edge) the port word; a
/// frame is the 20 bits up to and including a sample with SYNC low.
fn xy2_words(path: &Path) -> Vec<[u32; 3]> {
    let wave = read(
        path,
        &["CLK", "SYNC", "X", "Y", "Z"],
        &["clk", "sync", "x", "y", "z"],
    );
    let pins = PinMap {
        sync: 4,
        x: 0,
        y: 1,
        z: Some(2),
        status: None,
    };
    let mut frames = Vec::new();
    let mut acc = [0u32; 3];
    let mut n = 0;
    for s in xy2_port_words(&wave, &pins).unwrap() {
        for (i, a) in acc.iter_mut().enumerate() {
            *a = (*a << 1) | u32::from(s >> i & 1);
        }
        n += 1;
        if s & 1 << 4 == 0 {
            assert_eq!(n, 20, "frame {} has {n} bits", frames.len());
            frames.push(acc.map(|a| a & 0xF_FFFF));
            acc = [0; 3];
            n = 0;
        }
    }
    frames
}

fn xy2_expected(ch: &Channel) -> xy2::Frame {
    match *ch {
        Channel::Pos { pos, bits: 16 } => xy2::Frame::Position16(pos as u16),
        Channel::Pos { pos, .. } => xy2::Frame::Position18(pos),
        Channel::Cmd { cmd, .. } => xy2::Frame::Command {
            command: (cmd >> 8) as u8,
            parameter: cmd as u8,
        },
        Channel::Error(_) => panic!("generate made an error frame"),
    }
}

fn check_xy2(path: &Path, records: &[ForwardRecord], config: &xy2::LinkConfig) {
    let words = xy2_words(path);
    assert_eq!(words.len(), records.len());
    for (k, (w, r)) in words.iter().zip(records).enumerate() {
        for (lane, word) in ["x", "y", "z"].iter().zip(w) {
            let want = xy2_expected(r.channel(lane).unwrap());
            assert_eq!(
                xy2::decode(*word, config),
                Ok(want),
                "frame {k} lane {lane}"
            );
        }
    }
}

#[test]
fn xy2_generate_round_trips_with_and_without_impairments() {
    let d = dir("xy2");
    let std16 = xy2::LinkConfig::default();
    let recs: Vec<ForwardRecord> = generate(
        &d,
        "plain",
        &[
            "--protocol",
            "xy2",
            "--pattern",
            "steps",
            "--frames",
            "200",
            "--command-every",
            "7",
        ],
    );
    assert_eq!(recs.len(), 200);
    // Frames are back to back at 2 MHz: 10 us apart.
    assert_eq!(recs.get(1).unwrap().t_ns, Some(11_000));
    // The steps pattern reaches both ends and the centre.
    let xs: Vec<u32> = recs
        .iter()
        .filter_map(|r| match r.x {
            Some(Channel::Pos { pos, .. }) => Some(pos),
            _ => None,
        })
        .collect();
    for v in [0, 0x8000, 0xFFFF] {
        assert!(xs.contains(&v), "{v:#x} missing");
    }
    assert!(recs
        .iter()
        .any(|r| matches!(r.x, Some(Channel::Cmd { .. }))));
    check_xy2(&d.join("plain.vcd"), &recs, &std16);

    // Rate offset, jitter and skew move edges but keep every bit readable.
    let recs: Vec<ForwardRecord> = generate(
        &d,
        "impaired",
        &[
            "--protocol",
            "xy2",
            "--pattern",
            "random",
            "--frames",
            "200",
            "--xy2-mode",
            "18",
            "--parity",
            "data",
            "--rate-offset-ppm",
            "-30000",
            "--jitter-ns",
            "40",
            "--skew",
            "y=60",
            "--seed",
            "7",
        ],
    );
    let data18 = xy2::LinkConfig {
        mode: xy2::Mode::Extended18,
        parity: xy2::Parity::DataOnly,
    };
    check_xy2(&d.join("impaired.vcd"), &recs, &data18);
}

#[test]
fn xy2_noise_is_caught_by_parity_not_passed_on() {
    let d = dir("xy2_noise");
    let recs: Vec<ForwardRecord> = generate(
        &d,
        "noisy",
        &[
            "--protocol",
            "xy2",
            "--pattern",
            "circle",
            "--frames",
            "100",
            // Glitches on X during frames 20..60 (the capture starts at 1 us).
            "--noise",
            "x,201,601,30,300",
        ],
    );
    let words = xy2_words(&d.join("noisy.vcd"));
    assert_eq!(words.len(), 100);
    let cfg = xy2::LinkConfig::default();
    let mut rejected = 0;
    for (k, (w, r)) in words.iter().zip(&recs).enumerate() {
        let want = xy2_expected(r.x.as_ref().unwrap());
        match xy2::decode(w[0], &cfg) {
            Ok(f) if f == want => {}
            // An even number of flipped bits passes parity: possible, but then the
            // word must differ by an even number of bits.
            Ok(_) => assert_eq!(
                (w[0] ^ xy2::encode(want, &cfg).unwrap()).count_ones() % 2,
                0
            ),
            Err(_) => {
                assert!((20..61).contains(&k), "frame {k} outside the burst");
                rejected += 1;
            }
        }
        // Y is untouched.
        assert_eq!(
            xy2::decode(w[1], &cfg),
            Ok(xy2_expected(r.y.as_ref().unwrap()))
        );
    }
    assert!(rejected > 5, "only {rejected} frames hit");
}

// ---------------------------------------------------------------- XY3-100

fn check_xy3(path: &Path, records: &[ForwardRecord]) {
    let lanes = ["X", "Y", "Z", "U", "W"];
    let wave = read(
        path,
        &["CLK", "SYNC", "X", "Y", "Z", "U", "W"],
        &["clk", "sync", "x", "y", "z", "u", "w"],
    );
    let cap = xy3_spi(&wave, &lanes, PartialByte::Discard).unwrap();
    assert_eq!(cap.frame_ends.len(), records.len());
    let mut from = 0usize;
    for (k, (&end, r)) in cap.frame_ends.iter().zip(records).enumerate() {
        let end = end as usize;
        let size = match end - from {
            3 => xy3::FrameSize::Bits24,
            4 => xy3::FrameSize::Bits32,
            n => panic!("frame {k}: {n} bytes"),
        };
        for (i, lane) in ["x", "y", "z", "u", "w"].iter().enumerate() {
            let word = cap.bytes[i][from..end]
                .iter()
                .fold(0u32, |w, &b| w << 8 | u32::from(b));
            let want = match *r.channel(lane).unwrap() {
                Channel::Pos { pos, bits: 20 } => xy3::Frame::Position24(pos),
                Channel::Pos { pos, .. } => xy3::Frame::Position32(pos),
                Channel::Cmd { cmd, frame_bits } => match frame_bits {
                    Some(32) => xy3::Frame::Command32 {
                        code: cmd,
                        unused: 0,
                    },
                    _ => xy3::Frame::Command24(cmd),
                },
                Channel::Error(_) => panic!("error frame generated"),
            };
            assert_eq!(xy3::decode(word, size), Ok(want), "frame {k} lane {lane}");
        }
        from = end;
    }
}

#[test]
fn xy3_generate_round_trips_24_and_32_bit_with_impairments() {
    let d = dir("xy3");
    let recs: Vec<ForwardRecord> = generate(
        &d,
        "b24",
        &[
            "--protocol",
            "xy3",
            "--pattern",
            "raster",
            "--frames",
            "150",
            "--command-every",
            "10",
        ],
    );
    check_xy3(&d.join("b24.vcd"), &recs);
    let recs: Vec<ForwardRecord> = generate(
        &d,
        "b32",
        &[
            "--protocol",
            "xy3",
            "--xy3-bits",
            "32",
            "--pattern",
            "random",
            "--frames",
            "150",
            "--command-every",
            "5",
            "--jitter-ns",
            "25",
            "--rate-offset-ppm",
            "50000",
            "--skew",
            "w=-40",
            "--seed",
            "3",
        ],
    );
    assert!(recs.iter().any(|r| matches!(
        r.x,
        Some(Channel::Cmd {
            frame_bits: Some(32),
            ..
        })
    )));
    check_xy3(&d.join("b32.vcd"), &recs);
}

// ---------------------------------------------------------------- HANS-100

/// Samples `name` at the bit centres of the 12.5 MHz stream starting at 1 us and
/// decodes consecutive 125-bit frames.
fn hans_frames(
    wave: &Waveform,
    name: &str,
    n: usize,
) -> Vec<Result<hans::Frame, hans::DecodeError>> {
    let s = wave.get(name).unwrap();
    (0..n)
        .map(|f| {
            let mut p = 0u128;
            for b in 0..125u64 {
                let t = 1_000_000 + (f as u64 * 125 + b) * 80_000 + 40_000;
                p = p << 1 | u128::from(s.level_at(t));
            }
            hans::Frame::decode(p)
        })
        .collect()
}

#[test]
fn hans_generate_round_trips_and_a_stuck_channel_is_rejected() {
    let d = dir("hans");
    let recs: Vec<HansRecord> = generate(
        &d,
        "h",
        &[
            "--protocol",
            "hans",
            "--pattern",
            "steps",
            "--frames",
            "100",
            "--jitter-ns",
            "12",
            "--skew",
            "ch3=20",
            // 10 us frames from 1 us: ch2 dies during frame 50.
            "--stuck",
            "ch2,505,0",
        ],
    );
    let chans = ["ch1", "ch2", "ch3", "ch4", "ch5"];
    let wave = read(&d.join("h.vcd"), &chans, &chans);
    let want: Vec<[u32; 3]> = recs
        .iter()
        .map(|r| match r {
            HansRecord::Frame { data, .. } => *data,
            HansRecord::Error { .. } => panic!("error generated"),
        })
        .collect();
    assert!(want.iter().any(|w| w[0] == 0) && want.iter().any(|w| w[0] == 0xF_FFFF));
    for ch in chans {
        for (k, (got, w)) in hans_frames(&wave, ch, 100).iter().zip(&want).enumerate() {
            if ch == "ch2" && k >= 50 {
                assert!(got.is_err(), "stuck ch2 frame {k} accepted");
            } else {
                assert_eq!(got.map(|f| f.words()), Ok(*w), "{ch} frame {k}");
            }
        }
    }
}

// ---------------------------------------------------------------- encode

#[test]
// Binary literals are grouped by frame field (header, data, parity), not by nibble.
#[allow(clippy::unusual_byte_groupings)]
fn encode_hand_written_xy2_frames() {
    let d = dir("encode_xy2");
    let vcd = d.join("e.vcd");
    let o = ok(&[
        "encode",
        "--protocol",
        "xy2",
        "--frames",
        concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/sim_xy2.jsonl"),
        "--output",
        vcd.to_str().unwrap(),
    ]);
    assert!(o.stderr.contains("4 frames"), "{}", o.stderr);
    let words = xy2_words(&vcd);
    assert_eq!(words.len(), 4);
    // Hand-worked words (see the fixture): 001 + data + even whole-frame parity.
    // 0x0000 -> 001 0000000000000000 1 (one 1 -> parity 1)
    // 0x8000 -> 001 1000000000000000 0
    // 0xFFFF -> 001 1111111111111111 1 (17 ones -> parity 1)
    // cmd 0x1234 -> 111 00010010 00110100 0 (3 + 2 + 3 ones = 8 -> parity 0)
    #[rustfmt::skip]
    let want: [[u32; 3]; 4] = [
        [0b001_0000000000000000_1, 0b001_1000000000000000_0, 0b001_1111111111111111_1],
        [0b111_00010010_00110100_0, 0b001_1000000000000000_0, 0b001_0000000000000000_1],
        [0b001_1111111111111111_1, 0, 0b001_1000000000000000_0],
        [0b001_1000000000000000_0, 0b001_1000000000000000_0, 0b001_1000000000000000_0],
    ];
    for (k, (got, w)) in words.iter().zip(&want).enumerate() {
        for lane in 0..3 {
            if k == 2 && lane == 1 {
                // The fixture's error record: sent as a word the receiver rejects.
                assert!(matches!(
                    xy2::decode(got[1], &xy2::LinkConfig::default()),
                    Err(xy2::DecodeError::Parity { .. })
                ));
            } else {
                assert_eq!(got[lane], w[lane], "frame {k} lane {lane}");
            }
        }
    }
    // Frame starts follow t_ns: the first CLK rise of each frame.
    let wave = read(&vcd, &["CLK"], &["clk"]);
    let rises: Vec<u64> = wave
        .get("CLK")
        .unwrap()
        .rising_edges()
        .step_by(20)
        .collect();
    assert_eq!(rises, vec![2_000_000, 12_000_000, 50_000_000, 60_000_000]);
}

#[test]
// Binary literals are grouped by frame field (header, data, parity), not by nibble.
#[allow(clippy::unusual_byte_groupings)]
fn encode_xy3_and_hans_fixtures_round_trip() {
    let d = dir("encode_xy3");
    let vcd = d.join("e.vcd");
    let fixture = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/sim_xy3.jsonl");
    ok(&[
        "encode",
        "--protocol",
        "xy3",
        "--frames",
        fixture,
        "--output",
        vcd.to_str().unwrap(),
    ]);
    let recs: Vec<ForwardRecord> = jsonl::parse(&std::fs::read_to_string(fixture).unwrap())
        .unwrap()
        .into_iter()
        .map(|(_, r)| r)
        .collect();
    // Only X and Y are in the fixture, so only they are on the wire.
    let wave = read(&vcd, &["CLK", "SYNC", "X", "Y"], &["clk", "sync", "x", "y"]);
    assert!(read_vcd_file(&vcd, &["u"], &NameMap::new()).is_err());
    let cap = xy3_spi(&wave, &["X", "Y"], PartialByte::Discard).unwrap();
    // 24-bit, 32-bit, 24-bit frames: 3 + 4 + 3 bytes.
    assert_eq!(cap.frame_ends, vec![3, 7, 10]);
    // Frame 1 by hand: x = 32-bit position 0x3FFFFFF -> 1 1 + 26 ones + parity 26 % 16
    // = 0b1010.
    let x1 = cap.bytes[0][3..7]
        .iter()
        .fold(0u32, |w, &b| w << 8 | u32::from(b));
    assert_eq!(x1, 0b11_11111111111111111111111111_1010);
    // Frame 2: x = 24-bit command 0x88000 -> 0 0 + code + parity (2 ones) = 0b10.
    let x2 = cap.bytes[0][7..10]
        .iter()
        .fold(0u32, |w, &b| w << 8 | u32::from(b));
    assert_eq!(x2, 0b00_10001000000000000000_10);
    assert_eq!(recs.len(), 3);

    // HANS-100: three frames back to back; DATA words must come back exactly.
    let hvcd = d.join("h.vcd");
    ok(&[
        "encode",
        "--protocol",
        "hans",
        "--frames",
        concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/sim_hans.jsonl"),
        "--output",
        hvcd.to_str().unwrap(),
    ]);
    let chans = ["ch1", "ch2", "ch3", "ch4", "ch5"];
    let wave = read(&hvcd, &chans, &chans);
    let got = hans_frames(&wave, "ch4", 3);
    assert_eq!(got[0].map(|f| f.words()), Ok([0, 0x8_0000, 0xF_FFFF]));
    assert!(matches!(
        got[1],
        Err(hans::DecodeError::Complement { word: 1, bit: 19 })
    ));
    assert_eq!(
        got[2].map(|f| f.words()),
        Ok([0x1_2345, 0xA_BCDE, 0x8_0000])
    );
}

// ---------------------------------------------------------------- backchannel

#[test]
fn xy3_back_generate_decode_round_trip() {
    let d = dir("back");
    let vcd = d.join("b.vcd");
    let want: Vec<BackRecord> = generate(
        &d,
        "b",
        &[
            "--protocol",
            "xy3-back",
            "--frames",
            "60",
            "--pattern",
            "random",
        ],
    );
    // The sender put a SYNC first and more as time passed (every 50 ms).
    let syncs = want
        .iter()
        .filter(|r| matches!(r, BackRecord::Packet { ty: 0x41, .. }))
        .count();
    assert!(syncs >= 2, "{syncs} SYNCs");
    let o = ok(&[
        "decode",
        "--protocol",
        "xy3-back",
        "--input",
        vcd.to_str().unwrap(),
    ]);
    let got: Vec<BackRecord> = records(&o.stdout);
    assert_eq!(got, want);
    assert!(
        o.stderr.contains(&format!("accepted {}", want.len())),
        "{}",
        o.stderr
    );

    // Encode the decoded lines again (at their ns times) and decode: same lines.
    let jl = d.join("decoded.jsonl");
    std::fs::write(&jl, &o.stdout).unwrap();
    let again = d.join("again.vcd");
    ok(&[
        "encode",
        "--protocol",
        "xy3-back",
        "--frames",
        jl.to_str().unwrap(),
        "--output",
        again.to_str().unwrap(),
    ]);
    let o2 = ok(&[
        "decode",
        "--protocol",
        "xy3-back",
        "--input",
        again.to_str().unwrap(),
    ]);
    assert!(
        o2.stdout == o.stdout,
        "re-encoded capture decodes differently"
    );
}

#[test]
fn xy3_back_noise_gives_errors_then_resync() {
    let d = dir("back_noise");
    let want: Vec<BackRecord> = generate(
        &d,
        "n",
        &[
            "--protocol",
            "xy3-back",
            "--frames",
            "80",
            "--noise",
            "back,20000,30000,40,3000",
            "--map",
            "back=RS485_RX",
        ],
    );
    let vcd = d.join("n.vcd");
    // Under its capture name only.
    let o = run(&[
        "decode",
        "--protocol",
        "xy3-back",
        "--input",
        vcd.to_str().unwrap(),
    ]);
    assert_eq!(o.code, 1);
    assert!(
        o.stderr.contains("`back`") && o.stderr.contains("RS485_RX"),
        "{}",
        o.stderr
    );
    let o = ok(&[
        "decode",
        "--protocol",
        "xy3-back",
        "--input",
        vcd.to_str().unwrap(),
        "--map",
        "back=RS485_RX",
    ]);
    let got: Vec<BackRecord> = records(&o.stdout);
    assert!(got.iter().any(|r| matches!(r, BackRecord::Error { .. })));
    // Everything after the burst (20..30 ms) is received again, exactly.
    let late = |v: &[BackRecord]| -> Vec<BackRecord> {
        v.iter()
            .filter(|r| matches!(r, BackRecord::Packet { t_ns: Some(t), .. } if *t > 60_000_000))
            .cloned()
            .collect()
    };
    assert!(!late(&want).is_empty());
    assert_eq!(late(&got), late(&want));
}

#[test]
fn xy3_back_capture_from_another_tool() {
    let o = ok(&[
        "decode",
        "--protocol",
        "xy3-back",
        "--baud",
        "1000000",
        "--map",
        "back=RS485_RX",
        "--input",
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/sim_back_100ns.vcd"
        ),
    ]);
    // Bytes 48 41 00 | 48 07 02 00 03, each 10 bits + 2 idle bits = 12 us, from 5 us.
    assert_eq!(
        o.stdout,
        "{\"t_ns\":5000,\"type\":65,\"payload\":\"\"}\n\
         {\"t_ns\":41000,\"type\":7,\"payload\":\"0003\"}\n"
    );
}

// ---------------------------------------------------------------- bad input

fn decode_args(f: &Path) -> Vec<&str> {
    vec![
        "decode",
        "--protocol",
        "xy3-back",
        "--input",
        f.to_str().unwrap(),
    ]
}

#[test]
fn bad_input_fails_cleanly() {
    let d = dir("bad");
    ok(&[
        "generate",
        "--protocol",
        "xy3-back",
        "--frames",
        "5",
        "--output",
        d.join("good.vcd").to_str().unwrap(),
    ]);
    let good = std::fs::read_to_string(d.join("good.vcd")).unwrap();
    let check = |args: &[&str], want: &str| {
        let o = run(args);
        assert_eq!(o.code, 1, "{args:?}: {}", o.stderr);
        assert!(o.stderr.contains(want), "{args:?}: {}", o.stderr);
        assert_eq!(o.stderr.trim().lines().count(), 1, "{}", o.stderr);
    };

    // Truncated inside the header and inside a value change.
    let cut = d.join("cut_header.vcd");
    std::fs::write(&cut, &good[..good.find("$enddefinitions").unwrap()]).unwrap();
    check(&decode_args(&cut), "truncated");
    let cut = d.join("cut_body.vcd");
    std::fs::write(&cut, format!("{good}$dumpvars\n1!\n")).unwrap();
    check(&decode_args(&cut), "truncated");
    // Garbage.
    let junk = d.join("junk.vcd");
    std::fs::write(&junk, b"\x00\xffnot a vcd at all #12 $$ b10").unwrap();
    check(&decode_args(&junk), "VCD");
    // A file that does not exist.
    let nope = d.join("nope.vcd");
    check(&decode_args(&nope), "nope.vcd");
    // Missing signal: an XY2-100 capture has no `back`.
    let xy2 = d.join("xy2.vcd");
    ok(&[
        "generate",
        "--protocol",
        "xy2",
        "--frames",
        "3",
        "--output",
        xy2.to_str().unwrap(),
    ]);
    check(&decode_args(&xy2), "signal `back`");

    // JSON lines: bad line 3 (unknown key), bad channel, bad hex, mixed t_ns.
    let enc = |name: &str, proto: &str, text: &str, want: &str| {
        let f = d.join(name);
        std::fs::write(&f, text).unwrap();
        let out = d.join("out.vcd");
        check(
            &[
                "encode",
                "--protocol",
                proto,
                "--frames",
                f.to_str().unwrap(),
                "--output",
                out.to_str().unwrap(),
            ],
            want,
        );
    };
    let p = r#"{"x":{"pos":1,"bits":16}}"#;
    enc(
        "a.jsonl",
        "xy2",
        &format!("{p}\n{p}\n{{\"x\":{{\"pos\":1,\"bits\":16}},\"q\":1}}\n"),
        "line 3:",
    );
    enc(
        "b.jsonl",
        "xy2",
        r#"{"x":{"pos":70000,"bits":16}}"#,
        "line 1: position 70000 does not fit 16 bits",
    );
    enc(
        "c.jsonl",
        "xy2",
        r#"{"x":{"pos":1,"bits":20}}"#,
        "line 1: channel x: XY2-100 positions have 16 or 18 bits",
    );
    enc(
        "d.jsonl",
        "xy3-back",
        "\n\n{\"type\":7,\"payload\":\"0g\"}",
        "line 3:",
    );
    enc(
        "e.jsonl",
        "xy3",
        "{\"t_ns\":5,\"x\":{\"cmd\":1}}\n{\"x\":{\"cmd\":1}}",
        "line 2: no \"t_ns\"",
    );
    enc(
        "f.jsonl",
        "xy2",
        "{\"t_ns\":5000,\"x\":{\"cmd\":1}}\n{\"t_ns\":9000,\"x\":{\"cmd\":1}}",
        "line 2: frame starts at 9000 ns, before",
    );
    enc(
        "g.jsonl",
        "hans",
        r#"{"x":{"pos":1,"bits":20},"y":{"pos":1,"bits":20}}"#,
        "line 1:",
    );
    enc("h.jsonl", "xy2", "not json", "line 1:");
    enc("i.jsonl", "hans", "\n\n", "no frames");
    enc("j.jsonl", "xy3-back", "{\"error\":\"lost\"}\n", "no frames");

    // Bad options.
    let o = run(&[
        "generate",
        "--protocol",
        "xy2",
        "--output",
        "/dev/null",
        "--stuck",
        "x,1",
    ]);
    assert_eq!(o.code, 1);
    assert!(o.stderr.contains("--stuck"), "{}", o.stderr);
    let o = run(&[
        "generate",
        "--protocol",
        "xy2",
        "--output",
        "/dev/null",
        "--skew",
        "q=5",
    ]);
    assert_eq!(o.code, 1);
    assert!(o.stderr.contains("`q`"), "{}", o.stderr);
    let o = run(&[
        "decode",
        "--protocol",
        "hans",
        "--input",
        "x.vcd",
        "--hans-mode",
        "normal:9",
    ]);
    assert_eq!(o.code, 2);
}

// ---------------------------------------------------------------- formats

#[test]
fn json_lines_print_and_parse_exactly_as_documented() {
    #[rustfmt::skip]
    let forward: &[(ForwardRecord, &str)] = &[
        (
            ForwardRecord {
                t_ns: Some(1000),
                x: Some(Channel::Pos { pos: 62258, bits: 16 }),
                y: Some(Channel::Cmd { cmd: 20481, frame_bits: None }),
                z: Some(Channel::Error("parity".to_owned())),
                ..ForwardRecord::default()
            },
            r#"{"t_ns":1000,"x":{"pos":62258,"bits":16},"y":{"cmd":20481},"z":{"error":"parity"}}"#,
        ),
        (
            ForwardRecord {
                t_ns: Some(0),
                u: Some(Channel::Cmd { cmd: 0x88000, frame_bits: Some(32) }),
                w: Some(Channel::Pos { pos: 0x3FF_FFFF, bits: 26 }),
                ..ForwardRecord::default()
            },
            r#"{"t_ns":0,"u":{"cmd":557056,"frame_bits":32},"w":{"pos":67108863,"bits":26}}"#,
        ),
    ];
    for (rec, line) in forward {
        assert_eq!(jsonl::to_line(rec), *line);
        assert_eq!(
            jsonl::parse::<ForwardRecord>(line).unwrap(),
            vec![(1, rec.clone())]
        );
    }
    let hans = [
        (
            HansRecord::Frame {
                t_ns: Some(5),
                data: [0, 0x8_0000, 0xF_FFFF],
            },
            r#"{"t_ns":5,"x":{"pos":0,"bits":20},"y":{"pos":524288,"bits":20},"z":{"pos":1048575,"bits":20}}"#,
        ),
        (
            HansRecord::Error {
                t_ns: Some(7),
                error: "stop bits".to_owned(),
            },
            r#"{"t_ns":7,"error":"stop bits"}"#,
        ),
    ];
    for (rec, line) in &hans {
        assert_eq!(jsonl::to_line(rec), *line);
        assert_eq!(
            jsonl::parse::<HansRecord>(line).unwrap(),
            vec![(1, rec.clone())]
        );
    }
    let back = [
        (
            BackRecord::Packet {
                t_ns: Some(9),
                ty: 7,
                payload: vec![0x00, 0xAB],
            },
            r#"{"t_ns":9,"type":7,"payload":"00ab"}"#,
        ),
        (
            BackRecord::Error {
                t_ns: Some(3),
                error: "lost sync".to_owned(),
            },
            r#"{"t_ns":3,"error":"lost sync"}"#,
        ),
    ];
    for (rec, line) in &back {
        assert_eq!(jsonl::to_line(rec), *line);
        assert_eq!(
            jsonl::parse::<BackRecord>(line).unwrap(),
            vec![(1, rec.clone())]
        );
    }
    // Mixed-shape channels and records are rejected.
    for bad in [
        r#"{"x":{"pos":1,"cmd":2}}"#,
        r#"{"x":{"pos":1}}"#,
        r#"{"x":{"cmd":1048576}}"#,
        r#"{"x":{"pos":5,"bits":17}}"#,
    ] {
        assert!(jsonl::parse::<ForwardRecord>(bad).is_err(), "{bad}");
    }
    assert!(jsonl::parse::<HansRecord>(r#"{"x":{"pos":1,"bits":20},"error":"e"}"#).is_err());
    assert!(jsonl::parse::<BackRecord>(r#"{"type":7,"error":"e"}"#).is_err());
}
