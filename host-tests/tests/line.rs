//! Line conversions: generator -> sampler round trips, hand-worked BSRR/bitstream
//! playback, HANS oversampling and UART.

use host_tests::impair;
use host_tests::line::drive::{bitstream_to_signal, bsrr_to_wave, OutPinMap, HANS_BIT_RATE_HZ};
use host_tests::line::sample::{xy2_port_words, xy3_spi, Oversampler, PartialByte, PinMap};
use host_tests::line::serial::{xy2_waveform, xy3_waveform, FrameTiming, FrameWord, Idle, Lane};
use host_tests::line::uart::{uart_decode, uart_encode};
use host_tests::line::{roles, LineError};
use host_tests::wave::{Signal, Waveform};
use proptest::prelude::*;

const PINS: PinMap = PinMap {
    sync: 3,
    x: 0,
    y: 7,
    z: Some(12),
    status: None,
};

fn words20(v: &[u32]) -> Vec<FrameWord> {
    v.iter()
        .map(|&value| FrameWord {
            value: value & 0xF_FFFF,
            bits: 20,
        })
        .collect()
}

fn timing(rate: f64, period_ps: Option<f64>, idle: Idle) -> FrameTiming {
    FrameTiming {
        bit_rate_hz: rate,
        frame_period_ps: period_ps,
        idle,
        start_ps: 1_000.0,
    }
}

/// Checks 20 port words against the frame words, bit by bit (MSB first).
fn check_xy2_frame(samples: &[u16], x: u32, y: u32, z: u32) {
    assert_eq!(samples.len(), 20);
    for (b, &s) in samples.iter().enumerate() {
        let bit = |w: u32| (w >> (19 - b)) & 1 == 1;
        assert_eq!(s & 1 != 0, bit(x), "X bit {b}");
        assert_eq!(s & (1 << 7) != 0, bit(y), "Y bit {b}");
        assert_eq!(s & (1 << 12) != 0, bit(z), "Z bit {b}");
        assert_eq!(s & (1 << 3) != 0, b < 19, "SYNC bit {b}");
        assert_eq!(
            s & !((1 << 0) | (1 << 3) | (1 << 7) | (1 << 12)),
            0,
            "unmapped bits"
        );
    }
}

proptest! {
    #[test]
    fn xy2_frames_sample_back(
        frames in prop::collection::vec((0u32..1 << 20, 0u32..1 << 20, 0u32..1 << 20), 1..8),
        rate in prop::sample::select(vec![0.5e6, 2e6, 4e6]),
    ) {
        let xs: Vec<u32> = frames.iter().map(|f| f.0).collect();
        let ys: Vec<u32> = frames.iter().map(|f| f.1).collect();
        let zs: Vec<u32> = frames.iter().map(|f| f.2).collect();
        let (wx, wy, wz) = (words20(&xs), words20(&ys), words20(&zs));
        let lanes = [
            Lane { name: roles::X, words: &wx },
            Lane { name: roles::Y, words: &wy },
            Lane { name: roles::Z, words: &wz },
        ];
        let bit_ps = 1e12 / rate;
        // Back to back, gated clock with a longer period, running clock with 4 idle bits.
        for (period, idle, extra) in [
            (None, Idle::ClockStopped, 0usize),
            (Some(27.0 * bit_ps), Idle::ClockStopped, 0),
            (Some(24.0 * bit_ps), Idle::ClockRunning, 4),
        ] {
            let wave = xy2_waveform(&lanes, &timing(rate, period, idle)).unwrap();
            let samples = xy2_port_words(&wave, &PINS).unwrap();
            prop_assert_eq!(samples.len(), frames.len() * (20 + extra) - extra);
            for (f, chunk) in samples.chunks(20 + extra).enumerate() {
                check_xy2_frame(&chunk[..20], xs[f], ys[f], zs[f]);
                // Idle clocks see SYNC and data low.
                prop_assert!(chunk[20..].iter().all(|&s| s == 0));
            }
        }
    }

    #[test]
    fn xy3_frames_through_spi(
        frames in prop::collection::vec((any::<bool>(), any::<u32>(), any::<u32>()), 1..8),
    ) {
        let len = |long: bool| if long { 32u8 } else { 24 };
        let mk = |v: u32, long: bool| FrameWord {
            value: if long { v } else { v & 0xFF_FFFF },
            bits: len(long),
        };
        let wx: Vec<FrameWord> = frames.iter().map(|f| mk(f.1, f.0)).collect();
        let wy: Vec<FrameWord> = frames.iter().map(|f| mk(f.2, f.0)).collect();
        let lanes = [Lane { name: roles::X, words: &wx }, Lane { name: roles::Y, words: &wy }];
        let expected = |ws: &[FrameWord]| -> Vec<u8> {
            ws.iter()
                .flat_map(|w| w.value.to_be_bytes().into_iter().skip(4 - usize::from(w.bits / 8)))
                .collect()
        };
        let mut ends = Vec::new();
        let mut n = 0u32;
        for w in &wx {
            n += u32::from(w.bits / 8);
            ends.push(n);
        }
        for (period, idle) in [
            (None, Idle::ClockStopped),
            (Some(12e6), Idle::ClockRunning), // 12 us at 3.2 MHz: clocks while NSS is high
        ] {
            let wave = xy3_waveform(&lanes, &timing(3.2e6, period, idle)).unwrap();
            let cap = xy3_spi(&wave, &[roles::X, roles::Y], PartialByte::Discard).unwrap();
            prop_assert_eq!(&cap.bytes[0], &expected(&wx));
            prop_assert_eq!(&cap.bytes[1], &expected(&wy));
            prop_assert_eq!(&cap.frame_ends, &ends);
            prop_assert_eq!(cap.pending_bits, 0);
        }
    }
}

