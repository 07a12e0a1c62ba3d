//! Input that never arrived: [`HansRx::skip`] tells the receiver that the next
//! `words` words of every channel are missing (a DMA half the firmware's load
//! governor dropped, or one lost on a full queue), so that a settled lock
//! **coasts** across the gap instead of hunting and locking again.
//!
//! # Why a lock may coast
//! The sender's clock runs on through the gap, and a settled lock knows its frame
//! period to about 2.5·10^-4 bit per frame (rms at ±25 % jitter, 1·10^-3 at worst,
//! measured on 180 one-channel locks at 37.5 / 40 / 50 MHz and 0 / ±1 % offset; the
//! steady-state variance of the alpha-beta filter at its settled gains gives the
//! same; every mode times on one reference channel, so the modes that decode
//! several channels track as well), so the
//! start edges it predicts across a gap of a few DMA halves (20 frames each) are off
//! by a few hundredths of a bit more than they are anyway. A fresh receiver, by
//! contrast, hunts for two start edges and runs the young fit ([`super::phase`],
//! ~1.7 times the settled CPU in super mode) for [`super::timing::YOUNG`] frames,
//! publishing nothing for the first [`super::timing::SETTLED`]: in overload,
//! shedding a half that way would add work instead of saving it.
//!
//! # What happens to the frames around the gap
//! The gap covers words `written .. written + words` of the stream; the word count
//! (and so every position) moves on by `words`, as if they had arrived.
//! - **No frame that reads a sample of the gap is decoded.** The first frame not
//!   decoded yet (its samples were still being waited for, so it reaches into the
//!   gap) and every later frame that would read a sample before the gap's end (from
//!   1.5 bits plus the largest channel delay before its start edge: the alignment
//!   search and the confirmation read no earlier) is skipped: the timing moves on
//!   by whole predicted periods without measuring an edge, the frame after the last
//!   one decoded waits for no measurement either, and decoding resumes with the
//!   first frame whose samples all lie after the gap. Its start edge and its
//!   successor's must lie within 3/8 of a bit of the prediction, as every frame's
//!   (module docs of [`super`], "Frames"), before anything is published, and its
//!   edges correct the timing as ever.
//! - **The first frames after the gap re-centre the phase.** Until
//!   [`super::timing::RECENTRE`] frames after a coast have verified (failed ones
//!   measure nothing and do not count) the timing is the
//!   least-squares line of [`super::phase`] again, its prior the filter's 128
//!   start edges as far back as the coast reached ([`super::phase::Fit::prior`]):
//!   a verified frame's 61 mid-pair edges then move the phase to within a few
//!   hundredths of a bit and the rate by their lever arm across the gap. At the
//!   filter's settled gains alone the drift would go at ~3 % a frame: a 4-half
//!   gap at 37.5 MHz, +1 % offset and ±25 % jitter left the phase 0.13 bit off
//!   for a dozen frames, until three failed frames in a row cost the lock.
//!   Each such frame costs what a young lock's does (~2 400 instructions more in
//!   super mode), twice per gap.
//! - **The rings never hold stale samples for the gap.** The ring slots of the gap's
//!   words (all of them when the gap is a ring lap or more) are cleared to zero:
//!   they still held samples from one or more laps earlier, which can pass every
//!   check (a frame's tail from 64 or 4 096 words before). Zeros hold no falling
//!   edge, also not against the first sample after the gap, so they cannot give a
//!   start edge, a hunt candidate or a pattern that passes.
//! - **Counting.** A skipped frame period counts none of a channel's frames ok,
//!   check failures or missing (nothing about the channels is known; the input was
//!   discarded, not absent from the line) but one [`HansRx::skipped`]: so in every
//!   locked period each used channel counts exactly one of frames ok, check
//!   failures, missing, or the period counts skipped. While the timing is lost
//!   after a first lock, every nominal frame period of skipped input counts
//!   skipped (as every nominal period of input counts missing). `skip` reports no
//!   event of its own: the caller that lost the input reports it once (the
//!   firmware: a `Dropped` fault on `Framing`), and an event per skipped period
//!   would cost the overloaded decoder work in proportion to what it shed.
//!
//! # When the lock is dropped instead
//! A gap that skips a frame drops the lock (as losing the timing does: the period
//! at hand counts missing, resyncs are reported, the hunt starts after the gap) when
//! - the lock is still **young** (the least-squares fit of its first
//!   [`super::timing::YOUNG`] frames, which has not pinned the rate down yet; its
//!   last [`super::timing::RECENTRE`] frames, and those re-centring a coast, may
//!   coast), or
//! - the timing would have to predict more than [`MAX_COAST`] frames without a
//!   measured start edge (consecutive skips before a frame is decoded add up).
//!
//! The bound: after the gap the tracking searches the start edge ±1.5 bits around
//! the prediction, but a settled lock follows only an edge within half a bit of it
//! (farther ones are taken for noise) and confirms a frame only within 3/8 of a
//! bit. On a line at the spec's ±25 % jitter that leaves 1/4 bit for the
//! prediction to follow the line (1/8 to confirm every frame at once); the settled
//! phase error is ~0.1 bit at worst, and the rate error adds ~1·10^-3 bit per
//! predicted frame at worst: 128 frames keep the worst prediction error measured
//! (0.22 bit) inside the 1/4, and the rms one at ~0.05. That is 5.9 DMA halves of
//! 512 words at 37.5 MHz, 6.3 at 40 MHz, 7.8 at 50 MHz; a longer gap is a new
//! acquisition ([`HansRx::max_gap_words`] for the caller's choice). The bound is
//! about keeping the lock: reading every bit right at 3x and ±25 % jitter wants the
//! phase within ~0.1 bit, so frames right after a long gap may fail their checks
//! (counted, never published) until the re-centring has caught up.

