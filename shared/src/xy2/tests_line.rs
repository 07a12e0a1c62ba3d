//! Unit tests of the line-level pieces: hand-built sample sequences for the receiver,
//! hand-worked BSRR tables for the transmitter, the STATUS line in both forms.

use super::rx::{
    ChannelError, Counters, Event, FramePeriod, FramingFault, PinError, PinMap, Receiver,
};
use super::status_line::{
    LevelChange, LevelDebouncer, StatusConfigError, StatusOut, StatusWordConfig, StatusWordReceiver,
};
use super::tx::{OutPinMap, Transmitter, TxError, TxFrame};
use super::*;
use crate::model::{Axis, Command, FaultKind, Line, LineEvent, Position};
use proptest::prelude::*;

/// Input pins of the hand-built samples: SYNC 0, X 1, Y 2, Z 3.
const PINS: PinMap = PinMap {
    sync: 0,
    x: 1,
    y: 2,
    z: Some(3),
};

/// The 20 samples of one frame, written out from the protocol (not from `tx`):
/// sample k carries word bit 19 - k, SYNC is high for samples 0..=18.
fn frame_samples(x: u32, y: u32, z: u32) -> Vec<u16> {
    (0..20)
        .map(|k| {
            let bit = |w: u32| ((w >> (19 - k)) & 1) as u16;
            u16::from(k < 19) | bit(x) << 1 | bit(y) << 2 | bit(z) << 3
        })
        .collect()
}

fn w16(v: u16) -> u32 {
    encode(Frame::Position16(v), &LinkConfig::default()).unwrap()
}

fn run(rx: &mut Receiver, samples: &[u16]) -> Vec<Event> {
    let mut out = Vec::new();
    rx.feed(samples, &mut |e| out.push(e));
    out
}

/// A receiver that has seen one idle (SYNC low) sample, so the next SYNC rising edge
/// starts a frame. A fresh receiver cannot know whether a first high sample is bit 1.
fn receiver() -> Receiver {
    let mut rx = Receiver::new(PINS, LinkConfig::default()).unwrap();
    assert_eq!(run(&mut rx, &[0]), []);
    rx
}

fn ok_period(x: u16, y: u16, z: u16) -> Event {
    Event::Frame(FramePeriod {
        x: Ok(Frame::Position16(x)),
        y: Ok(Frame::Position16(y)),
        z: Some(Ok(Frame::Position16(z))),
    })
}

#[test]
fn clean_frames_back_to_back_and_with_idle() {
    let mut rx = receiver();
    let mut s = frame_samples(w16(0x0000), w16(0x8000), w16(0xFFFF));
    s.extend(frame_samples(w16(0x1234), w16(0x5678), w16(0x9ABC)));
    s.extend([0, 0, 0]); // idle clocks with SYNC low
    s.extend(frame_samples(w16(1), w16(2), w16(3)));
    assert_eq!(
        run(&mut rx, &s),
        [
            ok_period(0x0000, 0x8000, 0xFFFF),
            ok_period(0x1234, 0x5678, 0x9ABC),
            ok_period(1, 2, 3)
        ]
    );
    assert_eq!(
        rx.counters(),
        Counters {
            frames: 3,
            ..Counters::default()
        }
    );
}

#[test]
fn partial_first_frame_is_silent() {
    let mut rx = Receiver::new(PINS, LinkConfig::default()).unwrap();
    let f = frame_samples(w16(7), w16(8), w16(9));
    let mut s = f[5..].to_vec(); // joined mid-frame
    s.extend(&f);
    assert_eq!(run(&mut rx, &s), [ok_period(7, 8, 9)]);
    assert_eq!(rx.counters().framing, 0);
    // Even a whole first frame: without a low sample before it, bit 1 is unknown.
    let mut rx = Receiver::new(PINS, LinkConfig::default()).unwrap();
    let mut s = f.clone();
    s.extend(&f);
    assert_eq!(run(&mut rx, &s), [ok_period(7, 8, 9)]);
    // After `reset` the same holds.
    rx.reset();
    assert_eq!(run(&mut rx, &s), [ok_period(7, 8, 9)]);
}

