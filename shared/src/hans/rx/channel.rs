//! Clock recovery and framing for one oversampled HANS-100 channel.
//!
//! # How one channel is decoded
//! The line is sampled by a clock that has nothing to do with the sender's bit clock,
//! at `r` = 3..4 samples per bit (layout item 3). Fixed-point positions (16 fraction
//! bits, in samples) describe where things are; they are kept relative to the start
//! of the word being processed, so nothing grows without bound.
//!
//! 1. **Hunt**: the only run of three or more equal bits in a frame is the stop field
//!    (`1 1 1`, possibly preceded by a complement `1`), and it is always followed by
//!    the start bit `0` (spec "receiving" item 2, marker `1 1 1 0 1`). A falling edge
//!    after at least 2.5 bit times of ones is therefore a frame-start candidate.
//!    Word-parallel: falling edges are `!w & (w >> 1 | carry)`, visited with
//!    `leading_zeros`, and a run's length comes from the nearest zero above it.
//! 2. **Confirm**: a second candidate 125 bit times (±5 %) after the first gives the
//!    frame period, so the bit rate is measured before any bit is trusted.
//! 3. **Bits**: bit `i` of the frame is taken from the sample nearest to
//!    `E + (i + ½)·r̂`, where `E` is the start-edge estimate and `r̂` the tracked
//!    samples-per-bit. Centre sampling gives the largest margin against edge jitter.
//! 4. **Seek**: after the 125th bit the next start edge must lie within ±1.5 bits of
//!    the prediction `E + 125·r̂` (there is exactly one falling edge in that window on
//!    a good line: the stop field has none and the next one comes after the start
//!    pair). The measured edge corrects phase and rate with an alpha-beta filter whose
//!    gains start as a least-squares line fit over the frames seen so far and settle at
//!    a fit over about 128 frames, so a jittery edge moves the estimate very little
//!    while a ±1 % (or larger) rate offset is tracked exactly. No edge in the window:
//!    the channel reports a loss and hunts again.
//!
//! The channel only recovers raw 125-bit patterns; checking them (start pair,
//! complement pairs, stop bits) is [`crate::hans::Frame::decode`]'s job, done by the
//! decode mode in [`super`]. A pattern that fails there costs nothing here: timing
//! comes from the start edges alone, which keep coming while the data is good or bad.
//!
//! Work per word is bounded: at most a handful of state steps, each a loop over at
//! most 16 samples or 8 edges.

use crate::hans::FRAME_BITS;

/// Fraction bits of the fixed-point sample positions.
const FRAC: u32 = 16;
/// Half a sample.
const HALF: i32 = 1 << (FRAC - 1);
/// One 16-sample ring word.
const WORD: i32 = 16 << FRAC;
/// Frames after which the alpha-beta gains stop shrinking.
const FIT_FRAMES: i32 = 128;
/// Failing patterns in a row after which a lock is abandoned.
pub const RELOCK_AFTER: u8 = 3;
/// Bits in a frame as the fixed-point multiplier.
const BITS: i32 = FRAME_BITS as i32;

/// Where the channel is.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum State {
    /// Looking for a start-edge candidate.
    Hunt,
    /// One candidate at `first` (Q16, relative to the current word); looking for the
    /// next one a frame later.
    Confirm { first: i32 },
    /// Sampling the bits of a frame.
    Bits,
    /// Frame done; looking for the next start edge in samples `lo..=hi` (relative to
    /// the current word).
    Seek { lo: i32, hi: i32 },
}

/// What one word produced on one channel.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Step {
    /// A complete 125-bit pattern (first bit at bit 124), not yet checked.
    pub pattern: Option<u128>,
    /// The channel lost frame alignment (no start edge where one was due).
    pub lost: bool,
}

