//! Word-level bit gathering: the bit-centre samples of a 32-sample window are pulled
//! out with four multiplications instead of one step per bit.
//!
//! # Why it works
//! Inside a window the centres sit at samples `p0 < p1 < ...` (at most 12 of them at
//! 2.85 samples per bit, the slowest rate the timing accepts). They depend only on
//! where the first centre falls (the phase, quantised to 1/16 sample = one
//! [`Entry`] slot) and on the rate. Centres `k, k + 4, k + 8` form group `k % 4`; in
//! a group they are at least `4 × 2.85 - 1 = 10` samples apart. Multiplying the
//! window, masked to one group, by `Σ 2^(p_k - k)` moves centre `k` to bit `31 - k`
//! (the k-th bit of the result, first centre on top). Every other product term lands
//! at least 10 bits away from its own slot, which is never another slot of the same
//! group (those are 4 and 8 apart), and the terms below a slot add up to less than a
//! third of it, so no carry reaches it. Masking each product to its group's slots and
//! OR-ing the four gives the window's centre samples in order in the top bits.
//!
//! # Two windows per entry
//! An entry ([`Pair`]) covers two consecutive windows: the first window's centres
//! from the phase slot, and the second's from where the first's last centre plus
//! one bit lands (at the table's rate). The gather loop then looks up one entry,
//! loads two windows and appends up to 24 bits per step, halving the per-window
//! bookkeeping. The second window's centres come from the slot's middle at the
//! table's rate instead of the exact phase: they are off by at most 1/32 sample
//! (the slot) plus 1/32 sample (the rate slack over the 23 centres after the
//! first), plus, when the table's rate puts a centre just past a window's end that
//! really lies just before it, that centre's overshoot (the next entry starts at
//! phase 0): about 0.08 sample at most by this account, inside the 1/8 sample
//! `gather_matches_bit_by_bit` allows around a rounding boundary. **But** the
//! proptest `gather_reads_every_centre_anywhere` (any ring position, rate and
//! table rate within `RATE_SLACK`) finds centres read from the neighbouring
//! sample up to ~0.2 sample off (e.g. rate 232 881, table rate +71, first centre
//! 721 653 681: a window's last centre at x.84 read from the next window's first
//! sample); it allows 1/4 sample until that is traced. At 3x and ±25 % jitter a
//! centre has ~0.25 sample of margin, so this error eats into it.
//!
//! The entries are built lazily for the rate in use (a few dozen instructions each,
//! at most one per step) and all dropped when the tracked rate moves enough to
//! shift a centre by 1/32 sample over two windows; after acquisition that rarely
//! happens.

use super::ring::FRAC;

/// Phase slots per sample (1/16 sample each).
const SLOT_BITS: u32 = FRAC - 4;
/// Slots: phases 0..r for r up to 4.2 samples per bit, plus slack.
pub const SLOTS: usize = 72;
/// Largest rate change (Q16 samples per bit) an entry tolerates: 23 centres after
/// its first (the last of two windows of at most 12) it moves the last one by less
/// than 1/32 sample.
const RATE_SLACK: i32 = (1 << FRAC) / 32 / 24;
/// Result bits that can hold a group's centres: every group's product puts its
/// centres `k, k + 4, k + 8` at bits 31, 27, 23, and the four are then OR-ed in one
/// bit apart (the M7 shifts an operand for free), so one mask constant serves all.
const SLOTS_MASK: u32 = 1 << 31 | 1 << 27 | 1 << 23;

/// The centres of a window whose first centre is in one phase slot.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Entry {
    /// Group g's centre samples (bit 31 - p for sample p) and multiplier, side by
    /// side so that one double load fetches both.
    groups: [[u32; 2]; 4],
    /// Centres in the window.
    pub count: u32,
    /// All centre samples.
    pub all: u32,
}

impl Entry {
    /// The window's centre samples, first in bit 31, in its top `count` bits; the
    /// bits below are zero.
    /// `slots` is [`Table::slots`]: a run-time value, so the compiler keeps one
    /// mask register and shifted OR operands instead of four mask constants.
    #[inline(always)]
    pub fn bits(&self, x: u32, slots: u32) -> u32 {
        let [[m0, k0], [m1, k1], [m2, k2], [m3, k3]] = self.groups;
        let g = |m: u32, k: u32| (x & m).wrapping_mul(k) & slots;
        g(m0, k0) | g(m1, k1) >> 1 | g(m2, k2) >> 2 | g(m3, k3) >> 3
    }
}

/// The centres of two consecutive windows whose first centre is in one phase slot.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Pair {
    /// The first window.
    pub a: Entry,
    /// The second window, its first centre one bit after `a`'s last.
    pub b: Entry,
}

