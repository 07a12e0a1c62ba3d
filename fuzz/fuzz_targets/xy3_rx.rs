#![no_main]
//! XY3-100 line receiver: arbitrary bytes and end positions in any interleaving never
//! panic, every poll terminates, and every frame reported valid re-encodes to a word
//! that decodes to the same frame.

use shared::model::{Axis, LineEvent};
use shared::xy3::rx::{Lines, Receiver};
use shared::xy3::{decode, encode};

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&select, mut rest)) = data.split_first() else {
        return;
    };
    // X always, the others by the selector's bits.
    let axes: Vec<Axis> = Axis::ALL
        .into_iter()
        .filter(|a| *a == Axis::X || select >> a.index() & 1 == 1)
        .collect();
    let Some(lines) = Lines::new(&axes) else {
        return;
    };
    let origin = u32::from(select >> 5) << 29;
    let mut rx = Receiver::with_origin(lines, origin);
    let mut end = origin;
    while let Some((&op, tail)) = rest.split_first() {
        rest = tail;
        let n = usize::from(op >> 2);
        match op & 3 {
            // Bytes: n per line (line i takes every i-th of the next bytes).
            0 | 1 => {
                let take = (n * axes.len()).min(rest.len());
                let (chunk, tail) = rest.split_at(take);
                rest = tail;
                let per = take / axes.len();
                let slices: Vec<Vec<u8>> = (0..axes.len())
                    .map(|i| {
                        chunk
                            .iter()
                            .skip(i)
                            .step_by(axes.len())
                            .take(per)
                            .copied()
                            .collect()
                    })
                    .collect();
                let refs: Vec<&[u8]> = slices.iter().map(Vec::as_slice).collect();
                assert!(rx.push_bytes(&refs).is_ok());
            }
            // End positions: small steps (mostly plausible frames).
            2 => {
                let steps: Vec<u32> = rest
                    .iter()
                    .take(n.min(16))
                    .map(|&s| {
                        end = end.wrapping_add(u32::from(s % 6));
                        end
                    })
                    .collect();
                rest = rest.get(steps.len()..).unwrap_or_default();
                rx.push_ends(&steps);
            }
            // A raw end position (anything, including backwards).
            _ => {
                let mut raw = [0u8; 4];
                for (d, s) in raw.iter_mut().zip(rest) {
                    *d = *s;
                }
                rest = rest.get(4..).unwrap_or_default();
                end = u32::from_le_bytes(raw);
                rx.push_ends(&[end]);
            }
        }
        let mut polls = 0;
        while let Some(period) = rx.poll() {
            polls += 1;
            assert!(polls <= 64, "more periods than queued end positions");
            for frame in period.lines.iter().flatten().flatten() {
                let (word, size) = encode(frame).expect("a decoded frame re-encodes");
                assert_eq!(decode(word, size), Ok(*frame));
            }
            let mut frames = 0;
            period.for_each_event(|e| frames += usize::from(matches!(e, LineEvent::Frame(_))));
            assert_eq!(frames, usize::from(period.all_ok()));
        }
    }
});
