//! HANS-100 line level end to end: frames -> transmit slots (`write_slot`) -> the SPI
//! bitstream at 12.5 MHz (with rate offset) -> impairments -> the oversampling SPI
//! slaves (`Oversampler`, random phase) -> `hans::rx::HansRx` in every mode.
//!
//! Checks: every intact frame after lock is recovered, nothing that was not sent is
//! ever published (and the order is kept), broken channels per mode, ±2 samples of
//! skew, chunking independence, and the loss-rate limits against rate offset,
//! jitter and asymmetric rising / falling edge delays (printed with `--nocapture`).

use host_tests::impair;
use host_tests::line::drive::bitstream_to_signal;
use host_tests::line::roles::HANS_CHANNELS;
use host_tests::line::sample::Oversampler;
use host_tests::wave::{Ps, Waveform};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use shared::hans::rx::{HansRx, Mode, RxEvent};
use shared::hans::{write_slot, Frame, RING_BYTES, RING_SLOTS, WORD_MAX};

const BIT_PS: f64 = 80_000.0;

fn random_frames(n: usize, rng: &mut ChaCha8Rng) -> Vec<Frame> {
    (0..n)
        .map(|_| {
            let mut w = || rng.random_range(0..=WORD_MAX);
            Frame::new(w(), w(), w()).unwrap()
        })
        .collect()
}

/// The bytes the transmit ring sends over successive DMA turns (`write_slot` per
/// frame), concatenated. The frame count must fill whole turns (8 frames).
fn tx_bytes(frames: &[Frame]) -> Vec<u8> {
    assert!(
        frames.len().is_multiple_of(RING_SLOTS),
        "whole DMA turns only"
    );
    let mut out = Vec::new();
    for turn in frames.chunks(RING_SLOTS) {
        let mut ring = [0u8; RING_BYTES];
        for (slot, f) in turn.iter().enumerate() {
            write_slot(&mut ring, slot, f).unwrap();
        }
        out.extend_from_slice(&ring);
    }
    out
}

/// Line conditions of one run.
#[derive(Clone, Copy, Debug)]
struct Line {
    fs_hz: f64,
    /// Sender rate offset, percent.
    offset_pct: f64,
    /// Edge jitter, fraction of a bit.
    jitter: f64,
    /// Skew per channel in samples (at fs).
    skew: [f64; 5],
    /// Rising edges' delay against the falling ones, fraction of a bit (negative:
    /// the falling edges late), on every channel (`impair::asymmetry`).
    asym: f64,
}

/// What may go wrong on one channel.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fault {
    None,
    /// Stuck at a level from `from` frames on.
    Stuck(bool),
    /// Dense glitches over the whole run.
    Noise,
}

/// The five channels' sample words (`u16`, as the SPI slaves deliver them).
fn capture(frames: &[Frame], line: Line, faults: [Fault; 5], seed: u64) -> (Vec<Vec<u16>>, Ps) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let bytes = tx_bytes(frames);
    let rate = 12.5e6 * (1.0 + line.offset_pct / 100.0);
    let t0: Ps = 1_000_000;
    let mut wave = Waveform::new();
    for name in HANS_CHANNELS {
        wave.insert(bitstream_to_signal(name, &bytes, rate, t0).unwrap());
    }
    let end = t0 + (bytes.len() as f64 * 8.0 * 1e12 / rate) as Ps;
    if line.jitter > 0.0 {
        let max = (line.jitter * BIT_PS) as u64;
        impair::jitter(&mut wave, &[], max, rng.random()).unwrap();
    }
    impair::asymmetry(&mut wave, &[], (line.asym * BIT_PS).round() as i64).unwrap();
    let sample_ps = 1e12 / line.fs_hz;
    let delays: Vec<(&str, i64)> = HANS_CHANNELS
        .iter()
        .zip(line.skew)
        .map(|(&n, s)| (n, (s * sample_ps) as i64 + 100_000))
        .collect();
    impair::skew(&mut wave, &delays).unwrap();
    for (name, fault) in HANS_CHANNELS.iter().zip(faults) {
        match fault {
            Fault::None => {}
            Fault::Stuck(level) => {
                impair::stuck_at(&mut wave, name, t0 + (end - t0) / 3, level).unwrap()
            }
            Fault::Noise => impair::noise_burst(
                &mut wave,
                name,
                (t0, end),
                frames.len() * 3,
                40_000,
                rng.random(),
            )
            .unwrap(),
        }
    }
    let sampler = Oversampler {
        fs_hz: line.fs_hz,
        start_ps: rng.random_range(0.0..200_000.0),
    };
    let words = sampler.sample(&wave, &HANS_CHANNELS, end).unwrap();
    let words = words
        .into_iter()
        .map(|ch| {
            ch.into_iter()
                .flat_map(|w| [(w >> 16) as u16, w as u16])
                .collect()
        })
        .collect();
    (words, end)
}

