//! Skipped input ([`HansRx::skip`]): a settled lock coasts across a gap and
//! resumes within a frame or two (a fresh receiver needs eight or more), publishes
//! only frames that were sent and lie wholly outside the gap, counts every skipped
//! period, and drops the lock when it is young or the gap too long.

use super::*;
use crate::hans::rx::gap::MAX_COAST;

/// Words in one DMA half as the firmware feeds the receiver.
const DMA_HALF: usize = 512;

/// A modelled line: frames sent back to back, sampled at `ratio` samples per bit
/// from `phase` bits into the stream, every bit edge moved by up to `jitter` bits.
pub(super) struct Stream {
    sent: Vec<Frame>,
    pub(super) words: Vec<u16>,
    ratio: f64,
    pub(super) phase: f64,
}

impl Stream {
    pub(super) fn new(n: usize, seed: u32, ratio: f64, phase: f64, jitter: f64) -> Stream {
        let sent = frames(n, seed);
        let bits = line_bits(&sent);
        let words = if jitter == 0.0 {
            oversample(&bits, ratio, phase)
        } else {
            jittered(&bits, ratio, phase, jitter, u64::from(seed))
        };
        Stream {
            sent,
            words,
            ratio,
            phase,
        }
    }

    /// Line time (bits) of the start of word `w`.
    fn time(&self, w: usize) -> f64 {
        self.phase + (16 * w) as f64 / self.ratio
    }

    /// The frames with a bit in words `g0..g1`, and the first frame wholly after.
    fn touched(&self, g0: usize, g1: usize) -> (std::ops::Range<usize>, usize) {
        let first = (self.time(g0) / 125.0).floor() as usize;
        let after = (self.time(g1) / 125.0).ceil() as usize;
        (first..after, after)
    }

    /// Index in `sent` of each published frame (every one must have been sent).
    fn indices(&self, events: &[RxEvent]) -> Vec<usize> {
        let mut out = Vec::new();
        for (i, f) in published(events).iter().enumerate() {
            if let Some(k) = self.sent.iter().position(|s| s == f) {
                out.push(k);
                continue;
            }
            // The sent frame nearest to it (data bits that differ), for the message.
            let differ = |s: &Frame| {
                (s.data1() ^ f.data1()).count_ones()
                    + (s.data2() ^ f.data2()).count_ones()
                    + (s.data3() ^ f.data3()).count_ones()
            };
            let nearest = self.sent.iter().enumerate().min_by_key(|(_, s)| differ(s));
            panic!(
                "published #{i} was never sent (previous published: sent frame {:?}; \
                 nearest sent frame {:?} differs in {:?} data bits)",
                out.last(),
                nearest.map(|(k, _)| k),
                nearest.map(|(_, s)| differ(s)),
            );
        }
        out
    }
}

/// [`oversample`] with every bit edge moved by a uniform random amount within
/// ±`jitter` bits (below 1/2).
fn jittered(bits: &[bool], ratio: f64, phase: f64, jitter: f64, seed: u64) -> Vec<u16> {
    let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut uniform = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    // Edge b (the start of bit b) lies at b + moved[b].
    let moved: Vec<f64> = (0..bits.len() + 2)
        .map(|_| (2.0 * uniform() - 1.0) * jitter)
        .collect();
    let samples = ((bits.len() as f64 - phase - 1.0) * ratio) as usize;
    (0..samples / 16)
        .map(|w| {
            (0..16).fold(0u16, |word, k| {
                let t = phase + (w * 16 + k) as f64 / ratio;
                let b = t as usize;
                let f = t - b as f64;
                let i = if f < moved[b] {
                    b.wrapping_sub(1)
                } else if f >= 1.0 + moved[b + 1] {
                    b + 1
                } else {
                    b
                };
                word << 1 | u16::from(bits.get(i).copied().unwrap_or(true))
            })
        })
        .collect()
}

