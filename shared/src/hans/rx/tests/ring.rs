//! The ring's fast paths held to their general versions: a store against a
//! word-by-word model of the ring, the five-ring store of
//! vote5 / super mode against five single-ring stores, and the centre compare's
//! slice walk (windows that do not wrap) against a sample-by-sample compare.

use super::super::ring::{Centres, Ring, RING_WORDS};
use super::super::table::Table;
use proptest::prelude::*;

/// Five rings filled with `fill` (per ring: words stored from stream word `from`).
fn rings(fill: &[Vec<u16>; 5], from: u32) -> [Ring; 5] {
    let mut rings = [Ring::default(); 5];
    for (ring, words) in rings.iter_mut().zip(fill) {
        for (k, chunk) in words.chunks(RING_WORDS / 2).enumerate() {
            ring.write(from.wrapping_add((k * RING_WORDS / 2) as u32), chunk);
        }
    }
    rings
}

/// Sample `s` (modulo the ring) of `ring`.
fn sample(ring: &Ring, s: i64) -> u32 {
    let s = s.rem_euclid((RING_WORDS * 16) as i64) as u32;
    ring.window(s >> 5) >> (31 - (s & 31)) & 1
}

proptest! {
    /// A store of any length (none, odd, up to more than a lap) from any stream
    /// word leaves every window as a ring of words written one after the other
    /// has it: the two slot runs (to the ring's end, then from its start) and
    /// the half windows at both ends in place, older words kept.
    #[test]
    fn write_matches_word_model(
        fill in proptest::collection::vec(any::<u16>(), RING_WORDS),
        at in any::<u32>(),
        words in proptest::collection::vec(any::<u16>(), 0..=RING_WORDS + 9),
    ) {
        let mut ring = Ring::default();
        ring.write(0, &fill[..RING_WORDS / 2]);
        ring.write(RING_WORDS as u32 / 2, &fill[RING_WORDS / 2..]);
        let mut model = fill.clone();
        for (i, &w) in words.iter().enumerate() {
            model[(at as usize).wrapping_add(i) % RING_WORDS] = w;
        }
        ring.write(at, &words);
        for j in 0..RING_WORDS / 2 {
            let want = u32::from(model[2 * j]) << 16 | u32::from(model[2 * j + 1]);
            prop_assert_eq!(ring.window(j as u32), want, "window {}", j);
        }
    }

    /// The five-ring store of words `from .. from + len` of five chunks equals five
    /// single-ring stores, at any ring position and word parity; a chunk missing
    /// or too short for the range refuses the store and leaves every ring as it
    /// was.
    #[test]
    fn write_all_matches_five_writes(
        fill in proptest::array::uniform5(proptest::collection::vec(any::<u16>(), RING_WORDS)),
        from_ring in any::<u32>(),
        at in any::<u32>(),
        from in 0usize..8,
        len in 0usize..=RING_WORDS / 2,
        words in proptest::array::uniform5(proptest::collection::vec(any::<u16>(), RING_WORDS / 2 + 8)),
        short in proptest::option::of((0usize..5, 0usize..8)),
        chunk_count in 4usize..=6,
    ) {
        let before = rings(&fill, from_ring);
        // The chunks end right after the range, or (`short`) up to 8 words early.
        let chunks: Vec<&[u16]> = (0..chunk_count)
            .map(|k| {
                let end = match short {
                    Some((s, cut)) if s == k % 5 => (from + len).saturating_sub(cut + 1),
                    _ => from + len,
                };
                &words[k % 5][..end]
            })
            .collect();
        let mut fast = before;
        let stored = Ring::write_all(&mut fast, at, &chunks, from, len);
        let fits = chunks.len() >= 5 && chunks.iter().take(5).all(|c| c.len() >= from + len);
        prop_assert_eq!(stored, fits);
        if fits {
            let mut general = before;
            for (ring, c) in general.iter_mut().zip(&chunks) {
                ring.write(at, &c[from..from + len]);
            }
            prop_assert_eq!(fast, general);
        } else {
            prop_assert_eq!(fast, before);
        }
    }

    /// `agrees` is true exactly when the channel, `d` samples later, has the
    /// reference's sample at every centre, wherever the frame lies in the ring
    /// (wrapping or not) and for matching, shifted and corrupted channels.
    #[test]
    fn agrees_matches_sample_by_sample(
        reference in proptest::collection::vec(any::<u16>(), RING_WORDS),
        noise in proptest::collection::vec(any::<u16>(), RING_WORDS),
        d in -40i32..=40,
        start in 0u32..(RING_WORDS as u32 * 16),
        ratio in (3.0f64..4.0).prop_map(|r| (r * 65536.0) as u32),
        flip in proptest::option::of(0u32..(RING_WORDS as u32 * 16)),
        random_channel in any::<bool>(),
    ) {
        let mut ref_ring = Ring::default();
        ref_ring.write(0, &reference[..RING_WORDS / 2]);
        ref_ring.write(RING_WORDS as u32 / 2, &reference[RING_WORDS / 2..]);
        // The channel: the reference delayed by `d` samples (or noise), with one
        // sample flipped.
        let total = RING_WORDS * 16;
        let mut words = [0u16; RING_WORDS];
        for s in 0..total {
            let bit = if random_channel {
                u32::from(noise[s / 16] >> (15 - s % 16) & 1)
            } else {
                sample(&ref_ring, s as i64 - i64::from(d))
            } ^ u32::from(flip == Some(s as u32));
            words[s / 16] |= (bit as u16) << (15 - s % 16);
        }
        let mut channel = Ring::default();
        channel.write(0, &words[..RING_WORDS / 2]);
        channel.write(RING_WORDS as u32 / 2, &words[RING_WORDS / 2..]);
        let mut table = Table::new(ratio as i32);
        let mut centres = Centres::default();
        let first = (start << 16).wrapping_add(ratio / 2);
        ref_ring.gather::<true>(&mut table, first, ratio, &mut centres);
        let mut want = true;
        for (i, [m, v]) in centres.windows[..centres.count].iter().enumerate() {
            for b in 0..32 {
                if m >> (31 - b) & 1 == 1 {
                    let s = i64::from(centres.first) * 32 + (i * 32 + b) as i64;
                    prop_assert_eq!(v >> (31 - b) & 1, sample(&ref_ring, s));
                    want &= sample(&channel, s + i64::from(d)) == sample(&ref_ring, s);
                }
            }
        }
        prop_assert_eq!(channel.agrees(&centres, d), want);
    }
}
