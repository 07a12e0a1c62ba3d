//! XY3-100 line level end to end: `xy3::tx` BSRR words -> waveform -> impairments ->
//! SPI-slave capture (both partial-byte behaviours) -> `xy3::rx`; and the backchannel
//! UART -> parser -> `HeadStatus` path.

use host_tests::impair;
use host_tests::line::drive::{bsrr_to_wave, OutPinMap as HostPins};
use host_tests::line::roles;
use host_tests::line::sample::{xy3_spi, PartialByte, SpiCapture};
use host_tests::line::uart::{uart_decode, uart_encode};
use host_tests::wave::{Ps, Waveform};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use shared::model::{Alarms, Axis, FaultKind, ForwardFrame, HeadStatus, Line, LineEvent};
use shared::xy3::back::{Packet, Parser};
use shared::xy3::rx::{Lines, Period, Receiver, RxError};
use shared::xy3::tx::{OutPinMap, Transmitter, TxConfig, TxConfigError, TxError};
use shared::xy3::{back_rx, neutral, DecodeError, Frame, FrameSize};

type Sent = [Option<Frame>; 5];

/// Port bits of the output (deliberately scattered).
const PINS: OutPinMap = OutPinMap {
    clk: 3,
    sync: 7,
    data: [Some(0), Some(12), Some(5), Some(9), Some(14)],
};

const ROLE: [&str; 5] = [roles::X, roles::Y, roles::Z, roles::U, roles::W];

fn pins_for(axes: &[Axis]) -> OutPinMap {
    let mut p = PINS;
    for (i, d) in p.data.iter_mut().enumerate() {
        if !axes.iter().any(|a| a.index() == i) {
            *d = None;
        }
    }
    p
}

fn host_pins(p: &OutPinMap) -> HostPins {
    HostPins {
        clk: p.clk,
        sync: p.sync,
        x: p.data[0].unwrap(),
        y: p.data[1].unwrap(),
        z: p.data[2],
        u: p.data[3],
        w: p.data[4],
    }
}

fn random_frame(rng: &mut ChaCha8Rng, size: FrameSize, command: bool) -> Frame {
    match (size, command) {
        (FrameSize::Bits24, false) => Frame::Position24(rng.random_range(0..1 << 20)),
        (FrameSize::Bits32, false) => Frame::Position32(rng.random_range(0..1 << 26)),
        (FrameSize::Bits24, true) => Frame::Command24(rng.random_range(0..1 << 20)),
        (FrameSize::Bits32, true) => Frame::Command32 {
            code: rng.random_range(0..1 << 20),
            unused: 0,
        },
    }
}

/// `n` random frame periods on `axes`; about one in 16 carries a command on X.
fn random_periods(rng: &mut ChaCha8Rng, n: usize, size: FrameSize, axes: &[Axis]) -> Vec<Sent> {
    (0..n)
        .map(|_| {
            let cmd = rng.random_range(0..16) == 0;
            let mut p = [None; 5];
            for a in axes {
                p[a.index()] = Some(random_frame(rng, size, cmd && *a == Axis::X));
            }
            p
        })
        .collect()
}

/// Frame period 10 us (100 kHz).
const PERIOD_PS: f64 = 10e6;
/// Start of the first frame (after an idle stretch).
const T0: Ps = 2_000_000;

/// Transmits `sent` and returns the waveform (SYNC idles high before the start).
fn transmit(sent: &[Sent], size: FrameSize, axes: &[Axis]) -> Waveform {
    let pins = pins_for(axes);
    let tx = Transmitter::new(&TxConfig {
        pins,
        size,
        idle_ticks: 2,
    })
    .unwrap();
    let t = tx.ticks_per_frame();
    let mut words = vec![0u32; t * sent.len()];
    for (p, out) in sent.iter().zip(words.chunks_exact_mut(t)) {
        tx.encode(p, out).unwrap();
    }
    bsrr_to_wave(
        &words,
        PERIOD_PS / t as f64,
        T0,
        &host_pins(&pins),
        &[(roles::SYNC, true)],
    )
    .unwrap()
}

