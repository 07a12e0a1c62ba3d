//! The governor against a model of the firmware's decoder loop: halves arrive every
//! half period into a queue that drops the newest half when full (`HANS_INPUT`), the
//! decoder takes the oldest, asks the governor, pauses / drops / decodes for a given
//! cost. The checks are the module's guarantee over every window, no pause or drop
//! under budget, and the age bound.

use super::*;
use proptest::prelude::*;
use std::collections::VecDeque;
use std::vec::Vec;

/// Half period of the model: 205 us in 1 us ticks, as in the firmware.
const T: u64 = 205;

/// The firmware's limits (`firmware/tasks/governor.rs`): 90 %, burst half a half
/// period, halves up to two half periods old, optional work refused for at most
/// eight half periods.
fn limits() -> Limits {
    Limits {
        half: T,
        share_permille: 900,
        burst: T / 2,
        max_age: 2 * T,
        optional_gap: 8 * T,
    }
}

/// What one run of the model did.
#[derive(Debug, Default)]
struct Run {
    /// Busy intervals `[start, end)` in time order.
    busy: Vec<(u64, u64)>,
    /// Halves decoded / dropped by the governor / lost on the full queue.
    decoded: usize,
    dropped: usize,
    lost: usize,
    /// Pause steps, and the time spent in them.
    pauses: usize,
    paused: u64,
    /// Time from a half being complete to the start of its decode, per decoded half.
    ages: Vec<u64>,
    /// Time the model ran.
    end: u64,
}

/// Runs the decoder loop on `halves` input halves with queue depth `depth`; `cost(n)`
/// is the busy time of the n-th decode. `governed = false` decodes everything (the
/// checker must catch that).
fn run(
    limits: Limits,
    depth: usize,
    halves: u64,
    governed: bool,
    mut cost: impl FnMut(usize) -> u64,
) -> Run {
    let mut gov = Governor::new(limits).expect("valid limits");
    let mut out = Run::default();
    let mut queue: VecDeque<u64> = VecDeque::new();
    // Half n is complete at (n + 1) * T.
    let mut next_ready = T;
    let mut t = 0u64;
    let last_ready = halves * T;
    let fill = |t: u64, queue: &mut VecDeque<u64>, next_ready: &mut u64, lost: &mut usize| {
        while *next_ready <= t && *next_ready <= last_ready {
            if queue.len() < depth {
                queue.push_back(*next_ready);
            } else {
                *lost += 1;
            }
            *next_ready += T;
        }
    };
    loop {
        fill(t, &mut queue, &mut next_ready, &mut out.lost);
        let Some(ready) = queue.pop_front() else {
            if next_ready > last_ready {
                break;
            }
            t = next_ready;
            continue;
        };
        loop {
            let step = if governed {
                gov.next(t, Class::Essential, ready)
            } else {
                Step::Decode
            };
            match step {
                Step::Pause { until } => {
                    assert!(until > t, "a pause must move time on");
                    out.pauses += 1;
                    out.paused += until - t;
                    t = until;
                    fill(t, &mut queue, &mut next_ready, &mut out.lost);
                }
                Step::Drop => {
                    out.dropped += 1;
                    break;
                }
                Step::Decode => {
                    let b = cost(out.decoded);
                    out.ages.push(t - ready);
                    out.busy.push((t, t + b));
                    t += b;
                    gov.spent(Class::Essential, b);
                    out.decoded += 1;
                    break;
                }
            }
        }
    }
    out.end = t;
    out
}

/// Busy time within `[from, to)`.
fn busy_in(busy: &[(u64, u64)], from: u64, to: u64) -> u64 {
    busy.iter()
        .map(|&(s, e)| e.min(to).saturating_sub(s.max(from)))
        .sum()
}

