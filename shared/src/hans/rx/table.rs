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
//! bookkeeping.
//!
//! # How far a centre is read from where it lies
//! The gather carries the exact phase of the next centre (the receiver's first
//! centre plus whole bits at its rate, in Q16) from entry to entry, advancing it
//! by the centres the entry said its windows hold, so the table's errors do not
//! add up along a frame. Inside an entry, centre `k` (counted from the slot's
//! first, `k <= 22`: two windows hold at most 23 centres at 2.85 samples per bit)
//! is put at the slot's middle plus `k` bits at the table's rate instead of at
//! the phase plus `k` bits at the true rate: at most half a slot (1/32 sample)
//! plus `22 × RATE_SLACK` (`Table::follow` lets the rate drift that far before it
//! drops the entries) off, `ERROR` = 3 918 / 65 536 ≈ 0.060 sample. A centre
//! whose exact position is more than that from a sample boundary is therefore
//! read from its own sample.
//!
//! One consequence must be caught: a centre within `ERROR` before a window's
//! end can be put past it. The entry then does not gather it, and the next
//! entry's phase is slightly negative (the centre lies in the window before). The
//! table has `BELOW` slots for such phases, whose entries read their first
//! centre from sample 0 (still within `ERROR` of it: reading it is the same
//! near-boundary case) and put every other one where it belongs. Before they
//! existed a negative phase was clamped to slot 0: the entry put all its centres
//! 1/32 sample plus the overshoot late, so at a rate just below `32 / n` samples
//! per bit (`n` centres per window; 4.0 and 3.2 are the 50 and 40 MHz clocks,
//! there with the sender up to ~0.09 % fast) its last centre was put past the
//! end again, in every following entry too, and the error grew by
//! `64 - 2n × rate` samples (up to ~0.055) per entry for the rest of the frame:
//! about 0.4 sample at most (the proptest `gather_reads_every_centre_anywhere`
//! met 0.23, a random search near those rates 0.37). At 3x an entry's phase
//! steps by a third of a bit from one to the next, so only lone entries were
//! hurt there (~0.11 sample).
//!
//! The entries are built lazily for the rate in use (a few dozen instructions each,
//! at most one per step) and all dropped when the tracked rate moves enough to
//! shift a centre by 1/32 sample over two windows; after acquisition that rarely
//! happens.

use super::ring::FRAC;

/// Phase slots per sample (1/16 sample each).
const SLOT_BITS: u32 = FRAC - 4;
/// Slots: phases -1/16..r for r up to 4.2 samples per bit, plus slack.
pub const SLOTS: usize = 72;
/// Slots below phase 0 (the first ones): a centre the previous entry put past
/// its window's end lies up to `ERROR` before the next window's start.
const BELOW: i32 = 1;
/// Largest rate change (Q16 samples per bit) an entry tolerates: 22 centres after
/// its first (the last of the at most 23 in two windows) it moves the last one by
/// less than 1/32 sample.
const RATE_SLACK: i32 = (1 << FRAC) / 32 / 24;
/// Most a gathered centre lies from where the table puts it (Q16): half a slot
/// plus the rate slack over the 22 centres after an entry's first (module doc).
pub(super) const ERROR: i32 = (1 << (SLOT_BITS - 1)) + 22 * RATE_SLACK;
const _: () = assert!(
    ERROR < BELOW << SLOT_BITS,
    "a negative phase needs its slot"
);
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
    /// half a sample) `phase` (Q16) after its start; `phase` may be down to
    /// `-ERROR` (module doc), the entry then reads that centre from sample 0.
    #[inline(always)]
    pub fn entry(&mut self, phase: i32) -> &Pair {
        let slot = slot(phase);
        let ratio = self.ratio;
        match self.entries.get_mut(slot) {
            Some(e) => {
                // A built entry has a centre in its first window (the slot lies
                // within 4.44 samples of its start), so 0 marks an unbuilt one.
                if e.a.count == 0 {
                    *e = pair(slot, ratio);
                }
                e
            }
            None => &EMPTY,
        }
    }
}