use super::channel::DELAY_MAX;
use super::ring::{diff, FRAC, RING_WORDS};
use super::{HansRx, RxEvent};

/// Most frame periods a settled lock predicts without a measured start edge
/// across skipped input (see the module docs for how it follows from the rate
/// error and the tracking window).
pub const MAX_COAST: u32 = 128;

/// Frames a single gap can add beyond its length in periods: the frame after the
/// last decoded one, a partial frame at each end.
const ENDS: u32 = 3;

/// What the receiver keeps about skipped input.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Gaps {
    /// Frame periods not decoded because their input was skipped (wrapping).
    skipped: u32,
    /// The frames the last coast predicted without a measured edge. They still
    /// count while its first frame's successor has not been measured: the timing
    /// is then at the first of its [`super::timing::RECENTRE`] young frames.
    coasted: u8,
}

impl HansRx {
    /// Tells the receiver that the next `words` words of every channel are missing
    /// (see the module docs of [`super::gap`]): a settled lock coasts across the
    /// gap, skipping every frame that would read a sample of it, and resumes with
    /// the first frame whose samples all follow it; a young lock, or one that would
    /// predict more than [`MAX_COAST`] frames without an edge, is dropped and the
    /// hunt starts after the gap. `skip(a)` then `skip(b)` is `skip(a + b)`.
    /// Events: only those of a dropped lock.
    pub fn skip(&mut self, words: u32, sink: &mut impl FnMut(RxEvent)) {
        if words == 0 {
            return;
        }
        let gap = u64::from(words) << (FRAC + 4);
        if self.locked && !self.coast(gap) {
            self.gaps.coasted = 0;
            self.lose(sink);
        }
        self.invalidate(words);
        self.written = self.written.wrapping_add(words);
        if !self.locked {
            // A run of ones or a candidate edge does not continue across the gap.
            for ch in &mut self.channels {
                ch.reset_hunt();
            }
            if self.seen {
                let period = u64::try_from(self.timing.nominal_period())
                    .unwrap_or(1)
                    .max(1);
                let total = u64::try_from(self.idle).unwrap_or(0).saturating_add(gap);
                // Truncations cannot lose anything that matters: the count wraps
                // like every counter, and the rest is below one period (< 2^31).
                self.gaps.skipped = self.gaps.skipped.wrapping_add((total / period) as u32);
                self.idle = (total % period) as i32;
            }
        }
    }