/// Clock recovery and framing state of one channel.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ChannelRx {
    /// Shortest and longest plausible frame period (Q16): the nominal ±5 %.
    bounds: (i32, i32),
    /// Tracked samples per bit (Q16).
    ratio: i32,
    /// Tracked frame period (Q16 samples).
    period: i32,
    /// Start-edge estimate of the current frame (Q16, relative to the current word).
    start: i32,
    /// Sample position of the next bit centre plus half a sample (Q16, relative to the
    /// current word), so that `>> FRAC` rounds to the nearest sample.
    next: i32,
    /// Bits sampled so far in this frame.
    nbits: u32,
    /// The first 96 bits of the frame (three 32-bit groups) and the current group.
    groups: [u32; 3],
    acc: u32,
    /// The previous word (for edges across the word boundary and look-back).
    prev: u32,
    /// Length in samples of the run of ones that ends with the previous word.
    run: u32,
    /// Measurements in the current lock (selects the alpha-beta gains).
    fits: i32,
    /// Consecutive patterns that failed their checks.
    failures: u8,
    state: State,
}

impl ChannelRx {
    /// A channel decoder for `ratio_q16` samples per bit (16 fraction bits).
    pub const fn new(ratio_q16: i32) -> ChannelRx {
        let period = ratio_q16 as i64 * BITS as i64;
        ChannelRx {
            bounds: (clamp_i32(period * 95 / 100), clamp_i32(period * 105 / 100)),
            ratio: ratio_q16,
            period: ratio_q16.saturating_mul(BITS),
            start: 0,
            next: 0,
            nbits: 0,
            groups: [0; 3],
            acc: 0,
            prev: 0,
            run: 0,
            fits: 0,
            failures: 0,
            state: State::Hunt,
        }
    }

    /// True while the channel follows a frame sequence (sampling or seeking).
    pub fn locked(&self) -> bool {
        matches!(self.state, State::Bits | State::Seek { .. })
    }

    /// The tracked samples per bit (Q16).
    pub fn ratio_q16(&self) -> i32 {
        self.ratio
    }

    /// Shortest and longest plausible frame period (Q16), precomputed: the
    /// divisions would cost more than a word's decoding.
    fn period_bounds(&self) -> (i32, i32) {
        self.bounds
    }

    /// Tells the channel whether its last pattern passed the checks. A lock that
    /// yields [`RELOCK_AFTER`] failing patterns in a row is taken to be a false lock
    /// (on a data edge that happened to repeat a frame apart, or a rate far off):
    /// the channel hunts again. Returns true when it gave up its lock.
    pub fn checked(&mut self, ok: bool) -> bool {
        if ok {
            self.failures = 0;
            return false;
        }
        self.failures = self.failures.saturating_add(1);
        if self.failures >= RELOCK_AFTER && self.locked() {
            self.failures = 0;
            self.state = State::Hunt;
            return true;
        }
        false
    }

    /// Feeds one 16-sample word (bit 15 = earliest sample).
    pub fn push(&mut self, word: u16) -> Step {
        let w = u32::from(word);
        let x = self.prev << 16 | w;
        let mut step = Step::default();
        // Fast path: mid-frame, the word only feeds the sampler.
        if self.state == State::Bits && self.sample(x, &mut step) {
            self.end_word(w);
            return step;
        }
        // Samples before `from` (in this word) were already looked at by an earlier
        // state in this same word.
        let mut from: i32 = 0;
        // Each pass either finishes the word or moves to a later state; four passes
        // cover the longest chain (seek fails -> hunt -> confirm -> bits).
        for _ in 0..5 {
            match self.state {
                State::Bits => {
                    if self.sample(x, &mut step) {
                        break;
                    }
                }
                State::Seek { lo, hi } => match find_falling(x, lo.max(from), hi) {
                    Some(s) => {
                        self.track(s);
                        from = s;
                    }
                    None if hi <= 15 => {
                        step.lost = true;
                        self.state = State::Hunt;
                        from = from.max(hi.max(0));
                    }
                    None => break,
                },
                State::Hunt | State::Confirm { .. } => match self.hunt(w, x, from) {
                    Some(s) => from = s,
                    None => break,
                },
            }
        }
        self.end_word(w);
        step
    }

