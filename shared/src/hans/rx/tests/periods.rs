//! The period outcome of the vote and super modes: every decoded period ends in
//! exactly one frame or one period fault (`channel: None`), whatever its channels
//! reported, and a lost timing reports a period resync. The bridge relies on it to
//! tell a lost period (breaks its recovery run) from a channel fault the mode rode
//! through (counted only).

use super::*;

/// Flips one data bit (never the start marker or its edge) in about `per_mille` of
/// every channel's frames, independently per channel.
fn flipped(sent: &[Frame], per_mille: u32, seed: u32) -> Vec<Vec<u16>> {
    let clean = line_bits(sent);
    let mut x = seed.max(1);
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        x
    };
    (0..CHANNELS)
        .map(|_| {
            let mut bits = clean.clone();
            for f in 0..sent.len() {
                if next() % 1000 < per_mille {
                    let at = f * FRAME_BITS + 10 + (next() as usize % (FRAME_BITS - 12));
                    bits[at] = !bits[at];
                }
            }
            oversample(&bits, 3.2, 0.3)
        })
        .collect()
}

#[test]
fn every_decoded_period_ends_in_one_frame_or_one_period_fault() {
    let sent = frames(400, 31);
    for (per_mille, seed) in [(250, 3), (400, 4)] {
        let words = flipped(&sent, per_mille, seed);
        for mode in [
            Mode::Vote3 {
                channels: [2, 3, 5],
            },
            Mode::Vote5,
            Mode::Super,
        ] {
            let label = format!("{mode:?} {per_mille}/1000");
            let mut rx = HansRx::new(40_000_000, mode).unwrap();
            let mut events = Vec::new();
            for at in (0..words[0].len()).step_by(25) {
                let end = (at + 25).min(words[0].len());
                let parts: [&[u16]; 5] = std::array::from_fn(|n| &words[n][at..end]);
                rx.push(&parts, &mut |e| events.push(e));
            }
            let frames = published(&events);
            let period = |k: FaultKind| {
                events
                    .iter()
                    .filter(|e| {
                        **e == RxEvent::Fault {
                            channel: None,
                            kind: k,
                        }
                    })
                    .count()
            };
            // Flips never touch the timing, and at these rates no three periods in a
            // row lose every used channel (a false-lock guard would start a hunt):
            // no loss, so every used channel counts
            // every decoded period once (frames ok, check failure or missing).
            assert_eq!(period(FaultKind::Resync), 0, "{label}");
            let outcomes =
                frames.len() + period(FaultKind::CheckFailed) + period(FaultKind::Disagree);
            for ch in bits(mode.channel_mask()) {
                let s = rx.stats(number(ch)).unwrap();
                let decoded = (s.frames_ok + s.check_failures + s.missing) as usize;
                // The young lock's periods publish nothing and report nothing.
                assert_eq!(
                    decoded,
                    outcomes + super::ACQUISITION,
                    "{label}: CH{}",
                    number(ch)
                );
            }
            // Channels failed a lot, periods were lost, and no flipped frame got out.
            let failed: u32 = (1..=5).map(|c| rx.stats(c).unwrap().check_failures).sum();
            assert!(failed > 100, "{label}: {failed}");
            assert_eq!(
                u32::try_from(outcomes - frames.len()).unwrap(),
                rx.rejected()
            );
            let first = sent.iter().position(|f| Some(f) == frames.first()).unwrap();
            assert!(first <= super::LOCK, "{label}");
            let mut rest = sent[first..].iter();
            for f in &frames {
                assert!(
                    rest.any(|s| s == f),
                    "{label}: a frame not sent, or out of order"
                );
            }
        }
    }
}

/// Every channel dying at once: the vote and super modes report the lost timing
/// as a period resync (normal mode says it with its channel's resync).
#[test]
fn a_lost_timing_is_a_period_fault() {
    let sent = frames(60, 8);
    let mut words = oversample(&line_bits(&sent), 3.2, 0.3);
    for w in &mut words[30 * 25..] {
        *w = 0;
    }
    for mode in MODES {
        let mut rx = HansRx::new(40_000_000, mode).unwrap();
        let events = run(&mut rx, &words, 25);
        let period_resyncs = events
            .iter()
            .filter(|e| {
                **e == RxEvent::Fault {
                    channel: None,
                    kind: FaultKind::Resync,
                }
            })
            .count();
        let want = usize::from(!matches!(mode, Mode::Normal { .. }));
        assert_eq!(period_resyncs, want, "{mode:?}");
        assert!(events.iter().any(|e| matches!(
            e,
            RxEvent::Fault {
                channel: Some(_),
                kind: FaultKind::Resync
            }
        )));
    }
}