/// The most busy time any window of length `w` holds. The maximum is reached with
/// the window starting at a busy start or ending at a busy end, so only those are
/// tried (prefix sums keep it fast).
fn max_busy_in_window(busy: &[(u64, u64)], w: u64) -> u64 {
    let mut prefix = Vec::with_capacity(busy.len() + 1);
    prefix.push(0u64);
    for &(s, e) in busy {
        prefix.push(prefix.last().copied().unwrap_or(0) + (e - s));
    }
    // Busy time in [0, x).
    let upto = |x: u64| -> u64 {
        let i = busy.partition_point(|&(s, _)| s < x);
        let whole = prefix[i];
        // The interval starting before x may end after it.
        match i.checked_sub(1).and_then(|j| busy.get(j)) {
            Some(&(s, e)) if e > x => whole - (e - s) + (x - s),
            _ => whole,
        }
    };
    let mut best = 0;
    for &(s, e) in busy {
        best = best.max(upto(s + w) - upto(s));
        let from = e.saturating_sub(w);
        best = best.max(upto(e) - upto(from));
    }
    best
}

/// The module's bound for a window of length `w`: `share * w + burst + (1 - share) *
/// b_max`, rounded up to whole ticks.
fn bound(l: Limits, w: u64, b_max: u64) -> u64 {
    let s = u64::from(l.share_permille);
    (s * w).div_ceil(1000) + l.burst + ((1000 - s) * b_max).div_ceil(1000)
}

/// A small deterministic generator for cost jitter (no test depends on a seed
/// beyond these sequences being fixed).
struct Lcg(u64);
impl Lcg {
    fn below(&mut self, n: u64) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 33) % n
    }
}

#[test]
fn limits_are_checked() {
    assert!(Governor::new(limits()).is_ok());
    let bad = |f: fn(&mut Limits)| {
        let mut l = limits();
        f(&mut l);
        Governor::new(l).err()
    };
    assert_eq!(bad(|l| l.half = 0), Some(LimitsError::ZeroHalf));
    assert_eq!(
        bad(|l| l.share_permille = 0),
        Some(LimitsError::Share { permille: 0 })
    );
    assert_eq!(
        bad(|l| l.share_permille = 1000),
        Some(LimitsError::Share { permille: 1000 })
    );
    assert_eq!(bad(|l| l.burst = T + 1), Some(LimitsError::Burst));
    assert_eq!(bad(|l| l.max_age = T - 1), Some(LimitsError::MaxAge));
    assert_eq!(
        bad(|l| l.optional_gap = T - 1),
        Some(LimitsError::OptionalGap)
    );
    let text = std::format!("{}", LimitsError::Share { permille: 1000 });
    assert!(text.contains("1000 per mille"), "{text}");
    assert!(std::format!("{}", LimitsError::MaxAge).contains("age limit"));
}

#[test]
fn the_checker_catches_an_ungoverned_decoder() {
    // Without the governor a decoder at 130 % takes every window whole: the window
    // check below must see that, or it could not fail.
    let r = run(limits(), 2, 2_000, false, |_| T * 13 / 10);
    let w = 16 * T;
    assert!(max_busy_in_window(&r.busy, w) > bound(limits(), w, T * 13 / 10));
    assert_eq!(max_busy_in_window(&r.busy, w), w);
}

#[test]
fn under_budget_never_pauses_or_drops() {
    // 55..95 % of a half (mean 75 %) with single halves up to 120 %: below the 90 %
    // share on average, above it now and then.
    let mut g = Lcg(7);
    let r = run(limits(), 2, 20_000, true, |n| {
        if n % 97 == 0 {
            T * 12 / 10
        } else {
            T * 55 / 100 + g.below(T * 40 / 100)
        }
    });
    assert_eq!((r.pauses, r.dropped, r.lost), (0, 0, 0));
    assert_eq!(r.decoded, 20_000);
    assert!(r.ages.iter().all(|&a| a <= T / 4), "decoder fell behind");
}

#[test]
fn exactly_at_the_share_never_drops() {
    // 90 % of every half, the share itself: credit stays where it is.
    let r = run(limits(), 2, 5_000, true, |_| T * 9 / 10);
    assert_eq!((r.pauses, r.dropped, r.lost), (0, 0, 0));
}

