//! A frame whose tail the line moves off its timing between two good start edges
//! (the tail confirmation, [`super::confirm`]): a transient phase excursion of
//! `δ` bits over the last 28 bits, the stop field taking it back up, so both
//! start edges lie where the timing puts them.

use super::*;

/// The frame that carries the excursion.
const AT: usize = 12;
/// First line bit of that frame whose start boundary the excursion moves: pair 47
/// (DATA3 D13), the last 14 data pairs and the stop field's first bit.
const FROM: usize = 94;
/// Last moved boundary: the start of bit 121 (D0's complement); the stop bits'
/// boundaries are where they belong.
const TO: usize = 121;

/// The frames sent: frame [`AT`] has DATA3's last 16 bits zero, so that its pairs
/// 45..=60 are `0 1` and its line a square wave of one bit per level there.
fn sent() -> Vec<Frame> {
    let mut sent = frames(24, 31);
    let f = sent[AT];
    sent[AT] = frame(f.data1(), f.data2(), f.data3() & !0xFFFF);
    sent
}

/// The line bits sampled at `ratio` samples per bit from `phase` bits, with the
/// bit boundaries `FROM..=TO` of frame [`AT`] moved `delta` bits later.
fn excursion(bits: &[bool], ratio: f64, phase: f64, delta: f64) -> Vec<u16> {
    let moved = AT * 125 + FROM..=AT * 125 + TO;
    let samples = ((bits.len() as f64 - phase) * ratio) as usize;
    let mut words = Vec::new();
    for w in 0..samples / 16 {
        let mut word = 0u16;
        for k in 0..16 {
            let t = phase + (w * 16 + k) as f64 / ratio;
            let mut b = t as usize;
            // Inside a moved bit's first `delta`: the previous bit still holds.
            if moved.contains(&b) && t - (b as f64) < delta {
                b -= 1;
            } else if moved.contains(&(b + 1)) && delta < 0.0 && t - (b as f64) >= 1.0 + delta {
                b += 1;
            }
            word = word << 1 | u16::from(bits.get(b).copied().unwrap_or(true));
        }
        words.push(word);
    }
    words
}

/// Frame [`AT`] read 0.65 bit late over its last 14 data pairs: each of them is
/// read one bit late, `1 0` (the previous pair's complement, this pair's data
/// bit), a valid pair with D = 1, so the pattern passes every check as a frame
/// with DATA3's last 14 bits set, which was never sent. Its start edges are on
/// time, so the start-edge confirmation alone published it (asserted as the old
/// behaviour with the tail check off); its mid-pair edges lie 0.35 bit early
/// against the timing, so the receiver rejects it, as a check failure on every
/// channel, in every mode, and publishes every other frame.
#[test]
fn a_tail_read_off_its_timing_is_not_published() {
    let sent = sent();
    let wrong = frame(
        sent[AT].data1(),
        sent[AT].data2(),
        sent[AT].data3() | 0x3FFF,
    );
    // At 4x the same excursion can pass: there two bits are eight samples, so
    // every checked edge of a line without jitter is measured with the same
    // rounding, up to half a sample (an eighth of a bit) towards the timing
    // (README "Known limits", docs/engineering-log.md).
    // 3.0003: within the rounding steps of a line near a whole ratio, which a
    // frame whose edges show one is re-read across (`HansRx::rephased`): the
    // excursion's successor edge is not at the tail's rounding.
    for (ratio, hz) in [(3.0, 37_500_000), (3.0003, 37_500_000), (3.2, 40_000_000)] {
        for phase in [0.1, 0.45, 0.7] {
            let words = excursion(&line_bits(&sent), ratio, phase, 0.65);
            for mode in MODES {
                let mut rx = HansRx::new(hz, mode).unwrap();
                let events = run(&mut rx, &words, 16);
                let got = published(&events);
                let at = format!("{mode:?} {ratio} {phase}");
                assert!(!got.contains(&wrong), "{at}: wrong frame published");
                assert!(!got.contains(&sent[AT]), "{at}: not the frame sent");
                let mut expect = sent.clone();
                expect.remove(AT);
                assert_recovered(&expect, &got, LOCK);
                for ch in mode_channels(mode) {
                    assert_eq!(rx.stats(ch).unwrap().check_failures, 1, "{at} channel {ch}");
                }
            }
        }
    }
}

