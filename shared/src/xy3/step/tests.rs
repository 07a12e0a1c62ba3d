//! The watch on a real receiver with one line shifted by a bit mid-stream, and its
//! timing rules (limit, proof of flowing bytes, backoff).

use super::*;
use crate::model::{Axis, FaultKind, ForwardFrame, Line, LineEvent};
use crate::xy3::rx::{Lines, Receiver};
use crate::xy3::{encode, Frame};

/// Frame period, ns (100 kHz).
const FP: u64 = 10_000;

/// Line `l`'s 24-bit position frame in period `i`.
fn value(l: usize, i: usize) -> u32 {
    ((i as u32).wrapping_mul(7919) ^ (l as u32) << 17) & 0xF_FFFF
}

/// The bytes of `periods` 24-bit frames on line `l`, from period `from`; with
/// `slip_at = Some(k)`, one extra bit (a glitch edge on this line's SPI only) enters
/// at the start of period `k`, so every later bit arrives one place late while the
/// byte count stays the same.
fn line_bytes(l: usize, from: usize, periods: usize, slip_at: Option<usize>) -> Vec<u8> {
    let mut bits = Vec::new();
    for i in from..from + periods {
        if slip_at == Some(i) {
            bits.push(true);
        }
        let (word, _) = encode(&Frame::Position24(value(l, i))).unwrap();
        bits.extend((0..24).rev().map(|b| word >> b & 1 != 0));
    }
    bits.truncate(periods * 24);
    bits.chunks(8)
        .map(|c| c.iter().fold(0u8, |b, &bit| b << 1 | u8::from(bit)))
        .collect()
}

/// What came out of [`run`].
struct Out {
    /// Per period: the frame event, if one was emitted.
    frames: Vec<Option<ForwardFrame>>,
    /// Per period: whether every line decoded.
    good: Vec<bool>,
    /// The period that asked for a restart.
    restart: Option<usize>,
    /// `Resync` / withheld (`Dropped` on `Framing`) events.
    resyncs: usize,
    withheld: usize,
}

/// Runs `lines` (all the same length) through a fresh receiver in 60-byte chunks,
/// period `i` ending at time `t0 + (i + 1) * FP`, and the watch on every period.
fn run(lines: &[Vec<u8>], t0: u64, watch: &mut StepWatch) -> Out {
    let axes = [Axis::X, Axis::Y, Axis::Z];
    let mut rx = Receiver::new(Lines::new(&axes[..lines.len()]).unwrap());
    let n = lines[0].len();
    let mut out = Out {
        frames: Vec::new(),
        good: Vec::new(),
        restart: None,
        resyncs: 0,
        withheld: 0,
    };
    for start in (0..n).step_by(60) {
        let end = (start + 60).min(n);
        let part: Vec<&[u8]> = lines.iter().map(|l| &l[start..end]).collect();
        rx.push_bytes(&part).unwrap();
        let ends: Vec<u32> = (start / 3 + 1..=end / 3).map(|k| 3 * k as u32).collect();
        rx.push_ends(&ends);
        while let Some(p) = rx.poll() {
            let i = out.frames.len();
            let mut frame = None;
            let t = t0 + (i as u64 + 1) * FP;
            let restart = watch.period(t, &p, |e| match e {
                LineEvent::Frame(f) => frame = Some(f),
                LineEvent::Fault {
                    line: Line::Framing,
                    kind: FaultKind::Resync,
                } => out.resyncs += 1,
                LineEvent::Fault {
                    line: Line::Framing,
                    kind: FaultKind::Dropped,
                } => out.withheld += 1,
                LineEvent::Fault { .. } => {}
            });
            if restart && out.restart.is_none() {
                out.restart = Some(i);
            }
            out.frames.push(frame);
            out.good.push(p.all_ok());
        }
    }
    out
}

/// The 20-bit Y value of a frame.
fn y(f: &ForwardFrame) -> Option<u32> {
    f.axis(Axis::Y).map(|p| p.to_raw(20))
}