/// Runs `mode` over the capture in chunks of random length.
fn receive(words: &[Vec<u16>], fs_hz: f64, mode: Mode, seed: u64) -> (Vec<RxEvent>, HansRx) {
    let mut rx = HansRx::new(fs_hz.round() as u32, mode).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let len = words[0].len();
    let mut at = 0;
    let mut events = Vec::new();
    while at < len {
        let n = rng.random_range(1..=64).min(len - at);
        let chunks: Vec<&[u16]> = words.iter().map(|w| &w[at..at + n]).collect();
        rx.push(&chunks, &mut |e| events.push(e));
        at += n;
    }
    (events, rx)
}

fn published(events: &[RxEvent]) -> Vec<Frame> {
    events
        .iter()
        .filter_map(|e| match e {
            RxEvent::Frame(f) => Some(*f),
            RxEvent::Fault { .. } => None,
        })
        .collect()
}

/// Matches `got` against `sent` in order: returns (frames after the first `skip`
/// that were not published, published frames that were never sent at that point).
fn score(sent: &[Frame], got: &[Frame], skip: usize) -> (usize, usize) {
    let (lost, invented) = scored(sent, got, skip);
    (lost.len(), invented)
}

/// Like [`score`], with the indices of the frames lost.
fn scored(sent: &[Frame], got: &[Frame], skip: usize) -> (Vec<usize>, usize) {
    let mut i = 0;
    let mut matched = Vec::new();
    let mut invented = 0;
    for f in got {
        match sent[i.min(sent.len())..].iter().position(|s| s == f) {
            Some(k) => {
                matched.push(i + k);
                i += k + 1;
            }
            None => invented += 1,
        }
    }
    // The last frame needs no following start edge to be sampled, but the capture
    // may end inside it: don't count it.
    let lost: Vec<usize> = (skip..sent.len() - 1)
        .filter(|k| !matched.contains(k))
        .collect();
    (lost, invented)
}

/// Like [`score`], failing on any published frame that was not sent.
fn lost_after(sent: &[Frame], got: &[Frame], skip: usize) -> usize {
    let (lost, invented) = score(sent, got, skip);
    assert_eq!(invented, 0, "published frames that were not sent");
    lost
}

const MODES: [Mode; 4] = [
    Mode::Normal { channel: 2 },
    Mode::Vote3 {
        channels: [5, 1, 3],
    },
    Mode::Vote5,
    Mode::Super,
];

/// Frames that may be lost during acquisition: hunt (1-2 frames), rate measurement
/// (1 frame), the young lock's periods that publish nothing (6, see
/// `shared::hans::rx::timing::SETTLED`), and one relock after a false lock (3
/// failures).
const LOCK_FRAMES: usize = 16;

#[test]
fn every_mode_recovers_every_intact_frame() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for (k, fs) in [37.5e6, 40e6, 50e6, 45.3e6].into_iter().enumerate() {
        for offset in [-1.0, 0.0, 1.0] {
            let frames = random_frames(160, &mut rng);
            let skew = std::array::from_fn(|_| rng.random_range(-2.0..=2.0));
            let line = Line {
                fs_hz: fs,
                offset_pct: offset,
                jitter: 0.15,
                skew,
                asym: 0.0,
            };
            let (words, _) = capture(&frames, line, [Fault::None; 5], k as u64);
            for mode in MODES {
                let (events, _) = receive(&words, fs, mode, 9);
                let lost = lost_after(&frames, &published(&events), LOCK_FRAMES);
                assert_eq!(lost, 0, "{mode:?} {line:?}");
            }
        }
    }
}

#[test]
fn chunking_does_not_matter() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let frames = random_frames(48, &mut rng);
    let line = Line {
        fs_hz: 40e6,
        offset_pct: 0.4,
        jitter: 0.2,
        skew: [0.0, 1.5, -2.0, 0.7, 2.0],
        asym: 0.0,
    };
    let faults = [
        Fault::None,
        Fault::Noise,
        Fault::None,
        Fault::Stuck(true),
        Fault::None,
    ];
    let (words, _) = capture(&frames, line, faults, 5);
    for mode in MODES {
        let (a, _) = receive(&words, line.fs_hz, mode, 1);
        let (b, _) = receive(&words, line.fs_hz, mode, 2);
        let (c, _) = receive(&words, line.fs_hz, mode, 3);
        assert_eq!(a, b, "{mode:?}");
        assert_eq!(a, c, "{mode:?}");
    }
}