/// The same line with the excursion under half a bit (0.4): every bit is still
/// read right, but its tail's edges are 0.4 bit late: the frame is rejected too
/// (the check sees the phase, not the content; a good line's mean stays within
/// a few hundredths of a bit).
#[test]
fn a_tail_phase_excursion_is_rejected_even_when_read_right() {
    let sent = sent();
    let words = excursion(&line_bits(&sent), 3.2, 0.3, 0.4);
    let mut rx = HansRx::new(40_000_000, Mode::Super).unwrap();
    let got = published(&run(&mut rx, &words, 25));
    let mut expect = sent.clone();
    expect.remove(AT);
    assert_recovered(&expect, &got, LOCK);
    assert!(!got.contains(&sent[AT]));
}

/// The channels 1..=5 a mode uses.
fn mode_channels(mode: Mode) -> Vec<u8> {
    (1..=5)
        .filter(|&c| mode.channel_mask() & bit(c) != 0)
        .collect()
}

/// Frame [`SHORT_AT`] of [`short_excursion`]'s lines: late enough that every
/// lock, ±25 % jitter included, has settled ([`LOCK`] plus the slowest
/// acquisitions of `limits_over_many_locks`).
const SHORT_AT: usize = 20;

/// `n` frames of `seed` sent back to back, [`SHORT_AT`]'s DATA3 with its last 16
/// bits zero when `square` (pairs `0 1`: a tail read a whole bit off still holds
/// valid pairs, each with the other data bit), sampled at `ratio` from `phase`
/// bits, every bit boundary moved by a uniform random amount within ±`jitter`
/// bits and the boundaries of [`SHORT_AT`]'s last `pairs` pairs (from the first
/// bit of its pair `61 - pairs` to the middle of pair 60; the stop field's are
/// where they belong) `delta` bits more: a transient excursion of the line's
/// phase that the stop field takes back up.
#[allow(clippy::too_many_arguments)]
fn short_excursion(
    n: usize,
    seed: u32,
    square: bool,
    ratio: f64,
    phase: f64,
    jitter: f64,
    pairs: usize,
    delta: f64,
) -> (Vec<Frame>, Vec<u16>) {
    let mut sent = frames(n, seed);
    if square {
        let f = sent[SHORT_AT];
        sent[SHORT_AT] = frame(f.data1(), f.data2(), f.data3() & !0xFFFF);
    }
    let bits = line_bits(&sent);
    let mut x = u64::from(seed).wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut uniform = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    let moved = SHORT_AT * 125 + 122 - 2 * pairs..=SHORT_AT * 125 + 121;
    // Boundary b (the start of bit b) lies at `at[b]`.
    let at: Vec<f64> = (0..bits.len() + 2)
        .map(|b| {
            let j = (2.0 * uniform() - 1.0) * jitter;
            b as f64 + j + if moved.contains(&b) { delta } else { 0.0 }
        })
        .collect();
    let samples = ((bits.len() as f64 - phase - 2.0) * ratio) as usize;
    let words = (0..samples / 16)
        .map(|w| {
            (0..16).fold(0u16, |word, k| {
                let t = phase + (w * 16 + k) as f64 / ratio;
                // The latest boundary at or before t (jitter and excursion stay
                // within a bit, so it lies within two of t's whole bit).
                let b = t as usize;
                let i = (b.saturating_sub(2)..=b + 2)
                    .rev()
                    .find(|&i| at[i] <= t)
                    .unwrap_or(0);
                word << 1 | u16::from(bits.get(i).copied().unwrap_or(true))
            })
        })
        .collect();
    (sent, words)
}

