//! The bit loop shared by both waveform transmitters for up to three data lines
//! (XY2-100 X, Y, Z here; XY3-100 heads without U and W in `xy3::tx`). Both follow
//! item 4 of the README's "DMA buffer layouts": two BSRR words per bit, the first
//! setting CLK and every data line's level, the second only resetting CLK.
//!
//! Per bit the first word depends only on the three lines' bits, so a table of the 8
//! patterns gives it with one look-up. The pattern index of each bit time is gathered
//! for eight bit times of all three lines at once: each line's next byte is spread by
//! a 256-entry table so that bit `k` lands at bit `3k`, and the lines are merged one
//! place apart, so bits `3k + 2 ..= 3k` are the index of bit time `7 - k` (line 0 in
//! the index's bit 0). Per bit that leaves one field extract, one look-up and one
//! store of the word with the constant CLK-reset word (a 64-bit store on the
//! Cortex-M7): no branches on the data and no per-bit gathering.

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

/// Writes the word pairs of the first `BITS` bits (at most 32) of the MSB-aligned
/// line words `lines` (the first bit on the wire in bit 31) into `out`: per bit the
/// rising word from `patterns` and `fall`. Fully unrolled for a constant `BITS`.
#[inline(always)]
pub(crate) fn fill<const BITS: usize>(
    patterns: &[u32; 8],
    fall: u32,
    lines: [u32; 3],
    out: &mut [[u32; 2]; BITS],
) {
    const { assert!(BITS <= 32, "a line word holds at most 32 bits") };
    for (g, group) in out.chunks_mut(8).enumerate() {
        // Group g holds bits 31 - 8g ..= 24 - 8g of every line.
        let shift = 24u32.saturating_sub(8 * g as u32);
        let merged = merge(lines.map(|l| l >> shift));
        for (pair, k) in group.iter_mut().zip((0..8u32).rev()) {
            let rise = patterns.get((merged >> (3 * k) & 7) as usize);
            *pair = [rise.copied().unwrap_or(0), fall];
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