/// Runs one broken-line scenario; returns frames lost after lock.
fn broken(mode: Mode, faults: [Fault; 5], seed: u64) -> (usize, usize) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let frames = random_frames(120, &mut rng);
    let fs = [37.5e6, 40e6, 50e6][seed as usize % 3];
    let line = Line {
        fs_hz: fs,
        offset_pct: rng.random_range(-1.0..=1.0),
        jitter: 0.15,
        skew: std::array::from_fn(|_| rng.random_range(-2.0..=2.0)),
        asym: 0.0,
    };
    let (words, _) = capture(&frames, line, faults, seed);
    let (events, _) = receive(&words, fs, mode, seed);
    let got = published(&events);
    (lost_after(&frames, &got, LOCK_FRAMES), got.len())
}

#[test]
fn broken_channels_never_yield_garbage() {
    use Fault::{Noise, Stuck};
    const OK: Fault = Fault::None;
    for seed in 0..3 {
        // Normal on a broken channel loses frames, never invents any (checked in
        // `lost_after`); on a stuck one it stops publishing.
        let (lost, _) = broken(Mode::Normal { channel: 2 }, [OK, Noise, OK, OK, OK], seed);
        assert!(lost > 0, "dense noise should cost frames");
        let (lost, got) = broken(
            Mode::Normal { channel: 2 },
            [OK, Stuck(seed % 2 == 0), OK, OK, OK],
            seed,
        );
        assert!(
            lost > 60 && got < 60,
            "stuck channel: {lost} lost, {got} published"
        );
        // Vote3 with one bad channel of three.
        let vote3 = Mode::Vote3 {
            channels: [5, 1, 3],
        };
        let (lost, _) = broken(vote3, [Stuck(false), OK, OK, Noise, OK], seed);
        assert_eq!(lost, 0, "vote3, one stuck");
        // Vote5 with two bad of five: one stuck, one noisy.
        let (lost, _) = broken(Mode::Vote5, [OK, Stuck(true), OK, OK, Noise], seed);
        assert_eq!(lost, 0, "vote5, two bad");
        // Super with four bad of five.
        let faults = [Noise, Stuck(true), Noise, OK, Stuck(false)];
        let (lost, _) = broken(Mode::Super, faults, seed);
        assert_eq!(lost, 0, "super, four bad");
    }
}

/// Loss rate (percent) of normal mode on one clean channel over `n` frames, and the
/// number of published frames that were not sent (wrong frames that happened to pass
/// every check: possible only far beyond the specified impairments).
fn loss(fs: f64, offset_pct: f64, jitter: f64, n: usize, seed: u64) -> (f64, usize) {
    let l = run_lock(fs, offset_pct, jitter, n, seed);
    (
        100.0 * l.lost as f64 / (n - LOCK_FRAMES - 1) as f64,
        l.wrong,
    )
}

#[test]
fn limits_rate_offset_and_jitter() {
    const N: usize = 400;
    println!("HANS-100 receiver: frames lost (%) over {N} frames, normal mode, after lock");
    print!("{:>14}", "rate offset");
    let offsets = [-3.0, -2.0, -1.5, -1.0, 0.0, 1.0, 1.5, 2.0, 3.0];
    for o in offsets {
        print!("{o:>7.1}%");
    }
    println!();
    for fs in [37.5e6, 50e6] {
        print!("{:>10.1} MHz", fs / 1e6);
        for (i, o) in offsets.into_iter().enumerate() {
            let (l, wrong) = loss(fs, o, 0.0, N, 100 + i as u64);
            print!("{l:>7.1}{}", if wrong > 0 { '!' } else { ' ' });
            if o.abs() <= 1.0 {
                assert_eq!((l, wrong), (0.0, 0), "lost frames at {o} % offset, {fs} Hz");
            }
        }
        println!();
    }
    print!("{:>14}", "jitter ±");
    let jitters = [0.0, 0.1, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45];
    for j in jitters {
        print!("{:>7.0}%", j * 100.0);
    }
    println!();
    for fs in [37.5e6, 40e6, 50e6] {
        print!("{:>10.1} MHz", fs / 1e6);
        for (i, j) in jitters.into_iter().enumerate() {
            let (l, wrong) = loss(fs, 0.0, j, N, 200 + i as u64);
            print!("{l:>7.1}{}", if wrong > 0 { '!' } else { ' ' });
            // The spec's ±25 %: a young lock fits its phase and rate on every
            // verified frame's mid-pair edges (`shared::hans::rx::phase`) and the
            // start edges are confirmed within 3/8 of a bit, centred.
            if j <= 0.25 {
                assert_eq!(
                    (l, wrong),
                    (0.0, 0),
                    "lost frames at ±{j} bit jitter, {fs} Hz"
                );
            }
        }
        println!();
    }
    println!("(! = a frame that was not sent passed every check)");
}