#[test]
fn extra_clock_edge_is_overlong_then_resync() {
    let mut rx = receiver();
    let good = frame_samples(w16(10), w16(20), w16(30));
    let mut bad = good.clone();
    bad.insert(7, bad[7]); // a glitch on CLK: one bit sampled twice
    let mut s = good.clone();
    s.extend(&bad);
    s.extend(&good);
    assert_eq!(
        run(&mut rx, &s),
        [
            ok_period(10, 20, 30),
            Event::Framing(FramingFault::Overlong),
            Event::Resync,
            ok_period(10, 20, 30)
        ]
    );
    let c = rx.counters();
    assert_eq!((c.frames, c.framing, c.resyncs), (2, 1, 1));
}

#[test]
fn missing_clock_edge_is_short() {
    let mut rx = receiver();
    let good = frame_samples(w16(10), w16(20), w16(30));
    let mut bad = good.clone();
    bad.remove(4);
    let mut s = good.clone();
    s.extend(&bad);
    s.extend(&good);
    assert_eq!(
        run(&mut rx, &s),
        [
            ok_period(10, 20, 30),
            Event::Framing(FramingFault::Short { high_bits: 18 }),
            Event::Resync,
            ok_period(10, 20, 30)
        ]
    );
}

#[test]
fn sync_glitch_low_splits_the_frame() {
    let mut rx = receiver();
    let good = frame_samples(w16(10), w16(20), w16(30));
    let mut bad = good.clone();
    bad[6] &= !1; // SYNC reads low at bit 7
    let mut s = good.clone();
    s.extend(&bad);
    s.extend(&good);
    assert_eq!(
        run(&mut rx, &s),
        [
            ok_period(10, 20, 30),
            Event::Framing(FramingFault::Short { high_bits: 6 }),
            Event::Framing(FramingFault::Short { high_bits: 12 }),
            Event::Resync,
            ok_period(10, 20, 30)
        ]
    );
}

#[test]
fn sync_glitch_high_on_bit_20_merges_two_frames() {
    let mut rx = receiver();
    let good = frame_samples(w16(10), w16(20), w16(30));
    let mut s = good.clone();
    let mut bad = good.clone();
    bad[19] |= 1;
    s.extend(&bad);
    s.extend(&good);
    s.extend(&good);
    assert_eq!(
        run(&mut rx, &s),
        [
            ok_period(10, 20, 30),
            Event::Framing(FramingFault::Overlong),
            Event::Resync,
            ok_period(10, 20, 30)
        ]
    );
}

#[test]
fn sync_stuck_high_reports_once_then_nothing() {
    let mut rx = receiver();
    let mut s = frame_samples(w16(1), w16(2), w16(3));
    s.extend(std::iter::repeat_n(1u16 | 0b1110, 10_000));
    assert_eq!(
        run(&mut rx, &s),
        [ok_period(1, 2, 3), Event::Framing(FramingFault::Overlong)]
    );
    // Released: the next frame is a resync.
    let mut s = vec![0u16];
    s.extend(frame_samples(w16(4), w16(5), w16(6)));
    assert_eq!(run(&mut rx, &s), [Event::Resync, ok_period(4, 5, 6)]);
}

#[test]
fn sync_stuck_low_gives_nothing() {
    let mut rx = receiver();
    let s: Vec<u16> = frame_samples(w16(1), w16(2), w16(3))
        .iter()
        .cycle()
        .take(400)
        .map(|s| s & !1)
        .collect();
    assert_eq!(run(&mut rx, &s), []);
    assert_eq!(rx.counters(), Counters::default());
}

#[test]
fn x_stuck_high_or_low_is_rejected() {
    let mut rx = receiver();
    // Stuck high: all ones would pass whole-frame parity as command 0xFF/0xFF.
    assert_eq!(
        decode(0xF_FFFF, &LinkConfig::default()),
        Ok(Frame::Command {
            command: 0xFF,
            parameter: 0xFF
        })
    );
    let s = frame_samples(0xF_FFFF, w16(2), w16(3));
    let Event::Frame(p) = run(&mut rx, &s)[0] else {
        panic!("no frame period");
    };
    assert_eq!(p.x, Err(ChannelError::StuckHigh));
    assert_eq!(p.y, Ok(Frame::Position16(2)));
    let s = frame_samples(0, w16(2), w16(3));
    let Event::Frame(p) = run(&mut rx, &s)[0] else {
        panic!("no frame period");
    };
    assert_eq!(
        p.x,
        Err(ChannelError::Decode(DecodeError::ReservedHeader {
            header: 0,
            mode: Mode::Standard16
        }))
    );
    assert_eq!(rx.counters().check_failures, [2, 0, 0]);
    // 18-bit full scale under data-only parity is all ones too.
    let link = LinkConfig {
        mode: Mode::Extended18,
        parity: Parity::DataOnly,
    };
    assert_eq!(
        encode(Frame::Position18(0x3_FFFF), &link),
        Ok(0xF_FFFF),
        "the word this rule gives up"
    );
}