#[test]
fn xy3_partial_byte_policies() {
    let (w0, w1) = (0x5A_C3_96u32, 0x1E_2D_3Cu32);
    let wx = [
        FrameWord {
            value: w0,
            bits: 24,
        },
        FrameWord {
            value: w1,
            bits: 24,
        },
    ];
    let lanes = [Lane {
        name: roles::X,
        words: &wx,
    }];
    let rate = 2.4e6;
    let bit_ps = 1e12 / rate;
    let t = timing(rate, None, Idle::ClockStopped);
    let mut wave = xy3_waveform(&lanes, &t).unwrap();
    // NSS rises after 12 bits of frame 0 (a truncated frame): 1 byte + 4 bits.
    let from = (t.start_ps + 12.0 * bit_ps).round() as u64;
    let to = (t.start_ps + 24.0 * bit_ps).round() as u64;
    impair::gap(&mut wave, roles::SYNC, from, to, true).unwrap();

    let d = xy3_spi(&wave, &[roles::X], PartialByte::Discard).unwrap();
    assert_eq!(d.bytes[0], vec![0x5A, 0x1E, 0x2D, 0x3C]);
    assert_eq!(d.frame_ends, vec![1, 4]);
    assert_eq!(d.pending_bits, 0);

    // Carried over: the 4 bits 0xC (of 0xC3) are completed by the next frame's 0x1 nibble.
    let c = xy3_spi(&wave, &[roles::X], PartialByte::CarryOver).unwrap();
    assert_eq!(c.bytes[0], vec![0x5A, 0xC1, 0xE2, 0xD3]);
    assert_eq!(c.frame_ends, vec![1, 4]);
    assert_eq!(c.pending_bits, 4);
}

#[test]
fn generator_rejects_inconsistent_lanes() {
    let a = words20(&[1, 2]);
    let b = words20(&[1]);
    let t = timing(2e6, None, Idle::ClockStopped);
    let lanes = [
        Lane {
            name: roles::X,
            words: &a,
        },
        Lane {
            name: roles::Y,
            words: &b,
        },
    ];
    assert!(matches!(
        xy2_waveform(&lanes, &t),
        Err(LineError::LaneMismatch { .. })
    ));
    let bad = [FrameWord { value: 0, bits: 16 }];
    let lanes = [Lane {
        name: roles::X,
        words: &bad,
    }];
    assert_eq!(
        xy2_waveform(&lanes, &t),
        Err(LineError::BadWordLength { frame: 0, bits: 16 })
    );
    let short = timing(2e6, Some(5e6), Idle::ClockStopped);
    let ok = words20(&[1]);
    let lanes = [Lane {
        name: roles::X,
        words: &ok,
    }];
    assert!(matches!(
        xy2_waveform(&lanes, &short),
        Err(LineError::FramePeriodTooShort { .. })
    ));
    let same = [
        Lane {
            name: roles::X,
            words: &ok,
        },
        Lane {
            name: roles::X,
            words: &ok,
        },
    ];
    assert_eq!(
        xy2_waveform(&same, &t),
        Err(LineError::BadLaneName { name: "X".into() })
    );
    let clk = [Lane {
        name: roles::CLK,
        words: &ok,
    }];
    assert_eq!(
        xy2_waveform(&clk, &t),
        Err(LineError::BadLaneName { name: "CLK".into() })
    );
    let e = xy2_port_words(&Waveform::new(), &PINS).unwrap_err();
    assert!(matches!(e, LineError::MissingSignal { ref name, .. } if name == "CLK"));
    let clash = PinMap { sync: 0, ..PINS };
    let wave = xy2_waveform(&lanes, &t).unwrap();
    assert_eq!(
        xy2_port_words(&wave, &clash),
        Err(LineError::BadPinMap { bit: 0 })
    );
}