/// Feeds `words` to `rx` (the same on every channel) in chunks of `chunk`, with the
/// words `g0..g0 + len` of every `(g0, len)` of `gaps` skipped instead of pushed.
fn feed(rx: &mut HansRx, words: &[u16], gaps: &[(usize, usize)], chunk: usize) -> Vec<RxEvent> {
    let mut out = Vec::new();
    let mut at = 0;
    for &(g0, len) in gaps.iter().chain([&(words.len(), 0)]) {
        for part in words[at..g0].chunks(chunk.max(1)) {
            rx.push(&[part; 5], &mut |e| out.push(e));
        }
        rx.skip(len as u32, &mut |e| out.push(e));
        at = g0 + len;
    }
    out
}

/// A stream's frames published around one gap `g0..g1`: in order, each once, none
/// with a bit in the gap, and none lost but those, one on either side (the last
/// one before needs its successor's start edge, the first one after is skipped
/// when its start edge is read less than the search window after the gap), the
/// first verified one after a coast (held until it has re-measured the phase) and
/// `relock` more. Returns the first frame published after the gap and its distance
/// from the first frame wholly after it.
fn check_gap(
    s: &Stream,
    got: &[usize],
    (g0, g1): (usize, usize),
    relock: usize,
    label: &str,
) -> (usize, usize) {
    assert!(
        got.windows(2).all(|w| w[0] < w[1]),
        "{label}: order {got:?}"
    );
    let (touched, after) = s.touched(g0, g1);
    assert!(
        got.iter().all(|k| !touched.contains(k)),
        "{label}: published a frame of the gap {touched:?}: {got:?}"
    );
    let first = *got
        .iter()
        .find(|&&k| k >= after)
        .unwrap_or_else(|| panic!("{label}: nothing after the gap"));
    let last = s.sent.len() - 2;
    let missed = (got[0]..last)
        .filter(|k| !got.contains(k) && !touched.contains(k))
        .count();
    assert!(
        missed <= 3 + relock,
        "{label}: {missed} frames lost: {got:?}"
    );
    (first, first - after)
}

/// Frames per DMA half and frame periods in words at `ratio`.
fn frame_words(ratio: f64) -> f64 {
    125.0 * ratio / 16.0
}

#[test]
fn a_settled_lock_coasts_across_whole_halves() {
    for (hz, ratio) in [(37_500_000, 3.0), (40_000_000, 3.2), (50_000_000, 4.0)] {
        for halves in 1..=4 {
            for mode in MODES {
                let label = format!("{hz} Hz, {halves} halves, {mode:?}");
                let s = Stream::new(60 + 90 * halves, halves as u32, ratio, 0.37, 0.0);
                // Well after the young fit (frame ~35), mid-frame.
                let g0 = (50.4 * frame_words(ratio)) as usize;
                let g1 = g0 + halves * DMA_HALF;
                let mut rx = HansRx::new(hz, mode).unwrap();
                let got = s.indices(&feed(&mut rx, &s.words, &[(g0, g1 - g0)], 64));
                let (first, late) = check_gap(&s, &got, (g0, g1), 0, &label);
                assert!(late <= 2, "{label}: resumed {late} frames late");
                // Skipped: the periods from the last decoded before the gap to the
                // first after; every other period verified on every used channel
                // (the first SETTLED - 2 of the lock without publishing).
                let last_before = *got.iter().rev().find(|&&k| k < first).unwrap();
                assert_eq!(
                    rx.skipped() as usize,
                    first - last_before - 2,
                    "{label}: skipped"
                );
                for n in bits(mode.channel_mask()) {
                    let st = rx.stats(number(n)).unwrap();
                    assert_eq!(
                        (st.frames_ok as usize, st.check_failures, st.missing),
                        (got.len() + ACQUISITION + 1, 0, 0),
                        "{label}: CH{}",
                        n + 1
                    );
                }
                // A fresh receiver from the gap's end takes a hunt and a young lock.
                let mut fresh = HansRx::new(hz, mode).unwrap();
                let again = s.indices(&feed(&mut fresh, &s.words[g1..], &[], 64));
                let fresh_first = *again.first().unwrap();
                assert!(
                    fresh_first >= first + 6,
                    "{label}: coasting resumed at {first}, a fresh lock at {fresh_first}"
                );
            }
        }
    }
}