#[test]
fn every_single_bit_error_is_a_check_failure() {
    let x = w16(0x8001);
    for bit in 0..20 {
        let mut rx = receiver();
        let s = frame_samples(x ^ 1 << bit, w16(2), w16(3));
        let Event::Frame(p) = run(&mut rx, &s)[0] else {
            panic!("no frame period");
        };
        assert!(p.x.is_err(), "bit {bit}");
    }
}

#[test]
fn line_events_of_a_period() {
    let pos = |v| Some(Position::from_raw(v, 16).unwrap());
    let mut out = Vec::new();
    let cmd = Frame::Command {
        command: 5,
        parameter: 1,
    };
    // Command on X, positions on Y and Z.
    let p = FramePeriod {
        x: Ok(cmd),
        y: Ok(Frame::Position16(0x8000)),
        z: Some(Ok(Frame::Position16(0xFFFF))),
    };
    p.line_events(&mut |e| out.push(e));
    let LineEvent::Frame(f) = out[0] else {
        panic!("{out:?}");
    };
    assert_eq!(out.len(), 1);
    assert_eq!(
        f.command,
        Some(Command::Xy2Enhanced {
            command: 5,
            parameter: 1
        })
    );
    assert_eq!(f.axes, [None, pos(0x8000), pos(0xFFFF), None, None]);
    // A command on Y is dropped, the frame still goes.
    out.clear();
    let p = FramePeriod {
        x: Ok(Frame::Position16(0)),
        y: Ok(cmd),
        z: None,
    };
    p.line_events(&mut |e| out.push(e));
    let LineEvent::Frame(f) = out[0] else {
        panic!("{out:?}");
    };
    assert_eq!(
        (f.axes, f.command),
        ([pos(0), None, None, None, None], None)
    );
    // Failures: one fault per failed channel, no frame.
    out.clear();
    let p = FramePeriod {
        x: Err(ChannelError::StuckHigh),
        y: Ok(Frame::Position16(1)),
        z: Some(Err(ChannelError::Decode(DecodeError::TooWide { word: 0 }))),
    };
    p.line_events(&mut |e| out.push(e));
    let fault = |axis| LineEvent::Fault {
        line: Line::Axis(axis),
        kind: FaultKind::CheckFailed,
    };
    assert_eq!(out, [fault(Axis::X), fault(Axis::Z)]);
    out.clear();
    Event::Framing(FramingFault::Overlong).line_events(&mut |e| out.push(e));
    Event::Resync.line_events(&mut |e| out.push(e));
    let framing = |kind| LineEvent::Fault {
        line: Line::Framing,
        kind,
    };
    assert_eq!(
        out,
        [framing(FaultKind::Framing), framing(FaultKind::Resync)]
    );
}

#[test]
fn bad_pin_maps_are_refused() {
    let link = LinkConfig::default();
    let mut p = PINS;
    p.z = Some(16);
    assert_eq!(
        Receiver::new(p, link).err(),
        Some(PinError::OutOfRange { bit: 16 })
    );
    p.z = Some(2);
    assert_eq!(
        Receiver::new(p, link).err(),
        Some(PinError::Reused { bit: 2 })
    );
    assert!(Receiver::new(PinMap { z: None, ..PINS }, link).is_ok());
    assert_eq!(
        PinError::Reused { bit: 2 }.to_string(),
        "pin bit 2 is mapped to two signals"
    );
    assert_eq!(
        FramingFault::Short { high_bits: 3 }.to_string(),
        "SYNC high for 3 bits, not 19"
    );
}

/// A naive reference receiver over the whole sample vector: find every low->high
/// SYNC transition, count the high run, and decode the samples when it is 19 long.
/// Like [`receiver`], it has seen one low sample before `samples`.
fn reference(samples: &[u16]) -> Vec<(u32, u32, u32)> {
    let samples = &[&[0], samples].concat();
    let sync = |i: usize| samples[i] & 1 != 0;
    let mut out = Vec::new();
    for start in 1..samples.len() {
        if sync(start) && !sync(start - 1) {
            let run = (start..samples.len()).take_while(|&i| sync(i)).count();
            if run == 19 && start + 19 < samples.len() {
                let word = |b: u16| {
                    (start..start + 20).fold(0, |w, i| w << 1 | u32::from(samples[i] >> b & 1))
                };
                out.push((word(1), word(2), word(3)));
            }
        }
    }
    out
}