#[test]
fn bsrr_playback_hand_worked() {
    let pins = OutPinMap {
        clk: 0,
        sync: 1,
        x: 2,
        y: 3,
        z: None,
        u: None,
        w: None,
    };
    #[rustfmt::skip]
    let words = [
        0x0008_0007, // set CLK, SYNC, X; reset Y
        0x0001_0000, // reset CLK
        0x0004_0009, // set CLK, Y; reset X
        0x0003_0000, // reset CLK, SYNC
        0x0004_0004, // set and reset X: set wins
    ];
    let w = bsrr_to_wave(&words, 250_000.0, 0, &pins, &[]).unwrap();
    let get = |n: &str| {
        let s = w.get(n).unwrap();
        (s.initial(), s.changes().to_vec())
    };
    assert_eq!(
        get("CLK"),
        (
            true,
            vec![(250_000, false), (500_000, true), (750_000, false)]
        )
    );
    assert_eq!(get("SYNC"), (true, vec![(750_000, false)]));
    assert_eq!(get("X"), (true, vec![(500_000, false), (1_000_000, true)]));
    assert_eq!(get("Y"), (false, vec![(500_000, true)]));
    assert!(w.get("Z").is_none());
}

/// The host pin map from a `shared` transmitter's map keeps every line on its bit
/// (U / W only where the map has them) and refuses an XY3-100 map without X or Y.
#[test]
fn pin_maps_from_shared_transmitter_maps() {
    let xy2 = shared::xy2::tx::OutPinMap {
        clk: 4,
        sync: 5,
        x: 6,
        y: 7,
        z: None,
    };
    let want = OutPinMap {
        clk: 4,
        sync: 5,
        x: 6,
        y: 7,
        z: None,
        u: None,
        w: None,
    };
    assert_eq!(OutPinMap::from_xy2(&xy2), want);
    let xy3 = shared::xy3::tx::OutPinMap {
        clk: 9,
        sync: 8,
        data: [Some(1), Some(2), None, Some(3), Some(11)],
    };
    let want = OutPinMap {
        clk: 9,
        sync: 8,
        x: 1,
        y: 2,
        z: None,
        u: Some(3),
        w: Some(11),
    };
    assert_eq!(OutPinMap::from_xy3(&xy3), Some(want));
    for missing in [0, 1] {
        let mut bad = xy3;
        bad.data[missing] = None;
        assert_eq!(OutPinMap::from_xy3(&bad), None, "line {missing} missing");
    }
}

#[test]
fn bitstream_playback_hand_worked() {
    let s = bitstream_to_signal("CH1", &[0xA0, 0x01], HANS_BIT_RATE_HZ, 1_000_000).unwrap();
    // 1010 0000 0000 0001 at 80 ns per bit from 1 us; low before.
    assert!(!s.initial());
    assert_eq!(
        s.changes(),
        &[
            (1_000_000, true),
            (1_080_000, false),
            (1_160_000, true),
            (1_240_000, false),
            (2_200_000, true)
        ]
    );
}

/// Run lengths of a bool sequence.
fn runs(v: &[bool]) -> Vec<(bool, usize)> {
    let mut out: Vec<(bool, usize)> = Vec::new();
    for &b in v {
        match out.last_mut() {
            Some((l, n)) if *l == b => *n += 1,
            _ => out.push((b, 1)),
        }
    }
    out
}

