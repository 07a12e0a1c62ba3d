//! The start-edge hunt on its own ([`super::super::hunt`]): where it locks on a clean
//! line, and that false candidates (stretched data runs, garbage with long runs
//! one frame apart, frames that do not read right) neither lock nor hide the true
//! start edges.

use super::super::hunt::{Found, Hunt};
use super::super::ring::Ring;
use super::*;

/// The rates the receiver runs at: (samples per bit, sampling rate).
const RATES: [(f64, u32); 3] = [(3.0, 37_500_000), (3.2, 40_000_000), (4.0, 50_000_000)];

/// Runs one channel's hunt word by word over `words` (as `HansRx::hunt` does, the
/// hunt going on after each lock): every lock and the index of the word it came
/// in.
fn locks(words: &[u16], hz: u32) -> Vec<(usize, Found)> {
    let timing = timing::Timing::new(((u64::from(hz) << 16) / 12_500_000) as i32);
    let (threshold, bounds) = (timing.hunt_threshold(), timing.bounds);
    let mut ring = Ring::default();
    let mut h = Hunt::default();
    let mut out = Vec::new();
    for (i, &w) in words.iter().enumerate() {
        ring.write(i as u32, &[w]);
        if let Some(found) = h.word(&ring, i as u32, threshold, bounds) {
            out.push((i, found));
        }
    }
    out
}

/// The first lock of [`locks`].
fn hunt(words: &[u16], hz: u32) -> Option<(usize, Found)> {
    locks(words, hz).first().copied()
}

/// Sample position (Q16) of bit boundary `bit` of a stream oversampled at `ratio`
/// from `phase` bits on.
fn at(bit: f64, ratio: f64, phase: f64) -> f64 {
    (bit - phase) * ratio * 65_536.0
}

/// `found` is the start edge of bit `bit` within a sample, with the nominal period
/// within half a sample.
fn assert_at(found: &Found, bit: f64, ratio: f64, phase: f64) {
    let err = (found.start as f64 - at(bit, ratio, phase)) / 65_536.0;
    assert!(err.abs() <= 1.0, "start {err} samples off bit {bit}");
    let period = found.period as f64 / 65_536.0;
    assert!(
        (period - 125.0 * ratio).abs() <= 0.5,
        "period {period} at {ratio}"
    );
}

#[test]
fn a_clean_line_locks_at_its_second_start_edge_with_one_frame() {
    for (ratio, hz) in RATES {
        for phase in [0.0, 0.3, 0.77] {
            let words = oversample(&line_bits(&frames(6, 3)), ratio, phase);
            // The stream starts with a start bit: the first candidate is frame 1's
            // start edge, the lock frame 2's.
            let (_, found) = hunt(&words, hz).expect("no lock");
            assert_at(&found, 250.0, ratio, phase);
            assert_eq!(found.edges, 2, "a clean frame reads with margin");
        }
    }
}

/// Frames whose last two data pairs are `0 1`, `1 0`: bits 119 and 120 are a
/// two-bit run of ones that ends at the mid-pair edge 4 bits before the stop
/// field's end.
fn frames_with_late_run(n: usize) -> Vec<Frame> {
    frames(n, 9)
        .into_iter()
        .map(|f| {
            let [a, b, c] = f.words();
            frame(a, b, (c & !0b11) | 0b01)
        })
        .collect()
}

#[test]
fn a_stretched_data_run_a_period_after_a_start_edge_does_not_lock() {
    for (ratio, hz) in RATES {
        let sent = frames_with_late_run(8);
        let mut bits = line_bits(&sent);
        // Frame 1's bit 118 (D1 = 0) high: a three-bit run ending 121 bits after
        // frame 1's start edge, within 5 % of a period. The single-candidate hunt
        // locked there with a 3 % short period.
        bits[125 + 118] = true;
        let words = oversample(&bits, ratio, 0.4);
        let (_, found) = hunt(&words, hz).expect("no lock");
        // Frame 1 does not read right any more: the first good pair is frames 2-3.
        assert_at(&found, 375.0, ratio, 0.4);
    }
}

#[test]
fn long_runs_one_period_apart_in_garbage_never_lock() {
    let mut x = 0x2545_F491u32;
    let mut random = || {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        x
    };
    for (ratio, hz) in RATES {
        for _ in 0..8 {
            // Random bits with the stop field and start bit of a frame every 125
            // bits: candidates exactly one period apart, no complement pairs.
            let mut bits: Vec<bool> = (0..125 * 40).map(|_| random() & 1 == 1).collect();
            for k in 1..40 {
                bits[125 * k - 3..125 * k].fill(true);
                bits[125 * k] = false;
            }
            let words = oversample(&bits, ratio, 0.25);
            assert_eq!(hunt(&words, hz), None);
            for mode in MODES {
                let mut rx = HansRx::new(hz, mode).unwrap();
                assert!(published(&run(&mut rx, &words, 11)).is_empty());
            }
        }
    }
}

#[test]
fn frames_that_never_read_right_never_lock() {
    for (ratio, hz) in RATES {
        // Every frame has one pair broken (both bits equal), at a different pair
        // each time: good stop fields a period apart, frames that fail.
        let mut bits = line_bits(&frames(30, 4));
        for k in 0..30 {
            let pair = 2 + 2 * ((7 * k) % 60);
            bits[125 * k + pair + 1] = bits[125 * k + pair];
        }
        let words = oversample(&bits, ratio, 0.6);
        assert_eq!(hunt(&words, hz), None);
    }
}

#[test]
fn noise_and_dense_candidates_never_lock() {
    let noise = super::noise(0x9E37_79B9, 20_000);
    // Runs of ones just over the threshold everywhere: a candidate every 9 to 12
    // samples, many pairs within a period's bounds, each read and dropped.
    let dense: Vec<u16> = [0xFF7F, 0xBFDF, 0xEFF7, 0xFBFD, 0xFEFF]
        .into_iter()
        .cycle()
        .take(5_000)
        .collect();
    for (_, hz) in RATES {
        for words in [&noise, &dense] {
            assert_eq!(hunt(words, hz), None);
        }
    }
}

#[test]
fn after_a_lock_the_hunt_starts_from_nothing() {
    // Each lock resets the hunt: the next one needs two new start edges, so on a
    // clean line the locks come every second frame, each at a start edge.
    for (ratio, hz) in RATES {
        let words = oversample(&line_bits(&frames(12, 5)), ratio, 0.1);
        let found = locks(&words, hz);
        assert_eq!(found.len(), 5, "{ratio}");
        for (k, (_, f)) in found.iter().enumerate() {
            assert_at(f, 250.0 * (k + 1) as f64, ratio, 0.1);
        }
    }
}