fn capture(wave: &Waveform, axes: &[Axis], mode: PartialByte) -> SpiCapture {
    let names: Vec<&str> = axes.iter().map(|a| ROLE[a.index()]).collect();
    xy3_spi(wave, &names, mode).unwrap()
}

/// Feeds a capture in chunks drawn by `chunk` (0 = one frame's bytes at a time with
/// its end position, in order) and collects every period.
fn receive(cap: &SpiCapture, axes: &[Axis], seed: Option<u64>) -> Vec<Period> {
    let mut rx = Receiver::new(Lines::new(axes).unwrap());
    let mut out = Vec::new();
    let total = cap.bytes[0].len();
    let (mut b, mut e) = (0usize, 0usize);
    let mut rng = ChaCha8Rng::seed_from_u64(seed.unwrap_or(0));
    while b < total || e < cap.frame_ends.len() {
        let ends_ahead = e - out.len();
        // Contract: bytes at most WINDOW/2 ahead of the last decoded period.
        let done = out.last().map_or(0, |p: &Period| p.end as usize);
        let room = (done + 64).saturating_sub(b);
        let push_ends = e < cap.frame_ends.len()
            && match seed {
                None => cap.frame_ends[e] as usize <= b,
                Some(_) => {
                    ends_ahead < 24 && (b >= total || room == 0 || rng.random_range(0..3) == 0)
                }
            };
        if push_ends {
            let n = match seed {
                None => 1,
                Some(_) => rng.random_range(1..=8).min(24 - ends_ahead),
            };
            let n = n.min(cap.frame_ends.len() - e);
            rx.push_ends(&cap.frame_ends[e..e + n]);
            e += n;
        } else if b < total {
            let n = match seed {
                None => 1,
                Some(_) => rng.random_range(1..=48).min(room.max(1)),
            }
            .min(total - b);
            let slices: Vec<&[u8]> = cap.bytes.iter().map(|l| &l[b..b + n]).collect();
            rx.push_bytes(&slices).unwrap();
            b += n;
        } else {
            break;
        }
        while let Some(p) = rx.poll() {
            out.push(p);
        }
    }
    out
}

fn neutral_of(sent: &Sent) -> ForwardFrame {
    let mut f = ForwardFrame::default();
    for (a, fr) in Axis::ALL.iter().zip(sent) {
        if let Some(fr) = fr {
            neutral::apply(fr, *a, &mut f).unwrap();
        }
    }
    f
}

/// What came out against what was sent.
#[derive(Debug, Default)]
struct Score {
    /// Frame events that equal a sent period, in order.
    good: usize,
    /// Frame events that match no sent period (must stay 0).
    wrong: usize,
    /// Per-line `Ok` frames (in periods with failures) matching no nearby sent frame.
    wrong_lines: usize,
}

/// Per-line `Ok` frames are looked up among the sent frames near the period's end
/// position (`bpf` bytes per frame).
fn score(sent: &[Sent], periods: &[Period]) -> Score {
    let bpf = sent
        .iter()
        .flatten()
        .flatten()
        .next()
        .map_or(3, |f| u32::from(f.size().bits() / 8));
    let expected: Vec<ForwardFrame> = sent.iter().map(neutral_of).collect();
    let mut s = Score::default();
    let mut j = 0;
    for p in periods {
        let events = p.line_events();
        if let Some(LineEvent::Frame(f)) = events.iter().find(|e| matches!(e, LineEvent::Frame(_)))
        {
            match expected[j..].iter().position(|x| x == f) {
                Some(k) => {
                    s.good += 1;
                    j += k + 1;
                }
                None => s.wrong += 1,
            }
        } else {
            for (i, r) in p.lines.iter().enumerate() {
                if let Some(Ok(fr)) = r {
                    let at = (p.end / bpf) as usize;
                    let near =
                        &sent[at.saturating_sub(4).min(sent.len())..(at + 3).min(sent.len())];
                    if !near.iter().any(|x| x[i] == Some(*fr)) {
                        s.wrong_lines += 1;
                    }
                }
            }
        }
    }
    s
}

const XYZ: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];
const MODES: [PartialByte; 2] = [PartialByte::Discard, PartialByte::CarryOver];
const SIZES: [FrameSize; 2] = [FrameSize::Bits24, FrameSize::Bits32];

