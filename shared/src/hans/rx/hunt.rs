//! The start-edge hunt of one channel, used while no frame timing is known (spec
//! "receiving" item 2).
//!
//! # Candidates
//! The only run of three or more equal bits in a frame is the stop field (`1 1 1`,
//! possibly preceded by a complement `1`), and it is always followed by the start bit
//! `0` (marker `1 1 1 0 1`). A falling edge after at least 2.5 bit times of ones is
//! therefore a frame-start candidate. Word-parallel: falling edges are
//! `!w & (w >> 1 | carry)`, visited with `leading_zeros`, and a run's length comes
//! from the nearest zero before it. At ±25 % edge jitter a stop field can look as
//! short as 2.5 bits and a two-bit data run as long, so the threshold misses a stop
//! field now and then and takes about one data run a frame at 40 MHz (fewer at
//! 37.5 and 50 MHz) as a false candidate.
//!
//! # Pairs, checked by reading the frame between them
//! The hunt remembers the last [`CANDIDATES`] candidates of the longest frame
//! period. A new candidate one plausible period (nominal ±5 %) after a remembered
//! one makes a pair, which measures the bit rate, and the frame between the two
//! is **read** on the line through them ([`read`]): start pair, 60 complement
//! pairs, stop bits. A false pair (a stretched data run, or a start edge paired
//! with one) reads the frame a bit or more off somewhere and its pairs match only
//! by chance, so it is dropped, usually after a few pairs: a false candidate
//! neither locks nor displaces a true one (the single remembered candidate of the
//! earlier hunt did both: a false lock cost six frames).
//!
//! # The line the lock starts with
//! Two start edges a frame apart give the rate to half a bit and a sample per
//! frame at ±25 % jitter, too little for the young lock's first frames at 3x. The
//! pair's frame has 61 mid-pair edges (every complement pair changes level in its
//! middle), so its least-squares line ([`super::phase`]) through both start edges
//! and those edges is taken, and the frame must read right on it. A few pairs
//! may read wrong on the two-edge line ([`MISREAD`]), none on the fitted one.
//!
//! Even the fitted line of one jittered frame is off by a few tenths of a sample
//! per frame at times, which at ±25 % jitter and 3x fails the lock's first frames
//! (no verified frame, no mid-pair edges, and each jittered start edge then moves
//! the phase). So the lock takes one frame only when that frame also reads right
//! with the line moved a quarter of a bit either way ([`MARGIN`]; an eighth was
//! tried and let one lock in 64 fail at 40 MHz), as any clean line does: the
//! acquisition of a clean line is as fast as before. Else the pair is kept, and
//! the next pair that continues it (its first edge is this one's last) adds its
//! start edge and its own 61 mid-pair edges to the fit: two frames give the rate
//! about three times as precisely.
//!
//! # Bounded work
//! Per word at most 2 candidates (a candidate needs 7 samples of ones and a zero),
//! each paired with at most [`CANDIDATES`] remembered ones. A pair costs at most
//! 7 frame reads of 125 samples and 4 mid-pair measurements with a 2x2 solve
//! (two-edge line, up to three fit rounds, margins, continuation); a false pair
//! usually stops within its first pairs, as a read gives up at [`MISREAD`] + 1
//! wrong. No loop depends on the data beyond that, and only an unlocked receiver
//! hunts.

use super::phase::{self, Fit, Points};
use super::ring::{diff, Ring, FRAC, HALF};
use crate::hans::FRAME_BITS;

/// Start-edge candidates remembered per channel. Within the longest period a good
/// line gives one true candidate, plus the false ones (about one a frame at ±25 %
/// jitter and 40 MHz).
const CANDIDATES: usize = 4;
/// Pairs (or stop bits) a true candidate pair's frame may read wrong on the line
/// through its two start edges (at ±25 % jitter a centre can land on its bit's
/// jittered edge; demanding none took up to 9 frames at 40 MHz). On the fitted
/// line none may.
const MISREAD: u32 = 16;
/// A single frame is enough when it reads right with its fitted line moved by
/// `ratio / MARGIN` (a quarter of a bit) either way.
const MARGIN: i32 = 4;
/// Bits per frame.
const BITS: i32 = FRAME_BITS as i32;

