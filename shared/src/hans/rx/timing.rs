//! The frame timing shared by all channels: where the current frame starts and how
//! long a frame (and so a bit) is, in samples.
//!
//! The five channels come from one sender clock, so one clock recovery serves them
//! all; each channel only adds its own delay ([`super::channel`]). The bit rate is
//! first measured by the hunt over one or two whole frames, on their start edges
//! and mid-pair edges ([`super::hunt`]), then every frame's start
//! edge corrects phase and rate with an alpha-beta filter whose gains start as a
//! least-squares line fit over the frames seen so far and settle at a fit over about
//! 128 frames: a jittery edge moves the estimate very little while a ±1 % (or larger)
//! rate offset is tracked exactly.
//!
//! A start edge per frame is too little for a young lock at ±25 % jitter (phase
//! known to ~0.35 sample after 8 frames, where a 3x centre has as little as 0.25
//! sample of margin), so for its first [`YOUNG`] frames the timing is the exact
//! least-squares line ([`super::phase`]) through the start edges **and the 61
//! mid-pair edges of every frame that verified** ([`Timing::refine`]): after two
//! or three verified frames phase and rate are known to a few hundredths of a
//! sample; from the fourth frame on ([`DENSE`]) every other pair's edge is enough,
//! the last 8 pairs' taken from the tail confirmation, which measured them
//! already ([`super::phase::Points::tail`]), and the frame's start edge is
//! solved with them (one solve a frame, [`Timing::advance`]).
//! Then the alpha-beta filter takes over at its settled gains (on the M7 the 61
//! edges cost ~1 700 instructions a frame, the 27 even ones before the tail
//! ~800, and the fit's solve ~190 with its 64-bit divisions ([`super::phase`]'s
//! `Divisor`), which only a young lock pays; `cargo xtask profile "young
//! lock"`). Its
//! phase measurement is the start edge blended with the mean of the 8 mid-pair
//! edges that every published frame's tail confirmation measures anyway
//! ([`super::confirm::tail`], [`Timing::tail`]): on the start edge alone its phase
//! wandered up to 0.05 bit (0.15 sample at 3x) from the mid-pair edges over a
//! lock, enough to push a ±25 % jittered tail past its quarter-bit bound; with
//! the tail the wander is below what 50 frames of tail jitter can resolve
//! (README "Known limits", docs/engineering-log.md).

use super::hunt::Found;
use super::phase::{self, Correction, Fit, Points};
use super::ring::{diff, Ring, FRAC};
use crate::hans::FRAME_BITS;

/// Start edges whose least-squares line fit the settled alpha-beta filter's gains
/// are those of, and the start edges [`Timing::recentre`]'s prior stands for.
const FIT_FRAMES: i32 = 128;
/// Start edges a lock must have measured before its frames are published: the
/// first edges set phase and rate with large gains, so a rate measured over one
/// jittered frame, or a false edge among them, can leave the sampling phase
/// drifting by half a bit and more across a frame. From here on the gains are
/// small (phase 0.42, period 0.08) and an outlier edge is not followed.
pub const SETTLED: i32 = 8;
/// Frames from the lock during which the timing is the least-squares line of
/// [`super::phase`], mid-pair edges included. Long enough for a lock whose first
/// frames fail (rate measured over one jittered frame) to see several verified
/// frames; short enough for the fit's sums to stay small (see `Fit::add`).
pub const YOUNG: i32 = 32;
/// Verified frames after a coast across skipped input ([`super::gap`]) during
/// which the timing is the least-squares line again, so that their mid-pair edges
/// re-measure the phase the gap's prediction drifted. Frames that fail do not
/// count: they measure no mid-pair edge, and handing a drifted phase to the
/// filter's settled gains (~3 % of an error a frame) left it ~0.15 bit off for
/// dozens of frames at 3x, where a ±25 % jittered pair read a bit early passes
/// every check now and then (a frame never sent, published).
pub const RECENTRE: i32 = 2;
// `Timing::advance` weighs the tail's sum as that of 8 edges.
const _: () = assert!(super::confirm::TAIL_PAIRS == 8);
/// Points a young fit holds before its verified frames are measured on every other
/// pair only ([`super::phase::even_mid_pairs`], half the cost): the hunt's frame
/// and three verified frames on all 61 pairs (62 points a frame with its start
/// edge). The first frames set the phase the lock publishes with; later ones
/// mostly add lever arm for the rate, where the line through 31 edges a frame
/// over the young frames hands the filter a rate ~15 % less precise (rms) than
/// through 61 (`tests::young`). From here on a frame's start edge also waits
/// for its mid-pair edges, so that one solve takes both ([`Timing::advance`]).
pub const DENSE: i64 = 4 * 62;
/// Bits in a frame as the fixed-point multiplier.
const BITS: i32 = FRAME_BITS as i32;