    /// Samples bit centres inside this word. Returns true when the word is done
    /// (false: the frame completed and the state moved on).
    fn sample(&mut self, x: u32, step: &mut Step) -> bool {
        let mut acc = self.acc;
        let mut nbits = self.nbits;
        let mut next = self.next;
        // At 3..4 samples per bit a word holds at most 6 bit centres. When they can
        // neither complete a 32-bit group nor the frame, the loop needs no checks
        // (the common case, about four words in five).
        if nbits % 32 + 6 < 32 && nbits + 6 < FRAME_BITS as u32 {
            let ratio = self.ratio;
            while next < WORD {
                // `next` >= -16 samples here (see `end_word`), so the shift is 0..=31.
                let shift = ((next >> FRAC) + 16) as u32 & 31;
                acc = acc << 1 | (x << shift) >> 31;
                nbits += 1;
                next += ratio;
            }
            self.acc = acc;
            self.nbits = nbits;
            self.next = next;
            return true;
        }
        while next < WORD {
            // `x` holds the previous word in bits 31..16: position p (-16..15) is bit
            // 15 - p; shifting it to bit 31 and back isolates it.
            let shift = ((next >> FRAC) + 16).clamp(0, 31) as u32;
            acc = acc << 1 | (x << shift) >> 31;
            nbits += 1;
            next += self.ratio;
            if nbits.is_multiple_of(32) {
                if let Some(g) = self.groups.get_mut((nbits / 32 - 1) as usize) {
                    *g = acc;
                }
            }
            if nbits == FRAME_BITS as u32 {
                let [g0, g1, g2] = self.groups;
                let pattern = u128::from(g0) << 93
                    | u128::from(g1) << 61
                    | u128::from(g2) << 29
                    | u128::from(acc & ((1 << 29) - 1));
                step.pattern = Some(pattern);
                let pred = self.start.saturating_add(self.period);
                let margin = self.ratio + self.ratio / 2;
                self.state = State::Seek {
                    lo: pred.saturating_sub(margin) >> FRAC,
                    hi: pred.saturating_add(margin).saturating_add(HALF) >> FRAC,
                };
                self.acc = 0;
                self.nbits = 0;
                self.next = next;
                return false;
            }
        }
        self.acc = acc;
        self.nbits = nbits;
        self.next = next;
        true
    }

    /// A start edge found at sample `s` (first sample low): corrects phase and rate
    /// and starts sampling the new frame.
    fn track(&mut self, s: i32) {
        let meas = (s << FRAC) - HALF;
        let pred = self.start.saturating_add(self.period);
        // Alpha-beta gains of a least-squares line fit over the last k start edges
        // (k capped at FIT_FRAMES): phase 2(2k-1)/(k(k+1)), period 6/(k(k+1)).
        // The seek window bounds the error to about ±2 bits (< 2^20 in Q16), so the
        // products below stay far inside i32 (k(k+1) <= 16512, 2(2k-1) <= 510) and
        // the divisions are single instructions on the M7.
        let err = meas.saturating_sub(pred).clamp(-(1 << 21), 1 << 21);
        self.fits = (self.fits + 1).min(FIT_FRAMES);
        let k = self.fits;
        let start = pred.saturating_add(err * 2 * (2 * k - 1) / (k * (k + 1)));
        let period = self.period.saturating_add(err * 6 / (k * (k + 1)));
        let (lo, hi) = self.period_bounds();
        if (lo..=hi).contains(&period) {
            self.begin(start, period);
        } else {
            self.state = State::Hunt;
        }
    }

    /// Starts sampling a frame whose start edge is at `start` (Q16).
    fn begin(&mut self, start: i32, period: i32) {
        self.start = start;
        self.period = period;
        self.ratio = period / BITS;
        self.next = start + self.ratio / 2 + HALF;
        self.nbits = 0;
        self.acc = 0;
        self.state = State::Bits;
    }