/// Clean line with a rate offset, jitter and skew within the margins: every frame
/// arrives, in order, identical; for both partial-byte behaviours and both sizes.
#[test]
fn clean_and_within_margins_recovers_every_frame() {
    for (seed, axes) in [(1u64, &XYZ[..]), (2, &Axis::ALL[..]), (3, &XYZ[..2])] {
        for size in SIZES {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let sent = random_periods(&mut rng, 1500, size, axes);
            let mut wave = transmit(&sent, size, axes);
            let ppm = rng.random_range(-3000.0..3000.0);
            impair::rate_offset_ppm(&mut wave, ppm).unwrap();
            // A tick is at least 150 ns: +-30 ns of jitter and skew keep every data
            // change a tick away from the sampling edge.
            impair::jitter(&mut wave, &[], 30_000, seed).unwrap();
            let skews: Vec<(&str, i64)> = axes
                .iter()
                .map(|a| (ROLE[a.index()], rng.random_range(-30_000..30_000)))
                .collect();
            impair::skew(&mut wave, &skews).unwrap();
            for mode in MODES {
                let cap = capture(&wave, axes, mode);
                let periods = receive(&cap, axes, None);
                assert_eq!(periods.len(), sent.len());
                let s = score(&sent, &periods);
                assert_eq!(
                    (s.good, s.wrong, s.wrong_lines),
                    (sent.len(), 0, 0),
                    "{seed} {size:?} {mode:?}"
                );
                // Chunking and interleaving do not change anything.
                for chunk_seed in 10..13 {
                    assert_eq!(receive(&cap, axes, Some(chunk_seed)), periods);
                }
            }
        }
    }
}

/// Runs `sent` through `impairments` and both partial-byte behaviours; returns the
/// scores.
fn run_impaired(
    sent: &[Sent],
    size: FrameSize,
    axes: &[Axis],
    impair_fn: impl Fn(&mut Waveform),
) -> Vec<(Score, Vec<Period>)> {
    let mut wave = transmit(sent, size, axes);
    impair_fn(&mut wave);
    MODES
        .iter()
        .map(|&mode| {
            let cap = capture(&wave, axes, mode);
            let periods = receive(&cap, axes, None);
            assert_eq!(receive(&cap, axes, Some(7)), periods, "chunking");
            (score(sent, &periods), periods)
        })
        .collect()
}

fn frame_start(i: usize) -> Ps {
    T0 + (i as f64 * PERIOD_PS) as Ps
}

/// Single glitches on data lines (one per burst frame): each costs at most its own
/// period, nothing wrong gets through.
#[test]
fn data_line_noise_is_detected() {
    for seed in 0..4u64 {
        for size in SIZES {
            let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
            let sent = random_periods(&mut rng, 1200, size, &XYZ);
            let hit: Vec<(usize, usize)> = (0..60)
                .map(|k| (k * 20 + rng.random_range(0..20), rng.random_range(0..3)))
                .collect();
            for (s, _) in run_impaired(&sent, size, &XYZ, |w| {
                // Only after the kind bit (bit 1) was sampled: a flipped kind bit turns
                // a command into a valid position and back, which no check of
                // the protocol can see (module docs of `xy3`).
                for (n, &(f, line)) in hit.iter().enumerate() {
                    let from = frame_start(f) + 1_000_000;
                    impair::noise_burst(
                        w,
                        ROLE[line],
                        (from, from + 8_500_000),
                        1,
                        60_000,
                        seed * 1000 + n as u64,
                    )
                    .unwrap();
                }
            }) {
                assert_eq!((s.wrong, s.wrong_lines), (0, 0), "{seed} {size:?}");
                assert!(s.good + hit.len() >= sent.len(), "{s:?}");
            }
        }
    }
}