/// What one lock of [`run_lock`] did.
struct Lock {
    /// Frames lost after [`LOCK_FRAMES`].
    lost: usize,
    /// How many of them after the first published frame (the rest are a slow
    /// acquisition).
    late: usize,
    /// Published frames that were never sent.
    wrong: usize,
    /// Index of the first published frame (the frames the acquisition took).
    first: usize,
    /// The frames lost after [`LOCK_FRAMES`] (indices).
    which: Vec<usize>,
}

/// One lock of normal mode on one clean channel over `n` frames (`seed` chooses
/// the frames, the jitter, the sampling phase and the chunking).
fn run_lock(fs: f64, offset_pct: f64, jitter: f64, n: usize, seed: u64) -> Lock {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let frames = random_frames(n, &mut rng);
    let line = Line {
        fs_hz: fs,
        offset_pct,
        jitter,
        skew: [0.0; 5],
        asym: 0.0,
    };
    let (words, _) = capture(&frames, line, [Fault::None; 5], seed);
    let words = vec![words[0].clone()];
    let (events, _) = receive(&words, fs, Mode::Normal { channel: 1 }, seed);
    let got = published(&events);
    let (which, wrong) = scored(&frames, &got, LOCK_FRAMES);
    let lost = which.len();
    let first = got
        .iter()
        .find_map(|f| frames.iter().position(|s| s == f))
        .unwrap_or(n);
    let (late, _) = score(&frames, &got, first.max(LOCK_FRAMES));
    Lock {
        lost,
        late,
        wrong,
        first,
        which,
    }
}

/// What a point of [`limits_over_many_locks`] must show besides no wrong frame.
#[derive(Clone, Copy, PartialEq)]
enum Must {
    /// No lock loses a frame after [`LOCK_FRAMES`].
    LoseNothing,
    /// Measured only.
    Measure,
}

/// The young lock is where jitter costs frames (README "Known limits", docs/engineering-log.md): one seed per
/// point says little, so this runs many locks per point (each its own frames,
/// jitter, sampling phase and, for the "±1 %" rows, a random offset within ±1 %)
/// and prints how many of them lost frames, how many lost any after their first
/// published frame (the rest: an acquisition longer than [`LOCK_FRAMES`]), mean and
/// worst loss, and the mean and longest acquisition (frames before the first
/// published one) (with `--nocapture`). Nothing wrong may be published at any
/// point. `HANS_LOCKS` sets the locks per point (default 64; e.g. 640 for the
/// figures in the engineering log), the assertions unchanged.
#[test]
fn limits_over_many_locks() {
    let locks = std::env::var("HANS_LOCKS").map_or(64, |v| v.parse::<u64>().unwrap_or(64));
    // `HANS_JITTER=0.25,0.2` runs the points with those jitters only (tracing).
    let only: Option<Vec<f64>> = std::env::var("HANS_JITTER")
        .ok()
        .map(|v| v.split(',').filter_map(|j| j.trim().parse().ok()).collect());
    const N: usize = 80;
    let scored = N - LOCK_FRAMES - 1;
    println!(
        "HANS-100 receiver over {locks} locks per point ({scored} frames scored after {LOCK_FRAMES}), normal mode"
    );
    println!(
        "{:>9} {:>9} {:>7} | {:>12} {:>16} {:>7} {:>8} | {:>10} {:>9}",
        "fs MHz",
        "jitter ±",
        "offset",
        "locks losing",
        "after publishing",
        "mean %",
        "worst %",
        "first mean",
        "first max"
    );
    // (jitter, offset in percent (None: random within ±1 %), requirement)
    let points = [
        (0.20, Some(0.0), Must::LoseNothing),
        // The hunt reads the frame between its two start edges and fits its line
        // on the frame's mid-pair edges (`shared::hans::rx::hunt`).
        (0.25, Some(0.0), Must::LoseNothing),
        // Seed 20023 at 37.5 MHz, frame 53, lost here before: 7 of its last 8
        // mid-pair edges measured a sample early (3x, jitter alone), their mean
        // 0.29 bit off a timing within 0.02 sample of the line; the edges
        // between its pairs confirm the timing (the tail's second look,
        // `shared::hans::rx::confirm`).
        (0.25, None, Must::LoseNothing),
        (0.0, Some(2.5), Must::Measure),
        (0.30, Some(0.0), Must::Measure),
        // A clean line: the acquisition time (first published frame) is printed.
        (0.0, Some(0.0), Must::LoseNothing),
    ];
    // Loss requirements that failed, asserted after the whole table is printed.
    let mut failed = Vec::new();
    // Every lock that lost frames at a point that should lose none, printed
    // after the table (with `HANS_LOCKS` above 64).
    let mut losers = Vec::new();
    for fs in [37.5e6, 40e6, 50e6] {
        for (p, &(jitter, offset, must)) in points.iter().enumerate() {
            if !only.as_ref().is_none_or(|j| j.contains(&jitter)) {
                continue;
            }
            let (mut losing, mut late_locks, mut lost_all, mut worst) = (0, 0, 0, 0);
            let (mut first_all, mut first_max) = (0, 0);
            for lock in 0..locks {
                let seed = 10_000 * p as u64 + lock;
                let offset = offset.unwrap_or_else(|| {
                    ChaCha8Rng::seed_from_u64(seed ^ 0xA5A5).random_range(-1.0..=1.0)
                });
                let Lock {
                    lost,
                    late,
                    wrong,
                    first,
                    which,
                } = run_lock(fs, offset, jitter, N, seed);
                let at = format!("{fs} Hz, ±{jitter} bit, {offset:.2} %, seed {seed}");
                assert_eq!(wrong, 0, "published a frame that was not sent: {at}");
                if lost > 0 && must == Must::LoseNothing {
                    losers.push(format!("{at}: first published {first}, lost {which:?}"));
                }
                if must == Must::LoseNothing && lost > 0 {
                    failed.push(format!("lost {lost} ({late} after publishing): {at}"));
                }
                losing += usize::from(lost > 0);
                late_locks += usize::from(late > 0);
                lost_all += lost;
                worst = worst.max(lost);
                first_all += first;
                first_max = first_max.max(first);
            }
            let offset = offset.map_or("±1 %".to_string(), |o| format!("{o:.1} %"));
            println!(
                "{:>9.1} {:>8.0}% {:>7} | {:>9}/{locks} {:>13}/{locks} {:>7.2} {:>8.1} | {:>10.2} {:>9}",
                fs / 1e6,
                jitter * 100.0,
                offset,
                losing,
                late_locks,
                100.0 * lost_all as f64 / (scored as f64 * locks as f64),
                100.0 * worst as f64 / scored as f64,
                first_all as f64 / locks as f64,
                first_max,
            );
        }
    }
    println!("(no wrong frame at any point)");
    for l in &losers {
        println!("losing lock: {l}");
    }
    assert!(failed.is_empty(), "{failed:#?}");
}