    /// Frame periods not decoded because their input was skipped ([`HansRx::skip`]):
    /// locked periods a coast passed over, and nominal periods of skipped input
    /// while the timing was lost after a first lock (wrapping).
    pub fn skipped(&self) -> u32 {
        self.gaps.skipped
    }

    /// True when a gap within [`HansRx::max_gap_words`] would be coasted across: a
    /// lock whose rate is known well enough to predict over it (its young fit in
    /// its last frames or done, `Timing::coasts`). Before that, [`HansRx::skip`]
    /// drops the lock, and the hunt and the young fit start again after the gap,
    /// so a caller that decodes only some blocks passes on every block until then
    /// (the head STATUS input, `shared::hans::follow`).
    pub fn coasts(&self) -> bool {
        self.locked && self.timing.coasts()
    }

    /// The longest gap (words per channel) a settled lock coasts across wherever it
    /// falls against the frames: [`MAX_COAST`] frame periods, less the partial and
    /// pending frames at its ends, at the shortest period the timing accepts
    /// (nominal - 5 %). About 2 970 words (5.8 DMA halves of 512) at 40 MHz. A
    /// caller with a longer gap may as well start a new receiver.
    pub fn max_gap_words(&self) -> u32 {
        let shortest = u64::try_from(self.timing.bounds.0).unwrap_or(0);
        let samples = u64::from(MAX_COAST - ENDS).saturating_mul(shortest);
        u32::try_from(samples >> (FRAC + 4)).unwrap_or(u32::MAX)
    }

    /// Moves a lock across `gap` (Q16 samples) from the word count on. False when the
    /// lock must be dropped instead (young, or beyond [`MAX_COAST`]).
    fn coast(&mut self, gap: u64) -> bool {
        let t = &self.timing;
        let period = u64::try_from(t.period).unwrap_or(0);
        if period == 0 {
            return false;
        }
        // Frames predicted without a measured edge so far: those of a coast whose
        // end has not been measured past (a re-centring before its first verified
        // frame), and a decoded frame's successor.
        let mut before = if t.recentring() {
            u64::from(self.gaps.coasted)
        } else {
            0
        };
        let first = if self.pending.is_some() {
            before += 1;
            t.predicted()
        } else {
            t.start
        };
        // The earliest sample a frame's decode reads: an unaligned channel's start
        // edge search 1.5 bits before the edge (and the sample before that), an
        // aligned channel's confirmation at its delay (up to DELAY_MAX early).
        let lead_in = (t.ratio / 2 * 3).saturating_add(DELAY_MAX + (2 << FRAC));
        let reads_from = first.wrapping_sub(lead_in as u32);
        let behind = i64::from(diff(reads_from, self.written << (FRAC + 4)));
        // The frames from `first` on whose reads begin before the gap's end; none
        // when the gap ends before the first one reads anything.
        let short = i64::try_from(gap)
            .unwrap_or(i64::MAX)
            .saturating_sub(behind);
        let Some(short) = u64::try_from(short).ok().filter(|&s| s > 0) else {
            return true;
        };
        let k = short.div_ceil(period);
        let frames = before.saturating_add(k);
        if !t.coasts() || frames > u64::from(MAX_COAST) {
            return false;
        }
        // Positions wrap (see `ring`): the product is taken modulo 2^32 on purpose.
        self.timing.start = first.wrapping_add(k.wrapping_mul(period) as u32);
        self.pending = None;
        // Both at most MAX_COAST here.
        self.gaps.skipped = self.gaps.skipped.wrapping_add(k as u32);
        self.gaps.coasted = frames as u8;
        self.timing.recentre(frames as u32);
        self.need = self.need();
        true
    }

    /// Clears the ring slots of the `words` words from the word count on (all of
    /// them for a ring lap or more): they hold samples from earlier laps.
    fn invalidate(&mut self, words: u32) {
        const ZERO: [u16; RING_WORDS] = [0; RING_WORDS];
        let n = words.min(RING_WORDS as u32);
        let at = self.written.wrapping_add(words).wrapping_sub(n);
        let zeros = ZERO.get(..n as usize).unwrap_or(&ZERO);
        for ring in &mut self.rings {
            ring.write(at, zeros);
        }
    }
}