#[test]
fn overload_keeps_the_share_over_every_window() {
    let l = limits();
    for (name, b) in [
        ("130 % constant", T * 13 / 10),
        (
            "super mode today (4770 of 4800 cycles + preemption)",
            T * 115 / 100,
        ),
    ] {
        let r = run(l, 2, 10_000, true, |_| b);
        for halves in [4, 16, 64, 1_000] {
            let w = halves * T;
            let most = max_busy_in_window(&r.busy, w);
            assert!(
                most <= bound(l, w, b),
                "{name}: {most} busy in a window of {w} (bound {})",
                bound(l, w, b)
            );
        }
        // Over 16 halves (3.3 ms): at most 94.4 % (14.4 + 0.5 + 0.13 half periods).
        let w = 16 * T;
        assert!(max_busy_in_window(&r.busy, w) * 1000 <= w * 944, "{name}");
        // Over the whole run, too.
        assert!(busy_in(&r.busy, 0, r.end) <= bound(l, r.end, b), "{name}");
        // The overload was shed, not hidden: pauses, and halves not decoded.
        assert!(r.pauses > 0 && r.dropped + r.lost > 0, "{name}: {r:?}");
        assert!(
            r.ages.iter().all(|&a| a <= l.max_age),
            "{name}: stale decode"
        );
    }
}

#[test]
fn random_overload_keeps_the_share_and_the_age() {
    let l = limits();
    let mut g = Lcg(11);
    let mut b_max = 0;
    let r = run(l, 2, 20_000, true, |_| {
        let b = T / 2 + g.below(2 * T);
        b_max = b_max.max(b);
        b
    });
    for halves in [2, 8, 32, 256] {
        let w = halves * T;
        assert!(max_busy_in_window(&r.busy, w) <= bound(l, w, b_max));
    }
    assert!(r.ages.iter().all(|&a| a <= l.max_age));
    assert!(r.dropped > 0 && r.pauses > 0);
}

#[test]
fn stale_halves_are_dropped_fresh_ones_decoded() {
    let mut g = Governor::new(limits()).expect("valid");
    assert_eq!(
        g.next(10_000, Class::Essential, 10_000 - 2 * T),
        Step::Decode
    );
    assert_eq!(
        g.next(10_000, Class::Essential, 10_000 - 2 * T - 1),
        Step::Drop
    );
    // A half stamped after `now` (clocks read in another order) is fresh.
    assert_eq!(g.next(10_000, Class::Essential, 10_500), Step::Decode);
}

#[test]
fn a_pause_lasts_until_the_debt_is_paid() {
    let mut g = Governor::new(limits()).expect("valid");
    assert_eq!(g.next(0, Class::Essential, 0), Step::Decode);
    // Full credit T/2 = 102; 1000 busy at 90 %: 102 + 900 - 1000 = 2 left... at
    // the next call, after exactly the busy time.
    g.spent(Class::Essential, 1_000);
    assert_eq!(g.next(1_000, Class::Essential, 1_000), Step::Decode);
    assert_eq!(g.credit(), 2);
    g.spent(Class::Essential, 1_000);
    // 2 + 900 - 1000 = -98: pause ceil(98 / 0.9) = 109.
    assert_eq!(
        g.next(2_000, Class::Essential, 2_000),
        Step::Pause { until: 2_109 }
    );
    // Asking early still pauses, until the same time.
    assert_eq!(
        g.next(2_050, Class::Essential, 2_000),
        Step::Pause { until: 2_109 }
    );
    assert_eq!(g.next(2_109, Class::Essential, 2_000), Step::Decode);
    assert!(g.credit() >= 0);
}