proptest! {
    #[test]
    fn hans_oversampling_runs(
        bytes in prop::collection::vec(any::<u8>(), 16..64),
        fs in prop::sample::select(vec![37.5e6, 40e6, 50e6]),
        phase in 0.0f64..1.0,
    ) {
        // A known alternating prefix guarantees single-bit runs.
        let mut stream = vec![0x55u8, 0xAA];
        stream.extend(&bytes);
        let sig = bitstream_to_signal("CH1", &stream, HANS_BIT_RATE_HZ, 0).unwrap();
        let mut other = sig.clone();
        other.set_name("CH2");
        let mut wave = Waveform::new();
        wave.add(sig).unwrap();
        wave.add(other).unwrap();
        let sample_ps = 1e12 / fs;
        let end = (stream.len() * 8) as u64 * 80_000;
        let os = Oversampler { fs_hz: fs, start_ps: phase * sample_ps };
        let words = os.sample(&wave, &["CH1", "CH2"], end).unwrap();
        prop_assert_eq!(&words[0], &words[1]); // same instants on every channel
        let samples: Vec<bool> =
            words[0].iter().flat_map(|w| (0..32).rev().map(move |i| (w >> i) & 1 == 1)).collect();
        prop_assert!(!samples.is_empty());
        let bits: Vec<bool> =
            stream.iter().flat_map(|b| (0..8).rev().map(move |i| (b >> i) & 1 == 1)).collect();
        let bit_runs = runs(&bits);
        let sample_runs = runs(&samples);
        let ratio = fs / HANS_BIT_RATE_HZ;
        // Interior runs only: the first and last are cut by the sampling window.
        let n = sample_runs.len();
        prop_assert!(n > 4);
        for (i, &(level, got)) in sample_runs.iter().enumerate().skip(1).take(n - 2) {
            let (bl, len) = bit_runs[i];
            prop_assert_eq!(level, bl);
            let ideal = len as f64 * ratio;
            prop_assert!(got as f64 >= ideal.floor() && got as f64 <= ideal.ceil(),
                "run {} of {} bits: {} samples at ratio {}", i, len, got, ratio);
            if len == 1 {
                prop_assert!((3..=4).contains(&got));
            }
        }
    }

    #[test]
    fn uart_round_trip(bytes in prop::collection::vec(any::<u8>(), 1..64),
                       baud in prop::sample::select(vec![115_200.0, 921_600.0]),
                       gap in 0u32..3) {
        let line = uart_encode(roles::UART, &bytes, baud, 5_000_000, gap).unwrap();
        let rx = uart_decode(&line, baud).unwrap();
        let got: Vec<u8> = rx.iter().map(|f| f.value).collect();
        prop_assert_eq!(got, bytes);
        prop_assert!(rx.iter().all(|f| !f.framing_error));
        let bit = 1e12 / baud;
        for (k, f) in rx.iter().enumerate() {
            let t = 5e6 + (k as f64) * f64::from(10 + gap) * bit;
            prop_assert!((f.time as f64 - t).abs() <= 1.0);
        }
    }
}

#[test]
fn uart_framing_error_and_glitch() {
    let baud = 115_200.0;
    let bit = 1e12 / baud;
    let t0 = 1_000_000.0;
    let line = uart_encode(roles::UART, &[0x00, 0x41], baud, t0 as u64, 2).unwrap();
    let mut w = Waveform::new();
    w.add(line).unwrap();
    // Stop bit of byte 0 forced low.
    let (a, b) = ((t0 + 9.0 * bit) as u64, (t0 + 10.0 * bit) as u64);
    impair::gap(&mut w, roles::UART, a, b, false).unwrap();
    // A 1 us glitch on the idle line after byte 1.
    let idle = (t0 + 30.0 * bit) as u64;
    impair::gap(&mut w, roles::UART, idle, idle + 1_000_000, false).unwrap();
    let rx = uart_decode(w.get(roles::UART).unwrap(), baud).unwrap();
    assert_eq!(rx.len(), 2, "{rx:?}");
    assert!(rx[0].framing_error);
    assert_eq!(rx[0].value, 0x00);
    assert!(!rx[1].framing_error);
    assert_eq!(rx[1].value, 0x41);
    assert!(matches!(
        uart_decode(&Signal::new("u", true), 0.0),
        Err(LineError::BadParameter { .. })
    ));
}

#[test]
fn oversampler_rejects_bad_parameters() {
    let mut w = Waveform::new();
    w.add(Signal::new("CH1", false)).unwrap();
    let bad_fs = Oversampler {
        fs_hz: f64::NAN,
        start_ps: 0.0,
    };
    assert!(matches!(
        bad_fs.sample(&w, &["CH1"], 1_000),
        Err(LineError::BadParameter { .. })
    ));
    let os = Oversampler {
        fs_hz: 40e6,
        start_ps: 0.0,
    };
    assert!(matches!(
        os.sample(&w, &["CH1"], u64::MAX),
        Err(LineError::BadParameter { .. })
    ));
    assert!(matches!(
        os.sample(&w, &["CH9"], 1_000),
        Err(LineError::MissingSignal { .. })
    ));
    // 800 ns at 40 MHz = 32 samples = exactly one word; one sample less = no word.
    assert_eq!(os.sample(&w, &["CH1"], 800_000).unwrap(), vec![vec![0u32]]);
    assert_eq!(
        os.sample(&w, &["CH1"], 799_999).unwrap(),
        vec![Vec::<u32>::new()]
    );
}