/// Where a lock is in its life, and so what times it: the least-squares line of
/// [`super::phase`] (young or re-centring, with its fit) or the alpha-beta filter
/// (settled, no fit). One state, so that a settled lock holding a fit, or a
/// re-centring that is not young, cannot be written down.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Stage {
    /// A new lock's young fit over its first `frames` frames (the hunt's 2 or 3
    /// start edges, then one a frame whether it verified or not; 0 before the
    /// first lock). At [`YOUNG`] the filter takes over ([`Stage::Settled`]).
    Young {
        /// Frames measured since the lock (below [`YOUNG`]).
        frames: i32,
        /// The fit; its line is the timing.
        fit: Fit,
        /// The current frame's start edge (its error, Q16) while it waits for
        /// the frame's mid-pair edges, so that one solve takes both
        /// ([`Timing::advance`], [`Timing::refine`]); the next advance solves
        /// it when they do not come. A coast ([`Timing::recentre`]) or a new
        /// lock drops it: its line is the prediction already.
        held: Option<i32>,
    },
    /// The young fit again after a coast ([`Timing::recentre`]) until `owed`
    /// more verified frames (1 to [`RECENTRE`]) have re-measured the phase; frames
    /// that fail do not count. The timing coasts and counts as settled meanwhile
    /// (the rate is known): it is the young fit's last `owed` frames.
    Recentre {
        /// Verified frames still to come.
        owed: i32,
        /// The fit, [`Fit::prior`] at the coast; its line is the timing.
        fit: Fit,
    },
    /// The alpha-beta filter at its settled gains (those of a line fit over
    /// [`FIT_FRAMES`] start edges).
    Settled,
}

/// Shared clock recovery.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Timing {
    /// Nominal samples per bit (Q16).
    nominal: i32,
    /// Shortest and longest plausible frame period (Q16): the nominal ±5 %.
    pub bounds: (i32, i32),
    /// Tracked samples per bit (Q16).
    pub ratio: i32,
    /// Tracked frame period (Q16 samples).
    pub period: i32,
    /// Start edge of the current frame (Q16 position, see [`super::ring`]).
    pub start: u32,
    /// Young fit, re-centring or settled filter.
    stage: Stage,
    /// The summed deviation of the current frame's last
    /// [`super::confirm::TAIL_PAIRS`] mid-pair edges from this timing, when the
    /// reference confirmed it on its own ([`super::confirm::tail`]; 0 before the
    /// lock has settled): read by the next [`Timing::advance`] as a phase
    /// measurement, unless the receiver clears it (the frame was timed on a
    /// median of other channels' edges). Every decoded frame sets it before its
    /// advance; a lock and a coast clear it.
    pub(super) tail: Option<i32>,
    /// The current frame was re-read at a rounding step ([`Timing::rephase`]):
    /// its mid-pair edges straddle the step, so [`Timing::refine`] does not
    /// take them. Cleared by the next young frame, a lock and a coast.
    rephased: bool,
    /// Far edges ([`super::confirm::far_edge`]) per settled frame of the
    /// reference's tail, averaged over about the last 16 frames (Q12; each
    /// frame counts at most [`super::confirm::FAR_EDGES`]): under [`CLEAN`]
    /// the line's tails are clean enough that [`super::confirm::excursion`]
    /// applies. A lock starts at [`FAR_START`].
    far: u16,
    /// Off edges ([`super::confirm::OFF_EDGE`], 3/4 sample) per settled frame
    /// of the reference's tail, averaged as `far` is: under [`CLEAN`] the line
    /// is steady ([`Timing::steady`]). Never below `far` (an off edge counts
    /// wherever a far one does), so a steady line is clean.
    off: u16,
}

/// [`Timing::clean`] below this far-edge rate (Q12 per frame): one far edge in
/// 32 frames. On a line with ±25 % jitter at 3x (0.45 a frame, 0.13 at 4x) the
/// average of ~16 frames stays above it (a tail with one far edge keeps it
/// above for 11 frames without any); within ±15 % (0.013 a frame at 3x, none
/// at 3.2x and 4x) it falls below it 11 frames after settling.
const CLEAN: u16 = 4096 / 32;