/// SYNC glitches (frames cut in two, frames merged, empty periods) and clock stops:
/// nothing wrong gets through, the receiver realigns each time, and it ends in step.
#[test]
fn sync_glitches_and_clock_stops_realign() {
    for seed in 0..4u64 {
        for size in SIZES {
            let mut rng = ChaCha8Rng::seed_from_u64(200 + seed);
            let sent = random_periods(&mut rng, 1200, size, &XYZ);
            let events: Vec<(usize, u64, bool)> = (0..38)
                .map(|k| {
                    (
                        k * 30 + rng.random_range(0..25),
                        rng.random_range(0..10_000_000),
                        rng.random_range(0..4) == 0,
                    )
                })
                .collect();
            let results = run_impaired(&sent, size, &XYZ, |w| {
                for (n, &(f, at, clock_stop)) in events.iter().enumerate() {
                    let t = frame_start(f) + at;
                    if clock_stop {
                        impair::gap(w, roles::CLK, t, t + 25_000_000, false).unwrap();
                    } else {
                        impair::noise_burst(w, roles::SYNC, (t, t + 1), 1, 80_000, n as u64)
                            .unwrap();
                    }
                }
            });
            for (mode, (s, periods)) in MODES.iter().zip(results) {
                assert_eq!(s.wrong, 0, "{seed} {size:?} {mode:?} {s:?}");
                // Each event costs a few periods (cut frame, remainder, a hunt).
                assert!(s.good + 8 * events.len() >= sent.len(), "{mode:?} {s:?}");
                // In step at the end: the last periods are all good.
                assert!(
                    periods.iter().rev().take(20).all(Period::all_ok),
                    "{mode:?}"
                );
            }
        }
    }
}

/// Extra clock edges inside frames: with dropped partial bytes the frame is caught by
/// its checks (or, rarely, not: the parity's limit, module docs); with carried-over
/// bits every later byte shifts and the receiver must find the new bit offset.
#[test]
fn clock_glitches_slip_and_relock() {
    let mut accepted_wrong = 0;
    let mut glitches = 0;
    for seed in 0..4u64 {
        for size in SIZES {
            let mut rng = ChaCha8Rng::seed_from_u64(300 + seed);
            let sent = random_periods(&mut rng, 1200, size, &XYZ);
            let events: Vec<(usize, u64)> = (0..29)
                .map(|k| {
                    (
                        k * 40 + rng.random_range(0..30),
                        rng.random_range(0..9_000_000),
                    )
                })
                .collect();
            glitches += 2 * events.len();
            let results = run_impaired(&sent, size, &XYZ, |w| {
                for (n, &(f, at)) in events.iter().enumerate() {
                    let t = frame_start(f) + at;
                    impair::noise_burst(w, roles::CLK, (t, t + 1), 1, 40_000, n as u64).unwrap();
                }
            });
            for (mode, (s, periods)) in MODES.iter().zip(results) {
                accepted_wrong += s.wrong;
                assert!(s.good + 10 * events.len() >= sent.len(), "{mode:?} {s:?}");
                assert!(
                    periods.iter().rev().take(20).all(Period::all_ok),
                    "{mode:?}"
                );
            }
        }
    }
    println!("clock glitches: {accepted_wrong} corrupted periods accepted of {glitches}");
    // Parity-only detection (module docs): well under the 1-in-8 of a single line.
    assert!(
        accepted_wrong * 50 <= glitches,
        "{accepted_wrong} of {glitches}"
    );
}

/// Stuck and broken data lines: no frame event while a line is dead, never a wrong one.
#[test]
fn stuck_lines_stop_frames() {
    for (line, level) in [(0usize, false), (1, true), (2, false)] {
        for size in SIZES {
            let mut rng = ChaCha8Rng::seed_from_u64(400 + line as u64);
            let sent = random_periods(&mut rng, 400, size, &XYZ);
            for (s, periods) in run_impaired(&sent, size, &XYZ, |w| {
                impair::stuck_at(w, ROLE[line], frame_start(200) + 1, level).unwrap();
            }) {
                assert_eq!((s.wrong, s.wrong_lines), (0, 0));
                assert_eq!(s.good, 200, "{line} {level} {size:?}");
                // After the break every period faults on the dead line.
                for p in &periods[201..] {
                    assert!(p.line_events().contains(&LineEvent::Fault {
                        line: Line::Axis(Axis::ALL[line]),
                        kind: FaultKind::CheckFailed
                    }));
                }
            }
        }
    }
}