fn periods(events: &[Event]) -> Vec<FramePeriod> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::Frame(p) => Some(*p),
            _ => None,
        })
        .collect()
}

proptest! {
    /// Realistic frames with random faults (dropped/doubled samples, flipped bits):
    /// the receiver finds exactly the periods the reference does, decodes them with
    /// `decode`, and any chunking gives identical events.
    #[test]
    fn matches_reference_and_any_chunking(
        frames in prop::collection::vec((any::<u16>(), any::<u16>(), any::<u16>(), 0u8..4), 1..20),
        faults in prop::collection::vec((any::<prop::sample::Index>(), 0u8..3, 0u8..4), 0..6),
        cuts in prop::collection::vec(any::<prop::sample::Index>(), 0..6),
    ) {
        let mut s = Vec::new();
        for &(x, y, z, idle) in &frames {
            s.extend(frame_samples(w16(x), w16(y), w16(z)));
            s.extend(std::iter::repeat_n(0u16, usize::from(idle)));
        }
        for &(at, kind, bit) in &faults {
            let i = at.index(s.len());
            match kind {
                0 => { s.remove(i); }
                1 => s.insert(i, s[i]),
                _ => s[i] ^= 1 << bit,
            }
            if s.is_empty() { s.push(0); }
        }
        let whole = run(&mut receiver(), &s);
        let cfg = LinkConfig::default();
        let want: Vec<FramePeriod> = reference(&s).into_iter().map(|(x, y, z)| {
            let d = |w: u32| if w == FRAME_MASK { Err(ChannelError::StuckHigh) } else { decode(w, &cfg).map_err(ChannelError::Decode) };
            FramePeriod { x: d(x), y: d(y), z: Some(d(z)) }
        }).collect();
        prop_assert_eq!(periods(&whole), want);
        // Arbitrary chunking.
        let mut cut: Vec<usize> = cuts.iter().map(|c| c.index(s.len() + 1)).collect();
        cut.sort_unstable();
        let mut rx = receiver();
        let mut chunked = Vec::new();
        let mut from = 0;
        for &c in cut.iter().chain([&s.len()]) {
            rx.feed(&s[from..c], &mut |e| chunked.push(e));
            from = c;
        }
        prop_assert_eq!(chunked, whole);
    }

    /// Garbage on every pin: no panic, and every accepted word passes `decode`.
    #[test]
    fn garbage_never_yields_a_bad_frame(samples in prop::collection::vec(any::<u16>(), 0..400), ext: bool) {
        let link = LinkConfig { mode: if ext { Mode::Extended18 } else { Mode::Standard16 }, parity: Parity::DataOnly };
        let mut rx = Receiver::new(PINS, link).unwrap();
        rx.feed(&[0], &mut |_| {});
        rx.feed(&samples, &mut |e| {
            if let Event::Frame(p) = e {
                for f in [p.x, p.y].into_iter().chain(p.z).flatten() {
                    let w = encode(f, &link).unwrap();
                    assert_ne!(w, FRAME_MASK);
                    assert_eq!(decode(w, &link), Ok(f));
                }
            }
        });
    }

    /// Transmitter -> ideal port sampling -> receiver recovers the frames.
    #[test]
    fn tx_to_rx_round_trip(
        frames in prop::collection::vec((any::<u16>(), any::<u16>(), any::<u16>()), 1..10),
        extra in 0usize..8,
    ) {
        let tx = Transmitter::new(OUT, 40 + extra, LinkConfig::default()).unwrap();
        let sent: Vec<TxFrame> = frames.iter().map(|&(x, y, z)| TxFrame {
            x: Frame::Position16(x), y: Frame::Position16(y), z: Some(Frame::Position16(z)),
        }).collect();
        let mut buf = vec![0u32; tx.ticks_per_frame() * sent.len()];
        tx.write_half(&mut buf, &sent).unwrap();
        let s = play(&buf);
        let events = run(&mut receiver(), &s);
        let want: Vec<Event> = frames.iter().map(|&(x, y, z)| ok_period(x, y, z)).collect();
        prop_assert_eq!(events, want);
    }
}

