//! What the receiver keeps per channel: the start-edge hunt used while no frame
//! timing is known, and, once it is, the channel's delay against the shared timing.
//!
//! # Hunt (spec "receiving" item 2)
//! The only run of three or more equal bits in a frame is the stop field (`1 1 1`,
//! possibly preceded by a complement `1`), and it is always followed by the start bit
//! `0` (marker `1 1 1 0 1`). A falling edge after at least 2.5 bit times of ones is
//! therefore a frame-start candidate. Word-parallel: falling edges are
//! `!w & (w >> 1 | carry)`, visited with `leading_zeros`, and a run's length comes
//! from the nearest zero before it. A second candidate one frame period (±5 %) after
//! the first measures the bit rate before any bit is trusted; the first channel to
//! get there sets the shared timing ([`super::timing`]).
//!
//! # Delay
//! All channels come from one sender clock, so they share bit rate and phase up to a
//! fixed skew. Each channel's start edge is measured every frame; its offset from the
//! shared frame start is averaged (plain mean over the first 16 frames, then a 1/16
//! filter, each step clamped to one sample so a glitch cannot throw it).

use super::ring::{diff, Ring, FRAC, HALF};

/// Measurements after which the delay filter stops narrowing.
const DELAY_FITS: i32 = 16;
/// Largest delay against the shared timing (samples): two samples of skew plus jitter
/// and filter slack. A channel further off is not the same line.
pub const DELAY_MAX: i32 = 8 << FRAC;

/// Per-channel state.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Channel {
    /// Length in samples of the run of ones that ends with the last word (hunt).
    run: u32,
    /// The unconfirmed start candidate (hunt).
    first: Option<u32>,
    /// Delay against the shared timing (Q16 samples), `None` while not aligned.
    pub delay: Option<i32>,
    /// Delay measurements so far (selects the filter gain).
    fits: i32,
    /// Consecutive patterns that failed their checks.
    pub failures: u8,
}

impl Channel {
    /// Forgets the hunt (called when the shared timing locks or is lost).
    pub fn reset_hunt(&mut self) {
        self.run = 0;
        self.first = None;
    }

    /// Drops the alignment. Returns true if the channel was aligned.
    pub fn unalign(&mut self) -> bool {
        self.failures = 0;
        self.fits = 0;
        self.delay.take().is_some()
    }

    /// True when the delay filter has settled (aligned and measured often enough).
    pub fn settled(&self) -> bool {
        self.delay.is_some() && self.fits >= DELAY_FITS
    }

    /// Aligns the channel with its first measured delay.
    pub fn align(&mut self, delay: i32) {
        if (-DELAY_MAX..=DELAY_MAX).contains(&delay) {
            self.delay = Some(delay);
            self.fits = 1;
            self.failures = 0;
        }
    }

    /// Moves the delay toward `measured`, the channel's start edge against the
    /// shared one (see the module docs). Returns false (and unaligns) if the channel
    /// drifted out of the plausible range.
    pub fn track(&mut self, measured: i32) -> bool {
        let Some(d) = self.delay else { return false };
        self.fits = (self.fits + 1).min(DELAY_FITS);
        let step = measured.saturating_sub(d).clamp(-(1 << FRAC), 1 << FRAC) / self.fits;
        let d = d + step;
        if (-DELAY_MAX..=DELAY_MAX).contains(&d) {
            self.delay = Some(d);
            true
        } else {
            self.unalign();
            false
        }
    }

    /// Hunts in word `w` (stream word `index`, bit 15 first, `prev` the word before).
    /// `threshold` is the shortest run of ones (samples) before a candidate, `bounds`
    /// the plausible frame periods (Q16). Returns the confirmed start edge and the
    /// measured period when a candidate falls one period after the previous one.
    pub fn hunt(
        &mut self,
        index: u32,
        w: u32,
        prev: u32,
        threshold: u32,
        bounds: (i32, i32),
    ) -> Option<(u32, i32)> {
        let x = prev << 16 | w;
        let mut falls = !x & (x >> 1) & 0xFFFF;
        let base = index << (FRAC + 4);
        let mut found = None;
        while falls != 0 {
            let j = 31 - falls.leading_zeros();
            let s = 15 - j;
            falls &= !(1 << j);
            // Zeros earlier than s in this word: the nearest one bounds the run.
            let zeros = !w & 0xFFFF & !((2u32 << j) - 1);
            let run = if zeros == 0 {
                self.run.saturating_add(s)
            } else {
                zeros.trailing_zeros() - j - 1
            };
            if run < threshold {
                continue;
            }
            let meas = base.wrapping_add(s << FRAC).wrapping_sub(HALF);
            if let Some(first) = self.first {
                let d = diff(meas, first);
                if (bounds.0..=bounds.1).contains(&d) {
                    found = Some((meas, d));
                    break;
                }
            }
            // No candidate yet, or too close or too far: one of the two was not a
            // frame start. The newer one is the better guess.
            self.first = Some(meas);
        }
        let ones = w.trailing_ones();
        self.run = if ones >= 16 {
            self.run.saturating_add(16)
        } else {
            ones
        };
        // A candidate older than the longest period can never be confirmed.
        if let Some(first) = self.first {
            let end = base.wrapping_add(16 << FRAC);
            if diff(end, first) > bounds.1 {
                self.first = None;
            }
        }
        if found.is_some() {
            self.reset_hunt();
        }
        found
    }

    /// Looks for this channel's start edge near `at` (Q16, its expected position),
    /// ±1.5 bit times: there is exactly one falling edge in that window on a good
    /// line (the stop field has none, the next one is two bits after the start).
    pub fn edge(ring: &Ring, at: u32, ratio: i32) -> Option<u32> {
        let margin = (ratio + ratio / 2) as u32;
        ring.first_fall(
            at.wrapping_sub(margin),
            at.wrapping_add(margin).wrapping_add(HALF),
        )
    }
}