#[test]
fn gaps_add_up_whatever_the_pieces() {
    let s = Stream::new(200, 21, 3.2, 0.6, 0.0);
    let g0 = 1_210;
    for mode in MODES {
        let whole = {
            let mut rx = HansRx::new(40_000_000, mode).unwrap();
            (feed(&mut rx, &s.words, &[(g0, 1_100)], 37), rx)
        };
        for cut in [1, 17, 64, 512, 1_099] {
            let mut rx = HansRx::new(40_000_000, mode).unwrap();
            let ev = feed(&mut rx, &s.words, &[(g0, cut), (g0 + cut, 1_100 - cut)], 37);
            assert_eq!((&ev, &rx), (&whole.0, &whole.1), "{mode:?} cut {cut}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Gaps of any length up to the bound, at any position against the frames, any
    /// rate and phase and chunking: the lock coasts and resumes at once, nothing of
    /// the gap or unsent is published, the skipped periods are counted.
    #[test]
    fn gaps_anywhere(ratio in 3.0f64..=4.0, phase in 0.0f64..1.0, seed in 1u32..,
                     at in 0.0f64..1.0,
                     len in prop_oneof![1usize..80, 80usize..2_700],
                     chunk in 1usize..80, mode in 0usize..4) {
        let mode = MODES[mode];
        let hz = (ratio * 12.5e6).round() as u32;
        let fw = frame_words(ratio);
        let frames = 60 + (len as f64 / fw) as usize + 12;
        let s = Stream::new(frames, seed, ratio, phase, 0.0);
        let g0 = ((45.0 + at) * fw) as usize;
        let mut rx = HansRx::new(hz, mode).unwrap();
        prop_assert!(len as u32 <= rx.max_gap_words());
        let got = s.indices(&feed(&mut rx, &s.words, &[(g0, len)], chunk));
        let label = format!("{mode:?} gap {g0}+{len}");
        let (first, late) = check_gap(&s, &got, (g0, g0 + len), 0, &label);
        prop_assert!(late <= 2, "{}: resumed {} frames late", label, late);
        let last_before = *got.iter().rev().find(|&&k| k < first).unwrap();
        let skipped = rx.skipped() as usize;
        prop_assert!(skipped >= s.touched(g0, g0 + len).0.len());
        prop_assert!(skipped < first - last_before);
        // Every period the same stream without the gap decodes is decoded or
        // skipped here, on every used channel.
        let mut whole = HansRx::new(hz, mode).unwrap();
        feed(&mut whole, &s.words, &[], chunk);
        let periods = |st: ChannelStats| (st.frames_ok + st.check_failures + st.missing) as usize;
        for n in bits(mode.channel_mask()) {
            let (a, b) = (rx.stats(number(n)).unwrap(), whole.stats(number(n)).unwrap());
            prop_assert_eq!(periods(a) + skipped, periods(b), "{:?} {:?}", a, b);
        }
    }
}

/// The spec's ±25 % jitter, alone and with a ±1 % rate offset: the coasted lock
/// publishes only sent frames and resumes as soon as the timing allows.
#[test]
fn coasting_under_jitter_and_offset() {
    let mut late_total = 0;
    let mut runs = 0;
    for (hz, nominal) in [(37_500_000, 3.0), (40_000_000, 3.2), (50_000_000, 4.0)] {
        for offset in [-0.01, 0.0, 0.01] {
            for halves in 1..=4 {
                let seed = (hz / 1_000_000) * 10 + halves as u32;
                let ratio = nominal / (1.0 + offset);
                let s = Stream::new(60 + 90 * halves, seed, ratio, 0.2, 0.25);
                let g0 = (55.7 * frame_words(ratio)) as usize;
                let g1 = g0 + halves * DMA_HALF;
                for mode in [Mode::Normal { channel: 2 }, Mode::Super] {
                    let label = format!("{hz} Hz {offset} {halves} halves {mode:?}");
                    let mut rx = HansRx::new(hz, mode).unwrap();
                    let got = s.indices(&feed(&mut rx, &s.words, &[(g0, g1 - g0)], 64));
                    let (_, late) = check_gap(&s, &got, (g0, g1), 0, &label);
                    assert!(late <= 3, "{label}: resumed {late} frames late");
                    late_total += late;
                    runs += 1;
                }
            }
        }
    }
    // Most runs resume with the first frame wholly after the gap but one (the one
    // that re-measures the phase is held, `Timing::recentring`) or the next.
    assert!(
        late_total * 2 <= runs * 3,
        "{late_total} frames late over {runs} runs"
    );
}

/// The premise of `MAX_COAST`: on a ±25 % jitter line with up to ±1 % offset a
/// settled lock's prediction `MAX_COAST` frames ahead stays within the quarter bit
/// the tracking leaves (half a bit, less the jitter). Prints the measured errors.
#[test]
fn coast_bound_holds_on_settled_locks() {
    let ahead = [1u32, 32, 64, MAX_COAST];
    for (hz, nominal) in [(37_500_000, 3.0), (40_000_000, 3.2), (50_000_000, 4.0)] {
        for offset in [-0.01, 0.0, 0.01] {
            let ratio = nominal / (1.0 + offset);
            let mut worst = [0.0f64; 4];
            for seed in 1..=8u32 {
                let s = Stream::new(300, seed, ratio, 0.3, 0.25);
                let mut rx = HansRx::new(hz, Mode::Normal { channel: 1 }).unwrap();
                let (mut count, mut last) = (0usize, 0u32);
                for part in s.words.chunks(4) {
                    rx.push(&[part; 5], &mut |_| {});
                    count += part.len();
                    let t = &rx.timing;
                    if !rx.locked || t.young() || t.start == last || count < 2_500 {
                        continue;
                    }
                    last = t.start;
                    // The start edge in samples from the stream's first.
                    let at = (count * 16) as f64
                        + f64::from(diff(t.start, (count as u32) << 20)) / 65536.0;
                    let frame = ((at / ratio + s.phase) / 125.0).round();
                    for (w, f) in worst.iter_mut().zip(ahead) {
                        let predicted = at + f64::from(f) * f64::from(t.period) / 65536.0;
                        let truth = ((frame + f64::from(f)) * 125.0 - s.phase) * ratio;
                        *w = w.max(((predicted - truth) / ratio).abs());
                    }
                }
            }
            println!(
                "{hz} Hz, offset {offset:+}: worst prediction error (bits) {ahead:?} frames ahead: {worst:.3?}"
            );
            assert!(worst[3] < 0.25, "{hz} Hz {offset}: {worst:?}");
            assert!(worst[0] < 0.15, "{hz} Hz {offset}: {worst:?}");
        }
    }
}

/// The rate a coast predicts with, in every mode: on five channels with their own
/// ±25 % jitter and up to ±2 samples of skew at 3x with a ±1 % offset, the
/// modes that decode several channels track the frame period as closely as one
/// channel does (normal mode). They time on their reference channel alone, as
/// normal mode does on its one; when every eighth frame's remeasure of all
/// channels moved the timing and every delay (the reference's too) toward the
/// channels' median instead, the delays' common part wandered with the jitter
/// and the rate with it: rms ~2e-3 bit a frame, 6.6e-3 at worst in vote5 /
/// super, against 2.5e-4 / 7e-4 in normal mode. Prints the measured errors.
#[test]
fn every_mode_tracks_the_rate_as_one_channel_does() {
    const FRAMES: usize = 200;
    // Settled (past the young fit) from about here on.
    const FROM: f64 = 50.0;
    let modes = [
        Mode::Normal { channel: 1 },
        Mode::Vote3 {
            channels: [5, 1, 3],
        },
        Mode::Vote5,
        Mode::Super,
    ];
    for offset in [-0.01, 0.01] {
        let ratio = 3.0 / (1.0 + offset);
        let mut rms = [0.0f64; 4];
        let mut worst = [0.0f64; 4];
        for (m, mode) in modes.into_iter().enumerate() {
            let (mut sum2, mut n) = (0.0f64, 0usize);
            for seed in 1..=12u32 {
                let bits = line_bits(&frames(FRAMES, seed));
                let words: Vec<Vec<u16>> = (0..5u32)
                    .map(|c| {
                        let skew = f64::from((c * 7 + seed) % 5) - 2.0;
                        let jitter_seed = u64::from(seed * 8 + c);
                        jittered(&bits, ratio, 1.0 - skew / ratio, 0.25, jitter_seed)
                    })
                    .collect();
                let mut rx = HansRx::new(37_500_000, mode).unwrap();
                let from = (FROM * frame_words(ratio)) as usize;
                let mut last = 0u32;
                let len = words[0].len();
                for at in (0..len).step_by(4) {
                    let parts: [&[u16]; 5] =
                        std::array::from_fn(|c| &words[c][at..(at + 4).min(len)]);
                    rx.push(&parts, &mut |_| {});
                    let t = &rx.timing;
                    if !rx.locked || t.young() || t.start == last || at < from {
                        continue;
                    }
                    last = t.start;
                    let err = (f64::from(t.period) / 65536.0 - 125.0 * ratio) / ratio;
                    sum2 += err * err;
                    n += 1;
                    worst[m] = worst[m].max(err.abs());
                }
            }
            assert!(n > 1_000, "{mode:?}: {n} settled frames");
            rms[m] = (sum2 / n as f64).sqrt();
        }
        let show = |v: &[f64; 4]| v.map(|e| format!("{e:.1e}")).join(" / ");
        println!(
            "37.5 MHz, offset {offset:+}: rate error (bit a frame) normal / vote3 / vote5 / super: rms {}, worst {}",
            show(&rms),
            show(&worst)
        );
        // Measured: within 1.1x of normal mode but for one lock (seed 10 at +1 %)
        // whose young fit switched its reference (the first one failed while
        // others verified): the new one's young delay shifts the fit's later
        // points against its earlier ones, and the filter still worked off the
        // handed-over rate at frame 50 (2.3e-3 bit a frame). Before the reference
        // timed alone: rms 4x..5x normal mode's, worst 5.3e-3.
        for m in 1..modes.len() {
            assert!(
                rms[m] < 1.7 * rms[0] && worst[m] < 2.5e-3,
                "{offset}: {:?}: rms {rms:?}, worst {worst:?}",
                modes[m]
            );
        }
    }
}

#[test]
fn a_young_lock_is_dropped_and_relocks() {
    let s = Stream::new(120, 4, 3.2, 0.1, 0.0);
    // Frame 20 of the stream: the lock (at frame ~2) is young.
    let (g0, g1) = (20 * 25 + 7, 20 * 25 + 7 + DMA_HALF);
    for mode in MODES {
        let mut rx = HansRx::new(40_000_000, mode).unwrap();
        let mut events = feed(&mut rx, &s.words[..g0], &[], 64);
        assert!(rx.locked && rx.timing.young(), "{mode:?}");
        let before = events.len();
        rx.skip((g1 - g0) as u32, &mut |e| events.push(e));
        assert!(!rx.locked, "{mode:?}: a young lock coasted");
        assert!(events[before..].contains(&RxEvent::Fault {
            channel: Some(number(rx.reference)),
            kind: FaultKind::Resync
        }));
        // Hunted again after the gap, like a fresh receiver.
        let more = feed(&mut rx, &s.words[g1..], &[], 64);
        let got = s.indices(&more);
        let (_, after) = s.touched(g0, g1);
        assert!(got[0] >= after + 6, "{mode:?}: {got:?}");
        let label = format!("young {mode:?}");
        events.extend(more);
        check_gap(&s, &s.indices(&events), (g0, g1), LOCK, &label);
    }
}

#[test]
fn a_too_long_gap_is_dropped_and_relocks() {
    let s = Stream::new(400, 6, 3.2, 0.8, 0.0);
    let g0 = 60 * 25 + 3;
    let rx0 = HansRx::new(40_000_000, Mode::Super).unwrap();
    let max = rx0.max_gap_words() as usize;
    // A gap of more than `MAX_COAST` periods (25 words each), the same in
    // pieces, and one just over.
    let long = (MAX_COAST as usize + 8) * 25;
    let cases: [&[(usize, usize)]; 3] = [
        &[(g0, long)],
        &[(g0, 1_000), (g0 + 1_000, long - 1_000)],
        &[(g0, (MAX_COAST as usize + 1) * 25)],
    ];
    for gaps in cases {
        for mode in MODES {
            let label = format!("{mode:?} {gaps:?}");
            let mut rx = HansRx::new(40_000_000, mode).unwrap();
            let events = feed(&mut rx, &s.words, gaps, 64);
            let got = s.indices(&events);
            let g1 = gaps.last().map(|&(a, n)| a + n).unwrap();
            let (first, late) = check_gap(&s, &got, (g0, g1), LOCK, &label);
            assert!(late >= 6, "{label}: a too-long gap coasted ({first})");
            // The lock was dropped (a clean stream has no other resync).
            assert!(
                events.iter().any(|e| matches!(
                    e,
                    RxEvent::Fault {
                        channel: Some(_),
                        kind: FaultKind::Resync
                    }
                )),
                "{label}"
            );
        }
    }
    // The bound holds at the bound: a gap of `max_gap_words` anywhere coasts.
    for shift in 0..25 {
        let mut rx = HansRx::new(40_000_000, Mode::Super).unwrap();
        let got = s.indices(&feed(&mut rx, &s.words, &[(g0 + shift, max)], 64));
        let (_, late) = check_gap(&s, &got, (g0 + shift, g0 + shift + max), 0, "at the bound");
        assert!(late <= 2, "shift {shift}: {late}");
    }
}

/// What follows a gap may be anything: noise, a line stuck high or low, or the
/// stream at another phase (the sender restarted). Nothing wrong is published, the
/// lock goes, and a good stream after it locks again.
#[test]
fn garbage_after_a_gap_never_yields_a_frame() {
    let s = Stream::new(200, 9, 3.2, 0.5, 0.0);
    let g0 = 50 * 25 + 11;
    let noise = super::noise(0xC0FF_EE11, 400);
    // Half a bit, one bit and half a frame late: the same frames, other edges.
    let shifted = |bits: f64| oversample(&line_bits(&s.sent), 3.2, 0.5 - bits);
    let tails: [(&str, Vec<u16>); 6] = [
        ("noise", noise),
        ("low", vec![0; 400]),
        ("high", vec![0xFFFF; 400]),
        ("half bit", shifted(0.5)[g0 + 512..].to_vec()),
        ("one bit", shifted(1.0)[g0 + 512..].to_vec()),
        ("half frame", shifted(62.5)[g0 + 512..].to_vec()),
    ];
    for (name, tail) in tails {
        for mode in MODES {
            let mut rx = HansRx::new(40_000_000, mode).unwrap();
            let mut words = s.words[..g0].to_vec();
            words.extend(vec![0u16; DMA_HALF]);
            words.extend(&tail);
            let events = feed(&mut rx, &words, &[(g0, DMA_HALF)], 64);
            let label = format!("{name} {mode:?}");
            // Every frame published is a sent one, in order, none of the gap.
            let got = s.indices(&events);
            assert!(got.windows(2).all(|w| w[0] < w[1]), "{label}: {got:?}");
            let (touched, _) = s.touched(g0, g0 + DMA_HALF);
            let after: Vec<usize> = got.iter().copied().filter(|&k| k > touched.end).collect();
            match name {
                // A line with no frames: nothing, and the lock goes.
                "noise" | "low" | "high" => {
                    assert!(after.is_empty(), "{label}: {after:?}");
                    assert!(!rx.locked, "{label}: still locked");
                }
                // The frames again at another phase: published again (after a
                // new lock, or at the old timing if still read right), and only
                // as sent (checked above).
                _ => assert!(!after.is_empty(), "{label}: never locked again"),
            }
        }
    }
}

/// A gap of exactly a ring lap (64 words) or a position lap (4 096 words) at a
/// rate whose frame period is 32 words, so the rings hold frames at the very
/// phase of the missing ones: nothing stale may be decoded. With the rings only
/// moved on, the two frames before the gap would be published again in place of
/// the two in it.
#[test]
fn a_ring_lap_gap_reads_no_stale_samples() {
    // 4.096 samples per bit at 50 MHz (the sender 2.3 % slow): 512 samples a frame.
    let ratio = 4.096;
    let s = Stream::new(340, 13, ratio, 0.0, 0.0);
    for lap in [RING_WORDS, 4_096] {
        for shift in (0..32).step_by(3) {
            for mode in [Mode::Normal { channel: 4 }, Mode::Super] {
                let g0 = 60 * 32 + shift;
                let label = format!("lap {lap} at {g0} {mode:?}");
                let mut rx = HansRx::new(50_000_000, mode).unwrap();
                let events = feed(&mut rx, &s.words, &[(g0, lap)], 64);
                let got = s.indices(&events);
                // A position lap is beyond the bound: a new lock.
                let relock = if lap == RING_WORDS { 0 } else { LOCK };
                let (_, late) = check_gap(&s, &got, (g0, g0 + lap), relock, &label);
                if lap == RING_WORDS {
                    assert!(late <= 2, "{label}: {late}");
                }
            }
        }
    }
    // The rings themselves: every slot of a lap-long gap is cleared.
    let mut rx = HansRx::new(50_000_000, Mode::Super).unwrap();
    feed(&mut rx, &s.words[..2_000], &[], 64);
    rx.skip(RING_WORDS as u32, &mut |_| {});
    for ring in &rx.rings {
        assert!((0..RING_WORDS as u32 / 2).all(|j| ring.window(j) == 0));
    }
}

#[test]
fn skipping_while_hunting_counts_nominal_periods() {
    let s = Stream::new(100, 17, 3.2, 0.0, 0.0);
    // Never locked: nothing counted, the hunt just goes on.
    let mut rx = HansRx::new(40_000_000, Mode::Vote5).unwrap();
    rx.skip(1_000, &mut |_| panic!("an event"));
    assert_eq!(rx.skipped(), 0);
    let got = s.indices(&feed(&mut rx, &s.words, &[], 64));
    assert!(got[0] <= LOCK, "{got:?}");
    // Locked once, then lost (a dead line), then 1 000 words skipped: 40 periods.
    let mut rx = HansRx::new(40_000_000, Mode::Vote5).unwrap();
    feed(&mut rx, &s.words[..1_000], &[], 64);
    feed(&mut rx, &[0; 200], &[], 64);
    assert!(!rx.locked);
    let missing = rx.stats(1).unwrap().missing;
    let period = u64::try_from(rx.timing.nominal_period()).unwrap();
    let mut idle = u64::try_from(rx.idle).unwrap();
    let mut want = 0u64;
    for words in [1_000, u32::MAX, 3] {
        rx.skip(words, &mut |_| panic!("an event"));
        idle += u64::from(words) << 20;
        want += idle / period;
        idle %= period;
        assert_eq!(u64::from(rx.skipped()), want % (1 << 32), "{words}");
    }
    assert_eq!(rx.stats(1).unwrap().missing, missing);
    // And it locks again on the stream.
    let got = s.indices(&feed(&mut rx, &s.words, &[], 64));
    assert!(got[0] <= LOCK, "{got:?}");
}

/// `HansRx::coasts` says exactly what `skip` does with a gap within
/// `max_gap_words`: after every chunk of a clean lock's life (hunt, young fit,
/// settled), a copy skipping a gap keeps the lock when it says so and drops it
/// (a resync) otherwise; it turns true once the young fit is in its last frames
/// and stays so.
#[test]
fn coasts_says_what_a_skip_does() {
    let s = Stream::new(60, 7, 3.2, 0.3, 0.0);
    let mut rx = HansRx::new(40_000_000, Mode::Normal { channel: 1 }).unwrap();
    let mut became = None;
    for (k, part) in s.words.chunks(16).enumerate() {
        rx.push(&[part; 5], &mut |_| {});
        let mut copy = rx;
        let mut dropped = false;
        copy.skip(100, &mut |e| {
            dropped |= matches!(
                e,
                RxEvent::Fault {
                    kind: FaultKind::Resync,
                    ..
                }
            )
        });
        assert_eq!(rx.coasts(), rx.locked && !dropped, "chunk {k}");
        assert_eq!(copy.locked, rx.coasts(), "chunk {k}");
        match (became, rx.coasts()) {
            (None, true) => became = Some(k),
            (Some(_), false) => panic!("chunk {k}: coasting stopped on a clean line"),
            _ => {}
        }
    }
    // Not before the lock has published (frame 8 of the lock, about 10 frames of
    // 125 bits at 3.2 samples, 25 words each), and well within the stream.
    let became = became.expect("a clean line's lock coasts");
    assert!((10 * 25 / 16..50 * 25 / 16).contains(&became), "{became}");
    // A gap beyond the bound drops the lock.
    rx.skip(rx.max_gap_words() * 2, &mut |_| {});
    assert!(!rx.coasts());
}

/// A coast's frame count (`Gaps::coasted`) is for the re-centring right after it,
/// not for a later lock: after a long coast, a lost lock and a new one, `coasts`
/// still says exactly what a skip does at every chunk of the new lock's life. (The
/// young fit's frame count that a re-centring starts from once also picked up the
/// old coast's frames there, and a gap `coasts` promised to cross dropped the lock.)
#[test]
fn a_new_lock_does_not_inherit_an_old_coast() {
    let a = Stream::new(160, 11, 3.2, 0.3, 0.0);
    let b = Stream::new(60, 12, 3.2, 0.7, 0.0);
    let mut rx = HansRx::new(40_000_000, Mode::Normal { channel: 1 }).unwrap();
    // Settled on A, a coast of ~100 frames, and A again after it.
    let (g0, long) = (50 * 25 + 3, 100 * 25);
    let events = feed(&mut rx, &a.words, &[(g0, long)], 64);
    let got = a.indices(&events);
    check_gap(&a, &got, (g0, g0 + long), 0, "long coast");
    assert!(rx.locked && !rx.timing.young());
    // Noise drops that lock.
    let n = noise(5, 400);
    rx.push(&[&n[..]; 5], &mut |_| {});
    assert!(!rx.locked, "noise kept the lock");
    // B: a new lock. A gap of 60 frame periods is within the bound, but not with
    // the old coast's ~100 added.
    let gap = 60 * 25;
    assert!(gap < rx.max_gap_words());
    let mut young_coasts = 0;
    for (k, part) in b.words.chunks(16).enumerate() {
        rx.push(&[part; 5], &mut |_| {});
        let mut copy = rx;
        copy.skip(gap, &mut |_| {});
        assert_eq!(copy.locked, rx.coasts(), "chunk {k}");
        young_coasts += usize::from(rx.coasts() && rx.timing.young());
    }
    assert!(
        young_coasts > 0,
        "the young fit's last frames were not reached"
    );
}
