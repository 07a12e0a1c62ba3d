//! The bit loop shared by both waveform transmitters for up to three data lines
//! (XY2-100 X, Y, Z here; XY3-100 heads without U and W in `xy3::tx`). Both follow
//! item 4 of the README's "DMA buffer layouts": two BSRR words per bit, the first
//! setting CLK and every data line's level, the second only resetting CLK.
//!
//! Per bit the first word depends only on the three lines' bits, one of 8 patterns
//! ([`patterns`]). The pattern index of each bit time is gathered for eight bit
//! times of all three lines at once: each line's next byte is spread by a 256-entry
//! table so that bit `k` lands at bit `3k`, and the lines are merged one place
//! apart, so bits `3k + 2 ..= 3k` are the index of bit time `7 - k` (line 0 in the
//! index's bit 0). Two neighbouring 3-bit fields are then one 6-bit index into a
//! table holding the four words of both bit times ([`pair_patterns`]), copied as one
//! block ([`fill_pairs`]): no branches on the data and no per-bit gathering.
/// The spreading table of `BITS`-bit indices: entry `i` holds bit `k` of `i` at bit
/// `stride * k`. Built at compile time; the bit loops of both transmitters use one
/// (three lines: stride 3, eight bit times here; five lines: stride 5 in
/// `xy3::tx`).
pub(crate) const fn spread_table<const N: usize>(bits: u32, stride: u32) -> [u32; N] {
    let mut t = [0u32; N];
    let mut i = 0;
    while i < N {
        let mut k = 0;
        while k < bits {
            t[i] |= ((i as u32 >> k) & 1) << (stride * k);
            k += 1;
        }
        i += 1;
    }
    t
}

/// Bit `k` of the index at bit `3k` (k < 8).
const SPREAD3: [u32; 256] = spread_table(8, 3);

/// The low byte of `v` spread three places apart (bits above 7 ignored).
#[inline(always)]
fn spread(v: u32) -> u32 {
    SPREAD3.get((v & 0xFF) as usize).copied().unwrap_or(0)
}

/// The pattern indices of eight bit times of three lines (the low bytes of `lines`,
/// the earliest bit in bit 7): bit time `7 - k` in bits `3k + 2 ..= 3k`, line `i` in
/// the index's bit `i`.
#[inline(always)]
pub(crate) fn merge([a, b, c]: [u32; 3]) -> u32 {
    spread(a) | spread(b) << 1 | spread(c) << 2
}

/// The rising word of every pattern of one bit on three lines: `rise` (CLK, and SYNC
/// on XY2-100) set, each line's pin (`lanes`, set-bit masks; 0 for a line without a
/// pin, whose bit then selects identical entries) set for 1 and reset for 0. Bit `i`
/// of the index is line `i`.
pub(crate) fn patterns(rise: u32, lanes: [u32; 3]) -> [u32; 8] {
    let data = lanes.iter().fold(0, |a, &m| a | m);
    let mut t = [0u32; 8];
    for (v, entry) in t.iter_mut().enumerate() {
        let set = lanes
            .iter()
            .enumerate()
            .filter(|(i, _)| v >> i & 1 != 0)
            .fold(0, |a, (_, &m)| a | m);
        *entry = rise | set | (data ^ set) << 16;
    }
    t
}

/// Words per entry of [`pair_patterns`]' table: the five words [`fill_pairs`] copies and
/// three of padding, so an entry's address is the 6-bit index shifted, with no
/// multiply.
pub(crate) const ENTRY: usize = 8;

/// The words of two consecutive bit times per pair of patterns: entry `8 e + l`
/// starts with the rising word of pattern `e` (the earlier bit time), `fall`, the
/// rising word of pattern `l` (the later one), `fall`, then `fall` once more as the
/// fifth word [`fill_pairs`] copies (the first word of the next bit time, which the
/// next copy writes over); the padding is 0.
pub(crate) fn pair_patterns(patterns: &[u32; 8], fall: u32) -> [[u32; ENTRY]; 64] {
    let mut t = [[0u32; ENTRY]; 64];
    for (early, row) in patterns.iter().zip(t.chunks_exact_mut(8)) {
        for (late, entry) in patterns.iter().zip(row) {
            if let Some(head) = entry.first_chunk_mut::<5>() {
                *head = [*early, fall, *late, fall, fall];
            }
        }
    }
    t
}

