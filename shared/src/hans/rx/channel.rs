//! What the receiver keeps per channel: the start-edge hunt used while no frame
//! timing is known, and, once it is, the channel's delay against the shared timing.
//!
//! # Hunt
//! While no timing is known each used channel hunts for two start edges a frame
//! apart ([`super::hunt`]); the first channel to confirm a pair sets the shared
//! timing ([`super::timing`]).
//!
//! # Delay
//! All channels come from one sender clock, so they share bit rate and phase up to a
//! fixed skew. Each channel's start edge is measured every frame; its offset from the
//! shared frame start is averaged (plain mean over the first 16 frames, then a 1/16
//! filter, each step clamped to one sample so a glitch cannot throw it).

use super::hunt::{Found, Hunt};
use super::ring::{Ring, FRAC, HALF};

/// Measurements after which the delay filter stops narrowing.
const DELAY_FITS: i32 = 16;
/// Largest delay against the shared timing (samples): two samples of skew plus jitter
/// and filter slack. A channel further off is not the same line.
pub const DELAY_MAX: i32 = 8 << FRAC;

/// Per-channel state.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Channel {
    /// The hunt, while no timing is known.
    search: Hunt,
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
        self.search.reset();
    }

    /// Drops the alignment. Returns true if the channel was aligned.
    pub fn unalign(&mut self) -> bool {
        self.failures = 0;
        self.fits = 0;
        self.delay.take().is_some()
    }

    /// True when the delay filter has settled (aligned and measured often enough).
    /// `fits` alone says it: it is 0 whenever the channel is not aligned (`align`
    /// and `unalign` set both, `track` counts only while aligned), so one compare
    /// a channel, which the receiver pays for every channel and frame.
    pub fn settled(&self) -> bool {
        #[cfg(test)]
        assert!(self.delay.is_some() || self.fits == 0, "{self:?}");
        self.fits >= DELAY_FITS
    }

    /// Aligns the channel with its first measured delay.
    pub fn align(&mut self, delay: i32) {
        if (-DELAY_MAX..=DELAY_MAX).contains(&delay) {
            self.delay = Some(delay);
            self.fits = 1;
            self.failures = 0;
        }
    }

    /// [`Channel::track`] of a measurement equal to the delay (a lone verified
    /// reference, whose own edge the shared timing follows): the step is zero, so
    /// only the measurement is counted; no division. The delay stays where
    /// [`Channel::align`] or [`Channel::track`] put it, which only ever store one
    /// within ±[`DELAY_MAX`], so unlike `track` this can never unalign.
    pub fn hold(&mut self) {
        #[cfg(test)]
        assert!(
            self.delay
                .is_none_or(|d| (-DELAY_MAX..=DELAY_MAX).contains(&d)),
            "{self:?}"
        );
        if self.delay.is_some() {
            self.fits = (self.fits + 1).min(DELAY_FITS);
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

    /// Hunts in stream word `index` of `ring` ([`Hunt::word`]).
    pub fn hunt(
        &mut self,
        ring: &Ring,
        index: u32,
        threshold: u32,
        bounds: (i32, i32),
    ) -> Option<Found> {
        self.search.word(ring, index, threshold, bounds)
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