/// Output pins: CLK 4, SYNC 0, X 1, Y 2, Z 3 (the input map plus a clock).
const OUT: OutPinMap = OutPinMap {
    clk: 4,
    sync: 0,
    x: 1,
    y: 2,
    z: Some(3),
};

/// Applies BSRR words to a port (set wins, as on STM32) and samples the port at every
/// CLK (bit 4) falling edge, without the clock bit: an ideal wire and input timer.
fn play(words: &[u32]) -> Vec<u16> {
    let mut port: u16 = 0;
    let mut out = Vec::new();
    for &w in words {
        let next = (port & !(w >> 16) as u16) | w as u16;
        if port & 0x10 != 0 && next & 0x10 == 0 {
            out.push(next & 0xF);
        }
        port = next;
    }
    out
}

// BSRR bit values for pins CLK 0, SYNC 1, X 2, Y 3, Z 4: set = 1 << pin,
// reset = 1 << (pin + 16).
const HAND: OutPinMap = OutPinMap {
    clk: 0,
    sync: 1,
    x: 2,
    y: 3,
    z: Some(4),
};

/// Frame A: X = Position16(0x0000) = 001_0000000000000000_1 (one header one, P = 1),
/// Y = Position16(0xFFFF) = 001_1111111111111111_1 (17 ones, P = 1), no Z frame (Z low).
#[rustfmt::skip]
const TABLE_A: &[(u32, u32, u32)] = &[
    // (first bit 1..=20, last bit, first word of each bit)
    (1,  2,  0x001C_0003), // CLK set, SYNC set, X 0, Y 0, Z 0
    (3,  3,  0x0010_000F), // X 1, Y 1 (header bit 17)
    (4,  19, 0x0014_000B), // X 0, Y 1 (data 15..0)
    (20, 20, 0x0012_000D), // SYNC reset, X 1, Y 1 (parity), Z 0
];

/// Frame B: X = Y = Position16(0x8000) = 001_1000000000000000_0 (two ones, P = 0),
/// Z = Command { 0x05, 0x01 } = 111_00000101_00000001_0 (six ones, P = 0).
#[rustfmt::skip]
const TABLE_B: &[(u32, u32, u32)] = &[
    (1,  2,  0x000C_0013), // X 0, Y 0, Z 1
    (3,  3,  0x0000_001F), // X 1, Y 1, Z 1
    (4,  4,  0x0010_000F), // X 1 (D15), Y 1, Z 0
    (5,  8,  0x001C_0003), // all 0
    (9,  9,  0x000C_0013), // Z 1 (command bit 2)
    (10, 10, 0x001C_0003),
    (11, 11, 0x000C_0013), // Z 1 (command bit 0)
    (12, 18, 0x001C_0003),
    (19, 19, 0x000C_0013), // Z 1 (parameter bit 0)
    (20, 20, 0x001E_0001), // SYNC reset, all data 0 (parity 0)
];

fn check_table(words: &[u32], table: &[(u32, u32, u32)]) {
    for &(first, last, want) in table {
        for bit in first..=last {
            let i = 2 * (bit as usize - 1);
            assert_eq!(words[i], want, "bit {bit} first word");
            assert_eq!(
                words[i + 1],
                0x0001_0000,
                "bit {bit} second word: CLK reset"
            );
        }
    }
}

#[test]
fn bsrr_words_by_hand() {
    let tx = Transmitter::new(HAND, 43, LinkConfig::default()).unwrap();
    let mut slot = [0u32; 43];
    let a = TxFrame {
        x: Frame::Position16(0x0000),
        y: Frame::Position16(0xFFFF),
        z: None,
    };
    tx.write_frame(&mut slot, &a).unwrap();
    check_table(&slot, TABLE_A);
    // Idle: reset CLK, SYNC, X, Y, Z.
    assert_eq!(slot[40..], [0x001F_0000; 3]);
    let b = TxFrame {
        x: Frame::Position16(0x8000),
        y: Frame::Position16(0x8000),
        z: Some(Frame::Command {
            command: 0x05,
            parameter: 0x01,
        }),
    };
    tx.write_frame(&mut slot, &b).unwrap();
    check_table(&slot, TABLE_B);
    // The same words written raw.
    let mut raw = [0u32; 43];
    tx.write_words(&mut raw, [0x3_0000, 0x3_0000, 0xE_0A02])
        .unwrap();
    assert_eq!(raw, slot);
}