/// Locks whose hunt left the line a few tenths of a sample and ~0.2 sample a
/// frame off (traced at 640 locks a point, docs/engineering-log.md
/// 2026-12-03): none of their first frames verified, the young fit got no
/// mid-pair edge, and after six failures the lock was dropped and the hunt
/// started over (first frame published 17..33, where a lock publishes from 8).
/// A failed unsettled frame that reads right an eighth or a quarter of a bit
/// over now corrects the fit (`shared::hans::rx::HansRx::reread`): each
/// publishes from frame 10 at the latest and loses nothing, and publishes
/// nothing that was not sent.
#[test]
fn an_off_young_lock_is_put_back() {
    // (fs, offset: None for the many-locks test's random one, seed, first
    // frame published before)
    let locks = [
        (37.5e6, Some(0.0), 10_318, 17),
        (37.5e6, Some(0.0), 10_402, 33),
        (37.5e6, Some(0.0), 10_425, 17),
        (37.5e6, Some(0.0), 10_596, 19),
        (37.5e6, None, 20_220, 17),
        (37.5e6, None, 20_279, 18),
        (37.5e6, None, 20_289, 17),
        (37.5e6, None, 20_327, 18),
        (40e6, Some(0.0), 10_201, 17),
        (40e6, Some(0.0), 10_214, 17),
        (40e6, None, 20_088, 17),
        (50e6, None, 20_279, 18),
    ];
    for (fs, offset, seed, before) in locks {
        let offset = offset
            .unwrap_or_else(|| ChaCha8Rng::seed_from_u64(seed ^ 0xA5A5).random_range(-1.0..=1.0));
        let l = run_lock(fs, offset, 0.25, 80, seed);
        let at = format!("{fs} Hz, {offset:.2} %, seed {seed} (first published {before} before)");
        assert_eq!(l.wrong, 0, "published a frame that was not sent: {at}");
        assert!(
            l.first <= 10 && l.lost == 0,
            "{at}: first published {}, lost {:?}",
            l.first,
            l.which
        );
    }
}