// ---- hand-built receiver cases -------------------------------------------------

fn word_bytes(frame: &Frame) -> Vec<u8> {
    let (w, size) = shared::xy3::encode(frame).unwrap();
    let n = usize::from(size.bits() / 8);
    w.to_be_bytes()[4 - n..].to_vec()
}

fn feed(rx: &mut Receiver, x: &[u8], y: &[u8], ends: &[u32]) -> Vec<Period> {
    rx.push_bytes(&[x, y]).unwrap();
    rx.push_ends(ends);
    std::iter::from_fn(|| rx.poll()).collect()
}

#[test]
fn truncated_and_extended_periods_are_framing_errors() {
    let a = Frame::Position32(0x200_0000);
    let b = Frame::Position24(0x8_0000);
    let c = Frame::Command24(0xE_0000);
    let mut x = word_bytes(&a);
    x.extend([0x12, 0x34]); // truncated: 2 bytes
    x.extend(word_bytes(&b)); // the next period: possibly the rest -> withdrawn
    x.extend(word_bytes(&c));
    x.extend([0xAA; 5]); // extended: 5 bytes
    x.extend(word_bytes(&a));
    let y = x.clone();
    let mut rx = Receiver::new(Lines::XY);
    let p = feed(&mut rx, &x, &y, &[4, 6, 9, 12, 17, 21]);
    let first = |p: &Period| p.lines[0];
    assert_eq!(first(&p[0]), Some(Ok(a)));
    assert_eq!(first(&p[1]), Some(Err(RxError::Framing { bytes: 2 })));
    assert_eq!(first(&p[2]), Some(Err(RxError::Remainder)));
    assert_eq!(first(&p[3]), Some(Ok(c)));
    assert_eq!(first(&p[4]), Some(Err(RxError::Framing { bytes: 5 })));
    assert_eq!(first(&p[5]), Some(Ok(a)));
    assert_eq!(p.len(), 6);
    assert_eq!(rx.stats().framing, 3);
    // Command on X: frame event with the command, no X position.
    let events = p[3].line_events();
    let LineEvent::Frame(f) = events[0] else {
        panic!("{events:?}")
    };
    assert_eq!(f.command, Some(shared::model::Command::Xy3(0xE_0000)));
    assert_eq!(f.axis(Axis::X), None);
    assert_eq!(events.len(), 1);
    // Framing faults per line.
    assert_eq!(
        p[1].line_events().as_slice(),
        &[
            LineEvent::Fault {
                line: Line::Axis(Axis::X),
                kind: FaultKind::Framing
            },
            LineEvent::Fault {
                line: Line::Axis(Axis::Y),
                kind: FaultKind::Framing
            }
        ]
    );
}

#[test]
fn size_and_parity_failures_withdraw_the_period() {
    let a = Frame::Position24(0x1_2345);
    let good = word_bytes(&a);
    let mut bad = good.clone();
    bad[2] ^= 0x04; // one data bit
    let mut rx = Receiver::new(Lines::XY);
    let p = feed(
        &mut rx,
        &[good.clone(), good.clone()].concat(),
        &[bad, good.clone()].concat(),
        &[3, 6],
    );
    assert_eq!(p[0].lines[0], Some(Ok(a)));
    assert!(matches!(
        p[0].lines[1],
        Some(Err(RxError::Check(DecodeError::Parity { .. })))
    ));
    assert!(!p[0]
        .line_events()
        .iter()
        .any(|e| matches!(e, LineEvent::Frame(_))));
    assert!(p[1].all_ok());
    // 4 bytes of a 24-bit frame's line: the first bit announces 24.
    let mut rx = Receiver::new(Lines::XY);
    let four = [good.clone(), vec![0]].concat();
    let p = feed(&mut rx, &four, &four, &[4]);
    assert!(matches!(
        p[0].lines[0],
        Some(Err(RxError::Check(DecodeError::SizeMismatch { .. })))
    ));
    // Both lines failed: suspected slip, the receiver hunts (each hunting period needs
    // the next period's first byte), then relocks at 0 once two periods agree.
    assert_eq!(rx.offset(), None);
    let values = [
        0x3_1F5A, 0xA_B3C1, 0x0_47E2, 0x5_9D06, 0xC_2A7B, 0x7_E419, 0x2_6C83,
    ];
    let frames: Vec<Frame> = values.iter().map(|&v| Frame::Position24(v)).collect();
    let bytes: Vec<u8> = frames.iter().flat_map(word_bytes).collect();
    let ends: Vec<u32> = (1..=7).map(|i| 4 + 3 * i).collect();
    let p = feed(&mut rx, &bytes, &bytes, &ends);
    assert_eq!(rx.offset(), Some(0));
    assert_eq!(rx.stats().relocks, 1);
    let first_ok = p.iter().position(Period::all_ok).unwrap();
    assert!(p[..first_ok]
        .iter()
        .all(|p| p.lines[0] == Some(Err(RxError::Unaligned))));
    for (i, q) in p.iter().enumerate().skip(first_ok) {
        assert_eq!(q.lines[0], Some(Ok(frames[i])));
    }
}