/// A new lock's far-edge rate: as if the frame before it had one (a line not yet
/// known to be clean).
const FAR_START: u16 = 4096 / 16;

impl Timing {
    /// Timing for `ratio_q16` nominal samples per bit.
    pub const fn new(ratio_q16: i32) -> Timing {
        let period = ratio_q16 as i64 * BITS as i64;
        Timing {
            nominal: ratio_q16,
            bounds: (clamp_i32(period * 95 / 100), clamp_i32(period * 105 / 100)),
            ratio: ratio_q16,
            period: ratio_q16.saturating_mul(BITS),
            start: 0,
            stage: Stage::Young {
                frames: 0,
                fit: Fit::lock(),
                held: None,
            },
            tail: None,
            rephased: false,
            far: FAR_START,
            off: FAR_START,
        }
    }

    /// Shortest run of ones (samples) that can only be the stop field: 2.5 bit times,
    /// rounded (data runs are at most 2 bit times).
    pub fn hunt_threshold(&self) -> u32 {
        ((self.nominal as u32).saturating_mul(5) + (1 << FRAC)) >> (FRAC + 1)
    }

    /// Starts tracking on the hunt's line ([`super::hunt`]): its start edges and
    /// mid-pair edges are the young lock's first points.
    pub fn lock(&mut self, found: Found) {
        self.stage = Stage::Young {
            frames: found.edges,
            fit: found.fit,
            held: None,
        };
        self.tail = None;
        self.rephased = false;
        self.far = FAR_START;
        self.off = FAR_START;
        self.set(found.start, found.period);
    }

    /// True when the recent settled frames' tails held (nearly) no far edges
    /// ([`super::confirm::excursion`]).
    pub fn clean(&self) -> bool {
        self.far < CLEAN
    }

    /// Counts a settled frame's reference tail's far and off edges into the
    /// rates [`Timing::clean`] and [`Timing::steady`] read (a sixteenth of the
    /// way, rounded so that each rate decays to 0).
    pub fn count_tail(&mut self, tail: super::confirm::Tail) {
        // One tail's count weighs at most `FAR_EDGES`, so the rate stays within
        // its type (16 x 4 x 256 at most).
        let blend = |rate: u16, edges: u32| {
            let edges = edges.min(super::confirm::FAR_EDGES) as u16;
            rate - rate.div_ceil(16) + edges * (4096 / 16)
        };
        self.far = blend(self.far, tail.far);
        self.off = blend(self.off, tail.off);
    }

    /// True when the recent settled frames' tails held (nearly) no off edges:
    /// every checked edge within 3/4 sample of the timing, a line without
    /// jitter to speak of, on which [`super::confirm::excursion`] rejects 3 far
    /// edges instead of 4.
    pub fn steady(&self) -> bool {
        self.off < CLEAN
    }

    fn set(&mut self, start: u32, period: i32) {
        self.start = start;
        self.period = period;
        self.ratio = period / BITS;
    }

    /// The nominal frame period (Q16 samples): paces the counting of missing
    /// channels while no timing is held.
    pub fn nominal_period(&self) -> i32 {
        self.nominal.saturating_mul(BITS)
    }

    /// The next frame's start edge as predicted.
    pub fn predicted(&self) -> u32 {
        self.start.wrapping_add(self.period as u32)
    }