/// Feeds `words` as the firmware does (`tasks/hans_in.rs`): 512-word halves in
/// 64-word chunks, with the halves `from..from + halves` missing (dropped by the
/// load governor): `HansRx::skip` tells the receiver. Returns the events.
fn receive_with_gap(
    words: &[Vec<u16>],
    rx: &mut HansRx,
    from: usize,
    halves: usize,
) -> Vec<RxEvent> {
    const HALF: usize = 512;
    let mut events = Vec::new();
    let len = words[0].len() / HALF * HALF;
    for half in (0..len / HALF).filter(|h| !(from..from + halves).contains(h)) {
        if half == from + halves {
            rx.skip((halves * HALF) as u32, &mut |e| events.push(e));
        }
        for at in (half * HALF..(half + 1) * HALF).step_by(64) {
            let chunks: Vec<&[u16]> = words.iter().map(|w| &w[at..at + 64]).collect();
            rx.push(&chunks, &mut |e| events.push(e));
        }
    }
    events
}

/// Halves dropped mid-stream on the realistic line (±25 % jitter, ±1 % offset,
/// ±2 samples of skew), as the firmware's governor drops them: the receiver coasts
/// across 1..4 missing halves and publishes again within two frames of the first
/// frame wholly after the gap (the line model's sampling phase is random within
/// 200 ns, so "wholly after" is known to a frame), where a fresh receiver, what the
/// firmware started before, needs a hunt and a young lock; and it never publishes a
/// frame that was not sent, or one that lay in the gap. Every mode keeps the lock
/// in every run: the vote and super modes time on their reference channel alone,
/// as normal mode does on its one (54 of the 144 runs relocked, all in those
/// modes, while every eighth frame moved the timing and every delay toward the
/// channels' median: the rate wandered several times one channel's error).
#[test]
fn dropped_halves_are_coasted_across() {
    const HALF: usize = 512;
    let mut rng = ChaCha8Rng::seed_from_u64(66);
    let (mut coasted, mut fresh_total, mut runs) = (0, 0, 0);
    for fs in [37.5e6, 40e6, 50e6] {
        for offset in [-1.0, 0.0, 1.0] {
            let frames = random_frames(208, &mut rng);
            let line = Line {
                fs_hz: fs,
                offset_pct: offset,
                jitter: 0.25,
                skew: std::array::from_fn(|_| rng.random_range(-2.0..=2.0)),
                asym: 0.0,
            };
            let (words, _) = capture(&frames, line, [Fault::None; 5], rng.random());
            // Frame k starts ~200 ns (a 100 ns line delay, ~100 ns of sampling
            // phase) after 1 us + k frame periods, in words.
            let frame_ps = 125.0 * BIT_PS / (1.0 + offset / 100.0);
            let frame_at = |w: f64| (w * 16.0 * 1e12 / fs - 1_000_000.0) / frame_ps;
            for halves in 1..=4 {
                // From the half holding frame ~60 on (settled, past the young fit).
                let from = ((60.0 * frame_ps + 1_000_000.0) * fs / 1e12 / 16.0) as usize / HALF;
                let (g0, g1) = (from * HALF, (from + halves) * HALF);
                let (in_gap, after) = (frame_at(g0 as f64), frame_at(g1 as f64).ceil() as usize);
                for mode in MODES {
                    let at = format!("{fs} Hz {offset} % {halves} halves {mode:?}");
                    let mut rx = HansRx::new(fs.round() as u32, mode).unwrap();
                    let got = published(&receive_with_gap(&words, &mut rx, from, halves));
                    let (_, invented) = score(&frames, &got, LOCK_FRAMES);
                    assert_eq!(invented, 0, "{at}: published frames that were not sent");
                    let idx: Vec<usize> = got
                        .iter()
                        .map(|f| frames.iter().position(|s| s == f).unwrap())
                        .collect();
                    assert!(idx.windows(2).all(|w| w[0] < w[1]), "{at}: order");
                    // Frames surely in the gap (a frame's margin either side).
                    let sure = in_gap.ceil() as usize + 1..after.saturating_sub(1);
                    assert!(!idx.iter().any(|k| sure.contains(k)), "{at}: {idx:?}");
                    let first = *idx.iter().find(|&&k| k + 1 >= after).unwrap();
                    // Every frame after that one arrives (but those cut by the last
                    // whole half)...
                    let end = frame_at((words[0].len() / HALF * HALF) as f64) as usize - 1;
                    let lost = (first..end).filter(|k| !idx.contains(k)).count();
                    assert!(rx.skipped() > 0, "{at}: no period skipped");
                    runs += 1;
                    // ...in every mode: the lock is kept (no relock, which would lose
                    // a hunt and a young lock's frames).
                    assert!(
                        first <= after + 2 && lost <= 1,
                        "{at}: {lost} frames lost, resumed at {first} (first wholly after the gap: {after})"
                    );
                    // What the firmware did before: a fresh receiver after the gap.
                    let mut fresh = HansRx::new(fs.round() as u32, mode).unwrap();
                    let later: Vec<Vec<u16>> = words.iter().map(|w| w[g1..].to_vec()).collect();
                    let again = published(&receive_with_gap(&later, &mut fresh, usize::MAX, 0));
                    let fresh_first = frames
                        .iter()
                        .position(|s| Some(s) == again.first())
                        .unwrap();
                    assert!(
                        fresh_first >= first + 5,
                        "{at}: fresh at {fresh_first}, coasted {first}"
                    );
                    coasted += (first + 1).saturating_sub(after);
                    fresh_total += (fresh_first + 1).saturating_sub(after);
                }
            }
        }
    }
    println!(
        "1..4 dropped halves, ±25 % jitter, {runs} runs, every one coasted: first frame published {:.2} frames after the first one wholly after the gap on average (a fresh receiver: {:.2})",
        coasted as f64 / runs as f64,
        fresh_total as f64 / runs as f64
    );
    // Most runs resume with the frame after that one or the next: the first
    // verified frame after a coast is held until it has re-measured the phase
    // (`Timing::recentring`), and the estimate of the first frame wholly after
    // the gap is a frame off at most.
    assert!(
        coasted <= 3 * runs,
        "{coasted} frames late over {runs} runs"
    );
}

