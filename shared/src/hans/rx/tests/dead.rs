//! A channel that breaks mid-stream (stuck low, stuck high, noise) and comes back:
//! its counters grow every frame period while the other channels keep the frames
//! flowing, the bridge sees the same count, and it counts frames again once back.

use super::*;

/// Samples per frame at 40 MHz (3.2 per bit): 400, exactly 25 words, so pushing 25
/// words at a time feeds one frame period per push.
const PERIOD_WORDS: usize = 25;
const FRAMES: usize = 64;
/// The break starts mid-frame in period 20 and ends mid-frame in period 40.
const BREAK: usize = 20 * PERIOD_WORDS + 9;
const BACK: usize = 40 * PERIOD_WORDS + 17;

#[derive(Clone, Copy, Debug)]
enum Broken {
    Low,
    High,
    Noise,
}

/// The clean words, with `channel`'s (1..=5) replaced by `how` in `BREAK..BACK`.
fn streams(how: Broken, channel: usize) -> Vec<Vec<u16>> {
    let clean = oversample(&line_bits(&frames(FRAMES, 5)), 3.2, 0.3);
    let mut x = 0x9E37_79B9u32;
    let mut all = vec![clean; 5];
    for w in &mut all[channel - 1][BREAK..BACK] {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        *w = match how {
            Broken::Low => 0,
            Broken::High => 0xFFFF,
            Broken::Noise => x as u16,
        };
    }
    all
}

/// Per pushed period: frames published, and the counters of every channel after it.
struct Trace {
    published: Vec<usize>,
    stats: Vec<[ChannelStats; 5]>,
    /// Missing events per channel over the whole run.
    dropped: [u32; 5],
}

fn trace(mode: Mode, words: &[Vec<u16>]) -> Trace {
    let mut rx = HansRx::new(40_000_000, mode).unwrap();
    let mut t = Trace {
        published: Vec::new(),
        stats: Vec::new(),
        dropped: [0; 5],
    };
    for at in (0..words[0].len()).step_by(PERIOD_WORDS) {
        let end = (at + PERIOD_WORDS).min(words[0].len());
        let parts: [&[u16]; 5] = std::array::from_fn(|n| &words[n][at..end]);
        let mut frames = 0;
        rx.push(&parts, &mut |e| {
            if let LineEvent::Fault {
                line: crate::model::Line::HansChannel(c),
                kind: FaultKind::Missing,
            } = e.to_line_event()
            {
                t.dropped[usize::from(c) - 1] += 1;
            }
            frames += usize::from(matches!(e, RxEvent::Frame(_)));
        });
        t.published.push(frames);
        t.stats
            .push(std::array::from_fn(|n| rx.stats(n as u8 + 1).unwrap()));
    }
    t
}

/// Checks one mode with `channel` broken as `how`.
fn check(mode: Mode, channel: usize, how: Broken) {
    let label = format!("{mode:?} CH{channel} {how:?}");
    let t = trace(mode, &streams(how, channel));
    let periods = t.stats.len();
    let bad = channel - 1;
    let used = mode.channel_mask();
    let grew =
        |k: usize, f: fn(&ChannelStats) -> u32| f(&t.stats[k][bad]) - f(&t.stats[k - 1][bad]);
    let lost = |s: &ChannelStats| s.check_failures.wrapping_add(s.missing);
    // Two periods to notice the break (the cut frame fails, then the edge is gone);
    // every later period of the break counts one fault, and never a frame. A stuck
    // line is missing each period; noise may fail a check instead, and where normal
    // mode tracks the noise for a frame or two before it gives up, a decode may slip
    // into the next push: there the sum is checked, to one period.
    let start = BREAK / PERIOD_WORDS + 1;
    for k in start + 1..BACK / PERIOD_WORDS {
        let since = lost(&t.stats[k][bad]) - lost(&t.stats[start][bad]);
        assert!(
            since.abs_diff((k - start) as u32) <= 1,
            "{label}: period {k}"
        );
        assert_eq!(grew(k, |s| s.frames_ok), 0, "{label}: period {k}");
        if !matches!(how, Broken::Noise) {
            assert_eq!(grew(k, |s| s.missing), 1, "{label}: period {k} missing");
        }
        // The other channels keep the frames flowing (normal mode has none left).
        let want = usize::from(!matches!(mode, Mode::Normal { .. }));
        assert_eq!(t.published[k], want, "{label}: period {k} published");
    }
    // Back: it aligns again at a start edge and counts frames, nothing else.
    // Normal mode lost its timing: the new lock publishes after its acquisition.
    for k in BACK / PERIOD_WORDS + 4 + super::ACQUISITION..periods - 1 {
        assert_eq!(grew(k, |s| s.frames_ok), 1, "{label}: period {k} back");
        assert_eq!(grew(k, lost), 0, "{label}: period {k} back");
        assert_eq!(t.published[k], 1, "{label}: period {k} back");
    }
    let end = t.stats[periods - 1];
    for (n, (s, events)) in end.iter().zip(t.dropped).enumerate() {
        let ch = n + 1;
        // The bridge is told every missing period: as many events as counted.
        assert_eq!(events, s.missing, "{label}: CH{ch} events");
        if n == bad {
            continue;
        }
        // Healthy and unused channels: nothing missing (the acquisition before the
        // first lock is not counted), nothing failed.
        assert_eq!(s.missing, 0, "{label}: CH{ch}");
        assert_eq!(s.check_failures, 0, "{label}: CH{ch}");
        if used & (1 << n) == 0 {
            assert_eq!(*s, ChannelStats::default(), "{label}: unused CH{ch}");
        }
    }
    // Every locked period accounts for the broken channel exactly once.
    let s = end[bad];
    let from = t.stats[3][bad];
    let counted = s.frames_ok + s.check_failures + s.missing;
    let counted_from = from.frames_ok + from.check_failures + from.missing;
    assert!(
        (counted - counted_from).abs_diff((periods - 4) as u32) <= 1,
        "{label}: {s:?} from {from:?} over {periods} periods"
    );
}

#[test]
fn a_broken_channel_counts_every_period_in_every_mode() {
    for how in [Broken::Low, Broken::High, Broken::Noise] {
        check(Mode::Normal { channel: 2 }, 2, how);
        check(
            Mode::Vote3 {
                channels: [1, 3, 4],
            },
            3,
            how,
        );
        check(Mode::Vote5, 2, how);
        check(Mode::Super, 5, how);
        // The reference channel (the first used one) breaking costs nothing either.
        check(Mode::Super, 1, how);
    }
}