#[test]
fn ends_may_come_before_their_bytes_and_bad_ends_are_dropped() {
    let a = word_bytes(&Frame::Position24(7));
    let mut rx = Receiver::new(Lines::XY);
    rx.push_ends(&[3, 6, 2]); // 2 goes backwards: dropped
    assert_eq!(rx.stats().bad_ends, 1);
    assert_eq!(rx.poll(), None);
    let p = feed(&mut rx, &a, &a, &[]);
    assert_eq!(p.len(), 1);
    let p = feed(&mut rx, &a, &a, &[]);
    assert!(p[0].all_ok());
    // Wrong slice count or lengths are refused.
    assert!(rx.push_bytes(&[&a]).is_err());
    assert!(rx.push_bytes(&[&a, &a[..2]]).is_err());
    // Bytes overwritten before their end arrived: overrun, not a guess.
    let mut rx = Receiver::new(Lines::XY);
    let long = vec![0u8; 300];
    let p = feed(&mut rx, &long, &long, &[3]);
    assert_eq!(p[0].lines[0], Some(Err(RxError::Overrun)));
}

/// The NSS glitch that cuts a 32-bit frame after its first byte: the 3-byte rest
/// would pass as a 24-bit frame for some data; it is withdrawn as a remainder.
#[test]
fn nss_glitch_after_first_byte() {
    for value in 0..64u32 {
        let axes = &XYZ[..2];
        let f = Frame::Position32(value << 20 | 0x5_5555);
        let sent = vec![[Some(f), Some(f), None, None, None]; 4];
        for (s, periods) in run_impaired(&sent, FrameSize::Bits32, axes, |w| {
            // Tick 66 per 10 us; bit 8's rising edge is word 17: rise just before it.
            let t = frame_start(1) + (16.5 * PERIOD_PS / 66.0) as Ps;
            impair::noise_burst(w, roles::SYNC, (t, t + 1), 1, 20_000, 1).unwrap();
        }) {
            assert_eq!(s.wrong, 0);
            assert_eq!(
                periods[1].lines[0],
                Some(Err(RxError::Framing { bytes: 1 }))
            );
            assert!(!periods[2].all_ok());
        }
    }
}

// ---- transmitter ---------------------------------------------------------------

/// BSRR words of a 24-bit frame on X and Y, worked out by hand from the table in the
/// `tx` module docs with CLK = bit 0, SYNC = bit 1, X = bit 2, Y = bit 3:
/// set masks CLK 0x1, SYNC 0x2, X 0x4, Y 0x8; reset masks << 16.
/// (X frame, X wire bits by hand, (word index, expected word)).
type BsrrRow = (Frame, &'static str, &'static [(usize, u32)]);