    /// Moves to the next frame, whose start edge was measured `err` (Q16) after the
    /// prediction, and by [`Timing::tail`] when the frame left one.
    /// Returns false when the corrected period is implausible (the lock is then
    /// worthless).
    pub fn advance(&mut self, err: i32) -> bool {
        // The search window bounds the error to about ±2 bits (< 2^20 in Q16), so
        // the products below stay far inside i32.
        let mut err = err.clamp(-(1 << 21), 1 << 21);
        // A settled lock predicts a good line's edge within its jitter plus half a
        // sample; an edge half a bit or more off is a false (noise) or a missing
        // (next edge found) one. The timing coasts on its prediction: a frame that
        // is really off then fails its own confirmation (`HansRx::confirmed`), and
        // failing channels realign, or the lock is lost.
        if self.settled() && err.unsigned_abs() > (self.ratio / 2).unsigned_abs() {
            err = 0;
        }
        let c = match &mut self.stage {
            Stage::Young { frames, fit, held } => {
                fit.next_frame();
                let mut edge = Points::start_edge(err);
                // The frame before did not verify (or its edges were not
                // taken): its start edge, now a frame back, is solved here.
                let before = held.take();
                if let Some(h) = before {
                    edge = edge.and(&Points::start_edge(h).frame_before());
                }
                *frames += 1;
                if *frames >= YOUNG {
                    let c = fit.add(&edge);
                    self.stage = Stage::Settled;
                    c
                } else if fit.points() >= DENSE && before.is_none() {
                    // A dense fit: one start edge among its hundreds of points
                    // moves the line little, so the frame is read on the line
                    // as it was and its edge waits for the frame's mid-pair
                    // edges (one solve a frame instead of two; the fit's line
                    // after them is the same, `tests::young` measured the same
                    // precision).
                    *held = Some(err);
                    Correction::default()
                } else {
                    fit.add(&edge)
                }
            }
            // A re-centring timing stays young until its verified frames have
            // re-measured the phase ([`RECENTRE`]): the frame count does not move.
            Stage::Recentre { fit, .. } => {
                fit.next_frame();
                fit.add(&Points::start_edge(err))
            }
            Stage::Settled => return self.filter(err),
        };
        self.rephased = false;
        self.apply(self.predicted(), c)
    }

    /// [`Timing::advance`] of a settled lock: the alpha-beta filter.
    #[inline(always)]
    fn filter(&mut self, mut err: i32) -> bool {
        // The tail's mean lies 8 to 16 bits before the next start edge, so it
        // measures the same phase error as `err` (the rate error over those bits
        // is a few thousandths of a sample), with about a third of its jitter
        // (σ ~0.065 bit against ~0.17 bit at ±25 % and 3x): weighted by inverse
        // variance it counts 7/8. On the start edge alone the settled filter's
        // phase wandered up to 0.05 bit from the mid-pair edges, the margin a
        // ±25 % tail needs to pass its quarter-bit mean bound (one frame in 64
        // locks at 37.5 MHz, -0.42 %, seed 20004 of `limits_over_many_locks`:
        // mean 0.257 bit). Bounded by the tail's window, so a tail that passed by
        // chance moves the phase a few thousandths of a bit at most.
        // `tail` is 8 times the mean: (8 err + 7 tail) / 64, rounded down (half
        // a Q16 unit of bias, 1e-5 sample).
        if let Some(t) = self.tail {
            err = err.wrapping_mul(8).wrapping_add(t.wrapping_mul(7)) >> 6;
        }
        // Gains of a least-squares line fit over the last k start edges: phase
        // 2(2k-1)/(k(k+1)), period 6/(k(k+1)), at k = FIT_FRAMES. `err` is within
        // ±2^21 (`advance`), so the products stay inside i32.
        let k = FIT_FRAMES;
        let start = self
            .predicted()
            .wrapping_add((err * 2 * (2 * k - 1) / (k * (k + 1))) as u32);
        let period = self.period.saturating_add(err * 6 / (k * (k + 1)));
        self.set(start, period);
        period_ok(self.bounds, period)
    }

    /// Moves the current frame's start edge, and so every later prediction, by
    /// `shift` (Q16): the frame was re-read and confirmed at the phase its own
    /// edges showed at a rounding step (`HansRx::rephased`, [`super::confirm`]),
    /// so the next frames are read there. Phase only: a step says where the
    /// line is now, not how fast it moves. A young fit's earlier points then
    /// count as moved with it (its sums are residuals against the line). The
    /// frame re-measured the phase (its start edges and tail agree within a
    /// quarter sample), so it counts towards a re-centring ([`RECENTRE`]) as a
    /// verified frame whose mid-pair edges refined the fit does.
    pub fn rephase(&mut self, shift: i32) {
        self.start = self.start.wrapping_add(shift as u32);
        self.rephased = true;
        self.remeasured();
    }

    /// One more verified frame has measured the phase: counted by a re-centring
    /// after a coast ([`RECENTRE`]); after the last one the alpha-beta filter
    /// takes over at its settled gains from the fitted line.
    fn remeasured(&mut self) {
        if let Stage::Recentre { owed, .. } = &mut self.stage {
            if *owed > 1 {
                *owed -= 1;
            } else {
                self.stage = Stage::Settled;
            }
        }
    }

