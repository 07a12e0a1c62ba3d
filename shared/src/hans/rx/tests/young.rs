//! The young lock's precision ([`timing::YOUNG`], [`phase`]): on ±25 % jittered
//! lines with rate offsets, how far the timing is from the line while the fit
//! times it, when the alpha-beta filter takes over, and over the frames after.

use super::gap::Stream;
use super::*;

/// Errors of one lock against the true line, in bits (rate: bits a frame).
#[derive(Clone, Copy, Default, Debug)]
struct Errors {
    /// Worst phase error across a frame (its start and its end) over the
    /// published young frames: from `timing::SETTLED` to 16, and from 16 to
    /// `timing::YOUNG`.
    young: (f64, f64),
    /// Phase and rate error when the filter takes over.
    handover: (f64, f64),
    /// Worst phase error across a frame over the 120 frames after.
    after: f64,
}

/// Runs a normal-mode receiver over `s` (true rate `ratio` samples a bit) and
/// measures its timing against the line at every change.
fn measure(s: &Stream, hz: u32, ratio: f64) -> Errors {
    let mut rx = HansRx::new(hz, Mode::Normal { channel: 1 }).unwrap();
    let mut e = Errors::default();
    let (mut count, mut last) = (0usize, (0u32, 0i32));
    let mut lock_frame = None;
    let mut handed = false;
    for part in s.words.chunks(4) {
        rx.push(&[part; 5], &mut |_| {});
        count += part.len();
        let t = rx.timing;
        if !rx.locked || (t.start, t.period) == last {
            continue;
        }
        last = (t.start, t.period);
        let delay = rx.channels[rx.reference].delay.unwrap_or(0);
        let at = (count * 16) as f64
            + f64::from(diff(
                t.start.wrapping_add(delay as u32),
                (count as u32) << 20,
            )) / 65536.0;
        let frame = ((at / ratio + s.phase) / 125.0).round();
        let truth = |f: f64| (f * 125.0 - s.phase) * ratio;
        let period = f64::from(t.period) / 65536.0;
        let e0 = (at - truth(frame)) / ratio;
        let e1 = (at + period - truth(frame + 1.0)) / ratio;
        let worst = e0.abs().max(e1.abs());
        let age = frame - *lock_frame.get_or_insert(frame);
        if t.young() {
            assert!(!handed, "young again after the handover");
            if age >= 16.0 {
                e.young.1 = e.young.1.max(worst);
            } else if age >= f64::from(timing::SETTLED) {
                e.young.0 = e.young.0.max(worst);
            }
        } else if !handed {
            handed = true;
            e.handover = (e0, (period - 125.0 * ratio) / ratio);
        } else if age < f64::from(timing::YOUNG) + 120.0 {
            e.after = e.after.max(worst);
        }
    }
    assert!(handed, "never settled");
    e
}