/// Asymmetries measured (fraction of a bit, rising edges late; negative: falling).
const ASYMS: [f64; 11] = [
    0.0, 0.025, -0.025, 0.05, -0.05, 0.1, -0.1, 0.15, -0.15, 0.2, -0.2,
];

/// Line conditions of [`edge_asymmetry`]'s rows: the rate offset (percent, each
/// lock a random one within it) and the edge jitter (fraction of a bit). Every
/// lock also skews the channels within ±2 samples.
const ASYM_LINES: [(&str, f64, f64); 4] = [
    // Crystal clocks: within ±0.02 % of nominal, so at 37.5 and 50 MHz within a
    // few hundred ppm of a whole number of samples a bit (the rounding steps of
    // `shared::hans::rx::confirm::stepped`).
    ("±0.02 %", 0.02, 0.0),
    ("±1 %", 1.0, 0.0),
    ("±1 %, ±20 %", 1.0, 0.2),
    ("±1 %, ±25 %", 1.0, 0.25),
];

/// Asymmetric rising / falling edge delays (`impair::asymmetry`, the same on
/// every channel) against the lines of [`ASYM_LINES`], in normal (one channel)
/// and super mode (five), at 37.5 / 40 / 50 MHz. Prints the frames lost after
/// [`LOCK_FRAMES`] over the locks of each point (each lock its own frames,
/// offset, skew, jitter and sampling phase; the same locks for every asymmetry,
/// so a column differs from the 0 % one by the asymmetry alone), `!` marking a
/// point that published a frame not sent (with `--nocapture`).
///
/// Asserted: no frame that was not sent, at any point. At 40 MHz (the
/// firmware's rate) and 50 MHz, up to ±10 % of a bit (8 ns) and ±20 % jitter:
/// no frame lost beyond the same locks without asymmetry, in both modes
/// (measured with 32 locks a point: none lost; README "Measured figures").
/// Measured only, because they lose frames (README "Known limits"): 37.5 MHz
/// (3x), where a clean line within a few hundred ppm of 3 samples a bit loses
/// good frames from 2.5 % on (rising and falling edges round to samples one
/// apart, and the tail confirmation and `confirm::stepped` take the mixture
/// for a phase error); and ±25 % jitter, where 10 % costs a few frames in 10^3
/// (the asymmetry closes the eye by half its size: a ±25 % line with 10 % is
/// read as if it had ±30 %, and some young locks fail and relock).
#[test]
fn edge_asymmetry() {
    const LOCKS: u64 = 4;
    const N: usize = 80;
    let scored = N - LOCK_FRAMES - 1;
    println!(
        "HANS-100 receiver, rising edges late by a fraction of a bit (negative: falling): frames lost of {LOCKS} locks x {scored} per point"
    );
    print!("{:>29} |", "offset, jitter");
    for a in ASYMS {
        print!("{:>6.1}%", a * 100.0);
    }
    println!();
    for fs in [37.5e6, 40e6, 50e6] {
        for (row, &(name, offset, jitter)) in ASYM_LINES.iter().enumerate() {
            // [mode][asymmetry]: frames lost, wrong frames.
            let mut lost = [[0usize; ASYMS.len()]; 2];
            let mut wrong = [[0usize; ASYMS.len()]; 2];
            for lock in 0..LOCKS {
                let seed = 1000 * row as u64 + lock;
                let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5A5A);
                let frames = random_frames(N, &mut rng);
                let mut line = Line {
                    fs_hz: fs,
                    offset_pct: rng.random_range(-offset..=offset),
                    jitter,
                    skew: std::array::from_fn(|_| rng.random_range(-2.0..=2.0)),
                    asym: 0.0,
                };
                for (k, a) in ASYMS.into_iter().enumerate() {
                    line.asym = a;
                    let (words, _) = capture(&frames, line, [Fault::None; 5], seed);
                    for (m, mode) in [Mode::Normal { channel: 1 }, Mode::Super]
                        .into_iter()
                        .enumerate()
                    {
                        let (events, _) = receive(&words, fs, mode, seed);
                        let (l, w) = score(&frames, &published(&events), LOCK_FRAMES);
                        lost[m][k] += l;
                        wrong[m][k] += w;
                    }
                }
            }
            for (m, mode) in ["normal", "super"].into_iter().enumerate() {
                print!("{:>5.1} MHz {name:>12} {mode:>6} |", fs / 1e6);
                for (k, a) in ASYMS.into_iter().enumerate() {
                    let (l, w) = (lost[m][k], wrong[m][k]);
                    print!("{l:>6}{}", if w > 0 { '!' } else { ' ' });
                    let at = format!("{fs} Hz, {name}, {mode}, {a} bit");
                    assert_eq!(w, 0, "published a frame that was not sent: {at}");
                    // 3x (37.5 MHz) is measured only (see above).
                    let held = f64::abs(a) <= 0.1 && jitter <= 0.2 && fs != 37.5e6;
                    if held {
                        assert!(
                            l <= lost[m][0],
                            "{at}: {l} frames lost, {} without asymmetry",
                            lost[m][0]
                        );
                    }
                }
                println!();
            }
        }
    }
    println!("(no wrong frame at any point)");
}