    /// Moves the current frame's start edge and the period by `c` from `start`.
    /// Returns false when the period leaves its bounds.
    fn apply(&mut self, start: u32, c: Correction) -> bool {
        let period = self.period.saturating_add(c.period);
        self.set(start.wrapping_add(c.start as u32), period);
        period_ok(self.bounds, period)
    }

    /// True while the timing is the least-squares line of [`super::phase`] (a
    /// young lock, or one re-centring after a coast).
    pub fn young(&self) -> bool {
        !matches!(self.stage, Stage::Settled)
    }

    /// [`Timing::refine`] on the mid-pair edges of the verified frame that starts
    /// at `start` (Q16, the channel's own start edge) on `ring`, `pattern` its
    /// pattern ([`phase::mid_pairs`]): every pair's until a young fit holds
    /// [`DENSE`] points, then every other pair's, the last 8 as the reference's
    /// tail measured them ([`Timing::tail`], [`phase::Points::tail`]: 4 edges
    /// fewer to measure, 4 points more) when it did; every pair's while
    /// re-centring (its few verified frames re-measure a phase the coast
    /// drifted). Out of line: a young lock's step, kept out of the settled
    /// frame's code.
    ///
    /// Every fourth pair before the tail (14 edges and the tail's 8) measured
    /// ~210 instructions a frame less and kept the fit's precision on jittered
    /// lines (`tests::young`), but on a clean line within a few hundred ppm of 3
    /// samples a bit the thinner fit followed a rounding step of every edge too
    /// slowly, and a young lock failed its frames until frame 20
    /// (`tests::rounding`).
    #[inline(never)]
    pub fn learn(&mut self, ring: &Ring, start: u32, pattern: u128) {
        let ratio = self.ratio;
        let points = match (&self.stage, self.tail) {
            (Stage::Young { fit, .. }, tail) if fit.points() >= DENSE => match tail {
                Some(sum) => {
                    phase::head_mid_pairs(ring, start, ratio, pattern).and(&Points::tail(sum))
                }
                None => phase::even_mid_pairs(ring, start, ratio, pattern),
            },
            _ => phase::mid_pairs(ring, start, ratio, pattern),
        };
        self.refine(&points);
    }

    /// Adds the edges `p` measured on the current frame (against this timing plus
    /// the channel's delay) to a young lock's fit and moves the timing to the new
    /// line. Points that would move the phase by half a bit or more, or the period
    /// out of bounds, are not taken: a frame read that far off cannot have
    /// verified. Nor are those of a frame re-read at a rounding step
    /// ([`Timing::rephase`]): its earlier edges lie a sample from its later ones,
    /// which would tilt the line; the step's phase is all it tells. (A failed
    /// young frame that `HansRx::reread` reads right a little over is taken: its
    /// edges are one reading's.)
    // Inlined into `learn`, as when it was its one caller: called from
    // `HansRx::reread` too, it stayed out of line and cost the young lock ~30
    // instructions a frame (QEMU).
    #[inline(always)]
    pub fn refine(&mut self, p: &Points) {
        if self.rephased {
            return;
        }
        let mut none = None;
        let (fit, held) = match &mut self.stage {
            Stage::Young { fit, held, .. } => (fit, held),
            Stage::Recentre { fit, .. } => (fit, &mut none),
            Stage::Settled => return,
        };
        let mut next = *fit;
        let c = next.add(&held.map_or(*p, |h| p.and(&Points::start_edge(h))));
        let period = self.period.saturating_add(c.period);
        if c.start.unsigned_abs() < (self.ratio / 2).unsigned_abs()
            && period_ok(self.bounds, period)
        {
            *fit = next;
            *held = None;
            self.apply(self.start, c);
            self.remeasured();
        }
    }

    /// Failing patterns in a row after which a channel's alignment, or the lock, is
    /// abandoned: [`super::RELOCK_AFTER`], twice that before the lock has settled.
    /// A lock's first period is measured over one jittered frame: at ±25 % jitter
    /// its first frames can drift out of the bit centres at their ends and fail
    /// until a few start edges (or the first verified frame's edges) have fixed
    /// the rate; giving up there costs a hunt, which at ±25 % jitter (a data run
    /// of two bits can look like the stop field's 2.5) can take many frames.
    pub fn relock_after(&self) -> u8 {
        if self.settled() {
            super::RELOCK_AFTER
        } else {
            2 * super::RELOCK_AFTER
        }
    }