#[rustfmt::skip]
const BSRR_24: &[BsrrRow] = &[
    // (X frame, X wire bits written out by hand, (word index, expected word)); Y sends
    // Command24(0) = all zeros throughout.
    (Frame::Position24(0), "010000000000000000000000", &[
        (0, 0x000F_0000),  // SYNC low, CLK low, X=0, Y=0 (set-up)
        (1, 0x000C_0001),  // bit 0 = 0: CLK high, X reset, Y reset
        (2, 0x0001_0000),  // CLK low (sampling edge)
        (3, 0x0008_0005),  // bit 1 = 1: CLK high, X set, Y reset
        (48, 0x0001_0000), // last falling edge
        (49, 0x000C_0002), // SYNC high, data low
    ]),
    // Centre: D = 0x80000 has one 1 -> P = 01.
    (Frame::Position24(0x8_0000), "011000000000000000000001", &[
        (0, 0x000F_0000),
        (5, 0x0008_0005),  // bit 2 = 1
        (7, 0x000C_0001),  // bit 3 = 0
        (47, 0x0008_0005), // bit 23 (P0) = 1
        (49, 0x000C_0002),
    ]),
    // Full scale: twenty ones -> 20 & 3 = 0 -> P = 00.
    (Frame::Position24(0xF_FFFF), "011111111111111111111100", &[
        (0, 0x000F_0000),
        (45, 0x000C_0001), // bit 22 (P1) = 0
        (46, 0x0001_0000),
        (47, 0x000C_0001), // bit 23 (P0) = 0
        (49, 0x000C_0002),
    ]),
];

#[test]
fn bsrr_words_by_hand() {
    let pins = OutPinMap {
        clk: 0,
        sync: 1,
        data: [Some(2), Some(3), None, None, None],
    };
    let tx = Transmitter::new(&TxConfig {
        pins,
        size: FrameSize::Bits24,
        idle_ticks: 2,
    })
    .unwrap();
    assert_eq!(tx.ticks_per_frame(), 50);
    assert_eq!(tx.tick_hz(100_000), 5_000_000);
    for &(x, bits, words) in BSRR_24 {
        let mut out = [0xDEAD_BEEFu32; 50];
        tx.encode(
            &[Some(x), Some(Frame::Command24(0)), None, None, None],
            &mut out,
        )
        .unwrap();
        for &(i, w) in words {
            assert_eq!(out[i], w, "{x:?} word {i}");
        }
        // Every bit: CLK-high word carries the hand-written bit, then CLK low.
        for (b, c) in bits.chars().enumerate() {
            let xbit = if c == '1' { 0x4 } else { 0x4_0000 };
            assert_eq!(out[2 * b + 1], 0x1 | 0x8_0000 | xbit, "{x:?} bit {b}");
            assert_eq!(out[2 * b + 2], 0x1_0000);
        }
    }
    // 32-bit: 66 ticks; idle words after the SYNC rise are 0.
    let tx = Transmitter::new(&TxConfig {
        pins,
        size: FrameSize::Bits32,
        idle_ticks: 4,
    })
    .unwrap();
    assert_eq!(tx.ticks_per_frame(), 68);
    let mut out = [1u32; 68];
    let f = Frame::Position32(0);
    tx.encode(&[Some(f), Some(f), None, None, None], &mut out)
        .unwrap();
    assert_eq!(out[65], 0x000C_0002);
    assert_eq!(&out[66..], &[0, 0]);
    let mut idle = [1u32; 68];
    tx.idle(&mut idle).unwrap();
    assert_eq!(idle[0], 0x000D_0002);
    assert!(idle[1..].iter().all(|&w| w == 0));
}