/// Writes the `4 * PAIRS` words of the first `2 * PAIRS` bits (at most 32) of the
/// MSB-aligned line words `lines` (the first bit on the wire in bit 31) into `out`,
/// two bit times per entry of `table` ([`pair_patterns`]). `WORDS` is `4 * PAIRS`
/// (XY2-100: the last two bits are four single copies) or one more, a word after
/// the bits that the loop may scratch (XY3-100, which writes SYNC's rise there
/// afterwards). Fully unrolled for constant sizes.
///
/// Why two bit times and five words per copy: a block copy of more than four words
/// is one load-multiple and one store-multiple on the Cortex-M7 (four words the
/// compiler splits into single loads and stores), so every two bits cost one field
/// extract, two address computations and the block copy (five instructions) instead
/// of an extract, a load and two stores per bit (eight). The copies overlap by one
/// word, the next entry's first word writing over the previous entry's fifth, so
/// they run in order. The compiler would see that fifth word overwritten and shorten
/// each copy to four words again, so two optimisation barriers keep it whole: `out`'s
/// address is handed to `black_box` once (it then counts as visible outside the
/// function), and `black_box(())` after each copy (no instruction) is an opaque step
/// that might read it. The words written are the same either way; only the count of
/// instructions depends on the barriers, and the bench shows it.
#[inline(always)]
pub(crate) fn fill_pairs<const PAIRS: usize, const WORDS: usize>(
    table: &[[u32; ENTRY]; 64],
    lines: [u32; 3],
    out: &mut [u32; WORDS],
) {
    const {
        assert!(PAIRS <= 16, "a line word holds at most 32 bits");
        assert!(WORDS == 4 * PAIRS || WORDS == 4 * PAIRS + 1);
    };
    // Group g holds bits 31 - 8g ..= 24 - 8g of every line; its bit time `7 - k`
    // is the merged word's field `3k + 2 ..= 3k`, so the bit times `2j` and
    // `2j + 1` of the group are the 6-bit field at `18 - 6j` (the earlier one
    // high). All groups are gathered first: the lines are then no longer needed
    // while the block copies take their registers. The compiler would load every
    // group's spread bytes first and merge each group only before its copies,
    // parking the loaded bytes on the stack meanwhile (nine spills and reloads for
    // the four groups of a 32-bit frame); passing the merged groups through
    // `black_box` makes it merge them at once and park four words instead
    // (XY3-100 32-bit: 163 -> 153 instructions per fill; XY2-100 one more, 116 ->
    // 117, taken for one loop for both).
    let groups: [u32; 4] = core::array::from_fn(|g| merge(lines.map(|l| l >> (24 - 8 * g))));
    let groups = core::hint::black_box(groups);
    core::hint::black_box(out.as_mut_ptr());
    for (g, &merged) in groups.iter().enumerate().take(PAIRS.div_ceil(4)) {
        for j in 0..4 {
            let pair = 4 * g + j;
            if pair >= PAIRS {
                break;
            }
            let Some(entry) = table.get((merged >> (18 - 6 * j as u32) & 63) as usize) else {
                continue;
            };
            let at = 4 * pair;
            if let (Some(to), Some(from)) = (out.get_mut(at..at + 5), entry.get(..5)) {
                to.copy_from_slice(from);
                core::hint::black_box(());
            } else if let (Some(to), Some(from)) = (out.get_mut(at..at + 4), entry.get(..4)) {
                // The last two bits without a word to scratch.
                to.copy_from_slice(from);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// `merge` puts bit k of line i at 3k + i.
        #[test]
        fn merge_matches_bit_by_bit(lines in any::<[u32; 3]>()) {
            let mut want = 0;
            for k in 0..8 {
                for (i, v) in lines.into_iter().enumerate() {
                    want |= (v >> k & 1) << (3 * k + i as u32);
                }
            }
            prop_assert_eq!(merge(lines), want);
        }
    }
}