    /// After a coast that predicted `frames` periods without a measured start
    /// edge ([`super::gap`]): the fit becomes [`Fit::prior`] of the filter's
    /// `FIT_FRAMES` (128) start edges that far back, and the timing stays young
    /// until [`RECENTRE`] verified frames have refined it (mid-pair edges
    /// measured, then the filter takes over again at its settled gains). Frames
    /// that fail meanwhile are bounded by the failure counts as ever (channels
    /// realign, the lock is lost).
    pub fn recentre(&mut self, frames: u32) {
        self.stage = Stage::Recentre {
            owed: RECENTRE,
            fit: Fit::prior(FIT_FRAMES as u32, frames),
        };
        self.tail = None;
        self.rephased = false;
    }

    /// True when the rate is known well enough to predict across a gap: the
    /// alpha-beta filter has taken over, or the young fit is in its last
    /// [`RECENTRE`] frames (which also re-centre a coast).
    pub fn coasts(&self) -> bool {
        match self.stage {
            Stage::Young { frames, .. } => frames >= YOUNG - RECENTRE,
            Stage::Recentre { .. } | Stage::Settled => true,
        }
    }

    /// True after a coast until the first verified frame has re-measured the
    /// phase on its mid-pair edges: until then the phase is the coast's
    /// prediction, which can have drifted a good part of a bit, and a frame read
    /// with it can pass every check with one pair read a bit off (the first frame
    /// after a 2-half coast at 50 MHz / -1 % in super mode did), so it must not be
    /// published.
    pub fn recentring(&self) -> bool {
        matches!(self.stage, Stage::Recentre { owed: RECENTRE, .. })
    }

    /// Points in a young (or re-centring) lock's fit; `None` once settled.
    #[cfg(test)]
    pub(super) fn fit_points(&self) -> Option<i64> {
        match &self.stage {
            Stage::Young { fit, .. } | Stage::Recentre { fit, .. } => Some(fit.points()),
            Stage::Settled => None,
        }
    }

    /// True once the lock has measured [`SETTLED`] start edges.
    pub fn settled(&self) -> bool {
        match self.stage {
            Stage::Young { frames, .. } => frames >= SETTLED,
            Stage::Recentre { .. } | Stage::Settled => true,
        }
    }

    /// Offset of position `p` from the current start edge.
    pub fn since_start(&self, p: u32) -> i32 {
        diff(p, self.start)
    }
}