/// A lock the hunt confirmed: the timing line and the fit behind it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Found {
    /// The start edge of the frame to come (Q16 position, on the fitted line).
    pub start: u32,
    /// The frame period (Q16 samples).
    pub period: i32,
    /// The least-squares fit the line comes from, origin at `start`.
    pub fit: Fit,
    /// Start edges in the fit (2 or 3).
    pub edges: i32,
}

/// A pair whose frame read right but not with margin: kept for the next pair.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
struct Held {
    /// The candidate that ended the pair (the next pair must start there).
    edge: u32,
    /// The fitted line: start edge at `edge` and period.
    start: u32,
    period: i32,
    /// Its fit.
    fit: Fit,
}

/// One channel's hunt state.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Hunt {
    /// Length in samples of the run of ones that ends with the last word.
    run: u32,
    /// Unconfirmed start candidates, newest first: the first `count` slots.
    candidates: [u32; CANDIDATES],
    /// Candidates held.
    count: u8,
    /// A pair that read right without margin.
    held: Option<Held>,
}

impl Hunt {
    /// Hunts in stream word `index` of `ring` (bit 15 first). `threshold` is the
    /// shortest run of ones (samples) before a candidate, `bounds` the plausible
    /// frame periods (Q16). Returns the lock when a candidate confirms it (see the
    /// module docs); the hunt is then reset.
    pub fn word(
        &mut self,
        ring: &Ring,
        index: u32,
        threshold: u32,
        bounds: (i32, i32),
    ) -> Option<Found> {
        let (w, prev) = ring.word_and_prev(index);
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
            found = self.pair(ring, meas, bounds);
            if found.is_some() {
                break;
            }
            self.remember(meas);
        }
        let ones = w.trailing_ones();
        self.run = if ones >= 16 {
            self.run.saturating_add(16)
        } else {
            ones
        };
        // Candidates older than the longest period can never be confirmed (they
        // are the oldest, at the end).
        let end = base.wrapping_add(16 << FRAC);
        while let Some(&oldest) = self.candidates.get(usize::from(self.count).wrapping_sub(1)) {
            if diff(end, oldest) <= bounds.1 {
                break;
            }
            self.count -= 1;
        }
        if self.held.is_some_and(|h| diff(end, h.edge) > bounds.1) {
            self.held = None;
        }
        if found.is_some() {
            self.reset();
        }
        found
    }

    /// Forgets everything.
    pub fn reset(&mut self) {
        *self = Hunt::default();
    }

    /// Pairs candidate `meas` with the remembered ones one plausible period
    /// before it, newest first, and returns the lock one of them confirms.
    fn pair(&mut self, ring: &Ring, meas: u32, bounds: (i32, i32)) -> Option<Found> {
        let held = self.candidates.get(..usize::from(self.count))?;
        for &first in held {
            let d = diff(meas, first);
            if d < bounds.0 {
                continue;
            }
            if d > bounds.1 {
                // The older ones are further still.
                break;
            }
            let Some(line) = fitted(ring, first, meas, bounds) else {
                continue;
            };
            // The pair continues a held one: two frames' fit.
            if let Some(h) = self.held.filter(|h| h.edge == first) {
                if let Some(found) = continued(ring, h, meas, bounds) {
                    return Some(found);
                }
            }
            if margin(ring, &line) {
                return Some(line);
            }
            self.held = Some(Held {
                edge: meas,
                start: line.start,
                period: line.period,
                fit: line.fit,
            });
            return None;
        }
        None
    }

    /// Remembers candidate `meas`, newest first; the oldest is forgotten when all
    /// slots are taken.
    fn remember(&mut self, meas: u32) {
        self.candidates.copy_within(..CANDIDATES - 1, 1);
        if let Some(newest) = self.candidates.first_mut() {
            *newest = meas;
        }
        self.count = (self.count + 1).min(CANDIDATES as u8);
    }
}