#[test]
fn optional_work_uses_only_spare_credit() {
    let l = limits();
    let mut g = Governor::new(l).expect("valid");
    // Full credit: optional work runs, and its cost is remembered.
    assert_eq!(g.next(0, Class::Optional, 0), Step::Decode);
    g.spent(Class::Optional, 500);
    // Credit 102 - 500 + 450 = 52 covers its net cost (1 - 0.9) * 500 = 50: decode.
    assert_eq!(g.next(500, Class::Optional, 500), Step::Decode);
    g.spent(Class::Optional, 500);
    // 52 - 50 = 2 < 50: dropped, never paused.
    assert_eq!(g.next(1_000, Class::Optional, 1_000), Step::Drop);
    // Essential work still runs on the 2 left, and its debt pauses only it.
    assert_eq!(g.next(1_000, Class::Essential, 1_000), Step::Decode);
    g.spent(Class::Essential, 1_000);
    assert!(matches!(
        g.next(2_000, Class::Essential, 2_000),
        Step::Pause { .. }
    ));
    assert_eq!(g.next(2_000, Class::Optional, 2_000), Step::Drop);
    // Idle time refills the credit (capped at the burst) and optional work resumes.
    assert_eq!(g.next(10_000, Class::Optional, 10_000), Step::Decode);
    assert_eq!(g.credit(), i64::try_from(l.burst).unwrap_or(0));
}

#[test]
fn garbage_times_neither_panic_nor_earn_credit() {
    let mut g = Governor::new(limits()).expect("valid");
    assert_eq!(g.next(5_000, Class::Essential, 5_000), Step::Decode);
    g.spent(Class::Essential, u64::MAX);
    // Time going back earns nothing and keeps the debt.
    let step = g.next(1_000, Class::Essential, 0);
    assert!(matches!(step, Step::Pause { .. }), "{step:?}");
    assert!(g.credit() < 0);
    // The far end of the clock: the earnings saturate (no wrap) and repay the debt.
    assert_eq!(g.next(u64::MAX, Class::Essential, u64::MAX), Step::Decode);
    // A half stamped at the clock's start is stale by then.
    assert_eq!(g.next(u64::MAX, Class::Essential, 0), Step::Drop);
    let mut h = Governor::new(Limits {
        half: u64::MAX,
        burst: u64::MAX,
        max_age: u64::MAX,
        optional_gap: u64::MAX,
        ..limits()
    })
    .expect("valid");
    assert_eq!(h.next(u64::MAX, Class::Optional, 0), Step::Decode);
    h.spent(Class::Optional, u64::MAX);
    let _ = h.next(0, Class::Essential, u64::MAX);
}

#[test]
fn starved_optional_work_is_admitted_like_essential_work() {
    let l = limits();
    let mut g = Governor::new(l).expect("valid");
    // Essential work runs the credit deep into debt.
    assert_eq!(g.next(0, Class::Essential, 0), Step::Decode);
    g.spent(Class::Essential, 20 * T);
    // Optional work is refused (first asked at 3T) until it has waited the gap...
    assert_eq!(g.next(3 * T, Class::Optional, 3 * T), Step::Drop);
    assert_eq!(g.next(11 * T - 1, Class::Optional, 11 * T - 1), Step::Drop);
    // ...then it is paused for like essential work, never dropped for credit.
    let Step::Pause { until } = g.next(11 * T, Class::Optional, 11 * T) else {
        panic!("a starved optional half in debt must be paused for");
    };
    // The half at hand went stale in the long pause; a fresh one is decoded.
    assert_eq!(g.next(until, Class::Optional, 11 * T), Step::Drop);
    assert_eq!(g.next(until, Class::Optional, until), Step::Decode);
    g.spent(Class::Optional, T);
    // Decoded: the gap starts again.
    assert_eq!(g.next(until + T, Class::Optional, until + T), Step::Drop);
}