/// Prints the distribution of the errors over many locks (240 a rate) at the
/// spec's ±25 % jitter and ±1 % offset, and bounds them. Measured with the fit on
/// every pair throughout (before `timing::DENSE`), in bits, at 37.5 / 40 / 50 MHz:
/// young worst 0.077 / 0.119 / 0.042, handover rate rms 0.00042 / 0.00039 /
/// 0.00034 a frame, worst after 0.067 / 0.041 / 0.036; with every other pair
/// after the first frames 0.077 / 0.119 / 0.058, 0.00048 / 0.00045 / 0.00040,
/// 0.061 / 0.042 / 0.044; with every fourth pair the rate was 0.00063 / 0.00060 /
/// 0.00055 (and a coast across dropped halves at 37.5 MHz +1 % resumed 12
/// frames late, host test `dropped_halves_are_coasted_across`). With one solve
/// a frame and the last 8 pairs taken from the tail (27 even pairs measured,
/// `timing::DENSE`): young worst 0.077 / 0.119 / 0.060 (from frame 16 0.055 /
/// 0.048 / 0.042, was 0.058 / 0.050 / 0.042), handover phase rms 0.0123 /
/// 0.0087 / 0.0079 (was 0.0126 / 0.0091 / 0.0084), rate rms 0.00050 / 0.00047
/// / 0.00041, worst after 0.059 / 0.044 / 0.041; one solve alone changed no
/// figure by more than 0.0001. Every fourth pair before the tail from
/// `DENSE` to 8 frames before the handover: young from frame 16 0.068 / 0.053
/// / 0.046, rate rms 0.00053 / 0.00049 / 0.00044 (not taken: see
/// `Timing::learn`).
#[test]
fn young_fit_precision() {
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let max = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for (hz, nominal) in [(37_500_000, 3.0), (40_000_000, 3.2), (50_000_000, 4.0)] {
        let (mut early, mut young, mut phase, mut rate, mut after) =
            (vec![], vec![], vec![], vec![], vec![]);
        for offset in [-0.01, 0.0, 0.01] {
            let ratio = nominal / (1.0 + offset);
            for seed in 1..=80u32 {
                let s = Stream::new(180, seed, ratio, 0.1 + f64::from(seed % 40) * 0.023, 0.25);
                let e = measure(&s, hz, ratio);
                early.push(e.young.0);
                young.push(e.young.1);
                phase.push(e.handover.0);
                rate.push(e.handover.1);
                after.push(e.after);
            }
        }
        println!(
            "{hz} Hz: young worst {:.3} (rms {:.3}) / {:.3} (rms {:.3}); handover phase rms {:.4} max {:.4}, \
             rate rms {:.5} max {:.5} bit/frame; after worst {:.3} (rms {:.3})",
            max(&early),
            rms(&early),
            max(&young),
            rms(&young),
            rms(&phase),
            max(&phase),
            rms(&rate),
            max(&rate),
            max(&after),
            rms(&after),
        );
        // Half a bit less the ±25 % jitter leaves a quarter bit; from ~0.15 bit
        // off a jittered pair read a bit early passes every check now and then
        // (`timing::RECENTRE`).
        assert!(max(&young) < 0.15 && max(&early) < 0.15, "{hz} Hz: young");
        assert!(max(&after) < 0.1, "{hz} Hz: after");
        assert!(rms(&rate) < 6e-4, "{hz} Hz: rate {}", rms(&rate));
    }
}

/// Pins a known flaw (issue 4, open): a young lock that has not settled does not
/// check its frames' tails (`HansRx::confirmed`), so it measures none, yet its
/// confirmation's `sum` of 0 is stored as the timing's tail, and a dense young
/// fit (`timing::DENSE`) then takes that frame's last 8 pairs as
/// `Points::tail(0)`: 8 points at a deviation no edge showed (`Timing::learn`),
/// instead of measuring them. The far/off-edge record (`Timing::clean`,
/// `Timing::steady`) is not touched: it counts only measured tails. Keeping the
/// unmeasured tail out (`measured.tail.and(measured.sum)`) improved the young
/// fit's early worst phase error but lost 2 good frames at 3.0003x +2.5 %
/// (`rounding::ASYM_KNOWN_LOST`), so it was not kept (docs/engineering-log.md,
/// 2026-12-03). On ±25 % jittered lines at 3x with rate offsets, every
/// unsettled timing after a verified frame holds exactly `Some(0)`, and the
/// dense fit learns frames with it: when this fails, the flaw is fixed (or
/// moved) and this test must become its guard (the tail `None`).
#[test]
fn a_young_lock_learns_a_tail_it_did_not_measure() {
    let mut dense_learned = 0;
    for (seed, offset) in (1..=12u32).zip([-0.01, 0.0, 0.01].into_iter().cycle()) {
        let ratio = 3.0 / (1.0 + offset);
        let s = Stream::new(40, seed, ratio, 0.1 + f64::from(seed) * 0.07, 0.25);
        let mut rx = HansRx::new(37_500_000, Mode::Normal { channel: 1 }).unwrap();
        let mut last = None;
        for part in s.words.chunks(4) {
            rx.push(&[part; 5], &mut |_| {});
            let t = rx.timing;
            if !rx.locked || t.settled() {
                last = None;
                continue;
            }
            let points = t.fit_points();
            if let (Some(before), Some(now)) = (last, points) {
                // More than the held start edge: the frame verified and its
                // mid-pair edges were learned, with the tail it left.
                if now > before + 1 {
                    assert_eq!(t.tail, Some(0), "seed {seed}: {t:?}");
                    if before >= timing::DENSE {
                        dense_learned += 1;
                    }
                }
            }
            last = points;
        }
    }
    assert!(dense_learned >= 24, "{dense_learned}");
}