#[test]
fn tx_errors() {
    let link = LinkConfig::default();
    assert_eq!(
        Transmitter::new(HAND, 39, link).err(),
        Some(TxError::TicksPerFrame { ticks: 39 })
    );
    let mut pins = HAND;
    pins.z = Some(0);
    assert_eq!(
        Transmitter::new(pins, 40, link).err(),
        Some(TxError::Pins(PinError::Reused { bit: 0 }))
    );
    let tx = Transmitter::new(HAND, 40, link).unwrap();
    let mut slot = [0u32; 41];
    let f = TxFrame {
        x: Frame::Position16(1),
        y: Frame::Position16(2),
        z: None,
    };
    assert_eq!(
        tx.write_frame(&mut slot, &f),
        Err(TxError::Length {
            expected: 40,
            got: 41
        })
    );
    // An 18-bit frame on a 16-bit link: that slot idles, the other is written.
    let bad = TxFrame {
        y: Frame::Position18(5),
        ..f
    };
    let mut half = [0u32; 80];
    assert_eq!(
        tx.write_half(&mut half, &[f, bad]),
        Err(TxError::Encode {
            axis: Axis::Y,
            error: EncodeError::WrongMode {
                kind: FrameKind::Position18,
                mode: Mode::Standard16
            }
        })
    );
    assert!(half[40..].iter().all(|&w| w == tx.idle_word()));
    assert_eq!(half[0], 0x001C_0003);
}

#[test]
fn debouncer_needs_consecutive_equal_samples() {
    let mut d = LevelDebouncer::new(StatusLevel::default(), 3);
    assert_eq!(d.health(), None);
    let levels = [
        false, false, true, false, false, true, true, true, true, false,
    ];
    let got: Vec<Option<LevelChange>> = levels
        .iter()
        .enumerate()
        .map(|(t, &l)| d.feed(t as u64 * 10, l))
        .collect();
    let change = |health, since| Some(LevelChange { health, since });
    let want = [
        None,
        None,
        None, // a one-sample high glitch resets the count
        None,
        None,
        None, // first accepted level needs 3 equal: samples 3, 4 ... broken by 5
        None,
        change(Health::Fault, 50), // samples 5, 6, 7 high: fault since t = 50
        None,
        None,
    ];
    assert_eq!(got, want);
    assert_eq!(d.health(), Some(Health::Fault));
    assert_eq!(
        d.health().map(Health::alarms),
        Some(crate::model::Alarms::ELECTRICAL)
    );
    // First level accepted after exactly `required` samples.
    let mut d = LevelDebouncer::new(StatusLevel::default(), 2);
    assert_eq!(d.feed(0, false), None);
    assert_eq!(d.feed(1, false), change(Health::Ok, 0));
    assert_eq!(d.feed(2, false), None);
}

#[test]
fn status_word_samples_aligned_with_output_frames() {
    let link = LinkConfig::default();
    // 20 bits + 4 idle slots per period; the status frame starts at sample 1.
    let cfg = StatusWordConfig {
        pin: 5,
        samples_per_period: 24,
        offset: 1,
        link,
    };
    let mut rx = StatusWordReceiver::new(cfg).unwrap();
    let ok = StatusWord::ALL_OK.to_frame(&link); // 001_1111110111111101_1
    let x_lost = StatusWord::from_word(0xF5F5).unwrap();
    let mut s = Vec::new();
    for word in [ok, x_lost.to_frame(&link), ok ^ 1 << 7] {
        s.push(!(1 << 5)); // sample 0: not part of the frame (other pins high)
        s.extend(
            (0..20)
                .rev()
                .map(|b| ((word >> b & 1) as u16) << 5 | 0x0001),
        );
        s.extend([0u16; 3]);
    }
    let mut got = Vec::new();
    rx.feed(&s, &mut |r| got.push(r));
    assert_eq!(got.len(), 3);
    assert_eq!(got[0], Ok(StatusWord::ALL_OK));
    assert_eq!(
        got[1].map(StatusWord::alarms),
        Ok(crate::model::Alarms::POSITION_X)
    );
    assert!(matches!(
        got[2],
        Err(StatusError::Frame(DecodeError::Parity { .. }))
    ));
    // Back to back, offset 1: the frame's last bit is the next period's sample 0.
    let cfg = StatusWordConfig {
        samples_per_period: 20,
        ..cfg
    };
    let mut rx = StatusWordReceiver::new(cfg).unwrap();
    let mut s = vec![0u16];
    for _ in 0..3 {
        s.extend((0..20).rev().map(|b| ((ok >> b & 1) as u16) << 5));
    }
    let mut got = Vec::new();
    for chunk in s.chunks(7) {
        rx.feed(chunk, &mut |r| got.push(r));
    }
    assert_eq!(got, [Ok(StatusWord::ALL_OK); 3]);
    assert_eq!(
        StatusWordReceiver::new(StatusWordConfig { offset: 20, ..cfg }).err(),
        Some(StatusConfigError::Geometry {
            samples_per_period: 20,
            offset: 20
        })
    );
    assert_eq!(
        StatusWordReceiver::new(StatusWordConfig {
            samples_per_period: 19,
            offset: 0,
            ..cfg
        })
        .err(),
        Some(StatusConfigError::Geometry {
            samples_per_period: 19,
            offset: 0
        })
    );
}