/// Stands for an entry out of range (cannot happen: the slot is clamped).
static EMPTY: Pair = Pair {
    a: Entry {
        groups: [[0; 2]; 4],
        count: 0,
        all: 0,
    },
    b: Entry {
        groups: [[0; 2]; 4],
        count: 0,
        all: 0,
    },
};

/// Entries for every phase slot at one rate.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Table {
    /// Always `SLOTS_MASK`.
    pub slots: u32,
    /// The rate the entries are built for (Q16 samples per bit).
    pub(super) ratio: i32,
    entries: [Pair; SLOTS],
}

impl Table {
    /// An empty table for `ratio` (Q16).
    pub fn new(ratio: i32) -> Table {
        Table {
            slots: SLOTS_MASK,
            ratio,
            entries: [Pair::default(); SLOTS],
        }
    }

    /// Makes the table fit `ratio`: drops every entry if it moved too far.
    pub fn follow(&mut self, ratio: i32) {
        if (ratio - self.ratio).abs() > RATE_SLACK {
            self.ratio = ratio;
            for e in self.entries.iter_mut() {
                e.a.count = 0;
            }
        }
    }

    /// The entry for two windows, the first of which has its first centre (plus
    /// half a sample) `phase` (Q16) after its start.
    #[inline(always)]
    pub fn entry(&mut self, phase: i32) -> &Pair {
        let slot = ((phase.max(0) >> SLOT_BITS) as usize).min(SLOTS - 1);
        let ratio = self.ratio;
        match self.entries.get_mut(slot) {
            Some(e) => {
                // A built entry has a centre in its first window (the slot lies
                // within 4.5 samples of its start), so 0 marks an unbuilt one.
                if e.a.count == 0 {
                    *e = pair(slot, ratio);
                }
                e
            }
            None => &EMPTY,
        }
    }
}

/// Builds the entry of phase slot `slot` at `ratio` (Q16), taking the slot's middle.
fn pair(slot: usize, ratio: i32) -> Pair {
    let first = ((slot as u32) << SLOT_BITS) + (1 << (SLOT_BITS - 1));
    let step = ratio.max(1 << FRAC) as u32;
    let a = build(first, step);
    // The first centre after window a, against the start of the next window.
    let next = first
        .wrapping_add(a.count.wrapping_mul(step))
        .wrapping_sub(32 << FRAC);
    Pair {
        a,
        b: build(next, step),
    }
}

/// Builds the entry of a window whose first centre (plus half a sample) is at `pos`
/// (Q16, below 32 samples) at `step` (Q16 samples per bit, at least one sample).
fn build(pos: u32, step: u32) -> Entry {
    let mut e = Entry::default();
    let mut pos = pos;
    let mut k = 0u32;
    while pos < 32 << FRAC && k < 12 {
        let p = pos >> FRAC;
        let g = (k % 4) as usize;
        if let Some([m, mult]) = e.groups.get_mut(g) {
            *m |= 1 << (31 - p);
            // Centre k goes to bit 31 - 4 (k / 4) of its group's product; p >= k
            // because centres are at least a sample apart.
            *mult = mult.wrapping_add(1 << (p - k / 4 * 4));
        }
        e.all |= 1 << (31 - p);
        k += 1;
        pos += step;
    }
    e.count = k;
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every entry at rates 2.85..4.2 samples per bit gathers exactly the samples at
    /// its centres, in order, for random windows and the all-ones / all-zeros ones.
    #[test]
    fn entries_gather_their_centres() {
        let mut x = 0x9E37_79B9u32;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        };
        let mut ratio = (2.85 * 65536.0) as i32;
        while ratio <= (4.2 * 65536.0) as i32 {
            for slot in 0..SLOTS as u32 {
                if (slot << SLOT_BITS) as i32 >= ratio {
                    break;
                }
                let e = build((slot << SLOT_BITS) + (1 << (SLOT_BITS - 1)), ratio as u32);
                let centres: Vec<u32> = (0..32).filter(|p| e.all & (1 << (31 - p)) != 0).collect();
                assert_eq!(centres.len() as u32, e.count);
                let mut windows = vec![0, u32::MAX];
                windows.extend((0..64).map(|_| next()));
                for w in windows {
                    let mut want = 0u32;
                    for (k, p) in centres.iter().enumerate() {
                        want |= ((w >> (31 - p)) & 1) << (31 - k);
                    }
                    assert_eq!(
                        e.bits(w, SLOTS_MASK),
                        want,
                        "ratio {ratio} slot {slot} window {w:#x}"
                    );
                }
            }
            ratio += 97;
        }
    }
}