/// Two streams in one executor, as in the firmware: the controller input
/// (essential, queue of 2) and the head STATUS (optional, queue of 1), halves every
/// `T` (STATUS half a period later); when both have a half waiting the decoder takes
/// them in turn (the firmware's input decoder yields after every half, so the
/// executor runs the STATUS task in between). Returns the busy intervals and the
/// start times of the optional decodes.
fn run_two(
    limits: Limits,
    halves: u64,
    essential: u64,
    optional: u64,
) -> (Vec<(u64, u64)>, Vec<u64>) {
    let mut gov = Governor::new(limits).expect("valid limits");
    let mut busy = Vec::new();
    let mut optional_starts = Vec::new();
    let (mut qe, mut qo): (VecDeque<u64>, VecDeque<u64>) = (VecDeque::new(), VecDeque::new());
    let (mut next_e, mut next_o) = (T, T / 2);
    let last = halves * T;
    let mut t = 0u64;
    let mut last_was_e = false;
    let fill = |t: u64, q: &mut VecDeque<u64>, next: &mut u64, depth: usize| {
        while *next <= t && *next <= last {
            if q.len() < depth {
                q.push_back(*next);
            }
            *next += T;
        }
    };
    loop {
        fill(t, &mut qe, &mut next_e, 2);
        fill(t, &mut qo, &mut next_o, 1);
        let take_e = match (qe.is_empty(), qo.is_empty()) {
            (true, true) => {
                if next_e > last && next_o > last {
                    break;
                }
                t = next_e.min(next_o);
                continue;
            }
            (false, false) => !last_was_e,
            (e_empty, _) => !e_empty,
        };
        last_was_e = take_e;
        let (class, ready, cost) = if take_e {
            (Class::Essential, qe.pop_front().unwrap_or(0), essential)
        } else {
            (Class::Optional, qo.pop_front().unwrap_or(0), optional)
        };
        loop {
            match gov.next(t, class, ready) {
                Step::Pause { until } => {
                    t = until;
                    fill(t, &mut qe, &mut next_e, 2);
                    fill(t, &mut qo, &mut next_o, 1);
                }
                Step::Drop => break,
                Step::Decode => {
                    if class == Class::Optional {
                        optional_starts.push(t);
                    }
                    busy.push((t, t + cost));
                    t += cost;
                    gov.spent(class, cost);
                    break;
                }
            }
        }
    }
    (busy, optional_starts)
}

#[test]
fn overloaded_input_and_status_share_the_core_and_status_is_not_silenced() {
    let l = limits();
    // Input at 130 % of a half, STATUS at 50 %: far over the share together.
    let (busy, status) = run_two(l, 5_000, T * 13 / 10, T / 2);
    for halves in [4, 16, 256] {
        let w = halves * T;
        assert!(max_busy_in_window(&busy, w) <= bound(l, w, T * 13 / 10));
    }
    // STATUS still gets decoded, at least once per gap (plus the pause and the
    // decode in progress when the gap ends).
    assert!(status.len() > 100, "{}", status.len());
    let longest = status.windows(2).map(|p| p[1] - p[0]).max().unwrap_or(0);
    assert!(
        longest <= l.optional_gap + 3 * T,
        "STATUS silent for {longest}"
    );
    // Without the gap rule the same load silences it: the check above can fail.
    let never = Limits {
        optional_gap: u64::MAX,
        ..l
    };
    let (_, starved) = run_two(never, 5_000, T * 13 / 10, T / 2);
    assert!(starved.len() < status.len() / 10, "{}", starved.len());
}

#[test]
fn input_and_status_under_budget_are_both_decoded_in_full() {
    // 50 % + 35 %: under the 90 % share together.
    let (busy, status) = run_two(limits(), 5_000, T / 2, T * 35 / 100);
    assert_eq!(status.len(), 5_000);
    assert_eq!(busy.len(), 10_000);
}

proptest! {
    /// Any cost sequence below the share (each half at most 85 % of a half period):
    /// no pause, no drop, nothing lost.
    #[test]
    fn prop_under_budget(costs in proptest::collection::vec(0..=(T * 85 / 100), 1..400)) {
        let r = run(limits(), 2, costs.len() as u64, true, |n| costs[n]);
        prop_assert_eq!((r.pauses, r.dropped, r.lost), (0, 0, 0));
        prop_assert_eq!(r.decoded, costs.len());
    }

    /// Any cost sequence at all: the window bound and the age bound hold.
    #[test]
    fn prop_bounds_hold(
        costs in proptest::collection::vec(1..(4 * T), 1..400),
        halves in 1u64..64,
    ) {
        let l = limits();
        let b_max = costs.iter().copied().max().unwrap_or(0);
        let r = run(l, 2, costs.len() as u64 * 2, true, |n| costs[n % costs.len()]);
        let w = halves * T;
        prop_assert!(max_busy_in_window(&r.busy, w) <= bound(l, w, b_max));
        prop_assert!(r.ages.iter().all(|&a| a <= l.max_age));
    }
}
