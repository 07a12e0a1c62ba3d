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
            let mut released = Vec::new();
            let t = t0 + (i as u64 + 1) * FP;
            let restart = watch.period(t, &p, |e| match e {
                // Only the held periods, one or two before, are ever released.
                LineEvent::Frame(f) => released.push(f),
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
            out.frames.push(None);
            for f in released {
                place(&mut out.frames, i, t0, f);
            }
            out.good.push(p.all_ok());
        }
    }
    // The stream ends: the last period, if held, goes out once due.
    let end = t0 + out.frames.len() as u64 * FP;
    // Only a good period is ever held.
    assert!(watch.release_due().is_none() || out.good.last() == Some(&true));
    watch.release(end + CONFIRM_NS - 1, |_| panic!("released early"));
    let mut released = Vec::new();
    watch.release(end + CONFIRM_NS, |e| {
        if let LineEvent::Frame(f) = e {
            released.push(f);
        }
    });
    let i = out.frames.len();
    for f in released {
        place(&mut out.frames, i, t0, f);
    }
    assert_eq!(watch.release_due(), None);
    out
}

/// Records frame `f`, released when period `i` came (or after the last, `i` =
/// the count), at the period it stands for: one or two before `i`, told by its X
/// value (the run starts at period `t0 / FP`). Every released frame here has
/// its own X: X is in step, or (`two_lines_one_shifted_also_restarts`) no
/// shifted period of X gets out.
fn place(frames: &mut [Option<ForwardFrame>], i: usize, t0: u64, f: ForwardFrame) {
    let from = (t0 / FP) as usize;
    let x = f.axis(Axis::X).map(|p| p.to_raw(20));
    let back = (1..=2)
        .find(|&d| i >= d && x == Some(value(0, from + i - d)))
        .expect("a released frame is one of the two periods before");
    frames[i - back] = Some(f);
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
    // period forwarded with its own values, but the last one (held for the next
    // period to confirm it, below).
    for i in 2..SLIP - 1 {
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
    // The good period the watch held when the first bad one came is dropped.
    assert_eq!(out.frames[first_bad - 1], None);
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

/// A period with X decoded as `v` (`Some`) or dead (`None`).
fn one_line(v: Option<u32>, end: u32) -> Period {
    use crate::xy3::rx::RxError;
    let mut lines = [None; 5];
    lines[0] = Some(v.map(Frame::Position24).ok_or(RxError::Dead));
    Period { lines, end }
}

/// What the watch emitted for one call: the X values of released frames and the
/// `Dropped` / other faults.
#[derive(Debug, Default, PartialEq)]
struct Emitted {
    frames: Vec<u32>,
    dropped: usize,
    faults: usize,
}

impl Emitted {
    fn sink(&mut self) -> impl FnMut(LineEvent) + '_ {
        |e| match e {
            LineEvent::Frame(f) => self.frames.extend(f.axis(Axis::X).map(|p| p.to_raw(20))),
            LineEvent::Fault {
                line: Line::Framing,
                kind: FaultKind::Dropped,
            } => self.dropped += 1,
            LineEvent::Fault { .. } => self.faults += 1,
        }
    }
}

#[test]
fn a_good_period_waits_for_the_next_to_confirm_it() {
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    let mut e = Emitted::default();
    // The first good period is held: nothing out yet.
    assert!(!w.period(0, &one_line(Some(1), 3), e.sink()));
    assert_eq!(e, Emitted::default());
    assert_eq!(w.release_due(), Some(CONFIRM_NS));
    // A good next one releases it (and is held in turn).
    w.period(FP, &one_line(Some(2), 6), e.sink());
    assert_eq!(e.frames, [1]);
    // A bad next one drops it: a `Dropped` fault, then the bad period's own.
    w.period(2 * FP, &one_line(None, 9), e.sink());
    assert_eq!((e.frames.len(), e.dropped, e.faults), (1, 1, 1));
    assert_eq!(w.release_due(), None);
    // Two chance passes in a row, then the fault shows: the first gets out (the
    // residual), the second is dropped.
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    let mut e = Emitted::default();
    for (k, v) in [Some(7), Some(8), None, None].into_iter().enumerate() {
        w.period(k as u64 * FP, &one_line(v, 3 * k as u32), e.sink());
    }
    assert_eq!((e.frames, e.dropped, e.faults), (vec![7], 1, 2));
}

#[test]
fn the_last_period_goes_out_once_no_period_follows_in_time() {
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    let mut e = Emitted::default();
    // A stream of 5 good periods that stops (its last frame may be a laser-off
    // command): the last one waits CONFIRM_NS from its arrival, not longer.
    for k in 0..5u64 {
        w.period(k * FP, &one_line(Some(k as u32), 3 * k as u32), e.sink());
    }
    assert_eq!(e.frames, [0, 1, 2, 3]);
    let last = 4 * FP;
    assert_eq!(w.release_due(), Some(last + CONFIRM_NS));
    w.release(last + CONFIRM_NS - 1, e.sink());
    assert_eq!(e.frames, [0, 1, 2, 3]);
    w.release(last + CONFIRM_NS, e.sink());
    assert_eq!(e.frames, [0, 1, 2, 3, 4]);
    // Released once only; a later release or bad period has nothing to settle.
    w.release(u64::MAX, e.sink());
    w.period(u64::MAX, &one_line(None, 15), e.sink());
    assert_eq!((e.frames.len(), e.dropped, e.faults), (5, 0, 1));
    // Time going backwards releases nothing (and does not panic).
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    w.period(u64::MAX, &one_line(Some(9), 3), e.sink());
    w.release(0, e.sink());
    assert_eq!(e.frames.len(), 5);
    // A withheld (suspect) good period is never held: nothing to release.
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    for k in 0..u64::from(SUSPECT_BAD) {
        w.period(k * FP, &one_line(None, 0), e.sink());
    }
    w.period(10 * FP, &one_line(Some(1), 0), e.sink());
    assert_eq!(w.release_due(), None);
    assert_eq!(e.dropped, 1);
}

/// The cost on a noisy but in-step line: an isolated bad period also drops the
/// good one before it (2 periods lost, no more); a burst of SUSPECT_BAD withholds
/// a good run after it as before.
#[test]
fn noise_costs_the_period_before_each_bad_one() {
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    let mut e = Emitted::default();
    // One bad period in 50, for 100 000 periods: 2 000 bad, 2 000 dropped.
    let n = 100_000u64;
    for k in 0..n {
        let v = (k % 50 != 49).then_some(k as u32 & 0xF_FFFF);
        assert!(!w.period(k * FP, &one_line(v, 3 * k as u32), e.sink()));
    }
    w.release(n * FP + CONFIRM_NS, e.sink());
    assert_eq!((e.faults, e.dropped), (2_000, 2_000));
    assert_eq!(e.frames.len(), 96_000);
}

/// A period with X as `x` and Y as `y`, ending at `end`.
fn xy(x: Frame, y: Frame, end: u32) -> Period {
    let mut lines = [None; 5];
    lines[0] = Some(Ok(x));
    lines[1] = Some(Ok(y));
    Period { lines, end }
}

#[test]
fn only_the_direct_successor_confirms_a_held_period() {
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    let mut e = Emitted::default();
    w.period(0, &one_line(Some(1), 3), e.sink());
    // A half lost after it (64 bytes): the next good period begins at 67, not 3.
    w.period(FP, &one_line(Some(2), 70), e.sink());
    assert_eq!((e.frames.len(), e.dropped), (0, 1));
    // Its own successor confirms it as usual.
    w.period(2 * FP, &one_line(Some(3), 73), e.sink());
    assert_eq!((e.frames.clone(), e.dropped), (vec![2], 1));
    // A new session counts from 0 again: not a successor either.
    w.period(3 * FP, &one_line(Some(4), 3), e.sink());
    assert_eq!((e.frames.clone(), e.dropped), (vec![2], 2));
    // 32-bit frames are 4 bytes long.
    let p32 = |v, end| {
        let mut p = one_line(None, end);
        p.lines[0] = Some(Ok(Frame::Position32(v)));
        p
    };
    // (26-bit values, read as 20 bits by `Emitted`.)
    w.period(4 * FP, &p32(5 << 6, 7), e.sink());
    w.period(5 * FP, &p32(6 << 6, 11), e.sink());
    w.period(6 * FP, &p32(7 << 6, 16), e.sink());
    assert_eq!((e.frames.clone(), e.dropped), (vec![2, 4, 5], 3));
    // The byte count wraps: 0xFFFF_FFFE + 4 ends at 2.
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    let mut e = Emitted::default();
    w.period(0, &p32(1 << 6, 0xFFFF_FFFE), e.sink());
    w.period(FP, &p32(2 << 6, 2), e.sink());
    assert_eq!((e.frames, e.dropped), (vec![1], 0));
    // Never a gap fault of its own, and nothing is suspect after gaps: they
    // are not bad periods.
    assert!(!w.suspect());
}

#[test]
fn a_last_frame_after_a_gap_still_goes_out_before_the_input_timeout() {
    // A gap (a lost half), a few good periods, then the stream stops with a
    // command on X (a laser-off, say): the period before the gap is dropped,
    // the last one goes out CONFIRM_NS after it came, inside the bridge's
    // 1 ms input timeout (`failsafe.input_timeout_us`).
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    let mut ev = Vec::new();
    w.period(0, &one_line(Some(1), 3), |e| ev.push(e));
    w.period(FP, &one_line(Some(2), 70), |e| ev.push(e));
    w.period(2 * FP, &one_line(Some(3), 73), |e| ev.push(e));
    let mut off = one_line(None, 76);
    off.lines[0] = Some(Ok(Frame::Command24(0x4_0000)));
    let last = 3 * FP;
    w.period(last, &off, |e| ev.push(e));
    assert_eq!(w.release_due(), Some(last + CONFIRM_NS));
    let timeout = u64::from(crate::bridge::Config::default().failsafe.input_timeout_us) * 1000;
    assert!(last + CONFIRM_NS < last + timeout);
    w.release(last + CONFIRM_NS - 1, |e| ev.push(e));
    // Dropped (the period before the gap), then the frames 2 and 3.
    assert_eq!(ev.len(), 3);
    assert_eq!(ev[0], dropped());
    w.release(last + CONFIRM_NS, |e| ev.push(e));
    assert!(
        matches!(ev[3], LineEvent::Frame(f) if f.command.is_some()),
        "{ev:?}"
    );
    assert_eq!(ev.len(), 4);
}

#[test]
fn a_command_on_another_line_needs_the_same_on_x() {
    let (p, c) = (Frame::Position24, Frame::Command24);
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    let mut e = Emitted::default();
    // Conforming periods: positions, a command on X alone or repeated on Y.
    let ok = [
        xy(p(1), p(2), 3),
        xy(c(0xA_0000), p(3), 6),
        xy(c(0xA_0000), c(0xA_0000), 9),
        xy(p(4), p(5), 12),
    ];
    for (k, q) in ok.iter().enumerate() {
        w.period(k as u64 * FP, q, e.sink());
    }
    w.release(u64::MAX, e.sink());
    // (Command periods carry no X position: 2 of the 4 frames have one.)
    assert_eq!((e.frames, e.dropped, e.faults), (vec![1, 4], 0, 0));
    // A command on Y under a position on X, or another command than X's: the
    // held period before it and the period itself are withheld, and it is a
    // bad period (3 make the session suspect).
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    let mut e = Emitted::default();
    let stray = [
        xy(p(1), p(2), 3),
        xy(p(6), c(0x4_0000), 6),
        xy(c(0x2_0000), c(0x4_0000), 9),
        xy(p(7), c(0x1_0000), 12),
    ];
    for (k, q) in stray.iter().enumerate() {
        w.period(k as u64 * FP, q, e.sink());
    }
    assert!(w.suspect());
    w.period(4 * FP, &xy(p(8), p(9), 15), e.sink());
    w.release(u64::MAX, e.sink());
    assert_eq!((e.frames, e.dropped, e.faults), (vec![], 5, 0));
}

/// The periods of 24-bit `bytes` (one slice per line of `lines`) through a new
/// receiver, a period's bytes and its end at a time.
fn periods_of(lines: Lines, bytes: &[Vec<u8>]) -> Vec<Period> {
    let mut rx = Receiver::new(lines);
    let mut out = Vec::new();
    for i in 0..bytes[0].len() / 3 {
        let part: Vec<&[u8]> = bytes.iter().map(|b| &b[3 * i..3 * i + 3]).collect();
        rx.push_bytes(&part).unwrap();
        rx.push_ends(&[3 * (i as u32 + 1)]);
        out.extend(core::iter::from_fn(|| rx.poll()));
    }
    out
}

/// A line a whole byte late (an SPI that drops partial bytes saw 9 extra
/// edges) whose first shifted period passes by chance, then a gap: the input
/// session restarts (in step) right after it. The new session's first period
/// follows no held one, so the wrong period is dropped, not confirmed.
#[test]
fn a_chance_pass_before_a_gap_is_dropped() {
    const N: usize = 40;
    let lines = Lines::new(&[Axis::X, Axis::Y, Axis::Z]).unwrap();
    // The first slip period (from 10 on) at which Y, one byte late, passes
    // its check with a position frame (about one in 16).
    let shifted = |k: usize| -> Vec<Vec<u8>> {
        (0..3)
            .map(|l| {
                let mut b = line_bytes(l, 0, k + 1, None);
                if l == 1 {
                    b.insert(3 * k, 0x5A);
                    b.truncate(3 * (k + 1));
                }
                b
            })
            .collect()
    };
    let (k, periods) = (10..400)
        .find_map(|k| {
            let periods = periods_of(lines, &shifted(k));
            let p = periods.last()?;
            let y_ok = matches!(p.lines[1], Some(Ok(Frame::Position24(v))) if v != value(1, k));
            (p.all_ok() && y_ok).then_some((k, periods))
        })
        .expect("a chance pass");
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    let mut ev = Vec::new();
    let mut sink = |e| ev.push(e);
    for (i, p) in periods.iter().enumerate() {
        w.period(i as u64 * FP, p, &mut sink);
    }
    // The slip period is held.
    assert!(w.release_due().is_some());
    // The new session (all lines in step, counting from 0) from period k + 30.
    let from = k + 30;
    let again: Vec<Vec<u8>> = (0..3).map(|l| line_bytes(l, from, N, None)).collect();
    for (i, p) in periods_of(lines, &again).iter().enumerate() {
        w.period((from + i) as u64 * FP, p, &mut sink);
    }
    w.release(u64::MAX, &mut sink);
    // The wrong Y of period k never went out; the new session's all did.
    let frames: Vec<Option<u32>> = ev
        .iter()
        .filter_map(|e| match e {
            LineEvent::Frame(f) => Some(y(f)),
            _ => None,
        })
        .collect();
    assert_eq!(ev.iter().filter(|&&e| e == dropped()).count(), 1);
    let want: Vec<Option<u32>> = (0..k)
        .chain(from..from + N)
        .map(|i| Some(value(1, i)))
        .collect();
    assert_eq!(frames, want);
}

/// Hand-made periods of a line that slipped a whole byte (an SPI dropping
/// partial bytes missed edges in period 1 and delivered 2 bytes for it): from
/// then on Y reads the last two bytes of its own frame and the first byte of
/// the next, and these values make it pass its check (first bit 0, position,
/// parity) in the listed periods anyway. Each row: Y's sent values, the
/// periods whose shifted Y passes, the periods whose wrong Y the watch still
/// forwards. Without [`CONFIRM_OPEN`] (one successor confirms, as before) the
/// first row forwarded period 2 and the second periods 2 and 3: the first bad
/// period opened the window, but [`SUSPECT_BAD`] was not reached yet.
#[test]
fn chance_passes_in_an_open_window_need_two_successors() {
    type Row = ([u32; 6], &'static [usize], &'static [usize]);
    const ROWS: [Row; 2] = [
        // Two chance passes in a row after the slip period.
        (
            [0x8023f, 0x3d0fc, 0x09cd6, 0xb1373, 0x62af6, 0xe255f],
            &[0, 2, 3],
            &[],
        ),
        // Three in a row: the first gets out (the residual, one in 8^3 after a
        // slip for random 24-bit data).
        (
            [0xb019e, 0x93e45, 0x956fa, 0xb1b2a, 0xf170e, 0x73a1b],
            &[0, 2, 3, 4],
            &[2],
        ),
    ];
    let lines = Lines::new(&[Axis::X, Axis::Y]).unwrap();
    for (k, (ys, passing, forwarded)) in ROWS.iter().enumerate() {
        let bytes_of = |vals: &mut dyn Iterator<Item = u32>| -> Vec<u8> {
            vals.flat_map(|v| {
                let (w, _) = encode(&Frame::Position24(v)).unwrap();
                w.to_be_bytes().into_iter().skip(1)
            })
            .collect()
        };
        let x = bytes_of(&mut (0..6).map(|i| value(0, i)));
        let mut shifted = bytes_of(&mut ys.iter().copied());
        // Period 1 loses its last byte; the stream is one byte early after it.
        shifted.remove(3 + 2);
        shifted.push(0);
        let periods = periods_of(lines, &[x, shifted]);
        assert_eq!(periods.len(), 6, "row {k}");
        // The receiver passes these periods, with a wrong Y after the slip.
        let pass: Vec<usize> = (0..6).filter(|&i| periods[i].all_ok()).collect();
        assert_eq!(pass, *passing, "row {k}");
        for &i in passing.iter().skip(1) {
            assert!(
                matches!(periods[i].lines[1], Some(Ok(Frame::Position24(v))) if v != ys[i]),
                "row {k}: {i}"
            );
        }
        let mut w = StepWatch::new(OUT_OF_STEP_NS);
        let mut out: Vec<u32> = Vec::new();
        for (i, p) in periods.iter().enumerate() {
            w.period(i as u64 * FP, p, |e| {
                if let LineEvent::Frame(f) = e {
                    out.extend(y(&f));
                }
            });
        }
        w.release(u64::MAX, |e| {
            if let LineEvent::Frame(f) = e {
                out.extend(y(&f));
            }
        });
        // Only the listed wrong ones go out (period 0, in step, is dropped by
        // the bad period 1 after it).
        let mut want = Vec::new();
        for &i in *forwarded {
            assert!(matches!(periods[i].lines[1], Some(Ok(Frame::Position24(v))) if v != ys[i]));
            if let Some(Ok(Frame::Position24(v))) = periods[i].lines[1] {
                want.push(v);
            }
        }
        assert_eq!(out, want, "row {k}");
    }
}

/// The two-successor rule's mechanics: inside an open window a good period
/// waits for two good direct successors, a bad one drops every held period,
/// and a stream that stops lets them all out (oldest first) once the newest
/// has waited [`CONFIRM_NS`]; once a good run closes the window, one successor
/// confirms again.
#[test]
fn an_open_window_holds_a_period_for_two_successors() {
    let mut w = StepWatch::new(OUT_OF_STEP_NS);
    let mut e = Emitted::default();
    // Time and end position of the last period.
    let mut at = (0, 0);
    fn feed(w: &mut StepWatch, e: &mut Emitted, at: &mut (u64, u32), v: Option<u32>) {
        *at = (at.0 + FP, at.1 + 3);
        w.period(at.0, &one_line(v, at.1), e.sink());
    }
    // In step: 1 goes out when 2 comes.
    feed(&mut w, &mut e, &mut at, Some(1));
    feed(&mut w, &mut e, &mut at, Some(2));
    assert_eq!(e.frames, [1]);
    // A bad period drops 2 and opens the window.
    feed(&mut w, &mut e, &mut at, None);
    assert_eq!((e.dropped, e.faults), (1, 1));
    // 3 waits for 4 and 5.
    feed(&mut w, &mut e, &mut at, Some(3));
    feed(&mut w, &mut e, &mut at, Some(4));
    assert_eq!(e.frames, [1]);
    feed(&mut w, &mut e, &mut at, Some(5));
    assert_eq!(e.frames, [1, 3]);
    // A bad one drops both waiting (4 and 5).
    feed(&mut w, &mut e, &mut at, None);
    assert_eq!((e.frames.len(), e.dropped, e.faults), (2, 3, 2));
    // The stream stops after 6, 7: both out, in order, CONFIRM_NS after 7.
    feed(&mut w, &mut e, &mut at, Some(6));
    feed(&mut w, &mut e, &mut at, Some(7));
    assert_eq!(e.frames, [1, 3]);
    assert_eq!(w.release_due(), Some(at.0 + CONFIRM_NS));
    w.release(at.0 + CONFIRM_NS - 1, e.sink());
    assert_eq!(e.frames, [1, 3]);
    w.release(at.0 + CONFIRM_NS, e.sink());
    assert_eq!(e.frames, [1, 3, 6, 7]);
    assert_eq!(w.release_due(), None);
    // 6 and 7 began a good run; 15 makes it GOOD_RUN long and closes the
    // window. Before it each period went out two periods late, 14 waits for
    // 15 and 16, and 15 for 16 only.
    assert_eq!(GOOD_RUN, 8);
    for v in 10..=15 {
        feed(&mut w, &mut e, &mut at, Some(v));
    }
    assert_eq!(e.frames.last(), Some(&13));
    feed(&mut w, &mut e, &mut at, Some(16));
    assert_eq!(e.frames[e.frames.len() - 2..], [14, 15]);
    feed(&mut w, &mut e, &mut at, Some(17));
    assert_eq!(e.frames.last(), Some(&16));
    assert_eq!(e.dropped, 3);
}