    /// Looks for a start-edge candidate at or after sample `from` of this word
    /// (Hunt / Confirm). Returns the sample after the candidate when one was found
    /// (the state has moved on), `None` when the word holds none.
    fn hunt(&mut self, w: u32, x: u32, from: i32) -> Option<i32> {
        // Shortest run of ones that can only be the stop field: 2.5 bit times,
        // rounded (data runs are at most 2 bit times).
        let threshold = ((self.ratio as u32).saturating_mul(5) + (1 << FRAC)) >> (FRAC + 1);
        let mut falls = !x & (x >> 1) & 0xFFFF & window_mask(from, 15);
        while falls != 0 {
            let j = 31 - falls.leading_zeros();
            let s = 15 - j as i32;
            // Zeros earlier than s in this word: the nearest one bounds the run.
            let zeros = !w & 0xFFFF & !((2u32 << j) - 1);
            let run = if zeros == 0 {
                self.run.saturating_add(s as u32)
            } else {
                zeros.trailing_zeros() - j - 1
            };
            falls &= !(1 << j);
            if run < threshold {
                continue;
            }
            let meas = (s << FRAC) - HALF;
            match self.state {
                State::Confirm { first } => {
                    let d = meas.saturating_sub(first);
                    let (lo, hi) = self.period_bounds();
                    if (lo..=hi).contains(&d) {
                        self.fits = 2;
                        self.begin(meas, d);
                    } else {
                        // Too close or too far: one of the two was not a frame
                        // start. The newer one is the better guess.
                        self.state = State::Confirm { first: meas };
                    }
                }
                _ => self.state = State::Confirm { first: meas },
            }
            return Some(s + 1);
        }
        None
    }

    /// Moves every word-relative position back by one word.
    fn end_word(&mut self, w: u32) {
        self.start = self.start.saturating_sub(WORD);
        self.next = self.next.saturating_sub(WORD);
        match &mut self.state {
            State::Confirm { first } => {
                *first = first.saturating_sub(WORD);
                // A candidate older than the longest period can never be confirmed.
                if *first < -self.period_bounds().1 {
                    self.state = State::Hunt;
                }
            }
            State::Seek { lo, hi } => {
                *lo -= 16;
                *hi -= 16;
            }
            State::Bits | State::Hunt => {}
        }
        // A sampling position left behind by more than a word means the timing is
        // nonsense (cannot happen with sane estimates); start over rather than guess.
        if self.state == State::Bits && self.next < -WORD {
            self.state = State::Hunt;
        }
        let ones = w.trailing_ones();
        self.run = if ones >= 16 {
            self.run.saturating_add(16)
        } else {
            ones
        };
        self.prev = w;
    }
}

/// `v` saturated to `i32`.
const fn clamp_i32(v: i64) -> i32 {
    if v > i32::MAX as i64 {
        i32::MAX
    } else if v < i32::MIN as i64 {
        i32::MIN
    } else {
        v as i32
    }
}

/// Mask of the bits of a `prev << 16 | word` window that hold samples `lo..=hi`
/// (relative to the current word, valid range -16..=15; sample s is bit 15 - s).
fn window_mask(lo: i32, hi: i32) -> u32 {
    let lo = lo.max(-16);
    let hi = hi.min(15);
    if lo > hi {
        return 0;
    }
    // Bits 15 - hi ..= 15 - lo.
    let top = (15 - lo) as u32; // 0..=31
    let bottom = (15 - hi) as u32;
    let upto_top = if top >= 31 {
        u32::MAX
    } else {
        (2u32 << top) - 1
    };
    upto_top & !((1u32 << bottom) - 1)
}

/// The earliest falling edge (first low sample after a high one) at samples
/// `lo..=hi` of the window `x` (previous word in bits 31..16).
fn find_falling(x: u32, lo: i32, hi: i32) -> Option<i32> {
    let falls = !x & (x >> 1) & window_mask(lo.max(-15), hi);
    if falls == 0 {
        None
    } else {
        Some(15 - (31 - falls.leading_zeros()) as i32)
    }
}