/// The frame between candidates `first` and `meas`, if it is one: read on the
/// line through the two edges (at most [`MISREAD`] wrong), then the
/// least-squares line through the two edges and its 61 mid-pair edges, on which
/// it must read right.
fn fitted(ring: &Ring, first: u32, meas: u32, bounds: (i32, i32)) -> Option<Found> {
    let period = diff(meas, first);
    let mut pattern = read(ring, first, period)?.pattern;
    // The fit takes each edge's direction from the pattern, so it is only right
    // once the pattern it was made with reads back on its line. A round fits
    // again on what a line read: the rough line's misread pairs gave the first
    // fit points at the wrong level.
    for _ in 0..3 {
        let mut fit = Fit::lock();
        let points = phase::mid_pairs(ring, first, period / BITS, pattern);
        let line = apply(meas, period, &mut fit, &points.frame_before(), bounds)?;
        let again = read(ring, line.0.wrapping_sub(line.1 as u32), line.1)?;
        if again.wrong == 0 && again.pattern == pattern {
            return Some(Found {
                start: line.0,
                period: line.1,
                fit,
                edges: 2,
            });
        }
        pattern = again.pattern;
    }
    None
}

/// Adds `points` (residuals against the line `start`, `period`) to `fit` and
/// returns the new line, unless it moves the phase by half a bit or more or the
/// period out of `bounds` (then it is no fit of a frame).
fn apply(
    start: u32,
    period: i32,
    fit: &mut Fit,
    points: &Points,
    bounds: (i32, i32),
) -> Option<(u32, i32)> {
    let c = fit.add(points);
    let period = period.saturating_add(c.period);
    let ok = c.start.unsigned_abs() < (period / BITS / 2).unsigned_abs()
        && (bounds.0..=bounds.1).contains(&period);
    ok.then_some((start.wrapping_add(c.start as u32), period))
}

/// True when the frame before `line.start` also reads right with the line moved
/// by a quarter of a bit either way.
fn margin(ring: &Ring, line: &Found) -> bool {
    let shift = (line.period / BITS / MARGIN) as u32;
    let start = line.start.wrapping_sub(line.period as u32);
    [start.wrapping_sub(shift), start.wrapping_add(shift)]
        .into_iter()
        .all(|s| read(ring, s, line.period).is_some_and(|r| r.wrong == 0))
}

/// The two-frame lock: the held pair's fit, moved on a frame, takes the start
/// edge `meas` and the second frame's mid-pair edges; that frame must read right
/// on the line before its edges are added.
fn continued(ring: &Ring, h: Held, meas: u32, bounds: (i32, i32)) -> Option<Found> {
    let mut fit = h.fit;
    fit.next_frame();
    let predicted = h.start.wrapping_add(h.period as u32);
    let edge = Points::start_edge(diff(meas, predicted));
    let (start, period) = apply(predicted, h.period, &mut fit, &edge, bounds)?;
    let first = start.wrapping_sub(period as u32);
    let second = read(ring, first, period)?;
    if second.wrong != 0 {
        return None;
    }
    let points = phase::mid_pairs(ring, first, period / BITS, second.pattern);
    let (start, period) = apply(start, period, &mut fit, &points.frame_before(), bounds)?;
    Some(Found {
        start,
        period,
        fit,
        edges: 3,
    })
}

/// A frame read by [`read`].
struct Read {
    /// The 125 samples (first bit at bit 124).
    pattern: u128,
    /// Of the start pair, the 60 complement pairs and the 3 stop bits, those that
    /// read wrong.
    wrong: u32,
}

/// Reads the frame between start edges `start` and `start + period` (Q16): its
/// 125 bit centres, spaced `period / 125`, nearest sample each. `None` as soon as
/// more than [`MISREAD`] of its pairs and stop bits read wrong.
fn read(ring: &Ring, start: u32, period: i32) -> Option<Read> {
    let ratio = (period / BITS) as u32;
    // Centre of bit i at `start + (i + ½)·ratio`; half a sample more so that the
    // shift rounds to the nearest sample.
    let mut at = start.wrapping_add(ratio / 2).wrapping_add(HALF);
    let mut pattern = 0u128;
    let mut sample = || {
        let s = at >> FRAC;
        at = at.wrapping_add(ratio);
        let bit = (ring.window(s >> 5) >> (31 - (s & 31))) & 1;
        pattern = pattern << 1 | u128::from(bit);
        bit
    };
    let mut wrong = u32::from((sample(), sample()) != (0, 1));
    // The 60 data pairs after the start pair.
    for _ in 1..(FRAME_BITS - 3) / 2 {
        wrong += u32::from(sample() == sample());
        if wrong > MISREAD {
            return None;
        }
    }
    for _ in 0..3 {
        wrong += 1 - sample();
    }
    (wrong <= MISREAD).then_some(Read { pattern, wrong })
}