/// True when `period` lies within `bounds` (the timing's).
#[inline(always)]
fn period_ok(bounds: (i32, i32), period: i32) -> bool {
    (bounds.0..=bounds.1).contains(&period)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A settled lock at 3 samples a bit that has just coasted across 68 frames.
    fn coasted() -> Timing {
        let mut t = Timing::new(3 << FRAC);
        t.stage = Stage::Settled;
        t.recentre(68);
        t
    }

    /// A [`coasted`] timing whose lock was lost and found again by the hunt.
    fn relocked() -> Timing {
        let mut t = coasted();
        t.lock(Found {
            start: 1 << 24,
            period: 375 << FRAC,
            fit: Fit::lock(),
            edges: 2,
        });
        t
    }

    #[test]
    fn recentring_waits_for_verified_frames() {
        // Frames after the coast that fail (no mid-pair edges, no `refine`) leave
        // the timing young however many there are: handing the phase the coast
        // drifted to the settled gains let a frame read a pair a bit early and
        // publish it (37.5 MHz, +1 %, ±25 % jitter, 3 halves skipped, super mode).
        let mut t = coasted();
        for _ in 0..(2 * RECENTRE) {
            assert!(t.advance(0));
            assert!(t.young() && t.coasts() && t.settled(), "{t:?}");
        }
        // Each verified frame counts; after RECENTRE of them the filter takes over
        // at its settled gains.
        for n in 1..=RECENTRE {
            assert!(t.young(), "{n}: {t:?}");
            t.refine(&Points::start_edge(0));
            assert!(t.advance(0));
        }
        assert!(!t.young() && t.stage == Stage::Settled, "{t:?}");
    }

    #[test]
    fn a_settled_lock_weighs_the_tail_seven_eighths() {
        let settled = |tail| {
            let mut t = Timing::new(3 << FRAC);
            t.stage = Stage::Settled;
            t.tail = tail;
            t
        };
        // Start edge on time, the tail's 8 edges a sample late on average: as a
        // start edge 7/8 sample late alone.
        let mut blended = settled(Some(8 << FRAC));
        let mut alone = settled(None);
        assert!(blended.advance(0) && alone.advance(7 << (FRAC - 3)));
        assert_eq!((blended.start, blended.period), (alone.start, alone.period));
        assert_ne!(alone.start, settled(None).predicted());
        // Start edge a sample early, tail on time: an eighth of it counts.
        let mut blended = settled(Some(0));
        let mut alone = settled(None);
        assert!(blended.advance(-(1 << FRAC)) && alone.advance(-(1 << (FRAC - 3))));
        assert_eq!((blended.start, blended.period), (alone.start, alone.period));
        // A young lock's fit takes its mid-pair edges, the tail's included,
        // itself (`learn`): the tail is not counted twice.
        let young = |tail| young(Fit::lock(), SETTLED, tail);
        let (mut with, mut without) = (young(Some(8 << FRAC)), young(None));
        assert!(with.advance(1 << FRAC) && without.advance(1 << FRAC));
        assert_eq!((with.start, with.period), (without.start, without.period));
    }

    /// A young timing at 3 samples a bit, `frames` into its fit `fit`, its
    /// current frame at sample 20 and its tail `tail`.
    fn young(fit: Fit, frames: i32, tail: Option<i32>) -> Timing {
        let mut t = Timing::new(3 << FRAC);
        t.stage = Stage::Young {
            frames,
            fit,
            held: None,
        };
        t.start = 20 << FRAC;
        t.tail = tail;
        t
    }

    /// A young fit that holds [`DENSE`] points and more.
    fn thick() -> Fit {
        let mut thick = Fit::lock();
        thick.add(&Points::start_edge(0));
        for _ in 0..DENSE {
            thick.add(&Points::start_edge(0));
        }
        thick
    }

    #[test]
    fn a_young_fit_takes_every_other_pair_once_it_holds_a_few_frames() {
        use crate::hans::Frame;
        // A frame 0.3 sample late at 3.1 samples a bit against a timing at 3.
        let pattern = Frame::new(0x5A3C1, 0xF0F0F, 0x12345).unwrap().encode();
        let ring = phase::tests::ring_of_edges(pattern, |k| 20.3 + 3.1 * k as f64);
        let at = 20 << FRAC;
        let ratio = 3 << FRAC;
        let tail = super::super::confirm::tail(&ring, at, ratio, pattern).map(|t| t.sum);
        assert!(tail.is_some());
        let every = phase::mid_pairs(&ring, at, ratio, pattern);
        let even = phase::even_mid_pairs(&ring, at, ratio, pattern);
        let with_tail = |p: Points| p.and(&Points::tail(tail.unwrap_or(0)));
        let head = with_tail(phase::head_mid_pairs(&ring, at, ratio, pattern));
        for (fit, frames, tail, points) in [
            // A thin fit: every pair, with a tail or without.
            (Fit::lock(), 3, None, every),
            (Fit::lock(), 3, tail, every),
            // A dense one: every other pair before the tail and the tail's
            // edges; without a tail (the frame verified on another channel)
            // every other pair.
            (thick(), 3, tail, head),
            (thick(), YOUNG - 1, tail, head),
            (thick(), 3, None, even),
        ] {
            let (mut learned, mut refined) = (young(fit, frames, tail), young(fit, frames, tail));
            learned.learn(&ring, learned.start, pattern);
            refined.refine(&points);
            assert_eq!(learned, refined, "{frames} {tail:?} {points:?}");
            assert_ne!(learned, young(fit, frames, tail), "{frames} {tail:?}");
        }
        // Re-centring after a coast: every pair, however many points.
        let mut learned = young(thick(), 3, tail);
        learned.stage = Stage::Recentre {
            owed: RECENTRE,
            fit: thick(),
        };
        let mut refined = learned;
        learned.learn(&ring, learned.start, pattern);
        refined.refine(&every);
        assert_eq!(learned, refined);
    }

    #[test]
    fn a_dense_young_fit_solves_once_a_frame() {
        let q = |v: f64| (v * f64::from(1 << FRAC)) as i32;
        let p = Points::tail(q(2.4));
        // The line a fit gives after its next frame's `points`, from `timing`.
        let solved = |timing: &Timing, fit: Fit, frames: u32, points: Points| {
            let mut fit = fit;
            for _ in 0..frames {
                fit.next_frame();
            }
            let c = fit.add(&points);
            (
                timing.start.wrapping_add(c.start as u32),
                timing.period + c.period,
            )
        };
        // A thin fit solves the start edge at once.
        let mut t = young(Fit::lock(), 3, None);
        let before = t;
        assert!(t.advance(q(0.4)));
        let mut moved = before;
        moved.start = before.predicted();
        assert_eq!(
            (t.start, t.period),
            solved(&moved, Fit::lock(), 1, Points::start_edge(q(0.4)))
        );
        // A dense one reads the frame on the line as it was, and solves the
        // start edge with the frame's mid-pair edges.
        let mut t = young(thick(), 3, None);
        let before = t;
        assert!(t.advance(q(0.4)));
        assert_eq!((t.start, t.period), (before.predicted(), before.period));
        let read = t;
        t.refine(&p);
        let both = p.and(&Points::start_edge(q(0.4)));
        assert_eq!((t.start, t.period), solved(&read, thick(), 1, both));
        assert_ne!((t.start, t.period), (read.start, read.period));
        // A frame that did not verify: the next one's start edge is solved with
        // its edge, a frame back; that frame is read on the moved line.
        let mut t = young(thick(), 3, None);
        assert!(t.advance(q(0.4)));
        let read = t;
        assert!(t.advance(q(-0.2)));
        let mut moved = read;
        moved.start = read.predicted();
        let both = Points::start_edge(q(-0.2)).and(&Points::start_edge(q(0.4)).frame_before());
        assert_eq!((t.start, t.period), solved(&moved, thick(), 2, both));
        // A frame re-read at a rounding step takes no mid-pair edges: its start
        // edge waits for the next frame.
        let mut t = young(thick(), 3, None);
        assert!(t.advance(q(0.4)));
        t.rephase(q(1.0));
        let read = t;
        t.refine(&p);
        assert_eq!(t, read);
    }

    #[test]
    fn a_new_lock_owes_no_recentring() {
        // A coast whose frames all failed, then the lock was lost and the hunt
        // locked again: the new lock counts its young frames as ever (verified or
        // not), it does not wait for the old coast's re-centring.
        let mut t = relocked();
        for _ in 2..YOUNG {
            assert!(t.young(), "{t:?}");
            assert!(t.advance(0));
        }
        assert!(!t.young() && t.stage == Stage::Settled, "{t:?}");
    }

    #[test]
    fn a_line_is_clean_after_eleven_tails_without_far_edges() {
        // A new lock is not known to be clean (nor steady); 11 tails without a
        // far (off) edge make it so, one undoes that for 11 more at least, and
        // a line showing one in every third tail (±25 % jitter at 3x) never
        // gets there. A tail's count weighs at most `FAR_EDGES`, and the rate
        // stays within its type. The two records are kept apart: far edges
        // leave the steady one alone, off edges the clean one.
        use super::super::confirm::Tail;
        let far = |n: u32| Tail {
            sum: 0,
            far: n,
            off: 0,
            end: false,
        };
        let off = |n: u32| Tail {
            sum: 0,
            far: 0,
            off: n,
            end: false,
        };
        for (edges, state) in [
            (
                &far as &dyn Fn(u32) -> Tail,
                Timing::clean as fn(&Timing) -> bool,
            ),
            (&off, Timing::steady),
        ] {
            let mut t = relocked();
            let after = |t: &mut Timing| {
                (0..40).position(|_| {
                    let now = state(t);
                    t.count_tail(edges(0));
                    now
                })
            };
            assert_eq!(after(&mut t), Some(11), "{t:?}");
            t.count_tail(edges(1));
            assert!(!state(&t));
            let again = after(&mut t);
            assert!(again.is_some_and(|n| n >= 11), "{again:?} {t:?}");
            for k in 0..300 {
                t.count_tail(edges(u32::from(k % 3 == 0)));
                assert!(k < 2 || !state(&t), "{k}");
            }
            for _ in 0..300 {
                t.count_tail(edges(u32::MAX));
                assert!(!state(&t));
            }
        }
        let mut t = relocked();
        for _ in 0..20 {
            t.count_tail(far(8));
        }
        assert!(!t.clean() && t.steady());
        for _ in 0..100 {
            t.count_tail(off(8));
        }
        assert!(t.clean() && !t.steady());
    }
}