/// Frames not sent that today's receiver publishes on the points of
/// [`short_tail_excursions_never_publish_a_frame_not_sent`] (ratio, jitter,
/// pairs, delta, of 24 lines): a known limit (README "Known limits", docs/engineering-log.md, tail
/// excursions), pinned exactly: a change that makes it worse fails, and so does
/// one that makes it better until the table follows. Four pairs read half a
/// bit off and more: the pairs a whole bit read turns into other valid pairs
/// measure their edges half a bit early less up to a sample (a third of a bit at
/// 3x), and four of eight such edges leave the tail's mean near 0.2 bit; at ±25 %
/// on eight pairs 0.4 bit off, jitter read some pairs a bit off and left the
/// others near 0.4, the mean inside a quarter bit. The far-edge check
/// (`confirm::excursion`) rejects 4 far edges of 8 on a line whose recent
/// tails had (nearly) none: it took the 8 points within ±15 % jitter (±20 % at
/// 4x, whose ±0.5 bit excursions leave 4 far edges) off this list (62 lines at
/// 16 points before, 28 at 8 then; 26 measured 2026-12-03, 3.2x ±25 % -0.5
/// bit publishing on 2 lines, not 4, when the bound became exact). Left: lines
/// jittered enough to show far edges of their own, and at ±20 % -0.5 bit and
/// 3.2x ±25 %, jitter put one of the 4 slipped edges within 5/16 bit (3 far
/// edges). Around this grid: [`BEYOND`].
const KNOWN_WRONG: &[(f64, f64, usize, f64, usize)] = &[
    (3.0, 0.15, 4, -0.5, 4),
    (3.0, 0.2, 4, -0.5, 4),
    (3.0, 0.25, 4, -0.5, 4),
    (3.2, 0.2, 4, -0.5, 4),
    (3.2, 0.25, 4, -0.5, 2),
    (3.2, 0.25, 8, 0.4, 2),
    (4.0, 0.25, 4, -0.5, 4),
    (4.0, 0.25, 4, 0.5, 2),
];

/// The line at 37.5, 40 or 50 MHz: the sampling rate of `ratio` (3, 3.2, 4).
fn rate(ratio: f64) -> u32 {
    (f64::from(BIT_RATE_HZ) * ratio).round() as u32
}

/// Runs the 24 lines of one excursion point (6 seeds, random data and a square
/// wave, normal and super mode; [`short_excursion`]): returns how many
/// published the excursion frame (the frame sent) and how many published a
/// frame not sent. Every other line publishes every frame after the lock but,
/// at most, the excursion frame.
fn excursion_lines(ratio: f64, jitter: f64, pairs: usize, delta: f64) -> (usize, usize) {
    let (mut passed, mut wrong) = (0, 0);
    for seed in 1..=6 {
        for square in [false, true] {
            let phase = f64::from(seed) * 0.37 % 1.0;
            let (sent, words) =
                short_excursion(32, seed, square, ratio, phase, jitter, pairs, delta);
            for mode in [Mode::Normal { channel: 2 }, Mode::Super] {
                let mut rx = HansRx::new(rate(ratio), mode).unwrap();
                let got = published(&run(&mut rx, &words, 16));
                if got.iter().any(|f| !sent.contains(f)) {
                    wrong += 1;
                    continue;
                }
                let mut expect = sent.clone();
                if got.contains(&sent[SHORT_AT]) {
                    passed += 1;
                } else {
                    expect.remove(SHORT_AT);
                }
                assert_recovered(&expect, &got, SHORT_AT - 4);
            }
        }
    }
    (passed, wrong)
}