impl Table {
    /// The sample (counted from its first window's start) at which the entry
    /// [`Table::entry`] gives for `phase` reads that window's centre `k`: 32 or
    /// more when the window has no centre `k`. The entries are built at the
    /// table's rate (`follow` drops them all when it changes), so this is where
    /// the entry put it, without walking its centres: the gather masks a window's
    /// first or last centres off in one step.
    #[inline(always)]
    pub fn centre(&self, phase: i32, k: u32) -> u32 {
        let pos = slot_first(slot(phase)).wrapping_add((k as i32).wrapping_mul(step(self.ratio)));
        pos.max(0) as u32 >> FRAC
    }
}

/// The phase slot of `phase` (Q16, clamped to the table).
#[inline(always)]
fn slot(phase: i32) -> usize {
    // Offset before clamping: the compiler folds the constant into the gather's
    // phase arithmetic, so the lookup gets no longer.
    let slot = phase.wrapping_add(BELOW << SLOT_BITS).max(0) >> SLOT_BITS;
    (slot as usize).min(SLOTS - 1)
}

/// The middle of phase slot `slot` (Q16; negative for the `BELOW` slots): where
/// its entry puts the first centre.
#[inline(always)]
fn slot_first(slot: usize) -> i32 {
    ((slot as i32 - BELOW) << SLOT_BITS) + (1 << (SLOT_BITS - 1))
}

/// The distance between centres the entries are built with at `ratio`.
#[inline(always)]
fn step(ratio: i32) -> i32 {
    ratio.max(1 << FRAC)
}

/// Builds the entry of phase slot `slot` at `ratio` (Q16), taking the slot's middle
/// (negative for the `BELOW` slots).
fn pair(slot: usize, ratio: i32) -> Pair {
    let first = slot_first(slot);
    let step = step(ratio);
    let a = build(first, step);
    // The first centre after window a, against the start of the next window.
    let next = first
        .wrapping_add((a.count as i32).wrapping_mul(step))
        .wrapping_sub(32 << FRAC);
    Pair {
        a,
        b: build(next, step),
    }
}

/// Builds the entry of a window whose first centre (plus half a sample) is at `pos`
/// (Q16, below 32 samples; a negative one is read from sample 0) at `step` (Q16
/// samples per bit, at least one sample).
fn build(pos: i32, step: i32) -> Entry {
    let mut e = Entry::default();
    let mut pos = pos;
    let mut k = 0u32;
    while pos < 32 << FRAC && k < 12 {
        let p = pos.max(0) as u32 >> FRAC;
        let g = (k % 4) as usize;
        if let Some([m, mult]) = e.groups.get_mut(g) {
            *m |= 1 << (31 - p);
            // Centre k goes to bit 31 - 4 (k / 4) of its group's product; p >= k
            // because centres are at least a sample apart.
            *mult = mult.wrapping_add(1 << (p - k / 4 * 4));
        }
        e.all |= 1 << (31 - p);
        k += 1;
        pos = pos.saturating_add(step);
    }
    e.count = k;
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Table::centre` names the sample of every centre of every built entry's
    /// first window, in order, and 32 or more past its last, at rates 2.85..4.2
    /// samples per bit and phases from below the first slot to past the last.
    #[test]
    fn centre_is_where_the_entry_reads() {
        let mut ratio = (2.85 * 65536.0) as i32;
        while ratio <= (4.2 * 65536.0) as i32 {
            let mut table = Table::new(ratio);
            for phase in (-(2 << SLOT_BITS)..(SLOTS as i32 + 2) << SLOT_BITS).step_by(37) {
                let e = table.entry(phase).a;
                let samples: Vec<u32> = (0..32).filter(|p| e.all & (1 << (31 - p)) != 0).collect();
                assert_eq!(samples.len() as u32, e.count);
                for k in 0..=13u32 {
                    let at = table.centre(phase, k);
                    match samples.get(k as usize) {
                        Some(&p) => assert_eq!(at, p, "ratio {ratio} phase {phase} k {k}"),
                        None => assert!(at >= 32, "ratio {ratio} phase {phase} k {k}: {at}"),
                    }
                }
            }
            ratio += 97;
        }
    }

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
                let e = build(
                    ((slot as i32 - BELOW) << SLOT_BITS) + (1 << (SLOT_BITS - 1)),
                    ratio,
                );
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