/// Seed 10627 of [`limits_over_many_locks`] (37.5 MHz, ±25 %, no offset) lost
/// its frame 66 at 640 locks a point: 7 of the 8 checked mid-pair edges of its
/// tail measured a sample early (jitter alone, the timing on the line: both
/// start edges 0.03 bit off), the mean -0.33 bit, beyond a quarter bit, and
/// its only 2 edges between the pairs measured on time and a sample late
/// (+0.13 bit, just beyond the second look's eighth of a bit). Edges between
/// the pairs lying the other way from the mid-pair ones contradict a slip,
/// which moves both groups alike, so the second look bounds them by a quarter
/// bit on that side (`shared::hans::rx::confirm`, `between_pairs`): the lock
/// loses nothing and publishes nothing that was not sent.
#[test]
fn a_tail_whose_edges_between_the_pairs_lie_late_is_kept() {
    let l = run_lock(37.5e6, 0.0, 0.25, 80, 10_627);
    assert_eq!(l.wrong, 0, "published a frame that was not sent");
    assert!(l.lost == 0, "lost {:?}", l.which);
}

/// Locks of [`limits_over_many_locks`] that lost one frame each at 640 locks a
/// point (docs/engineering-log.md 2026-12-03 `tol25`, 2026-12-04 `tolzero`):
/// 4 of the 8 checked mid-pair edges of a tail measured a hair beyond the far
/// bound (5/16 bit) on a jittered line whose record had counted them a hair
/// under it, so the line was clean and the tail rejected as a short
/// excursion: at 4x with the timing a quarter sample off the sampling grid
/// (edges a sample early at 1.249 samples, then 1.251, the bound 1.25), at 3x
/// with a 0.01 % offset (late edges from 0.84..0.90 sample to 0.95, the bound
/// 0.9375). Counted again 1/32 sample beyond the bound on a line that is not
/// steady (`shared::hans::rx::HansRx::recounted`), each lock loses nothing
/// and publishes nothing that was not sent.
#[test]
fn a_tail_whose_far_edges_lie_a_hair_over_the_bound_is_kept() {
    // (fs, jitter, offset: None for the many-locks test's random one, seed,
    // frame lost before)
    let locks = [
        (37.5e6, 0.25, None, 20_587, 24),
        (50e6, 0.2, Some(0.0), 323, 23),
        (50e6, 0.25, Some(0.0), 10_185, 70),
    ];
    for (fs, jitter, offset, seed, before) in locks {
        let offset = offset
            .unwrap_or_else(|| ChaCha8Rng::seed_from_u64(seed ^ 0xA5A5).random_range(-1.0..=1.0));
        let l = run_lock(fs, offset, jitter, 80, seed);
        let at = format!("{fs} Hz, ±{jitter}, {offset:.2} %, seed {seed} (lost {before} before)");
        assert_eq!(l.wrong, 0, "published a frame that was not sent: {at}");
        assert!(l.lost == 0, "{at}: lost {:?}", l.which);
    }
}