/// Short excursions of a frame's tail (its last 4, 8 or 12 pairs read 0.3 to 0.5
/// bit off, either way; the start edges of the frame and its successor where
/// they belong), at 3x, 3.2x and 4x, with and without jitter, in normal and
/// super mode, on random data and on a square wave (the data a whole-bit read
/// turns into other valid pairs), 6 seeds each. Every other frame after the
/// lock is published, and no frame that was not sent, except at the points of
/// [`KNOWN_WRONG`], exactly as many as it says (fewer is progress: update the
/// table). The tail confirmation rejects the excursion frame on 8 or 12 pairs
/// half a bit off, and 0.4 bit off at 3x and 3.2x, whatever the jitter.
/// Prints, per point, how many excursion frames (and how many frames not sent)
/// were published (with `--nocapture`).
#[test]
fn short_tail_excursions_never_publish_a_frame_not_sent() {
    const DELTAS: [f64; 6] = [-0.5, -0.4, -0.3, 0.3, 0.4, 0.5];
    println!(
        "excursion frames published (frames not sent published) of 6 seeds x 2 data x 2 modes"
    );
    println!("ratio jitter pairs | delta {DELTAS:?}");
    let mut pinned = 0;
    for ratio in [3.0, 3.2, 4.0] {
        for jitter in [0.0, 0.15, 0.2, 0.25] {
            for pairs in [4, 8, 12] {
                let mut row = String::new();
                for delta in DELTAS {
                    let point = format!("{ratio} ±{jitter} {pairs} pairs {delta} bit");
                    let (passed, wrong) = excursion_lines(ratio, jitter, pairs, delta);
                    let seen = (f64::abs(delta) >= 0.5 && pairs >= 8)
                        || (f64::abs(delta) >= 0.4 && pairs >= 8 && ratio < 4.0);
                    assert!(!seen || passed == 0, "{point}: excursion frame published");
                    let known = KNOWN_WRONG
                        .iter()
                        .find(|k| (k.0, k.1, k.2, k.3) == (ratio, jitter, pairs, delta))
                        .map_or(0, |k| {
                            pinned += 1;
                            k.4
                        });
                    assert_eq!(
                        wrong, known,
                        "{point}: lines that published a frame not sent"
                    );
                    row += &format!(" {passed:>2} ({wrong})");
                }
                println!("{ratio:>5} {jitter:>6} {pairs:>5} |      {row}");
            }
        }
    }
    assert_eq!(
        pinned,
        KNOWN_WRONG.len(),
        "a KNOWN_WRONG point off the grid"
    );
}

/// The slips of [`BEYOND`]'s columns (bits), either way.
const BEYOND_DELTAS: [f64; 12] = [
    -0.65, -0.6, -0.55, -0.5, -0.4, -0.3, 0.3, 0.4, 0.5, 0.55, 0.6, 0.65,
];