#[rustfmt::skip]
const STATUS_OUT: &[(Polarity, Health, u32)] = &[
    // (polarity, health, BSRR word for pin 6: set 0x40, reset 0x40_0000)
    (Polarity::LowIsOk,  Health::Ok,    0x0040_0000),
    (Polarity::LowIsOk,  Health::Fault, 0x0000_0040),
    (Polarity::HighIsOk, Health::Ok,    0x0000_0040),
    (Polarity::HighIsOk, Health::Fault, 0x0040_0000),
];

#[test]
fn status_outputs() {
    for &(polarity, health, word) in STATUS_OUT {
        let out = StatusOut::new(6, StatusLevel { polarity }).unwrap();
        assert_eq!(out.level_word(health), word, "{polarity:?} {health:?}");
    }
    let out = StatusOut::new(6, StatusLevel::default()).unwrap();
    let mut words = [0u32; 20];
    // 0xFDFD frame, whole-frame parity: 001_1111110111111101_1.
    out.word_frame(StatusWord::ALL_OK, &LinkConfig::default(), &mut words);
    let bits = "00111111101111111011";
    for (w, b) in words.iter().zip(bits.chars()) {
        assert_eq!(*w, if b == '1' { 0x40 } else { 0x40_0000 });
    }
    assert_eq!(
        StatusOut::new(16, StatusLevel::default()).err(),
        Some(PinError::OutOfRange { bit: 16 })
    );
}

/// `feed_at` reports each event after the sample that completed it (samples
/// consumed): a frame after its 20th bit, a short SYNC after its falling edge, an
/// overlong one after its 20th high sample; the same events as `feed`, whatever the
/// chunking.
#[test]
fn feed_at_positions_are_the_completing_samples() {
    let mut s = vec![0u16];
    s.extend(frame_samples(w16(1), w16(2), w16(3)));
    // A SYNC high for 5 bits only (framing fault at its falling edge).
    s.extend([1, 1, 1, 1, 1, 0]);
    s.extend(frame_samples(w16(4), w16(5), w16(6)));
    // SYNC stuck high: overlong at the 20th high sample.
    s.extend([1; 25]);
    let mut rx = Receiver::new(PINS, LinkConfig::default()).unwrap();
    let mut got = Vec::new();
    rx.feed_at(&s, &mut |at, e| got.push((at, e)));
    let positions: Vec<usize> = got.iter().map(|(at, _)| *at).collect();
    // Frame 1 ends with sample 20, the short SYNC falls at 26, the resync and
    // frame 2 end with 46, the overlong run's 20th high sample is 66.
    assert_eq!(positions, [21, 27, 47, 47, 67]);
    assert_eq!(got[0].1, ok_period(1, 2, 3));
    assert_eq!(
        got[1].1,
        Event::Framing(FramingFault::Short { high_bits: 5 })
    );
    assert_eq!(got[2].1, Event::Resync);
    assert_eq!(got[3].1, ok_period(4, 5, 6));
    assert_eq!(got[4].1, Event::Framing(FramingFault::Overlong));
    // Chunked: positions are relative to each chunk, the events the same.
    let mut rx = Receiver::new(PINS, LinkConfig::default()).unwrap();
    let mut chunked = Vec::new();
    let mut base = 0;
    for part in s.chunks(7) {
        rx.feed_at(part, &mut |at, e| chunked.push((base + at, e)));
        base += part.len();
    }
    assert_eq!(chunked, got);
}