#[test]
fn transmitter_refuses_bad_input() {
    let cfg = |pins, idle_ticks| TxConfig {
        pins,
        size: FrameSize::Bits24,
        idle_ticks,
    };
    let mut p = PINS;
    p.data[1] = Some(3); // Y on CLK's pin
    assert_eq!(
        Transmitter::new(&cfg(p, 2)),
        Err(TxConfigError::PinTwice(3))
    );
    p.data[1] = Some(16);
    assert_eq!(
        Transmitter::new(&cfg(p, 2)),
        Err(TxConfigError::PinOutOfRange(16))
    );
    p.data[1] = None;
    assert_eq!(
        Transmitter::new(&cfg(p, 2)),
        Err(TxConfigError::MissingLine(Axis::Y))
    );
    assert_eq!(
        Transmitter::new(&cfg(PINS, 1)),
        Err(TxConfigError::IdleTooShort(1))
    );
    let tx = Transmitter::new(&cfg(pins_for(&XYZ), 2)).unwrap();
    let f24 = Some(Frame::Position24(1));
    let mut out = [0u32; 50];
    assert_eq!(
        tx.encode(&[f24, f24, None, None, None], &mut out),
        Err(TxError::MissingFrame(Axis::Z))
    );
    assert_eq!(
        tx.encode(&[f24, f24, f24, f24, None], &mut out),
        Err(TxError::NotDriven(Axis::U))
    );
    let f32 = Some(Frame::Position32(1));
    assert_eq!(
        tx.encode(&[f24, f32, f24, None, None], &mut out),
        Err(TxError::WrongSize(Axis::Y))
    );
    let wide = Some(Frame::Position24(1 << 20));
    assert!(matches!(
        tx.encode(&[wide, f24, f24, None, None], &mut out),
        Err(TxError::Encode(_))
    ));
    assert_eq!(
        tx.encode(&[f24, f24, f24, None, None], &mut out[..49]),
        Err(TxError::BufferTooShort {
            needed: 50,
            got: 49
        })
    );
}

// ---- backchannel ---------------------------------------------------------------

#[test]
fn backchannel_through_uart_noise() {
    let mut bytes = Vec::new();
    let mut buf = [0u8; 300];
    let mut packets = vec![
        Packet::Sync,
        Packet::ErrorState([0, 2].into_iter().collect()),
        Packet::Sync,
        Packet::Vendor(b"ACME".iter().copied().collect()),
    ];
    // Enough after the noise that a misread length (up to 255 bytes swallowed) still
    // leaves a SYNC and a FRAME_ERROR_COUNT behind it.
    for _ in 0..6 {
        packets.extend(std::iter::repeat_n(Packet::Sync, 8));
        packets.push(Packet::FrameErrorCount([1, 2, 3, 4, 5]));
    }
    packets.push(Packet::Sync);
    let mut starts = Vec::new();
    for p in &packets {
        starts.push(bytes.len());
        let n = p.encode(&mut buf).unwrap();
        bytes.extend_from_slice(&buf[..n]);
    }
    bytes.extend_from_slice(&[0x48]); // head of the next packet confirms the last SYNC
    let baud = 115_200.0;
    let bit_ps = 1e12 / baud;
    let mut line = uart_encode(roles::UART, &bytes, baud, 1_000_000, 1).unwrap();
    // Noise over the VENDOR packet's length byte: the parser cuts the packet wrong
    // and loses sync (a payload byte hit instead would go unnoticed: the backchannel
    // has no checksum, `back` module docs).
    let from = 1_000_000 + ((starts[3] + 2) as f64 * 11.0 * bit_ps) as Ps;
    let mut w = Waveform::new();
    w.insert(line.clone());
    impair::noise_burst(
        &mut w,
        roles::UART,
        (from, from + (9.0 * bit_ps) as Ps),
        3,
        3_000_000,
        5,
    )
    .unwrap();
    line = w.get(roles::UART).unwrap().clone();
    let rx: Vec<u8> = uart_decode(&line, baud)
        .unwrap()
        .into_iter()
        .filter(|f| !f.framing_error)
        .map(|f| f.value)
        .collect();
    let mut parser = Parser::new();
    let mut status = HeadStatus::default();
    let mut faults = Vec::new();
    back_rx::push_bytes(&mut parser, &rx, &mut status, |e| faults.push(e));
    // The error state arrived before the noise, the counts after the resync.
    assert!(status.alarms.contains(Alarms::COMMUNICATION));
    assert_eq!(status.frame_errors, Some([1, 2, 3, 4, 5]));
    assert!(
        faults.contains(&LineEvent::Fault {
            line: Line::Backchannel,
            kind: FaultKind::Framing
        }) || faults.contains(&LineEvent::Fault {
            line: Line::Backchannel,
            kind: FaultKind::CheckFailed
        })
    );
    assert!(
        faults
            .iter()
            .filter(|f| **f
                == LineEvent::Fault {
                    line: Line::Backchannel,
                    kind: FaultKind::Resync
                })
            .count()
            >= 2
    );
}