#[test]
fn a_line_shifted_by_a_bit_restarts_the_session() {
    const SLIP: usize = 300;
    const N: usize = 1000;
    let mut watch = StepWatch::new(OUT_OF_STEP_NS);
    // Y slips by one bit at period 300; X and Z stay in step.
    let lines: Vec<Vec<u8>> = (0..3)
        .map(|l| line_bytes(l, 0, N, (l == 1).then_some(SLIP)))
        .collect();
    let out = run(&lines, 0, &mut watch);
    assert_eq!(out.frames.len(), N);
    // In step until the slip (the first two periods lock the bit offset): every
    // period forwarded with its own values.
    for i in 2..SLIP {
        assert_eq!(out.frames[i].as_ref().and_then(y), Some(value(1, i)), "{i}");
    }
    // After the slip the shifted Y passes its check now and then, with a wrong
    // value: the receiver alone would deliver those periods.
    let passing = out.good[SLIP + 1..].iter().filter(|&&g| g).count();
    let wrong: Vec<usize> = (SLIP..N)
        .filter(|&i| {
            out.frames[i]
                .as_ref()
                .is_some_and(|f| y(f) != Some(value(1, i)))
        })
        .collect();
    println!(
        "one line a bit out of step: {passing} of {} periods pass the checks \
         (wrong Y); forwarded with the watch: {}",
        N - SLIP - 1,
        wrong.len()
    );
    assert!(passing > 20, "{passing}");
    // With the watch only those before the session became suspect go out (the
    // receiver's residual risk, `rx` docs), here none.
    assert!(wrong.iter().all(|&i| i < SLIP + 8), "{wrong:?}");
    assert!(wrong.len() <= 2, "{wrong:?}");
    // The restart comes once the window is 2 ms (200 periods) old.
    let first_bad = out.good.iter().skip(2).position(|g| !g).unwrap() + 2;
    assert!((SLIP..=SLIP + 1).contains(&first_bad), "{first_bad}");
    assert_eq!(out.restart, Some(first_bad + 200));
    // This run goes on without restarting: the next request comes after twice the
    // limit (backoff), 401 periods later.
    assert_eq!(out.resyncs, 2);
    assert_eq!(watch.limit_ns(), 4 * OUT_OF_STEP_NS);
    assert!(out.withheld >= passing - wrong.len() - 1);
    // The restarted session (all SPIs started together again) is in step: after
    // the two lock periods and a good run every period is forwarded with its own
    // values, and no further restart.
    let from = first_bad + 205;
    let again: Vec<Vec<u8>> = (0..3).map(|l| line_bytes(l, from, 400, None)).collect();
    let out = run(&again, (from as u64) * FP, &mut watch);
    assert_eq!((out.restart, out.resyncs), (None, 0));
    // Still suspect from the old session: good periods are withheld until a good
    // run closes the window (the run may have begun in the old session's last
    // periods), then every period goes out with its own values.
    assert!(out.good.iter().all(|&g| g));
    let first = out.frames.iter().position(Option::is_some).unwrap();
    assert!((1..usize::from(GOOD_RUN)).contains(&first), "{first}");
    assert_eq!(out.withheld, first);
    for i in first..400 {
        assert_eq!(out.frames[i].as_ref().and_then(y), Some(value(1, from + i)));
    }
    assert_eq!(watch.limit_ns(), OUT_OF_STEP_NS);
}

#[test]
fn two_lines_one_shifted_also_restarts() {
    let mut watch = StepWatch::new(OUT_OF_STEP_NS);
    let lines: Vec<Vec<u8>> = (0..2)
        .map(|l| line_bytes(l, 0, 600, (l == 0).then_some(100)))
        .collect();
    let out = run(&lines, 0, &mut watch);
    assert!(out.good[2..100].iter().all(|&g| g));
    let r = out.restart.expect("no restart");
    assert!((300..=302).contains(&r), "{r}");
}

#[test]
fn sporadic_noise_passes_a_burst_costs_a_good_run_a_pause_does_not_restart() {
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    // One bad period in GOOD_RUN + 1: every good period passes, never a restart.
    let every = u64::from(GOOD_RUN) + 1;
    for i in 0..10_000u64 {
        let good = i % every != 0;
        assert_eq!(w.outcome(i * FP, good), (good, false), "{i}");
    }
    // A burst of 5 bad periods: the next GOOD_RUN - 1 good ones are withheld.
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    for i in 0..5 {
        assert_eq!(w.outcome(i * FP, false), (false, false));
    }
    let passed: Vec<bool> = (5..20).map(|i| w.outcome(i * FP, true).0).collect();
    let held = usize::from(GOOD_RUN) - 1;
    assert!(passed[..held].iter().all(|p| !p) && passed[held..].iter().all(|&p| p));
    // A few bad periods, then the controller stops for a second: a restart would
    // not help a silent line, so none is asked for, even at the next bad period.
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    for i in 0..(u64::from(MIN_BAD_PERIODS) - 2) {
        assert_eq!(w.outcome(i * FP, false), (false, false));
    }
    assert_eq!(w.outcome(1_000_000_000, false), (false, false));
    // The next one is the 16th bad period, a second after the first: due.
    assert_eq!(w.outcome(1_000_000_000 + FP, false), (false, true));
}

#[test]
fn restarts_that_do_not_help_back_off_and_a_good_run_resets() {
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    // A dead line: bad periods for ever. Restarts at 2, then 4, 8, ... ms after
    // the previous one, the limit capped at 2 ms * 2^MAX_BACKOFF.
    let mut t = 0u64;
    let mut restarts = Vec::new();
    while t < 2_000_000_000 {
        if w.outcome(t, false).1 {
            restarts.push(t);
        }
        t += FP;
    }
    // Each gap is the limit plus the one period that opens the next window.
    let gaps: Vec<u64> = restarts.windows(2).map(|p| p[1] - p[0] - FP).collect();
    assert_eq!(restarts[0], OUT_OF_STEP_NS);
    let ms: Vec<u64> = gaps.iter().map(|g| g / 1_000_000).collect();
    assert_eq!(&ms[..6], &[4, 8, 16, 32, 64, 128]);
    assert!(ms[6..].iter().all(|&g| g == 128), "{ms:?}");
    assert_eq!(w.limit_ns(), OUT_OF_STEP_NS << MAX_BACKOFF);
    // Good periods short of a run change nothing; a run resets the limit.
    for k in 1..=GOOD_RUN {
        assert!(w.suspect() == (k < GOOD_RUN) || k == GOOD_RUN);
        let (pass, restart) = w.outcome(t, true);
        assert!(!restart);
        assert_eq!(pass, k == GOOD_RUN, "{k}");
    }
    assert_eq!(w.limit_ns(), OUT_OF_STEP_NS);
    assert!(!w.suspect());
    // Time going backwards (never in use) counts as no time passed: no panic, no
    // restart.
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    for _ in 0..100 {
        assert!(!w.outcome(u64::MAX, false).1);
        assert!(!w.outcome(0, false).1);
    }
}