/// Lines (of 24) that publish a frame not sent beyond [`KNOWN_WRONG`]'s grid,
/// per (pairs, ratio, jitter) and slip ([`BEYOND_DELTAS`]): the last 3, 5, 6 or
/// 7 pairs 0.3 to 0.65 bit off and the last 4 pairs 0.55 to 0.65 bit off (their
/// 0.3..0.5 columns are [`KNOWN_WRONG`]'s, not run here: 0). Measured
/// 2026-12-03 with the steady line's check (`confirm::excursion`: 3 far edges
/// of 8, the last 3 edges among the off ones, on a line whose edges measure
/// within 3/4 sample, `Timing::steady`): 422 lines at 97 of the 648 points run
/// (570 at 121 before it), 48 of them at 7 points without jitter (148 at 18
/// before), all 0.65 bit late: read a whole bit late, their slipped edges
/// measure 0.35 bit early less the rounding, a sample at 4x (a quarter bit)
/// and at 3.2x (0.31 bit), under the far bound (5/16 bit), so no count of far
/// edges sees them (4..7 pairs at 4x, 8 of 24; 3 pairs at 3.2x and 4x, 6 and
/// 8; 4 pairs at 3.2x, 2). A sample off is also what one polarity's rounding
/// step makes on a line with asymmetric edges near a whole ratio
/// (`rounding::ASYM_KNOWN_LOST`), so a bound that low loses good frames there
/// (tried 2026-12-03). On jittered lines: 3 slipped pairs make at most 3 far
/// edges, under [`confirm::FAR_EDGES`], where the line is not steady; a slip of
/// 0.55..0.65 bit is read a whole bit off, and jitter and rounding take some of
/// its edges under the far bound and the mean inside a quarter bit. Pinned
/// exactly (a change either way fails until the table is updated), so that the
/// limit's extent stays known (README "Known limits", docs/engineering-log.md).
const BEYOND: &[(usize, f64, f64, [u8; 12])] = &[
    (3, 3.0, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (3, 3.0, 0.15, [0, 0, 0, 0, 4, 0, 0, 2, 0, 6, 10, 10]),
    (3, 3.0, 0.2, [0, 0, 0, 0, 4, 0, 0, 2, 0, 2, 10, 10]),
    (3, 3.0, 0.25, [0, 0, 0, 0, 4, 4, 0, 2, 0, 6, 6, 10]),
    (3, 3.2, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 6]),
    (3, 3.2, 0.15, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2]),
    (3, 3.2, 0.2, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2]),
    (3, 3.2, 0.25, [0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 6]),
    (3, 4.0, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 8]),
    (3, 4.0, 0.15, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 6]),
    (3, 4.0, 0.2, [0, 0, 0, 0, 4, 0, 0, 0, 0, 0, 0, 0]),
    (3, 4.0, 0.25, [0, 0, 0, 4, 4, 0, 0, 0, 2, 2, 2, 2]),
    (4, 3.0, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (4, 3.0, 0.15, [0, 0, 2, 0, 0, 0, 0, 0, 0, 4, 10, 10]),
    (4, 3.0, 0.2, [0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 10, 10]),
    (4, 3.0, 0.25, [0, 2, 2, 0, 0, 0, 0, 0, 0, 4, 5, 10]),
    (4, 3.2, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2]),
    (4, 3.2, 0.15, [0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 2]),
    (4, 3.2, 0.2, [0, 2, 4, 0, 0, 0, 0, 0, 0, 0, 0, 2]),
    (4, 3.2, 0.25, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2]),
    (4, 4.0, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 8]),
    (4, 4.0, 0.15, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 6]),
    (4, 4.0, 0.2, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (4, 4.0, 0.25, [0, 2, 2, 0, 0, 0, 0, 0, 0, 0, 2, 2]),
    (5, 3.0, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (5, 3.0, 0.15, [0, 0, 0, 2, 0, 0, 0, 0, 0, 2, 6, 10]),
    (5, 3.0, 0.2, [0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 6, 10]),
    (5, 3.0, 0.25, [0, 0, 0, 2, 0, 0, 0, 0, 0, 4, 4, 7]),
    (5, 3.2, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (5, 3.2, 0.15, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (5, 3.2, 0.2, [2, 0, 2, 4, 0, 0, 0, 0, 0, 0, 0, 0]),
    (5, 3.2, 0.25, [2, 2, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0]),
    (5, 4.0, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 8]),
    (5, 4.0, 0.15, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 4]),
    (5, 4.0, 0.2, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (5, 4.0, 0.25, [0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 2]),
    (6, 3.0, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (6, 3.0, 0.15, [0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 6]),
    (6, 3.0, 0.2, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 4, 8]),
    (6, 3.0, 0.25, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 6, 6]),
    (6, 3.2, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (6, 3.2, 0.15, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (6, 3.2, 0.2, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (6, 3.2, 0.25, [0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0]),
    (6, 4.0, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 8]),
    (6, 4.0, 0.15, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2]),
    (6, 4.0, 0.2, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (6, 4.0, 0.25, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0]),
    (7, 3.0, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (7, 3.0, 0.15, [0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 4]),
    (7, 3.0, 0.2, [0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 4]),
    (7, 3.0, 0.25, [0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 4, 6]),
    (7, 3.2, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (7, 3.2, 0.15, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (7, 3.2, 0.2, [0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (7, 3.2, 0.25, [0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0]),
    (7, 4.0, 0.0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 8]),
    (7, 4.0, 0.15, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (7, 4.0, 0.2, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    (7, 4.0, 0.25, [0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0]),
];

/// The excursions around [`short_tail_excursions_never_publish_a_frame_not_sent`]'s
/// grid ([`BEYOND`]): the same lines, 3 and 5..7 pairs, and slips of 0.55..0.65
/// bit. Every line that publishes no frame not sent publishes every other frame
/// after the lock; the lines that do are exactly as many as [`BEYOND`] says.
#[test]
fn tail_excursions_beyond_the_grid_are_pinned() {
    let mut rows = 0;
    for pairs in 3..=7 {
        for ratio in [3.0, 3.2, 4.0] {
            for jitter in [0.0, 0.15, 0.2, 0.25] {
                let Some((.., known)) = BEYOND
                    .iter()
                    .find(|k| (k.0, k.1, k.2) == (pairs, ratio, jitter))
                else {
                    panic!("no BEYOND row for {pairs} pairs {ratio} ±{jitter}");
                };
                rows += 1;
                for (&delta, &known) in BEYOND_DELTAS.iter().zip(known) {
                    let (_, wrong) = if pairs == 4 && f64::abs(delta) <= 0.5 {
                        (0, 0)
                    } else {
                        excursion_lines(ratio, jitter, pairs, delta)
                    };
                    assert_eq!(
                        wrong,
                        usize::from(known),
                        "{ratio} ±{jitter} {pairs} pairs {delta} bit: lines that published a frame not sent"
                    );
                }
            }
        }
    }
    assert_eq!(rows, BEYOND.len(), "a BEYOND row off the grid");
}

/// A whole-bit read of the last 7 pairs (the line 0.55 to 0.65 bit off there,
/// either way, without jitter, at 3x and 3.2x): the pairs read a bit off
/// measure their edges half a bit off less up to a sample (a third of a bit at
/// 3x), 7 of 8 such edges put the mean beyond a quarter bit, and the frame
/// (never sent, on data whose last bits repeat) is rejected. A wider tail
/// check for jittered good frames (the last 8 pairs' mean up to 5/16 bit when
/// the last 16's is within a quarter, README "Known limits", docs/engineering-log.md) published frames
/// not sent at 4 of these 12 points (up to 14 of the 24 lines a point), and
/// the excursion frame at 2 more.
#[test]
fn a_whole_bit_read_of_seven_pairs_is_not_published() {
    for (ratio, hz) in [(3.0, 37_500_000), (3.2, 40_000_000)] {
        for delta in [-0.65, -0.6, -0.55, 0.55, 0.6, 0.65] {
            for seed in 1..=6 {
                for square in [false, true] {
                    let phase = f64::from(seed) * 0.37 % 1.0;
                    let (sent, words) =
                        short_excursion(32, seed, square, ratio, phase, 0.0, 7, delta);
                    for mode in [Mode::Normal { channel: 2 }, Mode::Super] {
                        let mut rx = HansRx::new(hz, mode).unwrap();
                        let got = published(&run(&mut rx, &words, 16));
                        let at = format!("{ratio} {delta} bit, {mode:?} seed {seed} {square}");
                        assert!(
                            got.iter().all(|f| sent.contains(f)),
                            "{at}: a frame not sent"
                        );
                        assert!(!got.contains(&sent[SHORT_AT]), "{at}: excursion published");
                        assert!(got.len() >= 32 - LOCK - 2, "{at}: {} published", got.len());
                    }
                }
            }
        }
    }
}
